"""The encoding of integer images: never guessed; calibrated from the matte spheres (ffls.spheres.encoding)."""
import importlib
import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ffls.cli import main
from ffls.errors import InputError
from ffls.io import capture as cap
from ffls.io.images import read_image, write_png
from ffls.radiance.encoding import gamma_decode, gamma_encode, srgb_encode
from ffls.radiance.photos import load_photo
from ffls.spheres.detect import find_spheres
from ffls.spheres.encoding import (
    EncodingCalibrationError,
    calibrate_capture_encoding,
    calibrate_encoding,
)
from ffls.spheres.estimate import estimate_lights
from ffls.synth.scene import SynthScene, write_synthetic_capture

RES = 256
N_LIGHTS = 14
ONE_SPHERE = (0.25, -0.25, 0.07)  # x, y on the ground, and the radius (= z of the centre), metres


def _one_line(e, *names):
    assert "\n" not in str(e)
    for n in names:
        assert n in str(e), (n, str(e))


@pytest.fixture(scope="module")
def linear_captures(tmp_path_factory):
    """Noise-free linear EXR captures: the default four spheres, and one sphere."""
    root = tmp_path_factory.mktemp("linear")
    four = write_synthetic_capture(root / "four", n_lights=N_LIGHTS, resolution=RES, progress=False, seed=3)
    one_scene = SynthScene(sphere_xy=(ONE_SPHERE[:2],), sphere_radius=ONE_SPHERE[2])
    one = write_synthetic_capture(root / "one", n_lights=N_LIGHTS, resolution=RES, progress=False, seed=4,
                                  scene=one_scene)
    return {"four": (root / "four", four["directions"]), "one": (root / "one", one["directions"])}


def encoded_capture(src, dst, true, bits=8, noise=1.0 / 255, n=None, encoding_key=None, seed=0, jpeg=None):
    """Copy the linear capture ``src`` to ``dst`` as integer PNGs encoded with ``true`` (no ``encoding`` key).

    ``jpeg`` (a quality, 8 bits only) writes JPEG files with OpenCV instead.
    """
    dst.mkdir()
    doc = json.loads((src / "capture.json").read_text())
    doc.pop("encoding")
    names = doc["images"][:n] if n else doc["images"]
    imgs = [read_image(src / nm).pixels.astype(np.float64) for nm in names]
    exposure = 0.9 / max(float(np.percentile(im, 99.9)) for im in imgs)
    rng = np.random.default_rng(seed)
    top = 255 if bits == 8 else 65535
    out = []
    for nm, im in zip(names, imgs):
        lin = np.clip(im * exposure, 0.0, None)
        enc = lin if true == "linear" else srgb_encode(lin) if true == "srgb" else gamma_encode(lin, true)
        enc = enc + rng.normal(0.0, noise, enc.shape)
        codes = np.rint(np.clip(enc, 0, 1) * top).astype(np.uint8 if bits == 8 else np.uint16)
        if jpeg:
            import cv2

            png = nm.replace(".exr", ".jpg")
            assert cv2.imwrite(str(dst / png), codes[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(jpeg)])
        else:
            png = nm.replace(".exr", ".png")
            write_png(dst / png, codes)
        out.append(png)
    doc["images"] = out
    if encoding_key is not None:
        doc["encoding"] = encoding_key
    (dst / "capture.json").write_text(json.dumps(doc))
    return dst


def _angles(lights, truth):
    ok = lights.ok_mask
    cos = np.clip(np.sum(lights.directions * truth[: len(lights)], axis=1), -1, 1)
    return np.degrees(np.arccos(cos))[ok]


# ----------------------------------------------------------------------------- the pure function
def _disc_normals():
    """(m, 3) normals of a sphere's visible disc seen along +y, on a 60 x 60 grid."""
    t = np.linspace(-0.95, 0.95, 60)
    x, y = np.meshgrid(t, t)
    inside = x * x + y * y < 0.95 ** 2
    return np.column_stack([x[inside], -np.sqrt(1 - x[inside] ** 2 - y[inside] ** 2), y[inside]])


def _random_light(rng):
    """A unit light direction on the camera's side (y < 0)."""
    light = rng.normal(size=3)
    light[1] = -abs(light[1]) - 0.5
    return light / np.linalg.norm(light)


