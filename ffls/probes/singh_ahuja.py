"""Illumination by projection onto convex sets (POCS): Singh and Ahuja's method.

Singh, Ahuja (summarised in ``shared/papers/illumination-estimation-survey.txt``, sections 4
and 5). The lighting ``f`` is discretised on the spherical coordinates (a lat-long grid, denser
towards the poles, as in the paper) and the image of a Lambertian object of known geometry is
``g(x) = sum_j H(x, j) f(j)`` with the kernel ``H(x, j) = rho / pi max(0, n_x . w_j) dw_j`` (``f``
is radiance, ``dw_j`` the texel's solid angle). Two kinds of convex constraint:

* the *amplitude* set ``{f : 0 <= f <= L}``, projection ``P_A`` = clipping (eq. 8);
* for every pixel, the *residual* set ``{f : |g(x) - H(x, .) f| <= delta}``, projection (eq. 10)
  ``f += (r -+ delta) H(x, .) / |H(x, .)|^2`` when the residual ``r`` is outside
  ``[-delta, delta]`` (nothing otherwise).

One iteration applies every residual projection once, in a fresh random order (the paper: a
fixed order leaves artefacts and converges more slowly), then the amplitude projection (eq. 6).
:func:`pocs` is the solver on any kernel (a cast-shadow kernel works too); :func:`singh_ahuja`
builds the kernel of a diffuse object from its normals. The relative residual after every
iteration is returned to show the convergence.

Noise, or a model that cannot render the data exactly, leaves the residual sets with no common point,
and the sweeps then cycle. :func:`pocs` also offers relaxed projections and Combettes' extrapolated
parallel projections (``scheme='extrapolated'``), which converge to the least-squares point of the
amplitude set, and a stopping rule on the change per sweep (``tol``); the paper's scheme is the default.
:func:`dykstra_pocs` (``scheme='dykstra'``) gives a definite answer instead of wherever the path ends: the
projection of the start (zero: the least-norm map) onto the amplitude set and a residual-energy set whose
bound comes from the data (:func:`residual_bound`). :func:`least_power_pocs` (``scheme='least-power'``) adds a
third set, the maps of total power at most ``E``, with ``E`` the least at which it meets the amplitude set and an
L1 residual set bounded from the data (:func:`residual_l1_bound`): the sparsest map that fits, one linear
programme (HiGHS). Under noise that map loses power to the residual budget and jumps between vertices;
:func:`averaged_least_power` (the adaptive least-power scheme) refits each programme's lit sources and averages
the programmes of disjoint pixel subsets.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ffls.conventions import latlong_directions
from ffls.errors import InputError
from ffls.probes.hougen_ahuja import check_normals
from ffls.probes.linear import as_rgb_pixels, broadcast_albedo, lambert_matrix
from ffls.probes.selection import CRITERIA, Selection, bic, normal_blocks, refine_sources
from ffls.probes.sources import geodesic_level, latlong_solid_angles, sources_to_latlong

__all__ = ["BLOCK", "SCHEMES", "PROJECTION_SCHEMES", "PocsResult", "PocsSources", "pocs", "dykstra_pocs",
           "least_power_pocs", "averaged_least_power", "refit_support", "residual_bound", "residual_l1_bound",
           "ResidualEnergySet", "pixel_subset", "pixel_subsets",
           "singh_ahuja", "singh_ahuja_sources", "adaptive_singh_ahuja",
           "estimate_lighting_SinghAhuja"]


@dataclass(frozen=True)
class PocsResult:
    """Lighting recovered by POCS.

    Attributes
    ----------
    radiance : (h, 2h, 3) float64
        The recovered lat-long radiance on the solver's grid.
    residuals : (iterations + 1,) float64
        Relative RMS residual ``|g - H f| / |g|`` before the first and after every iteration.
    rendered : (m, 3) float64
        The input pixels re-rendered from the result (all pixels, not only those used).
    rms, relative_rms : float
        RMS of ``rendered - radiance`` and that over the input's RMS.
    iterations : int
    pixels_used : int
        Pixels (residual constraints) in each sweep.
    method : str
    """

    radiance: np.ndarray
    residuals: np.ndarray
    rendered: np.ndarray
    rms: float
    relative_rms: float
    iterations: int
    pixels_used: int
    method: str = "SinghAhuja"

    def latlong(self, height: int | None = None) -> np.ndarray:
        """The map at ``height`` (a multiple of the grid's: texels repeated, energy kept exactly)."""
        h = self.radiance.shape[0]
        if height is None or int(height) == h:
            return self.radiance.copy()
        height = int(height)
        if height % h:
            raise ValueError(f"map height {height} must be a multiple of the POCS grid height {h}")
        k = height // h
        return np.repeat(np.repeat(self.radiance, k, axis=0), k, axis=1)


#: Rows of the residual projections solved together in one triangular system (see :func:`pocs`):
#: their Gram matrix is ``BLOCK x BLOCK`` float64 (32 MB).
BLOCK = 2048


#: The schemes of :func:`pocs`: the paper's sequential sweeps, extrapolated parallel projections, Dykstra's
#: best approximation (the feasible map nearest the start, :func:`dykstra_pocs`), or the feasible map of least
#: total power (:func:`least_power_pocs`).
SCHEMES = ("sequential", "extrapolated", "dykstra", "least-power")
#: The schemes of :func:`pocs` that iterate projections from a start ``x0`` (with a stopping rule ``tol``); the
#: least-power scheme solves one linear programme instead.
PROJECTION_SCHEMES = SCHEMES[:3]


def pocs(H, g, iterations: int = 50, lower: float = 0.0, upper=None, delta: float = 0.0,
         order: str = "random", seed: int = 0, x0=None, scheme: str = "sequential", relaxation: float = 1.0,
         tol: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Projections onto convex sets for ``g ~ H f`` with ``lower <= f <= upper``.

    One sweep applies the residual projection of every row ``i`` once, in order,
    ``f += h_i (g_i - h_i . f) / |h_i|^2`` (``delta = 0``), then the amplitude projection (clipping).
    With ``delta = 0`` the step of row ``i`` is ``c_i = r_i / |h_i|^2`` with ``r_i`` the residual
    left by the rows before it, ``r_i = r0_i - sum_{k before i} (h_i . h_k) c_k``: the steps of a
    sweep solve the lower-triangular system ``(D + L) c = r0`` of the rows' Gram matrix in the
    sweep's order, and ``f += H^T c``. That is exactly the sequence of projections (the same
    arithmetic in another association), solved by ``scipy.linalg.solve_triangular`` in blocks of
    :data:`BLOCK` rows (``f`` is updated between blocks), instead of a Python loop over rows.
    ``delta > 0`` (a soft threshold per row) runs the projections one by one. A relaxation
    ``lambda`` in (0, 2) moves each row ``lambda`` times its projection's step (``lambda = 1``: the
    paper; the triangular system's diagonal is divided by ``lambda``).

    ``scheme='extrapolated'``: the residual projections in parallel, extrapolated (Combettes 1997,
    "Convex set theoretic image recovery by extrapolated iterations of parallel subgradient
    projections"), then the amplitude projection. The mean of the ``m`` row projections moves ``f`` by
    ``(1/m) Hn^T (gn - Hn f)`` (``Hn``, ``gn``: the rows scaled to unit norm, the preconditioning the
    projections imply). Combettes' extrapolation factor ``L(f) = m |gn - Hn f|^2 / |Hn^T (gn - Hn f)|^2``
    is at least ``m / s^2`` (``s`` the largest singular value of ``Hn``) for every ``f``; that bound
    is the factor used, times ``relaxation`` (in (0, 1] here), so that the step is the same at every
    iterate and an inertial extrapolation over iterations (Nesterov's, as in Beck and Teboulle's FISTA,
    restarted when it moves against the last step) can be added. With inconsistent sets (noise, a
    model that cannot render the data exactly) it converges to the point of the amplitude set nearest
    to the residual sets in the mean squared distance (Combettes 1994), i.e. the row-normalised
    non-negative least squares, where sequential sweeps of unrelaxed projections cycle. Each iteration
    costs two ``J x J`` products (the rows' Gram matrix ``Hn^T Hn`` is formed once), not ``m`` rows.
    ``delta`` must be 0.

    ``tol``: stop when a sweep changes ``f`` by less than ``tol`` times ``|f|`` (Frobenius), with
    ``iterations`` as the cap; ``None`` runs exactly ``iterations`` sweeps (the paper).

    Parameters
    ----------
    H : (m, J) array_like
        Kernel (one row per residual constraint).
    g : (m, c) array_like
        Data, ``c`` channels (solved together, one projection per row for all channels).
    iterations : int
        Sweeps; each applies every row's residual projection once, then the amplitude one.
    lower : float
        Lower amplitude bound.
    upper : float, (J,) array_like or None
        Upper amplitude bound, one for all unknowns or one each (``None``: no upper bound).
    delta : float
        Allowed residual magnitude per pixel (0 in the paper's experiments).
    order : {'random', 'sequential'}
        Order of the residual projections in a sweep: a fresh permutation each sweep, or 0..m-1.
    seed : int
        Seed of the permutations.
    x0 : (J, c) array_like, optional
        Start (zeros by default).
    scheme : {'sequential', 'extrapolated', 'dykstra', 'least-power'}
        The paper's sweeps of row projections, extrapolated parallel projections (above),
        :func:`dykstra_pocs` (the feasible point nearest ``x0``; ``delta`` 0 and ``relaxation`` 1), or
        :func:`least_power_pocs` (one linear programme: ``iterations`` and ``order`` unused; ``delta`` 0,
        ``relaxation`` 1, no ``tol`` or ``x0``).
    relaxation : float
        ``lambda``: in (0, 2) for ``'sequential'``, (0, 1] for ``'extrapolated'``.
    tol : float, optional
        Stopping rule on the relative change of ``f`` per sweep (``None``: a fixed sweep count).

    Returns
    -------
    f : (J, c) float64
    residuals : (sweeps + 1,) float64
        ``|g - H f| / |g|`` (Frobenius) at the start and after every sweep run.
    """
    from scipy.linalg import solve_triangular

    H = np.ascontiguousarray(H, dtype=np.float64)
    g = np.asarray(g, dtype=np.float64)
    if g.ndim == 1:
        g = g[:, None]
    m, J = H.shape
    if order not in ("random", "sequential"):
        raise ValueError(f"order must be 'random' or 'sequential', not {order!r}")
    if scheme not in SCHEMES:
        raise ValueError(f"scheme must be one of {SCHEMES}, not {scheme!r}")
    lam = float(relaxation)
    if not (0.0 < lam < 2.0) or (scheme == "extrapolated" and lam > 1.0):
        raise ValueError(f"relaxation {relaxation!r} must be in (0, 2) (sequential) or (0, 1] (extrapolated)")
    if scheme == "extrapolated" and float(delta) != 0.0:
        raise ValueError("scheme='extrapolated' projects onto the residual hyperplanes: delta must be 0")
    norm2 = np.einsum("ij,ij->i", H, H)
    if not np.any(norm2 > 0):
        raise InputError("singular system: no pixel is lit by any direction of the POCS model")
    rows = np.flatnonzero(norm2 > 0)
    f = np.zeros((J, g.shape[1])) if x0 is None else np.array(x0, dtype=np.float64).reshape(J, g.shape[1])
    hi = np.inf if upper is None else np.asarray(upper, dtype=np.float64)
    hi = hi.reshape(-1, 1) if np.ndim(hi) == 1 else hi
    gn = float(np.linalg.norm(g)) or 1.0
    res = [float(np.linalg.norm(g - H @ f)) / gn]
    rng = np.random.default_rng(seed)
    d = float(delta)
    gram = H[rows] @ H[rows].T if rows.size <= BLOCK and d == 0 else None
    Hn = H / np.where(norm2 > 0, norm2, 1.0)[:, None] if d > 0 else None
    if scheme == "dykstra":
        if d != 0.0 or lam != 1.0:
            raise ValueError("scheme='dykstra' projects exactly onto its two sets: delta must be 0, relaxation 1")
        return dykstra_pocs(H, g, iterations, lower, upper, x0=x0, tol=tol)
    if scheme == "least-power":
        _check_least_power(d, lam, tol, x0)
        return least_power_pocs(H, g, lower, upper)
    if scheme == "extrapolated":
        return _extrapolated(H[rows], g[rows], norm2[rows], f, lower, hi, lam, int(iterations), tol, g, gn, res)
    pos = np.full(m, -1, dtype=np.int64)
    pos[rows] = np.arange(rows.size)
    for _ in range(int(iterations)):
        prev = f.copy() if tol is not None else None
        seq = rng.permutation(rows) if order == "random" else rows
        if d > 0:
            for i in seq:
                r = g[i] - H[i] @ f
                r = np.where(r > d, r - d, np.where(r < -d, r + d, 0.0))
                f += lam * np.outer(Hn[i], r)
        else:
            for s in range(0, seq.size, BLOCK):
                blk = seq[s:s + BLOCK]
                Hb = H[blk]
                G = np.take(np.take(gram, pos[blk], axis=0), pos[blk], axis=1) if gram is not None else Hb @ Hb.T
                if lam != 1.0:
                    G[np.diag_indices_from(G)] /= lam
                c = solve_triangular(G, g[blk] - Hb @ f, lower=True, check_finite=False)
                f += Hb.T @ c
        np.clip(f, lower, hi, out=f)
        res.append(float(np.linalg.norm(g - H @ f)) / gn)
        if prev is not None and _settled(f, prev, tol):
            break
    return f, np.asarray(res)


def residual_bound(H, g, lower: float = 0.0, upper=None) -> np.ndarray:
    """Per channel, the bound ``eps`` of the residual-energy set ``{f : |g - H f| <= eps}`` from the data.

    ``r`` is the residual of the bounded least-squares fit (``scipy.optimize.lsq_linear``, the amplitude
    set's bounds), ``k`` the number of its unknowns strictly inside their bounds (the degrees of freedom
    the fit used). The noise variance is then estimated without bias as ``s^2 = r^2 / (m - k)`` and the
    set admits the residual a map would leave in that noise, ``eps^2 = m s^2`` (Morozov's discrepancy
    principle; Trussell and Civanlar's residual set). Model error (a source set that cannot render the
    true map) counts as noise: it is what no map on the set can fit.

    Parameters
    ----------
    H : (m, J) array_like
    g : (m, c) array_like
    lower, upper
        The amplitude set's bounds, as :func:`pocs`.

    Returns
    -------
    eps : (c,) float64
    """
    from scipy.optimize import lsq_linear

    H, g, lo, hi = _lp_arrays(H, g, lower, upper)
    m = H.shape[0]
    eps = np.empty(g.shape[1])
    for c in range(g.shape[1]):
        x = lsq_linear(H, g[:, c], bounds=(lo, hi), method="bvls").x
        k = int(np.count_nonzero((x > lo + 1e-12 * np.maximum(1.0, np.abs(lo))) & (x < hi)))
        r2 = float(np.sum((g[:, c] - H @ x) ** 2))
        # k >= m: the fit spends every degree of freedom of the data, and no noise can be estimated; the set is
        # then the fit's own residual (the narrowest that is not empty)
        eps[c] = np.sqrt(r2 * m / (m - k)) if k < m else np.sqrt(r2)
    return eps


class ResidualEnergySet:
    """The residual-energy set ``{f : |g_c - H f_c| <= eps_c}`` per channel ``c``, and its exact projection.

    With ``H = U S V^T`` (thin SVD), the projection of ``z`` is ``(I + mu H^T H)^{-1} (z + mu H^T g)``
    with ``mu >= 0`` the root of ``|g - H P(z)| = eps`` (``scipy.optimize.brentq`` on ``log mu``, in the
    singular basis), ``mu = 0`` when ``z`` is in the set, and the projection onto the exact-fit affine set
    when ``eps`` is the least-squares residual.

    Parameters
    ----------
    H : (m, J) array_like
    g : (m, c) array_like
    eps : float or (c,) array_like
        At least the unconstrained least-squares residual of each channel (else the set is empty).
    """

    def __init__(self, H, g, eps):
        H = np.asarray(H, dtype=np.float64)
        g = np.asarray(g, dtype=np.float64)
        self.g = g[:, None] if g.ndim == 1 else g
        self.H = H
        nc = self.g.shape[1]
        self.eps = np.broadcast_to(np.asarray(eps, dtype=np.float64), (nc,)).copy()
        U, s, Vt = np.linalg.svd(H, full_matrices=False)
        keep = s > s[0] * 1e-12 if s.size else s > 0
        self.U, self.s, self.Vt = U[:, keep], s[keep], Vt[keep]
        self.bc = self.U.T @ self.g                                # (k, c)
        self.gperp2 = np.sum((self.g - self.U @ self.bc) ** 2, axis=0)   # what no f can fit
        slack = 1e-9 * self.gperp2 + 1e-24 * np.sum(self.g ** 2, axis=0)
        if np.any(~np.isfinite(self.eps)) or np.any(self.eps ** 2 < self.gperp2 - slack):
            raise ValueError("eps is below the least-squares residual: the residual set is empty")

    def contains(self, f, rtol: float = 1e-9) -> bool:
        """Whether every channel of ``f`` (J, c) leaves a residual within its bound."""
        f = np.asarray(f, dtype=np.float64).reshape(self.H.shape[1], -1)
        r = np.linalg.norm(self.g - self.H @ f, axis=0)
        return bool(np.all(r <= self.eps * (1.0 + rtol) + 1e-12 * np.linalg.norm(self.g, axis=0)))

    def project(self, z) -> np.ndarray:
        """The nearest point of the set to ``z`` (J, c), in the Euclidean norm."""
        from scipy.optimize import brentq

        z = np.asarray(z, dtype=np.float64).reshape(self.H.shape[1], -1)
        s, s2, Vt, bc = self.s, self.s * self.s, self.Vt, self.bc
        out = z.copy()
        zc = Vt @ z
        for c in range(z.shape[1]):
            a = s * zc[:, c] - bc[:, c]
            e2 = self.eps[c] ** 2 - self.gperp2[c]

            def excess(t, a=a, e2=e2):
                return float(np.sum((a / (1.0 + np.exp(t) * s2)) ** 2)) - e2
            if float(np.sum(a * a)) <= e2:
                continue
            if e2 <= 0.0 or excess(200.0) > 0.0:                 # the exact-fit (affine) set
                fc = bc[:, c] / s
            else:
                mu = np.exp(brentq(excess, -690.0, 200.0, xtol=1e-12))
                fc = (zc[:, c] + mu * s * bc[:, c]) / (1.0 + mu * s2)
            out[:, c] += Vt.T @ (fc - zc[:, c])
        return out


def dykstra_pocs(H, g, iterations: int = 3000, lower: float = 0.0, upper=None, x0=None, weights=None, eps=None,
                 tol: float | None = 1e-7) -> tuple[np.ndarray, np.ndarray]:
    """The feasible map nearest a stated prior point: Dykstra's alternating projections (best approximation).

    Two convex sets: Singh and Ahuja's amplitude set ``A = {lower <= f <= upper}`` and the residual-energy
    set ``R = {f : |g - H f| <= eps}`` (the paper's per-pixel residual sets summed in squares, Trussell and
    Civanlar 1984; ``eps`` from the data, :func:`residual_bound`). Plain POCS stops at *some* point of
    ``A`` and ``R``, which depends on the start and the order: for a Lambertian ball that set is wide along
    the directions the ball cannot tell apart. Dykstra's algorithm (Boyle and Dykstra 1986) adds a
    correction per set to the alternating projections and converges to the *projection* of the start
    ``x0`` onto ``A`` and ``R``: with ``x0 = 0`` (the default) the feasible map of least energy
    ``sum_j w_j f_j^2``, a definite answer that no path changes.

    The projection onto ``R`` is exact: with ``H' = U S V^T`` (the rows in the weighted variables
    ``u = sqrt(w) f``), ``P_R(z) = (I + mu H'^T H')^{-1} (z + mu H'^T g)`` with ``mu >= 0`` the root of
    ``|g - H' P_R(z)| = eps`` (``scipy.optimize.brentq`` on the singular values; ``mu = 0`` when ``z``
    is in ``R``). Each channel is solved on its own.

    Parameters
    ----------
    H : (m, J) array_like
    g : (m, c) array_like
    iterations : int
        Cap on Dykstra cycles (each: one projection onto each set).
    lower, upper
        The amplitude set, as :func:`pocs`.
    x0 : (J, c) array_like, optional
        The prior point (zeros: minimum energy).
    weights : (J,) array_like, optional
        ``w`` of the energy ``sum w_j (f_j - x0_j)^2`` (ones by default; the solid-angle metric for radiance).
    eps : (c,) array_like, optional
        Residual bound per channel (default :func:`residual_bound`).
    tol : float, optional
        Stop when a cycle moves ``f`` by less than ``tol |f|``.

    Returns
    -------
    f : (J, c) float64
    residuals : (cycles + 1,) float64
        ``|g - H f| / |g|`` at the start and after every cycle.
    """
    H = np.asarray(H, dtype=np.float64)
    g = np.asarray(g, dtype=np.float64)
    g = g[:, None] if g.ndim == 1 else g
    m, J = H.shape
    nc = g.shape[1]
    w = np.ones(J) if weights is None else np.asarray(weights, dtype=np.float64).reshape(J)
    if not np.all(np.isfinite(w) & (w > 0)):
        raise ValueError("weights must be finite and positive")
    sw = np.sqrt(w)
    lo = np.broadcast_to(np.asarray(lower, dtype=np.float64), (J,)) * sw
    hi = np.broadcast_to(np.inf if upper is None else np.asarray(upper, dtype=np.float64), (J,)) * sw
    Hw = H / sw[None, :]
    if eps is None:
        eps = residual_bound(Hw, g, lo, None if upper is None else hi)
    eps = np.broadcast_to(np.asarray(eps, dtype=np.float64), (nc,))
    R = ResidualEnergySet(Hw, g, eps)

    u = np.zeros((J, nc)) if x0 is None else np.array(x0, dtype=np.float64).reshape(J, nc) * sw[:, None]
    gn = float(np.linalg.norm(g)) or 1.0
    res = [float(np.linalg.norm(g - Hw @ u)) / gn]
    p = np.zeros_like(u)
    q = np.zeros_like(u)
    for _ in range(int(iterations)):
        prev = u
        y = R.project(u + p)
        p = u + p - y
        u = np.clip(y + q, lo[:, None], hi[:, None])
        q = y + q - u
        res.append(float(np.linalg.norm(g - Hw @ u)) / gn)
        if tol is not None and _settled(u, prev, tol):
            break
    return u / sw[:, None], np.asarray(res)


def residual_l1_bound(H, g, lower: float = 0.0, upper=None) -> np.ndarray:
    """Per channel, the bound ``eps`` of the residual set ``{f : sum_i |g_i - h_i . f| <= eps}`` from the data.

    The L1 counterpart of :func:`residual_bound`: ``r`` is the least total absolute residual of a map in the
    amplitude set (the non-negative least-absolute-deviation fit, a linear programme solved by HiGHS through
    ``scipy.optimize.linprog``), ``k`` the number of its unknowns strictly inside their bounds, and the set
    admits the residual a map leaves in that much noise, ``eps = r m / (m - k)`` (Morozov's discrepancy
    principle; ``eps = r`` when ``k >= m``). Unlike the largest residual of a fit, the bound does not grow
    with the one worst pixel, and an outlier pixel (a highlight, a JPEG block) weighs in it as its distance,
    not its square.

    Parameters
    ----------
    H : (m, J) array_like
    g : (m, c) array_like
    lower, upper
        The amplitude set's bounds, as :func:`pocs`.

    Returns
    -------
    eps : (c,) float64
    """
    H, g, lo, hi = _lp_arrays(H, g, lower, upper)
    m, J = H.shape
    eps = np.empty(g.shape[1])
    for c in range(g.shape[1]):
        x, r = _least_absolute_deviation(H, g[:, c], lo, hi)
        tiny = 1e-9 * max(float(np.max(np.abs(x))), 1e-300)
        k = int(np.count_nonzero((x > lo + tiny) & (x < hi - tiny)))
        eps[c] = r * m / (m - k) if k < m else r
    return eps


def least_power_pocs(H, g, lower: float = 0.0, upper=None, eps=None, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """The feasible map of least total power: Singh and Ahuja's sets and a power set, solved as one LP.

    Three convex sets: the amplitude set ``A = {lower <= f <= upper}``; the residual set
    ``R1 = {f : sum_i |g_i - h_i . f| <= eps}`` (the paper's per-pixel residual sets, eq. 9-10, held in
    total rather than pixel by pixel, with ``eps`` from the data, :func:`residual_l1_bound`); and the
    power set ``P = {f : sum_j f_j <= E}`` with ``E`` the least value at which the three meet. With
    ``f_j`` a source's power (``singh_ahuja_sources``) ``sum_j f_j`` is the total power of the light; a
    Lambertian probe cannot tell apart many maps that fit it equally well, and the one of least power
    is the sparsest among them (few sources lit, as lamps and a sun are). The three sets then meet in a
    single point, which alternating projections reach only arbitrarily slowly; every set is a
    polyhedron, so the point is the solution of the linear programme
    ``min sum_j f_j`` subject to ``H f + p - q = g``, ``sum_i (p_i + q_i) <= eps``, ``p, q >= 0`` and
    ``f`` in ``A``, solved exactly (HiGHS through ``scipy.optimize.linprog``), one per channel.

    Why the residual is bounded in total: the paper's slabs ``|g_i - h_i . f| <= delta`` must be as wide as
    the largest noise sample to meet, and then admit a smooth error of that size on every pixel at once,
    which the least-power answer spends on moving light between the directions the ball barely tells apart
    (``docs/probes.md``, "The least total power").

    Parameters
    ----------
    H : (m, J) array_like
    g : (m, c) array_like
    lower, upper
        The amplitude set, as :func:`pocs`.
    eps : (c,) array_like, optional
        The L1 residual bound per channel (default :func:`residual_l1_bound`); at least the least
        absolute residual of a map in ``A``, else the sets do not meet.
    weights : (J,) array_like, optional
        The power of a unit of each unknown (ones: the unknowns are powers; a texel's solid angle when they
        are radiances, as :func:`singh_ahuja`'s grid). Each channel is solved scaled to unit mean absolute
        value (the LP is homogeneous in ``g``; HiGHS's tolerances are absolute), so the answer does not
        depend on the photograph's exposure.

    Returns
    -------
    f : (J, c) float64
    residuals : (2,) float64
        ``|g - H f| / |g|`` (Frobenius) at zero and at the answer.
    """
    from scipy import sparse
    from scipy.optimize import linprog

    H, g, lo, hi = _lp_arrays(H, g, lower, upper)
    m, J = H.shape
    eps = residual_l1_bound(H, g, lo, hi) if eps is None else np.broadcast_to(
        np.asarray(eps, dtype=np.float64), (g.shape[1],))
    w = np.ones(J) if weights is None else np.asarray(weights, dtype=np.float64).reshape(J)
    if not np.all(np.isfinite(w) & (w > 0)):
        raise ValueError("weights must be finite and positive")
    A_ub = sparse.csr_matrix(np.r_[np.zeros(J), np.ones(2 * m)][None, :])
    cost = np.r_[w, np.zeros(2 * m)]
    f = np.empty((J, g.shape[1]))
    for c in range(g.shape[1]):
        k = _unit_scale(g[:, c])
        A_eq, bounds = _l1_programme(H, lo / k, hi / k)
        # a hair of slack over the bound: at the least absolute residual the feasible set is a single face
        e = float(eps[c]) / k * (1.0 + 1e-9) + 1e-12 * m
        sol = linprog(cost, A_ub=A_ub, b_ub=[e], A_eq=A_eq, b_eq=g[:, c] / k, bounds=bounds, method="highs")
        if sol.status != 0:
            raise InputError(f"the least-power programme has no solution ({sol.message.strip()}): the residual "
                             f"bound {eps[c]:.4g} is below the least absolute residual the amplitude set allows")
        f[:, c] = np.clip(sol.x[:J] * k, lo, hi)
    gn = float(np.linalg.norm(g)) or 1.0
    return f, np.array([float(np.linalg.norm(g)) / gn, float(np.linalg.norm(g - H @ f)) / gn])


def _check_least_power(delta, relaxation, tol, x0=None) -> None:
    """Refuse the options of the iterative schemes, which the least-power programme does not take."""
    if float(delta) != 0.0 or float(relaxation) != 1.0 or tol is not None or x0 is not None:
        raise ValueError("scheme='least-power' solves one linear programme: delta must be 0, relaxation 1, "
                         "and it takes no tol or x0")


def _lp_arrays(H, g, lower, upper):
    """``(H, g, lo, hi)`` as float64: ``g`` (m, c), the bounds broadcast to (J,) (``inf`` with no upper);
    the arrays of :func:`residual_bound` and the linear programmes alike."""
    H = np.asarray(H, dtype=np.float64)
    g = np.asarray(g, dtype=np.float64).reshape(H.shape[0], -1)
    J = H.shape[1]
    lo = np.array(np.broadcast_to(np.asarray(lower, dtype=np.float64), (J,)))
    hi = np.array(np.broadcast_to(np.inf if upper is None else np.asarray(upper, dtype=np.float64).ravel(), (J,)))
    return H, g, lo, hi


def _l1_programme(H, lo, hi):
    """``(A_eq, bounds)`` of the variables ``[f, p, q]`` with ``H f + p - q = g``: ``f`` in ``[lo, hi]``,
    ``p, q >= 0`` (the residual's two parts, ``sum p + q`` its L1 norm at the optimum)."""
    from scipy import sparse

    m = H.shape[0]
    A_eq = sparse.hstack([sparse.csr_matrix(H), sparse.identity(m), -sparse.identity(m)], format="csr")
    return A_eq, np.r_[np.c_[lo, hi], np.tile([0.0, np.inf], (2 * m, 1))]


def _least_absolute_deviation(H, g, lo, hi) -> tuple[np.ndarray, float]:
    """``(x, r)``: ``x`` in ``[lo, hi]`` of least ``r = sum_i |g_i - h_i . x|`` (one channel; HiGHS).

    Solved through the dual programme, ``max g'^T y - u^T z`` subject to ``H^T y - z <= 0``, ``-1 <= y <= 1``,
    ``z >= 0`` (``g' = g - H lo``, ``u = hi - lo``; ``z`` only where ``u`` is finite): ``J`` rows against the
    primal's ``m`` (one per pixel), 1.6-3.7 times faster on the benchmark ball's 1000 pixels
    (``docs/probes.md``); ``x - lo`` is the rows' dual values, and ``r`` the optimum of both programmes.
    """
    from scipy import sparse
    from scipy.optimize import linprog

    m, J = H.shape
    k = _unit_scale(g)
    u = (hi - lo) / k
    fin = np.flatnonzero(np.isfinite(u))
    gp = (g - H @ lo) / k
    A = sparse.hstack([sparse.csr_matrix(H.T), -sparse.identity(J, format="csr")[:, fin]], format="csr")
    bounds = np.r_[np.tile([-1.0, 1.0], (m, 1)), np.tile([0.0, np.inf], (fin.size, 1))]
    sol = linprog(np.r_[-gp, u[fin]], A_ub=A, b_ub=np.zeros(J), bounds=bounds, method="highs")
    if sol.status != 0:
        raise InputError(f"the least-absolute-deviation fit has no solution ({sol.message.strip()})")
    x = np.clip(lo - sol.ineqlin.marginals * k, lo, hi)
    return x, float(np.sum(np.abs(g - H @ x)))


def _unit_scale(g) -> float:
    """The mean absolute value of ``g`` (1 if zero): the LPs are solved on ``g`` over it."""
    k = float(np.mean(np.abs(g)))
    return k if k > 0 and np.isfinite(k) else 1.0


def _settled(f, prev, tol) -> bool:
    """Whether the last sweep moved ``f`` by less than ``tol`` times its norm."""
    return float(np.linalg.norm(f - prev)) <= float(tol) * max(float(np.linalg.norm(f)), 1e-300)


def _extrapolated(Hr, gr, norm2, f, lower, hi, lam, iterations, tol, g, gn, res):
    """:func:`pocs`'s ``scheme='extrapolated'`` on the rows that constrain (``norm2 > 0``)."""
    s = np.sqrt(norm2)[:, None]
    Hn, gnr = Hr / s, gr / s
    A = Hn.T @ Hn                              # J x J: the mean projection is (b - A f) / m
    b = Hn.T @ gnr
    smax2 = float(np.linalg.eigvalsh(A)[-1])   # the largest singular value of Hn, squared
    step = lam / smax2                         # (lam m / s^2) x the mean projection's 1/m
    # the residual over all rows, |g - H f|^2 = |g|^2 - 2 <H^T g, f> + <f, H^T H f>, from J x J products
    HtH, Htg, g2 = Hr.T @ Hr, Hr.T @ gr, float(np.sum(g * g))

    def resid(x):
        return float(np.sqrt(max(g2 - 2.0 * np.sum(Htg * x) + np.sum(x * (HtH @ x)), 0.0))) / gn

    y, t = f.copy(), 1.0
    for _ in range(iterations):
        fn = np.clip(y + step * (b - A @ y), lower, hi)
        if np.sum((y - fn) * (fn - f)) > 0.0:   # the inertia moves against the step: restart it
            t = 1.0
        tn = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        y = fn + ((t - 1.0) / tn) * (fn - f)
        done = tol is not None and _settled(fn, f, tol)
        f, t = fn, tn
        res.append(resid(f))
        if done:
            break
    return f, np.asarray(res)


def _pixels(normals, radiance, albedo):
    """``(n, b, rho, g)``: checked normals ``(m, 3)``, RGB radiance, albedo and irradiance ``pi b / rho``.

    Raises ``InputError`` with no pixels.
    """
    n = check_normals(normals)
    m = n.shape[0]
    if m == 0:
        raise InputError("no pixels to fit")
    b = as_rgb_pixels(radiance, m)
    rho = broadcast_albedo(albedo, m)
    return n, b, rho, np.pi * b / rho


def singh_ahuja(normals, radiance, albedo=1.0, height: int = 16, iterations: int = 50, upper: float | None = None,
                delta: float = 0.0, order: str = "random", seed: int = 0, max_pixels: int | None = 2000,
                visibility=None, scheme: str = "sequential", relaxation: float = 1.0,
                tol: float | None = None) -> PocsResult:
    """Recover a lat-long map from a Lambertian object's pixels by POCS (Singh and Ahuja).

    Parameters
    ----------
    normals : (m, 3) array_like
        Unit world-frame normals of the pixels.
    radiance : (m,) or (m, 3) array_like
        Their linear values.
    albedo : float, (3,), (m,) or (m, 3) array_like
        ``rho`` (pixel = ``rho / pi`` x irradiance); divided out before the solve.
    height : int
        Height of the lat-long grid of unknowns (width ``2 height``; the survey used 16 x 16,
        the paper 64 x 64).
    iterations : int
        Sweeps (the paper: 50).
    upper : float, optional
        Upper amplitude bound ``L`` on the radiance (none by default).
    delta : float
        Allowed residual per pixel, in irradiance units (0 in the paper).
    order : {'random', 'sequential'}
    seed : int
    max_pixels : int, optional
        Use at most this many pixels (a fixed-seed random subset) as residual constraints, to
        bound the time of the sequential sweeps; ``rendered`` covers every pixel.
    visibility : (m, h * 2h) array_like of bool, optional
        Occlusion of each grid direction at each pixel (a cast-shadow kernel); none by default.
    scheme, relaxation, tol
        As :func:`pocs` (the defaults: the paper's sequential sweeps, a fixed count).

    Returns
    -------
    PocsResult
    """
    n, b, rho, g = _pixels(normals, radiance, albedo)
    m = n.shape[0]
    h = int(height)
    if h < 2:
        raise ValueError(f"POCS grid height must be >= 2, not {height!r}")
    dirs = latlong_directions(2 * h, h).reshape(-1, 3)
    sa = latlong_solid_angles(h).ravel()
    H = lambert_matrix(n, dirs, visibility) * sa[None, :]
    use = np.arange(m)
    if max_pixels is not None and m > int(max_pixels):
        use = np.sort(np.random.default_rng(seed).choice(m, int(max_pixels), replace=False))
    if scheme == "dykstra":   # the feasible radiances of least Euclidean norm
        if float(delta) != 0.0 or float(relaxation) != 1.0:
            raise ValueError("scheme='dykstra' projects exactly onto its two sets: delta must be 0, relaxation 1")
        f, res = dykstra_pocs(H[use], g[use], iterations, 0.0, upper, tol=tol)
    elif scheme == "least-power":   # the unknowns are radiances: a texel's power is its radiance times its solid angle
        _check_least_power(delta, relaxation, tol)
        f, res = least_power_pocs(H[use], g[use], 0.0, upper, weights=sa)
    else:
        f, res = pocs(H[use], g[use], iterations, 0.0, upper, delta, order, seed, scheme=scheme,
                      relaxation=relaxation, tol=tol)
    rendered = (H @ f) * rho / np.pi
    rms = float(np.sqrt(np.mean((rendered - b) ** 2)))
    ref = float(np.sqrt(np.mean(b ** 2)))
    return PocsResult(radiance=f.reshape(h, 2 * h, 3), residuals=res, rendered=rendered, rms=rms,
                      relative_rms=rms / ref if ref > 0 else np.inf, iterations=int(res.size - 1),
                      pixels_used=int(use.size))


#: The colour-hdri style name of :func:`singh_ahuja`.
estimate_lighting_SinghAhuja = singh_ahuja


# ----------------------------------------------------------------------------- adaptive source sets
@dataclass(frozen=True)
class PocsSources:
    """Source powers recovered by POCS over a set of source directions (an adaptive geodesic set).

    Attributes
    ----------
    directions : (n, 3) float64
        The sources (world frame, unit).
    intensities : (n, 3) float64
        Irradiance at normal incidence of each source (its cell's power), ``>= 0``.
    rendered : (m, 3) float64
        Every input pixel re-rendered from the result.
    rms, relative_rms : float
        RMS of ``rendered - radiance``, and that over the input's RMS.
    residuals : (iterations + 1,) float64
        Relative residual ``|g - H f| / |g|`` over the pixels used, before the first and after every sweep.
    iterations, pixels_used : int
    hemisphere : str or dict
        Domain of the sources.
    method : str
    """

    directions: np.ndarray
    intensities: np.ndarray
    rendered: np.ndarray
    rms: float
    relative_rms: float
    residuals: np.ndarray
    iterations: int
    pixels_used: int
    hemisphere: object = "full"
    method: str = "SinghAhuja"

    def latlong(self, height: int = 64) -> np.ndarray:
        """The lighting as lat-long radiance (height, 2 height, 3): each source spread over its Voronoi cell."""
        return sources_to_latlong(self.directions, self.intensities, height, self.hemisphere)


def pixel_subset(m: int, max_pixels: int | None, seed: int = 0) -> np.ndarray:
    """Sorted indices of at most ``max_pixels`` of ``m`` pixels (a fixed-seed random subset; all if None)."""
    if max_pixels is None or m <= int(max_pixels):
        return np.arange(m)
    return np.sort(np.random.default_rng(seed).choice(m, int(max_pixels), replace=False))


def pixel_subsets(m: int, max_pixels: int | None, count: int, seed: int = 0) -> list[np.ndarray]:
    """Up to ``count`` disjoint sorted index sets of ``m`` pixels, each of about ``max_pixels``.

    The first is :func:`pixel_subset`'s (``seed``); the others split the remaining pixels (a permutation from
    ``default_rng(seed)``) into as many parts of about ``max_pixels`` as they fill (the count rounded: each part
    holds 0.67 to 1.5 times ``max_pixels``), at most ``count - 1``, of exactly ``max_pixels`` when capped. All
    pixels in one set when ``max_pixels`` is None or at least ``m``.
    """
    count = int(count)
    if count < 1:
        raise ValueError(f"count must be >= 1, not {count!r}")
    first = pixel_subset(m, max_pixels, seed)
    if count == 1 or first.size == m:
        return [first]
    size = int(max_pixels)
    rest = np.setdiff1d(np.arange(m), first)
    fill = int(round(rest.size / size))
    k = min(count - 1, fill)
    if k < 1:
        return [first]
    perm = np.random.default_rng(seed).permutation(rest)[:rest.size if k == fill else k * size]
    return [first] + [np.sort(part) for part in np.array_split(perm, k)]


def singh_ahuja_sources(normals, radiance, albedo=1.0, directions=None, iterations: int = 50, upper=None,
                        delta: float = 0.0, order: str = "random", seed: int = 0, max_pixels: int | None = 2000,
                        x0=None, scheme: str = "sequential", relaxation: float = 1.0,
                        tol: float | None = None) -> PocsSources:
    """POCS (Singh and Ahuja's projections) over a kernel built on explicit source directions.

    The unknown ``f_j >= 0`` is the power of source ``j`` (the irradiance it gives a surface
    facing it), and the kernel is ``H(x, j) = max(0, n_x . w_j)``: the same residual and amplitude
    projections as :func:`singh_ahuja`, on a source set instead of the lat-long grid (each source
    then stands for its angular Voronoi cell, :meth:`PocsSources.latlong`).

    Parameters
    ----------
    normals, radiance, albedo
        As :func:`singh_ahuja`.
    directions : (n, 3) array_like
        Unit source directions.
    iterations, delta, order, seed, max_pixels
        As :func:`singh_ahuja`.
    upper : float, optional
        Upper amplitude bound on the *radiance*: source ``j`` is bounded by ``upper`` times its
        cell's solid angle (:func:`ffls.probes.sources.cell_solid_angles`).
    x0 : (n, 3) array_like, optional
        Start of the iterations (zeros by default).
    scheme, relaxation, tol
        As :func:`pocs`.

    Returns
    -------
    PocsSources
    """
    n, b, rho, g = _pixels(normals, radiance, albedo)
    m = n.shape[0]
    if directions is None:
        raise ValueError("directions are required")
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    H = lambert_matrix(n, d)
    use = pixel_subset(m, max_pixels, seed)
    hi = _source_upper(d, upper)
    if scheme == "dykstra":   # the feasible powers of least Euclidean norm
        if float(delta) != 0.0 or float(relaxation) != 1.0:
            raise ValueError("scheme='dykstra' projects exactly onto its two sets: delta must be 0, relaxation 1")
        f, res = dykstra_pocs(H[use], g[use], iterations, 0.0, hi, x0, tol=tol)
    else:
        f, res = pocs(H[use], g[use], iterations, 0.0, hi, delta, order, seed, x0, scheme, relaxation, tol)
    rendered = (H @ f) * rho / np.pi
    rms = float(np.sqrt(np.mean((rendered - b) ** 2)))
    ref = float(np.sqrt(np.mean(b ** 2)))
    return PocsSources(directions=d, intensities=f, rendered=rendered, rms=rms,
                       relative_rms=rms / ref if ref > 0 else np.inf, residuals=res, iterations=int(res.size - 1),
                       pixels_used=int(use.size))


def _source_upper(directions, upper):
    """The amplitude bound of each source's power: ``upper`` (a radiance) times its cell's solid angle."""
    from ffls.probes.sources import cell_solid_angles

    return None if upper is None else float(upper) * cell_solid_angles(directions, "full")


def refit_support(H, g, f, lower: float = 0.0, upper=None) -> np.ndarray:
    """The least-squares powers on the unknowns ``f`` lights, within the amplitude set (per channel).

    ``f`` (J, c): a sparse answer (the least-power map). Its nonzero unknowns (above ``1e-9`` of the channel's
    largest) are refitted by bounded least squares (``scipy.optimize.lsq_linear``, BVLS), the others stay 0:
    the sources the programme chose keep, the power the L1 residual budget took from them is given back (the
    relaxed lasso's refit, Meinshausen 2007).

    Returns
    -------
    (J, c) float64
    """
    from scipy.optimize import lsq_linear

    H, g, lo, hi = _lp_arrays(H, g, lower, upper)
    f = np.asarray(f, dtype=np.float64).reshape(H.shape[1], g.shape[1])
    out = np.zeros_like(f)
    for c in range(g.shape[1]):
        S = np.flatnonzero(f[:, c] > 1e-9 * max(float(f[:, c].max()), 1e-300))
        if S.size:
            out[S, c] = np.clip(lsq_linear(H[:, S], g[:, c], bounds=(lo[S], hi[S]), method="bvls").x, lo[S], hi[S])
    return out


def averaged_least_power(normals, radiance, albedo, directions, upper=None, max_pixels: int | None = 2000,
                         subsets: int = 4, seed: int = 0, refit: bool = True) -> PocsSources:
    """The least-power powers of a source set (:func:`least_power_pocs`), averaged over disjoint pixel subsets.

    One programme per subset of :func:`pixel_subsets` (``max_pixels``, ``subsets``, ``seed``; the first subset
    is :func:`pixel_subset`'s, the pixels an adaptive set is chosen on), the sources each lights refitted by
    bounded least squares on its pixels (:func:`refit_support`), and the mean of their maps. Noise does two things
    to a least-power map: the residual budget it allows is spent on removing power (the L1 shrinkage of the
    lasso: studio relit with 8% less power than its true cells), which the refit gives back; and the answer, a
    vertex of its programme, jumps from vertex to vertex (power moved between sources the ball barely tells
    apart), which the mean over independent pixels averages out, where one programme over all the pixels costs
    far more and was no better (``docs/probes.md``, "Noise: refitted least-power maps averaged over pixel
    subsets").

    Parameters
    ----------
    normals, radiance, albedo, directions, upper
        As :func:`singh_ahuja_sources`.
    max_pixels : int, optional
        Pixels per programme (None: one programme over all).
    subsets : int
        At most this many programmes.
    seed : int
    refit : bool
        Refit each programme's lit sources (default); False with ``subsets=1``: :func:`singh_ahuja_sources` with
        ``scheme='least-power'``.

    Returns
    -------
    PocsSources
        ``residuals`` over the first subset (at zero and at the mean), ``pixels_used`` over all subsets,
        ``rendered`` every pixel.
    """
    if int(subsets) != subsets or subsets < 1:
        raise ValueError(f"subsets must be an integer >= 1, not {subsets!r}")
    n, b, rho, g = _pixels(normals, radiance, albedo)
    parts = pixel_subsets(n.shape[0], max_pixels, subsets, seed)
    fits = [singh_ahuja_sources(n[p], b[p], rho[p], directions, upper=upper, max_pixels=None, scheme="least-power")
            for p in parts]
    d = fits[0].directions
    if refit:
        hi = _source_upper(d, upper)
        f = np.mean([refit_support(lambert_matrix(n[p], d), g[p], x.intensities, 0.0, hi)
                     for p, x in zip(parts, fits)], axis=0)
    else:
        f = np.mean([x.intensities for x in fits], axis=0)
    g0 = g[parts[0]]
    gn = float(np.linalg.norm(g0)) or 1.0
    res = np.array([float(np.linalg.norm(g0)) / gn,
                    float(np.linalg.norm(g0 - lambert_matrix(n[parts[0]], d) @ f)) / gn])
    rendered = lambert_matrix(n, d) @ f * rho / np.pi
    return replace(fits[0], intensities=f, rendered=rendered, residuals=res, pixels_used=sum(p.size for p in parts),
                   **_rms_of(rendered, b))


def _rms_of(rendered, b) -> dict:
    """``rms`` and ``relative_rms`` of ``rendered`` against the pixels ``b``, as keyword arguments."""
    rms = float(np.sqrt(np.mean((rendered - b) ** 2)))
    ref = float(np.sqrt(np.mean(b ** 2)))
    return dict(rms=rms, relative_rms=rms / ref if ref > 0 else np.inf)


def adaptive_singh_ahuja(normals, radiance, albedo=1.0, iterations: int = 50, upper=None, order: str = "random",
                         seed: int = 0, max_pixels: int | None = 2000, criterion: str = "cv", folds: int = 5,
                         tolerance: float = 0.05, base_frequency: int = 3, max_sources: int = 500, max_level: int = 3,
                         power_share: float = 0.5, patience: int = 2, scheme: str = "sequential",
                         relaxation: float = 1.0, tol: float | None = None, subsets: int = 4):
    """POCS over an adaptive geodesic source set: Singh and Ahuja's projections where the light is.

    The set is grown by :func:`ffls.probes.selection.refine_sources`, as for Hougen and Ahuja
    (:func:`ffls.probes.selection.adaptive_hougen_ahuja`): 92 directions at first, then each round
    splits the fewest sources that carry half the power POCS recovered, down to nodes 2.6 degrees
    apart, and the round is chosen by blocked cross-validation (the pixels grouped by the
    direction of their normal; each fold is fitted by POCS on the other folds' pixels and
    scored on its own) or by BIC on the fit to all pixels. Every round runs ``iterations``
    sweeps from zero (as the paper's grid; starting a round from the previous round's powers was
    worse on every map of ``benchmarks/probes.py``, ``docs/probes.md``); the chosen round's residual
    after every sweep is kept (``fit.residuals``).

    Parameters
    ----------
    normals, radiance, albedo
        As :func:`singh_ahuja`.
    iterations, upper, order, seed
        As :func:`singh_ahuja_sources`.
    max_pixels : int, optional
        The selection and every fit use at most this many pixels (a fixed-seed random subset);
        the result re-renders all.
    criterion : {'cv', 'bic'}
    folds, tolerance
        As :func:`ffls.probes.selection.select_model`.
    base_frequency, max_sources, max_level, power_share, patience
        As :func:`ffls.probes.selection.refine_sources`.
    scheme, relaxation, tol
        As :func:`pocs`, for every fit; with ``scheme='least-power'`` the rounds are fitted and chosen by the
        paper's sweeps (``iterations``, ``order``, ``seed``, ``relaxation``, ``tol``), and the chosen set's
        powers are then :func:`averaged_least_power`'s: :func:`least_power_pocs` on up to ``subsets`` disjoint
        pixel subsets, each map's lit sources refitted, averaged.
    subsets : int
        ``scheme='least-power'``: the least-power map is solved on up to this many disjoint subsets of about
        ``max_pixels`` pixels (:func:`pixel_subsets`: the first the one the set was chosen on, the others from
        the remaining pixels, as many as they fill), as :func:`averaged_least_power`. 1: one programme, on the
        selection's pixels (refitted).

    Returns
    -------
    ffls.probes.selection.Selection
        ``fit`` is the chosen round's :class:`PocsSources` (on all pixels), ``chosen`` its number
        of sources, ``candidates`` and ``scores`` the rounds', ``note`` one line for the user.
    """
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, not {criterion!r}")
    if int(subsets) != subsets or subsets < 1:
        raise ValueError(f"subsets must be an integer >= 1, not {subsets!r}")
    n, b, rho, _ = _pixels(normals, radiance, albedo)
    m = n.shape[0]
    use = pixel_subset(m, max_pixels, seed)
    # least-power: the rounds are grown and chosen by the paper's sweeps, whose spread-out powers show where the
    # light is; the chosen set's powers are then the least-power map (its sparse powers, refined, lock the set
    # onto the wrong directions: docs/probes.md, "The least total power")
    kw = dict(iterations=iterations, upper=upper, order=order, seed=seed, max_pixels=None,
              scheme="sequential" if scheme == "least-power" else scheme, relaxation=relaxation, tol=tol)

    def fit_all(d):
        return singh_ahuja_sources(n[use], b[use], rho[use], d, **kw)

    if criterion == "bic":
        def score(d, fit):
            return bic(fit.rendered, b[use], d.shape[0])
    else:
        lab = normal_blocks(n[use])
        ub, inv = np.unique(lab, return_inverse=True)
        k = min(int(folds), ub.size)
        if k < 2:
            raise InputError("cross-validation needs at least two blocks of pixels")
        fold = (np.random.default_rng(seed).permutation(ub.size) % k)[inv.ravel()]
        y = b[use]
        scale = max(float(np.sqrt(np.mean(y ** 2))), 1e-300)

        def score(d, fit):
            err = 0.0
            for j in range(k):
                tr, te = use[fold != j], use[fold == j]
                f = singh_ahuja_sources(n[tr], b[tr], rho[tr], d, **kw).intensities
                err += float(np.sum((lambert_matrix(n[te], d) @ f * rho[te] / np.pi - b[te]) ** 2))
            return float(np.sqrt(err / y.size)) / scale

    # with few pixels, start coarser (as adaptive_hougen_ahuja): a fold must hold more pixels than unknowns
    f0 = max(int(base_frequency), 1)
    while f0 > 1 and geodesic_level(f0, 0, "full").shape[0] > 0.8 * use.size:
        f0 -= 1
    sel = refine_sources(fit_all, score, f0, "full", max_sources, max_level, power_share, patience, criterion,
                         tolerance)
    # the chosen round's sources, re-rendered on every pixel
    fit = sel.fit
    if scheme == "least-power":
        full = averaged_least_power(n, b, rho, fit.directions, upper, max_pixels, subsets, seed)
    else:
        rendered = lambert_matrix(n, fit.directions) @ fit.intensities * rho / np.pi
        full = replace(fit, rendered=rendered, **_rms_of(rendered, b))
    note = sel.note.replace("adaptive sources", "POCS over adaptive sources", 1)
    return Selection(chosen=sel.chosen, candidates=sel.candidates, scores=sel.scores, criterion=sel.criterion,
                     fit=full, note=note)
