"""Bad input found by the round-11 tester (briefs s11/test11, docs/reliability.md "Round 11").

The leftovers of round 10 (an output onto a capture's photo, symbolic links, a store named like
an image, absurd distortion, an unstated probe material, a synth of 100000 lights, a read-only
capture's compressed basis) and a new attack: damaged JPEG data, keys given twice in JSON, a near
light inside the scene, a full standard output, Ctrl-C outside a command. The promise checked is
the one of ``tests/test_bad_input.py``: exit status 2, one stderr line naming the flag or file,
nothing left.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cli_lines import one_line as _one_line
from ffls.cli import main


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    from ffls.synth.scene import write_synthetic_capture

    root = tmp_path_factory.mktemp("r11")
    write_synthetic_capture(root / "cap", n_lights=12, resolution=24, progress=False, seed=3)
    return root / "cap"


def _edited_capture(cap: Path, dst: Path, edit) -> Path:
    shutil.copytree(cap, dst)
    doc = json.loads((dst / "capture.json").read_text())
    edit(doc)
    (dst / "capture.json").write_text(json.dumps(doc))
    return dst


# ----------------------------------------------------------------------------- the table of round 11
@pytest.fixture(scope="module")
def ws(cap, tmp_path_factory):
    """Broken files beside the good capture ``cap``."""
    import cv2

    root = tmp_path_factory.mktemp("r11ws")
    w = {"cap": cap, "root": root}
    _edited_capture(cap, root / "cap_dist_huge", lambda d: d["camera"].__setitem__("dist", [1e10, 0, 0, 0, 0]))
    _edited_capture(cap, root / "cap_dist_fold", lambda d: d["camera"].__setitem__("dist", [-2.0, 0, 0, 0, 0]))
    shutil.copytree(cap, root / "cap_dup")
    text = (cap / "capture.json").read_text()
    assert '"encoding": "linear"' in text
    (root / "cap_dup" / "capture.json").write_text(text.replace('"encoding": "linear"',
                                                                '"encoding": "srgb", "encoding": "linear"', 1))
    (root / "lights_dup.json").write_text((cap / "lights.json").read_text().replace('"version": 1',
                                                                                    '"version": 1, "version": 1', 1))
    (root / "empty.json").write_text("")
    br = root / "bracket"
    br.mkdir()
    for k in range(3):
        assert cv2.imwrite(str(br / f"b{k}.png"), np.full((16, 16, 3), 40 * (k + 1), np.uint8))
    (br / "exposures.json").write_text('{"b0.png": 0.01, "b0.png": 0.02, "b1.png": 0.02, "b2.png": 0.04}')
    cut = root / "bracket_cut"  # a truncated photo in a good bracket
    shutil.copytree(br, cut)
    (cut / "exposures.json").write_text('{"b0.png": 0.01, "b1.png": 0.02, "b2.png": 0.04}')
    data = (cut / "b1.png").read_bytes()
    (cut / "b1.png").write_bytes(data[: len(data) // 2])
    rng = np.random.default_rng(0)
    assert cv2.imwrite(str(root / "whole.jpg"), rng.integers(0, 255, (24, 24, 3), dtype=np.uint8))
    data = (root / "whole.jpg").read_bytes()
    (root / "zeroed.jpg").write_bytes(data[:200] + bytes(200) + data[400:])  # the header whole, data zeroed
    (root / "dangling.exr").symlink_to(root / "nowhere.exr")
    (root / "photo_link.exr").symlink_to(cap / "img_0004.exr")
    return w


L11 = ["relight", "{cap}", "--probe", "sky"]
CASES11 = [
    # a command with no capture among its inputs wrote over a capture's photo (directly or through a link)
    ("lightmap-make-onto-photo", ["lightmap", "make", "sky", "{cap}/img_0000.exr", "--height", "8"],
     "img_0000.exr: is a photo of the capture"),
    ("lightmap-convert-onto-photo", ["lightmap", "convert", "sky", "{cap}/img_0001.exr"],
     "img_0001.exr: is a photo of the capture"),
    ("lightmap-make-link-to-photo", ["lightmap", "make", "sky", "{root}/photo_link.exr", "--height", "8"],
     "is a photo of the capture"),
    # a dangling link was replaced by a file (cp refuses to write through one)
    ("lightmap-make-dangling-link", ["lightmap", "make", "sky", "{root}/dangling.exr", "--height", "8"],
     "dangling.exr: is a symbolic link to"),
    # --store x.exr made a zarr folder named x.exr
    ("ingest-store-exr", ["ingest", "{cap}", "--store", "{out}/x.exr", "--workers", "1"],
     "x.exr: a store is a folder: its name ends with .zarr or has no extension, not .exr"),
    # absurd distortion was accepted; detection then found no sphere
    ("capture-dist-huge", ["lights", "{root}/cap_dist_huge", "--workers", "1", "-o", "{out}/l.json"],
     "camera.dist: scales the image corners' distance from the principal point by"),
    ("capture-dist-folds", L11[:1] + ["{root}/cap_dist_fold"] + L11[2:] + ["-o", "{out}/a.exr"],
     "camera.dist: the distortion is not monotonic over the image"),
    # damaged JPEG data after a valid header decoded grey blocks silently
    ("mask-jpeg-zeroed", L11 + ["--mask", "{root}/zeroed.jpg", "-o", "{out}/a.png"],
     "zeroed.jpg: cannot decode JPEG image (corrupt, truncated or not a JPEG file) (libjpeg: Corrupt JPEG data"),
    # a key given twice: Python's parser kept the last one silently
    ("capture-json-dup-key", L11[:1] + ["{root}/cap_dup"] + L11[2:] + ["-o", "{out}/a.exr"],
     "capture.json: corrupt JSON: the key 'encoding' is given twice in one object"),
    ("lights-json-dup-key", L11 + ["--lights", "{root}/lights_dup.json", "-o", "{out}/a.exr"],
     "lights_dup.json: corrupt JSON: the key 'version' is given twice"),
    ("lights-json-empty", L11 + ["--lights", "{root}/empty.json", "-o", "{out}/a.exr"],
     "empty.json: the file is empty (no JSON in it)"),
    ("exposures-json-dup-key", ["calibrate", "response", "{root}/bracket", "-o", "{out}/r.npy"],
     "exposures.json: cannot read exposures (corrupt JSON: the key 'b0.png' is given twice"),
    # a turntable into a folder of other files (the capture itself) was refused after its coverage lines
    ("render-turntable-into-capture", ["render", "{cap}", "--probe", "sky", "--cpu", "--turntable", "2", "-o",
                                       "{cap}"], "the folder holds other files than frames"),
    # a file name over the file system's limit: an OSError traceback while the arguments were parsed
    ("output-name-too-long", ["lightmap", "make", "sky", "{out}/" + "a" * 300 + ".exr", "--height", "8"],
     ".exr: cannot use this path (file name too long)"),
    # a trailing slash (a folder) on a file output: Path drops it, and the file o/a.exr was written
    ("output-file-with-slash", ["lightmap", "make", "sky", "{out}/a.exr/", "--height", "8"],
     "a.exr/: ends with '/', a folder, but names a .exr file"),
    # a folder output named like a file: demo -o d.exr made a folder d.exr
    ("demo-folder-named-exr", ["demo", "-o", "{out}/d.exr", "--no-view"],
     "d.exr: the output is a folder; a name ending with .exr is a file's"),
    ("synth-folder-named-json", ["synth", "{out}/s.json", "--lights", "2", "--resolution", "8"],
     "s.json: the output is a folder; a name ending with .json is a file's"),
    # calibrate read its photos with cv2.imread: "cannot read image" for a missing, truncated or folder path
    ("calibrate-response-truncated", ["calibrate", "response", "{root}/bracket_cut", "-o", "{out}/r.npy"],
     "b1.png: cannot decode PNG image: its 16x16 header is valid but the data is corrupt or truncated"),
    ("calibrate-camera-folder", ["calibrate", "camera", "{root}/bracket", "--capture", "{cap}"],
     "bracket: is a folder, not an image file"),
    ("calibrate-camera-missing", ["calibrate", "camera", "{root}/bracket/b0.png", "{root}/nope.png", "--capture",
                                  "{cap}"], "nope.png: image file not found"),
    # a near light inside the scene: a ZeroDivisionError traceback (1e-300) or lights inside the object
    ("synth-near-tiny", ["synth", "{out}/s", "--lights", "2", "--resolution", "8", "--near", "1e-300"],
     "--near 1e-300 puts the lights inside the scene"),
    ("synth-near-inside", ["synth", "{out}/s", "--lights", "2", "--resolution", "8", "--near", "0.2"],
     "--near 0.2 puts the lights inside the scene: its object and spheres reach"),
    # --layout with a built-in map: refused by relight, ignored by lightmap info/convert
    ("lightmap-info-layout-builtin", ["lightmap", "info", "sky", "--layout", "cube"],
     "a layout (cube) applies to a light-map file, and 'sky' is a built-in map"),
    ("lightmap-convert-layout-builtin", ["lightmap", "convert", "sky", "{out}/m.exr", "--layout", "angular"],
     "a layout (angular) applies to a light-map file"),
]


@pytest.mark.parametrize("argv,names", [pytest.param(a, n, id=i) for i, a, n in CASES11])
def test_round11_bad_input_is_one_line(ws, tmp_path, capfd, argv, names):
    out = tmp_path / "out"
    out.mkdir()
    keys = {k: str(v) for k, v in ws.items()}
    args = [a.format(out=out, **keys) for a in argv]
    watched = (out, ws["cap"], ws["root"])
    before = {p: sorted((q.name, q.is_symlink() or q.stat().st_mtime_ns) for q in p.iterdir()) for p in watched}
    rc, line = _one_line(capfd, args)
    assert rc == 2 and "error" in line and names in line, line
    for p, entries in before.items():  # nothing written or replaced, no temporary left
        assert sorted((q.name, q.is_symlink() or q.stat().st_mtime_ns) for q in p.iterdir()) == entries, p


# ----------------------------------------------------------------------------- outputs
def test_an_output_link_is_written_through(tmp_path, capfd):
    """A link to an existing file was replaced by a file: now the file it points to is written, as
    cp, ffmpeg and oiiotool do, and the link stays."""
    from ffls.io.images import read_image

    target = tmp_path / "maps" / "sky.exr"
    target.parent.mkdir()
    target.write_bytes(b"old")
    link = tmp_path / "sky.exr"
    link.symlink_to(target)
    assert main(["lightmap", "make", "sky", str(link), "--height", "8"]) == 0
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert read_image(target).pixels.shape == (8, 16, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["maps", "sky.exr"]
    assert sorted(p.name for p in target.parent.iterdir()) == ["sky.exr"]  # no temporary left there


def test_a_capture_photo_in_a_subfolder_is_protected(tmp_path):
    """The capture.json that lists a photo may be a folder or more above it."""
    from ffls.io.capture import capture_listing

    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "a.exr").write_bytes(b"x")
    (tmp_path / "other.exr").write_bytes(b"x")
    (tmp_path / "capture.json").write_text(json.dumps({"format": "ffls-capture", "images": ["photos/a.exr"]}))
    assert capture_listing(tmp_path / "photos" / "a.exr") == tmp_path / "capture.json"
    assert capture_listing(tmp_path / "other.exr") is None
    assert capture_listing(tmp_path / "missing.exr") is None


def test_capture_given_as_its_capture_json_finds_its_lights(cap, tmp_path, capfd):
    """``relight CAP/capture.json`` looked for ``CAP/capture.json/lights.json``."""
    assert main(["relight", str(cap / "capture.json"), "--probe", "sky", "-o", str(tmp_path / "a.exr")]) == 0, \
        capfd.readouterr().err


def test_lights_outputs_appear_together_or_not_at_all(cap, tmp_path, capfd, monkeypatch):
    """``ffls lights -o L.json --lp L.lp``: a failure writing the .lp left a new lights.json beside an
    old (or no) .lp, and an old lights.json was replaced although the command failed."""
    import ffls.io.capture
    import ffls.spheres.detect
    import ffls.spheres.estimate
    from ffls.errors import OutputError

    def no_fit(monkeypatch):  # (the detection and the fit are not what is tested)
        monkeypatch.setattr(ffls.spheres.detect, "find_spheres_in_capture", lambda capture, **kw: [])
        monkeypatch.setattr(ffls.spheres.estimate, "estimate_lights",
                            lambda capture, **kw: ffls.io.capture.load_lights(cap / "lights.json", capture))

    no_fit(monkeypatch)

    def full(path, *a, **k):
        raise OutputError("cannot write (no space left on the device (disk full))", path)

    out, lp = tmp_path / "l.json", tmp_path / "l.lp"
    out.write_text("old")
    monkeypatch.setattr(ffls.io.capture, "write_lp", full)
    rc, line = _one_line(capfd, ["lights", cap, "--workers", "1", "-o", out, "--lp", lp])
    assert rc == 2 and f"{lp}: cannot write" in line, line
    assert out.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["l.json"]
    monkeypatch.undo()
    no_fit(monkeypatch)
    assert main(["lights", str(cap), "--workers", "1", "-o", str(out), "--lp", str(lp)]) == 0
    assert out.read_text() != "old" and lp.is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["l.json",
                                                                                                          "l.lp"]


# ----------------------------------------------------------------------------- camera.dist
@pytest.mark.parametrize("dist,ok", [
    ([-0.3, 0.1, 0.001, 0.001, 0.0], True),  # a wide-angle lens, barrel
    ([0.2, 0.0, 0.0, 0.0, 0.0], True),  # pincushion
    ([-0.3, 0.1, 0.0, 0.0, 0.0, 0.1, 0.02, 0.01], True),  # the rational model
    ([1e10, 0, 0, 0, 0], False), ([-1e10, 0, 0, 0, 0], False), ([0, 0, 0, 0, 1e10], False),
    ([-0.4, 0.0, 0.0, 0.0, 0.0], False),  # folds back before the corners of this 88-degree view
])
def test_distortion_must_stay_monotonic_and_within_a_factor_4(dist, ok):
    from ffls.io.capture import distortion_problem

    K = np.array([[1000.0, 0, 959.5], [0, 1000.0, 539.5], [0, 0, 1]])
    why = distortion_problem(K, dist, (1920, 1080))
    assert (why is None) == ok, why


# ----------------------------------------------------------------------------- probe.json material
def test_unstated_probe_material_is_said_not_invented(tmp_path, capfd):
    """A probe.json without "sphere" (or its material) was described as a mirror by ``probe
    diffuse`` ("this one is 'mirror'"): now the command says what the ball is, and the note says so."""
    from ffls.synth.probe import look_at, write_mirror_probe

    K = np.array([[350.0, 0, 40], [0, 350.0, 40], [0, 0, 1]])
    m = np.full((16, 32, 3), 0.3, np.float32)
    m[:8] *= 2
    write_mirror_probe(tmp_path / "p", m, (80, 80), K=K, world_from_camera=look_at([0, -1.0, 0.2]), radius=0.1,
                       supersample=1)
    doc = json.loads((tmp_path / "p" / "probe.json").read_text())
    doc["sphere"] = {k: v for k, v in doc["sphere"].items() if k in ("center", "radius")}
    (tmp_path / "p" / "probe.json").write_text(json.dumps(doc))
    capfd.readouterr()
    assert main(["probe", "mirror", str(tmp_path / "p"), "-o", str(tmp_path / "m.exr"), "--size", "8"]) == 0
    err = capfd.readouterr().err
    assert "sphere.material not stated in probe.json: taken as 'mirror' (ffls probe mirror)" in err, err


# ----------------------------------------------------------------------------- synth of many lights
def test_synth_of_many_lights_says_its_time_and_size_first(tmp_path, capfd, monkeypatch):
    """``synth --lights 100000 --resolution 8`` ran for minutes without a word."""
    import ffls.commands.synth as synth

    def stop(args, folder):
        raise KeyboardInterrupt  # (the estimate is printed before rendering starts)

    monkeypatch.setattr(synth, "_synth", stop)
    capfd.readouterr()
    rc = main(["synth", str(tmp_path / "s"), "--lights", "100000", "--resolution", "8"])
    lines = capfd.readouterr().err.strip().splitlines()
    assert rc == 130 and len(lines) == 2, lines
    assert lines[0].startswith("ffls synth: estimate: --lights 100000 at --resolution 8: 100000 images, about "), lines
    assert " min and up to 134 MiB on a 2-core machine" in lines[0], lines
    assert list(tmp_path.iterdir()) == []


def test_synth_beyond_the_free_space_is_refused(tmp_path, capfd, monkeypatch):
    import shutil as sh
    from types import SimpleNamespace

    import ffls.commands.synth as synth

    monkeypatch.setattr(sh, "disk_usage", lambda p: SimpleNamespace(total=1 << 30, used=1 << 30, free=1 << 20))
    monkeypatch.setattr(synth, "_synth", lambda *a: pytest.fail("rendered before the size was checked"))
    rc, line = _one_line(capfd, ["synth", tmp_path / "s", "--lights", "100", "--resolution", "64"])
    assert rc == 2 and "s: --lights 100 at --resolution 64: 100 images need up to 2.44 MiB, more than the 1 MiB free " \
        "on its file system" in line, line
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- --rank in a read-only capture
def test_rank_in_a_read_only_capture_says_the_basis_is_not_kept(cap, tmp_path, capfd, monkeypatch):
    """``relight --rank K`` computed the compressed basis in memory only, silently, where it could not
    keep it (mocked read-only: root ignores permissions); in a writable capture it keeps it, as
    ``render`` does."""
    import ffls.errors
    from ffls.relight.compress import COMPRESSED_FILENAME

    c = tmp_path / "cap"
    shutil.copytree(cap, c)
    real = ffls.errors.os.access
    monkeypatch.setattr(ffls.errors.os, "access", lambda p, mode: False if Path(p) == c else real(p, mode))
    capfd.readouterr()
    assert main(["relight", str(c), "--probe", "sky", "--rank", "3", "-o", str(tmp_path / "a.exr")]) == 0
    err = capfd.readouterr().err
    assert (f"ffls relight: the compressed basis (rank 3) was computed in memory and not kept in {c} ("
            in err and "it is computed again on every run" in err), err
    assert not (c / COMPRESSED_FILENAME).exists()
    monkeypatch.setattr(ffls.errors.os, "access", real)
    assert main(["relight", str(c), "--probe", "sky", "--rank", "3", "-o", str(tmp_path / "a.exr")]) == 0
    assert "computed in memory" not in capfd.readouterr().err
    assert (c / COMPRESSED_FILENAME).is_file()


def test_tiles_in_a_read_only_capture_say_where_the_store_can_go(cap, tmp_path, capfd, monkeypatch):
    """``relight --tiles`` in a read-only capture named the folder without saying that ``--store``
    puts the store elsewhere (round 10's leftover; mocked: root ignores permissions)."""
    import ffls.store.ingest

    real = ffls.store.ingest.os.access
    monkeypatch.setattr(ffls.store.ingest.os, "access", lambda p, mode: False if Path(p) == cap else real(p, mode))
    rc, line = _one_line(capfd, ["relight", cap, "--probe", "sky", "--tiles", "--workers", "1", "-o",
                                 tmp_path / "a.exr"])
    assert rc == 2 and f"{cap}: folder is not writable" in line and "with --store DIR.zarr" in line, line
    assert not (cap / "field.zarr").exists() and list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- standard output, Ctrl-C
@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
@pytest.mark.parametrize("buffered", [False, True])
def test_full_standard_output_is_one_line_naming_it(tmp_path, buffered):
    """``ffls lightmap info sky > /dev/full`` said "file: no space left"; ``ffls --help > /dev/full``
    lost the text with status 0 (argparse ignores the error), or printed "Exception ignored"."""
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONUNBUFFERED="" if buffered else "1")
    with open("/dev/full", "w") as full:
        for argv in ([["lightmap", "info", "sky"]] if buffered else [["relight", "--help"], ["--version"]]):
            p = subprocess.run([sys.executable, "-m", "ffls", *argv], env=env, stdout=full, stderr=subprocess.PIPE,
                               text=True, timeout=120)
            lines = p.stderr.strip().splitlines()
            assert p.returncode == 2 and len(lines) == 1, p.stderr
            assert "error: standard output: cannot write (no space left on the device" in lines[0], lines


