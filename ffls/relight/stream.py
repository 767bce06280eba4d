"""Relighting and compression streamed from the chunked store, in bounded memory.

The store (:mod:`ffls.store.field`) holds a capture as chunks of one tile x all photos. Here:

* :func:`relight_field` is the weighted sum ``sum_i w_i B_i`` (Masselus, Dutre, Anrys 2002,
  section 6) one chunk at a time: :func:`ffls.relight.cpu.relight_fast` on each tile, written
  into the output image. Memory is the output image plus one chunk's working set, whatever
  the number of photos and their size; :func:`check_budget` refuses a ``--memory`` below that,
  before anything is read. The result equals the in-memory relighting within the float16
  rounding of the stored photos (relative 2**-11 of each term).
* :func:`compress_field` is the compressed basis (:mod:`ffls.relight.compress`: mean + K
  eigen-images per channel) out of core, in two streaming passes over the chunks. Because the
  number of photos ``n`` is small next to the number of pixels, the randomised sketch of
  Halko et al. is not needed: pass 1 accumulates, per channel, the exact ``n x n`` Gram matrix
  ``B B^T`` in float64; the centred Gram matrix ``C B B^T C`` (``C = I - 11^T/n``) gives the
  loadings ``U`` and singular values by an eigendecomposition; pass 2 writes the layers
  ``[mean, E_1..E_K] = [1^T/n; U^T] B`` tile by tile into the store (float16, checked scale),
  with their pyramid. Both passes are lists of independent tasks that a runner maps
  (:class:`ffls.store.ingest.SerialRunner`, or a Dask cluster through
  :class:`ffls.cluster.DaskRunner`).
* :func:`load_compressed_level` reads one pyramid level of a stored compressed basis as a
  :class:`ffls.relight.compress.CompressedBasis` for the GPU engine (the viewer shows the level
  that fits).
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from ffls.errors import InputError
from ffls.relight.compress import CompressedBasis, rank_range
from ffls.relight.cpu import relight_fast
from ffls.relight.inputs import WeightsInputs
from ffls.store.field import compressor, read_json, tile_slices, write_json_atomic
from ffls.store.float16 import choose_scale, to_float16
from ffls.store.ingest import SerialRunner, build_pyramid

__all__ = ["MAX_MEMORY", "parse_memory", "default_memory", "tile_working_set", "check_budget", "relight_field",
           "StoredCompression", "compress_field", "load_or_compress_field", "relight_compressed_field",
           "load_compressed_level", "compression_key", "gram_tiles", "layer_tiles", "StreamedRelighter", "in_memory_bytes", "open_streamed"]


# ----------------------------------------------------------------------------- memory
_UNITS = {"": 1, "b": 1, "k": 2 ** 10, "m": 2 ** 20, "g": 2 ** 30, "t": 2 ** 40}


#: The largest memory budget :func:`parse_memory` takes (1 EiB): a larger one is a typo.
MAX_MEMORY = 2 ** 60


def parse_memory(text) -> int:
    """``'1G'``, ``'512M'``, ``'800k'``, ``'123456'`` (bytes; binary units, an optional ``iB``/``B``) -> bytes.

    Raises
    ------
    ValueError
        Not a positive size.
    """
    t = str(text).strip().lower().removesuffix("ib").removesuffix("b")
    unit = t[-1:] if t[-1:] in _UNITS and not t[-1:].isdigit() else ""
    num = t[: len(t) - len(unit)]
    try:
        v = float(num)
    except ValueError:
        raise ValueError(f"expected a size such as 1G, 512M or 800K, not {text!r}") from None
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"expected a positive size such as 1G, not {text!r}")
    size = v * _UNITS[unit]
    if not size <= MAX_MEMORY:  # (an overflow to inf too)
        raise ValueError(f"{text!r} is more than any machine has (at most {MAX_MEMORY // 2 ** 50} PiB)")
    return int(size)


def default_memory(available: int) -> int:
    """The default budget: half of the memory available now (``MemAvailable``), at least 256 MiB."""
    return int(max(available // 2, 256 * 2 ** 20))


def tile_working_set(n_stored: int, n_used: int, tile: int) -> int:
    """Bytes one chunk costs while it is summed: the stored chunk (compressed and decoded), its
    used rows in float32 and the sum's temporaries."""
    px = tile * tile
    return int(px * 3 * (2 * 2 * n_stored + 2 * n_used + 4 * n_used) + px * 3 * 4 * 12)


