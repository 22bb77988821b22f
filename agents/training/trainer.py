"""Training a landing policy with stable-baselines3: the timing task's (PPO, DQN,
RecurrentPPO) or a lander of ``DeckLanding`` (SAC, TQC, PPO).

``deck-landing train timing --config configs/train/timing_ppo.yaml`` and ``deck-landing train
landing --config configs/train/lander_ppo.yaml`` read a YAML with two top-level keys:

* a registered id (``DeckLandingTiming-BenchSS4-v6``: the scenario is built in, see
  :mod:`landing_env.scenarios`) holding the hyper-parameters in rl-zoo3's
  format (``n_envs``, ``n_timesteps``, ``policy``, ``policy_kwargs`` as a ``"dict(...)"``
  string, ``learning_rate`` as a number or ``"lin_<x>"``, ``frame_stack`` (SB3's
  ``VecFrameStack``, as rl-zoo3 applies it), and the algorithm's own keyword
  arguments), so that ``python -m rl_zoo3.train --env <id> --gym-packages landing_env
  --conf-file <yaml>`` trains the same task from the same file, unmodified;
* ``deck_landing``, which rl-zoo3 ignores: the algorithm, the seed, optional extra keyword
  arguments of the environment, the evaluation and checkpoint schedule, the
  target success rate and the wall-clock budget.

Training runs the environments in a ``SubprocVecEnv`` (one process per core), shows SB3's
progress bar, saves checkpoints, evaluates on held-out seeds (``EvalCallback``, which also
keeps the best model), logs to TensorBoard and stops early once the evaluation success rate
reaches the target.
"""

from __future__ import annotations

import ast
import importlib
import shutil
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml

from agents.common.cards import (
    card_for_training,
    check_compatible,
    env_signature,
    read_metadata,
    write_metadata,
)
from agents.policies.lander import model_normalization, normalization_path, shipped_lander_model
from agents.policies.lookahead import LookaheadSettings, LookaheadTimingWrapper
from agents.policies.timing import shipped_timing_model
from agents.training.imitation import ImitationSettings, imitate_and_save
from agents.training.learning_curve import read_learning_curve, write_learning_curve
from agents.training.sampler import RandomiseSettings, make_randomised_env, sensing_signatures
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, Limited, limited, require_limits
from landing_env.config_loading import build_dataclass
from landing_env.errors import ConfigError, require_choice
from landing_env.scenarios import LANDING_TASK, SCENARIO_IDS, SCENARIOS, TASKS, TIMING_TASK

#: the shipped training scenario: the timing task over a bench-ss4 deck, built into the id
SCENARIO_ENV_ID = SCENARIOS["bench-ss4"].ids[TIMING_TASK]
#: keys of the rl-zoo3 section that are not keyword arguments of the algorithm
ZOO_META_KEYS = ("n_envs", "n_timesteps", "policy", "normalize", "env_wrapper", "frame_stack")
ALGOS = ("ppo", "dqn", "recurrentppo", "sac", "tqc")
#: the algorithms of each task (Discrete actions for the timing task, Box for the lander)
TASK_ALGOS: dict[str, tuple[str, ...]] = {
    TIMING_TASK: ("ppo", "dqn", "recurrentppo"),
    LANDING_TASK: ("sac", "tqc", "ppo"),
}


@dataclass
class EvalSettings(Limited):
    """The evaluation during training (``EvalCallback``) on held-out seeds."""

    #: evaluate every this many environment steps (summed over the parallel environments)
    freq: int = limited(10_000, Limit(1))
    episodes: int = limited(40, Limit(1))
    #: seed of the evaluation environment; far from the training seeds
    seed: int = 900_000


