"""What a trained model (timing or lander) was trained on, in its SB3 zip, checked on load.

SB3's zip holds the network; :data:`METADATA_NAME` beside it in the same archive (SB3 ignores
it) holds the model's card: the environment id with its version, the observation layout
(every setting that changes what an observation value means), the estimator whose deck pose
it observed, the sensing profiles it was trained under, the camera mode and the training
config.  :func:`check_compatible` compares a card with an environment and refuses a mismatch
with a :class:`~landing_env.errors.ConfigError` that names the field; a caller may accept
named mismatches on purpose (``allow``), e.g. ``sensing`` to test an ideal-trained model
under realistic noise.

``deck-landing model show MODEL.zip`` prints a card.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

from landing_env.anticipation.deck_history import HISTORY_FEATURES
from landing_env.config import SENSOR_SETS
from landing_env.envs.deck_landing import PRIVILEGED_KEY
from landing_env.errors import ConfigError
from landing_env.scenarios import LANDING_TASK, TIMING_TASK
from landing_env.timing.layout import (
    HISTORY_SCALES,
    OBSERVATION_LIMIT,
    TOF_SCALE,
    timing_layout,
)

#: the card's name inside the SB3 zip
METADATA_NAME = "deck_landing_metadata.json"
#: version of the card's own format
CARD_FORMAT = 1
#: the fields of a card that an environment must match, in the order they are checked
CHECKED_FIELDS: tuple[str, ...] = ("env_id", "observation", "estimator", "sensing")


@dataclass
class ModelMetadata:
    """A trained timing model's card (see the module docstring)."""

    #: the registered id it was trained on, with its version (``DeckLandingTiming-BenchSS4-v6``)
    env_id: str
    #: :func:`observation_signature` of the environment it was trained in
    observation: dict[str, Any]
    #: ``estimation.observed`` during training
    estimator: str
    #: the sensing profiles (:func:`sensing_profile`) it was trained under
    sensing: list[str]
    #: ``camera.mode`` during training (recorded; ``render`` at evaluation is allowed)
    camera_mode: str = "project"
    algo: str = ""
    #: the training YAML's contents and where it came from
    training_config: dict[str, Any] = field(default_factory=dict)
    training_config_source: str = ""
    note: str = ""
    format: int = CARD_FORMAT
    #: the observation signatures of the other timing tasks it was trained over, where one
    #: fit spans several (the look-ahead's features on the ship's and the bench's descents):
    #: an environment matches ``observation`` or one of these
    other_observations: list[dict[str, Any]] = field(default_factory=list)

    #: the other registered ids it was trained on, where a fit spans several scenarios
    other_env_ids: list[str] = field(default_factory=list)

    def env_ids(self) -> list[str]:
        """Every registered id it was trained on, ``env_id`` first."""
        return [self.env_id, *self.other_env_ids]

    def observations(self) -> list[dict[str, Any]]:
        """Every observation signature it was trained on, ``observation`` first."""
        return [self.observation, *self.other_observations]

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2, sort_keys=False)

    @classmethod
    def from_json(cls, text: str, where: str = "metadata") -> ModelMetadata:
        data = json.loads(text)
        if not isinstance(data, dict):
            raise ConfigError(where, "is not a JSON object")
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(where, f"unknown fields {unknown}; allowed {sorted(known)}")
        missing = [
            name for name in ("env_id", "observation", "estimator", "sensing") if name not in data
        ]
        if missing:
            raise ConfigError(where, f"missing fields {missing}")
        return cls(**data)


# ------------------------------------------------------------------------------ signatures
def sensing_profile(config: Any, profile: str | None = None) -> str:
    """The sensing profile of a ``DeckLandingConfig``.

    A config under ``sensors: realistic`` (or another named bundle) has that name; under
    ``sensors: ideal``, ``ideal`` when no sensor noise is configured, else the settings that
    depart from ideal (``tof.noise=vl53l1x``, ...).  ``profile`` names the profile the config
    was built from where it has a name of its own (``realistic-2x``, a bundle with its noise
    doubled: :data:`agents.training.sampler.SENSING_PROFILES`).  A lens other than the
    standard one is named after it (``realistic,lens=wide``): the camera sees another field
    at another resolution.
    """
    lens = getattr(config, "lens", "standard")
    suffix = "" if lens == "standard" else f",lens={lens}"
    return (profile or _sensing_without_lens(config)) + suffix


