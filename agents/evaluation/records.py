"""The record types the evaluations share (a leaf module: it imports no other evaluation).

* :class:`EpisodeRecord`: one evaluated policy episode, the one record of every evaluation
  (:mod:`agents.evaluation.pipeline`).  The columns every evaluation fills come first (who,
  where, which seed, how it ended, the touchdown metrics), then each evaluation's own, marked
  with its name (:func:`own_fields`); the runner (:mod:`agents.evaluation.runner`) writes
  each record as a JSON line as it arrives.
* :class:`ScenarioRecord` and :class:`EstimatorTrace`: an estimator run's time series, with
  the axis names and units and the error helpers that the estimator tables
  (:mod:`~agents.evaluation.estimators`), the figures (:mod:`~agents.evaluation.plots`,
  :mod:`~agents.evaluation.fusion_plot`) and the sweep read.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

_R = TypeVar("_R", bound="EpisodeRecord")

#: the metadata of a record's or summary's field that one evaluation alone fills
LANDING = {"evaluation": "landing"}
APPROACH = {"evaluation": "approach"}


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
    #: compliant-touchdown metrics (landing_env/touchdown.py)
    bounce_height_m: float = math.nan
    peak_load_g: float = math.nan
    deck_vertical_accel_g: float = math.nan
    tipped_over: bool = False
    failed_checks: str = ""
    #: the timing task's wait before the commit, seconds (NaN outside the timing task)
    wait_s: float = field(default=math.nan, metadata=LANDING)
    #: the timing task's waved-off descents (``timing.wave_off_tilt_deg``)
    wave_offs: int = field(default=0, metadata=LANDING)
    #: the approach: the estimator observed
    estimator: str = field(default="", metadata=APPROACH)
    #: start: height above the deck's home surface and horizontal offset, metres
    start_height_m: float = field(default=math.nan, metadata=APPROACH)
    start_offset_m: float = field(default=math.nan, metadata=APPROACH)
    #: the policy's last state; relocations (svgs-routine's Algorithm 4); searches
    #: (beacon-range: PX4 searches flown; svgs-routine: scans re-entered after a relocation)
    final_state: str = field(default="", metadata=APPROACH)
    relocations: int = field(default=0, metadata=APPROACH)
    searches: int = field(default=0, metadata=APPROACH)
    wall_time_s: float = field(default=math.nan, metadata=APPROACH)
    #: the SVGS paper's landing error: commanded minus actual landing point at the first
    #: touchdown, x and y in the deck plate's frame P and its length, metres
    landing_error_x_m: float = field(default=math.nan, metadata=APPROACH)
    landing_error_y_m: float = field(default=math.nan, metadata=APPROACH)
    landing_error_m: float = field(default=math.nan, metadata=APPROACH)
    #: (t, x, y, z) of the drone relative to the deck's home, every few periods (figures only)
    trajectory: list[tuple[float, float, float, float]] = field(
        default_factory=list, repr=False, metadata={**APPROACH, "table": False}
    )

    def record_end(self, info: dict[str, Any]) -> None:
        """Fill the touchdown metrics (or the crash contact) from the last step's ``info``."""
        touchdown = info.get("touchdown")
        if touchdown:

            def number(key: str) -> float:
                # info holds None where a metric does not exist (no NaN: Gymnasium's checks)
                value = touchdown.get(key)
                return math.nan if value is None else float(value)

            self.relative_normal_speed = number("relative_normal_speed")
            self.deck_tilt_deg = number("deck_tilt_deg")
            self.lateral_offset_m = number("lateral_offset_m")
            self.relative_attitude_deg = number("relative_attitude_deg")
            self.time_to_land_s = number("time_s")
            self.bounce_height_m = number("bounce_height_m")
            self.peak_load_g = number("peak_load_g")
            self.deck_vertical_accel_g = number("deck_vertical_accel_g")
            self.tipped_over = bool(touchdown.get("tipped_over", False))
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
    def from_json(cls: type[_R], data: dict[str, Any]) -> _R:
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


def own_fields(cls: type, evaluation: str) -> tuple[str, ...]:
    """The fields of a record or summary class that ``evaluation`` fills: the shared ones and
    its own (not those marked with another's name), as its files show them."""
    return tuple(
        f.name
        for f in dataclasses.fields(cls)
        if f.metadata.get("evaluation", evaluation) == evaluation and f.metadata.get("table", True)
    )


