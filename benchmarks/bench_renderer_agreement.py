"""Planar renderer against the reference renderers: tag corners, offset against spread.

    python -m benchmarks.bench_renderer_agreement [--reference tiny|egl] [--supersample 6]

For level and tilted drone/deck poses at 4, 2, 1 and 0.6 m (default deck, 0.30 m tag) and at
0.3 m (a 0.12 m tag, as the 0.30 m tag is larger than the view there), the ideal image is
rendered by the planar renderer and by the reference (TinyRenderer, or OpenGL through the
EGL plugin), plain and supersampled ``--supersample`` times and box-filtered (see
:mod:`landing_env.sensors.renderer_agreement`); the tag is detected in each.  Printed per
pose: the mean corner differences; per height and over all poses: the mean difference, the
mean difference *vector* (a systematic offset: pixel centres, row flip, projection), the
spread (standard deviation per axis) and the radial scale (a focal length or image-size
error; shown as the difference it makes 200 px from the principal point), for planar -
plain, planar - supersampled, plain - supersampled and each against the analytic corners.
"""

from __future__ import annotations

import argparse
import warnings

from rich.console import Console
from rich.table import Table

from estimation.detection import AprilTagDetector
from landing_env.config import load_config
from landing_env.sensors.renderer_agreement import (
    HEIGHTS_M,
    corner_norms,
    corner_sets,
    corner_statistics,
    standard_poses,
)
from landing_env.world import World


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--reference", choices=("tiny", "egl"), default="tiny")
    parser.add_argument("--supersample", type=int, default=6)
    args = parser.parse_args()
    console = Console(width=150)
    plain, fine = f"{args.reference} x1", f"{args.reference} x{args.supersample}"
    pairs = [
        ("planar", plain),
        ("planar", fine),
        (plain, fine),
        ("planar", "truth"),
        (plain, "truth"),
        (fine, "truth"),
    ]
    detector = AprilTagDetector()
    results = []
    # one world at a time: the EGL plugin draws one scene per process
    for tag_size, small in ((0.30, False), (0.12, True)):
        overrides = {"camera.mode": "render", "deck.tag_size": tag_size}
        overrides["camera.use_egl"] = args.reference == "egl"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            world = World(load_config("default", overrides=overrides))
        k = world.camera.intrinsics
        try:
            if args.reference == "egl" and world.camera.renderer != "egl":
                raise SystemExit("the EGL renderer plugin did not load on this machine")
            for pose in standard_poses():
                if (pose.height_m < 0.5) == small:
                    refs = ((args.reference, 1), (args.reference, args.supersample))
                    results.append((pose, corner_sets(world, detector, pose, refs)))
        finally:
            world.close()

    per_pose = Table(title="mean corner difference per pose, px (ideal images, 512 px)")
    columns = ("height m", "drone r/p/y deg", "deck r/p deg", *(f"{a} - {b}" for a, b in pairs))
    for column in columns:
        per_pose.add_column(column, justify="right")
    for pose, found in results:
        cells = []
        for a, b in pairs:
            missing = found[a] is None or found[b] is None
            cells.append("-" if missing else f"{corner_norms(found[a] - found[b]).mean():.3f}")
        per_pose.add_row(
            f"{pose.height_m}",
            "/".join(f"{v:g}" for v in pose.drone_rpy_deg),
            "/".join(f"{v:g}" for v in pose.deck_rp_deg),
            *cells,
        )
    console.print(per_pose)

    pooled = Table(title="pooled over poses: offset = mean difference vector, spread = std")
    columns = ("difference", "height m", "mean |d| px", "offset x, y px", "spread x, y px")
    for column in (*columns, "scale: px at 200 px"):
        pooled.add_column(column, justify="right")
    centre = (k.cx, k.cy)
    for a, b in pairs:
        for heights, label in [({h}, f"{h}") for h in HEIGHTS_M] + [(set(HEIGHTS_M), "all")]:
            both = [
                found
                for pose, found in results
                if pose.height_m in heights and found[a] is not None and found[b] is not None
            ]
            if not both:
                pooled.add_row(f"{a} - {b}", label, "-", "-", "-", "-")
                continue
            diffs = [found[a] - found[b] for found in both]
            s = corner_statistics(diffs, [found["truth"] for found in both], centre)
            pooled.add_row(
                f"{a} - {b}",
                label,
                f"{s.mean_px:.3f}",
                f"{s.offset_px[0]:+.3f}, {s.offset_px[1]:+.3f}",
                f"{s.spread_px[0]:.3f}, {s.spread_px[1]:.3f}",
                f"{200.0 * s.scale:+.3f}",
                end_section=label == "all",
            )
    console.print(pooled)


if __name__ == "__main__":
    main()
