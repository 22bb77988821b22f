"""How far the planar renderer's images and detections are from the reference renderers.

A helper of ``tests/landing_env/sensors/test_planar_renderer.py`` and
``tests/landing_env/sensors/test_camera_realism.py``: a world is posed (drone height above the
deck, drone and deck tilts), the same camera pose is rendered by both renderers (ideal pinhole
images, no lens distortion), the tag is detected in both images, and the corner differences
and image differences are returned; the analytic projection of the tag corners is the truth
both are also measured against.

Which reference measures the truth (the 15 :func:`standard_poses`; the benchmark that printed
them is in history, ``git show 7d43668:benchmarks/bench_renderer_agreement.py``).  Plain
TinyRenderer is no fair yardstick: it samples its texture at
one point per pixel (nearest texel, no filtering, no anti-aliasing), so its corners are
quantised.  The planar renderer minus plain TinyRenderer is 0.23 px mean, but its *mean
vector* (the systematic offset a pixel-centre, half-pixel, row-flip or projection error would
leave) is (+0.015, -0.001) px over all corners and at most 0.05 px per height, against a
spread (standard deviation) of 0.1 to 0.4 px per axis; and plain TinyRenderer differs as much
from its own supersampled image (0.21 px mean) and from the analytic corners (0.25 px, against
the planar renderer's 0.10 px).  The difference is TinyRenderer's quantisation, not an offset.
The references are therefore:

* TinyRenderer *supersampled* (always available): rendered at ``supersample`` times the
  resolution (same camera, pixel centres kept) and box-filtered down with ``cv2.INTER_AREA``,
  the anti-aliased image it converges to; ``supersample=1`` is its plain output.  x4 is
  0.04 px from x6 in the mean over the standard poses (0.13 px at worst), x3 0.09 px (0.55 px
  at the level pose at 0.3 m), and only x6 keeps the planar corners within 0.1 px of it at
  every pose (2026-11-29, at 4797a9c): the tests use x6, 2.6 s of CPU a pose.  The standard
  poses' x6 images are committed in ``tests/data/renderer-references/`` (150 kB), each named by
  its pose's plain TinyRenderer image (:func:`committed_reference_path`): a change to the
  scene, the camera, the poses or the rendering code names other files, which
  ``python -m tests.renderer_agreement`` writes again (a test fails until it has, naming the
  command, and another renders one pose live and finds its committed image to the byte); any
  other pose's is kept in the user cache (:func:`supersampled_cache_path`).  Near the deck
  (0.3 m) its texels are magnified (1.7 px a texel) and point-sampled, which leaves 0.2-0.3 px
  of its own error there.
* OpenGL through PyBullet's EGL plugin, where it loads (a GPU, or Mesa's software llvmpipe):
  it filters textures, and the planar renderer agrees with its *plain* output to 0.04 px
  mean with no offset (mean vector under 0.01 px), 0.008 px at 0.3 m.
"""

from __future__ import annotations

import contextlib
import hashlib
import inspect
import io
import zipfile
from dataclasses import dataclass, replace
from importlib import metadata
from pathlib import Path

import cv2
import numpy as np

from estimation.array_files import locked, write_atomic
from estimation.detection import AprilTagDetector
from estimation.frames import matrix_from_euler_zyx
from landing_env.config import DeckLandingConfig, load_config
from landing_env.resources import cache_dir
from landing_env.sensors.camera import CameraSensor
from landing_env.world import World
from tests.paths import DATA_DIR, ROOT

#: the user cache directory's folder of supersampled TinyRenderer images
REFERENCE_CACHE_FOLDER = "renderer-references"
#: the committed supersampled TinyRenderer images of the standard poses
COMMITTED_REFERENCES = DATA_DIR / REFERENCE_CACHE_FOLDER
#: the supersampling factor of the committed references (and of the corner tests)
COMMITTED_SUPERSAMPLE = 6

#: heights (drone centre above the deck's home surface, m) the agreement is checked at
HEIGHTS_M = (4.0, 2.0, 1.0, 0.6, 0.3)
#: poses below this height (m) view a smaller tag: the default 0.30 m tag is larger than the
#: view at 0.3 m
SMALL_TAG_BELOW_M = 0.5
#: the smaller tag's size, m
SMALL_TAG_M = 0.12


@dataclass(frozen=True)
class Pose:
    """A test pose: height (m), drone roll/pitch/yaw and deck roll/pitch (degrees)."""

    height_m: float
    drone_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    deck_rp_deg: tuple[float, float] = (0.0, 0.0)
    offset_m: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class Agreement:
    """Results for one pose; corner differences are planar minus reference, pixels."""

    pose: Pose
    corner_diff_px: np.ndarray | None
    corner_error_planar_px: np.ndarray | None
    corner_error_reference_px: np.ndarray | None
    mean_abs_grey: float
    #: fraction of pixels differing by more than 32 grey levels (edges only, if they agree)
    far_fraction: float


