"""benchmarks/lights_timeline.py and benchmarks/abba_lights.py: the wall time of ``ffls lights``
(docs/spheres.md, Speed: "The wall time of --workers 2")."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import abba_lights  # noqa: E402  (benchmarks/abba_lights.py)
import lights_timeline  # noqa: E402  (benchmarks/lights_timeline.py)


def test_main_alone_counts_the_samples_where_no_worker_ran():
    """The main process's CPU alone: the samples' CPU growth where no worker grew its CPU by a tenth
    of the sample (a worker that only exists, or barely runs, does not count)."""
    samples = [(0.0, 0.0, {}),
               (0.1, 0.1, {}),                    # main alone: 0.1
               (0.2, 0.15, {7: 0.09}),            # a worker ran: not alone
               (0.3, 0.25, {7: 0.095}),           # the worker's 0.005 < 0.01: alone, 0.1
               (0.4, 0.26, {7: 0.095, 8: 0.05})]  # another worker ran
    assert abs(lights_timeline.main_alone(samples) - 0.2) < 1e-12
    assert abs(lights_timeline.main_alone(samples, 0.15, 1.0) - 0.1) < 1e-12
    assert abs(lights_timeline.workers_cpu(samples, 0.0, 0.4) - 0.145) < 1e-12


def test_abba_environments_set_and_unset():
    py, env = abba_lights.environment("PYTHONPATH=/tmp/a,PYTHONDONTWRITEBYTECODE=-,PY=/bin/python9")
    assert py == "/bin/python9" and env["PYTHONPATH"] == "/tmp/a" and env["OMP_NUM_THREADS"] == "1"
    assert "PYTHONDONTWRITEBYTECODE" not in env


def test_timeline_of_a_small_capture(tmp_path):
    """The timeline of ``ffls lights --workers 2`` on a small synthetic capture: the pipeline's
    stages in order, the workers' CPU inside the pools' stages, the totals, status 0."""
    from ffls.cli import main

    cap = tmp_path / "cap"
    assert main(["synth", str(cap), "--lights", "6", "--resolution", "192"]) == 0
    out = tmp_path / "t.json"
    done = subprocess.run([sys.executable, str(BENCHMARKS / "lights_timeline.py"), str(cap), "--out", str(out),
                           "--lights-out", str(tmp_path / "lights.json"), "--", "--workers", "2"],
                          env=dict(os.environ, OMP_NUM_THREADS="1"), stdout=subprocess.PIPE, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stdout
    doc = json.loads(out.read_text())
    top = [s["stage"] for s in doc["stages"] if s["depth"] == 0]
    assert top[:4] == ["load_capture", "decode_photos", "calibrate_if_unknown", "find_spheres_in_capture"], top
    assert "estimate_lights" in top and "save_lights" in top
    t = doc["totals"]
    assert t["rc"] == 0 and t["main_cpu_s"] > 0 and t["workers_cpu_s"] > 0
    assert 0 <= t["main_alone_cpu_s"] <= t["main_cpu_s"] and t["main_cpu_before_stages_s"] > 0
    assert json.loads((tmp_path / "lights.json").read_text())["lights"]
