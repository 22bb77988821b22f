"""Record what ``fused`` is fed on the pinned-drone bench, then replay the filter offline.

The drone is pinned and ``fused`` is only compared (``estimation.observed: truth``), so the
filter changes nothing in the run: recording each step's inputs (the delivered poses of its
sources, the ToF reading, the IMU samples, the drone attitude) and the true deck pose once
lets any number of filter settings be scored on exactly the same data, in seconds.
"""

from __future__ import annotations

import dataclasses
import pickle
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from estimation.fusion import DeckFusion, FusionConfig
from estimation.types import DeckPoseEstimate


@dataclass
class Recording:
    """One bench run: the fusion's inputs per step, the truth, and the scored estimators'
    own poses (``poses[name]``: (N, 6), NaN where invalid)."""

    label: str
    tof_positions_c: np.ndarray
    t_bc: np.ndarray
    fusion: FusionConfig
    steps: list[tuple] = field(default_factory=list)
    truth: list[np.ndarray] = field(default_factory=list)
    poses: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def save(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("wb") as handle:
            pickle.dump(self, handle)

    @staticmethod
    def load(path: Path) -> Recording:
        with path.open("rb") as handle:
            return pickle.load(handle)


def record(
    label: str,
    scenario: str,
    overrides: dict[str, Any],
    seed: int,
    duration_s: float,
    compare: tuple[str, ...] = ("atda", "ihrcf", "crhf", "tight"),
) -> Recording:
    """Run ``scenario`` with the drone pinned, rendered and detected, and record the fusion's
    inputs at every step (the env's own ``fused`` runs too; its settings are kept)."""
    import gymnasium as gym  # heavy: only the recording needs the simulator

    import landing_env  # noqa: F401  (registers the environments)
    from landing_env.config import load_config
    from landing_env.errors import PinnedDroneWarning

    forced = {
        "simulation.drone_fixed": True,
        "simulation.max_episode_s": float(duration_s),
        "camera.mode": "render",
        "estimation.observed": "truth",
        "estimation.compare": [*compare, "fused"],
    }
    config = load_config(scenario, {**overrides, **forced})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PinnedDroneWarning)
        env = gym.make("DeckLanding-v2", config=config)
    base = env.unwrapped
    stage = base.bank.vision
    rec = Recording(
        label,
        np.asarray(config.tof.mount_offsets_c, dtype=float),
        np.asarray(base.world.t_bc, dtype=float),
        stage.fusion.config,
        poses={name: [] for name in compare},
    )
    process = stage.process
    sources = stage.fusion.config.sources

    def recorded(time, estimates, ranges, imu_samples, r_wb):
        poses = [e for e in estimates.values() if e.method in sources and e.valid]
        rec.steps.append((float(time), np.array(r_wb), list(imu_samples), ranges, poses))
        return process(time, estimates, ranges, imu_samples, r_wb)

    stage.process = recorded

    def keep(info: dict) -> None:
        rec.truth.append(np.asarray(info["deck_pose_true"], dtype=float))
        for name in compare:
            estimate = info["estimates"][name]
            ok = bool(estimate["valid"])
            rec.poses[name].append(
                np.asarray(estimate["pose"], float) if ok else np.full(6, np.nan)
            )

    try:
        _, info = env.reset(seed=seed)
        keep(info)
        hover = np.zeros(env.action_space.shape, dtype=np.float32)
        for _ in range(base.max_steps):
            _, _, terminated, truncated, info = env.step(hover)
            keep(info)
            if terminated or truncated:
                break
    finally:
        env.close()
    return rec


@dataclass
class Replay:
    """``fused`` replayed on a recording: poses (N, 6; NaN invalid), the roll/pitch
    covariance (N, 2, 2, radians²) and the NIS of each step's pose update (NaN: none)."""

    time_s: np.ndarray
    pose: np.ndarray
    cov_tilt: np.ndarray
    nis: np.ndarray
    fusion: DeckFusion


#: the settings a replay takes from the code's defaults (or its overrides), never from the
#: recording: how the filter identifies the motion and models its sources' errors
_FILTER_OWN = ("identify_", "tilt_error_")


def settings(rec: Recording, **overrides: object) -> FusionConfig:
    """The filter's settings for a replay: the recorded run's (its sources, its sensors'
    noise, its prior, when the scenario gave one), with the identification and coloured-
    error settings at the code's defaults, then ``overrides``."""
    kept = {
        item.name: getattr(rec.fusion, item.name)
        for item in dataclasses.fields(FusionConfig)
        if not item.name.startswith(_FILTER_OWN)
    }
    return FusionConfig(**{**kept, **overrides})


def replay(rec: Recording, config: FusionConfig) -> Replay:
    """Run a fresh filter with ``config`` over the recorded inputs."""
    fusion = DeckFusion(config, rec.tof_positions_c, rec.t_bc)
    times, poses, covs, nis = [], [], [], []
    for time, r_wb, imu, ranges, delivered in rec.steps:
        estimate: DeckPoseEstimate = fusion.step(time, r_wb, imu, ranges, delivered)
        times.append(time)
        if estimate.valid and estimate.covariance is not None:
            poses.append(estimate.as_vector())
            covs.append(estimate.covariance[3:5, 3:5])
        else:
            poses.append(np.full(6, np.nan))
            covs.append(np.full((2, 2), np.nan))
        # the NIS of this step's pose update (the filter reports its latest per source)
        key = f"nis_tilt_{config.sources[0]}"
        nis.append(float(estimate.extras.get(key, np.nan)) if delivered else np.nan)
    return Replay(np.asarray(times), np.asarray(poses), np.asarray(covs), np.asarray(nis), fusion)
