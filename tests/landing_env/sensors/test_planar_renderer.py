"""Planar renderer: agrees with the reference renderer (TinyRenderer) in corners and pixels."""

from __future__ import annotations

import warnings
from collections.abc import Iterator

import numpy as np
import pybullet as p
import pytest

from estimation.detection import AprilTagDetector
from landing_env.config import load_config
from landing_env.world import World
from tests.renderer_agreement import (
    COMMITTED_REFERENCES,
    HEIGHTS_M,
    Pose,
    committed_reference_of,
    compare,
    corner_norms,
    corner_sets,
    corner_statistics,
    place,
    planar_image,
    render_config,
    render_supersampled,
    standard_poses,
    supersampled_cache_path,
    uses_small_tag,
)


@pytest.fixture(scope="module")
def world() -> Iterator[World]:
    w = World(render_config())
    yield w
    w.close()


@pytest.fixture(scope="module")
def small_tag_world() -> Iterator[World]:
    """A 0.12 m tag: the default 0.30 m tag is larger than the view at 0.3 m."""
    w = World(render_config(small_tag=True))
    yield w
    w.close()


def test_worlds_render_with_the_planar_renderer_by_default(world: World) -> None:
    assert world.camera.active_renderer == "planar"
    bullet = World(load_config("default", overrides={"camera.renderer": "bullet"}))
    try:
        assert bullet.camera.active_renderer == "tiny"
    finally:
        bullet.close()


@pytest.fixture(scope="module")
def tinyrenderer_corners(world: World, small_tag_world: World) -> list[tuple[Pose, dict]]:
    """Corners of the standard poses (every height) by the planar renderer, plain
    TinyRenderer and TinyRenderer x6, with the analytic truth."""
    detector = AprilTagDetector()
    out = []
    for pose in standard_poses():
        chosen = small_tag_world if uses_small_tag(pose) else world
        found = corner_sets(chosen, detector, pose, (("tiny", 1), ("tiny", 6)))
        assert all(c is not None for c in found.values()), f"tag not detected at {pose}"
        out.append((pose, found))
    return out


def test_every_standard_pose_has_its_committed_supersampled_reference_and_no_other(
    world: World, small_tag_world: World
) -> None:
    """The corner tests read the standard poses' TinyRenderer x6 images from the committed
    references, each named by its pose's plain image: a change that moves any plain image
    (the scene, the camera, a pose, the rendering code) leaves a pose without its file."""
    named = set()
    for pose in standard_poses():
        path, _ = committed_reference_of(small_tag_world if uses_small_tag(pose) else world, pose)
        assert path.is_file(), (
            f"no committed TinyRenderer x6 reference for {pose} ({path.name}): "
            "write them again with `python -m tests.renderer_agreement`"
        )
        named.add(path)
    assert set(COMMITTED_REFERENCES.glob("*.npz")) == named


def test_a_committed_supersampled_reference_is_what_tinyrenderer_renders_now(world: World) -> None:
    """One standard pose (tilted drone and deck, off centre) rendered x6 live: its committed
    image is the same to the grey level, so a PyBullet or OpenCV release that renders or
    filters otherwise is caught."""
    pose = standard_poses()[8]
    assert pose.height_m == 1.0 and pose.offset_m != (0.0, 0.0) and pose.deck_rp_deg != (0, 0)
    path, _ = committed_reference_of(world, pose)
    with np.load(path) as stored:
        committed = stored["image"]
    np.testing.assert_array_equal(render_supersampled(world, pose), committed)


def _diffs(results, a: str, b: str, heights=None) -> list[np.ndarray]:
    return [
        found[a] - found[b]
        for pose, found in results
        if heights is None or pose.height_m in heights
    ]


def _magnified(pose: Pose) -> bool:
    """The level pose at 0.3 m: TinyRenderer's point-sampled texels span 1.7 px there."""
    return pose.height_m < 0.5 and pose.drone_rpy_deg == (0.0, 0.0, 0.0)


@pytest.mark.slow
def test_planar_tag_corners_agree_with_supersampled_tinyrenderer_to_a_tenth_of_a_pixel(
    tinyrenderer_corners,
) -> None:
    everything = corner_statistics(_diffs(tinyrenderer_corners, "planar", "tiny x6"))
    assert everything.corners == 4 * len(standard_poses())
    assert everything.mean_px < 0.1  # mean over states at all heights
    assert {pose.height_m for pose, _ in tinyrenderer_corners} == set(HEIGHTS_M)
    for pose, found in tinyrenderer_corners:
        planar = corner_norms(found["planar"] - found["truth"]).mean()
        reference = corner_norms(found["tiny x6"] - found["truth"]).mean()
        if _magnified(pose):
            # the reference's own error dominates: the planar corners are nearer the truth
            assert planar < reference, pose
        else:
            assert corner_norms(found["planar"] - found["tiny x6"]).mean() < 0.1, pose
            assert planar < reference + 0.05, pose


