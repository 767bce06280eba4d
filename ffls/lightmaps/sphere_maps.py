"""Sphere parameterisations with exact per-texel solid angles.

Every map turns an image (or, for the cube map, six faces) into directions on the unit sphere
(or the upper hemisphere) and back, and gives the exact solid angle that each texel covers, so
that the solid angles of a map sum to 4 pi (full sphere) or 2 pi (upper hemisphere) up to
floating-point rounding at any resolution.

Maps (``MAPS``, :func:`get_map`)
--------------------------------
``latlong``
    Equirectangular, Blender/Cycles orientation (:mod:`ffls.conventions`); shape (res, 2 res).
``concentric``
    Upper hemisphere; Shirley & Chiu's concentric square-to-disc map [1]_ followed by the
    equal-area (Lambert) lift of the disc onto the hemisphere, as in Clarberg [2]_; every texel
    covers 2 pi / res^2. Shape (res, res).
``octahedral``
    Full sphere; Clarberg's equal-area octahedral map [2]_ (upper hemisphere in the inner
    diamond); every texel covers 4 pi / res^2. Shape (res, res).
``angular``
    Debevec's light-probe angular map [3]_: the disc inscribed in the square, radius
    r = theta / pi where theta is the angle from the map's centre direction. Shape (res, res).
``mirrorball``
    The photograph of a mirrored sphere seen from far away: r = sin(theta / 2). Shape (res, res).
``cube``
    OpenGL cube map, faces +X, -X, +Y, -Y, +Z, -Z. Shape (6, res, res).

Image coordinates
-----------------
For the 2-D maps, ``uv`` is continuous in [0, 1]^2 with u to the right (increasing column) and
v downward (increasing row): texel (row j, column i) of an (H, W) map covers
[i/W, (i+1)/W] x [j/H, (j+1)/H] and has its centre at ((i + 0.5)/W, (j + 0.5)/H). Flat texel
indices are row-major over ``shape(res)``.

References
----------
.. [1] P. Shirley and K. Chiu, "A low distortion map between disk and square", Journal of
   Graphics Tools 2(3), 1997.
.. [2] P. Clarberg, "Fast equal-area mapping of the (hemi)sphere using SIMD", Journal of
   Graphics Tools 13(3), 2008.
.. [3] P. Debevec, "Rendering synthetic objects into real scenes", SIGGRAPH 1998, and the
   Light Probe Image Gallery (angular map format).
"""
from __future__ import annotations

import functools

import numpy as np

from ffls import conventions

__all__ = [
    "SphereMap", "LatLongMap", "ConcentricMap", "OctahedralMap", "AngularMap", "MirrorBallMap",
    "CubeMap", "MAPS", "get_map", "DEFAULT_PROBE_FRAME", "disc_to_hemisphere", "hemisphere_to_disc",
]

#: Columns: image right, image up and the image centre of the angular and mirror-ball maps, in
#: world coordinates. A probe photographed by the default camera (looking along +Y, image right
#: +X, image up +Z; :data:`ffls.conventions.DEFAULT_WORLD_FROM_CAMERA`) shows at its centre the
#: direction back toward the camera, -Y.
DEFAULT_PROBE_FRAME = np.array(
    [[1.0, 0.0, 0.0],
     [0.0, 0.0, -1.0],
     [0.0, 1.0, 0.0]]
)

#: Texels of the disc maps whose solid angle is below this (sr) are invalid: a grid line that
#: clips the rim leaves slivers whose solid angle is below the rounding of the exact formula.
#: The slivers dropped this way cover less than 4 res * 1e-13 sr in all.
SLIVER_FLOOR = 1e-13


def _as_dirs(d) -> np.ndarray:
    d = np.asarray(d, dtype=np.float64)
    if d.shape[-1:] != (3,):
        raise ValueError(f"directions must have shape (..., 3), not {d.shape}")
    return d


def _as_uv(uv) -> np.ndarray:
    uv = np.asarray(uv, dtype=np.float64)
    if uv.shape[-1:] != (2,):
        raise ValueError(f"uv must have shape (..., 2), not {uv.shape}")
    return uv


def _check_res(res) -> int:
    r = int(res)
    if r != res or r < 1:
        raise ValueError(f"res must be a positive integer, not {res!r}")
    return r


