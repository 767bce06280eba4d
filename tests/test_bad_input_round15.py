"""Bad input found by the round-15 tester (briefs s15/atk15, docs/reliability.md "Round 15").

The stop's merged tree attacked as a careless user would: camera poses typed by hand (rolled,
rounded, scaled, mirrored), ``--lights`` files with odd keys, ``.lp`` files, captures of one or two
photos, photos all alike or all black but one, ``--workers`` out of range. The promise checked is the
one of ``tests/test_bad_input.py``: exit status 2, one stderr line naming the flag or file, nothing
left; and valid but unusual input read (no false refusal).
"""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from cli_lines import one_line, tiny_capture


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r15"), seed=15)


def _tilted(t_deg: float, decimals: int | None) -> list:
    """docs/formats.md's pose of a camera looking down by ``t_deg`` (its "The camera's tilt"), rounded."""
    s, c = np.sin(np.radians(t_deg)), np.cos(np.radians(t_deg))
    T = np.array([[1, 0, 0, 0], [0, -s, c, -c], [0, -c, -s, 0.5], [0, 0, 0, 1]], dtype=float)
    return (T if decimals is None else np.round(T, decimals)).tolist()


def _with_pose(cap, tmp_path, pose):
    c = tmp_path / "c"
    shutil.copytree(cap, c)
    doc = json.loads((c / "capture.json").read_text())
    doc["camera"]["world_from_camera"] = pose
    (c / "capture.json").write_text(json.dumps(doc))
    return c


# ----------------------------------------------------------------------------- world_from_camera
@pytest.mark.parametrize("t", [20, 30, 45, 60])
def test_a_pose_typed_to_3_decimals_is_read_as_its_rotation(cap, tmp_path, t):
    """docs/formats.md gives the tilt's pose to 3 decimals; ``R R^T`` of 20 deg so written is 5.6e-4
    off the identity (45 deg: 3.0e-4), and a 1e-4 tolerance refused it: "not a rigid transform"."""
    from ffls.conventions import is_rotation
    from ffls.io.capture import load_capture

    c = _with_pose(cap, tmp_path, _tilted(t, 3))
    wfc = load_capture(c).world_from_camera
    assert is_rotation(wfc[:3, :3], atol=1e-12)
    assert np.abs(wfc - _tilted(t, None)).max() < 1e-3


