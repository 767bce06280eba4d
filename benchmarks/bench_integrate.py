"""Benchmark pass 1 (per-cell light-map integration): the three GPU techniques vs NumPy.

For N lights (random, upper hemisphere) and lat-long light maps of 2h x h texels, times
``CellIntegrator.run(R)`` + ``ctx.finish()`` per technique ('blend', 'atomic', 'sort'), the
float64 reference ``integrate_weights(..., cells=)`` and a fast float32 NumPy path; reports the
median of ``--repeat`` runs after one warm-up, the ratio NumPy-float64 / GPU, and the accuracy of
every path (max relative error over cells holding >= 1e-6 of the power) against the float64
reference. Prints a table and writes JSON (default ``benchmarks/results/bench_integrate.json``).

    python benchmarks/bench_integrate.py [--repeat 5] [--lights 64 256 1024] [--heights 128 256 512]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ffls.conventions import rotation_ypr
from ffls.gpu.context import create_headless_context
from ffls.gpu.integrate import METHODS, CellIntegrator
from ffls.lightmaps.lightmap import sky_sun_map
from ffls.weights.voronoi import bake_cells, integrate_weights

from common import device_info, device_line, median_seconds, write_json  # benchmarks/common.py


def numpy_fast(samples32, R, cells, n):
    """float32 rotation, candidate lookup, float32 per-cell sums (np.add.at on float32)."""
    dirs32, power32 = samples32
    p = dirs32 @ R.astype(np.float32).T
    keep = p[:, 2] >= 0
    idx = cells.assign(p[keep].astype(np.float64))
    w = np.zeros((n, 3), dtype=np.float32)
    ok = idx >= 0
    np.add.at(w, idx[ok], power32[keep][ok])
    return w


def rel_err(w, ref):
    total = ref.total_power
    big = np.abs(ref.weights) >= 1e-6 * np.abs(total)[None, :]
    return float(np.max(np.abs(w - ref.weights)[big] / np.abs(ref.weights)[big]))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--lights", type=int, nargs="+", default=[64, 256, 1024])
    ap.add_argument("--heights", type=int, nargs="+", default=[128, 256, 512])
    ap.add_argument("--cell-res", type=int, default=128)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_integrate.json"))
    args = ap.parse_args(argv)

    ctx = create_headless_context()
    dev = device_info(ctx)
    device = {k: dev[k] for k in ("renderer", "version", "backend", "cpu_count", "machine")}
    print(device_line(device))
    rng = np.random.default_rng(0)
    R = rotation_ypr(37.0, 21.0, -8.0)
    rows = []
    hdr = f"{'N':>5} {'map':>10} {'texels':>8} " + " ".join(f"{m + ' ms':>10}" for m in METHODS) \
        + f" {'np64 ms':>9} {'np32 ms':>9} {'np64/best':>9}  max rel err (" + ", ".join(METHODS) + ", np32)"
    print(hdr)
    for n in args.lights:
        d = rng.normal(size=(n, 3))
        d[:, 2] = np.abs(d[:, 2])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        cells = bake_cells(d, "upper", args.cell_res, k=8)
        for h in args.heights:
            lm = sky_sun_map(h)
            dirs, rad, sa = lm.samples()
            power = rad * sa[:, None]
            ref = integrate_weights(lm, d, R, "upper", cells=cells)
            row = {"n_lights": n, "map": f"{2 * h}x{h}", "texels": int(dirs.shape[0]),
                   "cell_res": cells.res, "cell_overflow": cells.overflow}
            for m in METHODS:
                gpu = CellIntegrator(ctx, d, "upper", cells, method=m)
                gpu.set_lightmap(lm)
                row[f"{m}_s"] = median_seconds(lambda: gpu.run(R), args.repeat, ctx=ctx)
                row[f"{m}_rel_err"] = rel_err(gpu.read_weights().astype(np.float64), ref)
                a = gpu.run(R).read()
                row[f"{m}_repeatable"] = a == gpu.run(R).read()
                gpu.release()
                ctx.gc()
            row["numpy64_s"] = median_seconds(lambda: integrate_weights(lm, d, R, "upper", cells=cells),
                                              max(1, min(args.repeat, 3)))
            s32 = (dirs.astype(np.float32), power.astype(np.float32))
            row["numpy32_s"] = median_seconds(lambda: numpy_fast(s32, R, cells, n), max(1, min(args.repeat, 3)))
            row["numpy32_rel_err"] = rel_err(numpy_fast(s32, R, cells, n).astype(np.float64), ref)
            best = min(row[f"{m}_s"] for m in METHODS)
            row["numpy64_over_best_gpu"] = row["numpy64_s"] / best
            rows.append(row)
            print(f"{n:>5} {row['map']:>10} {row['texels']:>8} "
                  + " ".join(f"{1e3 * row[m + '_s']:>10.2f}" for m in METHODS)
                  + f" {1e3 * row['numpy64_s']:>9.1f} {1e3 * row['numpy32_s']:>9.1f} {row['numpy64_over_best_gpu']:>9.1f}  "
                  + ", ".join(f"{row[m + '_rel_err']:.1e}" for m in METHODS) + f", {row['numpy32_rel_err']:.1e}",
                  flush=True)
    wins = {m: sum(1 for r in rows if min(METHODS, key=lambda k: r[k + '_s']) == m) for m in METHODS}
    print("fastest technique per configuration:", wins)
    write_json(args.out, {"device": device, "repeat": args.repeat, "rotation_ypr": [37.0, 21.0, -8.0],
                          "rows": rows, "fastest_counts": wins}, indent=2)
    ctx.release()


if __name__ == "__main__":
    main()
