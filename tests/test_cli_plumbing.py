"""One way to say the same thing (issue 9, items 8 and 9): rotation flags shared by relight, render
and view; --mask and alpha; --exposure auto metering the object; valid default ranks and one line
for a bad --rank."""
from __future__ import annotations

import numpy as np
import pytest

from ffls import conventions as cv
from ffls.cli import build_parser, main
from ffls.commands.common import rotation_from_args
from ffls.display.tonemap import auto_exposure, object_pixels, to_uint8, tonemap
from ffls.io.images import read_image, write_exr, write_png

COMMANDS = {"relight": ["CAP", "--probe", "paper", "-o", "x.exr"],
            "render": ["CAP", "--probe", "paper", "-o", "x.exr"],
            "view": ["CAP"]}


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    from ffls.synth.scene import write_synthetic_capture

    folder = tmp_path_factory.mktemp("plumb")
    write_synthetic_capture(folder, n_lights=8, resolution=32, progress=False, seed=5)
    return folder


@pytest.fixture(scope="module")
def mask_png(cap, tmp_path_factory):
    m = np.zeros((32, 32), np.uint8)
    m[8:24, 10:22] = 255
    path = tmp_path_factory.mktemp("mask") / "mask.png"
    write_png(path, m)
    return path, m > 0


# ----------------------------------------------------------------------------- rotation
@pytest.mark.parametrize("flags, R", [
    ([], np.eye(3)),
    (["--rotate-z", "30"], cv.rotation_z(30)),
    (["--rotate", "30"], cv.rotation_z(30)),
    (["--rotate", "30,0,0"], cv.rotation_z(30)),
    (["--rotate", "10,-20,45"], cv.rotation_ypr(10, -20, 45)),
    (["--rotate=-90,5"], cv.rotation_ypr(-90, 5, 0)),
])
def test_rotation_flags_parse_the_same_in_relight_render_and_view(flags, R):
    parser = build_parser()
    for cmd, rest in COMMANDS.items():
        args = parser.parse_args([cmd, *rest, *flags])
        np.testing.assert_allclose(rotation_from_args(args), R, atol=1e-15, err_msg=cmd)


@pytest.mark.parametrize("flags", [["--rotate", "1,2,3,4"], ["--rotate", "a,b"], ["--rotate", "nan"],
                                   ["--rotate-z", "inf"], ["--rotate", "1", "--rotate-z", "2"]])
def test_bad_rotation_flags_are_one_argparse_line(flags, capsys):
    for cmd, rest in COMMANDS.items():
        with pytest.raises(SystemExit) as e:
            build_parser().parse_args([cmd, *rest, *flags])
        assert e.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert "--rotate" in err[-1], cmd


def test_view_state_takes_the_shared_rotation():
    from viewer.command import build_state

    pytest.importorskip("imgui_bundle", reason="imgui-bundle is not installed")
    st = build_state(build_parser().parse_args(["view", "CAP", "--rotate-z", "25"]))
    assert (st.yaw, st.pitch, st.roll) == (25.0, 0.0, 0.0)


def test_relight_rotate_and_rotate_z_agree(cap, tmp_path):
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    assert main(["relight", str(cap), "--probe", "sky", "--rotate-z", "40", "-o", str(a)]) == 0
    assert main(["relight", str(cap), "--probe", "sky", "--rotate", "40,0,0", "-o", str(b)]) == 0
    np.testing.assert_array_equal(read_image(a).pixels, read_image(b).pixels)


