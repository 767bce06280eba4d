"""The outer outline of a mirror ball: the silhouette, not the reflected horizon.

A chrome (or black glossy) ball shows its surroundings, not its own shading. Under a hand-held
light in a room or on a table, the upper part of the ball reflects the dark room or sky, the lower
part the lit table: in the max image the ball is a dark cap on a bright background whose lower
boundary is the *reflected horizon*, a curve well inside the silhouette, while the lower part of
the silhouette (table reflected against the table) has little contrast. A circle fitted to that dark
cap is too small and too high (on ``ffls synth --sphere-material mirror`` at 384 px: radius 19.9 px
against 27.2, centre 9 px off), and every light direction from it is tens of degrees wrong.

:func:`enclosing_circle` searches, around such a candidate circle, for the *outermost* circle that
the edges support: a circle at least ``min_growth`` times larger that encloses the candidate's own
outline points, is covered by edge points over at least ``min_coverage`` of its in-frame
circumference, and gains edge points the candidate circle does not have. For a mirror ball the
upper arc of the dark cap is the silhouette; with the remaining outline points (sides, contact
shadow) it fixes the outer circle, and the horizon is left inside. A matte sphere's fitted outline
encloses everything of it, so no larger circle is supported and the candidate stays as it is.

Pure functions on point arrays (pixels, x right, y down); the sphere fit itself (tangent cone or
circle) stays in :mod:`ffls.spheres.detect`.
"""
from __future__ import annotations

import dataclasses

import numpy as np

#: ``SphereFit.source`` of a sphere fitted to an outer outline found by :func:`enclosing_circle`.
OUTER_SOURCE = "auto (outer outline)"

#: Least outline ambiguity of a mirror ball (pixels): the reflected contrasts that give its outline
#: run 1 to 2 px inside the limb at 384 px (``ffls synth --sphere-material mirror``), and the two
#: outline estimates can agree by chance (``SphereFit.outline_sigma_px``).
MIRROR_OUTLINE_FLOOR_PX = 1.0
#: Least outline ambiguity (pixels) of a mirror ball whose outline a second estimate measured (the
#: limb's reflectance step, ``SphereFit.outline_sigma_px``: at least half their gap): the
#: per-axis RMS of the centre errors of 17 chrome balls' outlines found without hints (0.24-0.90 px,
#: 2-D; 384 px renders with JPEG, noise, vignetting, textured, white and grey grounds, long lenses,
#: anti-aliasing: ``docs/spheres.md``, "A lone mirror ball's own cone"). Without a second
#: estimate the ambiguity stays :data:`MIRROR_OUTLINE_FLOOR_PX`. Also the least centre sigma of a
#: lone ball that the second estimate measured (``SphereFit.outline_centre_sigma_px``).
MIRROR_OUTLINE_SIGMA_FLOOR_PX = 0.4


@dataclasses.dataclass
class OuterCircle:
    """A circle enclosing a candidate outline (:func:`enclosing_circle`).

    Attributes
    ----------
    center : (2,) float
        Pixels (x, y).
    radius : float
        Pixels.
    inliers : (n,) bool
        Over the ``points`` given: within ``tol`` of the circle.
    coverage : float
        Fraction of the circle's in-frame circumference (5-degree bins) with an inlier.
    new_fraction : float
        Fraction of the inliers that are not on the candidate circle (the evidence it adds).
    """

    center: np.ndarray
    radius: float
    inliers: np.ndarray
    coverage: float
    new_fraction: float


def highest_first(values, idx, head: int = 64):
    """``idx`` ordered by ``values[idx]``, highest first and ties in the order of ``idx``: the order
    of one stable sort of all, in two blocks, the ``head`` highest (with every value tied with the
    last of them) and then the rest, sorted only when it is asked for (a search picks its few
    windows among the highest of thousands)."""
    v = values[idx]
    if len(v) > head:
        top = v >= np.partition(v, len(v) - head)[len(v) - head]
        yield idx[top][np.argsort(-v[top], kind="stable")]
        idx, v = idx[~top], v[~top]
    yield idx[np.argsort(-v, kind="stable")]


