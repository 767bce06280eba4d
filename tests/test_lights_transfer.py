"""Lights of one capture applied to another (issue 9, item 6): .lp or lights.json, by name, by
order, or by a name map; ``ffls lights --lp`` export."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.io.capture import (load_capture, load_capture_and_lights, load_lights, load_lights_any, lights_from_lp,
                             parse_lights_map, read_lp)

N = 8


@pytest.fixture(scope="module")
def calib(tmp_path_factory):
    from ffls.synth.scene import write_synthetic_capture

    folder = tmp_path_factory.mktemp("calib")
    write_synthetic_capture(folder, n_lights=N, resolution=24, progress=False, seed=3)
    return folder


def _object_capture(calib, dest, n=N):
    """The calibration capture's photos under other names (the object's shots), without lights."""
    doc = json.loads((calib / "capture.json").read_text())
    names = []
    for k, src in enumerate(doc["images"][:n]):
        names.append(f"obj_{k:02d}.exr")
        shutil.copy(calib / src, dest / names[-1])
    doc["images"] = names
    doc.pop("truth", None)
    (dest / "capture.json").write_text(json.dumps(doc))
    return dest


def test_by_order_when_no_name_matches_and_counts_agree(calib, tmp_path):
    obj = _object_capture(calib, tmp_path)
    cal = load_lights(calib / "lights.json")
    cap, lights = load_capture_and_lights(obj, calib / "lights.json")
    assert lights.image_names == cap.image_names
    np.testing.assert_array_equal(lights.directions, cal.directions)
    assert "by order" in lights.note and "'img_0000.exr' -> 'obj_00.exr'" in lights.note
    # the calibration capture itself: by name, nothing to say
    _, same = load_capture_and_lights(calib)
    assert same.note is None


def test_by_name_map_inline_and_file(calib, tmp_path):
    obj = _object_capture(calib, tmp_path)
    cal = load_lights(calib / "lights.json")
    mapping = {cal.image_names[k]: f"obj_{N - 1 - k:02d}.exr" for k in range(N)}  # reversed
    for spec in (json.dumps(mapping), str(_write(tmp_path / "map.json", mapping))):
        cap, lights = load_capture_and_lights(obj, calib / "lights.json", spec)
        np.testing.assert_array_equal(lights.directions, cal.directions[::-1])
        assert lights.image_names == cap.image_names and "name map" in lights.note
    # a map may leave lights out (a calibration set with extra shots), not images
    bigger = dict(mapping)
    with pytest.raises(InputError, match="'obj_00.exr' has no light"):
        load_lights_any(calib / "lights.json", load_capture(obj), {k: v for k, v in bigger.items() if v != "obj_00.exr"})


def _write(path, doc):
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("spec, match", [
    ("{not json", "not valid JSON"),
    ("{}", "expected a non-empty JSON object"),
    ('{"a.png": 3}', "must map to a non-empty image name"),
    ('{"a.png": "x.png", "b.png": "x.png"}', "both map to 'x.png'"),
])
def test_bad_lights_map_is_one_line(spec, match):
    with pytest.raises(InputError, match=match) as e:
        parse_lights_map(spec)
    assert "--lights-map" in str(e.value) and "\n" not in str(e.value)


def test_lights_map_file_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="lights map not found"):
        parse_lights_map(tmp_path / "missing.json")
    p = _write(tmp_path / "list.json", [1, 2])
    with pytest.raises(InputError, match="must hold a JSON object") as e:
        parse_lights_map(p)
    assert str(p) in str(e.value)


def test_map_naming_unknown_lights_or_images(calib, tmp_path):
    obj = load_capture(_object_capture(calib, tmp_path))
    with pytest.raises(InputError, match="light 'nope.exr', which is not in the lights file"):
        load_lights_any(calib / "lights.json", obj, {"nope.exr": "obj_00.exr"})
    with pytest.raises(InputError, match="'zzz.exr', which is not an image of the capture"):
        load_lights_any(calib / "lights.json", obj, {"img_0000.exr": "zzz.exr"})


def test_counts_differ_and_no_name_matches(calib, tmp_path):
    obj = _object_capture(calib, tmp_path, n=N - 2)
    with pytest.raises(InputError, match=r"none of the 8 lights names an image of the capture \(6 images\).*--lights-map"):
        load_capture_and_lights(obj, calib / "lights.json")
    with pytest.raises(InputError, match="lights file not found"):
        load_capture_and_lights(obj, tmp_path / "missing.json")


def test_lp_export_round_trip_and_lp_by_order(calib, tmp_path):
    from ffls.commands.lights import export_lp

    cap, lights = load_capture_and_lights(calib)
    lights.status[3], lights.reasons[3] = "rejected", "test"
    lp = tmp_path / "calib.lp"
    line = export_lp(lights, cap, lp)
    assert line == f"wrote {lp} ({N - 1} lights; 1 rejected left out)"
    names, _ = read_lp(lp)
    assert names == [n for k, n in enumerate(cap.image_names) if k != 3]
    # the calibration capture reads that .lp back by name: the photo left out is rejected, and said
    part = lights_from_lp(lp, cap)
    assert part.status[3] == "rejected" and part.status.count("ok") == N - 1 and "1 of the capture's" in part.note
    from ffls.cli import main

    out = tmp_path / "r.exr"
    assert main(["relight", str(calib), "--lights", str(lp), "--probe", "paper", "-o", str(out)]) == 0 and out.is_file()
    lights.status[3] = "ok"
    export_lp(lights, cap, lp)
    back = lights_from_lp(lp, cap)
    np.testing.assert_allclose(back.directions, lights.directions, atol=1e-8)
    # and the object's capture (same camera) takes it by order
    obj = _object_capture(calib, tmp_path)
    _, on_obj = load_capture_and_lights(obj, lp)
    np.testing.assert_allclose(on_obj.directions, lights.directions, atol=1e-8)
    assert "by order" in on_obj.note and "calib.lp" in on_obj.note


def test_lights_command_has_lp_flag():
    from ffls.cli import build_parser

    args = build_parser().parse_args(["lights", "CAP", "--lp", "out.lp"])
    assert args.lp == "out.lp"


def test_relight_takes_lp_and_other_captures_lights(calib, tmp_path, capsys):
    from ffls.cli import main
    from ffls.commands.lights import export_lp
    from ffls.io.images import read_image

    obj = _object_capture(calib, tmp_path)
    cap, lights = load_capture_and_lights(calib)
    export_lp(lights, cap, tmp_path / "calib.lp")
    outs = []
    for lights_arg in (calib / "lights.json", tmp_path / "calib.lp"):
        out = tmp_path / f"relit_{lights_arg.suffix[1:]}.exr"
        rc = main(["relight", str(obj), "--lights", str(lights_arg), "--probe", "paper", "-o", str(out)])
        err = capsys.readouterr().err
        assert rc == 0
        notes = [ln for ln in err.splitlines() if "by order" in ln]
        assert len(notes) == 1 and notes[0].startswith("ffls relight: lights: ")
        outs.append(read_image(out).pixels)
    np.testing.assert_allclose(outs[0], outs[1], rtol=1e-5, atol=1e-7)
    # the same images, same lights: the object's relit image is the calibration capture's
    ref = tmp_path / "ref.exr"
    assert main(["relight", str(calib), "--probe", "paper", "-o", str(ref)]) == 0
    capsys.readouterr()
    np.testing.assert_array_equal(outs[0], read_image(ref).pixels)
    # a bad map is one line and exit status 2
    rc = main(["relight", str(obj), "--lights", str(calib / "lights.json"), "--lights-map", "{bad",
               "--probe", "paper", "-o", str(tmp_path / "x.exr")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and "--lights-map" in err and not (tmp_path / "x.exr").exists()


def test_lp_with_rejected_lights_left_out_applies_by_a_map(calib, tmp_path):
    """An .lp from ``ffls lights --lp`` lists only the accepted lights: by order it cannot apply to a
    capture of all the photos, and a name map that names every photo (or only the listed ones)
    was refused; the photos without a light are rejected, and the note says how many."""
    from ffls.commands.lights import export_lp

    cap, lights = load_capture_and_lights(calib)
    lights.status[3], lights.reasons[3] = "rejected", "test"
    lp = tmp_path / "calib.lp"
    export_lp(lights, cap, lp)
    (tmp_path / "obj").mkdir()
    obj = load_capture(_object_capture(calib, tmp_path / "obj"))
    full = {n: f"obj_{k:02d}.exr" for k, n in enumerate(cap.image_names)}
    listed = {k: v for k, v in full.items() if k != cap.image_names[3]}
    for m in (full, listed):
        out = load_lights_any(lp, obj, m)
        assert out.status[3] == "rejected" and "only accepted lights" in out.reasons[3]
        assert out.status.count("ok") == N - 1 and "1 images without a light in it are left out" in out.note
        np.testing.assert_allclose(out.directions[[0, 1, 2, 4]], lights.directions[[0, 1, 2, 4]], atol=1e-6)
    with pytest.raises(InputError, match="has no light in --lights-map"):  # a map that maps nothing there
        load_lights_any(lp, obj, {cap.image_names[3]: "obj_00.exr"})
    # a lights.json lists every photo, rejected ones too: an image the map leaves out is still an error
    with pytest.raises(InputError, match="'obj_03.exr' has no light"):
        load_lights_any(calib / "lights.json", obj, listed)
    # without a map, the error says why the counts differ, and which file applies by order
    with pytest.raises(InputError) as e:
        load_lights_any(lp, obj)
    assert "only accepted lights" in str(e.value) and "lights.json" in str(e.value) and "\n" not in str(e.value)


def test_a_file_with_more_lights_than_the_capture_applies_by_name(calib, tmp_path):
    """A lights file that names every image of the capture and more (a calibration set with extra
    shots) applies by name, the others unused and said; names that match only partly suggest
    --lights-map (the error named the first unknown image and stopped)."""
    doc = json.loads((calib / "capture.json").read_text())
    (tmp_path / "few").mkdir()
    for src in doc["images"][:5]:
        shutil.copy(calib / src, tmp_path / "few" / src)
    few = dict(doc, images=doc["images"][:5])
    (tmp_path / "few" / "capture.json").write_text(json.dumps(few))
    cal = load_lights(calib / "lights.json")
    cap, lights = load_capture_and_lights(tmp_path / "few", calib / "lights.json")
    assert lights.image_names == cap.image_names and f"the other {N - 5} are not" in lights.note
    np.testing.assert_array_equal(lights.directions, cal.directions[:5])
    (tmp_path / "mix").mkdir()
    names = doc["images"][:3] + ["other_a.exr", "other_b.exr"]
    for src, dst in zip(doc["images"][:5], names):
        shutil.copy(calib / src, tmp_path / "mix" / dst)
    (tmp_path / "mix" / "capture.json").write_text(json.dumps(dict(doc, images=names)))
    with pytest.raises(InputError, match=r"3 of the 8 lights name images of the capture.*--lights-map") as e:
        load_capture_and_lights(tmp_path / "mix", calib / "lights.json")
    assert "\n" not in str(e.value)


def test_an_encoding_calibrated_on_another_capture_is_said(tmp_path):
    """8-bit object shots whose capture.json states no encoding take the one ``ffls lights`` calibrated on the
    calibration shots (their lights.json's record): an assumption about the camera, made without a word."""
    from ffls.io.capture import save_lights
    from ffls.synth.photo import PhotoSettings
    from ffls.synth.scene import write_synthetic_capture

    cal = tmp_path / "cal"
    write_synthetic_capture(cal, n_lights=4, resolution=24, progress=False, seed=3,
                            photo=PhotoSettings("png8", "linear", exposure=3, state_encoding=False))
    lights = load_lights(cal / "lights.json")
    lights.encoding = {"curve": "gamma", "gamma": 1.05, "uncertainty": 0.01, "method": "spheres:gamma",
                       "spheres": 4, "photos": 4}
    save_lights(lights, cal / "lights.json")
    obj = tmp_path / "obj"
    obj.mkdir()
    doc = json.loads((cal / "capture.json").read_text())
    for k, src in enumerate(doc["images"]):
        shutil.copy(cal / src, obj / f"obj_{k:02d}.png")
    doc["images"] = [f"obj_{k:02d}.png" for k in range(4)]
    (obj / "capture.json").write_text(json.dumps(doc))
    cap, got = load_capture_and_lights(obj, cal / "lights.json")
    assert cap.encoding == {"gamma": 1.05}
    assert "by order" in got.note and "encoding: capture.json states none; the gamma 1.05 curve" in got.note
    assert str(cal / "lights.json") in got.note
    own, same = load_capture_and_lights(cal)  # its own calibration, which ffls lights printed: nothing more
    assert own.encoding == {"gamma": 1.05} and same.note is None


def test_an_lp_says_the_frame_it_was_read_in(calib, tmp_path):
    """RTI tools differ in the .lp's axes (z toward the camera or into the scene, y up or down) and
    nothing in the file says which: a relight with an .lp whose z was negated was 0.63 relative RMS
    off without a word about the frame (only coverage lines). Every .lp read says the frame, and a
    file whose lights mostly point away from the camera (behind the object) is named."""
    from ffls.commands.lights import export_lp
    from ffls.io.capture import world_to_lp

    cap, lights = load_capture_and_lights(calib)
    lp = tmp_path / "calib.lp"
    export_lp(lights, cap, lp)
    _, same = load_capture_and_lights(calib, lp)
    assert "calib.lp: .lp directions read in the image frame (x right, y up, z toward the camera" in same.note
    assert "point away from the camera" not in same.note
    names, d = read_lp(lp)
    flipped = tmp_path / "zaway.lp"
    flipped.write_text(f"{len(names)}\n" + "".join(f"{n} {x:.9f} {y:.9f} {-z:.9f}\n" for n, (x, y, z) in zip(names, d)))
    away = int(np.sum(d[:, 2] > 0))  # negated: these now point away
    assert away > len(names) / 2
    _, neg = load_capture_and_lights(calib, flipped)
    assert f"{away} of its {N} lights point away from the camera (z < 0)" in neg.note
    np.testing.assert_allclose(world_to_lp(neg.directions, cap.world_from_camera)[:, 2], -d[:, 2], atol=1e-8)
