"""The landing deck's top plate: its texture (AprilTag, optional colour pads) and its body.

The texture is laid out as the deck seen from above with the bow at the image top and port on
the image left.  Texel ``(row v, column u)`` of an ``N x N`` texture covers the plate point
``x_P = L/2 - (v + 0.5) L/N`` (towards the bow), ``y_P = L/2 - (u + 0.5) L/N`` (towards port).
With ``R_PD = R_BC`` (see :mod:`estimation.frames`) the tag frame's x axis points along the
texture's columns and its y axis down its rows, so the texture *is* the tag frame D seen with
x right and y down, and the tag is drawn in AprilTag's canonical orientation (corner 0
bottom-left).  OpenCV's ``generateImageMarker`` draws AprilTags rotated by 180 degrees
(its detected corner 0 is top-right), so its bit pattern is turned round before use.
With ``landmarks`` set, several tags are drawn, each at its centre ``(x, y)`` in D with D's
axes (nested landmarks, :mod:`estimation.landmarks`); ``tag_id`` and ``tag_size`` then
describe no drawn tag.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import pybullet as p
from pybullet_utils.bullet_client import BulletClient

from estimation.array_files import write_atomic
from estimation.frames import R_PD, tag_corners_in_tag_frame, tof_positions_in_camera_frame
from estimation.landmarks import Landmark, LandmarkLayout
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from landing_env._quiet import client_id
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.resources import cache_dir

#: AprilTag family of the deck; the only one OpenCV and pupil-apriltags both provide here.
TAG_FAMILY = "tag36h11"

#: Cells across a tag36h11 tag including its black border (the data bits are 6 x 6).
TAG_CELLS = 8

#: Pad colours in RGB, in sensor order ps1..ps4 (IHRCF Sec. 2.2: blue, green, yellow, red).
#: Green is dark enough (Y ~ 94) not to pass IHRCF Table 1's yellow thresholds as well.
PAD_COLOURS_RGB: tuple[tuple[int, int, int], ...] = (
    (0, 0, 255),
    (0, 160, 0),
    (255, 255, 0),
    (255, 0, 0),
)
PAD_NAMES: tuple[str, ...] = ("blue", "green", "yellow", "red")

#: Bump when the generated files change so old cache entries are not reused.
_ASSET_VERSION = 1

#: Where generated meshes and textures are cached: the user cache directory, never the
#: installed package (``DECK_LANDING_CACHE_DIR`` overrides it; see landing_env/resources.py).
GENERATED_DIR = cache_dir() / f"assets-v{_ASSET_VERSION}"


def default_pad_centres_p() -> tuple[tuple[float, float], ...]:
    """Pad centres in P (x, y): the ToF touch points of a level drone centred over a level deck.

    A level, zero-yaw drone sees ``R_CD = I``, so a sensor at ``(x, y)`` in C touches the deck
    at ``(x, y)`` in D, which is ``R_PD (x, y, 0)`` in P.
    """
    sensors_c = tof_positions_in_camera_frame()
    points_p = (R_PD @ sensors_c.T).T
    return tuple((float(px), float(py)) for px, py, _ in points_p)


@dataclass
class DeckSurfaceConfig:
    """The deck's top plate and what is drawn on it."""

    #: edge of the square plate, metres
    size: float = limited(1.0, POSITIVE, physical=Limit.positive(1e3))
    #: plate thickness, metres (the body's frame is the centre of the *top* surface)
    thickness: float = limited(0.03, POSITIVE, physical=Limit.positive(10.0))
    #: AprilTag family (fixed: OpenCV draws it, pupil-apriltags detects it)
    tag_family: str = TAG_FAMILY
    tag_id: int = limited(0, Limit(0, 586))
    #: edge of the tag's black border, metres (pupil-apriltags' ``tag_size``)
    tag_size: float = limited(0.30, POSITIVE, physical=Limit.positive(1e3))
    #: draw the tag; with pads on the tag may be left out, as pads sit on its area
    tag: bool = True
    #: width of the white quiet zone round the tag, in tag cells (tag_size / 8)
    quiet_zone_cells: float = limited(1.0, NON_NEGATIVE, physical=Limit.non_negative(100.0))
    #: texels across the plate
    texture_px: int = limited(1024, Limit(16, 8192))
    #: plate colour, RGB 0-255 (neutral grey fails every IHRCF Table 1 pad threshold)
    deck_rgb: tuple[int, int, int] = (110, 110, 110)
    #: coloured ToF calibration pads (IHRCF Sec. 2.2), drawn over the tag
    pads: bool = False
    #: pad radius, metres
    pad_radius: float = limited(0.04, physical=Limit.positive(10.0))
    #: pad centres (x, y) in P in sensor order ps1..ps4; None = the ToF touch points
    pad_centres_p: tuple[tuple[float, float], ...] | None = None
    #: nested landmarks (tag_id, size, x, y in D; see estimation.landmarks) drawn instead of
    #: the single centred tag (tag_id, tag_size); empty = the single tag
    landmarks: tuple[Landmark, ...] = ()

    def __post_init__(self) -> None:
        require_limits(self)
        require_choice("tag_family", self.tag_family, (TAG_FAMILY,))
        # tag36h11 has 587 codes
        outer = self.tag_size * (TAG_CELLS + 2 * self.quiet_zone_cells) / TAG_CELLS
        if outer > self.size:
            raise ConfigError(
                "tag_size",
                f"{self.tag_size} m with its quiet zone (quiet_zone_cells = "
                f"{self.quiet_zone_cells}: {outer:.3f} m) does not fit on the deck (size = "
                f"{self.size} m); allowed tag_size <= "
                f"{self.size * TAG_CELLS / (TAG_CELLS + 2 * self.quiet_zone_cells):.3f} m",
            )
        if self.landmarks:
            try:
                self.layout.check_fits(self.size)
            except ConfigError as exc:
                raise exc.under("") from None
        if len(self.deck_rgb) != 3 or any(not 0 <= c <= 255 for c in self.deck_rgb):
            raise ConfigError("deck_rgb", f"{self.deck_rgb!r}: need three values in [0, 255]")
        require_range(
            "pad_radius",
            self.pad_radius,
            0.0,
            0.5 * self.size,
            low_inclusive=False,
            bounds_from=f"size = {self.size}",
        )
        if self.pad_centres_p is not None:
            if len(self.pad_centres_p) != len(PAD_COLOURS_RGB):
                raise ConfigError(
                    "pad_centres_p", f"need {len(PAD_COLOURS_RGB)} (x, y) centres or None"
                )
            half = 0.5 * self.size
            for x, y in self.pad_centres_p:
                if abs(x) > half or abs(y) > half:
                    raise ConfigError(
                        "pad_centres_p", f"({x}, {y}) is off the deck; allowed |x|, |y| <= {half}"
                    )

    @property
    def pad_centres(self) -> tuple[tuple[float, float], ...]:
        """Pad centres (x, y) in P actually used."""
        return default_pad_centres_p() if self.pad_centres_p is None else self.pad_centres_p

    @property
    def metres_per_texel(self) -> float:
        return self.size / self.texture_px

    @property
    def layout(self) -> LandmarkLayout:
        """The tags on the deck: the landmarks, or the single centred tag."""
        if self.landmarks:
            return LandmarkLayout(tuple(self.landmarks), self.quiet_zone_cells)
        return LandmarkLayout.single(self.tag_id, self.tag_size, self.quiet_zone_cells)


