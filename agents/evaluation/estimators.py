"""Run a scenario with the drone pinned over the moving deck and score every estimator.

This reproduces the papers' Stewart-platform experiments (IHRCF Table 2, CRHF Table 5): a
motionless quadrotor above the moving platform, 50 ms steps, the tag rendered and detected,
and per axis the mean absolute error (the papers' Eq. 28) and the maximum error of each
estimator against the ground truth ``T_CD``.  Translations in metres, angles in degrees (ZYX,
reported as roll, pitch, yaw; angle errors wrapped to (-180, 180]).  The MAE is taken over an
estimator's valid frames only; its invalid frames are counted, with their reasons, beside it.
"""

from __future__ import annotations

import csv
import json
import math
import time
import warnings
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import landing_env  # noqa: F401  (registers the environments)
from agents.evaluation.fusion_plot import plot_fusion_dropout
from agents.evaluation.plots import plot_all
from agents.evaluation.records import (
    AXES,
    AXIS_UNITS,
    TRUTH,
    EstimatorTrace,
    ScenarioRecord,
    display_name,
    pose_errors,
)
from estimation.limits import POSITIVE, Limit, limited, require_limits
from landing_env.config import DeckLandingConfig, load_config
from landing_env.errors import ConfigError, PinnedDroneWarning, require_choice
from landing_env.sensors.camera_config import CAMERA_MODES

#: the command-line option that sets each key the evaluation forces
_FORCED_BY = {
    "camera.mode": "--mode",
    "simulation.drone_fixed": "the pinned-drone bench",
    "simulation.max_episode_s": "--duration",
    "estimation.compare": "--estimators",
}


@dataclass(frozen=True)
class PaperResult:
    """A published mean-absolute-error row: x, y, z (m) and the angles about x, y, z (deg).

    The papers name the angles inconsistently (CRHF calls the rotation about x "pitch"), so
    the rows are mapped by axis: about x = our roll, about y = pitch, about z = yaw.
    """

    method: str
    source: str
    mae: tuple[float, float, float, float, float, float]


#: The papers' Table 2 (IHRCF, Sensors 2022) and Table 5 (CRHF, Drones 2022): MAE over 120 s.
PAPER_RESULTS: tuple[PaperResult, ...] = (
    PaperResult("atda", "IHRCF paper, Table 2", (0.0162, 0.0134, 0.0697, 2.9843, 1.657, 1.7743)),
    PaperResult("ihrcf", "IHRCF paper, Table 2", (0.0035, 0.0039, 0.0041, 0.98, 1.3731, 1.180)),
    PaperResult("atda", "CRHF paper, Table 5", (0.0157, 0.0129, 0.0687, 3.9043, 1.7684, 1.7859)),
    PaperResult("crhf", "CRHF paper, Table 5", (0.0047, 0.0042, 0.0051, 1.4239, 1.5231, 1.3290)),
)


