"""Mutation testing of the modules a user relies on beyond the simulator, with mutmut.

``tools/mutation.yaml`` keeps the one mapping: the modules to mutate (``paths``, globs); for
each module, the test files that import it (``tests``, derived by ``map``); and, for the
modules whose mapped files fly episodes or run a filter over minutes of sea, the quick unit
tests a run takes instead (``chosen``, kept by hand: files or pytest node ids among the mapped
files, so that the score is a lower bound of the score on all of them). Each module runs in its
own folder ``results/mutation/<module>/`` (links to the packages, a ``pyproject.toml`` with the
module's ``[tool.mutmut]`` section), so that mutmut collects its coverage from that module's
tests alone and runs each mutant against the tests that reached the mutated function. The
report of a run is ``docs/reference/mutation.md``.

    python tools/mutation.py map            # derive tests: from the imports in tests/
    python tools/mutation.py map --check    # refuse a mapping that is out of date
    python tools/mutation.py run agents/io/timesync.py agents/io/mavlink.py --workers 2
    python tools/mutation.py run 'agents/io/*'            # every mapped module under agents/io
    python tools/mutation.py run agents/io/pacing.py --survivors   # after new tests
    python tools/mutation.py summary 'agents/io/*'        # score and survivors with their diffs
    python tools/mutation.py run estimation/fusion/model.py --all-tests   # every mapped file
    python tools/mutation.py run --runs results/mutation-full   # every module, a fresh folder
"""

from __future__ import annotations

import argparse
import ast
import fnmatch
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
MAP_FILE = ROOT / "tools" / "mutation.yaml"
RUNS = ROOT / "results" / "mutation"
# what a module's tests need next to the mutated package: the code, the configs, the tests
LINKED = ("agents", "estimation", "landing_env", "configs", "tests", "benchmarks", "docs")
LINKED_FILES = ("README.md",)  # the docs' snippets are tested from the README too
SOURCES = ("agents", "estimation", "landing_env")
#: mutmut's wall-clock limit of a mutant: this many times its tests' measured time (plus 1 s)
TIMEOUT_MULTIPLIER = 60.0
HEADER = """\
# Mutation testing (tools/mutation.py, make mutation): the modules mutated and, for each, the
# test files that import it. `paths` is kept by hand; `tests` is derived from the imports in
# tests/ by `python tools/mutation.py map` (tests/test_mutation_map.py checks it is current).
# `chosen` is kept by hand: for a module whose mapped files fly episodes or run the filter over
# minutes of sea, the quick ones among them (files or pytest node ids) that a run takes.
"""


def module_name(path: str) -> str:
    """``agents/io/timesync.py`` -> ``agents.io.timesync``."""
    return path.removesuffix(".py").replace("/", ".")


def reexports(package: str) -> dict[str, str]:
    """What a package's ``__init__`` takes from its own modules, name -> module: so that
    ``from estimation.fusion import DeckFusion`` imports ``estimation.fusion.filter``."""
    init = ROOT / package.replace(".", "/") / "__init__.py"
    if not init.is_file():
        return {}
    names: dict[str, str] = {}
    for node in ast.parse(init.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.ImportFrom):
            source = node.module or ""
            if node.level:  # ``from .filter import X`` inside the package
                source = ".".join(filter(None, (package, source)))
            if source.startswith(f"{package}."):
                names.update({alias.asname or alias.name: source for alias in node.names})
    return names


def imported_modules(test_file: Path) -> set[str]:
    """Every module a test file imports: the ``from package import module`` form included, and
    the module a package's ``__init__`` takes a name from, for ``from package import Name``."""
    tree = ast.parse(test_file.read_text(encoding="utf-8"))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
            taken = reexports(node.module)
            found.update(taken[alias.name] for alias in node.names if alias.name in taken)
    return found