def _sphere_shading(true_gamma, n_photos=8, seed=0):
    """Stored values of one matte sphere (Lambert + ambient) under random lights, encoded with ``true_gamma``."""
    rng = np.random.default_rng(seed)
    normals = _disc_normals()
    raw = []
    for _ in range(n_photos):
        light = _random_light(rng)
        lin = 0.8 * np.maximum(normals @ light, 0) + 0.03
        enc = gamma_encode(lin, true_gamma)[:, None] + rng.normal(0, 1 / 255, (len(lin), 3))
        raw.append([np.clip(np.rint(enc * 255), 0, 255) / 255])
    return raw, [normals]


@pytest.mark.parametrize("true_gamma, curve", [(1.0, "linear"), (1.8, "gamma"), (2.6, "gamma")])
def test_calibrate_encoding_on_arrays(true_gamma, curve):
    raw, normals = _sphere_shading(true_gamma)
    cal = calibrate_encoding(raw, normals, method="gamma")
    assert cal.curve == curve
    assert abs(cal.gamma - true_gamma) <= cal.uncertainty
    assert 0 < cal.uncertainty < 0.1
    assert cal.n_photos == 8 and cal.n_spheres == 1


def test_calibrate_encoding_same_for_any_workers():
    """The (photo, sphere) pairs selected and profiled in 2 worker processes give the same calibration,
    to the bit, as in this process."""
    raw, normals = _sphere_shading(2.2, n_photos=40)
    one = calibrate_encoding(raw, normals, code_step=1 / 255)
    assert one.n_units == 40 and one.curve == "gamma"
    assert calibrate_encoding(raw, normals, code_step=1 / 255, workers=2) == one


def test_encoding_named_by_bic_or_half_a_code():
    """Naming: the best gamma must beat a named curve by more than the BIC's ln(n_eff); failing that,
    a named curve within half a code value of it is named all the same (the file cannot tell them
    apart), and the summary says which test named it."""
    raw, normals = _sphere_shading(1.0, n_photos=40)
    cal = calibrate_encoding(raw, normals, code_step=1 / 255)
    assert cal.curve == "linear" and cal.linear_excess <= cal.bic_penalty
    assert "BIC" in cal.summary() and "half a code" not in cal.summary()
    # gamma 1.004: "significantly" off linear by the BIC, but 0.0015 from it at most, under half a code
    raw, normals = _sphere_shading(1.004, n_photos=40)
    assert calibrate_encoding(raw, normals).curve == "gamma"
    cal = calibrate_encoding(raw, normals, code_step=1 / 255)
    assert cal.curve == "linear" and cal.linear_excess > cal.bic_penalty
    assert "within half a code value" in cal.summary()
    # gamma 1.02: 0.0074 from linear at most, about two codes: not linear
    raw, normals = _sphere_shading(1.02, n_photos=40)
    assert calibrate_encoding(raw, normals, code_step=1 / 255).curve == "gamma"
    rec = cal.record()
    assert {"linear_excess", "srgb_excess", "bic_penalty"} <= set(rec)


def _four_spheres_with_misfit(encode, eps, n_photos=40, seed=0):
    """Stored values (rounding only, no noise) of four matte spheres whose shading has a small
    non-affine term ``eps_k (n . l)^2`` that differs between spheres (as interreflection does)."""
    rng = np.random.default_rng(seed)
    normals = _disc_normals()
    raw = []
    for _ in range(n_photos):
        light = _random_light(rng)
        c = np.maximum(normals @ light, 0)
        raw.append([np.repeat(np.rint(encode(0.8 * c + 0.03 + e * c * c) * 255)[:, None], 3, axis=1) / 255
                    for e in eps])
    return raw, [normals] * len(eps)


