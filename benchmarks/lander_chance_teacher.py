"""The deck-tilt predictor's chance as the flare rule of align-descend on DeckLanding-BenchSS4-v1 (docs/experiments/lander.md).

    THR=0.9 IDX=0,1 LIMIT=4 N=40 python benchmarks/lander_chance_teacher.py
"""
import numpy as np
import gymnasium as gym
from gymnasium import spaces
from estimation.deck_prediction import LinearTiltPredictor
from estimation.frames import levelled_deck_pose, matrix_from_euler_zyx
from landing_env.resources import tilt_predictor_path
from landing_env.timing.history import HISTORY_FEATURES, DeckMotionHistory

HORIZONS = (0.6, 1.0, 1.4, 1.8)


class CalmChance(gym.ObservationWrapper):
    def __init__(self, env, predictor="bench-ss4", limit_deg=5.0):
        super().__init__(env)
        self.predictor = LinearTiltPredictor.load(tilt_predictor_path(predictor))
        dt = env.unwrapped.env_dt if hasattr(env.unwrapped, "env_dt") else 0.05
        self.dt = dt
        self.history = DeckMotionHistory(self.predictor.n_window, 10, dt)
        self.columns = [HISTORY_FEATURES.index(n) for n in self.predictor.channels]
        self.limit = limit_deg
        self.observation_space = spaces.Dict({**env.observation_space.spaces,
            "deck_calm_chance": spaces.Box(0.0, 1.0, (len(HORIZONS),), np.float32)})
        self.last = np.zeros(len(HORIZONS), np.float32)

    def reset(self, **kw):
        self.history.reset()
        return super().reset(**kw)

    def observation(self, obs):
        if obs["deck_pose_valid"][0] > 0.5:
            roll, pitch = (float(v) for v in obs["attitude"])
            pose = levelled_deck_pose(obs["deck_pose"].astype(float), matrix_from_euler_zyx(roll, pitch, 0.0))
            self.history.push(pose)
        else:
            self.history.push(None)
        rows = self.history.rows()
        values, valid = rows[:, self.columns], rows[:, -1] > 0.5
        out = np.zeros(len(HORIZONS), np.float32)
        phi = self.predictor.features(values, valid)
        if not isinstance(phi, str):
            for i, h in enumerate(HORIZONS):
                p = self.predictor._from_features(phi, h)
                out[i] = p.probability_within(self.limit)
        self.last = out
        return {**obs, "deck_calm_chance": out}
import os
import time
import numpy as np, gymnasium as gym
import landing_env  # noqa
import agents.align_descend as ad
from agents.align_descend import build_align_descend
from agents.calm_window import CalmPrediction
THR = float(os.environ.get("THR", 0.9)); IDX = [int(i) for i in os.environ.get("IDX", "1,2").split(",")]
N = int(os.environ.get("N", 20)); LIMIT = float(os.environ.get("LIMIT", 5.0))
env = CalmChance(gym.make("DeckLanding-BenchSS4-v1", overrides={"sensors": "realistic", "estimation.observed": "tight"}), limit_deg=LIMIT)
def calm(rows, dt, cfg):
    c = env.last[IDX]
    return CalmPrediction(bool(c.min() >= THR), 0.0, 0.0, 0.0, "chance")
ad.predict_calm = calm
pol = build_align_descend(env, None, ())
outs = []
t0 = time.time()
for s in range(N):
    obs, _ = env.reset(seed=4_000_000 + s); pol.reset()
    while True:
        obs, r, term, trunc, info = env.step(pol.act(obs))
        if term or trunc: break
    outs.append(str(info.get("outcome")))
print(f"THR {THR} IDX {IDX} LIMIT {LIMIT}: {sum(o=='success' for o in outs)}/{N}", {o: outs.count(o) for o in set(outs)}, f"{time.time()-t0:.0f}s", flush=True)
