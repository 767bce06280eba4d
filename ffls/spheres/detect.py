"""Finding the reference spheres: silhouette edges -> sphere centres (Masselus et al. 2002, sec. 5).

The Free-form Light Stage places four white diffuse spheres of known radius ``R`` beside the
object. Their centres ``C`` (camera frame) give every sphere pixel a surface normal, from which
the per-photo light direction follows (:mod:`ffls.spheres.estimate`).

Method
------
1. **Max image.** The per-pixel maximum over the whole sequence (:func:`max_image`). A hand-held
   light visits every side of the spheres, so in the maximum each sphere is lit almost all the
   way round and its silhouette is a closed, high-contrast outline; a single photo shows only the
   lit crescent, whose terminator is not a silhouette.
2. **Edges.** Luminance of the max image, log tone-mapped to 8 bit, lightly blurred; Canny with
   thresholds derived from the image itself (Otsu split into background and foreground classes;
   the edge contrast is the difference of the class means). Edge pixels are refined to subpixel
   precision along the gradient (parabola through the gradient magnitude).
3. **Candidates.** With no hints, :func:`cv2.HoughCircles` (``HOUGH_GRADIENT_ALT``) proposes
   circles, scored by how much of their outline the edges support and how bright their inside is;
   the ``n_spheres`` best non-overlapping ones are kept. Hints (an approximate pixel circle, or a
   world centre projected through the camera) restrict the search to an annulus around them.
   Overrides skip detection altogether.
4. **Centre from the silhouette (equation 1).** Every silhouette ray ``s_i`` is tangent to the
   sphere: ``|C|^2 - R^2 - (s_i . C)^2 = 0``. The same condition in geometric form is
   ``angle(s_i, C) = alpha`` with ``sin(alpha) = R / |C|``: the rays lie on the tangent cone. We
   minimise ``f * (angle(s_i, c) - alpha)`` (``f`` the focal length in pixels, so the residual
   is in pixels) over the cone axis ``c`` and half-angle ``alpha``, and set
   ``C = R / sin(alpha) * c``. This parametrisation stays well conditioned for a near-orthographic
   camera (a long lens far away), where the algebraic form degenerates: direction and apparent
   size are always well measured, and the depth follows from the apparent size.
5. **Robustness.** Edge pixels that are not silhouette (a stand, an occluder, a shadow boundary,
   the terminator) are handled by (a) keeping only edges whose gradient is radial and of the
   majority polarity, (b) a RANSAC circle search for the initial cone, (c) a ``soft_l1`` loss
   with a 1-pixel scale, and (d) trimming at a robust multiple of the residual spread followed
   by a refit on the inliers. Inlier counts, the fraction of the outline covered by inliers and
   the RMS residual are reported.

The silhouette fixes only the cone, not ``R``: a wrong ``sphere_radius`` scales every centre's
distance. It is caught against a scene scale where one exists (the camera's distance to the
scene centre from ``world_from_camera``, or world-centre hints).
"""
from __future__ import annotations

import dataclasses
import os

import cv2
import numpy as np
from scipy.optimize import least_squares

from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA, angle_between, tangent_basis
from ffls.camera.projection import camera_arrays, pixel_rays, project_points
from ffls.errors import InputError
from ffls.radiance.photos import load_photo

__all__ = [
    "SphereFit",
    "max_image",
    "pixel_rays",
    "project_points",
    "find_spheres",
    "find_spheres_in_capture",
    "fit_sphere_center",
    "sphere_mask",
    "sphere_normals",
    "silhouette_px",
    "to_world",
    "edge_points",
]


# ----------------------------------------------------------------------------- result
@dataclasses.dataclass
class SphereFit:
    """One reference sphere found in the images.

    Attributes
    ----------
    center_cam : (3,) float64
        Sphere centre in the camera frame (OpenCV: x right, y down, z forward), scene units.
    center_world : (3,) float64
        The same centre in the world frame (``world_from_camera`` applied).
    radius : float
        Sphere radius in scene units (the capture's ``sphere_radius``).
    center_px : (2,) float64
        Projection of the centre into the (distorted) image, pixels.
    radius_px : float
        Apparent radius: mean distance from ``center_px`` to the projected silhouette.
    residual_px : float
        RMS distance of the inlier silhouette rays from the fitted tangent cone, pixels.
    n_edge_points : int
        Edge points considered for this sphere.
    n_inliers : int
        Edge points kept as silhouette.
    inlier_fraction : float
        ``n_inliers / n_edge_points``.
    coverage : float
        Fraction of the outline (36 angular bins around the centre) with inlier support.
    source : str
        ``'auto'`` (Hough), ``'hint'`` or ``'override'``.
    edge_px : (m, 2) float64
        The inlier silhouette points, pixels (empty for overrides).
    K, dist : arrays
        The camera used for the fit (kept so :meth:`mask` and :meth:`normals` need no arguments).
    world_from_camera : (4, 4) float64
    """

    center_cam: np.ndarray
    center_world: np.ndarray
    radius: float
    center_px: np.ndarray
    radius_px: float
    residual_px: float
    n_edge_points: int
    n_inliers: int
    inlier_fraction: float
    coverage: float
    source: str
    edge_px: np.ndarray
    K: np.ndarray
    dist: np.ndarray
    world_from_camera: np.ndarray

    @property
    def distance(self) -> float:
        """Distance from the camera centre to the sphere centre, scene units."""
        return float(np.linalg.norm(self.center_cam))

    def mask(self, shape, margin_px: float = 0.0) -> np.ndarray:
        """Pixels whose rays hit this sphere; see :func:`sphere_mask`."""
        return sphere_mask(shape, self.K, self.dist, self.center_cam, self.radius, margin_px=margin_px)

    def normals(self, pixels) -> np.ndarray:
        """Camera-frame unit normals at ``pixels`` (n, 2); see :func:`sphere_normals`."""
        return sphere_normals(pixels, self.K, self.dist, self.center_cam, self.radius)

    def normals_world(self, pixels) -> np.ndarray:
        """World-frame unit normals at ``pixels`` (n, 2)."""
        return to_world(self.normals(pixels), self.world_from_camera, points=False)

    def to_dict(self) -> dict:
        """JSON-friendly summary (no edge points, no camera)."""
        return {
            "center_cam": [float(v) for v in self.center_cam],
            "center_world": [float(v) for v in self.center_world],
            "radius": float(self.radius),
            "center_px": [float(v) for v in self.center_px],
            "radius_px": float(self.radius_px),
            "residual_px": float(self.residual_px),
            "n_edge_points": int(self.n_edge_points),
            "n_inliers": int(self.n_inliers),
            "inlier_fraction": float(self.inlier_fraction),
            "coverage": float(self.coverage),
            "source": self.source,
        }


