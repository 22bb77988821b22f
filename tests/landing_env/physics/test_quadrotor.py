"""Tests of the quadrotor model: parameters, URDF, state, motors, forces, ground effect, wind."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
import yaml
from pybullet_utils.bullet_client import BulletClient
from scipy.spatial.transform import Rotation

from estimation.frames import R_BC, euler_zyx_from_matrix, tof_positions_in_camera_frame
from landing_env.errors import ConfigError
from landing_env.physics.drone_state import DroneState
from landing_env.physics.quadrotor import Quadrotor
from landing_env.physics.quadrotor_params import DEFAULT_PARAMS_PATH, GRAVITY, QuadrotorParams
from landing_env.physics.wind import WindConfig, WindModel

DT = 1.0 / 240.0


def make_world(gravity: float = -GRAVITY, ground: bool = True) -> BulletClient:
    """A DIRECT world at 240 Hz with a static plane at z = 0."""
    client = BulletClient(p.DIRECT)
    client.setGravity(0.0, 0.0, gravity)
    client.setTimeStep(DT)
    if ground:
        client.createMultiBody(0.0, client.createCollisionShape(p.GEOM_PLANE))
    return client


def add_box(client: BulletClient, center: tuple[float, float, float], half: tuple) -> int:
    """A static box."""
    shape = client.createCollisionShape(p.GEOM_BOX, halfExtents=half)
    return client.createMultiBody(0.0, shape, basePosition=center)


@pytest.fixture(scope="module")
def params() -> QuadrotorParams:
    return QuadrotorParams.from_yaml()


# ---------------------------------------------------------------- parameters


def test_shipped_params_describe_the_intended_vehicle(params: QuadrotorParams) -> None:
    assert 0.6 <= params.mass <= 1.0
    assert 2.0 <= params.thrust_to_weight <= 2.5
    assert 0.12 <= params.arm_length <= 0.13
    # Arms at 45 deg to the body axes.
    angles = np.degrees(np.arctan2(params.rotor_positions_b[:, 1], params.rotor_positions_b[:, 0]))
    np.testing.assert_allclose(np.sort(np.abs(angles)), [45.0, 45.0, 135.0, 135.0], atol=1e-3)
    # Each rotor sits above the ToF sensor of the same index (sensors in the camera plane).
    tof_b = tof_positions_in_camera_frame() @ R_BC.T + params.camera_offset_b
    np.testing.assert_allclose(tof_b[:, 2], params.tof_mount_z)
    for rotor, tof in zip(params.rotor_positions_b, tof_b, strict=True):
        direction_rotor = rotor[:2] / np.linalg.norm(rotor[:2])
        direction_tof = tof[:2] / np.linalg.norm(tof[:2])
        np.testing.assert_allclose(direction_rotor, direction_tof, atol=1e-6)
    # Hover: four rotors carry the weight at hover_omega.
    assert 4 * params.k_f * params.hover_omega**2 == pytest.approx(params.mass * GRAVITY)
    assert params.omega_min < params.hover_omega < params.omega_max


def test_invalid_field_raises_config_error_naming_it(params: QuadrotorParams) -> None:
    with pytest.raises(ConfigError) as info:
        dataclasses.replace(params, k_f=-1.0)
    assert info.value.key == "k_f"
    with pytest.raises(ConfigError) as info:
        dataclasses.replace(params, spin_directions=np.array([1.0, 1.0, -1.0, 1.0]))
    assert info.value.key == "spin_directions"
    with pytest.raises(ConfigError) as info:
        dataclasses.replace(params, ground_effect_model="magic")
    assert info.value.key == "ground_effect_model"
    assert "cheeseman_bennett" in str(info.value)


def _write_variant(tmp_path: Path, edit) -> Path:
    data = yaml.safe_load(DEFAULT_PARAMS_PATH.read_text())
    edit(data)
    data["urdf"] = str(DEFAULT_PARAMS_PATH.parent / data["urdf"])
    path = tmp_path / "variant.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_yaml_errors_name_the_yaml_key(tmp_path: Path) -> None:
    def weak_motors(data: dict) -> None:
        data["motors"]["omega_max"] = 1000.0  # thrust-to-weight below 1

    with pytest.raises(ConfigError) as info:
        QuadrotorParams.from_yaml(_write_variant(tmp_path, weak_motors))
    assert info.value.key == "motors.omega_max"
    assert "thrust-to-weight" in info.value.detail

    def unknown_key(data: dict) -> None:
        data["drag"]["quadratic"] = 0.1

    with pytest.raises(ConfigError) as info:
        QuadrotorParams.from_yaml(_write_variant(tmp_path, unknown_key))
    assert info.value.key == "drag.quadratic"

    def missing_key(data: dict) -> None:
        del data["motors"]["k_m"]

    with pytest.raises(ConfigError) as info:
        QuadrotorParams.from_yaml(_write_variant(tmp_path, missing_key))
    assert info.value.key == "motors.k_m"


# ---------------------------------------------------------------- URDF


def test_urdf_mass_and_inertia_match_the_yaml(params: QuadrotorParams) -> None:
    client = make_world(ground=False)
    drone = Quadrotor(client, params, position_w=(0.0, 0.0, 2.0))
    masses = []
    centres = []
    inertias = []
    for link in (-1, *drone.foot_link_indices):
        info = client.getDynamicsInfo(drone.body_id, link)
        masses.append(info[0])
        inertias.append(np.diag(info[2]))
        if link == -1:
            centres.append(np.array(client.getBasePositionAndOrientation(drone.body_id)[0]))
        else:
            centres.append(np.array(client.getLinkState(drone.body_id, link)[0]))
    masses_arr = np.array(masses)
    centres_arr = np.array(centres)
    assert masses_arr.sum() == pytest.approx(params.mass, rel=1e-9)
    com = masses_arr @ centres_arr / masses_arr.sum()
    # Body origin within a millimetre of the combined centre of mass.
    assert np.linalg.norm(com - centres_arr[0]) < 1e-3
    total = np.zeros((3, 3))
    for m, c, inertia in zip(masses_arr, centres_arr, inertias, strict=True):
        d = c - com
        total += inertia + m * (d @ d * np.eye(3) - np.outer(d, d))
    np.testing.assert_allclose(np.diag(total), params.inertia_diag, rtol=1e-3)


def test_feet_are_the_lowest_points_and_clear_of_sensors(params: QuadrotorParams) -> None:
    client = make_world(ground=False)
    drone = Quadrotor(client, params, position_w=(0.0, 0.0, 2.0))
    assert len(drone.foot_link_indices) == 4
    base_low = client.getAABB(drone.body_id, -1)[0][2]
    foot_lows = [client.getAABB(drone.body_id, link)[0][2] for link in drone.foot_link_indices]
    assert max(foot_lows) < base_low
    drop = 2.0 - np.array(foot_lows)
    assert np.all((drop >= 0.06) & (drop <= 0.09))
    # Nothing of the drone in the camera's view (rays to the image corners and centre, well
    # wider than the 38 deg half-diagonal field of view) nor in the ToF beams.
    camera_w = np.array([0.0, 0.0, 2.0]) + params.camera_offset_b
    tof_w = tof_positions_in_camera_frame() @ R_BC.T + params.camera_offset_b + [0.0, 0.0, 2.0]
    starts = [camera_w] * 9 + list(tof_w)
    spread = math.tan(math.radians(45.0))
    offsets = [(sx, sy) for sx in (-1, 0, 1) for sy in (-1, 0, 1)]
    directions = [np.array([sx * spread, sy * spread, -1.0]) for sx, sy in offsets]
    ends = [s + 0.5 * d for s, d in zip(starts[:9], directions, strict=True)]
    ends += [t + np.array([0.0, 0.0, -0.5]) for t in tof_w]
    hits = client.rayTestBatch([list(s) for s in starts], [list(e) for e in ends])
    assert all(hit[0] == -1 for hit in hits)


def test_resting_drone_touches_the_ground_only_with_its_feet(params: QuadrotorParams) -> None:
    client = make_world()
    drone = Quadrotor(client, params, position_w=(0.0, 0.0, 0.3))
    drone.armed = False
    for _ in range(480):
        drone.apply_rotor_commands(np.zeros(4), DT)
        client.stepSimulation()
    contacts = client.getContactPoints(bodyA=drone.body_id)
    assert {c[3] for c in contacts} == set(drone.foot_link_indices)
    state = drone.read_state()
    assert state.position_w[2] == pytest.approx(0.08, abs=2e-3)
    assert not drone.last_saturated  # disarmed: zero rotor speed is no saturation
    np.testing.assert_allclose(drone.rotor_speeds, 0.0, atol=1e-6)


# ---------------------------------------------------------------- state


def test_read_state_reports_frames_as_documented(params: QuadrotorParams) -> None:
    client = make_world(gravity=0.0, ground=False)
    drone = Quadrotor(client, params)
    rotation = Rotation.from_euler("ZYX", [0.7, -0.2, 0.3])
    omega_w = np.array([0.3, -1.1, 2.0])
    client.resetBasePositionAndOrientation(drone.body_id, [1.0, 2.0, 3.0], rotation.as_quat())
    client.resetBaseVelocity(drone.body_id, [0.5, -0.4, 0.2], omega_w.tolist())
    state = drone.read_state()
    np.testing.assert_allclose(state.position_w, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(state.velocity_w, [0.5, -0.4, 0.2])
    np.testing.assert_allclose(state.rotation_wb, rotation.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(
        Rotation.from_quat(state.quaternion_xyzw).as_matrix(), rotation.as_matrix(), atol=1e-12
    )
    np.testing.assert_allclose(state.angular_velocity_b, rotation.as_matrix().T @ omega_w)
    np.testing.assert_allclose(state.euler, euler_zyx_from_matrix(rotation.as_matrix()))
    np.testing.assert_allclose(state.euler, [0.3, -0.2, 0.7], atol=1e-12)
    assert state.yaw == pytest.approx(0.7)


def test_state_floats_and_arrays_agree(params: QuadrotorParams) -> None:
    client = make_world(gravity=0.0, ground=False)
    drone = Quadrotor(client, params)
    rotation = Rotation.from_euler("ZYX", [-2.5, 0.4, -0.1])
    client.resetBasePositionAndOrientation(drone.body_id, [1.0, 2.0, 3.0], rotation.as_quat())
    client.resetBaseVelocity(drone.body_id, [0.5, -0.4, 0.2], [0.3, -1.1, 2.0])
    state = drone.read_state()
    floats = state.floats
    np.testing.assert_array_equal(state.position_w, floats.position_w)
    np.testing.assert_array_equal(state.quaternion_xyzw, floats.quaternion_xyzw)
    np.testing.assert_array_equal(state.rotation_wb.ravel(), floats.rotation_wb)
    np.testing.assert_array_equal(state.velocity_w, floats.velocity_w)
    np.testing.assert_array_equal(state.angular_velocity_b, floats.angular_velocity_b)
    np.testing.assert_allclose(state.euler, [-0.1, 0.4, -2.5], atol=1e-12)
    assert state.euler_tuple == tuple(state.euler.tolist())
    assert state.yaw == pytest.approx(-2.5)
    assert state.rotation_wb is state.rotation_wb  # built once
    # A state built from arrays: its euler is the given one, else derived from the rotation.
    given = DroneState(
        state.position_w,
        state.quaternion_xyzw,
        state.rotation_wb,
        state.velocity_w,
        state.angular_velocity_b,
        euler=np.array([0.0, 0.0, 1.0]),
    )
    assert given.yaw == 1.0 and given.floats == floats
    derived = DroneState(
        state.position_w,
        state.quaternion_xyzw,
        state.rotation_wb,
        state.velocity_w,
        state.angular_velocity_b,
    )
    np.testing.assert_array_equal(derived.euler, state.euler)


def test_reset_places_level_drone_with_yaw_and_velocity(params: QuadrotorParams) -> None:
    client = make_world(ground=False)
    drone = Quadrotor(client, params)
    drone.reset((0.5, -0.5, 1.5), yaw=-2.0, velocity_w=(1.0, 0.0, -0.5))
    state = drone.read_state()
    np.testing.assert_allclose(state.position_w, [0.5, -0.5, 1.5])
    np.testing.assert_allclose(state.euler, [0.0, 0.0, -2.0], atol=1e-12)
    np.testing.assert_allclose(state.velocity_w, [1.0, 0.0, -0.5])
    np.testing.assert_allclose(drone.rotor_speeds, params.hover_omega)


# ---------------------------------------------------------------- motors and forces


def test_motor_lag_clamp_and_saturation_flag(params: QuadrotorParams) -> None:
    client = make_world(ground=False)
    drone = Quadrotor(client, params, position_w=(0.0, 0.0, 5.0))
    start = params.hover_omega
    drone.apply_rotor_commands(np.full(4, params.hover_omega * 1.1), DT)
    assert not drone.last_saturated
    drone.set_rotor_speeds(np.full(4, start))
    steps = round(params.motor_time_constant / DT)
    for _ in range(steps):
        drone.apply_rotor_commands(np.full(4, 3.0 * params.omega_max), DT)
        assert drone.last_saturated
        assert np.all(drone.rotor_speeds <= params.omega_max)
    # First-order lag towards the clamped command.
    expected = params.omega_max + (start - params.omega_max) * math.exp(-steps * DT / 0.025)
    np.testing.assert_allclose(drone.rotor_speeds, expected, rtol=1e-9)
    drone.apply_rotor_commands(np.array([0.0, start, start, start]), DT)
    assert drone.last_saturated
    drone.apply_rotor_commands(np.array([np.nan, start, start, start]), DT)
    assert drone.last_saturated


def _angular_acceleration(drone: Quadrotor, client: BulletClient, omega: np.ndarray) -> np.ndarray:
    """Body angular acceleration over one step with the rotors held at ``omega``."""
    drone.set_rotor_speeds(omega)
    before = drone.read_state().angular_velocity_b
    drone.apply_rotor_commands(omega, DT)
    client.stepSimulation()
    return (drone.read_state().angular_velocity_b - before) / DT


def test_rotor_thrust_and_torques(params: QuadrotorParams) -> None:
    client = make_world(gravity=0.0, ground=False)
    drone = Quadrotor(client, params, position_w=(0.0, 0.0, 5.0))
    zero_drag = dataclasses.replace(params, linear_drag_b=np.zeros(3))
    drone.params = zero_drag
    omega = np.full(4, 1500.0)
    drone.set_rotor_speeds(omega)
    drone.apply_rotor_commands(omega, DT)
    client.stepSimulation()
    state = drone.read_state()
    expected_az = 4 * params.k_f * 1500.0**2 / params.mass
    assert state.velocity_w[2] / DT == pytest.approx(expected_az, rel=1e-3)

    # Rotor order: front-left, front-right, back-right, back-left.
    w0, dw = 1500.0, 100.0
    jx, jy, jz = params.inertia_diag
    arm = params.rotor_positions_b[0, 1]
    dthrust = params.k_f * ((w0 + dw) ** 2 - w0**2)
    left_up = _angular_acceleration(drone, client, np.array([w0 + dw, w0, w0, w0 + dw]))
    assert left_up[0] == pytest.approx(2 * arm * dthrust / jx, rel=0.02)  # roll right-side down
    client.resetBaseVelocity(drone.body_id, [0, 0, 0], [0, 0, 0])
    front_up = _angular_acceleration(drone, client, np.array([w0 + dw, w0 + dw, w0, w0]))
    assert front_up[1] == pytest.approx(-2 * arm * dthrust / jy, rel=0.02)  # nose up: -pitch
    client.resetBaseVelocity(drone.body_id, [0, 0, 0], [0, 0, 0])
    # Faster counter-clockwise rotors (spin +1) twist the body clockwise (negative yaw).
    ccw = params.spin_directions > 0
    yaw_cmd = np.where(ccw, w0 + dw, w0)
    yaw_acc = _angular_acceleration(drone, client, yaw_cmd)
    expected = -2 * params.k_m * ((w0 + dw) ** 2 - w0**2) / jz
    assert yaw_acc[2] == pytest.approx(expected, rel=0.02)
    assert abs(yaw_acc[0]) < 1e-6 and abs(yaw_acc[1]) < 1e-6


def test_linear_drag_acts_in_the_body_frame(params: QuadrotorParams) -> None:
    client = make_world(gravity=0.0, ground=False)
    drag = np.array([0.1, 0.4, 0.3])
    prm = dataclasses.replace(params, linear_drag_b=drag, drag_airframe_fraction=1.0)
    drone = Quadrotor(client, prm)
    # Yawed 90 deg: world x is body -y, so world-x motion feels the body-y coefficient.
    drone.reset((0.0, 0.0, 5.0), yaw=math.pi / 2, velocity_w=(1.0, 0.0, 0.0))
    drone.armed = False
    drone.set_rotor_speeds(np.zeros(4))
    for _ in range(120):
        drone.apply_rotor_commands(np.zeros(4), DT)
        client.stepSimulation()
    state = drone.read_state()
    assert state.velocity_w[0] == pytest.approx(math.exp(-drag[1] / prm.mass * 0.5), rel=2e-3)
    assert abs(state.velocity_w[1]) < 1e-9


# ---------------------------------------------------------------- ground effect


def _hover_thrust_at(drone: Quadrotor, client: BulletClient, position) -> float:
    drone.reset(position, yaw=0.0)
    drone.apply_rotor_commands(np.full(4, drone.params.hover_omega), DT)
    return sum(drone.last_thrusts)


def _over_the_ground(params: QuadrotorParams) -> tuple[BulletClient, Quadrotor, float, float]:
    """A drone over the ground plane, its hubs' height in the body, its thrust out of reach."""
    client = make_world()
    drone = Quadrotor(client, params)
    return client, drone, params.rotor_positions_b[0, 2], _hover_thrust_at(drone, client, (0, 0, 2))


