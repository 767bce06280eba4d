"""Bad input, round 14b: attacks on round 14's merged refusals (issues 9 and 11).

Valid but unusual files (``.JPG``/``.jpeg``/``.TIFF``/``.HDR``, a JPEG-compressed TIFF, a 16-bit PNG
with sRGB/iCCP/gAMA chunks, a tiled EXR, a Radiance file with several EXPOSURE lines) are read as
before; the faults found are below, each one line, status 2, nothing written.
"""
from __future__ import annotations

import numpy as np
import pytest

from cli_lines import one_line, tiny_capture


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r14b"), seed=141)


def _latlong_u8() -> np.ndarray:
    """A 64x32 8-bit RGB image: the size of a lat-long light map, so that only its format can refuse it."""
    return (np.random.default_rng(0).random((32, 64, 3)) * 255).astype(np.uint8)


def _relight_with_mask(capfd, cap, mask, out):
    """``ffls relight CAP --probe sky --mask MASK -o OUT``: its status and its one line."""
    return one_line(capfd, ["relight", cap, "--probe", "sky", "--mask", mask, "-o", out])


def _encoded(fmt: str) -> bytes:
    """A 24x24 white 8-bit image (a mask of :func:`tiny_capture`'s photos) in ``fmt``, by OpenCV (BMP,
    PPM, WebP) or Pillow (GIF, JPEG 2000: OpenCV's OpenJPEG writes none this small)."""
    import io

    import cv2
    from PIL import Image

    white = np.full((24, 24, 3), 255, np.uint8)
    if fmt in ("gif", "jp2"):
        b = io.BytesIO()
        Image.fromarray(white).save(b, format={"gif": "GIF", "jp2": "JPEG2000"}[fmt])
        return b.getvalue()
    ok, buf = cv2.imencode("." + fmt, white)
    if not ok:
        pytest.skip(f"this OpenCV cannot write .{fmt}")
    return buf.tobytes()


@pytest.mark.parametrize("fmt, name, what", [("webp", "m.jpg", "a WebP"), ("webp", "m.png", "a WebP"),
                                             ("bmp", "m.png", "a BMP"), ("gif", "m.png", "a GIF"),
                                             ("jp2", "m.jpg", "a JPEG 2000"), ("ppm", "m.tif", "a PNM")])
def test_a_file_of_a_format_ffls_does_not_read_is_refused(cap, tmp_path, capfd, fmt, name, what):
    """Round 14 refused a file whose signature is another format's that ffls reads (a PNG named
    ``.jpg``), and left unknown signatures to the decoder. But OpenCV decodes by content: a WebP
    (a web download), BMP, GIF, JPEG 2000 or PPM named ``.jpg``/``.png``/``.tif`` was read with no
    check made from its header (size, memory, grey, bit depth, orientation: ``image_header`` None):
    ``relight --mask`` used it, status 0. One line now names the format."""
    src = tmp_path / name
    src.write_bytes(_encoded(fmt))
    out = tmp_path / "out.exr"
    rc, line = _relight_with_mask(capfd, cap, src, out)
    assert rc == 2 and f"{name}: is {what}" in line and "a format ffls does not read" in line, line
    assert not out.exists()


@pytest.mark.parametrize("head, what", [(b"\x00\x00\x00\x18ftypheic\x00\x00\x00\x00", "a HEIF (HEIC)"),
                                        (b"\x00\x00\x00\x0cJXL \r\n\x87\n", "a JPEG XL")])
def test_a_phone_or_new_format_named_jpg_is_named(cap, tmp_path, capfd, head, what):
    """A phone's HEIC or a JPEG XL named ``.jpg`` was refused as 'cannot decode JPEG image (corrupt,
    truncated or not a JPEG file)': the file is not corrupt; the line now says what it is."""
    src = tmp_path / "IMG_0001.jpg"
    src.write_bytes(head + bytes(200))
    out = tmp_path / "out.exr"
    rc, line = _relight_with_mask(capfd, cap, src, out)
    assert not out.exists()
    assert rc == 2 and f"IMG_0001.jpg: is {what} file named '.jpg', a format ffls does not read" in line, line


