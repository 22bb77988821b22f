"""The chance that a landing committed now succeeds, learned from hindsight labels.

On a ship deck the final descent from the 2 m hold takes 3-15 s: the view gate holds it while a
gust leans the tag towards the image edge, the go-around climbs when the deck is lost, and the
heave and the wind decide the touchdown as much as the tilt does.  No deck-tilt predictor a
descent ahead can judge that (the ``predictive`` rule of the bench needs a contact at a known
time).  What can be judged is *when the sea and the wind are in a good spell*: at ship sea
state 5 a commit 0.5 s after one that landed lands 91 % of the time, after one that failed
19 % (``benchmarks/bench_ship_commit_labels.py``).  Wave groups make the deck's motion come and
go over tens of seconds (the quiescent periods of ship landing: Sherman 2007, *Ship motion
prediction and the quiescent period*; Ferrier, Duncan & Fallon 2008, *Landing Period Designator*
for the US Navy), and the drone's station-keeping error in gusty wind shows the gusts' spell
the same way.

:class:`CommitChanceModel` is a logistic regression (regularised maximum likelihood, SciPy's
L-BFGS) of a commit's success on statistics of the observed deck motion over several windows
(:func:`commit_features`: the deck tilt's largest and RMS value, the spread of the heave rate
and of the deck's horizontal position in the levelled camera frame, the mean height and the
estimate's validity, over each window; the newest tilt, offset and height; the ToF rays on
the deck; the fraction of the wait used).  Its labels are *hindsight* labels: in simulation a
commit at each decision of a waiting episode is tried in a snapshot and undone
(:mod:`agents.timing.hindsight`), so every decision gets the touchdown a commit then would have
given, the whole descent included.  The labels need the simulator; the model reads only what
the drone observes.  Its held-out chances (fitted on the other folds of episodes) are kept so
that a policy can weigh a chance against the optimal-stopping value of waiting on
(:mod:`landing_env.timing.stopping`).

Pure NumPy and SciPy; :meth:`CommitChanceModel.chance` never raises on data (too few valid
samples: an invalid chance with its reason).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from estimation.array_files import load_arrays, save_arrays
from estimation.frames import tilt_deg
from landing_env.timing.stopping import StoppingValues

#: the per-window statistics of :func:`commit_features`, in order
WINDOW_STATISTICS: tuple[str, ...] = (
    "tilt_max_deg",
    "tilt_rms_deg",
    "heave_rate_std",
    "x_std",
    "y_std",
    "z_mean",
    "valid_fraction",
)
#: the statistics of the newest sample and of the rest of the observation, after the windows
NOW_STATISTICS: tuple[str, ...] = (
    "tilt_deg",
    "x",
    "y",
    "z",
    "tilt_rate_deg_s",
    "tof_on_deck",
    "wait_fraction",
)
#: the history's columns the features read (``landing_env.timing.history.HISTORY_FEATURES``'s
#: order: x, y, z, roll, pitch, yaw, z_rate, roll_rate, pitch_rate, valid)
_X, _Y, _Z, _ROLL, _PITCH, _Z_RATE, _ROLL_RATE, _PITCH_RATE, _VALID = 0, 1, 2, 3, 4, 6, 7, 8, 9
#: the fewest valid samples a window needs for its statistics
MIN_WINDOW_SAMPLES = 2
#: history values are clipped to this magnitude before any statistic (SI units)
_BOUND = 1.0e3


def feature_names(windows_s: Sequence[float]) -> list[str]:
    """The names of :func:`commit_features`' values for ``windows_s``."""
    names = [f"{name}@{w:g}s" for w in windows_s for name in WINDOW_STATISTICS]
    return names + list(NOW_STATISTICS)


def commit_features(
    history: np.ndarray,
    dt_s: float,
    windows_s: Sequence[float],
    tof_valid: np.ndarray,
    wait_fraction: float,
) -> np.ndarray:
    """The features of one decision (``feature_names(windows_s)``).

    ``history``: (n, 10) rows of the timing task's history (SI units, oldest first; a row
    whose ``valid`` is 0 is ignored); each window takes its last ``round(w / dt_s)`` rows.  A
    window with fewer than :data:`MIN_WINDOW_SAMPLES` valid rows gives zeros (and a valid
    fraction of 0, which says so); non-finite values are zeroed."""
    rows = np.asarray(history, dtype=float)
    if rows.ndim != 2 or rows.shape[1] <= _VALID:
        rows = np.zeros((0, _VALID + 1))
    # no estimate is this far out (metres, radians): bound what a corrupt row could carry
    rows = np.clip(np.nan_to_num(rows, nan=0.0), -_BOUND, _BOUND)
    with np.errstate(all="ignore"):
        out = _statistics(rows, dt_s, windows_s)
    out += [float(np.sum(np.asarray(tof_valid, dtype=bool))), float(wait_fraction)]
    return np.nan_to_num(np.array(out, dtype=float), nan=0.0, posinf=0.0, neginf=0.0)


