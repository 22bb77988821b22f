"""The record of one evaluated episode, shared by every policy evaluation (a leaf module).

``evaluate landing`` and ``evaluate approach`` write the same columns first (who, where,
which seed, how it ended, the touchdown metrics) and add their own after them; the runner
(:mod:`agents.evaluation.runner`) writes each record as a JSON line as it arrives.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, TypeVar

R = TypeVar("R", bound="EpisodeRecord")


@dataclass
class EpisodeRecord:
    """One evaluated episode (NaN where a metric does not exist, e.g. after a crash)."""

    policy: str
    scenario: str
    seed: int
    outcome: str
    success: bool
    relative_normal_speed: float = math.nan
    deck_tilt_deg: float = math.nan
    #: horizontal offset of the drone's centre from the deck centre at touchdown, metres
    lateral_offset_m: float = math.nan
    relative_attitude_deg: float = math.nan
    #: simulated time from the episode start to the touchdown, seconds
    time_to_land_s: float = math.nan
    failed_checks: str = ""

    def record_end(self, info: dict[str, Any]) -> None:
        """Fill the touchdown metrics (or the crash contact) from the last step's ``info``."""
        touchdown = info.get("touchdown")
        if touchdown:
            self.relative_normal_speed = float(touchdown["relative_normal_speed"])
            self.deck_tilt_deg = float(touchdown["deck_tilt_deg"])
            self.lateral_offset_m = float(touchdown["lateral_offset_m"])
            self.relative_attitude_deg = float(touchdown["relative_attitude_deg"])
            self.time_to_land_s = float(touchdown["time_s"])
            self.failed_checks = ";".join(touchdown["failed_checks"])
        elif "crash_contact" in info:
            self.failed_checks = str(info["crash_contact"])

    def to_json(self) -> dict[str, Any]:
        """The record as JSON data (NaN as null)."""
        return {
            k: (None if isinstance(v, float) and math.isnan(v) else v)
            for k, v in dataclasses.asdict(self).items()
        }

    @classmethod
    def from_json(cls: type[R], data: dict[str, Any]) -> R:
        """The record back from :meth:`to_json` (null as NaN, tuples restored)."""
        fields = {f.name: f for f in dataclasses.fields(cls)}
        kwargs: dict[str, Any] = {}
        for name, value in data.items():
            if name not in fields:
                continue
            if value is None:
                value = math.nan
            elif name == "trajectory":
                value = [tuple(point) for point in value]
            kwargs[name] = value
        return cls(**kwargs)


__all__ = ["EpisodeRecord"]
