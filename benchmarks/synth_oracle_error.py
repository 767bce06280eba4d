"""Discretisation error of the synthetic oracle (ffls.synth.scene.render_lightmap), beside relighting.

Usage: python benchmarks/synth_oracle_error.py [--res 96] [--ref 8192] [--n-dirs 512 2048]
                                              [--lights 100 400] [--out result.json]

For each light map (the procedural sky-with-sun and paper maps, 128 texels high) the oracle with
``--ref`` directions is the reference; the table gives the relative RMS and max absolute errors of
the oracle with fewer directions, and, for scale, of Voronoi relighting (ffls.weights.voronoi exact cells,
``relit = sum_i w_i B_i``) of distant-light synthetic captures with ``--lights`` lights.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from ffls.synth import scene as synth
from ffls.lightmaps.lightmap import paper_map, sky_sun_map
from ffls.weights.voronoi import integrate_weights

from common import write_json  # benchmarks/common.py


def _rel(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=96)
    ap.add_argument("--ref", type=int, default=8192)
    ap.add_argument("--n-dirs", type=int, nargs="+", default=[512, 2048])
    ap.add_argument("--lights", type=int, nargs="+", default=[100, 400])
    ap.add_argument("--out")
    a = ap.parse_args()
    scene = synth.SynthScene()
    synth.gbuffer(scene, a.res)
    rows = []
    print(f"{'map':<6} {'method':<18} {'n':>6} {'rel RMS':>9} {'max abs':>9} {'ref max':>8} {'time':>7}")
    for name, lm in (("sky", sky_sun_map(128)), ("paper", paper_map(128))):
        t = time.perf_counter()
        ref = synth.render_lightmap(scene, lm, a.res, n_dirs=a.ref)
        t_ref = time.perf_counter() - t
        cases = [("oracle", n) for n in a.n_dirs] + [("voronoi relight", n) for n in a.lights]
        for method, n in cases:
            t = time.perf_counter()
            if method == "oracle":
                img = synth.render_lightmap(scene, lm, a.res, n_dirs=n)
            else:
                dirs = synth.stratified_directions(n, "upper", seed=1)
                w = integrate_weights(lm, dirs, hemisphere="upper").weights
                img = np.einsum("nc,nhwc->hwc", w, synth.render_lights(scene, a.res, dirs))
            dt = time.perf_counter() - t
            r = {"map": name, "method": method, "n": n, "rel_rms": _rel(img, ref),
                 "max_abs": float(np.abs(img - ref).max()), "ref_max": float(ref.max()), "seconds": dt,
                 "ref_seconds": t_ref}
            rows.append(r)
            print(f"{name:<6} {method:<18} {n:>6} {r['rel_rms']:>9.5f} {r['max_abs']:>9.4f} {r['ref_max']:>8.3f} {dt:>6.1f}s",
                  flush=True)
    print(f"resolution {a.res}, reference n_dirs {a.ref}, cpus {os.cpu_count()}")
    if a.out:
        write_json(a.out, {"resolution": a.res, "ref_n_dirs": a.ref, "cpu_count": os.cpu_count(), "rows": rows})


if __name__ == "__main__":
    main()
