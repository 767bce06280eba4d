"""A washed-out photo (overexposed: most of its pixels at full scale) among good ones is left out of
the sphere detection's reductions (``ffls.spheres.detect.WASHED_OUT_SHARE``): in the max image and
the brightest-photo map it hid every other photo, so that one overexposed frame of 60 made
``ffls lights`` find no sphere (docs/spheres.md, "A washed-out photo")."""
import json

import cv2
import numpy as np
import pytest

from ffls.spheres.detect import WASHED_OUT_SHARE, SequenceAccumulator


def _photos(n=6, shape=(16, 20, 3), seed=0):
    rng = np.random.default_rng(seed)
    return [rng.uniform(0.0, 0.6, shape).astype(np.float32) for _ in range(n)]


def test_accumulator_leaves_a_washed_out_photo_apart():
    ims = _photos()
    ims[3] = np.ones_like(ims[3])  # clipped everywhere
    acc = SequenceAccumulator(colour=False, edges=False)
    for i, im in enumerate(ims):
        acc.add(im, i, full_scale=1.0 if i == 3 else 0.0)
    st = acc.result()
    assert st.washed_out == ((3, 1.0),) and st.n == 5
    good = [im for i, im in enumerate(ims) if i != 3]
    np.testing.assert_array_equal(st.max, np.max(good, axis=0))
    assert 3 not in np.unique(st.brightest)
    # cut in chunks and merged in order: the same
    a, b = SequenceAccumulator(colour=False, edges=False), SequenceAccumulator(colour=False, edges=False)
    for i, im in enumerate(ims):
        (a if i < 4 else b).add(im, i, full_scale=1.0 if i == 3 else None)
    m = a.merge(b).result()
    assert m.washed_out == st.washed_out and m.n == 5
    np.testing.assert_array_equal(m.brightest, st.brightest)
    # a share at the limit is kept; where every photo is washed out, all of them are used
    c = SequenceAccumulator(colour=False, edges=False)
    for i, im in enumerate(ims):
        c.add(im, i, full_scale=WASHED_OUT_SHARE)
    assert c.result().n == 6 and c.result().washed_out == ()
    d = SequenceAccumulator(colour=False, edges=False)
    for i, im in enumerate(ims):
        d.add(im, i, full_scale=0.9)
    assert d.result().n == 6 and d.result().washed_out == ()
    np.testing.assert_array_equal(d.result().max, np.max(ims, axis=0))


@pytest.fixture(scope="module")
def overexposed_capture(tmp_path_factory):
    """Two grey balls, a long lens, 16-bit TIFFs of an unstated encoding, 12 lights; photo 5 three
    stops over (91% of its pixels at full scale)."""
    from ffls.cli import main

    cap = tmp_path_factory.mktemp("washed") / "cap"
    assert main(["synth", str(cap), "--lights", "12", "--resolution", "256", "--lens", "orthographic",
                 "--spheres", "2", "--sphere-material", "grey", "--format", "tiff16", "--encoding", "srgb",
                 "--unstated-encoding", "--exposure", "3", "--seed", "4", "--quiet"]) == 0
    path = str(cap / "img_0005.tiff")
    codes = cv2.imread(path, cv2.IMREAD_UNCHANGED).astype(np.float64)
    cv2.imwrite(path, np.clip(codes * 8, 0, 65535).astype(np.uint16))
    return cap


def test_lights_finds_the_spheres_past_an_overexposed_photo(overexposed_capture, tmp_path, capfd):
    """Before: one ball set aside (``its shading does not change across the 12 photos``: the
    overexposed photo the brightest on 94% of it), 10/12 lights at 1.37 / 19.12 deg median / max.
    After: both balls, the photo named and rejected as saturated, 10/12 at 0.75 / 1.31 deg (the
    capture without the overexposed photo: 0.74 / 1.26)."""
    from ffls.cli import main

    out = tmp_path / "lights.json"
    capfd.readouterr()
    assert main(["lights", str(overexposed_capture), "-o", str(out), "--workers", "1", "--no-progress"]) == 0
    captured = capfd.readouterr()
    line = next(x for x in captured.err.splitlines() if "full scale" in x)
    assert "'img_0005.tiff'" in line and "left out of finding the spheres" in line, line
    assert "2 spheres found" in captured.out
    got = json.loads(out.read_text())["lights"]
    assert got[5]["status"] == "rejected" and got[5]["reason"] == "saturated"
    truth = json.loads((overexposed_capture / "truth.json").read_text())["directions"]
    err = [np.degrees(np.arccos(np.clip(np.dot(truth[i], e["direction"]), -1, 1)))
           for i, e in enumerate(got) if e["status"] == "ok"]
    assert len(err) >= 9 and max(err) < 2.0, err


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_full_scale_share_counts_pixels_with_any_channel_at_the_top_code(dtype):
    from ffls.radiance.photos import Photo, full_scale_share

    top = np.iinfo(dtype).max
    rng = np.random.default_rng(1)
    codes = rng.integers(0, top, (20, 30, 3), dtype=dtype)
    codes[rng.random((20, 30, 3)) < 0.2] = top
    want = np.count_nonzero(codes.max(axis=2) == top) / 600
    raw = codes.astype(np.float32) / np.float32(top)
    depth = 8 if dtype == np.uint8 else 16
    assert full_scale_share(Photo(raw, raw, depth, codes)) == pytest.approx(want)
    assert full_scale_share(Photo(raw, raw, depth, None)) == pytest.approx(want)  # from raw
    assert full_scale_share(Photo(raw, raw, "half", None)) is None  # a float file does not clip


def test_a_repeated_photo_is_named_in_the_coverage_line():
    """A photo copied twice into a set gives its light twice: the coverage line said only "1 light
    repeats the direction of an earlier one"; with the photos' names it says which."""
    from ffls.synth.scene import stratified_directions
    from ffls.weights.voronoi import coverage_warnings

    d = stratified_directions(40)
    d = np.concatenate([d[:10], d[9:10], d[10:]])  # photo 10 a copy of photo 9
    names = [f"img_{i:04d}.tiff" for i in range(len(d))]
    line = next(x for x in coverage_warnings(d, names=names) if "repeat" in x)
    assert "'img_0010.tiff' repeats 'img_0009.tiff'" in line, line
    assert "img_" not in next(x for x in coverage_warnings(d) if "repeat" in x)


def test_find_spheres_in_capture_reading_the_photos_itself_leaves_it_apart(overexposed_capture):
    """The path that reads the photos itself (the Dask cluster's, ``find_spheres_in_capture``
    without ``stats``) keeps the overexposed photo apart too: both balls."""
    import dataclasses

    from ffls.io.capture import load_capture
    from ffls.spheres.detect import find_spheres_in_capture

    cap = dataclasses.replace(load_capture(overexposed_capture), encoding="srgb")
    assert len(find_spheres_in_capture(cap)) == 2
