"""Which image shapes crash pupil-apriltags' native detector (the probe behind
``estimation.detection.MIN_DETECT_SIDE_PX``).

Each shape is detected in a child process (flat, random, black and white images); a child
that dies (SIGSEGV) names the shape it was on, is recorded, and a new child goes on from the
next shape, so the probe itself never crashes.  Then the guarded wrapper is checked on every
crashing shape, also in a child.

    python -m benchmarks.probe_detector_min_size --max-side 30
"""

from __future__ import annotations

import argparse
import subprocess
import sys

from tqdm import tqdm

_CHILD = """
import sys, numpy as np
from pupil_apriltags import Detector
decimate = float(sys.argv[1])
shapes = [tuple(map(int, s.split('x'))) for s in sys.argv[2].split(',')]
detector = Detector(families='tag36h11', quad_decimate=decimate)
rng = np.random.default_rng(0)
for h, w in shapes:
    print(f'{h}x{w}', flush=True)
    for image in (np.full((h, w), 103, np.uint8), rng.integers(0, 256, (h, w), dtype=np.uint8),
                  np.zeros((h, w), np.uint8), np.full((h, w), 255, np.uint8)):
        detector.detect(np.ascontiguousarray(image))
"""

_GUARDED = """
import sys, numpy as np
from estimation.detection import AprilTagDetector
decimate = float(sys.argv[1])
shapes = [tuple(map(int, s.split('x'))) for s in sys.argv[2].split(',')]
detector = AprilTagDetector(quad_decimate=decimate)
for h, w in shapes:
    assert detector.detect(np.full((h, w), 103, np.uint8)) == ()
print('ok')
"""


def crashing_shapes(decimate: float, shapes: list[str]) -> list[tuple[int, int]]:
    """The shapes on which a raw pupil-apriltags detector kills its process."""
    bad: list[tuple[int, int]] = []
    todo = list(shapes)
    with tqdm(total=len(todo), desc=f"decimate {decimate}", leave=False) as bar:
        while todo:
            run = subprocess.run(
                [sys.executable, "-c", _CHILD, str(decimate), ",".join(todo)],
                capture_output=True,
                text=True,
            )
            if run.returncode == 0:
                bar.update(len(todo))
                break
            last = run.stdout.strip().split("\n")[-1]
            bad.append(tuple(int(v) for v in last.split("x")))  # type: ignore[arg-type]
            done = todo.index(last) + 1
            bar.update(done)
            todo = todo[done:]
    return bad


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--max-side", type=int, default=30)
    parser.add_argument("--decimate", type=float, nargs="+", default=[1.0, 1.5, 2.0, 3.0, 4.0])
    args = parser.parse_args()
    from estimation.detection import min_detect_side_px

    sides = range(1, args.max_side + 1)
    shapes = [f"{h}x{w}" for h in sides for w in sides]
    for decimate in args.decimate:
        bad = crashing_shapes(decimate, shapes)
        worst = max((min(b) for b in bad), default=0)
        guard = min_detect_side_px(decimate)
        guarded = subprocess.run(
            [sys.executable, "-c", _GUARDED, str(decimate), ",".join(f"{h}x{w}" for h, w in bad)],
            capture_output=True,
            text=True,
        )
        print(
            f"quad_decimate {decimate}: {len(bad)} of {len(shapes)} shapes crash, "
            f"largest crashing min(h, w) = {worst} px; guard min side = {guard} px; "
            f"guarded wrapper on them: {'ok' if guarded.returncode == 0 else guarded.returncode}"
        )


if __name__ == "__main__":
    main()
