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
from ffls.io.images import narrow_to_half, widen_half

__all__ = ["F16_TARGET_MAX", "SIGNIFICANT_REL", "Float16Report", "choose_scale", "finite_max_abs",
           "to_float16"]

#: The largest basis magnitude after scaling to float16 (2**12; float16 max is 65504).
F16_TARGET_MAX = 2.0 ** 12
#: Values with ``|x| >= SIGNIFICANT_REL * max|x|`` must survive float16 as normal numbers.
SIGNIFICANT_REL = 1e-6

_F16_MIN_NORMAL = 2.0 ** -14
#: Values checked at a time by :func:`to_float16` and :func:`finite_max_abs` (1 MiB of float32): the
#: temporaries of the checks stay in the CPU's cache, and no temporary of a whole basis is made.
BLOCK_VALUES = 1 << 18


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


def _flat_blocks(a: np.ndarray, per: int | None = None):
    """``a``'s values in C order as ``(offset, block)``: flat views of at most
    :data:`BLOCK_VALUES` values and the C-order index of each one's first value. By default a
    C-contiguous ``a`` is walked whole and another one layer range at a time (copied); with
    ``per``, always ``per`` layers at a time (copied only where not C-contiguous)."""
    block = BLOCK_VALUES
    a = a.reshape(1) if a.ndim == 0 else a
    if per is None and a.flags.c_contiguous:
        flat = a.reshape(-1)
        for i in range(0, flat.size, block):
            yield i, flat[i:i + block]
        return
    if per is None:
        per = max(1, block // max(1, a[0].size))
    row = a[0].size if a.shape[0] else 0
    for k in range(0, a.shape[0], per):
        flat = np.ascontiguousarray(a[k:k + per]).reshape(-1)
        for i in range(0, flat.size, block):
            yield k * row + i, flat[i:i + block]


def finite_max_abs(basis: np.ndarray) -> float:
    """Largest magnitude of ``basis`` in one pass of cache-sized blocks (no temporary of its size).

    Returns
    -------
    float
        ``max |x|`` (0 for an empty array); NaN or inf where ``basis`` holds a NaN or an inf, so
        that one ``np.isfinite`` of the result checks the whole array.
    """
    basis = np.asarray(basis)
    top = 0.0
    buf = None
    for _, blk in _flat_blocks(basis):
        if buf is None:
            buf = np.empty(blk.size, dtype=blk.dtype)
        v = float(np.abs(blk, out=buf[:blk.size]).max())
        if not v <= top:  # (a NaN stays: NaN compares false)
            top = v
            if np.isnan(v):
                break
    return top


def to_float16(basis: np.ndarray, scale: float | None = None, path=None, chunk: int = 64,
               max_abs: float | None = None) -> tuple[np.ndarray, Float16Report]:
    """Scale and convert a basis to float16, checking overflow and underflow.

    The values are converted and checked in cache-sized blocks (:data:`BLOCK_VALUES`): the result
    and the report do not depend on the blocks (counts add up, the error is a maximum).

    Parameters
    ----------
    basis : (n, ...) float array
        Finite values.
    scale : float, optional
        Scale to apply; default :func:`choose_scale` of the basis.
    path : path-like, optional
        Named in errors.
    chunk : int
        Layers at most copied at a time where ``basis`` is not C-contiguous (bounds that copy).
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
    checked = False  # every value known finite
    if max_abs is None or not (np.isfinite(max_abs) and max_abs >= 0):
        top = finite_max_abs(basis) if basis.size else 0.0
        if not np.isfinite(top):
            _raise_nonfinite(basis, path)
        checked = True
        max_abs = top if max_abs is None else max_abs
    if scale is None:
        scale = choose_scale(max_abs)
    out = np.empty(basis.shape, dtype=np.float16)
    sig = SIGNIFICANT_REL * max_abs
    s32, sig32 = np.float32(scale), np.float32(sig * scale)
    # where sig * scale >= 2**-14, a significant value rounds to a normal float16 (rounding is
    # monotone and 2**-14 is a float16): no significant value can underflow, and every value that
    # becomes zero or subnormal is a flushed one; blocks that hold an inf or a NaN after the
    # conversion take the general checks
    fast = sig > 0 and sig32 >= _F16_MIN_NORMAL
    counts = np.zeros(3, dtype=np.int64)  # overflow, underflow, flushed
    rel = 0.0
    chunk = max(1, int(chunk))
    dst_f = out.reshape(-1)
    bufs = None
    for i, src in _flat_blocks(basis, per=chunk):
        dst = dst_f[i:i + src.size]
        if bufs is None:
            bufs = _Buffers(src.size)
        x = bufs.scaled(src, s32)
        narrow_to_half(x, dst)
        if fast and bufs.all_finite(dst):  # (a NaN or inf of the input is one after it)
            counts[2] += bufs.flushed(x, dst)
            rel = max(rel, bufs.max_rel_error(x, dst, sig32))
            continue
        if not checked and not np.all(np.isfinite(src)):
            _raise_nonfinite(basis, path)
        rel = max(rel, _check_block(x, dst, sig, sig32, counts))
    n_over, n_under, n_flush = (int(c) for c in counts)
    report = Float16Report(float(scale), max_abs, n_over, n_under, n_flush, rel)
    if n_over:
        raise InputError(f"float16 basis: {n_over} values overflow to inf at scale {scale:g} (max |x| = {max_abs:g})", path)
    if n_under:
        raise InputError(f"float16 basis: {n_under} significant values underflow at scale {scale:g} "
                         f"(max |x| = {max_abs:g}); use dtype='f32'", path)
    return out, report


def _raise_nonfinite(basis: np.ndarray, path):
    bad = int(np.count_nonzero(~np.isfinite(basis)))
    raise InputError(f"basis has {bad} NaN/Inf values; cannot upload", path)


def _check_block(x: np.ndarray, h: np.ndarray, sig: float, sig32, counts: np.ndarray) -> float:
    """The general checks of one block: ``x`` the scaled float32 values, ``h`` their float16;
    adds (overflow, underflow, flushed) to ``counts`` and returns the largest relative error."""
    hf = h.astype(np.float32)
    counts[0] += np.count_nonzero(np.isinf(hf))
    tiny = (np.abs(hf) < _F16_MIN_NORMAL) & (x != 0)
    significant = np.abs(x) >= sig32
    counts[1] += np.count_nonzero(tiny & significant & (sig > 0))
    counts[2] += np.count_nonzero(tiny & ~significant)
    m = significant & (x != 0) & np.isfinite(hf)
    if np.any(m):
        return float(np.max(np.abs(hf[m] - x[m]) / np.abs(x[m])))
    return 0.0


class _Buffers:
    """Scratch arrays of one block for :func:`to_float16`'s checks (reused: no allocation per block)."""

    def __init__(self, n: int):
        self.x = np.empty(n, dtype=np.float32)
        self.e = np.empty(n, dtype=np.float32)
        self.d = np.empty(n, dtype=np.float32)
        self.bits = np.empty(n, dtype=np.uint16)
        self.words = np.empty(n, dtype=np.uint32)
        self.mask = np.empty(n, dtype=bool)

    def scaled(self, src: np.ndarray, s32) -> np.ndarray:
        """``float32(src) * s32`` (the float32 product, as ``np.asarray(src, float32) * s32``)."""
        x = self.x[:src.size]
        if src.dtype != np.float32:
            np.copyto(x, src, casting="unsafe")
            src = x
        return np.multiply(src, s32, out=x)

    def all_finite(self, h: np.ndarray) -> bool:
        """No inf or NaN in the float16 block ``h`` (exponent bits all set: magnitude >= 0x7c00);
        leaves the magnitudes' bits in ``self.bits``."""
        bits = np.bitwise_and(h.view(np.uint16), np.uint16(0x7FFF), out=self.bits[:h.size])
        return bool(bits.max() < 0x7C00)

    def flushed(self, x: np.ndarray, h: np.ndarray) -> int:
        """Non-zero values of ``x`` whose float16 ``h`` is zero or subnormal (exponent bits 0), from
        :meth:`all_finite`'s bits: non-zero values less those that stayed normal (a zero of ``x``
        is a zero of ``h``)."""
        nonzero = np.left_shift(x.view(np.uint32), 1, out=self.words[:x.size])  # (no sign: +-0 are 0)
        normal = np.right_shift(self.bits[:h.size], 10, out=self.bits[:h.size])
        return int(np.count_nonzero(nonzero)) - int(np.count_nonzero(normal))

    def max_rel_error(self, x: np.ndarray, h: np.ndarray, sig32) -> float:
        """``max |float32(h) - x| / |x|`` over ``|x| >= sig32`` (> 0), each in float32 as
        :func:`_check_block` forms it: the others' numerators are set to 0 and their
        denominators to ``sig32`` (0 / sig32 = 0 adds nothing to a maximum of values >= 0)."""
        n = x.size
        e, d, m = self.e[:n], self.d[:n], self.mask[:n]
        widen_half(h.reshape(n, 1, 1), e.reshape(n, 1, 1))
        np.subtract(e, x, out=e)
        np.abs(e, out=e)
        np.abs(x, out=d)
        np.greater_equal(d, sig32, out=m)
        np.multiply(e, m, out=e)
        np.maximum(d, sig32, out=d)
        np.divide(e, d, out=e)
        return float(e.max())
