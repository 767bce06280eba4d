"""Weighting schemes: how a light-map direction is shared among the captured lights.

One entry point, :func:`cell_weights` (``scheme=``), over five schemes, each with its own module:

``'voronoi'``
    The paper's box filter (Masselus, Dutre, Anrys 2002, section 6; :mod:`ffls.weights.voronoi`):
    the nearest light by angle takes everything.
``'antialiased'``
    Cell borders with sub-texel coverage (:mod:`ffls.weights.antialiased`).
``'barycentric'``
    Spherical barycentric interpolation over the Delaunay triangulation of the directions, the
    rim handled by mirrored lights (:mod:`ffls.weights.barycentric`).
``'gaussian'``
    A von Mises-Fisher kernel over the ``k`` nearest lights, its width from the local light
    spacing (:mod:`ffls.weights.gaussian`).

``'spline'``
    Local thin-plate splines on the sphere blended by the barycentric coordinates (a partition
    of unity over the Delaunay triangulation, :mod:`ffls.weights.spline`): higher order than
    barycentric, interpolating, continuous; its weights may be negative.

``'kriging'``
    Universal-kriging (Gaussian-process) weights with a Matérn kernel and a nugget, its
    parameters learnt from the capture's photos by leave-one-out
    (:func:`ffls.weights.kriging.fit_kernel`; :mod:`ffls.weights.kriging`): smooth, signed, the
    ``slots`` largest weights per direction kept.

Every scheme gives each direction a sparse set of lights and weights that sum to 1, so
integrating a light map (:func:`integrate`) conserves its power exactly: the weights summed over
the lights plus the dropped power (outside the hemisphere) equal the map's total, to float64
rounding.

On the GPU the weights of the smooth schemes travel as a :class:`WeightTexture` (``bake_weights``):
over the same sphere map as the Voronoi cell texture (concentric for ``upper``, octahedral
otherwise), in the world frame, ``slots`` (light index, weight) pairs per texel; pass 1 rotates
every light-map texel, looks up the texel its direction falls in (nearest) and adds ``power x
weight`` to each of the slot's lights (:class:`ffls.gpu.integrate.CellIntegrator`).
:func:`integrate` with ``texture=`` is the float64 twin of that lookup; without it, the weights
are evaluated exactly at every rotated direction. ``'voronoi'`` keeps its exact candidate-cell
fast path (:func:`ffls.weights.voronoi.integrate_weights`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ffls.conventions import check_hemisphere, in_domain, is_rotation, rotate_directions
from ffls.lightmaps.lightmap import sample_bands_of
from ffls.weights import antialiased as _aa
from ffls.weights import gaussian as _ga
from ffls.weights import kriging as _kr
from ffls.weights import spline as _sp
from ffls.weights.barycentric import Barycentric
from ffls.weights.voronoi import Weights, assign_cells, cell_map_name, integrate_weights, unique_directions

__all__ = ["SCHEMES", "EXTRA_SCHEMES", "ALL_SCHEMES", "DEFAULT_SCHEME", "SMOOTH_SCHEMES", "SIGNED_SCHEMES", "OPTIONS",
           "SparseWeights", "Weighting",
           "cell_weights", "light_weights", "WeightTexture", "bake_weights", "integrate", "DEFAULT_TEXTURE_RES",
           "texture_slots"]

#: The weighting schemes (``--weighting``).
SCHEMES = ("voronoi", "antialiased", "barycentric", "gaussian", "spline", "kriging")
#: Library-only schemes, not offered by ``--weighting`` (none now: ``kriging`` is offered, its kernel
#: learnt by the relighters from their basis, :class:`ffls.weights.kriging.KernelLearner`).
EXTRA_SCHEMES = ()
#: Every scheme :class:`Weighting` accepts.
ALL_SCHEMES = SCHEMES + EXTRA_SCHEMES
#: The default (the paper's box filter) until the measurements say otherwise (docs/weighting.md).
DEFAULT_SCHEME = "voronoi"
#: Schemes whose weights are continuous in the direction.
SMOOTH_SCHEMES = ("barycentric", "gaussian")
#: Schemes whose weights may be negative (higher-order interpolants).
SIGNED_SCHEMES = ("spline", "kriging")
#: Options each scheme accepts, with their defaults.
OPTIONS = {
    "voronoi": {},
    "antialiased": {"width_deg": _aa.DEFAULT_WIDTH_DEG, "samples": _aa.DEFAULT_SAMPLES},
    "barycentric": {},
    "gaussian": {"k": _ga.DEFAULT_K, "width": _ga.DEFAULT_WIDTH},
    "spline": {"k": _sp.DEFAULT_K, "blend": _sp.DEFAULT_BLEND, "max_lebesgue": _sp.DEFAULT_MAX_LEBESGUE},
    "kriging": {"nu": _kr.DEFAULT_NU, "length": None, "nugget": _kr.DEFAULT_NUGGET, "slots": _kr.DEFAULT_SLOTS},
}
#: Default resolution of a :class:`WeightTexture` (texels per side).
DEFAULT_TEXTURE_RES = 512


def _check_scheme(scheme: str, options: dict) -> dict:
    if scheme not in ALL_SCHEMES:
        raise ValueError(f"weighting scheme must be one of {', '.join(ALL_SCHEMES)}, not {scheme!r}")
    bad = sorted(set(options) - set(OPTIONS[scheme]))
    if bad:
        raise ValueError(f"weighting {scheme!r} takes no option {', '.join(bad)} "
                         f"(it takes: {', '.join(OPTIONS[scheme]) or 'none'})")
    return {**OPTIONS[scheme], **options}


def texture_slots(scheme: str, **options) -> int:
    """(light, weight) pairs per texel of a scheme's :class:`WeightTexture` (its most lights per direction)."""
    opts = _check_scheme(scheme, options)
    if scheme == "voronoi":
        return 1
    if scheme == "barycentric":
        return 3
    if scheme == "gaussian":
        return int(opts["k"])
    if scheme == "spline":  # the union of 3 overlapping neighbourhoods: rarely more than 1.5 k lights
        return (3 * int(opts["k"]) + 1) // 2
    if scheme == "kriging":
        return int(opts["slots"])
    return 4  # antialiased: a cap rarely meets more than 3 cells; a 4th slot for vertices of 4


