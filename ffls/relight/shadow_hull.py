"""The object's shadow hull: its volume carved from the capture's own cast shadows on the ground.

Where a calibration sphere hides a ground pixel ``p`` from a light direction ``d``, no photo holds
the object's shadow at ``p`` under ``d`` (:mod:`ffls.relight.sphere_shadows`): the pixel is dark
in the object capture and in the surface capture alike, so differential rendering shows no object
shadow there. The object's shadow is geometry, though: ``p`` is shadowed under ``d`` when the ray
from ``p`` toward ``d`` meets the object. The capture's other photos constrain that geometry from
every other light, and this module recovers it by *shadow carving*: a point of space is empty when
some light projects it onto a ground pixel that the camera sees lit (Savarese, Andreetto,
Rushmeier, Bernardini and Perona, "3D Reconstruction by Shadow Carving: Theory and Practical
Evaluation", IJCV 2007; here with the ground plane as the shadow receiver, as in shadow-volume
reconstruction from a turntable's cast shadows), intersected with the camera's silhouette (the
object's mask: Laurentini's visual hull, 1994). What is left contains the object (a point of the
object is never seen through), so its shadows contain the object's shadows; with many lights it
is close to them except in concavities that no shadow reveals. It also keeps the space whose
shadows no photo shows at all: ground the camera does not see (behind the object, behind and
under a calibration sphere) or that a sphere shades under every light that would reach it. Such a
voxel is not evidence of the object, and beside a sphere its shadow runs along the sphere's own,
where the hull is used (:data:`MIN_SHADOWS`): a voxel stays only where some photos see its
projection in shadow.

* :func:`lit_photos` gives, per photo and ground pixel, the photo's visibility of its light: its
  luminance over the pixel's unshadowed linear model's
  (:func:`ffls.relight.lightflow.unshadowed_fit` over all photos, the sphere-hidden ones left
  out), and whether it says anything there at all (ground the camera sees, not hidden by a
  sphere). A pixel is lit at
  :data:`ffls.relight.lightflow.SHADOW_LEVEL` or more; carving reads the visibility bilinearly at a
  voxel's projection, so the shadows' edges are placed between pixels.
* :class:`ShadowHull` is the carved voxel grid (:meth:`ShadowHull.carve`) and the query
  :meth:`ShadowHull.shadow`: the fraction of a ray from ground points toward a direction that the
  hull blocks (trilinear occupancy, the maximum along the ray).

Directional lights only: a photo with a near light position is not used for carving.
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from ffls.camera.projection import project_points
from ffls.errors import InputError
from ffls.relight.lightflow import LUMINANCE, SHADOW_LEVEL, unshadowed_fit
from ffls.relight.sphere_shadows import ground_points

__all__ = ["MAX_CELLS", "MIN_VOTES", "MIN_SHADOWS", "VISIBILITY_STEPS", "lit_photos",
           "visibility_codes", "ShadowHull"]

#: The hull's grid has at most this many voxels along its longest side.
MAX_CELLS = 160
#: A voxel is carved when at least this many photos see its ground projection lit: one photo lit
#: by mistake (noise, a light direction a little off at a shadow's edge) does not carve the object.
MIN_VOTES = 2
#: A voxel stays only where at least this many photos see its ground projection in shadow: a voxel
#: whose shadow no photo shows (ground hidden from the camera by the object or a calibration
#: sphere, or in a sphere's shadow, under every light) is not evidence of the object. Uncarved and
#: unseen, it would cast a shadow where the captures saw none; beside a sphere it casts it along
#: the sphere's own shadow, where the fill then darkens the ground (docs/composite.md).
MIN_SHADOWS = 2
#: Visibility is held in steps of 1 / VISIBILITY_STEPS (:func:`visibility_codes`: one byte per photo
#: and pixel, 0 meaning not known).
VISIBILITY_STEPS = 254
#: Rows of pixels per chunk of :func:`lit_photos` (the fit holds (rows x W x n) values).
_FIT_PIXELS = 1 << 14


def lit_photos(basis, directions, ground, hidden=None, *, shadow_level: float = SHADOW_LEVEL):
    """Per photo and pixel: is the ground lit, and is it known at all.

    Parameters
    ----------
    basis : (n, H, W, 3) float array
        The capture's photos.
    directions : (n, 3) array_like
        Unit light directions.
    ground : (H, W) bool
        Pixels where the camera sees the ground (not the object, not a sphere).
    hidden : (n, H, W) bool, optional
        :func:`ffls.relight.sphere_shadows.hidden_photos`: photos that see a pixel through a
        calibration sphere say nothing of the object's shadow there.
    shadow_level : float

    Returns
    -------
    visibility : (n, H, W) float32
        The photo's luminance over the unshadowed model's, clipped to [0, 1] (in steps of
        1 / :data:`VISIBILITY_STEPS`); 0 where not known.
    known : (n, H, W) bool
        The photo says whether the object shadows the pixel (ground, not hidden, a model that
        predicts light). The pixel is lit where it is known and ``visibility >= shadow_level``.
    umbra : float
        The median visibility (photo over model) of the known pixels that are not lit: the light
        that reaches the object's shadows anyway (bounce from the object and the ground); 0 where
        no pixel is shadowed.
    """
    codes, umbra = visibility_codes(basis, directions, ground, hidden, shadow_level=shadow_level)
    vis, known = _decoded(codes)
    return vis, known, umbra


def visibility_codes(basis, directions, ground, hidden=None, *,
                     shadow_level: float = SHADOW_LEVEL) -> tuple[np.ndarray, float]:
    """:func:`lit_photos` in one byte per photo and pixel: 0 where not known, else
    ``1 + round(visibility * VISIBILITY_STEPS)``.

    The carving reads every photo whole, while the unshadowed fit needs every photo of a pixel, so
    the visibilities are held for all photos at once: one byte each (1 GiB for 1000 photos of
    1024 x 1024 px, where float32 and a mask took 5). Same parameters as :func:`lit_photos`.

    Returns
    -------
    codes : (n, H, W) uint8
    umbra : float
        As :func:`lit_photos` (the median from a histogram of 1 / :data:`VISIBILITY_STEPS` bins).
    """
    n, H, W, _ = basis.shape
    d = np.asarray(directions, dtype=np.float64).reshape(n, 3)
    g = np.asarray(ground, dtype=bool)
    if g.shape != (H, W):
        raise InputError(f"the ground mask {g.shape} does not match the photos ({H}, {W})")
    codes = np.zeros((n, H, W), dtype=np.uint8)
    dark = np.zeros(VISIBILITY_STEPS + 1, dtype=np.int64)
    rows = max(1, _FIT_PIXELS // max(W, 1))
    for y0 in range(0, H, rows):
        sl = slice(y0, min(H, y0 + rows))
        if not g[sl].any():
            continue
        photos = np.asarray(basis[:, sl], dtype=np.float32)
        prior = None
        if hidden is not None:
            prior = (~np.asarray(hidden[:, sl], dtype=bool)).astype(np.float64)
        b = unshadowed_fit(photos, d, shadow_level=shadow_level, prior=prior)
        pred = np.einsum("hwci,ki->khwc", np.nan_to_num(b), d) @ LUMINANCE
        ok = g[sl][None] & np.all(np.isfinite(b), axis=(-2, -1))[None] & (pred > 0)
        if prior is not None:
            ok &= prior.astype(bool)
        lum = photos @ LUMINANCE.astype(np.float32)
        v = np.where(ok, lum / np.where(ok, pred, 1.0), 0.0)
        steps = np.rint(np.clip(v, 0.0, 1.0) * VISIBILITY_STEPS).astype(np.int64)
        codes[:, sl] = np.where(ok, 1 + steps, 0).astype(np.uint8)
        dark += np.bincount(steps[ok & (v < shadow_level)], minlength=VISIBILITY_STEPS + 1)
    umbra = 0.0
    if dark.sum():
        umbra = float(np.searchsorted(np.cumsum(dark), 0.5 * dark.sum())) / VISIBILITY_STEPS
    return codes, float(np.clip(umbra, 0.0, 1.0))


def _decoded(codes) -> tuple[np.ndarray, np.ndarray]:
    """Visibility (float32, 0 where not known) and known (bool) of :func:`visibility_codes`."""
    codes = np.asarray(codes)
    known = codes > 0
    vis = np.where(known, (codes.astype(np.float32) - 1.0) / VISIBILITY_STEPS, 0.0)
    return vis.astype(np.float32), known


class ShadowHull:
    """A voxel grid of the space the object may fill, carved by its cast shadows.

    Parameters
    ----------
    occupancy : (nx, ny, nz) float32
        1 where the hull is, 0 where it is carved.
    origin : (3,) float
        World position of voxel (0, 0, 0)'s centre.
    voxel : float
        Edge of a voxel (world units).

    Attributes
    ----------
    umbra : float
        The light left in the object's shadows, as a fraction of the unshadowed ground
        (:func:`lit_photos`).
    votes : (nx, ny, nz) int32 or None
        Per voxel, the photos that saw its ground projection lit (:meth:`carve`).
    """

    def __init__(self, occupancy, origin, voxel: float, umbra: float = 0.0, votes=None):
        self.occupancy = np.asarray(occupancy, dtype=np.float32)
        self.origin = np.asarray(origin, dtype=np.float64).reshape(3)
        self.voxel = float(voxel)
        self.umbra = float(umbra)
        self.votes = votes

    @property
    def top(self) -> float:
        """Height (z) of the grid's top face."""
        return float(self.origin[2] + (self.occupancy.shape[2] - 0.5) * self.voxel)

    @classmethod
    def carve(cls, basis, directions, object_mask, K, world_from_camera, *, ground=None,
              hidden=None, dist=None, max_height: float | None = None, min_votes: int = MIN_VOTES,
              min_shadows: int = MIN_SHADOWS, max_cells: int = MAX_CELLS,
              shadow_level: float = SHADOW_LEVEL) -> "ShadowHull":
        """Carve the hull of an object standing on the plane z = 0 from its capture.

        Parameters
        ----------
        basis : (n, H, W, 3) float array
            The object capture's photos.
        directions : (n, 3) array_like
            Their unit light directions (distant lights).
        object_mask : (H, W) bool or float
            The object's coverage in the camera (> 0.5: object).
        K : (3, 3) array_like
        world_from_camera : (4, 4) array_like
            The camera (OpenCV axes), in a world whose ground is z = 0.
        ground : (H, W) bool, optional
            Pixels where the camera sees the ground (default: every pixel whose ray meets the
            ground, off the object mask). Leave the calibration spheres out.
        hidden : (n, H, W) bool, optional
            :func:`ffls.relight.sphere_shadows.hidden_photos` of these photos.
        dist : array_like, optional
            OpenCV distortion.
        max_height : float, optional
            The grid's top (default: 0.9 of the camera's height above the ground).
        min_votes : int
            :data:`MIN_VOTES`.
        min_shadows : int
            :data:`MIN_SHADOWS` (0 keeps every voxel no photo sees lit: the strict hull, which
            contains the object and the space whose shadows no photo shows).
        max_cells : int
            :data:`MAX_CELLS`.
        shadow_level : float

        Returns
        -------
        ShadowHull
        """
        basis = np.asarray(basis)
        n, H, W, _ = basis.shape
        d = np.asarray(directions, dtype=np.float64).reshape(n, 3)
        M = np.asarray(world_from_camera, dtype=np.float64)
        obj = np.asarray(object_mask, dtype=np.float64) > 0.5
        if obj.shape != (H, W):
            raise InputError(f"the object mask {obj.shape} does not match the photos ({H}, {W})")
        if not obj.any():
            raise InputError("the object mask is empty: no hull to carve")
        C = M[:3, 3]
        if not C[2] > 0:
            raise InputError("the camera must be above the ground (z > 0) to carve the object's "
                             "hull")
        pts = ground_points(K, M, (W, H), dist=dist)
        on_plane = np.all(np.isfinite(pts), axis=-1)
        if ground is None:
            ground = on_plane & ~obj
        ground = np.asarray(ground, dtype=bool) & on_plane & ~obj
        top = 0.9 * C[2] if max_height is None else float(max_height)
        if not top > 0:
            raise InputError(f"max_height must be > 0, not {max_height}")
        # Every point of the object lies on a mask pixel's ray between the camera and the ground.
        sil = cv2.dilate(obj.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & on_plane
        G = pts[sil]
        ends = np.concatenate([G, G + (top / C[2]) * (C - G)])
        lo, hi = ends.min(0), ends.max(0)
        lo[2], hi[2] = 0.0, top
        focal = float(np.asarray(K, dtype=np.float64)[0, 0])
        footprint = float(np.median(np.linalg.norm(G - C, axis=-1))) / focal
        codes, umbra = visibility_codes(basis, d, ground, hidden, shadow_level=shadow_level)
        hull = None
        for _ in range(2):
            # Coarse to fine: the first grid spans every place the camera allows, the second the
            # first one's hull (plus two voxels), at the pixels' footprint where the cap allows.
            voxel = max(footprint, float((hi - lo).max()) / max_cells)
            hull = cls._carved(lo, hi, voxel, sil, codes, d, K, M, dist, int(min_votes),
                               int(min_shadows), umbra, float(shadow_level))
            occ = np.argwhere(hull.occupancy > 0)
            if occ.size == 0 or voxel <= footprint:
                break
            lo = np.maximum(lo, hull.origin + (occ.min(0) - 2.5) * hull.voxel)
            hi = np.minimum(hi, hull.origin + (occ.max(0) + 2.5) * hull.voxel)
        return hull

    @classmethod
    def _carved(cls, lo, hi, voxel, sil, codes, d, K, M, dist, min_votes, min_shadows, umbra,
                level) -> "ShadowHull":
        """One carving of the box ``lo``-``hi`` at ``voxel`` (see :meth:`carve`)."""
        shape = np.maximum(np.ceil((hi - lo) / voxel).astype(int), 1)
        origin = lo + 0.5 * voxel
        axes = [origin[i] + voxel * np.arange(shape[i]) for i in range(3)]
        X = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        # The camera's silhouette (visual hull).
        cand = np.flatnonzero(_lookup(sil, _pixels(X, K, M, dist)))
        votes = np.zeros(cand.size, dtype=np.int32)
        shadows = np.zeros(cand.size, dtype=np.int32)
        Xc = X[cand]
        for i in range(d.shape[0]):
            if not d[i, 2] > 0:
                continue
            q = _ground_pixels_along(Xc, d[i], K, M, dist)
            vis, known = _decoded(codes[i])
            seen = _lookup(known, q)
            lit = _bilinear(vis, q) >= level
            votes += seen & lit
            shadows += seen & ~lit
        occ = np.zeros(X.shape[0], dtype=np.float32)
        occ[cand] = ((votes < min_votes) & (shadows >= min_shadows)).astype(np.float32)
        all_votes = np.zeros(X.shape[0], dtype=np.int32)
        all_votes[cand] = votes
        return cls(occ.reshape(shape), origin, voxel, umbra, all_votes.reshape(shape))

    def visibility(self, points, direction) -> np.ndarray:
        """(q,) the fraction of a distant light from ``direction`` reaching ``points``:
        ``1 - shadow (1 - umbra)`` (:meth:`shadow`, :attr:`umbra`)."""
        return 1.0 - self.shadow(points, direction) * (1.0 - self.umbra)

    def shadow(self, points, direction) -> np.ndarray:
        """How much of a distant light from ``direction`` the hull blocks at ``points``.

        Parameters
        ----------
        points : (q, 3) float array
            World points (ground points; NaN rows give 0).
        direction : (3,) array_like
            Unit direction toward the light.

        Returns
        -------
        (q,) float64 in [0, 1]
            The largest trilinear occupancy along the ray from each point toward the light, within
            the grid (1: the ray passes through the hull's interior).
        """
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        dvec = np.asarray(direction, dtype=np.float64).reshape(3)
        dvec = dvec / np.linalg.norm(dvec)
        out = np.zeros(P.shape[0])
        ok = np.all(np.isfinite(P), axis=-1)
        if not ok.any() or not self.occupancy.any():
            return out
        shape = np.array(self.occupancy.shape)
        lo = self.origin - 0.5 * self.voxel
        hi = lo + shape * self.voxel
        with np.errstate(divide="ignore", invalid="ignore"):
            t0 = (lo - P[ok]) / dvec
            t1 = (hi - P[ok]) / dvec
        tn = np.where(np.isnan(t0), -np.inf, np.minimum(t0, t1)).max(1)
        tf = np.where(np.isnan(t1), np.inf, np.maximum(t0, t1)).min(1)
        tn = np.maximum(tn, 0.0)
        hit = tf > tn
        steps = int(2 * np.ceil(np.linalg.norm(shape))) + 1
        s = np.linspace(0.0, 1.0, steps)
        best = np.zeros(hit.sum())
        Pk, tnk, tfk = P[ok][hit], tn[hit], tf[hit]
        for j in range(0, steps, 64):
            t = tnk[:, None] + (tfk - tnk)[:, None] * s[None, j:j + 64]
            Y = Pk[:, None, :] + t[..., None] * dvec
            idx = ((Y - self.origin) / self.voxel).reshape(-1, 3).T
            v = map_coordinates(self.occupancy, idx, order=1, mode="constant", cval=0.0)
            best = np.maximum(best, v.reshape(t.shape).max(1))
        res = np.zeros(ok.sum())
        res[hit] = best
        out[ok] = np.clip(res, 0.0, 1.0)
        return out


def _ground_pixels_along(X, direction, K, M, dist) -> np.ndarray:
    """Pixels (m, 2) of the ground points (z = 0) below world points ``X`` (m, 3) along
    ``direction`` (z > 0; NaN behind the camera). Without distortion the map from ``X`` to the
    pixel is one 3 x 3 matrix per direction (the shift along it, then the camera's), so the
    ground points themselves are never formed."""
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    if dist is not None and np.any(np.asarray(dist, dtype=np.float64)):
        return _pixels(X - (X[:, 2] / direction[2])[:, None] * direction, K, M, dist)
    # fx, fy, cx, cy as cv2.projectPoints reads them (no skew)
    Kp = np.array([[K[0, 0], 0.0, K[0, 2]], [0.0, K[1, 1], K[1, 2]], [0.0, 0.0, 1.0]])
    shift = np.eye(3)
    shift[:, 2] -= direction / direction[2]
    A = Kp @ M[:3, :3].T
    h = X @ (A @ shift).T - A @ M[:3, 3]
    px = np.full((X.shape[0], 2), np.nan)
    front = h[:, 2] > 1e-9
    px[front] = h[front, :2] / h[front, 2:]
    return px


def _pixels(X, K, M, dist) -> np.ndarray:
    """World points (m, 3) to pixels (m, 2); NaN behind the camera."""
    cam = (X - M[:3, 3]) @ M[:3, :3]
    px = np.full((X.shape[0], 2), np.nan)
    front = cam[:, 2] > 1e-9
    if front.any():
        px[front] = project_points(cam[front], K, dist)
    return px


def _bilinear(image, px) -> np.ndarray:
    """(m,) ``image`` (H, W) read bilinearly at pixels ``px`` (m, 2) (0 outside or at NaN)."""
    ok = np.all(np.isfinite(px), axis=-1)
    out = np.zeros(px.shape[0])
    if ok.any():
        out[ok] = map_coordinates(image, [px[ok, 1], px[ok, 0]], order=1, mode="constant", cval=0.0)
    return out


def _lookup(mask, px) -> np.ndarray:
    """``mask`` at the nearest pixel of each ``px`` (False outside the image or NaN)."""
    H, W = mask.shape
    ok = np.all(np.isfinite(px), axis=-1)
    ij = np.zeros((px.shape[0], 2), dtype=np.int64)
    ij[ok] = np.rint(px[ok]).astype(np.int64)
    ok &= (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)
    out = np.zeros(px.shape[0], dtype=bool)
    out[ok] = mask[ij[ok, 1], ij[ok, 0]]
    return out
