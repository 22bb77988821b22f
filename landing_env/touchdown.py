"""Touchdown and crash detection from PyBullet contacts, and the touchdown metrics."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from enum import Enum

import numpy as np

from landing_env.config import TouchdownConfig


class Outcome(str, Enum):
    """How an episode ended (``IN_FLIGHT`` while it goes on)."""

    IN_FLIGHT = "in_flight"
    SUCCESS = "success"
    HARD_LANDING = "hard_landing"
    CRASH = "crash"
    TIMEOUT = "timeout"


@dataclass
class TouchdownMetrics:
    """What was measured at the first foot-deck contact and during the settle that follows."""

    time_s: float = math.nan
    #: approach speed along the deck normal, drone relative to the deck point it hits, m/s
    relative_normal_speed: float = math.nan
    #: relative speed in the deck plane at contact, m/s
    relative_tangential_speed: float = math.nan
    #: angle between the deck normal and the world vertical, degrees
    deck_tilt_deg: float = math.nan
    #: angle between the drone's z axis and the deck normal, degrees
    relative_attitude_deg: float = math.nan
    #: horizontal distance (in the deck plane) of the drone centre from the tag centre, metres
    lateral_offset_m: float = math.nan
    #: every foot touched the deck during the settle
    all_feet_touched: bool = False
    #: at the end of the settle the drone still stood on the deck (>= 3 feet in contact)
    on_deck_after_settle: bool = False
    #: what failed, empty on success
    failed_checks: tuple[str, ...] = ()

    def as_dict(self) -> dict:
        data = asdict(self)
        data["failed_checks"] = list(self.failed_checks)
        return data


@dataclass
class ContactSummary:
    """Contacts of the drone after one physics step."""

    feet_on_deck: frozenset[int]
    #: a non-foot part touched anything, or a foot touched something other than the deck
    forbidden: bool
    forbidden_what: str = ""


def summarise_contacts(
    contact_points: tuple, foot_links: frozenset[int], deck_body: int
) -> ContactSummary:
    """Classify ``getContactPoints(bodyA=drone)`` output into feet-on-deck and forbidden."""
    feet: set[int] = set()
    forbidden = False
    what = ""
    for contact in contact_points:
        link_a, body_b = contact[3], contact[2]
        if link_a in foot_links and body_b == deck_body:
            feet.add(link_a)
        elif not forbidden:
            forbidden = True
            part = "foot" if link_a in foot_links else f"link {link_a}"
            what = f"{part} touched body {body_b}"
    return ContactSummary(frozenset(feet), forbidden, what)


def evaluate_touchdown(
    metrics: TouchdownMetrics, thresholds: TouchdownConfig
) -> tuple[Outcome, TouchdownMetrics]:
    """Apply the success thresholds to measured metrics; list every failed check."""
    failed = []
    if not metrics.relative_normal_speed <= thresholds.max_normal_speed:
        failed.append("relative_normal_speed")
    if not metrics.deck_tilt_deg <= thresholds.max_deck_tilt_deg:
        failed.append("deck_tilt")
    if not metrics.relative_attitude_deg <= thresholds.max_relative_attitude_deg:
        failed.append("relative_attitude")
    if not metrics.all_feet_touched:
        failed.append("all_feet_on_deck")
    if not metrics.on_deck_after_settle:
        failed.append("on_deck_after_settle")
    metrics.failed_checks = tuple(failed)
    return (Outcome.SUCCESS if not failed else Outcome.HARD_LANDING), metrics


def contact_metrics(
    time_s: float,
    drone_position_w: np.ndarray,
    drone_velocity_w: np.ndarray,
    drone_rotation_wb: np.ndarray,
    deck_position_w: np.ndarray,
    deck_rotation_wp: np.ndarray,
    deck_velocity_w: np.ndarray,
    deck_angular_velocity_w: np.ndarray,
    tag_centre_w: np.ndarray,
) -> TouchdownMetrics:
    """Metrics at the first contact, from the states just before it."""
    normal = deck_rotation_wp[:, 2]
    # velocity of the deck point under the drone (rigid-body kinematics of the top plate)
    deck_point_velocity = deck_velocity_w + np.cross(
        deck_angular_velocity_w, drone_position_w - deck_position_w
    )
    relative = drone_velocity_w - deck_point_velocity
    normal_speed = -float(relative @ normal)
    tangential = relative - (relative @ normal) * normal
    offset = drone_position_w - tag_centre_w
    offset_in_plane = offset - (offset @ normal) * normal
    tilt = math.degrees(math.acos(float(np.clip(normal[2], -1.0, 1.0))))
    attitude = math.degrees(math.acos(float(np.clip(drone_rotation_wb[:, 2] @ normal, -1.0, 1.0))))
    return TouchdownMetrics(
        time_s=time_s,
        relative_normal_speed=normal_speed,
        relative_tangential_speed=float(np.linalg.norm(tangential)),
        deck_tilt_deg=tilt,
        relative_attitude_deg=attitude,
        lateral_offset_m=float(np.linalg.norm(offset_in_plane)),
    )
