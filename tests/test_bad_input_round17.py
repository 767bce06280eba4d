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
