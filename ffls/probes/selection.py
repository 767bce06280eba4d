"""Model only what the scene requires: choose the number of sources or nodes from the data.

Two criteria (:func:`select_model`):

``'cv'`` (default)
    Blocked K-fold cross-validation: the pixels are grouped into spatial blocks (by the
    direction of their normal, or by their position for a cast shadow), whole blocks are held
    out, the model is fitted on the rest and scored by the relative RMS of its prediction of
    the held-out pixels. Holding out blocks (not single pixels, whose neighbours are nearly
    identical) makes an over-fitted model pay for its wild values between the data. The chosen
    candidate is the *smallest* whose score is within ``tolerance`` (relative) of the best.
``'bic'``
    The Bayesian information criterion ``m log(RSS / m) + k log m`` per channel, summed, on the
    fit to all pixels (``k`` unknowns).

:func:`select_hougen_ahuja` and :func:`select_sato_sato_ikeuchi` apply it to the two
source-based methods and return the chosen fit with the table of scores.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ffls.errors import InputError
from ffls.probes.hougen_ahuja import SourceFit, check_normals, ground_axis, hougen_ahuja, resolve_ambient
from ffls.conventions import normalize, rotation_about_axis
from ffls.probes.linear import as_rgb_pixels, broadcast_albedo
from ffls.probes.sato_sato_ikeuchi import (dome_nodes, occluder_visibility, sato_sato_ikeuchi, shadow_in_view,
                                           shadow_kernel)
from ffls.probes.sources import HOUGEN_AHUJA_SIZES, geodesic_sources

__all__ = ["Selection", "select_model", "bic", "refine_sources", "adaptive_hougen_ahuja",
           "adaptive_sato_sato_ikeuchi", "normal_blocks", "position_blocks", "select_hougen_ahuja",
           "select_sato_sato_ikeuchi", "select_regularization", "choose_weight", "CRITERIA", "REGULARIZERS",
           "WEIGHT_RULES", "ROUND_RULES", "HIERARCHY_PERIOD_DEG", "horizon_rotations", "oriented_fits"]

#: Model-selection criteria.
CRITERIA = ("cv", "bic")
#: Penalties :func:`select_regularization` chooses the weight of.
REGULARIZERS = ("energy", "smoothness", "tv", "power")
#: Rules :func:`choose_weight` applies to the held-out errors of a sweep of penalty weights.
WEIGHT_RULES = ("one_se", "paired_se", "min")
#: Rules :func:`refine_sources` applies to the held-out errors of its rounds (CV).
ROUND_RULES = ("tolerance", "paired_se")
#: Degrees: the geodesic hierarchy (:func:`ffls.probes.sources.geodesic_level`) maps onto itself when turned
#: by this much about its vertex on +Z (the icosahedron's 5-fold axis).
HIERARCHY_PERIOD_DEG = 72.0


@dataclass(frozen=True)
class Selection:
    """The outcome of a model selection.

    Attributes
    ----------
    chosen : object
        The chosen candidate.
    candidates : list
    scores : (k,) float64
        Held-out relative RMS (``'cv'``) or BIC, per candidate.
    criterion : str
    fit : object
        The chosen model fitted on all pixels (None if the caller only asked for scores).
    note : str
        One line saying what was chosen and why (for the caller to report).
    fold_errors : (k, K) float64 or None
        Held-out sum of squared errors per candidate and CV fold (:func:`select_regularization`, and
        :func:`refine_sources` with ``rule='paired_se'``; None elsewhere).
    """

    chosen: object
    candidates: list
    scores: np.ndarray
    criterion: str
    fit: object = field(default=None)
    note: str = ""
    fold_errors: np.ndarray | None = None


def normal_blocks(normals, n_blocks: int = 42) -> np.ndarray:
    """Block label (m,) of every pixel: the nearest of ~``n_blocks`` geodesic directions to its normal."""
    f = max(1, int(round(np.sqrt(max(n_blocks - 2, 10) / 10.0))))
    centres = geodesic_sources(f)
    _, lab = cKDTree(centres).query(np.asarray(normals, dtype=np.float64))
    return np.asarray(lab, dtype=np.int64)


def position_blocks(points, n_side: int = 6) -> np.ndarray:
    """Block label (m,) of every point: a ``n_side x n_side`` grid over its x-y bounding box."""
    p = np.asarray(points, dtype=np.float64)
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    q = np.clip(((p[:, :2] - lo) / np.maximum(hi - lo, 1e-300) * n_side).astype(np.int64), 0, n_side - 1)
    return q[:, 0] * n_side + q[:, 1]


def select_model(fit_predict, candidates, data, n_params=None, criterion: str = "cv", folds: int = 5,
                 blocks=None, tolerance: float = 0.05, seed: int = 0) -> Selection:
    """Choose among ``candidates`` (ordered from simplest to richest) by CV or BIC.

    Parameters
    ----------
    fit_predict : callable
        ``fit_predict(candidate, train_index, test_index) -> (len(test_index), c)`` predictions
        of the data at ``test_index`` from a model fitted on ``train_index``. For ``'bic'`` it is
        called with ``train_index = test_index = all``.
    candidates : sequence
        From simplest to richest.
    data : (m, c) array_like
        The observations.
    n_params : callable, optional
        ``n_params(candidate) -> int`` (``'bic'`` only).
    criterion : {'cv', 'bic'}
    folds : int
        CV folds (over blocks).
    blocks : (m,) array_like of int, optional
        Spatial block of every pixel; random single-pixel folds without it.
    tolerance : float
        CV: the smallest candidate within ``(1 + tolerance)`` x the best score wins.
    seed : int

    Returns
    -------
    Selection
        ``fit`` is None (the wrappers fill it).
    """
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, not {criterion!r}")
    y = np.asarray(data, dtype=np.float64)
    if y.ndim == 1:
        y = y[:, None]
    m = y.shape[0]
    cands = list(candidates)
    if not cands:
        raise ValueError("no candidates")
    rng = np.random.default_rng(seed)
    scores = np.full(len(cands), np.inf)
    if criterion == "cv":
        fold, k, n_blocks = _cv_folds(m, blocks, folds, rng)
        for ci, c in enumerate(cands):
            scores[ci] = _cv_score(fit_predict, c, fold, k, y)
        best = np.nanmin(scores)
        if not np.isfinite(best):
            raise InputError("no candidate model could be fitted on the cross-validation folds")
        chosen_i = int(np.flatnonzero(scores <= best * (1.0 + tolerance))[0])
        note = (f"cross-validation ({k} folds over {n_blocks} blocks) chose {cands[chosen_i]!r}: held-out "
                f"relative RMS {scores[chosen_i]:.4f} (best {best:.4f}, tolerance {tolerance:.0%})")
    else:
        if n_params is None:
            raise ValueError("BIC needs n_params")
        idx = np.arange(m)
        for ci, c in enumerate(cands):
            try:
                pred = fit_predict(c, idx, idx)
            except InputError:
                continue
            scores[ci] = bic(pred, y, n_params(c))
        if not np.isfinite(scores).any():
            raise InputError("no candidate model could be fitted")
        chosen_i = int(np.argmin(scores))
        note = f"BIC chose {cands[chosen_i]!r} (BIC {scores[chosen_i]:.1f})"
    return Selection(chosen=cands[chosen_i], candidates=cands, scores=scores, criterion=criterion, note=note)


def _cv_folds(m: int, blocks, folds: int, rng) -> tuple[np.ndarray, int, int]:
    """Fold (m,) of every pixel (whole blocks per fold), the number of folds and of blocks."""
    lab = np.arange(m) if blocks is None else np.asarray(blocks, dtype=np.int64)
    ub = np.unique(lab)
    k = min(int(folds), ub.size)
    if k < 2:
        raise InputError("cross-validation needs at least two blocks of pixels")
    fold_of_block = rng.permutation(ub.size) % k
    return fold_of_block[np.searchsorted(ub, lab)], k, int(ub.size)


def _cv_fold_errors(fit_predict, c, fold, k: int, y) -> np.ndarray:
    """Held-out sum of squared errors (k,) of candidate ``c`` per fold (inf if a fold cannot be fitted)."""
    err = np.full(k, np.inf)
    try:
        for f in range(k):
            test = np.flatnonzero(fold == f)
            train = np.flatnonzero(fold != f)
            pred = fit_predict(c, train, test)
            err[f] = float(np.sum((pred - y[test]) ** 2))
    except InputError:
        return np.full(k, np.inf)  # this candidate cannot be fitted on a fold: not a choice
    return err


def _relative_rms(sse: float, y) -> float:
    """Held-out relative RMS of a total squared error ``sse`` over the data ``y``."""
    return float(np.sqrt(sse / y.size) / max(float(np.sqrt(np.mean(y ** 2))), 1e-300))


def _cv_score(fit_predict, c, fold, k: int, y) -> float:
    """Held-out relative RMS of candidate ``c`` over the folds (inf if a fold cannot be fitted)."""
    return _relative_rms(float(np.sum(_cv_fold_errors(fit_predict, c, fold, k, y))), y)


def bic(predicted, data, n_params: int) -> float:
    """The Bayesian information criterion ``m log(RSS / m) + k log m`` per channel, summed.

    Parameters
    ----------
    predicted, data : (m, c) array_like
    n_params : int
        Unknowns of the model (``k``).

    Returns
    -------
    float
    """
    y = np.asarray(data, dtype=np.float64)
    y = y[:, None] if y.ndim == 1 else y
    pred = np.asarray(predicted, dtype=np.float64).reshape(y.shape)
    m = y.shape[0]
    rss = np.maximum(np.sum((pred - y) ** 2, axis=0), 1e-300)
    return float(np.sum(m * np.log(rss / m) + int(n_params) * np.log(m)))


def _fill(sel: Selection, fit) -> Selection:
    return Selection(chosen=sel.chosen, candidates=sel.candidates, scores=sel.scores, criterion=sel.criterion,
                     fit=fit, note=sel.note)


def select_hougen_ahuja(normals, radiance, albedo=1.0, candidates=(5, 9, 17, 42, 92, 162, 252), criterion: str = "cv",
                        folds: int = 5, tolerance: float = 0.05, seed: int = 0, **kwargs) -> Selection:
    """Hougen-Ahuja with the number of model sources chosen from the data.

    Parameters
    ----------
    normals, radiance, albedo
        As :func:`ffls.probes.hougen_ahuja.hougen_ahuja` (albedo a scalar or (3,)).
    candidates : sequence of int
        Source-set sizes, simplest first.
    criterion, folds, tolerance, seed
        As :func:`select_model`; CV blocks group the pixels by normal direction.
    **kwargs
        Passed to :func:`~ffls.probes.hougen_ahuja.hougen_ahuja` (``nonnegative``, ``ambient``,
        ``smoothness``, ``rcond``...).

    Returns
    -------
    Selection
        ``fit`` is the chosen :class:`SourceFit` on all pixels; ``chosen`` the size.
    """
    n = check_normals(normals)
    b = as_rgb_pixels(radiance, n.shape[0])

    full = {}  # fits on every pixel (BIC's), reused for the chosen model

    def fp(c, train, test):
        fit = hougen_ahuja(n[train], b[train], albedo, int(c), **kwargs)
        if train.size == n.shape[0]:
            full[c] = fit
        rho = np.broadcast_to(np.asarray(albedo, dtype=np.float64), (3,))
        return fit.irradiance(n[test]) * rho / np.pi

    def k_of(c):  # the ring sets (5, 9, 17) cover a hemisphere: 'auto' keeps their ambient
        dom = "upper" if int(c) in HOUGEN_AHUJA_SIZES else kwargs.get("hemisphere", "full")
        return int(c) + (1 if resolve_ambient(kwargs.get("ambient", True), kwargs.get("nonnegative", False), dom)
                         else 0)

    sel = select_model(fp, candidates, b, k_of, criterion, folds, normal_blocks(n), tolerance, seed)
    fit = full.get(sel.chosen)
    return _fill(sel, fit if fit is not None else hougen_ahuja(n, b, albedo, int(sel.chosen), **kwargs))


def _sato_predictor(p, b, occluder, plane_normal, kwargs):
    """``predict(d, V, train, test) -> (fit on train, prediction at test)`` for Sato-Sato-Ikeuchi."""
    m = p.shape[0]

    def split(idx):
        out = {}
        for k, v in kwargs.items():
            a = np.asarray(v) if isinstance(v, (list, tuple, np.ndarray)) else None
            out[k] = a[idx] if a is not None and a.ndim >= 1 and a.shape[0] == m and m > 3 else v
        return out

    def predict(d, V, train, test):
        fit = sato_sato_ikeuchi(p[train], b[train], occluder, plane_normal, d, visibility=V[train], **split(train))
        if np.array_equal(train, test):
            return fit, fit.rendered
        kw = split(test)
        case = kw.get("case", "lambertian")
        K = shadow_kernel(d, V[test], plane_normal, case, kw.get("albedo", 1.0), kw.get("view_dirs"), kw.get("specular"))
        E = fit.intensities
        if case == "ratio":
            s_all = as_rgb_pixels(kwargs["surface_radiance"], m, "surface image")
            e0 = np.pi * np.mean(s_all[train], axis=0) / float(kwargs.get("reference_albedo", 1.0))
            return fit, np.einsum("xnc,nc->xc", K, E / e0) * s_all[test]
        return fit, np.einsum("xnc,nc->xc", K, E)

    return predict


def select_sato_sato_ikeuchi(points, radiance, occluder, plane_normal=(0.0, 0.0, 1.0),
                             candidates=(46, 91, 126, 196, 246, 341, 526), criterion: str = "cv", folds: int = 5,
                             tolerance: float = 0.05, seed: int = 0, **kwargs) -> Selection:
    """Sato-Sato-Ikeuchi with the number of dome nodes chosen from the data.

    Parameters
    ----------
    points, radiance, occluder, plane_normal
        As :func:`ffls.probes.sato_sato_ikeuchi.sato_sato_ikeuchi`.
    candidates : sequence of int
        Dome sizes, simplest first.
    criterion, folds, tolerance, seed
        As :func:`select_model`; CV blocks are a 6 x 6 grid over the receiver.
    **kwargs
        Passed on (``case``, ``albedo``, ``surface_radiance``, ``view_dirs``, ``specular``...).
        Per-pixel arrays among them are split with the pixels.

    Returns
    -------
    Selection
    """
    p = np.asarray(points, dtype=np.float64)
    b = as_rgb_pixels(radiance, p.shape[0])
    m = p.shape[0]
    vis = {}

    def nodes_of(c):
        if c not in vis:
            d = dome_nodes(int(c), plane_normal)
            vis[c] = (d, occluder_visibility(p, d, occluder))
        return vis[c]

    full = {}  # fits on every pixel (BIC's), reused for the chosen model
    predict = _sato_predictor(p, b, occluder, plane_normal, kwargs)

    def fp(c, train, test):
        d, V = nodes_of(c)
        fit, pred = predict(d, V, train, test)
        if train.size == m:
            full[c] = fit
        return pred

    def k_of(c):
        return int(nodes_of(c)[0].shape[0])

    sel = select_model(fp, candidates, b, k_of, criterion, folds, position_blocks(p), tolerance, seed)
    d, V = nodes_of(sel.chosen)
    fit: SourceFit | None = full.get(sel.chosen)
    if fit is None:
        fit = sato_sato_ikeuchi(p, b, occluder, plane_normal, d, visibility=V, **kwargs)
    return _fill(sel, fit)


def refine_sources(fit_all, score, base_frequency: int = 3, hemisphere="full", max_sources: int = 500,
                   max_level: int = 3, power_share: float = 0.5, patience: int = 2, criterion: str = "cv",
                   tolerance: float = 0.05, can_split=None, rule: str = "tolerance") -> Selection:
    """Adaptive source sets: refine the geodesic hierarchy where the recovered light is, stop by CV or BIC.

    Start from level 0 of the hierarchy (:func:`ffls.probes.sources.geodesic_level`). Each round
    fits every pixel, scores the fit, and splits (:func:`ffls.probes.sources.split_sources`) the
    fewest sources that together carry ``power_share`` of the recovered power (among those not
    yet at ``max_level``): a small bright light gets cells a few degrees wide while the rest of
    the sky stays coarse, which a uniform set of the same size cannot do (``docs/probes.md``
    measures the floors). The rounds stop when the score has not improved for ``patience``
    rounds, when nothing is left to split, or at ``max_sources``; the chosen round is the one
    :func:`select_model` would choose among them (CV: the smallest within ``tolerance`` of the
    best, or with ``rule='paired_se'`` within one paired standard error; BIC: the lowest).

    Parameters
    ----------
    fit_all : callable
        ``fit_all(directions) -> SourceFit`` on all pixels.
    score : callable
        ``score(directions, fit) -> float``, lower is better (held-out relative RMS, or BIC).
    base_frequency : int
        Frequency of level 0 (3: 92 directions on the sphere, 46 on a dome).
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}
    max_sources : int
        No round grows the set past this (the issue's "geodesic sets up to about 500").
    max_level : int
        Levels of splitting (3 from frequency 3: nodes 2.6 degrees apart at the finest, about a
        texel of a 64-row map).
    power_share : float
        In (0, 1]: the share of the recovered power split each round (0.5: the number of rounds
        grows with the log of the number of lights, not their count).
    patience : int
        Rounds without a better score before stopping (2: a split can help only once the next
        level of the same light is split too).
    criterion : {'cv', 'bic'}
        How the round is chosen from the scores.
    tolerance : float
        CV's tolerance.
    can_split : callable, optional
        ``can_split(directions) -> (n,) bool``: sources the data can resolve finer (for a cast
        shadow, :func:`ffls.probes.sato_sato_ikeuchi.shadow_in_view`); the others are never split.
    rule : {'tolerance', 'paired_se'}
        CV only. ``'tolerance'`` (default): the smallest round whose held-out relative RMS is
        within ``(1 + tolerance)`` of the best. ``'paired_se'``: the smallest round whose excess
        over the best is within one standard error of that excess, from the paired differences of
        the ``K`` folds' held-out errors (:func:`choose_weight`'s rule, the rounds taken from the
        richest). ``score`` must then return ``(score, (K,) held-out squared errors per fold)``.
        A relative tolerance is a tolerance on the noise too: with 1% noise the held-out error is
        mostly the noise, every round past the first few is within 5% of the best, and the
        smallest of them is too coarse for a lamp (``docs/probes.md``, *Choosing with paired
        folds*); the paired differences cancel the noise that all rounds share.

    Returns
    -------
    Selection
        ``chosen`` and ``candidates`` are source counts (one per round), ``fit`` the chosen round's fit;
        ``fold_errors`` the ``(rounds, K)`` held-out squared errors with ``rule='paired_se'``.
    """
    from ffls.probes.sources import geodesic_level, split_sources

    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, not {criterion!r}")
    if not 0.0 < float(power_share) <= 1.0:
        raise ValueError(f"power_share must be in (0, 1], not {power_share!r}")
    if rule not in ROUND_RULES or rule != "tolerance" and criterion != "cv":
        raise ValueError(f"rule must be one of {ROUND_RULES} ('paired_se' with criterion 'cv'), not {rule!r}")
    paired = rule == "paired_se"
    d = np.array(geodesic_level(base_frequency, 0, hemisphere))
    lev = np.zeros(d.shape[0], dtype=np.int64)
    fits, scores, folds = [], [], []
    best, since = np.inf, 0
    while True:
        try:
            fit = fit_all(d)
        except InputError:
            if not fits:
                raise
            break  # the finer set cannot be fitted (too few pixels for it): the coarser ones stand
        sc = score(d, fit)
        if paired:
            sc, fe = sc
            folds.append(np.asarray(fe, dtype=np.float64))
        sc = float(sc)
        fits.append(fit)
        scores.append(sc)
        if sc < best:
            best, since = sc, 0
        else:
            since += 1
            if since >= patience:
                break
        w = np.abs(np.asarray(fit.intensities, dtype=np.float64)).sum(axis=1)
        w[lev >= int(max_level)] = 0.0
        if can_split is not None:
            w[~np.asarray(can_split(d), dtype=bool)] = 0.0
        if not np.any(w > 0):
            break
        order = np.argsort(-w, kind="stable")
        order = order[w[order] > 0]
        k = int(np.searchsorted(np.cumsum(w[order]) / w[order].sum(), float(power_share) - 1e-12)) + 1
        k = min(k, order.size)
        while k >= 1:
            d2, lev2 = split_sources(d, lev, order[:k], base_frequency, hemisphere)
            if d2.shape[0] <= int(max_sources):
                break
            k //= 2
        if k < 1:
            break
        d, lev = d2, lev2
    s = np.asarray(scores)
    sizes = [int(f.directions.shape[0]) for f in fits]
    fold_errors = None
    if paired:  # choose_weight takes the last within: the rounds from the richest, the smallest within last
        fold_errors = np.stack(folds)
        i = len(fits) - 1 - choose_weight(fold_errors[::-1], "paired_se")[0]
        note = (f"adaptive sources, cross-validation over {len(fits)} refinements ({sizes[0]}..{max(sizes)} sources) "
                f"chose {sizes[i]}: held-out relative RMS {s[i]:.4f} (best {np.min(s):.4f}, within one paired "
                f"standard error)")
    elif criterion == "cv":
        i = int(np.flatnonzero(s <= np.min(s) * (1.0 + tolerance))[0])
        note = (f"adaptive sources, cross-validation over {len(fits)} refinements ({sizes[0]}..{max(sizes)} sources) "
                f"chose {sizes[i]}: held-out relative RMS {s[i]:.4f} (best {np.min(s):.4f}, tolerance {tolerance:.0%})")
    else:
        i = int(np.argmin(s))
        note = f"adaptive sources, BIC over {len(fits)} refinements ({sizes[0]}..{max(sizes)} sources) chose {sizes[i]}"
    return Selection(chosen=sizes[i], candidates=sizes, scores=s, criterion=criterion, fit=fits[i], note=note,
                     fold_errors=fold_errors)


def _base_frequency(base_frequency: int, m: int, hemisphere, extra: int) -> int:
    """The largest frequency up to ``base_frequency`` whose level 0 leaves a CV fold (4/5 of the
    ``m`` pixels) more pixels than unknowns (1 at least: the icosahedron)."""
    from ffls.probes.sources import geodesic_level

    f = max(int(base_frequency), 1)
    while f > 1 and geodesic_level(f, 0, hemisphere).shape[0] + extra > 0.8 * m:
        f -= 1
    return f


def _scorer(criterion, fit_predict, data, blocks, folds, seed, extra_params, per_fold: bool = False):
    """``score(directions, fit)`` for :func:`refine_sources`: CV on fixed folds, or BIC. ``per_fold`` (CV
    only): the pair ``(held-out relative RMS, (K,) held-out squared errors per fold)``, which
    :func:`refine_sources`' paired rule needs."""
    if criterion == "bic":
        return lambda d, fit: bic(fit.rendered, data, d.shape[0] + extra_params)
    fold, k, _ = _cv_folds(data.shape[0], blocks, folds, np.random.default_rng(seed))
    if not per_fold:
        return lambda d, fit: _cv_score(fit_predict, d, fold, k, data)

    def score(d, fit):
        e = _cv_fold_errors(fit_predict, d, fold, k, data)
        return _relative_rms(float(np.sum(e)), data), e

    return score