def _unit(d: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return d / n


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


class SphereMap:
    """Common interface of the sphere parameterisations (2-D maps; see :class:`CubeMap`).

    Attributes
    ----------
    name : str
        Key in :data:`MAPS`.
    domain : {'upper', 'full'}
        The part of the sphere that the map covers.
    """

    name: str = ""
    domain: str = "full"

    # ----------------------------------------------------------------- to be provided
    def shape(self, res: int) -> tuple:
        """Shape of the texel array at resolution ``res``: (H, W)."""
        res = _check_res(res)
        return (res, res)

    def uv_to_direction(self, uv) -> np.ndarray:
        """Directions for image coordinates.

        Parameters
        ----------
        uv : (..., 2) array_like
            u to the right, v downward, both in [0, 1].

        Returns
        -------
        (..., 3) float64
            Unit directions; NaN where ``uv`` lies outside the map's valid region.
        """
        raise NotImplementedError

    def direction_to_uv(self, d) -> np.ndarray:
        """Image coordinates of directions (the inverse of :meth:`uv_to_direction`).

        Parameters
        ----------
        d : (..., 3) array_like
            Directions (normalised here).

        Returns
        -------
        (..., 2) float64
            uv in [0, 1]^2; NaN for directions outside :attr:`domain` or containing NaN.
        """
        raise NotImplementedError

    def solid_angles(self, res: int) -> np.ndarray:
        """Exact solid angle (sr) of every texel, float64 of :meth:`shape`; 0 where invalid."""
        raise NotImplementedError

    # ----------------------------------------------------------------- shared
    def valid_mask(self, res: int) -> np.ndarray:
        """Boolean array of :meth:`shape`: texels that cover part of the domain."""
        return np.ones(self.shape(res), dtype=bool)

    def texel_centers_uv(self, res: int) -> np.ndarray:
        """uv of the texel centres, (H, W, 2) float64."""
        h, w = self.shape(res)[-2:]
        u = (np.arange(w) + 0.5) / w
        v = (np.arange(h) + 0.5) / h
        uu, vv = np.meshgrid(u, v)
        return np.stack([uu, vv], axis=-1)

    def directions(self, res: int) -> np.ndarray:
        """Texel-centre directions, ``shape(res) + (3,)`` float64, unit; NaN where invalid."""
        return self.uv_to_direction(self.texel_centers_uv(res))

    def to_pixel(self, d, res: int) -> np.ndarray:
        """Continuous pixel coordinates (..., 2) = (column, row) = uv * (W, H) of directions."""
        h, w = self.shape(res)[-2:]
        return self.direction_to_uv(d) * np.array([w, h], dtype=np.float64)

    def texel_index(self, d, res: int) -> np.ndarray:
        """Flat (row-major) index of the texel containing each direction.

        Parameters
        ----------
        d : (..., 3) array_like
            Directions.
        res : int
            Resolution.

        Returns
        -------
        (...) int64
            Index into ``solid_angles(res).ravel()``; -1 for directions outside :attr:`domain`
            (or NaN). ``texel_index(directions(res)[valid_mask(res)], res)`` is
            ``flatnonzero(valid_mask(res))``.
        """
        h, w = self.shape(res)[-2:]
        uv = self.direction_to_uv(d)
        return self._uv_index(uv, h, w)

    @staticmethod
    def _uv_index(uv: np.ndarray, h: int, w: int) -> np.ndarray:
        bad = ~np.all(np.isfinite(uv), axis=-1)
        uv = np.where(bad[..., None], 0.0, uv)
        i = np.clip(np.floor(uv[..., 0] * w), 0, w - 1).astype(np.int64)
        j = np.clip(np.floor(uv[..., 1] * h), 0, h - 1).astype(np.int64)
        return np.where(bad, -1, j * w + i)

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


# ============================================================================ lat-long
class LatLongMap(SphereMap):
    """Equirectangular (lat-long) map of the full sphere, shape (res, 2 res).

    Orientation (:mod:`ffls.conventions`, Blender/Cycles): theta = pi v from +Z,
    phi = pi (1 - 2u) from +X toward +Y; the top row is +Z, the centre column +X and the column
    a quarter from the left +Y. A row of texels between polar angles theta0 < theta1 covers
    exactly (cos theta0 - cos theta1) * 2 pi / W per texel.
    """

    name = "latlong"
    domain = "full"

    def shape(self, res: int) -> tuple:
        res = _check_res(res)
        return (res, 2 * res)

    def uv_to_direction(self, uv) -> np.ndarray:
        uv = _as_uv(uv)
        return conventions.latlong_uv_to_direction(uv[..., 0], uv[..., 1])

    def direction_to_uv(self, d) -> np.ndarray:
        d = _as_dirs(d)
        u, v = conventions.direction_to_latlong_uv(d)
        uv = np.stack([u, v], axis=-1)
        bad = ~np.all(np.isfinite(d), axis=-1) | ~(np.linalg.norm(d, axis=-1) > 0)
        return np.where(bad[..., None], np.nan, uv)

    def solid_angles(self, res: int) -> np.ndarray:
        h, w = self.shape(res)
        return np.repeat(self.row_solid_angles(res)[:, None], w, axis=1)

    def row_solid_angles(self, res: int) -> np.ndarray:
        """Exact solid angle (sr) of one texel of each row, (H,) float64: every texel of a row has it."""
        h, w = self.shape(res)
        theta = np.pi * np.arange(h + 1) / h
        # cos t0 - cos t1 = 2 sin((t0 + t1)/2) sin((t1 - t0)/2), no cancellation for thin rows
        band = 2.0 * np.sin(0.5 * (theta[:-1] + theta[1:])) * np.sin(0.5 * (theta[1:] - theta[:-1]))
        return band * (2.0 * np.pi / w)


# ============================================================================ concentric
def _concentric_square_to_disc(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shirley-Chiu: square point (a, b) in [-1, 1]^2 -> disc point r (cos phi, sin phi).

    Returns the signed radius r (max(|a|, |b|) in absolute value) and the angle phi; the map
    is equal-area (constant Jacobian pi / 4).
    """
    horiz = np.abs(a) > np.abs(b)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(horiz, a, b)
        phi = np.where(horiz, (np.pi / 4) * (b / a), np.pi / 2 - (np.pi / 4) * (a / b))
    return r, np.where(r == 0, 0.0, phi)


def _concentric_disc_to_square(r: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`_concentric_square_to_disc` from polar disc coordinates (r >= 0)."""
    q = np.pi / 4
    phi = np.where(phi < -q, phi + 2 * np.pi, phi)  # now in [-pi/4, 7pi/4)
    a = np.select([phi < q, phi < 3 * q, phi < 5 * q],
                  [r, -r * (phi - 2 * q) / q, -r], r * (phi - 6 * q) / q)
    b = np.select([phi < q, phi < 3 * q, phi < 5 * q],
                  [r * phi / q, r, -r * (phi - 4 * q) / q], -r)
    return a, b


def disc_to_hemisphere(r: np.ndarray, phi: np.ndarray, lower: bool = False) -> np.ndarray:
    """Lambert's equal-area lift of the unit disc onto a hemisphere (Clarberg 2008).

    The disc point ``r (cos phi, sin phi)`` goes to ``(x sqrt(2 - r^2), y sqrt(2 - r^2), 1 - r^2)``:
    area on the disc is proportional to solid angle (``dOmega = 2 dA``), the centre is the pole and
    the rim the horizon. The second step of :class:`ConcentricMap`.

    Parameters
    ----------
    r, phi : (...) float
        Polar disc coordinates, ``|r| <= 1``.
    lower : bool
        Lift onto the lower hemisphere (``z = r^2 - 1``, seen from above) instead of the upper.

    Returns
    -------
    (..., 3) float64
        Unit directions.
    """
    r = np.asarray(r, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    r2 = r * r  # exactly 1 on the border: z = 0, never below
    s = r * np.sqrt(np.maximum(2.0 - r2, 0.0))
    z = 1.0 - r2
    return np.stack([s * np.cos(phi), s * np.sin(phi), -z if lower else z], axis=-1)


def hemisphere_to_disc(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`disc_to_hemisphere` (either hemisphere, by ``|z|``).

    Parameters
    ----------
    d : (..., 3) float
        Unit directions.

    Returns
    -------
    r, phi : (...) float64
        Polar disc coordinates, ``r = sqrt(1 - |z|)`` computed without cancellation.
    """
    d = np.asarray(d, dtype=np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.hypot(x, y) / np.sqrt(1.0 + np.abs(z))  # sqrt(1 - |z|), without cancellation
    return r, np.arctan2(y, x)


class ConcentricMap(SphereMap):
    """Equal-area map of the upper hemisphere on a square, shape (res, res).

    The square point (a, b) = (2u - 1, 1 - 2v) goes to the disc by Shirley & Chiu's concentric
    map (r, phi), then to the hemisphere by the Lambert lift
    d = (x sqrt(2 - r^2), y sqrt(2 - r^2), 1 - r^2), as in Clarberg (2008). Both steps have a
    constant Jacobian, so every texel covers exactly 2 pi / res^2.

    Orientation: the zenith +Z at the centre of the image, +X toward the right (increasing
    column), +Y toward the top (decreasing row); the horizon is the square's border.
    """

    name = "concentric"
    domain = "upper"

    def uv_to_direction(self, uv) -> np.ndarray:
        uv = _as_uv(uv)
        a = 2.0 * uv[..., 0] - 1.0
        b = 1.0 - 2.0 * uv[..., 1]
        r, phi = _concentric_square_to_disc(a, b)
        d = disc_to_hemisphere(r, phi)
        out = (np.maximum(np.abs(a), np.abs(b)) > 1.0) | ~np.isfinite(a + b)
        return np.where(out[..., None], np.nan, d)

    def direction_to_uv(self, d) -> np.ndarray:
        d = _unit(_as_dirs(d))
        z = d[..., 2]
        r, phi = hemisphere_to_disc(d)
        r = np.where(z >= 0.0, r, 0.0)  # z < 0 (or NaN): placeholder, NaN below
        a, b = _concentric_disc_to_square(r, phi)
        uv = np.stack([0.5 * (a + 1.0), 0.5 * (1.0 - b)], axis=-1)
        bad = ~(z >= 0.0)
        return np.where(bad[..., None], np.nan, uv)

    def solid_angles(self, res: int) -> np.ndarray:
        return np.full(self.shape(res), 2.0 * np.pi / _check_res(res) ** 2)


# ============================================================================ octahedral
class OctahedralMap(SphereMap):
    """Clarberg's equal-area octahedral map of the full sphere, shape (res, res).

    With (a, b) = (2u - 1, 1 - 2v), the upper hemisphere fills the inner diamond
    |a| + |b| <= 1 and the lower hemisphere the four corner triangles, folded across the
    diamond's edges (the octahedral wrap). Radius r = 1 - | 1 - (|a| + |b|) | gives
    |z| = 1 - r^2; the angle in each quadrant is linear along the diamond's edge. Every texel
    covers exactly 4 pi / res^2.

    Orientation: +Z at the centre, -Z at the four corners, +X toward the right, +Y toward the
    top, the equator on the diamond |a| + |b| = 1.
    """

    name = "octahedral"
    domain = "full"

    def uv_to_direction(self, uv) -> np.ndarray:
        uv = _as_uv(uv)
        a = 2.0 * uv[..., 0] - 1.0
        b = 1.0 - 2.0 * uv[..., 1]
        ap, bp = np.abs(a), np.abs(b)
        sd = 1.0 - (ap + bp)
        r = 1.0 - np.abs(sd)
        with np.errstate(invalid="ignore", divide="ignore"):
            phi = np.where(r == 0, 1.0, (bp - ap) / r + 1.0) * (np.pi / 4)
        z = np.copysign(1.0 - r * r, sd)
        s = r * np.sqrt(np.maximum(2.0 - r * r, 0.0))
        cphi = np.where(a < 0, -1.0, 1.0) * np.cos(phi)
        sphi = np.where(b < 0, -1.0, 1.0) * np.sin(phi)
        d = np.stack([cphi * s, sphi * s, z], axis=-1)
        out = (np.maximum(ap, bp) > 1.0) | ~np.isfinite(a + b)
        return np.where(out[..., None], np.nan, d)

    def direction_to_uv(self, d) -> np.ndarray:
        d = _unit(_as_dirs(d))
        x, y, z = d[..., 0], d[..., 1], d[..., 2]
        az = np.abs(z)
        with np.errstate(invalid="ignore"):
            r = np.hypot(x, y) / np.sqrt(1.0 + az)  # sqrt(1 - |z|)
        frac = np.arctan2(np.abs(y), np.abs(x)) * (2.0 / np.pi)
        bq = frac * r
        aq = r - bq
        lower = z < 0
        aq, bq = np.where(lower, 1.0 - bq, aq), np.where(lower, 1.0 - aq, bq)
        a = np.where(x < 0, -aq, aq)
        b = np.where(y < 0, -bq, bq)
        return np.stack([0.5 * (a + 1.0), 0.5 * (1.0 - b)], axis=-1)

    def solid_angles(self, res: int) -> np.ndarray:
        return np.full(self.shape(res), 4.0 * np.pi / _check_res(res) ** 2)


# ============================================================================ disc maps
def _edges(res: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel edges in disc coordinates: |e_k| as integers m_k / res and their signs."""
    k = np.arange(res + 1)
    m = 2 * k - res  # e_k = m_k / res, exactly antisymmetric
    return np.abs(m), np.sign(m)


class _DiscMap(SphereMap):
    """A map of the full sphere onto the disc inscribed in the square (angular, mirror ball).

    Disc coordinates (px, py) = (2u - 1, 1 - 2v); the direction depends on the radius
    r = |p| <= 1 and the polar angle of p, in the frame ``world_from_map`` whose columns are
    the image right, image up and image centre directions (default
    :data:`DEFAULT_PROBE_FRAME`: +X, +Z, -Y). The rim r = 1 is the single direction opposite
    the centre.

    A texel is valid when its intersection with the disc has a solid angle above
    :data:`SLIVER_FLOOR`. Its direction is that of its centre when the centre lies inside the
    disc; for rim texels whose centre lies outside, a point of texel ∩ disc is used instead:
    halfway from the texel's point nearest to the image centre to the rim, along the line
    toward the texel centre.
    """

    domain = "full"
    _PULL = 1.0 - 1e-4  # radius to which directions landing in sliver texels are pulled

    def __init__(self, world_from_map=None):
        R = DEFAULT_PROBE_FRAME if world_from_map is None else np.asarray(world_from_map, float)
        if not conventions.is_rotation(R):
            raise ValueError("world_from_map must be a 3x3 rotation (columns: right, up, centre)")
        self.world_from_map = _readonly(np.array(R, dtype=np.float64))

    def __repr__(self) -> str:
        if np.array_equal(self.world_from_map, DEFAULT_PROBE_FRAME):
            return f"{type(self).__name__}()"
        return f"{type(self).__name__}(world_from_map={self.world_from_map.tolist()})"

    # local frame: x = image right, y = image up, z = image centre
    def _disc_to_local(self, px, py) -> np.ndarray:
        raise NotImplementedError

    def _local_to_radius(self, lx, ly, lz, rho) -> np.ndarray:
        """Disc radius r of local directions; rho = hypot(lx, ly)."""
        raise NotImplementedError

    def _corner_function(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Solid angle of the disc part of the rectangle [0, x] x [0, y] (x, y >= 0)."""
        raise NotImplementedError

    def uv_to_direction(self, uv) -> np.ndarray:
        uv = _as_uv(uv)
        px = 2.0 * uv[..., 0] - 1.0
        py = 1.0 - 2.0 * uv[..., 1]
        r2 = px * px + py * py
        inside = r2 <= 1.0
        px = np.where(inside, px, 0.0)
        py = np.where(inside, py, 0.0)
        local = self._disc_to_local(px, py)
        d = local @ self.world_from_map.T
        return np.where(inside[..., None], d, np.nan)

    def direction_to_uv(self, d) -> np.ndarray:
        local = _unit(_as_dirs(d)) @ self.world_from_map
        lx, ly, lz = local[..., 0], local[..., 1], local[..., 2]
        rho = np.hypot(lx, ly)
        r = self._local_to_radius(lx, ly, lz, rho)
        # the antipode goes to (1, 0); so do directions whose rho is subnormal, where lx / rho
        # keeps only a few significant bits (a direction 1e-313 from the antipode is the antipode)
        off_axis = rho >= np.finfo(np.float64).tiny
        with np.errstate(invalid="ignore", divide="ignore"):
            px = np.where(off_axis, r * lx / rho, r)
            py = np.where(off_axis, r * ly / rho, 0.0)
        return np.stack([0.5 * (px + 1.0), 0.5 * (1.0 - py)], axis=-1)

    @functools.lru_cache(maxsize=16)
    def _solid_angles(self, res: int) -> np.ndarray:
        m, sgn = _edges(res)
        mu = np.unique(m)
        vals = mu / res
        gx, gy = np.meshgrid(vals, vals, indexing="ij")
        G = self._corner_function(gx, gy)
        pos = np.searchsorted(mu, m)
        # signed corner function C(e_kx, e_ky) = sign(x) sign(y) G(|x|, |y|), x = column edges,
        # y = row edges (row k's top edge is py = -e_k)
        C = (sgn[:, None] * -sgn[None, :]) * G[pos[:, None], pos[None, :]]  # (kx, ky)
        C = C.T  # (ky, kx): rows of edges
        # texel (j, i): y from -e_{j+1} (bottom) to -e_j (top), x from e_i to e_{i+1}
        om = (C[:-1, 1:] - C[:-1, :-1]) - (C[1:, 1:] - C[1:, :-1])
        om = np.where(om > SLIVER_FLOOR, om, 0.0)
        return _readonly(om)

    def solid_angles(self, res: int) -> np.ndarray:
        return self._solid_angles(_check_res(res)).copy()

    def valid_mask(self, res: int) -> np.ndarray:
        return self._solid_angles(_check_res(res)) > 0

    def _representative_points(self, res: int) -> tuple[np.ndarray, np.ndarray]:
        """Disc points (px, py), (res, res) each, inside texel ∩ disc of every valid texel."""
        e = (2.0 * np.arange(res + 1) - res) / res
        x0, x1 = e[:-1][None, :], e[1:][None, :]
        y1, y0 = -e[:-1][:, None], -e[1:][:, None]  # row j: top -e_j, bottom -e_{j+1}
        cx = np.broadcast_to(0.5 * (x0 + x1), (res, res))
        cy = np.broadcast_to(0.5 * (y0 + y1), (res, res))
        qx = np.broadcast_to(np.clip(0.0, x0, x1), (res, res))
        qy = np.broadcast_to(np.clip(0.0, y0, y1), (res, res))
        wx, wy = cx - qx, cy - qy
        qq = qx * qx + qy * qy
        qw = qx * wx + qy * wy
        ww = wx * wx + wy * wy
        with np.errstate(invalid="ignore", divide="ignore"):
            tstar = (1.0 - qq) / (qw + np.sqrt(qw * qw + ww * (1.0 - qq)))
        near_rim = cx * cx + cy * cy >= 1.0 - 1e-9
        t = np.where(near_rim, 0.5 * tstar, 1.0)
        return qx + t * wx, qy + t * wy

    def directions(self, res: int) -> np.ndarray:
        res = _check_res(res)
        px, py = self._representative_points(res)
        uv = np.stack([0.5 * (px + 1.0), 0.5 * (1.0 - py)], axis=-1)
        d = self.uv_to_direction(uv)
        return np.where(self.valid_mask(res)[..., None], d, np.nan)

    def texel_index(self, d, res: int) -> np.ndarray:
        """Flat index of the texel containing each direction (see :meth:`SphereMap.texel_index`).

        Directions that land in a sliver texel (solid angle below :data:`SLIVER_FLOOR`, so
        invalid) are assigned to the texel toward the image centre that contains the same
        point pulled to radius 1 - 1e-4.
        """
        res = _check_res(res)
        uv = self.direction_to_uv(d)
        idx = self._uv_index(uv, res, res)
        valid = self.valid_mask(res).ravel()
        miss = (idx >= 0) & ~valid[np.maximum(idx, 0)]
        if np.any(miss):
            p = np.stack([2.0 * uv[..., 0] - 1.0, 1.0 - 2.0 * uv[..., 1]], axis=-1)
            n = np.linalg.norm(p, axis=-1, keepdims=True)
            p = p * np.minimum(1.0, self._PULL / np.maximum(n, 1e-300))
            uv2 = np.stack([0.5 * (p[..., 0] + 1.0), 0.5 * (1.0 - p[..., 1])], axis=-1)
            idx = np.where(miss, self._uv_index(uv2, res, res), idx)
        return idx


class AngularMap(_DiscMap):
    """Debevec's angular light-probe map of the full sphere, shape (res, res).

    The disc point p = (2u - 1, 1 - 2v) at radius r = |p| <= 1 is the direction at angle
    theta = pi r from the image centre, rotated toward the image direction of p. With the
    default frame (:data:`DEFAULT_PROBE_FRAME`), the centre is -Y (toward the default camera),
    image right +X, image up +Z, and the rim is +Y. Texels outside the disc are invalid.

    The solid angle element is dOmega = pi sin(pi r) / r dA. Over the part of the rectangle
    [0, x] x [0, y] inside the disc, integrated in polar form, the radial integral is closed form
    (cos(pi r_in) - cos(pi r_out)); along each edge the remaining integral
    x * int g(x^2 + t^2) dt with g(w) = (1 - cos(pi sqrt w)) / w (an entire function) is done
    by 24-point Gauss-Legendre quadrature, exact to rounding. Texels follow by inclusion and
    exclusion of their corners, so the total is 4 pi to rounding.
    """

    name = "angular"
    _NODES, _WEIGHTS = np.polynomial.legendre.leggauss(24)

    def _disc_to_local(self, px, py):
        r = np.hypot(px, py)
        theta = np.pi * r
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(r > 0, np.sin(theta) / r, np.pi)
        return np.stack([px * s, py * s, np.cos(theta)], axis=-1)

    def _local_to_radius(self, lx, ly, lz, rho):
        return np.arctan2(rho, lz) / np.pi

    @classmethod
    def _edge_integral(cls, x: np.ndarray, L: np.ndarray) -> np.ndarray:
        """x * int_0^L g(x^2 + t^2) dt, g(w) = (1 - cos(pi sqrt w)) / w = (pi^2/2) sinc^2."""
        t = 0.5 * L[..., None] * (cls._NODES + 1.0)
        s = np.sqrt(x[..., None] ** 2 + t * t)
        g = 0.5 * np.pi ** 2 * np.sinc(0.5 * s) ** 2
        return x * 0.5 * L * np.sum(cls._WEIGHTS * g, axis=-1)

    def _corner_function(self, x, y):
        def half(x, y):  # rays leaving through the edge X = x (polar angle below atan2(y, x))
            L = np.minimum(y, np.sqrt(np.maximum(1.0 - x * x, 0.0)))
            return self._edge_integral(x, L) + 2.0 * (np.arctan2(y, x) - np.arctan2(L, x))

        return half(x, y) + half(y, x)


class MirrorBallMap(_DiscMap):
    """Mirror-ball (light probe photograph) map of the full sphere, shape (res, res).

    The disc point p at radius r = |p| <= 1 reflects the direction at angle theta from the
    image centre with r = sin(theta / 2): in the map frame,
    d = (2 s px, 2 s py, 1 - 2 r^2) with s = sqrt(1 - r^2). Same orientation as
    :class:`AngularMap` (default centre -Y toward the camera, image right +X, image up +Z; the
    rim is +Y, behind the ball).

    dOmega = 4 dA on the disc, so a texel covers exactly 4 * area(texel ∩ disc), from the
    closed-form area of a corner rectangle [0, x] x [0, y] inside the unit disc
    (int sqrt(1 - t^2) dt = (t sqrt(1 - t^2) + asin t) / 2) and inclusion-exclusion.
    """

    name = "mirrorball"

    def _disc_to_local(self, px, py):
        r2 = px * px + py * py
        s2 = 2.0 * np.sqrt(np.maximum(1.0 - r2, 0.0))
        return np.stack([s2 * px, s2 * py, 1.0 - 2.0 * r2], axis=-1)

    def _local_to_radius(self, lx, ly, lz, rho):
        # r^2 = (1 - lz) / 2 = rho^2 / (2 (1 + lz)); pick the form without cancellation
        with np.errstate(invalid="ignore", divide="ignore"):
            up = rho / np.sqrt(2.0 * (1.0 + np.maximum(lz, 0.0)))
        return np.where(lz > 0, up, np.sqrt(np.maximum(0.5 * (1.0 - lz), 0.0)))

    def _corner_function(self, x, y):
        x = np.minimum(x, 1.0)
        y = np.minimum(y, 1.0)
        a = np.sqrt(np.maximum(1.0 - y * y, 0.0))

        def F(t):
            return 0.5 * (t * np.sqrt(np.maximum(1.0 - t * t, 0.0)) + np.arcsin(t))

        area = np.where(x <= a, x * y, a * y + F(np.maximum(x, a)) - F(a))
        return 4.0 * area


# ============================================================================ cube
# OpenGL cube-map faces (spec table 8.19): major axis, and (sc, tc) as functions of (x, y, z).
_FACE_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")


class CubeMap(SphereMap):
    """OpenGL cube map of the full sphere, shape (6, res, res).

    Faces in OpenGL order +X, -X, +Y, -Y, +Z, -Z (``GL_TEXTURE_CUBE_MAP_POSITIVE_X + face``).
    Within a face, u = s and v = t of the OpenGL specification (table 8.19), and row j of
    ``faces[f]`` is the j-th row uploaded by ``glTexImage2D`` (t increasing with the row), so
    the array can be uploaded without flipping. With sc = 2u - 1, tc = 2v - 1 the face
    directions are (before normalisation):

    ====  ==================
    +X    ( 1, -tc, -sc)
    -X    (-1, -tc,  sc)
    +Y    ( sc,  1,  tc)
    -Y    ( sc, -1, -tc)
    +Z    ( sc, -tc,  1)
    -Z    (-sc, -tc, -1)
    ====  ==================

    The face of a direction is that of its largest absolute component (ties: x before y before
    z). Texel solid angles use the exact formula for a rectangle on the face plane at unit
    distance, Omega([0, x] x [0, y]) = atan2(x y, sqrt(x^2 + y^2 + 1)), by inclusion and
    exclusion; each face sums to 4 atan(1/sqrt 3) = 2 pi / 3.

    ``uv_to_direction(face, uv)`` takes the face index; ``direction_to_uv(d)`` returns
    ``(face, uv)``.
    """

    name = "cube"
    domain = "full"
    face_names = _FACE_NAMES

    def shape(self, res: int) -> tuple:
        res = _check_res(res)
        return (6, res, res)

    def uv_to_direction(self, face, uv) -> np.ndarray:
        """Directions (..., 3) of ``uv`` (..., 2) on cube face ``face`` (int, broadcast)."""
        uv = _as_uv(uv)
        face = np.asarray(face)
        sc = 2.0 * uv[..., 0] - 1.0
        tc = 2.0 * uv[..., 1] - 1.0
        one = np.ones_like(sc)
        cands = np.stack([
            np.stack([one, -tc, -sc], -1),
            np.stack([-one, -tc, sc], -1),
            np.stack([sc, one, tc], -1),
            np.stack([sc, -one, -tc], -1),
            np.stack([sc, -tc, one], -1),
            np.stack([-sc, -tc, -one], -1),
        ])
        f = np.broadcast_to(face, sc.shape)
        if np.any((f < 0) | (f > 5)):
            raise ValueError("cube face index must be in 0..5")
        d = np.take_along_axis(cands, f[None, ..., None].astype(np.int64), axis=0)[0]
        out = (np.maximum(np.abs(sc), np.abs(tc)) > 1.0) | ~np.isfinite(sc + tc)
        return np.where(out[..., None], np.nan, _unit(d))

    def direction_to_uv(self, d) -> tuple[np.ndarray, np.ndarray]:
        """(face (...) int64, uv (..., 2) float64) of directions (..., 3); face -1 for NaN/0."""
        d = _as_dirs(d)
        x, y, z = d[..., 0], d[..., 1], d[..., 2]
        ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
        use_x = (ax >= ay) & (ax >= az)
        use_y = ~use_x & (ay >= az)
        face = np.where(use_x, np.where(x < 0, 1, 0),
                        np.where(use_y, np.where(y < 0, 3, 2), np.where(z < 0, 5, 4)))
        ma = np.where(use_x, ax, np.where(use_y, ay, az))
        sc = np.choose(face, [-z, z, x, x, x, -x])
        tc = np.choose(face, [-y, -y, z, -z, -y, -y])
        with np.errstate(invalid="ignore", divide="ignore"):
            uv = np.stack([0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0)], axis=-1)
        bad = ~np.all(np.isfinite(d), axis=-1) | ~(ma > 0)
        face = np.where(bad, -1, face).astype(np.int64)
        return face, np.where(bad[..., None], np.nan, uv)

    def directions(self, res: int) -> np.ndarray:
        res = _check_res(res)
        uv = self.texel_centers_uv(res)
        return np.stack([self.uv_to_direction(f, uv) for f in range(6)])

    def to_pixel(self, d, res: int) -> tuple[np.ndarray, np.ndarray]:
        """(face, (..., 2) continuous (column, row) pixel coordinates) of directions."""
        face, uv = self.direction_to_uv(d)
        return face, uv * float(_check_res(res))

    def texel_index(self, d, res: int) -> np.ndarray:
        res = _check_res(res)
        face, uv = self.direction_to_uv(d)
        idx = self._uv_index(uv, res, res)
        return np.where(face < 0, -1, face * res * res + idx)

    def solid_angles(self, res: int) -> np.ndarray:
        res = _check_res(res)
        e = (2.0 * np.arange(res + 1) - res) / res
        X, Y = np.meshgrid(e, e)  # Y: rows (tc), X: columns (sc)
        A = np.arctan2(X * Y, np.sqrt(X * X + Y * Y + 1.0))
        face = (A[1:, 1:] - A[1:, :-1]) - (A[:-1, 1:] - A[:-1, :-1])
        return np.broadcast_to(face, (6, res, res)).copy()


# ============================================================================ registry
MAPS: dict[str, SphereMap] = {
    m.name: m for m in (LatLongMap(), ConcentricMap(), OctahedralMap(), AngularMap(),
                        MirrorBallMap(), CubeMap())
}


def get_map(name: str) -> SphereMap:
    """The sphere map called ``name`` (a key of :data:`MAPS`).

    Raises
    ------
    ValueError
        For an unknown name; the message lists the known ones.
    """
    try:
        return MAPS[name]
    except KeyError:
        raise ValueError(f"unknown sphere map {name!r}; known: {', '.join(MAPS)}") from None
