"""The evaluation runner: Ray gives the serial results seed by seed, fails fast on a bad
config, reports a crashed worker's seed and keeps the rest, writes as it goes, resumes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import ray

from agents.common.parallel import batch_session
from agents.evaluation.landing import run_policy
from agents.evaluation.runner import EpisodeTask, run_episodes
from estimation.errors import ConfigError
from tests.paths import ROOT

TOY = "tests.runner_toy:TOY"


@pytest.fixture(scope="module")
def ray_session():
    with batch_session(2, None):
        yield
    assert not ray.is_initialized()


def test_ray_gives_the_serial_results_seed_by_seed(ray_session: None) -> None:
    serial = run_policy("land-now", "bench-ss4", 3, workers=1)
    parallel = run_policy("land-now", "bench-ss4", 3, workers=2)
    assert (serial.backend, parallel.backend) == ("serial", "ray")
    assert parallel.records == serial.records
    assert [r.seed for r in parallel.records] == [1_000_000, 1_000_001, 1_000_002]


def test_a_bad_config_fails_fast_with_its_message(ray_session: None) -> None:
    with pytest.raises(ConfigError, match=r"tof\.nosie"):
        run_policy("land-now", "bench-ss4", 4, workers=2, extra_overrides={"tof.nosie": 1})
    task = EpisodeTask(TOY, "p", "s", {"bad_in_worker": True})
    with pytest.raises(ConfigError, match=r"camera\.mode"):  # raised inside a Ray worker
        run_episodes(task, list(range(4)), workers=2)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_workers_user_error_reaches_the_driver_as_its_own_one_line(
    workers: int, ray_session: None
) -> None:
    task = EpisodeTask(TOY, "p", "s", {"bad_in_worker": True})
    with pytest.raises(ConfigError) as error:
        run_episodes(task, list(range(4)), workers=workers)
    # no Ray traceback, actor id or colour codes: the same line as without Ray
    assert str(error.value) == "camera.mode: 'raytrace' is not allowed"
    assert type(error.value) is ConfigError


@pytest.mark.parametrize("workers", [1, 2])
def test_a_crashed_episode_is_reported_with_its_seed_and_the_rest_kept(
    workers: int, ray_session: None
) -> None:
    options = {"raise_seed": 2} if workers == 1 else {"crash_seed": 2, "raise_seed": 4}
    result = run_episodes(EpisodeTask(TOY, "p", "s", options), list(range(6)), workers=workers)
    failed = [f.seed for f in result.failures]
    assert failed == ([2] if workers == 1 else [2, 4])
    assert [r.seed for r in result.records] == [s for s in range(6) if s not in failed]
    assert "blew up" in result.failures[-1].error


def test_results_are_written_as_they_arrive_and_resume_skips_finished_seeds(
    tmp_path: Path, ray_session: None
) -> None:
    path = tmp_path / "episodes.jsonl"
    task = EpisodeTask(TOY, "p", "s", {"crash_seed": 3})
    first = run_episodes(task, list(range(5)), workers=2, results_path=path)
    assert [f.seed for f in first.failures] == [3]
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert sorted(d["seed"] for d in lines) == [0, 1, 2, 4]
    # resume: only the missing seed runs (now without the crash)
    again = run_episodes(
        EpisodeTask(TOY, "p", "s", {}), list(range(5)), workers=1, results_path=path, resume=True
    )
    assert again.resumed == 4 and not again.failures
    assert [r.seed for r in again.records] == [0, 1, 2, 3, 4]
    assert len(path.read_text().splitlines()) == 5


def test_a_session_keeps_its_workers_and_their_env_from_run_to_run(ray_session: None) -> None:
    def workers(options: dict) -> set[tuple[str, str]]:
        task = EpisodeTask(TOY, "p", "s", {"report_worker": True, **options})
        result = run_episodes(task, list(range(6)), workers=2)
        assert [r.seed for r in result.records] == list(range(6)) and not result.failures
        return {tuple(r.failed_checks.split(":")) for r in result.records}

    first, again = workers({}), workers({})
    assert len({pid for pid, _ in first}) == 2  # both workers ran episodes
    assert again == first  # the same processes, the same environments: no start-up again
    other = workers({"variant": 1})  # another task: the same processes, new environments
    assert {pid for pid, _ in other} == {pid for pid, _ in first}
    assert not other & first  # no (process, environment) pair again


def test_tasks_after_episodes_in_one_session_get_the_idle_workers_cpus(
    ray_session: None,
) -> None:
    from agents.common.parallel import map_tasks
    from tests.runner_toy import square

    run_episodes(EpisodeTask(TOY, "p", "s", {}), list(range(4)), workers=2)
    # the two idle actors hold both CPUs of the batch: the tasks must not wait for them
    assert map_tasks(square, [1, 2, 3], workers=2) == [1, 4, 9]


def test_local_workers_run_at_the_users_priority(ray_session: None) -> None:
    import os

    @ray.remote(num_cpus=1)
    def niceness() -> int:
        return os.nice(0)

    # Ray's default is nice 15; the former pool's workers ran at the caller's priority
    assert ray.get(niceness.remote()) == os.nice(0)


def test_the_shared_record_types_live_in_a_leaf_module() -> None:
    import ast

    root = ROOT / "agents" / "evaluation"

    def imported(name: str) -> set[str]:
        tree = ast.parse((root / name).read_text())
        return {
            node.module
            for node in ast.walk(tree)
            if isinstance(node, ast.ImportFrom) and node.module
        }

    assert not {m for m in imported("records.py") if m.startswith("agents")}
    # the figures read the records, not the estimator run: no estimators <-> plots cycle
    for figures in ("plots.py", "fusion_plot.py"):
        assert "agents.evaluation.estimators" not in imported(figures)


@pytest.mark.slow
def test_a_sweep_on_ray_gives_the_serial_points(ray_session: None, tmp_path: Path) -> None:
    import numpy as np

    from agents.evaluation.sweep import SweepSettings, run_sweep

    def sweep(workers: int) -> list:
        return run_sweep(
            SweepSettings(
                duration_s=0.3, parameters=("height",), heights_m=(1.0, 2.0),
                camera_mode="project", progress=False, workers=workers,
                calibration_dir=str(tmp_path / f"cal{workers}"),
            )
        )  # fmt: skip

    serial, parallel = sweep(1), sweep(2)
    assert [(p.parameter, p.value) for p in parallel] == [(p.parameter, p.value) for p in serial]
    for a, b in zip(serial, parallel, strict=True):
        for name in a.metrics:
            # Ray's workers run BLAS on one thread: equal to round-off
            np.testing.assert_allclose(a.metrics[name].mae, b.metrics[name].mae, rtol=1e-9)


@pytest.mark.slow
def test_the_two_calibrations_on_ray_give_the_serial_files(
    ray_session: None, tmp_path: Path
) -> None:
    from agents.calibration.simulated import run_calibration

    runs = {
        w: run_calibration(out_dir=tmp_path / str(w), views=4, stages=4, progress=False, workers=w)
        for w in (1, 2)
    }
    # the same draws; Ray's workers run BLAS/OpenCV on one thread, which may change the last
    # bits of a least-squares sum (OpenCV's multi-threaded sums are not even repeatable run
    # to run), and an LM solve carries that to 1e-9..1e-11 on a coefficient near zero
    # (k1 = -2.6e-4), hence a tolerance far below any calibration error: 1e-6 relative
    # (5e-4 px on fx) or 1e-6 absolute (a chessboard k1 is known to ~1e-3, a range to ~1 mm)
    for name in ("intrinsics", "tof_camera"):
        serial = json.loads(runs[1].files[name].read_text())
        on_ray = json.loads(runs[2].files[name].read_text())
        _assert_close(serial, on_ray, name)


def _assert_close(a: object, b: object, where: str) -> None:
    import numpy as np

    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for key in a:
            _assert_close(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_close(x, y, f"{where}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert np.isclose(a, b, rtol=1e-6, atol=1e-6, equal_nan=True), (where, a, b)
    else:
        assert a == b, (where, a, b)
