"""Planar renderer against the reference renderer (TinyRenderer): tag corners and images.

    python -m benchmarks.bench_renderer_agreement [--supersample 6]

For level and tilted drone/deck poses at 4, 2, 1 and 0.6 m (default deck, 0.30 m tag) and at
0.3 m (a 0.12 m tag, as the 0.30 m tag is larger than the view there), the ideal image is
rendered by the planar renderer and by TinyRenderer supersampled ``--supersample`` times and
box-filtered (see :mod:`landing_env.sensors.renderer_agreement`), the tag is detected in
both, and the corner differences (planar - reference) and each renderer's corner error
against the analytic projection are printed.  ``--supersample 1`` compares with TinyRenderer's
plain (aliased) output.
"""

from __future__ import annotations

import argparse

import numpy as np
from rich.console import Console
from rich.table import Table

from estimation.detection import AprilTagDetector
from landing_env.config import load_config
from landing_env.sensors.renderer_agreement import compare, corner_norms, standard_poses
from landing_env.world import World


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--supersample", type=int, default=6)
    args = parser.parse_args()
    console = Console(width=140)
    table = Table(title=f"planar vs TinyRenderer x{args.supersample} (ideal images, 512 px)")
    for column in (
        "height m",
        "drone r/p/y deg",
        "deck r/p deg",
        "|planar - ref| px",
        "planar err px",
        "ref err px",
        "mean |grey diff|",
    ):
        table.add_column(column, justify="right")
    worlds = {
        "default": World(load_config("default", overrides={"camera.mode": "render"})),
        "small": World(
            load_config("default", overrides={"camera.mode": "render", "deck.tag_size": 0.12})
        ),
    }
    detector = AprilTagDetector()
    diffs, planar_err, ref_err = [], [], []
    for pose in standard_poses():
        world = worlds["small" if pose.height_m < 0.5 else "default"]
        result = compare(world, detector, pose, args.supersample)
        if result.corner_diff_px is None:
            table.add_row(f"{pose.height_m}", str(pose.drone_rpy_deg), "-", "not detected")
            continue
        d = corner_norms(result.corner_diff_px)
        e_p = corner_norms(result.corner_error_planar_px)
        e_r = corner_norms(result.corner_error_reference_px)
        diffs.append(d)
        planar_err.append(e_p)
        ref_err.append(e_r)
        table.add_row(
            f"{pose.height_m}",
            "/".join(f"{v:g}" for v in pose.drone_rpy_deg),
            "/".join(f"{v:g}" for v in pose.deck_rp_deg),
            f"{d.mean():.3f} (max {d.max():.3f})",
            f"{e_p.mean():.3f}",
            f"{e_r.mean():.3f}",
            f"{result.mean_abs_grey:.2f}",
        )
    console.print(table)
    console.print(
        f"all poses: |planar - reference| mean {np.concatenate(diffs).mean():.3f} px; "
        f"error against the analytic corners: planar {np.concatenate(planar_err).mean():.3f} "
        f"px, reference {np.concatenate(ref_err).mean():.3f} px"
    )


if __name__ == "__main__":
    main()
