"""Inverse camera-response tables on disk: ``.npy`` or ``.csv``, 256 rows of 3 numbers.

The table is the linear exposure (relative units) that produces each 8-bit code, per channel
(RGB). :mod:`ffls.radiance.response` recovers it; ``capture.json`` names it with
``"encoding": {"response": "response.npy"}``.

:func:`polynomial_response` evaluates the response family that :mod:`ffls.spheres.encoding`
calibrates from matte spheres (a gamma times the exponential of a low-order polynomial) and
:func:`polynomial_response_table` tabulates it for 8- or 16-bit codes: the table that linearises photos
whose ``lights.json`` names such a curve (``"curve": "polynomial"``, ``docs/formats.md``).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ffls.errors import InputError, atomic_output, not_a_regular_file

__all__ = ["save_response", "load_response", "polynomial_response", "polynomial_response_partials",
           "polynomial_response_table", "POLYNOMIAL_MIN_SLOPE"]

#: Least local log-log slope ``d ln f / d ln x`` of a polynomial response over (0, 1]: the curve is
#: strictly increasing (a camera's response is monotone, Mitsunaga & Nayar 1999), and no range of
#: codes is flattened onto almost one radiance (a slope of 0.1 is a tenth of a linear file's).
POLYNOMIAL_MIN_SLOPE = 0.1
_TINY = 1e-6


def polynomial_response(x, coefficients, derivative: bool = False):
    """Inverse response ``f(x) = x ** g * exp(sum_j a_j (x ** j - 1))`` of normalised codes ``x``.

    A gamma (``g``) times the exponential of a polynomial of order ``K`` in the code, which is 0 at
    full scale, so ``f(1) = 1`` (the scale is the lights'). ``K = 0`` is the pure gamma; the
    polynomial bends it into a camera's toe and shoulder (an S-shaped tone curve). It is the
    low-order polynomial inverse response of Mitsunaga & Nayar (1999), written in the logarithm
    so that it nests the gamma family and its order can be chosen by the BIC.

    Parameters
    ----------
    x : (...) array_like
        Stored values normalised to [0, 1].
    coefficients : sequence of float
        ``(g, a_1, ..., a_K)``.
    derivative : bool
        Also return ``f'(x)``.

    Returns
    -------
    f : (...) float64 ndarray
    df : (...) float64 ndarray
        Only when ``derivative``.
    """
    c = np.asarray(coefficients, dtype=np.float64).ravel()
    if c.size < 1 or not np.all(np.isfinite(c)):
        raise ValueError(f"coefficients must be finite numbers (g, a_1, ..., a_K), got {coefficients!r}")
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, None)
    lx = np.log(np.maximum(x, _TINY))
    poly = np.zeros_like(x)
    dpoly = np.zeros_like(x)  # x * d poly / dx
    xj = np.ones_like(x)
    for j, a in enumerate(c[1:], start=1):
        xj = xj * x
        poly += a * (xj - 1.0)
        dpoly += j * a * xj
    base = np.exp((c[0] - 1.0) * lx + poly)  # f / x
    f = np.where(x > 0, base * x, 0.0)
    if not derivative:
        return f
    return f, base * (c[0] + dpoly)


def polynomial_response_partials(x, coefficients) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`polynomial_response` ``f`` and its slope ``f'`` at ``x``, with their derivatives in
    the coefficients, from one evaluation (what a fit of the coefficients needs for its gradient).

    With ``D = sum_j j a_j x^j`` (so ``f' = (f / x)(g + D)``): ``d f / d g = f ln x``,
    ``d f / d a_j = f (x^j - 1)``, ``d f' / d g = (f / x)(ln x (g + D) + 1)`` and
    ``d f' / d a_j = (f / x)((x^j - 1)(g + D) + j x^j)``. At ``x = 0`` ``f`` and its partials are 0.

    Parameters
    ----------
    x : (U,) array_like
        Stored values normalised to [0, 1].
    coefficients : sequence of float
        ``(g, a_1, ..., a_K)``.

    Returns
    -------
    f, df : (U,) float64 ndarray
        :func:`polynomial_response` with ``derivative=True``.
    f_partials, df_partials : (K + 1, U) float64 ndarray
        ``d f / d c`` and ``d f' / d c`` for each coefficient ``c``.
    """
    c = np.asarray(coefficients, dtype=np.float64).ravel()
    f, d = polynomial_response(x, c, derivative=True)
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, None)
    lx = np.log(np.maximum(x, _TINY))
    powers = [x ** j for j in range(1, c.size)]
    poly = sum((a * (xj - 1.0) for a, xj in zip(c[1:], powers)), np.zeros_like(x))
    slope = c[0] + sum((j * a * xj for j, (a, xj) in enumerate(zip(c[1:], powers), start=1)), np.zeros_like(x))
    base = np.exp((c[0] - 1.0) * lx + poly)  # f / x
    f0 = np.where(x > 0, f, 0.0)
    df = np.stack([f0 * lx] + [f0 * (xj - 1.0) for xj in powers])
    dd = np.stack([base * (lx * slope + 1.0)]
                  + [base * ((xj - 1.0) * slope + j * xj) for j, xj in enumerate(powers, start=1)])
    return f, d, df, dd


