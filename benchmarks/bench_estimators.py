"""Per-frame cost of the deck-pose estimators and of AprilTag detection (prints a table).

    .venv/bin/python benchmarks/bench_estimators.py [--frames 3000] [--detect-frames 100]

Estimators run without detection, on synthetic corners and ranges
(:mod:`estimation.synthetic`) of random deck poses (camera 0.5–4 m above the deck, deck
tilted up to 15°, tag anywhere in the central image), built as the environment builds them:
the shipped calibration files (``configs/calibration/``), PCHIP look-up.  The shipped
intrinsics carry the small distortion the chessboard calibration estimated, so IHRCF and
CRHF undistort their pixels as in the environment; the "ideal lens" rows give the same
estimators a distortion-free camera model (no undistortion step).  ``+kf`` rows wrap the
estimator in the corner Kalman tracker.

Detection is pupil-apriltags on a rendered 512 x 512 frame of the default deck 2 m below the
camera: the whole image at quad_decimate 1 and 2, and the window round the tag that the
environment's default ``camera.render_region = "tag"`` searches.
Timings are per call, in microseconds of the thread's CPU time: median and 90th percentile.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from rich.console import Console
from rich.table import Table

from estimation.camera_model import CameraIntrinsics
from estimation.detection import AprilTagDetector
from estimation.frames import matrix_from_euler_zyx
from estimation.registry import make_estimator
from estimation.synthetic import SyntheticMeasurement, SyntheticScene
from estimation.tight_config import TightConfig
from estimation.tracking import CornerTracker, TrackedEstimator
from landing_env.config import load_config
from landing_env.estimators import load_intrinsics, load_tag_corner_fit, load_tof_calibration


def synthetic_frames(
    count: int, intrinsics: CameraIntrinsics, tag_size: float, rng: np.random.Generator
) -> list[SyntheticMeasurement]:
    """``count`` measurable frames of random deck poses (noise 0.2 px, 2 mm)."""
    scene = SyntheticScene(intrinsics, tag_size, max_range_m=4.0)
    frames: list[SyntheticMeasurement] = []
    while len(frames) < count:
        rotation = matrix_from_euler_zyx(
            *np.radians(rng.uniform(-15.0, 15.0, 2)), rng.uniform(-np.pi, np.pi)
        )
        depth = rng.uniform(0.5, 4.0)
        translation = np.array([*(rng.uniform(-0.2, 0.2, 2) * depth), depth])
        measurement = scene.measure(
            rotation, translation, pixel_noise_px=0.2, range_noise_m=0.002, rng=rng
        )
        if measurement.frame.detections and np.all(measurement.ranges.valid):
            frames.append(measurement)
    return frames


def time_calls(call: Callable[[int], object], count: int) -> np.ndarray:
    """Time of ``call(i)`` for i < count, microseconds (after a short warm-up): CPU time of
    this process (``time.thread_time``), which other processes on a shared machine inflate
    far less than wall time."""
    for i in range(min(count, 50)):
        call(i)
    times = np.empty(count)
    for i in range(count):
        start = time.thread_time_ns()
        call(i)
        times[i] = (time.thread_time_ns() - start) * 1e-3
    return times


def estimator_rows(frames_n: int, rng: np.random.Generator) -> list[tuple[str, np.ndarray, str]]:
    config = load_config("default")
    calibrated = load_intrinsics(config)
    ideal = config.camera.intrinsics
    tof = load_tof_calibration(config)
    tag_size = config.deck.tag_size
    frames = synthetic_frames(frames_n, ideal, tag_size, rng)
    # tight as `realistic` runs it: the tag detector's corner offset (and noise) that the
    # realistic camera's intrinsics file measured, removed from every frame's corners
    realistic = load_config("realistic")
    corner_fit = load_tag_corner_fit(realistic)
    with_offset = TightConfig()
    if corner_fit is not None:
        bias = corner_fit.bias
        with_offset = TightConfig(
            pixel_sigma_px=corner_fit.sigma_px, corner_bias_px=(bias.a_px, bias.b_px, bias.c_px2)
        )
    rows = []
    variants: list[tuple] = [
        ("atda", calibrated, False, ""),
        ("ihrcf", calibrated, False, ""),
        ("crhf", calibrated, False, ""),
        ("tight", calibrated, False, ""),
        ("tight", calibrated, False, "corner offset removed (realistic calibration)", with_offset),
        ("ihrcf", ideal, False, "ideal lens"),
        ("crhf", ideal, False, "ideal lens"),
        ("atda", calibrated, True, ""),
        ("ihrcf", calibrated, True, ""),
        ("crhf", calibrated, True, ""),
        ("tight", calibrated, True, ""),
    ]
    for name, intrinsics, tracked, note, *settings in variants:
        estimator = make_estimator(
            name,
            intrinsics=intrinsics,
            tag_size=tag_size,
            tof_calibration=tof if name != "atda" else None,
            config=settings[0] if settings else None,
        )
        if tracked:
            estimator = TrackedEstimator(estimator, CornerTracker(dt=0.05))
        valid = []

        def call(i: int, estimator=estimator, valid=valid) -> None:
            m = frames[i % len(frames)]
            valid.append(estimator.estimate(m.frame, m.ranges).valid)

        times = time_calls(call, frames_n)
        label = name + ("+kf" if tracked else "")
        rows.append((label, times, f"{note}{'; ' if note else ''}{np.mean(valid):.0%} valid"))
    return rows


def refinement_rows(frames_n: int, rng: np.random.Generator) -> list[tuple[str, np.ndarray, str]]:
    """tight's refinement alone, by its hand-written LM and by SciPy's ``least_squares``
    (method "lm") on the same residuals and analytic Jacobian, from the same perturbed start."""
    from scipy.optimize import least_squares

    from estimation.tight import TightEstimator
    from estimation.tight_problem import TightProblem, rotation_exp

    config = load_config("default")
    intrinsics = load_intrinsics(config)
    tag_size = config.deck.tag_size
    estimator = TightEstimator(intrinsics=intrinsics, tag_size=tag_size)
    cases = []
    for m in synthetic_frames(frames_n, config.camera.intrinsics, tag_size, rng):
        solved = estimator.estimate(m.frame, m.ranges)
        problem = TightProblem(
            estimator._model,
            m.frame.detections[0].corners_px,
            estimator.intrinsics,
            estimator.config.pixel_sigma_px,
            estimator.tof_positions_c,
            m.ranges.ranges,
            estimator.config.tof_noise.sigma(m.ranges.ranges),
        )
        start_r = rotation_exp(rng.normal(0.0, 0.01, 3)) @ solved.rotation
        start_t = solved.translation + rng.normal(0.0, 0.002, 3)
        cases.append((problem, start_r, start_t))

    def hand(i: int) -> None:
        problem, r0, t0 = cases[i % len(cases)]
        problem.solve(r0, t0, estimator.config.max_iterations)

    def scipy(i: int) -> None:
        problem, r0, t0 = cases[i % len(cases)]
        least_squares(
            lambda x: problem.residuals(rotation_exp(x[3:]) @ r0, t0 + x[:3]),
            np.zeros(6),
            jac=lambda x: problem.linearise(rotation_exp(x[3:]) @ r0, t0 + x[:3])[1],
            method="lm",
        )

    return [
        ("tight refinement, hand LM", time_calls(hand, frames_n), "from a perturbed start"),
        ("tight refinement, SciPy lm", time_calls(scipy, frames_n), "same residuals, jac"),
    ]


def detection_rows(frames_n: int) -> list[tuple[str, np.ndarray, str]]:
    # imported here: the estimator timings above need no simulator
    from landing_env.world import World

    config = load_config("default", overrides={"motion.kind": "static"})
    world = World(config)
    try:
        world.reset(np.random.default_rng(0), world.deck_home_w + np.array([0.0, 0.0, 2.03]), 0.0)
        image = world.render_camera_image()
        frame = world.capture()
        view = world.camera.project_tag(
            *world.camera_pose_w(),
            world.deck_state().tag_centre_w,
            world.deck_state().rotation_wd,
            config.deck.tag_size,
        )
        window = world.camera.tag_window(view.corners_px)
    finally:
        world.close()
    assert window is not None and frame.detections, "the tag is not in view"
    x0, y0, x1, y1 = window
    patch = np.ascontiguousarray(image[y0:y1, x0:x1])
    rows = []
    for label, decimate, pixels in (
        ("detect 512x512", 1.0, image),
        ("detect 512x512, decimate 2", 2.0, image),
        (f"detect tag window {x1 - x0}x{y1 - y0}", 1.0, patch),
    ):
        detector = AprilTagDetector(quad_decimate=decimate)
        found = []

        def call(_: int, detector=detector, pixels=pixels, found=found) -> None:
            found.append(len(detector.detect(pixels)))

        times = time_calls(call, frames_n)
        detector.close()
        rows.append((label, times, f"{np.mean(found):.2f} tags found"))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=3000, help="estimator calls per row")
    parser.add_argument("--detect-frames", type=int, default=100, help="detections per row")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    rows = (
        estimator_rows(args.frames, rng)
        + refinement_rows(min(args.frames, 500), rng)
        + detection_rows(args.detect_frames)
    )
    table = Table(title="per-frame cost (µs)")
    for column in ("what", "median", "p90", "calls", "note"):
        table.add_column(column, justify="left" if column in ("what", "note") else "right")
    for label, times, note in rows:
        table.add_row(
            label,
            f"{np.median(times):.0f}",
            f"{np.percentile(times, 90):.0f}",
            str(len(times)),
            note,
        )
    Console().print(table)


if __name__ == "__main__":
    main()
