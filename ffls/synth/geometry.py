"""Ray geometry of the synthetic scene: solid primitives, closest hits and any-hit shadow tests.

Every primitive is a convex solid (or a union of three, the capsule) with ``interval(o, d)``,
the entry and exit distances of rays ``o + t d``, and ``normal(p)`` on its surface. Closest hits
(:func:`closest_hit`) take the nearest entry; shadow rays (:func:`occluded`) cull boxes and
capsules with bounding spheres first. Used by :mod:`ffls.synth.scene`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffls.conventions import normalize

__all__ = ["Material", "Sphere", "Box", "Capsule", "Ground", "closest_hit", "occluded"]


@dataclass(frozen=True)
class Material:
    """Lambert ``kd`` (RGB albedo), a normalised Blinn-Phong lobe and a perfect-mirror coat.

    Attributes
    ----------
    kd : (3,) tuple
        Lambertian albedo.
    ks, shininess : float
        Weight and exponent of a normalised Blinn-Phong lobe (the object's gloss).
    mirror : float
        Reflectance of a perfect-mirror coat at normal incidence (0 = none; chrome about 0.9).
    fresnel : bool
        Whether the coat's reflectance follows Schlick's approximation,
        ``F = mirror + (1 - mirror) (1 - cos)^5`` (a dielectric coat, e.g. a glossy black ball),
        or stays ``mirror`` at every angle (a metal).
    """

    kd: tuple
    ks: float = 0.0
    shininess: float = 1.0
    mirror: float = 0.0
    fresnel: bool = False


def _safe_inv(d):
    d = np.where(d == 0.0, 1e-300, d)
    return 1.0 / d


@dataclass(frozen=True)
class Sphere:
    """A solid sphere."""

    center: tuple
    radius: float
    material: Material
    label: int

    def interval(self, o, d):
        """Entry and exit distances (n,), +inf/-inf for a miss; ``d`` unit (n, 3)."""
        oc = o - np.asarray(self.center)
        b = np.einsum("ij,ij->i", oc, d)
        c = np.einsum("ij,ij->i", oc, oc) - self.radius ** 2
        h = b * b - c
        s = np.sqrt(np.maximum(h, 0.0))
        miss = h < 0
        return np.where(miss, np.inf, -b - s), np.where(miss, -np.inf, -b + s)

    def normal(self, p):
        return (p - np.asarray(self.center)) / self.radius

    def distance(self, p) -> float:
        """Signed distance (m) from the point ``p`` (3,) to the surface (negative inside)."""
        return float(np.linalg.norm(np.asarray(p) - np.asarray(self.center)) - self.radius)


@dataclass(frozen=True)
class Box:
    """A solid axis-aligned box from corner ``lo`` to corner ``hi``."""

    lo: tuple
    hi: tuple
    material: Material
    label: int

    def interval(self, o, d):
        inv = _safe_inv(d)
        with np.errstate(invalid="ignore", over="ignore"):
            a = (np.asarray(self.lo) - o) * inv
            b = (np.asarray(self.hi) - o) * inv
        t0 = np.nanmax(np.minimum(a, b), axis=1)
        t1 = np.nanmin(np.maximum(a, b), axis=1)
        miss = t0 > t1
        return np.where(miss, np.inf, t0), np.where(miss, -np.inf, t1)

    def normal(self, p):
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        q = (p - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
        axis = np.argmax(np.abs(q), axis=1)
        n = np.zeros_like(p)
        n[np.arange(len(p)), axis] = np.sign(q[np.arange(len(p)), axis])
        return n

    def distance(self, p) -> float:
        """Distance (m) from the point ``p`` (3,) to the box (0 inside)."""
        p = np.asarray(p)
        return float(np.linalg.norm(np.maximum(np.maximum(np.asarray(self.lo) - p, p - np.asarray(self.hi)), 0.0)))


@dataclass(frozen=True)
class Capsule:
    """A solid capsule: the segment ``a``-``b`` swept by a ball of ``radius``."""

    a: tuple
    b: tuple
    radius: float
    material: Material
    label: int

    def _pieces(self):
        return (Sphere(self.a, self.radius, self.material, self.label),
                Sphere(self.b, self.radius, self.material, self.label))

    def _cylinder(self, o, d):
        a, b = np.asarray(self.a), np.asarray(self.b)
        ax = b - a
        L = np.linalg.norm(ax)
        ax = ax / L
        oa = o - a
        dp = d - np.outer(d @ ax, ax)
        op = oa - np.outer(oa @ ax, ax)
        A = np.einsum("ij,ij->i", dp, dp)
        B = np.einsum("ij,ij->i", dp, op)
        C = np.einsum("ij,ij->i", op, op) - self.radius ** 2
        h = B * B - A * C
        par = A < 1e-14
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.sqrt(np.maximum(h, 0.0))
            c0 = np.where(par, np.where(C < 0, -np.inf, np.inf), (-B - s) / A)
            c1 = np.where(par, np.where(C < 0, np.inf, -np.inf), (-B + s) / A)
        c0 = np.where(~par & (h < 0), np.inf, c0)
        c1 = np.where(~par & (h < 0), -np.inf, c1)
        # slab 0 <= (o + t d - a).ax <= L
        da = d @ ax
        pa = oa @ ax
        inv = _safe_inv(da)
        with np.errstate(invalid="ignore", over="ignore"):
            s0, s1 = (0.0 - pa) * inv, (L - pa) * inv
        par2 = da == 0.0
        inside = (pa >= 0) & (pa <= L)
        s_lo = np.where(par2, np.where(inside, -np.inf, np.inf), np.minimum(s0, s1))
        s_hi = np.where(par2, np.where(inside, np.inf, -np.inf), np.maximum(s0, s1))
        t0, t1 = np.maximum(c0, s_lo), np.minimum(c1, s_hi)
        miss = t0 > t1
        return np.where(miss, np.inf, t0), np.where(miss, -np.inf, t1)

    def intervals(self, o, d):
        """The (entry, exit) pairs of the capsule's three convex pieces."""
        return [self._cylinder(o, d)] + [s.interval(o, d) for s in self._pieces()]

    def interval(self, o, d):
        """Entry of the union (origin outside) and the largest exit; exact for first hits."""
        ivs = self.intervals(o, d)
        return np.minimum.reduce([i[0] for i in ivs]), np.maximum.reduce([i[1] for i in ivs])

    def _offset(self, p):
        """``p`` (..., 3) minus its nearest point on the segment ``a``-``b``."""
        a, b = np.asarray(self.a, dtype=np.float64), np.asarray(self.b, dtype=np.float64)
        ax = b - a
        t = np.clip(((p - a) @ ax) / (ax @ ax), 0.0, 1.0)
        return p - (a + t[..., None] * ax)

    def normal(self, p):
        return normalize(self._offset(p))

    def distance(self, p) -> float:
        """Signed distance (m) from the point ``p`` (3,) to the surface (negative inside)."""
        return float(np.linalg.norm(self._offset(np.asarray(p, dtype=np.float64))) - self.radius)


@dataclass(frozen=True)
class Ground:
    """The ground: the solid half-space z < 0."""

    material: Material
    label: int

    def interval(self, o, d):
        """The solid half-space z < 0."""
        dz, oz = d[:, 2], o[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -oz / dz
        t0 = np.where(dz < 0, t, np.where(dz > 0, -np.inf, np.where(oz < 0, -np.inf, np.inf)))
        t1 = np.where(dz < 0, np.inf, np.where(dz > 0, t, np.where(oz < 0, np.inf, -np.inf)))
        return t0, t1

    def normal(self, p):
        n = np.zeros_like(p)
        n[:, 2] = 1.0
        return n


def closest_hit(prims, o, d):
    """Closest entry t > 0 and the index of the primitive hit (-1 for none); origins outside."""
    best = np.full(len(o), np.inf)
    idx = np.full(len(o), -1, dtype=np.int64)
    for k, p in enumerate(prims):
        t0, t1 = p.interval(o, d)
        ok = (t0 > 0) & (t0 <= t1) & (t0 < best)
        best = np.where(ok, t0, best)
        idx = np.where(ok, k, idx)
    return best, idx


def _bound(p):
    """Bounding sphere (centre (3,), radius) of a box or capsule primitive."""
    if isinstance(p, Box):
        lo, hi = np.asarray(p.lo), np.asarray(p.hi)
        return 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))
    a, b = np.asarray(p.a), np.asarray(p.b)
    return 0.5 * (a + b), 0.5 * float(np.linalg.norm(b - a)) + p.radius