def adaptive_hougen_ahuja(normals, radiance, albedo=1.0, base_frequency: int = 3, max_sources: int = 500,
                          max_level: int = 3, criterion: str = "cv", folds: int = 5, tolerance: float = 0.05,
                          seed: int = 0, power_share: float = 0.5, patience: int = 2, orientations: int = 1,
                          orientation_seed: int = 0, ground=None, rule: str = "tolerance", **kwargs) -> Selection:
    """Hougen-Ahuja over an adaptive geodesic source set (:func:`refine_sources`).

    Parameters
    ----------
    normals, radiance, albedo
        As :func:`ffls.probes.hougen_ahuja.hougen_ahuja`.
    base_frequency, max_sources, max_level, power_share, patience
        As :func:`refine_sources` (the sources cover the whole sphere). With few pixels the base
        frequency is lowered until a CV fold (4/5 of the pixels) holds more pixels than unknowns.
    criterion, folds, tolerance, seed
        As :func:`select_model`; CV blocks group the pixels by normal direction.
    rule : {'tolerance', 'paired_se'}
        How CV chooses the round (:func:`refine_sources`): within ``tolerance`` of the best
        (default), or within one paired standard error (``docs/probes.md``, *Choosing with paired
        folds*).
    orientations : int
        1 (default): the geodesic hierarchy in its own orientation (a vertex on +Z). ``K > 1``: the
        whole estimate (refinement and choice) is made ``K`` times, the hierarchy turned by ``K``
        rotations (the first the identity, the others uniformly random from ``orientation_seed``),
        and the fits are averaged (:func:`ffls.probes.hougen_ahuja.average_fits`). Which
        non-negative map NNLS returns among those that fit the ball depends on where the sources
        lie, not on the data (``docs/probes.md``, *The orientation of the source set*); the average
        removes that part of the error for spread light (night), but turned sets can move lamps a few
        degrees above the horizon below it (studio), and it costs ``K`` estimates: an option, not
        the default. With ``ground`` the rotations are about the plane's normal (uniformly random
        azimuths), which keeps the sources above the plane.
    orientation_seed : int
        Seed of the random rotations.
    ground : (3,) array_like, optional
        The normal (up) of a ground plane: the hierarchy is a dome over it (a vertex on the normal)
        and the light from below it one uniform term (:func:`~ffls.probes.hougen_ahuja.hougen_ahuja`'s
        ``ground``). The dome is fixed by the plane up to an azimuth, and a lamp just above the
        horizon cannot move below it (``docs/probes.md``, *A ground plane*).
    **kwargs
        Passed to :func:`~ffls.probes.hougen_ahuja.hougen_ahuja` (``nonnegative``, ``ambient``...).

    Returns
    -------
    Selection
        ``chosen`` is the number of sources; ``fit.directions`` the adaptive set. With
        ``orientations > 1``: ``chosen`` is the tuple of the members' sizes, ``candidates`` their
        rounds' sizes (one list per member), ``scores`` the score of each member's chosen round and
        ``fit`` a
        :class:`~ffls.probes.hougen_ahuja.SourceEnsemble`.
    """
    n = check_normals(normals)
    b = as_rgb_pixels(radiance, n.shape[0])
    rho = broadcast_albedo(albedo, n.shape[0])  # (m, 3): per-pixel albedo is split with the pixels
    k_or = int(orientations)
    if k_or != orientations or k_or < 1:
        raise ValueError(f"orientations must be an integer >= 1, not {orientations!r}")
    if k_or > 1:
        return _oriented_ensemble(normals, radiance, albedo, n, k_or, orientation_seed, dict(
            base_frequency=base_frequency, max_sources=max_sources, max_level=max_level, criterion=criterion,
            folds=folds, tolerance=tolerance, seed=seed, power_share=power_share, patience=patience,
            ground=ground, rule=rule, **kwargs))
    dom = "full"
    if ground is not None:
        kwargs["ground"] = ground_axis(ground)
        dom = {"axis": [float(v) for v in kwargs["ground"]]}
        if kwargs.get("ambient", True) == "auto":
            kwargs["ambient"] = False  # the dome and the ground hold any uniform light

    def fp(d, train, test):
        fit = hougen_ahuja(n[train], b[train], rho[train], d, **kwargs)
        return fit.irradiance(n[test]) * rho[test] / np.pi

    extra = 1 if resolve_ambient(kwargs.get("ambient", True), kwargs.get("nonnegative", False), "full") else 0
    extra += 0 if ground is None else 1
    score = _scorer(criterion, fp, b, normal_blocks(n), folds, seed, extra, per_fold=rule == "paired_se")
    base_frequency = _base_frequency(base_frequency, n.shape[0], dom, extra)
    return refine_sources(lambda d: hougen_ahuja(n, b, rho, d, **kwargs), score, base_frequency, dom,
                          max_sources, max_level, power_share, patience, criterion, tolerance, rule=rule)


