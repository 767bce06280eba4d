"""Bad input found by the round-14 tester (briefs s14/test14, docs/reliability.md "Round 14").

Round 13's leftovers (a capture mixing 8-bit and 16-bit photos, ``--bounce observed``'s lines
naming capture.json, ``composite -o SET/truth.exr``, the probe benchmarks' temporary folders) and a
fresh attack on every command. The promise checked is the one of ``tests/test_bad_input.py``:
exit status 2, one stderr line naming the flag or file, nothing left.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cli_lines import child_env, composite_set, entries, tiny_capture
from cli_lines import one_line as _one_line

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r14"), seed=14)



# ----------------------------------------------------------------------------- bit depths
def _png_copy(cap: Path, dst: Path, bits) -> Path:
    """A copy of ``cap`` whose photos are linear PNGs ``p{k}.png`` of ``bits[k]`` bits (8 or 16)."""
    from ffls.io.images import read_image, write_png

    shutil.copytree(cap, dst)
    doc = json.loads((dst / "capture.json").read_text())
    for k, name in enumerate(doc["images"]):
        px = np.clip(read_image(dst / name).pixels, 0, 1)
        top, dtype = (255, np.uint8) if bits[k] == 8 else (65535, np.uint16)
        write_png(dst / f"p{k}.png", np.round(px * top).astype(dtype))
        doc["images"][k] = f"p{k}.png"
    (dst / "capture.json").write_text(json.dumps(doc))
    return dst


@pytest.mark.parametrize("bits,odd,says", [
    ((16, 16, 16, 16, 16, 8), "p5.png", "is a 8-bit image but 5 of the 6 photos are 16-bit (e.g. 'p0.png')"),
    ((8, 16, 8, 8, 8, 8), "p1.png", "is a 16-bit image but 5 of the 6 photos are 8-bit (e.g. 'p0.png')"),
    ((16, 16, 16, 8, 8, 8), "p3.png", "is a 8-bit image but 3 of the 6 photos are 16-bit (e.g. 'p0.png')"),
], ids=["one-8-bit", "one-16-bit", "tie"])
def test_a_capture_mixing_8_and_16_bit_photos_is_refused_from_the_headers(cap, tmp_path, capfd, monkeypatch, bits,
                                                                          odd, says):
    """A capture of 16-bit PNGs with an 8-bit one (stated encoding) was read without complaint:
    one line now names the first photo of the minority depth, before any photo is decoded."""
    import cv2

    c = _png_copy(cap, tmp_path / "c", bits)
    monkeypatch.setattr(cv2, "imdecode", None)  # (refused from the headers: nothing is decoded)
    out = tmp_path / "a.exr"
    rc, line = _one_line(capfd, ["relight", c, "--probe", "sky", "--lights", cap / "lights.json",
                                 "--lights-map", json.dumps({f"img_{k:04d}.exr": f"p{k}.png" for k in range(6)}),
                                 "-o", out])
    assert rc == 2 and f"{odd}: {says}: a capture mixing 8-bit and 16-bit images" in line, line
    assert not out.exists()


def test_a_capture_of_one_depth_is_read(cap, tmp_path):
    """The guard: all 16-bit, or all 8-bit, loads (EXR and HDR photos have no integer depth)."""
    from ffls.io.capture import load_capture
    from ffls.io.images import check_one_bit_depth, write_hdr

    for bits in ((16,) * 6, (8,) * 6):
        assert len(load_capture(_png_copy(cap, tmp_path / f"c{bits[0]}", bits))) == 6
    write_hdr(tmp_path / "f.hdr", np.ones((4, 4, 3), np.float32))
    check_one_bit_depth([tmp_path / "c8" / "p0.png", tmp_path / "f.hdr", cap / "img_0000.exr"])


# ----------------------------------------------------------------------------- --bounce observed
def test_bounce_observed_with_scheduler_is_refused_before_loading(tmp_path, capfd):
    """``--bounce observed --scheduler local`` was refused only once the capture had loaded, naming capture.json."""
    rc, line = _one_line(capfd, ["lights", tmp_path / "no-capture", "--bounce", "observed", "--model", "distant",
                                 "--scheduler", "local", "--workers", "1"])
    assert rc == 2 and line == ("ffls lights: error: --bounce observed is not available with --scheduler (the "
                                "cluster reads the spheres' pixels only)"), line


def test_bounce_observed_lines_name_the_flag(cap, tmp_path, capfd):
    """Its lines began with capture.json's path, as if the file were wrong; the flag asks what the capture lacks."""
    c = tmp_path / "c"
    shutil.copytree(cap, c)
    rc, line = _one_line(capfd, ["lights", c, "--bounce", "observed", "--workers", "1", "-o", tmp_path / "l.json"])
    assert rc == 2 and line.startswith("ffls lights: error: --bounce observed needs --model distant, not --model "
                                       "auto"), line
    doc = json.loads((c / "capture.json").read_text())
    del doc["camera"]["world_from_camera"]
    (c / "capture.json").write_text(json.dumps(doc))
    rc, line = _one_line(capfd, ["lights", c, "--bounce", "observed", "--model", "distant", "--workers", "1",
                                 "-o", tmp_path / "l.json"])
    assert rc == 2 and line.startswith(f"ffls lights: error: --bounce observed needs camera.world_from_camera in "
                                       f"{c / 'capture.json'}"), line
    assert not (tmp_path / "l.json").exists()


