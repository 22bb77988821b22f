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
    #: highest clearance of the lowest foot above the deck plane during the settle, metres
    #: (> 0: the drone left the deck again, all feet in the air)
    bounce_height_m: float = math.nan
    #: largest total normal force foot-deck in one physics step after the contact, newtons,
    #: and that as a multiple of the drone's weight
    peak_load_n: float = math.nan
    peak_load_g: float = math.nan
    #: deck vertical acceleration at the contact (g; the quantity CAP 437's Motion Severity
    #: Index is built from), from the deck's commanded motion
    deck_vertical_accel_g: float = math.nan
    #: largest angle between the drone's z axis and the deck normal during the settle, deg
    max_settle_attitude_deg: float = math.nan
    #: the drone tipped over: that angle passed the tip-over limit, or a part other than a
    #: foot touched the deck during the settle
    tipped_over: bool = False
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
    if metrics.bounce_height_m > thresholds.max_bounce_m:
        failed.append("bounce")
    if metrics.tipped_over:
        failed.append("tip_over")
    metrics.failed_checks = tuple(failed)
    return (Outcome.SUCCESS if not failed else Outcome.HARD_LANDING), metrics


class TouchdownProbe:
    """Watches the settle after the first contact at every physics step.

    Records the peak foot-deck normal load, the bounce (the lowest foot's largest clearance
    above the deck plane) and the largest drone-to-deck-normal angle, and whether a non-foot
    part touched the deck.
    """

    def __init__(
        self,
        client_id: int,
        drone_id: int,
        deck_id: int,
        foot_links: frozenset[int],
        foot_radius_m: float,
        tip_over_deg: float,
    ) -> None:
        self._cid = client_id
        self._drone = drone_id
        self._deck = deck_id
        self._feet = tuple(sorted(foot_links))
        self._foot_set = frozenset(foot_links)
        self._radius = foot_radius_m
        self._tip_over_deg = tip_over_deg
        self.peak_load_n = 0.0
        self.bounce_height_m = -math.inf
        self.max_attitude_deg = 0.0
        self.body_contact = False

    def update(self) -> None:
        import pybullet as p

        cid = self._cid
        load = 0.0
        for contact in p.getContactPoints(bodyA=self._drone, bodyB=self._deck, physicsClientId=cid):
            if contact[3] in self._foot_set:
                load += contact[9]
            else:
                self.body_contact = True
        self.peak_load_n = max(self.peak_load_n, load)
        position, orientation = p.getBasePositionAndOrientation(self._deck, physicsClientId=cid)
        normal = np.asarray(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)[:, 2]
        feet = p.getLinkStates(self._drone, self._feet, physicsClientId=cid)
        clearance = min(
            float(normal @ (np.asarray(foot[0]) - position)) - self._radius for foot in feet
        )
        self.bounce_height_m = max(self.bounce_height_m, clearance)
        _, drone_q = p.getBasePositionAndOrientation(self._drone, physicsClientId=cid)
        drone_z = np.asarray(p.getMatrixFromQuaternion(drone_q)).reshape(3, 3)[:, 2]
        angle = math.degrees(math.acos(float(np.clip(drone_z @ normal, -1.0, 1.0))))
        self.max_attitude_deg = max(self.max_attitude_deg, angle)

    def fill(self, metrics: TouchdownMetrics, weight_n: float) -> None:
        """Write what was watched into ``metrics``."""
        metrics.bounce_height_m = max(0.0, self.bounce_height_m)
        metrics.peak_load_n = self.peak_load_n
        metrics.peak_load_g = self.peak_load_n / weight_n
        metrics.max_settle_attitude_deg = self.max_attitude_deg
        metrics.tipped_over = self.body_contact or self.max_attitude_deg > self._tip_over_deg


def spool_down_thrust_n(progress: float, weight_n: float, final_fraction: float) -> float:
    """The land sequence's thrust cap, N: the weight at the contact (``progress`` 0), falling
    linearly to ``final_fraction`` of it at the end (``progress`` 1)."""
    progress = min(max(progress, 0.0), 1.0)
    return weight_n * (1.0 - progress * (1.0 - final_fraction))


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
