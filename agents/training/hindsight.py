"""Hindsight commit labels: the touchdown a commit at each decision would have given.

In simulation the touchdown of a commit *now* can be tried and undone: at every decision of a
waiting episode, the commit is run in a snapshot of the environment
(:mod:`landing_env.envs.snapshot`, as :mod:`agents.policies.oracle` does), its touchdown's margin
(:func:`agents.policies.oracle.touchdown_margin`: the smallest relative slack of the normal speed,
the deck tilt and the relative attitude) is recorded beside that decision's observation, and the
episode goes on as if nothing had been tried.  A trained policy sees one commit per episode;
these labels judge every decision, so a commit rule can be replayed offline on them
(:func:`replay_rule`), which is how the touchdown-prediction study measured what a deck-tilt
predictor is worth before any training (``docs/experiments/index.md``).  Privileged: it needs
the simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import landing_env  # noqa: F401  (registers the environments)
from agents.policies.oracle import touchdown_margin
from agents.training.sampler import SENSING_PROFILES
from landing_env.envs.snapshot import restore_snapshot, save_snapshot
from landing_env.errors import require_choice, require_range
from landing_env.scenarios import SCENARIOS, TIMING_TASK

#: the label of a commit that did not touch down (crash, descent timeout); margins below it
#: are clipped to it (a miss is a miss, however far)
MIN_MARGIN = -1.0


@dataclass
class LabelSet:
    """Observations of the timing task and the touchdown of a commit at each."""

    observations: np.ndarray
    #: :func:`agents.policies.oracle.touchdown_margin`, clipped below at :data:`MIN_MARGIN`
    margin: np.ndarray
    success: np.ndarray
    deck_tilt_deg: np.ndarray
    #: time from the commit to the first contact (or to the end of a descent without one), s
    descent_s: np.ndarray
    #: episode number (in ``seeds`` order) and decision of each example
    episode: np.ndarray
    decision: np.ndarray
    #: every waited observation of each episode, labelled or not (the estimate's series)
    waited: list[np.ndarray]

    def save(self, path: str | Path) -> Path:
        """Write the labelled arrays (not ``waited``) to a compressed ``.npz``."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays = {name: getattr(self, name) for name in self.__dataclass_fields__}
        arrays.pop("waited")
        np.savez_compressed(path, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> LabelSet:
        """Read a file written by :meth:`save` (``waited`` is not kept: empty)."""
        with np.load(Path(path), allow_pickle=False) as data:
            fields = {
                name: np.asarray(data[name])
                for name in cls.__dataclass_fields__
                if name != "waited"
            }
        return cls(**fields, waited=[])


def make_timing_env(
    scenario: str,
    sensing: str,
    estimator: str = "tight",
    overrides: dict[str, Any] | None = None,
) -> Any:
    """The timing environment of ``scenario`` under the sensing profile ``sensing``
    (:data:`agents.training.sampler.SENSING_PROFILES`), built as the evaluation builds it
    (``overrides`` under ``timing.`` set the timing task, e.g. its descent)."""
    require_choice("sensing", sensing, tuple(SENSING_PROFILES))
    require_choice("scenario", scenario, tuple(SCENARIOS))
    settings = {
        **SCENARIOS[scenario].overrides(TIMING_TASK, estimator),
        **SENSING_PROFILES[sensing],
        **(overrides or {}),
    }
    return gym.make(
        TIMING_TASK, config=SCENARIOS[scenario].config, overrides=settings, render_mode=None
    )


def collect_labels(
    env: Any, seeds: list[int], max_decisions: int, every: int = 1, progress: bool = True
) -> LabelSet:
    """Fly each seeded episode, waiting, and try the commit at every ``every``-th of its first
    ``max_decisions`` decisions in a snapshot (the episode continues as if it had not)."""
    from tqdm import tqdm

    require_range("max_decisions", max_decisions, 1)
    require_range("every", every, 1)
    base = env.unwrapped
    thresholds = base.config.touchdown
    rows: dict[str, list[Any]] = {
        name: [] for name in LabelSet.__dataclass_fields__ if name != "waited"
    }
    waited: list[np.ndarray] = []
    for number, seed in enumerate(tqdm(seeds, desc="labels", unit="ep", disable=not progress)):
        observation, info = env.reset(seed=seed)
        if info.get("hold_failed"):
            # the warm-up hold ended the episode: there is no decision to label
            env.step(0)
            waited.append(np.array([observation], dtype=np.float32))
            continue
        series = [observation]
        for decision in range(max_decisions):
            if decision % every == 0:
                here = save_snapshot(base)
                _, _, _, _, info = env.step(1)
                restore_snapshot(base, here, keep=False)
                touchdown = info.get("touchdown") or {}
                rows["observations"].append(observation)
                rows["margin"].append(max(touchdown_margin(touchdown, thresholds), MIN_MARGIN))
                rows["success"].append(info["outcome"] == "success")
                rows["deck_tilt_deg"].append(float(touchdown.get("deck_tilt_deg", math.nan)))
                rows["descent_s"].append(float(info["descent_s"]))
                rows["episode"].append(number)
                rows["decision"].append(decision)
            observation, _, terminated, truncated, _ = env.step(0)
            if terminated or truncated:
                break
            series.append(observation)
        waited.append(np.array(series, dtype=np.float32))
    return LabelSet(
        observations=np.array(rows["observations"], dtype=np.float32),
        margin=np.array(rows["margin"], dtype=float),
        success=np.array(rows["success"], dtype=bool),
        deck_tilt_deg=np.array(rows["deck_tilt_deg"], dtype=float),
        descent_s=np.array(rows["descent_s"], dtype=float),
        episode=np.array(rows["episode"], dtype=int),
        decision=np.array(rows["decision"], dtype=int),
        waited=waited,
    )


def replay_rule(margin: np.ndarray, commit: np.ndarray, episode: np.ndarray) -> dict[str, float]:
    """Replay a commit rule on labelled episodes: each commits at its first labelled decision
    where ``commit`` is true (at its last labelled one when none is).

    Returns the success rate of those commits (``margin >= 0``), the success rate among the
    episodes that did commit (the rule's precision), and how many did not."""
    landed, precise, none = [], [], 0
    for key in np.unique(episode):
        rows = np.where(episode == key)[0]
        hits = np.where(commit[rows])[0]
        pick = rows[hits[0]] if len(hits) else rows[-1]
        ok = bool(margin[pick] >= 0.0)
        landed.append(ok)
        if len(hits):
            precise.append(ok)
        else:
            none += 1
    return {
        "success": float(np.mean(landed)),
        "precision": float(np.mean(precise)) if precise else math.nan,
        "episodes_without_commit": float(none),
        "episodes": float(len(landed)),
    }
