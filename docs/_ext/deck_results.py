"""Results tables generated from the committed result summaries ``docs/results/<name>.json``.

A summary holds one evaluation: ``title``, ``date`` (YYYY-MM-DD), ``commit`` (the commit the
figures were measured at), ``command`` (what reproduces it), ``scenario``, ``sensing``,
``episodes`` (per policy), ``first_seed`` (the held-out seeds are ``first_seed`` on),
``rows`` (one per policy: ``policy``, ``successes``, ``episodes``, ``success_pct``,
``ci95_low_pct``, ``ci95_high_pct``: the 95 % Wilson interval) and optionally ``note``.
``deck-results`` renders every file (or the names given), each table followed by its
"How to replicate" command; a file that breaks the format fails the build naming the field.
"""

from __future__ import annotations

import datetime
import json
from pathlib import Path
from typing import Any

from deck_docs import GeneratedDirective, list_table
from sphinx.errors import ExtensionError

RESULTS_DIR = Path(__file__).resolve().parent.parent / "results"
FIELDS: dict[str, type | tuple[type, ...]] = {
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
ROW_FIELDS: dict[str, type | tuple[type, ...]] = {
    "policy": str,
    "successes": int,
    "episodes": int,
    "success_pct": (int, float),
    "ci95_low_pct": (int, float),
    "ci95_high_pct": (int, float),
}


def _require(where: str, data: dict[str, Any], fields: dict[str, Any]) -> None:
    for key, kind in fields.items():
        if key not in data:
            raise ExtensionError(f"{where}: field {key!r} is missing")
        if not isinstance(data[key], kind) or isinstance(data[key], bool):
            raise ExtensionError(f"{where}: field {key!r} = {data[key]!r} has the wrong type")


def load_summary(path: Path) -> dict[str, Any]:
    """A result summary, checked: every field present and typed, the date a date, each row's
    percentage its successes over its episodes and inside its interval."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ExtensionError(f"{path}: cannot read a result summary ({exc})") from None
    if not isinstance(data, dict):
        raise ExtensionError(f"{path}: a result summary is a JSON object")
    _require(str(path), data, FIELDS)
    try:
        datetime.date.fromisoformat(data["date"])
    except ValueError:
        raise ExtensionError(f"{path}: field 'date' = {data['date']!r} is not YYYY-MM-DD") from None
    if not data["rows"]:
        raise ExtensionError(f"{path}: field 'rows' is empty")
    for i, row in enumerate(data["rows"]):
        where = f"{path}: rows[{i}]"
        if not isinstance(row, dict):
            raise ExtensionError(f"{where} is not an object")
        _require(where, row, ROW_FIELDS)
        if not 0 <= row["successes"] <= row["episodes"] or row["episodes"] == 0:
            raise ExtensionError(f"{where}: successes must lie in 0..episodes (> 0)")
        if abs(100.0 * row["successes"] / row["episodes"] - row["success_pct"]) > 0.051:
            raise ExtensionError(f"{where}: success_pct is not successes / episodes")
        if not row["ci95_low_pct"] <= row["success_pct"] <= row["ci95_high_pct"]:
            raise ExtensionError(f"{where}: success_pct lies outside its 95 % interval")
    return data


def summary_lines(data: dict[str, Any]) -> list[str]:
    """The RST of one summary: heading line, table, note and the replicating command."""
    seeds = f"{data['first_seed']:_}".replace("_", " ")
    lines = [
        f"**{data['title']}**",
        "",
        f"``{data['scenario']}``, {data['sensing']} sensing, {data['episodes']} episodes per "
        f"policy on the held-out seeds from {seeds}; measured {data['date']} at commit "
        f"``{data['commit']}``.",
        "",
    ]
    rows = [
        [
            f"``{row['policy']}``",
            f"{row['successes']} / {row['episodes']}",
            f"{row['success_pct']:.1f} %",
            f"{row['ci95_low_pct']:.1f}–{row['ci95_high_pct']:.1f} %",
        ]
        for row in data["rows"]
    ]
    lines += list_table(["policy", "landed", "success", "95 % interval"], rows, "35 20 20 25")
    if data.get("note"):
        lines += [str(data["note"]), ""]
    return [
        *lines,
        "How to replicate:",
        "",
        ".. code-block:: bash",
        "",
        f"   {data['command']}",
        "",
    ]


class ResultsDirective(GeneratedDirective):
    """``deck-results [NAME ...]``: the summaries of ``docs/results/`` (all, by name)."""

    optional_arguments = 50

    def lines(self) -> list[str]:
        names = self.arguments or sorted(p.stem for p in RESULTS_DIR.glob("*.json"))
        lines: list[str] = []
        for name in names:
            path = RESULTS_DIR / f"{name}.json"
            self.env.note_dependency(str(path))
            lines += summary_lines(load_summary(path))
        return lines


def setup(app: Any) -> None:
    app.add_directive("deck-results", ResultsDirective)
