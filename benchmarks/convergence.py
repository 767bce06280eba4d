"""Convergence of Voronoi relighting to the direct render as the number of lights grows.

For each N, a distant-light capture of the built-in synthetic scene (``ffls.synth.scene``) with N
stratified light directions is relit under a smooth light map (Masselus et al. 2002, section 6:
angular Voronoi weights, exact k-d tree cells and the candidate texture) and compared with the
oracle :func:`ffls.synth.scene.render_lightmap`, which lights the scene directly by the map reduced to
``--oracle-dirs`` distant lights. Error: relative RMS over all pixels and channels,
``||relit - oracle|| / ||oracle||``, and the 99th percentile of the per-pixel relative error on
pixels brighter than 5 % of the mean.

Usage::

    python benchmarks/convergence.py [--res 64] [--lights 50,100,200,400] [--map sky|paper]
                                     [--oracle-dirs 2048] [--json benchmarks/results/convergence.json]

Prints a table and writes JSON (with the CPU count and the timings: median of --repeat runs of
the weight integration after a warm-up).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from ffls.synth import scene as synth
from ffls.lightmaps.lightmap import paper_map, sky_sun_map
from ffls.relight.cpu import relight_fast, relight_reference
from ffls.weights.voronoi import bake_cells, integrate_weights

from common import host_info, median_seconds, write_json  # benchmarks/common.py


def smooth_map(name: str, height: int):
    if name == "sky":
        return sky_sun_map(height, sun_irradiance=0.0)  # the procedural sky without its sun
    if name == "paper":
        return paper_map(height)
    raise SystemExit(f"unknown map {name!r}")


def errors(relit: np.ndarray, oracle: np.ndarray) -> tuple[float, float]:
    relit = relit.astype(np.float64)
    oracle = oracle.astype(np.float64)
    rms = float(np.linalg.norm(relit - oracle) / np.linalg.norm(oracle))
    lum = oracle.mean(axis=-1)
    bright = lum > 0.05 * lum.mean()
    rel = np.abs(relit - oracle).mean(axis=-1)[bright] / lum[bright]
    return rms, float(np.percentile(rel, 99))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--lights", default="50,100,200,400")
    ap.add_argument("--map", default="sky", choices=("sky", "paper"))
    ap.add_argument("--map-height", type=int, default=256)
    ap.add_argument("--oracle-dirs", type=int, default=2048)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", default="benchmarks/results/convergence.json")
    args = ap.parse_args(argv)

    scene = synth.SynthScene()
    lm = smooth_map(args.map, args.map_height)
    t0 = time.perf_counter()
    oracle = synth.render_lightmap(scene, lm, args.res, n_dirs=args.oracle_dirs)
    t_oracle = time.perf_counter() - t0
    rows = []
    for n in (int(s) for s in args.lights.split(",")):
        dirs = synth.stratified_directions(n, "upper", seed=args.seed)
        basis = synth.render_lights(scene, args.res, dirs)
        cells = bake_cells(dirs, "upper", res=256, max_res=1024)
        t_integrate = median_seconds(lambda: integrate_weights(lm, dirs, hemisphere="upper", cells=cells), args.repeat)
        w = integrate_weights(lm, dirs, hemisphere="upper", cells=cells)
        w_exact = integrate_weights(lm, dirs, hemisphere="upper")
        ref = relight_reference(w_exact.weights, basis)
        fast = relight_fast(w.weights, basis)
        rms, p99 = errors(ref, oracle)
        rms_fast, _ = errors(fast, oracle)
        rows.append({"n_lights": n, "rel_rms": rms, "rel_p99": p99, "rel_rms_fast_cells": rms_fast,
                     "cells_res": cells.res, "cells_overflow": cells.overflow,
                     "weights_equal": bool(np.array_equal(w.weights, w_exact.weights)),
                     "integrate_s_median": t_integrate})
    print(f"map {args.map} ({lm.data.shape[1]}x{lm.data.shape[0]}), image {args.res}x{args.res}, "
          f"oracle {args.oracle_dirs} dirs ({t_oracle:.1f} s), {host_info()['cpu_count']} CPUs")
    print(f"{'N':>6} {'rel RMS':>10} {'p99 rel':>10} {'fast+cells':>11} {'cells==exact':>13} {'integrate':>10}")
    for r in rows:
        print(f"{r['n_lights']:>6} {r['rel_rms']:>10.4f} {r['rel_p99']:>10.4f} {r['rel_rms_fast_cells']:>11.4f} "
              f"{str(r['weights_equal']):>13} {1e3 * r['integrate_s_median']:>8.1f}ms")
    out = {"map": args.map, "map_height": args.map_height, "res": args.res, "oracle_dirs": args.oracle_dirs,
           **host_info(), "oracle_s": t_oracle, "rows": rows}
    write_json(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