def test_a_radiance_xyze_file_is_named(tmp_path, capfd):
    """A Radiance picture of CIE XYZ values (``FORMAT=32-bit_rle_xyze``, e.g. from ``ra_xyze``) was
    refused as 'cannot decode HDR image (corrupt, truncated or not a HDR file)' (OpenCV reads RGBE
    only): one line now says what it is and how to convert it."""
    import cv2

    ok, buf = cv2.imencode(".hdr", np.full((32, 64, 3), 0.5, np.float32))
    src = tmp_path / "m.hdr"
    src.write_bytes(buf.tobytes().replace(b"FORMAT=32-bit_rle_rgbe", b"FORMAT=32-bit_rle_xyze", 1))
    out = tmp_path / "out.exr"
    rc, line = one_line(capfd, ["lightmap", "convert", src, out])
    assert rc == 2 and "m.hdr: is a Radiance XYZE file (FORMAT=32-bit_rle_xyze" in line and "ra_xyze -r" in line
    assert not out.exists()


def test_unusual_valid_files_are_still_read(tmp_path):
    """The new refusals leave valid files alone: upper-case and long extensions, a JPEG-compressed
    and an LZW TIFF, a progressive JPEG, a 16-bit PNG with sRGB, gAMA and iCCP chunks, a palette
    PNG, and a Radiance file whose EXPOSURE lines multiply to 1 (Radiance's definition) read as
    their plain twins."""
    import struct
    import zlib

    import cv2
    from PIL import Image

    from ffls.io.images import image_header, read_image

    a8 = _latlong_u8()
    a16 = a8.astype(np.uint16) * 257
    Image.fromarray(a8).save(tmp_path / "p.JPEG", quality=95, progressive=True)
    Image.fromarray(a8).save(tmp_path / "t.TIFF", compression="jpeg")
    Image.fromarray(a8).save(tmp_path / "l.tif", compression="tiff_lzw")
    Image.fromarray(a8).convert("P").save(tmp_path / "pal.PNG")
    png = cv2.imencode(".png", a16)[1].tobytes()

    def chunk(typ, data):
        return struct.pack(">I", len(data)) + typ + data + struct.pack(">I", zlib.crc32(typ + data) & 0xFFFFFFFF)

    icc = b"sRGB\x00\x00" + zlib.compress(bytes(64))
    (tmp_path / "c16.png").write_bytes(png[:33] + chunk(b"sRGB", b"\x00") + chunk(b"gAMA", struct.pack(">I", 45455))
                                       + chunk(b"iCCP", icc) + png[33:])
    hdr = cv2.imencode(".hdr", np.full((32, 64, 3), 0.5, np.float32))[1].tobytes()
    end = hdr.find(b"\n\n")
    (tmp_path / "e.HDR").write_bytes(hdr[:end] + b"\nEXPOSURE=2\nEXPOSURE=0.5" + hdr[end:])
    for name, bits in [("p.JPEG", 8), ("t.TIFF", 8), ("l.tif", 8), ("pal.PNG", 8), ("c16.png", 16)]:
        img = read_image(tmp_path / name)
        assert img.pixels.shape == (32, 64, 3) and image_header(tmp_path / name).bits == bits == img.bit_depth
    np.testing.assert_allclose(read_image(tmp_path / "c16.png").pixels, a8[..., ::-1] / 255.0, atol=1e-6)
    np.testing.assert_allclose(read_image(tmp_path / "e.HDR").pixels, 0.5, rtol=0.01)


