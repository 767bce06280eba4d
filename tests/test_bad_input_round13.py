"""Bad input found by the round-13 tester (briefs s13/test13, docs/reliability.md "Round 13").

Round 12's leftovers (``--bounce-shape off`` with another bounce, JSON files read whole whatever
their size, ``benchmarks/probes_orientation.py --orientations 1``) and a fresh attack: symbolic-link
loops, ``--store`` paths, brackets mixing grey and colour, misspelt ``capture.json`` keys,
``calibrate camera --capture``, a Ctrl-C during the interpreter's exit. The promise checked is the
one of ``tests/test_bad_input.py``: exit status 2, one stderr line naming the flag or file, nothing
left.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cli_lines import child_env, entries, tiny_capture
from cli_lines import one_line as _one_line

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r13"), seed=5)



# ----------------------------------------------------------------------------- --bounce-shape
@pytest.mark.parametrize("shape,bounce", [("off", "free"), ("off", "observed"), ("on", "observed"),
                                          ("on", "free")])
def test_bounce_shape_with_another_bounce_is_refused_before_loading(tmp_path, capfd, shape, bounce):
    """``--bounce-shape off --bounce free`` was accepted and did nothing (the shape applies to
    neither); ``on`` was refused only once the capture had loaded, naming capture.json."""
    rc, line = _one_line(capfd, ["lights", tmp_path / "no-capture", "--bounce-shape", shape, "--bounce", bounce,
                                 "--workers", "1"])
    assert rc == 2 and line.startswith(f"ffls lights: error: --bounce-shape {shape} applies only with --bounce "
                                       "calibrated"), line


# ----------------------------------------------------------------------------- JSON size
def _sparse(path: Path, size: int) -> Path:
    """A file of ``size`` bytes that takes no disk (a hole)."""
    with open(path, "wb") as f:
        f.truncate(size)
    return path


@pytest.fixture(scope="module")
def huge(cap, tmp_path_factory):
    """Files one byte over MAX_JSON_BYTES: as capture.json, probe.json, exposures.json, lights files."""
    from ffls.io.capture import MAX_JSON_BYTES

    root = tmp_path_factory.mktemp("r13huge")
    n = MAX_JSON_BYTES + 1
    shutil.copytree(cap, root / "bigcap")
    _sparse(root / "bigcap" / "capture.json", n)
    (root / "bigprobe").mkdir()
    _sparse(root / "bigprobe" / "probe.json", n)
    (root / "bracket").mkdir()
    _sparse(root / "bracket" / "exposures.json", n)
    for name in ("lights.json", "lights.lp", "map.json"):
        _sparse(root / name, n)
    return root


@pytest.mark.parametrize("argv,named", [
    (["relight", "{h}/bigcap", "--probe", "sky", "-o", "{o}/r.exr"], "bigcap/capture.json: is 268435457 bytes, "
     "more than the 256 MiB (268435456 bytes) a capture.json may be"),
    (["relight", "{cap}", "--lights", "{h}/lights.json", "--probe", "sky", "-o", "{o}/r.exr"],
     "lights.json: is 268435457 bytes, more than the 256 MiB (268435456 bytes) a lights.json may be"),
    (["relight", "{cap}", "--lights", "{h}/lights.lp", "--probe", "sky", "-o", "{o}/r.exr"],
     "lights.lp: is 268435457 bytes, more than the 256 MiB (268435456 bytes) a .lp file may be"),
    (["relight", "{cap}", "--lights-map", "{h}/map.json", "--probe", "sky", "-o", "{o}/r.exr"],
     "map.json: is 268435457 bytes, more than the 256 MiB (268435456 bytes) a lights map may be"),
    (["probe", "mirror", "{h}/bigprobe", "-o", "{o}/m.exr"], "probe.json: is 268435457 bytes, more than the"),
    (["calibrate", "response", "{h}/bracket", "-o", "{o}/r.npy"], "exposures.json: cannot read exposures (is "
     "268435457 bytes, more than the 256 MiB (268435456 bytes) a exposures.json"),
    (["calibrate", "camera", "{h}/lights.json", "--capture", "{h}/bigcap"], "capture.json: cannot read JSON (is "
     "268435457 bytes"),
], ids=["capture.json", "lights.json", "lp", "lights-map", "probe.json", "exposures.json", "calibrate-capture"])
def test_a_json_file_over_the_limit_is_refused_before_it_is_read(cap, huge, tmp_path, capfd, monkeypatch, argv,
                                                                  named):
    """A JSON (or .lp) input was read whole whatever its size (a 256 MiB capture.json: 3.9 s and
    647 MB before its "corrupt JSON" line; an .lp of 300 MiB 12 s and 1.7 GB)."""
    import ffls.io.capture as capture_io

    parse = capture_io.parse_json

    def small_only(text):  # (the size is refused before the text is parsed; the small ones are read)
        assert len(text) < 1 << 20, "a huge file was read and parsed"
        return parse(text)

    monkeypatch.setattr(capture_io, "parse_json", small_only)
    rc, line = _one_line(capfd, [a.format(h=huge, cap=cap, o=tmp_path) for a in argv])
    assert rc == 2 and named in line and "(ffls reads it whole into memory; docs/formats.md)" in line, line
    assert entries(tmp_path) == set()


def test_a_json_file_at_the_limit_is_read(tmp_path):
    """The guard of the limit: a file of exactly MAX_JSON_BYTES is read (the check is on the size only)."""
    from ffls.io.capture import MAX_JSON_BYTES, read_json_text

    p = tmp_path / "x.json"
    with open(p, "wb") as f:
        f.write(b"{}")
        f.truncate(MAX_JSON_BYTES)
    assert len(read_json_text(p)) == MAX_JSON_BYTES


# ----------------------------------------------------------------------------- benchmark
def test_the_orientation_benchmark_runs_with_one_orientation(tmp_path, monkeypatch):
    """``benchmarks/probes_orientation.py --orientations 1`` crashed: one SourceFit has no ``members``."""
    from ffls.synth.scene import write_synthetic_capture

    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import probes_orientation

    def small_capture(prefix):
        from ffls.io.capture import load_capture_and_lights

        write_synthetic_capture(tmp_path / "cap", n_lights=12, resolution=24, progress=False, seed=1)
        return load_capture_and_lights(tmp_path / "cap")

    monkeypatch.setattr(probes_orientation, "probe_benchmark_capture", small_capture)
    monkeypatch.setattr(sys, "argv", ["probes_orientation.py"])
    out = tmp_path / "o.json"
    probes_orientation.main(["--maps", "sunrise", "--orientations", "1", "--json", str(out)])
    row = json.loads(out.read_text())["rows"][0]
    assert len(row["relit_capture_single"]) == 1 and list(row["relit_capture_average"]) == ["1"]
    assert len(row["sources"]) == 1 and len(row["heldout"]) == 1 and 0 < row["heldout"][0] < 1


# ----------------------------------------------------------------------------- symbolic-link loops
@pytest.fixture()
def loop(tmp_path):
    (tmp_path / "loop2.exr").symlink_to("loop1.exr")
    (tmp_path / "loop1.exr").symlink_to("loop2.exr")
    (tmp_path / "capdir").symlink_to("capdir")
    return tmp_path


LOOP = "is a symbolic link loop (its links lead back to themselves, to no file)"


@pytest.mark.parametrize("argv,named", [
    (["lightmap", "info", "{t}/loop1.exr"], "loop1.exr: " + LOOP),
    (["relight", "{cap}", "--probe", "{t}/loop1.exr", "-o", "{t}/o.exr"], "loop1.exr: " + LOOP),
    (["relight", "{cap}", "--probe", "sky", "--mask", "{t}/loop1.exr", "-o", "{t}/o.exr"], "loop1.exr: " + LOOP),
    (["relight", "{cap}", "--probe", "sky", "--lights", "{t}/loop1.exr", "-o", "{t}/o.exr"], "loop1.exr: " + LOOP),
    (["relight", "{t}/capdir", "--probe", "sky", "-o", "{t}/o.exr"], "capdir: " + LOOP),
    (["lightmap", "make", "sky", "{t}/loop1.exr"], "loop1.exr: " + LOOP + "; ffls writes through a link only"),
], ids=["map", "probe", "mask", "lights", "capture", "output"])
def test_a_symbolic_link_loop_says_so(cap, loop, capfd, argv, named):
    """A link loop was "image file not found" (or "lights file not found", "capture folder not found");
    as an output, "a symbolic link to X, which does not exist" (X the link itself)."""
    before = entries(loop)
    rc, line = _one_line(capfd, [a.format(t=loop, cap=cap) for a in argv])
    assert rc == 2 and named in line, line
    assert entries(loop) == before


def test_a_dangling_link_names_its_target(cap, tmp_path, capfd):
    (tmp_path / "gone.exr").symlink_to(tmp_path / "nowhere.exr")
    rc, line = _one_line(capfd, ["relight", cap, "--probe", tmp_path / "gone.exr", "-o", tmp_path / "o.exr"])
    assert rc == 2 and f"gone.exr: is a symbolic link to {tmp_path / 'nowhere.exr'}, which does not exist" in line


# ----------------------------------------------------------------------------- --store
@pytest.mark.parametrize("store,named", [
    ("nofolder/s.zarr", "argument --store: {t}/nofolder/s.zarr: the store's folder {t}/nofolder does not exist"),
    ("s.exr", "argument --store: {t}/s.exr: a store is a folder: its name ends with .zarr or has no extension"),
    ("file.zarr", "argument --store: {t}/file.zarr: is a file; the store must be a new path or an ffls store"),
], ids=["no-folder", "named-like-a-file", "a-file"])
@pytest.mark.parametrize("command", ["relight", "render"])
def test_a_bad_store_path_is_refused_where_it_is_parsed(cap, tmp_path, capfd, store, named, command):
    """``relight``/``render`` use the store only when the photos do not fit in memory: a store path
    that can never be one was accepted silently (status 0) when they fitted."""
    (tmp_path / "file.zarr").write_text("mine")
    argv = [command, cap, "--probe", "sky", "--store", tmp_path / store, "-o", tmp_path / "o.png"]
    rc, line = _one_line(capfd, argv + (["--cpu"] if command == "render" else []))
    assert rc == 2 and named.format(t=tmp_path) in line, line
    assert entries(tmp_path) == {"file.zarr"} and (tmp_path / "file.zarr").read_text() == "mine"


# ----------------------------------------------------------------------------- brackets
def test_a_bracket_mixing_grey_and_colour_is_refused(tmp_path, capfd):
    """``probe merge`` of a colour JPEG and a grey PNG merged them (the grey replicated), status 0."""
    import cv2

    rng = np.random.default_rng(0)
    cv2.imwrite(str(tmp_path / "a.png"), (rng.random((16, 16, 3)) * 200).astype(np.uint8))
    cv2.imwrite(str(tmp_path / "b.png"), (rng.random((16, 16)) * 200).astype(np.uint8))
    rc, line = _one_line(capfd, ["probe", "merge", tmp_path / "a.png", tmp_path / "b.png", "--exposures", "1,2",
                                 "--encoding", "srgb", "-o", tmp_path / "m.exr"])
    assert rc == 2 and "b.png: is grey (one channel) but 1 of the 2 bracketed images are colour (e.g. 'a.png'): " \
        "a bracket mixing grey and colour images is almost always a wrong export" in line, line
    assert not (tmp_path / "m.exr").exists()


def test_bit_depths_are_named_with_their_article(tmp_path, capfd):
    """'is a 8-bit image' (probe merge without an encoding) and 'got a float-bit RGB image' (calibrate
    response of EXR photos)."""
    import cv2

    from ffls.io.images import write_exr

    for k in range(2):
        cv2.imwrite(str(tmp_path / f"a{k}.png"), np.full((16, 16, 3), 60 * (k + 1), np.uint8))
    rc, line = _one_line(capfd, ["probe", "merge", tmp_path / "a0.png", tmp_path / "a1.png", "--exposures", "1,2",
                                 "-o", tmp_path / "m.exr"])
    assert rc == 2 and "a0.png is an 8-bit image that could be sRGB" in line, line
    br = tmp_path / "br"
    br.mkdir()
    for k in range(2):
        write_exr(br / f"b{k}.exr", np.full((16, 16, 3), 0.2 * (k + 1), np.float32))
    (br / "exposures.json").write_text('{"b0.exr": 1, "b1.exr": 2}')
    rc, line = _one_line(capfd, ["calibrate", "response", br, "-o", tmp_path / "r.npy"])
    assert rc == 2 and "bracketed images must be 8-bit RGB, got a 32-bit float RGB image" in line, line


# ----------------------------------------------------------------------------- capture.json keys
@pytest.mark.parametrize("key,meant", [("encodng", "encoding"), ("sphere_radus", "sphere_radius"),
                                       ("Encoding", "encoding"), ("sphere_materal", "sphere_material"),
                                       ("image", "images")])
def test_a_misspelt_capture_key_is_refused(cap, tmp_path, capfd, key, meant):
    """An unknown key is kept and ignored: ``"encodng": "srgb"`` left the encoding unstated (ffls
    lights then calibrates it), silently."""
    c = tmp_path / "c"
    shutil.copytree(cap, c)
    doc = json.loads((c / "capture.json").read_text())
    doc[key] = doc["images"] if key == "image" else "srgb"
    (c / "capture.json").write_text(json.dumps(doc))
    rc, line = _one_line(capfd, ["relight", c, "--probe", "sky", "-o", tmp_path / "o.exr"])
    assert rc == 2 and f"capture.json: {key}: unknown key; did you mean {meant!r}?" in line, line
    assert not (tmp_path / "o.exr").exists()


@pytest.mark.parametrize("edit,named", [
    (lambda d: d["lights"][2].update(stauts="rejected", reason="blurred"), "lights[2].stauts: unknown key; did you "
     "mean 'status'?"),
    (lambda d: d["lights"][0].update(uncertainty_dge=2.0), "lights[0].uncertainty_dge: unknown key; did you mean "
     "'uncertainty_deg'?"),
    (lambda d: d.update(encodng={"curve": "srgb"}), "encodng: unknown key; did you mean 'encoding'?"),
], ids=["status", "uncertainty", "encoding"])
def test_a_misspelt_lights_key_is_refused(cap, tmp_path, capfd, edit, named):
    """``"stauts": "rejected"`` left the light's status "ok": a light meant rejected was used, silently."""
    doc = json.loads((cap / "lights.json").read_text())
    edit(doc)
    (tmp_path / "l.json").write_text(json.dumps(doc))
    rc, line = _one_line(capfd, ["relight", cap, "--lights", tmp_path / "l.json", "--probe", "sky",
                                 "-o", tmp_path / "o.exr"])
    assert rc == 2 and f"l.json: {named}" in line, line
    assert not (tmp_path / "o.exr").exists()


