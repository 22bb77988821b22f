"""An estimator of one's own, registered by a public call, is usable by name everywhere."""

from __future__ import annotations

import dataclasses
import importlib.metadata
import linecache
import types
import warnings
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from estimation import registry
from estimation.atda import ATDAConfig, AtdaEstimator
from estimation.camera_model import CameraIntrinsics
from estimation.fusion.config import FusionConfig
from estimation.landmarks import Landmark, LandmarkLayout
from estimation.pipeline import EstimationOptions, build_estimators
from estimation.registry import (
    ESTIMATOR_NAMES,
    FRAME_ESTIMATOR_NAMES,
    PLUGIN_GROUP,
    REGISTRY,
    BuildInputs,
    EstimatorSpec,
    load_plugins,
    register_estimator,
    unregister_estimator,
)
from estimation.synthetic import SyntheticScene
from landing_env.config import EstimationConfig
from landing_env.errors import ConfigError


@dataclasses.dataclass
class TagOnlyConfig:
    """The settings of the example estimator: ATDA's, under its own name."""

    atda: ATDAConfig = dataclasses.field(default_factory=ATDAConfig)


class TagOnlyEstimator:
    """A user's estimator: the tag-only pose, reported under its own name."""

    name = "tag_only"

    def __init__(self, inputs: BuildInputs) -> None:
        assert inputs.intrinsics is not None
        self.inner = AtdaEstimator(
            intrinsics=inputs.intrinsics,
            tag_size=inputs.tag_size,
            tag_id=inputs.tag_id,
            config=inputs.config.atda,
        )

    def reset(self) -> None:
        self.inner.reset()

    def estimate(self, frame, ranges):
        return dataclasses.replace(self.inner.estimate(frame, ranges), method=self.name)


@pytest.fixture
def tag_only() -> Iterator[str]:
    register_estimator("tag_only", TagOnlyEstimator, TagOnlyConfig)
    try:
        yield "tag_only"
    finally:
        unregister_estimator("tag_only")


def test_a_registered_estimator_is_built_by_name_through_the_pipeline(tag_only: str) -> None:
    intrinsics = CameraIntrinsics()
    options = EstimationOptions(
        names=(tag_only,),
        layout=LandmarkLayout((Landmark(tag_id=0, size=0.15),)),
        intrinsics=intrinsics,
    )
    estimator = build_estimators(options)[tag_only]
    scene = SyntheticScene(intrinsics=intrinsics, tag_size=0.15)
    rotation = np.eye(3)
    translation = np.array([0.02, -0.01, 1.5])
    measurement = scene.measure(rotation, translation)
    estimate = estimator.estimate(measurement.frame, measurement.ranges)
    assert estimate.valid, estimate.reason
    assert estimate.method == tag_only
    assert np.allclose(estimate.translation, translation, atol=1e-3)


def test_a_registered_name_is_accepted_by_the_config_but_not_as_a_fusion_source(
    tag_only: str,
) -> None:
    assert tag_only in ESTIMATOR_NAMES and tag_only in FRAME_ESTIMATOR_NAMES
    assert EstimationConfig(observed=tag_only, compare=("atda",)).observed == tag_only
    # the EKF weighs each source by its own sigmas, which a registered estimator lacks
    with pytest.raises(ConfigError, match="sources"):
        FusionConfig(sources=(tag_only,))


def test_an_unregistered_name_is_refused_again_afterwards() -> None:
    register_estimator("tag_only", TagOnlyEstimator, TagOnlyConfig)
    unregister_estimator("tag_only")
    assert "tag_only" not in REGISTRY and "tag_only" not in ESTIMATOR_NAMES
    with pytest.raises(ConfigError, match="tag_only"):
        EstimationConfig(observed="tag_only")


