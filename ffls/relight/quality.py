"""Quality knobs of relighting: what is traded against speed, and how each one changes the inputs.

One :class:`Quality` names a configuration; the relighters (:class:`ffls.relight.cpu.CpuRelighter`,
:class:`ffls.gpu.engine.Engine`), the CLI (``relight``, ``render``, ``view``), the viewer's quality
panel and ``benchmarks/tradeoff.py`` all read it. Each knob acts on plain arrays here:

* **near-light correction** (:func:`near_light_scales`, :func:`near_light_directions`): a photo lit
  by a point light at position ``q`` carries the irradiance ``I / r^2`` at the scene centre
  (``r = |q - c|``) and the light's direction *as seen from the centre*, ``(q - c) / r``. The
  basis of the architecture is photos of unit irradiance at normal incidence (Masselus, Dutre,
  Anrys 2002, section 3), so each photo is multiplied by ``(r / r_ref)^2`` and its direction is
  taken from the position. The lamp's intensity ``I`` is one unknown constant for the capture:
  ``r_ref`` (the median distance by default) fixes the overall level, "unit" being the irradiance
  of the lamp at that distance. What the correction cannot fix is the variation of ``1 / r^2``
  and of the light's angle *across* the object (a light at 0.5 m from a 0.3 m object), which needs
  the object's geometry; ``docs/tradeoff.md`` measures when the correction pays.
* **basis subset** (:func:`farthest_point_subset`): ``m`` of the ``n`` photos chosen by
  farthest-point sampling on the light directions (Gonzalez 1985, "Clustering to minimize the
  maximum intercluster distance", the greedy 2-approximation of the k-centre problem): each new
  light is the one farthest (in angle) from those already chosen. Pass 2 reads ``m`` layers
  instead of ``n``; the cells of the remaining lights grow to cover the sphere.
* **storage precision** (:mod:`ffls.relight.storage`): float16 with a checked per-dataset scale,
  or float32.
* **rank** K of the compressed basis (:mod:`ffls.relight.compress`).
* **resolutions**: of the cell texture of pass 1 (``cell_res``) and of the light map pass 1
  integrates (``map_res``: a lat-long map ``map_res`` texels high, box-filtered so that its
  integral is kept; :func:`integration_map`).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from ffls.errors import InputError
from ffls.relight.storage import parse_storage
from ffls.weights.weighting import SCHEMES

__all__ = ["Quality", "near_light_scales", "near_light_directions", "apply_near_correction",
           "farthest_point_subset", "integration_map", "prepare_basis", "WEIGHTINGS", "MAP_RES_CHOICES",
           "pass1_buffer_bytes", "pass1_fit_height"]

#: Weighting schemes of pass 1 (:data:`ffls.weights.weighting.SCHEMES`).
WEIGHTINGS = SCHEMES
#: Light-map heights offered for pass 1 (None = the map as loaded).
MAP_RES_CHOICES = (None, 512, 256, 128, 64, 32)


@dataclass(frozen=True)
class Quality:
    """One relighting configuration (every knob of the speed/accuracy trade).

    Attributes
    ----------
    weighting : {'voronoi', 'antialiased', 'barycentric', 'gaussian', 'spline'}
        Weighting scheme of pass 1 (:mod:`ffls.weights.weighting`; ``'voronoi'``: the paper's box
        filter per cell).
    precision : {'f16', 'f32'}
        Storage of the basis (or of the compressed layers).
    rank : int or None
        Compressed basis of K eigen-images; None = every basis image.
    basis_subset : int or None
        Use only this many photos, chosen by :func:`farthest_point_subset`; None = all.
    cell_res : int or None
        Resolution of the texture pass 1 looks directions up in: the candidate-cell texture
        (``voronoi``) or the weight texture (smooth schemes); None = the scheme's default
        (256 for the cells, :data:`ffls.weights.weighting.DEFAULT_TEXTURE_RES` for weights).
    map_res : int or None
        Height of the lat-long map pass 1 integrates (:func:`integration_map`); None = as loaded.
    near_correction : bool
        Normalise each photo by its light's distance (:func:`apply_near_correction`).
    """

    weighting: str = "voronoi"
    precision: str = "f16"
    rank: int | None = None
    basis_subset: int | None = None
    cell_res: int | None = None
    map_res: int | None = None
    near_correction: bool = False

    def __post_init__(self):
        object.__setattr__(self, "precision", parse_storage(self.precision))
        if self.rank is not None and int(self.rank) < 1:
            raise ValueError(f"rank must be >= 1 or None, not {self.rank}")
        if self.basis_subset is not None and int(self.basis_subset) < 1:
            raise ValueError(f"basis_subset must be >= 1 or None, not {self.basis_subset}")
        if self.map_res is not None and int(self.map_res) < 2:
            raise ValueError(f"map_res must be >= 2 or None, not {self.map_res}")
        if self.cell_res is not None and int(self.cell_res) < 16:
            raise ValueError(f"cell_res must be >= 16 or None, not {self.cell_res}")
        if self.weighting not in SCHEMES:
            raise ValueError(f"weighting must be one of {SCHEMES}, not {self.weighting!r}")

    def replace(self, **kw) -> "Quality":
        """A copy with some knobs changed."""
        return replace(self, **kw)

    def as_dict(self) -> dict:
        return asdict(self)

    def label(self) -> str:
        """A short description, e.g. ``'gaussian f16 K15 sub64 tex256 map64 near'``."""
        parts = [self.weighting, self.precision, "full" if self.rank is None else f"K{self.rank}"]
        if self.basis_subset is not None:
            parts.append(f"sub{self.basis_subset}")
        if self.cell_res is not None:
            parts.append(f"tex{self.cell_res}")
        parts.append("map-full" if self.map_res is None else f"map{self.map_res}")
        if self.near_correction:
            parts.append("near")
        return " ".join(parts)


# ----------------------------------------------------------------------------- near lights
def _distances(positions, centre) -> np.ndarray:
    q = np.asarray(positions, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 3:
        raise ValueError(f"positions must be (n, 3), not {q.shape}")
    c = np.zeros(3) if centre is None else np.asarray(centre, dtype=np.float64).reshape(3)
    return np.linalg.norm(q - c, axis=1)


def near_light_scales(positions, centre=None, reference: float | None = None) -> np.ndarray:
    """Factors ``(r_i / r_ref)^2`` that bring each photo to the irradiance of a light at ``r_ref``.

    Parameters
    ----------
    positions : (n, 3) float
        Light positions (world units), finite.
    centre : (3,) float, optional
        Scene centre (the origin by convention).
    reference : float, optional
        ``r_ref`` (world units, > 0); default the median distance, so that the correction keeps
        the capture's overall level.

    Returns
    -------
    (n,) float64
        Multiply photo ``i`` by ``scales[i]``.

    Raises
    ------
    ValueError
        A position that is not finite, or at the scene centre.
    """
    r = _distances(positions, centre)
    if not np.all(np.isfinite(r)):
        raise ValueError("light positions must be finite")
    if np.any(r <= 0):
        raise ValueError("a light position is at the scene centre")
    r_ref = float(np.median(r)) if reference is None else float(reference)
    if not (np.isfinite(r_ref) and r_ref > 0):
        raise ValueError(f"reference distance must be > 0, not {reference}")
    return (r / r_ref) ** 2


def near_light_directions(positions, centre=None) -> np.ndarray:
    """Unit directions ``(q - c) / |q - c|`` ``(n, 3)`` of the lights as seen from the scene centre."""
    q = np.asarray(positions, dtype=np.float64)
    c = np.zeros(3) if centre is None else np.asarray(centre, dtype=np.float64).reshape(3)
    r = _distances(q, c)
    if np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise ValueError("light positions must be finite and away from the scene centre")
    return (q - c) / r[:, None]


def apply_near_correction(basis, positions, centre=None, reference: float | None = None, path=None):
    """Normalise a basis of near-light photos to the irradiance of a light at ``r_ref`` at the centre.

    Parameters
    ----------
    basis : (n, H, W, 3) float array
    positions : (n, 3) float
        Light positions; NaN rows (unknown) are refused.
    centre, reference
        As :func:`near_light_scales`.
    path : path-like, optional
        Named in errors (the lights file).

    Returns
    -------
    basis : (n, H, W, 3) float32
        ``basis[i] * scales[i]`` (a new array).
    directions : (n, 3) float64
        :func:`near_light_directions`.
    scales : (n,) float64

    Raises
    ------
    InputError
        Some lights have no position (the lights file gives none).
    """
    q = np.asarray(positions, dtype=np.float64)
    b = np.asarray(basis)
    if q.shape != (b.shape[0], 3):
        raise ValueError(f"positions must be ({b.shape[0]}, 3), not {q.shape}")
    missing = int(np.count_nonzero(~np.all(np.isfinite(q), axis=1)))
    if missing:
        raise InputError(f"near-light correction needs light positions; {missing} of {len(q)} accepted lights "
                         f"have none", path)
    try:
        s = near_light_scales(q, centre, reference)
        d = near_light_directions(q, centre)
    except ValueError as e:
        raise InputError(f"near-light correction: {e}", path) from None
    out = np.empty(b.shape, dtype=np.float32)
    for i in range(b.shape[0]):
        out[i] = b[i] * np.float32(s[i])
    return out, d, s


# ----------------------------------------------------------------------------- basis subset
def farthest_point_subset(directions, m: int, first: int | None = None) -> np.ndarray:
    """Indices of ``m`` directions chosen by farthest-point sampling (Gonzalez 1985).

    Parameters
    ----------
    directions : (n, 3) float
        Unit light directions.
    m : int
        How many to keep, ``1 <= m``; ``m >= n`` keeps all (indices ``0..n-1``).
    first : int, optional
        The first light chosen; default the light closest to the mean direction (the centre of
        the capture's coverage), so the result does not depend on the order of the lights.

    Returns
    -------
    (min(m, n),) int ndarray
        Sorted indices (the basis keeps the capture's order).

    Notes
    -----
    Each step adds the direction with the largest angle to its nearest chosen direction (ties:
    the lowest index), which makes the largest gap at most twice the best possible for ``m``
    points. Duplicate directions are chosen last.
    """
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3 or len(d) == 0:
        raise ValueError(f"directions must be (n, 3) with n >= 1, not {d.shape}")
    m = int(m)
    if m < 1:
        raise ValueError(f"m must be >= 1, not {m}")
    n = len(d)
    if m >= n:
        return np.arange(n)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    if first is None:
        mean = u.mean(axis=0)
        first = int(np.argmax(u @ mean)) if np.linalg.norm(mean) > 1e-12 else 0
    chosen = [int(first)]
    best = u @ u[first]  # cosine to the nearest chosen direction (larger = closer)
    best[first] = np.inf
    for _ in range(m - 1):
        k = int(np.argmin(best))
        chosen.append(k)
        best = np.maximum(best, u @ u[k])
        best[k] = np.inf
    return np.sort(np.array(chosen))


# ----------------------------------------------------------------------------- light map resolution
def integration_map(lightmap, height: int | None):
    """The light map pass 1 integrates: ``lightmap`` itself, or a lat-long ``height`` texels high.

    A lat-long map whose height is a multiple of ``height`` is box-filtered
    (:meth:`ffls.lightmaps.lightmap.LightMap.downsample`, which keeps its integral); other maps
    are resampled with :meth:`~ffls.lightmaps.lightmap.LightMap.to_latlong` at four times the
    height first, then box-filtered, then scaled (per channel) to the original total power: the
    resampling alone can move a sun's energy by several percent. A map no taller than ``height``
    is returned as it is, and so is a map given as samples.
    """
    if height is None or not hasattr(lightmap, "layout"):
        return lightmap
    h = int(height)
    if lightmap.layout == "latlong":
        if lightmap.res <= h:
            return lightmap
        if lightmap.res % h == 0:
            return lightmap.downsample(lightmap.res // h)
    small = lightmap.to_latlong(4 * h).downsample(4)
    # resampling moves a small bright source's energy; give back the exact total, per channel
    want, got = lightmap.total_power(), small.total_power()
    scale = np.divide(want, got, out=np.ones(3), where=got > 0)
    return replace(small, data=(small.data * scale.astype(np.float32)).astype(np.float32))


def pass1_buffer_bytes(n_texels: int, weighting: str, **options) -> int:
    """Largest single GPU storage buffer (bytes) pass 1 needs for a map of ``n_texels`` texels.

    :class:`ffls.gpu.integrate.CellIntegrator` (technique ``sort``) holds the texel directions
    (float64 x 3: 24 bytes a texel) and, for a scheme with a weight texture, one 16-byte item per
    texel and slot (:func:`ffls.weights.weighting.texture_slots`; ``voronoi``'s cell path: one item
    per texel). Each must fit one storage block (``GL_MAX_SHADER_STORAGE_BLOCK_SIZE``; 128 MiB on
    llvmpipe), so a many-slot scheme (``spline``: 24) limits the map pass 1 can take.
    """
    from ffls.weights.weighting import texture_slots

    slots = 1 if weighting == "voronoi" else texture_slots(weighting, **options)
    return int(n_texels) * max(24, 16 * slots)


def pass1_fit_height(max_bytes: int, weighting: str, **options) -> int:
    """Tallest power-of-two lat-long height ``H`` (``H x 2H`` texels) whose pass 1 fits ``max_bytes``
    per buffer (:func:`pass1_buffer_bytes`); 0 if not even ``H = 2`` fits."""
    h = 2
    if pass1_buffer_bytes(2 * h * h, weighting, **options) > max_bytes:
        return 0
    while pass1_buffer_bytes(2 * (2 * h) ** 2, weighting, **options) <= max_bytes:
        h *= 2
    return h


# ----------------------------------------------------------------------------- all together
def prepare_basis(basis, directions, positions=None, *, near_correction: bool = False,
                  basis_subset: int | None = None, path=None):
    """Apply the knobs that change the basis itself: near-light correction, then the subset.

    Parameters
    ----------
    basis : (n, H, W, 3) float array
    directions : (n, 3) float
    positions : (n, 3) float, optional
        Light positions (NaN where unknown); needed by ``near_correction``.
    near_correction : bool
    basis_subset : int, optional
    path : path-like, optional
        Named in errors.

    Returns
    -------
    basis : (m, H, W, 3) float array
        A view or new array (never the input modified).
    directions : (m, 3) float64
    info : dict
        ``{'indices': (m,) int, 'near_scales': (n,) float or None}``.
    """
    b = np.asarray(basis)
    d = np.asarray(directions, dtype=np.float64)
    scales = None
    if near_correction:
        if positions is None:
            raise InputError("near-light correction needs light positions; the lights file gives none", path)
        b, d, scales = apply_near_correction(b, positions, path=path)
    idx = np.arange(len(d))
    if basis_subset is not None and int(basis_subset) < len(d):
        idx = farthest_point_subset(d, int(basis_subset))
        b, d = b[idx], d[idx]
    return b, d, {"indices": idx, "near_scales": scales}
