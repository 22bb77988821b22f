"""The landing evaluation's summaries: one row per policy (success with its Wilson interval,
touchdown metrics, the oracles' columns), the Markdown table and the figure."""

from __future__ import annotations

import math
import textwrap
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib
import numpy as np

from agents.evaluation.records import EpisodeRecord
from agents.evaluation.summary import (
    Column,
    counts_cell,
    finite_mean,
    finite_p95,
    success_cell,
    success_fields,
)
from agents.evaluation.summary import markdown_table as summary_table
from agents.policies.registry import POLICIES
from landing_env.config import TouchdownConfig
from landing_env.scenarios import TIMING_TASK

matplotlib.use("Agg")
import matplotlib.pyplot as plt


@dataclass
class LandingSummary:
    """One policy on one scenario; touchdown metrics over the episodes that touched down."""

    policy: str
    scenario: str
    episodes: int
    successes: int
    success_rate: float
    success_ci_low: float
    success_ci_high: float
    normal_speed_mean: float
    normal_speed_p95: float
    deck_tilt_mean_deg: float
    deck_tilt_p95_deg: float
    lateral_offset_mean_m: float
    time_to_land_mean_s: float
    #: waved-off descents per episode (the timing task with ``timing.wave_off_tilt_deg``)
    wave_offs_mean: float = 0.0
    outcomes: dict[str, int] = field(default_factory=dict)
    #: how often each touchdown check failed (an episode can fail several), and crashes
    failures: dict[str, int] = field(default_factory=dict)
    bounce_p95_m: float = math.nan
    peak_load_p95_g: float = math.nan
    #: the oracle's success on the same seeds (NaN without it or outside the timing task)
    oracle_success_rate: float = math.nan
    #: oracle minus this policy, percentage points
    gap_points: float = math.nan
    #: this policy's failures on seeds where the oracle failed too: no timing avoids them
    unavoidable_failures: int = 0
    #: the deck oracle's success on the same seeds (it knows the deck's future, not the
    #: wind's: :class:`agents.policies.oracle.DeckOracleTimingPolicy`); NaN without it
    deck_oracle_success_rate: float = math.nan
    #: deck oracle minus this policy, percentage points
    deck_gap_points: float = math.nan


def compare_with_oracle(
    summaries: list[LandingSummary], results: dict[str, list[EpisodeRecord]]
) -> None:
    """Fill in the oracles' columns of the timing policies' summaries (seed by seed): the
    full oracle's, and the deck oracle's where it ran."""
    deck_oracle = results.get("deck-oracle")
    if deck_oracle:
        deck_rate = sum(r.success for r in deck_oracle) / len(deck_oracle)
        for summary in summaries:
            if is_timing(summary.policy):
                summary.deck_oracle_success_rate = deck_rate
                summary.deck_gap_points = 100.0 * (deck_rate - summary.success_rate)
    oracle = results.get("oracle")
    if not oracle:
        return
    oracle_success = {r.seed: r.success for r in oracle}
    rate = sum(oracle_success.values()) / len(oracle_success)
    for summary in summaries:
        if not is_timing(summary.policy):
            continue
        summary.oracle_success_rate = rate
        summary.gap_points = 100.0 * (rate - summary.success_rate)
        summary.unavoidable_failures = sum(
            1
            for r in results[summary.policy]
            if not r.success and oracle_success.get(r.seed) is False
        )


def is_timing(policy: str) -> bool:
    return policy in POLICIES and POLICIES[policy].task == TIMING_TASK


def summarise(results: list[EpisodeRecord]) -> LandingSummary:
    """The figures of the table for the episodes of one policy on one scenario."""

    def column(name: str) -> list[float]:
        return [getattr(r, name) for r in results]

    return LandingSummary(
        policy=results[0].policy if results else "",
        scenario=results[0].scenario if results else "",
        **success_fields(results),
        normal_speed_mean=finite_mean(column("relative_normal_speed")),
        normal_speed_p95=finite_p95(column("relative_normal_speed")),
        deck_tilt_mean_deg=finite_mean(column("deck_tilt_deg")),
        deck_tilt_p95_deg=finite_p95(column("deck_tilt_deg")),
        lateral_offset_mean_m=finite_mean(column("lateral_offset_m")),
        time_to_land_mean_s=finite_mean(column("time_to_land_s")),
        wave_offs_mean=float(np.mean([r.wave_offs for r in results])) if results else 0.0,
        outcomes=dict(Counter(r.outcome for r in results)),
        failures=dict(
            Counter(
                check
                for r in results
                if not r.success
                for check in (
                    r.failed_checks.split(";") if r.outcome == "hard_landing" else [r.outcome]
                )
                if check
            )
        ),
        bounce_p95_m=finite_p95(column("bounce_height_m")),
        peak_load_p95_g=finite_p95(column("peak_load_g")),
    )


def _oracle_cells(s: LandingSummary) -> tuple[str, str, str]:
    if not math.isfinite(s.oracle_success_rate):
        return ("", "", "")
    return (
        f"{100 * s.oracle_success_rate:.1f}%",
        f"{s.gap_points:+.1f}",
        f"{s.unavoidable_failures} of {s.episodes - s.successes}",
    )


