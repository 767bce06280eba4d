"""GPU pass 1: integrate a rotated light map over the angular Voronoi cells of the lights.

Masselus, Dutre, Anrys, "The Free-form Light Stage", EGWR 2002, section 6: every light-map
texel adds ``radiance * solid_angle`` to the cell of the light nearest (by angle) to its rotated
direction ``R d``. This is the GPU twin of :func:`ffls.weights.voronoi.integrate_weights` with
``cells=`` a :class:`ffls.weights.voronoi.CellTexture`: per texel, the rotated direction picks a texel of
the cell texture, and the exact cell is the candidate with the largest dot product (ties to the
lowest index). Rotation, hemisphere test and dot products run in float64 (GLSL ``double``), so
the cell of every texel matches the float64 reference except on exact ties; accumulation is
float32.

Three techniques (``method=``), all deterministic (same input, same bits):

``'blend'``
    one ``GL_POINTS`` vertex per texel, additively blended into an RGBA32F target of
    ``S`` slices x the cells; GL processes fragments in primitive order, so each pixel is a
    fixed-order sum. A compute pass then sums the slices in a fixed order.
``'atomic'``
    a compute shader with per-workgroup shared-memory bins (float atomics,
    ``GL_NV_shader_atomic_float``), then the same fixed-order reduction over workgroups.
    Float atomics are order-nondeterministic by specification; on llvmpipe a workgroup runs
    on one thread, in invocation order, which is why its results repeat there (tested), but
    that is not guaranteed elsewhere.
``'sort'``
    cell id per texel, then a stable counting sort (per-block serial histograms, a scan,
    a serial scatter) and a per-cell segmented sum: deterministic by construction on any GPU.

``'auto'`` picks ``'sort'`` (see ``docs/gpu.md``, "Pass 1", for the measurements).

Smooth weighting schemes (:mod:`ffls.weights.weighting`): with ``cells`` a
:class:`ffls.weights.weighting.WeightTexture` every texel adds ``power x weight`` to each of the
(light, weight) slots of the weight-texture texel its rotated direction falls in
(the GPU twin of :func:`ffls.weights.weighting.integrate` with ``texture=``): ``'sort'`` makes one
item per texel and slot (``shaders/integrate_sparse_items.glsl``: cell = the slot's light, power x
weight) and sorts and sums the items as above; ``'blend'`` finds every texel's weight texel once
(``integrate_sparse_texels.glsl``) and blends one point per texel and slot
(``integrate_sparse.glsl``).
"""
from __future__ import annotations

import numpy as np

from ffls.conventions import check_hemisphere, is_rotation
from ffls.gpu.context import default_framebuffer, release_gl
from ffls.gpu.shaders import load_program

__all__ = ["CellIntegrator", "METHODS", "WEIGHTS_BINDING"]

#: Techniques of pass 1 (see the module docstring).
METHODS = ("blend", "atomic", "sort")
#: The method ``'auto'`` chooses (fastest deterministic-by-construction technique measured).
AUTO_METHOD = "sort"
#: Binding of the weights SSBO when pass 1 writes it (pass 2 binds it itself).
WEIGHTS_BINDING = 0

_LOCAL = 64
#: Serial float32 chain length aimed at per (cell, slice) in 'blend' and per group in 'atomic'.
_CHAIN = 128
#: Budget of partial sums (cells x slices) for 'blend' and 'atomic' (16 bytes each).
_PARTIAL_BUDGET = 1 << 22
#: Most blocks of the counting sort ('sort'); each is walked serially by one invocation.
_SORT_BLOCKS = 256
#: Items per block aimed at: fewer blocks for a small map (the scan walks cells x blocks counts).
_SORT_PER_BLOCK = 512
#: Items one invocation sums in the segment sum: under llvmpipe's 65535 loop iterations per
#: invocation (a longer loop is cut short there, silently).
_SEG_CHUNK = 32768


def _dispatch(prog, groups: int) -> None:
    """Run compute program ``prog`` over ``groups`` workgroups, then a memory barrier: the next
    dispatch reads what this one wrote to storage buffers (GL 4.3 section 7.13 requires the
    barrier; llvmpipe happens to serialise without it, a real GPU does not)."""
    prog.run(groups)
    prog.ctx.memory_barrier()