def selected_modules(paths: list[str]) -> list[str]:
    """The module files the globs in ``paths`` name (package ``__init__`` files left out)."""
    modules: set[str] = set()
    for pattern in paths:
        matches = [p.relative_to(ROOT).as_posix() for p in ROOT.glob(pattern)]
        if not matches:
            raise SystemExit(f"tools/mutation.yaml: paths entry {pattern!r} names no file")
        modules.update(m for m in matches if not m.endswith("__init__.py"))
    return sorted(modules)


def derive_tests(paths: list[str]) -> dict[str, list[str]]:
    """For each selected module, the test files that import it, sorted. A module no test
    imports takes the test files that import a module of the packages that imports it (one
    step: not the importers of its importers)."""
    imports = {
        f.relative_to(ROOT).as_posix(): imported_modules(f)
        for f in sorted((ROOT / "tests").rglob("test_*.py"))
    }
    importers: dict[str, set[str]] = {}
    for source in SOURCES:
        for code in sorted((ROOT / source).rglob("*.py")):
            name = module_name(code.relative_to(ROOT).as_posix())
            for imported in imported_modules(code):
                importers.setdefault(imported, set()).add(name)
    derived: dict[str, list[str]] = {}
    for module in selected_modules(paths):
        wanted = {module_name(module)}
        tests = [test for test, names in imports.items() if wanted & names]
        if not tests:
            wanted = importers.get(module_name(module), set())
            tests = [test for test, names in imports.items() if wanted & names]
        derived[module] = tests
    return derived


def load_map() -> dict:
    return yaml.safe_load(MAP_FILE.read_text(encoding="utf-8"))


def write_map(paths: list[str], tests: dict[str, list[str]], picked: dict[str, list[str]]) -> None:
    body = yaml.safe_dump(
        {"paths": paths, "tests": tests, "chosen": picked}, sort_keys=False, width=100
    )
    MAP_FILE.write_text(HEADER + body, encoding="utf-8")


def check_chosen(picked: dict[str, list[str]], tests: dict[str, list[str]]) -> list[str]:
    """What is wrong with the hand-kept ``chosen`` section: a module not mapped, an empty
    choice, a test outside the module's mapped files or a file that does not exist."""
    problems = []
    for module, choice in picked.items():
        if module not in tests:
            problems.append(f"chosen: {module} is not a mapped module")
            continue
        if not choice:
            problems.append(f"chosen: {module} chooses no test (leave it out to run all)")
        for test in choice:
            path, _, name = test.partition("::")
            if path not in tests[module]:
                problems.append(f"chosen: {module}: {test} is not among its mapped test files")
            elif name and name not in test_names(ROOT / path):
                problems.append(f"chosen: {module}: {path} has no test {name}")
    return problems


def has_functions(module: Path) -> bool:
    """Whether a module defines a function or method: what mutmut mutates."""
    tree = ast.parse(module.read_text(encoding="utf-8"))
    return any(isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef) for n in ast.walk(tree))


def test_names(test_file: Path) -> set[str]:
    """The test functions a test file defines at its top level."""
    tree = ast.parse(test_file.read_text(encoding="utf-8"))
    return {
        node.name
        for node in tree.body
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.name.startswith("test")
    }


def cmd_map(args: argparse.Namespace) -> int:
    mapping = load_map()
    derived = derive_tests(mapping["paths"])
    picked = mapping.get("chosen") or {}
    problems = check_chosen(picked, derived)
    if problems:
        print("tools/mutation.yaml: " + "; ".join(problems))
        return 1
    if args.check:
        if derived != mapping["tests"]:
            stale = sorted(
                m
                for m in derived.keys() | mapping["tests"].keys()
                if derived.get(m) != mapping["tests"].get(m)
            )
            print(
                f"tools/mutation.yaml: tests of {', '.join(stale)} out of date; "
                "run python tools/mutation.py map"
            )
            return 1
        return 0
    write_map(mapping["paths"], derived, picked)
    untested = [m for m, tests in derived.items() if not tests]
    print(f"{len(derived)} modules, {len(untested)} imported by no test: {', '.join(untested)}")
    return 0