# ----------------------------------------------------------------------------- alpha
def test_exr_and_png_alpha_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    rgb = rng.random((6, 5, 3)).astype(np.float32)
    alpha = rng.random((6, 5)).astype(np.float32)
    write_exr(tmp_path / "a.exr", rgb, alpha=alpha)
    back = read_image(tmp_path / "a.exr")
    np.testing.assert_array_equal(back.pixels, rgb)
    np.testing.assert_array_equal(back.alpha, alpha)
    assert read_image(tmp_path / "a.exr").alpha.dtype == np.float32
    write_exr(tmp_path / "h.exr", rgb, half=True, alpha=alpha)
    np.testing.assert_allclose(read_image(tmp_path / "h.exr").alpha, alpha, atol=5e-4)
    write_exr(tmp_path / "n.exr", rgb)
    assert read_image(tmp_path / "n.exr").alpha is None
    rgba = np.concatenate([(rgb * 255).astype(np.uint8), (alpha[..., None] * 255).astype(np.uint8)], axis=-1)
    write_png(tmp_path / "a.png", rgba)
    png = read_image(tmp_path / "a.png")
    np.testing.assert_array_equal(png.alpha, rgba[..., 3] / np.float32(255))
    np.testing.assert_array_equal(png.pixels, rgba[..., :3] / np.float32(255))
    with pytest.raises(ValueError, match="alpha"):
        write_exr(tmp_path / "bad.exr", rgb, alpha=alpha[:3])
    with pytest.raises(ValueError, match="alpha"):
        write_exr(tmp_path / "bad.exr", rgb, alpha=alpha + 1)
    assert not (tmp_path / "bad.exr").exists()


@pytest.mark.parametrize("command", ["relight", "render"])
def test_mask_writes_alpha_in_exr_and_png(cap, mask_png, tmp_path, command):
    mpath, m = mask_png
    extra = ["--cpu"] if command == "render" else []
    plain, masked = tmp_path / "plain.exr", tmp_path / "masked.exr"
    assert main([command, str(cap), "--probe", "sky", *extra, "-o", str(plain)]) == 0
    assert main([command, str(cap), "--probe", "sky", *extra, "--mask", str(mpath), "-o", str(masked)]) == 0
    p, q = read_image(plain), read_image(masked)
    assert p.alpha is None
    np.testing.assert_array_equal(q.alpha, m.astype(np.float32))
    np.testing.assert_array_equal(q.pixels, p.pixels * m[..., None])  # OpenEXR's premultiplied RGBA
    png = tmp_path / "masked.png"
    assert main([command, str(cap), "--probe", "sky", *extra, "--mask", str(mpath), "-o", str(png)]) == 0
    img = read_image(png)
    np.testing.assert_array_equal(img.alpha, m.astype(np.float32))
    assert img.pixels[m].max() > 0