def standard_poses() -> list[Pose]:
    """Level and tilted poses at every height of :data:`HEIGHTS_M` (the tag in view)."""
    poses = []
    for h in HEIGHTS_M:
        tilt = min(8.0, 25.0 * h)  # near the deck a large tilt takes the tag out of view
        poses.append(Pose(h))
        poses.append(Pose(h, (0.3 * tilt, -0.5 * tilt, 20.0), (4.0, -3.0)))
        poses.append(Pose(h, (-0.5 * tilt, 0.2 * tilt, -35.0), (-5.0, 2.0), (0.02 * h, 0.0)))
    return poses


def render_config(small_tag: bool = False) -> DeckLandingConfig:
    """The default config with the camera rendering (the planar renderer attached), with
    the smaller tag where ``small_tag`` (the poses :func:`uses_small_tag`)."""
    overrides: dict[str, object] = {"camera.mode": "render"}
    if small_tag:
        overrides["deck.tag_size"] = SMALL_TAG_M
    return load_config("default", overrides=overrides)


def uses_small_tag(pose: Pose) -> bool:
    """Whether ``pose`` is rendered with the smaller tag (it is below
    :data:`SMALL_TAG_BELOW_M`)."""
    return pose.height_m < SMALL_TAG_BELOW_M


def place(world, pose: Pose) -> None:
    """Put the drone and the deck of a :class:`~landing_env.world.World` in ``pose``."""
    c = world.client
    home = world.deck_home_w
    r_wp = matrix_from_euler_zyx(*np.deg2rad(pose.deck_rp_deg), 0.0)
    c.resetBasePositionAndOrientation(world.deck_id, home.tolist(), _quaternion(r_wp))
    world.stewart.update_leg_visuals()
    roll, pitch, yaw = np.deg2rad(pose.drone_rpy_deg)
    r_wb = matrix_from_euler_zyx(roll, pitch, yaw)
    position = home + np.array([*pose.offset_m, pose.height_m])
    world.place_drone(position, yaw)
    c.resetBasePositionAndOrientation(world.drone.body_id, position.tolist(), _quaternion(r_wb))
    world._state = world.drone.read_state()


def _quaternion(rotation: np.ndarray) -> list[float]:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(rotation).as_quat().tolist()


def reference_image(world, supersample: int = 3, renderer: str | None = None) -> np.ndarray:
    """The ideal (pinhole) image of the reference, supersampled and box-filtered (see above).

    ``renderer``: "tiny" (TinyRenderer) or "egl" (the EGL plugin, which the world's camera
    must have loaded: ``camera.use_egl``); None = the world's own reference renderer.
    A supersampled TinyRenderer image is read from the committed references
    (:func:`committed_reference_path`) when one is named by the pose's plain image, else kept
    in the user cache directory (:func:`supersampled_cache_path`) and read back while the
    plain image of the same pose is the same to the byte.
    """
    s = int(supersample)
    renderer = world.camera.renderer if renderer is None else renderer
    if renderer not in ("tiny", "egl"):
        raise ValueError(f"renderer: {renderer!r} is not allowed; choose 'tiny' or 'egl'")
    if renderer == "egl" and world.camera.renderer != "egl":
        raise ValueError(
            "renderer: 'egl' needs a world whose camera loaded the EGL plugin "
            "(camera.use_egl: true, and the plugin available)"
        )
    if renderer != "tiny" or s == 1:
        return _render_reference(world, s, renderer)
    plain = _render_reference(world, 1, renderer)
    committed = committed_reference_path(plain, s)
    if committed.is_file():
        with np.load(committed) as stored:
            return stored["image"]
    path = supersampled_cache_path(plain, s)
    with locked(path):
        with contextlib.suppress(OSError, ValueError, KeyError, zipfile.BadZipFile):
            with np.load(path) as stored:
                return stored["image"]
        image = _render_reference(world, s, renderer)
        buffer = io.BytesIO()
        np.savez_compressed(buffer, image=image)
        write_atomic(path, buffer.getvalue())
    return image


def supersampled_cache_path(plain: np.ndarray, supersample: int) -> Path:
    """Where the supersampled TinyRenderer image of a pose is kept: named by a hash of the
    pose's plain TinyRenderer image (the scene, its textures, the camera and the pose all
    show in it), the factor, the code that renders and filters it, and PyBullet's and
    OpenCV's versions."""
    name = _reference_name(plain, supersample, metadata.version("pybullet"), cv2.__version__)
    return cache_dir() / REFERENCE_CACHE_FOLDER / name


