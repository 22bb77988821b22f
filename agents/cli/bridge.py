"""``deck-landing bridge``: the live simulator's estimates to an autopilot over MAVLink.

A paced run (``--speed`` > 0) also listens to the autopilot on the same connection: it
answers and sends TIMESYNC (the stamps' clock is the simulator's, read on the wall clock) and,
with ``--vehicle-pose mavlink``, takes the vehicle's pose from the autopilot's telemetry
instead of the simulator's truth.

This module imports no pymavlink at import time, so that the command line works without the
``io`` extra; the bridge itself needs it (``pip install deck-landing[io]``).
"""

from __future__ import annotations

import argparse
import contextlib
import math

from agents.cli_args import UserError, add_set_argument, parse_overrides, positive_int
from agents.io.autopilot_listener import AutopilotListener
from agents.io.landing_target import AUTOPILOTS, ardupilot_parameters
from agents.io.sim_source import SimulatorSource


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value < 0.0:
        raise argparse.ArgumentTypeError(f"{value} is out of range; allowed [0, inf)")
    return value


def _bridge(args: argparse.Namespace) -> int:
    try:
        # pymavlink: an optional dependency (the `io` extra), needed by this command only
        from agents.io.mavlink import LandingTargetBridge, MavlinkLink, parse_connection_url
    except ImportError as exc:
        raise UserError(
            f"deck-landing bridge needs pymavlink ({exc}); install it with "
            "`pip install deck-landing[io]`"
        ) from None

    url = parse_connection_url(args.to)  # a bad --to fails before the simulator starts
    if args.vehicle_pose == "mavlink":
        if args.autopilot != "px4":
            raise UserError(
                "--vehicle-pose mavlink: only px4 needs the vehicle's pose (ardupilot reads "
                "LANDING_TARGET in MAV_FRAME_BODY_FRD)"
            )
        if args.speed != 1.0:
            raise UserError(
                f"--vehicle-pose mavlink: --speed {args.speed:g} is not allowed; the "
                "simulator's stamps must run on the wall clock (--speed 1)"
            )
    with (
        SimulatorSource(
            config=None if args.scenario else args.config,
            scenario=args.scenario,
            estimator=args.estimator,
            camera_mode=args.mode,
            episodes=args.episodes,
            seed=args.seed,
            speed=args.speed,
            overrides=parse_overrides(args.set),
        ) as source,
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
        f"episodes: {', '.join(source.outcomes)}"
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
        help="fly the simulator and send its deck estimates to an autopilot as MAVLink "
        "LANDING_TARGET (needs the io extra)",
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
    bridge.add_argument("--estimator", default="tight", help="the observed estimator")
    where = bridge.add_mutually_exclusive_group()
    where.add_argument("--config", default="default", help="a config in configs/ or a path")
    where.add_argument(
        "--scenario", default=None, help="a shipped config made a landing run (e.g. bench-ss4)"
    )
    bridge.add_argument(
        "--mode", choices=("project", "render"), default="project", help="camera mode"
    )
    bridge.add_argument("--episodes", type=positive_int, default=1, help="episodes (seeds on)")
    bridge.add_argument("--seed", type=int, default=0, help="the first episode's seed")
    bridge.add_argument(
        "--speed",
        type=_non_negative_float,
        default=1.0,
        help="simulated seconds per wall second (1: real time; 0: as fast as it goes)",
    )
    bridge.add_argument(
        "--vehicle-pose",
        choices=("truth", "mavlink"),
        default="truth",
        help="px4's vehicle pose at each measurement: the simulator's truth (default), or "
        "the autopilot's LOCAL_POSITION_NED + ATTITUDE_QUATERNION (or ODOMETRY) mapped "
        "through TIMESYNC (needs --speed 1)",
    )
    bridge.add_argument("--system-id", type=int, default=1, help="MAVLink system id (1..255)")
    bridge.add_argument(
        "--component-id",
        type=int,
        default=191,
        help="MAVLink component id (default 191, MAV_COMP_ID_ONBOARD_COMPUTER)",
    )
    add_set_argument(bridge)
    bridge.set_defaults(func=_bridge)


__all__ = ["add_bridge_parser"]