def circle_search(points, center, max_offset: float, r_min: float, r_max: float, *, tol: float = 1.0,
                  n_best: int = 1, per_radius: bool = False) -> list:
    """The best-supported circles near a centre: a Hough vote on a grid of centres, refined by least squares.

    Deterministic: the answer depends only on the set of points (not their order, nor a random
    state). Every point votes, for each centre of a square grid (step ``s = max(tol, max_offset /
    8)``) within ``max_offset`` of ``center``, for its distance; votes are binned at ``w / 2``
    (``w = max(2 tol, 1.5 s)``, wide enough for the grid's centre error) and summed over
    windows of ``w``. The ``max(2 n_best, 3)`` highest windows (a window may not lie within ``s``
    in centre and ``w`` in radius of a higher one) are refined one by one by a robust geometric circle fit
    (``scipy.optimize.least_squares``, ``soft_l1`` loss of scale ``tol``) to the points within
    ``w`` of the window's circle, and again to those within ``2 tol`` of that fit; each is then
    scored by its points within ``tol``. This replaces RANSAC over 3-point samples, whose
    answer changed with the seed where clutter competes with the outline.

    Parameters
    ----------
    points : (n, 2) float
        Edge points (x, y), pixels.
    center : (2,) float
        Where the circle's centre is expected, pixels.
    max_offset : float
        Largest distance of the centre from ``center``, pixels.
    r_min, r_max : float
        Radius range, pixels.
    tol : float
        Inlier distance, pixels.
    n_best : int
        Circles returned.
    per_radius : bool
        Rank by inliers per pixel of radius (a share of the circumference) rather than by count.

    Returns
    -------
    list of (centre (2,), radius, inliers (n,) bool)
        Best first (by the refined inliers, ties by the smaller centre offset); fewer, or none,
        when fewer windows hold 3 points, or a refined circle leaves the radius range or moves its
        centre beyond ``max_offset + tol``.
    """
    from scipy.optimize import least_squares
    P = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    c0 = np.asarray(center, dtype=np.float64).reshape(2)
    if len(P) < 3 or not (np.isfinite(r_min) and np.isfinite(r_max) and r_max > r_min >= 0):
        return []
    s = max(float(tol), float(max_offset) / 8.0)
    k = int(np.ceil(max_offset / s))
    g = np.arange(-k, k + 1) * s
    off = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    off = off[np.hypot(off[:, 0], off[:, 1]) <= max_offset + 1e-9]
    cs = c0 + off  # (C, 2)
    w = max(2.0 * tol, 1.5 * s)
    lo = r_min - 0.5 * w
    nb = int(np.ceil((r_max + 0.5 * w - lo) / (0.5 * w))) + 1
    # the distances' bins, computed in place on (C, n) arrays (the voting is most of the search's
    # own cost); sqrt(dx^2 + dy^2) rather than np.hypot, 4x faster and within 1 ulp of it: a vote
    # moves to the next bin only where a distance lies within 1 ulp (1e-14 px) of a bin's edge
    d = P[None, :, 0] - cs[:, None, 0]  # (C, n)
    dy = P[None, :, 1] - cs[:, None, 1]
    d *= d
    dy *= dy
    d += dy
    np.sqrt(d, out=d)
    d -= lo
    d /= 0.5 * w
    np.floor(d, out=d)
    # the bins out of range go to two spare bins per centre (below and above), cut off after the
    # count: the same votes as selecting the bins in range, without the boolean mask's copy
    np.clip(d, -1.0, nb, out=d)
    d += (np.arange(len(cs)) * (nb + 2) + 1)[:, None]  # (exact: integers far below 2**53)
    votes = np.bincount(d.ravel().astype(np.int64), minlength=len(cs) * (nb + 2)).reshape(len(cs), nb + 2)
    votes = votes[:, 1:-1]
    win = votes[:, :-1] + votes[:, 1:]  # window j covers [lo + j w/2, lo + (j + 2) w/2)
    radii = lo + (np.arange(nb - 1) + 1.0) * 0.5 * w
    score = win / np.maximum(radii, 1.0)[None, :] if per_radius else win.astype(np.float64)
    score = np.where((win >= 3) & (radii >= r_min - 0.5 * w)[None, :] & (radii <= r_max + 0.5 * w)[None, :], score, -1)
    # highest first, ties by grid index; only the windows that may be picked (score >= 0) are sorted
    picked = []
    need = max(2 * n_best, 3)
    for block in highest_first(score.ravel(), np.flatnonzero(score.ravel() >= 0)):
        for idx in block:
            if len(picked) >= need:
                break
            ci, ri = divmod(int(idx), nb - 1)
            if any(np.hypot(*(cs[ci] - cs[cj])) <= s + 1e-9 and abs(radii[ri] - radii[rj]) <= w
                   for cj, rj in picked):
                continue
            picked.append((ci, ri))
        if len(picked) >= need:
            break

    # the residuals and Jacobian on the points' x and y columns (contiguous, split once): the same
    # floats as on the (n, 2) rows, with less of the per-evaluation overhead of the small fits
    def resid(p, X, Y):
        return np.hypot(X - p[0], Y - p[1]) - p[2]

    def jac(p, X, Y):
        J = np.empty((len(X), 3))
        dist = np.hypot(X - p[0], Y - p[1])
        np.maximum(dist, 1e-12, out=dist)
        np.divide(np.subtract(p[0], X, out=J[:, 0]), dist, out=J[:, 0])  # -(x - x0) / dist
        np.divide(np.subtract(p[1], Y, out=J[:, 1]), dist, out=J[:, 1])
        J[:, 2] = -1.0
        return J

    PX, PY = np.ascontiguousarray(P[:, 0]), np.ascontiguousarray(P[:, 1])
    out = []
    for ci, ri in picked:
        p = np.array([cs[ci, 0], cs[ci, 1], radii[ri]])
        for band, scale in ((w, tol), (2.0 * tol, tol)):
            near = np.abs(resid(p, PX, PY)) <= band
            if np.count_nonzero(near) < 3:
                break
            p = least_squares(resid, p, jac=jac, args=(PX[near], PY[near]), loss="soft_l1", f_scale=scale,
                              method="trf").x
        else:
            if r_min <= p[2] <= r_max and np.hypot(*(p[:2] - c0)) <= max_offset + tol:
                inl = np.abs(resid(p, PX, PY)) <= tol
                out.append((p[:2].copy(), float(p[2]), inl))
    rank = [(-(inl.sum() / max(r, 1.0) if per_radius else inl.sum()), float(np.hypot(*(c - c0))), i)
            for i, (c, r, inl) in enumerate(out)]
    return [out[t[2]] for t in sorted(rank)][:n_best]


def _in_frame_bins(center, radius, shape, n_bins):
    """(n_bins,) bool: which angular bins of the circle lie inside the image (all when no shape)."""
    if shape is None:
        return np.ones(n_bins, bool)
    H, W = shape
    t = (np.arange(n_bins) + 0.5) / n_bins * 2 * np.pi - np.pi
    x = center[0] + radius * np.cos(t)
    y = center[1] + radius * np.sin(t)
    return (x >= 0) & (x <= W - 1) & (y >= 0) & (y <= H - 1)


