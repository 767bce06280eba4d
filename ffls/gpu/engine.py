"""The relighting engine: light map -> pass 1 (cell weights) -> pass 2 (weighted sum) -> tone map.

:class:`Engine` owns the GPU state of one capture: the basis texture arrays (float16 with a
per-dataset scale, or float32; optionally a compressed basis of K eigen-images), pass 1
(:class:`ffls.gpu.integrate.CellIntegrator`), pass 2
(:class:`ffls.gpu.weighted_sum.WeightedSum`) and the display pass. It never creates a context.

Typical use (viewer or CLI)::

    eng = Engine.from_capture(ctx, capture, lights, dtype="f16")
    eng.set_lightmap(lm)
    eng.set_rotation(rotation_z(30))
    eng.render(exposure=0.0, tonemap="aces")
    imgui.image(eng.display_texture.glo, eng.size)    # row 0 = top row: uv (0,0)-(1,1) is upright
    hdr = eng.read_hdr()

Only what changed is recomputed: a new exposure or tone curve reruns the display pass only; a
new light map or rotation reruns pass 1 and 2.
"""
from __future__ import annotations

import time

import numpy as np

from ffls.conventions import check_hemisphere, checked_rotation, checked_weights
from ffls.errors import InputError
from ffls.gpu.basis import DEFAULT_BUDGET, BasisTextures, PackedBasis
from ffls.gpu.context import release_gl
from ffls.gpu.integrate import CellIntegrator
from ffls.gpu.weighted_sum import DEFAULT_METHOD, Projector, ToneMapPass, WeightedSum, default_method, weights_to_vec4
from ffls.relight.basis import capture_basis
from ffls.relight.quality import integration_map
from ffls.weights.kriging import KernelLearner

__all__ = ["Engine", "gpu_frame_ms"]


