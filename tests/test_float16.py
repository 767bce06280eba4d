"""The checked float16 conversion (ffls.store.float16) against its whole-array NumPy reference.

:func:`to_float16` converts and checks in cache-sized blocks with OpenCV's half casts; the
reference below is the whole-array form it replaced (NumPy casts, boolean masks). Both must give
the same float16 bytes, the same report and the same errors, whatever the blocks.
"""
from __future__ import annotations

import tracemalloc
import warnings

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.io.images import narrow_to_half, widen_half
from ffls.store import float16
from ffls.store.float16 import SIGNIFICANT_REL, Float16Report, choose_scale, finite_max_abs, to_float16


def _reference(basis, scale=None, path=None, max_abs=None):
    """The whole-array conversion and checks (float16 of ``basis * scale`` and its report)."""
    basis = np.asarray(basis)
    if basis.size and not np.all(np.isfinite(basis)):
        bad = int(np.count_nonzero(~np.isfinite(basis)))
        raise InputError(f"basis has {bad} NaN/Inf values; cannot upload", path)
    if max_abs is None:
        max_abs = float(np.max(np.abs(basis))) if basis.size else 0.0
    if scale is None:
        scale = choose_scale(max_abs)
    sig = SIGNIFICANT_REL * max_abs
    x = np.asarray(basis, dtype=np.float32) * np.float32(scale)
    with np.errstate(over="ignore"):
        h = x.astype(np.float16)
    hf = h.astype(np.float32)
    n_over = int(np.count_nonzero(np.isinf(hf)))
    tiny = (np.abs(hf) < 2.0 ** -14) & (x != 0)
    significant = np.abs(x) >= np.float32(sig * scale)
    n_under = int(np.count_nonzero(tiny & significant & (sig > 0)))
    n_flush = int(np.count_nonzero(tiny & ~significant))
    m = significant & (x != 0) & np.isfinite(hf)
    rel = float(np.max(np.abs(hf[m] - x[m]) / np.abs(x[m]))) if np.any(m) else 0.0
    if n_over:
        raise InputError(f"float16 basis: {n_over} values overflow to inf at scale {scale:g} "
                         f"(max |x| = {max_abs:g})", path)
    if n_under:
        raise InputError(f"float16 basis: {n_under} significant values underflow at scale {scale:g} "
                         f"(max |x| = {max_abs:g}); use dtype='f32'", path)
    return h, Float16Report(float(scale), max_abs, n_over, n_under, n_flush, rel)


def _outcome(fn, *args, **kw):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # (a float32 product may overflow: checked)
            h, rep = fn(*args, **kw)
    except InputError as e:
        return "error", str(e)
    return "ok", h.shape, h.tobytes(), rep


def _random_basis(rng, n_max=7):
    shape = tuple(int(v) for v in rng.integers(1, n_max, size=rng.integers(1, 5)))
    x = rng.standard_normal(shape) * 10.0 ** rng.uniform(-12, 8, size=shape)  # 20 decades
    x[rng.random(shape) < 0.3] = 0.0
    x[rng.random(shape) < 0.05] = -0.0
    if rng.random() < 0.1:
        x.flat[rng.integers(x.size)] = rng.choice([np.nan, np.inf, -np.inf])
    with np.errstate(over="ignore"):  # (float16 input: its own infinities, refused as input)
        x = x.astype(rng.choice([np.float32, np.float32, np.float64, np.float16]))
    if x.ndim > 1 and rng.random() < 0.3:
        x = x[:, ::-1]  # not C-contiguous
    return x


@pytest.mark.parametrize("block", [7, 64, float16.BLOCK_VALUES])
def test_to_float16_matches_whole_array_reference(monkeypatch, block):
    monkeypatch.setattr(float16, "BLOCK_VALUES", block)
    rng = np.random.default_rng(block)
    seen = set()
    for _ in range(300):
        x = _random_basis(rng)
        kw = {}
        finite = x[np.isfinite(x)]
        top = float(np.max(np.abs(finite))) if finite.size else 0.0
        if rng.random() < 0.4:
            kw["scale"] = float(2.0 ** rng.integers(-30, 30))
        if rng.random() < 0.5:
            kw["max_abs"] = top * float(rng.choice([1.0, 8.0, 1e-3]))
        if rng.random() < 0.3:
            kw["chunk"] = int(rng.integers(1, 4))
        got = _outcome(to_float16, x, path="cap", **kw)
        kw.pop("chunk", None)
        want = _outcome(_reference, x, path="cap", **kw)
        assert got[0] == want[0] and got[1:] == want[1:], (x.dtype, x.shape, kw, got[-1], want[-1])
        seen.add(got[-1] if got[0] == "error" else ("flushed" if got[-1].n_flushed else "ok"))
    # every outcome was met: clean, flushed values, non-finite input, overflow, underflow
    assert {"ok", "flushed"} <= seen
    for what in ("NaN/Inf values", "overflow to inf", "significant values underflow"):
        assert any(what in s for s in seen), what


