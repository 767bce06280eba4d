"""The calibration spheres' shadows on the ground, and relighting that does not see them.

A capture's calibration spheres sit on the surface the object stands on, and every basis photo
holds their cast shadows. A virtual scene has no spheres, so differential rendering
(:mod:`ffls.relight.composite`) must not carry them over; and where photo ``i`` has ``p`` in a
sphere's shadow it holds nothing of what ``p`` would look like under light ``i`` without the
sphere: not the surface's brightness, not the object's shadow or bounce there. Those (photo,
pixel) pairs are *missing*, in the object-on-surface capture and in the surface-alone capture
alike, and this module fills them from the photos that do see ``p``.

* :func:`ground_points` puts each pixel's camera ray on the ground plane.
* :func:`hidden_photos` says, from geometry alone (the ground points, the spheres' world centres
  and radius, each photo's light direction or position, and its 95% direction cone as a margin),
  which photos have which pixels in a sphere's shadow: ``(n, H, W)`` bool.
* :class:`SphereShadowFill` is the fill: per pixel, the weights of the hidden photos go to the
  photos that see the pixel, by the barycentric weights of each hidden photo's direction over
  the spherical Delaunay triangulation of the visible photos alone
  (:class:`ffls.weights.barycentric.Barycentric` restricted to them: the weighting the pixel
  would get had the hidden photos never been taken). :meth:`SphereShadowFill.weights_correction`
  gives, per pixel, the change of every photo's weight; :meth:`SphereShadowFill.relight` adds it
  to a relit image (the CPU reference of the weighted sum with the correction). A compact source
  interpolated between its triangle's photos (:mod:`ffls.relight.lightflow`) is, where the source
  itself would be hidden by a sphere (:meth:`SphereShadowFill.hidden_for`), taken from the visible
  photos' blend at its direction (:meth:`SphereShadowFill.source_image`).

Measured on the Mitsuba benchmark (docs/composite.md, "Filling the spheres' shadows"): filling the
rest's weights gains 0.1-1 point of the change-region error, filling the sources loses under a sun.

Pixels are grouped by their set of hidden photos (a few hundred to a few thousand distinct sets in
a capture), so one triangulation serves every pixel of a group.
"""
from __future__ import annotations

import cv2
import numpy as np

from ffls.camera.projection import camera_rays
from ffls.conventions import check_hemisphere
from ffls.errors import InputError
from ffls.relight.lightflow import FIT_NEIGHBOURS, unshadowed_fit
from ffls.weights.barycentric import Barycentric
from ffls.weights.voronoi import unique_directions

__all__ = ["ground_points", "hidden_photos", "SphereShadowFill"]


def ground_points(K, world_from_camera, size, plane_point=(0.0, 0.0, 0.0), plane_normal=(0.0, 0.0, 1.0),
                  dist=None) -> np.ndarray:
    """World points where each pixel's camera ray meets the ground plane.

    Parameters
    ----------
    K : (3, 3) array_like
        Pinhole intrinsics (pixel centres at integer coordinates, OpenCV).
    world_from_camera : (4, 4) array_like
        Camera pose (OpenCV axes: +z forward).
    size : (int, int)
        ``(W, H)`` of the photos.
    plane_point, plane_normal : (3,) array_like
        The ground plane (world frame).
    dist : array_like, optional
        OpenCV distortion coefficients.

    Returns
    -------
    (H, W, 3) float64
        NaN where the ray misses the plane (parallel to it, or meets it behind the camera).
    """
    W, H = (int(v) for v in size)
    M = np.asarray(world_from_camera, dtype=np.float64)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise InputError(f"world_from_camera must be a finite 4x4 matrix, not of shape {M.shape}")
    n = np.asarray(plane_normal, dtype=np.float64)
    if n.shape != (3,) or not np.linalg.norm(n) > 0:
        raise InputError("the ground plane's normal must be a non-zero 3-vector")
    n = n / np.linalg.norm(n)
    jj, ii = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = camera_rays(np.stack([ii.ravel(), jj.ravel()], -1), "pinhole", K, dist) @ M[:3, :3].T
    origin = M[:3, 3]
    den = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((np.asarray(plane_point, dtype=np.float64) - origin) @ n) / den
    t = np.where(np.isfinite(t) & (t > 0), t, np.nan)
    return (origin + t[:, None] * rays).reshape(H, W, 3)