@dataclass
class TrainSettings:
    """The ``deck_landing`` section of a training YAML."""

    algo: Literal["ppo", "dqn", "recurrentppo", "sac", "tqc"] = "ppo"
    seed: int = 0
    #: extra keyword arguments of ``gym.make(id, ...)`` (config, overrides, timing); empty
    #: in the shipped YAMLs, whose id has the scenario built in, so that rl-zoo3 trains the
    #: same task without ``--env-kwargs``
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    #: domain randomisation per episode (:class:`agents.training.sampler.RandomiseSettings`:
    #: scenarios, sensing profiles, estimator, wind, start heights); when set, the episodes
    #: come from it and ``env_kwargs`` keeps only ``timing``
    randomise: dict[str, Any] | None = None
    eval: EvalSettings = field(default_factory=EvalSettings)
    #: save a checkpoint every this many environment steps (summed over the environments)
    checkpoint_freq: int = limited(50_000, Limit(1))
    #: stop when the evaluation success rate reaches this (above 1: never stop early)
    target_success_rate: float = limited(0.95, NON_NEGATIVE)
    #: stop after this much wall-clock time, minutes (the run keeps what it has learnt)
    max_minutes: float = limited(30.0, POSITIVE)
    out_dir: str = "results/train/timing_ppo"
    #: "subproc" runs one process per environment; "dummy" runs them in this process
    vec_env: Literal["subproc", "dummy"] = "subproc"
    #: threads of the learner's torch: one, so that the gradient steps do not compete with
    #: the environment processes for the cores (the network is small)
    torch_threads: int = limited(1, Limit(1))
    #: start from this trained model's weights (same algorithm and network; its card must
    #: describe the same task, observation and estimator): training goes on from it
    init_model: str | None = None
    #: decide on the onboard look-ahead's features
    #: (:class:`agents.policies.lookahead.LookaheadSettings`: draws, check_every_s, min_margin,
    #: checks, seed) instead of the task's observation
    lookahead: dict[str, Any] | None = None
    #: imitate a scripted teacher before the algorithm learns
    #: (:class:`agents.training.imitation.ImitationSettings`: teacher, iterations, episodes,
    #: epochs, ...); the student is saved as ``imitation_model.zip``
    imitation: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        require_choice("algo", self.algo, ALGOS)
        require_choice("vec_env", self.vec_env, ("subproc", "dummy"))
        require_limits(self)
        if self.randomise is not None:
            build_dataclass(RandomiseSettings, self.randomise, "deck_landing.randomise")
        if self.lookahead is not None:
            if self.randomise is not None:
                raise ConfigError(
                    "deck_landing.lookahead",
                    "looks ahead in one scenario's environment; drop deck_landing.randomise",
                )
            build_dataclass(LookaheadSettings, self.lookahead, "deck_landing.lookahead")
        if self.imitation is not None:
            build_dataclass(ImitationSettings, self.imitation, "deck_landing.imitation")


@dataclass
class TrainConfig:
    """A training run: the zoo hyper-parameters and the deck-landing settings."""

    hyperparams: dict[str, Any]
    settings: TrainSettings
    source: str = ""
    #: the registered id the YAML's rl-zoo3 section is keyed by (the scenario built in)
    env_id: str = TIMING_TASK

    @property
    def task(self) -> str:
        """The task its id builds (``DeckLandingTiming-v0`` or ``DeckLanding-v2``)."""
        return self.env_id if self.env_id in TASKS else SCENARIO_IDS[self.env_id].task

    @property
    def frame_stack(self) -> int:
        """Steps stacked in the observation (rl-zoo3's ``frame_stack``; 1: none)."""
        return int(self.hyperparams.get("frame_stack", 1) or 1)

    @property
    def n_envs(self) -> int:
        return int(self.hyperparams.get("n_envs", 1))

    @property
    def n_timesteps(self) -> int:
        return int(float(self.hyperparams.get("n_timesteps", 100_000)))


@dataclass
class TrainResult:
    """What a training run produced."""

    model_path: Path
    best_model_path: Path | None
    timesteps: int
    wall_time_s: float
    #: (timesteps, success rate) of every evaluation
    evaluations: list[tuple[int, float]]
    stopped_because: str