class CellIntegrator:
    """Per-cell integration of a rotated light map on the GPU (pass 1).

    Parameters
    ----------
    ctx : moderngl.Context
        OpenGL 4.3+ context (compute shaders, SSBOs, float64 in shaders).
    directions : (n, 3) array_like
        Light directions (the ones ``cells`` was baked from; normalised here).
    hemisphere : Hemisphere, {'upper', 'full'} or {'axis': [x, y, z]}
        Texels whose rotated direction is outside (``z < 0`` for ``'upper'``, ``d . axis < 0``
        for an axis hemisphere; the ``HEMI_AXIS`` define and the ``hemi_axis`` uniform) are
        dropped and counted.
    cells : ffls.weights.voronoi.CellTexture or ffls.weights.weighting.WeightTexture
        Candidate texture baked from ``directions`` for ``hemisphere`` (Voronoi cells), or the
        weight texture of a smooth scheme (``'sort'``, the default, or ``'blend'``).
    method : {'auto', 'blend', 'atomic', 'sort'}
        Technique (module docstring).

    Attributes
    ----------
    weights_buffer : moderngl.Buffer
        std430 ``vec4 w[n]`` (rgb = weight, a = 0), float32; written by :meth:`run`.
    method : str
        The technique in use.
    total_power : (3,) float64
        ``radiance * solid_angle`` summed over the light map (float64, CPU).
    """

    def __init__(self, ctx, directions, hemisphere, cells, method: str = "auto"):
        hemisphere = check_hemisphere(hemisphere)
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        if cells.hemisphere != hemisphere:
            raise ValueError(f"cells were baked for hemisphere {cells.hemisphere!r}, not {hemisphere!r}")
        if cells.directions.shape != d.shape or not np.allclose(cells.directions, d, rtol=0, atol=1e-12):
            raise ValueError("cells were baked for other directions")
        self.sparse = hasattr(cells, "slots")  # a WeightTexture (smooth weighting)
        if self.sparse and method not in ("auto", "blend", "sort"):
            raise ValueError(f"a weight texture ({cells.scheme}) integrates with method 'sort' or 'blend', not {method!r}")
        method = AUTO_METHOD if method == "auto" else method
        if method not in METHODS:
            raise ValueError(f"method must be 'auto' or one of {METHODS}, not {method!r}")
        if method == "atomic" and "GL_NV_shader_atomic_float" not in ctx.extensions:
            raise ValueError("method 'atomic' needs GL_NV_shader_atomic_float")
        self.ctx = ctx
        self.method = method
        self.n = int(d.shape[0])
        self.hemisphere = hemisphere
        self.cells = cells
        if self.sparse:
            self._defines = {"N_LIGHTS": self.n, "CELL_RES": int(cells.res), "SLOTS": int(cells.slots)}
        else:
            self._defines = {"N_LIGHTS": self.n, "CELL_RES": int(cells.res), "CELL_K": int(cells.k)}
        if hemisphere == "upper":
            self._defines["HEMI_UPPER"] = 1
        elif hemisphere.axis is not None:
            self._defines["HEMI_AXIS"] = 1
        self._max_ssbo = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or (1 << 27))
        self._lights = ctx.buffer(np.ascontiguousarray(cells.directions, dtype=np.float64).tobytes())
        if self.sparse:
            self._cand = ctx.buffer(np.ascontiguousarray(cells.index, dtype=np.int32).tobytes())
            self._slot_weights = ctx.buffer(np.ascontiguousarray(cells.weight, dtype=np.float32).tobytes())
            self._program = "integrate_sparse.glsl"
            self._per_texel = int(cells.slots)
        else:
            cand = np.ascontiguousarray(cells.candidates, dtype=np.int32)
            self._cand = ctx.buffer(cand.tobytes())
            self._slot_weights = None
            self._program = "integrate_blend.glsl"
            self._per_texel = 1
        self.weights_buffer = ctx.buffer(reserve=16 * self.n)
        self._stats = ctx.buffer(reserve=32)
        self._objects: list = []  # per-light-map objects
        self.m = 0
        self.total_power = np.zeros(3)
        self._ran = False

    # ------------------------------------------------------------------ light map
    def set_lightmap(self, lm) -> None:
        """Upload a light map: texel directions (float64) and radiance x solid angle (float32).

        Parameters
        ----------
        lm : ffls.lightmaps.lightmap.LightMap or tuple
            A light map of any layout (its ``samples()``), or ``(dirs (M, 3), radiance (M, 3),
            solid_angle (M,))``. The product ``radiance * solid_angle`` is formed in float64
            and rounded once to float32.
        """
        dirs, rad, sa = lm.samples() if hasattr(lm, "samples") else lm
        dirs = np.ascontiguousarray(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
        power = np.asarray(rad, dtype=np.float64).reshape(-1, 3) * np.asarray(sa, dtype=np.float64).reshape(-1, 1)
        if not np.all(np.isfinite(power)) or not np.all(np.isfinite(dirs)):
            raise ValueError("light map has NaN/Inf radiance, solid angles or directions")
        m = dirs.shape[0]
        if m == 0:
            raise ValueError("light map has no valid texels")
        if 24 * m > self._max_ssbo or 16 * m > self._max_ssbo:
            raise ValueError(f"light map of {m} texels exceeds the SSBO limit ({self._max_ssbo} bytes); "
                             "downsample it (LightMap.downsample)")
        self._release_map()
        self.m = m
        self.total_power = power.sum(axis=0)
        p4 = np.zeros((m, 4), dtype=np.float32)
        p4[:, :3] = power
        ctx = self.ctx
        self._tdir = ctx.buffer(dirs.tobytes())
        self._tpow = ctx.buffer(p4.tobytes())
        self._objects = [self._tdir, self._tpow]
        getattr(self, f"_setup_{self.method}")()

    def _release_map(self):
        for o in self._objects:
            release_gl(o)
        self._objects = []

    def _bind_common(self, prog, R):
        if "R" in prog:
            prog["R"].write(np.ascontiguousarray(np.asarray(R, dtype=np.float64).T).tobytes())
        if "n_texels" in prog:
            prog["n_texels"].value = self.m
        if "hemi_axis" in prog:
            prog["hemi_axis"].write(np.asarray(self.hemisphere.axis, dtype=np.float64).tobytes())
        self._tdir.bind_to_storage_buffer(1)
        self._tpow.bind_to_storage_buffer(2)
        self._lights.bind_to_storage_buffer(3)
        self._cand.bind_to_storage_buffer(4)
        if self._slot_weights is not None:
            self._slot_weights.bind_to_storage_buffer(5)

    # ------------------------------------------------------------------ (a) blend
    def _setup_blend(self):
        ctx = self.ctx
        nb = self.n + 1
        max_tex = int(ctx.info.get("GL_MAX_TEXTURE_SIZE") or 16384)
        max_vp = int((ctx.info.get("GL_MAX_VIEWPORT_DIMS") or (max_tex, max_tex))[1])
        max_h = min(max_tex, max_vp)
        tw = min(nb, max_h)
        th = -(-nb // tw)
        s_max = max(1, min(max_h // th, _PARTIAL_BUDGET // (tw * th)))
        s = max(1, min(-(-self.m // _CHAIN), s_max))
        self._per_slice = -(-self.m // s)
        self._slices = -(-self.m // self._per_slice)
        self._grid = (tw, th)
        self._tex = ctx.texture((tw, th * self._slices), 4, dtype="f4")
        self._tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self._fbo = ctx.framebuffer(color_attachments=[self._tex])
        self._vao = ctx.vertex_array(load_program(ctx, self._program, self._defines), [])
        self._objects += [self._fbo, self._tex, self._vao]
        if self.sparse:  # the weight-texture texel of every light-map texel (integrate_sparse_texels.glsl)
            self._wtexel = ctx.buffer(reserve=4 * self.m)
            self._objects.append(self._wtexel)

    def _run_blend(self, R):
        import moderngl

        ctx = self.ctx
        if self.sparse:  # rotation, hemisphere test and lookup once per texel, then one point per slot
            look = load_program(ctx, "integrate_sparse_texels.glsl", self._defines)
            self._bind_common(look, R)
            self._wtexel.bind_to_storage_buffer(7)
            _dispatch(look, -(-self.m // _LOCAL))
        prog = load_program(ctx, self._program, self._defines)
        self._bind_common(prog, R)
        prog["texels_per_slice"].value = self._per_slice
        prog["grid"].value = self._grid
        prog["target"].value = (float(self._tex.width), float(self._tex.height))
        prev_fbo = ctx.fbo
        self._fbo.use()
        self._fbo.viewport = (0, 0, self._tex.width, self._tex.height)
        self._fbo.clear(0.0, 0.0, 0.0, 0.0)
        # moderngl cannot read the blend state back; leave blending disabled and the
        # default blend function / equation, as a fresh context has them
        ctx.enable_only(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        ctx.blend_equation = moderngl.FUNC_ADD
        try:
            self._vao.render(moderngl.POINTS, vertices=self.m * self._per_texel)
        finally:
            ctx.blend_func = moderngl.DEFAULT_BLENDING
            ctx.blend_equation = moderngl.FUNC_ADD
            ctx.disable(moderngl.BLEND)
            # leave our framebuffer unbound: moderngl re-binds the current one whenever it
            # creates a framebuffer, which fails once ours is released
            (prev_fbo if prev_fbo is not None else default_framebuffer(ctx)).use()
        red = load_program(ctx, "integrate_reduce.glsl", {**self._defines, "SOURCE_TEXTURE": 1})
        self._tex.use(0)
        red["partials"].value = 0
        red["grid"].value = self._grid
        red["n_slices"].value = self._slices
        self.weights_buffer.bind_to_storage_buffer(0)
        self._stats.bind_to_storage_buffer(6)
        _dispatch(red, self.n + 1)

    # ------------------------------------------------------------------ (b) atomic
    def _setup_atomic(self):
        ctx = self.ctx
        nb = self.n + 1
        # moderngl does not report GL_MAX_COMPUTE_SHARED_MEMORY_SIZE; 32 KiB is GL 4.3's minimum
        shared = int(ctx.info.get("GL_MAX_COMPUTE_SHARED_MEMORY_SIZE") or 32768)
        self._global_bins = 12 * nb > shared
        g_max = max(1, _PARTIAL_BUDGET // nb)
        g = max(1, min(-(-self.m // _CHAIN), g_max))
        self._chunk = -(-self.m // g)
        self._groups = -(-self.m // self._chunk)
        self._partial = ctx.buffer(reserve=16 * nb * self._groups)
        self._objects.append(self._partial)
        if self._global_bins:
            self._defines_atomic = {**self._defines, "GLOBAL_BINS": 1}
        else:
            self._defines_atomic = dict(self._defines)

    def _run_atomic(self, R):
        ctx = self.ctx
        prog = load_program(ctx, "integrate_atomic.glsl", self._defines_atomic)
        self._bind_common(prog, R)
        prog["chunk"].value = self._chunk
        if self._global_bins:
            self._partial.clear()
        self._stats.clear()
        self._partial.bind_to_storage_buffer(5)
        self._stats.bind_to_storage_buffer(6)
        _dispatch(prog, self._groups)
        red = load_program(ctx, "integrate_reduce.glsl", self._defines)
        red["n_slices"].value = self._groups
        self.weights_buffer.bind_to_storage_buffer(0)
        _dispatch(red, self.n + 1)

    # ------------------------------------------------------------------ (c) sort
    def _setup_sort(self):
        ctx = self.ctx
        items = self.m * self._per_texel
        # a stable sort: the order within a cell is texel order whatever the number of blocks
        self._blocks = int(min(_SORT_BLOCKS, max(8, -(-items // _SORT_PER_BLOCK))))
        # a cell's segment is summed in chunks of _SEG_CHUNK items (integrate_segment_sum.glsl:
        # llvmpipe cuts an invocation's loops at 65535 iterations)
        self._seg_chunks = max(1, -(-items // _SEG_CHUNK))
        self._sort_defines = {"N_LIGHTS": self.n, "N_BLOCKS": self._blocks, "N_CHUNKS": self._seg_chunks,
                              "SEG_CHUNK": _SEG_CHUNK}
        bins = self.n + (2 if self.sparse else 1)  # + the void bin of padded slots
        self._cell_ids = ctx.buffer(reserve=4 * items)
        self._counts = ctx.buffer(reserve=4 * bins * self._blocks)
        self._sorted = ctx.buffer(reserve=16 * items)
        self._seg_partial = ctx.buffer(reserve=16 * (self.n + 1) * self._seg_chunks)
        self._objects += [self._cell_ids, self._counts, self._sorted, self._seg_partial]
        if self.sparse:
            if 16 * items > self._max_ssbo:
                raise ValueError(f"light map of {self.m} texels x {self._per_texel} slots exceeds the SSBO limit; "
                                 "downsample it (LightMap.downsample)")
            self._item_power = ctx.buffer(reserve=16 * items)
            self._objects.append(self._item_power)

    def _run_sort(self, R):
        ctx = self.ctx
        items = self.m * self._per_texel
        bins = self.n + (2 if self.sparse else 1)
        if self.sparse:
            ids = load_program(ctx, "integrate_sparse_items.glsl", self._defines)
            self._bind_common(ids, R)
            self._cand.bind_to_storage_buffer(3)
            self._slot_weights.bind_to_storage_buffer(4)
            self._cell_ids.bind_to_storage_buffer(5)
            self._item_power.bind_to_storage_buffer(9)
            _dispatch(ids, -(-self.m // _LOCAL))
            power = self._item_power
        else:
            ids = load_program(ctx, "integrate_cell_ids.glsl", self._defines)
            self._bind_common(ids, R)
            self._cell_ids.bind_to_storage_buffer(5)
            _dispatch(ids, -(-self.m // _LOCAL))
            power = self._tpow
        self._counts.clear()
        self._counts.bind_to_storage_buffer(7)
        self._sorted.bind_to_storage_buffer(8)
        groups = -(-self._blocks // 8)
        hist = load_program(ctx, "integrate_sort.glsl", {**self._sort_defines, "HISTOGRAM": 1})
        hist["n_texels"].value = items
        _dispatch(hist, groups)
        scan = load_program(ctx, "integrate_sort.glsl", {**self._sort_defines, "SCAN": 1})
        scan["n_counts"].value = bins * self._blocks
        _dispatch(scan, 1)
        scat = load_program(ctx, "integrate_sort.glsl", {**self._sort_defines, "SCATTER": 1})
        scat["n_texels"].value = items
        power.bind_to_storage_buffer(2)
        _dispatch(scat, groups)
        self._seg_partial.bind_to_storage_buffer(10)
        part = load_program(ctx, "integrate_segment_sum.glsl", {**self._sort_defines, "PARTIAL": 1})
        _dispatch(part, -(-((self.n + 1) * self._seg_chunks) // _LOCAL))  # one invocation per (cell, chunk)
        seg = load_program(ctx, "integrate_segment_sum.glsl", self._sort_defines)
        self.weights_buffer.bind_to_storage_buffer(0)
        self._stats.bind_to_storage_buffer(6)
        _dispatch(seg, -(-(self.n + 1) // _LOCAL))  # one invocation per cell (and the dropped one)

    # ------------------------------------------------------------------ public
    def run(self, R=None):
        """Integrate the light map rotated by ``R`` into :attr:`weights_buffer`.

        Parameters
        ----------
        R : (3, 3) array_like, optional
            Light-map rotation (content at ``d`` moves to ``R d``); identity by default.

        Returns
        -------
        moderngl.Buffer
            :attr:`weights_buffer` (std430 ``vec4 w[n]``, float32, rgb used).
        """
        if self.m == 0:
            raise RuntimeError("call set_lightmap() before run()")
        R = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
        if not is_rotation(R):
            raise ValueError("R must be a 3x3 rotation matrix")
        getattr(self, f"_run_{self.method}")(R)
        self._ran = True
        return self.weights_buffer

    def read_weights(self) -> np.ndarray:
        """The weights of the last :meth:`run`, (n, 3) float32."""
        return np.frombuffer(self.weights_buffer.read(), dtype=np.float32).reshape(self.n, 4)[:, :3].copy()

    def _read_stats(self):
        raw = self._stats.read()
        return np.frombuffer(raw[:16], dtype=np.float32)[:3].copy(), int(np.frombuffer(raw[16:20], dtype=np.uint32)[0])

    @property
    def dropped_texels(self) -> int:
        """Texels of the last :meth:`run` given to no light (counted on the GPU)."""
        return self._read_stats()[1]

    @property
    def dropped_power(self) -> np.ndarray:
        """Their ``radiance * solid_angle`` sum, (3,) float32."""
        return self._read_stats()[0]

    def release(self) -> None:
        """Release every GL object this integrator made (programs stay in the loader's cache)."""
        self._release_map()
        for o in (self._lights, self._cand, self._slot_weights, self.weights_buffer, self._stats):
            release_gl(o)
        self.m = 0
