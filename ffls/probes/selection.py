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
from ffls.probes.hougen_ahuja import SourceFit, check_normals, hougen_ahuja
from ffls.probes.linear import as_rgb_pixels
from ffls.probes.sato_sato_ikeuchi import dome_nodes, occluder_visibility, sato_sato_ikeuchi, shadow_kernel
from ffls.probes.sources import geodesic_sources

__all__ = ["Selection", "select_model", "normal_blocks", "position_blocks", "select_hougen_ahuja",
           "select_sato_sato_ikeuchi", "CRITERIA"]

#: Model-selection criteria.
CRITERIA = ("cv", "bic")


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
    """

    chosen: object
    candidates: list
    scores: np.ndarray
    criterion: str
    fit: object = field(default=None)
    note: str = ""


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
        lab = np.arange(m) if blocks is None else np.asarray(blocks, dtype=np.int64)
        ub = np.unique(lab)
        k = min(int(folds), ub.size)
        if k < 2:
            raise InputError("cross-validation needs at least two blocks of pixels")
        fold_of_block = rng.permutation(ub.size) % k
        fold = fold_of_block[np.searchsorted(ub, lab)]
        for ci, c in enumerate(cands):
            err = 0.0
            try:
                for f in range(k):
                    test = np.flatnonzero(fold == f)
                    train = np.flatnonzero(fold != f)
                    pred = fit_predict(c, train, test)
                    err += float(np.sum((pred - y[test]) ** 2))
            except InputError:
                continue  # this candidate cannot be fitted on a fold: not a choice
            scores[ci] = np.sqrt(err / y.size) / max(float(np.sqrt(np.mean(y ** 2))), 1e-300)
        best = np.nanmin(scores)
        if not np.isfinite(best):
            raise InputError("no candidate model could be fitted on the cross-validation folds")
        chosen_i = int(np.flatnonzero(scores <= best * (1.0 + tolerance))[0])
        note = (f"cross-validation ({k} folds over {ub.size} blocks) chose {cands[chosen_i]!r}: held-out "
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
            rss = np.maximum(np.sum((pred - y) ** 2, axis=0), 1e-300)
            scores[ci] = float(np.sum(m * np.log(rss / m) + n_params(c) * np.log(m)))
        if not np.isfinite(scores).any():
            raise InputError("no candidate model could be fitted")
        chosen_i = int(np.argmin(scores))
        note = f"BIC chose {cands[chosen_i]!r} (BIC {scores[chosen_i]:.1f})"
    return Selection(chosen=cands[chosen_i], candidates=cands, scores=scores, criterion=criterion, note=note)


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
        E = np.maximum(n[test] @ fit.directions.T, 0.0) @ fit.intensities + fit.ambient
        return E * rho / np.pi

    def k_of(c):
        return int(c) + (1 if kwargs.get("ambient", True) else 0)

    sel = select_model(fp, candidates, b, k_of, criterion, folds, normal_blocks(n), tolerance, seed)
    fit = full.get(sel.chosen)
    return _fill(sel, fit if fit is not None else hougen_ahuja(n, b, albedo, int(sel.chosen), **kwargs))


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

    def split(idx):
        out = {}
        for k, v in kwargs.items():
            a = np.asarray(v) if isinstance(v, (list, tuple, np.ndarray)) else None
            out[k] = a[idx] if a is not None and a.ndim >= 1 and a.shape[0] == m and m > 3 else v
        return out

    full = {}  # fits on every pixel (BIC's), reused for the chosen model

    def fp(c, train, test):
        d, V = nodes_of(c)
        fit = sato_sato_ikeuchi(p[train], b[train], occluder, plane_normal, d, visibility=V[train], **split(train))
        if train.size == m:
            full[c] = fit
        if np.array_equal(train, test):
            return fit.rendered
        kw = split(test)
        case = kw.get("case", "lambertian")
        K = shadow_kernel(d, V[test], plane_normal, case, kw.get("albedo", 1.0), kw.get("view_dirs"), kw.get("specular"))
        E = fit.intensities
        if case == "ratio":
            s_all = as_rgb_pixels(kwargs["surface_radiance"], m, "surface image")
            e0 = np.pi * np.mean(s_all[train], axis=0) / float(kwargs.get("reference_albedo", 1.0))
            return np.einsum("xnc,nc->xc", K, E / e0) * s_all[test]
        return np.einsum("xnc,nc->xc", K, E)

    def k_of(c):
        return int(nodes_of(c)[0].shape[0])

    sel = select_model(fp, candidates, b, k_of, criterion, folds, position_blocks(p), tolerance, seed)
    d, V = nodes_of(sel.chosen)
    fit: SourceFit | None = full.get(sel.chosen)
    if fit is None:
        fit = sato_sato_ikeuchi(p, b, occluder, plane_normal, d, visibility=V, **kwargs)
    return _fill(sel, fit)
