"""The helideck monitoring system (HMS): the ship's own record of its helideck's motion.

A moving helideck carries one by rule: CAP 437 (UK Civil Aviation Authority, *Standards for
offshore helicopter landing areas*, 8th ed., amdt. 2 2021, Ch. 6) restricts operations to
vessels without an HMS meeting the Helideck Certification Agency's standard (HCA, *Standard
measuring equipment for helideck monitoring system (HMS) and weather data*, Rev. 9) to stable
decks, and the HMS's data is passed to the helicopter.  That standard asks for pitch, roll and
inclination accurate to 0.1 deg RMS, heave rate to 0.1 m/s RMS, and the motion sampled at 2 Hz
at least.  Its sensor is a motion reference unit; Kongsberg Seatex's MRU 5 (5th generation
data sheet, 2013): roll and pitch 0.02 deg RMS, heave 5 cm or 5 % (the larger), output up to
200 Hz.

:class:`HelideckMonitor` samples the helideck's pose (the deck motion source: surge, sway,
heave, roll and pitch at the helideck) at ``rate_hz`` with white Gaussian errors: the HCA's
0.1 deg bound on the angles (five times the MRU's) and the MRU's 5 cm or 5 % of the channel's
standard deviation on the positions.  An MRU's real error is coloured (its heave filter's
phase error at long periods); white noise at the bound is the simple stand-in.  The samples
are a fixed function of the sample's index and the monitor's seed, so overlapping windows read
the same record, before the episode's start too (the ship was at sea before the drone came).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimation.limits import Limit, Limited, limited
from landing_env.stewart.motion import MotionSource, sample_poses

#: the pose values the HMS reports, in this order (m and rad, the motion source's axes)
HMS_CHANNELS: tuple[str, ...] = ("x", "y", "z", "roll", "pitch")
#: their columns in a motion source's (x, y, z, roll, pitch, yaw) pose
_COLUMNS = [0, 1, 2, 3, 4]
#: samples per noise chunk (each drawn from its own seeded stream)
_CHUNK = 4096
#: chunk offset, so that samples before the episode's start have non-negative chunk seeds
_CHUNK_OFFSET = 1 << 32
#: samples per chunk of the true motion, each sampled as one block: a block's values do not
#: depend on which window reads them (a matrix product's rounding depends on its shape)
_TRUTH_CHUNK = 64


@dataclass(frozen=True)
class HelideckMonitorConfig(Limited):
    """What the ship's HMS reports to the drone, and how well (sources in the module's doc)."""

    #: samples per second on the link (HCA: at least 2; an MRU gives up to 200)
    rate_hz: float = limited(10.0, Limit(0.5, 1000.0))
    #: roll and pitch error, deg RMS (HCA Rev. 9's bound; the MRU 5 itself: 0.02)
    angle_noise_deg: float = limited(0.1, Limit(0.0, 10.0))
    #: surge, sway and heave error floor, m RMS (MRU 5: 5 cm ...)
    position_noise_m: float = limited(0.05, Limit(0.0, 10.0))
    #: ... or this fraction of the channel's standard deviation, whichever is larger
    position_noise_fraction: float = limited(0.05, Limit(0.0, 1.0))

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz


class HelideckMonitor:
    """The HMS record of one ship's helideck: ``motion`` sampled at the configured rate, with
    errors drawn from ``seed``."""

    def __init__(
        self,
        motion: MotionSource,
        config: HelideckMonitorConfig | None = None,
        seed: int = 0,
        spread_record_s: float = 600.0,
    ) -> None:
        self.motion = motion
        self.config = config or HelideckMonitorConfig()
        self.seed = int(seed) % 2**63
        self.dt_s = self.config.dt_s
        # the positions' 5 % term: the channel's spread over a stretch of the record
        times = np.arange(-spread_record_s, 0.0, self.dt_s)
        spread = np.std(sample_poses(motion, times)[:, _COLUMNS], axis=0)
        position = np.maximum(
            self.config.position_noise_m, self.config.position_noise_fraction * spread[:3]
        )
        #: (5,) error standard deviations of :data:`HMS_CHANNELS` (m and rad)
        self.noise_std = np.concatenate(
            [position, np.full(2, math.radians(self.config.angle_noise_deg))]
        )
        self._chunks: dict[int, np.ndarray] = {}
        self._truth_chunks: dict[int, np.ndarray] = {}

    def _noise(self, index: np.ndarray) -> np.ndarray:
        """Unit-variance errors (n, 5) of the samples ``index`` (a fixed function of each)."""

        def block(c: int) -> np.ndarray:
            rng = np.random.default_rng([self.seed, c + _CHUNK_OFFSET])
            return rng.standard_normal((_CHUNK, len(HMS_CHANNELS)))

        return _from_blocks(index, _CHUNK, self._chunks, block)

    def _truth(self, index: np.ndarray) -> np.ndarray:
        """The true values (n, 5) of the samples ``index``, each sampled in its fixed block."""

        def block(c: int) -> np.ndarray:
            times = (c * _TRUTH_CHUNK + np.arange(_TRUTH_CHUNK)) * self.dt_s
            return sample_poses(self.motion, times)[:, _COLUMNS]

        return _from_blocks(index, _TRUTH_CHUNK, self._truth_chunks, block)

    def window(self, t_end_s: float, window_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The record's samples in (``t_end_s - window_s``, ``t_end_s``], oldest first: their
        times (n,) and values (n, 5) of :data:`HMS_CHANNELS`."""
        last = math.floor(t_end_s / self.dt_s + 1e-9)
        n = max(1, round(window_s / self.dt_s))
        index = np.arange(last - n + 1, last + 1)
        return index * self.dt_s, self._truth(index) + self._noise(index) * self.noise_std


def _from_blocks(
    index: np.ndarray, size: int, cache: dict[int, np.ndarray], make: Callable[[int], np.ndarray]
) -> np.ndarray:
    """The rows ``index`` of a record kept in blocks of ``size`` rows: block ``c`` holds rows
    ``c * size`` on, made by ``make(c)`` when first read and kept in ``cache``."""
    out = np.empty((len(index), len(HMS_CHANNELS)))
    chunk = np.floor_divide(index, size)
    for c in np.unique(chunk):
        block = cache.get(int(c))
        if block is None:
            block = cache[int(c)] = make(int(c))
        here = chunk == c
        out[here] = block[index[here] - int(c) * size]
    return out
