"""Model light sources for the inverse methods, and their conversion to a lat-long light map.

Hougen and Ahuja (1993) model the illumination as point sources at fixed directions plus an
ambient term; Sato, Sato and Ikeuchi (1999) use the nodes of a geodesic dome, each standing for
a patch of (nearly) equal solid angle. Both give a set of unit directions ``(n, 3)`` and, after
the solve, one *intensity* per source: its irradiance at normal incidence (W m^-2, RGB), the
unit of ffls' per-light weights (``docs/architecture.md``).

Source sets
-----------
* :func:`ring_sources` -- 5, 9 and 17 sources, Hougen and Ahuja's sizes: a source on the pole of
  a hemisphere and rings of 4 or 8 around it, the rings placed at the middle (in ``cos``) of
  equal-solid-angle bands, so that every source stands for about ``2 pi / n`` sr.
* :func:`geodesic_sources` -- the vertices of an icosahedron whose faces are cut into
  ``f x f`` triangles and pushed onto the sphere (class I geodesic), ``10 f^2 + 2`` on the
  sphere; on a hemisphere (a dome) those with ``d . axis >= 0``. ``f = 10`` gives a 526-node
  dome (about the 521 nodes Sato, Sato and Ikeuchi used). The cells' solid angles are near equal (their
  max/min ratio is given by :func:`cell_solid_angles`, measured in ``docs/probes.md``).
* :func:`model_sources` picks one by size.
* :func:`split_sources` -- adaptive sets: the geodesic sets of frequencies ``f0, 2 f0, 4 f0...``
  are nested (every vertex of one is a vertex of the next, the others are the midpoints of its
  edges), so they form a hierarchy, a quadtree on the sphere. A source of level ``L`` is split into
  its *children*: itself and the level ``L + 1`` midpoints of its edges (5 or 6, half its spacing). Split
  only where the light is, a small bright sun gets fine cells and the rest of the sky stays
  coarse (:func:`ffls.probes.selection.adaptive_hougen_ahuja` chooses where and how far).

To a light map
--------------
:func:`sources_to_latlong` spreads every source's intensity evenly over its angular Voronoi cell
(the cells of :mod:`ffls.weights.voronoi`, the same rule the relighter integrates a map with):
a texel of cell ``k`` gets radiance ``E_k / Omega_k`` with ``Omega_k`` the summed solid angle
of the cell's texels, so ``sum L dw`` over the map equals ``sum E_k`` exactly at every
resolution. An ambient term ``A`` (irradiance on any unshadowed normal) is uniform radiance
``A / pi`` over the whole sphere.
"""
from __future__ import annotations

import functools

import numpy as np
from scipy.spatial import cKDTree

from ffls.conventions import check_hemisphere, in_domain, latlong_directions, normalize, rotation_about_axis
from ffls.errors import InputError
from ffls.lightmaps.lightmap import LightMap
from ffls.lightmaps.sphere_maps import get_map
from ffls.weights.voronoi import assign_cells, cell_solid_angles

__all__ = [
    "HOUGEN_AHUJA_SIZES",
    "cell_energies",
    "ring_sources",
    "geodesic_sources",
    "geodesic_count",
    "geodesic_frequency_for",
    "geodesic_level",
    "split_sources",
    "model_sources",
    "frame_to_axis",
    "latlong_solid_angles",
    "sources_to_latlong",
    "cells_to_latlong",
    "to_lightmap",
    "cell_solid_angles",
]

#: Hougen and Ahuja's numbers of model sources, and the rings (after the pole) of each.
HOUGEN_AHUJA_SIZES = {5: (4,), 9: (8,), 17: (8, 8)}


def frame_to_axis(axis) -> np.ndarray:
    """Rotation (3, 3) that takes +Z to the unit vector ``axis`` (the identity for +Z).

    Parameters
    ----------
    axis : (3,) array_like
        Non-zero.

    Returns
    -------
    (3, 3) float64
    """
    a = normalize(np.asarray(axis, dtype=np.float64).reshape(3))
    if not np.any(a):
        raise ValueError("axis must be a non-zero vector")
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.clip(a @ z, -1.0, 1.0))
    if c > 1.0 - 1e-15:
        return np.eye(3)
    if c < -1.0 + 1e-15:
        return np.diag([1.0, -1.0, -1.0])
    return rotation_about_axis(np.cross(z, a), np.degrees(np.arccos(c)))