@pytest.mark.slow
def test_planar_renderer_has_no_systematic_offset_from_plain_tinyrenderer(
    world: World, tinyrenderer_corners
) -> None:
    """A half-pixel shift, a row flip or a wrong projection would move every corner alike;
    a focal length, aspect or image-size error would scale the image about its centre."""
    everything = corner_statistics(_diffs(tinyrenderer_corners, "planar", "tiny x1"))
    assert np.all(np.abs(everything.offset_px) < 0.05)
    assert np.all(everything.spread_px > 2.0 * np.abs(everything.offset_px))
    # the scale, where TinyRenderer's texels are not magnified (0.6 m and above): under
    # 0.1 px at 200 px from the centre (measured 0.03; a 1 px error in 512 px gives 0.39)
    above = {h for h in HEIGHTS_M if h >= 0.6}
    diffs = _diffs(tinyrenderer_corners, "planar", "tiny x1", above)
    truths = [f["truth"] for pose, f in tinyrenderer_corners if pose.height_m in above]
    k = world.camera.intrinsics
    scaled = corner_statistics(diffs, truths, (k.cx, k.cy))
    assert abs(scaled.scale) * 200.0 < 0.1, scaled
    for height in HEIGHTS_M:
        at = corner_statistics(_diffs(tinyrenderer_corners, "planar", "tiny x1", {height}))
        assert np.all(np.abs(at.offset_px) < 0.08), (height, at)


@pytest.mark.slow
def test_plain_tinyrenderer_is_off_its_own_supersampled_image_as_much_as_the_planar_one(
    tinyrenderer_corners,
) -> None:
    """Why plain TinyRenderer is not the yardstick: its corners are quantised."""
    planar_vs_plain = corner_statistics(_diffs(tinyrenderer_corners, "planar", "tiny x1"))
    plain_vs_x6 = corner_statistics(_diffs(tinyrenderer_corners, "tiny x1", "tiny x6"))
    assert plain_vs_x6.mean_px > 0.8 * planar_vs_plain.mean_px
    planar_err = corner_statistics(_diffs(tinyrenderer_corners, "planar", "truth"))
    plain_err = corner_statistics(_diffs(tinyrenderer_corners, "tiny x1", "truth"))
    assert plain_err.mean_px > 1.5 * planar_err.mean_px


@pytest.mark.slow
def test_planar_tag_corners_agree_with_egl_opengl_where_it_loads() -> None:
    """OpenGL filters its textures: the planar renderer agrees with its plain output."""
    detector = AprilTagDetector()
    found_all = []
    for tag_size, heights in ((0.30, (4.0, 2.0, 1.0, 0.6)), (0.12, (0.3,))):
        overrides = {"camera.mode": "render", "camera.use_egl": True, "deck.tag_size": tag_size}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            # the EGL plugin draws one scene per process: one EGL world at a time
            w = World(load_config("default", overrides=overrides))
        try:
            if w.camera.renderer != "egl":
                pytest.skip(
                    "PyBullet's EGL renderer plugin did not load here (no EGL driver or GPU, "
                    "or another client of this process holds it); the planar renderer is "
                    "checked against supersampled TinyRenderer only (the tests above)"
                )
            for pose in standard_poses():
                if pose.height_m in heights:
                    found = corner_sets(w, detector, pose, (("egl", 1), ("egl", 6)))
                    assert all(c is not None for c in found.values()), pose
                    found_all.append((pose, found))
        finally:
            w.close()
    for reference in ("egl x1", "egl x6"):
        everything = corner_statistics(_diffs(found_all, "planar", reference))
        assert everything.mean_px < 0.1, reference
        assert np.all(np.abs(everything.offset_px) < 0.03), reference
        for height in HEIGHTS_M:
            at = corner_statistics(_diffs(found_all, "planar", reference, {height}))
            assert at.mean_px < 0.1, (reference, height, at)


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


def test_a_kept_supersampled_reference_is_found_again_only_by_the_same_plain_image(
    tmp_path, monkeypatch
) -> None:
    """The cache of supersampled TinyRenderer images is named by the pose's plain image: a
    one-grey-level change anywhere in it (a moved tag, another texture, another camera) or
    another factor names another file."""
    monkeypatch.setenv("DECK_LANDING_CACHE_DIR", str(tmp_path))
    plain = np.random.default_rng(0).integers(0, 256, (512, 512, 3), dtype=np.uint8)
    path = supersampled_cache_path(plain, 6)
    assert path.parent.parent == tmp_path
    assert supersampled_cache_path(plain.copy(), 6) == path
    changed = plain.copy()
    changed[300, 200, 1] ^= 1
    assert supersampled_cache_path(changed, 6) != path
    assert supersampled_cache_path(plain, 4) != path
