"""The GPU engine over a capture too large for memory or the GPU: pass 2 tile by tile from the store.

:class:`TiledEngine` has the interface of :class:`ffls.gpu.engine.Engine` (``set_lightmap``,
``set_rotation``, ``set_weights``, ``render``, ``read_hdr``, ``read_display``, ``read_weights``,
``release``). Pass 1 (:class:`ffls.gpu.integrate.CellIntegrator`) runs once for the whole
image; pass 2 runs per tile of the store (:mod:`ffls.store.field`): the tile's photos are read
(one chunk), uploaded as a small :class:`Engine`'s basis, summed with the pass-1 weights and
read back into the full-resolution result. With a compressed basis
(:class:`ffls.relight.stream.StoredCompression`) pass 2 is the streamed sum of its ``K + 1``
layers (:func:`ffls.relight.stream.relight_compressed_field`). The display image is the tone
curve of :func:`ffls.display.tonemap.tonemap` (the GLSL display pass is its twin).

Memory: the result image and one tile; GPU memory: one tile's basis.
"""
from __future__ import annotations

import numpy as np

from ffls.errors import InputError
from ffls.gpu.engine import Engine
from ffls.gpu.integrate import CellIntegrator
from ffls.relight.inputs import WeightsInputs
from ffls.relight.stream import relight_compressed_field

__all__ = ["TiledEngine", "engine_for_view"]


class TiledEngine(WeightsInputs):
    """GPU relighting of a stored capture, tile by tile.

    Parameters
    ----------
    ctx : moderngl.Context
    streamed : ffls.relight.stream.StreamedRelighter
        Gives the store, the rows and directions of the lights, the hemisphere and the compression.
    dtype : {'f16', 'f32'}
        GPU storage of each tile's basis.
    cell_res : int
        Resolution of the cell texture of pass 1 (``voronoi``).
    weighting : str, optional
        Weighting scheme of pass 1; default the streamed relighter's.
    weights_res : int, optional
        Resolution of a smooth scheme's weight texture (default
        :data:`ffls.weights.weighting.DEFAULT_TEXTURE_RES`).
    map_res : int, optional
        Height of the lat-long map pass 1 integrates; default the streamed relighter's.
    """

    def __init__(self, ctx, streamed, dtype: str = "f16", cell_res: int = 256, method: str = "auto",
                 weighting: str | None = None, weights_res: int | None = None, map_res: int | None = None):
        from ffls.weights.voronoi import bake_cells
        from ffls.weights.weighting import DEFAULT_TEXTURE_RES, bake_weights

        self.ctx = ctx
        self.streamed = streamed
        self.dtype = dtype
        self.method = method
        self.directions = streamed.directions
        self.hemisphere = streamed.hemisphere
        self.weighting = streamed.weighting if weighting is None else str(weighting)
        self.map_res = streamed.map_res if map_res is None else int(map_res)
        if self.weighting == "voronoi":
            table = bake_cells(self.directions, self.hemisphere, cell_res)
        else:  # the smooth schemes' weight texture, as the Engine's pass 1
            table = bake_weights(self.directions, self.weighting, self.hemisphere, weights_res or DEFAULT_TEXTURE_RES)
        self._integrator = CellIntegrator(ctx, self.directions, self.hemisphere, table)
        self._init_inputs()
        self.timings: dict = {}

    def set_lightmap(self, lm) -> None:
        from ffls.relight.quality import integration_map

        self._lightmap = lm
        self._integrator.set_lightmap(integration_map(lm, self.map_res))
        self._weights = None

    def _pass2(self, w) -> np.ndarray:
        s = self.streamed
        if s.compression is not None:
            return relight_compressed_field(s.compression, w, s.level, s.progress)
        f = s.field
        h, wd = f.levels[s.level]
        out = np.empty((h, wd, 3), dtype=np.float32)
        arr = f.array(s.level)
        for ys, xs in f.tiles(s.level):
            tile = f.read_tile(ys, xs, s.rows, s.level, arr=arr)
            eng = Engine(self.ctx, tile, self.directions, self.hemisphere, dtype=self.dtype, method=self.method)
            try:
                eng.set_weights(w)
                eng.render()
                out[ys, xs] = eng.read_hdr()
            finally:
                eng.release()
            del tile
        return out

    def _pass1(self) -> np.ndarray:
        self._integrator.run(self._rotation)
        return np.asarray(self._integrator.read_weights(), dtype=np.float64)[:, :3]

    @property
    def size(self) -> tuple[int, int]:
        return self.streamed.size

    @property
    def n_lights(self) -> int:
        return int(len(self.directions))

    @property
    def basis_info(self) -> dict:
        f = self.streamed.field
        return {"dtype": self.dtype, "tiles": len(f.tiles(self.streamed.level)), "tile": f.tile,
                "rank": None if self.streamed.compression is None else self.streamed.compression.rank}

    def release(self) -> None:
        if self._integrator is not None:
            self._integrator.release()
        self._integrator = None
        self._hdr = self._display = self._weights = None


