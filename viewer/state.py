"""The viewer's state: everything the GUI may change, and nothing else.

The viewer has three parts (GUIDE section 2):

* :class:`ViewerState` (this module): a plain dataclass. The GUI function
  (:func:`viewer.gui.draw_gui`) changes only it; the renderer (:class:`viewer.renderer.Renderer`)
  and the window loop (:mod:`viewer.app`) read it.
* :class:`ViewInfo`: what the renderer tells the GUI each frame (texture ids, light positions in
  the preview, timings, messages). The GUI reads it and never changes it.
* :data:`QUALITY_KNOBS`: descriptors of the quality panel. A later issue adds a knob by appending
  a :class:`Knob` here (and reading ``state.quality[key]`` in the renderer); the GUI draws every
  knob from its descriptor.

Nothing here imports a GL or window module.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ffls.commands.common import WEIGHTINGS
from ffls.commands.common import parse_rotation  # noqa: F401  (re-exported: one --rotate for every command)
from ffls.relight.compress import DEFAULT_RANK, rank_range

__all__ = ["Knob", "QUALITY_KNOBS", "METHODS", "TONEMAPS", "BUILTIN_MAPS", "ViewerState", "ViewInfo",
           "TurntableJob", "default_quality", "SUBSETS", "subset_size", "quality_from_state", "state_quality", "parse_size", "parse_rotation"]

#: Tone curves of :func:`ffls.display.tonemap.tonemap` (and the engine's display pass).
TONEMAPS = ("srgb", "reinhard", "aces")
#: Built-in light maps (:func:`ffls.lightmaps.lightmap.builtin_lightmap`).
BUILTIN_MAPS = ("courtyard", "studio", "sunrise", "night", "sky", "paper")
#: Pass-2 methods: compressed basis of rank K (float16 eigen-images), or the full basis.
#: 'auto' is the full float16 basis on a GPU and the compressed one on a CPU rasteriser
#: (llvmpipe), where the full basis cannot keep frame rate (docs/viewer.md).
METHODS = ("auto", "compressed", "full f16", "full f32")
#: Basis subsets of the quality panel: all photos, or a fraction chosen by farthest-point sampling.
SUBSETS = ("all", "1/2", "1/4", "1/8")
#: Frame times kept for the plot.
HISTORY = 240


@dataclass(frozen=True)
class Knob:
    """Descriptor of one quality control; the GUI draws it, the renderer reads ``state.quality[key]``.

    Attributes
    ----------
    key : str
        Key in :attr:`ViewerState.quality`.
    label : str
        Text beside the widget.
    kind : {'choice', 'int', 'float', 'bool'}
        Widget: combo box, integer slider, float slider, checkbox.
    default : object
        Initial value.
    choices : tuple of str
        Values of a ``'choice'`` knob.
    lo, hi : float
        Slider range of ``'int'``/``'float'`` knobs. ``hi`` may be lowered per capture (see
        :meth:`ViewerState.knob_range`), e.g. the rank cannot exceed the number of lights.
    help : str
        Tooltip.
    enabled_when : tuple, optional
        ``(key, values)``: the knob is enabled only while ``quality[key]`` is in ``values``.
    rebuild : bool
        True when a change needs a new engine (GPU upload); False when the next render suffices.
    """

    key: str
    label: str
    kind: str
    default: object
    choices: tuple = ()
    lo: float = 0
    hi: float = 1
    help: str = ""
    enabled_when: tuple | None = None
    rebuild: bool = True


#: The quality panel, in display order.
QUALITY_KNOBS: tuple[Knob, ...] = (
    Knob("method", "method", "choice", "auto", choices=METHODS,
         help="auto: full f16 on a GPU, compressed on a CPU rasteriser; compressed: mean + K "
              "eigen-images (fast); full: every basis image, float16 or float32"),
    Knob("rank", "rank K", "int", DEFAULT_RANK, lo=1, hi=128, enabled_when=("method", ("auto", "compressed")),
         help="eigen-images of the compressed basis (computed once, saved in the capture folder)"),
    Knob("cell_res", "cell texture", "choice", "256", choices=("128", "256", "512"),
         help="resolution of the Voronoi cell-index texture of pass 1"),
    Knob("map_res", "pass-1 map", "choice", "64", choices=("full", "256", "128", "64", "32"),
         help="lat-long height of the light map integrated by pass 1 (box-filtered: the integral is kept)",
         rebuild=False),
    Knob("weighting", "weighting", "choice", "voronoi", choices=WEIGHTINGS,
         help="how a light-map direction is shared among the lights: voronoi (box per cell), antialiased "
              "(soft cell borders), barycentric (spherical triangles), gaussian (kernel over the nearest "
              "lights); the smooth ones do not pop as the map rotates (docs/weighting.md)",
         rebuild=False),
    Knob("subset", "basis subset", "choice", "all", choices=SUBSETS,
         help="use a fraction of the photos, chosen by farthest-point sampling on the light directions"),
    Knob("near", "near-light correction", "bool", False,
         help="scale each photo by its light's squared distance to the scene centre (needs light positions)"),
)


def default_quality() -> dict:
    """``{key: default}`` of every :data:`QUALITY_KNOBS` entry."""
    return {k.key: k.default for k in QUALITY_KNOBS}


def subset_size(choice: str, n_lights: int) -> int | None:
    """Photos kept for a :data:`SUBSETS` choice or a count ``'N'`` (None = all); at least 1."""
    if choice in (None, "all"):
        return None
    text = str(choice)
    if "/" in text:
        return max(1, n_lights // int(text.split("/")[1]))
    return min(max(1, int(text)), n_lights)  # a count given on the command line (--basis-subset N)


def quality_from_state(quality: dict, n_lights: int, software: bool):
    """The :class:`ffls.relight.quality.Quality` of the panel's values ``quality`` for ``n_lights`` photos.

    ``software``: the GL renderer is a CPU rasteriser (``method='auto'`` is then the compressed basis).
    """
    from ffls.relight.compress import default_rank
    from ffls.relight.quality import Quality

    method = quality.get("method", "auto")
    if method == "auto":
        method = "compressed" if software else "full f16"
    sub = subset_size(quality.get("subset", "all"), n_lights)
    n = n_lights if sub is None else sub
    rank = default_rank(n, int(quality.get("rank", DEFAULT_RANK))) if method == "compressed" and n > 1 else None
    mr = quality.get("map_res", "full")
    return Quality(weighting=quality.get("weighting", "voronoi"),
                   precision="f32" if method.endswith("f32") else "f16", rank=rank, basis_subset=sub,
                   cell_res=int(quality.get("cell_res", 256)), map_res=None if mr in (None, "full") else int(mr),
                   near_correction=bool(quality.get("near", False)))


def state_quality(quality) -> dict:
    """The panel's values (``{key: value}`` of :data:`QUALITY_KNOBS`) for a
    :class:`ffls.relight.quality.Quality` (what ``--quality auto`` chose, or the command line's knobs).

    A compressed basis is float16 in the viewer; ``quality.precision`` applies to the full basis.
    """
    q = default_quality()
    if quality.rank is not None:
        q["method"], q["rank"] = "compressed", int(quality.rank)
    else:
        q["method"] = "full f32" if quality.precision == "f32" else "full f16"
    q["subset"] = "all" if quality.basis_subset is None else str(int(quality.basis_subset))
    q["cell_res"] = str(int(quality.cell_res or 256))
    q["map_res"] = "full" if quality.map_res is None else str(int(quality.map_res))
    q["near"] = bool(quality.near_correction)
    q["weighting"] = quality.weighting
    return q


def parse_size(text: str) -> tuple[int, int]:
    """``'WxH'`` -> ``(W, H)`` positive ints; ``ValueError`` otherwise."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise ValueError(f"size must be WxH (e.g. 1280x800), not {text!r}") from None
    if w < 1 or h < 1:
        raise ValueError(f"size must be positive, not {text!r}")
    return w, h


@dataclass
class TurntableJob:
    """A turntable recording in progress: ``frames`` frames over 360 degrees of yaw into ``folder``
    (an ``.mp4`` file, or a folder of ``frame_NNNN.png``)."""

    folder: str
    frames: int = 120
    done: int = 0
    start_yaw: float = 0.0


@dataclass
class ViewerState:
    """Everything the viewer's GUI controls.

    Attributes
    ----------
    yaw, pitch, roll : float
        Light-map rotation in degrees (:func:`ffls.conventions.rotation_ypr`).
    auto_rotate : bool
        Advance the yaw by ``auto_rotate_speed`` degrees per second.
    auto_rotate_speed : float
    exposure : float
        Stops applied before the tone curve.
    tonemap : {'srgb', 'reinhard', 'aces'}
    show_background : bool
        Show the pixels outside the capture's object mask (only with a mask, see docs/viewer.md).
    composite : bool
        Show the object composited into the background (differential rendering,
        :mod:`ffls.relight.composite`; only with ``ffls view --composite-surface``).
    lightmap : str
        A built-in name (:data:`BUILTIN_MAPS`) or a file path; the renderer loads it when it changes.
    lightmap_path_input : str
        The path text field (fallback of the open dialog).
    open_dialog : bool
        Pending: the app opens a file dialog (portable_file_dialogs) and puts the result in
        ``lightmap``.
    selected_light : int or None
        Index (among the accepted lights) whose basis photo is shown.
    preview_mode : {'lightmap', 'weights'}
        Light-map preview: the rotated map, or the per-cell weights as a heat map.
    quality : dict
        Values of :data:`QUALITY_KNOBS`.
    quality_drafts : dict
        Slider values being dragged, committed to ``quality`` on release (knobs that rebuild).
    window_size : (int, int)
        Window size in screen coordinates (updated on resize).
    fullscreen : bool
    screenshot_path : str or None
        Pending: save the window (PNG, GUI included) and the relit HDR (EXR, same stem).
    turntable : TurntableJob or None
        Recording in progress.
    turntable_frames, turntable_folder : int, str
        Settings of the next recording.
    frame_times_ms : deque of float
        Recent frame times (ms), newest last.
    show_help, show_gui : bool
    quit : bool
        Pending: close the window.
    drag_deg_per_px : float
        Rotation per pixel of mouse drag.
    light_mode : bool
        RTI-style relighting: one directional light (``light_az``, ``light_el``) instead of the
        light map, interpolated with the ``weighting`` knob; dragging moves the light.
    light_az, light_el : float
        The light's azimuth (degrees from +X toward +Y, wrapped to [-180, 180)) and elevation
        (degrees above the horizon, [-90, 90]), world frame.
    image_rect : (x0, y0, x1, y1) or None
        Where the GUI laid out the relit image in the last frame (window coordinates, y down);
        the window draws it there when :attr:`ViewInfo.image_drawn_by_window` is set.
    """

    yaw: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0
    auto_rotate: bool = False
    auto_rotate_speed: float = 30.0
    exposure: float = 0.0
    tonemap: str = "aces"
    show_background: bool = True
    composite: bool = False
    lightmap: str = "courtyard"
    lightmap_path_input: str = ""
    open_dialog: bool = False
    selected_light: int | None = None
    preview_mode: str = "lightmap"
    quality: dict = field(default_factory=default_quality)
    quality_drafts: dict = field(default_factory=dict)
    window_size: tuple = (1280, 800)
    fullscreen: bool = False
    screenshot_path: str | None = None
    turntable: TurntableJob | None = None
    turntable_frames: int = 120
    turntable_folder: str = "turntable.mp4"
    frame_times_ms: deque = field(default_factory=lambda: deque(maxlen=HISTORY))
    show_help: bool = False
    show_gui: bool = True
    quit: bool = False
    drag_deg_per_px: float = 0.4
    light_mode: bool = False
    light_az: float = 45.0
    light_el: float = 45.0
    image_rect: tuple | None = None

    # ------------------------------------------------------------------ pure updates
    def rotate_by(self, dyaw: float = 0.0, dpitch: float = 0.0, droll: float = 0.0) -> None:
        """Add to the rotation; yaw and roll wrap to [-180, 180), pitch is clamped to [-90, 90]."""
        self.yaw = wrap_degrees(self.yaw + dyaw)
        self.roll = wrap_degrees(self.roll + droll)
        self.pitch = float(np.clip(self.pitch + dpitch, -90.0, 90.0))

    def move_light(self, daz: float = 0.0, delev: float = 0.0) -> None:
        """Move the single light: azimuth wraps to [-180, 180), elevation is clamped to [-90, 90]."""
        self.light_az = wrap_degrees(self.light_az + daz)
        self.light_el = float(np.clip(self.light_el + delev, -90.0, 90.0))

    def set_light_disc(self, x: float, y: float) -> None:
        """Put the light over the point (x, y) of the unit disc (the upper hemisphere seen from above,
        +X right, +Y up, as an RTI viewer's light widget); outside the disc it goes to the rim."""
        r = float(np.hypot(x, y))
        if r > 1.0:
            x, y, r = x / r, y / r, 1.0
        self.light_az = wrap_degrees(float(np.degrees(np.arctan2(y, x))) if r > 0 else self.light_az)
        self.light_el = float(np.degrees(np.arccos(min(r, 1.0))))

    def light_vector(self) -> np.ndarray:
        """Unit world direction (3,) toward the single light."""
        az, el = np.radians(self.light_az), np.radians(self.light_el)
        return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])

    def reset_rotation(self) -> None:
        """Yaw, pitch and roll back to 0 and auto-rotation off."""
        self.yaw = self.pitch = self.roll = 0.0
        self.auto_rotate = False

    def advance(self, dt: float) -> None:
        """Advance time by ``dt`` seconds (auto-rotation); turntable frames are stepped by the app."""
        if self.auto_rotate and self.turntable is None:
            self.yaw = wrap_degrees(self.yaw + self.auto_rotate_speed * float(dt))

    def record_frame_time(self, ms: float) -> None:
        """Append a frame time (ms) to the history."""
        self.frame_times_ms.append(float(ms))

    def fps(self) -> float:
        """Frames per second over the history (0 when empty)."""
        if not self.frame_times_ms:
            return 0.0
        return 1000.0 / max(1e-6, float(np.mean(self.frame_times_ms)))

    def knob_range(self, knob: Knob, n_lights: int | None) -> tuple[float, float]:
        """Slider range of ``knob`` for a capture of ``n_lights`` accepted lights."""
        hi = knob.hi
        if knob.key == "rank" and n_lights:
            hi = min(hi, rank_range(n_lights)[1])  # K <= n - 1 (ffls.relight.compress.rank_range)
        return knob.lo, hi

    def knob_enabled(self, knob: Knob) -> bool:
        """Whether ``knob`` applies under the other knobs' current values."""
        if knob.enabled_when is None:
            return True
        key, values = knob.enabled_when
        return self.quality.get(key) in values

    def quality_key(self) -> tuple:
        """The values of the knobs that need a new engine (the renderer rebuilds when this changes)."""
        rebuild = [k.key for k in QUALITY_KNOBS if k.rebuild and self.knob_enabled(k)]
        return tuple((k, self.quality.get(k)) for k in rebuild)


