"""Bad input found by the round-10 tester (briefs s10/test10, docs/reliability.md "Round 10").

Each case failed on main: a huge photo decoded before its size was refused, grey photos silently
replicated among colour ones, flags silently meaning something else, disk-full lines naming
temporary files, and library noise after the one line. The promise checked is the one of
``tests/test_bad_input.py``: exit status 2, one stderr line naming the flag or file, nothing left.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from cli_lines import one_line as _one_line
from ffls.cli import main
from ffls.errors import InputError
from ffls.io.images import read_image, write_png


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    from ffls.synth.scene import write_synthetic_capture

    root = tmp_path_factory.mktemp("r10")
    write_synthetic_capture(root / "cap", n_lights=12, resolution=24, progress=False, seed=3)
    return root / "cap"


def _edited(cap: Path, dst: Path, index: int, name: str, pixels) -> Path:
    """A copy of ``cap`` whose photo ``index`` is replaced by ``name`` holding ``pixels``."""
    import cv2

    shutil.copytree(cap, dst)
    assert cv2.imwrite(str(dst / name), pixels)
    doc = json.loads((dst / "capture.json").read_text())
    (dst / doc["images"][index]).unlink()
    doc["images"][index] = name
    (dst / "capture.json").write_text(json.dumps(doc))
    return dst


# ----------------------------------------------------------------------------- photo headers
def test_photo_of_another_size_is_refused_from_its_header(cap, tmp_path, capfd, monkeypatch):
    """A 12000x12000 PNG took 7 s and 2.6 GB to decode before its size was refused: the header says it."""
    import cv2

    big = _edited(cap, tmp_path / "big", 3, "big.png", np.full((600, 800, 3), 40, np.uint8))

    def no_decoding(*a, **k):
        raise AssertionError("a photo was decoded before its size was checked")

    monkeypatch.setattr(cv2, "imdecode", no_decoding)
    for argv in (["lights", big, "-o", tmp_path / "l.json", "--workers", "1", "--no-progress"],
                 ["relight", big, "--probe", "sky", "--lights", cap / "lights.json", "-o", tmp_path / "a.exr"]):
        rc, line = _one_line(capfd, argv)
        assert rc == 2 and "big.png: image is 800x600 but capture.json says image_size 24x24" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big"]


def test_photo_size_against_the_first_photo_without_image_size(cap, tmp_path):
    from ffls.io.capture import load_capture

    c = _edited(cap, tmp_path / "c", 5, "odd.png", np.full((20, 24, 3), 40, np.uint8))
    doc = json.loads((c / "capture.json").read_text())
    del doc["image_size"]
    (c / "capture.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"odd.png: image is 24x20 but the first image 'img_0000.exr' is 24x24"):
        load_capture(c)


@pytest.mark.parametrize("grey", [np.full((24, 24), 30000, np.uint16), np.full((24, 24, 1), 30000, np.uint16)])
def test_grey_photo_among_colour_ones_is_refused(cap, tmp_path, capfd, grey):
    """A grey photo among colour ones was replicated to RGB silently (a colourless light)."""
    g = _edited(cap, tmp_path / "g", 4, "grey.png", grey)
    out = tmp_path / "a.exr"
    rc, line = _one_line(capfd, ["relight", g, "--probe", "sky", "--lights", cap / "lights.json",
                                 "--lights-map", json.dumps({"img_0004.exr": "grey.png"}), "-o", out])
    assert rc == 2 and "grey.png: is grey (one channel) but 11 of the 12 photos are colour" in line, line
    assert not out.exists()


def _grey_copy(cap: Path, g: Path, colour: int | None = None) -> Path:
    """A copy of ``cap`` at ``g`` whose photos are 16-bit grey PNGs ``p{k}.png``, photo ``colour`` (if
    given) written as the same grey in three channels."""
    import cv2

    shutil.copytree(cap, g)
    doc = json.loads((g / "capture.json").read_text())
    for k, name in enumerate(doc["images"]):
        px = read_image(g / name).pixels
        grey = (np.clip(px.mean(axis=-1), 0, 1) * 65535).astype(np.uint16)
        assert cv2.imwrite(str(g / f"p{k}.png"), grey if k != colour else np.repeat(grey[..., None], 3, axis=-1))
        doc["images"][k] = f"p{k}.png"
    (g / "capture.json").write_text(json.dumps(doc))
    return g


def test_colour_photo_among_grey_ones_names_the_colour_one(cap, tmp_path):
    """The minority is named: one colour photo in a grey capture is the odd one."""
    from ffls.io.capture import load_capture

    g = _grey_copy(cap, tmp_path / "g", colour=7)
    with pytest.raises(InputError, match=r"p7.png: is colour but 11 of the 12 photos are grey"):
        load_capture(g)


def test_all_grey_capture_is_read(cap, tmp_path):
    """Grey throughout is a choice, not a mistake: replicated to RGB as before."""
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import load_photos

    g = _grey_copy(cap, tmp_path / "g")
    photos = load_photos(load_capture(g), progress=False)
    assert photos.shape == (12, 24, 24, 3) and np.array_equal(photos[..., 0], photos[..., 2])


def test_image_header_reads_sizes_and_channels_without_decoding(tmp_path, monkeypatch):
    import cv2

    from ffls.io.images import ImageHeader, image_header, write_exr, write_hdr

    write_png(tmp_path / "c.png", np.zeros((5, 7, 3), np.uint8))
    write_png(tmp_path / "g.png", np.zeros((5, 7), np.uint8))
    assert cv2.imwrite(str(tmp_path / "g16.tif"), np.zeros((5, 7), np.uint16))
    assert cv2.imwrite(str(tmp_path / "c16.tif"), np.zeros((5, 7, 3), np.uint16))
    assert cv2.imwrite(str(tmp_path / "g.jpg"), np.zeros((5, 7), np.uint8))
    write_exr(tmp_path / "c.exr", np.zeros((5, 7, 3), np.float32))
    write_hdr(tmp_path / "c.hdr", np.zeros((5, 7, 3), np.float32))
    monkeypatch.setattr(cv2, "imdecode", None)  # nothing is decoded
    for name, grey, bits in (("c.png", False, 8), ("g.png", True, 8), ("g16.tif", True, 16), ("c16.tif", False, 16),
                             ("g.jpg", True, 8), ("c.exr", False, None), ("c.hdr", False, None)):
        assert image_header(tmp_path / name) == ImageHeader(7, 5, grey, bits=bits), name
    (tmp_path / "bad.png").write_bytes(b"not a png")
    assert image_header(tmp_path / "bad.png") is None  # left to the decoder, which names the problem


# ----------------------------------------------------------------------------- flags
def test_first_pass_beyond_the_photos_is_refused(cap, tmp_path, capfd):
    """--first-pass 13 on 12 photos silently meant every photo."""
    out = tmp_path / "l.json"
    rc, line = _one_line(capfd, ["lights", cap, "--first-pass", "13", "--workers", "1", "-o", out])
    assert rc == 2 and "--first-pass 13 is more than the capture's 12 photos" in line, line
    rc, line = _one_line(capfd, ["lights", cap, "--first-pass", "4", "--bounce", "free", "--workers", "1", "-o", out])
    assert rc == 2 and "--first-pass applies only with --bounce calibrated" in line, line
    assert not out.exists()


def test_response_samples_are_bounded(tmp_path, capfd):
    """--samples 4000 ran OpenCV's Debevec solve for minutes; refused while parsing."""
    rc, line = _one_line(capfd, ["calibrate", "response", tmp_path, "--samples", "4000", "-o", tmp_path / "r.npy"])
    assert rc == 2 and "--samples" in line and "[10, 1000]" in line and "cube of the samples" in line, line