def _cheeseman_bennett(params: QuadrotorParams, h: float) -> float:
    return 1.0 / (1.0 - (params.rotor_radius / (4.0 * h)) ** 2)


def _four_rotor_model(params: QuadrotorParams, h: float) -> float:
    """Sanchez-Cuevas, Heredia & Ollero (2017), Eq. 8, written out from the paper."""
    r = params.rotor_radius
    d = math.dist(params.rotor_positions_b[0, :2], params.rotor_positions_b[1, :2])  # adjacent
    b = params.arm_length
    k_b = params.ground_effect_body_coefficient
    return 1.0 / (
        1.0
        - (r / (4.0 * h)) ** 2
        - r**2 * h / math.sqrt((d**2 + 4 * h**2) ** 3)
        - (r**2 / 2) * h / math.sqrt((2 * d**2 + 4 * h**2) ** 3)
        - 2 * r**2 * h * k_b / math.sqrt((b**2 + 4 * h**2) ** 3)
    )


def test_ground_effect_thrust_at_a_tenth_of_a_metre_matches_the_four_rotor_model(
    params: QuadrotorParams,
) -> None:
    client, drone, hub_z, far = _over_the_ground(params)
    near = _hover_thrust_at(drone, client, (0.0, 0.0, 0.1 - hub_z))  # hubs 0.10 m up
    np.testing.assert_allclose(drone.last_ground_heights, 0.1, atol=1e-4)
    assert near / far == pytest.approx(_four_rotor_model(params, 0.1), rel=1e-4)
    # +21 % for this frame at 0.10 m, +11 % at 0.15 m (Cheeseman-Bennett alone: +2.6 %)
    assert near / far == pytest.approx(1.213, abs=0.005)
    high = _hover_thrust_at(drone, client, (0.0, 0.0, 0.15 - hub_z))
    assert high / far == pytest.approx(1.112, abs=0.005)
    single = dataclasses.replace(params, ground_effect_model="cheeseman_bennett")
    drone.params = single
    assert _hover_thrust_at(drone, client, (0.0, 0.0, 0.1 - hub_z)) / far == pytest.approx(
        _cheeseman_bennett(params, 0.1), rel=1e-4
    )


