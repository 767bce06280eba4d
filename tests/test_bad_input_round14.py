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

from cli_lines import child_env, tiny_capture
from cli_lines import one_line as _one_line

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r14"), seed=14)


def _entries(folder: Path) -> set:
    return {p.name for p in folder.iterdir()}


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
    from ffls.cli import main

    root = tmp_path_factory.mktemp("r14set") / "set"
    assert main(["synth", str(root), "--composite-set", "sunrise", "--lights", "8", "--surface-lights", "8",
                 "--resolution", "24", "--truth-dirs", "32", "--quiet"]) == 0
    return root


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
    assert (s / name).read_bytes() == before and _entries(s) == _entries(cset)


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