def _sensing_without_lens(config: Any) -> str:
    declared = getattr(config, "sensors", None) or "ideal"
    if declared != "ideal":
        # a named bundle (``sensors: realistic``: camera profile, ToF noise, distortion,
        # calibrations)
        return str(declared)
    departures = []
    if config.tof.noise != "none":
        departures.append(f"tof.noise={config.tof.noise}")
    if config.camera.pixel_noise_px > 0.0:
        departures.append(f"camera.pixel_noise_px={config.camera.pixel_noise_px:g}")
    if config.camera.dropout_prob > 0.0:
        departures.append(f"camera.dropout_prob={config.camera.dropout_prob:g}")
    return ",".join(departures) if departures else "ideal"


def _runnable(profiles: list[str]) -> str:
    """The first of a card's sensing profiles that flags can give (else the first)."""
    for profile in profiles:
        base = profile.partition(",lens=")[0]
        if base in SENSOR_SETS or "=" in base:
            return profile
    return profiles[0]


def sensing_flags(profile: str) -> str:
    """The command-line flags that give an environment the sensing ``profile``
    (:func:`sensing_profile`): ``--sensors realistic``, ``--set tof.noise=vl53l1x lens=wide``."""
    base, _, lens = profile.partition(",lens=")
    flags: list[str] = []
    settings = [f"lens={lens}"] if lens else []
    if "=" in base:  # ideal with departures: each a config key
        settings = base.split(",") + settings
    elif base in SENSOR_SETS:
        flags.append(f"--sensors {base}")
    else:  # a profile of the training's sampler (realistic-2x): no flag gives it
        return f"the training profile {profile!r}"
    if settings:
        flags.append("--set " + " ".join(settings))
    return " ".join(flags)


#: what a card written before a field was recorded was trained with (the descent was the
#: range-scheduled one until the timed descent came)
LEGACY_OBSERVATION: dict[str, Any] = {"descent": {"profile": "range"}}


def descent_signature(
    gains: Any,
    wave_off_tilt_deg: float = 0.0,
    wave_off_predictor: str = "linear",
    tilt_model: str = "",
    wave_off_probability: float = 0.8,
    wave_off_rule: str = "fixed",
    opportunity_s: float = 1.0,
    contact_times_s: tuple[float, ...] = (),
) -> dict[str, Any]:
    """The final descent a commit starts (:class:`~landing_env.guidance_gains.GuidanceGains`,
    and the timing task's wave-off): a timing policy learns how far ahead the touchdown comes
    and whether a bad commit is waved off, so another descent is another task even where the
    observation's layout is the same.  ``contact_times_s``: the contact times a commit
    chooses among (``TimingConfig.contact_window_s``; empty or one: the fixed descent)."""
    # the deck tracker's model and lead, where not the default (the ship's guidance from v2)
    tracking: dict[str, Any] = {}
    if getattr(gains, "tracker_model", "velocity") != "velocity" or getattr(
        gains, "deck_lead_s", 0.0
    ):
        tracking = {"tracker_model": gains.tracker_model, "deck_lead_s": float(gains.deck_lead_s)}
    # the go-around with the deck lost, where not the default (the ship's guidance from v3)
    if getattr(gains, "lost_deck", "descend") != "descend":
        tracking["lost_deck"] = gains.lost_deck
    # the relative speed held to the plan, where on (the ship's guidance from v8)
    if getattr(gains, "descent_rate_gain", 0.0):
        tracking["descent_rate_gain"] = float(gains.descent_rate_gain)
    if gains.descent_profile == "range":
        return {"profile": "range", **tracking}
    signature: dict[str, Any] = {
        **tracking,
        "profile": gains.descent_profile,
        "time_s": float(gains.descent_time_s),
        "touchdown_speed": float(gains.touchdown_speed),
    }
    if wave_off_tilt_deg > 0.0:
        signature["wave_off_tilt_deg"] = float(wave_off_tilt_deg)
        if wave_off_predictor != "linear":
            signature["wave_off_predictor"] = wave_off_predictor
        if wave_off_predictor == "model":
            signature["tilt_model"] = tilt_model
            if wave_off_rule == "value":
                signature["wave_off_rule"] = wave_off_rule
                signature["opportunity_s"] = float(opportunity_s)
            else:
                signature["wave_off_probability"] = float(wave_off_probability)
    if len(contact_times_s) > 1:
        # the descent's duration is chosen at each commit by this predictor
        signature["contact_times_s"] = [float(c) for c in contact_times_s]
        signature["tilt_model"] = tilt_model
    return signature