def test_the_ground_effect_gains_of_given_hub_heights_are_the_ones_the_drone_flies_with(
    params: QuadrotorParams,
) -> None:
    client, drone, hub_z, far = _over_the_ground(params)
    heights = np.array([0.08, 0.1, 0.15, 0.3])
    gains = drone.ground_effect_gains(heights)
    for height, gain in zip(heights, gains, strict=True):
        near = _hover_thrust_at(drone, client, (0.0, 0.0, height - hub_z))
        assert gain == pytest.approx(near / far, rel=1e-9)
    # beyond the ray's reach, with no surface, or with the effect off: no gain
    reach = params.ground_effect_ray_length
    assert np.all(drone.ground_effect_gains(np.array([reach + 0.01, np.nan])) == 1.0)
    assert drone.ground_effect_gains(np.array([0.001]))[0] == params.ground_effect_max_gain
    drone.params = dataclasses.replace(params, ground_effect_enabled=False)
    _hover_thrust_at(drone, client, (0.0, 0.0, 2.0))
    assert np.all(drone.ground_effect_gains(heights) == 1.0)


def test_ground_effect_raises_thrust_over_a_raised_box(params: QuadrotorParams) -> None:
    client = make_world()
    add_box(client, (0.0, 0.0, 0.5), (0.5, 0.5, 0.5))  # top at z = 1 m
    drone = Quadrotor(client, params)
    hub_z = params.rotor_positions_b[0, 2]
    near = _hover_thrust_at(drone, client, (0.0, 0.0, 1.0 + 0.08 + 0.05))  # feet 5 cm above
    heights_near = np.array(drone.last_ground_heights)
    far = _hover_thrust_at(drone, client, (0.0, 0.0, 2.0))  # 1 m above the box
    out_of_ground_effect = 4 * params.k_f * params.hover_omega**2
    assert far == pytest.approx(out_of_ground_effect, rel=1e-12)
    assert np.all(np.isnan(drone.last_ground_heights))
    np.testing.assert_allclose(heights_near, 0.13 + hub_z, atol=1e-4)
    assert near == pytest.approx(far * _four_rotor_model(params, 0.13 + hub_z), rel=1e-4)
    assert near > 1.01 * far


