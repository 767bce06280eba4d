"""The viewer's imgui function: :func:`draw_gui` changes only a :class:`viewer.state.ViewerState`.

No GL calls here and no GL module imported (``tests/test_viewer.py`` checks): the GUI reads
texture names from the :class:`viewer.state.ViewInfo` the renderer hands it and records draw
commands; the window loop (:mod:`viewer.app`) turns pending actions of the state (screenshot,
turntable, open dialog, quit, fullscreen) into effects.

Keyboard shortcuts (also listed in the help panel and docs/viewer.md) are in :data:`SHORTCUTS`.
"""
from __future__ import annotations

import time

import numpy as np
from imgui_bundle import imgui, implot

from viewer.state import BUILTIN_MAPS, QUALITY_KNOBS, TONEMAPS, TurntableJob, ViewerState, ViewInfo

__all__ = ["draw_gui", "handle_shortcuts", "SHORTCUTS", "PANEL_WIDTH", "PANEL_WINDOW"]

#: Width of the control panel in unscaled pixels.
PANEL_WIDTH = 360
#: imgui name of the control panel's window (viewer.gui_cache draws its draw list from a texture).
PANEL_WINDOW = "ffls view"
#: (keys, action) pairs shown in the help panel.
SHORTCUTS = (
    ("drag image / preview", "rotate the light map (horizontal: yaw, vertical: pitch)"),
    ("click a light (preview)", "show its basis photo"),
    ("light mode: drag image / disc", "move the single light (RTI style)"),
    ("Left / Right", "yaw -/+ 5 deg (Shift: 1 deg)"),
    ("Up / Down", "pitch +/- 5 deg (Shift: 1 deg)"),
    (", / .", "roll -/+ 5 deg"),
    ("+ / -", "exposure +/- 0.5 EV"),
    ("Space", "auto-rotate on/off"),
    ("R", "reset rotation"),
    ("S", "screenshot (window PNG + relit EXR)"),
    ("F", "fullscreen on/off"),
    ("Tab", "hide/show the controls"),
    ("H / F1", "help"),
    ("Esc", "quit"),
)


def _tex(glo: int):
    return imgui.ImTextureRef(int(glo))


def _u32(r, g, b, a=1.0):
    return imgui.color_convert_float4_to_u32(imgui.ImVec4(r, g, b, a))


def draw_gui(state: ViewerState, view: ViewInfo) -> None:
    """Draw the viewer's windows for one imgui frame and apply the user's input to ``state``.

    Parameters
    ----------
    state : ViewerState
        Changed in place (and only it).
    view : ViewInfo
        Read only: textures and facts from the renderer.

    Notes
    -----
    Call between ``imgui.new_frame()`` and ``imgui.render()``. Draws the relit image filling the
    window right of the control panel and the control panel (light map, rotation, image,
    quality, speed, output, window, help).
    """
    handle_shortcuts(state)
    vp = imgui.get_main_viewport()
    scale = max(1.0, float(view.content_scale))
    panel_w = PANEL_WIDTH * scale if state.show_gui else 0.0
    _image_window(state, view, vp.work_pos.x + panel_w, vp.work_pos.y, vp.work_size.x - panel_w, vp.work_size.y)
    if state.show_gui:
        imgui.set_next_window_pos(imgui.ImVec2(vp.work_pos.x, vp.work_pos.y))
        imgui.set_next_window_size(imgui.ImVec2(panel_w, vp.work_size.y))
        flags = imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse
        imgui.begin(PANEL_WINDOW, None, flags)
        _lightmap_panel(state, view)
        _light_panel(state)
        _rotation_panel(state)
        _image_panel(state, view)
        _quality_panel(state, view)
        _speed_panel(state, view)
        _output_panel(state, view)
        _window_panel(state, view)
        if view.message:
            imgui.separator()
            imgui.text_wrapped(view.message)
        imgui.end()
    if state.show_help:
        _help_window(state)


