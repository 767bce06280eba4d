"""The viewer's renderer: reads :class:`viewer.state.ViewerState`, drives the GPU engine, makes
the textures the GUI shows, and reports them in a :class:`viewer.state.ViewInfo`.

It receives the ``moderngl.Context`` of the window (it never creates one) and never changes
the state. What it makes:

* the relit image: :class:`ffls.gpu.engine.Engine` (pass 1, pass 2, tone map); rebuilt when a
  quality knob that needs it changes (:meth:`ViewerState.quality_key`);
* the light-map preview: a lat-long thumbnail of the rotated light map (or of the per-cell
  weights as a heat map) with the Voronoi cell borders of the capture's lights drawn in; the
  light positions go to the GUI as uv so that it can draw and pick them;
* the selected light's basis photo (tone-mapped);
* the composite (``state.composite``, with :class:`CompositeInputs`): a second engine relights the
  surface-alone capture under the same rotated map, and :func:`ffls.relight.composite.composite`
  merges both into the background on the CPU (registration fitted once per light map); the
  result is tone-mapped into its own texture;
* the background overlay: a checkerboard outside the capture's object mask, drawn by the GUI
  over the relit image when the background is hidden. A capture has a mask only when one is
  given explicitly (``"mask": "mask.png"`` in ``capture.json``, or ``ffls view --mask``);
  the viewer never guesses one from the pixel values.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffls.conventions import direction_to_latlong_uv, in_domain, latlong_directions, rotation_ypr
from ffls.errors import FflsError
from ffls.lightmaps.lightmap import lightmap_from_spec
from ffls.display.tonemap import tonemap as tonemap_np
from ffls.display.tonemap import auto_exposure, to_uint8
from ffls.radiance.photos import load_photo
from ffls.relight.quality import integration_map

from viewer.state import BUILTIN_MAPS, ViewerState, ViewInfo, quality_from_state

__all__ = ["Renderer", "CompositeInputs", "load_mask", "heat_colours", "pass1_lightmap", "resolve_method"]

#: Height of the lat-long preview texture (width is twice that).
PREVIEW_HEIGHT = 128
#: While the map turns by itself (auto-rotation, turntable), the preview and the cell-weight heat
#: map are redrawn at most this often (seconds): they are a thumbnail, and the heat map reads the
#: weights back from the GPU (a wait for pass 1).
PREVIEW_INTERVAL = 0.1


def load_mask(capture, path=None, size=None) -> np.ndarray | None:
    """The capture's object mask ``(H, W)`` bool (True = object), or None when it has none.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
        ``capture.extra['mask']`` (a file relative to the capture folder) is used when ``path``
        is None.
    path : path-like, optional
        An explicit mask image: white (> 0.5 after reading, any channel) is the object
        (:func:`ffls.io.images.read_mask`).
    size : (int, int), optional
        Expected (W, H); a mask of another size raises :class:`ffls.errors.InputError`, and so
        does an empty one (no object pixel: the background could only be hidden entirely).
    """
    from ffls.io.images import read_mask

    if path is None:
        rel = (capture.extra or {}).get("mask") if capture is not None else None
        if not rel:
            return None
        path = Path(capture.folder) / str(rel)
    mask = read_mask(path, size=size) > 0.5
    if not mask.any():
        from ffls.errors import InputError

        raise InputError("the mask is empty (no object pixel: white = object)", path)
    return mask


def resolve_method(method: str, renderer: str) -> str:
    """The pass-2 method that ``'auto'`` stands for on ``renderer`` (a GL_RENDERER string).

    A CPU rasteriser gets the compressed basis (the full one cannot keep frame rate there); a
    GPU gets the full float16 basis. Other methods are returned unchanged.
    """
    from ffls.gpu.context import is_software_renderer

    if method != "auto":
        return method
    return "compressed" if is_software_renderer(renderer) else "full f16"


def pass1_lightmap(lm, height):
    """The light map pass 1 integrates: ``lm`` itself (``'full'``) or a lat-long of ``height`` rows
    (:func:`ffls.relight.quality.integration_map`: box-filtered, the integral kept)."""
    return integration_map(lm, None if height in (None, "full") else int(height))


def heat_colours(t: np.ndarray) -> np.ndarray:
    """A perceptual heat map (dark blue -> purple -> orange -> yellow) of ``t`` in [0, 1]; (..., 3) float."""
    stops = np.array([[0.02, 0.02, 0.10], [0.30, 0.05, 0.45], [0.80, 0.20, 0.30], [0.98, 0.60, 0.10],
                      [1.00, 1.00, 0.60]])
    x = np.clip(np.asarray(t, dtype=np.float64), 0, 1) * (len(stops) - 1)
    i = np.minimum(x.astype(int), len(stops) - 2)
    f = (x - i)[..., None]
    return stops[i] * (1 - f) + stops[i + 1] * f


@dataclass
class CompositeInputs:
    """What the composite mode needs beside the object capture (``ffls view --composite-surface``).

    Attributes
    ----------
    capture, lights
        The surface-alone capture (same camera) and its lights.
    background : (H, W, 3) float32
        Linear background (the scene without the object).
    object_mask, surface_mask : (H, W) float32
        Coverage of the object and of the surface region.
    method : str
        :data:`ffls.relight.composite.METHODS`.
    """

    capture: object
    lights: object
    background: np.ndarray
    object_mask: np.ndarray
    surface_mask: np.ndarray
    method: str = "Debevec1998"


class Renderer:
    """Draws what a :class:`ViewerState` asks for with an :class:`ffls.gpu.engine.Engine`.

    Parameters
    ----------
    ctx : moderngl.Context
        The window's context (OpenGL 4.3).
    capture : ffls.io.capture.Capture
    lights : ffls.io.capture.Lights
    mask : (H, W) bool array, optional
        Object mask (True = object); None disables hiding the background.
    mask_reason : str
        Shown as the tooltip of the disabled background checkbox when ``mask`` is None.
    composite : CompositeInputs, optional
        Enables the composite mode.
    """

    def __init__(self, ctx, capture, lights, mask=None, mask_reason: str = "", composite=None,
                 profile: bool = False):
        self.mask = mask  # metered by automatic exposure (ffls.display.tonemap.auto_exposure)
        from ffls.weights.voronoi import bake_cells

        self.ctx = ctx
        self.profile = bool(profile)  # per-pass timings (a wait for the GPU after each pass)
        self._preview_time = -np.inf
        self.capture = capture
        self.lights = lights
        ok = np.asarray(lights.ok_mask, dtype=bool)
        names = [n for n, o in zip(lights.image_names, ok) if o]
        pos = {n: i for i, n in enumerate(capture.image_names)}
        self.image_index = [pos[n] for n in names if n in pos]
        self.directions = np.asarray(lights.directions, dtype=np.float64)[ok]
        self.hemisphere = getattr(capture, "hemisphere", "upper")
        self.engine = None
        self.composite_inputs = composite
        self.surface_engine = None
        self._composite_tex = None
        self._composite_hdr = None
        self._composite_display = None
        self._registration = None
        self.streamed, self.level = None, 0  # the full-resolution store when a pyramid level is shown
        self.info = ViewInfo(n_lights=len(self.directions), renderer=ctx.info.get("GL_RENDERER", ""),
                             mask_available=mask is not None,
                             mask_reason=mask_reason or "this capture has no object mask")
        self._quality_key = None
        self._light_key = None
        self._light_weightings = {}
        self._lightmap_spec = None
        self._failed_spec = None
        self._lightmap = None
        self._pass1_key = None
        self._preview_latlong = None
        self._preview_key = None
        self._photo_key = None
        self._handed = None  # the basis read for the default rank, for the first engine (hand_basis)
        self.frame_ms = {}
        # textures owned here
        self._preview_tex = ctx.texture((2 * PREVIEW_HEIGHT, PREVIEW_HEIGHT), 4, dtype="f1")
        self._photo_tex = None
        self._overlay_tex = None
        # the world-frame geometry of the preview: texel directions, cells, cell borders, light uv
        d = latlong_directions(2 * PREVIEW_HEIGHT, PREVIEW_HEIGHT)
        self._preview_dirs = d
        self._below = ~in_domain(d, self.hemisphere)  # outside the capture's hemisphere
        cells = bake_cells(self.directions, self.hemisphere, 256)
        cid = cells.assign(d.reshape(-1, 3)).reshape(d.shape[:2])
        border = np.zeros(cid.shape, dtype=bool)
        border[:, :-1] |= cid[:, :-1] != cid[:, 1:]
        border[:-1, :] |= cid[:-1, :] != cid[1:, :]
        self._cell_id = cid
        self._border = border & (cid >= 0)
        u, v = direction_to_latlong_uv(self.directions)
        self.info.light_uv = np.stack([u, v], axis=-1)
        if mask is not None:
            self._make_overlay(mask)
        self.info.composite_available = composite is not None

    # ------------------------------------------------------------------ setup
    def _make_overlay(self, mask: np.ndarray) -> None:
        h, w = mask.shape
        yy, xx = np.mgrid[0:h, 0:w]
        checker = (((yy // 8) + (xx // 8)) % 2).astype(np.uint8)
        rgba = np.empty((h, w, 4), dtype=np.uint8)
        rgba[..., :3] = np.where(checker[..., None] == 1, 96, 64)
        rgba[..., 3] = np.where(mask, 0, 255)
        self._overlay_tex = self.ctx.texture((w, h), 4, np.ascontiguousarray(rgba).tobytes())
        self.info.overlay_tex = self._overlay_tex.glo

    def hand_basis(self, basis, directions, quality) -> None:
        """The accepted basis (:func:`ffls.relight.basis.capture_basis` under ``quality``), read by the
        command to choose the default rank: the next engine build takes it instead of reading every
        photo again, when its own quality prepares the same basis (near correction, subset)."""
        self._handed = ((quality.near_correction, quality.basis_subset), basis, directions)

    def _build_engine(self, state: ViewerState) -> None:
        from ffls.gpu.engine import Engine

        from ffls.gpu.context import is_software_renderer
        from ffls.relight.basis import accepted_positions

        quality = quality_from_state(state.quality, len(self.directions), is_software_renderer(self.info.renderer))
        note = ""
        if quality.near_correction and not np.all(np.isfinite(accepted_positions(self.lights))):
            quality = quality.replace(near_correction=False)
            note = "; near-light correction off: the lights file gives no positions"
        t0 = time.perf_counter()
        # the pass-1 map height is applied here (it changes without a rebuild), not by the engine; the
        # weighting knob switches without a rebuild (set_weighting in update), its texture at its default
        # the photos, or the level of the store's pyramid that fits the GPU and the window (docs/scale.md)
        from ffls.commands.common import available_memory
        from ffls.gpu.tiled import engine_for_view
        from ffls.relight.stream import default_memory

        handed, self._handed = self._handed, None
        kw = {} if handed is None or handed[0] != (quality.near_correction, quality.basis_subset) else {
            "basis": handed[1:]}
        new, self.streamed, self.level = engine_for_view(self.ctx, self.capture, self.lights,
                                                         default_memory(available_memory()), quality=quality,
                                                         window=state.window_size, map_res=None, profile=self.profile,
                                                         cell_res=quality.cell_res or 256, weights_res=None, **kw)
        del handed, kw
        self._light_key = None
        if self.engine is not None:
            self.engine.release()
        self.engine = new
        if self.composite_inputs is not None:
            if self.surface_engine is not None:
                self.surface_engine.release()
            ci = self.composite_inputs
            sq = quality_from_state(state.quality, int(np.count_nonzero(ci.lights.ok_mask)),
                                    is_software_renderer(self.info.renderer))
            if sq.near_correction and not np.all(np.isfinite(accepted_positions(ci.lights))):
                sq = sq.replace(near_correction=False)
            self.surface_engine = Engine.from_capture(self.ctx, ci.capture, ci.lights, quality=sq, map_res=None,
                                                      profile=self.profile, cell_res=sq.cell_res or 256,
                                                      weights_res=None)
            self._registration = None
        self._pass1_key = None
        self.info.basis_info = dict(new.basis_info)
        self.info.image_size = new.size
        self.info.message = f"engine ready ({time.perf_counter() - t0:.1f} s): {self._describe_basis()}{note}"

    def _describe_basis(self) -> str:
        b = self.info.basis_info
        r = "full basis" if b.get("rank") is None else f"rank {b['rank']}"
        return f"{r}, {b.get('layers')} layers {b.get('dtype')}, {b.get('bytes', 0) / 2**20:.0f} MiB"

    def _load_lightmap(self, spec: str) -> None:
        try:
            lm = lightmap_from_spec(spec)
        except (FflsError, OSError, ValueError) as e:
            self._failed_spec = spec
            self.info.message = f"light map {spec!r}: {e}"
            return
        self._lightmap = lm
        self._lightmap_spec = spec
        self._failed_spec = None
        rad = lm.to_latlong(PREVIEW_HEIGHT).data.astype(np.float64)
        lum = rad @ np.array([0.2126, 0.7152, 0.0722])
        med = float(np.median(lum[lum > 0])) if np.any(lum > 0) else 1.0
        self._preview_latlong = to_uint8(tonemap_np(rad, float(np.log2(0.25 / med)), "reinhard"))
        self._preview_key = None
        self._pass1_key = None
        self.info.message = f"light map: {Path(spec).name if spec not in BUILTIN_MAPS else spec}"

    # ------------------------------------------------------------------ per frame
    def update(self, state: ViewerState) -> ViewInfo:
        """Bring the engine and textures up to date with ``state`` and render the relit image.

        Returns
        -------
        ViewInfo
            Texture ids and facts for the GUI (the same object every call).
        """
        t0 = time.perf_counter()
        if state.quality_key() != self._quality_key:
            self._quality_key = state.quality_key()
            self._build_engine(state)
        if state.lightmap != self._lightmap_spec and state.lightmap != self._failed_spec:
            self._load_lightmap(state.lightmap)
        R = rotation_ypr(state.yaw, state.pitch, state.roll)
        eng = self.engine
        self._check_pass1_fits(state, eng)
        pass1_key = (self._lightmap_spec, state.quality.get("map_res", "full"))
        scheme = state.quality.get("weighting", "voronoi")
        try:
            eng.set_weighting(scheme)  # a no-op unless it changed (pass 1 reruns then)
            if self.surface_engine is not None:
                self.surface_engine.set_weighting(scheme)
        except FflsError as e:  # kriging with too few lights, or no photos in memory to learn its kernel from
            self.info.message = f"weighting {scheme}: {e}"
            scheme = state.quality["weighting"] = eng.weighting
        if state.light_mode:  # RTI style: one directional light, weights from the scheme
            key = (state.light_az, state.light_el, scheme)
            if key != self._light_key:
                eng.set_weights(self.single_light_weights(state))
                self._light_key = key
                self._pass1_key = None  # the light map comes back when the mode ends
            eng.render(state.exposure, state.tonemap, hdr=False)  # the HDR is computed when read (screenshot)
            self.info.image_tex = eng.display_texture.glo
            u, v = direction_to_latlong_uv(state.light_vector()[None, :])
            self.info.single_light_uv = (float(u[0]), float(v[0]))
        else:
            self._light_key = None
            self.info.single_light_uv = None
            if self._lightmap is not None and pass1_key != self._pass1_key:
                lm1 = pass1_lightmap(self._lightmap, pass1_key[1])
                eng.set_lightmap(lm1)
                if self.surface_engine is not None:
                    self.surface_engine.set_lightmap(lm1)
                self._pass1_key = pass1_key
                self._registration = None  # refitted under the new map
            if self._lightmap is not None:
                eng.set_rotation(R)
                # the composite reads the HDR every frame; otherwise only a screenshot or exposure does
                eng.render(state.exposure, state.tonemap, hdr=bool(state.composite and self.surface_engine is not None))
                self.info.image_tex = eng.display_texture.glo
                self._composite_hdr = None
                if state.composite and self.surface_engine is not None:
                    self._update_composite(state, R)
        self.info.timings = dict(eng.timings)
        self._update_preview(state, R, animating=state.auto_rotate or state.turntable is not None)
        self._update_photo(state)
        self.frame_ms = {"renderer": (time.perf_counter() - t0) * 1e3}
        return self.info

    def _check_pass1_fits(self, state: ViewerState, eng) -> None:
        """Refuse a weighting / pass-1 map pair the GPU's pass 1 cannot take (one line in the status bar).

        A scheme with many weight-texture slots (``spline``: 24) over a large map passes the GPU's
        storage-buffer limit (:func:`ffls.relight.quality.pass1_buffer_bytes`). A new weighting
        knob value is then set back to the engine's scheme; a new pass-1 map height to the tallest
        offered one that fits. Either way the status line says why and which height fits.
        """
        from ffls.relight.quality import pass1_buffer_bytes, pass1_fit_height

        if self._lightmap is None:
            return
        scheme = state.quality.get("weighting", "voronoi")
        height = state.quality.get("map_res", "full")
        key = (self._lightmap_spec, height, scheme)
        if key == getattr(self, "_fit_key", None):
            return
        limit = int(self.ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 2 ** 27)
        m = len(pass1_lightmap(self._lightmap, height).samples()[0])
        if pass1_buffer_bytes(m, scheme) <= limit:
            self._fit_key = key
            return
        h = pass1_fit_height(limit, scheme)
        fits = [c for c in ("256", "128", "64", "32") if int(c) <= h]
        why = (f"weighting {scheme}: the GPU's pass 1 cannot take a {m}-texel map "
               f"({pass1_buffer_bytes(m, scheme) / 2 ** 20:.0f} MiB in one buffer, over {limit / 2 ** 20:.0f} MiB); ")
        before = getattr(eng, "weighting", "voronoi")
        if fits and scheme == before:  # the map height (or the map) changed under this scheme
            state.quality["map_res"] = fits[0]
            self.info.message = why + f"pass-1 map set to {fits[0]}"
        else:  # the knob changed: back to the scheme in use (voronoi if that was this one)
            state.quality["weighting"] = before if before != scheme else "voronoi"
            self.info.message = why + (f"choose pass-1 map {fits[0]} or lower" if fits else "no map height fits")
        self._fit_key = None

    def single_light_weights(self, state: ViewerState) -> np.ndarray:
        """Per-light RGB weights ``(n, 3)`` of the light mode's light under the ``weighting`` knob
        (:func:`ffls.weights.weighting.light_weights`); zero when the light is outside the hemisphere."""
        from ffls.weights.weighting import Weighting

        scheme = state.quality.get("weighting", "voronoi")
        d = state.light_vector()
        if not in_domain(d[None, :], self.hemisphere)[0] or len(self.directions) == 0:
            return np.zeros((len(self.directions), 3))
        if scheme not in self._light_weightings:
            self._light_weightings[scheme] = Weighting(self.directions, scheme, self.hemisphere,
                                                       **self.engine.kernel.options_for(scheme, {}))
        wt = self._light_weightings[scheme]
        w = wt(d[None, :]).dense(wt.n_lights)[0]
        return np.repeat(w[:, None], 3, axis=1)

    def _update_composite(self, state: ViewerState, R: np.ndarray) -> None:
        """Relight the surface capture, composite both into the background, show it (CPU merge)."""
        from ffls.relight.composite import composite

        ci = self.composite_inputs
        self.surface_engine.set_rotation(R)
        self.surface_engine.render(0.0, state.tonemap)
        try:
            res = composite(ci.background, self.engine.read_hdr(), self.surface_engine.read_hdr(), ci.object_mask,
                            ci.surface_mask, method=ci.method,
                            registration=self._registration if self._registration is not None else "auto")
        except FflsError as e:
            self.info.message = f"composite: {e}"
            state.composite = False
            return
        self._registration = res.registration
        self.info.registration = res.registration.describe()
        self._composite_hdr = res.image
        disp = self._composite_display = to_uint8(tonemap_np(res.image, state.exposure, state.tonemap))
        rgba = np.concatenate([disp, np.full(disp.shape[:2] + (1,), 255, np.uint8)], axis=-1)
        size = (disp.shape[1], disp.shape[0])
        if self._composite_tex is None:
            self._composite_tex = self.ctx.texture(size, 4, dtype="f1")
        self._composite_tex.write(np.ascontiguousarray(rgba).tobytes())
        self.info.image_tex = self._composite_tex.glo

    def _update_preview(self, state: ViewerState, R: np.ndarray, animating: bool = False) -> None:
        if self._preview_latlong is None:
            return
        now = time.perf_counter()
        if (animating and self._preview_key is not None and self._preview_key[2] == state.preview_mode
                and self._preview_key[0] == self._lightmap_spec and now - self._preview_time < PREVIEW_INTERVAL):
            return  # a thumbnail of a turning map: 10 redraws a second are enough
        weights_key = None
        if state.preview_mode == "weights":
            weights_key = self.engine.read_weights().sum(axis=1).round(9).tobytes()
        key = (self._lightmap_spec, R.round(9).tobytes(), state.preview_mode, weights_key)
        if key == self._preview_key:
            return
        self._preview_key = key
        self._preview_time = now
        rgb = self.preview_image(R, state.preview_mode)
        rgba = np.concatenate([rgb, np.full(rgb.shape[:2] + (1,), 255, np.uint8)], axis=-1)
        self._preview_tex.write(np.ascontiguousarray(rgba).tobytes())
        self.info.panel_version += 1
        self.info.preview_tex = self._preview_tex.glo
        self.info.preview_size = (2 * PREVIEW_HEIGHT, PREVIEW_HEIGHT)

    def preview_image(self, R: np.ndarray, mode: str = "lightmap") -> np.ndarray:
        """The light-map preview ``(PREVIEW_HEIGHT, 2 PREVIEW_HEIGHT, 3)`` uint8, world frame.

        Parameters
        ----------
        R : (3, 3) float
            Light-map rotation: the preview texel at world direction ``d`` shows the map's
            radiance from ``R^T d``.
        mode : {'lightmap', 'weights'}
            The rotated map (Reinhard, exposed for its median), or each cell filled with its
            light's weight (luminance, log scale over three decades) as a heat map.
        """
        d = self._preview_dirs
        if mode == "weights":
            w = self.engine.read_weights()
            lum = 0.2126 * w[:, 0] + 0.7152 * w[:, 1] + 0.0722 * w[:, 2]
            top = float(lum.max()) if lum.size and lum.max() > 0 else 1.0
            t = np.clip((np.log10(np.maximum(lum, top * 1e-3) / top) + 3.0) / 3.0, 0, 1)
            cid = self._cell_id
            rgb = np.where((cid >= 0)[..., None], heat_colours(t[np.maximum(cid, 0)]), 0.05)
            img = to_uint8(rgb)
        else:
            R = np.asarray(R, dtype=np.float64)
            h, w = self._preview_latlong.shape[:2]
            if (h, w) == d.shape[:2] and abs(R[2, 2] - 1.0) < 1e-12:
                # a rotation about +Z (yaw only: auto-rotation, turntable) turns the lat-long by whole
                # columns: R^T d has azimuth phi - yaw, u + yaw / 360 (conventions.direction_to_latlong_uv),
                # so column i shows column floor(i + 0.5 + w yaw / 360) mod w; no per-texel trigonometry
                yaw = np.degrees(np.arctan2(R[1, 0], R[0, 0]))
                cols = (np.arange(w) + int(np.floor(0.5 + w * yaw / 360.0))) % w
                img = self._preview_latlong[:, cols]
            else:
                src = d @ R  # R^T d, row vectors
                u, v = direction_to_latlong_uv(src)
                ii = np.clip((u * w).astype(int), 0, w - 1)
                jj = np.clip((v * h).astype(int), 0, h - 1)
                img = self._preview_latlong[jj, ii]  # tone-mapped once per map (Reinhard, exposed for its median)
            if self.hemisphere != "full":  # dim what the capture does not cover
                img[self._below] = img[self._below] // 3
        img[self._border] = (230, 230, 230)
        return img

    def _update_photo(self, state: ViewerState) -> None:
        sel = state.selected_light
        if sel is None or not 0 <= sel < len(self.image_index):
            self.info.photo_tex = 0
            return
        if self._photo_key == sel:
            return

        img = load_photo(self.capture, self.image_index[sel])
        disp = to_uint8(tonemap_np(img, auto_exposure(img), "srgb"))
        rgba = np.concatenate([disp, np.full(disp.shape[:2] + (1,), 255, np.uint8)], axis=-1)
        size = (disp.shape[1], disp.shape[0])
        if self._photo_tex is None or self._photo_tex.size != size:
            if self._photo_tex is not None:
                self._photo_tex.release()
            self._photo_tex = self.ctx.texture(size, 4, dtype="f1")
        self._photo_tex.write(np.ascontiguousarray(rgba).tobytes())
        self.info.panel_version += 1
        self._photo_key = sel
        self.info.photo_tex = self._photo_tex.glo

    # ------------------------------------------------------------------ outputs
    @property
    def image_texture(self):
        """The ``moderngl.Texture`` (RGBA8) whose name is ``info.image_tex``: the composite or the engine's display."""
        if self._composite_tex is not None and self.info.image_tex == self._composite_tex.glo:
            return self._composite_tex
        return self.engine.display_texture if self.engine is not None else None

    def read_hdr(self) -> np.ndarray:
        """The relit HDR image ``(H, W, 3)`` float32 of the last :meth:`update` (the composite in composite mode)."""
        if self._composite_hdr is not None:
            return self._composite_hdr
        return self.engine.read_hdr()

    def read_hdr_full(self) -> np.ndarray:
        """The relit HDR at full resolution: the composite in composite mode, the engine's, or the store's relit
        tile by tile with its weights."""
        if self._composite_hdr is not None:
            return self._composite_hdr
        if self.streamed is None:
            return self.engine.read_hdr()
        self.streamed.set_weights(self.engine.read_weights())
        self.streamed.render()
        return self.streamed.read_hdr()

    def read_display(self) -> np.ndarray:
        """The tone-mapped relit image ``(H, W, 3)`` uint8 of the last :meth:`update` (or the composite)."""
        if self._composite_hdr is not None:
            return self._composite_display
        return self.engine.read_display()

    def release(self) -> None:
        """Release the engine and every texture made here (not the context)."""
        if self.engine is not None:
            self.engine.release()
            self.engine = None
        if self.surface_engine is not None:
            self.surface_engine.release()
            self.surface_engine = None
        for t in (self._preview_tex, self._photo_tex, self._overlay_tex, self._composite_tex):
            if t is not None:
                t.release()
        self._preview_tex = self._photo_tex = self._overlay_tex = self._composite_tex = None