def test_ground_effect_uses_the_surface_under_each_rotor(params: QuadrotorParams) -> None:
    client = make_world()
    box = add_box(client, (0.0, 0.0, 0.5), (0.5, 0.5, 0.5))
    drone = Quadrotor(client, params)
    hub_z = params.rotor_positions_b[0, 2]
    # 0.1 m above the box top, far above z = 0: the gain follows the box.
    _hover_thrust_at(drone, client, (0.0, 0.0, 1.1))
    np.testing.assert_allclose(drone.last_ground_heights, 0.1 + hub_z, atol=1e-4)
    gains = np.array(drone.last_ground_effect_gains)
    np.testing.assert_allclose(gains, _four_rotor_model(params, 0.1 + hub_z), rtol=1e-4)
    # Straddling the box's edge at x = 0.5: the front rotors see the floor 1.1 m down (beyond
    # the ray), the back rotors the box.
    _hover_thrust_at(drone, client, (0.5, 0.0, 1.1))
    front = [0, 1]
    back = [2, 3]
    assert np.all(np.isnan(np.array(drone.last_ground_heights)[front]))
    np.testing.assert_allclose(np.array(drone.last_ground_heights)[back], 0.1 + hub_z, atol=1e-4)
    thrusts = np.array(drone.last_thrusts)
    assert np.all(thrusts[back] > thrusts[front] * 1.01)
    # The deck moves: the heights follow it, at any height.
    for top in (0.3, 2.7):
        client.resetBasePositionAndOrientation(box, (0.0, 0.0, top - 0.5), (0, 0, 0, 1))
        _hover_thrust_at(drone, client, (0.0, 0.0, top + 0.15))
        np.testing.assert_allclose(drone.last_ground_heights, 0.15 + hub_z, atol=1e-4)


