"""``--weighting kriging`` in the commands: the relighters learn its kernel from their own basis.

Tolerances as ``tests/test_weighting_spline_cli.py``: the CPU relight equals
``relight_reference`` of the exact float64 weights of the kernel that
:func:`ffls.weights.kriging.fit_kernel` learns from the same photos, to 1e-4 of the image's
maximum (float32 storage); the GPU render equals the reference of the weight-texture lookup
(``integrate(..., texture=bake_weights(...))``) with that kernel, to 1e-4 of the maximum.
"""
from __future__ import annotations

import numpy as np
import pytest

from test_weighting_spline_cli import capture_and_basis, small_capture


def _reference(folder, texture: bool):
    """(capture, basis, d, learnt options, reference image) of the sky map turned 30 degrees:
    the exact kriging weights, or (``texture``) the GPU's weight-texture lookup."""
    from ffls.conventions import rotation_z
    from ffls.lightmaps.lightmap import lightmap_from_spec
    from ffls.relight.cpu import relight_reference
    from ffls.weights.kriging import fit_kernel
    from ffls.weights.weighting import DEFAULT_TEXTURE_RES, bake_weights, integrate

    capture, basis, d = capture_and_basis(folder)
    opts = fit_kernel(d, basis).options
    tex = bake_weights(d, "kriging", capture.hemisphere, DEFAULT_TEXTURE_RES, **opts) if texture else None
    w = integrate(lightmap_from_spec("sky"), d, rotation_z(30), capture.hemisphere, "kriging", texture=tex, **opts)
    return capture, basis, d, opts, relight_reference(w.weights, basis)


def test_cli_relight_kriging_uses_the_kernel_learnt_from_the_photos(tmp_path, capsys):
    from ffls.cli import main
    from ffls.conventions import rotation_z
    from ffls.io.images import read_image
    from ffls.lightmaps.lightmap import lightmap_from_spec
    from ffls.relight.cpu import relight_reference
    from ffls.weights.weighting import integrate

    folder = small_capture(tmp_path)
    capture, basis, d, opts, ref = _reference(folder, texture=False)
    out = tmp_path / "r.exr"
    assert main(["relight", str(folder), "--probe", "sky", "--rotate-z", "30", "--weighting", "kriging",
                 "-o", str(out)]) == 0
    assert "kriging kernel learnt from the photos by leave-one-out: Matern nu" in capsys.readouterr().out
    got = read_image(out).pixels
    np.testing.assert_allclose(got, ref, atol=1e-4 * np.abs(ref).max())
    # a kernel other than the learnt one gives another image: the learning is what was used
    other = {**opts, "length": 2.0 * opts["length"]}
    w2 = integrate(lightmap_from_spec("sky"), d, rotation_z(30), capture.hemisphere, "kriging", **other)
    assert np.abs(relight_reference(w2.weights, basis) - got).max() > 1e-3 * np.abs(ref).max()


