"""The viewer's light mode (RTI style) and weighting knob: state (no GL), GUI drag (no GL) and the
renderer on the headless context (no window).

Tolerance of the renderer test: the engine's weights equal ``ffls.weights.weighting.light_weights``
to 1e-12 (they are uploaded, not integrated), and the relit HDR equals ``relight_reference`` of those
weights over the float16 basis to 2e-3 of its maximum (float16 rounding: 2^-11 relative).
"""
from __future__ import annotations

import numpy as np
import pytest

from viewer.state import QUALITY_KNOBS, ViewerState, ViewInfo

imgui_bundle = pytest.importorskip("imgui_bundle", reason="imgui-bundle is not installed")


def test_light_state_moves_and_wraps():
    st = ViewerState()
    assert "weighting" in {k.key for k in QUALITY_KNOBS} and st.quality["weighting"] == "voronoi"
    key = st.quality_key()
    st.quality["weighting"] = "gaussian"  # a pass-1 change: no engine rebuild
    assert st.quality_key() == key
    st.light_az, st.light_el = 170.0, 80.0
    st.move_light(daz=20.0, delev=30.0)
    assert st.light_az == pytest.approx(-170.0) and st.light_el == 90.0
    st.set_light_disc(0.0, 0.5)  # toward +Y, half-way to the rim of the disc (orthographic view from above)
    assert st.light_az == pytest.approx(90.0) and st.light_el == pytest.approx(60.0)
    np.testing.assert_allclose(st.light_vector(), [0.0, 0.5, np.sin(np.radians(60))], atol=1e-12)
    st.set_light_disc(3.0, 0.0)  # outside: on the rim
    assert st.light_az == 0.0 and st.light_el == pytest.approx(0.0, abs=1e-9)


def test_gui_drag_moves_the_light_in_light_mode():
    from imgui_bundle import imgui, implot

    from viewer.gui import draw_gui

    c = imgui.create_context()
    imgui.set_current_context(c)
    p = implot.create_context()
    implot.set_current_context(p)
    try:
        io = imgui.get_io()
        io.set_ini_filename(None)
        io.display_size = imgui.ImVec2(900, 600)
        io.delta_time = 1 / 60
        io.backend_flags |= imgui.BackendFlags_.renderer_has_textures
        st = ViewerState(window_size=(900, 600), drag_deg_per_px=0.4, light_mode=True, light_az=0.0, light_el=45.0)
        info = ViewInfo(image_tex=7, image_size=(64, 64), n_lights=0, renderer="none")
        events = [lambda io: io.add_mouse_pos_event(600, 300), lambda io: io.add_mouse_button_event(0, True),
                  lambda io: io.add_mouse_pos_event(650, 280), lambda io: io.add_mouse_button_event(0, False), None]
        for ev in events:
            if ev is not None:
                ev(io)
            imgui.new_frame()
            draw_gui(st, info)
            imgui.render()
        # 50 px right, 20 px up at 0.4 deg/px: azimuth -20, elevation +8; the map did not turn
        assert st.light_az == pytest.approx(-20.0) and st.light_el == pytest.approx(53.0)
        assert st.yaw == 0.0 and st.pitch == 0.0
    finally:
        implot.destroy_context(p)
        imgui.destroy_context(c)


@pytest.mark.gl
def test_renderer_light_mode_and_weighting(ctx, tmp_path):
    from ffls.relight.basis import accepted_basis
    from ffls.relight.cpu import relight_reference
    from ffls.synth.scene import write_synthetic_capture
    from ffls.weights.weighting import light_weights
    from viewer.app import open_capture
    from viewer.renderer import Renderer

    folder = tmp_path / "cap"
    write_synthetic_capture(folder, n_lights=16, resolution=24, seed=3, progress=False)
    capture, lights = open_capture(folder)
    basis, d = accepted_basis(capture, lights)
    st = ViewerState(lightmap="sky", tonemap="srgb")
    st.quality["method"] = "full f16"
    r = Renderer(ctx, capture, lights)
    try:
        r.update(st)
        map_hdr = r.read_hdr()
        st.light_mode = True
        for scheme, (az, el) in (("voronoi", (30.0, 50.0)), ("barycentric", (30.0, 50.0)), ("gaussian", (-100.0, 20.0))):
            st.quality["weighting"] = scheme
            st.light_az, st.light_el = az, el
            info = r.update(st)
            w = light_weights(d, st.light_vector(), scheme, capture.hemisphere)
            np.testing.assert_allclose(r.engine.read_weights(), np.repeat(w[:, None], 3, 1), atol=1e-12)
            ref = relight_reference(np.repeat(w[:, None], 3, 1), basis)
            np.testing.assert_allclose(r.read_hdr(), ref, atol=2e-3 * np.abs(ref).max())
            assert info.single_light_uv is not None
        st.light_el = -30.0  # below the horizon: no light
        r.update(st)
        assert np.abs(r.read_hdr()).max() == 0.0
        st.light_mode = False  # the map comes back
        st.quality["weighting"] = "voronoi"
        info = r.update(st)
        assert info.single_light_uv is None
        np.testing.assert_allclose(r.read_hdr(), map_hdr, rtol=0, atol=1e-6 * np.abs(map_hdr).max())
        st.quality["weighting"] = "barycentric"  # live switch under the map
        r.update(st)
        assert np.abs(r.read_hdr() - map_hdr).max() > 1e-4 * np.abs(map_hdr).max()
    finally:
        r.release()
