"""Automatic quality: the cheapest configuration that meets an error or frame-rate target.

``--quality auto --max-error E`` (or ``--fps F``) picks a :class:`ffls.relight.quality.Quality`
for *this* capture and *this* light map from measurements made here, on the capture itself:

* **time**: the caller's ``timer(quality, basis, directions) -> ms per frame`` (the GPU engine, or the CPU relighter:
  :func:`cpu_frame_ms`), measured for every candidate;
* **error**, with no ground truth:

  - the *floor*, ``e0``: how well the capture's lights sample the light field where this map
    puts its power, by leave-one-out (:func:`leave_one_out_errors`): each photo ``B_j`` of the
    lights that carry the most power is predicted from the *other* photos, with the weights the
    weighting scheme gives a point light at ``d_j``; the relative misses ``eps_j`` combine as
    ``e0 = 0.5 sqrt(sum_j (w_j eps_j ||B_j||)^2) / ||sum_j w_j B_j||``. The held-out light sits a
    whole light spacing from its neighbours, while the map's texels lie on average half a spacing
    from their cell's light, hence the 0.5; cells are taken as independent (sum of squares).
    ``docs/tradeoff.md`` compares this estimate with the true error on synthetic captures;
  - the *deviation* ``d_c`` of candidate ``c`` from the reference configuration (full basis,
    float32, every photo, the map at full resolution), relit on the CPU:
    ``||I_c - I_ref|| / ||I_ref||``;
  - the estimate ``e_c = sqrt(e0^2 + d_c^2)``.

With ground truth (a benchmark), the caller passes the true errors instead.

Candidates (:func:`candidate_qualities`): every weighting scheme of :data:`AUTO_WEIGHTINGS` (and
the base quality's, ``--weighting``, when it is not one of them: ``spline`` is considered only
when asked for, see :data:`AUTO_WEIGHTINGS`); ranks whose K + 1 layers fill
whole blocks of 8 float16 layers (7, 15, 23, 31, 63: pass 2 reads blocks of 8, so K = 16 costs as
much as K = 23); the full basis in float16 and float32; farthest-point subsets of 1/2 and 1/4 of
the photos; pass-1 map heights full and 64.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ffls.conventions import rotation_z
from ffls.relight.compress import CompressedBasis, compress_basis, rank_range
from ffls.relight.cpu import CpuRelighter, relight_reference
from ffls.relight.quality import Quality, farthest_point_subset, integration_map, prepare_basis
from ffls.relight.storage import store_basis
from ffls.weights.kriging import KernelLearner
from ffls.weights.weighting import SCHEMES, integrate as integrate_scheme, light_weights

__all__ = ["Choice", "candidate_qualities", "leave_one_out_errors", "loo_floor", "relight_quality",
           "estimate_errors", "cpu_frame_ms", "shrink", "truncate", "relight_weights", "choose", "choose_quality", "BLOCK_RANKS", "point_light_weights",
           "no_costlier", "timed_candidates", "AUTO_WEIGHTINGS"]

#: Ranks K whose K + 1 layers fill whole blocks of 8 float16 layers (the packed pass 2's unit).
BLOCK_RANKS = (7, 15, 23, 31, 63)
#: Weighting schemes every automatic choice considers: all but ``spline`` and ``kriging``, each added
#: only when the base quality names it (``--weighting spline --quality auto``; kriging's candidates
#: are measured with the kernel learnt from the photos, as the relighters use). Its leave-one-out floor, its
#: exact-weight reference and its timing double the measurement (64 lights, 64 px, studio map:
#: 2.5 s -> 5.4 s, the choice unchanged; docs/tradeoff.md), its pass 1 costs 4-10x barycentric's,
#: and on llvmpipe its full-size map is refused (its candidates then time as ``inf``).
AUTO_WEIGHTINGS = tuple(s for s in SCHEMES if s not in ("spline", "kriging"))
#: Map heights tried for pass 1 (None = the map as given).
MAP_HEIGHTS = (None, 64)


@dataclass
class Choice:
    """What :func:`choose` picked, and from what.

    Attributes
    ----------
    quality : Quality
    error : float
        Its (estimated or true) relative RMS error.
    ms : float
        Its measured time per frame.
    met : bool
        Whether it meets the target(s).
    reason : str
        One or two lines: what was chosen and why.
    table : list of dict
        Every candidate: ``{'quality', 'label', 'error', 'ms'}``.
    """

    quality: Quality
    error: float
    ms: float
    met: bool
    reason: str
    table: list = field(default_factory=list)


def candidate_qualities(n_lights: int, base: Quality | None = None, subsets: bool = True,
                        map_heights=MAP_HEIGHTS, weightings=None) -> list[Quality]:
    """The configurations the automatic choice considers for ``n_lights`` photos.

    Every weighting scheme (``weightings``, default :data:`AUTO_WEIGHTINGS` plus ``base``'s scheme) with
    the full basis (float16 and float32) and the block ranks, at each map height; subsets with
    ``base``'s scheme. ``base`` gives the knobs not varied here (texture resolution, near
    correction).
    """
    base = Quality() if base is None else base
    if weightings is None:
        schemes = AUTO_WEIGHTINGS + (() if base.weighting in AUTO_WEIGHTINGS else (base.weighting,))
    else:
        schemes = tuple(weightings)
    hi = rank_range(n_lights)[1]
    out = []
    for mr in map_heights:
        for w in schemes:
            b = base.replace(weighting=w, map_res=mr, basis_subset=None)
            out.append(b.replace(rank=None, precision="f32"))
            out.append(b.replace(rank=None, precision="f16"))
            for k in BLOCK_RANKS:
                if k <= hi and k < n_lights - 1:
                    out.append(b.replace(rank=k, precision="f16"))
        if subsets:
            for frac in (2, 4):
                m = n_lights // frac
                if m >= 8:
                    out.append(base.replace(rank=None, precision="f16", basis_subset=m, map_res=mr))
    return out


def point_light_weights(directions, d, weighting: str = "voronoi", hemisphere="upper", **options) -> np.ndarray:
    """Weights ``(n,)`` that a weighting scheme gives the ``n`` lights for one point light at ``d``
    (:func:`ffls.weights.weighting.light_weights`, with the scheme's ``options``; ``'voronoi'``: all
    to the nearest light)."""
    return light_weights(directions, d, weighting, hemisphere, **options)


def leave_one_out_errors(basis, directions, held_out, weighting: str = "voronoi", hemisphere="upper",
                         **options) -> np.ndarray:
    """Relative error ``||B_j - sum_{i != j} p_i B_i|| / ||B_j||`` of each held-out photo.

    Parameters
    ----------
    basis : (n, H, W, 3) float
    directions : (n, 3) float, unit
    held_out : (m,) int
        Indices of the photos to predict, each from all the others.
    weighting : str
        Scheme of :func:`point_light_weights`.
    **options
        The scheme's options (e.g. kriging's kernel).

    Returns
    -------
    (m,) float64
        ``nan`` for a black photo (nothing to be relative to) or a capture of one photo.
    """
    b = np.asarray(basis)
    dirs = np.asarray(directions, dtype=np.float64)
    n = len(dirs)
    out = np.empty(len(held_out))
    for t, j in enumerate(np.asarray(held_out, dtype=int)):
        others = np.delete(np.arange(n), j)
        if others.size == 0:
            out[t] = np.nan
            continue
        p = point_light_weights(dirs[others], dirs[j], weighting, hemisphere, **options)
        pred = np.zeros(b.shape[1:], dtype=np.float64)
        for i, wi in zip(others[p != 0], p[p != 0]):
            pred += wi * b[i].astype(np.float64)
        ref = b[j].astype(np.float64)
        nr = float(np.linalg.norm(ref))
        out[t] = float(np.linalg.norm(pred - ref)) / nr if nr > 0 else np.nan
    return out


def loo_floor(basis, directions, weights, weighting: str = "voronoi", hemisphere="upper", max_photos: int = 24,
              relit=None, **options) -> tuple[float, dict]:
    """The error floor ``e0`` of relighting under a map whose weights are ``weights`` (module docstring).

    Parameters
    ----------
    basis : (n, H, W, 3) float
    directions : (n, 3) float
    weights : (n, 3) float
        The map's weights over all lights (reference configuration).
    max_photos : int
        Hold out at most this many photos: those with the largest ``|w_j| ||B_j||`` (they carry
        most of the relit image); the rest is taken at their mean relative miss.
    relit : (H, W, 3) float, optional
        ``sum_j w_j B_j`` if already computed.
    **options
        The scheme's options (e.g. kriging's kernel), for its point-light weights.

    Returns
    -------
    e0 : float
    info : dict
        ``{'held_out': indices, 'eps': their relative misses, 'share': fraction of sum |w_j| ||B_j||
        they carry}``.
    """
    b = np.asarray(basis)
    w = np.asarray(weights, dtype=np.float64)
    n = len(w)
    norms = np.array([np.linalg.norm(b[i], axis=(0, 1)) for i in range(n)])  # (n, 3) per channel
    contrib = np.sqrt(((w * norms) ** 2).sum(axis=1))  # (n,)
    if n < 2 or contrib.sum() <= 0:
        return (0.0 if n >= 1 else np.nan), {"held_out": np.zeros(0, int), "eps": np.zeros(0), "share": 0.0}
    order = np.argsort(-contrib, kind="stable")[:max_photos]
    eps = leave_one_out_errors(b, directions, order, weighting, hemisphere, **options)
    eps = np.where(np.isfinite(eps), eps, 0.0)
    eps_all = np.full(n, float(np.mean(eps)))
    eps_all[order] = eps
    if relit is None:
        relit = np.einsum("nc,nhwc->hwc", w, b.astype(np.float64))
    denom = float(np.linalg.norm(relit))
    e0 = 0.5 * float(np.sqrt(np.sum((eps_all * contrib) ** 2))) / denom if denom > 0 else 0.0
    return e0, {"held_out": order, "eps": eps, "share": float(contrib[order].sum() / contrib.sum())}


def relight_quality(basis, directions, lightmap, rotation, quality: Quality, hemisphere="upper",
                    compressed: CompressedBasis | None = None, cells=None) -> np.ndarray:
    """The relit image ``(H, W, 3)`` float64 of a configuration, on the CPU (float64 sums).

    ``basis`` and ``directions`` are after near correction; the subset, the map height, the
    storage rounding and the rank are applied here. ``compressed`` (of rank >= ``quality.rank``)
    is truncated to the rank instead of compressing again.
    """
    b, d, _ = prepare_basis(basis, directions, basis_subset=quality.basis_subset)
    cb = None
    if quality.rank is not None:
        cb = compressed if compressed is not None and compressed.n_lights == len(d) else None
        cb = compress_basis(b, quality.rank) if cb is None or cb.rank < quality.rank else truncate(cb, quality.rank)
    r = CpuRelighter(b, d, hemisphere, precision="f64", compressed=cb, cell_res=None, storage=quality.precision,
                     map_res=quality.map_res, weighting=quality.weighting)
    r.set_lightmap(lightmap)
    r.set_rotation(np.eye(3) if rotation is None else rotation)
    r.render()
    return np.asarray(r.hdr, dtype=np.float64)


def relight_weights(basis, weights, quality: Quality, compressed: CompressedBasis | None = None) -> np.ndarray:
    """Pass 2 of a configuration on the CPU: ``(H, W, 3)`` float64 from ``weights`` ``(n, 3)``.

    The storage rounding and the rank of ``quality`` are applied (``compressed`` of rank >= K is
    truncated instead of compressing again); the subset, the weighting and the map height are
    already in ``basis`` and ``weights``.
    """
    b = np.asarray(basis)
    if quality.rank is not None:
        cb = compressed if compressed is not None and compressed.rank >= quality.rank else compress_basis(b, quality.rank)
        layers = store_basis(truncate(cb, quality.rank).layers(), quality.precision)
        stored = layers[0].astype(np.float64) / layers[1]
        coeffs = truncate(cb, quality.rank).layer_coefficients(weights)
        return np.einsum("kc,khwc->hwc", coeffs, stored)
    stored, scale, _ = store_basis(b, quality.precision)
    return relight_reference(weights, stored) / scale


def truncate(cb: CompressedBasis, rank: int) -> CompressedBasis:
    """The first ``rank`` eigen-images of a compressed basis (the best rank-K part of it)."""
    return CompressedBasis(cb.mean, cb.components[:rank], cb.loadings[:, :rank], cb.singular_values[:rank],
                           cb.mode, dict(cb.info))


def estimate_errors(basis, directions, lightmap, rotation, candidates, hemisphere="upper", weighting="voronoi",
                    max_photos: int = 24) -> tuple[list[float], dict]:
    """Estimated relative RMS error of each candidate, without ground truth (module docstring).

    Candidates are grouped by their basis subset and weighting scheme; each group has its own
    reference (float32, every photo of the subset, full rank, the map as given, the scheme) and
    its own leave-one-out floor on the subset's photos with the scheme's point-light weights, so
    that a coarser sampling or a better interpolation shows in the floor. ``weighting`` names the
    scheme whose floor is reported as ``e0``. ``'kriging'`` uses the kernel each group learns from
    its own photos (:class:`ffls.weights.kriging.KernelLearner`), as the relighters do.

    Returns
    -------
    errors : list of float
    info : dict
        ``e0`` (the floor of the whole basis), ``floors`` ({(subset, scheme): e0}), ``loo``
        (details for the whole basis) and ``deviations``.
    """
    b = np.asarray(basis)
    d = np.asarray(directions, dtype=np.float64)
    groups = {}
    for i, q in enumerate(candidates):
        m = q.basis_subset if q.basis_subset is not None and q.basis_subset < len(d) else None
        groups.setdefault((m, q.weighting), []).append(i)
    errs = [np.nan] * len(candidates)
    devs = [np.nan] * len(candidates)
    floors, loo_all = {}, None
    for (m, scheme), members in groups.items():
        idx = np.arange(len(d)) if m is None else farthest_point_subset(d, m)
        bs, ds = b[idx], d[idx]
        weights = {}  # one pass 1 per map height: rank and storage change only pass 2
        options = KernelLearner(ds, bs).options_for(scheme, {}) if scheme == "kriging" else {}

        def weights_at(mr, ds=ds, scheme=scheme, weights=weights, options=options):
            if mr not in weights:
                weights[mr] = integrate_scheme(integration_map(lightmap, mr), ds, rotation, hemisphere, scheme,
                                               **options).weights
            return weights[mr]

        w = weights_at(None)
        ref = relight_weights(bs, w, Quality(precision="f32"))
        e0, loo = loo_floor(bs, ds, w, scheme, hemisphere, max_photos, relit=ref, **options)
        floors[(m, scheme)] = e0
        if m is None and (loo_all is None or scheme == weighting):
            loo_all = loo
        ranks = [candidates[i].rank for i in members if candidates[i].rank is not None]
        cb = compress_basis(bs, max(ranks)) if ranks else None
        denom = float(np.linalg.norm(ref))
        for i in members:
            q = candidates[i]
            img = relight_weights(bs, weights_at(q.map_res), q, compressed=cb)
            devs[i] = float(np.linalg.norm(img - ref)) / denom if denom > 0 else 0.0
            errs[i] = float(np.hypot(e0, devs[i]))
    e0 = floors.get((None, weighting), min(floors.values()))
    if loo_all is None:
        loo_all = {"held_out": np.zeros(0, int), "eps": np.zeros(0), "share": 0.0}
    return errs, {"e0": e0, "floors": floors, "loo": loo_all, "deviations": devs}


def shrink(basis, size: int | None) -> np.ndarray:
    """Photos ``(n, H, W, 3)`` area-averaged to at most ``size`` pixels on a side (the same array if already)."""
    import cv2

    b = np.asarray(basis)
    if size is None or max(b.shape[1:3]) <= int(size):
        return b
    f = int(size) / max(b.shape[1:3])
    w, h = max(1, round(b.shape[2] * f)), max(1, round(b.shape[1] * f))
    return np.stack([cv2.resize(np.asarray(x, dtype=np.float32), (w, h), interpolation=cv2.INTER_AREA) for x in b])


def cpu_frame_ms(basis, directions, lightmap, quality: Quality, hemisphere="upper", repeats: int = 2) -> float:
    """Median ms per frame of the CPU relighter (float32 pass 2) for ``quality``, the map rotated each frame."""
    b, d, _ = prepare_basis(basis, directions, basis_subset=quality.basis_subset)
    r = CpuRelighter(b, d, hemisphere, rank=quality.rank, cell_res=quality.cell_res or 256,
                     storage=quality.precision, map_res=quality.map_res, weighting=quality.weighting)
    r.set_lightmap(lightmap)
    ts = []
    for k in range(repeats + 1):
        r.set_rotation(rotation_z(1.0 + k))
        t0 = time.perf_counter()
        r.render()
        ts.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(ts[1:]))


def choose(candidates, errors, ms, max_error: float | None = None, fps: float | None = None,
           how: str = "") -> Choice:
    """The cheapest candidate meeting ``max_error`` and/or ``fps``; see :class:`Choice`.

    With only ``fps``: the most accurate candidate within the frame time. With neither target,
    raises ``ValueError``. When nothing meets the target(s): the most accurate (error target) or
    the fastest (fps target) candidate, and ``met`` is False.
    """
    if max_error is None and fps is None:
        raise ValueError("give max_error, fps or both")
    errors = np.asarray(errors, dtype=np.float64)
    ms = np.asarray(ms, dtype=np.float64)
    budget = None if fps is None else 1000.0 / float(fps)
    ok = np.ones(len(candidates), dtype=bool)
    if max_error is not None:
        ok &= errors <= max_error
    if budget is not None:
        ok &= ms <= budget
    table = [{"quality": q, "label": q.label(), "error": float(e), "ms": float(t)}
             for q, e, t in zip(candidates, errors, ms)]
    if np.any(ok):
        idx = np.flatnonzero(ok)
        # error target: cheapest; fps only: most accurate within the budget (ties: cheaper)
        key = (ms[idx], errors[idx]) if max_error is not None else (errors[idx], ms[idx])
        i = int(idx[np.lexsort(key[::-1])[0]])
        met = True
    else:
        i = int(np.argmin(errors)) if max_error is not None and fps is None else int(np.argmin(ms))
        met = False
    q = candidates[i]
    target = " and ".join(t for t in (None if max_error is None else f"error <= {100 * max_error:.3g}%",
                                      None if fps is None else f">= {fps:g} fps ({budget:.1f} ms)") if t)
    if met:
        why = (f"the cheapest of {int(ok.sum())} of {len(candidates)} candidates meeting {target}"
               if max_error is not None else
               f"the most accurate of {int(ok.sum())} of {len(candidates)} candidates meeting {target}")
    else:
        why = (f"no candidate of {len(candidates)} meets {target}; this is the "
               f"{'most accurate' if max_error is not None and fps is None else 'fastest'}")
    reason = (f"quality auto: {q.label()} (error {100 * errors[i]:.2f}%, {ms[i]:.1f} ms/frame): {why}"
              + (f"\n  {how}" if how else ""))
    return Choice(q, float(errors[i]), float(ms[i]), met, reason, table)


def choose_quality(basis, directions, lightmap, rotation=None, *, max_error: float | None = None,
                   fps: float | None = None, timer=None, hemisphere="upper", base: Quality | None = None,
                   candidates=None, max_photos: int = 24, error_size: int | None = 128,
                   error_map_height: int | None = 128, prune: bool = True) -> Choice:
    """Measure every candidate on this capture and map, and :func:`choose`.

    Parameters
    ----------
    basis : (n, H, W, 3) float
        After near correction (when the base quality asks for it).
    directions : (n, 3) float
    lightmap : LightMap
    rotation : (3, 3) float, optional
    max_error, fps : float, optional
        Targets (relative RMS error; frames per second).
    timer : callable, optional
        ``timer(quality, basis, directions) -> ms per frame`` (the subset is for it to apply, as
        :func:`cpu_frame_ms` does); default :func:`cpu_frame_ms`.
    base : Quality, optional
        Knobs not chosen here (weighting, cell resolution, near correction).
    candidates : list of Quality, optional
        Default :func:`candidate_qualities`.
    max_photos : int
        Photos held out by the leave-one-out floor.
    error_size : int, optional
        The errors are estimated on the photos shrunk (area average, :func:`cv2.resize`) to at
        most this many pixels on a side (relative errors hardly change; the time does); None =
        full size. Times are always measured at full size.
    error_map_height : int, optional
        The errors are estimated on the map box-filtered to at most this height
        (:func:`ffls.relight.quality.integration_map`, integral kept): a smooth scheme's exact
        weights cost per texel. None = the map as given.
    prune : bool
        Time only the candidates that could be chosen (:func:`timed_candidates`; the others get
        ``inf`` ms in ``Choice.table``); False times every candidate.
    """
    b = np.asarray(basis)
    d = np.asarray(directions, dtype=np.float64)
    cands = candidate_qualities(len(d), base) if candidates is None else list(candidates)
    errs, info = estimate_errors(shrink(b, error_size), d, integration_map(lightmap, error_map_height), rotation,
                                 cands, hemisphere,
                                 (base or Quality()).weighting, max_photos)
    if timer is None:
        def timer(q, basis_, directions_):
            return cpu_frame_ms(basis_, directions_, lightmap, q, hemisphere)
    if prune:
        ms = timed_candidates(cands, errs, lambda q: float(timer(q, b, d)), len(d), max_error, fps)
    else:
        ms = [float(timer(q, b, d)) for q in cands]
    choice = choose(cands, errs, ms, max_error, fps)
    q = choice.quality
    m = q.basis_subset if q.basis_subset is not None and q.basis_subset < len(d) else None
    floor = info["floors"].get((m, q.weighting), info["e0"])
    n_timed = int(np.count_nonzero(np.isfinite(ms)))
    how = (f"error = its leave-one-out floor {100 * floor:.2f}% ({q.weighting}"
           f"{'' if m is None else f', {m} photos'}; up to {max_photos} photos held out) combined with its "
           f"deviation from the full basis; times measured here"
           + (f" for {n_timed} of {len(cands)} candidates (the others cost more than a timed one with the "
              f"same scheme and photos and could not be chosen)" if n_timed < len(cands) else ""))
    choice.reason = f"{choice.reason}\n  {how}"
    return choice


def no_costlier(a: Quality, b: Quality, n_lights: int) -> bool:
    """Whether ``a`` does no more work per frame than ``b``, by construction (no measurement).

    Both have the same weighting scheme, basis subset, cell texture and near correction, and
    ``a`` has no more pass-2 layers (K + 1 for rank K, else the photos), no wider storage
    (float16 <= float32) and no larger pass-1 map (a height <= the map as loaded, ``None``)
    than ``b``. Pass 1 then runs the same program over no more texels, the projection is
    negligible, and pass 2 reads no more bytes per pixel (:func:`timed_candidates`).
    """
    if (a.weighting, a.basis_subset, a.cell_res, a.near_correction) != \
            (b.weighting, b.basis_subset, b.cell_res, b.near_correction):
        return False
    photos = n_lights if a.basis_subset is None else min(int(a.basis_subset), n_lights)

    def layers(q):
        return photos if q.rank is None else min(int(q.rank) + 1, photos)

    wide = {"f16": 0, "f32": 1}
    if layers(a) > layers(b) or wide[a.precision] > wide[b.precision]:
        return False
    if b.map_res is None:
        return True
    return a.map_res is not None and int(a.map_res) <= int(b.map_res)


def timed_candidates(candidates, errors, time_one, n_lights: int, max_error: float | None = None,
                     fps: float | None = None) -> np.ndarray:
    """Frame times of the candidates :func:`choose` could pick, ``inf`` for the others (never timed).

    :func:`choose` with an error target picks the cheapest candidate meeting it (or, with none, the most
    accurate, or with an fps target too the fastest of all); with only an fps target, the most
    accurate within the frame time. A candidate ``b`` for which some other candidate ``a`` is
    :func:`no_costlier` (and different in cost) is never the cheapest of a set holding ``a``, so
    only the minimal candidates of the set that matters are timed; with only an fps target the
    candidates are timed from the most accurate on, stopping at the first that fits, and every
    candidate costlier than one that missed the budget is skipped. The choice is that of timing
    every candidate, as long as more layers, wider storage or a larger map never run faster
    (up to the timer's noise).

    Parameters
    ----------
    candidates : list of Quality
    errors : (n,) float
    time_one : callable
        ``time_one(quality) -> ms per frame``.
    n_lights : int
        Photos of the capture (before any subset).
    max_error, fps : float, optional
        As :func:`choose`.

    Returns
    -------
    (n,) float64 ndarray
        ms per frame; ``inf`` where not timed.
    """
    errors = np.asarray(errors, dtype=np.float64)
    n = len(candidates)
    ms = np.full(n, np.inf)
    timed = np.zeros(n, dtype=bool)

    def dominated(i, pool):  # some other candidate of the pool costs strictly less by construction
        return any(j != i and no_costlier(candidates[j], candidates[i], n_lights)
                   and not no_costlier(candidates[i], candidates[j], n_lights) for j in pool)

    def time_minimal(pool):
        pool = list(pool)
        for i in pool:
            if not timed[i] and not dominated(i, pool):
                ms[i] = float(time_one(candidates[i]))
                timed[i] = True

    budget = None if fps is None else 1000.0 / float(fps)
    if max_error is not None:
        feasible = np.flatnonzero(errors <= max_error)
        if feasible.size:
            time_minimal(feasible)
            if budget is None or np.any(ms[feasible] <= budget):
                return ms
        elif budget is None:  # nothing meets the error: choose() takes the most accurate
            i = int(np.argmin(errors))
            ms[i] = float(time_one(candidates[i]))
            return ms
        time_minimal(range(n))  # choose() falls back to the fastest of all
        return ms
    order = np.lexsort((np.arange(n), errors))  # most accurate first
    best = None
    for i in order:
        if best is not None and errors[i] > best:
            break
        if any(timed[j] and ms[j] > budget and no_costlier(candidates[j], candidates[i], n_lights)
               for j in range(n)):
            continue  # costs at least as much as one that missed the budget
        ms[i] = float(time_one(candidates[i]))
        timed[i] = True
        if ms[i] <= budget and best is None:
            best = errors[i]  # the most accurate that fits; equal errors are timed too (ties: cheaper)
    if best is None:
        time_minimal(range(n))  # choose() falls back to the fastest of all
    return ms