def engine_for_view(ctx, capture, lights, memory: int, *, window=None, budget_bytes: int | None = None,
                    rank: int | None = None, quality=None, runner=None, progress: bool = False, **kw):
    """An :class:`Engine` of the resolution that fits: the photos themselves, or a level of the store's pyramid.

    When the accepted photos fit both the GPU budget (RGBA16F layers) and ``memory`` (float32 in
    host memory) the engine is :meth:`Engine.from_capture`, as before. Otherwise the store is
    built if needed (:func:`ffls.store.ingest.ensure_field`) and the level chosen by
    :func:`ffls.store.field.choose_level` (the finest that fits the budget and is not finer
    than ``window`` needs) is loaded; with ``rank`` the level of the stored compressed basis.

    Parameters
    ----------
    memory : int
        Host memory allowed, bytes (the viewer's default: half of ``MemAvailable``).
    quality : ffls.relight.quality.Quality, optional
        The quality knobs (:meth:`Engine.from_capture`); its ``rank`` is used when ``rank`` is None.
        From the store, the basis subset and the near-light correction are refused (they need the
        photos in memory); the rank, precision, weighting and texture sizes apply.

    Returns
    -------
    engine : Engine
    streamed : ffls.relight.stream.StreamedRelighter or None
        The full-resolution relighter of the store (None when the engine holds the photos
        themselves): screenshots and final renders use it, tile by tile, with the engine's weights.
    level : int
        The pyramid level shown (0 = full resolution).
    """
    from ffls.gpu.basis import DEFAULT_BUDGET
    from ffls.relight.stream import StreamedRelighter, load_compressed_level, load_or_compress_field
    from ffls.store.field import choose_level
    from ffls.store.ingest import ensure_field

    budget = DEFAULT_BUDGET if budget_bytes is None else int(budget_bytes)
    idx, dirs = lights.accepted()
    if capture.image_size is not None:
        H, W = int(capture.image_size[1]), int(capture.image_size[0])
    else:
        from ffls.io.images import read_image

        H, W = read_image(capture.image_paths[0]).pixels.shape[:2]
    if rank is None and quality is not None:
        rank = quality.rank
    layers = len(idx) if rank is None else int(rank) + 1
    mem = int(memory)
    if layers * H * W * 8 <= budget and (len(idx) + 2) * H * W * 12 <= mem:
        if rank is not None:
            kw["rank"] = rank
        return Engine.from_capture(ctx, capture, lights, quality=quality, **kw), None, 0
    kw.pop("basis", None)  # (the photos' basis, read already: the store's pyramid is shown instead)
    if quality is not None:
        if quality.basis_subset is not None or quality.near_correction:
            flag = "--basis-subset" if quality.basis_subset is not None else "--near-correction"
            raise InputError(f"{flag} needs the photos in memory; this capture is too large and is shown from "
                             "its store's pyramid (docs/scale.md)", capture.folder)
        kw.setdefault("dtype", quality.precision)
        kw.setdefault("map_res", quality.map_res)
        kw.setdefault("weighting", quality.weighting)
        if quality.cell_res is not None:
            kw.setdefault("cell_res" if quality.weighting == "voronoi" else "weights_res", quality.cell_res)
    field = ensure_field(capture, runner=runner, progress=progress).field
    names = [lights.image_names[i] for i in idx]
    comp = None if rank is None else load_or_compress_field(field, names, int(rank), runner=runner, progress=progress)
    level = choose_level(field.levels, layers, min(budget, mem // 2), window)
    streamed = StreamedRelighter(field, names, dirs, capture.hemisphere, compression=comp, progress=progress)
    h, w = field.levels[level]
    if comp is not None:
        cb = load_compressed_level(comp, level)
        shape_only = np.broadcast_to(np.zeros((), np.float32), (len(idx), h, w, 3))  # never read with a compression
        eng = Engine(ctx, shape_only, dirs, capture.hemisphere, compressed=cb, path=field.path, **kw)
    else:
        eng = Engine(ctx, field.read_level(level, streamed.rows), dirs, capture.hemisphere, path=field.path, **kw)
    return eng, streamed, level