def circle_coverage(points, center, radius, tol: float = 1.5, shape=None, n_bins: int = 72) -> float:
    """Fraction of a circle's in-frame circumference with an edge point within ``tol`` (5-degree bins).

    Parameters
    ----------
    points : (n, 2) float
        Edge points (x, y), pixels.
    center : (2,) float
    radius : float
    tol : float
        Pixels.
    shape : (H, W), optional
        Image size: bins outside the frame are not counted.
    n_bins : int
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    vis = _in_frame_bins(center, radius, shape, n_bins)
    if not vis.any() or len(pts) == 0:
        return 0.0
    v = pts - center
    on = np.abs(np.hypot(v[:, 0], v[:, 1]) - radius) <= tol
    ang = np.arctan2(v[on, 1], v[on, 0])
    bins = np.floor((ang + np.pi) / (2 * np.pi) * n_bins).astype(int) % n_bins
    hit = np.zeros(n_bins, bool)
    hit[bins] = True
    return float(np.count_nonzero(hit & vis) / np.count_nonzero(vis))


def enclosing_circle(points, center, radius, *, shape=None, tol: float = 1.5,
                     min_growth: float = 1.12, max_growth: float = 2.0, min_coverage: float = 0.5,
                     min_new: float = 0.3, max_outside: float = 0.05, n_search: int = 6) -> OuterCircle | None:
    """The outermost well-supported circle that encloses a candidate circle's outline, or None.

    The circles best supported by the edge points within ``max_growth`` radii of the candidate
    (:func:`circle_search`, ranked by inliers per pixel of radius; centres within ``max_growth -
    1`` radii of the candidate's, radii ``min_growth`` to ``max_growth`` times its radius) are
    tested. A circle qualifies when at most ``max_outside`` of the candidate's own outline points
    (within ``tol`` of the candidate circle) lie more than ``tol`` outside it, at least ``min_new``
    of its inliers are off the candidate circle, and its inliers cover at least ``min_coverage`` of
    its in-frame circumference (:func:`circle_coverage`). Of the qualifying circles the best
    covered wins (ties: the larger). The result is then refined by an algebraic least-squares
    circle on its inliers (Kasa), re-checked against the same tests. Deterministic: the same
    points in any order give the same circle.

    Parameters
    ----------
    points : (n, 2) float
        Edge points (x, y), pixels: every edge of the image (or of the region).
    center : (2,) float
        The candidate circle's centre, pixels.
    radius : float
        Its radius, pixels.
    shape : (H, W), optional
        Image size, for the in-frame circumference.
    tol : float
        Inlier distance, pixels.
    min_growth, max_growth, min_coverage, min_new, max_outside : float
        The tests above.
    n_search : int
        Circles of :func:`circle_search` tested.

    Returns
    -------
    OuterCircle or None
        None when no larger circle qualifies (the candidate is its own outline).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    c0 = np.asarray(center, dtype=np.float64).reshape(2)
    r0 = float(radius)
    if not (np.isfinite(r0) and r0 > 0) or len(pts) < 8:
        return None
    d0 = np.hypot(pts[:, 0] - c0[0], pts[:, 1] - c0[1])
    own = np.abs(d0 - r0) <= tol
    max_offset = (max_growth - 1) * r0 + tol
    P = pts[d0 <= max_offset + max_growth * r0 + tol]  # every point a qualifying circle can pass through
    own_pts = pts[own]
    if len(P) < 8 or len(own_pts) < 3:
        return None

    def qualifies(cc, rr):
        if not (min_growth * r0 <= rr <= max_growth * r0) or np.hypot(*(cc - c0)) >= rr:
            return None
        d_own = np.hypot(own_pts[:, 0] - cc[0], own_pts[:, 1] - cc[1])
        if np.mean(d_own > rr + tol) > max_outside:
            return None
        d = np.hypot(pts[:, 0] - cc[0], pts[:, 1] - cc[1])
        inl = np.abs(d - rr) <= tol
        if inl.sum() < 8:
            return None
        new = float(np.mean(~own[inl]))
        cov = circle_coverage(pts[inl], cc, rr, tol, shape)
        if new < min_new or cov < min_coverage:
            return None
        return OuterCircle(center=np.asarray(cc, dtype=np.float64), radius=float(rr), inliers=inl, coverage=cov,
                           new_fraction=new)

    best = None
    for cc, rr, _ in circle_search(P, c0, max_offset, min_growth * r0, max_growth * r0, tol=tol,
                                   n_best=n_search, per_radius=True):
        q = qualifies(cc, rr)
        if q is not None and (best is None or (q.coverage, q.radius) > (best.coverage, best.radius)):
            best = q
    if best is None:
        return None
    # refine on the inliers (Kasa: x^2 + y^2 = 2 a x + 2 b y + e), re-checked
    Q = pts[best.inliers]
    A = np.column_stack([2 * Q[:, 0], 2 * Q[:, 1], np.ones(len(Q))])
    sol, *_ = np.linalg.lstsq(A, np.sum(Q ** 2, axis=1), rcond=None)
    cc = sol[:2]
    rr = float(np.sqrt(max(sol[2] + cc @ cc, 0.0)))
    q = qualifies(cc, rr)
    if q is not None and q.coverage >= best.coverage - 0.05:
        best = q
    return best


def _ray_profiles(log_lum, c, rs, n_angles: int, step_px: float):
    """Bilinear samples of ``log_lum`` along ``n_angles`` rays from ``c`` at radii ``rs``, smoothed along each ray.

    Returns ``inside`` (A, R) bool (the sample lies in the frame), the profiles (A, R) float, each
    convolved with a 0.7-pixel Gaussian along its ray, and the rays' unit directions (A, 2).
    """
    H, W = log_lum.shape
    t = np.arange(n_angles) / n_angles * 2 * np.pi
    u = np.stack([np.cos(t), np.sin(t)], axis=1)
    xy = c[None, None, :] + rs[None, :, None] * u[:, None, :]  # (A, R, 2)
    inside = (xy[..., 0] >= 0) & (xy[..., 0] <= W - 1) & (xy[..., 1] >= 0) & (xy[..., 1] <= H - 1)
    x = np.clip(xy[..., 0], 0, W - 1.000001)
    y = np.clip(xy[..., 1], 0, H - 1.000001)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    img = np.asarray(log_lum, dtype=np.float64)
    prof = ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x0 + 1])
            + fy * ((1 - fx) * img[y0 + 1, x0] + fx * img[y0 + 1, x0 + 1]))
    k = np.exp(-0.5 * (np.arange(-8, 9) * step_px / 0.7) ** 2)  # 0.7-pixel Gaussian along the ray
    k /= k.sum()
    pad = np.pad(prof, ((0, 0), (8, 8)), mode="edge")
    return inside, np.stack([np.convolve(p, k, mode="valid") for p in pad]), u


def radial_steps(log_lum, center, radius, *, r_range=(0.9, 1.3), n_angles: int = 180, step_px: float = 0.25,
                 min_step: float = 0.02) -> np.ndarray:
    """Every radial brightness step near a circle, sub-pixel: weak outline points of a mirror ball.

    At its limb a mirror reflects what lies just behind it, so its silhouette against that
    background is only the step of its reflectance (about 10% for polished chrome in the renders,
    40% for a real chrome ball), too weak for the image-wide edge thresholds. Along ``n_angles``
    rays from ``center``, ``log_lum`` is sampled (bilinear) from ``r_range[0]`` to ``r_range[1]``
    radii; every local maximum of the absolute radial derivative (after a 0.7-pixel Gaussian) that
    is at least ``min_step`` natural-log units per pixel and 4 times the lower quartile of the
    absolute derivative (the noise of the flat parts) is an outline point, refined by a parabola through its neighbours.

    Parameters
    ----------
    log_lum : (H, W) float
        Natural log of the luminance (of the max image).
    center : (2,) float
        Pixels (x, y).
    radius : float
        Pixels.
    r_range : (2,) float
        Radii searched, in units of ``radius``.
    n_angles : int
    step_px : float
        Sampling step along the rays, pixels.
    min_step : float
        Least derivative, log units per pixel.

    Returns
    -------
    (m, 2) float
        Points (x, y) inside the image.
    """
    c = np.asarray(center, dtype=np.float64).reshape(2)
    rs = np.arange(r_range[0] * radius, r_range[1] * radius, step_px)
    inside, sm, u = _ray_profiles(log_lum, c, rs, n_angles, step_px)
    g = np.abs(np.gradient(sm, step_px, axis=1))
    g[~inside] = 0.0
    noise = float(np.percentile(g[inside], 25)) if inside.any() else 0.0  # flat parts: most of a ray is structure
    thr = max(min_step, 4.0 * noise)
    peak = (g[:, 1:-1] >= thr) & (g[:, 1:-1] >= g[:, :-2]) & (g[:, 1:-1] > g[:, 2:]) & inside[:, 1:-1]
    a_i, r_i = np.nonzero(peak)
    r_i = r_i + 1
    gm, g0, gp = g[a_i, r_i - 1], g[a_i, r_i], g[a_i, r_i + 1]
    den = gm - 2 * g0 + gp
    off = np.where(den < 0, 0.5 * (gm - gp) / np.where(den < 0, den, -1.0), 0.0)
    r = rs[r_i] + np.clip(off, -0.5, 0.5) * step_px
    return c[None, :] + r[:, None] * u[a_i]