def test_ground_effect_rays_follow_the_body_axis(params: QuadrotorParams) -> None:
    client = make_world()
    drone = Quadrotor(client, params)
    roll = math.radians(20.0)
    quat = Rotation.from_euler("x", roll).as_quat()
    client.resetBasePositionAndOrientation(drone.body_id, (0.0, 0.0, 0.3), quat)
    state = drone.read_state()
    drone.apply_rotor_commands(np.full(4, params.hover_omega), DT, state)
    hubs_w = state.position_w + params.rotor_positions_b @ state.rotation_wb.T
    expected = hubs_w[:, 2] / math.cos(roll)  # slant distance down body -z to z = 0
    np.testing.assert_allclose(drone.last_ground_heights, expected, atol=1e-4)


def test_ground_effect_cap_is_flagged(params: QuadrotorParams) -> None:
    client = make_world()
    drone = Quadrotor(client, params)
    drone.reset((0.0, 0.0, 1.0), yaw=0.0)
    hub = params.rotor_positions_b[0] + [0.0, 0.0, 1.0]
    # A thin post right under the front-left hub, its top 2 cm below it: the model's gain there
    # (2.7) is above the 1.5 cap.
    add_box(client, (hub[0], hub[1], (hub[2] - 0.02) / 2), (0.005, 0.005, (hub[2] - 0.02) / 2))
    drone.apply_rotor_commands(np.full(4, params.hover_omega), DT)
    assert drone.last_ground_heights[0] == pytest.approx(0.02, abs=1e-4)
    assert drone.last_ground_effect_capped
    assert drone.last_ground_effect_gains[0] == params.ground_effect_max_gain
    assert drone.last_ground_effect_gains[1:] == (1.0, 1.0, 1.0)


