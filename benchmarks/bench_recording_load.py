"""Load time of a long motion recording: a 2-hour log at 100 Hz (720 001 samples).

Measures, on this machine (reported, never asserted):

* the CSV read by numpy's C parser (``landing_env.waves.recording``), cold (first read in the
  process) and again (the per-process cache);
* the row-by-row ``csv`` module parse it replaced (the slow path kept to name a bad line);
* the same recording as ``.npy`` (read without parsing);
* the first pose of an episode at a random start (one PCHIP piece built), and the pose of a
  whole 40 s episode at 240 Hz.

    python -m benchmarks.bench_recording_load [--hours 2] [--rate-hz 100]

Writes results/bench_recording_load.md (dated).
"""

from __future__ import annotations

import argparse
import datetime as dt
import tempfile
import time
from pathlib import Path

import numpy as np

from landing_env.waves import recording
from landing_env.waves.recording import (
    CsvMotionConfig,
    csv_motion_from_config,
    load_recording,
    write_motion_npy,
)


def _timed(function) -> tuple[float, object]:
    start = time.perf_counter()
    value = function()
    return time.perf_counter() - start, value


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=2.0)
    parser.add_argument("--rate-hz", type=float, default=100.0)
    parser.add_argument("--out", default="results/bench_recording_load.md")
    args = parser.parse_args(argv)
    n = int(args.hours * 3600 * args.rate_hz) + 1
    times = 10.0 + np.arange(n) / args.rate_hz
    rng = np.random.default_rng(0)
    poses = np.cumsum(rng.normal(0.0, 1e-4, (n, 6)), axis=0)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        csv_path = Path(folder) / "log.csv"
        npy_path = Path(folder) / "log.npy"
        table = np.column_stack([times, poses])
        table[:, 4:] = np.degrees(table[:, 4:])
        with csv_path.open("w") as handle:
            handle.write(",".join(recording.CSV_HEADER) + "\n")
            np.savetxt(handle, table, delimiter=",", fmt="%.6f")
        write_motion_npy(npy_path, times, poses)
        size_mb = csv_path.stat().st_size / 1e6
        cold, _ = _timed(lambda: load_recording(csv_path))
        warm, _ = _timed(lambda: load_recording(csv_path))
        scan, _ = _timed(lambda: recording._scan_csv(csv_path))
        npy, _ = _timed(lambda: load_recording(npy_path))
        config = CsvMotionConfig(str(npy_path), start="random")
        first, _ = _timed(
            lambda: csv_motion_from_config(config, np.random.default_rng(1)).pose(0.0)
        )
        motion = csv_motion_from_config(config, np.random.default_rng(2))
        episode, _ = _timed(lambda: motion.poses(np.arange(0.0, 40.0, 1.0 / 240.0)))
        rows = [
            (f"CSV, numpy C parser, first read ({size_mb:.0f} MB)", cold),
            ("CSV, read again (per-process cache)", warm),
            ("CSV, row-by-row csv module (the error path)", scan),
            (".npy, first read", npy),
            ("first pose of an episode at a random start", first),
            ("a 40 s episode's poses at 240 Hz (one call)", episode),
        ]
    lines = [
        f"# Motion recording load time ({dt.date.today().isoformat()})",
        "",
        f"{args.hours:g} h at {args.rate_hz:g} Hz: {n} samples "
        "(`python -m benchmarks.bench_recording_load`).",
        "",
        "| step | seconds |",
        "|---|---|",
        *(f"| {name} | {seconds:.3f} |" for name, seconds in rows),
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)


if __name__ == "__main__":
    main()