def committed_reference_path(plain: np.ndarray, supersample: int) -> Path:
    """Where the committed supersampled TinyRenderer image of a pose is: named as in the
    user cache but for the libraries' versions (a release that renders or filters otherwise
    is caught by the test that renders a committed pose live)."""
    return COMMITTED_REFERENCES / _reference_name(plain, supersample)


def _reference_name(plain: np.ndarray, supersample: int, *versions: str) -> str:
    digest = hashlib.sha256(plain.tobytes())
    for part in (
        repr((plain.shape, plain.dtype.str, int(supersample))),
        inspect.getsource(_render_reference),
        *versions,
    ):
        digest.update(part.encode())
    return f"tiny_x{int(supersample)}_{digest.hexdigest()[:24]}.npz"


def committed_reference_of(world, pose: Pose) -> tuple[Path, np.ndarray]:
    """The committed reference's path of ``pose`` in ``world`` (placed there), and the pose's
    plain TinyRenderer image that names it."""
    place(world, pose)
    plain = _render_reference(world, 1, "tiny")
    return committed_reference_path(plain, COMMITTED_SUPERSAMPLE), plain


def render_supersampled(world, pose: Pose, supersample: int = COMMITTED_SUPERSAMPLE) -> np.ndarray:
    """The supersampled TinyRenderer image of ``pose`` in ``world``, rendered now (neither
    the committed references nor the user cache are read)."""
    place(world, pose)
    return _render_reference(world, int(supersample), "tiny")


def write_committed_references() -> list[Path]:
    """Render the standard poses' supersampled TinyRenderer images into
    :data:`COMMITTED_REFERENCES` (about 40 s of CPU) and remove the files no pose names any
    more; the written paths."""
    worlds = {small: World(render_config(small)) for small in (False, True)}
    written = []
    try:
        for pose in standard_poses():
            world = worlds[uses_small_tag(pose)]
            path, _ = committed_reference_of(world, pose)
            image = render_supersampled(world, pose)
            buffer = io.BytesIO()
            np.savez_compressed(buffer, image=image)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(buffer.getvalue())
            written.append(path)
    finally:
        for world in worlds.values():
            world.close()
    for stale in set(COMMITTED_REFERENCES.glob("tiny_x*.npz")) - set(written):
        stale.unlink()
    return written


def _render_reference(world, s: int, renderer: str) -> np.ndarray:
    k = world.camera.intrinsics
    config = replace(
        world.config.camera,
        mode="project",
        renderer="bullet",
        use_egl=False,
        width=k.width * s,
        height=k.height * s,
        fx=k.fx * s,
        fy=k.fy * s,
        cx=s * (k.cx + 0.5) - 0.5,
        cy=s * (k.cy + 0.5) - 0.5,
        k1=0.0,
        k2=0.0,
        p1=0.0,
        p2=0.0,
        k3=0.0,
    )
    camera = CameraSensor(world.client, config, np.random.default_rng(0))
    camera.renderer = renderer  # the world's client holds the plugin; this camera borrows it
    world._drone_visible(False)
    try:
        big = camera.render_image(*world.camera_pose_w())
    finally:
        world._drone_visible(True)
        camera.close()
    if s == 1:
        return big
    return cv2.resize(big, (k.width, k.height), interpolation=cv2.INTER_AREA)


def planar_image(world) -> np.ndarray:
    """The planar renderer's ideal (pinhole) image of the world's camera pose."""
    camera = world.camera
    if camera.active_renderer != "planar":
        raise RuntimeError("the world's camera has no planar scene attached")
    k = camera.intrinsics
    world._drone_visible(False)
    try:
        return camera._render_canvas(*world.camera_pose_w(), (0, 0, k.width, k.height))
    finally:
        world._drone_visible(True)


def corner_sets(
    world,
    detector: AprilTagDetector,
    pose: Pose,
    references: tuple[tuple[str, int], ...] = (("tiny", 1), ("tiny", 6)),
) -> dict[str, np.ndarray | None]:
    """Tag corners (4x2 px, None if not detected) of ``pose`` by each renderer.

    Keys: "truth" (the analytic projection), "planar", and ``f"{renderer} x{supersample}"``
    for each of ``references`` (see :func:`reference_image`).
    """
    place(world, pose)
    layout = world.config.deck.layout.landmarks[0]
    images = {"planar": planar_image(world)}
    for renderer, supersample in references:
        images[f"{renderer} x{supersample}"] = reference_image(world, supersample, renderer)
    found: dict[str, np.ndarray | None] = {"truth": _truth(world)}
    for name, image in images.items():
        hits = [d for d in detector.detect(image) if d.tag_id == layout.tag_id]
        found[name] = hits[0].corners_px if hits else None
    return found


