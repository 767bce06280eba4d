"""benchmarks/bench_conditions.py --cache: a cached render is used only for its own condition.

The cache's folders are numbered by position; a condition inserted before others would have scored
their renders as its own. Each folder now records its condition's command.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_conditions  # noqa: E402  (benchmarks/bench_conditions.py)


def test_a_cached_render_of_another_condition_stops_the_benchmark(tmp_path, capsys):
    folder = tmp_path / "c00_384"
    folder.mkdir()
    (folder / bench_conditions.CONDITION_FILE).write_text("ffls synth OUT --resolution 384 --background white\n")
    with pytest.raises(SystemExit, match="another condition"):
        bench_conditions.check_cached_condition(folder, "ffls synth OUT --resolution 384")
    bench_conditions.check_cached_condition(folder, "ffls synth OUT --resolution 384 --background white")


def test_a_cache_without_the_record_is_taken_as_it_is(tmp_path):
    """A folder rendered by an earlier version (no record) or not rendered yet passes."""
    bench_conditions.check_cached_condition(tmp_path, "ffls synth OUT --resolution 384")
    bench_conditions.check_cached_condition(tmp_path / "new", "ffls synth OUT --resolution 384")
