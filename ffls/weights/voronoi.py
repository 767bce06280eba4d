"""Angular Voronoi weighting of a light map over the captured light directions.

Masselus, Dutre, Anrys, "The Free-form Light Stage", EGWR 2002, section 6: every light-map
texel represents a small solid angle of incident light; it is given to the captured light
direction nearest to it *by angle* (an angular Voronoi diagram on the sphere), and the weight of
basis image ``i`` is the sum of ``radiance * solid_angle`` over the texels of cell ``i``.

Two ways to find the cell of a texel, with one tie rule:

* ``cells=None`` -- the float64 reference. A :class:`scipy.spatial.cKDTree` over the unit light
  vectors (chord order is angle order on the unit sphere) proposes the two nearest lights, and
  the winner is the larger dot product ``d . l`` (computed by :func:`_dots`), ties to the lowest
  light index.
* a :class:`CellTexture` (``bake_cells``) -- what the GPU does too. A texture over the
  concentric map (upper hemisphere) or the octahedral map (full sphere) stores, per texel, a
  *conservative candidate list*: every light whose Voronoi cell can intersect the texel. A
  rotated light-map direction is looked up with the map's ``texel_index`` and given to the
  candidate with the largest dot product (the same :func:`_dots`), ties to the lowest index
  (candidates are stored in increasing index order, so the first maximum wins). Because the true
  nearest light is always a candidate, this assignment equals the reference one exactly.

Why the candidate list is conservative: let ``c`` be a texel centre, ``r`` the texel's angular
radius (the largest angle from ``c`` to its corners and edge midpoints, padded by 5 % + 1e-9 rad)
and ``n`` the light nearest to ``c``. A light ``j`` can own a point ``p`` of the texel only if
``p . (j - n) >= 0`` for some ``p`` within ``r`` of ``c``, i.e. only if the bisector great circle
of ``n`` and ``j`` passes within ``r`` of ``c``: ``c . (n - j) <= |n - j| sin r``. The baker keeps
every such ``j`` (after the triangle-inequality prefilter ``angle(c, j) <= angle(c, n) + 2 r``).
If more than ``k`` qualify, the ``k`` nearest are kept and the texel counts in ``overflow``;
only then can the lookup differ from the reference. See ``docs/voronoi.md`` for measurements.

Exact duplicates: directions are de-duplicated before anything else; the first occurrence
(lowest index) keeps the cell and every later copy gets an empty cell (weight 0). Nearly equal
but different directions are distinct points and split the cell between them.

Dropped light: for the ``upper`` hemisphere, texels whose rotated direction has ``z < 0`` are
dropped; their count and power are reported in :class:`Weights`. ``z == 0`` is kept. For a
hemisphere around another axis (:class:`ffls.conventions.Hemisphere`) the test is
``d . axis >= 0`` and the cells are baked over the full sphere's octahedral map (the lookup is
exact there too; half of the texture lies outside the domain and is never read).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ffls.conventions import (
    check_hemisphere,
    covered_solid_angle,
    in_domain,
    is_rotation,
    latlong_directions,
    rotate_directions,
)
from ffls.lightmaps.lightmap import sample_bands_of

__all__ = [
    "CellTexture",
    "Weights",
    "MAP_FOR_HEMISPHERE",
    "cell_map_name",
    "bake_cells",
    "integrate_weights",
    "assign_cells",
    "cell_solid_angles",
    "unique_directions",
    "Coverage",
    "coverage",
    "coverage_warnings",
]

#: The sphere parameterisation a cell texture uses for each named hemisphere (any other axis:
#: ``'octahedral'``, see :func:`cell_map_name`).
MAP_FOR_HEMISPHERE = {"upper": "concentric", "full": "octahedral"}

#: Relative and absolute slack added to the candidate radius ``a + 2 r``.
CANDIDATE_REL_SLACK = 0.05
CANDIDATE_ABS_SLACK = 1e-9

#: Lights with 0 <= z <= this count as on the horizon in :func:`cell_solid_angles`.
_HORIZON_EPS = 1e-9


# ----------------------------------------------------------------------------- helpers
def _check_directions(directions) -> np.ndarray:
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim == 1 and d.shape == (3,):
        d = d[None, :]
    if d.ndim != 2 or d.shape[1] != 3 or d.shape[0] < 1:
        raise ValueError(f"directions must have shape (n, 3) with n >= 1, not {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ValueError("directions contain NaN or Inf")
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    if np.any(norm == 0):
        raise ValueError("directions contain a zero vector")
    return d / norm


def unique_directions(directions) -> tuple[np.ndarray, np.ndarray]:
    """De-duplicate light directions, keeping the first (lowest-index) occurrence.

    Parameters
    ----------
    directions : (n, 3) array_like
        Light directions; normalised here.

    Returns
    -------
    unit : (n, 3) float64
        The normalised directions.
    keep : (u,) int64
        Increasing indices into ``directions`` of the first occurrence of every distinct unit
        vector (bitwise equality after normalisation).
    """
    d = _check_directions(directions)
    d = d + 0.0  # turn -0.0 into +0.0 so that equal vectors compare equal bytewise
    _, first = np.unique(d, axis=0, return_index=True)
    return d, np.sort(first)


def _dots(p: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """Dot products ``p . l`` in one fixed float64 operation order (shared by both assigners).

    Parameters
    ----------
    p : (m, 3) float64
    lights : (m, k, 3) float64

    Returns
    -------
    (m, k) float64
    """
    return (p[:, None, 0] * lights[..., 0] + p[:, None, 1] * lights[..., 1]) + p[:, None, 2] * lights[..., 2]


def _argmax_lowest(dots: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """Per row, the candidate with the largest dot; ties to the lowest candidate index.

    ``cand`` rows may be in any order and contain -1 padding (whose dots must be -inf).
    """
    best = dots.max(axis=1, keepdims=True)
    big = np.iinfo(np.int64).max
    return np.where(dots == best, cand.astype(np.int64), big).min(axis=1)


def _chord_to_angle(chord: np.ndarray) -> np.ndarray:
    return 2.0 * np.arcsin(np.clip(0.5 * chord, 0.0, 1.0))


def _angle_to_chord(angle: np.ndarray) -> np.ndarray:
    return 2.0 * np.sin(0.5 * np.minimum(angle, np.pi))


def cell_map_name(hemisphere) -> str:
    """The sphere map a cell texture uses: ``'concentric'`` for ``upper``, else ``'octahedral'``."""
    return "concentric" if check_hemisphere(hemisphere) == "upper" else "octahedral"


def _get_map(hemisphere):
    from ffls.lightmaps.sphere_maps import get_map  # written alongside; imported lazily

    return get_map(cell_map_name(hemisphere))


# ----------------------------------------------------------------------------- cell texture
@dataclass(frozen=True)
class CellTexture:
    """Angular Voronoi cells of a set of light directions, baked into a sphere-map texture.

    Attributes
    ----------
    index : (res, res) int32
        The nearest light (by angle; ties to the lowest index) at each texel centre, -1 where
        the map has no valid texel.
    candidates : (res, res, k) int32
        Every light whose Voronoi cell can intersect the texel, in increasing index order,
        padded with -1 (see the module docstring for the bound). Where more than ``k`` lights
        qualify, the ``k`` nearest to the centre are kept (then re-sorted by index).
    overflow : int
        Number of texels that had more than ``k`` candidates (0 means the lookup is exact).
    res : int
        Texture resolution (square).
    hemisphere : ffls.conventions.Hemisphere
        ``'upper'`` (concentric map), ``'full'`` or another axis (octahedral map).
    map_name : str
        Name of the :mod:`ffls.lightmaps.sphere_maps` parameterisation.
    directions : (n, 3) float64
        The normalised light directions the cells were built from (duplicates included).
    k : int
        Candidate slots per texel.
    texel_radius : (res, res) float64
        Angular radius (rad) of every texel: largest angle from its centre to its boundary
        (corners and edge midpoints), before the slack; NaN for texels that the hierarchical
        bake settled at a coarser level (inside one cell).
    """

    index: np.ndarray
    candidates: np.ndarray
    overflow: int
    res: int
    hemisphere: object
    map_name: str
    directions: np.ndarray
    k: int
    texel_radius: np.ndarray

    @property
    def n_lights(self) -> int:
        return int(self.directions.shape[0])

    def texel_of(self, d: np.ndarray) -> np.ndarray:
        """Flat texel index (-1 outside the map's domain) of directions ``d`` (m, 3)."""
        smap = _get_map(self.hemisphere)
        idx = smap.texel_index(np.asarray(d, dtype=np.float64), self.res)
        if isinstance(idx, tuple):  # (row, col) form: flatten, keeping -1 outside
            rows, cols = (np.asarray(a, dtype=np.int64) for a in idx)
            out = rows * self.res + cols
            return np.where((rows < 0) | (cols < 0), -1, out)
        return np.asarray(idx, dtype=np.int64)

    def assign(self, d: np.ndarray) -> np.ndarray:
        """Cell (light index) of each direction (m, 3) by candidate lookup; -1 outside the map."""
        d = np.asarray(d, dtype=np.float64)
        t = self.texel_of(d).astype(np.int64).reshape(-1)
        out = np.full(t.shape, -1, dtype=np.int64)
        ok = t >= 0
        if np.any(ok):
            cand = self.candidates.reshape(-1, self.k)[t[ok]]
            out[ok] = _assign_from_candidates(d.reshape(-1, 3)[ok], cand, self.directions)
        return out


def _assign_from_candidates(p: np.ndarray, cand: np.ndarray, lights: np.ndarray, chunk: int = 1 << 17) -> np.ndarray:
    """Max dot among ``cand`` (m, k) for directions ``p`` (m, 3); ties to the lowest index.

    A texel with a single candidate needs no dot product (most texels, away from cell edges);
    the others are evaluated on only as many columns as the fullest row uses.
    """
    cand = np.asarray(cand)
    out = cand[:, 0].astype(np.int64)
    if cand.shape[1] == 1:
        return out
    multi = np.flatnonzero(cand[:, 1] >= 0)
    if multi.size == 0:
        return out
    cm = cand[multi]
    width = int((cm >= 0).sum(axis=1).max())
    cm = cm[:, :width].astype(np.int64)
    pm = p[multi]
    padded = np.concatenate([lights, np.zeros((1, 3))], axis=0)  # row -1 -> zeros, masked below
    for s in range(0, multi.size, chunk):
        c = cm[s:s + chunk]
        dots = _dots(pm[s:s + chunk], padded[c])
        dots[c < 0] = -np.inf
        out[multi[s:s + chunk]] = _argmax_lowest(dots, c)
    return out


def _texel_geometry(smap, res: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texel centres (res, res, 3), angular radii (res, res) and validity (res, res).

    The radius is the largest angle from the centre to the texel's four corners and four edge
    midpoints, evaluated with the map's ``uv_to_direction`` on a half-texel grid. The uv axis
    order (u along columns) is checked against ``directions(res)``.
    """
    centres = np.asarray(smap.directions(res), dtype=np.float64)
    valid = np.asarray(smap.valid_mask(res), dtype=bool) & np.all(np.isfinite(centres), axis=-1)
    t = np.arange(2 * res + 1) / (2.0 * res)
    uu, vv = np.meshgrid(t, t)  # [row, col]: u varies along columns
    grid = np.asarray(smap.uv_to_direction(np.stack([uu, vv], axis=-1)), dtype=np.float64)
    mid = grid[1::2, 1::2]
    ok = valid & np.all(np.isfinite(mid), axis=-1)
    if not np.allclose(mid[ok], centres[ok], atol=1e-9):
        grid = np.swapaxes(grid, 0, 1)  # the map puts u along rows
        mid = grid[1::2, 1::2]
        if not np.allclose(mid[ok], centres[ok], atol=1e-9):
            raise RuntimeError("sphere map uv_to_direction disagrees with directions(res)")
    cz = np.where(valid[..., None], centres, 0.0)
    chord = np.zeros((res, res))
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            if di == 1 and dj == 1:
                continue
            b = grid[di:di + 2 * res:2, dj:dj + 2 * res:2] - cz
            chord = np.fmax(chord, np.sqrt(np.einsum("ijk,ijk->ij", b, b)))  # fmax skips NaN
    return centres, _chord_to_angle(chord), valid


def _candidate_rows(unit: np.ndarray, keep: np.ndarray, tree: cKDTree, q: np.ndarray, rad: np.ndarray,
                    k: int, k_query: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Candidates of texels with centres ``q`` (m, 3) and padded angular radii ``rad`` (m,).

    Returns ``cand`` (m, k) original light indices (-1 padded, nearest first), ``nearest`` (m,)
    (max dot at the centre, ties to the lowest index) and ``count`` (m,) (candidates before
    truncation to ``k``).
    """
    m = q.shape[0]
    nu = keep.size
    kq = min(k + 4 if k_query is None else k_query, nu)
    dist, idx = tree.query(q, k=kq)
    dist = dist.reshape(m, kq)
    idx = idx.reshape(m, kq)
    ang = _chord_to_angle(dist)
    # triangle-inequality prefilter: a light j can own part of the texel only if
    # angle(c, j) <= angle(c, nearest) + 2 r
    reach = ang[:, 0] + 2.0 * rad
    rows = [(np.arange(m), idx, ang)]
    more = np.flatnonzero(ang[:, -1] <= reach) if kq < nu else np.zeros(0, dtype=np.int64)
    if more.size:  # rare: more than k_query lights in reach; gather them all
        lists = tree.query_ball_point(q[more], _angle_to_chord(reach[more]) * (1 + 1e-12) + 1e-15)
        width = max(len(x) for x in lists)
        big = np.full((more.size, width), -1, dtype=np.int64)
        for r, lst in enumerate(lists):
            big[r, :len(lst)] = lst
        bang = np.where(big >= 0, np.arccos(np.clip(np.einsum("mi,mki->mk", q[more], unit[keep][np.maximum(big, 0)]), -1, 1)), np.inf)
        order = np.argsort(bang, axis=1, kind="stable")
        rows.append((more, np.take_along_axis(big, order, 1), np.take_along_axis(bang, order, 1)))
    cand = np.full((m, k), -1, dtype=np.int64)
    count = np.zeros(m, dtype=np.int64)
    nearest = np.empty(m, dtype=np.int64)
    for sel, ii, aa in rows:
        qs = q[sel]
        # exact nearest at the centre: max dot among the two nearest, ties to the lowest index
        k2 = min(2, ii.shape[1])
        lit2 = keep[ii[:, :k2]]
        nearest[sel] = _argmax_lowest(_dots(qs, unit[lit2]), lit2)
        # j can own a point p of the texel (angle(p, c) <= r) only if p . (j - n) >= 0 for
        # some such p, i.e. the angle from c to the bisector great circle of n and j is <= r:
        #     c . (n - j) <= |n - j| sin(r)
        # tested only where the triangle prefilter passes (few entries per row)
        ok = (aa <= reach[sel][:, None] + 1e-12) & (ii >= 0)
        r_i, c_i = np.nonzero(ok)
        lit = keep[ii[r_i, c_i]]
        diff = unit[nearest[sel][r_i]] - unit[lit]
        lhs = np.einsum("si,si->s", qs[r_i], diff)
        rhs = np.sqrt(np.einsum("si,si->s", diff, diff)) * np.sin(np.minimum(rad[sel][r_i], np.pi / 2))
        ok[r_i, c_i] = (lhs <= rhs) | (lit == nearest[sel][r_i])
        count[sel] = ok.sum(axis=1)
        # keep the k nearest qualifying lights (columns are in distance order)
        rank = np.cumsum(ok, axis=1) - 1
        put = ok & (rank < k)
        r_idx, c_idx = np.nonzero(put)
        cand[sel[r_idx], rank[r_idx, c_idx]] = keep[ii[r_idx, c_idx]]
    return cand, nearest, count


#: The hierarchical bake starts at this resolution or below (``_bake``).
_COARSE_RES = 64
#: Boundary points per texel edge (corners included) for the radius of a coarse texel.
_COARSE_EDGE_POINTS = 3


def _subset_geometry(smap, res: int, flat: np.ndarray, edge_points: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Centres (m, 3) and angular radii (m,) of texels ``flat`` (row-major) at ``res``.

    The radius is the largest angle from the centre to ``edge_points`` points along each edge
    (corners included; 3 = corners and edge midpoints, as :func:`_texel_geometry`). The maps
    used here (concentric, octahedral) put u along columns (:meth:`SphereMap.texel_centers_uv`).
    """
    row = (flat // res).astype(np.float64)
    col = (flat % res).astype(np.float64)
    centre = np.asarray(smap.uv_to_direction(np.stack([(col + 0.5) / res, (row + 0.5) / res], -1)), dtype=np.float64)
    t = np.linspace(0.0, 1.0, int(edge_points))
    ring = np.unique(np.concatenate([np.stack([t, np.zeros_like(t)], 1), np.stack([t, np.ones_like(t)], 1),
                                     np.stack([np.zeros_like(t), t], 1), np.stack([np.ones_like(t), t], 1)]), axis=0)
    chord = np.zeros(flat.size)
    for du, dv in ring:
        b = np.asarray(smap.uv_to_direction(np.stack([(col + du) / res, (row + dv) / res], -1)), dtype=np.float64)
        chord = np.fmax(chord, np.linalg.norm(b - centre, axis=1))
    return centre, _chord_to_angle(chord)


def _bake_direct(unit, keep, smap, res, k, hemisphere, map_name) -> CellTexture:
    centres, radius, valid = _texel_geometry(smap, res)
    tree = cKDTree(unit[keep])
    q = centres[valid]
    rad = radius[valid] * (1.0 + CANDIDATE_REL_SLACK) + CANDIDATE_ABS_SLACK
    cand, nearest, count = _candidate_rows(unit, keep, tree, q, rad, k)
    overflow = int(np.count_nonzero(count > k))
    # increasing index order, -1 padding last (so the first maximum is the lowest index)
    key = np.where(cand < 0, np.iinfo(np.int64).max, cand)
    cand = np.take_along_axis(cand, np.argsort(key, axis=1, kind="stable"), axis=1)
    index = np.full((res, res), -1, dtype=np.int32)
    index[valid] = nearest
    candidates = np.full((res, res, k), -1, dtype=np.int32)
    candidates[valid] = cand
    return CellTexture(index=index, candidates=candidates, overflow=overflow, res=res, hemisphere=hemisphere,
                       map_name=map_name, directions=unit, k=k, texel_radius=radius)


def _levels(res: int) -> list:
    """Resolutions of the hierarchical bake, coarse to fine (each half the next)."""
    levels = [res]
    while levels[0] > _COARSE_RES and levels[0] % 2 == 0:  # halving: the least refined work (measured)
        levels.insert(0, levels[0] // 2)
    return levels


def _bake(unit: np.ndarray, keep: np.ndarray, smap, res: int, k: int, hemisphere: str, map_name: str) -> CellTexture:
    """Candidate texture, hierarchically: a coarse texel inside one cell gives it to all its sub-texels.

    A texel at a coarse level whose conservative candidate list (the same test as at full
    resolution, with its own larger radius) holds one light lies entirely inside that light's
    cell, and so does every finer texel it contains: they get that single candidate (and it is
    the exact cell of their centres) without a query. Only the texels of coarse texels with
    several candidates are refined, level by level; the finest level runs the usual bake on
    them. The lookup equals the reference exactly as before (tests/test_voronoi.py); the lists
    can only be shorter than a direct bake's. Maps with invalid texels bake directly.
    """
    levels = _levels(res)
    if len(levels) == 1 or not np.all(smap.valid_mask(levels[0])):
        return _bake_direct(unit, keep, smap, res, k, hemisphere, map_name)
    tree = cKDTree(unit[keep])
    single = np.full(res * res, -1, dtype=np.int64)  # light of texels settled at a coarse level
    todo = np.arange(levels[0] * levels[0], dtype=np.int64)  # texels to examine at the current level
    for li, r in enumerate(levels[:-1]):
        q, rad = _subset_geometry(smap, r, todo, _COARSE_EDGE_POINTS)
        rad = rad * (1.0 + CANDIDATE_REL_SLACK) + CANDIDATE_ABS_SLACK
        cand, nearest, count = _candidate_rows(unit, keep, tree, q, rad, 1)
        f_to_fine = res // r
        one = count == 1
        # settle the fine texels under single-candidate coarse texels
        rows, cols = np.divmod(todo[one], r)
        sub = np.arange(f_to_fine)
        fr = (rows[:, None] * f_to_fine + sub[None, :])[:, :, None]
        fc = (cols[:, None] * f_to_fine + sub[None, :])[:, None, :]
        single[(fr * res + fc).reshape(-1)] = np.repeat(nearest[one], f_to_fine * f_to_fine)
        # children of the others at the next level
        nr = levels[li + 1]
        g = nr // r
        rows, cols = np.divmod(todo[~one], r)
        sub = np.arange(g)
        cr = (rows[:, None] * g + sub[None, :])[:, :, None]
        cc = (cols[:, None] * g + sub[None, :])[:, None, :]
        todo = (cr * nr + cc).reshape(-1)
    index = np.full(res * res, -1, dtype=np.int32)
    candidates = np.full((res * res, k), -1, dtype=np.int32)
    settled = single >= 0
    index[settled] = single[settled]
    candidates[settled, 0] = single[settled]
    overflow = 0
    if todo.size:
        q, radius = _subset_geometry(smap, res, todo)
        rad = radius * (1.0 + CANDIDATE_REL_SLACK) + CANDIDATE_ABS_SLACK
        # few lights are in reach of a small texel: query 6 (more in reach are gathered exactly)
        cand, nearest, count = _candidate_rows(unit, keep, tree, q, rad, k, k_query=min(k + 4, 6))
        overflow = int(np.count_nonzero(count > k))
        key = np.where(cand < 0, np.iinfo(np.int64).max, cand)
        cand = np.take_along_axis(cand, np.argsort(key, axis=1, kind="stable"), axis=1)
        index[todo] = nearest
        candidates[todo] = cand
    texel_radius = np.full(res * res, np.nan)
    if todo.size:
        texel_radius[todo] = radius
    return CellTexture(index=index.reshape(res, res), candidates=candidates.reshape(res, res, k), overflow=overflow,
                       res=res, hemisphere=hemisphere, map_name=map_name, directions=unit, k=k,
                       texel_radius=texel_radius.reshape(res, res))


def bake_cells(directions, hemisphere: str = "upper", res: int = 256, k: int = 8, max_res: int | None = None,
               method: str = "hierarchical") -> CellTexture:
    """Bake the angular Voronoi cells of ``directions`` into a candidate texture.

    Parameters
    ----------
    directions : (n, 3) array_like
        Light directions in the capture/world frame (normalised here). Duplicates allowed.
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
        ``'upper'`` bakes over the concentric map (z >= 0), the others over the octahedral map.
    res : int
        Texture resolution (res x res texels).
    k : int
        Candidate slots per texel (the GPU twin reads ``k`` ints per texel).
    max_res : int, optional
        If given and the bake at ``res`` overflows (some texel has more than ``k`` candidates),
        ``res`` is doubled until the overflow is 0 or ``max_res`` is reached; the last bake is
        returned and its ``overflow`` says whether the lookup is exact. Default: no retry.
    method : {'hierarchical', 'direct'}
        ``'hierarchical'`` (default): texels settled at coarser levels where one cell covers a
        whole coarse texel, only the rest refined (docs/voronoi.md, "Bake speed"); ``'direct'``:
        every texel queried at full resolution. Both give the exact lookup.

    Returns
    -------
    CellTexture
    """
    hemisphere = check_hemisphere(hemisphere)
    if int(k) < 1 or int(res) < 1:
        raise ValueError("res and k must be positive")
    if method not in ("hierarchical", "direct"):
        raise ValueError(f"method must be 'hierarchical' or 'direct', not {method!r}")
    bake = _bake if method == "hierarchical" else _bake_direct
    unit, keep = unique_directions(directions)
    map_name = cell_map_name(hemisphere)
    smap = _get_map(hemisphere)
    res = int(res)
    while True:
        cells = bake(unit, keep, smap, res, int(k), hemisphere, map_name)
        if cells.overflow == 0 or max_res is None or 2 * res > int(max_res):
            return cells
        res *= 2


# ----------------------------------------------------------------------------- integration
@dataclass(frozen=True)
class Weights:
    """Per-light weights of a light map.

    Attributes
    ----------
    weights : (n, 3) float64
        Sum of ``radiance * solid_angle`` over the texels in each light's Voronoi cell
        (irradiance units, W m^-2). Later exact duplicates get 0.
    dropped_texels : int
        Light-map texels not given to any light (rotated below the horizon for ``upper``).
    dropped_power : (3,) float64
        Their summed ``radiance * solid_angle``.
    total_power : (3,) float64
        ``radiance * solid_angle`` over every texel; ``weights.sum(0) + dropped_power`` equals it
        up to float64 rounding.
    """

    weights: np.ndarray
    dropped_texels: int
    dropped_power: np.ndarray
    total_power: np.ndarray


def assign_cells(p, directions, cells: CellTexture | None = None) -> np.ndarray:
    """Angular Voronoi cell (light index) of each direction.

    Parameters
    ----------
    p : (m, 3) array_like
        Unit directions (already rotated, in the capture frame).
    directions : (n, 3) array_like
        Light directions.
    cells : CellTexture, optional
        ``None``: k-d tree reference. Otherwise the candidate lookup (``cells`` must be baked
        from the same directions).

    Returns
    -------
    (m,) int64
        Light index, ties to the lowest index; -1 where ``cells`` has no texel for ``p``.
    """
    p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
    if cells is not None:
        return cells.assign(p)
    unit, keep = unique_directions(directions)
    kq = min(2, keep.size)
    out = np.empty(p.shape[0], dtype=np.int64)
    tree = cKDTree(unit[keep])
    chunk = 1 << 18
    for s in range(0, p.shape[0], chunk):
        ps = p[s:s + chunk]
        _, idx = tree.query(ps, k=kq)
        idx = keep[np.asarray(idx).reshape(ps.shape[0], kq)]
        out[s:s + chunk] = _argmax_lowest(_dots(ps, unit[idx]), idx)
    return out


def integrate_weights(lightmap_or_samples, directions, rotation=None, hemisphere: str = "upper",
                      cells: CellTexture | None = None, method: str = "MasselusDutreAnrys2002") -> Weights:
    """Integrate a light map over the angular Voronoi cells of the light directions.

    Masselus, Dutre, Anrys 2002, section 6: every texel adds ``radiance * solid_angle`` to the
    cell that its rotated direction ``R d`` falls in.

    Parameters
    ----------
    lightmap_or_samples : LightMap or tuple
        A :class:`ffls.lightmaps.lightmap.LightMap` (its ``samples()`` are used) or a tuple
        ``(dirs (M, 3), radiance (M, 3), solid_angle (M,))`` of valid texels.
    directions : (n, 3) array_like
        Light directions in the capture frame.
    rotation : (3, 3) array_like, optional
        Light-map rotation (content at ``d`` moves to ``R d``); identity by default.
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
        Texels whose rotated direction is outside (``z < 0`` for ``'upper'``, ``d . axis < 0``)
        are dropped and counted.
    cells : CellTexture, optional
        ``None``: exact k-d tree assignment (float64 reference). A CellTexture baked from the
        same directions: candidate-texture lookup (what the GPU does); identical cells while
        ``cells.overflow == 0``. Directions outside the texture's map are dropped and counted.
    method : str
        Only ``'MasselusDutreAnrys2002'`` (nearest light by angle).

    Returns
    -------
    Weights
    """
    if method != "MasselusDutreAnrys2002":
        raise ValueError(f"unknown method {method!r}")
    hemisphere = check_hemisphere(hemisphere)
    unit = _check_directions(directions)
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    if not is_rotation(R):
        raise ValueError("rotation must be a 3x3 rotation matrix")
    if cells is not None:
        if cells.hemisphere != hemisphere or cells.directions.shape != unit.shape or not np.array_equal(cells.directions, unit):
            raise ValueError("cells were baked for other directions or another hemisphere")
    n = unit.shape[0]
    w, total, lost, n_lost = np.zeros((n, 3)), np.zeros(3), np.zeros(3), 0
    # a lat-long map in bands of rows (an 8192 x 4096 map's samples at once held 6.3 GB)
    for dirs, rad, sa in sample_bands_of(lightmap_or_samples):
        power = rad * sa[:, None]
        total += power.sum(axis=0)
        p = rotate_directions(R, dirs)
        keep = in_domain(p, hemisphere)
        idx = np.full(p.shape[0], -1, dtype=np.int64)
        if np.any(keep):
            idx[keep] = assign_cells(p[keep], unit, cells)
        hit = idx >= 0
        w += np.stack([np.bincount(idx[hit], weights=power[hit, c], minlength=n) for c in range(3)], axis=1)
        dropped = ~hit
        n_lost += int(np.count_nonzero(dropped))
        lost += power[dropped].sum(axis=0)
    return Weights(weights=w, dropped_texels=n_lost, dropped_power=lost, total_power=total)


# ----------------------------------------------------------------------------- cell areas
def _latlong_samples(height: int) -> tuple[np.ndarray, np.ndarray]:
    """Directions (M, 3) and exact solid angles (M,) of a 2h x h lat-long grid."""
    width = 2 * height
    d = latlong_directions(width, height).reshape(-1, 3)
    edges = np.cos(np.pi * np.arange(height + 1) / height)
    row = (edges[:-1] - edges[1:]) * (2.0 * np.pi / width)
    return d, np.repeat(row, width)


def cell_solid_angles(directions, hemisphere: str = "upper", method: str = "auto", res: int = 1024) -> np.ndarray:
    """Solid angle (sr) of every light's angular Voronoi cell within the covered domain.

    Parameters
    ----------
    directions : (n, 3) array_like
        Light directions.
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
    method : {'auto', 'spherical_voronoi', 'sample'}
        ``'spherical_voronoi'``: exact areas from :class:`scipy.spatial.SphericalVoronoi`. For a
        hemisphere the lights are mirrored through its plane (z = 0 for ``'upper'``; a mirrored
        light is never nearer to a direction inside than its original, so the cells of the
        originals in the mirrored set are exactly their parts inside); needs all lights inside
        (``d . axis >= 0``) and at least 4 distinct points. ``'sample'``: integrate a constant map on a ``2 res x res`` lat-long
        grid with exact texel solid angles (error ~ boundary length x texel size).
        ``'auto'``: spherical Voronoi where it applies, else sampling.
    res : int
        Lat-long height for ``'sample'``.

    Returns
    -------
    (n,) float64
        Cell solid angles; later exact duplicates get 0. They sum to 2 pi (a hemisphere) or 4 pi (full).
    """
    hemisphere = check_hemisphere(hemisphere)
    unit, keep = unique_directions(directions)
    if method not in ("auto", "spherical_voronoi", "sample"):
        raise ValueError(f"unknown method {method!r}")
    if method in ("auto", "spherical_voronoi"):
        try:
            return _cell_areas_sv(unit, keep, hemisphere)
        except (ValueError, RuntimeError):
            if method == "spherical_voronoi":
                raise
    d, sa = _latlong_samples(int(res))
    w = integrate_weights((d, np.ones((d.shape[0], 3)), sa), unit, hemisphere=hemisphere)
    return w.weights[:, 0]


def _cell_areas_sv(unit: np.ndarray, keep: np.ndarray, hemisphere) -> np.ndarray:
    from scipy.spatial import SphericalVoronoi

    pts = unit[keep]
    half = hemisphere.axis is not None
    if half:
        a = np.asarray(hemisphere.axis)
        side = hemisphere.side(pts)
        if np.any(side < 0):
            raise ValueError("lights below the horizon: mirroring does not apply")
        horizon = side <= _HORIZON_EPS  # snapped onto the plane (area error O(side))
        pts = pts.copy()
        pts[horizon] -= side[horizon, None] * a
        pts[horizon] = pts[horizon] / np.linalg.norm(pts[horizon], axis=1, keepdims=True)
        mirrored = pts[~horizon] - 2.0 * side[~horizon, None] * a
        allpts = np.concatenate([pts, mirrored], axis=0)
    else:
        allpts = pts
    if allpts.shape[0] < 4:
        raise ValueError("spherical Voronoi needs at least 4 points")
    sv = SphericalVoronoi(allpts, radius=1.0, center=np.zeros(3))
    areas = sv.calculate_areas()[: pts.shape[0]]
    if half:
        areas = np.where(horizon, 0.5 * areas, areas)  # a horizon light's cell is symmetric
    if not np.isclose(areas.sum(), covered_solid_angle(hemisphere), rtol=1e-9):
        raise RuntimeError("spherical Voronoi areas do not sum to the covered solid angle")
    out = np.zeros(unit.shape[0])
    out[keep] = areas
    return out


# ----------------------------------------------------------------------------- coverage
#: A cell wider than this (degrees) covers its part of the map poorly (issue 9).
WIDE_CELL_DEG = 60.0
#: A direction farther than this (degrees) from every light is "far" (half of WIDE_CELL_DEG).
FAR_DEG = 30.0
#: Share of the domain far from every light above which :func:`coverage_warnings` warns.
FAR_SHARE = 0.10


@dataclass(frozen=True)
class Coverage:
    """How well a set of light directions covers its domain.

    Attributes
    ----------
    cell_width_deg : (n,) float64
        Width of every light's Voronoi cell within the domain: twice the largest angle from the
        light to a point of its cell (the diameter of the smallest cap centred on the light that
        holds the cell); 0 for empty cells (later exact duplicates).
    far_share : float
        Share (0..1) of the domain's solid angle more than ``far_deg`` from every light.
    far_deg : float
    max_gap_deg : float
        Largest angle from a point of the domain to its nearest light.
    """

    cell_width_deg: np.ndarray
    far_share: float
    far_deg: float
    max_gap_deg: float


def coverage(directions, hemisphere="upper", far_deg: float = FAR_DEG, res: int = 256) -> Coverage:
    """Measure how well ``directions`` cover the hemisphere's domain (the Voronoi cells' sizes).

    Sampled on a ``2 res x res`` lat-long grid with exact texel solid angles: each sample is
    given to its nearest light (:func:`assign_cells`); the cell width and the far share follow
    from the angles to those lights. The sampling error is about one texel (180 / res degrees).

    Parameters
    ----------
    directions : (n, 3) array_like
        Light directions (the accepted ones).
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
    far_deg : float
        Threshold of :attr:`Coverage.far_share`.
    res : int
        Lat-long height of the sampling grid.

    Returns
    -------
    Coverage
    """
    hemisphere = check_hemisphere(hemisphere)
    unit = _check_directions(directions)
    d, sa = _latlong_samples(int(res))
    inside = in_domain(d, hemisphere)
    d, sa = d[inside], sa[inside]
    idx = assign_cells(d, unit)
    ang = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", d, unit[idx]), -1.0, 1.0)))
    width = np.zeros(unit.shape[0])
    np.maximum.at(width, idx, 2.0 * ang)
    far = ang > far_deg
    return Coverage(cell_width_deg=width, far_share=float(sa[far].sum() / sa.sum()), far_deg=float(far_deg),
                    max_gap_deg=float(ang.max()))


def _repeat_guess(pairs, same_photo) -> str:
    """The guess after :func:`coverage_warnings`' repeated lights ``pairs`` ((later, earlier)
    indices): one photo twice where ``same_photo`` finds their pixels the same, one light position
    repeated where they differ; nothing without ``same_photo``."""
    if same_photo is None or not pairs:
        return ""
    same = [bool(same_photo(j, i)) for j, i in pairs]
    if all(same):
        return " (identical photos: the same photo twice, or a render of one light twice?)"
    if not any(same):
        return " (the photos differ: the same light position given for different photos)"
    return (f" ({sum(same)} of the {len(same)} named pairs identical photos, the same photo twice?; the others "
            "differ: the same light position given twice)")


def coverage_warnings(directions, hemisphere="upper", wide_deg: float = WIDE_CELL_DEG, far_deg: float = FAR_DEG,
                      far_share: float = FAR_SHARE, names=None, same_photo=None, cones_deg=None) -> list:
    """One line per coverage problem of ``directions`` over the hemisphere (empty when none).

    * cells wider than ``wide_deg`` degrees: ``"coverage: 3 cells wider than 60 deg (widest 84
      deg at az 120 el 10)"`` (azimuth from +X toward +Y, elevation above the xy plane, world
      frame, of the widest cell's light);
    * more than ``far_share`` of the domain farther than ``far_deg`` from every light:
      ``"coverage: 18% of the domain is more than 30 deg from every light (farthest 52 deg)"``;
    * lights outside the hemisphere (e.g. below the horizon of ``'upper'``), first: those whose
      95% cone (``cones_deg``) reaches the hemisphere are said to be at its edge (the horizon),
      the others to be beyond it, with the advice to declare ``full`` if the lights were there;
    * before them, lights that repeat an earlier light's direction exactly (they get no weight:
      :func:`unique_directions`).

    Parameters
    ----------
    directions : (n, 3) array_like
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
    wide_deg, far_deg, far_share : float
        Thresholds (defaults :data:`WIDE_CELL_DEG`, :data:`FAR_DEG`, :data:`FAR_SHARE`).
    names : sequence of str, optional
        The photo of each direction: a repeat is named with the photo it repeats.
    same_photo : callable, optional
        ``same_photo(i, j)`` (indices into ``directions``): whether the two photos hold the same
        pixels (e.g. :func:`ffls.io.images.same_pixels` of their files), asked of the repeats
        named. Identical photos are said to be perhaps one photo twice (a file copied twice into
        a set gives the same fit twice); differing ones, one light position given twice (a
        grid's zenith on every ring, a light file that repeats a position). Without it neither
        is guessed.
    cones_deg : (n,) array_like, optional
        The 95% cone radius (deg) of each light, NaN where unknown
        (:meth:`ffls.io.capture.Lights.cones_deg`): a light outside the hemisphere by no more than
        its cone is at the edge, not beyond it.

    Returns
    -------
    list of str
    """
    unit = _check_directions(directions)
    c = coverage(unit, hemisphere, far_deg)
    out = []
    _, keep = unique_directions(unit)
    if keep.size < len(unit):  # only the first of equal directions takes a cell: said, not silent
        k = len(unit) - keep.size
        which = ""
        if names is not None:
            _, first, group = np.unique(unit + 0.0, axis=0, return_index=True, return_inverse=True)
            rep = [(j, int(first[group.ravel()[j]])) for j in range(len(unit)) if first[group.ravel()[j]] != j]
            which = ": " + ", ".join(f"{names[j]!r} repeats {names[i]!r}" for j, i in rep[:3]) + \
                (", ..." if len(rep) > 3 else "") + _repeat_guess(rep[:3], same_photo)
        out.append(f"coverage: {k} light{'s' if k > 1 else ''} repeat{'' if k > 1 else 's'} the direction of "
                   f"an earlier one and get{'' if k > 1 else 's'} no weight ({keep.size} distinct directions of "
                   f"{len(unit)}){which}")
    hemi = check_hemisphere(hemisphere)
    outside = ~in_domain(unit, hemi)
    beyond_deg = np.zeros(len(unit)) if not outside.any() else \
        np.degrees(np.arcsin(np.clip(-hemi.side(unit), -1.0, 1.0)))  # > 0 outside the domain
    cones = np.full(len(unit), np.nan) if cones_deg is None else \
        np.asarray(cones_deg, dtype=np.float64).reshape(len(unit))
    edge = outside & (beyond_deg <= cones)  # its cone reaches the hemisphere: estimated at the edge
    for which in (outside & ~edge, edge):  # e.g. below the horizon of an 'upper' capture: said, not kept silently
        if not which.any():
            continue
        i = int(np.argmax(np.where(which, beyond_deg, -np.inf)))
        az = np.degrees(np.arctan2(unit[i, 1], unit[i, 0]))
        el = np.degrees(np.arcsin(np.clip(unit[i, 2], -1.0, 1.0)))
        k = int(np.count_nonzero(which))
        cells = f"{'their cells keep' if k > 1 else 'its cell keeps'} only the domain nearest"
        if which is edge:
            where = "the horizon" if hemi.name == "upper" else "the hemisphere's edge"
            out.append(f"coverage: {k} light{'s' if k > 1 else ''} at {where}: estimated just outside the "
                       f"capture's {hemi.name} hemisphere, within {'their 95% cones' if k > 1 else 'its 95% cone'} "
                       f"(farthest at az {az:.0f} el {el:.1f}, {beyond_deg[i]:.1f} deg beyond its edge, cone "
                       f"{cones[i]:.1f} deg): {cells}")
        else:
            out.append(f"coverage: {k} light{'s' if k > 1 else ''} outside the capture's {hemi.name} hemisphere "
                       f"(farthest at az {az:.0f} el {el:.0f}, {beyond_deg[i]:.0f} deg beyond its "
                       f"edge): {cells}; if the lights were there, declare \"hemisphere\": \"full\" in "
                       "capture.json")
    wide = np.flatnonzero(c.cell_width_deg > wide_deg)
    if wide.size:
        i = int(np.argmax(c.cell_width_deg))
        az = np.degrees(np.arctan2(unit[i, 1], unit[i, 0]))
        el = np.degrees(np.arcsin(np.clip(unit[i, 2], -1.0, 1.0)))
        out.append(f"coverage: {wide.size} cell{'s' if wide.size > 1 else ''} wider than {wide_deg:g} deg "
                   f"(widest {c.cell_width_deg[i]:.0f} deg at az {az:.0f} el {el:.0f})")
    if c.far_share > far_share:
        out.append(f"coverage: {100 * c.far_share:.0f}% of the domain is more than {far_deg:g} deg from every light "
                   f"(farthest {c.max_gap_deg:.0f} deg)")
    return out
