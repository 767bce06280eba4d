"""Pass-2 time against the number of layers: the packed pass 2 reads float16 layers in blocks of 8.

Usage: python benchmarks/pass2_blocks.py [--res 512] [--layers 8 16 17 24 32] [--reps 7]

For each layer count L (a compressed basis of rank K has L = K + 1 layers), an Engine over
random L x res x res x 3 images; the median over ``--reps`` interleaved rounds of
``set_weights`` + ``render`` (``timings['pass2']``, after ``ctx.finish()``). Shows why the ranks
whose K + 1 is a multiple of 8 (7, 15, 23, ...) are the ones worth using.
"""
from __future__ import annotations

import argparse

import numpy as np

from ffls.gpu.context import create_headless_context
from ffls.gpu.engine import Engine

from common import device_info, device_line  # benchmarks/common.py


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--layers", type=int, nargs="+", default=[8, 16, 17, 24, 32])
    ap.add_argument("--reps", type=int, default=7)
    a = ap.parse_args()
    ctx = create_headless_context()
    print(device_line(device_info(ctx)))
    rng = np.random.default_rng(0)
    engines = {}
    for n in a.layers:
        d = rng.normal(size=(n, 3))
        d[:, 2] = np.abs(d[:, 2])
        d /= np.linalg.norm(d, axis=1)[:, None]
        engines[n] = Engine(ctx, rng.random((n, a.res, a.res, 3), dtype=np.float32), d)
    times = {n: [] for n in engines}
    for _ in range(a.reps):
        for n, e in engines.items():
            e.set_weights(rng.random((n, 3)))
            e.render()
            times[n].append(e.timings["pass2"])
    base = float(np.median(times[a.layers[0]]))
    for n in a.layers:
        t = float(np.median(times[n]))
        print(f"{n:>4} layers ({-(-n // 8)} blocks): pass 2 {t:7.1f} ms  ({t / base:.2f}x {a.layers[0]} layers)")
    for e in engines.values():
        e.release()
    ctx.release()


if __name__ == "__main__":
    main()
