"""Configuration errors, shared by the simulator and the estimators (no heavy imports here)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any


class ConfigError(ValueError):
    """A configuration key or value is not allowed; the message names the key and what is allowed.

    Config dataclasses raise it from ``__post_init__`` with the bare field name as ``key``; the
    loader re-raises it with the full dotted path (``camera.mode``).
    """

    def __init__(self, key: str, message: str) -> None:
        self.key = key
        self.detail = message
        super().__init__(f"{key}: {message}")

    def __reduce__(self) -> tuple[type[ConfigError], tuple[str, str]]:
        # the default pickles ``args`` (the joined message) and calls __init__ with it alone,
        # which fails; a worker process's error must reach the caller with key and message
        return (type(self), (self.key, self.detail))

    def under(self, prefix: str) -> ConfigError:
        """The same error with ``prefix.`` in front of the key."""
        return ConfigError(f"{prefix}.{self.key}" if prefix else self.key, self.detail)


def require_choice(key: str, value: Any, allowed: Iterable[Any]) -> None:
    """Raise ConfigError unless ``value`` is one of ``allowed``."""
    allowed = tuple(allowed)
    if value not in allowed:
        names = ", ".join(repr(a) for a in allowed)
        raise ConfigError(key, f"{value!r} is not allowed; choose one of {names}")


def require_finite(key: str, value: float) -> None:
    """Raise ConfigError unless ``value`` is a finite number (not NaN, not +-inf)."""
    try:
        finite = math.isfinite(value)
    except TypeError:
        raise ConfigError(key, f"{value!r} is not a number") from None
    if not finite:
        raise ConfigError(key, f"{value!r} is not allowed; give a finite number")


def require_range(
    key: str,
    value: float,
    low: float | None = None,
    high: float | None = None,
    *,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
    bounds_from: str | None = None,
) -> None:
    """Raise ConfigError unless ``low <= value <= high`` (bounds optional, inclusivity settable).

    NaN is never in range. ``bounds_from`` names the other keys a bound is computed from, so that
    a cross-field error names both keys (e.g. ``"length_m = 15.0"``).
    """
    ok = value == value  # False for NaN
    if low is not None:
        ok &= value >= low if low_inclusive else value > low
    if high is not None:
        ok &= value <= high if high_inclusive else value < high
    if not ok:
        lo = "-inf" if low is None else f"{low}"
        hi = "inf" if high is None else f"{high}"
        lb = "[" if low_inclusive else "("
        hb = "]" if high_inclusive else ")"
        why = f" (set by {bounds_from})" if bounds_from else ""
        raise ConfigError(key, f"{value!r} is out of range; allowed {lb}{lo}, {hi}{hb}{why}")
