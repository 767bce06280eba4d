"""Pass 2 (weighted sum), float16 basis, split arrays, compression, tone-map shader, Engine, ``ffls render``.

Tolerances (the reference is float64 ``relight_reference``):

* ``max |gpu - ref| <= TOL * max |ref|`` over the image, and
* per pixel ``|gpu - ref| <= TOL * |ref|`` wherever ``|ref| >= 0.1 max |ref|`` (bright pixels),

with ``TOL = 1e-3`` for both storages (float16 rounds each basis value by <= 2**-11 = 4.9e-4
relative; a sum of non-negative terms keeps that bound; float32 is ~1e-6).
Display images: at most one 8-bit code value from ``to_uint8(tonemap(...))``.
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.errors import InputError

TOL = 1e-3


def _check_close(gpu, ref, tol=TOL):
    gpu = np.asarray(gpu, dtype=np.float64)
    assert gpu.shape == ref.shape
    assert np.all(np.isfinite(gpu))
    scale = np.abs(ref).max()
    assert np.abs(gpu - ref).max() <= tol * scale, np.abs(gpu - ref).max() / scale
    bright = np.abs(ref) >= 0.1 * scale
    assert np.all(np.abs(gpu - ref)[bright] <= tol * np.abs(ref)[bright])


def _basis(rng, n, H=16, W=16, dynamic=True):
    b = rng.random((n, H, W, 3), dtype=np.float32)
    if dynamic:  # several decades, as real radiance
        b *= np.float32(10.0) ** rng.uniform(-3, 1, size=(n, 1, 1, 1)).astype(np.float32)
    return b


def _run_pass2(ctx, basis, w, dtype="f16", method="compute", **kw):
    from ffls.gpu.basis import BasisTextures, PackedBasis
    from ffls.gpu.context import release_gl
    from ffls.gpu.weighted_sum import WeightedSum, weights_to_vec4

    bt = (PackedBasis if method == "packed" else BasisTextures)(ctx, basis, dtype, **kw)
    ws = WeightedSum(ctx, bt, method)
    buf = ctx.buffer(weights_to_vec4(w))
    try:
        ws.run(buf)
        return ws.read(), bt.n_arrays
    finally:
        release_gl(buf)
        ws.release()
        bt.release()


# ----------------------------------------------------------------------------- float16 checks (no GL)
def test_float16_scale_keeps_1e6_finite():
    from ffls.gpu.basis import F16_TARGET_MAX, to_float16

    b = np.array([[1e6, 1.0, 1e-3, 0.0]], dtype=np.float32)
    h, rep = to_float16(b)
    assert np.all(np.isfinite(h))
    assert rep.n_overflow == 0 and rep.n_underflow == 0
    assert F16_TARGET_MAX / 2 < 1e6 * rep.scale <= F16_TARGET_MAX
    # significant values (>= 1e-6 of the max) keep float16's relative precision ...
    np.testing.assert_allclose(h[0, :2].astype(np.float64) / rep.scale, b[0, :2], rtol=2 ** -11)
    assert rep.max_rel_error <= 2 ** -11
    # ... 1e-3 (1e-9 of the max) becomes subnormal: allowed, but counted
    assert rep.n_flushed == 1


def test_float16_overflow_and_underflow_are_reported():
    from ffls.gpu.basis import to_float16

    with pytest.raises(InputError, match="overflow"):
        to_float16(np.array([1e6, 1.0], dtype=np.float32), scale=1.0)
    with pytest.raises(InputError, match="underflow"):  # 1e-3 is significant next to 1.0
        to_float16(np.array([1.0, 1e-3], dtype=np.float32), scale=2.0 ** -16)
    with pytest.raises(InputError, match="NaN"):
        to_float16(np.array([1.0, np.nan], dtype=np.float32))
    # insignificant values may flush to zero, and are counted
    _, rep = to_float16(np.array([1.0, 1e-12], dtype=np.float32))
    assert rep.n_flushed == 1 and rep.n_underflow == 0


# ----------------------------------------------------------------------------- pass 2
@pytest.mark.gl
@pytest.mark.parametrize("dtype", ["f16", "f32"])
@pytest.mark.parametrize("method", ["compute", "fragment", "packed"])
def test_pass2_matches_reference(ctx, rng, dtype, method):
    from ffls.relight.cpu import relight_reference

    basis = _basis(rng, 64, 12, 20)
    w = rng.random((64, 3)) * 3
    gpu, _ = _run_pass2(ctx, basis, w, dtype, method)
    _check_close(gpu, relight_reference(w, basis))


@pytest.mark.gl
@pytest.mark.parametrize("method", ["compute", "fragment", "packed"])
def test_two_pass2_instances_of_different_sizes_share_a_context(ctx, rng, method):
    """The programs are cached per context: an instance made after another of another size must not
    change the first's image size (the viewer's composite, the tiled engine's tiles)."""
    from ffls.gpu.basis import BasisTextures, PackedBasis
    from ffls.gpu.context import release_gl
    from ffls.gpu.weighted_sum import ToneMapPass, WeightedSum, weights_to_vec4
    from ffls.relight.cpu import relight_reference

    kind = PackedBasis if method == "packed" else BasisTextures
    a, b = _basis(rng, 8, 12, 20), _basis(rng, 8, 7, 33)
    w = rng.random((8, 3))
    ta, tb = kind(ctx, a, "f32"), kind(ctx, b, "f32")
    wa, wb = WeightedSum(ctx, ta, method), WeightedSum(ctx, tb, method)  # both made before either runs
    pa, pb = ToneMapPass(ctx, wa.size), ToneMapPass(ctx, wb.size)
    buf = ctx.buffer(weights_to_vec4(w))
    try:
        wa.run(buf)
        wb.run(buf)
        _check_close(wa.read(), relight_reference(w, a))
        _check_close(wb.read(), relight_reference(w, b))
        pa.run(wa.output)
        pb.run(wb.output)
        assert pa.read().shape == (12, 20, 3) and pb.read().shape == (7, 33, 3)
        assert pa.read().any()  # written over the whole image, not clipped to the other's size
    finally:
        release_gl(buf)
        for x in (pa, pb, wa, wb, ta, tb):
            x.release()


