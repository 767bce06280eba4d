"""The conventions every ffls module shares (GUIDE section 1). Defined here once; import them.

World frame
    Right-handed, +Z up. The scene centre is the origin unless the capture says otherwise.
    A *light direction* is a unit vector from the scene centre toward the light.
Camera
    OpenCV pinhole: x right, y down, z forward. ``K`` is 3x3, ``dist`` is OpenCV's distortion
    vector, ``world_from_camera`` a 4x4 rigid transform. Where a capture gives none, the world
    axes are image right (+X), image up (+Z) and straight ahead (+Y); see
    :data:`DEFAULT_WORLD_FROM_CAMERA`.
Lat-long light maps
    Blender/Cycles (Poly Haven): top row +Z, centre column +X, a quarter from the left +Y.
    Pixel (i, j) of a W x H map has its centre at u = (i + 0.5)/W, v = (j + 0.5)/H,
    theta = pi v, phi = pi (1 - 2u), direction (sin theta cos phi, sin theta sin phi, cos theta).
Rotation of a light map
    A rotation R moves the map's content: radiance that came from d now comes from R d.
    Rotating about +Z by +a degrees moves a light at azimuth phi to phi + a.
Hemisphere
    Captures cover the upper hemisphere (z >= 0) unless they say ``full``, or give the axis of
    their hemisphere (``{"axis": [x, y, z]}``: the directions ``d`` with ``d . axis >= 0``; an RTI
    dome's axis is the camera axis). :class:`Hemisphere` is the value type; every function that
    takes a hemisphere accepts it or its JSON form (``'upper'``, ``'full'``, ``{'axis': [...]}``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

UP = np.array([0.0, 0.0, 1.0])
HEMISPHERES = ("upper", "full")
#: Camera models a capture may declare (``"camera": {"model": ...}``): OpenCV pinhole with
#: distortion, or orthographic (parallel rays along the camera's +z; no focal length needed).
CAMERA_MODELS = ("pinhole", "orthographic")
#: Light models of ``lights.json`` (a light's ``"model"``): a distant light (a direction only) or a
#: near one (also a ``"position"``).
LIGHT_MODELS = ("distant", "near")
#: The widest 95% cone (``uncertainty_deg``): 180 deg covers every direction, so a wider one says
#: nothing more.
MAX_CONE_DEG = 180.0
#: How far past :data:`ffls.spheres.estimate.TILT_SEARCH_DEG`'s ends the grid reaches, a step at
#: a time, while its least misfit is at an end (:func:`ffls.spheres.estimate.fit_camera_tilt`):
#: from a camera looking straight up (-90) to one turned over onto its back (180): past 90 a camera
#: looks down and back, toward its own feet (an RTI dome's camera is as likely at 92 as at 88: a
#: 41-light dome 88 deg down was found at 90.0, the grid's end, docs/spheres.md). Every tilt in it
#: is a distinct ground normal seen from the camera; a tilt found at one of these ends is said
#: (``ffls lights``' line); a capture's ``camera_tilt_deg`` is refused outside it.
TILT_REACH_DEG = (-90.0, 180.0)

#: world_from_camera when a capture gives none: camera x (image right) -> +X,
#: camera y (image down) -> -Z, camera z (forward) -> +Y. The camera sits at the origin.
DEFAULT_WORLD_FROM_CAMERA = np.array(
    [[1.0, 0.0, 0.0, 0.0],
     [0.0, 0.0, 1.0, 0.0],
     [0.0, -1.0, 0.0, 0.0],
     [0.0, 0.0, 0.0, 1.0]]
)


@dataclass(frozen=True, eq=False)
class Hemisphere:
    """The part of the sphere of directions that a capture's lights cover.

    Attributes
    ----------
    axis : (3,) tuple of float, unit, or None
        The hemisphere of directions ``d`` with ``d . axis >= 0``; ``None`` is the full sphere.
        ``(0, 0, 1)`` is the upper hemisphere (``'upper'``).

    Notes
    -----
    Build it with :func:`as_hemisphere` (or :func:`check_hemisphere`), which also accepts the JSON
    forms ``'upper'``, ``'full'`` and ``{'axis': [x, y, z]}``. A hemisphere compares equal to its
    JSON form, so ``hemisphere == 'upper'`` works whichever form a caller holds.
    """

    axis: tuple | None = (0.0, 0.0, 1.0)

    @property
    def name(self) -> str:
        """``'upper'``, ``'full'`` or ``'axis'``."""
        if self.axis is None:
            return "full"
        return "upper" if self.axis == (0.0, 0.0, 1.0) else "axis"

    @property
    def solid_angle(self) -> float:
        """Covered solid angle (sr): 4 pi for the full sphere, else 2 pi."""
        return 4.0 * np.pi if self.axis is None else 2.0 * np.pi

    def to_json(self):
        """``'upper'``, ``'full'`` or ``{'axis': [x, y, z]}``."""
        return self.name if self.name != "axis" else {"axis": [float(v) for v in self.axis]}

    def side(self, directions) -> np.ndarray:
        """``d . axis`` of directions (..., 3) in the fixed operation order ``(x a_x + y a_y) + z a_z``
        (the GPU's, see ``shaders/include/cell_lookup.glsl``); the full sphere has no side (ValueError)."""
        if self.axis is None:
            raise ValueError("the full sphere has no axis")
        d = np.asarray(directions, dtype=np.float64)
        a = self.axis
        return (d[..., 0] * a[0] + d[..., 1] * a[1]) + d[..., 2] * a[2]

    def contains(self, directions) -> np.ndarray:
        """Boolean mask (...) of directions (..., 3) inside (``d . axis >= 0``; all for ``full``)."""
        d = np.asarray(directions)
        if self.axis is None:
            return np.ones(d.shape[:-1], dtype=bool)
        if self.name == "upper":
            return d[..., 2] >= 0.0
        return self.side(d) >= 0.0

    def __eq__(self, other) -> bool:
        if not isinstance(other, Hemisphere):
            try:
                other = as_hemisphere(other)
            except (ValueError, TypeError):
                return NotImplemented
        return self.axis == other.axis

    def __hash__(self) -> int:
        return hash(self.axis)

    def __str__(self) -> str:
        return self.name if self.name != "axis" else "axis " + ",".join(f"{v:.4g}" for v in self.axis)


UPPER = Hemisphere((0.0, 0.0, 1.0))
FULL = Hemisphere(None)


def as_hemisphere(value) -> Hemisphere:
    """A :class:`Hemisphere` from itself or its JSON form.

    Parameters
    ----------
    value : Hemisphere, {'upper', 'full'} or dict
        ``{'axis': [x, y, z]}`` (any non-zero finite length; normalised here).

    Returns
    -------
    Hemisphere

    Raises
    ------
    ValueError
        Anything else, naming the accepted forms.
    """
    if isinstance(value, Hemisphere):
        return value
    if isinstance(value, str):
        if value == "upper":
            return UPPER
        if value == "full":
            return FULL
    elif isinstance(value, dict) and set(value) == {"axis"}:
        a = value["axis"]
        ok = isinstance(a, (list, tuple, np.ndarray)) and len(a) == 3 and not any(isinstance(v, (bool, str)) for v in a)
        if ok:
            try:
                v = np.array(a, dtype=np.float64)
            except (TypeError, ValueError):
                ok = False
        if ok and np.all(np.isfinite(v)) and np.any(v != 0):
            # scaled by its largest entry first: the norm of (0, 0, 1e308) overflows to inf,
            # which had made the axis (0, 0, 0) without a word
            v = normalize(v / np.max(np.abs(v)))
            v = v + 0.0  # -0.0 -> 0.0
            if np.allclose(v, [0.0, 0.0, 1.0], rtol=0, atol=1e-12):
                return UPPER
            return Hemisphere(tuple(float(x) for x in v))
        raise ValueError(f"hemisphere axis must be three finite numbers, not all zero, not {a!r}")
    raise ValueError(f"hemisphere must be one of {HEMISPHERES} or {{'axis': [x, y, z]}}, not {value!r}")


def covered_solid_angle(hemisphere) -> float:
    """Solid angle (sr) covered by a capture's lights: 4 pi for ``full``, else 2 pi."""
    return check_hemisphere(hemisphere).solid_angle


def check_hemisphere(hemisphere) -> Hemisphere:
    """The :class:`Hemisphere` of ``hemisphere`` (see :func:`as_hemisphere`); ValueError otherwise."""
    return as_hemisphere(hemisphere)


def in_domain(directions: np.ndarray, hemisphere) -> np.ndarray:
    """Boolean mask of directions (..., 3) inside the covered domain (``d . axis >= 0``; z >= 0 for ``upper``)."""
    return check_hemisphere(hemisphere).contains(directions)


# ----------------------------------------------------------------------------- directions
def normalize(v: np.ndarray, axis: int = -1) -> np.ndarray:
    """Unit vectors along ``axis``; zero vectors stay zero (no NaN)."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=axis, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def spherical_to_direction(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Direction (..., 3) from polar angle ``theta`` (from +Z) and azimuth ``phi`` (from +X toward +Y), radians."""
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def direction_to_spherical(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) of directions (..., 3): theta in [0, pi] from +Z, phi in (-pi, pi] from +X."""
    d = np.asarray(d, dtype=np.float64)
    # atan2 keeps full precision near the poles, where arccos(z) loses half the digits
    theta = np.arctan2(np.hypot(d[..., 0], d[..., 1]), d[..., 2])
    phi = np.arctan2(d[..., 1], d[..., 0])
    return theta, phi


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in radians between direction arrays (..., 3), numerically stable at 0 and pi."""
    a = normalize(a)
    b = normalize(b)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def tangent_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal basis ``(e1, e2)`` of the plane perpendicular to the unit vector ``u`` (3,).

    ``e1 = normalize(u x a)`` with ``a = +X`` (or ``+Y`` where ``|u_x| >= 0.9``) and
    ``e2 = u x e1``, so that ``(e1, e2, u)`` is right-handed. The same ``u`` always gives the same
    basis: tangent-plane offsets (a sphere centre's shift in pixels, a direction's update) are
    reproducible.
    """
    u = np.asarray(u, dtype=np.float64)
    a = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = normalize(np.cross(u, a))
    return e1, np.cross(u, e1)


# ----------------------------------------------------------------------------- lat-long
def latlong_uv_to_direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Direction for lat-long texture coordinates u, v in [0, 1] (v = 0 is the top row, +Z)."""
    theta = np.pi * np.asarray(v, dtype=np.float64)
    phi = np.pi * (1.0 - 2.0 * np.asarray(u, dtype=np.float64))
    return spherical_to_direction(theta, phi)


def direction_to_latlong_uv(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lat-long texture coordinates (u in [0, 1), v in [0, 1]) of directions (..., 3)."""
    theta, phi = direction_to_spherical(d)
    u = np.mod(0.5 * (1.0 - phi / np.pi), 1.0)
    v = theta / np.pi
    return u, v


def latlong_directions(width: int, height: int, rows: slice = slice(None)) -> np.ndarray:
    """Texel-centre directions (height, width, 3) float64 of a lat-long map (its ``rows`` only)."""
    u = (np.arange(width) + 0.5) / width
    v = ((np.arange(height) + 0.5) / height)[rows]
    uu, vv = np.meshgrid(u, v)
    return latlong_uv_to_direction(uu, vv)


# ----------------------------------------------------------------------------- rotations
def rotation_about_axis(axis: np.ndarray, degrees: float) -> np.ndarray:
    """3x3 rotation by ``degrees`` counter-clockwise about ``axis`` (right-hand rule)."""
    a = normalize(np.asarray(axis, dtype=np.float64))
    t = np.deg2rad(degrees)
    c, s = np.cos(t), np.sin(t)
    x, y, z = a
    C = 1.0 - c
    return np.array(
        [[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
         [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
         [z * x * C - y * s, z * y * C + x * s, c + z * z * C]]
    )


def rotation_z(degrees: float) -> np.ndarray:
    """Rotation about +Z: moves a light at azimuth phi to phi + degrees (CCW seen from above)."""
    return rotation_about_axis(UP, degrees)


def rotation_ypr(yaw: float = 0.0, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """Light-map rotation from yaw (about +Z), pitch (about +Y) and roll (about +X), degrees.

    Applied as R = Rz(yaw) @ Ry(pitch) @ Rx(roll): roll first, yaw last, all about world axes.
    """
    return rotation_z(yaw) @ rotation_about_axis([0, 1, 0], pitch) @ rotation_about_axis([1, 0, 0], roll)


def rotate_directions(R: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Apply the light-map rotation R (3x3) to directions (..., 3): content at d moves to R d.

    Written as three fused column updates: a BLAS product with an inner size of 3 is several
    times slower for millions of directions.
    """
    d = np.asarray(d, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    return d[..., 0:1] * R[:, 0] + d[..., 1:2] * R[:, 1] + d[..., 2:3] * R[:, 2]


def is_rotation(R: np.ndarray, atol: float = 1e-6) -> bool:
    R = np.asarray(R, dtype=np.float64)
    return R.shape == (3, 3) and np.allclose(R @ R.T, np.eye(3), atol=atol) and abs(np.linalg.det(R) - 1) < atol


def checked_rotation(R) -> np.ndarray:
    """``R`` as a float64 (3, 3) array; ``ValueError`` unless it is a rotation (every relighter's ``set_rotation``)."""
    R = np.asarray(R, dtype=np.float64)
    if not is_rotation(R):
        raise ValueError("R must be a 3x3 rotation matrix")
    return R


def checked_weights(weights, n: int) -> np.ndarray:
    """Per-light RGB weights as a float64 ``(n, 3)`` copy; ``ValueError`` for another shape or a non-finite value
    (every relighter's ``set_weights``)."""
    w = np.array(weights, dtype=np.float64)
    if w.shape != (int(n), 3):
        raise ValueError(f"weights must have shape ({int(n)}, 3), not {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("weights must be finite")
    return w
