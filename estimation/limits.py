"""The bounds of numeric settings, declared once on the field they bound.

A config dataclass declares a field's bounds where it declares the field::

    fx: float = limited(458.5, POSITIVE, physical=Limit.positive(1e5, "pixels"))

``limit`` is what the code can run with: :func:`require_limits`, called from the
dataclass's ``__post_init__`` (a dataclass with no other checks derives from
:class:`Limited`), refuses a value outside it whenever the dataclass is built, naming the
field.  ``physical`` is the range a config file may give (a datasheet's, a
standard's, or where larger values only broke runs): the loader checks it on every value it
reads (:data:`landing_env.config_limits.LIMITS` collects them by dotted key), so an absurd
value is refused with its key before it reaches the physics.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields
from typing import Any

from estimation.errors import require_range


@dataclass(frozen=True)
class Limit:
    """``low <= value <= high`` (ends exclusive when asked); ``inf`` allowed if ``allow_inf``."""

    low: float | None = None
    high: float | None = None
    low_inclusive: bool = True
    high_inclusive: bool = True
    allow_inf: bool = False
    #: where the bound comes from (a datasheet, a standard) or why it is there
    note: str = ""

    @classmethod
    def positive(cls, high: float, note: str = "") -> Limit:
        """``0 < value <= high``."""
        return cls(0.0, high, low_inclusive=False, note=note)

    @classmethod
    def non_negative(cls, high: float, note: str = "") -> Limit:
        """``0 <= value <= high``."""
        return cls(0.0, high, note=note)

    @classmethod
    def symmetric(cls, bound: float, note: str = "") -> Limit:
        """``-bound <= value <= bound``."""
        return cls(-bound, bound, note=note)

    def check(self, key: str, value: float) -> None:
        """Raise ConfigError unless the number ``value`` is within this limit."""
        if self.allow_inf and math.isinf(value) and value > 0:
            return
        require_range(
            key,
            value,
            self.low,
            self.high,
            low_inclusive=self.low_inclusive,
            high_inclusive=self.high_inclusive,
        )


#: greater than zero
POSITIVE = Limit(0.0, low_inclusive=False)
#: zero or more
NON_NEGATIVE = Limit(0.0)


def limited(
    default: Any = MISSING,
    limit: Limit | None = None,
    *,
    physical: Limit | None = None,
    default_factory: Any = MISSING,
) -> Any:
    """A dataclass field with ``default`` (or ``default_factory``) and its bounds: ``limit``,
    checked whenever the dataclass is built (:func:`require_limits`), and ``physical``,
    checked on every value the config loader reads (module docstring)."""
    metadata = {
        name: bound
        for name, bound in (("limit", limit), ("physical", physical))
        if bound is not None
    }
    return field(default=default, default_factory=default_factory, metadata=metadata)


def require_limits(config: Any) -> None:
    """Raise ConfigError, keyed by the field's name, for the first field of the dataclass
    ``config`` that is outside the limit it declares with :func:`limited` (a field whose
    default is None may be None)."""
    for item in fields(config):
        limit = item.metadata.get("limit")
        value = getattr(config, item.name)
        # None is an optional setting's "unset" where it is the default
        if limit is not None and not (value is None and item.default is None):
            limit.check(item.name, value)


class Limited:
    """A dataclass base whose ``__post_init__`` is :func:`require_limits`: its fields' limits
    are checked whenever it is built."""

    def __post_init__(self) -> None:
        require_limits(self)
