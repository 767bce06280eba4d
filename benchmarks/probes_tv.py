"""Hougen-Ahuja with an edge-preserving prior: total variation on the source graph, over orientations.

    OMP_NUM_THREADS=1 python benchmarks/probes_tv.py [--noise 0.01 [--seed 1]] [--maps night,studio]
        [--orientations 4] [--methods default,smoothness,tv,paired,paired_tv,paired_power]

The scenes and the measure are those of ``benchmarks/probes_orientation.py`` (a Lambertian ball of albedo
0.7, 80 px, seen from the relit capture's camera; the four bundled maps at 64 rows; the ``ffls synth``
capture relit under the recovered vs the true map; relative RMS; ``--seed`` seeds the noise). Per orientation
and per map of the geodesic hierarchy (the first its own, the others those of
``adaptive_hougen_ahuja(..., orientations=K)``: ``Rotation.random(K, random_state=0)``): the plain
estimate (``default``: adaptive set by CV, NNLS, ``ambient='auto'``; the default before the thirteenth
stop), then on its source set the weight of the
quadratic first-difference prior (``'smoothness'``) and of total variation (``'tv'``) chosen by
``select_regularization`` (blocked CV, rule ``one_se``, weights ``SMOOTHNESS_WEIGHTS``): the relit error
of each, the weight chosen and the CPU seconds of each choice (``time.process_time``). The fits are
made in the turned frame (the pixels turned, as ``adaptive_hougen_ahuja`` does) and their sources turned
back. ``paired``: ``diffuse_lightmap``'s default since the thirteenth stop, the adaptive set's round and
the quadratic prior's weight both chosen by the paired-fold rule (``adaptive_hougen_ahuja(...,
rule='paired_se')``, then ``select_regularization(..., 'smoothness', rule='paired_se')`` on its set; its
``cpu_s`` is both); ``paired_tv``: the same with total variation; ``paired_power``: the same with the
least-total-power penalty, its weight among ``POWER_WEIGHTS`` (``--prior power``). ``--methods`` runs a
subset (``default`` too where a prior on its set is asked). Writes
``benchmarks/results/probes_tv[_noise[_seedS]].json`` (``--json`` another file).
"""
from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from common import (diffuse_ball, host_info, probe_benchmark_args, probe_benchmark_capture, probe_benchmark_map,
                    relit_capture_error, write_json)
from probes import H, MAPS
from ffls.conventions import normalize
from ffls.probes.estimate import POWER_WEIGHTS, SMOOTHNESS_WEIGHTS
from ffls.probes.selection import adaptive_hougen_ahuja, select_regularization

ROOT = Path(__file__).resolve().parent.parent
PRIORS = ("smoothness", "tv")
#: The paired methods: what each weighs and its candidate weights.
PAIRED = {"paired": ("smoothness", SMOOTHNESS_WEIGHTS), "paired_tv": ("tv", SMOOTHNESS_WEIGHTS),
          "paired_power": ("power", POWER_WEIGHTS)}
METHODS = ("default", *PRIORS, *PAIRED)


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(add_help=False)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--orientations", type=int, default=4)
    ap.add_argument("--methods", default=",".join(METHODS))
    own, rest = ap.parse_known_args(argv if argv is not None else sys.argv[1:])
    methods = own.methods.split(",")
    if any(m not in METHODS for m in methods):
        ap.error(f"--methods: each of {', '.join(METHODS)}, not {own.methods!r}")
    a = probe_benchmark_args(__doc__, MAPS, rest)
    rng = np.random.default_rng(own.seed)
    rots = Rotation.random(own.orientations, random_state=0).as_matrix()
    rots[0] = np.eye(3)
    cap, lights = probe_benchmark_capture("ffls_probes_tv_")
    tag = ("_noise" if a.noise > 0 else "") + (f"_seed{own.seed}" if own.seed else "")
    path = a.json or str(ROOT / f"benchmarks/results/probes_tv{tag}.json")
    scenes = {}
    for name in a.maps.split(","):
        lm, true, truth = probe_benchmark_map(name, H, cap, lights)
        sph, rad = diffuse_ball(lm, cap, a.noise, rng)
        scenes[name] = (sph.normals, rad, truth)
    out = []
    for i, R in enumerate(rots):  # orientation first: the own orientation of every map is measured first
        for name, (normals, rad, truth) in scenes.items():
            n = normals if i == 0 else normals @ R.T

            def err(fit):
                back = fit if i == 0 else dataclasses.replace(fit, directions=normalize(fit.directions @ R))
                return relit_capture_error(cap, lights, back.latlong(H), truth)

            r = {"map": name, "orientation": i}
            if "default" in methods or any(p in methods for p in PRIORS):
                t = time.process_time()
                sel = adaptive_hougen_ahuja(n, rad, 0.7, nonnegative=True, ambient="auto")
                r.update(sources=int(sel.chosen), default=err(sel.fit), default_cpu_s=time.process_time() - t)
            for prior in [p for p in PRIORS if p in methods]:
                t = time.process_time()
                reg = select_regularization(n, rad, 0.7, sel.fit.directions, SMOOTHNESS_WEIGHTS, prior,
                                            nonnegative=True, ambient="auto")
                r[prior] = {"weight": reg.chosen, "relit_capture": err(reg.fit), "cpu_s": time.process_time() - t,
                            "heldout": [float(s) for s in reg.scores]}
            paired = [m for m in PAIRED if m in methods]
            if paired:
                t = time.process_time()
                ps = adaptive_hougen_ahuja(n, rad, 0.7, nonnegative=True, ambient="auto", rule="paired_se")
                set_cpu = time.process_time() - t
            for m in paired:
                t = time.process_time()
                reg = select_regularization(n, rad, 0.7, ps.fit.directions, PAIRED[m][1], PAIRED[m][0],
                                            rule="paired_se", nonnegative=True, ambient="auto")
                r[m] = {"sources": int(ps.chosen), "weight": reg.chosen, "relit_capture": err(reg.fit),
                        "relit_capture_unregularised": err(ps.fit), "cpu_s": set_cpu + time.process_time() - t,
                        "heldout": [float(s) for s in reg.scores]}
            out.append(r)
            shown = [p for p in METHODS[1:] if p in r]
            print(f"{name} orientation {i}: "
                  + (f"{r['sources']} sources, default {100 * r['default']:.1f}%; " if "default" in r else "")
                  + "; ".join(f"{p} cv {r[p]['weight']:g}: {100 * r[p]['relit_capture']:.1f}% "
                              f"({r[p]['cpu_s']:.1f} CPU s)" for p in shown), flush=True)
            write_json(path, {"host": host_info(), "noise": a.noise, "seed": own.seed, "map_height": H,
                              "weights": list(SMOOTHNESS_WEIGHTS), "methods": methods, "rows": out,
                              "command": " ".join(["OMP_NUM_THREADS=1 python", "benchmarks/probes_tv.py",
                                                   *sys.argv[1:]])})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