def observation_signature(timing: Any, env_hz: float) -> dict[str, Any]:
    """Every setting that changes what a timing observation's values mean.

    ``timing`` is a :class:`~landing_env.timing_config.TimingConfig`; the layout's own constants
    (features, scales, bounds) are included so that a change to them is caught too.
    """

    layout = timing_layout(timing, env_hz)
    n_history = layout.n_history
    # the prediction observation's values mean what its predictor and contact times make them
    prediction: dict[str, Any] = {}
    if timing.observation == "prediction":
        prediction = {
            "observation": timing.observation,
            "tilt_model": timing.tilt_model,
            "contact_times_s": [float(c) for c in timing.contact_times_s],
            "opportunity_s": float(timing.opportunity_s),
        }
    return {
        **prediction,
        "descent": descent_signature(
            timing.guidance,
            timing.wave_off_tilt_deg,
            timing.wave_off_predictor,
            timing.tilt_model,
            timing.wave_off_probability,
            timing.wave_off_rule,
            timing.opportunity_s,
            timing.contact_times_s,
        ),
        "size": layout.size,
        "n_history": n_history,
        "history_features": list(HISTORY_FEATURES),
        "history_scales": [float(v) for v in HISTORY_SCALES],
        "tof_scale": float(TOF_SCALE),
        "observation_limit": float(OBSERVATION_LIMIT),
        "env_hz": float(env_hz),
        "hold_height_m": float(timing.hold_height_m),
        "history_s": float(timing.history_s),
        "rate_window_s": float(timing.rate_window_s),
        "level_history": bool(timing.level_history),
        "steps_per_decision": int(timing.steps_per_decision),
        "wait_limit_s": float(timing.wait_limit_s),
    }


def _observing_wrapper(env: Any) -> Any:
    """The wrapper in ``env``'s chain that observes for the policy (one with a
    ``lookahead_settings``, :class:`agents.policies.lookahead.LookaheadTimingWrapper`), if any."""
    while isinstance(env, gym.Wrapper):
        if getattr(env, "lookahead_settings", None) is not None:
            return env
        env = env.env
    return None


def landing_observation_signature(space: Any, frame_stack: int = 1) -> dict[str, Any]:
    """What a ``DeckLanding`` observation is to a model: its keys with their shapes and
    bounds, and how many steps a model sees stacked (SB3's ``VecFrameStack``).  The
    ``privileged`` key is left out: only a critic reads it, and a trained actor flies an
    environment built without it."""
    keys = {
        key: {
            "shape": list(box.shape),
            "low": [float(v) for v in box.low.reshape(-1)[:1]],
            "high": [float(v) for v in box.high.reshape(-1)[:1]],
        }
        for key, box in sorted(space.spaces.items())
        if key != PRIVILEGED_KEY
    }
    return {"task": "DeckLanding", "keys": keys, "frame_stack": int(frame_stack)}


def model_class(path: Path) -> Any:
    """The SB3 algorithm that saved ``path`` (PPO, DQN, SAC; RecurrentPPO or TQC of
    sb3-contrib), read from the saved model's data without loading it."""
    from stable_baselines3 import DQN, PPO, SAC

    with zipfile.ZipFile(path) as archive:
        data = json.loads(archive.read("data"))
    module = str(data.get("policy_class", {}).get("__module__", ""))
    if module.startswith("sb3_contrib"):
        from sb3_contrib import TQC, RecurrentPPO

        return RecurrentPPO if "recurrent" in module else TQC
    for marker, algo in ((".dqn.", DQN), (".sac.", SAC)):
        if marker in module:
            return algo
    return PPO


