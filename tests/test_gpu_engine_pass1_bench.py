"""benchmarks/gpu_engine_pass1.py: its light sets and largest-cell count, and a tiny run on the test context."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import gpu_engine_pass1  # noqa: E402  (benchmarks/gpu_engine_pass1.py)


def test_two_opposite_lights_split_the_hemisphere_in_equal_cells():
    d = np.array([[1.0, 0.0, 0.1], [-1.0, 0.0, 0.1]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    h = 64
    upper = h // 2 * 2 * h  # the rows whose centres have z >= 0
    assert gpu_engine_pass1.largest_cell(d, h) == upper // 2


def test_light_sets_are_unit_upper_directions_and_unknown_names_stop():
    for name in ("fib", "rand3"):
        d = gpu_engine_pass1.light_set(name, 50)
        assert d.shape == (50, 3) and np.allclose(np.linalg.norm(d, axis=1), 1.0) and (d[:, 2] >= 0).all()
    with pytest.raises(SystemExit, match="unknown light set 'grid'"):
        gpu_engine_pass1.light_set("grid", 10)


def test_a_tiny_run_writes_its_rows(tmp_path, gl_session):
    out = tmp_path / "rows.json"
    assert gpu_engine_pass1.main(["--sets", "fib", "--lights", "16", "--sizes", "16", "--reps", "3",
                                  "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [(r["set"], r["n"], r["size"]) for r in rows] == [("fib", 16, 256), ("rand0", 16, 16)]
    assert all(r["ms"] > 0 and "pass1" in r["pass_ms"] for r in rows)
