"""``deck-landing tune timing``: hyper-parameter search for the timing policy on Ray Tune.

The search YAML (``configs/train/tune_timing.yaml``) names a base training YAML, a budget
(trials, timesteps per trial, evaluation episodes, concurrent trials) and a small search space
over the zoo section's hyper-parameters (``choice``, ``uniform``, ``loguniform``).  Each trial
is one :func:`agents.training.trainer.train` run with the sampled values; it reports the success
rate of the evaluation at its end (``EvalCallback`` on held-out seeds), and Ray Tune keeps the best.
Ray runs on this machine by default, or on a cluster with ``--address``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from agents.common.parallel import ensure_ray
from agents.training.trainer import load_train_config, train
from estimation.limits import Limit, limited, require_limits
from landing_env.config import _calibration_path
from landing_env.config_loading import build_dataclass
from landing_env.errors import ConfigError

#: the samplers a search-space entry may use, and how many arguments each takes
SAMPLERS = {"choice": 1, "uniform": 2, "loguniform": 2}


@dataclass
class TuneSettings:
    """A search: the base training YAML, the budget and the space."""

    base: str = "configs/train/timing_dqn.yaml"
    samples: int = limited(8, Limit(1))
    timesteps: int = limited(20_000, Limit(1))
    eval_episodes: int = limited(20, Limit(1))
    max_concurrent: int = limited(2, Limit(1))
    seed: int = 0
    out_dir: str = "results/tune/timing"
    space: dict[str, Any] = field(default_factory=dict)
    #: extra keyword arguments of the environment (on top of the base YAML's)
    env_kwargs: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        require_limits(self)
        if not self.space:
            raise ConfigError("space", "is empty; give at least one hyper-parameter to search")
        for key, spec in self.space.items():
            if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in SAMPLERS:
                raise ConfigError(
                    f"space.{key}",
                    f"{spec!r}: give one of {sorted(SAMPLERS)}, e.g. {{uniform: [0, 1]}}",
                )
            ((kind, values),) = spec.items()
            if not isinstance(values, list) or (kind != "choice" and len(values) != 2):
                raise ConfigError(f"space.{key}.{kind}", f"{values!r} is not a list of bounds")


def load_tune_settings(path: str | Path) -> TuneSettings:
    """Read a search YAML; errors name the key."""

    path = _calibration_path(str(path), Path(path))  # "configs/..." works from anywhere
    if not path.is_file():
        raise ConfigError("config", f"{str(path)!r} does not exist")
    data = yaml.safe_load(path.read_text()) or {}
    if not isinstance(data, dict):
        raise ConfigError("config", f"{path} does not hold a mapping")
    return build_dataclass(TuneSettings, data, "")


def search_space(settings: TuneSettings) -> dict[str, Any]:
    """The space as Ray Tune samplers."""
    from ray import tune

    space: dict[str, Any] = {}
    for key, spec in settings.space.items():
        ((kind, values),) = spec.items()
        space[key] = tune.choice(values) if kind == "choice" else getattr(tune, kind)(*values)
    return space


def _trial(params: dict[str, Any], settings: TuneSettings, root: str) -> dict[str, float]:
    """One trial: train with the sampled values, return the final evaluation's success rate."""
    import os

    os.chdir(root)  # Ray Tune runs a trial in its own directory
    config = load_train_config(_resolve(settings.base))
    config.hyperparams.update(params)
    config.hyperparams["n_envs"] = 1
    s = config.settings
    s.seed = settings.seed
    s.vec_env = "dummy"
    s.eval.freq = settings.timesteps
    s.eval.episodes = settings.eval_episodes
    s.checkpoint_freq = settings.timesteps
    s.target_success_rate = 1.1  # run the whole budget
    s.env_kwargs = {**s.env_kwargs, **settings.env_kwargs}
    if "overrides" in settings.env_kwargs:
        base_overrides = load_train_config(_resolve(settings.base)).settings.env_kwargs
        s.env_kwargs["overrides"] = {
            **(base_overrides.get("overrides") or {}),
            **settings.env_kwargs["overrides"],
        }
    from ray import tune

    out = Path(tune.get_context().get_trial_dir() or ".")
    result = train(config, out_dir=out, total_timesteps=settings.timesteps, progress_bar=False)
    success = result.evaluations[-1][1] if result.evaluations else float("nan")
    return {"success_rate": success, "timesteps": float(result.timesteps)}


def _resolve(name: str) -> str:

    return str(_calibration_path(name, Path(name)))


@dataclass
class TuneResult:
    """Every trial's values and success rate, the best, and where they were written."""

    trials: list[dict[str, Any]]
    best: dict[str, Any]
    out_dir: Path


def tune_timing(settings: TuneSettings, address: str | None = None) -> TuneResult:
    """Run the search (see the module docstring)."""
    import os

    import ray
    from ray import tune

    out_dir = Path(settings.out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    started = ensure_ray(address, settings.max_concurrent)
    try:
        trainable = tune.with_parameters(_trial, settings=settings, root=os.getcwd())
        tuner = tune.Tuner(
            tune.with_resources(trainable, {"cpu": 1}),
            param_space=search_space(settings),
            tune_config=tune.TuneConfig(
                metric="success_rate",
                mode="max",
                num_samples=settings.samples,
                max_concurrent_trials=settings.max_concurrent,
                search_alg=tune.search.BasicVariantGenerator(random_state=settings.seed),
            ),
            run_config=tune.RunConfig(
                name="tune_timing", storage_path=str(out_dir / "ray"), verbose=0
            ),
        )
        grid = tuner.fit()
        trials = []
        for result in grid:
            if result.error is not None:
                trials.append({"config": result.config, "error": str(result.error)})
                continue
            trials.append({"config": result.config, **(result.metrics or {})})
        ok = [t for t in trials if "success_rate" in t]
        if not ok:
            raise RuntimeError(f"every trial failed: {trials[0].get('error') if trials else ''}")
        best = max(ok, key=lambda t: t["success_rate"])
    finally:
        if started:
            ray.shutdown()
    keep = ("config", "success_rate", "timesteps", "error")
    trials = [{k: t[k] for k in keep if k in t} for t in trials]
    (out_dir / "trials.json").write_text(json.dumps(trials, indent=2, default=float))
    (out_dir / "best.yaml").write_text(
        yaml.safe_dump(
            {"success_rate": float(best["success_rate"]), "hyperparams": best["config"]},
            sort_keys=False,
        )
    )
    return TuneResult(trials, {k: best[k] for k in keep if k in best}, out_dir)