def horizon_rotations(up, k: int) -> np.ndarray:
    """The ``k`` orientations of the geodesic hierarchy that share its layout about the horizon.

    Each puts the hierarchy's vertex (its own +Z) on ``up`` and turns it about ``up`` by ``i`` of ``k``
    equal steps of :data:`HIERARCHY_PERIOD_DEG`, the period of its symmetry about that vertex: the
    sources' elevations above and below the horizon are the same in every member, only their azimuths
    change, and ``k`` members sample the azimuths evenly. With ``up`` the world's +Z the first is the
    identity (the hierarchy's own orientation, to the last bit).

    Parameters
    ----------
    up : (3,) array_like
        The world's up (the normal of the horizon plane); non-zero.
    k : int
        ``>= 1``.

    Returns
    -------
    (k, 3, 3) float64
        Rotations ``R`` in :func:`oriented_fits`' convention (the pixels turned by ``R``, the sources
        found in the turned frame turned back by ``R^T``).
    """
    from ffls.probes.sources import frame_to_axis

    k = int(k)
    if k < 1:
        raise ValueError(f"the number of azimuths must be >= 1, not {k!r}")
    F = frame_to_axis(ground_axis(up))
    return np.stack([(F @ rotation_about_axis((0.0, 0.0, 1.0), HIERARCHY_PERIOD_DEG * i / k)).T
                     for i in range(k)])


