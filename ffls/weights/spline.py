"""Local thin-plate splines on the sphere, blended over the Delaunay triangulation (partition of unity).

Barycentric interpolation (:mod:`ffls.weights.barycentric`) is linear inside each triangle: its
error on a smooth reflectance function is second order in the light spacing. A higher-order
interpolant that stays local: every hull vertex ``v`` (a light, a mirrored light or a virtual
vertex of :class:`ffls.weights.barycentric.Barycentric`) gets its own interpolant ``s_v`` over its
``k`` nearest vertices, and a direction ``p`` in the triangle ``(a, b, c)`` takes

``w(p) = b_a(p) s_a(p) + b_b(p) s_b(p) + b_c(p) s_c(p)``

with ``b`` the barycentric coordinates (a partition of unity over the triangulation: Babuska and
Melenk, "The partition of unity method", Int. J. Numer. Meth. Eng. 40, 1997). ``s_v`` is the
thin-plate spline with a degree-1 polynomial part, in the chord distance ``r = |p - q|`` of the
unit sphere: ``phi(r) = r^2 log r`` is conditionally positive definite of order 2 in R^3, so its
restriction to the sphere with the polynomials ``1, x, y, z`` gives a unique interpolant for any
``k >= 4`` points not on one plane (Duchon 1977; Wendland, "Scattered data approximation", 2005,
ch. 8 and 17); it needs no width. Its cardinal functions (the weights each neighbour gets) come
from the inverse of the bordered system ``[[Phi, Q], [Q^T, 0]]``, computed once per vertex.

Properties:

* **Sums to 1.** Each ``s_v`` reproduces constants (the polynomial part holds them), so its
  cardinal functions sum to 1 everywhere, and so does ``w``: the light map's power is conserved
  exactly. The weights may be negative (a higher-order interpolant overshoots), and are bounded
  (each ``s_v`` is a fixed, well-conditioned linear map).
* **Interpolates.** At a light's direction ``b`` is 1 for that vertex and ``s_v`` reproduces
  ``v``: the light takes weight 1, as in barycentric.
* **Continuous.** ``b`` is continuous and each ``s_v`` is one fixed function, so ``w`` is
  continuous across triangle edges (the third coordinate vanishes there).
* **Local.** ``p`` takes at most the union of three neighbourhoods (``3 k`` lights; they overlap,
  so a :class:`ffls.weights.weighting.WeightTexture` keeps ``1.5 k`` slots, the largest).
* **Blend.** ``blend`` in [0, 1] mixes each ``s_v`` with the delta at ``v``:
  ``(1 - blend) e_v + blend s_v``; ``blend = 0`` is barycentric exactly.

Degenerate neighbourhoods (fewer than 4 vertices, all on one plane, or an ill-conditioned
system) fall back to the delta at ``v``, that is barycentric there. Vertices within
``MIN_SEPARATION`` (chord) of a vertex already in a neighbourhood are left out of it (a light
barely off the horizon and its own mirror image), and nearly equal vertices share the local
function of the first of them.

Bounded: the Lebesgue function ``sum_j |w_j|`` of each vertex's spline is sampled on its star
(the incident triangles, 14 points each) and, where it exceeds ``max_lebesgue``, the vertex's
spline is blended toward its delta until ``(1 - b) + b L_v <= max_lebesgue``; the weights then
stay within that bound (on the samples; between them, measured within 10 % in the tests).

Measured (docs/weighting.md): 0.90 of barycentric's relit error on four real HDR maps, 0.83 on
the synthetic ones, flicker 24x below voronoi's; issue 12's goal (0.8) is not reached. It is
offered by ``--weighting spline`` (:data:`ffls.weights.weighting.SCHEMES`), not the default: its
pass 1 costs 4-10x barycentric's and the user makes that trade.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["DEFAULT_K", "DEFAULT_BLEND", "DEFAULT_MAX_LEBESGUE", "MIN_SEPARATION", "LocalSpline", "thin_plate"]

#: Vertices in each local spline.
DEFAULT_K = 16
#: Weight of the spline against the delta at the vertex (1: the spline; 0: barycentric).
DEFAULT_BLEND = 1.0
#: Chord under which a vertex counts as a duplicate of one already in a neighbourhood.
MIN_SEPARATION = 1e-3
#: Largest condition number of a local system accepted (else the vertex falls back to its delta).
_MAX_COND = 1e10
#: Bound on ``sum_j |w_j(p)|`` (the Lebesgue function) of each vertex's blended spline over its star.
DEFAULT_MAX_LEBESGUE = 8.0
#: Barycentric coordinates of the points where each incident triangle is sampled for that bound.
_STAR_SAMPLES = np.array([[1.0, 0.0, 0.0], [0.5, 0.5, 0.0], [0.5, 0.0, 0.5], [0.0, 0.5, 0.5], [0.0, 1.0, 0.0],
                          [0.0, 0.0, 1.0], [1 / 3, 1 / 3, 1 / 3], [0.75, 0.25, 0.0], [0.75, 0.0, 0.25],
                          [0.25, 0.75, 0.0], [0.25, 0.0, 0.75], [0.5, 0.25, 0.25], [0.25, 0.5, 0.25],
                          [0.25, 0.25, 0.5]])


def thin_plate(cos_angle: np.ndarray) -> np.ndarray:
    """The thin-plate kernel ``r^2 log r`` of the chord ``r = sqrt(2 - 2 cos)`` (0 at ``r = 0``)."""
    r2 = np.maximum(2.0 - 2.0 * np.asarray(cos_angle, dtype=np.float64), 0.0)
    out = np.zeros_like(r2)
    pos = r2 > 0
    out[pos] = 0.5 * r2[pos] * np.log(r2[pos])
    return out


def _features(p: np.ndarray, nb_points: np.ndarray) -> np.ndarray:
    """``[phi(p . q_1) .. phi(p . q_k), 1, x, y, z]`` per row: (m, k + 4) from p (m, 3), nb_points (m, k, 3)."""
    return np.concatenate([thin_plate(np.einsum("mkj,mj->mk", nb_points, p)), np.ones((p.shape[0], 1)), p], axis=1)


class LocalSpline:
    """Partition-of-unity local thin-plate splines over a :class:`Barycentric` triangulation.

    Parameters
    ----------
    bary : ffls.weights.barycentric.Barycentric
        The triangulation (its vertices: lights, mirror images, virtual vertices; their owners).
    k : int
        Vertices per local spline (>= 4; fewer distinct vertices: all of them).
    blend : float
        In [0, 1]: the spline's share against the vertex's own delta (0 is barycentric).

    Attributes
    ----------
    neighbours : (P, k) int64
        The vertices of each vertex's spline (the vertex first; -1 padding).
    coeffs : (P, k + 4, k) float64
        Maps the features of a direction (:func:`_features`) to its weights over ``neighbours``.
    n_fallback : int
        Vertices whose spline fell back to their delta (degenerate neighbourhood).
    """

    def __init__(self, bary, k: int = DEFAULT_K, blend: float = DEFAULT_BLEND,
                 max_lebesgue: float = DEFAULT_MAX_LEBESGUE):
        k = int(k)
        if k < 4:
            raise ValueError("k must be >= 4 (a thin-plate spline with a linear part needs 4 points)")
        blend = float(blend)
        if not 0.0 <= blend <= 1.0:
            raise ValueError("blend must be in [0, 1]")
        max_lebesgue = float(max_lebesgue)
        if not max_lebesgue >= 1.0:
            raise ValueError("max_lebesgue must be >= 1")
        self.bary = bary
        pts = bary.points
        n_pts = pts.shape[0]
        self.k = k
        tree = cKDTree(pts)
        kq = min(n_pts, 2 * k)
        _, cand = tree.query(pts, k=kq)
        cand = np.asarray(cand).reshape(n_pts, kq)
        nb = np.full((n_pts, k), -1, dtype=np.int64)
        delta = np.zeros((k + 4, k))
        delta[k, 0] = 1.0  # the delta at the vertex: weight 1 to itself, from the constant feature
        spline = np.zeros((n_pts, k + 4, k))
        ok = np.zeros(n_pts, dtype=bool)
        # nearly equal vertices share one local function (the lowest index's), so a near pair
        # takes one light's weight between them
        canon = np.array([min(c) for c in tree.query_ball_point(pts, MIN_SEPARATION)], dtype=np.int64)
        for v in range(n_pts):
            if canon[v] != v:
                continue
            chosen = [v]
            for c in cand[v]:
                if len(chosen) == k:
                    break
                if c != v and np.min(np.linalg.norm(pts[chosen] - pts[c], axis=1)) > MIN_SEPARATION:
                    chosen.append(int(c))
            nb[v, :len(chosen)] = chosen
            inv = self._cardinal(pts[chosen]) if blend > 0 else None
            if inv is None:
                spline[v] = delta
                continue
            kk = len(chosen)
            spline[v, :kk, :kk] = inv[:kk]
            spline[v, k:, :kk] = inv[kk:]
            ok[v] = True
        nb, spline, ok = nb[canon], spline[canon], ok[canon]
        self.neighbours = nb
        lebesgue = self._star_lebesgue(spline)
        np.maximum.at(lebesgue, canon, lebesgue.copy())  # a cluster's bound covers all its stars
        lebesgue = lebesgue[canon]
        # (1 - b) e_v + b s_v has a Lebesgue function <= (1 - b) + b L_v: cap it at max_lebesgue
        share = np.full(n_pts, blend)
        over = lebesgue > max_lebesgue
        share[over] = np.minimum(blend, (max_lebesgue - 1.0) / (lebesgue[over] - 1.0))
        share[~ok] = 0.0
        self.lebesgue = lebesgue
        self.share = share
        self.coeffs = share[:, None, None] * spline + (1.0 - share[:, None, None]) * delta
        self.n_fallback = int(np.count_nonzero(~ok)) if blend > 0 else 0

    def _local(self, v: np.ndarray, p: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
        """Weights (m, k) over ``neighbours[v]`` of the local functions of vertices ``v`` (m,) at ``p`` (m, 3)."""
        nb = self.neighbours[v]
        f = _features(p, self.bary.points[np.maximum(nb, 0)])
        f[:, :self.k][nb < 0] = 0.0
        w = np.einsum("mi,mij->mj", f, coeffs[v])
        w[nb < 0] = 0.0
        w[:, 0] += 1.0 - w.sum(axis=1)  # the local weights sum to 1 up to rounding: make it exact
        return w

    def _star_lebesgue(self, coeffs: np.ndarray) -> np.ndarray:
        """Largest ``sum |w|`` of each vertex's local function on samples of its incident triangles (P,)."""
        simp = self.bary.simplices
        pts = self.bary.points
        q = np.einsum("sc,fcj->fsj", _STAR_SAMPLES, pts[simp])  # (F, S, 3) on the flat triangles
        q /= np.linalg.norm(q, axis=2, keepdims=True)
        out = np.ones(pts.shape[0])
        n_s = _STAR_SAMPLES.shape[0]
        for c in range(3):
            v = np.repeat(simp[:, c], n_s)
            lam = np.abs(self._local(v, q.reshape(-1, 3), coeffs)).sum(axis=1).reshape(-1, n_s).max(axis=1)
            np.maximum.at(out, simp[:, c], lam)
        return out

    @staticmethod
    def _cardinal(q: np.ndarray):
        """``(kk + 4, kk)`` rows of the inverse bordered system, or None when it is degenerate."""
        kk = q.shape[0]
        if kk < 4:
            return None
        poly = np.concatenate([np.ones((kk, 1)), q], axis=1)
        sv = np.linalg.svd(poly - np.r_[0.0, q.mean(axis=0)], compute_uv=False)
        if sv[-1] <= 1e-6 * max(sv[0], 1.0):  # all on one plane: the linear part is not unisolvent
            return None
        a = np.zeros((kk + 4, kk + 4))
        a[:kk, :kk] = thin_plate(q @ q.T)
        a[:kk, kk:] = poly
        a[kk:, :kk] = poly.T
        if not np.isfinite(np.linalg.cond(a)) or np.linalg.cond(a) > _MAX_COND:
            return None
        return np.linalg.inv(a)[:, :kk]  # symmetric: weights = [phi(p), 1, p] @ this

    def __call__(self, p: np.ndarray, chunk: int = 1 << 13) -> tuple[np.ndarray, np.ndarray]:
        """Weights of unit directions ``p`` (m, 3).

        Returns
        -------
        index : (m, 3 k) int64
            Lights (owners of the vertices), repeated where neighbourhoods overlap (their weights
            add), -1 padding.
        weight : (m, 3 k) float64
            Rows sum to 1; may be negative.
        """
        m = p.shape[0]
        k = self.k
        owner = self.bary.owner
        index = np.full((m, 3 * k), -1, dtype=np.int64)
        weight = np.zeros((m, 3 * k))
        for a in range(0, m, chunk):
            ps = p[a:a + chunk]
            verts, b = self.bary.coordinates(ps)
            for c in range(3):
                v = verts[:, c]
                nb = self.neighbours[v]
                w = self._local(v, ps, self.coeffs) * b[:, c:c + 1]
                index[a:a + chunk, c * k:(c + 1) * k] = np.where(nb >= 0, owner[np.maximum(nb, 0)], -1)
                weight[a:a + chunk, c * k:(c + 1) * k] = w
        return index, weight
