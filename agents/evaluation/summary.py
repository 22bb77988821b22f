"""The one home of a policy evaluation's summary: success with its interval, the table, the files.

``evaluate landing`` and ``evaluate approach`` summarise their episodes differently (the
landing table has the touchdown checks and the oracle, the approach table the relocations),
but everything else is the same and lives here:

* :func:`wilson_interval` and :func:`success_fields`: the success rate with its 95 % Wilson
  interval, the fields every summary starts with;
* :func:`finite_mean`, :func:`finite_p95`: statistics over the episodes where a metric exists
  (NaN when none has it);
* :class:`Column` and :func:`markdown_table`: a summary table from a list of columns;
* :func:`write_summary_files`: the Markdown table, the JSON summary and the CSV of every
  episode, under one stem, and :func:`failures_note` for the seeds whose worker crashed;
* :func:`print_summary`: the same on the console.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.records import EpisodeRecord


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
    """A column of a summary table: its header and how a summary fills its cell."""

    header: str
    cell: Callable[[Any], str]


def markdown_table(summaries: Sequence[Any], columns: Sequence[Column]) -> str:
    """One row per summary."""
    lines = [
        "| " + " | ".join(c.header for c in columns) + " |",
        "|" + "|".join("---" for _ in columns) + "|",
    ]
    for summary in summaries:
        lines.append("| " + " | ".join(c.cell(summary) for c in columns) + " |")
    return "\n".join(lines)


def failures_note(failures: dict[str, list[Any]]) -> str:
    """A line per crashed seed, for the table's file (empty when none crashed)."""
    if not failures:
        return ""
    lines = ["", "Seeds whose worker crashed (not in the table):", ""]
    for name, fs in failures.items():
        lines += [f"- {name}, seed {f.seed}: {f.error}" for f in fs]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------ the files
def write_summary_files(
    out_dir: Path,
    stem: str,
    *,
    heading: str,
    title: str,
    table: str,
    summaries: Sequence[Any],
    results: dict[str, list[Any]],
    failures: dict[str, list[Any]],
    settings: dict[str, Any],
    command: str = "",
    notes: str = "",
    csv_exclude: tuple[str, ...] = (),
) -> list[Path]:
    """Write ``STEM.md`` (heading, title, command, table, notes, crashed seeds), ``STEM.json``
    (``settings``, the command and every summary) and ``STEM_episodes.csv`` (one row per
    episode, every record column but ``csv_exclude``); the paths written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    markdown = out_dir / f"{stem}.md"
    markdown.write_text(
        f"# {heading}\n\n{title}\n\n"
        + (f"Command: `{command}`\n\n" if command else "")
        + table
        + "\n"
        + (f"\n{notes}\n" if notes else "")
        + failures_note(failures)
    )
    summary_json = out_dir / f"{stem}.json"
    summary_json.write_text(
        json.dumps(
            {**settings, "command": command, "summaries": [asdict(s) for s in summaries]},
            indent=2,
        )
    )
    episodes_csv = out_dir / f"{stem}_episodes.csv"
    first = next(iter(results.values()))[0]
    columns = [k for k in asdict(first) if k not in csv_exclude]
    with episodes_csv.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for records in results.values():
            writer.writerows(asdict(r) for r in records)
    return [markdown, summary_json, episodes_csv]


def print_summary(
    heading: str, table: str, failures: dict[str, list[Any]], files: Sequence[Path]
) -> None:
    """The table, the crashed seeds and the files written, on the console."""
    from rich.console import Console

    console = Console()
    console.print(f"\n[bold]{heading}[/bold]")
    print(table)
    note = failures_note(failures)
    if note:
        console.print(note, style="yellow")
    for path in files:
        console.print(f"  wrote {path}")


__all__ = [
    "Column",
    "counts_cell",
    "failures_note",
    "finite",
    "finite_mean",
    "finite_p95",
    "markdown_table",
    "print_summary",
    "success_cell",
    "success_fields",
    "wilson_interval",
    "write_summary_files",
]
