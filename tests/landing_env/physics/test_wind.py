"""Wind at sea: Dryden gusts by MIL-F-8785C, the deck's airwake, wind scaled with sea state."""

from __future__ import annotations

import math

import numpy as np
import pytest

from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.physics.wind import WindConfig, WindModel


def test_dryden_scales_follow_mil_f_8785c_low_altitude() -> None:
    config = WindConfig(enabled=True, mean_velocity_w=(6.0, 8.0, 0.0), turbulence="dryden")
    (su, sv, sw), (lu, lv, lw) = config.dryden()
    h_ft = 10.0 / 0.3048
    assert sw == pytest.approx(0.1 * 10.0)
    assert su == sv == pytest.approx(sw / (0.177 + 0.000823 * h_ft) ** 0.4)
    assert lw == pytest.approx(10.0)
    assert lu == lv == pytest.approx(h_ft / (0.177 + 0.000823 * h_ft) ** 1.2 * 0.3048)
    assert 1.8 < su / sw < 2.0 and 60.0 < lu < 75.0


def test_dryden_gusts_have_the_model_variance_and_correlation_time() -> None:
    config = WindConfig(enabled=True, mean_velocity_w=(8.0, 0.0, 0.0), turbulence="dryden")
    model = WindModel(config, np.random.default_rng(0))
    dt = 0.05
    samples = np.array([model.velocity((k + 1) * dt, dt) for k in range(200_000)])
    gust = samples - np.array(config.mean_velocity_w)
    sigma, taus = config.gust_process()
    np.testing.assert_allclose(np.std(gust, axis=0), sigma, rtol=0.06)
    # the vertical gust's autocorrelation at one correlation time is 1/e
    w = gust[:, 2] - gust[:, 2].mean()
    lag = round(taus[2] / dt)
    rho = float(np.mean(w[:-lag] * w[lag:]) / np.var(w))
    assert rho == pytest.approx(math.exp(-1.0), abs=0.05)


def test_dryden_u_axis_follows_the_mean_wind() -> None:
    config = WindConfig(enabled=True, mean_velocity_w=(0.0, 10.0, 0.0), turbulence="dryden")
    model = WindModel(config, np.random.default_rng(1))
    dt = 0.05
    gust = np.array([model.velocity((k + 1) * dt, dt) for k in range(100_000)]) - [0, 10, 0]
    sigma_u, sigma_v, _ = config.gust_process()[0]
    # the wind blows along y: the longitudinal gust (sigma_u) is along y, the lateral along x
    assert np.std(gust[:, 1]) == pytest.approx(sigma_u, rel=0.1)
    assert np.std(gust[:, 0]) == pytest.approx(sigma_v, rel=0.1)


def test_the_airwake_adds_a_downdraft_and_turbulence_over_the_deck_only() -> None:
    config = WindConfig(
        enabled=True,
        mean_velocity_w=(10.0, 0.0, 0.0),
        turbulence="dryden",
        airwake_radius_m=3.0,
        airwake_height_m=5.0,
        airwake_downdraft_fraction=0.05,
        airwake_turbulence_factor=1.5,
    )
    model = WindModel(config, np.random.default_rng(2))
    wind = (11.0, 1.0, 0.2)
    over = model.airwake(wind, (0.5, 0.0, 2.0))
    assert over == pytest.approx((10.0 + 1.5, 1.5, 0.3 - 0.5))
    assert model.airwake(wind, (4.0, 0.0, 2.0)) == wind  # beside the deck
    assert model.airwake(wind, (0.0, 0.0, 6.0)) == wind  # above the wake


