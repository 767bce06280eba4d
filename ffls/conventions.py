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
    Captures cover the upper hemisphere (z >= 0) unless they say ``full``.
"""
from __future__ import annotations

import numpy as np

UP = np.array([0.0, 0.0, 1.0])
HEMISPHERES = ("upper", "full")

#: world_from_camera when a capture gives none: camera x (image right) -> +X,
#: camera y (image down) -> -Z, camera z (forward) -> +Y. The camera sits at the origin.
DEFAULT_WORLD_FROM_CAMERA = np.array(
    [[1.0, 0.0, 0.0, 0.0],
     [0.0, 0.0, 1.0, 0.0],
     [0.0, -1.0, 0.0, 0.0],
     [0.0, 0.0, 0.0, 1.0]]
)


def covered_solid_angle(hemisphere: str) -> float:
    """Solid angle (sr) covered by a capture's lights: 2 pi for ``upper``, 4 pi for ``full``."""
    check_hemisphere(hemisphere)
    return 2.0 * np.pi if hemisphere == "upper" else 4.0 * np.pi


def check_hemisphere(hemisphere: str) -> str:
    if hemisphere not in HEMISPHERES:
        raise ValueError(f"hemisphere must be one of {HEMISPHERES}, not {hemisphere!r}")
    return hemisphere


def in_domain(directions: np.ndarray, hemisphere: str) -> np.ndarray:
    """Boolean mask of directions (..., 3) inside the covered domain (z >= 0 for ``upper``)."""
    check_hemisphere(hemisphere)
    d = np.asarray(directions)
    if hemisphere == "full":
        return np.ones(d.shape[:-1], dtype=bool)
    return d[..., 2] >= 0.0


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


def latlong_directions(width: int, height: int) -> np.ndarray:
    """Texel-centre directions (height, width, 3) float64 of a lat-long map."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
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
