"""The simulated world: PyBullet physics, the quadrotor, the Stewart-platform deck, the sensors.

This is the core simulation layer; the Gymnasium environments in :mod:`landing_env.envs` are
thin tasks on top of it.  One call to :meth:`World.step` advances one control period: the
controller, motors, deck motion and IMU run at the physics rate and their results are
aggregated for the step.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np
import pybullet as p
from pybullet_utils.bullet_client import BulletClient
from scipy.spatial.transform import Rotation

from estimation.frames import R_BC, R_PD, deck_pose_in_camera
from estimation.geometry import plane_of_ranges
from estimation.landmarks import landmark_pose_w
from estimation.types import CameraFrame, ImuSample, RangeReading
from landing_env._quiet import quiet_stdout
from landing_env.config import DeckLandingConfig
from landing_env.physics.controller import CascadeController, VelocitySetpoint
from landing_env.physics.drone_state import DroneState
from landing_env.physics.quadrotor import Quadrotor
from landing_env.physics.quadrotor_params import GRAVITY, QuadrotorParams
from landing_env.physics.wind import WindModel
from landing_env.scene.deck import create_deck_body, make_deck_texture
from landing_env.sea.deck_mount import ShipDeck
from landing_env.sensors.camera import CameraSensor
from landing_env.sensors.camera_realism import RelativeMotion
from landing_env.sensors.imu import ImuModel
from landing_env.sensors.planar_renderer import planar_scene_or_none
from landing_env.sensors.rangefinder import Rangefinder
from landing_env.sensors.tag_view import TagPlacement
from landing_env.sensors.tof import TofArray
from landing_env.stewart.motion import CsvMotion, make_motion_source
from landing_env.stewart.platform import StewartPlatform, StewartStatus
from landing_env.touchdown import (
    ContactSummary,
    TouchdownMetrics,
    TouchdownProbe,
    contact_metrics,
    spool_down_thrust_n,
    summarise_contacts,
)

#: mass of the top plate: heavy against the drone so that touchdowns do not deflect it
TOP_PLATE_MASS_KG = 15.0
#: below this height of the drone above the deck's home surface, contacts are checked every
#: physics step; it exceeds the deck's heave reach plus the feet's depth with a wide margin
CONTACT_WATCH_HEIGHT_M = 0.8
#: ... for a deck up to 1 m square; a larger deck's corners rise further as it tilts, so the
#: height grows by its extra half-diagonal times the sine of this tilt (beyond the workspace)
CONTACT_WATCH_TILT_DEG = 15.0


@dataclass
class DeckState:
    """The top plate (frame P) and the tag frame D in the world, from PyBullet."""

    position_w: np.ndarray
    rotation_wp: np.ndarray
    velocity_w: np.ndarray
    angular_velocity_w: np.ndarray

    @property
    def tag_centre_w(self) -> np.ndarray:
        return self.position_w

    @property
    def rotation_wd(self) -> np.ndarray:
        return self.rotation_wp @ R_PD


def _deck_state_of(reading: tuple[tuple[float, ...], ...], cid: int) -> DeckState:
    """The :class:`DeckState` of a :meth:`World._deck_reading` (client ``cid``)."""
    position, orientation, velocity, angular = reading
    rotation = np.asarray(p.getMatrixFromQuaternion(orientation, physicsClientId=cid))
    return DeckState(
        np.asarray(position), rotation.reshape(3, 3), np.asarray(velocity), np.asarray(angular)
    )


@dataclass
class PhysicsReport:
    """What happened during one control period."""

    imu_samples: list[ImuSample] = field(default_factory=list)
    first_contact: TouchdownMetrics | None = None
    forbidden_contact: str = ""
    stewart: StewartStatus | None = None
    stewart_clamped: bool = False
    motor_saturated: bool = False


#: how far under the deck surface a harpoon's tension pulls the point between the feet, m:
#: more than the gear deflects under its force, so the harpoon presses the drone down
HARPOON_DRAW_M = 0.01


class World:
    """One PyBullet world with the drone, the deck on its Stewart platform and the sensors."""

    def __init__(self, config: DeckLandingConfig, gui: bool = False) -> None:
        self.config = config
        sim = config.simulation
        self.dt = 1.0 / sim.physics_hz
        self.substeps = sim.substeps
        if gui and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            # PyBullet's GUI aborts the whole process without a display: refuse cleanly instead
            raise RuntimeError(
                "render_mode='human' (simulation.gui) needs a display; none is set (DISPLAY). "
                "Use render_mode='rgb_array' on a headless machine, or run under Xvfb."
            )
        with quiet_stdout():  # PyBullet prints ``argv[0]=`` from C on connect
            self.client = BulletClient(connection_mode=p.GUI if gui else p.DIRECT)
        c = self.client
        c.setGravity(0.0, 0.0, -GRAVITY)
        c.setTimeStep(self.dt)
        c.setPhysicsEngineParameter(deterministicOverlappingPairs=1)
        if gui:
            c.configureDebugVisualizer(p.COV_ENABLE_GUI, 0)
        rng = np.random.default_rng(0)
        # before any body: the EGL renderer (camera.use_egl) draws only bodies created after
        # its plugin is loaded (the camera draws nothing from rng until the first step)
        self.camera = CameraSensor(c, config.camera, rng)

        # the sea / hangar floor; nothing assumes it is the landing surface
        plane_shape = c.createCollisionShape(p.GEOM_PLANE)
        plane_visual = c.createVisualShape(
            p.GEOM_BOX, halfExtents=[30.0, 30.0, 0.001], rgbaColor=[0.16, 0.30, 0.42, 1.0]
        )
        self.ground_id = c.createMultiBody(0.0, plane_shape, plane_visual, [0.0, 0.0, 0.0])

        self.params = QuadrotorParams.from_yaml(config.vehicle or None)
        self.drone = Quadrotor(c, self.params)
        self.controller = CascadeController(self.params, config.controller)
        self.foot_links = frozenset(self.drone.foot_link_indices)
        self._drone_colours = {
            shape[1]: tuple(shape[7]) for shape in c.getVisualShapeData(self.drone.body_id)
        }
        self.t_bc = np.asarray(self.params.camera_offset_b, dtype=float)

        if config.deck_mount == "ship":
            # a full-scale helideck: no legs, no workspace, home high above the sea plane
            home = np.array([0.0, 0.0, config.ship_deck_height_m])
            self.deck_id = create_deck_body(
                c, config.deck, TOP_PLATE_MASS_KG, home, [0.0, 0.0, 0.0, 1.0]
            )
            self.stewart: StewartPlatform = ShipDeck(
                c, home, self.deck_id, make_motion_source(config.motion, rng)
            )
        else:
            base_position = np.asarray(config.stewart_base_position, dtype=float)
            self.deck_id = create_deck_body(
                c, config.deck, TOP_PLATE_MASS_KG, base_position, [0.0, 0.0, 0.0, 1.0]
            )
            self.stewart = StewartPlatform(
                c,
                config.stewart,
                base_position,
                self.deck_id,
                make_motion_source(config.motion, rng),
            )
        # Bullet multiplies the two bodies' friction coefficients: the deck's 1 leaves the pair
        # the feet's (landing_gear.friction in the vehicle YAML)
        c.changeDynamics(self.deck_id, -1, lateralFriction=1.0, restitution=0.0)
        home_position, _ = self.stewart.home_pose_w()
        self.deck_home_w = np.asarray(home_position, dtype=float)
        self._extra_half_diagonal = max(0.0, (config.deck.size - 1.0) * math.sqrt(0.5))
        self.contact_watch_height_m = self._watch_height()
        hx, hy, hz = self.deck_home_w.tolist()
        self._deck_home_floats = (hx, hy, hz)
        self._airwake = config.wind.enabled and config.wind.airwake_radius_m > 0.0
        if config.camera.renderer == "planar":
            scene = planar_scene_or_none(
                c._client,
                config.camera,
                self.deck_id,
                config.deck,
                make_deck_texture(config.deck),
                hidden_bodies=(self.drone.body_id,),
            )
            if scene is not None:
                self.camera.attach_scene(scene)
        self._landmarks = config.deck.layout.landmarks
        self.tof = TofArray(c, config.tof, rng, self.t_bc)
        self.rangefinder = Rangefinder(c, config.rangefinder, rng)
        #: the latest downward rangefinder reading (for estimators that use it: ``beacon``)
        self.last_range_down = RangeReading(0.0, np.full(1, np.nan), np.zeros(1, dtype=bool))
        self.imu = ImuModel(config.imu, rng, sim.physics_hz)
        self.wind = WindModel(config.wind, rng)
        self.time = 0.0
        self.armed = True
        #: the drone is held at its start pose (the papers' bench), see SimulationConfig
        self.pinned = config.simulation.drone_fixed
        self._pinned_pose: tuple[list[float], list[float]] = ([0.0] * 3, [0.0, 0.0, 0.0, 1.0])
        self._state: DroneState | None = None
        #: the touchdown being settled, and its per-physics-step probe (None in flight)
        self._touchdown: TouchdownMetrics | None = None
        self._probe: TouchdownProbe | None = None
        #: the deck-securing device's constraint while it holds the drone (None otherwise)
        self._harpoon: int | None = None
        self._foot_radius = float(
            c.getCollisionShapeData(self.drone.body_id, min(self.foot_links))[0][3][0]
        )

    # ------------------------------------------------------------------ episode control
    def reset(self, rng: np.random.Generator, position_w: np.ndarray, yaw: float) -> None:
        """Start an episode: new random streams, deck at t = 0, drone hovering at a pose."""
        streams = rng.spawn(5)
        self.stewart.motion = make_motion_source(self.config.motion, streams[0])
        self.camera.rng = streams[1]
        self.tof.rng = streams[2]
        self.imu.rng = streams[3]
        self.imu.reset()
        self.wind = WindModel(self.config.wind, streams[4])
        # a stream of its own: the other sensors' streams are unchanged by its addition
        self.rangefinder.rng = rng.spawn(1)[0]
        self.last_range_down = RangeReading(0.0, np.full(1, np.nan), np.zeros(1, dtype=bool))
        self.time = 0.0
        self.stewart.reset(0.0)
        self.contact_watch_height_m = self._watch_height()
        if self.config.start.relative_to == "deck":
            # the start is given from the deck's home: carry it to where the deck is now
            deck_now, _ = self.stewart.top_plate_pose_w()
            position_w = np.asarray(position_w, dtype=float) + (deck_now - self.deck_home_w)
        self.drone.reset(position_w, yaw)
        self._pinned_pose = (
            [float(v) for v in position_w],
            [0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)],
        )
        self.controller.reset()
        self._touchdown = None
        self._probe = None
        self.release_from_deck()
        self.armed = True
        self._state = self.drone.read_state()
        self._hover_rotors()
        if self.config.start.trim_to_wind and self.config.wind.enabled:
            self._trim_to_wind(position_w, yaw)

    def redraw_unknowable_future(self, rng: np.random.Generator) -> None:
        """Give the future what no one on board could know a new draw from ``rng``: the gusts'
        innovations (the present gust kept) and every sensor's noise.  The deck's motion, a
        fixed function of time since the reset, and the present state stay: a look-ahead
        from a snapshot then knows the deck's future but not the wind's (the deck oracle,
        :mod:`agents.policies.oracle`)."""
        streams = rng.spawn(5)
        self.wind.redraw(streams[0])
        self.camera.rng = streams[1]
        self.tof.rng = streams[2]
        self.imu.rng = streams[3]
        self.rangefinder.rng = streams[4]

    def _watch_height(self) -> float:
        """Height above the deck's home below which contacts are checked every physics step.

        The bench's deck moves centimetres; a ship deck carries its own reach (its motion's
        bound on vertical displacement and tilt, ``vertical_reach_m`` / ``tilt_reach_rad``).
        """
        motion = self.stewart.motion
        reach = float(getattr(motion, "vertical_reach_m", 0.0))
        tilt = max(
            math.radians(CONTACT_WATCH_TILT_DEG), float(getattr(motion, "tilt_reach_rad", 0.0))
        )
        if isinstance(motion, CsvMotion) and self.config.deck_mount == "ship":
            reach = float(np.max(np.abs(motion.samples[:, 2])))
            tilt = max(tilt, float(np.max(np.abs(motion.samples[:, 3:5]))))
        half_diagonal = self._extra_half_diagonal
        if self.config.deck_mount == "ship":
            half_diagonal = 0.5 * self.config.deck.size * math.sqrt(2.0)
        return CONTACT_WATCH_HEIGHT_M + reach + half_diagonal * math.sin(min(tilt, 1.5))

    def place_drone(self, position_w: np.ndarray, yaw: float) -> None:
        """Put the drone level at a pose without stepping time (a calibration rig's move)."""
        self.drone.reset(position_w, yaw)
        self._state = self.drone.read_state()

    @property
    def foot_radius_m(self) -> float:
        """The radius of the drone's feet (their collision spheres), m."""
        return self._foot_radius

    def shift_drone(self, shift_w: np.ndarray) -> None:
        """Move the drone by ``shift_w`` (m, world frame) keeping its attitude and velocities,
        without stepping time: a look-ahead's model of where the drone is
        (:mod:`agents.policies.deck_forecast`).  A non-finite or misshapen shift is refused by
        name."""
        shift = np.asarray(shift_w, dtype=float).reshape(-1)
        if shift.shape != (3,) or not np.all(np.isfinite(shift)):
            raise ValueError(f"shift_w must be 3 finite metres, got {shift_w!r}")
        state = self.drone_state()
        body = self.drone.body_id
        velocity, angular = self.client.getBaseVelocity(body)
        self.client.resetBasePositionAndOrientation(
            body, (state.position_w + shift).tolist(), state.quaternion_xyzw.tolist()
        )
        self.client.resetBaseVelocity(body, velocity, angular)
        self._state = self.drone.read_state()

    def _trim_to_wind(self, position_w: np.ndarray, yaw: float) -> None:
        """Lean into the mean wind at rest: the thrust carries the weight and the linear body
        drag of the air going past (found by fixed-point iteration, the drag depending on the
        attitude), the rotors at that thrust, the controller's integrators holding it."""
        prm = self.params
        wind = np.asarray(self.config.wind.mean_velocity_w, dtype=float)
        if not np.all(np.isfinite(wind)) or float(np.linalg.norm(wind)) < 1e-9:
            return
        heading = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        rotation = Rotation.from_euler("z", yaw).as_matrix()
        thrust_w = np.array([0.0, 0.0, prm.mass * GRAVITY])
        for _ in range(8):
            drag_w = rotation @ (-prm.linear_drag_b * (rotation.T @ -wind))
            thrust_w = np.array([0.0, 0.0, prm.mass * GRAVITY]) - drag_w
            z_b = thrust_w / np.linalg.norm(thrust_w)
            y_b = np.cross(z_b, heading)
            y_b /= np.linalg.norm(y_b)
            rotation = np.column_stack([np.cross(y_b, z_b), y_b, z_b])
        self.drone.reset(position_w, yaw, rotation_wb=rotation)
        thrust = float(np.linalg.norm(thrust_w))
        # a wind beyond what the rotors can carry starts at full speed (and is blown away)
        omega = min(math.sqrt(thrust / (4.0 * prm.k_f)), prm.omega_max)
        self.drone.set_rotor_speeds(np.full(4, omega))
        self.controller.preload_acceleration(thrust_w / prm.mass)
        self._state = self.drone.read_state()

    def _hover_rotors(self) -> None:
        """Spin the rotors up to hover so that an episode does not start with a drop."""
        hover = math.sqrt(self.params.mass * GRAVITY / (4.0 * self.params.k_f))
        self.drone.set_rotor_speeds(np.full(4, hover))

    def disarm(self) -> None:
        """Cut the motors to idle (after touchdown, as a land detector does)."""
        self.armed = False
        self.controller.thrust_cap_n = math.inf
        self.controller.thrust_axis_w = None

    # ------------------------------------------------------------------ stepping
    def step(self, setpoint: VelocitySetpoint, monitor_contacts: bool = True) -> PhysicsReport:
        """Advance one control period (``substeps`` physics steps)."""
        report = PhysicsReport()
        cid = self.client._client
        dt = self.dt
        idle = [self.params.omega_min] * 4
        watch_below = self.deck_home_w[2] + self.contact_watch_height_m
        # nothing in the world stands as high as the watch height (the contacts' own rule)
        self.drone.surfaces_below_z = float(watch_below)
        # the hot loop works on plain floats: small numpy arrays cost more than the physics
        times: list[float] = []
        rotations: list[tuple[float, ...]] = []
        accels: list[tuple[float, float, float]] = []
        rates: list[tuple[float, float, float]] = []
        probe = self._probe
        # the loop's callees and flags looked up once (nothing in the loop replaces them)
        drone, body = self.drone, self.drone.body_id
        read_state = drone.read_state
        update = self.controller.update_floats
        apply_rotor_commands = drone.apply_rotor_commands
        wind_velocity = self.wind.velocity_tuple
        airwake = self.wind.airwake if self._airwake else None
        advance = self.stewart.advance
        step_simulation = p.stepSimulation
        flying, armed = not self.pinned, self.armed
        saturated = report.motor_saturated
        clamped = report.stewart_clamped
        for _ in range(self.substeps):
            state = self._state if self._state is not None else read_state()
            if flying:
                command = update(state, setpoint, dt) if armed else idle
                wind = wind_velocity(self.time, dt)
                if airwake is not None:
                    px, py, pz = state.floats.position_w
                    hx, hy, hz = self._deck_home_floats
                    wind = airwake(wind, (px - hx, py - hy, pz - hz))
                drone.wind_velocity_w = wind
                apply_rotor_commands(command, dt, state)
                saturated |= drone.last_saturated
            clamped |= advance(self.time + dt)
            # contacts need the states just before the touch; nothing in the world stands
            # higher than the deck's reach, so far above it the queries are skipped
            near_deck = monitor_contacts and state.floats.position_w[2] < watch_below
            deck_before = self._deck_reading() if near_deck else None
            step_simulation(physicsClientId=cid)
            if not flying:
                p.resetBasePositionAndOrientation(body, *self._pinned_pose, physicsClientId=cid)
                p.resetBaseVelocity(body, [0.0] * 3, [0.0] * 3, physicsClientId=cid)
            self.time += dt
            if probe is not None:
                probe.update()
            new_state = read_state()
            v0, new = state.floats.velocity_w, new_state.floats
            v1 = new.velocity_w
            times.append(self.time)
            rotations.append(new.rotation_wb)
            accels.append(((v1[0] - v0[0]) / dt, (v1[1] - v0[1]) / dt, (v1[2] - v0[2]) / dt))
            rates.append(new.angular_velocity_b)
            self._state = new_state
            if near_deck:
                contacts = self.contacts()
                if contacts.forbidden and not report.forbidden_contact:
                    report.forbidden_contact = contacts.forbidden_what
                if contacts.feet_on_deck and report.first_contact is None:
                    assert deck_before is not None
                    deck = _deck_state_of(deck_before, cid)
                    report.first_contact = metrics = contact_metrics(
                        self.time,
                        state.position_w,
                        state.velocity_w,
                        state.rotation_wb,
                        deck.position_w,
                        deck.rotation_wp,
                        deck.velocity_w,
                        deck.angular_velocity_w,
                        deck.tag_centre_w,
                    )
                    metrics.deck_vertical_accel_g = self._deck_vertical_accel(self.time) / GRAVITY
                    self._touchdown = metrics
                if report.first_contact is not None or report.forbidden_contact:
                    break
        report.motor_saturated = saturated
        report.stewart_clamped = clamped
        report.imu_samples = self.imu.sample_many(times, rotations, accels, rates)
        report.stewart = self.stewart.last_status
        return report

    def settle(
        self, duration_s: float, setpoint: VelocitySetpoint | None = None
    ) -> tuple[set[int], bool, str, set[int]]:
        """Run the touchdown's settle: the land sequence (``touchdown.spool_down_s``), then
        disarmed for ``duration_s``; return feet seen on deck, on-deck-at-end, crash.

        With ``spool_down_s`` 0 (the default) the motors are cut at the first contact.
        Otherwise the controller stays armed that long after it: PX4's land detector
        sequence (ground contact, thrust lowered, landed, disarm) rather than a cut at the
        first touch.  The attitude loop aims the thrust along the deck's normal as the
        drone's ToF ranges measure it each step (:meth:`deck_normal_measured_w`), the
        velocity loop flies ``setpoint`` (the guidance's last; none: hold still), and the
        collective thrust it may ask for falls linearly from the weight to
        ``spool_down_final_thrust`` of it.  With ``harpoon_force_n`` above 0 a deck-securing
        device holds the drone down from the contact on (:meth:`secure_to_deck`).
        """
        touchdown = self.config.touchdown
        feet_seen: set[int] = set()
        forbidden = ""
        end_feet: set[int] = set()
        self._probe = TouchdownProbe(
            self.client._client,
            self.drone.body_id,
            self.deck_id,
            self.foot_links,
            self._foot_radius,
            touchdown.tip_over_deg,
        )
        if touchdown.harpoon_force_n > 0.0:
            self.secure_to_deck(touchdown.harpoon_force_n)
        env_hz = self.config.simulation.env_hz
        spool_steps = round(touchdown.spool_down_s * env_hz) if self.armed else 0
        hold = setpoint if setpoint is not None else VelocitySetpoint(np.zeros(3), 0.0)
        zero = VelocitySetpoint(np.zeros(3), 0.0)
        steps = max(1, round(duration_s * env_hz))
        for i in range(spool_steps + steps):
            if i < spool_steps:
                self.controller.thrust_cap_n = spool_down_thrust_n(
                    (i + 1) / spool_steps, self.params.weight, touchdown.spool_down_final_thrust
                )
                measured = self.deck_normal_measured_w()
                if measured is not None:  # else the last measured one (none: the loop's)
                    self.controller.thrust_axis_w = measured
            elif self.armed:
                self.disarm()
            report = self.step(hold if i < spool_steps else zero, monitor_contacts=False)
            del report
            contacts = self.contacts()
            feet_seen |= set(contacts.feet_on_deck)
            end_feet = set(contacts.feet_on_deck)
            if contacts.forbidden and not forbidden:
                forbidden = contacts.forbidden_what
        self.stewart.update_leg_visuals()
        if self._touchdown is not None:
            self._probe.fill(self._touchdown, self.params.weight)
        self._probe = None
        return feet_seen, len(end_feet) >= 3 and not forbidden, forbidden, end_feet

    def deck_normal_measured_w(self) -> tuple[float, float, float] | None:
        """The deck's upward normal in W as the drone measures it: the plane through its ToF
        ranges (a reading now, with its noise), placed at the sensors' nominal origins along
        the camera's axis (``tof.mount_offsets_c``; a misaligned beam is not known to the
        drone), fitted in C (:func:`~estimation.geometry.plane_of_ranges`) and turned into W by the
        drone's attitude (its autopilot's estimate, the truth here as everywhere the
        simulated autopilot is read).  None with fewer than three valid ranges or a
        degenerate layout."""
        state = self.drone_state()
        reading = self.tof.measure(
            self.time, state.position_w, state.rotation_wb, self.drone.body_id
        )
        valid = np.asarray(reading.valid, dtype=bool)
        if int(valid.sum()) < 3:
            return None
        sensors_c = np.asarray(self.config.tof.mount_offsets_c, dtype=float)[valid]
        plane = plane_of_ranges(sensors_c, np.asarray(reading.ranges, dtype=float)[valid])
        if plane is None:
            return None
        # the plane's normal points along +z_C, away from the camera: the deck's up is its
        # opposite
        up_w = state.rotation_wb @ (R_BC @ -plane.normal)
        return (float(up_w[0]), float(up_w[1]), float(up_w[2]))

    def secure_to_deck(self, max_force_n: float) -> None:
        """Hold the drone down on the deck with at most ``max_force_n`` (a harpoon under its
        centre engaging a deck grid): a point-to-point constraint that pulls the point
        between its feet, at their soles, towards the deck under it (``HARPOON_DRAW_M``
        below the surface); the attitude is left to the gear."""
        c = self.client
        deck_position, deck_orientation = c.getBasePositionAndOrientation(self.deck_id)
        drone_position, drone_orientation = c.getBasePositionAndOrientation(self.drone.body_id)
        rotation = np.asarray(c.getMatrixFromQuaternion(drone_orientation)).reshape(3, 3)
        feet_w = np.array(
            [f[0] for f in c.getLinkStates(self.drone.body_id, sorted(self.foot_links))]
        )
        sole_w = feet_w.mean(axis=0) - self._foot_radius * rotation[:, 2]
        in_body = rotation.T @ (sole_w - np.asarray(drone_position))
        deck_rotation = np.asarray(c.getMatrixFromQuaternion(deck_orientation)).reshape(3, 3)
        feet_deck = (feet_w - np.asarray(deck_position)) @ deck_rotation
        anchor = deck_rotation.T @ (sole_w - np.asarray(deck_position))
        # the deck's surface: where the lowest sole touches it at the first contact; the
        # harpoon's tension pulls towards a point HARPOON_DRAW_M under it (held short by
        # the gear), so it presses the drone down with up to its force
        anchor[2] = float(feet_deck[:, 2].min()) - self._foot_radius - HARPOON_DRAW_M
        self._harpoon = c.createConstraint(
            self.deck_id,
            -1,
            self.drone.body_id,
            -1,
            p.JOINT_POINT2POINT,
            [0.0, 0.0, 0.0],
            anchor.tolist(),
            in_body.tolist(),
        )
        c.changeConstraint(self._harpoon, maxForce=max_force_n)

    def release_from_deck(self) -> None:
        """Let go of the deck (:meth:`secure_to_deck`); nothing when not held."""
        if self._harpoon is not None:
            self.client.removeConstraint(self._harpoon)
            self._harpoon = None

    def _deck_vertical_accel(self, t: float, h: float = 0.01) -> float:
        """Vertical acceleration of the deck's commanded motion at ``t`` (m/s^2)."""
        motion = self.stewart.motion
        return float(motion.velocity(t + h)[2] - motion.velocity(max(0.0, t - h))[2]) / (2 * h)

    def contacts(self) -> ContactSummary:
        points = p.getContactPoints(bodyA=self.drone.body_id, physicsClientId=self.client._client)
        return summarise_contacts(points, self.foot_links, self.deck_id)

    def gust_gain_at_drone(self) -> float:
        """How much of the present gust reaches the drone where it is: 1, and inside the ship's
        airwake its turbulence factor there."""
        if not self._airwake:
            return 1.0
        offset = tuple((self.drone_state().position_w - self.deck_home_w).tolist())
        return (
            self.wind.airwake((1.0, 0.0, 0.0), offset)[0]
            - self.wind.airwake((0.0, 0.0, 0.0), offset)[0]
        )

    def shift_wind_at_drone(self, delta_w: np.ndarray) -> None:
        """Change the present gust so that the wind at the drone changes by ``delta_w`` (m/s,
        world): inside the ship's airwake a gust reaches the drone scaled by its turbulence
        factor."""
        delta = np.asarray(delta_w, dtype=float).reshape(-1)
        if delta.shape != (3,) or not np.all(np.isfinite(delta)):
            raise ValueError(f"delta_w must be 3 finite m/s values, got {delta_w!r}")
        gain = self.gust_gain_at_drone()
        if gain > 1e-9:
            self.wind.set_present_gust_w(self.wind.gust_w + delta / gain)

    # ------------------------------------------------------------------ sensing and truth
    def drone_state(self) -> DroneState:
        if self._state is None:
            self._state = self.drone.read_state()
        return self._state

    def deck_state(self) -> DeckState:
        return _deck_state_of(self._deck_reading(), self.client._client)

    def _deck_reading(self) -> tuple[tuple[float, ...], ...]:
        """The top plate's pose and velocities as PyBullet gives them (plain tuples)."""
        cid, deck = self.client._client, self.deck_id
        position, orientation = p.getBasePositionAndOrientation(deck, physicsClientId=cid)
        velocity, angular = p.getBaseVelocity(deck, physicsClientId=cid)
        return position, orientation, velocity, angular

    def camera_pose_w(self) -> tuple[np.ndarray, np.ndarray]:
        state = self.drone_state()
        return state.position_w + state.rotation_wb @ self.t_bc, state.rotation_wb @ R_BC

    def true_deck_pose_c(self, deck: DeckState | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Ground truth ``(R_CD, t_CD)``: the tag frame in the camera frame (``deck``: the
        :meth:`deck_state` already read now, if any)."""
        state = self.drone_state()
        if deck is None:
            deck = self.deck_state()
        return deck_pose_in_camera(
            state.position_w, state.rotation_wb, deck.position_w, deck.rotation_wp, self.t_bc
        )

    def _drone_visible(self, visible: bool) -> None:
        """Show or hide the drone's own visuals.

        The camera hides its own airframe: parts within the near plane make TinyRenderer's
        rasteriser blow up (seconds per frame), and a real camera on the belly does not see them.
        """
        alpha = 1.0 if visible else 0.0
        for link, colour in self._drone_colours.items():
            self.client.changeVisualShape(
                self.drone.body_id, link, rgbaColor=[*colour[:3], alpha * colour[3]]
            )

    def camera_motion(self) -> RelativeMotion:
        """The camera's and the deck's motion now, for the exposure (motion blur)."""
        state = self.drone_state()
        deck = self.deck_state()
        omega_w = state.rotation_wb @ state.angular_velocity_b
        v_camera = state.velocity_w + np.cross(omega_w, state.rotation_wb @ self.t_bc)
        return RelativeMotion(
            v_camera,
            omega_w,
            deck.position_w,
            deck.rotation_wp,
            deck.velocity_w,
            deck.angular_velocity_w,
        )

    def camera_image(self, frame: CameraFrame) -> np.ndarray:
        """A full camera render with ``frame``'s detections drawn (both camera modes)."""
        if self.camera.formation is not None:
            self.camera.motion = self.camera_motion()
        self._drone_visible(False)
        try:
            return self.camera.annotated_image(frame, *self.camera_pose_w())
        finally:
            self._drone_visible(True)

    def render_camera_image(self) -> np.ndarray:
        """A full camera render (HxWx3 RGB, lens distortion applied), drone hidden, no overlay.

        For calibration rigs, which segment the raw image themselves (both camera modes).
        """
        if self.camera.formation is not None:
            self.camera.motion = self.camera_motion()
        self._drone_visible(False)
        try:
            return self.camera.render_image(*self.camera_pose_w())
        finally:
            self._drone_visible(True)

    def capture(self) -> CameraFrame:
        t_wc, r_wc = self.camera_pose_w()
        deck = self.deck_state()
        if self.camera.formation is not None:
            self.camera.motion = self.camera_motion()
        if self.config.camera.mode == "render":
            self._drone_visible(False)
            try:
                return self._capture(t_wc, r_wc, deck)
            finally:
                self._drone_visible(True)
        return self._capture(t_wc, r_wc, deck)

    def _capture(self, t_wc: np.ndarray, r_wc: np.ndarray, deck: DeckState) -> CameraFrame:
        # every landmark of the deck (one centred tag by default), placed from the deck frame D
        t_wd = deck.tag_centre_w
        tags = [
            TagPlacement(lm.tag_id, lm.size, *landmark_pose_w(t_wd, deck.rotation_wd, lm))
            for lm in self._landmarks
        ]
        return self.camera.capture_tags(self.time, t_wc, r_wc, tags)

    def measure_ranges(self) -> RangeReading:
        state = self.drone_state()
        return self.tof.measure(self.time, state.position_w, state.rotation_wb, self.drone.body_id)

    def measure_range_down(self) -> RangeReading:
        """The downward rangefinder's reading now (also kept as ``last_range_down``)."""
        state = self.drone_state()
        self.last_range_down = self.rangefinder.measure(
            self.time, state.position_w, state.rotation_wb, self.drone.body_id
        )
        return self.last_range_down

    def close(self) -> None:
        try:
            self.client.disconnect()
        except p.error:
            pass
