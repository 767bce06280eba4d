"""Ingest: a capture's photos, linearised one by one, into its chunked store (:mod:`ffls.store.field`).

Three phases, each a list of independent tasks that a *runner* maps (:class:`SerialRunner` in
this process; :class:`ffls.cluster.DaskRunner` on a Dask cluster, local processes or remote
machines sharing the store's file system):

1. **photos** (:func:`stage_photo`): read and linearise photo ``i``
   (:func:`ffls.radiance.photos.read_photo`), convert it to float16 with its own checked
   power-of-two scale, write it to ``staging[i]`` (one chunk per tile), then record it in
   ``progress/i.json`` (its file's size and time, scale, largest magnitude). A photo is done only
   once its record exists, and the record is written atomically after its chunks.
2. **tiles** (:func:`build_tile`): once every photo is staged the capture's scale is known
   (:func:`ffls.store.float16.choose_scale` of the largest magnitude); each tile of all photos
   is rescaled (powers of two: exact, and checked again against the capture's largest
   magnitude) into one chunk ``(n, tile, tile, 3)`` of ``basis``.
3. **pyramid** (:func:`build_level_tile`): each level halves the previous one (2x2 means).

Then the completion marker is written, atomically, and only then the staging data removed: a
store without the marker never reads as complete (:func:`ffls.store.field.open_field`).

Interrupted (Ctrl-C, a killed process, a lost worker), an ingest **resumes**: the next run keeps
the staged photos whose record matches their file now and stages the rest; the tile and pyramid
phases are redone from the staging data (they are cheap next to decoding photos). A store whose
plan (photo list, image size, tile, encoding) differs is started again from nothing.

A complete store whose photos changed since (:func:`ffls.store.field.stale_reason`) is
**rebuilt**: :func:`ingest_capture` returns the one line that says why in its ``note``.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import sys
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from ffls.errors import FflsError, InputError, OutputError, broken_link, kept_on_interrupt, os_error_message
from ffls.store.field import (FORMAT, MARKER, MIN_LEVEL_SIZE, VERSION, ReflectanceField, choose_tile, compressor, default_store_path,
                              level_shapes, open_field, photo_record, provenance, read_json, stale_reason,
                              tile_slices, write_json_atomic)
from ffls.store.float16 import choose_scale, to_float16

__all__ = ["SerialRunner", "IngestReport", "ingest_capture", "ensure_field", "stage_photo", "build_tile",
           "build_level_tile", "build_pyramid", "PLAN", "PROGRESS", "STORE_SUFFIX",
           "check_store_path"]

#: The extension of a new store's folder (a store may also be named without one).
STORE_SUFFIX = ".zarr"
#: The plan of an ingest under way (what a resumed ingest must match).
PLAN = "plan.json"
#: Folder of the per-photo records of the staged photos.
PROGRESS = "progress"


class SerialRunner:
    """Runs the tasks of an ingest in this process, in order, with a tqdm bar on stderr.

    A runner has one method, ``map(fn, items, desc) -> list`` (results in the order of
    ``items``); :class:`ffls.cluster.DaskRunner` is the other one.
    """

    def __init__(self, progress: bool = True):
        self.progress = progress

    def map(self, fn, items, desc: str = "") -> list:
        from tqdm import tqdm

        items = list(items)
        disable = not self.progress or not sys.stderr.isatty() or bool(os.environ.get("CI"))
        return [fn(x) for x in tqdm(items, desc=desc, unit="task", disable=disable, leave=False)]


@dataclass
class IngestReport:
    """What :func:`ingest_capture` did.

    Attributes
    ----------
    field : ReflectanceField
        The complete store.
    built : bool
        False when the store was already complete and fresh (nothing done).
    resumed : int
        Photos kept from an interrupted ingest.
    staged : int
        Photos read and linearised by this run.
    note : str or None
        One line: why an existing store was rebuilt or restarted.
    seconds : dict
        Wall time of each phase.
    """

    field: ReflectanceField
    built: bool
    resumed: int = 0
    staged: int = 0
    note: str | None = None
    seconds: dict | None = None


def _plan(capture, prov: dict, shape, tile: int) -> dict:
    return {"format": FORMAT, "version": VERSION, "names": list(capture.image_names), "shape": list(shape),
            "tile": int(tile), "encoding": prov["encoding"], "response_sha1": prov["response_sha1"]}


def _image_shape(capture) -> tuple[int, int]:
    if capture.image_size is not None:
        return int(capture.image_size[1]), int(capture.image_size[0])
    from ffls.io.images import read_image

    return tuple(read_image(capture.image_paths[0]).pixels.shape[:2])


def stage_photo(path, capture, i: int) -> dict:
    """Phase 1 for photo ``i``: linearise, float16 at its own scale, write ``staging[i]``, then its record.

    Returns
    -------
    dict
        The record also written to ``progress/i.json``: ``index``, ``photo``
        (:func:`ffls.store.field.photo_record`, taken before reading), ``scale``, ``max_abs``,
        ``n_flushed``.
    """
    import zarr

    from ffls.radiance.photos import read_photo

    path = Path(path)
    rec = photo_record(capture.image_paths[i])
    lin = read_photo(capture, i).linear
    staging = zarr.open_array(str(path / "staging"), mode="r+")
    if lin.shape != tuple(staging.shape[1:]):
        h, w = lin.shape[:2]
        raise InputError(f"image is {w}x{h} but the capture's first image is {staging.shape[2]}x{staging.shape[1]}",
                         capture.image_paths[i])
    max_abs = float(np.max(np.abs(lin))) if lin.size else 0.0
    # converted 256 rows at a time: the temporaries stay a few MB even for a 24 MP photo
    half, rep = to_float16(lin, path=capture.image_paths[i], max_abs=max_abs, chunk=256)
    del lin
    staging[i] = half
    out = {"index": int(i), "photo": rec, "scale": rep.scale, "max_abs": max_abs, "n_flushed": rep.n_flushed}
    write_json_atomic(path / PROGRESS / f"{i}.json", out)
    return out


def build_tile(path, photo_scales, scale: float, max_abs: float, tile: tuple) -> dict:
    """Phase 2 for one tile ``(ys, xs)``: all photos rescaled to the capture's ``scale``, into one ``basis`` chunk."""
    import zarr

    path = Path(path)
    ys, xs = tile
    block = zarr.open_array(str(path / "staging"), mode="r")[:, ys, xs, :].astype(np.float32)
    block *= (1.0 / np.asarray(photo_scales, dtype=np.float32))[:, None, None, None]  # radiance (exact: 2^k)
    half, rep = to_float16(block, scale=scale, path=path, max_abs=max_abs)
    zarr.open_array(str(path / "basis"), mode="r+")[:, ys, xs, :] = half
    return {"n_flushed": rep.n_flushed, "max_rel_error": rep.max_rel_error}


