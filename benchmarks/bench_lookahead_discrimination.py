"""How well the look-ahead's features tell a check whose commit lands from one whose does not.

    python -m benchmarks.bench_lookahead_discrimination --data FILE.npz [FILE.npz ...]

Reads recorded look-ahead transitions (``python -m agents.training.lookahead_data collect``: every
check of whole episodes, with the outcome of a commit there tried in the episode's own future) and
prints, per scenario, over the checks where a look-ahead was made and a commit could be
tried: the share whose commit lands, that share by quarter of the draws landing with the
margin (``chance``) and when all of them do, how often all of them do, and each feature's
area under the ROC curve for the commit's outcome (0.5: no better than chance;
``bench_ship_forecast_labels.auc``) (README "Fitted on episodes from the
start in trim").
"""

from __future__ import annotations

import argparse

import numpy as np

from agents.policies.lookahead import LOOKAHEAD_FEATURES
from agents.training.lookahead_data import load_transitions
from benchmarks.bench_ship_forecast_labels import auc

#: the bins of ``chance`` (the share of draws that land with the margin), the last one "all"
CHANCE_BINS = ((0.0, 0.25), (0.25, 0.5), (0.5, 0.75), (0.75, 1.0 - 1e-9), (1.0 - 1e-9, 1.01))


def discrimination(data: dict[str, np.ndarray]) -> dict[str, dict]:
    """Each scenario's figures (the module's doc) from :func:`load_transitions`' records."""
    out: dict[str, dict] = {}
    n = len(LOOKAHEAD_FEATURES)
    for scenario in sorted(set(data["scenario"].tolist())):
        mask = (
            (data["scenario"] == scenario)
            & data["check_tried"].astype(bool)
            & data["commit_terminal"].astype(bool)
        )
        lands = data["commit_success"][mask].astype(bool)
        observed = data["observation"][mask]
        chance = observed[:, LOOKAHEAD_FEATURES.index("chance")]
        bins = {}
        for low, high in CHANCE_BINS:
            inside = (chance >= low) & (chance < high)
            label = "all" if low > 0.99 else f"{low:.2f}-{high:.2f}"
            bins[label] = (
                int(inside.sum()),
                float(lands[inside].mean()) if inside.any() else float("nan"),
            )
        out[scenario] = {
            "checks": int(mask.sum()),
            "commit_lands": float(lands.mean()) if len(lands) else float("nan"),
            "by_chance": bins,
            "all_draws_land_share": float(np.mean(chance >= 1.0 - 1e-9)) if len(chance) else 0.0,
            "auc": {
                f"{'previous ' if k >= n else ''}{LOOKAHEAD_FEATURES[k % n]}": auc(
                    observed[:, k], lands
                )
                for k in range(1, 2 * n)
                if k != n  # the validity flags: 1 wherever a look-ahead was made
            },
        }
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", nargs="+", required=True, help="recorded transitions (.npz)")
    args = parser.parse_args(argv)
    for scenario, figures in discrimination(load_transitions(args.data)).items():
        print(
            f"{scenario}: {figures['checks']} checks, commit lands {figures['commit_lands']:.1%}; "
            f"all draws land at {figures['all_draws_land_share']:.1%} of checks"
        )
        for span, (count, rate) in figures["by_chance"].items():
            print(f"  chance {span}: {count:5d} checks, commit lands {rate:.1%}")
        print("  ROC AUC: " + ", ".join(f"{k} {v:.3f}" for k, v in figures["auc"].items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
