"""Optional compiled forms of the physics loop's plain-float functions (Numba).

A function written in plain floats for the 240 Hz loop (the controller's cascade,
:func:`landing_env.physics.controller.cascade_step`) is compiled here with Numba's ``njit``
when Numba is installed (``pip install deck-landing[fast]``) and ``DECK_LANDING_COMPILED``
is not ``0``; otherwise the Python function itself runs.  Both give the same floats bit for
bit: no ``fastmath`` (no reassociation, no fused multiply-adds), and the two functions of
CPython's ``math`` that are not the C library's, ``hypot`` and ``remainder``, are compiled
as CPython computes them (:func:`cpython_hypot`, :func:`cpython_remainder`).
"""

from __future__ import annotations

import math
import os
import types
from collections.abc import Callable
from typing import Any

try:  # Numba is optional: without it every function runs as written
    import numba
    from llvmlite import ir
    from numba.core import types as nb_types
    from numba.extending import intrinsic
except ImportError:  # pragma: no cover - depends on the installation
    numba = None

#: the environment variable that turns the compiled forms off (``0``) where Numba is installed
COMPILED_ENV = "DECK_LANDING_COMPILED"


def compiled_available() -> bool:
    """Whether Numba is importable and the compiled forms are not turned off."""
    return numba is not None and os.environ.get(COMPILED_ENV, "1") != "0"


def why_not_compiled() -> str:
    """Why :func:`compiled_available` is False (empty when it is True)."""
    if numba is None:
        return "numba is not installed (pip install deck-landing[fast])"
    if os.environ.get(COMPILED_ENV, "1") == "0":
        return f"{COMPILED_ENV}=0 turns the compiled forms off"
    return ""


def cpython_remainder(x: float, y: float) -> float:
    """``math.remainder(x, y)`` as CPython computes it (``m_remainder``: from ``fmod``),
    for finite ``y`` other than 0 (a NaN ``x`` gives itself, an infinite one NaN)."""
    if math.isfinite(x):
        absx = abs(x)
        absy = abs(y)
        # fmod of two non-negative floats: Python's % gives it exactly (no sign to adjust)
        m = absx % absy
        c = absy - m
        if m < c:
            r = m
        elif m > c:
            r = -c
        else:
            r = m - 2.0 * ((0.5 * (absx - m)) % absy)
        return math.copysign(1.0, x) * r
    if math.isnan(x):
        return x
    return math.nan  # CPython raises ValueError here; the loop's angles are never infinite


def _fast_sum(a: float, b: float) -> tuple[float, float]:
    """Compensated sum of two floats with ``|a| >= |b|``: (sum, its rounding error)."""
    x = a + b
    return x, (a - x) + b


def cpython_hypot(x: float, y: float) -> float:
    """``math.hypot(x, y)`` as CPython computes it (``vector_norm``: a power-of-two
    scaling, exact squares, compensated sums and a correction of the square root), not the C
    library's ``hypot``.  Compiled only: it needs an exact fused multiply-add."""
    ax = abs(x)
    ay = abs(y)
    top = ax if ax > ay else ay
    if math.isinf(ax) or math.isinf(ay):
        return math.inf
    if math.isnan(ax) or math.isnan(ay):
        return math.nan
    if top == 0.0:
        return top
    factor = 1.0
    _, max_e = math.frexp(top)
    if max_e < -1023:  # subnormal: CPython scales by DBL_MIN first (ldexp would overflow)
        factor = 2.2250738585072014e-308
        ax /= factor
        ay /= factor
        top /= factor
        _, max_e = math.frexp(top)
    scale = math.ldexp(1.0, -max_e)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    for v in (ax, ay):
        v *= scale
        hi = v * v
        lo = _fma(v, v, -hi)
        csum, err = _fast_sum(csum, hi)
        frac1 += lo
        frac2 += err
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    hi = -h * h
    lo = _fma(-h, h, -hi)
    csum, err = _fast_sum(csum, hi)
    frac1 += lo
    frac2 += err
    v = csum - 1.0 + (frac1 + frac2)
    h += v / (2.0 * h)
    if factor != 1.0:
        return factor * (h / scale)
    return h / scale


def _fma(x: float, y: float, z: float) -> float:  # pragma: no cover - replaced when compiled
    raise NotImplementedError("an exact fused multiply-add exists only in the compiled form")


if numba is not None:

    @intrinsic
    def _llvm_fma(typingctx, x, y, z):
        """``llvm.fma.f64``: x * y + z with one rounding."""
        signature = nb_types.float64(nb_types.float64, nb_types.float64, nb_types.float64)

        def codegen(context, builder, sig, args):
            double = ir.DoubleType()
            fma = builder.module.declare_intrinsic(
                "llvm.fma", [double], ir.FunctionType(double, [double, double, double])
            )
            return builder.call(fma, args)

        return signature, codegen

    @numba.njit(cache=True)
    def _compiled_fma(x, y, z):
        return _llvm_fma(x, y, z)


def _rebound(function: Callable[..., Any], names: dict[str, Any]) -> Callable[..., Any]:
    """``function`` with some of its module's names bound to other objects (its own copy of
    the globals), for Numba to compile."""
    namespace = dict(function.__globals__)
    namespace.update(names)
    copy = types.FunctionType(
        function.__code__, namespace, function.__name__, function.__defaults__, function.__closure__
    )
    copy.__qualname__ = function.__qualname__
    copy.__module__ = function.__module__
    copy.__doc__ = function.__doc__
    return copy


_COMPILED: dict[Callable[..., Any], Callable[..., Any]] = {}


def compiled(function: Callable[..., Any]) -> Callable[..., Any]:
    """The Numba-compiled form of a plain-float ``function`` (``njit``, no ``fastmath``);
    ``function`` itself when :func:`compiled_available` is False.

    ``function`` calls ``hypot`` and ``remainder`` by those names (``math``'s in Python): the
    compiled form binds them to :func:`cpython_hypot` and :func:`cpython_remainder`.  The
    plain functions of its module that it calls are compiled with it.  Compiled once a
    process, on the first call.
    """
    if not compiled_available():
        return function
    done = _COMPILED.get(function)
    if done is None:
        assert numba is not None
        fast_sum = numba.njit(_fast_sum)
        names: dict[str, Any] = {
            "hypot": numba.njit(
                _rebound(cpython_hypot, {"_fma": _compiled_fma, "_fast_sum": fast_sum})
            ),
            "remainder": numba.njit(cpython_remainder),
        }
        done = numba.njit(_rebound(function, {**names, **_callees(function, names)}))
        _COMPILED[function] = done
    return done


def _callees(function: Callable[..., Any], names: dict[str, Any]) -> dict[str, Any]:
    """The compiled forms of the plain functions of ``function``'s module that it calls."""
    callees = {}
    for name in function.__code__.co_names:
        callee = function.__globals__.get(name)
        if (
            name not in names
            and isinstance(callee, types.FunctionType)
            and callee.__module__ == function.__module__
        ):
            assert numba is not None
            callees[name] = numba.njit(_rebound(callee, {**names, **_callees(callee, names)}))
    return callees