def test_relighter_learns_once_and_explicit_options_win():
    from ffls.relight.cpu import CpuRelighter

    rng = np.random.default_rng(0)
    d = rng.normal(size=(12, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.2
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    basis = rng.random((12, 6, 5, 3)).astype(np.float32)
    CpuRelighter(basis, d, weighting="kriging")  # learns at construction, without error
    from ffls.weights.kriging import KernelLearner

    k = KernelLearner(d, basis)
    assert k.fit is None
    a = k.options_for("kriging", {})
    assert k.fit is not None and k.options_for("kriging", {}) == a  # learnt once
    assert k.options_for("kriging", {"nu": 0.5}) == {"nu": 0.5}  # explicit options win
    assert k.options_for("spline", {}) == {}


def test_kriging_needs_five_lights_in_one_line(tmp_path, capsys):
    from ffls.cli import main

    folder = small_capture(tmp_path, n=4)
    assert main(["relight", str(folder), "--probe", "sky", "--weighting", "kriging", "-o", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--weighting kriging" in err[0] and "at least 5 lights" in err[0], err
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.gl
def test_cli_render_kriging_on_the_gpu_matches_the_reference(ctx, tmp_path):
    from ffls.cli import main
    from ffls.io.images import read_image

    folder = small_capture(tmp_path)
    ref = _reference(folder, texture=True)[-1]
    gpu = tmp_path / "g.exr"
    assert main(["render", str(folder), "--probe", "sky", "--rotate-z", "30", "--weighting", "kriging",
                 "--dtype", "f32", "-o", str(gpu)]) == 0
    np.testing.assert_allclose(read_image(gpu).pixels, ref, atol=1e-4 * np.abs(ref).max())


@pytest.mark.gl
def test_viewer_kriging_knob_learns_and_its_refusal_keeps_the_scheme(ctx, tmp_path):
    """The knob relights with the learnt kernel (light mode too); with 4 lights the knob goes back,
    and the status line says why."""
    pytest.importorskip("imgui_bundle", reason="imgui-bundle is not installed")
    from ffls.weights.weighting import light_weights
    from viewer.app import open_capture
    from viewer.renderer import Renderer
    from viewer.state import ViewerState

    folder = small_capture(tmp_path / "a", n=16)
    capture, lights = open_capture(folder)
    _, basis, d = capture_and_basis(folder)
    st = ViewerState(lightmap="sky", tonemap="srgb", light_mode=True, light_az=60.0, light_el=40.0)
    st.quality["method"] = "full f32"
    st.quality["weighting"] = "kriging"
    r = Renderer(ctx, capture, lights)
    try:
        r.update(st)
        opts = r.engine.kernel.fit.options
        lw = light_weights(d, st.light_vector(), "kriging", capture.hemisphere, **opts)
        np.testing.assert_allclose(r.engine.read_weights(), np.repeat(lw[:, None], 3, 1), atol=1e-12)
    finally:
        r.release()
    few = small_capture(tmp_path / "b", n=4)
    capture, lights = open_capture(few)
    st = ViewerState(lightmap="sky", tonemap="srgb")
    r = Renderer(ctx, capture, lights)
    try:
        r.update(st)
        st.quality["weighting"] = "kriging"
        info = r.update(st)
        assert st.quality["weighting"] == "voronoi" and "at least 5 lights" in info.message
    finally:
        r.release()


def test_cli_render_light_kriging_uses_the_learnt_kernel(tmp_path):
    """``render --light AZ,EL --weighting kriging --cpu``: the single light's weights come from the
    learnt kernel, so the image is the photos weighted by ``light_weights`` with it."""
    from ffls.cli import main
    from ffls.commands.common import light_vector
    from ffls.io.images import read_image
    from ffls.relight.cpu import relight_reference
    from ffls.weights.kriging import fit_kernel
    from ffls.weights.weighting import light_weights

    folder = small_capture(tmp_path)
    capture, basis, d = capture_and_basis(folder)
    out = tmp_path / "l.exr"
    assert main(["render", str(folder), "--light", "40,35", "--weighting", "kriging", "--cpu", "-o", str(out)]) == 0
    w = light_weights(d, light_vector((40.0, 35.0)), "kriging", capture.hemisphere, **fit_kernel(d, basis).options)
    ref = relight_reference(np.repeat(w[:, None], 3, 1), basis)
    np.testing.assert_allclose(read_image(out).pixels, ref, atol=1e-4 * np.abs(ref).max())


def test_kriging_with_few_distinct_directions_is_one_line(tmp_path, capsys):
    """20 photos lit from 3 directions (repeated): no kernel can be learnt; one line naming --weighting."""
    import json

    from ffls.cli import main

    folder = small_capture(tmp_path)
    doc = json.loads((folder / "lights.json").read_text())
    dirs = [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.6, 0.8]]
    for i, item in enumerate(doc["lights"]):
        item["direction"] = dirs[i % 3]
        item.pop("position", None)
    (tmp_path / "grp3.json").write_text(json.dumps(doc))
    rc = main(["relight", str(folder), "--lights", str(tmp_path / "grp3.json"), "--probe", "sky",
               "--weighting", "kriging", "-o", str(tmp_path / "x.exr")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--weighting kriging" in err[0] and "5 distinct" in err[0], err
    assert not (tmp_path / "x.exr").exists()
