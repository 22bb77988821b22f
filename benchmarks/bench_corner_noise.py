"""Project mode's corner noise against render-and-detect under the realistic camera.

    python -m benchmarks.bench_corner_noise [--states 1500] [--seed 0]

Measures render-and-detect corner errors over random states (landing_env.sensors.corner_noise),
fits the noise model, and compares the two error distributions: the fitted model's project
mode over fresh random states against render-and-detect over the same states (per-axis RMS
overall and by tag size, and a two-sample Kolmogorov-Smirnov test).  Paste the printed
coefficients into configs/sensors/realistic.yaml (camera.pixel_noise_fit).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import ks_2samp

from landing_env.config import load_config
from landing_env.sensors.corner_noise import fit_corner_noise, measure_corner_errors
from landing_env.world import World


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--states", type=int, default=1500)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    worlds = {
        mode: World(load_config("default", overrides={"sensors": "realistic", "camera.mode": mode}))
        for mode in ("render", "project")
    }
    start = time.process_time()
    fit_set = measure_corner_errors(worlds["render"], args.states, np.random.default_rng(args.seed))
    print(
        f"fit on {len(fit_set.side_px)} detected frames ({fit_set.missed} missed), "
        f"{time.process_time() - start:.1f} s CPU"
    )
    print("fitted pixel_noise_fit (base, size, blur, side2):", fit_corner_noise(fit_set))
    check = args.seed + 1
    rendered = measure_corner_errors(worlds["render"], args.states, np.random.default_rng(check))
    projected = measure_corner_errors(worlds["project"], args.states, np.random.default_rng(check))
    print("shipped pixel_noise_fit:", worlds["project"].config.camera.pixel_noise_fit)
    print(f"{'tag side px':>14} {'frames':>7} {'render rms':>11} {'project rms':>12} {'ratio':>6}")
    for lo, hi in ((0, 60), (60, 120), (120, 180), (180, 400), (0, 400)):
        r = (rendered.side_px >= lo) & (rendered.side_px < hi)
        q = (projected.side_px >= lo) & (projected.side_px < hi)
        if r.sum() < 5 or q.sum() < 5:
            continue
        rr = np.sqrt((rendered.errors_px[r] ** 2).mean())
        qq = np.sqrt((projected.errors_px[q] ** 2).mean())
        print(f"{lo:>6}-{hi:<7} {r.sum():>7} {rr:>11.3f} {qq:>12.3f} {qq / rr:>6.2f}")
    ks = ks_2samp(rendered.errors_px.reshape(-1), projected.errors_px.reshape(-1))
    print(f"two-sample KS on all per-axis errors: D = {ks.statistic:.3f}, p = {ks.pvalue:.3g}")


if __name__ == "__main__":
    main()
