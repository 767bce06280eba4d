"""The chunked reflectance field (ffls.store): tiny tiles, float16 scale, pyramid, provenance, interrupted ingests."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.io.capture import Capture, Lights, load_capture, save_capture, save_lights
from ffls.io.images import write_exr
from ffls.relight.cpu import relight_fast
from ffls.radiance.photos import load_photos
from ffls.store.field import MARKER, choose_level, field_status, level_shapes, open_field
from ffls.store.ingest import ingest_capture


def make_capture(folder, n=7, H=40, W=56, seed=0, dynamic_range=False):
    """A capture of ``n`` random linear EXR photos (float32), capture.json and lights.json."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for i in range(n):
        img = rng.random((H, W, 3), dtype=np.float32) * (i + 1)
        img[rng.random((H, W)) < 0.3] = 0.0  # a dark background
        if dynamic_range and i == 2:
            img[3, 4] = 1.0e6  # a sun next to 1e-3
            img[5, 6] = 1.0e-3
        write_exr(folder / f"p{i:02d}.exr", img)
        names.append(f"p{i:02d}.exr")
    save_capture(Capture(folder, names, encoding="linear"))
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.2
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    save_lights(Lights(names, d, status=["ok"] * n, reasons=[None] * n, extra=[{} for _ in range(n)]),
                folder / "lights.json")
    return load_capture(folder)


@pytest.fixture
def capture(tmp_path):
    return make_capture(tmp_path / "cap")


def test_tiny_tiles_hold_the_photos_within_float16_rounding(capture):
    rep = ingest_capture(capture, tile=16, progress=False)
    f = rep.field
    assert rep.built and f.tile == 16 and f.shape == (40, 56) and f.n == 7
    assert f.array().chunks == (7, 16, 16, 3)  # tiles x all photos
    assert len(f.tiles()) == 3 * 4  # 40 x 56 in 16 px tiles, partial at the edges
    photos = load_photos(capture, progress=False)
    stored = f.read_level(0)
    assert f.scale == 2.0 ** np.floor(np.log2(2 ** 12 / np.abs(photos).max()))
    sig = np.abs(photos) > 2 ** -14 / f.scale
    assert np.all(np.abs(stored - photos)[sig] <= 2 ** -11 * np.abs(photos)[sig])


def test_tiled_relighting_equals_in_memory(capture):
    from ffls.relight.stream import relight_field

    f = ingest_capture(capture, tile=16, progress=False).field
    photos = load_photos(capture, progress=False)
    rng = np.random.default_rng(1)
    rows = np.array([4, 0, 6, 2])
    w = rng.random((4, 3)) * 3
    ref = relight_fast(w, photos[rows])
    got = relight_field(f, rows, w, progress=False)
    bound = 2 ** -11 * np.einsum("nc,nhwc->hwc", w, np.abs(photos[rows])) + 1e-6 * np.abs(ref)
    assert got.shape == ref.shape and got.dtype == np.float32
    assert np.all(np.abs(got - ref) <= bound)


def test_float16_scale_is_checked_on_a_wide_dynamic_range(tmp_path):
    cap = make_capture(tmp_path / "hdr", n=4, dynamic_range=True)
    f = ingest_capture(cap, tile=16, progress=False).field
    assert f.scale == 2.0 ** -8  # 1e6 lands at 3906.25, below float16's 65504
    stored = f.read_level(0, rows=[2])[0]
    assert stored[3, 4, 0] == pytest.approx(1.0e6, rel=2 ** -11)
    assert np.isfinite(stored).all()


