"""Speed of the synthetic renderer (ffls.synth.scene): G-buffer, per-image render, whole captures.

Usage: python benchmarks/synth_speed.py [--repeats 3] [--big] [--out result.json]

Prints one row per case with the median of ``--repeats`` runs after a warm-up: the G-buffer (and
bounce matrix) build, one distant-light image, one near area-light image, a whole capture
(100 images at 256 x 256 written as EXR; with ``--big`` also 80 at 768 x 768) and the shadow-ray
throughput. The reference in the same run is NumPy's copy bandwidth on this machine, reported
as the ratio "bytes of the output image per second / copy bandwidth".
"""
from __future__ import annotations

import argparse
import os
import platform
import tempfile

import numpy as np

from ffls.synth import scene as synth

from common import median_seconds, numpy_copy_bandwidth, write_json  # benchmarks/common.py


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--big", action="store_true", help="also a 768 x 768 capture of 80 images")
    ap.add_argument("--out", help="write the table as JSON here")
    a = ap.parse_args()
    scene = synth.SynthScene()
    bw = numpy_copy_bandwidth(64 << 20, 5, np.float64)
    rows = []

    def row(case, seconds, res, images=1):
        out_bytes = images * res * res * 3 * 4
        rows.append({"case": case, "resolution": res, "images": images, "seconds": seconds,
                     "ms_per_image": 1e3 * seconds / images, "ratio_to_copy_bw": out_bytes / seconds / bw})
        print(f"{case:<36} {res:>5} {images:>4} {seconds:>9.3f} s {1e3 * seconds / images:>9.1f} ms/img", flush=True)

    print(f"{'case':<36} {'res':>5} {'imgs':>4} {'median':>11} {'per image':>15}")
    for res in (256, 768) if a.big else (256,):
        def build():
            synth.gbuffer.cache_clear()
            synth.gbuffer(scene, res)
        row("gbuffer + bounce matrix", median_seconds(build, a.repeats), res)
        row("distant light, 1 image", median_seconds(lambda: synth.render_light(scene, res, direction=[0.3, -0.4, 0.8]), a.repeats), res)
        row("near area light (9 pts), 1 image", median_seconds(
            lambda: synth.render_light(scene, res, position=[0.6, -0.8, 1.2], light_radius=0.05), a.repeats), res)
    cases = [(100, 256)] + ([(80, 768)] if a.big else [])
    for n, res in cases:
        with tempfile.TemporaryDirectory() as tmp:
            def cap():
                synth.gbuffer.cache_clear()  # include the G-buffer build: a cold capture
                synth.write_synthetic_capture(tmp, n_lights=n, resolution=res, progress=False)
            row("capture (EXR, cold cache)", median_seconds(cap, 1 if res > 256 else a.repeats), res, n)
    info = {"cpu_count": os.cpu_count(), "machine": platform.machine(), "processor": platform.processor(),
            "numpy": np.__version__, "copy_bandwidth_GBps": bw / 1e9, "rows": rows}
    print(f"cpus {os.cpu_count()}, numpy {np.__version__}, copy bandwidth {bw / 1e9:.1f} GB/s")
    if a.out:
        write_json(a.out, info)


if __name__ == "__main__":
    main()
