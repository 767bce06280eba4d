"""Relit-image error and speed of the compressed basis (ffls.relight.compress) against K, on a synthetic capture.

For K in 4..64 and both modes ('per_channel', 'shared') it reports the relative RMS error
``||relit_K - relit|| / ||relit||`` (float64, the whole image) of the compressed relighting
against ``relight_reference`` under three light maps (sky + sun, the paper's map, and a bundled
HDR), and the compression time. The capture is written by ``ffls.synth.scene.write_synthetic_capture``.

    python benchmarks/compression_error.py [--lights 128] [--res 128]

Prints a table and writes ``benchmarks/results/compression_error.json``.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from ffls.io.capture import load_capture, load_lights
from ffls.relight.compress import compress_basis
from ffls.conventions import rotation_z
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.relight.cpu import relight_reference
from ffls.synth.scene import write_synthetic_capture
from ffls.weights.voronoi import integrate_weights
from ffls.radiance.photos import load_photos

from common import write_json  # benchmarks/common.py

RESULTS = Path(__file__).resolve().parent / "results" / "compression_error.json"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lights", type=int, default=128)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--maps", default="sky,paper,courtyard")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        write_synthetic_capture(tmp, n_lights=args.lights, resolution=args.res, progress=False)
        cap = load_capture(tmp)
        lights = load_lights(Path(tmp) / "lights.json", cap)
        basis = load_photos(cap, progress=False)
        print(f"synthetic capture: {basis.shape[0]} lights, {args.res}x{args.res}, {time.perf_counter() - t0:.1f} s")
    d = lights.directions[lights.ok_mask]
    maps = {m: builtin_lightmap(m, 128) for m in args.maps.split(",")}
    weights = {m: integrate_weights(lm, d, rotation_z(30.0), cap.hemisphere).weights for m, lm in maps.items()}
    refs = {m: relight_reference(w, basis) for m, w in weights.items()}
    rows = []
    header = f"{'mode':12s} {'K':>4s} " + " ".join(f"{m:>10s}" for m in maps) + f" {'compress s':>10s}"
    print(header)
    for mode in ("per_channel", "shared"):
        for K in (4, 8, 16, 32, 64):
            if K >= basis.shape[0]:
                continue
            cb = compress_basis(basis, K, mode=mode)
            errs = {m: float(np.linalg.norm(cb.relight(weights[m]) - refs[m]) / np.linalg.norm(refs[m])) for m in maps}
            rows.append({"mode": mode, "K": K, "rel_rms": errs, "compress_s": cb.info["seconds"]})
            print(f"{mode:12s} {K:4d} " + " ".join(f"{errs[m]:10.2e}" for m in maps) + f" {cb.info['seconds']:10.2f}",
                  flush=True)
    write_json(RESULTS, {"lights": int(basis.shape[0]), "res": args.res, "maps": list(maps), "rows": rows})


if __name__ == "__main__":
    main()
