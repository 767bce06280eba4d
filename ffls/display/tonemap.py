"""Tone mapping: exposure, then the sRGB, Reinhard or ACES curve, and 8-bit quantisation.

Everything inside ffls is linear radiance; this module turns it into display values.

* sRGB transfer function: :func:`ffls.radiance.encoding.srgb_encode` (IEC 61966-2-1:1999).
* Reinhard: E. Reinhard, M. Stark, P. Shirley, J. Ferwerda, "Photographic tone reproduction for
  digital images", SIGGRAPH 2002 -- the simple global operator ``x / (1 + x)``, per channel.
* ACES: K. Narkowicz, "ACES Filmic Tone Mapping Curve" (blog post, 2016), a rational fit of the
  ACES reference rendering transform + ODT, applied per channel.

* Automatic exposure: the log-average luminance mapped to a key value (the "key" of
  Reinhard et al. 2002, section 2), :func:`auto_exposure`.

NaN and Inf are **not** silently replaced: :func:`tonemap` assumes finite input (NaN stays NaN)
and :func:`to_uint8` raises ``ValueError`` on non-finite values.
"""
from __future__ import annotations

import numpy as np

from ffls.radiance.encoding import float_array, srgb_encode

__all__ = [
    "METHODS",
    "apply_exposure",
    "reinhard",
    "aces",
    "tonemap",
    "to_uint8",
    "auto_exposure",
]

#: Tone curves accepted by :func:`tonemap`.
METHODS = ("srgb", "reinhard", "aces")

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
    x = float_array(rgb)
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
    x = np.maximum(float_array(x), 0)
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
    x = np.maximum(float_array(x), 0)
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
    d = float_array(display)
    if not np.all(np.isfinite(d)):
        raise ValueError(f"to_uint8: {int(np.count_nonzero(~np.isfinite(d)))} non-finite values")
    return np.rint(np.clip(d, 0, 1) * 255).astype(np.uint8)


def auto_exposure(hdr: np.ndarray, key: float = 0.18) -> float:
    """Exposure in stops that maps the log-average luminance of ``hdr`` (H, W, 3) to ``key``.

    Reinhard et al. 2002, equation 1 (Rec.709 luminance). Pixels that are exactly zero
    (background) are ignored; an all-zero image gives 0 stops.
    """
    lum = 0.2126 * hdr[..., 0] + 0.7152 * hdr[..., 1] + 0.0722 * hdr[..., 2]
    lum = lum[lum > 0]
    if lum.size == 0:
        return 0.0
    log_avg = float(np.exp(np.mean(np.log(lum + 1e-12))))
    return float(np.log2(key / log_avg))
