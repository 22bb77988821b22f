"""Imitation before reinforcement: DAgger from a scripted teacher into the SB3 policy.

The lander's recipe (``configs/train/lander_ppo.yaml``, ``deck_landing.imitation``) starts PPO
from an actor that already flies the teacher's *how* and *when*.  The teacher is a registered
policy (``align-predictive``: ``align-descend``'s approach and hold, ``land`` by ``predictive``'s
stopping rule on the observed chances); it reads the raw observation, the student the
normalised one.  DAgger (Ross, Gordon and Bagnell, AISTATS 2011): the first iteration is flown
by the teacher, each later one by the student, every step labelled with the teacher's action;
the student is fitted on everything gathered so far.  The fit is a regression of the actor's
mean (the deterministic action) on the labels, a commit step of the ``land`` entry weighing
``commit_weight`` hold steps: commits are about 1 % of the steps, yet weighing the two classes
equally tips the student into committing early, and a false commit costs a landing where a
late one costs a moment.  The
critic is fitted on the discounted returns of the student's own episodes, so that PPO's first
advantages are not read off an untrained value function.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from agents.policies.lander import normalization_path
from agents.policies.registry import make_policy
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from landing_env.errors import require_choice

#: the teachers an imitation stage can name (registered landing policies)
TEACHERS = ("align-predictive",)


@dataclass
class ImitationSettings:
    """The ``deck_landing.imitation`` section of a training YAML."""

    #: the registered policy imitated
    teacher: str = "align-predictive"
    #: DAgger iterations; the first is flown by the teacher, the rest by the student
    iterations: int = limited(6, Limit(1, 100))
    #: episodes gathered per iteration, over the training environments
    episodes: int = limited(60, Limit(1))
    #: passes over the gathered steps after each iteration, the learning rate falling by
    #: ``decay`` over them (cosine): the hold must be imitated to a hundredth of the action
    #: range, for a lateral bias of 1 % of the speed range halves the landings
    epochs: int = limited(8, Limit(1))
    #: passes of the last iteration's fit
    final_epochs: int = limited(40, Limit(1))
    decay: float = limited(0.03, Limit(0.0, 1.0))
    batch_size: int = limited(256, Limit(1))
    learning_rate: float = limited(1e-3, POSITIVE)
    #: weight of the ``land`` entry's error against the set-points'
    land_weight: float = limited(1.0, NON_NEGATIVE)
    #: a commit step's weight in the ``land`` entry's error, a hold step's being 1
    commit_weight: float = limited(10.0, POSITIVE)
    #: passes of the critic over the student's returns after the last iteration
    value_epochs: int = limited(10, Limit(0))

    def __post_init__(self) -> None:
        require_choice("deck_landing.imitation.teacher", self.teacher, TEACHERS)
        require_limits(self)


@dataclass
class ImitationResult:
    """What the imitation stage did: per iteration, the episodes' success and the fit."""

    iterations: list[dict[str, float]]
    steps: int
    wall_time_s: float


class _Steps:
    """The steps gathered so far: raw observations (normalised at each fit, with the
    statistics as they then stand) and the teacher's actions."""

    def __init__(self) -> None:
        self.observations: dict[str, list[np.ndarray]] = {}
        self.actions: list[np.ndarray] = []

    def add(self, observation: dict[str, np.ndarray], actions: np.ndarray) -> None:
        for key, value in observation.items():
            self.observations.setdefault(key, []).append(np.asarray(value, np.float32))
        self.actions.append(np.asarray(actions, np.float32))

    def arrays(self) -> tuple[dict[str, np.ndarray], np.ndarray]:
        return (
            {key: np.concatenate(value) for key, value in self.observations.items()},
            np.concatenate(self.actions),
        )


def _discounted(rewards: list[float], gamma: float) -> np.ndarray:
    out = np.zeros(len(rewards), np.float32)
    running = 0.0
    for k in range(len(rewards) - 1, -1, -1):
        running = rewards[k] + gamma * running
        out[k] = running
    return out


