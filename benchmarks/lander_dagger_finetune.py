"""SAC fine-tune of the DAgger actor, the critic trained first with the actor frozen; docs/experiments/lander.md."""

import json
import os
import time

import gymnasium as gym
import numpy as np
import torch

import landing_env  # noqa: F401
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack

torch.set_num_threads(1)
STACK = int(os.environ.get("STACK", 20))
INIT = os.environ["INIT"]
OUT = os.environ.get("OUT", "/tmp/ft_run")
WARM = int(os.environ.get("WARM", 20000))
TOTAL = int(os.environ.get("TOTAL", 120000))
EVAL_EVERY = int(os.environ.get("EVAL_EVERY", 20000))
EVAL_N = int(os.environ.get("EVAL_N", 20))
os.makedirs(OUT, exist_ok=True)
ENV_ID = "DeckLanding-BenchSS4-v1"
KW = {"overrides": {"sensors": "realistic", "estimation.observed": "tight"}, "render_mode": None}


def log(*a):
    print(time.strftime("%H:%M:%S"), *a, flush=True)


def make_env():
    return VecFrameStack(DummyVecEnv([lambda: gym.make(ENV_ID, **KW)]), STACK)


env = make_env()
env.seed(7)
eval_env = make_env()
model = SAC.load(
    INIT,
    env=env,
    device="cpu",
    custom_objects={
        "buffer_size": 200000,
        "learning_starts": 2000,
        "batch_size": 256,
        "train_freq": 8,
        "gradient_steps": 8,
        "gamma": 0.99,
        "tau": 0.01,
        "learning_rate": float(os.environ.get("LR", 1e-4)),
    },
)
# SB3 builds the learning-rate schedule from learning_rate at load: rebuild it
model._setup_lr_schedule()
model.ent_coef_optimizer = None
model.ent_coef_tensor = torch.tensor(float(os.environ.get("ENT", 0.002)))
actor_step = model.actor.optimizer.step
model.actor.optimizer.step = lambda *a, **k: None  # critic first
log(f"loaded {INIT}; critic warm-up {WARM} steps, then actor and critic to {TOTAL}")
results = []


def evaluate(tag):
    outcomes = []
    for s in range(EVAL_N):
        eval_env.seed(4_000_000 + s)
        obs = eval_env.reset()
        while True:
            a, _ = model.predict(obs, deterministic=True)
            obs, _, done, info = eval_env.step(a)
            if done[0]:
                outcomes.append(str(info[0].get("outcome")))
                break
    ok = outcomes.count("success")
    log(f"EVAL {tag}: {ok}/{EVAL_N}", {o: outcomes.count(o) for o in set(outcomes)})
    results.append({"step": tag, "success": ok})
    json.dump(results, open(f"{OUT}/results.json", "w"), indent=1)


class Cb(BaseCallback):
    def __init__(self):
        super().__init__()
        self.outs = []

    def _on_step(self):
        for done, info in zip(self.locals["dones"], self.locals["infos"]):
            if done:
                self.outs.append(str(info.get("outcome")))
        n = self.num_timesteps
        if n == WARM:
            model.actor.optimizer.step = actor_step
            log("actor released")
        if n % EVAL_EVERY == 0:
            last = self.outs[-30:]
            log(f"step {n}: rollouts {last.count('success')}/{len(last)} success (last 30)")
            evaluate(n)
            model.save(f"{OUT}/ft_{n}.zip")
        return True


evaluate(0)
model.learn(TOTAL, callback=Cb(), reset_num_timesteps=True)
log("done", results)
