"""ffls.lightmaps.lightmap: loading, layout detection, validation, crosses, procedural maps, the CLI."""
from __future__ import annotations

import numpy as np
import pytest

from ffls import conventions
from ffls.lightmaps import lightmap
from ffls.assets import builtin_lightmaps
from ffls.errors import FflsError, InputError
from ffls.io.images import read_image, write_exr, write_hdr
from ffls.lightmaps.lightmap import LightMap, LightMapWarning


def _one_line(e: Exception, name: str) -> None:
    assert "\n" not in str(e)
    assert name in str(e)


# ----------------------------------------------------------------------------- bundled maps
@pytest.mark.parametrize("name", sorted(builtin_lightmaps()))
def test_bundled_maps_load_with_clamp_warning(name):
    path = builtin_lightmaps()[name]
    raw = read_image(path).pixels
    n_neg = int(np.count_nonzero((raw < 0).any(axis=-1)))
    assert n_neg > 0  # real-world input: lossy compression leaves tiny negatives
    with pytest.warns(LightMapWarning, match=rf"clamped {n_neg} pixels") as rec:
        lm = lightmap.load_lightmap(path)
    assert path.name in str(rec[0].message)
    assert lm.layout == "latlong" and lm.data.shape == (512, 1024, 3)
    assert lm.clamped_negatives == n_neg
    assert lm.data.min() >= 0 and np.all(np.isfinite(lm.data))
    np.testing.assert_array_equal(lm.data, np.maximum(raw, 0))


def test_builtin_lightmap_names():
    lm = lightmap.builtin_lightmap("studio")  # no warning escapes: the count is recorded
    assert lm.clamped_negatives > 0 and lm.data.min() >= 0
    assert lightmap.builtin_lightmap("sky", height=16).data.shape == (16, 32, 3)
    assert lightmap.builtin_lightmap("paper", height=16).source == "paper"
    with pytest.raises(FflsError, match="courtyard"):
        lightmap.builtin_lightmap("nonexistent")


# ----------------------------------------------------------------------------- layout detection
@pytest.mark.parametrize("hw,layout", [((8, 16), "latlong"), ((8, 8), "angular"), ((12, 16), "cube"), ((16, 12), "cube")])
def test_detect_layout(hw, layout):
    assert lightmap.detect_layout(*hw) == layout


def test_detect_layout_explicit_and_bad():
    assert lightmap.detect_layout(8, 8, "mirrorball") == "mirrorball"
    with pytest.raises(ValueError, match="cannot be a latlong"):
        lightmap.detect_layout(8, 8, "latlong")
    with pytest.raises(ValueError, match="fits no light-map layout"):
        lightmap.detect_layout(10, 15)


def test_load_square_is_angular_unless_told(tmp_path):
    write_exr(tmp_path / "sq.exr", np.ones((8, 8, 3)))
    assert lightmap.load_lightmap(tmp_path / "sq.exr").layout == "angular"
    assert lightmap.load_lightmap(tmp_path / "sq.exr", layout="mirrorball").layout == "mirrorball"


def test_load_bad_aspect_ratio(tmp_path):
    write_exr(tmp_path / "odd.exr", np.ones((10, 15, 3)))
    with pytest.raises(InputError, match="fits no light-map layout") as e:
        lightmap.load_lightmap(tmp_path / "odd.exr")
    _one_line(e.value, "odd.exr")


# ----------------------------------------------------------------------------- validation
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_inf_rejected_with_count(tmp_path, bad):
    data = np.ones((8, 16, 3), np.float32)
    data[1, 2, 0] = bad
    data[3, 4, :] = bad
    write_exr(tmp_path / "bad.exr", data)
    with pytest.raises(InputError, match="2 pixels with NaN or Inf") as e:
        lightmap.load_lightmap(tmp_path / "bad.exr")
    _one_line(e.value, "bad.exr")
    # where to look: a half-float sun over 65504 is stored as Inf (round 16: the count alone)
    assert "the first at column 2, row 1)" in str(e.value)


