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
from scipy.optimize import least_squares
from scipy.stats import chi2 as _chi2

from ..conventions import UP, angle_between, normalize
from ..errors import InputError
from .lambert import SphereSamples, fit_lambert, ground_bounce, sphere_samples, tangent_uncertainty_deg

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
        m = normalize(m0 + x[0] * e1 + x[1] * e2)
        return normalize(m[None, :] - (x[2] / scale) * C), m

    def fun(x):
        p, _ = dirs(x)
        return (np.einsum("kij,kj->ki", T, p - d) / sig[:, None]).ravel()

    best = None
    for rho0 in (0.0, 0.1, 0.5):
        r = least_squares(fun, np.array([0.0, 0.0, rho0]), bounds=([-1, -1, 0.0], [1, 1, 0.99]), method="trf")
        if best is None or r.cost < best.cost:
            best = r
    _, m = dirs(best.x)
    rho = best.x[2] / scale
    chi = 2.0 * best.cost
    pos = None if rho <= 1e-12 else np.asarray(scene_center, dtype=np.float64) + m / rho
    return {"direction": m, "rho": float(rho), "position": pos, "chi2": float(chi), "dof": max(2 * k - 3, 0)}


# ----------------------------------------------------------------------------- joint near fit
def fit_near_light(samples: list[SphereSamples], values: list[np.ndarray], masks: list[np.ndarray],
                   position0: np.ndarray, terms: list[tuple[bool, bool]] | None = None,
                   terminator: float = 0.15, up: np.ndarray = UP, n_rounds: int = 2) -> dict:
    """Joint fit of a point light's position to several spheres' pixels.

    Model per pixel ``p`` of sphere ``k`` (surface point ``P``, normal ``n``, ``d = S - P``)::

        I = a_k D_k^2 max(0, n . d) / |d|^3 + b_k + c_k g(n)

    with ``D_k = |S0 - C_k|`` a fixed scale (so ``a_k`` is in image units), ``b_k, c_k >= 0``.
    Solved with :func:`scipy.optimize.least_squares` (analytic Jacobian), pixels near the
    terminator re-selected and outliers (MAD) rejected between rounds.

    Parameters
    ----------
    samples : list of SphereSamples
    values : list of (m_k,) float
    masks : list of (m_k,) bool
        Pixels allowed (valid, not outliers of the per-sphere fit).
    position0 : (3,) float
        Initial light position (world).
    terms : list of (bool, bool), optional
        Per sphere: fit ambient ``b_k``, fit bounce ``c_k``. Default both.
    terminator : float
    up : (3,) float
    n_rounds : int

    Returns
    -------
    dict
        ``position`` (3,), ``cov`` (3, 3) covariance of the position, ``rms`` (relative),
        ``n_pixels``, ``success`` (bool).
    """
    K = len(samples)
    if terms is None:
        terms = [(True, True)] * K
    S0 = np.asarray(position0, dtype=np.float64)
    D2 = [float(np.sum((S0 - s.center) ** 2)) for s in samples]
    gs = [ground_bounce(s.normals, up) for s in samples]
    # parameter layout
    idx = []
    p = 3
    for (hb, hc) in terms:
        ia = p
        ib = p + 1 if hb else None
        ic = (p + 1 + hb) if hc else None
        idx.append((ia, ib, ic))
        p += 1 + hb + hc
    sel = [np.asarray(m, dtype=bool).copy() for m in masks]

    def parts(x):
        S = x[:3]
        out = []
        for k, s in enumerate(samples):
            n, P, y = s.normals[sel[k]], s.points[sel[k]], values[k][sel[k]]
            dd = S - P
            r2 = np.sum(dd * dd, axis=1)
            r = np.sqrt(r2)
            q = np.sum(n * dd, axis=1)
            lit = q > 0
            f = np.where(lit, q, 0.0) / (r2 * r) * D2[k]
            ia, ib, ic = idx[k]
            pred = x[ia] * f
            if ib is not None:
                pred = pred + x[ib]
            if ic is not None:
                pred = pred + x[ic] * gs[k][sel[k]]
            out.append((dd, r, q, lit, f, pred, y, n))
        return out

    def fun(x):
        return np.concatenate([pr[5] - pr[6] for pr in parts(x)])

    def jac(x):
        pr_all = parts(x)
        m = sum(len(pr[6]) for pr in pr_all)
        J = np.zeros((m, p))
        o = 0
        for k, (dd, r, q, lit, f, pred, y, n) in enumerate(pr_all):
            ia, ib, ic = idx[k]
            mk = len(y)
            dS = (n / (r ** 3)[:, None] - 3.0 * (q / r ** 5)[:, None] * dd) * (x[ia] * D2[k])
            J[o:o + mk, :3] = np.where(lit[:, None], dS, 0.0)
            J[o:o + mk, ia] = f
            if ib is not None:
                J[o:o + mk, ib] = 1.0
            if ic is not None:
                J[o:o + mk, ic] = gs[k][sel[k]]
            o += mk
        return J

    # initial per-sphere linear terms from the start position
    x = np.zeros(p)
    x[:3] = S0
    for k, s in enumerate(samples):
        dd = S0 - s.points
        r = np.linalg.norm(dd, axis=1)
        f = np.maximum(np.sum(s.normals * dd, axis=1), 0.0) / r ** 3 * D2[k]
        m = sel[k] & (f > 0.3 * max(f.max(), 1e-300))
        if m.sum() > 0:
            x[idx[k][0]] = max(float(np.median(values[k][m] / f[m])), 1e-12)
    lb = np.full(p, 0.0)
    lb[:3] = -np.inf
    ub = np.full(p, np.inf)
    res = None
    for rnd in range(n_rounds):
        # terminator band and outliers with the current position
        for k, s in enumerate(samples):
            dd = x[:3] - s.points
            c = np.sum(s.normals * dd, axis=1) / np.linalg.norm(dd, axis=1)
            sel[k] = np.asarray(masks[k], dtype=bool) & (np.abs(c) > terminator)
        if rnd > 0 and res is not None:
            r_all = fun(x)
            o = 0
            for k in range(K):
                mk = int(sel[k].sum())
                rk = r_all[o:o + mk]
                o += mk
                sd = max(1.4826 * float(np.median(np.abs(rk - np.median(rk)))), 0.01 * x[idx[k][0]])
                keep = np.abs(rk) <= 4.0 * sd
                w = np.flatnonzero(sel[k])
                sel[k][w[~keep]] = False
        if sum(int(s_.sum()) for s_ in sel) <= p:
            break
        x0 = np.clip(x, lb, ub)
        x0[3:] = np.maximum(x0[3:], 1e-12)
        res = least_squares(fun, x0, jac=jac, bounds=(lb, ub), method="trf", x_scale="jac", tr_solver="lsmr",
                            xtol=1e-10, ftol=1e-10, max_nfev=60)
        x = res.x
    if res is None:
        return {"position": S0, "cov": np.full((3, 3), np.inf), "rms": np.inf, "n_pixels": 0, "success": False}
    r = res.fun
    J = res.jac
    mtot = r.size
    s2 = float(r @ r) / max(mtot - p, 1)
    cov = s2 * np.linalg.pinv(J.T @ J)
    a_mean = float(np.mean([x[i[0]] for i in idx]))
    return {"position": x[:3].copy(), "cov": cov[:3, :3], "rms": float(np.sqrt(np.mean(r * r))) / max(a_mean, 1e-300),
            "n_pixels": int(mtot), "success": bool(res.status > 0 and np.all(np.isfinite(x)))}