def ring_sources(n: int, axis=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Hougen and Ahuja's model sources: a pole and rings on the hemisphere around ``axis``.

    The hemisphere is cut into ``n`` bands of equal solid angle (``2 pi / n`` sr per source):
    a polar cap holding one source and, for each ring of ``m`` sources, a band of ``m`` cells.
    A ring sits at the middle of its band in ``cos(theta)``; successive rings are offset by half
    a step in azimuth.

    Parameters
    ----------
    n : {5, 9, 17}
    axis : (3,) array_like
        Pole of the hemisphere (world frame).

    Returns
    -------
    (n, 3) float64
        Unit directions; the pole first.
    """
    n = int(n)
    if n not in HOUGEN_AHUJA_SIZES:
        raise ValueError(f"ring sets have {sorted(HOUGEN_AHUJA_SIZES)} sources, not {n}")
    out = [np.array([0.0, 0.0, 1.0])]
    top = 1.0 - 1.0 / n  # cos of the polar cap's edge
    for k, m in enumerate(HOUGEN_AHUJA_SIZES[n]):
        bottom = top - m / n
        ct = 0.5 * (top + max(bottom, 0.0))
        st = np.sqrt(1.0 - ct * ct)
        phi = 2.0 * np.pi * (np.arange(m) + 0.5 * k) / m
        out.extend(np.stack([st * np.cos(phi), st * np.sin(phi), np.full(m, ct)], axis=1))
        top = bottom
    d = np.asarray(out)
    return normalize(d @ frame_to_axis(axis).T)


def _icosahedron() -> tuple[np.ndarray, np.ndarray]:
    """Vertices (12, 3), a vertex on +Z, and faces (20, 3) of the regular icosahedron."""
    z = 1.0 / np.sqrt(5.0)
    r = 2.0 / np.sqrt(5.0)
    ring = np.arange(5)
    up = np.stack([r * np.cos(2 * np.pi * ring / 5), r * np.sin(2 * np.pi * ring / 5), np.full(5, z)], axis=1)
    dn = np.stack([r * np.cos(2 * np.pi * (ring + 0.5) / 5), r * np.sin(2 * np.pi * (ring + 0.5) / 5),
                   np.full(5, -z)], axis=1)
    v = np.concatenate([[[0.0, 0.0, 1.0]], up, dn, [[0.0, 0.0, -1.0]]])
    faces = []
    for i in range(5):
        a, b = 1 + i, 1 + (i + 1) % 5
        c, d = 6 + i, 6 + (i + 1) % 5
        faces += [(0, a, b), (a, c, b), (b, c, d), (11, d, c)]
    return v, np.asarray(faces)


def geodesic_count(frequency: int, hemisphere="full") -> int:
    """Number of nodes of :func:`geodesic_sources` for ``frequency`` (no solve; for planning)."""
    return int(geodesic_sources(frequency, hemisphere).shape[0])


def geodesic_sources(frequency: int, hemisphere="full") -> np.ndarray:
    """Vertices of a class-I geodesic sphere or dome (icosahedron faces cut ``f x f``).

    Parameters
    ----------
    frequency : int
        ``f >= 1``; the sphere has ``10 f^2 + 2`` vertices (f = 1: the icosahedron's 12).
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}
        ``'full'``: every vertex. Otherwise the dome: the sphere is turned so that a vertex lies
        on the hemisphere's axis and the vertices with ``d . axis >= -1e-12`` are kept (those on
        the horizon are snapped onto it).

    Returns
    -------
    (n, 3) float64
        Unit directions, in a fixed order (by decreasing ``d . axis``, then azimuth).
    """
    f = int(frequency)
    if f < 1:
        raise ValueError(f"geodesic frequency must be >= 1, not {frequency!r}")
    hemi = check_hemisphere(hemisphere)
    v, faces = _icosahedron()
    i, j = np.meshgrid(np.arange(f + 1), np.arange(f + 1), indexing="ij")
    keep = (i + j) <= f
    a, b = i[keep] / f, j[keep] / f
    w = np.stack([1.0 - a - b, a, b], axis=1)  # barycentric weights (k, 3)
    pts = np.einsum("kc,fcx->fkx", w, v[faces]).reshape(-1, 3)
    pts = normalize(pts)
    # de-duplicate the shared edge points (exact up to rounding)
    key = np.round(pts * 1e9).astype(np.int64)
    _, first = np.unique(key, axis=0, return_index=True)
    pts = pts[np.sort(first)]
    axis = np.array([0.0, 0.0, 1.0]) if hemi.axis is None else np.asarray(hemi.axis, dtype=np.float64)
    if hemi.axis is not None:
        side = pts[:, 2]
        pts = pts[side >= -1e-12]
        on = np.abs(pts[:, 2]) <= 1e-12
        pts[on, 2] = 0.0
        pts = normalize(pts)
    order = np.lexsort((np.arctan2(pts[:, 1], pts[:, 0]), -np.round(pts[:, 2], 9)))
    pts = pts[order]
    return normalize(pts @ frame_to_axis(axis).T)


def geodesic_frequency_for(n: int, hemisphere="full") -> int:
    """The geodesic frequency whose node count is nearest ``n`` (ties to the smaller)."""
    n = int(n)
    if n < 1:
        raise ValueError(f"number of sources must be >= 1, not {n}")
    best, best_err = 1, None
    f = 1
    while True:
        c = geodesic_count(f, hemisphere)
        err = abs(c - n)
        if best_err is None or err < best_err:
            best, best_err = f, err
        if c > n:
            return best
        f += 1


def model_sources(n: int, hemisphere="full", axis=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A model source set by size.

    Parameters
    ----------
    n : int
        5, 9 or 17: :func:`ring_sources` around ``axis``. Anything else: the geodesic set of
        :func:`geodesic_sources` over ``hemisphere`` whose size is nearest ``n``.
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}
        Domain of geodesic sets.
    axis : (3,) array_like
        Pole of the ring sets.

    Returns
    -------
    (k, 3) float64
        Unit directions (``k == n`` for ring sets, near ``n`` for geodesic ones).
    """
    n = int(n)
    if n in HOUGEN_AHUJA_SIZES:
        return ring_sources(n, axis)
    return geodesic_sources(geodesic_frequency_for(n, hemisphere), hemisphere)


