"""One light from several spheres' directions: the distant and the near model.

Masselus, Dutre, Anrys, "The Free-form Light Stage", EGWR 2002, section 5: each sphere gives a
direction (:mod:`ffls.spheres.lambert`); "the best fitted intersection is used to find the
illuminant direction with respect to the centre of the scene". The spheres' directions ``l_i``
(RMS uncertainties ``s_i``) are explained by

* a **distant** light (:func:`combine_distant`): one direction ``l``, inverse-variance mean on
  the unit sphere, ``chi2 = sum angle(l_i, l)^2 / (s_i^2 / 2)`` with ``2 (k - 1)`` degrees of
  freedom;
* a **near** light at ``S = c + l / rho`` (:func:`fit_ray_convergence`; ``c`` the scene centre,
  inverse distance ``rho >= 0`` so that ``rho -> 0`` is the distant limit and nearly parallel
  rays stay stable): the rays ``C_i + t l_i`` meet at ``S``; ``2 k - 3`` degrees of freedom.

A near light changes the shading itself (direction and ``1/r^2`` over each sphere), so its
position is refined by a **joint** fit to all used spheres' pixels (:func:`fit_near_light`,
variable projection, Golub & Pereyra 1973), initialised from the ray intersection.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffls.conventions import UP, angle_between, normalize, tangent_basis
from ffls.spheres.lambert import solve_normal_equations
from ffls.spheres.samples import SphereSamples

__all__ = ["combine_distant", "RayConvergence", "fit_ray_convergence", "NearLightFit", "fit_near_light",
           "fit_near_light_mixed"]


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


def _levenberg_marquardt(fun, x0, lb=None, ub=None, max_iter: int = 40, rel_step: float = 1e-7, ftol: float = 1e-10,
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
        scaling = np.diag(np.maximum(np.diag(JtJ), 1e-12 * max(float(np.max(np.diag(JtJ))), 1e-300)))
        improved = False
        while lam < 1e8:
            try:
                dx = -np.linalg.solve(JtJ + lam * scaling, grad)
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


@dataclass
class RayConvergence:
    """Result of :func:`fit_ray_convergence`.

    Attributes
    ----------
    direction : (3,) float, unit
        From the scene centre toward the light.
    rho : float
        Inverse distance of the light from the scene centre (1/units); 0 for a distant light.
    position : (3,) float or None
        The light's position (world); None when ``rho == 0``.
    chi2 : float
        With ``dof = 2 k - 3`` degrees of freedom.
    dof : int
    """

    direction: np.ndarray
    rho: float
    position: np.ndarray | None
    chi2: float
    dof: int


def fit_ray_convergence(centers: np.ndarray, directions: np.ndarray, uncertainty_deg: np.ndarray,
                        scene_center: np.ndarray) -> RayConvergence:
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
    RayConvergence
    """
    C = np.atleast_2d(np.asarray(centers, dtype=np.float64)) - np.asarray(scene_center, dtype=np.float64)
    d = normalize(np.atleast_2d(directions))
    sig = _sigma_axis(uncertainty_deg)
    k = len(d)
    m0, _, _, _ = combine_distant(d, uncertainty_deg)
    e1, e2 = tangent_basis(m0)
    tangents = np.stack([np.stack(tangent_basis(di)) for di in d])  # (k, 2, 3)
    scale = float(np.max(np.linalg.norm(C, axis=1))) or 1.0

    def predicted(x):
        m = m0 + x[0] * e1 + x[1] * e2
        m = m / np.sqrt(m @ m)
        p = m[None, :] - (x[2] / scale) * C
        return p / np.sqrt(np.einsum("ij,ij->i", p, p))[:, None], m

    def residuals(x):
        # the log map of the predicted direction at each observed one: its length is the angle
        # between them, so a prediction opposite to a sphere's direction costs 180 degrees (the
        # projection of p - d alone, sin(angle), falls back to 0 there and let a mirror ball's
        # highlight 162 degrees off pass as consistent)
        p, _ = predicted(x)
        c = np.einsum("ij,ij->i", p, d)
        t = p - c[:, None] * d
        nt = np.sqrt(np.einsum("ij,ij->i", t, t))
        stretch = np.arccos(np.clip(c, -1.0, 1.0)) / np.maximum(nt, 1e-12)
        r = np.einsum("kij,kj->ki", tangents, t) * np.where(nt > 1e-12, stretch, 1.0)[:, None]
        r[(nt <= 1e-12) & (c < 0), 0] = np.pi  # exactly opposite: 180 degrees, along any tangent axis
        return (r / sig[:, None]).ravel()

    best = None
    for rho0 in (0.0, 0.1, 0.5):
        x, r, _ = _levenberg_marquardt(residuals, np.array([0.0, 0.0, rho0]), np.array([-1.0, -1.0, 0.0]),
                                       np.array([1.0, 1.0, 0.99]), ftol=_FTOL, xtol=_XTOL, want_jac=False)
        if best is None or r @ r < best[1] @ best[1]:
            best = (x, r)
    _, m = predicted(best[0])
    rho = best[0][2] / scale
    chi = float(best[1] @ best[1])
    pos = None if rho <= 1e-12 else np.asarray(scene_center, dtype=np.float64) + m / rho
    return RayConvergence(direction=m, rho=float(rho), position=pos, chi2=float(chi), dof=max(2 * k - 3, 0))


