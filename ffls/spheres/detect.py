"""Finding the reference spheres: silhouette edges -> sphere centres (Masselus et al. 2002, sec. 5).

Calibration spheres of known radius ``R`` (white or grey matte, or chrome) stand in the scene or
in their own calibration shots. Their centres ``C`` (camera frame) give every sphere pixel a
surface normal, from which the per-photo light direction follows (:mod:`ffls.spheres.estimate`).
Any number of spheres is found, with no hint; hints (a count, a rough pixel circle, a world
centre) are optional.

Method
------
1. **Max image.** The per-pixel maximum over the whole sequence, and which photo gave it
   (:func:`extreme_images`). A light that visits every side of the spheres makes each
   silhouette a closed, high-contrast outline in the maximum; a single photo shows only the lit
   crescent, whose terminator is not a silhouette. In the same streamed pass each photo adds its
   colour evidence (:func:`photo_colour_counts`: colour is judged per photo, where a glossy ball's
   highlights cover few pixels, not on the max image they whiten) and, for at most
   :data:`EDGE_PHOTOS` photos, its log-luminance structure tensor (:func:`photo_edge_tensor`).
2. **Edges.** Luminance of the max image, log tone-mapped to 8 bit, lightly blurred; Canny with
   thresholds derived from the image itself (a radiance ratio of about 1.2, never below the
   texture/noise level). Edge pixels are refined to subpixel precision along the gradient.
3. **Candidates.** With no hints, :func:`cv2.HoughCircles` proposes circles, kept by how much of
   their in-image outline the edges support. Hints (an approximate pixel circle, with or
   without radius, or a world centre projected through the camera) restrict the search to an
   annulus around them. Overrides skip detection altogether.
4. **Centre from the silhouette (equation 1).** Every silhouette ray ``s_i`` is tangent to the
   sphere: ``|C|^2 - R^2 - (s_i . C)^2 = 0``. The same condition in geometric form is
   ``angle(s_i, C) = alpha`` with ``sin(alpha) = R / |C|``: the rays lie on the tangent cone. We
   minimise ``f * (angle(s_i, c) - alpha)`` (``f`` the focal length in pixels, so the residual
   is in pixels) over the cone axis ``c`` and half-angle ``alpha``, and set
   ``C = R / sin(alpha) * c``. This parametrisation stays well conditioned for a near-orthographic
   camera (a long lens far away), where the algebraic form degenerates. An orthographic camera
   (no ``K``) fits a circle in pixels instead (:func:`fit_circle`); its normals follow from the
   pixel offset over the pixel radius (:func:`orthographic_normals`).
4b. **Edges that hold in the photos.** The ridge points of the summed tensor
   (:func:`consistent_edge_points`) keep a silhouette whatever its polarity in each photo, while
   terminators and cast shadows move: circles are also proposed and fitted on them, and every
   candidate is refitted on them where that fits better (:func:`_refine_on_consistent_edges`; a
   white sphere on a white ground merges with the ground in the max image).
5. **Robustness.** Edge pixels that are not silhouette (a stand, an occluder, a shadow boundary,
   the terminator) are handled by (a) keeping only edges whose gradient is radial and of the
   majority polarity, (b) a deterministic circle search (a Hough vote refined by least squares, :func:`ffls.spheres.mirror_outline.circle_search`) for the initial fit, (c) a ``soft_l1`` loss
   with a 1-pixel scale, and (d) trimming at a robust multiple of the residual spread followed
   by a refit on the inliers.
5b. **The outline at the linear step** (:func:`step_edges`, once the spheres are chosen): each
   outline point is moved along its ray from the centre to the Gaussian-blurred step between
   sphere and background fitted to the linear max image's profile (the photos' mean's, where its
   steps are blurred beyond a pixel: the max of blurred photos is no blurred step), and the
   outline refitted. The gradient maximum of the log image lies toward the dark side of an anti-aliased or defocused
   edge, and inside a limb that shades off (0.1-0.3 px on ``ffls synth`` renders).
6. **Which outlines are spheres** (no hints, :mod:`ffls.spheres.select`): round
   (fit RMS), closed and supported (coverage of the visible outline), visible enough (a sphere
   cut by the frame edge is used when 60 % of its outline is inside), neutral in colour, shading
   that changes across the photos as a sphere's does (not the same brightest photo everywhere),
   and sizes consistent with one shared ``sphere_radius``. Round outlines set aside are reported
   with their reason (:attr:`Spheres.rejected`).

The silhouette fixes only the cone, not ``R``: a wrong ``sphere_radius`` scales every centre's
distance. It is caught against a scene scale where one exists (the camera's distance to the
scene centre from ``world_from_camera``, or world-centre hints).
"""
from __future__ import annotations

import dataclasses
import math
import os

import cv2
import numpy as np

from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA, angle_between, normalize, tangent_basis
from ffls.camera.projection import CAMERA_MODELS, camera_arrays, pixel_rays, project_points
from ffls.errors import InputError
from ffls.radiance.photos import full_scale_share, read_photo
from ffls.spheres.select import (COLOUR_STEP, CRITERIA, disc_pixels, highlight_pixels, photos_highlighted_around,
                                 round_outline, select_spheres)
from ffls.spheres.mirror_outline import (MIRROR_OUTLINE_FLOOR_PX, MIRROR_OUTLINE_SIGMA_FLOOR_PX, OUTER_SOURCE,
                                         changing_limb_radius, circle_search, dark_body, dark_cap, enclosing_circle,
                                         limb_radius, mirror_silhouette)

__all__ = [
    "SphereFit",
    "max_image",
    "pixel_rays",
    "project_points",
    "find_spheres",
    "find_spheres_in_capture",
    "stated_circle_problem",
    "circle_candidates",
    "fit_sphere_center",
    "sphere_mask",
    "sphere_normals",
    "silhouette_px",
    "to_world",
    "edge_points",
    "step_edges",
    "Spheres",
    "extreme_images",
    "sequence_stats",
    "SequenceStats",
    "SequenceAccumulator",
    "photo_colour_counts",
    "photo_edge_tensor",
    "unit_cone_residuals",
    "consistent_edge_points",
    "consistent_edge_strength",
    "COLOUR_BINS",
    "EDGE_PHOTOS",
    "orthographic_normals",
    "disc_mask",
    "outline_visible_fraction",
    "fit_circle",
    "gradient_noise",
    "shading_ratio",
    "outline_quality",
    "outline_support",
    "PHOTO_EDGES",
    "CRITERIA",
]


#: ``SphereFit.outline_edges`` of an outline fitted on the edges that hold in the photos.
PHOTO_EDGES = "photos"


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
    camera_model : {'pinhole', 'orthographic'}
        For ``'orthographic'`` ``K`` and ``dist`` are None; the normals follow from the pixel
        offset over :attr:`radius_px` (:func:`orthographic_normals`) and ``center_cam`` is
        ``(u - cx, v - cy, 0) * radius / radius_px`` with ``(cx, cy)`` the image centre (an
        orthographic camera measures no depth).
    visible_fraction : float
        Fraction of the projected outline inside the image (1 unless the frame edge cuts it).
    score : float
        Detection score of an unhinted sphere (support x closure x neutrality x fit quality).
    center_sigma_px : float
        Standard error of the fitted centre, pixels (0 for overrides).
    outline_sigma_px : float
        A mirror ball's outline ambiguity, pixels: half the gap (centre and radius) between its two
        outline estimates (the reflected room's contrasts, which run inside the limb, and the limb's
        reflectance step, :mod:`ffls.spheres.mirror_outline`); 0 for other spheres.
    outline_gap_px : float
        Half the gap (centre and radius, pixels) between a mirror ball's outline and its second
        estimate, the limb's reflectance step; 0 where there is none.
    outline_centre_sigma_px : float
        A lone mirror ball's centre uncertainty per axis, pixels, its outline's misfit included,
        where a second outline estimate exists (:func:`_outline_centre_sigma`, set by
        :func:`find_spheres` when it finds one sphere): the sector jackknife of the outline fit,
        bounded above by :attr:`outline_gap_px`, at least
        :data:`ffls.spheres.mirror_outline.MIRROR_OUTLINE_SIGMA_FLOOR_PX`; 0 where not measured.
    outline_edges : {'max image', 'photos'}
        Where the outline's points come from: the max image's edges, or the edges that hold in the
        photos (:data:`PHOTO_EDGES`, :func:`consistent_edge_points`).
    outline_at_step : bool
        The outline was refitted on its points moved to the step of the linear max image
        (:func:`step_edges`): its centre needs no photometric correction
        (:func:`ffls.spheres.estimate.centres_to_refine`).
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
    K: np.ndarray | None
    dist: np.ndarray | None
    world_from_camera: np.ndarray
    camera_model: str = "pinhole"
    visible_fraction: float = 1.0
    score: float = 0.0
    center_sigma_px: float = 0.0
    outline_sigma_px: float = 0.0
    outline_gap_px: float = 0.0
    outline_centre_sigma_px: float = 0.0
    outline_edges: str = "max image"
    outline_at_step: bool = False

    @property
    def distance(self) -> float:
        """Distance from the camera centre to the sphere centre, scene units."""
        return float(np.linalg.norm(self.center_cam))

    def mask(self, shape, margin_px: float = 0.0) -> np.ndarray:
        """Pixels whose rays hit this sphere; see :func:`sphere_mask` (:func:`disc_mask` when orthographic)."""
        if self.camera_model == "orthographic":
            return disc_mask(shape, self.center_px, self.radius_px, margin_px=margin_px)
        return sphere_mask(shape, self.K, self.dist, self.center_cam, self.radius, margin_px=margin_px)

    def normals(self, pixels) -> np.ndarray:
        """Camera-frame unit normals at ``pixels`` (n, 2); see :func:`sphere_normals` (:func:`orthographic_normals`)."""
        if self.camera_model == "orthographic":
            return orthographic_normals(pixels, self.center_px, self.radius_px)
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
            "camera_model": self.camera_model,
            "visible_fraction": float(self.visible_fraction),
            "center_sigma_px": float(self.center_sigma_px),
            "outline_sigma_px": float(self.outline_sigma_px),
            "outline_gap_px": float(self.outline_gap_px),
            "outline_centre_sigma_px": float(self.outline_centre_sigma_px),
            "outline_edges": self.outline_edges,
            "outline_at_step": bool(self.outline_at_step),
        }


class Spheres(list):
    """The spheres found (a list of :class:`SphereFit`) and the round outlines set aside.

    Attributes
    ----------
    rejected : list of str
        One line per candidate that looked like a sphere (a closed, round outline) but was not
        used, with the reason (cut by the frame edge, coloured, unchanging shading, apparent size
        inconsistent with the other spheres).
    """

    def __init__(self, fits=(), rejected=()):
        super().__init__(fits)
        self.rejected = list(rejected)


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


def orthographic_normals(pixels, center_px, radius_px) -> np.ndarray:
    """Camera-frame unit normals of a sphere seen by an orthographic camera.

    The viewing ray is +z everywhere, so the visible hemisphere faces -z and the normal at pixel
    offset ``(dx, dy) / radius_px = (a, b)`` is ``(a, b, -sqrt(1 - a^2 - b^2))``.

    Parameters
    ----------
    pixels : (n, 2) float
    center_px : (2,) float
    radius_px : float

    Returns
    -------
    (n, 3) float64
        Unit normals; NaN outside the disc.
    """
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    ab = (p - np.asarray(center_px, dtype=np.float64).reshape(2)) / float(radius_px)
    q = 1.0 - np.sum(ab * ab, axis=1)
    n = np.concatenate([ab, -np.sqrt(np.clip(q, 0.0, None))[:, None]], axis=1)
    n[q < 0] = np.nan
    return n


def disc_mask(shape, center_px, radius_px, margin_px: float = 0.0) -> np.ndarray:
    """Pixels (H, W) bool within ``radius_px - margin_px`` of ``center_px`` (an orthographic sphere)."""
    H, W = int(shape[0]), int(shape[1])
    yy, xx = np.ogrid[:H, :W]
    r = float(radius_px) - float(margin_px)
    return (xx - center_px[0]) ** 2 + (yy - center_px[1]) ** 2 <= max(r, 0.0) ** 2


def outline_visible_fraction(outline_px, shape) -> float:
    """Fraction of outline points (n, 2) inside the image ``shape`` (H, W), half a pixel in from the border."""
    H, W = int(shape[0]), int(shape[1])
    o = np.asarray(outline_px, dtype=np.float64)
    inside = (o[:, 0] >= 0.5) & (o[:, 0] <= W - 1.5) & (o[:, 1] >= 0.5) & (o[:, 1] <= H - 1.5)
    return float(inside.mean()) if len(o) else 0.0


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


#: Bins of :func:`photo_colour_counts` over the min/max channel ratio [0, 1].
COLOUR_BINS = 16
#: At most this many photos, evenly spread over the sequence, give the per-photo edge evidence
#: (:func:`photo_edge_tensor`): a silhouette holds in nearly all of them, so a score of photos is
#: plenty, and the cost stays bounded for long sequences.
EDGE_PHOTOS = 24
#: Rows of the per-photo edge evidence (:func:`photo_edge_tensor`): ``[sum gx^2, sum gx gy, sum gy^2,
#: sum gx, sum gy]``.
EDGE_TENSOR_ROWS = 5
#: A photo with more than this share of its pixels at full scale (an integer file's top code in any
#: channel) is washed out (overexposed, or lit by more than the capture's light): it shades nothing,
#: and in the max image and the brightest-photo map it would hide every other photo. It is left out
#: of the detection's reductions (:meth:`SequenceAccumulator.add`), unless every photo is.
WASHED_OUT_SHARE = 0.5


@dataclasses.dataclass
class SequenceStats:
    """What detection keeps of a photo sequence, gathered in one streamed pass (:func:`sequence_stats`).

    Attributes
    ----------
    max : (H, W, 3) or (H, W) float32
        Per-pixel maximum (:func:`max_image`).
    brightest : (H, W) int32 or None
        Index of the photo with the highest luminance at each pixel (the first on ties).
    mean : (H, W) float64 or None
        Mean luminance over the photos.
    n : int
        Photos.
    colour_counts : (COLOUR_BINS, ceil(H / COLOUR_STEP), ceil(W / COLOUR_STEP)) uint16 or None
        Per sampled pixel, how many photos put it in each bin of the min/max channel ratio,
        counting only the photos where it is lit and unclipped (:func:`photo_colour_counts`); None
        for a single image or a single-channel sequence.
    edge_tensor : (EDGE_TENSOR_ROWS, H, W) float32 or None
        The per-photo edge evidence (:func:`photo_edge_tensor`) of at most :data:`EDGE_PHOTOS`
        photos; None for a single image.
    edge_photos : int
        How many photos gave ``edge_tensor``.
    washed_out : tuple of (int, float)
        The photos left out as washed out (:data:`WASHED_OUT_SHARE`): (index, share of their
        pixels at full scale), in index order; not counted in ``n``.
    levels : tuple of (int, float)
        Per photo (washed-out ones included), in index order: (index, the 99.5th percentile of its
        luminance, :func:`_robust_peak`), the frame's level (a misfired flash's is far below the
        capture's: ``ffls.spheres.estimate.reject_dark_photos``).
    """

    max: np.ndarray
    brightest: np.ndarray | None
    mean: np.ndarray | None
    n: int
    colour_counts: np.ndarray | None = None
    edge_tensor: np.ndarray | None = None
    edge_photos: int = 0
    washed_out: tuple = ()
    levels: tuple = ()


def _robust_peak(lum, q: float = 99.5) -> float:
    """The ``q``-th percentile of a luminance image, on every 4th pixel of every 4th row (fast, and as robust)."""
    sub = np.asarray(lum)[::4, ::4] if min(np.shape(lum)) >= 64 else np.asarray(lum)
    return float(np.percentile(sub, q))


def photo_edge_tensor(lum, tensor, sigma: float = 1.0, floor: float = 0.01, peak: float | None = None) -> None:
    """Add one photo's log-luminance structure tensor to ``tensor`` (in place): per-photo edge evidence.

    A silhouette is an edge at the same place in nearly every photo, whatever the light: the
    sphere's limb and the ground behind it differ in most photos, though which is brighter
    changes. In the max image it can vanish where both are bright in some photo (a white sphere on
    a white ground, at its top), and a contact shadow's boundary can replace it below. Moving
    edges (terminators, cast shadows) cross each pixel in few photos. The sum over the photos of
    the gradient's outer product ``g g^T`` of ``ln(L + floor * peak)`` (blurred by ``sigma``;
    ``peak`` the photo's 99.5th percentile (:func:`_robust_peak`), so the noise of its dark parts is not amplified)
    keeps the consistent edges strong whatever their polarity (a summed gradient would cancel
    them) and spreads the moving ones thin (:func:`consistent_edge_points`).

    The summed gradient itself is kept too (rows 3 and 4): the covariance of the gradient over the
    photos (``centered`` in :func:`consistent_edge_strength`) drops what is the same in every photo.
    A textured ground's edges are in ``ln`` units its albedo's, the same under every light, and
    vanish there; a silhouette's limb-to-ground contrast changes with the light, and stays.

    Parameters
    ----------
    lum : (H, W) float
        The photo's luminance.
    tensor : (3, H, W) or (5, H, W) float32
        ``[sum gx^2, sum gx gy, sum gy^2]`` and, with 5 rows, ``sum gx, sum gy``: gradients in
        natural-log units per pixel.
    sigma, floor : float
    peak : float, optional
        ``lum``'s robust peak where the caller has it (:attr:`SequenceStats.levels`).
    """
    peak = _robust_peak(lum) if peak is None else peak
    if not peak > 0:
        return
    g = cv2.GaussianBlur(np.log(np.asarray(lum, dtype=np.float32) + np.float32(floor * peak)), (0, 0), sigma)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    tensor[0] += gx * gx
    tensor[1] += gx * gy
    tensor[2] += gy * gy
    if len(tensor) >= EDGE_TENSOR_ROWS:
        tensor[3] += gx
        tensor[4] += gy


