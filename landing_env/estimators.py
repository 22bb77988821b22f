"""The estimators the environment runs each step: the observed one and those compared."""

from __future__ import annotations

from typing import TYPE_CHECKING

from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading
from landing_env.config import DeckLandingConfig

if TYPE_CHECKING:
    from landing_env.world import World


class TruthEstimator:
    """The ground-truth deck pose, in the estimate type; the reference and the default."""

    name = "truth"

    def __init__(self, world: World) -> None:
        self.world = world

    def reset(self) -> None:
        """Nothing to forget."""

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        rotation, translation = self.world.true_deck_pose_c()
        return DeckPoseEstimate(
            method=self.name,
            timestamp=frame.timestamp,
            valid=True,
            rotation=rotation,
            translation=translation,
        )


class EstimatorBank:
    """Runs the observed estimator and every compared one on the same sensor data."""

    def __init__(self, config: DeckLandingConfig, world: World) -> None:
        names = dict.fromkeys((config.estimation.observed, *config.estimation.compare))
        self.estimators = {name: self._make(name, config, world) for name in names}

    @staticmethod
    def _make(name: str, config: DeckLandingConfig, world: World):
        if name == "truth":
            return TruthEstimator(world)
        raise NotImplementedError(f"estimator {name!r} is not wired into the environment yet")

    def reset(self) -> None:
        for estimator in self.estimators.values():
            estimator.reset()

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> dict[str, DeckPoseEstimate]:
        results = {}
        for name, estimator in self.estimators.items():
            try:
                results[name] = estimator.estimate(frame, ranges)
            except Exception as exc:  # an estimator must never break step(): flag it instead
                results[name] = DeckPoseEstimate.invalid(
                    name, frame.timestamp, f"estimator error: {type(exc).__name__}: {exc}"
                )
        return results
