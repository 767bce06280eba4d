"""Tone mapping: exposure, the sRGB transfer curves, Reinhard and ACES curves.

Everything inside ffls is linear radiance; this module turns it into display values.

* sRGB transfer function: IEC 61966-2-1:1999 (the exact piecewise curve, not a 2.2 gamma).
* Reinhard: E. Reinhard, M. Stark, P. Shirley, J. Ferwerda, "Photographic tone reproduction for
  digital images", SIGGRAPH 2002 -- the simple global operator ``x / (1 + x)``, per channel.
* ACES: K. Narkowicz, "ACES Filmic Tone Mapping Curve" (blog post, 2016), a rational fit of the
  ACES reference rendering transform + ODT, applied per channel.

NaN and Inf are **not** silently replaced: :func:`tonemap` assumes finite input (NaN stays NaN)
and :func:`to_uint8` raises ``ValueError`` on non-finite values.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "METHODS",
    "srgb_encode",
    "srgb_decode",
    "apply_exposure",
    "reinhard",
    "aces",
    "tonemap",
    "to_uint8",
]

#: Tone curves accepted by :func:`tonemap`.
METHODS = ("srgb", "reinhard", "aces")

# IEC 61966-2-1 constants.
_ENC_THRESHOLD = 0.0031308
_DEC_THRESHOLD = 0.04045
_LINEAR_SLOPE = 12.92
_A = 0.055
_GAMMA = 2.4


def _as_float(x) -> np.ndarray:
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
    x = _as_float(linear)
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
    c = _as_float(encoded)
    lin = c / c.dtype.type(_LINEAR_SLOPE)
    powed = np.power((np.maximum(c, c.dtype.type(_DEC_THRESHOLD)) + c.dtype.type(_A)) / c.dtype.type(1.0 + _A), c.dtype.type(_GAMMA))
    return np.where(c <= _DEC_THRESHOLD, lin, powed).astype(c.dtype, copy=False)


def apply_exposure(rgb, stops: float) -> np.ndarray:
    """Scale linear values by ``2 ** stops``.

    Parameters
    ----------
    rgb : (...) array_like
        Linear values.
    stops : float
        Exposure change in photographic stops (EV); +1 doubles.

    Returns
    -------
    (...) ndarray
        Scaled values in the input's float precision.
    """
    x = _as_float(rgb)
    return x * x.dtype.type(2.0 ** float(stops))


def reinhard(x) -> np.ndarray:
    """Reinhard et al. 2002 global operator ``x / (1 + x)`` per channel; negatives map to 0.

    Parameters
    ----------
    x : (...) array_like
        Linear values.

    Returns
    -------
    (...) ndarray
        Values in [0, 1).
    """
    x = np.maximum(_as_float(x), 0)
    return x / (1 + x)


def aces(x) -> np.ndarray:
    """Narkowicz (2016) fit of the ACES filmic curve, per channel, clipped to [0, 1].

    ``f(x) = x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)``. Narkowicz suggests pre-scaling
    by 0.6 to match the reference exposure; use ``exposure`` in :func:`tonemap` for that.

    Parameters
    ----------
    x : (...) array_like
        Linear values.

    Returns
    -------
    (...) ndarray
        Values in [0, 1] (still linear: encode with :func:`srgb_encode` for display).
    """
    x = np.maximum(_as_float(x), 0)
    t = x.dtype.type
    y = (x * (t(2.51) * x + t(0.03))) / (x * (t(2.43) * x + t(0.59)) + t(0.14))
    return np.clip(y, 0, 1)


def tonemap(rgb, exposure: float = 0.0, method: str = "srgb") -> np.ndarray:
    """Linear HDR radiance to sRGB-encoded display values in [0, 1].

    Parameters
    ----------
    rgb : (..., 3) or (...) array_like
        Linear radiance. Must be finite: NaN is not replaced (it stays NaN).
    exposure : float
        Exposure in stops applied before the curve.
    method : {'srgb', 'reinhard', 'aces'}
        ``'srgb'`` clips to [0, 1]; ``'reinhard'`` and ``'aces'`` compress highlights first.

    Returns
    -------
    (...) float32 ndarray
        sRGB-encoded display values in [0, 1].
    """
    if method not in METHODS:
        raise ValueError(f"tone-map method must be one of {METHODS}, not {method!r}")
    x = apply_exposure(rgb, exposure)
    if method == "srgb":
        y = np.clip(x, 0, 1)
    elif method == "reinhard":
        y = reinhard(x)
    else:
        y = aces(x)
    return np.clip(srgb_encode(y), 0, 1).astype(np.float32, copy=False)


def to_uint8(display) -> np.ndarray:
    """Display values in [0, 1] to uint8 with rounding (values outside are clipped).

    Parameters
    ----------
    display : (...) array_like
        Display (already encoded) values, finite.

    Returns
    -------
    (...) uint8 ndarray

    Raises
    ------
    ValueError
        If any value is NaN or infinite.
    """
    d = _as_float(display)
    if not np.all(np.isfinite(d)):
        raise ValueError(f"to_uint8: {int(np.count_nonzero(~np.isfinite(d)))} non-finite values")
    return np.rint(np.clip(d, 0, 1) * 255).astype(np.uint8)
