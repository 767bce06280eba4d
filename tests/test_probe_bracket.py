"""Exposure brackets: hat weights that reach zero at the clipping limits, 8-/16-bit/float input, flags, errors."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.cli import main
from ffls.errors import InputError
from ffls.io.images import read_image, write_exr, write_png
from ffls.probes.bracket import (float_clip_level, hat_weights, merge_bracket_files,
                                 merge_exposures_DebevecMalik1997)
from ffls.radiance.encoding import srgb_encode

TIMES = (1 / 250, 1 / 60, 1 / 15, 1 / 4)


def _scene(rng, h=24, w=32):
    """Radiance spanning 5 decades, plus a sun no exposure holds."""
    L = 10 ** rng.uniform(0.0, 3.0, (h, w, 1)) * rng.uniform(0.5, 1.0, (h, w, 3))
    L[:3, :3] = 1e6
    return L.astype(np.float64)


def _write_bracket(tmp_path, L, bits, times=TIMES):
    import cv2

    paths = []
    top = 255 if bits == 8 else 65535
    for k, t in enumerate(times):
        code = np.rint(srgb_encode(np.clip(L * t / 50.0, 0, 1)) * top).astype(np.uint8 if bits == 8 else np.uint16)
        p = tmp_path / f"b{k}.png"
        cv2.imwrite(str(p), code[..., ::-1])
        paths.append(p)
    return paths


def test_hat_weights_are_zero_at_the_limits():
    z = np.array([[[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [0.99, 0.2, 0.2], [1.0, 1.0, 1.0], [0.3, 0.0, 0.3]]])
    w = hat_weights(z, 1.0)
    assert np.all(w[0, 0] == 0) and np.all(w[0, 1] == 1) and np.all(w[0, 2] == 0) and np.all(w[0, 3] == 0)
    assert w[0, 4, 1] == 0 and w[0, 4, 0] > 0  # the bottom is per channel, the top per pixel
    np.testing.assert_array_equal(hat_weights(np.array([[[0.0, 2.0, 5.0]]]), None), [[[0.0, 1.0, 1.0]]])


@pytest.mark.parametrize("bits", [8, 16])
def test_integer_bracket_recovers_radiance(tmp_path, bits):
    L = _scene(np.random.default_rng(bits))
    m = merge_bracket_files(_write_bracket(tmp_path, L, bits), TIMES, "srgb")
    rec = m.radiance.astype(np.float64) * 50.0
    ok = ~m.saturated
    rel = np.abs(rec - L)[ok] / L[ok]
    assert np.median(rel) < (0.01 if bits == 8 else 0.001) and rel.max() < (0.15 if bits == 8 else 0.01)
    # the sun is clipped in every exposure: flagged, and given the shortest exposure's (lower-bound) value
    assert m.saturated[:3, :3].all() and m.saturated.sum() == 9
    assert "9 pixels" in m.describe() and "lower bound" in m.describe() and "shorter than 0.004 s" in m.describe()
    assert np.all(rec[:3, :3] < 1e6) and np.all(rec[:3, :3] >= 0.99 * 50 / TIMES[0])


def test_float_bracket_with_a_clipping_plateau():
    rng = np.random.default_rng(3)
    L = _scene(rng)
    stored = [np.minimum(L * t / 50.0, 1.0).astype(np.float32) for t in TIMES]  # a raw converter clipping at 1
    clips = [float_clip_level(s) for s in stored]
    assert clips[-1] == 1.0
    assert float_clip_level(L.astype(np.float32) * 1e-6 + rng.uniform(0, 1e-3, L.shape)) is None
    m = merge_exposures_DebevecMalik1997(stored, stored, TIMES, clips)
    ok = ~m.saturated
    np.testing.assert_allclose(m.radiance[ok] * 50.0, L[ok], rtol=1e-5)
    assert m.saturated.sum() == 9


def test_equal_exposures_and_shapes_are_refused(tmp_path):
    img = np.ones((2, 4, 4, 3), np.float32)
    with pytest.raises(ValueError, match="equal"):
        merge_exposures_DebevecMalik1997(img, img, [0.1, 0.1], [None, None])
    with pytest.raises(ValueError, match="positive"):
        merge_exposures_DebevecMalik1997(img, img, [0.1, -1], [None, None])
    paths = _write_bracket(tmp_path, _scene(np.random.default_rng(0)), 8, (0.01, 0.01))
    with pytest.raises(InputError) as e:
        merge_bracket_files(paths, (0.01, 0.01), "srgb")
    assert "equal" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(InputError, match="does not guess"):
        merge_bracket_files(paths, (0.01, 0.02), "auto")


def test_cli_merge_with_exposures_and_exif(tmp_path, capsys):
    from PIL import Image

    L = _scene(np.random.default_rng(5))
    paths = _write_bracket(tmp_path, L, 8)
    out = tmp_path / "hdr.exr"
    args = ["probe", "merge", *map(str, paths), "-o", str(out), "--encoding", "srgb",
            "--exposures", ",".join(str(t) for t in TIMES)]
    assert main(args) == 0
    img = read_image(out)
    assert img.alpha is not None and (img.alpha == 0).sum() == 9
    # EXIF exposure times (written as JPEG, read back with Pillow)
    jpgs = []
    for k, (p, t) in enumerate(zip(paths, TIMES)):
        im = Image.open(p)
        ex = Image.Exif()
        ex[33434] = t  # ExposureTime
        jp = tmp_path / f"e{k}.jpg"
        im.save(jp, quality=98, exif=ex)
        jpgs.append(jp)
    assert main(["probe", "merge", *map(str, jpgs), "-o", str(tmp_path / "e.exr"), "--encoding", "srgb"]) == 0
    assert "from EXIF" in capsys.readouterr().err
    # bad input: one line, status 2, no output
    times = ",".join(str(t) for t in TIMES)
    for bad in (["--encoding", "srgb", "--exposures", "0.1,0.1,0.1,0.1"],  # equal exposures
                ["--encoding", "srgb", "--exposures", "0.1,0.2"],  # one time per image
                ["--exposures", times],  # 8-bit images of unstated encoding
                ["--encoding", "srgb"]):  # PNGs carry no EXIF
        capsys.readouterr()
        code = main(["probe", "merge", *map(str, paths), "-o", str(tmp_path / "x.exr"), *bad])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "error" in err[0], (bad, err)
        if "--encoding" not in bad:  # the unstated encoding itself is named, not a default's parse error
            assert "not stated" in err[0] and "does not guess" in err[0], err
            # in the flag's own words (gamma=G), not probe.json's ({"gamma": g}), and in English
            assert "gamma=G" in err[0] and '{"gamma"' not in err[0] and "an 8-bit image" in err[0], err
        assert not (tmp_path / "x.exr").exists()


def test_cli_merge_calibrates_the_response(tmp_path, capsys):
    L = _scene(np.random.default_rng(6), 48, 64)
    paths = _write_bracket(tmp_path, L, 8)
    out = tmp_path / "cal.exr"
    assert main(["probe", "merge", *map(str, paths), "-o", str(out), "--encoding", "calibrate",
                 "--exposures", ",".join(str(t) for t in TIMES)]) == 0
    rec = read_image(out).pixels.astype(np.float64)
    ok = read_image(out).alpha > 0
    # the recovered response is known up to a scale: compare log-radiance after removing it
    r = np.log(rec[ok] + 1e-12) - np.log(L[ok])
    assert np.std(r - np.median(r)) < 0.15
    with pytest.raises(InputError):
        write_png(tmp_path / "w.png", np.zeros((4, 4, 3), np.uint8))
        write_exr(tmp_path / "f.exr", np.ones((4, 4, 3), np.float32))
        merge_bracket_files([tmp_path / "w.png", tmp_path / "f.exr"], (0.1, 0.2), "srgb")


def test_cli_merge_of_float_files_needs_no_encoding(tmp_path, capsys):
    """Float files are linear by definition: ``ffls probe merge`` takes them without ``--encoding``."""
    L = _scene(np.random.default_rng(8))
    paths = []
    for k, t in enumerate(TIMES):
        p = tmp_path / f"f{k}.exr"
        write_exr(p, np.minimum(L * t / 50.0, 1.0).astype(np.float32))
        paths.append(p)
    out = tmp_path / "m.exr"
    times = ",".join(str(t) for t in TIMES)
    assert main(["probe", "merge", *map(str, paths), "-o", str(out), "--exposures", times]) == 0, capsys.readouterr()
    m = read_image(out).pixels[..., :3].astype(np.float64) * 50.0
    ok = np.ones(L.shape[:2], dtype=bool)
    ok[:3, :3] = False  # the sun, clipped in every exposure
    np.testing.assert_allclose(m[ok], L[ok], rtol=2e-3)


def test_cli_merge_refuses_times_no_camera_gives_and_a_file_twice(tmp_path, capsys):
    """Exposure times outside a microsecond to a day (a typo, a broken EXIF tag) would overflow or
    zero the merged radiance; a file listed twice is no bracket. One line each, nothing written."""
    from PIL import Image

    paths = _write_bracket(tmp_path, _scene(np.random.default_rng(6)), 8, TIMES[:2])
    bad_exif = tmp_path / "z.jpg"
    ex = Image.Exif()
    ex[33434] = 0.0
    Image.open(paths[0]).save(bad_exif, exif=ex)
    cases = [(paths, ["--exposures", "1e-300,0.04"], "--exposures: 1e-300 s is not an exposure time"),
             (paths, ["--exposures", "1e300,1e308"], "--exposures: 1e+300 s is not an exposure time"),
             ([paths[0], paths[0]], ["--exposures", "0.01,0.04"], "listed twice in the bracket"),
             ([bad_exif, paths[1]], [], "EXIF ExposureTime: 0 s is not an exposure time")]
    for files, extra, msg in cases:
        capsys.readouterr()
        code = main(["probe", "merge", *map(str, files), "-o", str(tmp_path / "x.exr"), "--encoding", "srgb", *extra])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and msg in err[0], (extra, err)
        assert not (tmp_path / "x.exr").exists()


def test_noisy_short_exposures_do_not_set_the_dark_parts():
    """Read noise of a fixed size in the stored values (clipped at black, as a camera's codes are)
    is 1/t larger in x/t: the default merge weighs each exposure by t^2 (Robertson et al. 2003), so
    a dark region is set by the long exposure, not by the short one's biased noise."""
    from ffls.probes.bracket import merge_exposures

    rng = np.random.default_rng(5)
    L = np.full((64, 64, 3), 0.02)           # a dark region ...
    L[:, 32:] = 20.0                         # ... beside a bright one
    times = (1 / 1000, 1 / 30, 1.0)
    stored = [np.clip(np.rint((L * t + rng.normal(0, 0.004, L.shape)).clip(0, 1) * 255) / 255, 0, 1)
              for t in times]
    m = merge_exposures(stored, stored, times, [1.0] * 3)
    dark = m.radiance[:, :32].astype(np.float64)
    assert abs(np.median(dark) / 0.02 - 1) < 0.05, np.median(dark)
    bright = m.radiance[:, 32:].astype(np.float64)
    assert abs(np.median(bright) / 20.0 - 1) < 0.05
    # the hat-weighted mean alone (Debevec and Malik) is pulled up by the short exposure's noise
    old = merge_exposures_DebevecMalik1997(stored, stored, times, [1.0] * 3).radiance[:, :32]
    assert np.median(old) > 1.5 * 0.02
