"""Fusion of delayed, intermittent deck-pose estimates and ToF ranges with the IMU (an EKF).

:mod:`~estimation.fusion.model` holds the state and the process and measurement models,
:mod:`~estimation.fusion.filter` the delayed-measurement buffer, gating and resets,
:mod:`~estimation.fusion.config` the settings.
"""

from estimation.fusion.config import POSE_SOURCES, FusionConfig
from estimation.fusion.filter import METHOD, DeckFusion, pose_measurement
from estimation.fusion.model import N_STATE

__all__ = ["METHOD", "N_STATE", "POSE_SOURCES", "DeckFusion", "FusionConfig", "pose_measurement"]
