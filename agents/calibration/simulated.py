"""``deck-landing calibrate``: both of the papers' calibrations, run in the simulator.

Runs the chessboard intrinsics calibration (CRHF Sec. 2.1–2.2) and the ToF–camera pad
calibration (IHRCF Sec. 2.2, CRHF Sec. 2.3) for a config's camera and ToF layout, prints
their figures, and writes to ``--out`` (default ``results/calibration/``):

* ``intrinsics.json``: K, distortion, reprojection errors, the camera it was made for, and
  the tag detector's corner offset and noise on that camera (a third rig, after K:
  ``landing_env/calibration/tag_corner_sim.py``, :mod:`estimation.corner_bias`);
* ``tof_rig/``: the pad rig's stages as a recording folder (frames, ranges and the rig file
  ``tof_rig.json``, :mod:`agents.io.tof_rig`), from which the ToF–camera calibration is made
  as ``deck-landing calibrate tof --recording`` makes a real rig's;
* ``tof_camera.json``: the range → pixel samples of each sensor (the PCHIP look-up's data);
* ``tof_camera_curves.png``: pixel against range per sensor with the PCHIP and hyperbola
  fits, and their error against the analytic touch-point pixel;
* ``summary.json``: the printed figures.

``--install`` also copies the two calibration files to ``configs/calibration/``, where the
environment finds them by default; it is refused for a config whose camera or ToF layout
differs from the default config's, since the shipped files are for those.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table
from tqdm import tqdm

from agents.common.parallel import map_tasks
from agents.io.tof_rig import INTRINSICS_NAME, calibrate_tof_recording, write_rig_recording
from estimation.tof_calibration import PAD_COLOURS
from landing_env.calibration.intrinsics_sim import (
    ChessboardRigConfig,
    IntrinsicsSimReport,
    calibrate_intrinsics_in_sim,
)
from landing_env.calibration.tag_corner_sim import (
    TagCornerReport,
    TagRigConfig,
    calibrate_tag_corners_in_sim,
)
from landing_env.calibration.tof_camera_sim import (
    TofRigConfig,
    TofSimReport,
    record_tof_rig_in_sim,
    tof_sim_report,
)
from landing_env.config import (
    CALIBRATION_DIR,
    DeckLandingConfig,
    load_config,
)
from landing_env.errors import ConfigError

TOF_NAME = "tof_camera.json"
PLOT_NAME = "tof_camera_curves.png"
SUMMARY_NAME = "summary.json"
RIG_RECORDING_NAME = "tof_rig"


@dataclass(frozen=True)
class CalibrationRun:
    """Both reports and the files written."""

    intrinsics: IntrinsicsSimReport
    tof: TofSimReport
    files: dict[str, Path]
    tag_corners: TagCornerReport | None = None


def _layout_differences(config: DeckLandingConfig) -> list[str]:
    """Where the config's camera or ToF layout differs from the default config's."""
    default = load_config("default")
    differences = []
    if config.camera.intrinsics != default.camera.intrinsics:
        differences.append("camera intrinsics")
    if not np.allclose(config.tof.mount_offsets_c, default.tof.mount_offsets_c):
        differences.append("tof.mount_offsets_c")
    if config.tof.max_range != default.tof.max_range:
        differences.append("tof.max_range")
    return differences


def summary(
    intrinsics: IntrinsicsSimReport, tof: TofSimReport, tags: TagCornerReport | None = None
) -> dict:
    """The figures of the calibrations as plain data."""
    result = intrinsics.result
    tag_part = (
        {} if tags is None else {"tag_corners": {**tags.fit.as_dict(), "missed": tags.missed_views}}
    )
    return {
        **tag_part,
        "intrinsics": {
            "views_used": intrinsics.views_used,
            "views_rejected": intrinsics.views_rejected,
            "rms_reprojection_error_px": result.rms_reprojection_error,
            "K": result.K.tolist(),
            "dist": result.dist.tolist(),
            "k_error_px": intrinsics.k_error_px(),
            "k_error_pct": intrinsics.k_error_pct(),
        },
        "tof_camera": {
            "sensors": [
                {
                    "pad": PAD_COLOURS[i],
                    "samples": len(tof.calibration.samples[i]),
                    "range_span_m": tof.calibration.range_span[i].tolist(),
                    "skipped": {reason: counts[i] for reason, counts in tof.skipped.items()},
                    "hyperbola_u": {"a": hu.a, "c": hu.c, "rms_px": hu.rms},
                    "hyperbola_v": {"a": hv.a, "c": hv.c, "rms_px": hv.rms},
                    "pchip_max_error_px": float(tof.exact_error_px[i]),
                    "sample_rms_error_px": float(tof.sample_error_px[i]),
                }
                for i, (hu, hv) in enumerate(tof.hyperbolas)
            ]
        },
    }


def print_summary(console: Console, intrinsics: IntrinsicsSimReport, tof: TofSimReport) -> None:
    """Tables of the calibrated K against the truth and of the ToF–camera fits."""
    result = intrinsics.result
    true = intrinsics.true_intrinsics
    console.print(
        f"[bold]Intrinsics[/bold]: {intrinsics.views_used} views used, "
        f"{intrinsics.views_rejected} rejected (board not found); "
        f"RMS reprojection error {result.rms_reprojection_error:.3f} px"
    )
    table = Table("", "true", "calibrated", "error px", "error %")
    errors_px, errors_pct = intrinsics.k_error_px(), intrinsics.k_error_pct()
    truth = {"fx": true.fx, "fy": true.fy, "cx": true.cx, "cy": true.cy}
    for key, value in truth.items():
        table.add_row(
            key,
            f"{value:.3f}",
            f"{value + errors_px[key]:.3f}",
            f"{errors_px[key]:+.3f}",
            f"{errors_pct[key]:+.3f}",
        )
    console.print(table)
    console.print(
        "distortion (k1, k2, p1, p2, k3): "
        + ", ".join(f"{d:+.5f}" for d in result.dist.reshape(-1)[:5])
        + f"  (true: {', '.join(f'{d:+.5f}' for d in true.dist)})"
    )
    console.print(
        "[bold]ToF–camera[/bold]: touch-point pixel = a / range + c per sensor and axis "
        "(CRHF Table 4); PCHIP err = worst distance of the look-up from the exact pixel"
    )
    table = Table("sensor", "axis", "a px·m", "c px", "fit RMS px", "n", "skipped", "PCHIP err px")
    for i, fits in enumerate(tof.hyperbolas):
        skipped = sum(counts[i] for counts in tof.skipped.values())
        for axis, fit in zip("uv", fits, strict=True):
            table.add_row(
                f"{i + 1} {PAD_COLOURS[i]}" if axis == "u" else "",
                axis,
                f"{fit.a:.3f}",
                f"{fit.c:.3f}",
                f"{fit.rms:.3f}",
                str(len(tof.calibration.samples[i])) if axis == "u" else "",
                str(skipped) if axis == "u" else "",
                f"{tof.exact_error_px[i]:.3f}" if axis == "u" else "",
            )
    console.print(table)
    skipped = {reason: sum(counts) for reason, counts in tof.skipped.items() if sum(counts)}
    console.print(f"skipped sensor-stages by reason: {skipped or 'none'}")


def plot_curves(tof: TofSimReport, path: Path) -> None:
    """Pixel against range per sensor (samples, PCHIP, hyperbola) and the fits' errors."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"blue": "tab:blue", "green": "tab:green", "yellow": "goldenrod", "red": "tab:red"}
    cal = tof.calibration
    hyperbola = cal.with_method("hyperbola")
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8), constrained_layout=True)
    low, high = cal.range_span[:, 0].min(), cal.range_span[:, 1].max()
    dense = np.linspace(low, high, 600)
    pchip_px = np.array([cal.lookup(np.full(cal.n_sensors, r)).pixels for r in dense])
    hyper_px = np.array([hyperbola.lookup(np.full(cal.n_sensors, r)).pixels for r in dense])
    exact_px = np.array([tof.exact.lookup(np.full(cal.n_sensors, r)).pixels for r in dense])
    for i, samples in enumerate(cal.samples):
        colour = colours.get(PAD_COLOURS[i], None)
        for axis, ax in enumerate(axes[:2]):
            ax.plot(samples[:, 0], samples[:, 1 + axis], ".", color=colour, ms=4)
            ax.plot(dense, pchip_px[:, i, axis], "-", color=colour, lw=1.0)
            ax.plot(dense, hyper_px[:, i, axis], "--", color="k", lw=0.7)
        for looked_up, style, name in ((pchip_px, "-", "PCHIP"), (hyper_px, ":", "hyperbola")):
            error = np.linalg.norm(looked_up[:, i] - exact_px[:, i], axis=1)
            axes[2].plot(dense, error, style, color=colour, lw=1.0, label=f"sensor {i + 1} {name}")
    for axis, ax in enumerate(axes[:2]):
        name = "u (column)" if axis == 0 else "v (row)"
        ax.set_xlabel("range (m)")
        ax.set_ylabel(f"touch-point pixel {name} (px)")
        ax.set_title(f"{name}: samples (dots), PCHIP (lines), a/r + c (dashed)")
        ax.grid(alpha=0.3)
    axes[2].set_xlabel("range (m)")
    axes[2].set_ylabel("distance from the analytic touch pixel (px)")
    axes[2].set_title("look-up error against the exact projection")
    axes[2].grid(alpha=0.3)
    axes[2].legend(fontsize=7, ncol=2)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _calibration_part(job: tuple) -> Any:
    """One of the two calibrations (top level: it runs in a Ray worker too)."""
    kind, cfg, rig, rng = job
    if kind == "intrinsics":
        return calibrate_intrinsics_in_sim(cfg.camera, rig, rng)
    return record_tof_rig_in_sim(cfg, rig, rng)