def limb_radius(log_lum, center, radius, *, r_range=(0.97, 1.1), n_angles: int = 180, step_px: float = 0.25,
                min_step: float = 0.03, min_angles: int = 30) -> float | None:
    """A mirror ball's radius from its limb: the median distance of its reflectance steps from ``center``.

    At its limb a mirror shows what lies just behind it, dimmed by its reflectance (below 1): going
    outward across the silhouette the radiance *rises*, all round, by the same ratio. The
    reflected room's contrasts that an outer outline follows (:func:`enclosing_circle`) run 1 to 2
    px inside it, so that outline's radius comes out short (3-5% at 384 px), while its centre is
    good (they are nearly concentric). Along ``n_angles`` rays from ``center``, ``log_lum`` is
    sampled (bilinear) over ``r_range`` radii and smoothed by a 0.7-pixel Gaussian; on each ray the
    rising step (a local maximum of the outward derivative of at least ``min_step`` log units per
    pixel: a 10% reflectance step gives about 0.05) *nearest* the outline's radius
    is taken; the median of their distances is the radius. The median ignores the rays that meet a
    contact shadow's outer edge (also rising outward) or no step. None with fewer than
    ``min_angles`` steps.

    Parameters
    ----------
    log_lum : (H, W) float
        Natural log of the luminance (of the max image).
    center : (2,) float
        The outline's centre, pixels (x, y).
    radius : float
        The outline's radius, pixels.
    r_range : (2,) float
        Radii searched, in units of ``radius``.
    n_angles : int
    step_px : float
    min_step : float
    min_angles : int

    Returns
    -------
    float or None
        Pixels.
    """
    c = np.asarray(center, dtype=np.float64).reshape(2)
    rs = np.arange(r_range[0] * radius, r_range[1] * radius, step_px)
    if rs.size < 5:
        return None
    inside, sm, u = _ray_profiles(log_lum, c, rs, n_angles, step_px)
    g = np.gradient(sm, step_px, axis=1)  # signed: > 0 where it brightens outward
    whole = np.all(inside, axis=1)  # rays wholly inside the frame
    if not whole.any():
        return None
    thr = min_step  # not raised by the quartile of the derivative: the reflected room fills the band with structure
    peak = (g[:, 1:-1] >= thr) & (g[:, 1:-1] >= g[:, :-2]) & (g[:, 1:-1] > g[:, 2:]) & whole[:, None]
    a_i, r_i = np.nonzero(peak)
    if a_i.size == 0:
        return None
    dist = np.abs(rs[r_i + 1] - radius)
    best = {}
    for a, r, d in zip(a_i, rs[r_i + 1], dist):
        if a not in best or d < best[a][1]:
            best[a] = (r, d)
    if len(best) < min_angles:
        return None
    return float(np.median([v[0] for v in best.values()]))


def changing_limb_edges(strength, center, radius, *, band_px: float = 3.0, outside_px=(4.0, 7.0),
                        level: float = 0.5, n_angles: int = 180, step_px: float = 0.25) -> np.ndarray:
    """Per ray, the outer edge of the band of edges that change with the light (see
    :func:`changing_limb_radius`, which takes their median).

    Along ``n_angles`` rays from ``center`` (ray ``k`` at ``2 pi k / n_angles`` from the image's
    +x, toward +y), ``strength`` is sampled (bilinear, 0.7-pixel Gaussian along the ray) from
    ``radius - band_px - 1`` to ``radius + outside_px[1]``; on each ray the peak within ``band_px``
    of ``radius`` and the outside level (the median over ``outside_px`` beyond ``radius``) are
    taken, and the edge is where the profile first falls, going outward from the peak, below
    ``level`` of the way from the outside level to the peak (linear between samples).

    Parameters
    ----------
    strength : (H, W) float
    center : (2,) float
        Pixels (x, y).
    radius : float
        Pixels.
    band_px, outside_px, level, n_angles, step_px
        As :func:`changing_limb_radius`.

    Returns
    -------
    (n_angles,) float
        Each ray's edge, pixels from ``center``; NaN for a ray that leaves the frame, whose peak is
        not above the outside level, or that does not fall below the level.
    """
    c = np.asarray(center, dtype=np.float64).reshape(2)
    edges = np.full(n_angles, np.nan)
    rs = np.arange(max(radius - band_px - 1.0, step_px), radius + outside_px[1] + step_px / 2, step_px)
    inside, prof, _ = _ray_profiles(strength, c, rs, n_angles, step_px)
    whole = np.all(inside, axis=1)
    in_band = np.abs(rs - radius) <= band_px
    outer = (rs >= radius + outside_px[0]) & (rs <= radius + outside_px[1])
    if not (in_band.any() and outer.any()):
        return edges
    first = int(np.flatnonzero(in_band)[0])
    for a in np.flatnonzero(whole):
        p = prof[a]
        k0 = first + int(np.argmax(p[in_band]))
        out = float(np.median(p[outer]))
        if not p[k0] > out:
            continue
        thr = out + level * (p[k0] - out)
        below = np.flatnonzero(p[k0 + 1:] < thr)
        if below.size == 0:
            continue
        k = k0 + int(below[0])  # p[k] >= thr > p[k + 1]
        edges[a] = rs[k] + (p[k] - thr) / (p[k] - p[k + 1]) * step_px
    return edges


