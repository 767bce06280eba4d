"""The decoding shortcuts of `ffls lights` give the same numbers as the plain paths.

- ``read_image(out=...)`` widens an EXR into the caller's array (no copy), with the same values;
- ``read_photo`` keeps an integer file's codes (``Photo.codes``), equal to ``raw`` re-quantised;
- ``sphere_values`` judges integer codes (saturated, clipped black) without a float copy, with
  the validity and saturated count of the float path (:func:`ffls.radiance.response.valid_pixel_mask`).
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from ffls.io.images import read_image, write_exr, write_png
from ffls.radiance.photos import read_photo
from ffls.spheres.samples import SphereSamples, sphere_values


def _exr(tmp_path, half=True):
    rng = np.random.default_rng(3)
    rgb = rng.uniform(0.0, 4.0, (24, 32, 3)).astype(np.float32)
    return write_exr(tmp_path / "a.exr", rgb, half=half)


@pytest.mark.parametrize("half", [True, False])
def test_read_image_widens_exr_into_out(tmp_path, half):
    path = _exr(tmp_path, half)
    plain = read_image(path)
    out = np.full((24, 32, 3), -1.0, np.float32)
    img = read_image(path, out=out)
    assert img.pixels is out
    np.testing.assert_array_equal(out, plain.pixels)
    assert img.bit_depth == plain.bit_depth == ("half" if half else "float")


def test_read_image_out_of_another_shape_or_type_is_ignored(tmp_path):
    path = _exr(tmp_path)
    plain = read_image(path)
    for out in (np.zeros((24, 31, 3), np.float32), np.zeros((24, 32, 3), np.float64),
                np.zeros((32, 24, 3), np.float32).transpose(1, 0, 2)):
        before = out.copy()
        img = read_image(path, out=out)
        assert img.pixels is not out
        np.testing.assert_array_equal(img.pixels, plain.pixels)
        np.testing.assert_array_equal(out, before)  # untouched


def test_read_image_widens_every_half_value_exactly(tmp_path):
    """Every finite half value (subnormals, -0 and both infinities too) reads back as the same
    float32, bit for bit, into ``out`` or not: the widening is exact."""
    halves = np.arange(65536, dtype=np.uint16).view(np.float16)
    halves = halves[~np.isnan(halves)]
    rgb = np.concatenate([halves, np.zeros(-halves.size % 192, np.float16)]).reshape(64, -1, 3)
    path = write_exr(tmp_path / "all.exr", rgb.astype(np.float32), half=True)
    want = rgb.astype(np.float32).view(np.uint32)
    img = read_image(path, allow_nonfinite=True)
    assert img.bit_depth == "half" and img.pixels.dtype == np.float32
    np.testing.assert_array_equal(img.pixels.view(np.uint32), want)
    out = np.empty(rgb.shape, np.float32)
    assert read_image(path, allow_nonfinite=True, out=out).pixels is out
    np.testing.assert_array_equal(out.view(np.uint32), want)


def _capture(tmp_path, name, codes, encoding="srgb"):
    write_png(tmp_path / name, codes)
    (tmp_path / "capture.json").write_text(json.dumps({"format": "ffls-capture", "version": 1, "images": [name], "encoding": encoding}))
    from ffls.io.capture import load_capture

    return load_capture(tmp_path)


@pytest.mark.parametrize("dtype,top", [(np.uint8, 255), (np.uint16, 65535)])
def test_read_photo_keeps_the_codes(tmp_path, dtype, top):
    rng = np.random.default_rng(0)
    codes = rng.integers(0, top + 1, (16, 20, 3)).astype(dtype)
    ph = read_photo(_capture(tmp_path, "a.png", codes), 0)
    assert ph.codes is not None and ph.codes.dtype == dtype
    np.testing.assert_array_equal(ph.codes, codes)
    np.testing.assert_array_equal(np.rint(np.clip(ph.raw, 0.0, 1.0) * top).astype(dtype), ph.codes)


def test_read_photo_of_an_exr_has_no_codes(tmp_path):
    path = _exr(tmp_path)
    (tmp_path / "capture.json").write_text(json.dumps({"format": "ffls-capture", "version": 1, "images": [path.name]}))
    from ffls.io.capture import load_capture

    ph = read_photo(load_capture(tmp_path), 0)
    assert ph.codes is None


@pytest.mark.parametrize("bit_depth,dtype,top", [(8, np.uint8, 255), (16, np.uint16, 65535)])
def test_sphere_values_of_integer_codes_match_the_float_path(bit_depth, dtype, top):
    rng = np.random.default_rng(7)
    h, w = 40, 50
    codes = rng.integers(0, top + 1, (h, w, 3)).astype(dtype)
    codes[:5] = 0  # clipped black in every channel
    codes[5:8, :, 1] = top  # one saturated channel
    k = int(np.ceil(0.98 * top))  # around the saturation threshold (0.98 of full scale)
    codes[8:10, :, 2] = rng.integers(k - 2, k + 2, (2, w))
    codes[10:12, :, :2] = 0  # black in two channels only: not clipped
    codes[10:12, :, 2] = rng.integers(1, 4, (2, w))
    rows, cols = (x.ravel() for x in np.mgrid[0:h, 0:w])
    m = rows.size
    normals = np.tile([0.0, 0.0, 1.0], (m, 1))
    s = SphereSamples(rows, cols, normals, np.zeros((m, 3)), np.zeros(3), 1.0, 10.0)
    image = codes.astype(np.float32) / np.float32(top)
    (a,) = sphere_values(image, [s], raw=codes, bit_depth=bit_depth)
    (b,) = sphere_values(image, [s], raw=image, bit_depth=bit_depth)  # the stored values as floats
    np.testing.assert_array_equal(a.valid, b.valid)
    assert a.n_saturated == b.n_saturated > 0
    np.testing.assert_array_equal(a.grey, b.grey)
    assert not a.valid[:5 * w].any() and not a.valid[5 * w:8 * w].any()


def test_sequence_accumulator_stowed_in_buffers_gives_the_same_stats():
    """A worker's reductions handed over through buffers (``stow``, pickled without its arrays,
    ``unstow``) merge to exactly what the accumulators give directly."""
    import pickle

    from ffls.spheres.detect import SequenceAccumulator

    rng = np.random.default_rng(5)
    photos = rng.uniform(0.0, 1.0, (6, 40, 56, 3)).astype(np.float32)
    direct, parts = [], []
    for lo, hi in ((0, 3), (3, 6)):
        a, b = SequenceAccumulator(n_images=6), SequenceAccumulator(n_images=6)
        for i in range(lo, hi):
            a.add(photos[i], i)
            b.add(photos[i], i)
        direct.append(a)
        buffers = {k: np.zeros(shape, dtype) for k, (shape, dtype) in b.layout(photos.shape[1:]).items()}
        assert set(buffers) == set(SequenceAccumulator.ARRAYS)
        sent = pickle.dumps(b.stow(buffers))
        assert len(sent) < 2000  # the arrays are in the buffers, not in the pickle
        parts.append(pickle.loads(sent).unstow(buffers, copy=not parts))
    want = direct[0].merge(direct[1]).result()
    got = parts[0].merge(parts[1]).result()
    for name in ("max", "brightest", "mean", "colour_counts", "edge_tensor"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
    assert (got.n, got.edge_photos) == (want.n, want.edge_photos)


def test_read_image_keeps_a_half_exr_as_stored(tmp_path):
    """``read_image(stored=...)`` interleaves a half EXR's values into the caller's float16 array
    as stored (``decode_photos`` keeps them there), and widens them as without it; a float EXR, or
    an array of another size, is left untouched."""
    path = _exr(tmp_path, half=True)
    plain = read_image(path)
    stored = np.full((24, 32, 3), -1.0, np.float16)
    out = np.empty((24, 32, 3), np.float32)
    img = read_image(path, out=out, stored=stored)
    assert img.pixels is out and img.bit_depth == "half"
    np.testing.assert_array_equal(out.view(np.uint32), plain.pixels.view(np.uint32))
    np.testing.assert_array_equal(stored.astype(np.float32).view(np.uint32), plain.pixels.view(np.uint32))
    for shape, half in (((24, 32, 3), False), ((24, 31, 3), True)):
        other = np.full(shape, -1.0, np.float16)
        img = read_image(_exr(tmp_path, half), stored=other)
        assert np.all(other == -1.0)
        np.testing.assert_array_equal(img.pixels, read_image(_exr(tmp_path, half)).pixels)


def test_sequence_accumulator_made_in_its_buffers():
    """An accumulator given its buffers makes its reductions in them (a worker's shared memory:
    ``stow`` then copies nothing, and pickles neither arrays nor buffers), with the same stats as
    one without; buffers of another shape or type are not used."""
    import pickle

    from ffls.spheres.detect import SequenceAccumulator

    rng = np.random.default_rng(6)
    photos = rng.uniform(0.0, 1.0, (4, 40, 56, 3)).astype(np.float32)
    plain = SequenceAccumulator(n_images=4)
    layout = plain.layout(photos.shape[1:])
    buffers = {k: np.full(shape, 7, dtype) for k, (shape, dtype) in layout.items()}  # (not zeroed)
    wrong = {"max": np.zeros((40, 55, 3), np.float32), "total": np.zeros((40, 56), np.float32)}
    made, other = SequenceAccumulator(n_images=4, buffers=buffers), SequenceAccumulator(n_images=4, buffers=wrong)
    for i, ph in enumerate(photos):
        for acc in (plain, made, other):
            acc.add(ph, i)
    assert all(getattr(made, k) is buffers[k] for k in layout)
    assert made.max is not wrong["max"] and other.total is not wrong["total"] and not wrong["max"].any()
    want = plain.result()
    sent = pickle.dumps(made.stow(buffers))
    assert len(sent) < 2000
    got = pickle.loads(sent).unstow(buffers).result()
    for name in ("max", "brightest", "mean", "colour_counts", "edge_tensor"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
        np.testing.assert_array_equal(getattr(other.result(), name), getattr(want, name))


@pytest.mark.parametrize("encoding", ["srgb", {"gamma": 2.2}])
@pytest.mark.parametrize("dtype,top", [(np.uint8, 255), (np.uint16, 65535)])
def test_kept_codes_linearised_by_their_table(monkeypatch, encoding, dtype, top):
    """A kept integer photo linearised whole (``DecodedPhotos.photo``, e.g. the reductions of
    ``linear_stats``) has the curve evaluated at the float values, exactly, but by a table of its
    codes: no curve is evaluated at each of its pixels."""
    from types import SimpleNamespace

    from ffls.io.images import ImageData
    from ffls.radiance import photos
    from ffls.spheres.estimate import DecodedPhotos

    rng = np.random.default_rng(5)
    codes = rng.integers(0, top + 1, (1, 30, 40, 3)).astype(dtype)
    depth = 8 if dtype == np.uint8 else 16
    want = photos.linearise(ImageData(codes[0].astype(np.float32) / np.float32(top), depth, "png", None), encoding)
    stats = SimpleNamespace(n=1, max=np.zeros((30, 40, 3), np.float32))
    decoded = DecodedPhotos(stats=stats, bit_depths={depth}, encoding=encoding, linear=None, raw=codes)
    sizes = []
    for name in ("srgb_decode", "gamma_decode"):
        real = getattr(photos, name)
        monkeypatch.setattr(photos, name, lambda x, *a, real=real: sizes.append(np.size(x)) or real(x, *a))
    photos.code_table.cache_clear()
    linear, kept, got_depth = decoded.photo(0)
    np.testing.assert_array_equal(linear, want)
    assert np.shares_memory(kept, codes) and got_depth == depth
    assert sizes == [top + 1]  # the table's codes only, not the photo's 3600 values
