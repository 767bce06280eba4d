"""The chunked reflectance field on disk: a capture's linear photos as one Zarr v3 store.

A capture of ``n`` photos of ``H x W`` pixels is stored as one array ``basis`` of shape
``(n, H, W, 3)``, float16 with the capture's checked power-of-two scale
(:mod:`ffls.store.float16`), chunked as tiles of ``tile x tile`` pixels x *all* photos
(``(n, tile, tile, 3)``) and compressed (Blosc zstd, bit shuffle). One chunk is everything a
relighter needs for one tile of the output, so a relit image is a stream of chunks whatever the
capture's size (:mod:`ffls.relight.stream`).

Layout of ``CAPTURE/field.zarr`` (the default place, :data:`STORE_NAME`)::

    zarr.json                 the Zarr group
    basis/                    (n, H, W, 3) float16, chunks (n, tile, tile, 3); attrs: scale
    levels/1, levels/2, ...   the pyramid: level k is (n, ceil(H / 2^k), ceil(W / 2^k), 3), 2x2 means
    compressed/K/layers       a compressed basis of rank K: [mean, E_1..E_K], (K + 1, H, W, 3) float16
    compressed/K/levels/k     its pyramid (same halving)
    compressed/K.json         its loadings, singular values and scale (:mod:`ffls.relight.stream`)
    complete.json             the completion marker: written last, atomically (:data:`MARKER`)

While an ingest runs (:mod:`ffls.store.ingest`) the store also holds ``staging`` (one chunk per
photo tile, each photo with its own scale), ``progress/`` (one small file per photo staged) and
``plan.json``; they go once the marker is written.

Provenance: the marker records, per photo, its file name, size in bytes and modification time
(nanoseconds), and the capture's encoding (and a digest of its response table). A store whose
record differs from the capture's files now is *stale*: :func:`stale_reason` says, in one line,
which photo or setting changed.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffls.errors import InputError, atomic_output

__all__ = ["STORE_NAME", "MARKER", "FORMAT", "VERSION", "CHUNK_TARGET_BYTES", "MIN_LEVEL_SIZE", "ReflectanceField",
           "provenance", "photo_record", "stale_reason", "default_store_path", "open_field", "field_status",
           "choose_tile", "level_shapes", "tile_slices", "compressor", "write_json_atomic", "read_json",
           "choose_level"]

#: Folder of the store inside a capture folder.
STORE_NAME = "field.zarr"
#: The completion marker (inside the store), written last and atomically.
MARKER = "complete.json"
FORMAT = "ffls-field"
VERSION = 1
#: Default bytes of one chunk (all photos x one tile, float16): sets the tile side.
CHUNK_TARGET_BYTES = 8 * 2 ** 20
#: The pyramid stops at the first level whose larger side is at most this.
MIN_LEVEL_SIZE = 256


def compressor():
    """The codec of every array of the store: Blosc zstd level 3 with bit shuffle (float16 data)."""
    from zarr.codecs import BloscCodec

    return BloscCodec(cname="zstd", clevel=3, shuffle="bitshuffle")


def choose_tile(n: int, target_bytes: int = CHUNK_TARGET_BYTES) -> int:
    """Tile side (pixels, a multiple of 16, 16 to 1024) whose chunk of ``n`` float16 RGB photos is about ``target_bytes``."""
    side = math.sqrt(max(target_bytes, 1) / (6.0 * max(int(n), 1)))
    return int(min(1024, max(16, 16 * round(side / 16))))


def level_shapes(H: int, W: int, min_size: int = MIN_LEVEL_SIZE) -> list[tuple[int, int]]:
    """``[(H, W), (ceil(H/2), ceil(W/2)), ...]`` down to the first level with ``max(h, w) <= min_size``."""
    out = [(int(H), int(W))]
    while max(out[-1]) > min_size:
        h, w = out[-1]
        out.append(((h + 1) // 2, (w + 1) // 2))
    return out


def tile_slices(H: int, W: int, tile: int):
    """The tiles ``(slice(y0, y1), slice(x0, x1))`` of an ``H x W`` image in row-major order."""
    return [(slice(y, min(y + tile, H)), slice(x, min(x + tile, W)))
            for y in range(0, H, tile) for x in range(0, W, tile)]


def choose_level(shapes, n_layers: int, budget_bytes: int, window=None, bytes_per_value: int = 2) -> int:
    """The pyramid level to show: the finest that fits ``budget_bytes`` and is not finer than the window needs.

    Parameters
    ----------
    shapes : list of (h, w)
        Level shapes, finest first (:func:`level_shapes`).
    n_layers : int
        Images per level (photos, or K + 1 layers of a compressed basis).
    budget_bytes : int
        Memory allowed for the level (``n_layers * h * w * 4 * bytes_per_value``: RGBA storage).
    window : (width, height), optional
        The viewport; a level at least this large in both directions is enough.

    Returns
    -------
    int
        The level index (0 = full resolution); the coarsest level when none fits the budget.
    """
    chosen = len(shapes) - 1
    for k, (h, w) in enumerate(shapes):
        if n_layers * h * w * 4 * bytes_per_value <= budget_bytes:
            chosen = k
            break
    if window is not None:
        ww, wh = int(window[0]), int(window[1])
        coarsest_enough = 0
        for k, (h, w) in enumerate(shapes):
            if w >= ww and h >= wh:
                coarsest_enough = k
        chosen = max(chosen, coarsest_enough)
    return int(chosen)


# ----------------------------------------------------------------------------- provenance
def photo_record(path) -> dict:
    """``{'name', 'bytes', 'mtime_ns'}`` of one photo file (what a change of the photo changes)."""
    p = Path(path)
    try:
        st = os.stat(p)
    except OSError as e:
        raise InputError(f"cannot read the photo: {e.strerror}", p) from None
    return {"name": p.name, "bytes": int(st.st_size), "mtime_ns": int(st.st_mtime_ns)}


def _encoding_json(encoding):
    return encoding if isinstance(encoding, (str, dict)) else str(encoding)


def provenance(capture) -> dict:
    """What a store of ``capture`` is built from: its photos' sizes and times, their order, the encoding.

    Returns
    -------
    dict
        ``images`` (per photo :func:`photo_record`), ``encoding`` (the capture's, as in
        ``capture.json`` or calibrated by ``ffls lights``) and ``response_sha1`` (a digest of the
        inverse response table, or None).
    """
    resp = getattr(capture, "response", None)
    digest = None if resp is None else hashlib.sha1(np.ascontiguousarray(resp, dtype=np.float64).tobytes()).hexdigest()
    return {"images": [photo_record(p) for p in capture.image_paths],
            "encoding": _encoding_json(capture.encoding), "response_sha1": digest}


def stale_reason(recorded: dict, current: dict) -> str | None:
    """One line saying why a store built from ``recorded`` does not hold ``current``'s photos; None when it does."""
    if json.dumps(recorded.get("encoding"), sort_keys=True) != json.dumps(current.get("encoding"), sort_keys=True):
        return f"the encoding changed ({recorded.get('encoding')!r} -> {current.get('encoding')!r})"
    if recorded.get("response_sha1") != current.get("response_sha1"):
        return "the response table changed"
    a, b = recorded.get("images", []), current.get("images", [])
    if [r["name"] for r in a] != [r["name"] for r in b]:
        return f"the capture lists other photos ({len(a)} stored, {len(b)} now)"
    for r, c in zip(a, b):
        if r["bytes"] != c["bytes"]:
            return f"photo {c['name']} changed (size {r['bytes']} -> {c['bytes']} bytes)"
        if r["mtime_ns"] != c["mtime_ns"]:
            return f"photo {c['name']} changed (modified since the store was built)"
    return None


