"""The committed result summaries: one JSON file per evaluation, the one home of every
published figure.

A summary, ``configs/results/<name>.json`` (package data, so an installed ``deck-landing``
reads it too), holds one ``evaluate landing`` run: ``title``, ``date`` (YYYY-MM-DD), ``commit``
(the commit it was measured at), ``command`` (what reproduces it), ``scenario``, ``sensing``,
``estimator`` (optional: the estimate observed, when the run set it), ``episodes`` (per
policy), ``first_seed`` (the seeds are ``first_seed`` on), ``rows`` (one per policy:
``policy``, ``successes``, ``episodes``, ``success_pct`` and the 95 % Wilson interval
``ci95_low_pct``-``ci95_high_pct``), and optionally ``note`` and ``chosen_by`` (for a figure
that reports a choice: what chose the policy, on other seeds).

The registry (:data:`agents.policies.registry.RECOMMENDED`) names, per setting, the policy
and the summary that measures it, and no number; :func:`recommended_figures` joins the two,
and :func:`default_figures` gives every scenario's default policy its figure.  What the README
and the docs show of them is written by :mod:`agents.cli.pages`.

To add a result, write its summary from an evaluation's output (the run's
``results/landing/landing_<scenario>.json``)::

    python -m agents.evaluation.results add results/landing/landing_bench-ss5.json \\
        --name bench-ss5-realistic-heldout --title "..." --commit abc1234
"""

from __future__ import annotations

import argparse
import datetime
import functools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.evaluation.summary import wilson_interval
from agents.policies.registry import (
    DEFAULT_POLICY,
    RECOMMENDED,
    Recommendation,
    env_settings,
    scenario_config,
)
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.resources import config_dir
from landing_env.scenarios import SCENARIO_IDS

#: a summary's fields and their types (``estimator``, ``note`` and ``chosen_by`` optional)
FIELDS: dict[str, type] = {
    "title": str,
    "date": str,
    "commit": str,
    "command": str,
    "scenario": str,
    "sensing": str,
    "episodes": int,
    "first_seed": int,
    "rows": list,
}
OPTIONAL_FIELDS: dict[str, type] = {"estimator": str, "note": str, "chosen_by": str}
ROW_FIELDS: dict[str, type | tuple[type, ...]] = {
    "policy": str,
    "successes": int,
    "episodes": int,
    "success_pct": (int, float),
    "ci95_low_pct": (int, float),
    "ci95_high_pct": (int, float),
}
#: how far a stored percentage may lie from the one its counts give (one rounding step)
PCT_TOLERANCE = 0.051


def summary_dir() -> Path:
    """Where the summaries are: ``configs/results`` (in a wheel, the configs' package)."""
    return config_dir() / "results"


@dataclass(frozen=True)
class ResultRow:
    """One policy's outcome in a summary."""

    policy: str
    successes: int
    episodes: int

    @property
    def success_pct(self) -> float:
        return 100.0 * self.successes / self.episodes

    @property
    def ci95_pct(self) -> tuple[float, float]:
        """The 95 % Wilson interval, in percent."""
        low, high = wilson_interval(self.successes, self.episodes)
        return 100.0 * low, 100.0 * high

    def cell(self) -> str:
        """``82.5 % (76.6-87.1)``."""
        low, high = self.ci95_pct
        return f"{self.success_pct:.1f} % ({low:.1f}-{high:.1f})"


@dataclass(frozen=True)
class ResultSummary:
    """One committed evaluation (see the module docstring)."""

    name: str
    title: str
    date: str
    commit: str
    command: str
    scenario: str
    sensing: str
    episodes: int
    first_seed: int
    rows: tuple[ResultRow, ...]
    estimator: str | None = None
    note: str | None = None
    chosen_by: str | None = None

    def row(self, policy: str) -> ResultRow:
        """The row of ``policy`` (refused naming the summary's policies)."""
        for row in self.rows:
            if row.policy == policy:
                return row
        names = ", ".join(row.policy for row in self.rows)
        raise ConfigError(f"results/{self.name}", f"no row for {policy} (it has {names})")

    def has(self, policy: str) -> bool:
        return any(row.policy == policy for row in self.rows)

    @property
    def seeds(self) -> str:
        """``200 seeds from 5 000 000``."""
        return f"{self.episodes} seeds from {spaced(self.first_seed)}"


def spaced(number: int) -> str:
    """``5000000`` as ``5 000 000``."""
    return f"{number:_}".replace("_", " ")