def _rollouts(
    model: Any, venv: Any, teachers: list[Any], episodes: int, student: bool, gamma: float
) -> tuple[dict[str, np.ndarray], np.ndarray, dict[str, np.ndarray], np.ndarray, list[bool]]:
    """``episodes`` episodes over ``venv``, flown by the student (``student``) or the teacher,
    every step labelled by the teacher: raw observations, labels, and the episodes' raw
    observations with their discounted (normalised) returns; and each episode's success."""
    n = venv.num_envs
    observation = venv.reset()
    raw = _original(venv, observation)
    for teacher in teachers:
        teacher.reset()
    seen: dict[str, list[np.ndarray]] = {}
    labels: list[np.ndarray] = []
    episode_obs: list[dict[str, list[np.ndarray]]] = [{} for _ in range(n)]
    episode_rewards: list[list[float]] = [[] for _ in range(n)]
    value_obs: dict[str, list[np.ndarray]] = {}
    returns: list[np.ndarray] = []
    successes: list[bool] = []
    while len(successes) < episodes:
        teacher_actions = np.stack(
            [teachers[i].act({k: v[i] for k, v in raw.items()}) for i in range(n)]
        )
        for key, value in raw.items():
            seen.setdefault(key, []).append(np.array(value, np.float32))
            for i in range(n):
                episode_obs[i].setdefault(key, []).append(np.array(value[i], np.float32))
        labels.append(teacher_actions)
        if student:
            actions, _ = model.predict(observation, deterministic=True)
        else:
            actions = teacher_actions
        observation, rewards, dones, infos = venv.step(actions)
        raw = _original(venv, observation)
        for i in range(n):
            episode_rewards[i].append(float(rewards[i]))
            if dones[i]:
                successes.append(bool(infos[i].get("is_success", False)))
                for key, value in episode_obs[i].items():
                    value_obs.setdefault(key, []).append(np.stack(value))
                returns.append(_discounted(episode_rewards[i], gamma))
                episode_obs[i], episode_rewards[i] = {}, []
                teachers[i].reset()
    # the steps of episodes still under way are labelled too; their returns are not complete
    observations = {key: np.concatenate(value) for key, value in seen.items()}
    return (
        observations,
        np.concatenate(labels),
        {key: np.concatenate(value) for key, value in value_obs.items()},
        np.concatenate(returns),
        successes[:episodes],
    )


def _original(venv: Any, observation: Any) -> dict[str, np.ndarray]:
    """The raw observation under a ``VecNormalize`` (else the observation itself)."""
    if hasattr(venv, "get_original_obs"):
        return venv.get_original_obs()
    return observation