def test_an_unhinted_probe_ball_too_small_for_a_probe_is_refused(tmp_path):
    """A mirror ball (radius 33 px) under ``night``, photographed 320x240 with a blur of 1 px and 1%
    noise: the unhinted finder's outline was a street lamp's 4 px blob at the frame's top edge, 137 px
    from the ball, sharp enough to pass, and ``probe mirror`` unwrapped it without a word. Unhinted
    outlines under ``MIN_BALL_FRACTION`` of the shorter side (12 px) are now refused in one line, as
    ``diffuse_ball`` refuses them; without blur the ball is still found (within 1 px)."""
    import cv2

    from ffls.errors import InputError
    from ffls.io.images import read_image, write_exr
    from ffls.io.probe import load_probe
    from ffls.lightmaps.lightmap import builtin_lightmap
    from ffls.probes.bracket import view_radiance
    from ffls.probes.locate import locate_sphere
    from ffls.synth.probe import off_axis_view, write_mirror_probe

    centre = np.array([0.0, 0.0, 0.1])
    K, T, c_true = off_axis_view(centre, 1.2, 400.0, (70.0, 10.0))

    def locate(blurred):
        folder = tmp_path / ("blurred" if blurred else "sharp")
        write_mirror_probe(folder, builtin_lightmap("night"), (320, 240), "pinhole", K, None, T, centre, 0.1,
                           sphere="auto", reflectance=0.7)
        if blurred:
            img = cv2.GaussianBlur(read_image(folder / "ball.exr").pixels, (0, 0), 1.0)
            img = img * (1 + 0.01 * np.random.default_rng(0).standard_normal(img.shape)).astype(np.float32)
            write_exr(folder / "ball.exr", np.clip(img, 0, None).astype(np.float32))
        probe = load_probe(folder)
        vr = view_radiance(probe.views[0], probe.encoding, probe.response, probe.json_path)
        return locate_sphere(probe.views[0], vr.radiance, probe.json_path)

    assert np.hypot(*(locate(False).center_px - c_true)) < 1.0
    with pytest.raises(InputError, match=r"radius [0-9]+ px, is too small for a probe \(under 0.05 of the photo's "
                                         r"shorter side, 12 px\); give a hint"):
        locate(True)


def test_a_charuco_board_of_the_legacy_layout_is_calibrated(tmp_path):
    """A ChArUco board with an even number of rows printed before OpenCV 4.6 (or by a generator that
    kept its layout) is not found by today's detector: an 8x6 board in 5 sharp views was 'found in 0
    of 5 photos; need at least 3'. It is now looked for in the legacy layout too, found in all 5, and
    the result says so; today's layout of the same board is unchanged (not legacy)."""
    import cv2

    from ffls.camera import calibrate as cal

    K = np.array([[820.0, 0, 331.0], [0, 820.0, 236.0], [0, 0, 1]])
    squares, sq, mk = (8, 6), 0.03, 0.022

    def views(legacy):
        board = cal.make_board(squares, sq, mk, legacy=legacy)
        flat = board.generateImage((8 * 120 + 80, 6 * 120 + 80), marginSize=40, borderBits=1)
        obj, img = cal.detect_board(flat, "charuco", squares, sq, mk, legacy=legacy)
        Hb, _ = cv2.findHomography(obj[:, :2], img, 0)
        out = []
        for ax, ay, az, ox, oy in [(0, 0, 0, 0, 0), (30, 0, 0, 0.05, 0.03), (-30, 5, 0, -0.05, -0.03),
                                   (0, 30, 10, -0.06, 0.04), (5, -30, -10, 0.06, -0.04)]:
            R, _ = cv2.Rodrigues(np.deg2rad([ax, ay, az]).astype(np.float64))
            t = np.array([ox, oy, 0.5]) - R @ np.array([8 * sq / 2, 6 * sq / 2, 0])
            M = K @ np.column_stack([R[:, 0], R[:, 1], t]) @ np.linalg.inv(Hb)
            out.append(cv2.GaussianBlur(cv2.warpPerspective(flat, M, (640, 480), flags=cv2.INTER_AREA,
                                                            borderValue=200), (0, 0), 0.6))
        return out

    names = [tmp_path / f"v{i}.png" for i in range(5)]
    for legacy in (True, False):
        res = cal.calibrate_camera(names, squares=squares, square_size=sq, marker_size=mk, images=views(legacy))
        assert len(res.used) == 5 and res.legacy_pattern == legacy and res.rms < 0.5
        assert abs(res.K[0, 0] / 820.0 - 1) < 0.01
        assert res.to_dict().get("legacy_pattern", False) == legacy