# ----------------------------------------------------------------------------- joint near fit
@dataclass
class NearLightFit:
    """Result of :func:`fit_near_light`.

    Attributes
    ----------
    position : (3,) float
        The light's position (world; the initial one when the fit failed).
    cov : (3, 3) float
        Covariance of the position (infinite when the fit failed).
    rms : float
        RMS residual relative to the mean light coefficient ``a_k``.
    n_pixels : int
        Pixels in the final fit.
    success : bool
    """

    position: np.ndarray
    cov: np.ndarray
    rms: float
    n_pixels: int
    success: bool


class _JointShading:
    """The pixels of a joint near-light fit and their shading model for a light position ``S``.

    Per sphere, a fixed lattice of its pixels (every ``stride``-th, raster order) is gathered once
    as contiguous float64. :meth:`select` chooses the pixels of a round and stacks all spheres'
    selected pixels into one array, so that ``q = n . S - n . P`` and
    ``|S - P|^2 = S . S - 2 P . S + P . P`` are two matrix-vector products per evaluation and the
    per-sphere Gram entries are segment sums. :meth:`solve` gives the per-sphere linear
    coefficients in closed form and the residuals of all selected pixels.
    """

    def __init__(self, samples, values, masks, position0, terms, up, stride):
        self.n_spheres = len(samples)
        self.up = up
        # D_k^2 = |S0 - C_k|^2: fixed scale so that a_k is in image units
        self.scale_sq = np.array([float(np.sum((position0 - s.center) ** 2)) for s in samples])
        self.contacts = np.array([s.center - s.radius * up for s in samples])  # G_k
        ratio = [None if isinstance(b, (bool, np.bool_)) else float(b) for _, b in terms]
        # per sphere, the coefficient columns present besides the first (a_k): ambient, free bounce
        self.has_ambient = np.array([bool(b_) for b_, _ in terms])
        self.has_free_bounce = np.array([b_ is True for _, b_ in terms])
        self.ground_ratio = np.array([0.0 if r_ is None else r_ for r_ in ratio])
        self.n_linear = sum(1 + bool(hb) + (b is True) for hb, b in terms)
        lattice = [np.arange(0, len(s), max(int(stride), 1)) for s in samples]
        self.normals = [np.ascontiguousarray(s.normals[i], dtype=np.float64) for s, i in zip(samples, lattice)]
        self.points = [np.ascontiguousarray(s.points[i], dtype=np.float64) for s, i in zip(samples, lattice)]
        self.values = [np.asarray(v, dtype=np.float64)[i] for v, i in zip(values, lattice)]
        self.ground = [s.ground_factor(up)[i] for s, i in zip(samples, lattice)]
        self.allowed = [np.asarray(m, dtype=bool)[i] for m, i in zip(masks, lattice)]

    def terminator_selection(self, S, terminator):
        """Per sphere, its allowed pixels outside the terminator band ``|cos| <= terminator`` of a light at ``S``."""
        sel = []
        for n, P, ok in zip(self.normals, self.points, self.allowed):
            dd = S - P
            c = np.einsum("ij,ij->i", n, dd) / np.sqrt(np.einsum("ij,ij->i", dd, dd))
            sel.append(ok & (np.abs(c) > terminator))
        return sel

    def select(self, selection):
        """Stack the selected pixels (per sphere a (lattice,) bool) of all spheres for :meth:`solve`."""
        K = self.n_spheres
        idx = [np.flatnonzero(w) for w in selection]
        cnt = np.array([i.size for i in idx])
        starts = np.concatenate([[0], np.cumsum(cnt)[:-1]])
        n = np.concatenate([self.normals[k][i] for k, i in enumerate(idx)])
        P = np.concatenate([self.points[k][i] for k, i in enumerate(idx)])
        y = np.concatenate([self.values[k][i] for k, i in enumerate(idx)])
        g = np.concatenate([self.ground[k][i] for k, i in enumerate(idx)])
        self.normals_points = np.ascontiguousarray(np.stack([n, P]))
        self.n_dot_p = np.einsum("ij,ij->i", n, P)
        self.p_dot_p = np.einsum("ij,ij->i", P, P)
        self.y, self.g, self.counts = y, g, cnt
        self.segment_starts = np.minimum(starts, max(int(cnt.sum()) - 1, 0))
        self.pixel_scale_sq = np.repeat(self.scale_sq, cnt)
        self.nonempty = cnt > 0
        # data-only sums: 1, g, g^2, y, g y
        self.data_sums = np.stack([cnt.astype(np.float64), *(np.add.reduceat(v, np.minimum(starts, max(v.size - 1, 0)))
                                                              * (cnt > 0) if v.size else np.zeros(K)
                                                              for v in (g, g * g, y, g * y))])

    def solve(self, S):
        """Per sphere the closed-form coefficients ``(a_k, b_k, c_k)`` at ``S`` (K, 3); the residuals of all pixels."""
        K, up = self.n_spheres, self.up
        hb, hc = self.has_ambient, self.has_free_bounce
        qp = self.normals_points @ S
        q = qp[0] - self.n_dot_p
        r2 = (S @ S) - 2.0 * qp[1] + self.p_dot_p
        f = np.maximum(q, 0.0) / (r2 * np.sqrt(r2)) * self.pixel_scale_sq
        g, y = self.g, self.y
        ff, f1, fg, fy = np.add.reduceat(np.stack([f * f, f, f * g, f * y]), self.segment_starts, axis=1) * self.nonempty
        n1, sg, sgg, sy, sgy = self.data_sums
        # calibrated bounce: the first column is f + t_k g, t_k = rho_k h_k(S) D_k^2
        e = S[None, :] - self.contacts
        t = self.ground_ratio * np.maximum(e @ up, 0.0) / np.einsum("ij,ij->i", e, e) ** 1.5 * self.scale_sq
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
            X[k, cols] = solve_normal_equations(Gm[k][np.ix_(cols, cols)], h[k, cols], n_free=1)[0]
        X = np.column_stack([X[:, 0], X[:, 1], X[:, 2] + t * X[:, 0]])  # c_k: free, or t_k a_k
        Xp = np.repeat(X, self.counts, axis=0)
        return y - Xp[:, 0] * f - Xp[:, 1] - Xp[:, 2] * g, X

    def residuals(self, S):
        return self.solve(S)[0]

    def drop_outliers(self, selection, residuals, coefficients, clip: float = 4.0):
        """Unselect, per sphere, pixels beyond ``clip`` robust sigma (MAD, at least 1 % of ``a_k``); in place."""
        for k, rk in enumerate(np.split(residuals, np.cumsum(self.counts)[:-1])):
            sd = max(1.4826 * float(np.median(np.abs(rk - np.median(rk)))), 0.01 * abs(coefficients[k, 0]))
            w = np.flatnonzero(selection[k])
            selection[k][w[np.abs(rk) > clip * sd]] = False