class Engine:
    """GPU relighting of one capture.

    Parameters
    ----------
    ctx : moderngl.Context
        OpenGL 4.3+ (compute shaders, SSBOs). Created by the caller.
    basis : (n, H, W, 3) float32 array
        Linear basis images, finite; row 0 is the top row.
    directions : (n, 3) float array
        Unit light directions (world frame) of the basis images.
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
    dtype : {'f16', 'f32'}
        GPU storage of the basis (float16 uses a checked per-dataset scale).
    rank : int, optional
        Use a compressed basis of ``rank`` eigen-images (:mod:`ffls.relight.compress`).
    cell_res : int
        Resolution of the Voronoi cell-index texture (pass 1).
    weighting : {'voronoi', 'antialiased', 'barycentric', 'gaussian', 'spline'}
        Weighting scheme of pass 1 (:mod:`ffls.weights.weighting`); ``'voronoi'`` uses the exact
        candidate-cell texture, the others a baked :class:`ffls.weights.weighting.WeightTexture`.
    weights_res : int
        Resolution of that weight texture (smooth schemes).
    weighting_options : dict, optional
        Scheme options (:data:`ffls.weights.weighting.OPTIONS`).
    compressed : ffls.relight.compress.CompressedBasis, optional
        A precomputed compression (``rank`` is then its rank); with ``rank`` and no
        ``compressed`` the basis is compressed here.
    method : {'auto', 'packed', 'fragment', 'compute'}
        Pass-2 implementation (:data:`ffls.gpu.weighted_sum.METHODS`). ``'packed'`` stores the
        basis as pixel-major float16 pairs in SSBOs (:class:`ffls.gpu.basis.PackedBasis`) and is
        the fastest on llvmpipe; ``'fragment'`` and ``'compute'`` read RGBA16F/RGBA32F texture
        arrays (docs/gpu.md "Pass 2"). ``'auto'`` (default): packed on a CPU rasteriser, compute
        on a GPU (:func:`ffls.gpu.weighted_sum.default_method`).
    max_layers : int, optional
        Layers per texture array (default :data:`ffls.gpu.basis.ARRAY_LAYERS`) or per packed
        chunk (default :data:`ffls.gpu.basis.PACKED_LAYERS`); more lights split the basis.
    budget_bytes : int
        GPU memory allowed for the basis; more raises :class:`ffls.errors.InputError`.
    map_res : int, optional
        Height of the lat-long light map pass 1 integrates
        (:func:`ffls.relight.quality.integration_map`, box-filtered, integral kept); None = the
        map as given.
    profile : bool
        Wait for the GPU after each pass and record its time in :attr:`timings` (default True).
        False lets the CPU run ahead (the viewer's frames overlap its own work with the GPU's);
        :attr:`timings` is then empty.
    path : path-like, optional
        Named in errors (the capture folder).
    """

    def __init__(self, ctx, basis, directions, hemisphere: str = "upper", *, dtype: str = "f16",
                 rank: int | None = None, cell_res: int = 256, compressed=None, method: str = DEFAULT_METHOD,
                 max_layers: int | None = None, budget_bytes: int = DEFAULT_BUDGET, map_res: int | None = None,
                 profile: bool = True, path=None, weighting: str = "voronoi", weights_res: int | None = None,
                 weighting_options: dict | None = None):
        hemisphere = check_hemisphere(hemisphere)
        basis = np.asarray(basis)
        d = np.asarray(directions, dtype=np.float64)
        if basis.ndim != 4 or basis.shape[-1] != 3:
            raise InputError(f"basis must have shape (n, H, W, 3), not {basis.shape}", path)
        if d.shape != (basis.shape[0], 3):
            raise InputError(f"{d.shape[0] if d.ndim == 2 else '?'} light directions for {basis.shape[0]} basis images", path)
        self.ctx = ctx
        self.hemisphere = hemisphere
        self.directions = d
        self.cell_res = int(cell_res)
        self.map_res = None if map_res is None else int(map_res)
        self.profile = bool(profile)
        self._n = int(basis.shape[0])
        self._size = (int(basis.shape[2]), int(basis.shape[1]))
        self.timings: dict[str, float] = {}
        self.compressed = None
        self._objs = []
        if method == "auto":
            method = default_method(ctx)
        self.method = method
        storage = PackedBasis if method == "packed" else BasisTextures
        self._textures = self._pass2 = self._display = self._projector = None
        self._integrator = None
        self._weights_buffer = ctx.buffer(reserve=16 * self._n)
        self._cpu_weights = np.zeros((self._n, 3))
        self._cells = None
        self._hdr_stored = True  # False while pass 2 has written only the display image (_store_hdr)
        self._pass2_source = None  # the buffer pass 2 last read its weights from
        self._pending_weights = None  # set_weights' bytes, written at the next render
        #: Kriging's kernel, learnt from this basis when first chosen (:class:`ffls.weights.kriging.KernelLearner`).
        self.kernel = KernelLearner(d, basis)
        self.set_weighting(weighting, weights_res, **(weighting_options or {}))
        self._lightmap = None
        self._rotation = np.eye(3)
        self._weights_source = None
        self._weights_dirty = False
        self._hdr_dirty = True
        self._display_key = None
        try:
            if compressed is None and rank is not None:
                from ffls.relight.compress import compress_basis

                compressed = compress_basis(basis, int(rank))
            if compressed is not None:
                if compressed.n_lights != self._n or tuple(compressed.shape) != basis.shape[1:3]:
                    raise InputError("compressed basis does not match the capture's basis", path)
                self.compressed = compressed
                self._textures = storage(ctx, compressed.layers(), dtype, max_layers=max_layers,
                                               budget_bytes=budget_bytes, path=path)
                self._projector = Projector(ctx, compressed.projection_matrix())
            else:
                self._textures = storage(ctx, basis, dtype, max_layers=max_layers,
                                               budget_bytes=budget_bytes, path=path)
            self._pass2 = WeightedSum(ctx, self._textures, method)
            self._display = ToneMapPass(ctx, self._size)
        except BaseException:
            self.release()
            raise

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_capture(cls, ctx, capture, lights, quality=None, **kw) -> "Engine":
        """An engine for a capture folder and its light directions.

        Parameters
        ----------
        capture : ffls.io.capture.Capture
            :func:`ffls.relight.basis.accepted_basis` gives the basis, ``capture.hemisphere`` the domain.
        lights : ffls.io.capture.Lights
            ``directions`` (m, 3) matched to the capture's images by ``image_names``; lights
            with ``ok_mask`` False are left out (their basis images are not loaded).
        quality : ffls.relight.quality.Quality, optional
            Every knob at once: near-light correction and basis subset
            (:func:`ffls.relight.basis.capture_basis`), then ``dtype``, ``rank``, ``map_res``,
            ``weighting`` and ``cell_res`` (``weights_res`` for a smooth scheme) from it (keywords
            given in ``kw`` win).
        **kw
            As :class:`Engine`. With ``rank=K`` a compressed basis saved in the capture folder
            (:func:`ffls.relight.compress.load_compressed`) is used when it has at least K
            eigen-images and was made from the same images (checksum); otherwise it is computed and saved
            there (skipped silently if the folder is read-only). ``basis=(basis, directions)``:
            what :func:`ffls.relight.basis.capture_basis` gives under ``quality``, read already
            (the viewer's default rank reads it): the photos are not read again.
        """
        given = kw.pop("basis", None)
        basis, d = capture_basis(capture, lights, quality)[:2] if given is None else given
        if quality is not None:
            kw.setdefault("dtype", quality.precision)
            kw.setdefault("rank", quality.rank)
            kw.setdefault("map_res", quality.map_res)
            kw.setdefault("weighting", quality.weighting)
            if quality.cell_res is not None:  # the cell texture (voronoi) or the weight texture (smooth schemes)
                kw.setdefault("cell_res" if quality.weighting == "voronoi" else "weights_res", quality.cell_res)
        rank = kw.get("rank")
        if rank is not None and kw.get("compressed") is None:
            from ffls.relight.compress import load_or_compress

            kw["compressed"] = load_or_compress(capture.folder, basis, int(rank), save=True)
        kw.setdefault("path", getattr(capture, "folder", None))
        return cls(ctx, basis, d, getattr(capture, "hemisphere", "upper"), **kw)

    # ------------------------------------------------------------------ inputs
    def set_lightmap(self, lm) -> None:
        """Use light map ``lm`` (:class:`ffls.lightmaps.lightmap.LightMap`); pass 1 reruns at the next render."""
        lm = integration_map(lm, self.map_res)
        self._lightmap = lm
        if self._integrator is not None:
            self._integrator.set_lightmap(lm)
        self._weights_dirty = True

    def set_rotation(self, R) -> None:
        """Rotate the light map by ``R`` (3, 3) (content at d moves to R d; conventions.rotation_z)."""
        R = checked_rotation(R)
        if not np.array_equal(R, self._rotation):
            self._rotation = R.copy()
            self._weights_dirty = self._lightmap is not None

    def set_weights(self, weights) -> None:
        """Use these per-light weights ``(n, 3)`` directly (bypasses pass 1 until the next light map)."""
        w = checked_weights(weights, self._n)
        self._lightmap = None
        self._cpu_weights = w
        # written at the next render: until then the buffer holds the last render's weights, from
        # which its HDR may still be stored (_store_hdr)
        self._pending_weights = weights_to_vec4(w)
        self._weights_source = self._weights_buffer
        self._weights_dirty = False
        self._hdr_dirty = True

    def set_weighting(self, scheme: str = "voronoi", res: int | None = None, **options) -> None:
        """Use weighting ``scheme`` in pass 1 (:mod:`ffls.weights.weighting`); reruns pass 1 at the next render.

        ``res``: resolution of the smooth schemes' weight texture (default
        :data:`ffls.weights.weighting.DEFAULT_TEXTURE_RES`); ``options``: the scheme's options.
        The texture is baked at the next render. ``'kriging'`` without options uses the kernel
        learnt from this basis (:class:`ffls.weights.kriging.KernelLearner`).
        """
        from ffls.weights.weighting import DEFAULT_TEXTURE_RES, texture_slots

        options = self.kernel.options_for(scheme, options)
        texture_slots(scheme, **options)  # checks the scheme and its options
        key = (scheme, DEFAULT_TEXTURE_RES if res is None else int(res), tuple(sorted(options.items())))
        if key == getattr(self, "_weighting_key", None):
            return
        self._weighting_key = key
        self.weighting = scheme
        if self._integrator is not None:
            if self._pass2_source is self._integrator.weights_buffer:
                self._store_hdr()  # its weights buffer goes: store the last render's HDR first
                self._pass2_source = None
            self._integrator.release()
            self._integrator = None
        if scheme != "voronoi" or not hasattr(self._cells, "candidates"):
            self._cells = None
        self._weights_dirty = getattr(self, "_lightmap", None) is not None

    # ------------------------------------------------------------------ passes
    def _ensure_cells(self):
        if self._cells is None:
            scheme, res, options = self._weighting_key
            if scheme == "voronoi":
                from ffls.weights.voronoi import bake_cells

                self._cells = bake_cells(self.directions, self.hemisphere, self.cell_res)
            else:
                from ffls.weights.weighting import bake_weights

                self._cells = bake_weights(self.directions, scheme, self.hemisphere, res, **dict(options))
        return self._cells

    def _run_pass1(self):
        if self._integrator is None:
            self._integrator = CellIntegrator(self.ctx, self.directions, self.hemisphere, self._ensure_cells())
            self._integrator.set_lightmap(self._lightmap)
        self._weights_source = self._integrator.run(self._rotation)
        self._cpu_weights = None

    def _timed(self, name, fn):
        if not self.profile:
            fn()
            return
        t0 = time.perf_counter()
        fn()
        self.ctx.finish()
        self.timings[name] = (time.perf_counter() - t0) * 1e3

    def render(self, exposure: float = 0.0, tonemap: str = "srgb", hdr: bool = True) -> None:
        """Run what changed of pass 1, projection, pass 2 and the display pass.

        Parameters
        ----------
        exposure : float
            Stops applied before the tone curve (display texture only; the HDR is unscaled).
        tonemap : {'srgb', 'reinhard', 'aces'}
        hdr : bool
            False: the caller shows the display image and rarely reads the HDR (the viewer). A
            packed pass 2 of one chunk then writes the display image alone, and the HDR is
            stored only if :meth:`read_hdr` or :attr:`hdr_texture` asks for it (one more pass 2).

        Notes
        -----
        :attr:`timings` gets the wall time (ms, after ``ctx.finish()``) of each pass that ran:
        ``pass1``, ``project`` (compressed basis), ``pass2``, ``tonemap``; passes that did not
        need to run are absent (all are absent when :attr:`profile` is False). The packed pass 2
        also writes the display image (``WeightedSum.run(display=)``), so ``tonemap`` runs on its
        own only when just the exposure or the tone curve changed. With ``hdr=False`` and one
        chunk it writes the display image alone, and the HDR is stored when read
        (:meth:`read_hdr`, :attr:`hdr_texture`); ``tonemap`` is then that pass from the weights.
        """
        if self._lightmap is None and self._weights_source is None:
            raise RuntimeError("Engine.render: call set_lightmap(lm) or set_weights(w) first")
        self.timings = {}
        if self._weights_dirty:
            self._timed("pass1", self._run_pass1)
            self._weights_dirty = False
            self._hdr_dirty = True
        key = (float(exposure), tonemap)
        if self._pending_weights is not None:
            self._weights_buffer.write(self._pending_weights)
            self._pending_weights = None
        if self._hdr_dirty:
            if self._projector is not None:
                self._timed("project", lambda: self._projector.run(self._weights_source))
                self._pass2_source = self._projector.coeffs_buffer
            else:
                self._pass2_source = self._weights_source
            src = self._pass2_source
            if not hdr and self._pass2.display_only:  # the display image alone; the HDR is stored when read
                self._timed("pass2", lambda: self._pass2.run(src, display=(self._display.output, exposure, tonemap),
                                                             hdr=False))
                self._hdr_stored = False
                self._display_key = key
            elif self._pass2.fuses_display:  # pass 2 writes the display image too: no display pass
                self._timed("pass2", lambda: self._pass2.run(src, display=(self._display.output, exposure, tonemap)))
                self._hdr_stored = True
                self._display_key = key
            else:
                self._timed("pass2", lambda: self._pass2.run(src))
                self._hdr_stored = True
                self._display_key = None
            self._hdr_dirty = False
        if key != self._display_key:
            if self._hdr_stored:
                self._timed("tonemap", lambda: self._display.run(self._pass2.output, exposure, tonemap))
            else:  # the display pass from the weights (no HDR stored): the same curves, one dispatch
                self._timed("tonemap", lambda: self._pass2.run(self._pass2_source,
                                                               display=(self._display.output, exposure, tonemap),
                                                               hdr=False))
            self._display_key = key

    def _store_hdr(self) -> None:
        """Write the HDR of the last render into :attr:`hdr_texture` if pass 2 wrote the display alone.

        Its input buffers change only in :meth:`render` (pass 1, projection, :meth:`set_weights`'s
        deferred write), so they still hold that render's weights."""
        if not self._hdr_stored and self._pass2_source is not None:
            self._pass2.run(self._pass2_source)
            self._hdr_stored = True

    # ------------------------------------------------------------------ outputs
    @property
    def hdr_texture(self):
        """RGBA32F ``moderngl.Texture`` (W, H): the last relit image, linear radiance (alpha 1).

        After ``render(hdr=False)`` a one-chunk packed pass 2 wrote only the display image; the
        HDR is then written here, when asked for (one more pass 2)."""
        self._store_hdr()
        return self._pass2.output

    @property
    def display_texture(self):
        """RGBA8 ``moderngl.Texture`` (W, H): the last tone-mapped, sRGB-encoded image; ``.glo`` for imgui."""
        return self._display.output

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) of the images."""
        return self._size

    @property
    def n_lights(self) -> int:
        return self._n

    @property
    def basis_info(self) -> dict:
        """How the basis is stored: dtype, float16 scale, arrays, bytes, rank (None = uncompressed)."""
        t = self._textures
        return {"dtype": t.dtype, "scale": t.scale, "n_arrays": t.n_arrays, "layers": t.n, "bytes": t.nbytes,
                "rank": None if self.compressed is None else self.compressed.rank, "method": self.method}

    def read_hdr(self) -> np.ndarray:
        """The relit image ``(H, W, 3)`` float32, row 0 = top row."""
        self._store_hdr()
        return self._pass2.read()

    def read_display(self) -> np.ndarray:
        """The display image ``(H, W, 3)`` uint8, sRGB-encoded."""
        return self._display.read()

    def read_weights(self) -> np.ndarray:
        """The weights of the last render ``(n, 3)`` float64 (pass-1 output or :meth:`set_weights`)."""
        if self._cpu_weights is not None:
            return np.array(self._cpu_weights, dtype=np.float64)
        return np.asarray(self._integrator.read_weights(), dtype=np.float64)

    def release(self) -> None:
        """Release every GL object the engine made (not the context)."""
        for o in (self._integrator, self._projector, self._pass2, self._display, self._textures):
            if o is not None:
                o.release()
        release_gl(self._weights_buffer)
        self._pass2_source = None
        self._cells = None
        self._integrator = self._projector = self._pass2 = self._display = self._textures = None
        self._weights_buffer = None


def gpu_frame_ms(ctx, basis, directions, lightmap, quality, hemisphere="upper", frames: int = 3,
                 compressed=None) -> float:
    """Median ms per frame of an :class:`Engine` for ``quality``, the map rotated every frame.

    ``basis`` and ``directions`` are after near correction; the subset, storage, rank, cell
    texture and map height of ``quality`` are applied here. A frame is pass 1, projection, pass 2
    and the display pass, with ``ctx.finish()`` (the timer of ``--quality auto``,
    :func:`ffls.relight.auto.choose_quality`). ``compressed``: a compression of the (subset)
    basis of rank >= ``quality.rank`` to truncate instead of compressing again.
    """
    from ffls.conventions import rotation_z
    from ffls.relight.quality import prepare_basis

    b, d, _ = prepare_basis(basis, directions, basis_subset=quality.basis_subset)
    cb = None
    if quality.rank is not None and compressed is not None and compressed.rank >= quality.rank \
            and compressed.n_lights == len(d):
        from ffls.relight.auto import truncate

        cb = truncate(compressed, quality.rank)
    res = {} if quality.cell_res is None else {"cell_res" if quality.weighting == "voronoi" else "weights_res":
                                               quality.cell_res}
    eng = Engine(ctx, b, d, hemisphere, dtype=quality.precision, rank=quality.rank, map_res=quality.map_res,
                 profile=False, compressed=cb, weighting=quality.weighting, **res)
    try:
        eng.set_lightmap(lightmap)
        ts = []
        for k in range(frames + 1):
            eng.set_rotation(rotation_z(1.0 + k))
            t0 = time.perf_counter()
            eng.render()
            ctx.finish()
            ts.append((time.perf_counter() - t0) * 1e3)
    finally:
        eng.release()
    return float(np.median(ts[1:]))