def _sphere_any(o, oo, d, od, c, r, tmax):
    """Any-hit of segments with a solid sphere; ``oo`` = |o|^2 (n,), ``od`` = o.d (n,)."""
    dc = d @ c
    b = od - dc
    cc = oo - 2.0 * (o @ c) + (c @ c - r * r)
    h = b * b - cc
    hit = (h >= 0) & ((b < 0) | (cc < 0))
    if tmax is not None:
        k = np.flatnonzero(hit)  # few candidates: test the segment length on them only
        hit[k] = -b[k] - np.sqrt(h[k]) < tmax[k]
    return hit


def occluded(prims, o, d, tmax=None):
    """Whether the open segment o + t d, 0 < t < tmax, meets any primitive's solid. (n,) bool.

    Parameters
    ----------
    o : (n, 3) float64
        Origins, outside or on the primitives.
    d : (n, 3) or (3,) float64
        Unit directions (one shared direction for a distant light).
    tmax : (n,) float or None
        Segment lengths; None = rays.

    Boxes and capsules are first culled with their bounding spheres (exact tests only on the
    rays that pass near them).
    """
    n = len(o)
    hit = np.zeros(n, dtype=bool)
    if n == 0:
        return hit
    oo = np.einsum("ij,ij->i", o, o)
    od = o @ d if d.ndim == 1 else np.einsum("ij,ij->i", o, d)
    for p in prims:
        if isinstance(p, Sphere):
            hit |= _sphere_any(o, oo, d, od, np.asarray(p.center), p.radius, tmax)
            continue
        if isinstance(p, Ground):
            if o[:, 2].min() >= 0:  # segments in z >= 0 (convex) cannot enter the half-space z < 0
                if d.ndim == 1 and d[2] >= 0:
                    continue
                if tmax is not None and (o[:, 2] + tmax * d[:, 2]).min() >= 0:
                    continue
            dd = np.broadcast_to(d, o.shape)
            t0, t1 = p.interval(o, dd)
            h = (t1 > 0) & (t0 <= t1)
            if tmax is not None:
                h &= t0 < tmax
            hit |= h
            continue
        c, r = _bound(p)
        sel = np.flatnonzero(_sphere_any(o, oo, d, od, c, r, tmax) & ~hit)
        if len(sel) == 0:
            continue
        os_ = o[sel]
        ds_ = np.broadcast_to(d, o.shape)[sel]
        ivs = p.intervals(os_, ds_) if isinstance(p, Capsule) else [p.interval(os_, ds_)]
        hs = np.zeros(len(sel), dtype=bool)
        for t0, t1 in ivs:
            h = (t1 > 0) & (t0 <= t1)
            if tmax is not None:
                h &= t0 < tmax[sel]
            hs |= h
        hit[sel] |= hs
    return hit
