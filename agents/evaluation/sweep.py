"""Each estimator's error against one condition at a time: height, ToF noise, pixel noise,
tilt, distortion.

Every point is a short run of a base scenario (``paper-stewart`` by default) with one setting
changed, the drone pinned, rendered and detected like the full evaluation (``project`` mode is
available for quick looks; it has no detection noise unless ``camera.pixel_noise_px`` is set).
The conditions:

* ``height``: the camera's height above the deck's home surface, metres (0.5-4 m); the ToF
  maximum range is raised to ``tof_max_range_m`` so that the 4 m point still has ranges (a
  VL53L1X is rated to 4 m: beyond it the fusion methods would simply have no input);
* ``tof_noise``: the VL53L1X noise model scaled by a factor (0 = noise-free ranges);
* ``pixel_noise``: Gaussian corner noise, pixels (``project`` mode only: in ``render`` mode
  the noise is what rendering and detection give);
* ``tilt``: the peak roll and pitch of the platform, degrees (the scenario's sinusoids scaled);
* ``k1``: the radial distortion of the lens (the CRHF paper leaves its effect as future work),
  in two variants per value.  ``modelled``: the estimators use the simulated chessboard
  calibration of that lens fitting k1 k2 p1 p2 (ATDA and the fusion methods undistort the
  pixels); ``ignored``: the same calibration with a pinhole model (what a calibration that
  leaves distortion out gives: a focal length that absorbs part of it), and the fusion
  methods use the raw pixels, as in the papers.  The touch-point pixels come from the exact
  range-to-pixel map of that lens in both (a pad calibration per lens would cost ~20 s a
  point and add its own look-up error, which the other sweeps already carry).
"""

from __future__ import annotations

import csv
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from agents.common.parallel import map_tasks
from agents.evaluation import SWEEP_PARAMETERS
from agents.evaluation.estimators import EstimatorMetrics, RunSettings, run_scenario, score_record
from agents.evaluation.plots import COLOURS, pyplot, save_figure
from agents.evaluation.records import AXES, AXIS_UNITS, display_name
from estimation.limits import POSITIVE, Limit, limited, require_limits
from estimation.noise import VL53L1X_SIGMA_0_M, VL53L1X_SIGMA_PER_M
from landing_env.calibration.intrinsics_sim import ChessboardRigConfig, calibrate_intrinsics_in_sim
from landing_env.config import DeckLandingConfig, load_config
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.physics.quadrotor_params import QuadrotorParams
from landing_env.sensors.camera_config import CAMERA_MODES

#: axis labels of the sweep figures
PARAMETER_LABELS: dict[str, str] = {
    "height": "camera height above the deck (m)",
    "tof_noise": "ToF noise (x VL53L1X model: 2 mm + 2.5 mm/m)",
    "pixel_noise": "corner pixel noise, 1-sigma (px)",
    "tilt": "peak deck roll and pitch (deg)",
    "k1": "radial distortion k1",
}
#: how the estimators treat the lens in the k1 sweep, and the chessboard model of each
K1_VARIANTS: dict[str, str] = {"modelled": "k1k2p1p2", "ignored": "none"}


