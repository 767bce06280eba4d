"""Exposure-bracket merging (hat weights, times t^2: Robertson et al. 2003): error against the known radiance.

A scene spanning 3 decades (plus a sun no exposure holds) is stored as sRGB 8- and 16-bit PNG
brackets (4 exposures, 1/250 to 1/4 s, 2 stops apart) and merged by ``ffls.probes.bracket``
(the default, ``merge_exposures_Robertson2003``, and the hat weights alone,
``merge_exposures_DebevecMalik1997``); also through OpenCV's ``MergeDebevec`` (8-bit only) with
the same sRGB curve, for comparison. The "noisy" rows add a camera's read noise (Gaussian, 0.004
of full scale in linear values, clipped at black) before the 8-bit sRGB encoding.
Reported: median and 99th-percentile relative error over the pixels not saturated in every
exposure, and how many pixels were flagged.

Run: ``OMP_NUM_THREADS=1 python benchmarks/probe_bracket.py``
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import cv2
import numpy as np

from ffls.probes.bracket import merge_bracket_files, merge_exposures
from ffls.radiance.encoding import srgb_decode, srgb_encode

TIMES = (1 / 250, 1 / 60, 1 / 15, 1 / 4)


def main():
    rng = np.random.default_rng(0)
    L = 10 ** rng.uniform(0.0, 3.0, (256, 256, 1)) * rng.uniform(0.5, 1.0, (256, 256, 3))
    L[:8, :8] = 1e6
    tmp = Path(tempfile.mkdtemp())
    print(f"{'input':22s} {'median':>8s} {'p99':>8s} {'flagged':>8s}")
    for bits in (8, 16):
        top = 255 if bits == 8 else 65535
        paths, codes = [], []
        for k, t in enumerate(TIMES):
            c = np.rint(srgb_encode(np.clip(L * t / 50.0, 0, 1)) * top).astype(np.uint8 if bits == 8 else np.uint16)
            p = tmp / f"b{bits}_{k}.png"
            cv2.imwrite(str(p), c[..., ::-1])
            paths.append(p)
            codes.append(c)
        m = merge_bracket_files(paths, TIMES, "srgb")
        ok = ~m.saturated
        rel = np.abs(m.radiance * 50.0 - L)[ok] / L[ok]
        print(f"ffls {bits}-bit{'':13s} {100 * np.median(rel):7.3f}% {100 * np.percentile(rel, 99):7.3f}% "
              f"{int(m.saturated.sum()):8d}")
        if bits == 8:
            curve = np.repeat(srgb_decode(np.arange(256) / 255.0)[:, None], 3, axis=1).astype(np.float32)
            cv = cv2.createMergeDebevec().process([c[..., ::-1].copy() for c in codes],
                                                  np.asarray(TIMES, np.float32), curve.reshape(256, 1, 3))
            rel = np.abs(cv[..., ::-1] * 50.0 - L)[ok] / L[ok]
            print(f"OpenCV MergeDebevec 8-bit {100 * np.median(rel):7.3f}% {100 * np.percentile(rel, 99):7.3f}% "
                  f"{'-':>8s}")
    noise = np.random.default_rng(1)
    lin = [np.clip(L * t / 50.0 + noise.normal(0.0, 0.004, L.shape), 0, 1) for t in TIMES]
    stored = [np.rint(srgb_encode(x) * 255) / 255.0 for x in lin]
    decoded = [srgb_decode(z) for z in stored]
    for method in ("Robertson2003", "DebevecMalik1997"):
        m = merge_exposures(decoded, stored, TIMES, [1.0] * len(TIMES), method=method)
        ok = ~m.saturated
        rel = np.abs(m.radiance * 50.0 - L)[ok] / L[ok]
        print(f"{'noisy 8-bit ' + method:26s} {100 * np.median(rel):7.3f}% {100 * np.percentile(rel, 99):7.3f}% "
              f"{int(m.saturated.sum()):8d}")


if __name__ == "__main__":
    main()
