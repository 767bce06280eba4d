"""``--weighting spline`` everywhere the other schemes are offered: relight (CPU), render (GPU and
``--cpu``, maps and ``--light``), composite, the viewer's quality panel; the one-line refusal of a
map the GPU's pass 1 cannot take; ``--quality auto`` considers it only when asked.

Tolerances, as the other schemes' tests: the CPU relight equals ``relight_reference`` of the exact
float64 weights (``integrate(..., 'spline')``) to 1e-4 of the image's maximum (float32 storage);
the GPU render equals the reference of ``integrate(..., texture=bake_weights(...))`` (the GPU's
weight-texture lookup) to 1e-4 of the maximum (float32 basis, float32 power and weights);
``render --light`` on the GPU equals ``--cpu`` to 1e-4 of the maximum.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest


def small_capture(tmp_path, n=20):
    from ffls.synth.scene import write_synthetic_capture

    folder = tmp_path / "cap"
    write_synthetic_capture(folder, n_lights=n, resolution=24, seed=5, progress=False)
    return folder


def capture_and_basis(folder):
    from ffls.relight.basis import accepted_basis
    from viewer.app import open_capture

    capture, lights = open_capture(folder)
    basis, d = accepted_basis(capture, lights)
    return capture, basis, d


def _big_map(path, height=512):
    """A 2H x H lat-long EXR with a sun (H = 512: 524 288 texels, over llvmpipe's buffer for spline)."""
    from ffls.lightmaps.lightmap import sky_sun_map
    from ffls.io.images import write_exr

    write_exr(path, sky_sun_map(height).data)
    return path


def test_spline_is_offered_by_every_command_and_the_panel():
    import argparse

    from ffls.commands import composite, relight, render
    from ffls.commands.common import WEIGHTINGS
    from ffls.relight.quality import Quality
    from ffls.weights.weighting import EXTRA_SCHEMES, SCHEMES
    from viewer import command as view
    from viewer.state import QUALITY_KNOBS

    assert "spline" in SCHEMES and "spline" in WEIGHTINGS and "spline" not in EXTRA_SCHEMES
    knob = {k.key: k for k in QUALITY_KNOBS}["weighting"]
    assert "spline" in knob.choices and knob.default == "voronoi"
    assert Quality(weighting="spline").weighting == "spline"
    for mod in (relight, render, view, composite):  # the shared flag: parsed, default voronoi
        p = argparse.ArgumentParser()
        mod.add_arguments(p)
        assert "{voronoi,antialiased,barycentric,gaussian,spline,kriging}" in p.format_help(), mod.__name__
        assert p.get_default("weighting") == "voronoi", mod.__name__


def test_quality_auto_considers_spline_only_when_asked():
    from ffls.relight.auto import AUTO_WEIGHTINGS, candidate_qualities
    from ffls.relight.quality import Quality

    assert "spline" not in AUTO_WEIGHTINGS and "barycentric" in AUTO_WEIGHTINGS
    assert "spline" not in {q.weighting for q in candidate_qualities(40)}
    asked = {q.weighting for q in candidate_qualities(40, Quality(weighting="spline"))}
    assert asked == set(AUTO_WEIGHTINGS) | {"spline"}


def test_cli_relight_spline_matches_the_numpy_reference(tmp_path, capsys):
    from ffls.cli import main
    from ffls.conventions import rotation_z
    from ffls.io.images import read_image
    from ffls.lightmaps.lightmap import lightmap_from_spec
    from ffls.relight.cpu import relight_reference
    from ffls.weights.weighting import integrate

    folder = small_capture(tmp_path)
    capture, basis, d = capture_and_basis(folder)
    out = tmp_path / "r.exr"
    assert main(["relight", str(folder), "--probe", "sky", "--rotate-z", "30", "--weighting", "spline",
                 "-o", str(out)]) == 0
    assert "spline weighting" in capsys.readouterr().out
    w = integrate(lightmap_from_spec("sky"), d, rotation_z(30), capture.hemisphere, "spline")
    ref = relight_reference(w.weights, basis)
    got = read_image(out).pixels
    np.testing.assert_allclose(got, ref, atol=1e-4 * np.abs(ref).max())
    bary = tmp_path / "b.exr"  # the scheme did change the result
    assert main(["relight", str(folder), "--probe", "sky", "--rotate-z", "30", "--weighting", "barycentric",
                 "-o", str(bary)]) == 0
    assert np.abs(read_image(bary).pixels - got).max() > 1e-3 * np.abs(ref).max()


@pytest.mark.gl
def test_cli_render_spline_on_the_gpu_matches_the_reference(ctx, tmp_path, capsys):
    from ffls.cli import main
    from ffls.conventions import rotation_z
    from ffls.io.images import read_image
    from ffls.lightmaps.lightmap import lightmap_from_spec
    from ffls.relight.cpu import relight_reference
    from ffls.weights.weighting import DEFAULT_TEXTURE_RES, bake_weights, integrate

    folder = small_capture(tmp_path)
    capture, basis, d = capture_and_basis(folder)
    gpu, cpu = tmp_path / "g.exr", tmp_path / "c.exr"
    assert main(["render", str(folder), "--probe", "sky", "--rotate-z", "30", "--weighting", "spline",
                 "--dtype", "f32", "-o", str(gpu)]) == 0
    tex = bake_weights(d, "spline", capture.hemisphere, DEFAULT_TEXTURE_RES)
    w = integrate(lightmap_from_spec("sky"), d, rotation_z(30), capture.hemisphere, "spline", texture=tex)
    ref = relight_reference(w.weights, basis)
    np.testing.assert_allclose(read_image(gpu).pixels, ref, atol=1e-4 * np.abs(ref).max())
    # --light: one directional light, GPU against the CPU path
    assert main(["render", str(folder), "--light", "40,35", "--weighting", "spline", "--dtype", "f32",
                 "-o", str(gpu)]) == 0
    assert main(["render", str(folder), "--light", "40,35", "--weighting", "spline", "--cpu", "-o", str(cpu)]) == 0
    a, b = read_image(gpu).pixels, read_image(cpu).pixels
    np.testing.assert_allclose(a, b, atol=1e-4 * np.abs(b).max())
    assert "spline weighting" in capsys.readouterr().out


def test_gpu_pass1_check_names_the_flag_and_the_map_height_that_fits():
    from ffls.commands.common import check_gpu_pass1
    from ffls.errors import InputError
    from ffls.lightmaps.lightmap import sky_sun_map
    from ffls.relight.quality import Quality, pass1_buffer_bytes, pass1_fit_height

    llvmpipe = SimpleNamespace(info={"GL_MAX_SHADER_STORAGE_BLOCK_SIZE": 2 ** 27})
    assert pass1_buffer_bytes(524288, "spline") == 524288 * 16 * 24
    assert pass1_fit_height(2 ** 27, "spline") == 256  # 2 x 256^2 x 24 x 16 B = 48 MiB; 512: 192 MiB
    assert pass1_fit_height(2 ** 27, "voronoi") == 1024
    big = sky_sun_map(512)
    with pytest.raises(InputError) as e:
        check_gpu_pass1(llvmpipe, big, Quality(weighting="spline"))
    msg = str(e.value)
    assert "\n" not in msg and "--weighting spline" in msg and "--map-res 256" in msg and "192 MiB" in msg
    check_gpu_pass1(llvmpipe, big, Quality(weighting="spline", map_res=256))
    check_gpu_pass1(llvmpipe, big, Quality(weighting="barycentric"))
    check_gpu_pass1(llvmpipe, None, Quality(weighting="spline"))  # --light: no map


@pytest.mark.gl
def test_cli_render_refuses_a_map_too_large_for_spline_in_one_line(ctx, tmp_path, capsys):
    from ffls.cli import main
    from ffls.relight.quality import pass1_buffer_bytes

    if pass1_buffer_bytes(2 * 512 * 512, "spline") <= int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 0):
        pytest.skip("this GPU's storage buffers take a 1024 x 512 map under spline")
    folder = small_capture(tmp_path, n=12)
    probe = _big_map(tmp_path / "big.exr")
    out = tmp_path / "x.exr"
    capsys.readouterr()
    assert main(["render", str(folder), "--probe", str(probe), "--weighting", "spline", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--weighting spline" in err[0] and "--map-res 256" in err[0], err
    assert not out.exists()
    assert main(["render", str(folder), "--probe", str(probe), "--weighting", "spline", "--map-res", "256",
                 "-o", str(out)]) == 0
    assert out.exists()


@pytest.mark.gl
def test_viewer_spline_knob_and_its_refusal(ctx, tmp_path):
    pytest.importorskip("imgui_bundle", reason="imgui-bundle is not installed")
    from ffls.conventions import rotation_ypr
    from ffls.lightmaps.lightmap import lightmap_from_spec
    from ffls.relight.cpu import relight_reference
    from ffls.relight.quality import pass1_buffer_bytes
    from ffls.weights.weighting import DEFAULT_TEXTURE_RES, bake_weights, integrate, light_weights
    from viewer.app import open_capture
    from viewer.renderer import Renderer, pass1_lightmap
    from viewer.state import ViewerState

    folder = small_capture(tmp_path, n=16)
    capture, lights = open_capture(folder)
    _, basis, d = capture_and_basis(folder)
    st = ViewerState(lightmap="sky", tonemap="srgb", yaw=25.0)
    st.quality["method"] = "full f32"
    st.quality["weighting"] = "spline"
    r = Renderer(ctx, capture, lights)
    try:
        r.update(st)  # under the map, pass 1 from spline's weight texture
        tex = bake_weights(d, "spline", capture.hemisphere, DEFAULT_TEXTURE_RES)
        lm = pass1_lightmap(lightmap_from_spec("sky"), st.quality["map_res"])
        w = integrate(lm, d, rotation_ypr(st.yaw, st.pitch, st.roll), capture.hemisphere, "spline", texture=tex)
        np.testing.assert_allclose(r.engine.read_weights(), w.weights, atol=1e-5 * w.total_power.max())
        ref = relight_reference(w.weights, basis)
        np.testing.assert_allclose(r.read_hdr(), ref, atol=1e-4 * np.abs(ref).max())
        st.light_mode = True  # RTI style
        st.light_az, st.light_el = 60.0, 40.0
        r.update(st)
        lw = light_weights(d, st.light_vector(), "spline", capture.hemisphere)
        np.testing.assert_allclose(r.engine.read_weights(), np.repeat(lw[:, None], 3, 1), atol=1e-12)
        st.light_mode = False
        limit = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 0)
        if pass1_buffer_bytes(2 * 512 * 512, "spline") > limit:
            # a full-size 1024 x 512 map under spline: the pass-1 map height is set to one that fits
            st.lightmap = str(_big_map(tmp_path / "big.exr"))
            st.quality["map_res"] = "full"
            info = r.update(st)
            assert st.quality["map_res"] == "256" and st.quality["weighting"] == "spline"
            assert "weighting spline" in info.message and "pass-1 map set to 256" in info.message
            # choosing spline over a full map with another scheme in use: the knob goes back
            st.quality["weighting"] = "barycentric"
            r.update(st)
            st.quality["map_res"] = "full"
            r.update(st)
            st.quality["weighting"] = "spline"
            info = r.update(st)
            assert st.quality["weighting"] == "barycentric" and st.quality["map_res"] == "full"
            assert "choose pass-1 map 256 or lower" in info.message
    finally:
        r.release()