# ----------------------------------------------------------------------------- input
def handle_shortcuts(state: ViewerState) -> None:
    """Apply the keyboard shortcuts of :data:`SHORTCUTS` to ``state`` (not while typing text)."""
    io = imgui.get_io()
    if io.want_text_input:
        return
    K = imgui.Key
    step = 1.0 if io.key_shift else 5.0
    pressed = imgui.is_key_pressed
    if pressed(K.left_arrow):
        state.rotate_by(dyaw=-step)
    if pressed(K.right_arrow):
        state.rotate_by(dyaw=step)
    if pressed(K.up_arrow):
        state.rotate_by(dpitch=step)
    if pressed(K.down_arrow):
        state.rotate_by(dpitch=-step)
    if pressed(K.comma):
        state.rotate_by(droll=-5.0)
    if pressed(K.period):
        state.rotate_by(droll=5.0)
    if pressed(K.equal) or pressed(K.keypad_add):
        state.exposure = round(state.exposure + 0.5, 3)
    if pressed(K.minus) or pressed(K.keypad_subtract):
        state.exposure = round(state.exposure - 0.5, 3)
    if pressed(K.space, False):
        state.auto_rotate = not state.auto_rotate
    if pressed(K.r, False):
        state.reset_rotation()
    if pressed(K.s, False):
        state.screenshot_path = default_screenshot_name()
    if pressed(K.f, False):
        state.fullscreen = not state.fullscreen
    if pressed(K.tab, False):
        state.show_gui = not state.show_gui
    if pressed(K.h, False) or pressed(K.f1, False):
        state.show_help = not state.show_help
    if pressed(K.escape, False):
        state.quit = True


def default_screenshot_name() -> str:
    """``ffls-view-YYYYmmdd-HHMMSS.png`` in the working directory."""
    return time.strftime("ffls-view-%Y%m%d-%H%M%S.png")


def _drag_rotate(state: ViewerState, deg_x: float, deg_y: float) -> None:
    """While the last item is dragged, rotate: ``deg_x`` degrees of yaw per pixel right, pitch per pixel up."""
    if imgui.is_item_active() and imgui.is_mouse_dragging(imgui.MouseButton_.left, 0.0):
        d = imgui.get_io().mouse_delta
        if d.x or d.y:
            if state.light_mode:  # RTI style: the drag moves the single light (right: azimuth down, up: higher)
                state.move_light(daz=-d.x * deg_x, delev=-d.y * deg_y)
            else:
                state.rotate_by(dyaw=-d.x * deg_x, dpitch=-d.y * deg_y)


# ----------------------------------------------------------------------------- image
def _image_window(state: ViewerState, view: ViewInfo, x, y, w, h) -> None:
    imgui.set_next_window_pos(imgui.ImVec2(x, y))
    imgui.set_next_window_size(imgui.ImVec2(max(w, 1.0), max(h, 1.0)))
    flags = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_saved_settings
             | imgui.WindowFlags_.no_bring_to_front_on_focus | imgui.WindowFlags_.no_scroll_with_mouse
             | imgui.WindowFlags_.no_background)  # the cleared framebuffer is the background: one blend less
    imgui.begin("relit", None, flags)
    avail = imgui.get_content_region_avail()
    iw, ih = view.image_size
    s = max(1e-6, min(avail.x / max(iw, 1), avail.y / max(ih, 1)))
    dw, dh = iw * s, ih * s
    p = imgui.get_cursor_screen_pos()
    p0 = imgui.ImVec2(p.x + (avail.x - dw) / 2, p.y + (avail.y - dh) / 2)
    p1 = imgui.ImVec2(p0.x + dw, p0.y + dh)
    imgui.invisible_button("##relit", imgui.ImVec2(max(avail.x, 1.0), max(avail.y, 1.0)))
    _drag_rotate(state, state.drag_deg_per_px, state.drag_deg_per_px)
    dl = imgui.get_window_draw_list()
    state.image_rect = (p0.x, p0.y, p1.x, p1.y)
    if view.image_tex:
        if not view.image_drawn_by_window:
            dl.add_image(_tex(view.image_tex), p0, p1)
        if view.overlay_tex and not state.show_background:
            dl.add_image(_tex(view.overlay_tex), p0, p1)
    if view.recording:
        dl.add_text(imgui.ImVec2(p0.x + 8, p0.y + 8), _u32(1, 0.3, 0.3), view.recording)
    imgui.end()