def load_train_config(path: str | Path, algo: str | None = None) -> TrainConfig:
    """Read a training YAML (see the module docstring); ``algo`` overrides its ``algo``."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError("config", f"{str(path)!r} does not exist")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ConfigError("config", f"{path} is not YAML: {exc}") from None
    ids = _trainable_ids()
    keys = [key for key in data if key in ids] if isinstance(data, dict) else []
    if len(keys) != 1:
        raise ConfigError(
            "config",
            f"{path} needs one top-level section named by a registered id (rl-zoo3 style), "
            f"e.g. {SCENARIO_ENV_ID!r} or {SCENARIOS['bench-ss4'].ids[LANDING_TASK]!r}",
        )
    section = dict(data.get("deck_landing") or {})
    if algo is not None:
        section["algo"] = algo
    settings = build_dataclass(TrainSettings, section, "deck_landing")
    hyperparams = dict(data[keys[0]] or {})
    zoo_kwargs = hyperparams.pop("env_kwargs", None) or {}
    if not isinstance(zoo_kwargs, dict):
        raise ConfigError(f"{keys[0]}.env_kwargs", f"{zoo_kwargs!r} is not a mapping")
    # rl-zoo3 reads env_kwargs from the hyper-parameters: the same keywords here
    settings.env_kwargs = {**zoo_kwargs, **settings.env_kwargs}
    config = TrainConfig(hyperparams, settings, str(path), keys[0])
    allowed = TASK_ALGOS[config.task]
    if settings.algo not in allowed:
        raise ConfigError(
            "deck_landing.algo",
            f"{settings.algo!r} does not train {config.task} ({keys[0]}); choose one of "
            f"{', '.join(allowed)}",
        )
    frame_stack = hyperparams.get("frame_stack", 1)
    if not isinstance(frame_stack, int) or isinstance(frame_stack, bool) or frame_stack < 1:
        raise ConfigError(f"{keys[0]}.frame_stack", f"{frame_stack!r} is not an integer >= 1")
    if config.task == TIMING_TASK and frame_stack != 1:
        raise ConfigError(
            f"{keys[0]}.frame_stack", "the timing task's observation has its own history"
        )
    _check_stopping_rule_feature(hyperparams, keys[0])
    return config


def _check_stopping_rule_feature(hyperparams: dict[str, Any], section: str) -> None:
    """The stopping rule's margin feature (:class:`landing_env.privileged.DeckFeatures`) reads
    its key as the environment gives it: one frame, not normalised."""
    extractor = parse_policy_kwargs(hyperparams.get("policy_kwargs", {})).get(
        "features_extractor_kwargs", {}
    )
    key = extractor.get("stopping_rule_key") if isinstance(extractor, dict) else None
    if key is None:
        return
    if hyperparams.get("frame_stack", 1) != 1:
        raise ConfigError(
            f"{section}.frame_stack",
            f"the stopping rule's feature reads {key!r} as one frame: stack none (1)",
        )
    normalize = normalize_kwargs(hyperparams)
    if normalize is not None and key in (normalize.get("norm_obs_keys") or [key]):
        raise ConfigError(
            f"{section}.normalize",
            f"the stopping rule's feature reads {key!r} unnormalised: list the other keys "
            "in dict(norm_obs_keys=[...])",
        )


def _trainable_ids() -> tuple[str, ...]:
    """The ids a training YAML can name: both tasks and their registered scenarios."""
    return (*TASKS, *SCENARIO_IDS)


# ------------------------------------------------------------------------------ zoo syntax
def _literal(node: ast.AST, names: dict[str, Any]) -> Any:
    """Evaluate the small subset of Python rl-zoo3 uses in ``policy_kwargs`` strings."""
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        value = _literal(node.operand, names)
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise ValueError(f"a sign before {value!r}")
        return -value if isinstance(node.op, ast.USub) else value

    if isinstance(node, (ast.List, ast.Tuple)):
        values = [_literal(v, names) for v in node.elts]
        return values if isinstance(node, ast.List) else tuple(values)
    if isinstance(node, ast.Dict):
        if any(k is None for k in node.keys):
            raise ValueError("dict unpacking (**) is not supported")
        pairs = zip(node.keys, node.values, strict=True)
        return {_literal(k, names): _literal(v, names) for k, v in pairs}  # type: ignore[arg-type]
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict":
        if node.args:
            raise ValueError("dict(...) takes keyword arguments only")
        return {kw.arg: _literal(kw.value, names) for kw in node.keywords}
    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
        key = f"{node.value.id}.{node.attr}"
        if key in names:
            return names[key]
    raise ValueError(f"unsupported expression {ast.dump(node)}")


def parse_policy_kwargs(value: Any) -> dict[str, Any]:
    """``policy_kwargs`` as rl-zoo3 writes it (``"dict(net_arch=[64, 64])"``) or a mapping."""
    if isinstance(value, dict):
        return dict(value)
    from torch import nn

    names = {f"nn.{n}": getattr(nn, n) for n in ("ReLU", "Tanh", "ELU", "LeakyReLU", "SiLU")}
    try:
        parsed = _literal(ast.parse(str(value), mode="eval").body, names)
    except (SyntaxError, ValueError) as exc:
        raise ConfigError("policy_kwargs", f"{value!r}: {exc}") from None
    if not isinstance(parsed, dict):
        raise ConfigError("policy_kwargs", f"{value!r} is not a dict(...)")
    return parsed


def _schedule(value: Any, key: str) -> float | Callable[[float], float]:
    """A number, or rl-zoo3's ``"lin_<x>"`` (linear decay from x to 0 over the run)."""
    if isinstance(value, str) and value.startswith("lin_"):
        start = float(value[4:])
        return lambda progress_remaining: progress_remaining * start
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ConfigError(key, f"{value!r} is neither a number nor 'lin_<number>'") from None


