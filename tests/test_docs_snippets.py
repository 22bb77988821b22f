"""Every command of the README and the docs runs: each ```bash/```sh/```shell/```console and
```python block of README.md and docs/**/*.md (not the dated records in docs/experiments/) runs
in a fresh process, at reduced size, and a failing block fails the suite under its page:line
(a block whose reduced commands repeat an earlier block's runs once, under both page:lines).

How a block runs
  * Shell blocks run as ``bash -euo pipefail -c BLOCK`` with the test's virtualenv first on PATH
    (so ``deck-landing`` and ``python`` are its own); ``$ `` prompts of ```console blocks are
    stripped and their output lines dropped.  Python blocks run as a file in a fresh ``python``.
  * Each block runs in its own temporary folder that holds the repository's top-level entries
    as symbolic links (configs/, tests/, the packages), shrunk training configs, and small data
    under the placeholders' names (``SEED_DATA``); outputs go there, never into the repository.
  * A Python block whose first line is a path comment (``# my_estimators/tag_only.py``) is
    written to that path before it runs, so a later block of its page can import it; a
    ```toml block of the same page that declares the package's entry points is then installed
    there as pip lays it out (its ``.dist-info``), as the page's ``pip install -e .`` would.

What is reduced (``REDUCTIONS`` and ``shrink_train_config``, the one place for it)
  * ``--episodes N`` -> 1, ``--workers N`` -> 1, ``--seeds N`` -> 1, ``--duration N`` -> 1,
    ``--seconds N`` -> 2, rl-zoo3 given ``-n 32`` (its step budget: one rollout);
  * ``evaluate estimators`` and ``evaluate sweep`` get ``--duration 1`` (the sweep also
    ``--parameters tilt``: every condition runs in ``tests/agents/evaluation``),
    ``evaluate landing`` ``--workers 1 --episodes 1`` (at ``ship-ss5`` and ``ship-ss6`` also
    ``--seed 1000007``: there ``deck-oracle`` commits within a second and
    ``timing-dqn-lookahead`` within five, where the first seed has them wait up to ten, each
    second of the wait a few look-ahead descents), ``benchmarks.bench_fused_unseen``
    ``--duration 10`` and ``bridge`` ``--speed 0`` (not in real time) in front of their own
    flags (the written ones, reduced, win);
  * a list of alternatives as the docs write them (``tight|ihrcf|crhf``) -> its first;
  * ``configs/train/*.yaml`` -> copies with 32 steps (one rollout; 16 off policy), one
    evaluation of one episode and one checkpoint at the end, and small buffers, so ``train``
    still writes ``best_model.zip``, and an imitation stage of one teacher episode and one
    pass of each fit; a lander's episodes end after 8 simulated seconds;
  * placeholders name small files made once per run: ``DIR`` (the chessboard photos of
    tests/data and the simulated camera's calibration folder), ``photos/`` (the photos),
    ``my_camera/`` (the calibration folder), ``REC`` and
    ``REC.mcap`` and ``results/episode.mcap`` (a recorded demo episode), ``rig/``, ``rig.mcap``
    with ``rig.json`` and ``rig_stages.json`` (the simulated ToF rig).

What is not run
  A block right after ``<!-- not-run: REASON -->`` in the Markdown source (MyST renders the
  comment invisibly) is reported as a skipped test with that reason (``pytest -ra`` lists them).

Python blocks also run with deprecation warnings as errors, so a snippet that shows a
superseded API or id fails here.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from estimation.array_files import locked
from tests.paths import ROOT

#: the pages whose blocks run: the README and the docs, less the dated experiment records
_DOCS = (ROOT / "docs").rglob("*.md")
PAGES = [
    "README.md",
    *sorted(
        str(p.relative_to(ROOT))
        for p in _DOCS
        if not {"experiments", "_build"} & set(p.relative_to(ROOT / "docs").parts)
    ),
]
LANGUAGES = ("bash", "sh", "shell", "console", "python")
_FENCE = re.compile(
    r"^```(?P<lang>[\w-]+)[ \t]*\n(?P<code>.*?)^```[ \t]*$", re.DOTALL | re.MULTILINE
)
_NOT_RUN = re.compile(r"<!--\s*not-run:\s*(?P<reason>(?:(?!-->).)*?)\s*-->\s*\Z", re.DOTALL)
_PATH_COMMENT = re.compile(r"\A#\s*(?P<path>[\w./-]+\.py)\s*\n")
#: seconds one block may take before it fails as hung
BLOCK_TIMEOUT_S = 600

#: (pattern, replacement) applied in order to every shell block: the reduction rules
REDUCTIONS: tuple[tuple[str, str], ...] = (
    (r"--episodes \d+", "--episodes 1"),
    (r"--workers \d+", "--workers 1"),
    (r"--seeds \d+", "--seeds 1"),
    (r"--duration \d+(\.\d+)?", "--duration 1"),
    (r"--seconds \d+", "--seconds 2"),
    (r"\b(\w+)(?:\|\w+)+\b", r"\1"),  # tight|ihrcf|crhf -> tight
    (r"(python -m rl_zoo3\.train\b)", r"\1 -n 32"),
    (r"--input REC\b(?!\.)", "--input REC.mcap"),
    # the flags a command's default makes long, given first (a written value still wins)
    (r"(deck-landing evaluate estimators)\b", r"\1 --duration 1"),
    # one condition's four points (the k1 condition calibrates a camera at each of its twelve)
    (r"(deck-landing evaluate sweep)\b", r"\1 --duration 1 --parameters tilt"),
    (r"(deck-landing evaluate landing)\b", r"\1 --workers 1 --episodes 1"),
    # at the ship's sea states 5 and 6, a seed where the look-ahead policies commit soon
    (r"(deck-landing evaluate landing)\b(?=[^\n]*--scenario ship-ss[56]\b)", r"\1 --seed 1000007"),
    (r"(-m benchmarks\.bench_fused_unseen)\b", r"\1 --duration 10"),
    # the bridge as fast as it goes, not in real time
    (r"(deck-landing bridge)\b", r"\1 --speed 0"),
)


@dataclass(frozen=True)
class Block:
    """One fenced block of a page: where it starts, its language, its code and its marker."""

    page: str
    line: int
    lang: str
    code: str
    not_run: str | None

    @property
    def id(self) -> str:
        return f"{self.page}:{self.line}"


def blocks_of(text: str, page: str) -> list[Block]:
    """The shell and Python blocks of a Markdown text, each with the reason of a ``not-run``
    comment right before it (None when it runs)."""
    found = []
    for match in _FENCE.finditer(text):
        if match["lang"] not in LANGUAGES:
            continue
        marker = _NOT_RUN.search(text[: match.start()])
        line = text.count("\n", 0, match.start()) + 1
        reason = marker["reason"] if marker else None
        found.append(Block(page, line, match["lang"], match["code"], reason))
    return found


def shell_of(block: Block) -> str:
    """The block as bash runs it: prompts stripped, output dropped, the reductions applied."""
    code = block.code
    if block.lang == "console":
        kept, continued = [], False
        for line in code.splitlines():
            if line.startswith("$ "):
                kept.append(line[2:])
            elif continued:
                kept.append(line)
            else:
                continue
            continued = line.rstrip().endswith("\\")
        code = "\n".join(kept) + "\n"
    for pattern, replacement in REDUCTIONS:
        code = re.sub(pattern, replacement, code)
    return code


def shrink_train_config(source: Path, target: Path) -> None:
    """A training YAML cut to a few steps that still evaluates once and saves its best model:
    one rollout of 32 steps on policy, 16 steps (8 before learning starts) off policy."""
    doc = yaml.safe_load(source.read_text(encoding="utf-8"))
    algos = [v for k, v in doc.items() if k != "deck_landing" and isinstance(v, dict)]
    steps = 16 if any("learning_starts" in v for v in algos) else 32
    for key, value in doc.items():
        if key == "deck_landing":
            value["eval"] = {**value.get("eval", {}), "freq": steps, "episodes": 1}
            value["checkpoint_freq"] = steps
            value["vec_env"] = "dummy"
            if value.get("imitation") is not None:
                # one teacher episode, one pass of each fit
                value["imitation"] = {
                    **value["imitation"],
                    **dict.fromkeys(("iterations", "episodes", "epochs", "final_epochs"), 1),
                    "value_epochs": 1,
                }
        elif isinstance(value, dict):
            value.update(n_envs=1, n_timesteps=steps)
            if key.startswith("DeckLanding-"):
                # a lander's episodes (the teacher's, the evaluations') end after 8 s
                kwargs = value.setdefault("env_kwargs", {})
                kwargs["overrides"] = {
                    **kwargs.get("overrides", {}),
                    "simulation.max_episode_s": 8.0,
                }
            small_values = (("learning_starts", steps // 2), ("buffer_size", 1000), ("n_steps", 32))
            for name, small in small_values:
                if name in value:
                    value[name] = small
            if "batch_size" in value:
                value["batch_size"] = min(int(value["batch_size"]), 32)
    target.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")


ALL_BLOCKS = [block for page in PAGES for block in blocks_of((ROOT / page).read_text(), page)]


def _earlier_blocks(block: Block) -> list[Block]:
    """The Python blocks of the same page before ``block`` that define a module by path."""
    return [
        b
        for b in ALL_BLOCKS
        if b.page == block.page
        and b.line < block.line
        and b.lang == "python"
        and _PATH_COMMENT.match(b.code)
    ]


#: a shell comment to the end of its line (no quote after it)
_COMMENT = re.compile(r"(?:^|\s)#[^'\"\n]*$", re.MULTILINE)


def _commands(shell: str) -> tuple[str, ...]:
    """A shell block's commands without their comments, continued lines joined and blanks
    collapsed: what two blocks compare by."""
    joined = _COMMENT.sub("", shell).replace("\\\n", " ")
    return tuple(" ".join(line.split()) for line in joined.splitlines() if line.strip())


def runs_of(blocks: list[Block]) -> list[list[Block]]:
    """The blocks grouped by what runs, in their order: shell blocks whose reduced commands,
    modules written before them and marker are the same (a page repeating the README's
    commands) form one group, run once under all their ids; a Python block is its own."""
    groups: dict[object, list[Block]] = {}
    for block in blocks:
        if block.lang == "python":
            key: object = block.id
        else:
            earlier = tuple(b.code for b in _earlier_blocks(block))
            key = (_commands(shell_of(block)), earlier, block.not_run)
        groups.setdefault(key, []).append(block)
    return list(groups.values())


_CASES = [
    pytest.param(
        group[0],
        "+".join(block.id for block in group),
        id="+".join(block.id for block in group),
        marks=[pytest.mark.skip(reason=f"not-run: {group[0].not_run}")] if group[0].not_run else [],
    )
    for group in runs_of(ALL_BLOCKS)
]


def _environment(cwd: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(cwd)
    env["MPLBACKEND"] = "Agg"
    env.pop("PYTEST_XDIST_WORKER", None)
    return env


def _run(command: list[str], cwd: Path, what: str) -> subprocess.CompletedProcess[str]:
    """Run a block in a session of its own: a block that hangs fails, and every process it
    started (a make target's workers) ends with it."""
    with subprocess.Popen(
        command,
        cwd=cwd,
        env=_environment(cwd),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    ) as process:
        try:
            stdout, stderr = process.communicate(timeout=BLOCK_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate()
            raise
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)
    done = subprocess.CompletedProcess(command, process.returncode, stdout, stderr)
    assert done.returncode == 0, (
        f"{what} exited {done.returncode}\n--- stdout\n{done.stdout[-4000:]}"
        f"\n--- stderr\n{done.stderr[-4000:]}"
    )
    return done


def _link_repository(folder: Path) -> None:
    """The repository's top-level entries as links in ``folder``; configs/ as a real folder
    whose train/ holds shrunk copies; results/ left out (outputs land in the folder)."""
    for entry in ROOT.iterdir():
        if entry.name in {".git", "results", "configs"} or entry.name.startswith("."):
            continue
        (folder / entry.name).symlink_to(entry)
    (folder / ".venv").symlink_to(Path(sys.prefix))
    configs = folder / "configs"
    configs.mkdir()
    for entry in (ROOT / "configs").iterdir():
        if entry.name != "train":
            (configs / entry.name).symlink_to(entry)
    (configs / "train").mkdir()
    for entry in (ROOT / "configs" / "train").iterdir():
        target = configs / "train" / entry.name
        if entry.suffix == ".yaml":
            shrink_train_config(entry, target)
        else:
            target.symlink_to(entry)


_SEED_SCRIPT = """
import numpy as np
from agents.io.tof_rig import write_rig_recording
from agents.io.tof_rig_bag import write_rig_mcap
from estimation.tof_rig import RIG_FILE
from landing_env.calibration.tof_camera_sim import TofRigConfig, record_tof_rig_in_sim
from landing_env.config import load_config
import shutil

rig = record_tof_rig_in_sim(
    load_config("default"), TofRigConfig(stages=8, readings_per_stage=5), np.random.default_rng(7)
)
write_rig_recording("rig", rig.stages, rig.description)
write_rig_mcap("rig.mcap", rig.stages, rig.description, stages_file="rig.json")
shutil.copy("rig.json", "rig_stages.json")

# the simulated camera's calibration folder: its intrinsics, ToF calibration and mount
import json
from estimation.frames import R_BC
from landing_env.physics.quadrotor_params import QuadrotorParams

for name in ("intrinsics.json", "tof_camera.json"):
    shutil.copy(f"configs/calibration/{name}", f"my_camera/{name}")
mount = {
    "format": "deck-landing/camera-extrinsics",
    "format_version": 1,
    "r_bc": R_BC.tolist(),
    "t_bc_m": list(map(float, QuadrotorParams.from_yaml(None).camera_offset_b)),
}
with open("my_camera/extrinsics.json", "w") as f:
    json.dump(mount, f)
for name in ("intrinsics.json", "tof_camera.json", "extrinsics.json"):
    shutil.copy(f"my_camera/{name}", f"DIR/{name}")
"""

#: the placeholders' small data, made once per run: shell steps run in the seed folder
SEED_DATA = (
    "mkdir -p photos DIR my_camera results",
    "cp tests/data/opencv_chessboard/*.jpg photos/",
    "cp tests/data/opencv_chessboard/*.jpg DIR/",
    "deck-landing demo --mode project --no-timing --episodes 1 --record REC.mcap",
    "cp REC.mcap results/episode.mcap",
    "python seed_rig.py",
)
_SEEDS = ("photos", "DIR", "my_camera", "results", "REC.mcap", "rig", "rig.mcap", "rig.json")


def _make_seed_data(folder: Path) -> None:
    _link_repository(folder)
    (folder / "seed_rig.py").write_text(_SEED_SCRIPT, encoding="utf-8")
    _run(["bash", "-euo", "pipefail", "-c", "\n".join(SEED_DATA)], folder, "the seed data")
    shutil.copy(folder / "rig.json", folder / "rig_stages.json")


@pytest.fixture(scope="session")
def seed_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The placeholders' data, made by the CLI once per run: under pytest-xdist by the first
    worker that asks, in the run's shared temporary folder, while the others wait for it (the
    blocks only copy from it)."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        folder = tmp_path_factory.mktemp("doc-seed")
        _make_seed_data(folder)
        return folder
    folder = tmp_path_factory.getbasetemp().parent / "doc-seed"
    made = folder / ".made"
    with locked(folder):
        if not made.is_file():
            shutil.rmtree(folder, ignore_errors=True)  # a worker's failed attempt
            folder.mkdir()
            _make_seed_data(folder)
            made.touch()
    return folder


