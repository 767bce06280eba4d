"""Benchmark of pass 2 (weighted sum of basis images), its compressed variant, and the display pass.

For each (N lights, W x H) it reports the median time (after one warm-up, ``ctx.finish()``
before stopping the clock) of pass 2 over a float16 basis in its three versions: ``compute``
and ``fragment`` (RGBA16F texture arrays, the previous method) and ``packed`` (pixel-major
float16 pairs in SSBOs, :class:`ffls.gpu.basis.PackedBasis`, the Engine's default); frames per
second, bytes moved per frame by each storage (basis read + RGBA32F output written: 8 bytes per
RGBA16F texel, 6 bytes per packed RGB value plus block padding), the resulting bandwidth as a
fraction of the device's copy bandwidth measured in the same run (``ctx.copy_buffer`` of a large
buffer; NumPy ``copyto`` for the CPU), and the NumPy float32 path
(:func:`ffls.relight.cpu.relight_fast`) as a ratio. Compressed rows (``--comp-lights`` = 160 lights,
K = 8, 16, 32, 512 x 512: the viewer's case) time the coefficient projection (GPU compute pass;
the CPU alternative, NumPy + buffer upload, beside it) plus pass 2 over K + 1 layers, for
``fragment`` and ``packed``. Combinations whose float32 basis would exceed ``--host-budget`` MiB
of host memory are skipped and listed.

    python benchmarks/bench_weighted_sum.py [--quick] [--reps 5]

Prints a table and writes ``benchmarks/results/bench_weighted_sum.json``.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ffls.gpu.basis import BasisTextures, PackedBasis
from ffls.gpu.context import create_headless_context
from ffls.gpu.weighted_sum import Projector, ToneMapPass, WeightedSum, release_gl, weights_to_vec4
from ffls.relight.cpu import relight_fast

from common import device_info, device_line, gl_copy_bandwidth, median_ms, numpy_copy_bandwidth, write_json

RESULTS = Path(__file__).resolve().parent / "results" / "bench_weighted_sum.json"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N in (64, 256), sizes 256 and 512 only")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--host-budget", type=float, default=1024, help="MiB of float32 basis on the host")
    ap.add_argument("--comp-lights", type=int, default=160, help="lights of the compressed rows")
    args = ap.parse_args(argv)

    ctx = create_headless_context()
    info = device_info(ctx)
    gl_bw, np_bw = gl_copy_bandwidth(ctx, 256 << 20, args.reps), numpy_copy_bandwidth(256 << 20, args.reps)
    print(device_line(info))
    print(f"copy bandwidth (read+write): GL copy_buffer {gl_bw / 1e9:.2f} GB/s, NumPy copyto {np_bw / 1e9:.2f} GB/s")

    ns = (64, 256) if args.quick else (64, 256, 1024)
    sizes = (256, 512) if args.quick else (256, 512, 1024)
    rng = np.random.default_rng(0)
    rows, skipped = [], []
    for s in sizes:
        tm = ToneMapPass(ctx, (s, s))
        for n in ns:
            host_mib = n * s * s * 3 * 4 / 2 ** 20
            if host_mib > args.host_budget:
                skipped.append(f"N={n} {s}x{s}: float32 basis {host_mib:.0f} MiB > host budget {args.host_budget:.0f} MiB")
                continue
            basis = rng.random((n, s, s, 3), dtype=np.float32)
            w = rng.random((n, 3))
            bt = BasisTextures(ctx, basis, "f16")
            pb = PackedBasis(ctx, basis, "f16")
            wbuf = ctx.buffer(weights_to_vec4(w))
            moved = n * s * s * 8 + s * s * 16  # RGBA16F texels read + RGBA32F written
            moved_packed = pb.nbytes + s * s * 16  # packed halves (with block padding) + RGBA32F written
            row = {"n": n, "size": s, "bytes_per_frame": moved, "bytes_per_frame_packed": moved_packed}
            for method in ("compute", "fragment", "packed"):
                ws = WeightedSum(ctx, pb if method == "packed" else bt, method)
                ms = median_ms(lambda: ws.run(wbuf), args.reps, ctx=ctx)
                row[f"{method}_ms"] = ms
                if method == "compute":
                    row["tonemap_ms"] = median_ms(lambda: tm.run(ws.output, 0.0, "aces"), args.reps, ctx=ctx)
                ws.release()
            row["numpy_f32_ms"] = median_ms(lambda: relight_fast(w, basis), max(3, args.reps // 2))
            prev = min(row["compute_ms"], row["fragment_ms"])
            row["previous_best"] = "compute" if row["compute_ms"] <= row["fragment_ms"] else "fragment"
            row["frac_copy_bw_previous"] = moved / (prev * 1e-3) / gl_bw
            best = row["packed_ms"]
            row["fps_pass2"] = 1e3 / best
            row["gbps"] = moved_packed / (best * 1e-3) / 1e9
            row["frac_copy_bw"] = moved_packed / (best * 1e-3) / gl_bw
            row["speedup_vs_previous"] = prev / best
            row["numpy_over_gl"] = row["numpy_f32_ms"] / best
            rows.append(row)
            print(f"N={n:5d} {s:4d}^2  compute {row['compute_ms']:8.1f}  fragment {row['fragment_ms']:8.1f}  "
                  f"packed {best:7.1f} ms  tonemap {row['tonemap_ms']:5.1f}  numpy {row['numpy_f32_ms']:7.1f} ms  "
                  f"packed {row['gbps']:5.2f} GB/s = {100 * row['frac_copy_bw']:5.1f}% of copy "
                  f"(previous {100 * row['frac_copy_bw_previous']:4.1f}%), x{row['speedup_vs_previous']:.1f}", flush=True)
            release_gl(wbuf)
            bt.release()
            pb.release()
            basis = None  # the host copy freed before the next size
        tm.release()

    # compressed basis rows: projection (n -> K + 1) + pass 2 over K + 1 layers
    comp_rows = []
    n, s = args.comp_lights, 512
    w = rng.random((n, 3))
    wbuf = ctx.buffer(weights_to_vec4(w))
    for K in (8, 16, 32):
        layers = rng.standard_normal((K + 1, s, s, 3)).astype(np.float32)
        P = np.ones((n, K + 1, 3), np.float32)
        P[:, 1:] = rng.standard_normal((n, K, 3)) / np.sqrt(n)
        proj = Projector(ctx, P)
        proj_ms = median_ms(lambda: proj.run(wbuf), args.reps, ctx=ctx)
        cpu_proj_ms = median_ms(lambda: proj.coeffs_buffer.write(weights_to_vec4(np.einsum("nkc,nc->kc", P, w))),
                                args.reps, ctx=ctx)
        r = {"n": n, "size": s, "K": K, "project_gpu_ms": proj_ms, "project_cpu_ms": cpu_proj_ms}
        for method in ("fragment", "packed"):
            store = (PackedBasis if method == "packed" else BasisTextures)(ctx, layers, "f16")
            ws = WeightedSum(ctx, store, method)
            ms = median_ms(lambda: ws.run(proj.coeffs_buffer), args.reps, ctx=ctx)
            moved = (store.nbytes if method == "packed" else (K + 1) * s * s * 8) + s * s * 16
            r[f"pass2_{method}_ms"] = ms
            r[f"frac_copy_bw_{method}"] = moved / (ms * 1e-3) / gl_bw
            ws.release()
            store.release()
        r["pass2_ms"] = r["pass2_packed_ms"]
        r["fps"] = 1e3 / (proj_ms + r["pass2_ms"])
        r["frac_copy_bw"] = r["frac_copy_bw_packed"]
        comp_rows.append(r)
        print(f"compressed N={n} {s}^2 K={K:3d}: project GPU {proj_ms:6.2f} ms (CPU {cpu_proj_ms:6.2f} ms), "
              f"pass2 fragment {r['pass2_fragment_ms']:7.2f} ms, packed {r['pass2_packed_ms']:6.2f} ms, "
              f"{r['fps']:6.1f} fps, {100 * r['frac_copy_bw']:5.1f}% of copy "
              f"(fragment {100 * r['frac_copy_bw_fragment']:4.1f}%)", flush=True)
        proj.release()
    release_gl(wbuf)
    for line in skipped:
        print("skipped:", line)

    out = {"device": info, "copy_bandwidth_gl_Bps": gl_bw, "copy_bandwidth_numpy_Bps": np_bw,
           "reps": args.reps, "rows": rows, "compressed": comp_rows, "skipped": skipped}
    write_json(RESULTS, out)
    ctx.release()


if __name__ == "__main__":
    main()
