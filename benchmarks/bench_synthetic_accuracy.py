"""The estimators' accuracy on synthetic geometry under the issue's noise (prints a table).

    .venv/bin/python -m benchmarks.bench_synthetic_accuracy [--poses 300] [--tag-size 0.3]

Issue 12's test case: 0.5 px corner noise, ToF sigma = max(5 mm, 0.5 % of range), random
deck poses (tilted up to 15°, any yaw, tag in the central half of the view) at 0.5, 1, 2 and
3 m, the same single frames for ATDA, IHRCF, CRHF and tight (tight weighting by that
noise; :mod:`estimation.synthetic_accuracy`).  MAE per axis (x, y, z in mm, roll, pitch,
yaw in degrees) and tight's MAE over the best of the other three.
``tests/test_synthetic_accuracy.py`` asserts the ordering.
"""

from __future__ import annotations

import argparse

import numpy as np
from rich.console import Console
from rich.table import Table

from estimation.synthetic_accuracy import (
    ESTIMATORS,
    ISSUE_PIXEL_SIGMA_PX,
    synthetic_accuracy,
)

_SCALE = np.array([1e3, 1e3, 1e3, 1.0, 1.0, 1.0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--poses", type=int, default=300, help="random poses per height")
    parser.add_argument("--tag-size", type=float, default=0.30, help="tag edge, metres")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    result = synthetic_accuracy(poses=args.poses, tag_size=args.tag_size, seed=args.seed)
    table = Table(
        "height m", "estimator", "x mm", "y mm", "z mm", "roll °", "pitch °", "yaw °",
        title=f"MAE over {args.poses} poses per height: {ISSUE_PIXEL_SIGMA_PX} px corners, "
        f"ToF sigma max(5 mm, 0.5 % r), tag {args.tag_size} m",
    )  # fmt: skip
    for height in result.errors:
        mae = result.mae(height)
        best = np.minimum.reduce([mae[n] for n in ESTIMATORS if n != "tight"])
        for name in ESTIMATORS:
            table.add_row(f"{height:g}", name, *(f"{v:.2f}" for v in mae[name] * _SCALE))
        table.add_row(
            "", "tight / best", *(f"{v:.2f}" for v in mae["tight"] / best), end_section=True
        )
    Console().print(table)


if __name__ == "__main__":
    main()