@pytest.fixture
def page_folder(seed_folder: Path, tmp_path: Path) -> Path:
    """A block's working folder: the repository linked, the seed data copied."""
    _link_repository(tmp_path)
    for name in (*_SEEDS, "rig_stages.json"):
        source = seed_folder / name
        if source.is_dir():
            shutil.copytree(source, tmp_path / name)
        else:
            shutil.copy(source, tmp_path / name)
    return tmp_path


_PROJECT_NAME = re.compile(r'^name = "(?P<name>[\w.-]+)"$', re.MULTILINE)
_ENTRY_POINTS = re.compile(
    r'^\[project\.entry-points\."(?P<group>[\w.-]+)"\]\n(?P<body>(?:\w+ = ".*"\n)+)', re.MULTILINE
)


def install_page_package(page: str, folder: Path) -> None:
    """A package a page declares (a ```toml block with entry points) installed in ``folder`` as
    pip lays it out: its dist-info beside the modules its path-named blocks wrote there."""
    text = (ROOT / page).read_text(encoding="utf-8")
    for match in _FENCE.finditer(text):
        name = _PROJECT_NAME.search(match["code"])
        if match["lang"] != "toml" or not name:
            continue
        info = folder / f"{name['name'].replace('-', '_')}-0.0.0.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(
            f"Metadata-Version: 2.1\nName: {name['name']}\nVersion: 0.0.0\n", encoding="utf-8"
        )
        groups = "".join(
            f"[{group['group']}]\n{group['body'].replace(chr(34), '')}"
            for group in _ENTRY_POINTS.finditer(match["code"])
        )
        (info / "entry_points.txt").write_text(groups, encoding="utf-8")