def opencv_tag_bits(tag_id: int) -> np.ndarray:
    """The 8x8 tag36h11 cells (1 = white) in AprilTag's canonical orientation.

    OpenCV's marker image is AprilTag's canonical image turned by 180 degrees (measured: its
    detected corner 0 is top-right, canonical corner 0 is bottom-left), so turn it back.
    """
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    marker = cv2.aruco.generateImageMarker(dictionary, tag_id, TAG_CELLS, borderBits=1)
    return np.rot90(marker > 127, 2).astype(float)


def _coverage(texels: int, length: float, edges: np.ndarray) -> np.ndarray:
    """Fraction of each texel (along one axis of ``length`` metres) inside each interval.

    ``edges`` are the interval boundaries measured from the texture's first edge; returns a
    ``texels x (len(edges) - 1)`` matrix whose rows sum to the covered fraction.
    """
    texel = length / texels
    lo = np.arange(texels)[:, None] * texel
    hi = lo + texel
    overlap = np.minimum(hi, edges[None, 1:]) - np.maximum(lo, edges[None, :-1])
    return np.clip(overlap, 0.0, None) / texel


def make_deck_texture(config: DeckSurfaceConfig) -> np.ndarray:
    """The plate's RGB texture (``texture_px`` square, uint8), laid out as the module describes.

    The tag (with its white quiet zone) is area-averaged onto the texels, so its edges are at
    their exact metric positions to a fraction of a texel.
    """
    n = config.texture_px
    image = np.empty((n, n, 3), dtype=np.uint8)
    image[:] = np.asarray(config.deck_rgb, dtype=np.uint8)
    if config.tag:
        for landmark in config.layout.landmarks:
            _draw_tag(image, config, landmark)
    if config.pads:
        _draw_pads(image, config)
    return image


