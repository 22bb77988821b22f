"""How well the shipped deck-tilt predictors predict, on episodes they were not fitted on.

For each scenario: waiting episodes of the timing task (held-out seeds from 1 000 000, the
evaluations' own), and at every decision the deck's levelled roll and pitch predicted 0.7 s
(the wave-off's horizon) and 1.3 s (the timed descent's contact) ahead by

* ``wiener``: the scenario's shipped predictor (:mod:`estimation.deck_prediction`);
* ``linear``: the newest estimate carried along its 0.5 s least-squares rates (the ``linear``
  wave-off of v1);
* ``hold``: the newest estimate (the deck assumed to stay as it is);

against the truth.  Printed: RMS errors (deg) and, for ``wiener``, how often the truth falls
inside the predicted 95 % ellipse (calibration: 95 % is honest).

    python -m benchmarks.bench_deck_prediction --scenario bench-ss4 bench-ss5 --episodes 10
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from agents.training.deck_prediction_fit import collect
from estimation.deck_prediction import LinearTiltPredictor
from landing_env.resources import tilt_predictor_path

HORIZONS_S = (0.7, 1.3)
#: chi-square with 2 degrees of freedom at 95 %
CHI2_95 = -2.0 * math.log(0.05)


def evaluate(scenario: str, episodes: int, seed: int, sensing: str) -> list[dict[str, float]]:
    predictor = LinearTiltPredictor.load(tilt_predictor_path(scenario))
    histories, truth, numbers, decision_s = collect(
        scenario,
        sensing,
        episodes,
        seed,
        window_s=predictor.window_s,
        wait_s=40.0,
        channels=predictor.channels,
    )
    dt = predictor.dt_s
    c = len(predictor.channels)
    tilt = [predictor.channels.index("roll"), predictor.channels.index("pitch")]
    rows: list[dict[str, float]] = []
    for horizon in HORIZONS_S:
        steps = round(horizon / decision_s)
        errors: dict[str, list[np.ndarray]] = {"wiener": [], "linear": [], "hold": []}
        inside: list[bool] = []
        for i in range(len(truth) - steps):
            if numbers[i + steps] != numbers[i]:
                continue
            history = histories[i].astype(float)
            valid = history[:, c] > 0.5
            prediction = predictor.predict(history[:, :c], valid, horizon)
            recent = history[-10:][valid[-10:]][:, tilt]
            if not prediction.valid or len(recent) < 5 or not valid[-1]:
                continue
            target = truth[i + steps]
            residual = np.array([prediction.roll, prediction.pitch]) - target
            errors["wiener"].append(residual)
            inside.append(
                float(residual @ np.linalg.solve(prediction.covariance, residual)) <= CHI2_95
            )
            t = (np.arange(10) * dt)[valid[-10:]]
            slope = np.polyfit(t - t.mean(), recent[:, :2], 1)[0]
            errors["linear"].append(history[-1, tilt] + slope * horizon - target)
            errors["hold"].append(history[-1, tilt] - target)
        row: dict[str, float] = {"horizon_s": horizon, "examples": len(inside)}
        for name, values in errors.items():
            rms = np.degrees(np.sqrt(np.mean(np.square(values), axis=0)))
            row[f"{name}_roll"], row[f"{name}_pitch"] = float(rms[0]), float(rms[1])
        row["coverage_95"] = float(np.mean(inside))
        rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", nargs="+", default=["bench-ss3", "bench-ss4", "bench-ss5"])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=1_000_000)
    parser.add_argument("--sensors", default="realistic")
    args = parser.parse_args()
    print(
        "| scenario | horizon (s) | wiener roll / pitch (deg) | linear | hold | "
        "inside the 95 % ellipse | examples |"
    )
    print("|---|---|---|---|---|---|---|")
    for scenario in args.scenario:
        for r in evaluate(scenario, args.episodes, args.seed, args.sensors):
            print(
                f"| {scenario} | {r['horizon_s']:.1f} | {r['wiener_roll']:.2f} / "
                f"{r['wiener_pitch']:.2f} | {r['linear_roll']:.2f} / {r['linear_pitch']:.2f} | "
                f"{r['hold_roll']:.2f} / {r['hold_pitch']:.2f} | {100 * r['coverage_95']:.1f} % | "
                f"{r['examples']:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
