"""Motion sources: static, sinusoids, JONSWAP sea state, CSV replay; their configs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from landing_env.errors import ConfigError
from landing_env.stewart.kinematics import StewartGeometry, StewartKinematics
from landing_env.stewart.motion import (
    BatchMotionSource,
    MotionConfig,
    MotionSource,
    SeaStateConfig,
    SeaStateMotion,
    SinusoidConfig,
    SinusoidMotion,
    StaticMotion,
    StaticMotionConfig,
    make_motion_source,
    sample_poses,
)
from landing_env.waves.recording import CsvMotion, CsvMotionConfig, CsvMotionError, write_motion_csv
from landing_env.waves.spectrum import SEA_STATE_TABLE


def rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


def assert_velocity_is_derivative(source: MotionSource, times: np.ndarray, tol: float) -> None:
    h = 1e-5
    for t in times:
        numeric = (source.pose(t + h) - source.pose(t - h)) / (2 * h)
        np.testing.assert_allclose(source.velocity(t), numeric, atol=tol, rtol=0)


# ------------------------------------------------------------------ static
def test_static_holds_its_pose_in_si_units() -> None:
    config = MotionConfig(
        kind="static",
        static=StaticMotionConfig(position_m=(0.01, -0.02, 0.03), attitude_deg=(2.0, -3.0, 5.0)),
    )
    source = make_motion_source(config, rng())
    assert isinstance(source, StaticMotion)
    expected = np.array([0.01, -0.02, 0.03, *np.deg2rad([2.0, -3.0, 5.0])])
    for t in (0.0, 1.5, 100.0):
        np.testing.assert_allclose(source.pose(t), expected)
        np.testing.assert_array_equal(source.velocity(t), np.zeros(6))


# ------------------------------------------------------------------ sinusoids
def test_sinusoids_are_deterministic_per_seed_and_differ_between_seeds() -> None:
    times = np.linspace(0.0, 30.0, 61)
    a = sample_poses(make_motion_source(MotionConfig(), rng(5)), times)
    b = sample_poses(make_motion_source(MotionConfig(), rng(5)), times)
    c = sample_poses(make_motion_source(MotionConfig(), rng(6)), times)
    np.testing.assert_array_equal(a, b)
    assert np.max(np.abs(a - c)) > 0.01


def test_given_phases_make_the_motion_seed_independent_and_exact() -> None:
    config = SinusoidConfig(
        amplitudes=((0.02,), (), (0.05,), (4.0,), (), (2.0,)),
        frequencies_hz=((0.1,), (), (0.2,), (0.15,), (), (0.05,)),
        phases_deg=((30.0,), (), (0.0,), (90.0,), (), (-45.0,)),
    )
    one = SinusoidMotion.from_config(config, rng(1))
    two = SinusoidMotion.from_config(config, rng(2))
    for t in (0.0, 0.7, 3.3):
        np.testing.assert_array_equal(one.pose(t), two.pose(t))
        expected = [
            0.02 * math.sin(2 * math.pi * 0.1 * t + math.radians(30)),
            0.0,
            0.05 * math.sin(2 * math.pi * 0.2 * t),
            math.radians(4.0) * math.sin(2 * math.pi * 0.15 * t + math.pi / 2),
            0.0,
            math.radians(2.0) * math.sin(2 * math.pi * 0.05 * t - math.pi / 4),
        ]
        np.testing.assert_allclose(one.pose(t), expected, atol=1e-15)


def test_sinusoid_amplitudes_match_the_config() -> None:
    """A least-squares fit at the configured frequencies recovers every amplitude."""
    config = SinusoidConfig()
    source = make_motion_source(MotionConfig(sinusoids=config), rng(11))
    times = np.arange(0.0, 600.0, 0.1)
    poses = sample_poses(source, times)
    for axis in range(6):
        freqs = np.asarray(config.frequencies_hz[axis])
        basis = np.hstack(
            [np.sin(2 * np.pi * np.outer(times, freqs)), np.cos(2 * np.pi * np.outer(times, freqs))]
        )
        coef, *_ = np.linalg.lstsq(basis, poses[:, axis], rcond=None)
        amplitude = np.hypot(coef[: len(freqs)], coef[len(freqs) :])
        expected = np.asarray(config.amplitudes[axis])
        if axis >= 3:
            expected = np.deg2rad(expected)
        np.testing.assert_allclose(amplitude, expected, rtol=1e-9)


def test_sinusoid_velocity_is_the_derivative() -> None:
    source = make_motion_source(MotionConfig(), rng(2))
    assert_velocity_is_derivative(source, np.linspace(0.0, 20.0, 9), 1e-8)


def test_default_sinusoids_stay_inside_the_default_workspace() -> None:
    kinematics = StewartKinematics(StewartGeometry())
    source = make_motion_source(MotionConfig(), rng(3))
    poses = sample_poses(source, np.arange(0.0, 600.0, 0.5))
    assert np.all(kinematics.is_reachable(poses))
    # centimetres and a few degrees
    assert 0.02 < np.max(np.abs(poses[:, :3])) < 0.1
    assert 3.0 < np.rad2deg(np.max(np.abs(poses[:, 3:]))) < 10.0


# ------------------------------------------------------------------ sea state
@pytest.mark.parametrize(("sea_state", "seed"), [(3, 0), (4, 1), (5, 2)])
def test_jonswap_significant_height(sea_state: int, seed: int) -> None:
    source = SeaStateMotion(SeaStateConfig(sea_state=sea_state), rng(seed))
    hs = SEA_STATE_TABLE[sea_state][0]
    assert math.isclose(source.significant_height, hs, rel_tol=1e-12)
    # three hours of the synthesised elevation at 2 Hz
    elevation = source.elevation(np.arange(0.0, 3 * 3600.0, 0.5))
    assert abs(4.0 * np.std(elevation) / hs - 1.0) < 0.03
    assert abs(np.mean(elevation)) < 0.02 * hs


def test_jonswap_explicit_height_and_period_override_the_table() -> None:
    config = SeaStateConfig(sea_state=2, significant_height_m=1.2, peak_period_s=6.0)
    source = SeaStateMotion(config, rng(4))
    elevation = source.elevation(np.arange(0.0, 3 * 3600.0, 0.5))
    assert abs(4.0 * np.std(elevation) / 1.2 - 1.0) < 0.03
    # the discrete spectrum peaks at the peak frequency
    width = np.gradient(source.frequencies_hz)
    density = source.amplitudes_m**2 / 2 / width
    peak = source.frequencies_hz[np.argmax(density)]
    assert abs(peak - 1.0 / 6.0) < 0.01


def test_sea_state_is_deterministic_per_seed_and_zero_when_calm() -> None:
    times = np.linspace(0.0, 60.0, 31)
    config = MotionConfig(kind="sea_state")
    a = sample_poses(make_motion_source(config, rng(7)), times)
    b = sample_poses(make_motion_source(config, rng(7)), times)
    c = sample_poses(make_motion_source(config, rng(8)), times)
    np.testing.assert_array_equal(a, b)
    assert np.max(np.abs(a - c)) > 0.005
    calm = make_motion_source(MotionConfig(kind="sea_state", sea_state=SeaStateConfig(0)), rng())
    np.testing.assert_array_equal(sample_poses(calm, times), np.zeros((31, 6)))


def test_sea_state_scale_and_velocity() -> None:
    base = SeaStateConfig(scale=(0.1, 0.1, 0.06, 0.7, 1.0, 3.5))
    double = SeaStateConfig(scale=(0.2, 0.2, 0.12, 1.4, 2.0, 7.0))
    one, two = SeaStateMotion(base, rng(9)), SeaStateMotion(double, rng(9))
    for t in (0.0, 12.5, 99.0):
        np.testing.assert_allclose(two.pose(t), 2.0 * one.pose(t), atol=1e-15)
    assert_velocity_is_derivative(one, np.linspace(0.0, 50.0, 7), 1e-7)


def test_sea_state_4_uses_most_of_the_workspace() -> None:
    kinematics = StewartKinematics(StewartGeometry())
    source = make_motion_source(MotionConfig(kind="sea_state"), rng(12))
    poses = sample_poses(source, np.arange(0.0, 1200.0, 0.5))
    reachable = kinematics.is_reachable(poses)
    usage = kinematics.stroke_usage(kinematics.inverse_kinematics(poses[reachable]))
    assert reachable.mean() > 0.95  # clamped only occasionally
    assert np.max(np.abs(2.0 * usage - 1.0)) > 0.8  # but near the stroke ends at times
    # every axis moves: heave in centimetres, roll and pitch in degrees
    assert np.std(poses[:, 2]) > 0.02
    assert np.rad2deg(np.std(poses[:, 3:5], axis=0)).min() > 2.0


# ------------------------------------------------------------------ csv
def write_csv(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_csv_replay_reproduces_its_samples(tmp_path: Path) -> None:
    times = np.linspace(0.0, 10.0, 41)
    truth = make_motion_source(MotionConfig(), rng(3))
    poses = sample_poses(truth, times)
    path = tmp_path / "motion.csv"
    write_motion_csv(path, times, poses)
    assert path.read_text().splitlines()[0] == "t,x,y,z,roll,pitch,yaw"
    # the file holds degrees
    first = [float(v) for v in path.read_text().splitlines()[1].split(",")]
    assert math.isclose(first[4], math.degrees(poses[0, 3]), rel_tol=1e-12)
    source = make_motion_source(MotionConfig(kind="csv", csv=CsvMotionConfig(str(path))), rng())
    assert isinstance(source, CsvMotion)
    np.testing.assert_allclose(sample_poses(source, times), poses, atol=1e-14)
    # between samples PCHIP follows the smooth motion closely
    between = times[:-1] + 0.125
    np.testing.assert_allclose(
        sample_poses(source, between), sample_poses(truth, between), atol=1e-3
    )
    assert_velocity_is_derivative(source, between, 1e-6)


def test_csv_end_hold_and_loop(tmp_path: Path) -> None:
    path = write_csv(
        tmp_path / "m.csv",
        "t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1,0.01,0,0,10,0,0\n2,0.02,0,0,20,0,0\n",
    )
    hold = CsvMotion.from_file(path, end="hold")
    loop = CsvMotion.from_file(path, end="loop")
    np.testing.assert_allclose(hold.pose(5.0), [0.02, 0, 0, math.radians(20), 0, 0])
    np.testing.assert_array_equal(hold.velocity(5.0), np.zeros(6))
    np.testing.assert_allclose(hold.pose(-1.0), np.zeros(6))
    np.testing.assert_allclose(loop.pose(5.0), loop.pose(1.0), atol=1e-15)
    np.testing.assert_allclose(loop.pose(2.5), loop.pose(0.5), atol=1e-15)
    assert loop.velocity(5.0)[0] > 0.0


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("time,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0\n", "expected 't,x,y,z"),
        ("", "empty"),
        ("t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0\n1,0,0,0,0,0,0\n", "line 4"),
        ("t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n2,0,0,0,0,0,0\n1,0,0,0,0,0,0\n", "increase"),
        ("t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1,0,0,zero,0,0,0\n", "line 3: not a number"),
        ("t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0\n", "expected 7 columns"),
        ("t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n", "at least two"),
    ],
)
def test_csv_errors_are_clear(tmp_path: Path, text: str, match: str) -> None:
    path = write_csv(tmp_path / "bad.csv", text)
    with pytest.raises(CsvMotionError, match=match):
        CsvMotion.from_file(path)


def test_csv_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"csv\.path.*nope\.csv"):
        MotionConfig(kind="csv", csv=CsvMotionConfig(str(tmp_path / "nope.csv")))


# ------------------------------------------------------------------ configs
def test_every_source_satisfies_the_protocol(tmp_path: Path) -> None:
    path = tmp_path / "m.csv"
    write_motion_csv(path, np.array([0.0, 1.0]), np.zeros((2, 6)))
    for kind in ("static", "sinusoids", "sea_state", "csv"):
        config = MotionConfig(kind=kind, csv=CsvMotionConfig(str(path)))
        source = make_motion_source(config, rng())
        assert isinstance(source, MotionSource)
        assert source.pose(0.3).shape == (6,) and source.velocity(0.3).shape == (6,)


@pytest.mark.parametrize("kind", ["static", "sinusoids", "sea_state", "csv-hold", "csv-loop"])
def test_batch_poses_equal_single_poses(kind: str, tmp_path: Path) -> None:
    path = tmp_path / "m.csv"
    write_motion_csv(path, np.linspace(0.0, 4.0, 9), rng(1).normal(0.0, 0.02, (9, 6)))
    config = MotionConfig(
        kind=kind.split("-")[0],  # type: ignore[arg-type]
        static=StaticMotionConfig((0.01, -0.02, 0.03), (1.0, -2.0, 3.0)),
        csv=CsvMotionConfig(str(path), end=kind.split("-")[-1] if "csv" in kind else "hold"),
    )
    source = make_motion_source(config, rng(2))
    assert isinstance(source, BatchMotionSource)
    # before the start, across the samples, after the end (hold or loop), repeated times
    times = np.concatenate([np.linspace(-1.0, 9.0, 401), [2.0, 2.0]])
    batch = source.poses(times)
    assert batch.shape == (len(times), 6)
    single = np.array([source.pose(float(t)) for t in times])
    np.testing.assert_allclose(batch, single, rtol=0.0, atol=1e-15)
    np.testing.assert_array_equal(sample_poses(source, times), batch)


def test_motion_config_errors_name_the_field() -> None:
    with pytest.raises(ConfigError) as info:
        MotionConfig(kind="waves")  # type: ignore[arg-type]
    assert info.value.key == "kind"
    for kind in ("static", "sinusoids", "sea_state", "csv"):
        assert repr(kind) in str(info.value)
    with pytest.raises(ConfigError, match=r"csv\.path"):
        MotionConfig(kind="csv")
    with pytest.raises(ConfigError) as info:
        MotionConfig(sea_state={"gamma": 0.5})  # type: ignore[arg-type]
    assert info.value.key == "sea_state.gamma"
    with pytest.raises(ConfigError, match="sea_state"):
        SeaStateConfig(sea_state=9)
    with pytest.raises(ConfigError, match="significant_height_m"):
        SeaStateConfig(sea_state=None, peak_period_s=7.0)
    with pytest.raises(ConfigError, match="six rows"):
        SinusoidConfig(amplitudes=((0.01,),), frequencies_hz=((0.1,),))
    with pytest.raises(ConfigError, match="frequencies_hz"):
        SinusoidConfig(
            amplitudes=((0.01,),) * 6,
            frequencies_hz=((0.1, 0.2),) + ((0.1,),) * 5,
        )
    with pytest.raises(ConfigError, match="end"):
        CsvMotionConfig("x.csv", end="bounce")  # type: ignore[arg-type]


def test_motion_config_accepts_mappings() -> None:
    config = MotionConfig(
        kind="sea_state",
        sea_state={"sea_state": None, "significant_height_m": 1.0, "peak_period_s": 7.0},  # type: ignore[arg-type]
        sinusoids={"amplitudes": [[0.01]] * 6, "frequencies_hz": [[0.1]] * 6},  # type: ignore[arg-type]
    )
    assert isinstance(config.sea_state, SeaStateConfig) and config.sea_state.hs == 1.0
    assert config.sinusoids.amplitudes == ((0.01,),) * 6
