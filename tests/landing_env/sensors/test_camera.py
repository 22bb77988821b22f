"""Camera: rendered detections agree with the analytic projection; project-mode rules."""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pybullet as p
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation

from estimation.detection import AprilTagDetector
from estimation.frames import R_BC, TAG_CORNER_SIGNS, matrix_from_euler_zyx
from landing_env.errors import ConfigError
from landing_env.scene.deck import DeckSurfaceConfig, create_deck_body, tag_pose_w
from landing_env.sensors.camera import CameraSensor, _row_norms
from landing_env.sensors.camera_config import CameraConfig
from landing_env.sensors.camera_render import opengl_projection
from landing_env.sensors.detection_overlay import draw_detections
from landing_env.sensors.tag_view import (
    MISS_BEHIND,
    MISS_DROPOUT,
    MISS_OBLIQUE,
    MISS_OUT_OF_VIEW,
    MISS_SMALL,
)

TAG_SIZE = 0.30
DECK_HOME = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Scene:
    client: int
    deck: int


@dataclass(frozen=True)
class State:
    t_wc: np.ndarray
    r_wc: np.ndarray
    t_wp: np.ndarray
    r_wp: np.ndarray


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Scene]:
    client = p.connect(p.DIRECT)
    ground = p.createVisualShape(
        p.GEOM_BOX,
        halfExtents=[10, 10, 0.01],
        rgbaColor=[0.35, 0.5, 0.3, 1],
        physicsClientId=client,
    )
    p.createMultiBody(0, -1, ground, [0, 0, -0.01], physicsClientId=client)
    cache = tmp_path_factory.mktemp("deck")
    deck = create_deck_body(client, DeckSurfaceConfig(), 5.0, DECK_HOME, [0, 0, 0, 1], cache)
    yield Scene(client, deck)
    p.disconnect(client)


def random_states(count: int, seed: int) -> list[State]:
    """Heights 1-4 m, tag anywhere in the central image, drone tilt <= 15 deg, deck <= 10 deg."""
    rng = np.random.default_rng(seed)
    states = []
    for _ in range(count):
        r_wp = matrix_from_euler_zyx(
            *np.deg2rad(rng.uniform(-10, 10, 2)), rng.uniform(-np.pi, np.pi)
        )
        r_wb = matrix_from_euler_zyx(
            *np.deg2rad(rng.uniform(-15, 15, 2)), rng.uniform(-np.pi, np.pi)
        )
        r_wc = r_wb @ R_BC
        # put the camera so the tag centre is seen along a ray up to ~0.25 off the axis
        ray_c = np.array([*rng.uniform(-0.25, 0.25, 2), 1.0])
        distance = rng.uniform(1.0, 4.0)
        t_wc = DECK_HOME - r_wc @ (distance * ray_c / np.linalg.norm(ray_c))
        states.append(State(t_wc, r_wc, DECK_HOME.copy(), r_wp))
    return states


def capture(scene: Scene, camera: CameraSensor, state: State, tag_id: int = 0):
    quat = Rotation.from_matrix(state.r_wp).as_quat()
    p.resetBasePositionAndOrientation(scene.deck, state.t_wp, quat, physicsClientId=scene.client)
    t_wd, r_wd = tag_pose_w(state.t_wp, state.r_wp)
    return camera.capture(0.0, state.t_wc, state.r_wc, t_wd, r_wd, TAG_SIZE, tag_id)


