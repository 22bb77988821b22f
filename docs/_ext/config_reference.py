"""The configuration reference, generated from the config dataclasses.

``deck-config`` walks the tree of :class:`landing_env.config.DeckLandingConfig` (and the
timing task's settings, found through the task class's ``timing`` argument, wherever the
class lives) and writes one table per section: the dotted key, its type, its default, the
allowed range from :data:`landing_env.config_limits.LIMITS` (with where the bound comes from)
and the field's ``#:`` comment, which carries the unit.
"""

from __future__ import annotations

import dataclasses
import inspect
import typing
from typing import Any

from deck_docs import GeneratedDirective, list_table, task_class
from sphinx.pycode import ModuleAnalyzer


def _type_name(hint: Any) -> str:
    text = getattr(hint, "__name__", None) if not typing.get_args(hint) else None
    return text or str(hint).replace("typing.", "")


def _range(limit: Any) -> str:
    if limit is None:
        return ""
    low = "" if limit.low is None else f"{limit.low:g} {'≤' if limit.low_inclusive else '<'} "
    high = "" if limit.high is None else f" {'≤' if limit.high_inclusive else '<'} {limit.high:g}"
    text = f"{low}x{high}" if (low or high) else ""
    if limit.allow_inf:
        text += " or inf"
    return f"{text} ({limit.note})" if limit.note else text


def _comment(cls: type, name: str) -> str:
    for klass in cls.__mro__:
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            docs = ModuleAnalyzer.for_module(klass.__module__).find_attr_docs()
        except Exception:  # a module without source (compiled): no comments to show
            continue
        lines = docs.get((klass.__qualname__, name))
        if lines:
            return " ".join(line.strip() for line in lines if line.strip())
    return ""


def sections(cls: type, prefix: str = "") -> list[tuple[str, type, list[list[str]]]]:
    """(section key, its dataclass, rows of its leaves), depth first."""
    from landing_env.config_limits import LIMITS

    hints = typing.get_type_hints(cls)
    defaults = cls()
    rows: list[list[str]] = []
    nested: list[tuple[str, type, list[list[str]]]] = []
    for f in dataclasses.fields(cls):
        key = f"{prefix}{f.name}"
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            nested.extend(sections(hint, key + "."))
            continue
        default = getattr(defaults, f.name)
        rows.append(
            [
                f"``{key}``",
                f"``{_type_name(hint)}``",
                f"``{default!r}``",
                _range(LIMITS.get(key)),
                _comment(cls, f.name),
            ]
        )
    return [(prefix.rstrip(".") or "(top level)", cls, rows), *nested]


def timing_config() -> type | None:
    """The timing task's settings dataclass: the ``timing`` argument of its class."""
    from landing_env.scenarios import TIMING_TASK

    cls = task_class(TIMING_TASK)
    if "timing" not in inspect.signature(cls.__init__).parameters:
        return None
    hint = typing.get_type_hints(cls.__init__).get("timing")
    for option in typing.get_args(hint) or (hint,):
        if dataclasses.is_dataclass(option):
            return option
    return None


class ConfigDirective(GeneratedDirective):
    """``deck-config``: every config key with type, default, range and meaning."""

    def lines(self) -> list[str]:
        from landing_env.config import DeckLandingConfig

        trees: list[tuple[str, type]] = [("", DeckLandingConfig)]
        timing = timing_config()
        # once the timing settings are a section of the config tree, they are documented there
        seen = {cls for _, cls, _ in sections(DeckLandingConfig)}
        if timing is not None and timing not in seen:
            trees.append(("timing.", timing))
        lines: list[str] = []
        for prefix, root in trees:
            for key, cls, rows in sections(root, prefix):
                if not rows:
                    continue
                lines += [
                    f"**{key}** (:class:`{cls.__module__}.{cls.__qualname__}`)",
                    "",
                ]
                lines += list_table(
                    ["key", "type", "default", "allowed", "meaning, unit"], rows, "22 12 14 18 34"
                )
        return lines


def setup(app: Any) -> None:
    app.add_directive("deck-config", ConfigDirective)
