"""Photometric refinement of a sphere's centre from the shading of the whole sequence.

The silhouette fixes a sphere's centre well where the outline is lit, poorly where the limb is
only dimly lit (the underside above the contact shadow, the side the light never visits): the
edge is found inside the true outline there and the centre's direction moves by 0.2-0.3 px, which
tilts the normals near the limb by ``delta / (r cos)`` and costs up to ~1 degree of light
direction (docs/spheres.md, "Independent renders"). The shading of a Lambertian sphere is a
second, independent measurement of the centre: with the wrong centre the normals at the pixels
are wrong, and no light direction, ambient and ground bounce reproduce the shading of many
photos with diverse light directions (the terminator moves, the limb darkens at the wrong
place). Masselus et al. (2002, section 5) fit the light from the shading of a sphere of known
centre; here the same model (:func:`ffls.spheres.lambert.fit_lambert`:
``I = [n . l > 0] n . v + b + c g(n)``) is fitted to many photos at once with the centre free.

Method (:func:`refine_sphere_centre`):

* the centre moves on the sphere of radius ``D = |C - O|`` around the camera centre ``O`` (the
  silhouette's half-angle ``asin(R / D)``, i.e. the depth, is kept: it is weakly determined
  photometrically and does not change the normals' directions to first order); two parameters,
  the shift of the cone axis in pixels (``f`` times the tangent-plane offset);
* pixels: the sphere's samples (already 1.5 px inside the outline) shrunk by a further
  ``margin_px`` of the initial outline, so that every trial centre within ``max_shift_px`` still
  hits every pixel; fixed during the optimisation;
* photos: up to ``max_photos`` whose first-pass fit of this sphere is ``'ok'``, chosen by
  farthest-point sampling of their light directions (diverse terminators);
* per photo the lit and shadow pixels (``|n . l| > terminator`` with the first-pass direction and
  the initial normals) and the outliers (beyond ``clip_sigma`` robust sigma at the initial
  centre: cast shadows, the object's interreflection, specks) are held fixed; saturated and
  near-black pixels (the caller's validity mask) are never used;
* for each trial centre the per-photo linear parameters ``v = a l, b, c`` are solved in closed
  form (variable projection, Golub & Pereyra 1973); the projected residual, relative to the
  photo's intensity ``a``, is minimised over the two centre parameters by
  :func:`scipy.optimize.least_squares` with a robust ``soft_l1`` loss (scale: the median
  per-photo robust sigma);
* two rounds: after the first the lit/shadow classes and outliers are recomputed with the
  refined normals and the photos' refitted directions.

The refined centre replaces the detected one only if the fit succeeded, lowered the cost and
stayed inside ``max_shift_px``. :func:`recentre_samples` then recomputes the sphere's pixels and
normals (a subset of the original pixels, so the photos' values need not be read again).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ffls.conventions import UP, normalize, tangent_basis
from ffls.spheres.samples import SphereSamples, ground_bounce

__all__ = ["CentreRefinement", "refine_sphere_centre", "refine_sphere_centre_shading", "recentre_samples", "select_photos"]


@dataclass
class CentreRefinement:
    """Result of :func:`refine_sphere_centre`.

    Attributes
    ----------
    center : (3,) float64
        Refined world-frame centre (the initial one when ``accepted`` is False).
    center_initial : (3,) float64
        The centre the refinement started from.
    shift_px : (2,) float64
        Shift of the centre's direction in pixels (tangent-plane basis ``e1, e2`` of the initial
        axis, times the focal length).
    shift_sigma_px : float
        RMS standard error of the shift (from the Gauss-Newton covariance at the robust scale).
    n_photos, n_pixels : int
        Photos and residuals (pixel-photo pairs) used.
    cost_initial, cost_final : float
        Robust cost at the initial and the refined centre (final round).
    accepted : bool
        Whether ``center`` differs from ``center_initial``.
    message : str
        Why a refinement was not accepted (or ``'ok'``).
    radius_shift_px : float
        Change of the apparent radius, pixels (0 unless ``fit_radius``: the centre's distance
        then changes with it, the sphere radius being fixed).
    """

    center: np.ndarray
    center_initial: np.ndarray
    shift_px: np.ndarray
    shift_sigma_px: float = float("nan")
    n_photos: int = 0
    n_pixels: int = 0
    cost_initial: float = float("nan")
    cost_final: float = float("nan")
    accepted: bool = False
    message: str = ""
    radius_shift_px: float = 0.0

    @property
    def shift_norm_px(self) -> float:
        """Length of :attr:`shift_px` (0 when not accepted)."""
        return float(np.linalg.norm(self.shift_px)) if self.accepted else 0.0

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        def num(x):
            x = float(x)
            return x if np.isfinite(x) else None

        return {"center": [float(v) for v in self.center], "center_initial": [float(v) for v in self.center_initial],
                "shift_px": [float(v) for v in self.shift_px], "shift_norm_px": self.shift_norm_px,
                "shift_sigma_px": num(self.shift_sigma_px), "n_photos": int(self.n_photos),
                "n_pixels": int(self.n_pixels), "cost_initial": num(self.cost_initial),
                "cost_final": num(self.cost_final), "accepted": bool(self.accepted), "message": self.message,
                "radius_shift_px": float(self.radius_shift_px)}


def _geometry(samples: SphereSamples):
    """Camera centre, ray directions, distance, half-angle, focal length of a sphere's samples."""
    if samples.origin is None:
        raise ValueError("SphereSamples has no camera origin; build it with sphere_samples()")
    O = np.asarray(samples.origin, dtype=np.float64)
    C = np.asarray(samples.center, dtype=np.float64)
    D = float(np.linalg.norm(C - O))
    alpha = float(np.arcsin(samples.radius / D))
    f = float(samples.radius_px / np.tan(alpha))
    d = normalize(samples.points - O)
    return O, C, D, alpha, f, d


