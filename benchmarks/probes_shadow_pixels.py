"""The shadow probe's pixel budget: a regular grid of pixels against a random subset.

    OMP_NUM_THREADS=1 python benchmarks/probes_shadow_pixels.py [--noise 0.01]

The scene and the measure are those of ``benchmarks/probes.py`` (its geometry constants are
imported): a 0.2 m cube's shadow on a 2.5 m x 2.5 m plane seen from above (128 px, 16.3k receiver
pixels), the four bundled maps at 64 rows, and the ``ffls synth`` capture (150 lights) relit under
the recovered map against the true map. The receiver pixels are cut to ``ffls probe shadow``'s
budget (``shadow_lightmap``'s ``max_pixels``) two ways: a regular grid
(:func:`ffls.probes.estimate.pixel_grid_subset`, what the CLI does now) and a fixed-seed random
subset of exactly the budget (what it did before); then the adaptive dome is chosen by CV and BIC
(:func:`ffls.probes.selection.adaptive_sato_sato_ikeuchi`). Prints the relit error and the CPU
seconds of each estimate; writes ``benchmarks/results/probes_shadow_pixels.json`` (with
``--noise``: Gaussian noise of that fraction of the image's mean, as ``probes.py --noise``;
``probes_shadow_pixels_noise.json``).
"""
from __future__ import annotations

import argparse
import inspect
import sys
import time
from pathlib import Path

import numpy as np

from common import (host_info, probe_benchmark_capture, probe_benchmark_map, relit_capture_error, with_noise,
                    write_json)
from probes import H, MAPS, SHADOW_GEOMETRY, SHADOW_RES
from ffls.probes.estimate import pixel_grid_subset, shadow_lightmap
from ffls.probes.selection import adaptive_sato_sato_ikeuchi
from ffls.synth.probe_scenes import cast_shadow_scene

ROOT = Path(__file__).resolve().parent.parent
BUDGET = inspect.signature(shadow_lightmap).parameters["max_pixels"].default


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, default=0.0, help="Gaussian noise, as a fraction of the image's mean")
    a = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    cap, lights = probe_benchmark_capture("ffls_probes_px_")
    out = []
    for name in MAPS:
        lm, _, truth = probe_benchmark_map(name, H, cap, lights)
        sc = cast_shadow_scene(lm, SHADOW_RES, albedo="checker", **SHADOW_GEOMETRY)
        occ = {"box": {"center": sc.box_center.tolist(), "size": sc.box_size.tolist()}}
        rad = sc.radiance
        rad = with_noise(rad, a.noise, rng)
        rows, cols = np.nonzero(sc.mask)  # row-major, as sc.points
        grid, _ = pixel_grid_subset(np.stack([cols, rows], axis=1), BUDGET)
        rand = np.sort(np.random.default_rng(0).choice(sc.points.shape[0], BUDGET, replace=False))
        for subset, keep in (("grid", grid), ("random", rand)):
            for crit in ("cv", "bic"):
                t = time.process_time()
                sel = adaptive_sato_sato_ikeuchi(sc.points[keep], rad[keep], occ, criterion=crit,
                                                 albedo=sc.albedo[keep])
                t = time.process_time() - t
                err = relit_capture_error(cap, lights, sel.fit.latlong(H), truth)
                out.append({"map": name, "subset": subset, "pixels": int(keep.size), "criterion": crit,
                            "nodes": int(sel.chosen), "relit_capture": err, "cpu_s": t})
                print(f"{name:9s} {subset:6s} {keep.size:5d} px {crit:3s} -> {sel.chosen:3d} nodes  relit "
                      f"{100 * err:5.1f}%  {t:5.1f} CPU s", flush=True)
    stem = "probes_shadow_pixels" + ("_noise" if a.noise > 0 else "")
    write_json(ROOT / f"benchmarks/results/{stem}.json",
               {"host": host_info(), "map_height": H, "budget": BUDGET, "noise": a.noise, "rows": out,
                "command": " ".join(["python", "benchmarks/probes_shadow_pixels.py", *sys.argv[1:]])})


if __name__ == "__main__":
    main()