def _require(where: str, data: dict[str, Any], fields: dict[str, Any], optional: bool) -> None:
    for key, kind in fields.items():
        if key not in data:
            if optional:
                continue
            raise ConfigError(where, f"field {key!r} is missing")
        value = data[key]
        if not isinstance(value, kind) or isinstance(value, bool):
            raise ConfigError(where, f"field {key!r} = {value!r} has the wrong type")


def parse_summary(name: str, data: Any) -> ResultSummary:
    """A summary's JSON checked: every field present and typed, the date a date, each row's
    counts inside its episodes and its percentages those the counts give (Wilson)."""
    where = f"configs/results/{name}.json"
    if not isinstance(data, dict):
        raise ConfigError(where, "a result summary is a JSON object")
    _require(where, data, FIELDS, optional=False)
    _require(where, data, OPTIONAL_FIELDS, optional=True)
    unknown = set(data) - set(FIELDS) - set(OPTIONAL_FIELDS)
    if unknown:
        allowed = ", ".join([*FIELDS, *OPTIONAL_FIELDS])
        raise ConfigError(where, f"unknown fields {sorted(unknown)} (allowed: {allowed})")
    try:
        datetime.date.fromisoformat(data["date"])
    except ValueError:
        raise ConfigError(where, f"field 'date' = {data['date']!r} is not YYYY-MM-DD") from None
    if not data["rows"]:
        raise ConfigError(where, "field 'rows' is empty")
    rows = []
    for i, raw in enumerate(data["rows"]):
        at = f"{where}: rows[{i}]"
        if not isinstance(raw, dict):
            raise ConfigError(at, "is not an object")
        _require(at, raw, ROW_FIELDS, optional=False)
        if raw["episodes"] <= 0 or not 0 <= raw["successes"] <= raw["episodes"]:
            raise ConfigError(at, "successes must lie in 0..episodes, episodes > 0")
        row = ResultRow(raw["policy"], raw["successes"], raw["episodes"])
        low, high = row.ci95_pct
        for key, value in (
            ("success_pct", row.success_pct),
            ("ci95_low_pct", low),
            ("ci95_high_pct", high),
        ):
            if not math.isclose(raw[key], value, abs_tol=PCT_TOLERANCE):
                raise ConfigError(
                    at, f"{key} = {raw[key]} but its counts give {value:.1f} (95 % Wilson)"
                )
        rows.append(row)
    fields = {key: data[key] for key in (*FIELDS, *OPTIONAL_FIELDS) if key in data}
    fields["rows"] = tuple(rows)
    return ResultSummary(name=name, **fields)


def load_summary(path: Path) -> ResultSummary:
    """The summary in ``path`` (a clear error naming the file when it cannot be read)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as error:
        raise ConfigError(str(path), f"cannot read a result summary ({error})") from None
    return parse_summary(path.stem, data)


@functools.cache
def summaries() -> dict[str, ResultSummary]:
    """Every committed summary by name, in name order."""
    paths = sorted(summary_dir().glob("*.json"), key=lambda path: path.stem)
    return {path.stem: load_summary(path) for path in paths}


def summary(name: str) -> ResultSummary:
    """The committed summary ``name`` (refused naming the ones there are)."""
    table = summaries()
    if name not in table:
        raise ConfigError("summary", f"{name!r} is not in configs/results (there: {list(table)})")
    return table[name]


@dataclass(frozen=True)
class Figure:
    """A policy's figure: its row in a summary, for one setting or scenario."""

    label: str
    policy: str
    result: ResultSummary

    @property
    def row(self) -> ResultRow:
        return self.result.row(self.policy)


def recommended_figures() -> list[Figure]:
    """The registry's recommendations with their figures, setting by setting; a
    recommendation whose summary contradicts it (scenario, sensing, no row) is refused."""
    return [_checked(rec) for rec in RECOMMENDED]


def _checked(rec: Recommendation) -> Figure:
    result = summary(rec.summary)
    where = f"RECOMMENDED[{rec.setting}]"
    if (result.scenario, result.sensing) != (rec.scenario, rec.sensing):
        raise ConfigError(
            where,
            f"{rec.summary} measured {result.scenario} with {result.sensing} sensing, not "
            f"{rec.scenario} with {rec.sensing}",
        )
    if not result.has(rec.policy):
        raise ConfigError(where, f"{rec.summary} has no row for {rec.policy}")
    return Figure(rec.setting, rec.policy, result)