def test_spheres_disagreeing_widen_the_gamma_and_keep_the_named_curve():
    """A misfit the model lacks that differs between spheres moves their gammas apart; the free
    gamma must not win on it: an sRGB file is named srgb (the spheres' spread counts as noise,
    and the interval widens to it), while a gamma-2.2 file with the same misfit is still gamma."""
    eps = (-0.015, 0.015, -0.005, 0.01)
    clean = calibrate_encoding(*_four_spheres_with_misfit(srgb_encode, (0, 0, 0, 0)), code_step=1 / 255)
    cal = calibrate_encoding(*_four_spheres_with_misfit(srgb_encode, eps), code_step=1 / 255)
    assert clean.curve == "srgb" and cal.curve == "srgb"
    assert cal.srgb_excess < cal.bic_penalty and "half a code" not in cal.summary()
    assert cal.uncertainty > 10 * clean.uncertainty
    # the spheres' own gammas lie within the widened interval of the pooled one
    for k in range(4):
        raw, normals = _four_spheres_with_misfit(srgb_encode, eps)
        one = calibrate_encoding([[r[k]] for r in raw], [normals[k]], code_step=1 / 255)
        assert abs(one.gamma - cal.gamma) < cal.uncertainty
    g22 = calibrate_encoding(*_four_spheres_with_misfit(lambda v: gamma_encode(v, 2.2), eps), code_step=1 / 255)
    assert g22.curve == "gamma" and abs(g22.gamma - 2.2) <= g22.uncertainty
    assert g22.srgb_excess > g22.bic_penalty


def test_calibrate_encoding_refuses():
    raw, normals = _sphere_shading(2.2, n_photos=3)
    with pytest.raises(EncodingCalibrationError, match="only 3 photos"):
        calibrate_encoding(raw, normals)
    raw, normals = _sphere_shading(2.2)
    with pytest.raises(EncodingCalibrationError, match="no matte sphere"):
        calibrate_encoding(raw, normals, matte=[False])
    with pytest.raises(ValueError, match="method"):
        calibrate_encoding(raw, normals, method="polynomial")
    flat = [[np.full_like(r[0], 0.5)] for r in raw]  # no shading: nothing constrains the curve
    with pytest.raises(EncodingCalibrationError):
        calibrate_encoding(flat, normals)


def test_gamma_curve_round_trip():
    x = np.linspace(0, 1, 101)
    np.testing.assert_allclose(gamma_decode(gamma_encode(x, 2.2), 2.2), x, atol=1e-12)
    np.testing.assert_allclose(gamma_decode(np.array([0.5]), 2.0), [0.25])
    assert gamma_decode(np.float32([0.5]), 1.5).dtype == np.float32
    with pytest.raises(ValueError, match="gamma"):
        gamma_decode(x, 0.0)


# ----------------------------------------------------------------------------- captures
@pytest.mark.parametrize("true", ["linear", "srgb", 2.2])
def test_lights_calibrates_four_spheres(linear_captures, tmp_path, capsys, true):
    src, truth = linear_captures["four"]
    folder = encoded_capture(src, tmp_path / "c", true)
    assert main(["lights", str(folder), "--no-progress", "--workers", "1"]) == 0
    out = capsys.readouterr().out
    line = [ln for ln in out.splitlines() if ln.startswith("encoding: ")]
    assert len(line) == 1, out
    lights = cap.load_lights(folder / "lights.json")
    rec = lights.encoding
    assert rec["curve"] == ("gamma" if true == 2.2 else true), out
    assert rec["photos"] >= 8 and rec["spheres"] >= 3 and rec["method"] == "spheres:gamma"
    if true != "srgb":
        assert abs(rec["gamma"] - (1.0 if true == "linear" else true)) <= rec["uncertainty"], rec
    assert line[0].startswith(f"encoding: {'gamma 2.2' if true == 2.2 else true}")
    ang = _angles(lights, truth)
    assert lights.ok_mask.sum() >= N_LIGHTS - 2
    assert np.median(ang) < 1.0 and np.percentile(ang, 90) < 1.5, ang
    # the other commands find the calibrated encoding in lights.json
    c, l2 = cap.load_capture_and_lights(folder)
    assert c.encoding == cap.encoding_from_record(rec) and l2.encoding == rec
    # and how the cones were sized (the error model of ffls.spheres.uncertainty)
    assert l2.uncertainty["confidence"] == 0.95 and l2.uncertainty["cone_factor"] > 0


@pytest.mark.parametrize("true", [2.2, "linear"])
def test_one_sphere(linear_captures, tmp_path, true):
    """One matte sphere calibrates too (placed at its true centre: this tests the calibration, not detection)."""
    src, truth = linear_captures["one"]
    folder = encoded_capture(src, tmp_path / "c", true, seed=1)
    c = cap.load_capture(folder)
    spheres = find_spheres(read_image(c.image_paths[0]).pixels, c.K, c.dist, c.sphere_radius,
                           overrides=[{"center": list(ONE_SPHERE)}], world_from_camera=c.world_from_camera)
    cal, used = calibrate_capture_encoding(c, spheres=spheres)
    assert used is spheres and cal.n_spheres == 1
    assert cal.curve == ("gamma" if true == 2.2 else "linear"), cal.summary()
    assert abs(cal.gamma - (1.0 if true == "linear" else true)) <= cal.uncertainty, cal.summary()
    lights = estimate_lights(replace(c, encoding=cal.encoding), spheres=spheres, progress=False, workers=1)
    ang = _angles(lights, truth)
    assert np.median(ang) < 1.0, ang