@dataclass(frozen=True)
class SparseWeights:
    """Per-direction sparse weights over the lights.

    Attributes
    ----------
    index : (m, K) int64
        Light indices, ``-1`` padding (weight 0). An index may appear twice in a row (a light and
        its mirror image in one triangle); its weights add.
    weight : (m, K) float64
        Weights >= 0 (may be negative for :data:`SIGNED_SCHEMES`); every row sums to 1 (to
        float64 rounding).
    """

    index: np.ndarray
    weight: np.ndarray

    def dense(self, n: int) -> np.ndarray:
        """The weights as a dense ``(m, n)`` float64 array."""
        m, k = self.index.shape
        out = np.zeros((m, n))
        ok = self.index >= 0
        rows = np.repeat(np.arange(m), k).reshape(m, k)
        np.add.at(out, (rows[ok], self.index[ok]), self.weight[ok])
        return out


class Weighting:
    """A weighting scheme prepared for one set of light directions.

    Parameters
    ----------
    directions : (n, 3) array_like
        Light directions (world frame; normalised here). Exact duplicates: the first copy takes
        the weight, later ones get 0 (as :mod:`ffls.weights.voronoi`).
    scheme : {'voronoi', 'antialiased', 'barycentric', 'gaussian', 'spline', 'kriging'}
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
    **options
        Scheme options (:data:`OPTIONS`): ``antialiased``: ``width_deg`` (cap radius, degrees),
        ``samples``; ``gaussian``: ``k`` (lights per direction), ``width`` (sigma over the angle to
        the (k+1)-th nearest light); ``spline``: ``k`` (vertices per local spline), ``blend``
        (the splines' share against barycentric, in [0, 1]), ``max_lebesgue`` (bound on
        ``sum |w|``); ``kriging``: ``nu``, ``length`` (chord; None: from the light spacing),
        ``nugget``, ``slots`` (:class:`ffls.weights.kriging.Kriging`; learn the first three from the
        photos with :func:`ffls.weights.kriging.fit_kernel`, ``KernelFit.options``).
    """

    def __init__(self, directions, scheme: str = DEFAULT_SCHEME, hemisphere="upper", **options):
        self.options = _check_scheme(scheme, options)
        self.scheme = scheme
        self.hemisphere = check_hemisphere(hemisphere)
        self.directions, self._keep = unique_directions(directions)
        self._tree = cKDTree(self.directions[self._keep])
        self._bary = (Barycentric(self.directions, self._keep, self.hemisphere) if scheme in ("barycentric", "spline")
                      else None)
        self._spline = (_sp.LocalSpline(self._bary, self.options["k"], self.options["blend"],
                                        self.options["max_lebesgue"]) if scheme == "spline" else None)
        self._density = (_ga.light_density(self.directions, self._keep, self._tree, self.options["k"],
                                           self.options["width"]) if scheme == "gaussian" else None)
        self._kriging = (_kr.Kriging(self.directions, self._keep, self.options["nu"], self.options["length"],
                                     self.options["nugget"], self.options["slots"]) if scheme == "kriging" else None)

    @property
    def n_lights(self) -> int:
        return int(self.directions.shape[0])

    @property
    def triangulation(self) -> Barycentric | None:
        """The :class:`ffls.weights.barycentric.Barycentric` triangulation (``'barycentric'``, ``'spline'``)."""
        return self._bary

    def _assign(self, q: np.ndarray) -> np.ndarray:
        return assign_cells(q, self.directions)

    def _nearest2(self, q: np.ndarray):
        """Exact cell, and angles to the nearest and second-nearest distinct lights (inf if one)."""
        cell = assign_cells(q, self.directions)
        kk = min(2, self._keep.size)
        dist, _ = self._tree.query(q, k=kk)
        ang = 2.0 * np.arcsin(np.clip(0.5 * np.asarray(dist).reshape(q.shape[0], kk), 0.0, 1.0))
        a2 = ang[:, 1] if kk == 2 else np.full(q.shape[0], np.inf)
        return cell, ang[:, 0], a2

    def __call__(self, p) -> SparseWeights:
        """Weights of unit directions ``p`` (m, 3) (world frame; not tested against the hemisphere)."""
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(p)):
            raise ValueError("directions contain NaN or Inf")
        norm = np.linalg.norm(p, axis=1, keepdims=True)
        if np.any(norm == 0):
            raise ValueError("directions contain a zero vector")
        p = p / norm
        if p.shape[0] == 0:
            k = texture_slots(self.scheme, **self.options)
            return SparseWeights(index=np.zeros((0, k), dtype=np.int64), weight=np.zeros((0, k)))
        if self.scheme == "voronoi":
            idx = self._assign(p)[:, None]
            w = np.ones(idx.shape)
        elif self.scheme == "antialiased":
            idx, w = _aa.weights_antialiased(p, self._assign, self.options["width_deg"], self.options["samples"],
                                             nearest2=self._nearest2)
        elif self.scheme == "barycentric":
            idx, w = self._bary(p)
        elif self.scheme == "spline":
            idx, w = self._spline(p)
        elif self.scheme == "kriging":
            idx, w = self._kriging(p)
        else:
            idx, w = _ga.weights_gaussian(p, self.directions, self._keep, self._tree, self.options["k"],
                                          self.options["width"], density=self._density)
        return SparseWeights(index=idx, weight=w)