def oriented_fits(normals, rotations, estimate, turned_from=None) -> tuple[list, list]:
    """An estimate made in several orientations of its source set, each fit turned back into the world.

    Parameters
    ----------
    normals : (m, 3) array_like
        Unit world-frame normals.
    rotations : (k, 3, 3) array_like
        The source hierarchy fixed, the pixels turned by ``R`` (``normals @ R.T``): the sources ``d'``
        the estimate finds are the world's ``R^T d'``. An identity gets ``normals`` as given (NNLS
        can return another of its equally good vertices after a change in the last bits).
    estimate : callable
        ``estimate(turned_normals) -> (fit, selection)``: a :class:`SourceFit` in the turned frame and
        whatever the caller wants back with it.
    turned_from : (m, 3) array_like, optional
        The normals the rotations other than the identity turn (default ``normals``; the same
        directions, for example re-normalised).

    Returns
    -------
    fits : list of SourceFit
        In the world frame.
    selections : list
        The estimate's second outputs.
    """
    import dataclasses

    check_normals(normals)
    n = np.asarray(normals if turned_from is None else turned_from, dtype=np.float64)
    fits, sels = [], []
    for R in np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3):
        same = np.array_equal(R, np.eye(3))
        fit, sel = estimate(normals if same else n @ R.T)
        fits.append(fit if same else dataclasses.replace(fit, directions=normalize(fit.directions @ R)))
        sels.append(sel)
    return fits, sels


