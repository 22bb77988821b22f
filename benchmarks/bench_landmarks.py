"""Which nested landmarks the rendered camera decodes at each height, and the estimators' errors.

Runs configs/high-approach.yaml in render mode (PyBullet TinyRenderer + pupil-apriltags) with
the drone pinned over the landing point (deck centre) at each camera height, the deck moving
(sea state 3), and prints per height: the detected tag ids and their sides (px), the chosen
landmark, and each estimator's error against the truth (position mm, angle deg).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np

import landing_env  # noqa: F401  (registers the environments)
from estimation.landmarks import shortest_side_px
from landing_env.envs.base import DeckLandingBaseEnv

HEIGHTS_M = (20.0, 10.0, 5.0, 3.0, 2.0, 1.0, 0.5, 0.3, 0.2, 0.15)
CAMERA_BELOW_COM_M = 0.03


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=10, help="frames per height")
    parser.add_argument("--offset", type=float, default=0.05, help="lateral offset, m")
    parser.add_argument("--out", default="results/high-approach")
    parser.add_argument(
        "--one-tag", action="store_true", help="ATDA from the chosen tag only (no joint PnP)"
    )
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(
        "DeckLanding-v2",
        config="high-approach",
        render_mode="rgb_array",
        overrides={
            "camera.mode": "render",
            "simulation.drone_fixed": True,
            "wind.enabled": False,
            "estimation.observed": "atda",
            "estimation.compare": ["ihrcf", "crhf"],
            "estimation.atda.joint_landmarks": not args.one_tag,
        },
    )
    base: DeckLandingBaseEnv = env.unwrapped  # type: ignore[assignment]
    print("height_m  detected ids (side px)  ATDA's tags  atda/ihrcf/crhf |dt| mm, |dR| deg")
    for height in HEIGHTS_M:
        _, info = env.reset(
            seed=1,
            options={
                "height_m": height + CAMERA_BELOW_COM_M,
                "offset_m": (args.offset, 0.0),
                "yaw": 0.0,
            },
        )
        seen: dict[int, list[float]] = {}
        chosen: dict[int, int] = {}
        errors: dict[str, list[tuple[float, float]]] = {"atda": [], "ihrcf": [], "crhf": []}
        for i in range(args.frames):
            if i:
                _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
            frame = base._sensing.frame
            for d in frame.detections:
                seen.setdefault(d.tag_id, []).append(shortest_side_px(d.corners_px))
            truth = info["deck_pose_true"]
            for name in errors:
                est = info["estimates"][name]
                if est["valid"]:
                    # the joint ATDA lists every tag it used
                    lm = est["extras"].get("landmark_ids", est["extras"].get("landmark_id"))
                    if name == "atda":
                        chosen[lm] = chosen.get(lm, 0) + 1
                    diff = est["pose"] - truth
                    angle = np.degrees(np.abs((diff[3:] + math.pi) % (2 * math.pi) - math.pi))
                    errors[name].append((1e3 * float(np.linalg.norm(diff[:3])), float(angle.max())))
            if i == 0 and height in (20.0, 1.0, 0.3):
                image = env.render()
                name = f"camera_{height:g}m.png"
                cv2.imwrite(str(out / name), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        ids = ", ".join(
            f"{k} ({np.mean(v):.0f} px, {len(v)}/{args.frames})" for k, v in sorted(seen.items())
        )
        parts = []
        for name, values in errors.items():
            if values:
                arr = np.asarray(values)
                parts.append(f"{name} {arr[:, 0].mean():.1f} mm {arr[:, 1].mean():.2f} deg")
            else:
                parts.append(f"{name} invalid ({info['estimates'][name]['reason']})")
        print(f"{height:5.2f}  {ids:34s}  {chosen}  " + "; ".join(parts))
    env.close()


if __name__ == "__main__":
    main()