def consistent_edge_strength(tensor, n_photos: int, centered: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Strength ``sqrt(lambda_1 / n)`` (H, W) and angle (H, W, radians) of the principal direction
    ``e_1`` of the summed per-photo structure tensor (:func:`photo_edge_tensor`); ``centered``: of
    the gradient's covariance over the photos instead (the tensor's 5 rows needed)."""
    n = max(int(n_photos), 1)
    jxx, jxy, jyy = (np.asarray(t, dtype=np.float64) / n for t in tensor[:3])
    if centered:
        mx, my = (np.asarray(t, dtype=np.float64) / n for t in tensor[3:5])
        jxx, jxy, jyy = jxx - mx * mx, jxy - mx * my, jyy - my * my
    half_tr = 0.5 * (jxx + jyy)
    l1 = half_tr + np.sqrt(np.maximum(half_tr ** 2 - (jxx * jyy - jxy ** 2), 0.0))
    return np.sqrt(np.maximum(l1, 0.0)), 0.5 * np.arctan2(2 * jxy, jxx - jyy)


def consistent_edge_points(tensor, n_photos: int, centered: bool = False):
    """Ridge points of the per-photo edge evidence (:func:`photo_edge_tensor`), sub-pixel.

    The strength is ``sqrt(lambda_1 / n)``, the RMS over the photos of the log-luminance gradient
    along the tensor's principal direction ``e_1``. A point is kept where the strength is a local
    maximum along ``e_1`` and above 3 times its median over the image; its position is refined by
    a parabola through its two neighbours along ``e_1``. ``centered``: of the gradient's
    covariance over the photos (:func:`consistent_edge_strength`).

    Parameters
    ----------
    tensor : (3, H, W) or (5, H, W) float
    n_photos : int
    centered : bool

    Returns
    -------
    points : (m, 2) float64
        (x, y), pixels.
    dirs : (m, 2) float64
        Unit ``e_1`` (across the edge; its sign is arbitrary).
    strength : (m,) float64
    """
    return _ridge_points(*consistent_edge_strength(tensor, n_photos, centered))


def _ridge_points(S, ang):
    """:func:`consistent_edge_points` of the strength ``S`` and angle ``ang`` (:func:`consistent_edge_strength`)."""
    H, W = S.shape
    ys, xs = np.mgrid[0:H, 0:W]
    thr = 3.0 * float(np.median(S))
    cand = S > max(thr, 1e-12)
    p = np.stack([xs[cand], ys[cand]], axis=1).astype(np.float64)
    e = np.stack([np.cos(ang[cand]), np.sin(ang[cand])], axis=1)
    s0 = S[cand]
    sp, sm = _bilinear(S, p + e), _bilinear(S, p - e)
    ridge = (s0 >= sp) & (s0 > sm)
    den = sm - 2 * s0 + sp
    off = np.where(den < 0, 0.5 * (sm - sp) / np.where(den < 0, den, -1.0), 0.0)
    off = np.clip(off, -0.5, 0.5)
    return p[ridge] + off[ridge, None] * e[ridge], e[ridge], s0[ridge]


@dataclasses.dataclass
class ConsistentEdges:
    """One reading of the per-photo edge evidence: its strength and angle
    (:func:`consistent_edge_strength`) and ridge points (:func:`consistent_edge_points`), made once
    per :func:`find_spheres` and shared by the photo-edge search and every refit on these edges."""

    strength: np.ndarray
    angle: np.ndarray
    points: tuple
    rows: tuple = dataclasses.field(init=False, repr=False)  # the points' running y bounds (:meth:`near_rows`)

    def __post_init__(self):
        # the ridge points come row by row (each within half a pixel of its row): a running maximum
        # of y from the start and a running minimum from the end are sorted, and bound a band of rows
        y = self.points[0][:, 1]
        self.rows = (np.maximum.accumulate(y), np.minimum.accumulate(y[::-1])[::-1])

    @classmethod
    def of(cls, tensor, n_photos: int, centered: bool = False) -> "ConsistentEdges":
        S, ang = consistent_edge_strength(tensor, n_photos, centered)
        return cls(S, ang, _ridge_points(S, ang))

    def near_rows(self, y0: float, y1: float) -> slice:
        """A slice of ``points`` (in their order) holding every point with ``y0 <= y <= y1``: the
        ones before it have a running maximum of y below ``y0``, those after it a running minimum
        from the end above ``y1`` (so the slice is exact for any order, and short for rows)."""
        up, down = self.rows
        return slice(int(np.searchsorted(up, y0, "left")), int(np.searchsorted(down, y1, "right")))


def photo_colour_counts(im, lum, counts, lit_fraction: float = 0.1, clip_fraction: float = 0.98) -> None:
    """Add one photo's colour evidence to ``counts`` (in place): per pixel, its min/max channel bin.

    Colour is judged in each photo, not in the max image: a coloured glossy ball's highlights
    from many photos whiten it in the max image, but each photo shows a highlight on few of its
    pixels, and its body colour (dichromatic reflection, Shafer 1985) everywhere else it is lit.
    A pixel counts in a photo when it is lit (luminance at least ``lit_fraction`` of the photo's
    99.5th percentile, :func:`_robust_peak`: dark pixels' ratios are noise) and no channel is clipped (at or above
    ``clip_fraction`` of the photo's channel maximum: a clipped highlight reads white, a clipped
    red channel reads less red). Its bin is ``floor(COLOUR_BINS * min/max)``.

    Parameters
    ----------
    im : (H, W, 3+) float
        Linear photo.
    lum : (H, W) float
        Its luminance.
    counts : (COLOUR_BINS, ceil(H / COLOUR_STEP), ceil(W / COLOUR_STEP)) uint16
        Every :data:`COLOUR_STEP`-th pixel of every :data:`COLOUR_STEP`-th row.
    lit_fraction, clip_fraction : float
    """
    im = im[::COLOUR_STEP, ::COLOUR_STEP]
    lum = lum[::COLOUR_STEP, ::COLOUR_STEP]
    peak = _robust_peak(lum)
    if not peak > 0:
        return
    chans = [im[..., c] for c in range(3)]  # channel slices: numpy's reductions over a last axis of 3 are slow
    hi = np.maximum(np.maximum(chans[0], chans[1]), chans[2])
    use = (lum >= lit_fraction * peak) & (hi > 0)
    for c in chans:
        use &= c < clip_fraction * float(c.max())
    flat = np.flatnonzero(use)
    if flat.size == 0:
        return
    lo = np.minimum(np.minimum(chans[0], chans[1]), chans[2])
    # a channel below 0 (sensor noise around black in a float photo) has no colour left: bin 0
    ratio = np.clip(lo.reshape(-1)[flat] / hi.reshape(-1)[flat], 0.0, 1.0)
    b = np.minimum((ratio * COLOUR_BINS).astype(np.int64), COLOUR_BINS - 1)
    cf = counts.reshape(-1)
    cf[b * (counts.shape[1] * counts.shape[2]) + flat] += 1  # one bin per pixel: no repeated index


class _Stowed:
    """Marks an array of a :class:`SequenceAccumulator` that :meth:`~SequenceAccumulator.stow` moved to a buffer."""


class SequenceAccumulator:
    """The streamed reductions of :func:`sequence_stats`, one photo at a time: ``add(image, index)``,
    ``merge(later)``, ``result()``.

    Every reduction is a function of the photo's index in the sequence, not of the order of
    ``add`` calls, so a sequence cut into consecutive chunks, each accumulated on its own (e.g.
    in worker processes) and merged in order, gives what one accumulator over the whole sequence
    gives: the max and the colour counts exactly, the brightest photo exactly (the first on ties),
    the luminance sum and the edge tensor to within rounding (exactly, for a given chunking).

    Parameters
    ----------
    colour : bool
        Gather :attr:`SequenceStats.colour_counts` (:func:`photo_colour_counts`; 3-channel photos).
    edges : bool
        Gather :attr:`SequenceStats.edge_tensor` (:func:`photo_edge_tensor`) from photos
        ``0, k, 2k, ...`` (at most :data:`EDGE_PHOTOS` of them), ``k = ceil(n_images / EDGE_PHOTOS)``
        (``k = 1`` when the length is unknown: the first :data:`EDGE_PHOTOS`).
    n_images : int, optional
        The whole sequence's length.
    buffers : dict, optional
        Arrays of :meth:`layout`'s shapes and types, by name, that the reductions are made in
        (e.g. the shared memory a worker process hands them over in: :meth:`stow` then copies
        nothing); an array without one of its shape and type is made as usual.
    """

    def __init__(self, colour: bool = True, edges: bool = True, n_images: int | None = None,
                 buffers: dict | None = None):
        self.colour, self.edges = bool(colour), bool(edges)
        self.buffers = buffers
        self.every = max(1, -(-int(n_images) // EDGE_PHOTOS)) if n_images else 1
        self.max = self.best = self.brightest = self.total = self.counts = self.tensor = None
        self.n = self.edge_photos = 0
        # the washed-out photos: (index, share) and their own reductions (used where every photo is)
        self.washed_out, self.washed = [], None
        self.levels = {}  # per photo index: the frame's level (SequenceStats.levels)

    def add(self, im, index: int | None = None, full_scale: float | None = None) -> None:
        """Add photo number ``index`` (default: the count so far) of the sequence.

        Parameters
        ----------
        im : (H, W, 3), (H, W, 1) or (H, W) float
            Linear photo (non-finite values count as 0).
        index : int, optional
        full_scale : float, optional
            The share of the photo's pixels at full scale (:func:`ffls.radiance.photos.full_scale_share`;
            None for a floating-point file): above :data:`WASHED_OUT_SHARE` the photo is kept apart.
        """
        i = self.n + len(self.washed_out) if index is None else int(index)
        if full_scale is not None and full_scale > WASHED_OUT_SHARE:
            if self.washed is None:
                self.washed = SequenceAccumulator(colour=False, edges=False)
            self.washed.add(im, i)
            self.washed_out.append((i, float(full_scale)))
            self.levels[i] = self.washed.levels[i]
            return
        im = np.asarray(im, dtype=np.float32)
        if not np.isfinite(im).all():
            im = np.nan_to_num(im, nan=0.0, posinf=0.0, neginf=0.0)
        if im.ndim == 3 and im.shape[2] >= 3:  # float32 luminance (Rec. 709), channel by channel: fast
            lum = im[..., 0] * np.float32(0.2126) + im[..., 1] * np.float32(0.7152) + im[..., 2] * np.float32(0.0722)
        else:
            lum = (im[..., 0] if im.ndim == 3 else im).astype(np.float32)
        self.levels[i] = _robust_peak(lum)
        if self.max is None:
            self.max = self._array("max", im.shape, np.float32)
            self.best = self._array("best", lum.shape, np.float32)
            self.brightest, self.total = (self._array("brightest", lum.shape, np.int32),
                                          self._array("total", lum.shape, np.float64))
            np.copyto(self.max, im)
            np.copyto(self.best, lum)
            self.brightest.fill(i)
            np.copyto(self.total, lum)  # (float32 into float64: exact)
            if self.colour and im.ndim == 3 and im.shape[2] >= 3:
                sub = lum[::COLOUR_STEP, ::COLOUR_STEP].shape
                self.counts = self._array("counts", (COLOUR_BINS, *sub), np.uint16)
                self.counts.fill(0)
            if self.edges:
                self.tensor = self._array("tensor", (EDGE_TENSOR_ROWS, *lum.shape), np.float32)
                self.tensor.fill(0)
        elif im.shape != self.max.shape:
            raise ValueError(f"image shapes differ: {im.shape} vs {self.max.shape}")
        else:
            np.maximum(self.max, im, out=self.max)
            up = lum > self.best
            self.brightest[up] = i
            self.best[up] = lum[up]
            self.total += lum
        if self.counts is not None and i < np.iinfo(np.uint16).max:  # no count can overflow
            photo_colour_counts(im, lum, self.counts)
        if self.tensor is not None and i % self.every == 0 and i // self.every < EDGE_PHOTOS:
            photo_edge_tensor(lum, self.tensor, peak=self.levels[i])
            self.edge_photos += 1
        self.n += 1

    def _array(self, name: str, shape: tuple, dtype) -> np.ndarray:
        """The buffer ``name`` where one of this shape and type was given, else a new array (both
        uninitialised: the caller fills it)."""
        buf = None if self.buffers is None else self.buffers.get(name)
        if buf is None or buf.shape != tuple(shape) or buf.dtype != np.dtype(dtype):
            return np.empty(shape, dtype)
        return buf

    #: The array attributes (:meth:`layout`, :meth:`stow`, :meth:`unstow`).
    ARRAYS = ("max", "best", "brightest", "total", "counts", "tensor")

    def layout(self, image_shape: tuple) -> dict:
        """``{name: (shape, dtype)}`` of the arrays that :meth:`add` makes for photos of
        ``image_shape`` ((H, W, 3) as read): e.g. buffers in shared memory for :meth:`stow`."""
        H, W = image_shape[:2]
        out = {"max": (tuple(image_shape), np.dtype(np.float32)), "best": ((H, W), np.dtype(np.float32)),
               "brightest": ((H, W), np.dtype(np.int32)), "total": ((H, W), np.dtype(np.float64))}
        if self.colour and len(image_shape) == 3 and image_shape[2] >= 3:
            out["counts"] = ((COLOUR_BINS, -(-H // COLOUR_STEP), -(-W // COLOUR_STEP)), np.dtype(np.uint16))
        if self.edges:
            out["tensor"] = ((EDGE_TENSOR_ROWS, H, W), np.dtype(np.float32))
        return out

    def stow(self, buffers: dict) -> "SequenceAccumulator":
        """Copy each array into the buffer of its name (where shape and dtype match) and drop it
        from this accumulator (self, cheap to pickle); :meth:`unstow` puts them back. A worker
        process hands its reductions over through shared memory instead of a pipe (28 MB per
        768 px chunk: pickling, the pipe and unpickling cost more than the copy)."""
        for name, buf in buffers.items():
            arr = getattr(self, name)
            if isinstance(arr, np.ndarray) and arr.shape == buf.shape and arr.dtype == buf.dtype:
                if arr is not buf:  # (made in it: nothing to copy)
                    np.copyto(buf, arr)
                setattr(self, name, _Stowed())
        self.buffers = None  # (not pickled with it)
        return self

    def unstow(self, buffers: dict, copy: bool = False) -> "SequenceAccumulator":
        """The arrays that :meth:`stow` put in ``buffers`` back (views of them, or ``copy``); returns self."""
        for name, buf in buffers.items():
            if isinstance(getattr(self, name), _Stowed):
                setattr(self, name, np.array(buf) if copy else buf)
        return self

    def merge(self, later: "SequenceAccumulator") -> "SequenceAccumulator":
        """Fold in ``later``, an accumulator of photos that all come after this one's (ties of the
        brightest photo go to the earlier photo); returns self."""
        if later.washed is not None:
            self.washed = later.washed if self.washed is None else self.washed.merge(later.washed)
            self.washed_out = self.washed_out + later.washed_out
        levels = {**self.levels, **later.levels}
        self.levels = levels
        if later.max is None:
            return self
        if self.max is None:
            washed, washed_out = self.washed, self.washed_out
            self.__dict__.update(later.__dict__)
            self.washed, self.washed_out, self.levels = washed, washed_out, levels
            return self
        if later.max.shape != self.max.shape:
            raise ValueError(f"image shapes differ: {later.max.shape} vs {self.max.shape}")
        np.maximum(self.max, later.max, out=self.max)
        up = later.best > self.best
        self.brightest[up] = later.brightest[up]
        self.best[up] = later.best[up]
        self.total += later.total
        if self.counts is not None and later.counts is not None:
            self.counts += later.counts
        if self.tensor is not None and later.tensor is not None:
            self.tensor += later.tensor
        self.n += later.n
        self.edge_photos += later.edge_photos
        return self

    def result(self) -> SequenceStats:
        """The :class:`SequenceStats` of the photos added (and merged); those of the washed-out
        photos where every photo is washed out."""
        if self.max is None:
            if self.washed is not None:
                return self.washed.result()
            raise ValueError("no images")
        tensor = self.tensor if self.n > 1 and self.edge_photos else None
        return SequenceStats(self.max, self.brightest, self.total / self.n, self.n, self.counts, tensor,
                             self.edge_photos if tensor is not None else 0, tuple(self.washed_out),
                             tuple(sorted(self.levels.items())))


def sequence_stats(images, colour: bool = True, edges: bool = True, n_images: int | None = None) -> SequenceStats:
    """The max image, the brightest photo, the mean luminance, the per-photo colour counts and the
    per-photo edge evidence, in one pass (a :class:`SequenceAccumulator` over ``images``).

    Parameters
    ----------
    images : as :func:`max_image`
        A single image is taken to be a max image already: no index, mean or colour counts; count 1.
    colour : bool
        Gather :attr:`SequenceStats.colour_counts` (:func:`photo_colour_counts`).
    edges : bool
        Gather :attr:`SequenceStats.edge_tensor` (:func:`photo_edge_tensor`), from every
        ``ceil(n_images / EDGE_PHOTOS)``-th photo (all when the count is unknown: the first
        :data:`EDGE_PHOTOS`).
    n_images : int, optional
        The length of ``images`` when it is an iterator.

    Returns
    -------
    SequenceStats
    """
    if isinstance(images, np.ndarray) and images.ndim in (2, 3) and not (images.ndim == 3 and images.shape[-1] not in (1, 3, 4)):
        return SequenceStats(max_image(images), None, None, 1)
    if n_images is None and hasattr(images, "__len__"):
        n_images = len(images)
    acc = SequenceAccumulator(colour, edges, n_images)
    for im in images:
        acc.add(im)
    return acc.result()


def extreme_images(images) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, int]:
    """Per-pixel maximum over a sequence, which photo gave it, the mean luminance and the count, in one pass.

    Parameters
    ----------
    images : as :func:`max_image`
        A single image is taken to be a max image already: no index (None), count 1.

    Returns
    -------
    mx : (H, W, 3) or (H, W) float32
        :func:`max_image`.
    brightest : (H, W) int32 or None
        Index of the photo with the highest luminance at each pixel (the first on ties).
    mean : (H, W) float64 or None
        Mean luminance over the photos (None for a single image).
    n : int
    """
    st = sequence_stats(images, colour=False, edges=False)
    return st.max, st.brightest, st.mean, st.n


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


def gradient_noise(g, sigma: float = 1.0) -> float:
    """Median Sobel gradient magnitude that pixel noise alone gives in ``g`` blurred by ``sigma``.

    Measured on the high-pass residual ``g - median3(g)``: for white noise its blurred gradient
    magnitude is 1/1.78 of the noise's own (measured on Gaussian noise of any level), while
    smooth scene content, shading and texture with features wider than a pixel, leaves almost
    nothing in it. Hence ``1.78 * median(|grad(blur(g - median3(g)))|)``.

    Parameters
    ----------
    g : (H, W) float
        Image (here the 8-bit log tone map).
    sigma : float
        The Gaussian blur applied before the gradient.
    """
    g32 = np.ascontiguousarray(g, dtype=np.float32)
    res = cv2.GaussianBlur((g32 - cv2.medianBlur(g32, 3)).astype(np.float64), (0, 0), sigma)
    gx = cv2.Sobel(res, cv2.CV_64F, 1, 0, ksize=3)
    gy = cv2.Sobel(res, cv2.CV_64F, 0, 1, ksize=3)
    return 1.78 * float(np.median(np.hypot(gx, gy)))


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
    # step gives an L2 Sobel magnitude of about 2.9 * 0.4 * s. Never below the noise: the
    # gradient of the pixel noise alone, measured on the image minus its 3x3 median (which keeps
    # the noise and drops the scene, textured grounds included; a textured tablecloth's own
    # gradients are not noise and must not raise the threshold above the spheres' outlines).
    gx = cv2.Sobel(blur, cv2.CV_64F, 1, 0, ksize=3)
    gy = cv2.Sobel(blur, cv2.CV_64F, 0, 1, ksize=3)
    mag = np.hypot(gx, gy)
    noise = gradient_noise(g8f, sigma)
    high = max(0.5 * scale, 8.0 * noise)
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


def _radius_from_edges(pts, grads, cpx, r_max, r_min: float = 3.0):
    """Apparent radius around a known centre: the peak of the radial-edge distance histogram.

    Counts are divided by the circumference (``2 pi r``), so the score is the fraction of each
    circle covered by radial edges, not how much clutter a large circle crosses; of the radii
    scoring at least 0.6 of the best, the largest is taken (the outline encloses whatever lies
    inside the sphere, e.g. a mirror's highlights). At least 8 edge points are needed.
    """
    v = pts - cpx
    d = np.hypot(v[:, 0], v[:, 1])
    cosr = np.abs(np.sum(v * grads, axis=1)) / np.maximum(d, 1e-9)
    sel = (cosr > 0.9) & (d >= max(r_min, 3)) & (d <= r_max)
    if sel.sum() < 8:
        return None
    hist = np.bincount(np.rint(d[sel]).astype(int), minlength=int(r_max) + 3).astype(np.float64)
    hist = np.convolve(hist, [1, 2, 1], mode="same")
    frac = hist / (4 * 2 * np.pi * np.maximum(np.arange(hist.size), 1.0))
    frac[hist < 32] = 0
    if not frac.max() > 0:
        return None
    return float(np.nonzero(frac >= 0.6 * frac.max())[0].max())


# ----------------------------------------------------------------------------- sub-pixel outline
@dataclasses.dataclass(frozen=True)
class _StepSearch:
    """One scale of :func:`step_edges`: the offsets ``t`` (pixels) along each profile, the candidate
    edge positions (pixels from the point) and the blurs (the step's Gaussian sigma, pixels)."""

    t: np.ndarray
    edges: np.ndarray
    blurs: np.ndarray


#: The scales of :func:`step_edges`. Sharp: 3 px either side every quarter pixel, the edge within
#: 1.5 px, blur sigma 0.3 (an aliased pixel step) to 1.7. Soft, for the profiles the sharp scale
#: finds blurred by 1.25 px or more (a defocused lens): 6 px either side every half pixel, the edge
#: within 3 px, sigma 1.25-4: a step blurred that much does not fit in the sharp window, and its
#: log edge lies 1-2 px toward the dark side.
STEP_SEARCHES = (
    _StepSearch(np.arange(-3.0, 3.0 + 1e-9, 0.25), np.arange(-1.5, 1.5 + 1e-9, 0.05),
                np.array([0.3, 0.45, 0.65, 0.9, 1.25, 1.7])),
    _StepSearch(np.arange(-6.0, 6.0 + 1e-9, 0.5), np.arange(-3.0, 3.0 + 1e-9, 0.1),
                np.array([1.25, 1.7, 2.3, 3.0, 4.0])),
)
#: Least radiance ratio across a step that :func:`step_edges` takes for an edge: the ratio that the
#: high threshold of :func:`edge_points` stands for (a white sphere's limb against a white ground,
#: 1.1 in the max image, is left to the photos' edges).
MIN_STEP_RATIO = 1.2
#: Least blur sigma (pixels, the median over an outline's steps in the photos' mean) for which the
#: outline's steps are fitted on the mean rather than the max image (:func:`_refine_on_profiles`): a
#: pixel's own footprint (a box, sigma 0.29 px, sampled bilinearly) fits the sharp scale's least
#: blurs, 0.3 px; beyond it the max of the photos is no blurred step (``benchmarks/blur_lights.py``).
SHARP_BLUR_PX = 0.45


def _step_design(t, e, s) -> np.ndarray:
    """(..., m, 4) design of the blurred-step model of :func:`step_edges` at offsets ``t`` (..., m),
    edges ``e`` and blurs ``s`` (broadcast): columns ``1 - Phi``, ``(t - e)(1 - Phi)``, ``Phi``,
    ``(t - e) Phi`` with ``Phi = Phi((t - e) / s)``."""
    from scipy.special import ndtr

    te = np.asarray(t) - e
    phi = ndtr(te / s)
    return np.stack([1 - phi, te * (1 - phi), phi, te * phi], axis=-1)


_PROJECTORS: dict = {}


def _step_projectors(k: int) -> np.ndarray:
    """(edges, blurs, m, m) residual projectors ``I - X X^+`` of :data:`STEP_SEARCHES` ``[k]``, made once."""
    if k not in _PROJECTORS:
        sc = STEP_SEARCHES[k]
        X = _step_design(sc.t, sc.edges[:, None, None], sc.blurs[None, :, None])  # (edges, blurs, m, 4)
        _PROJECTORS[k] = np.eye(sc.t.size) - X @ np.linalg.pinv(X)
    return _PROJECTORS[k]


def _fit_steps(Lf, P, U, k: int, noise: float, radius=None):
    """:func:`step_edges` at one scale ``k`` of :data:`STEP_SEARCHES`: the moved points (n, 2), whether
    each is an edge (n,), its fitted blur (n,) and whether its edge lies inside the search range (n,)."""
    sc = STEP_SEARCHES[k]
    t, n, m = sc.t, len(P), sc.t.size
    V = _bilinear(Lf, (P[:, None, :] + t[None, :, None] * U[:, None, :]).reshape(-1, 2)).reshape(n, m)
    flat = _step_projectors(k).reshape(-1, m)
    sse = np.empty((n, sc.edges.size, sc.blurs.size))
    for a in range(0, n, 256):  # v^T M v (M a symmetric projector), in chunks of profiles
        W = (V[a:a + 256] @ flat.T).reshape(-1, sc.edges.size, sc.blurs.size, m)
        sse[a:a + 256] = np.einsum("nijk,nk->nij", W, V[a:a + 256])
    best_s = np.argmin(sse.min(axis=1), axis=1)
    rows = np.arange(n)
    curve = sse[rows, :, best_s]  # (n, edges) at the best blur
    i = np.argmin(curve, axis=1)
    inner = (i > 0) & (i < sc.edges.size - 1)
    ic = np.clip(i, 1, sc.edges.size - 2)
    ym, y0, yp = (curve[rows, ic + d] for d in (-1, 0, 1))
    den = ym - 2 * y0 + yp
    off = np.where(den > 0, 0.5 * (ym - yp) / np.where(den > 0, den, 1.0), 0.0)
    e = sc.edges[ic] + np.clip(off, -1.0, 1.0) * (sc.edges[1] - sc.edges[0])
    s = sc.blurs[best_s]
    X = _step_design(t[None, :], e[:, None], s[:, None])  # (n, m, 4): the sides' levels at the edge
    coef = (np.linalg.pinv(X) @ V[:, :, None])[:, :, 0]
    r = V - np.einsum("nmk,nk->nm", X, coef)
    rms = np.sqrt(np.einsum("nm,nm->n", r, r) / m)
    lo, hi = np.minimum(coef[:, 0], coef[:, 2]), np.maximum(coef[:, 0], coef[:, 2])
    ok = inner & (hi - lo > 4.0 * np.maximum(rms, float(noise))) & (hi >= MIN_STEP_RATIO * np.maximum(lo, 0.0))
    if radius is not None:  # the half-way level of a blurred disc lies s^2 / 2r inside its edge
        e = e + s ** 2 / (2.0 * np.asarray(radius, dtype=np.float64))
    return P + e[:, None] * U, ok, s, inner


def step_edges(L, points, dirs, noise: float = 0.0, radius=None, clip: float | None = None, clip_image=None,
               with_blur: bool = False):
    """Sub-pixel edge of each radial profile: a blurred step between two sloped sides, fitted in linear radiance.

    Where the sphere meets its background, the image is a step blurred by the lens and the pixels:
    an anti-aliased pixel straddling the outline holds the *linear* mix of both sides, so the edge
    is where the linear radiance crosses half-way between them, whatever the blur. The maximum of
    the gradient of a log (or otherwise tone-mapped) image is not there: a log curve moves it
    toward the dark side (by 1-2 px under a defocus blur of 2-3 px), and a limb that shades off
    toward its edge (a matte sphere whose light grazes it, in one photo or in the max image) moves
    it inward, by 0.1-0.3 px on ``ffls synth`` renders. Along each profile ``v(t) = L(p + t u)``,
    the model

        ``v(t) = (a0 + a1 (t - e)) (1 - Phi((t - e) / s)) + (b0 + b1 (t - e)) Phi((t - e) / s)``

    (``Phi`` the standard normal CDF: a Gaussian-blurred step at ``e`` between two sides of their
    own level and slope) is fitted by least squares: linear in ``a0, a1, b0, b1``, searched over
    the edge ``e`` (refined by a parabola) and the blur ``s``, at the sharp scale of
    :data:`STEP_SEARCHES`, and again at the soft scale where the sharp one finds a blur of 1.25 px
    or more, or its best edge at the end of its range (a faint step stays faint at any scale).
    Where the edge is a circle of known ``radius`` (``dirs`` pointing out of it), the half-way
    crossing is moved out by ``s^2 / (2 radius)``: a Gaussian blur of a disc puts its half-way
    level that far inside the edge (to first order in the curvature).

    Parameters
    ----------
    L : (H, W) float
        Linear luminance.
    points : (n, 2) float
        Approximate edge points (x, y), pixels.
    dirs : (n, 2) float
        Unit directions across the edge (e.g. radial, outward).
    noise : float
        Pixel noise of ``L`` (standard deviation): a profile whose step ``|b0 - a0|`` is below 4
        times it, or below 4 times the fit's RMS residual, is not an edge; nor is one whose sides
        differ by a ratio below :data:`MIN_STEP_RATIO`.
    radius : float or (n,) float, optional
        Radius of curvature of the edge, pixels (``dirs`` pointing away from its centre).
    clip : float, optional
        The level at or above which ``L`` is clipped (an integer file's largest code): a profile
        that reaches it is not used (a clipped side's level, hence the half-way level, is unknown).
    clip_image : (H, W) float, optional
        The image whose profiles are checked against ``clip`` (default ``L``): the max image of the
        photos whose mean ``L`` is (a profile clipped in one photo is not a blurred step in the mean).
    with_blur : bool
        Return the fitted blurs too.

    Returns
    -------
    points : (n, 2) float64
        The edge points moved along ``dirs`` to the fitted step.
    ok : (n,) bool
        A step was found within the search range, with the contrast above.
    blur : (n,) float64
        With ``with_blur``: each step's fitted blur sigma, pixels (NaN where none was fitted).
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    U = np.asarray(dirs, dtype=np.float64).reshape(-1, 2)
    if len(P) == 0:
        return (P.copy(), np.zeros(0, dtype=bool)) + ((np.zeros(0),) if with_blur else ())
    Lf = np.asarray(L, dtype=np.float64)
    rad = None if radius is None else np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(P),))
    unclipped = np.ones(len(P), dtype=bool)
    if clip is not None:  # over the soft scale's window, the wider one
        t = STEP_SEARCHES[1].t
        C = Lf if clip_image is None else np.asarray(clip_image, dtype=np.float64)
        V = _bilinear(C, (P[:, None, :] + t[None, :, None] * U[:, None, :]).reshape(-1, 2)).reshape(len(P), -1)
        unclipped = V.max(axis=1) < clip
        if not unclipped.any():
            return (P.copy(), np.zeros(len(P), dtype=bool)) + ((np.full(len(P), np.nan),) if with_blur else ())
        P, U = P[unclipped], U[unclipped]
        rad = None if rad is None else rad[unclipped]
    Q, ok, s, inner = _fit_steps(Lf, P, U, 0, noise, rad)
    soft = (ok & (s >= STEP_SEARCHES[1].blurs[0])) | ~inner
    if soft.any():
        Qs, oks, ss, _ = _fit_steps(Lf, P[soft], U[soft], 1, noise, None if rad is None else rad[soft])
        Q[soft] = np.where(oks[:, None], Qs, Q[soft])
        s = s.copy()
        s[soft] = np.where(oks, ss, s[soft])
        ok[soft] = oks
    Q_all = np.asarray(points, dtype=np.float64).reshape(-1, 2).copy()
    ok_all = np.zeros(len(Q_all), dtype=bool)
    Q_all[unclipped], ok_all[unclipped] = Q, ok
    if not with_blur:
        return Q_all, ok_all
    s_all = np.full(len(Q_all), np.nan)
    s_all[unclipped] = np.where(ok, s, np.nan)
    return Q_all, ok_all, s_all


# ----------------------------------------------------------------------------- fitting
#: Inlier distance (pixels) of the start circle of a candidate's fit (:func:`_start_circle`).
START_TOL = 1.5


def _start_circle(pts, center, r_expected, tol=START_TOL):
    """Best-supported circle (centre (2,), radius) near a candidate, radius within 40 %, or None.

    :func:`ffls.spheres.mirror_outline.circle_search` (deterministic) with the centre within half
    the expected radius of ``center``.
    """
    found = circle_search(pts, center, 0.5 * r_expected, 0.6 * r_expected, 1.4 * r_expected, tol=tol)
    return (found[0][0], found[0][1]) if found else None


def _cone_residuals(params, s, f):
    """Signed distances (pixels) of the rays ``s`` (n, 3) from the cone ``params`` = f (x, y, alpha)."""
    return unit_cone_residuals(params, normalize(s), f)


def unit_cone_residuals(params, s, f):
    """Signed distances (pixels) of the unit rays ``s`` (n, 3; :func:`ffls.conventions.normalize`)
    from the cone ``params`` = f (x, y, alpha): the outline fit's residual.

    :func:`ffls.conventions.angle_between` written out for (n, 3) unit rows against one direction:
    the same operations in the same order (so the same floats), without normalising the rays
    again at every evaluation nor ``np.cross``'s general-axis overhead (the outline fits evaluate
    it tens of thousands of times per capture). The direction ``c`` is normalised twice as before
    (``c /= np.linalg.norm(c)``, whose 1-D path is the square root of ``c.dot(c)``, then
    :func:`ffls.conventions.normalize`, the squares summed in order) on three scalars: the same
    floats without the arrays' per-call overhead."""
    x, y, a = params / f
    v = np.array([x, y, 1.0])
    n = math.sqrt(v.dot(v))
    c0, c1, c2 = x / n, y / n, 1.0 / n
    n = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    c0, c1, c2 = c0 / n, c1 / n, c2 / n
    s0, s1, s2 = s[:, 0], s[:, 1], s[:, 2]
    x0 = s1 * c2
    x0 -= s2 * c1
    x1 = s2 * c0
    x1 -= s0 * c2
    x2 = s0 * c1
    x2 -= s1 * c0
    return f * (np.arctan2(np.sqrt(x0 * x0 + x1 * x1 + x2 * x2), s0 * c0 + s1 * c1 + s2 * c2) - a)


def unit_cone_jacobian(params, s, f):
    """Jacobian (n, 3) of :func:`unit_cone_residuals` with respect to ``params`` = f (x, y, alpha).

    With ``u = (x, y, 1)``, ``c = u / |u|`` and ``theta`` the angle of a unit ray ``s`` from ``c``,
    ``d theta / d u = -(s - (s . c) c) / (|u| sin theta)``; the residual ``f (theta - alpha)``
    gives ``-(s_k - (s . c) c_k) / (|u| sin theta)`` for the first two parameters and -1 for the
    third (``sin theta`` kept above 1e-12: a ray on the axis is no outline point)."""
    x, y, _ = params / f
    nu = math.sqrt(x * x + y * y + 1.0)
    c0, c1, c2 = x / nu, y / nu, 1.0 / nu
    s0, s1, s2 = s[:, 0], s[:, 1], s[:, 2]
    dot = s0 * c0 + s1 * c1 + s2 * c2
    x0 = s1 * c2 - s2 * c1
    x1 = s2 * c0 - s0 * c2
    x2 = s0 * c1 - s1 * c0
    scale = -1.0 / (nu * np.maximum(np.sqrt(x0 * x0 + x1 * x1 + x2 * x2), 1e-12))
    J = np.empty((len(dot), 3))
    np.multiply(s0 - dot * c0, scale, out=J[:, 0])
    np.multiply(s1 - dot * c1, scale, out=J[:, 1])
    J[:, 2] = -1.0
    return J


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
    p, inl = trimmed_fit(lambda q, pts: unit_cone_residuals(q, pts, f), p0, normalize(s), f_scale, trim,
                         jac=lambda q, pts: unit_cone_jacobian(q, pts, f))
    x, y, a = p / f
    if not (0 < a < np.pi / 2):
        raise ValueError("fitted apparent radius is not in (0, 90) degrees")
    c = np.array([x, y, 1.0])
    c /= np.linalg.norm(c)
    return R / np.sin(a) * c, inl, _cone_residuals(p, s, f)


def trimmed_fit(residuals, p0, pts, f_scale: float, trim: float, jac=None):
    """``least_squares`` with a ``soft_l1`` loss of scale ``f_scale`` on ``residuals(p, pts)``, then up
    to three rounds of trimming the points farther than ``max(trim * robust sigma, 1)`` and refitting
    on the rest. Returns the parameters and the inlier mask (n,) of the last round.

    The points are handed to ``residuals`` column-major (``np.asfortranarray``): both residuals
    read them column by column, elementwise, so the floats are the same and each column is
    contiguous (the evaluations, tens of thousands per capture, ran on strided columns)."""
    from scipy.optimize import least_squares
    p = p0
    pts = np.asfortranarray(pts)
    inl = np.ones(len(pts), dtype=bool)
    for _ in range(3):
        p = least_squares(residuals, p, jac="2-point" if jac is None else jac, args=(np.asfortranarray(pts[inl]),),
                          loss="soft_l1", f_scale=f_scale, x_scale=1.0, method="trf").x
        r = residuals(p, pts)
        sigma = 1.4826 * np.median(np.abs(r[inl])) + 1e-9
        new = np.abs(r) < max(trim * sigma, 1.0)
        if new.sum() < 3 or np.array_equal(new, inl):
            inl = new if new.sum() >= 3 else inl
            break
        inl = new
    return p, inl


def _circle_residuals(params, pts):
    return np.hypot(pts[:, 0] - params[0], pts[:, 1] - params[1]) - params[2]


def fit_circle(points, init_center, init_radius, f_scale: float = 1.0, trim: float = 3.0):
    """Robust circle fit in pixels: the outline of a sphere seen by an orthographic camera.

    Same loss and trimming as :func:`fit_sphere_center` (``soft_l1`` with scale ``f_scale``
    pixels, then up to three rounds of trimming at ``max(trim * robust sigma, 1 px)``).

    Parameters
    ----------
    points : (n, 2) float
        Candidate outline points, pixels.
    init_center : (2,) float
    init_radius : float

    Returns
    -------
    center : (2,) float64
    radius : float
    inliers : (n,) bool
    residuals : (n,) float64
        Signed distances of all points from the circle, pixels.
    """
    P = np.asarray(points, dtype=np.float64)
    p0 = np.array([init_center[0], init_center[1], init_radius], dtype=np.float64)
    p, inl = trimmed_fit(_circle_residuals, p0, P, f_scale, trim)
    if not p[2] > 0:
        raise ValueError("fitted radius is not positive")
    return p[:2].copy(), float(p[2]), inl, _circle_residuals(p, P)


def _coverage(points, center, n_bins=36):
    if len(points) == 0:
        return 0.0
    ang = np.arctan2(points[:, 1] - center[1], points[:, 0] - center[0])
    bins = np.floor((ang + np.pi) / (2 * np.pi) * n_bins).astype(int) % n_bins
    return float(np.unique(bins).size / n_bins)


# ----------------------------------------------------------------------------- candidates
def _score_circle(cx, cy, r, dt):
    """Edge support of a circle: the fraction of its in-image outline within 1.5 px of an edge.

    Returns ``(support, visible)``; ``visible`` is the fraction of the outline inside the image.
    Brightness is not scored: a sphere may be darker than a white background.
    """
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    H, W = dt.shape
    xs = cx + r * np.cos(t)
    ys = cy + r * np.sin(t)
    ok = (xs >= 0) & (xs <= W - 1) & (ys >= 0) & (ys <= H - 1)
    if not ok.any():
        return 0.0, 0.0
    d = dt[np.rint(ys[ok]).astype(int), np.rint(xs[ok]).astype(int)]
    return float(np.count_nonzero(d <= 1.5) / ok.sum()), float(ok.mean())


def _hough_candidates(g8, min_r, max_r, scale):
    """Circle candidates (m, 3) = (x, y, r) from OpenCV's Hough transforms on the log image.

    ``scale`` (levels per log unit, from :func:`_log8`) sets Hough's internal Canny threshold to
    a radiance ratio of about e^2 for ``HOUGH_GRADIENT_ALT`` (Scharr) and e for ``HOUGH_GRADIENT``.
    """
    return _hough_candidates_many([(g8, min_r, max_r, scale)])[0]


def _hough_calls(g8, min_r, max_r, scale, plain: bool = True, alt_calls: bool = True) -> list:
    """The three ``cv2.HoughCircles`` calls of :func:`_hough_candidates` on ``g8`` (zero-argument
    callables, each returning its circles (m, 3), the plain gradient's first 30; without
    ``plain``, the two ``HOUGH_GRADIENT_ALT`` calls only; without ``alt_calls``, the plain one only)."""
    blur = cv2.GaussianBlur(g8, (0, 0), 1.5)

    def alt(p2):
        return lambda: cv2.HoughCircles(blur, cv2.HOUGH_GRADIENT_ALT, dp=1.5, minDist=max(2 * min_r, 4),
                                        param1=1.0 * scale, param2=p2, minRadius=int(min_r), maxRadius=int(max_r))

    def gradient():
        c = cv2.HoughCircles(blur, cv2.HOUGH_GRADIENT, dp=1, minDist=max(2 * min_r, 4), param1=scale,
                             param2=20, minRadius=int(min_r), maxRadius=int(max_r))
        return None if c is None else c.reshape(-1, 3)[:30]

    return ([alt(0.8), alt(0.7)] if alt_calls else []) + ([gradient] if plain else [])


def _hough_candidates_many(images: list) -> list:
    """:func:`_hough_candidates` of each ``(g8, min_r, max_r, scale[, plain, alt_calls])`` of ``images``
    (:func:`_hough_calls`' arguments), its Hough
    transforms run concurrently in threads (OpenCV releases the GIL; each transform is
    independent and deterministic, so the circles are those of the calls made one by one)."""
    calls = [_hough_calls(*im) for im in images]
    flat = [c for cs in calls for c in cs]
    if len(flat) > 1 and (os.cpu_count() or 1) > 1:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=min(len(flat), os.cpu_count() or 1)) as ex:
            done = list(ex.map(lambda fn: fn(), flat))
    else:
        done = [fn() for fn in flat]
    out, k = [], 0
    for cs in calls:
        found = []
        for c in done[k:k + len(cs)]:
            if c is not None:
                found.extend(np.asarray(c).reshape(-1, 3).tolist())
        k += len(cs)
        out.append(np.array(found, dtype=np.float64).reshape(-1, 3))
    return out