# ----------------------------------------------------------------------------- small json files
def write_json_atomic(path, doc: dict) -> Path:
    """Write ``doc`` to ``path`` through :func:`ffls.errors.atomic_output` (never a half-written file;
    a part of the store, not named as an output of its own)."""
    path = Path(path)
    with atomic_output(path, part=True) as tmp:
        tmp.write_text(json.dumps(doc, indent=1, sort_keys=True))
    return path


def read_json(path) -> dict | None:
    """The JSON document at ``path``, or None when missing or unreadable (an incomplete write)."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


# ----------------------------------------------------------------------------- the store
def default_store_path(capture) -> Path:
    """``CAPTURE/field.zarr``."""
    return Path(capture.folder) / STORE_NAME


@dataclass
class ReflectanceField:
    """A complete store, opened for reading.

    Attributes
    ----------
    path : Path
    names : list of str
        Photo names, in the order of the ``basis`` rows.
    shape : (H, W)
    tile : int
        Tile side of the chunks.
    scale : float
        Stored value = radiance * scale (a power of two).
    levels : list of (h, w)
        The pyramid's shapes, level 0 first.
    marker : dict
        The completion marker (provenance, float16 report, timings).
    """

    path: Path
    names: list
    shape: tuple
    tile: int
    scale: float
    levels: list
    marker: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.names)

    def group(self, mode: str = "r"):
        import zarr

        return zarr.open_group(str(self.path), mode=mode)

    def array(self, level: int = 0, mode: str = "r"):
        """The zarr array of pyramid level ``level`` (0 = ``basis``)."""
        g = self.group(mode)
        return g["basis"] if level == 0 else g[f"levels/{level}"]

    def rows_of(self, image_names) -> np.ndarray:
        """Row indices of ``image_names`` in the store (InputError naming the first missing one)."""
        pos = {n: i for i, n in enumerate(self.names)}
        missing = [n for n in image_names if n not in pos]
        if missing:
            raise InputError(f"the store holds no photo {missing[0]!r}", self.path)
        return np.array([pos[n] for n in image_names], dtype=np.intp)

    def tiles(self, level: int = 0):
        """The chunk-aligned tiles ``(rows, cols)`` slices of level ``level``."""
        h, w = self.levels[level]
        return tile_slices(h, w, self.tile)

    def read_tile(self, ys: slice, xs: slice, rows=None, level: int = 0, arr=None) -> np.ndarray:
        """Radiance of one tile: ``(len(rows), h, w, 3)`` float32 (all photos when ``rows`` is None)."""
        a = self.array(level) if arr is None else arr
        block = a[:, ys, xs, :]
        if rows is not None:
            block = block[np.asarray(rows)]
        out = block.astype(np.float32)
        out *= np.float32(1.0 / self.scale)
        return out

    def read_level(self, level: int, rows=None) -> np.ndarray:
        """A whole pyramid level as radiance ``(len(rows), h, w, 3)`` float32 (the caller checks it fits)."""
        h, w = self.levels[level]
        k = self.n if rows is None else len(rows)
        out = np.empty((k, h, w, 3), dtype=np.float32)
        a = self.array(level)
        for ys, xs in self.tiles(level):
            out[:, ys, xs] = self.read_tile(ys, xs, rows, level, arr=a)
        return out

    def dask_array(self, level: int = 0):
        """Level ``level`` as a dask array of the stored float16 values (chunks = the store's)."""
        import dask.array as da

        return da.from_zarr(self.array(level))


def _marker_path(path) -> Path:
    return Path(path) / MARKER


def open_field(path) -> ReflectanceField:
    """Open a complete store.

    Raises
    ------
    InputError
        No store there, or one without its completion marker (an ingest that did not finish).
    """
    path = Path(path)
    m = read_json(_marker_path(path))
    if m is None:
        if path.exists():
            raise InputError("the store is incomplete (an ingest did not finish); run 'ffls ingest' again", path)
        raise InputError("no reflectance-field store (run 'ffls ingest CAPTURE')", path)
    if m.get("format") != FORMAT or m.get("version") != VERSION:
        raise InputError(f"not an {FORMAT} store of version {VERSION}", path)
    return ReflectanceField(path, list(m["names"]), tuple(m["shape"]), int(m["tile"]), float(m["scale"]),
                            [tuple(s) for s in m["levels"]], m)


def field_status(capture, path=None) -> tuple[str, str | None]:
    """``(status, reason)`` of the store of ``capture``: ``'ok'``, ``'missing'``, ``'incomplete'`` or ``'stale'``.

    ``reason`` is one line for ``'stale'`` (:func:`stale_reason`) and ``'incomplete'``.
    """
    path = default_store_path(capture) if path is None else Path(path)
    if not path.exists():
        return "missing", None
    m = read_json(_marker_path(path))
    if m is None:
        return "incomplete", "an earlier ingest did not finish"
    why = stale_reason(m.get("provenance", {}), provenance(capture))
    if why is not None:
        return "stale", why
    return "ok", None
