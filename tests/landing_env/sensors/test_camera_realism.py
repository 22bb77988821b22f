"""Camera realism: blur follows relative speed x exposure, noise follows its model, tags decode."""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from estimation.camera_model import CameraIntrinsics
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.sensors.camera_config import CameraConfig
from landing_env.sensors.camera_profiles import PROFILES, camera_profile
from landing_env.sensors.camera_realism import ImageFormation, RelativeMotion, bayer_mosaic
from landing_env.world import World
from tests.renderer_agreement import Pose, place

ZERO = np.zeros(3)


@pytest.fixture(scope="module")
def world() -> Iterator[World]:
    overrides = {"camera.mode": "render", "camera.profile": "ov9281", "camera.exposure_s": 0.01}
    w = World(load_config("default", overrides=overrides))
    yield w
    w.close()


def _still_deck_motion(world: World, v_camera_w: np.ndarray) -> RelativeMotion:
    deck = world.deck_state()
    return RelativeMotion(
        np.asarray(v_camera_w, float), ZERO, deck.position_w, deck.rotation_wp, ZERO, ZERO
    )


def _exposed(world: World, motion: RelativeMotion | None, window) -> np.ndarray:
    camera = world.camera
    t_wc, r_wc = world.camera_pose_w()
    world._drone_visible(False)
    try:
        return camera.formation.expose(
            lambda w: camera._render_canvas(t_wc, r_wc, w), t_wc, r_wc, window, motion
        )
    finally:
        world._drone_visible(True)


def _box_blur_rows(image: np.ndarray, length: float) -> np.ndarray:
    """Average over ``length`` pixels along the columns (a box of fractional length)."""
    n = int(np.ceil(length)) | 1
    kernel = np.ones(n, dtype=np.float32)
    excess = (n - length) / 2.0
    kernel[0] -= excess
    kernel[-1] -= excess
    kernel /= kernel.sum()
    return cv2.filter2D(image, -1, kernel.reshape(-1, 1), borderType=cv2.BORDER_REPLICATE)


def test_motion_blur_length_is_relative_speed_times_exposure_over_depth(world: World) -> None:
    place(world, Pose(1.0))
    t_wc, _ = world.camera_pose_w()
    depth = float(t_wc[2] - world.deck_state().position_w[2])
    speed = 2.0  # m/s along world x: image rows for a level, zero-yaw camera
    expected = world.camera.intrinsics.fx * speed * 0.01 / depth
    window = (150, 150, 360, 360)
    sharp = _exposed(world, None, window)
    blurred = _exposed(world, _still_deck_motion(world, [speed, 0.0, 0.0]), window)
    lengths = np.arange(0.5 * expected, 1.5 * expected, 0.25)
    errors = [np.abs(_box_blur_rows(sharp, n) - blurred)[10:-10, 10:-10].mean() for n in lengths]
    best = lengths[int(np.argmin(errors))]
    assert best == pytest.approx(expected, rel=0.08)
    # and the blur is along the motion only: columns are as sharp as without motion
    assert world.camera.formation.blur_length_px(
        t_wc, world.camera_pose_w()[1], _still_deck_motion(world, [speed, 0, 0]), (255.5, 255.5)
    ) == pytest.approx(expected, rel=0.02)


def test_no_relative_motion_gives_no_blur(world: World) -> None:
    place(world, Pose(1.0))
    window = (150, 150, 360, 360)
    sharp = _exposed(world, None, window)
    still = _exposed(world, _still_deck_motion(world, ZERO), window)
    assert np.abs(sharp - still).max() < 1e-4


