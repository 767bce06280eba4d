"""The control panel drawn into a texture when it changes, and copied to the window every frame.

On a CPU rasteriser (llvmpipe, 2 cores) imgui's draw of the control panel costs about as much as
the relit image itself: a blended 360 x 800 window background, text, widgets, the preview and the
frame-time plot, about 5.5 ms of CPU per frame in a 1280 x 800 window (docs/viewer.md, frame
budget). The panel changes far less often than the image. :class:`GuiCache` draws the panel's
draw list into a texture the size of the window's framebuffer, cleared to the window's clear
colour, and copies the panel's rectangle from it to the window, texel for pixel, opaque and
unblended (``shaders/gui_copy.glsl``, about 1.6 ms), until the panel's content changes.

When the content changes, the texture is redrawn:

- at once while the user works in the panel: the mouse over it (or over it the frame before), a
  mouse drag that started in it, or text input;
- otherwise (readouts that an animation moves: the rotation sliders under auto-rotation or a drag
  of the image, the frame-time plot, the preview thumbnail) at most every :data:`PANEL_INTERVAL`
  seconds of the viewer's clock, the rate at which the renderer redraws the preview of a turning
  map (``viewer.renderer.PREVIEW_INTERVAL``);
- always before the window is read (a screenshot): :meth:`GuiCache.stale` says so.

The content is the draw list's vertices, indices and commands (clip rectangles, textures) and a
version number of the textures the panel shows (``ViewInfo.panel_version``). The pixels are the
same as imgui's own draw: the panel is blended over the clear colour in the texture as it would be
over the cleared window, and the copy is exact (``tests/test_viewer.py``).

Draw lists other than the panel's (tooltips, popups, the help window, the image window's overlay)
are drawn live over it each frame. Where one of them lies under the panel (it comes before the
panel's list in imgui's order and overlaps it) the frame is drawn live, without the texture.
"""
from __future__ import annotations

import ctypes

import numpy as np

__all__ = ["GuiCache", "PANEL_INTERVAL", "content_key", "list_bounds", "rects_overlap", "split_draw_lists", "sub_draw_data", "uncovered"]

#: Seconds between redraws of the panel's texture when only an animation changed it (10 a second).
PANEL_INTERVAL = 0.1
_VERT_FLOATS = 5  # ImDrawVert: pos (2 float), uv (2 float), col (uint32): 20 bytes
_IDX_BYTES = 4  # ImDrawIdx: imgui-bundle builds imgui with 32-bit indices


def _vertex_bytes(dl) -> bytes:
    n = dl.vtx_buffer.size()
    return ctypes.string_at(dl.vtx_buffer.data_address(), 4 * _VERT_FLOATS * n) if n else b""


def list_bounds(dl) -> tuple[float, float, float, float] | None:
    """``(x0, y0, x1, y1)`` of an ``imgui.ImDrawList``'s vertex positions (display coordinates),
    None when it has no vertex."""
    raw = _vertex_bytes(dl)
    if not raw:
        return None
    pos = np.frombuffer(raw, dtype=np.float32).reshape(-1, _VERT_FLOATS)[:, :2]
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def rects_overlap(a, b) -> bool:
    """Whether two rectangles ``(x0, y0, x1, y1)`` share an area (False when either is None)."""
    return a is not None and b is not None and a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _union(boxes):
    boxes = [b for b in boxes if b is not None]
    if not boxes:
        return None
    a = np.array(boxes)
    return float(a[:, 0].min()), float(a[:, 1].min()), float(a[:, 2].max()), float(a[:, 3].max())


def split_draw_lists(lists, panel_lists):
    """Split imgui's draw lists (back to front) into the panel's and the others.

    Parameters
    ----------
    lists : sequence of imgui.ImDrawList
        ``ImDrawData.cmd_lists``, in imgui's order (back to front).
    panel_lists : sequence of imgui.ImDrawList
        The lists that belong to the panel (compared by identity).

    Returns
    -------
    (list, list, tuple) or None
        ``(panel, others, bounds)``: the panel's lists, the others (both in imgui's order) and the
        panel's bounds ``(x0, y0, x1, y1)`` in display coordinates. None when there is no panel
        list, or when another list lies under the panel (before its last list, overlapping it), so
        that drawing the panel first would change the picture.
    """
    lists = list(lists)
    is_panel = [any(dl is p for p in panel_lists) for dl in lists]
    if not any(is_panel):
        return None
    panel = [dl for dl, p in zip(lists, is_panel) if p]
    bounds = _union([list_bounds(dl) for dl in panel])
    if bounds is None:
        return None
    last = max(i for i, p in enumerate(is_panel) if p)
    others = []
    for i, (dl, p) in enumerate(zip(lists, is_panel)):
        if p:
            continue
        if i < last and rects_overlap(list_bounds(dl), bounds):
            return None
        others.append(dl)
    return panel, others, bounds