def test_pyramid_levels_are_2x2_means(tmp_path):
    import zarr

    cap = make_capture(tmp_path / "pyr", n=3, H=37, W=70)
    assert ingest_capture(cap, tile=16, progress=False).field.levels == [(37, 70)]  # small: one level
    f = ingest_capture(cap, tmp_path / "pyr16.zarr", tile=16, progress=False, min_level=16).field
    assert f.levels == level_shapes(37, 70, min_size=16) == [(37, 70), (19, 35), (10, 18), (5, 9)]
    g = zarr.open_group(str(f.path), mode="r")
    for k in (1, 2, 3):
        fine = (g["basis"] if k == 1 else g[f"levels/{k - 1}"])[:].astype(np.float32)
        coarse = g[f"levels/{k}"][:].astype(np.float32)
        h, w = f.levels[k]
        assert coarse.shape == (3, h, w, 3)
        padded = np.pad(fine, ((0, 0), (0, 2 * h - fine.shape[1]), (0, 2 * w - fine.shape[2]), (0, 0)), mode="edge")
        mean = padded.reshape(3, h, 2, w, 2, 3).mean(axis=(2, 4))
        np.testing.assert_allclose(coarse, mean, rtol=2 ** -10, atol=1e-7)
    # a level read back as radiance: the photos' means, within float16 rounding
    photos = load_photos(cap, progress=False)
    lvl1 = f.read_level(1)
    padded = np.pad(photos, ((0, 0), (0, 1), (0, 0), (0, 0)), mode="edge").reshape(3, 19, 2, 35, 2, 3).mean(axis=(2, 4))
    np.testing.assert_allclose(lvl1, padded, rtol=2 ** -9, atol=2 ** -14 / f.scale)


def test_choose_level_fits_budget_and_window():
    shapes = [(4096, 4096), (2048, 2048), (1024, 1024), (512, 512)]
    # 64 layers at RGBA16F: level 0 needs 8 GiB, level 1 2 GiB, level 2 512 MiB
    assert choose_level(shapes, 64, 1 << 30) == 2
    assert choose_level(shapes, 64, 1 << 40) == 0
    assert choose_level(shapes, 64, 1 << 40, window=(1280, 720)) == 1  # finer than the window is wasted
    assert choose_level(shapes, 64, 1) == 3  # nothing fits: the coarsest


def test_changed_photo_invalidates_the_store(capture):
    ingest_capture(capture, tile=16, progress=False)
    assert field_status(capture) == ("ok", None)
    new = np.full((40, 56, 3), 0.5, dtype=np.float32)
    write_exr(capture.image_paths[3], new)
    st = os.stat(capture.image_paths[3])
    os.utime(capture.image_paths[3], ns=(st.st_atime_ns, st.st_mtime_ns + 10 ** 9))
    status, why = field_status(capture)
    assert status == "stale" and "p03.exr" in why and "\n" not in why
    rep = ingest_capture(capture, tile=16, progress=False)
    assert rep.built and "p03.exr" in rep.note and "rebuilding" in rep.note
    np.testing.assert_array_equal(rep.field.read_level(0, rows=[3])[0], new)
    assert field_status(capture) == ("ok", None)


def test_changed_encoding_invalidates_the_store(capture):
    from dataclasses import replace

    ingest_capture(capture, tile=16, progress=False)
    status, why = field_status(replace(capture, encoding={"gamma": 2.2}))
    assert status == "stale" and "encoding" in why


def test_store_without_marker_never_reads_as_complete(capture):
    f = ingest_capture(capture, tile=16, progress=False).field
    (f.path / MARKER).unlink()
    with pytest.raises(InputError, match="incomplete"):
        open_field(f.path)
    assert field_status(capture)[0] == "incomplete"


_INGEST_SCRIPT = textwrap.dedent("""
    import sys, time
    from ffls.io.capture import load_capture
    from ffls.store.ingest import ingest_capture

    class SlowRunner:
        def map(self, fn, items, desc=""):
            out = []
            for x in items:
                out.append(fn(x))
                print(desc, flush=True)
                time.sleep(0.3)
            return out

    ingest_capture(load_capture(sys.argv[1]), tile=16, runner=SlowRunner())
    print("finished", flush=True)
""")


def test_an_interrupted_ingest_says_what_it_kept(tmp_path, monkeypatch, capsys):
    """Ctrl-C during an ingest keeps the staged photos on purpose (the next run resumes): the last
    line says so, instead of "nothing partial was left"."""
    import ffls.store.ingest as ingest
    from ffls.cli import main

    cap = make_capture(tmp_path / "cap", n=4)

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(ingest, "build_tile", stop)
    assert main(["ingest", str(cap.folder), "--workers", "1", "--no-progress"]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "interrupted; the unfinished store" in err[0] and "the next run resumes it" in err[0], err
    assert (cap.folder / "field.zarr" / "staging").exists()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL])
