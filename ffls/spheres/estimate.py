"""One light per photograph from the four spheres: combination, near lights, rejection.

Masselus, Dutre, Anrys, "The Free-form Light Stage", EGWR 2002, section 5: each sphere gives a
direction (:mod:`ffls.spheres.lambert`); "the best fitted intersection is used to find the
illuminant direction with respect to the centre of the scene".

Per photo:

1. every sphere is fitted on its own (Lambert + ambient + ground bounce);
2. the usable spheres' directions ``l_i`` (RMS uncertainties ``s_i``, a statistical part from the
   fit and a floor ``sigma_floor_deg`` for what the model does not capture) are explained by
   * a **distant** light: one direction ``l``, inverse-variance mean on the unit sphere,
     ``chi2 = sum angle(l_i, l)^2 / (s_i^2 / 2)`` with ``2 (k - 1)`` degrees of freedom;
   * a **near** light at ``S = c + l / rho`` (``c`` the scene centre; inverse distance
     ``rho >= 0`` so that ``rho -> 0`` is the distant limit and nearly parallel rays stay
     stable): the rays ``C_i + t l_i`` meet at ``S``; ``2 k - 3`` degrees of freedom;
   ``model='auto'`` takes the near model only when its chi-square drop is significant
   (likelihood-ratio test, 1 degree of freedom, ``p < 1e-3``);
3. if the chosen model is inconsistent (``p < 1e-3``) and one sphere's removal makes it
   consistent, that sphere is dropped (``'outlier'``); otherwise the photo is rejected;
4. a near light changes the shading itself (direction and ``1/r^2`` over each sphere), so the
   light position is refined by a **joint** fit to all used spheres' pixels
   (:func:`fit_near_light`), initialised from the ray intersection.

Rejection reasons (:data:`REASONS`) are short fixed strings stored in ``lights.json``.
"""
from __future__ import annotations

import os
from collections import Counter
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.stats import chi2 as _chi2

from ffls.conventions import UP, angle_between, normalize
from ffls.errors import InputError
from ffls.spheres.lambert import SphereSamples, fit_lambert, ground_bounce, sphere_samples, tangent_uncertainty_deg
from ffls.radiance.photos import load_photo, read_photo

__all__ = [
    "REASONS",
    "LIGHT_MODELS",
    "combine_distant",
    "fit_ray_convergence",
    "fit_near_light",
    "pixel_validity",
    "estimate_photo",
    "estimate_lights",
    "estimate_lights_MasselusDutreAnrys2002",
    "capture_samples",
    "sphere_values",
    "calibrate_bounce",
    "estimate_photos",
    "refine_sphere_centres",
]

#: Rejection reasons of a photo (and of single spheres), with their meaning.
REASONS = {
    "too_dark": "too few lit, unsaturated pixels on the spheres (light off, or pointing away)",
    "saturated": "the lit part of the spheres is clipped",
    "shadowed": "the spheres are in a cast shadow (object, person) or much darker than the others",
    "spheres_disagree": "the spheres' directions are inconsistent beyond their uncertainty and no single "
                        "sphere explains it",
    "too_few_spheres": "fewer usable spheres than needed (min_spheres)",
    "fit_failed": "the shading fit did not converge to a finite direction",
}
#: Light models of :func:`estimate_lights`.
LIGHT_MODELS = ("auto", "distant", "near")
#: Sphere status for a sphere dropped from the combination because it disagreed with the others.
OUTLIER = "outlier"

_ALPHA = 1e-3


# ----------------------------------------------------------------------------- pixel validity
def pixel_validity(pixels: np.ndarray, black_fraction: float = 0.02, min_plateau: int = 4,
                   saturation: float | None = None) -> tuple[np.ndarray, int]:
    """Usable pixels of one sphere: finite, not saturated, not near-black.

    Saturation is the clip level ``saturation`` where the caller knows it, and in any case a
    plateau: at least ``min_plateau`` pixels sharing the maximum of a channel (clipping makes
    plateaus; unclipped radiance does not).

    Parameters
    ----------
    pixels : (m, 3) or (m,) float
        Linear values of the sphere's pixels.
    black_fraction : float
        Grey values below this fraction of the sphere's 99th percentile are near-black.
    min_plateau : int
    saturation : float, optional

    Returns
    -------
    valid : (m,) bool
    n_saturated : int
    """
    p = np.asarray(pixels, dtype=np.float64)
    if p.ndim == 1:
        p = p[:, None]
    finite = np.all(np.isfinite(p), axis=1)
    sat = np.zeros(p.shape[0], dtype=bool)
    if finite.any():
        q = np.where(finite[:, None], p, -np.inf)
        for ch in range(p.shape[1]):
            top = float(q[:, ch].max())
            if top > 0:
                at_top = q[:, ch] >= top * (1.0 - 1e-6)
                if at_top.sum() >= min_plateau:
                    sat |= at_top
            if saturation is not None:
                sat |= q[:, ch] >= 0.999 * saturation
    grey = np.where(finite, p.mean(axis=1), 0.0)
    ok = finite & ~sat
    ref = float(np.percentile(grey[ok], 99)) if ok.any() else 0.0
    dark = grey <= max(black_fraction * ref, 0.0)
    return ok & ~dark, int((sat & finite).sum())


# ----------------------------------------------------------------------------- combination
def _sigma_axis(unc_deg):
    """Per-axis standard deviation (radians) from an RMS angular uncertainty (degrees)."""
    return np.radians(np.asarray(unc_deg, dtype=np.float64)) / np.sqrt(2.0)


def combine_distant(directions: np.ndarray, uncertainty_deg: np.ndarray) -> tuple[np.ndarray, float, float, int]:
    """Inverse-variance mean direction of several estimates of one distant light.

    Parameters
    ----------
    directions : (k, 3) float, unit
    uncertainty_deg : (k,) float
        RMS angular uncertainties.

    Returns
    -------
    direction : (3,) float, unit
    uncertainty_deg : float
        RMS angular uncertainty of the mean.
    chi2 : float
        ``sum angle_i^2 / sigma_i^2`` (per-axis sigma).
    dof : int
        ``2 (k - 1)``.
    """
    d = normalize(np.atleast_2d(directions))
    w = 1.0 / _sigma_axis(uncertainty_deg) ** 2
    mean = normalize(np.sum(w[:, None] * d, axis=0))
    for _ in range(2):  # refine on the sphere (tangent-plane mean)
        t = d - (d @ mean)[:, None] * mean
        mean = normalize(mean + np.sum(w[:, None] * t, axis=0) / w.sum())
    ang = angle_between(d, mean)
    chi = float(np.sum(w * ang ** 2))
    return mean, float(np.degrees(np.sqrt(2.0 / w.sum()))), chi, 2 * (len(d) - 1)


