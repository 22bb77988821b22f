"""The degraded vision link: latency, irregular rate and dropouts of the camera estimates.

SVGS (paper 003, Sec. 2.4) runs its vision on a phone: readings arrive 175–230 ms after the
image was taken, at an irregular 6–15 Hz, and some never arrive.  :class:`VisionLink` puts
the camera-based deck-pose estimates through such a pipeline before the observation and the
fusion see them.  At each camera frame (one control step) the pipeline takes the frame when
its next (randomly spaced) capture is due, drops it with ``dropout_prob``, or delivers it
``latency_s ± latency_jitter_s`` later (the first step at or after then), stamped with its
capture time.  Between deliveries the observation holds the latest delivered estimate (stale:
what a policy would have) for up to ``max_age_s``; beyond that, or before the first delivery,
the estimate is invalid.  All randomness comes from the generator given at :meth:`reset`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from estimation.fusion import METHOD as FUSED
from estimation.fusion import DeckFusion, FusionConfig
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from estimation.types import DeckPoseEstimate, ImuSample, RangeReading
from landing_env.errors import ConfigError

#: estimators the link never delays: the reference and the fusion (which fuses delayed input)
UNDELAYED: frozenset[str] = frozenset({"truth", FUSED})


@dataclass
class VisionLinkConfig:
    """The camera pipeline's latency, rate and dropouts (defaults: SVGS on a phone)."""

    #: off by default: the existing scenarios see every estimate at once
    enabled: bool = False
    #: mean delay from image capture to delivery, seconds
    latency_s: float = limited(0.2025, NON_NEGATIVE, physical=Limit.non_negative(10.0))
    #: the delay is uniform in latency_s ± latency_jitter_s (175–230 ms by default, the SVGS
    #: paper's measurement-to-flight-controller latency, Sec. 2.4)
    latency_jitter_s: float = limited(0.0275, physical=Limit.non_negative(10.0))
    #: the pipeline's rate, drawn uniformly in [min, max] for each frame it takes, Hz
    rate_hz: tuple[float, float] = limited((6.0, 15.0), physical=Limit.positive(1e3))
    #: probability that a taken frame never arrives
    dropout_prob: float = limited(0.0, Limit(0.0, 1.0))
    #: a delivered estimate is shown (stale) until it is this old, seconds
    max_age_s: float = limited(1.0, POSITIVE, physical=Limit.positive(60.0))

    def __post_init__(self) -> None:
        require_limits(self)
        if not 0.0 <= self.latency_jitter_s <= self.latency_s:
            raise ConfigError(
                "latency_jitter_s",
                f"{self.latency_jitter_s} must lie in [0, latency_s = {self.latency_s}] "
                "(a delay is never negative)",
            )
        self.rate_hz = tuple(float(v) for v in self.rate_hz)  # type: ignore[assignment]
        if len(self.rate_hz) != 2 or not 0.0 < self.rate_hz[0] <= self.rate_hz[1]:
            raise ConfigError("rate_hz", f"{self.rate_hz!r} must be [min, max] with 0 < min <= max")


@dataclass
class _InFlight:
    capture_time: float
    delivery_time: float
    estimates: dict[str, DeckPoseEstimate]


@dataclass
class LinkOutput:
    """One step through the link."""

    #: per estimator: what the observation shows now (held, stale, or invalid)
    shown: dict[str, DeckPoseEstimate]
    #: estimates delivered at this step (each stamped with its capture time), oldest first
    delivered: list[dict[str, DeckPoseEstimate]] = field(default_factory=list)
    #: this step's frame was taken by the pipeline / taken and then dropped
    captured: bool = False
    dropped: bool = False