@pytest.mark.parametrize(
    ("name", "build", "config_type", "message"),
    [
        ("atda", TagOnlyEstimator, TagOnlyConfig, "taken"),
        ("fused", TagOnlyEstimator, TagOnlyConfig, "taken"),
        ("Mine", TagOnlyEstimator, TagOnlyConfig, "lower-case identifier"),
        ("my-estimator", TagOnlyEstimator, TagOnlyConfig, "lower-case identifier"),
        ("", TagOnlyEstimator, TagOnlyConfig, "lower-case identifier"),
        (None, TagOnlyEstimator, TagOnlyConfig, "lower-case identifier"),
        ("mine", "not callable", TagOnlyConfig, "callable"),
        ("mine", TagOnlyEstimator, TagOnlyConfig(), "must be a class"),
        ("mine", TagOnlyEstimator, len, "must be a class"),
        ("mine", TagOnlyEstimator, Landmark, "no arguments"),
    ],
)
def test_a_bad_registration_is_refused_naming_what_is_wrong(
    name, build, config_type, message
) -> None:
    before = (dict(REGISTRY), list(ESTIMATOR_NAMES), list(FRAME_ESTIMATOR_NAMES))
    with pytest.raises(ValueError, match=message):
        register_estimator(name, build, config_type)
    assert (dict(REGISTRY), list(ESTIMATOR_NAMES), list(FRAME_ESTIMATOR_NAMES)) == before


def test_the_shipped_estimators_cannot_be_unregistered() -> None:
    for name in ("atda", "ihrcf", "crhf", "tight"):
        with pytest.raises(ValueError, match="shipped"):
            unregister_estimator(name)
    with pytest.raises(ValueError, match="not registered"):
        unregister_estimator("never_registered")


def test_the_environment_observes_a_registered_estimator(tag_only: str) -> None:
    import gymnasium as gym

    import landing_env  # noqa: F401  (registers the ids)

    env = gym.make(
        "DeckLanding-v2",
        overrides={"estimation.observed": tag_only, "motion.kind": "static"},
    )
    try:
        observation, info = env.reset(seed=1)
        for _ in range(3):
            observation, _, _, _, info = env.step(
                np.zeros(env.action_space.shape, dtype=np.float32)
            )
        mine = info["estimates"][tag_only]
        assert mine["valid"], mine["reason"]
        assert observation["deck_pose_valid"][0] == 1
        assert np.all(np.abs(observation["deck_pose"][:3] - info["deck_pose_true"][:3]) < 0.02)
    finally:
        env.close()


def test_a_registered_estimator_needs_the_intrinsics_alone_by_default_and_comes_before_beacon() -> (
    None
):
    spec = register_estimator("tag_only", TagOnlyEstimator, TagOnlyConfig)
    try:
        assert REGISTRY["tag_only"] is spec
        assert spec == EstimatorSpec(
            "tag_only",
            TagOnlyConfig,
            TagOnlyEstimator,
            needs_intrinsics=True,
            needs_tof_calibration=False,
            uses_ranges=False,
            wants_tof_calibration=False,
        )
        assert FRAME_ESTIMATOR_NAMES[-1] == "tag_only"
        assert ESTIMATOR_NAMES[-4:] == ["tag_only", "beacon", "auto", "fused"]
    finally:
        unregister_estimator("tag_only")
    flags = {
        "needs_intrinsics": False,
        "needs_tof_calibration": True,
        "uses_ranges": True,
        "wants_tof_calibration": True,
    }
    spec = register_estimator("tag_only", TagOnlyEstimator, TagOnlyConfig, **flags)
    try:
        assert dataclasses.asdict(spec) == {
            "name": "tag_only",
            "config_type": TagOnlyConfig,
            "build": TagOnlyEstimator,
            **flags,
        }
    finally:
        unregister_estimator("tag_only")


def test_a_taken_name_is_refused_listing_every_name_taken() -> None:
    with pytest.raises(ValueError) as error:
        register_estimator("crhf", TagOnlyEstimator, TagOnlyConfig)
    assert str(error.value) == (
        f"estimator name 'crhf' is taken; taken: {', '.join(ESTIMATOR_NAMES)}"
    )
    assert ", tight, beacon, auto, fused" in str(error.value)


