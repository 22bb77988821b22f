"""An offline DQN on the look-ahead's transitions: SB3's DQN fitted on recorded episodes.

Online, a DQN on :class:`~agents.policies.lookahead.LookaheadTimingWrapper` learns from the one
action it took at each check, and each check costs four descents of look-ahead (~0.7 s of CPU): in
50 minutes on this machine it saw some 5 000 checks and still committed at the first or
second (73 % at its 30-episode evaluations, README).
:func:`agents.training.lookahead_data.collect_transitions` records **both** actions' outcomes at
every check of whole episodes instead (the commit tried
in a saved copy with the episode's own future, the wait played on), so every check labels
the commit, and the DQN is fitted on that fixed replay buffer: SB3's own Q-learning update
(:meth:`stable_baselines3.DQN.train`, its loss, optimiser and target network), run for as many
gradient steps as it takes, with no further simulation.  Recorded episodes held out by seed
score each model exactly (:func:`agents.training.lookahead_data.replay_success`: a policy's path
through a recorded episode is the recorded one up to its commit).  With
``offline.ensemble: K``, K DQNs of consecutive seeds are fitted side by side and scored, and
decide, by their mean Q-values;
the model shipped is one SB3 DQN distilled from that mean (:func:`distil`), so the policy
that loads it is unchanged.

``python -m agents.training.lookahead_training
--config configs/train/timing_dqn_lookahead_offline.yaml --data results/lookahead/*.npz
--out results/train/timing_dqn_lookahead_offline``
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

from agents.common.cards import card_for_training, merge_cards, write_metadata
from agents.policies.lookahead import LookaheadSettings
from agents.policies.registry import make_env_and_policy
from agents.training.lookahead_data import load_transitions, replay_success
from agents.training.trainer import algorithm_kwargs, load_train_config
from landing_env.config_loading import build_dataclass
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.scenarios import SCENARIOS


class _Spaces(gym.Env):  # type: ignore[type-arg]
    """The wrapper's spaces, for building the DQN without an environment to step."""

    def __init__(self, size: int) -> None:
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (size,), dtype=np.float32)
        self.action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        return np.zeros(self.observation_space.shape, np.float32), {}

    def step(self, action: Any) -> Any:
        raise RuntimeError("an offline DQN does not step an environment")


