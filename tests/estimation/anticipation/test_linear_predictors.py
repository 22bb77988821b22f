"""The linear (Wiener) predictor, unit by unit: its features, its reasons for no prediction,
the interpolation between fitted horizons, the chances, the fit and the file.

Most tests use a hand-made predictor whose answers are known; the fits are on small
synthetic series (a fitted predictor's skill is tested in
``tests/test_onboard_tilt_prediction.py``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation.anticipation import linear_predictors
from estimation.anticipation.linear_predictors import (
    LinearMotionPredictor,
    LinearTiltPredictor,
    TiltPrediction,
    _normal_points,
    _probabilities_within,
)
from estimation.frames import tilt_deg

DT = 0.05


def _predictor(
    n: int = 6,
    block: int = 2,
    scales=(2.0, 4.0),
    horizons=(0.0, 1.0, 3.0),
    targets=("roll", "pitch"),
    heldout_means=None,
    cls=LinearMotionPredictor,
) -> LinearMotionPredictor:
    """A window of ``n`` samples of (roll, pitch) in blocks of ``block``; horizon ``k``'s
    coefficients are ``k + 1`` times a fixed pattern (so that interpolation is visible), its
    covariance ``(k + 1)`` times a fixed one."""
    features = 2 * (n // block) + 1
    pattern = np.arange(features * len(targets), dtype=float).reshape(features, len(targets))
    pattern /= pattern.size
    coefficients = np.stack([(k + 1) * pattern for k in range(len(horizons))])
    base = np.array([[4.0, 1.0], [1.0, 3.0]]) * 1e-4
    covariance = np.stack([(k + 1) * base for k in range(len(horizons))])
    if len(targets) != 2:
        covariance = np.stack([(k + 1) * 1e-4 * np.eye(len(targets)) for k in range(len(horizons))])
    return cls(
        n * DT,
        DT,
        block,
        np.array(horizons, dtype=float),
        coefficients,
        covariance,
        scales=np.array(scales),
        targets=targets,
        heldout_means=np.zeros((0, 0, len(targets))) if heldout_means is None else heldout_means,
    )


# ---------------------------------------------------------------- features
def test_the_features_are_the_windows_block_means_over_the_scales_and_a_constant() -> None:
    predictor = _predictor(n=5, block=2)
    values = np.column_stack([np.arange(7.0), 10.0 * np.arange(7.0)])  # 7 samples, 5 read
    phi = predictor.features(values, np.ones(7, bool))
    # the window is samples 2..6; with 5 % 2 = 1 the oldest is dropped: blocks (3, 4), (5, 6)
    np.testing.assert_allclose(phi, [3.5 / 2, 35.0 / 4, 5.5 / 2, 55.0 / 4, 1.0])
    # a gap is filled along the line between the samples either side; what it held is not read
    holed = values.copy()
    holed[4] = 1e6
    valid = np.ones(7, bool)
    valid[4] = False
    np.testing.assert_allclose(predictor.features(holed, valid), phi)
    # a sample not finite is a gap too, even when flagged valid
    holed[4, 1] = math.nan
    np.testing.assert_allclose(predictor.features(holed, np.ones(7, bool)), phi)
    # the flags as a column, or as numbers, are the same flags
    np.testing.assert_allclose(predictor.features(holed, valid[:, None]), phi)
    np.testing.assert_allclose(predictor.features(holed, valid.astype(float)), phi)


def test_a_predictor_without_scales_divides_by_one_and_its_window_is_rounded() -> None:
    predictor = LinearMotionPredictor(
        0.149, DT, 1, np.array([0.0]), np.zeros((1, 7, 2)), np.zeros((1, 2, 2))
    )
    assert predictor.n_window == 3
    np.testing.assert_array_equal(predictor.scales, [1.0, 1.0])
    assert predictor.channels == ("roll", "pitch") and predictor.targets == ("roll", "pitch")
    assert predictor.heldout_means.shape == (0, 0, 2)
    values = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    np.testing.assert_array_equal(predictor.features(values, np.ones(3)), [1, 2, 3, 4, 5, 6, 1])
    assert LinearMotionPredictor.default_targets() == ("roll", "pitch")


def test_a_history_that_cannot_be_read_gives_the_reason_exactly() -> None:
    predictor = _predictor(n=10, block=2)
    ones = np.ones(10, bool)
    shape = "history must be (n, 2) values of roll, pitch with n flags"
    assert predictor.features(np.zeros((10, 3)), ones) == shape
    assert predictor.features(np.zeros(10), ones) == shape
    assert predictor.features(np.zeros((10, 2)), np.ones(9, bool)) == shape
    assert predictor.features(np.zeros((9, 2)), np.ones(9, bool)) == (
        "history of 9 samples; the predictor needs 10"
    )
    # 8 of 10 valid (min_valid_fraction 0.8) is enough, 7 is not
    for n_valid, reason in ((8, None), (7, "too few valid estimates in the window")):
        valid = np.zeros(10, bool)
        valid[-n_valid:] = True
        got = predictor.features(np.zeros((10, 2)), valid)
        assert got == reason if reason else not isinstance(got, str)
    # the newest max_gap_s (0.3 s: 6 samples) without a valid one: no prediction
    valid = np.ones(10, bool)
    valid[-6:] = False
    predictor.min_valid_fraction = 0.1
    assert predictor.features(np.zeros((10, 2)), valid) == "no valid estimate in the newest samples"
    valid[-6] = True
    assert not isinstance(predictor.features(np.zeros((10, 2)), valid), str)
    # a window of one valid sample is never enough, whatever the fraction; two are
    predictor.min_valid_fraction = 0.0
    valid = np.zeros(10, bool)
    valid[-1] = True
    assert predictor.features(np.zeros((10, 2)), valid) == "too few valid estimates in the window"
    valid[0] = True
    assert not isinstance(predictor.features(np.zeros((10, 2)), valid), str)
    valid[0] = False
    # a max gap below one sample still reads the newest
    predictor.max_gap_s = 0.0
    valid[:-1] = True
    assert not isinstance(predictor.features(np.zeros((10, 2)), valid), str)
    valid[-1] = False
    assert predictor.features(np.zeros((10, 2)), valid) == "no valid estimate in the newest samples"


# ---------------------------------------------------------------- prediction
def test_the_targets_at_every_horizon_are_the_features_times_each_horizons_coefficients() -> None:
    predictor = _predictor(targets=("x", "roll", "pitch"))
    values = np.column_stack([np.linspace(0, 1, 6), np.linspace(1, -1, 6)])
    phi = predictor.features(values, np.ones(6, bool))
    means = predictor.predict_targets(values, np.ones(6, bool))
    assert means.shape == (3, 3)
    for k in range(3):
        np.testing.assert_allclose(means[k], phi @ predictor.coefficients[k])
    assert predictor.predict_targets(values[:3], np.ones(3, bool)) == (
        "history of 3 samples; the predictor needs 6"
    )
    predictor.coefficients[1, 0, 0] = math.nan
    assert predictor.predict_targets(values, np.ones(6, bool)) == "non-finite prediction"


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.floats(0.0, 3.0), st.sampled_from([("roll", "pitch"), ("pitch", "z", "roll")]))
def test_a_prediction_interpolates_the_coefficients_and_covariance_of_the_horizons_around_it(
    horizon_s: float, targets: tuple[str, ...]
) -> None:
    predictor = _predictor(horizons=(0.0, 1.0, 3.0), targets=targets)
    values = np.column_stack([np.linspace(0.1, 0.4, 6), np.linspace(0.3, -0.2, 6)])
    phi = predictor.features(values, np.ones(6, bool))
    prediction = predictor.predict(values, np.ones(6, bool), horizon_s)
    k = 0 if horizon_s <= 1.0 else 1
    h0, h1 = (0.0, 1.0) if k == 0 else (1.0, 3.0)
    w = (horizon_s - h0) / (h1 - h0)
    coefficients = (1 - w) * predictor.coefficients[k] + w * predictor.coefficients[k + 1]
    covariance = (1 - w) * predictor.covariance[k] + w * predictor.covariance[k + 1]
    roll, pitch = targets.index("roll"), targets.index("pitch")
    assert prediction.valid and prediction.reason == "" and prediction.horizon_s == horizon_s
    assert prediction.roll == pytest.approx(phi @ coefficients[:, roll], rel=1e-9, abs=1e-15)
    assert prediction.pitch == pytest.approx(phi @ coefficients[:, pitch], rel=1e-9, abs=1e-15)
    expected = covariance[np.ix_([roll, pitch], [roll, pitch])]
    np.testing.assert_allclose(prediction.covariance, expected, rtol=1e-9, atol=1e-18)
    assert type(prediction.roll) is float and type(prediction.pitch) is float
    assert prediction.tilt_deg == float(tilt_deg(prediction.roll, prediction.pitch))


def test_the_horizons_bracket_is_the_fitted_pair_around_it_and_one_horizon_is_its_own() -> None:
    predictor = _predictor(horizons=(0.0, 1.0, 3.0))
    assert predictor._bracket(0.0) == (0, 1, 0.0)
    assert predictor._bracket(0.5) == (0, 1, 0.5)
    assert predictor._bracket(1.0) == (0, 1, 1.0)
    assert predictor._bracket(2.5) == (1, 2, 0.75)
    assert predictor._bracket(3.0) == (1, 2, 1.0)
    assert predictor._bracket(-1.0) == (0, 1, 0.0)  # held to the ends
    assert predictor._bracket(9.0) == (1, 2, 1.0)
    single = _predictor(horizons=(1.3,))
    assert single._bracket(1.3) == (0, 0, 0.0)
    values = np.zeros((6, 2))
    assert single.predict(values, np.ones(6, bool), 1.3).valid
    assert single.predict(values, np.ones(6, bool), 1.3 + 5e-10).valid
    assert single.predict(values, np.ones(6, bool), 1.3 - 5e-10).valid
    assert single.predict(values, np.ones(6, bool), 1.3 + 2e-9).reason == (
        "horizon 1.300000002 s outside the fitted 1.3-1.3 s"
    )


def test_a_prediction_out_of_reach_is_invalid_with_its_horizon_and_reason() -> None:
    predictor = _predictor(horizons=(0.0, 1.0, 3.0))
    values = np.zeros((6, 2))
    short = predictor.predict(values[:2], np.ones(2, bool), 1.5)
    assert (short.valid, short.reason, short.horizon_s) == (
        False,
        "history of 2 samples; the predictor needs 6",
        1.5,
    )
    assert math.isnan(short.roll) and math.isnan(short.pitch) and math.isnan(short.tilt_deg)
    assert np.isnan(short.covariance).all() and short.covariance.shape == (2, 2)
    far = predictor.predict(values, np.ones(6, bool), 3.5)
    assert far.reason == "horizon 3.5 s outside the fitted 0.0-3.0 s"
    early = predictor.predict(values, np.ones(6, bool), -0.5)
    assert early.reason == "horizon -0.5 s outside the fitted 0.0-3.0 s"
    assert predictor.predict(values, np.ones(6, bool), math.nan).reason.startswith("horizon nan")
    untilted = _predictor(targets=("x", "z"))
    assert untilted.predict(values, np.ones(6, bool), 1.0).reason == (
        "the predictor predicts x, z, not roll and pitch"
    )
    assert untilted.predict(values, np.ones(6, bool), 1.0).horizon_s == 1.0
    assert _predictor(targets=("roll", "z")).predict(values, np.ones(6, bool), 1.0).reason == (
        "the predictor predicts roll, z, not roll and pitch"
    )
    broken = _predictor()
    broken.coefficients[:, -1, 0] = math.nan
    nonfinite = broken.predict(values, np.ones(6, bool), 1.0)
    assert (nonfinite.valid, nonfinite.reason, nonfinite.horizon_s) == (
        False,
        "non-finite prediction",
        1.0,
    )


# ---------------------------------------------------------------- chances
def test_the_normal_points_are_a_fixed_standard_normal_sample() -> None:
    points = _normal_points()
    assert points.shape == (4096, 2)
    np.testing.assert_array_equal(points, _normal_points())
    np.testing.assert_allclose(points.mean(axis=0), 0.0, atol=0.01)
    np.testing.assert_allclose(np.cov(points.T), np.eye(2), atol=0.02)
    # scrambled: no point at the clipped tails (an unscrambled Sobol set starts at 0)
    assert np.isfinite(points).all() and np.abs(points).max() < 5.0


def test_the_normal_points_are_drawn_once_at_the_first_chance(monkeypatch) -> None:
    monkeypatch.setattr(linear_predictors, "_POINTS", None)
    level = TiltPrediction(True, "", 1.0, 0.0, 0.0, np.eye(2) * 1e-4)
    chance = level.probability_within(1.0)
    assert linear_predictors._POINTS is not None
    np.testing.assert_array_equal(linear_predictors._POINTS, _normal_points())
    drawn = linear_predictors._POINTS
    assert level.probability_within(1.0) == chance and linear_predictors._POINTS is drawn


def test_the_chances_of_many_means_are_counted_over_the_points_in_chunks() -> None:
    cov = np.array([[4.0, 1.0], [1.0, 2.0]]) * math.radians(1.0) ** 2
    means = np.radians(np.column_stack([np.linspace(-6, 6, 150), np.linspace(3, -2, 150)]))
    factor = np.linalg.cholesky(cov + 1e-14 * np.eye(2))
    samples = means[:, None, :] + (_normal_points() @ factor.T)[None]
    expected = np.mean(tilt_deg(samples[..., 0], samples[..., 1]) <= 4.0, axis=1)
    np.testing.assert_array_equal(_probabilities_within(means, cov, 4.0), expected)
    np.testing.assert_array_equal(_probabilities_within(means, cov, 4.0, chunk=7), expected)
    # a chance is the share of points within, the limit included
    on = TiltPrediction(True, "", 1.0, math.radians(3.0), 0.0, np.zeros((2, 2)))
    assert on.probability_within(3.001) == 1.0 and on.probability_within(2.999) == 0.0
    # a covariance that is not one: no chance; a zero one is a point
    assert _probabilities_within(means[:3], -np.eye(2), 4.0).tolist() == [0.0, 0.0, 0.0]
    assert _probabilities_within(means[:1] * 0.0, np.zeros((2, 2)), 1e-3).tolist() == [1.0]


def test_the_best_contact_time_is_the_first_of_the_best_chances_and_none_says_why() -> None:
    predictor = _predictor(horizons=(0.0, 1.0, 3.0))
    predictor.coefficients[:] = 0.0  # level at every horizon
    values = np.zeros((6, 2))
    ones = np.ones(6, bool)
    # a level window: every horizon predicts level; the covariance grows with the horizon,
    # so the earliest has the best chance
    best = predictor.best_within(values, ones, (2.0, 0.5, 1.0), 1.0)
    assert best.valid and best.horizon_s == 0.5
    # all the same chance (a limit all points pass): the earliest given
    predictor.covariance[:] = 0.0
    assert predictor.best_within(values, ones, (2.0, 0.5, 1.0), 5.0).horizon_s == 2.0
    # the invalid ones are skipped; with none valid, the last one's reason
    skipped = predictor.best_within(values, ones, (7.0, 2.0, 9.0), 5.0)
    assert skipped.valid and skipped.horizon_s == 2.0
    none = predictor.best_within(values, ones, (7.0, 9.0), 5.0)
    assert not none.valid and none.reason == "horizon 9.0 s outside the fitted 0.0-3.0 s"
    assert predictor.best_within(values, ones, (), 5.0).reason == "no contact time given"
    assert predictor.best_within(values[:2], ones[:2], (1.0,), 5.0).reason == (
        "history of 2 samples; the predictor needs 6"
    )
    # a chance of 0 is still a prediction
    predictor.coefficients[:, -1, 0] = 1.0  # 57 deg of roll
    zero = predictor.best_within(values, ones, (1.0,), 0.5)
    assert zero.valid and zero.probability_within(0.5) == 0.0


def test_the_mean_chance_needs_every_contact_time_and_says_why_not() -> None:
    predictor = _predictor(horizons=(0.0, 1.0, 3.0))
    predictor.coefficients[:] = 0.0  # level at every horizon, more spread further ahead
    values, ones = np.zeros((6, 2)), np.ones(6, bool)
    chance, predictions = predictor.mean_within(values, ones, (0.5, 2.0), 1.0)
    each = [predictor.predict(values, ones, h).probability_within(1.0) for h in (0.5, 2.0)]
    assert chance == pytest.approx(np.mean(each)) and 0.0 < chance < 1.0
    assert [p.horizon_s for p in predictions] == [0.5, 2.0]
    chance, predictions = predictor.mean_within(values, ones, (0.5, 4.0), 1.0)
    assert chance == 0.0 and [p.valid for p in predictions] == [True, False]
    chance, predictions = predictor.mean_within(values, ones, (), 1.0)
    assert chance == 0.0 and [p.reason for p in predictions] == ["no contact time given"]
    chance, predictions = predictor.mean_within(values[:2], ones[:2], (1.0,), 1.0)
    assert chance == 0.0 and predictions[0].reason == "history of 2 samples; the predictor needs 6"


def test_the_held_out_chances_interpolate_the_means_and_combine_by_best_or_mean() -> None:
    rng = np.random.default_rng(5)
    means = np.radians(rng.uniform(-4.0, 4.0, (3, 70, 3)))
    predictor = _predictor(targets=("pitch", "x", "roll"), heldout_means=means)
    cov = predictor.covariance

    def at(h: float) -> np.ndarray:
        k, w = (0, h) if h <= 1.0 else (1, (h - 1.0) / 2.0)
        m = (1 - w) * means[k] + w * means[k + 1]
        c = (1 - w) * cov[k] + w * cov[k + 1]
        return _probabilities_within(m[:, [2, 0]], c[np.ix_([2, 0], [2, 0])], 2.0)

    np.testing.assert_allclose(predictor.chances(0.4, 2.0), at(0.4))
    np.testing.assert_allclose(predictor.chances([0.4, 2.0], 2.0), np.maximum(at(0.4), at(2.0)))
    np.testing.assert_allclose(
        predictor.chances([0.4, 2.0, 3.0], 2.0, combine="mean"),
        (at(0.4) + at(2.0) + at(3.0)) / 3,
    )
    for horizons in ([], [0.4, math.nan], [-0.1], [3.1], [0.5, 3.1]):
        assert predictor.chances(horizons, 2.0).size == 0
    assert predictor.chances([0.0, 3.0 + 5e-10], 2.0).size == 70
    assert _predictor().chances(1.0, 2.0).size == 0  # none recorded
    untilted = _predictor(targets=("x", "z", "y"), heldout_means=means)
    assert untilted.chances(1.0, 2.0).size == 0  # no tilt predicted
    with pytest.raises(ValueError) as error:
        predictor.chances(1.0, 2.0, combine="worst")
    assert str(error.value) == "combine must be 'best' or 'mean', not 'worst'"


# ---------------------------------------------------------------- fitting
def _linear_examples(episodes: int = 4, n: int = 4, per: int = 40, seed: int = 0):
    """Windows of roll and pitch and their futures at horizons 0 and 1: a known linear map of
    the window (the future is a sum of its samples with fixed weights, no noise)."""
    rng = np.random.default_rng(seed)
    weights = rng.normal(0.0, 1.0, (n * 2, 2))
    histories, futures, groups = [], [], []
    for episode in range(episodes):
        for _ in range(per):
            window = rng.normal(0.0, 0.1, (n, 2))
            target = window.reshape(-1) @ weights + 0.02
            histories.append(np.column_stack([window, np.ones(n)]))
            futures.append([target, 2.0 * target])
            groups.append(episode)
    return np.array(histories), np.array(futures), np.array(groups), weights


def test_a_fit_of_noiseless_linear_futures_finds_their_map_and_records_how() -> None:
    histories, futures, groups, _ = _linear_examples()
    fitted = LinearTiltPredictor.fit(
        histories,
        futures,
        groups,
        np.array([0.0, 1.0]),
        4 * DT,
        DT,
        block=1,
        ridges=(1e-12,),
        metadata={"scenario": "synthetic"},
        record=7,
    )
    # the same future predicted from every window, to the ridge's bias
    for history, future in zip(histories[::17], futures[::17], strict=True):
        means = fitted.predict_targets(history[:, :2], history[:, 2] > 0.5)
        np.testing.assert_allclose(means, future, atol=1e-6)
    np.testing.assert_allclose(fitted.scales, histories[..., :2].reshape(-1, 2).std(axis=0))
    np.testing.assert_allclose(fitted.covariance, 0.0, atol=1e-12)
    assert fitted.heldout_means.shape == (2, 7, 2)
    # the recorded predictions are of held-out examples (the last quarter of the episodes):
    # evenly spaced from the first held-out one to the last
    held = np.where(groups == 3)[0]
    picked = held[np.linspace(0, len(held) - 1, 7).astype(int)]
    np.testing.assert_allclose(fitted.heldout_means[1], futures[picked, 1], atol=1e-6)
    assert fitted.metadata == {
        "scenario": "synthetic",
        "examples": 160,
        "episodes": 4,
        "ridge": [1e-12, 1e-12],
        "heldout_rms_deg": [[0.0, 0.0], [0.0, 0.0]],
    }
    assert (fitted.window_s, fitted.dt_s, fitted.block) == (4 * DT, DT, 1)
    assert fitted.channels == ("roll", "pitch") and fitted.targets == ("roll", "pitch")


def test_a_fit_is_the_ridge_regression_on_the_scaled_features_its_penalty_grown_with_them() -> None:
    """Per horizon: the penalty is the ridge times the features' mean square (the constant
    left out) times the examples; the covariance is that of the held-out residuals of the
    fit on the others (the last quarter of the episodes: 3 and 4 of 5), and the coefficients
    are refitted on every example."""
    histories, futures, groups, _ = _linear_examples(episodes=5, per=20, seed=3)
    futures = futures + np.random.default_rng(4).normal(0.0, 0.05, futures.shape)
    ridge = 0.3
    fitted = LinearTiltPredictor.fit(
        histories,
        futures,
        groups[:, None],
        np.array([0.0, 1.0]),
        4 * DT,
        DT,
        block=2,
        ridges=(ridge,),
    )
    x = np.array([fitted.features(h[:, :2], h[:, 2] > 0.5) for h in histories])
    scale = float(np.mean(x[:, :-1] ** 2))
    held = groups >= 3
    for k in range(2):
        y = futures[:, k]
        np.testing.assert_allclose(
            fitted.coefficients[k],
            linear_predictors._ridge(x, y, ridge * scale * len(x)),
            rtol=1e-9,
            atol=1e-12,
        )
        train = linear_predictors._ridge(x[~held], y[~held], ridge * scale * (~held).sum())
        residual = y[held] - x[held] @ train
        np.testing.assert_allclose(fitted.covariance[k], np.cov(residual.T), rtol=1e-9)
        np.testing.assert_allclose(fitted.heldout_means[k], x[held] @ train, rtol=1e-9)
    assert fitted.block == 2 and fitted.coefficients.shape == (2, 5, 2)
    # the default block is 2, the default targets roll and pitch
    default = LinearMotionPredictor.fit(
        histories, futures, groups, np.array([0.0, 1.0]), 4 * DT, DT
    )
    assert default.block == 2 and default.targets == ("roll", "pitch")


def test_a_fit_keeps_at_most_1000_held_out_predictions_by_default() -> None:
    histories, futures, groups, _ = _linear_examples(episodes=4, per=1001, seed=6)
    fitted = LinearTiltPredictor.fit(
        histories, futures, groups, np.array([0.0, 1.0]), 4 * DT, DT, block=1
    )
    assert fitted.heldout_means.shape == (2, 1000, 2)


def test_a_fit_chooses_for_each_horizon_the_ridge_with_the_least_held_out_error() -> None:
    histories, futures, groups, _ = _linear_examples(per=30, seed=1)
    noisy = futures + np.random.default_rng(2).normal(0.0, [[0.0, 0.0], [3.0, 3.0]], futures.shape)
    ridges = (1e-9, 1e3)
    fitted = LinearMotionPredictor.fit(
        histories,
        noisy,
        groups,
        np.array([0.0, 1.0]),
        4 * DT,
        DT,
        block=1,
        ridges=ridges,
        targets=("z", "x"),
    )
    # the clean horizon wants no penalty, the one drowned in noise the heavy one
    assert fitted.metadata["ridge"] == [1e-9, 1e3]
    assert "heldout_rms" in fitted.metadata and "heldout_rms_deg" not in fitted.metadata
    assert fitted.targets == ("z", "x")
    # the covariance is the held-out residuals' of the chosen ridge, and its rms recorded
    rms = np.sqrt(np.diag(fitted.covariance[1]))
    np.testing.assert_allclose(fitted.metadata["heldout_rms"][1], rms.round(3))
    assert 2.0 < rms.min() < 4.5
    # the rms of angles is in degrees
    angles = LinearTiltPredictor.fit(
        histories, noisy, groups, np.array([0.0, 1.0]), 4 * DT, DT, block=1, ridges=ridges
    )
    rms_deg = np.degrees(np.sqrt(np.diag(angles.covariance[1]))).round(3)
    np.testing.assert_allclose(angles.metadata["heldout_rms_deg"][1], rms_deg)
    # every angle is an angle: roll, pitch and yaw together are in degrees too
    three = np.concatenate([noisy, noisy[..., :1]], axis=2)
    all_angles = LinearMotionPredictor.fit(
        histories,
        three,
        groups,
        np.array([0.0, 1.0]),
        4 * DT,
        DT,
        block=1,
        ridges=ridges,
        targets=("roll", "pitch", "yaw"),
    )
    assert "heldout_rms_deg" in all_angles.metadata


def test_the_constant_is_never_penalised_by_the_ridge() -> None:
    x = np.column_stack([np.linspace(-1, 1, 20), np.ones(20)])
    y = 3.0 * x[:, :1] + 5.0
    fit = linear_predictors._ridge(x, y, 1e6)
    assert fit[1, 0] == pytest.approx(5.0) and abs(fit[0, 0]) < 1e-3
    np.testing.assert_allclose(linear_predictors._ridge(x, y, 0.0, x.T @ x), [[3.0], [5.0]])


def test_a_fit_refuses_examples_it_cannot_use_saying_which() -> None:
    histories, futures, groups, _ = _linear_examples(episodes=2, per=20)
    horizons = np.array([0.0, 1.0])

    def fit(**kwargs):
        args = {"histories": histories, "futures": futures, "groups": groups}
        args.update(kwargs)
        return LinearTiltPredictor.fit(
            args["histories"],
            args["futures"],
            args["groups"],
            horizons,
            4 * DT,
            DT,
            block=args.get("block", 1),
            channels=args.get("channels", ("roll", "pitch")),
        )

    cases = [
        (
            {"histories": histories[:, :, :2]},
            "histories must be (N, n, 3): roll, pitch and validity",
        ),
        ({"histories": histories[0]}, "histories must be (N, n, 3): roll, pitch and validity"),
        (
            {"channels": ("z", "roll", "pitch")},
            "histories must be (N, n, 4): z, roll, pitch and validity",
        ),
        ({"futures": futures[:, :1]}, "futures must be (N, 2, 2), got (40, 1, 2)"),
        ({"groups": groups[:-1]}, "groups needs one entry per example"),
        ({"block": 0}, "block must be >= 1"),
        ({"groups": np.zeros(40)}, "need at least two episodes (groups) to hold some out"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError) as error:
            fit(**kwargs)
        assert str(error.value) == message
    few = histories.copy()
    few[9:, -1, 2] = 0.0  # the newest sample lost: 9 usable windows
    with pytest.raises(ValueError) as error:
        fit(histories=few)
    assert str(error.value) == "only 9 examples with a valid window; need at least 10"
    unknown = futures.copy()
    unknown[20:36, 1] = math.nan  # 4 held-out examples with a future 1 s ahead
    with pytest.raises(ValueError) as error:
        fit(futures=unknown)
    assert str(error.value) == "too few examples with a known future at 1.0 s"
    assert fit(block=1).metadata["examples"] == 40
    # ten usable windows are enough to be judged by the next rule (here: too few to train)
    ten = histories.copy()
    ten[5:20, -1, 2] = 0.0
    ten[25:, -1, 2] = 0.0
    with pytest.raises(ValueError) as error:
        fit(histories=ten)
    assert str(error.value) == "too few examples with a known future at 0.0 s"
    # as many training examples as features (9) and five held out are enough
    edge = futures.copy()
    edge[9:20, 1] = math.nan
    edge[25:, 1] = math.nan
    assert fit(futures=edge).metadata["examples"] == 40
    edge[8, 1] = math.nan
    with pytest.raises(ValueError) as error:
        fit(futures=edge)
    assert str(error.value) == "too few examples with a known future at 1.0 s"
    # a channel that never moves is divided by 1
    still = histories.copy()
    still[..., 1] = 0.25
    np.testing.assert_array_equal(fit(histories=still).scales[1], 1.0)


# ---------------------------------------------------------------- files
def test_a_saved_predictor_loads_equal_and_exact_keeps_the_held_out_means_to_the_bit(
    tmp_path,
) -> None:
    means = np.full((3, 4, 2), 1.0 + 2.0**-40)
    predictor = _predictor(heldout_means=means, cls=LinearTiltPredictor)
    predictor.min_valid_fraction, predictor.max_gap_s = 0.6, 0.2
    predictor.metadata = {"ridge": [1e-3]}
    predictor.channels = ("z", "roll")
    for exact in (False, True):
        path = predictor.save(tmp_path / f"p{exact}.npz", exact=exact)
        loaded = LinearTiltPredictor.load(path)
        assert type(loaded) is LinearTiltPredictor
        for name in ("window_s", "dt_s", "block", "min_valid_fraction", "max_gap_s"):
            assert getattr(loaded, name) == getattr(predictor, name)
            assert type(getattr(loaded, name)) is type(getattr(predictor, name))
        for name in ("horizons_s", "coefficients", "covariance", "scales"):
            np.testing.assert_array_equal(getattr(loaded, name), getattr(predictor, name))
        assert loaded.channels == ("z", "roll") and loaded.targets == ("roll", "pitch")
        assert loaded.metadata == {"ridge": [1e-3]}
        assert bool((loaded.heldout_means == means).all()) is exact
        np.testing.assert_allclose(loaded.heldout_means, means, rtol=1e-7)
    motion = _predictor(targets=("z", "roll", "pitch"))
    loaded = LinearMotionPredictor.load(motion.save(tmp_path / "m.npz"))
    assert loaded.targets == ("z", "roll", "pitch") and loaded.heldout_means.shape == (0, 0, 3)
    # a window that is not a whole number of blocks (5 samples, blocks of 2)
    odd = _predictor(n=5, block=2)
    assert LinearMotionPredictor.load(odd.save(tmp_path / "odd.npz")).n_window == 5


def test_a_file_whose_arrays_do_not_fit_its_window_is_refused_naming_it(tmp_path) -> None:
    predictor = _predictor()
    path = predictor.save(tmp_path / "p.npz")
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    for name, bad in (
        ("coefficients", arrays["coefficients"][:, :-1]),
        ("covariance", arrays["covariance"][:2]),
        ("scales", arrays["scales"][:1]),
        ("block", np.array(3)),
    ):
        broken = tmp_path / f"broken_{name}.npz"
        np.savez(broken, **{**arrays, name: bad})
        with pytest.raises(ValueError) as error:
            LinearMotionPredictor.load(broken)
        assert (
            str(error.value)
            == f"{broken}: coefficient or covariance shapes do not match its window"
        )
    # a file that is none: named, as not a deck-tilt predictor file
    missing = tmp_path / "missing.npz"
    with pytest.raises(ValueError) as error:
        LinearTiltPredictor.load(missing)
    assert str(error.value).startswith(f"{missing} is not a deck-tilt predictor file: ")
    # an old file without targets is roll and pitch
    np.savez(tmp_path / "old.npz", **{k: v for k, v in arrays.items() if k != "targets"})
    assert LinearMotionPredictor.load(tmp_path / "old.npz").targets == ("roll", "pitch")


def test_a_tilt_predictor_of_other_targets_is_refused_naming_them() -> None:
    with pytest.raises(ValueError) as error:
        _predictor(targets=("z", "roll", "pitch"), cls=LinearTiltPredictor)
    assert (
        str(error.value) == "a tilt predictor predicts roll and pitch, not ('z', 'roll', 'pitch')"
    )
    assert LinearTiltPredictor.KIND == "deck-tilt predictor"
    assert LinearMotionPredictor.KIND == "deck-motion predictor"


def test_an_invalid_prediction_gives_no_chance_of_a_level_deck() -> None:
    invalid = TiltPrediction(False, "no window", 1.0)
    assert invalid.probability_within(90.0) == 0.0


def test_an_older_file_without_held_out_means_loads_with_none_and_a_save_halves_them(
    tmp_path,
) -> None:
    """A file written before the held-out means were kept loads with none (shape (0, 0, 2));
    a plain save keeps them as float32, not to the bit."""
    means = np.full((3, 4, 2), 1.0 + 2.0**-40)
    predictor = _predictor(heldout_means=means, cls=LinearTiltPredictor)
    path = predictor.save(tmp_path / "plain.npz")
    assert not bool((LinearTiltPredictor.load(path).heldout_means == means).all())
    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files if key != "heldout_means"}
    older = tmp_path / "older.npz"
    np.savez(older, **arrays)
    loaded = LinearTiltPredictor.load(older)
    assert loaded.heldout_means.shape == (0, 0, 2)
    np.testing.assert_array_equal(loaded.coefficients, predictor.coefficients)


def test_the_ridge_penalises_every_coefficient_but_the_constant_at_its_optimum() -> None:
    rng = np.random.default_rng(3)
    x = np.column_stack([rng.normal(0.0, 1.0, (30, 3)), np.ones(30)])
    y = rng.normal(0.0, 1.0, (30, 2))
    penalty = 2.5
    fit = linear_predictors._ridge(x, y, penalty)
    # the gradient of |x b - y|^2 + penalty |b without its constant|^2 vanishes at the fit
    shrink = fit.copy()
    shrink[-1] = 0.0
    np.testing.assert_allclose(x.T @ (x @ fit - y) + penalty * shrink, 0.0, atol=1e-9)
    np.testing.assert_allclose(linear_predictors._ridge(x, y, penalty, x.T @ x), fit)


def test_each_horizon_is_fitted_on_its_own_examples_whatever_the_other_horizons() -> None:
    histories, futures, groups, _ = _linear_examples(episodes=6, per=30, seed=4)
    rng = np.random.default_rng(5)
    futures = futures + rng.normal(0.0, 0.01, futures.shape)
    futures[::3, 1] = np.nan  # a third of the examples' second future is unknown

    def fit(futures_h: np.ndarray, horizons: list[float]) -> LinearTiltPredictor:
        return LinearTiltPredictor.fit(
            histories,
            futures_h,
            groups,
            np.array(horizons),
            4 * DT,
            DT,
            block=1,
            ridges=(1e-3, 1e-1),
        )

    both = fit(futures, [0.0, 1.0])
    alone = fit(futures[:, 1:], [1.0])
    np.testing.assert_allclose(both.coefficients[1], alone.coefficients[0], rtol=1e-9)
    np.testing.assert_allclose(both.covariance[1], alone.covariance[0], rtol=1e-9)


def test_the_chances_normal_points_are_a_balanced_set_with_no_point_beyond_six_sigma() -> None:
    points = linear_predictors._normal_points()
    assert points.shape == (linear_predictors._N_POINTS, 2)
    # a scrambled Sobol set: no point at the unit square's corner (-7 sigma once clipped)
    assert float(np.abs(points).max()) < 6.0
    np.testing.assert_allclose(points.mean(axis=0), 0.0, atol=0.02)
    np.testing.assert_allclose(points.std(axis=0), 1.0, atol=0.02)


def test_a_fit_on_three_channels_reads_each_window_of_them_and_keeps_them() -> None:
    histories, futures, groups, _ = _linear_examples(episodes=4, per=20, seed=6)
    heave = np.random.default_rng(7).normal(0.0, 0.1, (*histories.shape[:2], 1))
    with_heave = np.concatenate([histories[..., :2], heave, histories[..., 2:]], axis=-1)
    channels = ("roll", "pitch", "heave")
    fitted = LinearTiltPredictor.fit(
        with_heave, futures, groups, np.array([0.0, 1.0]), 4 * DT, DT, block=1, channels=channels
    )
    assert fitted.channels == channels
    assert fitted.coefficients.shape == (2, 3 * 4 + 1, 2)
    # the futures are a map of roll and pitch alone: heave's coefficients are (near) zero
    np.testing.assert_allclose(fitted.coefficients[:, 2:12:3], 0.0, atol=0.05)