# ----------------------------------------------------------------------------- full disk
def test_writer_error_names_the_output_not_the_temporary(tmp_path):
    """A writer's error that names the temporary file (OpenEXR's "Failed to write pixel data to
    image file .a.x1y2.tmp.exr") names the user's output instead."""
    from ffls.errors import OutputError, atomic_folder, atomic_output

    out = tmp_path / "a.exr"
    with pytest.raises(OutputError) as e:
        with atomic_output(out) as tmp:
            raise OutputError(f'cannot write (failed to write "{tmp}")', tmp)
    assert str(e.value) == f'{out}: cannot write (failed to write "{out}")'
    folder = tmp_path / "frames"
    with pytest.raises(OutputError) as e:
        with atomic_folder(folder) as stage:
            with atomic_output(stage / "f.png") as tmp:
                raise OutputError("disk full", tmp)
    assert str(e.value) == f"{folder / 'f.png'}: disk full"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("what", ["exr", "frames", "synth", "mp4", "ingest"])
def test_real_full_disk_names_the_output(cap, tiny_tmpfs, capfd, what):
    """On a full disk the line named ``.a.x1y2.tmp.exr``, ``.frames.x1y2.tmp/frame_0000.png``,
    said "OpenCV cannot write mp4 here" or "file: no space left"."""
    import os

    fd = os.open(tiny_tmpfs / "filler", os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, b"\1" * 1024)
    except OSError:
        pass
    finally:
        os.close(fd)
    out = tiny_tmpfs / {"exr": "a.exr", "frames": "frames", "synth": "s", "mp4": "t.mp4", "ingest": "s.zarr"}[what]
    argv = {"exr": ["relight", cap, "--probe", "sky", "-o", out],
            "frames": ["render", cap, "--probe", "sky", "--cpu", "--turntable", "2", "-o", out],
            "mp4": ["render", cap, "--probe", "sky", "--cpu", "--turntable", "2", "-o", out],
            "synth": ["synth", out, "--lights", "4", "--resolution", "64", "--quiet"],
            "ingest": ["ingest", cap, "--store", out]}[what]
    capfd.readouterr()
    rc = main([str(a) for a in argv])
    _, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if "error" in ln]
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert f"error: {out}" in lines[0] and ".tmp" not in lines[0] and "disk full" in lines[0], lines[0]
    if what != "ingest":  # (an ingest keeps what it staged, for a resume; it says so)
        assert sorted(p.name for p in tiny_tmpfs.iterdir()) == ["filler"]