def test_ship_scenarios_blow_harder_with_the_sea_state() -> None:
    speeds = []
    for state in (3, 4, 5, 6):
        wind = load_config(f"ship-ss{state}").wind
        assert wind.enabled and wind.turbulence == "dryden"
        speeds.append(wind.mean_speed)
        # Pierson-Moskowitz: Hs = 0.21 U19.5^2 / g with U10 = U19.5 / 1.08
        hs = load_config(f"ship-ss{state}").motion.ship.hs
        assert wind.mean_speed == pytest.approx(math.sqrt(hs * 9.81 / 0.21) / 1.08, rel=0.01)
    assert np.all(np.diff(speeds) > 0)


def test_bad_wind_keys_are_named() -> None:
    with pytest.raises(ConfigError, match=r"wind\.turbulence"):
        load_config("ship-ss4", overrides={"wind.turbulence": "karman"})
    with pytest.raises(ConfigError, match=r"wind\.airwake_turbulence_factor"):
        load_config("ship-ss4", overrides={"wind.airwake_turbulence_factor": 0.5})


def _drift_in_steady_wind(
    trim: bool, speed_mps: float = 8.0, controller: dict | None = None
) -> tuple[float, float]:
    """The start's lean (deg) and how far the drone drifts in 1 s of hold (m) in a steady
    wind of ``speed_mps`` with no gusts (``controller``: overrides of its gains)."""
    from landing_env.physics.controller import VelocitySetpoint
    from landing_env.world import World

    overrides = {
        "wind.enabled": True,
        "wind.mean_velocity_w": [speed_mps, 0.0, 0.0],
        "wind.gust_intensity": [0.0, 0.0, 0.0],
        "start.trim_to_wind": trim,
        **{f"controller.{key}": value for key, value in (controller or {}).items()},
    }
    world = World(load_config("default", overrides=overrides))
    try:
        world.reset(np.random.default_rng(0), np.array([0.0, 0.0, 3.0]), 0.0)
        start = world.drone_state()
        lean = math.degrees(math.acos(float(start.rotation_wb[2, 2])))
        hold = VelocitySetpoint(np.zeros(3), 0.0)
        for _ in range(round(1.0 / (world.dt * world.substeps))):
            world.step(hold, monitor_contacts=False)
        end = world.drone_state().position_w
        return lean, float(np.linalg.norm(end[:2] - start.position_w[:2]))
    finally:
        world.close()


def test_a_start_in_trim_leans_into_the_wind_and_holds_its_place() -> None:
    lean, drift = _drift_in_steady_wind(trim=True)
    level_lean, level_drift = _drift_in_steady_wind(trim=False)
    # drag 0.25 N/(m/s) x 8 m/s against 0.8 kg x g: atan(2.0 / 7.85) = 14.3 deg
    assert lean == pytest.approx(math.degrees(math.atan(0.25 * 8.0 / (0.8 * 9.81))), abs=0.5)
    assert level_lean == pytest.approx(0.0, abs=1e-6)
    assert drift < 0.1 and level_drift > 3.0 * drift


def test_the_ship_configs_autopilot_limits_hold_station_in_sea_state_6s_wind() -> None:
    """Sea state 6's 14.2 m/s mean wind needs 4.4 m/s^2 against its drag: beyond the bench's
    3 m/s^2 velocity integrator, so a trimmed start drifts off; the ship configs' stock
    autopilot limits (10 m/s^2, 45 deg) hold it in place."""
    ship = load_config("ship-ss6").controller
    bench = load_config("default").controller
    assert ship.vel_i_limit_xy == 10.0
    assert ship.max_tilt == pytest.approx(math.radians(45.0), abs=1e-4)
    speed = float(np.linalg.norm(load_config("ship-ss6").wind.mean_velocity_w))
    limits = {"vel_i_limit_xy": ship.vel_i_limit_xy, "max_tilt": ship.max_tilt}
    _, drift_at_sea = _drift_in_steady_wind(True, speed, limits)
    _, drift_bench = _drift_in_steady_wind(True, speed)
    assert bench.vel_i_limit_xy == 3.0
    assert drift_at_sea < 0.1 and drift_bench > 2.0 * drift_at_sea