# ----------------------------------------------------------------------------- camera of one search
@dataclasses.dataclass
class DetectionCamera:
    """What the stages need of the camera: pinhole (K, dist, f) or orthographic (pixels only)."""

    model: str
    K: np.ndarray | None
    dist: np.ndarray | None
    wfc: np.ndarray
    R: float
    shape: tuple

    @property
    def ortho(self) -> bool:
        return self.model == "orthographic"

    @property
    def f(self) -> float:
        return float(np.sqrt(self.K[0, 0] * self.K[1, 1]))


def _outline_circle_px(C, R, K, dist) -> tuple[np.ndarray, float]:
    """A sphere's projected centre (2,) and mean outline radius (pixels), as a SphereFit has them."""
    outline = silhouette_px(K, dist, C, R)
    cpx = project_points(np.asarray(C)[None], K, dist)[0]
    return cpx, float(np.mean(np.hypot(*(outline - cpx).T)))


def make_fit(C, R, K, dist, wfc, source, edge_px=None, residual=0.0, n_edge=0, n_in=0, coverage=1.0,
              shape=None):
    cpx, rpx = _outline_circle_px(C, R, K, dist)
    return SphereFit(
        center_cam=np.asarray(C, dtype=np.float64), center_world=to_world(C, wfc), radius=float(R),
        center_px=cpx, radius_px=rpx, residual_px=float(residual),
        n_edge_points=int(n_edge), n_inliers=int(n_in), inlier_fraction=float(n_in / n_edge) if n_edge else 1.0,
        coverage=float(coverage), source=source, edge_px=np.zeros((0, 2)) if edge_px is None else edge_px,
        K=K, dist=dist, world_from_camera=wfc,
        visible_fraction=1.0 if shape is None else outline_visible_fraction(silhouette_px(K, dist, C, R, n=360),
                                                                            shape))


def _make_fit_ortho(cpx, rpx, cam: DetectionCamera, source, edge_px=None, residual=0.0, n_edge=0, n_in=0, coverage=1.0):
    H, W = cam.shape
    cpx = np.asarray(cpx, dtype=np.float64)
    scale = cam.R / float(rpx)  # scene units per pixel
    C = np.array([(cpx[0] - (W - 1) / 2) * scale, (cpx[1] - (H - 1) / 2) * scale, 0.0])
    t = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    outline = cpx + float(rpx) * np.stack([np.cos(t), np.sin(t)], axis=1)
    return SphereFit(
        center_cam=C, center_world=to_world(C, cam.wfc), radius=cam.R, center_px=cpx, radius_px=float(rpx),
        residual_px=float(residual), n_edge_points=int(n_edge), n_inliers=int(n_in),
        inlier_fraction=float(n_in / n_edge) if n_edge else 1.0, coverage=float(coverage), source=source,
        edge_px=np.zeros((0, 2)) if edge_px is None else edge_px, K=None, dist=None, world_from_camera=cam.wfc,
        camera_model="orthographic", visible_fraction=outline_visible_fraction(outline, cam.shape))


def _centre_sigma_px(fun, p, args) -> float:
    """Standard error (pixels) of the centre of a fitted outline: the larger principal value of the
    covariance of the first two parameters (both in pixels), ``(J^T J)^-1 * rms^2``, with ``J``
    the forward-difference Jacobian of the residuals ``fun(p, *args)`` at the solution ``p``."""
    p = np.asarray(p, dtype=np.float64)
    r0 = fun(p, *args)
    n = r0.size
    if n <= p.size:
        return float("inf")
    J = np.empty((n, p.size))
    for i in range(p.size):
        dp = np.zeros_like(p)
        dp[i] = 1e-3
        J[:, i] = (fun(p + dp, *args) - r0) / 1e-3
    try:
        cov = np.linalg.inv(J.T @ J) * float(r0 @ r0) / (n - p.size)
    except np.linalg.LinAlgError:
        return float("inf")
    return float(np.sqrt(max(np.linalg.eigvalsh(cov[:2, :2]).max(), 0.0)))


def fit_outline(P, cam: DetectionCamera, c0_px, r0_px, source, n_edge=None, rays=None):
    """One sphere fitted to outline points ``P`` (m, 2) around a circle start; ``ValueError`` if it fails.

    The fit's ``center_sigma_px`` is the standard error of its centre (:func:`_centre_sigma_px`).
    ``rays`` (m, 3), optional: ``pixel_rays(P, cam.K, cam.dist)`` where the caller has them
    (pinhole; each point's ray is undistorted on its own, so a subset's are the same floats).
    """
    return outline_solved(P, cam, c0_px, r0_px, rays).fit(cam, source, n_edge)


@dataclasses.dataclass
class _OutlineSolution:
    """The robust fit of :func:`fit_outline` before its bookkeeping (:meth:`fit`): what a round of
    :func:`fit_until_stable` needs to place its band (``center_px``, ``radius_px``,
    ``center_cam``), the rest (visible share, coverage, centre's standard error) made only for
    the round it returns."""

    P: np.ndarray
    inl: np.ndarray
    res: np.ndarray
    center_px: np.ndarray
    radius_px: float
    center_cam: np.ndarray | None = None  # pinhole
    rays: np.ndarray | None = None  # pinhole: the points' rays

    @property
    def rms(self) -> float:
        """RMS distance (pixels) of the inliers from the outline: the fit's ``residual_px``."""
        return float(np.sqrt(np.mean(self.res[self.inl] ** 2)))

    def fit(self, cam: DetectionCamera, source, n_edge=None) -> SphereFit:
        P, inl, rms = self.P, self.inl, self.rms
        if cam.ortho:
            c, r = self.center_px, self.radius_px
            ft = _make_fit_ortho(c, r, cam, source, edge_px=P[inl], residual=rms, n_edge=n_edge or len(P),
                                 n_in=int(inl.sum()), coverage=_coverage(P[inl], c))
            ft.center_sigma_px = _centre_sigma_px(_circle_residuals, [c[0], c[1], r], (P[inl],))
            return ft
        C, f, s = self.center_cam, cam.f, self.rays
        ft = make_fit(C, cam.R, cam.K, cam.dist, cam.wfc, source, edge_px=P[inl], residual=rms,
                       n_edge=n_edge or len(P), n_in=int(inl.sum()),
                       coverage=_coverage(P[inl], project_points(C[None], cam.K, cam.dist)[0]), shape=cam.shape)
        d = C / np.linalg.norm(C)
        p = f * np.array([d[0] / d[2], d[1] / d[2], np.arcsin(min(cam.R / np.linalg.norm(C), 1.0))])
        ft.center_sigma_px = _centre_sigma_px(_cone_residuals, p, (s[inl], f))
        return ft


def outline_solved(P, cam: DetectionCamera, c0_px, r0_px, rays=None) -> _OutlineSolution:
    """The robust fit of :func:`fit_outline` (``ValueError`` if it fails), its bookkeeping left
    to :meth:`_OutlineSolution.fit`."""
    if cam.ortho:
        c, r, inl, res = fit_circle(P, c0_px, r0_px)
        return _OutlineSolution(P, inl, res, np.asarray(c, dtype=np.float64), float(r))
    f = cam.f
    K_und = np.array([[f, 0, cam.K[0, 2]], [0, f, cam.K[1, 2]], [0, 0, 1]])
    c0 = pixel_rays(np.asarray(c0_px, dtype=np.float64)[None], K_und)[0]
    edge_ray = pixel_rays((np.asarray(c0_px, dtype=np.float64) + [r0_px, 0])[None], K_und)[0]
    a0 = float(angle_between(c0, edge_ray))
    s = pixel_rays(P, cam.K, cam.dist) if rays is None else rays
    C, inl, res = fit_sphere_center(s, cam.R, f, c0, a0)
    cpx, rpx = _outline_circle_px(C, cam.R, cam.K, cam.dist)
    return _OutlineSolution(P, inl, res, cpx, rpx, np.asarray(C, dtype=np.float64), s)


# ----------------------------------------------------------------------------- hints
def stated_circle_problem(center_px, radius_px, shape) -> str | None:
    """What is wrong with a circle stated in pixels (a hint's or probe.json's ``center_px`` and
    ``radius_px``) for a photo of ``shape`` (H, W, ...), or None: a radius larger than the photo, or
    a circle that no pixel (their centres at integer coordinates) falls inside (a radius under 1 px
    holds at most one: a probe was refused blaming the photo). The text follows
    "the circle " (e.g. "(500, 80) px, radius 60 px, lies wholly outside the photo (160x160 px)")."""
    cx, cy = (float(v) for v in center_px)
    r = float(radius_px)
    h, w = shape[:2]
    if r > max(h, w):
        return (f"({cx:.0f}, {cy:.0f}) px, radius {r:.0f} px, is larger than the photo ({w}x{h} px): a circle measured "
                "in the photo has a radius of at most its size")
    if np.hypot(max(-0.5 - cx, 0.0, cx - (w - 0.5)), max(-0.5 - cy, 0.0, cy - (h - 0.5))) >= r:
        return f"({cx:.0f}, {cy:.0f}) px, radius {r:.0f} px, lies wholly outside the photo ({w}x{h} px)"
    if r < 1 or np.hypot(cx - min(max(round(cx), 0), w - 1), cy - min(max(round(cy), 0), h - 1)) >= r:
        return (f"({cx:.1f}, {cy:.1f}) px, radius {r:.3g} px, holds " + ("at most one pixel" if r < 1 else
                "no pixel's centre") + ": a ball in a photo is several pixels across")
    return None


