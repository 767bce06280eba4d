"""Hougen-Ahuja inside the Lambertian ambiguity: where NNLS puts spread light, and what a penalty does.

    OMP_NUM_THREADS=1 python benchmarks/probes_regularised.py [--noise 0.01] [--maps night,studio]

The scenes and the measure are those of ``benchmarks/probes.py`` (a Lambertian ball of albedo 0.7,
80 px, seen from the relit capture's camera; the four bundled maps at 64 rows; the ``ffls synth``
capture, 150 lights, relit under the recovered vs the true map). Per map:

1. the default estimate, ``adaptive_hougen_ahuja(..., criterion='cv', nonnegative=True,
   ambient='nonnegative')``, and on its source set:
2. the **concentration** of the NNLS (vertex) solution: the share of the recovered power in its 10
   strongest sources against the true map's share in its 10 strongest cells of the same set, and
   the strongest recovered and true sources (elevation, azimuth, share of the recovered / true
   power);
3. a **sweep** of each penalty weight (``energy``: minimum squared radiance; ``smoothness``: first
   differences; :func:`ffls.probes.hougen_ahuja.hougen_ahuja`) on that set: the relit capture
   error, the sphere-of-normals error, the re-render error and the blocked-CV held-out error of
   ``select_regularization``;
4. the weight that ``select_regularization`` chooses from the data (rule ``one_se``) and its errors.

Writes ``benchmarks/results/probes_regularised.json`` (``..._noise.json`` with ``--noise``).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from common import (diffuse_ball, host_info, probe_benchmark_args, probe_benchmark_capture, probe_benchmark_map,
                    relit_capture_error, write_json)
from probes import H, MAPS
from ffls.probes.evaluate import relit_error
from ffls.probes.hougen_ahuja import hougen_ahuja
from ffls.probes.selection import adaptive_hougen_ahuja, select_regularization
from ffls.probes.sources import cell_energies

ROOT = Path(__file__).resolve().parent.parent
WEIGHTS = (0.0, 0.001, 0.003, 0.01, 0.03)
KW = {"nonnegative": True, "ambient": "nonnegative"}


def describe(d, i):
    el = np.degrees(np.arcsin(np.clip(d[i, 2], -1, 1)))
    az = np.degrees(np.arctan2(d[i, 1], d[i, 0]))
    return {"elevation": float(el), "azimuth": float(az)}


def main(argv=None):
    a = probe_benchmark_args(__doc__, MAPS, argv)
    rng = np.random.default_rng(0)
    cap, lights = probe_benchmark_capture("ffls_probes_reg_")
    out = []
    for name in a.maps.split(","):
        lm, true, truth = probe_benchmark_map(name, H, cap, lights)

        def err(L):
            return relit_capture_error(cap, lights, L, truth)

        sph, rad = diffuse_ball(lm, cap, a.noise, rng)
        sel = adaptive_hougen_ahuja(sph.normals, rad, 0.7, criterion="cv", **KW)
        d = sel.fit.directions
        rec = np.abs(sel.fit.intensities).sum(axis=1)
        tru = cell_energies(d, true).sum(axis=1)
        top_r, top_t = np.argsort(-rec)[:5], np.argsort(-tru)[:5]
        conc = {"recovered_top10_share": float(np.sort(rec)[::-1][:10].sum() / rec.sum()),
                "true_top10_share": float(np.sort(tru)[::-1][:10].sum() / tru.sum()),
                "strongest_recovered": [{**describe(d, i), "recovered": float(rec[i] / rec.sum()),
                                         "true": float(tru[i] / tru.sum())} for i in top_r],
                "strongest_true": [{**describe(d, i), "recovered": float(rec[i] / rec.sum()),
                                    "true": float(tru[i] / tru.sum())} for i in top_t]}
        row = {"map": name, "sources": int(d.shape[0]), "concentration": conc, "sweep": {}, "chosen": {}}
        print(f"{name}: adaptive CV chose {d.shape[0]} sources; top-10 share recovered "
              f"{conc['recovered_top10_share']:.2f}, true {conc['true_top10_share']:.2f}")
        for s in conc["strongest_recovered"]:
            print(f"   recovered: elevation {s['elevation']:5.1f} azimuth {s['azimuth']:6.1f}  share "
                  f"{s['recovered']:.3f} (true {s['true']:.3f})")
        for s in conc["strongest_true"]:
            print(f"   true:      elevation {s['elevation']:5.1f} azimuth {s['azimuth']:6.1f}  share "
                  f"{s['true']:.3f} (recovered {s['recovered']:.3f})")
        for pen in ("energy", "smoothness"):
            cv = select_regularization(sph.normals, rad, 0.7, d, WEIGHTS, pen, **KW)
            sweep = []
            for lam, score in zip(WEIGHTS, cv.scores):
                fit = hougen_ahuja(sph.normals, rad, 0.7, d, **{pen: lam}, **KW)
                L = fit.latlong(H)
                r = {"weight": lam, "relit_capture": err(L), "relit_sphere": relit_error(L, true),
                     "rerender": float(fit.relative_rms), "cv": float(score)}
                sweep.append(r)
                print(f"   {pen:10s} {lam:<6g} capture {100 * r['relit_capture']:5.1f}%  sphere "
                      f"{100 * r['relit_sphere']:6.1f}%  re-render {100 * r['rerender']:.3f}%  held-out "
                      f"{100 * r['cv']:.3f}%", flush=True)
            L = cv.fit.latlong(H)
            row["sweep"][pen] = sweep
            row["chosen"][pen] = {"weight": cv.chosen, "relit_capture": err(L), "relit_sphere": relit_error(L, true),
                                  "note": cv.note}
            print(f"   {cv.note}: capture {100 * row['chosen'][pen]['relit_capture']:.1f}%", flush=True)
        out.append(row)
    path = a.json or str(ROOT / f"benchmarks/results/probes_regularised{'_noise' if a.noise > 0 else ''}.json")
    write_json(path, {"host": host_info(), "noise": a.noise, "map_height": H, "weights": WEIGHTS, "rows": out,
                      "command": " ".join(["OMP_NUM_THREADS=1 python", "benchmarks/probes_regularised.py",
                                           *sys.argv[1:]])})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
