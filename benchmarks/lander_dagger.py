"""DAgger into an SB3 SAC actor on DeckLanding-BenchSS4-v1: TEACHER=align (align-descend) or truth (deck-future teacher); docs/experiments/lander.md."""

import json
import os
import sys
import time

import gymnasium as gym
import numpy as np
import torch

import landing_env  # noqa: F401
from agents.align_descend import build_align_descend
from stable_baselines3 import SAC
from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack

torch.set_num_threads(1)
STACK = int(os.environ.get("STACK", 10))
ENV_ID = "DeckLanding-BenchSS4-v1"
KW = {"overrides": {"sensors": "realistic", "estimation.observed": "tight"}, "render_mode": None}
OUT = os.environ.get("OUT", "/tmp/bc_run")
os.makedirs(OUT, exist_ok=True)
ITERS = [int(x) for x in os.environ.get("ITERS", "30,15,15,15").split(",")]
EVAL_N = int(os.environ.get("EVAL_N", 20))


def log(*a):
    print(time.strftime("%H:%M:%S"), *a, flush=True)


venv = VecFrameStack(DummyVecEnv([lambda: gym.make(ENV_ID, **KW)]), STACK)
base = venv.venv.envs[0]
widths = {k: space.shape[-1] for k, space in base.observation_space.spaces.items()}
expert = build_align_descend(base, None, ())
TEACHER = os.environ.get("TEACHER", "align")
LEAD = [float(x) for x in os.environ.get("LEAD", "0.6,1.6").split(",")]
MAX_TILT = float(os.environ.get("MAX_TILT", "3.5"))
import agents.align_descend as ad
from agents.calm_window import CalmPrediction


def _truth_calm(rows, dt, cfg):
    world = base.unwrapped.world
    motion = world.stewart.motion
    t = world.time
    tilts = []
    for lead in np.linspace(LEAD[0], LEAD[1], 11):
        r, p = motion.pose(t + lead)[3:5]
        tilts.append(np.degrees(np.arccos(np.clip(np.cos(r) * np.cos(p), -1, 1))))
    worst = float(max(tilts))
    return CalmPrediction(worst <= MAX_TILT, worst, worst, 0.0, "teacher")


if TEACHER == "truth":
    ad.predict_calm = _truth_calm
model = SAC(
    "MultiInputPolicy",
    venv,
    policy_kwargs={"net_arch": [256, 256]},
    learning_rate=3e-4,
    buffer_size=10,
    seed=0,
    device="cpu",
)
actor = model.policy.actor
opt = torch.optim.Adam(actor.parameters(), lr=1e-3)
data_obs: dict[str, list] = {k: [] for k in widths}
data_act: list = []


def run_episode(seed, drive):
    venv.seed(seed)
    obs = venv.reset()
    expert.reset()
    steps = 0
    while True:
        raw = {k: obs[k][0][..., -w:] for k, w in widths.items()}
        a_exp = np.asarray(expert.act(raw), dtype=np.float32)
        if drive != "eval":
            for k in widths:
                data_obs[k].append(obs[k][0].copy())
            data_act.append(a_exp)
        if drive == "expert":
            a = a_exp
        else:
            a, _ = model.predict(obs, deterministic=True)
            a = np.asarray(a).reshape(4)
        obs, _, done, info = venv.step(a[None])
        steps += 1
        if done[0]:
            return info[0].get("outcome"), steps


def train(epochs):
    obs = {k: torch.as_tensor(np.asarray(v), dtype=torch.float32) for k, v in data_obs.items()}
    target = torch.as_tensor(np.clip(np.asarray(data_act), -0.97, 0.97))
    n = len(target)
    for epoch in range(epochs):
        perm = torch.randperm(n)
        total = 0.0
        for i in range(0, n, 256):
            idx = perm[i : i + 256]
            batch = {k: v[idx] for k, v in obs.items()}
            mean, log_std, _ = actor.get_action_dist_params(batch)
            loss = torch.nn.functional.mse_loss(torch.tanh(mean), target[idx])
            loss = loss + 0.01 * torch.mean((log_std + 2.0) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss) * len(idx)
        if epoch % 5 == 4 or epoch == epochs - 1:
            log(f"  epoch {epoch + 1}: loss {total / n:.5f} on {n}")


def evaluate(tag):
    outcomes = []
    for s in range(EVAL_N):
        outcome, steps = run_episode(4_000_000 + s, "eval")
        outcomes.append(str(outcome))
    ok = sum(o.endswith("success") or o == "success" for o in outcomes)
    log(f"EVAL {tag}: {ok}/{EVAL_N}", {o: outcomes.count(o) for o in set(outcomes)})
    return ok


seed = 100_000
results = []
for it, n_eps in enumerate(ITERS):
    t0 = time.time()
    drive = "expert" if it == 0 else "student"
    outs = []
    for _ in range(n_eps):
        outcome, steps = run_episode(seed, drive)
        seed += 1
        outs.append(str(outcome))
    log(f"iter {it} ({drive}): {n_eps} episodes, {len(data_act)} samples, "
        f"{time.time() - t0:.0f} s", {o: outs.count(o) for o in set(outs)})
    train(30 if it == 0 else 15)
    ok = evaluate(f"iter {it}")
    results.append({"iter": it, "samples": len(data_act), "eval_success": ok})
    model.save(f"{OUT}/bc_iter{it}.zip")
    json.dump(results, open(f"{OUT}/results.json", "w"), indent=1)
log("done", results)
sys.exit(0)