def split_episodes(
    episodes: np.ndarray, every: int, fold: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the training and held-out records: every ``every``-th episode (by seed, in
    order) is held out, starting at the ``fold``-th (default: the last of each ``every``)."""
    require_range("holdout_every", every, 2)
    offset = every - 1 if fold is None else fold
    require_range("fold", offset, 0, every - 1)
    seeds = np.unique(episodes)
    held = np.isin(episodes, seeds[offset::every])
    return ~held, held


#: what the offline DQN is paid (``offline.reward``): ``task``, the task's own rewards (its
#: graded touchdown, its costs of waiting); ``success``, 1 for a landing that passes every
#: criterion and 0 otherwise, so that the Q-values are chances of success and the greedy
#: policy is the optimal stopping for the success rate the targets count
REWARDS = ("task", "success")


def rewards(data: dict[str, np.ndarray], reward: str) -> tuple[np.ndarray, np.ndarray]:
    """Each record's commit and wait reward under ``reward`` (:data:`REWARDS`)."""
    if reward == "task":
        return data["commit_reward"], data["wait_reward"]
    if reward == "success":
        ended = data["wait_terminal"].astype(bool)
        return data["commit_success"].astype(float), (ended & data["wait_success"]).astype(float)
    raise ConfigError("offline.reward", f"must be one of {list(REWARDS)}, got {reward!r}")


def fill_buffer(
    model: Any, data: dict[str, np.ndarray], mask: np.ndarray, reward: str = "task"
) -> int:
    """Add the masked records' transitions to ``model``'s replay buffer: the commit (where it
    ended the episode) and the wait, paid as ``reward`` says.  Returns how many were added."""
    commit_reward, wait_reward = rewards(data, reward)
    added = 0
    for i in np.flatnonzero(mask):
        observation = data["observation"][i][None]
        if data["commit_terminal"][i]:
            model.replay_buffer.add(
                observation,
                observation,
                np.array([1]),
                np.array([commit_reward[i]]),
                np.array([True]),
                [{}],
            )
            added += 1
        model.replay_buffer.add(
            observation,
            data["next_observation"][i][None],
            np.array([0]),
            np.array([wait_reward[i]]),
            np.array([bool(data["wait_terminal"][i])]),
            [{}],
        )
        added += 1
    return added


def mean_q(models: Any, observations: np.ndarray) -> np.ndarray:
    """The Q-values of a model, or the mean of an ensemble's, on a batch of observations."""
    import torch

    members = models if isinstance(models, list | tuple) else [models]
    batch = torch.as_tensor(observations, dtype=torch.float32)
    with torch.no_grad():
        return torch.stack([member.q_net(batch) for member in members]).mean(dim=0).numpy()


def greedy(models: Any) -> Any:
    """The deterministic decisions of a model, or of an ensemble by its mean Q-values, on a
    batch of observations."""

    def decide(observations: np.ndarray) -> np.ndarray:
        return mean_q(models, observations).argmax(axis=1)

    return decide


def distil(
    student: Any,
    teachers: list[Any],
    observations: np.ndarray,
    epochs: int = 3000,
    advantage_weight: float = 10.0,
) -> float:
    """Fit ``student``'s Q-network to the mean Q-values of ``teachers`` on ``observations``
    (regression, full batches, Adam), so that one SB3 DQN carries the ensemble's decisions;
    the target network is set to the result.  Returns the share of ``observations`` on which
    the student decides as the ensemble does.

    Paid by success, the Q-values are chances near 1 whose two actions differ by hundredths
    where the decision is close, so the commit's advantage (Q(commit) - Q(wait)) is fitted
    too, ``advantage_weight`` times over: on the 246 recorded episodes of commit 9a8e5ed the 2x32
    student then decides as a 5-member ensemble on 98.9 % of the observations (97.8 % from
    the Q-values alone, 95.2 % after 300 epochs)."""
    import torch

    target = torch.as_tensor(mean_q(teachers, observations))
    advantage = target[:, 1] - target[:, 0]
    batch = torch.as_tensor(observations, dtype=torch.float32)
    net = student.q_net
    optimiser = torch.optim.Adam(net.parameters(), lr=3e-3)
    mse = torch.nn.functional.mse_loss
    for _ in range(epochs):
        optimiser.zero_grad()
        q = net(batch)
        loss = mse(q, target) + advantage_weight * mse(q[:, 1] - q[:, 0], advantage)
        loss.backward()
        optimiser.step()
    student.q_net_target.load_state_dict(net.state_dict())
    agree = greedy(student)(observations) == target.numpy().argmax(axis=1)
    return float(np.mean(agree))


#: the keys of a YAML's ``offline`` section
OFFLINE_KEYS = (
    "gradient_steps",
    "rounds",
    "holdout_every",
    "cross_validate",
    "reward",
    "scenario",
    "ensemble",
)


def train_offline(
    config_path: str | Path,
    data_paths: list[str | Path],
    out_dir: str | Path,
    progress: bool = True,
    airframe_in_trim: bool | None = None,
) -> dict[str, Any]:
    """Fit the YAML's DQN on the transitions and write the chosen model with its card; returns
    the summary (also ``train_summary.yaml``).

    The model is chosen by its replay on held-out episodes (every ``holdout_every``-th).  With
    ``cross_validate``, each of the ``holdout_every`` folds is held out in turn, every episode
    is scored once by a model that never saw it, the number of gradient steps is chosen on
    that score, and the model is fitted anew on every episode for that many steps.
    """
    import torch
    from stable_baselines3 import DQN
    from stable_baselines3.common.logger import configure
    from tqdm import tqdm

    config = load_train_config(config_path)
    s = config.settings
    if s.algo != "dqn" or s.lookahead is None:
        raise ConfigError("deck_landing", "an offline look-ahead DQN needs algo: dqn and lookahead")
    if airframe_in_trim is not None:
        # the YAML's look-ahead with its drawn airframes in their own trim (the card signs it)
        s.lookahead["airframe_in_trim"] = bool(airframe_in_trim)
    # the YAML's own ``offline`` section (OFFLINE_KEYS); ``scenario``'s environment signs the card
    offline = dict((yaml.safe_load(Path(config_path).read_text()) or {}).get("offline") or {})
    unknown = sorted(set(offline) - set(OFFLINE_KEYS))
    if unknown:
        raise ConfigError("offline", f"unknown keys {unknown}; allowed: {list(OFFLINE_KEYS)}")
    settings = LookaheadSettings(**s.lookahead)
    # the YAML's look-ahead: the files' own, or theirs with fewer draws
    data = load_transitions(list(data_paths), settings)
    every = int(offline.get("holdout_every", 5))
    cross_validate = offline.get("cross_validate", False)
    if not isinstance(cross_validate, bool):
        raise ConfigError(
            "offline.cross_validate", f"must be true or false, got {cross_validate!r}"
        )
    reward = str(offline.get("reward", "task"))
    rewards(data, reward)  # refuses an unknown one before any fitting
    members = offline.get("ensemble", 1)
    if not isinstance(members, int) or isinstance(members, bool):
        raise ConfigError("offline.ensemble", f"must be a whole number, got {members!r}")
    require_range("offline.ensemble", members, 1, 16)
    torch.set_num_threads(s.torch_threads)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    hyper = {k: v for k, v in config.hyperparams.items() if k != "env_kwargs"}
    kwargs = algorithm_kwargs(hyper)
    kwargs["buffer_size"] = max(int(kwargs.get("buffer_size", 0)), 2 * len(data["episode"]) + 1)
    rounds = int(offline.get("rounds", 40))
    steps = int(offline.get("gradient_steps", 500))
    target_every = int(hyper.get("target_update_interval", 250))
    batch = int(kwargs.get("batch_size", 64))
    require_range("offline.rounds", rounds, 1)
    require_range("offline.gradient_steps", steps, 1)
    started = time.perf_counter()

    scenarios = sorted(set(data["scenario"].tolist()))
    #: the records' groups the replay is also scored by: each scenario's, each sensing
    #: profile's (records of several profiles: ideal, realistic, twice realistic)
    groups = {key: sorted(set(data[key].tolist())) for key in ("scenario", "sensing")}
    #: each group's held-out successes after each round (summed over the folds)
    held_by = {key: {name: np.zeros(rounds) for name in names} for key, names in groups.items()}

    def new_dqn(seed: int) -> Any:
        return DQN(
            hyper.get("policy", "MlpPolicy"),
            _Spaces(settings.size),
            seed=seed,
            device="cpu",
            verbose=0,
            **kwargs,
        )

    def fit(
        train_mask: np.ndarray, held_mask: np.ndarray | None, rounds: int, logs: Path
    ) -> tuple[list[Any], int, list[list[float]]]:
        """Fresh DQNs (``offline.ensemble`` of them, seeded ``seed``, ``seed + 1``, ...)
        fitted on the masked records, the transitions each was given, and after each round
        the replays of their mean Q-values: [gradient steps, training episodes, held-out
        episodes] (each group's held-out successes added to ``held_by``).  With one held-out
        split (no cross-validation) the best held-out model is saved."""
        ensemble = []
        for k in range(members):
            member = new_dqn(s.seed + k)
            member.set_logger(
                configure(str(logs if k == 0 else logs / f"member{k}"), ["tensorboard", "csv"])
            )
            added = fill_buffer(member, data, train_mask, reward)
            ensemble.append(member)
        model = ensemble[0]
        history: list[list[float]] = []
        done = 0
        best = -1.0
        for _ in tqdm(range(rounds), desc=f"offline DQN ({logs.name})", disable=not progress):
            for begin in range(0, steps, target_every):
                chunk = min(target_every, steps - begin)
                for member in ensemble:
                    member.train(gradient_steps=chunk, batch_size=batch)
                    member.q_net_target.load_state_dict(member.q_net.state_dict())
                done += chunk
            train_rate, _ = replay_success(_subset(data, train_mask), greedy(ensemble))
            row = [done, round(train_rate, 4)]
            model.logger.record("replay/train_success", train_rate)
            if held_mask is not None:
                held_rate, _ = replay_success(_subset(data, held_mask), greedy(ensemble))
                row.append(round(held_rate, 4))
                for key, names in groups.items():
                    for name in names:
                        mask = held_mask & (data[key] == name)
                        if mask.any():
                            rate, chosen_checks = replay_success(
                                _subset(data, mask), greedy(ensemble)
                            )
                            held_by[key][name][len(history)] += rate * len(chosen_checks)
                            model.logger.record(f"replay/heldout_success_{name}", rate)
                model.logger.record("replay/heldout_success", held_rate)
                if held_rate > best and not cross_validate:
                    best = held_rate
                    save(ensemble, out / "best_model.zip")
            model.logger.dump(done)
            history.append(row)
        return ensemble, added, history

    #: the share of the records' observations on which each saved model decides as its
    #: ensemble does (a model of one member: 1)
    agreement: dict[str, float] = {}

    def save(ensemble: list[Any], path: Path) -> None:
        """Save one SB3 DQN: the member itself, or one distilled from the ensemble's mean
        Q-values on every recorded observation (the members beside it, ``<name>_members/``)."""
        if len(ensemble) == 1:
            ensemble[0].save(path)
            agreement[path.name] = 1.0
            return
        observations = np.concatenate([data["observation"], data["next_observation"]])
        student = new_dqn(s.seed)
        agreement[path.name] = round(distil(student, ensemble, observations), 4)
        student.save(path)
        (path.parent / f"{path.stem}_members").mkdir(exist_ok=True)
        for k, member in enumerate(ensemble):
            member.save(path.parent / f"{path.stem}_members" / f"member{k}.zip")

    episodes = np.unique(data["episode"])
    if cross_validate:
        # each episode scored once, by the fold's model that never saw it
        held_successes = np.zeros(rounds)
        for fold in range(every):
            train_mask, held_mask = split_episodes(data["episode"], every, fold)
            _, _, fold_history = fit(train_mask, held_mask, rounds, out / "tb" / f"fold{fold}")
            count = len(np.unique(data["episode"][held_mask]))
            held_successes += np.array([row[2] for row in fold_history]) * count
        scores = held_successes / len(episodes)
        chosen = int(np.argmax(scores))
        ensemble, added, _ = fit(
            np.ones(len(data["episode"]), bool), None, chosen + 1, out / "tb" / "all"
        )
        save(ensemble, out / "best_model.zip")
        # the final model is the chosen one: copied, not distilled again
        shutil.copyfile(out / "best_model.zip", out / "timing_dqn_final.zip")
        agreement["timing_dqn_final.zip"] = agreement["best_model.zip"]
        history = [[(r + 1) * steps, round(float(v), 4)] for r, v in enumerate(scores)]
        best = (round(float(scores[chosen]), 4), (chosen + 1) * steps)
        held = data
        held_count = len(episodes)
    else:
        train_mask, held_mask = split_episodes(data["episode"], every)
        ensemble, added, history = fit(train_mask, held_mask, rounds, out / "tb")
        rates = [row[2] for row in history]
        chosen = int(np.argmax(rates))
        best = (float(rates[chosen]), int(history[chosen][0]))
        held = _subset(data, held_mask)
        held_count = len(np.unique(data["episode"][held_mask]))
        save(ensemble, out / "timing_dqn_final.zip")

    def _held_count(name: str, key: str = "scenario") -> int:
        return len(np.unique(held["episode"][held[key] == name]))

    card = sign_card(config, data, offline.get("scenario"))
    per_scenario = {
        name: len(np.unique(data["episode"][data["scenario"] == name])) for name in scenarios
    }
    card.note = (
        "offline DQN on recorded episodes ("
        + ", ".join(f"{count} of {name}" for name, count in per_scenario.items())
        + f"; {added} transitions); data: {[str(p) for p in data_paths]}"
    )
    for saved in (out / "best_model.zip", out / "timing_dqn_final.zip"):
        write_metadata(saved, card)
    summary = {
        "baselines_heldout_replay": {
            name: round(replay_success(held, rule)[0], 4) for name, rule in RULES.items()
        },
        "best_check_in_hindsight_heldout": round(hindsight_success(held), 4),
        "best_check_in_hindsight_by_scenario": {
            name: round(hindsight_success(_subset(held, held["scenario"] == name)), 4)
            for name in scenarios
            if np.any(held["scenario"] == name)
        },
        "episodes": len(episodes),
        "held_out_episodes": held_count,
        "cross_validated": cross_validate,
        "reward": reward,
        "transitions": added,
        "gradient_steps": int(history[-1][0]),
        "wall_time_s": round(time.perf_counter() - started, 1),
        "best_heldout_replay": list(best),
        # the chosen round's held-out replay, each scenario's and each sensing profile's own
        # (its episodes in brackets)
        **{
            f"best_heldout_replay_by_{key}": {
                name: [
                    round(float(held_by[key][name][chosen]) / _held_count(name, key), 4),
                    _held_count(name, key),
                ]
                for name in names
                if _held_count(name, key)
            }
            for key, names in groups.items()
        },
        "baselines_heldout_replay_by_scenario": {
            name: {
                rule_name: round(
                    replay_success(_subset(held, held["scenario"] == name), rule)[0], 4
                )
                for rule_name, rule in RULES.items()
            }
            for name in scenarios
            if np.any(held["scenario"] == name)
        },
        "replay": history,
    }
    summary["ensemble"] = members
    if members > 1:
        # the share of recorded observations where the saved (distilled) DQN decides as the
        # ensemble's mean Q-values do
        summary["distilled_agreement"] = agreement
    if cross_validate:
        summary["chosen_model_replay_all_episodes"] = round(
            replay_success(data, greedy(ensemble))[0], 4
        )
        shipped = DQN.load(out / "best_model.zip", device="cpu")
        summary["saved_model_replay_all_episodes"] = round(
            replay_success(data, greedy(shipped))[0], 4
        )
    (out / "train_summary.yaml").write_text(yaml.safe_dump(summary, sort_keys=False))
    return summary


def sign_card(config: Any, data: dict[str, np.ndarray], scenario: str | None = None) -> Any:
    """The card of a model fitted on ``data``: signed by the environment of each scenario and
    estimator in the records (:func:`agents.common.cards.merge_cards`: a fit on the ship's
    and the bench's episodes knows both timing tasks), or by ``scenario``'s alone (the YAML's
    ``offline.scenario``, with its default estimator)."""

    if scenario is not None:
        require_choice("offline.scenario", scenario, tuple(SCENARIOS))
        signers = [(scenario, SCENARIOS[scenario].estimator)]
    else:
        pairs = zip(data["scenario"].tolist(), data["estimator"].tolist(), strict=True)
        signers = sorted(set(pairs))
        unknown = sorted({name for name, _ in signers} - set(SCENARIOS))
        if unknown:
            raise ConfigError(
                "data", f"records of unknown scenarios {unknown}: set offline.scenario to sign"
            )
    overrides = dict(config.settings.env_kwargs.get("overrides", {}))
    lookahead = None
    if config.settings.lookahead is not None:
        lookahead = build_dataclass(
            LookaheadSettings, config.settings.lookahead, "deck_landing.lookahead"
        )
    cards = []
    for name, estimator in signers:
        env, _ = make_env_and_policy("land-now", name, estimator, extra_overrides=overrides)
        try:
            card = card_for_training(env, config, lookahead=lookahead)
        finally:
            env.close()
        if scenario is None:
            # the profiles the records were collected under, where they say (the world's, not
            # the observation's: the environment signs the rest)
            mine = (data["scenario"] == name) & (data["estimator"] == estimator)
            recorded = set(data["sensing"][mine].tolist()) - {"unknown"}
            if recorded:
                card.sensing = sorted(recorded)
        cards.append(card)
    return merge_cards(cards)


#: fixed rules on the same features, replayed beside the model: a commit at the first check,
#: all draws land with the margin, and a looser standard (three in four)
RULES: dict[str, Any] = {
    "commit_at_once": lambda obs: np.ones(len(obs), dtype=int),
    "all_draws_land": lambda obs: (obs[:, 1] >= 1.0 - 1e-9).astype(int),
    "three_quarters_land": lambda obs: (obs[:, 1] >= 0.75 - 1e-9).astype(int),
}


def hindsight_success(data: dict[str, np.ndarray]) -> float:
    """The share of episodes where some check's commit, or the forced one, lands."""
    return float(
        np.mean(
            [
                data["commit_success"][data["episode"] == seed].any()
                or data["wait_success"][data["episode"] == seed][-1]
                for seed in np.unique(data["episode"])
            ]
        )
    )


def _subset(data: dict[str, np.ndarray], mask: np.ndarray) -> dict[str, np.ndarray]:
    return {key: value[mask] for key, value in data.items()}


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m agents.training.lookahead_training", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--config", required=True)
    parser.add_argument("--data", nargs="+", required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument(
        "--airframe-in-trim",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="the look-ahead's drawn airframes start in their own trim, or not (the YAML's "
        "unless given; the data must be collected so)",
    )
    args = parser.parse_args(argv)
    summary = train_offline(
        args.config,
        args.data,
        args.out,
        airframe_in_trim=args.airframe_in_trim,
    )
    print(yaml.safe_dump(summary, sort_keys=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
