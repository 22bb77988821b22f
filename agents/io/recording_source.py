"""A recording as a source of ``(stamp_s, estimate)`` pairs for the MAVLink bridge.

:class:`RecordingSource` (``deck-landing bridge --input REC``) reads a recording (a plain
folder, MCAP or rosbag2) and runs the estimator on it by ``deck-landing estimate``'s code
path: :func:`agents.io.estimate.read_checked` reads and checks it,
:func:`agents.io.estimate.recording_estimator` builds the estimator, and
:meth:`agents.io.estimate.RecordingEstimator.run` estimates frame after frame.  Each pair's
stamp is the frame's own (the image's stamp in the recording), so LANDING_TARGET's
``time_usec`` is the measurement's time, as from the live simulator.

``speed`` plays the frames on the wall clock by their stamps (:class:`agents.io.pacing.
StampPacer`, the first frame at the start; 1: as recorded, 2: twice as fast); 0 runs them as
fast as they go.  :meth:`RecordingSource.clock_s` is then the stamps' clock, for TIMESYNC.

The camera's mount (:class:`~agents.io.landing_target.CameraMount`) is the estimator's
extrinsics (``extrinsics.json`` in ``--calibration``, or the config's camera mount without
``--calibration``); :meth:`RecordingSource.vehicle_pose` gives the vehicle's pose at a stamp
from the recording's ``/tf`` (world -> body, :class:`agents.io.recording.PoseSeries`),
aligned with the ranges' tolerance and mode.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator

from agents.io.estimate import (
    is_folder_recording,
    read_checked,
    recording_estimator,
    skipped_report,
    user_errors,
)
from agents.io.landing_target import CameraMount, VehiclePose
from agents.io.pacing import StampPacer
from agents.io.recording import Topics
from estimation.types import DeckPoseEstimate


class RecordingSource:
    """A recording's estimates, stamped with their frames' stamps (module doc).

    ``args``: ``deck-landing estimate``'s options (``input``, ``estimator``, ``config``,
    ``calibration``, ``set``, ``tolerance``, ``align`` and the topics).  A bad recording,
    calibration or config is a :class:`agents.common.user_input.UserError` naming the file,
    topic or field, as ``deck-landing estimate`` gives it."""

    def __init__(self, args: argparse.Namespace, speed: float = 1.0) -> None:
        with user_errors():
            self.topics = Topics.from_arguments(args)
            self.rec = read_checked(args)
            self.runner = recording_estimator(args, self.rec)
            self.pacer = StampPacer(speed, origin_s=self.rec.frames[0].timestamp)
        self.input = str(args.input)
        self.tolerance_s = float(args.tolerance)
        self.align = str(args.align)
        extrinsics = self.runner.extrinsics
        #: the camera's mount on the body (None without extrinsics)
        self.mount = None if extrinsics is None else CameraMount(extrinsics.r_bc, extrinsics.t_bc_m)
        self.frames = 0

    @property
    def has_vehicle_poses(self) -> bool:
        """Whether the recording holds the vehicle's pose (``/tf`` world -> body)."""
        return len(self.rec.vehicle) > 0

    def where_vehicle_poses(self) -> str:
        """Where the vehicle's poses are looked for (for an error's message)."""
        if is_folder_recording(self.input):
            return "a plain folder holds no vehicle pose"
        if not self.topics.tf:
            return "no tf topic read"
        parent, child = self.topics.tf_frames
        return f"no {parent} -> {child} transform on {self.topics.tf} (--tf-topic, --tf-frames)"

    def vehicle_pose(self, stamp_s: float) -> VehiclePose | str:
        """The vehicle's pose at ``stamp_s`` in the local NED frame (the recording's world
        frame W turned to NED), or why there is none."""
        found = self.rec.vehicle.at(stamp_s, self.tolerance_s, self.align)
        if found is None:
            return f"none in the recording within {self.tolerance_s:g} s"
        r_wb, t_wb = found
        return VehiclePose.from_world(t_wb, r_wb)

    def clock_s(self) -> float:
        """Now, on the clock of the recording's stamps (paced runs only)."""
        return self.pacer.clock_s()

    def __iter__(self) -> Iterator[tuple[float, DeckPoseEstimate]]:
        self.pacer.start()
        rec = self.rec
        estimates = self.runner.run(rec, self.tolerance_s, self.align, self.pacer.wait_until)
        for recorded, (estimate, _) in zip(rec.frames, estimates, strict=True):
            self.frames += 1
            yield recorded.timestamp, estimate

    def summary(self) -> str:
        """What was played, for the command's report."""
        return f"frames: {self.frames} of {self.input}; {skipped_report(self.rec)}"

    def close(self) -> None:
        """Nothing to release (the recording is read in full)."""

    def __enter__(self) -> RecordingSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["RecordingSource"]
