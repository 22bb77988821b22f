"""The tables the README and the docs show of the registries and the committed results,
generated into the Markdown and committed, so that they read the same on the repository host
as in the built site.

Each page holds one generated block between ``<!-- generated: NAME ... -->`` and
``<!-- end generated: NAME -->`` (MyST and the host render the comments invisibly)::

    python -m agents.cli.pages --write    # rewrite every block from its sources (make pages)
    python -m agents.cli.pages --check    # exit 1 naming the stale pages

The sources: the policy registry (:mod:`agents.policies.registry`), the id table
(:mod:`landing_env.scenarios`) and the result summaries (:mod:`agents.evaluation.results`);
the tables are :mod:`agents.cli.catalogue`'s, which ``deck-landing list`` prints.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable, Sequence
from pathlib import Path

from agents.cli.catalogue import ids_table, policies_table, recommendation_cell
from agents.evaluation.results import (
    ResultSummary,
    default_figures,
    recommended_figures,
    spaced,
    summaries,
)
from agents.evaluation.summary import markdown_rows
from agents.policies.registry import POLICIES, env_settings
from landing_env.errors import ConfigError

#: the repository's root (the pages are source files of a checkout)
ROOT = Path(__file__).resolve().parents[2]
#: what regenerates the blocks (named in every stale-page message)
WRITE_COMMAND = "python -m agents.cli.pages --write"


def which_to_use() -> str:
    """The README's table: each setting's recommended policy, its id and its figure."""
    rows = []
    for figure in recommended_figures():
        result = figure.result
        env_id, _ = env_settings(figure.policy, result.scenario)
        model = POLICIES[figure.policy].model
        rows.append(
            (
                figure.label,
                f"`{env_id}`",
                f"`{figure.policy}`",
                f"`{model}`" if model else "-",
                f"{figure.row.cell()}; seeds from {spaced(result.first_seed)}",
                f"`--scenario {result.scenario} --sensors {result.sensing} "
                f"--seed {result.first_seed}`",
            )
        )
    header = ("setting", "id", "policy", "model", "success (95 % interval)")
    return markdown_rows((*header, "`deck-landing evaluate landing`"), rows)


def summary_section(result: ResultSummary) -> str:
    """One summary: its heading, the table, the note and the command that reproduces it."""
    lines = [
        f"### {result.title}",
        "",
        f"`{result.scenario}`, {result.sensing} sensing"
        + (f", `{result.estimator}` estimate" if result.estimator else "")
        + f", {result.episodes} episodes per policy on the seeds from "
        f"{spaced(result.first_seed)}; measured {result.date} at commit `{result.commit}` "
        f"(`configs/results/{result.name}.json`).",
        "",
    ]
    rows = []
    for row in result.rows:
        low, high = row.ci95_pct
        rows.append(
            (
                f"`{row.policy}`",
                f"{row.successes} / {row.episodes}",
                f"{row.success_pct:.1f} %",
                f"{low:.1f}-{high:.1f} %",
            )
        )
    lines += [markdown_rows(("policy", "landed", "success", "95 % interval"), rows), ""]
    if result.chosen_by:
        lines += [f"Chosen by: {result.chosen_by}.", ""]
    if result.note:
        lines += [result.note, ""]
    lines += ["```bash", result.command, "```", ""]
    return "\n".join(lines)


def results_page() -> str:
    """The results page's tables: every scenario's default, the recommendations, then every
    summary with its command."""
    defaults = [
        (
            f"`{figure.label}`",
            f"`{figure.policy}`",
            figure.result.sensing,
            recommendation_cell(figure),
            f"`{figure.result.name}`",
        )
        for figure in default_figures()
    ]
    recommended = [
        (
            figure.label,
            f"`{figure.policy}`",
            recommendation_cell(figure),
            figure.result.chosen_by or "-",
            f"`{figure.result.name}`",
        )
        for figure in recommended_figures()
    ]
    parts = [
        "## Every scenario's default policy",
        "",
        "What `deck-landing evaluate landing --scenario S` flies without `--policy`, with its "
        "figure.",
        "",
        markdown_rows(
            ("scenario", "policy", "sensing", "success (95 % interval)", "summary"), defaults
        ),
        "",
        "## What to use",
        "",
        "The recommended policy of each setting, on seeds that did not choose it.",
        "",
        markdown_rows(
            ("setting", "policy", "success (95 % interval)", "chosen by", "summary"), recommended
        ),
        "",
        "## The summaries",
        "",
    ]
    parts += [summary_section(result) for result in summaries().values()]
    return "\n".join(parts).rstrip("\n")


def policies_page() -> str:
    """The policies page's tables (``deck-landing list policies``)."""
    return policies_table()


#: page -> (block name, what writes it)
PAGES: dict[str, tuple[str, Callable[[], str]]] = {
    "README.md": ("which-to-use", which_to_use),
    "docs/results.md": ("results", results_page),
    "docs/policies.md": ("policies", policies_page),
    "docs/reference/ids.md": ("ids", ids_table),
}


def _block(name: str) -> re.Pattern[str]:
    return re.compile(
        rf"(?P<begin><!-- generated: {re.escape(name)}\b[^\n]*-->\n)(?P<body>.*?)"
        rf"(?P<end><!-- end generated: {re.escape(name)} -->)",
        re.DOTALL,
    )


def begin_marker(name: str) -> str:
    return f"<!-- generated: {name} by `{WRITE_COMMAND}`; edit its sources, not this block -->"


def regenerated(text: str, page: str) -> str:
    """``text`` (the page ``page``) with its generated block rewritten."""
    name, build = PAGES[page]
    match = _block(name).search(text)
    if match is None:
        raise ConfigError(
            page,
            f"no generated block '{name}' (put '{begin_marker(name)}' and "
            f"'<!-- end generated: {name} -->' where its tables go)",
        )
    body = "\n" + build().strip("\n") + "\n\n"
    return text[: match.start("body")] + body + text[match.end("body") :]


def stale_pages(root: Path = ROOT) -> list[str]:
    """The pages whose generated block differs from what its sources give."""
    stale = []
    for page in PAGES:
        text = (root / page).read_text(encoding="utf-8")
        if regenerated(text, page) != text:
            stale.append(page)
    return stale


def write_pages(root: Path = ROOT) -> list[str]:
    """Rewrite every stale block; the pages written."""
    written = []
    for page in PAGES:
        path = root / page
        text = path.read_text(encoding="utf-8")
        new = regenerated(text, page)
        if new != text:
            path.write_text(new, encoding="utf-8")
            written.append(page)
    return written


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m agents.cli.pages",
        description="The generated tables of the README and the docs pages.",
    )
    action = parser.add_mutually_exclusive_group(required=True)
    action.add_argument("--write", action="store_true", help="rewrite the stale blocks")
    action.add_argument("--check", action="store_true", help="exit 1 naming the stale pages")
    args = parser.parse_args(argv)
    if args.write:
        written = write_pages()
        print("wrote " + ", ".join(written) if written else "every page is current")
        return 0
    stale = stale_pages()
    if stale:
        print(f"stale: {', '.join(stale)}; run `{WRITE_COMMAND}` (make pages)")
        return 1
    print("every page is current")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
