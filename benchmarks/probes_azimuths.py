"""Hougen-Ahuja with the source hierarchy's vertex on the world's up, averaged over azimuths, over orientations.

    OMP_NUM_THREADS=1 python benchmarks/probes_azimuths.py [--noise 0.01 [--seed 1]] [--maps night,studio]
        [--orientations 0,1,2,3] [--azimuths 4] [--json FILE]

The scenes, the measure and the orientations are those of ``benchmarks/probes_tv.py`` (a Lambertian ball of
albedo 0.7, 80 px, seen from the relit capture's camera; the four bundled maps at 64 rows; the ``ffls synth``
capture relit under the recovered vs the true map; relative RMS; orientation ``i`` turns the ball's normals
by the ``i``-th of ``Rotation.random(4, random_state=0)``, the first the identity). The estimate is
``diffuse_lightmap``'s (``azimuths=K``): in the turned frame the world's up is ``R e_z``; per azimuth
(``horizon_rotations(up, K)``) the adaptive set by the paired rule, then the quadratic prior's weight among
``SMOOTHNESS_WEIGHTS`` by the paired rule on that set, and the ``K`` fits averaged (``oriented_fits``,
``average_fits``). Per map and orientation: the relit error of every member (the first, with the world's up
on +Z, is the default before: ``azimuths=1``) and of the mean, the weights, the sources and the CPU seconds
of the whole estimate (``time.process_time``). Writes ``benchmarks/results/probes_azimuths[_noise[_seedS]]
.json`` after every row; ``python benchmarks/probes_azimuths.py --summary FILE...`` prints the table.
"""
from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from common import (diffuse_ball, host_info, probe_benchmark_args, probe_benchmark_capture, probe_benchmark_map,
                    relit_capture_error, write_json)
from probes import H, MAPS
from ffls.conventions import normalize
from ffls.probes.estimate import SMOOTHNESS_WEIGHTS
from ffls.probes.hougen_ahuja import average_fits
from ffls.probes.selection import adaptive_hougen_ahuja, horizon_rotations, oriented_fits, select_regularization

ROOT = Path(__file__).resolve().parent.parent


def summary(paths) -> list[str]:
    """Per condition: per map the mean's relit % (member 0 = one estimate), median and worst over the
    orientations, and the misses of 7%."""
    rows = {}
    for p in paths:
        doc = json.loads(Path(p).read_text())
        key = (doc["noise"], doc["seed"])
        rows.setdefault(key, {}).update({(r["map"], r["orientation"]): r for r in doc["rows"]})
    lines = []
    for (noise, seed), rs in sorted(rows.items()):
        lines.append(f"noise {noise}, seed {seed}:")
        for what, get in (("mean", lambda r: r["relit_capture"]), ("one", lambda r: r["members"][0])):
            miss, cells = 0, []
            for m in MAPS:
                e = [100 * get(r) for (mm, _), r in sorted(rs.items()) if mm == m]
                if not e:
                    continue
                miss += sum(x > 7.0 for x in e)
                cells.append(f"{m} " + "/".join(f"{x:.1f}" for x in e) + f" (median {np.median(e):.1f}, worst "
                             f"{max(e):.1f})")
            lines.append(f"  {what:4s} misses of 7%: {miss}: " + " | ".join(cells))
        cpu = [r["cpu_s"] for r in rs.values()]
        lines.append(f"  CPU s per map (the whole mean): {min(cpu):.1f}-{max(cpu):.1f}, mean {np.mean(cpu):.1f}")
    return lines


def main(argv=None):
    import argparse

    argv = list(argv if argv is not None else sys.argv[1:])
    if argv[:1] == ["--summary"]:
        print("\n".join(summary(argv[1:])))
        return
    ap = argparse.ArgumentParser(add_help=False)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--orientations", default="0,1,2,3")
    ap.add_argument("--azimuths", type=int, default=4)
    own, rest = ap.parse_known_args(argv)
    a = probe_benchmark_args(__doc__, MAPS, rest)
    rng = np.random.default_rng(own.seed)
    rots = Rotation.random(4, random_state=0).as_matrix()
    rots[0] = np.eye(3)
    cap, lights = probe_benchmark_capture("ffls_probes_azimuths_")
    tag = ("_noise" if a.noise > 0 else "") + (f"_seed{own.seed}" if own.seed else "")
    path = a.json or str(ROOT / f"benchmarks/results/probes_azimuths{tag}.json")
    scenes = {}
    for name in MAPS:  # every map's noise drawn in the same order, whichever maps are run
        lm, true, truth = probe_benchmark_map(name, H, cap, lights)
        sph, rad = diffuse_ball(lm, cap, a.noise, rng)
        scenes[name] = (sph.normals, rad, truth)
    out = []
    for i in map(int, own.orientations.split(",")):
        R = rots[i]
        for name in a.maps.split(","):
            normals, rad, truth = scenes[name]
            n = normals if i == 0 else normals @ R.T

            def one(turned):
                sel = adaptive_hougen_ahuja(turned, rad, 0.7, nonnegative=True, ambient="auto", rule="paired_se")
                reg = select_regularization(turned, rad, 0.7, sel.fit.directions, SMOOTHNESS_WEIGHTS, "smoothness",
                                            rule="paired_se", nonnegative=True, ambient="auto")
                return reg.fit, (int(sel.chosen), float(reg.chosen))

            def err(fit):  # back from the turned frame to the world's
                back = fit if i == 0 else dataclasses.replace(fit, directions=normalize(fit.directions @ R))
                return relit_capture_error(cap, lights, back.latlong(H), truth)

            t = time.process_time()
            fits, parts = oriented_fits(n, horizon_rotations(R[:, 2], own.azimuths), one)
            mean = average_fits(fits, rad)
            cpu = time.process_time() - t
            r = {"map": name, "orientation": i, "relit_capture": err(mean), "members": [err(f) for f in fits],
                 "sources": [p[0] for p in parts], "weights": [p[1] for p in parts], "cpu_s": cpu}
            out.append(r)
            print(f"{name} orientation {i}: members " + " ".join(f"{100 * e:.1f}" for e in r["members"])
                  + f" %, mean {100 * r['relit_capture']:.1f}%; weights {r['weights']}; {cpu:.1f} CPU s", flush=True)
            write_json(path, {"host": host_info(), "noise": a.noise, "seed": own.seed, "map_height": H,
                              "azimuths": own.azimuths, "weights": list(SMOOTHNESS_WEIGHTS), "rows": out,
                              "command": " ".join(["OMP_NUM_THREADS=1 python", "benchmarks/probes_azimuths.py",
                                                   *argv])})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
