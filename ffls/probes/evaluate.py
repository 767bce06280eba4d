"""Evaluation of recovered lighting, as the papers do it and as users need it.

* Re-render the input: every fit carries ``rendered`` and ``relative_rms`` (the papers' RMS).
* :func:`map_error` -- the recovered map against the true one (relative L2 over solid angle).
* :func:`relit_error` -- what users see: a diffuse object (any set of normals; by default every
  direction of the sphere, or of one hemisphere) relit under the recovered map against the same
  object under the true map, relative RMS of the irradiance (= of the relit radiance for any
  albedo).
* The limit of a Lambertian probe, in spherical harmonics (Ramamoorthi and Hanrahan 2001): the
  clamped-cosine kernel's coefficients (:func:`clamped_cosine_coefficients`), the share of its
  energy up to an order (:func:`clamped_cosine_energy`, 99.2 % up to order 2; the odd orders
  above 1 are exactly 0), and per-order recovery of a map (:func:`sh_recovery`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import eval_legendre, sph_harm_y

from ffls.conventions import direction_to_spherical, latlong_directions
from ffls.probes.linear import irradiance_from_map
from ffls.probes.sources import latlong_solid_angles

__all__ = [
    "sphere_normals_uniform",
    "as_latlong_array",
    "map_error",
    "relit_error",
    "clamped_cosine_coefficients",
    "clamped_cosine_energy",
    "sh_basis",
    "sh_project",
    "SHRecovery",
    "sh_recovery",
]


def sphere_normals_uniform(n: int = 2000, hemisphere: str = "full") -> np.ndarray:
    """Near-uniform unit normals (n, 3) on the sphere (a Fibonacci spiral), or its upper half."""
    n = int(n)
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n if hemisphere == "full" else 1.0 - i / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def as_latlong_array(lightmap) -> np.ndarray:
    """Lat-long radiance (H, 2H, 3) float64 from a LightMap (any layout, resampled) or an array."""
    if hasattr(lightmap, "layout"):
        lm = lightmap if lightmap.layout == "latlong" else lightmap.to_latlong(max(8, lightmap.res // 2))
        return np.asarray(lm.data, dtype=np.float64)
    a = np.asarray(lightmap, dtype=np.float64)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[1] != 2 * a.shape[0]:
        raise ValueError(f"a lat-long map must be (H, 2H, 3), not {a.shape}")
    return a


def _samples(a: np.ndarray):
    h = a.shape[0]
    return latlong_directions(2 * h, h).reshape(-1, 3), a.reshape(-1, 3), latlong_solid_angles(h).ravel()


def _common(rec: np.ndarray, true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bring two lat-long maps to the smaller height by area-weighted block means (exact energy)."""
    def down(a, h):
        k = a.shape[0] // h
        if k == 1:
            return a
        if a.shape[0] % h:
            raise ValueError(f"map heights {rec.shape[0]} and {true.shape[0]} must divide each other")
        sa = latlong_solid_angles(a.shape[0])
        num = (a * sa[..., None]).reshape(h, k, 2 * h, k, 3).sum(axis=(1, 3))
        den = sa.reshape(h, k, 2 * h, k).sum(axis=(1, 3))
        return num / den[..., None]
    h = min(rec.shape[0], true.shape[0])
    return down(rec, h), down(true, h)


def map_error(recovered, true, hemisphere: str = "full") -> float:
    """Relative L2 error of a recovered map, ``sqrt(sum |L_r - L_t|^2 dw / sum |L_t|^2 dw)``.

    Parameters
    ----------
    recovered, true : LightMap or (H, 2H, 3) array_like
        Lat-long maps whose heights divide each other (the finer is block-averaged).
    hemisphere : {'full', 'upper'}
        Compare over the whole sphere or ``z >= 0`` only.

    Returns
    -------
    float
    """
    r, t = _common(as_latlong_array(recovered), as_latlong_array(true))
    d, _, sa = _samples(t)
    w = sa * ((d[:, 2] >= 0) if hemisphere == "upper" else 1.0)
    num = np.sum(((r - t).reshape(-1, 3) ** 2) * w[:, None])
    den = np.sum((t.reshape(-1, 3) ** 2) * w[:, None])
    return float(np.sqrt(num / den)) if den > 0 else np.inf


