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
from tests.paths import ROOT


def test_estimation_imports_no_simulator_or_rl_package() -> None:
    modules = [m.name for m in pkgutil.walk_packages(estimation.__path__, "estimation.")]
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
        "landing_env.privileged",  # SB3's policy classes: torch
    )
    inside = [
        f"{name}:{line} imports {target}"
        for name, path in modules.items()
        for target, in_function, line in _imports(path, modules)
        if in_function and not target.startswith(optional)
    ]
    assert not inside, inside


# ------------------------------------------------------------------ the folders within a package
#: each package's folders (and top-level modules), bottom up: a folder imports only itself and
#: the folders of the layers below its own; the folders of one layer do not import each other
FOLDER_LAYERS: dict[str, tuple[tuple[str, ...], ...]] = {
    "agents": (
        ("common",),  # model cards, the parallel runner, the user-error type
        ("policies",),  # both tasks' policies and their registry
        ("io",),  # recorded data, the MAVLink bridge (flies the simulator with a policy)
        ("training", "calibration", "evaluation"),  # the roles
        ("cli",),  # the command line: nothing imports it
    ),
    "landing_env": (
        ("errors", "_quiet", "resources"),
        # the parts' own settings and models: the waves and a ship's motion in them, the
        # physics, the deck's surface, the vision link
        ("config_limits", "physics", "scene", "vision_link", "waves"),
        ("guidance_gains",),  # the guidance's gains (the controller's PID gain by default)
        ("config_loading", "sensors", "stewart", "timing_config"),
        ("config",),  # the environment config: every section's settings
        ("sea", "touchdown"),  # the ship at sea (helideck mount, HMS); the contact
        # the deck ahead: onboard a descent ahead, from the ship's HMS seconds ahead
        ("anticipation",),
        ("scenarios", "world"),  # the scenario table; the simulated world
        ("calibration", "estimators"),
        # the committed descent (hold, guidance, timed descent, wave-off) that both tasks fly
        ("timing",),
        ("envs",),  # the landing task and the timing task, on one base environment
        ("privileged",),  # the SB3 policy class whose critic reads the privileged key
        ("__init__",),  # the package: registers the ids
    ),
}


def _folder(module: str) -> str:
    """The folder (or top-level module) of ``module`` within its package; ``__init__`` for
    the package itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _folder_layer(package: str) -> dict[str, int]:
    return {f: i for i, layer in enumerate(FOLDER_LAYERS[package]) for f in layer}


def _upward_folder_imports(package: str) -> list[str]:
    """Every import within ``package`` that runs up, or sideways within a layer, or touches a
    folder not declared in :data:`FOLDER_LAYERS` (imports inside functions counted)."""
    modules = _modules()
    layer = _folder_layer(package)
    wrong = []
    for name, path in modules.items():
        if name.split(".")[0] != package:
            continue
        here = _folder(name)
        for target, _, line in _imports(path, modules):
            there = _folder(target)
            if target.split(".")[0] != package or there == here:
                continue
            if here not in layer or there not in layer or layer[there] >= layer[here]:
                wrong.append(f"{name}:{line} imports {target}")
    return wrong


def test_agents_folders_import_only_the_layers_below_theirs() -> None:
    """agents: common < policies < io < training, calibration, evaluation < cli."""
    assert _upward_folder_imports("agents") == []


def test_landing_env_folders_import_only_the_layers_below_theirs() -> None:
    """landing_env: the waves below the deck's motion, the config below the sea and the timing
    task, the scenario table above the sea."""
    assert _upward_folder_imports("landing_env") == []


def test_the_agents_command_line_is_imported_by_nothing_and_common_by_every_role() -> None:
    modules = _modules()
    into_cli = [
        f"{name} imports {target}"
        for name, path in modules.items()
        if not name.startswith("agents.cli")
        for target, _, _ in _imports(path, modules)
        if target.startswith("agents.cli")
    ]
    assert into_cli == []
    layers = FOLDER_LAYERS["agents"]
    assert layers[0] == ("common",) and layers[-1] == ("cli",)
    roles = {"training", "evaluation", "cli"}
    assert not roles & {f for layer in layers[:2] for f in layer}, "policies under a role"


def test_every_declared_folder_is_in_its_package() -> None:
    for package, layers in FOLDER_LAYERS.items():
        for folder in (f for layer in layers for f in layer):
            path = ROOT / package / folder
            assert path.is_dir() or path.with_suffix(".py").is_file(), path


def test_agents_has_at_most_eight_top_level_entries() -> None:
    """agents/ is its roles (and models/), not a heap of modules."""
    entries = sorted(
        p.name
        for p in (ROOT / "agents").iterdir()
        if p.name != "__init__.py"
        and not p.name.startswith((".", "__pycache__"))
        and (p.is_dir() or p.suffix == ".py")
    )
    assert len(entries) <= 8, entries