def check_budget(budget: int, shape, n_stored: int, n_used: int, tile: int, output_copies: int = 3,
                 baseline: int = 160 * 2 ** 20, flag: str = "--memory", path=None) -> dict:
    """Refuse a memory budget below what a streamed relighting needs.

    The need is ``baseline`` (the interpreter and its libraries), ``output_copies`` float32
    images of ``shape`` (the result, and the tone map's or the writer's copies) and one chunk's
    :func:`tile_working_set`.

    Returns
    -------
    dict
        ``need``, ``output``, ``tile`` bytes.

    Raises
    ------
    InputError
        One line naming ``flag``, the need and its parts.
    """
    H, W = shape
    out = int(output_copies * H * W * 3 * 4)
    tw = tile_working_set(n_stored, n_used, tile)
    need = baseline + out + tw
    if need > budget:
        raise InputError(f"{flag} {budget / 2 ** 20:.0f}M is too small: a {W}x{H} relighting needs about "
                         f"{need / 2 ** 20:.0f}M ({baseline / 2 ** 20:.0f}M interpreter, {out / 2 ** 20:.0f}M "
                         f"output images, {tw / 2 ** 20:.0f}M per {tile}x{tile} tile of {n_stored} photos; "
                         f"'ffls ingest --tile' makes smaller tiles)", path)
    return {"need": need, "output": out, "tile": tw}


def _bar(total: int, desc: str, progress: bool):
    import os
    import sys

    from tqdm import tqdm

    disable = not progress or not sys.stderr.isatty() or bool(os.environ.get("CI"))
    return tqdm(total=total, desc=desc, unit="tile", disable=disable, leave=False)


# ----------------------------------------------------------------------------- relighting
def relight_field(field, rows, weights, level: int = 0, progress: bool = True, out=None) -> np.ndarray:
    """``sum_i weights[i] * B_rows[i]`` streamed from the store, one chunk at a time.

    Parameters
    ----------
    field : ffls.store.field.ReflectanceField
    rows : (k,) int array
        Store rows of the lights, in the order of ``weights`` (:meth:`ReflectanceField.rows_of`).
    weights : (k, 3) array_like
    level : int
        Pyramid level (0 = full resolution).
    progress : bool
    out : (h, w, 3) float32 array, optional
        Written in place (e.g. a memory map); a new array by default.

    Returns
    -------
    (h, w, 3) float32
        Equal to :func:`ffls.relight.cpu.relight_fast` of the in-memory photos within the float16
        rounding of the stored values.
    """
    rows = np.asarray(rows, dtype=np.intp)
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (len(rows), 3):
        raise ValueError(f"weights must be ({len(rows)}, 3), not {w.shape}")
    h, wd = field.levels[level]
    out = np.empty((h, wd, 3), dtype=np.float32) if out is None else out
    ws = w / field.scale  # the stored values are radiance * scale
    arr = field.array(level)
    tiles = field.tiles(level)
    with _bar(len(tiles), "relight", progress) as bar:
        for ys, xs in tiles:
            block = arr[:, ys, xs, :]
            sel = block if len(rows) == block.shape[0] and np.array_equal(rows, np.arange(len(rows))) else block[rows]
            del block
            out[ys, xs] = relight_fast(ws, sel.astype(np.float32))
            bar.update(1)
    return out


# ----------------------------------------------------------------------------- compression
def compression_key(names, rank: int) -> str:
    """Name of a stored compressed basis: the rank and a digest of the photos it was made from."""
    digest = hashlib.sha1("\n".join(names).encode()).hexdigest()[:10]
    return f"rank{int(rank)}-{digest}"


