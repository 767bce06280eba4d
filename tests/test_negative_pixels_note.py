"""A relit still whose pixels sum below zero says so in one line (the EXR keeps them; the PNG shows black)."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.cli import main
from ffls.commands.common import negative_pixels_note
from ffls.io.images import read_image


def test_the_note_counts_pixels_with_any_negative_channel():
    hdr = np.ones((4, 5, 3), np.float32)
    assert negative_pixels_note(hdr, "x.exr") == ""
    hdr[0, 0, 2] = -1e-3
    hdr[3, 4] = -2.0
    note = negative_pixels_note(hdr, "x.exr")
    assert note.startswith("2 of 20 pixels (10%) are negative") and note.endswith("kept as they are")
    assert negative_pixels_note(hdr, "x.png").endswith("black in the PNG")


@pytest.fixture(scope="module")
def few_lights(tmp_path_factory):
    root = tmp_path_factory.mktemp("neg")
    assert main(["synth", str(root / "cap"), "--lights", "6", "--resolution", "48"]) == 0
    return root


@pytest.mark.parametrize("weighting", ["voronoi", "kriging"])
def test_relight_reports_negative_pixels_when_and_only_when_the_exr_has_them(few_lights, weighting, capsys):
    out = few_lights / f"{weighting}.exr"
    capsys.readouterr()
    assert main(["relight", str(few_lights / "cap"), "--probe", "sunrise", "--weighting", weighting,
                 "-o", str(out)]) == 0
    err = capsys.readouterr().err
    n = int(np.count_nonzero(np.any(read_image(out).pixels < 0, axis=-1)))
    if weighting == "kriging":
        assert n > 0  # six lights: the kriging weights' negative lobes show
    assert (f"ffls relight: {n} of 2304 pixels" in err) == (n > 0)
    assert ("are negative" in err) == (n > 0)
