"""``fused`` on deck motions it was never tuned for: online identification against the prior.

    python -m benchmarks.bench_fused_unseen [--duration 120] [--seeds 2] [--reuse]
        [--out results/fused_unseen]

On the ``realistic`` bench (drone pinned 2 m above the platform, rendered and detected, 50 ms
steps) the deck is driven by the HELD-OUT motions of :mod:`benchmarks.fused_motions`
(bimodal swell plus wind sea, long swell; CSV replays, seeds from 7 000 000: never used to
choose a setting) and by the scenario's own motion (its sinusoids, seed 0).  Each run is
recorded once (:mod:`benchmarks.fused_replay`) and ``fused`` is replayed on exactly the same
poses, ranges and IMU samples with:

* ``before``: the filter as it was: no identification, pose errors taken as independent
  (the scenario's own motion: its prior, the two wave components the simulator gives);
* ``identified``: the defaults: the deck's motion identified online, prior OFF, the pose
  sources' coloured tilt errors modelled;
* ``prior + coloured`` (own motion only): the prior given, the coloured errors modelled.

Per run and averaged over runs: the roll/pitch MAE of each variant and of the single-frame
estimators on the same frames, the 10 s MAE ending 30 s after reset against the MAE after
60 s (converged: within 20 %), and the roll/pitch NEES (the filter's error against its own
covariance, chi-square with 2 degrees of freedom) and NIS (each pose's roll/pitch
innovation against its predicted covariance) with their 95 % bands, counted over the
effective number of independent samples (the integrated autocorrelation time of each
series).  Writes ``summary.json`` and ``table.md`` under ``--out``.  A run shorter than 60 s
(a smoke run) leaves the figures of the windows it does not reach NaN.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from agents.evaluation.records import pose_errors
from benchmarks.fused_motions import HELD_OUT_SEED_BASE, HELD_OUT_SPECTRA, write_held_out_csv
from benchmarks.fused_replay import Recording, record, replay, settings

SINGLE_FRAME = ("atda", "ihrcf", "crhf", "tight")


def variants(rec: Recording, own: bool) -> dict[str, dict]:
    """The filter settings compared on a recording (overrides of its own config)."""
    before = {
        "identify_deck_motion": False,
        "tilt_error_correlation_s": 0.0,
        "tilt_error_sigma_scale": 1.0,
    }
    identified = {"deck_roll_periods_s": (), "deck_pitch_periods_s": ()}
    out = {"before": before, "identified": identified}
    if own and rec.fusion.deck_roll_periods_s:
        out["prior + coloured"] = {}
    return out


def effective_count(series: np.ndarray) -> float:
    """Samples over the integrated autocorrelation time (summed to the first negative lag)."""
    x = np.asarray(series, dtype=float) - np.mean(series)
    n = len(x)
    if n < 4 or not np.any(x):
        return float(n)
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    acf /= acf[0]
    tau = 1.0
    for value in acf[1 : n // 2]:
        if value <= 0.0:
            break
        tau += 2.0 * value
    return n / tau


def band(values: list[np.ndarray], dof: int) -> dict:
    """Mean of chi-square samples with its 95 % band over the effective sample count."""
    parts = [v for v in values if len(v)]
    n_eff = sum(effective_count(v) for v in parts)
    joined = np.concatenate(parts) if parts else np.array([])
    if not len(joined):
        return {"mean": math.nan, "low": math.nan, "high": math.nan, "n_eff": 0.0}
    low, high = chi2.ppf([0.025, 0.975], dof * n_eff) / n_eff
    mean = float(np.mean(joined))
    return {
        "mean": mean,
        "low": float(low),
        "high": float(high),
        "n_eff": float(n_eff),
        "inside": bool(low <= mean <= high),
    }


def mean_abs(error: np.ndarray) -> list[float]:
    """The mean absolute roll and pitch error; NaN where a window holds no sample (a run
    shorter than the window)."""
    return np.abs(error).mean(axis=0).tolist() if len(error) else [math.nan, math.nan]


def score(rec: Recording, config_overrides: dict) -> dict:
    """One variant of ``fused`` replayed on a recording: errors, convergence, NEES, NIS."""
    rep = replay(rec, settings(rec, **config_overrides))
    truth = np.asarray(rec.truth)
    t = rep.time_s - rep.time_s[0]
    error = pose_errors(rep.pose, truth)[:, 3:5]
    ok = np.all(np.isfinite(error), axis=1)
    settled = ok & (t >= 30.0)
    e_rad = np.radians(error[settled])
    nees = np.einsum("ni,nij,nj->n", e_rad, np.linalg.inv(rep.cov_tilt[settled]), e_rad)
    nis = rep.nis[np.isfinite(rep.nis) & (t >= 30.0)]
    models = rep.fusion.identifier.models if rep.fusion.identifier is not None else None
    return {
        "mae_deg": mean_abs(error[ok]),
        "window_20_30_deg": mean_abs(error[ok & (t > 20.0) & (t <= 30.0)]),
        "after_60_deg": mean_abs(error[ok & (t >= 60.0)]),
        "valid": float(ok.mean()),
        "_nees": nees,
        "_nis": nis,
        "identified": None
        if models is None
        else [
            {
                "periods_s": [round(p, 2) for p in m.periods_s],
                "damping": [round(z, 3) for z in m.damping],
                "rms_deg": round(math.degrees(m.rms_rad), 2),
            }
            for m in models
        ],
    }


def single_frame(rec: Recording) -> dict[str, list[float]]:
    truth = np.asarray(rec.truth)
    out = {}
    for name in SINGLE_FRAME:
        error = pose_errors(np.asarray(rec.poses[name]), truth)[:, 3:5]
        ok = np.all(np.isfinite(error), axis=1)
        out[name] = mean_abs(error[ok])
    return out


def recordings(out: Path, duration_s: float, seeds: int, reuse: bool) -> dict[str, list[Path]]:
    """Record (or reuse) every held-out motion and the scenario's own; paths per group."""
    groups: dict[str, list[Path]] = {}
    for name in HELD_OUT_SPECTRA:
        for index in range(seeds):
            seed = HELD_OUT_SEED_BASE + index
            path = out / "recordings" / f"{name}-{seed}.pkl"
            if not (reuse and path.is_file()):
                csv_path = out / "motions" / f"{name}-{seed}.csv"
                csv = write_held_out_csv(name, seed, csv_path, duration_s)
                overrides = {"motion.kind": "csv", "motion.csv.path": str(csv)}
                record(name, "realistic", overrides, 0, duration_s).save(path)
            groups.setdefault(f"held-out {name}", []).append(path)
    path = out / "recordings" / "own-0.pkl"
    if not (reuse and path.is_file()):
        record("own", "realistic", {}, 0, duration_s).save(path)
    groups["own motion (sinusoids)"] = [path]
    return groups