@dataclass
class StoredCompression:
    """A compressed basis kept in the store: layers ``[M, E_1..E_K]`` chunked like the basis.

    Attributes
    ----------
    field : ReflectanceField
    key : str
        ``compressed/KEY`` in the store (:func:`compression_key`).
    loadings : (n, K, 3) float32
    singular_values : (K, 3) float64
    scale : float
        Stored layer value = layer * scale.
    levels : list of (h, w)
    info : dict
    """

    field: object
    key: str
    loadings: np.ndarray
    singular_values: np.ndarray
    scale: float
    levels: list
    info: dict

    @property
    def rank(self) -> int:
        return int(self.loadings.shape[1])

    def array(self, level: int = 0):
        g = self.field.group()
        return g[f"compressed/{self.key}"] if level == 0 else g[f"compressed/{self.key}/levels/{level}"]

    def layer_coefficients(self, weights) -> np.ndarray:
        """``(K + 1, 3)`` float64: ``sum_i w_i`` for the mean and ``U^T w`` for the eigen-images."""
        cb = CompressedBasis(np.zeros((1, 1, 3), np.float32), np.zeros((self.rank, 1, 1, 3), np.float32),
                             self.loadings, self.singular_values)
        return cb.layer_coefficients(weights)


def gram_tiles(path, rows, tiles) -> tuple[np.ndarray, np.ndarray]:
    """Pass 1 over some tiles: per channel ``B B^T`` ``(3, k, k)`` float64 and the largest magnitude (stored units)."""
    import zarr

    arr = zarr.open_array(str(Path(path) / "basis"), mode="r")
    k = len(rows)
    G = np.zeros((3, k, k))
    mx = 0.0
    for ys, xs in tiles:
        b = arr[:, ys, xs, :][np.asarray(rows)]
        mx = max(mx, float(np.max(np.abs(b))) if b.size else 0.0)
        for c in range(3):
            x = b[..., c].reshape(k, -1).astype(np.float64)
            G[c] += x @ x.T
    return G, mx


def layer_tiles(path, rows, proj, scale: float, max_abs: float, key: str, tiles) -> None:
    """Pass 2 over some tiles: layers ``proj[c] @ B_c`` ``(K + 1, ...)``, float16 at ``scale``, into ``compressed/KEY``."""
    import zarr

    p = Path(path)
    arr = zarr.open_array(str(p / "basis"), mode="r")
    dst = zarr.open_array(str(p / "compressed" / key), mode="r+")
    k = len(rows)
    for ys, xs in tiles:
        b = arr[:, ys, xs, :][np.asarray(rows)].astype(np.float32)
        h, w = b.shape[1:3]
        lay = np.empty((proj.shape[2], h, w, 3), dtype=np.float32)
        for c in range(3):
            lay[..., c] = (proj[c].T.astype(np.float32) @ b[..., c].reshape(k, -1)).reshape(-1, h, w)
        half, _ = to_float16(lay, scale=scale, path=p, max_abs=max_abs)
        dst[:, ys, xs, :] = half


def _groups(items: list, n_groups: int) -> list[list]:
    n_groups = max(1, min(int(n_groups), len(items)))
    return [items[g::n_groups] for g in range(n_groups)]