# ----------------------------------------------------------------------------- panels
def _lightmap_panel(state: ViewerState, view: ViewInfo) -> None:
    if not imgui.collapsing_header("Light map", imgui.TreeNodeFlags_.default_open):
        return
    names = list(BUILTIN_MAPS)
    current = names.index(state.lightmap) if state.lightmap in names else len(names)
    items = names + ([state.lightmap] if current == len(names) else [])
    changed, idx = imgui.combo("map", current, [n if n in BUILTIN_MAPS else f"file: {n}" for n in items])
    if changed:
        state.lightmap = items[idx]
    imgui.begin_disabled(not view.dialog_available)
    if imgui.button("Open..."):
        state.open_dialog = True
    imgui.end_disabled()
    if not view.dialog_available:
        imgui.set_item_tooltip("no desktop file dialog here: type a path below, or drop a file on the window")
    imgui.same_line()
    imgui.text_disabled("or drop a .exr/.hdr on the window")
    _, state.lightmap_path_input = imgui.input_text("##path", state.lightmap_path_input)
    imgui.same_line()
    if imgui.button("Load") and state.lightmap_path_input.strip():
        state.lightmap = state.lightmap_path_input.strip()
    if imgui.radio_button("map", state.preview_mode == "lightmap"):
        state.preview_mode = "lightmap"
    imgui.same_line()
    if imgui.radio_button("cell weights", state.preview_mode == "weights"):
        state.preview_mode = "weights"
    _preview(state, view)


def _preview(state: ViewerState, view: ViewInfo) -> None:
    """The lat-long preview with the lights; drag rotates, a click selects the nearest light."""
    if not view.preview_tex:
        return
    w = imgui.get_content_region_avail().x
    h = w / 2
    p0 = imgui.get_cursor_screen_pos()
    imgui.invisible_button("##preview", imgui.ImVec2(max(w, 1.0), max(h, 1.0)))
    _drag_rotate(state, 360.0 / max(w, 1.0), 180.0 / max(h, 1.0))
    if imgui.is_item_deactivated():
        drag = imgui.get_mouse_drag_delta(imgui.MouseButton_.left, 0.0)
        if abs(drag.x) + abs(drag.y) < 3 and len(view.light_uv):
            m = imgui.get_mouse_pos()
            px = np.stack([p0.x + view.light_uv[:, 0] * w, p0.y + view.light_uv[:, 1] * h], axis=-1)
            dist = np.hypot(px[:, 0] - m.x, px[:, 1] - m.y)
            i = int(np.argmin(dist))
            state.selected_light = i if dist[i] < 12 else None
    dl = imgui.get_window_draw_list()
    dl.add_image(_tex(view.preview_tex), p0, imgui.ImVec2(p0.x + w, p0.y + h))
    dot, sel = _u32(0.2, 0.9, 1.0), _u32(1.0, 0.2, 0.2)
    if view.single_light_uv is not None:  # light mode: the single light
        u, v = view.single_light_uv
        dl.add_circle_filled(imgui.ImVec2(p0.x + u * w, p0.y + v * h), 5.0, _u32(1.0, 0.9, 0.2))
    for i, (u, v) in enumerate(view.light_uv):
        c = imgui.ImVec2(p0.x + u * w, p0.y + v * h)
        if i == state.selected_light:
            dl.add_circle(c, 6.0, sel, 0, 2.0)
        dl.add_circle_filled(c, 2.0, dot)
    if imgui.is_item_hovered():
        imgui.set_item_tooltip("drag: rotate the light map; click a light: show its photo")
    imgui.text_disabled(f"{view.n_lights} lights; lat-long, world frame (+Z top, +X centre)")
    if view.photo_tex and state.selected_light is not None:
        imgui.text(f"light {state.selected_light}: basis photo")
        imgui.same_line()
        if imgui.small_button("close"):
            state.selected_light = None
        iw, ih = view.image_size
        pw = imgui.get_content_region_avail().x
        imgui.image(_tex(view.photo_tex), imgui.ImVec2(pw, pw * ih / max(iw, 1)))


