"""Actions of the landing tasks: validation against the action space, encoding and decoding.

Both environments check an action with :func:`validate_action` against their own action
space before anything moves: ``DeckLanding-v2``'s ``Box(5)`` velocity set-point and land
trigger (``Box(4)`` with ``action.land_trigger: false``) and ``DeckLandingTiming-v0``'s
``Discrete(2)`` wait/commit.  A bad action is refused with a
``ValueError`` that says what was given and what is allowed (never an ``OverflowError``,
``IndexError`` or ``TypeError`` from deeper down, and never silently flattened or cut).

:func:`setpoint_from_action` decodes the Box action into a heading-frame velocity set-point and
:func:`action_from_setpoint` encodes one (what the scripted policies output; their ``land``
entry is -1: they fly their own descent).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from landing_env.config import ActionConfig
from landing_env.physics.controller import VelocitySetpoint

#: the timing task's actions
WAIT, COMMIT = 0, 1
#: what each entry of the Box(4) velocity action means
BOX_ACTION_FIELDS: tuple[str, ...] = ("vx", "vy", "vz", "yaw_rate")
#: ``DeckLanding``'s fifth entry: above ``action.land_threshold`` it commits to the descent
LAND_FIELD = "land"


def action_fields(config: ActionConfig) -> tuple[str, ...]:
    """The entries of ``DeckLanding``'s Box action under ``config``: the velocity set-point,
    and ``land`` with ``land_trigger``."""
    return (*BOX_ACTION_FIELDS, LAND_FIELD) if config.land_trigger else BOX_ACTION_FIELDS


def _describe(action: Any) -> str:
    text = repr(action)
    if len(text) > 80:
        text = text[:77] + "..."
    return f"{text} ({type(action).__name__})"


def validate_action(action: Any, space: spaces.Space, meaning: str = "") -> Any:
    """``action`` checked against ``space``: an ``int`` for a ``Discrete`` space, a float64
    array of the space's shape for a ``Box``.  Raises ``ValueError`` naming what was wrong.

    A ``Discrete`` action is an integer (Python or NumPy, or a 0-d integer array) in the
    space; booleans, floats, strings, sequences and ``None`` are refused.  A ``Box`` action is
    real (integer or floating) and finite, with exactly the space's shape; values beyond the
    bounds are left to the environment (which clips and flags them).
    """
    suffix = f" ({meaning})" if meaning else ""
    if isinstance(space, spaces.Discrete):
        return _validate_discrete(action, space, suffix)
    if isinstance(space, spaces.Box):
        return _validate_box(action, space, suffix)
    raise TypeError(f"no action validation for {type(space).__name__} spaces")


def _validate_discrete(action: Any, space: spaces.Discrete, suffix: str) -> int:
    low, n = int(space.start), int(space.n)
    allowed = f"an integer in [{low}, {low + n - 1}]{suffix}"
    is_integer = isinstance(action, (int, np.integer)) and not isinstance(action, (bool, np.bool_))
    if isinstance(action, np.ndarray):
        is_integer = action.shape == () and np.issubdtype(action.dtype, np.integer)
    if not is_integer:
        raise ValueError(f"action must be {allowed}; got {_describe(action)}")
    value = int(action)
    if not low <= value < low + n:
        raise ValueError(f"action must be {allowed}; got {value}")
    return value


def _validate_box(action: Any, space: spaces.Box, suffix: str) -> np.ndarray:
    allowed = f"a real array of shape {space.shape}{suffix}"
    try:
        array = np.asarray(action)
    except (ValueError, TypeError) as error:  # ragged sequences
        raise ValueError(f"action must be {allowed}; got {_describe(action)}: {error}") from None
    if array.dtype.kind not in "iuf":
        raise ValueError(
            f"action must be {allowed}; got dtype {array.dtype} from {_describe(action)}"
        )
    if array.shape != space.shape:
        raise ValueError(f"action must be {allowed}; got shape {array.shape}")
    array = array.astype(np.float64)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"action must be finite; got {array}")
    return array


def setpoint_from_action(action: np.ndarray, config: ActionConfig) -> VelocitySetpoint:
    """The heading-frame set-point of a Box action in [-1, 1] (vx, vy, vz, yaw rate; a
    ``land`` entry after them is not a set-point)."""
    velocity = np.array(
        [
            action[0] * config.max_horizontal_speed,
            action[1] * config.max_horizontal_speed,
            action[2] * config.max_vertical_speed,
        ]
    )
    return VelocitySetpoint(velocity, float(action[3] * math.radians(config.max_yaw_rate_deg)))


def action_from_setpoint(setpoint: VelocitySetpoint, config: ActionConfig) -> np.ndarray:
    """A heading-frame set-point as the Box action in [-1, 1] (the inverse of
    :func:`setpoint_from_action` inside the bounds; beyond them it is clipped), with
    ``land`` at -1 (no commit) where ``config.land_trigger`` adds that entry."""
    v = setpoint.velocity_h
    command = [
        v[0] / config.max_horizontal_speed,
        v[1] / config.max_horizontal_speed,
        v[2] / config.max_vertical_speed,
        setpoint.yaw_rate / math.radians(config.max_yaw_rate_deg),
    ]
    if config.land_trigger:
        command.append(-1.0)
    # the guidance's limits lie inside the action's; this clip only guards hand-set gains
    return np.clip(np.array(command), -1.0, 1.0).astype(np.float32)
