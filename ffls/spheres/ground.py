"""The ground bounce from the photograph itself: each sphere's ground, as the camera sees it.

The bounce model of :mod:`ffls.spheres.lambert` is an infinite uniform ground, ``c g(n)`` with
``g(n) = (1 - n . up) / 2``. A real ground is not uniform: the object's cast shadow falls on it,
its albedo varies, the object hides part of it. But the camera sees most of the ground around
each sphere, in every photo. Here the ground plane under a sphere (the plane through its lowest
point, normal to ``up``: the sphere rests on it) is sampled along a set of equal-solid-angle
directions ``w`` of the lower hemisphere, seen from the sphere's centre; each direction's ground
point is projected into the photo (the capture's camera, pinhole or orthographic) and read there
where the camera sees it (in the frame, not behind or on a sphere, within
:data:`GROUND_REACH` sphere radii of the contact point). Those points are patches of the ground;
from each sphere point, the bounce is the sum over them of their radiance times the point's form
factor to the patch (:meth:`GroundView.kernel`). Only the ground's departure from the uniform
model is taken from the photo (its radiance over ``L_ref``, the median of the lit ground seen
around the sphere, against the uniform model's own shadow; :func:`observed_bounce`): the hidden
ground within reach (behind the sphere) as its nearest seen neighbours, the ground out of reach
as the uniform model has it. A uniform ground then gives the uniform form factor less the own
shadow (:func:`ffls.spheres.lambert.shadowed_ground_bounce`) back, its scale and the capture's
ground ratio their meaning. The object's outline is unknown: :data:`GROUND_REACH` keeps the
ground read near the sphere, and :func:`not_ground` finds, from the photos, the seen points
that are not shaded as the ground plane is (the object within reach), which :func:`mask_view`
then reads as the ground around them (:func:`ffls.spheres.estimate.mask_object_from_ground`).
Measured in docs/spheres.md, "The ground bounce from the photograph".
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from ffls.camera.projection import project_points
from ffls.conventions import UP

__all__ = ["GROUND_DIRECTIONS", "GROUND_MARGIN_PX", "GROUND_REACH", "GROUND_SHADING_RATIO", "GroundView",
           "ground_pixels", "ground_radiance", "ground_views", "hidden_form_factor", "mask_radiance", "mask_view",
           "not_ground", "observed_bounce", "own_shadow_mask", "reference_radiance", "seen_bounce"]

#: Directions of the lower hemisphere at which each sphere's ground is read (equal solid angles).
GROUND_DIRECTIONS = 1024
#: Farthest ground point read, in sphere radii from the contact point along the ground. From the
#: sphere's lowest point (``n = -up``) the ground within ``rho`` radii of the contact holds
#: ``rho^2 / (rho^2 + 1)`` of the cosine-weighted bounce (the centre is one radius up): 98.5% at 8
#: (94% at 4). The ground out of reach is the uniform model's, in the hidden ground's term whose
#: ratio is calibrated (:func:`hidden_form_factor`); from the sphere's upper half that far ground
#: is most of its bounce, and smooth, nearly the direct term's and the ambient's columns, so a
#: calibrated ratio carrying it is pulled by any misfit of the far field (an object 7 radii away
#: that hides the far ground: 11% low at 4 radii, docs/spheres.md, "The hidden ratio's bias").
#: Read out to 8 radii, the photo measures most of it; the object within reach is taken out of
#: the ground by :func:`not_ground`.
GROUND_REACH = 8.0
#: Seen ground points whose radiance a hidden one (behind the sphere) takes, by inverse distance.
FILL_NEIGHBOURS = 4
#: Margin around each sphere's outline, in pixels, within which the ground is not read (the
#: outline's pixels mix sphere and ground).
GROUND_MARGIN_PX = 2.0
#: A seen ground point is not the ground (:func:`not_ground`) where, in some well-exposed photo,
#: its radiance over the ground's (the median of the sphere's seen ground in that photo) exceeds
#: its median over the photos by more than this factor: under distant lights a plane's points
#: share one shading (a point's ratio is its albedo's, lower only in a cast shadow), while a
#: surface that is not horizontal (the object) is shaded by its own normal.
GROUND_SHADING_RATIO = 1.3
#: Photos whose ground (the median of the seen ground) is darker than this fraction of the
#: brightest photo's are not used by :func:`not_ground` (their ratios are noise).
GROUND_MASK_EXPOSURE = 0.1


def _lower_directions(n: int) -> np.ndarray:
    """``n`` unit directions of the lower hemisphere (``z < 0``) with equal solid angles (a
    Fibonacci lattice: rings of equal area in ``z``, golden-angle azimuths)."""
    i = np.arange(n, dtype=np.float64)
    z = -(i + 0.5) / n
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


@dataclass(frozen=True)
class GroundView:
    """Where one sphere's ground is seen in the photos (fixed per capture: camera and sphere).

    Attributes
    ----------
    rows, cols : (p, r) int
        The pixels of each seen direction's read: its bilinear four (``r = 4``), or, after
        :func:`mask_view`, its neighbours' (``r = 4 FILL_NEIGHBOURS``, unused columns weigh 0).
    weights : (p, r) float
        Their weights.
    seen : (D,) bool
        Which of the directions are read (in the frame, not behind a sphere, within reach).
    offsets : (p + h, 3) float
        The ground points, from the sphere's centre, in sphere radii: the ``p`` seen ones, then the
        ``h`` hidden ones within reach (in the frame, behind a sphere).
    areas : (p + h,) float
        The ground area each stands for, in square sphere radii (``dOmega / |w . up|^3``).
    fill_index, fill_weights : (h, k) int, float
        Each hidden point's nearest seen points along the ground and their weights (inverse
        distance, summing to 1): its ground is taken as theirs (:func:`observed_bounce`).
    up : (3,) float
        World up (the ground's normal).
    kappa : float or None
        The sphere's albedo for its seen ground's bounce (:func:`seen_bounce`), calibrated over the
        capture (:func:`ffls.spheres.estimate.calibrate_ground_albedo`): the fits then subtract
        the seen ground's bounce and fit the hidden ground's (:func:`hidden_form_factor`). None:
        the bounce is :func:`observed_bounce`'s (the first pass).
    """

    rows: np.ndarray
    cols: np.ndarray
    weights: np.ndarray
    seen: np.ndarray
    offsets: np.ndarray
    areas: np.ndarray
    fill_index: np.ndarray
    fill_weights: np.ndarray
    up: np.ndarray
    kappa: float | None = None
    _kernels: dict = field(default_factory=dict, compare=False, repr=False)
    _fills: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def n_seen(self) -> int:
        return int(len(self.offsets) - len(self.fill_index))

    def neighbour_fill(self, keep: np.ndarray):
        """(gone (g,), src (g, k), w (g, k)): the seen points not kept, their nearest kept seen points
        and inverse-distance weights; None where all are kept or too few are. Kept in the view per
        ``keep`` (:func:`mask_view` and every photo's :func:`mask_radiance` of a sphere share one)."""
        keep = np.asarray(keep, bool)
        key = keep.tobytes()
        if key in self._fills:
            return self._fills[key]
        fill = None
        if not (keep.all() or keep.sum() < FILL_NEIGHBOURS):
            kept, gone = np.flatnonzero(keep), np.flatnonzero(~keep)
            seen_off = self.offsets[:self.n_seen]
            dist_, near = cKDTree(seen_off[kept]).query(seen_off[gone], k=FILL_NEIGHBOURS)
            w = 1.0 / np.maximum(dist_, 1e-9)
            fill = gone, kept[near], w / w.sum(axis=1, keepdims=True)
        if len(self._fills) > 8:
            self._fills.clear()
        self._fills[key] = fill
        return fill

    def kernel(self, normals: np.ndarray) -> np.ndarray:
        """(m, p + h) float32: the form factor from each sphere point (its unit ``normals``; the point
        is the centre plus a radius along it) to each seen ground patch, as a disc of the patch's
        area facing up: ``cos_p cos_g dA / (pi |r|^2 + dA)`` (Wallace, Elmquist, Haines 1989),
        ``r`` from the point to the patch in radii (a patch near the point is then not an
        infinitely bright point). Kept per ``normals`` array (a capture's fits reuse their
        samples' normals), or a view of the same memory (:func:`memory_key`)."""
        normals = np.asarray(normals)
        key = memory_key(normals)
        hit = self._kernels.get(key)
        if hit is not None:
            return hit[1]
        n = np.asarray(normals, dtype=np.float64)
        out = np.empty((len(n), len(self.offsets)), np.float32)
        for a in range(0, len(n), 1024):  # (in blocks: three (block, p) temporaries)
            r = self.offsets[None, :, :] - n[a:a + 1024, None, :]
            r2 = np.einsum("ijk,ijk->ij", r, r)
            cos_p = np.maximum(np.einsum("ijk,ik->ij", r, n[a:a + 1024]), 0.0)
            out[a:a + 1024] = cos_p * np.maximum(-(r @ self.up), 0.0) / r2 * self.areas / (np.pi * r2 + self.areas)
        if len(self._kernels) > 16:  # (recentred samples replace the first ones; 2 per normals)
            self._kernels.clear()
        self._kernels[key] = (normals, out)  # (the array kept: its memory is not reused while kept)
        return out

    def kernel64(self, normals: np.ndarray) -> np.ndarray:
        """(m, p + h) float64: :meth:`kernel` widened (its float32 values), kept as it is: the
        bounce's matrix-vector products in float64 (:func:`observed_bounce`, :func:`seen_bounce`)
        read it instead of widening the kernel at every fit (the same floats)."""
        normals = np.asarray(normals)
        key = ("float64", memory_key(normals))
        hit = self._kernels.get(key)
        if hit is not None:
            return hit[1]
        out = self.kernel(normals).astype(np.float64)
        self._kernels[key] = (normals, out)
        return out


def memory_key(a: np.ndarray) -> tuple:
    """What :meth:`GroundView.kernel` (and :func:`ffls.spheres.lambert.own_shadow_of`) keeps a result under: the array's memory (address, shape,
    strides, type), not the array object: a worker process's unpickled samples have a dtype that
    is equal to, but not, numpy's own, so ``np.asarray(normals, dtype=np.float64)`` in each fit
    gives a new view of the same normals (``ffls lights --workers 2`` built the kernel per fit)."""
    return (a.__array_interface__["data"][0], a.shape, a.strides, a.dtype.str)


def _camera_frame(world_from_camera) -> tuple[np.ndarray, np.ndarray]:
    M = np.asarray(world_from_camera, dtype=np.float64)
    return M[:3, :3], M[:3, 3]


def _hidden_by_spheres(origin, targets, centers, radii) -> np.ndarray:
    """Whether each segment ``origin -> target`` (origins (3,) or one per target) passes through
    any sphere (centres, inflated radii)."""
    hidden = np.zeros(len(targets), bool)
    origin = np.broadcast_to(origin, targets.shape)
    for c, r in zip(centers, radii):
        d = targets - origin
        length = np.linalg.norm(d, axis=1)
        u = d / length[:, None]
        t = np.clip(np.einsum("ij,ij->i", c - origin, u), 0.0, length)
        closest = origin + u * t[:, None]
        hidden |= np.linalg.norm(closest - c, axis=1) < r
    return hidden


def ground_views(samples, shape: tuple[int, int], camera_model: str, K, dist, world_from_camera,
                 up: np.ndarray = UP, n_dirs: int = GROUND_DIRECTIONS, reach: float = GROUND_REACH,
                 margin_px: float = GROUND_MARGIN_PX) -> list[GroundView]:
    """Each sphere's :class:`GroundView`: where its ground plane's points are seen in the photos.

    Parameters
    ----------
    samples : list of :class:`ffls.spheres.samples.SphereSamples`
        Every sphere of the capture (each one's ground is read where no sphere hides it).
    shape : (H, W)
    camera_model : {'pinhole', 'orthographic'}
    K, dist : the pinhole camera (ignored for an orthographic one)
    world_from_camera : (4, 4)
    up : (3,) float
        World up (``+Z``): the ground is normal to it.
    n_dirs : int
    reach : float
        :data:`GROUND_REACH`.
    margin_px : float
        :data:`GROUND_MARGIN_PX`.
    """
    H, W = int(shape[0]), int(shape[1])
    up = np.asarray(up, dtype=np.float64)
    Rw, tw = _camera_frame(world_from_camera)
    base = _lower_directions(n_dirs)
    # the lattice is about world z: turn it about up (a rotation taking +Z to up)
    if not np.allclose(up, UP):
        v = np.cross(UP, up)
        c = float(UP @ up)
        vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        base = base @ (np.eye(3) + vx + vx @ vx / (1.0 + c)).T
    d_omega = 2.0 * np.pi / n_dirs
    ortho = camera_model == "orthographic"
    centers = np.array([s.center for s in samples], dtype=np.float64)
    scale_px = []  # pixels per world unit near each sphere (for the margin)
    for s in samples:
        if ortho:
            scale_px.append(s.radius_px / s.radius)
        else:
            depth = float(Rw[:, 2] @ (s.center - tw))
            scale_px.append(0.5 * (K[0][0] + K[1][1]) / depth)
    # what depends on no sphere: the directions' slope to the ground, and every sphere's hiding radius
    cos_down = -(base @ up)  # > 0
    sin_down = np.sqrt(np.maximum(1.0 - cos_down ** 2, 0.0))
    radii = np.array([sm.radius + margin_px / sc for sm, sc in zip(samples, scale_px)])
    views = []
    for k, s in enumerate(samples):
        height = s.radius  # the centre's height above the ground it rests on
        t = height / cos_down
        reach_ok = t * sin_down <= reach * s.radius
        X = s.center + base * t[:, None]
        Xc = (X - tw) @ Rw  # camera frame
        if ortho:  # pixel offsets from the sphere's centre pixel, at the sphere's scale
            c_cam = (s.center - tw) @ Rw
            n_cam = s.normals @ Rw
            cx = float(np.mean(s.cols - s.radius_px * n_cam[:, 0]))
            cy = float(np.mean(s.rows - s.radius_px * n_cam[:, 1]))
            px = np.stack([cx + (Xc[:, 0] - c_cam[0]) * scale_px[k], cy + (Xc[:, 1] - c_cam[1]) * scale_px[k]],
                          axis=1)
            view_dir = Rw[:, 2]
            origin = X - view_dir * (100.0 * s.radius + np.abs((X - s.center) @ view_dir)).max()
            in_front = np.ones(len(X), bool)
        else:
            in_front = Xc[:, 2] > 1e-9
            px = np.full((len(X), 2), -1.0)
            if in_front.any():
                px[in_front] = project_points(Xc[in_front], K, dist)
            origin = tw
        ok = reach_ok & in_front & np.isfinite(px).all(axis=1)
        ok &= (px[:, 0] >= 0) & (px[:, 0] <= W - 1) & (px[:, 1] >= 0) & (px[:, 1] <= H - 1)
        framed = ok.copy()  # (in the frame: hidden only by a sphere)
        if ok.any():
            idx = np.flatnonzero(ok)
            o = origin[idx] if np.ndim(origin) == 2 else origin
            ok[idx[_hidden_by_spheres(o, X[idx], centers, radii)]] = False
        x0 = np.clip(np.floor(px[ok, 0]).astype(np.intp), 0, max(W - 2, 0))
        y0 = np.clip(np.floor(px[ok, 1]).astype(np.intp), 0, max(H - 2, 0))
        fx, fy = px[ok, 0] - x0, px[ok, 1] - y0
        rows = np.stack([y0, y0, y0 + 1, y0 + 1], axis=1)
        cols = np.stack([x0, x0 + 1, x0, x0 + 1], axis=1)
        wts = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1)
        # the ground within reach that a sphere hides from the camera: as its nearest seen
        # neighbours (the ground out of the frame is left to the uniform model, as out of reach:
        # filled from the frame's edge out to 8 radii, the test's cast shadow 1.5-4 radii beside
        # the ball spread to 8, tests/test_observed_bounce.py)
        hidden = framed & ~ok
        fill_index = np.zeros((0, FILL_NEIGHBOURS), np.intp)
        fill_weights = np.zeros((0, FILL_NEIGHBOURS))
        if hidden.any() and ok.sum() >= FILL_NEIGHBOURS:
            dist_, fill_index = cKDTree(X[ok]).query(X[hidden], k=FILL_NEIGHBOURS)
            w = 1.0 / np.maximum(dist_, 1e-9 * s.radius)
            fill_weights = w / w.sum(axis=1, keepdims=True)
        else:
            hidden[:] = False
        pts = np.concatenate([X[ok], X[hidden]])
        views.append(GroundView(rows=np.minimum(rows, H - 1), cols=np.minimum(cols, W - 1), weights=wts, seen=ok,
                                offsets=(pts - s.center) / s.radius,
                                areas=d_omega / np.concatenate([cos_down[ok], cos_down[hidden]]) ** 3,
                                fill_index=fill_index, fill_weights=fill_weights, up=up))
    return views


def _upper_quartile(a: np.ndarray, axis: int) -> np.ndarray:
    """The 75th percentile along ``axis`` of the finite values (NaN where none)."""
    with warnings.catch_warnings():  # (an all-NaN slice gives NaN, and says so)
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanpercentile(a, 75, axis=axis)


def not_ground(radiances: np.ndarray, lit: np.ndarray | None = None, ratio: float = GROUND_SHADING_RATIO,
               exposure: float = GROUND_MASK_EXPOSURE) -> np.ndarray:
    """(p,) bool: the seen ground points that are not a Lambertian plane's, from their radiance
    over the photos (the object standing within the sphere's reach, another object, a highlight).

    Under a distant light every point of a horizontal Lambertian plane has the same shading, so
    its radiance over the plane's (the median of the lit points in that photo) is its albedo's
    ratio in every photo where it is lit, and lower where it is in a cast shadow. A point on a
    surface that is not the plane follows its own normal's shading: its ratio rises well above
    its usual one in the photos whose light faces it. A point is flagged where its second-highest
    ratio over the photos where it is outside the sphere's own shadow (one photo's noise or glint
    is not enough) exceeds ``ratio`` times their upper quartile (a point in another cast shadow
    in up to three quarters of the photos keeps its lit ratio there). No outline of the object is
    needed, and the test holds through vignetting and a textured ground (fixed per pixel).

    Parameters
    ----------
    radiances : (n, p) float
        :func:`ground_radiance` of ``n`` photos (rows with a non-finite value are skipped).
    lit : (n, p) bool, optional
        Which points are outside the sphere's own shadow in each photo
        (``~``:func:`own_shadow_mask` under its light); None: all.
    ratio : float
        :data:`GROUND_SHADING_RATIO`.
    exposure : float
        :data:`GROUND_MASK_EXPOSURE`.

    Returns
    -------
    (p,) bool
        True: not the ground. False where fewer than 3 of the photos are usable for the point.
    """
    R = np.asarray(radiances, dtype=np.float64)
    if R.ndim != 2 or R.size == 0:
        return np.zeros(R.shape[-1] if R.ndim == 2 else 0, bool)
    lit = np.ones(R.shape, bool) if lit is None else np.asarray(lit, bool).copy()
    lit &= np.isfinite(R)
    # rank one, robust to shadows (low) and to the object (a few points): each photo's level and
    # each point's albedo, both as upper quartiles of the other's ratios
    level = np.array([np.percentile(r[m], 75) if m.sum() >= 3 else np.nan for r, m in zip(R, lit)])
    good = np.isfinite(level) & (level > 0)
    good &= level > exposure * (level[good].max() if good.any() else 0.0)
    R, lit = np.maximum(R[good], 0.0), lit[good]
    usable = lit.sum(axis=0) >= 3
    out = np.zeros(usable.shape, bool)
    if len(R) < 3 or not usable.any():
        return out
    R, lit, level = R[:, usable], lit[:, usable], level[good]
    for _ in range(3):
        albedo = _upper_quartile(np.where(lit, R / level[:, None], np.nan), axis=0)
        level = _upper_quartile(np.where(lit, R / np.maximum(albedo, 1e-30)[None, :], np.nan), axis=1)
        level = np.where(np.isfinite(level) & (level > 0), level, np.inf)
    q = np.where(lit, R / (level[:, None] * np.maximum(albedo, 1e-30)[None, :]), -np.inf)
    high = -np.sort(-q, axis=0)[1]  # the second highest
    out[usable] = high > ratio
    return out


def mask_radiance(view: GroundView, keep: np.ndarray, radiance: np.ndarray) -> np.ndarray:
    """(p,) float: a photo's :func:`ground_radiance` under the unmasked ``view`` as the masked view
    (:func:`mask_view` of ``view`` and ``keep``) reads it: the points not kept take their
    neighbours' radiance."""
    out = np.array(radiance, dtype=np.float64)
    fill = view.neighbour_fill(keep)
    if fill is not None:
        gone, src, w = fill
        out[gone] = (out[src] * w).sum(axis=1)
    return out


def mask_view(view: GroundView, keep: np.ndarray) -> GroundView:
    """The view with the seen points not in ``keep`` (p,) bool read elsewhere: each is given the
    radiance of its :data:`FILL_NEIGHBOURS` nearest kept seen points along the ground (inverse
    distance; their pixels and bilinear weights, scaled), in every photo. The ground an object
    stands on (or that it hides from the camera) then reads as the ground around it, its shadows
    included. The view itself where fewer than :data:`FILL_NEIGHBOURS` points are kept."""
    fill = view.neighbour_fill(keep)
    if fill is None:
        return view
    p = view.n_seen
    gone, src, w = fill
    width = 4 * FILL_NEIGHBOURS
    rows = np.repeat(view.rows[:, :1], width, axis=1)  # (a kept point's extra columns weigh 0)
    cols = np.repeat(view.cols[:, :1], width, axis=1)
    weights = np.zeros((p, width))
    rows[:, :4], cols[:, :4], weights[:, :4] = view.rows, view.cols, view.weights
    rows[gone] = view.rows[src].reshape(len(gone), width)
    cols[gone] = view.cols[src].reshape(len(gone), width)
    weights[gone] = (view.weights[src] * w[:, :, None]).reshape(len(gone), width)
    return replace(view, rows=rows, cols=cols, weights=weights, _kernels={}, _fills={})


def ground_pixels(views: list[GroundView]) -> tuple[np.ndarray, np.ndarray]:
    """The pixels every view reads (rows, cols), e.g. to linearise an integer photo there."""
    if not views:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    return (np.concatenate([v.rows.ravel() for v in views]).astype(np.intp),
            np.concatenate([v.cols.ravel() for v in views]).astype(np.intp))


def ground_radiance(view: GroundView, image: np.ndarray) -> np.ndarray | None:
    """(p,) float64: the seen directions' ground radiance in one photo's linear ``image`` (H, W[, C])
    (grey: the channels' mean); None where none is seen or a value is not finite."""
    if view.n_seen == 0:
        return None
    px = np.asarray(image)[view.rows, view.cols].astype(np.float64)
    if px.ndim == 3:
        px = px.mean(axis=-1)
    L = np.sum(px * view.weights, axis=1)
    return L if np.all(np.isfinite(L)) else None


def own_shadow_mask(view: GroundView, light: np.ndarray) -> np.ndarray:
    """(p + h,) bool: the ground points (seen, then hidden) in the sphere's own shadow under the
    distant ``light``."""
    light = np.asarray(light, dtype=np.float64)
    light = light / np.linalg.norm(light)
    tc = -view.offsets @ light  # along the light from the ground point to the centre
    d2 = np.einsum("ij,ij->i", view.offsets, view.offsets) - tc * tc
    return (tc > 0) & (d2 < 1.0)


def observed_bounce(view: GroundView, radiance: np.ndarray | None, light: np.ndarray, uniform: np.ndarray,
                    normals: np.ndarray) -> np.ndarray:
    """The bounce's form factor (m,) with the photographed ground in place of a uniform one.

    ``uniform`` is the uniform ground's form factor less the sphere's own shadow under ``light``
    (:func:`ffls.spheres.lambert.shadowed_ground_bounce`), for a ground of radiance ``L_ref``: the
    median of the seen ground outside the own shadow. Where the ground is seen, its departure from
    that model, ``L(w) / L_ref - (1 - shadow(w))``, is added with its cosine weights; where it is
    hidden within reach (behind the sphere, in the frame), it is taken as bright as its
    nearest seen points that are lit (:attr:`GroundView.fill_index`); out of reach or of the frame, the uniform
    model stands. A
    uniform ground gives ``uniform`` back, so the ground ratio of
    :func:`ffls.spheres.estimate.calibrate_bounce` keeps its meaning (``L_ref`` is the uniform
    ground's radiance).

    Parameters
    ----------
    view : GroundView
    radiance : (p,) float or None
        :func:`ground_radiance` of the photo (None: ``uniform`` is returned).
    light : (3,) float
        The light's direction (the own shadow's).
    uniform : (m,) float
    normals : (m, 3) float
        The sphere's sample normals (world frame).

    Returns
    -------
    (m,) float, >= 0
    """
    uniform = np.asarray(uniform, dtype=np.float64)
    if radiance is None:
        return uniform
    lit = ~own_shadow_mask(view, light)
    p = view.n_seen
    seen_lit = lit[:p]
    if seen_lit.sum() < 3:
        return uniform
    ref = float(np.median(radiance[seen_lit]))
    if not ref > 0:
        return uniform
    q = radiance / ref
    # a hidden point (behind the sphere) is lit as the model has it (its own shadow), its ground
    # as bright as its seen neighbours' that are lit (none: as the reference)
    w = view.fill_weights * seen_lit[view.fill_index]
    total = w.sum(axis=1)
    near = np.where(total > 0, (w * q[view.fill_index]).sum(axis=1) / np.where(total > 0, total, 1.0), 1.0)
    dev = np.concatenate([q - seen_lit, lit[p:] * (near - 1.0)])
    # (the ground out of reach stays as the uniform model has it: filling all the unseen ground
    # with the seen ground's mean spread a cast shadow beside the sphere all round it, and
    # tripled the test's errors, tests/test_observed_bounce.py)
    return np.maximum(uniform + view.kernel64(normals) @ dev, 0.0)


def reference_radiance(view: GroundView, radiance: np.ndarray, light: np.ndarray) -> float:
    """``L_ref`` of :func:`observed_bounce`: the median radiance of the seen ground outside the
    sphere's own shadow under ``light`` (NaN where fewer than 3 such points)."""
    lit = ~own_shadow_mask(view, light)[:view.n_seen]
    return float(np.median(np.asarray(radiance)[lit])) if lit.sum() >= 3 else float("nan")


def seen_bounce(view: GroundView, radiance: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(m,) float: the irradiance over pi that the SEEN ground sends each sphere point, in the
    photo's own linear units (``sum_j K_j L_j``): times the sphere's albedo, its pixels' bounce
    from that ground. The albedo is one constant of the sphere for the capture (measured in
    docs/spheres.md, "Two terms")."""
    return view.kernel64(normals)[:, :view.n_seen] @ np.asarray(radiance, dtype=np.float64)


def hidden_form_factor(view: GroundView, light: np.ndarray, uniform: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(m,) float: the form factor of the ground the camera does NOT see (behind the sphere, out of
    the frame or of reach), lit, under ``light``: the uniform model less the own shadow
    (``uniform``, :func:`ffls.spheres.lambert.shadowed_ground_bounce`) less the seen points'
    lit share. With :func:`seen_bounce` it splits the bounce into a measured part and one whose
    ground ratio is calibrated over the capture like the uniform model's."""
    lit = ~own_shadow_mask(view, light)[:view.n_seen]
    K = view.kernel(normals)[:, :view.n_seen]
    return np.maximum(np.asarray(uniform, dtype=np.float64) - K @ lit, 0.0)