def content_key(lists) -> tuple:
    """What the pixels of ``lists`` depend on: vertices, indices and each command's clip rectangle,
    texture and index range (``imgui.ImDrawList`` sequence -> hashable tuple)."""
    key = []
    for dl in lists:
        n_idx = dl.idx_buffer.size()
        idx = ctypes.string_at(dl.idx_buffer.data_address(), _IDX_BYTES * n_idx) if n_idx else b""
        cmds = tuple((c.clip_rect.x, c.clip_rect.y, c.clip_rect.z, c.clip_rect.w, int(c.get_tex_id()),
                      c.elem_count, c.idx_offset, c.vtx_offset) for c in dl.cmd_buffer)
        key.append((_vertex_bytes(dl), idx, cmds))
    return tuple(key)


def uncovered(width: int, height: int, rects) -> list[tuple[int, int, int, int]]:
    """The parts of a ``width`` x ``height`` framebuffer that no rectangle of ``rects`` covers.

    Parameters
    ----------
    width, height : int
    rects : sequence of (x0, y0, x1, y1) or None
        Pixel rectangles (None entries are skipped).

    Returns
    -------
    list of (x, y, w, h)
        Disjoint rectangles (as ``moderngl`` viewports) that together are the uncovered area: the
        grid that the rectangles' edges cut, its uncovered cells merged along rows.
    """
    rects = [tuple(int(v) for v in r) for r in rects if r is not None]
    xs = sorted({0, width, *(min(max(v, 0), width) for r in rects for v in (r[0], r[2]))})
    ys = sorted({0, height, *(min(max(v, 0), height) for r in rects for v in (r[1], r[3]))})
    out = []
    for y0, y1 in zip(ys[:-1], ys[1:]):
        run = None
        for x0, x1 in zip(xs[:-1], xs[1:]):
            covered = any(r[0] <= x0 and x1 <= r[2] and r[1] <= y0 and y1 <= r[3] for r in rects)
            if covered or x1 <= x0 or y1 <= y0:
                if run is not None:
                    out.append(run)
                    run = None
            elif run is None:
                run = (x0, y0, x1 - x0, y1 - y0)
            else:
                run = (run[0], y0, x1 - run[0], y1 - y0)
        if run is not None:
            out.append(run)
    return out


def sub_draw_data(draw_data, lists, textures: bool = False):
    """An ``imgui.ImDrawData`` with ``draw_data``'s display rectangle and scale and only ``lists``.

    ``textures``: also hand on the texture list, whose pending updates (the font atlas) the backend
    then carries out; draw once with it per frame, before any draw list is read.
    """
    from imgui_bundle import imgui

    sub = imgui.ImDrawData()
    sub.valid = True
    sub.display_pos, sub.display_size = draw_data.display_pos, draw_data.display_size
    sub.framebuffer_scale = draw_data.framebuffer_scale
    if textures:
        sub.textures = draw_data.textures
    for dl in lists:
        sub.add_draw_list(dl)
    return sub