def test_a_drone_out_of_reach_of_every_surface_casts_no_ray_and_gets_the_same_thrust(
    params: QuadrotorParams, monkeypatch: pytest.MonkeyPatch
) -> None:
    client = make_world()
    add_box(client, (0.0, 0.0, 0.5), (0.5, 0.5, 0.5))  # top at z = 1 m
    drone = Quadrotor(client, params)
    cast = []
    ray_test_batch = p.rayTestBatch
    monkeypatch.setattr(
        p, "rayTestBatch", lambda *a, **k: cast.append(1) or ray_test_batch(*a, **k)
    )
    hub_z = params.rotor_positions_b[0, 2]
    for z in (1.0 + 0.1 - hub_z, 1.3, 1.7, 2.5):  # in reach of the box's top, then not
        drone.surfaces_below_z = math.inf  # always cast
        cast.clear()
        thrust = _hover_thrust_at(drone, client, (0.0, 0.0, z))
        heights, gains = drone.last_ground_heights, drone.last_ground_effect_gains
        assert cast
        drone.surfaces_below_z = 1.0
        cast.clear()
        assert _hover_thrust_at(drone, client, (0.0, 0.0, z)) == thrust
        np.testing.assert_array_equal(drone.last_ground_heights, heights)
        assert drone.last_ground_effect_gains == gains
        assert bool(cast) == (z - drone._ge_reach <= 1.0)
    assert drone._ge_reach == pytest.approx(
        params.ground_effect_ray_length + math.hypot(*params.rotor_positions_b[0])
    )