def test_to_float16_of_a_photo_basis_matches_reference():
    """Half-precision photos (exact after a power-of-two scale), dark noise and black background."""
    rng = np.random.default_rng(3)
    b = (rng.random((6, 64, 80, 3)) ** 6).astype(np.float16).astype(np.float32)
    b[:, :20] = 0.0
    b[2, 5, 5] = 1e-9  # flushed, insignificant
    for kw in ({}, {"max_abs": float(b.max())}, {"scale": 2.0 ** 11}):
        assert _outcome(to_float16, b, **kw)[1:] == _outcome(_reference, b, **kw)[1:]
    _, rep = to_float16(b)
    assert rep.n_flushed == 3 and rep.max_rel_error == 0.0


def test_to_float16_makes_no_temporary_of_the_basis_size():
    """The checks run in blocks of BLOCK_VALUES: beside its result, the conversion of a 50 MB
    basis holds 7 MiB (the whole-array checks held 300 MiB: copies of 64 layers)."""
    b = np.random.default_rng(0).random((64, 256, 256, 3), dtype=np.float32)
    tracemalloc.start()
    try:
        h, _ = to_float16(b, max_abs=1.0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak - h.nbytes < 16 * 2 ** 20, peak  # (the whole-array checks: 300 MiB)


def test_finite_max_abs():
    rng = np.random.default_rng(5)
    for dtype in (np.float16, np.float32, np.float64):
        x = rng.standard_normal((5, 7, 3)).astype(dtype)
        assert finite_max_abs(x) == float(np.max(np.abs(x)))
        assert finite_max_abs(x[:, ::-1]) == float(np.max(np.abs(x)))
        y = x.copy()
        y[4, 6, 2] = np.nan
        assert np.isnan(finite_max_abs(y))
        y[4, 6, 2] = -np.inf
        assert finite_max_abs(y) == np.inf
    assert finite_max_abs(np.zeros((0, 3), np.float32)) == 0.0
    assert repr(finite_max_abs(-np.zeros((2, 3), np.float32))) == "0.0"


def test_half_casts_match_numpy_bit_for_bit():
    """OpenCV's float32 -> float16 rounding is NumPy's on every class of value: the float16
    values, the midpoints between neighbours (ties to even) and one float32 ulp either side, the
    subnormal range and the overflow threshold; the widening back is exact."""
    h = np.arange(1 << 16, dtype=np.uint16).view(np.float16)
    h = h[np.isfinite(h)]
    v = h.astype(np.float64)
    v = np.sort(v)
    mid = (v[:-1] + v[1:]) / 2
    x = np.concatenate([v, mid, [65504.0, 65519.99, 65520.0, 1e9, 2.0 ** -25, 2.0 ** -26]]).astype(np.float32)
    up, down = np.nextafter(x, np.float32(np.inf)), np.nextafter(x, np.float32(-np.inf))
    x = np.concatenate([x, up, down, -x, np.float32(np.random.default_rng(1).standard_normal(10000))])
    out = np.empty(x.shape, np.float16)
    narrow_to_half(x, out)
    with np.errstate(over="ignore"):
        want = x.astype(np.float16)
    assert np.array_equal(out.view(np.uint16), want.view(np.uint16))
    back = np.empty(x.shape, np.float32)
    widen_half(out.reshape(-1, 1, 1), back.reshape(-1, 1, 1))
    assert np.array_equal(back.view(np.uint32), want.astype(np.float32).view(np.uint32))


@pytest.mark.gl
def test_basis_textures_hold_the_checked_float16_values_and_zero_alpha(ctx):
    """The f16 texture arrays hold to_float16's values and alpha 0 (the RGBA layers are assembled by
    OpenCV's channel copy), over two arrays."""
    from ffls.gpu.basis import BasisTextures

    rng = np.random.default_rng(7)
    b = (rng.random((5, 9, 11, 3)) ** 3).astype(np.float32)
    b[1, 2, 3] = 0.0
    bt = BasisTextures(ctx, b, "f16", max_layers=3)
    try:
        h, rep = to_float16(b)
        want = np.zeros((5, 9, 11, 4), np.float16)
        want[..., :3] = h
        got = np.concatenate([np.frombuffer(t.read(), np.float16).reshape(-1, 9, 11, 4) for t in bt.textures])
        assert bt.n_arrays == 2 and got.tobytes() == want.tobytes()
        assert bt.report == rep
    finally:
        bt.release()
