"""Von Mises-Fisher kernel weights over the nearest lights, the width from the local spacing.

The box filter of the paper (Masselus, Dutre, Anrys 2002, section 6) names Gaussian filtering as
future work. Here a direction ``p`` is shared among its ``k`` nearest lights with von
Mises-Fisher (spherical Gaussian) kernel weights ``K_j = exp(kappa (p . l_j - 1))`` (R. Fisher,
"Dispersion on a sphere", Proc. Royal Society A 217, 1953), ``kappa = 1 / sigma^2``, whose width
follows the local light spacing: ``sigma(p) = width * theta_{k+1}(p)``, with ``theta_{k+1}`` the
angle from ``p`` to its ``(k+1)``-th nearest light (a continuous function of ``p``).

Continuity across changes of the neighbour set: the weight of neighbour ``j`` is
``K_j - K_{k+1}`` (the kernel minus its value at the ``(k+1)``-th nearest light), which is 0 when
neighbour ``k`` and ``k+1`` swap, so the weights are continuous in ``p`` (a truncated kernel that
simply drops the ``(k+1)``-th light would jump by its share). The weights are normalised to sum
to 1. Where all ``k + 1`` nearest lights are at exactly the same angle (a ring of lights around
``p`` on a symmetric gantry) the differences vanish; there the plain kernel over the ``k``
nearest is used (a single point of discontinuity). With ``n <= k`` lights all take part,
without the subtraction.

Declustering: a kernel sum counts a cluster of lights several times (two nearly equal lights
would take twice the share of one). Each light's kernel is divided by its own density
``rho_j``: the same un-normalised sum evaluated at the light's own direction
(:func:`light_density`), so a pair of nearly equal lights shares about what one light would
take, as the Voronoi cells do. ``rho_j`` is a constant per light: continuity is kept.
"""
from __future__ import annotations

import numpy as np

__all__ = ["DEFAULT_K", "DEFAULT_WIDTH", "weights_gaussian", "light_density"]

#: Nearest lights that share a direction.
DEFAULT_K = 4
#: Kernel sigma as a multiple of the angle to the (k+1)-th nearest light.
DEFAULT_WIDTH = 0.3
#: Relative size of the subtracted kernel sum under which the plain kernel is used (ties).
_TIE_REL = 1e-9


def _chord_to_angle(chord):
    return 2.0 * np.arcsin(np.clip(0.5 * chord, 0.0, 1.0))


def _raw(ps, keep, tree, k, width):
    """Un-normalised weights ``(m, min(k, u))`` and their light indices (into ``keep``'s order)."""
    u = keep.size
    kk = min(k + 1, u)
    dist, idx = tree.query(ps, k=kk)
    dist = np.asarray(dist).reshape(ps.shape[0], kk)
    idx = np.asarray(idx).reshape(ps.shape[0], kk)
    theta = _chord_to_angle(dist)
    cosang = 1.0 - 0.5 * dist * dist  # p . l from the chord, exact for unit vectors
    sigma = np.maximum(width * theta[:, -1:], 1e-9)
    kern = np.exp((cosang - 1.0) / (sigma * sigma))
    if u > k:
        w = kern[:, :k] - kern[:, k:k + 1]
        tot = w.sum(axis=1, keepdims=True)
        tie = tot[:, 0] <= _TIE_REL * kern[:, :k].sum(axis=1)
        w[tie] = kern[tie, :k]
        w = np.maximum(w, 0.0)
    else:
        w = kern
    return w, idx[:, :w.shape[1]]


def light_density(unit, keep, tree, k: int = DEFAULT_K, width: float = DEFAULT_WIDTH) -> np.ndarray:
    """Declustering density ``(u,)`` of the distinct lights: the un-normalised kernel sum at each light."""
    w, _ = _raw(unit[keep], keep, tree, int(k), float(width))
    return w.sum(axis=1)


def weights_gaussian(p, unit, keep, tree, k: int = DEFAULT_K, width: float = DEFAULT_WIDTH,
                     chunk: int = 1 << 17, density=None) -> tuple[np.ndarray, np.ndarray]:
    """vMF kernel weights of directions over their ``k`` nearest lights.

    Parameters
    ----------
    p : (m, 3) float64
        Unit query directions.
    unit : (n, 3) float64
        Unit light directions (duplicates included).
    keep : (u,) int64
        Indices of the distinct lights; ``tree`` is built over ``unit[keep]``.
    tree : scipy.spatial.cKDTree
        k-d tree of ``unit[keep]`` (chord order is angle order).
    density : (u,) float64, optional
        :func:`light_density` (computed here when not given).
    k : int
        Lights per direction (>= 1).
    width : float
        ``sigma`` as a multiple of the angle to the ``(k+1)``-th nearest light (> 0).

    Returns
    -------
    index : (m, min(k, u)) int64
    weight : (m, min(k, u)) float64
        Rows sum to 1.
    """
    k = int(k)
    if k < 1:
        raise ValueError("k must be >= 1")
    if not width > 0:
        raise ValueError("width must be > 0")
    u = keep.size
    m = p.shape[0]
    kout = min(k, u)
    if density is None:
        density = light_density(unit, keep, tree, k, width)
    index = np.empty((m, kout), dtype=np.int64)
    weight = np.empty((m, kout))
    for a in range(0, m, chunk):
        w, idx = _raw(p[a:a + chunk], keep, tree, k, width)
        w = w / density[idx]
        w /= w.sum(axis=1, keepdims=True)
        index[a:a + chunk] = keep[idx]
        weight[a:a + chunk] = w
    return index, weight
