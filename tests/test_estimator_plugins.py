"""An estimator of another package joins through the entry-point group: the how-to
(docs/howto/own-estimator.md) run as written, each use in a fresh process."""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.paths import ROOT

HOWTO = ROOT / "docs" / "howto" / "own-estimator.md"


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", HOWTO.read_text(encoding="utf-8"), re.S)


def _run(args: list[str], path: list[Path], cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(str(p) for p in [*path, ROOT])}
    return subprocess.run(
        [sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


def _install(site: Path, module: str, entry_points: dict[str, str], name: str) -> None:
    """A distribution in ``site`` as pip lays it out: the package and its dist-info."""
    package, _, leaf = module.partition(".")
    (site / package).mkdir(parents=True, exist_ok=True)
    (site / package / "__init__.py").write_text("")
    (site / package / f"{leaf}.py").write_text(_blocks("python")[0])
    info = site / f"{name.replace('-', '_')}-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1.0\n")
    lines = "".join(f"{key} = {value}\n" for key, value in entry_points.items())
    (info / "entry_points.txt").write_text(f"[deck_landing.estimators]\n{lines}")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The how-to's package, installed from its own blocks (the module and the pyproject)."""
    toml = _blocks("toml")[0]  # read by hand: tomllib is not in Python 3.10
    name = re.search(r'^name = "(.+)"$', toml, re.M)
    group = toml.split('[project.entry-points."deck_landing.estimators"]\n')[1]
    points = dict(re.findall(r'^(\w+) = "(.+)"$', group.split("\n[")[0], re.M))
    assert name and points, toml
    site = tmp_path_factory.mktemp("site")
    (module,) = set(points.values())
    _install(site, module, points, name.group(1))
    return site


def test_the_howto_installs_an_estimator_that_the_command_line_evaluates(
    site: Path, tmp_path: Path
) -> None:
    done = _run(
        [
            "-m",
            "agents.cli",
            "evaluate",
            "estimators",
            "--scenario",
            "paper-stewart",
            "--estimators",
            "tag_only",
            "--mode",
            "project",
            "--duration",
            "0.5",
            "--no-plots",
            "--out",
            str(tmp_path / "out"),
        ],
        [site],
        tmp_path,
    )
    assert done.returncode == 0, done.stderr
    rows = [line for line in done.stdout.splitlines() if "tag_only" in line.lower()]
    assert rows, done.stdout
    assert "11/11" in rows[0]  # every frame of the 0.5 s estimated


#: runs each command line of ``COMMANDS`` through the CLI's ``main`` in one fresh process and
#: prints a line "exit-code<TAB>stdout<TAB>stderr" (repr'd) for each
_PARSE_EACH = """
import contextlib, io
from agents.cli import main
for argv in COMMANDS:
    out, err, code = io.StringIO(), io.StringIO(), None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exit:
            code = exit.code
    print("RESULT", repr((code, out.getvalue(), err.getvalue())))
"""


def test_the_installed_estimator_is_among_the_commands_choices(site: Path, tmp_path: Path) -> None:
    bridge = ["bridge", "--to", "udpout:127.0.0.1:14599", "--autopilot", "ardupilot"]
    commands = [["estimate", "--help"], ["evaluate", "landing", "--help"]]
    # the bridge's simulator names what it allows when refusing a name
    commands.append([*bridge, "--estimator", "nope"])
    done = _run(["-c", f"COMMANDS = {commands!r}\n{_PARSE_EACH}"], [site], tmp_path)
    assert done.returncode == 0, done.stderr
    results = [
        ast.literal_eval(line.removeprefix("RESULT "))
        for line in done.stdout.splitlines()
        if line.startswith("RESULT ")
    ]
    assert len(results) == len(commands), done.stdout
    for command, (code, out, _) in zip(commands[:2], results, strict=False):
        assert code == 0 and "tag_only" in out, command
    code, _, err = results[2]
    assert code == 2
    assert "'nope' is not allowed" in err and "'tag_only'" in err


def test_gym_make_observes_the_installed_estimator(site: Path, tmp_path: Path) -> None:
    code = _blocks("python")[1] + (
        "\nobservation, _, _, _, info = env.step(env.action_space.sample())"
        "\nassert info['estimates']['tag_only']['valid'], info['estimates']['tag_only']"
        "\nassert observation['deck_pose_valid'][0] == 1"
        "\nprint('observed', env.unwrapped.config.estimation.observed)"
    )
    done = _run(["-c", code], [site], tmp_path)
    assert done.returncode == 0, done.stderr
    assert "observed tag_only" in done.stdout


def test_the_howtos_script_registers_before_landing_env_is_imported(tmp_path: Path) -> None:
    first, second = _blocks("python")
    done = _run(["-c", f"{first}\n{second}\nprint('built', env.spec.id)"], [], tmp_path)
    assert done.returncode == 0, done.stderr
    assert "built DeckLanding-v2" in done.stdout


def test_a_plugin_that_fails_to_load_is_skipped_naming_it(tmp_path: Path) -> None:
    site = tmp_path / "site"
    (site / "broken_estimators").mkdir(parents=True)
    (site / "broken_estimators" / "__init__.py").write_text("raise RuntimeError('no numpy')\n")
    info = site / "broken_estimators-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken\nVersion: 0.1.0\n")
    (info / "entry_points.txt").write_text(
        "[deck_landing.estimators]\nbroken = broken_estimators\n"
    )
    code = (
        "from estimation.registry import REGISTRY, load_plugins\n"
        "print(load_plugins(), sorted(REGISTRY))\n"
    )
    done = _run(["-c", code], [site], tmp_path)
    assert done.returncode == 0, done.stderr
    assert "estimator plugin 'broken' (broken_estimators) skipped: RuntimeError: no numpy" in (
        done.stderr
    )
    assert "[] ['atda', 'crhf', 'ihrcf', 'tight']" in done.stdout