_WARNINGS_AS_ERRORS = "import warnings\nwarnings.simplefilter('error', DeprecationWarning)\n"


@pytest.mark.parametrize(("block", "where"), _CASES)
def test_the_documented_block_runs_in_a_fresh_process(
    block: Block, where: str, page_folder: Path
) -> None:
    for earlier in _earlier_blocks(block):
        path = page_folder / _PATH_COMMENT.match(earlier.code)["path"]
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(earlier.code, encoding="utf-8")
    if _earlier_blocks(block):
        install_page_package(block.page, page_folder)
    if block.lang == "python":
        named = _PATH_COMMENT.match(block.code)
        path = page_folder / (named["path"] if named else "snippet.py")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(block.code, encoding="utf-8")
        runner = page_folder / "run_snippet.py"
        runner.write_text(
            _WARNINGS_AS_ERRORS
            + f"import runpy\nrunpy.run_path({str(path)!r}, run_name='__main__')\n",
            encoding="utf-8",
        )
        _run([sys.executable, str(runner)], page_folder, where)
    else:
        _run(["bash", "-euo", "pipefail", "-c", shell_of(block)], page_folder, where)


# ------------------------------------------------------------------ the collector itself


def test_every_page_with_commands_is_collected() -> None:
    pages = {block.page for block in ALL_BLOCKS}
    assert {"README.md", "docs/getting-started.md", "docs/howto/train-policy.md"} <= pages
    assert not any(page.startswith("docs/experiments/") for page in pages)


