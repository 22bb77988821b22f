"""The command line's one error path, and the failures that used to hang or pass silently."""

from __future__ import annotations

import pickle
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

import landing_env  # noqa: F401
from agents.cli import main
from estimation.errors import ConfigError
from landing_env.errors import PinnedDroneWarning
from tests.paths import ROOT

LANDING = ["evaluate", "landing", "--policy", "land-now", "--scenario", "bench-ss4"]


def test_config_error_survives_pickling_with_key_and_message() -> None:
    error = pickle.loads(pickle.dumps(ConfigError("tof.nosie", "unknown key")))
    assert isinstance(error, ConfigError)
    assert (error.key, error.detail, str(error)) == (
        "tof.nosie",
        "unknown key",
        "tof.nosie: unknown key",
    )
    assert pickle.loads(pickle.dumps(error.under("x"))).key == "x.tof.nosie"


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse
        code = int(exc.code or 0)
    err = capsys.readouterr().err.strip()
    return code, err


@pytest.mark.parametrize(
    ("argv", "names"),
    [
        ([*LANDING, "--episodes", "0"], "--episodes"),
        ([*LANDING, "--workers", "-3"], "--workers"),
        (["evaluate", "approach", "--workers", "0"], "--workers"),
        (["demo", "--config", "nope", "--no-timing"], "'nope' not found"),
        (["demo", "--episodes", "0"], "--episodes"),
        (
            ["train", "timing", "--config", "configs/bench-ss4.yaml"],
            "DeckLandingTiming-BenchSS4-v6",
        ),
        (["train", "timing", "--config", "no/such/file.yaml"], "does not exist"),
        (
            ["evaluate", "landing", "--policy", "timing-model", "--model", "no-such.zip",
             "--scenario", "bench-ss4", "--episodes", "1", "--workers", "1", "--no-progress"],
            "no-such.zip",
        ),
        (
            ["evaluate", "estimators", "--scenario", "paper-stewart", "--mode", "project",
             "--duration", "0.2", "--no-plots", "--set", "camera.mode=raytrace"],
            "camera.mode",
        ),
    ],
)  # fmt: skip
def test_every_user_error_exits_2_with_one_line_naming_it(
    argv: list[str], names: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, err = _run(argv, capsys)
    assert code == 2
    assert len(err.splitlines()) == 1, err
    assert names in err
    assert "Traceback" not in err


def test_a_typo_in_set_fails_fast_with_two_workers(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # a ConfigError raised in a worker process used to hang the pool forever
    argv = ["evaluate", "landing", "--policy", "land-now", "--scenario", "bench-ss4",
            "--episodes", "2", "--workers", "2", "--no-progress", "--out", str(tmp_path),
            "--set", "tof.nosie=vl53l1x"]  # fmt: skip
    code, err = _run(argv, capsys)
    assert code == 2
    assert "tof.nosie" in err and "unknown key" in err
    approach = ["evaluate", "approach", "--policy", "beacon-range", "--episodes", "2",
                "--workers", "2", "--no-progress", "--out", str(tmp_path),
                "--set", "tof.nosie=vl53l1x"]  # fmt: skip
    code, err = _run(approach, capsys)
    assert code == 2
    assert "tof.nosie" in err and "unknown key" in err


@pytest.mark.parametrize("policy", ["lander-model", "timing-model"])
def test_a_trained_policy_without_its_model_is_refused_alike_with_one_or_two_workers(
    policy: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    import ray

    errors = []
    for workers in ("1", "2"):
        argv = ["evaluate", "landing", "--policy", policy, "--scenario", "bench-ss4",
                "--episodes", "2", "--workers", workers, "--no-progress",
                "--out", str(tmp_path)]  # fmt: skip
        code, err = _run(argv, capsys)
        assert code == 2
        errors.append(err)
    assert errors[0] == errors[1]
    assert errors[0] == (
        f"deck-landing evaluate: error: --model: {policy} runs a trained model: give --model "
        "PATH, or a name `deck-landing list models` prints"
    )
    assert not ray.is_initialized()  # refused before any worker started


def test_model_show_takes_the_name_list_models_prints(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["model", "show", "timing_dqn_lookahead.zip"]) == 0
    assert '"env_id": "DeckLandingTiming-ShipSS6-v7"' in capsys.readouterr().out
    assert main(["model", "show", "timing_dqn_lookahead"]) == 0


@pytest.mark.parametrize(
    ("model", "message"),
    [
        ("README.md", "model: README.md is not a model (an SB3 .zip;"),
        ("nothing.zip", "nothing.zip: no such file, nor a shipped model"),
    ],
)
def test_model_show_refuses_what_is_not_a_model_in_one_line(
    model: str, message: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(ROOT)
    code, err = _run(["model", "show", model], capsys)
    assert code == 2
    assert err.startswith("deck-landing model: error: ") and message in err
    assert len(err.splitlines()) == 1


def test_a_model_name_is_taken_where_a_model_path_is() -> None:
    from agents.policies.registry import MODEL_DIR, find_model, require_model

    assert find_model("timing_dqn.zip") == MODEL_DIR / "timing_dqn.zip"
    assert require_model("timing-model", "timing_dqn") == str(MODEL_DIR / "timing_dqn.zip")
    with pytest.raises(ConfigError, match=r"^model: .*pyproject\.toml is not a model"):
        require_model("timing-model", str(ROOT / "pyproject.toml"))


def test_debug_shows_the_traceback_instead() -> None:
    with pytest.raises(ConfigError, match="nope"):
        main(["--debug", "demo", "--config", "nope", "--no-timing"])


def test_demo_runs_a_short_projected_episode_without_the_timing_part(tmp_path: Path) -> None:
    code = main(["demo", "--mode", "project", "--no-timing", "--out", str(tmp_path)])
    assert code == 0
    assert (tmp_path / "camera.mp4").stat().st_size > 0
    assert not (tmp_path / "timing_camera.mp4").exists()


@pytest.mark.slow
def test_demo_timing_part_flies_the_realistic_policy_under_realistic_sensing(
    tmp_path: Path, monkeypatch, capsys
) -> None:
    """`deck-landing demo --sensors realistic` flies the policy trained for realistic sensing
    (once it refused the ideal-trained timing-dqn)."""
    from agents.cli.demo import run_timing_demo
    from landing_env.config import SENSORS_ENV

    monkeypatch.setenv(SENSORS_ENV, "realistic")
    log = run_timing_demo(seed=4, out_dir=tmp_path)
    assert log is not None and log.final_info["outcome"] == "success"
    assert "predictive" in capsys.readouterr().out
    assert (tmp_path / "timing_camera.mp4").stat().st_size > 0


def test_pybullet_prints_nothing_when_an_env_is_made() -> None:
    code = (
        "import gymnasium as gym, landing_env; "
        "env = gym.make('DeckLanding-v2'); env.reset(seed=0); env.close()"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert "pybullet build time" not in done.stdout + done.stderr
    assert "argv[0]" not in done.stdout + done.stderr


def test_an_env_with_a_pinned_drone_says_it_cannot_land() -> None:
    with pytest.warns(PinnedDroneWarning, match="cannot land"):
        env = gym.make("DeckLanding-v2", config="paper-stewart")
    env.close()


def _help(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit):
        main([*argv, "--help"])
    return " ".join(capsys.readouterr().out.split())


def test_help_shows_the_defaults(capsys: pytest.CaptureFixture[str]) -> None:
    text = _help(["evaluate", "landing"], capsys)
    assert "--episodes EPISODES episodes per policy and scenario (default: 100)" in text
    assert "(default: None)" not in text and "(default: False)" not in text
    assert "--views VIEWS chessboard poses (CRHF: 20) (default: 20)" in _help(["calibrate"], capsys)


@pytest.mark.parametrize(
    ("argv", "has_sensors"),
    [
        (["list"], False),
        (["model", "show"], False),
        (["calibrate", "intrinsics"], False),
        (["calibrate", "tof"], False),
        (["calibrate"], True),
        (["demo"], True),
        (["evaluate", "landing"], True),
        (["estimate"], True),
    ],
)
def test_sensors_is_offered_only_where_it_acts(
    argv: list[str], has_sensors: bool, capsys: pytest.CaptureFixture[str]
) -> None:
    assert ("--sensors" in _help(argv, capsys)) is has_sensors


def test_one_flag_name_has_one_meaning_stages_is_a_number_the_rig_file_another_flag(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert "--stages STAGES climb stages" in _help(["calibrate"], capsys)
    tof = _help(["calibrate", "tof"], capsys)
    assert "--stages-file STAGES_FILE the rig file" in tof and "--stages " not in tof
    assert "in the simulator" not in _help([], capsys)


def test_install_refuses_to_replace_a_model_a_policy_flies_unless_forced(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    from agents.policies.registry import MODEL_DIR

    shipped = MODEL_DIR / "timing_dqn.zip"
    before = shipped.read_bytes()
    argv = ["train", "timing", "--config", str(ROOT / "configs/train/timing_dqn_predictive.yaml"),
            "--install", "--out", str(tmp_path)]  # fmt: skip
    code, err = _run(argv, capsys)
    assert code == 2 and len(err.splitlines()) == 1
    assert f"--install: would replace {shipped}" in err and "add --force" in err
    assert shipped.read_bytes() == before
    assert not (tmp_path / "best_model.zip").exists()  # refused before training
