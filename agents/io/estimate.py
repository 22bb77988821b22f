"""``deck-landing estimate``: the deck-pose estimators on a recording, poses out.

The estimators are built as the simulator builds them (:func:`estimation.pipeline.
build_estimators` from :func:`landing_env.estimators.estimation_options` of a config), and
``fused`` runs after them in the same :class:`landing_env.vision_link.VisionStage` (the
vision link's simulated latency is off: a recording has its own).  Each frame gets the
ranges aligned to its stamp (:meth:`agents.io.recording.Recording.ranges_at`).
:func:`read_checked` and :func:`recording_estimator` are the command's reading and building;
``deck-landing bridge --input`` (:mod:`agents.io.recording_source`) runs the same.

Outputs: a CSV with one row per frame (every frame, valid or not, with the reason), and an
MCAP file with, per valid frame, ``geometry_msgs/PoseWithCovarianceStamped`` on
``/deck_pose/camera`` (T_CD: frame ``camera``, OpenCV axes) and, given the extrinsics, on
``/deck_pose/body_flu`` and ``/deck_pose/body_frd``; per frame, ``deck_landing_msgs/
EstimateStatus`` on ``/deck_pose/status``.  An invalid estimate is never written as a pose.
The covariance (x, y, z, rotations about x, y, z) is the method's where it gives one
(``fused``), zeros otherwise.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import json
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.common.user_input import UserError, parse_overrides
from agents.io import messages as m
from agents.io.bag import read_bag
from agents.io.recording import (
    Recording,
    RecordingError,
    Topics,
    read_folder,
    recording_estimators,
)
from estimation.detection import AprilTagDetector
from estimation.frames import R_BC
from estimation.fusion import METHOD as FUSED
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.pipeline import build_estimators, names_to_build
from estimation.registry import needs_tof_calibration_names
from estimation.tof_calibration import TofCameraCalibration
from estimation.types import CameraFrame, DeckPoseEstimate
from landing_env.config import DeckLandingConfig, load_config
from landing_env.estimators import estimation_options, fusion_settings
from landing_env.physics.quadrotor_params import QuadrotorParams
from landing_env.sensors.camera import tag_detector
from landing_env.vision_link import VisionLinkConfig, VisionStage

EXTRINSICS_FORMAT = "deck-landing/camera-extrinsics"
#: FLU body axes in FRD: x forward stays, y left -> right, z up -> down
R_FRD_FLU = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class Extrinsics:
    """The camera's mount on the body (FLU): its axes ``r_bc`` and origin ``t_bc_m``.

    File ``extrinsics.json``: ``{"format": "deck-landing/camera-extrinsics",
    "format_version": 1, "r_bc": 3x3 (columns: camera axes in the body), "t_bc_m": [x, y, z]}``.
    """

    r_bc: np.ndarray
    t_bc_m: np.ndarray

    @classmethod
    def load(cls, path: Path) -> Extrinsics:
        doc = json.loads(path.read_text())
        if doc.get("format") != EXTRINSICS_FORMAT or doc.get("format_version") != 1:
            raise RecordingError(f"{path}: not a format_version 1 {EXTRINSICS_FORMAT} file")
        r_bc = np.asarray(doc.get("r_bc"), dtype=float)
        t_bc = np.asarray(doc.get("t_bc_m"), dtype=float)
        if (
            r_bc.shape != (3, 3)
            or not np.allclose(r_bc @ r_bc.T, np.eye(3), atol=1e-6)
            or np.linalg.det(r_bc) < 0.0  # a mirror, not a turn
        ):
            raise RecordingError(f"{path}: r_bc must be a 3x3 rotation matrix")
        if t_bc.shape != (3,) or not np.all(np.isfinite(t_bc)):
            raise RecordingError(f"{path}: t_bc_m must be 3 finite numbers (metres)")
        return cls(r_bc, t_bc)

    def save(self, path: Path) -> None:
        doc = {
            "format": EXTRINSICS_FORMAT,
            "format_version": 1,
            "r_bc": self.r_bc.tolist(),
            "t_bc_m": self.t_bc_m.tolist(),
        }
        path.write_text(json.dumps(doc, indent=1))

    def deck_in_body(self, estimate: DeckPoseEstimate) -> tuple[np.ndarray, np.ndarray]:
        """(R_BD, t_BD) in FLU body axes."""
        return self.r_bc @ estimate.rotation, self.r_bc @ estimate.translation + self.t_bc_m


class _Host:
    """What :func:`estimation_options` reads from a world, for a recording."""

    def __init__(self, t_bc: np.ndarray) -> None:
        self.t_bc = t_bc
        self.last_range_down = None


def is_folder_recording(path: str | Path) -> bool:
    """Whether ``path`` is a plain folder recording (it has ``frames.csv``)."""
    path = Path(path)
    return path.is_dir() and (path / "frames.csv").is_file()


def read_recording(path: str | Path, topics: Topics | None = None) -> Recording:
    """A plain folder (it has ``frames.csv``) or an MCAP / rosbag2 recording."""
    if is_folder_recording(path):
        return read_folder(path)
    return read_bag(path, topics)


class RecordingEstimator:
    """Builds one estimator (and ``fused``'s sources) for a recording and runs it."""

    def __init__(
        self,
        name: str,
        config: DeckLandingConfig,
        calibration: Path | None,
        image_size: tuple[int, int] | None,
    ) -> None:
        allowed = recording_estimators()
        if name not in allowed:
            raise UserError(f"--estimator {name!r}; allowed: {', '.join(allowed)}")
        self.name = name
        est = config.estimation
        t_bc = np.asarray(QuadrotorParams.from_yaml(config.vehicle or None).camera_offset_b)
        self.extrinsics: Extrinsics | None = None
        options = estimation_options(config, _Host(t_bc))  # type: ignore[arg-type]
        names = names_to_build(name, (), est.fusion.sources)
        options = dataclasses.replace(options, names=tuple(names))
        if calibration is not None:
            options = self._calibrated(options, calibration, image_size, est.tof_lookup)
        elif image_size is not None and options.intrinsics is not None:
            if (options.intrinsics.width, options.intrinsics.height) != tuple(image_size):
                raise RecordingError(
                    f"the config's camera is {options.intrinsics.width}x"
                    f"{options.intrinsics.height}, the recording's images are "
                    f"{image_size[0]}x{image_size[1]}: give --calibration DIR"
                )
        if self.extrinsics is None and calibration is None:
            self.extrinsics = Extrinsics(R_BC.copy(), t_bc)
        self.estimators = build_estimators(options)
        fusion = fusion_settings(config) if name == FUSED else None
        mounts = options.tof_positions_c
        assert mounts is not None
        self.t_bc = self.extrinsics.t_bc_m if self.extrinsics is not None else t_bc
        self.stage = VisionStage(VisionLinkConfig(enabled=False), fusion, mounts, self.t_bc)
        self._camera = config.camera
        self._detector: AprilTagDetector | None = None

    def _calibrated(self, options, folder: Path, image_size, tof_lookup: str):  # type: ignore[no-untyped-def]
        if not folder.is_dir():
            raise RecordingError(f"--calibration {folder}: not a folder")
        changes: dict = {}
        intrinsics_file = folder / "intrinsics.json"
        if intrinsics_file.is_file():
            result = IntrinsicsCalibrationResult.load(intrinsics_file)
            if image_size is not None:
                result.require_camera(image_size, source=str(intrinsics_file))
            changes["intrinsics"] = result.to_intrinsics()
        else:
            raise RecordingError(f"--calibration {folder}: no intrinsics.json")
        tof_file = folder / "tof_camera.json"
        if tof_file.is_file():
            tof = TofCameraCalibration.load(tof_file).with_method(tof_lookup)
            if image_size is not None:
                tof.require_camera(image_size, source=str(tof_file))
            changes["tof_calibration"] = tof
            mounts = tof.metadata.get("tof_mount_offsets_c")
            if mounts is not None:
                changes["tof_positions_c"] = np.asarray(mounts, dtype=float)
        elif set(options.names) & needs_tof_calibration_names():
            raise RecordingError(f"--calibration {folder}: {self.name} needs tof_camera.json")
        else:
            changes["tof_calibration"] = None
        extrinsics_file = folder / "extrinsics.json"
        if extrinsics_file.is_file():
            self.extrinsics = Extrinsics.load(extrinsics_file)
        return dataclasses.replace(options, **changes)

    def _frame(self, recorded) -> CameraFrame:  # type: ignore[no-untyped-def]
        if recorded.detections is not None:
            return CameraFrame(recorded.timestamp, recorded.detections, None, recorded.miss_reason)
        if self._detector is None:
            self._detector = tag_detector(self._camera)
        detections = self._detector.detect(recorded.image)
        return CameraFrame(
            recorded.timestamp, detections, None, "" if detections else "not_detected"
        )

    def run(
        self,
        rec: Recording,
        tolerance_s: float,
        mode: str,
        pace: Callable[[float], object] | None = None,
    ) -> Iterator[tuple[DeckPoseEstimate, bool]]:
        """Per frame of ``rec.frames``, in order: the estimate and whether ranges were found
        within the tolerance.  ``pace(stamp_s)``, when given, is called with each frame's stamp
        before the frame is estimated (a replay waits there for the frame's time)."""
        for est in self.estimators.values():
            est.reset()
        self.stage.reset(None)
        previous = -math.inf
        for recorded in rec.frames:
            if pace is not None:
                pace(recorded.timestamp)
            frame = self._frame(recorded)
            ranges = rec.ranges_at(frame.timestamp, tolerance_s, mode)
            results = {n: e.estimate(frame, ranges) for n, e in self.estimators.items()}
            if self.name == FUSED:
                r_wb = rec.attitude_at(frame.timestamp)
                imu = rec.imu_between(previous, frame.timestamp)
                if r_wb is None:
                    results[FUSED] = DeckPoseEstimate.invalid(
                        FUSED, frame.timestamp, "no_attitude: no IMU orientation yet"
                    )
                else:
                    results = self.stage.process(frame.timestamp, results, ranges, imu, r_wb)
            previous = frame.timestamp
            yield _checked(results[self.name]), bool(np.any(ranges.valid))


def _checked(estimate: DeckPoseEstimate) -> DeckPoseEstimate:
    """Never a NaN pose as valid."""
    if estimate.valid and not (
        np.all(np.isfinite(estimate.rotation)) and np.all(np.isfinite(estimate.translation))
    ):
        return DeckPoseEstimate.invalid(estimate.method, estimate.timestamp, "non_finite_result")
    return estimate


def _pose_columns(prefix: str, rotation: np.ndarray, translation: np.ndarray) -> dict:
    q = m.quaternion_xyzw(rotation)
    return {
        **{f"{a}_{prefix}_m": float(v) for a, v in zip("xyz", translation, strict=True)},
        **{f"q{a}_{prefix}": float(v) for a, v in zip("xyzw", q, strict=True)},
    }


def _pose_message(t_s: float, frame_id: str, estimate: DeckPoseEstimate, r, t):  # type: ignore[no-untyped-def]
    covariance = np.zeros(36)
    if estimate.covariance is not None:
        covariance = np.asarray(estimate.covariance, dtype=float).reshape(-1)
    return m.msg(
        m.POSE_COV,
        header=m.header(t_s, frame_id),
        pose=m.msg(
            "geometry_msgs/msg/PoseWithCovariance", pose=m.pose(r, t), covariance=covariance
        ),
    )


@dataclass
class EstimateSummary:
    frames: int = 0
    valid: int = 0
    without_ranges: int = 0
    reasons: dict = dataclasses.field(default_factory=dict)


def write_estimates(
    runner: RecordingEstimator, rec: Recording, out: Path, tolerance_s: float, mode: str
) -> tuple[EstimateSummary, Path, Path]:
    """Run ``runner`` on ``rec`` and write ``out`` with suffixes .csv and .mcap."""
    csv_path, mcap_path = out.with_suffix(".csv"), out.with_suffix(".mcap")
    out.parent.mkdir(parents=True, exist_ok=True)
    summary = EstimateSummary()
    extrinsics = runner.extrinsics
    with csv_path.open("w", newline="") as table, mcap_path.open("wb") as stream:
        writer = m.McapWriter(stream)
        rows = None
        for estimate, had_ranges in runner.run(rec, tolerance_s, mode):
            t = estimate.timestamp
            summary.frames += 1
            summary.without_ranges += int(not had_ranges)
            row: dict = {
                "t_s": f"{t:.9f}",
                "method": estimate.method,
                "valid": int(estimate.valid),
                "reason": estimate.reason,
                "ranges_in_tolerance": int(had_ranges),
            }
            status = m.msg(
                m.STATUS,
                header=m.header(t, "camera"),
                method=estimate.method,
                valid=estimate.valid,
                reason=estimate.reason,
            )
            writer.write("/deck_pose/status", m.STATUS, status, t)
            if estimate.valid:
                summary.valid += 1
                poses = {"camera": (estimate.rotation, estimate.translation)}
                if extrinsics is not None:
                    r_bd, t_bd = extrinsics.deck_in_body(estimate)
                    poses["body_flu"] = (r_bd, t_bd)
                    poses["body_frd"] = (R_FRD_FLU @ r_bd, R_FRD_FLU @ t_bd)
                for frame_id, (r, tr) in poses.items():
                    row.update(_pose_columns(frame_id, r, tr))
                    message = _pose_message(t, frame_id, estimate, r, tr)
                    writer.write(f"/deck_pose/{frame_id}", m.POSE_COV, message, t)
            else:
                summary.reasons[estimate.reason] = summary.reasons.get(estimate.reason, 0) + 1
            if rows is None:
                frames = ("camera", "body_flu", "body_frd") if extrinsics else ("camera",)
                fields = [*row.keys()][:5] + [
                    k for f in frames for k in _pose_columns(f, np.eye(3), np.zeros(3))
                ]
                rows = csv.DictWriter(table, fieldnames=fields, restval="")
                rows.writeheader()
            rows.writerow(row)
        writer.finish()
    return summary, csv_path, mcap_path


@contextlib.contextmanager
def user_errors() -> Iterator[None]:
    """A bad recording, calibration or config as the command's one-line error."""
    try:
        yield
    except (RecordingError, ValueError) as exc:
        raise UserError(str(exc)) from None


def read_checked(args: argparse.Namespace) -> Recording:
    """``--input`` read with the command's topics (:meth:`Topics.from_arguments`) and checked
    for ``--estimator``: a frame to estimate, the ranges and the IMU it needs."""
    allowed = recording_estimators()
    if args.estimator not in allowed:
        raise UserError(f"--estimator {args.estimator!r}; allowed: {', '.join(allowed)}")
    rec = read_recording(args.input, Topics.from_arguments(args))
    if not rec.frames:
        skipped = "; ".join(f"{n} x {r}" for r, n in rec.skipped.items()) or "none"
        raise RecordingError(f"{args.input}: no usable camera frame (skipped: {skipped})")
    needs_ranges = args.estimator in needs_tof_calibration_names()
    if needs_ranges and not rec.has_ranges:
        missing = ", ".join(rec.missing_topics) or "ranges.csv"
        raise RecordingError(f"{args.input}: {args.estimator} needs ranges; missing: {missing}")
    if args.estimator == FUSED and not rec.imu:
        raise RecordingError(f"{args.input}: fused needs the IMU; none read")
    return rec


def recording_estimator(args: argparse.Namespace, rec: Recording) -> RecordingEstimator:
    """``--estimator`` built for ``rec`` from ``--config`` and ``--set`` (the estimator
    observed, none compared) and ``--calibration``."""
    overrides = {**parse_overrides(args.set or []), "estimation.observed": args.estimator}
    overrides["estimation.compare"] = []
    config = load_config(args.config, overrides)
    calibration = Path(args.calibration) if args.calibration else None
    return RecordingEstimator(args.estimator, config, calibration, rec.image_size())


def skipped_report(rec: Recording) -> str:
    """The bad messages left out of ``rec``, by reason."""
    skipped = sum(rec.skipped.values())
    return f"skipped {skipped} bad messages" + "".join(
        f"\n  {n} x {r}" for r, n in rec.skipped.items()
    )


def run_estimate(args: argparse.Namespace) -> EstimateSummary:
    """The command's work (also called by the tests)."""
    with user_errors():
        rec = read_checked(args)
        runner = recording_estimator(args, rec)
        summary, csv_path, mcap_path = write_estimates(
            runner, rec, Path(args.out), args.tolerance, args.align
        )
    print(
        f"{summary.frames} frames, {summary.valid} valid, {summary.without_ranges} without "
        f"ranges within {args.tolerance} s; invalid by reason: {summary.reasons or 'none'}"
    )
    print(skipped_report(rec))
    print(f"wrote {csv_path} and {mcap_path}")
    summary.skipped = dict(rec.skipped)  # type: ignore[attr-defined]
    return summary