#: Stopping tolerances of the light-position fits: a relative step of 1e-6 is 6e-5 deg of direction
#: (and 2 um of a light at 2 m), far below the 1 deg floor of a sphere's uncertainty.
_FTOL, _XTOL = 1e-8, 1e-6


def _lm(fun, x0, lb=None, ub=None, max_iter: int = 40, rel_step: float = 1e-7, ftol: float = 1e-10,
        xtol: float = 1e-9, want_jac: bool = True):
    """Small Levenberg-Marquardt with box bounds (projection) and a forward-difference Jacobian.

    For the few (<= 3) nonlinear parameters of this module, where :func:`scipy.optimize.least_squares`
    costs more in overhead than in arithmetic.

    Parameters
    ----------
    fun : callable
        ``fun(x) -> (m,) residuals``.
    x0 : (p,) float
    lb, ub : (p,) float, optional
    max_iter : int
    rel_step : float
        Finite-difference step relative to ``max(|x_i|, 1)``.
    ftol, xtol : float
        Stop when the relative cost decrease falls below ``ftol`` or the relative step below
        ``xtol``.
    want_jac : bool
        False: the Jacobian at the solution is not needed (returned as None when the iterations
        end by convergence; it costs ``p`` more evaluations).

    Returns
    -------
    x : (p,) float
    r : (m,) float
        Residuals at ``x``.
    J : (m, p) float
        Jacobian at ``x``.
    """
    x = np.asarray(x0, dtype=np.float64).copy()
    p = x.size
    lb = np.full(p, -np.inf) if lb is None else np.asarray(lb, dtype=np.float64)
    ub = np.full(p, np.inf) if ub is None else np.asarray(ub, dtype=np.float64)
    x = np.clip(x, lb, ub)

    def jacobian(x, r):
        J = np.empty((r.size, p))
        for i in range(p):
            h = rel_step * max(abs(x[i]), 1.0)
            xh = x.copy()
            xh[i] = x[i] + h if x[i] + h <= ub[i] else x[i] - h
            J[:, i] = (fun(xh) - r) / (xh[i] - x[i])
        return J

    r = fun(x)
    cost = float(r @ r)
    lam = 1e-3
    J = jacobian(x, r)
    for _ in range(max_iter):
        JtJ = J.T @ J
        grad = J.T @ r
        D = np.diag(np.maximum(np.diag(JtJ), 1e-12 * max(float(np.max(np.diag(JtJ))), 1e-300)))
        improved = False
        while lam < 1e8:
            try:
                dx = -np.linalg.solve(JtJ + lam * D, grad)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            xn = np.clip(x + dx, lb, ub)
            if float(np.max(np.abs(xn - x) / np.maximum(np.abs(x), 1.0))) <= xtol:
                break  # the damped step is negligible: converged (no more trials at higher damping)
            rn = fun(xn)
            cn = float(rn @ rn)
            if np.isfinite(cn) and cn <= cost:
                improved = True
                break
            lam *= 10.0
        if not improved:
            break
        step = float(np.max(np.abs(xn - x) / np.maximum(np.abs(x), 1.0)))
        done = (cost - cn) <= ftol * max(cost, 1e-300) or step <= xtol
        x, r, cost = xn, rn, cn
        lam = max(lam / 10.0, 1e-9)
        if done:
            J = jacobian(x, r) if want_jac else None
            break
        J = jacobian(x, r)
    return x, r, J


def _tangent_basis(u):
    a = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = normalize(np.cross(u, a))
    return e1, np.cross(u, e1)


def fit_ray_convergence(centers: np.ndarray, directions: np.ndarray, uncertainty_deg: np.ndarray,
                        scene_center: np.ndarray) -> dict:
    """Best meeting point of the rays ``centers[i] + t directions[i]`` (a near light).

    Parameterised as ``S = c + m / rho`` with ``m`` a unit direction and ``rho >= 0`` the inverse
    distance, so that parallel rays give ``rho = 0`` (a distant light) without blowing up. The
    predicted direction at sphere ``i`` is ``normalize(m - rho (C_i - c))``.

    Parameters
    ----------
    centers : (k, 3) float
        Sphere centres (world).
    directions : (k, 3) float, unit
    uncertainty_deg : (k,) float
    scene_center : (3,) float

    Returns
    -------
    dict
        ``direction`` (3,) unit from the scene centre, ``rho`` (1/units), ``position`` (3,) or
        None when ``rho == 0``, ``chi2`` (float, ``2 k - 3`` dof), ``dof``.
    """
    C = np.atleast_2d(np.asarray(centers, dtype=np.float64)) - np.asarray(scene_center, dtype=np.float64)
    d = normalize(np.atleast_2d(directions))
    sig = _sigma_axis(uncertainty_deg)
    k = len(d)
    m0, _, _, _ = combine_distant(d, uncertainty_deg)
    e1, e2 = _tangent_basis(m0)
    bases = [_tangent_basis(di) for di in d]
    T = np.stack([np.stack(b) for b in bases])  # (k, 2, 3)
    scale = float(np.max(np.linalg.norm(C, axis=1))) or 1.0

    def dirs(x):
        m = m0 + x[0] * e1 + x[1] * e2
        m = m / np.sqrt(m @ m)
        p = m[None, :] - (x[2] / scale) * C
        return p / np.sqrt(np.einsum("ij,ij->i", p, p))[:, None], m

    def fun(x):
        p, _ = dirs(x)
        return (np.einsum("kij,kj->ki", T, p - d) / sig[:, None]).ravel()

    best = None
    for rho0 in (0.0, 0.1, 0.5):
        x, r, _ = _lm(fun, np.array([0.0, 0.0, rho0]), np.array([-1.0, -1.0, 0.0]), np.array([1.0, 1.0, 0.99]),
                      ftol=_FTOL, xtol=_XTOL, want_jac=False)
        if best is None or r @ r < best[1] @ best[1]:
            best = (x, r)
    _, m = dirs(best[0])
    rho = best[0][2] / scale
    chi = float(best[1] @ best[1])
    pos = None if rho <= 1e-12 else np.asarray(scene_center, dtype=np.float64) + m / rho
    return {"direction": m, "rho": float(rho), "position": pos, "chi2": float(chi), "dof": max(2 * k - 3, 0)}


