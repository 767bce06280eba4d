"""Speed of the angular Voronoi integration (ffls.weights.voronoi) and of CPU relighting (ffls.relight.cpu).

Usage::

    python benchmarks/voronoi_speed.py [--height 512] [--lights 50,400,2048] [--repeat 7] [--bake-res 1024]
        [--json benchmarks/results/voronoi_speed.json]

For a ``2h x h`` lat-long light map (the bundled paper map) and N random upper-hemisphere lights,
times (median of --repeat runs after a warm-up, wall clock): baking the candidate texture, the
integration with the exact k-d tree, with the candidate texture, and ``relight_fast`` of a
256x256 basis. As the reference measured in the same run: the time to copy the light-map
samples (dirs + radiance + solid angle, float64) once, i.e. the machine's copy bandwidth on the
same bytes. Then the bake of a ``--bake-res`` cell texture (upper hemisphere, k = 8) for 50, 500
and 2048 lights, hierarchical (the default) and direct, wall and CPU time (``time.process_time``,
one thread: the machine may be shared), with a check that both give the same exact lookup. Prints
tables and writes JSON.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from ffls.lightmaps.lightmap import paper_map
from ffls.relight.cpu import relight_fast, relight_reference
from ffls.weights.voronoi import assign_cells, bake_cells, integrate_weights

from common import median_seconds, write_json  # benchmarks/common.py


def gpu_pass1_rows(rng, repeat: int) -> list:
    """Pass 1 on the GPU (ffls.gpu.integrate.CellIntegrator) per weighting scheme: voronoi's
    candidate cells and the smooth schemes' weight textures (one item per texel and slot), both
    with the default technique 'sort'; 256 random upper lights, sky_sun maps of height 128 and
    512. Empty without GL."""
    from ffls.errors import GLUnavailable
    from ffls.weights.weighting import SCHEMES, bake_weights

    try:
        from ffls.gpu.context import create_headless_context
        from ffls.gpu.integrate import CellIntegrator

        ctx = create_headless_context()
    except GLUnavailable:
        return []
    from ffls.conventions import rotation_z
    from ffls.lightmaps.lightmap import sky_sun_map

    dirs = rng.normal(size=(256, 3))
    dirs[:, 2] = np.abs(dirs[:, 2])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    textures, bake_s = {}, {}
    for s in SCHEMES:
        t0 = time.perf_counter()
        textures[s] = bake_cells(dirs, "upper", res=256) if s == "voronoi" else bake_weights(dirs, s, "upper", res=512)
        bake_s[s] = time.perf_counter() - t0
    rows = []
    for h in (128, 512):
        lm = sky_sun_map(h)
        ms = {}
        for s in SCHEMES:
            gi = CellIntegrator(ctx, dirs, "upper", textures[s])
            gi.set_lightmap(lm)
            ms[s] = median_seconds(lambda: gi.run(rotation_z(10.0)), repeat, ctx=ctx) * 1e3
            gi.release()
        rows.append({"map": f"{2 * h}x{h}", "ms": ms, "bake_s": bake_s})
    ctx.release()
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--height", type=int, default=512)
    ap.add_argument("--lights", default="50,400,2048")
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--bake-res", type=int, default=1024)
    ap.add_argument("--json", default="benchmarks/results/voronoi_speed.json")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    lm = paper_map(args.height)
    samples = lm.samples()
    nbytes = sum(a.nbytes for a in samples)
    t_copy = median_seconds(lambda: [a.copy() for a in samples], args.repeat)
    rows = []
    for n in (int(s) for s in args.lights.split(",")):
        dirs = rng.normal(size=(n, 3))
        dirs[:, 2] = np.abs(dirs[:, 2])
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        R = np.eye(3)
        t_bake = median_seconds(lambda: bake_cells(dirs, "upper", res=256, max_res=1024), max(1, args.repeat // 2))
        cells = bake_cells(dirs, "upper", res=256, max_res=1024)
        t_exact = median_seconds(lambda: integrate_weights(samples, dirs, R, "upper"), args.repeat)
        t_cells = median_seconds(lambda: integrate_weights(samples, dirs, R, "upper", cells=cells), args.repeat)
        w = integrate_weights(samples, dirs, R, "upper", cells=cells).weights
        basis = rng.exponential(size=(n, 256, 256, 3)).astype(np.float32) if n <= 400 else None
        t_relight = median_seconds(lambda: relight_fast(w, basis), args.repeat) if basis is not None else float("nan")
        t_ref = median_seconds(lambda: relight_reference(w, basis), 1) if basis is not None else float("nan")
        rows.append({"n_lights": n, "bake_s": t_bake, "cells_res": cells.res, "overflow": cells.overflow,
                     "integrate_exact_s": t_exact, "integrate_cells_s": t_cells,
                     "relight_fast_256_s": t_relight, "relight_reference_256_s": t_ref,
                     "cells_vs_copy": t_cells / t_copy})
    bake_rows = []
    q = rng.normal(size=(200_000, 3))
    q[:, 2] = np.abs(q[:, 2])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    for n in (50, 500, 2048):
        dirs = rng.normal(size=(n, 3))
        dirs[:, 2] = np.abs(dirs[:, 2])
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        row = {"n_lights": n, "res": args.bake_res}
        for method in ("hierarchical", "direct"):
            walls, cpus = [], []
            for _ in range(1 if method == "direct" else 3):
                t0, c0 = time.perf_counter(), time.process_time()
                cells = bake_cells(dirs, "upper", res=args.bake_res, method=method)
                cpus.append(time.process_time() - c0)
                walls.append(time.perf_counter() - t0)
            row[f"{method}_wall_s"] = statistics.median(walls)
            row[f"{method}_cpu_s"] = statistics.median(cpus)
            row[f"{method}_overflow"] = cells.overflow
            row[f"{method}_lookup"] = assign_cells(q, dirs, cells)
        row["same_lookup"] = bool(np.array_equal(row.pop("hierarchical_lookup"), row.pop("direct_lookup")))
        bake_rows.append(row)
    pass1 = gpu_pass1_rows(rng, args.repeat)
    W, H = 2 * args.height, args.height
    print(f"light map {W}x{H} ({H * W} texels, {nbytes / 1e6:.1f} MB of samples, copy {1e3 * t_copy:.1f} ms "
          f"= {nbytes / t_copy / 1e9:.2f} GB/s), {os.cpu_count()} CPUs, median of {args.repeat}")
    print(f"{'N':>6} {'bake':>9} {'res':>5} {'exact':>9} {'cells':>9} {'cells/copy':>11} {'relight256':>11} {'ref256':>9}")
    for r in rows:
        print(f"{r['n_lights']:>6} {1e3 * r['bake_s']:>7.0f}ms {r['cells_res']:>5} {1e3 * r['integrate_exact_s']:>7.0f}ms "
              f"{1e3 * r['integrate_cells_s']:>7.0f}ms {r['cells_vs_copy']:>10.1f}x {1e3 * r['relight_fast_256_s']:>9.1f}ms "
              f"{1e3 * r['relight_reference_256_s']:>7.0f}ms")
    print(f"bake of a {args.bake_res}^2 cell texture (upper, k = 8): wall / CPU seconds")
    print(f"{'N':>6} {'hierarchical':>16} {'direct':>16} {'same lookup':>12}")
    for r in bake_rows:
        print(f"{r['n_lights']:>6} {r['hierarchical_wall_s']:>7.2f} / {r['hierarchical_cpu_s']:>5.2f} "
              f"{r['direct_wall_s']:>7.2f} / {r['direct_cpu_s']:>5.2f} {str(r['same_lookup']):>12}")
    if pass1:
        print("GPU pass 1 per weighting scheme (256 lights, weight texture 512^2): ms, and bake s")
        print(f"{'map':>10} " + " ".join(f"{s:>12}" for s in pass1[0]["ms"]))
        for r in pass1:
            print(f"{r['map']:>10} " + " ".join(f"{v:>10.1f}ms" for v in r["ms"].values()))
        print(f"{'bake':>10} " + " ".join(f"{v:>11.2f}s" for v in pass1[0]["bake_s"].values()))
    write_json(args.json, {"width": W, "height": H, "cpu_count": os.cpu_count(), "copy_s": t_copy,
                           "sample_bytes": nbytes, "rows": rows, "bake": bake_rows, "gpu_pass1": pass1})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
