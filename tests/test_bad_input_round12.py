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

from cli_lines import one_line as _one_line
from ffls.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    from ffls.synth.scene import write_synthetic_capture

    root = tmp_path_factory.mktemp("r12")
    write_synthetic_capture(root / "cap", n_lights=6, resolution=24, progress=False, seed=4)
    return root / "cap"


def _child_env():
    return dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT))


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
    out = subprocess.run([sys.executable, "-c", code], env=_child_env(), capture_output=True, text=True, timeout=60)
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
    p = subprocess.run([sys.executable, str(script)], env=_child_env(), capture_output=True, text=True, timeout=60)
    assert p.returncode == 130 and p.stderr == "ffls: interrupted; nothing was done\n", p.stderr


# ----------------------------------------------------------------------------- standard output closed
@pytest.mark.parametrize("argv", [["lightmap", "info", "sky"], ["lights", "{cap}", "--workers", "1", "-o", "{out}"],
                                  ["--help"]])
def test_closed_standard_output_is_refused_before_anything_runs(cap, tmp_path, argv):
    """``ffls lights CAP -o x.json >&-`` (and every command) ran, lost its result lines and said 0."""
    out = tmp_path / "x.json"
    args = [a.format(cap=cap, out=out) for a in argv]
    p = subprocess.run([sys.executable, "-m", "ffls", *args], env=_child_env(), stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE, text=True, timeout=120, preexec_fn=lambda: os.close(1))
    assert p.returncode == 2 and p.stderr.splitlines() == [
        "ffls: error: standard output: is closed, and the command's results are printed there; nothing was done "
        "(give >/dev/null to discard them)"], p.stderr
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- composite --fill
@pytest.fixture(scope="module")
def cset(tmp_path_factory):
    """A small composite set whose object capture states its spheres' world centres (as --fill reads them)."""
    root = tmp_path_factory.mktemp("r12set") / "set"
    assert main(["synth", str(root), "--composite-set", "sunrise", "--lights", "16", "--surface-lights", "16",
                 "--resolution", "32", "--truth-dirs", "64", "--quiet"]) == 0
    return root


@pytest.mark.parametrize("edit,names", [
    (lambda d, c: d.__setitem__("spheres", [{"center": c[0]}] * len(c)),
     "spheres[0].center and spheres[1].center are 0 apart, less than sphere_radius 0.05: spheres of that radius "
     "would overlap"),
    (lambda d, c: d.__setitem__("sphere_radius", 50.0), "less than sphere_radius 50: spheres of that radius"),
    (lambda d, c: d.__setitem__("sphere_radius", 1e300), "less than sphere_radius 1e+300"),
    (lambda d, c: d["spheres"][1].__setitem__("center", [c[1][0], c[1][1], c[1][2] - 10.0]),
     "spheres[1].center [ 0.25 -0.25 -9.95] projects to pixel ("),
    (lambda d, c: d["spheres"][2].__setitem__("center", [1e300, 0.0, 0.0]), "spheres[2].center [1.e+300 0.e+00"),
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