def algorithm_kwargs(hyperparams: dict[str, Any]) -> dict[str, Any]:
    """The algorithm's keyword arguments from the zoo section (meta keys removed)."""
    kwargs = {k: v for k, v in hyperparams.items() if k not in ZOO_META_KEYS}
    if "policy_kwargs" in kwargs:
        kwargs["policy_kwargs"] = parse_policy_kwargs(kwargs["policy_kwargs"])
    for key in ("learning_rate", "clip_range"):
        if key in kwargs:
            kwargs[key] = _schedule(kwargs[key], key)
    if isinstance(kwargs.get("train_freq"), list):
        kwargs["train_freq"] = tuple(kwargs["train_freq"])
    return kwargs


# ------------------------------------------------------------------------------ callbacks
def _callbacks(config: TrainConfig, out: Path, eval_env: Any, started: float) -> tuple[Any, Any]:
    from stable_baselines3.common.callbacks import (
        BaseCallback,
        CallbackList,
        CheckpointCallback,
        EvalCallback,
    )

    settings = config.settings
    n_envs = max(config.n_envs, 1)

    class StopOnSuccessRate(BaseCallback):
        """After an evaluation: stop once its success rate reaches the target."""

        def _on_step(self) -> bool:
            successes = getattr(self.parent, "evaluations_successes", [])
            if successes and float(np.mean(successes[-1])) >= settings.target_success_rate:
                self.model._stopped_because = (  # type: ignore[attr-defined]
                    f"evaluation success rate {np.mean(successes[-1]):.3f} reached the target "
                    f"{settings.target_success_rate}"
                )
                return False
            return True

    class WallClockBudget(BaseCallback):
        """Stop after ``max_minutes`` of wall-clock time (a budget, not a measurement)."""

        def _on_step(self) -> bool:
            if time.perf_counter() - started > 60.0 * settings.max_minutes:
                self.model._stopped_because = (  # type: ignore[attr-defined]
                    f"wall-clock budget of {settings.max_minutes} min"
                )
                return False
            return True

    class SaveBestNormalization(BaseCallback):
        """On a new best model: save the training env's ``VecNormalize`` statistics beside
        it, so that the best model is run with the statistics it was evaluated with."""

        def _on_step(self) -> bool:
            normalize = self.model.get_vec_normalize_env()
            if normalize is not None:
                normalize.save(str(normalization_path(out / "best_model.zip")))
            return True

    evaluation = EvalCallback(
        eval_env,
        # SB3 counts callback calls per vectorised step: divide by the number of environments
        eval_freq=max(settings.eval.freq // n_envs, 1),
        n_eval_episodes=settings.eval.episodes,
        best_model_save_path=str(out),
        log_path=str(out / "eval"),
        deterministic=True,
        callback_after_eval=StopOnSuccessRate(),
        callback_on_new_best=SaveBestNormalization(),
        verbose=1,
    )
    checkpoints = CheckpointCallback(
        save_freq=max(settings.checkpoint_freq // n_envs, 1),
        save_path=str(out / "checkpoints"),
        name_prefix=_model_name(config),
        # each checkpoint with its VecNormalize statistics (lander-model reads them)
        save_vecnormalize=True,
    )
    return CallbackList([checkpoints, evaluation, WallClockBudget()]), evaluation


def _student_as_best(
    model: Any, train_env: Any, eval_env: Any, evaluation: Any, episodes: int, out: Path
) -> None:
    """The imitation's student evaluated as the ``EvalCallback`` evaluates and saved as the
    best model so far (with its statistics): the algorithm's evaluations replace it only with
    a better mean return."""
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import sync_envs_normalization

    if hasattr(train_env, "obs_rms"):
        sync_envs_normalization(train_env, eval_env)
    landed: list[bool] = []

    def count(local: dict[str, Any], _: dict[str, Any]) -> None:
        if local["done"]:
            landed.append(bool(local["info"].get("is_success", False)))

    returns, _ = evaluate_policy(
        model,
        eval_env,
        n_eval_episodes=episodes,
        deterministic=True,
        return_episode_rewards=True,
        callback=count,
    )
    evaluation.best_mean_reward = float(np.mean(returns))
    model.save(out / "best_model.zip")
    if hasattr(train_env, "obs_rms"):
        train_env.save(str(normalization_path(out / "best_model.zip")))
    print(
        f"imitation: the student lands {np.mean(landed):.0%} of {episodes} evaluation episodes "
        f"(mean return {np.mean(returns):.2f}): the best model until a better one",
        flush=True,
    )


def _model_name(config: TrainConfig) -> str:
    task = "lander" if config.task == LANDING_TASK else "timing"
    return f"{task}_{config.settings.algo}"


def training_wrapper(config: TrainConfig) -> Callable[[Any], Any] | None:
    """The YAML's rl-zoo3 ``env_wrapper`` (``module.Class``, or a mapping of it to keyword
    arguments), built as rl-zoo3 builds it; None without one.  A bad one names the key."""
    if not config.hyperparams.get("env_wrapper"):
        return None
    if config.settings.lookahead is not None:
        raise ConfigError(
            f"{config.env_id}.env_wrapper", "cannot be combined with deck_landing.lookahead"
        )
    from rl_zoo3.utils import get_wrapper_class

    try:
        return get_wrapper_class(config.hyperparams)
    except (ImportError, AttributeError, ValueError, TypeError) as error:
        raise ConfigError(f"{config.env_id}.env_wrapper", str(error)) from None


def make_envs(config: TrainConfig) -> tuple[Any, Any]:
    """The training VecEnv (SubprocVecEnv over ``n_envs`` processes) and the evaluation env."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    s = config.settings
    vec_cls = SubprocVecEnv if s.vec_env == "subproc" and config.n_envs > 1 else DummyVecEnv
    # the "module:id" form makes the worker processes import and register the package
    env_id: Any = f"landing_env:{config.env_id}"
    # make_vec_env asks for render_mode="rgb_array" unless told otherwise: nothing is rendered
    env_kwargs = {"render_mode": None, **s.env_kwargs}
    if s.randomise is not None:
        env_id = make_randomised_env
        env_kwargs = {
            "render_mode": None,
            "randomise": s.randomise,
            "timing": s.env_kwargs.get("timing", {}),
        }
    wrapping: dict[str, Any] = {}
    if s.lookahead is not None:
        wrapping = {"wrapper_class": LookaheadTimingWrapper, "wrapper_kwargs": s.lookahead}
    # rl-zoo3's env_wrapper (e.g. the lander's start curriculum) wraps the training
    # environments; the evaluation measures the task itself
    zoo_wrapper = training_wrapper(config)
    train_wrapping = wrapping if zoo_wrapper is None else {"wrapper_class": zoo_wrapper}
    train_env = make_vec_env(
        env_id,
        n_envs=config.n_envs,
        seed=s.seed,
        vec_env_cls=vec_cls,
        env_kwargs=env_kwargs,
        **train_wrapping,
    )
    eval_env = make_vec_env(env_id, n_envs=1, seed=s.eval.seed, env_kwargs=env_kwargs, **wrapping)
    if config.frame_stack > 1:
        from stable_baselines3.common.vec_env import VecFrameStack

        train_env = VecFrameStack(train_env, config.frame_stack)
        eval_env = VecFrameStack(eval_env, config.frame_stack)
    normalize = normalize_kwargs(config.hyperparams)
    if normalize is not None:
        from stable_baselines3.common.vec_env import VecNormalize

        # as rl-zoo3: the training env's statistics, the evaluation env reading them (SB3's
        # EvalCallback copies them before each evaluation) and scoring the raw reward
        train_env = VecNormalize(train_env, **normalize)
        eval_env = VecNormalize(eval_env, **{**normalize, "training": False, "norm_reward": False})
    return train_env, eval_env


def normalize_kwargs(hyperparams: dict[str, Any]) -> dict[str, Any] | None:
    """rl-zoo3's ``normalize`` key as ``VecNormalize``'s keyword arguments: ``true`` (its
    defaults), a ``"dict(...)"`` string or a mapping; None when absent or false.  As in
    rl-zoo3, the reward's discount is the algorithm's ``gamma``."""
    value = hyperparams.get("normalize", False)
    if value is False or value is None:
        return None
    kwargs: dict[str, Any] = {}
    if value is not True:
        try:
            kwargs = parse_policy_kwargs(value)
        except ConfigError:
            raise ConfigError(
                "normalize", f"{value!r} is not true, false or a dict(...) of VecNormalize's"
            ) from None
    if "gamma" in hyperparams:
        kwargs.setdefault("gamma", float(hyperparams["gamma"]))
    return kwargs


def resolve_policy(policy: Any) -> Any:
    """A policy name as rl-zoo3 reads it: an SB3 alias (``MultiInputPolicy``, the
    ``PrivilegedCriticPolicy`` of :mod:`landing_env.privileged`) or a ``module.Class`` path."""
    from landing_env.privileged import register_policy_aliases

    register_policy_aliases()
    if not isinstance(policy, str) or "." not in policy:
        return policy
    module, _, name = policy.rpartition(".")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as error:
        raise ConfigError("policy", f"{policy!r} does not import: {error}") from None


def _base_env(vec_env: Any) -> Any:
    """The first environment of a (possibly wrapped) ``DummyVecEnv``."""
    while not hasattr(vec_env, "envs"):
        vec_env = vec_env.venv
    return vec_env.envs[0]


def _start_from(model: Any, path: str, env: Any, train_env: Any = None) -> None:
    """Load ``path``'s weights into ``model`` after checking its card against ``env`` (the
    sensing may differ: a randomised training draws several), and, where the training
    normalises, the ``VecNormalize`` statistics the model was saved with (as rl-zoo3 does
    for ``--trained-agent``), which training then goes on updating."""

    found = Path(path)
    if not found.is_absolute() and not found.is_file():
        # a path in the repository (agents/models/...) from anywhere
        found = Path(__file__).resolve().parents[2] / path
    if not found.is_file():
        raise ConfigError("deck_landing.init_model", f"{path!r} does not exist")
    card = read_metadata(found)
    if card is None:
        raise ConfigError("deck_landing.init_model", f"{path} has no card")
    check_compatible(card, env_signature(env), found.name, allow=("sensing",))
    model.set_parameters(str(found), exact_match=True, device="cpu")
    saved = model_normalization(found)
    if saved is not None and hasattr(train_env, "obs_rms"):
        train_env.obs_rms = saved.obs_rms
        train_env.ret_rms = saved.ret_rms


def _card(config: TrainConfig, eval_env: Any) -> Any:
    """The card of the models ``config`` trains: what they were trained on (checked when a
    model is loaded)."""
    settings = config.settings
    sensing = None
    if settings.randomise is not None:
        sensing = sensing_signatures(
            build_dataclass(RandomiseSettings, settings.randomise, "deck_landing.randomise")
        )
    lookahead = None
    if settings.lookahead is not None:
        lookahead = build_dataclass(LookaheadSettings, settings.lookahead, "deck_landing.lookahead")
    return card_for_training(
        _base_env(eval_env),
        config,
        sensing=sensing,
        lookahead=lookahead,
        frame_stack=config.frame_stack,
    )


def install_path(config: TrainConfig) -> Path:
    """Where ``--install`` copies the model ``config`` trains (its task's and algorithm's)."""
    algo = config.settings.algo
    return shipped_lander_model(algo) if config.task == LANDING_TASK else shipped_timing_model(algo)


def train(
    config: TrainConfig,
    out_dir: str | Path | None = None,
    total_timesteps: int | None = None,
    progress_bar: bool = True,
    install: bool = False,
    force: bool = False,
) -> TrainResult:
    """Train, evaluate and save; with ``install`` copy the best model to the shipped path,
    which, when a model is there (a policy flies it), only ``force`` replaces: refused
    before training."""
    import torch
    from sb3_contrib import TQC, RecurrentPPO
    from stable_baselines3 import DQN, PPO, SAC
    from stable_baselines3.common.logger import configure

    settings = config.settings
    target = install_path(config)
    if install and target.exists() and not force:
        raise ConfigError(
            "--install",
            f"would replace {target}, a shipped model a policy flies (deck-landing list "
            "models); add --force to replace it, or leave --install out and evaluate the "
            "trained model with --model",
        )
    torch.set_num_threads(settings.torch_threads)
    out = Path(out_dir or settings.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "train_config.yaml").write_text(
        yaml.safe_dump(
            {"hyperparams": config.hyperparams, "source": config.source}, sort_keys=False
        )
    )
    algorithms = {"ppo": PPO, "dqn": DQN, "recurrentppo": RecurrentPPO, "sac": SAC, "tqc": TQC}
    algo_cls = algorithms[settings.algo]
    default_policy = "MlpLstmPolicy" if settings.algo == "recurrentppo" else "MlpPolicy"
    if config.task == LANDING_TASK:
        default_policy = "MultiInputPolicy"  # the landing task observes a Dict
    steps = int(total_timesteps if total_timesteps is not None else config.n_timesteps)
    started = time.perf_counter()
    train_env, eval_env = make_envs(config)
    try:
        model = algo_cls(
            resolve_policy(config.hyperparams.get("policy", default_policy)),
            train_env,
            seed=settings.seed,
            tensorboard_log=str(out / "tb"),
            device="cpu",
            verbose=0,
            **algorithm_kwargs(config.hyperparams),
        )
        # SB3's TensorBoard log and its CSV twin (progress.csv) in one folder
        model.set_logger(configure(str(out / "tb" / _model_name(config)), ["csv", "tensorboard"]))
        if settings.init_model:
            _start_from(model, settings.init_model, _base_env(eval_env), train_env)
        card = _card(config, eval_env)
        saved_models = [out / "best_model.zip"]
        if settings.imitation is not None:
            imitation = build_dataclass(
                ImitationSettings, settings.imitation, "deck_landing.imitation"
            )
            saved_models.append(
                imitate_and_save(
                    model, train_env, _base_env(eval_env), imitation, settings.seed, out
                )
            )
            write_metadata(saved_models[-1], card)
        callbacks, evaluation = _callbacks(config, out, eval_env, started)
        if settings.imitation is not None:
            _student_as_best(model, train_env, eval_env, evaluation, settings.eval.episodes, out)
        model._stopped_because = "all timesteps done"  # type: ignore[attr-defined]
        with warnings.catch_warnings():
            # the evaluation env runs in this process on purpose (a DummyVecEnv of one)
            warnings.filterwarnings("ignore", message="Training and eval env are not of the same")
            try:
                model.learn(
                    total_timesteps=steps,
                    callback=callbacks,
                    progress_bar=progress_bar,
                    tb_log_name=_model_name(config),
                )
            except KeyboardInterrupt:
                # Ctrl-C ends the run as a budget would: the model, its statistics and the
                # cards are saved below
                model._stopped_because = "interrupted"  # type: ignore[attr-defined]
        model_path = out / f"{_model_name(config)}_final.zip"
        model.save(model_path)
        if hasattr(train_env, "obs_rms"):
            # the normalisation the model was trained under (rl-zoo3's file name)
            train_env.save(str(out / "vecnormalize.pkl"))
    finally:
        for env in (train_env, eval_env):
            try:
                env.close()
            except (EOFError, BrokenPipeError, ConnectionResetError):
                pass  # a subprocess environment already ended by Ctrl-C
    wall = time.perf_counter() - started
    best = out / "best_model.zip"
    for saved in (model_path, *saved_models):
        if saved.is_file():
            write_metadata(saved, card)
    evaluations = [
        (int(t), float(np.mean(s)))
        for t, s in zip(
            evaluation.evaluations_timesteps, evaluation.evaluations_successes, strict=False
        )
    ]
    result = TrainResult(
        model_path=model_path,
        best_model_path=best if best.is_file() else None,
        timesteps=int(model.num_timesteps),
        wall_time_s=wall,
        evaluations=evaluations,
        stopped_because=model._stopped_because,  # type: ignore[attr-defined]
    )
    (out / "train_summary.yaml").write_text(
        yaml.safe_dump(
            {
                "timesteps": result.timesteps,
                "wall_time_s": round(wall, 1),
                "stopped_because": result.stopped_because,
                "evaluations": [[t, round(s, 4)] for t, s in evaluations],
            },
            sort_keys=False,
        )
    )
    if evaluations:
        write_learning_curve(
            read_learning_curve(out), out / "learning_curve.png", _model_name(config)
        )
    if install:
        source = result.best_model_path or model_path
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)
        statistics = normalization_path(source)
        if not statistics.is_file():
            statistics = source.parent / "vecnormalize.pkl"
        if statistics.is_file():
            shutil.copyfile(statistics, normalization_path(target))
    return result
