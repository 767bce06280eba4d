"""ffls.io.images and ffls.display.tonemap: round trips, error messages, atomic writes, sRGB curves."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.display import tonemap
from ffls.radiance import encoding
from ffls.io import images as imageio
from ffls.errors import InputError, OutputError


def _one_line(e: Exception, name: str) -> None:
    s = str(e)
    assert "\n" not in s
    assert name in s


# ----------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("shape", [(5, 7, 3), (1, 1, 3), (16, 9, 3)])
def test_exr_float_round_trip_exact(tmp_path, rng, shape):
    rgb = (rng.standard_normal(shape) * 100).astype(np.float32)
    p = imageio.write_exr(tmp_path / "a.exr", rgb)
    img = imageio.read_image(p)
    assert img.bit_depth == "float" and img.kind == "exr"
    assert img.pixels.dtype == np.float32 and img.pixels.shape == shape
    np.testing.assert_array_equal(img.pixels, rgb)


def test_exr_non_contiguous_input(tmp_path, rng):
    big = rng.random((10, 12, 4)).astype(np.float32)
    rgb = big[::2, ::3, 1:]  # a strided view
    imageio.write_exr(tmp_path / "a.exr", rgb)
    np.testing.assert_array_equal(imageio.read_image(tmp_path / "a.exr").pixels, rgb)


def test_exr_string_attributes_round_trip_and_bad_ones_are_refused(tmp_path, rng):
    import OpenEXR

    rgb = rng.random((4, 6, 3)).astype(np.float32)
    p = imageio.write_exr(tmp_path / "a.exr", rgb, attributes={"ffls:pocs_scheme": "least-power"})
    assert OpenEXR.File(str(p)).header()["ffls:pocs_scheme"] == "least-power"
    assert np.array_equal(imageio.read_image(p).pixels, rgb)
    for bad in ({"ffls:n": 3}, {"compression": "none"}, {"dataWindow": "x"}):
        with pytest.raises(ValueError, match="attribute"):
            imageio.write_exr(tmp_path / "b.exr", rgb, attributes=bad)
    assert not (tmp_path / "b.exr").exists()


def test_exr_half_round_trip(tmp_path, rng):
    rgb = (rng.random((6, 8, 3)) * 1000).astype(np.float32)
    imageio.write_exr(tmp_path / "h.exr", rgb, half=True)
    img = imageio.read_image(tmp_path / "h.exr")
    assert img.bit_depth == "half"
    np.testing.assert_array_equal(img.pixels, rgb.astype(np.float16).astype(np.float32))


def test_exr_half_overflow_rejected(tmp_path):
    rgb = np.full((2, 2, 3), 1e5, np.float32)
    with pytest.raises(ValueError, match="half"):
        imageio.write_exr(tmp_path / "h.exr", rgb, half=True)
    assert list(tmp_path.iterdir()) == []


def test_exr_half_overflow_is_one_line_naming_the_output(tmp_path):
    """write_exr itself makes the commands' check (``check_half_range``, called before it at three
    sites): an OutputError naming the path, the commands' one line with status 2."""
    rgb = np.full((2, 2, 3), 1e5, np.float32)
    with pytest.raises(OutputError) as e:
        imageio.write_exr(tmp_path / "h.exr", rgb, half=True)
    assert str(e.value) == (f"{tmp_path / 'h.exr'}: values up to 100000 exceed the half-float range (65504): "
                            "write float (without --half / half=False)")


def test_exr_luminance_only_is_replicated(tmp_path):
    import OpenEXR

    y = np.arange(12, dtype=np.float32).reshape(3, 4)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, {"Y": y}) as f:
        f.write(str(tmp_path / "y.exr"))
    img = imageio.read_image(tmp_path / "y.exr")
    assert img.pixels.shape == (3, 4, 3)
    for c in range(3):
        np.testing.assert_array_equal(img.pixels[..., c], y)