# ----------------------------------------------------------------------------- joint near fit
def fit_near_light(samples: list[SphereSamples], values: list[np.ndarray], masks: list[np.ndarray],
                   position0: np.ndarray, terms: list[tuple] | None = None,
                   terminator: float = 0.15, up: np.ndarray = UP, n_rounds: int = 2, stride: int = 4) -> dict:
    """Joint fit of a point light's position to several spheres' pixels.

    Model per pixel ``p`` of sphere ``k`` (surface point ``P``, normal ``n``, ``d = S - P``)::

        I = a_k D_k^2 [max(0, n . d) / |d|^3 + rho_k h_k(S) g(n)] + b_k            (calibrated)
        I = a_k D_k^2 max(0, n . d) / |d|^3 + b_k + c_k g(n)                       (free bounce)

    with ``D_k = |S0 - C_k|`` a fixed scale (so ``a_k`` is in image units), ``b_k, c_k >= 0``,
    ``rho_k`` the sphere's calibrated ground ratio and ``h_k(S) = max(0, (S - G_k) . up) /
    |S - G_k|^3`` the point light's irradiance of the ground at the sphere's contact point
    ``G_k = C_k - R up`` (per unit ``a_k D_k^2``). For a given ``S`` the per-sphere coefficients
    are linear and solved in closed form (variable projection, Golub & Pereyra 1973); the three
    coordinates of ``S`` by Levenberg-Marquardt on the projected residual. Pixels near the
    terminator are re-selected and outliers (MAD) rejected between rounds.

    Parameters
    ----------
    samples : list of SphereSamples
    values : list of (m_k,) float
    masks : list of (m_k,) bool
        Pixels allowed (valid, not outliers of the per-sphere fit).
    position0 : (3,) float
        Initial light position (world).
    terms : list of (bool, bool or float), optional
        Per sphere: fit the ambient ``b_k``; the bounce: True (free ``c_k``), False (none) or a
        float (the calibrated ratio ``rho_k``). Default ``(True, True)``.
    terminator : float
    up : (3,) float
    n_rounds : int

    Returns
    -------
    dict
        ``position`` (3,), ``cov`` (3, 3) covariance of the position, ``rms`` (relative),
        ``n_pixels``, ``success`` (bool).
    """
    from ffls.spheres.lambert import _solve_normal

    K = len(samples)
    if terms is None:
        terms = [(True, True)] * K
    up = np.asarray(up, dtype=np.float64)
    S0 = np.asarray(position0, dtype=np.float64)
    D2 = np.array([float(np.sum((S0 - s.center) ** 2)) for s in samples])
    G = [s.center - s.radius * up for s in samples]
    ratio = [None if isinstance(b, (bool, np.bool_)) else float(b) for _, b in terms]
    # per sphere, the coefficient columns present besides the first (a_k): ambient, free bounce
    hb = np.array([bool(b_) for b_, _ in terms])
    hc = np.array([b_ is True for _, b_ in terms])
    rho = np.array([0.0 if r_ is None else r_ for r_ in ratio])
    Gc = np.array(G)
    # a fixed lattice of each sphere's pixels (every ``stride``-th of the pixel list, raster order),
    # its geometry gathered once per call as contiguous float64 and subset per round
    lat = [np.arange(0, len(s), max(int(stride), 1)) for s in samples]
    allN = [np.ascontiguousarray(s.normals[i], dtype=np.float64) for s, i in zip(samples, lat)]
    allP = [np.ascontiguousarray(s.points[i], dtype=np.float64) for s, i in zip(samples, lat)]
    allY = [np.asarray(v, dtype=np.float64)[i] for v, i in zip(values, lat)]
    allG = [(s.ground if s.ground is not None and np.array_equal(up, UP) else ground_bounce(s.normals, up))[i]
            for s, i in zip(samples, lat)]
    allM = [np.asarray(m, dtype=bool)[i] for m, i in zip(masks, lat)]
    sel = [m.copy() for m in allM]
    D = {}

    def prepare():
        # all used spheres' selected pixels in one array: q = n.S - n.P and |S - P|^2 = S.S - 2 P.S + P.P
        # are then two matrix-vector products per evaluation, the per-sphere Gram entries segment sums
        idx = [np.flatnonzero(w) for w in sel]
        cnt = np.array([i.size for i in idx])
        starts = np.concatenate([[0], np.cumsum(cnt)[:-1]])
        n = np.concatenate([allN[k][i] for k, i in enumerate(idx)])
        P = np.concatenate([allP[k][i] for k, i in enumerate(idx)])
        y = np.concatenate([allY[k][i] for k, i in enumerate(idx)])
        g = np.concatenate([allG[k][i] for k, i in enumerate(idx)])
        D.update(NP=np.ascontiguousarray(np.stack([n, P])), nP=np.einsum("ij,ij->i", n, P),
                 PP=np.einsum("ij,ij->i", P, P), y=y, g=g, cnt=cnt, starts=np.minimum(starts, max(int(cnt.sum()) - 1, 0)),
                 d2=np.repeat(D2, cnt), nonempty=cnt > 0,
                 # data-only sums: 1, g, g^2, y, g y
                 const=np.stack([cnt.astype(np.float64), *(np.add.reduceat(v, np.minimum(starts, max(v.size - 1, 0)))
                                                           * (cnt > 0) if v.size else np.zeros(K)
                                                           for v in (g, g * g, y, g * y))]))

    def solve_all(S):
        """Per sphere the closed-form coefficients at ``S``; the residuals of all pixels."""
        qp = D["NP"] @ S
        q = qp[0] - D["nP"]
        r2 = (S @ S) - 2.0 * qp[1] + D["PP"]
        f = np.maximum(q, 0.0) / (r2 * np.sqrt(r2)) * D["d2"]
        g, y = D["g"], D["y"]
        ff, f1, fg, fy = np.add.reduceat(np.stack([f * f, f, f * g, f * y]), D["starts"], axis=1) * D["nonempty"]
        n1, sg, sgg, sy, sgy = D["const"]
        # calibrated bounce: the first column is f + t_k g, t_k = rho_k h_k(S) D_k^2
        e = S[None, :] - Gc
        t = rho * np.maximum(e @ up, 0.0) / np.einsum("ij,ij->i", e, e) ** 1.5 * D2
        ff, f1, fg, fy = ff + 2 * t * fg + t * t * sgg, f1 + t * sg, fg + t * sgg, fy + t * sgy
        # (K, 3, 3) normal equations of (a_k, b_k, c_k); an absent column is an identity row (-> 0)
        Gm = np.empty((K, 3, 3))
        Gm[:, 0, 0], Gm[:, 0, 1], Gm[:, 0, 2] = ff, f1 * hb, fg * hc
        Gm[:, 1, 1], Gm[:, 1, 2], Gm[:, 2, 2] = np.where(hb, n1, 1.0), sg * hb * hc, np.where(hc, sgg, 1.0)
        Gm[:, 1, 0], Gm[:, 2, 0], Gm[:, 2, 1] = Gm[:, 0, 1], Gm[:, 0, 2], Gm[:, 1, 2]
        h = np.stack([fy, sy * hb, sgy * hc], axis=1)
        try:
            X = np.linalg.solve(Gm, h[:, :, None])[:, :, 0]
            bad = ~(np.all(X[:, 1:] >= 0, axis=1) & np.all(np.isfinite(X), axis=1))
        except np.linalg.LinAlgError:
            X, bad = np.zeros((K, 3)), np.ones(K, dtype=bool)
        for k in np.flatnonzero(bad):  # a bound active (or singular): the active-set solution
            cols = [0] + ([1] if hb[k] else []) + ([2] if hc[k] else [])
            X[k] = 0.0
            X[k, cols] = _solve_normal(Gm[k][np.ix_(cols, cols)], h[k, cols], n_free=1)[0]
        X = np.column_stack([X[:, 0], X[:, 1], X[:, 2] + t * X[:, 0]])  # c_k: free, or t_k a_k
        Xp = np.repeat(X, D["cnt"], axis=0)
        return y - Xp[:, 0] * f - Xp[:, 1] - Xp[:, 2] * g, X

    def fun(S):
        return solve_all(S)[0]

    x = S0.copy()
    res = None
    for rnd in range(n_rounds):
        # terminator band and outliers with the current position
        for k in range(K):
            dd = x - allP[k]
            c = np.einsum("ij,ij->i", allN[k], dd) / np.sqrt(np.einsum("ij,ij->i", dd, dd))
            sel[k] = allM[k] & (np.abs(c) > terminator)
        if rnd > 0 and res is not None:
            prepare()
            r_all, X = solve_all(x)
            for k, rk in enumerate(np.split(r_all, np.cumsum(D["cnt"])[:-1])):
                sd = max(1.4826 * float(np.median(np.abs(rk - np.median(rk)))), 0.01 * abs(X[k, 0]))
                w = np.flatnonzero(sel[k])
                sel[k][w[np.abs(rk) > 4.0 * sd]] = False
        if sum(int(s_.sum()) for s_ in sel) <= 3 + 3 * K:
            break
        prepare()
        sel_fit = [s_.copy() for s_ in sel]
        scale = float(np.linalg.norm(x))
        last = rnd == n_rounds - 1
        xs, r, J = _lm(lambda u: fun(u * scale), x / scale, ftol=_FTOL, xtol=_XTOL, want_jac=last)
        x = xs * scale
        res = (r, None if J is None else J / scale, scale)  # J None: not needed if another round follows
    if res is None or not np.all(np.isfinite(x)):
        return {"position": S0, "cov": np.full((3, 3), np.inf), "rms": np.inf, "n_pixels": 0, "success": False}
    r, J, scale = res
    if J is None:  # the last round that ran was not the last planned one (too few pixels left)
        sel[:] = sel_fit
        prepare()
        u = x / scale
        J = np.empty((r.size, 3))
        for i in range(3):
            h = 1e-7 * max(abs(u[i]), 1.0)
            uh = u.copy()
            uh[i] += h
            J[:, i] = (fun(uh * scale) - r) / h
        J /= scale
    n_lin = sum(1 + bool(hb) + (b is True) for hb, b in terms)
    mtot = r.size
    s2 = float(r @ r) / max(mtot - 3 - n_lin, 1)
    cov = s2 * np.linalg.pinv(J.T @ J)
    a_mean = float(np.mean(np.abs(solve_all(x)[1][:, 0])))
    return {"position": x.copy(), "cov": cov, "rms": float(np.sqrt(np.mean(r * r))) / max(a_mean, 1e-300),
            "n_pixels": int(mtot), "success": bool(np.all(np.isfinite(x)) and a_mean > 0)}