# ---------------------------------------------------------------- wind


def test_wind_config_validates() -> None:
    with pytest.raises(ConfigError) as info:
        WindConfig(gust_time_constant=0.0)
    assert info.value.key == "gust_time_constant"
    with pytest.raises(ConfigError) as info:
        WindConfig(gust_intensity=(1.0, -1.0, 0.0))
    assert info.value.key == "gust_intensity"
    with pytest.raises(ConfigError) as info:
        WindConfig(mean_velocity_w=(1.0, 2.0))
    assert info.value.key == "mean_velocity_w"


def test_wind_gusts_have_the_configured_statistics() -> None:
    config = WindConfig(
        enabled=True, mean_velocity_w=(2.0, -1.0, 0.0), gust_intensity=(1.0, 0.5, 0.2)
    )
    model = WindModel(config, np.random.default_rng(7))
    samples = np.array([model.velocity(k * DT, DT) for k in range(1, 240 * 600)])
    np.testing.assert_allclose(samples.mean(axis=0), [2.0, -1.0, 0.0], atol=0.15)
    np.testing.assert_allclose(samples.std(axis=0), [1.0, 0.5, 0.2], rtol=0.12)
    # Correlation over one time constant is exp(-1).
    lag = round(config.gust_time_constant / DT)
    x = samples[:, 0] - samples[:, 0].mean()
    correlation = (x[:-lag] @ x[lag:]) / (x @ x)
    assert correlation == pytest.approx(math.exp(-1.0), abs=0.08)
    # Asking twice at one instant does not advance the process.
    np.testing.assert_array_equal(model.velocity(1e6, DT), model.velocity(1e6, DT))
    assert np.all(WindModel(WindConfig(), np.random.default_rng(0)).velocity(1.0, DT) == 0.0)


def _drift(params: QuadrotorParams, wind: WindModel | None, seconds: float) -> np.ndarray:
    """Positions of a drone with its rotors held at hover speed (no controller)."""
    client = make_world()
    drone = Quadrotor(client, params, wind=wind, position_w=(0.0, 0.0, 20.0))
    positions = []
    for _ in range(round(seconds / DT)):
        drone.apply_rotor_commands(np.full(4, params.hover_omega), DT)
        client.stepSimulation()
        positions.append(drone.read_state().position_w)
    return np.array(positions)