def named_modules(patterns: list[str], tests: dict[str, list[str]]) -> list[str]:
    """The mapped modules the command-line patterns name; a pattern naming none is refused."""
    if not patterns:
        return list(tests)
    picked: list[str] = []
    for pattern in patterns:
        hits = [m for m in tests if fnmatch.fnmatch(m, pattern) or m == pattern]
        if not hits:
            raise SystemExit(f"module {pattern!r} is not in tools/mutation.yaml (paths and tests)")
        picked.extend(h for h in hits if h not in picked)
    return picked


def prepare(module: str, test_files: list[str], runs: Path = RUNS) -> Path:
    """The module's run folder under ``runs``: links to the packages and its own
    ``[tool.mutmut]`` section."""
    run_dir = runs / module_name(module)
    run_dir.mkdir(parents=True, exist_ok=True)
    for name in LINKED:
        link = run_dir / name
        if not link.is_symlink():
            link.symlink_to(ROOT / name, target_is_directory=True)
    for name in LINKED_FILES:
        link = run_dir / name
        if not link.is_symlink():
            link.symlink_to(ROOT / name)
    settings = {
        "source_paths": list(SOURCES),
        "only_mutate": [module],
        "also_copy": ["configs", "benchmarks", "docs", *LINKED_FILES],
        "pytest_add_cli_args_test_selection": test_files,
        "pytest_add_cli_args": ["-p", "no:cacheprovider", "-x", "-q"],
        "use_git_change_detection": False,
        "mutate_only_covered_lines": False,
        # mutmut stops a mutant's tests after 15 times their measured time plus 1 s, wall
        # clock; eight workers on two cores run each test about four times slower than the
        # measuring pass did, so a mutant whose tests merely ran slow would count as killed
        "timeout_multiplier": TIMEOUT_MULTIPLIER,
    }
    lines = ["", "[tool.mutmut]"]
    for key, value in settings.items():
        if isinstance(value, bool):
            lines.append(f"{key} = {'true' if value else 'false'}")
        elif isinstance(value, float):
            lines.append(f"{key} = {value}")
        else:
            lines.append(f"{key} = [{', '.join(repr(v).replace(chr(39), chr(34)) for v in value)}]")
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8") + "\n".join(lines) + "\n"
    (run_dir / "pyproject.toml").write_text(text, encoding="utf-8")
    return run_dir


def mutmut(run_dir: Path, *argv: str, capture: bool = False) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONPATH": ""}
    exe = Path(sys.executable).with_name("mutmut")
    return subprocess.run(
        [str(exe), *argv], cwd=run_dir, env=env, text=True, capture_output=capture, check=False
    )


def chosen_tests(
    module: str, picked: list[str] | None, mapped: list[str], kept: list[str] | None = None
) -> list[str]:
    """The tests ``--tests`` picks (files or pytest node ids of the module's mapped files), else
    the module's ``chosen`` tests of the map (``kept``), else the mapped files; a test outside
    them is refused, so that a run on a choice stays a lower bound of the run on all of them."""
    if not picked:
        return kept or mapped
    outside = [test for test in picked if test.split("::")[0] not in mapped]
    if outside:
        raise SystemExit(
            f"--tests: {', '.join(outside)} not among the test files of {module} "
            f"({', '.join(mapped)})"
        )
    return picked


