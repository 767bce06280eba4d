"""The linear image-formation model shared by the inverse methods, and its solvers.

A Lambertian point of albedo ``rho`` and normal ``n`` under distant sources ``l_k`` of
irradiance ``E_k`` (at normal incidence) plus an ambient irradiance ``A`` has radiance

    I = rho / pi * (A + sum_k E_k V_k max(0, n . l_k))

with ``V_k`` the visibility of source ``k`` (1 without shadows). ffls' synthetic renderer uses
the same ``kd / pi`` convention. Under a light map the irradiance is
``E(n) = sum_texels L max(0, n . w) dw`` (:func:`irradiance_from_map`).

Solvers (:func:`solve_sources`, on the thin-QR reduction of :func:`reduce_rows`): plain least
squares (``numpy.linalg.lstsq``, optionally truncated at a relative singular value ``rcond``), or non-negative least squares
(``scipy.optimize.nnls``) with the ambient term left free by splitting it into two
non-negative columns ``+1`` and ``-1`` (``A = a+ - a-``; the pair's minimum-norm choice is what
NNLS returns, and the fit is the same as with a free column). Optional Tikhonov rows: a
first-difference ``smoothness`` between neighbouring unknowns and a minimum-``energy`` term on the
radiance of each source's cell; and total variation (``tv``) between neighbours, by iteratively reweighted
least squares.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import qr
from scipy.optimize import nnls

from ffls.errors import InputError

__all__ = [
    "lambert_matrix",
    "irradiance_from_map",
    "as_rgb_pixels",
    "LinearSolution",
    "solve_sources",
    "reduce_rows",
    "neighbour_edges",
    "broadcast_albedo",
]


def lambert_matrix(normals, directions, visibility=None) -> np.ndarray:
    """Clamped cosines ``max(0, n_i . l_k)`` (times visibility) of every pixel and source.

    Parameters
    ----------
    normals : (m, 3) array_like
        Unit surface normals.
    directions : (n, 3) array_like
        Unit source directions.
    visibility : (m, n) array_like of bool or float, optional
        1 where source ``k`` reaches pixel ``i``.

    Returns
    -------
    (m, n) float64
    """
    c = np.maximum(np.asarray(normals, dtype=np.float64) @ np.asarray(directions, dtype=np.float64).T, 0.0)
    if visibility is not None:
        c = c * np.asarray(visibility, dtype=np.float64)
    return c


def irradiance_from_map(normals, lightmap_or_samples, chunk: int = 4096) -> np.ndarray:
    """Irradiance ``sum L max(0, n . w) dw`` of a light map on every normal (no shadows).

    Parameters
    ----------
    normals : (m, 3) array_like
        Unit normals.
    lightmap_or_samples : LightMap or (dirs (M, 3), radiance (M, 3), solid_angle (M,))
    chunk : int
        Normals per block (memory ``chunk x M`` float64).

    Returns
    -------
    (m, 3) float64
    """
    from ffls.lightmaps.lightmap import as_samples

    dirs, rad, sa = as_samples(lightmap_or_samples)
    p = rad * sa[:, None]
    nz = np.any(p != 0, axis=1)
    dirs, p = dirs[nz], p[nz]
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    out = np.empty((n.shape[0], 3))
    for s in range(0, n.shape[0], chunk):
        out[s:s + chunk] = np.maximum(n[s:s + chunk] @ dirs.T, 0.0) @ p
    return out


def as_rgb_pixels(radiance, m: int | None = None, name: str = "radiance") -> np.ndarray:
    """Pixel values as (m, 3) float64: a single channel is repeated; NaN or Inf is an InputError."""
    r = np.asarray(radiance, dtype=np.float64)
    if r.ndim == 1:
        r = np.repeat(r[:, None], 3, axis=1)
    if r.ndim != 2 or r.shape[1] != 3:
        raise ValueError(f"{name} must be (m,) or (m, 3), not {r.shape}")
    if m is not None and r.shape[0] != m:
        raise ValueError(f"{name} has {r.shape[0]} pixels, the geometry {m}")
    if not np.all(np.isfinite(r)):
        raise InputError(f"{name} holds NaN or Inf")
    return r


def broadcast_albedo(albedo, m: int) -> np.ndarray:
    """Albedo as (m, 3) float64 from a scalar, (3,), (m,) or (m, 3); must be > 0 and finite."""
    a = np.asarray(albedo, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == m and m != 3:
        a = a[:, None]
    a = np.broadcast_to(a, (m, 3)).astype(np.float64)
    if not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise InputError("albedo must be positive and finite")
    return a


@dataclass(frozen=True)
class LinearSolution:
    """A solved linear model, per channel.

    Attributes
    ----------
    x : (n, 3) float64
        Unknowns (without the ambient term); 0 for unobserved ones.
    ambient : (3,) float64
        The free constant term (0 when not fitted).
    predicted : (m, 3) float64
        The model's prediction of the data.
    condition : float
        Ratio of the largest to the smallest singular value of the (column-normalised) design
        over the observed unknowns.
    rank : int
        Numerical rank of that design (singular values above ``1e-10`` x the largest).
    observed : (n,) bool
        Unknowns whose column is not all zero (an unknown that no pixel sees stays 0).
    """

    x: np.ndarray
    ambient: np.ndarray
    predicted: np.ndarray
    condition: float
    rank: int
    observed: np.ndarray


#: Relative singular value below which a design counts as rank deficient.
RANK_TOL = 1e-10
#: :func:`solve_sources`' total variation: the most reweighted rounds, the smallest difference (relative
#: to the quadratic fit's RMS difference) a weight is computed from, and the relative change that stops it.
TV_ROUNDS = 3
TV_EPS = 1e-3
TV_TOL = 1e-3


def neighbour_edges(directions, k: int = 6) -> np.ndarray:
    """Edges (e, 2) int64 between each direction and its ``k`` nearest (by angle), each once."""
    from scipy.spatial import cKDTree

    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    kk = min(k + 1, d.shape[0])
    if kk < 2:
        return np.zeros((0, 2), dtype=np.int64)
    _, idx = cKDTree(d).query(d, k=kk)
    a = np.repeat(np.arange(d.shape[0]), kk - 1)
    b = idx[:, 1:].ravel()
    e = np.sort(np.stack([a, b], axis=1), axis=1)
    return np.unique(e[e[:, 0] != e[:, 1]], axis=0)


def reduce_rows(A, b) -> tuple[np.ndarray, np.ndarray]:
    """An equivalent least-squares problem with at most as many rows as unknowns (thin QR).

    With ``A = Q R`` (``Q`` orthonormal columns, ``R`` square upper triangular; ``scipy.linalg.qr``
    of ``[A | b]``, whose factor holds ``R`` and ``Q^T b``),
    ``|A x - b|^2 = |R x - Q^T b|^2 + |(1 - Q Q^T) b|^2`` for every ``x``: the second term does
    not depend on ``x``, so any constrained least-squares problem (NNLS) has the same minimiser
    on ``(R, Q^T b)``. For a tall system (thousands of pixels, hundreds of sources) each of the
    active-set solver's steps then costs ``n^2`` instead of ``m n``, and the factorisation is
    shared by all channels.

    Parameters
    ----------
    A : (m, n) array_like
    b : (m, c) array_like

    Returns
    -------
    R : (min(m, n), n) float64
    rhs : (min(m, n), c) float64
        ``A`` and ``b`` themselves when ``m <= n``.
    """
    A = np.asarray(A, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    n = A.shape[1]
    if A.shape[0] <= n:
        return A, b
    # the triangular factor of [A | b] holds R and Q^T b (its first n rows): Q is never formed
    Rb = qr(np.concatenate([A, b.reshape(A.shape[0], -1)], axis=1), mode="r", overwrite_a=True, check_finite=False)[0]
    return Rb[:n, :n], Rb[:n, n:].reshape((n,) + b.shape[1:])


def solve_sources(M, b, ambient_column=None, nonnegative: bool = False, rcond: float | None = None,
                  what: str = "sources", smoothness: float = 0.0, edges=None,
                  ambient_nonnegative: bool = False, energy: float = 0.0, cell_solid_angles=None,
                  tv: float = 0.0, tv_rounds: int | None = None, power: float = 0.0) -> LinearSolution:
    """Solve ``b ~ M x + c a`` per channel, ``x >= 0`` with ``nonnegative``, ``a`` always free.

    Unknowns whose column is all zero (a source that lights no pixel) are left out and set to 0.

    Parameters
    ----------
    M : (m, n) array_like
        Design matrix (one column per unknown).
    b : (m, c) array_like
        Data (``c`` channels, solved independently with the same design).
    ambient_column : (m,) array_like, optional
        The column ``c`` of a free term ``a`` (None: no such term).
    nonnegative : bool
        NNLS (``scipy.optimize.nnls``) on ``x``, the free term split as ``a = a+ - a-``.
    rcond : float, optional
        Unconstrained only: singular values below ``rcond x`` the largest are cut (truncated
        SVD, the minimum-norm solution in the well-determined subspace). None: plain least
        squares, which needs a full-rank design.
    what : str
        Names the unknowns in the error message.
    smoothness : float
        Tikhonov weight ``lambda`` of a first-difference penalty ``lambda^2 sum (x_i - x_j)^2``
        over ``edges`` (neighbouring sources), relative to the data: the penalty rows are scaled
        by the RMS column norm of ``M``, so ``lambda`` is unit-free. It fills the directions
        the data cannot see (behind a probe, never shadowed) from their neighbours instead of
        leaving them arbitrary; 0 is the papers' plain fit.
    edges : (e, 2) array_like of int, optional
        Pairs of neighbouring unknowns (:func:`neighbour_edges`); needed when ``smoothness > 0``.
    ambient_nonnegative : bool
        With ``nonnegative``: constrain the ambient term too (not split).
    energy : float
        Tikhonov weight ``lambda`` of a minimum-energy penalty on the map the unknowns make:
        ``lambda^2 sum_k (x_k / Omega_k)^2 Omega_k mean(Omega)``, the integral of the squared
        radiance of source ``k`` spread over its cell of solid angle ``Omega_k``, relative to the
        data as ``smoothness`` is. Of the maps the data cannot tell apart it prefers the one
        whose power is spread most evenly (a vertex solution of NNLS concentrates spread light
        into a few sources); 0 is the papers' plain fit.
    cell_solid_angles : (n,) array_like, optional
        ``Omega_k`` (:func:`ffls.probes.hougen_ahuja.cell_solid_angles`); needed when ``energy > 0``.
    tv : float
        Weight ``lambda`` of a total-variation (edge-preserving) penalty over ``edges``,
        ``lambda^2 c sum |x_i - x_j|`` with the rows scaled as ``smoothness``'s and ``c`` the RMS
        first difference of the fit with the quadratic ``smoothness`` penalty at the same weight
        (where ``|x_i - x_j| = c`` the two penalties agree; ``c`` makes ``lambda`` unit-free).
        The quadratic penalty spreads a sharp lamp over its neighbours; the L1 norm of the
        differences charges a jump by its height only, so it keeps isolated lamps sharp while it
        flattens spread light. Solved by iteratively reweighted least squares: the fit with the
        quadratic penalty, then up to ``tv_rounds`` fits with each difference row reweighted by
        ``sqrt(c / max(|x_i - x_j|, TV_EPS c))`` from the previous fit (each one NNLS or lstsq,
        per channel), stopped when the unknowns change by less than ``TV_TOL`` of their largest.
        0 is the papers' plain fit.
    tv_rounds : int
        The most reweighted fits after the first (None: ``TV_ROUNDS``).
    power : float
        Weight ``lambda`` of a least-total-power penalty ``lambda^2 (ref sum_k x_k)^2`` on the
        unknowns of ``M`` (not the free term), ``ref`` the RMS column norm of ``M`` as for
        ``smoothness``. With ``nonnegative`` the sum is the light's total power, whatever the
        source set: the penalty does not depend on where the sources lie. A source lighting every
        seen pixel adds only a linear function of the normal, which the sum of other such sources
        can replace; of those equally good maps the penalty prefers the one with the least power,
        the most concentrated (``docs/probes.md``, *Least total power*). 0 is the papers' plain fit.

    Returns
    -------
    LinearSolution

    Raises
    ------
    InputError
        Fewer rows than unknowns; no unknown seen by any pixel; or, for plain least squares
        (``rcond=None``, unconstrained), a rank-deficient design (a singular system).
    """
    M = np.asarray(M, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if b.ndim == 1:
        b = b[:, None]
    m, n = M.shape
    observed = np.any(M != 0, axis=0)
    if not observed.any():
        raise InputError(f"singular system: none of the {what} lights any pixel")
    cols = [M[:, observed]] if ambient_column is None else \
        [M[:, observed], np.asarray(ambient_column, dtype=np.float64).reshape(m, 1)]
    D = np.concatenate(cols, axis=1)
    k = D.shape[1]
    if m < k:
        dark = int(n - observed.sum())  # (left out: the count of unknowns would not add up to ``what``)
        left = f"; the {dark} that light no pixel left out" if dark else ""
        raise InputError(f"singular system: {m} pixels for {k} unknowns ({what}{left}); "
                         f"use fewer sources or more pixels")
    scale = np.linalg.norm(D, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    # every solve below runs on the thin-QR reduction (same minimiser, same singular values)
    Ds, bq = reduce_rows(D / scale, b)
    s = np.linalg.svd(Ds, compute_uv=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else np.inf
    rank = int(np.count_nonzero(s > s[0] * RANK_TOL))
    Dsolve, bsolve = Ds, bq
    G = None
    # the penalties' common scale: the RMS column norm of the seen unknowns
    ref = float(np.sqrt(np.mean(np.sum(M[:, observed] ** 2, axis=0)))) \
        if smoothness > 0 or tv > 0 or energy > 0 or power > 0 else None
    if smoothness > 0 or tv > 0:
        if edges is None:
            raise ValueError("smoothness and tv need the edges between neighbouring unknowns")
        e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        remap = np.full(n, -1, dtype=np.int64)
        remap[observed] = np.arange(int(observed.sum()))
        e = remap[e]
        e = e[(e >= 0).all(axis=1)]
        if e.shape[0]:
            G = np.zeros((e.shape[0], k))
            rows = np.arange(e.shape[0])
            G[rows, e[:, 0]] = ref / scale[e[:, 0]]
            G[rows, e[:, 1]] = -ref / scale[e[:, 1]]
    if smoothness > 0 and G is not None:
        Dsolve = np.concatenate([Ds, float(smoothness) * G], axis=0)
        bsolve = np.concatenate([bq, np.zeros((G.shape[0], b.shape[1]))], axis=0)
    if energy > 0:
        if cell_solid_angles is None:
            raise ValueError("energy needs the cells' solid angles")
        om = np.asarray(cell_solid_angles, dtype=np.float64).reshape(-1)
        if om.shape[0] != n or not np.all(np.isfinite(om)) or np.any(om <= 0):
            raise ValueError(f"cell_solid_angles must be ({n},) positive, not {om.shape}")
        om = om[observed]
        nobs = om.shape[0]
        Ge = np.zeros((nobs, k))
        Ge[np.arange(nobs), np.arange(nobs)] = np.sqrt(np.mean(om) / om) / scale[:nobs]
        Dsolve = np.concatenate([Dsolve, float(energy) * ref * Ge], axis=0)
        bsolve = np.concatenate([bsolve, np.zeros((nobs, b.shape[1]))], axis=0)
    if power > 0:
        nobs = int(observed.sum())
        Gp = np.zeros((1, k))
        Gp[0, :nobs] = float(power) * ref / scale[:nobs]
        Dsolve = np.concatenate([Dsolve, Gp], axis=0)
        bsolve = np.concatenate([bsolve, np.zeros((1, b.shape[1]))], axis=0)
    split = nonnegative and ambient_column is not None and not ambient_nonnegative
    if not nonnegative and rcond is None and rank < k and not (smoothness > 0 or energy > 0 or tv > 0
                                                                   or power > 0):
        raise InputError(f"singular system: the {m} pixels determine only {rank} of the {k} unknowns "
                         f"({what}); use fewer sources, non-negativity, or a cut-off (rcond)")

    def solve(A, rhs):  # (rows, k) design, (rows, c) data -> (k, c)
        if not nonnegative:
            return np.linalg.lstsq(A, rhs, rcond=rcond)[0]
        A = np.concatenate([A, -A[:, -1:]], axis=1) if split else A
        out = np.zeros((A.shape[1], rhs.shape[1]))
        for c in range(rhs.shape[1]):
            out[:, c], _ = nnls(A, rhs[:, c], maxiter=50 * A.shape[1])
        return np.concatenate([out[:-2], out[-2:-1] - out[-1:]], axis=0) if split else out

    if tv > 0 and G is not None:
        rounds = TV_ROUNDS if tv_rounds is None else int(tv_rounds)
        sol = _total_variation(Dsolve, bsolve, float(tv) * G, solve, rounds)
    else:
        sol = solve(Dsolve, bsolve)
    sol = sol / scale[:, None]
    pred = D @ sol
    x = np.zeros((n, b.shape[1]))
    nobs = int(observed.sum())
    x[observed] = sol[:nobs]
    amb = sol[nobs] if ambient_column is not None else np.zeros(b.shape[1])
    return LinearSolution(x=x, ambient=amb, predicted=pred, condition=cond, rank=rank, observed=observed)


def _total_variation(A, rhs, G, solve, rounds: int) -> np.ndarray:
    """:func:`solve_sources`' total-variation fit by iteratively reweighted least squares.

    ``A x ~ rhs`` (rows, k), (rows, c) with the weighted difference rows ``G`` (e, k): the first fit
    has the quadratic penalty ``|G x|^2``, each channel's next ones ``sum_ij c |(G x)_ij|`` through
    rows ``sqrt(w) G``, ``w = c / max(|G x_prev|, TV_EPS c)``, ``c`` the first fit's RMS difference.
    """
    zeros = np.zeros((G.shape[0], 1))
    sol = solve(np.concatenate([A, G], axis=0), np.concatenate([rhs, np.zeros((G.shape[0], rhs.shape[1]))]))
    c = np.sqrt(np.mean((G @ sol) ** 2, axis=0))
    for _ in range(max(int(rounds), 0)):
        prev = sol
        sol = np.empty_like(prev)
        for ch in range(rhs.shape[1]):
            if c[ch] <= 0:  # the quadratic fit is flat: its differences are all 0, and so are TV's
                sol[:, ch] = prev[:, ch]
                continue
            w = np.sqrt(c[ch] / np.maximum(np.abs(G @ prev[:, ch]), TV_EPS * c[ch]))
            sol[:, ch:ch + 1] = solve(np.concatenate([A, w[:, None] * G], axis=0),
                                      np.concatenate([rhs[:, ch:ch + 1], zeros]))
        if np.max(np.abs(sol - prev)) <= TV_TOL * max(float(np.max(np.abs(prev))), 1e-300):
            break
    return sol