# ------------------------------------------------------------------------------- running
@dataclass
class RunSettings:
    """How :func:`run_scenario` runs a scenario.

    The drone is always pinned (``simulation.drone_fixed``), as on the papers' bench.
    """

    #: a config name in ``configs/`` or a YAML path
    scenario: str = "paper-stewart"
    #: simulated seconds; None: the scenario's ``simulation.max_episode_s``
    duration_s: float | None = limited(None, POSITIVE)
    #: None: the scenario's seed, else 0
    seed: int | None = limited(None, Limit(0))
    #: the papers' experiments render and detect; ``project`` is the fast analytic camera
    camera_mode: Literal["render", "project"] = "render"
    #: the estimators to score (sets ``estimation.compare``); None: the scenario's observed
    #: and compared ones except truth.  Naming ``truth`` scores it (a plumbing check: zero)
    estimators: tuple[str, ...] | None = None
    #: extra dotted-key overrides applied on top of the scenario
    overrides: dict[str, Any] = field(default_factory=dict)
    #: show a tqdm progress bar
    progress: bool = True

    def __post_init__(self) -> None:
        require_choice("camera_mode", self.camera_mode, CAMERA_MODES)
        require_limits(self)
        if self.estimators is not None:
            self.estimators = tuple(self.estimators)
            if not self.estimators:
                raise ConfigError("estimators", "is empty; name one or more estimators")

    @property
    def name(self) -> str:
        """The scenario's short name (the YAML file's stem)."""
        return (
            Path(self.scenario).stem
            if self.scenario.endswith((".yaml", ".yml"))
            else (self.scenario)
        )

    def all_overrides(self) -> dict[str, Any]:
        """The scenario overrides that make it an evaluation run."""
        forced: dict[str, Any] = {
            "camera.mode": self.camera_mode,
            "simulation.drone_fixed": True,
        }
        if self.duration_s is not None:
            forced["simulation.max_episode_s"] = float(self.duration_s)
        if self.estimators is not None:
            forced["estimation.compare"] = list(self.estimators)
        for key, value in self.overrides.items():
            if key in forced and value != forced[key]:
                flag = _FORCED_BY.get(key, "the evaluation")
                raise ConfigError(
                    key,
                    f"{value!r} conflicts with the evaluation's {forced[key]!r}, which {flag} "
                    "sets; drop it from --set",
                )
        return {**self.overrides, **forced}

    def scored(self, config: DeckLandingConfig) -> list[str]:
        """The estimators the run scores (truth only when named explicitly)."""
        if self.estimators is not None:
            return list(dict.fromkeys(self.estimators))
        names = dict.fromkeys((config.estimation.observed, *config.estimation.compare))
        return [name for name in names if name != TRUTH]

    def config(self) -> DeckLandingConfig:
        """The validated environment config of the run."""
        return load_config(self.scenario, self.all_overrides())


def run_scenario(settings: RunSettings) -> ScenarioRecord:
    """Run the scenario with the drone pinned and record the truth and every estimate."""
    config = settings.config()
    seed = settings.seed if settings.seed is not None else (config.seed or 0)
    names = settings.scored(config)
    if not names:
        raise ConfigError(
            "estimation.compare",
            "names no estimator to score; add some of 'atda', 'ihrcf', 'crhf'",
        )
    with warnings.catch_warnings():  # the pinned drone is this bench's point
        warnings.simplefilter("ignore", PinnedDroneWarning)
        env = gym.make("DeckLanding-v2", config=config)
    base = env.unwrapped
    steps = base.max_steps
    times: list[float] = []
    truth: list[np.ndarray] = []
    clamped: list[bool] = []
    misses: list[str] = []
    poses: dict[str, list[np.ndarray]] = {n: [] for n in names}
    valid: dict[str, list[bool]] = {n: [] for n in names}
    predicted: dict[str, list[bool]] = {n: [] for n in names}
    reasons: dict[str, list[str]] = {n: [] for n in names}
    stds: dict[str, list[np.ndarray]] = {n: [] for n in names}
    captures: dict[str, list[float]] = {n: [] for n in names}

    def record(info: dict[str, Any]) -> None:
        times.append(float(info["time_s"]))
        truth.append(np.asarray(info["deck_pose_true"], dtype=float))
        clamped.append(bool(info["stewart_clamped"]))
        misses.append(str(info["tag_miss_reason"]))
        for name in names:
            estimate = info["estimates"][name]
            ok = bool(estimate["valid"])
            poses[name].append(
                np.asarray(estimate["pose"], dtype=float) if ok else np.full(6, np.nan)
            )
            valid[name].append(ok)
            predicted[name].append(bool(estimate["predicted"]))
            reasons[name].append(str(estimate["reason"]))
            stds[name].append(np.asarray(estimate.get("std", np.full(6, np.nan)), dtype=float))
            captures[name].append(float(estimate["extras"].get("capture_time_s", np.nan)))

    hover = np.zeros(env.action_space.shape, dtype=np.float32)  # ignored: the drone is pinned
    start = time.perf_counter()
    try:
        _, info = env.reset(seed=seed)
        record(info)
        with tqdm(
            total=steps, desc=settings.name, unit="step", disable=not settings.progress
        ) as bar:
            for _ in range(steps):
                _, _, terminated, truncated, info = env.step(hover)
                record(info)
                bar.update()
                if terminated or truncated:
                    break
    finally:
        env.close()
    wall = time.perf_counter() - start
    return ScenarioRecord(
        scenario=settings.name,
        seed=seed,
        time_s=np.asarray(times),
        truth=np.asarray(truth),
        estimates={
            n: EstimatorTrace(
                pose=np.asarray(poses[n]),
                valid=np.asarray(valid[n], dtype=bool),
                predicted=np.asarray(predicted[n], dtype=bool),
                reasons=reasons[n],
                std=np.asarray(stds[n]) if np.isfinite(stds[n]).any() else None,
                capture_time_s=np.asarray(captures[n]) if np.isfinite(captures[n]).any() else None,
            )
            for n in names
        },
        stewart_clamped=np.asarray(clamped, dtype=bool),
        tag_miss_reason=misses,
        wall_time_s=wall,
        config={"overrides": settings.all_overrides(), "scenario": settings.scenario},
    )