def test_overflowing_and_black_maps_refused(tmp_path):
    """A texel near float32's limit (3e38) made Inf pixels in ``ffls render`` and was written to a
    .hdr as 0; a map black everywhere lit nothing without a word. Each is one line naming the file."""
    data = np.ones((8, 16, 3), np.float32)
    data[2, 3] = 3e38
    write_exr(tmp_path / "fmax.exr", data)
    with pytest.raises(InputError, match="radiance up to 3e.38: beyond 1e.30") as e:
        lightmap.load_lightmap(tmp_path / "fmax.exr")
    _one_line(e.value, "fmax.exr")
    write_exr(tmp_path / "zero.exr", np.zeros((8, 16, 3), np.float32))
    assert lightmap.load_lightmap(tmp_path / "zero.exr").data.max() == 0  # (ffls lightmap info shows it)
    with pytest.raises(InputError, match="black everywhere") as e:
        lightmap.lightmap_from_spec(str(tmp_path / "zero.exr"))
    _one_line(e.value, "zero.exr")
    bright = LightMap(np.full((8, 16, 3), 2e38, np.float32), "latlong")
    with pytest.raises(FflsError, match="Radiance .hdr range"):
        lightmap.save_lightmap(bright, tmp_path / "b.hdr")
    assert not (tmp_path / "b.hdr").exists()


def test_negatives_clamped_with_count(tmp_path):
    data = np.ones((8, 16, 3), np.float32)
    data[0, 0, 1] = -0.5
    data[5, 5, :] = -1e-4
    data[6, 6, 2] = -2.0
    write_exr(tmp_path / "neg.exr", data)
    with pytest.warns(LightMapWarning, match="clamped 3 pixels") as rec:
        lm = lightmap.load_lightmap(tmp_path / "neg.exr")
    assert "neg.exr" in str(rec[0].message)
    assert lm.clamped_negatives == 3
    assert lm.data[0, 0, 1] == 0 and lm.data[6, 6, 2] == 0 and lm.data[0, 0, 0] == 1


def test_missing_and_corrupt_maps(tmp_path):
    with pytest.raises(InputError, match="not found") as e:
        lightmap.load_lightmap(tmp_path / "gone.exr")
    _one_line(e.value, "gone.exr")
    (tmp_path / "junk.hdr").write_bytes(b"#?RADIANCE\ngarbage")
    with pytest.raises(InputError) as e:
        lightmap.load_lightmap(tmp_path / "junk.hdr")
    _one_line(e.value, "junk.hdr")
    (tmp_path / "map.png").write_bytes(b"x")
    with pytest.raises(InputError, match=".exr or .hdr") as e:
        lightmap.load_lightmap(tmp_path / "map.png")
    _one_line(e.value, "map.png")


def test_lightmap_shape_checked():
    with pytest.raises(ValueError, match="does not fit"):
        LightMap(np.zeros((8, 8, 3)), "latlong")
    with pytest.raises(ValueError, match="layout"):
        LightMap(np.zeros((8, 16, 3)), "sphere")


# ----------------------------------------------------------------------------- save / load
@pytest.mark.parametrize("ext,half", [(".exr", False), (".exr", True), (".hdr", False)])
def test_save_load_round_trip(tmp_path, ext, half):
    lm = lightmap.paper_map(16)
    p = lightmap.save_lightmap(lm, tmp_path / f"m{ext}", half=half)
    back = lightmap.load_lightmap(p)
    assert back.layout == "latlong"
    # error relative to the pixel's largest channel (RGBE shares one exponent per pixel)
    tol = {(".exr", False): 0, (".exr", True): 1e-3, (".hdr", False): 1 / 128}[(ext, half)]
    err = np.abs(back.data - lm.data) / lm.data.max(axis=-1, keepdims=True)
    assert err.max() <= tol


def test_save_unknown_extension_writes_nothing(tmp_path):
    with pytest.raises(FflsError, match="use .exr or .hdr") as e:
        lightmap.save_lightmap(lightmap.constant_map(4), tmp_path / "m.png")
    _one_line(e.value, "m.png")
    with pytest.raises(FflsError, match="half"):
        lightmap.save_lightmap(lightmap.constant_map(4), tmp_path / "m.hdr", half=True)
    assert list(tmp_path.iterdir()) == []