def env_signature(env: Any, lookahead: Any = None, frame_stack: int = 1) -> dict[str, Any]:
    """The checked fields of a ``DeckLandingTiming`` or ``DeckLanding`` environment (wrapped
    or not; a ``DeckLanding`` model's observation is its keys and ``frame_stack``).

    ``env_id`` is the registered id it was made from, with its version (the bare task's where
    it was built directly).  Observed through the look-ahead (a wrapper with
    ``lookahead_settings`` in ``env``'s chain, or its ``lookahead`` settings given), the
    observation's size and meaning are the look-ahead's."""
    if lookahead is None:
        wrapper = _observing_wrapper(env)
        lookahead = wrapper.lookahead_settings if wrapper is not None else None
    base = env.unwrapped
    spec = getattr(base, "spec", None)
    if isinstance(base.action_space, gym.spaces.Box):  # the landing task (Box actions)
        return {
            "env_id": spec.id if spec is not None else LANDING_TASK,
            "observation": landing_observation_signature(base.observation_space, frame_stack),
            "estimator": base.config.estimation.observed,
            "sensing": sensing_profile(base.config),
            "camera_mode": base.config.camera.mode,
        }
    env_id = spec.id if spec is not None else TIMING_TASK
    observation = observation_signature(base.timing, base.config.simulation.env_hz)
    if lookahead is not None:
        observation = {**observation, "size": lookahead.size, "lookahead": lookahead.signature()}
    return {
        "env_id": env_id,
        "observation": observation,
        "estimator": base.config.estimation.observed,
        "sensing": sensing_profile(base.config),
        "camera_mode": base.config.camera.mode,
    }


def check_compatible(
    card: ModelMetadata,
    signature: dict[str, Any],
    model: str = "the model",
    allow: tuple[str, ...] | list[str] = (),
) -> None:
    """Refuse an environment (its ``signature``) that differs from what the model was trained
    on; a field named in ``allow`` may differ.  Fields missing from ``signature`` are not
    checked (e.g. a routine that knows only the observation)."""
    unknown = sorted(set(allow) - set(CHECKED_FIELDS))
    if unknown:
        raise ConfigError("allow_mismatch", f"unknown fields {unknown}; allowed {CHECKED_FIELDS}")
    hint = " (to use it anyway, allow the mismatch: --allow-mismatch {field})"
    for name in CHECKED_FIELDS:
        if name not in signature or name in allow:
            continue
        have = signature[name]
        if name == "observation":
            # the first of the trained observations' mismatches, unless one matches
            errors = [
                _observation_mismatch(trained, have, model) for trained in card.observations()
            ]
            first = errors[0]
            if first is not None and all(errors):
                more = len(errors) - 1
                if not more:
                    raise first
                raise ConfigError(
                    first.key,
                    f"{first.detail} (nor does it match the {more} other observation"
                    f"{'s' if more > 1 else ''} on its card)",
                )
            continue
        if name == "env_id":
            if have not in card.env_ids():
                raise ConfigError(
                    "env_id",
                    f"{model} was trained on {card.env_ids()}, the environment is {have!r}"
                    + hint.format(field="env_id"),
                )
            continue
        if name == "sensing":
            if have not in card.sensing:
                flags = sensing_flags(_runnable(card.sensing))
                raise ConfigError(
                    "sensing",
                    f"{model} was trained under sensing {card.sensing}, the environment's is "
                    f"{have!r}: run it under its own ({flags}; to use it anyway: "
                    "--allow-mismatch sensing)",
                )
            continue
        trained = getattr(card, name)
        if have != trained:
            raise ConfigError(
                name,
                f"{model} was trained on {trained!r}, the environment has {have!r}"
                + hint.format(field=name),
            )


def _observation_mismatch(
    trained: dict[str, Any], have: dict[str, Any], model: str
) -> ConfigError | None:
    """How the environment's observation ``have`` differs from a ``trained`` one (None: it
    does not)."""
    if trained.get("task") == "DeckLanding":  # a lander's: keys, shapes, stacking
        if trained != have:
            changed = sorted(
                key for key in set(trained) | set(have) if trained.get(key) != have.get(key)
            )
            old, new = trained.get(changed[0]), have.get(changed[0])
            if isinstance(old, dict) and isinstance(new, dict):
                # the observation's keys: name the entries that differ, not the whole space
                entries = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
                return ConfigError(
                    f"observation.{changed[0]}.{entries[0]}",
                    f"{model} was trained on another observation ({', '.join(entries)} "
                    f"differ: {old.get(entries[0])!r} against {new.get(entries[0])!r})",
                )
            return ConfigError(
                f"observation.{changed[0]}",
                f"{model} was trained on another observation ({', '.join(changed)} differ: "
                f"{trained.get(changed[0])!r} against {have.get(changed[0])!r})",
            )
        return None
    described = {**LEGACY_OBSERVATION, **trained}
    # what is observed first (history, prediction, forecast): the rest follows from it; a
    # signature without the key is the deck-pose history's
    described.setdefault("observation", "history")
    present = {"observation": "history", **have}
    for key in ("observation", *described):
        value = described[key]
        if present.get(key) != value:
            fix = f" (--set timing.observation={value})" if key == "observation" else ""
            return ConfigError(
                f"observation.{key}",
                f"{model} was trained with {value!r}, the environment has "
                f"{present.get(key)!r}: use the timing settings it was trained with{fix}"
                + (
                    " (the range-scheduled descent: --set timing.guidance.descent_profile=range)"
                    if key == "descent" and value == LEGACY_OBSERVATION["descent"]
                    else ""
                ),
            )
    extra = sorted(set(present) - set(described))
    if extra:
        return ConfigError(
            "observation", f"{model}'s card does not describe {extra}; retrain or re-stamp"
        )
    return None