def changing_limb_radius(strength, center, radius, *, band_px: float = 3.0, outside_px=(4.0, 7.0),
                         level: float = 0.5, n_angles: int = 180, step_px: float = 0.25,
                         min_angles: int = 30) -> float | None:
    """A mirror ball's radius from the outer edge of the band of edges that change with the light.

    Inside a chrome ball the reflected scene changes with each light (reflected highlights and
    shadows move), and near the limb it is squeezed into the last pixels (a reflected direction's
    distance from the rim goes as the square root of its distance from grazing), so the strength
    of the changing edges (``strength``: :func:`ffls.spheres.detect.consistent_edge_strength`
    ``centered``) is a plateau over the ball's inside that peaks just inside the limb and falls to
    the ground's level outside it. A pixel on the silhouette integrates part ball, part ground
    (a lens and sensor blur the limb over a pixel or more): the peak of the band lies 0.5-1.5 px
    inside the silhouette, its outer edge on it. The edge is found per ray
    (:func:`changing_limb_edges`), and the median of the edges' distances is the radius. None with
    fewer than ``min_angles`` edges; however far the edges spread, their median is kept. The edges
    spread by what changes with the light just beside the limb (the ball's cast and contact
    shadows outside it, the dark cap's edge and the reflected horizon inside it: 1-4 px in some
    30-degree sectors), not by the median's error: an
    anti-aliased lone chrome ball whose edges spread 1.38 px (``bench_conditions.py``'s c21) has
    their median 0.13 px inside its silhouette, and refusing it left the outline 1.64 px short
    (docs/spheres.md, ``i-aa15``). The caller's
    :data:`ffls.spheres.detect.MIRROR_LIMB_MAX_CHANGE` bounds the change instead.

    Parameters
    ----------
    strength : (H, W) float
    center : (2,) float
        The outline's centre, pixels (x, y).
    radius : float
        The outline's radius, pixels.
    band_px : float
    outside_px : (2,) float
    level : float
    n_angles : int
    step_px : float
    min_angles : int

    Returns
    -------
    float or None
        Pixels.
    """
    edges = changing_limb_edges(strength, center, radius, band_px=band_px, outside_px=outside_px, level=level,
                                n_angles=n_angles, step_px=step_px)
    edges = edges[np.isfinite(edges)]
    if len(edges) < min_angles:
        return None
    return float(np.median(edges))


def mirror_silhouette(log_lum, center, radius, *, shape=None, min_coverage: float = 0.5,
                      max_growth: float = 1.25, tol: float = 1.0, min_shrink: float = 0.97,
                      n_best: int | None = None, max_offset: float | None = None, r_min: float | None = None,
                      r_max: float | None = None):
    """A mirror ball's silhouette near an outer outline: the circle of weak reflectance steps.

    The outline found from the image-wide edges (:func:`enclosing_circle`) follows the reflected
    room's strongest contrasts, which run just inside the limb (at 384 px the ball's radius came out
    1.4 px short, its centre 5 cm deep). The steps of :func:`radial_steps` within ``0.9`` to
    ``max_growth`` radii (from ``min_shrink`` radii when that is smaller) are searched for the
    circle with most of them within ``tol`` (:func:`circle_search`: radius at least ``min_shrink``
    of the outline's, centre within ``max_growth - 0.9`` radii of its centre); the result is kept
    when its inliers cover at least ``min_coverage`` of its in-frame circumference.

    ``min_shrink`` below 1 serves an outline that is too large: a mirror ball's dark cap fitted
    together with the contact shadow under the ball, where the ball's lower half reflects the table
    it stands on and shows no silhouette in the edges (``bench_lights.py --configs near_mixed`` at
    384 px: that fit was 1.8 px off and its radius 7 % large; the circle of steps from 0.75 radii
    is 0.2 px off).

    ``n_best`` asks for the ``n_best`` best-supported circles (:func:`circle_search`) instead of the
    best one, for a caller that chooses among them (:func:`ffls.probes.locate.mirror_limb`).
    ``max_offset``, ``r_min`` and ``r_max`` (pixels) replace the search window's centre offset
    (``max_growth - 0.9`` radii) and radius range (``min_shrink`` to ``max_growth`` radii), for a
    caller that searches another window on the same steps (:func:`ffls.probes.locate.unhinted_mirror_limb`).

    Returns
    -------
    (points (m, 2), centre (2,), radius) or None
        The inlier points (for the sphere fit) and the circle.
    list of (points (m, 2), centre (2,), radius)
        With ``n_best``: each of those circles that passes the coverage test, best first (empty
        when none does).
    """
    lo = min(0.9, min_shrink)
    pts = radial_steps(log_lum, center, radius, r_range=(lo, max_growth))
    max_offset = (max_growth - lo) * radius if max_offset is None else max_offset
    r_min = min_shrink * radius if r_min is None else r_min
    r_max = max_growth * radius if r_max is None else r_max
    found = [] if len(pts) < 8 else circle_search(pts, center, max_offset, r_min, r_max, tol=tol,
                                                  n_best=n_best or 1)
    passed = [(pts[inl], c, r) for c, r, inl in found
              if inl.sum() >= 8 and circle_coverage(pts[inl], c, r, tol, shape) >= min_coverage]
    if n_best:
        return passed
    return passed[0] if passed else None


def _disc_crop(lum, center, radius, outer: float = 1.4):
    """``(crop, d)``: ``lum`` within ``outer`` radii of the circle (clipped to the frame) and each
    pixel's distance from the centre in radii; ``(None, None)`` when nothing of it is in the frame."""
    H, W = lum.shape
    cx, cy = float(center[0]), float(center[1])
    R = outer * float(radius)
    x0, x1 = max(int(np.floor(cx - R)), 0), min(int(np.ceil(cx + R)) + 1, W)
    y0, y1 = max(int(np.floor(cy - R)), 0), min(int(np.ceil(cy + R)) + 1, H)
    if x1 <= x0 or y1 <= y0:
        return None, None
    yy, xx = np.mgrid[y0:y1, x0:x1]
    d = np.hypot(xx - cx, yy - cy) / float(radius)
    return np.asarray(lum, dtype=np.float64)[y0:y1, x0:x1], d


def dark_cap(lum, center, radius, ratio: float = 0.7, quantile: float = 50.0) -> bool:
    """Whether a circle looks like a mirror ball's dark cap: darker inside than just around it.

    A chrome ball under a hand-held light reflects the dark room above the table: in the max image
    the cap (inside 0.7 radii) is darker than the ring just outside (1.15 to 1.4 radii), whose
    median it must stay below ``ratio`` times. A sphere's lit cap or a highlight is brighter than its
    surroundings; only a dark cap is grown to an outer outline (:func:`enclosing_circle`).
    ``quantile`` (percent) is the share of the cap compared: 50 (its median) by default; 25 asks
    only a quarter of it to be dark (a chrome ball whose cap also holds the highlights of many
    lights and the lit table's reflection).

    Parameters
    ----------
    lum : (H, W) float
        Luminance of the max image.
    center : (2,) float
    radius : float
    ratio : float
    quantile : float
    """
    crop, d = _disc_crop(lum, center, radius)
    if crop is None:
        return False
    inside, ring = crop[d <= 0.7], crop[(d >= 1.15) & (d <= 1.4)]
    if inside.size < 5 or ring.size < 5:
        return False
    return bool(np.percentile(inside, quantile) < ratio * np.median(ring))


