"""Light maps from photographs of a mirror ball (Debevec 1998).

Debevec, P., "Rendering Synthetic Objects into Real Scenes: Bridging Traditional and
Image-Based Graphics with Global Illumination and High Dynamic Range Photography", SIGGRAPH
1998, section 3 (the light probe: a mirrored ball photographed, unwrapped into a radiance map,
two views combined to replace the poorly sampled rim and the camera's reflection).

Unwrapping (:func:`unwrap_mirror_ball_Debevec1998`) runs backwards, from each direction of the
output lat-long map (GUIDE section 1, world frame) to the pixel that sees it:

* **perspective** (a calibrated pinhole camera with OpenCV distortion): the point ``P`` of the
  ball that reflects direction ``w`` toward the camera satisfies ``n = normalize(w - v)`` with
  ``v = normalize(P)`` the viewing ray to ``P = C + R n`` (camera frame, ``C`` the ball's centre).
  It is solved by fixed-point iteration from the orthographic answer (a contraction of ratio about
  ``R / |C|``), then checked: the reflection of ``v`` about ``n`` must be ``w`` and ``P`` must face
  the camera (``n . v < 0``). ``P`` is projected with the distortion (``cv2.projectPoints``) and
  the image sampled bilinearly. Only the ratio ``|C| / R`` matters, so a ball located by pixels
  needs no radius.
* **orthographic**: every viewing ray is the camera's +z, ``n = normalize(w - z)``, and the pixel
  is ``centre_px + radius_px (n_x, n_y)``: the classic formula, the limit of the perspective one
  as the camera recedes.

Each direction gets a **confidence** in [0, 1]: the cosine of the angle of incidence,
``-n . v``. The ball maps the sphere of directions onto the disc with (orthographically) a
uniform solid angle per pixel, but the radial angular resolution is ``2 / (R_px cos)`` per pixel:
near the rim one pixel spans a wide band of directions, any error of the centre or radius moves
them by as much, and edge pixels mix ball and background. The confidence is zero for the pixels
within ``rim_px`` of the outline, for pixels not valid in the image, and within a cone of
``camera_cone_deg`` around the direction from the ball to the camera: there the ball reflects
the camera and the photographer, not the scene. Directions behind the ball (the cone of half-angle
``asin(R / |C|)`` around the forward direction, plus the rim) are not seen at all.

Two or more views (:func:`merge_mirror_views`, Debevec's two photographs 90 degrees apart) are
averaged per direction with weights ``confidence ** power`` (2 by default: the variance of a
direction's error grows as ``1 / cos^2``), clipped samples counting only where no view has an
unclipped one. What no view saw is the **blind spot** (:func:`blind_spot`); by default it is
filled from the nearest seen directions (:func:`fill_unseen`) so that the map relights without a
black hole, and the mask of what was seen is kept beside the map.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from ffls.camera.projection import camera_arrays, project_points
from ffls.conventions import latlong_directions, latlong_uv_to_direction, normalize

__all__ = ["MirrorView", "BlindSpot", "latlong_solid_angles", "mirror_ball_pixels",
           "unwrap_mirror_ball_Debevec1998", "auto_supersample", "splat_mirror_ball", "splat_supersample",
           "RESAMPLE_MODES", "merge_mirror_views", "fill_unseen", "blind_spot",
           "CAMERA_CONE_DEG", "RIM_PX"]

#: Default half-angle (degrees) of the cone around the direction toward the camera that is masked out.
CAMERA_CONE_DEG = 10.0
#: Default width (pixels) of the ball's rim given zero confidence.
RIM_PX = 1.0


@dataclass
class MirrorView:
    """One view of a mirror ball unwrapped into a lat-long map.

    Attributes
    ----------
    radiance : (H, 2H, 3) float32
        Linear radiance (0 where unseen).
    confidence : (H, 2H) float32
        In [0, 1]; 0 where the view did not see the direction.
    clipped : (H, 2H) bool
        Seen through clipped (saturated) pixels: the value is a lower bound.
    camera_direction : (3,) float64
        World direction from the ball's centre toward the camera.
    camera_cone : (H, 2H) bool
        The masked cone around ``camera_direction``.
    """

    radiance: np.ndarray
    confidence: np.ndarray
    clipped: np.ndarray
    camera_direction: np.ndarray
    camera_cone: np.ndarray


@dataclass
class BlindSpot:
    """The directions no view saw.

    Attributes
    ----------
    solid_angle : float
        Steradians.
    fraction : float
        Of the whole sphere (4 pi).
    direction : (3,) float64 or None
        Solid-angle weighted mean direction of the blind spot (None when nothing is unseen).
    radius_deg : float
        Half-angle of a cone of the same solid angle.
    """

    solid_angle: float
    fraction: float
    direction: np.ndarray | None
    radius_deg: float

    def describe(self) -> str:
        """One line."""
        if self.direction is None:
            return "blind spot: none (every direction seen)"
        d = ", ".join(f"{x:+.2f}" for x in self.direction)
        return (f"blind spot: {self.solid_angle:.3f} sr ({100 * self.fraction:.2f}% of the sphere, a cone of "
                f"{self.radius_deg:.1f} deg), centred near ({d})")


def latlong_solid_angles(height: int) -> np.ndarray:
    """Exact solid angles (H, 2H) float64 of the texels of a lat-long map of height ``height``; they sum to 4 pi."""
    h = int(height)
    t = np.linspace(0.0, np.pi, h + 1)
    row = (2 * np.pi / (2 * h)) * (np.cos(t[:-1]) - np.cos(t[1:]))
    return np.repeat(row[:, None], 2 * h, axis=1)


def _reflect(v, n):
    return v - 2.0 * np.sum(v * n, axis=-1, keepdims=True) * n


def mirror_ball_pixels(directions_cam, camera_model: str, K=None, dist=None, center_cam=None, radius=None,
                       center_px=None, radius_px=None, iterations: int = 100, tol: float = 1e-10) -> dict:
    """Where a mirror ball shows each direction: pixel, normal, incidence cosine and visibility.

    Parameters
    ----------
    directions_cam : (n, 3) float
        Unit directions toward the scene, camera frame (x right, y down, z forward).
    camera_model : {'pinhole', 'orthographic'}
    K, dist : camera (pinhole)
    center_cam : (3,) float
        Ball centre, camera frame (pinhole); any scale, with ``radius`` in the same units.
    radius : float
    center_px, radius_px : (2,) float, float
        The ball's disc (orthographic).
    iterations, tol : int, float
        Fixed-point iteration limit and convergence tolerance (pinhole).

    Returns
    -------
    dict
        ``pixels`` (n, 2) float64 (distorted image coordinates), ``normals`` (n, 3) camera frame,
        ``cos`` (n,) the cosine of incidence ``-n . v``, ``visible`` (n,) bool (the direction is
        reflected by a point of the ball that faces the camera), ``rim_px`` (n,) float64 the
        distance in pixels (approximately, for a pinhole) of that point's image from the outline,
        ``toward_camera`` (3,) the direction from the ball to the camera.
    """
    w = np.asarray(directions_cam, dtype=np.float64).reshape(-1, 3)
    if camera_model == "orthographic":
        v = np.array([0.0, 0.0, 1.0])
        n = normalize(w - v)
        cos = -n[:, 2]
        visible = cos > 1e-9
        px = np.asarray(center_px, dtype=np.float64).reshape(2) + float(radius_px) * n[:, :2]
        rim = float(radius_px) * (1.0 - np.hypot(n[:, 0], n[:, 1]))
        return {"pixels": px, "normals": n, "cos": cos, "visible": visible, "rim_px": rim,
                "toward_camera": -v}
    K, dist = camera_arrays(K, dist)
    C = np.asarray(center_cam, dtype=np.float64).reshape(3) / float(radius)  # unit radius
    D = float(np.linalg.norm(C))
    if not (D > 1.0 and C[2] > 0):
        raise ValueError("the ball must lie in front of the camera, not around it")
    c_hat = C / D
    n = normalize(w - c_hat)
    active = np.arange(len(w))
    for _ in range(int(iterations)):  # iterate only the directions not yet converged
        v = normalize(C + n[active])
        n_new = normalize(w[active] - v)
        step = np.linalg.norm(n_new - n[active], axis=1)
        n[active] = n_new
        active = active[~(step < tol)]
        if not len(active):
            break
    P = C + n
    v = normalize(P)
    cos = -np.sum(n * v, axis=1)
    ok = np.linalg.norm(_reflect(v, n) - w, axis=1) < 1e-6
    visible = ok & (cos > 1e-9) & np.all(np.isfinite(n), axis=1)
    f = float(np.sqrt(K[0, 0] * K[1, 1]))
    alpha = np.arcsin(1.0 / D)
    ang = np.arccos(np.clip(v @ c_hat, -1.0, 1.0))
    px = np.full((len(w), 2), np.nan)
    if visible.any():
        px[visible] = project_points(P[visible], K, dist)
    return {"pixels": px, "normals": n, "cos": np.where(visible, cos, 0.0), "visible": visible,
            "rim_px": f * (alpha - ang), "toward_camera": -c_hat}


def _sample(image, pixels, shape, border=0.0):
    """Bilinear samples of ``image`` (H, W[, c]) at ``pixels`` (n, 2); outside the image: ``border``."""
    mx = pixels[:, 0].astype(np.float32).reshape(shape)
    my = pixels[:, 1].astype(np.float32).reshape(shape)
    return cv2.remap(np.ascontiguousarray(image, dtype=np.float32), mx, my, interpolation=cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=border)


def unwrap_mirror_ball_Debevec1998(image, camera_model: str = "pinhole", K=None, dist=None,
                                   world_from_camera=None, center_cam=None, radius=None, center_px=None,
                                   radius_px=None, height: int = 128, valid=None, saturated=None,
                                   camera_cone_deg: float = CAMERA_CONE_DEG, rim_px: float = RIM_PX,
                                   supersample: int | None = None, reflectance: float = 1.0,
                                   resample: str = "splat") -> MirrorView:
    """Unwrap one photograph of a mirror ball into a lat-long radiance map with a confidence per direction.

    Parameters
    ----------
    image : (H_img, W_img, 3) float
        Linear radiance.
    camera_model : {'pinhole', 'orthographic'}
    K, dist : camera (pinhole)
    world_from_camera : (4, 4) float
        The camera's pose; only its rotation matters (directions).
    center_cam, radius : (3,) float, float
        Ball centre in the camera frame and radius (pinhole).
    center_px, radius_px : (2,) float, float
        The ball's disc in pixels (orthographic).
    height : int
        Output map height (width ``2 height``).
    valid : (H_img, W_img) bool, optional
        Usable pixels (default all).
    saturated : (H_img, W_img) bool, optional
        Clipped pixels (their directions are flagged ``clipped``).
    camera_cone_deg : float
        Half-angle of the masked cone around the direction toward the camera (0: none).
    rim_px : float
        Width of the rim given zero confidence, pixels.
    supersample : int or None
        Directions per output texel side; the samples are averaged with their solid angles and
        confidences (area-weighted, so the total power is kept). None: :func:`auto_supersample`
        (about 4 samples per pixel of the ball).
    reflectance : float
        The ball's reflectance; the map is the image divided by it.
    resample : {'splat', 'bilinear'}
        The radiance of a texel: ``'splat'`` (default) the mean of the pixels whose footprints
        reflect its directions (:func:`splat_mirror_ball`; texels smaller than a sub-pixel's
        footprint, which no sub-pixel lands in, keep the bilinear value); ``'bilinear'`` the photo
        sampled bilinearly at the texel's ``S x S`` directions (which blurs a lamp over a pixel more
        than the pixel's own footprint; ``docs/probes.md`` measures both). Which directions are
        seen, and the confidence, come from the backward map either way.

    Returns
    -------
    MirrorView
    """
    if resample not in RESAMPLE_MODES:
        raise ValueError(f"resample must be one of {RESAMPLE_MODES}, not {resample!r}")
    img = np.asarray(image, dtype=np.float32)
    H_img, W_img = img.shape[:2]
    h = int(height)
    if camera_model == "orthographic":
        r_px = float(radius_px)
    else:
        Kc, _ = camera_arrays(K, dist)
        D = float(np.linalg.norm(center_cam)) / float(radius)
        r_px = float(np.sqrt(Kc[0, 0] * Kc[1, 1]) * np.tan(np.arcsin(min(1.0 / D, 1.0))))
    s = max(int(supersample), 1) if supersample is not None else auto_supersample(r_px, h)
    T = np.asarray(world_from_camera, dtype=np.float64)
    Rwc = T[:3, :3]
    ok = np.ones((H_img, W_img), dtype=np.float32) if valid is None else np.asarray(valid, dtype=np.float32)
    sat = None if saturated is None else np.asarray(saturated, dtype=np.float32)
    cos_cone = np.cos(np.radians(camera_cone_deg)) if camera_cone_deg > 0 else None
    hf, wf = h * s, 2 * h * s
    t = np.linspace(0.0, np.pi, hf + 1)
    row_sa = (2 * np.pi / wf) * (np.cos(t[:-1]) - np.cos(t[1:]))  # solid angle of a fine texel, per fine row
    u = (np.arange(wf) + 0.5) / wf
    out = np.zeros((h, 2 * h, 3))
    conf_out = np.zeros((h, 2 * h))
    clip_out = np.zeros((h, 2 * h), dtype=bool)
    cone_out = np.zeros((h, 2 * h), dtype=bool)
    toward = None
    rows = max(1, int(2_000_000 // (wf * s)))  # output rows per chunk: about 2 M directions at a time
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        v = (np.arange(r0 * s, r1 * s) + 0.5) / hf
        uu, vv = np.meshgrid(u, v)
        d_world = latlong_uv_to_direction(uu, vv).reshape(-1, 3)
        g = mirror_ball_pixels(d_world @ Rwc, camera_model, K, dist, center_cam, radius, center_px, radius_px)
        toward = Rwc @ g["toward_camera"]
        px = np.where(g["visible"][:, None], g["pixels"], -10.0)
        shape = ((r1 - r0) * s, wf)
        rad = _sample(img, px, shape).astype(np.float64) / float(reflectance)
        ok_s = (_sample(ok, px, shape) > 0.999).ravel()
        cone = (d_world @ toward) >= cos_cone if cos_cone is not None else np.zeros(len(d_world), dtype=bool)
        conf = np.where(g["visible"] & (g["rim_px"] >= rim_px) & ok_s & ~cone, g["cos"], 0.0).reshape(shape)
        sa = np.repeat(row_sa[r0 * s:r1 * s, None], wf, axis=1)
        wgt = sa * conf
        blk = (r1 - r0, s, 2 * h, s)
        wsum = wgt.reshape(blk).sum(axis=(1, 3))
        num = (rad * wgt[..., None]).reshape(blk + (3,)).sum(axis=(1, 3))
        out[r0:r1] = num / np.where(wsum > 0, wsum, 1.0)[..., None]
        conf_out[r0:r1] = wsum / sa.reshape(blk).sum(axis=(1, 3))
        if sat is not None:
            clip_out[r0:r1] = ((_sample(sat, px, shape) > 0) & (conf > 0)).reshape(blk).any(axis=(1, 3))
        cone_out[r0:r1] = cone.reshape(blk).any(axis=(1, 3))
    if resample == "splat":
        spl, wsp = splat_mirror_ball(img, camera_model, K, dist, T, center_cam, radius, center_px, radius_px, h,
                                     valid, rim_px, toward, camera_cone_deg, None, reflectance)
        out = np.where((wsp > 0)[..., None], spl, out)
    return MirrorView(np.where(conf_out[..., None] > 0, out, 0.0).astype(np.float32),
                      conf_out.astype(np.float32), clip_out & (conf_out > 0), toward, cone_out)


#: How :func:`unwrap_mirror_ball_Debevec1998` resamples the photo: ``'splat'`` spreads every pixel
#: over the directions its footprint reflects (:func:`splat_mirror_ball`); ``'bilinear'`` samples the
#: photo bilinearly at each direction (the backward map alone).
RESAMPLE_MODES = ("splat", "bilinear")


def splat_supersample(radius_px: float, height: int, limit: int = 16) -> int:
    """Sub-pixels per pixel side for :func:`splat_mirror_ball`: sub-pixel footprints a third of a texel or less.

    A pixel of a mirror ball of radius ``r`` pixels reflects ``4 / r^2`` sr (orthographically, at
    every point of the disc), a square of side about ``2 / r`` radians; a texel of a lat-long map
    of height ``h`` is ``pi / h`` radians high. ``ceil(3 (2 / r) / (pi / h))``, at least 8 (each
    pixel's power is then shared among the texels its footprint covers to 1/64: with 4, a sun
    smaller than a pixel was shared unevenly enough to relight sunrise 0.66% wrong instead of
    0.28%, and 16 gave the same as 8, ``docs/probes.md``) and at most ``limit``.
    """
    s = int(np.ceil(6.0 * int(height) / (np.pi * max(float(radius_px), 1e-9))))
    return int(min(max(s, 8), limit))


def splat_mirror_ball(image, camera_model: str = "pinhole", K=None, dist=None, world_from_camera=None,
                      center_cam=None, radius=None, center_px=None, radius_px=None, height: int = 128, valid=None,
                      rim_px: float = RIM_PX, toward=None, camera_cone_deg: float = 0.0,
                      supersample: int | None = None, reflectance: float = 1.0, rows_per_chunk: int = 64):
    """Spread the pixels of a mirror ball over the directions they reflect (forward resampling).

    A pixel's value is the mean radiance over its footprint: the directions the ball reflects
    into it. Each pixel is cut into ``S x S`` sub-pixels, each traced to the ball and reflected
    (exactly: the ray from the camera, its intersection with the sphere, the mirror direction),
    and given the pixel's value with the weight of the area it covers on the ball seen across the
    ray (``t^2 (v . z)^3``, ``t`` the distance to the ball, ``v`` the unit ray, the distortion's
    change of pixel area neglected: the solid angle a mirror ball reflects is 4 / R^2 times that
    area; 1 for an orthographic camera). A texel gets
    the weighted mean of the sub-pixels landing in it. Unlike sampling the photo bilinearly at each
    direction, this adds no blur beyond the pixel's own footprint: a small bright lamp stays in the
    texels its pixels reflect, and every pixel's power is kept.

    Parameters
    ----------
    image : (H_img, W_img, 3) float
        Linear radiance.
    camera_model, K, dist, world_from_camera, center_cam, radius, center_px, radius_px, height, reflectance
        As :func:`unwrap_mirror_ball_Debevec1998`.
    valid : (H_img, W_img) bool, optional
        Usable pixels.
    rim_px : float
        Pixels whose centre lies within ``rim_px`` of the outline, or whose footprint is not all on
        the ball, are left out (they mix ball and background).
    toward : (3,) float, optional
        World direction from the ball toward the camera; with ``camera_cone_deg > 0`` sub-pixels
        reflecting directions within that cone of it are left out.
    supersample : int or None
        ``S``; None: :func:`splat_supersample`.
    rows_per_chunk : int
        Image rows traced at a time (bounds the memory: ``rows x W x S^2`` sub-pixels).

    Returns
    -------
    radiance : (height, 2 height, 3) float64
        The weighted mean per texel (0 where no sub-pixel landed).
    weight : (height, 2 height) float64
        The summed weights (0: the texel is not covered; use the backward sample there).
    """
    from ffls.camera.projection import pixel_rays
    from ffls.conventions import direction_to_latlong_uv

    img = np.asarray(image, dtype=np.float64)
    H_img, W_img = img.shape[:2]
    h = int(height)
    Rwc = np.asarray(world_from_camera, dtype=np.float64)[:3, :3]
    ok = np.ones((H_img, W_img), dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    if camera_model == "orthographic":
        c_px = np.asarray(center_px, dtype=np.float64).reshape(2)
        r_px = float(radius_px)
        cx, cy = c_px
    else:
        Kc, dc = camera_arrays(K, dist)
        C = np.asarray(center_cam, dtype=np.float64).reshape(3) / float(radius)  # unit radius
        D = float(np.linalg.norm(C))
        f = float(np.sqrt(Kc[0, 0] * Kc[1, 1]))
        alpha = np.arcsin(1.0 / D)
        r_px = f * np.tan(alpha)
        cx, cy = project_points(C[None], Kc, dc)[0]
    S = max(int(supersample), 1) if supersample is not None else splat_supersample(r_px, h)
    m = 1.2 * r_px + 3.0  # the disc's bounding box, with room for distortion
    x0, x1 = max(int(np.floor(cx - m)), 0), min(int(np.ceil(cx + m)) + 1, W_img)
    y0, y1 = max(int(np.floor(cy - m)), 0), min(int(np.ceil(cy + m)) + 1, H_img)
    num = np.zeros((h * 2 * h, 3))
    wsum = np.zeros(h * 2 * h)
    if x1 <= x0 or y1 <= y0:
        return num.reshape(h, 2 * h, 3), wsum.reshape(h, 2 * h)
    cos_cone = np.cos(np.radians(camera_cone_deg)) if camera_cone_deg > 0 and toward is not None else None
    off = (np.arange(S) + 0.5) / S - 0.5
    xs = np.arange(x0, x1)
    for r0 in range(y0, y1, max(1, int(rows_per_chunk))):
        r1 = min(y1, r0 + max(1, int(rows_per_chunk)))
        yy, xx = np.meshgrid(np.arange(r0, r1), xs, indexing="ij")
        ny, nx = yy.shape
        # sub-pixel positions (ny, S, nx, S)
        sy = (yy[:, None, :, None] + off[None, :, None, None]) + 0.0 * off[None, None, None, :]
        sx = (xx[:, None, :, None] + off[None, None, None, :]) + 0.0 * off[None, :, None, None]
        sub = np.stack([sx.ravel(), sy.ravel()], axis=1)
        if camera_model == "orthographic":
            ab = (sub - c_px) / r_px
            q = 1.0 - np.sum(ab * ab, axis=1)
            hit = q > 0
            n = np.concatenate([ab, -np.sqrt(np.clip(q, 0.0, None))[:, None]], axis=1)
            v = np.broadcast_to(np.array([0.0, 0.0, 1.0]), n.shape)
            wgt = np.ones(len(sub))
            centre = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(np.float64)
            rim = r_px - np.hypot(centre[:, 0] - cx, centre[:, 1] - cy)
        else:
            v = pixel_rays(sub, Kc, dc)
            b = v @ C
            disc = b * b - (C @ C - 1.0)
            hit = (disc >= 0) & (b > 0)
            t = b - np.sqrt(np.where(hit, disc, 0.0))
            n = t[:, None] * v - C
            wgt = t ** 2 * np.clip(v[:, 2], 0.0, None) ** 3
            vc = pixel_rays(np.stack([xx.ravel(), yy.ravel()], axis=1).astype(np.float64), Kc, dc)
            rim = f * (alpha - np.arccos(np.clip(vc @ (C / D), -1.0, 1.0)))
        r = v - 2.0 * np.sum(v * n, axis=1, keepdims=True) * n
        wd = r @ Rwc.T
        # a pixel is used when its centre is rim_px inside the outline, all its footprint on the ball, and it is valid
        use_px = (rim >= float(rim_px)) & ok[r0:r1, x0:x1].ravel()
        use_px &= hit.reshape(ny, S, nx, S).all(axis=(1, 3)).ravel()
        use = np.broadcast_to(use_px.reshape(ny, 1, nx, 1), (ny, S, nx, S)).ravel() & hit
        if cos_cone is not None:
            use &= (wd @ np.asarray(toward, dtype=np.float64)) < cos_cone
        if not use.any():
            continue
        u, vv = direction_to_latlong_uv(wd[use])
        col = np.clip((np.asarray(u) * 2 * h).astype(np.int64), 0, 2 * h - 1)
        row = np.clip((np.asarray(vv) * h).astype(np.int64), 0, h - 1)
        idx = row * 2 * h + col
        val = np.broadcast_to(img[r0:r1, x0:x1][:, None, :, None, :], (ny, S, nx, S, 3)).reshape(-1, 3)[use]
        w = wgt[use]
        wsum += np.bincount(idx, weights=w, minlength=h * 2 * h)
        for c in range(3):
            num[:, c] += np.bincount(idx, weights=w * val[:, c], minlength=h * 2 * h)
    out = num / np.where(wsum > 0, wsum, 1.0)[:, None] / float(reflectance)
    return out.reshape(h, 2 * h, 3), wsum.reshape(h, 2 * h)


def auto_supersample(radius_px: float, height: int, samples_per_pixel: float = 4.0, limit: int = 16) -> int:
    """Directions per texel side so that the ball's pixels get about ``samples_per_pixel`` samples each.

    The ball's disc (``pi r^2`` pixels) covers the sphere of directions (``2 (s h)^2`` fine texels)
    with a nearly uniform density (the orthographic mirror ball is Lambert's equal-area projection),
    so ``s = ceil(sqrt(samples_per_pixel * pi / 2) r / h)``, at least 1 and at most ``limit``. A
    compact bright source of a pixel or two is then sampled often enough that its energy is kept.
    """
    s = int(np.ceil(np.sqrt(samples_per_pixel * np.pi / 2) * float(radius_px) / int(height)))
    return int(min(max(s, 1), limit))


def merge_mirror_views(views, power: float = 2.0) -> MirrorView:
    """Combine unwrapped views of a mirror ball, per direction, weighted by ``confidence ** power``.

    Clipped samples (lower bounds) count only where no view saw the direction unclipped.

    Parameters
    ----------
    views : sequence of MirrorView
        Of one size.
    power : float
        Weight exponent.

    Returns
    -------
    MirrorView
        ``confidence`` is the largest of the views'; ``camera_direction`` and ``camera_cone`` are
        those of the first view, ``camera_cone`` kept only where no other view saw the direction.
    """
    views = list(views)
    if len(views) == 1:
        return views[0]
    conf = np.stack([v.confidence for v in views]).astype(np.float64)
    clipped = np.stack([v.clipped for v in views])
    seen = conf > 0
    unclipped_somewhere = np.any(seen & ~clipped, axis=0)
    use = seen & ~(clipped & unclipped_somewhere[None])
    w = np.where(use, conf ** float(power), 0.0)
    wsum = w.sum(axis=0)
    rad = np.stack([v.radiance for v in views]).astype(np.float64)
    out = (rad * w[..., None]).sum(axis=0) / np.where(wsum > 0, wsum, 1.0)[..., None]
    best = conf.max(axis=0)
    return MirrorView(out.astype(np.float32), best.astype(np.float32), np.any(seen, axis=0) & ~unclipped_somewhere,
                      views[0].camera_direction, views[0].camera_cone & ~(best > 0))


def fill_unseen(radiance, seen, k: int = 16) -> np.ndarray:
    """Fill the unseen texels of a lat-long map from the nearest seen directions.

    Each unseen texel takes the per-channel median of its ``k`` nearest seen texel directions
    (on the sphere, so the seam and the poles need no care). The median, unlike a mean, does not
    smear a compact bright source at the edge of the blind spot over all of it.

    Parameters
    ----------
    radiance : (H, 2H, 3) float
    seen : (H, 2H) bool
    k : int

    Returns
    -------
    (H, 2H, 3) float32
        ``radiance`` where seen, filled elsewhere (unchanged when nothing or everything is seen).
    """
    rad = np.asarray(radiance, dtype=np.float32)
    seen = np.asarray(seen, dtype=bool)
    if seen.all() or not seen.any():
        return rad.copy()
    h = rad.shape[0]
    d = latlong_directions(2 * h, h).reshape(-1, 3)
    flat_seen = seen.ravel()
    tree = cKDTree(d[flat_seen])
    kk = int(min(k, flat_seen.sum()))
    _, idx = tree.query(d[~flat_seen], k=kk)
    idx = np.asarray(idx).reshape(-1, kk)
    src = rad.reshape(-1, 3)[flat_seen]
    out = rad.reshape(-1, 3).copy()
    out[~flat_seen] = np.median(src[idx], axis=1)
    return out.reshape(rad.shape)


def blind_spot(seen) -> BlindSpot:
    """The solid angle, centre and equivalent cone of the directions not ``seen`` ((H, 2H) bool lat-long)."""
    seen = np.asarray(seen, dtype=bool)
    h = seen.shape[0]
    sa = latlong_solid_angles(h)
    un = ~seen
    omega = float(sa[un].sum())
    if omega <= 0:
        return BlindSpot(0.0, 0.0, None, 0.0)
    d = latlong_directions(2 * h, h)
    m = (d[un] * sa[un][:, None]).sum(axis=0)
    nrm = float(np.linalg.norm(m))
    direction = m / nrm if nrm > 1e-12 else None
    radius = float(np.degrees(np.arccos(np.clip(1.0 - omega / (2 * np.pi), -1.0, 1.0))))
    return BlindSpot(omega, omega / (4 * np.pi), direction if direction is not None else np.zeros(3), radius)