@dataclass
class SweepSettings:
    """Which conditions to sweep, over which values, and how long each run is."""

    scenario: str = "paper-stewart"
    #: simulated seconds per point
    duration_s: float = limited(10.0, POSITIVE)
    seed: int = limited(0, Limit(0))
    camera_mode: Literal["render", "project"] = "render"
    #: None: every condition (pixel_noise only in project mode)
    parameters: tuple[str, ...] | None = None
    heights_m: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0)
    tof_noise_scales: tuple[float, ...] = (0.0, 1.0, 2.0, 4.0, 8.0)
    pixel_noise_px: tuple[float, ...] = (0.0, 0.25, 0.5, 1.0, 2.0)
    tilt_peaks_deg: tuple[float, ...] = (0.0, 3.0, 6.5, 10.0)
    k1_values: tuple[float, ...] = (-0.15, -0.1, -0.05, 0.0, 0.05, 0.1)
    k1_variants: tuple[str, ...] = ("modelled", "ignored")
    #: where the k1 sweep's chessboard calibrations are written; empty: a temporary directory
    calibration_dir: str = ""
    #: ToF maximum range during the height sweep, metres
    tof_max_range_m: float = limited(5.0, POSITIVE)
    #: extra dotted-key overrides for every point
    overrides: dict[str, Any] = field(default_factory=dict)
    progress: bool = True
    #: parallel workers (Ray beyond one) and an existing Ray cluster's address
    workers: int = 1
    address: str | None = None

    def __post_init__(self) -> None:
        require_limits(self)
        require_choice("camera_mode", self.camera_mode, CAMERA_MODES)
        if self.parameters is None:
            self.parameters = tuple(
                p for p in SWEEP_PARAMETERS if p != "pixel_noise" or self.camera_mode == "project"
            )
        self.parameters = tuple(self.parameters)
        if not self.parameters:
            raise ConfigError("parameters", f"is empty; choose from {', '.join(SWEEP_PARAMETERS)}")
        for name in self.parameters:
            require_choice("parameters", name, SWEEP_PARAMETERS)
        for h in self.heights_m:
            require_range("heights_m", h, 0.25, 10.0)
        for s in self.tof_noise_scales:
            require_range("tof_noise_scales", s, 0.0)
        for s in self.pixel_noise_px:
            require_range("pixel_noise_px", s, 0.0, 20.0)
        if "pixel_noise" in self.parameters and self.camera_mode != "project":
            raise ConfigError(
                "parameters",
                "pixel_noise needs camera_mode 'project' (render mode's noise is the renderer's)",
            )
        for a in self.tilt_peaks_deg:
            require_range("tilt_peaks_deg", a, 0.0, 30.0)
        for k in self.k1_values:
            require_range("k1_values", k, -1.0, 1.0)
        self.k1_variants = tuple(self.k1_variants)
        if not self.k1_variants:
            raise ConfigError("k1_variants", f"is empty; choose from {', '.join(K1_VARIANTS)}")
        for variant in self.k1_variants:
            require_choice("k1_variants", variant, tuple(K1_VARIANTS))

    def plan(self) -> list[tuple[str, float, str]]:
        """Every point as (condition, value, variant); the variant is empty but for k1."""
        return [
            (parameter, value, variant)
            for parameter in self.parameters or ()
            for value in self.values(parameter)
            for variant in (self.k1_variants if parameter == "k1" else ("",))
        ]

    def values(self, parameter: str) -> tuple[float, ...]:
        return {
            "height": self.heights_m,
            "tof_noise": self.tof_noise_scales,
            "pixel_noise": self.pixel_noise_px,
            "tilt": self.tilt_peaks_deg,
            "k1": self.k1_values,
        }[parameter]


# ------------------------------------------------------------------------------- overrides
def _height_overrides(value: float, base: DeckLandingConfig, settings: SweepSettings) -> dict:
    # the drone's centre sits above the camera by the camera's body offset
    offset = float(QuadrotorParams.from_yaml(base.vehicle or None).camera_offset_b[2])
    centre = value - offset
    return {"start.height_m": [centre, centre], "tof.max_range": settings.tof_max_range_m}


def _tof_overrides(value: float) -> dict:
    if value == 0.0:
        return {"tof.noise": "none"}
    return {
        "tof.noise": "vl53l1x",
        "tof.sigma_0": VL53L1X_SIGMA_0_M * value,
        "tof.sigma_per_m": VL53L1X_SIGMA_PER_M * value,
    }


def _tilt_overrides(value: float, base: DeckLandingConfig) -> dict:
    if base.motion.kind != "sinusoids":
        raise ConfigError(
            "motion.kind", f"the tilt sweep scales sinusoids; the base is {base.motion.kind!r}"
        )
    rows = [list(row) for row in base.motion.sinusoids.amplitudes]
    for k in (3, 4):  # roll, pitch
        peak = sum(rows[k])
        if peak <= 0.0:
            raise ConfigError(
                "motion.sinusoids.amplitudes", f"the {AXES[k]} row is zero; nothing to scale"
            )
        rows[k] = [a * value / peak for a in rows[k]]
    return {"motion.sinusoids.amplitudes": rows}