@functools.lru_cache(maxsize=32)
def _level_cached(frequency: int, axis) -> tuple[np.ndarray, cKDTree]:
    d = geodesic_sources(frequency, "full" if axis is None else {"axis": list(axis)})
    d.setflags(write=False)
    return d, cKDTree(d)


@functools.lru_cache(maxsize=32)
def _parents(frequency: int, axis) -> np.ndarray:
    """Parents (n_fine, 2) in the frequency-``f`` set of every vertex of the frequency-``2 f`` set.

    A vertex of both sets is its own parent (twice); a new vertex is the midpoint of an edge of
    the coarse set, and its parents are that edge's ends: its two nearest coarse vertices (the
    triangle's third vertex is sqrt(3) times farther). On a dome, a vertex whose edge's other end
    lies below the horizon goes to its two nearest dome vertices: the set still tiles the dome.
    """
    fine, _ = _level_cached(2 * frequency, axis)
    _, tree = _level_cached(frequency, axis)
    dist, idx = tree.query(fine, k=2)
    old = dist[:, 0] < 1e-9
    idx[old, 1] = idx[old, 0]
    idx.setflags(write=False)
    return idx


def geodesic_level(base_frequency: int, level: int, hemisphere="full") -> np.ndarray:
    """Level ``level`` of the geodesic hierarchy: :func:`geodesic_sources` of frequency ``base_frequency * 2**level``.

    Parameters
    ----------
    base_frequency : int
        Frequency of level 0 (3: 92 directions on the sphere, 51 on a dome).
    level : int
        ``>= 0``; every level holds the one before it.
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}

    Returns
    -------
    (n, 3) float64, read-only
    """
    if int(level) < 0:
        raise ValueError(f"level must be >= 0, not {level!r}")
    hemi = check_hemisphere(hemisphere)
    return _level_cached(int(base_frequency) * 2 ** int(level), hemi.axis)[0]