def _parse_hint(h, cam: DetectionCamera):
    """(center_px (2,), radius_px or None, center_cam or None, projected radius or None) from one hint dict.

    A hint giving both a pixel circle and a world centre must agree: the projected world centre
    within half a radius (+2 px) of ``center_px``, and a ``radius_px`` within a factor 1.5 of the
    projected radius.
    """
    K, dist, R = cam.K, cam.dist, cam.R
    px = rpx = Cc = None
    if "center_px" in h:
        px = np.asarray(h["center_px"], dtype=np.float64).reshape(2)
        rpx = float(h.get("radius_px") or 0) or None
        why = None if rpx is None else stated_circle_problem(px, rpx, cam.shape)
        if why:
            raise ValueError(f"the circle {why}")
    if "center" in h or "center_world" in h or "center_cam" in h:
        if cam.ortho:
            raise ValueError("a world centre hint needs a pinhole camera (camera.K); give 'center_px' for an "
                             "orthographic camera")
        if "center_cam" in h:
            Cc = np.asarray(h["center_cam"], dtype=np.float64).reshape(3)
        else:
            Cw = np.asarray(h.get("center", h.get("center_world")), dtype=np.float64).reshape(3)
            T = np.linalg.inv(cam.wfc)
            Cc = T[:3, :3] @ Cw + T[:3, 3]
        if Cc[2] <= R or np.linalg.norm(Cc) <= R:
            raise ValueError(f"hinted centre {np.round(Cc, 4).tolist()} (camera frame) is not in front of the camera")
        wpx = project_points(Cc[None], K, dist)[0]
        wr = float(np.mean(np.hypot(*(silhouette_px(K, dist, Cc, R) - wpx).T)))
        if px is not None:
            if np.hypot(*(px - wpx)) > 0.5 * wr + 2 or (rpx is not None and not 1 / 1.5 <= rpx / wr <= 1.5):
                raise ValueError(f"its pixel circle ({px[0]:.0f}, {px[1]:.0f}) px"
                                 f"{f', radius {rpx:.0f} px' if rpx else ''} disagrees with its world centre, "
                                 f"which projects to ({wpx[0]:.0f}, {wpx[1]:.0f}) px, radius {wr:.0f} px")
        else:
            px = wpx
            # the radius comes from the image for a world hint (searched within a factor 4 of the
            # projected one): a wrong sphere_radius must not steer the search
            rpx = wr if "center_cam" in h else None
        return px, rpx, Cc, wr
    if px is None:
        raise ValueError(f"a sphere hint needs 'center' [x, y, z] or 'center_px' [u, v], got keys {sorted(h)}")
    return px, rpx, Cc, None


def _check_duplicate_circles(circles, what, source) -> None:
    """Two hints (or hinted fits) for the same circle: centres closer than half the mean radius."""
    for i in range(len(circles)):
        for j in range(i + 1, len(circles)):
            (xi, yi, ri), (xj, yj, rj) = circles[i], circles[j]
            if np.hypot(xi - xj, yi - yj) < 0.5 * (ri + rj) / 2 + 1:
                raise InputError(f"spheres[{i}] and spheres[{j}] {what} the same sphere, at pixel ({xi:.0f}, {yi:.0f});"
                                 f" hints conflict: give one hint per sphere", source)


# ----------------------------------------------------------------------------- main entry
def find_spheres(images, K, dist, sphere_radius, n_spheres: int | None = None, hints=None, overrides=None,
                 world_from_camera=None, scene_center=None, source: str | os.PathLike | None = None,
                 max_residual_px: float = 1.5, min_coverage: float = 0.3,
                 lit_limb: float | None = 0.65, camera_model: str = "pinhole", brightest_index=None,
                 n_photos: int | None = None, min_visible: float = 0.6, mean_luminance=None,
                 saturates: bool = False, colour_counts=None, edge_tensor=None,
                 edge_photos: int | None = None, workers: int = 1, retry_hints: bool = True,
                 seeds=None) -> Spheres:
    """Find the reference spheres and their centres: any number, with or without hints.

    The stages of the module docstring, one function each: the max (and min) image
    (:func:`_max_luminance`), its edges (:func:`edge_map`), candidate circles
    (:func:`_fit_hints` or :func:`hough_circle_candidates`), a fit per candidate
    (:func:`fit_candidates`: the tangent cone for a pinhole camera, a circle for an orthographic
    one), the choice of the spheres (:func:`ffls.spheres.select.select_spheres` without hints, :func:`_check_hinted_fits`
    with hints), the lit-limb refit (:func:`_refine_on_lit_limb`) and the scale check
    (:func:`_check_radius`).

    Parameters
    ----------
    images : (H, W, 3) float, (N, H, W, 3) float, or an iterable of (H, W, 3) float
        Linear radiance. A sequence is reduced to its per-pixel maximum and minimum
        (:func:`extreme_images`); a single image is used as the max image.
    K : (3, 3) float or None
        Camera matrix (None for an orthographic camera).
    dist : (k,) float or None
        OpenCV distortion coefficients.
    sphere_radius : float or None
        Radius of the spheres, scene units. Optional for an orthographic camera (then 1: the
        centres are in sphere radii; directions need no scale).
    n_spheres : int, optional
        How many spheres there are (``capture.json`` ``sphere_count``): the best ``n_spheres``
        candidates that pass the criteria are kept, and fewer is an error. None: every
        candidate that passes.
    hints : list of dict, optional
        One per sphere: ``{"center": [x, y, z]}`` (world), ``{"center_cam": [...]}`` or
        ``{"center_px": [u, v]}`` with an optional ``"radius_px"``. Only edges near each hinted
        outline are used. Two hints for the same sphere, a count that disagrees with the hints, or
        a pixel and a world centre that disagree are errors.
    overrides : list of dict, optional
        Sphere centres to use as they are (``{"center": ...}`` world or ``{"center_cam": ...}``);
        detection is skipped (pinhole only).
    world_from_camera : (4, 4) float, optional
        Defaults to :data:`ffls.conventions.DEFAULT_WORLD_FROM_CAMERA`.
    scene_center : (3,) float, optional
        World scene centre (default the origin); with the camera's position it gives the scene
        scale that catches a wrong ``sphere_radius``.
    source : path, optional
        Named in error messages (the capture folder or the images).
    max_residual_px, min_coverage : float
        Quality limits for hinted spheres: RMS outline residual (pixels) and outline coverage
        (fraction of the visible outline). Unhinted candidates need coverage 0.6 (:data:`CRITERIA`).
    lit_limb : float or None
        Refit each chosen sphere on its directly lit limb (:func:`_refine_on_lit_limb`); None: no refit.
    camera_model : {'pinhole', 'orthographic'}
    brightest_index : (H, W) int, optional
        Per pixel, the photo that is brightest there (:func:`extreme_images`), when ``images`` is
        already a max image (enables the shading-change criterion).
    n_photos : int, optional
        Photos behind a max image given directly (for messages and the shading criterion).
    mean_luminance : (H, W) float, optional
        Mean luminance over the photos (:func:`extreme_images`), when ``images`` is already a max
        image: with 3 or more photos, circles are also proposed on :func:`shading_ratio`, where a
        textured ground's albedo cancels.
    saturates : bool
        The photos are integer files that clip at their largest code: pixels with a channel at
        or above :func:`ffls.spheres.select.clip_levels` carry no colour evidence for the
        neutrality criterion (a saturated red ball reads white). False for floating-point images.
        Used only without per-photo colour evidence.
    colour_counts : (COLOUR_BINS, H, W) int, optional
        Per-photo colour evidence (:func:`photo_colour_counts`), when ``images`` is already a max
        image; gathered from ``images`` when they are a sequence. With it, colour is judged per
        photo (:func:`ffls.spheres.select.photo_neutrality`), not on the max image.
    edge_tensor : (3, H, W) float, optional
        Per-photo edge evidence (:func:`photo_edge_tensor`), when ``images`` is already a max
        image; gathered from ``images`` when they are a sequence. With it each sphere found is
        refitted on the edges that hold in the photos (:func:`_refine_on_consistent_edges`).
    edge_photos : int, optional
        How many photos gave ``edge_tensor`` (default ``n_photos``).
    min_visible : float
        A sphere cut by the frame edge is used when at least this fraction of its outline is
        inside the image; otherwise it is set aside (``Spheres.rejected``), or an error when hinted.
    workers : int
        Processes (forked) that fit the candidate outlines, which are independent: the same
        spheres for any number (1: in this process).
    retry_hints : bool
        A hint whose outline's centre is poorly constrained is tried again (:func:`_fit_hints`);
        False keeps the first fit, refused where it is poorly constrained (a probe stated to be a
        mirror ball, :func:`ffls.probes.locate.locate_sphere`).
    seeds : Spheres, optional
        The spheres found before on other values of the same photos (an unstated capture's stored
        codes, before its curve is known): without hints, when each was fitted on the max image's
        edges (:func:`seeded_circles`), their circles are fitted again on these images' edges,
        chosen and refined as the search's candidates are, instead of searched again (the Hough
        transforms and the photo-edge search); their ``rejected`` lines are kept. Where the seeded
        fits do not give as many spheres, the full search.

    Returns
    -------
    Spheres
        A list of :class:`SphereFit`, sorted left to right by ``center_px`` x (hints keep their
        order), with ``.rejected``: one line per round outline set aside, with the reason.

    Raises
    ------
    InputError
        All-black images; no sphere found (the message says where ffls looked and how to give a
        hint); fewer spheres than ``n_spheres``; conflicting hints; a hinted sphere cropped too
        much or whose outline does not fit a sphere; a ``sphere_radius`` inconsistent with the scene.
    """
    if camera_model not in CAMERA_MODELS:
        raise ValueError(f"camera_model must be one of {CAMERA_MODELS}, not {camera_model!r}")
    ortho = camera_model == "orthographic"
    wfc = DEFAULT_WORLD_FROM_CAMERA if world_from_camera is None else np.asarray(world_from_camera, dtype=np.float64)
    if ortho and sphere_radius is None:
        R = 1.0
    else:
        try:
            R = float(sphere_radius)
        except (TypeError, ValueError):
            R = float("nan")
        if not (np.isfinite(R) and R > 0):
            raise InputError(f"sphere_radius must be a positive number, got {sphere_radius!r}", source)
    if ortho:
        K = dist = None
    else:
        if K is None:
            raise InputError("a pinhole camera needs camera.K in capture.json (or declare "
                             "\"camera\": {\"model\": \"orthographic\"})", source)
        K, dist = camera_arrays(K, dist)
    if n_spheres is not None and (isinstance(n_spheres, bool) or int(n_spheres) != n_spheres or n_spheres < 1):
        raise InputError(f"sphere_count must be a positive integer, got {n_spheres!r}", source)
    if hints and n_spheres is not None and int(n_spheres) != len(hints):
        raise InputError(f"sphere_count is {int(n_spheres)} but {len(hints)} spheres are listed; hints conflict: "
                         f"give one hint per sphere, or remove sphere_count", source)
    if overrides:
        if ortho:
            raise InputError("sphere overrides need a pinhole camera; give 'center_px' hints instead", source)
        return Spheres(_spheres_from_overrides(overrides, K, dist, wfc, R, source))
    mx, brightest, mean, L, n_img, colour, tensor = _max_luminance(images, source)
    if colour_counts is not None:
        colour = np.asarray(colour_counts)
    if edge_tensor is not None:
        tensor = (np.asarray(edge_tensor), int(edge_photos or n_photos or n_img))
    if tensor[0] is None:
        tensor = None
    if brightest_index is not None:
        brightest = np.asarray(brightest_index, dtype=np.int64)
    if mean_luminance is not None:
        mean = np.asarray(mean_luminance, dtype=np.float64)
    n_photos = int(n_photos) if n_photos is not None else n_img
    if not ortho:
        _check_scale(K, wfc, R, L.shape, source, scene_center)
    cam = DetectionCamera(camera_model, K, dist, wfc, R, L.shape)
    edges = edge_map(mx, L, source)
    # the edges that hold in the photos (None: a single image, or fewer than 3 photos), read once
    held = ConsistentEdges.of(*tensor) if tensor is not None and tensor[1] >= 3 else None
    # and whether those whose contrast changes with the light can be read (a mirror ball's silhouette
    # on a textured ground; the photo-edge search reads them too)
    with_changing = held is not None and len(tensor[0]) >= EDGE_TENSOR_ROWS
    rejected: list[str] = []
    ratio = shading_ratio(L, mean) if mean is not None and n_photos >= 3 else None
    # the max image's highlights (a chrome ball on a black ground shows nothing else), once
    hl = highlight_pixels(L, ratio, n_photos) if ratio is not None and brightest is not None else None
    if hints:
        hint_info = []
        for k, h in enumerate(hints):
            try:
                hint_info.append(_parse_hint(h, cam))
            except (ValueError, TypeError) as e:
                raise InputError(f"spheres[{k}]: bad sphere hint: {e}", source) from None
        # a stated circle whose outline does not show (chrome on black) is taken as stated
        near = _highlight_surroundings(hl)
        stated = {k: stated_fit(h[0], h[1], cam) for k, h in enumerate(hint_info) if h[1] is not None
                  and outline_unseen(h[0], h[1], edges, hl, near, brightest, n_photos, min_coverage)}
        seen_k = [k for k in range(len(hint_info)) if k not in stated]
        seen = [hint_info[k] for k in seen_k]
        fits, failures = _fit_hints(seen, edges, cam, L.shape, source, workers, retry_hints,
                                    seen_k) if seen else ([], [])
        if not failures:  # a centre alone, around which only highlights show: their cluster, not the ball
            for k, ft in zip(seen_k, fits):
                if hint_info[k][1] is None and outline_unseen(ft.center_px, ft.radius_px, edges, hl, near, brightest,
                                                              n_photos, min_coverage):
                    x, y = hint_info[k][0]
                    raise InputError(f"spheres[{k}]: around the hinted centre ({x:.0f}, {y:.0f}) px only highlights"
                                     f" show, no outline (a mirror ball on a black ground): its radius cannot be"
                                     f" measured; give the ball's circle, \"center_px\" and \"radius_px\"", source)
        fits = _with_consistent_edges(fits, held, L, cam, max_residual_px)
        mirror = [_is_mirror_outline(ft, L) for ft in fits]
        if any(mirror):  # a mirror's outline: on the changing edges where they decide, else grown as unhinted
            changing = ConsistentEdges.of(*tensor, centered=True) if with_changing else None
            refit = _with_changing_edges(fits, changing, L, cam, max_residual_px)
            grow = [m and r is f for m, r, f in zip(mirror, refit, fits)]
            if any(grow):
                grown = _hinted_mirror_outlines([f for f, g in zip(fits, grow) if g], edges, L, cam, ratio, workers)
                it = iter(_with_changing_edges(grown, changing, L, cam, max_residual_px))
                refit = [next(it) if g else r for r, g in zip(refit, grow)]
            fits = _on_changing_limb(refit, changing, L, mean, cam)
        if not failures:  # in the hints' order
            it = iter(fits)
            fits = [stated[k] if k in stated else next(it) for k in range(len(hint_info))]
        _check_hinted_fits(fits, failures, max_residual_px, min_coverage, min_visible, source)
        _check_duplicate_circles([(*ft.center_px, ft.radius_px) for ft in fits], "hints fit", source)
    else:
        hint_info = []
        changing = ConsistentEdges.of(*tensor, centered=True) if with_changing else None
        def search(start):
            """The candidates (the circles of ``start``, a :class:`Spheres`, fitted again; or
            Hough's and the photo edges' where none), their fits and the spheres chosen."""
            seeded = seeded_circles(start)
            cands = seeded or hough_circle_candidates(edges, L, ratio=ratio)
            fits, _ = fit_candidates(cands, edges, cam, 0.3, "auto", workers)
            n_cands = len(cands)
            fits = _with_outer_outlines(fits, edges, L, cam)  # a mirror's dark cap -> its silhouette
            if held is not None and not seeded:  # outlines the max image leaves out (white on white)
                more, n_more = _photo_edge_fits(fits, tensor, cam, max_residual_px, edges, held, workers, changing)
                # one the photos' edges outline precisely but leave open (a textured ground's patches
                # match the sphere's limb in some photos) is a circle the max image's Hough transform
                # may have missed among the texture's: it is fitted on the max image's edges too
                open_circles = [(*ft.center_px, ft.radius_px) for ft in more if not round_outline(ft, max_residual_px)]
                again, _ = fit_candidates(open_circles, edges, cam, 0.3, "auto", workers) if open_circles else ([], [])
                fits, n_cands = fits + more + again, n_cands + n_more
            # an outline the max image leaves open (a white sphere's top on a white ground) may close on the
            # photos' edges; a closed one is refitted only once chosen, so that no candidate (a textured
            # ground's circles hold in every photo too) gains from them a score that hides a real sphere
            open_ = [ft.coverage < CRITERIA["min_closed"] * ft.visible_fraction for ft in fits]
            refit = _with_consistent_edges([ft for ft, o in zip(fits, open_) if o], held, L, cam, max_residual_px)
            it = iter(refit)
            fits = [next(it) if o else ft for ft, o in zip(fits, open_)]
            fits, rejected = select_spheres(fits, mx, brightest, L, cam.ortho, n_photos, max_residual_px, min_visible,
                                            saturates=saturates, colour_counts=colour,
                                            max_over_mean=None if ratio is None else np.exp(ratio))
            if n_spheres is not None and len(fits) > n_spheres:
                fits = sorted(fits, key=lambda ft: -ft.score)[:int(n_spheres)]
            return seeded, fits, rejected, n_cands

        seeded, fits, rejected, n_cands = search(seeds)
        if seeded and (len(fits) != len(seeded) or not all(  # not the same spheres: searched
                any(np.hypot(*(np.subtract(ft.center_px, c[:2]))) < 1.0 and abs(ft.radius_px - c[2]) < 1.0
                    for c in seeded) for ft in fits)):
            seeded, fits, rejected, n_cands = search(None)
        if seeded:
            rejected = list(seeds.rejected)
        _check_enough_found(fits, n_spheres, rejected, L.shape, hl, brightest, n_photos, n_cands, source)
        fits = sorted(fits, key=lambda ft: ft.center_px[0])
    if lit_limb is not None:  # the spheres are chosen; refine each on its directly lit outline
        fits = [ft if ft.source in _UNREFINED_SOURCES or ft.outline_edges == PHOTO_EDGES
                else _refine_on_lit_limb(ft, L, cam, lit_limb) for ft in fits]
    if not hints:  # and on the edges that hold in the photos, where they fit better
        fits = _with_consistent_edges(fits, held, L, cam, max_residual_px)
        fits = _grown_on_changing_edges(fits, changing, L, cam, max_residual_px)  # a dark cap -> its silhouette
        fits = _with_changing_edges(fits, changing, L, cam, max_residual_px)
        # a cap whose outline crosses the silhouette -> the ring of the changing edges around it
        old = fits
        fits = _grown_on_changing_edges(fits, changing, L, cam, max_residual_px, rings=True)
        fits = list(with_max_image_rings(fits, edges, changing, L, cam, max_residual_px))
        # the radius at the changing band's outer edge, where no ring replaced the outline (a ring is
        # fitted on that band already: moved again, a checker ground's ball went 1.3 px long; moved
        # first, a lone 8-bit chrome ball's longer outline found a ring 4.7 px off)
        same = [k for k, (a, b) in enumerate(zip(old, fits)) if a is b]
        for k, ft in zip(same, _on_changing_limb([fits[k] for k in same], changing, L, mean, cam)):
            fits[k] = ft
        fits = _without_highlight_clusters(fits, rejected, L.shape, hl, brightest, n_photos, n_spheres, n_cands,
                                           source)
    # every outline's points moved to the step of the linear image; an integer file's clipped
    # pixels read its largest code, the max image's maximum (as select.clip_levels); on the photos'
    # mean where they are blurred beyond the pixel (_refine_on_profiles)
    clip = 0.98 * float(L.max()) if saturates else None
    M = np.asarray(mean, dtype=np.float64) if mean is not None and n_photos >= 3 else None
    noise, mean_noise = _pixel_noise(L), None if M is None else _pixel_noise(M)
    fits = [ft if ft.source in _UNREFINED_SOURCES
            else _refine_on_profiles(ft, L, cam, max_residual_px, noise, clip, mean=M, mean_noise=mean_noise)
            for ft in fits]
    if not ortho:
        _check_radius(fits, hint_info, wfc, R, source, scene_center)
    if len(fits) == 1 and fits[0].outline_gap_px > 0:  # a lone mirror ball: its centre's own sigma
        fits[0].outline_centre_sigma_px = _outline_centre_sigma(fits[0], fits[0].outline_gap_px, cam)
    return Spheres(fits, rejected)


def seeded_circles(seeds) -> list[tuple[float, float, float]]:
    """The circles ``(x, y, r)`` px of ``seeds`` (:class:`Spheres`) that :func:`find_spheres` fits
    again instead of searching: all of them when each is an unhinted candidate's outline (source
    ``"auto"``), else none (a mirror's outer outline, a stated circle: found by stages that the
    seeded fit skips)."""
    if not seeds or any(ft.source != "auto" for ft in seeds):
        return []
    return [(float(ft.center_px[0]), float(ft.center_px[1]), float(ft.radius_px)) for ft in seeds]


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
        fits.append(make_fit(C, R, K, dist, wfc, "override"))
    return fits


def _max_luminance(images, source):
    """Stage 1: the max image, the brightest-photo index and the mean luminance (None for a single image),
    luminance of the max, count, and the per-photo colour counts (:func:`sequence_stats`)."""
    try:
        st = sequence_stats(images)
    except ValueError as e:
        raise InputError(str(e), source) from None
    mx, brightest, mean, n = st.max, st.brightest, st.mean, st.n
    L = _luminance(mx)
    peak = float(L.max()) if L.size else 0.0
    if not np.isfinite(peak) or peak <= 0 or float(np.percentile(L, 99.9)) <= 1e-6 * max(peak, 1e-30):
        raise InputError("all images are black (no light on the spheres in any photo)", source)
    return mx, brightest, mean, L, n, st.colour_counts, (st.edge_tensor, st.edge_photos)


@dataclasses.dataclass
class _EdgeMap:
    """Stage 2's output: subpixel edge points, their gradients, the log image and the edge distance map."""

    points: np.ndarray  # (n, 2) x, y
    grads: np.ndarray  # (n, 2) unit, toward brighter
    log8: np.ndarray  # (H, W) uint8, :func:`_log8`
    scale: float  # 8-bit levels per natural-log unit of radiance
    distance: np.ndarray  # (H, W) float32: distance to the nearest edge pixel