def _light_panel(state: ViewerState) -> None:
    """Light mode (RTI style): one directional light; a disc (the hemisphere seen from above) to drag it."""
    if not imgui.collapsing_header("Single light"):
        return
    _, state.light_mode = imgui.checkbox("light mode (instead of the map)", state.light_mode)
    imgui.set_item_tooltip("relight with one directional light, interpolated with the quality panel's weighting")
    imgui.begin_disabled(not state.light_mode)
    _, state.light_az = imgui.slider_float("azimuth", state.light_az, -180.0, 180.0, "%.1f deg")
    _, state.light_el = imgui.slider_float("elevation", state.light_el, -90.0, 90.0, "%.1f deg")
    side = min(160.0, imgui.get_content_region_avail().x)
    p0 = imgui.get_cursor_screen_pos()
    imgui.invisible_button("##lightdisc", imgui.ImVec2(side, side))
    c = imgui.ImVec2(p0.x + side / 2, p0.y + side / 2)
    rad = side / 2 - 4
    if state.light_mode and imgui.is_item_active():
        m = imgui.get_mouse_pos()
        state.set_light_disc((m.x - c.x) / rad, -(m.y - c.y) / rad)  # screen y down, disc +Y up
    dl = imgui.get_window_draw_list()
    dl.add_circle(c, rad, _u32(0.6, 0.6, 0.6), 64, 1.5)
    d = state.light_vector()
    col = _u32(1.0, 0.9, 0.2) if d[2] >= 0 else _u32(0.5, 0.5, 0.5)  # below the horizon: seen through
    dl.add_circle_filled(imgui.ImVec2(c.x + d[0] * rad, c.y - d[1] * rad), 5.0, col)
    imgui.set_item_tooltip("the upper hemisphere seen from above (+X right, +Y up): drag to move the light")
    imgui.end_disabled()


def _rotation_panel(state: ViewerState) -> None:
    if not imgui.collapsing_header("Rotation", imgui.TreeNodeFlags_.default_open):
        return
    _, state.yaw = imgui.slider_float("yaw", state.yaw, -180.0, 180.0, "%.1f deg")
    _, state.pitch = imgui.slider_float("pitch", state.pitch, -90.0, 90.0, "%.1f deg")
    _, state.roll = imgui.slider_float("roll", state.roll, -180.0, 180.0, "%.1f deg")
    _, state.auto_rotate = imgui.checkbox("auto-rotate", state.auto_rotate)
    imgui.same_line()
    imgui.set_next_item_width(imgui.get_content_region_avail().x - 60)
    _, state.auto_rotate_speed = imgui.slider_float("deg/s", state.auto_rotate_speed, -180.0, 180.0, "%.0f")
    if imgui.button("reset"):
        state.reset_rotation()


def _image_panel(state: ViewerState, view: ViewInfo) -> None:
    if not imgui.collapsing_header("Image", imgui.TreeNodeFlags_.default_open):
        return
    _, state.exposure = imgui.slider_float("exposure", state.exposure, -10.0, 10.0, "%+.2f EV")
    idx = TONEMAPS.index(state.tonemap) if state.tonemap in TONEMAPS else 0
    changed, idx = imgui.combo("tone map", idx, list(TONEMAPS))
    if changed:
        state.tonemap = TONEMAPS[idx]
    imgui.begin_disabled(not view.mask_available)
    _, state.show_background = imgui.checkbox("show background", state.show_background)
    imgui.end_disabled()
    if not view.mask_available:
        imgui.set_item_tooltip(f"{view.mask_reason}; give one with ffls view --mask FILE or \"mask\" in capture.json")
    imgui.begin_disabled(not view.composite_available)
    _, state.composite = imgui.checkbox("composite into background", state.composite)
    imgui.end_disabled()
    imgui.set_item_tooltip(view.registration if view.composite_available else
                           "give ffls view --composite-surface CAPTURE --background BG.exr --surface-mask SURF.png "
                           "--mask OBJ.png")


def _quality_panel(state: ViewerState, view: ViewInfo) -> None:
    if not imgui.collapsing_header("Quality"):
        return
    drafts = state.quality_drafts
    for knob in QUALITY_KNOBS:
        imgui.begin_disabled(not state.knob_enabled(knob))
        val = state.quality.get(knob.key, knob.default)
        if knob.kind == "choice":
            items = list(knob.choices)
            if val not in items:  # a value from the command line (e.g. --basis-subset 100)
                items.append(str(val))
            changed, i = imgui.combo(knob.label, items.index(val) if val in items else 0, items)
            if changed:
                state.quality[knob.key] = items[i]
        elif knob.kind == "bool":
            changed, v = imgui.checkbox(knob.label, bool(val))
            if changed:
                state.quality[knob.key] = v
        else:  # sliders commit on release when the knob needs a rebuild
            lo, hi = state.knob_range(knob, view.n_lights)
            cur = drafts.get(knob.key, val)
            if knob.kind == "int":
                _, cur = imgui.slider_int(knob.label, int(cur), int(lo), int(hi))
            else:
                _, cur = imgui.slider_float(knob.label, float(cur), float(lo), float(hi))
            if not knob.rebuild or imgui.is_item_deactivated_after_edit():
                state.quality[knob.key] = cur
                drafts.pop(knob.key, None)
            elif imgui.is_item_active():
                drafts[knob.key] = cur
        imgui.end_disabled()
        if knob.help:
            imgui.set_item_tooltip(knob.help)
    b = view.basis_info
    if b:
        r = "full" if b.get("rank") is None else f"rank {b['rank']}"
        imgui.text_disabled(f"basis: {r}, {b.get('layers')} layers {b.get('dtype')}, "
                            f"{b.get('bytes', 0) / 2**20:.0f} MiB")