def test_a_block_is_found_between_its_fences_with_its_line_and_marker() -> None:
    text = (
        "<!-- not-run: a -->\n```sh\nx\n```\n"
        "x\n```python\nprint(1)\n```\n<!-- not-run: runs until stopped -->\n\n"
        "```bash\nls\n```\n```text\nno\n```\n```console\n$ a \\\n  b\nout\n$ c\n```\n"
    )
    found = blocks_of(text, "p.md")
    assert [(b.line, b.lang, b.not_run) for b in found] == [
        (2, "sh", "a"),
        (6, "python", None),
        (11, "bash", "runs until stopped"),
        (17, "console", None),
    ]
    assert shell_of(found[3]) == "a \\\n  b\nc\n"


def test_blocks_that_run_the_same_commands_run_once_under_each_ones_place() -> None:
    command = "deck-landing evaluate landing --scenario bench-ss4 --episodes 200\n"
    blocks = [
        Block("README.md", 5, "bash", command, None),
        Block("b.md", 9, "console", "$ " + command.replace("200", "20 # twenty"), None),
        Block("b.md", 12, "bash", command, "runs until stopped"),
        Block("b.md", 15, "python", "print(1)\n", None),
        Block("c.md", 3, "python", "print(1)\n", None),
    ]
    groups = runs_of(blocks)
    assert [[block.id for block in group] for group in groups] == [
        ["README.md:5", "b.md:9"],
        ["b.md:12"],
        ["b.md:15"],
        ["c.md:3"],
    ]
    # every block of the pages is in exactly one test's id
    places = [place for case in _CASES for place in case.id.split("+")]
    assert sorted(places) == sorted(block.id for block in ALL_BLOCKS)


def test_the_reductions_shrink_counts_and_pick_the_first_alternative() -> None:
    block = Block("p.md", 1, "bash", "x --episodes 200 --workers 2 --estimator tight|crhf\n", None)
    assert shell_of(block) == "x --episodes 1 --workers 1 --estimator tight\n"


def test_a_commands_own_flags_follow_the_reductions_it_gets_so_that_they_win() -> None:
    written = (
        "deck-landing evaluate sweep --parameters k1\n"
        "deck-landing evaluate landing --scenario ship-ss6 --seed 5000000\n"
        "deck-landing evaluate landing --scenario ship-ss4\n"
        "deck-landing bridge --input REC --speed 2\n"
    )
    assert shell_of(Block("p.md", 1, "bash", written, None)).splitlines() == [
        "deck-landing evaluate sweep --duration 1 --parameters tilt --parameters k1",
        "deck-landing evaluate landing --seed 1000007 --workers 1 --episodes 1"
        " --scenario ship-ss6 --seed 5000000",
        "deck-landing evaluate landing --workers 1 --episodes 1 --scenario ship-ss4",
        "deck-landing bridge --speed 0 --input REC.mcap --speed 2",
    ]