@pytest.mark.parametrize("k1", [0.0, -0.05])
def test_render_matches_project(scene: Scene, k1: float) -> None:
    render = CameraSensor(
        scene.client, CameraConfig(mode="render", k1=k1), np.random.default_rng(0)
    )
    project = CameraSensor(
        scene.client, CameraConfig(mode="project", k1=k1), np.random.default_rng(0)
    )
    errors = []
    render_s, project_s = [], []
    for state in random_states(10, seed=7):
        start = time.perf_counter()
        rendered = capture(scene, render, state)
        render_s.append(time.perf_counter() - start)
        start = time.perf_counter()
        projected = capture(scene, project, state)
        project_s.append(time.perf_counter() - start)
        assert projected.miss_reason == ""
        assert rendered.miss_reason == "", rendered.miss_reason
        corners_r = rendered.detections[0].corners_px
        corners_p = projected.detections[0].corners_px
        errors.append(np.linalg.norm(corners_r - corners_p, axis=1))
    errors = np.asarray(errors)
    print(
        f"\nk1={k1}: corner error mean {errors.mean():.3f} px, max {errors.max():.3f} px; "
        f"render+detect {1e3 * np.median(render_s):.1f} ms, "
        f"project {1e3 * np.median(project_s):.3f} ms (medians)"
    )
    # the same corner order: each rendered corner is nearest its own projected corner
    assert errors.max() < 1.0


def test_tag_window_render_equals_full_render(scene: Scene) -> None:
    state = random_states(1, seed=3)[0]
    full = CameraSensor(
        scene.client, CameraConfig(mode="render", render_region="full"), np.random.default_rng(0)
    )
    window = CameraSensor(scene.client, CameraConfig(mode="render"), np.random.default_rng(0))
    frame_full = capture(scene, full, state)
    frame_window = capture(scene, window, state)
    np.testing.assert_allclose(
        frame_full.detections[0].corners_px, frame_window.detections[0].corners_px, atol=0.02
    )
    # the window's pixels are the full render's pixels
    painted = np.any(frame_window.image != 127, axis=2)
    rows, cols = np.nonzero(painted)
    block = (slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1))
    np.testing.assert_array_equal(frame_window.image[block], frame_full.image[block])


def test_render_reports_other_tag_ids_as_not_detected(scene: Scene) -> None:
    camera = CameraSensor(scene.client, CameraConfig(mode="render"), np.random.default_rng(0))
    frame = capture(scene, camera, random_states(1, seed=5)[0], tag_id=4)
    assert frame.detections == ()
    assert frame.miss_reason == "not_detected"


def test_opengl_projection_maps_principal_point_to_image_centre() -> None:
    projection = opengl_projection(400.0, 400.0, 99.5, 49.5, 200, 100, 0.1, 10.0)
    point = np.array([0.0, 0.0, -2.0, 1.0])  # on the optical axis, OpenGL eye coordinates
    clip = projection @ point
    np.testing.assert_allclose(clip[:2] / clip[3], [0.0, 0.0], atol=1e-12)
    # one focal length off the axis at unit depth lands fx pixels right of the centre
    clip = projection @ np.array([1.0, 0.0, -1.0, 1.0])
    u = (clip[0] / clip[3] + 1.0) * 200 / 2 - 0.5
    assert u == pytest.approx(99.5 + 400.0)


def level_view(height: float = 2.0, offset=(0.0, 0.0)) -> State:
    t_wc = DECK_HOME + np.array([offset[0], offset[1], height])
    return State(t_wc, R_BC.copy(), DECK_HOME.copy(), np.eye(3))


def project_frame(config: CameraConfig, state: State, seed: int = 0):
    camera = CameraSensor(-1, config, np.random.default_rng(seed))
    t_wd, r_wd = tag_pose_w(state.t_wp, state.r_wp)
    return camera.capture(1.5, state.t_wc, state.r_wc, t_wd, r_wd, TAG_SIZE, 0)


def test_project_level_view_is_centred_and_ordered() -> None:
    frame = project_frame(CameraConfig(), level_view(2.0))
    assert frame.timestamp == 1.5 and frame.miss_reason == ""
    corners = frame.detections[0].corners_px
    centre = corners.mean(axis=0)
    np.testing.assert_allclose(centre, [255.5, 255.5], atol=1e-9)
    # R_CD = I: corner i lies at TAG_CORNER_SIGNS[i] * half-size * f / z from the centre
    expected = TAG_CORNER_SIGNS * 0.15 / 2.0 * np.array([458.5, 457.855])
    np.testing.assert_allclose(corners - centre, expected, atol=1e-9)