def highlight_ratio(lum, center, radius) -> float | None:
    """How much brighter a circle's brightest pixel is than its surroundings: a mirror ball's highlights.

    A mirror reflects the lights themselves, whose radiance far exceeds that of any lit diffuse
    surface around it, so in the max image a chrome or black glossy ball holds pixels many times
    brighter than the ring just outside it (1049 and 85 times the ring's 95th percentile on
    ``bench_lights.py --configs near_mixed`` at 384 px; 3.5 in an 8-bit file where the highlight
    clips). A dark patch of a textured ground whose outline looks like a mirror's dark cap holds
    none (1.02 on the busy JPEG). Returns the brightest pixel within 0.95 radii over the 95th
    percentile of the ring from 1.15 to 1.4 radii (``lum``: the max image's luminance), or None
    when either holds fewer than 5 pixels in the frame, or when the ring itself is clipped (its
    95th percentile at 0.98 of the image's maximum or above: a saturated file gives no evidence).

    Parameters
    ----------
    lum : (H, W) float
    center : (2,) float
    radius : float
    """
    crop, d = _disc_crop(lum, center, radius)
    if crop is None:
        return None
    disc, ring = crop[d <= 0.95], crop[(d >= 1.15) & (d <= 1.4)]
    if disc.size < 5 or ring.size < 5:
        return None
    ring95 = float(np.percentile(ring, 95))
    if ring95 >= 0.98 * float(np.max(lum)):
        return None
    return float(disc.max() / max(ring95, 1e-12))


#: Half-width (pixels) of the band around the outline in which :func:`fit_limb_profile` models the
#: brightness: the blurred step and the ramps on either side (a glossy ball's Fresnel rim brightens
#: over 2-3 px at 384 px) within it, the ball's reflected contents beyond it.
LIMB_BAND_PX = 5.0
#: The limb's step places a ball only where its body is dark against what surrounds it: 90 % of
#: the disc (inside 0.7 radii of the sequence's mean image) below this fraction of the ring just
#: outside it (:func:`dark_cap`; :func:`ffls.spheres.highlight.refine_view_limb`,
#: ``detect._on_changing_limb``). A black glossy ball (a dielectric:
#: about 4 % reflectance) reads 0.10-0.12 on the renders of ``bench_conditions.py``; a chrome ball
#: reflects its surroundings at their own brightness somewhere on its disc (0.96-4.9), and a clear
#: step there can be a reflected edge inside the rim (a chrome ball of the 8 mixed spheres: a jump
#: of 18 noise units, the step 1.4 px short where the detected outline was 0.46 px short).
LIMB_DARK_BODY_RATIO = 0.5


def dark_body(lum, center, radius) -> bool:
    """Whether a ball's body is dark against what surrounds it (:data:`LIMB_DARK_BODY_RATIO`, 90 %
    of the disc: :func:`dark_cap`): a black glossy ball's, not a chrome ball's."""
    return dark_cap(lum, center, radius, ratio=LIMB_DARK_BODY_RATIO, quantile=90.0)


#: Least brightness jump of a sector at the limb, in units of the band's noise, for its edge to
#: count in the outline's uncertainty (:attr:`LimbFit.sector_offsets_px`).
LIMB_MIN_JUMP_SNR = 3.0


@dataclasses.dataclass(frozen=True)
class LimbFit:
    """A sphere's silhouette located by the brightness step at its limb (:func:`fit_limb_profile`).

    Attributes
    ----------
    center_px : (2,) float
        The centre of the silhouette's apparent circle (orthographic) or the image of the
        sphere's centre (pinhole), pixels.
    radius_px : float
        Apparent radius (orthographic), or ``f tan(alpha)`` (pinhole: ``alpha`` the tangent cone's
        half-angle, ``f`` the mean focal length), pixels.
    center_cam : (3,) float or None
        Pinhole: the sphere's centre in the camera frame, from the cone and the sphere's radius.
    blur_px : float
        The fitted Gaussian blur of the step (optics, pixel area, demosaicing), pixels.
    center_sigma_px : float
        Per-axis standard deviation of the centre (pixels), from the scatter of the sectors' edges.
    radius_sigma_px : float
        Standard deviation of the radius (pixels).
    shift_px : float
        How far the outline moved from the circle it started from: at most this many pixels
        anywhere on the circumference (the centre's move plus the radius's change).
    sector_offsets_px : (n,) float
        Radial offset of each sector's own step from the fitted outline (NaN: the sector's jump is
        below :data:`LIMB_MIN_JUMP_SNR` times the noise, or it has too few pixels).
    noise : float
        Robust spread of the model's residuals in the band.
    jump_snr : (n,) float
        Each sector's brightness jump at the outline (background less rim) over ``noise``
        (NaN: a sector without pixels on both sides).
    """

    center_px: np.ndarray
    radius_px: float
    center_cam: np.ndarray | None
    blur_px: float
    center_sigma_px: float
    radius_sigma_px: float
    shift_px: float
    sector_offsets_px: np.ndarray
    noise: float
    jump_snr: np.ndarray


def limb_window(center_px, radius_px: float, shape, band_px: float | None = None) -> tuple[int, int, int, int]:
    """The pixels :func:`fit_limb_profile` reads around a ball: ``(x0, x1, y0, y1)``, inclusive.

    A square of half-width ``1.25 radius_px + band_px + 2`` around ``center_px``, clipped to the
    image ``shape`` (H, W); ``band_px`` as :func:`fit_limb_profile`'s default when None. Where the
    whole photo is not at hand (the Dask path, :mod:`ffls.cluster.lights`), this window of every
    photo is all the limb fit needs.
    """
    c0 = np.asarray(center_px, dtype=np.float64)
    r0 = float(radius_px)
    band_px = max(LIMB_BAND_PX, 0.15 * r0) if band_px is None else float(band_px)
    H, W = int(shape[0]), int(shape[1])
    reach = r0 * 1.25 + band_px + 2
    x0, x1 = max(int(np.floor(c0[0] - reach)), 0), min(int(np.ceil(c0[0] + reach)), W - 1)
    y0, y1 = max(int(np.floor(c0[1] - reach)), 0), min(int(np.ceil(c0[1] + reach)), H - 1)
    return x0, x1, y0, y1


