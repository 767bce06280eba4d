"""Bad input found by the round-12 tester (briefs s12/test12, docs/reliability.md "Round 12").

Round 11's leftovers (EXIF orientation, Ctrl-C while ``ffls.cli`` imports, standard output closed
at start) and a fresh attack on the newest flags and on every command. The promise checked is the
one of ``tests/test_bad_input.py``: exit status 2, one stderr line naming the flag or file,
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

from cli_lines import child_env, composite_set, tiny_capture
from cli_lines import one_line as _one_line
from ffls.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r12"), seed=4)


# ----------------------------------------------------------------------------- EXIF orientation
def _save_oriented(path: Path, rgb8: np.ndarray, orientation: int) -> Path:
    """``rgb8`` stored as is, with an EXIF orientation tag (Pillow writes it for JPEG, PNG, TIFF)."""
    from PIL import Image

    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(rgb8).save(path, exif=exif, **({"quality": 100} if path.suffix == ".jpg" else {}))
    return path


@pytest.mark.parametrize("suffix", [".jpg", ".png", ".tif"])
def test_exif_orientation_is_applied_as_viewers_do(tmp_path, suffix):
    """A JPEG or PNG tagged "turned" was read as stored (OpenCV's IMREAD_UNCHANGED), unlike every
    viewer and unlike a TIFF (which OpenCV turns itself); the header gave the stored size."""
    import cv2

    from ffls.io.images import image_header, read_image, read_mask

    rgb = np.zeros((20, 40, 3), np.uint8)
    rgb[:5, :10] = 255  # a white block in the stored top-left corner
    for turn in range(1, 9):
        p = _save_oriented(tmp_path / f"o{turn}{suffix}", rgb, turn)
        img = read_image(p)
        shown = cv2.imdecode(np.fromfile(p, np.uint8), cv2.IMREAD_COLOR)  # (OpenCV turns it with this flag)
        viewer = cv2.cvtColor(shown, cv2.COLOR_BGR2RGB)
        assert np.array_equal(img.codes, viewer), (turn, suffix)
        head = image_header(p)
        assert (head.height, head.width, head.orientation) == (*img.shape, turn), (turn, suffix)
        assert read_mask(p).shape == img.shape
    assert read_image(tmp_path / f"o6{suffix}").shape == (40, 20)


def test_png_alpha_is_turned_with_its_colour(tmp_path):
    from PIL import Image

    from ffls.io.images import read_image

    rgba = np.zeros((4, 6, 4), np.uint8)
    rgba[..., 3] = 255
    rgba[0, 0] = (255, 0, 0, 128)
    exif = Image.Exif()
    exif[0x0112] = 8
    Image.fromarray(rgba).save(tmp_path / "a.png", exif=exif)
    img = read_image(tmp_path / "a.png")
    assert img.shape == (6, 4) and img.pixels[5, 0, 0] == 1.0 and img.alpha[5, 0] == pytest.approx(128 / 255)


#: How a photo shown upright is stored under the EXIF orientations these tests use
_STORED = {1: lambda a: a, 3: lambda a: a[::-1, ::-1], 6: lambda a: np.rot90(a, 1)}


def _png_capture(cap: Path, dst: Path, turns) -> Path:
    """``cap``'s photos as 8-bit sRGB PNGs stored turned back and tagged ``turns``, so each shows as the original."""
    from ffls.io.images import read_image
    from ffls.radiance.encoding import srgb_encode

    dst.mkdir()
    doc = json.loads((cap / "capture.json").read_text())
    names = []
    for k, (name, turn) in enumerate(zip(doc["images"], turns)):
        code = np.round(srgb_encode(np.clip(read_image(cap / name).pixels, 0, 1)) * 255).astype(np.uint8)
        names.append(f"img_{k:04d}.png")
        _save_oriented(dst / names[-1], np.ascontiguousarray(_STORED[turn](code)), turn)
    doc["images"], doc["encoding"] = names, "srgb"
    (dst / "capture.json").write_text(json.dumps(doc))
    return dst


def test_a_capture_of_turned_photos_reads_as_shown(cap, tmp_path):
    """Photos stored turned, tagged so that they show upright, read as the upright capture."""
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import load_photo

    c = load_capture(_png_capture(cap, tmp_path / "c", [6] * 6))
    ref = load_capture(_png_capture(cap, tmp_path / "ref", [1] * 6))
    assert c.image_size == ref.image_size == (24, 24)
    assert np.array_equal(load_photo(c, 2), load_photo(ref, 2))


def test_a_capture_mixing_orientations_is_refused(cap, tmp_path, capfd):
    """One photo tagged "rotated 180 degrees" among upright ones kept its size: it was read as stored
    (so it matched by chance); shown as viewers show it, it would be upside down among the others."""
    c = _png_capture(cap, tmp_path / "c", [1, 1, 3, 1, 1, 1])
    rc, line = _one_line(capfd, ["relight", c, "--probe", "sky", "-o", tmp_path / "a.exr"])
    assert rc == 2 and "img_0002.png: its EXIF orientation is 3 (rotated 180 degrees) but 5 of the 6 photos are 1 " \
        "(upright (as stored), e.g. 'img_0000.png')" in line, line
    assert not (tmp_path / "a.exr").exists()


# ----------------------------------------------------------------------------- Ctrl-C while importing
def test_console_script_imports_nothing_before_it_can_answer_ctrl_c():
    """The console script imported ``ffls.cli`` (0.05 to 0.1 s of imports) before any handler ran."""
    import tomllib

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["ffls"] == "ffls.__main__:main"
    code = "import sys, ffls.__main__; print(sorted(m for m in sys.modules if m.startswith(('ffls', 'numpy'))))"
    out = subprocess.run([sys.executable, "-c", code], env=child_env(), capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "['ffls', 'ffls.__main__']", out


def test_ctrl_c_while_the_cli_imports_is_one_line(tmp_path):
    """A real SIGINT (Python's default handler) while ``ffls.cli`` is imported: a traceback before."""
    script = tmp_path / "early.py"
    script.write_text(
        "import os, signal, sys\n"
        "class Interrupting:\n"  # (the signal lands inside the import, as a Ctrl-C in its first 0.1 s)
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'ffls.commands':\n"
        "            os.kill(os.getpid(), signal.SIGINT)\n"
        "        return None\n"
        "sys.meta_path.insert(0, Interrupting())\n"
        "sys.argv = ['ffls', 'lightmap', 'info', 'sky']\n"
        "from ffls.__main__ import main\n"
        "sys.exit(main())\n")
    p = subprocess.run([sys.executable, str(script)], env=child_env(), capture_output=True, text=True, timeout=60)
    assert p.returncode == 130 and p.stderr == "ffls: interrupted; nothing was done\n", p.stderr


# ----------------------------------------------------------------------------- standard output closed
@pytest.mark.parametrize("argv", [["lightmap", "info", "sky"], ["lights", "{cap}", "--workers", "1", "-o", "{out}"],
                                  ["--help"]])
def test_closed_standard_output_is_refused_before_anything_runs(cap, tmp_path, argv):
    """``ffls lights CAP -o x.json >&-`` (and every command) ran, lost its result lines and said 0."""
    out = tmp_path / "x.json"
    args = [a.format(cap=cap, out=out) for a in argv]
    p = subprocess.run([sys.executable, "-m", "ffls", *args], env=child_env(), stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE, text=True, timeout=120, preexec_fn=lambda: os.close(1))
    assert p.returncode == 2 and p.stderr.splitlines() == [
        "ffls: error: standard output: is closed, and the command's results are printed there; nothing was done "
        "(give >/dev/null to discard them)"], p.stderr
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- composite --fill
@pytest.fixture(scope="module")
def cset(tmp_path_factory):
    """A small composite set whose object capture states its spheres' world centres (as --fill reads them)."""
    return composite_set(tmp_path_factory.mktemp("r12set"))


@pytest.mark.parametrize("edit,names", [
    (lambda d, c: d.__setitem__("spheres", [{"center": c[0]}] * len(c)),
     "spheres[0].center and spheres[1].center are 0 apart, less than sphere_radius 0.05: spheres of that radius "
     "would overlap"),
    (lambda d, c: d.__setitem__("sphere_radius", 50.0), "less than sphere_radius 50: spheres of that radius"),
    (lambda d, c: d.__setitem__("sphere_radius", 1e300), "less than sphere_radius 1e+300"),
    (lambda d, c: d["spheres"][1].__setitem__("center", [c[1][0], c[1][1], c[1][2] - 10.0]),
     "spheres[1].center [0.25, -0.25, -9.95] projects to pixel ("),
    (lambda d, c: d["spheres"][2].__setitem__("center", [1e300, 0.0, 0.0]), "spheres[2].center [1e+300, 0, 0]"),
], ids=["one-centre-for-all", "radius-50", "radius-1e300", "one-10m-below", "centre-1e300"])
def test_fill_refuses_stated_spheres_that_cannot_be_the_photos(cset, tmp_path, capfd, edit, names):
    """``composite --fill`` took ``capture.json``'s sphere centres and radius as stated: overlapping
    spheres or a centre off the photos gave a composite (status 0), 1e300 numpy's overflow warnings."""
    obj = tmp_path / "object"
    shutil.copytree(cset / "object", obj)
    doc = json.loads((obj / "capture.json").read_text())
    centres = json.loads((obj / "truth.json").read_text())["sphere_centers"]
    doc["spheres"] = [{"center": c} for c in centres]
    edit(doc, centres)
    (obj / "capture.json").write_text(json.dumps(doc))
    out = tmp_path / "out"
    out.mkdir()
    rc, line = _one_line(capfd, ["composite", "--object", obj, "--surface", cset / "surface", "--lightmap", "sunrise",
                                 "--background", cset / "background.exr", "--mask", cset / "object_mask.png",
                                 "--surface-mask", cset / "surface_mask.png", "--fill", "model", "-o", out / "c.exr"])
    assert rc == 2 and f"{obj}/capture.json: --fill: " in line and names in line, line
    assert list(out.iterdir()) == []


# ----------------------------------------------------------------------------- FIFOs and devices
@pytest.fixture(scope="module")
def specials(cap, tmp_path_factory):
    """FIFOs where files are read (each would be waited on forever), and a copy of the capture whose
    capture.json, and another whose photo, is a FIFO."""
    root = tmp_path_factory.mktemp("r12fifo")
    for name in ("fifo.json", "fifo.lp", "fifo.png", "fifo.exr"):
        os.mkfifo(root / name)
    for sub, name in (("cap_fifo_json", "capture.json"), ("cap_fifo_photo", "img_0002.exr")):
        shutil.copytree(cap, root / sub)
        (root / sub / name).unlink()
        os.mkfifo(root / sub / name)
    br = root / "bracket"
    br.mkdir()
    os.mkfifo(br / "b0.jpg")
    return root


FIFO = "is a FIFO (named pipe), not a regular file"
R12 = ["relight", "{cap}", "--probe", "sky", "-o", "{out}/a.exr"]
SPECIAL_CASES = [
    ("lights-fifo-json", R12 + ["--lights", "{root}/fifo.json"], f"fifo.json: {FIFO} (lights.json expected)"),
    ("lights-fifo-lp", R12 + ["--lights", "{root}/fifo.lp"], f"fifo.lp: {FIFO}"),
    ("lights-map-fifo", R12 + ["--lights-map", "{root}/fifo.json"], f"fifo.json: {FIFO} (lights map expected)"),
    ("mask-fifo", R12 + ["--mask", "{root}/fifo.png"], f"fifo.png: {FIFO}"),
    ("probe-fifo", ["relight", "{cap}", "--probe", "{root}/fifo.exr", "-o", "{out}/a.exr"], f"fifo.exr: {FIFO}"),
    ("capture-json-fifo", ["relight", "{root}/cap_fifo_json", "--probe", "sky", "-o", "{out}/a.exr"],
     f"capture.json: {FIFO} (capture.json expected)"),
    ("capture-photo-fifo", ["relight", "{root}/cap_fifo_photo", "--probe", "sky", "-o", "{out}/a.exr"],
     f"capture.json: images: listed image 'img_0002.exr' {FIFO}"),
    ("bracket-photo-fifo", ["calibrate", "response", "{root}/bracket", "-o", "{out}/r.npy"], f"b0.jpg: {FIFO}"),
    # /dev/zero was read until the memory ran out ("out of memory; ask for a smaller size")
    ("lights-dev-zero", R12 + ["--lights", "/dev/zero"], "/dev/zero: is a character device, not a regular file"),
    ("lights-map-dev-zero", R12 + ["--lights-map", "/dev/zero"], "/dev/zero: is a character device"),
    # an output onto a FIFO or a device: the atomic rename replaced it with a regular file
    ("output-onto-fifo", ["lightmap", "make", "sky", "{root}/fifo.exr", "--height", "8"],
     f"fifo.exr: {FIFO}: ffls writes an output beside its path and renames it there, which would replace it"),
]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
@pytest.mark.parametrize("argv,names", [pytest.param(a, n, id=i) for i, a, n in SPECIAL_CASES])
def test_fifos_and_devices_are_one_line(cap, specials, tmp_path, capfd, argv, names):
    """Each hung forever on a FIFO (a blocking read), or ran out of memory on /dev/zero; an output
    onto a FIFO (or, as root, ``-o /dev/null``) replaced it with a regular file."""
    out = tmp_path / "out"
    out.mkdir()
    args = [a.format(out=out, cap=cap, root=specials) for a in argv]
    before = sorted((p.name, p.stat().st_mode) for p in specials.iterdir())
    rc, line = _one_line(capfd, args)
    assert rc == 2 and "error" in line and names in line, line
    assert list(out.iterdir()) == [] and sorted((p.name, p.stat().st_mode) for p in specials.iterdir()) == before


def test_an_output_onto_a_device_is_refused(tmp_path, capfd):
    """``-o /dev/null`` as root replaced the device with a file (tried on a copy of the node where mknod is allowed)."""
    from ffls.errors import OutputError, check_output_path

    node = tmp_path / "null.exr"
    try:
        os.mknod(node, 0o666 | __import__("stat").S_IFCHR, os.makedev(1, 3))
    except (PermissionError, OSError):
        pytest.skip("mknod is not allowed here")
    with pytest.raises(OutputError, match="is a character device, not a regular file"):
        check_output_path(node)
    rc, line = _one_line(capfd, ["lightmap", "make", "sky", node, "--height", "8"])
    assert rc == 2 and "null.exr: is a character device" in line and node.is_char_device(), line


# ----------------------------------------------------------------------------- probe diffuse --ground
@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    from ffls.lightmaps.lightmap import builtin_lightmap
    from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe

    sc = diffuse_sphere_scene(builtin_lightmap("studio").downsample(8), resolution=32, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("r12ball") / "ball", sc)


def test_a_huge_plane_normal_is_a_direction(ball, tmp_path, capfd):
    """``plane.normal`` [1e308, 1e308, 1e308]: its norm overflowed, the normal became zero, and
    ``probe diffuse --ground`` ended in a ValueError traceback."""
    from ffls.io.probe import load_probe

    p = tmp_path / "p"
    shutil.copytree(ball, p)
    doc = json.loads((p / "probe.json").read_text())
    doc["plane"] = {"point": [0, 0, 0], "normal": [1e308, 1e308, 1e308]}
    (p / "probe.json").write_text(json.dumps(doc))
    np.testing.assert_allclose(load_probe(p).plane.normal, np.full(3, 3 ** -0.5))
    assert main(["probe", "diffuse", str(p), "-o", str(tmp_path / "m.exr"), "--size", "8", "--sources", "9",
                 "--ground"]) == 0
    assert "Traceback" not in capfd.readouterr().err


def test_nothing_poorly_seen_says_no_more(ball, tmp_path, capfd):
    """At a coarse map every direction is seen: the line went on "(confidence <= 0.2; the map there
    is the method's extrapolation)" about no direction."""
    capfd.readouterr()
    assert main(["probe", "diffuse", str(ball), "-o", str(tmp_path / "m.exr"), "--size", "4", "--sources", "9"]) == 0
    lines = [ln for ln in capfd.readouterr().err.splitlines() if "poorly seen" in ln]
    assert lines == ["ffls probe: poorly seen: none (every direction seen)"], lines


# ----------------------------------------------------------------------------- empty path values
_COMPOSITE = ["composite", "--object", "o", "--surface", "s", "--lightmap", "sky", "--background", "b.exr", "--mask",
              "m.png", "--surface-mask", "sm.png", "-o", "{out}/c.exr"]


@pytest.mark.parametrize("argv,flag", [
    (_COMPOSITE[:2] + [""] + _COMPOSITE[3:], "--object"),  # (was the working folder: a capture there was used)
    (_COMPOSITE[:4] + [""] + _COMPOSITE[5:], "--surface"),
    (_COMPOSITE[:6] + [""] + _COMPOSITE[7:], "--lightmap"),
    (_COMPOSITE[:8] + [""] + _COMPOSITE[9:], "--background"),
    (_COMPOSITE[:10] + [""] + _COMPOSITE[11:], "--mask"),
    (_COMPOSITE[:12] + [""] + _COMPOSITE[13:], "--surface-mask"),
    (["render", "{cap}", "--probe", "sky", "--cpu", "--store", "", "-o", "{out}/a.exr"], "--store"),  # (ran, status 0)
    (["relight", "{cap}", "--probe", "sky", "--tiles", "--store", "", "-o", "{out}/a.exr"], "--store"),  # (named '.')
    (["ingest", "{cap}", "--store", ""], "--store"),
    (["calibrate", "camera", "b.png", "--capture", ""], "--capture"),
], ids=["composite-object", "composite-surface", "composite-lightmap", "composite-background", "composite-mask",
        "composite-surface-mask", "render-store", "relight-store", "ingest-store", "calibrate-capture"])
def test_an_empty_path_value_is_refused(cap, tmp_path, capfd, argv, flag):
    """An empty value (an unset shell variable) is refused as every positional path and -o already are."""
    out = tmp_path / "out"
    out.mkdir()
    rc, line = _one_line(capfd, [a.format(out=out, cap=cap) for a in argv])
    assert rc == 2 and f"argument {flag}: empty path" in line, line
    assert list(out.iterdir()) == []


def test_an_image_size_of_the_stored_layout_names_the_orientation(cap, tmp_path, capfd):
    """A capture.json written for the stored (unturned) size: the refusal says why the sizes differ."""
    c = _png_capture(cap, tmp_path / "c", [6] * 6)
    for k in range(6):  # stored 32 wide and 24 high, tagged 6: shown 24 wide and 32 high
        _save_oriented(c / f"img_{k:04d}.png", np.full((24, 32, 3), 100, np.uint8), 6)
    doc = json.loads((c / "capture.json").read_text())
    doc["image_size"] = [32, 24]
    (c / "capture.json").write_text(json.dumps(doc))
    rc, line = _one_line(capfd, ["relight", c, "--probe", "sky", "-o", tmp_path / "a.exr"])
    assert rc == 2 and "img_0000.png: image is 24x32 but capture.json says image_size 32x24 (as shown: its EXIF " \
        "orientation 6, turned 90 degrees clockwise, turns the stored 32x24; docs/formats.md)" in line, line


def test_closed_standard_error_keeps_its_lines_out_of_the_results(tmp_path):
    """``ffls lightmap info nope.exr 2>&- > out.txt``: the error line went into out.txt (print's
    fallback for a missing stderr is standard output); now it is dropped, the status says 2."""
    p = subprocess.run([sys.executable, "-m", "ffls", "lightmap", "info", str(tmp_path / "nope.exr")],
                       env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, timeout=120,
                       preexec_fn=lambda: os.close(2))
    assert p.returncode == 2 and p.stdout == "", p.stdout


@pytest.mark.parametrize("cmd", ["calibrate", "merge"])
def test_a_bracket_mixing_orientations_is_refused(tmp_path, capfd, cmd):
    """A bracket shot from a tripod whose middle photo is tagged "rotated 180 degrees": it kept its size,
    and was read as stored; shown as viewers show it, it would be upside down against the others."""
    br = tmp_path / "br"
    br.mkdir()
    rng = np.random.default_rng(1)
    base = rng.integers(20, 120, (16, 16, 3), dtype=np.uint8)
    for k, turn in enumerate((1, 3, 1)):
        _save_oriented(br / f"b{k}.png", np.clip(base.astype(int) * (k + 1), 0, 255).astype(np.uint8), turn)
    (br / "exposures.json").write_text('{"b0.png": 0.01, "b1.png": 0.02, "b2.png": 0.04}')
    argv = (["calibrate", "response", br, "-o", tmp_path / "r.npy"] if cmd == "calibrate" else
            ["probe", "merge", br / "b0.png", br / "b1.png", br / "b2.png", "--exposures", "0.01,0.02,0.04",
             "--encoding", "srgb", "-o", tmp_path / "m.exr"])
    rc, line = _one_line(capfd, argv)
    assert rc == 2 and "b1.png: its EXIF orientation is 3 (rotated 180 degrees) but 2 of the 3 bracketed " in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["br"]


def test_a_singular_system_counts_its_unknowns():
    """``probe diffuse --sources 100000 --ground`` said "1396 pixels for 98012 unknowns (99406 sources
    + ground)": the sources that light no pixel were left out without a word."""
    from ffls.errors import InputError
    from ffls.probes.linear import solve_sources

    M = np.zeros((3, 6))
    M[:, :4] = np.random.default_rng(0).random((3, 4))  # 2 of the 6 sources light no pixel
    with pytest.raises(InputError, match=r"3 pixels for 4 unknowns \(6 sources; the 2 that light no pixel left "
                                         r"out\)"):
        solve_sources(M, np.ones(3), what="6 sources")


# ----------------------------------------------------------------- Radiance orientations (leftover)
#: Radiance's coordinates: (0, 0) is the picture's lower left, +X right, +Y up. A resolution line
#: names the scanline axis (slow), then the pixel axis (fast), each with its direction.
_RADIANCE_LINES = ("-Y {h} +X {w}", "+Y {h} +X {w}", "-Y {h} -X {w}", "+Y {h} -X {w}",
                   "+X {w} -Y {h}", "+X {w} +Y {h}", "-X {w} -Y {h}", "-X {w} +Y {h}")


def _stored_scanlines(img: np.ndarray, line: str) -> np.ndarray:
    """The pixels of ``img`` (shown: top row first) in the order ``line`` stores them."""
    h, w = img.shape[:2]
    (a1, _, a2, _) = line.split()
    n1, n2 = (h if a1[1] == "Y" else w), (h if a2[1] == "Y" else w)
    out = np.empty((n1, n2, 3), img.dtype)
    for k1 in range(n1):
        for k2 in range(n2):
            coord = {}
            for axis, k, n in ((a1, k1, n1), (a2, k2, n2)):
                coord[axis[1]] = k if axis[0] == "+" else n - 1 - k
            out[k1, k2] = img[h - 1 - coord["Y"], coord["X"]]  # row 0 is the top (+Y up)
    return out


@pytest.mark.parametrize("line", _RADIANCE_LINES)
def test_radiance_files_of_every_orientation_read_as_shown(tmp_path, capfd, line):
    """Radiance allows 8 orientations; OpenCV reads only ``-Y H +X W`` and called the others
    "corrupt, truncated or not a HDR file". They are read turned to the standard layout."""
    import cv2

    from ffls.io.images import image_header, read_image, write_hdr

    img = np.random.default_rng(7).uniform(0.01, 4.0, size=(6, 12, 3)).astype(np.float32)
    shown = read_image(write_hdr(tmp_path / "std.hdr", img), working_space=False).pixels  # RGBE-rounded
    stored = _stored_scanlines(shown, line)
    cv2.imwrite(str(tmp_path / "s.hdr"), np.ascontiguousarray(stored[:, :, ::-1]))  # BGR
    data = (tmp_path / "s.hdr").read_bytes()
    standard = f"-Y {stored.shape[0]} +X {stored.shape[1]}".encode()
    assert data.count(standard) == 1
    p = tmp_path / "turned.hdr"
    p.write_bytes(data.replace(standard, line.format(h=6, w=12).encode()))
    got = read_image(p, working_space=False)
    np.testing.assert_array_equal(got.pixels, shown)
    head = image_header(p)
    assert (head.width, head.height) == (12, 6)
    assert main(["lightmap", "info", str(p)]) == 0
    assert "corrupt" not in capfd.readouterr().err


# ----------------------------------------------------------------- POCS time estimate (leftover)
def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


@pytest.mark.parametrize("flags, said", [
    (["--iterations", "100000"], "estimate: adaptive sources, --scheme least-power, 100000 sweeps, "),
    (["--sources", "grid", "--grid", "256", "--size", "256", "--iterations", "100000"],
     "estimate: --sources grid --grid 256 (131072 unknowns), --scheme sequential, 100000 sweeps, "),
    (["--sources", "grid", "--grid", "256", "--size", "256", "--scheme", "dykstra"],
     "--sources grid --grid 256 (131072 unknowns), --scheme dykstra: a linear programme over "),
    (["--sources", "grid", "--grid", "256", "--size", "256", "--scheme", "least-power"],
     "--sources grid --grid 256 (131072 unknowns), --scheme least-power: a linear programme over "),
])
def test_a_long_pocs_says_its_estimate_before_it_starts(ball, tmp_path, capfd, monkeypatch, flags, said):
    """``probe pocs --iterations 100000`` (and a 256-row grid with least-power or dykstra) ran for
    minutes without a word. The estimate is said once the probe is read, before the solve (which
    is interrupted here, as a user's Ctrl-C: the line is already out and nothing is written)."""
    import ffls.probes.singh_ahuja as sa

    monkeypatch.setattr(sa, "adaptive_singh_ahuja", _interrupt)
    monkeypatch.setattr(sa, "singh_ahuja", _interrupt)
    out = tmp_path / "m.exr"
    assert main(["probe", "pocs", str(ball), "-o", str(out), *flags]) == 130
    err = capfd.readouterr().err
    line = err.splitlines()[0]
    assert line.startswith("ffls probe: " + said) and " on a 2-core machine" in line, line
    assert line.endswith("Ctrl-C stops it and writes nothing"), line
    assert not out.exists()


def test_a_short_pocs_says_no_estimate(ball, tmp_path, capfd):
    assert main(["probe", "pocs", str(ball), "-o", str(tmp_path / "m.exr"), "--size", "8"]) == 0
    assert "estimate" not in capfd.readouterr().err