def test_wind_pushes_an_uncontrolled_drone_downwind(params: QuadrotorParams) -> None:
    calm = _drift(params, None, 3.0)
    assert np.abs(calm[-1] - [0.0, 0.0, 20.0]).max() < 1e-6
    config = WindConfig(enabled=True, mean_velocity_w=(3.0, 0.0, 0.0), gust_intensity=(0, 0, 0))
    windy = _drift(params, WindModel(config, np.random.default_rng(0)), 3.0)
    # Drag accelerates it towards the wind speed: v(t) = 3 (1 - exp(-k t / m)).
    k_over_m = params.linear_drag_b[0] / params.mass
    expected_x = 3.0 * (3.0 - (1.0 - math.exp(-k_over_m * 3.0)) / k_over_m)
    assert windy[-1, 0] == pytest.approx(expected_x, rel=0.02)
    assert abs(windy[-1, 1]) < 1e-6


def test_identically_seeded_gusts_give_identical_trajectories(params: QuadrotorParams) -> None:
    config = WindConfig(enabled=True, mean_velocity_w=(1.0, 0.5, 0.0), gust_intensity=(1, 1, 0.3))
    first = _drift(params, WindModel(config, np.random.default_rng(42)), 2.0)
    second = _drift(params, WindModel(config, np.random.default_rng(42)), 2.0)
    other = _drift(params, WindModel(config, np.random.default_rng(43)), 2.0)
    np.testing.assert_array_equal(first, second)
    assert np.abs(first - other).max() > 1e-3


def test_wind_can_be_set_from_outside(params: QuadrotorParams) -> None:
    config = WindConfig(enabled=True, mean_velocity_w=(3.0, -1.0, 0.0), gust_intensity=(0, 0, 0))
    modelled = _drift(params, WindModel(config, np.random.default_rng(0)), 1.0)
    client = make_world()
    drone = Quadrotor(client, params, position_w=(0.0, 0.0, 20.0))
    for _ in range(round(1.0 / DT)):
        drone.wind_velocity_w = np.array([3.0, -1.0, 0.0])
        drone.apply_rotor_commands(np.full(4, params.hover_omega), DT)
        client.stepSimulation()
    assert drone.last_wind_w == (3.0, -1.0, 0.0)
    np.testing.assert_allclose(drone.read_state().position_w, modelled[-1], atol=1e-12)


def _drag_decay(params: QuadrotorParams, omega: float) -> float:
    """World-x speed left after 0.5 s of drag alone (no gravity), the rotors held at
    ``omega``, from 1 m/s."""
    client = make_world(gravity=0.0, ground=False)
    drone = Quadrotor(client, params)
    drone.reset((0.0, 0.0, 5.0), 0.0, velocity_w=(1.0, 0.0, 0.0))
    drone.armed = omega > 0.0  # disarmed rotors stay stopped
    drone.set_rotor_speeds(np.full(4, omega))
    for _ in range(120):
        drone.apply_rotor_commands(np.full(4, omega), DT)
        client.stepSimulation()
    return float(drone.read_state().velocity_w[0])


def test_the_rotor_drag_fades_with_the_rotor_speed_and_the_airframe_s_does_not(
    params: QuadrotorParams,
) -> None:
    """At hover the whole identified drag acts; with the rotors stopped only the airframe's
    share (``drag.airframe_fraction``), so a drone whose motors are cut on a deck in wind is no
    longer pushed as hard as one flying."""
    fraction = params.drag_airframe_fraction
    assert 0.0 < fraction < 1.0
    d, m = params.linear_drag_b[0], params.mass
    assert _drag_decay(params, params.hover_omega) == pytest.approx(
        math.exp(-d / m * 0.5), rel=2e-3
    )
    stopped = _drag_decay(params, 0.0)
    assert stopped == pytest.approx(math.exp(-fraction * d / m * 0.5), rel=2e-3)
    half = _drag_decay(params, 0.5 * params.hover_omega)
    assert half == pytest.approx(
        math.exp(-(fraction + 0.5 * (1 - fraction)) * d / m * 0.5), rel=2e-3
    )


def test_a_bad_airframe_drag_fraction_is_refused_naming_its_yaml_key(tmp_path: Path) -> None:
    def above_one(data: dict) -> None:
        data["drag"]["airframe_fraction"] = 1.5

    with pytest.raises(ConfigError) as info:
        QuadrotorParams.from_yaml(_write_variant(tmp_path, above_one))
    assert info.value.key == "drag.airframe_fraction"