def limb_basis(t: np.ndarray, blur: float) -> np.ndarray:
    """The blurred limb's five brightness terms at signed distances ``t`` from the outline.

    The brightness across the limb is ``a + b t + c t^2`` inside (``t < 0``: the ball's rim, where
    a glossy ball's Fresnel reflectance rises toward grazing) and ``d + e t`` outside (the
    background), seen through a Gaussian blur of standard deviation ``blur``: each term is the
    expectation of its piece over ``X ~ N(t, blur^2)`` restricted to its side, in closed form
    (``Phi``, ``phi`` the normal CDF and density, ``z = t / blur``): ``Phi(-z)``,
    ``t Phi(-z) - s phi(z)``, ``(t^2 + s^2) Phi(-z) - t s phi(z)``, ``Phi(z)``, ``t Phi(z) + s phi(z)``.

    Parameters
    ----------
    t : (m,) float
        Signed distance from the outline (pixels; negative inside).
    blur : float
        Standard deviation of the blur (pixels, > 0).

    Returns
    -------
    (m, 5) float
        The terms multiplying ``(a, b, c, d, e)``.
    """
    from scipy.special import ndtr

    t = np.asarray(t, dtype=np.float64)
    s = float(blur)
    z = t / s
    cin, cout = ndtr(-z), ndtr(z)
    pdf = np.exp(-0.5 * z * z) / np.sqrt(2.0 * np.pi)
    return np.stack([cin, t * cin - s * pdf, (t * t + s * s) * cin - t * s * pdf, cout, t * cout + s * pdf], axis=1)