def test_trim_to_wind_must_be_a_boolean() -> None:
    with pytest.raises(ConfigError) as error:
        load_config("default", overrides={"start.trim_to_wind": "yes"})
    assert error.value.key == "start.trim_to_wind"


def test_a_trim_start_in_a_gale_stays_within_the_rotors_and_finite() -> None:
    from landing_env.world import World

    overrides = {
        "wind.enabled": True,
        "wind.mean_velocity_w": [60.0, -20.0, 0.0],
        "start.trim_to_wind": True,
    }
    world = World(load_config("default", overrides=overrides))
    try:
        world.reset(np.random.default_rng(1), np.array([0.0, 0.0, 3.0]), 0.3)
        state = world.drone_state()
        assert np.all(np.isfinite(state.rotation_wb)) and np.all(np.isfinite(state.position_w))
        assert np.all(np.asarray(world.drone._omega) <= world.params.omega_max + 1e-9)
        # it leans into the wind: its thrust axis points upwind
        assert state.rotation_wb[0, 2] < 0.0 and state.rotation_wb[1, 2] > 0.0
    finally:
        world.close()


def test_the_ship_ids_start_in_trim_with_the_autopilots_limits() -> None:
    from landing_env.scenarios import SCENARIO_IDS

    for n in (3, 4, 5, 6):
        for env_id in (f"DeckLandingTiming-ShipSS{n}-v8", f"DeckLanding-ShipSS{n}-v6"):
            scenario = SCENARIO_IDS[env_id]
            config = load_config(scenario.config, scenario.overrides)
            assert config.start.trim_to_wind is True, env_id
            assert config.controller.vel_i_limit_xy == 10.0, env_id
        # the ship configs themselves start in trim (what ``evaluate landing`` flies)
        assert load_config(f"ship-ss{n}").start.trim_to_wind is True


def test_random_decisions_on_ship_ss6_started_in_trim_never_leave_the_space() -> None:
    """The sea-state-6 timing task started in trim (realistic sensing, a gale's gusts): random
    waits and commits, every observation inside the space, every reward finite, every episode
    ended with an outcome; the start leans into the wind."""
    import gymnasium as gym

    import landing_env  # noqa: F401  (registers the environments)

    env = gym.make("DeckLandingTiming-ShipSS6-v8", overrides={"sensors": "realistic"})
    rng = np.random.default_rng(11)
    try:
        for episode in range(3):
            observation, _ = env.reset(seed=500 + episode)
            assert env.observation_space.contains(observation)
            done = False
            while not done:
                observation, reward, terminated, truncated, info = env.step(int(rng.random() < 0.1))
                assert env.observation_space.contains(observation)
                assert math.isfinite(reward)
                done = terminated or truncated
            assert info["outcome"] != "in_flight"
        world = env.unwrapped.world
        world.reset(np.random.default_rng(0), world.deck_home_w + np.array([0, 0, 2.5]), 0.0)
        mean = np.asarray(env.unwrapped.config.wind.mean_velocity_w)
        thrust_axis = world.drone_state().rotation_wb[:, 2]
        assert float(thrust_axis[:2] @ mean[:2]) < -0.3 * float(np.linalg.norm(mean[:2]))
    finally:
        env.close()