def test_exr_luminance_chroma_is_refused_not_read_as_grey(tmp_path):
    import OpenEXR

    ones = np.ones((2, 2), np.float32)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"Y": ones, "RY": 0.2 * ones, "BY": -0.1 * ones}) as f:
        f.write(str(tmp_path / "yc.exr"))
    with pytest.raises(InputError, match=r"luminance and chroma channels \(BY, RY, Y\).*convert it to RGB") as e:
        imageio.read_image(tmp_path / "yc.exr")
    _one_line(e.value, "yc.exr")


def test_exr_without_colour_channels_rejected(tmp_path):
    import OpenEXR

    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"Z": np.ones((2, 2), np.float32)}) as f:
        f.write(str(tmp_path / "z.exr"))
    with pytest.raises(InputError, match=r"needs the channels R, G and B, or Y .luminance.; it has \[.Z.\]") as e:
        imageio.read_image(tmp_path / "z.exr")
    _one_line(e.value, "z.exr")


def test_exr_multi_part_and_offset_data_window_refused(tmp_path):
    """Only the first part of a multi-part file was read, as if it were the image; a data window
    other than the display window was read at the origin, its pixels misplaced."""
    import OpenEXR

    head = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    rgb = {c: np.ones((6, 6), np.float32) for c in "RGB"}
    parts = [OpenEXR.Part(dict(head, name="black"), {c: np.zeros((6, 6), np.float32) for c in "RGB"}),
             OpenEXR.Part(dict(head, name="photo"), rgb)]
    with OpenEXR.File(parts) as f:
        f.write(str(tmp_path / "two.exr"))
    with pytest.raises(InputError, match="has 2 parts") as e:
        imageio.read_image(tmp_path / "two.exr")
    _one_line(e.value, "two.exr")
    window = dict(head, dataWindow=(np.array([2, 2], np.int32), np.array([7, 7], np.int32)),
                  displayWindow=(np.array([0, 0], np.int32), np.array([5, 5], np.int32)))
    with OpenEXR.File(window, rgb) as f:
        f.write(str(tmp_path / "win.exr"))
    with pytest.raises(InputError, match=r"data window \(2,2\)-\(7,7\) differs from its display window") as e:
        imageio.read_image(tmp_path / "win.exr")
    _one_line(e.value, "win.exr")


def test_tiff_grey_alpha_keeps_its_alpha(tmp_path):
    """OpenCV decodes a grey + alpha TIFF as grey and drops the alpha: it is read by Pillow, so a
    transparent photo is seen as such (as a grey + alpha PNG is)."""
    from PIL import Image

    grey = np.full((6, 8), 120, np.uint8)
    alpha = np.full((6, 8), 255, np.uint8)
    alpha[:3] = 0
    Image.merge("LA", (Image.fromarray(grey), Image.fromarray(alpha))).save(tmp_path / "la.tif")
    img = imageio.read_image(tmp_path / "la.tif")
    assert img.alpha is not None and img.alpha[:3].max() == 0 and img.alpha[3:].min() == 1
    assert np.all(img.pixels == img.pixels[0, 0]) and img.pixels.shape == (6, 8, 3)
    Image.fromarray(grey).save(tmp_path / "l.tif")  # no alpha: none made up
    assert imageio.read_image(tmp_path / "l.tif").alpha is None