def test_mask_of_the_wrong_size_is_one_line(cap, tmp_path, capsys):
    bad = tmp_path / "small.png"
    write_png(bad, np.full((8, 8), 255, np.uint8))
    out = tmp_path / "x.png"
    rc = main(["relight", str(cap), "--probe", "sky", "--mask", str(bad), "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and "mask is 8x8, the images are 32x32" in err[-1] and not out.exists()


# ----------------------------------------------------------------------------- auto exposure
def test_auto_exposure_meters_the_object_not_the_background():
    rng = np.random.default_rng(1)
    img = (0.003 * rng.uniform(0.5, 1.5, (64, 64, 1)) * np.ones(3)).astype(np.float32)  # dark cloth
    m = np.zeros((64, 64), bool)
    m[20:36, 24:40] = True  # the object: 6% of the frame
    img[m] = 0.5 * rng.uniform(0.8, 1.2, (m.sum(), 1))
    assert auto_exposure(img, mask=m) == pytest.approx(np.log2(0.18 / 0.5), abs=0.05)  # the object's level
    assert auto_exposure(img) == pytest.approx(auto_exposure(img, mask=m), abs=1e-9)  # Otsu found the object
    np.testing.assert_array_equal(object_pixels(img), m)
    # metering every pixel (the old rule) is 4 stops off here
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    every = float(np.log2(0.18 / np.exp(np.mean(np.log(lum)))))
    assert every - auto_exposure(img, mask=m) > 4
    # no background (an object filling the frame): every pixel is metered
    fill = (0.5 * rng.uniform(0.8, 1.2, (16, 16, 1)) * np.ones(3)).astype(np.float32)
    assert object_pixels(fill).all()
    assert auto_exposure(np.zeros((4, 4, 3))) == 0.0
    with pytest.raises(ValueError, match="mask"):
        auto_exposure(img, mask=m[:10])


def test_relight_exposure_auto_uses_the_mask(cap, mask_png, tmp_path):
    from ffls.relight.cpu import relight_capture
    from ffls.io.capture import load_capture_and_lights
    from ffls.lightmaps.lightmap import builtin_lightmap

    mpath, m = mask_png
    out = tmp_path / "auto.png"
    assert main(["relight", str(cap), "--probe", "sky", "--mask", str(mpath), "--exposure", "auto",
                 "-o", str(out)]) == 0
    c, lights = load_capture_and_lights(cap)
    image, _ = relight_capture(c, lights, builtin_lightmap("sky"))
    expected = to_uint8(tonemap(image, exposure=auto_exposure(image, mask=m)))
    np.testing.assert_array_equal(np.rint(read_image(out).pixels * 255).astype(np.uint8), expected)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["relight", "CAP", "--probe", "x", "-o", "x.png", "--exposure", "bright"])


# ----------------------------------------------------------------------------- rank
@pytest.mark.parametrize("n", range(2, 13))
def test_default_rank_is_always_valid(n):
    from ffls.relight.compress import DEFAULT_RANK, compress_basis, default_rank, rank_range

    k = default_rank(n)
    lo, hi = rank_range(n)
    assert (lo, hi) == (1, n - 1) and lo <= k <= hi and k == min(DEFAULT_RANK, n - 1)
    basis = np.random.default_rng(n).random((n, 4, 4, 3)).astype(np.float32)
    cb = compress_basis(basis, k)  # the default never raises
    assert cb.rank == k
    if k == n - 1:  # K = n - 1 is exact
        np.testing.assert_allclose(cb.relight(np.eye(n)[:, :1].repeat(3, 1)), basis[0], atol=1e-4)


def test_viewer_rank_slider_stops_at_n_minus_1():
    pytest.importorskip("imgui_bundle", reason="imgui-bundle is not installed")
    from viewer.state import QUALITY_KNOBS, ViewerState

    knob = next(k for k in QUALITY_KNOBS if k.key == "rank")
    assert ViewerState().knob_range(knob, 12) == (1, 11)


@pytest.mark.parametrize("rank", ["0", "8", "50", "-1"])
def test_rank_out_of_range_is_one_line(cap, tmp_path, capsys, rank):
    out = tmp_path / "r.exr"
    rc = main(["render", str(cap), "--probe", "sky", "--cpu", "--rank", rank, "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and not out.exists()
    assert err[-1] == f"ffls render: error: --rank {rank} is out of range: it must be in [1, 7] for 8 lights"


def test_view_rank_out_of_range_is_one_line_before_any_window(cap, capsys):
    pytest.importorskip("imgui_bundle", reason="imgui-bundle is not installed")
    rc = main(["view", str(cap), "--headless", "--frames", "1", "--rank", "9"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err[-1] == "ffls view: error: --rank 9 is out of range: it must be in [1, 7] for 8 lights"


def test_render_light_summary_reports_the_rotated_light(cap, tmp_path, capsys):
    """--rotate turns --light as it turns a map (docs/weighting.md): the image is that of the turned
    light, and the summary says so (it said the unturned 'light az 10 el 45')."""
    turned, direct = tmp_path / "t.png", tmp_path / "d.png"
    assert main(["render", str(cap), "--light", "10,45", "--rotate", "90,0,0", "--cpu", "-o", str(turned)]) == 0
    text = capsys.readouterr().out
    assert "light az 100 el 45 (--light 10,45 turned by --rotate/--rotate-z)" in text, text
    assert main(["render", str(cap), "--light", "100,45", "--cpu", "-o", str(direct)]) == 0
    text = capsys.readouterr().out
    assert "light az 100 el 45," in text and "turned" not in text, text
    np.testing.assert_array_equal(read_image(turned).pixels, read_image(direct).pixels)
