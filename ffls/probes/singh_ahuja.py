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
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffls.conventions import latlong_directions
from ffls.errors import InputError
from ffls.probes.hougen_ahuja import check_normals
from ffls.probes.linear import as_rgb_pixels, broadcast_albedo, lambert_matrix
from ffls.probes.sources import latlong_solid_angles

__all__ = ["PocsResult", "pocs", "singh_ahuja", "estimate_lighting_SinghAhuja"]


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


def pocs(H, g, iterations: int = 50, lower: float = 0.0, upper: float | None = None, delta: float = 0.0,
         order: str = "random", seed: int = 0, x0=None) -> tuple[np.ndarray, np.ndarray]:
    """Projections onto convex sets for ``g ~ H f`` with ``lower <= f <= upper``.

    Parameters
    ----------
    H : (m, J) array_like
        Kernel (one row per residual constraint).
    g : (m, c) array_like
        Data, ``c`` channels (solved together, one projection per row for all channels).
    iterations : int
        Sweeps; each applies every row's residual projection once, then the amplitude one.
    lower, upper : float
        Amplitude bounds (``upper=None``: no upper bound).
    delta : float
        Allowed residual magnitude per pixel (0 in the paper's experiments).
    order : {'random', 'sequential'}
        Order of the residual projections in a sweep: a fresh permutation each sweep, or 0..m-1.
    seed : int
        Seed of the permutations.
    x0 : (J, c) array_like, optional
        Start (zeros by default).

    Returns
    -------
    f : (J, c) float64
    residuals : (iterations + 1,) float64
        ``|g - H f| / |g|`` (Frobenius) at the start and after every sweep.
    """
    H = np.ascontiguousarray(H, dtype=np.float64)
    g = np.asarray(g, dtype=np.float64)
    if g.ndim == 1:
        g = g[:, None]
    m, J = H.shape
    if order not in ("random", "sequential"):
        raise ValueError(f"order must be 'random' or 'sequential', not {order!r}")
    norm2 = np.einsum("ij,ij->i", H, H)
    if not np.any(norm2 > 0):
        raise InputError("singular system: no pixel is lit by any direction of the POCS grid")
    rows = np.flatnonzero(norm2 > 0)
    Hn = H / np.where(norm2 > 0, norm2, 1.0)[:, None]
    f = np.zeros((J, g.shape[1])) if x0 is None else np.array(x0, dtype=np.float64).reshape(J, g.shape[1])
    hi = np.inf if upper is None else float(upper)
    gn = float(np.linalg.norm(g)) or 1.0
    res = [float(np.linalg.norm(g - H @ f)) / gn]
    rng = np.random.default_rng(seed)
    d = float(delta)
    for _ in range(int(iterations)):
        seq = rng.permutation(rows) if order == "random" else rows
        for i in seq:
            r = g[i] - H[i] @ f
            if d > 0:
                r = np.where(r > d, r - d, np.where(r < -d, r + d, 0.0))
            f += np.outer(Hn[i], r)
        np.clip(f, lower, hi, out=f)
        res.append(float(np.linalg.norm(g - H @ f)) / gn)
    return f, np.asarray(res)


def singh_ahuja(normals, radiance, albedo=1.0, height: int = 16, iterations: int = 50, upper: float | None = None,
                delta: float = 0.0, order: str = "random", seed: int = 0, max_pixels: int | None = 2000,
                visibility=None) -> PocsResult:
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

    Returns
    -------
    PocsResult
    """
    n = check_normals(normals)
    m = n.shape[0]
    if m == 0:
        raise InputError("no pixels to fit")
    b = as_rgb_pixels(radiance, m)
    rho = broadcast_albedo(albedo, m)
    h = int(height)
    if h < 2:
        raise ValueError(f"POCS grid height must be >= 2, not {height!r}")
    dirs = latlong_directions(2 * h, h).reshape(-1, 3)
    sa = latlong_solid_angles(h).ravel()
    g = np.pi * b / rho  # irradiance
    H = lambert_matrix(n, dirs, visibility) * sa[None, :]
    use = np.arange(m)
    if max_pixels is not None and m > int(max_pixels):
        use = np.sort(np.random.default_rng(seed).choice(m, int(max_pixels), replace=False))
    f, res = pocs(H[use], g[use], iterations, 0.0, upper, delta, order, seed)
    rendered = (H @ f) * rho / np.pi
    rms = float(np.sqrt(np.mean((rendered - b) ** 2)))
    ref = float(np.sqrt(np.mean(b ** 2)))
    return PocsResult(radiance=f.reshape(h, 2 * h, 3), residuals=res, rendered=rendered, rms=rms,
                      relative_rms=rms / ref if ref > 0 else np.inf, iterations=int(iterations),
                      pixels_used=int(use.size))


#: The colour-hdri style name of :func:`singh_ahuja`.
estimate_lighting_SinghAhuja = singh_ahuja