class GuiCache:
    """The panel's texture, its redraw rule and the copy to the window.

    Parameters
    ----------
    ctx : moderngl.Context
        The window's context.
    interval : float
        :data:`PANEL_INTERVAL`.

    Attributes
    ----------
    redraws : int
        How many times the panel was drawn into the texture (tests, benchmarks).
    stale : bool
        The panel shown differs from the last frame's draw lists (a redraw was put off).
    """

    def __init__(self, ctx, interval: float = PANEL_INTERVAL):
        from ffls.gpu.shaders import load_program

        self.ctx = ctx
        self.interval = float(interval)
        self._prog = load_program(ctx, "gui_copy.glsl")
        self._vao = ctx.vertex_array(self._prog, [])
        self._tex = self._fbo = None
        self._key = None
        self._time = -np.inf
        self._rect = None  # framebuffer pixels (x0, y0, x1, y1), GL origin bottom-left
        self._mouse_was_inside = False
        self._drag_from_panel = False
        self.redraws = 0
        self.stale = False

    def interactive(self, io, bounds) -> bool:
        """Whether the user works in the panel: the mouse over ``bounds`` now or last frame, a drag
        (left button) that started in it, or text input (``io``: ``imgui.get_io()``)."""
        m = io.mouse_pos
        inside = bounds[0] <= m.x < bounds[2] and bounds[1] <= m.y < bounds[3]
        if io.mouse_clicked[0]:
            self._drag_from_panel = inside
        elif not io.mouse_down[0]:
            self._drag_from_panel = False
        was, self._mouse_was_inside = self._mouse_was_inside, inside
        return bool(inside or was or self._drag_from_panel or io.want_text_input)

    def draw(self, draw_data, panel, bounds, *, version, interactive: bool, now: float, clear, render,
             force: bool = False) -> tuple[int, int, int, int]:
        """Redraw the panel's texture when its rule says so, then copy it to the bound framebuffer.

        Parameters
        ----------
        draw_data : imgui.ImDrawData
            This frame's (display position, size and framebuffer scale), its textures already
            brought up to date (:func:`sub_draw_data` with ``textures=True``).
        panel : list of imgui.ImDrawList
            The panel's lists (:func:`split_draw_lists`).
        bounds : (4,) float
            Their bounds, display coordinates.
        version : int
            ``ViewInfo.panel_version``: changes when a texture the panel shows is rewritten.
        interactive : bool
            :meth:`interactive`: redraw at once when the content changed.
        now : float
            Seconds of the viewer's animation clock (the sum of ``ViewerApp.step``'s ``dt``: wall
            time in the window, 1/30 s a frame under ``ffls view --benchmark``).
        clear : (4,) float
            The window's clear colour (RGBA).
        render : callable
            ``render(draw_data)``: imgui's renderer backend.
        force : bool
            Redraw whenever the content changed (before reading the window).

        Returns
        -------
        (int, int, int, int)
            The rectangle copied, framebuffer pixels ``(x0, y0, x1, y1)`` with the origin at the
            bottom-left corner (GL).
        """
        import moderngl

        sx, sy = draw_data.framebuffer_scale.x, draw_data.framebuffer_scale.y
        fbw = int(draw_data.display_size.x * sx)
        fbh = int(draw_data.display_size.y * sy)
        ox, oy = draw_data.display_pos.x, draw_data.display_pos.y
        x0 = max(0, int(np.floor((bounds[0] - ox) * sx)))
        x1 = min(fbw, int(np.ceil((bounds[2] - ox) * sx)))
        y_top = max(0, int(np.floor((bounds[1] - oy) * sy)))
        y_bot = min(fbh, int(np.ceil((bounds[3] - oy) * sy)))
        rect = (x0, fbh - y_bot, x1, fbh - y_top)
        if self._tex is None or self._tex.size != (fbw, fbh):
            self.release_texture()
            self._tex = self.ctx.texture((fbw, fbh), 4, dtype="f1")
            self._tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._fbo = self.ctx.framebuffer([self._tex])
            self._key = None
        key = (content_key(panel), int(version), rect, (fbw, fbh), tuple(clear))
        changed = key != self._key
        if changed and (self._key is None or force or interactive or now - self._time >= self.interval):
            screen = self.ctx.fbo
            self._fbo.use()
            w, h = rect[2] - rect[0], rect[3] - rect[1]
            self.ctx.clear(*clear, viewport=(rect[0], rect[1], w, h))
            render(sub_draw_data(draw_data, panel))
            screen.use()
            self._key, self._time, self._rect = key, now, rect
            self.redraws += 1
            changed = False
        self.stale = changed
        r = self._rect
        self.ctx.viewport = (r[0], r[1], r[2] - r[0], r[3] - r[1])
        self.ctx.disable(moderngl.BLEND)
        self._tex.use(0)
        self._prog["u_panel"].value = 0
        self._vao.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.viewport = (0, 0, fbw, fbh)
        return r

    def invalidate(self) -> None:
        """Forget the texture's content (the next :meth:`draw` redraws it)."""
        self._key = None

    def release_texture(self) -> None:
        for o in (self._fbo, self._tex):
            if o is not None:
                o.release()
        self._fbo = self._tex = None

    def release(self) -> None:
        """Release the texture and the vertex array (the program is the context's shader cache's)."""
        self.release_texture()
        if self._vao is not None:
            self._vao.release()
            self._vao = None