# ----------------------------------------------------------------------------- one photo
def _evaluate(idx, fits, centers, floor, scene_center, model):
    dirs = np.array([fits[i].direction for i in idx])
    unc = np.array([np.hypot(fits[i].uncertainty_deg, floor) for i in idx])
    mean, u_mean, chi_d, dof_d = combine_distant(dirs, unc)
    out = {"idx": list(idx), "model": "distant", "direction": mean, "uncertainty_deg": u_mean,
           "chi2": chi_d, "dof": dof_d, "position": None}
    # a near fit can only lower chi2 to >= 0: when chi2 of the distant model is below the LR
    # threshold, the near model cannot be significant and is not fitted
    if len(idx) >= 2 and (model == "near" or (model == "auto" and chi_d > _chi2.ppf(1 - _ALPHA, 1))):
        conv = fit_ray_convergence(centers[list(idx)], dirs, unc, scene_center)
        near = conv["position"] is not None and (
            model == "near" or chi_d - conv["chi2"] > _chi2.ppf(1 - _ALPHA, 1))
        if near:
            out.update(model="near", direction=conv["direction"], chi2=conv["chi2"], dof=conv["dof"],
                       position=conv["position"])
    out["p"] = 1.0 if out["dof"] == 0 else float(_chi2.sf(out["chi2"], out["dof"]))
    return out