def fit_limb_profile(image, center_px, radius_px, *, model: str = "orthographic", K=None, dist=None,
                     center_cam=None, radius=None, band_px: float | None = None,
                     n_sectors: int | None = None) -> LimbFit | None:
    """A mirror or glossy ball's silhouette from the brightness step at its limb, sub-pixel.

    Edge detectors put a chrome or black glossy ball's outline where the brightness changes
    fastest, which is not the limb: toward grazing, the ball's reflectance rises (Fresnel) and its
    rim brightens over a few pixels toward the background it reflects, so the steepest change, and
    the edge, lie up to a pixel inside the silhouette (on ``ffls synth --sphere-material
    glossy_black`` at 384 px, 0.8 px: 3 % of the radius, 2 degrees of light direction). Here the
    limb is the position of a *discontinuity*: around the outline, in ``n_sectors`` sectors
    each with its own brightness on either side, the band of pixels within ``band_px`` of the
    outline is fitted with a step of smooth sides under a Gaussian blur (:func:`limb_basis`; the
    parametric blurred-edge model of Nalwa and Binford, "On Detecting Edges", PAMI 1986, on a
    circle), by robust least squares (``scipy.optimize.least_squares``, ``soft_l1``) over the
    outline's geometry, the blur and every sector's five brightness terms. The image should be a
    reduction of the whole sequence (the mean luminance of the photos): the silhouette is fixed,
    the lights move.

    Geometry: orthographic, the apparent circle (centre, radius; ``t`` the distance to it);
    pinhole, the sphere's tangent cone (its axis and half-angle ``alpha``, ``t`` the angle of the
    pixel's viewing ray (:func:`ffls.camera.projection.camera_rays`, with distortion) to the axis
    less ``alpha``, times the focal length): the silhouette's ellipse, exactly.

    Uncertainty: each sector's own step (its radial offset, fitted with the rest held) scatters
    about the outline; with ``m`` sectors whose jump exceeds :data:`LIMB_MIN_JUMP_SNR` times the
    noise and robust spread ``s`` of their offsets, the centre's per-axis sigma is
    ``s sqrt(2 / m)`` and the radius's ``s / sqrt(m)`` (a circle fitted to ``m`` evenly spread
    points).

    Parameters
    ----------
    image : (H, W) or (n, H, W) float
        Brightness (linear preferred: a blurred step mixes linear light): a reduction of the
        sequence, or a stack of ``n`` photos, each sector of each photo then with brightness
        terms of its own and the outline shared (its jump, :attr:`LimbFit.jump_snr`, the RMS
        over the photos). Pixels may be NaN (not read).
    center_px : (2,) float
        The starting outline's centre (pixels, x right, y down).
    radius_px : float
        Its apparent radius (pixels).
    model : {'orthographic', 'pinhole'}
    K, dist
        Pinhole intrinsics and OpenCV distortion.
    center_cam : (3,) float, optional
        Pinhole: the starting sphere centre (camera frame; required with ``radius``).
    radius : float, optional
        Pinhole: the sphere's radius (scene units).
    band_px : float, optional
        Half-width of the band (pixels); default the larger of :data:`LIMB_BAND_PX` and 15 % of the
        radius (the rim's ramp scales with the ball). The outline may move by half of it; a fit
        that reaches that bound found another edge, and gives None.
    n_sectors : int, optional
        Sectors around the outline; default one per 8 px of circumference, 8 to 36.

    Returns
    -------
    LimbFit or None
        None where the band holds too few pixels in the frame, fewer than 3 sectors show a jump, or
        the fit does not converge.
    """
    from scipy.optimize import least_squares, minimize_scalar

    from ffls.camera.projection import camera_rays, project_points
    from ffls.conventions import normalize, tangent_basis

    img = np.asarray(image, dtype=np.float64)
    if img.ndim == 2:
        img = img[None]
    n_img, H, W = img.shape
    c0 = np.asarray(center_px, dtype=np.float64)
    r0 = float(radius_px)
    if not (np.all(np.isfinite(c0)) and np.isfinite(r0) and r0 > 2):
        return None
    pinhole = model == "pinhole"
    band_px = max(LIMB_BAND_PX, 0.15 * r0) if band_px is None else float(band_px)
    if pinhole and (K is None or center_cam is None or radius is None):
        raise ValueError("a pinhole limb fit needs K, center_cam and radius")
    x0, x1, y0, y1 = limb_window(c0, r0, (H, W), band_px)
    if x1 <= x0 or y1 <= y0:
        return None
    yy, xx = np.mgrid[y0:y1 + 1, x0:x1 + 1]
    px = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(np.float64)
    vals = img[:, yy.ravel(), xx.ravel()]  # (n_img, pixels)
    if pinhole:
        K = np.asarray(K, dtype=np.float64)
        f = 0.5 * (K[0, 0] + K[1, 1])
        C = np.asarray(center_cam, dtype=np.float64)
        dC = float(np.linalg.norm(C))
        if not dC > float(radius):
            return None
        u0 = C / dC
        alpha0 = float(np.arcsin(float(radius) / dC))
        e1, e2 = tangent_basis(u0)
        rays = camera_rays(px, "pinhole", K, dist)

        def geometry(g):
            u = normalize(u0 + (g[0] * e1 + g[1] * e2) / f)
            return u, alpha0 + g[2] / f

        def signed(g):
            u, alpha = geometry(g)
            return (np.arccos(np.clip(rays @ u, -1.0, 1.0)) - alpha) * f

        def azimuth(g):
            u, _ = geometry(g)
            return np.arctan2(rays @ e2, rays @ e1)
    else:
        def signed(g):
            return np.hypot(px[:, 0] - c0[0] - g[0], px[:, 1] - c0[1] - g[1]) - (r0 + g[2])

        def azimuth(g):
            return np.arctan2(px[:, 1] - c0[1] - g[1], px[:, 0] - c0[0] - g[0])

    g0 = np.zeros(3)
    t0 = signed(g0)
    band = np.abs(t0) <= band_px
    if not np.all(np.isfinite(vals[:, band])):
        band &= np.all(np.isfinite(vals), axis=0)
    circumference = 2 * np.pi * r0
    n_sec = int(np.clip(round(circumference / 8.0), 8, 36)) if n_sectors is None else int(n_sectors)
    sector = np.floor((azimuth(g0) + np.pi) / (2 * np.pi) * n_sec).astype(int) % n_sec
    # a sector needs pixels on both sides of its step to have one
    keep = np.zeros(n_sec, dtype=bool)
    for j in range(n_sec):
        sj = band & (sector == j)
        keep[j] = np.count_nonzero(sj & (t0 < -1)) >= 6 and np.count_nonzero(sj & (t0 > 1)) >= 6
    if np.count_nonzero(keep) < 3:
        return None
    idx = np.flatnonzero(band & keep[sector])
    idx = idx[np.argsort(sector[idx], kind="stable")]  # grouped by sector (for np.add.reduceat)
    sec_ids, sec = np.unique(sector[idx], return_inverse=True)
    y = vals[:, idx].ravel()  # photo by photo, each grouped by sector
    # the band's pixels only from here on (signed() reads these names)
    if pinhole:
        rays = rays[idx]
    else:
        px = px[idx]
    n_s = len(sec_ids)
    lim = 0.5 * band_px  # how far the outline may move
    # every photo's sectors have brightness terms of their own: group (photo, sector)
    grp = (np.arange(n_img)[:, None] * n_s + sec[None, :]).ravel()
    starts = np.flatnonzero(np.r_[True, grp[1:] != grp[:-1]])

    def terms(theta, w):
        """Each group's five brightness terms by weighted least squares, for the geometry and blur ``theta``."""
        B = np.tile(limb_basis(signed(theta[:3]), np.exp(theta[3])), (n_img, 1))
        A = B * w[:, None]
        G = np.add.reduceat(A[:, :, None] * A[:, None, :], starts, axis=0)
        h = np.add.reduceat(A * (w * y)[:, None], starts, axis=0)
        G = G + 1e-12 * np.trace(G, axis1=1, axis2=2)[:, None, None] * np.eye(5)
        return B, np.linalg.solve(G, h[:, :, None])[:, :, 0]

    def residuals(theta, w):
        B, lin = terms(theta, w)
        return w * (np.sum(B * lin[grp], axis=1) - y)

    # variable projection (the terms are linear given the geometry: solved inside), with the robust
    # soft-L1 loss by reweighting (its weights 1 / sqrt(1 + (r / scale)^2) from the previous round)
    theta = np.array([0.0, 0.0, 0.0, np.log(0.7)])
    lo, hi = np.array([-lim, -lim, -lim, np.log(0.2)]), np.array([lim, lim, lim, np.log(3.0)])
    w = np.ones(y.size)
    for _ in range(3):
        try:
            sol = least_squares(residuals, theta, args=(w,), bounds=(lo, hi), x_scale=np.array([1.0, 1.0, 1.0, 0.5]),
                                diff_step=1e-4, max_nfev=100)
        except (ValueError, np.linalg.LinAlgError):
            return None
        if sol.status <= 0 or not np.all(np.isfinite(sol.x)):
            return None
        theta = sol.x
        B, lin = terms(theta, w)
        res = np.sum(B * lin[grp], axis=1) - y
        scale = max(1.4826 * float(np.median(np.abs(res))), 1e-9 * max(float(np.abs(y).max()), 1e-12))
        w = (1.0 + (res / scale) ** 2) ** -0.25  # sqrt of the soft-L1 weight
    if np.any(np.abs(theta[:3]) >= 0.98 * lim):  # at the window's edge: another edge than the limb's pulled it
        return None
    g, blur = theta[:3], float(np.exp(theta[3]))
    noise = max(1.4826 * float(np.median(np.abs(res))), 1e-12)
    # each sector's own step: its offset along t, the others held
    t_fit = signed(g)
    offsets, snr = np.full(n_sec, np.nan), np.full(n_sec, np.nan)
    w2, y2 = w.reshape(n_img, -1), y.reshape(n_img, -1)
    lin2 = lin.reshape(n_img, n_s, 5)
    for k, j in enumerate(sec_ids):
        m = sec == k
        # the background over the rim at the outline, RMS over the photos
        snr[int(j)] = float(np.sqrt(np.mean((lin2[:, k, 3] - lin2[:, k, 0]) ** 2))) / noise
        if snr[int(j)] < LIMB_MIN_JUMP_SNR:
            continue

        wm, ym, tm = w2[:, m], y2[:, m], t_fit[m]

        def cost(q, wm=wm, ym=ym, tm=tm):
            A = limb_basis(tm - q, blur)[None] * wm[:, :, None]  # (photos, pixels, 5)
            G = np.einsum("pik,pil->pkl", A, A)
            G = G + 1e-12 * np.trace(G, axis1=1, axis2=2)[:, None, None] * np.eye(5)
            x = np.linalg.solve(G, np.einsum("pik,pi->pk", A, wm * ym)[:, :, None])[:, :, 0]
            return float(np.sum((np.einsum("pik,pk->pi", A, x) - wm * ym) ** 2))

        sk = minimize_scalar(cost, bounds=(-lim, lim), method="bounded", options={"xatol": 1e-3})
        if sk.success and abs(sk.x) < 0.95 * lim:  # at the bound: no step of its own within reach
            offsets[int(j)] = sk.x
    good = np.isfinite(offsets)
    m_good = int(np.count_nonzero(good))
    if m_good < 3:
        return None
    spread = 1.4826 * float(np.median(np.abs(offsets[good] - np.median(offsets[good]))))
    # at least the scatter a single sector's step would have alone (its own fit's precision)
    spread = max(spread, blur / np.sqrt(max(idx.size / n_s, 1.0)))
    c_sig, r_sig = spread * np.sqrt(2.0 / m_good), spread / np.sqrt(m_good)
    if pinhole:
        u, alpha = geometry(g)
        if not 0 < alpha < np.pi / 2:
            return None
        Cn = float(radius) / np.sin(alpha) * u
        cpx = project_points(Cn[None], K, dist)[0]
        rpx = f * np.tan(alpha)
    else:
        Cn, cpx, rpx = None, c0 + g[:2], r0 + g[2]
    shift = float(np.hypot(g[0], g[1]) + abs(g[2]))
    return LimbFit(center_px=np.asarray(cpx, dtype=np.float64), radius_px=float(rpx), center_cam=Cn, blur_px=blur,
                   center_sigma_px=float(c_sig), radius_sigma_px=float(r_sig), shift_px=shift,
                   sector_offsets_px=offsets, noise=noise, jump_snr=snr)
