"""A normal lens declared orthographic is noticed from the spheres' outlines
(``ffls.spheres.perspective``): one line, and the cones widened; a long lens is not flagged.

i-user15: a 46 deg lens declared ``{"model": "orthographic"}`` gave lights 16.74 / 19.91 deg off,
none inside its cone, without a word (docs/formats.md).
"""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from ffls.spheres.detect import silhouette_px
from ffls.spheres.perspective import perspective_outlines


def outline_fit(f_px: float, offset_px, size=(384, 384), radius_px=22.0, noise_px=0.25, seed=0):
    """An orthographic fit's outline points of a sphere seen through a pinhole of focal ``f_px``,
    centred ``offset_px`` (dx, dy) from the image centre, with ``noise_px`` of edge noise."""
    H, W = size
    K = np.array([[f_px, 0, (W - 1) / 2], [0, f_px, (H - 1) / 2], [0, 0, 1.0]])
    dist = 20.0 * f_px / 450.0  # scene units: the depth keeps the pixel radius near radius_px
    R = radius_px * dist / f_px
    C = np.array([offset_px[0] * dist / f_px, offset_px[1] * dist / f_px, dist])
    pts = silhouette_px(K, None, C, R, n=150)
    rng = np.random.default_rng(seed)
    pts = pts + noise_px * rng.standard_normal(pts.shape)
    c = pts.mean(axis=0)
    return SimpleNamespace(camera_model="orthographic", edge_px=pts, coverage=1.0, center_px=c,
                           radius_px=float(np.mean(np.linalg.norm(pts - c, axis=1))), residual_px=noise_px)


OFFSETS = [(-110.0, 60.0), (100.0, -50.0)]


@pytest.mark.parametrize("seed", range(5))
def test_normal_lens_outlines_are_flagged(seed):
    fits = [outline_fit(450.0, o, seed=seed + 10 * k) for k, o in enumerate(OFFSETS)]
    ev = perspective_outlines(fits, (384, 384))
    assert ev.detected, ev.z
    true_deg = [np.degrees(np.arctan(np.hypot(*o) / 450.0)) for o in OFFSETS]
    # the widening bounds each sphere's angle off the axis (the orthographic model's error)
    assert all(a >= 0.8 * t for a, t in zip(ev.angles_deg, true_deg)), (ev.angles_deg, true_deg)
    assert 300 < ev.focal_px < 650
    assert "K" in ev.note("cap/capture.json") and "cap/capture.json" in ev.note("cap/capture.json")


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("f_px", [4500.0, 1e7])
def test_long_lens_outlines_are_not_flagged(seed, f_px):
    fits = [outline_fit(f_px, o, seed=seed + 10 * k) for k, o in enumerate(OFFSETS)]
    ev = perspective_outlines(fits, (384, 384))
    assert not ev.detected, ev.z
    assert ev.note("capture.json") is None and ev.angles_deg == [0.0, 0.0]


def test_one_sphere_off_the_axis_is_enough():
    ev = perspective_outlines([outline_fit(450.0, (120.0, 70.0))], (384, 384))
    assert ev.detected and ev.angles_deg[0] > 12.0


def test_pinhole_fits_are_not_measured():
    fit = outline_fit(450.0, OFFSETS[0])
    fit.camera_model = "pinhole"
    ev = perspective_outlines([fit], (384, 384))
    assert not ev.detected and ev.shapes == [None]


def test_lights_of_a_normal_lens_declared_orthographic(tmp_path, capsys):
    """End to end: the one line names capture.json and K, and the cones hold the truth."""
    from ffls.cli import main

    cap = tmp_path / "cap"
    assert main(["synth", str(cap), "--spheres", "2", "--sphere-material", "grey", "--lights", "8",
                 "--resolution", "384", "--format", "exr", "--quiet"]) == 0
    doc = json.loads((cap / "capture.json").read_text())
    doc["camera"] = {"model": "orthographic", "world_from_camera": doc["camera"]["world_from_camera"]}
    (cap / "capture.json").write_text(json.dumps(doc))
    capsys.readouterr()
    out = tmp_path / "lights.json"
    assert main(["lights", str(cap), "--workers", "1", "--no-progress", "-o", str(out)]) == 0
    err = capsys.readouterr().err
    line = [ln for ln in err.splitlines() if "declared orthographic" in ln]
    assert len(line) == 1 and "capture.json" in line[0] and '"K"' in line[0], err
    truth = json.loads((cap / "truth.json").read_text())
    got = json.loads(out.read_text())["lights"]
    ok = [(e, np.asarray(t)) for e, t in zip(got, truth["directions"]) if e["status"] == "ok"]
    assert len(ok) >= 6
    errs = [np.degrees(np.arccos(np.clip(np.dot(e["direction"], t), -1, 1))) for e, t in ok]
    covered = [err_ <= e["uncertainty_deg"] for err_, (e, _) in zip(errs, ok)]
    assert max(errs) > 5.0  # the wrong model's error is real ...
    assert np.mean(covered) >= 0.9, (errs, [e["uncertainty_deg"] for e, _ in ok])  # ... and now inside
    assert all(e["orthographic_misfit_deg"] > 5.0 for e, _ in ok)
