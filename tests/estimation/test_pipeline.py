"""Building every estimator an application asks for from one options object
(estimation.pipeline): which names, which calibrations, which layout, which tracker."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np
import pytest

from estimation.atda import ATDAConfig, AtdaEstimator, JointAtdaEstimator
from estimation.beacon import BeaconConfig, BeaconEstimator
from estimation.camera_model import CameraIntrinsics
from estimation.errors import ConfigError
from estimation.estimator import RankedEstimator
from estimation.frames import tof_positions_in_camera_frame
from estimation.ihrcf import IhrcfEstimator
from estimation.landmarks import Landmark, LandmarkEstimator, LandmarkLayout
from estimation.pipeline import (
    EstimationOptions,
    build_estimators,
    names_to_build,
    needs_intrinsics,
    needs_tof_calibration,
)
from estimation.registry import (
    AUTO_RANKING,
    ESTIMATOR_NAMES,
    REGISTRY,
    BuildInputs,
    register_estimator,
    unregister_estimator,
)
from estimation.tof_calibration import TofCameraCalibration
from estimation.tracking import TrackedEstimator
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading, TagDetection

K = CameraIntrinsics()
#: the sensors half as far again from the camera as the standard layout's
POSITIONS_C = 1.5 * tof_positions_in_camera_frame()
CAL = TofCameraCalibration.exact(K, POSITIONS_C, 0.04, 4.0)
SINGLE = LandmarkLayout.single(tag_id=5, size=0.3)
#: a large tag off the landing point and a small one on it
NESTED = LandmarkLayout((Landmark(1, 0.6, 0.6, 0.0), Landmark(2, 0.12, 0.0, 0.0)))


@dataclasses.dataclass(frozen=True)
class ProbeConfig:
    gain: float = 1.0


class ProbeEstimator:
    """A registered estimator that keeps what it was built from and reports its tag at 1 m."""

    name = "probe"

    def __init__(self, inputs: BuildInputs) -> None:
        if inputs.config.gain < 0.0:
            raise ConfigError("gain", f"{inputs.config.gain} must not be negative")
        self.inputs = inputs
        self.tag_id = inputs.tag_id

    def reset(self) -> None:
        pass

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        return DeckPoseEstimate(
            method=self.name,
            timestamp=frame.timestamp,
            valid=True,
            rotation=np.eye(3),
            translation=np.array([0.0, 0.0, 1.0]),
            extras={"tag_id": self.inputs.tag_id, "tag_size": self.inputs.tag_size},
        )


@pytest.fixture
def probe(request: pytest.FixtureRequest) -> Iterator[str]:
    """``probe`` registered with the flags given as the test's parameter."""
    flags = getattr(request, "param", {})
    register_estimator("probe", ProbeEstimator, ProbeConfig, **flags)
    try:
        yield "probe"
    finally:
        unregister_estimator("probe")


def _options(
    names: tuple[str, ...], layout: LandmarkLayout = SINGLE, **kwargs
) -> EstimationOptions:
    return EstimationOptions(
        names=names,
        layout=layout,
        intrinsics=K,
        tof_calibration=CAL,
        tof_positions_c=POSITIONS_C,
        **kwargs,
    )


def _square(side_px: float, centre: tuple[float, float]) -> np.ndarray:
    x, y = centre
    h = 0.5 * side_px
    return np.array([[x - h, y + h], [x + h, y + h], [x + h, y - h], [x - h, y - h]])


def test_fused_is_built_as_its_sources_each_name_once_in_the_order_asked() -> None:
    assert names_to_build("atda", ("fused", "atda", "ihrcf"), ("tight", "ihrcf")) == [
        "atda",
        "ihrcf",
        "tight",
    ]
    assert names_to_build("fused", (), ("crhf",)) == ["crhf"]
    # the fusion's sources are built only for fused
    assert names_to_build("atda", ("crhf", "atda"), ("tight",)) == ["atda", "crhf"]


def test_the_names_that_need_the_intrinsics_and_the_tof_calibration() -> None:
    assert needs_intrinsics(["atda"]) and needs_intrinsics(["beacon"])
    assert needs_intrinsics(["truth", "auto"])  # auto runs IHRCF and ATDA
    assert not needs_intrinsics(["truth"]) and not needs_intrinsics(("truth", "fused"))
    assert needs_tof_calibration(["auto"]) and needs_tof_calibration(("crhf",))
    assert not needs_tof_calibration(["truth"]) and not needs_tof_calibration(["atda"])
    # tight uses the calibration when there is one, without needing it
    assert not needs_tof_calibration(["tight"])
    assert needs_tof_calibration(["tight"], optional=True)
    assert not needs_tof_calibration(["atda", "beacon"], optional=True)