# ----------------------------------------------------------------------------- composite onto its set
@pytest.fixture(scope="module")
def cset(tmp_path_factory):
    """A small composite set (``ffls synth --composite-set``)."""
    return composite_set(tmp_path_factory.mktemp("r14set"))


@pytest.mark.parametrize("name,key", [("truth.exr", "truth"), ("scene_map.exr", "scene map"),
                                      ("sphere_mask.png", "sphere mask")])
def test_composite_refuses_to_replace_a_file_of_its_synthetic_set(cset, tmp_path, capfd, name, key):
    """``composite -o SET/truth.exr`` replaced the synthetic set's ground truth (status 0)."""
    s = tmp_path / "set"
    shutil.copytree(cset, s)
    before = (s / name).read_bytes()
    rc, line = _one_line(capfd, ["composite", "--object", s / "object", "--surface", s / "surface",
                                 "--lightmap", "sunrise", "--background", s / "background.exr",
                                 "--mask", s / "object_mask.png", "--surface-mask", s / "surface_mask.png",
                                 "-o", s / name])
    assert rc == 2 and line == (f"ffls composite: error: {s / name}: is the {key} of the synthetic set {s} (its "
                                "composite.json lists it), which the composite would replace: choose another name"), line
    assert (s / name).read_bytes() == before and entries(s) == entries(cset)