def hidden_photos(points, centres, radius, directions=None, positions=None, margin_deg=0.0,
                  dilate_px: int = 1) -> np.ndarray:
    """Which photos see which ground points through a calibration sphere.

    Parameters
    ----------
    points : (H, W, 3) float
        Ground points (:func:`ground_points`; NaN: no ground there, never hidden).
    centres : (k, 3) array_like
        The spheres' world centres.
    radius : float
        Their radius (world units).
    directions : (n, 3) array_like, optional
        Unit directions towards each photo's (distant) light.
    positions : (n, 3) array_like, optional
        Each photo's near light position (world); wins over ``directions`` where given (rows of NaN:
        use the direction).
    margin_deg : float or (n,) array_like
        Widening of each shadow (degrees, the shadow cone's half-angle grows by it): the light
        direction's 95% uncertainty cone (``lights.json``'s ``uncertainty_deg``) plus the light's
        own angular radius, where the photos' penumbra is wider than the sphere's edge.
    dilate_px : int
        The masks are grown by this many pixels (a pixel's footprint straddles the shadow's edge;
        the spheres' centres carry their own error).

    Returns
    -------
    (n, H, W) bool
    """
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3:
        raise InputError(f"ground points must have shape (H, W, 3), not {P.shape}")
    C = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    r = float(radius)
    if not r > 0 or not np.all(np.isfinite(C)):
        raise InputError("the calibration spheres need finite centres and a radius > 0")
    if directions is None and positions is None:
        raise InputError("hidden_photos needs the photos' light directions or positions")
    D = None if directions is None else np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    L = None if positions is None else np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    n = (D if D is not None else L).shape[0]
    margin = np.broadcast_to(np.asarray(margin_deg, dtype=np.float64), (n,))
    H, W = P.shape[:2]
    out = np.zeros((n, H, W), dtype=bool)
    valid = np.all(np.isfinite(P), axis=-1)
    pts = P[valid]
    # Per sphere, the points' offsets and squared distances, shared by every photo.
    offsets = [(c - pts, np.einsum("ij,ij->i", c - pts, c - pts)) for c in C]
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * dilate_px + 1, 2 * dilate_px + 1)) if dilate_px > 0 else None
    for i in range(n):
        near = L is not None and np.all(np.isfinite(L[i]))
        if near:
            to_light = L[i] - pts
            reach = np.linalg.norm(to_light, axis=-1)
            d = to_light / np.maximum(reach, 1e-300)[:, None]
        else:
            if D is None or not np.all(np.isfinite(D[i])) or not np.linalg.norm(D[i]) > 0:
                raise InputError(f"photo {i}: no light position and no usable light direction")
            d = np.broadcast_to(D[i] / np.linalg.norm(D[i]), pts.shape)
            reach = np.full(pts.shape[0], np.inf)
        tan_m = np.tan(np.radians(margin[i]))
        hit = np.zeros(pts.shape[0], dtype=bool)
        for v, vv in offsets:
            along = np.einsum("ij,ij->i", v, d)
            cone = r + along * tan_m
            # The distance from the ray by |v|^2 - along^2 picks the candidates (with a margin for its
            # rounding); the exact test below decides them, as for every point before.
            near_ray = vv - along ** 2 < (1 + 1e-6) * cone ** 2 + 1e-12 * vv
            k = np.flatnonzero((along > 0) & (along < reach) & near_ray)
            off = np.linalg.norm(v[k] - along[k, None] * d[k], axis=-1)
            hit[k] |= off < cone[k]
        m = np.zeros((H, W), dtype=bool)
        m[valid] = hit
        if kernel is not None and m.any():
            m = cv2.dilate(m.astype(np.uint8), kernel).astype(bool) & valid
        out[i] = m
    return out