def split_sources(directions, levels, split, base_frequency: int, hemisphere="full"):
    """Replace the sources ``split`` of an adaptive set by their children one level finer.

    The children of a level-``L`` source ``s`` are ``s`` itself and the vertices of level
    ``L + 1`` (:func:`geodesic_level`) at the midpoints of the level-``L`` edges out of ``s``
    (an edge's midpoint is a child of both its ends and is kept once). The set stays a subset of the hierarchy's vertices, and
    its Voronoi cells tile the domain as before, finer where split.

    Parameters
    ----------
    directions : (n, 3) array_like
        Vertices of the hierarchy (a level, or an earlier output of this function).
    levels : (n,) array_like of int
        The level of each source.
    split : sequence of int or (n,) bool
        Sources to split.
    base_frequency : int
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}

    Returns
    -------
    directions : (n', 3) float64
        The sources not split, in their order, then the children of each split source.
    levels : (n',) int64

    Raises
    ------
    ValueError
        A source that is not a vertex of its level.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    lev = np.asarray(levels, dtype=np.int64).reshape(-1)
    if lev.shape[0] != d.shape[0]:
        raise ValueError(f"levels must be ({d.shape[0]},), not {lev.shape}")
    mask = np.zeros(d.shape[0], dtype=bool)
    mask[np.asarray(split).reshape(-1) if np.asarray(split).dtype != bool else np.flatnonzero(split)] = True
    hemi = check_hemisphere(hemisphere)
    keep_d, keep_l = [d[~mask]], [lev[~mask]]
    for s in np.flatnonzero(mask):
        L = int(lev[s])
        _, tree = _level_cached(int(base_frequency) * 2 ** L, hemi.axis)
        dist, _ = tree.query(d[s])
        if dist > 1e-9:
            raise ValueError(f"source {s} is not a vertex of level {L} of the frequency-{base_frequency} hierarchy")
        fine, _ = _level_cached(int(base_frequency) * 2 ** (L + 1), hemi.axis)
        _, own = tree.query(d[s])
        # an edge's midpoint is a child of both its ends
        kids = fine[np.any(_parents(int(base_frequency) * 2 ** L, hemi.axis) == own, axis=1)]
        keep_d.append(kids)
        keep_l.append(np.full(kids.shape[0], L + 1, dtype=np.int64))
    out_d, out_l = np.concatenate(keep_d), np.concatenate(keep_l)
    # a midpoint shared by two split sources is kept once
    _, first = np.unique(np.round(out_d * 1e9).astype(np.int64), axis=0, return_index=True)
    first = np.sort(first)
    return out_d[first], out_l[first]


def latlong_solid_angles(height: int) -> np.ndarray:
    """Exact texel solid angles (height, 2 height) float64 of a lat-long map (sum 4 pi)."""
    h = int(height)
    return np.asarray(get_map("latlong").solid_angles(h), dtype=np.float64).reshape(h, 2 * h)


def sources_to_latlong(directions, intensities, height: int = 64, hemisphere="full", ambient=None,
                       outside=None) -> np.ndarray:
    """Spread source intensities over their angular Voronoi cells on a lat-long map.

    Parameters
    ----------
    directions : (n, 3) array_like
        Source directions (world frame).
    intensities : (n,) or (n, 3) array_like
        Irradiance at normal incidence of each source (may be negative for an unconstrained
        least-squares solution).
    height : int
        Map height (width ``2 height``).
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}
        Texels outside the domain get no source light (0).
    ambient : float or (3,) array_like, optional
        Ambient irradiance ``A``: uniform radiance ``A / pi`` added to every texel of the sphere.
    outside : float or (3,) array_like, optional
        Power spread as uniform radiance over the texels outside ``hemisphere`` (the light from
        below a ground plane, :func:`ffls.probes.hougen_ahuja.hougen_ahuja`'s ``ground``), exact
        in energy like the sources' cells.

    Returns
    -------
    (height, 2 height, 3) float64
        Radiance; ``sum L dw`` over the domain equals ``intensities.sum(0)`` exactly (plus
        ``4 A`` for the ambient term). A cell holding no texel centre (more sources than texels
        nearby) gives its intensity to the texel nearest its source.
    """
    h = int(height)
    if h < 2:
        raise ValueError(f"map height must be >= 2, not {height!r}")
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    e = np.asarray(intensities, dtype=np.float64)
    if e.ndim == 1:
        e = np.repeat(e[:, None], 3, axis=1)
    if e.shape != (d.shape[0], 3):
        raise ValueError(f"intensities must be (n,) or (n, 3) for {d.shape[0]} sources, not {e.shape}")
    texels = latlong_directions(2 * h, h).reshape(-1, 3)
    sa = latlong_solid_angles(h).ravel()
    inside = in_domain(texels, hemisphere)
    idx = np.full(texels.shape[0], -1, dtype=np.int64)
    idx[inside] = assign_cells(texels[inside], d)
    n = d.shape[0]
    hit = idx >= 0
    omega = np.bincount(idx[hit], weights=sa[hit], minlength=n)
    out = np.zeros((texels.shape[0], 3))
    has = omega > 0
    out[hit] = e[idx[hit]] / np.where(has, omega, 1.0)[idx[hit], None]
    for k in np.flatnonzero(~has):
        cand = np.flatnonzero(inside) if inside.any() else np.arange(texels.shape[0])
        t = cand[np.argmax(texels[cand] @ normalize(d[k]))]
        out[t] += e[k] / sa[t]
    if outside is not None and not inside.all():
        out[~inside] += np.broadcast_to(np.asarray(outside, dtype=np.float64), (3,)) / sa[~inside].sum()
    if ambient is not None:
        out += np.broadcast_to(np.asarray(ambient, dtype=np.float64), (3,)) / np.pi
    return out.reshape(h, 2 * h, 3)


def cell_energies(directions, radiance, hemisphere="full") -> np.ndarray:
    """The power of a lat-long map in each source's angular Voronoi cell: the map as the model holds it.

    ``sources_to_latlong(directions, cell_energies(directions, L), h, hemisphere)`` is the best
    a source model can do (every source exact): what it loses against ``L`` is the error of the
    discretisation itself, not of the estimate.

    Parameters
    ----------
    directions : (n, 3) array_like
        Source directions.
    radiance : (h, 2h, 3) array_like
        Lat-long radiance.
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}
        Texels outside the domain are left out.

    Returns
    -------
    (n, 3) float64
        ``sum L dw`` over each cell's texels (irradiance at normal incidence, the unit of
        :class:`ffls.probes.hougen_ahuja.SourceFit` intensities).
    """
    L = np.asarray(radiance, dtype=np.float64)
    h = L.shape[0]
    if L.shape != (h, 2 * h, 3):
        raise ValueError(f"radiance must be (h, 2h, 3), not {L.shape}")
    d = normalize(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
    texels = latlong_directions(2 * h, h).reshape(-1, 3)
    sa = latlong_solid_angles(h).ravel()
    inside = in_domain(texels, hemisphere)
    idx = assign_cells(texels[inside], d)
    p = L.reshape(-1, 3)[inside] * sa[inside, None]
    return np.stack([np.bincount(idx, weights=p[:, c], minlength=d.shape[0]) for c in range(3)], axis=1)


def cells_to_latlong(directions, values, height: int = 64, hemisphere="full") -> np.ndarray:
    """Give every lat-long texel the value of its source's cell (nearest by angle; 0 outside the domain).

    Parameters
    ----------
    directions : (n, 3) array_like
    values : (n,) array_like
        Per-source values (a confidence, a 0/1 "seen" flag...).
    height : int
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}

    Returns
    -------
    (height, 2 height) float64
    """
    h = int(height)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    texels = latlong_directions(2 * h, h).reshape(-1, 3)
    inside = in_domain(texels, hemisphere)
    out = np.zeros(texels.shape[0])
    out[inside] = v[assign_cells(texels[inside], d)]
    return out.reshape(h, 2 * h)


def to_lightmap(radiance, source: str = "probe") -> tuple[LightMap, int]:
    """A :class:`LightMap` from a lat-long radiance array that may hold negative values.

    Unconstrained least squares can give negative radiance; a light map cannot hold it. The
    negative texels are set to 0 and counted, never silently: the count is returned for the
    caller to report.

    Parameters
    ----------
    radiance : (H, 2H, 3) array_like
    source : str
        The map's ``source`` label.

    Returns
    -------
    lightmap : LightMap
        Lat-long, float32.
    clipped : int
        Number of texels that had a negative channel.
    """
    r = np.asarray(radiance, dtype=np.float64)
    if not np.all(np.isfinite(r)):
        raise InputError("the recovered light map holds NaN or Inf")
    neg = np.any(r < 0, axis=-1)
    return LightMap(np.maximum(r, 0.0).astype(np.float32), "latlong", source), int(np.count_nonzero(neg))
