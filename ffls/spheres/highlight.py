"""Light direction from the specular highlight on a mirror or glossy sphere.

A chrome ball or a black glossy ball (the calibration target of Reflectance Transformation
Imaging) reflects each light as a small bright blob. The light's direction is the viewing ray
through the blob's centre reflected about the sphere's normal there:

* the RTI highlight method (Mudge, Malzbender, Schroer, Lum, "New Reflection Transformation
  Imaging Methods for Rock Art and Multiple-Viewpoint Display", VAST 2006, section 3): per photo,
  the highlight's centre on a black reflective sphere of known outline gives the light's
  direction (:func:`highlight_direction_Mudge2006`);
* the mirror ball as a light probe (Debevec, "Rendering Synthetic Objects into Real Scenes",
  SIGGRAPH 1998, section 4): every pixel of a mirror ball maps to the world direction it
  reflects, ``l = 2 (n . v) n - v``; the light is the radiance-weighted mean of the directions
  of its blob, each pixel weighted by the solid angle of directions it covers
  (:func:`highlight_centre_Debevec1998`).

Exact geometry: the viewing ray of a pixel (:func:`ffls.camera.projection.camera_rays`: pinhole
with ``K`` and OpenCV distortion, or orthographic) meets the sphere (centre from detection, known
radius) at ``P`` with normal ``n``; the light direction is the reflection of the direction to the
camera ``v`` about ``n``. A near light lies on the ray ``P + t l``
(:func:`ffls.spheres.combine.fit_ray_convergence` meets several such rays).

Saturation: where the highlight's core is clipped its pixels keep the clip value; the blob's
weighted mean is taken in *direction* space, where the reflected image of a symmetric source is
symmetric, so a flat clipped core and its unclipped shoulder give an unbiased centre (a plain
pixel centroid is pulled toward the sphere's centre, where the mirror ball magnifies least).
Where enough pixels are clipped, a soft-edged disc light is fitted to the blob with the clipped
pixels as censored observations (Tobin 1958, :func:`highlight_centre_Tobin1958`): the clipped
blob's outline and its unclipped shoulder locate it.

Uncertainty (RMS angular, the unit of :attr:`ffls.spheres.lambert.LambertFit.uncertainty_deg`):
the centre's pixel uncertainty (background noise and clutter under the blob, the clipped core's
unknown profile, the sphere centre's own uncertainty, a discretisation floor) is mapped through
the numerical Jacobian of the pixel-to-direction map, and a floor ``floor_deg`` is added in
quadrature for what the model leaves out (a ball that is not quite round, its radius).

Kind of a sphere (:func:`classify_sphere`): the fraction of the disc above half of the
brightest signal, per photo (:func:`highlight_compactness`); its median over the photos is
small for a mirror or glossy ball (a compact blob) and large for a matte one (a broad lit cap).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from ffls.camera.projection import camera_rays
from ffls.conventions import CAMERA_MODELS, angle_between, normalize, tangent_basis
from ffls.io.capture import SPHERE_MATERIALS
from ffls.spheres.mirror_outline import LIMB_BAND_PX, LIMB_DARK_BODY_RATIO, LimbFit, dark_body, fit_limb_profile

__all__ = [
    "MATERIALS",
    "HIGHLIGHT_STATUSES",
    "CONE95_PER_RMS",
    "SphereView",
    "HighlightSpot",
    "HighlightFit",
    "SphereKind",
    "find_highlight",
    "highlight_centre_Debevec1998",
    "highlight_centre_Tobin1958",
    "CLIP_SIGMA_PX",
    "CENSORED_SIGMA_PX",
    "MIN_CENSORED_PX",
    "PIXEL_FLOOR_PX",
    "MIRROR_COMPACTNESS",
    "highlight_direction",
    "highlight_direction_Mudge2006",
    "fit_highlight",
    "fit_highlight_samples",
    "sample_patch",
    "highlight_compactness",
    "classify_sphere",
    "saturated_pixels",
    "LIMB_CLEAR_SNR",
    "LIMB_DARK_BODY_RATIO",
    "LIMB_MODEL_FLOOR_PX",
    "refine_view_limb",
    "limb_view",
    "highlights_outside",
    "outline_holding_highlights",
    "apparent_radius_px",
]

#: Sphere materials of ``capture.json`` (``'auto'``: classified from the photos).
MATERIALS = SPHERE_MATERIALS
#: Statuses of a highlight fit other than ``'ok'``, with their meaning.
HIGHLIGHT_STATUSES = {
    "no_highlight": "no compact highlight on the mirror sphere (light behind it, or off)",
    "saturated": "the highlight is clipped with no unclipped shoulder (exposure too high)",
    "highlight_at_rim": "the highlight touches the sphere's rim (light nearly behind the sphere)",
    "fit_failed": "the highlight's centre does not map to a finite direction",
}
#: Radius of the 95% cone of a 2-D isotropic normal error, per unit of its RMS angle:
#: ``sqrt(chi2_2(0.95) / 2)``.
CONE95_PER_RMS = float(np.sqrt(-2.0 * np.log(0.05) / 2.0))
#: Per-axis floor of a highlight centre's pixel uncertainty (sampling, demosaicing).
PIXEL_FLOOR_PX = 0.05
#: Per-axis uncertainty (pixels) of a clipped highlight's centre from the centroid (the profile
#: under the clip is lost) and from the censored fit. Measured on the renders of
#: ``tests/test_highlight.py`` (symmetric disc lights; docs/spheres.md): per-axis RMS 0.15 px for
#: cores of 2-4 clipped pixels (centroid), 0.05 px for larger ones (censored fit).
CLIP_SIGMA_PX = 0.15
CENSORED_SIGMA_PX = 0.05
#: Fewest clipped pixels for the censored fit (:func:`highlight_centre_Tobin1958`): a smaller
#: blob has fewer informative pixels than the fit's five parameters.
MIN_CENSORED_PX = 8
#: A highlight whose centre or core lies within ``RIM_SIGMAS`` standard deviations of its and the
#: outline's position plus half a pixel, or within :data:`RIM_MIN_PX`, of the sphere's outline is
#: at the rim (:func:`_rim_status`). 1.5 px: the old test's reach (signal within 1.5 px of the
#: disc's edge), now applied to the core and centre; at 0.5 px, renders of ``tests/test_highlight.py`` (a 60 px
#: ball, lights 6-10 deg wide at 153-162 deg from the view) were accepted 9-12 deg off with 95%
#: cones of 8.5 deg (the limb and the edge pixels' anti-aliasing cut the light's image).
RIM_SIGMAS = 1.0
RIM_MIN_PX = 2.0
#: The fraction of the disc above half the brightest signal below which a sphere is a mirror.
MIRROR_COMPACTNESS = 0.03


@dataclass(frozen=True)
class SphereView:
    """A sphere as the camera sees it: what maps a pixel on its disc to a reflected direction.

    Attributes
    ----------
    center_px : (2,) float
        The sphere centre's image (pixels, x right, y down).
    radius_px : float
        Apparent radius (pixels).
    model : {'pinhole', 'orthographic'}
    K : (3, 3) float or None
        Pinhole intrinsics (required for ``'pinhole'``).
    dist : (k,) float or None
        OpenCV distortion coefficients.
    center_cam : (3,) float or None
        Sphere centre in the camera frame (required for ``'pinhole'``; for ``'orthographic'``
        only to place the reflection point of a near light).
    radius : float or None
        Sphere radius in scene units (required for ``'pinhole'``).
    world_from_camera : (4, 4) float or None
        Identity when None.
    center_sigma_px : float
        Per-axis standard deviation of ``center_px`` (from the detection's silhouette fit).
    radius_sigma_px : float
        Standard deviation of the apparent radius (pixels; pinhole: of ``f tan(alpha)``, ``alpha``
        the tangent cone's half-angle, which sets the sphere's depth). A radius error tilts every
        direction toward or away from the camera, the more toward the rim
        (:meth:`outline_jacobian`).
    """

    center_px: np.ndarray
    radius_px: float
    model: str = "pinhole"
    K: np.ndarray | None = None
    dist: np.ndarray | None = None
    center_cam: np.ndarray | None = None
    radius: float | None = None
    world_from_camera: np.ndarray | None = None
    center_sigma_px: float = 0.1
    radius_sigma_px: float = 0.0

    def __post_init__(self):
        if self.model not in CAMERA_MODELS:
            raise ValueError(f"camera model must be one of {CAMERA_MODELS}, not {self.model!r}")
        if self.model == "pinhole" and (self.K is None or self.center_cam is None or self.radius is None):
            raise ValueError("a pinhole SphereView needs K, center_cam and radius")

    @classmethod
    def from_sphere(cls, sphere, model: str = "pinhole", K=None, dist=None, world_from_camera=None) -> "SphereView":
        """The view of a detected sphere (:class:`ffls.spheres.detect.SphereFit` or any object with
        ``center_px``, ``radius_px``, ``center_cam``, ``radius`` and optionally ``residual_px``,
        ``n_inliers``, ``outline_sigma_px``, ``outline_centre_sigma_px``); its centre's uncertainty
        is ``outline_centre_sigma_px`` where given (> 0: measured with the misfit included), else
        the silhouette's RMS residual (a mirror's outline points are edges of its reflections, whose
        misfit is shared, not independent), with its outline ambiguity (``outline_sigma_px``) in
        quadrature. Its radius's uncertainty is left at 0: the limb's step sets it
        (:func:`refine_view_limb`)."""
        res = float(getattr(sphere, "residual_px", 0.0) or 0.0)
        n = int(getattr(sphere, "n_inliers", 0) or 0)
        # a mirror's outline is its reflections' edges: their misfit moves the centre as a whole (not
        # independent per point), so the full residual, and the outline ambiguity, in quadrature
        own = float(getattr(sphere, "outline_centre_sigma_px", 0.0) or 0.0)
        sig = own or float(np.hypot(res if n > 0 else 0.1, float(getattr(sphere, "outline_sigma_px", 0.0) or 0.0)))
        cc = getattr(sphere, "center_cam", None)
        return cls(center_px=np.asarray(sphere.center_px, dtype=np.float64), radius_px=float(sphere.radius_px),
                   model=model, K=None if K is None else np.asarray(K, dtype=np.float64),
                   dist=None if dist is None else np.asarray(dist, dtype=np.float64),
                   center_cam=None if cc is None else np.asarray(cc, dtype=np.float64),
                   radius=None if getattr(sphere, "radius", None) is None else float(sphere.radius),
                   world_from_camera=world_from_camera, center_sigma_px=float(max(sig, 0.02)))

    def with_outline(self, shift_px=(0.0, 0.0), radius_change_px: float = 0.0) -> "SphereView":
        """The same sphere with its outline moved: its centre's image by ``shift_px`` (x, y) and its
        apparent radius by ``radius_change_px``.

        Orthographic: the circle. Pinhole: the centre ``C`` moves to the ray through the shifted
        image of the centre (:func:`ffls.camera.projection.camera_rays`, with distortion), at the
        depth where the tangent cone's ``f tan(alpha)`` (``f`` the mean focal length) changed by
        ``radius_change_px``: ``|C| = radius / sin(alpha)``.
        """
        d = np.asarray(shift_px, dtype=np.float64).reshape(2)
        c = np.asarray(self.center_px, dtype=np.float64) + d
        if self.model == "orthographic":
            cc = None if self.center_cam is None else np.asarray(self.center_cam, dtype=np.float64)
            return replace(self, center_px=c, radius_px=float(self.radius_px) + float(radius_change_px), center_cam=cc)
        K = np.asarray(self.K, dtype=np.float64)
        f = 0.5 * (K[0, 0] + K[1, 1])
        C = np.asarray(self.center_cam, dtype=np.float64)
        alpha = float(np.arcsin(min(float(self.radius) / float(np.linalg.norm(C)), 1.0)))
        alpha = float(np.arctan((f * np.tan(alpha) + float(radius_change_px)) / f))
        u = camera_rays(c.reshape(1, 2), "pinhole", K, self.dist)[0]
        return replace(self, center_px=c, center_cam=float(self.radius) / np.sin(alpha) * normalize(u))

    def outline_jacobian(self, pixel, h: float = 0.1) -> np.ndarray:
        """``d l / d (c_x, c_y, r)`` (3, 3): how the reflected direction of image point ``pixel``
        moves with the outline (its centre's image and its apparent radius, :meth:`with_outline`),
        by central differences of ``h`` pixels; NaN where a moved outline misses ``pixel``."""
        p = np.asarray(pixel, dtype=np.float64).reshape(1, 2)
        cols = []
        for e in np.eye(3) * h:
            lp = self.with_outline(e[:2], e[2]).reflect(p)[0][0]
            lm = self.with_outline(-e[:2], -e[2]).reflect(p)[0][0]
            cols.append((lp - lm) / (2 * h))
        return np.stack(cols, axis=1)

    def _rotation(self) -> tuple[np.ndarray, np.ndarray]:
        if self.world_from_camera is None:
            return np.eye(3), np.zeros(3)
        M = np.asarray(self.world_from_camera, dtype=np.float64)
        return M[:3, :3], M[:3, 3]

    def reflect(self, pixels) -> tuple[np.ndarray, np.ndarray]:
        """Reflected directions and surface points (world frame) of image points on the sphere.

        Parameters
        ----------
        pixels : (n, 2) float

        Returns
        -------
        directions : (n, 3) float, unit; NaN where the pixel's ray misses the sphere.
        points : (n, 3) float
            The reflection points ``P`` (world; NaN where missed or, for an orthographic view
            without ``center_cam``, unknown).
        """
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        d = camera_rays(p, self.model, self.K, self.dist)
        if self.model == "orthographic":
            q = (p - np.asarray(self.center_px, dtype=np.float64)) / float(self.radius_px)
            s = 1.0 - np.einsum("ij,ij->i", q, q)
            n = np.concatenate([q, -np.sqrt(np.where(s >= 0, s, np.nan))[:, None]], axis=1)
            P = (np.full_like(n, np.nan) if self.center_cam is None or self.radius is None
                 else np.asarray(self.center_cam) + float(self.radius) * n)
        else:
            C = np.asarray(self.center_cam, dtype=np.float64)
            R = float(self.radius)
            dc = d @ C
            disc = dc * dc - C @ C + R * R
            t = dc - np.sqrt(np.where(disc >= 0, disc, np.nan))
            P = d * t[:, None]
            n = (P - C) / R
        v = -d
        L = 2.0 * np.einsum("ij,ij->i", n, v)[:, None] * n - v
        Rw, tw = self._rotation()
        return L @ Rw.T, P @ Rw.T + tw


@dataclass
class HighlightSpot:
    """A highlight found in a sphere's disc (:func:`find_highlight`).

    Attributes
    ----------
    found : bool
    status : str
        ``'ok'`` or a :data:`HIGHLIGHT_STATUSES` key.
    peak : float
        Brightest signal above the local background.
    background, noise : float
        Local background level and its robust spread (noise and clutter), grey units.
    rows, cols : (m,) int
        The blob's pixels (core and shoulder) in the patch.
    weights : (m,) float
        Their signal above the background plane (noise may make a few negative).
    n_core, n_saturated : int
        Pixels of the core (above half the peak) and of them clipped.
    core_radius_px : float
        Equivalent radius of the core.
    rim_px : float
        Smallest distance from a blob pixel carrying signal to the edge of the disc.
    background_at : (m,) float
        The background plane at the blob's pixels (``values - weights``).
    clipped : (m,) bool
        The blob's clipped pixels.
    clip_level : float
        Median value of the clipped pixels (NaN when none).
    shoulder : bool
        False where a clipped core has no unclipped pixel above a tenth of the peak around it:
        its outline is then known to a pixel only.
    """

    found: bool
    status: str
    peak: float = 0.0
    background: float = 0.0
    noise: float = 0.0
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    cols: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n_core: int = 0
    n_saturated: int = 0
    core_radius_px: float = 0.0
    rim_px: float = float("inf")
    background_at: np.ndarray = field(default_factory=lambda: np.zeros(0))
    clipped: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    clip_level: float = float("nan")
    shoulder: bool = True


def saturated_pixels(grey: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """The clipped pixels of a sphere from its :class:`ffls.spheres.samples.SphereValues`.

    ``valid`` excludes clipped and near-black pixels alike; the clipped ones are the excluded
    finite pixels in the upper half of the sphere's range.

    Parameters
    ----------
    grey : (m,) float
    valid : (m,) bool

    Returns
    -------
    (m,) bool
    """
    g = np.asarray(grey, dtype=np.float64)
    fin = np.isfinite(g)
    if not fin.any():
        return np.zeros(g.shape, dtype=bool)
    top = float(g[fin].max())
    return ~np.asarray(valid, dtype=bool) & fin & (g >= 0.5 * top) & (top > 0)


def _background_plane(img, ring, at, med, spread, robust_start=True):
    """A plane ``b0 + bx (x - x0) + by (y - y0)`` fitted to the ring around the blob (one round of
    3-sigma rejection) and the residuals' robust spread: the ball's reflection of the room varies
    across the blob, and a constant level would tilt the centroid toward the brighter side.
    ``robust_start=False`` starts from every ring pixel instead of the median's neighbours: its
    spread then includes a step crossing the ring (the clutter a highlight must stand above)."""
    rr, cc = np.nonzero(ring)
    if rr.size < 8:
        return np.array([med, 0.0, 0.0]), spread
    v = img[rr, cc]
    A = np.stack([np.ones(rr.size), cc - at[1], rr - at[0]], axis=1).astype(np.float64)
    # a high-breakdown start: the ring's median level and spread. A least-squares plane through
    # every ring pixel is tilted by a step in the reflection (a mirror ball's reflected horizon or
    # table edge crossing the ring), and the highlight's centroid, weighted by the signal above that
    # plane, is pulled toward where the plane dips below the true level (up to 2.5 px on a
    # one-pixel highlight). The pixels on the majority's side of the step are the background at
    # the highlight's level; a smooth gradient keeps every ring pixel (3 MADs reach its ends).
    dev = np.abs(v - np.median(v))
    keep = dev <= 3.0 * max(1.4826 * float(np.median(dev)), spread, 1e-12)
    if keep.sum() < 8 or not robust_start:
        keep = np.ones(rr.size, dtype=bool)
    for _ in range(2):
        coef = np.linalg.lstsq(A[keep], v[keep], rcond=None)[0]
        res = v - A @ coef
        sig = float(1.4826 * np.median(np.abs(res[keep] - np.median(res[keep]))))
        keep = np.abs(res) <= 3.0 * max(sig, 1e-12) + 1e-300
        if keep.sum() < 8:
            keep = np.ones(rr.size, dtype=bool)
    return coef, max(sig, spread)


def find_highlight(image: np.ndarray, disc: np.ndarray, saturated: np.ndarray | None = None, *,
                   min_snr: float = 8.0, max_core_fraction: float = 0.06) -> HighlightSpot:
    """The brightest compact blob of a sphere's disc: core, unclipped shoulder, local background.

    1. The peak is the maximum of the disc after a 3x3 mean over disc pixels (a hot pixel is not
       a highlight); where pixels are clipped, the largest clipped component is the core.
    2. The core is the connected component around the peak above half of the peak's signal over
       the disc's median.
    3. The local background is a plane fitted to a ring of disc pixels around the core, its
       spread the residuals' MAD (at least the pixel noise); the blob is the core dilated by its
       shoulder (3 px plus half the core's radius), weighted by the signal above that plane.
    4. ``'saturated'``: a clipped core larger than ``max_core_fraction`` of the disc (gross
       over-exposure); ``'highlight_at_rim'``: signal within 1.5 px of the disc's edge.

    Parameters
    ----------
    image : (h, w) float
        Grey linear values of a patch holding the disc.
    disc : (h, w) bool
        The sphere's usable pixels.
    saturated : (h, w) bool, optional
        Clipped pixels (their value is the clip level).
    min_snr : float
        A peak less than ``min_snr`` times the disc's spread above the background is no highlight.
    max_core_fraction : float
        A clipped core larger than this fraction of the disc has no usable shoulder
        (``'saturated'``).

    Returns
    -------
    HighlightSpot
    """
    from scipy import ndimage  # imported here: only mirror spheres need it (the import is slow)

    img = np.asarray(image, dtype=np.float64)
    disc = np.asarray(disc, dtype=bool) & np.isfinite(img)
    sat = np.zeros_like(disc) if saturated is None else (np.asarray(saturated, dtype=bool) & disc)
    if disc.sum() < 20:
        return HighlightSpot(False, "no_highlight")
    vals = img[disc]
    med = float(np.median(vals))
    # pixel-to-pixel noise: horizontal differences inside the disc (the ball's smooth reflections cancel)
    pairs = disc[:, 1:] & disc[:, :-1]
    diffs = (img[:, 1:] - img[:, :-1])[pairs]
    spread = float(1.4826 * np.median(np.abs(diffs - np.median(diffs))) / np.sqrt(2.0)) if diffs.size else 0.0
    z = np.where(disc, img, 0.0).astype(np.float32)
    num = cv2.blur(z, (3, 3), borderType=cv2.BORDER_CONSTANT)
    den = cv2.blur(disc.astype(np.float32), (3, 3), borderType=cv2.BORDER_CONSTANT)
    smooth = np.where(disc, num / np.maximum(den, 1e-6), -np.inf)
    if sat.any():
        lab, nlab = ndimage.label(sat)
        sizes = ndimage.sum_labels(np.ones_like(img), lab, index=np.arange(1, nlab + 1))
        big = lab == (1 + int(np.argmax(sizes)))
        if float(sizes.max()) >= max_core_fraction * disc.sum():  # gross over-exposure
            return HighlightSpot(False, "saturated", background=med, noise=spread, n_core=int(sizes.max()),
                                 n_saturated=int(sizes.max()))
        r0, c0 = np.argwhere(big)[0]
    else:  # the blurred maximum finds the blob (not a hot pixel); its brightest raw pixel is the peak
        r0, c0 = np.unravel_index(int(np.argmax(smooth)), img.shape)
        win = np.where(disc, img, -np.inf)[max(r0 - 1, 0):r0 + 2, max(c0 - 1, 0):c0 + 2]
        dr, dc = np.unravel_index(int(np.argmax(win)), win.shape)
        r0, c0 = max(r0 - 1, 0) + dr, max(c0 - 1, 0) + dc
    peak_val = float(img[r0, c0])
    signal = peak_val - med
    # a highlight stands above the noise, and a compact 3x3 blob above the disc's own variation
    if not (signal > max(min_snr * spread, 1e-12 * max(abs(peak_val), 1e-30))
            and float(smooth[r0, c0]) - med > 3.0 * spread):
        return HighlightSpot(False, "no_highlight", peak=max(signal, 0.0), background=med, noise=spread)
    lab, _ = ndimage.label(disc & ((img >= med + 0.5 * signal) | sat))
    core = lab == lab[r0, c0]
    n_core = int(core.sum())
    r_core = float(np.sqrt(n_core / np.pi))
    dist_core = ndimage.distance_transform_edt(~core)
    ring = disc & (dist_core > r_core + 3.0) & (dist_core <= 2.0 * r_core + 8.0)
    if ring.sum() < 8:
        ring = disc & ~core
    # the background under the blob: the plane of the ring's majority (a reflected step crossing
    # the ring does not tilt it); whether the peak is a highlight at all: against the plane through
    # the whole ring and its spread, the clutter of reflections around it (a renderer's or sensor's
    # one-pixel glint on a reflected edge is no light)
    b_plane, _ = _background_plane(img, ring, (r0, c0), med, spread)
    clutter_plane, noise = _background_plane(img, ring, (r0, c0), med, spread, robust_start=False)
    shoulder = 3.0 + 0.5 * r_core
    blob = disc & (dist_core <= shoulder)
    rr, cc = np.nonzero(blob)
    back = b_plane[0] + b_plane[1] * (cc - c0) + b_plane[2] * (rr - r0)
    w = img[rr, cc] - back  # not clamped: the noise of the shoulder averages out
    b = float(b_plane[0])
    if not peak_val - float(clutter_plane[0]) > min_snr * max(noise, spread):  # not above the reflections around it
        return HighlightSpot(False, "no_highlight", peak=max(peak_val - b, 0.0), background=b, noise=noise)
    n_sat = int((sat & core).sum())
    # distance of the signal-carrying blob pixels to the disc's edge (outside the disc = 0)
    edge = ndimage.distance_transform_edt(np.pad(disc, 1))[1:-1, 1:-1]
    carrying = w > 0.1 * (peak_val - b)
    rim = float(edge[rr[carrying], cc[carrying]].min()) if carrying.any() else float("inf")
    spot = HighlightSpot(True, "ok", peak=float(peak_val - b), background=b, noise=noise, rows=rr, cols=cc, weights=w,
                         n_core=n_core, n_saturated=n_sat, core_radius_px=r_core, rim_px=rim, background_at=back,
                         clipped=sat[rr, cc], clip_level=float(np.median(img[sat])) if sat.any() else float("nan"))
    if n_sat > 0 and n_sat >= max_core_fraction * disc.sum():
        spot.status = "saturated"
    elif rim <= 1.5:
        spot.status = "highlight_at_rim"
    spot.shoulder = not (n_sat > 0 and not np.any(blob & ~sat & (img > b + 0.1 * (peak_val - b))))
    return spot


def highlight_centre_Debevec1998(view: SphereView, spot: HighlightSpot, origin_px=(0.0, 0.0)):
    """The blob's radiance-weighted mean reflected direction, and its pixel centre.

    Debevec 1998, section 4: a mirror ball's pixel ``p`` sees the world direction
    ``l(p) = 2 (n . v) n - v``. The light's direction is ``sum w_p Omega_p l(p)`` normalised,
    with ``w_p`` the signal above the background and ``Omega_p = |dl/dx x dl/dy|`` the solid angle
    of directions the pixel covers: the centroid of the source in the light probe, invariant to
    the ball's magnification (which grows toward the rim) and so unbiased for a clipped core.

    Parameters
    ----------
    view : SphereView
    spot : HighlightSpot
        From :func:`find_highlight` on a patch whose pixel (0, 0) is image pixel ``origin_px``.
    origin_px : (2,) float
        Image coordinates (x, y) of the patch's pixel (0, 0).

    Returns
    -------
    direction : (3,) float, unit (NaN when no blob pixel maps onto the sphere)
    pixel : (2,) float
        The weighted centre in image pixels (x, y).
    """
    px = np.stack([spot.cols + float(origin_px[0]), spot.rows + float(origin_px[1])], axis=1).astype(np.float64)
    h = 0.5
    L, _ = view.reflect(px)
    Lx, _ = view.reflect(px + [h, 0.0])
    Ly, _ = view.reflect(px + [0.0, h])
    omega = np.linalg.norm(np.cross((Lx - L) / h, (Ly - L) / h), axis=1)
    w = spot.weights * omega
    ok = np.all(np.isfinite(L), axis=1) & np.isfinite(w)
    if ok.any() and not np.sum(w[ok]) > 0:
        # the signal above the background plane sums to nothing (a small highlight on a bright
        # reflection, the plane above its shoulder): the source's radiance is never negative, its
        # centroid is that of the positive signal (the core above the plane)
        w = np.clip(spot.weights, 0.0, None) * omega
    if not ok.any() or not np.sum(w[ok]) > 0:
        return np.full(3, np.nan), np.full(2, np.nan)
    d = normalize(np.sum(w[ok, None] * L[ok], axis=0))
    pixel = np.sum(w[ok, None] * px[ok], axis=0) / w[ok].sum()
    return d, pixel


def highlight_centre_Tobin1958(view: SphereView, spot: HighlightSpot, start: np.ndarray, origin_px=(0.0, 0.0),
                               sub: int = 8) -> np.ndarray:
    """A clipped highlight's direction from a censored fit of a soft-edged disc light.

    Tobin, "Estimation of Relationships for Limited Dependent Variables", Econometrica 1958: a
    clipped pixel says only that its value is at least the clip level. The light is a disc of
    angular radius ``alpha`` and radiance ``A`` around ``l``, its edge softened by ``s`` (blur,
    the source's own fall-off); each blob pixel's value is the background plane plus ``A`` times
    the mean over ``sub x sub`` points of the pixel of ``Phi((alpha - angle(l(p), l)) / s)``
    (``l(p)`` the reflected direction, :meth:`SphereView.reflect`). Unclipped pixels give the
    residual ``(model - value) / noise``, clipped ones ``max(clip - model, 0) / noise``. The
    flat core fixes nothing but the edge: ``l`` comes from the clipped blob's outline and its
    unclipped shoulder, through the sphere's exact geometry.

    Parameters
    ----------
    view : SphereView
    spot : HighlightSpot
        With clipped pixels (``spot.clipped``, ``spot.clip_level``).
    start : (3,) float, unit
        Initial direction (:func:`highlight_centre_Debevec1998`).
    origin_px : (2,) float
    sub : int
        Sub-pixel samples per axis.

    Returns
    -------
    (3,) float, unit
        The light's direction (NaN when the fit fails). Its uncertainty is not taken from the
        fit's covariance: the disc's radius, radiance and edge are confounded when only the edge
        is seen (see :data:`CENSORED_SIGMA_PX`).
    """
    from scipy.optimize import least_squares
    from scipy.special import ndtr

    px = np.stack([spot.cols + float(origin_px[0]), spot.rows + float(origin_px[1])], axis=1).astype(np.float64)
    o = (np.arange(sub) + 0.5) / sub - 0.5
    offs = np.stack(np.meshgrid(o, o), -1).reshape(-1, 2)
    D, _ = view.reflect((px[:, None, :] + offs[None]).reshape(-1, 2))
    D = D.reshape(len(px), len(offs), 3)
    inside = np.all(np.isfinite(D), axis=2)
    D = np.where(inside[..., None], D, 0.0)
    y = spot.background_at + spot.weights
    clip = float(spot.clip_level)
    noise = max(float(spot.noise), 1e-3 * clip)
    start = normalize(np.asarray(start, dtype=np.float64))
    e1, e2 = tangent_basis(start)
    # start: the core's solid angle gives alpha, a pixel's angular size the edge
    omega_px = float(np.median(np.linalg.norm(np.cross(D[:, 1] - D[:, 0], D[:, sub] - D[:, 0]), axis=1))) * sub * sub
    alpha0 = max(float(np.sqrt(max(spot.n_core, 1) * omega_px / np.pi)), 1e-4)
    s0 = max(0.5 * float(np.sqrt(omega_px)), 1e-5)
    x0 = np.array([0.0, 0.0, np.log(alpha0), np.log(2.0 * max(clip - float(np.median(spot.background_at)), 1e-12)),
                   np.log(s0)])

    def direction(x):
        return normalize(start + x[0] * e1 + x[1] * e2)

    def model(x):
        ang = np.arccos(np.clip(D @ direction(x), -1.0, 1.0))
        cover = np.where(inside, ndtr((np.exp(x[2]) - ang) / np.exp(x[4])), 0.0).mean(axis=1)
        return spot.background_at + np.exp(x[3]) * cover

    def residuals(x):
        m = model(x)
        return np.where(spot.clipped, np.maximum(clip - m, 0.0), m - y) / noise

    # the edge is never sharper than a quarter pixel (lens blur, demosaicing; it also keeps the
    # model smooth between the sub-pixel samples), and a disc much smaller than the blur is a
    # point: bounds that keep the parameters identifiable
    lo = np.array([-0.5, -0.5, np.log(0.1 * s0), -np.inf, np.log(0.5 * s0)])
    hi = np.array([0.5, 0.5, np.log(np.pi / 2), np.inf, np.log(10.0 * s0)])
    res = None
    for a0 in (alpha0, 0.3 * alpha0):  # a disc, or a blurred point
        x0[2] = np.log(max(a0, 0.2 * s0))
        try:
            r = least_squares(residuals, np.clip(x0, lo + 1e-9, hi - 1e-9), x_scale=np.array([s0, s0, 0.3, 0.3, 0.3]),
                              bounds=(lo, hi), method="trf", max_nfev=400)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if r.status >= 0 and (res is None or r.cost < res.cost):
            res = r
    if res is None:  # (status 0, evaluations spent, keeps the best point)
        return np.full(3, np.nan)
    d = direction(res.x)
    return d if np.all(np.isfinite(d)) else np.full(3, np.nan)


def highlight_direction(view: SphereView, pixel) -> tuple[np.ndarray, np.ndarray]:
    """The reflected direction and reflection point (world) of one image point on the sphere.

    Parameters
    ----------
    view : SphereView
    pixel : (2,) float

    Returns
    -------
    direction : (3,) float, unit (NaN where the ray misses the sphere)
    point : (3,) float
    """
    L, P = view.reflect(np.asarray(pixel, dtype=np.float64).reshape(1, 2))
    return L[0], P[0]


def _pixel_jacobian(view: SphereView, pixel: np.ndarray, h: float = 0.25) -> np.ndarray:
    """``d l / d (x, y)`` (3, 2) at ``pixel``, central differences (one-sided near the rim)."""
    cols = []
    for e in ([h, 0.0], [0.0, h]):
        e = np.asarray(e)
        lp, _ = highlight_direction(view, pixel + e)
        lm, _ = highlight_direction(view, pixel - e)
        l0, _ = highlight_direction(view, pixel)
        if np.all(np.isfinite(lp)) and np.all(np.isfinite(lm)):
            cols.append((lp - lm) / (2 * h))
        elif np.all(np.isfinite(lm)):
            cols.append((l0 - lm) / h)
        else:
            cols.append((lp - l0) / h)
    return np.stack(cols, axis=1)


@dataclass
class HighlightFit:
    """A mirror or glossy sphere's light direction in one photo (:func:`fit_highlight`).

    The interface it shares with :class:`ffls.spheres.lambert.LambertFit`: ``status``,
    ``direction``, ``uncertainty_deg`` (RMS angle), ``intensity`` and :meth:`as_dict`.

    Attributes
    ----------
    status : str
        ``'ok'`` or a :data:`HIGHLIGHT_STATUSES` key.
    direction : (3,) float, unit (world; NaN when none)
    point : (3,) float
        Reflection point ``P`` on the sphere (world): where a near light's ray starts.
    uncertainty_deg : float
        RMS angular uncertainty (statistical, through the Jacobian, with ``floor_deg``).
    intensity : float
        The highlight's peak above its background.
    pixel : (2,) float
        The highlight's centre (image pixels, x, y).
    pixel_sigma : float
        Per-axis standard deviation of ``pixel`` relative to the sphere's centre.
    n_blob, n_core, n_saturated : int
    clipped : bool
    rim_px : float
        Distance of the highlight to the disc's edge.
    near_rim : bool
        The blob reaches the disc's edge but its centre and core lie inside it
        (:func:`_rim_status`): usable, with its cone widened, where no other sphere is.
    model : str
        ``'highlight'``.
    method : {'centroid', 'censored'}
        How the centre was found: the light-probe centroid, or for a clipped highlight the
        censored disc fit (:func:`highlight_centre_Tobin1958`).
    """

    status: str
    direction: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    point: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    uncertainty_deg: float = float("inf")
    intensity: float = 0.0
    pixel: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    pixel_sigma: float = float("inf")
    n_blob: int = 0
    n_core: int = 0
    n_saturated: int = 0
    clipped: bool = False
    rim_px: float = float("inf")
    near_rim: bool = False
    model: str = "highlight"
    method: str = "centroid"

    @property
    def cone95_deg(self) -> float:
        """Radius of the 95% cone of :attr:`direction` (2-D normal error of RMS ``uncertainty_deg``)."""
        return float(CONE95_PER_RMS * self.uncertainty_deg)

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        def num(x):
            x = float(x)
            return x if np.isfinite(x) else None

        fin = bool(np.all(np.isfinite(self.direction)))
        return {"status": self.status, "kind": "mirror", "model": self.model, "method": self.method,
                "direction": [float(x) for x in self.direction] if fin else None,
                "uncertainty_deg": num(self.uncertainty_deg), "cone95_deg": num(self.cone95_deg),
                "intensity": num(self.intensity),
                "highlight_px": [float(x) for x in self.pixel] if np.all(np.isfinite(self.pixel)) else None,
                "highlight_sigma_px": num(self.pixel_sigma), "n_blob": int(self.n_blob), "n_core": int(self.n_core),
                "n_saturated": int(self.n_saturated), "clipped": bool(self.clipped), "rim_px": num(self.rim_px),
                "near_rim": bool(self.near_rim)}


def highlight_direction_Mudge2006(view: SphereView, image: np.ndarray, disc: np.ndarray,
                                  saturated: np.ndarray | None = None, origin_px=(0.0, 0.0), *,
                                  floor_deg: float = 0.1, **kwargs) -> HighlightFit:
    """The light direction of one photo from a mirror or glossy sphere's highlight.

    Mudge et al. 2006 (the RTI highlight method): find the highlight (:func:`find_highlight`),
    take its centre (:func:`highlight_centre_Debevec1998`) and reflect the viewing ray there about
    the sphere's normal (:meth:`SphereView.reflect`).

    The highlight centre's own per-axis pixel uncertainty is
    ``sqrt(sigma_noise^2 + c^2 + q^2 + s0^2)``: ``sigma_noise`` the
    background's spread (noise and clutter) propagated through the weighted mean, ``c =``
    :data:`CLIP_SIGMA_PX` where the core is clipped (:data:`CENSORED_SIGMA_PX` where the censored
    fit :func:`highlight_centre_Tobin1958` located it: cores of :data:`MIN_CENSORED_PX` or more
    clipped pixels with an unclipped shoulder), ``q = 1/sqrt(12)`` px where a clipped core
    has no unclipped shoulder, and ``s0 =`` :data:`PIXEL_FLOOR_PX`. It is
    mapped to directions by the numerical Jacobian of the pixel-to-direction map. The sphere's
    outline adds its own part: its centre's per-axis uncertainty (``view.center_sigma_px``) and
    its radius's (``view.radius_sigma_px``) through :meth:`SphereView.outline_jacobian` at the
    highlight (a radius error moves a highlight near the rim far more than one at the centre).
    ``floor_deg`` is added in quadrature. ``pixel_sigma`` is the highlight's own part with the
    centre's in quadrature.

    Parameters
    ----------
    view : SphereView
    image : (h, w) float
        Grey linear values of a patch holding the disc.
    disc : (h, w) bool
    saturated : (h, w) bool, optional
    origin_px : (2,) float
        Image coordinates (x, y) of the patch's pixel (0, 0).
    floor_deg : float
        RMS angular floor.
    **kwargs
        Passed to :func:`find_highlight`.

    Returns
    -------
    HighlightFit
    """
    spot = find_highlight(image, disc, saturated, **kwargs)
    base = dict(intensity=spot.peak, n_blob=int(spot.rows.size), n_core=spot.n_core, n_saturated=spot.n_saturated,
                clipped=spot.n_saturated > 0, rim_px=spot.rim_px)
    # a highlight at the rim or off the outline: the blob's plain weighted centre is kept (where the
    # light was seen), which tells the capture's outline where it is too small (outline_holding_highlights)
    px = np.stack([spot.cols + float(origin_px[0]), spot.rows + float(origin_px[1])], axis=1)
    w = np.clip(spot.weights, 0.0, None)
    blob = np.sum(w[:, None] * px, axis=0) / w.sum() if px.size and w.sum() > 0 else np.full(2, np.nan)
    if not spot.found:
        return HighlightFit(status=spot.status, pixel=blob if spot.status == "highlight_at_rim" else np.full(2, np.nan),
                            **base)
    d, pixel = highlight_centre_Debevec1998(view, spot, origin_px)
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(pixel))):
        return HighlightFit(status="fit_failed", pixel=blob, **base)
    J = _pixel_jacobian(view, pixel)
    if not np.all(np.isfinite(J)):
        return HighlightFit(status="fit_failed", **base)
    norm_J = float(np.sqrt(np.sum(J * J)))  # sqrt(trace(J sigma^2 I J^T)) / sigma
    # the outline's part: its centre (per axis) and radius through the exact map, at this pixel
    Jo = view.outline_jacobian(pixel)
    if not np.all(np.isfinite(Jo)):  # a moved outline misses the pixel (at the rim): the centre's part alone
        Jo = np.concatenate([-J, np.zeros((3, 1))], axis=1)
    outline_deg = float(np.degrees(np.sqrt(view.center_sigma_px ** 2 * np.sum(Jo[:, :2] ** 2)
                                           + view.radius_sigma_px ** 2 * np.sum(Jo[:, 2] ** 2))))
    px = np.stack([spot.cols + float(origin_px[0]), spot.rows + float(origin_px[1])], axis=1)
    wsum = float(spot.weights.sum())
    if not wsum > 0:  # as the centroid (highlight_centre_Debevec1998): the positive signal's
        wsum = float(np.clip(spot.weights, 0.0, None).sum())
    var_noise = float(spot.noise ** 2 * np.sum((px - pixel) ** 2, axis=0).mean() / wsum ** 2) if wsum > 0 else np.inf
    clip = CLIP_SIGMA_PX if spot.n_saturated > 0 else 0.0
    quant = 0.0 if spot.shoulder else 1.0 / np.sqrt(12.0)  # an outline without shoulder: a pixel's quantisation
    own = float(np.sqrt(var_noise + clip ** 2 + quant ** 2 + PIXEL_FLOOR_PX ** 2))  # the highlight centre's own
    sigma = float(np.sqrt(own ** 2 + view.center_sigma_px ** 2))
    method = "centroid"
    if spot.n_saturated >= MIN_CENSORED_PX and spot.shoulder:  # the clipped core's profile is lost: fit its outline
        dc = highlight_centre_Tobin1958(view, spot, d, origin_px)
        # kept where it lies within 3 sigma of the centroid (a source far from a soft disc may not fit)
        if np.all(np.isfinite(dc)) and angle_between(dc, d) <= 3.0 * sigma * norm_J:
            d, method = dc, "censored"
            own = float(np.sqrt(var_noise + CENSORED_SIGMA_PX ** 2 + PIXEL_FLOOR_PX ** 2))
            sigma = float(np.sqrt(own ** 2 + view.center_sigma_px ** 2))
    status, widen_deg = spot.status, 0.0
    if status == "highlight_at_rim":  # the blob reaches the edge; its centre and core decide (_rim_status)
        status, widen_deg = _rim_status(view, d, pixel, px, spot.weights, float(np.hypot(own, view.center_sigma_px)))
    _, point = highlight_direction(view, pixel)
    stat = float(np.hypot(np.hypot(np.degrees(own * norm_J), outline_deg), widen_deg))
    return HighlightFit(status=status, direction=d, point=point, uncertainty_deg=float(np.hypot(stat, floor_deg)),
                        pixel=pixel, pixel_sigma=sigma, method=method, near_rim=spot.status != status, **base)


#: The package's name for the method (one paper per function; see the module docstring).
fit_highlight = highlight_direction_Mudge2006


def rim_distance_px(view: SphereView, pixels) -> np.ndarray:
    """Image distances (n,) in pixels from each of ``pixels`` (n, 2) outward, away from the sphere
    centre's image, to the sphere's outline (where the ray stops meeting the sphere,
    :meth:`SphereView.reflect`): bisection to 0.01 px, any camera model; NaN off the sphere."""
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    u = p - np.asarray(view.center_px, dtype=np.float64)
    n = np.hypot(u[:, 0], u[:, 1])[:, None]
    u = np.where(n > 0, u / np.where(n > 0, n, 1.0), np.array([1.0, 0.0]))

    def on(t):
        return np.all(np.isfinite(view.reflect(p + t[:, None] * u)[0]), axis=1)

    lo = np.zeros(len(p))
    hi = np.full(len(p), 2.0 * float(view.radius_px) + 4.0)  # beyond the outline from any disc point
    while np.any(hi - lo > 0.01):
        mid = 0.5 * (lo + hi)
        inside = on(mid)
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    return np.where(on(np.zeros(len(p))), 0.5 * (lo + hi), np.nan)


def _rim_status(view: SphereView, direction, pixel, px, weights, sigma_px: float) -> tuple[str, float]:
    """(status, widening deg) of a highlight whose blob reaches the disc's edge.

    The blob (:func:`find_highlight`) may reach the edge by its spread alone (a compact highlight
    a few pixels inside the rim, blurred by the lens or JPEG): its direction is determined. With
    ``a`` = :data:`RIM_SIGMAS` standard deviations of the centre (its own and the outline's
    centre and radius, in quadrature) plus the pixel's half-width, or :data:`RIM_MIN_PX` (the
    edge pixels' band) where wider, it is
    ``'highlight_at_rim'`` where its centre or its core (the blob's pixels above half its peak
    signal) lies within ``a`` of the outline: the light may be behind the sphere, or its image
    cut by the limb (a lit area hugging the edge). Otherwise ``'ok'``, with its cone widened (RMS,
    degrees) by two parts in quadrature: the limb may hide part of the light's image, which moves
    the centroid by up to the light's own angular extent (the blob's signal-weighted RMS angle
    from ``direction``, its pixels' reflected directions); and toward the rim the
    pixel-to-direction map bends faster than its Jacobian says (half the angle between the exact
    directions one standard deviation plus half a pixel inward and outward along the ball's
    radius)."""
    p = np.asarray(pixel, dtype=np.float64).reshape(1, 2)
    px = np.asarray(px, dtype=np.float64).reshape(-1, 2)
    w = np.clip(np.asarray(weights, dtype=np.float64), 0.0, None)
    if not (w.size and w.sum() > 0):
        return "highlight_at_rim", 0.0
    d = rim_distance_px(view, np.concatenate([p, px[w >= 0.5 * w.max()]]))
    sigma_rim = float(np.hypot(sigma_px, view.radius_sigma_px))
    if not (np.all(np.isfinite(d)) and float(d.min()) > max(RIM_SIGMAS * sigma_rim + 0.5, RIM_MIN_PX)):
        return "highlight_at_rim", 0.0
    dirs = view.reflect(px)[0]
    seen = np.all(np.isfinite(dirs), axis=1) & (w > 0)
    cosang = np.clip(dirs[seen] @ np.asarray(direction, dtype=np.float64), -1.0, 1.0)
    extent = float(np.degrees(np.sqrt(np.sum(w[seen] * np.arccos(cosang) ** 2) / w[seen].sum())))
    u = p[0] - np.asarray(view.center_px, dtype=np.float64)
    u = u / max(float(np.hypot(*u)), 1e-12)
    a = sigma_rim + 0.5  # one standard deviation and the pixel's half-width
    ends = view.reflect(np.concatenate([p + a * u, p - a * u]))[0]
    return "ok", float(np.hypot(extent, 0.5 * np.degrees(angle_between(ends[0], ends[1]))))


def sample_patch(rows: np.ndarray, cols: np.ndarray, *arrays):
    """Scatter per-pixel arrays of a sphere's samples into their bounding-box patch: ``((c0, r0),
    disc, patches)``, the patch's top-left pixel (column, row), the samples' mask over it and one
    patch per array (zero elsewhere, of its dtype)."""
    r0, c0 = int(rows.min()), int(cols.min())
    shape = (int(rows.max()) - r0 + 1, int(cols.max()) - c0 + 1)
    disc = np.zeros(shape, dtype=bool)
    disc[rows - r0, cols - c0] = True
    out = []
    for a in arrays:
        p = np.zeros(shape, dtype=np.asarray(a).dtype)
        p[rows - r0, cols - c0] = a
        out.append(p)
    return (c0, r0), disc, out


def fit_highlight_samples(view: SphereView, samples, grey: np.ndarray, valid: np.ndarray, *,
                          floor_deg: float = 0.1, **kwargs) -> HighlightFit:
    """:func:`fit_highlight` on a sphere's pixels as the pipeline holds them.

    Parameters
    ----------
    view : SphereView
    samples : ffls.spheres.samples.SphereSamples
        The sphere's pixels (``rows``, ``cols``).
    grey : (m,) float
        Their grey values in one photo (:class:`ffls.spheres.samples.SphereValues`).
    valid : (m,) bool
        Their validity (clipped pixels are the invalid bright ones, :func:`saturated_pixels`).
    floor_deg : float
    **kwargs
        Passed to :func:`find_highlight`.

    Returns
    -------
    HighlightFit
    """
    rows, cols = np.asarray(samples.rows), np.asarray(samples.cols)
    if rows.size == 0:
        return HighlightFit(status="no_highlight")
    g = np.asarray(grey, dtype=np.float64)
    sat = saturated_pixels(g, valid)
    fin = np.isfinite(g)
    origin, disc, (img, satp, finp) = sample_patch(rows, cols, np.where(fin, g, 0.0), sat, fin)
    return fit_highlight(view, img, disc & finp, satp, origin, floor_deg=floor_deg, **kwargs)


def highlight_compactness(rows: np.ndarray, cols: np.ndarray, grey: np.ndarray) -> float:
    """Fraction of a sphere's disc above half its brightest signal in one photo.

    The signal is the grey value above the disc's median. A mirror or glossy ball concentrates
    it in a compact highlight (a fraction of a percent of the disc); a matte ball spreads it
    over its lit cap (tens of percent). NaN when the disc has no signal (an unlit sphere).

    The brightest signal is the larger of the 3x3 mean's peak and the brightest pixel with an
    8-neighbour carrying at least half its signal: a lone hot pixel is no highlight, but a small
    ball's highlight of two or three clipped pixels is (the 3x3 mean alone dims it to a quarter,
    below the ball's moving reflection of the lit ground: ``ffls synth --resolution 256
    --spheres 1 --sphere-material mirror --format png8 --encoding srgb --exposure 3``, a chrome ball
    of 18 px radius, gave a median of 0.039 and was taken as matte; 0.012 with the pair).

    Parameters
    ----------
    rows, cols : (m,) int
        The sphere's pixels.
    grey : (m,) float
        Their grey values.

    Returns
    -------
    float
    """
    g = np.asarray(grey, dtype=np.float64)
    fin = np.isfinite(g)
    if fin.sum() < 20:
        return float("nan")
    _, disc, (img,) = sample_patch(np.asarray(rows)[fin], np.asarray(cols)[fin], g[fin])
    med = float(np.median(g[fin]))
    z = img.astype(np.float32)
    num = cv2.blur(z, (3, 3), borderType=cv2.BORDER_CONSTANT)
    den = cv2.blur(disc.astype(np.float32), (3, 3), borderType=cv2.BORDER_CONSTANT)
    smooth = np.where(disc, num / np.maximum(den, 1e-6), -np.inf)
    # the brightest signal: the 3x3 mean's peak (a hot pixel is no highlight), or the brightest pixel
    # with a neighbour carrying half its signal (a highlight of 2 pixels or more, which the 3x3 mean
    # would dim to 2/9: a small ball's highlight from a small light, whose ball then counted as matte)
    sig = np.where(disc, img - med, -np.inf).astype(np.float32)
    ring = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], dtype=np.uint8)
    neighbour = cv2.dilate(np.where(disc, sig, np.float32(-3e38)), ring, borderType=cv2.BORDER_CONSTANT,
                           borderValue=-3e38)
    paired = np.where(disc & (sig > 0) & (neighbour >= 0.5 * sig), sig, -np.inf)
    top = max(float(smooth.max()) - med, float(paired.max()))
    if not top > 1e-12 * max(abs(med), 1e-30):
        return float("nan")
    return float(np.count_nonzero(disc & (img >= med + 0.5 * top)) / max(int(disc.sum()), 1))


@dataclass(frozen=True)
class SphereKind:
    """A sphere's material as used (:func:`classify_sphere`).

    Attributes
    ----------
    kind : {'matte', 'mirror'}
    source : {'declared', 'classified'}
    statistic : float or None
        Median of :func:`highlight_compactness` over the photos (None when declared).
    threshold : float
        :data:`MIRROR_COMPACTNESS`.
    n_photos : int
        Photos that gave the statistic.
    """

    kind: str
    source: str
    statistic: float | None = None
    threshold: float = MIRROR_COMPACTNESS
    n_photos: int = 0

    def as_dict(self) -> dict:
        return {"kind": self.kind, "source": self.source, "compactness": self.statistic,
                "threshold": self.threshold, "n_photos": self.n_photos}

    def __str__(self) -> str:
        if self.source == "declared":
            return f"{self.kind} (declared)"
        return (f"{self.kind} (classified: median lit fraction {self.statistic:.3f} over {self.n_photos} photos, "
                f"mirror below {self.threshold:g})")


def classify_sphere(compactness, threshold: float = MIRROR_COMPACTNESS) -> SphereKind:
    """A sphere's kind from its per-photo :func:`highlight_compactness`.

    Parameters
    ----------
    compactness : (n,) float
        Per photo (NaN where the sphere was unlit).
    threshold : float

    Returns
    -------
    SphereKind
        ``'mirror'`` when the median over the lit photos is below ``threshold``; ``'matte'``
        otherwise, or when no photo lit the sphere.
    """
    c = np.asarray(compactness, dtype=np.float64)
    c = c[np.isfinite(c)]
    if c.size == 0:
        return SphereKind("matte", "classified", None, threshold, 0)
    med = float(np.median(c))
    return SphereKind("mirror" if med < threshold else "matte", "classified", med, threshold, int(c.size))


#: Median, over a ball's sectors, of the brightness jump at its limb in units of the noise
#: (:attr:`ffls.spheres.mirror_outline.LimbFit.jump_snr`) from which the limb's step, and not the
#: detected outline, places a mirror or glossy ball. A black glossy ball on any lit background
#: shows a clear step all round (30 to 40 on ``ffls synth --sphere-material glossy_black``); a chrome
#: ball reflects, at grazing, the very background it stands against, so its step is weak (median 5
#: on ``--sphere-material mirror``) and what the fit follows there is the reflected scene inside the
#: rim (a dark band of the ground the ball itself occludes), not the limb. At a jump of 10 noise
#: units a single sector's step is located to a tenth of the blur, so the step is the limb's.
LIMB_CLEAR_SNR = 10.0
#: Per-axis floor (pixels) of the limb step's position: the rim's Fresnel rise toward grazing is
#: steeper in its last pixel than the fit's quadratic (its slope is unbounded at the limb), which
#: leaves the step 0.13 to 0.17 px inside the silhouette on the glossy black renders of
#: ``benchmarks/bench_conditions.py`` at 384 px (docs/spheres.md).
LIMB_MODEL_FLOOR_PX = 0.15


def refine_view_limb(view: SphereView, image: np.ndarray, bracket: bool = False) -> tuple[SphereView, LimbFit | None]:
    """A mirror or glossy ball's view with its outline at the step of its limb, where that step is clear.

    The detected outline of a black glossy ball lies up to a pixel inside its silhouette (the
    brightening Fresnel rim moves the edge inward), and every direction from its highlights
    inherits that error (3 % of the radius: 2 degrees). :func:`ffls.spheres.mirror_outline.fit_limb_profile`
    locates the silhouette as the step of the brightness across the limb in ``image`` (a
    reduction of the whole sequence: the outline is fixed while the lights move). Where the step
    is clear (median sector jump at least :data:`LIMB_CLEAR_SNR` times the noise) and the ball's
    body is dark against its surroundings (:data:`LIMB_DARK_BODY_RATIO`), the view takes its
    geometry (pinhole: the centre from the tangent cone and the sphere's radius; orthographic:
    the circle). Otherwise (a chrome ball, whose limb reflects its own background, so that the
    step lies where the reflected backdrop ends, not at the silhouette) the detected outline is
    kept. Either way the kept outline is uncertain by at least the gap between the two: the
    centre's sigma at least the distance between their centres, the radius's the difference of
    their :func:`apparent_radius_px`, each with the step's own precision and
    :data:`LIMB_MODEL_FLOOR_PX` in quadrature, and neither below the detected outline's own. A
    gap beyond half of :data:`ffls.spheres.mirror_outline.LIMB_BAND_PX` (the step found another
    edge), or no fit, leaves the view as it is.

    ``bracket`` (a lone ball, whose cone its own outline sets): where the detected outline of a
    chrome ball is kept, the two estimates bracket its silhouette (its reflections' edges run
    inside the limb, the step at or just outside it), and the kept one is uncertain by half their
    gap (per axis), not all of it: on 9 lone chrome balls at 384 px (``docs/spheres.md``, "A lone
    chrome ball's outline: jackknife and bracket") the detected radius was 0.09-0.61 px off where
    the full gap said 0.45-1.36 px. Beside other spheres the full gap stays: it weights the
    spheres' combination (bench c11, c17 moved with the half gap).

    Parameters
    ----------
    view : SphereView
    image : (H, W) float
        The sequence's mean luminance (linear preferred).
    bracket : bool
        The ball is alone (see above): a kept chrome outline uncertain by half the gap.

    Returns
    -------
    view : SphereView
        Refined (geometry, or only its uncertainty), or ``view`` itself.
    limb : LimbFit or None
        The limb fit (None where it failed).
    """
    limb = fit_limb_profile(image, view.center_px, view.radius_px, model=view.model, K=view.K, dist=view.dist,
                            center_cam=view.center_cam, radius=view.radius)
    if limb is None or not np.any(np.isfinite(limb.jump_snr)):
        return view, limb
    c_own = float(np.hypot(limb.center_sigma_px, LIMB_MODEL_FLOOR_PX))
    r_own = float(np.hypot(limb.radius_sigma_px, LIMB_MODEL_FLOOR_PX))
    # two estimates of the outline, the detected one and the limb's step: which one holds is not
    # known (a chrome ball's step can follow its reflected backdrop inside the rim, 1.4 px short on
    # a 28 px ball of 8 mixed spheres), so whichever is kept is uncertain by at least their gap
    gap_c = float(np.linalg.norm(np.asarray(limb.center_px) - np.asarray(view.center_px)))
    gap_r = abs(float(limb.radius_px) - apparent_radius_px(view))
    if not (np.isfinite(gap_c) and np.isfinite(gap_r)) or max(gap_c, gap_r) > 0.5 * LIMB_BAND_PX:
        return view, limb  # the step found another edge than the limb: the detected outline's own uncertainty
    # never below the detected outline's own uncertainty (a second estimate that agrees with it
    # does not make it better: the limb's step can lie on the same wrong edge)
    # a chrome ball (a weak step, or a body that reflects its surroundings): the detected outline
    # (its reflections' edges) is kept; bracketed by the two estimates, uncertain by half their gap
    chrome = (np.nanmedian(limb.jump_snr) < LIMB_CLEAR_SNR
              or not dark_body(image, view.center_px, view.radius_px))
    k = 0.5 if bracket and chrome else 1.0
    c_sig = float(max(np.hypot(k * gap_c, c_own), view.center_sigma_px))
    r_sig = float(max(np.hypot(k * gap_r, r_own), view.radius_sigma_px))
    if chrome:
        return replace(view, center_sigma_px=c_sig, radius_sigma_px=r_sig), limb
    c_sig = float(max(c_sig, np.hypot(c_own, limb.radius_sigma_px)))
    if view.model == "pinhole":
        return replace(view, center_px=limb.center_px, center_cam=limb.center_cam, center_sigma_px=c_sig,
                       radius_sigma_px=r_sig), limb
    return replace(view, center_px=limb.center_px, radius_px=limb.radius_px, center_sigma_px=c_sig,
                   radius_sigma_px=r_sig), limb


def limb_view(view: SphereView, limb: LimbFit) -> SphereView:
    """``view`` with its outline moved to the limb fit's (pinhole: the image of the centre and
    ``center_cam``; orthographic: the circle); its uncertainties are left as they are."""
    if view.model == "pinhole":
        return replace(view, center_px=np.asarray(limb.center_px, dtype=np.float64),
                       center_cam=np.asarray(limb.center_cam, dtype=np.float64))
    return replace(view, center_px=np.asarray(limb.center_px, dtype=np.float64), radius_px=float(limb.radius_px))


def highlights_outside(view: SphereView, pixels) -> int:
    """How many of the highlight centres ``pixels`` ((n, 2) x, y; NaN rows skipped) lie off the
    view's outline (their pixel's ray misses the sphere: no reflected direction)."""
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.size == 0:
        return 0
    L, _ = view.reflect(p)
    return int(np.count_nonzero(~np.all(np.isfinite(L), axis=1)))


def outline_holding_highlights(view: SphereView, image: np.ndarray, pixels) -> tuple[SphereView, int, int]:
    """A chrome ball's outline chosen by its highlights: every photo's light is seen on the ball.

    A highlight is a reflection on the sphere, so its centre lies inside the silhouette in every
    photo, and over a sequence whose lights reach grazing the highlights' envelope bounds the
    silhouette from inside (a property of the geometry, not of the renderer or the scene). A chrome
    ball has two estimates of its outline: the detected one (its reflections' edges) and the step
    at its limb (:func:`ffls.spheres.mirror_outline.fit_limb_profile`, which finds where the
    reflected backdrop meets the reflected sky, within a pixel or two of the silhouette). The
    detected outline is kept unless it leaves more of the highlights off the ball than the limb
    step's outline does; then the limb's geometry is taken (its uncertainties, the two outlines'
    gap, :func:`refine_view_limb`, stay). A limb step beyond half of
    :data:`ffls.spheres.mirror_outline.LIMB_BAND_PX` from the detected outline (another edge) is
    never taken.

    Parameters
    ----------
    view : SphereView
        The sphere's view as the pipeline fitted it (after :func:`refine_view_limb`).
    image : (H, W) float
        The sequence's mean luminance.
    pixels : (n, 2) float
        The photos' highlight centres (x, y; NaN where none), those off the outline included
        (:attr:`HighlightFit.pixel` of a ``'fit_failed'`` fit).

    Returns
    -------
    view : SphereView
        ``view``, or its outline moved to the limb step's.
    outside_before, outside_after : int
        Highlights off the outline of ``view`` and of the returned view.
    """
    before = highlights_outside(view, pixels)
    if before == 0:
        return view, 0, 0
    limb = fit_limb_profile(image, view.center_px, view.radius_px, model=view.model, K=view.K, dist=view.dist,
                            center_cam=view.center_cam, radius=view.radius)
    if limb is None or not np.all(np.isfinite(limb.center_px)) or not np.isfinite(limb.radius_px):
        return view, before, before
    if view.model == "pinhole" and (limb.center_cam is None or not np.all(np.isfinite(limb.center_cam))):
        return view, before, before
    gap_c = float(np.linalg.norm(np.asarray(limb.center_px) - np.asarray(view.center_px)))
    gap_r = abs(float(limb.radius_px) - apparent_radius_px(view))
    if max(gap_c, gap_r) > 0.5 * LIMB_BAND_PX:
        return view, before, before
    moved = limb_view(view, limb)
    after = highlights_outside(moved, pixels)
    return (moved, before, after) if after < before else (view, before, before)


def apparent_radius_px(view: SphereView) -> float:
    """A view's apparent radius in the unit of :attr:`SphereView.radius_sigma_px`: orthographic its
    circle's radius, pinhole ``f tan(alpha)`` (``f`` the mean focal length, ``alpha`` the tangent
    cone's half-angle)."""
    if view.model != "pinhole":
        return float(view.radius_px)
    K = np.asarray(view.K, dtype=np.float64)
    alpha = np.arcsin(min(float(view.radius) / float(np.linalg.norm(view.center_cam)), 1.0))
    return float(0.5 * (K[0, 0] + K[1, 1]) * np.tan(alpha))
