"""Float16 storage of radiance with a checked power-of-two per-dataset scale.

One definition used by the GPU basis (:mod:`ffls.gpu.basis`) and the chunked reflectance field on
disk (:mod:`ffls.store.field`). Float16 storage multiplies every value by one power-of-two scale
``s`` (exact in binary floating point) chosen so that the largest magnitude lands at
:data:`F16_TARGET_MAX` = 2**12, far inside float16's range (65504) and far above its smallest
normal (2**-14): a 1e6 pixel becomes 1e6 * 2**-8 = 3906.25, never ``inf``.

The conversion is checked, never silent (:class:`Float16Report`): a non-finite input raises,
an overflow to ``inf`` raises, and a *significant* value (``|x| >= SIGNIFICANT_REL * max|x|``)
that becomes zero or subnormal raises.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffls.errors import InputError

__all__ = ["F16_TARGET_MAX", "SIGNIFICANT_REL", "Float16Report", "choose_scale", "to_float16"]

#: The largest basis magnitude after scaling to float16 (2**12; float16 max is 65504).
F16_TARGET_MAX = 2.0 ** 12
#: Values with ``|x| >= SIGNIFICANT_REL * max|x|`` must survive float16 as normal numbers.
SIGNIFICANT_REL = 1e-6

_F16_MIN_NORMAL = 2.0 ** -14


@dataclass(frozen=True)
class Float16Report:
    """What the float16 conversion did to a basis.

    Attributes
    ----------
    scale : float
        Power of two applied before the conversion (stored = round_f16(x * scale)).
    max_abs : float
        Largest input magnitude.
    n_overflow : int
        Values that became ``inf`` (always 0 on return: conversion raises otherwise).
    n_underflow : int
        Significant values (``|x| >= SIGNIFICANT_REL * max_abs``) that became zero or subnormal
        (always 0 on return).
    n_flushed : int
        Non-zero, insignificant values that became zero or subnormal (reported, allowed).
    max_rel_error : float
        Largest relative rounding error over significant values (<= 2**-11 for normal float16).
    """

    scale: float
    max_abs: float
    n_overflow: int
    n_underflow: int
    n_flushed: int
    max_rel_error: float


def choose_scale(max_abs: float, target: float = F16_TARGET_MAX) -> float:
    """Power-of-two scale ``s`` with ``max_abs * s`` in ``(target / 2, target]``; 1 for an all-zero basis.

    Parameters
    ----------
    max_abs : float
        Largest magnitude of the basis, finite and >= 0.
    target : float
        Where the largest magnitude should land.
    """
    if not np.isfinite(max_abs) or max_abs < 0:
        raise ValueError(f"max_abs must be finite and >= 0, not {max_abs}")
    if max_abs == 0:
        return 1.0
    return float(2.0 ** np.floor(np.log2(target / max_abs)))


def to_float16(basis: np.ndarray, scale: float | None = None, path=None, chunk: int = 64,
               max_abs: float | None = None) -> tuple[np.ndarray, Float16Report]:
    """Scale and convert a basis to float16, checking overflow and underflow.

    Parameters
    ----------
    basis : (n, ...) float array
        Finite values.
    scale : float, optional
        Scale to apply; default :func:`choose_scale` of the basis.
    path : path-like, optional
        Named in errors.
    chunk : int
        Layers converted at a time (bounds the temporaries).
    max_abs : float, optional
        The dataset's largest magnitude when ``basis`` is one part of it (defines which values
        are significant); default the largest magnitude of ``basis``.

    Returns
    -------
    (n, ...) float16 ndarray, Float16Report

    Raises
    ------
    InputError
        On NaN/Inf input, on overflow to inf, or on underflow of significant values.
    """
    basis = np.asarray(basis)
    if basis.size and not np.all(np.isfinite(basis)):
        bad = int(np.count_nonzero(~np.isfinite(basis)))
        raise InputError(f"basis has {bad} NaN/Inf values; cannot upload", path)
    if max_abs is None:
        max_abs = float(np.max(np.abs(basis))) if basis.size else 0.0
    if scale is None:
        scale = choose_scale(max_abs)
    out = np.empty(basis.shape, dtype=np.float16)
    n_over = n_under = n_flush = 0
    rel = 0.0
    sig = SIGNIFICANT_REL * max_abs
    for a in range(0, max(basis.shape[0], 1) if basis.ndim else 1, chunk):
        x = np.asarray(basis[a:a + chunk], dtype=np.float32) * np.float32(scale)
        with np.errstate(over="ignore"):
            h = x.astype(np.float16)
        out[a:a + chunk] = h
        hf = h.astype(np.float32)
        n_over += int(np.count_nonzero(np.isinf(hf)))
        tiny = (np.abs(hf) < _F16_MIN_NORMAL) & (x != 0)
        significant = np.abs(x) >= np.float32(sig * scale)
        n_under += int(np.count_nonzero(tiny & significant & (sig > 0)))
        n_flush += int(np.count_nonzero(tiny & ~significant))
        m = significant & (x != 0) & np.isfinite(hf)
        if np.any(m):
            rel = max(rel, float(np.max(np.abs(hf[m] - x[m]) / np.abs(x[m]))))
    report = Float16Report(float(scale), max_abs, n_over, n_under, n_flush, rel)
    if n_over:
        raise InputError(f"float16 basis: {n_over} values overflow to inf at scale {scale:g} (max |x| = {max_abs:g})", path)
    if n_under:
        raise InputError(f"float16 basis: {n_under} significant values underflow at scale {scale:g} "
                         f"(max |x| = {max_abs:g}); use dtype='f32'", path)
    return out, report
