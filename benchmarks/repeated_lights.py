"""The coverage line's repeated lights on a capture with a lights file, and the cost of its guess.

Prints the line of :func:`ffls.weights.voronoi.coverage_warnings` for the capture's accepted lights,
without and with ``same_photo`` (the photos' pixels compared for the repeats named,
:func:`ffls.commands.common.same_photo_of`), and the seconds each took (docs/formats.md, Coverage).

    cd benchmarks && OMP_NUM_THREADS=1 ../.venv/bin/python repeated_lights.py \\
        /work/briefs/bench16/c00_384 --lights /work/briefs/bench16/c00_384/lights_estimated.json
"""
from __future__ import annotations

import argparse
import sys
import time

from ffls.commands.common import same_photo_of
from ffls.io.capture import load_capture_and_lights
from ffls.weights.voronoi import coverage_warnings


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture")
    ap.add_argument("--lights", default=None, help="lights.json or .lp (default CAPTURE/lights.json)")
    a = ap.parse_args(argv)
    cap, li = load_capture_and_lights(a.capture, a.lights)
    idx, dirs = li.accepted()
    names = [cap.image_names[i] for i in idx]
    for label, same in (("without", None), ("with", same_photo_of(cap, idx))):
        t = time.perf_counter()
        lines = [x for x in coverage_warnings(dirs, cap.hemisphere, names=names, same_photo=same) if "repeat" in x]
        print(f"{label} same_photo ({time.perf_counter() - t:.3f} s): {lines[0] if lines else 'no repeat'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