#: Photo x pixel values per chunk of :meth:`SphereShadowFill.source_model`'s fit (float32 photos and a
#: float64 prior: about 170 MB), so that relighting every ground pixel of a large photo
#: (``everywhere``) holds one chunk at a time.
MODEL_CHUNK_VALUES = 1 << 23


class SphereShadowFill:
    """Per-pixel re-weighting over the photos that see each pixel (see the module notes).

    Parameters
    ----------
    hidden : (n, H, W) bool
        :func:`hidden_photos` (restricted by the caller to the pixels that lie on the ground).
    directions : (n, 3) array_like
        The photos' unit light directions (as the relighter weights them).
    hemisphere : {'upper', 'full'} or Hemisphere

    Attributes
    ----------
    groups : list of (hidden_idx (m,) int, pixels (q,) int, visible_idx (k,) int)
        Per distinct set of hidden photos: the photos, the flat pixel indices having exactly that
        set, and the photos that see them. Their triangulation (:meth:`triangulation`) is built
        on first use: the rest's fill and the blend need one per group (thousands of groups, a
        minute and 0.7 GB for 200 lights at 128 px), the model fill (:meth:`source_model`) none.
    """

    def __init__(self, hidden, directions, hemisphere="upper", *, geometry: dict | None = None):
        hid = np.asarray(hidden, dtype=bool)
        d = np.asarray(directions, dtype=np.float64)
        if hid.ndim != 3 or d.shape != (hid.shape[0], 3):
            raise InputError(f"hidden masks {hid.shape} do not match {d.shape[0] if d.ndim == 2 else '?'} light directions")
        self.hemisphere = check_hemisphere(hemisphere)
        #: :func:`hidden_photos`' keywords (``points``, ``centres``, ``radius``, ...) to find any
        #: direction's sphere shadows (a compact source's), or None.
        self.geometry = None if geometry is None else dict(geometry)
        if self.geometry is not None and "points" in self.geometry:  # (float64 once, as every use reads it)
            self.geometry["points"] = np.asarray(self.geometry["points"], dtype=np.float64)
        self._ground: np.ndarray | None = None  # ground_pixels(), made on first use
        self.shape = hid.shape[1:]
        self.n = hid.shape[0]
        unit, keep = unique_directions(d)
        self.directions = unit
        flat = hid.reshape(self.n, -1)
        any_hidden = np.flatnonzero(flat.any(axis=0))
        self.groups = []
        self._triangulations: dict = {}
        self._sets: np.ndarray | None = None  # _hidden_sets(), built on first use
        #: Per flat pixel, its index in :attr:`groups` (-1: no photo hidden there).
        self.group_of = np.full(flat.shape[1], -1, dtype=np.int32)
        if any_hidden.size == 0:
            return
        packed = np.packbits(flat[:, any_hidden], axis=0).T.copy()
        _, first, inverse = np.unique(packed, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.ravel()
        order = np.argsort(inverse, kind="stable")
        bounds = np.searchsorted(inverse[order], np.arange(first.size + 1))
        kept = np.zeros(self.n, dtype=bool)
        kept[keep] = True
        for g in range(first.size):
            pix = any_hidden[order[bounds[g]:bounds[g + 1]]]
            h = np.flatnonzero(flat[:, pix[0]])
            visible = np.flatnonzero(kept & ~flat[:, pix[0]])
            self.group_of[pix] = len(self.groups)
            self.groups.append((h, pix, visible))

    @classmethod
    def from_geometry(cls, points, centres, radius, directions, hemisphere="upper", *, positions=None,
                      margin_deg=0.0, dilate_px: int = 1) -> "SphereShadowFill":
        """The fill of the photos' sphere shadows found by :func:`hidden_photos` (same parameters)."""
        geometry = {"points": points, "centres": centres, "radius": radius, "dilate_px": dilate_px}
        hidden = hidden_photos(points, centres, radius, directions, positions, margin_deg, dilate_px)
        return cls(hidden, directions, hemisphere, geometry=geometry)

    def hidden_for(self, direction) -> np.ndarray | None:
        """(H, W) bool: the pixels a light from unit ``direction`` sees through a sphere (None without geometry)."""
        if self.geometry is None:
            return None
        return hidden_photos(directions=np.reshape(direction, (1, 3)), **self.geometry)[0]

    def triangulation(self, g: int):
        """The :class:`ffls.weights.barycentric.Barycentric` triangulation of group ``g``'s visible
        photos (built once, on first use), or None where fewer than 3 photos see its pixels:
        nothing to fill from, those pixels are left as they are."""
        if g not in self._triangulations:
            visible = self.groups[g][2]
            self._triangulations[g] = (Barycentric(self.directions, visible, self.hemisphere)
                                       if visible.size >= 3 else None)
        return self._triangulations[g]

    def _hidden_sets(self) -> np.ndarray:
        """(groups + 1, n) bool: row g the photos hidden from group g's pixels; the last row, all
        False, is that of the pixels with no group (:attr:`group_of` -1)."""
        if self._sets is None:
            self._sets = np.zeros((len(self.groups) + 1, self.n), dtype=bool)
            for g, (hid, _, _) in enumerate(self.groups):
                self._sets[g, hid] = True
        return self._sets

    @property
    def hidden_pixels(self) -> int:
        """Pixels with at least one hidden photo that can be filled."""
        return int(sum(p.size for _, p, v in self.groups if v.size >= 3))

    def _redistribution(self, directions, tri) -> tuple[np.ndarray, np.ndarray]:
        """Visible photos ``(m, 3)`` and their weights for unit ``directions`` (m, 3).

        The barycentric weights ``b`` over the visible photos' triangulation, divided by
        ``d . sum_j b_j d_j``: the visible photos' directions surround ``d`` at up to tens of
        degrees where a sphere hides a wide cone, and their normalised blend is a chord inside the
        sphere, shorter than ``d``. Scaled, the weights reproduce any photo that is linear in the
        light direction (a Lambertian surface's unshadowed shading ``albedo n . d``, the local model
        of :func:`ffls.relight.lightflow.unshadowed_fit`) exactly, instead of darkening the fill by
        the chord's length.
        """
        idx, b = tri(directions)
        reach = np.einsum("mj,mjc,mc->m", b, self.directions[idx], directions)
        scale = np.where(reach > 0, 1.0 / np.where(reach > 0, reach, 1.0), 1.0)
        return idx, b * scale[:, None]

    def weights_correction(self, weights) -> list:
        """Per group, the change of every photo's weight: hidden photos to 0, their weight to the visible ones.

        Parameters
        ----------
        weights : (n, 3) array_like
            The relighter's per-photo weights (pass 1).

        Returns
        -------
        list of (pixels (q,) int, photos (k,) int, delta (k, 3) float64)
            Over each group's pixels the filled weights are ``weights[photos] + delta``.
        """
        w = np.asarray(weights, dtype=np.float64).reshape(self.n, -1)
        out = []
        for g, (hid, pix, _) in enumerate(self.groups):
            tri = self.triangulation(g)
            if tri is None:
                continue
            idx, b = self._redistribution(self.directions[hid], tri)
            delta = np.zeros((self.n, w.shape[1]))
            delta[hid] -= w[hid]
            np.add.at(delta, idx.ravel(), (b[..., None] * w[hid][:, None, :]).reshape(-1, w.shape[1]))
            photos = np.flatnonzero(np.any(delta != 0, axis=1))
            out.append((pix, photos, delta[photos]))
        return out

    def relight(self, image, weights, basis) -> np.ndarray:
        """``image`` (the weighted sum of ``basis`` with ``weights``) with the hidden photos' weights moved.

        Parameters
        ----------
        image : (H, W, 3) float array
        weights : (n, 3) array_like
        basis : (n, H, W, 3) float array

        Returns
        -------
        (H, W, 3) float64
        """
        out = np.array(image, dtype=np.float64)
        flat = out.reshape(-1, 3)
        B = np.asarray(basis).reshape(self.n, -1, 3)
        for pix, photos, delta in self.weights_correction(weights):
            flat[pix] += np.einsum("kc,kqc->qc", delta, B[photos][:, pix].astype(np.float64))
        return out

    def model_width_deg(self) -> float:
        """Gaussian width (degrees) of :meth:`source_model`'s local fit: the cap that holds
        2 x :data:`ffls.relight.lightflow.FIT_NEIGHBOURS` of the photos on average."""
        area = (4 * np.pi if self.hemisphere.axis is None else 2 * np.pi) * min(1.0, 2 * FIT_NEIGHBOURS / self.n)
        return float(np.degrees(np.arccos(1.0 - area / (2 * np.pi))))

    def ground_pixels(self) -> np.ndarray:
        """(H, W) bool: the pixels with a ground point (``geometry['points']`` finite); made once
        (every compact source's :meth:`source_model` reads it). Read-only."""
        if self.geometry is None:
            raise ValueError("ground_pixels needs the spheres' geometry (SphereShadowFill.from_geometry)")
        if self._ground is None:
            self._ground = np.all(np.isfinite(self.geometry["points"]), axis=-1)
            self._ground.flags.writeable = False
        return self._ground

    def source_model(self, image, direction, basis, *, hull=None, everywhere: bool = False) -> np.ndarray:
        """A compact source's unit-power image with its sphere shadows replaced by the unshadowed model.

        Where a light from ``direction`` would be hidden by a sphere (:meth:`hidden_for`) no photo
        holds the pixel under that light. Its unshadowed brightness is the local linear model
        (:func:`ffls.relight.lightflow.unshadowed_fit`) of the photos that see the pixel (the
        pixel's hidden photos left out), weighted by a Gaussian of their angle to ``direction``
        (:meth:`model_width_deg`), evaluated at ``direction``: exact for a Lambertian surface. The
        object's shadow there comes from its geometry: times ``hull.visibility(points, direction)``
        (:class:`ffls.relight.shadow_hull.ShadowHull`) where a hull is given (the object capture),
        1 without (the surface-alone capture). With ``everywhere`` every ground pixel
        (:meth:`ground_pixels`) is relit so, not only the hidden ones: the object's shadow from the
        source is then placed by the hull's geometry instead of being interpolated between the photos
        of the nearest lights, whose shadows change shape between them (docs/composite.md).

        Parameters
        ----------
        image : (H, W, 3) float array
            The interpolated photo for ``direction``.
        direction : (3,) array_like
        basis : (n, H, W, 3) float array
        hull : ShadowHull, optional
        everywhere : bool
            Relight every ground pixel, not only those a sphere hides from ``direction``.

        Returns
        -------
        (H, W, 3) float64
        """
        out = np.array(image, dtype=np.float64)
        d = np.asarray(direction, dtype=np.float64).reshape(3)
        d = d / np.linalg.norm(d)
        here = self.hidden_for(d)
        if here is None:
            raise ValueError("source_model needs the spheres' geometry (SphereShadowFill.from_geometry)")
        if everywhere:
            here = here | self.ground_pixels()
        pix = np.flatnonzero(here.ravel())
        if pix.size == 0:
            return out
        angle = np.degrees(np.arccos(np.clip(self.directions @ d, -1.0, 1.0)))
        near = np.exp(-0.5 * (angle / self.model_width_deg()) ** 2)[:, None]
        flat_basis = np.asarray(basis).reshape(self.n, -1, 3)
        model = np.empty((pix.size, 3))
        step = max(1, MODEL_CHUNK_VALUES // self.n)  # pixels per chunk: the whole ground of a large photo
        for lo in range(0, pix.size, step):
            p = pix[lo:lo + step]
            groups = self.group_of[p]
            # 0 where the pixel's group has the photo hidden (a row of False for no group)
            prior = np.where(self._hidden_sets()[groups].T, 0.0, near)
            B = flat_basis[:, p].astype(np.float32)
            b = unshadowed_fit(B[:, :, None], self.directions, prior=prior[:, :, None])[:, 0]
            model[lo:lo + step] = np.maximum(np.einsum("qci,i->qc", b.astype(np.float64), d), 0.0)
        good = np.all(np.isfinite(model), axis=-1)
        if hull is not None:
            pts = self.geometry["points"].reshape(-1, 3)[pix]
            model *= hull.visibility(pts, d)[:, None]
        flat = out.reshape(-1, 3)
        flat[pix[good]] = model[good]
        return out

    def source_image(self, image, direction, triangle, basis, interpolate=None) -> np.ndarray:
        """A compact source's unit-power image with the fill where its triangle's photos are hidden.

        Parameters
        ----------
        image : (H, W, 3) float array
            The interpolated photo for ``direction`` (e.g. :meth:`ffls.relight.lightflow.FlowInterpolator.image`).
        direction : (3,) array_like
        triangle : (k,) int
            The photos it was interpolated from.
        basis : (n, H, W, 3) float array
        interpolate : callable, optional
            ``interpolate(idx, w) -> (H, W, 3)``: the photos ``idx`` blended with weights ``w`` summing
            to 1 (:meth:`ffls.relight.lightflow.FlowInterpolator.image_from`: warped by their flow, so
            that the visible triangle's shadows move to ``direction``); the plain blend otherwise.

        Returns
        -------
        (H, W, 3) float64
            Where a light from ``direction`` would be hidden by a sphere (:meth:`hidden_for`; without
            the geometry: where one of ``triangle`` is hidden), the visible photos' blend at
            ``direction`` (:meth:`_redistribution`'s weights). Elsewhere ``image``: where the
            direction itself sees the pixel, a hidden neighbour's sphere shadow is not there in the
            interpolated photo (the flow moved it with the light).
        """
        out = np.array(image, dtype=np.float64)
        flat = out.reshape(-1, 3)
        B = np.asarray(basis).reshape(self.n, -1, 3)
        d = np.asarray(direction, dtype=np.float64).reshape(1, 3)
        d = d / np.linalg.norm(d)
        tri_set = np.asarray(triangle, dtype=np.int64)
        here = self.hidden_for(d[0])
        cache: dict = {}
        here = None if here is None else here.ravel()
        for g, (hid, pix, visible) in enumerate(self.groups):
            if visible.size < 3:
                continue
            if here is not None:
                pix = pix[here[pix]]
                if pix.size == 0:
                    continue
            elif not np.isin(tri_set, hid).any():
                continue
            idx, b = self._redistribution(d, self.triangulation(g))
            if interpolate is None:
                flat[pix] = np.einsum("k,kqc->qc", b[0], B[idx[0]][:, pix].astype(np.float64))
                continue
            order = np.argsort(idx[0])
            key = tuple(int(v) for v in idx[0][order])
            total = float(b[0].sum())
            if key not in cache:
                keep = b[0][order] > 0
                cache[key] = np.asarray(interpolate(np.asarray(key)[keep], b[0][order][keep] / total),
                                        dtype=np.float64).reshape(-1, 3)
            flat[pix] = total * cache[key][pix]
        return out