def test_undecodable_files_say_why(tmp_path):
    """A valid file OpenCV does not decode is told from a corrupt one: a PNG header claiming
    34000 x 34000 pixels (beyond OpenCV's limit), a TIFF of a sample format it does not read."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 34000, 34000, 8, 0, 0, 0, 0))
    (tmp_path / "huge.png").write_bytes(png + chunk(b"IEND", b""))
    with pytest.raises(InputError, match="34000x34000 is beyond OpenCV's limit of 2.30 pixels") as e:
        imageio.read_image(tmp_path / "huge.png")
    _one_line(e.value, "huge.png")
    (tmp_path / "junk.tif").write_bytes(b"II*\x00junk")
    with pytest.raises(InputError, match="sample format such as 16-bit float") as e:
        imageio.read_image(tmp_path / "junk.tif")
    _one_line(e.value, "junk.tif")


def test_hdr_round_trip(tmp_path, rng):
    rgb = (rng.random((8, 16, 3)) * 50 + 0.01).astype(np.float32)
    rgb[0, 0] = [10.0, 0.5, 0.02]  # distinct channels catch a BGR/RGB swap
    imageio.write_hdr(tmp_path / "a.hdr", rgb)
    img = imageio.read_image(tmp_path / "a.hdr")
    assert img.kind == "hdr" and img.bit_depth == "float"
    # RGBE: 8-bit mantissa with a shared exponent -> relative error below 1/128 of the max channel
    err = np.abs(img.pixels - rgb) / rgb.max(axis=-1, keepdims=True)
    assert err.max() < 1 / 128
    assert img.pixels[0, 0, 0] > img.pixels[0, 0, 1] > img.pixels[0, 0, 2]


def test_hdr_rejects_negative_and_nan(tmp_path):
    with pytest.raises(ValueError, match="negative"):
        imageio.write_hdr(tmp_path / "a.hdr", -np.ones((2, 2, 3)))
    with pytest.raises(ValueError, match="non-finite"):
        imageio.write_hdr(tmp_path / "a.hdr", np.full((2, 2, 3), np.nan))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("dtype,scale,depth", [(np.uint8, 255, 8), (np.uint16, 65535, 16)])
def test_png_round_trip(tmp_path, rng, dtype, scale, depth):
    img = rng.integers(0, scale + 1, size=(7, 5, 3)).astype(dtype)
    img[0, 0] = [scale, 0, 0]  # pure red must stay red
    imageio.write_png(tmp_path / "a.png", img)
    back = imageio.read_image(tmp_path / "a.png")
    assert back.bit_depth == depth and back.kind == "png"
    np.testing.assert_array_equal(np.rint(back.pixels * scale).astype(dtype), img)
    np.testing.assert_array_equal(back.pixels[0, 0], [1, 0, 0])


def test_png_grey_and_rgba(tmp_path, rng):
    grey = rng.integers(0, 256, size=(4, 6)).astype(np.uint8)
    imageio.write_png(tmp_path / "g.png", grey)
    g = imageio.read_image(tmp_path / "g.png").pixels
    assert g.shape == (4, 6, 3)
    np.testing.assert_array_equal(g[..., 0], g[..., 2])
    rgba = rng.integers(0, 256, size=(4, 6, 4)).astype(np.uint8)
    imageio.write_png(tmp_path / "c.png", rgba)
    c = imageio.read_image(tmp_path / "c.png").pixels
    np.testing.assert_array_equal(np.rint(c * 255).astype(np.uint8), rgba[..., :3])


def test_png_rejects_float(tmp_path):
    with pytest.raises(ValueError, match="float input"):
        imageio.write_png(tmp_path / "a.png", np.zeros((2, 2, 3), np.float32))
    assert list(tmp_path.iterdir()) == []


def test_jpeg_and_tiff_read(tmp_path, rng):
    import cv2

    img = np.zeros((8, 8, 3), np.uint8)
    img[..., 2] = 200  # BGR: red
    cv2.imwrite(str(tmp_path / "a.jpg"), img)
    j = imageio.read_image(tmp_path / "a.jpg")
    assert j.kind == "jpeg" and j.bit_depth == 8
    assert j.pixels[..., 0].mean() > 0.7 and j.pixels[..., 2].mean() < 0.1
    t16 = rng.integers(0, 65536, size=(3, 4, 3)).astype(np.uint16)
    cv2.imwrite(str(tmp_path / "a.tif"), t16)
    t = imageio.read_image(tmp_path / "a.tif")
    assert t.kind == "tiff" and t.bit_depth == 16
    np.testing.assert_array_equal(np.rint(t.pixels * 65535).astype(np.uint16), t16[..., ::-1])


# ----------------------------------------------------------------------------- errors
def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found") as e:
        imageio.read_image(tmp_path / "missing.png")
    _one_line(e.value, "missing.png")


@pytest.mark.parametrize("name", ["bad.png", "bad.exr", "bad.hdr", "bad.jpg", "empty.tif"])
def test_corrupt_file(tmp_path, name):
    (tmp_path / name).write_bytes(b"" if name.startswith("empty") else b"not an image at all" * 20)
    with pytest.raises(InputError) as e:
        imageio.read_image(tmp_path / name)
    _one_line(e.value, name)


def test_truncated_exr(tmp_path, rng):
    imageio.write_exr(tmp_path / "a.exr", rng.random((64, 64, 3)).astype(np.float32))
    data = (tmp_path / "a.exr").read_bytes()
    (tmp_path / "t.exr").write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError) as e:
        imageio.read_image(tmp_path / "t.exr")
    _one_line(e.value, "t.exr")


def test_tga_rejected_with_reason(tmp_path):
    (tmp_path / "a.tga").write_bytes(b"\0" * 40)
    with pytest.raises(InputError, match="TGA") as e:
        imageio.read_image(tmp_path / "a.tga")
    _one_line(e.value, "a.tga")


def test_unknown_extension(tmp_path):
    (tmp_path / "a.xyz").write_bytes(b"\0")
    with pytest.raises(InputError, match="unsupported") as e:
        imageio.read_image(tmp_path / "a.xyz")
    _one_line(e.value, "a.xyz")


def test_writer_failure_leaves_nothing(tmp_path, monkeypatch):
    import OpenEXR

    class Boom:
        def __init__(self, *a, **k):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *a):
            return False

        def write(self, path):
            with open(path, "wb") as f:
                f.write(b"half")  # a partial file
            raise RuntimeError("disk full")

    monkeypatch.setattr(OpenEXR, "File", Boom)
    with pytest.raises(OutputError, match="disk full"):  # one line naming the file (docs/reliability.md)
        imageio.write_exr(tmp_path / "out.exr", np.zeros((2, 2, 3)))
    assert list(tmp_path.iterdir()) == []


def test_wrong_extension_for_writer(tmp_path):
    with pytest.raises(ValueError, match=".exr"):
        imageio.write_exr(tmp_path / "a.png", np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match="shape"):
        imageio.write_exr(tmp_path / "a.exr", np.zeros((2, 2)))


# ----------------------------------------------------------------------------- tonemap
def test_srgb_known_values():
    x = np.array([0.0, 0.0031308, 0.18, 0.5, 1.0])
    # reference values from the IEC 61966-2-1 formula
    want = np.array([0.0, 0.040449936, 0.461356129, 0.735356983, 1.0])
    np.testing.assert_allclose(encoding.srgb_encode(x), want, atol=1e-8)
    np.testing.assert_allclose(encoding.srgb_decode(np.array([0.04045, 0.5, 1.0])),
                               [0.04045 / 12.92, 0.214041140, 1.0], atol=1e-8)
    assert encoding.srgb_decode(np.array([128 / 255]))[0] == pytest.approx(0.2158605, abs=1e-6)


@pytest.mark.parametrize("dtype,tol", [(np.float64, 1e-12), (np.float32, 2e-6)])
def test_srgb_round_trip(rng, dtype, tol):
    x = rng.random(10000).astype(dtype)
    x[:5] = [0, 0.0031308, 0.04045, 1, 1e-7]
    y = encoding.srgb_decode(encoding.srgb_encode(x))
    assert y.dtype == dtype
    np.testing.assert_allclose(y, x, atol=tol, rtol=tol)
    enc = encoding.srgb_encode(x)
    assert np.all(np.diff(enc[np.argsort(x)]) >= 0)  # monotone


def test_srgb_is_continuous_at_the_knee():
    eps = 1e-12
    lo, hi = encoding.srgb_encode(np.array([0.0031308 - eps, 0.0031308 + eps]))
    assert abs(hi - lo) < 1e-7


def test_tonemap_methods(rng):
    hdr = rng.random((4, 5, 3)) * 20
    for m in tonemap.METHODS:
        out = tonemap.tonemap(hdr, exposure=-1.0, method=m)
        assert out.dtype == np.float32 and out.shape == hdr.shape
        assert out.min() >= 0 and out.max() <= 1
    np.testing.assert_allclose(tonemap.tonemap(np.array([0.25]), exposure=1.0), encoding.srgb_encode(0.5), rtol=1e-6)
    assert tonemap.reinhard(np.array([1.0]))[0] == 0.5
    assert tonemap.aces(np.array([0.0]))[0] == 0.0 and tonemap.aces(np.array([1e6]))[0] == 1.0
    with pytest.raises(ValueError, match="method"):
        tonemap.tonemap(hdr, method="filmic")


def test_to_uint8():
    np.testing.assert_array_equal(tonemap.to_uint8(np.array([0.0, 0.5, 1.0, 2.0, -1.0])), [0, 128, 255, 255, 0])
    with pytest.raises(ValueError, match="non-finite"):
        tonemap.to_uint8(np.array([np.nan]))


# ----------------------------------------------------------------------------- integer codes and their tables
@pytest.mark.parametrize("dtype, top, name", [(np.uint8, 255, "a.png"), (np.uint16, 65535, "a.png"),
                                              (np.uint16, 65535, "a.tif")])
@pytest.mark.parametrize("channels", [1, 3, 4])
def test_integer_codes_kept_and_tables_match_the_curves(tmp_path, rng, dtype, top, name, channels):
    """An integer file keeps its codes (RGB), its pixels are codes / top, and linearise's table of
    the codes gives bit for bit what the curve gives evaluated at every pixel."""
    import cv2

    from ffls.radiance.photos import linearise

    shape = (23, 37) if channels == 1 else (23, 37, channels)
    stored = rng.integers(0, top + 1, shape, dtype=np.int64).astype(dtype)
    stored.reshape(-1)[:256] = np.arange(256)  # every 8-bit code, at odd offsets
    assert cv2.imwrite(str(tmp_path / name), stored)
    img = imageio.read_image(tmp_path / name)
    rgb = np.repeat(stored[:, :, None], 3, axis=2) if channels == 1 else stored[:, :, 2::-1][:, :, -3:]
    assert img.codes.dtype == dtype and img.codes.shape == (23, 37, 3)
    np.testing.assert_array_equal(img.codes, rgb)
    np.testing.assert_array_equal(img.pixels, rgb.astype(np.float32) / np.float32(top))
    assert img.pixels.flags.c_contiguous and img.pixels.dtype == np.float32
    for enc, curve in (("srgb", encoding.srgb_decode), ({"gamma": 2.2}, lambda v: encoding.gamma_decode(v, 2.2)),
                       ({"gamma": 0.45}, lambda v: encoding.gamma_decode(v, 0.45))):
        lin = linearise(img, enc)
        assert lin.dtype == np.float32
        np.testing.assert_array_equal(lin, curve(img.pixels))
    if dtype == np.uint8:  # a response table is read at the same codes
        response = np.linspace(0.0, 1.0, 256 * 3).reshape(3, 256).T.copy()
        lin = linearise(img, {"response": "cam"}, response)
        np.testing.assert_array_equal(lin[..., 1], response[rgb[..., 1], 1].astype(np.float32))


def test_float_files_have_no_codes_and_a_bad_gamma_is_still_refused(tmp_path, rng):
    from ffls.radiance.photos import linearise

    imageio.write_exr(tmp_path / "a.exr", rng.random((4, 5, 3)).astype(np.float32))
    assert imageio.read_image(tmp_path / "a.exr").codes is None
    imageio.write_png(tmp_path / "b.png", rng.integers(0, 256, (4, 5, 3), dtype=np.uint8))
    img = imageio.read_image(tmp_path / "b.png")
    with pytest.raises(ValueError, match="gamma"):
        linearise(img, {"gamma": 100.0})
