"""Hougen-Ahuja's default estimate in several orientations of its source set, and their average.

    OMP_NUM_THREADS=1 python benchmarks/probes_orientation.py [--noise 0.01 [--seed 1]] [--maps night,studio]
        [--orientations 8] [--ground]

The scenes and the measure are those of ``benchmarks/probes.py`` and ``benchmarks/probes_night.py`` (a
Lambertian ball of albedo 0.7, 80 px, seen from the relit capture's camera; the four bundled maps at 64
rows; the ``ffls synth`` capture, 150 lights, relit under the recovered vs the true map; relative RMS;
``--seed`` seeds the noise as there). Per map, ``adaptive_hougen_ahuja(..., orientations=K)`` (the default
estimate, CV, NNLS, ``ambient='auto'``, made in ``K`` orientations of the geodesic hierarchy, the first its
own, and averaged): the relit error of every member (one orientation each) and of the average of the
first 2, 4 and ``K``, the members' held-out relative RMS (the CV score of the round each chose, on its
own folds), and the CPU seconds of the whole ensemble (``time.process_time``). Writes
``benchmarks/results/probes_orientation.json`` (``..._noise[_seedS].json`` with ``--noise``).
``--ground``: the estimate with a ground plane ``z = 0`` (``ground=(0, 0, 1)``: sources on a dome over it,
the light below it uniform), its orientations turned about +Z (random azimuths, seed 0); ``_ground`` is
added to the file name.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from common import (diffuse_ball, host_info, probe_benchmark_args, probe_benchmark_capture, probe_benchmark_map,
                    relit_capture_error, write_json)
from probes import H, MAPS
from ffls.probes.hougen_ahuja import average_fits
from ffls.probes.selection import adaptive_hougen_ahuja

ROOT = Path(__file__).resolve().parent.parent


def ensemble_parts(sel):
    """The members (fits), their source counts and their held-out scores of an ``adaptive_hougen_ahuja``
    selection: an ensemble's own with ``orientations > 1``, the plain estimate as the one member with 1
    (a ``SourceFit``, one size and one score per refinement round, of which the chosen round's)."""
    if hasattr(sel.fit, "members"):
        return sel.fit.members, [int(c) for c in sel.chosen], [float(s) for s in sel.scores]
    score = float(sel.scores[list(sel.candidates).index(sel.chosen)])
    return (sel.fit,), [int(sel.chosen)], [score]


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(add_help=False)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--orientations", type=int, default=8)
    ap.add_argument("--ground", action="store_true")
    own, rest = ap.parse_known_args(argv if argv is not None else sys.argv[1:])
    a = probe_benchmark_args(__doc__, MAPS, rest)
    rng = np.random.default_rng(own.seed)
    cap, lights = probe_benchmark_capture("ffls_probes_orientation_")
    out = []
    for name in a.maps.split(","):
        lm, true, truth = probe_benchmark_map(name, H, cap, lights)
        sph, rad = diffuse_ball(lm, cap, a.noise, rng)
        t = time.process_time()
        sel = adaptive_hougen_ahuja(sph.normals, rad, 0.7, nonnegative=True, ambient="auto",
                                    orientations=own.orientations, ground=(0.0, 0.0, 1.0) if own.ground else None)
        cpu = time.process_time() - t
        members, sizes, heldout = ensemble_parts(sel)
        single = [relit_capture_error(cap, lights, f.latlong(H), truth) for f in members]
        avg = {str(j): relit_capture_error(cap, lights, average_fits(members[:j], rad).latlong(H), truth)
               for j in sorted({2, 4, len(members)}) if j <= len(members)}
        row = {"map": name, "sources": sizes, "heldout": heldout,
               "relit_capture_single": single, "relit_capture_average": avg, "cpu_s": cpu}
        out.append(row)
        print(f"{name}: one orientation each "
              + " ".join(f"{100 * e:.1f}" for e in single)
              + " % (the first is the default's); average of "
              + ", ".join(f"{j}: {100 * e:.1f}%" for j, e in avg.items())
              + f"; sources {'/'.join(map(str, sizes))}; {cpu:.1f} CPU s", flush=True)
    tag = ("_noise" if a.noise > 0 else "") + (f"_seed{own.seed}" if own.seed else "") + (
        "_ground" if own.ground else "")
    path = a.json or str(ROOT / f"benchmarks/results/probes_orientation{tag}.json")
    write_json(path, {"host": host_info(), "noise": a.noise, "seed": own.seed, "orientations": own.orientations,
                      "ground": own.ground,
                      "map_height": H, "rows": out,
                      "command": " ".join(["OMP_NUM_THREADS=1 python", "benchmarks/probes_orientation.py",
                                           *sys.argv[1:]])})


if __name__ == "__main__":
    main()