def test_project_visibility_rules() -> None:
    config = CameraConfig()
    # camera below the deck, looking down: the tag is behind it
    assert project_frame(config, level_view(-0.5)).miss_reason == MISS_BEHIND
    # far off to the side
    assert project_frame(config, level_view(2.0, (1.5, 0.0))).miss_reason == MISS_OUT_OF_VIEW
    # right-hand corners moved to 1 px from the image edge: in view, but inside the margin
    edge = level_view(2.0)
    corner_x = 255.5 + 458.5 * 0.15 / 2.0
    shift_m = (511.5 - 1.0 - corner_x) * 2.0 / 458.5
    # moving the camera along -x_C moves the tag towards +u
    shifted = State(edge.t_wc - edge.r_wc[:, 0] * shift_m, edge.r_wc, edge.t_wp, edge.r_wp)
    assert project_frame(CameraConfig(edge_margin_px=0.0), shifted).miss_reason == ""
    assert project_frame(CameraConfig(edge_margin_px=2.0), shifted).miss_reason == MISS_OUT_OF_VIEW
    # seen at 80 degrees off its normal
    angle = np.deg2rad(80.0)
    look = Rotation.from_rotvec([0.0, angle, 0.0]).as_matrix()  # tilt the view about y_W
    r_wc = look @ R_BC
    t_wc = DECK_HOME - r_wc @ np.array([0.0, 0.0, 2.0])
    oblique = State(t_wc, r_wc, DECK_HOME.copy(), np.eye(3))
    assert project_frame(config, oblique).miss_reason == MISS_OBLIQUE
    assert project_frame(CameraConfig(max_view_angle_deg=85.0), oblique).miss_reason == ""
    # 0.3 m at 15 m is ~9 px
    assert project_frame(config, level_view(15.0)).miss_reason == MISS_SMALL
    assert project_frame(CameraConfig(min_tag_side_px=5.0), level_view(15.0)).miss_reason == ""


def test_dropouts_occur_at_the_configured_rate() -> None:
    camera = CameraSensor(-1, CameraConfig(dropout_prob=0.3), np.random.default_rng(11))
    state = level_view(2.0)
    t_wd, r_wd = tag_pose_w(state.t_wp, state.r_wp)
    n = 4000
    drops = sum(
        camera.capture(i, state.t_wc, state.r_wc, t_wd, r_wd, TAG_SIZE, 0).miss_reason
        == MISS_DROPOUT
        for i in range(n)
    )
    assert abs(drops / n - 0.3) < 4.0 * np.sqrt(0.3 * 0.7 / n)


def test_pixel_noise_is_seeded_and_has_the_configured_std() -> None:
    config = CameraConfig(pixel_noise_px=0.7)
    state = level_view(2.0)
    t_wd, r_wd = tag_pose_w(state.t_wp, state.r_wp)
    clean = project_frame(CameraConfig(), state).detections[0].corners_px

    def run(seed: int) -> np.ndarray:
        camera = CameraSensor(-1, config, np.random.default_rng(seed))
        return np.array(
            [
                camera.capture(i, state.t_wc, state.r_wc, t_wd, r_wd, TAG_SIZE, 0)
                .detections[0]
                .corners_px
                for i in range(1500)
            ]
        )

    first, second, other = run(3), run(3), run(4)
    np.testing.assert_array_equal(first, second)
    assert not np.array_equal(first, other)
    residual = first - clean
    assert np.std(residual) == pytest.approx(0.7, rel=0.05)
    assert abs(np.mean(residual)) < 0.05


def test_draw_detections_marks_the_corners() -> None:
    frame = project_frame(CameraConfig(), level_view(2.0))
    image = np.zeros((512, 512, 3), dtype=np.uint8)
    drawn = draw_detections(image, frame)
    assert drawn.shape == image.shape and not image.any()
    for u, v in np.rint(frame.detections[0].corners_px).astype(int):
        assert drawn[v - 6 : v + 7, u - 6 : u + 7].any()
    assert not drawn[:100, :100].any()  # nothing far from the tag


