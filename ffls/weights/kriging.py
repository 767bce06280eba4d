"""Kriging (Gaussian-process) weights, the kernel learnt from the capture's own photos.

Each pixel's value as a function of the light direction, ``f(l)``, is modelled as a Gaussian
process on the sphere: a linear trend ``b0 + b . l`` (universal kriging) plus a stationary
Matérn field with covariance ``k(l, l') = m_nu(|l - l'| / length)`` in the chord distance, plus
a nugget ``tau`` (the part of ``f`` that varies faster than the lights are spaced: hard shadow
edges and highlights, which the photos alias). The posterior mean at a direction ``p`` is
``sum_j w_j(p) f(l_j)``, with the kriging weights

``[w(p); mu] = [[K + tau I, P], [P^T, 0]]^-1 [k(p); 1, p]``

(Matheron 1963; Cressie, "Statistics for spatial data", 1993, section 3.4; the same linear map
is the Bayesian quadrature rule when integrated against a light map: O'Hagan, "Bayes-Hermite
quadrature", J. Stat. Plan. Inference 29, 1991). The Matérn functions with ``nu`` = 1/2, 3/2,
5/2 are positive definite in R^3 and so on the sphere with the chord distance (Gneiting,
"Strictly and non-strictly positive definite functions on spheres", Bernoulli 19, 2013,
section 4; Wendland 2005, ch. 6).

**Learnt from the capture.** ``nu``, ``length`` and ``tau`` are those with the least
leave-one-out error of predicting every photo from the others (:func:`fit_kernel`), in closed
form for all photos at once (Dubrule 1983: the residual of photo ``i`` is ``(A^-1 Y)_i /
(A^-1)_ii`` with ``A`` the bordered system and ``Y`` the photos): no ground truth, no light map.
The candidate lengths are multiples of the capture's median light spacing, so the grid scales
with the capture; the nugget is a share of the field's variance (the weights depend only on
``tau``, not on the photos' scale).

**Properties.**

* **Sums to 1.** The constant is in the trend, so ``sum_j w_j(p) = 1`` for every ``p``: the map's
  power is conserved exactly (each row is made to sum to 1 to rounding). Weights may be negative.
* **Smooth.** ``w(p)`` is as smooth as ``k``: continuous for every ``nu`` (no cell borders to
  pop across).
* **Global, truncated for the GPU.** Every light has some weight at every direction; the
  weights decay fast away from ``p`` (the Lagrange functions of Matérn kernels decay
  exponentially). :meth:`Kriging.__call__` keeps the ``slots`` largest ``|w_j|`` per direction,
  soft-thresholded at the next one (so the truncated weights stay continuous as lights enter
  and leave the kept set), with the dropped part shared in proportion to ``|w|``: rows still
  sum to 1 and the
  :class:`ffls.weights.weighting.WeightTexture` (pass 1 of the GPU) holds them;
  :meth:`Kriging.dense` is the untruncated reference.
* **Degenerate captures.** With fewer than 4 distinct lights, or all on one plane, the trend is
  the constant alone (ordinary kriging); one light takes weight 1 everywhere.

Measured (docs/weighting.md, "Kriging with a kernel learnt from the capture"): 0.812 of
barycentric's relit error on four real HDR maps (100 lights, three rotations; ``spline`` 0.903),
0.610 on ``benchmarks/tradeoff.py``'s capture (``spline`` 0.700); issue 12's 0.8 is not reached
on the first; 0.752 on independent Mitsuba renders (``benchmarks/tradeoff_mitsuba.py``).
Offered by ``--weighting kriging``: each relighter learns the kernel from its own basis when the
scheme is first chosen (:class:`KernelLearner`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["NUS", "LENGTH_FACTORS", "NUGGETS", "DEFAULT_NU", "DEFAULT_LENGTH_FACTOR", "DEFAULT_NUGGET",
           "DEFAULT_SLOTS", "MAX_LEBESGUE", "matern", "light_spacing", "KernelFit", "loo_errors", "fit_kernel", "Kriging",
           "KernelLearner"]

#: Matérn smoothness parameters offered (closed forms: exponential, once and twice differentiable).
NUS = (0.5, 1.5, 2.5)
#: Candidate lengths of :func:`fit_kernel`, in units of the capture's median light spacing
#: (a kernel narrower than the spacing cannot link neighbours; one wider than ~15 spacings is
#: nearly the trend alone), log-spaced.
LENGTH_FACTORS = (0.75, 1.0, 1.5, 2.0, 3.0, 4.5, 7.0, 10.0, 15.0)
#: Candidate nuggets of :func:`fit_kernel` (share of the field's variance), log-spaced from
#: nearly interpolating to heavily smoothing.
NUGGETS = (1e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3)
#: Defaults when no photos are given to learn from (Matérn 3/2, 2 spacings, 2 % nugget: the
#: middle of the grid, not a fitted value).
DEFAULT_NU = 1.5
DEFAULT_LENGTH_FACTOR = 2.0
DEFAULT_NUGGET = 0.02
#: Lights kept per direction for the GPU's weight texture (the spline scheme's 24).
DEFAULT_SLOTS = 24
#: Pixels used by the leave-one-out fit (a random subset: the error is a mean over pixels).
_LOO_PIXELS = 4096


def matern(cos_angle: np.ndarray, nu: float, length: float) -> np.ndarray:
    """Matérn covariance (variance 1) of the chord ``r = sqrt(2 - 2 cos)``, ``nu`` in :data:`NUS`."""
    r = np.sqrt(np.maximum(2.0 - 2.0 * np.asarray(cos_angle, dtype=np.float64), 0.0))
    if nu == 0.5:
        return np.exp(-r / length)
    if nu == 1.5:
        a = np.sqrt(3.0) * r / length
        return (1.0 + a) * np.exp(-a)
    if nu == 2.5:
        a = np.sqrt(5.0) * r / length
        return (1.0 + a + a * a / 3.0) * np.exp(-a)
    raise ValueError(f"nu must be one of {NUS}, not {nu!r}")


def light_spacing(directions: np.ndarray) -> float:
    """Median chord from each light to its nearest other light (2.0 for a single light)."""
    d = np.asarray(directions, dtype=np.float64)
    if d.shape[0] < 2:
        return 2.0
    g = d @ d.T
    np.fill_diagonal(g, -np.inf)
    return float(np.median(np.sqrt(np.maximum(2.0 - 2.0 * g.max(axis=1), 0.0))))


def _trend(p: np.ndarray, linear: bool) -> np.ndarray:
    return np.concatenate([np.ones((p.shape[0], 1)), p], axis=1) if linear else np.ones((p.shape[0], 1))


def _linear_ok(d: np.ndarray) -> bool:
    """The linear trend ``1, x, y, z`` is unisolvent on these directions (>= 4, not all on a plane)."""
    if d.shape[0] < 4:
        return False
    sv = np.linalg.svd(d - d.mean(axis=0), compute_uv=False)
    return bool(sv[-1] > 1e-6 * max(sv[0], 1e-12))


def _bordered(d: np.ndarray, nu: float, length: float, nugget: float, linear: bool) -> np.ndarray:
    n = d.shape[0]
    P = _trend(d, linear)
    m = P.shape[1]
    a = np.zeros((n + m, n + m))
    a[:n, :n] = matern(d @ d.T, nu, length) + nugget * np.eye(n)
    a[:n, n:] = P
    a[n:, :n] = P.T
    return a


@dataclass(frozen=True)
class KernelFit:
    """The kernel chosen by :func:`fit_kernel`.

    Attributes
    ----------
    nu, length, nugget : float
        Matérn smoothness, length (chord), nugget (share of variance).
    loo : float
        Relative leave-one-out error ``||residuals|| / ||photos||`` of the chosen kernel.
    spacing : float
        The capture's median light spacing (chord) the length grid was scaled by.
    table : dict
        ``(nu, length_factor, nugget) -> loo`` of every candidate.
    """

    nu: float
    length: float
    nugget: float
    loo: float
    spacing: float
    table: dict = field(repr=False, default_factory=dict)

    @property
    def options(self) -> dict:
        """The :class:`ffls.weights.weighting.Weighting` options of this kernel."""
        return {"nu": self.nu, "length": self.length, "nugget": self.nugget}

    def describe(self) -> str:
        """One line: the kernel and its leave-one-out error."""
        return (f"Matern nu {self.nu:g}, length {self.length:.3g} (chord; {self.length / self.spacing:.2g} light "
                f"spacings), nugget {self.nugget:g}; "
                f"leave-one-out error {self.loo:.3g}")


def _sample_pixels(photos, n: int, n_pixels: int, seed: int) -> np.ndarray:
    flat = np.asarray(photos).reshape(n, -1)
    if flat.shape[1] > n_pixels:
        cols = np.sort(np.random.default_rng(seed).choice(flat.shape[1], n_pixels, replace=False))
        flat = flat[:, cols]
    y = flat.astype(np.float64)
    if not np.all(np.isfinite(y)):
        raise ValueError("photos contain NaN or Inf")
    return y


def loo_errors(directions, photos, nu: float, length: float, nugget: float,
               n_pixels: int = _LOO_PIXELS, seed: int = 0) -> float:
    """Relative leave-one-out error of predicting each photo from the others with one kernel.

    Parameters
    ----------
    directions : (n, 3) array_like
        Distinct unit light directions.
    photos : (n, ...) array_like
        The photos (any pixel shape), one per light.

    Returns
    -------
    float
        ``sqrt(sum_i ||f_i - pred_i||^2 / sum_i ||f_i||^2)`` over ``n_pixels`` random pixels.
    """
    d = np.asarray(directions, dtype=np.float64)
    n = d.shape[0]
    y = _sample_pixels(photos, n, n_pixels, seed)
    return _loo(d, y, nu, length, nugget, _linear_ok(d))


def _loo(d, y, nu, length, nugget, linear) -> float:
    n = d.shape[0]
    try:
        ai = np.linalg.inv(_bordered(d, nu, length, nugget, linear))[:n, :n]
    except np.linalg.LinAlgError:
        return float("inf")
    diag = np.diag(ai)
    if np.any(diag <= 0):
        return float("inf")
    r = (ai @ y) / diag[:, None]
    den = float(np.sum(y * y))
    return float(np.sqrt(np.sum(r * r) / den)) if den > 0 else float("inf")


def fit_kernel(directions, photos, nus=NUS, length_factors=LENGTH_FACTORS, nuggets=NUGGETS,
               n_pixels: int = _LOO_PIXELS, seed: int = 0) -> KernelFit:
    """Choose ``nu``, ``length`` and ``nugget`` by leave-one-out on the capture's photos.

    Every candidate of the grid ``nus x length_factors x nuggets`` (lengths in units of
    :func:`light_spacing`) predicts each photo from the others (closed form, :func:`loo_errors`);
    the one with the least error is kept. Needs at least 5 distinct lights (one to leave out
    of a linear trend's four).

    Parameters
    ----------
    directions : (n, 3) array_like
        Unit light directions (distinct).
    photos : (n, ...) array_like
        One photo per light, linear values.

    Returns
    -------
    KernelFit
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = d.shape[0]
    if n < 5:
        raise ValueError(f"fitting a kriging kernel needs at least 5 lights, not {n}")
    if np.asarray(photos).shape[0] != n:
        raise ValueError("photos must have one image per direction")
    y = _sample_pixels(photos, n, n_pixels, seed)
    linear = _linear_ok(d)
    h = light_spacing(d)
    table = {}
    for nu in nus:
        for f in length_factors:
            for tau in nuggets:
                table[(float(nu), float(f), float(tau))] = _loo(d, y, nu, f * h, tau, linear)
    (nu, f, tau), best = min(table.items(), key=lambda kv: kv[1])
    if not np.isfinite(best):
        raise ValueError("no kriging kernel could be fitted to these photos (all systems singular)")
    return KernelFit(nu=nu, length=f * h, nugget=tau, loo=best, spacing=h, table=table)


#: Largest sum of |weights| a direction may have (its Lebesgue constant: how much the photos'
#: noise and misfit can be amplified); the same bound as ``spline``'s
#: (:data:`ffls.weights.spline.DEFAULT_MAX_LEBESGUE`). Well-spread captures stay far below it.
MAX_LEBESGUE = 8.0


def _bounded(w: np.ndarray) -> np.ndarray:
    """Rows of ``w`` (summing to 1) blended toward their normalised positive part where their sum
    of magnitudes exceeds :data:`MAX_LEBESGUE`, just enough to meet it: ``b w + (1 - b) w+/sum(w+)``
    has magnitude sum at most ``b L + (1 - b)``. Continuous in ``w``; rows still sum to 1.

    Where the lights cover the hemisphere poorly (all in a small cap, or a few lights), the linear
    trend extrapolates, and unbounded weights reached 1e5 (photos of 0.6 relit to +-2e5)."""
    lam = np.abs(w).sum(axis=1)
    over = lam > MAX_LEBESGUE
    if not over.any():
        return w
    wo = w[over]
    pos = np.maximum(wo, 0.0)
    pos /= pos.sum(axis=1, keepdims=True)  # > 0: the row sums to 1
    b = ((MAX_LEBESGUE - 1.0) / (lam[over] - 1.0))[:, None]
    out = w.copy()
    out[over] = b * wo + (1.0 - b) * pos
    return out


class Kriging:
    """Universal-kriging weights over a set of lights.

    Parameters
    ----------
    directions : (n, 3) ndarray
        Unit light directions (duplicates allowed: only ``keep`` take weight).
    keep : (n_keep,) int64
        Indices of the distinct lights.
    nu : float
        Matérn smoothness, one of :data:`NUS`.
    length : float or None
        Kernel length (chord). None: ``DEFAULT_LENGTH_FACTOR`` x :func:`light_spacing`.
    nugget : float
        Share of the field's variance that is uncorrelated between lights (> 0).
    slots : int
        Lights kept per direction by :meth:`__call__` (>= 1).

    Attributes
    ----------
    coeffs : (n_keep + m, n_keep) float64
        Maps the features ``[k(p); 1, p]`` of a direction to its weights over ``keep``.
    linear : bool
        Whether the trend is linear (else constant).
    """

    def __init__(self, directions, keep, nu: float = DEFAULT_NU, length: float | None = None,
                 nugget: float = DEFAULT_NUGGET, slots: int = DEFAULT_SLOTS):
        if float(nu) not in NUS:
            raise ValueError(f"nu must be one of {NUS}, not {nu!r}")
        nugget = float(nugget)
        if not (np.isfinite(nugget) and nugget > 0):
            raise ValueError("nugget must be a finite number > 0")
        slots = int(slots)
        if slots < 1:
            raise ValueError("slots must be >= 1")
        self.directions = np.asarray(directions, dtype=np.float64)
        self.keep = np.asarray(keep, dtype=np.int64)
        d = self.directions[self.keep]
        if length is None:
            length = DEFAULT_LENGTH_FACTOR * light_spacing(d)
        length = float(length)
        if not (np.isfinite(length) and length > 0):
            raise ValueError("length must be a finite number > 0")
        self.nu, self.length, self.nugget, self.slots = float(nu), length, nugget, slots
        self.linear = _linear_ok(d)
        n = d.shape[0]
        self.coeffs = np.linalg.inv(_bordered(d, self.nu, length, nugget, self.linear))[:, :n]

    def _features(self, p: np.ndarray) -> np.ndarray:
        d = self.directions[self.keep]
        return np.concatenate([matern(p @ d.T, self.nu, self.length), _trend(p, self.linear)], axis=1)

    def dense(self, p: np.ndarray) -> np.ndarray:
        """Untruncated weights ``(m, n)`` over all ``directions`` (0 for dropped duplicates); rows sum to 1."""
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
        w = _bounded(self._features(p) @ self.coeffs)
        out = np.zeros((p.shape[0], self.directions.shape[0]))
        out[:, self.keep] = w
        top = self.keep[np.argmax(np.abs(w), axis=1)]
        out[np.arange(p.shape[0]), top] += 1.0 - out.sum(axis=1)  # exact to rounding
        return out

    def __call__(self, p: np.ndarray, chunk: int = 1 << 12) -> tuple[np.ndarray, np.ndarray]:
        """The ``slots`` largest weights ``|w|`` of directions ``p`` (m, 3), rows summing to 1.

        Returns
        -------
        index : (m, slots) int64
            Light indices, -1 padding (fewer lights than slots).
        weight : (m, slots) float64
            Largest first. With more lights than slots, the weights are soft-thresholded at the
            ``(slots + 1)``-th largest magnitude (continuous in ``p``) and what that drops is
            shared among the kept lights in proportion to ``|w|``: rows sum to 1.
        """
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
        m = p.shape[0]
        n = self.keep.size
        s = min(self.slots, n)
        index = np.full((m, self.slots), -1, dtype=np.int64)
        weight = np.zeros((m, self.slots))
        rows = np.arange(min(chunk, m))
        for a in range(0, m, chunk):
            w = _bounded(self._features(p[a:a + chunk]) @ self.coeffs)
            r = rows[:w.shape[0]]
            if s < n:
                part = np.argpartition(-np.abs(w), s, axis=1)[:, :s + 1]
                mag = np.abs(w[r[:, None], part])
                cut = mag.min(axis=1, keepdims=True)  # the (s+1)-th largest |w|
                top = np.take_along_axis(part, np.argsort(-mag, axis=1)[:, :s], axis=1)
                wt = w[r[:, None], top]
                # soft threshold at the (s+1)-th magnitude: a light entering or leaving the top s
                # has weight 0 there, so the truncated weights stay continuous in p
                wt = np.sign(wt) * np.maximum(np.abs(wt) - cut, 0.0)
                # the part lost (the tail and the thresholds) goes to the kept lights in proportion
                # to |w|: continuous, and the rows sum to 1
                mass = np.abs(wt).sum(axis=1, keepdims=True)
                share = np.divide(np.abs(wt), mass, out=np.zeros_like(wt), where=mass > 0)
                share[mass[:, 0] == 0, 0] = 1.0
                wt = wt + (1.0 - wt.sum(axis=1, keepdims=True)) * share
            else:
                top = np.broadcast_to(np.argsort(-np.abs(w), axis=1), w.shape)
                wt = np.take_along_axis(w, top, axis=1)
            wt[:, 0] += 1.0 - wt.sum(axis=1)  # exact to rounding (the largest weight)
            index[a:a + chunk, :s] = self.keep[top]
            weight[a:a + chunk, :s] = wt
        return index, weight


class KernelLearner:
    """The kriging kernel of one basis, learnt when first asked for (what the relighters hold).

    A relighter keeps one: it samples the basis's pixels once (the few thousand :func:`fit_kernel`
    uses, so the photos need not be kept) and learns the kernel the first time ``'kriging'`` is
    chosen without options (``--weighting kriging``, the viewer's knob), then reuses it.

    Parameters
    ----------
    directions : (n, 3) array_like
        The basis's light directions.
    basis : (n, ...) array_like
        The basis photos (linear).
    """

    def __init__(self, directions, basis):
        self.directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        n = self.directions.shape[0]
        distinct = np.unique(np.round(self.directions, 9), axis=0).shape[0] if n else 0
        self._pixels, self._why = None, None
        if n < 5:
            self._why = f"needs at least 5 lights, not {n}"
        elif distinct < 5:
            self._why = f"needs at least 5 distinct light directions, not {distinct} ({n} lights)"
        else:
            try:
                self._pixels = _sample_pixels(basis, n, _LOO_PIXELS, 0)  # the pixels fit_kernel(basis) uses
            except ValueError as e:  # NaN or Inf in the photos
                self._why = f"cannot use these photos: {e}"
            else:
                if not np.any(self._pixels):  # e.g. an engine over a store's pyramid holds no photos
                    self._pixels, self._why = None, "has no photo values to learn from (the photos are not in memory)"
        #: The learnt :class:`KernelFit` (None until first needed).
        self.fit: KernelFit | None = None

    def options_for(self, scheme: str, options: dict) -> dict:
        """``options``, or for ``'kriging'`` without options the kernel learnt from the basis.

        Raises
        ------
        ffls.errors.InputError
            Fewer than 5 lights (no kernel can be learnt by leave-one-out), or photos with NaN or Inf.
        """
        if scheme != "kriging" or options:
            return dict(options)
        if self.fit is None:
            if self._pixels is None:
                from ffls.errors import InputError

                raise InputError(f"--weighting kriging learns its kernel from the photos by leave-one-out and "
                                 f"{self._why}; choose another --weighting")
            try:
                self.fit = fit_kernel(self.directions, self._pixels)
            except ValueError as e:  # every candidate's system singular (lights nearly coincident)
                from ffls.errors import InputError

                raise InputError(f"--weighting kriging: {e}; the light directions are too close together to "
                                 "learn a kernel from; choose another --weighting") from None
        return self.fit.options

