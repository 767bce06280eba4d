"""CPU relighting (ffls.relight.cpu), the ``ffls relight`` command and convergence to the oracle."""
from __future__ import annotations

import numpy as np
import pytest

from ffls import conventions as cv
from ffls.weights import voronoi as vo
from ffls.relight.cpu import relight_capture, relight_fast, relight_reference
from ffls.radiance.photos import load_photos


def _basis(rng, n, h=24, w=40, dtype=np.float32):
    return rng.exponential(1.0, size=(n, h, w, 3)).astype(dtype)


# ----------------------------------------------------------------------------- weighted sum
def test_reference_is_the_float64_weighted_sum(rng):
    B = _basis(rng, 7)
    w = rng.uniform(-0.5, 2, size=(7, 3))
    out = relight_reference(w, B)
    assert out.dtype == np.float64 and out.shape == (24, 40, 3)
    np.testing.assert_allclose(out, np.einsum("nc,nhwc->hwc", w, B.astype(np.float64)), rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("n", [1, 3, 64, 400])
@pytest.mark.parametrize("dtype", [np.float32, np.float16, np.float64])
def test_fast_matches_reference_in_float32_tolerance(rng, n, dtype):
    B = _basis(rng, n, dtype=dtype)
    w = rng.exponential(0.05, size=(n, 3)) * np.array([1.0, 10.0, 0.1])
    ref = relight_reference(w, B)
    fast = relight_fast(w, B, block_pixels=317)  # odd block size: exercises the last partial block
    assert fast.dtype == np.float32 and fast.shape == ref.shape
    # float32 accumulation: |error| <= n * 2^-24 * sum_i |w_i B_i| (worst case), plus the
    # rounding of the weights to float32; measured errors are ~100x below this bound
    scale = np.einsum("nc,nhwc->hwc", np.abs(w), np.abs(B.astype(np.float64)))
    assert np.all(np.abs(fast - ref) <= (n + 2) * 2.0 ** -24 * scale)


def test_fast_does_not_copy_float32_basis(rng):
    B = _basis(rng, 50, 64, 64)
    w = rng.uniform(size=(50, 3))
    import tracemalloc

    tracemalloc.start()
    relight_fast(w, B)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 0.25 * B.nbytes  # the basis (2.4 MB) is read in place


def test_shape_errors(rng):
    with pytest.raises(ValueError):
        relight_fast(np.ones((3, 3)), np.ones((4, 2, 2, 3), np.float32))
    with pytest.raises(ValueError):
        relight_reference(np.ones((3, 3)), np.ones((3, 2, 2)))


def test_single_bright_texel_picks_the_nearest_basis_image(rng):
    from ffls.lightmaps.sphere_maps import get_map

    m = get_map("latlong")
    d = m.directions(128).reshape(-1, 3)
    sa = m.solid_angles(128).ravel()
    dirs = cv.normalize(rng.normal(size=(40, 3)))
    dirs[:, 2] = np.abs(dirs[:, 2])
    k = int(np.argmax(d @ cv.normalize(np.array([0.2, -0.4, 0.7]))))
    L = np.zeros_like(d)
    L[k] = [5.0, 3.0, 1.0]
    B = _basis(rng, 40)
    nearest = int(np.argmax(dirs @ d[k]))
    for cells in (None, vo.bake_cells(dirs, "upper", res=128)):
        w = vo.integrate_weights((d, L, sa), dirs, cells=cells).weights
        assert np.count_nonzero(np.any(w != 0, axis=1)) == 1 and np.any(w[nearest] != 0)
        np.testing.assert_array_equal(w[nearest], L[k] * sa[k])
        np.testing.assert_array_equal(relight_reference(w, B), w[nearest] * B[nearest].astype(np.float64))
        np.testing.assert_allclose(relight_fast(w, B), (w[nearest] * B[nearest]).astype(np.float32), rtol=2e-7)


# ----------------------------------------------------------------------------- capture
@pytest.fixture(scope="module")
def small_capture(tmp_path_factory):
    from ffls.synth.scene import write_synthetic_capture

    folder = tmp_path_factory.mktemp("cap")
    write_synthetic_capture(folder, n_lights=16, resolution=32, progress=False, seed=3)
    return folder


def test_relight_capture_uses_only_ok_lights(small_capture):
    from ffls.io.capture import load_capture, load_lights
    from ffls.lightmaps.lightmap import paper_map

    cap = load_capture(small_capture)
    lights = load_lights(small_capture / "lights.json", cap)
    lights.status[2] = "rejected"
    lights.status[9] = "rejected"
    lm = paper_map(64)
    img, w = relight_capture(cap, lights, lm, rotation=cv.rotation_z(40.0))
    ok = lights.ok_mask
    assert w.weights.shape == (14, 3)
    basis = load_photos(cap, np.flatnonzero(ok))
    w_exact = vo.integrate_weights(lm, lights.directions[ok], cv.rotation_z(40.0), cap.hemisphere)
    np.testing.assert_array_equal(w.weights, w_exact.weights)  # the candidate texture is exact
    ref = relight_reference(w_exact.weights, basis)
    assert img.dtype == np.float32
    np.testing.assert_allclose(img, ref, rtol=1e-5, atol=1e-6 * ref.max())
    img64, _ = relight_capture(cap, lights, lm, rotation=cv.rotation_z(40.0), cells_res=None, fast=False)
    np.testing.assert_array_equal(img64, ref)


def test_relight_command_writes_exr_and_png(small_capture, tmp_path, capsys):
    from ffls.cli import main
    from ffls.io.images import read_image
    from ffls.lightmaps.lightmap import save_lightmap, sky_sun_map

    probe = tmp_path / "sky.exr"
    save_lightmap(sky_sun_map(32), probe)
    exr = tmp_path / "out.exr"
    rc = main(["relight", str(small_capture), "--probe", str(probe), "--rotate-z", "30", "-o", str(exr)])
    assert rc == 0
    line = capsys.readouterr().out.strip()
    assert "\n" not in line and "texels dropped (outside the capture's hemisphere, upper)" in line
    img = read_image(exr).pixels
    assert img.shape == (32, 32, 3) and np.all(np.isfinite(img)) and img.max() > 0
    png = tmp_path / "out.png"
    assert main(["relight", str(small_capture), "--probe", str(probe), "--exposure", "1", "-o", str(png)]) == 0
    assert read_image(png).pixels.shape == (32, 32, 3)


def test_relight_command_rejects_extension_before_work(tmp_path, capsys):
    from ffls.cli import main

    rc = main(["relight", str(tmp_path / "missing-capture"), "--probe", str(tmp_path / "missing.exr"),
               "-o", str(tmp_path / "out.jpg")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "out.jpg" in err and "missing" not in err.replace("out.jpg", "") and not (tmp_path / "out.jpg").exists()


# ----------------------------------------------------------------------------- convergence
def test_relit_capture_converges_to_the_oracle():
    # Distant-light basis images of the synthetic scene (48x48) relit under the procedural sky
    # without its sun, against the direct render (oracle, 1024 distant lights). Measured
    # (benchmarks/convergence.py, 64x64, 2048 oracle lights): rel. RMS 0.0245 (N=50),
    # 0.0088 (N=200). Stated: < 0.04 at N = 50, < 0.015 at N = 200, and at least 1.8x lower.
    from ffls.synth import scene as synth
    from ffls.lightmaps.lightmap import sky_sun_map

    scene = synth.SynthScene()
    lm = sky_sun_map(128, sun_irradiance=0.0)
    oracle = synth.render_lightmap(scene, lm, 48, n_dirs=1024).astype(np.float64)
    err = {}
    for n in (50, 200):
        dirs = synth.stratified_directions(n, "upper", seed=0)
        basis = synth.render_lights(scene, 48, dirs)
        w = vo.integrate_weights(lm, dirs, hemisphere="upper", cells=vo.bake_cells(dirs, "upper"))
        relit = relight_fast(w.weights, basis).astype(np.float64)
        err[n] = np.linalg.norm(relit - oracle) / np.linalg.norm(oracle)
    assert err[50] < 0.04 and err[200] < 0.015
    assert err[200] * 1.8 < err[50]


def test_cpu_relighter_has_the_engine_interface_and_the_reference_numbers(small_capture):
    """CpuRelighter: the Engine's methods; f64 = relight_reference, f32 = relight_fast; display = tonemap."""
    from ffls.display.tonemap import to_uint8, tonemap
    from ffls.gpu.engine import Engine
    from ffls.io.capture import load_capture, load_lights
    from ffls.lightmaps.lightmap import paper_map
    from ffls.relight.basis import accepted_basis
    from ffls.relight.cpu import CpuRelighter

    for name in ("set_lightmap", "set_rotation", "set_weights", "render", "read_hdr", "read_display",
                 "read_weights", "release", "size", "n_lights"):
        assert hasattr(Engine, name) and hasattr(CpuRelighter, name), name
    cap = load_capture(small_capture)
    lights = load_lights(small_capture / "lights.json", cap)
    lights.status[5] = "rejected"
    basis, dirs = accepted_basis(cap, lights)
    assert basis.shape[0] == dirs.shape[0] == 15
    lm, R = paper_map(64), cv.rotation_z(75.0)
    w = vo.integrate_weights(lm, dirs, R, cap.hemisphere, cells=vo.bake_cells(dirs, cap.hemisphere))
    for precision, ref in (("f64", relight_reference(w.weights, basis)), ("f32", relight_fast(w.weights, basis))):
        r = CpuRelighter.from_capture(cap, lights, precision=precision)
        assert r.size == (32, 32) and r.n_lights == 15
        with pytest.raises(RuntimeError):
            r.render()
        r.set_lightmap(lm)
        r.set_rotation(R)
        r.render(exposure=1.0, tonemap="aces")
        assert r.hdr.dtype == ref.dtype
        np.testing.assert_array_equal(r.hdr, ref)
        np.testing.assert_array_equal(r.read_hdr(), ref.astype(np.float32))
        np.testing.assert_array_equal(r.read_weights(), w.weights)
        np.testing.assert_array_equal(r.read_display(), to_uint8(tonemap(ref, 1.0, "aces")))
        hdr = r.hdr
        r.render(exposure=-2.0, tonemap="srgb")  # a new exposure re-tone-maps, never relights
        assert r.hdr is hdr
        np.testing.assert_array_equal(r.read_display(), to_uint8(tonemap(ref, -2.0, "srgb")))
        r.set_weights(2 * w.weights)
        r.render()
        np.testing.assert_allclose(r.read_hdr(), 2 * ref, rtol=1e-6)
        r.release()
