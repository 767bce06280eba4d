"""Hougen-Ahuja's adaptive source set at patience 2 and 6: which rows' sets differ, and the set's CPU.

    OMP_NUM_THREADS=1 python benchmarks/probes_patience_sets.py [--noise 0.01 [--seed S]] [--maps M]
        [--orientations 0,1,2,3] [--json OUT.json]

The scenes, noise draws and orientations of ``benchmarks/probes_power_split.py`` (no relighting): per map and
orientation, ``adaptive_hougen_ahuja(..., rule='paired_se', patience=P)`` for P = 2 and 6, the source count
chosen, the rounds, the CPU seconds (``time.process_time``) and whether the two chosen sets are the same
directions (then the estimate is the same). ``probes_power_split.py --patience P`` relights the rows that differ.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation

from common import diffuse_ball, probe_benchmark_capture
from probes import H, MAPS
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes.selection import adaptive_hougen_ahuja

PATIENCES = (2, 6)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, default=0.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--maps", default=",".join(MAPS))
    ap.add_argument("--orientations", default="0,1,2,3")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv if argv is not None else sys.argv[1:])
    rng = np.random.default_rng(a.seed)
    rots = Rotation.random(4, random_state=0).as_matrix()
    rots[0] = np.eye(3)
    cap, _ = probe_benchmark_capture("ffls_probes_patience_")
    scenes = {}
    for name in MAPS:  # every map in probes_power_split.py's order: the same noise draws
        lm = builtin_lightmap(name)
        sph, rad = diffuse_ball(lm.downsample(lm.res // H), cap, a.noise, rng)
        scenes[name] = (sph.normals, rad)
    out = []
    for i in [int(x) for x in a.orientations.split(",")]:
        for name in a.maps.split(","):
            normals, rad = scenes[name]
            n = normals if i == 0 else normals @ rots[i].T
            row, sets = {"map": name, "orientation": i}, []
            for p in PATIENCES:
                t = time.process_time()
                ps = adaptive_hougen_ahuja(n, rad, 0.7, nonnegative=True, ambient="auto", rule="paired_se",
                                           patience=p)
                row[f"patience_{p}"] = {"sources": int(ps.chosen), "rounds": [int(c) for c in ps.candidates],
                                        "cpu_s": time.process_time() - t}
                sets.append(ps.fit.directions)
            row["same_set"] = bool(sets[0].shape == sets[1].shape and np.array_equal(sets[0], sets[1]))
            out.append(row)
            shown = [(p, row[f"patience_{p}"]) for p in PATIENCES]
            print(f"{name} orientation {i}: " + "; ".join(
                f"patience {p} {r['sources']} sources ({r['cpu_s']:.1f} CPU s)" for p, r in shown)
                + ("" if row["same_set"] else ", DIFFERENT sets"), flush=True)
            if a.json:
                with open(a.json, "w") as f:
                    cmd = " ".join(["OMP_NUM_THREADS=1 python benchmarks/probes_patience_sets.py", *sys.argv[1:]])
                    json.dump({"noise": a.noise, "seed": a.seed, "rows": out, "command": cmd}, f, indent=1)


if __name__ == "__main__":
    main()
