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