def _hold_after_airframe_change(drag: float, thrust: float, in_trim: bool) -> np.ndarray:
    """How far (m, world) a drone trimmed in a steady 8 m/s wind moves in the 1 s after its
    drag is scaled by ``drag`` and its thrust by ``thrust`` (``in_trim``: the air going past
    1/drag as fast, so that the force it holds stays, and its thrust model and rotor speeds
    the new rotors', as the onboard look-ahead's ``airframe_in_trim`` does)."""
    import dataclasses

    from landing_env.physics.controller import VelocitySetpoint
    from landing_env.world import World

    overrides = {
        "wind.enabled": True,
        "wind.mean_velocity_w": [8.0, 0.0, 0.0],
        "wind.gust_intensity": [0.0, 0.0, 0.0],
        "start.trim_to_wind": True,
    }
    world = World(load_config("default", overrides=overrides))
    try:
        world.reset(np.random.default_rng(0), np.array([0.0, 0.0, 3.0]), 0.0)
        hold = VelocitySetpoint(np.zeros(3), 0.0)
        world.step(hold, monitor_contacts=False)
        params = world.drone.params
        world.drone.params = dataclasses.replace(
            params, linear_drag_b=params.linear_drag_b * drag, k_f=params.k_f * thrust
        )
        if in_trim:
            air_w = world.drone_state().velocity_w - np.asarray(world.drone.last_wind_w)
            world.shift_wind_at_drone(air_w * (1.0 - 1.0 / drag))
            world.controller.scale_thrust_model(thrust)
            world.drone.set_rotor_speeds(world.drone.rotor_speeds / math.sqrt(thrust))
        start = world.drone_state().position_w
        for _ in range(round(1.0 / (world.dt * world.substeps))):
            world.step(hold, monitor_contacts=False)
        return world.drone_state().position_w - start
    finally:
        world.close()


def test_a_drawn_airframe_started_in_its_own_trim_holds_where_the_nominal_trim_drifts() -> None:
    unchanged = _hold_after_airframe_change(1.0, 1.0, in_trim=False)
    # 30 % more drag: blown downwind from the nominal trim, hardly from its own
    drift = np.linalg.norm(_hold_after_airframe_change(1.3, 1.0, True)[:2] - unchanged[:2])
    nominal_drift = np.linalg.norm(_hold_after_airframe_change(1.3, 1.0, False)[:2] - unchanged[:2])
    assert nominal_drift > 0.1 and drift < nominal_drift / 4
    # 5 % less thrust: the nominal trim sinks, the learnt thrust model does not
    sink = abs(_hold_after_airframe_change(1.0, 0.95, True)[2] - unchanged[2])
    nominal_sink = abs(_hold_after_airframe_change(1.0, 0.95, False)[2] - unchanged[2])
    assert nominal_sink > 0.04 and sink < 0.005
    from landing_env.physics.controller import CascadeController
    from landing_env.physics.quadrotor_params import QuadrotorParams

    with pytest.raises(ValueError, match="factor"):
        CascadeController(QuadrotorParams.from_yaml()).scale_thrust_model(0.0)


def test_shifting_the_wind_at_the_drone_inside_the_airwake_moves_what_the_drone_feels() -> None:
    from landing_env.physics.controller import VelocitySetpoint
    from landing_env.world import World

    config = load_config("ship-ss5")
    assert config.wind.airwake_turbulence_factor != 1.0
    felt = []
    for delta in (np.zeros(3), np.array([0.5, -0.3, 0.1])):
        world = World(config)
        try:
            # 2 m above the deck's home: inside the airwake, which scales a gust by its factor
            world.reset(np.random.default_rng(0), world.deck_home_w + np.array([0, 0, 2.0]), 0.0)
            hold = VelocitySetpoint(np.zeros(3), 0.0)
            world.step(hold, monitor_contacts=False)
            gust = world.wind.gust_w
            world.shift_wind_at_drone(delta)
            # the gust itself moves by the shift over the airwake's factor
            factor = config.wind.airwake_turbulence_factor
            np.testing.assert_allclose(world.wind.gust_w - gust, delta / factor, atol=1e-12)
            world.step(hold, monitor_contacts=False)
            felt.append(np.asarray(world.drone.last_wind_w))
            with pytest.raises(ValueError, match="delta_w"):
                world.shift_wind_at_drone(np.array([np.nan, 0.0, 0.0]))
        finally:
            world.close()
    # the same gusts after, but for the shift (a step of the gusts' decay aside)
    np.testing.assert_allclose(felt[1] - felt[0], [0.5, -0.3, 0.1], atol=0.01)