def fit_near_light(samples: list[SphereSamples], values: list[np.ndarray], masks: list[np.ndarray],
                   position0: np.ndarray, terms: list[tuple] | None = None,
                   terminator: float = 0.15, up: np.ndarray = UP, n_rounds: int = 2, stride: int = 4) -> NearLightFit:
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
        Pixels allowed (valid, not outliers of the per-sphere fit; any side of the terminator:
        the band is re-selected here with the light's position).
    position0 : (3,) float
        Initial light position (world).
    terms : list of (bool, bool or float), optional
        Per sphere: fit the ambient ``b_k``; the bounce: True (free ``c_k``), False (none) or a
        float (the calibrated ratio ``rho_k``). Default ``(True, True)``.
    terminator : float
    up : (3,) float
    n_rounds : int
    stride : int
        Every ``stride``-th pixel of each sphere is used (a fixed lattice).

    Returns
    -------
    NearLightFit
    """
    K = len(samples)
    if terms is None:
        terms = [(True, True)] * K
    up = np.asarray(up, dtype=np.float64)
    S0 = np.asarray(position0, dtype=np.float64)
    shading = _JointShading(samples, values, masks, S0, terms, up, stride)
    x = S0.copy()
    res = None
    for rnd in range(n_rounds):
        # terminator band and outliers with the current position
        sel = shading.terminator_selection(x, terminator)
        if rnd > 0 and res is not None:
            shading.select(sel)
            shading.drop_outliers(sel, *shading.solve(x))
        if sum(int(s_.sum()) for s_ in sel) <= 3 + 3 * K:
            break
        shading.select(sel)
        sel_fit = [s_.copy() for s_ in sel]
        scale = float(np.linalg.norm(x))
        last = rnd == n_rounds - 1
        xs, r, J = _levenberg_marquardt(lambda u: shading.residuals(u * scale), x / scale, ftol=_FTOL, xtol=_XTOL,
                                        want_jac=last)
        x = xs * scale
        res = (r, None if J is None else J / scale, scale)  # J None: not needed if another round follows
    if res is None or not np.all(np.isfinite(x)):
        return NearLightFit(position=S0, cov=np.full((3, 3), np.inf), rms=np.inf, n_pixels=0, success=False)
    r, J, scale = res
    if J is None:  # the last round that ran was not the last planned one (too few pixels left)
        shading.select(sel_fit)
        u = x / scale
        J = np.empty((r.size, 3))
        for i in range(3):
            h = 1e-7 * max(abs(u[i]), 1.0)
            uh = u.copy()
            uh[i] += h
            J[:, i] = (shading.residuals(uh * scale) - r) / h
        J /= scale
    mtot = r.size
    s2 = float(r @ r) / max(mtot - 3 - shading.n_linear, 1)
    cov = s2 * np.linalg.pinv(J.T @ J)
    a_mean = float(np.mean(np.abs(shading.solve(x)[1][:, 0])))
    return NearLightFit(position=x.copy(), cov=cov, rms=float(np.sqrt(np.mean(r * r))) / max(a_mean, 1e-300),
                        n_pixels=int(mtot), success=bool(np.all(np.isfinite(x)) and a_mean > 0))


def fit_near_light_mixed(samples: list[SphereSamples], values: list[np.ndarray], masks: list[np.ndarray],
                         position0: np.ndarray, rays: list[tuple], terms: list[tuple] | None = None,
                         inflation: list[float] | None = None, terminator: float = 0.15, up: np.ndarray = UP,
                         n_rounds: int = 2, stride: int = 4) -> NearLightFit:
    """Joint fit of a point light's position to matte spheres' pixels and mirror spheres' rays.

    One least-squares problem (:func:`scipy.optimize.least_squares`) in the light's position
    ``S`` whose residuals, each in units of its own standard deviation, are

    * per matte sphere ``k``, its pixels' shading residuals (the model of :func:`fit_near_light`,
      linear coefficients solved in closed form for each ``S``) over the sphere's robust residual
      deviation ``s_k`` times ``sqrt(f_k)``, ``f_k`` the sphere's own variance inflation for
      spatially correlated residuals (:func:`ffls.spheres.uncertainty.correlation_inflation`;
      without it the hundreds of correlated pixels would outweigh every mirror);
    * per mirror sphere, the two tangent components of ``normalize(S - P_j)`` about its measured
      reflected direction ``d_j`` (the highlight's ray from its reflection point ``P_j``), over the
      direction's per-axis standard deviation.

    The position's covariance is ``(J^T J)^-1`` times the reduced chi-square when above 1 (the
    residuals' spread as measured), so that it carries into the light direction's cone.

    Parameters
    ----------
    samples, values, masks :
        The matte spheres, as :func:`fit_near_light` (may be empty).
    position0 : (3,) float
        Initial position (the ray intersection).
    rays : list of (origin (3,), direction (3,), sigma_axis_rad)
        The mirror spheres' reflected rays.
    terms : list of (bool, bool or float), optional
        Per matte sphere, as :func:`fit_near_light`.
    inflation : list of float, optional
        Per matte sphere, its own fit's variance inflation (``LambertFit.inflation``); 1 when None.
    terminator, up, n_rounds, stride :
        As :func:`fit_near_light`.

    Returns
    -------
    NearLightFit
    """
    from scipy.optimize import least_squares

    K = len(samples)
    up = np.asarray(up, dtype=np.float64)
    S0 = np.asarray(position0, dtype=np.float64)
    terms = [(True, True)] * K if terms is None else terms
    infl = np.ones(K) if inflation is None else np.maximum(np.nan_to_num(np.asarray(inflation, dtype=np.float64),
                                                                         nan=1.0), 1.0)
    origins = np.array([np.asarray(o, dtype=np.float64) for o, _, _ in rays]).reshape(-1, 3)
    dirs = normalize(np.array([np.asarray(d, dtype=np.float64) for _, d, _ in rays]).reshape(-1, 3)) if rays \
        else np.zeros((0, 3))
    sig = np.array([float(s) for _, _, s in rays])
    if len(rays) and not (np.all(np.isfinite(origins)) and np.all(np.isfinite(dirs)) and np.all(sig > 0)):
        return NearLightFit(position=S0, cov=np.full((3, 3), np.inf), rms=np.inf, n_pixels=0, success=False)
    tangents = np.stack([np.stack(tangent_basis(d)) for d in dirs]) if len(rays) else np.zeros((0, 2, 3))
    shading = _JointShading(samples, values, masks, S0, terms, up, stride) if K else None
    pixel_scale = np.zeros(0)

    def mirror_residuals(S):
        if not len(rays):
            return np.zeros(0)
        u = S[None, :] - origins
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        return (np.einsum("kij,kj->ki", tangents, u) / sig[:, None]).ravel()

    def residuals(S):
        r = mirror_residuals(S)
        if shading is None:
            return r
        return np.concatenate([shading.residuals(S) * pixel_scale, r])

    def per_sphere_scale(S):
        """Per selected pixel, 1 / (robust residual sd of its sphere * sqrt(its inflation)), that
        deviation never below the spheres' median: a sphere the model misses (part of it in a cast
        shadow) is weighted down, but none is weighted up for small residuals (a dark, vignetted
        sphere's are small in absolute units, and its shading is no truer for it)."""
        res, X = shading.solve(S)
        devs = []
        for k, rk in enumerate(np.split(res, np.cumsum(shading.counts)[:-1])):
            sd = 1.4826 * float(np.median(np.abs(rk - np.median(rk)))) if rk.size else 1.0
            devs.append(max(sd, 1e-3 * abs(float(X[k, 0])), 1e-12) * np.sqrt(infl[k]))
        floor = float(np.median(devs)) if devs else 1.0
        out = [np.full(n, 1.0 / max(d, floor)) for n, d in zip(shading.counts, devs)]
        return np.concatenate(out) if out else np.zeros(0)

    x = S0.copy()
    fit = None
    for rnd in range(max(int(n_rounds), 1)):
        if shading is not None:
            sel = shading.terminator_selection(x, terminator)
            if rnd > 0:
                shading.select(sel)
                shading.drop_outliers(sel, *shading.solve(x))
            shading.select(sel)
            if int(shading.counts.sum()) <= 3 * K:
                break
            pixel_scale = per_sphere_scale(x)
        scale = max(float(np.linalg.norm(x)), 1e-6)
        fit = least_squares(residuals, x, x_scale=scale, method="trf", xtol=_XTOL, ftol=_FTOL)
        if not np.all(np.isfinite(fit.x)):
            break
        x = fit.x
    if fit is None or not np.all(np.isfinite(x)) or fit.fun.size <= 3:
        return NearLightFit(position=S0, cov=np.full((3, 3), np.inf), rms=np.inf, n_pixels=0, success=False)
    r, J = fit.fun, fit.jac
    n_lin = shading.n_linear if shading is not None else 0
    dof = max(r.size - 3 - n_lin, 1)
    chi2_red = float(r @ r) / dof
    cov = max(chi2_red, 1.0) * np.linalg.pinv(J.T @ J)
    n_pix = int(shading.counts.sum()) if shading is not None else 0
    return NearLightFit(position=x.copy(), cov=cov, rms=float(np.sqrt(chi2_red)), n_pixels=n_pix,
                        success=bool(fit.status > 0))
