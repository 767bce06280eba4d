"""Transfer functions between encoded pixel values and linear radiance.

* sRGB: IEC 61966-2-1:1999, the exact piecewise curve (not a 2.2 gamma).
* A pure power law ("gamma"): ``linear = encoded ** gamma`` on values normalised to [0, 1], the
  ``{"gamma": g}`` encoding of ``capture.json`` and the family that
  :mod:`ffls.spheres.encoding` calibrates from the spheres.
"""
from __future__ import annotations

import numpy as np

from ffls.io.capture import GAMMA_RANGE  # the gammas ``{"gamma": g}`` accepts (defined with the file format)

__all__ = ["float_array", "srgb_encode", "srgb_decode", "gamma_encode", "gamma_decode", "GAMMA_RANGE"]

# IEC 61966-2-1 constants.
_ENC_THRESHOLD = 0.0031308
_DEC_THRESHOLD = 0.04045
_LINEAR_SLOPE = 12.92
_A = 0.055
_GAMMA = 2.4


def float_array(x) -> np.ndarray:
    """Float array keeping float32/float64 precision; other dtypes become float64."""
    x = np.asarray(x)
    if x.dtype in (np.float32, np.float64):
        return x
    return x.astype(np.float64)


def srgb_encode(linear) -> np.ndarray:
    """Linear values to sRGB-encoded values (IEC 61966-2-1 piecewise curve).

    Parameters
    ----------
    linear : (...) array_like
        Linear values; the curve is meant for [0, 1]. Values at or below 0.0031308 (including
        negatives) use the linear segment ``12.92 x``; values above 1 follow the power segment.

    Returns
    -------
    (...) ndarray
        Encoded values, float32 for float32 input, float64 otherwise (computed in that precision).
    """
    x = float_array(linear)
    lin = x * x.dtype.type(_LINEAR_SLOPE)
    powed = x.dtype.type(1.0 + _A) * np.power(np.maximum(x, x.dtype.type(_ENC_THRESHOLD)), x.dtype.type(1.0 / _GAMMA)) - x.dtype.type(_A)
    return np.where(x <= _ENC_THRESHOLD, lin, powed).astype(x.dtype, copy=False)


def srgb_decode(encoded) -> np.ndarray:
    """sRGB-encoded values to linear values (inverse of :func:`srgb_encode`).

    Parameters
    ----------
    encoded : (...) array_like
        Encoded values, meant for [0, 1] (8-bit images divided by 255).

    Returns
    -------
    (...) ndarray
        Linear values, float32 for float32 input, float64 otherwise.
    """
    c = float_array(encoded)
    lin = c / c.dtype.type(_LINEAR_SLOPE)
    powed = np.power((np.maximum(c, c.dtype.type(_DEC_THRESHOLD)) + c.dtype.type(_A)) / c.dtype.type(1.0 + _A), c.dtype.type(_GAMMA))
    return np.where(c <= _DEC_THRESHOLD, lin, powed).astype(c.dtype, copy=False)


def _check_gamma(gamma) -> float:
    g = float(gamma)
    if not (GAMMA_RANGE[0] <= g <= GAMMA_RANGE[1]):
        raise ValueError(f"gamma must be in [{GAMMA_RANGE[0]}, {GAMMA_RANGE[1]}], not {gamma!r}")
    return g


def gamma_decode(encoded, gamma: float) -> np.ndarray:
    """Encoded values to linear values by a power law: ``linear = max(encoded, 0) ** gamma``.

    Parameters
    ----------
    encoded : (...) array_like
        Values normalised to [0, 1] (an 8-bit image divided by 255, a 16-bit one by 65535).
    gamma : float
        The exponent, in :data:`GAMMA_RANGE` (1 is linear; 2.2 the common display gamma).

    Returns
    -------
    (...) ndarray
        Linear values, float32 for float32 input, float64 otherwise.
    """
    g = _check_gamma(gamma)
    c = float_array(encoded)
    return np.power(np.maximum(c, c.dtype.type(0)), c.dtype.type(g)).astype(c.dtype, copy=False)


def gamma_encode(linear, gamma: float) -> np.ndarray:
    """Linear values to encoded values, the inverse of :func:`gamma_decode`: ``max(linear, 0) ** (1 / gamma)``.

    Parameters
    ----------
    linear : (...) array_like
    gamma : float
        In :data:`GAMMA_RANGE`.

    Returns
    -------
    (...) ndarray
        Encoded values, float32 for float32 input, float64 otherwise.
    """
    g = _check_gamma(gamma)
    x = float_array(linear)
    return np.power(np.maximum(x, x.dtype.type(0)), x.dtype.type(1.0 / g)).astype(x.dtype, copy=False)
