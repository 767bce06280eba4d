"""The median and worst relit error over the orientations of ``benchmarks/probes_orientation.py``'s results.

    python benchmarks/probes_orientation_summary.py [RESULT.json ...]

Without arguments: every ``benchmarks/results/probes_orientation*.json``. Per file and map: the relit
synth-capture error of each orientation's estimate (one orientation each), its median and worst (max), the
average over all orientations, and the CPU seconds of the whole ensemble; then per file the median and
worst over all maps' orientations. Prints a table; reads only, writes nothing.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def summarise(path) -> list[str]:
    doc = json.loads(Path(path).read_text())
    lines = [f"{Path(path).name}: noise {doc.get('noise', 0)}, seed {doc.get('seed', 0)}, "
             f"ground {bool(doc.get('ground', False))}, {doc.get('orientations')} orientations"]
    every = []
    for r in doc["rows"]:
        e = 100 * np.asarray(r["relit_capture_single"], dtype=np.float64)
        every.extend(e)
        avg = r["relit_capture_average"]
        mean_k = 100 * avg[max(avg, key=int)] if avg else float("nan")
        lines.append(f"  {r['map']:10s} median {np.median(e):5.1f}%  worst {e.max():5.1f}%  best {e.min():5.1f}%  "
                     f"mean of all {mean_k:5.1f}%  ({r['cpu_s']:.1f} CPU s)")
    lines.append(f"  {'all maps':10s} median {np.median(every):5.1f}%  worst {max(every):5.1f}%")
    return lines


def main(argv=None):
    files = list(argv if argv is not None else sys.argv[1:]) or sorted(
        (ROOT / "benchmarks/results").glob("probes_orientation*.json"))
    for f in files:
        print("\n".join(summarise(f)))


if __name__ == "__main__":
    main()