def test_config_errors_name_the_field() -> None:
    with pytest.raises(ConfigError) as info:
        CameraConfig(mode="raytrace")  # type: ignore[arg-type]
    assert info.value.key == "mode" and "'render'" in str(info.value)
    with pytest.raises(ConfigError) as info:
        CameraConfig(dropout_prob=1.5)
    assert info.value.key == "dropout_prob"
    with pytest.raises(ConfigError) as info:
        CameraConfig(near=1.0, far=0.5)
    assert info.value.key == "far"


def test_detector_shifts_pupil_corners_to_opencv_pixels() -> None:
    # a tag whose black border spans pixel columns/rows 100..299 has edges at 99.5 and 299.5
    from landing_env.scene.deck import opencv_tag_bits

    bits = np.kron(opencv_tag_bits(0), np.ones((25, 25)))
    image = np.full((400, 400), 255, dtype=np.uint8)
    image[100:300, 100:300] = (bits * 255).astype(np.uint8)
    corners = AprilTagDetector().detect(image)[0].corners_px
    expected = 199.5 + 100.0 * TAG_CORNER_SIGNS
    np.testing.assert_allclose(corners, expected, atol=0.3)


@pytest.mark.slow
def test_egl_render_matches_project_or_falls_back(tmp_path) -> None:
    client = p.connect(p.DIRECT)
    try:
        # the EGL plugin only draws bodies created after it is loaded: camera first
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            camera = CameraSensor(
                client, CameraConfig(mode="render", use_egl=True), np.random.default_rng(0)
            )
        deck = create_deck_body(client, DeckSurfaceConfig(), 5.0, DECK_HOME, [0, 0, 0, 1], tmp_path)
        scene = Scene(client, deck)
        project = CameraSensor(client, CameraConfig(), np.random.default_rng(0))
        for state in random_states(3, seed=21):
            rendered = capture(scene, camera, state)
            projected = capture(scene, project, state)
            error = rendered.detections[0].corners_px - projected.detections[0].corners_px
            assert np.abs(error).max() < 1.0, camera.renderer
        camera.close()
        assert camera.renderer == "tiny"
    finally:
        p.disconnect(client)


def test_annotated_image_works_in_project_mode(scene: Scene) -> None:
    from pybullet_utils.bullet_client import BulletClient

    assert isinstance(scene.client, int) and not isinstance(scene.client, BulletClient)
    camera = CameraSensor(scene.client, CameraConfig(mode="project"), np.random.default_rng(0))
    state = random_states(1, seed=2)[0]
    frame = capture(scene, camera, state)
    plain = camera.render_image(state.t_wc, state.r_wc)
    annotated = camera.annotated_image(frame, state.t_wc, state.r_wc)
    assert annotated.shape == (512, 512, 3) and frame.image is None
    changed = np.any(annotated != plain, axis=2)
    u, v = np.rint(frame.detections[0].corners_px[0]).astype(int)
    assert changed[v - 5 : v + 6, u - 5 : u + 6].any()


def test_detectors_can_be_created_and_freed_repeatedly() -> None:
    # pupil-apriltags' own destructor frees in the wrong order; the wrapper must not crash
    image = np.zeros((64, 64), dtype=np.uint8)
    for _ in range(30):
        detector = AprilTagDetector()
        assert detector.detect(image) == ()
        del detector
    closed = AprilTagDetector()
    closed.close()
    closed.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        closed.detect(image)


@settings(max_examples=200, deadline=None)
@given(
    hnp.arrays(
        np.float64,
        hnp.array_shapes(min_dims=2, max_dims=2, min_side=0, max_side=6),
        elements=st.floats(allow_nan=True, allow_infinity=True),
    )
)
def test_the_projection_s_row_norms_are_numpy_s_bit_for_bit(rows: np.ndarray) -> None:
    with np.errstate(all="ignore"):
        assert _row_norms(rows).tobytes() == np.linalg.norm(rows, axis=1).tobytes()
        for row in rows:
            # the view angle's ray length: the norm's dot product and square root
            expected, got = float(np.linalg.norm(row)), math.sqrt(float(row.dot(row)))
            assert got == expected or (math.isnan(got) and math.isnan(expected))