# ------------------------------------------------------------------------------- metrics
@dataclass(frozen=True)
class EstimatorMetrics:
    """One estimator's scores over a run (metres and degrees per axis)."""

    name: str
    n_frames: int
    n_valid: int
    #: valid frames that the estimator bridged by prediction rather than measured
    n_predicted: int
    invalid_reasons: dict[str, int]
    #: mean absolute error over the valid frames (Eq. 28 of the papers); NaN if none valid
    mae: np.ndarray
    max_error: np.ndarray
    rmse: np.ndarray

    @property
    def n_invalid(self) -> int:
        return self.n_frames - self.n_valid

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "n_frames": self.n_frames,
            "n_valid": self.n_valid,
            "n_predicted": self.n_predicted,
            "n_invalid": self.n_invalid,
            "invalid_reasons": dict(self.invalid_reasons),
            "mae": dict(zip(AXES, self.mae.tolist(), strict=True)),
            "max_error": dict(zip(AXES, self.max_error.tolist(), strict=True)),
            "rmse": dict(zip(AXES, self.rmse.tolist(), strict=True)),
        }


def score_trace(name: str, trace: EstimatorTrace, truth: np.ndarray) -> EstimatorMetrics:
    """MAE, maximum and RMS error per axis over the valid frames; invalid ones tallied."""
    valid = trace.valid
    n_valid = int(valid.sum())
    reasons = Counter(
        r or "unspecified" for r, ok in zip(trace.reasons, valid, strict=True) if not ok
    )
    if n_valid:
        error = np.abs(pose_errors(trace.pose[valid], truth[valid]))
        mae, max_error = error.mean(axis=0), error.max(axis=0)
        rmse = np.sqrt(np.mean(error**2, axis=0))
    else:
        mae = max_error = rmse = np.full(6, np.nan)
    return EstimatorMetrics(
        name=name,
        n_frames=len(valid),
        n_valid=n_valid,
        n_predicted=int((trace.predicted & valid).sum()),
        invalid_reasons=dict(sorted(reasons.items())),
        mae=mae,
        max_error=max_error,
        rmse=rmse,
    )


def score_record(record: ScenarioRecord) -> dict[str, EstimatorMetrics]:
    """Scores of every estimator of a run, in the run's order."""
    return {
        name: score_trace(name, trace, record.truth) for name, trace in record.estimates.items()
    }


# ------------------------------------------------------------------------------- tables
@dataclass(frozen=True)
class TableRow:
    """One row of the comparison table."""

    method: str
    source: str
    statistic: Literal["MAE", "max"]
    values: tuple[float, ...]
    valid: str = ""
    invalid: str = ""


def _reasons_text(metrics: EstimatorMetrics) -> str:
    if not metrics.n_invalid:
        return "0"
    tally = ", ".join(f"{reason} {count}" for reason, count in metrics.invalid_reasons.items())
    return f"{metrics.n_invalid} ({tally})"


def comparison_rows(
    metrics: dict[str, EstimatorMetrics], label: str = "this run"
) -> list[TableRow]:
    """Per estimator: our MAE, our maximum, then the papers' published MAE for it."""
    rows: list[TableRow] = []
    for name, m in metrics.items():
        valid = f"{m.n_valid}/{m.n_frames}"
        if m.n_predicted:
            valid += f" ({m.n_predicted} predicted)"
        invalid = _reasons_text(m)
        rows.append(TableRow(name, label, "MAE", tuple(m.mae.tolist()), valid, invalid))
        rows.append(TableRow(name, label, "max", tuple(m.max_error.tolist()), valid, invalid))
        for paper in PAPER_RESULTS:
            if paper.method == name:
                rows.append(TableRow(name, paper.source, "MAE", paper.mae))
    return rows


