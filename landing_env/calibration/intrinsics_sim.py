"""Chessboard intrinsics calibration run in the simulator (CRHF Sec. 2.1–2.2).

The paper's rig is a chessboard (7 cm squares, 7 x 10 inner corners) on a Stewart table
carried by a rover round a circular path under the hovering drone, which takes 20 photos.
Here the same board is a textured plate in a PyBullet world of its own (nothing else in
it, so no airframe near the near plane and nothing to hide), shown to the camera in
``views`` poses: tilted by 10° to ``max_tilt_deg`` about a random in-plane axis, turned
in-plane, at distances across ``distance_m``, and spread over the image on a jittered grid
so that the corners cover it (as the rover's path does).  Each view is rendered through the
real camera pipeline (:class:`~landing_env.sensors.camera.CameraSensor`, lens distortion
included), its corners are found with :func:`estimation.intrinsics_calibration.find_chessboard`
and OpenCV's calibration gives K and the distortion.

Board frame G: origin at the first inner corner, x along the rows of inner corners (the
order of :func:`~estimation.intrinsics_calibration.chessboard_object_points`), y down the
columns, z into the board (the printed face looks along -z, like the tag frame D).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import pybullet as p
from pybullet_utils.bullet_client import BulletClient
from scipy.spatial.transform import Rotation

from estimation.camera_model import CameraIntrinsics
from estimation.intrinsics_calibration import (
    IntrinsicsCalibrationResult,
    calibrate,
    find_chessboard,
)
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from landing_env._quiet import quiet_stdout
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.sensors.camera import CameraSensor
from landing_env.sensors.camera_config import CameraConfig

#: OpenCV calibration flags of each distortion model.
DISTORTION_FLAGS: dict[str, int] = {
    "none": cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
    "k1k2p1p2": cv2.CALIB_FIX_K3,
    "full": 0,
}

#: The camera looks straight down from here; the boards are placed below it.
_CAMERA_POSITION_W = np.array([0.0, 0.0, 5.0])
#: A level camera at zero yaw: OpenCV axes in W (x_C = -y_W, y_C = -x_W, z_C = -z_W).
_CAMERA_ROTATION_W = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True)
class ChessboardRigConfig:
    """The calibration board and how it is shown to the camera.

    ``pattern``: inner corners per row and per column (OpenCV's ``patternSize``; CRHF: 7 x 10).
    ``square_size_m``: edge of one square (CRHF: 7 cm).  ``margin_squares``: white border
    round the squares, in squares (findChessboardCorners needs a light quiet zone).
    ``texels_per_square``: texture resolution.  ``views``: number of poses shown.
    ``distance_m``: (min, max) distance of the board centre along the optical axis.
    ``min_tilt_deg``/``max_tilt_deg``: tilt of the board away from facing the camera;
    tilted views are what separate the focal length from the distance.
    ``max_spin_deg``: in-plane turn.  ``edge_margin_px``: the board's squares must project
    this far inside the image.  ``distortion_model``: which distortion terms OpenCV fits
    (``"none"``, ``"k1k2p1p2"`` = k3 fixed at 0, ``"full"``).
    """

    pattern: tuple[int, int] = (7, 10)
    square_size_m: float = limited(0.07, POSITIVE)
    margin_squares: float = limited(1.0, Limit(0.5))
    texels_per_square: int = limited(48, Limit(4, 512))
    texture_blur_texels: float = 2.0
    views: int = limited(20, Limit(3))
    distance_m: tuple[float, float] = (1.0, 2.2)
    min_tilt_deg: float = limited(10.0, Limit(0.0, 80.0))
    max_tilt_deg: float = 40.0
    max_spin_deg: float = limited(30.0, Limit(0.0, 180.0))
    edge_margin_px: float = limited(6.0, NON_NEGATIVE)
    distortion_model: str = "k1k2p1p2"

    def __post_init__(self) -> None:
        if len(self.pattern) != 2 or min(self.pattern) < 3:
            raise ConfigError("pattern", f"{self.pattern!r}: need two counts of at least 3")
        require_limits(self)
        low, high = self.distance_m
        if not 0.0 < low <= high:
            raise ConfigError("distance_m", f"{self.distance_m!r} must satisfy 0 < min <= max")
        require_range(
            "max_tilt_deg",
            self.max_tilt_deg,
            self.min_tilt_deg,
            80.0,
            bounds_from=f"min_tilt_deg = {self.min_tilt_deg}",
        )
        require_choice("distortion_model", self.distortion_model, tuple(DISTORTION_FLAGS))

    @property
    def squares(self) -> tuple[int, int]:
        """Squares along x and y (one more than the inner corners)."""
        return self.pattern[0] + 1, self.pattern[1] + 1

    def board_extent_g(self, margin: float) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) in G of the squares plus ``margin`` squares round them."""
        s = self.square_size_m
        nx, ny = self.squares
        return (
            -(1.0 + margin) * s,
            -(1.0 + margin) * s,
            (nx - 1 + margin) * s,
            (ny - 1 + margin) * s,
        )


@dataclass(frozen=True)
class IntrinsicsSimReport:
    """The calibration, the camera it was run on and how many views were usable."""

    result: IntrinsicsCalibrationResult
    true_intrinsics: CameraIntrinsics
    views_used: int
    #: views whose chessboard was not found in the rendered image
    views_rejected: int

    def k_error_px(self) -> dict[str, float]:
        """Calibrated minus true fx, fy, cx, cy, pixels."""
        k, t = self.result.K, self.true_intrinsics
        return {
            "fx": float(k[0, 0] - t.fx),
            "fy": float(k[1, 1] - t.fy),
            "cx": float(k[0, 2] - t.cx),
            "cy": float(k[1, 2] - t.cy),
        }

    def k_error_pct(self) -> dict[str, float]:
        """The K errors in percent of the true fx, fy, cx, cy."""
        t = self.true_intrinsics
        truth = {"fx": t.fx, "fy": t.fy, "cx": t.cx, "cy": t.cy}
        return {key: 100.0 * err / truth[key] for key, err in self.k_error_px().items()}


def chessboard_texture(rig: ChessboardRigConfig) -> np.ndarray:
    """The board's RGB texture: black and white squares with a white margin (uint8).

    Square (i, j) with i + j even is black, so the first inner corner has a black square
    at its top-left, whatever the pattern size.
    """
    n = rig.texels_per_square
    margin = round(rig.margin_squares * n)
    nx, ny = rig.squares
    texture = np.full((ny * n + 2 * margin, nx * n + 2 * margin), 255, dtype=np.uint8)
    for j in range(ny):
        for i in range(nx):
            if (i + j) % 2 == 0:
                y0, x0 = margin + j * n, margin + i * n
                cv2.rectangle(texture, (x0, y0), (x0 + n - 1, y0 + n - 1), 0, thickness=-1)
    if rig.texture_blur_texels > 0.0:
        texture = cv2.GaussianBlur(texture, (0, 0), rig.texture_blur_texels)
    return cv2.cvtColor(texture, cv2.COLOR_GRAY2RGB)


def _board_obj(rig: ChessboardRigConfig) -> str:
    """A one-sided textured rectangle in G (z = 0), printed face towards -z_G.

    The texture's top-left is at G's (x0, y0); OBJ texture v grows towards the image top.
    """
    margin = round(rig.margin_squares * rig.texels_per_square) / rig.texels_per_square
    x0, y0, x1, y1 = rig.board_extent_g(margin)
    lines = [
        "# chessboard, generated by landing_env.calibration.intrinsics_sim",
        f"v {x0} {y0} 0",  # 1 texture top-left
        f"v {x1} {y0} 0",  # 2 top-right
        f"v {x1} {y1} 0",  # 3 bottom-right
        f"v {x0} {y1} 0",  # 4 bottom-left
        "vt 0 1",
        "vt 1 1",
        "vt 1 0",
        "vt 0 0",
        "vn 0 0 -1",
        # counter-clockwise seen from the printed side (-z_G)
        "f 1/1/1 3/3/1 2/2/1",
        "f 1/1/1 4/4/1 3/3/1",
    ]
    return "\n".join(lines) + "\n"


class ChessboardScene:
    """A PyBullet world holding only the chessboard, and the camera to look at it."""

    def __init__(self, camera: CameraConfig, rig: ChessboardRigConfig) -> None:
        self.rig = rig
        # the rig only renders: no detector, no EGL (its bodies must be created after it)
        self.camera_config = replace(camera, mode="project", use_egl=False)
        with quiet_stdout():
            self.client = BulletClient(connection_mode=p.DIRECT)
        self._files = tempfile.TemporaryDirectory(prefix="chessboard_")
        directory = Path(self._files.name)
        obj_path = directory / "board.obj"
        png_path = directory / "board.png"
        obj_path.write_text(_board_obj(rig))
        rgb = chessboard_texture(rig)
        cv2.imwrite(str(png_path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        c = self.client
        # a mid-grey floor far below: the board's white margin must stand out from the
        # background for findChessboardCorners (TinyRenderer's empty background is white)
        floor = c.createVisualShape(
            p.GEOM_BOX, halfExtents=[50.0, 50.0, 0.01], rgbaColor=[0.45, 0.45, 0.45, 1.0]
        )
        c.createMultiBody(0.0, -1, floor, [0.0, 0.0, -0.01])
        visual = c.createVisualShape(p.GEOM_MESH, fileName=str(obj_path), rgbaColor=[1, 1, 1, 1])
        self.board_id = c.createMultiBody(0.0, -1, visual, [0.0, 0.0, 0.0])
        texture = c.loadTexture(str(png_path))
        c.changeVisualShape(self.board_id, -1, textureUniqueId=texture, rgbaColor=[1, 1, 1, 1])
        self.sensor = CameraSensor(c, self.camera_config, np.random.default_rng(0))
        self.intrinsics = self.sensor.intrinsics

    def render(self, r_cg: np.ndarray, t_cg: np.ndarray) -> np.ndarray:
        """The camera image (RGB uint8) with the board at ``(R_CG, t_CG)``."""
        r_wg = _CAMERA_ROTATION_W @ r_cg
        t_wg = _CAMERA_POSITION_W + _CAMERA_ROTATION_W @ t_cg
        self.client.resetBasePositionAndOrientation(
            self.board_id, t_wg.tolist(), Rotation.from_matrix(r_wg).as_quat().tolist()
        )
        return self.sensor.render_image(_CAMERA_POSITION_W, _CAMERA_ROTATION_W)

    def close(self) -> None:
        self.sensor.close()
        try:
            self.client.disconnect()
        except p.error:
            pass
        self._files.cleanup()


def _grid_targets(count: int, width: int, height: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` jittered image points on a grid over the image (so views cover it)."""
    cols = int(np.ceil(np.sqrt(count * width / height)))
    rows = int(np.ceil(count / cols))
    cells = rng.permutation(rows * cols)[:count]
    u = (cells % cols + rng.uniform(0.2, 0.8, count)) / cols * width - 0.5
    v = (cells // cols + rng.uniform(0.2, 0.8, count)) / rows * height - 0.5
    return np.column_stack([u, v])


def sample_board_poses(
    rig: ChessboardRigConfig, intrinsics: CameraIntrinsics, rng: np.random.Generator
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``rig.views`` board poses ``(R_CG, t_CG)`` whose squares project inside the image.

    Each view aims the board centre at a grid point of the image; a pose that does not fit
    is pulled towards the image centre and pushed away from the camera until it does.
    """
    centre_g = np.array(
        [
            (rig.pattern[0] - 1) * rig.square_size_m / 2,
            (rig.pattern[1] - 1) * rig.square_size_m / 2,
            0.0,
        ]
    )
    x0, y0, x1, y1 = rig.board_extent_g(0.25)  # the squares and a sliver of margin
    outline_g = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
    k = intrinsics
    margin = rig.edge_margin_px
    centre_px = np.array([k.cx, k.cy])
    poses = []
    for target in _grid_targets(rig.views, k.width, k.height, rng):
        distance = rng.uniform(*rig.distance_m)
        tilt = np.radians(rng.uniform(rig.min_tilt_deg, rig.max_tilt_deg))
        axis_angle = rng.uniform(0.0, 2.0 * np.pi)
        spin = np.radians(rng.uniform(-rig.max_spin_deg, rig.max_spin_deg))
        axis = np.array([np.cos(axis_angle), np.sin(axis_angle), 0.0])
        r_cg = (
            Rotation.from_rotvec([0.0, 0.0, spin]) * Rotation.from_rotvec(tilt * axis)
        ).as_matrix()
        aim = target.copy()
        for attempt in range(90):
            ray = np.array([(aim[0] - k.cx) / k.fx, (aim[1] - k.cy) / k.fy, 1.0])
            t_cg = ray * distance - r_cg @ centre_g
            outline_px = k.project(outline_g @ r_cg.T + t_cg)
            inside = (
                np.all(np.isfinite(outline_px))
                and outline_px.min() >= margin - 0.5
                and np.all(outline_px[:, 0] <= k.width - 0.5 - margin)
                and np.all(outline_px[:, 1] <= k.height - 0.5 - margin)
            )
            if inside:
                break
            # slide towards the centre first; step back only when that is not enough
            aim = centre_px + 0.85 * (aim - centre_px)
            if attempt % 3 == 2:
                distance *= 1.04
        else:
            raise ConfigError(
                "distance_m", f"the board does not fit in the image even at {distance:.2f} m"
            )
        poses.append((r_cg, t_cg))
    return poses


def camera_metadata(intrinsics: CameraIntrinsics) -> dict:
    """The true camera model, saved with a calibration so a user can tell what it fits."""
    return intrinsics.as_dict()


def calibrate_intrinsics_in_sim(
    camera: CameraConfig,
    rig: ChessboardRigConfig | None = None,
    rng: np.random.Generator | None = None,
    progress: Callable[[], None] | None = None,
) -> IntrinsicsSimReport:
    """Render the board in ``rig.views`` poses, find its corners and calibrate with OpenCV.

    ``progress`` is called once per view.  Raises ``RuntimeError`` when fewer than 3 views
    show the whole board.
    """
    rig = rig or ChessboardRigConfig()
    rng = rng if rng is not None else np.random.default_rng(0)
    scene = ChessboardScene(camera, rig)
    try:
        poses = sample_board_poses(rig, scene.intrinsics, rng)
        found = []
        for r_cg, t_cg in poses:
            corners = find_chessboard(scene.render(r_cg, t_cg), rig.pattern)
            if corners is not None:
                found.append(corners)
            if progress is not None:
                progress()
    finally:
        scene.close()
    k = scene.intrinsics
    if len(found) < 3:
        raise RuntimeError(f"the chessboard was found in {len(found)} of {rig.views} views")
    result = calibrate(
        found,
        (k.width, k.height),
        rig.square_size_m,
        rig.pattern,
        flags=DISTORTION_FLAGS[rig.distortion_model],
    )
    metadata = {
        "source": "simulator",
        "camera": camera_metadata(k),
        "pattern": list(rig.pattern),
        "square_size_m": rig.square_size_m,
        "views_used": len(found),
        "views_rejected": rig.views - len(found),
        "distortion_model": rig.distortion_model,
    }
    result = replace(result, metadata=metadata)
    return IntrinsicsSimReport(
        result=result,
        true_intrinsics=k,
        views_used=len(found),
        views_rejected=rig.views - len(found),
    )