def _oriented_ensemble(normals, radiance, albedo, n, k: int, seed: int, kwargs: dict) -> Selection:
    """:func:`adaptive_hougen_ahuja` in ``k`` orientations of the source hierarchy, averaged (``n``: the
    checked normals; the first member is the plain estimate to the last bit)."""
    from scipy.spatial.transform import Rotation

    from ffls.probes.hougen_ahuja import average_fits

    up = kwargs.get("ground")
    if up is None:
        rots = Rotation.random(k, random_state=int(seed)).as_matrix()
    else:  # about the plane's normal: the dome stays over the plane
        up = ground_axis(up)
        az = np.random.default_rng(int(seed)).uniform(0.0, 360.0, k)
        rots = np.stack([rotation_about_axis(up, a) for a in az])
    rots[0] = np.eye(3)

    def one(turned):
        sel = adaptive_hougen_ahuja(turned, radiance, albedo, **kwargs)
        return sel.fit, sel

    fits, sels = oriented_fits(normals, rots, one, turned_from=n)
    sizes = tuple(int(s.chosen) for s in sels)
    note = (f"adaptive sources in {k} orientations of the geodesic hierarchy (the first its own, the others "
            f"random), averaged: {', '.join(map(str, sizes))} sources chosen ({sels[0].note})")
    scores = np.array([float(s.scores[list(s.candidates).index(s.chosen)]) for s in sels])
    return Selection(chosen=sizes, candidates=[s.candidates for s in sels], scores=scores,
                     criterion=sels[0].criterion, fit=average_fits(fits, radiance), note=note)