def sphere_values(image: np.ndarray, samples: list[SphereSamples], saturation: float | None = None,
                  raw: np.ndarray | None = None, bit_depth=None) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """The spheres' pixels of one photo: grey values, validity, saturated count.

    Only the sphere pixels are read (fancy indexing of the precomputed pixel lists), never the
    whole image.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) float
        Linear radiance.
    samples : list of SphereSamples
    saturation : float, optional
        Known clip level of the linear values.
    raw : (H, W, 3) array, optional
        The image as stored, with ``bit_depth``: then
        :func:`ffls.radiance.response.valid_pixel_mask` also applies (saturated codes of any
        channel, near-black codes; non-finite and negative floats).
    bit_depth : {8, 16, 'half', 'float'}, optional

    Returns
    -------
    list of (grey (m,) float64, valid (m,) bool, n_saturated int)
    """
    from ffls.radiance.response import valid_pixel_mask

    img = np.asarray(image)
    out = []
    for s in samples:
        px = img[s.rows, s.cols].astype(np.float64)
        valid, nsat = pixel_validity(px, saturation=saturation)
        if raw is not None and bit_depth is not None:
            rp = np.asarray(raw)[s.rows, s.cols]
            rp = rp.reshape(1, -1, rp.shape[-1] if rp.ndim == 2 else 1)
            if bit_depth in (8, 16):
                not_sat = valid_pixel_mask(rp, bit_depth, low=-1.0)[0]
                valid &= valid_pixel_mask(rp, bit_depth)[0]
                nsat = max(nsat, int((~not_sat).sum()))
            else:  # float data: no top code; near-black is relative (pixel_validity)
                valid &= valid_pixel_mask(rp, bit_depth, low=0.0)[0]
        grey = px.mean(axis=1) if px.ndim == 2 else px
        out.append((grey, valid, int(nsat)))
    return out


def estimate_photo(image: np.ndarray | None, samples: list[SphereSamples], scene_center: np.ndarray, *,
                   model: str = "auto", min_spheres: int | None = None, sigma_floor_deg: float = 1.0,
                   terminator: float = 0.15, saturation: float | None = None, up: np.ndarray = UP,
                   bounce_ratio: list | None = None, values: list | None = None, start: list | None = None,
                   joint: bool = True) -> dict:
    """Estimate the light of one photograph from its spheres.

    Parameters
    ----------
    image : (H, W, 3) float or None
        Linear radiance (None when ``values`` is given).
    samples : list of SphereSamples
        The spheres' pixels and normals (:func:`capture_samples`).
    scene_center : (3,) float
        World origin of the light direction.
    model : {'auto', 'distant', 'near'}
    min_spheres : int, optional
        Usable spheres needed; default ``min(2, len(samples))``.
    sigma_floor_deg : float
        RMS angular error added (in quadrature) to each sphere's statistical uncertainty for what
        the shading model does not capture.
    terminator : float
    saturation : float, optional
        Known clip level of the linear values.
    up : (3,) float
    bounce_ratio : list of (float or None), optional
        Per sphere, the calibrated ground ratio (:func:`calibrate_bounce`): the bounce is then
        imposed (``c = rho a max(l_z, 0)``) instead of fitted. None (or a None entry): free.
    values : list, optional
        :func:`sphere_values` of the photo, instead of ``image``.
    start : list, optional
        Per sphere, a direction (or None) to start its fit from (:func:`fit_lambert` ``start``):
        an earlier pass's result for the same photo.
    joint : bool
        Run the joint near-light fit (:func:`fit_near_light`) when the near model is chosen. False
        keeps the ray-intersection position (flagged ``joint_pending``): for a first pass whose
        per-sphere fits alone are used (:func:`estimate_photos` refits with the calibrated bounce).

    Returns
    -------
    dict
        ``status`` ('ok' | 'rejected'), ``reason`` (None or a :data:`REASONS` key), ``direction``
        (3,) unit (a best guess, or +Z, when rejected), ``position`` (3,) or None,
        ``uncertainty_deg``, ``model``, ``spheres`` (list of per-sphere dicts: status, direction,
        uncertainty_deg, rms, model, pixel counts, ground ratio), ``used_spheres`` (list of int).
    """
    if model not in LIGHT_MODELS:
        raise ValueError(f"model must be one of {LIGHT_MODELS}, not {model!r}")
    n_sph = len(samples)
    if values is None:
        if image is None:
            raise ValueError("estimate_photo needs an image or its sphere values")
        values = sphere_values(image, samples, saturation=saturation)
    if bounce_ratio is None:
        bounce_ratio = [None] * n_sph
    need = min(2, n_sph) if min_spheres is None else int(min_spheres)
    if start is None:
        start = [None] * n_sph
    fits = []
    for s, (grey, valid, nsat), rho, l0 in zip(samples, values, bounce_ratio, start):
        fits.append(fit_lambert(s.normals, grey, valid, n_saturated=nsat, terminator=terminator, up=up,
                                bounce_ratio=rho, g=s.ground if s.ground is not None and np.array_equal(up, UP) else None,
                                start=l0))
    status = [f.status for f in fits]
    ok = [i for i, f in enumerate(fits) if f.status == "ok"]
    if len(ok) >= 2:  # a sphere far darker than the others is in a shadow
        med = float(np.median([fits[i].intensity for i in ok]))
        for i in list(ok):
            if fits[i].intensity < 0.25 * med:
                status[i] = "shadowed"
                ok.remove(i)
    centers = np.array([s.center for s in samples])
    result = {"status": "rejected", "reason": None, "direction": np.array(UP, dtype=np.float64), "position": None,
              "uncertainty_deg": float("inf"), "model": None, "used_spheres": []}

    def sphere_report():
        return [{"status": status[i], **{k: v for k, v in fits[i].as_dict().items() if k != "status"}}
                for i in range(n_sph)]

    if len(ok) < need:
        if not ok:
            priority = ("saturated", "shadowed", "too_dark", "fit_failed")
            counts = Counter(st for st in status)
            reason = max(priority, key=lambda r: (counts.get(r, 0), -priority.index(r)))
        else:
            reason = "too_few_spheres"
        result.update(reason=reason, spheres=sphere_report())
        if ok:
            result["direction"] = fits[ok[0]].direction
        return result
    ev = _evaluate(ok, fits, centers, sigma_floor_deg, scene_center, model)
    if ev["p"] < _ALPHA:
        cands = []
        if len(ok) >= 3:
            for j in ok:
                sub = [i for i in ok if i != j]
                e = _evaluate(sub, fits, centers, sigma_floor_deg, scene_center, model)
                if e["p"] >= _ALPHA:
                    cands.append((e["chi2"], j, e))
        if not cands:
            result.update(reason="spheres_disagree", direction=ev["direction"], spheres=sphere_report())
            return result
        _, j, ev = min(cands, key=lambda c: c[0])
        status[j] = OUTLIER
    used = ev["idx"]
    direction, unc, position = ev["direction"], ev["uncertainty_deg"], ev["position"]
    if ev["model"] == "near" and not joint:
        result["joint_pending"] = True
    elif ev["model"] == "near":
        terms = []
        for i in used:
            f = fits[i]
            if f.bounce_ratio is not None:
                terms.append((f.model == "fixed_ambient", float(f.bounce_ratio)))
            else:
                terms.append((f.model != "plain", f.model == "bounce"))
        jf = fit_near_light([samples[i] for i in used], [values[i][0] for i in used],
                            [fits[i].inliers | _valid_lit(fits[i]) for i in used], position,
                            terms=terms, terminator=terminator, up=up)
        if jf["success"] and np.all(np.isfinite(jf["position"])):
            position = jf["position"]
            v = position - np.asarray(scene_center, dtype=np.float64)
            direction = normalize(v)
            stat = tangent_uncertainty_deg(v, jf["cov"])
            unc = float(np.hypot(stat, sigma_floor_deg / np.sqrt(len(used))))
        else:
            result.update(reason="fit_failed", direction=direction, spheres=sphere_report())
            return result
    result.update(status="ok", reason=None, direction=np.asarray(direction, dtype=np.float64),
                  position=None if position is None else np.asarray(position, dtype=np.float64),
                  uncertainty_deg=float(unc), model=ev["model"], used_spheres=[int(i) for i in used],
                  spheres=sphere_report(), chi2=float(ev["chi2"]), dof=int(ev["dof"]))
    return result