def _statistics(rows: np.ndarray, dt_s: float, windows_s: Sequence[float]) -> list[float]:
    """The window and newest-sample statistics of :func:`commit_features`."""
    out: list[float] = []
    for w in windows_s:
        n = max(1, round(float(w) / dt_s))
        window = rows[-n:]
        valid = window[:, _VALID] > 0.5
        if valid.sum() < MIN_WINDOW_SAMPLES:
            out += [0.0] * len(WINDOW_STATISTICS)
            continue
        seen = window[valid]
        tilt = tilt_deg(seen[:, _ROLL], seen[:, _PITCH])
        out += [
            float(np.max(tilt)),
            float(np.sqrt(np.mean(tilt**2))),
            float(np.std(seen[:, _Z_RATE])),
            float(np.std(seen[:, _X])),
            float(np.std(seen[:, _Y])),
            float(np.mean(seen[:, _Z])),
            float(valid.mean()),
        ]
    valid = rows[:, _VALID] > 0.5 if len(rows) else np.zeros(0, dtype=bool)
    if valid.any():
        last = rows[valid][-1]
        out += [
            float(tilt_deg(last[_ROLL], last[_PITCH])),
            float(last[_X]),
            float(last[_Y]),
            float(last[_Z]),
            float(np.degrees(math.hypot(last[_ROLL_RATE], last[_PITCH_RATE]))),
        ]
    else:
        out += [0.0] * 5
    return out


@dataclass(frozen=True)
class CommitChance:
    """A commit's predicted chance of success, or why there is none."""

    valid: bool
    probability: float
    reason: str = ""


def _sigmoid(s: np.ndarray) -> np.ndarray:
    return np.asarray(0.5 * (1.0 + np.tanh(0.5 * s)))


def _fit_logistic(x: np.ndarray, y: np.ndarray, penalty: float) -> np.ndarray:
    """Weights (constant last) of the L2-regularised logistic regression (no penalty on the
    constant), by SciPy's L-BFGS on the exact gradient."""
    from scipy.optimize import minimize

    design = np.c_[x, np.ones(len(x))]
    mask = np.r_[np.ones(x.shape[1]), 0.0]

    def loss(w: np.ndarray) -> tuple[float, np.ndarray]:
        s = design @ w
        value = float(np.sum(np.logaddexp(0.0, s) - y * s) + penalty * np.sum(mask * w * w))
        gradient = design.T @ (_sigmoid(s) - y) + 2.0 * penalty * mask * w
        return value, gradient

    result = minimize(loss, np.zeros(design.shape[1]), jac=True, method="L-BFGS-B")
    return np.asarray(result.x, dtype=float)


def _auc(p: np.ndarray, y: np.ndarray) -> float:
    """The area under the ROC curve (Mann-Whitney), NaN with one class only."""
    positives = int(y.sum())
    negatives = len(y) - positives
    if positives == 0 or negatives == 0:
        return math.nan
    ranks = np.argsort(np.argsort(p, kind="stable"), kind="stable") + 1
    return float((ranks[y > 0.5].sum() - positives * (positives + 1) / 2) / (positives * negatives))


