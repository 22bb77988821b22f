"""The one home of a policy evaluation's summary: success with its interval, and the table.

``evaluate landing`` and ``evaluate approach`` summarise their episodes alike and show
different columns of it (the landing table has the touchdown checks and the oracle, the
approach table the landing error and the relocations):

* :func:`wilson_interval` and :func:`success_fields`: the success rate with its 95 % Wilson
  interval, the fields every summary starts with;
* :func:`finite_mean`, :func:`finite_p95`: statistics over the episodes where a metric exists
  (NaN when none has it);
* :class:`Summary` and :func:`summarise`: one policy's figures over its episodes, and
  :func:`compare_with_oracle`, the timing policies' gap to the oracles run beside them;
* :data:`COLUMNS`, :func:`columns` and :func:`markdown_table`: a summary table from the
  columns an evaluation picks (written and shown by
  :class:`agents.evaluation.pipeline.Evaluated`).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agents.evaluation.records import APPROACH, LANDING, EpisodeRecord
from agents.policies.registry import POLICIES
from landing_env.scenarios import TIMING_TASK


def wilson_interval(successes: int, trials: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval of a success rate (scipy's ``binomtest``)."""
    from scipy.stats import binomtest

    if trials == 0:
        return math.nan, math.nan
    ci = binomtest(successes, trials).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def success_fields(records: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """``episodes``, ``successes``, ``success_rate`` and its 95 % Wilson interval
    (``success_ci_low``, ``success_ci_high``) over ``records``."""
    if not records:
        raise ValueError("no episodes to summarise")
    n = len(records)
    k = sum(bool(r.success) for r in records)
    low, high = wilson_interval(k, n)
    return {
        "episodes": n,
        "successes": k,
        "success_rate": k / n,
        "success_ci_low": low,
        "success_ci_high": high,
    }


def finite(values: Iterable[float]) -> np.ndarray:
    """The finite values (a metric is NaN where it does not exist, e.g. after a crash)."""
    array = np.asarray(list(values), dtype=float)
    return array[np.isfinite(array)]


def finite_mean(values: Iterable[float]) -> float:
    """Mean over the finite values; NaN when there is none."""
    array = finite(values)
    return float(array.mean()) if array.size else math.nan


def finite_p95(values: Iterable[float]) -> float:
    """95th percentile over the finite values; NaN when there is none."""
    array = finite(values)
    return float(np.percentile(array, 95)) if array.size else math.nan


# ------------------------------------------------------------------------------ the summary
@dataclass
class Summary:
    """One policy on one scenario: every figure a table or a JSON summary shows (touchdown
    metrics over the episodes that touched down); the fields marked with an evaluation's name
    are that evaluation's alone (:func:`~agents.evaluation.records.own_fields`)."""

    policy: str
    scenario: str = field(metadata=LANDING)
    estimator: str = field(metadata=APPROACH)
    episodes: int
    successes: int
    success_rate: float
    success_ci_low: float
    success_ci_high: float
    normal_speed_mean: float
    normal_speed_p95: float = field(metadata=LANDING)
    deck_tilt_mean_deg: float
    deck_tilt_p95_deg: float = field(metadata=LANDING)
    lateral_offset_mean_m: float
    lateral_offset_p95_m: float = field(metadata=APPROACH)
    #: the SVGS paper's landing error
    landing_error_mean_m: float = field(metadata=APPROACH)
    landing_error_p95_m: float = field(metadata=APPROACH)
    time_to_land_mean_s: float
    time_to_land_p95_s: float = field(metadata=APPROACH)
    #: waved-off descents per episode (the timing task with ``timing.wave_off_tilt_deg``)
    wave_offs_mean: float = field(metadata=LANDING)
    #: relocations and searches over all episodes
    relocations: int = field(metadata=APPROACH)
    searches: int = field(metadata=APPROACH)
    outcomes: dict[str, int]
    #: how often each touchdown check failed (an episode can fail several), and crashes
    failures: dict[str, int] = field(metadata=LANDING)
    bounce_p95_m: float = field(metadata=LANDING)
    peak_load_p95_g: float = field(metadata=LANDING)
    #: the oracle's success on the same seeds (NaN without it or outside the timing task)
    oracle_success_rate: float = field(default=math.nan, metadata=LANDING)
    #: oracle minus this policy, percentage points
    gap_points: float = field(default=math.nan, metadata=LANDING)
    #: this policy's failures on seeds where the oracle failed too: no timing avoids them
    unavoidable_failures: int = field(default=0, metadata=LANDING)
    #: the deck oracle's success on the same seeds (it knows the deck's future, not the
    #: wind's: :class:`agents.policies.oracle.DeckOracleTimingPolicy`); NaN without it
    deck_oracle_success_rate: float = field(default=math.nan, metadata=LANDING)
    #: deck oracle minus this policy, percentage points
    deck_gap_points: float = field(default=math.nan, metadata=LANDING)


def summarise(records: Sequence[EpisodeRecord]) -> Summary:
    """The figures of one policy's episodes on one scenario."""

    def mean(name: str) -> float:
        return finite_mean(getattr(r, name) for r in records)

    def p95(name: str) -> float:
        return finite_p95(getattr(r, name) for r in records)

    failed = (
        r.failed_checks.split(";") if r.outcome == "hard_landing" else [r.outcome]
        for r in records
        if not r.success
    )
    return Summary(
        policy=records[0].policy if records else "",
        scenario=records[0].scenario if records else "",
        estimator=records[0].estimator if records else "",
        **success_fields(records),
        normal_speed_mean=mean("relative_normal_speed"),
        normal_speed_p95=p95("relative_normal_speed"),
        deck_tilt_mean_deg=mean("deck_tilt_deg"),
        deck_tilt_p95_deg=p95("deck_tilt_deg"),
        lateral_offset_mean_m=mean("lateral_offset_m"),
        lateral_offset_p95_m=p95("lateral_offset_m"),
        landing_error_mean_m=mean("landing_error_m"),
        landing_error_p95_m=p95("landing_error_m"),
        time_to_land_mean_s=mean("time_to_land_s"),
        time_to_land_p95_s=p95("time_to_land_s"),
        wave_offs_mean=float(np.mean([r.wave_offs for r in records])),
        relocations=sum(r.relocations for r in records),
        searches=sum(r.searches for r in records),
        outcomes=dict(Counter(r.outcome for r in records)),
        failures=dict(Counter(check for checks in failed for check in checks if check)),
        bounce_p95_m=p95("bounce_height_m"),
        peak_load_p95_g=p95("peak_load_g"),
    )


def is_timing(policy: str) -> bool:
    """Whether ``policy`` is a registered policy of the timing task."""
    return policy in POLICIES and POLICIES[policy].task == TIMING_TASK


def compare_with_oracle(summaries: list[Summary], results: dict[str, list[EpisodeRecord]]) -> None:
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


# ------------------------------------------------------------------------------ the table
def success_cell(summary: Any) -> str:
    """``97.0% (93.6–98.6)``: the success rate and its interval, in percent."""
    return (
        f"{100 * summary.success_rate:.1f}% ({100 * summary.success_ci_low:.1f}–"
        f"{100 * summary.success_ci_high:.1f})"
    )


def counts_cell(counts: dict[str, int]) -> str:
    """``hard_landing 6, success 194`` (sorted by name); ``-`` when empty."""
    return ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "-"


@dataclass(frozen=True)
class Column:
    """A column of a summary table: its header and how a summary fills its cell (a function,
    or a format string of the summary ``s``)."""

    header: str
    cell: Callable[[Any], str] | str

    def fill(self, summary: Any) -> str:
        return self.cell.format(s=summary) if isinstance(self.cell, str) else self.cell(summary)


def _oracle_cells(s: Summary) -> tuple[str, str, str]:
    if not math.isfinite(s.oracle_success_rate):
        return ("", "", "")
    return (
        f"{100 * s.oracle_success_rate:.1f}%",
        f"{s.gap_points:+.1f}",
        f"{s.unavoidable_failures} of {s.episodes - s.successes}",
    )


def _deck_oracle_cells(s: Summary) -> tuple[str, str]:
    if not math.isfinite(s.deck_oracle_success_rate):
        return ("", "")
    return (f"{100 * s.deck_oracle_success_rate:.1f}%", f"{s.deck_gap_points:+.1f}")


#: every column a summary table can have, by header; an evaluation picks its own (:func:`columns`)
COLUMNS: dict[str, Column] = {
    c.header: c
    for c in (
        Column("policy", "{s.policy}"),
        Column("estimator", "{s.estimator}"),
        Column("episodes", "{s.episodes}"),
        Column("success (95% CI)", success_cell),
        Column("v_n mean (m/s)", "{s.normal_speed_mean:.3f}"),
        Column("v_n p95 (m/s)", "{s.normal_speed_p95:.3f}"),
        Column("tilt mean / p95 (deg)", "{s.deck_tilt_mean_deg:.2f} / {s.deck_tilt_p95_deg:.2f}"),
        Column("deck tilt mean (deg)", "{s.deck_tilt_mean_deg:.2f}"),
        Column("offset mean (m)", "{s.lateral_offset_mean_m:.3f}"),
        Column(
            "offset mean / p95 (m)", "{s.lateral_offset_mean_m:.3f} / {s.lateral_offset_p95_m:.3f}"
        ),
        Column(
            "landing error mean / p95 (m)",
            "{s.landing_error_mean_m:.3f} / {s.landing_error_p95_m:.3f}",
        ),
        Column("time to land (s)", "{s.time_to_land_mean_s:.2f}"),
        Column(
            "time to land mean / p95 (s)",
            "{s.time_to_land_mean_s:.1f} / {s.time_to_land_p95_s:.1f}",
        ),
        Column("wave-offs", "{s.wave_offs_mean:.2f}"),
        Column("bounce p95 (mm)", lambda s: f"{1000 * s.bounce_p95_m:.1f}"),
        Column("peak load p95 (g)", "{s.peak_load_p95_g:.1f}"),
        Column("relocations / searches", "{s.relocations} / {s.searches}"),
        Column("outcomes", lambda s: counts_cell(s.outcomes)),
        Column("failed checks", lambda s: counts_cell(s.failures)),
        Column("oracle", lambda s: _oracle_cells(s)[0]),
        Column("gap (points)", lambda s: _oracle_cells(s)[1]),
        Column("failures no timing avoids", lambda s: _oracle_cells(s)[2]),
        Column("deck oracle", lambda s: _deck_oracle_cells(s)[0]),
        Column("gap to deck oracle", lambda s: _deck_oracle_cells(s)[1]),
    )
}


def columns(*headers: str) -> tuple[Column, ...]:
    """The columns of :data:`COLUMNS` with these headers, in this order."""
    unknown = [h for h in headers if h not in COLUMNS]
    if unknown:
        raise ValueError(f"no table column {unknown[0]!r}; allowed: {sorted(COLUMNS)}")
    return tuple(COLUMNS[h] for h in headers)


def markdown_rows(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A Markdown table: one cell per value, on one line, ``|`` escaped."""

    def cell(value: Any) -> str:
        return " ".join(str(value).split()).replace("|", "\\|")

    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(cell(value) for value in row) + " |" for row in rows]
    return "\n".join(lines)


def markdown_table(summaries: Sequence[Any], columns: Sequence[Column]) -> str:
    """One row per summary."""
    return markdown_rows(
        [c.header for c in columns], ([c.fill(summary) for c in columns] for summary in summaries)
    )
