"""What a user asked for: the user-error type, the errors reported as one line, and dotted
``KEY=VALUE`` config overrides (a leaf module).

Every user error (a bad flag, a config key, a missing file) reaches :func:`agents.cli.main`,
which prints one line and exits with status 2; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

from typing import Any

from estimation.errors import ConfigError


class UserError(Exception):
    """A mistake in what the user asked for (reported as one line, exit status 2)."""


#: what :func:`agents.cli.main` reports as a user error rather than a crash
USER_ERRORS: tuple[type[BaseException], ...] = (ConfigError, UserError, FileNotFoundError)


def parse_overrides(pairs: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` pairs (dotted keys, YAML values) as an overrides mapping."""
    import yaml

    overrides: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set", f"{pair!r} is not KEY=VALUE (e.g. tof.noise=vl53l1x)")
        try:
            overrides[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError as exc:
            raise ConfigError(key.strip(), f"{value!r} is not a YAML value: {exc}") from None
    return overrides


__all__ = ["USER_ERRORS", "UserError", "parse_overrides"]