def build_level_tile(path, source: str, target: str, tile: tuple) -> None:
    """Phase 3 for one tile of a pyramid level: the 2x2 means of ``source`` (edge pixels repeated on odd sizes)."""
    import zarr

    path = Path(path)
    ys, xs = tile
    src = zarr.open_array(str(path / source), mode="r")
    _, hs, ws, _ = src.shape
    y0, y1 = 2 * ys.start, min(2 * ys.stop, hs)
    x0, x1 = 2 * xs.start, min(2 * xs.stop, ws)
    b = src[:, y0:y1, x0:x1, :].astype(np.float32)
    hh, ww = 2 * (ys.stop - ys.start), 2 * (xs.stop - xs.start)
    if b.shape[1] != hh or b.shape[2] != ww:
        b = np.pad(b, ((0, 0), (0, hh - b.shape[1]), (0, ww - b.shape[2]), (0, 0)), mode="edge")
    m = b.reshape(b.shape[0], hh // 2, 2, ww // 2, 2, 3).mean(axis=(2, 4))
    zarr.open_array(str(path / target), mode="r+")[:, ys, xs, :] = m.astype(np.float16)


def build_pyramid(path, prefix: str, n_layers: int, shape, tile: int, runner,
                  min_size: int = MIN_LEVEL_SIZE) -> list[tuple[int, int]]:
    """Create and fill ``PREFIX/levels/k`` (or ``levels/k`` with ``prefix`` '') from ``PREFIX``'s level 0.

    Levels halve down to the first whose larger side is at most ``min_size``
    (:func:`ffls.store.field.level_shapes`); returns their shapes, level 0 first."""
    import zarr

    g = zarr.open_group(str(path), mode="r+")
    shapes = level_shapes(*shape, min_size=min_size)
    base = f"{prefix}/levels" if prefix else "levels"
    src = prefix if prefix else "basis"
    for k in range(1, len(shapes)):
        h, w = shapes[k]
        name = f"{base}/{k}"
        g.create_array(name=name, shape=(n_layers, h, w, 3), chunks=(n_layers, tile, tile, 3), dtype="float16",
                       compressors=compressor(), fill_value=0, overwrite=True)
        runner.map(partial(build_level_tile, path, src, name), tile_slices(h, w, tile), desc=f"pyramid level {k}")
        src = name
    return shapes


def _remove(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def _group_format(path: Path):
    """The ``format`` attribute of the Zarr group at ``path`` (an ffls store's, set when it is created), or None."""
    doc = read_json(path / "zarr.json")
    attrs = doc.get("attributes") if isinstance(doc, dict) else None
    return attrs.get("format") if isinstance(attrs, dict) else None


def store_path_problem(path) -> str | None:
    """What is wrong with a store path whatever the store holds, or None: its folder missing, a new
    store named like a file (``--store x.exr`` made a zarr folder named ``x.exr``), or a file.

    Checked where ``--store`` is parsed: ``relight``/``render`` use the store only when the photos
    do not fit in memory, and a bad path was accepted silently when they did."""
    path = Path(path)
    if not path.parent.is_dir():
        return f"the store's folder {path.parent} does not exist"
    if path.is_symlink() and not path.exists():
        return broken_link(path)
    if not path.exists():
        if path.suffix and path.suffix.lower() != STORE_SUFFIX:
            return f"a store is a folder: its name ends with {STORE_SUFFIX} or has no extension, not {path.suffix}"
        return None
    if not path.is_dir():
        return ("is a file; the store must be a new path or an ffls store, and ffls never replaces anything "
                "else")
    return None


def check_store_path(path) -> None:
    """Refuse a store path that ffls must not write: its folder missing, or something there that is not an ffls store.

    An ingest replaces a stale or interrupted store of its own; anything else at ``path`` (a file,
    or a folder without this format's marker or plan) is the user's and is never removed.

    Raises
    ------
    ffls.errors.InputError
    """
    path = Path(path)
    why = store_path_problem(path)
    if why:
        raise InputError(why, path)
    if not os.access(path.parent, os.W_OK | os.X_OK):  # (the ingest's first write failed, naming no file)
        raise OutputError("folder is not writable (permission denied or read-only)", path.parent)
    if not path.exists():
        return
    marker = read_json(path / MARKER) if path.is_dir() else None
    ours = path.is_dir() and ((isinstance(marker, dict) and marker.get("format") == FORMAT)
                              or (marker is None and ((path / PLAN).is_file()  # an interrupted ingest
                                                      or _group_format(path) == FORMAT)))
    if not ours:
        what = ("a file" if not path.is_dir()
                else "a folder that is not an ffls store (no complete.json or plan.json of one)")
        raise InputError(f"is {what}; the store must be a new path or an ffls store, and ffls never replaces "
                         "anything else", path)


@contextlib.contextmanager
def _store_os_errors(path: Path):
    """An OS error while the store is written (a full disk: zarr's error names no file) as one
    line naming the store; what was staged is kept, as after an interruption, for a resume."""
    try:
        yield
    except FflsError:
        raise
    except OSError as e:
        kept = "; the unfinished store is kept: the next run resumes it" if path.exists() else ""
        raise OutputError(f"cannot write the store ({os_error_message(e)}){kept}", path) from None


def ingest_capture(capture, path=None, *, tile: int | None = None, runner=None, progress: bool = True,
                   rebuild: bool = False, min_level: int = MIN_LEVEL_SIZE) -> IngestReport:
    """Build (or resume, or check) the chunked store of ``capture``.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
        Its encoding must be known (stated, or calibrated by ``ffls lights`` and applied by
        :func:`ffls.io.capture.load_capture_and_lights`).
    path : path-like, optional
        The store; default ``CAPTURE/field.zarr``.
    tile : int, optional
        Tile side in pixels; default :func:`ffls.store.field.choose_tile` (chunks of about 8 MiB).
    runner : SerialRunner or ffls.cluster.DaskRunner, optional
        Maps the tasks; default :class:`SerialRunner`.
    progress : bool
        Progress bar of the default runner.
    rebuild : bool
        Build again even when the store is complete and fresh.
    min_level : int
        The pyramid stops at the first level whose larger side is at most this.

    Returns
    -------
    IngestReport

    Raises
    ------
    InputError
        ``path`` in a missing folder, or something there that is not an ffls store
        (:func:`check_store_path`); a photo that cannot be read or linearised, of another size, or whose float16 conversion
        fails (:func:`ffls.store.float16.to_float16`); the staged photos are kept for a resume.
    """
    import zarr

    path = default_store_path(capture) if path is None else Path(path)
    try:
        check_store_path(path)
    except OutputError as e:
        if path != default_store_path(capture):
            raise
        # a read-only capture: say where else the store can go
        raise OutputError(f"{e.message}; put the store in a writable folder with --store DIR.zarr", e.path) from None
    runner = SerialRunner(progress) if runner is None else runner
    prov = provenance(capture)
    n = len(capture.image_names)
    if n == 0:
        raise InputError("capture lists no images", capture.json_path)
    note = None
    marker = read_json(path / MARKER)
    if marker is not None:
        why = stale_reason(marker.get("provenance", {}), prov)
        if why is None and not rebuild:
            for leftover in ("staging", PROGRESS, PLAN):  # an ingest stopped while tidying up
                if (path / leftover).exists():
                    _remove(path / leftover)
            return IngestReport(open_field(path), built=False)
        note = f"{why}; rebuilding {path}" if why else None
        _remove(path)
    shape = _image_shape(capture)
    tile = choose_tile(n) if tile is None else int(tile)
    if tile < 1:
        raise ValueError(f"tile must be >= 1, not {tile}")
    plan = {**_plan(capture, prov, shape, tile), "min_level": int(min_level)}
    if path.exists() and marker is None:
        old = read_json(path / PLAN)
        if old != plan or not (path / "staging").exists():
            note = f"an interrupted ingest of other settings was found; restarting {path}"
            _remove(path)
    # an interruption from here keeps the unfinished store on purpose: the next run resumes it
    with kept_on_interrupt(f"the unfinished store {path} is kept: the next run resumes it"), _store_os_errors(path):
        t0 = time.perf_counter()
        if not path.exists():
            g = zarr.open_group(str(path), mode="w")
            g.attrs["format"] = FORMAT  # what check_store_path recognises before a plan or a marker exists
            g.create_array(name="staging", shape=(n, *shape, 3), chunks=(1, tile, tile, 3), dtype="float16",
                           compressors=compressor(), fill_value=0)
            (path / PROGRESS).mkdir()
            write_json_atomic(path / PLAN, plan)
        records = {}
        for i, cur in enumerate(prov["images"]):
            rec = read_json(path / PROGRESS / f"{i}.json")
            if rec is not None and rec.get("photo") == cur:
                records[i] = rec
        resumed = len(records)
        todo = [i for i in range(n) if i not in records]
        for rec in runner.map(partial(stage_photo, path, capture), todo, desc="ingest: photos"):
            records[int(rec["index"])] = rec
        t1 = time.perf_counter()
        max_abs = max(r["max_abs"] for r in records.values())
        scale = choose_scale(max_abs)
        g = zarr.open_group(str(path), mode="r+")
        g.create_array(name="basis", shape=(n, *shape, 3), chunks=(n, tile, tile, 3), dtype="float16",
                       compressors=compressor(), fill_value=0, overwrite=True)
        photo_scales = [records[i]["scale"] for i in range(n)]
        reports = runner.map(partial(build_tile, path, photo_scales, scale, max_abs), tile_slices(*shape, tile),
                             desc="ingest: tiles")
        t2 = time.perf_counter()
        shapes = build_pyramid(path, "", n, shape, tile, runner, min_level)
        t3 = time.perf_counter()
        seconds = {"photos": t1 - t0, "tiles": t2 - t1, "pyramid": t3 - t2}
        g["basis"].attrs["scale"] = scale
        doc = {"format": FORMAT, "version": VERSION, "names": list(capture.image_names), "shape": list(shape),
               "tile": tile, "scale": scale, "max_abs": max_abs, "levels": [list(s) for s in shapes],
               "provenance": {**prov, "images": [records[i]["photo"] for i in range(n)]},
               "float16": {"n_flushed": int(sum(r["n_flushed"] for r in reports)),
                           "max_rel_error": float(max((r["max_rel_error"] for r in reports), default=0.0))},
               "seconds": seconds}
        write_json_atomic(path / MARKER, doc)  # last: from here on the store reads as complete
        for leftover in ("staging", PROGRESS, PLAN):
            _remove(path / leftover)
        return IngestReport(open_field(path), built=True, resumed=resumed, staged=len(todo), note=note, seconds=seconds)


def ensure_field(capture, path=None, *, runner=None, progress: bool = True) -> IngestReport:
    """The complete, fresh store of ``capture``: opened when it is, else (re)built (lazily, on first use)."""
    return ingest_capture(capture, path, runner=runner, progress=progress)