def compress_field(field, names, rank: int, runner=None, progress: bool = True) -> StoredCompression:
    """The rank-``rank`` compressed basis of the photos ``names``, computed out of core and kept in the store.

    Per channel (``'per_channel'`` mode of :func:`ffls.relight.compress.compress_basis`): the
    exact eigendecomposition of the centred Gram matrix (module docstring). The result spans the
    same subspace as the in-memory randomised SVD up to its approximation error, and its
    reconstruction error is the optimal one for the rank.

    Parameters
    ----------
    field : ReflectanceField
    names : list of str
        The photos (lights) in the order of the loadings.
    rank : int
        1 <= K <= n - 1.
    runner : optional
        Maps the tasks (default :class:`ffls.store.ingest.SerialRunner`).

    Returns
    -------
    StoredCompression
    """
    import zarr

    runner = SerialRunner(progress) if runner is None else runner
    rows = field.rows_of(names)
    n = len(rows)
    lo, hi = rank_range(n)
    if not lo <= rank <= hi:
        raise ValueError(f"rank must be in [{lo}, {hi}] for {n} lights, not {rank}")
    t0 = time.perf_counter()
    tiles = field.tiles(0)
    n_groups = 4 * int(getattr(runner, "n_workers", 1))
    parts = runner.map(partial(gram_tiles, field.path, rows), _groups(tiles, n_groups), desc="compress: pass 1")
    G = sum(p[0] for p in parts)
    max_stored = max(p[1] for p in parts)
    C = np.eye(n) - 1.0 / n
    U = np.empty((n, rank, 3))
    s = np.empty((rank, 3))
    for c in range(3):
        evals, evecs = np.linalg.eigh(C @ G[c] @ C)
        order = np.argsort(evals)[::-1][:rank]
        U[:, :, c] = evecs[:, order]
        s[:, c] = np.sqrt(np.maximum(evals[order], 0.0))
    # layers in stored units: [1^T / n; U^T] B_stored; radiance = stored / field.scale
    proj = np.empty((3, n, rank + 1))
    proj[:, :, 0] = 1.0 / n
    proj[:, :, 1:] = np.moveaxis(U, 2, 0)
    proj /= field.scale
    bound = np.sqrt(n) * max_stored / field.scale  # |U_k^T b| <= |b|_2 <= sqrt(n) max|b|
    scale = choose_scale(bound)
    key = compression_key(names, rank)
    H, W = field.shape
    g = zarr.open_group(str(field.path), mode="r+")
    g.create_array(name=f"compressed/{key}", shape=(rank + 1, H, W, 3), chunks=(rank + 1, field.tile, field.tile, 3),
                   dtype="float16", compressors=compressor(), fill_value=0, overwrite=True)
    runner.map(partial(layer_tiles, field.path, rows, proj, scale, bound, key), _groups(tiles, n_groups),
               desc="compress: pass 2")
    shapes = build_pyramid(field.path, f"compressed/{key}", rank + 1, (H, W), field.tile, runner,
                           max(max(field.levels[-1]), 1))  # the photos' levels
    info = {"mode": "per_channel", "method": "gram", "seconds": time.perf_counter() - t0, "n": n, "H": H, "W": W}
    write_json_atomic(field.path / "compressed" / f"{key}.json",
                      {"key": key, "names": list(names), "rank": rank, "scale": scale, "levels": [list(x) for x in shapes],
                       "loadings": U.astype(np.float32).tolist(), "singular_values": (s / field.scale).tolist(),
                       "info": info})
    return StoredCompression(field, key, U.astype(np.float32), s / field.scale, scale, shapes, info)


def load_or_compress_field(field, names, rank: int, runner=None, progress: bool = True) -> StoredCompression:
    """The stored compression of ``names`` at ``rank`` (its metadata file is written last), else a new one."""
    key = compression_key(names, rank)
    doc = read_json(Path(field.path) / "compressed" / f"{key}.json")
    if doc is not None and doc.get("names") == list(names) and int(doc.get("rank", -1)) == int(rank):
        return StoredCompression(field, key, np.asarray(doc["loadings"], dtype=np.float32),
                                 np.asarray(doc["singular_values"]), float(doc["scale"]),
                                 [tuple(x) for x in doc["levels"]], dict(doc.get("info", {})))
    return compress_field(field, names, rank, runner=runner, progress=progress)


def relight_compressed_field(sc: StoredCompression, weights, level: int = 0, progress: bool = True) -> np.ndarray:
    """The relit image of a stored compressed basis, streamed: ``sum_k c_k L_k`` per tile, float64 sums.

    Returns
    -------
    (h, w, 3) float32
    """
    c = sc.layer_coefficients(weights) / sc.scale
    h, w = sc.levels[level]
    out = np.empty((h, w, 3), dtype=np.float32)
    arr = sc.array(level)
    tiles = tile_slices(h, w, sc.field.tile)
    with _bar(len(tiles), "relight (compressed)", progress) as bar:
        for ys, xs in tiles:
            lay = arr[:, ys, xs, :].astype(np.float64)
            out[ys, xs] = np.einsum("khwc,kc->hwc", lay, c)
            bar.update(1)
    return out