def cell_weights(directions, query, scheme: str = DEFAULT_SCHEME, hemisphere="upper", **options) -> SparseWeights:
    """Weights of directions ``query`` over the lights ``directions`` under a weighting scheme.

    Parameters
    ----------
    directions : (n, 3) array_like
        Light directions.
    query : (m, 3) array_like
        Directions to weight (world frame).
    scheme : {'voronoi', 'antialiased', 'barycentric', 'gaussian', 'spline', 'kriging'}
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
    **options
        As :class:`Weighting`.

    Returns
    -------
    SparseWeights
        Rows sum to 1.
    """
    return Weighting(directions, scheme, hemisphere, **options)(query)


def light_weights(directions, light, scheme: str = DEFAULT_SCHEME, hemisphere="upper", **options) -> np.ndarray:
    """Per-light weights ``(n,)`` of one directional light of unit irradiance from ``light`` (3,).

    The relit image under that light is ``sum_i w_i B_i`` (RTI-style relighting): the scheme's
    weights at that direction. They sum to 1; a direction outside the hemisphere raises
    ``ValueError``.
    """
    h = check_hemisphere(hemisphere)
    d = np.asarray(light, dtype=np.float64).reshape(1, 3)
    if not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
        raise ValueError("the light direction must be a finite non-zero vector")
    d = d / np.linalg.norm(d)
    if not in_domain(d, h)[0]:
        raise ValueError("the light direction is outside the capture's hemisphere")
    wt = Weighting(directions, scheme, h, **options)
    return wt(d).dense(wt.n_lights)[0]