def test_ctrl_c_before_the_command_runs_is_one_line(capfd, monkeypatch):
    """Ctrl-C while the parser was built (0.4 s of every start) was a KeyboardInterrupt traceback."""
    import ffls.cli

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(ffls.cli, "_build", interrupted)
    capfd.readouterr()
    try:
        rc = main(["lightmap", "info", "sky"])
    except KeyboardInterrupt:  # (what reached the user as a traceback; here a failure, not pytest's own Ctrl-C)
        pytest.fail("the interrupt escaped main")
    assert rc == 130
    assert capfd.readouterr().err == "ffls: interrupted; nothing was done\n"


def test_interrupt_leaves_no_asyncio_lines(tmp_path):
    """Ctrl-C during ``ffls ingest`` left zarr's pending writes, which asyncio logged at exit after the
    one line ("Task was destroyed but it is pending!"); a command that leaves a pending task and is
    interrupted stands for it (the real one depends on timing)."""
    script = tmp_path / "pending.py"
    script.write_text(
        "import asyncio, sys\n"
        "import ffls.commands.lightmap as lm\n"
        "from ffls.cli import main\n"
        "def run(args):\n"
        "    loop = asyncio.new_event_loop()\n"
        "    async def forever():\n"
        "        await asyncio.sleep(3600)\n"
        "    async def start():\n"
        "        loop.create_task(forever())\n"
        "        await asyncio.sleep(0)\n"
        "    loop.run_until_complete(start())\n"
        "    raise KeyboardInterrupt\n"
        "lm.run = run\n"
        "sys.exit(main(['lightmap', 'make', 'sky', sys.argv[1]]))\n")
    p = subprocess.run([sys.executable, str(script), str(tmp_path / "m.exr")], stderr=subprocess.PIPE, text=True,
                       timeout=120)
    assert p.returncode == 130 and p.stderr == "ffls lightmap: interrupted; nothing partial was left\n", p.stderr
