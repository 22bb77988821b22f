"""``deck-landing bridge``: deck estimates to an autopilot over MAVLink, from the live
simulator or, with ``--input REC``, from a recording (:mod:`agents.io.recording_source`:
``deck-landing estimate``'s code path, each LANDING_TARGET stamped with its image's stamp).

A paced run (``--speed`` > 0) also listens to the autopilot on the same connection: it
answers and sends TIMESYNC (the stamps' clock, the simulator's or the recording's, read on the
wall clock) and, with ``--vehicle-pose mavlink``, takes the vehicle's pose from the
autopilot's telemetry instead of the simulator's truth or the recording's ``/tf``.

This module imports neither pymavlink nor the recording readers at import time, so that the
command line works without the ``io`` extra; the bridge itself needs it (``pip install
deck-landing[io]``).
"""

from __future__ import annotations

import argparse
import contextlib

from agents.cli.args import add_mode_argument, add_set_argument, non_negative_float, positive_int
from agents.cli.recording_args import (
    add_alignment_arguments,
    add_topic_arguments,
    fill_alignment_defaults,
    recording_options_given,
)
from agents.common.user_input import UserError, parse_overrides
from agents.io.autopilot_listener import AutopilotListener
from agents.io.landing_target import AUTOPILOTS, ardupilot_parameters
from agents.io.sim_source import SimulatorSource

#: the simulator's options, refused with --input: destination, flag
SIMULATOR_OPTIONS = {"mode": "--mode", "episodes": "--episodes", "seed": "--seed"}


def _simulator_source(args: argparse.Namespace) -> SimulatorSource:
    given = recording_options_given(args)
    if given:
        raise UserError(f"{', '.join(given)}: the options of a recording; give --input REC")
    if args.vehicle_pose == "recording":
        raise UserError("--vehicle-pose recording: the pose recorded in --input REC; none given")
    return SimulatorSource(
        config=None if args.scenario else (args.config or "default"),
        scenario=args.scenario,
        estimator=args.estimator,
        camera_mode=args.mode or "project",
        episodes=args.episodes or 1,
        seed=args.seed or 0,
        speed=args.speed,
        overrides=parse_overrides(args.set),
    )


