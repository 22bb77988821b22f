"""The layering: `estimation/` runs on a real drone (no pybullet, no gymnasium), imports go
agents -> landing_env -> estimation only, and there is no import cycle, counting imports inside
functions."""

from __future__ import annotations

import ast
import pkgutil
import subprocess
import sys
from pathlib import Path

import estimation


def test_estimation_imports_no_simulator_or_rl_package() -> None:
    modules = [f"estimation.{m.name}" for m in pkgutil.iter_modules(estimation.__path__)]
    code = (
        "import importlib, sys\n"
        f"for name in {modules!r}: importlib.import_module(name)\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
        "('pybullet', 'pybullet_utils', 'gymnasium', 'landing_env', 'stable_baselines3'))\n"
        "print(','.join(bad))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert len(modules) > 5
    assert result.stdout.strip() == "", result.stdout


# ------------------------------------------------------------------------------ the layering
ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("estimation", "landing_env", "agents")
#: each package may import only itself and the packages after it
LAYERS = {"agents": {"agents", "landing_env", "estimation"}, "landing_env": {"landing_env",
          "estimation"}, "estimation": {"estimation"}}  # fmt: skip


def _modules() -> dict[str, Path]:
    modules = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            modules[name] = path
    return modules


def _imports(path: Path, modules: dict[str, Path]) -> list[tuple[str, bool, int]]:
    """(imported project module, inside a function, line) of every import in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found: list[tuple[str, bool, int]] = []

    def visit(node: ast.AST, in_function: bool, type_checking: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inside = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
            guarded = type_checking or (
                isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test)
            )
            if isinstance(child, ast.ImportFrom) and child.module and not child.level:
                names = [f"{child.module}.{a.name}" for a in child.names]
                targets = [n for n in names if n in modules] or [child.module]
                for target in targets:
                    if target.split(".")[0] in PACKAGES and not guarded:
                        found.append((target, inside, child.lineno))
            elif isinstance(child, ast.Import):
                for alias in child.names:
                    if alias.name.split(".")[0] in PACKAGES and not guarded:
                        found.append((alias.name, inside, child.lineno))
            visit(child, inside, guarded)

    visit(tree, False, False)
    return found


def test_no_import_cycles_counting_imports_inside_functions() -> None:
    modules = _modules()
    graph = {
        name: {target for target, _, _ in _imports(path, modules) if target in modules}
        for name, path in modules.items()
    }
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for target in sorted(graph.get(node, ())):
            if target not in graph:
                continue
            if state.get(target) == 1:
                cycle = stack[stack.index(target) :]
                raise AssertionError(f"import cycle: {' -> '.join([*cycle, target])}")
            if target not in state:
                visit(target)
        stack.pop()
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name)


def test_imports_go_down_the_layers_only() -> None:
    modules = _modules()
    wrong = [
        f"{name}:{line} imports {target}"
        for name, path in modules.items()
        for target, _, line in _imports(path, modules)
        if target.split(".")[0] not in LAYERS[name.split(".")[0]]
    ]
    assert not wrong, wrong


def test_project_modules_are_imported_at_the_top_of_a_module_not_inside_functions() -> None:
    """An import inside a function is kept for a heavy optional dependency only (torch, Ray,
    the ``io`` extra), never to dodge a cycle between the project's own modules; a module of
    ``agents.io`` that needs the ``io`` extra is imported where its command runs."""
    modules = _modules()
    optional = (
        "agents.io.mavlink",
        "agents.io.estimate",
        "agents.io.record",
        "agents.io.recording_source",
        "agents.io.tof_rig_bag",
    )
    inside = [
        f"{name}:{line} imports {target}"
        for name, path in modules.items()
        for target, in_function, line in _imports(path, modules)
        if in_function and not target.startswith(optional)
    ]
    assert not inside, inside