# ----------------------------------------------------------------------------- Dask
def _children(pid: int) -> list[int]:
    kids = []
    for t in Path(f"/proc/{pid}/task").glob("*/children"):
        kids += [int(k) for k in t.read_text().split()]
    return kids


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc to see the cluster's processes")
def test_ctrl_c_while_the_cluster_starts_is_one_line(tmp_path):
    """Ctrl-C while LocalCluster started printed, after the one line, "Exception ignored in atexit
    callback" (distributed's exit hook failed an assertion on the unstarted workers) and asyncio's
    "Task exception was never retrieved ... Nanny failed to start"."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from ffls.synth.scene import write_synthetic_capture

    cap = write_synthetic_capture(tmp_path / "cap", n_lights=12, resolution=96, progress=False, seed=3)["folder"]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    p = subprocess.Popen([sys.executable, "-m", "ffls", "lights", str(cap), "--scheduler", "local", "--workers", "2",
                          "--no-progress", "-o", str(tmp_path / "l.json")], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    t = time.monotonic()
    while not _children(p.pid) and p.poll() is None and time.monotonic() - t < 120:
        time.sleep(0.02)  # the first worker process exists: the cluster is starting
    time.sleep(0.3)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    lines = err.strip().splitlines()
    assert p.returncode == 130 and len(lines) == 1 and "interrupted" in lines[0], err
    assert not (tmp_path / "l.json").exists()


# ----------------------------------------------------------------------------- the table of round 10
@pytest.fixture(scope="module")
def ws(cap, tmp_path_factory):
    """Broken files beside the good capture ``cap``."""
    root = tmp_path_factory.mktemp("r10ws")
    w = {"cap": cap, "root": root}
    lights = (cap / "lights.json").read_text()
    (root / "deep.json").write_text("[" * 100000 + "]" * 100000)
    (root / "bigint.json").write_text(lights.replace('"version": 1', '"version": ' + "1" * 5000, 1))
    for name, text in (("cap_deep", "[" * 100000 + "]" * 100000),
                       ("cap_bigint", (cap / "capture.json").read_text().replace('"version": 1',
                                                                                   '"version": ' + "1" * 5000, 1))):
        shutil.copytree(cap, root / name)
        (root / name / "capture.json").write_text(text)
    br = root / "bracket"  # exposures.json nested too deep
    br.mkdir()
    for k in range(3):
        write_png(br / f"b{k}.png", np.full((16, 16, 3), 40 * (k + 1), np.uint8))
    (br / "exposures.json").write_text('{"a":' * 50000 + "1" + "}" * 50000)
    from ffls.io.images import write_exr

    write_exr(root / "neg.exr", -np.ones((32, 64, 3), np.float32))
    (root / "json_as.lp").write_text(lights)  # each kind of lights file under the other's extension
    names = [it["image"] for it in json.loads(lights)["lights"]]
    (root / "lp_as.json").write_text(f"{len(names)}\n" + "".join(f"{n} 0 0 1\n" for n in names))
    rng = np.random.default_rng(1)
    for ext in ("png", "jpg"):  # valid headers, the data cut in half
        import cv2

        assert cv2.imwrite(str(root / f"whole.{ext}"), rng.integers(0, 255, (40, 48, 3), dtype=np.uint8))
        data = (root / f"whole.{ext}").read_bytes()
        (root / f"cut.{ext}").write_bytes(data[: len(data) // 2])
    return w


L10 = ["relight", "{cap}", "--probe", "sky"]
CASES10 = [
    # JSON that Python's parser fails on with a traceback (RecursionError; a 4300-digit ValueError)
    ("lights-json-deep", L10 + ["--lights", "{root}/deep.json", "-o", "{out}/a.exr"], "deep.json: corrupt JSON: nested"),
    ("lights-json-bigint", L10 + ["--lights", "{root}/bigint.json", "-o", "{out}/a.exr"],
     "bigint.json: corrupt JSON: a number of more than 4300 digits"),
    ("capture-json-deep", ["relight", "{root}/cap_deep", "--probe", "sky", "-o", "{out}/a.exr"],
     "capture.json: corrupt JSON: nested"),
    ("capture-json-bigint", ["relight", "{root}/cap_bigint", "--probe", "sky", "-o", "{out}/a.exr"],
     "capture.json: corrupt JSON: a number of more"),
    ("lights-map-deep", L10 + ["--lights-map", '{"a":' + "[" * 100000 + "]" * 100000 + "}", "-o", "{out}/a.exr"],
     "--lights-map: not valid JSON (corrupt JSON: nested"),
    ("exposures-json-deep", ["calibrate", "response", "{root}/bracket", "-o", "{out}/r.npy"],
     "exposures.json: cannot read exposures (corrupt JSON: nested"),
    # a truncated PNG/JPEG was called "a sample format OpenCV does not read"
    ("mask-png-truncated", L10 + ["--mask", "{root}/cut.png", "-o", "{out}/a.png"],
     "cut.png: cannot decode PNG image: its 48x40 header is valid but the data is corrupt or truncated"),
    ("mask-jpg-truncated", L10 + ["--mask", "{root}/cut.jpg", "-o", "{out}/a.png"],
     "cut.jpg: cannot decode JPEG image: its 48x40 header is valid but the data is corrupt or truncated"),
    # a turntable into a still's file was refused after its coverage lines (two lines)
    ("render-turntable-png", ["render", "{cap}", "--probe", "sky", "--cpu", "--turntable", "2", "-o", "{out}/t.png"],
     "t.png: --turntable writes a video (.mp4) or a folder of PNGs (no extension), not .png"),
    # abbreviated flags: --light (render's) was "ambiguous" in relight, --exp silently --exposure
    ("relight-abbrev-light", L10 + ["--light", "10,45", "-o", "{out}/a.png"], "unrecognized arguments: --light"),
    ("relight-abbrev-exp", L10 + ["--exp", "2", "-o", "{out}/a.png"], "unrecognized arguments: --exp 2"),
    ("calibrate-abbrev", ["calibrate", "response", "{root}/bracket", "--samp", "20", "-o", "{out}/r.npy"],
     "unrecognized arguments: --samp 20"),
    # a negative value after a space, and the integer wording
    ("render-rotate-negative", ["render", "{cap}", "--probe", "sky", "--cpu", "--rotate", "-90,0,0", "-o",
                                "{out}/a.png"], "given as --rotate=-90,0,0"),
    ("render-rank-hex", ["render", "{cap}", "--probe", "sky", "--cpu", "--rank", "0x3", "-o", "{out}/a.png"],
     "expected an integer, not '0x3'"),
    # an empty path (an unset shell variable) was the working folder: synth wrote there, relight read its capture.json
    ("synth-empty-out", ["synth", "", "--lights", "2", "--resolution", "8"], "argument OUT_DIR: empty path"),
    ("relight-empty-capture", ["relight", "", "--probe", "sky", "-o", "{out}/a.png"], "argument capture: empty path"),
    ("lightmap-info-empty", ["lightmap", "info", ""], "argument map: empty path"),
    ("probe-empty-folder", ["probe", "mirror", "", "-o", "{out}/m.exr"], "argument FOLDER: empty path"),
    ("relight-empty-out", L10 + ["-o", ""], "argument -o/--out: empty path"),
    # a map of negative values only was "black everywhere", its negative pixels unsaid
    ("probe-all-negative", L10[:3] + ["{root}/neg.exr", "-o", "{out}/a.exr"],
     "black everywhere: it lights nothing (2048 pixels were negative and clamped to 0"),
    # view --probe of a missing or bad map rendered black with status 0 (the error only in the panel)
    ("view-probe-missing", ["view", "{cap}", "--headless", "--frames", "1", "--probe", "{root}/nope.exr"],
     "nope.exr: light map not found"),
    ("view-probe-negative", ["view", "{cap}", "--headless", "--frames", "1", "--probe", "{root}/neg.exr"],
     "neg.exr: the light map is black everywhere"),
    # a lights file of the other kind than its extension: a bare parse error
    ("lights-json-named-lp", L10 + ["--lights", "{root}/json_as.lp", "-o", "{out}/a.exr"],
     "its text is JSON (a lights.json?): name it .json"),
    ("lights-lp-named-json", L10 + ["--lights", "{root}/lp_as.json", "-o", "{out}/a.exr"],
     "its text is an RTI .lp file"),
    # --lights-map '[]' was looked for as a file ("[]: lights map not found")
    ("lights-map-list", L10 + ["--lights-map", '["a"]', "-o", "{out}/a.exr"],
     "--lights-map: expected a non-empty JSON object"),
    # lights onto capture.json was refused only after every fit
    ("lights-onto-capture", ["lights", "{cap}", "--workers", "1", "-o", "{cap}/capture.json"],
     "capture.json: refusing to overwrite an input"),
]


@pytest.mark.parametrize("argv,names", [pytest.param(a, n, id=i) for i, a, n in CASES10])
def test_round10_bad_input_is_one_line(ws, tmp_path, capfd, monkeypatch, argv, names):
    import ffls.spheres.estimate

    def no_fit(*a, **k):
        raise AssertionError("the lights were fitted before the output was checked")

    monkeypatch.setattr(ffls.spheres.estimate, "estimate_lights", no_fit)
    out = tmp_path / "out"
    out.mkdir()
    keys = {k: str(v) for k, v in ws.items()}
    args = [a if a.startswith(('{"a"', '["')) else a.format(out=out, **keys) for a in argv]
    before = {p: sorted(q.name for q in p.iterdir()) for p in (out, ws["cap"], ws["root"])}
    rc, line = _one_line(capfd, args)
    assert rc == 2 and "error" in line and names in line, line
    for p, names_before in before.items():  # nothing written, no temporary left
        assert sorted(q.name for q in p.iterdir()) == names_before, p


def test_lights_into_a_read_only_capture_is_refused_before_the_fits(cap, capfd, monkeypatch):
    """The default output CAP/lights.json in a read-only folder was refused after every fit
    (mocked: root ignores permissions)."""
    import ffls.errors
    import ffls.spheres.estimate

    def no_fit(*a, **k):
        raise AssertionError("the lights were fitted before the output was checked")

    real = ffls.errors.os.access
    monkeypatch.setattr(ffls.errors.os, "access", lambda p, mode: False if Path(p) == cap else real(p, mode))
    monkeypatch.setattr(ffls.spheres.estimate, "estimate_lights", no_fit)
    rc, line = _one_line(capfd, ["lights", cap, "--workers", "1"])
    assert rc == 2 and f"{cap}: folder is not writable" in line, line


def test_store_in_a_read_only_folder_is_one_line(cap, tmp_path, capfd, monkeypatch):
    """An ingest into a read-only folder said "cannot write the store (read-only file system); the
    unfinished store is kept" of a store that was never made (mocked: root ignores permissions)."""
    import ffls.store.ingest

    real = ffls.store.ingest.os.access
    monkeypatch.setattr(ffls.store.ingest.os, "access",
                        lambda p, mode: False if Path(p) == tmp_path else real(p, mode))
    rc, line = _one_line(capfd, ["ingest", cap, "--store", tmp_path / "s.zarr"])
    assert rc == 2 and f"{tmp_path}: folder is not writable" in line, line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("ext", ["exr", "hdr", "png"])