def adaptive_sato_sato_ikeuchi(points, radiance, occluder, plane_normal=(0.0, 0.0, 1.0), base_frequency: int = 3,
                               max_sources: int = 526, max_level: int = 3, criterion: str = "cv", folds: int = 5,
                               tolerance: float = 0.05, seed: int = 0, power_share: float = 0.5, patience: int = 2,
                               resolved_only: bool = True, **kwargs) -> Selection:
    """Sato-Sato-Ikeuchi over an adaptive geodesic dome (:func:`refine_sources`).

    Each node's shadow (its visibility from every pixel) is traced once, when the node first
    appears. Only nodes whose whole shadow falls in view are split
    (:func:`ffls.probes.sato_sato_ikeuchi.shadow_in_view`): a node low over the horizon casts a
    shadow longer than the view, whose far end (its elevation) the photograph does not show, and
    finer nodes there only trade elevation against intensity.

    Parameters
    ----------
    points, radiance, occluder, plane_normal
        As :func:`ffls.probes.sato_sato_ikeuchi.sato_sato_ikeuchi`.
    base_frequency, max_sources, max_level, power_share, patience
        As :func:`refine_sources`, over the dome around ``plane_normal`` (level 0, frequency 3:
        46 nodes, lowered for few pixels as in :func:`adaptive_hougen_ahuja`; the default
        ``max_sources`` is the paper's dome size).
    criterion, folds, tolerance, seed
        As :func:`select_model`; CV blocks are a 6 x 6 grid over the receiver.
    resolved_only : bool
        Split only nodes whose whole shadow is in view (default); False splits any.
    **kwargs
        Passed on (``case``, ``albedo``, ``surface_radiance``...).

    Returns
    -------
    Selection
    """
    p = np.asarray(points, dtype=np.float64)
    b = as_rgb_pixels(radiance, p.shape[0])
    hemi = {"axis": [float(v) for v in normalize(np.asarray(plane_normal, dtype=np.float64).reshape(3))]}
    cols: dict = {}

    def vis_of(d):
        keys = [tuple(k) for k in np.round(d * 1e9).astype(np.int64)]
        missing = [i for i, k in enumerate(keys) if k not in cols]
        if missing:
            V = np.asarray(occluder_visibility(p, d[missing], occluder))
            for j, i in enumerate(missing):
                cols[keys[i]] = V[:, j]
        return np.stack([cols[k] for k in keys], axis=1)

    predict = _sato_predictor(p, b, occluder, plane_normal, kwargs)

    def fp(d, train, test):
        return predict(d, vis_of(d), train, test)[1]

    def fit_all(d):
        return sato_sato_ikeuchi(p, b, occluder, plane_normal, d, visibility=vis_of(d), **kwargs)

    score = _scorer(criterion, fp, b, position_blocks(p), folds, seed, 0)
    base_frequency = _base_frequency(base_frequency, p.shape[0], hemi, 0)
    can_split = (lambda d: shadow_in_view(p, d, occluder, plane_normal)) if resolved_only else None
    return refine_sources(fit_all, score, base_frequency, hemi, max_sources, max_level, power_share, patience,
                          criterion, tolerance, can_split)


