"""Look-ahead timing models replayed exactly on recorded episodes, file by file.

Each file of ``python -m agents.training.lookahead_data collect`` holds, at every check of its
episodes, the outcome of a commit now and of a wait; a model's decisions replay on it exactly
(:func:`agents.training.lookahead_data.replay_success`).  This prints, for each file (its sea, or
its scenario) and for all together: the episodes, each model's replay, the fixed rules of
:data:`agents.training.lookahead_training.RULES` and the best check in hindsight (the bar of a
timing on these features).  A model is replayed as saved (an SB3 DQN), with the look-ahead of
its card's training configuration.

    python benchmarks/replay_lookahead.py --model agents/models/timing_dqn_lookahead.zip \\
        results/train/timing_dqn_lookahead_broad/best_model.zip \\
        --data results/broad-lookahead/*.npz
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from agents.common.cards import read_metadata
from agents.policies.lookahead import LookaheadSettings
from agents.training.lookahead_data import load_transitions, open_record, replay_success
from agents.training.lookahead_training import RULES, greedy, hindsight_success
from landing_env.errors import ConfigError


def _settings(path: Path) -> LookaheadSettings | None:
    card = read_metadata(path)
    signed = card.observation.get("lookahead") if card is not None else None
    return LookaheadSettings.from_signature(signed) if isinstance(signed, dict) else None


def _label(path: Path) -> str:
    with open_record(path) as data:
        if "sea" in data and str(data["sea"]):
            return str(data["sea"])
        return str(data["scenario"]) if "scenario" in data else path.stem


def main() -> None:
    from stable_baselines3 import DQN

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", nargs="+", type=Path, required=True)
    parser.add_argument("--data", nargs="+", type=Path, required=True)
    args = parser.parse_args()
    for path in [*args.model, *args.data]:
        if not path.is_file():
            raise ConfigError("model" if path in args.model else "data", f"no file {path}")
    settings = {_settings(m) for m in args.model} - {None}
    if len(settings) > 1:
        raise ConfigError("model", "the models were trained with different look-aheads")
    look = settings.pop() if settings else None
    models = {m: DQN.load(m, device="cpu") for m in args.model}
    groups: dict[str, list[Path]] = {}
    for path in args.data:
        groups.setdefault(_label(path), []).append(path)
    names = [f"model {k + 1}" for k in range(len(models))] + list(RULES) + ["hindsight"]
    print("models: " + ", ".join(f"{k + 1} = {m}" for k, m in enumerate(models)))
    print(f"| sea | episodes | {' | '.join(names)} |")
    print("|---|---:|" + "---:|" * len(names))
    rows = [*groups.items(), ("all", list(args.data))]
    for label, paths in rows:
        data = load_transitions([str(p) for p in paths], look)
        rates = [replay_success(data, greedy(model))[0] for model in models.values()]
        rates += [replay_success(data, rule)[0] for rule in RULES.values()]
        rates.append(hindsight_success(data))
        episodes = len(np.unique(data["episode"]))
        cells = " | ".join(f"{100 * r:.1f} %" for r in rates)
        print(f"| {label} | {episodes} | {cells} |", flush=True)


if __name__ == "__main__":
    main()
