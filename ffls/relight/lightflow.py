"""Relighting a small bright source by optical-flow interpolation between basis photos (Chen and Lensch 2005).

A light map with a sun, a window or a lamp puts most of its power into a few texels. The usual
weighting (:mod:`ffls.weights.weighting`) hands that power to the nearest lights, so the sun's
sharp shadow becomes a cross-fade of the neighbouring lights' shadows: two or three faint
shadows side by side instead of one dark one. Interpolating the *photos* instead of blending them
moves the shadow: Chen and Lensch, "Light Source Interpolation for Sparsely Sampled Reflectance
Fields" (VMV 2005) compute the optical flow between the photos of neighbouring lights and warp
each toward the intermediate light direction before blending (Fuchs et al., "Superresolution
Reflectance Fields: Synthesizing images for intermediate light directions", Eurographics 2007,
refine the idea). Neither paper is in the project's library; what follows is this module's own
construction, measured in docs/composite.md. Here:

* :func:`split_compact_sources` splits a light map into its compact bright sources (connected
  texels of at least ``threshold`` times the peak radiance, small in solid angle and holding a
  noticeable share of the power) and the rest (the map with those texels set to 0). The split
  conserves energy: the rest's power plus the sources' equals the map's, per channel, to float64
  rounding. An extended source is represented by a few power-weighted samples (k-means of its
  texels), so a window casts a soft shadow.
* :func:`reference_image` is a light-independent image of the basis (a high percentile over the
  lights, per pixel): the photos divided by it keep their shadows and highlights, which move with
  the light, and lose the texture, which does not.
* :func:`photo_flow` is the dense flow between two basis photos: DIS (Kroeger, Timofte, Dai and
  Van Gool, ECCV 2016) or Farneback (SCIA 2003), both from OpenCV, on the log of the blurred
  ratio to the reference (log: a shadow and a lit surface are far apart whatever the exposure;
  blur: the noise of a real photo, and a pyramid that can see a sharp shadow move farther than
  its width), with a forward-backward consistency check: where the two flows disagree the flow
  is set to 0, so the interpolation falls back to the plain blend there (occlusions, flat
  regions, JPEG blocks).
* :class:`FlowInterpolator` gives the photo for any direction ``d``: the lights of the spherical
  Delaunay triangle around ``d`` (:class:`ffls.weights.barycentric.Barycentric`) with barycentric
  weights ``w_v``; each photo's ratio to the reference ``I_v / A`` is warped by
  ``-sum_u w_u F_{v->u}`` (backward warping with bilinear interpolation: no ringing, no new
  extrema), multiplied back by ``A``, and the warped photos are blended with the same weights. At
  a light's own direction it is that light's photo exactly.
* :class:`LevelSetInterpolator` is the alternative that moves only the cast shadows: each light's
  shadow is estimated against a per-pixel linear model of the unshadowed photo
  (:func:`unshadowed_fit`), described by its signed distance (:func:`signed_distance`), and the
  shadow at ``d`` is the zero set of the blended signed distances, each warped toward ``d`` by the
  flow between the distances (:func:`distance_flow`); the blend of the photos is corrected where
  that shadow differs from the blend's cross-faded one.
* :func:`relight_lightflow` is the relit image: the rest through the usual weights and basis sum,
  plus each source's power times its interpolated photo. :class:`LightFlowRelighter` wraps a
  :class:`ffls.relight.cpu.CpuRelighter` with the relighter interface (``set_lightmap``,
  ``set_rotation``, ``render``, ``read_hdr``) for :class:`ffls.relight.composite.Compositor`.

The flow is computed on the CPU (OpenCV) and cached per pair of lights (the shadows per light); it
does not run in the GPU engine's live loop.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.cluster.vq import kmeans2
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ffls.conventions import check_hemisphere, checked_rotation, in_domain
from ffls.display.tonemap import to_uint8, tonemap as tonemap_np
from ffls.lightmaps.sphere_maps import get_map
from ffls.relight.cpu import relight_fast
from ffls.weights.barycentric import Barycentric
from ffls.weights.voronoi import unique_directions
from ffls.weights.weighting import integrate

__all__ = [
    "FLOWS",
    "INTERPOLATIONS",
    "FIT_NEIGHBOURS",
    "SHADOW_LEVEL",
    "BLUR_FRACTION",
    "reference_image",
    "LUMINANCE",
    "CompactSource",
    "SourceSplit",
    "split_compact_sources",
    "photo_flow",
    "FlowInterpolator",
    "unshadowed_fit",
    "signed_distance",
    "distance_flow",
    "LightShadow",
    "LevelSetInterpolator",
    "relight_lightflow",
    "LightFlowRelighter",
]

#: ``method=`` of :func:`photo_flow`.
FLOWS = ("dis", "farneback")
#: ``interpolation=`` of :class:`LightFlowRelighter`: :class:`FlowInterpolator`, :class:`LevelSetInterpolator`.
INTERPOLATIONS = ("flow", "levelset")
#: Default blur of :func:`photo_flow`, as a fraction of the image's larger side.
BLUR_FRACTION = 0.02
#: Barycentric weights at most this are dropped by :meth:`FlowInterpolator.weights`.
WEIGHT_EPS = 1e-9
#: Rec.709 luminance of linear RGB.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class CompactSource:
    """One compact bright source of a light map (directions in the rotated, world frame).

    Attributes
    ----------
    direction : (3,) float64
        Power-weighted mean direction (unit).
    power : (3,) float64
        Its integral of radiance over solid angle, per channel (the map's units times sr).
    solid_angle : float
        Solid angle of its texels (sr).
    texels : int
        Number of texels.
    sample_directions : (k, 3) float64
        Unit directions of the samples that stand for it (k >= 1).
    sample_powers : (k, 3) float64
        Their powers; they sum to ``power``.
    """

    direction: np.ndarray
    power: np.ndarray
    solid_angle: float
    texels: int
    sample_directions: np.ndarray
    sample_powers: np.ndarray

    @property
    def radius_deg(self) -> float:
        """Angular radius (degrees) of a disc of its solid angle."""
        return float(np.degrees(np.arccos(max(-1.0, 1.0 - self.solid_angle / (2 * np.pi)))))


@dataclass(frozen=True)
class SourceSplit:
    """A light map split into compact sources and the rest.

    Attributes
    ----------
    rest : ffls.lightmaps.lightmap.LightMap
        The map with the sources' texels set to 0 (same layout and size; not rotated).
    sources : tuple of CompactSource
    peak : float
        Peak luminance of the map inside the hemisphere (after the rotation).
    """

    rest: object
    sources: tuple
    peak: float

    @property
    def source_power(self) -> np.ndarray:
        """(3,) total power of the sources."""
        if not self.sources:
            return np.zeros(3)
        return np.sum([s.power for s in self.sources], axis=0)

    def describe(self) -> str:
        """One line: the sources' count, share of the power and size."""
        if not self.sources:
            return "no compact source"
        tot = float(self.rest.total_power() @ LUMINANCE + self.source_power @ LUMINANCE)
        parts = [f"{100 * float(s.power @ LUMINANCE) / max(tot, 1e-30):.0f}% in {s.radius_deg:.1f} deg "
                 f"({len(s.sample_powers)} sample{'s' if len(s.sample_powers) > 1 else ''})" for s in self.sources]
        return f"{len(self.sources)} compact source{'s' if len(self.sources) > 1 else ''}: " + ", ".join(parts)


def split_compact_sources(lightmap, rotation=None, hemisphere="upper", *, threshold: float = 0.1,
                          max_solid_angle: float = 0.05, min_power_fraction: float = 0.05,
                          sample_spacing_deg: float = 2.0, max_samples: int = 8, seed: int = 0) -> SourceSplit:
    """Split a light map into compact bright sources and the rest.

    The texels of luminance at least ``threshold`` times the peak luminance inside the hemisphere
    (after the rotation) are grouped into connected sets (neighbours within two texel sizes on
    the sphere, so a source across the lat-long seam or a cube edge is one set). A set is a compact
    source when its solid angle is at most ``max_solid_angle`` and its power at least
    ``min_power_fraction`` of the map's power inside the hemisphere; every texel of it, bright or
    not, stays in one of the two parts, so ``rest + sources == map`` exactly.

    Parameters
    ----------
    lightmap : ffls.lightmaps.lightmap.LightMap
    rotation : (3, 3) array_like, optional
        Light-map rotation (content at ``d`` moves to ``R d``); the sources' directions are rotated.
    hemisphere : {'upper', 'full'} or Hemisphere
        Sources whose centre falls outside it are left in the rest (no light reaches them there).
    threshold : float
        Fraction of the peak luminance a texel needs (0 < threshold <= 1). It is a radiance
        threshold, so a source's extent does not depend on the texel size; its power is the
        solid-angle-weighted sum.
    max_solid_angle : float
        Largest solid angle (sr) of a compact source (0.05 sr is a disc of 7.2 degrees radius).
    min_power_fraction : float
        Smallest share of the power a source must carry to be split off.
    sample_spacing_deg, max_samples : float, int
        A source of angular radius r is represented by ``min(max_samples, 1 + r // spacing)``
        k-means samples of its texels (power-weighted directions, summed powers).
    seed : int
        Seed of the k-means initialisation (the result is deterministic).

    Returns
    -------
    SourceSplit
    """
    if not hasattr(lightmap, "layout"):
        raise ValueError("split_compact_sources needs a LightMap (the rest keeps its layout)")
    if not 0 < threshold <= 1:
        raise ValueError(f"threshold must be in (0, 1], not {threshold}")
    hemi = check_hemisphere(hemisphere)
    R = np.eye(3) if rotation is None else checked_rotation(rotation)
    m = get_map(lightmap.layout)
    res = lightmap.res
    valid = np.flatnonzero(np.asarray(m.valid_mask(res), dtype=bool).ravel())
    d, rad, sa = lightmap.samples()
    if d.shape[0] != valid.size:
        raise ValueError("light map samples do not match its valid texels")
    dr = d @ R.T
    lum = rad @ LUMINANCE
    inside = in_domain(dr, hemi)
    peak = float(lum[inside].max()) if inside.any() else 0.0
    rest_data = np.array(lightmap.data, dtype=np.float32, copy=True)
    if peak <= 0:
        return SourceSplit(replace(lightmap, data=rest_data), (), peak)
    total = float((lum * sa)[inside].sum())
    bright = np.flatnonzero(lum >= threshold * peak)
    link = 2.0 * float(np.sqrt(4 * np.pi / d.shape[0])) * (1.0 if lightmap.layout != "latlong" else 1.3)
    pairs = cKDTree(dr[bright]).query_pairs(link, output_type="ndarray")
    nb = bright.size
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(nb, nb)) if len(pairs) else \
        coo_matrix((nb, nb))
    ncomp, label = connected_components(g, directed=False)
    flat = rest_data.reshape(-1, 3)
    sources = []
    rng = np.random.default_rng(seed)
    for c in range(ncomp):
        t = bright[label == c]
        omega = float(sa[t].sum())
        p = rad[t] * sa[t, None]
        pw = p.sum(0)
        if omega > max_solid_angle or float(pw @ LUMINANCE) < min_power_fraction * total:
            continue
        lw = p @ LUMINANCE
        centre = (dr[t] * lw[:, None]).sum(0)
        if np.linalg.norm(centre) <= 0:
            continue
        centre = centre / np.linalg.norm(centre)
        if not in_domain(centre[None], hemi)[0]:
            continue
        r_deg = float(np.degrees(np.arccos(max(-1.0, 1.0 - omega / (2 * np.pi)))))
        k = int(min(max_samples, t.size, 1 + r_deg // sample_spacing_deg))
        if k > 1:
            _, lab = kmeans2(dr[t], k, minit="++", seed=rng, iter=20)
            groups = [np.flatnonzero(lab == j) for j in range(k)]
            groups = [q for q in groups if q.size]
        else:
            groups = [np.arange(t.size)]
        sd, sp = [], []
        for q in groups:
            v = (dr[t[q]] * np.maximum(lw[q], 1e-30)[:, None]).sum(0)
            sd.append(v / np.linalg.norm(v))
            sp.append(p[q].sum(0))
        flat[valid[t]] = 0.0
        sources.append(CompactSource(centre, pw, omega, int(t.size), np.array(sd), np.array(sp)))
    sources.sort(key=lambda s: -float(s.power @ LUMINANCE))
    return SourceSplit(replace(lightmap, data=rest_data), tuple(sources), peak)


def reference_image(basis, percentile: float = 90.0, chunk_values: int = 1 << 23) -> np.ndarray:
    """A light-independent image of a basis: per pixel and channel, a high percentile over the lights.

    The photos of a reflectance field share the surface's texture and differ in shading, shadows
    and highlights. Dividing a photo by this image leaves its shading (``ratio``: about 1 where
    lit like the brighter photos, near 0 in a shadow), so that the flow follows the shadows and
    highlights that move with the light and not the texture that stays (a simple form of Weiss,
    "Deriving intrinsic images from image sequences", ICCV 2001, who takes the median over the
    illuminations of the log derivatives). A high percentile is robust to the noise of single
    photos and to a highlight seen under a few lights.

    Parameters
    ----------
    basis : (n, H, W, 3) float array
    percentile : float
    chunk_values : int
        Values per chunk of rows (bounds the temporary memory: about 4 bytes each).

    Returns
    -------
    (H, W, 3) float32
    """
    b = np.asarray(basis)
    out = np.empty(b.shape[1:], dtype=np.float32)
    rows = max(1, int(chunk_values) // max(1, b.shape[0] * b.shape[2] * b.shape[3]))
    for r in range(0, b.shape[1], rows):
        out[r:r + rows] = np.percentile(b[:, r:r + rows].astype(np.float32), percentile, axis=0)
    return out


def _ratio(img: np.ndarray, reference: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """``img / reference`` where the reference is above a floor (1e-3 of its median), else ``img / floor``."""
    if reference is None:
        return np.asarray(img, dtype=np.float32), None
    ref = np.asarray(reference, dtype=np.float32)
    pos = ref[ref > 0]
    floor = np.float32(1e-3 * float(np.median(pos))) if pos.size else np.float32(1.0)
    den = np.maximum(ref, floor)
    return np.asarray(img, dtype=np.float32) / den, den


def _flow_images(a: np.ndarray, b: np.ndarray, blur_sigma: float, reference=None) -> tuple[np.ndarray, np.ndarray]:
    """8-bit images for the flow with one shared scale: the luminance ratio to ``reference`` or the log luminance."""
    lum = LUMINANCE.astype(np.float32)
    ra, _ = _ratio(a, reference)
    rb, _ = _ratio(b, reference)
    la, lb = np.maximum(ra @ lum, 0), np.maximum(rb @ lum, 0)
    if blur_sigma > 0:
        la = cv2.GaussianBlur(la, (0, 0), blur_sigma)
        lb = cv2.GaussianBlur(lb, (0, 0), blur_sigma)
    # log of the luminance relative to the pair's median, from 1/32 to 4 times it: a shadow and a
    # lit surface are far apart, a highlight or a bright object does not squeeze the rest into a few levels
    both = np.concatenate([la.ravel(), lb.ravel()])
    pos = both[both > 0]
    med = float(np.median(pos)) if pos.size else 1.0
    lo, hi = np.log(1 / 32), np.log(4.0)

    def u8(x):
        g = np.log(np.maximum(x / med, 1 / 32))
        return np.clip((g - lo) / (hi - lo) * 255, 0, 255).astype(np.uint8)

    return u8(la), u8(lb)


def _raw_flow(a8: np.ndarray, b8: np.ndarray, method: str) -> np.ndarray:
    """OpenCV flow from ``a8`` to ``b8``, computed on images padded by half their size (edge replicated).

    Without the margin DIS misses a shadow that moves by more than its width near the image's
    border (its coarse pyramid levels have no room): the flow from a photo whose shadow is near
    the left edge to one whose shadow is 25 pixels to the right came out 4 to 8 pixels the wrong
    way at 96 pixels, and 25 pixels right with the margin. The margin is at least 8 pixels, so that
    an image smaller than DIS's smallest patch grid (12 pixels) still has a flow.
    """
    pad = max(max(a8.shape[:2]) // 2, 8)  # at least 8: DIS needs a side of 12 pixels or more
    A = cv2.copyMakeBorder(a8, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
    B = cv2.copyMakeBorder(b8, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
    if method == "dis":
        f = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(A, B, None)
    else:
        f = cv2.calcOpticalFlowFarneback(A, B, None, 0.5, 5, 15, 3, 5, 1.2, 0)
    return np.ascontiguousarray(f[pad:pad + a8.shape[0], pad:pad + a8.shape[1]])


def _warp(img: np.ndarray, disp: np.ndarray) -> np.ndarray:
    """``img(x + disp(x))`` with bilinear interpolation (edges replicated)."""
    H, W = disp.shape[:2]
    gx, gy = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    return cv2.remap(np.ascontiguousarray(img, dtype=np.float32), gx + disp[..., 0], gy + disp[..., 1],
                     interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def photo_flow(a, b, method: str = "dis", *, reference=None, blur_sigma: float | None = None,
               consistency: float = 0.2, consistency_px: float = 2.0, max_fraction: float = 0.4,
               explain: bool = True) -> np.ndarray:
    """Dense flow from photo ``a`` to photo ``b``, 0 where it is not trustworthy.

    Parameters
    ----------
    a, b : (H, W, 3) array_like
        Linear photos (basis images of two lights).
    method : {'dis', 'farneback'}
        OpenCV's DIS flow (medium preset) or Farneback's.
    reference : (H, W, 3) array_like, optional
        A light-independent image of the same scene (:func:`reference_image`): the flow is
        computed between the luminance ratios ``a / reference`` and ``b / reference``, which
        keep the shadows and highlights and drop the texture. Without it, between the log
        luminances.
    blur_sigma : float, optional
        Gaussian blur (pixels) of the luminance before the flow; default ``BLUR_FRACTION`` of the
        image's larger side (at least 1 pixel). It suppresses the noise of real photos, and it
        lets the coarse levels of the flow's pyramid see a sharp shadow that moves by more than
        its own width (a hard-edged shadow moving 25 pixels is found from a blur of 1.5 pixels
        on at 96 pixels, not below).
    consistency, consistency_px : float
        Forward-backward check: the flow at ``x`` is kept where
        ``|F_ab(x) + F_ba(x + F_ab(x))|^2 <= consistency * (|F_ab|^2 + |F_ba|^2) + consistency_px^2``
        (Sundaram, Brox and Keutzer, ECCV 2010); elsewhere it is 0. The kept-mask is blurred
        so that the flow goes to 0 smoothly.
    max_fraction : float
        Flows longer than this fraction of the image's larger side are set to 0.
    explain : bool
        Keep the flow only where it explains the change between the photos: ``b`` warped back by
        it is closer to ``a`` than ``b`` itself (both differences blurred like the images). A
        shading change with nothing moving (a curved surface turning away from the light) has
        no flow that explains it better than none, and then the photos are blended, not warped.

    Returns
    -------
    (H, W, 2) float32
        ``a(x) ~ b(x + flow(x))`` (x, y in pixels).
    """
    if method not in FLOWS:
        raise ValueError(f"flow method must be one of {', '.join(FLOWS)}, not {method!r}")
    if blur_sigma is None:
        blur_sigma = max(1.0, BLUR_FRACTION * max(np.shape(a)[:2]))
    a8, b8 = _flow_images(a, b, float(blur_sigma), reference)
    fab = _raw_flow(a8, b8, method)
    fba = _raw_flow(b8, a8, method)
    back = _warp(fba, fab)
    err = ((fab + back) ** 2).sum(-1)
    mag = (fab ** 2).sum(-1) + (back ** 2).sum(-1)
    H, W = fab.shape[:2]
    keep = (err <= consistency * mag + consistency_px ** 2) & (np.sqrt((fab ** 2).sum(-1)) <= max_fraction * max(H, W))
    if explain:
        # the motion must explain the change: b moved back by the flow is closer to a than b is
        fa, fb = a8.astype(np.float32), b8.astype(np.float32)
        e_still = cv2.GaussianBlur(np.abs(fa - fb), (0, 0), float(blur_sigma))
        e_moved = cv2.GaussianBlur(np.abs(fa - _warp(fb, fab)), (0, 0), float(blur_sigma))
        keep &= e_moved < e_still
    k = keep.astype(np.float32)
    s = max(1.0, 0.01 * max(H, W))
    k = np.minimum(k, cv2.GaussianBlur(k, (0, 0), s))
    return (fab * k[..., None]).astype(np.float32)


def _triangle_weights(tri, direction) -> tuple[np.ndarray, np.ndarray]:
    """Lights and barycentric weights (``tri``: a :class:`Barycentric`) of a direction, tiny weights dropped."""
    p = np.asarray(direction, dtype=np.float64).reshape(1, 3)
    p = p / np.linalg.norm(p)
    idx, w = tri(p)
    out: dict = {}
    for i, v in zip(idx[0], w[0]):
        out[int(i)] = out.get(int(i), 0.0) + float(v)
    keys = np.array(sorted(k for k, v in out.items() if v > WEIGHT_EPS), dtype=np.int64)
    ws = np.array([out[k] for k in keys])
    return keys, ws / ws.sum()


class FlowInterpolator:
    """Photos for arbitrary light directions, by flow-warped barycentric interpolation of a basis.

    Parameters
    ----------
    basis : (n, H, W, 3) float array
        Linear basis photos.
    directions : (n, 3) array_like
        Their unit light directions.
    hemisphere : {'upper', 'full'} or Hemisphere
    flow : {'dis', 'farneback'}
    texture : {'reference', 'photo'}
        ``'reference'`` (default): the flows are computed between the photos' ratios to
        :func:`reference_image` and the warps move those ratios, multiplied back by the reference
        afterwards, so that shadows and highlights move and the texture stays. ``'photo'``: the
        photos themselves are compared and warped (log luminance).
    **flow_options
        Options of :func:`photo_flow` (``blur_sigma``, ``consistency``, ...).

    Notes
    -----
    Flows are cached per ordered pair of lights (``H * W * 2`` float32 each).
    """

    def __init__(self, basis, directions, hemisphere="upper", *, flow: str = "dis", texture: str = "reference",
                 **flow_options):
        if flow not in FLOWS:
            raise ValueError(f"flow method must be one of {', '.join(FLOWS)}, not {flow!r}")
        self.basis = basis
        self.hemisphere = check_hemisphere(hemisphere)
        unit, keep = unique_directions(directions)
        self.directions = unit
        self._tri = Barycentric(unit, keep, self.hemisphere)
        self.flow_method = flow
        self.flow_options = dict(flow_options)
        if texture not in ("reference", "photo"):
            raise ValueError(f"texture must be 'reference' or 'photo', not {texture!r}")
        #: (H, W, 3) float32 light-independent image, or None (``texture='photo'``).
        self.reference = reference_image(basis) if texture == "reference" else None
        _, self._den = _ratio(np.zeros(1, np.float32), self.reference) if self.reference is not None else (None, None)
        self._flows: dict = {}

    def weights(self, direction) -> tuple[np.ndarray, np.ndarray]:
        """Lights and barycentric weights of a unit direction: ``index (k,)``, ``weight (k,)``, k <= 3, sum 1.

        Weights of at most :data:`WEIGHT_EPS` are dropped (rounding at a light's own direction or
        on an edge), so that a light's own direction gives its photo unwarped.
        """
        return _triangle_weights(self._tri, direction)

    def clear(self) -> None:
        """Drop the cached flows."""
        self._flows.clear()

    def flow(self, a: int, b: int) -> np.ndarray:
        """Cached :func:`photo_flow` from light ``a``'s photo to light ``b``'s."""
        key = (int(a), int(b))
        if key not in self._flows:
            self._flows[key] = photo_flow(self.basis[a], self.basis[b], self.flow_method, reference=self.reference,
                                          **self.flow_options)
        return self._flows[key]

    def image(self, direction) -> np.ndarray:
        """The photo under a unit-power light from ``direction``: ``(H, W, 3)`` float32 (see the module notes)."""
        return self.image_from(*self.weights(direction))

    def image_from(self, idx, w) -> np.ndarray:
        """The flow-warped blend of photos ``idx`` (k,) with weights ``w`` (k,) summing to 1: ``(H, W, 3)`` float32.

        :meth:`image` with the lights and weights given (e.g. a triangle of the photos that see a
        pixel, :class:`ffls.relight.sphere_shadows.SphereShadowFill`).
        """
        out = np.zeros(self.basis.shape[1:], dtype=np.float32)
        for v, bv in zip(idx, w):
            disp = np.zeros(out.shape[:2] + (2,), dtype=np.float32)
            for u, wu in zip(idx, w):
                if u != v:
                    disp -= np.float32(wu) * self.flow(v, u)
            img = np.asarray(self.basis[v], dtype=np.float32)
            if not np.any(disp):
                out += np.float32(bv) * img
            elif self._den is None:
                out += np.float32(bv) * _warp(img, disp)
            else:
                out += np.float32(bv) * _warp(img / self._den, disp) * self._den
        return out


#: Lights of the local model of :func:`unshadowed_fit` (about the first two rings of a light's
#: neighbours on the sphere: a linear model has 3 unknowns per channel and up to half the lights
#: around a shadow boundary are shadowed).
FIT_NEIGHBOURS = 12
#: A pixel is in a light's shadow where its photo is below this fraction of the unshadowed model:
#: the umbra's edge of a point light is where half of it is hidden, so the boundary between lit and
#: shadowed is the level 1/2 of the visibility.
SHADOW_LEVEL = 0.5


def unshadowed_fit(photos, directions, *, shadow_level: float = SHADOW_LEVEL, iterations: int = 4,
                   prior=None) -> np.ndarray:
    """Per pixel, a linear model of the unshadowed photo as a function of the light direction.

    Over a small cap of the sphere any smooth reflectance is, to first order, linear in the light
    direction, ``I(l) ~ b . l`` per channel (a Lambertian surface is exactly so while lit: ``b`` is
    its albedo times its normal, as in photometric stereo, Woodham 1980). A cast shadow breaks the
    model only downward, so the fit is iterated: the photos below ``shadow_level`` times the current
    model (luminance) are dropped and the rest refitted (weighted least squares per pixel, 3x3
    normal equations).

    Parameters
    ----------
    photos : (k, H, W, 3) float array
        The photos of ``k`` lights near each other on the sphere.
    directions : (k, 3) float array
        Their unit directions.
    shadow_level : float
    iterations : int
    prior : (k, H, W) float array, optional
        Per photo and pixel, a weight >= 0 of the least squares (0: a photo known to hold nothing
        of the unshadowed surface there, e.g. a calibration sphere's shadow from the geometry; a
        kernel of the photos' angle to a direction of interest). Default: 1.

    Returns
    -------
    (H, W, 3, 3) float32
        ``b[y, x, c]``: the model of channel ``c`` is ``b[y, x, c] @ l``; NaN where fewer than
        three photos are left lit (no model: every light around is shadowed, or the pixel faces
        away from them).
    """
    y = np.asarray(photos, dtype=np.float32)
    k, H, W, _ = y.shape
    L = np.asarray(directions, dtype=np.float64).reshape(k, 3)
    y = y.reshape(k, H * W, 3).transpose(1, 0, 2)  # (P, k, 3)
    lum = y @ LUMINANCE.astype(np.float32)  # (P, k)
    LL = np.einsum("ki,kj->kij", L, L).reshape(k, 9)  # (k, 9)
    if prior is None:
        w0 = np.ones(lum.shape, dtype=np.float64)
    else:
        w0 = np.asarray(prior, dtype=np.float64).reshape(k, H * W).T
        if w0.shape != lum.shape or not np.all(w0 >= 0):
            raise ValueError(f"prior must be ({k}, {H}, {W}) weights >= 0")
    m = w0.copy()
    ridge = 1e-9 * np.eye(3)
    b = None
    for _ in range(max(1, int(iterations))):
        # Stacked products, each pixel on its own (the same model in any chunk of pixels)
        M = np.matmul(m[:, None, :], LL)[:, 0].reshape(-1, 3, 3) + ridge
        rhs = np.matmul(L.T, m[:, :, None] * y)  # (P, i, c)
        ok = (m > 0).sum(1) >= 3
        b = np.full((H * W, 3, 3), np.nan)
        if ok.any():
            b[ok] = np.linalg.solve(M[ok], rhs[ok]).transpose(0, 2, 1)  # (P, channel, 3)
        pred = np.matmul(np.matmul(LUMINANCE, np.nan_to_num(b))[:, None, :], L.T)[:, 0]  # (P, k)
        new = ((lum >= shadow_level * pred) | (pred <= 0)) * w0
        if np.array_equal(new, m):
            break
        m = new
    return b.reshape(H, W, 3, 3).astype(np.float32)


def signed_distance(mask: np.ndarray) -> np.ndarray:
    """Signed distance (pixels) to the boundary of a binary mask: negative inside, positive outside.

    ``distance to the nearest inside pixel - distance to the nearest outside pixel`` (OpenCV's exact
    Euclidean distance transform), so the zero level lies half-way between an inside and an
    outside pixel (values +-1 on either side of the boundary). An empty mask is ``+2 max(H, W)``
    everywhere, a full one ``-2 max(H, W)``.

    Parameters
    ----------
    mask : (H, W) bool

    Returns
    -------
    (H, W) float32
    """
    m = np.asarray(mask, dtype=bool)
    big = np.float32(2 * max(m.shape))
    if not m.any():
        return np.full(m.shape, big, np.float32)
    if m.all():
        return np.full(m.shape, -big, np.float32)
    out = cv2.distanceTransform((~m).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    inside = cv2.distanceTransform(m.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return (out - inside).astype(np.float32)


def distance_flow(a: np.ndarray, b: np.ndarray, method: str = "dis", *, consistency: float = 0.2,
                  consistency_px: float = 2.0, reach: float = 0.25) -> np.ndarray:
    """Dense flow between two shadows' signed distances (:func:`signed_distance`), 0 where not trustworthy.

    A signed distance is smooth and has a gradient everywhere, so the flow's pyramid sees a thin
    shadow that moves by more than its width (where the photos' flow, which only sees the
    shadow's edges, loses it). The distances are clipped (``reach``, a quarter of the image's larger side by default)
    and quantised to 8 bits for OpenCV; the flow is checked forward-backward as in
    :func:`photo_flow`.

    Parameters
    ----------
    a, b : (H, W) float array
        Signed distances (pixels).
    method : {'dis', 'farneback'}
    consistency, consistency_px : float
        As in :func:`photo_flow`.
    reach : float
        The distances are clipped to this fraction of the image's larger side.

    Returns
    -------
    (H, W, 2) float32
        ``a(x) ~ b(x + flow(x))``.
    """
    if method not in FLOWS:
        raise ValueError(f"flow method must be one of {', '.join(FLOWS)}, not {method!r}")
    H, W = np.shape(a)[:2]
    r = float(reach) * max(H, W)

    def u8(x):
        return np.clip((np.asarray(x, dtype=np.float32) + r) / (2 * r) * 255, 0, 255).astype(np.uint8)

    a8, b8 = u8(a), u8(b)
    fab = _raw_flow(a8, b8, method)
    fba = _raw_flow(b8, a8, method)
    back = _warp(fba, fab)
    err = ((fab + back) ** 2).sum(-1)
    mag = (fab ** 2).sum(-1) + (back ** 2).sum(-1)
    keep = (err <= consistency * mag + consistency_px ** 2).astype(np.float32)
    s = max(1.0, 0.01 * max(H, W))
    keep = np.minimum(keep, cv2.GaussianBlur(keep, (0, 0), s))
    return (fab * keep[..., None]).astype(np.float32)


@dataclass(frozen=True)
class LightShadow:
    """One basis light's cast shadow, as :class:`LevelSetInterpolator` estimates it.

    Attributes
    ----------
    model : (H, W, 3, 3) float32
        :func:`unshadowed_fit` around the light (NaN where there is none).
    visibility : (H, W) float32
        The photo's luminance over the model's at the light, in [0, 1] (1 where there is no model).
    shadow : (H, W) bool
        ``visibility < SHADOW_LEVEL``.
    distance : (H, W) float32
        :func:`signed_distance` of ``shadow``.
    """

    model: np.ndarray
    visibility: np.ndarray
    shadow: np.ndarray
    distance: np.ndarray


class LevelSetInterpolator:
    """Photos for arbitrary light directions, with the cast shadows moved by level-set interpolation.

    The plain barycentric blend of the three lights around a direction ``d`` turns a sharp shadow
    into three faint ones (a cross-fade). Here each basis light's cast shadow is estimated on its
    own (:func:`unshadowed_fit` over its :data:`FIT_NEIGHBOURS` nearest lights: a pixel is shadowed
    where its photo falls below :data:`SHADOW_LEVEL` of the unshadowed model), described by the
    signed distance to its boundary (:func:`signed_distance`), and the shadow at ``d`` is the zero
    set of the barycentric blend of those signed distances: distance-field metamorphosis (Cohen-Or,
    Solomovic and Levin, "Three-dimensional distance field metamorphosis", ACM TOG 1998), here in
    two dimensions and on the image. A shadow edge that moves between two lights is put at the
    weighted place between its two positions, not faded from one to the other. With ``flow`` each
    light's signed distance is first warped toward ``d`` by ``-sum_u w_u F_{v->u}``, ``F`` the flow
    between the signed distances (:func:`distance_flow`), so that a shadow moving farther than its
    own width between two lights still meets itself half-way.

    The photo at ``d`` is the blend ``B = sum_v w_v I_v`` corrected where the morphed shadow
    differs from the blend of the shadows:

    ``I(d) = B + U(d) max(V_out - V_in, 0) (sum_v w_v S_v - S(d))``

    with ``S_v`` the light's shadow (0/1), ``S(d) = clip(1/2 - 1/2 sum_v w_v D_v, 0, 1)`` the morphed
    one (``D_v`` the signed, possibly warped, distances), ``U(d) = sum_v w_v max(b_v . d, 0)`` the
    unshadowed model at ``d``, and ``V_out``, ``V_in`` the blended visibilities of the lights that
    see the pixel lit and shadowed (1 where there are none): the contrast of the shadow there, so
    that light reaching a shadow anyway (bounce, penumbra) stays, and a pixel whose label flips on
    noise (visibility near :data:`SHADOW_LEVEL` under every light) is barely changed. It is the
    blend exactly at a light's own direction and wherever none of the three lights casts a shadow
    on the pixel (``V_in = 1`` there).

    Why on the image, not per pixel on the sphere: per pixel, the lights' shadowed/lit labels give
    a boundary on the sphere only to within the spacing of the lights, and with two lights (one
    shadowed, one lit) any per-pixel interpolation of the labels is the nearest light's; the
    image's signed distance says how far each pixel is from the edge, which places the edge
    between its two positions.

    Parameters
    ----------
    basis : (n, H, W, 3) float array
    directions : (n, 3) array_like
    hemisphere : {'upper', 'full'} or Hemisphere
    neighbours : int
        Lights of each light's unshadowed model (:data:`FIT_NEIGHBOURS`).
    shadow_level : float
        :data:`SHADOW_LEVEL`.
    flow : {'dis', 'farneback'} or None
        Flow between the signed distances (cached per ordered pair of lights), or None for the
        plain average of the distances.

    Notes
    -----
    Without the flow the morph follows a shadow that deforms or moves by less than its own width
    between neighbouring lights; a thin shadow that jumps farther (the two shadows disjoint) gets
    no shadow in between. Where the distances' flow fails its forward-backward check it is 0 and
    the plain average is used.
    """

    def __init__(self, basis, directions, hemisphere="upper", *, neighbours: int = FIT_NEIGHBOURS,
                 shadow_level: float = SHADOW_LEVEL, flow: str | None = "dis"):
        if not 0 < shadow_level < 1:
            raise ValueError(f"shadow_level must be in (0, 1), not {shadow_level}")
        if int(neighbours) < 3:
            raise ValueError(f"neighbours must be at least 3, not {neighbours}")
        self.basis = basis
        self.hemisphere = check_hemisphere(hemisphere)
        unit, keep = unique_directions(directions)
        self.directions = unit
        self._keep = keep
        self._tree = cKDTree(unit[keep])
        self._tri = Barycentric(unit, keep, self.hemisphere)
        self.neighbours = int(neighbours)
        self.shadow_level = float(shadow_level)
        if flow is not None and flow not in FLOWS:
            raise ValueError(f"flow method must be one of {', '.join(FLOWS)} or None, not {flow!r}")
        self.flow = flow
        self._shadows: dict = {}
        self._flows: dict = {}

    def weights(self, direction) -> tuple[np.ndarray, np.ndarray]:
        """Lights and barycentric weights of a unit direction (as :meth:`FlowInterpolator.weights`)."""
        return _triangle_weights(self._tri, direction)

    def clear(self) -> None:
        """Drop the cached shadows and flows."""
        self._shadows.clear()
        self._flows.clear()

    def shadow(self, v: int) -> LightShadow:
        """Cached :class:`LightShadow` of light ``v``."""
        v = int(v)
        if v not in self._shadows:
            k = min(self.neighbours, self._keep.size)
            _, j = self._tree.query(self.directions[v], k=k)
            idx = self._keep[np.atleast_1d(j)]
            if v not in idx:
                idx = np.concatenate([[v], idx[:-1]])
            b = unshadowed_fit(np.asarray(self.basis[idx], dtype=np.float32), self.directions[idx],
                               shadow_level=self.shadow_level)
            pred = np.einsum("hwci,i->hwc", b, self.directions[v]) @ LUMINANCE
            lum = np.asarray(self.basis[v], dtype=np.float32) @ LUMINANCE
            good = np.isfinite(pred) & (pred > 0)
            vis = np.ones(lum.shape, dtype=np.float32)
            vis[good] = np.clip(lum[good] / pred[good], 0, 1)
            sh = vis < self.shadow_level
            self._shadows[v] = LightShadow(b, vis, sh, signed_distance(sh))
        return self._shadows[v]

    def distance_flow(self, a: int, b: int) -> np.ndarray:
        """Cached flow from light ``a``'s signed distance to light ``b``'s (:func:`distance_flow`)."""
        key = (int(a), int(b))
        if key not in self._flows:
            self._flows[key] = distance_flow(self.shadow(a).distance, self.shadow(b).distance, self.flow)
        return self._flows[key]

    def image(self, direction) -> np.ndarray:
        """The photo under a unit-power light from ``direction``: ``(H, W, 3)`` float32 (see the class notes)."""
        d = np.asarray(direction, dtype=np.float64).reshape(3)
        d = d / np.linalg.norm(d)
        idx, w = self.weights(d)
        out = np.zeros(self.basis.shape[1:], dtype=np.float32)
        for v, wv in zip(idx, w):
            out += np.float32(wv) * np.asarray(self.basis[v], dtype=np.float32)
        if idx.size < 2:
            return out
        sh = [self.shadow(v) for v in idx]
        s_blend = sum(np.float32(wv) * s.shadow for wv, s in zip(w, sh))
        if not np.any(s_blend > 0):
            return out
        if self.flow is None:
            dist = sum(np.float32(wv) * s.distance for wv, s in zip(w, sh))
        else:
            dist = np.zeros(out.shape[:2], dtype=np.float32)
            for v, wv, s in zip(idx, w, sh):
                disp = np.zeros(out.shape[:2] + (2,), dtype=np.float32)
                for u, wu in zip(idx, w):
                    if u != v:
                        disp -= np.float32(wu) * self.distance_flow(v, u)
                dist += np.float32(wv) * (_warp(s.distance, disp) if np.any(disp) else s.distance)
        s_morph = np.clip(0.5 - 0.5 * dist, 0, 1)
        v_in = sum(np.float32(wv) * s.shadow * s.visibility for wv, s in zip(w, sh))
        v_in = np.where(s_blend > 0, v_in / np.maximum(s_blend, 1e-12), 1.0)
        lit = 1 - s_blend
        v_out = sum(np.float32(wv) * (1 - s.shadow) * s.visibility for wv, s in zip(w, sh))
        v_out = np.where(lit > 0, v_out / np.maximum(lit, 1e-12), 1.0)
        unshadowed = sum(np.float32(wv) * np.maximum(np.nan_to_num(np.einsum("hwci,i->hwc", s.model, d)), 0)
                         for wv, s in zip(w, sh))
        corr = unshadowed * (np.maximum(v_out - v_in, 0) * (s_blend - s_morph))[..., None]
        return np.maximum(out + corr.astype(np.float32), 0)


def relight_lightflow(basis, directions, lightmap, rotation=None, hemisphere="upper", *, scheme: str = "voronoi",
                      interpolator: FlowInterpolator | None = None, split_options: dict | None = None,
                      **scheme_options) -> tuple[np.ndarray, SourceSplit]:
    """Relit image with the compact sources interpolated by flow and the rest weighted as usual.

    Parameters
    ----------
    basis : (n, H, W, 3) float array
    directions : (n, 3) array_like
    lightmap : ffls.lightmaps.lightmap.LightMap
    rotation : (3, 3) array_like, optional
    hemisphere : {'upper', 'full'} or Hemisphere
    scheme : str
        Weighting scheme of the rest (:func:`ffls.weights.weighting.integrate`).
    interpolator : FlowInterpolator or LevelSetInterpolator, optional
        Reuse its cached flows or shadows (a :class:`FlowInterpolator` is built here otherwise).
    split_options : dict, optional
        Keyword arguments of :func:`split_compact_sources`.
    **scheme_options
        The scheme's options.

    Returns
    -------
    image : (H, W, 3) float32
    split : SourceSplit
    """
    split = split_compact_sources(lightmap, rotation, hemisphere, **(split_options or {}))
    w = integrate(split.rest, directions, rotation, hemisphere, scheme, **scheme_options).weights
    img = relight_fast(w, basis)
    if split.sources:
        fi = interpolator if interpolator is not None else FlowInterpolator(basis, directions, hemisphere)
        img = img + _sources_image(fi, split.sources)
    return img, split


def _sources_image(fi: FlowInterpolator, sources, fill=None, mode: str = "blend", hull=None) -> np.ndarray:
    """Sum of the sources' samples, each its power times its interpolated photo.

    A sample outside the hemisphere (a source straddling the horizon) adds nothing, as the
    weighting drops the texels there. With ``fill`` (:class:`ffls.relight.sphere_shadows.SphereShadowFill`)
    a sample's photo is, where the sample is hidden by a calibration sphere, the blend of the
    photos that see the pixel (``mode='blend'``) or their unshadowed model times the object's
    ``hull`` visibility (``mode='model'``: :meth:`ffls.relight.sphere_shadows.SphereShadowFill.source_model`);
    ``mode='ground'``: the same on every ground pixel.
    """
    out = np.zeros(fi.basis.shape[1:], dtype=np.float32)
    for s in sources:
        inside = in_domain(np.asarray(s.sample_directions, dtype=np.float64), fi.hemisphere)
        for d, p, ok in zip(s.sample_directions, s.sample_powers, inside):
            if ok:
                img = fi.image(d)
                if fill is not None and mode in ("model", "ground"):
                    img = fill.source_model(img, d, fi.basis, hull=hull, everywhere=mode == "ground").astype(np.float32)
                elif fill is not None:
                    img = fill.source_image(img, d, fi.weights(d)[0], fi.basis,
                                            interpolate=getattr(fi, "image_from", None)).astype(np.float32)
                out += img * p.astype(np.float32)
    return out


class LightFlowRelighter:
    """A :class:`ffls.relight.cpu.CpuRelighter` whose compact sources are relit by :class:`FlowInterpolator`.

    The inner relighter integrates the rest of the map (its weighting, precision, compression
    and cell texture apply there); the sources' interpolated photos are added to its image.
    Interface: ``set_lightmap``, ``set_rotation``, ``render``, ``read_hdr``, ``read_display``,
    ``release``, as the relighters :class:`ffls.relight.composite.Compositor` drives.

    Parameters
    ----------
    inner : ffls.relight.cpu.CpuRelighter
    flow : {'dis', 'farneback'}
    split_options : dict, optional
        Keyword arguments of :func:`split_compact_sources`.
    interpolation : {'flow', 'levelset'}
        :class:`FlowInterpolator` (the photos warped by their flow) or :class:`LevelSetInterpolator`
        (the cast shadows moved by their signed distances, warped by the distances' flow).
    fill : ffls.relight.sphere_shadows.SphereShadowFill, optional
        The calibration spheres' shadows to fill: where a photo has a pixel in one, the rest's
        weight of that photo there goes to the photos that see the pixel.
    fill_sources : bool or {'blend', 'model', 'ground'}
        Also fill a compact source's photo where the source itself would be hidden by a sphere:
        True or ``'blend'``, the visible photos' blend at its direction, tens of degrees away
        (measured worse on the Mitsuba benchmark, docs/composite.md, so off by default);
        ``'model'``, the visible photos' unshadowed model at its direction times ``hull``'s
        visibility (:meth:`ffls.relight.sphere_shadows.SphereShadowFill.source_model`);
        ``'ground'``, the model times the hull on every ground pixel, the spheres' shadows or not
        (``everywhere=True``): the object's shadow from the source is placed by the hull instead
        of interpolated between the nearest lights' photos. Needs ``fill``.
    hull : ffls.relight.shadow_hull.ShadowHull, optional
        The object's shadow hull, for ``fill_sources='model'`` or ``'ground'`` (None: a capture
        without the object).
    fill_rest : bool
        With ``fill``, fill the rest's weights (default); False fills the sources alone.
    """

    def __init__(self, inner, *, flow: str = "dis", split_options: dict | None = None,
                 interpolation: str = "flow", fill=None, fill_sources=False, hull=None,
                 fill_rest: bool = True):
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation must be one of {', '.join(INTERPOLATIONS)}, not {interpolation!r}")
        if fill_sources not in (False, True, "blend", "model", "ground"):
            raise ValueError(f"fill_sources must be False, True, 'blend', 'model' or 'ground', not {fill_sources!r}")
        self.inner = inner
        cls = FlowInterpolator if interpolation == "flow" else LevelSetInterpolator
        self.interpolation = interpolation
        self.interpolator = cls(inner.basis, inner.directions, inner.hemisphere, flow=flow)
        self.split_options = dict(split_options or {})
        self.fill = fill
        self.fill_sources = {False: None, True: "blend"}.get(fill_sources, fill_sources)
        self.hull = hull
        self.fill_rest = bool(fill_rest)
        self._lightmap = None
        self._rotation = np.eye(3)
        self._hdr = None
        self._display = None
        self._display_key = None
        #: :class:`SourceSplit` of the last render.
        self.last_split: SourceSplit | None = None

    @property
    def size(self) -> tuple[int, int]:
        return self.inner.size

    @property
    def n_lights(self) -> int:
        return self.inner.n_lights

    def set_lightmap(self, lm) -> None:
        """Use light map ``lm`` (a :class:`ffls.lightmaps.lightmap.LightMap`)."""
        if not hasattr(lm, "layout"):
            raise ValueError("LightFlowRelighter needs a LightMap, not samples")
        self._lightmap = lm
        self._hdr = None

    def set_rotation(self, R) -> None:
        """Rotate the light map by ``R`` (content at d moves to R d)."""
        R = checked_rotation(R)
        if not np.array_equal(R, self._rotation):
            self._rotation = R.copy()
            self._hdr = None

    def render(self, exposure: float = 0.0, tonemap: str = "srgb") -> None:
        """Relight: the rest by the inner relighter, plus the sources' interpolated photos."""
        if self._lightmap is None:
            raise RuntimeError("LightFlowRelighter.render: call set_lightmap(lm) first")
        if self._hdr is None:
            split = split_compact_sources(self._lightmap, self._rotation, self.inner.hemisphere, **self.split_options)
            self.inner.set_lightmap(split.rest)
            self.inner.set_rotation(self._rotation)
            self.inner.render()
            img = self.inner.read_hdr()
            if self.fill is not None and self.fill_rest:
                img = self.fill.relight(img, self.inner.read_weights(), self.inner.basis)
            if split.sources:
                img = img + _sources_image(self.interpolator, split.sources,
                                           self.fill if self.fill_sources else None,
                                           self.fill_sources or "blend", self.hull)
            self._hdr = img.astype(np.float32)
            self.last_split = split
            self._display = None
        key = (float(exposure), tonemap)
        if key != self._display_key:
            self._display, self._display_key = None, key

    def read_hdr(self) -> np.ndarray:
        """The relit image ``(H, W, 3)`` float32."""
        if self._hdr is None:
            raise RuntimeError("LightFlowRelighter: nothing rendered yet")
        return self._hdr

    def read_display(self) -> np.ndarray:
        """The tone-mapped image ``(H, W, 3)`` uint8."""
        if self._display is None:
            exposure, method = self._display_key if self._display_key is not None else (0.0, "srgb")
            self._display = to_uint8(tonemap_np(self.read_hdr(), exposure, method))
        return self._display

    def release(self) -> None:
        """Release the inner relighter and the cached flows."""
        self.inner.release()
        self.interpolator.clear()
        self.interpolator = None
        self._hdr = self._display = None
