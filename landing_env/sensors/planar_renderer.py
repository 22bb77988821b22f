"""A fast renderer of a downward camera's view: textured planes by homography, solids by polygons.

Why: PyBullet's TinyRenderer rasterises on the CPU at a cost that grows with the screen area
of its triangles, so it slows down tenfold as the drone nears the deck (the deck then fills
the image); a landing's final approach ran at a tenth of real time.  A downward camera sees
mostly *planes*: the deck's top with its tag (a texture), the sea or floor, the platform's
base plate.  A plane's image is a homography of its texture, which OpenCV warps in about a
millisecond whatever its size on screen.

What is drawn, far to near (painter's order by the distance of each clipped face's centroid
from the camera, which is exact for this scene of disjoint convex bodies seen from above):

- the top face of each registered textured plate (:class:`TexturedPlate`, the deck) as a
  homography warp of a mip level of its texture (levels pre-filtered by ``cv2.INTER_AREA``,
  the level chosen so that one texel spans about one pixel: no aliasing at altitude, full
  detail near the deck), its edge anti-aliased by the warp's bilinear alpha;
- every other visible face of boxes and cylinders (cylinders as 12-sided prisms), the plate's
  sides included, as anti-aliased flat-shaded convex polygons clipped to the view frustum.

Shading follows TinyRenderer's (``int(albedo * (ambient + diffuse * max(n.l, 0)))``, its
default light direction for a z-up world), so the images agree with the reference to a grey
level or so; :mod:`landing_env.sensors.camera_render` keeps TinyRenderer (or EGL) as the
reference renderer, and tests compare the two (tag corners and images).  Mesh bodies other than
the registered plates cannot be drawn; the camera then falls back to the reference renderer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import pybullet as p

#: TinyRenderer's default light direction in a z-up world (towards the light), normalised.
TINY_LIGHT_DIR_W = np.array([-50.0, 30.0, 100.0]) / np.linalg.norm([-50.0, 30.0, 100.0])

#: fixed-point bits for sub-pixel polygon vertices (cv2.fillConvexPoly ``shift``)
_SHIFT = 4

#: sides of the prism that stands in for a cylinder
_CYLINDER_SIDES = 12

#: drawn where no surface is hit (TinyRenderer's clear colour)
BACKGROUND_RGB = (255, 255, 255)


class UnsupportedScene(RuntimeError):
    """The scene holds a shape the planar renderer cannot draw (a mesh not registered)."""


@dataclass(frozen=True)
class TexturedPlate:
    """A box body whose top face (z = 0 of its frame) carries a texture.

    Texel ``(row v, column u)`` of the ``N x N`` texture covers the plate point
    ``x = L/2 - (v + 0.5) L/N``, ``y = L/2 - (u + 0.5) L/N`` (the deck's layout, see
    :mod:`landing_env.scene.deck`); the sides and bottom have the colour ``side_rgb``.
    """

    body_id: int
    size: float
    thickness: float
    texture_rgb: np.ndarray
    side_rgb: tuple[int, int, int]


@dataclass
class _Solid:
    """A flat-shaded convex solid of one body: faces in its link frame."""

    body_id: int
    link: int
    #: local frame of the shape in the link frame (position, 3x3 rotation)
    offset: np.ndarray
    rotation: np.ndarray
    #: F x V x 3 face vertices (local), F x 3 outward normals (local)
    faces: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray
    radius: float


def _box_faces(half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The six faces (counter-clockwise seen from outside) and normals of a box."""
    hx, hy, hz = half
    corners = np.array(
        [[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    )
    index = {
        (sx, sy, sz): i
        for i, (sx, sy, sz) in enumerate(
            [(sx, sy, sz) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
        )
    }
    faces, normals = [], []
    for axis in range(3):
        for sign in (-1, 1):
            others = [a for a in range(3) if a != axis]
            ring = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
            quad = []
            for a, b in ring:
                key = [0, 0, 0]
                key[axis], key[others[0]], key[others[1]] = sign, a, b
                quad.append(corners[index[tuple(key)]])
            normal = np.zeros(3)
            normal[axis] = sign
            faces.append(np.array(quad))
            normals.append(normal)
    return np.array(faces), np.array(normals)


def _cylinder_faces(length: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Side quads of a prism along z (the caps are left to :func:`_cap_faces`)."""
    angles = np.linspace(0.0, 2.0 * math.pi, _CYLINDER_SIDES + 1)
    ring = np.column_stack([np.cos(angles), np.sin(angles)]) * radius
    h = 0.5 * length
    faces, normals = [], []
    for i in range(_CYLINDER_SIDES):
        a, b = ring[i], ring[i + 1]
        faces.append([[a[0], a[1], -h], [b[0], b[1], -h], [b[0], b[1], h], [a[0], a[1], h]])
        mid = 0.5 * (angles[i] + angles[i + 1])
        normals.append([math.cos(mid), math.sin(mid), 0.0])
    # caps as polygons padded to 4 vertices is not possible: keep them apart
    return np.array(faces), np.array(normals)


def _cap_faces(length: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    angles = np.linspace(0.0, 2.0 * math.pi, _CYLINDER_SIDES, endpoint=False)
    ring = np.column_stack([np.cos(angles), np.sin(angles)]) * radius
    h = 0.5 * length
    top = np.column_stack([ring, np.full(len(ring), h)])
    bottom = np.column_stack([ring[::-1], np.full(len(ring), -h)])
    return np.array([top, bottom]), np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])


def _rotation(quaternion_xyzw) -> np.ndarray:
    return np.asarray(p.getMatrixFromQuaternion(quaternion_xyzw)).reshape(3, 3)


def _clip(polygon: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: keep the part of a convex polygon with ``n.x + d >= 0`` for all."""
    for plane in planes:
        if len(polygon) == 0:
            break
        dist = polygon @ plane[:3] + plane[3]
        if np.all(dist >= 0.0):
            continue
        if np.all(dist < 0.0):
            return polygon[:0]
        out = []
        n = len(polygon)
        for i in range(n):
            a, b = polygon[i], polygon[(i + 1) % n]
            da, db = dist[i], dist[(i + 1) % n]
            if da >= 0.0:
                out.append(a)
            if (da >= 0.0) != (db >= 0.0):
                out.append(a + (b - a) * (da / (da - db)))
        polygon = np.array(out) if out else polygon[:0]
    return polygon


def _mip_levels(texture: np.ndarray) -> list[np.ndarray]:
    """RGBA texture levels, each half the previous (area-averaged), down to 8 texels."""
    rgba = np.dstack([texture, np.full(texture.shape[:2], 255, dtype=np.uint8)])
    levels = [rgba]
    while min(levels[-1].shape[:2]) >= 16:
        h, w = levels[-1].shape[:2]
        levels.append(cv2.resize(levels[-1], (w // 2, h // 2), interpolation=cv2.INTER_AREA))
    return levels


class PlanarScene:
    """The drawable contents of a PyBullet client, read once; poses are read at each render."""

    def __init__(
        self,
        client: int,
        plates: tuple[TexturedPlate, ...] = (),
        hidden_bodies: tuple[int, ...] = (),
        ambient: float = 0.6,
        diffuse: float = 0.4,
    ) -> None:
        self.client = client
        self.plates = plates
        self.ambient = ambient
        self.diffuse = diffuse
        self._hidden = set(hidden_bodies)
        self._plate_levels = {plate.body_id: _mip_levels(plate.texture_rgb) for plate in plates}
        self._solids: list[_Solid] = []
        self._body_count = -1
        self._read()

    def _read(self) -> None:
        """Turn every visible box and cylinder into faces; refuse unregistered meshes."""
        c = self.client
        plates = {plate.body_id: plate for plate in self.plates}
        solids: list[_Solid] = []
        for plate in self.plates:
            half = np.array([0.5 * plate.size, 0.5 * plate.size, 0.5 * plate.thickness])
            faces, normals = _box_faces(half)
            keep = normals[:, 2] < 0.5  # the top face is the textured one
            solids.append(
                _Solid(
                    plate.body_id,
                    -1,
                    np.array([0.0, 0.0, -0.5 * plate.thickness]),
                    np.eye(3),
                    faces[keep],
                    normals[keep],
                    np.asarray(plate.side_rgb, dtype=float),
                    float(np.linalg.norm(half)),
                )
            )
        count = p.getNumBodies(physicsClientId=c)
        for index in range(count):
            body = p.getBodyUniqueId(index, physicsClientId=c)
            if body in self._hidden or body in plates:
                continue
            for shape in p.getVisualShapeData(body, physicsClientId=c):
                link, kind, dims, rgba = shape[1], shape[2], shape[3], shape[7]
                if rgba[3] <= 0.0:
                    continue
                # TinyRenderer turns the colour to bytes before shading
                albedo = np.floor(np.asarray(rgba[:3], dtype=np.float32) * 255.0).astype(float)
                if kind == p.GEOM_BOX:
                    half = 0.5 * np.asarray(dims, dtype=float)
                    # (faces, normals, bounding radius) of each solid the shape is drawn as
                    parts = [(*_box_faces(half), float(np.linalg.norm(half)))]
                elif kind == p.GEOM_CYLINDER:
                    length, r = float(dims[0]), float(dims[1])
                    radius = math.hypot(0.5 * length, r)
                    caps, side = _cap_faces(length, r), _cylinder_faces(length, r)
                    parts = [(*caps, radius), (*side, radius)]
                else:
                    raise UnsupportedScene(
                        f"body {body} link {link} has a visual shape of type {kind} "
                        "(only boxes, cylinders and registered textured plates are drawn)"
                    )
                for faces, normals, radius in parts:
                    position, rotation = np.asarray(shape[5], dtype=float), _rotation(shape[6])
                    solids.append(
                        _Solid(body, link, position, rotation, faces, normals, albedo, radius)
                    )
        self._solids = solids
        self._body_count = count
        self._colours = self._colour_key()

    def _colour_key(self) -> tuple:
        """Every drawn body's visual colours (changeVisualShape may recolour them)."""
        c = self.client
        bodies = {solid.body_id for solid in self._solids} - {
            plate.body_id for plate in self.plates
        }
        return tuple(
            tuple(shape[7] for shape in p.getVisualShapeData(body, physicsClientId=c))
            for body in sorted(bodies)
        )

    def refresh_if_changed(self) -> None:
        """Read the scene again if bodies were added or removed or recoloured."""
        if (
            p.getNumBodies(physicsClientId=self.client) != self._body_count
            or self._colour_key() != self._colours
        ):
            self._read()

    def shade(self, normal_w: np.ndarray) -> float:
        """TinyRenderer's Lambert factor for a face with this world normal."""
        return self.ambient + self.diffuse * max(float(normal_w @ TINY_LIGHT_DIR_W), 0.0)

    def _pose(self, body: int, link: int) -> tuple[np.ndarray, np.ndarray]:
        c = self.client
        if link < 0:
            position, orientation = p.getBasePositionAndOrientation(body, physicsClientId=c)
        else:
            state = p.getLinkState(body, link, physicsClientId=c)
            position, orientation = state[4], state[5]
        return np.asarray(position, dtype=float), _rotation(orientation)

    def render(
        self,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        k_window: np.ndarray,
        width: int,
        height: int,
        near: float,
        far: float,
    ) -> np.ndarray:
        """An ideal pinhole image (HxWx3 uint8 RGB) of a window; ``k_window`` is its 3x3 K.

        Pixel (u, v) of the window sees the ray ``K^-1 (u, v, 1)`` (OpenCV convention:
        pixel centres at integers), so a window's pixels equal those of the full image.
        """
        t_wc = np.asarray(t_wc, dtype=float)
        r_wc = np.asarray(r_wc, dtype=float)
        r_cw = r_wc.T
        k = np.asarray(k_window, dtype=float)
        image = np.empty((height, width, 3), dtype=np.uint8)
        image[:] = BACKGROUND_RGB
        planes = self._frustum_planes(k, width, height, near, far)
        # a plate that fills the whole window hides everything behind its plane (a tag window
        # near the deck): those faces are culled (n.x + d < 0 in camera coordinates)
        hiders = self._covering_plates(t_wc, r_wc, k, width, height)
        # (distance, kind, payload): polygons and textured plates, drawn far to near
        items: list[tuple[float, int, object]] = []
        for solid in self._solids:
            position, rotation = self._pose(solid.body_id, solid.link)
            centre_w = position + rotation @ solid.offset
            centre_c = r_cw @ (centre_w - t_wc)
            if not _sphere_in_frustum(centre_c, solid.radius, planes):
                continue
            if any(h[:3] @ centre_c + h[3] < -solid.radius for h in hiders):
                continue
            r_cs = r_cw @ rotation @ solid.rotation
            normals_c = solid.normals @ r_cs.T
            faces_c = centre_c + solid.faces @ r_cs.T
            # front faces only: the normal points towards the camera (at the origin)
            front = np.einsum("fj,fj->f", normals_c, faces_c[:, 0]) < 0.0
            if not np.any(front):
                continue
            faces_c, normals_c = faces_c[front], normals_c[front]
            dist = faces_c @ planes[:, :3].T + planes[:, 3]  # F x V x planes
            inside = np.all(dist >= 0.0, axis=(1, 2))
            outside = np.any(np.all(dist < 0.0, axis=1), axis=1)
            for h in hiders:
                outside |= np.all(faces_c @ h[:3] + h[3] <= 1e-9, axis=1)
            shades = self.ambient + self.diffuse * np.maximum(
                normals_c @ (r_cw @ TINY_LIGHT_DIR_W), 0.0
            )
            for face_c, shade, whole, gone in zip(faces_c, shades, inside, outside, strict=True):
                if gone:
                    continue
                polygon = face_c if whole else _clip(face_c, planes)
                if len(polygon) < 3:
                    continue
                colour = np.floor(solid.albedo * shade)
                distance = float(np.linalg.norm(polygon.mean(axis=0)))
                items.append((distance, 0, (polygon, colour)))
        for plate in self.plates:
            position, rotation = self._pose(plate.body_id, -1)
            h = 0.5 * plate.size
            corners_w = (
                position + np.array([[h, h, 0], [-h, h, 0], [-h, -h, 0], [h, -h, 0]]) @ rotation.T
            )
            if rotation[:, 2] @ (t_wc - position) <= 0.0:
                continue  # seen from below
            polygon = _clip((corners_w - t_wc) @ r_wc, planes)
            if len(polygon) < 3:
                continue
            distance = float(np.linalg.norm(polygon.mean(axis=0)))
            items.append((distance, 1, (plate, position, rotation, polygon)))
        items.sort(key=lambda item: -item[0])
        for _, kind, payload in items:
            if kind == 0:
                polygon, colour = payload  # type: ignore[misc]
                _fill(image, k, polygon, colour)
            else:
                self._draw_plate(image, k, t_wc, r_wc, *payload)  # type: ignore[misc]
        return image

    def _covering_plates(
        self, t_wc: np.ndarray, r_wc: np.ndarray, k: np.ndarray, width: int, height: int
    ) -> list[np.ndarray]:
        """Planes (n, d) in camera coordinates, towards the camera positive, of the plates
        that cover every pixel of the window (seen from above, one pixel of margin)."""
        hiders = []
        rays_c = _window_corner_rays(k, width, height)
        for plate in self.plates:
            position, rotation = self._pose(plate.body_id, -1)
            normal_c = r_wc.T @ rotation[:, 2]
            point_c = r_wc.T @ (position - t_wc)
            towards = float(normal_c @ point_c)  # < 0: the camera is on the top side
            if towards >= 0.0:
                continue
            denominators = rays_c @ normal_c
            if np.any(denominators >= 0.0):
                continue  # a corner ray runs parallel or away from the plane
            hits_c = rays_c * (towards / denominators)[:, None]
            local = (hits_c - point_c) @ (r_wc.T @ rotation)
            half = 0.5 * plate.size
            if np.all(np.abs(local[:, :2]) < half):
                hiders.append(np.append(normal_c, -towards))
        return hiders

    def _draw_plate(
        self,
        image: np.ndarray,
        k: np.ndarray,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        plate: TexturedPlate,
        position: np.ndarray,
        rotation: np.ndarray,
        polygon_c: np.ndarray,
    ) -> None:
        n = plate.texture_rgb.shape[0]
        s = plate.size / n
        half = 0.5 * plate.size
        # texel (u, v, 1) -> plate (x, y, 1)
        texel_to_plate = np.array([[0.0, -s, half - 0.5 * s], [-s, 0.0, half - 0.5 * s], [0, 0, 1]])
        r_cp = r_wc.T @ rotation
        t_cp = r_wc.T @ (position - t_wc)
        plate_to_pixel = k @ np.column_stack([r_cp[:, 0], r_cp[:, 1], t_cp])
        h0 = plate_to_pixel @ texel_to_plate
        # mip level: texels per pixel where the plate is seen (its clipped centroid)
        centre = k @ polygon_c.mean(axis=0)
        centre = centre[:2] / centre[2]
        inverse = np.linalg.inv(h0)
        samples = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]) + centre
        texels = np.column_stack([samples, np.ones(3)]) @ inverse.T
        texels = texels[:, :2] / texels[:, 2:3]
        footprint = max(
            float(np.linalg.norm(texels[1] - texels[0])),
            float(np.linalg.norm(texels[2] - texels[0])),
        )
        levels = self._plate_levels[plate.body_id]
        level = int(np.clip(round(math.log2(max(footprint, 1e-9))), 0, len(levels) - 1))
        scale = 2.0**level
        level_to_texel = np.array(
            [[scale, 0, 0.5 * scale - 0.5], [0, scale, 0.5 * scale - 0.5], [0, 0, 1]]
        )
        homography = h0 @ level_to_texel
        # only the plate's bounding box of the image is warped
        pixels = polygon_c @ k.T
        pixels = pixels[:, :2] / pixels[:, 2:3]
        height, width = image.shape[:2]
        x0 = max(math.floor(pixels[:, 0].min()) - 1, 0)
        y0 = max(math.floor(pixels[:, 1].min()) - 1, 0)
        x1 = min(math.ceil(pixels[:, 0].max()) + 2, width)
        y1 = min(math.ceil(pixels[:, 1].max()) + 2, height)
        if x1 <= x0 or y1 <= y0:
            return
        shift = np.array([[1.0, 0, -x0], [0, 1.0, -y0], [0, 0, 1]])
        warped = cv2.warpPerspective(
            levels[level],
            shift @ homography,
            (x1 - x0, y1 - y0),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=(0, 0, 0, 0),
        )
        # TinyRenderer truncates the shaded colour: round(x * shade - 0.5) = floor
        shaded = cv2.convertScaleAbs(
            cv2.cvtColor(warped, cv2.COLOR_RGBA2RGB), alpha=self.shade(rotation[:, 2]), beta=-0.5
        )
        region = image[y0:y1, x0:x1]
        alpha = warped[..., 3]
        if int(alpha.min()) == 255:
            region[:] = shaded
            return
        weight = alpha.astype(np.float32) * np.float32(1.0 / 255.0)
        region[:] = cv2.blendLinear(shaded, np.ascontiguousarray(region), weight, 1.0 - weight)

    @staticmethod
    def _frustum_planes(
        k: np.ndarray, width: int, height: int, near: float, far: float
    ) -> np.ndarray:
        """Planes (n, d) with n.x + d >= 0 inside: near, far and the window's four sides
        (one pixel beyond, so anti-aliased edges are drawn)."""
        rays = _window_corner_rays(k, width, height)
        planes = [np.array([0.0, 0.0, 1.0, -near]), np.array([0.0, 0.0, -1.0, far])]
        for i in range(4):
            normal = np.cross(rays[i], rays[(i + 1) % 4])
            normal /= np.linalg.norm(normal)
            planes.append(np.append(normal, 0.0))
        return np.array(planes)


def _window_corner_rays(k: np.ndarray, width: int, height: int) -> np.ndarray:
    """Rays (z = 1 in C) through the corners of a ``width`` x ``height`` window, one pixel
    beyond its edge."""
    corners = np.array(
        [
            [-1.5, -1.5, 1],
            [width + 0.5, -1.5, 1],
            [width + 0.5, height + 0.5, 1],
            [-1.5, height + 0.5, 1],
        ]
    )
    return corners @ np.linalg.inv(k).T


def _sphere_in_frustum(centre_c: np.ndarray, radius: float, planes: np.ndarray) -> bool:
    return bool(np.all(planes[:, :3] @ centre_c + planes[:, 3] >= -radius))


def _fill(image: np.ndarray, k: np.ndarray, polygon_c: np.ndarray, colour: np.ndarray) -> None:
    pixels = polygon_c @ k.T
    pixels = pixels[:, :2] / pixels[:, 2:3]
    # OpenCV's fixed-point polygon fill puts pixel centres at integers, as K does
    points = np.rint(pixels * (1 << _SHIFT)).astype(np.int32)
    cv2.fillConvexPoly(image, points, tuple(float(c) for c in colour), cv2.LINE_AA, _SHIFT)


def planar_scene_or_none(
    client: int,
    camera,
    deck_body: int,
    deck,
    deck_texture: np.ndarray,
    hidden_bodies: tuple[int, ...] = (),
) -> PlanarScene | None:
    """The planar scene of a world with one textured deck, or None (and a warning) when the
    world holds shapes it cannot draw.  ``camera`` is a CameraConfig, ``deck`` a
    DeckSurfaceConfig (duck-typed to keep this module free of the config modules)."""
    import warnings

    plate = TexturedPlate(
        deck_body, deck.size, deck.thickness, deck_texture, tuple(int(c) for c in deck.deck_rgb)
    )
    try:
        return PlanarScene(
            client,
            plates=(plate,),
            hidden_bodies=hidden_bodies,
            ambient=camera.light_ambient,
            diffuse=camera.light_diffuse,
        )
    except UnsupportedScene as exc:
        warnings.warn(f"planar renderer: {exc}; using the bullet renderer", stacklevel=2)
        return None
