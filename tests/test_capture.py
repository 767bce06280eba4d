"""ffls.io.capture: capture.json, lights.json and RTI .lp files."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ffls.io import capture as cap
from ffls import conventions
from ffls.errors import InputError
from ffls.io.images import write_exr, write_png
from ffls.radiance.encoding import srgb_decode
from ffls.radiance.photos import load_photo, load_photos


def _one_line(e: Exception, *names: str) -> None:
    assert "\n" not in str(e)
    for n in names:
        assert n in str(e), (n, str(e))


def _make(folder, n=3, size=(6, 4), doc_extra=None, depth=8, rng=None):
    """A capture folder with n PNG images of (W, H) = size."""
    rng = rng or np.random.default_rng(1)
    folder.mkdir(exist_ok=True)
    names = [f"img_{i:03d}.png" for i in range(n)]
    imgs = []
    for nm in names:
        hi = 255 if depth == 8 else 65535
        im = rng.integers(0, hi + 1, size=(size[1], size[0], 3)).astype(np.uint8 if depth == 8 else np.uint16)
        write_png(folder / nm, im)
        imgs.append(im)
    doc = {"format": "ffls-capture", "version": 1, "images": names,
           "camera": {"K": [[100, 0, 3], [0, 100, 2], [0, 0, 1]], "dist": [0, 0, 0, 0, 0]},
           "sphere_radius": 0.025}
    doc.update(doc_extra or {})
    (folder / "capture.json").write_text(json.dumps(doc))
    return names, imgs


def _edit(folder, **changes):
    p = folder / "capture.json"
    doc = json.loads(p.read_text())
    for k, v in changes.items():
        if v is None:
            doc.pop(k, None)
        else:
            doc[k] = v
    p.write_text(json.dumps(doc))


# ----------------------------------------------------------------------------- capture.json
def test_load_capture_and_images(tmp_path):
    names, imgs = _make(tmp_path / "c")
    c = cap.load_capture(tmp_path / "c")
    assert c.image_names == names and len(c) == 3
    assert c.encoding == "auto" and c.hemisphere == "upper"
    assert c.world_from_camera_is_default
    np.testing.assert_array_equal(c.world_from_camera, conventions.DEFAULT_WORLD_FROM_CAMERA)
    assert c.K.shape == (3, 3) and c.sphere_radius == 0.025
    with pytest.raises(InputError, match="does not guess") as e:  # 8-bit, no encoding: never guessed
        load_photo(c, 1)
    _one_line(e.value, "img_001.png")
    _edit(tmp_path / "c", encoding="srgb")
    c = cap.load_capture(tmp_path / "c")
    img = load_photo(c, 1)
    assert img.dtype == np.float32 and img.shape == (4, 6, 3)
    np.testing.assert_allclose(img, srgb_decode(imgs[1] / 255.0), atol=1e-6)
    basis = load_photos(c, progress=False)
    assert basis.shape == (3, 4, 6, 3) and basis.dtype == np.float32
    np.testing.assert_array_equal(basis[1], img)
    np.testing.assert_array_equal(load_photos(c, [2, 0], progress=False)[0], load_photo(c, 2))


def test_encoding_rules(tmp_path):
    _, imgs = _make(tmp_path / "c", depth=16)
    c = cap.load_capture(tmp_path / "c")
    with pytest.raises(InputError, match="16-bit image could be sRGB, linear or gamma"):  # 16-bit: not guessed either
        load_photo(c, 0)
    _edit(tmp_path / "c", encoding="linear")
    c = cap.load_capture(tmp_path / "c")
    np.testing.assert_allclose(load_photo(c, 0), imgs[0] / 65535.0, atol=1e-7)
    _edit(tmp_path / "c", encoding={"gamma": 1.8})
    c = cap.load_capture(tmp_path / "c")
    assert c.encoding == {"gamma": 1.8}
    np.testing.assert_allclose(load_photo(c, 0), (imgs[0] / 65535.0) ** 1.8, rtol=1e-5, atol=1e-7)
    for bad in ({"gamma": 9.0}, {"gamma": "2.2"}, {"gamma": 2.2, "x": 1}):
        _edit(tmp_path / "c", encoding=bad)
        with pytest.raises(InputError, match="encoding") as e:
            cap.load_capture(tmp_path / "c")
        _one_line(e.value, "capture.json")
    _edit(tmp_path / "c", encoding="srgb")
    c = cap.load_capture(tmp_path / "c")
    np.testing.assert_allclose(load_photo(c, 0), srgb_decode(imgs[0] / 65535.0), atol=1e-6)
    _edit(tmp_path / "c", encoding="gamma22")
    with pytest.raises(InputError, match="encoding") as e:
        cap.load_capture(tmp_path / "c")
    _one_line(e.value, "capture.json")


def test_exr_capture_is_linear(tmp_path, rng):
    folder = tmp_path / "c"
    folder.mkdir()
    rgb = rng.random((4, 5, 3)).astype(np.float32) * 7
    write_exr(folder / "a.exr", rgb)
    (folder / "capture.json").write_text(json.dumps({"format": "ffls-capture", "version": 1, "images": ["a.exr"]}))
    c = cap.load_capture(folder)
    assert c.K is None
    np.testing.assert_array_equal(load_photo(c, 0), rgb)


@pytest.mark.parametrize("ext", [".npy", ".csv"])
def test_response_table(tmp_path, ext):
    _, imgs = _make(tmp_path / "c")
    table = np.stack([np.linspace(0, 1, 256) ** g for g in (1.8, 2.0, 2.2)], axis=1)
    if ext == ".npy":
        np.save(tmp_path / "c" / "response.npy", table)
    else:
        np.savetxt(tmp_path / "c" / "response.csv", table, delimiter=",")
    _edit(tmp_path / "c", encoding={"response": "response" + ext})
    c = cap.load_capture(tmp_path / "c")
    img = load_photo(c, 0)
    for ch in range(3):
        np.testing.assert_allclose(img[..., ch], table[imgs[0][..., ch], ch], rtol=1e-6)


def test_bad_response_table(tmp_path):
    _make(tmp_path / "c")
    np.save(tmp_path / "c" / "response.npy", np.linspace(1, 0, 256))  # decreasing
    _edit(tmp_path / "c", encoding={"response": "response.npy"})
    with pytest.raises(InputError, match="non-decreasing") as e:
        cap.load_capture(tmp_path / "c")
    _one_line(e.value, "response.npy")
    _edit(tmp_path / "c", encoding={"response": "missing.npy"})
    with pytest.raises(InputError, match="missing.npy") as e:
        cap.load_capture(tmp_path / "c")
    _one_line(e.value, "capture.json")


def test_missing_folder_and_json(tmp_path):
    with pytest.raises(InputError, match="not found") as e:
        cap.load_capture(tmp_path / "nowhere")
    _one_line(e.value, "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="not found") as e:
        cap.load_capture(tmp_path / "empty")
    _one_line(e.value, "capture.json")


def test_corrupt_json(tmp_path):
    _make(tmp_path / "c")
    (tmp_path / "c" / "capture.json").write_text('{"format": "ffls-capture", "version": 1,\n "images": [')
    with pytest.raises(InputError, match="corrupt JSON at line 2") as e:
        cap.load_capture(tmp_path / "c")
    _one_line(e.value, "capture.json")


@pytest.mark.parametrize("change,key", [
    ({"images": None}, "images: missing key"),
    ({"format": "other"}, "format"),
    ({"version": 7}, "version"),
    ({"images": []}, "images"),
    ({"images": ["img_000.png", "img_000.png"]}, "listed twice"),
    ({"images": ["../outside.png"]}, "inside it"),
    ({"camera": {"K": [[1, 0], [0, 1]]}}, "camera.K"),
    ({"camera": {"K": [[1e308, 0, 3], [0, 1e308, 2], [0, 0, 1]]}}, "camera.K: values beyond +-1e+08"),
    ({"camera": {"K": [[1e7, 0, 3], [0, 100, 2], [0, 0, 1]]}}, "camera.K: fx / fy = 100000"),
    ({"camera": {"K": [[100, 0, 3], [0, 100, 2], [0, 0, 1]], "dist": [1, 2]}}, "camera.dist"),
    ({"camera": {"world_from_camera": np.eye(4).tolist() * 1 + [[0, 0, 0, 1]]}}, "camera.world_from_camera"),
    ({"camera": {"world_from_camera": (2 * np.eye(4)).tolist()}}, "rigid"),
    ({"sphere_radius": -1}, "sphere_radius"),
    ({"sphere_radius": "big"}, "sphere_radius"),
    ({"hemisphere": "lower"}, "hemisphere"),
    ({"scene_center": [0, 0]}, "scene_center"),
    ({"spheres": [{"center_px": [1, 2], "radius_px": -3}]}, "spheres[0].radius_px"),
    ({"spheres": [{}]}, "spheres[0]"),
    ({"image_size": [6]}, "image_size"),
])
def test_invalid_values_name_the_key(tmp_path, change, key):
    _make(tmp_path / "c")
    _edit(tmp_path / "c", **change)
    with pytest.raises(InputError) as e:
        cap.load_capture(tmp_path / "c")
    _one_line(e.value, "capture.json", key)


def test_listed_image_missing(tmp_path):
    names, _ = _make(tmp_path / "c")
    (tmp_path / "c" / names[1]).unlink()
    with pytest.raises(InputError) as e:
        cap.load_capture(tmp_path / "c")
    _one_line(e.value, "capture.json", names[1])


def test_image_sizes_disagree(tmp_path):
    names, _ = _make(tmp_path / "c", doc_extra={"encoding": "srgb"})
    write_png(tmp_path / "c" / names[2], np.zeros((5, 6, 3), np.uint8))
    with pytest.raises(InputError, match="6x5 but the first image") as e:  # from the headers, on loading
        cap.load_capture(tmp_path / "c")
    _one_line(e.value, names[2], names[0])


def test_image_size_key_checked(tmp_path):
    _make(tmp_path / "c", doc_extra={"image_size": [7, 4]})
    with pytest.raises(InputError, match="image_size 7x4") as e:  # from the headers, on loading
        cap.load_capture(tmp_path / "c")
    _one_line(e.value, "img_000.png")


def test_corrupt_image_in_capture(tmp_path):
    names, _ = _make(tmp_path / "c")
    (tmp_path / "c" / names[0]).write_bytes(b"broken")
    c = cap.load_capture(tmp_path / "c")
    with pytest.raises(InputError) as e:
        load_photos(c, progress=False)
    _one_line(e.value, names[0])


def test_capture_round_trip(tmp_path):
    wfc = np.eye(4)
    wfc[:3, 3] = [0.1, 0.2, 0.3]
    _make(tmp_path / "c", doc_extra={
        "camera": {"K": [[100, 0, 3], [0, 100, 2], [0, 0, 1]], "dist": [0.1, 0, 0, 0, 0], "world_from_camera": wfc.tolist()},
        "spheres": [{"center": [0.1, 0, 0]}, {"center_px": [3, 2], "radius_px": 1.5}],
        "scene_center": [0, 0, 0.5], "hemisphere": "full", "units": "m", "image_size": [6, 4],
        "encoding": "linear", "note": "kept"})
    c = cap.load_capture(tmp_path / "c")
    assert not c.world_from_camera_is_default and c.extra == {"note": "kept"}
    before = json.loads((tmp_path / "c" / "capture.json").read_text())
    (tmp_path / "c" / "capture.json").unlink()
    cap.save_capture(c)
    c2 = cap.load_capture(tmp_path / "c")
    for k in ("image_names", "encoding", "hemisphere", "spheres", "image_size", "units", "extra", "sphere_radius"):
        assert getattr(c2, k) == getattr(c, k), k
    for k in ("K", "dist", "world_from_camera", "scene_center"):
        np.testing.assert_array_equal(getattr(c2, k), getattr(c, k))
    assert json.loads((tmp_path / "c" / "capture.json").read_text())["camera"] == before["camera"]
    assert sorted(p.name for p in (tmp_path / "c").iterdir() if p.name.startswith(".")) == []


# ----------------------------------------------------------------------------- lights.json
def _lights_doc(names, dirs, **extra):
    items = [{"image": n, "direction": list(map(float, d))} for n, d in zip(names, dirs)]
    for it in items:
        it.update(extra)
    return {"format": "ffls-lights", "version": 1, "lights": items}


def _unit(rng, n):
    d = rng.standard_normal((n, 3))
    d[:, 2] = np.abs(d[:, 2])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_lights_round_trip(tmp_path, rng):
    names, _ = _make(tmp_path / "c")
    c = cap.load_capture(tmp_path / "c")
    dirs = _unit(rng, 3)
    # near lights' positions lie along their directions (a position off it is refused: test_user17)
    lights = cap.Lights(names, dirs, positions=[2.0 * dirs[0], [np.nan] * 3, 3.5 * dirs[2]],
                        status=["ok", "rejected", "ok"], reasons=[None, "sphere saturated", None],
                        extra=[{"uncertainty_deg": 0.5}, {}, {"source": "manual"}])
    p = cap.save_lights(lights, tmp_path / "c" / "lights.json")
    back = cap.load_lights(p, c)
    assert back.image_names == names and back.status == lights.status and back.reasons == lights.reasons
    np.testing.assert_allclose(back.directions, dirs, atol=1e-15)
    np.testing.assert_array_equal(back.positions, lights.positions)
    assert back.extra == lights.extra
    idx, d = back.accepted()
    np.testing.assert_array_equal(idx, [0, 2])
    np.testing.assert_array_equal(back.ok_mask, [True, False, True])
    np.testing.assert_allclose(d, dirs[[0, 2]], atol=1e-15)


@pytest.mark.parametrize("key, rec", [
    ("uncertainty", {"cone_factor": 2.61, "n_tail": 120, "scale": 1.4, "floor_deg": 0.2, "source": "disagreement"}),
    ("flat_field", {"model": "cos4", "strength": 1.02, "applied": True, "gradients": [[0.05, -0.01]],
                    "measured": [None], "photos": [3]}),
])
def test_lights_capture_records_round_trip_and_checked(tmp_path, rng, key, rec):
    """The top-level ``uncertainty`` (how the cones were sized) and ``flat_field`` (the lens's
    fall-off) records are kept; a non-object is refused, naming the key."""
    names, _ = _make(tmp_path / "c")
    c = cap.load_capture(tmp_path / "c")
    p = cap.save_lights(cap.Lights(names, _unit(rng, 3), **{key: rec}), tmp_path / "c" / "lights.json")
    assert getattr(cap.load_lights(p, c), key) == rec
    doc = json.loads(p.read_text())
    for bad in ([2.61], None):  # null too: the record is an object or absent
        doc[key] = bad
        p.write_text(json.dumps(doc))
        with pytest.raises(InputError, match=f"{key}: expected an object"):
            cap.load_lights(p, c)
    del doc[key]
    doc["lights"][0]["uncertainty_deg"] = -1.0  # a cone radius cannot be negative
    p.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="uncertainty_deg: a 95% cone's radius is between 0 and 180 deg, got -1"):
        cap.load_lights(p, c)


def test_lights_reordered_to_capture(tmp_path, rng):
    names, _ = _make(tmp_path / "c")
    c = cap.load_capture(tmp_path / "c")
    dirs = _unit(rng, 3)
    (tmp_path / "l.json").write_text(json.dumps(_lights_doc(names[::-1], dirs[::-1])))
    back = cap.load_lights(tmp_path / "l.json", c)
    assert back.image_names == names
    np.testing.assert_allclose(back.directions, dirs, atol=1e-15)


def test_direction_not_unit(tmp_path, rng):
    names, _ = _make(tmp_path / "c")
    dirs = _unit(rng, 3)
    dirs[1] *= 1.01
    (tmp_path / "l.json").write_text(json.dumps(_lights_doc(names, dirs)))
    with pytest.raises(InputError, match="not a unit vector") as e:
        cap.load_lights(tmp_path / "l.json")
    _one_line(e.value, "l.json", names[1], "1.01")


def test_lights_names_must_match_capture(tmp_path, rng):
    names, _ = _make(tmp_path / "c")
    c = cap.load_capture(tmp_path / "c")
    (tmp_path / "l.json").write_text(json.dumps(_lights_doc([names[0], "stranger.png", names[2]], _unit(rng, 3))))
    with pytest.raises(InputError, match="not in the capture") as e:
        cap.load_lights(tmp_path / "l.json", c)
    _one_line(e.value, "l.json", "stranger.png")
    (tmp_path / "l.json").write_text(json.dumps(_lights_doc(names[:2], _unit(rng, 2))))
    with pytest.raises(InputError, match="has no light") as e:
        cap.load_lights(tmp_path / "l.json", c)
    _one_line(e.value, "l.json", names[2])


@pytest.mark.parametrize("mutate,match", [
    (lambda d: d["lights"][0].pop("direction"), "direction: missing key"),
    (lambda d: d["lights"][0].update(direction=[0, 0, "x"]), "direction"),
    (lambda d: d["lights"][0].update(status="maybe"), "status"),
    (lambda d: d["lights"][0].update(status="rejected"), "reason"),
    (lambda d: d["lights"][1].update(image=d["lights"][0]["image"]), "two lights"),
    (lambda d: d.update(format="ffls-capture"), "format"),
    (lambda d: d["lights"][0].update(position=[1, 2]), "position"),
])
def test_bad_lights_json(tmp_path, rng, mutate, match):
    doc = _lights_doc(["a.png", "b.png"], _unit(rng, 2))
    mutate(doc)
    (tmp_path / "l.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=match) as e:
        cap.load_lights(tmp_path / "l.json")
    _one_line(e.value, "l.json")


def test_non_finite_direction(tmp_path):
    (tmp_path / "l.json").write_text('{"format": "ffls-lights", "version": 1, "lights": '
                                     '[{"image": "a.png", "direction": [NaN, 0, 1]}]}')
    with pytest.raises(InputError, match="non-finite") as e:
        cap.load_lights(tmp_path / "l.json")
    _one_line(e.value, "l.json")


def test_save_lights_failure_leaves_nothing(tmp_path, monkeypatch, rng):
    lights = cap.Lights(["a.png"], _unit(rng, 1))

    def boom(self, *a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(cap.Path, "write_text", boom)
    with pytest.raises(OSError, match="disk full"):
        cap.save_lights(lights, tmp_path / "lights.json")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="norm"):
        cap.save_lights(cap.Lights(["a.png"], [[0, 0, 2.0]]), tmp_path / "lights.json")


# ----------------------------------------------------------------------------- RTI .lp
def test_lp_round_trip(tmp_path, rng):
    names = ["a.jpg", "b c.jpg", "d.jpg"]
    d = _unit(rng, 3)
    cap.write_lp(tmp_path / "x.lp", names, d)
    n2, d2 = cap.read_lp(tmp_path / "x.lp")
    assert n2 == names
    np.testing.assert_allclose(d2, d, atol=1e-8)


def test_lights_given_a_folder_or_an_image(tmp_path):
    """``--lights`` given a folder or a photo: said as such (it was an IsADirectoryError or a
    UnicodeDecodeError in brackets, or ".lp file not found" for a folder named x.lp)."""
    (tmp_path / "d.lp").mkdir()
    (tmp_path / "p.exr").write_bytes(b"\x76\x2f\x31\x01\x02\xff\xfe\x00")
    with pytest.raises(InputError, match="is a folder, not lights.json"):
        cap.load_lights(tmp_path)
    with pytest.raises(InputError, match="is a folder, not an .lp file"):
        cap.read_lp(tmp_path / "d.lp")
    with pytest.raises(InputError, match="is not a JSON text file") as e:
        cap.load_lights(tmp_path / "p.exr")
    _one_line(e.value, "p.exr")


@pytest.mark.parametrize("text,match", [
    ("3\na.jpg 0 0 1\nb.jpg 0 1 0\n", "says 3 lights but 2 follow"),
    ("two\na.jpg 0 0 1\n", "number of lights"),
    ("1\na.jpg 0 zero 1\n", "line 2"),
    ("1\na.jpg 0 0 2\n", "not a unit vector"),
    ("1\na.jpg 0 0 5\n", r"not a unit vector \(norm 5\)"),  # (it said norm inf beyond 2)
    ("1\na.jpg 0.23 0.87 0.43 0.1 0.2\n", "line 2: more than three numbers after the file name"),
    ("2\na.jpg 0 0 1\na.jpg 0 1 0\n", r"line 3: 'a.jpg' is listed twice \(first on line 2\)"),
    ("1\na.jpg nan 0 1\n", "line 2: direction of 'a.jpg' has a component that is not a finite number"),
    ("0\n", "says 0 lights: an .lp file lists at least one"),
    ("", "empty"),
])
def test_bad_lp(tmp_path, text, match):
    (tmp_path / "bad.lp").write_text(text)
    with pytest.raises(InputError, match=match) as e:
        cap.read_lp(tmp_path / "bad.lp")
    _one_line(e.value, "bad.lp")


def test_lp_frame_conversion(rng):
    # default camera: .lp z (toward the camera) is world -Y, .lp y (image up) is world +Z
    np.testing.assert_allclose(cap.lp_to_world([[0, 0, 1], [0, 1, 0], [1, 0, 0]]),
                               [[0, -1, 0], [0, 0, 1], [1, 0, 0]], atol=1e-15)
    R = conventions.rotation_ypr(30, -20, 10)
    wfc = np.eye(4)
    wfc[:3, :3] = R
    wfc[:3, 3] = [1, 2, 3]  # translation must not matter for directions
    d = _unit(rng, 20)
    np.testing.assert_allclose(cap.world_to_lp(cap.lp_to_world(d, wfc), wfc), d, atol=1e-12)
    # light straight toward the camera: world direction = -(camera forward)
    np.testing.assert_allclose(cap.lp_to_world([[0, 0, 1]], wfc)[0], -R[:, 2], atol=1e-12)


def test_lights_from_lp(tmp_path, rng):
    names, _ = _make(tmp_path / "c")
    c = cap.load_capture(tmp_path / "c")
    d = _unit(rng, 3)
    cap.write_lp(tmp_path / "c" / "x.lp", [r"C:\rti\\" + n for n in names[::-1]], d[::-1])
    lights = cap.lights_from_lp(tmp_path / "c" / "x.lp", c)
    assert lights.image_names == names
    np.testing.assert_allclose(lights.directions, cap.lp_to_world(d), atol=1e-8)
    # an image the .lp does not list (ffls lights --lp leaves rejected photos out): rejected, and said
    cap.write_lp(tmp_path / "c" / "y.lp", names[:2], d[:2])
    part = cap.lights_from_lp(tmp_path / "c" / "y.lp", c)
    assert part.status == ["ok", "ok", "rejected"] and "no light in y.lp" in part.reasons[2]
    assert "y.lp has no light for 1 of the capture's 3 images" in part.note and names[2] in part.note
    np.testing.assert_allclose(part.directions[:2], cap.lp_to_world(d[:2]), atol=1e-8)


def test_load_capture_and_lights_says_how_to_make_missing_lights(tmp_path):
    _make(tmp_path / "c")
    (tmp_path / "c" / "lights.json").unlink(missing_ok=True)
    with pytest.raises(InputError, match="ffls lights") as e:
        cap.load_capture_and_lights(tmp_path / "c")
    _one_line(e.value, "lights.json")


def test_lights_calibrated_on_sixteen_bit_files_refused_on_eight_bit_photos(tmp_path):
    """A calibrated table's rows must match the capture's photos; the error names the lights file
    (its ``"bits"``), not a photo."""
    write_png(tmp_path / "a.png", np.full((4, 4, 3), 128, np.uint8))
    rec = {"curve": "polynomial", "gamma": 2.0, "uncertainty": 0.02, "method": "spheres:gamma", "order": 2,
           "coefficients": [1.9, 0.4, -0.2], "bits": 16}
    lights = cap.Lights(["a.png"], np.array([[0.0, 0.0, 1.0]]), encoding=rec, path=tmp_path / "l16.json")
    c = cap.Capture(folder=tmp_path, image_names=["a.png"], encoding="auto")
    with pytest.raises(InputError, match=r'calibrated on 16-bit files \("bits": 16\).*8-bit') as e:
        cap.apply_lights_encoding(c, lights)
    assert e.value.path == tmp_path / "l16.json"
    assert cap.apply_lights_encoding(c, cap.Lights(["a.png"], np.array([[0.0, 0.0, 1.0]]),
                                                   encoding={**rec, "bits": 8})).response.shape == (256, 3)


@pytest.mark.parametrize("key,value,match", [
    ("naming", 5, "naming must be one of"), ("naming", "foo", "naming must be one of"),
    ("shown_codes", "x", "shown_codes must be"), ("shown_codes", [0.9, 0.1], "shown_codes must be"),
    ("shown_codes", [0.1, 0.5, 0.9], "shown_codes must be"), ("dark_srgb_excess", "a", "dark_srgb_excess"),
    ("dark_srgb_excess", float("nan"), "dark_srgb_excess"), ("dark_bic_penalty", -3, "dark_bic_penalty"),
    ("dark_bic_penalty", [1], "dark_bic_penalty"),
])
def test_encoding_record_naming_keys_are_checked(tmp_path, key, value, match):
    """The naming keys of ``lights.json``'s encoding record are validated, not ignored (docs/formats.md:
    "a malformed record is an error naming lights.json and encoding")."""
    ok = {"curve": "srgb", "naming": "shown_codes", "shown_codes": [0.44, 0.91], "dark_srgb_excess": 3.5,
          "dark_bic_penalty": 4.7}
    assert cap.encoding_from_record(ok) == "srgb"
    with pytest.raises(ValueError, match=match):
        cap.encoding_from_record({**ok, key: value})


def test_a_folder_of_photos_without_its_document_says_how_to_write_one(tmp_path, capsys):
    """A first user's folder of photos: "capture.json not found" said neither what it is nor what it holds."""
    from ffls.cli import main
    from ffls.io.probe import load_probe

    write_png(tmp_path / "IMG_0001.png", np.zeros((4, 6, 3), np.uint8))
    assert main(["lights", str(tmp_path), "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "capture.json not found: a capture folder needs one listing its photos" in err
    doc = json.loads(err[err.index("{"):err.index("}") + 1].replace(", ...", ""))
    assert doc["format"] == "ffls-capture" and doc["version"] == 1 and "docs/formats.md" in err
    with pytest.raises(InputError, match='probe.json not found: a probe folder .*"format": "ffls-probe"'):
        load_probe(tmp_path)