# ----------------------------------------------------------------------------- texture
def _get_map(hemisphere):
    from ffls.lightmaps.sphere_maps import get_map

    return get_map(cell_map_name(hemisphere))


@dataclass(frozen=True)
class WeightTexture:
    """A scheme's weights baked over a sphere-map texture (the GPU's per-texel sparse set).

    Attributes
    ----------
    index : (res, res, slots) int32
        Light indices per texel, ``-1`` padding (and everywhere outside the map's domain).
    weight : (res, res, slots) float32
        Weights at the texel centre; each valid texel's slots sum to 1 (float32). Where a scheme
        gives more lights than ``slots``, the largest are kept and renormalised (counted in
        ``truncated``).
    res : int
    hemisphere : ffls.conventions.Hemisphere
    map_name : str
        ``'concentric'`` (upper) or ``'octahedral'``.
    scheme : str
    options : dict
    directions : (n, 3) float64
        The normalised light directions.
    truncated : int
        Texels whose scheme weights had more than ``slots`` lights.
    """

    index: np.ndarray
    weight: np.ndarray
    res: int
    hemisphere: object
    map_name: str
    scheme: str
    options: dict = field(default_factory=dict)
    directions: np.ndarray = None
    truncated: int = 0

    @property
    def slots(self) -> int:
        return int(self.index.shape[-1])

    @property
    def n_lights(self) -> int:
        return int(self.directions.shape[0])

    def texel_of(self, d: np.ndarray) -> np.ndarray:
        """Flat texel index of directions ``d`` (m, 3) (-1 outside the map)."""
        idx = _get_map(self.hemisphere).texel_index(np.asarray(d, dtype=np.float64), self.res)
        if isinstance(idx, tuple):
            rows, cols = (np.asarray(a, dtype=np.int64) for a in idx)
            return np.where((rows < 0) | (cols < 0), -1, rows * self.res + cols)
        return np.asarray(idx, dtype=np.int64).reshape(-1)

    def lookup(self, d) -> SparseWeights:
        """The weights of the texel each direction ``d`` (m, 3) falls in, renormalised in float64."""
        t = self.texel_of(np.asarray(d, dtype=np.float64).reshape(-1, 3))
        k = self.slots
        idx = np.full((t.size, k), -1, dtype=np.int64)
        w = np.zeros((t.size, k))
        ok = t >= 0
        idx[ok] = self.index.reshape(-1, k)[t[ok]]
        w[ok] = self.weight.reshape(-1, k)[t[ok]]
        tot = w.sum(axis=1, keepdims=True)
        w = np.divide(w, tot, out=np.zeros_like(w), where=tot > 0)
        return SparseWeights(index=idx, weight=w)