def polynomial_response_table(coefficients, bits: int = 8) -> np.ndarray:
    """(2 ** bits, 3) float32 inverse response table of :func:`polynomial_response`: the linear value
    of every code of ``bits``-bit files (256 rows for 8 bits, 65536 for 16).

    Raises
    ------
    ValueError
        Malformed coefficients or ``bits`` (8 or 16), or a curve that is not increasing over the codes.
    """
    if bits not in (8, 16):
        raise ValueError(f"bits must be 8 or 16, got {bits!r}")
    top = 2 ** bits - 1
    f = polynomial_response(np.arange(top + 1) / float(top), coefficients)
    if not np.all(np.diff(f) > 0):
        raise ValueError(f"the polynomial response must increase over the {bits}-bit codes")
    return np.repeat(f[:, None], 3, axis=1).astype(np.float32)


def save_response(path: str | os.PathLike, curve) -> Path:
    """Write an inverse response table atomically as ``.npy`` or ``.csv`` (256 rows, 3 columns)."""
    path = Path(path)
    c = np.asarray(curve, dtype=np.float64)
    if c.shape == (256,):
        c = np.repeat(c[:, None], 3, axis=1)
    if c.shape != (256, 3) or not np.all(np.isfinite(c)) or np.any(c < 0):
        raise ValueError(f"curve must be a finite non-negative (256, 3) table, got shape {c.shape}")
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".csv"):
        raise InputError("response files must end in .npy or .csv", path)
    with atomic_output(path) as tmp:
        if suffix == ".npy":
            with open(tmp, "wb") as f:
                np.save(f, c.astype(np.float32))
        else:
            np.savetxt(tmp, c, delimiter=",", fmt="%.9g")  # no header: ffls.io.capture reads it with loadtxt
    return path


def load_response(path: str | os.PathLike) -> np.ndarray:
    """Read an inverse response table written by :func:`save_response`.

    Returns
    -------
    (256, 3) float32
        A single-column table is repeated for the three channels.

    Raises
    ------
    InputError
        Missing file, wrong suffix or shape, non-finite, negative or decreasing values.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(not_a_regular_file(path) or "response file not found", path)
    try:
        if path.suffix.lower() == ".npy":
            c = np.load(path, allow_pickle=False)
        elif path.suffix.lower() == ".csv":
            c = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=2)
        else:
            raise InputError("response files must end in .npy or .csv", path)
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read response table ({e})", path) from None
    c = np.asarray(c, dtype=np.float64)
    if c.shape in ((256,), (256, 1)):
        c = np.repeat(c.reshape(256, 1), 3, axis=1)
    if c.shape != (256, 3):
        raise InputError(f"response table must have shape (256, 3), got {c.shape}", path)
    if not np.all(np.isfinite(c)) or np.any(c < 0):
        raise InputError("response table must be finite and non-negative", path)
    if np.any(np.diff(c, axis=0) < 0):
        raise InputError("response table must be non-decreasing in every channel", path)
    return c.astype(np.float32)
