"""``project`` mode's corner noise, fitted to what render-and-detect gives under a camera profile.

Render-and-detect errors (detected minus analytic corners, pixels) are measured over random
states: drone 0.8-4 m above the deck, tilted up to 8 degrees, any yaw, the deck tilted up to
5 degrees, the camera moving at up to ~1 m/s and 20 deg/s and the deck at ~0.1 m/s, so that
blur spans 0 to ~10 px.  A detected corner's error per axis is modelled as zero-mean
Gaussian with

    sigma^2 = base_px^2 + size_px2 / side_px + (blur_frac * blur_px)^2 + (side2_coef * side_px^2)^2

(an edge fit's noise falls with the edge's length in pixels; blur widens the edges and
smears them along the motion; a large tag's edges are curved by the lens distortion, which
the detector's straight-line fit does not follow: an error growing with the side squared).
``side_px`` is the tag's shortest side and ``blur_px`` how far the tag centre moves during
the exposure (:meth:`ImageFormation.blur_length_px`).  The coefficients are least squares
(non-negative) on the squared errors; ``python -m benchmarks.bench_corner_noise`` prints
them and the comparison of the two error distributions.  Measured under the realistic
camera (OV9281 profile with its Bayer mosaic, k1 = -0.05; 1500 states, seed 0):
``(0.137, 2.147, 0.114, 0)``: the image noise dominates (0.25 px for a 50 px tag) and each
pixel of blur adds about 0.1 px.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls
from scipy.spatial.transform import Rotation

from estimation.frames import matrix_from_euler_zyx
from landing_env.sensors.camera_realism import RelativeMotion


@dataclass(frozen=True)
class CornerSamples:
    """Per detected frame: corner errors (N x 4 x 2, px), tag side (px), blur (px)."""

    errors_px: np.ndarray
    side_px: np.ndarray
    blur_px: np.ndarray
    #: frames in which the tag was in view but not detected
    missed: int


def sigma_px(
    coefficients: tuple[float, float, float, float], side_px: np.ndarray, blur_px: np.ndarray
) -> np.ndarray:
    """The model's per-axis sigma (pixels); coefficients (base, size, blur, side2)."""
    base, size, blur, side2 = coefficients
    side = np.maximum(np.asarray(side_px, dtype=float), 1.0)
    blur_px = np.asarray(blur_px, dtype=float)
    return np.sqrt(base**2 + size / side + (blur * blur_px) ** 2 + (side2 * side**2) ** 2)


def random_motion(world, rng: np.random.Generator):
    """A random camera and deck motion for :func:`measure_corner_errors`."""

    deck = world.deck_state()
    return RelativeMotion(
        rng.normal(0.0, 1.0, 3),
        np.deg2rad(rng.normal(0.0, 30.0, 3)),
        deck.position_w,
        deck.rotation_wp,
        rng.normal(0.0, 0.05, 3),
        np.deg2rad(rng.normal(0.0, 3.0, 3)),
    )


def place_random(world, rng: np.random.Generator) -> None:
    """Drone and deck in a random state with the tag in view (see the module docstring)."""
    c = world.client
    home = world.deck_home_w
    r_wp = matrix_from_euler_zyx(*np.deg2rad(rng.uniform(-5.0, 5.0, 2)), 0.0)
    c.resetBasePositionAndOrientation(
        world.deck_id, home.tolist(), Rotation.from_matrix(r_wp).as_quat().tolist()
    )
    world.stewart.update_leg_visuals()
    height = rng.uniform(0.6, 4.0)
    r_wb = matrix_from_euler_zyx(*np.deg2rad(rng.uniform(-8.0, 8.0, 2)), rng.uniform(-np.pi, np.pi))
    offset = rng.uniform(-0.1, 0.1, 2) * height
    position = home + np.array([*offset, height])
    c.resetBasePositionAndOrientation(
        world.drone.body_id, position.tolist(), Rotation.from_matrix(r_wb).as_quat().tolist()
    )
    world._state = world.drone.read_state()


def measure_corner_errors(world, count: int, rng: np.random.Generator) -> CornerSamples:
    """Corner errors over ``count`` random states: rendered and detected (render mode) or
    the projected corners with their noise (project mode)."""
    camera = world.camera
    if camera.formation is None:
        raise ValueError("needs a camera with a profile other than 'ideal'")
    size = world.config.deck.layout.landmarks[0].size
    errors, sides, blurs = [], [], []
    missed = 0
    for _ in range(count):
        place_random(world, rng)
        motion = random_motion(world, rng)
        t_wc, r_wc = world.camera_pose_w()
        deck = world.deck_state()
        view = camera.project_tag(t_wc, r_wc, deck.tag_centre_w, deck.rotation_wd, size)
        if view.miss_reason:
            continue
        camera.motion = motion
        world._drone_visible(False)
        try:
            frame = world._capture(t_wc, r_wc, deck)
        finally:
            world._drone_visible(True)
        if not frame.detections:
            missed += 1
            continue
        ideal_centre = camera.intrinsics.project(view.corners_c.mean(axis=0)[None], distort=False)[
            0
        ]
        errors.append(frame.detections[0].corners_px - view.corners_px)
        sides.append(view.min_side_px)
        blurs.append(camera.formation.blur_length_px(t_wc, r_wc, motion, tuple(ideal_centre)))
    return CornerSamples(np.array(errors), np.array(sides), np.array(blurs), missed)


def fit_corner_noise(samples: CornerSamples) -> tuple[float, float, float, float]:
    """Non-negative least squares of the squared errors on (1, 1/side, blur^2, side^4)."""
    squared = (samples.errors_px**2).reshape(len(samples.side_px), -1)  # 8 per frame
    side = samples.side_px
    design = np.column_stack([np.ones_like(side), 1.0 / side, samples.blur_px**2, side**4])
    design = np.repeat(design, squared.shape[1], axis=0)
    solution, _ = nnls(design, squared.reshape(-1))
    return (
        float(np.sqrt(solution[0])),
        float(solution[1]),
        float(np.sqrt(solution[2])),
        float(np.sqrt(solution[3])),
    )
