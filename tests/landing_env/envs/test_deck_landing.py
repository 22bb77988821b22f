"""DeckLanding-v2 against the Gymnasium and SB3 API checks, seeding, vec envs, episodes."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

import landing_env  # noqa: F401
from agents.policies.align_descend import AlignDescendPolicy
from landing_env.errors import ConfigError


def make(**kwargs) -> gym.Env:
    return gym.make("DeckLanding-v2", **kwargs)


def test_both_ids_make_the_env() -> None:
    for env_id in ("DeckLanding-v2", "landing_env:DeckLanding-v2"):
        env = gym.make(env_id)
        observation, _ = env.reset(seed=1)
        assert env.observation_space.contains(observation)
        env.close()


def test_gymnasium_check_env() -> None:
    env = make()
    gym_check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_sb3_check_env() -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make()
    sb3_check_env(env.unwrapped, warn=True)
    env.close()


def test_bad_keyword_fails_with_the_key() -> None:
    with pytest.raises(ConfigError, match=r"tof\.noise"):
        make(tof={"noise": "gaussian-ish"})


def _rollout(seed: int, steps: int = 25) -> list[np.ndarray]:
    env = make(overrides={"tof.noise": "vl53l1x", "camera.pixel_noise_px": 0.5})
    observation, _ = env.reset(seed=seed)
    rng = np.random.default_rng(123)
    trace = [np.concatenate([observation["deck_pose"], observation["tof_range"]])]
    for _ in range(steps):
        observation, _reward, terminated, truncated, info = env.step(
            rng.uniform(-0.3, 0.3, 5).astype(np.float32)
        )
        trace.append(
            np.concatenate(
                [observation["deck_pose"], observation["tof_range"], info["drone"]["position_w"]]
            )
        )
        if terminated or truncated:
            break
    env.close()
    return trace


def test_same_seed_same_episode_and_other_seed_differs() -> None:
    first, second, other = _rollout(7), _rollout(7), _rollout(8)
    assert len(first) == len(second)
    for a, b in zip(first, second, strict=False):
        np.testing.assert_array_equal(a, b)
    assert not np.allclose(first[0], other[0])


def test_runs_under_subproc_vec_env() -> None:
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    # the "module:id" form makes the worker processes import and register the package
    vec = make_vec_env("landing_env:DeckLanding-v2", n_envs=2, seed=3, vec_env_cls=SubprocVecEnv)
    try:
        observations = vec.reset()
        assert observations["deck_pose"].shape == (2, 6)
        for _ in range(5):
            observations, rewards, _dones, _infos = vec.step(
                np.zeros((2, *vec.action_space.shape), dtype=np.float32)
            )
        assert rewards.shape == (2,)
        assert np.all(np.isfinite(observations["deck_pose"]))
    finally:
        vec.close()


def test_info_carries_truth_state_and_imu_samples() -> None:
    env = make()
    _, info = env.reset(seed=0)
    observation, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert info["deck_pose_true"].shape == (6,)
    # the deck is below the camera: the tag is at positive z_C
    assert 1.0 < info["deck_pose_true"][2] < 3.0
    # 12 physics steps per control step, each with an IMU sample: t, accel(3), gyro(3)
    assert info["imu_samples"].shape == (12, 7)
    hover_accel = info["imu_samples"][:, 3].mean()
    assert abs(hover_accel - 9.81) < 1.0
    # the default observation is the IHRCF estimate, close to the truth with noise-free ranges
    assert set(info["estimates"]) == {"ihrcf"}
    assert info["estimates"]["ihrcf"]["valid"]
    np.testing.assert_allclose(observation["deck_pose"][:3], info["deck_pose_true"][:3], atol=0.01)
    assert observation["tof_valid"].sum() == 4
    env.close()


def test_scripted_descent_lands_on_the_moving_deck() -> None:
    env = make()
    base = env.unwrapped
    policy = AlignDescendPolicy(
        base.config.action, dt=base.env_dt, tof_mounts_c=base.config.tof.mount_offsets_c
    )
    observation, _ = env.reset(seed=0)
    for _ in range(env.unwrapped.max_steps):
        observation, _reward, terminated, truncated, info = env.step(policy(observation))
        if terminated or truncated:
            break
    env.close()
    assert info["outcome"] == "success", info.get("touchdown")
    touchdown = info["touchdown"]
    assert touchdown["relative_normal_speed"] <= 0.5
    assert touchdown["all_feet_touched"]


def test_flying_into_the_ground_off_the_deck_is_a_crash() -> None:
    env = make(start={"max_offset_m": 0.0})
    env.reset(seed=0)
    outcome = "in_flight"
    for _ in range(400):
        # fly sideways off the deck and down: the feet hit the ground, not the deck
        _, reward, terminated, truncated, info = env.step(
            np.array([1.0, 0.0, -0.6, 0.0, -1.0], dtype=np.float32)
        )
        if terminated or truncated:
            outcome = info["outcome"]
            break
    env.close()
    assert outcome == "crash"
    assert reward < -5.0


def test_time_limit_truncates() -> None:
    env = make(simulation={"max_episode_s": 1.0})
    env.reset(seed=0)
    steps = 0
    while True:
        _, _, terminated, truncated, info = env.step(
            np.zeros(env.action_space.shape, dtype=np.float32)
        )
        steps += 1
        if terminated or truncated:
            break
    env.close()
    assert truncated and not terminated
    assert steps == 20
    assert info["outcome"] == "timeout"


def test_out_of_bounds_action_is_flagged_not_silently_clipped() -> None:
    env = make()
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([2.0, 0.0, 0.0, 0.0, 0.0], dtype=np.float32))
    assert info["action_clipped"]
    _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert not info["action_clipped"]
    env.close()


def test_fixed_drone_stays_put_over_the_moving_deck() -> None:
    env = make(simulation={"drone_fixed": True})
    _, info = env.reset(seed=2)
    start = info["drone"]["position_w"].copy()
    deck_heights = []
    for _ in range(40):
        _, _, terminated, truncated, info = env.step(
            np.ones(env.action_space.shape, dtype=np.float32)
        )
        deck_heights.append(info["deck"]["position_w"][2])
        assert not (terminated or truncated)
    env.close()
    np.testing.assert_allclose(info["drone"]["position_w"], start, atol=1e-9)
    assert np.ptp(deck_heights) > 0.005  # the deck moved under the motionless drone
    assert abs(info["imu_samples"][:, 3].mean() - 9.81) < 0.5


def test_the_gui_config_without_a_display_fails_clearly(monkeypatch: pytest.MonkeyPatch) -> None:
    # render_mode="human" falls back to headless (tests/test_ecosystem.py); simulation.gui
    # asks for the window explicitly and is refused
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(RuntimeError, match="needs a display"):
        make(overrides={"simulation.gui": True})


def test_rgb_array_shows_the_camera_view_with_the_detection() -> None:
    env = make(render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    env.close()
    assert image.shape == (512, 512, 3) and image.dtype == np.uint8
    # the tag (black and white cells) is in the middle of the view, the sea round it
    centre = image[206:306, 206:306].astype(int)
    assert centre.min() < 40 and centre.max() > 200
    # the detection outline is drawn in green
    green = (image[..., 1] > 200) & (image[..., 0] < 80) & (image[..., 2] < 80)
    assert green.sum() > 100


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_at_the_start_the_tag_spans_60_px_and_all_tof_rays_hit_the_deck(seed: int) -> None:
    env = make(camera={"mode": "render"}, estimation={"observed": "atda"})
    observation, info = env.reset(seed=seed)
    frame = env.unwrapped._sensing.frame
    env.close()
    assert len(frame.detections) == 1, info["tag_miss_reason"]
    corners = frame.detections[0].corners_px
    sides = np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)
    assert sides.min() >= 60.0
    assert observation["tof_valid"].tolist() == [1, 1, 1, 1]
    # each ray meets the deck plate, not the sea: ranges agree with the camera-to-deck depth
    assert np.all(np.abs(observation["tof_range"] - info["deck_pose_true"][2]) < 0.1)


def _equal_with_nan(a: object, b: object) -> bool:
    """Structural equality of two ``info`` values, NaN equal to NaN (missing = missing)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_equal_with_nan(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_equal_with_nan(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, (np.ndarray, float)) or isinstance(b, (np.ndarray, float)):
        x, y = np.asarray(a), np.asarray(b)
        if x.dtype.kind in "fc" or y.dtype.kind in "fc":
            return x.shape == y.shape and bool(np.array_equal(x, y, equal_nan=True))
        return bool(np.array_equal(x, y))
    return a == b


def test_info_with_missing_readings_is_deterministic() -> None:
    # at 20 m no ToF ray returns: info holds NaN ranges, which Gymnasium's checker (NaN != NaN)
    # cannot compare; the episode is deterministic all the same
    infos = []
    for _ in range(2):
        env = gym.make("DeckLanding-v2", config="high-approach")
        try:
            _, first = env.reset(seed=5)
            steps = [
                env.step(np.zeros(env.action_space.shape, dtype=np.float32))[4] for _ in range(3)
            ]
        finally:
            env.close()
        infos.append([first, *steps])
    # info holds no NaN: an invalid range is 0 beside its validity, so that Gymnasium's
    # determinism check can compare two runs
    assert not infos[0][1]["tof_ranges"].any()
    assert not infos[0][1]["tof_valid"].any()
    assert _equal_with_nan(infos[0], infos[1])
