"""The live simulator as a source of ``(stamp_s, estimate)`` pairs for the MAVLink bridge.

:class:`SimulatorSource` flies ``DeckLanding-v2`` episodes under the align-descend policy
(:class:`agents.policies.align_descend.AlignDescendPolicy`, as ``deck-landing demo``) with the
chosen estimator observed, and yields the observed estimate of every control step: after the reset
and after each step.  The stamp is the estimate's own (the camera frame's capture time in
simulated seconds; with the vision link, its capture time, not its delivery), continued across
episodes so that it never runs backwards: episode k's stamps are offset by the simulated
length of the episodes before it plus one control period.

It also keeps the drone's pose at each capture, for the autopilots that need the vehicle's
pose at the measurement's time (PX4): :meth:`vehicle_pose` looks it up by stamp, in the local
NED frame whose origin is the simulator's world origin (x north, the world's y left → east
is -y, z down).  ``speed`` paces the simulation against the wall clock (1: real time, 2: twice
as fast); 0 runs it as fast as it goes.

:meth:`clock_s` is the clock of the stamps read on the wall clock (paced runs only,
:class:`agents.io.pacing.StampPacer`): the companion's clock for TIMESYNC when the autopilot
maps ``time_usec`` or gives the vehicle's pose
(:class:`agents.io.autopilot_listener.AutopilotListener`).  It starts at the first call of it
or of the stream, whichever comes first.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterator
from typing import Any

import gymnasium as gym

import landing_env  # noqa: F401  (registers the environments)
from agents.io.landing_target import CameraMount, VehiclePose
from agents.io.pacing import StampPacer
from agents.policies.align_descend import AlignDescendPolicy
from agents.policies.registry import make_env_and_policy
from estimation.errors import ConfigError, require_choice
from estimation.registry import ESTIMATOR_NAMES
from estimation.types import DeckPoseEstimate
from landing_env.scenarios import LANDING_TASK

#: how many captures' vehicle poses are kept (the vision link delivers up to ~1 s late)
POSE_HISTORY = 256


class SimulatorSource:
    """Seeded ``DeckLanding-v2`` episodes as a stream of observed estimates.

    ``config``: a config name or path, flown as it is; ``scenario``: a scenario's landing id
    with its own starts (:func:`agents.policies.registry.make_env_and_policy`, as the landing
    evaluations fly it); give one of the two.
    ``overrides`` (dotted keys) apply last.
    """

    def __init__(
        self,
        config: str | None = "default",
        scenario: str | None = None,
        estimator: str = "tight",
        camera_mode: str = "project",
        episodes: int = 1,
        seed: int = 0,
        speed: float = 1.0,
        overrides: dict[str, Any] | None = None,
    ) -> None:
        require_choice("estimator", estimator, ESTIMATOR_NAMES)
        require_choice("mode", camera_mode, ("project", "render"))
        if episodes < 1:
            raise ConfigError("episodes", f"{episodes} is out of range; allowed [1, inf]")
        self.pacer = StampPacer(speed)
        if scenario is not None:
            # the scenario's own landing id and starts, as the landing evaluations fly it
            self.env, _ = make_env_and_policy(
                "align-descend",
                scenario,
                estimator,
                camera_mode,
                extra_overrides=overrides,
            )
        else:
            chosen = {"estimation.observed": estimator, "camera.mode": camera_mode}
            chosen.update(overrides or {})
            self.env = gym.make(LANDING_TASK, config=config, overrides=chosen)
        base = self.env.unwrapped
        self.base = base
        self.estimator = estimator
        self.episodes = episodes
        self.seed = seed
        self.speed = float(speed)
        self.mount = CameraMount(t_bc=base.world.t_bc)
        self.policy = AlignDescendPolicy(
            base.config.action, dt=base.env_dt, tof_mounts_c=base.config.tof.mount_offsets_c
        )
        self.outcomes: list[str] = []
        self._poses: OrderedDict[float, VehiclePose] = OrderedDict()
        self._offset_s = 0.0

    def clock_s(self) -> float:
        """Now, on the clock of the stamps (simulated seconds as paced on the wall clock)."""
        return self.pacer.clock_s()

    # ----------------------------------------------------------------- vehicle poses
    def vehicle_pose(self, stamp_s: float) -> VehiclePose | None:
        """The drone's pose at the capture stamped ``stamp_s`` (None when not kept)."""
        return self._poses.get(stamp_s)

    def _keep_pose(self) -> None:
        state = self.base.world.drone_state()
        stamp = self._offset_s + float(self.base.world.time)
        self._poses[stamp] = VehiclePose.from_world(state.position_w, state.rotation_wb)
        while len(self._poses) > POSE_HISTORY:
            self._poses.popitem(last=False)

    def _observed(self) -> DeckPoseEstimate:
        sensing = self.base._sensing  # the step's sensor data (DeckLandingBaseEnv)
        return sensing.estimates[self.base.config.estimation.observed]

    # ----------------------------------------------------------------- the stream
    def __iter__(self) -> Iterator[tuple[float, DeckPoseEstimate]]:
        env, base = self.env, self.base
        self.pacer.start()
        for episode in range(self.episodes):
            observation, _ = env.reset(seed=self.seed + episode)
            self.policy.reset()
            self._keep_pose()
            estimate = self._observed()
            yield self._offset_s + estimate.timestamp, estimate
            info: dict[str, Any] = {}
            while True:
                # the next capture happens at its simulated time on the wall clock
                self.pacer.wait_until(self._offset_s + base.world.time + base.env_dt)
                action = self.policy(observation)
                observation, _, terminated, truncated, info = env.step(action)
                self._keep_pose()
                estimate = self._observed()
                yield self._offset_s + estimate.timestamp, estimate
                if terminated or truncated:
                    break
            self.outcomes.append(str(info.get("outcome", "")))
            self._offset_s += float(base.world.time) + base.env_dt

    def close(self) -> None:
        self.env.close()

    def __enter__(self) -> SimulatorSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def summary(self) -> str:
        """What was flown, for the command's report."""
        return f"episodes: {', '.join(self.outcomes)}"


__all__ = ["POSE_HISTORY", "SimulatorSource"]
