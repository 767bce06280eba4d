"""Hougen-Ahuja's least-power weight: what each weight's map gets wrong, and what the pixels can tell.

    OMP_NUM_THREADS=1 python benchmarks/probes_power_split.py [--noise 0.01 [--seed 1]] [--maps studio,night]
        [--orientations 0,1,2,3] [--patience P] [--json OUT.json]

The scenes, the orientations and the measure are those of ``benchmarks/probes_tv.py --methods paired_power``
(an 80 px Lambertian ball of albedo 0.7 seen from the relit capture's camera, the four bundled maps at 64
rows, the ``ffls synth`` capture relit under the recovered vs the true map, relative RMS; orientation ``i``
is ``Rotation.random(4, random_state=0)[i]``, 0 the identity). Per map and orientation: the adaptive set
of the paired rule, then on it every weight of ``WEIGHTS`` (``POWER_WEIGHTS`` and 0.01) fitted on all
pixels: the relit error, that error split by the map's error in spherical-harmonic orders 0-2 (the true
map plus that part of the difference, relit) and above 2 (the rest), the per-order relative error of
orders 0-4 (``evaluate.sh_recovery``), the fit's re-rendered relative RMS and sum of squares over all
pixels, its total power; the adaptive set's rounds (sizes), their held-out relative RMS and the set's CPU seconds
(``set_cpu_s``, ``time.process_time``); and the
paired-fold cross-validation's held-out squared errors per fold
(``select_regularization(..., 'power', rule='paired_se')``) with the weight it chose. Writes
``benchmarks/results/probes_power_split[_noise[_seedS]].json``; prints a line per weight. ``--patience``: the
adaptive set's ``patience`` (rounds without a better held-out score before it stops; default 2, the estimator's).
``--jitter S``: the normals multiplied by ``1 + 1e-15 z`` (``z`` standard normal from seed ``S``), to see which
answers change with the inputs' last bits. ``--energy E``: every fit with the energy prior ``E`` too (a ridge:
one solution where NNLS has many).
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
from ffls.conventions import latlong_directions, normalize
from ffls.probes.estimate import POWER_WEIGHTS
from ffls.probes.evaluate import sh_basis, sh_project, sh_recovery
from ffls.probes.hougen_ahuja import hougen_ahuja
from ffls.probes.selection import adaptive_hougen_ahuja, select_regularization

ROOT = Path(__file__).resolve().parent.parent
WEIGHTS = (*POWER_WEIGHTS, 0.01)


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(add_help=False)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--orientations", default="0,1,2,3")
    ap.add_argument("--patience", type=int, default=2)
    ap.add_argument("--jitter", type=int, default=None)
    ap.add_argument("--energy", type=float, default=0.0)
    own, rest = ap.parse_known_args(argv if argv is not None else sys.argv[1:])
    a = probe_benchmark_args(__doc__, MAPS, rest)
    rng = np.random.default_rng(own.seed)
    rots = Rotation.random(4, random_state=0).as_matrix()
    rots[0] = np.eye(3)
    cap, lights = probe_benchmark_capture("ffls_probes_power_split_")
    scenes = {}
    for name in MAPS:  # every map, in probes_tv.py's order, so that each gets the same noise as there
        lm, true, truth = probe_benchmark_map(name, H, cap, lights)
        sph, rad = diffuse_ball(lm, cap, a.noise, rng)
        normals = sph.normals
        if own.jitter is not None:  # the normals moved by their last bits: which answers are a lottery
            normals = normals * (1 + 1e-15 * np.random.default_rng(own.jitter).standard_normal(normals.shape))
        scenes[name] = (normals, rad, truth, true)
    low = sh_basis(latlong_directions(2 * H, H).reshape(-1, 3), 2)
    tag = ("_noise" if a.noise > 0 else "") + (f"_seed{own.seed}" if own.seed else "")
    path = a.json or str(ROOT / f"benchmarks/results/probes_power_split{tag}.json")
    out = []
    for i in [int(x) for x in own.orientations.split(",")]:
        for name in a.maps.split(","):
            normals, rad, truth, true = scenes[name]
            R = rots[i]
            n = normals if i == 0 else normals @ R.T
            t = time.process_time()
            ps = adaptive_hougen_ahuja(n, rad, 0.7, nonnegative=True, ambient="auto", rule="paired_se",
                                       patience=own.patience, energy=own.energy)
            set_cpu = time.process_time() - t
            reg = select_regularization(n, rad, 0.7, ps.fit.directions, POWER_WEIGHTS, "power", rule="paired_se",
                                        nonnegative=True, ambient="auto", energy=own.energy)
            row = {"map": name, "orientation": i, "sources": int(ps.chosen), "cv_weight": reg.chosen,
                   "fold_errors": reg.fold_errors.tolist(), "pixels": int(rad.size), "weights": [],
                   "rounds": [int(c) for c in ps.candidates], "round_scores": [float(x) for x in ps.scores],
                   "set_cpu_s": set_cpu}
            print(f"{name} orientation {i}: {ps.chosen} sources (rounds "
                  + ", ".join(f"{c}: {x:.5f}" for c, x in zip(row["rounds"], row["round_scores"]))
                  + f" held-out relative RMS; {set_cpu:.1f} CPU s), paired CV chose {reg.chosen:g}", flush=True)
            for lam in WEIGHTS:
                fit = hougen_ahuja(n, rad, 0.7, ps.fit.directions, nonnegative=True, ambient="auto", power=lam,
                                   energy=own.energy)
                rec = dataclasses.replace(fit, directions=normalize(fit.directions @ R)).latlong(H)
                diff = rec - true
                part = (low @ sh_project(diff, 2)).reshape(diff.shape)
                w = {"weight": lam, "relit": relit_capture_error(cap, lights, rec, truth),
                     "relit_orders_0_2": relit_capture_error(cap, lights, true + part, truth),
                     "relit_orders_above_2": relit_capture_error(cap, lights, true + diff - part, truth),
                     "sh_relative_error_0_4": sh_recovery(rec, true, 4).relative_error.tolist(),
                     "rerender": fit.relative_rms,
                     "rss": float(np.sum((fit.rendered - np.asarray(rad).reshape(fit.rendered.shape)) ** 2)),
                     "power": float(np.sum(fit.intensities))}
                row["weights"].append(w)
                print(f"  {lam:<7g} relit {100 * w['relit']:5.1f}% (orders 0-2 {100 * w['relit_orders_0_2']:5.1f}%, "
                      f"above 2 {100 * w['relit_orders_above_2']:5.1f}%); SH error l0-4 "
                      + " ".join(f"{x:.3f}" for x in w["sh_relative_error_0_4"])
                      + f"; re-render {w['rerender']:.5f}; power {w['power']:.2f}", flush=True)
            out.append(row)
            write_json(path, {"host": host_info(), "noise": a.noise, "seed": own.seed, "map_height": H,
                              "weights": list(WEIGHTS), "patience": own.patience, "jitter": own.jitter,
                              "energy": own.energy, "rows": out,
                              "command": " ".join(["OMP_NUM_THREADS=1 python", "benchmarks/probes_power_split.py",
                                                   *sys.argv[1:]])})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