# ----------------------------------------------------------------------------- camera helpers
def to_world(v, world_from_camera=None, points: bool = True) -> np.ndarray:
    """Camera-frame points or directions (..., 3) to the world frame.

    Parameters
    ----------
    v : (..., 3) float
    world_from_camera : (4, 4) float or None
        ``None`` uses :data:`ffls.conventions.DEFAULT_WORLD_FROM_CAMERA`.
    points : bool
        True for points (rotation and translation), False for directions/normals (rotation only).
    """
    T = DEFAULT_WORLD_FROM_CAMERA if world_from_camera is None else np.asarray(world_from_camera, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    out = v @ T[:3, :3].T
    return out + T[:3, 3] if points else out


def _cone(C, R):
    C = np.asarray(C, dtype=np.float64).reshape(3)
    d = float(np.linalg.norm(C))
    if not (np.isfinite(d) and R > 0 and d > R and C[2] > 0):
        raise ValueError("the sphere must lie in front of the camera, not around it")
    return C / d, float(np.arcsin(R / d))


def silhouette_px(K, dist, C, R, n: int = 90) -> np.ndarray:
    """Pixels (n, 2) of the sphere's outline: the tangent circle projected with distortion."""
    c, alpha = _cone(C, R)
    a, b = tangent_basis(c)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
    rays = np.cos(alpha) * c + np.sin(alpha) * (np.cos(t) * a + np.sin(t) * b)
    return project_points(rays, K, dist)


def sphere_mask(shape, K, dist, C, R, margin_px: float = 0.0) -> np.ndarray:
    """Pixels whose viewing rays hit the sphere.

    Parameters
    ----------
    shape : tuple
        Image shape ``(H, W)`` or ``(H, W, c)``.
    K : (3, 3) float
    dist : (k,) float or None
    C : (3,) float
        Sphere centre, camera frame.
    R : float
        Sphere radius (same units as ``C``).
    margin_px : float
        Keep only pixels at least this far (pixels, approximately) inside the outline; use it to
        drop the rim, where normals are grazing and edge pixels mix sphere and background.

    Returns
    -------
    (H, W) bool
    """
    K, dist = camera_arrays(K, dist)
    H, W = int(shape[0]), int(shape[1])
    c, alpha = _cone(C, R)
    f = float(np.sqrt(K[0, 0] * K[1, 1]))
    mask = np.zeros((H, W), dtype=bool)
    outline = silhouette_px(K, dist, C, R)
    x0 = max(int(np.floor(outline[:, 0].min())) - 2, 0)
    x1 = min(int(np.ceil(outline[:, 0].max())) + 3, W)
    y0 = max(int(np.floor(outline[:, 1].min())) - 2, 0)
    y1 = min(int(np.ceil(outline[:, 1].max())) + 3, H)
    if x0 >= x1 or y0 >= y1:
        return mask
    yy, xx = np.mgrid[y0:y1, x0:x1]
    rays = pixel_rays(np.stack([xx.ravel(), yy.ravel()], axis=1), K, dist)
    ang = angle_between(rays, c)
    mask[y0:y1, x0:x1] = (ang <= alpha - margin_px / f).reshape(yy.shape)
    return mask


def sphere_normals(pixels, K, dist, C, R) -> np.ndarray:
    """Camera-frame unit surface normals where the pixels' rays first hit the sphere.

    Parameters
    ----------
    pixels : (n, 2) float
    K, dist : camera
    C : (3,) float
        Sphere centre, camera frame.
    R : float

    Returns
    -------
    (n, 3) float64
        Unit normals ``(P - C) / R`` with ``P`` the nearer intersection; NaN for rays that miss.
    """
    C = np.asarray(C, dtype=np.float64).reshape(3)
    s = pixel_rays(pixels, K, dist)
    b = s @ C
    disc = b * b - (C @ C - R * R)
    hit = disc >= 0
    t = b - np.sqrt(np.where(hit, disc, 0.0))
    n = (t[:, None] * s - C) / R
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[~hit] = np.nan
    return n


# ----------------------------------------------------------------------------- images
def max_image(images) -> np.ndarray:
    """Per-pixel maximum over a sequence of linear images.

    Parameters
    ----------
    images : (H, W, 3) or (N, H, W, 3) array, or an iterable of (H, W, 3) / (H, W) arrays
        A single image is returned as float32 unchanged (it is taken to be a max image already).
        Non-finite values are treated as 0.

    Returns
    -------
    (H, W, 3) or (H, W) float32
    """
    if isinstance(images, np.ndarray) and images.ndim in (2, 3) and not (images.ndim == 3 and images.shape[-1] not in (1, 3, 4)):
        return np.nan_to_num(images.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    acc = None
    for im in images:
        im = np.nan_to_num(np.asarray(im, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        if acc is None:
            acc = im.copy()
        elif im.shape != acc.shape:
            raise ValueError(f"image shapes differ: {im.shape} vs {acc.shape}")
        else:
            np.maximum(acc, im, out=acc)
    if acc is None:
        raise ValueError("no images")
    return acc


def _luminance(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img, dtype=np.float64)
    if img.ndim == 3:
        if img.shape[2] >= 3:
            return img[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
        return img[..., 0]
    return img


def _log8(L: np.ndarray) -> tuple[np.ndarray, float]:
    """Log tone map of luminance to 8 bit (float, 0..255) over the image's own range.

    ``g = s * ln((L + eps) / eps)``, with ``eps`` twice the noise level (so noise in the dark is
    not amplified) and ``s`` chosen so the robust peak (maximum after a 3x3 median, so hot pixels
    do not set the scale) maps to 255. Returns ``(g, s)``: ``s`` is 8-bit levels per natural-log
    unit, i.e. a radiance ratio ``r`` across an edge is a step of ``s * ln(r)`` levels.
    """
    L = np.clip(np.nan_to_num(np.asarray(L, dtype=np.float64)), 0, None)
    L32 = np.ascontiguousarray(L, dtype=np.float32)
    ref = float(cv2.medianBlur(L32, 3).max())
    if ref <= 0:
        ref = float(L.max()) or 1.0
    sigma = 1.4826 * float(np.median(np.abs(L32 - cv2.medianBlur(L32, 3))))
    eps = max(2.0 * sigma, 1e-5 * ref)
    s = 255.0 / np.log((ref + eps) / eps)
    return np.clip(s * np.log((L + eps) / eps), 0, 255), float(s)


def edge_points(img, sigma: float = 1.0):
    """Canny edges of a (max) image with data-driven thresholds, refined to subpixel.

    Parameters
    ----------
    img : (H, W) or (H, W, 3) float
        Linear image.
    sigma : float
        Gaussian blur (pixels) before edge detection.

    Returns
    -------
    points : (n, 2) float64
        Subpixel edge positions (x, y).
    grads : (n, 2) float64
        Unit gradient directions (pointing toward brighter) at the points.
    """
    L = _luminance(img)
    g8f, scale = _log8(L)
    blur = cv2.GaussianBlur(g8f, (0, 0), sigma)
    g8 = np.clip(np.rint(blur), 0, 255).astype(np.uint8)
    # Thresholds from the image's log scale: a silhouette of a white sphere is a radiance ratio
    # of at least ~1.5 (0.4 log units; the sphere against a grey table); blurred over ~2 px that
    # step gives an L2 Sobel magnitude of about 2.9 * 0.4 * s. Never below the noise: most pixels
    # are flat, so the median gradient magnitude measures it.
    gx = cv2.Sobel(blur, cv2.CV_64F, 1, 0, ksize=3)
    gy = cv2.Sobel(blur, cv2.CV_64F, 0, 1, ksize=3)
    mag = np.hypot(gx, gy)
    noise = float(np.median(mag))
    high = max(1.0 * scale, 8.0 * noise)
    low = 0.5 * high
    edges = cv2.Canny(g8, low, high, L2gradient=True)
    ys, xs = np.nonzero(edges)
    if xs.size == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    gxi, gyi = gx[ys, xs], gy[ys, xs]
    m0 = mag[ys, xs]
    n = np.stack([gxi, gyi], axis=1) / np.maximum(m0, 1e-12)[:, None]
    p = np.stack([xs, ys], axis=1).astype(np.float64)
    mp = _bilinear(mag, p + n)
    mm = _bilinear(mag, p - n)
    den = mm - 2 * m0 + mp
    off = np.where(den < 0, 0.5 * (mm - mp) / np.where(den < 0, den, -1.0), 0.0)
    off = np.clip(off, -0.5, 0.5)
    return p + off[:, None] * n, n


def _bilinear(img, xy):
    """Bilinear samples of ``img`` (H, W) at points (n, 2) (x, y), clamped to the image."""
    H, W = img.shape
    x = np.clip(xy[:, 0], 0, W - 1.000001)
    y = np.clip(xy[:, 1], 0, H - 1.000001)
    x0 = np.floor(x).astype(int)
    y0 = np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    return ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x0 + 1])
            + fy * ((1 - fx) * img[y0 + 1, x0] + fx * img[y0 + 1, x0 + 1]))


def _radius_from_edges(pts, grads, cpx, r_max):
    """Apparent radius around a known centre: the peak of the radial-edge distance histogram."""
    v = pts - cpx
    d = np.hypot(v[:, 0], v[:, 1])
    cosr = np.abs(np.sum(v * grads, axis=1)) / np.maximum(d, 1e-9)
    sel = (cosr > 0.9) & (d >= 3) & (d <= r_max)
    if sel.sum() < 8:
        return None
    hist = np.bincount(np.rint(d[sel]).astype(int), minlength=int(r_max) + 3).astype(np.float64)
    hist = np.convolve(hist, [1, 2, 1], mode="same")
    r = int(np.argmax(hist))
    return float(r) if hist[r] >= 8 else None


# ----------------------------------------------------------------------------- fitting
def _circle_from_3(p):
    (x1, y1), (x2, y2), (x3, y3) = p
    a = np.array([[x2 - x1, y2 - y1], [x3 - x1, y3 - y1]]) * 2
    b = np.array([x2**2 - x1**2 + y2**2 - y1**2, x3**2 - x1**2 + y3**2 - y1**2])
    det = np.linalg.det(a)
    if abs(det) < 1e-9:
        return None
    c = np.linalg.solve(a, b)
    return c, float(np.hypot(*(p[0] - c)))


def _ransac_circle(pts, r_expected, rng, n_iter=300, tol=1.5):
    """Best-supported circle (centre (2,), radius) among 3-point samples, radius within 40 %."""
    best, best_n = None, -1
    m = len(pts)
    if m < 3:
        return None
    for _ in range(n_iter):
        idx = rng.choice(m, 3, replace=False)
        res = _circle_from_3(pts[idx])
        if res is None:
            continue
        c, r = res
        if not (0.6 * r_expected <= r <= 1.4 * r_expected):
            continue
        n_in = int(np.count_nonzero(np.abs(np.hypot(*(pts - c).T) - r) < tol))
        if n_in > best_n:
            best, best_n = (c, r), n_in
    return best


def _cone_residuals(params, s, f):
    x, y, a = params / f
    c = np.array([x, y, 1.0])
    c /= np.linalg.norm(c)
    return f * (angle_between(s, c) - a)


def fit_sphere_center(rays, R, f, init_dir, init_alpha, f_scale: float = 1.0, trim: float = 3.0):
    """Robust fit of a sphere centre to silhouette rays (equation 1 in geometric form).

    Parameters
    ----------
    rays : (n, 3) float
        Unit back-projected rays of candidate silhouette points (camera frame).
    R : float
        Sphere radius, scene units.
    f : float
        Focal length in pixels (sqrt(fx fy)); converts angles to pixels.
    init_dir : (3,) float
        Initial direction of the centre.
    init_alpha : float
        Initial apparent angular radius, radians.
    f_scale : float
        Robust (soft_l1) loss scale, pixels.
    trim : float
        Points farther than ``max(trim * robust sigma, 1 px)`` from the cone are outliers.

    Returns
    -------
    C : (3,) float64
        Centre, camera frame.
    inliers : (n,) bool
    residuals : (n,) float64
        Signed distances of all rays from the fitted cone, pixels.
    """
    s = np.asarray(rays, dtype=np.float64)
    d = np.asarray(init_dir, dtype=np.float64)
    p0 = f * np.array([d[0] / d[2], d[1] / d[2], init_alpha])
    inl = np.ones(len(s), dtype=bool)
    p = p0
    for _ in range(3):
        sol = least_squares(_cone_residuals, p, args=(s[inl], f), loss="soft_l1", f_scale=f_scale,
                            x_scale=1.0, method="trf")
        p = sol.x
        r = _cone_residuals(p, s, f)
        sigma = 1.4826 * np.median(np.abs(r[inl])) + 1e-9
        new = np.abs(r) < max(trim * sigma, 1.0)
        if new.sum() < 3 or np.array_equal(new, inl):
            inl = new if new.sum() >= 3 else inl
            break
        inl = new
    x, y, a = p / f
    if not (0 < a < np.pi / 2):
        raise ValueError("fitted apparent radius is not in (0, 90) degrees")
    c = np.array([x, y, 1.0])
    c /= np.linalg.norm(c)
    return R / np.sin(a) * c, inl, _cone_residuals(p, s, f)


def _coverage(points, center, n_bins=36):
    if len(points) == 0:
        return 0.0
    ang = np.arctan2(points[:, 1] - center[1], points[:, 0] - center[0])
    bins = np.floor((ang + np.pi) / (2 * np.pi) * n_bins).astype(int) % n_bins
    return float(np.unique(bins).size / n_bins)


# ----------------------------------------------------------------------------- candidates
def _score_circle(cx, cy, r, dt, L, bg):
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    H, W = dt.shape
    xs = cx + r * np.cos(t)
    ys = cy + r * np.sin(t)
    ok = (xs >= 0) & (xs <= W - 1) & (ys >= 0) & (ys <= H - 1)
    if not ok.any():
        return 0.0
    d = dt[np.rint(ys[ok]).astype(int), np.rint(xs[ok]).astype(int)]
    support = np.count_nonzero(d <= 1.5) / t.size
    yy, xx = np.ogrid[:H, :W]
    inside = (xx - cx) ** 2 + (yy - cy) ** 2 <= (0.7 * r) ** 2
    bright = float(np.median(L[inside])) if inside.any() else 0.0
    return support * (1.0 if bright > bg else 0.25)


def _hough_candidates(g8, min_r, max_r, scale):
    """Circle candidates (m, 3) = (x, y, r) from OpenCV's Hough transforms on the log image.

    ``scale`` (levels per log unit, from :func:`_log8`) sets Hough's internal Canny threshold to
    a radiance ratio of about e^2 for ``HOUGH_GRADIENT_ALT`` (Scharr) and e for ``HOUGH_GRADIENT``.
    """
    blur = cv2.GaussianBlur(g8, (0, 0), 1.5)
    found = []
    for p2 in (0.9, 0.8, 0.7):
        c = cv2.HoughCircles(blur, cv2.HOUGH_GRADIENT_ALT, dp=1.5, minDist=max(2 * min_r, 4),
                             param1=2.0 * scale, param2=p2, minRadius=int(min_r), maxRadius=int(max_r))
        if c is not None:
            found.extend(c.reshape(-1, 3).tolist())
    c = cv2.HoughCircles(blur, cv2.HOUGH_GRADIENT, dp=1, minDist=max(2 * min_r, 4), param1=scale,
                         param2=20, minRadius=int(min_r), maxRadius=int(max_r))
    if c is not None:
        found.extend(c.reshape(-1, 3)[:30].tolist())
    return np.array(found, dtype=np.float64).reshape(-1, 3)


# ----------------------------------------------------------------------------- main entry
def _parse_hint(h, K, dist, world_from_camera, R):
    """(center_px (2,), radius_px, center_cam or None) from one hint dict."""
    if "center_px" in h:
        r = float(h.get("radius_px", 0)) or None
        return np.asarray(h["center_px"], dtype=np.float64), r, None
    if "center" in h or "center_world" in h:
        Cw = np.asarray(h.get("center", h.get("center_world")), dtype=np.float64)
        T = np.linalg.inv(world_from_camera)
        Cc = T[:3, :3] @ Cw + T[:3, 3]
        if Cc[2] <= R:
            raise ValueError(f"hinted centre {Cw.tolist()} is not in front of the camera")
        cpx = project_points(Cc[None], K, dist)[0]
        return cpx, None, Cc  # radius from the image: a wrong sphere_radius must not steer the search
    if "center_cam" in h:
        Cc = np.asarray(h["center_cam"], dtype=np.float64)
        outline = silhouette_px(K, dist, Cc, R)
        cpx = project_points(Cc[None], K, dist)[0]
        return cpx, float(np.mean(np.hypot(*(outline - cpx).T))), Cc
    raise ValueError(f"a sphere hint needs 'center', 'center_cam' or 'center_px', got keys {sorted(h)}")


def _make_fit(C, R, K, dist, wfc, source, edge_px=None, residual=0.0, n_edge=0, n_in=0, coverage=1.0):
    outline = silhouette_px(K, dist, C, R)
    cpx = project_points(np.asarray(C)[None], K, dist)[0]
    return SphereFit(
        center_cam=np.asarray(C, dtype=np.float64), center_world=to_world(C, wfc), radius=float(R),
        center_px=cpx, radius_px=float(np.mean(np.hypot(*(outline - cpx).T))), residual_px=float(residual),
        n_edge_points=int(n_edge), n_inliers=int(n_in), inlier_fraction=float(n_in / n_edge) if n_edge else 1.0,
        coverage=float(coverage), source=source, edge_px=np.zeros((0, 2)) if edge_px is None else edge_px,
        K=K, dist=dist, world_from_camera=wfc)


def _refine_on_lit_limb(ft, L, K, dist, R, f, wfc, lit_limb, min_points: int = 8,
                        min_coverage: float = 0.5):
    """Refit a found sphere on the part of its outline where the limb is directly lit.

    Where the limb is lit only by the ground bounce (the underside, above the sphere's own contact
    shadow) or never lit (azimuths the hand-held light did not visit), the max image fades
    gradually from the limb into a dark background and the edge lands inside the silhouette: on
    path-traced renders the centre moved up by 0.2-0.5 px and the distance grew by 0.3-0.8 %
    (docs/spheres.md, "Independent renders"). A directly lit limb is a sharp, high-contrast step.
    Edge points whose limb (1.5 px inside) is below ``lit_limb`` times the sphere's 95th
    percentile in the max image are dropped and the cone is refitted, if enough outline remains
    (``min_points``, ``min_coverage``); otherwise the fit is returned unchanged.
    """
    P = ft.edge_px
    if P is None or len(P) < min_points:
        return ft
    H, W = L.shape
    cpx, r = ft.center_px, ft.radius_px
    rr = np.hypot(P[:, 0] - cpx[0], P[:, 1] - cpx[1])
    u = (cpx - P) / np.maximum(rr, 1e-9)[:, None]
    limb = _bilinear(L, P + 1.5 * u)
    y0, y1 = max(int(cpx[1] - r), 0), min(int(cpx[1] + r) + 1, H)
    x0, x1 = max(int(cpx[0] - r), 0), min(int(cpx[0] + r) + 1, W)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (xx - cpx[0]) ** 2 + (yy - cpx[1]) ** 2 <= (0.8 * r) ** 2
    if not inside.any():
        return ft
    keep = limb >= lit_limb * float(np.percentile(L[yy[inside], xx[inside]], 95))
    if keep.sum() < min_points or keep.all() or _coverage(P[keep], cpx) < min_coverage:
        return ft
    s = pixel_rays(P[keep], K, dist)
    C0 = ft.center_cam
    try:
        C, inl, res = fit_sphere_center(s, R, f, C0 / np.linalg.norm(C0), float(np.arcsin(R / np.linalg.norm(C0))))
    except ValueError:
        return ft
    Pk = P[keep]
    rms = float(np.sqrt(np.mean(res[inl] ** 2)))
    return _make_fit(C, R, K, dist, wfc, ft.source, edge_px=Pk[inl], residual=rms, n_edge=ft.n_edge_points,
                     n_in=int(inl.sum()), coverage=_coverage(Pk[inl], project_points(C[None], K, dist)[0]))


def find_spheres(images, K, dist, sphere_radius, n_spheres: int = 4, hints=None, overrides=None,
                 world_from_camera=None, scene_center=None, source: str | os.PathLike | None = None,
                 max_residual_px: float = 1.5, min_coverage: float = 0.3, seed: int = 0,
                 lit_limb: float | None = 0.65) -> list[SphereFit]:
    """Find the reference spheres and their centres.

    The stages of the module docstring, one function each: the max image
    (:func:`_max_luminance`), its edges (:func:`_edge_map`), candidate circles
    (:func:`_hinted_candidates` or :func:`_hough_circle_candidates`), a cone fit per candidate
    (:func:`_fit_candidates`), the choice of the spheres (:func:`_choose_spheres`, or
    :func:`_check_hinted_fits` with hints), the lit-limb refit (:func:`_refine_on_lit_limb`) and
    the checks (:func:`_check_inside_image`, :func:`_check_radius`).

    Parameters
    ----------
    images : (H, W, 3) float, (N, H, W, 3) float, or an iterable of (H, W, 3) float
        Linear radiance. A sequence is reduced to its per-pixel maximum (:func:`max_image`);
        a single image is used as given (pass the max image yourself to save memory).
    K : (3, 3) float
        Camera matrix.
    dist : (k,) float or None
        OpenCV distortion coefficients.
    sphere_radius : float
        Radius of the spheres, scene units.
    n_spheres : int
        How many spheres to find when no hints are given.
    hints : list of dict, optional
        One per sphere: ``{"center": [x, y, z]}`` (world), ``{"center_cam": [...]}`` or
        ``{"center_px": [u, v], "radius_px": r}``. Only edges near the hinted outline are used.
    overrides : list of dict, optional
        Sphere centres to use as they are (``{"center": ...}`` world or ``{"center_cam": ...}``);
        detection is skipped.
    world_from_camera : (4, 4) float, optional
        Defaults to :data:`ffls.conventions.DEFAULT_WORLD_FROM_CAMERA`.
    scene_center : (3,) float, optional
        World scene centre (default the origin); with the camera's position it gives the scene
        scale that catches a wrong ``sphere_radius``.
    source : path, optional
        Named in error messages (the capture folder or the images).
    max_residual_px, min_coverage : float
        Quality limits: RMS silhouette residual (pixels) and outline coverage (fraction).
    seed : int
        RANSAC seed.
    lit_limb : float or None
        After the spheres are chosen, each is refitted on the edge points whose limb (1.5 px
        inside) is at least this fraction of the sphere's 95th percentile in the max image, i.e.
        where the limb was directly lit (:func:`_refine_on_lit_limb`); None: no refinement.

    Returns
    -------
    list of SphereFit
        Sorted left to right by ``center_px`` x (hints and overrides keep their order).

    Raises
    ------
    InputError
        All-black images, no sphere or too few spheres, a sphere cut by the image border, a
        silhouette that does not fit a sphere, or a ``sphere_radius`` inconsistent with the scene.
    """
    K, dist = camera_arrays(K, dist)
    wfc = DEFAULT_WORLD_FROM_CAMERA if world_from_camera is None else np.asarray(world_from_camera, dtype=np.float64)
    R = float(sphere_radius)
    if not (np.isfinite(R) and R > 0):
        raise InputError(f"sphere_radius must be a positive number, got {sphere_radius!r}", source)
    if overrides:
        return _spheres_from_overrides(overrides, K, dist, wfc, R, source)
    f = float(np.sqrt(K[0, 0] * K[1, 1]))
    mx, L = _max_luminance(images, source)
    edges = _edge_map(mx, L, source)
    if hints:
        hint_info = [_parse_hint_or_fail(h, K, dist, wfc, R, source) for h in hints]
        cands = _hinted_candidates(hint_info, edges, L.shape, source)
        search_tol = 0.35
    else:
        hint_info = []
        cands = _hough_circle_candidates(edges, L, source)
        search_tol = 0.3
    fits, failures = _fit_candidates(cands, edges, K, dist, wfc, R, f, search_tol, "hint" if hints else "auto",
                                     np.random.default_rng(seed))
    if hints:
        _check_hinted_fits(fits, failures, max_residual_px, min_coverage, source)
    else:
        fits = _choose_spheres(fits, mx, L, n_spheres, max_residual_px, min_coverage, len(cands), source)
    if lit_limb is not None:  # the spheres are chosen; refine each on its directly lit outline
        fits = [_refine_on_lit_limb(ft, L, K, dist, R, f, wfc, lit_limb) for ft in fits]
    _check_inside_image(fits, K, dist, R, L.shape, source)
    _check_radius(fits, hint_info, wfc, R, source, scene_center)
    return fits


# ----------------------------------------------------------------------------- stages of find_spheres
def _spheres_from_overrides(overrides, K, dist, wfc, R, source) -> list[SphereFit]:
    """Overridden centres (``center_cam``, or a world ``center``) as they are; detection is skipped."""
    fits = []
    for o in overrides:
        if "center_cam" in o:
            C = np.asarray(o["center_cam"], dtype=np.float64)
        else:
            Cw = np.asarray(o.get("center", o.get("center_world")), dtype=np.float64)
            T = np.linalg.inv(wfc)
            C = T[:3, :3] @ Cw + T[:3, 3]
        if C[2] <= R or np.linalg.norm(C) <= R:
            raise InputError(f"sphere override {o} is not in front of the camera", source)
        fits.append(_make_fit(C, R, K, dist, wfc, "override"))
    return fits


def _max_luminance(images, source) -> tuple[np.ndarray, np.ndarray]:
    """Stage 1: the max image (:func:`max_image`) and its luminance; all-black sequences refused."""
    try:
        mx = max_image(images)
    except ValueError as e:
        raise InputError(str(e), source) from None
    L = _luminance(mx)
    peak = float(L.max()) if L.size else 0.0
    if not np.isfinite(peak) or peak <= 0 or float(np.percentile(L, 99.9)) <= 1e-6 * max(peak, 1e-30):
        raise InputError("all images are black (no light on the spheres in any photo)", source)
    return mx, L


@dataclasses.dataclass
class _EdgeMap:
    """Stage 2's output: subpixel edge points, their gradients, the log image and the edge distance map."""

    points: np.ndarray  # (n, 2) x, y
    grads: np.ndarray  # (n, 2) unit, toward brighter
    log8: np.ndarray  # (H, W) uint8, :func:`_log8`
    scale: float  # 8-bit levels per natural-log unit of radiance
    distance: np.ndarray  # (H, W) float32: distance to the nearest edge pixel


def _edge_map(mx, L, source) -> _EdgeMap:
    """Stage 2: edges of the max image (:func:`edge_points`) and the distance to them."""
    H, W = L.shape
    pts, grads = edge_points(mx)
    if len(pts) < 10:
        raise InputError("no edges in the images: no sphere visible", source)
    g8f, scale = _log8(L)
    edge_img = np.ones((H, W), np.uint8)
    edge_img[np.clip(np.rint(pts[:, 1]).astype(int), 0, H - 1), np.clip(np.rint(pts[:, 0]).astype(int), 0, W - 1)] = 0
    return _EdgeMap(points=pts, grads=grads, log8=g8f.astype(np.uint8), scale=scale,
                    distance=cv2.distanceTransform(edge_img, cv2.DIST_L2, 3))


def _parse_hint_or_fail(h, K, dist, wfc, R, source):
    try:
        return _parse_hint(h, K, dist, wfc, R)
    except (ValueError, TypeError) as e:
        raise InputError(f"bad sphere hint: {e}", source) from None


def _hinted_candidates(hint_info, edges: _EdgeMap, shape, source) -> list[tuple[float, float, float]]:
    """Stage 3 with hints: one circle (x, y, r) per hint; a radius the hint lacks comes from the edges."""
    H, W = shape
    cands = []
    for cpx, rpx, _ in hint_info:
        if rpx is None:  # centre only: the radius comes from the edges around it
            rpx = _radius_from_edges(edges.points, edges.grads, cpx, min(H, W) / 2)
            if rpx is None:
                raise InputError(f"no sphere found near the hinted centre ({cpx[0]:.0f}, {cpx[1]:.0f}) px", source)
        cands.append((float(cpx[0]), float(cpx[1]), float(rpx)))
    return cands


def _hough_circle_candidates(edges: _EdgeMap, L, source, max_candidates: int = 40) -> list[tuple[float, float, float]]:
    """Stage 3 without hints: Hough circles scored by edge support and brightness, near-duplicates dropped."""
    H, W = L.shape
    bg = float(np.median(L))
    hc = _hough_candidates(edges.log8, 3, min(H, W) / 2, edges.scale)
    scored = [(float(_score_circle(x, y, r, edges.distance, L, bg)), x, y, r) for x, y, r in hc]
    scored = [s for s in scored if s[0] >= 0.35]
    scored.sort(key=lambda s: -s[0])
    cands = []  # drop near-duplicates only; overlapping circles are resolved after fitting
    for sc, x, y, r in scored:
        if all(np.hypot(x - cx, y - cy) > 0.2 * r or abs(r - cr) > 0.2 * r for cx, cy, cr in cands):
            cands.append((x, y, r))
    cands = cands[:max_candidates]
    if not cands:
        raise InputError("no sphere found in the images (no round bright outline)", source)
    return cands


def _fit_candidates(cands, edges: _EdgeMap, K, dist, wfc, R, f, search_tol, label, rng):
    """Stage 4: per candidate circle, the tangent cone fitted to its silhouette edge points.

    Edge points within ``search_tol`` of the circle's radius, with a radial gradient of the
    majority polarity; RANSAC circle start; :func:`fit_sphere_center`. Returns the fits and the
    failures ``(k, x, y, r, why)``.
    """
    pts, grads = edges.points, edges.grads
    K_und = np.array([[f, 0, K[0, 2]], [0, f, K[1, 2]], [0, 0, 1]])  # undistorted, square pixels
    fits, failures = [], []
    for k, (cx, cy, r) in enumerate(cands):
        d = np.hypot(pts[:, 0] - cx, pts[:, 1] - cy)
        near = (d > (1 - search_tol) * r - 2) & (d < (1 + search_tol) * r + 2)
        radial = np.stack([pts[:, 0] - cx, pts[:, 1] - cy], axis=1) / np.maximum(d, 1e-9)[:, None]
        cosr = np.sum(radial * grads, axis=1)
        sel = near & (np.abs(cosr) > 0.7)
        if sel.sum() >= 3:  # majority polarity (bright sphere on dark ground: gradient inward)
            inward = sel & (cosr < 0)
            sel = inward if inward.sum() >= 0.5 * sel.sum() else sel & (cosr > 0)
        P = pts[sel]
        if len(P) < 8:
            failures.append((k, cx, cy, r, f"only {len(P)} edge points"))
            continue
        und = project_points(pixel_rays(P, K, dist), K_und, None)
        circ = _ransac_circle(und, r, rng)
        if circ is None:
            failures.append((k, cx, cy, r, "no circle through the edge points"))
            continue
        c0 = pixel_rays(circ[0][None], K_und)[0]
        edge_ray = pixel_rays((circ[0] + [circ[1], 0])[None], K_und)[0]
        a0 = float(angle_between(c0, edge_ray))
        s = pixel_rays(P, K, dist)
        try:
            C, inl, res = fit_sphere_center(s, R, f, c0, a0)
        except ValueError as e:
            failures.append((k, cx, cy, r, str(e)))
            continue
        rms = float(np.sqrt(np.mean(res[inl] ** 2)))
        fits.append(_make_fit(C, R, K, dist, wfc, label, edge_px=P[inl], residual=rms, n_edge=len(P),
                              n_in=int(inl.sum()), coverage=_coverage(P[inl], project_points(C[None], K, dist)[0])))
    return fits, failures


def _choose_spheres(fits, mx, L, n_spheres, max_residual_px, min_coverage, n_cands, source) -> list[SphereFit]:
    """Stage 5 without hints: the ``n_spheres`` best non-overlapping fits, left to right.

    White diffuse spheres are the brightest, most neutral and most exactly round things in the
    max image, and nothing hides their outline: fits within the quality limits are ranked by
    outline support x coverage x brightness x neutrality x fit quality.
    """
    H, W = L.shape
    good = [ft for ft in fits if ft.residual_px <= max_residual_px and ft.coverage >= min_coverage]
    yy, xx = np.mgrid[0:H, 0:W]
    rgb = mx if mx.ndim == 3 and mx.shape[2] >= 3 else None
    bright, neutral = [], []
    for ft in good:
        inside = (xx - ft.center_px[0]) ** 2 + (yy - ft.center_px[1]) ** 2 <= (0.7 * ft.radius_px) ** 2
        bright.append(float(np.median(L[inside])) if inside.any() else 0.0)
        if rgb is not None and inside.any():
            med = np.median(rgb[inside][:, :3], axis=0)
            neutral.append(float(np.clip(med.min() / max(med.max(), 1e-12), 0, 1)))
        else:
            neutral.append(1.0)
    top = max(bright, default=1.0) or 1.0
    # support: inlier edge points per pixel of outline (about 1 for a fully visible outline),
    # so that a large, partly hidden round object does not outrank a small whole sphere
    score = [min(ft.n_inliers / (2 * np.pi * ft.radius_px), 1.2) * ft.coverage * (b / top)
             * (0.25 + 0.75 * nt) / (1 + (ft.residual_px / 0.5) ** 2)
             for ft, b, nt in zip(good, bright, neutral)]
    order = np.argsort([-v for v in score], kind="stable")
    chosen = []
    for i in order:
        ft = good[i]
        if all(np.hypot(*(ft.center_px - o.center_px)) > 0.8 * (ft.radius_px + o.radius_px) for o in chosen):
            chosen.append(ft)
    chosen = chosen[:n_spheres]
    if len(chosen) < n_spheres:
        raise InputError(f"found {len(chosen)} of {n_spheres} spheres in the images ({n_cands} candidate circles)",
                         source)
    return sorted(chosen, key=lambda ft: ft.center_px[0])


def _check_hinted_fits(fits, failures, max_residual_px, min_coverage, source) -> None:
    """Stage 5 with hints: every hinted sphere must have fitted within the quality limits."""
    if failures:
        k, cx, cy, r, why = failures[0]
        raise InputError(f"sphere {k} near pixel ({cx:.0f}, {cy:.0f}): cannot fit its outline ({why})", source)
    for k, ft in enumerate(fits):
        if ft.residual_px > max_residual_px or ft.coverage < min_coverage:
            raise InputError(f"sphere {k} near pixel ({ft.center_px[0]:.0f}, {ft.center_px[1]:.0f}): outline does"
                             f" not fit a sphere (rms {ft.residual_px:.2f} px, coverage {ft.coverage:.0%})", source)


def _check_inside_image(fits, K, dist, R, shape, source) -> None:
    """Every sphere's projected outline must lie inside the image."""
    H, W = shape
    for k, ft in enumerate(fits):
        outline = silhouette_px(K, dist, ft.center_cam, R)
        if (outline[:, 0].min() < 0.5 or outline[:, 1].min() < 0.5
                or outline[:, 0].max() > W - 1.5 or outline[:, 1].max() > H - 1.5):
            raise InputError(f"sphere {k} at pixel ({ft.center_px[0]:.0f}, {ft.center_px[1]:.0f}), radius"
                             f" {ft.radius_px:.0f} px, is cut by the image border", source)


def _check_radius(fits, hint_info, wfc, R, source, scene_center=None):
    """Catch a ``sphere_radius`` inconsistent with the scene scale (depth ratio outside 1/2..2)."""
    msg = "sphere_radius in capture.json looks wrong"
    for k, ft in enumerate(fits):
        if k < len(hint_info) and hint_info[k][2] is not None:
            ratio = ft.distance / float(np.linalg.norm(hint_info[k][2]))
            if not 0.5 <= ratio <= 2.0:
                raise InputError(f"{msg}: sphere {k} fits at {ft.distance:.3g} from the camera but its hinted"
                                 f" centre is at {np.linalg.norm(hint_info[k][2]):.3g} (radius {R:g})", source)
    centre = np.zeros(3) if scene_center is None else np.asarray(scene_center, dtype=np.float64).reshape(3)
    cam_dist = float(np.linalg.norm(wfc[:3, 3] - centre))  # camera to scene centre
    if cam_dist > 0 and fits:
        ratio = np.median([ft.distance for ft in fits]) / cam_dist
        if not 0.25 <= ratio <= 4.0:
            raise InputError(f"{msg}: spheres fit at {np.median([ft.distance for ft in fits]):.3g} from the camera"
                             f" but the scene centre is at {cam_dist:.3g} (radius {R:g})", source)


def find_spheres_in_capture(capture, n_spheres: int = 4, overrides=None, progress=None) -> list[SphereFit]:
    """:func:`find_spheres` on a loaded :class:`ffls.io.capture.Capture`, using its whole sequence.

    Uses ``capture.K``, ``.dist``, ``.sphere_radius``, ``.spheres`` (hints),
    ``.world_from_camera``, ``.scene_center`` and the max over ``load_photo(capture, i)`` for all
    photos (streamed: one image in memory at a time). ``progress`` is an optional wrapper such as
    ``tqdm.tqdm`` (called as ``progress(iterable, total=n)``).
    """
    n = len(capture.image_paths)
    it = (load_photo(capture, i) for i in range(n))
    if progress is not None:
        it = progress(it, total=n)
    hints = getattr(capture, "spheres", None) or None
    return find_spheres(max_image(it), capture.K, capture.dist, capture.sphere_radius,
                        n_spheres=len(hints) if hints else n_spheres, hints=hints, overrides=overrides,
                        world_from_camera=capture.world_from_camera,
                        scene_center=getattr(capture, "scene_center", None), source=capture.folder)
