"""Spherical barycentric interpolation over the Delaunay triangulation of the light directions.

The Delaunay triangulation of points on the sphere is their convex hull (scipy's
:class:`scipy.spatial.ConvexHull`, Qhull: Barber, Dobkin, Huhdanpaa, "The Quickhull algorithm for
convex hulls", ACM TOMS 22(4), 1996). A direction ``p`` lies in the one hull triangle
``(a, b, c)`` its ray from the centre crosses; its weights are the coefficients of
``p = b_a a + b_b b + b_c c`` (all >= 0 inside), divided by their sum: the barycentric
coordinates of the triangle point the ray meets (gnomonic barycentric coordinates). They are
continuous across edges (on a shared edge the third coefficient is 0 and the other two agree)
and reproduce a light exactly at its own direction.

The hemisphere's rim: for a hemisphere capture the lights are mirrored through the hemisphere's
plane (z = 0 for ``upper``) and the mirrored copy of light ``j`` passes its weight to ``j``, so a
direction near the horizon interpolates between a light and its own mirror image (that is, it
takes the nearest lights' values unchanged down to the horizon). Lights on the plane
(``|d . axis| <= 1e-9``) are not mirrored.

Uncovered parts: where the points (lights and mirrors) leave an open hemisphere empty (all lights
inside a small cap of a full-sphere capture, one or two lights) the centre is outside their hull.
Then virtual vertices are added: the vertices of a regular icosahedron farther than 45 degrees
from every point, each passing its weight to the light nearest to it. Every point of the sphere
is within 37.4 degrees of an icosahedron vertex, so every open hemisphere then holds a vertex
and the centre is strictly inside the hull. Weights sum to 1 everywhere.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

__all__ = ["HORIZON_EPS", "VIRTUAL_MIN_DEG", "Barycentric"]

#: Lights with ``|d . axis| <=`` this are on the rim and not mirrored.
HORIZON_EPS = 1e-9
#: An icosahedron vertex farther than this (degrees) from every point becomes a virtual vertex.
VIRTUAL_MIN_DEG = 45.0
#: Barycentric coefficients >= -this count as inside a triangle.
_INSIDE_EPS = 1e-12


def _icosahedron() -> np.ndarray:
    g = (1.0 + np.sqrt(5.0)) / 2.0
    v = []
    for a in (-1.0, 1.0):
        for b in (-g, g):
            v += [(0.0, a, b), (a, b, 0.0), (b, 0.0, a)]
    v = np.array(v)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


class Barycentric:
    """The triangulation of a set of light directions, ready to interpolate.

    Parameters
    ----------
    unit : (n, 3) float64
        Unit light directions (duplicates included).
    keep : (u,) int64
        Indices of the distinct lights (:func:`ffls.weights.voronoi.unique_directions`); later
        duplicates never get weight.
    hemisphere : ffls.conventions.Hemisphere
        A hemisphere (``axis`` not None) mirrors the lights through its plane.

    Attributes
    ----------
    points : (P, 3) float64
        Hull vertices: the distinct lights, their mirror images, virtual vertices.
    owner : (P,) int64
        The light (index into ``unit``) each vertex passes its weight to.
    simplices : (F, 3) int64
        Hull triangles (indices into ``points``).
    n_virtual : int
        Virtual vertices added.
    """

    def __init__(self, unit: np.ndarray, keep: np.ndarray, hemisphere):
        pts = unit[keep]
        owner = np.asarray(keep, dtype=np.int64)
        if hemisphere.axis is not None and pts.shape[0] > 0:
            a = np.asarray(hemisphere.axis, dtype=np.float64)
            side = pts @ a
            mir = np.abs(side) > HORIZON_EPS
            mirrored = pts[mir] - 2.0 * side[mir, None] * a
            mirrored /= np.linalg.norm(mirrored, axis=1, keepdims=True)
            pts = np.concatenate([pts, mirrored])
            owner = np.concatenate([owner, owner[mir]])
        ico = _icosahedron()
        tree = cKDTree(pts)
        dist, near = tree.query(ico, k=1)
        far = 2.0 * np.arcsin(np.clip(dist / 2.0, 0, 1)) > np.radians(VIRTUAL_MIN_DEG)
        self.n_virtual = int(far.sum())
        pts = np.concatenate([pts, ico[far]])
        owner = np.concatenate([owner, owner[near[far]]])
        try:
            hull = ConvexHull(pts)
        except QhullError:
            hull = ConvexHull(pts, qhull_options="QJ")
        self.points = pts
        self.owner = owner
        simp = np.asarray(hull.simplices, dtype=np.int64)
        # drop triangles whose plane passes (numerically) through the centre: none when the centre
        # is strictly inside the hull
        M = np.transpose(pts[simp], (0, 2, 1))  # columns = vertices
        det = np.linalg.det(M)
        good = np.abs(det) > 1e-300
        simp, M = simp[good], M[good]
        self.simplices = simp
        self._inv = np.linalg.inv(M)
        eq = hull.equations[good]
        self._polar = eq[:, :3] / (-eq[:, 3:4])  # ray hits facet f first <=> max p . polar_f
        self._tree = cKDTree(pts)
        # vertex -> incident triangles (padded with -1)
        nv = pts.shape[0]
        deg = np.bincount(simp.ravel(), minlength=nv)
        width = int(deg.max()) if deg.size else 1
        inc = np.full((nv, width), -1, dtype=np.int64)
        order = np.argsort(simp.ravel(), kind="stable")
        vert = simp.ravel()[order]
        tri = order // 3
        start = np.r_[0, np.cumsum(deg)[:-1]]
        inc[vert, np.arange(vert.size) - start[vert]] = tri
        self._incident = inc

    def _coeffs(self, p: np.ndarray, tri: np.ndarray) -> np.ndarray:
        return np.einsum("mij,mj->mi", self._inv[tri], p)

    def _locate(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Triangle (m,) and raw coefficients (m, 3) of the triangle each direction's ray crosses."""
        m = p.shape[0]
        tri = np.full(m, -1, dtype=np.int64)
        coef = np.zeros((m, 3))
        todo = np.arange(m)
        for kq in (1, 3):
            if todo.size == 0:
                break
            kk = min(kq, self.points.shape[0])
            _, v = self._tree.query(p[todo], k=kk)
            cand = self._incident[np.asarray(v).reshape(todo.size, kk)].reshape(todo.size, -1)
            best = np.full(todo.size, -np.inf)
            for c in range(cand.shape[1]):
                t = cand[:, c]
                ok = t >= 0
                if not np.any(ok):
                    continue
                b = np.zeros((todo.size, 3))
                b[ok] = self._coeffs(p[todo[ok]], t[ok])
                score = np.where(ok, b.min(axis=1), -np.inf)
                better = (score > best) & (score >= -_INSIDE_EPS)
                tri[todo[better]] = t[better]
                coef[todo[better]] = b[better]
                best = np.where(better, score, best)
            todo = todo[tri[todo] < 0]
        for a in range(0, todo.size, 4096):  # exhaustive: the facet the ray hits first
            s = todo[a:a + 4096]
            f = np.argmax(p[s] @ self._polar.T, axis=1)
            tri[s] = f
            coef[s] = self._coeffs(p[s], f)
        return tri, coef

    def coordinates(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Hull vertices and barycentric coordinates of unit directions ``p`` (m, 3).

        Returns
        -------
        vertices : (m, 3) int64
            The vertices (indices into :attr:`points`) of the triangle each ray crosses.
        coords : (m, 3) float64
            Their coordinates, >= 0, rows summing to 1.
        """
        tri, coef = self._locate(p)
        b = np.maximum(coef, 0.0)
        tot = b.sum(axis=1, keepdims=True)
        bad = tot[:, 0] <= 0  # cannot happen for a located ray; keep the sum-to-one contract
        b[bad] = 1.0 / 3.0
        tot[bad] = 1.0
        return self.simplices[tri], b / tot

    def __call__(self, p: np.ndarray, chunk: int = 1 << 16) -> tuple[np.ndarray, np.ndarray]:
        """Weights of unit directions ``p`` (m, 3): ``index (m, 3)`` lights, ``weight (m, 3)``, rows sum to 1."""
        m = p.shape[0]
        index = np.empty((m, 3), dtype=np.int64)
        weight = np.empty((m, 3))
        for a in range(0, m, chunk):
            verts, b = self.coordinates(p[a:a + chunk])
            weight[a:a + chunk] = b
            index[a:a + chunk] = self.owner[verts]
        return index, weight
