"""Captures of any size: Dask (a LocalCluster of 2 processes), out-of-core compression, --memory, tiled GPU pass 2."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.io.capture import load_capture_and_lights
from ffls.radiance.photos import load_photos
from ffls.relight.compress import compress_basis
from ffls.relight.stream import (check_budget, compress_field, load_compressed_level, load_or_compress_field,
                                 parse_memory, relight_compressed_field)
from ffls.store.ingest import SerialRunner, ingest_capture
from test_store import make_capture


@pytest.fixture(scope="module")
def cluster():
    from ffls.cluster import open_client

    with open_client(workers=2, progress=False) as runner:  # processes, one thread each
        yield runner


@pytest.fixture(scope="module")
def synth_capture(tmp_path_factory):
    from ffls.synth.scene import write_synthetic_capture

    folder = tmp_path_factory.mktemp("synth") / "cap"
    write_synthetic_capture(folder, n_lights=8, resolution=96, seed=3, progress=False)
    return folder


@pytest.mark.slow
def test_local_cluster_estimates_the_same_lights(cluster, synth_capture):
    from ffls.cluster.lights import estimate_lights_dask
    from ffls.io.capture import load_capture
    from ffls.spheres.estimate import estimate_lights

    cap = load_capture(synth_capture)
    assert cluster.n_workers == 2
    here = estimate_lights(cap, progress=False, workers=1)
    there = estimate_lights_dask(cap, cluster)
    np.testing.assert_array_equal(there.directions, here.directions)
    assert there.status == here.status and there.reasons == here.reasons
    assert [e.get("uncertainty_deg") for e in there.extra] == [e.get("uncertainty_deg") for e in here.extra]
    assert there.uncertainty == here.uncertainty and here.uncertainty["confidence"] == 0.95


def test_ingest_on_the_cluster_equals_the_serial_one(cluster, tmp_path):
    cap = make_capture(tmp_path / "cap", n=5)
    a = ingest_capture(cap, tmp_path / "a.zarr", tile=16, runner=cluster).field
    b = ingest_capture(cap, tmp_path / "b.zarr", tile=16, progress=False).field
    assert a.scale == b.scale
    np.testing.assert_array_equal(a.array()[:], b.array()[:])


def test_out_of_core_compression_matches_the_in_memory_one(tmp_path):
    cap = make_capture(tmp_path / "cap", n=9)
    f = ingest_capture(cap, tile=16, progress=False).field
    photos = load_photos(cap, progress=False)
    names = list(cap.image_names)
    sc = compress_field(f, names, 4, runner=SerialRunner(False))
    cb = compress_basis(f.read_level(0), 4, power_iters=8)  # the stored photos, in memory
    np.testing.assert_allclose(sc.singular_values, cb.singular_values, rtol=1e-4)
    w = np.random.default_rng(2).random((9, 3))
    ref = cb.relight(w)
    got = relight_compressed_field(sc, w, progress=False)
    assert np.max(np.abs(got - ref)) <= 4e-3 * np.max(np.abs(ref))  # float16 layers
    # exact at rank n - 1, as the in-memory compression
    full = compress_field(f, names, 8, runner=SerialRunner(False))
    exact = np.einsum("nc,nhwc->hwc", w, photos)
    assert np.max(np.abs(relight_compressed_field(full, w, progress=False) - exact)) <= 4e-3 * np.abs(exact).max()
    # the stored one is found again, and a level loads as a CompressedBasis
    again = load_or_compress_field(f, names, 4)
    assert again.key == sc.key and np.array_equal(again.loadings, sc.loadings)
    cbl = load_compressed_level(sc, 0)
    assert cbl.rank == 4 and cbl.shape == f.shape
    np.testing.assert_allclose(cbl.relight(w), got, rtol=1e-5, atol=1e-5 * np.abs(got).max())


def test_compression_on_the_cluster_equals_the_serial_one(cluster, tmp_path):
    cap = make_capture(tmp_path / "cap", n=6)
    f = ingest_capture(cap, tile=16, progress=False).field
    a = compress_field(f, list(cap.image_names), 3, runner=SerialRunner(False))
    la = a.array()[:]
    b = compress_field(f, list(cap.image_names), 3, runner=cluster)
    np.testing.assert_allclose(b.singular_values, a.singular_values, rtol=1e-12)
    np.testing.assert_array_equal(b.array()[:], la)


def test_parse_memory():
    assert parse_memory("1G") == 2 ** 30
    assert parse_memory("512M") == 512 * 2 ** 20
    assert parse_memory("1.5GiB") == 3 * 2 ** 29
    assert parse_memory("4096") == 4096
    for bad in ("", "-1G", "lots", "nanG", "0", "1e308G", "2e6P"):
        with pytest.raises(ValueError):
            parse_memory(bad)


def test_budget_too_small_is_one_line():
    with pytest.raises(InputError, match=r"--memory 100M is too small") as e:
        check_budget(100 * 2 ** 20, (4096, 4096), 64, 64, 128)
    assert "\n" not in str(e.value)
    check_budget(2 ** 30, (2048, 2048), 64, 64, 144)  # the goal: 64 photos at 2048^2 within 1 GiB


def test_cli_relight_streams_and_equals_in_memory(tmp_path, capsys):
    from ffls.cli import main
    from ffls.io.images import read_image

    cap = make_capture(tmp_path / "cap", n=6)
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    assert main(["relight", str(cap.folder), "--probe", "sky", "-o", str(a), "--workers", "1"]) == 0
    assert not (cap.folder / "field.zarr").exists()  # small: in memory, no store
    assert main(["relight", str(cap.folder), "--probe", "sky", "-o", str(b), "--tiles", "--workers", "1"]) == 0
    err = capsys.readouterr().err
    assert "streamed from" in err
    x, y = read_image(a).pixels, read_image(b).pixels
    assert np.max(np.abs(x - y)) <= 2 ** -10 * np.max(np.abs(x))


@pytest.mark.parametrize("knobs", [["--weighting", "barycentric"], ["--weighting", "gaussian", "--map-res", "32"]])
def test_cli_streamed_relight_follows_the_quality_knobs(tmp_path, capsys, knobs):
    """The streamed path relights under the same weighting scheme and pass-1 map as the in-memory one."""
    from ffls.cli import main
    from ffls.io.images import read_image

    cap = make_capture(tmp_path / "cap", n=6)
    a, b, v = tmp_path / "a.exr", tmp_path / "b.exr", tmp_path / "v.exr"
    base = ["relight", str(cap.folder), "--probe", "sky", "--workers", "1"]
    assert main(base + knobs + ["-o", str(a)]) == 0
    assert main(base + knobs + ["--tiles", "-o", str(b)]) == 0
    assert main(base + ["--tiles", "-o", str(v)]) == 0
    capsys.readouterr()
    x, y, z = read_image(a).pixels, read_image(b).pixels, read_image(v).pixels
    assert np.max(np.abs(x - y)) <= 2 ** -10 * np.max(np.abs(x))
    assert np.max(np.abs(y - z)) > 2 ** -8 * np.max(np.abs(x))  # the scheme did change the streamed result


@pytest.mark.parametrize("flag", [["--basis-subset", "3"], ["--quality", "auto", "--max-error", "0.1"],
                                  ["--weighting", "kriging"]])
def test_cli_streamed_refuses_in_memory_knobs_in_one_line(tmp_path, capsys, flag):
    from ffls.cli import main

    cap = make_capture(tmp_path / "cap", n=6)
    out = tmp_path / "x.exr"
    rc = main(["relight", str(cap.folder), "--probe", "sky", "--tiles", "--workers", "1", "-o", str(out)] + flag)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and flag[0] in err[0], err
    assert not out.exists()


def test_cli_memory_too_small_refused_in_one_line(tmp_path, capsys):
    from ffls.cli import main

    cap = make_capture(tmp_path / "cap", n=4)
    rc = main(["relight", str(cap.folder), "--probe", "sky", "-o", str(tmp_path / "x.exr"), "--tiles",
               "--memory", "64M", "--workers", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--memory 64M is too small" in err[0]
    assert not (tmp_path / "x.exr").exists()


def test_cli_ingest_reports_and_is_idempotent(tmp_path, capsys):
    from ffls.cli import main

    cap = make_capture(tmp_path / "cap", n=4)
    assert main(["ingest", str(cap.folder), "--workers", "1", "--tile", "16", "--no-progress"]) == 0
    assert "4 photos linearised" in capsys.readouterr().out
    assert main(["ingest", str(cap.folder), "--workers", "1", "--no-progress"]) == 0
    assert "complete and up to date" in capsys.readouterr().out


@pytest.mark.gl
def test_tiled_gpu_pass2_equals_the_engine(ctx, tmp_path):
    from ffls.gpu.engine import Engine
    from ffls.gpu.tiled import TiledEngine
    from ffls.lightmaps.lightmap import lightmap_from_spec
    from ffls.relight.stream import StreamedRelighter

    cap = make_capture(tmp_path / "cap", n=5)
    capture, lights = load_capture_and_lights(cap.folder)
    f = ingest_capture(capture, tile=16, progress=False).field
    idx, dirs = lights.accepted()
    lm = lightmap_from_spec("sky")
    s = StreamedRelighter(f, [lights.image_names[i] for i in idx], dirs, capture.hemisphere, progress=False)
    t = TiledEngine(ctx, s, dtype="f32")
    eng = Engine(ctx, f.read_level(0, s.rows), dirs, capture.hemisphere, dtype="f32")
    try:
        # the full engine first: programs are cached per context and an engine of another size
        # created later overwrites their size uniforms (ffls.gpu.weighted_sum sets them at init)
        for r in (eng, t):
            r.set_lightmap(lm)
            r.render()
        ref = eng.read_hdr()
        np.testing.assert_allclose(t.read_weights(), eng.read_weights(), rtol=1e-6)
        assert np.max(np.abs(t.read_hdr() - ref)) <= 1e-5 * np.max(np.abs(ref))
    finally:
        t.release()
        eng.release()


@pytest.mark.gl
def test_viewer_engine_shows_the_level_that_fits(ctx, tmp_path):
    from ffls.gpu.tiled import engine_for_view
    from ffls.relight.stream import relight_field

    cap = make_capture(tmp_path / "cap", n=5, H=40, W=56)
    capture, lights = load_capture_and_lights(cap.folder)
    f = ingest_capture(capture, tile=16, progress=False, min_level=16).field
    assert f.levels == [(40, 56), (20, 28), (10, 14)]
    # the photos fit: the engine holds them, no store is used
    eng, streamed, level = engine_for_view(ctx, capture, lights, 2 ** 30)
    assert streamed is None and level == 0 and eng.size == (56, 40)
    eng.release()
    # a budget that holds level 1 only (5 layers x 20 x 28 x RGBA16F = 22400 bytes)
    eng, streamed, level = engine_for_view(ctx, capture, lights, 10 ** 5, budget_bytes=30000)
    try:
        assert level == 1 and eng.size == (28, 20)
        w = np.random.default_rng(0).random((5, 3))
        eng.set_weights(w)
        eng.render()
        np.testing.assert_allclose(eng.read_hdr(), relight_field(f, streamed.rows, w, level=1, progress=False),
                                   rtol=2e-3, atol=1e-4)
        streamed.set_weights(eng.read_weights())  # the screenshot: full resolution, tile by tile
        streamed.render()
        assert streamed.read_hdr().shape == (40, 56, 3)
    finally:
        eng.release()


def test_local_cluster_is_quiet_when_the_dashboard_port_is_taken():
    """Another Dask cluster on the machine holds port 8787: ffls's cluster starts without a warning
    (distributed's "Port 8787 is already in use" would be a library's warning line)."""
    import socket
    import warnings

    from ffls.cluster import open_client

    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        s.bind(("0.0.0.0", 8787))
        s.listen()
    except OSError:  # already held by another process: the condition under test holds as well
        pass
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with open_client(workers=1, progress=False) as runner:
                assert runner.map(abs, [-1, -2]) == [1, 2]
    finally:
        s.close()
    assert not [str(w.message) for w in caught if "8787" in str(w.message) or "socket" in str(w.message)]
