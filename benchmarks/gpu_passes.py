"""Time every GPU pass of ffls at the sizes a user has, on whatever device the context gets.

Written for the first run on a real GPU (an NVIDIA H100, docs/gpu.md "On an NVIDIA H100"); the
same script on llvmpipe gives the ratios. Per pass, the median over ``--reps`` runs after a
warm-up, timed two ways: GL time-elapsed queries (the GPU's own clock; ``gpu_ms``) and the host
clock around the submission plus ``ctx.finish()`` (``wall_ms``). Rows:

* ``bandwidth``: the device's own memory ceilings measured here: a compute shader reading a
  large SSBO once (``read``, bytes read / time) and ``copy_buffer`` (bytes read + written).
* ``pass1``: ``CellIntegrator.run(R)`` (rotation, hemisphere test, per-cell integration) for
  each technique, N lights x lat-long maps 512..2048 wide, a new rotation every run.
* ``pass2``: ``WeightedSum.run`` for each method over a float16 basis of N photos at S^2; the
  bytes of the basis read once per frame over the measured read bandwidth give the floor, and
  ``floor_frac`` = floor / time (1.0 = at the floor).
* ``compressed``: ``Projector.run`` (rank-K projection) and pass 2 over K + 1 layers.
* ``tonemap``: ``ToneMapPass.run`` at S^2.
* ``frame``: an :class:`ffls.gpu.engine.Engine` frame (pass 1 + pass 2 + display) rotated every
  frame, with the engine's per-pass timings.
* ``auto``: :func:`ffls.gpu.engine.gpu_frame_ms` (the ``--quality auto`` timer) for every
  candidate of :func:`ffls.relight.auto.candidate_qualities`.
* ``cli``: wall time of ``ffls render`` (one EXR) and ``ffls render --turntable N`` on a capture
  made by ``ffls synth`` (``--capture-lights``, ``--capture-res``), process start included.

``python benchmarks/gpu_passes.py --preset h100 --out benchmarks/results/gpu_passes_h100.json``
(sizes of real captures; needs ~40 GiB of host memory and ~9 GiB of GPU memory; on an H100
the whole preset takes longer than one 10-minute device call, mostly building the large bases on
the host, so run it in parts with ``--only``, ``--p2`` and ``--frame``);
``--preset llvmpipe`` runs the same rows at sizes a CPU rasteriser finishes.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ffls.conventions import rotation_ypr, rotation_z
from ffls.gpu.basis import BasisTextures, PackedBasis
from ffls.gpu.context import create_headless_context, is_software_renderer, release_gl
from ffls.gpu.engine import Engine, gpu_frame_ms
from ffls.gpu.integrate import CellIntegrator
from ffls.gpu.weighted_sum import Projector, ToneMapPass, WeightedSum, weights_to_vec4
from ffls.lightmaps.lightmap import sky_sun_map
from ffls.weights.voronoi import bake_cells

from common import device_info, device_line, write_json

PRESETS = {
    # (lights, map heights) of pass 1; (N, S) of pass 2; packed up to this many MiB of basis.
    # The llvmpipe rows are a subset of the h100 rows, for ratios.
    "h100": {"p1_lights": (256, 1024, 1500), "p1_heights": (256, 512, 1024),
             "p2": ((256, 512), (256, 1024), (1024, 1024), (256, 2048)),
             "packed_mib": 1024, "fragment_mib": 16384, "comp_n": 1024, "chunk_layers": (256, 64), "ranks": (8, 16, 32, 64),
             "comp_sizes": (512, 1024, 2048), "frame": ((256, 512), (256, 1024), (1024, 1024)),
             "auto": (64, 256), "read_mib": 2048, "capture": (64, 256), "turntable": 24},
    "llvmpipe": {"p1_lights": (256, 1024), "p1_heights": (256, 512),
                 "p2": ((256, 512),), "packed_mib": 4096, "fragment_mib": 4096, "comp_n": 1024, "chunk_layers": (64,),
                 "ranks": (8, 16, 32), "comp_sizes": (512,), "frame": ((256, 512),),
                 "auto": (64, 256), "read_mib": 256, "capture": (64, 256), "turntable": 24},
}

#: True on a CPU rasteriser (set by main from the renderer string).
SOFTWARE = False

READ_SHADER = """#version 430 core
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Src { uvec4 src[]; };
layout(std430, binding = 1) writeonly buffer Dst { uint dst[]; };
uniform uint u_n;
uniform uint u_stride;
void main() {
    uint acc = 0u;
    for (uint i = gl_GlobalInvocationID.x; i < u_n; i += u_stride) {
        uvec4 v = src[i];
        acc ^= v.x ^ v.y ^ v.z ^ v.w;
    }
    dst[gl_GlobalInvocationID.x] = acc;
}
"""


def timed(ctx, fn, reps: int, warmup: int = 1, setup=None) -> dict:
    """Median GPU (time-elapsed query) and wall (submission + ``ctx.finish()``) ms of ``fn()``.

    ``setup(k)`` runs before run ``k`` (outside both clocks), e.g. to set a new rotation.
    """
    q = ctx.query(time=True)
    gpu, wall = [], []
    for k in range(warmup + reps):
        if setup is not None:
            setup(k)
        ctx.finish()
        t0 = time.perf_counter()
        with q:
            fn()
        ctx.finish()
        t1 = time.perf_counter()
        if k >= warmup:
            wall.append((t1 - t0) * 1e3)
            gpu.append(q.elapsed * 1e-6)
    del q  # moderngl's Query has no release(); the context's gc frees it
    g, w = float(statistics.median(gpu)), float(statistics.median(wall))
    # ms: the GPU's clock on a GPU; the wall clock on a CPU rasteriser (llvmpipe's queries time
    # neither its compute dispatches nor its threads)
    return {"ms": w if SOFTWARE else g, "gpu_ms": g, "wall_ms": w, "gpu_ms_min": float(min(gpu)),
            "gpu_ms_max": float(max(gpu))}


def upper_directions(rng, n: int) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.05
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def random_basis(rng, n: int, s: int, dtype=np.float16) -> np.ndarray:
    """``(n, s, s, 3)`` positive values: 8 random images repeated (content does not change the
    bytes a pass reads; generating every image would dominate the script's time)."""
    block = (0.05 + rng.random((min(n, 8), s, s, 3), dtype=np.float32)).astype(dtype)
    reps = -(-n // block.shape[0])
    return np.concatenate([block] * reps)[:n]


def bandwidth(ctx, mib: int, reps: int) -> dict:
    nbytes = mib << 20
    src = ctx.buffer(reserve=nbytes)
    dst = ctx.buffer(reserve=nbytes)
    src.write(np.arange(nbytes // 4, dtype=np.uint32).tobytes())  # real data, not zeros
    prog = ctx.compute_shader(READ_SHADER)
    groups = 132 * 16
    out = ctx.buffer(reserve=4 * 256 * groups)
    prog["u_n"].value = nbytes // 16
    prog["u_stride"].value = 256 * groups
    src.bind_to_storage_buffer(0)
    out.bind_to_storage_buffer(1)
    r = timed(ctx, lambda: prog.run(groups, 1, 1), reps)
    c = timed(ctx, lambda: ctx.copy_buffer(dst, src), reps)
    row = {"bytes": nbytes, "read_ms": r["ms"], "read_Bps": nbytes / (r["ms"] * 1e-3),
           "copy_ms": c["ms"], "copy_Bps": 2 * nbytes / (c["ms"] * 1e-3)}
    for o in (src, dst, out, prog):
        release_gl(o)
    return row


def bench_pass1(ctx, rng, lights, heights, reps, rec) -> None:
    for n in lights:
        d = upper_directions(rng, n)
        cells = bake_cells(d, "upper", 256, k=8)
        for h in heights:
            lm = sky_sun_map(h)
            for m in ("blend", "atomic", "sort"):
                integ = CellIntegrator(ctx, d, "upper", cells, method=m)
                integ.set_lightmap(lm)
                Rs = [rotation_ypr(10.0 * k, 3.0 * k, -2.0 * k) for k in range(reps + 1)]
                state = {}
                t = timed(ctx, lambda: integ.run(state["R"]), reps, setup=lambda k: state.update(R=Rs[k]))
                a = integ.run(Rs[0]).read()
                t["repeatable"] = a == integ.run(Rs[0]).read()
                rec("pass1", {"n": n, "map": f"{2 * h}x{h}", "texels": 2 * h * h, "method": m, **t})
                print(f"pass1 N={n:5d} map {2 * h:5d}x{h:<5d} {m:7s} {t['ms']:8.3f} ms  "
                      f"wall {t['wall_ms']:8.3f} ms  repeatable {t['repeatable']}", flush=True)
                integ.release()
                ctx.gc()


def bench_pass2(ctx, rng, sizes, reps, read_bps, packed_mib, fragment_mib, chunk_layers, rec) -> None:
    tone = set()
    for n, s in sizes:
        basis = random_basis(rng, n, s)
        w = rng.random((n, 3)) / n
        wbuf = ctx.buffer(weights_to_vec4(w))
        t0 = time.perf_counter()
        bt = BasisTextures(ctx, basis, "f16", budget_bytes=1 << 62)
        upload_s = time.perf_counter() - t0
        stores = [("compute", bt), ("fragment", bt)]
        # the same compute pass over arrays of fewer layers (one dispatch per array)
        stores += [(f"compute/{ml}", ml) for ml in chunk_layers if ml < n]
        if n * s * s * 6 / 2 ** 20 <= packed_mib:
            stores.append(("packed", None))
        for label, store in stores:
            method = label.split("/")[0]
            if method == "fragment" and bt.nbytes / 2 ** 20 > fragment_mib:
                continue
            if store is None:
                store = PackedBasis(ctx, basis, "f16", budget_bytes=1 << 62)
            elif isinstance(store, int):
                store = BasisTextures(ctx, basis, "f16", max_layers=store, budget_bytes=1 << 62)
            read = store.nbytes  # the basis read once (RGBA16F texels; packed: its words)
            ws = WeightedSum(ctx, store, method)
            t = timed(ctx, lambda: ws.run(wbuf), reps)
            floor_ms = (read + s * s * 16) / read_bps * 1e3
            row = {"n": n, "size": s, "method": label, "basis_bytes": read, "upload_s": upload_s, **t,
                   "floor_ms": floor_ms, "floor_frac": floor_ms / t["ms"],
                   "GBps": (read + s * s * 16) / (t["ms"] * 1e-3) / 1e9}
            rec("pass2", row)
            print(f"pass2 N={n:5d} {s:5d}^2 {label:12s} {t['ms']:8.3f} ms  wall {t['wall_ms']:8.3f} ms  "
                  f"{row['GBps']:7.1f} GB/s  floor {floor_ms:7.3f} ms = {100 * row['floor_frac']:5.1f}%",
                  flush=True)
            if method == "compute" and s not in tone:
                tm = ToneMapPass(ctx, (s, s))
                tt = timed(ctx, lambda: tm.run(ws.output, 0.5, "aces"), reps)
                tone.add(s)
                rec("tonemap", {"size": s, **tt})
                print(f"tonemap {s:5d}^2 {tt['ms']:8.3f} ms  wall {tt['wall_ms']:8.3f} ms", flush=True)
                tm.release()
            ws.release()
            if store is not bt:
                store.release()
        bt.release()
        release_gl(wbuf)
        basis = None
        ctx.gc()


def bench_compressed(ctx, rng, n, sizes, ranks, reps, read_bps, rec) -> None:
    w = rng.random((n, 3)) / n
    wbuf = ctx.buffer(weights_to_vec4(w))
    for s in sizes:
        for K in ranks:
            layers = random_basis(rng, K + 1, s, np.float32) - 0.5
            P = np.ones((n, K + 1, 3), np.float32)
            P[:, 1:] = rng.standard_normal((n, K, 3)) / np.sqrt(n)
            proj = Projector(ctx, P)
            tp = timed(ctx, lambda: proj.run(wbuf), reps)
            bt = BasisTextures(ctx, layers, "f16")
            ws = WeightedSum(ctx, bt, "compute")
            t = timed(ctx, lambda: ws.run(proj.coeffs_buffer), reps)
            floor_ms = (bt.nbytes + s * s * 16) / read_bps * 1e3
            rec("compressed", {"n": n, "size": s, "K": K, "project_ms": tp["ms"], "project_wall_ms": tp["wall_ms"],
                         **t, "floor_ms": floor_ms, "floor_frac": floor_ms / t["ms"]})
            print(f"compressed N={n} {s:5d}^2 K={K:3d}: project {tp['ms']:7.3f} ms, pass2 compute "
                  f"{t['ms']:7.3f} ms wall {t['wall_ms']:7.3f} ms, floor {100 * floor_ms / t['ms']:5.1f}%",
                  flush=True)
            for o in (ws, bt, proj):
                o.release()
    release_gl(wbuf)


def bench_frames(ctx, rng, sizes, reps, rec) -> None:
    lm = sky_sun_map(512)
    for n, s in sizes:
        basis = random_basis(rng, n, s, np.float32)
        d = upper_directions(rng, n)
        for method in ("auto", "packed"):
            if method == "packed" and n * s * s * 6 > 4 << 30:
                continue
            eng = Engine(ctx, basis, d, "upper", method=method, budget_bytes=1 << 62)
            eng.set_lightmap(lm)
            per = {}

            def setup(k):
                eng.set_rotation(rotation_z(5.0 * (k + 1)))
                if k > 1:  # frame k - 1's per-pass times (profile=True: finish after each pass); 0 is the warm-up
                    for name, v in eng.timings.items():
                        per.setdefault(name, []).append(v)

            t = timed(ctx, lambda: eng.render(0.0, "aces"), reps, setup=setup)
            for name, v in eng.timings.items():  # the last frame's
                per.setdefault(name, []).append(v)
            row = {"n": n, "size": s, "method": eng.method, **t,
                   "pass_wall_ms": {k: float(statistics.median(v)) for k, v in per.items()}}
            rec("frame", row)
            print(f"frame N={n:5d} {s:5d}^2 {eng.method:8s} {t['ms']:8.3f} ms  wall {t['wall_ms']:8.3f} ms  "
                  + "  ".join(f"{k} {v:.3f}" for k, v in row["pass_wall_ms"].items()), flush=True)
            eng.release()
            ctx.gc()
        basis = None


def bench_auto(ctx, rng, n, s, rec) -> None:
    from ffls.relight.auto import candidate_qualities
    from ffls.relight.compress import compress_basis

    basis = random_basis(rng, n, s, np.float32)
    d = upper_directions(rng, n)
    lm = sky_sun_map(512)
    cands = candidate_qualities(n)
    kmax = max((q.rank for q in cands if q.rank is not None), default=None)
    comp = compress_basis(basis, kmax) if kmax else None
    for q in cands:
        ms = gpu_frame_ms(ctx, basis, d, lm, q, frames=5, compressed=comp)
        rec("auto", {"quality": q.__dict__, "ms": ms})
        print(f"auto N={n} {s}^2 {q.weighting:11s} {q.precision} rank {q.rank} subset {q.basis_subset} "
              f"map {q.map_res}: {ms:8.3f} ms/frame", flush=True)


def bench_cli(lights, res, turntable, rec) -> None:
    exe = [sys.executable, "-m", "ffls"]
    with tempfile.TemporaryDirectory() as tmp:
        cap = Path(tmp) / "cap"
        subprocess.run(exe + ["synth", str(cap), "--lights", str(lights), "--resolution", str(res), "--quiet"],
                       check=True)
        row = {"lights": lights, "res": res, "turntable": turntable}
        for name, extra in (("render_exr", ["-o", str(Path(tmp) / "out.exr")]),
                            ("turntable_png", ["--turntable", str(turntable), "-o", str(Path(tmp) / "tt")]),
                            ("render_cpu_exr", ["--cpu", "-o", str(Path(tmp) / "cpu.exr")])):
            ts = []
            for _ in range(3):
                t0 = time.perf_counter()
                subprocess.run(exe + ["render", str(cap), "--probe", "courtyard"] + extra, check=True,
                               capture_output=True)
                ts.append(time.perf_counter() - t0)
            row[f"{name}_s"] = float(statistics.median(ts))
            print(f"cli {name} ({lights} lights, {res}^2): {row[f'{name}_s']:.2f} s", flush=True)
        rec("cli", row)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", choices=sorted(PRESETS), default="llvmpipe")
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--only", nargs="+", default=["bandwidth", "pass1", "pass2", "compressed", "tonemap", "frame",
                                                  "auto", "cli"])
    ap.add_argument("--p2", nargs="+", metavar="N,S", help="pass-2 sizes instead of the preset's")
    ap.add_argument("--frame", nargs="+", metavar="N,S", help="whole-frame sizes instead of the preset's")
    ap.add_argument("--peak-gbps", type=float,
                    help="memory bandwidth for the pass-2 floors, GB/s (e.g. a CUDA device-to-device copy measured "
                         "on the same machine, bytes read + written / time); default: the read kernel's, measured here")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "gpu_passes.json"))
    args = ap.parse_args(argv)
    P = PRESETS[args.preset]
    ctx = create_headless_context()
    info = device_info(ctx)
    global SOFTWARE
    SOFTWARE = is_software_renderer(info["renderer"])
    print(device_line(info), flush=True)
    rng = np.random.default_rng(10)
    doc = {"device": info, "preset": args.preset, "reps": args.reps, "command": " ".join(sys.argv)}
    out = Path(args.out)

    def rec(key, row):  # every row is written at once: a run cut by a time limit keeps its rows
        doc.setdefault(key, []).append(row)
        write_json(out, doc, quiet=True)

    bw = bandwidth(ctx, P["read_mib"], args.reps)
    doc["bandwidth"] = bw
    peak = bw["read_Bps"] if args.peak_gbps is None else args.peak_gbps * 1e9
    doc["floor_Bps"] = peak
    print(f"bandwidth: read {bw['read_Bps'] / 1e9:.1f} GB/s, copy_buffer (read+write) {bw['copy_Bps'] / 1e9:.1f} GB/s; "
          f"floors at {peak / 1e9:.1f} GB/s", flush=True)
    if "pass1" in args.only:
        bench_pass1(ctx, rng, P["p1_lights"], P["p1_heights"], args.reps, rec)
    if "pass2" in args.only:
        p2 = [tuple(int(v) for v in x.split(",")) for x in args.p2] if args.p2 else P["p2"]
        bench_pass2(ctx, rng, p2, args.reps, peak, P["packed_mib"], P["fragment_mib"], P["chunk_layers"], rec)
    if "compressed" in args.only:
        bench_compressed(ctx, rng, P["comp_n"], P["comp_sizes"], P["ranks"], args.reps, peak, rec)
    if "cli" in args.only:
        lights, res = P["capture"]
        bench_cli(lights, res, P["turntable"], rec)
    if "auto" in args.only:
        bench_auto(ctx, rng, *P["auto"], rec)
    if "frame" in args.only:
        fr = [tuple(int(v) for v in x.split(",")) for x in args.frame] if args.frame else P["frame"]
        bench_frames(ctx, rng, fr, args.reps, rec)
    write_json(out, doc)
    ctx.release()


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
