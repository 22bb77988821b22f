"""Physical limits of the numeric config values, checked as a config is loaded.

Every number that enters a config through YAML, ``overrides`` or section keywords passes
:func:`check_value`: NaN and infinities are refused everywhere (except where ``inf`` has a
meaning, ``allow_inf``), and a key with a physical range (:data:`LIMITS`) must lie in it.
Tuples are checked element by element.  The dataclasses' own ``__post_init__`` checks (and
the cross-field ones there) still run afterwards; the physical ranges add the bounds they
lack, so a value is refused with its own key before it can make a later check or the
physics fail.

A field declares both where it is declared (:func:`estimation.limits.limited`: ``limit``,
what the code can run with, and ``physical``, what a config may give); :data:`LIMITS`
collects the physical ones by dotted key.  ``tests/landing_env/test_config_limits.py`` fuzzes
every numeric key with NaN, inf and +-1e9.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from typing import Any

import numpy as np

from estimation.limits import Limit
from landing_env.errors import require_finite

#: Dotted key -> physical range, for the DeckLanding-v2 config tree: the ``physical`` bound
#: each field declares (:func:`estimation.limits.limited`), collected by
#: :func:`physical_limits` as soon as :mod:`landing_env.config` has defined the tree.
LIMITS: dict[str, Limit] = {}


def physical_limits(cls: type, prefix: str = "") -> dict[str, Limit]:
    """The physical range of every field of the config tree ``cls`` that declares one, by
    dotted key."""
    hints = typing.get_type_hints(cls)
    table: dict[str, Limit] = {}
    for item in dataclasses.fields(cls):
        key = f"{prefix}{item.name}"
        if dataclasses.is_dataclass(hints[item.name]):
            table.update(physical_limits(hints[item.name], key + "."))
        elif "physical" in item.metadata:
            table[key] = item.metadata["physical"]
    return table


def _numbers(value: Any) -> list[float] | None:
    """The numbers in ``value`` (a number, or a nested tuple/list/array of them), or None."""
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, float, np.integer, np.floating)):
        return [float(value)]
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        return [float(v) for v in value.reshape(-1)]
    if isinstance(value, (tuple, list)):
        numbers: list[float] = []
        for item in value:
            inner = _numbers(item)
            if inner is None:
                return None
            numbers.extend(inner)
        return numbers
    return None


def check_value(key: str, value: Any, limits: dict[str, Limit] | None = None) -> None:
    """Refuse a non-finite number anywhere and a number outside ``limits[key]``.

    ``key`` is the full dotted key; list indices (``height_m[1]``) are looked up without them.
    """
    numbers = _numbers(value)
    if not numbers:
        return
    table = LIMITS if limits is None else limits
    limit = table.get(key.split("[", 1)[0])
    for number in numbers:
        if limit is not None and limit.allow_inf and math.isinf(number) and number > 0:
            continue
        require_finite(key, number)
        if limit is not None:
            limit.check(key, number)


def config_leaves(cls: type, prefix: str = "") -> list[tuple[str, Any]]:
    """(dotted key, default value) of every leaf (non-dataclass field) of a config tree."""
    hints = typing.get_type_hints(cls)
    leaves: list[tuple[str, Any]] = []
    defaults = cls()
    for f in dataclasses.fields(cls):
        key = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(hints[f.name]):
            leaves.extend(config_leaves(hints[f.name], key + "."))
        else:
            leaves.append((key, getattr(defaults, f.name)))
    return leaves


def numeric_leaves(cls: type) -> list[tuple[str, Any]]:
    """The leaves holding numbers (a number or tuples of them): what the fuzzers of
    ``tests/`` and ``benchmarks/`` vary."""
    return [(key, value) for key, value in config_leaves(cls) if _numbers(value)]