def merge_cards(cards: list[ModelMetadata]) -> ModelMetadata:
    """One card for a model fitted on the data of several environments (``cards``: each one's
    card of the same training, the first the primary): their sensing profiles together and
    each distinct observation once, each registered id once.  Cards that differ in the
    estimator or the look-ahead's settings are refused: no one observation means the same in
    both."""
    if not cards:
        raise ConfigError("cards", "at least one card is needed")
    first = cards[0]
    for other in cards[1:]:
        for name in ("estimator", "camera_mode"):
            if getattr(other, name) != getattr(first, name):
                raise ConfigError(
                    name,
                    f"the fit's environments differ: {getattr(first, name)!r} and "
                    f"{getattr(other, name)!r}",
                )
        for key in ("size", "lookahead"):
            if other.observation.get(key) != first.observation.get(key):
                raise ConfigError(
                    f"observation.{key}", "the fit's environments observe differently"
                )
    observations: list[dict[str, Any]] = []
    for card in cards:
        for signature in card.observations():
            if signature not in observations:
                observations.append(signature)
    sensing = sorted({profile for card in cards for profile in card.sensing})
    env_ids: list[str] = []
    for card in cards:
        env_ids += [env_id for env_id in card.env_ids() if env_id not in env_ids]
    merged = ModelMetadata(**{**asdict(first), "sensing": sensing})
    merged.observation, merged.other_observations = observations[0], observations[1:]
    merged.env_id, merged.other_env_ids = env_ids[0], env_ids[1:]
    return merged


# ------------------------------------------------------------------------------ the zip
def read_metadata(path: str | Path) -> ModelMetadata | None:
    """The card inside a model zip; None when it has none."""
    path = Path(path)
    with zipfile.ZipFile(path) as archive:
        if METADATA_NAME not in archive.namelist():
            return None
        text = archive.read(METADATA_NAME).decode()
    return ModelMetadata.from_json(text, f"{path.name}:{METADATA_NAME}")


def write_metadata(path: str | Path, card: ModelMetadata) -> None:
    """Put ``card`` into the model zip (replacing an older card; the rest is copied as is)."""
    path = Path(path)
    with zipfile.ZipFile(path) as archive:
        entries = [
            (info, archive.read(info.filename))
            for info in archive.infolist()
            if info.filename != METADATA_NAME
        ]
    tmp = path.with_suffix(path.suffix + ".tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for info, data in entries:
            archive.writestr(info, data)
        archive.writestr(METADATA_NAME, card.to_json())
    tmp.replace(path)


def card_for_training(
    env: Any,
    config: Any,
    sensing: list[str] | None = None,
    lookahead: Any = None,
    frame_stack: int = 1,
) -> ModelMetadata:
    """The card of a model trained with ``config`` (:mod:`agents.training.trainer`) in environments
    like ``env`` (``sensing``: every profile the training sampled; ``lookahead``: the
    look-ahead settings it observed through, the env wrapped or not)."""
    signature = env_signature(env, lookahead, frame_stack)
    return ModelMetadata(
        env_id=signature["env_id"],
        observation=signature["observation"],
        estimator=signature["estimator"],
        sensing=sorted(set(sensing or [signature["sensing"]])),
        camera_mode=signature["camera_mode"],
        algo=config.settings.algo,
        training_config={
            "hyperparams": config.hyperparams,
            "deck_landing": asdict(config.settings),
        },
        training_config_source=str(config.source),
    )
