"""Predicting the deck's tilt a descent ahead: a linear (Wiener) predictor with its error.

A timing policy commits to a final descent whose contact comes a known time later (the timed
descent: 1.3 s); what it must judge is the deck's tilt *then*.  Straight-line extrapolation of
the last half second is 2-10 deg off at that horizon on a deck that rolls with a 3-5 s period
(it is worse than predicting level).  The classical answer of ship-motion prediction is a
linear predictor of the future motion from a window of past motion, fitted by least squares
to recorded motion (Yumori 1981, *Real time prediction of ship response to ocean waves using
time series analysis*, OCEANS 81; Triantafyllou, Bodson & Athans 1983, *Real time estimation
of ship motions using Kalman filtering techniques*, IEEE J. Oceanic Eng. 8(1); the *direct*
multi-step form, one regression per horizon, as in Fusco & Ringwood 2010, *Short-term wave
forecasting for real-time control of wave energy converters*, IEEE Trans. Sustain. Energy
1(2)).  Fitted on the *estimated* motion (what the drone sees, noise included) against the
*true* motion later, it is the Wiener predictor from noisy data: it smooths and predicts at
once, and its held-out residuals give the prediction's covariance.

:class:`LinearMotionPredictor` is that predictor for any of the pose's values (the ship's
helideck forecast, :mod:`agents.policies.deck_forecast`, predicts surge, sway, heave, roll and pitch
8 s ahead from the ship's own motion record); :class:`LinearTiltPredictor` is the one of roll
and pitch.  It maps the last ``window_s`` of the deck's (levelled) pose, the
``channels`` it was fitted on (roll and pitch, and the position: heave, surge and sway answer
the same waves, so the cross-spectra sharpen the tilt's prediction; at bench sea state 5 from
2.7 to 1.9 deg of roll error at 1.3 s), to its roll and pitch at each fitted horizon, with a
residual covariance per horizon; its :meth:`~LinearTiltPredictor.predict` returns a
:class:`TiltPrediction`, whose :meth:`~TiltPrediction.probability_within` is the chance that
the tilt at that horizon is within a limit.  It never raises on data: too few valid samples
give an invalid prediction with its reason.  Pure NumPy: it runs on recorded sensor data.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from estimation.array_files import load_arrays, save_arrays
from estimation.frames import tilt_deg

_P = TypeVar("_P", bound="LinearMotionPredictor")

#: the targets that are angles (reported in degrees)
_ANGLES = {"roll", "pitch", "yaw"}
#: targets' display scale: angles in degrees, positions in metres
_DISPLAY_SCALE = {name: math.degrees(1.0) for name in _ANGLES}

#: standard-normal points (a scrambled Sobol set, fixed) for the probability of a 2-D Gaussian
#: tilt inside a circle: deterministic, and 1/N-accurate where Monte Carlo is 1/sqrt(N)
_N_POINTS = 4096


def _normal_points() -> np.ndarray:
    from scipy.stats import norm, qmc

    uniform = qmc.Sobol(d=2, scramble=True, seed=12345).random(_N_POINTS)
    return np.asarray(norm.ppf(np.clip(uniform, 1e-12, 1.0 - 1e-12)))


_POINTS: np.ndarray | None = None


@dataclass(frozen=True)
class TiltPrediction:
    """The deck's roll and pitch predicted ``horizon_s`` ahead (rad) and their covariance."""

    valid: bool
    reason: str = ""
    horizon_s: float = math.nan
    roll: float = math.nan
    pitch: float = math.nan
    #: (2, 2) covariance of (roll, pitch), rad^2
    covariance: np.ndarray = field(default_factory=lambda: np.full((2, 2), np.nan))

    @property
    def tilt_deg(self) -> float:
        """The tilt of the predicted mean, degrees (NaN when invalid)."""
        return float(tilt_deg(self.roll, self.pitch)) if self.valid else math.nan

    def probability_within(self, limit_deg: float) -> float:
        """P(tilt <= ``limit_deg``) under the Gaussian prediction (0 when invalid)."""
        if not self.valid:
            return 0.0
        mean = np.array([[self.roll, self.pitch]])
        return float(_probabilities_within(mean, self.covariance, limit_deg)[0])


