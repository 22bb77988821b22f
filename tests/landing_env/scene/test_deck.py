"""Deck texture (tag orientation, pads) and the deck body."""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np
import pybullet as p
import pytest

from estimation.detection import AprilTagDetector
from estimation.frames import R_BC, TAG_CORNER_SIGNS
from landing_env.errors import ConfigError
from landing_env.scene.deck import (
    PAD_NAMES,
    DeckSurfaceConfig,
    create_deck_body,
    deck_asset_files,
    make_deck_texture,
    plate_to_texel,
    tag_corners_p,
    tag_corners_w,
    tag_pose_w,
)
from landing_env.sensors.camera import CameraSensor
from landing_env.sensors.camera_config import CameraConfig

#: IHRCF Table 1: (Y, Cb, Cr) inclusive ranges of each pad colour.
TABLE_1 = {
    "blue": ((0, 165), (139, 255), (0, 255)),
    "green": ((0, 255), (0, 155), (0, 90)),
    "yellow": ((103, 255), (0, 95), (0, 255)),
    "red": ((0, 160), (0, 255), (167, 255)),
}


def table_1_mask(rgb: np.ndarray, colour: str) -> np.ndarray:
    """Pixels passing a Table 1 threshold; OpenCV orders the channels Y, Cr, Cb."""
    ycrcb = cv2.cvtColor(rgb, cv2.COLOR_RGB2YCrCb).astype(int)
    y, cr, cb = ycrcb[..., 0], ycrcb[..., 1], ycrcb[..., 2]
    (y0, y1), (cb0, cb1), (cr0, cr1) = TABLE_1[colour]
    return (y >= y0) & (y <= y1) & (cb >= cb0) & (cb <= cb1) & (cr >= cr0) & (cr <= cr1)


@pytest.fixture(scope="module")
def client() -> Iterator[int]:
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


@pytest.mark.parametrize("tag_id", [0, 17, 586])
def test_texture_tag_decodes_in_frame_order(tag_id: int) -> None:
    config = DeckSurfaceConfig(tag_id=tag_id)
    texture = make_deck_texture(config)
    detections = AprilTagDetector().detect(texture)
    assert [d.tag_id for d in detections] == [tag_id]
    # the texture is the deck seen from above, bow up: its corners must be the tag-frame
    # corners mapped through R_PD, in TAG_CORNER_SIGNS order
    expected = plate_to_texel(config, tag_corners_p(config.tag_size)[:, :2])
    error = np.linalg.norm(detections[0].corners_px - expected, axis=1)
    assert error.max() < 0.5  # texels (1 mm each)
    # corner 0 is bottom-left in the image (x_D = -1, y_D = +1 with y down)
    signs = np.sign(detections[0].corners_px - expected.mean(axis=0))
    np.testing.assert_array_equal(signs, TAG_CORNER_SIGNS)


def test_tag_corners_in_plate_frame() -> None:
    corners = tag_corners_p(0.3)
    # corner 0 (x_D = -h, y_D = +h) is aft (x_P = -h) and to port (y_P = +h)
    np.testing.assert_allclose(corners[0], [-0.15, 0.15, 0.0])
    np.testing.assert_allclose(corners[2], [0.15, -0.15, 0.0])


def test_world_corners_and_tag_pose_follow_the_plate() -> None:
    r_wp = cv2.Rodrigues(np.array([0.1, -0.05, 0.7]))[0]
    t_wp = np.array([1.0, 2.0, 0.5])
    t_wd, r_wd = tag_pose_w(t_wp, r_wp)
    np.testing.assert_allclose(r_wd, r_wp @ R_BC)
    corners_w = tag_corners_w(0.3, t_wp, r_wp)
    # the same corners seen from the tag frame are the tag-frame corners
    corners_d = (r_wd.T @ (corners_w - t_wd).T).T
    np.testing.assert_allclose(corners_d[:, :2], 0.15 * TAG_CORNER_SIGNS, atol=1e-12)
    np.testing.assert_allclose(corners_d[:, 2], 0.0, atol=1e-12)


