"""Strict, typed construction of nested config dataclasses from plain dicts (YAML, kwargs).

Every key is checked against the dataclass fields and every value against the field's type
annotation; errors name the full dotted key and what is allowed.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin

import numpy as np

from landing_env.config_limits import check_value
from landing_env.errors import ConfigError

T = TypeVar("T")


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _type_name(annotation: Any) -> str:
    return getattr(annotation, "__name__", str(annotation))


#: Called with (dotted key, value) for every value given to the loader; raises ConfigError.
LeafCheck = Callable[[str, Any], None]


def _coerce(
    value: Any, annotation: Any, key: str, base: Any = None, check: LeafCheck | None = None
) -> Any:
    """Convert ``value`` to ``annotation`` or raise ConfigError naming ``key``."""
    origin = get_origin(annotation)
    args = get_args(annotation)

    if annotation is Any:
        return value
    if dataclasses.is_dataclass(annotation) and isinstance(annotation, type):
        if dataclasses.is_dataclass(value) and isinstance(value, annotation):
            return value
        if not isinstance(value, Mapping):
            raise ConfigError(key, f"expected a mapping of {annotation.__name__} fields")
        return build_dataclass(annotation, value, key, base=base, check=check)
    if origin is Literal:
        if value not in args:
            allowed = ", ".join(repr(a) for a in args)
            raise ConfigError(key, f"{value!r} is not allowed; choose one of {allowed}")
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(value, arg, key, base, check)
            except ConfigError as exc:
                errors.append(exc.detail)
        raise ConfigError(key, "; ".join(errors))
    if annotation is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise ConfigError(key, f"{value!r} is not a boolean (true/false)")
        return bool(value)
    if annotation is int:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            raise ConfigError(key, f"{value!r} is not an integer")
        return int(value)
    if annotation is float:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
            raise ConfigError(key, f"{value!r} is not a number")
        return float(value)
    if annotation is str:
        if not isinstance(value, str):
            raise ConfigError(key, f"{value!r} is not a string")
        return value
    if annotation is Path:
        if not isinstance(value, (str, Path)):
            raise ConfigError(key, f"{value!r} is not a path")
        return Path(value)
    if annotation is np.ndarray:
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ConfigError(key, f"{value!r} is not a numeric array") from exc
        return array
    if origin is tuple:
        if not isinstance(value, (list, tuple, np.ndarray)):
            raise ConfigError(key, f"{value!r} is not a list")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], f"{key}[{i}]") for i, v in enumerate(value))
        if args and len(value) != len(args):
            raise ConfigError(key, f"expected {len(args)} values, got {len(value)}")
        if not args:
            return tuple(value)
        return tuple(
            _coerce(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=False))
        )
    if origin is list:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(key, f"{value!r} is not a list")
        item = args[0] if args else Any
        return [_coerce(v, item, f"{key}[{i}]") for i, v in enumerate(value)]
    if origin is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(key, f"{value!r} is not a mapping")
        return dict(value)
    return value


def build_dataclass(
    cls: type[T],
    data: Mapping[str, Any],
    prefix: str = "",
    base: Any = None,
    check: LeafCheck | None = None,
) -> T:
    """Build ``cls`` from ``data``, starting from ``base`` (an instance) or the defaults.

    Unknown keys and badly typed values raise ConfigError with the full dotted key.  Every
    given value then passes ``check(dotted_key, value)``: by default
    :func:`~landing_env.config_limits.check_value` without limits, which refuses NaN and
    infinities in any number (``load_config`` adds the physical ranges of
    :data:`~landing_env.config_limits.LIMITS`).
    """
    if check is None:

        def check(key: str, value: Any) -> None:
            check_value(key, value, {})

    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = typing.get_type_hints(cls)
    unknown = [k for k in data if k not in fields]
    if unknown:
        allowed = ", ".join(sorted(fields))
        raise ConfigError(
            _join(prefix, str(unknown[0])), f"unknown key; allowed keys here are: {allowed}"
        )
    kwargs: dict[str, Any] = {}
    if base is not None:
        kwargs = {name: getattr(base, name) for name in fields}
    for name, value in data.items():
        sub_base = kwargs.get(name)
        if not dataclasses.is_dataclass(sub_base):
            sub_base = None
        key = _join(prefix, name)
        kwargs[name] = _coerce(value, hints[name], key, sub_base, check)
        if not dataclasses.is_dataclass(kwargs[name]):
            check(key, kwargs[name])
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        raise exc.under(prefix) from None


def deep_merge(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """Recursively merge ``override`` into a copy of ``base``."""
    merged: dict[str, Any] = dict(base)
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = deep_merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def dotted_to_nested(flat: Mapping[str, Any]) -> dict[str, Any]:
    """Turn ``{"camera.mode": "render"}`` (or ``camera__mode``) into nested dicts."""
    nested: dict[str, Any] = {}
    for key, value in flat.items():
        parts = key.replace("__", ".").split(".")
        node = nested
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(key, "conflicts with a non-mapping value given for a prefix")
        node[parts[-1]] = value
    return nested


def nested_to_dotted(nested: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Turn ``{"camera": {"mode": "render"}}`` into ``{"camera.mode": "render"}`` (under
    ``prefix.`` when given): the inverse of :func:`dotted_to_nested`."""
    flat: dict[str, Any] = {}
    for key, value in nested.items():
        name = _join(prefix, str(key))
        if isinstance(value, Mapping):
            flat.update(nested_to_dotted(value, name))
        else:
            flat[name] = value
    return flat


def to_plain(obj: Any) -> Any:
    """A dataclass (tree) as plain Python data, for saving next to results."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [to_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return obj


__all__ = [
    "_type_name",
    "build_dataclass",
    "deep_merge",
    "dotted_to_nested",
    "nested_to_dotted",
    "to_plain",
]
