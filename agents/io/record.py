"""Records what the simulator does as standard ROS 2 messages in an MCAP file.

:class:`McapRecorder` wraps a ``DeckLanding`` environment (Gymnasium wrapper); after each
``reset`` and ``step`` it writes, stamped with the simulation time of the step's camera frame:

======================== ========================================== ====================
topic                    type                                       frame id
======================== ========================================== ====================
/camera/image_raw        sensor_msgs/Image (rgb8; render mode only) camera
/camera/tag_detections   deck_landing_msgs/TagDetections            camera
/tof/range               sensor_msgs/Range, one per sensor          tof_1 .. tof_4
/tof/ranges              deck_landing_msgs/TofRanges (float64)      body
/imu/data                sensor_msgs/Imu, every sample of the step  body
/truth/drone             geometry_msgs/PoseStamped (B in W)         world
/truth/deck              geometry_msgs/PoseStamped (D in W)         world
/truth/deck_pose         geometry_msgs/PoseStamped (T_CD)           camera
/estimates/<method>      geometry_msgs/PoseWithCovarianceStamped    camera
/estimates/status        deck_landing_msgs/EstimateStatus           camera
/tf                      tf2_msgs/TFMessage: world→body,            (parent → child)
                         body→camera, world→deck
======================== ========================================== ====================

The detections are what the estimators consume (in ``project`` mode there is no image);
``deck-landing estimate`` reads them and reproduces the in-simulator estimates.  A range with
no return is +inf (REP 117).  The IMU sample at the frame's stamp carries the body's
attitude R_WB as its orientation; the others mark it unknown (``orientation_covariance[0] =
-1``, REP 145).  Only valid estimates are written as poses; every estimate's validity and
reason is on ``/estimates/status``.  The first ``max_episodes`` episodes are recorded.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.io import messages as m
from estimation.frames import R_BC
from estimation.types import DeckPoseEstimate


class McapRecorder(gym.Wrapper):
    """Writes each step of the wrapped environment to ``path`` (see the module doc)."""

    def __init__(self, env: gym.Env, path: str | Path, max_episodes: int = 1) -> None:
        super().__init__(env)
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = self.path.open("wb")
        self._writer: m.McapWriter | None = m.McapWriter(self._stream)
        self.max_episodes = max_episodes
        self.episodes = 0
        self.messages = 0

    def reset(self, **kwargs: Any) -> tuple[Any, dict]:
        observation, info = self.env.reset(**kwargs)
        self.episodes += 1
        if self.episodes > self.max_episodes:
            self.finish()
        self._record(info)
        return observation, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        result = self.env.step(action)
        self._record(result[4])
        return result

    def close(self) -> None:
        self.finish()
        super().close()

    def finish(self) -> None:
        """Close the file (also done by ``close``); later steps are not recorded."""
        if self._writer is not None:
            self._writer.finish()
            self._stream.close()
            self._writer = None

    def _write(self, topic: str, typename: str, message: Any, t: float) -> None:
        assert self._writer is not None
        self._writer.write(topic, typename, message, t)
        self.messages += 1

    def _record(self, info: dict) -> None:
        if self._writer is None:
            return
        base = self.env.unwrapped
        sensing = base._sensing  # the step's camera frame, ranges and estimates
        frame, ranges = sensing.frame, sensing.ranges
        t = float(frame.timestamp)
        self._camera(frame, t)
        self._ranges(base.config.tof, ranges, t)
        world = base.world
        state = world.drone_state()
        self._imu(info["imu_samples"], state.rotation_wb, t)
        deck = world.deck_state()
        r_cd, t_cd = world.true_deck_pose_c()
        truth = (
            ("/truth/drone", "world", state.rotation_wb, state.position_w),
            ("/truth/deck", "world", deck.rotation_wd, deck.tag_centre_w),
            ("/truth/deck_pose", "camera", r_cd, t_cd),
        )
        for topic, frame_id, rotation, position in truth:
            message = m.msg(m.POSE, header=m.header(t, frame_id), pose=m.pose(rotation, position))
            self._write(topic, m.POSE, message, t)
        tf = [
            m.transform(t, "world", "body", state.rotation_wb, state.position_w),
            m.transform(t, "body", "camera", R_BC, world.t_bc),
            m.transform(t, "world", "deck", deck.rotation_wd, deck.tag_centre_w),
        ]
        self._write("/tf", m.TF, m.msg(m.TF, transforms=tf), t)
        for name, estimate in sensing.estimates.items():
            self._estimate(name, estimate, t)

    def _camera(self, frame: Any, t: float) -> None:
        if frame.image is not None and np.asarray(frame.image).ndim == 3:
            self._write("/camera/image_raw", m.IMAGE, m.image_rgb8(t, frame.image), t)
        detections = [
            m.msg(
                "deck_landing_msgs/msg/TagDetection",
                id=int(d.tag_id),
                corners_px=np.asarray(d.corners_px, dtype=np.float64).reshape(8),
                decision_margin=float(d.decision_margin),
                hamming=int(d.hamming),
            )
            for d in frame.detections
        ]
        message = m.msg(
            m.DETECTIONS,
            header=m.header(t, "camera"),
            miss_reason=frame.miss_reason,
            detections=detections,
        )
        self._write("/camera/tag_detections", m.DETECTIONS, message, t)

    def _ranges(self, tof: Any, ranges: Any, t: float) -> None:
        messages, exact = m.tof_messages(
            t, ranges.ranges, ranges.valid, min_range_m=tof.min_range, max_range_m=tof.max_range
        )
        for message in messages:
            self._write("/tof/range", m.RANGE, message, t)
        self._write("/tof/ranges", m.TOF_RANGES, exact, t)

    def _imu(self, samples: np.ndarray, r_wb: np.ndarray, t: float) -> None:
        frame_ns = m.to_ns(t)
        for row in np.asarray(samples, dtype=float).reshape(-1, 7):
            at_frame = m.to_ns(row[0]) == frame_ns
            q = m.quaternion_xyzw(r_wb if at_frame else np.eye(3))
            covariance = np.zeros(9)
            if not at_frame:
                covariance[0] = -1.0  # REP 145: orientation unknown
            message = m.msg(
                m.IMU,
                header=m.header(row[0], "body"),
                orientation=m.msg("geometry_msgs/msg/Quaternion", x=q[0], y=q[1], z=q[2], w=q[3]),
                orientation_covariance=covariance,
                angular_velocity=m.vector3(row[4:7]),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=m.vector3(row[1:4]),
                linear_acceleration_covariance=np.zeros(9),
            )
            self._write("/imu/data", m.IMU, message, row[0])

    def _estimate(self, name: str, estimate: DeckPoseEstimate, t: float) -> None:
        status = m.msg(
            m.STATUS,
            header=m.header(t, "camera"),
            method=name,
            valid=bool(estimate.valid),
            reason=estimate.reason,
        )
        self._write("/estimates/status", m.STATUS, status, t)
        finite = np.all(np.isfinite(estimate.rotation)) and np.all(
            np.isfinite(estimate.translation)
        )
        if not (estimate.valid and finite):
            return
        covariance = np.zeros(36)
        if estimate.covariance is not None:
            covariance = np.asarray(estimate.covariance, dtype=float).reshape(-1)
        message = m.msg(
            m.POSE_COV,
            header=m.header(t, "camera"),
            pose=m.msg(
                "geometry_msgs/msg/PoseWithCovariance",
                pose=m.pose(estimate.rotation, estimate.translation),
                covariance=covariance,
            ),
        )
        self._write(f"/estimates/{name}", m.POSE_COV, message, t)
