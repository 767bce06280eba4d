"""Round 17's leftovers (briefs s17/atk17b, docs/reliability.md "Round 17b").

Input the round-17 attack found read without a word: an ``.lp`` file that is not UTF-8, a
``--memory`` budget above the machine's memory, ``lights.json`` ``frame`` keys, masks whose
values are not a mask's, and the Ctrl-C line after a finished output. The promise checked is the
one of ``tests/test_bad_input.py``: exit status 2, one stderr line naming the flag or file,
nothing left.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from cli_lines import entries, one_line, tiny_capture


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r17b"), seed=171)


# ----------------------------------------------------------------------------- an .lp file not in UTF-8
def test_an_lp_file_in_latin1_is_refused_as_not_utf8(cap, tmp_path, capfd):
    """``im\\xe9.exr`` saved by a Windows tool in latin-1 was decoded with U+FFFD and the command
    then failed on the name (``image 'im\\ufffd.exr' is not in the capture``)."""
    lp = tmp_path / "lat.lp"
    lp.write_bytes(b"1\nim\xe9.exr 0 0 1\n")
    before = entries(tmp_path)
    rc, line = one_line(capfd, ["relight", cap, "--lights", lp, "--probe", "sky", "-o", tmp_path / "o.png"])
    assert rc == 2
    assert "lat.lp" in line and "not UTF-8" in line and "\ufffd" not in line
    assert entries(tmp_path) == before


# ----------------------------------------------------------------------------- --memory above the machine
def test_a_memory_budget_above_the_machines_memory_is_refused(cap, tmp_path, capfd):
    """``--memory 1T`` on a 24 GiB machine was read as no limit (the photos held in memory)."""
    from ffls.errors import physical_memory

    have = physical_memory()
    if have is None:
        pytest.skip("this system does not say its memory")
    size = f"{have // 2 ** 20 + 1024}M"
    rc, line = one_line(capfd, ["relight", cap, "--probe", "sky", "-o", tmp_path / "o.png", "--memory", size])
    assert rc == 2
    assert "--memory" in line and size in line and "memory this machine has" in line
    assert not (tmp_path / "o.png").exists()


# ----------------------------------------------------------------------------- lights.json frame
def _lights_with_frame(cap, tmp_path, frame) -> Path:
    import json

    from ffls.io.capture import load_lights

    doc = load_lights(cap / "lights.json").to_json()
    doc["frame"] = frame
    out = tmp_path / "lf.json"
    out.write_text(json.dumps(doc))
    return out


_POSE = [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]]


@pytest.mark.parametrize("frame, key, words", [
    ({"world_from_camera": [[1, 0, 0, 1e308], *_POSE[1:]]}, "frame.world_from_camera", "beyond any number"),
    ({"world_from_camera": [[1, 0, 0, 1e200], [0, -1, 0, 1e200], [0, 0, -1, 0], [0, 0, 0, 1]]},
     "frame.world_from_camera", "beyond any number"),
    ({"world_from_camera": _POSE, "sorce": "mine"}, "frame.sorce", "did you mean 'source'"),
    ({"world_from_camera": _POSE, "tilt_uncertainty": 2.0}, "frame.tilt_uncertainty", "did you mean"),
    ({"world_from_camera": _POSE, "tilt_uncertainty_deg": "abc"}, "frame.tilt_uncertainty_deg", "finite number"),
    ({"world_from_camera": _POSE, "tilt_uncertainty_deg": -1.0}, "frame.tilt_uncertainty_deg", "0 to 180"),
    ({"world_from_camera": _POSE, "source": 3}, "frame.source", "string"),
])
def test_a_lights_frame_is_checked_as_the_other_blocks(cap, tmp_path, capfd, frame, key, words):
    """A translation of 1e308 and unknown or wrong-typed keys of ``frame`` were read without a word
    (only the pose's rotation was checked)."""
    lf = _lights_with_frame(cap, tmp_path, frame)
    rc, line = one_line(capfd, ["relight", cap, "--lights", lf, "--probe", "sky", "-o", tmp_path / "o.png",
                                "--workers", "1"])
    assert rc == 2
    assert f"lf.json: {key}" in line and words in line, line
    assert not (tmp_path / "o.png").exists()


def test_a_lights_frame_as_ffls_writes_it_is_read(cap, tmp_path):
    """The guard: the keys ``ffls lights`` writes, a null error (not measured), an ``x-`` key of
    the user's and a translation of a real pose are read as before."""
    from ffls.io.capture import load_lights

    frame = {"world_from_camera": [[1, 0, 0, 2.5], [0, -1, 0, -1e3], [0, 0, -1, 0], [0, 0, 0, 1]],
             "source": "the camera's tilt fitted to the spheres' shading", "tilt_uncertainty_deg": None,
             "x-note": "mine"}
    lights = load_lights(_lights_with_frame(cap, tmp_path, frame))
    assert lights.frame["world_from_camera"][1, 3] == -1e3 and lights.frame["x-note"] == "mine"


# ----------------------------------------------------------------------------- --mask values
def _relight_mask(cap, tmp_path, capfd, mask):
    from ffls.cli import main

    capfd.readouterr()
    rc = main([str(a) for a in ["relight", cap, "--probe", "sky", "-o", tmp_path / "o.png", "--workers", "1",
                                "--mask", mask]])
    err = capfd.readouterr().err
    assert "Traceback" not in err
    return rc, [ln for ln in err.splitlines() if ln.strip() and "coverage: " not in ln]


def test_a_float_photo_as_mask_is_refused(cap, tmp_path, capfd):
    """A float EXR whose values run past 1 on most pixels (a photo) was clipped to a "mask"."""
    import numpy as np

    from ffls.io.images import read_image, write_exr

    photo = read_image(cap / "img_0000.exr").pixels
    mask = tmp_path / "photo.exr"
    write_exr(mask, photo / np.median(photo) * 2)  # (half its pixels past 1)
    rc, lines = _relight_mask(cap, tmp_path, capfd, mask)
    assert rc == 2 and len(lines) == 1, lines
    assert "photo.exr" in lines[0] and "outside 0..1" in lines[0] and "is it a photo?" in lines[0]
    assert not (tmp_path / "o.png").exists()


def test_a_grey_mask_is_said_to_be_read_as_a_soft_one(cap, tmp_path, capfd):
    """A 0.7 grey TIFF was read as a 70% opaque object without a word."""
    import cv2
    import numpy as np

    from ffls.io.images import read_image

    h, w = read_image(cap / "img_0000.exr").pixels.shape[:2]
    mask = tmp_path / "grey.tif"
    cv2.imwrite(str(mask), np.full((h, w), 178, np.uint8))
    rc, lines = _relight_mask(cap, tmp_path, capfd, mask)
    assert rc == 0
    assert any("grey.tif has no white pixel" in ln and "soft mask" in ln for ln in lines), lines


def test_a_mask_with_soft_edges_reads_without_a_note(cap, tmp_path, capfd):
    """The guard: a binary mask, anti-aliased at its edges and resampled with a filter's ringing past
    0..1 on a few pixels, is read as before, without a note."""
    import numpy as np
    from scipy import ndimage

    from ffls.io.images import read_image, write_exr

    h, w = read_image(cap / "img_0000.exr").pixels.shape[:2]
    m = np.zeros((h, w), np.float32)
    m[h // 4: 3 * h // 4, w // 4: 3 * w // 4] = 1
    m = ndimage.gaussian_filter(m, 0.5)  # (an anti-aliased edge)
    m[h // 4, w // 4: w // 4 + 5] = 1.05  # (ringing on 5 pixels)
    mask = tmp_path / "soft.exr"
    write_exr(mask, np.repeat(m[..., None], 3, axis=-1))
    rc, lines = _relight_mask(cap, tmp_path, capfd, mask)
    assert rc == 0
    assert not any("mask" in ln for ln in lines), lines


# ----------------------------------------------------------------------------- Ctrl-C after the output
@pytest.mark.parametrize("extra", [[], ["--mask", None]])
def test_a_ctrl_c_just_after_the_output_is_renamed_names_it(cap, tmp_path, capfd, monkeypatch, extra):
    """A Ctrl-C arriving as ``ffls relight`` renamed its image (at ~1.6 s) said "interrupted;
    nothing partial was left", status 130, of a whole output. The signal is sent by the rename
    itself (deterministic, not timed): the line now names the complete output."""
    import os
    import signal

    import cv2
    import numpy as np

    from ffls.io.images import read_image

    out = tmp_path / "o.png"
    if extra:
        h, w = read_image(cap / "img_0000.exr").pixels.shape[:2]
        extra = ["--mask", tmp_path / "m.png"]
        cv2.imwrite(str(extra[1]), np.full((h, w), 255, np.uint8))
    real = os.replace

    def replace(src, dst, **kw):
        real(src, dst, **kw)
        if os.path.basename(dst) == "o.png":
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(os, "replace", replace)
    rc, line = one_line(capfd, ["relight", cap, "--probe", "sky", "-o", out, "--workers", "1", *extra])
    assert rc == 130, line
    assert line == f"ffls relight: interrupted; {out} was written whole before it; nothing partial was left"
    assert out.exists() and read_image(out).pixels.shape[:2] == read_image(cap / "img_0000.exr").pixels.shape[:2]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["o.png", *(["m.png"] if extra else [])])


def test_a_ctrl_c_before_the_rename_still_says_nothing_partial(cap, tmp_path, capfd, monkeypatch):
    """The guard: interrupted before its output is renamed, the command leaves nothing and says so."""
    import os

    real = os.replace

    def replace(src, dst, **kw):
        if os.path.basename(dst) == "o.png":
            raise KeyboardInterrupt
        real(src, dst, **kw)

    monkeypatch.setattr(os, "replace", replace)
    rc, line = one_line(capfd, ["relight", cap, "--probe", "sky", "-o", tmp_path / "o.png", "--workers", "1"])
    assert rc == 130 and line == "ffls relight: interrupted; nothing partial was left"
    assert list(tmp_path.iterdir()) == []
