"""Predicting the deck's tilt a descent ahead from the episode's own past: the online fit.

:class:`~estimation.deck_prediction.LinearTiltPredictor` is fitted offline, on a scenario's
recorded episodes, against the true motion; on a sea it was not fitted to it predicts that
sea with another sea's coefficients and states another sea's error.  :class:`OnlineTiltPredictor`
fits the same direct multi-step linear predictor (Fusco & Ringwood 2010; one ridge regression
per horizon, :func:`~estimation.deck_prediction.window_features` and
:func:`~estimation.deck_prediction.ridge_solve`) while the episode runs, from nothing but the
deck history it is shown:

* **examples**: each sample's window of the ``channels`` (its last ``window_s``, block-averaged)
  against the *estimated* roll and pitch at each horizon later, from the samples of the last
  ``memory_s`` whose future has been seen (no truth: it runs on recorded data);
* **refits** every ``refit_s``, with a small bank of ridge penalties;
* **its own errors**: every sample's prediction by each member of the bank is kept as it was
  made, with the fit then current, and compared with the estimate when that comes (a
  prequential error: no prediction is judged on data it was fitted to).  Per horizon, the
  member with the smallest such error is used (once ``select_after_s`` of errors can tell;
  the most cautious one before), and the covariance is its errors' mean outer product over
  the last ``error_memory_s``, shrunk toward a no-skill covariance (the tilt's own spread
  about its mean, or the prior's covariance) with the weight of ``covariance_prior_n``
  independent errors against the errors' own (one per ``decorrelation_s``), and widened by
  ``m / (m - 3)`` for ``m`` such errors (an inverted sample covariance is too confident by
  that much): wide while the errors are few, its own once they are many;
* **invalid, with the reason**, until the first fit and ``min_errors_s`` of its own errors at
  every horizon, and while roll and pitch do not move at all (a frozen estimate);
  :meth:`predict` then answers as the fitted predictor does, and :meth:`chances` gives the
  chances of the predictions it made of the episode's past windows (what the sea on hand
  offers, for the value of waiting on; out of sample, as a fitted predictor's held-out ones).

Optionally a fitted predictor is its **prior**: the online fit then reads that predictor's
window and channels, its ridge pulls toward the prior's coefficients, the prior itself is a
member of the bank (it is used while it predicts best), its covariance is the one the errors
are shrunk toward, its held-out chances stand until ``min_record_s`` of the episode's own,
and the prior answers from its first full window on.

The fusion's identification (:class:`~estimation.fusion.identify.DeckMotionIdentifier`) fits
each axis a two-oscillator spectrum for the filter's process model; predicting with it would
need the filter's state.  The direct regression predicts from the history alone, each horizon
fitted to its own error, and reads the channels together (a cross-spectrum the per-axis model
has not).

Samples arrive by :meth:`~OnlineTiltPredictor.append` (one at a time, every control period)
or :meth:`~OnlineTiltPredictor.update` (a sliding window, as an observation holds it: the rows
that continue the record are found by matching).  Pure NumPy; never raises on data.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimation.deck_prediction import (
    LinearTiltPredictor,
    TiltPrediction,
    ridge_solve,
    window_features,
)

#: roll and pitch that move less than this (rad) over the memory are a frozen estimate, not a
#: deck (a sensor's noise alone moves them more)
FROZEN_RAD = 1e-9


@dataclass(frozen=True)
class OnlineFitSettings:
    """The online fit's settings (the module docstring says what each does); the window,
    block, channels and horizons are the prior's when there is one."""

    #: the window of the channels each prediction reads, seconds
    window_s: float = 2.0
    #: samples averaged into one feature
    block: int = 5
    #: the history's pose values it reads (roll and pitch among them): the levelled pose but
    #: its height, as the fitted predictors read it (the deck's surge, sway and yaw answer the
    #: same waves, and the tag's position is measured more finely than its tilt)
    channels: tuple[str, ...] = ("x", "y", "roll", "pitch", "yaw")
    #: the horizons it fits, seconds (multiples of the sample period)
    horizons_s: tuple[float, ...] = tuple(round(0.1 * k, 1) for k in range(21))
    #: the examples of a fit: samples of the last ``memory_s``
    memory_s: float = 30.0
    refit_s: float = 0.5
    #: the bank's ridge penalties (relative to the features' mean square and the examples)
    ridges: tuple[float, ...] = (0.01, 0.1, 1.0, 10.0)
    #: the first fit waits for this many seconds of examples, and (without a prior) for
    #: ``examples_per_feature`` of them per feature
    min_fit_s: float = 3.0
    examples_per_feature: float = 3.0
    #: no prediction before this many seconds of its own errors at every horizon
    min_errors_s: float = 1.0
    #: until this many seconds of its own errors at a horizon, the bank's most cautious
    #: member predicts there (the strongest ridge, or the prior): a few errors choose by chance
    select_after_s: float = 4.0
    #: the errors that choose the bank's member and give the covariance: the last seconds
    error_memory_s: float = 15.0
    #: one independent error per this many seconds (the errors of a sample and its
    #: neighbours are nearly the same)
    decorrelation_s: float = 1.0
    #: the no-skill covariance weighs as this many independent errors
    covariance_prior_n: float = 1.0
    #: past windows whose predictions give :meth:`OnlineTiltPredictor.chances`, and the
    #: seconds of them below which a prior's held-out ones are used instead
    record: int = 150
    min_record_s: float = 5.0
    min_valid_fraction: float = 0.8
    max_gap_s: float = 0.3

    def __post_init__(self) -> None:
        checks = {
            "window_s": self.window_s > 0.0,
            "block": self.block >= 1,
            "memory_s": self.memory_s > 0.0,
            "refit_s": self.refit_s > 0.0,
            "ridges": len(self.ridges) > 0 and all(r > 0.0 for r in self.ridges),
            "min_fit_s": self.min_fit_s >= 0.0,
            "examples_per_feature": self.examples_per_feature >= 1.0,
            "min_errors_s": self.min_errors_s >= 0.0,
            "select_after_s": self.select_after_s >= 0.0,
            "error_memory_s": self.error_memory_s > 0.0,
            "decorrelation_s": self.decorrelation_s > 0.0,
            "covariance_prior_n": self.covariance_prior_n > 0.0,
            "record": self.record >= 1,
            "min_record_s": self.min_record_s >= 0.0,
            "horizons_s": len(self.horizons_s) > 0 and min(self.horizons_s) >= 0.0,
            "channels": {"roll", "pitch"} <= set(self.channels),
        }
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            raise ValueError(
                f"online fit settings: {', '.join(bad)} out of range (positive durations, "
                "block >= 1, positive ridges, roll and pitch among the channels)"
            )