class VisionLink:
    """Delays, thins and drops the camera-based estimates (see the module docstring)."""

    def __init__(self, config: VisionLinkConfig) -> None:
        self.config = config
        self.reset(np.random.default_rng(0))

    def reset(self, rng: np.random.Generator) -> None:
        """A new episode with its own random stream."""
        self.rng = rng
        self._next_capture = -math.inf
        self._in_flight: list[_InFlight] = []
        self._held: dict[str, DeckPoseEstimate] = {}
        self._last_delivery = -math.inf
        self.counts = {"captured": 0, "dropped": 0, "delivered": 0}

    def process(self, time: float, estimates: dict[str, DeckPoseEstimate]) -> LinkOutput:
        """Put this step's estimates (of a frame captured at ``time``) through the link."""
        cfg = self.config
        delayed = {k: v for k, v in estimates.items() if k not in UNDELAYED}
        captured = dropped = False
        if time >= self._next_capture - 1e-9:
            captured = True
            self.counts["captured"] += 1
            # three draws per taken frame, always, so the stream does not depend on outcomes
            period_u, drop_u, latency_u = self.rng.random(3)
            low, high = cfg.rate_hz
            period = 1.0 / (low + (high - low) * period_u)
            # keep to the schedule; a schedule the camera cannot keep restarts from now
            base = self._next_capture if math.isfinite(self._next_capture) else time
            self._next_capture = max(base + period, time + 1e-6)
            if drop_u < cfg.dropout_prob:
                dropped = True
                self.counts["dropped"] += 1
            else:
                latency = cfg.latency_s + cfg.latency_jitter_s * (2.0 * latency_u - 1.0)
                # a pipeline delivers in order: never before the previous delivery
                delivery = max(time + latency, self._last_delivery)
                self._last_delivery = delivery
                self._in_flight.append(_InFlight(time, delivery, dict(delayed)))
        delivered = []
        while self._in_flight and self._in_flight[0].delivery_time <= time + 1e-9:
            item = self._in_flight.pop(0)
            self.counts["delivered"] += 1
            delivered.append(item.estimates)
            self._held.update(item.estimates)
        shown = {k: v for k, v in estimates.items() if k in UNDELAYED}
        fresh = {name for batch in delivered for name in batch}
        for name in delayed:
            shown[name] = self._shown(name, time, name in fresh)
        return LinkOutput(shown, delivered, captured, dropped)

    def _shown(self, name: str, time: float, fresh: bool) -> DeckPoseEstimate:
        held = self._held.get(name)
        if held is None:
            return DeckPoseEstimate.invalid(name, time, "vision_link_waiting")
        age = time - held.timestamp
        extras = {**held.extras, "age_s": age, "capture_time_s": held.timestamp, "fresh": fresh}
        if age > self.config.max_age_s + 1e-9:
            return DeckPoseEstimate(
                name, held.timestamp, False, reason="vision_link_stale", extras=extras
            )
        return replace(held, extras=extras)


class VisionStage:
    """What follows the per-frame estimators: the vision link (when enabled) and the ``fused``
    EKF (when asked for), fed with the delivered poses of its sources, the ToF ranges, the
    step's IMU samples and the drone attitude (the autopilot's attitude estimate).

    Nothing raises from :meth:`process`: a failing fusion gives an invalid ``fused`` estimate.
    """

    def __init__(
        self,
        link: VisionLinkConfig,
        fusion: FusionConfig | None,
        tof_positions_c: np.ndarray,
        t_bc: np.ndarray,
    ) -> None:
        self.link = VisionLink(link) if link.enabled else None
        self.fusion = DeckFusion(fusion, tof_positions_c, t_bc) if fusion is not None else None

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """A new episode; the link draws from a stream spawned from ``rng``."""
        if self.link is not None:
            # spawning draws nothing from rng: the other streams are unchanged by the link
            self.link.reset(rng.spawn(1)[0] if rng is not None else np.random.default_rng(0))
        if self.fusion is not None:
            self.fusion.reset()

    def process(
        self,
        time: float,
        estimates: dict[str, DeckPoseEstimate],
        ranges: RangeReading,
        imu_samples: Sequence[ImuSample],
        r_wb: np.ndarray,
    ) -> dict[str, DeckPoseEstimate]:
        """The estimates as the observation shows them, with ``fused`` added when configured."""
        if self.link is not None:
            output = self.link.process(time, estimates)
            shown = output.shown
            arrived = [est for batch in output.delivered for est in batch.values()]
        else:
            shown = dict(estimates)
            arrived = list(estimates.values())
        if self.fusion is None:
            return shown
        sources = self.fusion.config.sources
        poses = [est for est in arrived if est.method in sources and est.valid]
        try:
            fused = self.fusion.step(time, r_wb, imu_samples, ranges, poses)
        except Exception as exc:  # the fusion must never break step(): flag it instead
            fused = DeckPoseEstimate.invalid(
                FUSED, time, f"estimator error: {type(exc).__name__}: {exc}"
            )
        if self.link is not None:
            fused.extras.update({f"link_{k}": v for k, v in self.link.counts.items()})
        shown[FUSED] = fused
        return shown
