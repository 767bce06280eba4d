"""The spheres' pixels: where they are, their normals, and their values in one photo.

Stage between detection (:mod:`ffls.spheres.detect`, a centre per sphere) and the per-sphere
fits (:mod:`ffls.spheres.lambert`): once per capture, :func:`sphere_samples` intersects every
pixel's (undistorted) ray with each sphere (Masselus, Dutre, Anrys 2002, section 5: "the normal
at each pixel of a sphere is known"); per photo, :func:`sphere_values` reads only those pixels
and marks the usable ones (:func:`pixel_validity`: finite, not saturated, not clipped at black).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ffls.camera.projection import pixel_rays
from ffls.conventions import UP, normalize
from ffls.spheres.ground import GroundView, ground_radiance

__all__ = ["ORTHO_VIRTUAL_DISTANCE", "GroundedValues", "SphereSamples", "SphereValues", "sphere_values_of", "channel_mean", "ground_bounce", "sphere_samples", "sphere_samples_orthographic",
           "pixel_validity", "sphere_values"]


def ground_bounce(normals: np.ndarray, up: np.ndarray = UP) -> np.ndarray:
    """Form factor ``(1 - n . up) / 2`` from sphere points to an infinite ground plane below.

    Parameters
    ----------
    normals : (m, 3) float, unit, world frame
    up : (3,) float, unit

    Returns
    -------
    (m,) float in [0, 1]
    """
    return np.clip(0.5 * (1.0 - np.asarray(normals, dtype=np.float64) @ np.asarray(up, dtype=np.float64)), 0.0, 1.0)


#: Distance, in sphere radii, of the virtual camera centre of an orthographic camera's samples
#: (:func:`sphere_samples_orthographic`): rays from it diverge by at most 1e-4 rad (0.006 deg).
ORTHO_VIRTUAL_DISTANCE = 1.0e4


@dataclass(frozen=True)
class SphereSamples:
    """The pixels of one sphere usable for shading fits; fixed for a capture (camera and sphere).

    Attributes
    ----------
    rows, cols : (m,) int
        Pixel coordinates (row = y, col = x).
    normals : (m, 3) float64
        Unit world-frame normals at the ray-sphere hits.
    points : (m, 3) float64
        World-frame surface points at the hits.
    center : (3,) float64
        World-frame sphere centre.
    radius : float
        Sphere radius (world units).
    radius_px : float
        Apparent radius in pixels (for reports).
    ground : (m,) float64 or None
        :func:`ground_bounce` of ``normals`` for world up ``+Z`` (computed once per capture).
    origin : (3,) float64 or None
        World-frame camera centre (the pixels' rays start there; needed by
        :mod:`ffls.spheres.refine`); for an orthographic camera a virtual one far behind the
        sphere (:data:`ORTHO_VIRTUAL_DISTANCE`).
    ground_view : ffls.spheres.ground.GroundView or None
        Where the sphere's ground is seen in the photos: :func:`sphere_values` then reads it, and
        the fits take the bounce from it (``bounce='observed'``, :mod:`ffls.spheres.ground`).
    """

    rows: np.ndarray
    cols: np.ndarray
    normals: np.ndarray
    points: np.ndarray
    center: np.ndarray
    radius: float
    radius_px: float
    ground: np.ndarray | None = None
    origin: np.ndarray | None = None
    ground_view: GroundView | None = None

    def values(self, image: np.ndarray) -> np.ndarray:
        """Grey intensity (m,) float64 of these pixels: the mean of the channels of ``image`` (H, W[, C])."""
        px = np.asarray(image)[self.rows, self.cols]
        px = px.astype(np.float64, copy=False)
        return px.mean(axis=-1) if px.ndim == 2 else px

    def ground_factor(self, up: np.ndarray = UP) -> np.ndarray:
        """:func:`ground_bounce` of :attr:`normals` for world ``up`` (the precomputed :attr:`ground` for ``+Z``)."""
        if self.ground is not None and np.array_equal(up, UP):
            return self.ground
        return ground_bounce(self.normals, up)

    def __len__(self) -> int:
        return int(self.rows.size)


def sphere_samples(shape: tuple[int, int], K: np.ndarray, dist: np.ndarray | None, center_cam: np.ndarray,
                   radius: float, world_from_camera: np.ndarray | None = None, margin_px: float = 1.5) -> SphereSamples:
    """Pixels of a sphere and their normals, from the ray-sphere intersection.

    Pixels whose ray passes within ``margin_px`` pixels (angularly) of the silhouette are left
    out: their colour mixes sphere and background and their normal is poorly defined.

    Parameters
    ----------
    shape : (H, W)
        Image size.
    K : (3, 3) float
        Camera matrix.
    dist : (k,) float or None
        OpenCV distortion coefficients.
    center_cam : (3,) float
        Sphere centre in the camera frame.
    radius : float
        Sphere radius, same units as ``center_cam``.
    world_from_camera : (4, 4) float, optional
        Camera-to-world transform; identity if None.
    margin_px : float
        Silhouette margin in pixels.

    Returns
    -------
    SphereSamples
    """
    C = np.asarray(center_cam, dtype=np.float64).reshape(3)
    R = float(radius)
    K = np.asarray(K, dtype=np.float64)
    H, W = int(shape[0]), int(shape[1])
    dC = float(np.linalg.norm(C))
    if not (R > 0 and dC > R and C[2] > 0):
        raise ValueError("sphere must lie in front of the camera and not contain it")
    f = 0.5 * (K[0, 0] + K[1, 1])
    ang_s = np.arcsin(R / dC)  # angular radius of the silhouette
    # image-space bounding box (generous, distortion is handled by the exact ray test below)
    cpx = K @ (C / C[2])
    r_px = f * np.tan(ang_s) * (dC / C[2]) ** 2 * 1.3 + 4.0
    x0, x1 = max(int(np.floor(cpx[0] - r_px)), 0), min(int(np.ceil(cpx[0] + r_px)), W - 1)
    y0, y1 = max(int(np.floor(cpx[1] - r_px)), 0), min(int(np.ceil(cpx[1] + r_px)), H - 1)
    if x1 < x0 or y1 < y0:
        raise ValueError("sphere is outside the image")
    yy, xx = np.mgrid[y0:y1 + 1, x0:x1 + 1]
    px = np.stack([xx.ravel(), yy.ravel()], axis=-1).astype(np.float64)
    d = pixel_rays(px, K, dist)
    ang = np.arccos(np.clip(d @ (C / dC), -1.0, 1.0))
    keep = ang < ang_s - margin_px / f
    d = d[keep]
    dc = d @ C
    disc = np.maximum(dc * dc - dC * dC + R * R, 0.0)
    t = dc - np.sqrt(disc)
    P = d * t[:, None]
    n = (P - C) / R
    if world_from_camera is None:
        Rw, tw = np.eye(3), np.zeros(3)
    else:
        M = np.asarray(world_from_camera, dtype=np.float64)
        Rw, tw = M[:3, :3], M[:3, 3]
    n_w = normalize(n @ Rw.T)
    P_w = P @ Rw.T + tw
    radius_px = f * np.tan(ang_s)
    return SphereSamples(rows=yy.ravel()[keep], cols=xx.ravel()[keep], normals=n_w, points=P_w,
                         center=Rw @ C + tw, radius=R, radius_px=float(radius_px),
                         ground=ground_bounce(n_w), origin=np.asarray(tw, dtype=np.float64).copy())


def sphere_samples_orthographic(shape: tuple[int, int], center_px, radius_px: float, center_cam=None,
                                radius: float = 1.0, world_from_camera: np.ndarray | None = None,
                                margin_px: float = 1.5) -> SphereSamples:
    """Pixels of a sphere seen by an orthographic camera, and their normals.

    Every viewing ray is +z (camera frame), so the normal at pixel offset ``(dx, dy)`` from the
    centre is ``(dx / r, dy / r, -sqrt(1 - (dx^2 + dy^2) / r^2))`` with ``r = radius_px``: no
    focal length, no pixel scale. Only pixels inside the image and at least ``margin_px`` inside
    the outline are kept (a sphere cut by the frame edge gives its visible part).

    Parameters
    ----------
    shape : (H, W)
    center_px : (2,) float
        Centre of the sphere's disc, pixels.
    radius_px : float
        Apparent radius, pixels.
    center_cam : (3,) float, optional
        Camera-frame centre for :attr:`SphereSamples.points` (``SphereFit.center_cam``); the
        origin when None.
    radius : float
        Sphere radius (scene units; 1 when ``sphere_radius`` is not given).
    world_from_camera : (4, 4) float, optional
    margin_px : float

    Returns
    -------
    SphereSamples
        ``origin`` is a virtual camera centre :data:`ORTHO_VIRTUAL_DISTANCE` sphere radii behind
        the centre along the viewing direction: an orthographic camera is the limit of a pinhole
        one far away, and from there the rays through the samples diverge by at most
        ``1 / ORTHO_VIRTUAL_DISTANCE`` rad, so :mod:`ffls.spheres.refine` (the photometric
        centre refinement, which needs a ray origin) applies unchanged; its pixel shifts are
        pixels of this image.
    """
    H, W = int(shape[0]), int(shape[1])
    cx, cy = (float(v) for v in np.asarray(center_px, dtype=np.float64).reshape(2))
    r = float(radius_px)
    if not r > margin_px:
        raise ValueError(f"sphere radius {r:.1f} px is too small")
    x0, x1 = max(int(np.floor(cx - r)), 0), min(int(np.ceil(cx + r)), W - 1)
    y0, y1 = max(int(np.floor(cy - r)), 0), min(int(np.ceil(cy + r)), H - 1)
    if x1 < x0 or y1 < y0:
        raise ValueError("sphere is outside the image")
    yy, xx = np.mgrid[y0:y1 + 1, x0:x1 + 1]
    a, b = (xx.ravel() - cx) / r, (yy.ravel() - cy) / r
    keep = np.hypot(a, b) < 1.0 - margin_px / r
    a, b = a[keep], b[keep]
    n = np.stack([a, b, -np.sqrt(np.clip(1.0 - a * a - b * b, 0.0, None))], axis=1)
    C = np.zeros(3) if center_cam is None else np.asarray(center_cam, dtype=np.float64).reshape(3)
    R = float(radius)
    M = np.eye(4) if world_from_camera is None else np.asarray(world_from_camera, dtype=np.float64)
    Rw, tw = M[:3, :3], M[:3, 3]
    n_w = normalize(n @ Rw.T)
    P_w = (C + R * n) @ Rw.T + tw
    C_w = Rw @ C + tw
    origin = C_w - ORTHO_VIRTUAL_DISTANCE * R * Rw[:, 2]  # camera +z is the viewing direction
    return SphereSamples(rows=yy.ravel()[keep], cols=xx.ravel()[keep], normals=n_w, points=P_w,
                         center=C_w, radius=R, radius_px=r, ground=ground_bounce(n_w), origin=origin)


class SphereValues(NamedTuple):
    """One sphere's pixels in one photo (:func:`sphere_values`), in :class:`SphereSamples` order.

    Attributes
    ----------
    grey : (m,) float
        Linear grey values (mean of the channels).
    valid : (m,) bool
        Usable pixels (finite, not saturated, not clipped at the black floor).
    n_saturated : int
        Saturated pixels among the sphere's.
    ground : (p,) float or None
        Not a field (the values stay a triple): the photographed radiance of the sphere's ground
        (:func:`ffls.spheres.ground.ground_radiance` of its :attr:`SphereSamples.ground_view`),
        on :class:`GroundedValues`; None here.
    """

    grey: np.ndarray
    valid: np.ndarray
    n_saturated: int
    ground = None  # (a class attribute: GroundedValues sets its own)

    def subset(self, index: np.ndarray) -> "SphereValues":
        """The values of the pixels ``index`` (the saturated count is kept: it describes the photo,
        and the ground: it is not the sphere's pixels)."""
        return sphere_values_of(self.grey[index], self.valid[index], self.n_saturated, self.ground)


class GroundedValues(SphereValues):
    """:class:`SphereValues` with the sphere's photographed ground (``bounce='observed'``) as the
    attribute ``ground``; still the triple ``(grey, valid, n_saturated)``."""

    def __new__(cls, grey, valid, n_saturated, ground):
        self = super().__new__(cls, grey, valid, n_saturated)
        self.ground = ground
        return self

    def __getnewargs__(self):
        # pickled to the --workers processes: the tuple's own arguments and the ground
        return (*self, self.ground)


def sphere_values_of(grey, valid, n_saturated, ground=None) -> SphereValues:
    """A :class:`SphereValues`, or a :class:`GroundedValues` where ``ground`` is given."""
    if ground is None:
        return SphereValues(grey, valid, n_saturated)
    return GroundedValues(grey, valid, n_saturated, ground)


def _columns(p: np.ndarray) -> list[np.ndarray]:
    """The columns of an (m, c) array, each contiguous (m,)."""
    return list(np.ascontiguousarray(p.T))


def channel_mean(chans: list[np.ndarray]) -> np.ndarray:
    """The mean of channel columns ``(c0 + c1 + ...) / c``: what ``mean(axis=1)`` of the (m, c)
    array gives (numpy sums so few terms in order), on contiguous columns (several times faster)."""
    total = chans[0].copy()
    for c in chans[1:]:
        total += c
    return total / float(len(chans))


def pixel_validity(pixels: np.ndarray, black_fraction: float | None = None, min_plateau: int = 4,
                   saturation: float | None = None) -> tuple[np.ndarray, int]:
    """Usable pixels of one sphere: finite, not saturated, not clipped at the black floor.

    Saturation is the clip level ``saturation`` where the caller knows it, and in any case a
    plateau: at least ``min_plateau`` pixels sharing the maximum of a channel (clipping makes
    plateaus; unclipped radiance does not).

    Dark pixels are *not* censored by their value: a noisy pixel of a dark region is as likely
    below its mean as above it, so dropping the pixels below a threshold keeps the bright half of
    the noise and biases the shading fit (the shadow side and the terminator read too bright: with
    Gaussian noise of 1% of full scale the lights were ~1 degree off, the same for every sphere).
    Near-zero and negative values are kept: the shading model takes them. Only the pixels
    clipped at the black floor are invalid: a plateau of at least ``min_plateau`` pixels at a
    channel's minimum, where that minimum is at most 0 (the black level of linear data; an
    8-bit code 0, a float image clipped at 0). Their true value is unknown (anything below the
    floor); :func:`ffls.spheres.lambert.fit_lambert` then also leaves out the pixels that its
    model predicts near the floor, so the censoring does not depend on the noise.

    Parameters
    ----------
    pixels : (m, 3) or (m,) float
        Linear values of the sphere's pixels.
    black_fraction : float, optional
        Also invalidate grey values below this fraction of the sphere's 99th percentile (the
        former near-black rule; biased under noise, see above). None (default): not applied.
    min_plateau : int
    saturation : float, optional

    Returns
    -------
    valid : (m,) bool
    n_saturated : int
    """
    p = np.asarray(pixels, dtype=np.float64)
    if p.ndim == 1:
        p = p[:, None]
    chans = _columns(p)  # contiguous channels: reductions over a last axis of 3 are slow
    finite = np.isfinite(chans[0])
    for c in chans[1:]:
        finite &= np.isfinite(c)
    sat = np.zeros(p.shape[0], dtype=bool)
    floor = np.zeros(p.shape[0], dtype=bool)
    if finite.any():
        every = bool(finite.all())
        for c in chans:
            q = c if every else np.where(finite, c, -np.inf)
            top = float(q.max())
            if top > 0:
                at_top = q >= top * (1.0 - 1e-6)
                if np.count_nonzero(at_top) >= min_plateau:
                    sat |= at_top
            if saturation is not None:
                sat |= q >= 0.999 * saturation
            qlo = c if every else np.where(finite, c, np.inf)
            low = float(qlo.min())
            if low <= 0.0:
                at_low = qlo <= low
                if np.count_nonzero(at_low) >= min_plateau:
                    floor |= at_low
    ok = finite & ~sat & ~floor
    if black_fraction is not None:
        grey = np.where(finite, channel_mean(chans), 0.0)
        ref = float(np.percentile(grey[ok], 99)) if ok.any() else 0.0
        ok &= grey > max(black_fraction * ref, 0.0)
    return ok, int((sat & finite).sum())


@functools.lru_cache(maxsize=4)
def _saturated_code(bit_depth: int, high: float) -> int:
    """The lowest code ``k`` of ``bit_depth`` with ``k / top >= high`` (top 255 or 65535), as
    :func:`ffls.radiance.response.valid_pixel_mask` computes the fraction (float64)."""
    top = 255 if bit_depth == 8 else 65535
    return int(np.searchsorted(np.arange(top + 1, dtype=np.float64) / float(top), high, side="left"))


def _code_masks(codes: np.ndarray, bit_depth: int, high: float = 0.98) -> tuple[np.ndarray, np.ndarray]:
    """(m,) saturated (a channel's code at or above ``high`` of full scale) and clipped-black
    (every channel 0) masks of integer ``codes`` (m, c): :func:`ffls.radiance.response.valid_pixel_mask`
    with ``low=0`` on the codes, without converting them to float."""
    k = _saturated_code(bit_depth, high)
    chans = [codes[:, c] for c in range(codes.shape[1])]  # (reductions over a last axis of 3 are slow)
    sat = chans[0] >= k
    black = chans[0] == 0
    for ch in chans[1:]:
        sat |= ch >= k
        black &= ch == 0
    return sat, black


def sphere_values(image: np.ndarray, samples: list[SphereSamples], saturation: float | None = None,
                  raw: np.ndarray | None = None, bit_depth=None) -> list[SphereValues]:
    """The spheres' pixels of one photo: grey values, validity, saturated count.

    Only the sphere pixels are read (fancy indexing of the precomputed pixel lists), never the
    whole image.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) float
        Linear radiance.
    samples : list of SphereSamples
    saturation : float, optional
        Known clip level of the linear values.
    raw : (H, W, 3) array, optional
        The image as stored, with ``bit_depth``: then
        :func:`ffls.radiance.response.valid_pixel_mask` also applies to integer codes (saturated
        codes of any channel, code 0 in every channel: clipped at the floor); float values
        (negative ones included) are left to :func:`pixel_validity`.
    bit_depth : {8, 16, 'half', 'float'}, optional

    Returns
    -------
    list of SphereValues
        One per sphere (grey float64).
    """
    from ffls.radiance.response import valid_pixel_mask

    img = np.asarray(image)
    flat = img.reshape(-1, img.shape[2]) if img.ndim == 3 and img.flags.c_contiguous else None
    out = []
    for s in samples:
        if flat is not None:  # one row gather of the flattened photo (the same values as img[rows, cols])
            px = np.take(flat, s.rows.astype(np.intp) * img.shape[1] + s.cols, axis=0).astype(np.float64)
        else:
            px = img[s.rows, s.cols].astype(np.float64)
        valid, nsat = pixel_validity(px, saturation=saturation)
        if raw is not None and bit_depth is not None:
            rp = np.asarray(raw)[s.rows, s.cols]
            rp = rp.reshape(1, -1, rp.shape[-1] if rp.ndim == 2 else 1)
            if bit_depth in (8, 16) and np.issubdtype(rp.dtype, np.integer):
                # valid_pixel_mask's test of the codes themselves (no float copy): saturated where
                # any channel is at or above its top code fraction, clipped where every channel is 0
                sat, black = _code_masks(rp[0], bit_depth)
                valid &= ~sat & ~black
                nsat = max(nsat, int(np.count_nonzero(sat)))
            elif bit_depth in (8, 16):  # saturated codes of any channel; code 0 in every channel (clipped)
                not_sat = valid_pixel_mask(rp, bit_depth, low=-1.0)[0]
                valid &= valid_pixel_mask(rp, bit_depth, low=0.0)[0]
                nsat = max(nsat, int((~not_sat).sum()))
            # float data: no top code, and near-zero or negative (noisy) values are data
            # (pixel_validity; the non-finite are already invalid)
        grey = channel_mean(_columns(px)) if px.ndim == 2 else px
        ground = None if s.ground_view is None else ground_radiance(s.ground_view, img)
        out.append(sphere_values_of(grey, valid, int(nsat), ground))
    return out