@pytest.mark.parametrize("name", ["fused", "apriltag"])
def test_a_name_that_is_no_estimator_is_refused_naming_the_key_and_the_names_allowed(
    name: str,
) -> None:
    with pytest.raises(ConfigError) as error:
        build_estimators(_options((name,)))
    allowed = ", ".join(n for n in ESTIMATOR_NAMES if n != "fused")
    assert error.value.key == "estimation.observed"
    assert error.value.detail == f"cannot build {name!r}; allowed: {allowed}"
    assert "fused" not in allowed.split(", ") and "beacon" in allowed.split(", ")


def test_the_truth_is_refused_unless_the_host_supplies_it() -> None:
    with pytest.raises(ConfigError) as error:
        build_estimators(_options(("truth", "atda")))
    assert error.value.key == "estimation.observed"
    assert error.value.detail == "'truth' must be supplied by the host"


@pytest.mark.parametrize(
    "probe",
    [
        {"needs_intrinsics": True},
        {"needs_intrinsics": False, "uses_ranges": True},
        {"needs_tof_calibration": True},
        {"wants_tof_calibration": True, "uses_ranges": True},
    ],
    indirect=True,
)
def test_an_estimator_gets_the_tags_size_and_id_and_only_the_calibrations_it_takes(
    probe: str,
) -> None:
    built = build_estimators(_options((probe,), configs={probe: ProbeConfig(gain=2.0)}))[probe]
    assert isinstance(built, ProbeEstimator)
    inputs = built.inputs
    assert (inputs.tag_id, inputs.tag_size) == (5, 0.3)
    assert inputs.intrinsics is K
    assert inputs.config == ProbeConfig(gain=2.0)
    spec = REGISTRY[probe]
    takes_calibration = spec.needs_tof_calibration or spec.wants_tof_calibration
    assert inputs.tof_calibration is (CAL if takes_calibration else None)
    assert inputs.tof_positions_c is (POSITIONS_C if spec.uses_ranges else None)
    # without a config of its own: its defaults
    default = build_estimators(_options((probe,)))[probe]
    assert default.inputs.config == ProbeConfig()


def test_a_config_error_of_an_estimator_is_named_under_its_estimation_key(probe: str) -> None:
    with pytest.raises(ConfigError) as error:
        build_estimators(_options((probe,), configs={probe: ProbeConfig(gain=-1.0)}))
    assert error.value.key == "estimation.probe.gain"
    assert error.value.detail == "-1.0 must not be negative"


def test_tracking_wraps_the_names_asked_for_in_a_tracker_of_the_options_settings(
    probe: str,
) -> None:
    settings = {"tracking_dt_s": 0.1, "max_bridged_frames": 5, "tracking_smooth": True}
    built = build_estimators(
        _options((probe, "atda"), tracking=True, tracking_names=("atda",), **settings)
    )
    assert isinstance(built[probe], ProbeEstimator)
    tracked = built["atda"]
    assert isinstance(tracked, TrackedEstimator) and isinstance(tracked.inner, AtdaEstimator)
    assert tracked.name == "atda" and tracked.tag_id == 5
    config = tracked.tracker.config
    assert (config.dt, config.max_bridged_frames, config.smooth) == (0.1, 5, True)
    # every name when none is named; none without tracking
    every = build_estimators(_options((probe, "atda"), tracking=True))
    assert all(isinstance(e, TrackedEstimator) for e in every.values())
    assert every[probe].name == probe and every[probe].tracker.config.smooth is False
    untracked = build_estimators(_options((probe, "atda"), tracking_names=(probe, "atda")))
    assert not any(isinstance(e, TrackedEstimator) for e in untracked.values())


def test_auto_ranks_instances_of_its_own_even_when_they_are_also_compared() -> None:
    built = build_estimators(_options(("auto", "ihrcf")))
    auto = built["auto"]
    assert isinstance(auto, RankedEstimator) and auto.name == "auto"
    assert [e.name for e in auto.estimators] == list(AUTO_RANKING)
    assert isinstance(auto.estimators[0], IhrcfEstimator)
    assert auto.estimators[0] is not built["ihrcf"]
    assert auto.estimators[0].tof_calibration is CAL