def load_compressed_level(sc: StoredCompression, level: int) -> CompressedBasis:
    """Pyramid level ``level`` of a stored compression as an in-memory :class:`CompressedBasis` (float32).

    Downsampling is linear, so this is the compression of the downsampled photos' approximation:
    the same loadings, smaller layers.
    """
    h, w = sc.levels[level]
    arr = sc.array(level)
    lay = np.empty((sc.rank + 1, h, w, 3), dtype=np.float32)
    for ys, xs in tile_slices(h, w, sc.field.tile):
        lay[:, ys, xs] = arr[:, ys, xs, :].astype(np.float32)
    lay *= np.float32(1.0 / sc.scale)
    return CompressedBasis(lay[0], lay[1:], sc.loadings, sc.singular_values, "per_channel",
                           {**sc.info, "level": level})



class StreamedRelighter(WeightsInputs):
    """Relighting streamed from the store, with the interface of :class:`ffls.relight.cpu.CpuRelighter`.

    Pass 1 is :func:`ffls.weights.weighting.integrate` under the ``weighting`` scheme, on the map
    at ``map_res`` rows (:func:`ffls.relight.quality.integration_map`), as the CPU relighter; pass 2
    :func:`relight_field` (or, with a compression, :func:`relight_compressed_field`), the
    display image :func:`ffls.display.tonemap.tonemap` of the relit image.

    Parameters
    ----------
    field : ffls.store.field.ReflectanceField
    names : list of str
        The photos of the lights used, in the order of ``directions``.
    directions : (k, 3) float
    hemisphere : Hemisphere
    compression : StoredCompression, optional
    cell_res, cell_k, cell_max_res : as :class:`ffls.relight.cpu.CpuRelighter`
    level : int
        Pyramid level relit (0 = full resolution).
    progress : bool
    weighting : str
        Weighting scheme of pass 1 (:data:`ffls.weights.weighting.SCHEMES`).
    map_res : int, optional
        Height of the lat-long map pass 1 integrates; None = as given.
    """

    def __init__(self, field, names, directions, hemisphere="upper", *, compression=None, cell_res: int | None = 256,
                 cell_k: int = 8, cell_max_res: int | None = None, level: int = 0, progress: bool = True,
                 weighting: str = "voronoi", map_res: int | None = None):
        from ffls.conventions import check_hemisphere
        from ffls.weights.voronoi import bake_cells

        self.field = field
        self.rows = field.rows_of(names)
        self.directions = np.asarray(directions, dtype=np.float64)
        if self.directions.shape != (len(self.rows), 3):
            raise InputError(f"{len(self.directions)} light directions for {len(self.rows)} photos", field.path)
        self.hemisphere = check_hemisphere(hemisphere)
        self.compression = compression
        self.level = int(level)
        self.progress = progress
        self.weighting = str(weighting)
        if self.weighting == "kriging":  # its kernel is learnt from photos in memory (KernelLearner)
            raise InputError("--weighting kriging learns its kernel from the photos in memory and is not "
                             "available tile by tile from a store (--memory); choose another --weighting", field.path)
        self.map_res = None if map_res is None else int(map_res)
        self.cells = None if cell_res is None or self.weighting != "voronoi" else bake_cells(
            self.directions, self.hemisphere, res=cell_res, k=cell_k, max_res=cell_max_res)
        self.last_weights = None
        self._init_inputs()

    def set_lightmap(self, lm) -> None:
        self._lightmap = lm
        self._weights = None

    def _pass1(self) -> np.ndarray:  # as the in-memory relighters (the scheme and the map height)
        from ffls.relight.quality import integration_map
        from ffls.weights.weighting import integrate

        self.last_weights = integrate(integration_map(self._lightmap, self.map_res), self.directions,
                                      self._rotation, self.hemisphere, self.weighting, cells=self.cells)
        return self.last_weights.weights

    def _pass2(self, weights) -> np.ndarray:
        if self.compression is not None:
            return relight_compressed_field(self.compression, weights, self.level, self.progress)
        return relight_field(self.field, self.rows, weights, self.level, self.progress)

    @property
    def size(self) -> tuple[int, int]:
        h, w = self.field.levels[self.level]
        return int(w), int(h)

    @property
    def n_lights(self) -> int:
        return len(self.rows)

    def release(self) -> None:
        self._hdr = self._display = self._weights = self.cells = None


