"""Bake time and GPU pass-1 time of the weighting schemes, the ``spline`` scheme included.

Usage::

    python benchmarks/weighting_speed.py [--lights 256] [--res 512] [--heights 128,512] [--repeat 5]
        [--schemes voronoi,barycentric,gaussian,spline] [--json benchmarks/results/weighting_speed.json]

``--lights`` random upper-hemisphere lights (seed 0); each scheme's texture is baked once
(``voronoi``: its 256² candidate-cell texture; the others: a ``--res``² weight texture,
:func:`ffls.weights.weighting.bake_weights`), single-threaded, wall and CPU time (the machine
may be shared); then pass 1
(:class:`ffls.gpu.integrate.CellIntegrator`, technique ``sort``) on ``sky_sun_map`` of each
height, median of ``--repeat`` runs after a warm-up. ``truncated``: texels whose scheme gave more
lights than the texture's slots (the largest in magnitude kept, renormalised). Pass 1 of a weight texture makes one item per
light-map texel and slot, so its cost grows with the slots (3 for barycentric, 24 for spline);
a map whose texels x slots pass the driver's SSBO limit is refused (``n/a`` in the table).
Prints a table and writes JSON; nothing on the GPU without GL.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from common import host_info, median_seconds, write_json  # benchmarks/common.py
from ffls.conventions import rotation_z
from ffls.lightmaps.lightmap import sky_sun_map
from ffls.weights.voronoi import bake_cells
from ffls.weights.weighting import ALL_SCHEMES, bake_weights


def main(argv=None) -> int:
    from ffls.gpu.context import create_headless_context
    from ffls.gpu.integrate import CellIntegrator

    ap = argparse.ArgumentParser()
    ap.add_argument("--lights", type=int, default=256)
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--heights", default="128,512")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--schemes", default="voronoi,barycentric,gaussian,spline")
    ap.add_argument("--json", default="benchmarks/results/weighting_speed.json")
    args = ap.parse_args(argv)
    schemes = args.schemes.split(",")
    bad = [s for s in schemes if s not in ALL_SCHEMES]
    if bad:
        ap.error(f"--schemes: unknown {', '.join(bad)} (one of {', '.join(ALL_SCHEMES)})")
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(args.lights, 3))
    dirs[:, 2] = np.abs(dirs[:, 2])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    textures, bake_s, bake_cpu_s, slots, truncated = {}, {}, {}, {}, {}
    for s in schemes:
        t0, c0 = time.perf_counter(), time.process_time()
        textures[s] = bake_cells(dirs, "upper", res=256) if s == "voronoi" else bake_weights(dirs, s, "upper",
                                                                                               res=args.res)
        bake_s[s] = time.perf_counter() - t0
        bake_cpu_s[s] = time.process_time() - c0
        slots[s] = getattr(textures[s], "slots", 1)
        truncated[s] = int(getattr(textures[s], "truncated", 0))
    ctx = create_headless_context()
    renderer = ctx.info.get("GL_RENDERER", "?")
    ms = {}
    for h in (int(x) for x in args.heights.split(",")):
        lm = sky_sun_map(h)
        ms[h] = {}
        for s in schemes:
            gi = CellIntegrator(ctx, dirs, "upper", textures[s])
            try:
                gi.set_lightmap(lm)
            except ValueError as e:  # texels x slots past the SSBO limit of this driver
                print(f"{s} at {2 * h}x{h}: {e}")
                ms[h][s] = None
            else:
                ms[h][s] = median_seconds(lambda: gi.run(rotation_z(10.0)), args.repeat, ctx=ctx) * 1e3
            gi.release()
    ctx.release()
    print(f"{args.lights} lights, weight textures {args.res}^2; GPU: {renderer}")
    print(f"{'scheme':>12} {'slots':>6} {'truncated':>10} {'bake s':>8} {'bake cpu s':>10} " + " ".join(f"{f'{2 * h}x{h} ms':>12}" for h in ms))
    for s in schemes:
        print(f"{s:>12} {slots[s]:>6} {truncated[s]:>10} {bake_s[s]:>8.2f} {bake_cpu_s[s]:>10.2f} " + " ".join(f"{ms[h][s]:>12.1f}" if ms[h][s] is not None else f"{'n/a':>12}" for h in ms))
    write_json(args.json, {"args": vars(args), "host": host_info(), "renderer": renderer, "bake_s": bake_s, "bake_cpu_s": bake_cpu_s, "slots": slots, "truncated": truncated,
                           "pass1_ms": {str(h): v for h, v in ms.items()}})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