def summarise(groups: dict[str, list[Path]]) -> dict:
    summary: dict = {}
    for group, paths in groups.items():
        rows: dict = {"runs": [p.stem for p in paths], "single_frame": {}, "fused": {}}
        frames = []
        scores: dict[str, list[dict]] = {}
        for path in paths:
            rec = Recording.load(path)
            frames.append(single_frame(rec))
            for label, overrides in variants(rec, group.startswith("own")).items():
                scores.setdefault(label, []).append(score(rec, overrides))
        for name in SINGLE_FRAME:
            rows["single_frame"][name] = np.mean([f[name] for f in frames], axis=0).tolist()
        for label, runs in scores.items():
            rows["fused"][label] = {
                "mae_deg": np.mean([r["mae_deg"] for r in runs], axis=0).tolist(),
                "per_run_mae_deg": [r["mae_deg"] for r in runs],
                "window_20_30_deg": np.mean([r["window_20_30_deg"] for r in runs], axis=0).tolist(),
                "after_60_deg": np.mean([r["after_60_deg"] for r in runs], axis=0).tolist(),
                "nees": band([r["_nees"] for r in runs], 2),
                "nis": band([r["_nis"] for r in runs], 2),
                "identified": [r["identified"] for r in runs],
            }
        summary[group] = rows
    return summary


def table(summary: dict) -> str:
    lines = [
        "| motion | estimator | roll / pitch MAE (deg) | 10 s MAE at 30 s / after 60 s "
        "| NEES (band) | NIS (band) |",
        "|---|---|---|---|---|---|",
    ]

    def pair(values: list[float]) -> str:
        return f"{values[0]:.2f} / {values[1]:.2f}"

    for group, rows in summary.items():
        for label, row in rows["fused"].items():
            nees, nis = row["nees"], row["nis"]
            lines.append(
                f"| {group} | fused, {label} | **{pair(row['mae_deg'])}** "
                f"| {pair(row['window_20_30_deg'])} vs {pair(row['after_60_deg'])} "
                f"| {nees['mean']:.2f} ({nees['low']:.2f}-{nees['high']:.2f}) "
                f"| {nis['mean']:.2f} ({nis['low']:.2f}-{nis['high']:.2f}) |"
            )
        for name, values in rows["single_frame"].items():
            lines.append(f"| {group} | {name} | {pair(values)} | | | |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=120.0, help="seconds per run")
    parser.add_argument("--seeds", type=int, default=2, help="seeds per held-out motion")
    parser.add_argument("--reuse", action="store_true", help="reuse recordings under --out")
    parser.add_argument("--out", type=Path, default=Path("results/fused_unseen"))
    args = parser.parse_args()
    if not args.duration > 0.0 or args.seeds < 1:
        parser.error("--duration must be above 0 and --seeds at least 1")
    start = time.perf_counter()
    groups = recordings(args.out, args.duration, args.seeds, args.reuse)
    summary = summarise(groups)
    args.out.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    meta = {"measured": stamp, "duration_s": args.duration, "seeds": args.seeds}
    (args.out / "summary.json").write_text(json.dumps({"meta": meta, **summary}, indent=2) + "\n")
    text = table(summary)
    (args.out / "table.md").write_text(f"# fused on held-out motions ({stamp})\n\n{text}")
    print(text)
    print(f"{time.perf_counter() - start:.0f} s; {args.out / 'summary.json'}")


if __name__ == "__main__":
    main()