def test_rolling_shutter_slants_vertical_edges_by_speed_times_line_time() -> None:
    profile = camera_profile("imx219")
    k = CameraIntrinsics()
    formation = ImageFormation(profile, k, exposure_s=0.0)
    r_wc = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    t_wc = np.array([0.0, 0.0, 1.0])
    # camera moving along world -y = image +x at 1 m/s over a plane 1 m below
    motion = RelativeMotion(np.array([0.0, -1.0, 0.0]), ZERO, ZERO, np.eye(3), ZERO, ZERO)

    def stripes(window):
        x0, y0, x1, y1 = window
        us = np.arange(x0, x1)
        column = ((us // 40) % 2).astype(np.uint8) * 255
        return np.repeat(np.repeat(column[None, :, None], y1 - y0, axis=0), 3, axis=2)

    # the "scene" here is a pattern fixed to the image at t = 0 (a plane seen head-on)
    exposed = formation.expose(stripes, t_wc, r_wc, (0, 0, 512, 512), motion)[..., 0]
    shift_top = _edge_position(exposed[20]) - _edge_position(exposed[490])
    expected = k.fx * 1.0 * profile.line_time_s * (490 - 20)
    assert abs(shift_top) == pytest.approx(expected, rel=0.05)


def _edge_position(row: np.ndarray) -> float:
    """Sub-pixel position of the first rising edge through 0.5 after column 100."""
    start = 100 + int(np.argmax(row[100:] < 0.5))
    i = start + int(np.argmax(row[start:] >= 0.5))
    return i - 1 + (0.5 - row[i - 1]) / (row[i] - row[i - 1])


@pytest.mark.parametrize("name", ["ov9281", "imx219"])
@pytest.mark.parametrize("level", [0.002, 0.05, 0.3, 0.8])
def test_noise_variance_follows_the_poisson_gaussian_model(name: str, level: float) -> None:
    formation = ImageFormation(camera_profile(name), CameraIntrinsics())
    rng = np.random.default_rng(3)
    dn = formation.raw_dn(np.full((300, 300), level, dtype=np.float32), rng)
    mean_e = level * formation.electrons_at_white()
    gain = formation._dn_per_e
    assert dn.mean() == pytest.approx(
        formation.profile.black_level_dn + gain * mean_e, abs=0.05 + 0.002 * gain * mean_e
    )
    assert dn.var() == pytest.approx(formation.dn_variance(mean_e), rel=0.06)


@pytest.mark.parametrize("name", ["ov9281", "imx219"])
@pytest.mark.parametrize("mean_e", [1.0, 5.0, 12.0, 30.0])
def test_dim_pixels_follow_the_exact_poisson_gaussian_law_after_the_adc(
    name: str, mean_e: float
) -> None:
    from scipy.stats import norm, poisson

    formation = ImageFormation(camera_profile(name), CameraIntrinsics())
    level = mean_e / formation.electrons_at_white()
    dn = formation.raw_dn(np.full((300, 300), level, dtype=np.float32), np.random.default_rng(2))
    # the exact law: Poisson electrons plus normal read noise, rounded by the ADC
    p = formation.profile
    g = formation._dn_per_e
    values = np.arange(int(dn.min()), int(dn.max()) + 1)
    electrons = np.arange(0, 200)
    upper = (values + 0.5 - p.black_level_dn) / g
    cdf = poisson.pmf(electrons, mean_e) @ norm.cdf(
        (upper[None, :] - electrons[:, None]) / p.read_noise_e
    )
    measured = np.searchsorted(np.sort(dn.reshape(-1)), values, side="right") / dn.size
    assert np.abs(measured - cdf).max() < 0.02


def test_gain_scales_signal_and_noise_together() -> None:
    base = ImageFormation(camera_profile("ov9281"), CameraIntrinsics())
    doubled = ImageFormation(camera_profile("ov9281"), CameraIntrinsics(), gain=2.0)
    signal = np.full((300, 300), 0.1, dtype=np.float32)
    black = base.profile.black_level_dn
    a = base.raw_dn(signal, np.random.default_rng(0)) - black
    b = doubled.raw_dn(signal, np.random.default_rng(0)) - black
    assert b.mean() == pytest.approx(2.0 * a.mean(), rel=0.01)
    assert b.std() == pytest.approx(2.0 * a.std(), rel=0.05)


def test_vignetting_reaches_the_profiles_corner_illumination() -> None:
    for name in ("ov9281", "imx219"):
        formation = ImageFormation(camera_profile(name), CameraIntrinsics())
        v = formation.vignetting((0, 0, 512, 512))
        assert v[0, 0] == pytest.approx(PROFILES[name].corner_illumination, rel=0.01)
        assert v.max() == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("origin", [(224, 224), (225, 224), (224, 225), (231, 228)])
def test_a_colour_sensor_collects_one_bayer_sample_a_pixel_and_demosaics_its_colour(
    origin: tuple[int, int],
) -> None:
    formation = ImageFormation(camera_profile("imx219"), CameraIntrinsics())
    scene = np.empty((64, 64, 3), dtype=np.float32)
    scene[...] = (0.6, 0.3, 0.05)
    mosaic = bayer_mosaic(scene, origin)
    # RGGB anchored at the full image's (0, 0): red where row and column are even
    x0, y0 = origin
    assert mosaic[(-y0) % 2, (-x0) % 2] == pytest.approx(0.6)
    assert mosaic[(1 - y0) % 2, (1 - x0) % 2] == pytest.approx(0.05)
    assert mosaic[(-y0) % 2, (1 - x0) % 2] == pytest.approx(0.3)
    # a window at the image centre (no vignetting to speak of), at each phase of the pattern
    image = formation.sensor(scene, origin, np.random.default_rng(0)).astype(float)
    expected = formation._to_8bit[
        np.rint(
            formation.profile.black_level_dn
            + formation._dn_per_e * formation.electrons_at_white() * np.array([0.6, 0.3, 0.05])
        ).astype(int)
    ]
    centre = image[8:-8, 8:-8].reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(centre, expected, atol=2.0)


@pytest.mark.parametrize("name", ["ov9281", "imx219"])
@pytest.mark.parametrize("height", [4.0, 2.0, 1.0, 0.6, 0.3])
def test_tags_still_decode_at_the_default_heights(name: str, height: float) -> None:
    overrides = {
        "camera.mode": "render",
        "camera.profile": name,
        "simulation.drone_fixed": True,
        "start.height_m": (height, height),
        "start.max_offset_m": 0.0,
    }
    import gymnasium as gym

    env = gym.make("DeckLanding-v2", overrides=overrides)
    env.reset(seed=4)
    seen = 0
    for _ in range(10):
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        seen += bool(env.unwrapped._sensing.frame.detections)
    env.close()
    assert seen >= 9


def test_realistic_images_are_seeded_and_deterministic() -> None:
    import gymnasium as gym

    frames = []
    for _ in range(2):
        env = gym.make(
            "DeckLanding-v2",
            overrides={
                "camera.mode": "render",
                "camera.profile": "imx219",
                "camera.render_region": "full",
            },
        )
        env.reset(seed=11)
        for _ in range(3):
            env.step(np.array([0.3, -0.2, 0.0, 0.0, -1.0], dtype=np.float32))
        frames.append(env.unwrapped._sensing.frame)
        env.close()
    np.testing.assert_array_equal(frames[0].image, frames[1].image)
    assert (
        frames[0].detections[0].corners_px.tolist() == frames[1].detections[0].corners_px.tolist()
    )


def test_unknown_profile_and_bad_settings_are_refused_by_name() -> None:
    with pytest.raises(ConfigError, match="profile"):
        CameraConfig(profile="gopro")
    with pytest.raises(ConfigError, match="exposure_s"):
        CameraConfig(exposure_s=-1.0)
    with pytest.raises(ConfigError, match="sun_direction_w"):
        CameraConfig(sun_direction_w=(0.0, 0.0, 0.0))


def test_an_overhead_sun_glints_on_the_deck_below_the_camera_and_saturates() -> None:
    overrides = {"camera.mode": "render", "camera.profile": "ov9281"}
    images = []
    for sun in (None, (0.0, 0.0, 1.0)):
        w = World(load_config("default", overrides={**overrides, "camera.sun_direction_w": sun}))
        try:
            place(w, Pose(1.5))
            w.camera.motion = _still_deck_motion(w, ZERO)
            images.append(w.camera.render_image(*w.camera_pose_w(), np.random.default_rng(0)))
        finally:
            w.close()
    plain, glare = (img.astype(float).mean(axis=2) for img in images)
    centre = (slice(246, 266), slice(246, 266))
    assert glare[centre].min() >= 250 and plain[centre].mean() < 200
    # the lobe is narrow: the image corners are as without the sun
    assert abs(glare[:40, :40].mean() - plain[:40, :40].mean()) < 3.0