def _normalised(venv: Any, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    if hasattr(venv, "normalize_obs"):
        return venv.normalize_obs(observation)
    return observation


def _land_weights(labels: np.ndarray, land_weight: float, commit_weight: float) -> np.ndarray:
    """Per-step weights of the ``land`` entry: ``commit_weight`` on a commit, 1 on a hold,
    scaled to a mean of ``land_weight``."""
    weights = np.where(labels[:, -1] > 0.0, commit_weight, 1.0).astype(np.float32)
    return land_weight * weights / float(weights.mean())


def _regress(
    policy: Any,
    observations: dict[str, np.ndarray],
    loss_of: Any,
    parameters: list[Any],
    passes: int,
    settings: ImitationSettings,
    seed: int,
) -> float:
    """Minimise ``loss_of(batch, index)`` over ``parameters`` by Adam in shuffled batches,
    ``passes`` times over ``observations``, the learning rate falling by ``settings.decay``
    (cosine); the mean loss of the last pass."""
    import torch as th

    tensors = {key: th.as_tensor(value) for key, value in observations.items()}
    n = len(next(iter(tensors.values())))
    batches = -(-n // settings.batch_size)
    optimiser = th.optim.Adam(parameters, lr=settings.learning_rate)
    schedule = th.optim.lr_scheduler.CosineAnnealingLR(
        optimiser, T_max=max(passes * batches, 1), eta_min=settings.learning_rate * settings.decay
    )
    generator = np.random.default_rng(seed)
    policy.set_training_mode(True)
    mean_loss = 0.0
    for _ in range(passes):
        order = generator.permutation(n)
        total = 0.0
        for start in range(0, n, settings.batch_size):
            index = th.as_tensor(order[start : start + settings.batch_size])
            loss = loss_of({key: value[index] for key, value in tensors.items()}, index)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
            total += float(loss.detach())
        mean_loss = total / batches
    policy.set_training_mode(False)
    return mean_loss


def fit_actor(
    model: Any,
    observations: dict[str, np.ndarray],
    labels: np.ndarray,
    settings: ImitationSettings,
    seed: int,
    epochs: int | None = None,
) -> float:
    """Regress the actor's mean on ``labels`` (normalised ``observations``) over ``epochs``
    passes (default ``settings.epochs``); the mean loss of the last pass."""
    import torch as th

    policy = model.policy
    weights = th.as_tensor(_land_weights(labels, settings.land_weight, settings.commit_weight))
    targets = th.as_tensor(labels)

    def loss_of(batch: dict[str, Any], index: Any) -> Any:
        error = (policy.get_distribution(batch).distribution.mean - targets[index]) ** 2
        return error[:, :-1].sum(dim=1).mean() + (weights[index] * error[:, -1]).mean()

    # every weight but the exploration's (log_std stays where the recipe sets it)
    parameters = [p for name, p in policy.named_parameters() if name != "log_std"]
    passes = settings.epochs if epochs is None else epochs
    return _regress(policy, observations, loss_of, parameters, passes, settings, seed)


def fit_critic(
    model: Any,
    observations: dict[str, np.ndarray],
    returns: np.ndarray,
    settings: ImitationSettings,
    seed: int,
) -> float:
    """Regress the critic alone on the discounted returns (the actor stays as imitation
    fitted it); the mean squared error of the last pass."""
    import torch as th

    policy = model.policy
    targets = th.as_tensor(returns)

    def loss_of(batch: dict[str, Any], index: Any) -> Any:
        return ((policy.predict_values(batch).flatten() - targets[index]) ** 2).mean()

    parameters = [p for name, p in policy.named_parameters() if _is_critic(name)]
    return _regress(
        policy, observations, loss_of, parameters, settings.value_epochs, settings, seed
    )


#: the parameters of the critic alone (SB3's value head and trunk; the privileged critic's)
_CRITIC_PREFIXES = (
    "value_net",
    "vf_features_extractor",
    "mlp_extractor.value_net",
    "mlp_extractor.critic",
)


def _is_critic(name: str) -> bool:
    return name.startswith(_CRITIC_PREFIXES)


def imitate(
    model: Any,
    venv: Any,
    env: Any,
    settings: ImitationSettings,
    gamma: float,
    seed: int,
    out: Path | None = None,
    log: Any = None,
) -> ImitationResult:
    """DAgger from ``settings.teacher`` into ``model``'s actor over ``venv`` (the training
    environments; a ``VecNormalize`` goes on updating its statistics), the teacher built for
    ``env`` (one environment of the same task); then the critic on the student's returns.
    Progress goes to ``log`` (default: printed at once); the per-iteration figures to
    ``out/imitation.yaml``."""
    if log is None:

        def log(line: str) -> None:
            print(line, flush=True)

    teachers = [make_policy(settings.teacher, env) for _ in range(venv.num_envs)]
    steps = _Steps()
    records: list[dict[str, float]] = []
    started = time.perf_counter()
    value_obs: dict[str, np.ndarray] = {}
    returns = np.zeros(0, np.float32)
    for iteration in range(settings.iterations):
        student = iteration > 0
        observed, labels, value_obs, returns, successes = _rollouts(
            model, venv, teachers, settings.episodes, student, gamma
        )
        steps.add(observed, labels)
        observations, actions = steps.arrays()
        last = iteration == settings.iterations - 1
        loss = fit_actor(
            model,
            _normalised(venv, observations),
            actions,
            settings,
            seed + iteration,
            epochs=settings.final_epochs if last else settings.epochs,
        )
        record = {
            "iteration": iteration,
            "flown_by": "student" if student else "teacher",
            "success": float(np.mean(successes)),
            "steps": len(actions),
            "commit_share": float(np.mean(actions[:, -1] > 0.0)),
            "loss": round(loss, 5),
            "minutes": round((time.perf_counter() - started) / 60.0, 2),
        }
        records.append(record)
        log(
            f"imitation {iteration + 1}/{settings.iterations}: {record['flown_by']} flew "
            f"{settings.episodes} episodes, {record['success']:.0%} landed; "
            f"{record['steps']} steps, loss {loss:.4f}"
        )
        if out is not None:
            (out / "imitation.yaml").write_text(yaml.safe_dump(records, sort_keys=False))
            # the steps gathered, raw, to fit again without flying (np.load)
            np.savez_compressed(out / "imitation_steps.npz", labels=actions, **observations)
    if settings.value_epochs and len(returns):
        value_loss = fit_critic(model, _normalised(venv, value_obs), returns, settings, seed)
        log(f"imitation: critic fitted on {len(returns)} steps, mse {value_loss:.4f}")
    return ImitationResult(
        iterations=records,
        steps=int(sum(len(a) for a in steps.actions)),
        wall_time_s=time.perf_counter() - started,
    )


def imitate_and_save(
    model: Any, venv: Any, env: Any, settings: ImitationSettings, seed: int, out: Path
) -> Path:
    """:func:`imitate` (the model's own discount), then the student saved as
    ``out/imitation_model.zip`` with its ``VecNormalize`` statistics beside it
    (:func:`agents.policies.lander.normalization_path`).  Returns its path."""
    imitate(model, venv, env, settings, gamma=float(model.gamma), seed=seed, out=out)
    path = out / "imitation_model.zip"
    model.save(path)
    if hasattr(venv, "obs_rms"):
        venv.save(str(normalization_path(path)))
    return path