def in_memory_bytes(n_lights: int, shape, output_copies: int = 3) -> int:
    """Bytes the in-memory path needs: the float32 photos, one photo being decoded, the output images."""
    H, W = shape
    return int((n_lights + 2 + output_copies) * H * W * 3 * 4)


def open_streamed(capture, lights, memory: int, *, store=None, runner=None, rank: int | None = None,
                  cell_res: int | None = 256, cell_max_res: int | None = None, force: bool = False,
                  progress: bool = True, output_copies: int = 3, gpu_budget: int | None = None, quality=None):
    """A :class:`StreamedRelighter` when the photos would not fit ``memory`` (or with ``force``); else None.

    The store is built on first use (:func:`ffls.store.ingest.ensure_field`, with ``runner``);
    a stale one is rebuilt, and the returned note says why.

    Parameters
    ----------
    capture, lights : as :func:`ffls.relight.basis.accepted_basis`
    memory : int
        The budget, bytes (checked: :func:`check_budget`).
    store : path-like, optional
        Default ``CAPTURE/field.zarr``.
    rank : int, optional
        Relight a compressed basis of this rank (computed out of core and kept in the store).
    gpu_budget : int, optional
        Bytes the GPU may hold; photos over it (RGBA16F layers) are streamed too.
    quality : ffls.relight.quality.Quality, optional
        The quality knobs: its rank (when ``rank`` is None), weighting scheme and pass-1 map
        height apply to the streamed relighter; a basis subset or the near-light correction,
        which need the photos in memory, is refused with one line when the capture must stream.

    Returns
    -------
    relighter : StreamedRelighter or None
        None: the in-memory path fits (the caller uses it).
    notes : list of str
        One line per thing worth saying (a rebuilt store, the budget used).
    """
    from ffls.store.field import choose_tile, default_store_path, field_status
    from ffls.store.ingest import ensure_field

    idx, dirs = lights.accepted()
    if not len(idx):
        raise InputError("no light has status ok", getattr(lights, "path", None) or capture.folder)
    if rank is None and quality is not None:
        rank = quality.rank
    names = [lights.image_names[i] for i in idx]
    path = default_store_path(capture) if store is None else Path(store)
    status, _ = field_status(capture, path)
    shape = None
    if capture.image_size is not None:
        shape = (int(capture.image_size[1]), int(capture.image_size[0]))
    else:
        from ffls.io.images import read_image

        shape = tuple(read_image(capture.image_paths[0]).pixels.shape[:2])
    layers = len(idx) if rank is None else int(rank) + 1
    too_big_for_gpu = gpu_budget is not None and layers * shape[0] * shape[1] * 8 > gpu_budget
    if not force and not too_big_for_gpu and in_memory_bytes(len(idx), shape, output_copies) <= memory:
        return None, []
    if quality is not None and (quality.basis_subset is not None or quality.near_correction):
        flag = "--basis-subset" if quality.basis_subset is not None else "--near-correction"
        raise InputError(f"{flag} needs the photos in memory, and this capture streams from its store "
                         f"(it does not fit --memory {memory / 2 ** 20:.0f}M, or --tiles was given)", capture.folder)
    tile = choose_tile(len(capture.image_names))
    if status != "ok":  # refuse a budget too small before the (long) ingest
        check_budget(memory, shape, len(capture.image_names), len(idx), tile, output_copies)
    rep = ensure_field(capture, path, runner=runner, progress=progress)
    field = rep.field
    need = check_budget(memory, field.shape, field.n, len(idx), field.tile, output_copies)
    notes = [rep.note,
             f"streamed from {path} in {field.tile}x{field.tile} tiles of {field.n} photos "
             f"(about {need['need'] / 2 ** 20:.0f}M of the {memory / 2 ** 20:.0f}M allowed)"]
    comp = None if rank is None else load_or_compress_field(field, names, int(rank), runner=runner, progress=progress)
    q = {} if quality is None else {"weighting": quality.weighting, "map_res": quality.map_res}
    r = StreamedRelighter(field, names, dirs, capture.hemisphere, compression=comp, cell_res=cell_res,
                          cell_max_res=cell_max_res, progress=progress, **q)
    return r, [x for x in notes if x]