@pytest.mark.gl
@pytest.mark.parametrize("n", [1, 2048])
@pytest.mark.parametrize("method", ["compute", "packed"])
def test_pass2_extreme_light_counts(ctx, rng, n, method):
    from ffls.gpu.basis import ARRAY_LAYERS, PACKED_LAYERS
    from ffls.relight.cpu import relight_reference

    basis = _basis(rng, n, 16, 16)
    w = rng.random((n, 3))
    gpu, n_arrays = _run_pass2(ctx, basis, w, "f16", method)
    if method == "packed":  # chunks of PACKED_LAYERS layers, one unrolled dispatch each
        assert n_arrays == -(-n // PACKED_LAYERS)
    else:  # arrays of ARRAY_LAYERS layers (256: an H100 read one array of 1024 at half the speed)
        assert ARRAY_LAYERS == 256 and n_arrays == -(-n // ARRAY_LAYERS)
    _check_close(gpu, relight_reference(w, basis))


@pytest.mark.gl
@pytest.mark.parametrize("dtype", ["f16", "f32"])
@pytest.mark.parametrize("method", ["compute", "packed"])
def test_sun_1e6_no_float16_overflow(ctx, rng, dtype, method):
    """A 1e6 basis value (a specular glint) and a 1e6 sun weight next to 1e-3 sky weights."""
    from ffls.relight.cpu import relight_reference

    basis = _basis(rng, 32, 8, 8, dynamic=False)
    basis[3, 2, 5] = 1e6
    w = np.full((32, 3), 1e-3)
    w[3] = 1e6
    gpu, _ = _run_pass2(ctx, basis, w, dtype, method)
    ref = relight_reference(w, basis)
    assert ref.max() > 1e11  # far beyond float16, inside float32
    _check_close(gpu, ref)


@pytest.mark.gl
@pytest.mark.parametrize("method", ["compute", "fragment"])
def test_split_arrays_match_reference(ctx, rng, method):
    from ffls.relight.cpu import relight_reference

    basis = _basis(rng, 50, 8, 12)
    w = rng.random((50, 3))
    gpu, n_arrays = _run_pass2(ctx, basis, w, "f16", method, max_layers=7)
    assert n_arrays == 8  # 7 * 7 + 1: the last array holds one layer, nothing truncated
    _check_close(gpu, relight_reference(w, basis))


@pytest.mark.gl
@pytest.mark.parametrize("dtype", ["f16", "f32"])
def test_packed_chunks_and_bands_match_reference(ctx, rng, dtype):
    """Layers cut into chunks (7 layers: an unaligned uniform-block offset, padded blocks) and
    rows into bands (a band buffer of 3 rows), signed values as in eigen-images."""
    from ffls.relight.cpu import relight_reference

    n, H, W = 50, 10, 12
    basis = _basis(rng, n, H, W) * rng.choice([-1.0, 1.0], size=(n, H, W, 3)).astype(np.float32)
    basis[:, 0, 0] = 0.0  # zeros stay zeros (no float16 bias artefact)
    w = rng.random((n, 3))
    per = 8 if dtype == "f16" else 4
    band_bytes = 3 * W * 48 * -(-7 // per)
    gpu, n_arrays = _run_pass2(ctx, basis, w, dtype, "packed", max_layers=7, band_bytes=band_bytes)
    assert n_arrays == 8
    ref = relight_reference(w, basis)
    # signed sums may cancel: the max-norm bound only, plus exact zeros
    assert np.abs(gpu - ref).max() <= TOL * np.abs(ref).max()
    assert np.all(gpu[0, 0] == 0.0)


@pytest.mark.gl
@pytest.mark.parametrize("dtype", ["f16", "f32"])
def test_packed_image_and_buffer_storage_agree(ctx, rng, dtype):
    """The packed basis read through imageLoad (storage 'image', the default) and through SSBO
    bands (storage 'buffer') give the same image, both within the tolerance of the reference;
    several chunks (7 layers, padded blocks) accumulate in the image path as in the buffer path."""
    from ffls.relight.cpu import relight_reference

    n, H, W = 23, 9, 13
    basis = _basis(rng, n, H, W) * rng.choice([-1.0, 1.0], size=(n, H, W, 3)).astype(np.float32)
    w = rng.random((n, 3))
    ref = relight_reference(w, basis)
    img, n_img = _run_pass2(ctx, basis, w, dtype, "packed", max_layers=7, storage="image")
    buf, n_buf = _run_pass2(ctx, basis, w, dtype, "packed", max_layers=7, storage="buffer")
    assert n_img == n_buf == 4
    assert np.abs(img - ref).max() <= TOL * np.abs(ref).max()
    np.testing.assert_allclose(img, buf, rtol=1e-6, atol=1e-6 * np.abs(ref).max())
    with pytest.raises(ValueError, match="storage"):
        _run_pass2(ctx, basis, w, dtype, "packed", storage="texture")


@pytest.mark.gl
@pytest.mark.parametrize("method", ["srgb", "reinhard", "aces"])
def test_packed_pass2_fused_display_equals_display_pass(ctx, rng, method):
    """WeightedSum.run(display=) writes, in its last chunk, the same display bytes as ToneMapPass
    over the HDR it wrote (same curves); the HDR is unchanged by it."""
    from ffls.gpu.basis import PackedBasis
    from ffls.gpu.context import release_gl
    from ffls.gpu.weighted_sum import ToneMapPass, WeightedSum, weights_to_vec4

    n, H, W = 19, 11, 17
    basis = _basis(rng, n, H, W) * 3.0
    w = rng.random((n, 3))
    pb = PackedBasis(ctx, basis, "f16", max_layers=8)
    ws = WeightedSum(ctx, pb, "packed")
    fused, sep = ToneMapPass(ctx, ws.size), ToneMapPass(ctx, ws.size)
    buf = ctx.buffer(weights_to_vec4(w))
    try:
        for ev in (-1.0, 0.5):
            ws.run(buf)
            hdr = ws.read()
            sep.run(ws.output, ev, method)
            ws.run(buf, display=(fused.output, ev, method))
            np.testing.assert_array_equal(ws.read(), hdr)
            assert np.abs(fused.read().astype(int) - sep.read().astype(int)).max() <= 1
            assert fused.read().any()
        with pytest.raises(ValueError, match="tone-map"):
            ws.run(buf, display=(fused.output, 0.0, "gamma"))
    finally:
        release_gl(buf)
        for x in (fused, sep, ws, pb):
            x.release()


def test_pack_pixel_major_layout(rng):
    """Word k of block b, channel c holds layers 8b + 2k (low half) and 8b + 2k + 1 (high half)."""
    from ffls.gpu.basis import pack_pixel_major

    m, h, w = 11, 3, 4
    x = rng.standard_normal((m, h, w, 3)).astype(np.float16)
    words = pack_pixel_major(x, "f16")
    assert words.shape == (h, w, 2, 3, 4) and words.dtype == np.uint32
    halves = words.view(np.uint16).reshape(h, w, 2, 3, 8).view(np.float16)  # little-endian: low half first
    for i in range(16):
        b, k = divmod(i, 8)
        expect = x[i] if i < m else np.zeros((h, w, 3), np.float16)
        np.testing.assert_array_equal(halves[:, :, b, :, k], expect)
    y = rng.random((5, h, w, 3), dtype=np.float32)
    f = pack_pixel_major(y, "f32").view(np.float32)
    assert f.shape == (h, w, 2, 3, 4)
    np.testing.assert_array_equal(f[:, :, 1, :, 0], y[4])
    assert np.all(f[:, :, 1, :, 1:] == 0)


@pytest.mark.gl
def test_pass2_method_needs_matching_storage(ctx, rng):
    from ffls.gpu.basis import BasisTextures, PackedBasis
    from ffls.gpu.weighted_sum import WeightedSum

    basis = _basis(rng, 3, 4, 4)
    pb = PackedBasis(ctx, basis)
    bt = BasisTextures(ctx, basis)
    try:
        with pytest.raises(TypeError, match="PackedBasis"):
            WeightedSum(ctx, bt, "packed")
        with pytest.raises(TypeError, match="BasisTextures"):
            WeightedSum(ctx, pb, "fragment")
    finally:
        pb.release()
        bt.release()


@pytest.mark.gl
def test_over_budget_is_refused(ctx, rng):
    from ffls.gpu.basis import BasisTextures, PackedBasis

    with pytest.raises(InputError, match="budget"):
        BasisTextures(ctx, _basis(rng, 4, 8, 8), "f16", budget_bytes=1000)
    with pytest.raises(InputError, match="budget"):
        PackedBasis(ctx, _basis(rng, 4, 8, 8), "f16", budget_bytes=1000)


# ----------------------------------------------------------------------------- compression
def _lowrank_basis(rng, n=40, H=12, W=16, r=5, noise=0.01):
    L = rng.random((n, r))
    S = rng.random((r, H, W, 3))
    return (np.einsum("nk,khwc->nhwc", L, S) + noise * rng.random((n, H, W, 3))).astype(np.float32)


@pytest.mark.parametrize("mode", ["per_channel", "shared"])
def test_compression_algebra_and_error(rng, mode):
    from ffls.relight.compress import compress_basis
    from ffls.relight.cpu import relight_reference

    basis = _lowrank_basis(rng)
    w = rng.random((40, 3))
    ref = relight_reference(w, basis)
    cb = compress_basis(basis, 8, mode=mode)
    # exact projection algebra: sum_i w_i (M + sum_k U_ik E_k) == (sum w) M + sum_k c_k E_k
    recon = np.stack([cb.reconstruct(i) for i in range(40)])
    np.testing.assert_allclose(cb.relight(w), relight_reference(w, recon), rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    # rank 8 > the true rank 5: only the 1 % noise is left
    assert np.sqrt(np.mean((cb.relight(w) - ref) ** 2) / np.mean(ref ** 2)) < 5e-3
    # the full rank n - 1 is exact up to float32
    _check_close(compress_basis(basis, 39, mode=mode).relight(w), ref, tol=1e-4)


def test_truncation_errors_match_the_compression_and_choose_rank(rng):
    """The data-driven rank (issue 9 item 9): the spectrum's truncation error equals the measured
    error of :func:`compress_basis` at each K (NumPy reference), and :func:`choose_rank` takes the
    smallest K under the level, raised to whole blocks of 8 layers and capped."""
    from ffls.relight.compress import budget_rank, choose_rank, compress_basis, truncation_errors

    basis = _lowrank_basis(rng, n=40, r=12, noise=0.002)
    err = truncation_errors(basis)
    assert err.shape == (40,) and err[-1] == 0 and np.all(np.diff(err) <= 1e-12)
    b = basis.astype(np.float64)
    for k in (3, 11, 20):
        cb = compress_basis(basis, k)
        recon = np.stack([cb.reconstruct(i) for i in range(40)])
        assert np.sqrt(np.sum((recon - b) ** 2) / np.sum(b ** 2)) == pytest.approx(err[k], rel=0.02, abs=1e-4)
    first = int(np.flatnonzero(err[1:] <= 0.01)[0]) + 1  # the 12 - 1 signal components (the mean is one)
    k, e = choose_rank(basis, max_error=0.01, max_rank=39)
    assert first <= k and (k + 1) % 8 == 0 and k < first + 8 and e == err[k] <= 0.01
    assert choose_rank(basis, max_error=0.01, max_rank=7) == (7, err[7])  # the frame budget binds
    assert choose_rank(basis[:6], max_error=0.0)[0] == 5  # never beyond n - 1
    # the frame budget: three blocks up to 384 x 384, one block (the old default 7) at 512 x 512
    assert [budget_rank(s, s) for s in (64, 256, 384, 512, 2048)] == [23, 23, 23, 7, 7]
    small = _lowrank_basis(rng, n=40, H=300, W=300, r=3)  # the spectrum from a pixel grid
    assert truncation_errors(small, max_pixels=4096)[2] == pytest.approx(truncation_errors(small, 10**6)[2],
                                                                         rel=0.1)


def test_compressed_save_load_roundtrip(tmp_path, rng):
    from ffls.relight.compress import compress_basis, load_compressed, save_compressed

    basis = _lowrank_basis(rng, n=10)
    cb = compress_basis(basis, 6)
    save_compressed(cb, tmp_path)
    cb2 = load_compressed(tmp_path, n_lights=10, shape=(12, 16), rank=4, basis=basis)
    assert cb2.rank == 4
    np.testing.assert_array_equal(cb2.components, cb.components[:4])
    with pytest.raises(InputError, match="lights"):
        load_compressed(tmp_path, n_lights=11)
    with pytest.raises(InputError, match="stale"):
        load_compressed(tmp_path, basis=basis * 2)
    with pytest.raises(InputError, match="rank"):
        load_compressed(tmp_path, rank=7)
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="corrupt"):
        load_compressed(tmp_path / "bad.npz")


@pytest.mark.gl
def test_gpu_projection_and_compressed_pass2(ctx, rng):
    from ffls.relight.compress import compress_basis
    from ffls.gpu.engine import Engine
    from ffls.gpu.context import release_gl
    from ffls.gpu.weighted_sum import Projector, weights_to_vec4
    from ffls.relight.cpu import relight_reference

    basis = _lowrank_basis(rng)
    w = rng.random((40, 3))
    cb = compress_basis(basis, 8)
    proj = Projector(ctx, cb.projection_matrix())
    buf = ctx.buffer(weights_to_vec4(w))
    try:
        proj.run(buf)
        np.testing.assert_allclose(proj.read(), cb.layer_coefficients(w), rtol=1e-5, atol=1e-5)
    finally:
        release_gl(buf)
        proj.release()
    d = _directions(rng, 40)
    cases = [(8, cb.relight(w), "f32", "packed"), (39, relight_reference(w, basis), "f32", "packed"),
             (8, cb.relight(w), "f16", "packed"), (8, cb.relight(w), "f32", "fragment")]
    for rank, ref, dtype, method in cases:
        # eigen-images have both signs: compare with the max-norm bound only
        eng = Engine(ctx, basis, d, dtype=dtype, rank=rank, method=method)
        try:
            eng.set_weights(w)
            eng.render()
            # the packed pass 2 writes the display image itself (no separate display pass)
            assert set(eng.timings) == ({"project", "pass2"} if method == "packed" else {"project", "pass2", "tonemap"})
            gpu = eng.read_hdr().astype(np.float64)
            assert np.abs(gpu - ref).max() <= TOL * np.abs(ref).max()
        finally:
            eng.release()


# ----------------------------------------------------------------------------- tone mapping
@pytest.mark.gl
@pytest.mark.parametrize("method", ["srgb", "reinhard", "aces"])
def test_tonemap_shader_matches_numpy(ctx, rng, method):
    from ffls.gpu.context import release_gl
    from ffls.gpu.weighted_sum import ToneMapPass
    from ffls.display.tonemap import to_uint8, tonemap

    H, W = 16, 24
    hdr = (10.0 ** rng.uniform(-5, 2.5, size=(H, W, 3))).astype(np.float32)
    hdr[0, 0] = 0.0
    hdr[0, 1] = -0.5  # negative radiance (noise) maps to 0 in every curve
    tex = ctx.texture((W, H), 4, data=np.dstack([hdr, np.ones((H, W), np.float32)]).tobytes(), dtype="f4")
    tm = ToneMapPass(ctx, (W, H))
    try:
        for ev in (-2.0, 0.0, 1.5):
            tm.run(tex, ev, method)
            ref = to_uint8(tonemap(hdr.astype(np.float64), ev, method))
            diff = np.abs(tm.read().astype(int) - ref)
            assert diff.max() <= 1, (ev, diff.max())
            assert np.count_nonzero(diff) <= 0.01 * diff.size
    finally:
        tm.release()
        release_gl(tex)


@pytest.mark.gl
@pytest.mark.parametrize("method", ["srgb", "reinhard", "aces"])
def test_tonemap_hands_the_rgba8_store_exact_code_values(ctx, rng, method):
    """tonemap() returns k / 255 (shaders/include/tonemap_curves.glsl): GL lets the float -> UNORM8
    conversion round either way, and an NVIDIA H100 moved ~2 % of unquantised values by one code."""
    from pathlib import Path

    from ffls.display.tonemap import to_uint8, tonemap
    from ffls.gpu.shaders import load_program

    n = 4096
    hdr = (10.0 ** rng.uniform(-5, 2.5, size=(n, 3))).astype(np.float32)
    prog = load_program(ctx, str(Path(__file__).resolve().parent / "shaders" / "tonemap_probe.glsl"))
    b_in = ctx.buffer(np.concatenate([hdr, np.ones((n, 1), np.float32)], axis=1).tobytes())
    b_out = ctx.buffer(reserve=16 * n)
    try:
        b_in.bind_to_storage_buffer(0)
        b_out.bind_to_storage_buffer(1)
        prog["n"] = n
        prog["u_method"] = ["srgb", "reinhard", "aces"].index(method)  # the codes the include documents
        for ev in (-2.0, 0.0, 1.5):
            prog["u_exposure_scale"] = 2.0 ** ev
            prog.run(group_x=-(-n // 64))
            code = np.frombuffer(b_out.read(), dtype="f4").reshape(n, 4)[:, :3].astype(np.float64) * 255
            assert np.abs(code - np.round(code)).max() < 1e-3
            diff = np.abs(np.round(code).astype(int) - to_uint8(tonemap(hdr.astype(np.float64), ev, method)))
            assert diff.max() <= 1 and np.count_nonzero(diff) <= 0.01 * diff.size
    finally:
        b_in.release()
        b_out.release()


# ----------------------------------------------------------------------------- Engine end to end
def _directions(rng, n):
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.05
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.gl
@pytest.mark.parametrize("dtype", ["f16", "f32"])
def test_engine_matches_cpu_pipeline(ctx, rng, dtype):
    from ffls.conventions import rotation_ypr, rotation_z
    from ffls.gpu.engine import Engine
    from ffls.lightmaps.lightmap import sky_sun_map
    from ffls.relight.cpu import relight_reference
    from ffls.display.tonemap import to_uint8, tonemap
    from ffls.weights.voronoi import bake_cells, integrate_weights

    n = 30
    basis = _basis(rng, n, 10, 14)
    d = _directions(rng, n)
    lm = sky_sun_map(32)
    cells = bake_cells(d, "upper", 64)
    eng = Engine(ctx, basis, d, "upper", dtype=dtype, cell_res=64)
    try:
        assert eng.size == (14, 10) and eng.n_lights == n
        for R in (rotation_z(40.0), rotation_ypr(10.0, 20.0, -5.0)):
            eng.set_lightmap(lm)
            eng.set_rotation(R)
            eng.render(exposure=-1.0, tonemap="aces")
            assert {"pass1", "pass2"} <= set(eng.timings)  # the packed pass 2 also writes the display
            w = integrate_weights(lm, d, R, "upper", cells=cells).weights
            np.testing.assert_allclose(eng.read_weights(), w, rtol=1e-4, atol=1e-6 * np.abs(w).max())
            ref = relight_reference(w, basis)
            _check_close(eng.read_hdr(), ref)
            disp = eng.read_display()
            assert np.abs(disp.astype(int) - to_uint8(tonemap(ref, -1.0, "aces"))).max() <= 1
        # a new exposure reruns the display pass only
        eng.render(exposure=0.5, tonemap="aces")
        assert set(eng.timings) == {"tonemap"}
        assert eng.display_texture.components == 4 and eng.hdr_texture.dtype == "f4"
    finally:
        eng.release()


@pytest.mark.gl
def test_render_command_gpu_matches_cpu(tmp_path):
    from ffls.cli import main
    from ffls.io.images import read_image
    from ffls.synth.scene import write_synthetic_capture

    cap = tmp_path / "cap"
    write_synthetic_capture(cap, n_lights=12, resolution=24, progress=False)
    gpu, cpu = tmp_path / "gpu.exr", tmp_path / "cpu.exr"
    assert main(["render", str(cap), "--probe", "sky", "--rotate-z", "30", "--dtype", "f32", "-o", str(gpu)]) == 0
    assert main(["render", str(cap), "--probe", "sky", "--rotate-z", "30", "--cpu", "-o", str(cpu)]) == 0
    a, b = read_image(gpu).pixels.astype(np.float64), read_image(cpu).pixels.astype(np.float64)
    assert np.abs(a - b).max() <= TOL * np.abs(b).max()
    frames = tmp_path / "frames"
    assert main(["render", str(cap), "--probe", "sky", "--turntable", "3", "-o", str(frames)]) == 0
    assert sorted(p.name for p in frames.iterdir()) == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    assert main(["render", str(cap), "--probe", "sky", "-o", str(tmp_path / "x.jpg")]) == 2


@pytest.mark.gl
def test_auto_method_is_packed_on_llvmpipe_and_compute_on_a_gpu(ctx):
    from types import SimpleNamespace

    from ffls.gpu.weighted_sum import default_method

    assert default_method(SimpleNamespace(info={"GL_RENDERER": "llvmpipe (LLVM 15.0.6, 256 bits)"})) == "packed"
    assert default_method(SimpleNamespace(info={"GL_RENDERER": "NVIDIA H100 80GB HBM3/PCIe/SSE2"})) == "compute"
    expected = "packed" if "llvmpipe" in ctx.info["GL_RENDERER"] else "compute"
    assert default_method(ctx) == expected


@pytest.mark.gl
@pytest.mark.parametrize("rank", [7, None])
def test_engine_stores_the_hdr_when_read(ctx, rng, rank):
    """A one-chunk packed pass 2 writes the display image alone; the HDR read afterwards is that of the
    last render, even after set_weights or a new weighting scheme (their buffers change later)."""
    from ffls.conventions import rotation_z
    from ffls.gpu.engine import Engine
    from ffls.lightmaps.lightmap import sky_sun_map
    from ffls.display.tonemap import to_uint8, tonemap

    n = 20
    basis = _lowrank_basis(rng)[:n]
    d = _directions(rng, n)
    eng = Engine(ctx, basis, d, rank=rank, method="packed")
    from ffls.relight.cpu import relight_reference

    def relit(w):
        return relight_reference(w, basis) if rank is None else eng.compressed.relight(w)

    try:
        assert eng.basis_info["n_arrays"] == 1 and eng.basis_info["method"] == "packed"
        w1, w2 = rng.random((n, 3)), rng.random((n, 3))
        eng.set_weights(w1)
        eng.render(exposure=0.5, tonemap="reinhard", hdr=False)
        disp1 = eng.read_display()
        eng.set_weights(w2)  # not rendered yet: the HDR is still w1's
        ref1 = relit(w1)
        h1 = eng.read_hdr().astype(np.float64)
        assert np.abs(h1 - ref1).max() <= TOL * np.abs(ref1).max()
        assert np.abs(disp1.astype(int) - to_uint8(tonemap(h1, 0.5, "reinhard"))).max() <= 1
        eng.render(exposure=0.5, tonemap="reinhard", hdr=False)
        ref2 = relit(w2)
        eng.render(exposure=-1.0, tonemap="aces", hdr=False)  # the display pass only, from the weights
        assert set(eng.timings) == {"tonemap"}
        assert np.abs(eng.read_display().astype(int) - to_uint8(tonemap(ref2, -1.0, "aces"))).max() <= 1
        assert np.abs(eng.read_hdr() - ref2).max() <= TOL * np.abs(ref2).max()
        eng.set_lightmap(sky_sun_map(16))
        eng.render()  # hdr=True: stored with the display image
        h3 = eng.read_hdr()
        eng.set_rotation(rotation_z(30.0))
        eng.render(exposure=1.0, hdr=False)
        eng.set_weighting("gaussian")  # releases pass 1's weights buffer, which the HDR is computed from
        h4 = eng.read_hdr()
        assert np.abs(h4 - h3).max() > 1e-3 * np.abs(h3).max()  # the rotated map's, not the previous one
        eng.set_rotation(rotation_z(30.0))
        eng.set_weighting("voronoi")
        eng.render(exposure=1.0)
        np.testing.assert_allclose(eng.read_hdr(), h4, rtol=1e-5, atol=1e-6 * np.abs(h4).max())
    finally:
        eng.release()