def cmd_run(args: argparse.Namespace) -> int:
    mapping = load_map()
    tests = mapping["tests"]
    kept = {} if args.all_tests else (mapping.get("chosen") or {})
    runs = args.runs.resolve()
    failed = 0
    started_all = time.monotonic()
    for module in named_modules(args.modules, tests):
        if not tests[module]:
            print(f"{module}: no test imports it; not run")
            continue
        if not has_functions(ROOT / module):
            # mutmut mutates code inside functions only, and stops with an error on a
            # module without any after running its tests
            print(f"{module}: no function to mutate; not run")
            continue
        test_files = chosen_tests(module, args.tests, tests[module], kept.get(module))
        run_dir = prepare(module, test_files, runs)
        started = time.monotonic()
        # without names mutmut tests the mutants that have no result yet: every one on the
        # first run, then those of the functions changed since (it keeps the others' results)
        names = args.mutants or []
        if args.survivors:
            found = statuses(run_dir) if (run_dir / "mutants").is_dir() else {}
            names = [n for n, s in found.items() if s in ("survived", "no tests")]
            if not names:
                print(f"== {module}: no survivor to run again", flush=True)
                continue
        what = "test files" if test_files == tests[module] else "chosen tests"
        print(f"== {module}: mutmut over {len(test_files)} {what}", flush=True)
        result = mutmut(run_dir, "run", "--max-children", str(args.workers), *names)
        failed += result.returncode != 0
        print(
            f"== {module}: {time.monotonic() - started:.0f} s "
            f"({time.monotonic() - started_all:.0f} s in all)",
            flush=True,
        )
    return 1 if failed else 0


RUNS_HELP = (
    "the folder of the modules' run folders (default results/mutation): another one for a "
    "run from scratch that keeps the results of the default"
)
STATUS = re.compile(r"^\s*(\S+): (.+)$")


def statuses(run_dir: Path) -> dict[str, str]:
    out = mutmut(run_dir, "results", "--all", "true", capture=True).stdout
    return {m[1]: m[2] for m in map(STATUS.match, out.splitlines()) if m}


def cmd_summary(args: argparse.Namespace) -> int:
    tests = load_map()["tests"]
    total: dict[str, int] = {}
    for module in named_modules(args.modules, tests):
        run_dir = args.runs.resolve() / module_name(module)
        if not (run_dir / "mutants").is_dir():
            print(f"## {module}: not run")
            continue
        found = statuses(run_dir)
        counts: dict[str, int] = {}
        for status in found.values():
            counts[status] = counts.get(status, 0) + 1
            total[status] = total.get(status, 0) + 1
        print(f"## {module}: {score_line(counts)}")
        for name, status in found.items():
            if status not in ("killed", "caught by type check"):
                print(mutmut(run_dir, "show", name, capture=True).stdout)
    print(f"## all: {score_line(total)}")
    return 0


def score_line(counts: dict[str, int]) -> str:
    mutants = sum(counts.values())
    killed = counts.get("killed", 0) + counts.get("timeout", 0)
    score = 100.0 * killed / mutants if mutants else float("nan")
    parts = ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))
    return f"{killed}/{mutants} killed ({score:.1f} %): {parts}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("map", help="derive each module's test files from the imports in tests/")
    p.add_argument("--check", action="store_true", help="refuse a mapping that is out of date")
    p.set_defaults(func=cmd_map)
    p = sub.add_parser("run", help="mutate the modules, each against its own test files")
    p.add_argument("modules", nargs="*", help="module paths or globs (default: every module)")
    p.add_argument(
        "--workers", type=int, default=8, help="mutants tested at once (default 8: many wait)"
    )
    p.add_argument(
        "--all-tests",
        action="store_true",
        help="run each module against all its mapped test files, not its chosen ones",
    )
    p.add_argument(
        "--mutants", nargs="+", help="only these mutant names (mutmut's, globs), run again"
    )
    p.add_argument(
        "--survivors",
        action="store_true",
        help="run again the mutants that survived (or had no test) last time: after new tests",
    )
    p.add_argument(
        "--tests",
        nargs="+",
        help="run against these of the module's mapped test files (or pytest node ids in "
        "them) alone, instead of its chosen ones: a lower bound of the score, since a "
        "mutant they kill all the mapped files kill too; a module's folder keeps one "
        "selection: another resets that folder's results",
    )
    p.add_argument("--runs", type=Path, default=RUNS, help=RUNS_HELP)
    p.set_defaults(func=cmd_run)
    p = sub.add_parser("summary", help="score and the diff of each mutant not killed")
    p.add_argument("modules", nargs="*", help="module paths or globs (default: every module)")
    p.add_argument("--runs", type=Path, default=RUNS, help=RUNS_HELP)
    p.set_defaults(func=cmd_summary)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
