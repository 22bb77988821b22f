"""Success across scenarios from several ``evaluate landing`` runs, in one figure.

``evaluate landing`` writes one JSON-lines file per policy and scenario
(``landing_<scenario>_<policy>.jsonl``, one episode a line). A result such as "the look-ahead
DQN at ship sea states 4-6 against the heuristics and the oracles" is spread over several runs;
this reads their files, groups the episodes by scenario and policy, and draws each policy's
success with its 95 % Wilson interval, the bounds (``oracle``, ``deck-oracle``) hatched, and,
given targets in points below the bound, the line a policy must reach::

    python -m agents.evaluation.success_plot RUN_DIR_OR_JSONL ... --out docs/img/figure.png \\
        --target ship-ss4=2 ship-ss5=4 ship-ss6=4

A directory stands for every ``landing_*.jsonl`` in it (:mod:`agents.evaluation.episode_files`
reads them); the same policy and scenario from two files is an error that names both.
"""

from __future__ import annotations

import argparse
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.evaluation.episode_files import load_outcomes
from agents.evaluation.plots import save_figure
from agents.evaluation.summary import wilson_interval
from landing_env.errors import ConfigError

#: the policies that bound what a timing can do (drawn hatched, used for the targets)
BOUNDS: tuple[str, ...] = ("oracle", "deck-oracle")


@dataclass(frozen=True)
class Cell:
    """One policy's episodes on one scenario."""

    scenario: str
    policy: str
    source: Path
    successes: int
    episodes: int

    @property
    def rate(self) -> float:
        return self.successes / self.episodes

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.successes, self.episodes)


def load_cells(paths: Sequence[Path]) -> list[Cell]:
    """Every (scenario, policy) in the runs' episode files, in the order first met
    (:func:`agents.evaluation.episode_files.load_outcomes`)."""
    return [
        Cell(o.scenario, o.policy, o.source, o.successes, o.episodes) for o in load_outcomes(paths)
    ]


def parse_targets(items: Sequence[str]) -> dict[str, float]:
    """``SCENARIO=POINTS`` pairs: how far below its bound a policy may land on a scenario."""
    targets: dict[str, float] = {}
    for item in items:
        scenario, sep, points = item.partition("=")
        try:
            value = float(points)
        except ValueError:
            value = float("nan")
        if not sep or not scenario or not np.isfinite(value) or value < 0:
            raise ConfigError("target", f"{item!r} is not SCENARIO=POINTS with POINTS >= 0")
        targets[scenario] = value
    return targets


def plot_success(
    cells: Sequence[Cell], path: Path, title: str = "", targets: dict[str, float] | None = None
) -> Path:
    """Grouped bars: scenarios along x, one bar per policy, the bounds hatched, the interval
    as error bars, each bar's successes/episodes on it; with ``targets``, a dashed line at
    the bound's success less the target's points over each scenario's group."""
    import matplotlib.pyplot as plt

    targets = targets or {}
    scenarios = list(dict.fromkeys(c.scenario for c in cells))
    unknown = sorted(set(targets) - set(scenarios))
    if unknown:
        raise ConfigError("target", f"no runs of {unknown}; allowed {scenarios}")
    policies = list(dict.fromkeys(c.policy for c in cells if c.policy not in BOUNDS))
    policies += [b for b in BOUNDS if any(c.policy == b for c in cells)]
    by_key = {(c.scenario, c.policy): c for c in cells}
    # each scenario's bars side by side and centred, each policy in its own colour throughout
    present = {s: [p for p in policies if (s, p) in by_key] for s in scenarios}
    width = 0.84 / max(len(names) for names in present.values())
    lowest = min(100 * c.interval[0] for c in cells)
    floor = max(0.0, 10 * np.floor(lowest / 10) - 10)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.5 + 0.5 * len(cells)), 4.8))
    drawn: set[str] = set()
    for i, scenario in enumerate(scenarios):
        names = present[scenario]
        for k, policy in enumerate(names):
            cell = by_key[(scenario, policy)]
            lo, hi = cell.interval
            x = i + width * (k - (len(names) - 1) / 2)
            bound = policy in BOUNDS
            colour = f"C{policies.index(policy)}"
            ax.bar(
                x,
                100 * cell.rate,
                width=width * 0.92,
                yerr=[[100 * (cell.rate - lo)], [100 * (hi - cell.rate)]],
                capsize=3,
                label=None if policy in drawn else policy,
                color="white" if bound else colour,
                edgecolor="0.35" if bound else colour,
                hatch="//" if bound else None,
            )
            drawn.add(policy)
            ax.text(
                x,
                floor + 1.5,
                f"{cell.successes}/{cell.episodes}",
                rotation=90,
                ha="center",
                va="bottom",
                fontsize="x-small",
                color="0.1" if bound else "white",
                bbox={"facecolor": "white", "edgecolor": "none", "pad": 1} if bound else None,
            )
    for i, scenario in enumerate(scenarios):
        if scenario not in targets:
            continue
        bound_cell = next((by_key[(scenario, b)] for b in BOUNDS if (scenario, b) in by_key), None)
        if bound_cell is None:
            raise ConfigError("target", f"{scenario!r} has a target but no oracle run to bound it")
        level = 100 * bound_cell.rate - targets[scenario]
        half = width * len(present[scenario]) / 2
        ax.hlines(level, i - half, i + half, colors="k", linestyles="--", linewidth=1.2)
        ax.text(
            i + half,
            level - 0.8,
            f"target: {bound_cell.policy} - {targets[scenario]:g}",
            ha="right",
            va="top",
            fontsize="x-small",
            bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.85, "pad": 1},
            zorder=6,
        )
    ax.set_xticks(range(len(scenarios)), scenarios)
    ax.set_ylim(floor, 104)
    ax.set_ylabel("success (%), 95 % Wilson interval")
    if title:
        ax.set_title(textwrap.fill(title, int(10 * fig.get_figwidth())), fontsize="medium")
    ax.legend(
        fontsize="small",
        loc="upper center",
        bbox_to_anchor=(0.5, -0.09),
        ncols=min(len(policies), 6),
        frameon=False,
    )
    ax.grid(axis="y", alpha=0.3)
    return save_figure(fig, path)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m agents.evaluation.success_plot", description=__doc__.split("\n")[0]
    )
    parser.add_argument("runs", nargs="+", type=Path, help="run directories or .jsonl files")
    parser.add_argument("--out", type=Path, required=True, help="the figure (.png)")
    parser.add_argument("--title", default="")
    parser.add_argument("--target", nargs="*", default=[], metavar="SCENARIO=POINTS")
    args = parser.parse_args(argv)
    try:
        cells = load_cells(args.runs)
        path = plot_success(cells, args.out, args.title, parse_targets(args.target))
    except ConfigError as exc:
        parser.error(str(exc))
    for cell in cells:
        lo, hi = cell.interval
        print(
            f"{cell.scenario:>10} {cell.policy:>22}: {cell.successes}/{cell.episodes} "
            f"{100 * cell.rate:.1f} % ({100 * lo:.1f}-{100 * hi:.1f})  {cell.source}"
        )
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
