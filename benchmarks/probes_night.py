"""Hougen-Ahuja on the night map: where the error sits, and the ambient term of full-sphere source sets.

    OMP_NUM_THREADS=1 python benchmarks/probes_night.py [--noise 0.01 [--seed 1]] [--maps night,studio]

The scenes and the measure are those of ``benchmarks/probes.py`` (a Lambertian ball of albedo 0.7,
80 px, seen from the relit capture's camera; the four bundled maps at 64 rows; the ``ffls synth``
capture, 150 lights, relit under the recovered vs the true map; relative RMS). Per map:

1. **the low-order limit**: the true map cut to its spherical-harmonic orders 0-2, 0-4 and 0-6,
   relit (negative texels clipped): what the best possible low-order recovery relights to (orders
   0-2 hold 99.2% of the clamped cosine's energy);
2. the default estimate before this round (adaptive set by CV, NNLS, ``ambient='nonnegative'``) and
   with ``ambient='auto'`` (no ambient with sources over the whole sphere), by CV and by BIC, with
   the ambient's share of the recovered power;
3. ``ambient='auto'`` plus the first-difference smoothness chosen by blocked CV
   (``select_regularization(..., 'smoothness')``, rule ``one_se``): ``diffuse_lightmap(smoothness='cv')``;
4. how that weight is chosen: per candidate weight its held-out relative RMS (the CV curve), the
   standard error ``one_se`` puts around the lowest (``sqrt(K)`` x the spread of the best weight's
   fold errors), the standard error of its paired fold differences from the lowest (``paired_se``),
   and the capture relit under the fit with that weight; then the weight each rule of
   ``selection.choose_weight`` picks, and its relit error (the sweep's fits are not in the CPU time).

``--seed`` seeds the noise (default 0).

Times are CPU seconds of this process (``time.process_time``). Writes
``benchmarks/results/probes_night.json`` (``..._noise.json`` with ``--noise``).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from common import (diffuse_ball, host_info, probe_benchmark_args, probe_benchmark_capture, probe_benchmark_map,
                    relit_capture_error, write_json)
from probes import H, MAPS
from ffls.probes.evaluate import relit_error, sh_basis
from ffls.conventions import normalize
from ffls.probes.estimate import SMOOTHNESS_WEIGHTS
from ffls.probes.hougen_ahuja import hougen_ahuja
from ffls.probes.selection import WEIGHT_RULES, adaptive_hougen_ahuja, choose_weight, select_regularization
from ffls.probes.sources import latlong_solid_angles
from ffls.conventions import latlong_directions

ROOT = Path(__file__).resolve().parent.parent
ORDERS = (2, 4, 6)


def low_orders(true, order):
    """The lat-long map ``true`` (h, 2h, 3) cut to its SH orders 0..``order`` (exact texel solid angles)."""
    h = true.shape[0]
    d = latlong_directions(2 * h, h).reshape(-1, 3)
    B = sh_basis(d, order)
    c = B.T @ (true.reshape(-1, 3) * latlong_solid_angles(h).reshape(-1, 1))
    return (B @ c).reshape(true.shape)


def weight_sweep(normals, rad, directions, reg, err):
    """The CV curve of ``reg`` (a ``select_regularization`` result), its standard errors, the relit
    error of every weight, and each rule's choice."""
    S = np.asarray(reg.fold_errors)
    k = S.shape[1]
    best = int(np.argmin(S.sum(axis=1)))
    ref = reg.scores[best] / np.sqrt(S[best].sum())  # relative RMS = ref * sqrt(total SSE)
    d = normalize(np.asarray(directions, dtype=np.float64))
    rows = []
    for i, lam in enumerate(reg.candidates):
        fit = reg.fit if lam == reg.chosen else hougen_ahuja(normals, rad, 0.7, d, smoothness=lam, nonnegative=True,
                                                             ambient="auto")
        diff = S[i] - S[best]
        rows.append({"weight": lam, "heldout": float(reg.scores[i]), "relit_capture": err(fit.latlong(H)),
                     "excess_sse": float(diff.sum()), "paired_se": float(np.sqrt(k) * np.std(diff, ddof=1)),
                     "folds_worse": int(np.sum(diff > 0))})
    one_se = float(np.sqrt(k) * np.std(S[best], ddof=1))
    picks = {r: reg.candidates[choose_weight(S, r)[0]] for r in WEIGHT_RULES}
    # the SEs in relative-RMS units at the best weight (d rel RMS = ref^2 / (2 rel RMS) d SSE)
    scale = ref ** 2 / (2 * reg.scores[best])
    print(f"      CV curve ({k} folds; one_se band {100 * one_se * scale:.4f} points of relative RMS):", flush=True)
    for r in rows:
        print(f"        weight {r['weight']:<6g} held-out {100 * r['heldout']:.4f}%  excess {100 * r['excess_sse'] * scale:+.4f}"
              f"  paired SE {100 * r['paired_se'] * scale:.4f}  folds worse {r['folds_worse']}/{k}  relit capture "
              f"{100 * r['relit_capture']:.1f}%", flush=True)
    by_w = {r["weight"]: r["relit_capture"] for r in rows}
    print("      rules: " + ", ".join(f"{r} {picks[r]:g} ({100 * by_w[picks[r]]:.1f}%)" for r in WEIGHT_RULES),
          flush=True)
    return {"folds": k, "one_se_sse": one_se, "weights": rows,
            "rules": {r: {"weight": picks[r], "relit_capture": by_w[picks[r]]} for r in WEIGHT_RULES}}


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(add_help=False)
    ap.add_argument("--seed", type=int, default=0)
    seed_args, rest = ap.parse_known_args(argv if argv is not None else sys.argv[1:])
    a = probe_benchmark_args(__doc__, MAPS, rest)
    rng = np.random.default_rng(seed_args.seed)
    cap, lights = probe_benchmark_capture("ffls_probes_night_")
    out = []
    for name in a.maps.split(","):
        lm, true, truth = probe_benchmark_map(name, H, cap, lights)

        def err(L):
            return relit_capture_error(cap, lights, L, truth)

        row = {"map": name, "low_order_limit": {str(o): err(low_orders(true, o)) for o in ORDERS}, "rows": []}
        print(f"{name}: true map cut to SH orders 0-2 / 0-4 / 0-6 relights "
              + " / ".join(f"{100 * row['low_order_limit'][str(o)]:.1f}%" for o in ORDERS), flush=True)
        sph, rad = diffuse_ball(lm, cap, a.noise, rng)
        for crit in ("cv", "bic"):
            for amb in ("nonnegative", "auto"):
                t = time.process_time()
                sel = adaptive_hougen_ahuja(sph.normals, rad, 0.7, criterion=crit, nonnegative=True, ambient=amb)
                cpu = time.process_time() - t
                L = sel.fit.latlong(H)
                power = float(np.abs(sel.fit.intensities).sum() + 4 * np.sum(sel.fit.ambient))
                r = {"criterion": crit, "ambient": amb, "smoothness": 0.0, "sources": sel.chosen,
                     "relit_capture": err(L), "relit_sphere": relit_error(L, true),
                     "ambient_share": float(4 * np.sum(sel.fit.ambient) / power), "cpu_s": cpu}
                row["rows"].append(r)
                print(f"   {crit} ambient={amb:11s} {sel.chosen:3d} sources: capture {100 * r['relit_capture']:5.1f}%  "
                      f"sphere {100 * r['relit_sphere']:6.1f}%  ambient share {r['ambient_share']:.3f}  "
                      f"{cpu:.1f} CPU s", flush=True)
                if crit == "cv" and amb == "auto":
                    t = time.process_time()
                    reg = select_regularization(sph.normals, rad, 0.7, sel.fit.directions, penalty="smoothness",
                                                nonnegative=True, ambient=amb)
                    cpu2 = cpu + time.process_time() - t
                    L = reg.fit.latlong(H)
                    r = {"criterion": crit, "ambient": amb, "smoothness": "cv", "chosen_weight": reg.chosen,
                         "sources": sel.chosen, "relit_capture": err(L), "relit_sphere": relit_error(L, true),
                         "cpu_s": cpu2}
                    r["sweep"] = weight_sweep(sph.normals, rad, sel.fit.directions, reg, err)
                    row["rows"].append(r)
                    print(f"   {crit} ambient={amb:11s} smoothness cv ({reg.chosen:g}): capture "
                          f"{100 * r['relit_capture']:5.1f}%  sphere {100 * r['relit_sphere']:6.1f}%  {cpu2:.1f} CPU s",
                          flush=True)
        out.append(row)
    tag = ("_noise" if a.noise > 0 else "") + (f"_seed{seed_args.seed}" if seed_args.seed else "")
    path = a.json or str(ROOT / f"benchmarks/results/probes_night{tag}.json")
    write_json(path, {"host": host_info(), "noise": a.noise, "seed": seed_args.seed, "map_height": H, "rows": out,
                      "command": " ".join(["OMP_NUM_THREADS=1 python", "benchmarks/probes_night.py", *sys.argv[1:]])})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