@dataclass
class CommitChanceModel:
    """A commit's chance of success from the observed deck motion (see the module docstring)."""

    windows_s: tuple[float, ...]
    dt_s: float
    #: feature standardisation (subtracted, divided) and the logistic weights (constant last)
    mean: np.ndarray
    scale: np.ndarray
    weights: np.ndarray
    #: the chances the model gave the labelled decisions while held out of its fit (in the
    #: labels' order; NaN where no fold held one out): the distribution a policy's value of
    #: waiting on is computed from
    heldout_chances: np.ndarray = field(default_factory=lambda: np.zeros(0))
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def n_history(self) -> int:
        """History rows the longest window needs."""
        return max(1, round(max(self.windows_s) / self.dt_s))

    @property
    def names(self) -> list[str]:
        return feature_names(self.windows_s)

    # ---------------------------------------------------------------- prediction
    def chance(
        self, history: np.ndarray, tof_valid: np.ndarray, wait_fraction: float
    ) -> CommitChance:
        """The chance that a commit now lands; invalid (with its reason) when the history is
        shorter than the longest window or the newest window holds too few valid estimates."""
        rows = np.asarray(history, dtype=float)
        if rows.ndim != 2 or rows.shape[1] <= _VALID:
            return CommitChance(False, 0.0, f"history of shape {rows.shape}: (n, 10) expected")
        if len(rows) < self.n_history:
            return CommitChance(
                False, 0.0, f"{len(rows)} history rows, the model's windows need {self.n_history}"
            )
        shortest = max(1, round(min(self.windows_s) / self.dt_s))
        if int(np.sum(rows[-shortest:, _VALID] > 0.5)) < MIN_WINDOW_SAMPLES:
            return CommitChance(False, 0.0, "too few valid estimates in the newest window")
        x = commit_features(rows, self.dt_s, self.windows_s, tof_valid, wait_fraction)
        return CommitChance(True, float(self.probabilities(x[None, :])[0]))

    def probabilities(self, features: np.ndarray) -> np.ndarray:
        """The chances of rows of :func:`commit_features`."""
        x = np.nan_to_num(np.asarray(features, dtype=float), nan=0.0, posinf=0.0, neginf=0.0)
        z = np.clip((x - self.mean) / self.scale, -50.0, 50.0)
        return _sigmoid(z @ self.weights[:-1] + self.weights[-1])

    def stopping_values(self) -> StoppingValues:
        """The value of waiting on, from the held-out chances."""
        return StoppingValues.from_samples(self.heldout_chances)

    # ---------------------------------------------------------------- fitting
    @classmethod
    def fit(
        cls,
        features: np.ndarray,
        success: np.ndarray,
        groups: np.ndarray,
        windows_s: Sequence[float],
        dt_s: float,
        penalty: float = 3.0,
        folds: int = 5,
        metadata: dict[str, Any] | None = None,
    ) -> CommitChanceModel:
        """Fit on labelled decisions (``features`` rows of :func:`commit_features`,
        ``success`` 0/1); ``groups`` (the episodes) split the ``folds`` for the held-out
        chances, so no episode is judged by a fit that saw it."""
        if not windows_s or min(windows_s) <= 0.0 or not dt_s > 0.0:
            raise ValueError(
                f"windows_s {list(windows_s)} and dt_s {dt_s} must be positive (and windows_s "
                "not empty)"
            )
        x = np.asarray(features, dtype=float)
        y = np.asarray(success, dtype=float).reshape(-1)
        g = np.asarray(groups).reshape(-1)
        if x.ndim != 2 or len(x) != len(y) or len(y) != len(g):
            raise ValueError(
                f"features {x.shape}, success {y.shape} and groups {g.shape} do not match"
            )
        if x.shape[1] != len(feature_names(windows_s)):
            raise ValueError(
                f"{x.shape[1]} features; windows {list(windows_s)} give "
                f"{len(feature_names(windows_s))}"
            )
        mean = x.mean(axis=0)
        scale = x.std(axis=0)
        scale[scale < 1e-9] = 1.0
        z = (x - mean) / scale
        unique = np.unique(g)
        fold_of = {key: i % folds for i, key in enumerate(unique)}
        fold = np.array([fold_of[key] for key in g])
        heldout = np.full(len(y), np.nan)
        for k in range(folds):
            test = fold == k
            if not test.any() or test.all():
                continue
            w = _fit_logistic(z[~test], y[~test], penalty)
            heldout[test] = _sigmoid(z[test] @ w[:-1] + w[-1])
        weights = _fit_logistic(z, y, penalty)
        info = dict(metadata or {})
        info.update(
            {
                "labels": len(y),
                "episodes": len(unique),
                "base_rate": float(y.mean()),
                "heldout_auc": _auc(heldout[np.isfinite(heldout)], y[np.isfinite(heldout)]),
                "penalty": penalty,
                "folds": folds,
            }
        )
        return cls(
            tuple(float(w) for w in windows_s),
            float(dt_s),
            mean,
            scale,
            weights,
            heldout.astype(np.float32),
            info,
        )

    # ---------------------------------------------------------------- files
    def save(self, path: str | Path) -> Path:
        """Write to ``path`` (``.npz``; the metadata as JSON inside)."""
        arrays = {
            "windows_s": np.array(self.windows_s, dtype=float),
            "dt_s": self.dt_s,
            "mean": self.mean,
            "scale": self.scale,
            "weights": self.weights,
            "heldout_chances": self.heldout_chances,
        }
        return save_arrays(path, arrays, self.metadata)

    @classmethod
    def load(cls, path: str | Path) -> CommitChanceModel:
        """Read a file written by :meth:`save`; a malformed one is a ``ValueError`` naming it."""

        def build(data: Any, metadata: dict[str, Any]) -> CommitChanceModel:
            return cls(
                tuple(float(w) for w in data["windows_s"]),
                float(data["dt_s"]),
                np.asarray(data["mean"], dtype=float),
                np.asarray(data["scale"], dtype=float),
                np.asarray(data["weights"], dtype=float),
                np.asarray(data["heldout_chances"], dtype=float),
                metadata,
            )

        model = load_arrays(path, "commit-chance model", build)
        n = len(feature_names(model.windows_s))
        if (
            not model.windows_s
            or model.dt_s <= 0.0
            or model.mean.shape != (n,)
            or model.scale.shape != (n,)
            or model.weights.shape != (n + 1,)
        ):
            raise ValueError(f"{path}: its weights do not match its windows {model.windows_s}")
        return model
