"""The look-ahead's offline data: both actions' outcomes at every check, recorded and read back.

:func:`collect_transitions` flies whole episodes of the timing task under the look-ahead
(:class:`~agents.policies.lookahead.LookaheadTimingWrapper`) and records, at every check, the
observation with the outcome of a commit now (tried in a saved copy of the episode) and of a
wait; :func:`load_transitions` reads such files back (with fewer draws where the look-ahead
asked for has fewer), and :func:`replay_success` scores a policy on
them exactly.  The data of the offline DQN (:mod:`agents.training.lookahead_training`).
``python -m agents.training.lookahead_data collect`` records a file.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from agents.common.cards import sensing_profile
from agents.policies.lookahead import (
    LOOKAHEAD_FEATURES,
    ONBOARD_MODELS,
    LookaheadSettings,
    LookaheadTimingWrapper,
    check_features,
    in_flight,
)
from agents.policies.oracle import TriedCommit
from agents.policies.registry import make_env_and_policy
from agents.training.sampler import SENSING_PROFILES
from landing_env.anticipation.hms_forecast import ONLINE
from landing_env.envs.snapshot import restore_snapshot, save_snapshot
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.scenarios import SCENARIOS
from landing_env.sea.training_seas import TrainingSea, training_sea

#: the arrays of a transitions file (:func:`collect_transitions`)
TRANSITION_KEYS = (
    "observation",
    "commit_reward",
    "commit_success",
    "commit_terminal",
    "wait_reward",
    "next_observation",
    "wait_terminal",
    "wait_success",
    "episode",
)
#: the check an observation was made at (:func:`collect_transitions`): whether commits were
#: tried (records,), and each draw's verdict (records, draws).  With them a file
#: recorded with many draws gives the observations of fewer (:func:`with_draws`): a draw's
#: future is seeded by the episode, the decision and its index, not by how many are drawn.
DRAW_KEYS = ("check_tried", "draw_lands", "draw_success", "draw_margin")


def collect_transitions(
    scenario: str,
    seeds: list[int],
    out: str | Path,
    settings: LookaheadSettings | None = None,
    estimator: str | None = None,
    progress: bool = True,
    forecast: Any = None,
    sensing: str | None = None,
    sea: TrainingSea | None = None,
) -> Path:
    """Both actions' outcomes at every check of whole episodes: the data of an offline DQN.

    Each episode holds to its wait limit; at every check the look-ahead's observation is
    recorded with the reward of a commit now, tried with the episode's own future in a saved
    copy (as :class:`agents.policies.oracle.OracleTimingPolicy` tries it), and with the wait's
    reward
    and the next check's observation.  The episode then goes on as if it waited, so any policy
    of the wrapper can be replayed exactly on the file (:func:`replay_success`): the states on
    its path and their observations are the ones recorded.  Each check's draws are kept
    (:data:`DRAW_KEYS`), so the file also serves a look-ahead of fewer draws.  The file is
    rewritten after every episode (an interrupted run keeps what it has).

    ``sensing`` names a profile of :data:`agents.training.sampler.SENSING_PROFILES`
    (``realistic-2x``: twice the realistic noise); the file records that name (with the
    scenario's lens where it is not the standard one: ``realistic-2x,lens=wide``).  Without it
    the ``sensors`` default applies (``DECK_LANDING_SENSORS``); the file records
    :func:`agents.common.cards.sensing_profile` either way.

    ``sea``: a member of a training family of seas (:mod:`landing_env.sea.training_seas`)
    flown on its scenario (``scenario`` must be the member's) with its sea's overrides and
    the helideck forecast identified online (``deck_forecast: online``); the file records
    the member's name as ``sea``.  A held-out sea is refused.
    """
    from tqdm import tqdm

    settings = settings or LookaheadSettings()
    overrides: dict[str, Any] = {}
    if sensing is not None:
        require_choice("sensing", sensing, tuple(SENSING_PROFILES))
        # a profile without a ``sensors`` bundle is ideal sensing plus its overrides, whatever
        # DECK_LANDING_SENSORS says
        overrides = {"sensors": "ideal", **SENSING_PROFILES[sensing]}
    require_choice("scenario", scenario, tuple(SCENARIOS))
    if SCENARIOS[scenario].held_out:
        raise ConfigError(
            "scenario", f"{scenario!r} is a held-out sea: nothing is recorded to fit on it"
        )
    if sea is not None:
        if sea.scenario != scenario:
            raise ConfigError(
                "sea", f"{sea.name!r} is a sea of {sea.scenario!r}, not of {scenario!r}"
            )
        overrides = {**overrides, **sea.overrides, "deck_forecast": ONLINE}
    env, _ = make_env_and_policy(
        "land-now",
        scenario,
        estimator or SCENARIOS[scenario].estimator,
        extra_overrides=overrides,
    )
    wrapper = LookaheadTimingWrapper(env, forecast=forecast, **asdict(settings))
    base = wrapper.unwrapped
    rows: dict[str, list[Any]] = {key: [] for key in TRANSITION_KEYS + DRAW_KEYS}
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        for seed in tqdm(seeds, desc=f"look-ahead transitions @ {scenario}", disable=not progress):
            observation, _ = wrapper.reset(seed=seed)
            while True:
                for key, value in zip(
                    DRAW_KEYS,
                    _draw_arrays(wrapper.observer.last_tries, settings.draws),
                    strict=True,
                ):
                    rows[key].append(value)
                commit = (0.0, False, True)
                if in_flight(base):
                    here = save_snapshot(base)
                    try:
                        _, reward, terminated, _, info = base.step(1)
                    finally:
                        restore_snapshot(base, here, keep=False)
                    commit = (float(reward), info["outcome"] == "success", bool(terminated))
                next_observation, reward, terminated, truncated, info = wrapper.step(0)
                for key, value in zip(
                    TRANSITION_KEYS,
                    (
                        observation,
                        *commit,
                        float(reward),
                        next_observation,
                        bool(terminated or truncated),
                        info["outcome"] == "success",
                        seed,
                    ),
                    strict=True,
                ):
                    rows[key].append(value)
                observation = next_observation
                if terminated or truncated:
                    break
            np.savez_compressed(
                path,
                settings=json.dumps(settings.signature()),
                scenario=scenario,
                sea=sea.name if sea is not None else "",
                estimator=base.config.estimation.observed,
                sensing=sensing_profile(base.config, sensing),
                **{key: np.asarray(value) for key, value in rows.items()},
            )
    finally:
        wrapper.close()
    return path


def _draw_arrays(
    tries: list[TriedCommit] | None, draws: int
) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray]:
    """One check's tried commits as :data:`DRAW_KEYS`' rows."""
    lands = np.zeros(draws, bool)
    success = np.zeros(draws, bool)
    margin = np.full(draws, np.nan)
    for k, tried in enumerate((tries or [])[:draws]):
        lands[k], success[k], margin[k] = tried.lands, tried.success, tried.margin
    return bool(tries), lands, success, margin


def recorded_tries(data: dict[str, np.ndarray], row: int, draws: int) -> list[TriedCommit] | None:
    """The first ``draws`` tried commits of record ``row``'s check (None: nothing tried)."""
    if not data["check_tried"][row]:
        return None
    lands, success, margin = (data[key][row][:draws] for key in DRAW_KEYS[1:])
    return [
        TriedCommit(bool(a), bool(b), float(m))
        for a, b, m in zip(lands, success, margin, strict=True)
    ]


def with_draws(data: dict[str, np.ndarray], settings: LookaheadSettings) -> dict[str, np.ndarray]:
    """The records as a look-ahead of ``settings`` (the file's, with fewer draws) sees them:
    every observation rebuilt from the first ``settings.draws`` draws of its checks."""
    if any(key not in data for key in DRAW_KEYS):
        raise ConfigError("data", "the transitions hold no draws of their own: record them anew")
    if settings.draws > data["draw_lands"].shape[1]:
        raise ConfigError(
            "lookahead.draws",
            f"{settings.draws} draws asked; the transitions hold {data['draw_lands'].shape[1]}",
        )
    checks = settings.checks
    features = np.array(
        [
            check_features(recorded_tries(data, i, settings.draws))
            for i in range(len(data["episode"]))
        ]
    )
    invalid = check_features(None)
    episodes = data["episode"]
    # what follows the checks (the wait used) is kept
    tail_from = checks * len(LOOKAHEAD_FEATURES)

    def stack(row: int, newest: np.ndarray | None, tail: np.ndarray) -> np.ndarray:
        """The observation whose newest check is ``newest`` (or row's), the earlier ones the
        rows before it in its episode."""
        parts = [] if newest is None else [newest]
        k = row
        while len(parts) < checks and k >= 0 and episodes[k] == episodes[row]:
            parts.append(features[k])
            k -= 1
        parts += [invalid] * (checks - len(parts))
        return np.concatenate([*parts, tail]).astype(np.float32)

    out = dict(data)
    n = len(episodes)
    out["observation"] = np.array(
        [stack(i, None, data["observation"][i][tail_from:]) for i in range(n)], np.float32
    )
    out["next_observation"] = np.array(
        [
            stack(i + 1, None, data["next_observation"][i][tail_from:])
            if i + 1 < n and episodes[i + 1] == episodes[i] and not data["wait_terminal"][i]
            else stack(i, invalid, data["next_observation"][i][tail_from:])
            for i in range(n)
        ],
        np.float32,
    )
    return out


def open_record(path: str | Path) -> Any:
    """A look-ahead record (:func:`collect_transitions`' ``.npz``), opened; anything else is
    refused naming ``data`` and the file."""
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as error:
        raise ConfigError("data", f"{path} is not a look-ahead record (.npz): {error}") from error
    refusal = ConfigError(
        "data",
        f"{path} is not a look-ahead record (python -m agents.training.lookahead_data collect "
        "writes them)",
    )
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise refusal
    if "settings" not in data:
        data.close()
        raise refusal
    return data


def load_transitions(
    paths: list[str | Path], settings: LookaheadSettings | None = None
) -> dict[str, np.ndarray]:
    """The transitions of several files, concatenated; they must share their look-ahead, and
    an episode (its seed) may be in one file only, whatever its scenario.  Each record also
    gets its file's ``scenario``, the ``estimator`` observed (a file without one: the
    scenario's own) and the ``sensing`` profile (:func:`agents.common.cards.sensing_profile`;
    a file without one: ``unknown``).  ``settings``: the look-ahead to see them with, the
    files' or the same with fewer draws (:func:`with_draws`)."""

    parts: list[dict[str, np.ndarray]] = []
    signature = None
    seen: dict[int, str] = {}
    for path in paths:
        with open_record(path) as data:
            if signature is None:
                signature = str(data["settings"])
            elif str(data["settings"]) != signature:
                raise ConfigError("data", f"{path} was collected with another look-ahead")
            keys = TRANSITION_KEYS + tuple(k for k in DRAW_KEYS if k in data)
            part = {key: data[key] for key in keys}
            scenario = str(data["scenario"]) if "scenario" in data else "unknown"
            estimator = (
                str(data["estimator"])
                if "estimator" in data
                else SCENARIOS[scenario].estimator
                if scenario in SCENARIOS
                else "unknown"
            )
            sensing = str(data["sensing"]) if "sensing" in data else "unknown"
        for seed in np.unique(part["episode"]).tolist():
            if seed in seen:
                raise ConfigError(
                    "data",
                    f"episode seed {seed} is in both {seen[seed]} and {path}: an episode "
                    "is one file's (record another scenario with other seeds)",
                )
            seen[seed] = str(path)
        part["scenario"] = np.full(len(part["episode"]), scenario)
        part["estimator"] = np.full(len(part["episode"]), estimator)
        part["sensing"] = np.full(len(part["episode"]), sensing)
        parts.append(part)
    if not parts or signature is None:
        raise ConfigError("data", "no transitions files given")
    keys = tuple(k for k in parts[0] if all(k in p for p in parts))
    merged = {key: np.concatenate([p[key] for p in parts]) for key in keys}
    if settings is None:
        return merged
    recorded = json.loads(signature)
    wanted = json.loads(json.dumps(settings.signature()))
    if recorded == wanted:
        return merged
    if {**recorded, "draws": settings.draws} != wanted or settings.draws > recorded["draws"]:
        raise ConfigError(
            "data",
            "the transitions were collected with another look-ahead than the one asked "
            f"(recorded {recorded['draws']} draws; only fewer draws can be taken from them)",
        )
    return with_draws(merged, settings)


def replay_success(data: dict[str, np.ndarray], decide: Any) -> tuple[float, np.ndarray]:
    """The success of a policy replayed on recorded episodes, exactly: ``decide(observations)``
    gives 1 (commit) or 0 for each check; an episode ends at its first commit (its recorded
    outcome) or, waiting throughout, as the wait limit ended it.  Returns the success rate
    and each episode's check of commit (-1: never)."""
    actions = np.asarray(decide(data["observation"])).reshape(-1)
    episodes = data["episode"]
    successes, chosen = [], []
    for seed in np.unique(episodes):
        index = np.flatnonzero(episodes == seed)
        commits = index[(actions[index] == 1) & data["commit_terminal"][index]]
        if len(commits):
            successes.append(bool(data["commit_success"][commits[0]]))
            chosen.append(int(np.searchsorted(index, commits[0])))
        else:
            successes.append(bool(data["wait_success"][index[-1]]))
            chosen.append(-1)
    return float(np.mean(successes)), np.asarray(chosen)


def main(argv: list[str] | None = None) -> int:
    """``python -m agents.training.lookahead_data collect``: record transitions
    (:func:`collect_transitions`); ``python -m agents.training.lookahead_training`` fits a DQN
    on them offline (:func:`agents.training.lookahead_training.train_offline`)."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m agents.training.lookahead_data", description=main.__doc__
    )
    sub = parser.add_subparsers(dest="command", required=True)
    collect = sub.add_parser("collect", help="both actions' outcomes at every check")
    collect.add_argument("--scenario", default="ship-ss5")
    collect.add_argument("--seed", type=int, default=10_000, help="first episode seed")
    collect.add_argument("--episodes", type=int, default=60)
    collect.add_argument("--draws", type=int, default=LookaheadSettings.draws)
    collect.add_argument("--check-every-s", type=float, default=LookaheadSettings.check_every_s)
    collect.add_argument(
        "--airframe-in-trim",
        action="store_true",
        help="the onboard model's drawn airframes start in their own trim",
    )
    collect.add_argument(
        "--onboard-model",
        choices=ONBOARD_MODELS,
        default=LookaheadSettings.model,
        help="what flies the look-ahead's futures: the replay of the simulation or the reduced "
        "model of the drone's closed loop (agents.policies.reduced_descent)",
    )
    collect.add_argument(
        "--estimator",
        default=None,
        help="the estimate observed (default: the scenario's; the bench's policies observe tight)",
    )
    collect.add_argument(
        "--sensors",
        default=None,
        help="a sensing profile by name (ideal, realistic, realistic-2x, ...; default: the "
        "sensors default, DECK_LANDING_SENSORS)",
    )
    collect.add_argument(
        "--sea",
        metavar="FAMILY/MEMBER",
        help="a member of a training family of seas (e.g. ship-broad/ochi-hubble-bow), flown "
        "on its own scenario with the helideck forecast identified online",
    )
    collect.add_argument("--out", required=True, help="the .npz to write")
    args = parser.parse_args(argv)
    if args.command == "collect":
        require_range("episodes", args.episodes, 1)
        settings = LookaheadSettings(
            draws=args.draws,
            check_every_s=args.check_every_s,
            airframe_in_trim=args.airframe_in_trim,
            model=args.onboard_model,
        )
        seeds = list(range(args.seed, args.seed + args.episodes))
        sea = training_sea(args.sea) if args.sea else None
        path = collect_transitions(
            sea.scenario if sea is not None else args.scenario,
            seeds,
            args.out,
            settings,
            args.estimator,
            sensing=args.sensors,
            sea=sea,
        )
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
