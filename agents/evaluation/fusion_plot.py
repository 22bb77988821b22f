"""The fusion through a vision dropout: raw (delayed) estimates, held estimates, fused, truth.

For a run with ``fused`` behind the vision link (``configs/realistic-degraded.yaml``): the
window around the longest gap between deliveries, for z and roll.  Each raw estimate is a
marker at its image's capture time (where it belongs) and the held estimate a step line (what
a policy sees, late); the fused estimate is drawn with its ±2-sigma band.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agents.evaluation.plots import _colour, pyplot, save_figure
from agents.evaluation.records import ScenarioRecord, display_name, to_table_units

#: (axis index, label, scale from m / degrees to the plotted unit)
_PANELS: tuple[tuple[int, str, float], ...] = ((2, "z (mm)", 1000.0), (3, "roll (°)", 1.0))


def longest_gap(capture_time_s: np.ndarray, time_s: np.ndarray) -> tuple[float, float]:
    """(start, end) of the longest stretch without a new delivery: between the frames at which
    the shown estimate's capture time changed (NaN frames count as no delivery)."""
    captured = np.nan_to_num(capture_time_s, nan=-1.0)
    changes = np.flatnonzero(np.diff(captured) != 0.0) + 1
    if len(changes) < 2:
        return float(time_s[0]), float(time_s[-1])
    gaps = np.diff(time_s[changes])
    i = int(np.argmax(gaps))
    return float(time_s[changes[i]]), float(time_s[changes[i + 1]])


def plot_fusion_dropout(
    record: ScenarioRecord,
    path: Path,
    window_s: float = 5.0,
    reference: str = "atda",
    shown: tuple[str, ...] = ("atda", "crhf"),
) -> Path:
    """Write the figure to ``path`` (PNG) and return the path.

    ``shown``: the delayed estimators drawn (IHRCF's z and roll are CRHF's: the same ToF
    plane); ``reference``: the one whose longest gap between deliveries is centred.
    """
    time = record.time_s
    delayed = [
        n for n, tr in record.estimates.items() if n in shown and tr.capture_time_s is not None
    ]
    ref = reference if reference in delayed else (delayed[0] if delayed else None)
    if ref is not None:
        trace = record.estimates[ref]
        assert trace.capture_time_s is not None
        gap = longest_gap(trace.capture_time_s, time)
    else:
        gap = (float(time[0]), float(time[0]))
    centre = 0.5 * (gap[0] + gap[1])
    lo = max(float(time[0]), centre - 0.5 * window_s)
    hi = min(float(time[-1]), lo + window_s)
    frames = (time >= lo) & (time <= hi)
    truth = to_table_units(record.truth)
    fig, axes = pyplot().subplots(len(_PANELS), 1, figsize=(9, 6.5), sharex=True)
    for ax, (axis, label, scale) in zip(axes, _PANELS, strict=True):
        ax.axvspan(*gap, color="lightsteelblue", alpha=0.35, lw=0, zorder=0, label="no delivery")
        for index, name in enumerate(delayed):
            trace = record.estimates[name]
            values = to_table_units(trace.pose)[:, axis] * scale
            colour = _colour(name, index)
            ax.step(
                time[frames],
                values[frames],
                where="post",
                color=colour,
                lw=0.8,
                alpha=0.6,
                label=f"{display_name(name)} as shown (held, late)",
            )
            assert trace.capture_time_s is not None
            fresh = np.flatnonzero(np.diff(np.nan_to_num(trace.capture_time_s, nan=-1.0))) + 1
            fresh = fresh[frames[fresh] & trace.valid[fresh]]
            ax.plot(
                trace.capture_time_s[fresh],
                values[fresh],
                "o",
                ms=3.5,
                color=colour,
                label=f"{display_name(name)} raw, at capture time",
            )
        fused = record.estimates.get("fused")
        if fused is not None:
            values = to_table_units(fused.pose)[:, axis] * scale
            ax.plot(time[frames], values[frames], color="black", lw=1.3, label="fused (EKF)")
            if fused.std is not None:
                std = fused.std[:, axis] * (np.degrees(1.0) if axis >= 3 else 1.0) * scale
                ax.fill_between(
                    time[frames],
                    (values - 2 * std)[frames],
                    (values + 2 * std)[frames],
                    color="black",
                    alpha=0.12,
                    lw=0,
                    label="fused ±2σ",
                )
        ax.plot(
            time[frames],
            truth[frames, axis] * scale,
            color="tab:green",
            lw=1.3,
            ls=(0, (4, 3)),
            zorder=5,
            label="truth",
        )
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=7, ncol=2)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(
        f"{record.scenario}: a vision dropout of {gap[1] - gap[0]:.2f} s (seed {record.seed})"
    )
    return save_figure(fig, path)