def _valid_lit(fit):
    # the per-sphere fit's final pixel set; the joint fit re-selects the terminator band itself
    return fit.inliers


# ----------------------------------------------------------------------------- capture level
def capture_samples(capture, spheres, shape: tuple[int, int]) -> list[SphereSamples]:
    """:func:`sphere_samples` for each found sphere (objects with ``center_cam`` and ``radius``)."""
    out = []
    for k, s in enumerate(spheres):
        R = float(getattr(s, "radius", None) or capture.sphere_radius)
        try:
            out.append(sphere_samples(shape, capture.K, capture.dist, np.asarray(s.center_cam), R,
                                      capture.world_from_camera))
        except ValueError as e:
            raise InputError(f"sphere {k}: {e}", capture.folder) from None
        if len(out[-1]) < 20:
            raise InputError(f"sphere {k} covers only {len(out[-1])} pixels; too small to estimate a light",
                             capture.folder)
    return out


def calibrate_bounce(results: list[dict], n_spheres: int, max_sigma: float = 0.05, min_photos: int = 3,
                     min_lz: float = 0.2) -> list[dict]:
    """Each sphere's ground ratio ``rho_g`` from the photos where it is well determined.

    The light reflected by the ground onto a sphere is ``c = rho_g a max(l_z, 0)``: the ground's
    irradiance is ``max(l_z, 0)`` times the sphere's (``a``), and ``rho_g`` (the ground albedo times
    the fraction of the ground the sphere sees lit) is a constant of the capture for each sphere.
    Where a photo shows the sphere's shadow side the free-bounce fit separates ``c`` from the
    ambient and the light (small ``ground_ratio_sigma``); where it does not (light on the camera
    side) ``c`` is confounded with them. The weighted median of the well-determined photos'
    ``c / (a l_z)`` is imposed in all photos (:func:`estimate_photo` ``bounce_ratio``).

    Parameters
    ----------
    results : list of dict
        :func:`estimate_photo` results with a free bounce (their ``spheres`` reports).
    n_spheres : int
    max_sigma : float
        Largest ``ground_ratio_sigma`` of a photo to use.
    min_photos : int
        Fewer usable photos than this leave the sphere uncalibrated (free bounce per photo).
    min_lz : float
        Smallest ``l_z`` of a photo to use (the ratio divides by ``l_z``).

    Returns
    -------
    list of dict
        Per sphere ``ratio`` (float, or None when uncalibrated), ``spread`` (robust standard
        deviation of the photos' estimates), ``n_photos``.
    """
    out = []
    for k in range(n_spheres):
        est, w = [], []
        for r in results:
            if r.get("status") != "ok" or not r.get("spheres"):
                continue
            sp = r["spheres"][k]
            d, q, sd = sp.get("direction"), sp.get("ground_ratio"), sp.get("ground_ratio_sigma")
            if (sp.get("status") != "ok" or d is None or q is None or sd is None or d[2] < min_lz
                    or not sd <= max_sigma):
                continue
            est.append(q)
            w.append(1.0 / max(sd, 1e-6) ** 2)
        if len(est) < min_photos:
            out.append({"ratio": None, "spread": None, "n_photos": len(est)})
            continue
        est, w = np.asarray(est), np.asarray(w)
        o = np.argsort(est)
        cw = np.cumsum(w[o])
        med = float(est[o][np.searchsorted(cw, 0.5 * cw[-1])])
        spread = float(1.4826 * np.median(np.abs(est - med)))
        out.append({"ratio": float(np.clip(med, 0.0, 1.0)), "spread": spread, "n_photos": int(len(est))})
    return out


def refine_sphere_centres(samples: list[SphereSamples], results: list[dict], values: list, terminator: float = 0.15,
                   **kwargs) -> tuple[list[SphereSamples], list, list]:
    """Refine every sphere's centre from the first-pass shading of all photos.

    :func:`ffls.spheres.refine.refine_sphere_centre` per sphere (photos where that sphere's fit
    was ``'ok'``), then :func:`ffls.spheres.refine.recentre_samples`; the photos' values are
    subset to the new pixels (no image is read again).

    Parameters
    ----------
    samples : list of SphereSamples
    results : list of dict
        First-pass :func:`estimate_photo` results (their per-sphere reports).
    values : list
        Per photo, its :func:`sphere_values` for ``samples``.
    terminator : float
    **kwargs
        Passed to :func:`ffls.spheres.refine.refine_sphere_centre`.

    Returns
    -------
    samples : list of SphereSamples
        Recentred where a refinement was accepted (others unchanged).
    values : list
        Per photo, the values for the new samples.
    refinements : list of CentreRefinement
    """
    from ffls.spheres.refine import recentre_samples, refine_sphere_centre

    new_s, idxs, refs = [], [], []
    for k, s in enumerate(samples):
        dirs = []
        for r in results:
            sp = (r.get("spheres") or [None] * len(samples))[k]
            ok = sp is not None and sp.get("status") == "ok" and sp.get("direction") is not None
            dirs.append(np.asarray(sp["direction"]) if ok else None)
        ref = refine_sphere_centre(s, [v[k] for v in values], dirs, terminator=terminator, **kwargs)
        refs.append(ref)
        if ref.accepted:
            s2, idx = recentre_samples(s, ref.center)
            new_s.append(s2)
            idxs.append(idx)
        else:
            new_s.append(s)
            idxs.append(None)
    new_v = [[tuple([vk[0][i], vk[1][i], *vk[2:]]) if i is not None else vk for vk, i in zip(v, idxs)]
             for v in values]
    return new_s, new_v, refs


