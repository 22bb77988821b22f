"""Fuzz soak of DeckLanding-v2: crashes, observations outside the space, NaN rewards, memory.

    python -m benchmarks.fuzz_soak                       # 1e5 project + 1e4 render steps
    python -m benchmarks.fuzz_soak --project-steps 20000 --render-steps 2000   # shorter
    python -m benchmarks.fuzz_soak --parts config --keys wind.   # the config keys under wind

Three parts, each printing its figures and writing ``<part>.json`` under ``--out``
(``results/fuzz_soak``) as it goes (re-written after every config):

1. ``project``: fuzzed episodes over every shipped config (steps split evenly; the
   configs that pin the drone also run with it free) in the ``project`` camera mode:
   random seeds, actions drawn in the box (uniform, extreme corners, or a descent with
   noise, so that touchdowns, settles and flips happen), every observation checked against
   ``observation_space`` and every reward for finiteness.  Memory: the RSS at 10 % and 100 %
   of each config's steps (flat = no leak), and after the first config and at the end.
2. ``render``: the same in ``render`` mode (pupil-apriltags on rendered windows).
3. ``config``: one key at a time, every numeric key of the config tree set to NaN, +-inf,
   0, -1, +-1e9 and 0.1x / 10x its default, and every key to a string, None, a mapping
   and a mixed list: each must either build and run
   (``--config-steps`` steps, observations in space, finite rewards) or raise a
   ``ConfigError`` naming that key.  ``--keys`` limits it to the keys that start with a
   prefix.

An exception inside reset()/step() counts as a crash (its traceback is saved); a native
crash would end the process, and the JSON written so far says where.
"""

from __future__ import annotations

import argparse
import json
import math
import time
import traceback
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import landing_env  # noqa: F401  (registers the environments)
from landing_env.config import DeckLandingConfig, available_configs, load_config
from landing_env.config_limits import config_leaves, numeric_leaves
from landing_env.errors import ConfigError

OUT_DIR = Path("results/fuzz_soak")


