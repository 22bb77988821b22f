"""Each maintained benchmark runs at its smallest size and prints or writes its figures.

The benchmarks are scripts, not a package that tests import: each runs here in a subprocess,
``python -m benchmarks.<name>`` with the repository on the path, in a temporary folder, at a
size of seconds.  Their figures are not checked, only that the run ends and reports them.
"""

from __future__ import annotations

import ast
import csv
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.paths import ROOT

#: the maintained benchmarks, each named in docs/reference/simulator.md and run by `make bench`
MAINTAINED = (
    "bench_env_speed",
    "bench_estimators",
    "bench_mavlink_bridge",
    "bench_recording_load",
    "bench_corner_noise",
    "bench_fused_unseen",
    "bench_paper_setup",
    "fuzz_soak",
    "bench_onboard_lookahead",
    "bench_decision_latency",
    "bench_deck_forecast",
)
#: modules of benchmarks/ that a maintained benchmark imports (not run on their own)
HELPERS = ("fused_motions", "fused_replay")


def run_benchmark(name: str, *args: str, cwd: Path, expect_rc: int = 0) -> str:
    """Run ``benchmarks/<name>.py`` with ``args`` in ``cwd``; its stdout (and stderr)."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    result = subprocess.run(
        [sys.executable, "-m", f"benchmarks.{name}", *args],
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": path},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == expect_rc, result.stdout[-2000:] + result.stderr[-4000:]
    return result.stdout + result.stderr


def test_benchmarks_holds_the_maintained_benchmarks_and_their_helpers_only() -> None:
    found = {p.stem for p in (ROOT / "benchmarks").glob("*.py")}
    assert found == set(MAINTAINED) | set(HELPERS)


def test_each_maintained_benchmark_is_listed_in_the_docs_and_run_by_make_bench() -> None:
    listing = (ROOT / "docs" / "reference" / "simulator.md").read_text(encoding="utf-8")
    bench = (ROOT / "Makefile").read_text(encoding="utf-8").split("\nbench:", 1)[1]
    bench = bench.split("\n\n", 1)[0]
    for name in MAINTAINED:
        assert f"`{name}.py`" in listing, name
        assert f"-m benchmarks.{name}\n" in bench + "\n", name


def test_no_test_imports_from_benchmarks() -> None:
    for path in (ROOT / "tests").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:
                continue
            assert not any(n.split(".")[0] == "benchmarks" for n in names), path.relative_to(ROOT)


def test_recording_load_writes_its_table_of_load_times(tmp_path: Path) -> None:
    out = tmp_path / "load.md"
    run_benchmark(
        "bench_recording_load", "--hours", "0.02", "--rate-hz", "10", "--out", str(out),
        cwd=tmp_path,
    )  # fmt: skip
    text = out.read_text()
    assert "721 samples" in text  # 0.02 h at 10 Hz, both ends
    rows = [line for line in text.splitlines() if line.startswith("| ") and "seconds" not in line]
    assert len(rows) == 6
    assert all(math.isfinite(float(row.split("|")[2])) for row in rows)


def test_estimators_prints_the_cost_of_every_estimator_and_of_detection(tmp_path: Path) -> None:
    out = run_benchmark("bench_estimators", "--frames", "5", "--detect-frames", "2", cwd=tmp_path)
    assert "per-frame cost" in out
    for row in ("atda", "ihrcf", "crhf", "tight", "tight+kf", "detect 512x512"):
        assert re.search(rf"│ {re.escape(row)} +│ +\d+ │", out), row


@pytest.mark.slow
def test_env_speed_prints_both_tables(tmp_path: Path) -> None:
    out = run_benchmark(
        "bench_env_speed", "--seconds", "0.5", "--render-seconds", "0.5", "--height-steps", "2",
        "--renderers", "planar", "--sensors", "ideal", "--envs", "1", cwd=tmp_path,
    )  # fmt: skip
    assert "render mode by height" in out and "DeckLanding-v2 speed" in out
    rows = re.findall(
        r"^ideal (project|render)/\w+ x1: 10 steps.*: ([\d.]+) of the physics", out, re.M
    )
    assert len(rows) == 4 and all(0.0 < float(share) < 1.0 for _, share in rows)
    assert re.search(r"^DeckLandingTiming-BenchSS4-v6: \d+ wait decisions/s by CPU", out, re.M)
    timing_row = r"│ +DeckLandingTiming-BenchSS4-v6 │ +default \(wait decisions\) │.*│ +([\d.]+) │$"
    timing = re.search(timing_row, out, re.M)
    assert timing is not None and 0.0 < float(timing.group(1)) < 1.0
    # the peers are rows of their own when installed, else named as missing
    for peer in ("gym-pybullet-drones HoverAviary", "PyFlyt QuadX-Hover-v4"):
        assert re.search(rf"(│ +peer │ +{peer}|not installed.*{peer})", out), peer


@pytest.mark.slow
def test_env_speed_profiles_a_step_in_each_case(tmp_path: Path) -> None:
    out = run_benchmark(
        "bench_env_speed", "--profile", "--seconds", "0.5", "--profile-top", "12", cwd=tmp_path
    )
    for case in ("truth observed", "tight:", "tight, realistic sensing"):
        for order in ("cumulative", "own"):
            assert re.search(rf"project mode, {case}.*10 steps, top 12 by {order}", out), case
        assert re.search(rf"project mode, {case}.*[\d.]+ CPU ms/step without the profiler", out)
    assert re.search(r"│ landing_env/world\.py:\d+\(step\) +│ +1\.0 │", out)
    # the controller runs once a physics sub-step: 12 calls a step, high in the own-time table
    assert re.search(r"│ landing_env/physics/controller\.py:\d+\(update_floats\) +│ +12\.0 │", out)


@pytest.mark.slow
def test_env_speed_replays_the_pybullet_calls_of_each_step_as_recorded(tmp_path: Path) -> None:
    out = run_benchmark(
        "bench_env_speed", "--api-floor", "--seconds", "0.5", "--repeats", "1", cwd=tmp_path
    )
    cases = re.findall(
        r"^(.+?): (\d+) steps replayed, ([\d.]+) API calls/step;.* at most ([\d.]+) of the "
        r"physics ceiling;.*replay identical: (\w+)$",
        out,
        re.M,
    )
    labels = [case[0].strip() for case in cases]
    assert len(cases) == 5, out[-3000:]
    assert labels[-1] == "DeckLandingTiming-BenchSS4-v6, wait decisions"
    for _, steps, calls, fraction, identical in cases:
        # every call a step makes, replayed from the saved state, ends where the step ended
        assert identical == "True" and int(steps) == 10
        assert float(calls) > 12.0 and 0.0 < float(fraction) < 1.0
    # a 20 Hz step is 12 physics sub-steps (a wait decision two control periods); low over
    # the deck the contacts are queried every sub-step, at the start height never
    assert re.search(r"│ stepSimulation +│ +12\.00 │ +12\.00 │ +12\.00 │ +12\.00 │ +24\.00 │", out)
    contacts = re.search(r"│ getContactPoints +│ +│ +│ +│ +12\.00 / [\d.]+ │", out)
    assert contacts is not None, out[-3000:]


@pytest.mark.slow
def test_env_speed_sets_each_start_rule_of_tight_against_the_truth(tmp_path: Path) -> None:
    out = run_benchmark("bench_env_speed", "--tight-starts", "--seconds", "0.5", cwd=tmp_path)
    for sensors in ("ideal", "realistic"):
        for rule in ("fallback", "first"):
            assert re.search(rf"│ +{sensors} │ +{rule} │ +\d+/10 │", out), (sensors, rule)


@pytest.mark.slow
def test_corner_noise_fits_the_noise_model_and_compares_the_modes(tmp_path: Path) -> None:
    out = run_benchmark("bench_corner_noise", "--states", "30", cwd=tmp_path)
    fitted = re.search(r"fitted pixel_noise_fit \(base, size, blur, side2\): \((.*)\)", out)
    assert fitted is not None, out
    assert all(math.isfinite(float(v)) for v in fitted.group(1).split(","))
    assert "two-sample KS" in out


@pytest.mark.slow
def test_mavlink_bridge_sends_and_the_listener_receives_every_landing_target(
    tmp_path: Path,
) -> None:
    out = run_benchmark("bench_mavlink_bridge", "--seconds", "1", "--cpu", "-1", cwd=tmp_path)
    for pacing in ("real time", "unpaced"):
        line = re.search(rf"^{pacing}: (\d+) estimates .*; (\d+) sent", out, re.M)
        assert line is not None and int(line.group(2)) > 0, out
        sent = line.group(2)
        assert re.search(rf"│ +{pacing} │.*│ +{sent}/{sent} │", out), out  # received all


@pytest.mark.slow
def test_fused_unseen_writes_every_motion_s_summary(tmp_path: Path) -> None:
    out = tmp_path / "fused"
    run_benchmark(
        "bench_fused_unseen", "--duration", "3", "--seeds", "1", "--out", str(out), cwd=tmp_path
    )
    summary = json.loads((out / "summary.json").read_text())
    groups = {"held-out bimodal", "held-out long-swell", "own motion (sinusoids)"}
    assert set(summary) == {"meta"} | groups
    for group in groups:
        for row in summary[group]["fused"].values():
            assert all(math.isfinite(v) for v in row["mae_deg"])
            # a 3 s run reaches neither the 20-30 s window nor 60 s: no figure, not an error
            assert all(math.isnan(v) for v in row["after_60_deg"])
    assert "| held-out bimodal | fused, identified |" in (out / "table.md").read_text()


@pytest.mark.slow
def test_paper_setup_writes_the_sweep_and_the_side_by_side_table(tmp_path: Path) -> None:
    out = tmp_path / "paper"
    run_benchmark("bench_paper_setup", "--duration", "1", "--out", str(out), cwd=tmp_path)
    with (out / "sweep.csv").open() as handle:
        rows = list(csv.reader(handle))
    assert rows[0][:3] == ["model", "method", "paper row"]
    models = {row[0] for row in rows[1:]}
    assert {"setup", "stated_layout", "readapriltag", "time_skew 0.2 s"} <= models
    assert any(m.startswith("fitted: stated_layout") for m in models)
    assert len(rows) - 1 == 4 * len(models)  # every paper row under every model
    assert "# Papers' setup: error-model sweep" in (out / "side_by_side.md").read_text()


@pytest.mark.slow
def test_fuzz_soak_runs_every_config_and_fuzzes_the_keys_asked(tmp_path: Path) -> None:
    out = tmp_path / "fuzz"
    run_benchmark(
        "fuzz_soak", "--parts", "project", "config", "--project-steps", "1",
        "--config-steps", "2", "--keys", "reward.touchdown_bonus", "--out", str(out),
        cwd=tmp_path,
    )  # fmt: skip
    project = json.loads((out / "project.json").read_text())
    assert len(project["configs"]) >= 10
    assert project["total"]["crashes"] == project["total"]["out_of_space"] == 0
    config = json.loads((out / "config.json").read_text())
    assert config["keys"] == 1 and config["cases"] == 13
    assert config["counts"]["crashed"] == config["counts"]["refused_naming_other"] == 0


def test_a_fuzz_prefix_that_names_no_key_is_refused_naming_keys(tmp_path: Path) -> None:
    out = run_benchmark(
        "fuzz_soak", "--parts", "config", "--keys", "no_such.", cwd=tmp_path, expect_rc=2
    )
    assert "--keys: no config key starts with 'no_such.'" in out


@pytest.mark.slow
def test_onboard_lookahead_sets_the_reduced_models_verdicts_against_the_replays(
    tmp_path: Path,
) -> None:
    out = tmp_path / "onboard.jsonl"
    printed = run_benchmark(
        "bench_onboard_lookahead", "--scenario", "ship-ss5", "--episodes", "1", "--checks", "1",
        "--out", str(out), cwd=tmp_path,
    )  # fmt: skip
    assert "ship-ss5, replay against reduced: 1 checks" in printed
    for verdict in ("success", "lands"):
        assert re.search(rf"^  {verdict} +agreement \d+\.\d %", printed, re.M), printed
    (row,) = [json.loads(line) for line in out.read_text().splitlines()]
    assert row["scenario"] == "ship-ss5" and row["first"]
    assert row["replay"] is None or len(row["replay"]) == len(row["reduced"]) == 16


def test_decision_latency_times_every_decision_of_the_recommended_policy(tmp_path: Path) -> None:
    printed = run_benchmark(
        "bench_decision_latency", "--scenario", "ship-ss4", "--episodes", "1", cwd=tmp_path
    )
    number = r" \| ([\d.]+)"
    row = re.search(rf"^\| ship-ss4 \| `(\S+)` \| (\d+){number * 3} \| (\d+) \|$", printed, re.M)
    assert row is not None, printed
    assert row.group(1) == "predictive"
    assert int(row.group(2)) >= 1
    p50, p95, top = (float(row.group(i)) for i in (3, 4, 5))
    assert 0.0 <= p50 <= p95 <= top
    assert int(row.group(6)) == 100  # two 20 Hz control periods a decision


def test_decision_latency_refuses_no_episodes(tmp_path: Path) -> None:
    out = run_benchmark(
        "bench_decision_latency", "--scenario", "ship-ss4", "--episodes", "0", cwd=tmp_path,
        expect_rc=2,
    )  # fmt: skip
    assert "--episodes must be at least 1, got 0" in out


def test_the_deck_forecast_benchmark_sets_the_measured_error_beside_the_claimed(
    tmp_path: Path,
) -> None:
    printed = run_benchmark(
        "bench_deck_forecast",
        "--scenario",
        "ship-ss4",
        "--forecast",
        "online",
        "--horizon",
        "2",
        "--record-s",
        "300",
        cwd=tmp_path,
    )
    cell = r"([\d.]+) / ([\d.]+) \(([\d.]+)\)"
    line = rf"^\| `ship-ss4` \| online \| 2 \| {cell} \| {cell} \| {cell} \|$"
    row = re.search(line, printed, re.M)
    assert row is not None, printed
    values = [float(v) for v in row.groups()]
    for measured, claimed, ratio in zip(values[0::3], values[1::3], values[2::3], strict=True):
        assert measured > 0.0 and claimed > 0.0
        # each printed to two decimals
        low, high = (measured - 0.005) / (claimed + 0.005), (measured + 0.005) / (claimed - 0.005)
        assert low - 0.005 <= ratio <= high + 0.005
    # an online forecast identified on the sea's own past is honest within a factor of two
    assert all(0.5 < r < 2.0 for r in values[2::3])


def test_the_deck_forecast_benchmark_refuses_a_bench_scenario_naming_the_argument(
    tmp_path: Path,
) -> None:
    printed = run_benchmark(
        "bench_deck_forecast", "--scenario", "bench-ss4", cwd=tmp_path, expect_rc=1
    )
    assert "scenario" in printed and "ship-ss4" in printed