def test_keys_of_ones_own_are_still_kept(cap, tmp_path):
    from ffls.io.capture import load_capture

    c = tmp_path / "c"
    shutil.copytree(cap, c)
    doc = json.loads((c / "capture.json").read_text())
    doc.update({"notes": "turntable, 2 lamps", "x-encodng": 1, "author": "me"})
    (c / "capture.json").write_text(json.dumps(doc))
    extra = load_capture(c).extra
    assert {"notes", "x-encodng", "author", "truth"} <= set(extra)
    from ffls.io.capture import load_lights

    doc = json.loads((cap / "lights.json").read_text())
    doc["lights"][1].update({"note": "lamp 2", "x-stauts": 1})
    doc["x-lihgts"] = 2
    (tmp_path / "l.json").write_text(json.dumps(doc))
    assert load_lights(tmp_path / "l.json").extra[1] == {"note": "lamp 2", "x-stauts": 1}


# ----------------------------------------------------------------------------- calibrate camera --capture
@pytest.mark.parametrize("target,named", [("nope", "nope: capture folder not found"),
                                          ("empty", "empty/capture.json: capture.json not found"),
                                          ("loop", "loop: " + LOOP)])
def test_calibrate_camera_checks_its_capture_before_calibrating(tmp_path, capfd, monkeypatch, target, named):
    """``--capture`` was read only after the calibration (a missing capture reported after it)."""
    import ffls.camera.calibrate as calib

    def no_calibration(*a, **k):
        raise AssertionError("calibrated first")

    monkeypatch.setattr(calib, "calibrate_camera", no_calibration)
    (tmp_path / "empty").mkdir()
    (tmp_path / "loop").symlink_to("loop")
    photo = tmp_path / "b.png"
    photo.write_bytes(b"")
    rc, line = _one_line(capfd, ["calibrate", "camera", photo, photo, photo, "--capture", tmp_path / target])
    assert rc == 2 and named in line, line


