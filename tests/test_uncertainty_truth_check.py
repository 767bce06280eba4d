"""benchmarks/bench_conditions.py --truth-check: the cone's parts against a render's truth.

Small hand-made stored runs (``lights_estimated.json`` with an error model, ``truth.json``) whose
spheres' errors are known: errors pointing away from the layout's centre cancel in the photo's
mean (negative correlation, photo variance below the independent-sphere variance); an error
shared by all spheres adds (positive correlation, above).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from ffls.conventions import normalize, spherical_to_direction
from ffls.spheres.uncertainty import ErrorModel

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_conditions  # noqa: E402  (benchmarks/bench_conditions.py)

CENTRES = np.array([[-0.25, -0.25, 0.05], [-0.25, 0.25, 0.05], [0.25, 0.25, 0.05], [0.25, -0.25, 0.05]])


def _tilt(d: np.ndarray, towards: np.ndarray, deg: float) -> np.ndarray:
    """``d`` turned by ``deg`` degrees towards the tangent part of ``towards``."""
    t = towards - (towards @ d) * d
    return normalize(np.cos(np.radians(deg)) * d + np.sin(np.radians(deg)) * normalize(t))


def _stored_run(folder: Path, radial_deg: float, common_deg: float, seed: int = 0) -> None:
    """A run of 60 distant lights over 4 spheres around the origin: each sphere's direction turned
    ``radial_deg`` away from the layout's centre, all turned ``common_deg`` along one photo-dependent
    axis, plus 0.05 deg of independent noise; the photo's direction is the spheres' mean."""
    rng = np.random.default_rng(seed)
    theta = np.radians(rng.uniform(10, 60, 60))
    phi = np.radians(rng.uniform(0, 360, 60))
    truth = spherical_to_direction(theta, phi)
    model = ErrorModel(scale=1.0, floor_deg=0.5, common_deg=0.3, source="disagreement", n_photos=60,
                       centre_deg=(0.0, 0.0, 0.0, 0.0), common_ratio=1.0 / 3.0)
    lights = []
    for t in truth:
        shared = rng.normal(size=3)
        dirs = []
        for c in CENTRES:
            away = np.array([c[0], c[1], 0.0])
            d = _tilt(_tilt(t, away, radial_deg), shared, common_deg)
            dirs.append(_tilt(d, rng.normal(size=3), abs(rng.normal(0.0, 0.05))))
        spheres = [{"status": "ok", "kind": "matte", "direction": d.tolist(), "sigma_deg": 0.1,
                    "center": c.tolist()} for d, c in zip(dirs, CENTRES)]
        lights.append({"direction": normalize(np.sum(dirs, axis=0)).tolist(), "status": "ok", "model": "distant",
                       "used_spheres": [0, 1, 2, 3], "spheres": spheres, "uncertainty_deg": 1.0})
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "lights_estimated.json").write_text(json.dumps({"lights": lights, "uncertainty": model.as_dict()}))
    (folder / "truth.json").write_text(json.dumps({"light_model": "distant", "directions": truth.tolist()}))
    (folder / "capture.json").write_text(json.dumps({"format": "ffls-capture", "version": 1}))


def test_errors_away_from_the_layout_centre_cancel_in_the_mean(tmp_path):
    _stored_run(tmp_path, radial_deg=1.0, common_deg=0.0)
    r = bench_conditions.truth_check(tmp_path)
    assert r["photos"] == 60
    assert r["pair_correlation"] < -0.25  # four errors that cancel: -1/3 at the limit
    assert r["photo_over_independent"] < 0.2
    assert r["away_share"] > 0.9 and r["away_mean_deg"] == pytest.approx(1.0, abs=0.05)
    assert r["centre_ratio"] is None  # no camera K: the centres cannot be compared


def test_a_shared_error_adds_in_the_mean(tmp_path):
    _stored_run(tmp_path, radial_deg=0.0, common_deg=1.0)
    r = bench_conditions.truth_check(tmp_path)
    assert r["pair_correlation"] > 0.9
    assert r["photo_over_independent"] > 1.5  # 1 deg shared against a 0.5 deg floor over 4 spheres
    assert r["away_share"] < 0.8
    # the independent part alone misses the shared error; the common-mode bound takes up part of it
    assert r["needed_factor_independent"] > 2.448
    assert r["needed_factor"] < r["needed_factor_independent"]


def test_without_photos_of_two_spheres_the_check_says_so(tmp_path):
    _stored_run(tmp_path, radial_deg=1.0, common_deg=0.0)
    doc = json.loads((tmp_path / "lights_estimated.json").read_text())
    for l in doc["lights"]:
        l["used_spheres"] = [0]
    (tmp_path / "lights_estimated.json").write_text(json.dumps(doc))
    assert bench_conditions.truth_check(tmp_path) == {"skipped": "no photo with 2+ spheres"}


def test_sphere_coverage_tells_cancelling_from_shared_errors(tmp_path):
    """Errors that cancel in the mean: each sphere's own cone holds its error no more often than the
    photo's does; a shared error: without the common mode the spheres' own cones miss it."""
    _stored_run(tmp_path / "away", radial_deg=1.0, common_deg=0.0)
    r = bench_conditions.truth_check(tmp_path / "away")
    assert r["photo_coverage"] == 1.0
    assert r["sphere_coverage_independent"] <= r["sphere_coverage"] <= 1.0
    # 1.5 deg shared by every sphere, beyond a sphere's own cone (2.448 x the 0.5 deg floor)
    _stored_run(tmp_path / "shared", radial_deg=0.0, common_deg=1.5)
    r = bench_conditions.truth_check(tmp_path / "shared")
    assert r["sphere_coverage_independent"] <= r["sphere_coverage"]
    assert r["sphere_coverage_independent"] < 0.5


def _budget_doc(n: int = 40):
    """A stored run of ``n`` equal photos with two matte spheres of unequal fit statistics (0.1 and
    2 deg RMS) under an error model with a floor, a common-mode bound and its floor (the photos'
    errors are passed to :func:`bench_conditions.cone_budget` apart)."""
    model = ErrorModel(scale=2.0, floor_deg=0.2, common_deg=0.2, source="disagreement", n_photos=n,
                       centre_deg=(0.0, 0.0), common_ratio=1.0 / 3.0, common_floor_deg=0.1, cone_factor=2.2)
    spheres = [{"status": "ok", "kind": "matte", "direction": [0.0, 0.0, 1.0], "sigma_deg": 0.1},
               {"status": "ok", "kind": "matte", "direction": [0.0, 0.0, 1.0], "sigma_deg": 2.0}]
    lights = [{"direction": [0.0, 0.0, 1.0], "status": "ok", "model": "distant", "used_spheres": [0, 1],
               "spheres": spheres, "uncertainty_deg": 1.0} for _ in range(n)]
    return {"lights": lights, "uncertainty": model.as_dict()}, model


def test_cone_budget_uses_the_combination_weights():
    """The budget's terms are those of the cone the photo got: the combination's weights (a matte
    sphere's statistics with the 1 deg floor), not the model's inverse variances, which give the
    precise sphere nearly all the weight and a fit term several times smaller."""
    doc, model = _budget_doc()
    ok = np.ones(len(doc["lights"]), dtype=bool)
    err = np.full(len(doc["lights"]), 0.3)
    b = bench_conditions.cone_budget(doc, doc["lights"], ok, err)
    stat = np.array([0.1, 2.0]) / np.sqrt(2.0)
    combination = 1.0 / (np.array([0.1, 2.0]) ** 2 + 1.0)  # photo.estimate_photo: the 1 deg matte floor
    want = model.budget(stat, np.array([0, 1]), combination)
    smallest = model.budget(stat, np.array([0, 1]))  # the inverse variances under the model
    assert b["weights"] == "combination"
    assert b["fit_deg"] == pytest.approx(want["fit_deg"])
    assert b["sigma_deg"] == pytest.approx(want["sigma_deg"])
    assert b["fit_deg"] > 3.0 * smallest["fit_deg"]
    assert b["stat_deg"] == pytest.approx(want["fit_deg"] / model.scale)
    assert b["cone_deg"] == pytest.approx(want["cone_deg"])
    assert b["common_bound_deg"] ** 2 + b["common_floor_deg"] ** 2 == pytest.approx(b["common_deg"] ** 2)
    # the cone holds the 0.3 deg error; every photo's cone is the same, so coverage is 0 or 1
    assert b["coverage_budget"] == 1.0
    assert set(b["coverage_without"]) == set(bench_conditions.WITHOUT)
    assert sum(b["share"].values()) == pytest.approx(1.0)


def test_cone_budget_coverage_without_each_part():
    """Leaving out a part narrows the cone by exactly that part: an error between the cone without
    the common mode and the whole cone is covered only with the common mode."""
    doc, model = _budget_doc()
    ok = np.ones(len(doc["lights"]), dtype=bool)
    b0 = bench_conditions.cone_budget(doc, doc["lights"], ok, np.zeros(len(doc["lights"])))
    f = model.cone_factor
    indep = np.sqrt(b0["sigma_deg"] ** 2 - b0["common_deg"] ** 2)
    err = np.full(len(doc["lights"]), f * 0.5 * (indep + b0["sigma_deg"]))  # between the two cones
    b = bench_conditions.cone_budget(doc, doc["lights"], ok, err)
    assert b["coverage_budget"] == 1.0
    assert b["coverage_without"]["common"] == 0.0
    assert b["needed_factor"] == pytest.approx(err[0] / b["sigma_deg"])


def test_self_measured_signals_beside_the_truth(tmp_path):
    """What a capture measures itself is reported beside the truth's measures (``i-cones17``): the
    spheres' disagreement, their fits' misfit and the common mode's share of the photos' cones.
    Errors that cancel in the mean and errors that add give the same misfit statistics here."""
    _stored_run(tmp_path / "away", radial_deg=1.0, common_deg=0.0)
    _stored_run(tmp_path / "shared", radial_deg=0.0, common_deg=1.0)
    for name in ("away", "shared"):
        doc = json.loads((tmp_path / name / "lights_estimated.json").read_text())
        for l in doc["lights"]:
            for s in l["spheres"]:
                s.update(inflation=2.0, rms=0.01, intensity=0.5)
        (tmp_path / name / "lights_estimated.json").write_text(json.dumps(doc))
    away = bench_conditions.truth_check(tmp_path / "away")
    shared = bench_conditions.truth_check(tmp_path / "shared")
    # each sphere 1 deg from the photo's mean (which the radial turns leave on the truth): radius 1
    assert away["disagreement_deg"] == pytest.approx(1.0 / 1.1774, rel=0.05)
    assert shared["disagreement_deg"] < 0.1  # the shared turn moves the mean with the spheres
    doc = json.loads((tmp_path / "away" / "lights_estimated.json").read_text())
    b = ErrorModel.from_dict(doc["uncertainty"]).budget(np.full(4, 0.1 / np.sqrt(2.0)), np.arange(4), np.ones(4))
    for r in (away, shared):
        assert r["inflation"] == 2.0 and r["relative_rms"] == pytest.approx(0.02)
        assert r["common_share"] == pytest.approx(b["common_deg"] ** 2 / b["sigma_deg"] ** 2, rel=0.02)
        assert r["photo_coverage_without_common"] <= r["photo_coverage"]
    # the shared 1 deg needs the common mode: without it the photos' cones miss more
    assert shared["photo_coverage_without_common"] < shared["photo_coverage"]


def test_truth_check_runs_on_named_folders(tmp_path, capsys):
    _stored_run(tmp_path / "cap", radial_deg=1.0, common_deg=0.0)
    out = tmp_path / "out.json"
    bench_conditions.main(["--truth-check", "--folders", str(tmp_path / "cap"), "--out", str(out)])
    rows = json.loads(out.read_text())["results"]
    assert [r["condition"] for r in rows] == ["cap"] and rows[0]["photos"] == 60
    assert "| cap |" in capsys.readouterr().out
