"""Where ``ffls composite --fill`` finds a capture's spheres, against ``ffls lights`` and the truth.

For each capture folder (``ffls synth --composite-set``'s ``object`` or ``surface``, with a
``lights.json`` from ``ffls lights``): the world centres' distances to ``truth.json``'s (mm, for a
capture in metres) of :func:`ffls.commands.composite.sphere_geometry` (the fill's), of the
detection on the stored codes of an unstated encoding (what ``ffls lights`` used before i-step15:
:func:`ffls.commands.lights.calibrate_if_unknown`'s spheres), of the detection on the photos
linearised with the calibrated curve (``ffls lights``' since), and of lights.json's records.

    cd benchmarks && OMP_NUM_THREADS=1 ../.venv/bin/python composite_spheres.py SET/object SET/surface
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from ffls.commands.composite import sphere_geometry
from ffls.commands.lights import calibrate_if_unknown
from ffls.io.capture import load_capture, load_capture_and_lights
from ffls.spheres.detect import find_spheres_in_capture
from ffls.spheres.estimate import decode_photos


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("captures", nargs="+")
    a = ap.parse_args(argv)
    for folder in a.captures:
        truth = np.array(json.loads((Path(folder) / "truth.json").read_text())["sphere_centers"])

        def mm(centres):
            c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
            return np.round([1000 * np.linalg.norm(truth - x, axis=1).min() for x in c], 2).tolist()

        cap, lights = load_capture_and_lights(folder)
        t = time.perf_counter()
        geo = sphere_geometry(cap, lights)
        print(f"{folder}: composite --fill ({geo['source']}, {time.perf_counter() - t:.1f} s): {mm(geo['centres'])}")
        raw = load_capture(folder)
        dec = decode_photos(raw, workers=1)
        linear, stored, cal = calibrate_if_unknown(raw, decoded=dec, workers=1)
        if cal is not None:
            print(f"  on the stored codes:      {mm([s.center_world for s in stored])}")
            found = find_spheres_in_capture(linear, stats=dec.linear_stats(linear), bit_depths=dec.bit_depths,
                                            workers=1)
            print(f"  on the linearised photos: {mm([s.center_world for s in found])}")
        rec = next(e["spheres"] for e in lights.extra if e.get("spheres"))
        print(f"  lights.json's records:    {mm([r['center'] for r in rec if r.get('center') is not None])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