def _draw_tag(image: np.ndarray, config: DeckSurfaceConfig, landmark: Landmark) -> None:
    """Area-average one tag with its quiet zone onto the texels it covers (in place)."""
    n = config.texture_px
    # cells of the tag plus quiet zone, white = 1; the quiet zone may be a fraction of a cell
    bits = np.pad(opencv_tag_bits(landmark.tag_id), 1, constant_values=1.0)
    cell = landmark.size / TAG_CELLS
    inner = (np.arange(TAG_CELLS + 1) - TAG_CELLS / 2) * cell
    quiet = config.quiet_zone_cells * cell
    local = np.concatenate([[inner[0] - quiet], inner, [inner[-1] + quiet]])
    # boundaries along x_D (texture columns) and y_D (rows), from the texture's edge
    cover_u = _coverage(n, config.size, local + landmark.x + config.size / 2)
    cover_v = _coverage(n, config.size, local + landmark.y + config.size / 2)
    inside_u, inside_v = cover_u.sum(axis=1), cover_v.sum(axis=1)
    # only the block of texels the tag touches is blended (a large texture in float is big)
    cols, rows = np.flatnonzero(inside_u > 0.0), np.flatnonzero(inside_v > 0.0)
    if cols.size == 0 or rows.size == 0:
        return
    u0, u1, v0, v1 = cols[0], cols[-1] + 1, rows[0], rows[-1] + 1
    cover_u, cover_v = cover_u[u0:u1], cover_v[v0:v1]
    # per-texel area fractions: white and covered-by-tag-square
    white = cover_v @ bits @ cover_u.T
    covered = np.outer(inside_v[v0:v1], inside_u[u0:u1])
    block = image[v0:v1, u0:u1].astype(float)
    block = block * (1.0 - covered)[..., None] + 255.0 * white[..., None]
    image[v0:v1, u0:u1] = np.clip(np.rint(block), 0, 255).astype(np.uint8)


def plate_to_texel(config: DeckSurfaceConfig, points_p: np.ndarray) -> np.ndarray:
    """Map Nx2 plate points (x_P, y_P) to Nx2 texel coordinates (column u, row v)."""
    points_p = np.atleast_2d(np.asarray(points_p, dtype=float))
    scale = config.texture_px / config.size
    u = (0.5 * config.size - points_p[:, 1]) * scale - 0.5
    v = (0.5 * config.size - points_p[:, 0]) * scale - 0.5
    return np.column_stack([u, v])


def _draw_pads(image: np.ndarray, config: DeckSurfaceConfig) -> None:
    """Draw the four filled calibration discs (anti-aliased, sub-texel centres)."""
    shift = 4  # cv2 fixed-point bits for sub-pixel centres
    factor = 1 << shift
    centres = plate_to_texel(config, np.asarray(config.pad_centres))
    radius = config.pad_radius / config.metres_per_texel
    for (u, v), colour in zip(centres, PAD_COLOURS_RGB, strict=True):
        cv2.circle(
            image,
            (round(u * factor), round(v * factor)),
            round(radius * factor),
            colour,
            thickness=-1,
            lineType=cv2.LINE_AA,
            shift=shift,
        )


def tag_corners_p(tag_size: float) -> np.ndarray:
    """The 4x3 tag corners in the plate frame P, in detection order."""
    return (R_PD @ tag_corners_in_tag_frame(tag_size).T).T


def tag_corners_w(tag_size: float, t_wp: np.ndarray, r_wp: np.ndarray) -> np.ndarray:
    """The 4x3 tag corners in the world, given the plate pose (t_wp, r_wp)."""
    return np.asarray(t_wp, dtype=float) + (np.asarray(r_wp) @ tag_corners_p(tag_size).T).T


