"""Anti-aliased angular Voronoi weights: cell borders with sub-texel coverage.

The paper's box filter (Masselus, Dutre, Anrys 2002, section 6, :mod:`ffls.weights.voronoi`)
gives every light-map texel to one cell. Here a direction ``p`` stands for a small cap of angular
radius ``width`` around it (the footprint of a light-map texel), and its weight is split among
the cells in proportion to the share of the cap each covers, estimated on a fixed stencil of
``samples`` points spread uniformly by area over the cap (Vogel's golden-angle spiral; H. Vogel,
"A better way to construct the sunflower head", Mathematical Biosciences 44, 1979). Every sample
takes the exact Voronoi cell (:func:`ffls.weights.voronoi.assign_cells`, ties to the lowest
index), so a direction deeper than ``width`` inside a cell gets that cell alone (weight 1) and
the weights of every direction sum to 1 exactly (a count over ``samples``).

It softens the cell borders over ``2 width`` only: a sun smaller than that still jumps from one
basis photo to the next within a few rotation steps (see docs/weighting.md, flicker).
"""
from __future__ import annotations

import numpy as np

__all__ = ["DEFAULT_WIDTH_DEG", "DEFAULT_SAMPLES", "stencil", "weights_antialiased"]

#: Default cap radius (degrees): about the radius of a texel of a 512 x 256 lat-long map.
DEFAULT_WIDTH_DEG = 0.5
#: Default number of stencil points per direction.
DEFAULT_SAMPLES = 16


def stencil(samples: int = DEFAULT_SAMPLES) -> np.ndarray:
    """Unit-disc stencil ``(samples, 2)``, uniform by area (Vogel's golden-angle spiral)."""
    s = int(samples)
    if s < 1:
        raise ValueError("samples must be >= 1")
    i = np.arange(s) + 0.5
    r = np.sqrt(i / s)
    a = i * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def _tangent_frame(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (m, 3) orthogonal to unit ``p`` (m, 3) and to each other (Frisvad-style helper axis)."""
    helper = np.where(np.abs(p[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    t1 = np.cross(helper, p)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(p, t1)
    return t1, t2


def weights_antialiased(p, assign, width_deg: float = DEFAULT_WIDTH_DEG,
                        samples: int = DEFAULT_SAMPLES, chunk: int = 1 << 15, nearest2=None) -> tuple[np.ndarray, np.ndarray]:
    """Coverage weights of the Voronoi cells over a cap around each direction.

    Parameters
    ----------
    p : (m, 3) float64
        Unit query directions.
    assign : callable
        ``assign(q (s, 3)) -> (s,) int64``: the exact Voronoi cell of directions.
    width_deg : float
        Angular radius of the cap (degrees), > 0.
    samples : int
        Stencil points per direction.
    nearest2 : callable, optional
        ``nearest2(p) -> (cell (m,), angle1 (m,), angle2 (m,))``: the exact cell of ``p`` and the
        angles (rad) to its nearest and second-nearest distinct lights. A direction with
        ``(angle2 - angle1) / 2 > width`` has its whole cap inside its cell (every point of the
        cap is nearer to that light than to any other, by the triangle inequality), so it takes
        weight 1 without the stencil (same result, fewer lookups).

    Returns
    -------
    index : (m, K) int64
        Light indices (``-1`` padding), ``K <= samples``.
    weight : (m, K) float64
        Share of the cap in each cell; rows sum to 1.
    """
    if not width_deg > 0:
        raise ValueError("width_deg must be > 0")
    st = stencil(samples) * np.radians(float(width_deg))
    rr = np.linalg.norm(st, axis=1)
    ang = np.arctan2(st[:, 1], st[:, 0])
    if nearest2 is not None and p.shape[0]:
        cell, a1, a2 = nearest2(p)
        deep = 0.5 * (a2 - a1) > np.radians(float(width_deg)) * (1.0 + 1e-9) + 1e-12
        if np.any(deep):
            rest = np.flatnonzero(~deep)
            ri, rw = weights_antialiased(p[rest], assign, width_deg, samples, chunk) if rest.size else (
                np.zeros((0, 1), dtype=np.int64), np.zeros((0, 1)))
            k = max(1, ri.shape[1])
            index = np.full((p.shape[0], k), -1, dtype=np.int64)
            weight = np.zeros((p.shape[0], k))
            index[deep, 0] = cell[deep]
            weight[deep, 0] = 1.0
            index[rest, :ri.shape[1]] = ri
            weight[rest, :rw.shape[1]] = rw
            return index, weight
    m = p.shape[0]
    s = st.shape[0]
    cells = np.empty((m, s), dtype=np.int64)
    for a in range(0, m, chunk):
        ps = p[a:a + chunk]
        t1, t2 = _tangent_frame(ps)
        q = (np.cos(rr)[None, :, None] * ps[:, None, :]
             + np.sin(rr)[None, :, None] * (np.cos(ang)[None, :, None] * t1[:, None, :]
                                             + np.sin(ang)[None, :, None] * t2[:, None, :]))
        q /= np.linalg.norm(q, axis=2, keepdims=True)
        cells[a:a + chunk] = assign(q.reshape(-1, 3)).reshape(-1, s)
    cells.sort(axis=1)
    first = np.ones((m, s), dtype=bool)
    first[:, 1:] = cells[:, 1:] != cells[:, :-1]
    k = int(first.sum(axis=1).max())
    # run lengths of the sorted rows: position of each run start, counts by difference
    rows, cols = np.nonzero(first)
    slot = np.cumsum(first, axis=1)[rows, cols] - 1
    index = np.full((m, k), -1, dtype=np.int64)
    index[rows, slot] = cells[rows, cols]
    ends = np.empty_like(cols)
    nxt = np.r_[cols[1:], 0]
    same_row = np.r_[rows[1:] == rows[:-1], False]
    ends[:] = np.where(same_row, nxt, s)
    weight = np.zeros((m, k))
    weight[rows, slot] = (ends - cols) / float(s)
    return index, weight