def test_sixteen_bit(linear_captures, tmp_path):
    src, _ = linear_captures["four"]
    folder = encoded_capture(src, tmp_path / "c", 2.2, bits=16, noise=0.5 / 255)
    c = cap.load_capture(folder)
    assert read_image(c.image_paths[0]).bit_depth == 16
    with pytest.raises(InputError, match="16-bit image could be sRGB, linear or gamma") as e:
        load_photo(c, 0)
    _one_line(e.value, c.image_names[0], "capture.json", "ffls lights")
    cal, _ = calibrate_capture_encoding(c)
    assert cal.curve == "gamma" and abs(cal.gamma - 2.2) <= cal.uncertainty, cal.summary()


def test_jpeg(linear_captures, tmp_path):
    """JPEG files (quality 95: blocks and ringing on top of the noise) are calibrated too."""
    src, _ = linear_captures["four"]
    folder = encoded_capture(src, tmp_path / "c", "srgb", jpeg=95)
    c = cap.load_capture(folder)
    assert read_image(c.image_paths[0]).kind == "jpeg"
    cal, _ = calibrate_capture_encoding(c)
    assert cal.curve == "srgb", cal.summary()


def test_too_few_photos_one_line(linear_captures, tmp_path, capsys):
    src, _ = linear_captures["four"]
    folder = encoded_capture(src, tmp_path / "c", "srgb", n=3)
    assert main(["lights", str(folder), "--no-progress", "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    _one_line(err, "cannot calibrate the encoding", "capture.json", '"encoding"')
    assert not (folder / "lights.json").exists()


def test_explicit_encoding_wins(linear_captures, tmp_path, capsys):
    src, truth = linear_captures["four"]
    # linear files declared sRGB: the statement is obeyed (no calibration, no record)
    folder = encoded_capture(src, tmp_path / "c", "linear", encoding_key="srgb")
    assert main(["lights", str(folder), "--no-progress", "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert "encoding:" not in out
    lights = cap.load_lights(folder / "lights.json")
    assert lights.encoding is None
    # a lights.json record never overrides capture.json
    lights.encoding = {"curve": "gamma", "gamma": 1.7, "uncertainty": 0.01, "method": "spheres:gamma",
                       "spheres": 4, "photos": 14}
    cap.save_lights(lights, folder / "lights.json")
    c, l2 = cap.load_capture_and_lights(folder)
    assert c.encoding == "srgb" and l2.encoding["gamma"] == 1.7
    # float images are linear by definition: nothing to calibrate, and a record does not apply
    c = cap.load_capture(src)
    assert cap.apply_lights_encoding(c, l2).encoding == "linear"
    c = replace(c, encoding="auto")
    assert cap.apply_lights_encoding(c, l2) is c
    with pytest.raises(InputError, match="linear by definition"):
        calibrate_capture_encoding(c)
    shutil.rmtree(folder)


def test_unknown_encoding_refused_elsewhere(linear_captures, tmp_path, capsys):
    src, _ = linear_captures["four"]
    folder = encoded_capture(src, tmp_path / "c", "srgb")
    shutil.copy(src / "lights.json", folder / "lights.json")  # lights without an encoding record
    doc = json.loads((folder / "lights.json").read_text())
    for it in doc["lights"]:
        it["image"] = it["image"].replace(".exr", ".png")
    (folder / "lights.json").write_text(json.dumps(doc))
    assert main(["relight", str(folder), "--probe", "sky", "-o", str(tmp_path / "out.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert sum("error" in ln for ln in err) == 1
    _one_line(err[-1], "does not guess", "ffls lights", "capture.json")
    assert not (tmp_path / "out.png").exists()


def test_lights_record_round_trip_and_validation(tmp_path):
    rec = {"curve": "gamma", "gamma": 2.2, "uncertainty": 0.02, "method": "spheres:gamma", "spheres": 4,
           "photos": 40}
    lights = cap.Lights(["a.png"], [[0, 0, 1.0]], encoding=rec)
    cap.save_lights(lights, tmp_path / "lights.json")
    back = cap.load_lights(tmp_path / "lights.json")
    assert back.encoding == rec and cap.encoding_from_record(rec) == {"gamma": 2.2}
    assert cap.encoding_from_record({"curve": "srgb"}) == "srgb"
    for bad in ({"curve": "gamma"}, {"curve": "gamma", "gamma": 30}, {"curve": "log"}, "srgb"):
        doc = json.loads((tmp_path / "lights.json").read_text())
        doc["encoding"] = bad
        (tmp_path / "lights.json").write_text(json.dumps(doc))
        with pytest.raises(InputError, match="encoding") as e:
            cap.load_lights(tmp_path / "lights.json")
        _one_line(e.value, "lights.json")
        with pytest.raises(ValueError):
            cap.Lights(["a.png"], [[0, 0, 1.0]], encoding=bad)


def test_gamma_files_on_a_grey_ground_are_calibrated(tmp_path):
    """Gamma-2.2 8-bit photos of grey balls on a grey ground, made without ffls.synth: the stored values
    compress the contrast so far that no candidate survives detection on them; the spheres are then
    searched on the values decoded as sRGB, and the gamma is calibrated (not taken from that search)."""
    import detect_scenes as ds

    sc = ds.layout(3, shape=(240, 320), f=400.0, R=0.04, seed=3)
    for b in sc.balls:
        b.albedo = (0.45, 0.45, 0.45)
    imgs = ds.render(sc, ds.lights(24, seed=1), background="grey", noise=0.004, seed=2)
    imgs = np.clip(imgs / np.percentile(imgs, 99.5) * 0.9, 0, 1)
    names = []
    for i, im in enumerate(imgs):
        names.append(f"p{i:02d}.png")
        write_png(tmp_path / names[-1], np.rint(gamma_encode(im, 2.2) * 255).astype(np.uint8))
    (tmp_path / "capture.json").write_text(json.dumps({
        "format": "ffls-capture", "version": 1, "images": names, "camera": {"K": sc.K.tolist()},
        "sphere_radius": 0.04}))
    calibration, spheres = calibrate_capture_encoding(cap.load_capture(tmp_path))
    assert len(spheres) == 3
    assert calibration.curve == "gamma" and abs(calibration.gamma - 2.2) <= max(calibration.uncertainty, 0.05)


# ----------------------------------------------------------------------------- decoding once
def test_photos_decoded_once_calibrate_and_estimate_as_read(linear_captures, tmp_path, monkeypatch):
    """decode_photos of a capture whose encoding is unstated keeps the stored codes; the encoding
    calibration and the light estimation read the photos from them, with the same numbers as
    reading the files: the same record, the same spheres' values, the same lights."""
    from ffls.radiance.photos import read_photo
    from ffls.spheres.estimate import capture_samples, decode_photos

    src, _ = linear_captures["four"]
    c = cap.load_capture(encoded_capture(src, tmp_path / "c", "srgb"))
    decoded = decode_photos(c, workers=1)
    assert decoded.stored and decoded.linear is None and decoded.raw.dtype == np.uint8
    assert decoded.photo(0) is None  # the encoding is unknown until calibrated
    import ffls.spheres.encoding as encoding_module

    reads = []
    real = encoding_module.read_image
    monkeypatch.setattr(encoding_module, "read_image", lambda p, *a, **k: reads.append(p) or real(p, *a, **k))
    cal_a, sph_a = calibrate_capture_encoding(c, decoded=decoded)
    assert len(reads) == 1  # the first photo's bit depth only
    monkeypatch.undo()
    cal_b, sph_b = calibrate_capture_encoding(c)
    ra, rb = cal_a.record(), cal_b.record()  # the spheres agree to rounding (chunked reductions): so do these
    assert ra.keys() == rb.keys() and cal_a.curve == cal_b.curve == "srgb"
    for key in ra:
        assert ra[key] == (pytest.approx(rb[key], rel=1e-6, abs=1e-3) if isinstance(ra[key], (float, list))
                           else rb[key]), key
    assert np.allclose([s.center_px for s in sph_a], [s.center_px for s in sph_b], atol=1e-6)
    c2 = replace(c, encoding=cal_a.encoding)
    samples = capture_samples(c2, sph_a, decoded.shape)
    rows = np.concatenate([s.rows for s in samples])
    cols = np.concatenate([s.cols for s in samples])
    for i in (0, 5):
        lin, codes, depth = decoded.photo(i, c2, (rows, cols))
        ph = read_photo(c2, i)
        assert depth == 8 and np.array_equal(lin[rows, cols], ph.linear[rows, cols])
        assert np.array_equal(codes, np.rint(ph.raw * 255).astype(np.uint8))
        assert np.array_equal(decoded.photo(i, c2)[0], ph.linear)  # the whole photo
    a = estimate_lights(c2, spheres=sph_a, progress=False, workers=1, decoded=decoded)
    b = estimate_lights(c2, spheres=sph_a, progress=False, workers=1)
    assert np.array_equal(a.directions, b.directions) and a.status == b.status


def test_cli_lights_reads_each_photo_once(linear_captures, tmp_path, monkeypatch, capsys):
    """`ffls lights` on integer files with no stated encoding reads every photo once (decoding,
    encoding calibration, detection and the first pass all use that decoding); the first photo
    is opened again only to learn the bit depth."""
    import ffls.io.images as images

    src, _ = linear_captures["four"]
    folder = encoded_capture(src, tmp_path / "c", 2.2)
    reads = {}
    real = images.read_image

    def counting(path, *args, **kwargs):
        name = str(path).rsplit("/", 1)[-1]
        reads[name] = reads.get(name, 0) + 1
        return real(path, *args, **kwargs)

    for module in ("ffls.io.images", "ffls.radiance.photos", "ffls.spheres.encoding"):
        monkeypatch.setattr(f"{module}.read_image", counting)
    assert main(["lights", str(folder), "--no-progress", "--workers", "1"]) == 0
    assert "encoding: gamma 2.2" in capsys.readouterr().out
    names = json.loads((folder / "capture.json").read_text())["images"]
    assert set(reads) == set(names)
    assert all(reads[n] == 1 for n in names[1:]), reads


def _exposed_capture(tag):
    """Stored values and normals of the four spheres of a ``bench_conditions`` capture exposed 3x
    (``ffls synth --format png8 --unstated-encoding --exposure 3``, 384 px; every third photo,
    every second pixel): ``c02`` sRGB, ``c04`` gamma 2.2. Their lit sides show codes 0.44-0.91 only."""
    data = np.load(Path(__file__).parent / "data" / "encoding_exposed_srgb_gamma22.npz")
    raw = [data[f"{tag}_raw_{k}"] for k in range(4)]
    return ([[raw[k][p] / 255.0 for k in range(4)] for p in range(len(raw[0]))],
            [data[f"{tag}_normals_{k}"].astype(np.float64) for k in range(4)])


def test_srgb_named_where_the_lit_codes_cannot_tell_it_from_a_gamma():
    """On codes 0.44-0.91 the sRGB curve is gamma 2.28 up to a scale and an offset (what each pair's
    light and ambient term absorb) within 0.1 code, less than the pairs' shading bends beyond the
    model: the BIC's preference for the free gamma there is the model's misfit, and sRGB is named
    (the dark sides, which show the toe, agree). A gamma-2.2 file exposed alike is still a gamma."""
    cal = calibrate_encoding(*_exposed_capture("c02"), code_step=1 / 255)
    assert cal.srgb_excess > cal.bic_penalty  # the BIC alone names the gamma
    assert cal.curve == "srgb" and cal.naming == "shown_codes"
    assert 0.4 < cal.shown_codes[0] < 0.5 and 0.85 < cal.shown_codes[1] < 0.95
    assert cal.dark_srgb_excess is not None and cal.dark_srgb_excess < cal.dark_bic_penalty
    assert "cannot tell it from the best gamma" in cal.summary() and "dark sides agree" in cal.summary()
    rec = cal.record()
    assert rec["naming"] == "shown_codes" and len(rec["shown_codes"]) == 2 and "dark_srgb_excess" in rec
    g22 = calibrate_encoding(*_exposed_capture("c04"), code_step=1 / 255)
    assert g22.curve == "gamma" and g22.naming == "bic" and g22.dark_srgb_excess is None


def test_encoding_calibration_finds_the_spheres_with_its_workers(linear_captures, tmp_path, monkeypatch):
    """``calibrate_capture_encoding(..., workers=2)`` (``ffls lights`` on 8-bit photos with no
    encoding stated) passes its workers to the sphere detection, whose outline fits then run in
    forked processes instead of the main one; the spheres and the record are the same."""
    from ffls.spheres import detect
    from ffls.spheres.estimate import decode_photos

    src, _ = linear_captures["four"]
    c = cap.load_capture(encoded_capture(src, tmp_path / "c", "srgb"))
    decoded = decode_photos(c, workers=1)
    cal_1, sph_1 = calibrate_capture_encoding(c, decoded=decoded)
    seen = []
    real = detect.find_spheres_in_capture
    monkeypatch.setattr(detect, "find_spheres_in_capture", lambda *a, **k: seen.append(k.get("workers")) or real(*a, **k))
    cal_2, sph_2 = calibrate_capture_encoding(c, decoded=decoded, workers=2)
    assert seen == [2]
    assert cal_2.record() == cal_1.record()
    assert [tuple(s.center_px) for s in sph_2] == [tuple(s.center_px) for s in sph_1]


def test_spheres_declared_mirrors_do_not_calibrate(linear_captures, tmp_path):
    """A sphere capture.json declares a mirror (chrome, black glossy) is not fitted as a matte one:
    with only such spheres the encoding is asked for, naming why."""
    src, _ = linear_captures["four"]
    folder = encoded_capture(src, tmp_path / "c", "srgb")
    doc = json.loads((folder / "capture.json").read_text())
    doc["sphere_material"] = "mirror"
    (folder / "capture.json").write_text(json.dumps(doc))
    with pytest.raises(InputError) as e:
        calibrate_capture_encoding(cap.load_capture(folder))
    _one_line(e.value, "cannot calibrate the encoding", "no matte sphere", "capture.json", '"encoding"')


def test_unknown_encoding_line_names_the_route_for_a_capture_without_spheres():
    """An object capture has no spheres to calibrate from: the refusal names the calibration
    capture's lights.json (whose "encoding" record ffls applies), not only 'ffls lights'."""
    from ffls.radiance.photos import unknown_encoding_message

    line = unknown_encoding_message(8)
    assert "\n" not in line
    assert "'ffls lights'" in line and "calibration capture" in line and "\"encoding\" record" in line


def test_lights_finds_the_spheres_again_on_the_calibrated_photos(linear_captures, tmp_path, monkeypatch):
    """With no encoding stated, the spheres the lights are estimated with are found on the photos
    linearised with the calibrated curve (the stored codes in memory), not on the stored values the
    calibration found them on: a curve moves a limb's half-way step toward its dark side (0.2-0.3
    px on an anti-aliased sRGB render, ``docs/spheres.md``)."""
    from ffls.spheres import detect
    from ffls.spheres.estimate import decode_photos

    src, _ = linear_captures["four"]
    folder = encoded_capture(src, tmp_path / "c", 2.2)
    calls = []
    real = detect.find_spheres_in_capture

    def spy(capture, *args, **kwargs):
        calls.append((capture.encoding, kwargs.get("stats")))
        return real(capture, *args, **kwargs)

    monkeypatch.setattr(detect, "find_spheres_in_capture", spy)
    assert main(["lights", str(folder), "--no-progress", "--workers", "1"]) == 0
    encoding, stats = calls[-1]  # the spheres handed to the estimation
    assert encoding not in ("linear", "auto"), encoding  # the calibrated curve
    stored = decode_photos(cap.load_capture(folder)).stats.max
    assert stats is not None and stats.max.shape == stored.shape
    lit = stored > 0.2
    # the linear max image: the stored one decoded with the curve (2.2), not the stored values
    assert np.allclose(stats.max[lit], gamma_decode(stored[lit].astype(np.float64), 2.2), rtol=0.1, atol=0.01)
    assert not np.allclose(stats.max[lit], stored[lit], rtol=0.1, atol=0.01)


def test_second_detection_fits_the_first_ones_circles(linear_captures, tmp_path, monkeypatch):
    """The detection on the linearised photos starts from the circles found on the stored codes
    (``seeds``): no Hough transform or photo-edge search again, and the same outlines as the full
    search on the same linearised photos (docs/spheres.md, "Speed")."""
    from ffls.spheres import detect

    src, _ = linear_captures["four"]
    folder = encoded_capture(src, tmp_path / "c", 2.2)
    calls, searched = [], []
    real, hough = detect.find_spheres_in_capture, detect.hough_circle_candidates

    def spy(capture, *args, **kwargs):
        found = real(capture, *args, **kwargs)
        calls.append((capture, kwargs, found, len(searched)))
        return found

    def counted(*args, **kwargs):
        searched.append(1)
        return hough(*args, **kwargs)

    monkeypatch.setattr(detect, "find_spheres_in_capture", spy)
    monkeypatch.setattr(detect, "hough_circle_candidates", counted)
    assert main(["lights", str(folder), "--no-progress", "--workers", "1"]) == 0
    (_, _, first, n_first), (capture, kwargs, second, n_second) = calls[-2], calls[-1]
    assert kwargs.get("seeds") is first and n_second == n_first  # seeded: no search in the second
    full = real(capture, stats=kwargs["stats"], bit_depths=kwargs["bit_depths"], workers=1)
    assert len(searched) == n_second + 1
    a = np.array([[*ft.center_px, ft.radius_px] for ft in full])
    b = np.array([[*ft.center_px, ft.radius_px] for ft in second])
    assert a.shape == b.shape == (4, 3) and np.abs(a - b).max() < 1e-9, (a, b)


def test_tone_curve_fit_evaluates_the_units_stacked(monkeypatch):
    """The polynomial tone curve's fit evaluates the RSS and its gradient of every unit with a few
    hundred distinct (r, g, b) triples (an 8-bit photo's sphere) stacked, in one pass of array
    operations, not one call per unit; the calibration is the one each unit's own evaluation gives
    (the same arithmetic summed in another order: within 1e-7)."""
    rng = np.random.default_rng(5)
    normals = _disc_normals()
    raw = []
    for _ in range(24):  # grey pixels: each unit's triples are its distinct codes, at most 256
        lin = 0.8 * np.maximum(normals @ _random_light(rng), 0) + 0.03
        enc = np.clip(np.rint((srgb_encode(lin) + rng.normal(0, 1 / 255, len(lin))) * 255), 0, 255) / 255
        raw.append([np.repeat(enc[:, None], 3, axis=1)])
    calls = []
    unit = getattr(importlib.import_module("ffls.spheres.encoding"), "_Unit")
    real = unit.rss_and_gradient
    monkeypatch.setattr(unit, "rss_and_gradient", lambda self, shared: calls.append(1) or real(self, shared))
    stacked = calibrate_encoding(raw, [normals], code_step=1 / 255)
    assert stacked.order >= 0 and stacked.polynomial_excess is not None and calls == []
    monkeypatch.setattr("ffls.spheres.encoding._StackedUnits.SMALL", -1)  # every unit on its own
    alone = calibrate_encoding(raw, [normals], code_step=1 / 255)
    assert len(calls) > 10 * alone.n_units
    assert stacked.curve == alone.curve and stacked.n_units == alone.n_units == 24
    for a, b in [(stacked.gamma, alone.gamma), (stacked.polynomial_excess, alone.polynomial_excess),
                 (stacked.srgb_excess, alone.srgb_excess), *zip(stacked.coefficients, alone.coefficients)]:
        assert a == pytest.approx(b, rel=1e-7, abs=1e-9)


def test_tone_curve_fit_stacks_the_units_once_per_round(monkeypatch):
    """The units are stacked (:class:`_StackedUnits`) once per selection round and the polynomial
    fit of every order reuses it (it was rebuilt per order and per call)."""
    rng = np.random.default_rng(5)
    normals = _disc_normals()
    raw = []
    for _ in range(24):
        lin = 0.8 * np.maximum(normals @ _random_light(rng), 0) + 0.03
        enc = np.clip(np.rint((srgb_encode(lin) + rng.normal(0, 1 / 255, len(lin))) * 255), 0, 255) / 255
        raw.append([np.repeat(enc[:, None], 3, axis=1)])
    stacked = getattr(importlib.import_module("ffls.spheres.encoding"), "_StackedUnits")
    built, real = [], stacked.__init__
    monkeypatch.setattr(stacked, "__init__", lambda self, *a: built.append(1) or real(self, *a))
    fit = calibrate_encoding(raw, [normals], code_step=1 / 255)
    assert fit.polynomial_excess is not None and len(built) == 2