def test_interrupted_ingest_resumes_cleanly(tmp_path, sig):
    cap = make_capture(tmp_path / "cap", n=8)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    with subprocess.Popen([sys.executable, "-c", _INGEST_SCRIPT, str(cap.folder)], stdout=subprocess.PIPE,
                          stderr=subprocess.DEVNULL, text=True, env=env,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL)) as proc:
        try:
            done = 0
            t0 = time.monotonic()
            while done < 3 and time.monotonic() - t0 < 120:
                line = proc.stdout.readline()
                assert line, "the ingest ended before it was interrupted"
                done += line.startswith("ingest: photos")
            proc.send_signal(sig)
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert proc.returncode != 0
    path = cap.folder / "field.zarr"
    assert path.exists() and not (path / MARKER).exists()
    with pytest.raises(InputError, match="incomplete"):
        open_field(path)
    rep = ingest_capture(cap, tile=16, progress=False)
    assert rep.built and rep.resumed >= 3 and rep.resumed + rep.staged == 8
    fresh = ingest_capture(cap, tmp_path / "fresh.zarr", tile=16, progress=False).field
    np.testing.assert_array_equal(rep.field.read_level(0), fresh.read_level(0))
    assert not (path / "staging").exists() and not (path / "progress").exists()


def test_ingest_of_other_settings_restarts(capture):
    """A leftover of an interrupted ingest with another tile size is not mixed in: the store is restarted."""
    import shutil

    f = ingest_capture(capture, tile=16, progress=False).field
    (f.path / MARKER).unlink()
    shutil.rmtree(f.path / "basis")
    rep = ingest_capture(capture, tile=32, progress=False)
    assert rep.built and rep.resumed == 0 and "restarting" in rep.note
    assert rep.field.tile == 32


def test_fresh_store_is_not_rebuilt(capture):
    ingest_capture(capture, tile=16, progress=False)
    rep = ingest_capture(capture, tile=16, progress=False)
    assert not rep.built and rep.note is None


def test_bad_photo_is_one_line_and_leaves_an_incomplete_store(capture):
    img = np.ones((40, 56, 3), dtype=np.float32)
    img[1, 2, 0] = np.nan
    write_exr(capture.image_paths[5], img)
    with pytest.raises(InputError, match="NaN") as e:
        ingest_capture(capture, tile=16, progress=False)
    assert str(capture.image_paths[5]) in str(e.value.path) and "\n" not in str(e.value)
    assert field_status(capture)[0] == "incomplete"
    write_exr(capture.image_paths[5], np.ones((40, 56, 3), dtype=np.float32))  # fixed: the ingest resumes
    rep = ingest_capture(capture, tile=16, progress=False)
    assert rep.built and rep.resumed == 5 and rep.staged == 2  # photos 0-4 were staged before photo 5 failed


@pytest.mark.parametrize("kind", ["file", "folder", "other zarr"])
def test_a_store_path_that_is_not_an_ffls_store_is_never_replaced(capture, tmp_path, capsys, kind):
    """--store naming the user's file or folder: one line, status 2, and the thing left exactly as it was."""
    from ffls.cli import main

    target = {"file": capture.json_path, "folder": tmp_path / "mine", "other zarr": tmp_path / "other.zarr"}[kind]
    if kind != "file":
        target.mkdir()
        (target / "keep.txt").write_text("the user's")
        if kind == "other zarr":
            (target / "zarr.json").write_text('{"zarr_format": 3, "node_type": "group"}')
    before = sorted((p.name, p.read_bytes()) for p in ([target] if target.is_file() else target.iterdir()))
    rc = main(["ingest", str(capture.folder), "--store", str(target), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "never replaces" in err[0], err
    after = sorted((p.name, p.read_bytes()) for p in ([target] if target.is_file() else target.iterdir()))
    assert after == before


def test_a_store_in_a_missing_folder_is_refused(capture, tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        ingest_capture(capture, tmp_path / "missing" / "s.zarr", progress=False)
    assert not (tmp_path / "missing").exists()