def refit_spheres(result: dict, samples: list[SphereSamples], values: list, refinements: list, *,
                  terminator: float = 0.15, up: np.ndarray = UP, **_) -> dict:
    """A photo's first-pass ``result`` with the free-bounce fits of the recentred spheres redone.

    What the capture-wide bounce calibration needs after a centre refinement
    (:func:`calibrate_bounce` reads the per-sphere ground ratios of the photos that were
    ``'ok'``): the photo's status and the spheres' combination are kept from the first pass (the
    second pass redoes them with the calibrated ratios), only the per-sphere fits of the spheres
    whose centre moved are recomputed, each started from its first-pass direction. Spheres that
    the first pass marked (shadowed, outlier) keep that mark.
    """
    out = dict(result)
    sph = result.get("spheres")
    if not sph:
        return out
    new = list(sph)
    for k, (s, (grey, valid, nsat), ref) in enumerate(zip(samples, values, refinements)):
        if not ref.accepted:
            continue
        f = fit_lambert(s.normals, grey, valid, n_saturated=nsat, terminator=terminator, up=up,
                        g=s.ground if s.ground is not None and np.array_equal(up, UP) else None,
                        start=None if sph[k].get("direction") is None else np.asarray(sph[k]["direction"]))
        d = f.as_dict()
        st = sph[k]["status"] if sph[k]["status"] not in ("ok",) else d["status"]
        new[k] = {**d, "status": st}
    out["spheres"] = new
    return out


def _starts(result: dict) -> list | None:
    """Per sphere, its direction in an earlier pass's ``result`` (None where it was not fitted)."""
    sph = result.get("spheres")
    if not sph:
        return None
    return [None if sp.get("direction") is None else np.asarray(sp["direction"], dtype=np.float64) for sp in sph]


def _attach_refinements(results: list[dict], refinements: list | None) -> list[dict]:
    """Record each sphere's (refined) centre and its shift in the per-sphere reports."""
    if not refinements:
        return results
    for r in results:
        for sp, ref in zip(r.get("spheres") or [], refinements):
            sp["center"] = [float(v) for v in ref.center]
            sp["center_shift_px"] = ref.shift_norm_px
            sp["center_refined"] = bool(ref.accepted)
    return results


def estimate_photos(values: list, samples: list[SphereSamples], scene_center: np.ndarray,
                    bounce: str = "calibrated", refine_centres: bool = True, refinements: list | None = None,
                    refine_options: dict | None = None, **kwargs) -> tuple[list[dict], list[dict] | None]:
    """:func:`estimate_photo` for several photos of one capture, in one process, with the
    capture-wide bounce calibration of :func:`estimate_lights`.

    Parameters
    ----------
    values : list
        Per photo, its :func:`sphere_values`.
    samples : list of SphereSamples
    scene_center : (3,) float
    bounce : {'calibrated', 'free'}
    refine_centres : bool
        Refine the spheres' centres from the first pass's shading and fit the photos again before the bounce calibration (:func:`refine_sphere_centres`).
    refinements : list, optional
        If given (an empty list), receives the :class:`~ffls.spheres.refine.CentreRefinement`
        of each sphere.
    **kwargs
        Passed to :func:`estimate_photo`.

    Returns
    -------
    results : list of dict
        Per-sphere reports hold ``center`` (world), ``center_shift_px`` and ``center_refined``
        when ``refine_centres``.
    calibration : list of dict or None
        :func:`calibrate_bounce` per sphere (None for ``bounce='free'``).
    """
    if bounce not in ("calibrated", "free"):
        raise ValueError(f"bounce must be 'calibrated' or 'free', not {bounce!r}")
    # with a calibrated bounce the first pass only feeds the centre refinement and the calibration
    # (per-sphere fits): its near photos skip the joint position fit, redone in the second pass
    results = [estimate_photo(None, samples, scene_center, values=v, joint=bounce == "free", **kwargs)
               for v in values]
    refs = None
    if refine_centres:
        samples, values, refs = refine_sphere_centres(samples, results, values, terminator=kwargs.get("terminator", 0.15),
                                                      **(refine_options or {}))
        if refinements is not None:
            refinements.extend(refs)
        if any(r.accepted for r in refs):
            if bounce == "free":
                results = [estimate_photo(None, samples, scene_center, values=v, start=_starts(r), **kwargs)
                           for v, r in zip(values, results)]
            else:
                results = [refit_spheres(r, samples, v, refs, **kwargs) for v, r in zip(values, results)]
    if bounce == "free":
        return _attach_refinements(results, refs), None
    calib = calibrate_bounce(results, len(samples))
    ratios = [c["ratio"] for c in calib]
    if any(r is not None for r in ratios):
        results = [estimate_photo(None, samples, scene_center, values=v, bounce_ratio=ratios, start=_starts(r), **kwargs)
                   for v, r in zip(values, results)]
    else:  # no calibration: the first pass is final; its near photos get their joint fit now
        results = [estimate_photo(None, samples, scene_center, values=v, start=_starts(r), **kwargs)
                   if r.get("joint_pending") else r for v, r in zip(values, results)]
    return _attach_refinements(results, refs), calib


_W = {}


def _init_worker(capture, samples, kwargs):
    _W.update(capture=capture, samples=samples, kwargs=kwargs)


def _load(capture, i):
    """Linear image ``i`` and its raw pixels and bit depth (for the validity mask)."""
    photo = read_photo(capture, i)
    return photo.linear, photo.raw, photo.bit_depth


def _work(i):
    cap, samples, kw = _W["capture"], _W["samples"], _W["kwargs"]
    lin, raw, depth = _load(cap, i)
    vals = sphere_values(lin, samples, saturation=kw.get("saturation"), raw=raw, bit_depth=depth)
    vals = [(g.astype(np.float32), v, n) for g, v, n in vals]  # cached for the second pass
    return estimate_photo(None, samples, cap.scene_center, values=vals, **kw), vals


def _work2(args):
    vals, ratios, start = args
    cap, samples, kw = _W["capture"], _W["samples"], _W["kwargs"]
    return estimate_photo(None, samples, cap.scene_center, values=vals, bounce_ratio=ratios, start=start, **kw)