def _probabilities_within(
    means: np.ndarray, covariance: np.ndarray, limit_deg: float, chunk: int = 64
) -> np.ndarray:
    """P(tilt <= ``limit_deg``) for Gaussians of (roll, pitch) ``means`` (M, 2), rad, sharing
    ``covariance``; 0 for a covariance that is not one."""
    global _POINTS
    if _POINTS is None:
        _POINTS = _normal_points()
    try:
        factor = np.linalg.cholesky(np.asarray(covariance, dtype=float) + 1e-14 * np.eye(2))
    except np.linalg.LinAlgError:
        return np.zeros(len(means))
    offsets = _POINTS @ factor.T
    out = np.empty(len(means))
    for start in range(0, len(means), chunk):
        samples = means[start : start + chunk, None, :] + offsets[None]
        out[start : start + chunk] = np.mean(
            tilt_deg(samples[..., 0], samples[..., 1]) <= limit_deg, axis=1
        )
    return out


def _invalid(reason: str, horizon_s: float = math.nan) -> TiltPrediction:
    return TiltPrediction(False, reason, horizon_s)


@dataclass
class LinearMotionPredictor:
    """Direct multi-horizon linear predictor of the deck's pose values ``targets``.

    Features: the last ``window_s`` of each of ``channels`` (pose values in m and rad, one
    sample per ``dt_s``, oldest first, gaps filled linearly), averaged in blocks of ``block``
    samples and divided by the channel's ``scales`` (its spread in the fitting data, so the
    ridge penalty treats metres and radians alike), and a constant.  For each horizon
    ``horizons_s[k]``: ``coefficients[k]`` (features, T) and the held-out residual
    ``covariance[k]`` (T, T) of the T ``targets``.  :class:`LinearTiltPredictor` is the one of
    roll and pitch that the timing task reads; the ship's helideck forecast
    (:mod:`agents.policies.deck_forecast`) predicts the whole pose from the ship's own motion
    record.
    """

    window_s: float
    dt_s: float
    block: int
    horizons_s: np.ndarray
    coefficients: np.ndarray
    covariance: np.ndarray
    #: fewer valid samples than this fraction of the window: no prediction
    min_valid_fraction: float = 0.8
    #: no valid sample in the newest ``max_gap_s``: no prediction (the present is unknown)
    max_gap_s: float = 0.3
    #: what it was fitted on (scenarios, sensing, estimator, samples, ridge, held-out errors)
    metadata: dict[str, Any] = field(default_factory=dict)
    #: the pose values it reads, by name (``x``, ``y``, ``z``, ``roll``, ``pitch``, ``yaw``)
    channels: tuple[str, ...] = ("roll", "pitch")
    #: each channel's divisor (m or rad); empty: ones
    scales: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: (H, M, T) the predicted targets of M held-out examples at each horizon: the
    #: distribution of predictions the sea offers (:meth:`LinearTiltPredictor.chances`);
    #: empty: not recorded
    heldout_means: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 2)))
    #: the pose values it predicts, by name (m and rad)
    targets: tuple[str, ...] = ("roll", "pitch")

    #: what a file of this kind is called in errors
    KIND = "deck-motion predictor"

    def __post_init__(self) -> None:
        self.channels = tuple(self.channels)
        self.targets = tuple(self.targets)
        scales = np.asarray(self.scales, dtype=float).reshape(-1)
        self.scales = scales if scales.size else np.ones(len(self.channels))
        means = np.asarray(self.heldout_means, dtype=float)
        t = len(self.targets)
        self.heldout_means = (
            means.reshape(len(self.horizons_s), -1, t) if means.size else np.zeros((0, 0, t))
        )

    @property
    def n_window(self) -> int:
        """Samples in the window."""
        return round(self.window_s / self.dt_s)

    # ---------------------------------------------------------------- features
    def features(self, values: np.ndarray, valid: np.ndarray) -> np.ndarray | str:
        """The feature vector of a history of the ``channels`` (n >= window samples, oldest
        first), or the reason there is none."""
        n = self.n_window
        c = len(self.channels)
        values = np.asarray(values, dtype=float)
        valid = np.asarray(valid, dtype=bool).reshape(-1)
        if values.ndim != 2 or values.shape[1] != c or len(valid) != len(values):
            return f"history must be (n, {c}) values of {', '.join(self.channels)} with n flags"
        if len(values) < n:
            return f"history of {len(values)} samples; the predictor needs {n}"
        window, ok = values[-n:], valid[-n:] & np.all(np.isfinite(values[-n:]), axis=1)
        if ok.sum() < max(2, math.ceil(self.min_valid_fraction * n)):
            return "too few valid estimates in the window"
        recent = max(1, round(self.max_gap_s / self.dt_s))
        if not ok[-recent:].any():
            return "no valid estimate in the newest samples"
        index = np.arange(n)
        filled = np.column_stack(
            [np.interp(index, index[ok], window[ok, axis]) for axis in range(c)]
        )
        blocks = filled[n % self.block :].reshape(-1, self.block, c).mean(axis=1) / self.scales
        return np.concatenate([blocks.ravel(), [1.0]])

    # ---------------------------------------------------------------- prediction
    def predict_targets(self, values: np.ndarray, valid: np.ndarray) -> np.ndarray | str:
        """The ``targets`` at every fitted horizon, (H, T), from a history of the ``channels``,
        or the reason there is none; never raises on data."""
        phi = self.features(values, valid)
        if isinstance(phi, str):
            return phi
        means = np.einsum("f,hft->ht", phi, self.coefficients)
        if not np.all(np.isfinite(means)):
            return "non-finite prediction"
        return means

    def _bracket(self, horizon_s: float) -> tuple[int, int, float]:
        """The fitted horizons either side of ``horizon_s`` and the weight of the later one."""
        h = self.horizons_s
        k = int(np.clip(np.searchsorted(h, horizon_s) - 1, 0, max(len(h) - 2, 0)))
        j = min(k + 1, len(h) - 1)
        w = 0.0 if j == k else float(np.clip((horizon_s - h[k]) / (h[j] - h[k]), 0.0, 1.0))
        return k, j, w

    # ---------------------------------------------------------------- the deck's tilt
    def _tilt_columns(self) -> list[int] | str:
        """The columns of roll and pitch among the ``targets``, or why there are none."""
        if "roll" not in self.targets or "pitch" not in self.targets:
            return f"the predictor predicts {', '.join(self.targets)}, not roll and pitch"
        return [self.targets.index("roll"), self.targets.index("pitch")]

    def predict(self, values: np.ndarray, valid: np.ndarray, horizon_s: float) -> TiltPrediction:
        """Roll and pitch ``horizon_s`` ahead from a history of the ``channels`` (coefficients
        and covariance interpolated linearly between the fitted horizons); never raises on
        data."""
        phi = self.features(values, valid)
        if isinstance(phi, str):
            return _invalid(phi, horizon_s)
        return self._from_features(phi, horizon_s)

    def _from_features(self, phi: np.ndarray, horizon_s: float) -> TiltPrediction:
        columns = self._tilt_columns()
        if isinstance(columns, str):
            return _invalid(columns, horizon_s)
        h = self.horizons_s
        if not (math.isfinite(horizon_s) and h[0] - 1e-9 <= horizon_s <= h[-1] + 1e-9):
            return _invalid(f"horizon {horizon_s} s outside the fitted {h[0]}-{h[-1]} s")
        k, j, w = self._bracket(horizon_s)
        coefficients = (1.0 - w) * self.coefficients[k] + w * self.coefficients[j]
        covariance = (1.0 - w) * self.covariance[k] + w * self.covariance[j]
        mean = phi @ coefficients[:, columns]
        if not np.all(np.isfinite(mean)):
            return _invalid("non-finite prediction", horizon_s)
        return TiltPrediction(
            True,
            "",
            horizon_s,
            float(mean[0]),
            float(mean[1]),
            covariance[np.ix_(columns, columns)],
        )

    def best_within(
        self,
        values: np.ndarray,
        valid: np.ndarray,
        horizons_s: Sequence[float],
        limit_deg: float,
    ) -> TiltPrediction:
        """Of the predictions at ``horizons_s`` (the contact times a descent can be given),
        the one with the best chance that the tilt is within ``limit_deg`` (the earliest of
        equal ones); invalid, with the reason, when none can be made.  Never raises on data."""
        phi = self.features(values, valid)
        if isinstance(phi, str):
            return _invalid(phi)
        best, best_chance = _invalid("no contact time given"), -1.0
        for horizon_s in horizons_s:
            prediction = self._from_features(phi, float(horizon_s))
            if not prediction.valid:
                best = best if best.valid else prediction
                continue
            chance = prediction.probability_within(limit_deg)
            if chance > best_chance:
                best, best_chance = prediction, chance
        return best

    def mean_within(
        self,
        values: np.ndarray,
        valid: np.ndarray,
        horizons_s: Sequence[float],
        limit_deg: float,
    ) -> tuple[float, list[TiltPrediction]]:
        """The chance that the tilt is within ``limit_deg`` at a contact equally likely to come
        at each of ``horizons_s`` (a descent whose contact time is not chosen but spread: the
        mean of the chances), and the predictions; 0 and the invalid predictions (with their
        reasons) when any cannot be made.  Never raises on data."""
        phi = self.features(values, valid)
        if isinstance(phi, str):
            return 0.0, [_invalid(phi)]
        predictions = [self._from_features(phi, float(h)) for h in horizons_s]
        if not predictions:
            return 0.0, [_invalid("no contact time given")]
        if not all(p.valid for p in predictions):
            return 0.0, predictions
        chance = float(np.mean([p.probability_within(limit_deg) for p in predictions]))
        return chance, predictions

    def chances(
        self, horizons_s: float | Sequence[float], limit_deg: float, combine: str = "best"
    ) -> np.ndarray:
        """The chance that the tilt ``horizons_s`` ahead is within ``limit_deg`` for each of the
        held-out examples recorded at fitting: how such chances are distributed over the sea
        (empty when none were recorded, a horizon is outside the fitted ones or the predictor
        predicts no tilt).  With several horizons, ``combine`` says how they make one chance:
        ``best`` (a descent whose contact time is chosen among them) or ``mean`` (a contact
        equally likely at each)."""
        if combine not in ("best", "mean"):
            raise ValueError(f"combine must be 'best' or 'mean', not {combine!r}")
        horizons = np.atleast_1d(np.asarray(horizons_s, dtype=float))
        h = self.horizons_s
        columns = self._tilt_columns()
        if (
            isinstance(columns, str)
            or self.heldout_means.size == 0
            or horizons.size == 0
            or not np.all(np.isfinite(horizons))
            or horizons.min() < h[0] - 1e-9
            or horizons.max() > h[-1] + 1e-9
        ):
            return np.zeros(0)
        out = np.zeros(self.heldout_means.shape[1])
        for horizon_s in horizons:
            k, j, w = self._bracket(float(horizon_s))
            means = (1.0 - w) * self.heldout_means[k] + w * self.heldout_means[j]
            covariance = (1.0 - w) * self.covariance[k] + w * self.covariance[j]
            chance = _probabilities_within(
                means[:, columns], covariance[np.ix_(columns, columns)], limit_deg
            )
            out = np.maximum(out, chance) if combine == "best" else out + chance
        return out if combine == "best" else out / len(horizons)

    # ---------------------------------------------------------------- fitting
    @classmethod
    def fit(
        cls: type[_P],
        histories: np.ndarray,
        futures: np.ndarray,
        groups: np.ndarray,
        horizons_s: np.ndarray,
        window_s: float,
        dt_s: float,
        block: int = 2,
        ridges: tuple[float, ...] = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2),
        holdout_fraction: float = 0.25,
        metadata: dict[str, Any] | None = None,
        channels: tuple[str, ...] = ("roll", "pitch"),
        record: int = 1000,
        targets: tuple[str, ...] | None = None,
    ) -> _P:
        """Fit on examples: ``histories`` (N, n, C + 1) of the C ``channels`` and validity,
        ``futures`` (N, H, T) the true ``targets`` (the class's own by default) at each
        horizon (NaN where unknown), ``groups`` (N,) the episode of each example.

        The ridge penalty is chosen per horizon on held-out episodes (the last
        ``holdout_fraction`` of the groups), the covariance is the held-out residuals' (an
        honest error), and the coefficients are then refitted on every example.  The
        predictions of ``record`` held-out examples (evenly spaced) are kept: the
        distribution of predictions (:meth:`chances`)."""
        histories = np.asarray(histories, dtype=float)
        futures = np.asarray(futures, dtype=float)
        groups = np.asarray(groups).reshape(-1)
        horizons_s = np.asarray(horizons_s, dtype=float).reshape(-1)
        c = len(channels)
        targets = tuple(targets) if targets is not None else cls.default_targets()
        n_targets = len(targets)
        if histories.ndim != 3 or histories.shape[2] != c + 1:
            raise ValueError(
                f"histories must be (N, n, {c + 1}): {', '.join(channels)} and validity"
            )
        if futures.shape != (len(histories), len(horizons_s), n_targets):
            raise ValueError(
                f"futures must be (N, {len(horizons_s)}, {n_targets}), got {futures.shape}"
            )
        if len(groups) != len(histories):
            raise ValueError("groups needs one entry per example")
        if block < 1:
            raise ValueError("block must be >= 1")
        ok = histories[..., c] > 0.5
        scales = np.array(
            [float(np.std(histories[..., k][ok])) if ok.any() else 1.0 for k in range(c)]
        )
        scales = np.where(scales > 1e-12, scales, 1.0)
        template = cls(
            window_s,
            dt_s,
            block,
            horizons_s,
            np.zeros(0),
            np.zeros(0),
            channels=channels,
            scales=scales,
            targets=targets,
        )
        rows, keep = [], []
        for index, history in enumerate(histories):
            phi = template.features(history[:, :c], history[:, c] > 0.5)
            if not isinstance(phi, str):
                rows.append(phi)
                keep.append(index)
        if len(rows) < 10:
            raise ValueError(f"only {len(rows)} examples with a valid window; need at least 10")
        x = np.array(rows)
        y = futures[keep]
        g = groups[keep]
        unique = np.unique(g)
        held = np.isin(g, unique[int(len(unique) * (1.0 - holdout_fraction)) :])
        if held.all() or not held.any():
            raise ValueError("need at least two episodes (groups) to hold some out")
        n_features = x.shape[1]
        coefficients = np.zeros((len(horizons_s), n_features, n_targets))
        covariance = np.zeros((len(horizons_s), n_targets, n_targets))
        chosen, rms = [], []
        held_rows = np.where(held)[0]
        recorded = held_rows[
            np.linspace(0, len(held_rows) - 1, min(record, len(held_rows))).astype(int)
        ]
        heldout_means = np.zeros((len(horizons_s), len(recorded), n_targets))
        display = np.array([_DISPLAY_SCALE.get(name, 1.0) for name in targets])
        grams: dict[bytes, np.ndarray] = {}
        scale = float(np.mean(x[:, :-1] ** 2)) or 1.0  # features are scaled: about 1
        for k in range(len(horizons_s)):
            known = np.all(np.isfinite(y[:, k]), axis=1)
            train, test = known & ~held, known & held
            if train.sum() < n_features or test.sum() < 5:
                raise ValueError(f"too few examples with a known future at {horizons_s[k]} s")
            best: tuple[float, float, np.ndarray, np.ndarray] | None = None
            gram = grams.setdefault(train.tobytes(), x[train].T @ x[train])
            for ridge in ridges:
                a = _ridge(x[train], y[train, k], ridge * scale * train.sum(), gram)
                residual = y[test, k] - x[test] @ a
                error = float(np.mean(residual**2))
                if best is None or error < best[0]:
                    best = (error, ridge, residual, a)
            assert best is not None
            _, ridge, residual, fitted = best
            covariance[k] = np.atleast_2d(np.cov(residual.T))
            heldout_means[k] = x[recorded] @ fitted
            coefficients[k] = _ridge(
                x[known],
                y[known, k],
                ridge * scale * known.sum(),
                grams.setdefault(known.tobytes(), x[known].T @ x[known]),
            )
            chosen.append(ridge)
            rms.append((display * np.sqrt(np.diag(covariance[k]))).round(3).tolist())
        info = dict(metadata or {})
        info.update(
            {
                "examples": len(x),
                "episodes": len(unique),
                "ridge": chosen,
                # angles in degrees, positions in metres
                ("heldout_rms_deg" if set(targets) <= _ANGLES else "heldout_rms"): rms,
            }
        )
        return cls(
            window_s,
            dt_s,
            block,
            horizons_s,
            coefficients,
            covariance,
            metadata=info,
            channels=channels,
            scales=scales,
            heldout_means=heldout_means,
            targets=targets,
        )

    @classmethod
    def default_targets(cls) -> tuple[str, ...]:
        """The targets a fit predicts unless told otherwise."""
        return ("roll", "pitch")

    # ---------------------------------------------------------------- files
    def save(self, path: str | Path, exact: bool = False) -> Path:
        """Write to ``path`` (``.npz``; the metadata as JSON inside).  The held-out predictions
        are kept as float32 (half the file) unless ``exact``: then :meth:`load` gives back an
        equal predictor, every array to the bit (a cache of a fit)."""
        arrays = {
            "window_s": self.window_s,
            "dt_s": self.dt_s,
            "block": self.block,
            "horizons_s": self.horizons_s,
            "coefficients": self.coefficients,
            "covariance": self.covariance,
            "min_valid_fraction": self.min_valid_fraction,
            "max_gap_s": self.max_gap_s,
            "channels": json.dumps(list(self.channels)),
            "scales": self.scales,
            "heldout_means": self.heldout_means.astype(np.float64 if exact else np.float32),
            "targets": json.dumps(list(self.targets)),
        }
        return save_arrays(path, arrays, self.metadata)

    @classmethod
    def load(cls: type[_P], path: str | Path) -> _P:
        """Read a file written by :meth:`save`; a malformed one is a ``ValueError`` naming it."""

        def build(data: Any, metadata: dict[str, Any]) -> _P:
            return cls(
                float(data["window_s"]),
                float(data["dt_s"]),
                int(data["block"]),
                np.asarray(data["horizons_s"], dtype=float),
                np.asarray(data["coefficients"], dtype=float),
                np.asarray(data["covariance"], dtype=float),
                float(data["min_valid_fraction"]),
                float(data["max_gap_s"]),
                metadata,
                tuple(json.loads(str(data["channels"]))),
                np.asarray(data["scales"], dtype=float),
                np.asarray(data["heldout_means"], dtype=float)
                if "heldout_means" in data
                else np.zeros((0, 0, 2)),
                tuple(json.loads(str(data["targets"])))
                if "targets" in data
                else cls.default_targets(),
            )

        predictor = load_arrays(path, cls.KIND, build)
        h, t = len(predictor.horizons_s), len(predictor.targets)
        n_features = len(predictor.channels) * (predictor.n_window // predictor.block) + 1
        shapes = (predictor.coefficients.shape, predictor.covariance.shape)
        if shapes != ((h, n_features, t), (h, t, t)) or len(predictor.scales) != len(
            predictor.channels
        ):
            raise ValueError(f"{path}: coefficient or covariance shapes do not match its window")
        return predictor


def _ridge(
    x: np.ndarray, y: np.ndarray, penalty: float, gram: np.ndarray | None = None
) -> np.ndarray:
    """Least squares with an L2 penalty on every coefficient but the constant (the last);
    ``gram`` is ``x.T @ x`` when already known."""
    gram = x.T @ x if gram is None else gram
    regulariser = penalty * np.eye(x.shape[1])
    regulariser[-1, -1] = 0.0
    return np.linalg.solve(gram + regulariser, x.T @ y)


class LinearTiltPredictor(LinearMotionPredictor):
    """The deck's roll and pitch a descent ahead (``targets`` = roll, pitch), with the chance
    that the tilt is within a limit."""

    KIND = "deck-tilt predictor"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.targets != ("roll", "pitch"):
            raise ValueError(f"a tilt predictor predicts roll and pitch, not {self.targets}")
