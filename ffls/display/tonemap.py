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

Automatic exposure (:func:`auto_exposure`) maps the log-average luminance of the *object* to a
key (Reinhard et al. 2002, section 3.1): the object is the mask when one is given, else the
bright class of an Otsu split of the log luminance (N. Otsu, "A threshold selection method from
gray-level histograms", IEEE SMC 9(1), 1979, through OpenCV) when it stands well clear of a dark
background, else every pixel above zero.
"""
from __future__ import annotations

import numpy as np

from ffls.radiance.encoding import float_array, srgb_encode

__all__ = [
    "METHODS",
    "LUMINANCE_WEIGHTS",
    "BACKGROUND_GAP_STOPS",
    "luminance",
    "object_pixels",
    "auto_exposure",
    "apply_exposure",
    "reinhard",
    "aces",
    "tonemap",
    "to_uint8",
    "auto_exposure",
]

#: Tone curves accepted by :func:`tonemap`.
METHODS = ("srgb", "reinhard", "aces")
#: Rec.709 / sRGB luminance of linear RGB (the working space, GUIDE section 1).
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])
#: Without a mask, the dark class of the Otsu split is background when its mean log luminance is
#: at least this many stops below the bright class's (a black cloth or an empty render
#: background is 5 or more stops below a lit object; shading within an object rarely splits so).
BACKGROUND_GAP_STOPS = 4.0


def luminance(rgb) -> np.ndarray:
    """Rec.709 luminance (...) float64 of linear RGB (..., 3)."""
    x = np.asarray(rgb, dtype=np.float64)
    return (LUMINANCE_WEIGHTS[0] * x[..., 0] + LUMINANCE_WEIGHTS[1] * x[..., 1]) + LUMINANCE_WEIGHTS[2] * x[..., 2]


def object_pixels(hdr, mask=None) -> np.ndarray:
    """The pixels that :func:`auto_exposure` meters: the object, not the background.

    Parameters
    ----------
    hdr : (H, W, 3) array_like
        Linear radiance.
    mask : (H, W) array_like, optional
        Object mask: coverage in [0, 1] or bool; pixels with mask > 0.5 are the object.

    Returns
    -------
    (H, W) bool
        Pixels with finite positive luminance that are inside the mask; without a mask, those
        of the bright class of an Otsu split of log2 luminance (256 bins between its minimum
        and maximum) when the two classes' mean log luminances differ by at least
        :data:`BACKGROUND_GAP_STOPS`, else all of them.
    """
    import cv2

    lum = luminance(hdr)
    ok = np.isfinite(lum) & (lum > 0)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != lum.shape:
            raise ValueError(f"mask of shape {m.shape} does not fit an image of shape {lum.shape}")
        return ok & (m.astype(np.float64) > 0.5)
    if np.count_nonzero(ok) < 2:
        return ok
    lg = np.log2(lum[ok])
    lo, hi = float(lg.min()), float(lg.max())
    if hi - lo < BACKGROUND_GAP_STOPS:
        return ok
    q = np.rint((lg - lo) / (hi - lo) * 255).astype(np.uint8).reshape(-1, 1)
    t, _ = cv2.threshold(q, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    bright = q[:, 0] > t
    if not bright.any() or bright.all() or lg[bright].mean() - lg[~bright].mean() < BACKGROUND_GAP_STOPS:
        return ok
    out = np.zeros_like(ok)
    out[ok] = bright
    return out


def auto_exposure(hdr, key: float = 0.18, mask=None) -> float:
    """Exposure in stops that maps the log-average luminance of the object in ``hdr`` to ``key``.

    Parameters
    ----------
    hdr : (H, W, 3) array_like
        Linear radiance.
    key : float
        Target log-average luminance (0.18: middle grey).
    mask : (H, W) array_like, optional
        Object mask (> 0.5 is the object; ``--mask``). Without one the dark background is left
        out as :func:`object_pixels` says.

    Returns
    -------
    float
        Stops (0 when no pixel qualifies, e.g. an all-zero image).
    """
    hdr = np.asarray(hdr)
    sel = object_pixels(hdr, mask)
    if not sel.any():
        return 0.0
    lum = luminance(hdr)[sel]
    log_avg = float(np.exp(np.mean(np.log(lum + 1e-12))))
    return float(np.log2(key / log_avg))


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