def test_calibrate_camera_takes_the_capture_json_file_for_its_folder(cap, tmp_path):
    from ffls.camera.calibrate import write_camera_to_capture

    c = tmp_path / "c"
    shutil.copytree(cap, c)
    K = [[30.0, 0, 12], [0, 30.0, 12], [0, 0, 1]]
    assert write_camera_to_capture(c / "capture.json", K, [0.0] * 5, (24, 24)) == c / "capture.json"
    assert json.loads((c / "capture.json").read_text())["camera"]["K"] == K


# ----------------------------------------------------------------------------- composite background, map size
def test_a_float_tiff_background_is_named_as_such(tmp_path, capfd):
    """It was told to 'convert an 8-bit photograph to linear radiance first'."""
    import cv2

    from ffls.cli import main

    root = tmp_path / "set"  # (the composite set: 2 lights, 16 px)
    assert main(["synth", str(root), "--composite-set", "sky", "--lights", "2", "--resolution", "16",
                 "--quiet"]) == 0
    cv2.imwrite(str(tmp_path / "bg.tif"), np.full((16, 16, 3), 0.5, np.float32))
    rc, line = _one_line(capfd, ["composite", "--object", root / "object", "--surface", root / "surface",
                                 "--lightmap", "sky", "--background", tmp_path / "bg.tif",
                                 "--mask", root / "object_mask.png", "--surface-mask", root / "surface_mask.png",
                                 "-o", tmp_path / "c.exr"])
    assert rc == 2 and "bg.tif: the background must be a linear HDR image (.exr or .hdr), not .tif;" in line, line
    assert "8-bit" not in line


