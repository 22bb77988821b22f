"""Planar renderer: agrees with the reference renderer (TinyRenderer) in corners and pixels."""

from __future__ import annotations

import warnings
from collections.abc import Iterator

import numpy as np
import pybullet as p
import pytest

from estimation.detection import AprilTagDetector
from landing_env.config import load_config
from landing_env.sensors.renderer_agreement import (
    Pose,
    compare,
    corner_norms,
    place,
    planar_image,
)
from landing_env.world import World


@pytest.fixture(scope="module")
def world() -> Iterator[World]:
    w = World(load_config("default", overrides={"camera.mode": "render"}))
    yield w
    w.close()


@pytest.fixture(scope="module")
def small_tag_world() -> Iterator[World]:
    """A 0.12 m tag: the default 0.30 m tag is larger than the view at 0.3 m."""
    w = World(load_config("default", overrides={"camera.mode": "render", "deck.tag_size": 0.12}))
    yield w
    w.close()


def test_worlds_render_with_the_planar_renderer_by_default(world: World) -> None:
    assert world.camera.active_renderer == "planar"
    bullet = World(load_config("default", overrides={"camera.renderer": "bullet"}))
    try:
        assert bullet.camera.active_renderer == "tiny"
    finally:
        bullet.close()


@pytest.mark.parametrize(
    "pose",
    [
        Pose(4.0, (2.4, -4.0, 20.0), (4.0, -3.0)),
        Pose(2.0, (-4.0, 1.6, -35.0), (-5.0, 2.0), (0.04, 0.0)),
        Pose(1.0, (2.4, -4.0, 20.0), (4.0, -3.0)),
        Pose(0.6, (-4.0, 1.6, -35.0), (-5.0, 2.0)),
        Pose(0.6),
        Pose(0.3, (2.0, -3.0, 20.0), (4.0, -3.0)),
    ],
    ids=lambda pose: f"{pose.height_m}m",
)
def test_planar_tag_corners_agree_with_supersampled_tinyrenderer_to_a_tenth_of_a_pixel(
    world: World, small_tag_world: World, pose: Pose
) -> None:
    chosen = small_tag_world if pose.height_m < 0.5 else world
    result = compare(chosen, AprilTagDetector(), pose, supersample=6)
    assert result.corner_diff_px is not None, "the tag was not detected in both images"
    assert corner_norms(result.corner_diff_px).mean() < 0.1
    # and the planar corners are no further from the analytic ones than the reference's
    planar = corner_norms(result.corner_error_planar_px).mean()
    reference = corner_norms(result.corner_error_reference_px).mean()
    assert planar < reference + 0.05


@pytest.mark.parametrize("height", [4.0, 1.0, 0.3])
def test_planar_image_matches_tinyrenderer_but_for_edge_pixels(world: World, height: float) -> None:
    """Same colours (within a grey level on average); only edge pixels differ (aliasing)."""
    result = compare(world, AprilTagDetector(), Pose(height, (3.0, -2.0, 10.0), (3.0, 2.0)), 1)
    assert result.mean_abs_grey < 1.5
    assert result.far_fraction < 0.02


def test_a_window_render_is_the_full_render_cropped_to_a_grey_level(world: World) -> None:
    place(world, Pose(1.0, (3.0, -2.0, 10.0), (3.0, 2.0)))
    full = planar_image(world)
    t_wc, r_wc = world.camera_pose_w()
    window = (100, 120, 300, 260)
    part = world.camera._render_canvas(t_wc, r_wc, window)
    # OpenCV's fixed-point warp rounds by absolute position: a grey level at most
    diff = np.abs(part.astype(int) - full[120:260, 100:300].astype(int))
    assert diff.max() <= 1 and diff.mean() < 0.05


def test_an_unknown_shape_makes_the_world_fall_back_to_the_reference_renderer() -> None:
    config = load_config("default", overrides={"camera.mode": "render"})
    w = World(config)
    try:
        mesh = p.createVisualShape(p.GEOM_SPHERE, radius=0.1, physicsClientId=w.client._client)
        p.createMultiBody(0.0, -1, mesh, [2.0, 0.0, 0.5], physicsClientId=w.client._client)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            image = w.render_camera_image()
        assert image.shape == (512, 512, 3)
        assert w.camera.active_renderer == "tiny"
        assert any("planar renderer" in str(c.message) for c in caught)
    finally:
        w.close()