def relit_error(recovered, true, normals=None, hemisphere: str = "full", clip: bool = True) -> float:
    """Relative RMS difference of a diffuse object relit under two maps.

    Parameters
    ----------
    recovered, true : LightMap or (H, 2H, 3) array_like
    normals : (k, 3) array_like, optional
        The object's normals (any diffuse object of known geometry, e.g. the probe itself).
        Default: 2000 near-uniform normals over ``hemisphere``.
    hemisphere : {'full', 'upper'}
        For the default normals.
    clip : bool
        Clip negative radiance of ``recovered`` first (what a saved light map holds).

    Returns
    -------
    float
        ``|E_r - E_t| / |E_t|`` over normals and channels (E the irradiance; the relit radiance
        is ``rho / pi E``, so the ratio holds for any albedo).
    """
    r = as_latlong_array(recovered)
    if clip:
        r = np.maximum(r, 0.0)
    t = as_latlong_array(true)
    n = sphere_normals_uniform(2000, hemisphere) if normals is None else np.asarray(normals, dtype=np.float64)
    er = irradiance_from_map(n, _samples(r))
    et = irradiance_from_map(n, _samples(t))
    den = float(np.sqrt(np.mean(et ** 2)))
    return float(np.sqrt(np.mean((er - et) ** 2))) / den if den > 0 else np.inf


def clamped_cosine_coefficients(order: int) -> np.ndarray:
    """Legendre coefficients ``c_l = int_0^1 t P_l(t) dt`` of ``max(t, 0)``, l = 0..order.

    ``max(t, 0) = sum_l (2l + 1) / 2 c_l P_l(t)``; ``c_0 = 1/2``, ``c_1 = 1/3``, ``c_2 = 1/8``,
    ``c_l = 0`` for odd ``l >= 3``. A map's SH coefficients of order ``l`` reach the irradiance
    multiplied by ``2 pi c_l`` (the Funk-Hecke theorem).
    """
    x, w = np.polynomial.legendre.leggauss(200)
    t = 0.5 * (x + 1.0)  # Gauss-Legendre on [0, 1]
    return np.array([0.5 * np.sum(w * t * eval_legendre(l, t)) for l in range(int(order) + 1)])


def clamped_cosine_energy(order: int, max_order: int = 400) -> float:
    """Share of the clamped cosine's energy ``int max(t, 0)^2 dt = 1/3`` in orders 0..``order``."""
    c = clamped_cosine_coefficients(max(int(order), 0))
    e = np.sum((2 * np.arange(c.size) + 1) / 2.0 * c ** 2)
    return float(e / (1.0 / 3.0))


def sh_basis(directions, order: int) -> np.ndarray:
    """Real orthonormal spherical harmonics (k, (order + 1)^2) at unit directions (k, 3).

    Columns in the order ``(l, m)``, l = 0..order, m = -l..l.
    """
    theta, phi = direction_to_spherical(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
    cols = []
    for l in range(int(order) + 1):
        for m in range(-l, l + 1):
            y = sph_harm_y(l, abs(m), theta, phi)
            if m < 0:
                cols.append(np.sqrt(2.0) * (-1) ** m * y.imag)
            elif m == 0:
                cols.append(y.real)
            else:
                cols.append(np.sqrt(2.0) * (-1) ** m * y.real)
    return np.stack(cols, axis=1)


def sh_project(lightmap, order: int) -> np.ndarray:
    """SH coefficients ((order + 1)^2, 3) of a lat-long map (exact texel solid angles)."""
    d, rad, sa = _samples(as_latlong_array(lightmap))
    return sh_basis(d, order).T @ (rad * sa[:, None])


@dataclass(frozen=True)
class SHRecovery:
    """Per-order comparison of a recovered map with the truth in spherical harmonics.

    Attributes
    ----------
    orders : (L + 1,) int
    true_energy : (L + 1,) float64
        Energy (sum of squared coefficients over m and channels) of the true map per order,
        as a share of the true map's total energy over all orders up to L.
    relative_error : (L + 1,) float64
        ``|c_rec - c_true| / |c_true|`` per order (1 means nothing recovered, 0 exact).
    kernel : (L + 1,) float64
        ``|2 pi c_l|``: how much of order ``l`` reaches a Lambertian image.
    """

    orders: np.ndarray
    true_energy: np.ndarray
    relative_error: np.ndarray
    kernel: np.ndarray


def sh_recovery(recovered, true, order: int = 8) -> SHRecovery:
    """Compare two maps order by order (what a Lambertian probe can and cannot recover).

    Parameters
    ----------
    recovered, true : LightMap or (H, 2H, 3) array_like
    order : int

    Returns
    -------
    SHRecovery
    """
    L = int(order)
    cr = sh_project(recovered, L)
    ct = sh_project(true, L)
    ls = np.concatenate([[l] * (2 * l + 1) for l in range(L + 1)])
    et = np.array([np.sum(ct[ls == l] ** 2) for l in range(L + 1)])
    err = np.array([np.sqrt(np.sum((cr[ls == l] - ct[ls == l]) ** 2)) / max(np.sqrt(et[l]), 1e-300)
                    for l in range(L + 1)])
    return SHRecovery(orders=np.arange(L + 1), true_energy=et / et.sum(), relative_error=err,
                      kernel=np.abs(2 * np.pi * clamped_cosine_coefficients(L)))
