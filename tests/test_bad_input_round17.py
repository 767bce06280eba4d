"""Bad input found by the round-17 tester (briefs s17/atk17, docs/reliability.md "Round 17").

An attack of every command's flags at their extremes (empty, negative, NaN, inf, 1e308, wrong
type), every key of ``capture.json``, ``lights.json``, ``probe.json`` and ``.lp`` files (BOM, CRLF,
duplicate keys, unicode, 1e308), odd image files and output paths. The promise checked is the one
of ``tests/test_bad_input.py``: exit status 2, one stderr line naming the flag or file, nothing
left; and valid but unusual input read as meant (no silent change).
"""
from __future__ import annotations

import json
import shutil
import warnings

import numpy as np
import pytest

from cli_lines import entries, one_line, tiny_capture
from ffls.cli import main


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r17"), seed=17)


# ----------------------------------------------------------------------------- a hemisphere's axis
@pytest.mark.parametrize("axis, expected", [([0.0, 0.0, 1e308], (0.0, 0.0, 1.0)),
                                            ([0.0, -1e308, 1e308], (0.0, -0.5 ** 0.5, 0.5 ** 0.5)),
                                            ([1e-320, 0.0, 0.0], (1.0, 0.0, 0.0))])
def test_a_hemisphere_axis_of_any_finite_length_keeps_its_direction(axis, expected):
    """``{"axis": [0, 0, 1e308]}``: its norm overflowed to inf, the axis became (0, 0, 0) with
    numpy's overflow warning as the only word (``ffls lights`` then measured its coverage against
    no hemisphere); a subnormal axis was refused as all zero."""
    from ffls.conventions import as_hemisphere

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        h = as_hemisphere({"axis": axis})
    got = (0.0, 0.0, 1.0) if h == "upper" else h.axis
    np.testing.assert_allclose(got, expected, atol=1e-15)


def test_a_capture_hemisphere_axis_of_1e308_is_upper(cap, tmp_path):
    """The same through ``capture.json``."""
    from ffls.io.capture import load_capture

    c = tmp_path / "c"
    shutil.copytree(cap, c)
    doc = json.loads((c / "capture.json").read_text())
    doc["hemisphere"] = {"axis": [0, 0, 1e308]}
    (c / "capture.json").write_text(json.dumps(doc))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_capture(c).hemisphere == "upper"


# ----------------------------------------------------------------------------- synth --sphere-xy far off
@pytest.mark.parametrize("xy", ["1e308,0", "1e200,0", "1e30,0"])
def test_a_sphere_placed_beyond_the_pixels_a_float_holds_is_out_of_frame(tmp_path, capfd, xy):
    """``synth --sphere-xy 1e308,0``: ``OverflowError: cannot convert float infinity to integer``
    (1e200: ``Python int too large to convert to C long``), a traceback."""
    rc, line = one_line(capfd, ["synth", tmp_path / "s", "--quiet", "--lights", "3", "--resolution", "24",
                                f"--sphere-xy={xy}"])
    assert rc == 2 and "--sphere-xy" in line and "out of the frame" in line
    assert entries(tmp_path) == set()


# ----------------------------------------------------------------------------- probes
def test_a_probe_pose_beyond_any_number_is_one_line(tmp_path, capfd):
    """``probe.json`` ``camera.world_from_camera`` with a translation of 1e308: the ball's distance
    overflowed to inf and ``detect``'s ``ValueError: the sphere must lie in front of the camera``
    came out as a traceback."""
    from ffls.synth.probe import look_at, write_mirror_probe

    d = tmp_path / "p"
    m = np.random.default_rng(17).uniform(0.1, 1.0, (16, 32, 3)).astype(np.float32)
    K = np.array([[300.0, 0, 40], [0, 300.0, 40], [0, 0, 1]])
    write_mirror_probe(d, m, (80, 80), K=K, world_from_camera=look_at([0, -1.0, 0.2]), radius=0.1, supersample=1)
    doc = json.loads((d / "probe.json").read_text())
    doc["camera"]["world_from_camera"][0][3] = 1e308
    (d / "probe.json").write_text(json.dumps(doc))
    rc, line = one_line(capfd, ["probe", "mirror", d, "-o", tmp_path / "m.exr", "--size", "8"])
    assert rc == 2 and "probe.json" in line and "world_from_camera" in line and "beyond any number" in line
    assert not (tmp_path / "m.exr").exists()


@pytest.mark.parametrize("level, word", [(255, "saturated everywhere"), (0, "black everywhere")])
def test_probe_merge_of_a_bracket_that_recorded_nothing_is_refused(tmp_path, capfd, level, word):
    """``probe merge`` of a bracket clipped (or black) in every exposure wrote an HDR of lower bounds
    (or of zeros) with status 0; the same bracket in a probe folder was refused."""
    import cv2

    for i in range(2):
        cv2.imwrite(str(tmp_path / f"s{i}.png"), np.full((16, 16, 3), level, np.uint8))
    rc, line = one_line(capfd, ["probe", "merge", tmp_path / "s0.png", tmp_path / "s1.png", "-o", tmp_path / "h.exr",
                                "--exposures", "0.01,0.02", "--encoding", "srgb"])
    assert rc == 2 and "s0.png" in line and word in line
    assert not (tmp_path / "h.exr").exists()


def test_probe_merge_of_a_usable_bracket_is_written(tmp_path, capfd):
    """The guard's other side: a bracket with some pixels clipped in every exposure is merged."""
    import cv2

    rng = np.random.default_rng(17)
    for i, s in enumerate([1, 2]):
        a = np.clip(rng.random((16, 16, 3)) * 120 * s, 0, 255).astype(np.uint8)
        a[:2] = 255
        cv2.imwrite(str(tmp_path / f"b{i}.png"), a)
    assert main(["probe", "merge", str(tmp_path / "b0.png"), str(tmp_path / "b1.png"), "-o", str(tmp_path / "h.exr"),
                 "--exposures", "0.01,0.02", "--encoding", "srgb"]) == 0
    assert (tmp_path / "h.exr").exists()


# ----------------------------------------------------------------------------- exposures.json
@pytest.mark.parametrize("value, shown", [("0.01", '"0.01"'), (True, "true")])
def test_an_exposure_time_given_as_a_string_or_boolean_is_refused(tmp_path, capfd, value, shown):
    """``calibrate response``'s ``exposures.json`` with ``"r0.png": true`` was read as 1 s (the
    response came out 684 times too bright, status 0), ``"0.01"`` as 0.01 s: ``float()`` reads both."""
    import cv2

    g = np.linspace(0, 1, 64)[None, :, None] * np.ones((48, 1, 3))
    times = {}
    for i, s in enumerate([1, 2, 4, 8]):
        cv2.imwrite(str(tmp_path / f"r{i}.png"), np.clip(g * 80 * s, 0, 255).astype(np.uint8))
        times[f"r{i}.png"] = 0.01 * s
    times["r0.png"] = value
    (tmp_path / "exposures.json").write_text(json.dumps(times))
    rc, line = one_line(capfd, ["calibrate", "response", tmp_path, "-o", tmp_path / "c.npy"])
    assert rc == 2 and "exposures.json" in line and "r0.png" in line and f"{shown} is not a number" in line
    assert not (tmp_path / "c.npy").exists()