# ----------------------------------------------------------------------------- one photo
def _evaluate(idx, fits, centers, floor, scene_center, model):
    dirs = np.array([fits[i].direction for i in idx])
    unc = np.array([np.hypot(fits[i].uncertainty_deg, floor) for i in idx])
    mean, u_mean, chi_d, dof_d = combine_distant(dirs, unc)
    out = {"idx": list(idx), "model": "distant", "direction": mean, "uncertainty_deg": u_mean,
           "chi2": chi_d, "dof": dof_d, "position": None}
    if len(idx) >= 2 and model in ("auto", "near"):
        conv = fit_ray_convergence(centers[list(idx)], dirs, unc, scene_center)
        near = conv["position"] is not None and (
            model == "near" or chi_d - conv["chi2"] > _chi2.ppf(1 - _ALPHA, 1))
        if near:
            out.update(model="near", direction=conv["direction"], chi2=conv["chi2"], dof=conv["dof"],
                       position=conv["position"])
    out["p"] = 1.0 if out["dof"] == 0 else float(_chi2.sf(out["chi2"], out["dof"]))
    return out


def estimate_photo(image: np.ndarray, samples: list[SphereSamples], scene_center: np.ndarray, *,
                   model: str = "auto", min_spheres: int | None = None, sigma_floor_deg: float = 1.0,
                   terminator: float = 0.15, saturation: float | None = None, up: np.ndarray = UP) -> dict:
    """Estimate the light of one photograph from its spheres.

    Parameters
    ----------
    image : (H, W, 3) float
        Linear radiance.
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

    Returns
    -------
    dict
        ``status`` ('ok' | 'rejected'), ``reason`` (None or a :data:`REASONS` key), ``direction``
        (3,) unit (a best guess, or +Z, when rejected), ``position`` (3,) or None,
        ``uncertainty_deg``, ``model``, ``spheres`` (list of per-sphere dicts: status, direction,
        uncertainty_deg, rms, model, pixel counts), ``used_spheres`` (list of int).
    """
    if model not in LIGHT_MODELS:
        raise ValueError(f"model must be one of {LIGHT_MODELS}, not {model!r}")
    img = np.asarray(image)
    n_sph = len(samples)
    need = min(2, n_sph) if min_spheres is None else int(min_spheres)
    fits = []
    for s in samples:
        px = img[s.rows, s.cols].astype(np.float64)
        valid, nsat = pixel_validity(px, saturation=saturation)
        grey = px.mean(axis=1) if px.ndim == 2 else px
        fits.append(fit_lambert(s.normals, grey, valid, n_saturated=nsat, terminator=terminator, up=up))
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
    if ev["model"] == "near":
        jf = fit_near_light([samples[i] for i in used],
                            [np.asarray(img[samples[i].rows, samples[i].cols], dtype=np.float64).mean(axis=1)
                             for i in used],
                            [fits[i].inliers | _valid_lit(fits[i]) for i in used], position,
                            terms=[(fits[i].model != "plain", fits[i].model == "bounce") for i in used],
                            terminator=terminator, up=up)
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