def _fit_slots(idx: np.ndarray, w: np.ndarray, slots: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Merge repeated indices per row, keep the ``slots`` largest weights, renormalise."""
    m, k = idx.shape
    order = np.argsort(np.where(idx < 0, np.iinfo(np.int64).max, idx), axis=1, kind="stable")
    idx = np.take_along_axis(idx, order, 1)
    w = np.take_along_axis(w, order, 1).copy()
    for c in range(k - 1, 0, -1):  # fold a run of equal indices into its first slot
        same = (idx[:, c] == idx[:, c - 1]) & (idx[:, c] >= 0)
        w[same, c - 1] += w[same, c]
        w[same, c] = 0.0
        idx[same, c] = -1
    w[idx < 0] = 0.0
    order = np.argsort(-np.abs(w), axis=1, kind="stable")  # the largest in magnitude (signed schemes)
    idx = np.take_along_axis(idx, order, 1)
    w = np.take_along_axis(w, order, 1)
    truncated = int(np.count_nonzero(w[:, slots:].max(axis=1, initial=0.0) > 0)) if k > slots else 0
    idx = idx[:, :slots]
    w = w[:, :slots]
    if idx.shape[1] < slots:
        pad = slots - idx.shape[1]
        idx = np.concatenate([idx, np.full((m, pad), -1, dtype=np.int64)], axis=1)
        w = np.concatenate([w, np.zeros((m, pad))], axis=1)
    w = w / w.sum(axis=1, keepdims=True)
    return idx, w, truncated


def bake_weights(directions, scheme: str, hemisphere="upper", res: int = DEFAULT_TEXTURE_RES, slots: int | None = None,
                 **options) -> WeightTexture:
    """Bake a scheme's weights at the texel centres of a sphere-map texture.

    Parameters
    ----------
    directions : (n, 3) array_like
        Light directions (world frame).
    scheme : {'voronoi', 'antialiased', 'barycentric', 'gaussian', 'spline', 'kriging'}
        (``'voronoi'`` is baked too, with one slot, though the engine uses its exact cell texture.)
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
        ``upper``: the concentric map; otherwise the octahedral map.
    res : int
        Texels per side.
    slots : int, optional
        (light, weight) pairs per texel; default :func:`texture_slots`.
    **options
        Scheme options (:data:`OPTIONS`).

    Returns
    -------
    WeightTexture
    """
    res = int(res)
    if res < 1:
        raise ValueError("res must be positive")
    wt = Weighting(directions, scheme, hemisphere, **options)
    slots = texture_slots(scheme, **options) if slots is None else int(slots)
    if slots < 1:
        raise ValueError("slots must be >= 1")
    smap = _get_map(wt.hemisphere)
    centres = np.asarray(smap.directions(res), dtype=np.float64).reshape(-1, 3)
    valid = np.asarray(smap.valid_mask(res), dtype=bool).reshape(-1) & np.all(np.isfinite(centres), axis=1)
    sw = wt(centres[valid])
    idx, w, truncated = _fit_slots(sw.index, sw.weight, slots)
    w32 = w.astype(np.float32)
    w32 /= w32.sum(axis=1, keepdims=True, dtype=np.float32)
    index = np.full((res * res, slots), -1, dtype=np.int32)
    weight = np.zeros((res * res, slots), dtype=np.float32)
    index[valid] = idx
    weight[valid] = np.where(idx >= 0, w32, 0.0)
    return WeightTexture(index=index.reshape(res, res, slots), weight=weight.reshape(res, res, slots), res=res,
                         hemisphere=wt.hemisphere, map_name=cell_map_name(wt.hemisphere), scheme=scheme,
                         options=dict(wt.options), directions=wt.directions, truncated=truncated)


# ----------------------------------------------------------------------------- integration
def integrate(lightmap_or_samples, directions, rotation=None, hemisphere="upper", scheme: str = DEFAULT_SCHEME,
              texture: WeightTexture | None = None, cells=None, weighting: Weighting | None = None,
              **options) -> Weights:
    """Integrate a rotated light map into per-light weights under a weighting scheme.

    Every light-map texel with rotated direction ``p = R d`` inside the hemisphere adds
    ``radiance * solid_angle * w_j(p)`` to light ``j``; the ``w_j(p)`` sum to 1, so
    ``weights.sum(0) + dropped_power == total_power`` to float64 rounding.

    Parameters
    ----------
    lightmap_or_samples : LightMap or (dirs (M, 3), radiance (M, 3), solid_angle (M,))
    directions : (n, 3) array_like
        Light directions (world frame).
    rotation : (3, 3) array_like, optional
        Light-map rotation (content at ``d`` moves to ``R d``).
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
    scheme : {'voronoi', 'antialiased', 'barycentric', 'gaussian', 'spline', 'kriging'}
    texture : WeightTexture, optional
        Look the weights up in this baked texture (the GPU's path) instead of evaluating them at
        every direction. Must be baked from the same directions, hemisphere and scheme.
    cells : ffls.weights.voronoi.CellTexture, optional
        ``'voronoi'`` only: the candidate-cell texture (:func:`ffls.weights.voronoi.integrate_weights`).
    weighting : Weighting, optional
        A prepared :class:`Weighting` (same directions, scheme and hemisphere) to reuse.
    **options
        Scheme options.

    Returns
    -------
    ffls.weights.voronoi.Weights
    """
    hemisphere = check_hemisphere(hemisphere)
    _check_scheme(scheme, options)
    if scheme == "voronoi" and texture is None:
        return integrate_weights(lightmap_or_samples, directions, rotation, hemisphere, cells=cells)
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    if not is_rotation(R):
        raise ValueError("rotation must be a 3x3 rotation matrix")
    unit, _ = unique_directions(directions)
    if texture is not None:
        if (texture.scheme != scheme or texture.hemisphere != hemisphere or texture.directions.shape != unit.shape
                or not np.array_equal(texture.directions, unit)):
            raise ValueError("the weight texture was baked for another scheme, hemisphere or directions")
        evaluate = texture.lookup
    else:
        if weighting is None:
            weighting = Weighting(unit, scheme, hemisphere, **options)
        elif weighting.scheme != scheme or not np.array_equal(weighting.directions, unit):
            raise ValueError("the weighting was prepared for another scheme or directions")
        evaluate = weighting
    n = unit.shape[0]
    w, total, lost, n_lost = np.zeros((n, 3)), np.zeros(3), np.zeros(3), 0
    chunk = 1 << 17
    # a lat-long map in bands of rows, as integrate_weights: never every texel's samples at once
    for dirs, rad, sa in sample_bands_of(lightmap_or_samples):
        power = rad * sa[:, None]
        total += power.sum(axis=0)
        p = rotate_directions(R, dirs)
        keep = in_domain(p, hemisphere)
        hit = np.zeros(p.shape[0], dtype=bool)
        sel = np.flatnonzero(keep)
        for a in range(0, sel.size, chunk):
            s = sel[a:a + chunk]
            sw = evaluate(p[s])
            ok = sw.index >= 0
            rows = np.broadcast_to(np.arange(s.size)[:, None], sw.index.shape)[ok]
            hit[s] = ok.any(axis=1)
            for c in range(3):
                w[:, c] += np.bincount(sw.index[ok], weights=power[s, c][rows] * sw.weight[ok], minlength=n)
        dropped = ~hit
        n_lost += int(np.count_nonzero(dropped))
        lost += power[dropped].sum(axis=0)
    return Weights(weights=w, dropped_texels=n_lost, dropped_power=lost, total_power=total)