def _number(value: float, unit: str) -> str:
    if not math.isfinite(value):
        return "n/a"
    return f"{value:.4f}" if unit == "m" else f"{value:.3f}"


def markdown_table(rows: list[TableRow]) -> str:
    """The comparison as a GitHub Markdown table (metres and degrees)."""
    head = [
        "method",
        "source",
        "statistic",
        *(f"{a} ({'m' if u == 'm' else '°'})" for a, u in zip(AXES, AXIS_UNITS, strict=True)),
        "valid frames",
        "invalid frames (reasons)",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * 3 + "---:|" * 6 + "---|---|"]
    for row in rows:
        cells = [
            display_name(row.method),
            row.source,
            row.statistic,
            *(_number(v, u) for v, u in zip(row.values, AXIS_UNITS, strict=True)),
            row.valid or "–",
            row.invalid or "–",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_csv_table(rows: list[TableRow], path: Path) -> None:
    """The comparison as CSV: one row per (method, source, statistic); m and degrees."""
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(
            [
                "method",
                "source",
                "statistic",
                *(f"{a}_{u}" for a, u in zip(AXES, AXIS_UNITS, strict=True)),
                "valid_frames",
                "invalid_frames",
            ]
        )
        for row in rows:
            writer.writerow(
                [
                    display_name(row.method),
                    row.source,
                    row.statistic,
                    *(f"{v:.6g}" for v in row.values),
                    row.valid,
                    row.invalid,
                ]
            )


# ------------------------------------------------------------------------------- the job
@dataclass
class EvaluationResult:
    """What ``evaluate estimators`` produced."""

    record: ScenarioRecord
    metrics: dict[str, EstimatorMetrics]
    rows: list[TableRow]
    out_dir: Path
    files: list[Path]


def _summary(record: ScenarioRecord, metrics: dict[str, EstimatorMetrics]) -> dict[str, Any]:
    steps = max(record.n_frames - 1, 1)
    return {
        "scenario": record.scenario,
        "seed": record.seed,
        "frames": record.n_frames,
        "simulated_s": round(float(record.time_s[-1] - record.time_s[0]), 6),
        "wall_time_s": round(record.wall_time_s, 2),
        "wall_ms_per_step": round(1000.0 * record.wall_time_s / steps, 2),
        "stewart_clamped_frames": int(record.stewart_clamped.sum()),
        "tag_missed_frames": int(sum(1 for r in record.tag_miss_reason if r)),
        "config": record.config,
        "estimators": {name: m.as_dict() for name, m in metrics.items()},
    }


def evaluate_estimators(
    settings: RunSettings, out_dir: Path | None = None, plots: bool = True
) -> EvaluationResult:
    """Run a scenario and write the tables, the summary, the time series and the figures."""
    record = run_scenario(settings)
    metrics = score_record(record)
    rows = comparison_rows(metrics)
    out = Path(out_dir) if out_dir is not None else Path("results") / settings.name
    out.mkdir(parents=True, exist_ok=True)
    table_md = out / "errors.md"
    title = (
        f"# {settings.name}: deck-pose errors over {record.time_s[-1]:.1f} s "
        f"({record.n_frames} frames, seed {record.seed})\n\n"
        "Mean absolute error (the papers' Eq. 28) and maximum absolute error per axis over each "
        "estimator's valid frames; invalid frames are counted separately.  Translations of "
        "the tag in the camera frame in metres; ZYX Euler angles in degrees (errors wrapped to "
        "(-180, 180]).\n\n"
    )
    table_md.write_text(title + markdown_table(rows))
    table_csv = out / "errors.csv"
    write_csv_table(rows, table_csv)
    summary = out / "summary.json"
    summary.write_text(json.dumps(_summary(record, metrics), indent=2) + "\n")
    series = out / "series.npz"
    record.save(series)
    files = [table_md, table_csv, summary, series]
    if plots:
        files += plot_all(record, out)
        if "fused" in record.estimates:
            files.append(plot_fusion_dropout(record, out / "fusion_dropout.png"))
    return EvaluationResult(record, metrics, rows, out, files)