def tag_pose_w(t_wp: np.ndarray, r_wp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tag frame D in the world ``(t_wd, r_wd)`` from the plate pose (tag at the centre)."""
    return np.asarray(t_wp, dtype=float).copy(), np.asarray(r_wp) @ R_PD


def _config_key(config: DeckSurfaceConfig) -> str:
    """A short hash of everything that changes the generated files."""
    text = repr((_ASSET_VERSION, sorted(asdict(config).items()), config.pad_centres))
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def _deck_obj(config: DeckSurfaceConfig) -> str:
    """An OBJ box in P (top face at z = 0) whose top face maps the whole texture.

    The OBJ's v coordinate grows towards the image top (OpenGL convention), so the bow edge
    (texture row 0) has v = 1.  Sides and bottom sample one texel at the texture's corner,
    which holds the plate colour.
    """
    h = 0.5 * config.size
    z = -config.thickness
    e = 0.5 / config.texture_px  # centre of the corner texel
    lines = [
        "# deck top plate, generated by landing_env.scene.deck",
        f"v {h} {h} 0",  # 1 bow-port top
        f"v {-h} {h} 0",  # 2 stern-port top
        f"v {-h} {-h} 0",  # 3 stern-starboard top
        f"v {h} {-h} 0",  # 4 bow-starboard top
        f"v {h} {h} {z}",  # 5
        f"v {-h} {h} {z}",  # 6
        f"v {-h} {-h} {z}",  # 7
        f"v {h} {-h} {z}",  # 8
        "vt 0 1",  # 1 bow-port: texture top-left
        "vt 0 0",  # 2 stern-port: bottom-left
        "vt 1 0",  # 3 stern-starboard: bottom-right
        "vt 1 1",  # 4 bow-starboard: top-right
        f"vt {e} {1 - e}",  # 5 plate-colour texel
        "vn 0 0 1",
        "vn 0 0 -1",
        "vn 1 0 0",
        "vn -1 0 0",
        "vn 0 1 0",
        "vn 0 -1 0",
        # faces counter-clockwise seen from outside
        "f 1/1/1 2/2/1 3/3/1",
        "f 1/1/1 3/3/1 4/4/1",
        "f 5/5/2 8/5/2 7/5/2",
        "f 5/5/2 7/5/2 6/5/2",
        "f 1/5/3 4/5/3 8/5/3",
        "f 1/5/3 8/5/3 5/5/3",
        "f 3/5/4 2/5/4 6/5/4",
        "f 3/5/4 6/5/4 7/5/4",
        "f 2/5/5 1/5/5 5/5/5",
        "f 2/5/5 5/5/5 6/5/5",
        "f 4/5/6 3/5/6 7/5/6",
        "f 4/5/6 7/5/6 8/5/6",
    ]
    return "\n".join(lines) + "\n"


def deck_asset_files(config: DeckSurfaceConfig, cache_dir: Path | None = None) -> tuple[Path, Path]:
    """Write (once) and return the deck's OBJ mesh and PNG texture, keyed by the config."""
    directory = GENERATED_DIR if cache_dir is None else Path(cache_dir)
    key = _config_key(config)
    obj_path = directory / f"deck_{key}.obj"
    png_path = directory / f"deck_{key}.png"
    if not png_path.is_file():
        rgb = make_deck_texture(config)
        ok, encoded = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        if not ok:
            raise RuntimeError(f"could not encode the deck texture for {png_path}")
        write_atomic(png_path, encoded.tobytes())
    if not obj_path.is_file():
        write_atomic(obj_path, _deck_obj(config).encode())
    return obj_path, png_path


def create_deck_body(
    client: int | BulletClient,
    config: DeckSurfaceConfig,
    mass: float,
    position_w: np.ndarray,
    orientation_xyzw: np.ndarray,
    cache_dir: Path | None = None,
) -> int:
    """Create the plate as a dynamic body whose base frame is P; return its body id.

    The collision box is shifted down by half the thickness so the frame sits at the centre
    of the top surface; the visual is the textured OBJ box.
    """
    if mass <= 0.0:
        raise ValueError(f"mass must be > 0 for a dynamic deck body, got {mass}")
    client = client_id(client)
    obj_path, png_path = deck_asset_files(config, cache_dir)
    half = 0.5 * config.size
    collision = p.createCollisionShape(
        p.GEOM_BOX,
        halfExtents=[half, half, 0.5 * config.thickness],
        collisionFramePosition=[0.0, 0.0, -0.5 * config.thickness],
        physicsClientId=client,
    )
    visual = p.createVisualShape(
        p.GEOM_MESH,
        fileName=str(obj_path),
        meshScale=[1.0, 1.0, 1.0],
        rgbaColor=[1.0, 1.0, 1.0, 1.0],
        physicsClientId=client,
    )
    body = p.createMultiBody(
        baseMass=mass,
        baseCollisionShapeIndex=collision,
        baseVisualShapeIndex=visual,
        basePosition=list(np.asarray(position_w, dtype=float)),
        baseOrientation=list(np.asarray(orientation_xyzw, dtype=float)),
        physicsClientId=client,
    )
    texture = p.loadTexture(str(png_path), physicsClientId=client)
    p.changeVisualShape(
        body, -1, textureUniqueId=texture, rgbaColor=[1, 1, 1, 1], physicsClientId=client
    )
    return body