def test_a_too_small_angular_map_has_its_article(tmp_path, capfd):
    from ffls.io.images import write_exr

    write_exr(tmp_path / "one.exr", np.ones((1, 1, 3), np.float32))
    rc, line = _one_line(capfd, ["lightmap", "info", tmp_path / "one.exr"])
    assert rc == 2 and "a 1x1 light map is too small: an angular map must be at least 4x4" in line, line


def test_a_cut_png_past_pillows_bomb_limit_says_its_size(cap, tmp_path, capfd):
    """A 14000x14000 grey PNG whose data is cut (196 million pixels, past Pillow's 179 million of
    ``Image.open``, within OpenCV's 2^30) was "over 178956970 pixels, which OpenCV did not decode
    (its limit is 2^30 pixels)": neither was the reason."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", 14000, 14000, 8, 0, 0, 0, 0)
    (tmp_path / "cut.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
                                       + chunk(b"IDAT", zlib.compress(bytes(1000))) + chunk(b"IEND", b""))
    rc, line = _one_line(capfd, ["relight", cap, "--probe", "sky", "--mask", tmp_path / "cut.png",
                                 "-o", tmp_path / "o.exr"])
    assert rc == 2 and line.endswith("cut.png: cannot decode PNG image: its 14000x14000 header is valid but the "
                                     "data is corrupt or truncated"), line


# ----------------------------------------------------------------------------- Ctrl-C during the exit
def test_a_ctrl_c_while_the_interpreter_exits_keeps_the_commands_status(tmp_path):
    """The command done and its output complete, a Ctrl-C while the interpreter joined its threads
    (zarr's and Dask's after ``ingest``) ended the process by SIGINT with no line (status -2 for 11
    of 40 late Ctrl-Cs of ``ingest``); now it ends the exit at once with the command's status."""
    script = tmp_path / "late.py"
    script.write_text(
        "import os, signal, sys, threading, time\n"
        "sys.argv = ['ffls', 'lightmap', 'make', 'sky', sys.argv[1], '--height', '8']\n"
        "from ffls.__main__ import main\n"
        "rc = main()\n"
        "def late():\n"  # (a thread the exit waits for, as a library's; the signal lands during the join)
        "    time.sleep(0.3)\n"
        "    os.kill(os.getpid(), signal.SIGINT)\n"
        "    time.sleep(5)\n"
        "threading.Thread(target=late).start()\n"
        "sys.exit(rc)\n")
    out = tmp_path / "m.exr"
    p = subprocess.run([sys.executable, str(script), str(out)], env=child_env(), capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 0 and "Traceback" not in p.stderr and "Exception ignored" not in p.stderr, p
    assert out.is_file()


def test_a_ctrl_c_just_after_the_command_returned_keeps_its_status(tmp_path):
    """A Ctrl-C after the command returned but before the exit's handler was in place (the instant in
    which ``signal.signal`` runs) ended in a ``KeyboardInterrupt`` traceback and status -2 (seen once
    in 8 Ctrl-Cs of ``ffls relight`` timed at its end); now it exits at once with the command's status."""
    script = tmp_path / "instant.py"
    script.write_text(
        "import signal, sys\n"
        "import ffls.cli\n"
        "ffls.cli.main = lambda: 3\n"  # (a command that returned status 3)
        "real = signal.signal\n"
        "def interrupted(*a):\n"  # (the Ctrl-C lands while the first handler is being set)
        "    signal.signal = real\n"
        "    raise KeyboardInterrupt\n"
        "signal.signal = interrupted\n"
        "from ffls.__main__ import main\n"
        "sys.exit(main())\n")
    p = subprocess.run([sys.executable, str(script)], env=child_env(), capture_output=True, text=True, timeout=60)
    assert p.returncode == 3 and "Traceback" not in p.stderr and p.stderr == "", p