def rss_mib() -> float:
    """Resident set size of this process, MiB (Linux /proc)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return math.nan


@dataclass
class Tally:
    steps: int = 0
    episodes: int = 0
    crashes: int = 0
    out_of_space: int = 0
    nan_rewards: int = 0
    outcomes: dict[str, int] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    #: RSS after a tenth of the steps and at the end, MiB (the growth in between is a leak)
    rss_mib_at_10pct: float = math.nan
    rss_mib_at_end: float = math.nan

    def add(self, other: Tally) -> None:
        self.steps += other.steps
        self.episodes += other.episodes
        self.crashes += other.crashes
        self.out_of_space += other.out_of_space
        self.nan_rewards += other.nan_rewards
        for key, count in other.outcomes.items():
            self.outcomes[key] = self.outcomes.get(key, 0) + count
        self.errors.extend(other.errors[:5])


def _actions(rng: np.random.Generator, kind: str, n: int) -> Iterator[np.ndarray]:
    """An endless stream of ``n``-entry actions of one kind."""
    while True:
        if kind == "uniform":
            yield rng.uniform(-1.0, 1.0, n).astype(np.float32)
        elif kind == "extreme":
            yield rng.choice([-1.0, 1.0], n).astype(np.float32)
        else:  # descend: down at full rate with some lateral noise
            action = np.clip(rng.normal(0.0, 0.3, n), -1.0, 1.0)
            action[2] = -1.0
            yield action.astype(np.float32)


def soak(
    env: gym.Env, steps: int, rng: np.random.Generator, bar: tqdm, max_errors: int = 5
) -> Tally:
    """Fuzzed episodes until ``steps`` steps were taken in ``env``."""
    tally = Tally()
    space = env.observation_space
    need_reset = True
    actions: Iterator[np.ndarray] = iter(())
    while tally.steps < steps:
        try:
            if need_reset:
                observation, _ = env.reset(seed=int(rng.integers(2**31)))
                tally.episodes += 1
                need_reset = False
                kind = str(rng.choice(["uniform", "extreme", "descend"]))
                actions = _actions(rng, kind, env.action_space.shape[0])
                if not space.contains(observation):
                    tally.out_of_space += 1
            observation, reward, terminated, truncated, info = env.step(next(actions))
        except Exception:  # a crash is what this counts
            tally.crashes += 1
            if len(tally.errors) < max_errors:
                tally.errors.append(traceback.format_exc(limit=6))
            need_reset = True
            tally.steps += 1
            bar.update(1)
            continue
        tally.steps += 1
        bar.update(1)
        if tally.steps == max(1, steps // 10):
            tally.rss_mib_at_10pct = rss_mib()
        if not space.contains(observation):
            tally.out_of_space += 1
        if not math.isfinite(float(reward)):
            tally.nan_rewards += 1
        if terminated or truncated:
            outcome = str(info.get("outcome", "truncated" if truncated else "?"))
            tally.outcomes[outcome] = tally.outcomes.get(outcome, 0) + 1
            need_reset = True
    tally.rss_mib_at_end = rss_mib()
    return tally


def soak_variants() -> list[tuple[str, str, dict]]:
    """(label, config, overrides): every shipped config as shipped, and those that pin the
    drone (the estimator benches) also with the drone free, so that their decks are landed on.
    """
    variants = []
    for name in available_configs():
        variants.append((name, name, {}))
        if load_config(name).simulation.drone_fixed:
            variants.append((f"{name}+free", name, {"simulation.drone_fixed": False}))
    return variants


def soak_configs(mode: str, total_steps: int, seed: int, out: Path = OUT_DIR) -> dict:
    configs = soak_variants()
    per_config = max(1, total_steps // len(configs))
    rng = np.random.default_rng(seed)
    result: dict = {"mode": mode, "steps_per_config": per_config, "configs": {}}
    total = Tally()
    rss_first = math.nan
    start = time.process_time()
    with tqdm(total=per_config * len(configs), desc=f"{mode} soak", unit="step") as bar:
        for index, (name, config, overrides) in enumerate(configs):
            overrides = {**overrides, "camera.mode": mode}
            env = gym.make("DeckLanding-v2", config=config, overrides=overrides)
            try:
                tally = soak(env, per_config, rng, bar)
            finally:
                env.close()
            total.add(tally)
            if index == 0:
                rss_first = rss_mib()
            result["configs"][name] = asdict(tally)
            result["total"] = {k: v for k, v in asdict(total).items() if k != "errors"}
            result["rss_mib_after_first_config"] = rss_first
            result["rss_mib_end"] = rss_mib()
            result["cpu_s"] = time.process_time() - start
            _write(out / f"{mode}.json", result)
    return result


def _shaped(default: object, number: float) -> object:
    if isinstance(default, tuple):
        return tuple(_shaped(item, number) for item in default)
    if isinstance(default, int) and not isinstance(default, bool):
        return int(number) if math.isfinite(number) and abs(number) < 2**62 else number
    return number


def _values(default: object) -> list[object]:
    numbers = np.asarray(default, dtype=float).reshape(-1)
    finite = numbers[np.isfinite(numbers)]
    base = float(finite[0]) if finite.size and finite[0] != 0.0 else 1.0
    raw = [math.nan, math.inf, -math.inf, 0.0, -1.0, 1e9, -1e9, 0.1 * base, 10.0 * base]
    return [_shaped(default, v) for v in raw]


def config_fuzz(steps: int, seed: int, out: Path = OUT_DIR, prefix: str = "") -> dict:
    """Every numeric key (those that start with ``prefix``), one at a time: a run, or a
    ConfigError naming the key."""
    leaves = [(k, d) for k, d in numeric_leaves(DeckLandingConfig) if k.startswith(prefix)]
    cases = [(key, value) for key, default in leaves for value in _values(default)]
    # every key, numeric or not, with values of the wrong type
    every = [(k, d) for k, d in config_leaves(DeckLandingConfig) if k.startswith(prefix)]
    cases += [(key, value) for key, _ in every for value in ("fuzz", None, {"a": 1}, [1, "x"])]
    rng = np.random.default_rng(seed)
    result: dict = {"numeric_keys": len(leaves), "keys": len(every), "cases": len(cases)}
    counts = {"ran": 0, "refused_naming_key": 0, "refused_naming_other": 0, "crashed": 0}
    problems: list[str] = []
    for key, value in tqdm(cases, desc="config fuzz", unit="case"):
        try:
            env = gym.make("DeckLanding-v2", overrides={key: value})
        except ConfigError as error:
            named = error.key.split("[", 1)[0] == key or key.rsplit(".", 1)[-1] in str(error)
            counts["refused_naming_key" if named else "refused_naming_other"] += 1
            if not named:
                problems.append(f"{key}={value!r}: {error}")
            continue
        except Exception as error:
            counts["crashed"] += 1
            problems.append(f"{key}={value!r}: make raised {type(error).__name__}: {error}")
            continue
        try:
            with tqdm(total=steps, disable=True) as bar:
                tally = soak(env, steps, rng, bar, max_errors=1)
        finally:
            env.close()
        if tally.crashes or tally.out_of_space or tally.nan_rewards:
            counts["crashed"] += 1
            problems.append(
                f"{key}={value!r}: {tally.crashes} crashes, {tally.out_of_space} out of space, "
                f"{tally.nan_rewards} NaN rewards {tally.errors[:1]}"
            )
        else:
            counts["ran"] += 1
        result.update(counts=counts, problems=problems)
        _write(out / "config.json", result)
    result.update(counts=counts, problems=problems)
    _write(out / "config.json", result)
    return result


def _write(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, default=str))


def _report(result: dict) -> None:
    total = result["total"]
    print(
        f"{result['mode']}: {total['steps']} steps, {total['episodes']} episodes over "
        f"{len(result['configs'])} config variants ({result['steps_per_config']} each); "
        f"crashes {total['crashes']}, observations outside the space {total['out_of_space']}, "
        f"NaN rewards {total['nan_rewards']}; RSS {result['rss_mib_after_first_config']:.1f} "
        f"MiB after the first config -> {result['rss_mib_end']:.1f} MiB at the end; "
        f"CPU {result['cpu_s']:.0f} s; outcomes {total['outcomes']}"
    )
    for name, tally in result["configs"].items():
        print(
            f"  {name}: {tally['steps']} steps, {tally['episodes']} episodes, crashes "
            f"{tally['crashes']}, out of space {tally['out_of_space']}, NaN rewards "
            f"{tally['nan_rewards']}, RSS {tally['rss_mib_at_10pct']:.1f} -> "
            f"{tally['rss_mib_at_end']:.1f} MiB from 10 % to 100 % of its steps"
        )
        for error in tally["errors"][:1]:
            print(f"  {name}: {error}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--project-steps", type=int, default=100_000)
    parser.add_argument("--render-steps", type=int, default=10_000)
    parser.add_argument("--config-steps", type=int, default=20, help="steps per fuzzed key")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--parts", nargs="+", default=["project", "render", "config"])
    parser.add_argument("--keys", default="", help="fuzz only the config keys with this prefix")
    parser.add_argument("--out", type=Path, default=OUT_DIR, help="folder of the JSON files")
    args = parser.parse_args()
    if not any(key.startswith(args.keys) for key, _ in config_leaves(DeckLandingConfig)):
        parser.error(f"--keys: no config key starts with {args.keys!r}")
    if "project" in args.parts:
        _report(soak_configs("project", args.project_steps, args.seed, args.out))
    if "render" in args.parts:
        _report(soak_configs("render", args.render_steps, args.seed + 1, args.out))
    if "config" in args.parts:
        result = config_fuzz(args.config_steps, args.seed + 2, args.out, args.keys)
        print(
            f"config fuzz: {result['keys']} keys ({result['numeric_keys']} numeric), "
            f"{result['cases']} cases: {result['counts']}"
        )
        for problem in result["problems"][:20]:
            print(f"  {problem}")


if __name__ == "__main__":
    main()