def _speed_panel(state: ViewerState, view: ViewInfo) -> None:
    if not imgui.collapsing_header("Speed", imgui.TreeNodeFlags_.default_open):
        return
    times = np.asarray(state.frame_times_ms, dtype=np.float32)
    last = float(times[-1]) if times.size else 0.0
    imgui.text(f"{state.fps():.1f} fps (mean of {times.size}), last {last:.1f} ms")
    t = view.timings
    if t:
        imgui.text_disabled("  ".join(f"{k} {v:.1f}" for k, v in t.items()) + " ms")
    if times.size and implot.begin_plot("##frametimes", imgui.ImVec2(-1, 110),
                                        implot.Flags_.no_legend | implot.Flags_.no_mouse_text):
        implot.setup_axes("", "ms", implot.AxisFlags_.no_tick_labels, implot.AxisFlags_.auto_fit)
        implot.setup_axis_limits(implot.ImAxis_.x1, 0, float(state.frame_times_ms.maxlen or times.size),
                                 implot.Cond_.always)
        implot.plot_line("frame ms", times)
        implot.end_plot()
    imgui.text_disabled(view.renderer)


def _output_panel(state: ViewerState, view: ViewInfo) -> None:
    if not imgui.collapsing_header("Output"):
        return
    if imgui.button("Screenshot (S)"):
        state.screenshot_path = default_screenshot_name()
    imgui.set_item_tooltip("window as PNG (GUI included) and the relit HDR as EXR, in the working directory")
    _, state.turntable_frames = imgui.slider_int("frames", state.turntable_frames, 8, 720)
    _, state.turntable_folder = imgui.input_text("output", state.turntable_folder)
    if state.turntable is None:
        if imgui.button("Record turntable") and state.turntable_folder.strip():
            state.turntable = TurntableJob(state.turntable_folder.strip(), int(state.turntable_frames),
                                           start_yaw=state.yaw)
        imgui.set_item_tooltip("rotates the yaw 360 degrees and records the relit image: to an .mp4 video, "
                               "or as frame_NNNN.png files when the output is a folder")
    else:
        imgui.text(view.recording or "recording...")
        if imgui.button("Stop"):
            state.turntable = None


def _window_panel(state: ViewerState, view: ViewInfo) -> None:
    if not imgui.collapsing_header("Window"):
        return
    _, state.fullscreen = imgui.checkbox("fullscreen (F)", state.fullscreen)
    fs = view.framebuffer_scale
    imgui.text_disabled(f"window {state.window_size[0]}x{state.window_size[1]}, framebuffer scale "
                        f"{fs[0]:g}x{fs[1]:g}, content scale {view.content_scale:g}")
    if imgui.button("Help (H)"):
        state.show_help = not state.show_help


def _help_window(state: ViewerState) -> None:
    imgui.set_next_window_size(imgui.ImVec2(460, 0), imgui.Cond_.first_use_ever)
    opened, state.show_help = imgui.begin("Help", state.show_help)
    if opened:
        if imgui.begin_table("keys", 2, imgui.TableFlags_.row_bg):
            for keys, what in SHORTCUTS:
                imgui.table_next_row()
                imgui.table_next_column()
                imgui.text(keys)
                imgui.table_next_column()
                imgui.text_wrapped(what)
            imgui.end_table()
        imgui.text_wrapped("Light maps: built-ins, Open... (desktop only), a typed path, or a file dropped on "
                           "the window. The preview shows the map in the world frame with the capture's lights "
                           "and their Voronoi cells.")
    imgui.end()