def _deck_oracle_cells(s: LandingSummary) -> tuple[str, str]:
    if not math.isfinite(s.deck_oracle_success_rate):
        return ("", "")
    return (f"{100 * s.deck_oracle_success_rate:.1f}%", f"{s.deck_gap_points:+.1f}")


#: the columns of the landing table (:func:`agents.evaluation.summary.markdown_table`)
COLUMNS: tuple[Column, ...] = (
    Column("policy", lambda s: s.policy),
    Column("episodes", lambda s: str(s.episodes)),
    Column("success (95% CI)", success_cell),
    Column("v_n mean (m/s)", lambda s: f"{s.normal_speed_mean:.3f}"),
    Column("v_n p95 (m/s)", lambda s: f"{s.normal_speed_p95:.3f}"),
    Column(
        "tilt mean / p95 (deg)", lambda s: f"{s.deck_tilt_mean_deg:.2f} / {s.deck_tilt_p95_deg:.2f}"
    ),
    Column("offset mean (m)", lambda s: f"{s.lateral_offset_mean_m:.3f}"),
    Column("time to land (s)", lambda s: f"{s.time_to_land_mean_s:.2f}"),
    Column("wave-offs", lambda s: f"{s.wave_offs_mean:.2f}"),
    Column("bounce p95 (mm)", lambda s: f"{1000 * s.bounce_p95_m:.1f}"),
    Column("peak load p95 (g)", lambda s: f"{s.peak_load_p95_g:.1f}"),
    Column("outcomes", lambda s: counts_cell(s.outcomes)),
    Column("failed checks", lambda s: counts_cell(s.failures)),
    Column("oracle", lambda s: _oracle_cells(s)[0]),
    Column("gap (points)", lambda s: _oracle_cells(s)[1]),
    Column("failures no timing avoids", lambda s: _oracle_cells(s)[2]),
    Column("deck oracle", lambda s: _deck_oracle_cells(s)[0]),
    Column("gap to deck oracle", lambda s: _deck_oracle_cells(s)[1]),
)
TABLE_HEADER = tuple(c.header for c in COLUMNS)


def markdown_table(summaries: list[LandingSummary]) -> str:
    """The summaries as a Markdown table (one row per policy)."""
    return summary_table(summaries, COLUMNS)


def plot_results(
    results: dict[str, list[EpisodeRecord]],
    summaries: list[LandingSummary],
    path: Path,
    title: str,
    speed_limit: float | None = None,
    tilt_limit_deg: float | None = None,
) -> None:
    """Histograms of the touchdown's relative normal speed and deck tilt per policy (with the
    success limits, by default the touchdown checks' own), and success rates with their
    intervals."""

    import matplotlib

    matplotlib.use("Agg")

    limits = TouchdownConfig()
    speed_limit = limits.max_normal_speed if speed_limit is None else speed_limit
    tilt_limit_deg = limits.max_deck_tilt_deg if tilt_limit_deg is None else tilt_limit_deg
    fig, (ax_speed, ax_tilt, ax_bar) = plt.subplots(1, 3, figsize=(16, 4.8))
    for ax, field_name, limit, label, heading in (
        (
            ax_speed,
            "relative_normal_speed",
            speed_limit,
            "relative normal speed at touchdown (m/s)",
            "Touchdown speeds",
        ),
        (ax_tilt, "deck_tilt_deg", tilt_limit_deg, "deck tilt at touchdown (deg)", "Deck tilt"),
    ):
        values_all = [
            getattr(r, field_name)
            for rs in results.values()
            for r in rs
            if math.isfinite(getattr(r, field_name))
        ]
        bins = np.linspace(0.0, max([limit * 1.3, *values_all]), 31)
        for name, rs in results.items():
            values = [getattr(r, field_name) for r in rs if math.isfinite(getattr(r, field_name))]
            ax.hist(values, bins=bins, histtype="step", linewidth=1.8, label=name)
        ax.axvline(limit, color="k", linestyle="--", linewidth=1, label="success limit")
        ax.set(xlabel=label, ylabel="episodes", title=heading)
        ax.legend(fontsize="small")
    names = [s.policy for s in summaries]
    rates = np.array([100 * s.success_rate for s in summaries])
    errors = np.array(
        [
            [100 * (s.success_rate - s.success_ci_low) for s in summaries],
            [100 * (s.success_ci_high - s.success_rate) for s in summaries],
        ]
    )
    ax_bar.bar(names, rates, yerr=errors, capsize=6, color="tab:blue", alpha=0.8)
    for i, rate in enumerate(rates):
        ax_bar.text(i, 2, f"{rate:.1f}%", ha="center", color="white", fontweight="bold")
    ax_bar.set(ylim=(0, 105), ylabel="success rate (%)", title="Success with 95% Wilson interval")
    ax_bar.tick_params(axis="x", labelrotation=20 if len(names) > 3 else 0)
    fig.suptitle(textwrap.fill(title, 170), fontsize="medium")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
