"""Errors raised by the simulator and its configuration (defined in :mod:`estimation.errors`)."""

from estimation.errors import ConfigError, require_choice, require_finite, require_range

__all__ = ["ConfigError", "require_choice", "require_finite", "require_range"]