def test_save_failure_leaves_no_partial_file(tmp_path, monkeypatch):
    import OpenEXR

    real = OpenEXR.File

    class Failing:
        def __init__(self, *a, **k):
            self.f = real(*a, **k)

        def __enter__(self):
            return self

        def __exit__(self, *a):
            return False

        def write(self, path):
            self.f.write(path)  # the whole file lands at the temporary path...
            raise OSError("simulated failure after writing")  # ...then the writer fails

    monkeypatch.setattr(OpenEXR, "File", Failing)
    with pytest.raises(OSError, match="simulated"):
        lightmap.save_lightmap(lightmap.constant_map(4), tmp_path / "m.exr")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- cube crosses
@pytest.mark.parametrize("orientation", ["horizontal", "vertical"])
def test_cross_matches_sphere_maps_cube(orientation):
    from ffls.lightmaps.sphere_maps import get_map

    R = 6
    d, mask = lightmap.cross_directions(R, orientation)
    assert mask.sum() == 6 * R * R
    faces = lightmap.cross_to_cube(d, orientation)
    np.testing.assert_allclose(faces, get_map("cube").directions(R), atol=1e-12)
    cross = lightmap.cube_to_cross(faces, orientation)
    np.testing.assert_array_equal(cross, np.where(mask[..., None], d, 0))