def _hit_normals(d, CO, R):
    """Unit normals at the first hits of rays ``d`` (from the camera centre) with a sphere at ``CO``.

    In the stable form: ``perp = b d - CO`` (the centre's offset from the ray, at most ``R``)
    and ``R^2 - |perp|^2`` in place of ``b^2 - |CO|^2 + R^2``, which cancels catastrophically
    for a far camera (the virtual centre of an orthographic one is 1e4 radii away).
    """
    b = d @ CO
    perp = d * b[:, None] - CO
    # |perp|^2 written out: the same sum as np.sum(perp * perp, axis=1), which is ~8x slower on (m, 3)
    s = np.sqrt(np.maximum(R * R - (perp[:, 0] * perp[:, 0] + perp[:, 1] * perp[:, 1] + perp[:, 2] * perp[:, 2]), 0.0))
    return (perp - d * s[:, None]) / R, b - s


def recentre_samples(samples: SphereSamples, center: np.ndarray, margin_px: float = 1.5,
                     up: np.ndarray = UP) -> tuple[SphereSamples, np.ndarray]:
    """The sphere's samples for a new centre: a subset of the same pixels, new normals.

    Parameters
    ----------
    samples : SphereSamples
        With ``origin`` (the camera centre, world frame).
    center : (3,) float
        New world-frame centre.
    margin_px : float
        Pixels whose rays pass within this many pixels of the new silhouette are dropped.
    up : (3,) float
        World up for the ground-bounce form factor.

    Returns
    -------
    SphereSamples
    index : (k,) int
        Indices of the kept pixels in ``samples`` (to subset per-photo values).
    """
    O, _, _, _, f, d = _geometry(samples)
    C = np.asarray(center, dtype=np.float64)
    CO = C - O
    D = float(np.linalg.norm(CO))
    alpha = float(np.arcsin(samples.radius / D))
    ang = np.arccos(np.clip(d @ (CO / D), -1.0, 1.0))
    idx = np.flatnonzero(ang < alpha - margin_px / f)
    n, t = _hit_normals(d[idx], CO, samples.radius)
    n = normalize(n)
    new = replace(samples, rows=samples.rows[idx], cols=samples.cols[idx], normals=n, points=O + d[idx] * t[:, None],
                  center=C.copy(), radius_px=float(f * np.tan(alpha)), ground=ground_bounce(n, up))
    return new, idx


def select_photos(directions: np.ndarray, max_photos: int, first: int = 0) -> np.ndarray:
    """Indices of up to ``max_photos`` of ``directions`` (n, 3) spread over the sphere.

    Farthest-point sampling by angle, starting from ``first``.
    """
    d = normalize(np.asarray(directions, dtype=np.float64))
    n = len(d)
    if n <= max_photos:
        return np.arange(n)
    chosen = [int(first)]
    best = d @ d[first]
    for _ in range(max_photos - 1):
        j = int(np.argmin(best))
        chosen.append(j)
        best = np.maximum(best, d @ d[j])
    return np.array(sorted(chosen))


