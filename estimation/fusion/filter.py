"""The delayed-measurement EKF of the drone–deck relative state (the ``fused`` estimator).

Delayed fusion (the idea of PX4 EKF2's buffer, implemented as re-propagation): every input
(IMU sample, ToF reading, pose measurement) is an event keyed by its timestamp, kept for
``horizon_s`` with the filter's state and covariance after it.  A measurement that arrives
late (the vision link's latency) is inserted at its own timestamp, the filter restarts from
the state just before it and re-applies every later event, so it gives exactly what fusing it
on time would have.  A measurement older than the horizon is rejected and counted
(``too_old``).  Each update passes a gate on its normalised innovation squared (NIS): a
chi-square quantile, or a Mahalanobis distance in standard deviations (``gate_sd``, as PX4
EKF2 states its gates); after ``reset_timeout_s`` without an accepted pose update the filter
resets and re-initialises from the next pose measurement (the accelerometer bias estimate survives).

Counts in the diagnostics cover every event ever applied, with the decisions of the events
still in the buffer as of their latest replay.
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from estimation.frames import R_BC, R_PD, euler_zyx_from_matrix, matrix_from_euler_zyx
from estimation.fusion.config import FusionConfig
from estimation.fusion.identify import DeckMotionIdentifier
from estimation.fusion.model import (
    BA,
    N_COLOURED,
    N_STATE,
    N_STATE_4,
    TH,
    P,
    TwoWaves,
    V,
    W,
    ekf_update,
    predict,
    rotation_zyx,
    tof_model,
    wrap_angle,
)
from estimation.types import DeckPoseEstimate, ImuSample, RangeReading

METHOD = "fused"
#: event kinds in the order they are applied at one timestamp: predict, then ToF, then poses
_ORDER = {"imu": 0, "tof": 1, "pose": 2}


@dataclass(frozen=True)
class _Snapshot:
    """The filter after an event."""

    time: float
    x: np.ndarray
    cov: np.ndarray
    initialised: bool
    #: timestamp of the last accepted pose update (or of the initialisation)
    last_pose_time: float


@dataclass
class _Event:
    time: float
    order: int
    seq: int
    kind: str
    source: str
    r_wb: np.ndarray
    #: imu: specific force (3); tof: ranges (NaN = invalid); pose: z (6)
    data: np.ndarray
    #: pose: the measurement's axes (6x6, rows in the state's axes: R_WC's columns for a
    #: translation given in the camera frame, else the state's own), its covariance (6x6) in
    #: those axes and the mask of the components used
    axes: np.ndarray | None = None
    noise: np.ndarray | None = None
    mask: np.ndarray | None = None
    after: _Snapshot | None = None
    #: pose: it already holds the ToF ranges of its frame (tight); tof: a pose that holds
    #: these ranges has arrived, so they are not fused again
    includes_ranges: bool = False
    superseded: bool = False
    outcome: Counter = field(default_factory=Counter)
    nis: float = float("nan")
    #: pose: the NIS of its roll and pitch alone
    nis_tilt: float = float("nan")

    @property
    def key(self) -> tuple[float, int, int]:
        return (self.time, self.order, self.seq)


def pose_measurement(
    estimate: DeckPoseEstimate, r_wb: np.ndarray, t_bc: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A T_CD estimate as the state's (p, th): the deck origin relative to the body's centre
    in W, and the deck's ZYX Euler angles in W; also R_WC (the camera's axes in W)."""
    r_wc = r_wb @ R_BC
    p = r_wc @ estimate.translation + r_wb @ t_bc
    th = euler_zyx_from_matrix(r_wc @ estimate.rotation @ R_PD.T)
    return np.concatenate([p, th]), r_wc