def edge_map(mx, L, source) -> _EdgeMap:
    """Stage 2: edges of the max image (:func:`edge_points`) and the distance to them."""
    H, W = L.shape
    pts, grads = edge_points(mx)
    g8f, scale = _log8(L)
    edge_img = np.ones((H, W), np.uint8)
    if len(pts):
        edge_img[np.clip(np.rint(pts[:, 1]).astype(int), 0, H - 1),
                 np.clip(np.rint(pts[:, 0]).astype(int), 0, W - 1)] = 0
    return _EdgeMap(points=pts, grads=grads, log8=g8f.astype(np.uint8), scale=scale,
                    distance=cv2.distanceTransform(edge_img, cv2.DIST_L2, 3))


#: A centre-only pixel hint lies within this share of the radius of the ball's centre
#: (:func:`_circle_near_hint`): a click on the middle of the ball, not on its outline.
HINT_CENTRE_OFFSET = 0.25


def _hint_radius_range(hint, shape) -> tuple[float, float]:
    """The radii (pixels) searched around a centre-only hint: 3 px to half the photo's shorter
    side, or a factor 4 either side of a world hint's projected radius."""
    H, W = shape
    r_proj = hint[3]
    return (3.0, min(H, W) / 2) if r_proj is None else (r_proj / 4, min(4 * r_proj, max(H, W)))


def _circle_near_hint(pts, grads, cpx, r_min, r_max):
    """The round outline around a centre-only hint: (centre (2,), radius), or None.

    The search goes outward from the hint in bands of radius (a factor 1.5 each, ``r_min`` to
    ``r_max``); in each, :func:`ffls.spheres.mirror_outline.circle_search` takes the circle best
    supported per pixel of radius (a share of its circumference, not how much clutter a large
    circle crosses), its centre within :data:`HINT_CENTRE_OFFSET` of the radius of the hint, among
    the edge points whose gradient lies within 25 degrees of the direction from the hint (an
    outline's gradients point at its centre, which such a hint sees within 14.5 degrees of it). Of
    the bands' circles scoring at least 0.6 of the best, the largest is taken (the outline encloses
    whatever lies inside the sphere), as :func:`_radius_from_edges` does around a known centre,
    whose histogram spreads over 20 px of radius when the click is 10 px off a 60-px ball.
    """
    v = pts - cpx
    d = np.hypot(v[:, 0], v[:, 1])
    cosr = np.abs(np.sum(v * grads, axis=1)) / np.maximum(d, 1e-9)
    keep = (cosr > np.cos(np.radians(25.0))) & (d >= (1 - HINT_CENTRE_OFFSET) * r_min - START_TOL) \
        & (d <= (1 + HINT_CENTRE_OFFSET) * r_max + START_TOL)
    P = pts[keep]
    found = []
    lo = float(r_min)
    while lo < r_max:
        hi = min(1.5 * lo, float(r_max))
        for c, r, inl in circle_search(P, cpx, HINT_CENTRE_OFFSET * hi, lo, hi, tol=START_TOL, per_radius=True):
            found.append((np.count_nonzero(inl) / max(r, 1.0), r, c))
        lo = hi
    if not found:
        return None
    best = max(f[0] for f in found)
    _, r, c = max((f for f in found if f[0] >= 0.6 * best), key=lambda f: f[1])
    return c, r


def _fit_hints(hint_info, edges: _EdgeMap, cam: DetectionCamera, shape, source, workers: int = 1,
               retry: bool = True, index=None):
    """Stages 3 and 4 with hints: one circle per hint, fitted (:func:`fit_candidates`, search
    band 0.35 of the radius); returns the fits and the failures as that does, each failure's
    first item its hint's place in ``index``.

    A hint without a radius takes the radius of the edges around its centre
    (:func:`_radius_from_edges`). Where that fails, or its fit's centre is poorly constrained
    (standard error above ``CRITERIA['max_center_sigma_px']``), the hint is tried again: a
    centre-only one on the round outline found around it (:func:`_circle_near_hint`), fitted with
    both gradient polarities on its start circle's points only (``narrow``); the second fit is
    taken when it succeeds with a smaller standard error. A grey ball on a busy ground of its own
    brightness (``tests/test_probe_detect.py``) outlines in both polarities, and the search band
    holds the ground's edges: its first fit is 4-20 px off and poorly constrained. Without
    ``retry`` the first fit stands. ``index``: each hint's place in capture.json's list, for the
    messages (default: its place in ``hint_info``).
    """
    H, W = shape
    index = list(range(len(hint_info))) if index is None else list(index)
    limit = CRITERIA["max_center_sigma_px"]
    starts = []  # per hint: its start circle, or None
    for h in hint_info:
        cpx, rpx = h[0], h[1]
        cand = None if rpx is None else (float(cpx[0]), float(cpx[1]), float(rpx))
        if rpx is None:
            lo, hi = _hint_radius_range(h, shape)
            r0 = _radius_from_edges(edges.points, edges.grads, cpx, hi, lo)
            cand = None if r0 is None else (float(cpx[0]), float(cpx[1]), float(r0))
        starts.append(cand)
    # the hints' fits in one call, then the retries' in one (each call undistorts the image's
    # edge points once, and its workers share the circles)
    firsts = _fit_each([c for c in starts if c is not None], edges, cam, 0.35, "hint", workers)
    got = [firsts.pop(0) if c is not None else ([], []) for c in starts]
    agains = {}
    for k, h in enumerate(hint_info):
        first = got[k][0][0] if got[k][0] else None
        if retry and (first is None or first.center_sigma_px > limit):
            cpx, rpx = h[0], h[1]
            again = starts[k] if rpx is not None else None
            if rpx is None:
                lo, hi = _hint_radius_range(h, shape)
                near = _circle_near_hint(edges.points, edges.grads, cpx, lo, hi)
                again = None if near is None else (float(near[0][0]), float(near[0][1]), float(near[1]))
            if again is not None:
                agains[k] = again
    seconds = _fit_each(list(agains.values()), edges, cam, 0.35, "hint", workers, narrow=True)
    cands, fits, failures = [], [], []
    for k, h in enumerate(hint_info):
        cpx, cand = h[0], starts[k]
        if k in agains:
            first = got[k][0][0] if got[k][0] else None
            second = seconds.pop(0)[0]
            if second and (first is None or second[0].center_sigma_px < first.center_sigma_px):
                got[k], cand = (second, []), agains[k]
        if cand is None:
            raise InputError(f"spheres[{index[k]}]: no round outline found around the hinted centre ({cpx[0]:.0f}, "
                             f"{cpx[1]:.0f}) px (image {W}x{H}); check the hint or add 'radius_px'", source)
        cands.append(cand)
        fits += got[k][0]
        failures += [(index[k], *f[1:]) for f in got[k][1]]
    _check_duplicate_circles(cands, "hint", source)
    return fits, failures


def _fit_each(cands, edges: _EdgeMap, cam: DetectionCamera, search_tol, label, workers: int = 1,
              narrow: bool = False) -> list:
    """:func:`fit_candidates` of ``cands`` in one call, split per candidate: ``[(fits, failures)]``
    as a call on that candidate alone returns (one fit or one failure)."""
    if not cands:
        return []
    return [([], [d]) if isinstance(d, tuple) else ([d], [])
            for d in fit_candidates(cands, edges, cam, search_tol, label, workers, narrow, split=False)]


def shading_ratio(L_max, L_mean) -> np.ndarray:
    """``ln(max / mean)`` of the luminance over the photos, per pixel: an albedo-free image.

    Albedo multiplies every photo of a Lambertian pixel alike and cancels in the ratio, so a
    textured ground (a patterned tablecloth, wood, paper with print) becomes flat: its value
    depends on its normal (and shadows) only. A sphere's pixels face every way, so its outline
    stands out against the ground whatever the ground's pattern. Circles are proposed on it as
    well as on the max image (:func:`hough_circle_candidates`).

    Parameters
    ----------
    L_max, L_mean : (H, W) float
        Max and mean luminance over the photos.

    Returns
    -------
    (H, W) float64, >= 0
    """
    L_max = np.clip(np.nan_to_num(np.asarray(L_max, dtype=np.float64)), 0, None)
    L_mean = np.clip(np.nan_to_num(np.asarray(L_mean, dtype=np.float64)), 0, None)
    ref = float(np.percentile(L_max, 99.9)) if L_max.size else 1.0
    eps = max(1e-5 * ref, 1e-30)
    return np.log((L_max + eps) / (np.minimum(L_mean, L_max) + eps))


#: Least share of a candidate circle's outline within 1.5 px of a max-image edge (:func:`_score_circle`).
MIN_EDGE_SUPPORT = 0.35
#: Circles of radius up to this many pixels are also sought on the images upsampled
#: :data:`SMALL_CIRCLE_UPSAMPLE` times (:func:`hough_circle_candidates`): the Hough transforms'
#: 1.5 px blur and 1.5 px accumulator cells wash out a smaller outline (a 4.5 px sphere at the back
#: of a 96 px photo gave no circle at all). Only the plain gradient transform runs there: over so
#: few radii it costs little (0.3 s on a 1152 px image where the ``HOUGH_GRADIENT_ALT`` pair took
#: 53 s and the whole first pass 146 s, on the loaded 2-core build machine).
SMALL_CIRCLE_PX = 8.0
SMALL_CIRCLE_UPSAMPLE = 2


def hough_circle_candidates(edges: _EdgeMap, L, max_candidates: int = 60, ratio=None) -> list[tuple[float, float, float]]:
    """Stage 3 without hints: Hough circles scored by edge support, near-duplicates dropped.

    Circles are proposed on the log max image and, when ``ratio`` (:func:`shading_ratio`) is
    given, on it too (mapped to 8 bit by its robust peak; Hough's edge threshold a ratio step of
    half its peak); all are scored on the max image's edges.
    """
    H, W = L.shape
    if len(edges.points) < 10:
        return []
    images = [(edges.log8, 3, min(H, W) / 2, edges.scale)]
    if ratio is not None:
        peak = float(np.percentile(ratio, 99.5))
        if peak > 0:
            sc = 255.0 / peak
            images.append((np.clip(ratio * sc, 0, 255).astype(np.uint8), 3, min(H, W) / 2, 0.5 * sc))
    # small circles on the images upsampled too; Canny's threshold follows the per-pixel gradient
    u = SMALL_CIRCLE_UPSAMPLE
    small = [(cv2.resize(g8, None, fx=u, fy=u, interpolation=cv2.INTER_LINEAR), u * lo, u * SMALL_CIRCLE_PX, sc / u,
              True, False) for g8, lo, hi, sc in images if hi > lo and SMALL_CIRCLE_PX > lo]
    found = _hough_candidates_many(images + small)  # all the transforms at once
    hc = np.concatenate(found[:len(images)])
    # the outermost well-covered circle around each Hough centre too: a mirror ball's highlights and
    # reflections make inner circles that Hough may prefer to its faint outline
    outer = []
    for x, y, r in hc:
        r2 = _radius_from_edges(edges.points, edges.grads, np.array([x, y]), min(2.5 * r, min(H, W) / 2), 1.2 * r)
        if r2 is not None:
            outer.append((x, y, r2))
    hc = np.concatenate([hc, np.array(outer).reshape(-1, 3)])

    def scored_circles(circles):
        out = []
        for x, y, r in circles:
            support, visible = _score_circle(x, y, r, edges.distance)
            if support >= MIN_EDGE_SUPPORT and visible >= 0.4:
                out.append((support * min(visible / 0.8, 1.0), x, y, r))
        return out

    scored = scored_circles(hc)
    # the upsampled images' circles, back in the image's pixels (a resized pixel x's centre is the
    # image's (x + 0.5) / u - 0.5), where no circle of the first pass surrounds them: inside one
    # they are its texture or highlights (a glossy ball's cluster), not a sphere too small for it
    tiny = np.concatenate([c / u - [0.5 - 0.5 / u, 0.5 - 0.5 / u, 0.0] for c in found[len(images):]]
                          + [np.zeros((0, 3))])
    scored += [t for t in scored_circles(tiny)
               if not any(np.hypot(t[1] - x, t[2] - y) < r for _, x, y, r in scored)]
    scored.sort(key=lambda s: -s[0])
    cands = []  # drop near-duplicates only; overlapping circles are resolved after fitting
    for sc, x, y, r in scored:
        if not any(_same_circle((x, y, r), c) for c in cands):
            cands.append((x, y, r))
    return cands[:max_candidates]


def _same_circle(a, b, tol: float = 0.2) -> bool:
    """Whether circle ``a = (x, y, r)`` is a near-duplicate of ``b``: centre and radius within ``tol``
    (20 %) of ``a``'s radius."""
    return bool(np.hypot(a[0] - b[0], a[1] - b[1]) <= tol * a[2] and abs(a[2] - b[2]) <= tol * a[2])


#: Largest RMS (px) of an outline that only the photos' edges show (:func:`_photo_edge_fits`): the
#: residual at which :func:`outline_quality` halves. Its points are sub-pixel ridge maxima of an edge
#: that stands still in every photo, so a silhouette fits them to a fraction of a pixel (0.15-0.37 px
#: on the 12 white-ground spheres of docs/spheres.md); arcs of moving shadows and shading joined into
#: a circle fit loosely (0.50-0.75 px there), and one, under a near light, passed every other test.
PHOTO_EDGE_MAX_RESIDUAL_PX = 0.5


def _photo_edge_fits(fits, tensor, cam: DetectionCamera, max_residual_px: float, edges: _EdgeMap,
                     held: ConsistentEdges, workers: int = 1,
                     changing: ConsistentEdges | None = None) -> tuple[list, int]:
    """Stages 3-4 again on the edges that hold in the photos: round outlines the max image does not show.

    In the max image every pixel reads its best light, so a white matte sphere on a white ground
    is about as bright as the ground all round its silhouette (both face some light head-on): the
    max image has no edge there, Hough proposes no circle, and the sphere is never a candidate. In
    each photo, though, its limb and the ground behind it differ (which is brighter changes), so
    the per-photo edge evidence (:func:`consistent_edge_strength`; ``held``, read once by
    :func:`find_spheres`) outlines it in full. Circles are proposed by Hough's ``HOUGH_GRADIENT_ALT`` transforms
    on that strength (8 bit over its robust peak) and each worth a fit (:func:`circles_to_fit`: one
    per distinct start, none on a round outline already fitted) is fitted on the ridge points
    (:func:`consistent_edge_points`) near it (:func:`fit_on_consistent_edges`, refitted on
    the points near its own outline until they hold); it is kept when its RMS is at
    most :data:`PHOTO_EDGE_MAX_RESIDUAL_PX`. The same is done on the edges whose contrast changes
    with the light (``centered``, the gradient's covariance over the photos; ``changing``, read
    once by :func:`find_spheres`, or read here when None), where a textured ground's edges, the
    same in every photo, drop out.

    A fit that is a near-duplicate (:func:`_same_circle`) of a round outline already fitted on the
    max image is dropped (that outline is judged, and refitted on these edges, as before); of two
    near-duplicate fits here the better outline is kept. A fit from the changing edges, or one that
    overlaps an outline fitted on the max image, must have the max image's edge support that a
    Hough candidate needs (:data:`MIN_EDGE_SUPPORT`): changing edges also trace the envelope of
    cast shadows round an object's foot. The others join the candidates with ``outline_edges``
    :data:`PHOTO_EDGES`, so they must close :data:`ffls.spheres.select.CRITERIA`
    ``min_closed_photos`` of their outline, and are judged by the same criteria. Returns those fits
    and how many circles were proposed.

    The circles' fits are independent of each other and of the judging: with ``workers > 1`` they
    are made in that many forked processes (:func:`_forked_map`), then judged here in order, so the
    result is the same for any number.
    """
    round_ = [ft for ft in fits if round_outline(ft, max_residual_px)]
    # the edges that hold in the photos, then the ones whose contrast changes with the light (the
    # gradient's covariance: a textured ground's edges, the same in every photo, drop out of it)
    passes, images = [], []
    for centered in (False, True)[:1 + (len(tensor[0]) >= EDGE_TENSOR_ROWS)]:
        if centered and changing is None:
            changing = ConsistentEdges.of(*tensor, centered=True)
        ev = changing if centered else held
        H, W = ev.strength.shape
        peak = _robust_peak(ev.strength)
        if not peak > 0:
            continue
        sc = 255.0 / peak
        g8 = np.clip(ev.strength * sc, 0, 255).astype(np.uint8)
        # Hough's edge threshold: half the robust peak of the strength (as for the shading ratio);
        # only the ALT transform's well-formed circles: the plain gradient's 30 (of some 5,000 it
        # rates on a busy capture's strength) are mostly arcs of moving shadows, and the transform
        # and their fits were a quarter of the search's cost for no sphere found (docs/spheres.md)
        passes.append((centered, ev))
        images.append((g8, 3, min(H, W) / 2, 0.5 * sc, False))
    found = _hough_candidates_many(images)  # every pass's transforms at once
    proposed = [(k, x, y, r) for k, hc in enumerate(found) for x, y, r in hc]
    circles = circles_to_fit(proposed, [(*o.center_px, o.radius_px) for o in round_])
    global _photo_edge_context
    _photo_edge_context = (circles, [ev for _, ev in passes], cam)  # inherited by forked workers
    try:
        done = _forked_map(photo_edge_fit, len(circles), workers)
    finally:
        _photo_edge_context = None
    more = []
    for (p, *_), ft in zip(circles, done):
        centered = passes[p][0]
        if ft is None or ft.residual_px > PHOTO_EDGE_MAX_RESIDUAL_PX or any(
                _same_circle((*ft.center_px, ft.radius_px), (*o.center_px, o.radius_px)) for o in round_):
            continue
        # edges that change with the light also trace the envelope of moving cast shadows round
        # an object's foot, and such arcs join into circles that overlap the object's outline:
        # a circle only the changing edges show, or one overlapping an outline fitted on the max
        # image, must be one the max image's edges support as a Hough candidate's must (a
        # silhouette is an edge there; a textured ground's circles only crowd it out of Hough's
        # proposals, and the fit of a circle Hough put near it may be a loose one many times
        # its size). A white sphere on a white ground, which the max image does not outline,
        # overlaps none.
        overlaps = any(np.hypot(*(ft.center_px - o.center_px)) <= 0.8 * (ft.radius_px + o.radius_px)
                       for o in fits)
        if ((centered or overlaps)
                and _score_circle(*ft.center_px, ft.radius_px, edges.distance)[0] < MIN_EDGE_SUPPORT):
            continue
        ft.outline_edges = PHOTO_EDGES
        same = [k for k, o in enumerate(more)
                if _same_circle((*ft.center_px, ft.radius_px), (*o.center_px, o.radius_px))]
        if not same:
            more.append(ft)
        elif outline_quality(ft) > outline_quality(more[same[0]]):  # the better outline of the same circle
            more[same[0]] = ft
    return more, len(proposed)


#: Circles of one photo-edge pass whose centre distance plus radius difference is at most this
#: (px) are fitted once (:func:`circles_to_fit`): a tenth of the 1-pixel tolerance of the search
#: that starts each fit (:func:`_start_circle`).
SAME_START_PX = 0.1


def circles_to_fit(circles, round_) -> list:
    """The photo-edge circles ``[(pass, x, y, r)]`` worth a fit (:func:`_photo_edge_fits`), in order.

    Dropped: a circle within half the near-duplicate tolerance (:func:`_same_circle`, 10 % of its
    radius) of a round outline ``round_`` ``[(x, y, r)]`` already fitted on the max image, whose fit
    on the sphere's own ridge would be dropped as that outline's near-duplicate (its search keeps
    the centre within half a radius of the start; docs/spheres.md: no such fit kept on the 768 px
    captures); and a circle within :data:`SAME_START_PX` of an earlier one of its pass, which starts
    the same search (one fit per distinct circle).
    """
    out = []
    for c in circles:
        if any(_same_circle(c[1:], o, 0.5 * 0.2) for o in round_):
            continue
        if any(o[0] == c[0] and np.hypot(c[1] - o[1], c[2] - o[2]) + abs(c[3] - o[3]) <= SAME_START_PX
               for o in out):
            continue
        out.append(c)
    return out


#: ``(circles [(pass, x, y, r)], each pass's edge evidence (:class:`ConsistentEdges`), camera)`` of the running
#: :func:`_photo_edge_fits`, inherited by its forked workers.
_photo_edge_context: tuple | None = None


def photo_edge_fit(k: int):
    """Circle ``k`` of :data:`_photo_edge_context` fitted on its pass's ridge points
    (:func:`fit_on_consistent_edges`, refitted on the points near its own outline until they hold:
    a Hough circle a few pixels off is not searched again from its fit, which changed no sphere of
    the bench rows and cost 10-40 % of the detection, docs/spheres.md); None where there is no fit."""
    circles, evidence, cam = _photo_edge_context
    p, x, y, r = circles[k]
    # a fit over PHOTO_EDGE_MAX_RESIDUAL_PX is dropped (_photo_edge_fits): none is made of it
    return fit_on_consistent_edges(np.array([x, y]), float(r), evidence[p], cam, "auto",
                                   max_rms_px=PHOTO_EDGE_MAX_RESIDUAL_PX)