def refine_sphere_centre(samples: SphereSamples, values: list, directions: list, **kwargs) -> CentreRefinement:
    """Refine a sphere's centre by fitting the Lambertian shading of many photos at once.

    :func:`refine_sphere_centre_shading` (its parameters are passed on); a shading system that
    has no unique solution (e.g. a photo whose pixels were all set aside, on a bright background)
    is a refinement not accepted, with the reason in ``message``, never an error: the detected
    centre stands.
    """
    try:
        return refine_sphere_centre_shading(samples, values, directions, **kwargs)
    except np.linalg.LinAlgError as e:
        C0 = _geometry(samples)[1]
        return CentreRefinement(center=C0.copy(), center_initial=C0.copy(), shift_px=np.zeros(2),
                                message=f"degenerate shading system ({e})")


def refine_sphere_centre_shading(samples: SphereSamples, values: list, directions: list, *, max_photos: int = 20,
                         margin_px: float = 1.0, max_shift_px: float = 2.0, terminator: float = 0.15,
                         clip_sigma: float = 4.0, rel_noise_floor: float = 0.01, min_lit: int = 30,
                         min_shadow: int = 10, n_rounds: int = 2, shading: str = "bounce", lit_only: bool = True,
                         up: np.ndarray = UP, fit_radius: bool = False) -> CentreRefinement:
    """Refine a sphere's centre by fitting the Lambertian shading of many photos at once.

    Parameters
    ----------
    samples : SphereSamples
        The sphere's pixels and normals for the initial (detected) centre, with ``origin``.
    values : list of (grey (m,), valid (m,) bool, ...)
        Per photo, this sphere's :func:`ffls.spheres.samples.sphere_values` entry.
    directions : list of (3,) float or None
        Per photo, the first-pass light direction of this sphere (None or NaN where its fit was
        not ``'ok'``; those photos are not used).
    max_photos : int
        Photos used (farthest-point sampling of their directions).
    margin_px : float
        Extra shrink of the pixel set inside the initial outline (beyond the samples' own).
    max_shift_px : float
        Bound on the centre's shift; a refinement at the bound is not accepted.
    terminator : float
        Pixels with ``|n . l| < terminator`` are not used.
    clip_sigma, rel_noise_floor : float
        Outlier rejection at ``clip_sigma`` robust sigma, the sigma floored at ``rel_noise_floor``
        of the photo's intensity.
    min_lit, min_shadow : int
        A photo needs ``min_lit`` lit pixels; the bounce column is fitted only with at least
        ``min_shadow`` shadow-side pixels (on the lit side it is collinear with ``b`` and ``v_z``).
    n_rounds : int
        Classification / rejection rounds.
    up : (3,) float
    fit_radius : bool
        Also fit the apparent radius (a third parameter, pixels, bounded like the shift): the
        silhouette's edge sits slightly inside a limb that darkens toward the outline, so the
        detected radius is small by a fraction of a pixel; with ``sphere_radius`` fixed the
        centre's distance changes with it. Used for orthographic cameras, where the virtual
        distance is arbitrary (:func:`ffls.spheres.samples.sphere_samples_orthographic`).

    Returns
    -------
    CentreRefinement
    """
    from scipy.optimize import least_squares
    O, C0, D, alpha, f, d_all = _geometry(samples)
    R = float(samples.radius)
    up = np.asarray(up, dtype=np.float64)
    CO0 = C0 - O
    u0 = CO0 / D
    e1, e2 = tangent_basis(u0)
    ang = np.arccos(np.clip(d_all @ u0, -1.0, 1.0))
    pix = np.flatnonzero(ang < alpha - margin_px / f)
    d = d_all[pix]
    fail = CentreRefinement(center=C0.copy(), center_initial=C0.copy(), shift_px=np.zeros(2))
    cand = [j for j, l in enumerate(directions) if l is not None and np.all(np.isfinite(l))]
    if len(pix) < 3 * min_lit or len(cand) < 3:
        fail.message = "too few pixels or photos"
        return fail
    n0 = normalize(_hit_normals(d, CO0, R)[0])
    L = normalize(np.array([directions[j] for j in cand], dtype=np.float64))
    nlit = np.array([int(np.sum(np.asarray(values[j][1], bool)[pix] & (n0 @ l > terminator))) for j, l in zip(cand, L)])
    keep = nlit >= min_lit
    cand, L, nlit = [c for c, k in zip(cand, keep) if k], L[keep], nlit[keep]
    if len(cand) < 3:
        fail.message = "too few lit photos"
        return fail
    sel = select_photos(L, max_photos, first=int(np.argmax(nlit)))
    photos = [cand[i] for i in sel]
    L = L[sel]
    Y = np.stack([np.asarray(values[j][0], dtype=np.float64)[pix] for j in photos])  # (J, m)
    V = np.stack([np.asarray(values[j][1], dtype=bool)[pix] for j in photos]) & np.isfinite(Y)
    Y = np.where(V, Y, 0.0)
    J = len(photos)

    r_px = float(f * np.tan(alpha))

    def dist_at(p):
        return D if len(p) < 3 else float(R / np.sin(np.arctan((r_px + p[2]) / f)))

    def normals_at(p):
        u = normalize(u0 + (p[0] * e1 + p[1] * e2) / f)
        n = _hit_normals(d, dist_at(p) * u, R)[0]
        return n, u

    def design(n, lit, use, has_g):
        if shading == "sh2":  # direct term + order-2 spherical harmonics of the indirect light
            x_, y_, z_ = n[:, 0], n[:, 1], n[:, 2]
            B = np.stack([np.ones_like(x_), x_, y_, z_, x_ * y_, x_ * z_, y_ * z_, x_ * x_ - y_ * y_,
                          3 * z_ * z_ - 1], axis=1)
            F = np.empty((J, n.shape[0], 12))
            F[..., :3] = n[None] * lit[..., None]
            F[..., 3:] = B[None] * use[..., None]
            return F
        F = np.empty((J, n.shape[0], 5))
        F[..., :3] = n[None] * lit[..., None]
        F[..., 3] = use
        F[..., 4] = 0.5 * (1.0 - n @ up)[None] * (use & has_g[:, None])
        return F

    iu = np.triu_indices(3)

    photo_terms = []  # the last weights below and what they were made of (compared by identity)

    def weights(lit, use, has_g, scale):
        """The photo-side factors of :func:`solve_bounce`, which depend on the classes and the
        scale only: made once per set of them (every residual evaluation of one least-squares
        run shares them), not at every trial centre."""
        key = (lit, use, has_g, scale)
        if photo_terms and all(a is b for a, b in zip(photo_terms[0], key)):
            return photo_terms[1]
        Wl, Wu = lit.astype(np.float64), use.astype(np.float64)
        Yw = Y * Wu / scale[:, None]
        out = (Wl, Wu, has_g.astype(np.float64), Yw, Yw * Wl, Yw.sum(axis=1))
        photo_terms[:] = [key, out]
        return out

    def solve_bounce(n, lit, use, has_g, scale):
        # the per-photo normal equations of the design [n [lit], 1 [use], g [use, has_g]] from
        # per-pixel products (one (J, m) @ (m, k) product each) instead of a (J, m, 5) design
        g = 0.5 * (1.0 - n @ up)
        Wl, Wu, hg, Yw, YwWl, Ysum = weights(lit, use, has_g, scale)
        Pl = np.concatenate([n[:, iu[0]] * n[:, iu[1]], n, n * g[:, None]], axis=1)  # (m, 12)
        Pu = np.stack([np.ones_like(g), g, g * g], axis=1)
        Sl, Su = Wl @ Pl, Wu @ Pu
        G = np.empty((J, 5, 5))
        G[:, iu[0], iu[1]] = Sl[:, :6]
        G[:, iu[1], iu[0]] = Sl[:, :6]
        G[:, :3, 3] = G[:, 3, :3] = Sl[:, 6:9]
        G[:, :3, 4] = G[:, 4, :3] = Sl[:, 9:12] * hg[:, None]
        G[:, 3, 3] = Su[:, 0]
        G[:, 3, 4] = G[:, 4, 3] = Su[:, 1] * hg
        G[:, 4, 4] = Su[:, 2] * hg + (1.0 - hg)
        h = np.empty((J, 5))
        h[:, :3] = YwWl @ n
        h[:, 3] = Ysum
        h[:, 4] = (Yw @ g) * hg
        x = np.linalg.solve(G, h[..., None])[..., 0]
        r = Yw - Wl * (x[:, :3] @ n.T) - Wu * (x[:, 3:4] + (x[:, 4] * hg)[:, None] * g[None])
        return r, x

    def solve(p, lit, use, has_g, scale):
        n, _ = normals_at(p)
        if shading != "sh2":
            return solve_bounce(n, lit, use, has_g, scale)
        F = design(n, lit, use, has_g)
        Yw = Y * use / scale[:, None]
        G = np.einsum("jmp,jmq->jpq", F, F)
        if shading == "sh2":  # the SH's linear part is collinear with v on the lit side: tiny ridge
            G[:, 3:, 3:] += 1e-6 * np.trace(G, axis1=1, axis2=2)[:, None, None] * np.eye(G.shape[1] - 3)
        else:
            G[:, 4, 4] += ~has_g
        h = np.einsum("jmp,jm->jp", F, Yw)
        x = np.linalg.solve(G, h[..., None])[..., 0]
        r = Yw - np.einsum("jmp,jp->jm", F, x)
        return r, x

    p = np.zeros(3 if fit_radius else 2)
    scale = np.ones(J)
    res = None
    cost0 = None
    for rnd in range(n_rounds):
        n, _ = normals_at(p)
        nl = L @ n.T  # (J, m)
        lit = V & (nl > terminator)
        shadow = V & (nl < -terminator)
        if lit_only:
            shadow[:] = False
        use = lit | shadow
        has_g = shadow.sum(axis=1) >= min_shadow
        # intensity per photo (for relative residuals) and outliers at the current centre
        r, x = solve(p, lit, use, has_g, np.ones(J))
        scale = np.maximum(np.linalg.norm(x[:, :3], axis=1), 1e-300)
        r = r / scale[:, None]
        sig = np.empty(J)
        for j in range(J):
            rj = r[j, use[j]]
            sig[j] = max(1.4826 * float(np.median(np.abs(rj - np.median(rj)))), rel_noise_floor)
        use = use & (np.abs(r) <= clip_sigma * sig[:, None])
        lit &= use
        f_scale = float(np.median(sig))
        mask = use

        def fun(q, lit=lit, use=use, has_g=has_g, mask=mask):
            return solve(q, lit, use, has_g, scale)[0][mask]

        r0 = fun(p)
        if rnd == 0:
            cost0 = float(np.sum(f_scale ** 2 * 2 * (np.sqrt(1 + (r0 / f_scale) ** 2) - 1)))
        res = least_squares(fun, p, loss="soft_l1", f_scale=f_scale, method="trf", x_scale=1.0,
                            bounds=(np.full(p.size, -max_shift_px - 0.5), np.full(p.size, max_shift_px + 0.5)),
                            xtol=1e-6, ftol=1e-10)
        p = res.x
        # the photos' light directions at the refined centre, for the next round's classes
        _, x = solve(p, lit, use, has_g, scale)
        L = normalize(x[:, :3])
    cost1 = float(2.0 * res.cost)
    Jm = res.jac
    try:
        cov = np.linalg.inv(Jm.T @ Jm) * float(np.sum(res.fun ** 2)) / max(res.fun.size - p.size - 5 * J, 1)
        sd = float(np.sqrt(max(np.trace(cov[:2, :2]), 0.0)))
    except np.linalg.LinAlgError:
        sd = float("inf")
    u = normalize(u0 + (p[0] * e1 + p[1] * e2) / f)
    C1 = O + dist_at(p) * u
    out = CentreRefinement(center=C1, center_initial=C0.copy(), shift_px=p[:2].copy(), shift_sigma_px=sd, n_photos=J,
                           n_pixels=int(mask.sum()), cost_initial=cost0, cost_final=cost1, accepted=True, message="ok",
                           radius_shift_px=float(p[2]) if p.size > 2 else 0.0)
    if not res.success or not np.all(np.isfinite(p)):
        out.accepted, out.message = False, f"least_squares failed: {res.message}"
    elif np.linalg.norm(p[:2]) > max_shift_px or (p.size > 2 and abs(p[2]) > max_shift_px):
        out.accepted, out.message = False, f"shift {np.linalg.norm(p):.2f} px beyond max_shift_px"
    if not out.accepted:
        out.center = C0.copy()
    return out
