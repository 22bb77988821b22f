"""Touchdown metrics and the success rule."""

from __future__ import annotations

import math

import numpy as np

from estimation.frames import matrix_from_euler_zyx
from landing_env.config import TouchdownConfig
from landing_env.touchdown import Outcome, contact_metrics, evaluate_touchdown


def test_relative_normal_speed_accounts_for_a_rising_deck() -> None:
    metrics = contact_metrics(
        time_s=1.0,
        drone_position_w=np.array([0.0, 0.0, 1.0]),
        drone_velocity_w=np.array([0.0, 0.0, -0.3]),
        drone_rotation_wb=np.eye(3),
        deck_position_w=np.array([0.0, 0.0, 0.9]),
        deck_rotation_wp=np.eye(3),
        deck_velocity_w=np.array([0.0, 0.0, 0.4]),
        deck_angular_velocity_w=np.zeros(3),
        tag_centre_w=np.array([0.1, 0.0, 0.9]),
    )
    assert math.isclose(metrics.relative_normal_speed, 0.7)
    assert math.isclose(metrics.lateral_offset_m, 0.1)
    assert math.isclose(metrics.deck_tilt_deg, 0.0, abs_tol=1e-9)


def test_rolling_deck_point_velocity_and_tilt() -> None:
    roll = math.radians(4.0)
    metrics = contact_metrics(
        time_s=0.0,
        drone_position_w=np.array([0.0, 0.5, 1.0]),
        drone_velocity_w=np.zeros(3),
        drone_rotation_wb=np.eye(3),
        deck_position_w=np.array([0.0, 0.0, 1.0]),
        deck_rotation_wp=matrix_from_euler_zyx(roll, 0.0, 0.0),
        deck_velocity_w=np.zeros(3),
        deck_angular_velocity_w=np.array([1.0, 0.0, 0.0]),
        tag_centre_w=np.array([0.0, 0.0, 1.0]),
    )
    # the deck point 0.5 m to port rises at 0.5 m/s under a 1 rad/s roll rate
    assert metrics.relative_normal_speed > 0.49
    assert math.isclose(metrics.deck_tilt_deg, 4.0, rel_tol=1e-9)
    assert math.isclose(metrics.relative_attitude_deg, 4.0, rel_tol=1e-9)


def test_every_failed_check_is_listed() -> None:
    metrics = contact_metrics(
        0.0,
        np.array([0.0, 0.0, 1.0]),
        np.array([0.0, 0.0, -1.0]),
        matrix_from_euler_zyx(math.radians(15.0), 0.0, 0.0),
        np.zeros(3),
        matrix_from_euler_zyx(0.0, math.radians(6.0), 0.0),
        np.zeros(3),
        np.zeros(3),
        np.zeros(3),
    )
    metrics.all_feet_touched = True
    metrics.on_deck_after_settle = True
    outcome, result = evaluate_touchdown(metrics, TouchdownConfig())
    assert outcome is Outcome.HARD_LANDING
    assert set(result.failed_checks) == {"relative_normal_speed", "deck_tilt", "relative_attitude"}


def test_gentle_level_touchdown_succeeds() -> None:
    metrics = contact_metrics(
        0.0,
        np.array([0.0, 0.0, 1.0]),
        np.array([0.0, 0.0, -0.3]),
        np.eye(3),
        np.zeros(3),
        np.eye(3),
        np.zeros(3),
        np.zeros(3),
        np.zeros(3),
    )
    metrics.all_feet_touched = True
    metrics.on_deck_after_settle = True
    outcome, result = evaluate_touchdown(metrics, TouchdownConfig())
    assert outcome is Outcome.SUCCESS
    assert result.failed_checks == ()
