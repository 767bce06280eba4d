"""Camera response recovery, HDR merge, response files and valid-pixel masks (ffls.radiance.response)."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from ffls.errors import InputError
from ffls.io import response as response_files
from ffls.radiance import response as rsp


def _camera(E, t, rng):
    """A made-up camera: S-shaped response f(x) = x^0.45 / (x^0.45 + 0.3) * 1.3, 8-bit, clipped."""
    x = E * t
    y = 1.3 * x ** 0.45 / (x ** 0.45 + 0.3)
    return np.clip(np.rint(255 * y + rng.normal(0, 0.3, y.shape)), 0, 255).astype(np.uint8)


def _finv(z):
    y = z / 255.0 / 1.3
    return (0.3 * y / (1 - y)) ** (1 / 0.45)


@pytest.fixture(scope="module")
def bracket():
    rng = np.random.default_rng(7)
    H, W = 64, 96
    E = np.exp(rng.uniform(np.log(0.05), np.log(20.0), (H, W, 1))) * np.array([1.0, 0.8, 0.6])
    times = np.array([1 / 64, 1 / 16, 1 / 4, 1.0, 4.0], dtype=np.float32)
    return E, times, [_camera(E, t, rng) for t in times]


def test_debevec_recovers_inverse_response(bracket):
    E, times, imgs = bracket
    curve = rsp.recover_response_DebevecMalik1997(imgs, times)
    assert curve.shape == (256, 3) and curve.dtype == np.float32
    assert np.all(np.diff(curve, axis=0) >= 0)
    z = np.arange(40, 220)
    truth = _finv(z.astype(np.float64))
    for c in range(3):
        ratio = curve[z, c] / truth
        # proportional to the true inverse response (unknown scale) within 10 % at mid codes
        assert np.max(np.abs(ratio / np.median(ratio) - 1)) < 0.10


def test_merge_hdr_is_linear_in_radiance(bracket):
    E, times, imgs = bracket
    curve = rsp.recover_response_DebevecMalik1997(imgs, times)
    hdr = rsp.merge_hdr(imgs, times, curve)
    assert hdr.shape == E.shape and hdr.dtype == np.float32
    ratio = hdr / E
    for c in range(3):
        r = ratio[..., c] / np.median(ratio[..., c])
        assert np.percentile(np.abs(r - 1), 95) < 0.1


def test_linearize_is_table_lookup():
    curve = np.stack([np.arange(256) * k for k in (1.0, 2.0, 3.0)], axis=1).astype(np.float32)
    im = np.array([[[0, 10, 255], [128, 1, 2]]], dtype=np.uint8)
    out = rsp.linearize(im, curve)
    np.testing.assert_array_equal(out, im * np.array([1.0, 2.0, 3.0], dtype=np.float32))
    with pytest.raises(ValueError):
        rsp.linearize(im.astype(np.uint16), curve)


@pytest.mark.parametrize("suffix", [".npy", ".csv"])
def test_save_load_roundtrip_and_capture_reader(tmp_path, suffix):
    curve = np.cumsum(np.random.default_rng(1).uniform(0.001, 0.01, (256, 3)), axis=0).astype(np.float32)
    p = response_files.save_response(tmp_path / f"response{suffix}", curve)
    np.testing.assert_allclose(response_files.load_response(p), curve, rtol=1e-6)
    assert [q.name for q in tmp_path.iterdir()] == [p.name]  # atomic: no temporary left
    # ffls.io.capture reads encoding.response through the same reader
    from ffls.io.capture import load_capture
    from ffls.io.images import write_png

    write_png(tmp_path / "a.png", np.zeros((4, 4, 3), np.uint8))
    (tmp_path / "capture.json").write_text(
        '{"format": "ffls-capture", "version": 1, "images": ["a.png"], "encoding": {"response": "%s"}}' % p.name)
    np.testing.assert_allclose(load_capture(tmp_path).response, curve, rtol=1e-6)


def test_load_response_errors(tmp_path):
    with pytest.raises(InputError, match="not found"):
        response_files.load_response(tmp_path / "nope.npy")
    bad = tmp_path / "bad.npy"
    np.save(bad, np.ones((10, 3)))
    with pytest.raises(InputError, match="shape") as e:
        response_files.load_response(bad)
    assert "bad.npy" in str(e.value)
    dec = tmp_path / "dec.npy"
    np.save(dec, np.linspace(1, 0, 256))
    with pytest.raises(InputError, match="non-decreasing"):
        response_files.load_response(dec)


def test_valid_pixel_mask_8_16_float():
    raw8 = np.array([[[255, 10, 10], [250, 250, 250], [3, 2, 1], [100, 0, 0]]], dtype=np.uint8)
    np.testing.assert_array_equal(rsp.valid_pixel_mask(raw8, 8), [[False, False, False, True]])
    # the same as normalised floats (ImageData.pixels)
    np.testing.assert_array_equal(rsp.valid_pixel_mask(raw8 / np.float32(255), 8), [[False, False, False, True]])
    raw16 = np.array([[[65535, 0, 0], [30000, 30000, 30000]]], dtype=np.uint16)
    np.testing.assert_array_equal(rsp.valid_pixel_mask(raw16, 16), [[False, True]])
    f = np.array([[[np.nan, 1, 1], [-1, 1, 1], [0.0, 0.0, 0.0], [50.0, 2.0, 1.0]]], dtype=np.float32)
    np.testing.assert_array_equal(rsp.valid_pixel_mask(f, "float"), [[False, False, False, True]])
    with pytest.raises(ValueError):
        rsp.valid_pixel_mask(f, 12)


def _write_bracket(folder, bracket, with_json=True):
    E, times, imgs = bracket
    names = []
    for k, im in enumerate(imgs):
        name = f"b{k}.png"
        cv2.imwrite(str(folder / name), cv2.cvtColor(im, cv2.COLOR_RGB2BGR))
        names.append(name)
    if with_json:
        (folder / "exposures.json").write_text(json.dumps({n: float(t) for n, t in zip(names, times)}))
    return names


def test_cli_response_from_exposures_json(tmp_path, bracket):
    from ffls.cli import main
    _write_bracket(tmp_path, bracket)
    out = tmp_path / "resp.npy"
    assert main(["calibrate", "response", str(tmp_path), "-o", str(out)]) == 0
    curve = response_files.load_response(out)
    z = np.arange(40, 220)
    ratio = curve[z, 1] / _finv(z.astype(np.float64))
    assert np.max(np.abs(ratio / np.median(ratio) - 1)) < 0.1


def test_exif_exposure_times(tmp_path, bracket):
    from PIL import Image
    _, times, imgs = bracket
    for k, (im, t) in enumerate(zip(imgs[:3], times[:3])):
        exif = Image.Exif()
        exif.get_ifd(0x8769)[33434] = float(t)
        Image.fromarray(im).save(tmp_path / f"e{k}.jpg", exif=exif, quality=95)
    _, ts, paths = rsp.read_bracket(tmp_path)
    np.testing.assert_allclose(ts, times[:3], rtol=1e-6)


def test_bracket_errors_name_files(tmp_path, bracket, capsys):
    from ffls.cli import main
    _write_bracket(tmp_path, bracket, with_json=False)
    with pytest.raises(InputError, match="ExposureTime") as e:
        rsp.read_bracket(tmp_path)
    assert "b0.png" in str(e.value)
    (tmp_path / "exposures.json").write_text(json.dumps({"b0.png": 0.1, "missing.png": 0.2}))
    assert main(["calibrate", "response", str(tmp_path)]) == 2
    assert "missing.png" in capsys.readouterr().err
    (tmp_path / "exposures.json").write_text(json.dumps({"b0.png": 0.1, "b1.png": -1}))
    with pytest.raises(InputError, match=r"exposure of .b1.png.: -1 s is not an exposure time"):
        rsp.read_bracket(tmp_path)