def test_a_rolled_pose_is_read(cap, tmp_path):
    from ffls.io.capture import load_capture

    a = np.radians(25)
    T = np.array(_tilted(30, None))
    T[:3, :3] = T[:3, :3] @ [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    assert np.allclose(load_capture(_with_pose(cap, tmp_path, T.tolist())).world_from_camera, T)


@pytest.mark.parametrize("edit,named", [
    (lambda T: T[:3, :3].__imul__(1.3), "its rotation block is 1.2 from orthonormal with determinant 1 "
                                        "(tolerance 0.002"),
    (lambda T: T[0].__setitem__(1, 0.4), "its rotation block is 0.38 from orthonormal"),
    (lambda T: T.__setitem__(slice(None), np.round(_tilted(30, None), 2)), "is 0.0069 from orthonormal"),
    (lambda T: T[:3, 0].__imul__(-1), "its rotation block has determinant -1 (a rotation's is 1; a negative one "
                                      "mirrors the image"),
    (lambda T: T[:3, :3].__setitem__(slice(None), 0), "its rotation block has determinant 0"),
    (lambda T: T[3].__setitem__(2, 1), "its last row must be 0 0 0 1, got [0.0, 0.0, 1.0, 1.0]"),
], ids=["scaled", "sheared", "2-decimals", "mirrored", "zero", "last-row"])
def test_a_pose_that_is_no_rotation_says_how_far_off_it_is(cap, tmp_path, capfd, edit, named):
    """Every such pose got the same line, however far off (a 1.3 scale and a 3-decimal rounding alike)."""
    T = np.array(_tilted(20, None))
    edit(T)
    c = _with_pose(cap, tmp_path, T.tolist())
    rc, line = one_line(capfd, ["relight", c, "--probe", "sky", "-o", tmp_path / "o.exr"])
    assert rc == 2 and "capture.json: camera.world_from_camera: not a rigid transform: " in line, line
    assert named in line, line
    assert not (tmp_path / "o.exr").exists()


# ----------------------------------------------------------------------------- UTF-16 / UTF-32 text
@pytest.mark.parametrize("which,codec", [("capture.json", "utf-16"), ("lights.json", "utf-16-le"),
                                         ("lights.json", "utf-32"), ("lights.lp", "utf-16")])
def test_json_and_lp_files_saved_as_unicode_by_notepad_are_read(cap, tmp_path, capfd, which, codec):
    """Windows Notepad's "Unicode" is UTF-16 (with a BOM): such a capture.json was refused ("its bytes
    are not UTF-8 text"), a UTF-16-LE one without a BOM as "corrupt JSON at line 1 column 2", and an
    .lp as "line 1: expected the number of lights, got '\\ufffd\\ufffd6\\x00'"."""
    from ffls.io.capture import load_capture, load_lights, world_to_lp, write_lp

    c = tmp_path / "c"
    shutil.copytree(cap, c)
    lights = load_lights(c / "lights.json")
    write_lp(c / "lights.lp", lights.image_names, world_to_lp(lights.directions, load_capture(c).world_from_camera))
    (c / which).write_bytes((c / which).read_text(encoding="utf-8").encode(codec))
    argv = ["relight", c, "--probe", "sky", "-o", tmp_path / "o.exr"]
    if which != "capture.json":
        argv += ["--lights", c / which]
    capfd.readouterr()
    from ffls.cli import main

    assert main([str(a) for a in argv]) == 0, capfd.readouterr().err
    assert (tmp_path / "o.exr").is_file()


# ----------------------------------------------------------------------------- camera_tilt_deg
@pytest.mark.parametrize("angle,value,named", [
    ("camera_tilt_deg", "abc", "camera_tilt_deg: expected a finite number, got 'abc'"),
    ("camera_tilt_deg", 400, "camera_tilt_deg: a camera's tilt is between -90 and 180 deg, got 400"),
    ("camera_tilt_deg", True, "camera_tilt_deg: expected a finite number, got True"),
    ("camera_tilt_deg", [30], "camera_tilt_deg: expected a finite number"),
    ("camera_roll_deg", "x", "camera_roll_deg: expected a finite number, got 'x'"),
    ("camera_roll_deg", -200, "camera_roll_deg: a camera's roll is between -180 and 180 deg, got -200"),
], ids=["text", "400", "bool", "list", "roll-text", "roll-200"])
def test_a_lights_files_camera_tilt_is_checked(cap, tmp_path, capfd, angle, value, named):
    """``ffls lights`` writes ``camera_tilt_deg`` (and with ``--fit-roll`` ``camera_roll_deg``; this
    stop); a ``--lights`` file giving it as text or 400 deg was read without a word."""
    doc = json.loads((cap / "lights.json").read_text())
    doc["lights"][0][angle] = value
    (tmp_path / "l.json").write_text(json.dumps(doc))
    rc, line = one_line(capfd, ["relight", cap, "--lights", tmp_path / "l.json", "--probe", "sky",
                                "-o", tmp_path / "o.exr"])
    assert rc == 2 and f"l.json: light for 'img_0000.exr': {named}" in line, line
    assert not (tmp_path / "o.exr").exists()


def test_a_fitted_camera_tilt_is_read_back_and_a_misspelt_one_named(cap, tmp_path, capfd):
    from ffls.io.capture import load_lights

    doc = json.loads((cap / "lights.json").read_text())
    for k, e in enumerate(doc["lights"]):
        e["camera_tilt_deg"] = None if k == 1 else 31.27
    (tmp_path / "l.json").write_text(json.dumps(doc))
    assert [e.get("camera_tilt_deg") for e in load_lights(tmp_path / "l.json").extra][:2] == [31.27, None]
    doc["lights"][0]["camera_tilt_dge"] = doc["lights"][0].pop("camera_tilt_deg")
    (tmp_path / "l.json").write_text(json.dumps(doc))
    rc, line = one_line(capfd, ["relight", cap, "--lights", tmp_path / "l.json", "--probe", "sky",
                                "-o", tmp_path / "o.exr"])
    assert rc == 2 and "lights[0].camera_tilt_dge: unknown key; did you mean 'camera_tilt_deg'?" in line, line


# ----------------------------------------------------------------------------- probe.json circle off the photo
@pytest.fixture(scope="module")
def probes(tmp_path_factory):
    """Two mirror probes of 80 px: an orthographic one stated by its pixel circle, a pinhole one by
    its world centre."""
    from ffls.synth.probe import look_at, write_mirror_probe

    root = tmp_path_factory.mktemp("r15probe")
    m = np.full((16, 32, 3), 0.3, np.float32)
    m[:8] *= 2
    write_mirror_probe(root / "px", m, (80, 80), "orthographic", center_px=(40, 40), radius_px=30, sphere="pixel",
                       supersample=1)
    K = np.array([[350.0, 0, 40], [0, 350.0, 40], [0, 0, 1]])
    write_mirror_probe(root / "world", m, (80, 80), K=K, world_from_camera=look_at([0, -1.0, 0.2]), radius=0.1,
                       supersample=1)
    return root


def _probe_with(probes, tmp_path, which, **sphere):
    p = tmp_path / which
    shutil.copytree(probes / which, p)
    doc = json.loads((p / "probe.json").read_text())
    doc["sphere"].update(sphere)
    (p / "probe.json").write_text(json.dumps(doc))
    return p


@pytest.mark.parametrize("which,sphere,named", [
    ("px", {"center_px": [500, 40]}, "sphere.center_px and radius_px: the circle (500, 40) px, radius 30 px, "
                                     "lies wholly outside the photo (80x80 px)"),
    ("px", {"center_px": [-31, -31]}, "sphere.center_px and radius_px: the circle (-31, -31) px, radius 30 px, "
                                      "lies wholly outside"),
    ("world", {"center": [0.6, 0.0, 0.0]}, "sphere.center projects to a circle (246, 40) px, radius 37 px, "),
], ids=["right", "corner", "world"])
def test_a_probe_circle_wholly_off_the_photo_names_probe_json(probes, tmp_path, capfd, which, sphere, named):
    """Such a circle was unwrapped as a ball seen nowhere: "ball.exr: the ball shows no usable
    direction (all its pixels invalid or masked)", the photo blamed for probe.json's hint."""
    p = _probe_with(probes, tmp_path, which, **sphere)
    rc, line = one_line(capfd, ["probe", "mirror", p, "-o", tmp_path / "m.exr", "--size", "8"])
    assert rc == 2 and f"{p.name}/probe.json: {named}" in line and "wholly outside the photo" in line, line
    assert not (tmp_path / "m.exr").exists()


def test_a_probe_circle_partly_off_the_photo_is_unwrapped(probes, tmp_path, capfd):
    p = _probe_with(probes, tmp_path, "px", center_px=[-20, 40])
    capfd.readouterr()
    from ffls.cli import main

    assert main(["probe", "mirror", str(p), "-o", str(tmp_path / "m.exr"), "--size", "8"]) == 0
    assert "saw " in capfd.readouterr().err


@pytest.mark.parametrize("hint,named", [
    ({"center_px": [400, 10], "radius_px": 5}, "the circle (400, 10) px, radius 5 px, lies wholly outside the photo "
                                               "(24x24 px)"),
    ({"center_px": [12, 12], "radius_px": 500}, "the circle (12, 12) px, radius 500 px, is larger than the photo "
                                                "(24x24 px)"),
], ids=["outside", "larger"])
def test_a_capture_hint_circle_off_the_photo_is_named(cap, tmp_path, capfd, hint, named):
    """capture.json's hints: "spheres[0] near pixel (12, 12): cannot fit its outline (only 0 edge
    points)" for a radius of 500 px in a 24 px photo (probe.json refused it already, in its words)."""
    c = tmp_path / "c"
    shutil.copytree(cap, c)
    doc = json.loads((c / "capture.json").read_text())
    doc["spheres"] = [hint]
    (c / "capture.json").write_text(json.dumps(doc))
    rc, line = one_line(capfd, ["lights", c, "--workers", "1", "-o", tmp_path / "l.json"])
    assert rc == 2 and f"spheres[0]: bad sphere hint: {named}" in line, line
    assert not (tmp_path / "l.json").exists()


# ----------------------------------------------------------------------------- long tail, kept already
@pytest.mark.parametrize("flag,value", [("--workers", "0"), ("--workers", "-1"), ("--workers", "10000"),
                                        ("--workers", "1.5"), ("--first-pass", "0")])
def test_out_of_range_counts_are_one_line(cap, tmp_path, capfd, flag, value):
    rc, line = one_line(capfd, ["lights", cap, flag, value, "-o", tmp_path / "l.json"])
    assert rc == 2 and line.startswith(f"ffls lights: error: argument {flag}: expected an integer in [1, "), line
    assert not (tmp_path / "l.json").exists()


def _lp_of(cap, tmp_path) -> str:
    from ffls.io.capture import load_capture, load_lights, world_to_lp, write_lp

    lights = load_lights(cap / "lights.json")
    write_lp(tmp_path / "w.lp", lights.image_names, world_to_lp(lights.directions, load_capture(cap).world_from_camera))
    return (tmp_path / "w.lp").read_text()


@pytest.mark.parametrize("edit", [lambda t: t.replace("\n", "\r\n"), lambda t: "\ufeff" + t,
                                  lambda t: t.replace(" ", "\t"), lambda t: "\n\n" + t + "\n\n"],
                         ids=["crlf", "bom", "tabs", "blank-lines"])
def test_lp_files_as_editors_save_them_are_read(cap, tmp_path, capfd, edit):
    from ffls.cli import main

    (tmp_path / "l.lp").write_text(edit(_lp_of(cap, tmp_path)), encoding="utf-8", newline="")
    out = tmp_path / "out dir ü" / "relit é.exr"
    out.parent.mkdir()
    assert main(["relight", str(cap), "--lights", str(tmp_path / "l.lp"), "--probe", "sky", "-o", str(out)]) == 0
    assert out.is_file()


@pytest.mark.parametrize("edit,named", [
    (lambda t: "\n".join(t.splitlines()[:-2]), "the count on line 1 says 6 lights but 4 follow"),
    (lambda t: "# made by hand\n" + t, "line 1: expected the number of lights, got '# made by hand'"),
    (lambda t: t.replace("6\n", "6.0\n", 1), "line 1: expected the number of lights, got '6.0'"),
], ids=["fewer-lines", "comment", "float-count"])
def test_lp_files_that_say_other_than_they_hold_are_one_line(cap, tmp_path, capfd, edit, named):
    (tmp_path / "l.lp").write_text(edit(_lp_of(cap, tmp_path)))
    rc, line = one_line(capfd, ["relight", cap, "--lights", tmp_path / "l.lp", "--probe", "sky",
                                "-o", tmp_path / "o.exr"])
    assert rc == 2 and f"l.lp: {named}" in line, line
    assert not (tmp_path / "o.exr").exists()