def wrap_degrees(a: float) -> float:
    """``a`` wrapped to [-180, 180)."""
    return float((a + 180.0) % 360.0 - 180.0)


@dataclass
class ViewInfo:
    """What the renderer shows the GUI each frame (read-only for the GUI).

    Attributes
    ----------
    image_tex : int
        GL name of the RGBA8 display texture (``Engine.display_texture.glo``), 0 when none.
    image_size : (int, int)
        (W, H) of the relit image.
    overlay_tex : int
        GL name of the background overlay (checkerboard outside the mask), 0 when none.
    preview_tex : int
        GL name of the lat-long preview (RGBA8), 0 when none.
    preview_size : (int, int)
        (W, H) of the preview texture (W = 2 H).
    light_uv : (n, 2) float
        Lat-long uv (0..1, v down) of the accepted lights, world frame.
    photo_tex : int
        GL name of the selected light's basis photo (tone-mapped), 0 when none.
    n_lights : int
    mask_available : bool
        Whether the capture has an object mask (enables the background checkbox).
    mask_reason : str
        Why the background checkbox is disabled.
    timings : dict
        The engine's last pass timings (ms).
    basis_info : dict
        ``Engine.basis_info``.
    renderer : str
        GL renderer string.
    message : str
        Last error or notice (e.g. a light map that failed to load).
    framebuffer_scale : (float, float)
        Framebuffer pixels per window coordinate.
    content_scale : float
        The monitor's content scale (HiDPI).
    dialog_available : bool
        Whether a native file dialog can be opened (a desktop session).
    recording : str
        Turntable progress text, empty when idle.
    single_light_uv : (2,) float or None
        In light mode, the single light's lat-long uv (for the preview marker); None otherwise.
    composite_available : bool
        Whether a surface capture and background were given (enables the composite checkbox).
    registration : str
        The composite's registration (:meth:`ffls.relight.composite.Registration.describe`).
    image_drawn_by_window : bool
        The window draws the relit image itself (opaque, under the GUI, in ``state.image_rect``),
        so the GUI only lays it out; False: the GUI draws it (imgui image, blended).
    panel_version : int
        Changes whenever a texture the control panel shows (preview, basis photo) is rewritten: the
        window's copy of the panel (:mod:`viewer.gui_cache`) is then out of date.
    """

    image_tex: int = 0
    image_size: tuple = (1, 1)
    overlay_tex: int = 0
    preview_tex: int = 0
    preview_size: tuple = (2, 1)
    light_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    photo_tex: int = 0
    n_lights: int = 0
    mask_available: bool = False
    mask_reason: str = ""
    timings: dict = field(default_factory=dict)
    basis_info: dict = field(default_factory=dict)
    renderer: str = ""
    message: str = ""
    framebuffer_scale: tuple = (1.0, 1.0)
    content_scale: float = 1.0
    dialog_available: bool = False
    recording: str = ""
    single_light_uv: tuple | None = None
    composite_available: bool = False
    registration: str = ""
    image_drawn_by_window: bool = False
    panel_version: int = 0