def run_calibration(
    config: str | Path | DeckLandingConfig = "default",
    out_dir: Path = Path("results/calibration"),
    views: int = 20,
    stages: int = 120,
    seed: int = 0,
    install: bool = False,
    progress: bool = True,
    console: Console | None = None,
    workers: int = 1,
    address: str | None = None,
    overrides: dict[str, Any] | None = None,
) -> CalibrationRun:
    """Run both calibrations, print the figures and write the files (see the module doc);
    ``overrides`` (dotted keys) apply on top of a named config."""
    console = console or Console()
    cfg = config if isinstance(config, DeckLandingConfig) else load_config(config, overrides)
    if install:
        differences = _layout_differences(cfg)
        if differences:
            raise ConfigError(
                "install",
                "the shipped calibration files are for the default camera and ToF layout; "
                f"this config differs in {', '.join(differences)}: write them with --out and "
                "point estimation.intrinsics_file / estimation.tof_calibration_file at them",
            )
    # spawn(3) gives the same first two streams as spawn(2) did before the tag rig
    intrinsics_rng, tof_rng, tag_rng = np.random.default_rng(seed).spawn(3)
    rig = ChessboardRigConfig(views=views)
    if workers > 1 or address is not None:
        # the two calibrations side by side on Ray (the same generators: the same results)

        intrinsics, recorded = map_tasks(
            _calibration_part,
            [
                ("intrinsics", cfg, rig, intrinsics_rng),
                ("tof", cfg, TofRigConfig(stages=stages), tof_rng),
            ],
            workers=min(workers, 2),
            address=address,
            progress=progress,
            desc="calibrations",
        )
    else:
        with tqdm(total=views, desc="chessboard views", unit="view", disable=not progress) as bar:
            intrinsics = calibrate_intrinsics_in_sim(cfg.camera, rig, intrinsics_rng, bar.update)
        with tqdm(
            total=stages, desc="ToF–camera stages", unit="stage", disable=not progress
        ) as bar:
            recorded = record_tof_rig_in_sim(cfg, TofRigConfig(stages=stages), tof_rng, bar.update)
    # the tag detector's corner offset, against the corners projected through the new K
    with tqdm(
        total=TagRigConfig().stages, desc="tag-corner stages", unit="stage", disable=not progress
    ) as bar:
        tags = calibrate_tag_corners_in_sim(
            cfg, intrinsics.result.to_intrinsics(), TagRigConfig(), tag_rng, bar.update
        )
    intrinsics = dataclasses.replace(
        intrinsics, result=dataclasses.replace(intrinsics.result, tag_corners=tags.fit.as_dict())
    )
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    # the rig's stages written as a recording folder, calibrated as a real rig's is
    rig_dir = write_rig_recording(
        out_dir / RIG_RECORDING_NAME, recorded.stages, recorded.description
    )
    tof = tof_sim_report(calibrate_tof_recording(rig_dir)[0], recorded.description)
    files = {
        "intrinsics": out_dir / INTRINSICS_NAME,
        "tof_camera": out_dir / TOF_NAME,
        "plot": out_dir / PLOT_NAME,
        "summary": out_dir / SUMMARY_NAME,
        "tof_rig": rig_dir,
    }
    intrinsics.result.save(files["intrinsics"])
    tof.calibration.save(files["tof_camera"])
    plot_curves(tof, files["plot"])
    files["summary"].write_text(json.dumps(summary(intrinsics, tof, tags), indent=1))
    print_summary(console, intrinsics, tof)
    fit = tags.fit
    console.print(
        f"[bold]Tag corners[/bold] ({fit.views} views, {tags.missed_views} missed): edge offset "
        f"{fit.bias.a_px:+.3f} {fit.bias.b_px:+.3f}·sin²2φ {fit.bias.c_px2:+.2f}/L px; corner "
        f"noise {fit.sigma_px:.3f} px after it ({fit.sigma_uncorrected_px:.3f} px before)"
    )
    if install:
        CALIBRATION_DIR.mkdir(parents=True, exist_ok=True)
        for key, name in (("intrinsics", INTRINSICS_NAME), ("tof_camera", TOF_NAME)):
            target = CALIBRATION_DIR / name
            shutil.copyfile(files[key], target)
            files[f"installed_{key}"] = target
    for key, path in files.items():
        console.print(f"{key}: {path}")
    return CalibrationRun(intrinsics=intrinsics, tof=tof, files=files, tag_corners=tags)