def _recording_source(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    given = [flag for dest, flag in SIMULATOR_OPTIONS.items() if getattr(args, dest) is not None]
    if given:
        raise UserError(f"{', '.join(given)}: the simulator's options; not with --input")
    if args.vehicle_pose == "truth":
        raise UserError(
            "--vehicle-pose truth: the simulator's; with --input give recording (the "
            "recording's /tf, the default) or mavlink"
        )
    try:
        # mcap and rosbags: the optional extra ``io``, needed with --input only
        from agents.io.recording_source import RecordingSource
    except ImportError as exc:
        raise UserError(
            f"deck-landing bridge --input needs the io extra ({exc}); install it with "
            "`pip install deck-landing[io]`"
        ) from None
    fill_alignment_defaults(args)
    args.config = "default"  # the estimator settings: the default config, then --set
    source = RecordingSource(args, speed=args.speed)
    if source.mount is None:
        raise UserError(
            f"--calibration {args.calibration}: no extrinsics.json; LANDING_TARGET is in the "
            "body or local NED frame, so the bridge needs the camera's mount on the body"
        )
    if args.autopilot == "px4" and args.vehicle_pose != "mavlink":
        if not source.has_vehicle_poses:
            raise UserError(
                f"--input {args.input}: px4 needs the vehicle's pose at each measurement and "
                f"the recording has none ({source.where_vehicle_poses()}); give "
                "--vehicle-pose mavlink (the autopilot's telemetry, with --speed 1)"
            )
    return source


def _bridge(args: argparse.Namespace) -> int:
    try:
        # pymavlink: an optional dependency (the `io` extra), needed by this command only
        from agents.io.mavlink import LandingTargetBridge, MavlinkLink, parse_connection_url
    except ImportError as exc:
        raise UserError(
            f"deck-landing bridge needs pymavlink ({exc}); install it with "
            "`pip install deck-landing[io]`"
        ) from None

    url = parse_connection_url(args.to)  # a bad --to fails before the source starts
    if args.vehicle_pose == "mavlink":
        if args.autopilot != "px4":
            raise UserError(
                "--vehicle-pose mavlink: only px4 needs the vehicle's pose (ardupilot reads "
                "LANDING_TARGET in MAV_FRAME_BODY_FRD)"
            )
        if args.speed != 1.0:
            raise UserError(
                f"--vehicle-pose mavlink: --speed {args.speed:g} is not allowed; the "
                "stamps must run on the wall clock (--speed 1)"
            )
    source = _recording_source(args) if args.input else _simulator_source(args)
    with (
        source,
        MavlinkLink(url, args.system_id, args.component_id) as link,
        contextlib.ExitStack() as stack,
    ):
        listener = None
        if args.speed > 0.0:  # the stamps follow the wall clock: TIMESYNC means something
            listener = stack.enter_context(AutopilotListener(link, source.clock_s))
        poses = listener.poses if args.vehicle_pose == "mavlink" else source.vehicle_pose
        bridge = LandingTargetBridge(link, args.autopilot, source.mount, vehicle_pose=poses)
        stats = bridge.run(source)
    print(
        f"LANDING_TARGET to {url.text} ({args.autopilot}): {stats.sent} sent in "
        f"{stats.wall_s:.1f} s ({stats.rate_hz:.1f} Hz), {stats.heartbeats} heartbeats; "
        f"{source.summary()}"
    )
    for reason, count in sorted(stats.skipped.items()):
        print(f"  not sent, {reason}: {count}")
    if listener is not None:
        print(listener.summary())
        for reason, count in sorted((listener.skipped + listener.poses.skipped).items()):
            print(f"  from the autopilot, skipped ({reason}): {count}")
    if args.autopilot == "ardupilot":
        params = ", ".join(f"{k}={v:g}" for k, v in ardupilot_parameters(source.mount).items())
        print(f"ArduPilot parameters for this camera: {params}")
    return 0


def add_bridge_parser(sub: argparse._SubParsersAction) -> None:
    """The ``bridge`` sub-command."""
    bridge = sub.add_parser(
        "bridge",
        help="send deck estimates, of the simulator flown live or of a recording, to an "
        "autopilot as MAVLink LANDING_TARGET (needs the io extra)",
    )
    bridge.add_argument(
        "--to",
        required=True,
        help="MAVLink connection: udpout:HOST:PORT, udpin:HOST:PORT, tcp:HOST:PORT, "
        "tcpin:HOST:PORT or /dev/ttyXXX[:BAUD]",
    )
    bridge.add_argument(
        "--autopilot",
        required=True,
        choices=AUTOPILOTS,
        help="px4: MAV_FRAME_LOCAL_NED positions; ardupilot: MAV_FRAME_BODY_FRD vectors",
    )
    bridge.add_argument(
        "--estimator",
        default="tight",
        help="the observed estimator (with --input: one that `deck-landing estimate` runs)",
    )
    where = bridge.add_mutually_exclusive_group()
    where.add_argument(
        "--config", default=None, help="a config in configs/ or a path (default: default)"
    )
    where.add_argument(
        "--scenario", default=None, help="a shipped config made a landing run (e.g. bench-ss4)"
    )
    where.add_argument(
        "--input",
        default=None,
        help="a recording (folder, .mcap or rosbag2 folder) instead of the simulator; its "
        "estimates as `deck-landing estimate` gives them (the default config, --set applies)",
    )
    add_mode_argument(bridge, None, "camera mode (default project)")
    bridge.add_argument(
        "--episodes", type=positive_int, default=None, help="episodes, seeds on (default 1)"
    )
    bridge.add_argument("--seed", type=int, default=None, help="the first episode's seed (0)")
    bridge.add_argument(
        "--speed",
        type=non_negative_float,
        default=1.0,
        help="simulated (or recorded) seconds per wall second (1: real time; 0: as fast as it "
        "goes)",
    )
    bridge.add_argument(
        "--vehicle-pose",
        choices=("truth", "recording", "mavlink"),
        default=None,
        help="px4's vehicle pose at each measurement: the simulator's truth (the default "
        "live), the recording's /tf world -> body (the default with --input), or the "
        "autopilot's LOCAL_POSITION_NED + ATTITUDE_QUATERNION (or ODOMETRY) mapped through "
        "TIMESYNC (needs --speed 1)",
    )
    bridge.add_argument("--system-id", type=int, default=1, help="MAVLink system id (1..255)")
    bridge.add_argument(
        "--component-id",
        type=int,
        default=191,
        help="MAVLink component id (default 191, MAV_COMP_ID_ONBOARD_COMPUTER)",
    )
    add_set_argument(bridge)
    recording = bridge.add_argument_group("with --input (as `deck-landing estimate` reads it)")
    add_alignment_arguments(recording, given_only=True)
    add_topic_arguments(recording, tf=True, given_only=True)
    bridge.set_defaults(func=_bridge)


__all__ = ["add_bridge_parser"]