def _k1_overrides(
    value: float, variant: str, base: DeckLandingConfig, settings: SweepSettings, workdir: Path
) -> dict:
    """The lens, and the chessboard calibration of it the estimators get (made once, cached)."""
    lens = {"camera.k1": value}
    path = workdir / f"intrinsics_k1_{value:+.4f}_{variant}_seed{settings.seed}.json"
    if not path.is_file():
        camera = load_config(base, lens).camera
        rig = ChessboardRigConfig(distortion_model=K1_VARIANTS[variant])
        report = calibrate_intrinsics_in_sim(camera, rig, np.random.default_rng(settings.seed))
        report.result.save(path)
    return {
        **lens,
        "estimation.intrinsics": "file",
        "estimation.intrinsics_file": str(path),
        "estimation.tof_calibration": "exact",
    }


def point_overrides(
    parameter: str,
    value: float,
    variant: str,
    base: DeckLandingConfig,
    settings: SweepSettings,
    workdir: Path,
) -> dict[str, Any]:
    """The dotted-key overrides of one point of the sweep."""
    if parameter == "height":
        return _height_overrides(value, base, settings)
    if parameter == "tof_noise":
        return _tof_overrides(value)
    if parameter == "pixel_noise":
        return {"camera.pixel_noise_px": float(value)}
    if parameter == "tilt":
        return _tilt_overrides(value, base)
    return _k1_overrides(value, variant, base, settings, workdir)


# ------------------------------------------------------------------------------- running
@dataclass(frozen=True)
class SweepPoint:
    """The scores of one run of the sweep."""

    parameter: str
    value: float
    #: k1 only: "modelled" or "ignored"; empty otherwise
    variant: str
    metrics: dict[str, EstimatorMetrics]
    stewart_clamped_frames: int
    wall_time_s: float


def run_sweep(settings: SweepSettings) -> list[SweepPoint]:
    """Run every point of the sweep (one short scenario run each), over ``settings.workers``
    (Ray beyond one, or on the cluster at ``settings.address``; the same points either way)."""
    base = load_config(settings.scenario, settings.overrides)
    with tempfile.TemporaryDirectory(prefix="deck-landing-sweep-") as scratch:
        workdir = Path(settings.calibration_dir or scratch)
        workdir.mkdir(parents=True, exist_ok=True)
        jobs = []
        for parameter, value, variant in settings.plan():
            # in this process: the k1 points' chessboard calibrations are written to workdir
            changes = point_overrides(parameter, value, variant, base, settings, workdir)
            run = RunSettings(
                scenario=settings.scenario,
                duration_s=settings.duration_s,
                seed=settings.seed,
                camera_mode=settings.camera_mode,
                overrides={**settings.overrides, **changes},
                progress=False,
            )
            jobs.append((parameter, float(value), variant, run))
        return map_tasks(
            _run_point,
            jobs,
            workers=settings.workers,
            address=settings.address,
            progress=settings.progress,
            desc="sweep",
        )


def _run_point(job: tuple[str, float, str, RunSettings]) -> SweepPoint:
    """One point of the sweep (top level: it runs in a Ray worker too)."""
    parameter, value, variant, run = job
    record = run_scenario(run)
    return SweepPoint(
        parameter,
        value,
        variant,
        score_record(record),
        int(record.stewart_clamped.sum()),
        record.wall_time_s,
    )


# ------------------------------------------------------------------------------- outputs
def series_label(name: str, variant: str) -> str:
    """ATDA, or ATDA (distortion ignored) for the k1 sweep's variants."""
    if variant == "ignored":
        return f"{display_name(name)} (distortion ignored)"
    if variant == "modelled":
        return f"{display_name(name)} (distortion modelled)"
    return display_name(name)


def _series_keys(points: list[SweepPoint], parameter: str) -> list[tuple[str, str]]:
    return list(
        dict.fromkeys(
            (name, p.variant) for p in points if p.parameter == parameter for name in p.metrics
        )
    )


