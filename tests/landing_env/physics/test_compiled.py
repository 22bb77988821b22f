"""The compiled forms of the physics loop's plain-float functions (Numba, optional) give the
Python functions' floats bit for bit, on random inputs; without Numba the Python functions run.
"""

from __future__ import annotations

import math
import struct
from math import hypot, remainder

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from landing_env.physics import compiled as compiled_module
from landing_env.physics.compiled import (
    COMPILED_ENV,
    compiled,
    compiled_available,
    cpython_remainder,
    why_not_compiled,
)
from landing_env.physics.controller import (
    MEMORY_SIZE,
    CascadeController,
    VelocitySetpoint,
    cascade_step,
)
from landing_env.physics.drone_state import DroneState, rotation_from_quaternion
from landing_env.physics.quadrotor import motor_step
from landing_env.physics.quadrotor_params import QuadrotorParams
from landing_env.stewart.platform import plate_velocity, quat_from_euler_zyx

needs_numba = pytest.mark.skipif(
    not compiled_available(), reason=why_not_compiled() or "compiled forms available"
)

PROPERTY = settings(max_examples=100, deadline=None)
PARAMS = QuadrotorParams.from_yaml()
DT = 1.0 / 240.0


def bits(value):
    """Every bit of a result: floats by their IEEE 754 bytes (NaN's payload too)."""
    if isinstance(value, (tuple, list, np.ndarray)):
        return tuple(bits(v) for v in list(value))
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    return struct.pack("<d", float(value))


# floats over many magnitudes, the signed zeros and the non-finite ones
anything = st.floats(allow_nan=True, allow_infinity=True)
magnitudes = st.floats(-1e6, 1e6, allow_nan=False) | st.sampled_from([0.0, -0.0, 1e-300])


@st.composite
def unit_quaternions(draw: st.DrawFn) -> tuple[float, float, float, float]:
    q = np.array(draw(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)))
    norm = float(np.linalg.norm(q))
    if norm < 1e-3:
        return (0.0, 0.0, 0.0, 1.0)
    x, y, z, w = (q / norm).tolist()
    return (x, y, z, w)


def vectors(scale: float) -> st.SearchStrategy:
    return st.tuples(*(st.floats(-scale, scale, allow_nan=False),) * 3)


@needs_numba
@PROPERTY
@given(x=anything, y=anything)
def test_the_compiled_hypot_is_cpythons_to_the_bit(x: float, y: float) -> None:
    hypot = compiled(_hypot_caller)
    assert bits(hypot(x, y)) == bits(math.hypot(x, y))


@needs_numba
@PROPERTY
@given(x=st.floats(-1e12, 1e12, allow_nan=False) | st.sampled_from([math.nan, math.tau, -math.pi]))
def test_the_compiled_remainder_is_cpythons_to_the_bit(x: float) -> None:
    remainder = compiled(_remainder_caller)
    assert bits(remainder(x)) == bits(math.remainder(x, math.tau))


def _hypot_caller(x: float, y: float) -> float:
    return hypot(x, y)  # cpython_hypot when compiled


def _remainder_caller(x: float) -> float:
    return remainder(x, math.tau)  # cpython_remainder when compiled


@needs_numba
@PROPERTY
@given(
    q=unit_quaternions(),
    velocity=vectors(30.0),
    rates=vectors(20.0),
    setpoint=vectors(8.0),
    yaw_rate=st.floats(-5.0, 5.0),
    memory=st.lists(st.floats(-40.0, 40.0), min_size=MEMORY_SIZE, max_size=MEMORY_SIZE),
    cap=st.sampled_from([math.inf]) | st.floats(0.0, 30.0),
    axis=st.none() | unit_quaternions(),
    first=st.booleans(),
)
def test_the_compiled_cascade_gives_the_python_cascades_floats(
    q, velocity, rates, setpoint, yaw_rate, memory, cap, axis, first
) -> None:
    python = CascadeController(PARAMS, compiled_step=False)
    fast = CascadeController(PARAMS, compiled_step=True)
    state = DroneState(
        np.zeros(3), np.array(q), np.array(rotation_from_quaternion(q)).reshape(3, 3),
        np.array(velocity), np.array(rates),
    )  # fmt: skip
    order = VelocitySetpoint(np.array(setpoint), yaw_rate)
    for controller in (python, fast):
        if not first:  # a controller in flight: its memory as drawn
            controller._initialised = True
            controller._memory[:] = memory
        controller.thrust_cap_n = cap
        controller.thrust_axis_w = None if axis is None else axis[:3]
    for _ in range(2):  # the second step reads the memory the first left
        commands = python.update_floats(state, order, DT)
        assert bits(fast.update_floats(state, order, DT)) == bits(commands)
        assert bits(fast._memory) == bits(python._memory)
        assert fast.status == python.status
        assert bits(fast.last_torque_setpoint_b) == bits(python.last_torque_setpoint_b)


@needs_numba
@PROPERTY
@given(
    speeds=st.tuples(*(st.floats(0.0, 3000.0),) * 4),
    commands=st.tuples(*(st.floats(-100.0, 4000.0) | st.just(math.nan),) * 4),
    armed=st.booleans(),
    gains=st.none() | st.tuples(*(st.floats(1.0, 2.0),) * 4),
    q=unit_quaternions(),
    velocity=vectors(30.0),
    wind=vectors(20.0),
)
def test_the_compiled_motors_give_the_python_motors_floats(
    speeds, commands, armed, gains, q, velocity, wind
) -> None:
    constants = (
        0.3, 100.0, 2500.0, 2e-6,
        0.1, 0.1, 1e-8, -0.1, 0.1, -1e-8, -0.1, -0.1, 1e-8, 0.1, -0.1, -1e-8,
        0.2, 0.2, 0.1, 0.4, 1.5e-4,
    )  # fmt: skip
    args = (
        constants, *speeds, armed, *commands, gains is not None,
        *(gains or (1.0, 1.0, 1.0, 1.0)), rotation_from_quaternion(q), velocity, *wind,
    )  # fmt: skip
    assert bits(compiled(motor_step)(*args)) == bits(motor_step(*args))


@needs_numba
@PROPERTY
@given(
    angles=st.tuples(*(st.floats(-math.pi, math.pi),) * 3),
    target=vectors(5.0),
    target_q=unit_quaternions(),
    position=vectors(5.0),
    q=unit_quaternions(),
)
def test_the_compiled_deck_command_gives_the_python_floats(
    angles, target, target_q, position, q
) -> None:
    assert bits(compiled(quat_from_euler_zyx)(*angles)) == bits(quat_from_euler_zyx(*angles))
    args = (*target, target_q, position, q, 240.0, (0.0, 0.0, -0.02))
    assert bits(compiled(plate_velocity)(*args)) == bits(plate_velocity(*args))


def test_without_the_compiled_forms_the_python_functions_run(monkeypatch) -> None:
    monkeypatch.setenv(COMPILED_ENV, "0")
    assert not compiled_available()
    assert compiled(cascade_step) is cascade_step
    assert COMPILED_ENV in why_not_compiled() or compiled_module.numba is None
    with pytest.raises(ValueError, match="compiled_step=True, but"):
        CascadeController(PARAMS, compiled_step=True)


def test_the_cpython_remainder_is_maths_to_the_bit_uncompiled_too() -> None:
    for x in (0.0, -0.0, 1.0, -7.5, math.pi, -math.pi, 3 * math.pi, 1e9, -1e-300, math.nan):
        assert bits(cpython_remainder(x, math.tau)) == bits(math.remainder(x, math.tau))