@pytest.mark.parametrize(
    ("probe", "chosen_id"),
    [({"uses_ranges": True}, 2), ({"uses_ranges": False}, 1)],
    indirect=["probe"],
)
def test_on_nested_tags_the_range_estimators_take_the_one_at_the_landing_point_others_the_largest(
    probe: str, chosen_id: int
) -> None:
    built = build_estimators(_options((probe,), layout=NESTED))[probe]
    assert isinstance(built, LandmarkEstimator) and built.layout is NESTED
    frame = CameraFrame(
        0.5,
        (
            TagDetection(1, _square(100.0, (200.0, 200.0))),
            TagDetection(2, _square(30.0, (400.0, 300.0))),
        ),
    )
    estimate = built.estimate(frame, RangeReading(0.5, np.full(4, 1.0), np.ones(4, dtype=bool)))
    assert estimate.valid and estimate.method == probe
    assert estimate.extras["landmark_id"] == chosen_id
    landmark = NESTED.by_id(chosen_id)
    # each tag's own estimator, of its size; the pose moved from the tag to the deck frame
    assert estimate.extras["tag_id"] == chosen_id
    assert estimate.extras["tag_size"] == landmark.size
    np.testing.assert_allclose(estimate.translation, [-landmark.x, -landmark.y, 1.0])


def test_atda_on_nested_landmarks_solves_over_every_tag_with_its_config_unless_told_not_to() -> (
    None
):
    atda_config = ATDAConfig(joint_landmarks=True, max_reprojection_error_px=3.0)
    joint = build_estimators(_options(("atda",), layout=NESTED, configs={"atda": atda_config}))
    joint = joint["atda"]
    assert isinstance(joint, JointAtdaEstimator)
    assert joint.intrinsics is K and joint.layout is NESTED and joint.config is atda_config
    assert joint.min_side_px == 12.0
    assert isinstance(joint.single, LandmarkEstimator) and joint.single.name == "atda"
    assert joint.single.choice.prefer == "largest"
    by_default = build_estimators(_options(("atda",), layout=NESTED))["atda"]
    assert isinstance(by_default, JointAtdaEstimator) and by_default.config == ATDAConfig()
    apart = ATDAConfig(joint_landmarks=False)
    single = build_estimators(_options(("atda",), layout=NESTED, configs={"atda": apart}))
    assert isinstance(single["atda"], LandmarkEstimator)
    # every tag's estimator has the config
    assert single["atda"].make_one(NESTED.landmarks[0]).config is apart


def _range_down() -> RangeReading:
    return RangeReading(0.0, np.array([2.0]), np.array([True]))


def test_beacon_takes_the_intrinsics_the_rangefinder_and_its_offset_over_its_config() -> None:
    configured = BeaconConfig(min_corner_area_px=9.0, max_range_m=12.0)
    options = dataclasses.replace(
        _options(("beacon",), configs={"beacon": configured}),
        range_down=_range_down,
        range_offset_m=0.07,
    )
    beacon = build_estimators(options)["beacon"]
    assert isinstance(beacon, BeaconEstimator)
    assert beacon.intrinsics is K and beacon.range_source is _range_down and beacon.tag_id == 5
    assert beacon.config == dataclasses.replace(configured, range_offset_m=0.07)
    default = build_estimators(dataclasses.replace(options, configs={}))["beacon"]
    assert default.config == BeaconConfig(range_offset_m=0.07)
    nested = build_estimators(dataclasses.replace(options, layout=NESTED))["beacon"]
    assert isinstance(nested, LandmarkEstimator) and nested.name == "beacon"
    assert nested.layout is NESTED
    for landmark in NESTED.landmarks:
        one = nested.make_one(landmark)
        assert isinstance(one, BeaconEstimator) and one.tag_id == landmark.tag_id
        assert one.range_source is _range_down and one.config.range_offset_m == 0.07


@pytest.mark.parametrize("missing", ["range_down", "intrinsics"])
def test_beacon_without_the_intrinsics_or_a_rangefinder_is_refused_naming_both(
    missing: str,
) -> None:
    options = dataclasses.replace(_options(("beacon",)), range_down=_range_down)
    with pytest.raises(ConfigError) as error:
        build_estimators(dataclasses.replace(options, **{missing: None}))
    assert error.value.key == "estimation.observed"
    assert error.value.detail == "beacon needs the intrinsics and a rangefinder"