def default_figures() -> list[Figure]:
    """Every scenario's default policy (what ``evaluate landing --scenario S`` flies) with its
    figure: the recommendation's for a recommended scenario (realistic sensing where there are
    several), else the summary of the scenario with a row for it on the latest seeds (the
    held-out ones, which follow the selection seeds); two on the same seeds are refused."""
    recommended = {}
    for figure in recommended_figures():
        scenario = figure.result.scenario
        if scenario not in recommended or figure.result.sensing == "realistic":
            recommended[scenario] = figure
    figures = []
    for scenario, policy in DEFAULT_POLICY.items():
        if scenario in recommended:
            figures.append(Figure(scenario, policy, recommended[scenario].result))
            continue
        found = [s for s in summaries().values() if s.scenario == scenario and s.has(policy)]
        latest = [s for s in found if s.first_seed == max(r.first_seed for r in found)]
        if len(latest) != 1:
            names = [s.name for s in latest] or "none"
            raise ConfigError(
                "DEFAULT_POLICY",
                f"{scenario} flies {policy}, which needs one summary in configs/results "
                f"with its figure on the latest seeds (found: {names})",
            )
        figures.append(Figure(scenario, policy, latest[0]))
    return figures


# ------------------------------------------------------------------------ writing a summary
def summary_from_run(
    run: dict[str, Any],
    title: str,
    commit: str,
    date: str,
    sensing: str,
    note: str | None = None,
    chosen_by: str | None = None,
    policies: Sequence[str] = (),
) -> dict[str, Any]:
    """A summary's JSON from an ``evaluate landing`` run's ``landing_<scenario>.json``
    (its ``summaries``, restricted to ``policies`` when given)."""
    rows = []
    for entry in run["summaries"]:
        if policies and entry["policy"] not in policies:
            continue
        row = ResultRow(entry["policy"], int(entry["successes"]), int(entry["episodes"]))
        low, high = row.ci95_pct
        rows.append(
            {
                "policy": row.policy,
                "successes": row.successes,
                "episodes": row.episodes,
                "success_pct": round(row.success_pct, 1),
                "ci95_low_pct": round(low, 1),
                "ci95_high_pct": round(high, 1),
            }
        )
    if not rows:
        raise ConfigError("--policy", f"none of {list(policies)} ran in this evaluation")
    estimator = run.get("estimator")
    if estimator is None:  # each policy's own: named when they share one
        own = {observed_estimator(row["policy"], run["scenario"]) for row in rows}
        estimator = own.pop() if len(own) == 1 else None
    data: dict[str, Any] = {
        "title": title,
        "date": date,
        "commit": commit,
        "command": run["command"].replace(" --resume", "").replace(" --no-progress", ""),
        "scenario": run["scenario"],
        "sensing": sensing,
        "estimator": estimator,
        "episodes": max(row["episodes"] for row in rows),
        "first_seed": int(run["first_seed"]),
        "rows": rows,
        "note": note,
        "chosen_by": chosen_by,
    }
    return {key: value for key, value in data.items() if value is not None}


def observed_estimator(policy: str, scenario: str) -> str:
    """The estimate ``policy`` observes on ``scenario`` without ``--estimator``: its own, else
    the scenario config's."""
    env_id, overrides = env_settings(policy, scenario)
    merged = {**SCENARIO_IDS[env_id].overrides, **overrides}
    return load_config(scenario_config(scenario), merged).estimation.observed


def _sensing_of(command: str) -> str | None:
    words = command.split()
    if "--sensors" in words and words.index("--sensors") + 1 < len(words):
        return words[words.index("--sensors") + 1]
    return None


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m agents.evaluation.results",
        description="Check the committed result summaries, or add one from an evaluation.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("check", help="read every summary and every figure the registry names")
    add = sub.add_parser("add", help="write configs/results/NAME.json from an evaluation")
    add.add_argument("run", type=Path, help="an evaluation's landing_<scenario>.json")
    add.add_argument("--name", required=True, help="the summary's file name, without .json")
    add.add_argument("--title", required=True)
    add.add_argument("--commit", required=True, help="the commit the run was made at")
    add.add_argument("--date", default=datetime.date.today().isoformat())
    add.add_argument("--note")
    add.add_argument("--chosen-by", help="what chose the policy it reports, on other seeds")
    add.add_argument("--policy", nargs="+", default=(), help="only these policies' rows")
    args = parser.parse_args(argv)
    if args.command == "check":
        figures = default_figures()
        print(f"{len(summaries())} summaries; {len(figures)} scenarios with a default's figure")
        return 0
    run = json.loads(args.run.read_text(encoding="utf-8"))
    sensing = _sensing_of(run["command"])
    if sensing is None:
        raise SystemExit(f"{args.run}: its command names no --sensors; the figure needs one")
    data = summary_from_run(
        run, args.title, args.commit, args.date, sensing, args.note, args.chosen_by, args.policy
    )
    parse_summary(args.name, data)
    path = summary_dir() / f"{args.name}.json"
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
