"""benchmarks/bench_conditions.py --bias-check: one bias magnitude per photo along a direction known
from the geometry (each sphere toward the scene centre), against a stored run's truth."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_conditions  # noqa: E402  (benchmarks/bench_conditions.py)

from ffls.conventions import normalize, tangent_basis  # noqa: E402


def _capture(folder: Path, bias_deg: float, noise_deg: float, seed: int, n: int = 40) -> None:
    """A stored run of 4 spheres on a ring around the scene centre: each sphere's direction off the
    truth by ``b h_i`` (``b`` drawn per photo, ``bias_deg`` RMS; ``h_i`` toward the centre) plus
    independent noise (``noise_deg`` per axis)."""
    rng = np.random.default_rng(seed)
    centres = np.array([[-0.25, -0.25, 0.05], [0.25, -0.25, 0.05], [0.25, 0.25, 0.05], [-0.25, 0.25, 0.05]])
    truth, lights = [], []
    for j in range(n):
        az, el = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(20, 80))
        t = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        e1, e2 = tangent_basis(t)
        b = np.radians(bias_deg) * rng.standard_normal()
        dirs = []
        for c in centres:
            g = normalize(-c)
            off = b * np.array([g @ e1, g @ e2]) + np.radians(noise_deg) * rng.standard_normal(2)
            dirs.append(normalize(t + off[0] * e1 + off[1] * e2))
        spheres = [{"status": "ok", "kind": "matte", "direction": list(d), "center": list(c), "sigma_deg": 0.05}
                   for d, c in zip(dirs, centres)]
        lights.append({"image": f"img_{j:04d}.exr", "status": "ok", "model": "distant",
                       "direction": list(normalize(np.mean(dirs, axis=0))), "uncertainty_deg": 1.0,
                       "used_spheres": [0, 1, 2, 3], "spheres": spheres})
        truth.append(list(t))
    folder.mkdir()
    (folder / "capture.json").write_text(json.dumps({"format": "ffls-capture", "version": 1}))
    (folder / "truth.json").write_text(json.dumps({"directions": truth, "light_model": "distant"}))
    (folder / "lights_estimated.json").write_text(json.dumps({"lights": lights, "uncertainty": {}}))


def test_a_bias_toward_the_centre_is_explained_and_found_by_the_capture(tmp_path):
    _capture(tmp_path / "biased", bias_deg=1.0, noise_deg=0.05, seed=1)
    r = bench_conditions.bias_check(tmp_path / "biased")
    assert r["explained"] > 0.95
    assert r["p"] < 1e-6
    # a balanced ring: only the direction's vertical part (the centres 5 cm above the scene
    # centre, 0.14 of it) survives the mean; what the term leaves is independent
    assert r["median_hbar"] < 0.15
    assert 0.5 < r["photo_over_independent_remainder"] < 2.0


def test_independent_errors_are_not_a_bias(tmp_path):
    _capture(tmp_path / "plain", bias_deg=0.0, noise_deg=0.3, seed=2)
    r = bench_conditions.bias_check(tmp_path / "plain")
    assert r["explained"] < 0.2
    assert r["p"] > 1e-3
    assert 0.5 < r["photo_over_independent"] < 2.0


def test_the_cli_writes_the_table(tmp_path, capsys):
    _capture(tmp_path / "one", bias_deg=1.0, noise_deg=0.05, seed=3)
    bench_conditions.main(["--bias-check", "--folders", str(tmp_path / "one"), "--out", str(tmp_path / "out.json")])
    rows = json.loads((tmp_path / "out.json").read_text())["results"]
    assert [r["direction"] for r in rows] == list(bench_conditions.BIAS_DIRECTIONS)
    assert "| one | toward_centre | 40 (40) |" in capsys.readouterr().out
