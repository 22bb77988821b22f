"""Errors raised by the simulator and its configuration (defined in :mod:`estimation.errors`)."""

from estimation.errors import ConfigError, require_choice, require_finite, require_range


class PinnedDroneWarning(UserWarning):
    """The config pins the drone (``simulation.drone_fixed``): a bench for the estimators, an
    environment that cannot land.  Filter it where the bench is meant (the estimator runs)."""


__all__ = ["ConfigError", "PinnedDroneWarning", "require_choice", "require_finite", "require_range"]
