"""Property-based fuzzing (hypothesis) of estimator inputs, actions and config overrides.

Bounded to run in well under a minute on one core: few environments are built, and each
runs a handful of steps.  ``benchmarks/fuzz_soak.py`` runs the long version.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import landing_env  # noqa: F401  (registers the environments)
from estimation.camera_model import CameraIntrinsics
from estimation.estimator import (
    BAD_CORNERS,
    BAD_TIMESTAMP,
    MAX_OUTSIDE_IMAGE_FRAC,
    RANGE_INVALID,
    RankedEstimator,
)
from estimation.frames import tof_positions_in_camera_frame
from estimation.registry import FRAME_ESTIMATOR_NAMES, make_estimator
from estimation.synthetic import SyntheticScene
from estimation.tof_calibration import TofCameraCalibration
from estimation.tracking import CornerTracker, TrackedEstimator
from estimation.types import CameraFrame, RangeReading, TagDetection
from landing_env.config import DeckLandingConfig
from landing_env.config_limits import LIMITS, numeric_leaves
from landing_env.errors import ConfigError

TAG_SIZE = 0.12
INTRINSICS = CameraIntrinsics(dist=(-0.25, 0.08, 0.001, -0.001, 0.0))
CALIBRATION = TofCameraCalibration.exact(INTRINSICS, tof_positions_in_camera_frame(), 0.2, 5.0)


def _estimators() -> dict:
    built = {
        name: make_estimator(
            name, intrinsics=INTRINSICS, tag_size=TAG_SIZE, tof_calibration=CALIBRATION
        )
        for name in FRAME_ESTIMATOR_NAMES
    }
    built["crhf+kf"] = TrackedEstimator(
        make_estimator(
            "crhf", intrinsics=INTRINSICS, tag_size=TAG_SIZE, tof_calibration=CALIBRATION
        ),
        CornerTracker(dt=0.05, max_bridged_frames=3),
    )
    built["auto"] = RankedEstimator(
        "auto",
        tuple(
            make_estimator(n, intrinsics=INTRINSICS, tag_size=TAG_SIZE, tof_calibration=CALIBRATION)
            for n in ("ihrcf", "atda")
        ),
    )
    return built


ESTIMATORS = _estimators()
SCENE = SyntheticScene(INTRINSICS, TAG_SIZE)
GOOD = SCENE.measure(np.eye(3), np.array([0.02, -0.01, 1.0]), timestamp=2.0)


@pytest.mark.parametrize("name", list(ESTIMATORS))
def test_the_clean_measurement_is_estimated(name: str) -> None:
    ESTIMATORS[name].reset()
    assert ESTIMATORS[name].estimate(GOOD.frame, GOOD.ranges).valid


@pytest.mark.parametrize("name", list(ESTIMATORS))
@pytest.mark.parametrize("timestamp", ["now", math.nan, math.inf, None, True, [2.0]])
def test_a_bad_timestamp_gives_an_invalid_estimate(name: str, timestamp: object) -> None:
    frame = CameraFrame(timestamp, GOOD.frame.detections)  # type: ignore[arg-type]
    estimate = ESTIMATORS[name].estimate(frame, GOOD.ranges)
    assert not estimate.valid and estimate.reason == BAD_TIMESTAMP


@pytest.mark.parametrize("name", list(ESTIMATORS))
@pytest.mark.parametrize("shift_px", [9e5, -2e4, 1.2 * INTRINSICS.width])
def test_corners_far_outside_the_image_are_refused(name: str, shift_px: float) -> None:
    corners = GOOD.frame.detections[0].corners_px + np.array([shift_px, 0.0])
    frame = CameraFrame(2.0, (TagDetection(0, corners),))
    estimate = ESTIMATORS[name].estimate(frame, GOOD.ranges)
    assert not estimate.valid and estimate.reason == BAD_CORNERS


def test_corners_just_past_the_edge_are_still_used() -> None:
    # a tracker's bridged corners may lie a little outside the image
    corners = GOOD.frame.detections[0].corners_px + np.array([-300.0, 0.0])
    assert corners.min() < 0.0 and corners.min() > -MAX_OUTSIDE_IMAGE_FRAC * INTRINSICS.width
    frame = CameraFrame(2.0, (TagDetection(0, corners),))
    assert ESTIMATORS["atda"].estimate(frame, GOOD.ranges).reason != BAD_CORNERS


@pytest.mark.parametrize("name", ["ihrcf", "crhf"])
@pytest.mark.parametrize("valid", [[math.nan] * 4, [0.5] * 4, [2] * 4, ["yes"] * 4])
def test_only_true_validity_flags_count(name: str, valid: list) -> None:
    ranges = RangeReading(2.0, GOOD.ranges.ranges, np.asarray(valid))
    estimate = ESTIMATORS[name].estimate(GOOD.frame, ranges)
    assert not estimate.valid
    assert estimate.reason in (RANGE_INVALID, "numerical_error")
    ones = RangeReading(2.0, GOOD.ranges.ranges, np.ones(4))
    assert ESTIMATORS[name].estimate(GOOD.frame, ones).valid


_number = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-2000.0, 2000.0),
    st.integers(-(10**6), 10**6),
)
_timestamp = st.one_of(_number, st.text(max_size=3), st.none(), st.booleans())


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    name=st.sampled_from(sorted(ESTIMATORS)),
    timestamp=_timestamp,
    corner_noise=st.lists(_number, min_size=8, max_size=8),
    scale=st.sampled_from([0.0, 1e-3, 1.0, 1e3]),
    n_corners=st.sampled_from([4, 3, 5]),
    tag_id=st.sampled_from([0, 0, 0, 7]),
    ranges=st.lists(_number, min_size=3, max_size=5),
    valid=st.lists(st.one_of(st.booleans(), _number), min_size=3, max_size=5),
)
def test_fuzzed_estimator_inputs_never_raise_nor_give_nonsense(
    name: str,
    timestamp: object,
    corner_noise: list,
    scale: float,
    n_corners: int,
    tag_id: int,
    ranges: list,
    valid: list,
) -> None:
    with np.errstate(all="ignore"):
        noise = np.asarray(corner_noise, dtype=float).reshape(4, 2) * scale
        corners = np.vstack([GOOD.frame.detections[0].corners_px + noise] * 2)[:n_corners]
    frame = CameraFrame(timestamp, (TagDetection(tag_id, corners),))  # type: ignore[arg-type]
    reading = RangeReading(2.0, np.asarray(ranges, dtype=float), np.asarray(valid, dtype=object))
    estimate = ESTIMATORS[name].estimate(frame, reading)
    if estimate.valid:
        assert np.isfinite(estimate.as_vector()).all()
        assert math.isfinite(estimate.timestamp)
        assert n_corners == 4 and tag_id == 0
        size = np.array([INTRINSICS.width, INTRINSICS.height])
        assert (np.abs(corners - size / 2) <= (0.5 + MAX_OUTSIDE_IMAGE_FRAC) * size).all()
    else:
        assert estimate.reason


# ------------------------------------------------------------------------------ actions
@pytest.fixture(scope="module")
def env() -> gym.Env:
    environment = gym.make("DeckLanding-v2", overrides={"tof.noise": "vl53l1x"})
    yield environment
    environment.close()


_action_value = st.one_of(
    st.floats(-1.0, 1.0, width=32),
    st.sampled_from([-1.0, 1.0, 0.0, -0.0, np.nextafter(np.float32(1), 0)]),
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31 - 1),
    actions=st.lists(st.lists(_action_value, min_size=5, max_size=5), min_size=1, max_size=25),
)
def test_fuzzed_actions_keep_every_observation_in_its_space(
    env: gym.Env, seed: int, actions: list
) -> None:
    observation, _ = env.reset(seed=seed)
    assert env.observation_space.contains(observation)
    for action in actions:
        observation, reward, terminated, truncated, _ = env.step(np.asarray(action, np.float32))
        assert env.observation_space.contains(observation), observation
        assert math.isfinite(reward)
        if terminated or truncated:
            break


@pytest.mark.parametrize(
    "action", [[math.nan, 0, 0, 0, 0], [0, math.inf, 0, 0, 0], [0, 0, 0, 0], [[0, 0], [0, 0, 1]]]
)
def test_malformed_actions_are_a_value_error(env: gym.Env, action: object) -> None:
    env.reset(seed=0)
    with pytest.raises(ValueError):
        env.step(action)


# ------------------------------------------------------------------------------ config overrides
LEAVES = numeric_leaves(DeckLandingConfig)


def _shaped(default: object, number: float) -> object:
    if isinstance(default, tuple):
        return tuple(_shaped(item, number) for item in default)
    if isinstance(default, int) and math.isfinite(number):
        return int(max(min(number, 2**62), -(2**62)))
    return number


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    leaf=st.sampled_from(LEAVES),
    factor=st.one_of(
        st.sampled_from([0.0, -1.0, 0.5, 2.0, 10.0, 1e3]), st.floats(-1e4, 1e4), st.just(math.nan)
    ),
    seed=st.integers(0, 1000),
)
def test_a_fuzzed_override_runs_or_is_refused_naming_its_key(
    leaf: tuple[str, object], factor: float, seed: int
) -> None:
    key, default = leaf
    numbers = np.asarray(default, dtype=float).reshape(-1)
    base = float(numbers[np.isfinite(numbers)][0]) if np.isfinite(numbers).any() else 1.0
    value = _shaped(default, (base if base != 0.0 else 1.0) * factor)
    try:
        environment = gym.make("DeckLanding-v2", overrides={key: value})
    except ConfigError as error:
        assert error.key.split("[", 1)[0] == key or key.rsplit(".", 1)[-1] in str(error), (
            key,
            value,
            str(error),
        )
        return
    try:
        observation, _ = environment.reset(seed=seed)
        assert environment.observation_space.contains(observation)
        for _ in range(5):
            step = environment.step(environment.action_space.sample())
            assert environment.observation_space.contains(step[0])
            assert math.isfinite(step[1])
            if step[2] or step[3]:
                break
    finally:
        environment.close()


def test_the_limits_keep_infinity_only_where_it_means_something() -> None:
    assert {k for k, limit in LIMITS.items() if limit.allow_inf} == {
        "estimation.fusion.atda_sigma",
        "estimation.fusion.ihrcf_sigma",
        "estimation.fusion.crhf_sigma",
        "estimation.fusion.tight_sigma",
        "estimation.ihrcf.max_plane_rms_m",
        "estimation.ihrcf.max_rigid_rms_rel",
        "estimation.crhf.max_plane_rms_m",
        "estimation.crhf.max_rigid_rms_rel",
    }


@pytest.fixture(scope="module")
def timing_env() -> gym.Env:
    environment = gym.make("DeckLandingTiming-v0")
    yield environment
    environment.close()


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), decisions=st.lists(st.integers(0, 1), max_size=40))
def test_fuzzed_timing_decisions_keep_every_observation_in_its_space(
    timing_env: gym.Env, seed: int, decisions: list[int]
) -> None:
    observation, _ = timing_env.reset(seed=seed)
    assert timing_env.observation_space.contains(observation)
    for decision in decisions:
        observation, reward, terminated, truncated, _ = timing_env.step(decision)
        assert timing_env.observation_space.contains(observation)
        assert math.isfinite(reward)
        if terminated or truncated:
            break


@pytest.fixture(scope="module")
def wave_off_env() -> gym.Env:
    # the timed descent with a wave-off that often fires: commits climb back and decide again
    environment = gym.make(
        "DeckLandingTiming-BenchSS4-v6",
        overrides={"timing.wave_off_tilt_deg": 2.0},
    )
    yield environment
    environment.close()


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), decisions=st.lists(st.integers(0, 1), max_size=30))
def test_fuzzed_decisions_with_wave_offs_stay_in_the_space_and_within_the_step_limit(
    wave_off_env: gym.Env, seed: int, decisions: list[int]
) -> None:
    observation, _ = wave_off_env.reset(seed=seed)
    limit = wave_off_env.spec.max_episode_steps
    steps = 0
    for decision in decisions:
        observation, reward, terminated, truncated, info = wave_off_env.step(decision)
        steps += 1
        assert wave_off_env.observation_space.contains(observation)
        assert math.isfinite(reward)
        assert reward <= 0.0 or terminated  # only a touchdown pays
        # a wave-off costs at least a decision period of waiting, so the step limit (the
        # decisions until the wait limit forces the commit) still bounds the episode; the last
        # one may start just before the limit: at most its window and its climb beyond it
        timing = wave_off_env.unwrapped.timing
        assert info["wait_s"] <= timing.wait_limit_s + timing.wave_off_until_s + 1.5 + 0.1
        if terminated or truncated:
            break
    assert steps <= limit