class OnlineTiltPredictor:
    """The deck's roll and pitch a descent ahead, fitted online (module docstring).

    ``dt_s``: the sample period of the history it is shown; ``settings``: the fit's; ``prior``:
    a fitted predictor to start from (its window, channels and horizons are then read).  It
    answers :meth:`predict`, :meth:`best_within` and :meth:`chances` as
    :class:`~estimation.deck_prediction.LinearTiltPredictor` does; ``fit_version`` changes
    whenever its fit does."""

    KIND = "online deck-tilt predictor"

    def __init__(
        self,
        dt_s: float,
        settings: OnlineFitSettings | None = None,
        prior: LinearTiltPredictor | None = None,
    ) -> None:
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f"dt_s must be a positive sample period, not {dt_s}")
        self.settings = s = settings or OnlineFitSettings()
        self.prior = prior
        self.dt_s = float(dt_s)
        if prior is not None:
            if abs(prior.dt_s - self.dt_s) > 1e-9:
                raise ValueError(
                    f"the prior was fitted at {1 / prior.dt_s:g} Hz, the history is at "
                    f"{1 / self.dt_s:g} Hz"
                )
            self.window_s, self.block = prior.window_s, prior.block
            self.channels = tuple(prior.channels)
            self.horizons_s = np.asarray(prior.horizons_s, dtype=float)
        else:
            self.window_s, self.block = float(s.window_s), int(s.block)
            self.channels = tuple(s.channels)
            self.horizons_s = np.asarray(s.horizons_s, dtype=float)
        steps = np.round(self.horizons_s / self.dt_s)
        if not np.allclose(steps * self.dt_s, self.horizons_s, atol=1e-6):
            raise ValueError(f"horizons must be multiples of the sample period {self.dt_s} s")
        self._steps = steps.astype(int)
        self._axes = [self.channels.index("roll"), self.channels.index("pitch")]
        self.n_window = round(self.window_s / self.dt_s)
        c = len(self.channels)
        self._n_features = c * (self.n_window // self.block) + 1
        #: the feature divisor of each channel's columns (the block-major ravel of the window)
        self._column_channel = np.arange(self._n_features - 1) % c
        self._recent = max(1, round(s.max_gap_s / self.dt_s))
        self._members = len(s.ridges) + (prior is not None)
        #: the prior's coefficients as the bank's (F, 2H)
        self._prior_bank = (
            None
            if prior is None
            else np.transpose(prior.coefficients, (1, 0, 2)).reshape(self._n_features, -1)
        )
        if prior is not None and prior.coefficients.shape[1] != self._n_features:
            raise ValueError("the prior's coefficients do not match its window")
        self._keep = (
            round(max(s.memory_s, s.error_memory_s) / self.dt_s)
            + self.n_window
            + int(self._steps.max())
            + 2
        )
        self.fit_version = 0
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget the episode: a new deck history starts."""
        cap, c, f, h = 2 * self._keep, len(self.channels), self._n_features, len(self._steps)
        self._values = np.zeros((cap, c))
        self._valid = np.zeros(cap, dtype=bool)
        self._features = np.full((cap, f), np.nan)
        self._predictions = np.full((cap, self._members, 2 * h), np.nan)
        self._n = 0
        self._since_fit = 0
        #: (members, F, 2H) the bank's coefficients, and the features' divisors they read;
        #: with a prior, every member is the prior until the first fit
        self._bank: np.ndarray | None = None
        self._divisor = np.ones(f)
        if self.prior is not None and self._prior_bank is not None:
            # until the first fit only the prior predicts (the ridges' members have no errors)
            self._bank = np.full((self._members, *self._prior_bank.shape), np.nan)
            self._bank[-1] = self._prior_bank
            self._divisor = np.concatenate([self.prior.scales[self._column_channel], [1.0]])
        self.samples = 0
        #: the predictor it answers with (None: it cannot yet), and why not
        self.fitted: LinearTiltPredictor | None = self.prior
        self.reason = "online fit: no deck history yet"
        self.fit_version += 1

    @property
    def valid(self) -> bool:
        """Whether it can predict now."""
        return self.fitted is not None

    def append(self, values: Any, valid: Any = True) -> None:
        """One more sample of the ``channels`` (their values, and whether they are an
        estimate); a malformed or non-finite one is an invalid sample."""
        row = np.asarray(values, dtype=float).reshape(-1) if _is_numeric(values) else None
        flag = np.asarray(valid).reshape(-1) if _is_numeric(valid) else np.zeros(0)
        ok = (
            row is not None
            and row.shape == (len(self.channels),)
            and bool(np.all(np.isfinite(row)))
            and flag.size == 1
            and bool(flag[0])
        )
        if self._n == len(self._values):
            self._shift()
        i = self._n
        self._values[i] = row if ok and row is not None else 0.0
        self._valid[i] = ok
        self._n += 1
        self.samples += 1
        lo = max(0, self._n - self.n_window)
        phi = window_features(
            self._values[lo : self._n],
            self._valid[lo : self._n],
            self.n_window,
            self.block,
            np.ones(len(self.channels)),
            self.channels,
            self.settings.min_valid_fraction,
            self._recent,
        )
        if not isinstance(phi, str):
            self._features[i] = phi
            if self._bank is not None:
                self._predictions[i] = np.einsum("f,rfy->ry", phi / self._divisor, self._bank)
        self._since_fit += 1
        if self._since_fit * self.dt_s >= self.settings.refit_s - 1e-9:
            self._since_fit = 0
            self._refit()

    def update(self, values: Any, valid: Any) -> int:
        """Merge a window of the history (``values`` (n, C) of the channels, oldest first, and
        their validity): the rows after the part that repeats the record's newest are
        appended; a window that does not join on starts the record afresh.  Returns the rows
        appended (0 for a malformed window).  A window that overlaps the record only in
        invalid rows cannot be placed and is taken to repeat them."""
        if not _is_numeric(values):
            return 0
        window = np.asarray(values, dtype=float)
        flags = np.asarray(valid).reshape(-1) if _is_numeric(valid) else np.zeros(0)
        if window.ndim != 2 or window.shape[1] != len(self.channels) or len(flags) != len(window):
            return 0
        flags = flags > 0.5 if flags.dtype != bool else flags
        start = self._join(window, flags)
        if start is None:
            self.reset()
            start = 0
        for k in range(start, len(window)):
            self.append(window[k], flags[k])
        return len(window) - start

    def _join(self, window: np.ndarray, flags: np.ndarray) -> int | None:
        """The first row of ``window`` that is new (``len(window)``: none), or None when it
        does not continue the record."""
        n, stored = len(window), self._n
        if stored == 0:
            return 0
        values, valid = self._values[:stored], self._valid[:stored]
        for new in range(n):
            m = n - new
            k = min(m, stored)
            if flags[m - 1] != valid[-1]:
                continue
            head, head_ok = window[m - k : m], flags[m - k : m]
            if np.array_equal(head_ok, valid[-k:]) and np.array_equal(
                np.where(head_ok[:, None], head, 0.0), np.where(valid[-k:, None], values[-k:], 0.0)
            ):
                return m
        return None

    def _shift(self) -> None:
        """Keep the newest samples (the fit's memory and what its errors need)."""
        keep, n = self._keep, self._n
        for array in (self._values, self._valid, self._features, self._predictions):
            array[:keep] = array[n - keep : n]
        self._n = keep

    # ------------------------------------------------------------------ fitting
    def _refit(self) -> None:
        """Refit the bank on the examples of the memory (when there are enough), then judge
        it on its own errors and renew the predictor it answers with."""
        s = self.settings
        now = self._n - 1
        lo = max(0, now - round(s.memory_s / self.dt_s))
        tilts = self._values[lo : now + 1][self._valid[lo : now + 1]][:, self._axes]
        if len(tilts) > 1 and np.all(np.ptp(tilts, axis=0) < FROZEN_RAD):
            self.fitted = None
            self.reason = (
                "online fit: the deck's roll and pitch have not moved in the last "
                f"{(now + 1 - lo) * self.dt_s:.1f} s (a frozen estimate): nothing to learn from"
            )
            self.fit_version += 1
            return
        rows = self._examples(lo, now)
        # a fit pulled toward a prior needs no more examples than features
        need = round(s.min_fit_s / self.dt_s)
        if self.prior is None:
            need = max(need, math.ceil(s.examples_per_feature * self._n_features))
        if len(rows) >= need:
            self._fit_bank(rows, lo, now)
        elif self._bank is None:
            self.reason = (
                f"online fit: {len(rows) * self.dt_s:.1f} s of examples; the first fit "
                f"needs {need * self.dt_s:.1f} s (window {self.window_s:g} s, horizons to "
                f"{self.horizons_s[-1]:g} s)"
            )
        if self._bank is None:
            return
        chosen, covariance, seen = self._judge(now, lo)
        if self.prior is None and seen < round(s.min_errors_s / self.dt_s):
            self.fitted = None
            self.reason = (
                f"online fit: {seen * self.dt_s:.1f} s of its own prediction errors at "
                f"{self.horizons_s[-1]:g} s; it predicts from {s.min_errors_s:g} s"
            )
            return
        stacked, divisor = self._bank, self._divisor
        scales = divisor[: len(self.channels)]
        coefficients = np.stack(
            [stacked[r][:, 2 * k : 2 * k + 2] for k, r in enumerate(chosen)]
        )  # (H, F, 2)
        self.fitted = LinearTiltPredictor(
            self.window_s,
            self.dt_s,
            self.block,
            self.horizons_s,
            coefficients,
            covariance,
            s.min_valid_fraction,
            s.max_gap_s,
            metadata={
                "online": True,
                "examples": len(rows),
                "history_s": round(self.samples * self.dt_s, 3),
                "member": [self._member_name(r) for r in chosen],
                "errors_s": round(seen * self.dt_s, 3),
            },
            channels=self.channels,
            scales=scales,
            heldout_means=self._past_means(lo, now, divisor, coefficients, chosen),
        )
        self.reason = ""
        self.fit_version += 1

    def _examples(self, lo: int, now: int) -> np.ndarray:
        """The samples from ``lo`` whose window is valid and whose roll and pitch at every
        horizon have been seen by ``now``."""
        candidates = np.arange(lo, now - int(self._steps.max()) + 1)
        if not len(candidates):
            return candidates
        later = candidates[:, None] + self._steps[None, :]
        known = np.all(self._valid[later], axis=1) & np.isfinite(self._features[candidates, 0])
        return candidates[known]

    def _fit_bank(self, rows: np.ndarray, lo: int, now: int) -> None:
        """Each ridge of the bank fitted on the examples ``rows`` (and the prior, unchanged)."""
        s = self.settings
        if self.prior is not None:
            scales = self.prior.scales
        else:
            span = self._values[lo : now + 1][self._valid[lo : now + 1]]
            scales = np.std(span, axis=0) if len(span) > 1 else np.ones(len(self.channels))
            scales = np.where(scales > 1e-12, scales, 1.0)
        divisor = np.concatenate([scales[self._column_channel], [1.0]])
        x = self._features[rows] / divisor
        later = rows[:, None] + self._steps[None, :]
        y = self._values[later][:, :, self._axes].reshape(len(rows), -1)
        gram = x.T @ x
        scale = float(np.mean(x[:, :-1] ** 2)) or 1.0
        bank = []
        try:
            for ridge in s.ridges:
                bank.append(
                    ridge_solve(x, y, ridge * scale * len(x), gram, toward=self._prior_bank)
                )
        except np.linalg.LinAlgError:
            return
        if self._prior_bank is not None:
            bank.append(self._prior_bank)
        stacked = np.array(bank)
        if np.all(np.isfinite(stacked)):
            self._bank, self._divisor = stacked, divisor

    def _judge(self, now: int, lo: int) -> tuple[list[int], np.ndarray, int]:
        """Per horizon: the bank's member with the smallest own error, the covariance of its
        errors shrunk toward the no-skill one, and the fewest errors any horizon has."""
        s = self.settings
        first = max(0, now - round(s.error_memory_s / self.dt_s))
        made = np.arange(first, now + 1)
        h = len(self._steps)
        fallback = len(s.ridges) if self.prior is not None else len(s.ridges) - 1
        spread = self._values[lo : now + 1][self._valid[lo : now + 1]][:, self._axes]
        no_skill = np.cov(spread.T) if len(spread) > 2 else np.eye(2)
        chosen, covariance, seen = [], np.zeros((h, 2, 2)), 10**9
        for k, step in enumerate(self._steps):
            at = made[made + step <= now]
            at = at[self._valid[at + step]]
            # (members, samples, 2): each member's errors (NaN where it made no prediction)
            errors = self._values[at + step][:, self._axes][None] - self._predictions[at][
                :, :, 2 * k : 2 * k + 2
            ].transpose(1, 0, 2)
            made_by = np.isfinite(errors[:, :, 0])
            every = np.all(made_by, axis=0)
            member = fallback
            if every.sum() * self.dt_s >= s.select_after_s:
                # compared on the same samples; a tie keeps the cautious member
                mse = np.mean(np.sum(errors[:, every] ** 2, axis=2), axis=1)
                best = int(np.argmin(mse))
                member = best if mse[best] < mse[fallback] else fallback
            mine = errors[member][made_by[member]]
            seen = min(seen, len(mine))
            own = mine.T @ mine / max(len(mine), 1)
            prior_covariance = self.prior.covariance[k] if self.prior is not None else no_skill
            weight = len(mine) * self.dt_s / s.decorrelation_s
            m = s.covariance_prior_n + weight
            # a covariance estimated from m errors is inverted by the chance: its inverse
            # is too large by about m / (m - 3) for two axes (the inverse-Wishart mean), so
            # it is widened by that (at most twice)
            covariance[k] = (
                (s.covariance_prior_n * prior_covariance + weight * own)
                / m
                * min(m / max(m - 3.0, 1e-9), 2.0)
            )
            chosen.append(member)
        return chosen, covariance, 0 if seen == 10**9 else seen

    def _past_means(
        self,
        lo: int,
        now: int,
        divisor: np.ndarray,
        coefficients: np.ndarray,
        chosen: Sequence[int],
    ) -> np.ndarray:
        """(H, M, 2): the predictions of up to ``record`` past windows, as each horizon's
        chosen member made them at the time (out of sample, as the fitted predictor's held-out
        ones; a fit's own examples would be predicted better than the present is), else by
        the present fit."""
        past = np.arange(lo, now + 1)
        past = past[np.isfinite(self._features[past, 0])]
        if len(past) * self.dt_s < self.settings.min_record_s:
            # too few to tell how the chances spread: the prior's, or these
            if self.prior is not None and self.prior.heldout_means.size:
                return self.prior.heldout_means
            if not len(past):
                return np.zeros((0, 0, 2))
        pick = past[np.linspace(0, len(past) - 1, min(self.settings.record, len(past))).astype(int)]
        means = np.einsum("mf,hft->hmt", self._features[pick] / divisor, coefficients)
        for k, member in enumerate(chosen):
            made = self._predictions[pick, member, 2 * k : 2 * k + 2]
            known = np.isfinite(made[:, 0])
            means[k, known] = made[known]
        return means

    def _member_name(self, member: int) -> str:
        ridges = self.settings.ridges
        return f"ridge {ridges[member]:g}" if member < len(ridges) else "prior"

    # ------------------------------------------------------------------ prediction
    def predict(self, values: np.ndarray, valid: np.ndarray, horizon_s: float) -> TiltPrediction:
        """Roll and pitch ``horizon_s`` ahead from a history of the ``channels`` by the
        current fit (as :meth:`LinearTiltPredictor.predict`); invalid, with the reason, before
        it can predict.  Never raises on data."""
        if self.fitted is None:
            return TiltPrediction(False, self.reason, float(horizon_s))
        return self.fitted.predict(values, valid, horizon_s)

    def best_within(
        self,
        values: np.ndarray,
        valid: np.ndarray,
        horizons_s: Sequence[float],
        limit_deg: float,
    ) -> TiltPrediction:
        """As :meth:`LinearTiltPredictor.best_within`, by the current fit."""
        if self.fitted is None:
            return TiltPrediction(False, self.reason)
        return self.fitted.best_within(values, valid, horizons_s, limit_deg)

    def chances(self, horizons_s: float | Sequence[float], limit_deg: float) -> np.ndarray:
        """The chances the current fit gives the episode's past windows (as
        :meth:`LinearTiltPredictor.chances`; empty before it can predict)."""
        if self.fitted is None:
            return np.zeros(0)
        return self.fitted.chances(horizons_s, limit_deg)


def _is_numeric(data: Any) -> bool:
    """Whether ``data`` converts to a float array (garbage such as strings does not)."""
    try:
        np.asarray(data, dtype=float)
    except (TypeError, ValueError):
        return False
    return True
