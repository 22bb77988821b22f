"""Sustained LANDING_TARGET rate and measurement-to-send latency of ``deck-landing bridge``
(prints figures; not a test).

    nice -n 10 .venv/bin/python benchmarks/bench_mavlink_bridge.py [--seconds 60] [--cpu 0]

The live simulator (``DeckLanding-v2`` on the default config, the align-descend policy
landing episode after episode, seeds 0, 1, ...) with ``tight`` observed in ``project`` camera
mode and the camera at ``--env-hz`` (30 by default: ``simulation.env_hz``), bridged to a UDP
port on loopback (``udpout``; a pymavlink listener in a child process counts what arrives)
for ``--seconds`` of wall time, pinned to one CPU core, twice:

* ``real time`` (``--speed 1``, what the bridge does for an autopilot): the stream's and the
  send rate, and how long after its simulated capture time (on the wall clock) each
  LANDING_TARGET leaves;
* ``unpaced`` (``--speed 0``): the rate the one core can sustain, the headroom.

Latency is from the camera capture (the wall time at which the simulated camera is read,
``World.capture``) to the LANDING_TARGET leaving the socket: the estimators, the
observation and the conversion; its median, 95th percentile and maximum are printed.  The
time of each stage per step (physics and sensing with the estimators, of which the
estimators alone; the policy; the bridge) says what limits the rate, and the CPU time per
estimate (this process's ``time.process_time``) what the one core can sustain when the
machine is shared: ``1000 / (CPU ms per estimate)`` Hz.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import multiprocessing as mp
import socket

import numpy as np
from rich.console import Console
from rich.table import Table

from agents.io.mavlink import LandingTargetBridge, MavlinkLink
from agents.io.sim_source import SimulatorSource


def _listen(port_queue: mp.Queue, result_queue: mp.Queue, seconds: float) -> None:
    """Count the LANDING_TARGETs and HEARTBEATs arriving on a loopback port (on the other
    cores: the receiver is the autopilot's work, not the bridge's)."""
    if hasattr(os, "sched_setaffinity") and len(os.sched_getaffinity(0)) == 1:
        others = set(range(os.cpu_count() or 1)) - os.sched_getaffinity(0)
        if others:
            os.sched_setaffinity(0, others)
    from pymavlink.dialects.v20 import common as mavlink2

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(1.0)
    port_queue.put(sock.getsockname()[1])
    decoder = mavlink2.MAVLink(None)
    counts = {"LANDING_TARGET": 0, "HEARTBEAT": 0}
    deadline = time.monotonic() + seconds + 120.0
    # until the stream has been quiet for 3 s (up to 30 s before its first message: the
    # simulator starts meanwhile)
    idle, heard = 0, False
    while time.monotonic() < deadline and idle < (3 if heard else 30):
        try:
            data, _ = sock.recvfrom(4096)
        except TimeoutError:
            idle += 1
            continue
        idle, heard = 0, True
        for message in decoder.parse_buffer(data) or []:
            kind = message.get_type()
            counts[kind] = counts.get(kind, 0) + 1
    result_queue.put(counts)


class _Timer:
    """Wraps a callable, adding its wall time to ``total_s``."""

    def __init__(self, function) -> None:
        self.function, self.total_s, self.calls = function, 0.0, 0

    def __getattr__(self, name: str):  # the wrapped object's other methods (policy.reset)
        return getattr(self.function, name)

    def __call__(self, *args, **kwargs):
        start = time.perf_counter()
        try:
            return self.function(*args, **kwargs)
        finally:
            self.total_s += time.perf_counter() - start
            self.calls += 1


def run(speed: float, seconds: float, env_hz: int) -> dict:
    port_queue: mp.Queue = mp.Queue()
    result_queue: mp.Queue = mp.Queue()
    listener = mp.Process(target=_listen, args=(port_queue, result_queue, seconds))
    listener.start()
    port = port_queue.get(timeout=30)
    source = SimulatorSource(
        estimator="tight",
        camera_mode="project",
        episodes=10**6,
        seed=0,
        speed=speed,
        overrides={"simulation.env_hz": env_hz},
    )
    base = source.base
    captured: dict[float, float] = {}
    capture = base.world.capture

    def timed_capture():
        # the wall time of the measurement, keyed by the stamp the bridge will see
        captured[source._offset_s + float(base.world.time)] = time.perf_counter()
        return capture()

    base.world.capture = timed_capture
    step = _Timer(source.env.step)
    source.env.step = step
    estimators = _Timer(base.bank.estimate)
    base.bank.estimate = estimators
    policy = _Timer(source.policy)
    source.policy = policy
    latencies: list[float] = []
    wall0 = time.perf_counter()
    late: list[float] = []

    def on_sent(stamp_s: float) -> None:
        now = time.perf_counter()
        latencies.append(now - captured.pop(stamp_s, np.nan))
        if speed > 0.0:
            late.append(now - (wall0 + stamp_s / speed))

    items = 0
    with MavlinkLink(f"udpout:127.0.0.1:{port}") as link:
        bridge = LandingTargetBridge(link, "px4", source.mount, source.vehicle_pose, on_sent)
        send = _Timer(bridge.send)
        start = time.perf_counter()
        cpu_start = time.process_time()
        for stamp_s, estimate in source:
            send(stamp_s, estimate)
            items += 1
            if len(captured) > 1000:  # the skipped ones' captures
                for key in sorted(captured)[:-100]:
                    del captured[key]
            if time.perf_counter() - start >= seconds:
                break
        wall = time.perf_counter() - start
        cpu = time.process_time() - cpu_start
    source.close()
    listener.join(timeout=60)
    received = result_queue.get(timeout=10) if not result_queue.empty() else {}
    lat = np.asarray(latencies) * 1000.0
    return {
        "wall_s": wall,
        "cpu_s": cpu,
        "items": items,
        "sent": bridge.stats.sent,
        "skipped": sum(bridge.stats.skipped.values()),
        "received": received.get("LANDING_TARGET", -1),
        "heartbeats": received.get("HEARTBEAT", -1),
        "episodes": len(source.outcomes),
        "latency_ms": np.percentile(lat, [50, 95, 100]) if lat.size else [np.nan] * 3,
        "late_ms": np.percentile(np.asarray(late) * 1000, [50, 95, 100]) if late else None,
        "step_ms": 1000 * step.total_s / max(step.calls, 1),
        "estimators_ms": 1000 * estimators.total_s / max(estimators.calls, 1),
        "policy_ms": 1000 * policy.total_s / max(policy.calls, 1),
        "send_ms": 1000 * send.total_s / max(send.calls, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="wall seconds per run")
    parser.add_argument("--env-hz", type=int, default=30, help="camera and control rate")
    parser.add_argument("--cpu", type=int, default=0, help="the core to pin to (-1: none)")
    args = parser.parse_args()
    if args.cpu >= 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.cpu})
    console = Console(width=220)
    table = Table(
        title=f"deck-landing bridge, tight, project mode, camera {args.env_hz} Hz, "
        f"{args.seconds:g} s per run, one core ({time.strftime('%Y-%m-%d')})"
    )
    columns = (
        "pacing",
        "estimates/s",
        "LANDING_TARGET/s",
        "received",
        "heartbeats",
        "CPU %",
        "CPU ms/estimate",
        "latency p50/p95/max (ms)",
        "sent after sim. capture time p50/p95/max (ms)",
        "per step: env.step (estimators) / policy / bridge (ms)",
    )
    for column in columns:
        table.add_column(column, justify="right")
    for name, speed in (("real time", 1.0), ("unpaced", 0.0)):
        r = run(speed, args.seconds, args.env_hz)
        late = "-" if r["late_ms"] is None else "/".join(f"{v:.1f}" for v in r["late_ms"])
        table.add_row(
            name,
            f"{r['items'] / r['wall_s']:.1f}",
            f"{r['sent'] / r['wall_s']:.1f}",
            f"{r['received']}/{r['sent']}",
            str(r["heartbeats"]),
            f"{100 * r['cpu_s'] / r['wall_s']:.0f}",
            f"{1000 * r['cpu_s'] / r['items']:.2f}",
            "/".join(f"{v:.2f}" for v in r["latency_ms"]),
            late,
            f"{r['step_ms']:.2f} ({r['estimators_ms']:.2f}) / {r['policy_ms']:.2f} / "
            f"{r['send_ms']:.2f}",
        )
        console.print(
            f"{name}: {r['items']} estimates in {r['wall_s']:.1f} s over {r['episodes']} "
            f"episodes; {r['sent']} sent, {r['skipped']} not sent (invalid or stale)"
        )
    console.print(table)


if __name__ == "__main__":
    main()