class _EntryPoint:
    """An installed entry point as importlib.metadata gives it, loading by a function."""

    def __init__(self, name: str, value: str, load: Callable[[], object]) -> None:
        self.name = name
        self.value = value
        self.attr = value.partition(":")[2] or None
        self._load = load
        self.loads = 0

    def load(self) -> object:
        self.loads += 1
        return self._load()


def _register_tag_only_as(name: str) -> EstimatorSpec:
    return register_estimator(name, TagOnlyEstimator, TagOnlyConfig)


def _fail() -> object:
    raise RuntimeError("boom")


def _import_registering(name: str) -> types.ModuleType:
    _register_tag_only_as(name)
    return types.ModuleType(f"{name}_package.estimator")


@pytest.fixture
def entry_points(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[_EntryPoint]]:
    """The installed entry points (fill the list), read afresh as in a new process."""
    points: list[_EntryPoint] = []

    def installed(*, group: str | None = None) -> list[_EntryPoint]:
        return points if group == PLUGIN_GROUP else []

    monkeypatch.setattr(importlib.metadata, "entry_points", installed)
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    try:
        yield points
    finally:
        for point in points:
            if point.name in REGISTRY and point.name not in registry.BUILT_IN:
                unregister_estimator(point.name)


def test_plugins_register_by_function_import_or_object_and_a_broken_one_is_skipped_naming_it(
    entry_points: list[_EntryPoint],
) -> None:
    entry_points += [
        # a name already registered: not loaded at all
        _EntryPoint("atda", "other_package.estimator:register", _fail),
        _EntryPoint("broken", "broken_package.estimator:register", _fail),
        _EntryPoint("silent", "silent_package.estimator", lambda: types.ModuleType("silent")),
        _EntryPoint(
            "by_function",
            "function_package.estimator:register",
            lambda: lambda: _register_tag_only_as("by_function"),
        ),
        _EntryPoint(
            "by_import", "import_package.estimator", lambda: _import_registering("by_import")
        ),
        # an attribute that is not a function: its module's import registers
        _EntryPoint(
            "by_object",
            "object_package.estimator:SPEC",
            lambda: _import_registering("by_object") and REGISTRY["by_object"],
        ),
    ]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        added = load_plugins()
    assert added == ["by_function", "by_import", "by_object"]
    assert all(name in REGISTRY and name in ESTIMATOR_NAMES for name in added)
    assert entry_points[0].loads == 0 and REGISTRY["atda"].build is not TagOnlyEstimator
    assert [str(w.message) for w in caught] == [
        "estimator plugin 'broken' (broken_package.estimator:register) skipped: RuntimeError: boom",
        "estimator plugin 'silent' (silent_package.estimator) skipped: loading it did not "
        "register 'silent' (register_estimator with the entry point's name)",
    ]
    assert all(w.category is UserWarning for w in caught)
    # once per process: a second call loads nothing and warns of nothing again
    with warnings.catch_warnings(record=True) as again:
        warnings.simplefilter("always")
        assert load_plugins() == []
    assert again == [] and [p.loads for p in entry_points] == [0, 1, 1, 1, 1, 1]


def test_a_skipped_plugins_warning_points_past_the_registry_to_the_code_that_loaded_it(
    entry_points: list[_EntryPoint],
) -> None:
    entry_points += [
        _EntryPoint("broken", "broken_package.estimator:register", _fail),
        _EntryPoint("silent", "silent_package.estimator", lambda: types.ModuleType("silent")),
    ]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_plugins()
    assert len(caught) == 2
    for warning in caught:
        # the line the warning names is a caller's (stacklevel 2), not the warning's own call
        line = linecache.getline(warning.filename, warning.lineno)
        assert line.strip() and "warnings.warn(" not in line, (warning.filename, line)