def test_cross_layout_is_continuous_and_centred_on_plus_x():
    R = 8
    d, _ = lightmap.cross_directions(R)
    # centre of the +X slot (row 1, column 1) looks at +X; top slot at +Z; bottom at -Z
    # pixel up-left of the slot centre: half a texel (1/R in face units) toward +Y (left) and +Z (up)
    np.testing.assert_allclose(d[R + R // 2 - 1, R + R // 2 - 1], conventions.normalize([1, 1 / R, 1 / R]), atol=1e-12)
    assert d[R // 2, R + R // 2, 2] > 0.9 and d[2 * R + R // 2, R + R // 2, 2] < -0.9
    # neighbouring pixels across a seam in the middle row are close (<= ~ a texel apart)
    row = d[R + R // 2]
    step = np.degrees(conventions.angle_between(row[:-1], row[1:]))
    assert step.max() < 2 * 90 / R
    col = d[:, R + R // 2]
    step = np.degrees(conventions.angle_between(col[:-1], col[1:]))
    assert step.max() < 2 * 90 / R


@pytest.mark.parametrize("orientation", ["horizontal", "vertical"])
def test_cube_file_round_trip(tmp_path, rng, orientation):
    R = 4
    faces = rng.random((6, R, R, 3)).astype(np.float32)
    cross = lightmap.cube_to_cross(faces, orientation)
    write_exr(tmp_path / "cross.exr", cross)
    lm = lightmap.load_lightmap(tmp_path / "cross.exr")
    assert lm.layout == "cube" and lm.data.shape == (6, R, R, 3)
    np.testing.assert_array_equal(lm.data, faces)
    lightmap.save_lightmap(lm, tmp_path / "again.exr")
    assert read_image(tmp_path / "again.exr").shape == (3 * R, 4 * R)
    np.testing.assert_array_equal(lightmap.load_lightmap(tmp_path / "again.exr").data, faces)


# ----------------------------------------------------------------------------- samples / integrals
@pytest.mark.parametrize("layout,shape", [("latlong", (8, 16, 3)), ("angular", (16, 16, 3)),
                                          ("mirrorball", (16, 16, 3)), ("cube", (6, 5, 5, 3))])
def test_constant_map_integrals(layout, shape):
    lm = LightMap(np.full(shape, 2.0), layout)
    d, rad, sa = lm.samples()
    assert d.shape == (len(sa), 3) and rad.shape == (len(sa), 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1, atol=1e-12)
    np.testing.assert_allclose(sa.sum(), 4 * np.pi, rtol=1e-9)
    np.testing.assert_allclose(lm.total_power(), 8 * np.pi, rtol=1e-9)
    # cosine-weighted irradiance of a constant map: pi * L
    np.testing.assert_allclose(lm.irradiance([0, 0, 1]), 2 * np.pi, rtol=0.05)


def test_upper_hemisphere_power():
    lm = lightmap.constant_map(32, (1.0, 2.0, 3.0))
    np.testing.assert_allclose(lm.total_power("upper"), 2 * np.pi * np.array([1, 2, 3]), rtol=1e-9)


def test_downsample_works_in_bands(rng, monkeypatch):
    """A large map is box-filtered band by band, never as a whole in float64 (a 16384 x 8192 map,
    relit with --map-res 512, peaked at 10 GB): the result is the whole-map solid-angle weighted
    mean, and the peak allocation stays under the map's own size."""
    import tracemalloc

    data = (rng.random((512, 1024, 3)) ** 4 * 50).astype(np.float32)
    lm = LightMap(data, "latlong")
    sa = lm.solid_angles()
    monkeypatch.setattr(lightmap, "DOWNSAMPLE_BAND_BYTES", 1 << 20)
    for f in (1, 2, 8, 64, 512):
        want = ((data.astype(np.float64) * sa[..., None]).reshape(512 // f, f, 1024 // f, f, 3).sum(axis=(1, 3))
                / sa.reshape(512 // f, f, 1024 // f, f).sum(axis=(1, 3))[..., None])
        np.testing.assert_allclose(lm.downsample(f).data, want, rtol=1e-6)
    tracemalloc.start()
    try:
        lm.downsample(8)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < data.nbytes, (peak, data.nbytes)


def test_info_statistics_work_in_bands(rng, monkeypatch):
    """``ffls lightmap info``'s statistics (stats, total_power, irradiance) sum a lat-long map band by
    band, never with float64 directions of the whole map (a 16384 x 8192 map peaked at 16 GB): the
    samples of the bands are :meth:`samples`' own, the sums the whole map's, the peak allocation
    under one float64 copy of the map."""
    import tracemalloc

    data = (rng.random((256, 512, 3)) ** 4 * 50).astype(np.float32)
    lm = LightMap(data, "latlong")
    monkeypatch.setattr(lightmap, "DOWNSAMPLE_BAND_BYTES", 1 << 16)
    d, rad, sa = lm.samples()
    bands = list(lm.sample_bands())
    assert len(bands) > 10
    for whole, parts in zip((d, rad, sa), zip(*bands)):
        np.testing.assert_array_equal(np.concatenate(parts), whole)
    st = lm.stats()
    np.testing.assert_array_equal(st["min"], rad.min(axis=0))
    np.testing.assert_array_equal(st["max"], rad.max(axis=0))
    np.testing.assert_allclose(st["mean"], (rad * sa[:, None]).sum(axis=0) / sa.sum(), rtol=1e-13)
    up = d[:, 2] >= 0
    np.testing.assert_allclose(lm.total_power("upper"), (rad[up] * sa[up, None]).sum(axis=0), rtol=1e-13)
    np.testing.assert_allclose(lm.total_power(), (rad * sa[:, None]).sum(axis=0), rtol=1e-13)
    n = conventions.normalize([0.2, -0.3, 1.0])
    np.testing.assert_allclose(lm.irradiance(n), (rad * (np.maximum(d @ n, 0) * sa)[:, None]).sum(axis=0),
                               rtol=1e-13)
    del d, rad, sa
    tracemalloc.start()
    try:
        lm.stats(), lm.total_power("upper"), lm.total_power(), lm.irradiance()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < data.size * 8, (peak, data.size * 8)


def test_load_peak_memory(rng, tmp_path, monkeypatch):
    """Reading a half-float map interleaves its planes in bands (no whole interleaved half copy: a
    8192 x 4096 map's read peaked at 2x its float32 size) and the validation holds one mask of the
    map's size at a time; the values are the file's, exactly."""
    import tracemalloc

    from ffls.io import images

    data = (rng.random((512, 1024, 3)) * 20).astype(np.float16).astype(np.float32)
    write_exr(tmp_path / "m.exr", data, half=True)
    monkeypatch.setattr(images, "EXR_BAND_BYTES", 1 << 16)
    tracemalloc.start()
    try:
        img = read_image(tmp_path / "m.exr")
        read_peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.reset_peak()
        got, clamped = lightmap.validate_radiance(img.pixels, "m.exr")
        check_peak = tracemalloc.get_traced_memory()[1] - tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    np.testing.assert_array_equal(got, data)
    assert clamped == 0
    assert read_peak < 1.75 * data.nbytes, (read_peak, data.nbytes)
    assert check_peak < 0.45 * data.nbytes, (check_peak, data.nbytes)


def test_downsample_keeps_integral(rng):
    lm = LightMap(rng.random((32, 64, 3)) * 10, "latlong")
    for f in (2, 4, 8, 32):
        small = lm.downsample(f)
        assert small.data.shape == (32 // f, 64 // f, 3)
        np.testing.assert_allclose(small.total_power(), lm.total_power(), rtol=1e-6)
    with pytest.raises(ValueError, match="divide"):
        lm.downsample(3)


def test_to_latlong_from_angular_keeps_constant():
    lm = LightMap(np.full((32, 32, 3), 0.5), "angular")
    ll = lm.to_latlong(16)
    assert ll.layout == "latlong" and ll.data.shape == (16, 32, 3)
    np.testing.assert_array_equal(ll.data, 0.5)


# ----------------------------------------------------------------------------- procedural maps
def test_sky_sun_map_sun_irradiance_is_exact():
    sun_dir = conventions.normalize([0.3, -0.4, 0.8])
    base = lightmap.sky_sun_map(64, sun_direction=sun_dir, sun_irradiance=0.0)
    for radius in (0.27, 3.0):  # smaller than a texel, and several texels
        lm = lightmap.sky_sun_map(64, sun_direction=sun_dir, sun_irradiance=(100.0, 90.0, 80.0),
                                  sun_angular_radius_deg=radius)
        np.testing.assert_allclose(lm.total_power() - base.total_power(), [100, 90, 80], rtol=1e-5)
    # the brightest texel is in the sun's direction; below the horizon it is dim
    d = conventions.latlong_directions(128, 64)
    j, i = np.unravel_index(np.argmax(lm.data.sum(-1)), lm.data.shape[:2])
    assert np.degrees(conventions.angle_between(d[j, i], sun_dir)) < 4
    assert lm.data[d[..., 2] < -0.1].max() < lm.data[d[..., 2] > 0.1].min()


def test_procedural_maps_deterministic_and_valid():
    a, b = lightmap.paper_map(32), lightmap.paper_map(32)
    np.testing.assert_array_equal(a.data, b.data)
    assert a.data.dtype == np.float32 and np.all(np.isfinite(a.data)) and a.data.min() > 0
    d = conventions.latlong_directions(64, 32)

    def colour_toward(v):
        k = np.argmax(d.reshape(-1, 3) @ conventions.normalize(v))
        return a.data.reshape(-1, 3)[k]

    r = colour_toward([0, 1, 0.6])   # behind: red
    y = colour_toward([0, -1, 0.6])  # front: yellow
    assert r[0] > 3 * r[1] and y[0] > 2 * y[2] and y[1] > 2 * y[2]
    assert np.all(colour_toward([0, 0, -1]) < 0.05)  # dark background


# ----------------------------------------------------------------------------- CLI
def test_cli_info_convert_make(tmp_path, capsys):
    from ffls.cli import main

    out = tmp_path / "sky.exr"
    assert main(["lightmap", "make", "sky", str(out), "--height", "16"]) == 0
    assert main(["lightmap", "convert", str(out), str(tmp_path / "sky.hdr")]) == 0
    assert read_image(tmp_path / "sky.hdr").shape == (16, 32)
    capsys.readouterr()
    assert main(["lightmap", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "latlong" in text and "32x16" in text and "upper hemisphere" in text and "clamped to 0: 0" in text
    assert main(["lightmap", "convert", str(out), str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "x.png" in err and err.count("\n") == 1
    assert not (tmp_path / "x.png").exists()


def test_write_hdr_of_procedural_map(tmp_path):
    write_hdr(tmp_path / "p.hdr", lightmap.paper_map(8).data)
    assert lightmap.load_lightmap(tmp_path / "p.hdr").data.shape == (8, 16, 3)


def test_lightmap_from_spec_file_builtin_and_errors(tmp_path):
    from ffls.errors import FflsError, InputError
    from ffls.lightmaps.lightmap import constant_map, lightmap_from_spec, save_lightmap

    save_lightmap(constant_map(8, 0.25), tmp_path / "grey.exr")
    assert lightmap_from_spec(tmp_path / "grey.exr").data.max() == pytest.approx(0.25)
    assert lightmap_from_spec("sky").layout == "latlong"
    with pytest.raises(InputError, match="missing.exr: light map not found"):
        lightmap_from_spec(tmp_path / "missing.exr")
    with pytest.raises(FflsError, match="built-in maps"):
        lightmap_from_spec("nosuchmap")