def test_pads_pass_only_their_own_table_1_thresholds() -> None:
    config = DeckSurfaceConfig(pads=True, tag=False)
    texture = make_deck_texture(config)
    centres = plate_to_texel(config, np.asarray(config.pad_centres))
    radius = 0.8 * config.pad_radius / config.metres_per_texel
    rows, cols = np.mgrid[: texture.shape[0], : texture.shape[1]]
    masks = {name: table_1_mask(texture, name) for name in TABLE_1}
    for name, (u, v) in zip(PAD_NAMES, centres, strict=True):
        disc = (cols - u) ** 2 + (rows - v) ** 2 <= radius**2
        for other, mask in masks.items():
            if other == name:
                assert mask[disc].all(), f"{name} pad fails its own thresholds"
            else:
                assert not mask[disc].any(), f"{name} pad passes the {other} thresholds"
    # the plate itself is none of the pad colours
    plate = np.ones(texture.shape[:2], dtype=bool)
    for u, v in centres:
        plate &= (cols - u) ** 2 + (rows - v) ** 2 > (1.2 * radius / 0.8) ** 2
    for name, mask in masks.items():
        assert not mask[plate].any(), f"the plate passes the {name} thresholds"


def test_pads_default_to_tof_touch_points() -> None:
    config = DeckSurfaceConfig(pads=True)
    # sensor 1 sits at (-dx, -dy) in C: with R_CD = I its touch point is (dy, dx) in P
    d = 0.1 * np.cos(np.deg2rad(45.0))
    expected = [(d, d), (d, -d), (-d, -d), (-d, d)]
    np.testing.assert_allclose(np.asarray(config.pad_centres), expected, atol=1e-12)


def test_config_errors_name_the_field() -> None:
    with pytest.raises(ConfigError) as info:
        DeckSurfaceConfig(tag_size=0.9)
    assert info.value.key == "tag_size"
    with pytest.raises(ConfigError) as info:
        DeckSurfaceConfig(tag_family="tag25h9")
    assert info.value.key == "tag_family"
    assert "tag36h11" in str(info.value)
    with pytest.raises(ConfigError) as info:
        DeckSurfaceConfig(pad_centres_p=((0.0, 0.0),))
    assert info.value.key == "pad_centres_p"


def test_assets_are_cached_per_config(tmp_path) -> None:
    first = deck_asset_files(DeckSurfaceConfig(texture_px=64), tmp_path)
    again = deck_asset_files(DeckSurfaceConfig(texture_px=64), tmp_path)
    other = deck_asset_files(DeckSurfaceConfig(texture_px=64, tag_id=3), tmp_path)
    assert first == again
    assert first[1] != other[1]
    assert all(path.is_file() for path in (*first, *other))


def test_body_frame_is_top_surface_centre(client: int, tmp_path) -> None:
    config = DeckSurfaceConfig(texture_px=128)
    position = np.array([0.3, -0.2, 1.25])
    body = create_deck_body(client, config, 4.0, position, [0, 0, 0, 1], cache_dir=tmp_path)
    try:
        assert p.getDynamicsInfo(body, -1, physicsClientId=client)[0] == pytest.approx(4.0)
        top = p.rayTest([0.3, -0.2, 3.0], [0.3, -0.2, 0.0], physicsClientId=client)[0]
        bottom = p.rayTest([0.3, -0.2, -1.0], [0.3, -0.2, 1.24], physicsClientId=client)[0]
        assert top[0] == body
        assert top[3][2] == pytest.approx(1.25, abs=1e-6)
        assert bottom[3][2] == pytest.approx(1.25 - config.thickness, abs=1e-6)
        pos, _ = p.getBasePositionAndOrientation(body, physicsClientId=client)
        np.testing.assert_allclose(pos, position, atol=1e-9)
    finally:
        p.removeBody(body, physicsClientId=client)


def test_rendered_pads_segment_at_the_touch_points(client: int, tmp_path) -> None:
    """Lit and rendered, each pad still passes its threshold and sits where it should."""
    config = DeckSurfaceConfig(pads=True, tag=False)
    t_wp = np.array([0.0, 0.0, 0.5])
    body = create_deck_body(client, config, 4.0, t_wp, [0, 0, 0, 1], cache_dir=tmp_path)
    try:
        camera = CameraSensor(client, CameraConfig(mode="project"), np.random.default_rng(0))
        t_wc = np.array([0.0, 0.0, 1.5])  # a level, zero-yaw drone 1 m above the deck
        image = camera.render_image(t_wc, R_BC)
        for name, (x, y) in zip(PAD_NAMES, config.pad_centres, strict=True):
            mask = table_1_mask(image, name)
            assert mask.sum() > 50, f"{name} pad not segmented"
            centroid = np.argwhere(mask).mean(axis=0)[::-1]
            point_w = t_wp + np.array([x, y, 0.0])
            expected = camera.intrinsics.project((R_BC.T @ (point_w - t_wc))[None])[0]
            assert np.linalg.norm(centroid - expected) < 1.0
    finally:
        p.removeBody(body, physicsClientId=client)
