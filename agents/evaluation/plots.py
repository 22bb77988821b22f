"""Figures of an estimator evaluation, in the papers' manner (IHRCF Figs. 14-20, CRHF 24-30).

Ground truth in green, as in the papers; invalid frames are gaps in the lines.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from agents.evaluation.records import (
    AXES,
    ScenarioRecord,
    display_name,
    pose_errors,
    to_table_units,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: the papers' colours: ground truth green, IHRCF blue, ATDA red; CRHF gets purple here
COLOURS: dict[str, str] = {
    "truth": "tab:green",
    "atda": "tab:red",
    "ihrcf": "tab:blue",
    "crhf": "tab:purple",
    "tight": "tab:orange",
}
_AXIS_COLOURS = ("tab:blue", "tab:red", "goldenrod")
DPI = 110


def _colour(name: str, index: int) -> str:
    return COLOURS.get(name, f"C{(index + 4) % 10}")


def _line(name: str) -> dict:
    # the truth is drawn last and dashed, so that it shows over estimates that hug it
    if name == "truth":
        return {"lw": 1.3, "ls": (0, (4, 3)), "zorder": 5}
    return {"lw": 0.9, "alpha": 0.9}


def _series(record: ScenarioRecord) -> dict[str, np.ndarray]:
    """Truth and every estimate in m and degrees, NaN where invalid."""
    series = {"truth": to_table_units(record.truth)}
    for name, trace in record.estimates.items():
        series[name] = to_table_units(trace.pose)
    return series


def pyplot() -> ModuleType:
    """``matplotlib.pyplot`` drawing to files (the Agg backend), imported when a figure is
    first drawn: a command that draws none does not load it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Figure, path: Path) -> Path:
    """Lay ``fig`` out, write it to ``path`` (its folder made if missing) and close it."""
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    pyplot().close(fig)
    return path


def plot_against_time(record: ScenarioRecord, path: Path, angles: bool) -> Path:
    """Three stacked panels (x, y, z or roll, pitch, yaw) against time, truth and estimates."""
    series = _series(record)
    t = record.time_s
    columns = range(3, 6) if angles else range(3)
    unit = "deg" if angles else "m"
    fig, axes = pyplot().subplots(3, 1, figsize=(10, 7.5), sharex=True)
    for ax, k in zip(axes, columns, strict=True):
        for i, (name, values) in enumerate(series.items()):
            label = "GT" if name == "truth" else display_name(name)
            ax.plot(t, values[:, k], color=_colour(name, i), label=label, **_line(name))
        ax.set_ylabel(f"{AXES[k]} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", ncol=len(series), fontsize=8)
    axes[-1].set_xlabel("time (s)")
    kind = "Euler angles (ZYX) of the tag" if angles else "Translation of the tag"
    axes[0].set_title(f"{record.scenario}: {kind} in the camera frame")
    return save_figure(fig, path)


def plot_trajectories(record: ScenarioRecord, path: Path) -> Path:
    """The tag's track in the camera frame: XZ, YZ, XY views and the XYZ view."""
    series = _series(record)
    fig = pyplot().figure(figsize=(11, 9))
    views = ((0, 2, "XZ view"), (1, 2, "YZ view"), (0, 1, "XY view"))
    for panel, (a, b, title) in enumerate(views, start=1):
        ax = fig.add_subplot(2, 2, panel)
        for i, (name, values) in enumerate(series.items()):
            label = "GT" if name == "truth" else display_name(name)
            ax.plot(values[:, a], values[:, b], color=_colour(name, i), label=label, **_line(name))
        ax.set(xlabel=f"{AXES[a]} (m)", ylabel=f"{AXES[b]} (m)", title=title)
        if b == 2:
            ax.invert_yaxis()  # z is the distance below the camera: deeper is lower
        ax.grid(alpha=0.3)
    fig.axes[0].legend(fontsize=8)
    ax3 = fig.add_subplot(2, 2, 4, projection="3d")
    for i, (name, values) in enumerate(series.items()):
        ax3.plot(values[:, 0], values[:, 1], values[:, 2], color=_colour(name, i), **_line(name))
    ax3.set(xlabel="x (m)", ylabel="y (m)", zlabel="z (m)", title="XYZ view")
    ax3.invert_zaxis()
    fig.suptitle(f"{record.scenario}: trajectory of the tag in the camera frame")
    return save_figure(fig, path)


def plot_errors(record: ScenarioRecord, path: Path) -> Path:
    """Absolute errors per axis against time: per estimator, translations and angles."""
    names = list(record.estimates)
    t = record.time_s
    fig, axes = pyplot().subplots(
        len(names), 2, figsize=(12, 2.6 * len(names) + 0.6), sharex=True, squeeze=False
    )
    for row, name in enumerate(names):
        error = np.abs(pose_errors(record.estimates[name].pose, record.truth))
        for col, (first, unit) in enumerate(((0, "m"), (3, "deg"))):
            ax = axes[row, col]
            for j in range(3):
                ax.plot(
                    t, error[:, first + j], color=_AXIS_COLOURS[j], lw=0.9, label=AXES[first + j]
                )
            invalid = ~record.estimates[name].valid
            if invalid.any():
                # invalid frames are not errors of zero: mark them along the time axis
                ax.plot(
                    t[invalid],
                    np.zeros(int(invalid.sum())),
                    "|",
                    color="0.4",
                    ms=8,
                    label=f"invalid ({int(invalid.sum())})",
                )
            kind = "translation" if col == 0 else "angle"
            ax.set(ylabel=f"|error| ({unit})", title=f"{display_name(name)} {kind} errors")
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", ncol=4, fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    return save_figure(fig, path)


def plot_all(record: ScenarioRecord, out_dir: Path) -> list[Path]:
    """Every figure of a run, as PNG files in ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    return [
        plot_against_time(record, out_dir / "angles.png", angles=True),
        plot_against_time(record, out_dir / "translations.png", angles=False),
        plot_trajectories(record, out_dir / "trajectory.png"),
        plot_errors(record, out_dir / "errors.png"),
    ]