def _truth(world) -> np.ndarray:
    """The analytic (pinhole) pixels of the posed tag's corners."""
    deck = world.deck_state()
    t_wc, r_wc = world.camera_pose_w()
    layout = world.config.deck.layout.landmarks[0]
    view = world.camera.project_tag(t_wc, r_wc, deck.tag_centre_w, deck.rotation_wd, layout.size)
    return _pinhole(world.camera.intrinsics, view.corners_c)


def compare(world, detector: AprilTagDetector, pose: Pose, supersample: int = 3) -> Agreement:
    """Render ``pose`` with the planar renderer and with the reference; compare."""
    place(world, pose)
    image_planar = planar_image(world)
    image_reference = reference_image(world, supersample)
    layout = world.config.deck.layout.landmarks[0]
    truth = _truth(world)
    found = []
    for image in (image_planar, image_reference):
        hits = [d for d in detector.detect(image) if d.tag_id == layout.tag_id]
        found.append(hits[0].corners_px if hits else None)
    diff = None if found[0] is None or found[1] is None else found[0] - found[1]
    grey = np.abs(image_planar.astype(int) - image_reference.astype(int)).max(axis=2)
    return Agreement(
        pose,
        diff,
        None if found[0] is None else found[0] - truth,
        None if found[1] is None else found[1] - truth,
        float(grey.mean()),
        float((grey > 32).mean()),
    )


def _pinhole(k, corners_c: np.ndarray) -> np.ndarray:
    """Undistorted pixels of camera-frame points (the images compared are ideal)."""
    return k.project(corners_c, distort=False)


def corner_norms(diff: np.ndarray) -> np.ndarray:
    """Per-corner Euclidean differences (pixels)."""
    return np.linalg.norm(diff, axis=1)


@dataclass(frozen=True)
class CornerStatistics:
    """Corner differences pooled over poses: a systematic offset against a spread (pixels)."""

    #: mean Euclidean difference
    mean_px: float
    #: mean difference vector (x, y): what a pixel-centre, row-flip or projection error leaves
    offset_px: np.ndarray
    #: standard deviation per axis (x, y)
    spread_px: np.ndarray
    corners: int
    #: the difference's growth with the distance from the principal point (a focal length,
    #: aspect or image-size error scales the image): d = scale * (p - c) + offset, least
    #: squares over both axes; NaN without the corners' positions
    scale: float = float("nan")


def corner_statistics(
    diffs: list[np.ndarray], positions_px: list[np.ndarray] | None = None, centre_px=None
) -> CornerStatistics:
    """Pool Nx2 corner differences (e.g. planar minus reference over several poses).

    ``positions_px`` (the corners' pixels, e.g. the analytic ones, one array per diff) and
    ``centre_px`` (the principal point) give the radial ``scale`` too.
    """
    d = np.concatenate([np.asarray(x, dtype=float).reshape(-1, 2) for x in diffs])
    scale = float("nan")
    if positions_px is not None:
        r = np.concatenate([np.asarray(x, dtype=float).reshape(-1, 2) for x in positions_px])
        r = r - np.asarray(centre_px, dtype=float)
        # one scale for both axes, one offset per axis
        design = np.zeros((2 * len(r), 3))
        design[: len(r), 0], design[len(r) :, 0] = r[:, 0], r[:, 1]
        design[: len(r), 1] = 1.0
        design[len(r) :, 2] = 1.0
        solution, *_ = np.linalg.lstsq(design, np.concatenate([d[:, 0], d[:, 1]]), rcond=None)
        scale = float(solution[0])
    return CornerStatistics(
        float(corner_norms(d).mean()), d.mean(axis=0), d.std(axis=0), int(d.shape[0]), scale
    )


__all__ = [
    "COMMITTED_REFERENCES",
    "COMMITTED_SUPERSAMPLE",
    "HEIGHTS_M",
    "Agreement",
    "CornerStatistics",
    "Pose",
    "committed_reference_of",
    "committed_reference_path",
    "compare",
    "corner_norms",
    "corner_sets",
    "corner_statistics",
    "place",
    "reference_image",
    "render_config",
    "render_supersampled",
    "standard_poses",
    "supersampled_cache_path",
    "uses_small_tag",
    "write_committed_references",
]


if __name__ == "__main__":
    for written in write_committed_references():
        print(written.relative_to(ROOT))
