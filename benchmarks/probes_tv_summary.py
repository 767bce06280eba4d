"""The table of ``benchmarks/probes_tv.py``'s results: per condition, map and method, the relit error in the
hierarchy's own orientation, the median and worst over the orientations measured, and the CPU seconds.

    python benchmarks/probes_tv_summary.py [RESULT.json ...]

Without arguments: every ``benchmarks/results/probes_tv*.json`` and ``probes_paired*.json``. Methods (those a
file holds): the default estimate before the thirteenth stop, and on its source set the quadratic
first-difference prior and total variation, each weight chosen by blocked CV; ``paired``, the round and the
quadratic prior's weight chosen by paired folds (the default since). Reads only, writes nothing.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
METHODS = ("default", "smoothness", "tv", "paired", "paired_tv", "paired_power")


def relit(row, method) -> float:
    return 100 * (row[method] if method == "default" else row[method]["relit_capture"])


def cpu(row, method) -> float:
    return row["default_cpu_s"] if method == "default" else row[method]["cpu_s"]


def summarise(path) -> list[str]:
    doc = json.loads(Path(path).read_text())
    rows = doc["rows"]
    maps = list(dict.fromkeys(r["map"] for r in rows))
    lines = [f"{Path(path).name}: noise {doc.get('noise', 0)}, seed {doc.get('seed', 0)}"]
    for method in [m for m in METHODS if all(m in r for r in rows)]:
        cells, misses, n = [], 0, 0
        for m in maps:
            rs = [r for r in rows if r["map"] == m]
            e = np.array([relit(r, method) for r in rs])
            own = [relit(r, method) for r in rs if r["orientation"] == 0]
            w = [] if method == "default" else [r[method]["weight"] for r in rs]
            misses += int(np.sum(e > 7.0))
            n += e.size
            cells.append(f"{m} {own[0] if own else float('nan'):.1f} (median {np.median(e):.1f}, worst {e.max():.1f}"
                         f" of {e.size}; CPU {np.mean([cpu(r, method) for r in rs]):.1f} s"
                         + (f"; weights {'/'.join(f'{x:g}' for x in w)}" if w else "") + ")")
        lines.append(f"  {method:10s} misses of 7%: {misses}/{n}: " + " | ".join(cells))
    return lines


def main(argv=None):
    res = ROOT / "benchmarks/results"
    paths = (argv if argv is not None else sys.argv[1:]) or sorted(
        str(p) for p in [*res.glob("probes_tv*.json"), *res.glob("probes_paired*.json")])
    for p in paths:
        print("\n".join(summarise(p)))


if __name__ == "__main__":
    main()