def _measurement_jacobian(
    estimate: DeckPoseEstimate, r_wb: np.ndarray, t_bc: np.ndarray, z: np.ndarray
) -> np.ndarray:
    """d(p, th)/d(x, y, z, roll, pitch, yaw of T_CD): the translation part is R_WC, the
    angles' by central differences (six small matrix products)."""
    jac = np.zeros((6, 6))
    jac[:3, :3] = r_wb @ R_BC
    euler = euler_zyx_from_matrix(estimate.rotation)
    step = 1e-6
    for k in range(3):
        delta = np.zeros(3)
        delta[k] = step
        up = dataclasses.replace(estimate, rotation=matrix_from_euler_zyx(*(euler + delta)))
        down = dataclasses.replace(estimate, rotation=matrix_from_euler_zyx(*(euler - delta)))
        z_up, _ = pose_measurement(up, r_wb, t_bc)
        z_down, _ = pose_measurement(down, r_wb, t_bc)
        jac[3:, 3 + k] = wrap_angle(z_up[3:] - z_down[3:]) / (2.0 * step)
    return jac


class DeckFusion:
    """EKF of the relative drone–deck state with delayed, gated measurements.

    ``tof_positions_c``: the ToF sensors' origins in the camera frame (n x 3, they measure
    along +z_C); ``t_bc``: the camera origin in the body frame.  The drone attitude passed to
    :meth:`step` is the autopilot's attitude estimate (an input, not a state).
    """

    def __init__(self, config: FusionConfig, tof_positions_c: np.ndarray, t_bc: np.ndarray) -> None:
        self.config = config
        self.t_bc = np.asarray(t_bc, dtype=float)
        mounts = np.asarray(tof_positions_c, dtype=float).reshape(-1, 3)
        self.tof_origins_b = self.t_bc + mounts @ R_BC.T
        self._gates = {dof: config.gate(dof) for dof in range(1, 7)}
        self._tof_noise = config.tof_noise
        self._deck4_initial = config.deck4_initial
        self._n = N_STATE_4 if self._deck4_initial is not None else N_STATE
        #: the coloured roll/pitch pose errors, the state's last entries (None: not modelled)
        self._coloured: slice | None = None
        if config.tilt_error_correlation_s > 0.0 and config.tilt_error_coloured_share > 0.0:
            self._coloured = slice(self._n, self._n + N_COLOURED)
            self._n += N_COLOURED
        self.identifier = (
            DeckMotionIdentifier(
                config.identify_window_s,
                config.identify_sample_s,
                config.identify_min_window_s,
                config.identify_refit_s,
                (config.identify_period_range_s[0], config.identify_period_range_s[1]),
                (config.identify_damping_range[0], config.identify_damping_range[1]),
                config.identify_noise_gain,
                config.identify_ar_order,
            )
            if config.identifies
            else None
        )
        self.reset()

    # ------------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        """Forget everything (a new episode)."""
        cov = np.zeros((self._n, self._n))
        cov[BA, BA] = np.eye(3) * self.config.initial_accel_bias_sigma**2
        self._base = _Snapshot(-math.inf, np.zeros(self._n), cov, False, -math.inf)
        self._head = self._base
        self._events: list[_Event] = []
        self._keys: list[tuple[float, int, int]] = []
        self._final: Counter = Counter()
        self._seq = 0
        self._now = -math.inf
        self._last_r_wb: np.ndarray | None = None
        self._attitudes: list[tuple[float, np.ndarray]] = []
        self._last_nis: dict[str, float] = {}
        self._deck4 = self._deck4_initial
        if self.identifier is not None:
            self.identifier.reset()

    # ------------------------------------------------------------------ inputs
    def step(
        self,
        time: float,
        r_wb: np.ndarray,
        imu_samples: Sequence[ImuSample] = (),
        ranges: RangeReading | None = None,
        poses: Sequence[DeckPoseEstimate] = (),
    ) -> DeckPoseEstimate:
        """Feed one control step's inputs and return the fused estimate at ``time``.

        ``r_wb``: the drone attitude at ``time``; ``imu_samples``: the samples since the last
        call; ``ranges``: the ToF reading at ``time``; ``poses``: pose estimates delivered now,
        each stamped with its capture time (older ones are fused at that time).
        """
        r_wb = np.asarray(r_wb, dtype=float)
        events: list[_Event] = []
        events += self._imu_events(imu_samples, r_wb)
        self._now = max([self._now, float(time), *(e.time for e in events)])
        self._attitudes.append((float(time), r_wb.copy()))
        if ranges is not None and self.config.use_tof and np.any(ranges.valid):
            data = np.where(ranges.valid, ranges.ranges, np.nan).astype(float)
            events.append(self._event(float(ranges.timestamp), "tof", "tof", r_wb, data))
        for estimate in poses:
            event = self._pose_event(estimate)
            if event is not None:
                events.append(event)
        self._add(events)
        self._prune()
        return self.estimate(time, r_wb)

    def _event(
        self, time: float, kind: str, source: str, r_wb: np.ndarray, data: np.ndarray
    ) -> _Event:
        self._seq += 1
        return _Event(time, _ORDER[kind], self._seq, kind, source, r_wb, data)

    def _imu_events(self, samples: Sequence[ImuSample], r_wb_end: np.ndarray) -> list[_Event]:
        if not len(samples):
            self._last_r_wb = r_wb_end
            return []
        # the attitude at each sample: integrate the gyro from the last known attitude
        start = self._last_r_wb if self._last_r_wb is not None else r_wb_end
        times = np.array([s.timestamp for s in samples], dtype=float)
        gyro = np.array([s.gyro for s in samples], dtype=float)
        previous = np.concatenate([[self._head_time_or(times[0])], times[:-1]])
        steps = Rotation.from_rotvec(gyro * np.clip(times - previous, 0.0, None)[:, None])
        events = []
        r = start
        for sample, increment in zip(samples, steps.as_matrix(), strict=True):
            r = r @ increment
            events.append(
                self._event(
                    float(sample.timestamp), "imu", "imu", r, np.asarray(sample.accel, float)
                )
            )
        self._last_r_wb = r_wb_end
        return events

    def _head_time_or(self, default: float) -> float:
        last = self._events[-1].time if self._events else self._head.time
        return last if math.isfinite(last) else default

    def _attitude_at(self, time: float) -> np.ndarray | None:
        if not self._attitudes:
            return None
        times = [t for t, _ in self._attitudes]
        i = bisect.bisect_left(times, time)
        candidates = [j for j in (i - 1, i) if 0 <= j < len(times)]
        best = min(candidates, key=lambda j: abs(times[j] - time))
        return self._attitudes[best][1]

    def _pose_event(self, estimate: DeckPoseEstimate) -> _Event | None:
        source = estimate.method
        if not estimate.valid or source not in self.config.sources:
            return None
        time = float(estimate.timestamp)
        if time < self._now - self.config.horizon_s or time < self._base.time:
            self._final[f"{source}_too_old"] += 1
            return None
        r_wb = self._attitude_at(time)
        if r_wb is None:
            return None
        z, r_wc = pose_measurement(estimate, r_wb, self.t_bc)
        if not np.all(np.isfinite(z)):
            return None
        own = estimate.covariance
        if (
            source in self.config.covariance_sources
            and own is not None
            and np.shape(own) == (6, 6)
            and np.all(np.isfinite(own))
        ):
            # the source's covariance of T_CD's (x, y, z, roll, pitch, yaw), carried into
            # the state's axes through the measurement function's Jacobian
            jac = _measurement_jacobian(estimate, r_wb, self.t_bc, z)
            noise = jac @ own @ jac.T
            mask = np.ones(6, dtype=bool)
            axes = np.eye(6)
        else:
            sigma = np.asarray(self.config.pose_sigma(source), dtype=float)
            mask = np.isfinite(sigma)
            sigma = np.where(mask, sigma, 1.0)
            sigma[3:] = np.deg2rad(sigma[3:])
            # the translation's sigmas are along the camera's axes: the measurement is taken
            # along them, so that a component dropped (IHRCF's and CRHF's depth) is the
            # camera's and lends none of its stand-in sigma to the others
            noise = np.diag(sigma**2)
            axes = np.eye(6)
            axes[:3, :3] = r_wc.T
        if self.config.tilt_error_sigma_scale != 1.0:
            scale = np.ones(6)
            scale[3:5] = self.config.tilt_error_sigma_scale
            noise = noise * np.outer(scale, scale)
        event = self._event(time, "pose", source, r_wb, z)
        event.axes, event.noise, event.mask = axes, noise, mask
        event.includes_ranges = bool(estimate.extras.get("ranges_used", 0))
        return event

    # ------------------------------------------------------------------ the buffer
    def _add(self, events: list[_Event]) -> None:
        if not events:
            return
        first = len(self._events)
        for event in events:
            i = bisect.bisect_right(self._keys, event.key)
            self._keys.insert(i, event.key)
            self._events.insert(i, event)
            first = min(first, i)
        # a pose that already fused its frame's ranges (tight) supersedes that frame's ToF
        # event: each reading is used once, and the filter replays from it
        for event in events:
            if event.kind != "pose" or not event.includes_ranges:
                continue
            i = bisect.bisect_left(self._keys, (event.time - 1e-9, -1, -1))
            while i < len(self._events) and self._events[i].time <= event.time + 1e-9:
                other = self._events[i]
                if other.kind == "tof" and not other.superseded:
                    other.superseded = True
                    first = min(first, i)
                i += 1
        # later events already applied were inserted after `first`: replay from there
        snap = self._events[first - 1].after if first > 0 else self._base
        assert snap is not None
        for event in self._events[first:]:
            snap = self._apply(event, snap)
            event.after = snap
        self._head = snap

    def _prune(self) -> None:
        cutoff = self._now - self.config.horizon_s
        n = 0
        while n < len(self._events) and self._events[n].time < cutoff:
            n += 1
        for event in self._events[:n]:
            self._final.update(event.outcome)
            assert event.after is not None
            self._base = event.after
            if self.identifier is not None and event.kind == "pose" and event.after.initialised:
                self._identify(event)
        del self._events[:n], self._keys[:n]
        while len(self._attitudes) > 1 and self._attitudes[1][0] < cutoff:
            self._attitudes.pop(0)

    def _identify(self, event: _Event) -> None:
        """Feed the identifier the deck's roll and pitch after a pose update that has left the
        buffer (final: no late measurement can change it), and take its refitted model."""
        assert self.identifier is not None and event.after is not None
        roll, pitch = event.after.x[6], event.after.x[7]
        if self.identifier.add(event.time, float(roll), float(pitch)):
            self._deck4 = self.identifier.deck4

    # ------------------------------------------------------------------ one event
    def _apply(self, event: _Event, snap: _Snapshot) -> _Snapshot:
        cfg = self.config
        event.outcome = Counter()
        event.nis = event.nis_tilt = float("nan")
        x, cov, initialised, last_pose = snap.x, snap.cov, snap.initialised, snap.last_pose_time
        if initialised and event.time - last_pose > cfg.reset_timeout_s:
            initialised = False
            event.outcome["resets"] += 1
        time = snap.time
        if event.kind == "imu":
            if initialised and event.time > snap.time:
                x, cov = predict(
                    x,
                    cov,
                    event.data,
                    event.r_wb,
                    event.time - snap.time,
                    cfg.deck_accel_psd,
                    cfg.deck_angular_accel_psd,
                    cfg.accel_noise_density,
                    cfg.accel_bias_random_walk,
                    cfg.deck_w0,
                    cfg.deck_damping_ratio,
                    self._deck4,
                    cfg.tilt_error_correlation_s if self._coloured is not None else 0.0,
                )
            time = max(time, event.time)
        elif event.kind == "tof":
            if event.superseded:
                event.outcome["tof_superseded"] += 1
            elif initialised:
                x, cov = self._update_tof(event, x, cov)
        elif not initialised:
            x, cov = self._initialise(event, x, cov)
            initialised, last_pose = True, event.time
            event.outcome[f"{event.source}_initialised"] += 1
            time = max(time, event.time) if math.isfinite(time) else event.time
        else:
            x, cov, accepted = self._update_pose(event, x, cov)
            if accepted:
                last_pose = max(last_pose, event.time)
        return _Snapshot(time, x, cov, initialised, last_pose)

    def _initialise(
        self, event: _Event, x: np.ndarray, cov: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.config
        assert event.noise is not None and event.mask is not None and event.axes is not None
        new_x = np.zeros(self._n)
        new_x[P], new_x[TH] = event.data[:3], event.data[3:]
        new_x[BA] = x[BA]  # the IMU's bias does not depend on the vision
        new_cov = np.zeros((self._n, self._n))
        noise = event.noise.copy()
        # a component the source does not give starts wide open (the gate will not bite)
        noise[~event.mask, :] = 0.0
        noise[:, ~event.mask] = 0.0
        wide = np.array([1.0, 1.0, 1.0, 0.5, 0.5, math.pi]) ** 2
        noise[~event.mask, ~event.mask] = wide[~event.mask]
        noise = event.axes.T @ noise @ event.axes  # from the measurement's axes into W
        new_cov[:3, :3] = noise[:3, :3]
        new_cov[TH, TH] = noise[3:, 3:]
        new_cov[V, V] = np.eye(3) * cfg.initial_velocity_sigma**2
        new_cov[W, W] = np.eye(3) * cfg.initial_rate_sigma**2
        new_cov[BA, BA] = cov[BA, BA]
        if self._coloured is not None and event.mask[3] and event.mask[4]:
            # the pose's tilt is the deck's plus its coloured error: they start anticorrelated
            new_cov[self._coloured, self._coloured] = np.eye(N_COLOURED)
            new_cov[6:8, self._coloured] = -self._coloured_gain(event.noise)
            new_cov[self._coloured, 6:8] = new_cov[6:8, self._coloured].T
        elif self._coloured is not None:
            new_cov[self._coloured, self._coloured] = np.eye(N_COLOURED)
        for i, model in enumerate(self._deck4 or ()):
            # the deck's angular acceleration and jerk (or second wave component's angle and
            # rate) start at the sea's stationary spread
            sigmas = model.second_sigmas if isinstance(model, TwoWaves) else model[2]
            new_cov[15 + i, 15 + i] = sigmas[0] ** 2
            new_cov[17 + i, 17 + i] = sigmas[1] ** 2
        return new_x, new_cov

    def _update_pose(
        self, event: _Event, x: np.ndarray, cov: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        assert event.noise is not None and event.mask is not None and event.axes is not None
        mask = event.mask
        h_full = np.zeros((6, self._n))
        h_full[0:3, P] = np.eye(3)
        h_full[3:6, TH] = np.eye(3)
        innovation = event.data - np.concatenate([x[P], x[TH]])
        innovation[3:] = wrap_angle(innovation[3:])
        # along the measurement's axes (the angles' rows are the state's own)
        innovation, h_full = event.axes @ innovation, event.axes @ h_full
        noise = event.noise
        if self._coloured is not None and mask[3] and mask[4]:
            # the tilt = the deck's + the coloured error (its share of the variance) + white
            innovation[3:5] -= self._coloured_gain(noise) @ x[self._coloured]
            h_full[3:5, self._coloured] = self._coloured_gain(noise)
            white = np.sqrt(1.0 - self.config.tilt_error_coloured_share)
            scale = np.ones(6)
            scale[3:5] = white
            noise = noise * np.outer(scale, scale)
        if mask[3] and mask[4]:
            # the roll/pitch part of the NIS (chi-square with 2 degrees of freedom)
            tilt = h_full[3:5] @ cov @ h_full[3:5].T + noise[3:5, 3:5]
            event.nis_tilt = float(innovation[3:5] @ np.linalg.solve(tilt, innovation[3:5]))
        h = h_full[mask]
        noise = noise[np.ix_(mask, mask)]
        gate = self._gates[int(mask.sum())]
        x, cov, nis, accepted = ekf_update(x, cov, innovation[mask], h, noise, gate)
        x[TH] = wrap_angle(x[TH])
        event.nis = nis
        event.outcome[f"{event.source}_{'accepted' if accepted else 'rejected'}"] += 1
        return x, cov, accepted

    def _coloured_gain(self, noise: np.ndarray) -> np.ndarray:
        """How the unit coloured-error states enter a pose's roll and pitch: the Cholesky
        factor of that pose's tilt noise, scaled to the coloured share of its variance."""
        tilt = noise[3:5, 3:5]
        try:
            factor = np.linalg.cholesky(0.5 * (tilt + tilt.T))
        except np.linalg.LinAlgError:
            factor = np.diag(np.sqrt(np.clip(np.diag(tilt), 0.0, None)))
        return math.sqrt(self.config.tilt_error_coloured_share) * factor

    def _update_tof(
        self, event: _Event, x: np.ndarray, cov: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        gate = self._gates[1]
        nis_values = []
        # one scalar update per sensor: a ray off the deck edge is rejected alone
        for origin, measured in zip(self.tof_origins_b, event.data, strict=True):
            if not math.isfinite(measured):
                continue
            model = tof_model(x, origin, event.r_wb)
            if model is None:
                event.outcome["tof_rejected"] += 1
                continue
            predicted, h = model
            sigma = self._tof_noise.sigma_scalar(measured)
            x, cov, nis, accepted = ekf_update(
                x,
                cov,
                np.array([measured - predicted]),
                h[None, :],
                np.array([[sigma * sigma]]),
                gate,
            )
            nis_values.append(nis)
            event.outcome[f"tof_{'accepted' if accepted else 'rejected'}"] += 1
        x[TH] = wrap_angle(x[TH])
        if nis_values:
            event.nis = float(np.mean(nis_values))
        return x, cov

    # ------------------------------------------------------------------ output
    @property
    def state(self) -> np.ndarray:
        """The current state (see :mod:`estimation.fusion.model`)."""
        return self._head.x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """The current 15x15 state covariance."""
        return self._head.cov.copy()

    @property
    def initialised(self) -> bool:
        return self._head.initialised

    def diagnostics(self) -> dict[str, float | int | bool]:
        """Counts (accepted, rejected, too old, resets, per kind) and the latest NIS per kind."""
        counts = Counter(self._final)
        nis: dict[str, float] = {}
        for event in self._events:
            if event.outcome:  # most events (IMU samples) decide nothing
                counts.update(event.outcome)
            if event.kind != "imu" and math.isfinite(event.nis):
                nis[event.source] = event.nis
            if math.isfinite(event.nis_tilt):
                nis[f"tilt_{event.source}"] = event.nis_tilt
        self._last_nis.update(nis)
        out: dict[str, float | int | bool] = {
            key: int(value) for key, value in sorted(counts.items())
        }
        out.setdefault("resets", 0)
        for source, value in self._last_nis.items():
            out[f"nis_{source}"] = value
        out["initialised"] = self._head.initialised
        out["since_pose_s"] = float(self._now - self._head.last_pose_time)
        return out

    def estimate(self, time: float, r_wb: np.ndarray) -> DeckPoseEstimate:
        """The fused T_CD at ``time`` with its 6x6 covariance (x, y, z, roll, pitch, yaw)."""
        head = self._head
        extras = self.diagnostics()
        if not head.initialised:
            reason = "fusion_not_initialised" if extras["resets"] == 0 else "fusion_reset"
            return DeckPoseEstimate(METHOD, time, False, reason=reason, extras=extras)
        if time - head.last_pose_time > self.config.reset_timeout_s:
            return DeckPoseEstimate(METHOD, time, False, reason="fusion_timed_out", extras=extras)
        r_wb = np.asarray(r_wb, dtype=float)
        r_wc = r_wb @ R_BC
        x = head.x
        translation = r_wc.T @ (x[P] - r_wb @ self.t_bc)
        rotation = r_wc.T @ rotation_zyx(x[TH]) @ R_PD
        jac = np.zeros((6, self._n))
        jac[0:3, P] = r_wc.T
        # d(euler of R_CD)/d(th) by central differences (three tiny matrix products)
        step = 1e-6
        for k in range(3):
            delta = np.zeros(3)
            delta[k] = step
            up = euler_zyx_from_matrix(r_wc.T @ rotation_zyx(x[TH] + delta) @ R_PD)
            down = euler_zyx_from_matrix(r_wc.T @ rotation_zyx(x[TH] - delta) @ R_PD)
            jac[3:6, 6 + k] = wrap_angle(up - down) / (2.0 * step)
        covariance = jac @ head.cov @ jac.T
        return DeckPoseEstimate(
            METHOD,
            time,
            True,
            rotation=rotation,
            translation=translation,
            covariance=covariance,
            # coasting: no pose accepted within the horizon (IMU and ToF only)
            predicted=time - head.last_pose_time > self.config.horizon_s,
            extras=extras,
        )