def _record(r: dict) -> dict:
    extra = {"uncertainty_deg": float(r["uncertainty_deg"]) if np.isfinite(r["uncertainty_deg"]) else None,
             "model": r["model"], "used_spheres": r["used_spheres"], "spheres": r.get("spheres", [])}
    if "chi2" in r:
        extra.update(chi2=r["chi2"], dof=r["dof"])
    return extra


def _map(fn, items, workers, capture, samples, kw, bar):
    out = []
    if workers == 1 or len(items) == 1:
        _init_worker(capture, samples, kw)
        for it in items:
            out.append(fn(it))
            if bar is not None:
                bar.update(1)
        return out
    with ProcessPoolExecutor(max_workers=min(workers, len(items)), initializer=_init_worker,
                             initargs=(capture, samples, kw)) as ex:
        for r in ex.map(fn, items, chunksize=max(1, len(items) // (8 * workers))):
            out.append(r)
            if bar is not None:
                bar.update(1)
    return out


def estimate_lights(capture, spheres=None, progress: bool = True, workers: int | None = None,
                    model: str = "auto", bounce: str = "calibrated", refine_centres: bool = True,
                    refine_options: dict | None = None, **kwargs):
    """Estimate every photograph's light from the capture's spheres.

    Two passes: every photo is fitted with a free ground bounce; each sphere's ground ratio is
    calibrated on the photos that determine it (:func:`calibrate_bounce`); every photo is then
    fitted again with that ratio imposed (spheres without enough such photos keep the free
    bounce). The spheres' pixels are kept in memory between the passes (never the images).

    Parameters
    ----------
    capture : ffls.io.capture.Capture
    spheres : list of SphereFit, optional
        The spheres (``center_cam`` camera frame, ``radius``); found with
        :func:`ffls.spheres.detect.find_spheres_in_capture` when None.
    progress : bool
        tqdm progress bar.
    workers : int, optional
        Processes; default every core. 1 runs in this process.
    model : {'auto', 'distant', 'near'}
    bounce : {'calibrated', 'free'}
        Two passes with the capture-wide ground ratio, or one pass with a free bounce per photo.
    refine_centres : bool
        After the first pass, refine each sphere's centre from the shading of up to 20 photos
        (:func:`refine_sphere_centres`) and repeat the first pass with the new centres.
    refine_options : dict, optional
        Passed to :func:`ffls.spheres.refine.refine_sphere_centre`.
    **kwargs
        Passed to :func:`estimate_photo` (``min_spheres``, ``sigma_floor_deg``, ``terminator``,
        ``saturation``).

    Returns
    -------
    ffls.io.capture.Lights
        Directions (world, from the scene centre), positions for near lights, status, reasons
        (:data:`REASONS`), and per light ``extra``: ``uncertainty_deg``, ``model``,
        ``used_spheres``, ``spheres`` (per-sphere direction, residual, uncertainty, pixel counts,
        ground ratio estimate and the imposed ``bounce_ratio``; with ``refine_centres`` also the
        sphere's world ``center``, ``center_shift_px`` and ``center_refined``).
    """
    from ffls.io.capture import Lights

    if model not in LIGHT_MODELS:
        raise ValueError(f"model must be one of {LIGHT_MODELS}, not {model!r}")
    if bounce not in ("calibrated", "free"):
        raise ValueError(f"bounce must be 'calibrated' or 'free', not {bounce!r}")
    if capture.K is None:
        raise InputError("capture has no camera intrinsics (camera.K); light estimation needs them", capture.json_path)
    if capture.sphere_radius is None:
        raise InputError("capture has no sphere_radius; light estimation needs it", capture.json_path)
    n = len(capture.image_names)
    if n == 0:
        raise InputError("capture lists no images", capture.json_path)
    if spheres is None:
        from ffls.spheres.detect import find_spheres_in_capture

        spheres = find_spheres_in_capture(capture)
    if model == "near" and len(spheres) < 2:
        raise InputError("model 'near' needs at least 2 spheres to triangulate the light", capture.json_path)
    if capture.image_size is not None:
        shape = (int(capture.image_size[1]), int(capture.image_size[0]))
    else:
        shape = load_photo(capture, 0).shape[:2]
    samples = capture_samples(capture, spheres, shape)
    kw = dict(model=model, **kwargs)
    workers = (os.cpu_count() or 1) if workers is None else max(1, int(workers))
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n * (2 if bounce == "calibrated" else 1), desc="lights", unit="img")
    try:
        # calibrated bounce: the first pass skips the joint near fit (redone in the second pass)
        first = _map(_work, list(range(n)), workers, capture, samples, dict(kw, joint=bounce == "free"), bar)
        results = [r for r, _ in first]
        refs = None
        if refine_centres:
            samples, vals, refs = refine_sphere_centres(samples, results, [v for _, v in first],
                                                        terminator=kw.get("terminator", 0.15), **(refine_options or {}))
            if any(r.accepted for r in refs):
                if bounce == "free":
                    results = _map(_work2, [(v, None, _starts(r)) for v, r in zip(vals, results)], workers, capture,
                                   samples, kw, None)
                else:  # only what the bounce calibration reads (cheap: in this process)
                    results = [refit_spheres(r, samples, v, refs, **kw) for v, r in zip(vals, results)]
                first = list(zip(results, vals))
        if bounce == "calibrated":
            calib = calibrate_bounce(results, len(samples))
            ratios = [c["ratio"] for c in calib]
            if any(r is not None for r in ratios):
                results = _map(_work2, [(v, ratios, _starts(r)) for r, v in first], workers, capture, samples, kw, bar)
            else:  # no calibration: the first pass is final; its near photos get their joint fit now
                pend = [i for i, r in enumerate(results) if r.get("joint_pending")]
                if pend:
                    redo = _map(_work2, [(first[i][1], None, _starts(results[i])) for i in pend], workers, capture,
                                samples, kw, None)
                    for i, r in zip(pend, redo):
                        results[i] = r
                if bar is not None:
                    bar.update(n)
    finally:
        if bar is not None:
            bar.close()
    results = _attach_refinements(results, refs)
    dirs = np.array([normalize(r["direction"]) if np.all(np.isfinite(r["direction"])) else UP for r in results])
    pos = np.array([r["position"] if r["position"] is not None else np.full(3, np.nan) for r in results])
    return Lights(image_names=capture.image_names, directions=dirs, positions=pos,
                  status=[r["status"] for r in results], reasons=[r["reason"] for r in results],
                  extra=[_record(r) for r in results])


#: The paper's method under its name (GUIDE: one paper per function).
estimate_lights_MasselusDutreAnrys2002 = estimate_lights