def _forked_map(fn, n: int, workers: int) -> list:
    """``[fn(k) for k in range(n)]``, made in ``workers`` forked processes where that is more than
    one (and the platform forks). ``fn`` reads what it shares from a module global set before the
    call, which the workers inherit: only ``k`` and the results are pickled. The same results, in
    the same order, for any number."""
    workers = max(1, min(int(workers), n))
    if workers > 1 and "fork" in _mp_methods():
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork")) as ex:
            return list(ex.map(fn, range(n), chunksize=max(1, n // (4 * workers))))
    return [fn(k) for k in range(n)]


def fit_candidates(cands, edges: _EdgeMap, cam: DetectionCamera, search_tol, label, workers: int = 1,
                    narrow: bool = False, split: bool = True):
    """Stage 4: per candidate circle, the sphere fitted to its outline edge points.

    Edge points within ``search_tol`` of the circle's radius, with a radial gradient of the
    majority polarity; a deterministic circle start (:func:`ffls.spheres.mirror_outline.circle_search`); :func:`fit_sphere_center` (pinhole) or
    :func:`fit_circle` (orthographic). With ``narrow`` both polarities are kept (a grey ball on a
    ground of its own brightness is brighter than the ground on its lit side and darker on its
    shadowed side) and the fit takes the points within ``2 START_TOL`` of the start circle only (a
    busy ground's edges fill the search band and pull a fit to all of them off the outline): the
    second try of a hint (:func:`_fit_hints`). Returns the fits and the failures ``(k, x, y, r, why)``.
    The candidates are independent: with ``workers > 1`` they are fitted in that many forked
    processes (the same fits, in the same order). Without ``split``: one list, each candidate's
    fit or failure in the candidates' order.
    """
    pts = edges.points
    if cam.ortho:
        und_all, K_und = pts, None
    else:
        f = cam.f
        K_und = np.array([[f, 0, cam.K[0, 2]], [0, f, cam.K[1, 2]], [0, 0, 1]])  # undistorted, square pixels
        und_all = project_points(pixel_rays(pts, cam.K, cam.dist), K_und, None) if len(pts) else pts
    context = _CandidateContext(list(cands), edges, cam, search_tol, label, und_all, K_und, narrow)
    global _candidate_context
    _candidate_context = context  # inherited by the forked workers (nothing pickled)
    try:
        done = _forked_map(_fit_candidate, len(context.cands), workers if len(pts) else 1)
    finally:
        _candidate_context = None
    if not split:
        return done
    fits = [d for d in done if not isinstance(d, tuple)]
    failures = [d for d in done if isinstance(d, tuple)]
    return fits, failures


def _mp_methods() -> list:
    import multiprocessing

    return multiprocessing.get_all_start_methods()


@dataclasses.dataclass
class _CandidateContext:
    """What every candidate fit of :func:`fit_candidates` shares."""

    cands: list
    edges: _EdgeMap
    cam: DetectionCamera
    search_tol: float
    label: str
    und_all: np.ndarray  # the edge points undistorted (square pixels), for the circle start
    K_und: np.ndarray | None
    narrow: bool = False  # both polarities, fitted on the start circle's points (:func:`fit_candidates`)


_candidate_context: _CandidateContext | None = None


def _fit_candidate(k: int):
    """Candidate ``k`` of the current :class:`_CandidateContext`: its SphereFit, or the failure
    ``(k, x, y, r, why)``."""
    ctx = _candidate_context
    cam, pts, grads, search_tol = ctx.cam, ctx.edges.points, ctx.edges.grads, ctx.search_tol
    cx, cy, r = ctx.cands[k]
    if len(pts) == 0:
        return (k, cx, cy, r, "no edges in the image")
    d = np.hypot(pts[:, 0] - cx, pts[:, 1] - cy)
    near = (d > (1 - search_tol) * r - 2) & (d < (1 + search_tol) * r + 2)
    radial = np.stack([pts[:, 0] - cx, pts[:, 1] - cy], axis=1) / np.maximum(d, 1e-9)[:, None]
    cosr = np.sum(radial * grads, axis=1)
    sel = near & (np.abs(cosr) > 0.7)
    if sel.sum() >= 3 and not ctx.narrow:  # majority polarity (bright sphere on dark ground: gradient inward)
        inward = sel & (cosr < 0)
        sel = inward if inward.sum() >= 0.5 * sel.sum() else sel & (cosr > 0)
    P = pts[sel]
    if len(P) < 8:
        return (k, cx, cy, r, f"only {len(P)} edge points")
    c_und = np.array([cx, cy]) if cam.ortho else project_points(pixel_rays(np.array([[cx, cy]]), cam.K, cam.dist),
                                                                  ctx.K_und, None)[0]
    circ = _start_circle(ctx.und_all[sel], c_und, r)
    if circ is None:
        return (k, cx, cy, r, "no circle through the edge points")
    if ctx.narrow:  # only the start circle's own points: a busy ground's edges in the band pull the fit
        on = np.abs(np.hypot(*(ctx.und_all[sel] - circ[0]).T) - circ[1]) <= 2 * START_TOL
        P = P[on]
        if len(P) < 8:
            return (k, cx, cy, r, f"only {len(P)} edge points on the outline")
    try:
        return fit_outline(P, cam, circ[0], circ[1], ctx.label)
    except ValueError as e:
        return (k, cx, cy, r, str(e))


def outline_quality(ft) -> float:
    """How well a fitted outline is supported: ``coverage / (1 + (residual_px / 0.5)^2)``.

    The fit-quality factor of the selection's score (:func:`ffls.spheres.select.select_spheres`):
    the share of the outline with edge support, discounted by the RMS distance of the points
    from the fitted outline (a 0.5-pixel RMS halves it).
    """
    return float(ft.coverage) * _rms_discount(ft)


def _rms_discount(ft) -> float:
    """The fit-quality discount of :func:`outline_quality`: ``1 / (1 + (residual_px / 0.5)^2)``."""
    return 1.0 / (1.0 + (float(ft.residual_px) / 0.5) ** 2)


def _with_outer_outlines(fits, edges: _EdgeMap, L, cam: DetectionCamera) -> list:
    """Each candidate grown to its outer outline (:func:`_outer_outline`); where a grown outline is
    the same circle (centre and radius within 15%) as a candidate fitted directly, the direct one is
    kept if it is round (RMS within ``CRITERIA['max_residual_px']``) and fits at least as well by
    the selection's outline quality, coverage / (1 + (RMS / 0.5 px)^2) (:func:`outline_quality`):
    a matte sphere's own closed outline beats its inner circles grown to it, while a mirror ball's
    dark cap fitted directly together with its contact shadow below (a wider circle, 1.4 px off,
    RMS 0.76 px) loses to the outer outline of its silhouette (RMS 0.47 px, same coverage).

    The circle of a mirror's limb steps stands in for a dark cap's outline only where *no* larger
    outline encloses the ball's dark cap (:func:`_outer_outline`). One ball gives several
    candidates (caps of several sizes); where one of them grew to an enclosing outline of the
    edges, a limb-step circle of the same ball from another candidate is dropped: its premise
    failed. At the top of a chrome ball the reflected horizon runs within a pixel of the limb, so
    the two steps merge into one that the step search puts inside the limb, and below the ball the
    lights' shadow edges run just outside it; both pull the step circle down (the lone 8-bit
    chrome ball of ``bench_conditions.py``: 1.8 px low, where its enclosing outline is 0.44 px off)."""
    grown, by_steps = zip(*[_outer_outline(ft, edges, L, cam) for ft in fits]) if fits else ((), ())
    enclosing = [g for g, s in zip(grown, by_steps) if g.source == OUTER_SOURCE and not s]

    def same(a, b):
        r = max(a.radius_px, b.radius_px)
        return np.hypot(*(a.center_px - b.center_px)) < 0.15 * r and abs(a.radius_px - b.radius_px) < 0.15 * r

    def better(d, g):  # a direct fit that is round (residual within the limit) and fits at least as well
        return outline_quality(d) >= outline_quality(g) and d.residual_px <= max(g.residual_px,
                                                                                 CRITERIA["max_residual_px"])

    grown = [g for g, s in zip(grown, by_steps) if not (s and any(same(g, e) for e in enclosing))]
    outer = [g for g in grown if g.source == OUTER_SOURCE]
    direct = [g for g in grown if g.source != OUTER_SOURCE]
    keep_outer = [g for g in outer if not any(same(g, d) and better(d, g) for d in direct)]
    keep_direct = [d for d in direct if not any(same(g, d) for g in keep_outer)]
    return keep_direct + keep_outer


#: Least share of its circumference a mirror ball's circle of reflectance steps must cover to replace a
#: dark cap's outline that no larger outline encloses (:func:`_outer_outline`).
MIRROR_STEP_COVERAGE = 0.75


def _hinted_mirror_outlines(fits, edges: _EdgeMap, L, cam: DetectionCamera, ratio=None, workers: int = 1) -> list:
    """Each hinted sphere outlined as a mirror ball's (:func:`_is_mirror_outline`) found as an
    unhinted one would be: the candidate circles of the search without hints
    (:func:`hough_circle_candidates`) whose centres lie within half the hinted fit's radius of
    its centre and whose radii are within a factor 2 of it are fitted and grown to their outer
    outlines (:func:`_with_outer_outlines`), with the hinted fit; the outer outline of the best
    :func:`outline_quality` within half a radius replaces the hinted fit where it fits better.
    A chrome ball's dark cap fitted from the hint alone is the reflected room's outline, inside
    the silhouette (the lone chrome ball of ``bench_conditions.py``: 2.0 px off, where the search
    without hints finds it 0.44 px off); the search's candidates, caps of several sizes, grow to
    its silhouette."""
    mirror = [_is_mirror_outline(ft, L) for ft in fits]
    if not any(mirror):
        return fits
    cands = hough_circle_candidates(edges, L, ratio=ratio)
    out = []
    for ft, m in zip(fits, mirror):
        c0, r0 = np.asarray(ft.center_px, dtype=np.float64), float(ft.radius_px)
        near = [c for c in cands if np.hypot(c[0] - c0[0], c[1] - c0[1]) < 0.5 * r0 and 0.5 * r0 < c[2] < 2 * r0]
        got = fit_candidates(near, edges, cam, 0.3, "auto", workers)[0] if m and near else []
        grown = [g for g in _with_outer_outlines(got + [ft], edges, L, cam) if g.source == OUTER_SOURCE
                 and np.hypot(*(g.center_px - c0)) < 0.25 * r0] if m else []
        best = max(grown, key=outline_quality, default=None)
        out.append(best if best is not None and outline_quality(best) > outline_quality(ft) else ft)
    return out


def _outer_outline(ft, edges: _EdgeMap, L, cam: DetectionCamera):
    """A candidate that is a dark cap (:func:`ffls.spheres.mirror_outline.dark_cap`) inside a larger
    outline the edges support (a mirror ball's reflected dark room inside its silhouette, :func:`ffls.spheres.mirror_outline.enclosing_circle`) is refitted on that outline,
    again until no larger one is supported (at most 3 times); its ``outline_sigma_px`` is the
    disagreement with the limb's reflectance step (:func:`ffls.spheres.mirror_outline.mirror_silhouette`).
    A dark cap that no larger outline encloses (or a candidate only a quarter of whose cap is dark:
    a chrome ball's cap also holds highlights and the table's reflection) is refitted on the circle of the limb's reflectance
    steps from 0.75 to 1.25 of its radius, when they cover :data:`MIRROR_STEP_COVERAGE` of it and
    fit better (:func:`outline_quality`, with the selection's support): under
    a chrome ball standing on a table the ball's lower half reflects the table and has no edge, and
    the cap's outline closes on the contact shadow instead (too low and too large).

    Returns ``(fit, by_steps)``: ``by_steps`` is True when the fit is that circle of limb steps
    (:func:`_with_outer_outlines` drops it where another candidate of the ball found an enclosing
    outline)."""
    cap = dark_cap(L, ft.center_px, ft.radius_px)
    if not cap and not dark_cap(L, ft.center_px, ft.radius_px, quantile=25.0):
        return ft, False
    for _ in range(3 if cap else 0):
        oc = enclosing_circle(edges.points, ft.center_px, ft.radius_px, shape=cam.shape)
        if oc is None:
            break
        try:
            ft = fit_outline(edges.points[oc.inliers], cam, oc.center, oc.radius, OUTER_SOURCE)
        except ValueError:
            break
    log_l = np.log(np.maximum(L, 1e-12))
    if ft.source != OUTER_SOURCE:  # no larger outline: the dark cap may include the contact shadow below
        sil = mirror_silhouette(log_l, ft.center_px, ft.radius_px, shape=cam.shape, min_shrink=0.75,
                                min_coverage=MIRROR_STEP_COVERAGE)
        if sil is None:
            return ft, False
        try:
            new = fit_outline(sil[0], cam, sil[1], sil[2], OUTER_SOURCE)
        except ValueError:
            return ft, False
        # kept only if it fits better and has the support the selection asks (its points are one per ray)
        if (outline_quality(new) <= outline_quality(ft)
                or new.n_inliers < CRITERIA["min_support"] * 2 * np.pi * new.radius_px * new.visible_fraction):
            return ft, False
        gap = 0.5 * float(np.hypot(np.linalg.norm(new.center_px - ft.center_px), new.radius_px - ft.radius_px))
        r_limb = limb_radius(log_l, new.center_px, new.radius_px)
        if r_limb is not None and abs(r_limb / new.radius_px - 1) <= 0.1:  # the radius of the limb, same centre
            new = _with_radius(new, r_limb, cam)
        new.outline_sigma_px = max(gap, MIRROR_OUTLINE_SIGMA_FLOOR_PX)
        new.outline_gap_px = gap
        return new, True
    r_limb = limb_radius(log_l, ft.center_px, ft.radius_px)
    if r_limb is not None and abs(r_limb / ft.radius_px - 1) <= 0.1:  # the radius of the limb, same centre
        ft = _with_radius(ft, r_limb, cam)
    ft.outline_sigma_px, ft.outline_gap_px = _outline_ambiguity(ft, log_l, cam)
    return ft, False


def _outline_ambiguity(ft, log_l, cam: DetectionCamera) -> tuple[float, float]:
    """A mirror outline's ambiguity (``SphereFit.outline_sigma_px``, pixels): half the gap (centre
    and radius) between it and the limb's reflectance step around it
    (:func:`ffls.spheres.mirror_outline.mirror_silhouette`, a second outline estimate: the
    reflected contrasts run inside the limb, the step at or just outside it), at least
    :data:`ffls.spheres.mirror_outline.MIRROR_OUTLINE_SIGMA_FLOOR_PX`;
    :data:`ffls.spheres.mirror_outline.MIRROR_OUTLINE_FLOOR_PX` without a step (no second estimate).
    Returned with the half gap itself (``SphereFit.outline_gap_px``; 0 without a step)."""
    sil = mirror_silhouette(log_l, ft.center_px, ft.radius_px, shape=cam.shape)
    if sil is None:
        return MIRROR_OUTLINE_FLOOR_PX, 0.0
    try:
        limb = fit_outline(sil[0], cam, sil[1], sil[2], OUTER_SOURCE)
    except ValueError:
        return MIRROR_OUTLINE_FLOOR_PX, 0.0
    gap = 0.5 * float(np.hypot(np.linalg.norm(limb.center_px - ft.center_px), limb.radius_px - ft.radius_px))
    return max(gap, MIRROR_OUTLINE_SIGMA_FLOOR_PX), gap


#: Angular sectors of an outline's points left out in turn by :func:`outline_jackknife_px`.
JACKKNIFE_SECTORS = 8


def outline_jackknife_px(ft, cam: DetectionCamera, sectors: int = JACKKNIFE_SECTORS) -> float:
    """The per-axis standard error (pixels) of an outline fit's centre by the delete-one-sector
    jackknife: ``ft.edge_px`` split into ``sectors`` equal angles around its centre, the outline
    refitted (:func:`fit_outline`) with each sector left out, and
    ``sqrt((k - 1) / k * sum |c_i - mean c|^2 / 2)`` over the ``k`` refits.

    A mirror ball's outline points are the edges of its reflections: their misfit is correlated
    along each arc and moves the centre by far more than the fit's covariance
    (``center_sigma_px``) says (0.03-0.1 px against actual 0.3-0.45 px on the bench's chrome
    balls); leaving out whole arcs measures how far the arcs' disagreement moves it. ``inf`` where
    fewer than 3 refits succeed."""
    P = np.asarray(ft.edge_px, dtype=np.float64).reshape(-1, 2)
    ang = np.arctan2(P[:, 1] - ft.center_px[1], P[:, 0] - ft.center_px[0])
    sector = np.minimum((ang + np.pi) / (2 * np.pi) * sectors, sectors - 1).astype(int)
    c = sector_jackknife_centres(P, sector, cam, ft.center_px, ft.radius_px, ft.source, 5)
    if len(c) < 3:
        return float("inf")
    k = len(c)
    return float(np.sqrt((k - 1) / k * np.sum((c - c.mean(axis=0)) ** 2) / 2.0))


def sector_jackknife_centres(points, sector, cam: DetectionCamera, center_px, radius_px, source,
                             min_keep: int) -> np.ndarray:
    """The centres (pixels, ``(g, 2)``) of the delete-one-group refits of an outline: for each
    distinct value of ``sector`` (one per point of ``points``, ``(m, 2)`` pixels) in ascending
    order, :func:`fit_outline` of the points outside it (started at ``center_px``,
    ``radius_px``), where at least ``min_keep`` remain and the refit succeeds. The jackknife of
    :func:`outline_jackknife_px` and :func:`ffls.probes.locate.limb_centre_uncertainty`, each
    with its own sectors and ``min_keep``."""
    centres = []
    for k in np.unique(sector):
        keep = sector != k
        if np.count_nonzero(keep) < min_keep:
            continue
        try:
            centres.append(fit_outline(points[keep], cam, center_px, radius_px, source).center_px)
        except ValueError:
            continue
    return np.asarray(centres, dtype=np.float64).reshape(-1, 2)


def _outline_centre_sigma(ft, half_gap: float, cam: DetectionCamera) -> float:
    """A mirror outline's centre uncertainty per axis (pixels) where a second estimate (the limb's
    step) measured it, its misfit included (``SphereFit.outline_centre_sigma_px``): the sector
    jackknife of its fit (:func:`outline_jackknife_px`), bounded above by ``half_gap`` (half the
    gap to the second estimate: where the two agree the misfit has not moved it further; where
    they disagree by more than the fit's own spread, the gap is not the centre's error: the step
    follows the reflected backdrop), and at least
    :data:`ffls.spheres.mirror_outline.MIRROR_OUTLINE_SIGMA_FLOOR_PX` (the measured population)."""
    return max(min(outline_jackknife_px(ft, cam), half_gap), MIRROR_OUTLINE_SIGMA_FLOOR_PX)


def _with_radius(ft, radius_px: float, cam: DetectionCamera):
    """The same sphere fit with its apparent radius set to ``radius_px`` and its centre's direction kept.

    Pinhole: the tangent cone's half-angle is scaled by ``radius_px / ft.radius_px`` (the apparent
    radius is proportional to it to within 0.1 % for a cone of 10 degrees) and the depth follows
    (``C = R / sin(alpha) c``); orthographic: the circle's radius. Fit statistics are kept.
    """
    if cam.ortho:
        new = _make_fit_ortho(ft.center_px, radius_px, cam, ft.source, edge_px=ft.edge_px, residual=ft.residual_px,
                              n_edge=ft.n_edge_points, n_in=ft.n_inliers, coverage=ft.coverage)
    else:
        C = np.asarray(ft.center_cam, dtype=np.float64)
        d = float(np.linalg.norm(C))
        alpha = np.arcsin(min(ft.radius / d, 1.0)) * radius_px / ft.radius_px
        if not 0 < alpha < np.pi / 2:
            return ft
        new = make_fit(cam.R / np.sin(alpha) * C / d, cam.R, cam.K, cam.dist, cam.wfc, ft.source, edge_px=ft.edge_px,
                        residual=ft.residual_px, n_edge=ft.n_edge_points, n_in=ft.n_inliers, coverage=ft.coverage,
                        shape=cam.shape)
    _carry_outline(new, ft).center_sigma_px = ft.center_sigma_px
    return new


def _carry_outline(new, ft):
    """``new`` (a refit of ``ft``) given ``ft``'s score and outline ambiguity: ``score``,
    ``outline_sigma_px``, ``outline_gap_px`` and ``outline_edges``."""
    new.score, new.outline_sigma_px, new.outline_gap_px = ft.score, ft.outline_sigma_px, ft.outline_gap_px
    new.outline_edges = ft.outline_edges
    return new


#: Edge points within this many pixels of a highlight pixel (:func:`highlight_pixels`) are the
#: highlight's own edges, not an outline (:func:`outline_unseen`).
HIGHLIGHT_EDGE_PX = 3


def _highlight_surroundings(hl):
    """(H, W) bool: the pixels within :data:`HIGHLIGHT_EDGE_PX` of a highlight pixel ``hl``
    (:func:`highlight_pixels`), whose edge points are the highlights' own; None without ``hl``."""
    if hl is None:
        return None
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * HIGHLIGHT_EDGE_PX + 1,) * 2)
    return cv2.dilate(hl.astype(np.uint8), k).astype(bool)


def outline_unseen(cpx, rpx, edges: _EdgeMap, hl, near, brightest, n_photos: int, min_coverage: float) -> bool:
    """Whether a stated circle (a hint's ``center_px`` and ``radius_px``) is a ball whose outline
    does not show: a chrome ball on a black ground, which mirrors black all round but its highlights.

    True when the circle holds the highlights (:func:`highlight_pixels`) of at least 3 photos and a
    quarter of them (a ball that reflects the lights), while the edge points of the max image that
    are not a highlight's own (farther than :data:`HIGHLIGHT_EDGE_PX` from one) cover less than
    ``min_coverage`` (a hinted fit's least) of the 36 angular bins of the hint's search band (0.35
    radii either side of the circle, as :func:`_fit_hints` searches): no fit there could pass
    :func:`_check_hinted_fits`, and a fit on the highlights' edges outlines their cluster, which
    lies well inside the ball (``docs/spheres.md``, "A chrome ball on a black ground").
    ``hl``: the max image's highlights (:func:`highlight_pixels`), None where the photos are too few
    to tell them; ``near``: their surroundings (:func:`_highlight_surroundings`).
    """
    if hl is None or brightest is None or n_photos < 3:
        return False
    H, W = hl.shape
    c = np.asarray(cpx, dtype=np.float64)
    yy, xx = np.nonzero(hl)
    inside = np.hypot(xx - c[0], yy - c[1]) <= rpx
    photos = np.unique(np.asarray(brightest)[yy[inside], xx[inside]]).size
    if photos < max(3, n_photos / 4):
        return False
    pts = edges.points
    if len(pts):
        ij = np.clip(np.rint(pts).astype(int), 0, [W - 1, H - 1])
        pts = pts[~near[ij[:, 1], ij[:, 0]]]
    d = np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1])
    band = pts[np.abs(d - rpx) <= 0.35 * rpx]
    return _coverage(band, c) < min_coverage


#: ``SphereFit.source`` of a hinted circle taken as stated: its outline does not show
#: (:func:`outline_unseen`), so no stage refits it.
STATED_SOURCE = "hint (as stated)"
#: ``SphereFit.source`` of the fits that no later stage refits (on the lit limb, on the profiles):
#: a circle the capture states (an override, a hint taken as stated) or a mirror's outer outline.
_UNREFINED_SOURCES = ("override", OUTER_SOURCE, STATED_SOURCE)


def stated_fit(cpx, rpx, cam: DetectionCamera) -> SphereFit:
    """The sphere whose outline is the circle ``cpx``, ``rpx`` (pixels) as stated: the tangent cone
    (pinhole) or the circle (orthographic) through 72 points of it, its ``outline_sigma_px`` the
    mirror outline's floor (:data:`ffls.spheres.mirror_outline.MIRROR_OUTLINE_FLOOR_PX`)."""
    t = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    P = np.asarray(cpx, dtype=np.float64) + float(rpx) * np.stack([np.cos(t), np.sin(t)], axis=1)
    ft = fit_outline(P, cam, cpx, rpx, STATED_SOURCE)
    ft.outline_sigma_px = MIRROR_OUTLINE_FLOOR_PX
    return ft


def unoutlined_highlights(hl, brightest, n_photos: int, gap_px: int = 5):
    """Where the photos' highlights gather with no round outline found: ``(x, y, extent_px, photos)``
    of the largest group, or None.

    A chrome ball on a black ground mirrors black all round but its highlights: no outline of it
    shows in the max image or the photos' edges, yet its highlights, each lit in one photo, gather
    on it. The pixels as bright as half the max image's maximum and lit in at most about two photos
    (``hl``, :func:`highlight_pixels`; None where the photos are too few) are joined within ``gap_px``;
    the group holding the most distinct brightest photos is returned when they are at least 3 and a
    quarter of the photos (its centroid, the largest distance of its pixels from it, the count).
    """
    if hl is None or brightest is None or n_photos < 3:
        return None
    if not hl.any():
        return None
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * gap_px + 1, 2 * gap_px + 1))
    n, lab = cv2.connectedComponents(cv2.dilate(hl.astype(np.uint8), k))
    best = None
    hy, hx = np.nonzero(hl)  # (once: each group's pixels are these, in the same order)
    labs = lab[hy, hx]
    for j in range(1, n):
        ys, xs = hy[labs == j], hx[labs == j]
        photos = int(np.unique(brightest[ys, xs]).size)
        if best is None or photos > best[3]:
            cx, cy = float(xs.mean()), float(ys.mean())
            best = (cx, cy, float(np.hypot(xs - cx, ys - cy).max()), photos)
    return best if best is not None and best[3] >= max(3, n_photos / 4) else None