def _series(
    points: list[SweepPoint], parameter: str, name: str, variant: str
) -> tuple[np.ndarray, np.ndarray]:
    chosen = [
        p for p in points if p.parameter == parameter and p.variant == variant and name in p.metrics
    ]
    x = np.array([p.value for p in chosen])
    mae = np.array([p.metrics[name].mae for p in chosen]).reshape(-1, 6)
    return x, mae


def write_sweep_csv(points: list[SweepPoint], path: Path) -> None:
    """One row per (condition, value, variant, estimator): valid frames, MAE and max per axis."""
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(
            [
                "parameter",
                "value",
                "variant",
                "estimator",
                "valid_frames",
                "frames",
                "stewart_clamped_frames",
                *(f"mae_{a}_{u}" for a, u in zip(AXES, AXIS_UNITS, strict=True)),
                *(f"max_{a}_{u}" for a, u in zip(AXES, AXIS_UNITS, strict=True)),
            ]
        )
        for point in points:
            for name, m in point.metrics.items():
                writer.writerow(
                    [
                        point.parameter,
                        f"{point.value:g}",
                        point.variant,
                        display_name(name),
                        m.n_valid,
                        m.n_frames,
                        point.stewart_clamped_frames,
                        *(f"{v:.6g}" for v in m.mae),
                        *(f"{v:.6g}" for v in m.max_error),
                    ]
                )


def sweep_markdown(points: list[SweepPoint]) -> str:
    """Per condition a table of translation and angle MAE (means over the three axes)."""
    parts: list[str] = []
    for parameter in dict.fromkeys(p.parameter for p in points):
        keys = _series_keys(points, parameter)
        values = list(dict.fromkeys(p.value for p in points if p.parameter == parameter))
        parts.append(f"### {PARAMETER_LABELS[parameter]}\n")
        head = ["value", *(series_label(n, v) for n, v in keys)]
        parts.append("| " + " | ".join(head) + " |")
        parts.append("|---:|" + "---:|" * len(keys))
        for value in values:
            cells = [f"{value:g}"]
            for name, variant in keys:
                match = [
                    p
                    for p in points
                    if (p.parameter, p.value, p.variant) == (parameter, value, variant)
                ]
                if not match or name not in match[0].metrics:
                    cells.append("–")
                    continue
                m = match[0].metrics[name]
                cells.append(
                    f"{np.mean(m.mae[:3]) * 1000:.1f} mm / {np.mean(m.mae[3:]):.2f}° "
                    f"({m.n_valid}/{m.n_frames})"
                )
            parts.append("| " + " | ".join(cells) + " |")
        parts.append("")
    return "\n".join(parts)


def _style(name: str, variant: str, index: int) -> dict[str, Any]:
    return {
        "color": COLOURS.get(name, f"C{index}"),
        "ls": "--" if variant == "ignored" else "-",
        "marker": "s" if variant == "ignored" else "o",
        "label": series_label(name, variant),
    }


def plot_parameter(points: list[SweepPoint], parameter: str, path: Path) -> Path:
    """Six panels (one per axis): each estimator's MAE against the condition."""
    keys = _series_keys(points, parameter)
    fig, axes = pyplot().subplots(2, 3, figsize=(13, 7), sharex=True)
    for k, ax in enumerate(axes.ravel()):
        for i, (name, variant) in enumerate(keys):
            x, mae = _series(points, parameter, name, variant)
            ax.plot(x, mae[:, k], **_style(name, variant, i))
        ax.set(title=f"{AXES[k]} MAE", ylabel=f"MAE ({AXIS_UNITS[k]})")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
    for ax in axes[-1]:
        ax.set_xlabel(PARAMETER_LABELS[parameter])
    axes[0, 0].legend(fontsize=7)
    return save_figure(fig, path)