def test_image_beyond_the_memory_is_refused_from_its_header(tmp_path, capfd, monkeypatch, ext):
    """A light map too large for the memory was decoded until the system ran out of it; now its
    header is enough (the memory made small here instead of the map huge)."""
    import cv2

    import ffls.errors
    from ffls.io.images import write_exr, write_hdr

    m = np.ones((32, 64, 3), np.float32)
    {"exr": write_exr, "hdr": write_hdr, "png": lambda p, a: write_png(p, (a * 255).astype(np.uint8))}[ext](
        tmp_path / f"m.{ext}", m)
    monkeypatch.setattr(ffls.errors, "available_memory", lambda: 32 * 64 * 10)
    monkeypatch.setattr(cv2, "imdecode", None)  # nothing is decoded
    with pytest.raises(InputError, match=rf"m.{ext}: a 64x32 image needs about .* GiB to decode, more than the"):
        read_image(tmp_path / f"m.{ext}")


def test_utf8_bom_is_no_content(cap, tmp_path, capfd):
    """A UTF-8 BOM (Windows Notepad writes one) made lights.json, capture.json and .lp files
    unreadable: "Unexpected UTF-8 BOM (decode using utf-8-sig)", "expected the number of lights"."""
    bom = b"\xef\xbb\xbf"
    c = tmp_path / "cap"
    shutil.copytree(cap, c)
    (c / "capture.json").write_bytes(bom + (cap / "capture.json").read_bytes())
    (c / "lights.json").write_bytes(bom + (cap / "lights.json").read_bytes())
    lights = json.loads((cap / "lights.json").read_text())["lights"]
    lp = "".join(f"{it['image']} 0 0 1\n" for it in lights)
    (tmp_path / "l.lp").write_bytes(bom + f"{len(lights)}\n{lp}".encode())
    for extra in ([], ["--lights", tmp_path / "l.lp"]):
        capfd.readouterr()
        assert main([str(a) for a in ["relight", c, "--probe", "sky", *extra, "-o", tmp_path / "a.exr"]]) == 0, \
            capfd.readouterr().err
