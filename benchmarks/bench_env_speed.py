"""Steps per second and real-time factor of DeckLanding-v2 (prints figures; not a test).

    .venv/bin/python benchmarks/bench_env_speed.py [--seconds 60]

Measures the `project` and `render` camera modes, one environment in this process and two
environments in parallel (one process each, as SubprocVecEnv runs them; ``--envs``).  The deck moves
(sum of sinusoids), the four ToF rays are cast and the IMU is sampled at 240 Hz in every case;
`truth` rows measure the simulation alone, `ihrcf` rows add the default estimator, `tight`
the tightly coupled one; `realistic` rows run with ``sensors: realistic`` (the OV9281-class
camera's blur and noise, lens distortion, ToF noise; ``--sensors`` picks the rows).  The
CPU-time columns (this process's, or the sum over the processes) are what a shared machine
inflates least.  The drone
hovers at the default start height (about 2 m), where `render` mode renders the tag's window.

The second table is `render` mode by height: the drone pinned (``simulation.drone_fixed``)
over the moving deck at 4, 2, 1, 0.6 and 0.3 m, one environment, for each renderer
(``camera.renderer``: ``planar``, the default, and ``bullet``, PyBullet's TinyRenderer; and
``planar+realistic``: ``sensors: realistic``, the OV9281-class camera's blur and noise), with
the time of a step and of a full-frame ``render()`` (``rgb_array``), each as CPU time of this
process (``time.process_time``, what the run costs when the machine is shared) and wall time.
Only ``--heights`` runs that table alone.

Each row of the first table is set against the physics ceiling of the same run: the CPU time
of the bare ``stepSimulation`` calls of the env's own world during the row's steps (the same
sub-steps, the same states), over the row's CPU time per step (1 would be a step that costs
its physics alone).  The timing task (``DeckLandingTiming-BenchSS4-v6``, ``step(0)`` in a loop,
reset at each end) is a row of its own: its steps are wait decisions, each some two control
periods of the hold, its CPU time is per decision, and its ceiling is its own physics.  When
gym-pybullet-drones or PyFlyt is importable, their hover tasks run beside the rows (at their
own step rates: HoverAviary's 30 Hz, QuadX-Hover-v4's 40 Hz), each with its fraction of its
own physics ceiling; otherwise the output says they are not installed.

``--profile`` prints, instead of the tables, the top functions by cumulative and by own CPU
time of ``--seconds`` simulated seconds of `project` mode with the truth observed, with
`tight`, and with `tight` under realistic sensing (cProfile; ``--profile-top`` rows each),
and the CPU time of a step of each case without the profiler and under it (cProfile's own
cost, with CPU time as its clock, is several times the step's)::

    .venv/bin/python -m benchmarks.bench_env_speed --profile --seconds 20

``--tight-starts`` prints what each start of ``tight`` costs and gains instead: over
``--seconds`` of a slow descent in `project` mode (ideal and realistic sensing), every frame
is estimated by ``tight`` as configured (``previous_start: fallback``: IPPE and ToF-plane
starts) and with ``previous_start: first``, each timed by CPU, with the Levenberg–Marquardt
iterations of every start refined, and each compared with the true pose.

``--api-floor`` prints what PyBullet's API costs a step alone: the steps of each profiled
case (and of a hover 0.5 m over the deck, and the timing task's wait decisions) are run as the
env runs them (CPU time and physics), then run again with every PyBullet call recorded
(:class:`ApiRecorder`), and the recorded calls replayed from the states saved before them
(``saveState``/``restoreState``) with nothing between them: all of them, and each
``stepSimulation`` of them timed alone.  Their ratio is the highest fraction of the physics
ceiling a step making those calls from Python can reach; every replay must end in the
recorded states, bit for bit::

    .venv/bin/python -m benchmarks.bench_env_speed --api-floor --seconds 20 --repeats 5
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import cProfile
import dataclasses
import importlib.util
import inspect
import multiprocessing as mp
import pstats
import statistics
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pybullet as p
from pybullet_utils.bullet_client import BulletClient
from rich.console import Console
from rich.table import Table

import landing_env  # noqa: F401


def _env(mode: str, estimator: str, sensors: str, **overrides: Any) -> gym.Env:
    """``DeckLanding-v2`` as the first table's rows run it (no end by time), with the camera
    mode, observed estimator and sensor set named, and any further ``overrides``."""
    overrides = {
        "camera.mode": mode,
        "estimation.observed": estimator,
        "simulation.max_episode_s": 1e4,
        "sensors": sensors,
        **overrides,
    }
    return gym.make("DeckLanding-v2", overrides=overrides)


def _run(
    mode: str, estimator: str, sim_seconds: float, seed: int, queue=None, sensors: str = "ideal"
) -> tuple[int, float, float, float, float]:
    """Steps, wall s, simulated s, CPU s and the CPU s of its ``stepSimulation`` calls."""
    env = _env(mode, estimator, sensors)
    env.reset(seed=seed)
    env_dt = 1.0 / env.unwrapped.config.simulation.env_hz
    steps = int(sim_seconds / env_dt)
    # hover: the drone stays in the air, so every step runs the full pipeline
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    env.step(action)
    start = time.perf_counter()
    cpu_start = time.process_time()
    with PhysicsClock() as physics:
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset(seed=seed)
    wall = time.perf_counter() - start
    cpu = time.process_time() - cpu_start
    env.close()
    result = (steps, wall, steps * env_dt, cpu, physics.cpu_s)
    if queue is not None:
        queue.put(result)
    return result


def _parallel(
    mode: str, estimator: str, sim_seconds: float, n: int, sensors: str = "ideal"
) -> tuple[int, float, float, float, float]:
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    procs = [
        ctx.Process(target=_run, args=(mode, estimator, sim_seconds, i, queue, sensors))
        for i in range(n)
    ]
    for proc in procs:
        proc.start()
    results = [queue.get() for _ in procs]
    for proc in procs:
        proc.join()
    steps = sum(r[0] for r in results)
    wall = max(r[1] for r in results)
    sim = sum(r[2] for r in results)
    cpu = sum(r[3] for r in results)
    physics = sum(r[4] for r in results)
    return steps, wall, sim, cpu, physics


@contextlib.contextmanager
def _pybullet_replaced(wrappers: dict[str, Callable[..., Any]]) -> Iterator[None]:
    """Put ``wrappers`` in place of PyBullet's functions of the same names while inside.

    Callers that go through the module (``pybullet.stepSimulation(physicsClientId=...)``)
    find a wrapper at the call.  ``BulletClient`` injects its client id only into PyBullet's
    built-in functions, not into a wrapper, so each wrapper is also set on the class as a
    method that passes the client's id (PyFlyt's aviary steps through ``BulletClient``).
    """
    saved = {name: getattr(p, name) for name in wrappers}

    def client_method(wrapper: Callable[..., Any]) -> Callable[..., Any]:
        def method(client: BulletClient, *args: Any, **kwargs: Any) -> Any:
            kwargs.setdefault("physicsClientId", client._client)
            return wrapper(*args, **kwargs)

        return method

    for name, wrapper in wrappers.items():
        setattr(p, name, wrapper)
        setattr(BulletClient, name, client_method(wrapper))
    try:
        yield
    finally:
        for name, function in saved.items():
            setattr(p, name, function)
            delattr(BulletClient, name)


class PhysicsClock:
    """Times every ``pybullet.stepSimulation`` call of this process (CPU seconds).

    The world calls ``pybullet.stepSimulation`` once per physics sub-step; while the clock is
    installed each call is timed, so a row's physics is measured in the row's own run: the
    same world, the same sub-steps, the same states.  Its total over the row's steps is the
    physics ceiling: what a step would cost if nothing but the physics ran.  Calls through a
    ``BulletClient`` (the peers') are timed too; ``calls`` counts them all.
    """

    def __init__(self) -> None:
        self.cpu_s = 0.0
        self.calls = 0
        self._replaced: contextlib.AbstractContextManager[None] | None = None

    def __enter__(self) -> PhysicsClock:
        step, clock = p.stepSimulation, time.process_time

        def timed(*args, **kwargs):
            start = clock()
            try:
                return step(*args, **kwargs)
            finally:
                self.cpu_s += clock() - start
                self.calls += 1

        self._replaced = _pybullet_replaced({"stepSimulation": timed})
        self._replaced.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        assert self._replaced is not None
        self._replaced.__exit__(None, None, None)


#: the peers' hover tasks: (package to import, label, env id, module whose import registers it)
PEERS = (
    ("gym_pybullet_drones", "gym-pybullet-drones HoverAviary", "hover-aviary-v0", None),
    ("PyFlyt", "PyFlyt QuadX-Hover-v4", "PyFlyt/QuadX-Hover-v4", "PyFlyt.gym_envs"),
)


def _peer_env(package: str, env_id: str, module: str | None) -> tuple[gym.Env, float]:
    """The peer's hover task and its steps a simulated second."""
    if package == "gym_pybullet_drones":
        from gym_pybullet_drones.envs.HoverAviary import HoverAviary

        env = HoverAviary()
        return env, float(env.CTRL_FREQ)
    if module is not None:
        importlib.import_module(module)
    env = gym.make(env_id)
    # PyFlyt's QuadX tasks step its 120 Hz loop ``env_step_ratio`` times (QuadX-Hover-v4:
    # 3, a 40 Hz step; its ``render_fps`` of 30 is the viewer's)
    return env, 120.0 / env.unwrapped.env_step_ratio


def peer_rows(
    sim_seconds: float,
) -> tuple[list[tuple[str, int, float, float, float, float, int]], list[str]]:
    """The installed peers' rows (label, steps, wall s, simulated s, CPU s, CPU s of their
    ``stepSimulation`` calls, episode ends) and the names of those not installed; the
    resets at the episodes' ends are not in the times."""
    rows, missing = [], []
    for package, label, env_id, module in PEERS:
        if importlib.util.find_spec(package) is None:
            missing.append(label)
            continue
        env, fps = _peer_env(package, env_id, module)
        env.reset(seed=0)
        steps = max(1, int(sim_seconds * fps))
        action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
        if np.issubdtype(env.action_space.dtype, np.floating):
            action = 0.5 * (env.action_space.low + env.action_space.high)
        # the steps alone are timed: an episode's end (PyFlyt's drone leaves its bounds
        # under the held action within seconds) resets outside the clocks
        wall = cpu = resets_physics = 0.0
        ends = 0
        with PhysicsClock() as physics:
            for _ in range(steps):
                start_wall, start_cpu = time.perf_counter(), time.process_time()
                _, _, terminated, truncated, _ = env.step(action)
                wall += time.perf_counter() - start_wall
                cpu += time.process_time() - start_cpu
                if terminated or truncated:
                    ends += 1
                    before = physics.cpu_s
                    env.reset(seed=0)
                    resets_physics += physics.cpu_s - before
        env.close()
        rows.append((label, steps, wall, steps / fps, cpu, physics.cpu_s - resets_physics, ends))
    return rows, missing


#: the timing task measured beside the table: ``step(0)`` (wait) in a loop, reset at each end
TIMING_IDS = ("DeckLandingTiming-BenchSS4-v6",)


def wait_decisions(env_id: str, cpu_seconds: float) -> tuple[int, float, float, float]:
    """Wait decisions of the timing task ``env_id`` (default observation, ``step(0)``) over
    about ``cpu_seconds`` of CPU: (decisions, CPU s, physics CPU s, wall s)."""
    env = gym.make(env_id)
    env.reset(seed=0)
    decisions, episodes = 0, 0
    with PhysicsClock() as physics:
        wall = time.perf_counter()
        start = time.process_time()
        while time.process_time() - start < cpu_seconds:
            _, _, terminated, truncated, _ = env.step(0)
            decisions += 1
            if terminated or truncated:
                episodes += 1
                env.reset(seed=episodes)
        cpu = time.process_time() - start
        wall = time.perf_counter() - wall
    env.close()
    return decisions, cpu, physics.cpu_s, wall


#: the profiled cases: (label, observed estimator, sensors), all in `project` mode
PROFILE_CASES = (
    ("project mode, truth observed", "truth", "ideal"),
    ("project mode, tight", "tight", "ideal"),
    ("project mode, tight, realistic sensing", "tight", "realistic"),
)


def profile(console: Console, sim_seconds: float, top: int) -> None:
    """Print the top functions by cumulative CPU time of each profiled case."""
    root = str(Path(__file__).resolve().parents[1]) + "/"
    for label, estimator, sensors in PROFILE_CASES:
        env = _env("project", estimator, sensors)
        env.reset(seed=0)
        env_dt = 1.0 / env.unwrapped.config.simulation.env_hz
        steps = max(1, int(sim_seconds / env_dt))
        action = np.zeros(env.action_space.shape, dtype=np.float32)
        env.step(action)
        # the same steps without the profiler first: what a step costs unobserved
        unobserved = time.process_time()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset(seed=0)
        unobserved = time.process_time() - unobserved
        env.reset(seed=0)
        env.step(action)
        profiler = cProfile.Profile(time.process_time)
        profiler.enable()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset(seed=0)
        profiler.disable()
        env.close()
        stats = pstats.Stats(profiler)
        # the outermost call's cumulative time: the whole of the steps
        total = max(max(entry[3] for entry in stats.stats.values()), 1e-12)
        console.print(
            f"{label}: {1e3 * unobserved / steps:.3f} CPU ms/step without the profiler, "
            f"{1e3 * total / steps:.3f} under it"
        )
        # by cumulative time (where the step's time goes) and by own time (what to rewrite)
        for order, column in (("cumulative", 3), ("own", 2)):
            table = Table(title=f"{label}: {steps} steps, top {top} by {order} CPU time")
            for heading in ("function", "calls/step", "cumulative %", "own %"):
                table.add_column(heading, justify="left" if heading == "function" else "right")
            entries = sorted(stats.stats.items(), key=lambda item: item[1][column], reverse=True)
            for (path, line, name), (_, calls, own, cumulative, _) in entries[:top]:
                where = path.removeprefix(root) if path.startswith(root) else path
                if "site-packages/" in where:
                    where = where.split("site-packages/", 1)[1]
                site = f"{where}:{line}({name})" if line else name
                table.add_row(
                    site, f"{calls / steps:.1f}", f"{100 * cumulative / total:.1f}",
                    f"{100 * own / total:.1f}",
                )  # fmt: skip
            console.print(table)


def tight_starts(console: Console, sim_seconds: float) -> None:
    """Per frame: CPU, iterations (all starts) and error of ``tight`` by its start rule."""
    from estimation.tight_problem import TightProblem

    counts = {"solves": 0, "iterations": 0}
    solve = TightProblem.solve

    def counted(self, *args, **kwargs):
        solution = solve(self, *args, **kwargs)
        counts["solves"] += 1
        counts["iterations"] += solution.iterations if solution is not None else 0
        return solution

    table = Table(title=f"tight by start rule, {sim_seconds:g} s of a slow descent per row")
    for column in (
        "sensors", "previous_start", "valid", "CPU µs median / mean", "starts", "LM iterations",
        "kept previous", "position error mm median / p95", "tilt error deg median / p95",
        "gap to fallback mm / deg",
    ):  # fmt: skip
        table.add_column(column, justify="right")
    TightProblem.solve = counted
    try:
        for sensors in ("ideal", "realistic"):
            env = _env("project", "tight", sensors)
            env.reset(seed=0)
            env_dt = 1.0 / env.unwrapped.config.simulation.env_hz
            own = env.unwrapped.bank.estimators["tight"]
            variants = {"fallback": copy.deepcopy(own), "first": copy.deepcopy(own)}
            variants["first"].config = dataclasses.replace(own.config, previous_start="first")
            rows = {name: [] for name in variants}
            action = np.zeros(env.action_space.shape, dtype=np.float32)
            action[2] = -0.1  # a slow descent: every height from the start's down to the deck
            for _ in range(max(1, int(sim_seconds / env_dt))):
                _, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    env.reset(seed=0)
                    for estimator in variants.values():
                        estimator.reset()
                    continue
                sensing = env.unwrapped._sensing
                truth = np.asarray(info["deck_pose_true"], dtype=float)
                for name, estimator in variants.items():
                    counts["solves"] = counts["iterations"] = 0
                    cpu = time.process_time()
                    estimate = estimator.estimate(sensing.frame, sensing.ranges)
                    cpu = time.process_time() - cpu
                    pose = estimate.as_vector() if estimate.valid else np.full(6, np.nan)
                    rows[name].append(
                        (cpu, counts["solves"], counts["iterations"],
                         estimate.extras.get("start") == "previous", *pose, *truth)
                    )  # fmt: skip
            env.close()
            fallback = np.array(rows["fallback"])
            for name, data in ((n, np.array(r)) for n, r in rows.items()):
                # the frames with an estimate (those without one cost no refinement)
                valid = np.isfinite(data[:, 4])
                used, pose, truth = data[valid], data[valid, 4:10], data[valid, 10:16]
                position = 1e3 * np.linalg.norm(pose[:, :3] - truth[:, :3], axis=1)
                tilt = np.degrees(np.max(np.abs(pose[:, 3:5] - truth[:, 3:5]), axis=1))
                both = valid & np.isfinite(fallback[:, 4])
                gap_m = np.abs(data[both, 4:7] - fallback[both, 4:7]).max(initial=0.0)
                gap_rad = np.abs(data[both, 7:10] - fallback[both, 7:10]).max(initial=0.0)
                table.add_row(
                    sensors, name, f"{int(valid.sum())}/{len(data)}",
                    f"{1e6 * np.median(used[:, 0]):.0f} / {1e6 * np.mean(used[:, 0]):.0f}",
                    f"{np.mean(used[:, 1]):.2f}", f"{np.mean(used[:, 2]):.1f}",
                    f"{np.mean(used[:, 3]):.0%}",
                    f"{np.median(position):.2f} / {np.percentile(position, 95):.2f}",
                    f"{np.median(tilt):.3f} / {np.percentile(tilt, 95):.3f}",
                    f"{1e3 * gap_m:.3f} / {np.degrees(gap_rad):.4f}",
                )  # fmt: skip
    finally:
        TightProblem.solve = solve
    console.print(table)


class ApiRecorder:
    """Records every call of a PyBullet function in this process while installed: PyBullet's
    own function, its arguments and its keywords, in the order made (``calls``).

    Each call goes on to PyBullet at once, so the recorded run is the run itself; replaying
    ``calls`` from the state it started in makes exactly the API calls it made.
    """

    #: left alone: a connection's own calls, which no step makes
    UNRECORDED = frozenset({"connect", "disconnect"})

    def __init__(self) -> None:
        self.calls: list[tuple[Callable[..., Any], tuple[Any, ...], dict[str, Any]]] = []
        self._replaced: contextlib.AbstractContextManager[None] | None = None

    def __enter__(self) -> ApiRecorder:
        calls = self.calls

        def recording(function: Callable[..., Any]) -> Callable[..., Any]:
            def record(*args: Any, **kwargs: Any) -> Any:
                calls.append((function, args, kwargs))
                return function(*args, **kwargs)

            return record

        functions = {
            name: value
            for name, value in vars(p).items()
            if inspect.isbuiltin(value) and name not in self.UNRECORDED
        }
        self._replaced = _pybullet_replaced({n: recording(f) for n, f in functions.items()})
        self._replaced.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        assert self._replaced is not None
        self._replaced.__exit__(None, None, None)


def _bodies_state(cid: int) -> tuple[tuple[Any, ...], ...]:
    """Every body's base pose and velocities in client ``cid`` (PyBullet's tuples)."""
    bodies = (p.getBodyUniqueId(i, physicsClientId=cid) for i in range(p.getNumBodies(cid)))
    return tuple(
        (
            p.getBasePositionAndOrientation(body, physicsClientId=cid),
            p.getBaseVelocity(body, physicsClientId=cid),
        )
        for body in bodies
    )


@dataclasses.dataclass
class ApiFloor:
    """What a run of steps costs in PyBullet's API alone, replayed from its recorded calls.

    Per repeat, ``api_s`` holds the CPU seconds of all the replayed calls, in the recorded
    order with nothing between them, and ``physics_s`` those of their ``stepSimulation``
    calls, each timed alone in a second replay (as :class:`PhysicsClock` times a row's).
    """

    steps: int
    calls: Counter[str]
    physics_s: list[float] = dataclasses.field(default_factory=list)
    api_s: list[float] = dataclasses.field(default_factory=list)
    #: the replay loop's own dispatch: the same loop with a function that does nothing
    dispatch_s: list[float] = dataclasses.field(default_factory=list)
    #: per function but ``stepSimulation``: its own calls replayed alone, one after another
    alone_s: dict[str, list[float]] = dataclasses.field(default_factory=dict)
    #: every replay of every block ended in the state its recorded steps ended in, bit for bit
    identical: bool = True


def api_floor(
    step: Callable[[], bool], reset: Callable[[], object], steps: int, repeats: int, block: int
) -> ApiFloor:
    """Record ``steps`` calls of ``step`` (true when the episode ended), then replay them.

    The steps are recorded in blocks of up to ``block`` steps, the world's state saved
    (``saveState``) before each; a step that ends an episode is left out, its block cut
    before it, and ``reset`` called.  Each repeat, for each block: restores its state and
    replays its calls once untimed (the first replay after a restore runs colder), then
    restores it before each timed replay: all the calls as a whole, by CPU; the same calls
    with each ``stepSimulation`` timed alone (the physics in the states the steps met:
    ``stepSimulation`` replayed without the forces would meet others, the drone falling
    onto the deck); and, for each other function, its own calls alone.
    """
    with ApiRecorder() as warm:
        step()
    cid = next(kw["physicsClientId"] for f, _, kw in warm.calls if f is p.stepSimulation)
    blocks: list[tuple[int, list[Any], tuple[Any, ...]]] = []
    recorded = 0
    while recorded < steps:
        state_id = p.saveState(physicsClientId=cid)
        calls: list[Any] = []
        end = _bodies_state(cid)
        ended = False
        for _ in range(min(block, steps - recorded)):
            with ApiRecorder() as recorder:
                ended = step()
            if ended:
                break
            calls += recorder.calls
            end = _bodies_state(cid)
            recorded += 1
        if calls:
            blocks.append((state_id, calls, end))
        else:
            p.removeState(state_id, physicsClientId=cid)
        if ended:
            reset()
    floor = ApiFloor(recorded, Counter(f.__name__ for _, c, _ in blocks for f, _, _ in c))
    others = [name for name in floor.calls if name != p.stepSimulation.__name__]
    clock, step_simulation = time.process_time, p.stepSimulation

    def nothing(*args: Any, **kwargs: Any) -> None:
        return None

    def replay(calls: list[Any]) -> float:
        start = clock()
        for function, args, kwargs in calls:
            function(*args, **kwargs)
        return clock() - start

    for _ in range(repeats):
        physics = api = dispatch = 0.0
        alone = dict.fromkeys(others, 0.0)
        for state_id, calls, end in blocks:
            p.restoreState(stateId=state_id, physicsClientId=cid)
            replay(calls)
            p.restoreState(stateId=state_id, physicsClientId=cid)
            api += replay(calls)
            floor.identical = floor.identical and _bodies_state(cid) == end
            p.restoreState(stateId=state_id, physicsClientId=cid)
            for function, args, kwargs in calls:
                if function is step_simulation:
                    start = clock()
                    function(*args, **kwargs)
                    physics += clock() - start
                else:
                    function(*args, **kwargs)
            floor.identical = floor.identical and _bodies_state(cid) == end
            for name in others:
                p.restoreState(stateId=state_id, physicsClientId=cid)
                alone[name] += replay([c for c in calls if c[0].__name__ == name])
            dispatch += replay([(nothing, args, kwargs) for _, args, kwargs in calls])
        floor.physics_s.append(physics)
        floor.api_s.append(api)
        floor.dispatch_s.append(dispatch)
        for name in others:
            floor.alone_s.setdefault(name, []).append(alone[name])
    for state_id, _, _ in blocks:
        p.removeState(state_id, physicsClientId=cid)
    return floor


#: the project rows' steps a simulated second (``simulation.env_hz``)
ROW_HZ = 20


def api_floor_table(console: Console, sim_seconds: float, repeats: int) -> None:
    """The API floor of each profiled case and of the timing task's wait decisions, beside
    what the same steps cost the env in the same process."""
    table = Table(
        title=f"PyBullet's API floor of a step: {sim_seconds:g} s a case, {repeats} replays"
    )
    for column in (
        "case", "steps", "API calls/step", "env CPU ms/step", "env physics ms/step",
        "replayed physics ms/step", "replayed API ms/step", "of which dispatch ms/step",
        "max fraction", "env fraction", "env beyond the API ms/step", "replay identical",
    ):  # fmt: skip
        table.add_column(column, justify="left" if column == "case" else "right")
    counts_table = Table(
        title="PyBullet's calls a step (replayed steps): calls / CPU µs a step of the calls alone"
    )
    counts_table.add_column("function")
    cases: list[tuple[str, Callable[[], gym.Env], Any]] = [
        (label, lambda e=estimator, s=sensors: _env("project", e, s), None)
        for label, estimator, sensors in PROFILE_CASES
    ]
    # low over the deck: the contacts and the ground effect's rays every sub-step
    cases.append(
        (
            "project mode, truth observed, 0.5 m over the deck",
            lambda: _env("project", "truth", "ideal", **{"start.height_m": (0.5, 0.5)}),
            None,
        )
    )
    cases += [
        (f"{env_id}, wait decisions", lambda i=env_id: gym.make(i), 0) for env_id in TIMING_IDS
    ]
    floors: list[ApiFloor] = []
    for label, make, held in cases:
        env = make()
        env.reset(seed=0)
        if held is None:
            held = np.zeros(env.action_space.shape, dtype=np.float32)
        # as many steps a case (the timing task's are decisions) as the rows' 20 Hz steps
        steps = max(1, int(sim_seconds * ROW_HZ))
        episodes = 0

        def step(env=env, held=held) -> bool:
            _, _, terminated, truncated, _ = env.step(held)
            return bool(terminated or truncated)

        def reset(env=env) -> None:
            nonlocal episodes
            episodes += 1
            env.reset(seed=episodes)

        step()
        # the steps as the env makes them, timed without the recorder
        with PhysicsClock() as physics:
            cpu = time.process_time()
            for _ in range(steps):
                if step():
                    reset()
            cpu = time.process_time() - cpu
        env_ms, env_physics_ms = 1e3 * cpu / steps, 1e3 * physics.cpu_s / steps
        episodes = 0
        env.reset(seed=0)
        step()
        floor = api_floor(step, reset, steps, repeats, block=20)
        env.close()
        per_step = 1e3 / floor.steps
        physics_ms = per_step * statistics.median(floor.physics_s)
        api_ms = per_step * statistics.median(floor.api_s)
        dispatch_ms = per_step * statistics.median(floor.dispatch_s)
        # the highest fraction of the physics ceiling a step on these calls can reach
        fraction = statistics.median(
            b / a for b, a in zip(floor.physics_s, floor.api_s, strict=True)
        )
        calls = sum(floor.calls.values()) / floor.steps
        console.print(
            f"{label}: {floor.steps} steps replayed, {calls:.1f} API calls/step; physics "
            f"{physics_ms:.3f} and API {api_ms:.3f} CPU ms/step replayed (best "
            f"{per_step * min(floor.physics_s):.3f} and {per_step * min(floor.api_s):.3f}; "
            f"dispatch {dispatch_ms:.3f}): at most {fraction:.2f} of the physics ceiling; the "
            f"env {env_ms:.3f} CPU ms/step, physics {env_physics_ms:.3f}: "
            f"{env_physics_ms / env_ms:.2f}; replay identical: {floor.identical}",
            soft_wrap=True,
        )
        table.add_row(
            label, str(floor.steps), f"{calls:.1f}", f"{env_ms:.3f}", f"{env_physics_ms:.3f}",
            f"{physics_ms:.3f}", f"{api_ms:.3f}", f"{dispatch_ms:.3f}", f"{fraction:.2f}",
            f"{env_physics_ms / env_ms:.2f}", f"{env_ms - api_ms:.3f}",
            "yes" if floor.identical else "no",
        )  # fmt: skip
        counts_table.add_column(label, justify="right")
        floors.append(floor)
    names = sorted(
        {name for floor in floors for name in floor.calls},
        key=lambda n: (-max(f.calls[n] / f.steps for f in floors), n),
    )
    for name in names:
        cells = []
        for floor in floors:
            cell = f"{floor.calls[name] / floor.steps:.2f}" if name in floor.calls else ""
            if name in floor.alone_s:
                cell += f" / {1e6 * statistics.median(floor.alone_s[name]) / floor.steps:.1f}"
            cells.append(cell)
        counts_table.add_row(name, *cells)
    console.print(table)
    console.print(counts_table)


HEIGHTS_M = (4.0, 2.0, 1.0, 0.6, 0.3)


def _by_height(case: str, height: float, steps: int, renders: int) -> dict[str, float]:
    """Per-step and per-render CPU and wall times (ms) with the drone pinned at a height.

    ``case`` is a renderer, optionally with ``+realistic`` (``sensors: realistic``).
    """
    renderer, _, extra = case.partition("+")
    overrides = {
        "camera.mode": "render",
        "camera.renderer": renderer,
        "estimation.observed": "ihrcf",
        "simulation.drone_fixed": True,
        "simulation.max_episode_s": 1e4,
        "start.height_m": (height, height),
        "start.max_offset_m": 0.0,
        "start.max_yaw_deg": 0.0,
    }
    if extra:
        overrides["sensors"] = extra
    env = gym.make("DeckLanding-v2", render_mode="rgb_array", overrides=overrides)
    env.reset(seed=0)
    env_dt = 1.0 / env.unwrapped.config.simulation.env_hz
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    env.step(action)
    cpu, wall = time.process_time(), time.perf_counter()
    for _ in range(steps):
        env.step(action)
    step_cpu, step_wall = (time.process_time() - cpu) / steps, (time.perf_counter() - wall) / steps
    cpu, wall = time.process_time(), time.perf_counter()
    for _ in range(renders):
        env.render()
    render_cpu = (time.process_time() - cpu) / renders
    render_wall = (time.perf_counter() - wall) / renders
    env.close()
    return {
        "step_cpu_ms": 1e3 * step_cpu,
        "step_wall_ms": 1e3 * step_wall,
        "rtf_cpu": env_dt / step_cpu,
        "rtf_wall": env_dt / step_wall,
        "render_cpu_ms": 1e3 * render_cpu,
        "render_wall_ms": 1e3 * render_wall,
    }


def height_table(console: Console, steps: int, renders: int, renderers: list[str]) -> None:
    table = Table(title="render mode by height (drone pinned, one env, 20 Hz steps)")
    for column in (
        "renderer",
        "height m",
        "step ms cpu / wall",
        "real-time factor cpu / wall",
        "rgb_array render ms cpu / wall",
    ):
        table.add_column(column, justify="right")
    for renderer in renderers:
        for height in HEIGHTS_M:
            r = _by_height(renderer, height, steps, renders)
            table.add_row(
                renderer,
                f"{height:g}",
                f"{r['step_cpu_ms']:.1f} / {r['step_wall_ms']:.1f}",
                f"{r['rtf_cpu']:.1f}x / {r['rtf_wall']:.1f}x",
                f"{r['render_cpu_ms']:.1f} / {r['render_wall_ms']:.1f}",
            )
            console.print(f"{renderer} {height} m: {r}")
    console.print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds per env")
    parser.add_argument("--render-seconds", type=float, default=20.0)
    parser.add_argument("--heights", action="store_true", help="only the table by height")
    parser.add_argument("--height-steps", type=int, default=100, help="steps per height")
    parser.add_argument(
        "--renderers",
        default="planar,planar+realistic,bullet",
        help="comma-separated renderers (planar, bullet), +realistic for sensors: realistic",
    )
    parser.add_argument("--no-heights", action="store_true", help="skip the table by height")
    parser.add_argument(
        "--sensors",
        default="ideal,realistic",
        help="comma-separated sensor sets of the first table's rows (ideal, realistic)",
    )
    parser.add_argument(
        "--envs", default="1,2", help="comma-separated environment counts of the first table"
    )
    parser.add_argument(
        "--profile",
        action="store_true",
        help="print the profile of a step (by cumulative and by own time) instead of the tables",
    )
    parser.add_argument("--profile-top", type=int, default=25, help="functions per profile")
    parser.add_argument(
        "--tight-starts", action="store_true", help="print what each start of tight costs"
    )
    parser.add_argument(
        "--api-floor",
        action="store_true",
        help="print what PyBullet's API calls of a step cost alone (recorded, then replayed)",
    )
    parser.add_argument("--repeats", type=int, default=5, help="replays of --api-floor")
    args = parser.parse_args()
    console = Console(width=180)
    if args.api_floor:
        api_floor_table(console, args.seconds, args.repeats)
        return
    if args.tight_starts:
        tight_starts(console, args.seconds)
        return
    if args.profile:
        profile(console, args.seconds, args.profile_top)
        return
    if not args.no_heights:
        height_table(console, args.height_steps, 10, args.renderers.split(","))
    if args.heights:
        return
    table = Table(title="DeckLanding-v2 speed (240 Hz physics, 20 Hz steps)")
    columns = ("sensors", "camera mode", "observed estimator", "envs", "steps/s")
    columns = (*columns, "real-time factor")
    # CPU time per step: what a shared machine inflates least (wall-clock figures need it idle)
    for column in (*columns, "CPU ms/step", "real-time factor by CPU", "of physics ceiling"):
        table.add_column(column, justify="right")
    cases = (
        ("ideal", "project", "truth", args.seconds),
        ("ideal", "project", "ihrcf", args.seconds),
        ("ideal", "project", "tight", args.seconds),
        ("ideal", "render", "ihrcf", args.render_seconds),
        # the realistic camera (blur, noise, lens), ToF noise and their calibrations
        ("realistic", "project", "tight", args.seconds),
        ("realistic", "render", "ihrcf", args.render_seconds),
        ("realistic", "render", "tight", args.render_seconds),
    )
    chosen = set(args.sensors.split(","))
    for sensors, mode, estimator, seconds in cases:
        if sensors not in chosen:
            continue
        for n in (int(count) for count in args.envs.split(",")):
            if n == 1:
                steps, wall, sim, cpu, physics = _run(mode, estimator, seconds, 0, None, sensors)
            else:
                steps, wall, sim, cpu, physics = _parallel(mode, estimator, seconds, n, sensors)
            table.add_row(
                sensors,
                mode,
                estimator,
                str(n),
                f"{steps / wall:.0f}",
                f"{sim / wall:.1f}x",
                f"{1e3 * cpu / steps:.2f}",
                f"{sim / cpu:.1f}x",
                f"{physics / cpu:.2f}",
            )
            console.print(
                f"{sensors} {mode}/{estimator} x{n}: {steps} steps in {wall:.1f} s, "
                f"{1e3 * cpu / steps:.3f} CPU ms/step, physics {1e3 * physics / steps:.3f} "
                f"CPU ms/step: {physics / cpu:.2f} of the physics ceiling"
            )
    for env_id in TIMING_IDS:
        decisions, cpu, physics, wall = wait_decisions(env_id, min(args.seconds, 15.0))
        console.print(
            f"{env_id}: {decisions / cpu:.0f} wait decisions/s by CPU ({decisions} in "
            f"{cpu:.1f} CPU s), {physics / cpu:.2f} of the physics ceiling"
        )
        # a row of its own: a step is a wait decision (its control periods inside it), so
        # its steps/s are decisions/s and its CPU time is per decision; no real-time factor
        table.add_row(
            "ideal", env_id, "default (wait decisions)", "1", f"{decisions / wall:.0f}", "",
            f"{1e3 * cpu / decisions:.2f}", "", f"{physics / cpu:.2f}",
        )  # fmt: skip
    peers, missing = peer_rows(args.seconds)
    for label, steps, wall, sim, cpu, physics, ends in peers:
        console.print(
            f"{label}: {steps} steps in {wall:.1f} s, {1e3 * cpu / steps:.3f} CPU ms/step, "
            f"physics {1e3 * physics / steps:.3f} CPU ms/step: {physics / cpu:.2f} of the "
            f"physics ceiling; {ends} episode ends (resets not timed)"
        )
        table.add_row(
            "peer", label, "", "1", f"{steps / wall:.0f}", f"{sim / wall:.1f}x",
            f"{1e3 * cpu / steps:.2f}", f"{sim / cpu:.1f}x", f"{physics / cpu:.2f}",
        )  # fmt: skip
    console.print(table)
    if missing:
        console.print(f"peers not installed (no rows): {', '.join(missing)}")


if __name__ == "__main__":
    main()