def plot_overview(points: list[SweepPoint], path: Path) -> Path:
    """One column per condition: mean translation MAE (top) and mean angle MAE (bottom)."""
    parameters = list(dict.fromkeys(p.parameter for p in points))
    fig, axes = pyplot().subplots(
        2, len(parameters), figsize=(4.2 * len(parameters), 7), squeeze=False
    )
    for col, parameter in enumerate(parameters):
        for i, (name, variant) in enumerate(_series_keys(points, parameter)):
            x, mae = _series(points, parameter, name, variant)
            style = _style(name, variant, i)
            axes[0, col].plot(x, 1000 * mae[:, :3].mean(axis=1), **style)
            axes[1, col].plot(x, mae[:, 3:].mean(axis=1), **style)
        axes[0, col].set(ylabel="translation MAE, mean of x y z (mm)")
        axes[1, col].set(ylabel="angle MAE, mean of roll pitch yaw (deg)")
        axes[1, col].set_xlabel(PARAMETER_LABELS[parameter])
        for ax in axes[:, col]:
            ax.set_yscale("log")
            ax.grid(alpha=0.3, which="both")
        axes[0, col].legend(fontsize=6)
    return save_figure(fig, path)


#: the estimators tight is held against in :func:`plot_tight_ratio` (the bar it is judged
#: by: at most 5 % above the better of them on every axis)
RATIO_REFERENCES = ("atda", "crhf")


def tight_ratios(points: list[SweepPoint]) -> list[tuple[str, float, np.ndarray]]:
    """Per point (condition, value): tight's MAE over min(ATDA, CRHF) per axis."""
    rows = []
    for p in points:
        if "tight" not in p.metrics or not all(r in p.metrics for r in RATIO_REFERENCES):
            continue
        best = np.minimum.reduce([np.asarray(p.metrics[r].mae) for r in RATIO_REFERENCES])
        with np.errstate(divide="ignore", invalid="ignore"):
            rows.append((p.parameter, p.value, np.asarray(p.metrics["tight"].mae) / best))
    return rows


def plot_tight_ratio(points: list[SweepPoint], path: Path) -> Path | None:
    """tight's MAE / min(ATDA, CRHF) per axis against each condition, with the 1.05 line."""
    rows = tight_ratios(points)
    parameters = list(dict.fromkeys(r[0] for r in rows))
    if not parameters:
        return None
    fig, axes = pyplot().subplots(
        1, len(parameters), figsize=(5 * len(parameters), 4), squeeze=False
    )
    for ax, parameter in zip(axes[0], parameters, strict=True):
        chosen = [r for r in rows if r[0] == parameter]
        x = np.array([r[1] for r in chosen])
        ratio = np.array([r[2] for r in chosen])
        for k, axis in enumerate(AXES):
            ax.plot(x, ratio[:, k], marker="o", label=axis)
        ax.axhline(1.05, color="k", ls="--", lw=1, label="1.05")
        ax.set(
            xlabel=PARAMETER_LABELS[parameter],
            ylabel="tight MAE / min(ATDA, CRHF) MAE",
            ylim=(0.0, max(1.2, float(np.nanmax(ratio)) * 1.05)),
        )
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=2)
    return save_figure(fig, path)


def write_sweep(points: list[SweepPoint], settings: SweepSettings, out_dir: Path) -> list[Path]:
    """The CSV, the Markdown summary and the figures of a sweep."""
    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path = out_dir / "sweep.csv"
    write_sweep_csv(points, csv_path)
    md_path = out_dir / "sweep.md"
    header = (
        f"# Estimator sweep on {settings.scenario} ({settings.camera_mode} mode, "
        f"{settings.duration_s:g} s per point, seed {settings.seed})\n\n"
        "Mean absolute error, averaged over the translation axes (mm) and over the angles "
        "(degrees), with the valid frames; per-axis values in sweep.csv.\n\n"
    )
    md_path.write_text(header + sweep_markdown(points))
    files = [csv_path, md_path]
    for parameter in dict.fromkeys(p.parameter for p in points):
        files.append(plot_parameter(points, parameter, out_dir / f"sweep_{parameter}.png"))
    files.append(plot_overview(points, out_dir / "sweep.png"))
    ratio = plot_tight_ratio(points, out_dir / "sweep_tight_ratio.png")
    if ratio is not None:
        files.append(ratio)
    return files