# ----------------------------------------------------------------------------- benchmark folders
def test_the_probe_benchmark_capture_is_removed_at_exit(tmp_path):
    """``benchmarks/common.probe_benchmark_capture`` left its /tmp/ffls_probes_* folder behind."""
    code = ("import sys; sys.path.insert(0, 'benchmarks'); import common, ffls.synth.scene as s; "
            "w = s.write_synthetic_capture; "
            "s.write_synthetic_capture = lambda f, **k: w(f, **{**k, 'n_lights': 6, 'resolution': 24}); "
            "c, l = common.probe_benchmark_capture('ffls_probes_r14_'); "
            "assert c.folder.parent.parent == __import__('pathlib').Path(sys.argv[1]); print(len(c))")
    p = subprocess.run([sys.executable, "-c", code, str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                       timeout=120, env=dict(child_env(), TMPDIR=str(tmp_path)))
    assert p.returncode == 0 and p.stdout.split() == ["6"], p.stderr
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- files of another format
def test_a_file_of_another_format_than_its_name_is_refused(cap, tmp_path, capfd):
    """A 16-bit PNG named ``.jpg`` among 8-bit PNGs was read (OpenCV decodes by content) and passed
    every check made from the header (size, memory, grey, bit depth), which read it as a JPEG and
    could not: one line now names it and the name it should have."""
    import cv2

    c = _png_copy(cap, tmp_path / "c", (8,) * 6)
    doc = json.loads((c / "capture.json").read_text())
    ok, buf = cv2.imencode(".png", np.full((24, 24, 3), 30000, np.uint16))
    (c / "p5.png").unlink()
    (c / "p5.jpg").write_bytes(buf.tobytes())
    doc["images"][5] = "p5.jpg"
    (c / "capture.json").write_text(json.dumps(doc))
    out = tmp_path / "a.exr"
    rc, line = _one_line(capfd, ["relight", c, "--probe", "sky", "--lights", cap / "lights.json",
                                 "--lights-map", json.dumps({f"img_{k:04d}.exr": n for k, n in enumerate(doc["images"])}),
                                 "-o", out])
    assert rc == 2 and line.endswith("p5.jpg: is a PNG file named '.jpg': ffls reads a file as its extension says (its "
                                     "checks before decoding read that format's header); rename it p5.png"), line
    assert not out.exists()


def test_an_exr_named_hdr_is_refused_as_a_light_map(tmp_path, capfd):
    from ffls.io.images import write_exr

    write_exr(tmp_path / "m.exr", np.ones((8, 16, 3), np.float32))
    (tmp_path / "m.exr").rename(tmp_path / "m.hdr")
    rc, line = _one_line(capfd, ["lightmap", "info", tmp_path / "m.hdr"])
    assert rc == 2 and "m.hdr: is an OpenEXR file named '.hdr'" in line and line.endswith("rename it m.exr"), line


def test_files_of_their_own_format_are_read(tmp_path):
    """The guard: each format under its own names (``.jpeg``, ``.tiff``, ``.pic`` too) reads."""
    import cv2

    from ffls.io.images import read_image, write_exr, write_hdr

    px = np.full((4, 6, 3), 100, np.uint8)
    for name in ("a.png", "a.jpg", "a.jpeg", "a.tif", "a.tiff"):
        assert cv2.imwrite(str(tmp_path / name), px)
    write_exr(tmp_path / "a.exr", np.ones((4, 6, 3), np.float32))
    write_hdr(tmp_path / "a.hdr", np.ones((4, 6, 3), np.float32))
    (tmp_path / "a.pic").write_bytes((tmp_path / "a.hdr").read_bytes())
    for p in sorted(tmp_path.iterdir()):
        assert read_image(p).pixels.shape == (4, 6, 3), p


# ----------------------------------------------------------------------------- transparent brackets
@pytest.fixture()
def clear_bracket(tmp_path):
    """Three 8-bit RGBA PNGs whose top half is transparent, with exposures.json."""
    from ffls.io.images import write_png

    br = tmp_path / "br"
    br.mkdir()
    for k in range(3):
        a = np.full((16, 16, 4), 40 * (k + 1), np.uint8)
        a[..., 3] = 255
        a[:8, :, 3] = 0
        write_png(br / f"b{k}.png", a)
    (br / "exposures.json").write_text(json.dumps({f"b{k}.png": 0.01 * 2 ** k for k in range(3)}))
    return br


CLEAR = ("b0.png: has transparent pixels (alpha below 1 in 50% of them): the colour under an unpremultiplied "
         "alpha is undefined; export the bracket without alpha")


@pytest.mark.parametrize("argv", [["probe", "merge", "{b}/b0.png", "{b}/b1.png", "--exposures", "0.01,0.02",
                                   "--encoding", "srgb", "-o", "{o}/m.exr"],
                                  ["calibrate", "response", "{b}", "-o", "{o}/r.npy"]], ids=["merge", "response"])
def test_a_bracket_with_transparent_pixels_is_refused(clear_bracket, tmp_path, capfd, argv):
    """``probe merge`` and ``calibrate response`` merged the colour under alpha 0 (status 0), where a
    capture's photo with transparent pixels is refused: the colour there is undefined."""
    out = tmp_path / "out"
    out.mkdir()
    rc, line = _one_line(capfd, [a.format(b=clear_bracket, o=out) for a in argv])
    assert rc == 2 and line.endswith(CLEAR), line
    assert entries(out) == set()


def test_an_opaque_rgba_bracket_merges(clear_bracket, tmp_path):
    """The guard: alpha 255 everywhere is no transparency."""
    from ffls.cli import main
    from ffls.io.images import read_image, write_png

    for k in range(3):
        a = read_image(clear_bracket / f"b{k}.png").codes
        write_png(clear_bracket / f"b{k}.png", np.dstack([a, np.full(a.shape[:2], 255, np.uint8)]))
    assert main(["probe", "merge", str(clear_bracket / "b0.png"), str(clear_bracket / "b1.png"), "--exposures",
                 "0.01,0.02", "--encoding", "srgb", "-o", str(tmp_path / "m.exr")]) == 0


# ----------------------------------------------------------------------------- --half beyond its range
@pytest.fixture(scope="module")
def bright_probe(tmp_path_factory):
    """A mirror probe (orthographic, 48 px) whose radiance reaches 1.5e6: beyond half floats."""
    from ffls.conventions import latlong_directions
    from ffls.synth.probe import write_mirror_probe

    folder = tmp_path_factory.mktemp("r14probe")
    d = latlong_directions(16, 8)
    m = (1e6 * (1 + 0.5 * d)).astype(np.float32)
    write_mirror_probe(folder, m, (48, 48), "orthographic", center_px=(24, 24), radius_px=20, sphere="pixel")
    return folder


@pytest.mark.parametrize("argv", [
    ["probe", "mirror", "{p}", "--size", "8", "--half", "-o", "{o}/m.exr"],
    ["probe", "merge", "{p}/ball.exr", "{b}", "--exposures", "0.01,0.02", "--half", "-o", "{o}/m.exr"],
    ["lightmap", "convert", "{p}/ball.exr", "{o}/m.exr", "--half"],
], ids=["mirror", "merge", "convert"])
def test_half_output_beyond_the_half_range_is_one_line(bright_probe, tmp_path, capfd, argv):
    """``probe mirror --half`` and ``probe merge --half`` of radiance above 65504 ended in write_exr's
    ValueError traceback (``lightmap convert --half`` said it in one line: the same check now)."""
    from ffls.io.images import read_image, write_exr

    write_exr(tmp_path / "b.exr", read_image(bright_probe / "ball.exr").pixels * 2)  # (a bracket of two)
    out = tmp_path / "out"
    out.mkdir()
    rc, line = _one_line(capfd, [a.format(p=bright_probe, b=tmp_path / "b.exr", o=out) for a in argv])
    assert rc == 2 and "m.exr: values up to " in line and line.endswith(
        "exceed the half-float range (65504): write float (without --half / half=False)"), line
    assert entries(out) == set()


# ----------------------------------------------------------------------------- synth spheres
@pytest.mark.parametrize("flags,says", [
    (["--sphere-radius", "1"], "--sphere-radius 1 with --spheres 4 puts the camera inside sphere 0 (its centre is "
                               "0.803 m from the camera)"),
    (["--sphere-radius", "0.3"], "--sphere-radius 0.3 with --spheres 4 makes spheres 0 and 1 intersect: their "
                                 "centres are 0.5 m apart, less than two radii (0.6 m)"),
    (["--sphere-xy=0.2,0.2;0.2,0.2"], "--sphere-xy with --sphere-radius 0.05 makes spheres 0 and 1 intersect: "
                                      "their centres are 0 m apart"),
    (["--spheres", "64"], "--sphere-radius 0.05 with --spheres 64 makes spheres"),
    (["--sphere-xy=0,0"], "--sphere-xy with --sphere-radius 0.05 makes sphere 0 intersect the object (its centre is "
                          "inside the object); --no-object leaves the object out"),
    (["--sphere-xy=0.15,0"], "--sphere-xy with --sphere-radius 0.05 makes sphere 0 intersect the object (its centre "
                             "is 0.0327 m from the object, less than its radius 0.05 m)"),
], ids=["camera-inside", "radius-0.3", "same-xy", "64-on-the-ring", "in-the-object", "into-the-object"])
def test_synth_refuses_spheres_that_intersect_or_hold_the_camera(tmp_path, capfd, flags, says):
    """``synth --sphere-radius 1`` (the camera inside every sphere) ended in a NaN traceback;
    intersecting spheres were rendered and written to truth.json as if they were apart."""
    rc, line = _one_line(capfd, ["synth", tmp_path / "s", "--lights", "2", "--resolution", "24", "--quiet", *flags])
    assert rc == 2 and line.startswith(f"ffls synth: error: {says}"), line
    assert entries(tmp_path) == set()


def test_synth_spheres_that_touch_are_rendered(tmp_path):
    """The guard: centres two radii apart (0.2,0.2 and 0.2,0.3 at 0.05 m) touch and do not intersect;
    a sphere where the object would be is rendered with --no-object; the benchmarks' row of four."""
    from ffls.cli import main

    for k, flags in enumerate((["--sphere-xy=0.2,0.2;0.2,0.3"], ["--sphere-xy=0,0", "--no-object"],
                               ["--sphere-xy=-0.3,-0.25;-0.1,-0.25;0.1,-0.25;0.3,-0.25"])):
        assert main(["synth", str(tmp_path / f"s{k}"), "--lights", "2", "--resolution", "24", "--quiet", *flags]) == 0


# ----------------------------------------------------------------------------- Radiance headers
def _hdr_with(path: Path, *lines: str, value: float = 0.5) -> Path:
    """A 16x8 Radiance file of ``value`` whose header carries ``lines`` (e.g. ``EXPOSURE=4``)."""
    from ffls.io.images import write_hdr

    write_hdr(path, np.full((8, 16, 3), value, np.float32))
    data = path.read_bytes()
    end = data.index(b"\n\n")
    path.write_bytes(data[:end] + b"".join(b"\n" + ln.encode() for ln in lines) + data[end:])
    return path


def test_a_radiance_files_exposure_and_colour_correction_are_undone(tmp_path):
    """An ``.hdr`` with ``EXPOSURE=4`` (hdrgen, Photosphere) was read 4 times too bright: the format
    says its values were multiplied by it (cumulatively), and by ``COLORCORR`` per channel."""
    from ffls.io.images import read_image

    assert np.allclose(read_image(_hdr_with(tmp_path / "a.hdr", "EXPOSURE=4")).pixels, 0.125)
    two = read_image(_hdr_with(tmp_path / "b.hdr", "EXPOSURE=2", "EXPOSURE=0.5", "COLORCORR= 1 2 4")).pixels
    assert np.allclose(two[..., 0], 0.5) and np.allclose(two[..., 1], 0.25) and np.allclose(two[..., 2], 0.125)
    assert np.allclose(read_image(_hdr_with(tmp_path / "c.hdr", "SOFTWARE=x")).pixels, 0.5)


def test_a_radiance_files_primaries_are_converted_and_reported(cap, tmp_path, capfd):
    """``PRIMARIES=`` (a Rec.2020 render) was read as Rec.709, silently; it is the EXR's
    ``chromaticities`` in another header, and converted and said as they are."""
    from ffls.cli import main
    from ffls.io.images import read_image

    p = _hdr_with(tmp_path / "m.hdr", "PRIMARIES= 0.708 0.292 0.170 0.797 0.131 0.046 0.3127 0.3290")
    capfd.readouterr()
    assert main(["relight", str(cap), "--probe", str(p), "-o", str(tmp_path / "r.exr")]) == 0
    out, err = capfd.readouterr()
    assert ("colour: light map: colour space ITU-R BT.2020 (R 0.708,0.292 G 0.17,0.797 B 0.131,0.046 white "
            "0.3127,0.329) converted to linear Rec.709 (D65)") in err, err
    assert np.allclose(read_image(p).pixels, 0.5, atol=1e-5)  # (a grey stays grey: D65 white both sides)
    assert read_image(p, working_space=False).chromaticities == (0.708, 0.292, 0.17, 0.797, 0.131, 0.046, 0.3127,
                                                                 0.329)


@pytest.mark.parametrize("line,says", [
    ("EXPOSURE=0", "Radiance header line EXPOSURE= must give a positive number (what the stored values were "
                   "multiplied by), not '0'"),
    ("EXPOSURE=abc", "EXPOSURE= must give a positive number"),
    ("EXPOSURE=nan", "EXPOSURE= must give a positive number"),
    ("COLORCORR= 1 1", "COLORCORR= must give 3 positive numbers"),
    ("PRIMARIES= 0.64 0.33", "PRIMARIES= must give 8 numbers (red, green, blue and white x y), not '0.64 0.33'"),
    ("PRIMARIES= 0.64 0.33 0.64 0.33 0.64 0.33 0.3127 0.329", "degenerate primaries"),
], ids=["exposure-0", "exposure-text", "exposure-nan", "colorcorr-2", "primaries-2", "primaries-collinear"])
def test_a_radiance_header_that_says_nothing_usable_is_one_line(tmp_path, capfd, line, says):
    p = _hdr_with(tmp_path / "m.hdr", line)
    rc, msg = _one_line(capfd, ["lightmap", "info", p])
    assert rc == 2 and "m.hdr: " in msg and says in msg, msg


# ----------------------------------------------------------------------------- --lights-map
def test_lights_map_to_an_unknown_image_names_the_flag_and_the_capture(cap, tmp_path, capfd):
    """``--lights-map '{"img_0000.exr": "zzz.exr"}'`` was refused naming lights.json, which is right."""
    rc, line = _one_line(capfd, ["relight", cap, "--probe", "sky", "--lights-map", '{"img_0000.exr": "zzz.exr"}',
                                 "-o", tmp_path / "a.exr"])
    assert rc == 2 and line == ("ffls relight: error: --lights-map maps 'img_0000.exr' to 'zzz.exr', which is not an "
                                f"image of the capture {cap / 'capture.json'} (its images: 'img_0000.exr' to "
                                "'img_0005.exr', 6 in all)"), line


# ----------------------------------------------------------------------------- --store onto -o
@pytest.mark.parametrize("store,made", [("t", False), ("t/s.zarr", True)], ids=["same-folder", "store-in-frames"])
def test_a_store_onto_the_output_folder_is_refused_before_it_is_built(cap, tmp_path, capfd, store, made):
    """``render --turntable 2 --store D -o D/`` built the store in D (the ingest: minutes on real
    photos), then refused D as the frames' folder, in four lines, and left the store there."""
    out = tmp_path / "out"
    (out / "t").mkdir(parents=True) if made else out.mkdir()
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    rc, line = _one_line(capfd, ["render", cap, "--probe", "sky", "--cpu", "--tiles", "--turntable", "2",
                                 "--store", out / store, "-o", f"{out / 't'}/"])
    assert rc == 2 and line.startswith(f"ffls render: error: --store {out / store} and -o {out / 't'}") and line.endswith(
        "the store and the output each need their own place"), line
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before


# ----------------------------------------------------------------------------- view --screenshot
def test_a_screenshot_whose_exr_fails_leaves_no_png(cap, tmp_path, capfd, monkeypatch):
    """``view --screenshot s.png`` wrote the PNG, then the EXR: a failed EXR (disk full) left a new
    PNG beside the old EXR (or none). Both now appear together or not at all."""
    import ffls.io.images as images
    from ffls.errors import OutputError

    def full(path, *a, **k):
        raise OutputError("cannot write OpenEXR file (no space left on the device (disk full))", path)

    from ffls.cli import main

    shot = tmp_path / "s.png"
    monkeypatch.setattr(images, "write_exr", full)
    capfd.readouterr()
    rc = main(["view", str(cap), "--headless", "--frames", "1", "--screenshot", str(shot)])
    out, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip() and "coverage:" not in ln]  # (6 lights: 2 notes)
    assert rc == 2 and "Traceback" not in err and len(lines) == 1 and lines[0].endswith(
        "s.exr: cannot write OpenEXR file (no space left on the device (disk full))"), err
    assert entries(tmp_path) == set()


def test_lightmap_info_and_convert_say_the_colour_conversion(tmp_path, capfd):
    """``lightmap info`` and ``convert`` of a map in another space (an EXR's chromaticities, a
    Radiance file's PRIMARIES) converted it silently: their statistics and output are the converted
    map, and they now say so, as ``relight`` does."""
    from ffls.cli import main

    p = _hdr_with(tmp_path / "m.hdr", "PRIMARIES= 0.708 0.292 0.170 0.797 0.131 0.046 0.3127 0.3290")
    said = ("colour space ITU-R BT.2020 (R 0.708,0.292 G 0.17,0.797 B 0.131,0.046 white 0.3127,0.329) converted "
            "to linear Rec.709 (D65)")
    for argv in (["lightmap", "info", str(p)], ["lightmap", "convert", str(p), str(tmp_path / "o.exr"),
                                                "--to-latlong", "8"]):
        capfd.readouterr()
        assert main(argv) == 0
        out, err = capfd.readouterr()
        assert said in out, out