# ------------------------------------------------------------------------------ estimator runs
AXES: tuple[str, ...] = ("x", "y", "z", "roll", "pitch", "yaw")
#: units of the tables and figures per axis (the env reports radians; tables use degrees)
AXIS_UNITS: tuple[str, ...] = ("m", "m", "m", "deg", "deg", "deg")
#: the reference, never scored against itself
TRUTH = "truth"
#: display names of the estimators
DISPLAY_NAMES: dict[str, str] = {"atda": "ATDA", "ihrcf": "IHRCF", "crhf": "CRHF", "fused": "Fused"}


def display_name(name: str) -> str:
    """ATDA, IHRCF, CRHF, or the name itself for any other estimator."""
    return DISPLAY_NAMES.get(name, name)


@dataclass
class EstimatorTrace:
    """One estimator's output at every frame: pose (m, rad; NaN when invalid) and flags."""

    pose: np.ndarray
    valid: np.ndarray
    predicted: np.ndarray
    reasons: list[str]
    #: 1-sigma per axis (m, rad) where the estimator gives one (``fused``), else None
    std: np.ndarray | None = None
    #: capture time of the image the shown estimate came from (the vision link), s; NaN
    #: where the estimate is not delayed
    capture_time_s: np.ndarray | None = None


@dataclass
class ScenarioRecord:
    """Everything a run recorded, frame by frame (the reset frame and every step)."""

    scenario: str
    seed: int
    time_s: np.ndarray
    #: the true T_CD as x, y, z (m), roll, pitch, yaw (rad)
    truth: np.ndarray
    estimates: dict[str, EstimatorTrace]
    #: a deck command was outside the legs' stroke and was clamped (the truth is still true)
    stewart_clamped: np.ndarray
    tag_miss_reason: list[str]
    wall_time_s: float
    config: dict[str, Any] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return len(self.time_s)

    def save(self, path: Path) -> None:
        """Write the time series as a compressed ``.npz`` (reasons as string arrays)."""
        arrays: dict[str, np.ndarray] = {
            "time_s": self.time_s,
            "truth": self.truth,
            "stewart_clamped": self.stewart_clamped,
            "tag_miss_reason": np.asarray(self.tag_miss_reason, dtype=str),
        }
        for name, trace in self.estimates.items():
            arrays[f"{name}.pose"] = trace.pose
            arrays[f"{name}.valid"] = trace.valid
            arrays[f"{name}.predicted"] = trace.predicted
            arrays[f"{name}.reasons"] = np.asarray(trace.reasons, dtype=str)
            for extra in ("std", "capture_time_s"):
                if getattr(trace, extra) is not None:
                    arrays[f"{name}.{extra}"] = getattr(trace, extra)
        arrays["meta"] = np.asarray(
            json.dumps({"scenario": self.scenario, "seed": self.seed, "wall": self.wall_time_s})
        )
        np.savez_compressed(path, **arrays)

    @classmethod
    def load(cls, path: Path) -> ScenarioRecord:
        """Read a record written by :meth:`save` (to re-plot or re-score without re-running)."""
        with np.load(path) as data:
            meta = json.loads(str(data["meta"]))
            names = [key.removesuffix(".pose") for key in data.files if key.endswith(".pose")]
            return cls(
                scenario=meta["scenario"],
                seed=int(meta["seed"]),
                time_s=data["time_s"],
                truth=data["truth"],
                estimates={
                    n: EstimatorTrace(
                        pose=data[f"{n}.pose"],
                        valid=data[f"{n}.valid"],
                        predicted=data[f"{n}.predicted"],
                        reasons=[str(r) for r in data[f"{n}.reasons"]],
                        std=data[f"{n}.std"] if f"{n}.std" in data.files else None,
                        capture_time_s=data[f"{n}.capture_time_s"]
                        if f"{n}.capture_time_s" in data.files
                        else None,
                    )
                    for n in names
                },
                stewart_clamped=data["stewart_clamped"],
                tag_miss_reason=[str(r) for r in data["tag_miss_reason"]],
                wall_time_s=float(meta["wall"]),
            )


def wrap_degrees(angle_deg: np.ndarray) -> np.ndarray:
    """Wrap angles to (-180, 180] degrees."""
    return 180.0 - np.mod(180.0 - np.asarray(angle_deg, dtype=float), 360.0)


def to_table_units(pose: np.ndarray) -> np.ndarray:
    """Poses (..., 6) in m and rad -> m and degrees."""
    out = np.array(pose, dtype=float, copy=True)
    out[..., 3:] = np.rad2deg(out[..., 3:])
    return out


def pose_errors(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Signed errors (N, 6) estimate - truth in m and degrees, angles wrapped; NaN stays NaN."""
    error = to_table_units(estimate) - to_table_units(truth)
    error[..., 3:] = wrap_degrees(error[..., 3:])
    return error