def choose_weight(fold_errors, rule: str = "one_se") -> tuple[int, int]:
    """Choose a penalty weight from its held-out errors on the same CV folds.

    Parameters
    ----------
    fold_errors : (w, K) array_like
        Held-out sum of squared errors of each of ``w`` weights (least regularised first) on
        each of ``K`` folds; a weight that could not be fitted has ``inf`` in its row.
    rule : {'one_se', 'paired_se', 'min'}
        ``'min'``: the lowest total. ``'one_se'``: the largest weight whose total is within one
        standard error of the lowest, that error taken as the spread of the best weight's own fold
        errors (``sqrt(K)`` times their standard deviation, the standard error of a sum of ``K``
        independent terms). ``'paired_se'``: the largest weight whose excess over the lowest total
        is within one standard error *of that excess*, estimated from the ``K`` paired fold
        differences (``sqrt(K)`` times their standard deviation). All weights are scored on the same
        folds, so what a fold holds (how many pixels, how bright, how hard to predict) is common to
        them and cancels in their difference; ``'one_se'`` counts it as uncertainty about the
        difference and so accepts weights the folds consistently reject.

    Returns
    -------
    chosen, best : int
        Index of the chosen weight and of the lowest total.
    """
    if rule not in WEIGHT_RULES:
        raise ValueError(f"rule must be one of {WEIGHT_RULES}, not {rule!r}")
    S = np.asarray(fold_errors, dtype=np.float64)
    if S.ndim != 2 or S.shape[1] < 2:
        raise ValueError(f"fold_errors must be (weights, folds) with 2 folds at least, not {S.shape}")
    total = S.sum(axis=1)
    if not np.isfinite(total).any():
        raise InputError("no penalty weight could be fitted on the cross-validation folds")
    best = int(np.nanargmin(np.where(np.isfinite(total), total, np.nan)))
    if rule == "min":
        return best, best
    k = S.shape[1]
    if rule == "one_se":
        within = total <= total[best] + np.sqrt(k) * np.std(S[best], ddof=1)
    else:
        with np.errstate(invalid="ignore"):
            D = S - S[best]
            within = np.isfinite(total) & (D.sum(axis=1) <= np.sqrt(k) * np.std(D, axis=1, ddof=1))
    return int(np.flatnonzero(within)[-1]), best