def _without_highlight_clusters(fits, rejected, shape, hl, brightest, n_photos, n_spheres, n_cands, source):
    """The spheres found without hints, less those whose final outline has the highlights of
    ``CRITERIA["max_outside_highlights"]`` photos or more just outside it
    (:func:`ffls.spheres.select.photos_highlighted_around`, of the highlights ``hl``): the cluster of
    a chrome ball's highlights outlined inside the ball, whose own silhouette does not show (on a
    black ground). Judged on the
    final outlines: a cap that grows to its ball's silhouette on the changing edges (the calibration
    shot's chrome ball) holds its highlights once grown. Each one set aside is named first in
    ``rejected`` (it was chosen as a sphere); none left, or fewer than ``n_spheres``: the "no sphere found" line."""
    if hl is None or brightest is None or n_photos < 3:
        return fits
    keep = []
    for ft in fits:
        out = photos_highlighted_around(hl, brightest, ft)
        if out >= CRITERIA["max_outside_highlights"]:
            rejected.insert(0, f"round outline at pixel ({ft.center_px[0]:.0f}, {ft.center_px[1]:.0f}), radius"
                            f" {ft.radius_px:.0f} px: the highlights of {out} photos lie just outside it (1.1 to"
                            f" 1.6 radii): the outline of some of a mirror ball's highlights, not its silhouette")
        else:
            keep.append(ft)
    if len(keep) < len(fits):
        _check_enough_found(keep, n_spheres, rejected, shape, hl, brightest, n_photos, n_cands, source)
    return keep


def _check_enough_found(fits, n_spheres, rejected, shape, hl, brightest, n_photos, n_cands, source) -> None:
    """The "no sphere found" line (:func:`_not_found_message`) as an :class:`InputError` where
    ``fits`` holds no sphere, or fewer than ``n_spheres``; with none, it names the photos'
    highlights that gather in no outline (:func:`unoutlined_highlights`)."""
    if not fits or (n_spheres is not None and len(fits) < n_spheres):
        hls = None if fits else unoutlined_highlights(hl, brightest, n_photos)
        raise InputError(_not_found_message(fits, n_spheres, rejected, shape, n_photos, n_cands, hls), source)


def _not_found_message(fits, n_spheres, rejected, shape, n_photos, n_cands, highlights=None) -> str:
    H, W = shape
    found = (f"found {len(fits)} of {int(n_spheres)} spheres" if n_spheres is not None and fits
             else f"no sphere found (sphere_count {int(n_spheres)})" if n_spheres is not None else "no sphere found")
    photos = f"the max image of {n_photos} photos" if n_photos > 1 else "the image"
    aside = f"; set aside: {rejected[0]}" + (f" (and {len(rejected) - 1} more)" if len(rejected) > 1 else "") \
        if rejected else ""
    looked = (f"{found}: looked in {photos} ({W}x{H} px) for round outlines of radius 3 to {min(H, W) // 2} px"
              f" ({n_cands} candidate circles){aside}")
    if highlights is not None:  # a ball whose outline does not show is used from its stated circle
        x, y, e = highlights[:3]
        return (f"{looked}; the highlights of {highlights[3]} photos gather around pixel ({x:.0f}, {y:.0f})"
                f" (within {e:.0f} px) in no round outline: a mirror ball whose outline does not show against"
                f" its ground (chrome on black); give its circle in capture.json, \"spheres\": [{{\"center_px\":"
                f" [u, v], \"radius_px\": r}}] (r more than {e:.0f} px)")
    return (f"{looked}; give a hint in capture.json, e.g. "
            f"\"spheres\": [{{\"center_px\": [u, v]}}] or \"sphere_count\": n")


def _check_hinted_fits(fits, failures, max_residual_px, min_coverage, min_visible, source) -> None:
    """Stage 5 with hints: every hinted sphere must fit within the quality limits and be visible enough."""
    if failures:
        k, cx, cy, r, why = failures[0]
        raise InputError(f"spheres[{k}] near pixel ({cx:.0f}, {cy:.0f}): cannot fit its outline ({why})", source)
    for k, ft in enumerate(fits):
        where = f"spheres[{k}] near pixel ({ft.center_px[0]:.0f}, {ft.center_px[1]:.0f}), radius {ft.radius_px:.0f} px"
        if ft.visible_fraction < min_visible:
            raise InputError(f"{where}: cropped too much, only {ft.visible_fraction:.0%} of its outline is inside the"
                             f" image (needs {min_visible:.0%}); reframe, or remove this sphere's hint", source)
        if ft.center_sigma_px > CRITERIA["max_center_sigma_px"]:
            raise InputError(f"{where}: its centre is poorly constrained by the visible outline (standard error"
                             f" {ft.center_sigma_px:.2f} px > {CRITERIA['max_center_sigma_px']})", source)
        closed = ft.coverage / max(ft.visible_fraction, 1e-6)
        if ft.residual_px > max_residual_px or closed < min_coverage:
            raise InputError(f"{where}: outline does not fit a sphere (rms {ft.residual_px:.2f} px, coverage"
                             f" {closed:.0%} of the visible outline)", source)


#: The shortest focal length (a fraction of the photo's longer side) of a pinhole camera: a field
#: of view of 170 degrees across the photo, ``1 / (2 tan 85 deg)``.
MIN_FOCAL_FRACTION = 1.0 / (2.0 * np.tan(np.radians(85.0)))


def _scene_distance(wfc, scene_center) -> float:
    centre = np.zeros(3) if scene_center is None else np.asarray(scene_center, dtype=np.float64).reshape(3)
    with np.errstate(over="ignore"):  # a translation beyond any number is named by the caller
        return float(np.linalg.norm(wfc[:3, 3] - centre))  # camera to scene centre


def _check_scale(K, wfc, R, shape, source, scene_center=None):
    """Before any search: can a sphere of radius ``R`` be seen at the scene's distance at all?

    A sphere ``r`` px in radius lies about ``f R / r`` from the camera. Over every radius a photo
    can hold (1 px to its longer side) that distance must meet the band :func:`_check_radius`
    allows after the fit (a quarter to four times the camera's distance to the scene centre), and
    be a finite number: a radius or focal length off by many orders of magnitude (``1e308``) would
    otherwise overflow in every fit and be reported as "no sphere found".
    """
    f_lo, f_hi = float(min(K[0, 0], K[1, 1])), float(max(K[0, 0], K[1, 1]))
    h, w = shape[:2]
    cx, cy = float(K[0, 2]), float(K[1, 2])
    if not (-w <= cx <= 2 * w and -h <= cy <= 2 * h):
        raise InputError(f"camera.K in capture.json looks wrong: its principal point ({cx:g}, {cy:g}) px lies more "
                         f"than a photo's size outside the {w}x{h} photos", source)
    if f_lo < MIN_FOCAL_FRACTION * max(w, h):
        raise InputError(f"camera.K in capture.json looks wrong: a focal length of {f_lo:g} px would give the {w}x{h} "
                         f"photos a field of view over 170 deg, which no pinhole lens has (fisheye models are not "
                         f"supported)", source)
    with np.errstate(over="ignore"):
        near, far = f_lo * R / float(max(shape)), f_hi * R
    cam_dist = _scene_distance(wfc, scene_center)
    if not np.isfinite(cam_dist):
        raise InputError("camera.world_from_camera and scene_center in capture.json put the camera at a distance "
                         "beyond any number from the scene centre", source)
    if not (np.isfinite(near) and np.isfinite(far)):
        raise InputError(f"sphere_radius ({R:g}) and camera.K (focal length {f_hi:g} px) in capture.json put the "
                         f"spheres at a distance beyond any number: one of them is wrong", source)
    if cam_dist > 0 and (far < 0.25 * cam_dist or near > 4.0 * cam_dist):
        raise InputError(f"sphere_radius or camera.K in capture.json looks wrong: a sphere of radius {R:g} under a "
                         f"focal length of {f_hi:g} px, 1 to {max(shape)} px in radius in the photo, lies {near:.3g} to "
                         f"{far:.3g} from the camera, but the scene centre is at {cam_dist:.3g}", source)


def _check_radius(fits, hint_info, wfc, R, source, scene_center=None):
    """Catch a ``sphere_radius`` inconsistent with the scene scale (depth ratio outside 1/2..2)."""
    msg = "sphere_radius in capture.json looks wrong"
    for k, ft in enumerate(fits):
        if k < len(hint_info) and hint_info[k][2] is not None:
            ratio = ft.distance / float(np.linalg.norm(hint_info[k][2]))
            if not 0.5 <= ratio <= 2.0:
                raise InputError(f"{msg}: sphere {k} fits at {ft.distance:.3g} from the camera but its hinted"
                                 f" centre is at {np.linalg.norm(hint_info[k][2]):.3g} (radius {R:g})", source)
    cam_dist = _scene_distance(wfc, scene_center)
    if cam_dist > 0 and fits:
        ratio = np.median([ft.distance for ft in fits]) / cam_dist
        if not 0.25 <= ratio <= 4.0:
            raise InputError(f"{msg}: spheres fit at {np.median([ft.distance for ft in fits]):.3g} from the camera"
                             f" but the scene centre is at {cam_dist:.3g} (radius {R:g})", source)


def _refine_on_lit_limb(ft, L, cam: DetectionCamera, lit_limb, min_points: int = 8, min_coverage: float = 0.5):
    """Refit a found sphere on the part of its outline where the limb is directly lit.

    Where the limb is lit only by the ground bounce (the underside, above the sphere's own contact
    shadow) or never lit (azimuths the hand-held light did not visit), the max image fades
    gradually from the limb into a dark background and the edge lands inside the silhouette: on
    path-traced renders the centre moved up by 0.2-0.5 px and the distance grew by 0.3-0.8 %
    (docs/spheres.md, "Independent renders"). A directly lit limb is a sharp, high-contrast step.
    Edge points whose limb (1.5 px inside) is below ``lit_limb`` times the sphere's 95th
    percentile in the max image are dropped and the outline is refitted, if enough of it remains
    (``min_points``, ``min_coverage`` of the visible outline); otherwise the fit is returned unchanged.
    """
    P = ft.edge_px
    if P is None or len(P) < min_points:
        return ft
    cpx, r = ft.center_px, ft.radius_px
    rr = np.hypot(P[:, 0] - cpx[0], P[:, 1] - cpx[1])
    u = (cpx - P) / np.maximum(rr, 1e-9)[:, None]
    limb = _bilinear(L, P + 1.5 * u)
    rows, cols = disc_pixels(ft, L.shape, 0.8)
    if rows.size == 0:
        return ft
    keep = limb >= lit_limb * float(np.percentile(L[rows, cols], 95))
    if keep.sum() < min_points or keep.all() or _coverage(P[keep], cpx) < min_coverage * ft.visible_fraction:
        return ft
    try:
        new = fit_outline(P[keep], cam, cpx, r, ft.source, n_edge=ft.n_edge_points)
    except ValueError:
        return ft
    new.score = ft.score
    return new


def _pixel_noise(L) -> float:
    """Pixel noise (standard deviation) of an image: the MAD of its difference from its 3x3 median."""
    L32 = np.ascontiguousarray(np.nan_to_num(np.asarray(L, dtype=np.float64)), dtype=np.float32)
    return 1.4826 * float(np.median(np.abs(L32 - cv2.medianBlur(L32, 3))))


def _refine_on_profiles(ft, L, cam: DetectionCamera, max_residual_px: float, noise: float = 0.0, clip=None,
                        min_points: int = 8, mean=None, mean_noise: float = 0.0):
    """Refit a found sphere on its outline points moved to the step of a linear image (:func:`step_edges`).

    Each inlier outline point is moved along the ray from the fitted centre to where a blurred
    step between the sphere and its background, each side with its own level and slope, best fits
    the luminance profile of ``L``, the max image (pixel noise ``noise``, clipped at ``clip`` or
    never), or of ``mean``, the photos' mean luminance (noise ``mean_noise``; its profiles that
    reach ``clip`` in ``L`` are not used), where its steps are blurred by :data:`SHARP_BLUR_PX` or
    more (the median over the outline): the mean of blurred photos is their blurred mean, a
    blurred step; their maximum is not (the brighter photo on each side, a step sharper than the
    blur, off the outline by up to half a pixel: ``benchmarks/blur_lights.py``); points
    where it shows no usable step (a white sphere's top on a white ground, seen only in the
    photos' edges; a clipped limb) keep their place. The refit
    replaces the fit when it is round (RMS within ``max_residual_px``) and moves the outline by
    less than a pixel, or twice the steps' median blur sigma where that is more (the log edges
    move toward the dark side with the blur), centre and radius; otherwise the fit is returned
    unchanged.
    """
    P = ft.edge_px
    if P is None or len(P) < min_points:
        return ft
    c = np.asarray(ft.center_px, dtype=np.float64)
    v = P - c
    u = v / np.maximum(np.hypot(v[:, 0], v[:, 1]), 1e-9)[:, None]
    Q, ok, blur = step_edges(L if mean is None else mean, P, u, noise if mean is None else mean_noise,
                             radius=ft.radius_px, clip=clip, clip_image=L, with_blur=True)
    if mean is not None and not (ok.sum() >= min_points and np.median(blur[ok]) >= SHARP_BLUR_PX):
        Q, ok, blur = step_edges(L, P, u, noise, radius=ft.radius_px, clip=clip, with_blur=True)
    if ok.sum() < min_points:
        return ft
    Q = np.where(ok[:, None], Q, P)
    try:
        new = fit_outline(Q, cam, c, ft.radius_px, ft.source, n_edge=ft.n_edge_points)
    except ValueError:
        return ft
    # the log edges it starts from lie up to ~1 blur sigma toward the dark side (step_edges)
    reach = max(1.0, 2.0 * float(np.median(blur[ok])))
    if (new.residual_px > max_residual_px or np.hypot(*(new.center_px - c)) > reach
            or abs(new.radius_px - ft.radius_px) > reach):
        return ft
    _carry_outline(new, ft).outline_at_step = True
    return new


def _with_consistent_edges(fits, held: ConsistentEdges | None, L, cam: DetectionCamera, max_residual_px: float) -> list:
    """Every fitted candidate refitted on the per-photo edge evidence ``held`` (its ridge points)
    where it fits better (:func:`_refine_on_consistent_edges`); unchanged without the evidence
    (None: a single image, or fewer than 3 photos). A mirror ball (an outer outline, or
    a dark cap, :func:`ffls.spheres.mirror_outline.dark_cap`, on ``L``, the max image's luminance)
    is left as it is: its silhouette's contrast, the step of its reflectance, is the same in every
    photo as the reflected contrasts inside it; its outline is the max image's (:func:`_outer_outline`)."""
    if held is None or not fits:
        return fits
    return [ft if ft.source == OUTER_SOURCE or dark_cap(L, ft.center_px, ft.radius_px)
            else _refine_on_consistent_edges(ft, held, cam, max_residual_px) for ft in fits]


#: Band (radii, + 2 px) around a mirror ball's outline searched for its silhouette on the edges
#: that change with the light (:func:`_with_changing_edges`): the outline from the max image can be
#: 4 px off on a 27 px ball (a chrome ball on a textured ground, ``bench_conditions.py`` c18).
MIRROR_CHANGING_BAND = 0.2
#: How many times more of its outline a mirror ball's refit on the changing edges must have on them
#: than the outline it replaces (:func:`_with_changing_edges`, :func:`outline_support`).
MIRROR_CHANGING_GAIN = 1.5


def _is_mirror_outline(ft, L) -> bool:
    """A fit outlined as a mirror ball's: an outer outline (:func:`_outer_outline`) or a dark cap
    (:func:`ffls.spheres.mirror_outline.dark_cap`) on ``L``, the max image's luminance."""
    return ft.source == OUTER_SOURCE or dark_cap(L, ft.center_px, ft.radius_px)