_W = {}


def _init_worker(capture, samples, kwargs):
    _W.update(capture=capture, samples=samples, kwargs=kwargs)


def _work(i):
    img = _W["capture"].load_image(i)
    return estimate_photo(img, _W["samples"], _W["capture"].scene_center, **_W["kwargs"])


def _record(r: dict) -> dict:
    extra = {"uncertainty_deg": float(r["uncertainty_deg"]) if np.isfinite(r["uncertainty_deg"]) else None,
             "model": r["model"], "used_spheres": r["used_spheres"], "spheres": r.get("spheres", [])}
    if "chi2" in r:
        extra.update(chi2=r["chi2"], dof=r["dof"])
    return extra


def estimate_lights(capture, spheres=None, progress: bool = True, workers: int | None = None,
                    model: str = "auto", **kwargs):
    """Estimate every photograph's light from the capture's spheres.

    Parameters
    ----------
    capture : ffls.capture.Capture
    spheres : list of SphereFit, optional
        The spheres (``center_cam`` camera frame, ``radius``); found with
        :func:`ffls.spheres.detect.find_spheres_in_capture` when None.
    progress : bool
        tqdm progress bar.
    workers : int, optional
        Processes; default every core. 1 runs in this process.
    model : {'auto', 'distant', 'near'}
    **kwargs
        Passed to :func:`estimate_photo` (``min_spheres``, ``sigma_floor_deg``, ``terminator``,
        ``saturation``).

    Returns
    -------
    ffls.capture.Lights
        Directions (world, from the scene centre), positions for near lights, status, reasons
        (:data:`REASONS`), and per light ``extra``: ``uncertainty_deg``, ``model``,
        ``used_spheres``, ``spheres`` (per-sphere direction, residual, uncertainty, pixel counts).
    """
    from ..capture import Lights

    if model not in LIGHT_MODELS:
        raise ValueError(f"model must be one of {LIGHT_MODELS}, not {model!r}")
    if capture.K is None:
        raise InputError("capture has no camera intrinsics (camera.K); light estimation needs them", capture.json_path)
    if capture.sphere_radius is None:
        raise InputError("capture has no sphere_radius; light estimation needs it", capture.json_path)
    n = len(capture.image_names)
    if n == 0:
        raise InputError("capture lists no images", capture.json_path)
    if spheres is None:
        from .detect import find_spheres_in_capture

        spheres = find_spheres_in_capture(capture)
    if model == "near" and len(spheres) < 2:
        raise InputError("model 'near' needs at least 2 spheres to triangulate the light", capture.json_path)
    if capture.image_size is not None:
        shape = (int(capture.image_size[1]), int(capture.image_size[0]))
    else:
        shape = capture.load_image(0).shape[:2]
    samples = capture_samples(capture, spheres, shape)
    kw = dict(model=model, **kwargs)
    workers = os.cpu_count() or 1 if workers is None else max(1, int(workers))
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n, desc="lights", unit="img")
    results = []
    try:
        if workers == 1 or n == 1:
            _init_worker(capture, samples, kw)
            for i in range(n):
                results.append(_work(i))
                if bar is not None:
                    bar.update(1)
        else:
            with ProcessPoolExecutor(max_workers=min(workers, n), initializer=_init_worker,
                                     initargs=(capture, samples, kw)) as ex:
                for r in ex.map(_work, range(n), chunksize=max(1, n // (8 * workers))):
                    results.append(r)
                    if bar is not None:
                        bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    dirs = np.array([normalize(r["direction"]) if np.all(np.isfinite(r["direction"])) else UP for r in results])
    pos = np.array([r["position"] if r["position"] is not None else np.full(3, np.nan) for r in results])
    return Lights(image_names=capture.image_names, directions=dirs, positions=pos,
                  status=[r["status"] for r in results], reasons=[r["reason"] for r in results],
                  extra=[_record(r) for r in results])


#: The paper's method under its name (GUIDE: one paper per function).
estimate_lights_MasselusDutreAnrys2002 = estimate_lights
