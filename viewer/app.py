"""The viewer's window: glfw + imgui-bundle's OpenGL 3 / glfw backends + the main loop.

This is one of the two places in ffls that create an OpenGL context (the other is
:mod:`ffls.gpu.context`): the glfw window's, wrapped by ``moderngl.create_context``. Per frame:

1. poll events (the drop callback puts a dropped light map into the state);
2. advance time (auto-rotation, turntable step);
3. :meth:`viewer.renderer.Renderer.update` (engine passes that the state made necessary);
4. :func:`viewer.gui.draw_gui` (changes only the state);
5. the relit image is drawn, opaque, where the GUI laid it out (``shaders/display_blit.glsl``),
   then imgui draws over it into the default framebuffer; pending actions (screenshot,
   turntable frame, fullscreen, open dialog, quit) are carried out; buffers are swapped.
"""
from __future__ import annotations

import ctypes
import time
from pathlib import Path

import numpy as np

from ffls.errors import GLUnavailable, InputError

from viewer import headless as platforms
from viewer.state import ViewerState

__all__ = ["ViewerApp", "open_capture", "CLEAR_COLOUR", "framebuffer_limit", "check_window_size"]

#: The window's background (RGBA), around the relit image and under the control panel.
CLEAR_COLOUR = (0.09, 0.09, 0.1, 1.0)


def open_capture(folder, lights=None, lights_map=None):
    """``(capture, lights)`` of a capture folder (:func:`ffls.io.capture.load_capture_and_lights`):
    ``lights`` a lights.json or .lp file, possibly another capture's (``lights_map``)."""
    from ffls.io.capture import load_capture_and_lights

    return load_capture_and_lights(folder, lights, lights_map)


def framebuffer_limit(ctx) -> tuple[int, str]:
    """The largest width and height of a framebuffer that ``ctx`` can draw and read, and the limit that sets it.

    The window's default framebuffer is read through a texture of its size (:meth:`ViewerApp.read_window`,
    the control panel's cache), drawn through a viewport of its size, and may be a renderbuffer:
    the smallest of ``GL_MAX_TEXTURE_SIZE``, ``GL_MAX_RENDERBUFFER_SIZE`` and ``GL_MAX_VIEWPORT_DIMS``
    (queried from the context; 16384 each on llvmpipe).

    Returns
    -------
    (int, str)
        The limit in pixels and the name of the GL limit that gave it.
    """
    info = ctx.info
    limits = {}
    for key in ("GL_MAX_TEXTURE_SIZE", "GL_MAX_RENDERBUFFER_SIZE", "GL_MAX_VIEWPORT_DIMS"):
        v = info.get(key)
        if v:
            limits[key] = int(min(v)) if isinstance(v, (tuple, list)) else int(v)
    if not limits:
        return 2 ** 31 - 1, "none reported"
    key = min(limits, key=limits.get)
    return limits[key], key


def check_window_size(ctx, size, flag: str = "--size") -> None:
    """Refuse a framebuffer ``size`` (W, H) beyond :func:`framebuffer_limit` of ``ctx``, in one line naming ``flag``.

    Raises
    ------
    ffls.errors.InputError
    """
    limit, key = framebuffer_limit(ctx)
    w, h = (int(v) for v in size)
    if w > limit or h > limit:
        raise InputError(f"{flag}: a {w}x{h} framebuffer is beyond this OpenGL context's limit of {limit} pixels "
                         f"a side ({key}; ffls info lists the limits)")


