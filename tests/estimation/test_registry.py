"""One home for building estimators: the registry, the pipeline builder, one name list."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from estimation import registry
from estimation.atda import ATDAConfig
from estimation.camera_model import CameraIntrinsics
from estimation.crhf import CrhfEstimator
from estimation.estimator import DeckPoseEstimator, RankedEstimator
from estimation.frames import tof_positions_in_camera_frame
from estimation.fusion.config import POSE_SOURCES, FusionConfig
from estimation.ihrcf import IhrcfEstimator
from estimation.landmarks import Landmark, LandmarkLayout
from estimation.pipeline import EstimationOptions, build_estimators, names_to_build
from estimation.registry import (
    ESTIMATOR_NAMES,
    FRAME_ESTIMATOR_NAMES,
    REGISTRY,
    BuildInputs,
    make_estimator,
    needs_intrinsics_names,
    needs_tof_calibration_names,
)
from estimation.tight import TightEstimator
from estimation.tight_config import TightConfig
from estimation.tof_calibration import TofCameraCalibration
from estimation.tracking import TrackedEstimator
from landing_env import config as env_config
from landing_env.errors import ConfigError

K = CameraIntrinsics()
CAL = TofCameraCalibration.exact(K, tof_positions_in_camera_frame(), 0.04, 4.0)


def test_there_is_one_list_of_names() -> None:
    assert env_config.ESTIMATOR_NAMES is ESTIMATOR_NAMES
    assert list(POSE_SOURCES) == FRAME_ESTIMATOR_NAMES == list(REGISTRY)
    assert "tight" in FRAME_ESTIMATOR_NAMES
    assert set(FRAME_ESTIMATOR_NAMES) < set(ESTIMATOR_NAMES)


def test_estimation_imports_without_a_cycle_in_any_order() -> None:
    for first in ("estimation.estimator", "estimation.tight", "estimation.registry",
                  "estimation.pipeline", "estimation.fusion"):  # fmt: skip
        code = f"import {first}; import estimation.registry, estimation.pipeline"
        subprocess.run([sys.executable, "-c", code], check=True)
    # the interface module does not reach back into the estimators that import it
    code = "import sys, estimation.estimator; assert 'estimation.atda' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("name", FRAME_ESTIMATOR_NAMES)
def test_every_registered_name_builds_with_its_default_config(name: str) -> None:
    estimator = make_estimator(name, intrinsics=K, tag_size=0.15, tof_calibration=CAL)
    assert isinstance(estimator, DeckPoseEstimator) and estimator.name == name
    with pytest.raises(TypeError, match=REGISTRY[name].config_type.__name__):
        make_estimator(name, intrinsics=K, tag_size=0.15, tof_calibration=CAL, config=object())


def test_tight_needs_the_camera_but_not_the_tof_lookup() -> None:
    with pytest.raises(ValueError, match="intrinsics"):
        make_estimator("tight", intrinsics=None, tag_size=0.15)
    estimator = make_estimator(
        "tight", intrinsics=K, tag_size=0.15, config=TightConfig(pixel_sigma_px=1.0)
    )
    assert isinstance(estimator, TightEstimator) and estimator.config.pixel_sigma_px == 1.0


def test_the_pipeline_builds_names_from_one_options_object() -> None:
    layout = LandmarkLayout((Landmark(tag_id=0, size=0.15),))
    names = names_to_build("fused", ("auto", "crhf"), fusion_sources=("tight", "atda"))
    assert names == ["auto", "crhf", "tight", "atda"]
    options = EstimationOptions(
        names=tuple(names),
        layout=layout,
        intrinsics=K,
        tof_calibration=CAL,
        tof_positions_c=tof_positions_in_camera_frame(),
        tracking=True,
        configs={"tight": TightConfig(pixel_sigma_px=0.8)},
    )
    built = build_estimators(options)
    assert list(built) == names
    assert isinstance(built["auto"], RankedEstimator)
    assert isinstance(built["tight"], TrackedEstimator)
    assert built["tight"].inner.config.pixel_sigma_px == 0.8
    with pytest.raises(ConfigError, match="truth"):
        build_estimators(EstimationOptions(names=("truth",), layout=layout))
    supplied = build_estimators(
        EstimationOptions(names=("truth",), layout=layout), {"truth": built["crhf"]}
    )
    assert supplied["truth"] is built["crhf"]


def test_tight_is_a_fusion_source_whose_own_covariance_is_the_noise() -> None:
    config = FusionConfig(sources=("tight",))
    assert "tight" in config.covariance_sources
    with pytest.raises(ConfigError, match="sources"):
        FusionConfig(sources=("apriltag",))


def test_the_env_observes_tight_and_fuses_it(tmp_path) -> None:
    import gymnasium as gym

    import landing_env  # noqa: F401

    env = gym.make(
        "DeckLanding-v2",
        overrides={
            "estimation.observed": "tight",
            "estimation.compare": ["fused", "truth"],
            "estimation.fusion.sources": ["tight"],
            "motion.kind": "static",
        },
    )
    try:
        _, info = env.reset(seed=1)
        for _ in range(10):
            _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        tight = info["estimates"]["tight"]
        assert tight["valid"], tight["reason"]
        assert np.all(np.abs(np.asarray(tight["pose"]) - info["deck_pose_true"]) < 0.02)
        assert "std" in tight  # the covariance travels with it
        fused = info["estimates"]["fused"]
        assert fused["valid"], fused["reason"]
        assert fused["extras"].get("tight_accepted", 0) > 0
    finally:
        env.close()


def test_the_simulator_hands_tight_and_fused_its_configured_sensor_noise() -> None:
    from landing_env.config import load_config
    from landing_env.estimators import _with_sensor_noise, fusion_settings

    exact = load_config("paper-stewart")
    noisy = load_config("realistic", overrides={"tof.sigma_per_m": 0.005})
    for config, sigma_per_m in ((exact, 0.0), (noisy, 0.005)):
        tight = _with_sensor_noise(config.estimation.tight, config)
        assert tight.tof_sigma_per_m == sigma_per_m
        assert fusion_settings(config).tof_sigma_per_m == sigma_per_m
    project = load_config("realistic", overrides={"camera.mode": "project"})
    assert _with_sensor_noise(project.estimation.tight, project).pixel_sigma_px == 0.01
    kept = load_config("realistic", overrides={"estimation.tight.noise_from_sensors": False})
    assert _with_sensor_noise(kept.estimation.tight, kept) == kept.estimation.tight


def test_the_simulator_hands_fused_the_seas_wave_components_when_asked() -> None:
    """With ``deck_waves_from_motion`` the fusion's roll and pitch model takes the motion's
    two largest components and its RMS; without it (or for another motion) none is set."""
    from landing_env.config import load_config
    from landing_env.estimators import fusion_settings

    # the prior is off by default: the filter identifies the motion itself
    assert fusion_settings(load_config("realistic")).deck_roll_periods_s == ()
    told = load_config("realistic", overrides={"estimation.fusion.deck_waves_from_motion": True})
    fusion = fusion_settings(told)  # the bench: 5 + 1.5 deg per axis
    np.testing.assert_allclose(fusion.deck_roll_periods_s, (1 / 0.091, 1 / 0.23))
    np.testing.assert_allclose(fusion.deck_pitch_periods_s, (1 / 0.11, 1 / 0.25))
    np.testing.assert_allclose(fusion.deck_attitude_rms_deg, [math.sqrt((25 + 2.25) / 2)] * 2)
    assert fusion_settings(load_config("paper-stewart")).deck_roll_periods_s == ()
    sea = load_config("bench-ss4", overrides={"estimation.fusion.deck_waves_from_motion": True})
    assert fusion_settings(sea).deck_roll_periods_s == ()


def test_the_names_that_get_the_intrinsics_and_the_tof_calibration() -> None:
    assert needs_intrinsics_names() == {"atda", "ihrcf", "crhf", "tight", "beacon"}
    assert needs_tof_calibration_names() == {"ihrcf", "crhf"}
    assert needs_tof_calibration_names(optional=True) == {"ihrcf", "crhf", "tight"}


def test_make_estimator_refuses_what_it_cannot_build_saying_what_is_missing() -> None:
    with pytest.raises(ValueError) as error:
        make_estimator("apriltag", intrinsics=K, tag_size=0.15)
    assert str(error.value) == "unknown estimator 'apriltag'; allowed: atda, ihrcf, crhf, tight"
    with pytest.raises(ValueError) as error:
        make_estimator("atda", intrinsics=None, tag_size=0.15)
    assert str(error.value) == "atda needs the camera intrinsics"
    with pytest.raises(ValueError) as error:
        make_estimator("crhf", intrinsics=K, tag_size=0.15)
    assert str(error.value) == "crhf needs a tof_calibration"
    with pytest.raises(TypeError) as type_error:
        make_estimator("atda", intrinsics=K, tag_size=0.15, config=TightConfig())
    assert str(type_error.value) == "atda expects a ATDAConfig"
    # IHRCF and CRHF only undistort with the intrinsics: they build without them
    assert (
        make_estimator("ihrcf", intrinsics=None, tag_size=0.15, tof_calibration=CAL).intrinsics
        is None
    )


def test_make_estimator_builds_for_tag_0_with_the_config_given_or_the_defaults() -> None:
    default = make_estimator("atda", intrinsics=K, tag_size=0.2)
    assert default.tag_id == 0 and default.tag_size == 0.2 and default.config == ATDAConfig()
    assert default.intrinsics is K
    config = ATDAConfig(max_reprojection_error_px=3.0)
    given = make_estimator("atda", intrinsics=K, tag_size=0.25, tag_id=9, config=config)
    assert (given.tag_id, given.tag_size, given.config) == (9, 0.25, config)
    assert given.config is config


@pytest.mark.parametrize("name", ["ihrcf", "crhf", "tight"])
def test_a_camera_and_tof_estimator_is_built_from_every_input_given(name: str) -> None:
    positions = 1.5 * tof_positions_in_camera_frame()
    calibration = TofCameraCalibration.exact(K, positions, 0.04, 4.0)
    config = REGISTRY[name].config_type()
    estimator = make_estimator(
        name,
        intrinsics=K,
        tag_size=0.2,
        tag_id=9,
        tof_calibration=calibration,
        tof_positions_c=positions,
        config=config,
    )
    assert (estimator.tag_size, estimator.tag_id) == (0.2, 9) and estimator.config is config
    np.testing.assert_array_equal(estimator.tof_positions_c, positions)


def test_the_builder_of_the_camera_and_tof_estimators_hands_on_every_input() -> None:
    # the builders are made when the registry is imported; this makes them again
    positions = 1.5 * tof_positions_in_camera_frame()
    calibration = TofCameraCalibration.exact(K, positions, 0.04, 4.0)
    for cls in (IhrcfEstimator, CrhfEstimator):
        config = cls.config_class()
        inputs = BuildInputs(K, 0.2, 9, calibration, positions, config)
        estimator = registry._camera_and_tof(cls, "tof_calibration")(inputs)
        assert isinstance(estimator, cls)
        assert (estimator.tag_size, estimator.tag_id) == (0.2, 9)
        assert estimator.config is config and estimator.intrinsics is K
        assert estimator.tof_calibration is calibration
        np.testing.assert_array_equal(estimator.tof_positions_c, positions)
    tight = registry._camera_and_tof(TightEstimator, "intrinsics")(
        BuildInputs(K, 0.2, 9, None, positions, TightConfig(pixel_sigma_px=1.0))
    )
    assert isinstance(tight, TightEstimator) and tight.config.pixel_sigma_px == 1.0
    assert tight.intrinsics is K