def select_regularization(normals, radiance, albedo, directions, weights=(0.0, 0.001, 0.003, 0.01, 0.03),
                          penalty: str = "energy", rule: str = "one_se", folds: int = 5, seed: int = 0,
                          **kwargs) -> Selection:
    """Choose the weight of a Hougen-Ahuja penalty on a fixed source set by blocked cross-validation.

    A diffuse object sees only the low orders of its lighting, so many maps fit its pixels; NNLS
    returns a vertex of that set. A penalty (``'energy'``: minimum squared radiance;
    ``'smoothness'``: first differences between neighbouring sources; ``'tv'``: their absolute values,
    total variation; all of
    :func:`ffls.probes.hougen_ahuja.hougen_ahuja`) picks another member of it. Its weight is
    chosen from the data: every weight is fitted on the blocked folds of :func:`select_model`
    (pixels grouped by normal) and scored by the squared error of its prediction of the held-out
    pixels.

    Parameters
    ----------
    normals, radiance, albedo
        As :func:`ffls.probes.hougen_ahuja.hougen_ahuja`.
    directions : (n, 3) array_like
        The source set (for example ``adaptive_hougen_ahuja(...).fit.directions``).
    weights : sequence of float
        Candidate weights, 0 (the plain fit) first, increasing.
    penalty : {'energy', 'smoothness', 'tv'}
    rule : {'one_se', 'paired_se', 'min'}
        :func:`choose_weight`. ``'min'``: the weight with the lowest held-out error. ``'one_se'``
        (default): the largest weight whose held-out error is within one standard error of the
        lowest (the standard error of a sum of ``K`` fold errors, ``sqrt(K)`` times their standard
        deviation): the most regularised map the held-out pixels cannot tell from the best.
        ``'paired_se'``: the same with the standard error of the paired fold differences.
    folds, seed
        As :func:`select_model`.
    **kwargs
        Passed to :func:`~ffls.probes.hougen_ahuja.hougen_ahuja` (``nonnegative``, ``ambient``).

    Returns
    -------
    Selection
        ``chosen`` is the weight, ``scores`` the held-out relative RMS per weight, ``fit`` the fit
        on all pixels with the chosen weight, ``fold_errors`` the held-out squared errors per
        weight and fold.
    """
    if penalty not in REGULARIZERS:
        raise ValueError(f"penalty must be one of {REGULARIZERS}, not {penalty!r}")
    if rule not in WEIGHT_RULES:
        raise ValueError(f"rule must be one of {WEIGHT_RULES}, not {rule!r}")
    w = [float(x) for x in weights]
    if not w or any(not np.isfinite(x) or x < 0 for x in w) or any(b <= a for a, b in zip(w, w[1:])):
        raise ValueError(f"weights must be finite, >= 0 and increasing, not {weights!r}")
    n = check_normals(normals)
    b = as_rgb_pixels(radiance, n.shape[0])
    rho = broadcast_albedo(albedo, n.shape[0])
    d = normalize(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
    fold, k, n_blocks = _cv_folds(n.shape[0], normal_blocks(n), folds, np.random.default_rng(seed))
    sse = np.full((len(w), k), np.inf)
    for i, lam in enumerate(w):
        try:
            for f in range(k):
                test, train = fold == f, fold != f
                fit = hougen_ahuja(n[train], b[train], rho[train], d, **{penalty: lam}, **kwargs)
                E = fit.irradiance(n[test])
                sse[i, f] = float(np.sum((E * rho[test] / np.pi - b[test]) ** 2))
        except InputError:
            continue  # this weight cannot be fitted on a fold: not a choice
    total = sse.sum(axis=1)
    chosen, best = choose_weight(sse, rule)
    ref = max(float(np.sqrt(np.mean(b ** 2))), 1e-300)
    scores = np.sqrt(total / b.size) / ref
    note = (f"{penalty} penalty: cross-validation ({k} folds over {n_blocks} blocks, rule {rule}) chose weight "
            f"{w[chosen]:g}: held-out relative RMS {scores[chosen]:.4f} (lowest {scores[best]:.4f} at {w[best]:g})")
    fit = hougen_ahuja(n, b, rho, d, **{penalty: w[chosen]}, **kwargs)
    return Selection(chosen=w[chosen], candidates=w, scores=scores, criterion="cv", fit=fit, note=note,
                     fold_errors=sse)