class ViewerApp:
    """The viewer window over one capture.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
    lights : ffls.io.capture.Lights
    state : ViewerState, optional
        Initial state (its ``window_size`` and ``fullscreen`` shape the window).
    headless : bool, optional
        True: glfw's null platform with EGL (no display needed); False: a desktop window;
        None: null platform when no ``DISPLAY``/``WAYLAND_DISPLAY`` is set.
    mask_path : path-like, optional
        Object mask image (white = object) for hiding the background; else the capture's
        ``"mask"`` entry, else none.
    vsync : bool
        Swap interval 1 on a desktop (the display limits the frame rate); always 0 headless.
    title : str
    composite : viewer.renderer.CompositeInputs, optional
        Enables the composite mode (``ffls view --composite-surface``).
    timing : bool
        Wait for the GPU after drawing the window each frame so that :attr:`stats` charges each
        part of the frame correctly (benchmarks; costs the CPU/GPU overlap).
    profile : bool
        Also wait for the GPU after each engine pass to time it (``ffls view --profile``); the
        passes then no longer overlap the frame's CPU work, so frames are slower.
    cache_gui : bool
        Draw the control panel into a texture when it changes and copy it to the window otherwise
        (:mod:`viewer.gui_cache`); False: imgui draws it every frame.

    Attributes
    ----------
    state : ViewerState
    renderer : viewer.renderer.Renderer
    ctx : moderngl.Context
    platform : {'null', 'desktop'}
    gui_cache : viewer.gui_cache.GuiCache or None
        The control panel's texture (None when ``cache_gui`` is False).
    stats : list of dict
        Per frame: ``frame_ms`` (wall time of :meth:`step`), ``cpu_ms`` (CPU time of the process
        over it, llvmpipe's threads included), the engine passes that ran and the parts of the
        frame (wall ms), and ``cpu: ...`` (CPU ms of the update, the GUI and the window's drawing).
    """

    def __init__(self, capture, lights, state: ViewerState | None = None, *, headless: bool | None = None,
                 mask_path=None, vsync: bool = True, title: str = "ffls view", timing: bool = False,
                 composite=None, profile: bool = False, cache_gui: bool = True):
        from viewer.renderer import Renderer, load_mask

        self.state = state if state is not None else ViewerState()
        self.platform = platforms.choose_platform(headless)
        self._imgui_ready = False
        self.window = None
        self.renderer = None
        self.ctx = None
        self._dialog = None
        self._blit_vao = None
        self.gui_cache = None
        self._frame = None  # (ViewInfo, framebuffer width, height) of the last frame drawn
        self._sink = self._sink_job = None  # turntable FrameWriter and the job it records
        self.frames_rendered = 0
        self.stats: list[dict] = []
        self.timing = bool(timing)
        self._previous_context = platforms.CurrentEGLContext()
        glfw = self.glfw = platforms.acquire_glfw(self.platform)
        try:
            platforms.window_hints(glfw, self.platform)
            w, h = (int(v) for v in self.state.window_size)
            monitor = glfw.get_primary_monitor() if self.state.fullscreen else None
            if monitor:
                mode = glfw.get_video_mode(monitor)
                w, h = mode.size.width, mode.size.height
            self.window = glfw.create_window(w, h, title, monitor, None)
            if not self.window:
                raise GLUnavailable(f"glfw could not open an OpenGL 4.3 window on the {self.platform} platform")
            self._fullscreen = bool(monitor)
            self._windowed_geometry = (100, 100, *self.state.window_size)
            glfw.make_context_current(self.window)
            glfw.swap_interval(1 if (vsync and self.platform == "desktop") else 0)
            import moderngl

            try:
                # wrap the window's current context through moderngl's own loader of the current
                # context's functions: glcontext's "detect" mode would assume GLX, and plain
                # create_context() hands a second window the first window's cached context
                from _moderngl import DefaultLoader

                self.ctx = moderngl.create_context(require=430, context=DefaultLoader())
            except Exception as e:  # moderngl raises plain Exception
                raise GLUnavailable(f"the window's context is not OpenGL 4.3: {e}") from None
            check_window_size(self.ctx, glfw.get_framebuffer_size(self.window))
            mask = load_mask(capture, mask_path, size=self._image_size(capture))
            reason = "" if mask is not None else "this capture has no object mask"
            self.renderer = Renderer(self.ctx, capture, lights, mask=mask, mask_reason=reason, composite=composite,
                                     profile=profile)
            from ffls.gpu.shaders import load_program

            self._blit = load_program(self.ctx, "display_blit.glsl")
            self._blit_vao = self.ctx.vertex_array(self._blit, [])
            if cache_gui:
                from viewer.gui_cache import GuiCache

                self.gui_cache = GuiCache(self.ctx)
            self.renderer.info.image_drawn_by_window = True
            self._init_imgui()
            glfw.set_drop_callback(self.window, self.on_drop)
            self._t_last = None
            self._clock = 0.0  # seconds of animation (the sum of step's dt): paces the panel's redraws
        except BaseException:
            self.close()
            raise

    @staticmethod
    def _image_size(capture):
        s = getattr(capture, "image_size", None)
        return tuple(s) if s else None

    def _init_imgui(self) -> None:
        from imgui_bundle import imgui, implot

        self._imgui_ctx = imgui.create_context()
        imgui.set_current_context(self._imgui_ctx)
        self._implot_ctx = implot.create_context()
        implot.set_current_context(self._implot_ctx)
        io = imgui.get_io()
        io.set_ini_filename(None)  # never write imgui.ini into the working directory
        sx, sy = self.glfw.get_window_content_scale(self.window)
        scale = max(1.0, float(sx))
        if scale != 1.0:
            imgui.get_style().scale_all_sizes(scale)
            imgui.get_style().font_scale_dpi = scale
        self.renderer.info.content_scale = scale
        addr = ctypes.cast(self.window, ctypes.c_void_p).value
        if not imgui.backends.glfw_init_for_opengl(addr, True):
            raise GLUnavailable("imgui's glfw backend did not initialise")
        if not imgui.backends.opengl3_init("#version 430"):
            raise GLUnavailable("imgui's OpenGL 3 backend did not initialise")
        self._imgui_ready = True
        self.renderer.info.dialog_available = self.platform == "desktop" and platforms.has_display()

    # ------------------------------------------------------------------ callbacks
    def make_current(self) -> None:
        """Make this window's GL and imgui contexts current (before using :attr:`ctx` from outside)."""
        self._make_current()

    def _make_current(self) -> None:
        """Make this window's GL and imgui contexts current (several viewers may coexist)."""
        from imgui_bundle import imgui, implot

        self.glfw.make_context_current(self.window)
        imgui.set_current_context(self._imgui_ctx)
        implot.set_current_context(self._implot_ctx)

    def on_drop(self, window, paths) -> None:
        """glfw drop callback: the first dropped file becomes the light map."""
        if paths:
            p = paths[0]
            self.state.lightmap = p.decode() if isinstance(p, bytes) else str(p)

    # ------------------------------------------------------------------ loop
    def should_close(self) -> bool:
        """Whether the user closed the window or asked to quit."""
        return bool(self.state.quit or self.glfw.window_should_close(self.window))

    def step(self, dt: float | None = None) -> None:
        """Run one frame.

        Parameters
        ----------
        dt : float, optional
            Seconds to advance the animation by (auto-rotation); default the wall time since
            the previous frame (0 for the first).
        """
        from imgui_bundle import imgui

        from viewer.gui import draw_gui

        glfw, st = self.glfw, self.state
        now, cpu0 = time.perf_counter(), time.process_time()
        self._make_current()
        if self._t_last is not None:
            st.record_frame_time((now - self._t_last) * 1e3)
        if dt is None:
            dt = 0.0 if self._t_last is None else now - self._t_last
        self._t_last = now
        self._clock += dt
        glfw.poll_events()
        st.window_size = tuple(glfw.get_window_size(self.window))
        self._poll_dialog()
        st.advance(dt)
        job = st.turntable
        if job is not None:
            st.yaw = ((job.start_yaw + 360.0 * job.done / job.frames) + 180.0) % 360.0 - 180.0
        t_update, c_update = time.perf_counter(), time.process_time()
        info = self.renderer.update(st)
        t_gui, c_gui = time.perf_counter(), time.process_time()
        fbw, fbh = glfw.get_framebuffer_size(self.window)
        ww, wh = st.window_size
        info.framebuffer_scale = (fbw / max(ww, 1), fbh / max(wh, 1))
        info.recording = "" if job is None else f"recording turntable {job.done + 1}/{job.frames} -> {job.folder}"

        imgui.backends.opengl3_new_frame()
        imgui.backends.glfw_new_frame()
        imgui.new_frame()
        draw_gui(st, info)
        imgui.render()
        t_draw, c_draw = time.perf_counter(), time.process_time()

        self._frame = (info, fbw, fbh)
        self._draw_window(info, fbw, fbh, interactive=self._panel_interactive())
        if self.timing:
            self.ctx.finish()  # charge the window's drawing to this frame, not to the next pass 1
        t_swap, c_swap = time.perf_counter(), time.process_time()
        if job is not None:
            self._turntable_frame(job)
        elif self._sink is not None:
            self._drop_sink()
        if st.screenshot_path:
            path, st.screenshot_path = st.screenshot_path, None
            self.save_screenshot(path)
        glfw.swap_buffers(self.window)
        self._apply_fullscreen()
        self.frames_rendered += 1
        t_end, c_end = time.perf_counter(), time.process_time()
        # CPU time of the process (llvmpipe's threads included): on a shared machine it measures the
        # work of a frame where wall time measures the other jobs too
        self.stats.append({"frame_ms": (t_end - now) * 1e3, "cpu_ms": (c_end - cpu0) * 1e3, **info.timings,
                           "update (all engine + preview)": (t_gui - t_update) * 1e3,
                           "gui": (t_draw - t_gui) * 1e3, "window draw": (t_swap - t_draw) * 1e3,
                           "swap + actions": (t_end - t_swap) * 1e3,
                           "cpu: update": (c_gui - c_update) * 1e3, "cpu: gui": (c_draw - c_gui) * 1e3,
                           "cpu: window draw": (c_swap - c_draw) * 1e3})

    def _panel_lists(self):
        """The control panel's imgui draw lists this frame (empty when it is hidden)."""
        from imgui_bundle import imgui

        from viewer.gui import PANEL_WINDOW

        w = imgui.internal.find_window_by_name(PANEL_WINDOW)
        return [w.draw_list] if w is not None and w.active else []

    def _panel_interactive(self) -> bool:
        """Whether the user works in the control panel this frame (:meth:`GuiCache.interactive`)."""
        from imgui_bundle import imgui

        from viewer.gui_cache import list_bounds

        if self.gui_cache is None:
            return True
        boxes = [b for b in (list_bounds(dl) for dl in self._panel_lists()) if b is not None]
        if not boxes:
            return True
        b = np.array(boxes)
        return self.gui_cache.interactive(imgui.get_io(), (b[:, 0].min(), b[:, 1].min(), b[:, 2].max(), b[:, 3].max()))

    def _draw_window(self, info, fbw: int, fbh: int, interactive: bool = True, force: bool = False) -> None:
        """Draw the window's back buffer: the relit image and imgui's draw data of this frame.

        With :attr:`gui_cache`, the control panel comes from its texture (:mod:`viewer.gui_cache`)
        and the other draw lists are drawn live over it; the pixels are the same as without it.
        ``force`` redraws the panel's texture if its content changed (before the window is read).
        """
        from imgui_bundle import imgui

        from viewer.gui_cache import rects_overlap, split_draw_lists, sub_draw_data, uncovered

        render = imgui.backends.opengl3_render_draw_data
        dd = imgui.get_draw_data()
        self.ctx.screen.use()
        self.ctx.viewport = (0, 0, fbw, fbh)
        split = None
        if self.gui_cache is not None:
            split = split_draw_lists(dd.cmd_lists, self._panel_lists())
            if split is not None and rects_overlap(split[2], self.state.image_rect):
                split = None  # the image under the panel: the panel's texture holds the clear colour there
            if split is None:
                self.gui_cache.invalidate()
        if split is None:
            self.ctx.clear(*CLEAR_COLOUR)
            self._draw_image(info, fbw, fbh)
            render(dd)
            return
        render(sub_draw_data(dd, [], textures=True))  # the font atlas's pending updates, before reading lists
        panel, others, bounds = split
        copied = self.gui_cache.draw(dd, panel, bounds, version=info.panel_version, interactive=interactive,
                                     now=self._clock, clear=CLEAR_COLOUR, render=render, force=force)
        drawn = self._draw_image(info, fbw, fbh)
        # the background only where neither the panel nor the image is (llvmpipe clears a scissored
        # rectangle by drawing it: a few thin strips cost less than clearing the whole window)
        for vp in uncovered(fbw, fbh, (copied, drawn)):
            self.ctx.clear(*CLEAR_COLOUR, viewport=vp)
        self.ctx.viewport = (0, 0, fbw, fbh)
        if others:
            render(sub_draw_data(dd, others))

    def redraw(self) -> None:
        """Draw the last frame's window again into the back buffer (the same imgui draw data), with
        the control panel's texture brought up to date; nothing is stepped, polled or swapped."""
        if self._frame is None:
            raise RuntimeError("ViewerApp.redraw: no frame was drawn yet (call step first)")
        self._make_current()
        self._draw_window(*self._frame, force=True)

    def _draw_image(self, info, fbw: int, fbh: int):
        """The relit image, opaque, where the GUI laid it out (``state.image_rect``), under the GUI.

        Returns the rectangle drawn, framebuffer pixels ``(x0, y0, x1, y1)`` from the bottom-left
        corner, or None.

        imgui would draw it as a blended textured quad; on llvmpipe this costs about a quarter less
        (no read of the framebuffer per fragment). Same texture, same bilinear filter.
        """
        import moderngl

        rect, tex = self.state.image_rect, self.renderer.image_texture
        if not info.image_tex or rect is None or tex is None:
            return None
        sx, sy = info.framebuffer_scale
        x0, y0 = int(round(rect[0] * sx)), int(round(rect[1] * sy))
        x1, y1 = int(round(rect[2] * sx)), int(round(rect[3] * sy))
        if x1 <= x0 or y1 <= y0:
            return None
        self.ctx.viewport = (x0, fbh - y1, x1 - x0, y1 - y0)  # GL's origin is the bottom-left corner
        self.ctx.disable(moderngl.BLEND)
        tex.use(0)
        self._blit["u_image"].value = 0
        self._blit_vao.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.viewport = (0, 0, fbw, fbh)
        return x0, fbh - y1, x1, fbh - y0

    def run(self, frames: int | None = None, screenshot=None, dt: float | None = None) -> None:
        """Run frames until the window closes, or ``frames`` frames; then save ``screenshot``.

        Parameters
        ----------
        frames : int, optional
            Stop after this many frames (scripted mode).
        screenshot : path-like, optional
            After the last frame: save the window (PNG) and the relit HDR (EXR, same stem).
        dt : float, optional
            Fixed animation step per frame (default: wall time).
        """
        n = 0
        while not self.should_close() and (frames is None or n < frames):
            if screenshot is not None and frames is not None and n == frames - 1:
                self.state.screenshot_path = str(screenshot)
            self.step(dt)
            n += 1
        if screenshot is not None and (frames is None or n < frames):  # window closed early
            self.save_screenshot(screenshot)

    def auto_expose(self, key: float = 0.18) -> float:
        """Set ``state.exposure`` so that the object's log-average luminance in the current relit image maps to ``key``.

        The object is the mask when the viewer has one, else the bright part of the image (the
        black background is not metered; :func:`ffls.display.tonemap.object_pixels`).

        Returns
        -------
        float
            The exposure in stops (:func:`ffls.display.tonemap.auto_exposure`, rounded to 0.01).
        """
        from ffls.display.tonemap import auto_exposure

        self._make_current()
        self.renderer.update(self.state)
        self.state.exposure = round(auto_exposure(self.renderer.read_hdr(), key, mask=self.renderer.mask), 2)
        return self.state.exposure

    def summary(self, skip: int = 1) -> dict:
        """Frame-time statistics of the frames run so far, leaving out the first ``skip``.

        Returns
        -------
        dict
            ``frames``, ``mean_ms``, ``median_ms``, ``fps`` (1000 / mean), ``cpu_ms`` (mean CPU
            time per frame), ``panel_redraws`` (how many times the control panel was drawn into its
            texture, over all frames; None without :attr:`gui_cache`), and ``passes``: the mean ms
            of each engine pass and part of the frame over the frames where it ran.
        """
        rows = self.stats[skip:] if len(self.stats) > skip else self.stats
        ms = np.array([r["frame_ms"] for r in rows]) if rows else np.zeros(0)
        keys = sorted({k for r in rows for k in r if k not in ("frame_ms", "cpu_ms")})
        passes = {k: float(np.mean([r[k] for r in rows if k in r])) for k in keys}
        mean = float(ms.mean()) if ms.size else float("nan")
        cpu = float(np.mean([r["cpu_ms"] for r in rows])) if rows else float("nan")
        return {"frames": int(ms.size), "mean_ms": mean, "median_ms": float(np.median(ms)) if ms.size else mean,
                "fps": 1000.0 / mean if ms.size and mean > 0 else float("nan"), "cpu_ms": cpu, "passes": passes,
                "panel_redraws": None if self.gui_cache is None else self.gui_cache.redraws}

    # ------------------------------------------------------------------ actions
    def read_window(self) -> np.ndarray:
        """The default framebuffer (the whole window, GUI included) ``(H, W, 3)`` uint8, row 0 on top."""
        self._make_current()
        if self.gui_cache is not None and self.gui_cache.stale and self._frame is not None:
            self._draw_window(*self._frame, force=True)  # the panel as of the last frame, not as of its last redraw
        # moderngl's screen.read() selects GL_COLOR_ATTACHMENT0 as the read buffer, which is
        # GL_INVALID_OPERATION on the default framebuffer; a blit into an FBO reads GL_BACK.
        fbw, fbh = self.glfw.get_framebuffer_size(self.window)
        fbo = self.ctx.simple_framebuffer((fbw, fbh), components=4)
        try:
            self.ctx.copy_framebuffer(fbo, self.ctx.detect_framebuffer(0))  # its size now, after resizes
            raw = fbo.read(components=3, alignment=1)
        finally:
            for a in (*fbo.color_attachments, fbo.depth_attachment, fbo):
                if a is not None:
                    a.release()
        self.ctx.screen.use()
        return np.frombuffer(raw, dtype=np.uint8).reshape(fbh, fbw, 3)[::-1].copy()

    def save_screenshot(self, path) -> tuple[Path, Path]:
        """Write the window to ``path`` (PNG) and the relit HDR to ``path`` with suffix ``.exr``.

        Returns
        -------
        (Path, Path)
            The PNG and the EXR.
        """
        from ffls.errors import atomic_outputs
        from ffls.io.images import write_exr, write_png

        path = Path(path)
        if path.suffix.lower() != ".png":
            raise InputError("screenshot must be a .png (the HDR goes beside it as .exr)", path)
        path.parent.mkdir(parents=True, exist_ok=True)
        exr = path.with_suffix(".exr")
        window, hdr = self.read_window(), self.renderer.read_hdr_full()  # (full resolution: from a store by tiles)
        with atomic_outputs():  # the PNG and the EXR appear together or not at all (a failed EXR left a new PNG)
            write_png(path, window)
            write_exr(exr, hdr)
        self.renderer.info.message = f"saved {path} and {exr.name}"
        return path, exr

    def _turntable_frame(self, job) -> None:
        from ffls.errors import FflsError
        from ffls.io.video import FrameWriter

        if self._sink_job is not job:
            self._drop_sink()
            try:
                self._sink = FrameWriter(job.folder, fps=30.0)
            except FflsError as e:
                self.state.turntable = None
                self.renderer.info.message = f"turntable: {e}"
                return
            self._sink_job = job
        self._sink.write(self.renderer.read_display())
        job.done += 1
        if job.done >= job.frames:
            self.state.turntable = None
            self.state.yaw = job.start_yaw
            self.renderer.info.message = f"turntable: {self._sink.close()}"
            self._sink = self._sink_job = None

    def _drop_sink(self) -> None:
        """Abort a recording that the GUI stopped (a partial mp4 is removed)."""
        if self._sink is not None:
            self._sink.abort()
            self.renderer.info.message = f"turntable stopped: {self._sink.out} not written" \
                if self._sink.is_video else f"turntable stopped after {self._sink.frames} frames"
        self._sink = self._sink_job = None

    def _apply_fullscreen(self) -> None:
        glfw = self.glfw
        want = bool(self.state.fullscreen)
        if want == self._fullscreen:
            return
        if want:
            monitor = glfw.get_primary_monitor()
            if not monitor:
                self.state.fullscreen = False
                self.renderer.info.message = "no monitor to go fullscreen on"
                return
            x, y = glfw.get_window_pos(self.window)
            self._windowed_geometry = (x, y, *glfw.get_window_size(self.window))
            mode = glfw.get_video_mode(monitor)
            glfw.set_window_monitor(self.window, monitor, 0, 0, mode.size.width, mode.size.height, mode.refresh_rate)
        else:
            x, y, w, h = self._windowed_geometry
            glfw.set_window_monitor(self.window, None, x, y, w, h, 0)
        self._fullscreen = want

    def _poll_dialog(self) -> None:
        st = self.state
        if st.open_dialog:
            st.open_dialog = False
            if self.renderer.info.dialog_available and self._dialog is None:
                try:
                    from imgui_bundle import portable_file_dialogs as pfd

                    self._dialog = pfd.open_file("Open a light map", "", ["HDR light maps", "*.exr *.hdr", "All files", "*"])
                except Exception as e:  # no zenity/kdialog: fall back to the path field
                    self.renderer.info.dialog_available = False
                    self.renderer.info.message = f"no file dialog ({e}); type a path instead"
        if self._dialog is not None and self._dialog.ready(0):
            res = self._dialog.result()
            self._dialog = None
            if res:
                st.lightmap = res[0]

    # ------------------------------------------------------------------ teardown
    def close(self) -> None:
        """Release the renderer, imgui, the window and glfw (safe to call twice)."""
        if getattr(self, "_sink", None) is not None:
            self._drop_sink()
        if self.window is not None:
            self.glfw.make_context_current(self.window)
        if self._imgui_ready:
            from imgui_bundle import imgui, implot

            self._make_current()
            imgui.backends.opengl3_shutdown()
            imgui.backends.glfw_shutdown()
            implot.destroy_context(self._implot_ctx)
            imgui.destroy_context(self._imgui_ctx)
            self._imgui_ready = False
        if getattr(self, "gui_cache", None) is not None:
            self.gui_cache.release()
            self.gui_cache = None
        if getattr(self, "_blit_vao", None) is not None:
            self._blit_vao.release()
            self._blit_vao = None
        if self.renderer is not None:
            self.renderer.release()
            self.renderer = None
        if self.ctx is not None:
            self.ctx.release()
            self.ctx = None
        if self.window is not None:
            self.glfw.destroy_window(self.window)
            self.window = None
        if getattr(self, "glfw", None) is not None:
            platforms.release_glfw(self.glfw)
            self.glfw = None
            self._previous_context.restore()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