def outline_support(ft, points, shape=None, tol: float = 1.0, n: int = 144, tree=None) -> float:
    """Share of a fitted sphere's outline within ``tol`` pixels of an edge point.

    The outline is sampled at ``n`` points (pinhole: the tangent cone's ellipse,
    :func:`silhouette_px`; orthographic: the circle); each counts when an edge point of ``points``
    ((m, 2) x, y) lies within ``tol`` of it. With the image ``shape`` (H, W) the share is of the
    samples in the frame. 0 without points or samples. ``tree``, optional: a
    ``scipy.spatial.cKDTree`` of ``points``, for a caller that measures several outlines on the
    same points (built here otherwise).
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if ft.camera_model == "orthographic":
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        P = np.asarray(ft.center_px, dtype=np.float64) + ft.radius_px * np.stack([np.cos(t), np.sin(t)], axis=1)
    else:
        P = silhouette_px(ft.K, ft.dist, ft.center_cam, ft.radius, n=n)
    if shape is not None:
        H, W = shape[:2]
        P = P[(P[:, 0] >= 0) & (P[:, 0] <= W - 1) & (P[:, 1] >= 0) & (P[:, 1] <= H - 1)]
    if len(pts) == 0 or len(P) == 0:
        return 0.0
    d, _ = (cKDTree(pts) if tree is None else tree).query(P, distance_upper_bound=tol + 1e-9)
    return float(np.mean(d <= tol))


def _with_changing_edges(fits, changing: ConsistentEdges | None, L, cam: DetectionCamera,
                         max_residual_px: float) -> list:
    """Each mirror ball's outline refitted on the edges whose contrast changes with the light,
    where the outline it has is not on them.

    A chrome ball's limb reflects the ground just behind it, so in the max image (and in each
    photo) its silhouette has only the contrast of its reflectance, which a textured ground's own
    edges drown: the outline from the max image follows the reflected contrasts inside the limb
    and the texture outside it (a chrome ball on ``ffls synth --background textured`` at 384 px:
    4.2 px off, radius 1.1 px short, 19 degrees of light direction). In the gradient's covariance
    over the photos (``changing``: :func:`consistent_edge_strength` ``centered``) the ground's
    texture drops out (its log contrast is its albedo's, the same under every light), while the
    ball's silhouette stays: the ball shows other parts of the scene, shadowed and lit at other
    times than the ground beside it, and the sky with the lights' highlights. The ridge points
    within :data:`MIRROR_CHANGING_BAND` radii (+ 2 px) of each mirror outline
    (:func:`_is_mirror_outline`) are searched for the best-supported circle and fitted
    (:func:`fit_on_consistent_edges`). The refit replaces the outline when it is round (RMS within
    ``max_residual_px``), moves the centre by less than a quarter of the radius, and has
    :data:`MIRROR_CHANGING_GAIN` times the share of its outline on the changing edges that the
    outline it replaces has (:func:`outline_support`, 1 px): the two outlines judged on the same
    evidence. Inside a chrome ball the changing edges also trace reflected circles; where the
    max image's outline already lies on the changing edges (0.53-0.65 of it on the renders of
    ``bench_conditions.py``, against 0.64-0.67 for the refit) the refit is one of several circles
    of equal support, and 1-2 sphere radii off in depth. Where it is replaced the old outline had
    0.25-0.42 of it, the refit 0.71-0.94. A refit's ``outline_sigma_px`` is its own ambiguity
    (:func:`_outline_ambiguity`), not the outline's it replaces. Unchanged without the evidence
    (None: fewer than 3 photos, or a tensor without the summed gradient).
    """
    def refit(ft, pts, tree):
        c0, r0 = np.asarray(ft.center_px, dtype=np.float64), float(ft.radius_px)
        new = fit_on_consistent_edges(c0, r0, changing, cam, ft.source, MIRROR_CHANGING_BAND)
        if (new is None or new.residual_px > max_residual_px or np.hypot(*(new.center_px - c0)) > 0.25 * r0
                or outline_support(new, pts, cam.shape, tree=tree)
                < MIRROR_CHANGING_GAIN * outline_support(ft, pts, cam.shape, tree=tree)):
            return None
        return new

    # a refit's ambiguity is its own, not the outline's it replaces (that one was the worse supported:
    # on the textured ground c18 its 2.66 px made the centre's sigma 2.74 px, the refit 0.51 px off)
    return mirror_outlines_replaced(fits, changing, L, cam, refit)


def mirror_outlines_replaced(fits, changing: ConsistentEdges | None, L, cam: DetectionCamera, refit,
                              photo_edges: bool = True) -> list:
    """``fits`` with each mirror ball's outline (:func:`_is_mirror_outline`, not an override)
    replaced by ``refit(fit, changing_points, tree)`` where that gives one (not None; ``tree`` a
    ``cKDTree`` of the points for :func:`outline_support`, built once): the replacement
    keeps the score, is marked as outlined on :data:`PHOTO_EDGES` (with ``photo_edges``: a refit on
    the photos' edges) and gets its own ambiguity (:func:`_outline_ambiguity`). Unchanged without
    the evidence (``changing`` None)."""
    if changing is None or not fits:
        return fits
    pts = changing.points[0]
    log_l = tree = None  # the image's log and the points' tree: made once, only where needed
    out = []
    for ft in fits:
        new = None
        if ft.source != "override" and _is_mirror_outline(ft, L):
            if tree is None:
                from scipy.spatial import cKDTree

                tree = cKDTree(np.asarray(pts, dtype=np.float64).reshape(-1, 2))
            new = refit(ft, pts, tree)
        if new is None:
            out.append(ft)
            continue
        if log_l is None:
            log_l = np.log(np.maximum(L, 1e-12))
        new.score = ft.score
        if photo_edges:
            new.outline_edges = PHOTO_EDGES
        new.outline_sigma_px, new.outline_gap_px = _outline_ambiguity(new, log_l, cam)
        out.append(new)
    return out


#: Largest change of a mirror ball's radius, as a share of it, that the outer edge of its band of
#: changing edges may make (:func:`_on_changing_limb`); beyond it the edge found is another one.
MIRROR_LIMB_MAX_CHANGE = 0.15


def _on_changing_limb(fits, changing: ConsistentEdges | None, L, mean, cam: DetectionCamera) -> list:
    """Each mirror ball's outline (:func:`_is_mirror_outline`, not an override) with its radius at
    the outer edge of the band of edges that change with the light
    (:func:`ffls.spheres.mirror_outline.changing_limb_radius`), its centre's direction kept
    (:func:`_with_radius`).

    Every mirror outline before this step follows the peak of an edge: of the max image's (the
    reflected room's contrasts), of the changing edges (:func:`_with_changing_edges`,
    :func:`_grown_on_changing_edges`), or the limb's reflectance step (:func:`limb_radius`). Inside
    a chrome ball the reflected scene is squeezed toward the rim, and the changing edges peak 0.5-1.5
    px inside the silhouette; where a lens and sensor integrate each pixel (anti-aliased, ``ffls
    synth --supersample 4``) the reflectance step fades too, and the outline came out 1.1-2.4 px
    short on 20-28 px balls (``benchmarks/mirror_outline_error.py``, docs/spheres.md). Taken when
    the radius changes by at most :data:`MIRROR_LIMB_MAX_CHANGE` of itself. A ball whose body is
    dark in ``mean`` (the sequence's mean luminance; :data:`ffls.spheres.mirror_outline.LIMB_DARK_BODY_RATIO`, as
    :func:`ffls.spheres.highlight.refine_view_limb` tells a glossy black ball) is left as it is:
    its silhouette is its own edge, the band's peak, and the outer edge lies outside it (an
    anti-aliased glossy ball: -0.23 -> +1.14 px). The centre, the fit statistics and the outline's
    ambiguity are kept. Unchanged without the evidence (``changing`` or ``mean`` None).
    """
    if changing is None or mean is None or not fits:
        return fits
    out = []
    for ft in fits:
        r = None
        if (ft.source != "override" and _is_mirror_outline(ft, L)
                and not dark_body(mean, ft.center_px, ft.radius_px)):
            r = changing_limb_radius(changing.strength, ft.center_px, ft.radius_px)
        if r is None or abs(r / ft.radius_px - 1.0) > MIRROR_LIMB_MAX_CHANGE:
            out.append(ft)
        else:
            out.append(_with_radius(ft, r, cam))
    return out


#: Least share of its outline on the changing edges (:func:`outline_support`) for a mirror ball's
#: outline grown on them (:func:`_grown_on_changing_edges`): a silhouette is a closed ring there.
MIRROR_GROWN_SUPPORT = 0.75


def _grown_on_changing_edges(fits, changing: ConsistentEdges | None, L, cam: DetectionCamera,
                             max_residual_px: float, max_steps: int = 3, rings: bool = False) -> list:
    """Each mirror ball's outline (:func:`_is_mirror_outline`) grown to the outermost circle the
    edges that change with the light support around it, where the max image's edges left it on a
    reflected circle inside the silhouette.

    A chrome ball reflects the room above it as a dark cap and the ground below it as ground: in
    the max image its lower silhouette has no edge where the reflected ground meets the ground
    beside it, and the enclosing circle of the max image's edges (:func:`_outer_outline`) is not
    found, so the ball is taken for its dark cap (``ffls synth --sphere-material mirror`` at 384
    px, seed 7, JPEG: 11.9 px off, radius 12.5 px short). Over the photos the inside of the ball
    changes otherwise than the ground beside it (the reflected shadows and highlights move with
    the light), and in the changing edges (:func:`consistent_edge_strength` ``centered``) the
    silhouette is a closed ring around the cap. The enclosing circle search
    (:func:`ffls.spheres.mirror_outline.enclosing_circle`) runs on their ridge points; the circle
    found is fitted (:func:`fit_outline`) and taken when it is round (RMS within
    ``max_residual_px``), at least :data:`MIRROR_GROWN_SUPPORT` of it lies on the changing edges
    and more than of the outline it replaces (:func:`outline_support`), repeated until no larger
    one is taken (at most ``max_steps``). The shadow edges of the many lights around a ball also
    make circles that enclose it; they are broken arcs, 0.34-0.62 of them on the changing edges,
    against 0.88-0.97 for a silhouette. Unchanged without the evidence (``changing`` None).

    With ``rings`` the circles tried are not the enclosing circle but every ring of the changing
    edges around the outline (:func:`_rings_around`), larger or smaller, that is not the same
    circle and not smaller, whose support discounted by its RMS as :func:`outline_quality` discounts
    coverage is higher than the outline's (a lone chrome ball lit from one side: a ring of the
    lights' shadow edges 4.7 px off, 0.76 of it on the changing edges at RMS 0.59 px, against the
    silhouette's 0.75 at 0.31 px); the best supported of those that pass the same tests is taken.
    A cap's outline whose
    top runs a pixel or two outside the silhouette has no enclosing circle, while the silhouette
    is the best-supported ring around it: 0.86-0.96 of it on the changing edges (a chrome ball on
    a checker ground, on a textured JPEG ground, near the frame's edge), where the rings around a
    right outline reach 0.76 (``bench_conditions.py``'s mirror and glossy balls), the same circle
    aside. :func:`find_spheres` runs it after the refit on the changing edges
    (:func:`_with_changing_edges`), on the outlines that refit did not replace as well.
    """
    def enclosing(cur, pts):
        oc = enclosing_circle(pts, cur.center_px, cur.radius_px, shape=cam.shape)
        if oc is None:
            return []
        try:
            return [fit_outline(pts[oc.inliers], cam, oc.center, oc.radius, OUTER_SOURCE)]
        except ValueError:
            return []

    def grow(ft, pts, tree):
        cur, cur_support, grown = ft, None, False  # the current outline's support, once measured
        for _ in range(max_steps):
            best = None
            for new in _rings_around(cur, pts, cam) if rings else enclosing(cur, pts):
                support = outline_support(new, pts, cam.shape, tree=tree)
                if new.residual_px > max_residual_px or support < MIRROR_GROWN_SUPPORT:
                    continue
                if cur_support is None:
                    cur_support = outline_support(cur, pts, cam.shape, tree=tree)
                # a ring against the outline: its support discounted by its RMS as the selection's
                # outline quality is (outline_quality: a ring of the lights' shadow edges, as well
                # supported but twice as rough, does not replace a silhouette)
                if rings and support * _rms_discount(new) <= cur_support * _rms_discount(cur):
                    continue
                if support > cur_support and (best is None or support > best[1]):
                    best = (new, support)
            if best is None:
                break
            cur, cur_support, grown = best[0], best[1], True
        return cur if grown else None

    return mirror_outlines_replaced(fits, changing, L, cam, grow)


#: A mirror outline's rings (:func:`_rings_around`): their centres within this many of its radii of
#: its centre, their radii within :data:`MIRROR_RING_RADII` times its radius.
MIRROR_RING_OFFSET = 0.5
MIRROR_RING_RADII = (0.8, 1.6)
#: Rings of :func:`ffls.spheres.mirror_outline.circle_search` fitted by :func:`_rings_around`.
MIRROR_RINGS = 8


def _ring_fits(points, center, max_offset: float, r_min: float, r_max: float, cam: DetectionCamera) -> list:
    """The :data:`MIRROR_RINGS` circles of the edge points ``points`` ((n, 2) x, y) best supported
    per pixel of radius (:func:`ffls.spheres.mirror_outline.circle_search`, 1-pixel tolerance),
    centres within ``max_offset`` of ``center``, radii ``r_min`` to ``r_max`` (pixels), each fitted
    to the points within :data:`OUTLINE_BAND_PX` of it until they hold (:func:`fit_until_stable`)."""
    c0 = np.asarray(center, dtype=np.float64)
    P = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    P = P[np.hypot(P[:, 0] - c0[0], P[:, 1] - c0[1]) <= max_offset + r_max + OUTLINE_BAND_PX]
    out = []
    for cc, rr, _ in circle_search(P, c0, max_offset, r_min, r_max, tol=1.0, n_best=MIRROR_RINGS, per_radius=True):
        on = np.abs(np.hypot(P[:, 0] - cc[0], P[:, 1] - cc[1]) - rr) <= OUTLINE_BAND_PX
        new = fit_until_stable(P, on, cam, cc, rr, OUTER_SOURCE)
        if new is not None:
            out.append(new)
    return out


def _rings_around(ft, points, cam: DetectionCamera) -> list:
    """The rings of edge points ``points`` ((n, 2) x, y) around a mirror outline ``ft``, each fitted
    (:func:`_ring_fits`): centres within :data:`MIRROR_RING_OFFSET` radii of its centre, radii
    within :data:`MIRROR_RING_RADII` times its radius; those that end smaller than it (the
    silhouette encloses the reflected scene: on an 8-light chrome ball a reflected ring 0.8 px
    smaller took the outline from 0.77 to 1.01 px off) or as the same circle (centre and radius
    within :data:`ffls.spheres.mirror_outline.MIRROR_OUTLINE_FLOOR_PX` of its) are dropped.

    A dark cap's outline runs along the limb at the top of a chrome ball and inside it below; where
    the fit of the cap puts its top a pixel or two outside the silhouette, no circle of the edges
    encloses it (:func:`ffls.spheres.mirror_outline.enclosing_circle` asks that it lies inside),
    though the silhouette is a closed ring of the changing edges around it (a chrome ball on a
    checker ground, ``ffls synth --background checker`` at 384 px: 5.2 px off, the ring 0.4 px)."""
    c0, r0 = np.asarray(ft.center_px, dtype=np.float64), float(ft.radius_px)
    lo, hi = MIRROR_RING_RADII
    return [new for new in _ring_fits(points, c0, MIRROR_RING_OFFSET * r0, lo * r0, hi * r0, cam)
            if new.radius_px >= r0
            and np.hypot(np.hypot(*(new.center_px - c0)), new.radius_px - r0) > MIRROR_OUTLINE_FLOOR_PX]


def with_max_image_rings(fits, edges: _EdgeMap, changing: ConsistentEdges | None, L, cam: DetectionCamera,
                          max_residual_px: float) -> list:
    """Each mirror ball's outline still on the max image's edges (:func:`_is_mirror_outline`, not
    refitted on the photos' edges) replaced by the ring of the max image's edges around it
    (:func:`_ring_fits`: centre within a quarter of its radius, radius within 0.1 radii + 2 px of its)
    that fits best (:func:`outline_quality`), where that one is round (RMS within ``max_residual_px``)
    and fits better than it; the replacement keeps the score and gets its own ambiguity
    (:func:`_outline_ambiguity`). The rings are another arc of the same ball: in a single probe
    photo a wider search (radii 0.8-1.6) took an inner reflection (``benchmarks/probe_detect.py``,
    night long: 2.2 -> 9.1 px off), and this band a reflected circle 0.89 px off for one 0.23 px
    off (courtyard normal). So the ring must also have more of its outline on the edges that change
    with the light (``changing``, :func:`outline_support`) than the outline it replaces (the
    calibration shot: 0.53 -> 0.57); unchanged without that evidence (None: fewer than 3 photos).

    Below a chrome ball on a plain table the ball reflects the table, which meets the table
    beside it with only the step of the ball's reflectance; just outside it the contact shadow's
    edge runs as a second arc. The enclosing circle (:func:`_outer_outline`) takes the better
    covered of the circles through the cap's top and either arc (ties: the larger), and took the
    shadow's (the chrome ball of ``bench_conditions.py``'s calibration shot: 2.36 px off, RMS
    0.76 px); the circle through the reflectance step fits the cap's top and the step closely. A
    ring whose centre lies within :data:`ffls.spheres.mirror_outline.MIRROR_OUTLINE_FLOOR_PX` of
    the outline's is the same outline (its radius may be the limb step's) and is not taken."""
    def ring(ft, pts, tree):
        if ft.outline_edges == PHOTO_EDGES:
            return None
        # another arc of the same ball: the centre within a quarter radius, the radius within the
        # refit's band (0.1 radii + 2 px, as _refine_on_consistent_edges); a ring about the same
        # centre is the same outline, whose radius may be its limb step's (_outer_outline)
        c0, r0 = np.asarray(ft.center_px, dtype=np.float64), float(ft.radius_px)
        band = 0.1 * r0 + 2.0
        rings = [g for g in _ring_fits(edges.points, c0, 0.25 * r0, r0 - band, r0 + band, cam)
                 if g.residual_px <= max_residual_px and np.hypot(*(g.center_px - c0)) > MIRROR_OUTLINE_FLOOR_PX]
        best = max(rings, key=outline_quality, default=None)
        if best is None or outline_quality(best) <= outline_quality(ft):
            return None
        return best if outline_support(best, pts, cam.shape, tree=tree) > outline_support(ft, pts, cam.shape,
                                                                                            tree=tree) else None

    return mirror_outlines_replaced(fits, changing, L, cam, ring, photo_edges=False)


def fit_on_consistent_edges(c0, r0: float, ev: ConsistentEdges, cam: DetectionCamera, source: str, band: float = 0.1,
                             min_points: int = 8, max_rms_px: float | None = None):
    """A sphere fitted on the ridge points of ``ev`` (:func:`consistent_edge_points`) near the circle
    ``(c0, r0)`` (pixels), or None.

    The points within ``band`` radii (+ 2 px) of the circle whose direction is radial
    (``|cos| > 0.7``) are searched for the best-supported circle (:func:`_start_circle`, 1-pixel
    tolerance: a contact shadow's boundary runs a few pixels outside the silhouette); the points
    within 1.5 px of it are fitted, then those within 1.5 px of the fitted outline, until they
    hold (:func:`fit_until_stable`; a fit whose RMS is above ``max_rms_px`` is None).
    """
    pts, dirs, _ = ev.points
    if len(pts) < min_points:
        return None
    # only the rows the band can reach (|y - y0| < d < (1 + band) r0 + 2, and a pixel to spare) are
    # measured: the same points, in the same order, as over all of them
    reach = (1.0 + band) * r0 + 3.0
    rows = ev.near_rows(c0[1] - reach, c0[1] + reach)
    pts, dirs = pts[rows], dirs[rows]
    v = pts - c0
    d = np.hypot(v[:, 0], v[:, 1])
    cosr = np.abs(np.sum(v * dirs, axis=1)) / np.maximum(d, 1e-9)
    sel = (np.abs(d - r0) < band * r0 + 2.0) & (cosr > 0.7)
    if sel.sum() < min_points:
        return None
    P = pts[sel]
    circ = _start_circle(P, c0, r0, tol=1.0)
    if circ is None:
        return None
    on = np.abs(np.hypot(P[:, 0] - circ[0][0], P[:, 1] - circ[0][1]) - circ[1]) <= OUTLINE_BAND_PX
    return fit_until_stable(P, on, cam, circ[0], circ[1], source, min_points, max_rms_px=max_rms_px)


#: Half-width (px) of the band of edge points around a circle, then around the fitted outline, that
#: an outline is fitted to (:func:`fit_on_consistent_edges`, :func:`fit_until_stable`).
OUTLINE_BAND_PX = 1.5


def outline_residuals_px(ft, points, cam: DetectionCamera, rays=None) -> np.ndarray:
    """Signed distances (pixels; positive outside) of ``points`` ((n, 2) x, y) from a fitted
    sphere's outline: the tangent cone's (:func:`_cone_residuals`, the fit's own residual) for a
    pinhole camera, the circle's for an orthographic one. ``rays`` (n, 3), optional: the points'
    ``pixel_rays(points, cam.K, cam.dist)`` where the caller has them (pinhole)."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if cam.ortho:
        return _circle_residuals([ft.center_px[0], ft.center_px[1], ft.radius_px], P)
    C = np.asarray(ft.center_cam, dtype=np.float64)
    d = C / np.linalg.norm(C)
    p = cam.f * np.array([d[0] / d[2], d[1] / d[2], np.arcsin(min(cam.R / np.linalg.norm(C), 1.0))])
    return _cone_residuals(p, pixel_rays(P, cam.K, cam.dist) if rays is None else rays, cam.f)


def fit_until_stable(P, on, cam: DetectionCamera, c0_px, r0_px, source, min_points: int = 8, rounds: int = 4,
                      max_rms_px: float | None = None):
    """The outline fitted (:func:`fit_outline`) to the points ``P[on]`` ((n, 2), ``on`` (n,) bool: those
    within :data:`OUTLINE_BAND_PX` of the start circle ``(c0_px, r0_px)``), then to the points of
    ``P`` within that band of the fitted outline, until that set no longer changes (at most
    ``rounds`` fits); None where fewer than ``min_points`` are in the band or the first fit fails.

    The band around the start circle depends on the start: circles 0.05 px apart took in
    different points, and ended in fits of RMS 0.14 against 0.48 px. Around the fitted outline
    (the tangent cone's ellipse, not the start's circle) the band is the fit's own, so nearby
    starts end in the same set and the same fit (docs/spheres.md "Circle fits that do not depend
    on their start"). With ``max_rms_px``, a fit whose RMS (``residual_px``) is above it is None:
    a caller that drops such fits has none made."""
    # the points undistorted once (pinhole): every round's fit and band read the same rays; each
    # round's robust fit only places the next band, and the one returned is made a SphereFit
    rays = None if cam.ortho else pixel_rays(np.asarray(P, dtype=np.float64).reshape(-1, 2), cam.K, cam.dist)
    done = []  # the rounds' solutions
    for _ in range(rounds):
        if np.count_nonzero(on) < min_points:
            break
        try:
            sol = outline_solved(P[on], cam, c0_px, r0_px, None if rays is None else rays[on])
        except ValueError:
            break
        done.append(sol)
        c0_px, r0_px = sol.center_px, sol.radius_px
        new = np.abs(outline_residuals_px(sol, P, cam, rays)) <= OUTLINE_BAND_PX
        if np.array_equal(new, on):
            break
        on = new
    for sol in reversed(done):  # where the last round's bookkeeping fails, the round before stands
        if max_rms_px is not None and sol.rms > max_rms_px:
            return None
        try:
            return sol.fit(cam, source)
        except ValueError:
            continue
    return None


def _refine_on_consistent_edges(ft, ev: ConsistentEdges, cam: DetectionCamera, max_residual_px: float,
                                band: float = 0.1, min_points: int = 8):
    """Refit a found sphere on the per-photo edge evidence (:func:`consistent_edge_points`), if it fits better.

    In the max image a silhouette can merge with a bright ground (a white sphere on a white
    ground, at its top) and meet its contact shadow below: the outline fit then follows the shadow
    (on ``ffls synth --background white`` at 384 px, 2 of 4 spheres 1.4-1.7 px off). The edges
    that hold in the photos keep the silhouette all round. The ridge points within
    ``band`` radii (+ 2 px) of the current outline whose direction is radial (``|cos| > 0.7``) are
    searched for the best-supported circle (:func:`ffls.spheres.mirror_outline.circle_search`, 1-pixel tolerance: a contact shadow's boundary runs a few
    pixels outside the silhouette); the points within 1.5 px of it are fitted
    (:func:`fit_on_consistent_edges`). The refit replaces the fit when it is round (RMS within
    ``max_residual_px``), moves the centre by less than a quarter of the radius and has the
    higher :func:`outline_quality`; otherwise the fit is returned unchanged.
    """
    if ft.source == "override":
        return ft
    c0, r0 = np.asarray(ft.center_px, dtype=np.float64), float(ft.radius_px)
    new = fit_on_consistent_edges(c0, r0, ev, cam, ft.source, band, min_points)
    if (new is None or new.residual_px > max_residual_px or np.hypot(*(new.center_px - c0)) > 0.25 * r0
            or outline_quality(new) <= outline_quality(ft)):
        return ft
    _carry_outline(new, ft).outline_edges = PHOTO_EDGES
    return new


def find_spheres_in_capture(capture, n_spheres: int | None = None, overrides=None, progress=None,
                            stats: SequenceStats | None = None, bit_depths=None, workers: int = 1,
                            seeds=None) -> Spheres:
    """:func:`find_spheres` on a loaded :class:`ffls.io.capture.Capture`, using its whole sequence.

    Uses ``capture.K``, ``.dist``, ``.camera_model``, ``.sphere_radius``, ``.spheres`` (hints),
    ``.sphere_count`` (``n_spheres`` when not given), ``.world_from_camera``, ``.scene_center``
    and the :func:`sequence_stats` of ``read_photo(capture, i)`` for all photos (streamed: one image in
    memory at a time). ``progress`` is an optional wrapper such as ``tqdm.tqdm`` (called as
    ``progress(iterable, total=n)``). ``stats``, when given, is that reduction already made, with
    ``bit_depths`` the photos' stored bit depths (e.g. :func:`ffls.spheres.estimate.decode_photos`,
    which decodes the photos once for detection and estimation): no photo is read. ``workers``
    processes fit the candidate outlines (:func:`find_spheres`; the same spheres for any number). ``seeds``:
    the spheres found on the photos' stored codes, fitted again (:func:`find_spheres`).
    """
    n = len(capture.image_paths)
    depths = set()

    def photos():
        for i in range(n):
            ph = read_photo(capture, i)
            depths.add(ph.bit_depth)
            yield ph

    if getattr(capture, "camera_model", "pinhole") != "orthographic" and capture.sphere_radius is None:
        raise InputError("has no sphere_radius: finding the spheres with a pinhole camera needs their radius "
                         "(world units; or \"camera\": {\"model\": \"orthographic\"} for a long lens)",
                         capture.json_path)
    if not n:
        raise InputError("capture lists no images", capture.folder)
    if stats is not None:
        depths.update(bit_depths or ())
    else:
        it = photos()
        if progress is not None:
            it = progress(it, total=n)
        acc = SequenceAccumulator(n_images=n)  # (sequence_stats, with the washed-out photos kept apart)
        for i, ph in enumerate(it):
            acc.add(ph.linear, i, full_scale=full_scale_share(ph))
        stats = acc.result()
    st = stats
    mx, brightest, mean, n_img = st.max, st.brightest, st.mean, st.n
    hints = getattr(capture, "spheres", None) or None
    if n_spheres is None:
        n_spheres = getattr(capture, "sphere_count", None)
    model = getattr(capture, "camera_model", "pinhole")
    return find_spheres(mx, capture.K, capture.dist, capture.sphere_radius, n_spheres=n_spheres, hints=hints,
                        overrides=overrides, world_from_camera=capture.world_from_camera,
                        scene_center=getattr(capture, "scene_center", None), source=capture.folder,
                        camera_model=model, brightest_index=brightest if n_img > 1 else None, n_photos=n_img,
                        mean_luminance=mean if n_img > 1 else None,
                        saturates=any(isinstance(d, int) for d in depths), colour_counts=st.colour_counts,
                        edge_tensor=st.edge_tensor, edge_photos=st.edge_photos, workers=workers,
                        seeds=None if hints else seeds)


def circle_candidates(image, source: str | os.PathLike | None = None, with_grads: bool = False) -> tuple:
    """The candidate circles of one image, ``(x, y, r)`` pixels, best edge support first: stages 1-3 of
    :func:`find_spheres` without hints (the max image's edges and :func:`hough_circle_candidates`), for a
    caller that judges the candidates by its own criteria (a probe ball, :func:`ffls.probes.locate.locate_sphere`).

    Parameters
    ----------
    image : (H, W, 3) float
        Linear radiance.
    source : path, optional
        Named in the all-black error.
    with_grads : bool
        Also return the edge points' gradients (a caller that judges outlines on the same edges).

    Returns
    -------
    candidates : list of (x, y, r)
        The circles, pixels.
    points : (n, 2) float64
        The max image's edge points (x, y) they were found from (:func:`edge_points`).
    grads : (n, 2) float64
        Only with ``with_grads``: the points' unit gradients, toward brighter (:func:`edge_points`).
    """
    mx, _, _, L, _, _, _ = _max_luminance(image, source)
    edges = edge_map(mx, L, source)
    if with_grads:
        return hough_circle_candidates(edges, L), edges.points, edges.grads
    return hough_circle_candidates(edges, L), edges.points
