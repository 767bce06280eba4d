"""POCS's least-power scheme under noise, in several orientations of the source set: one programme against the
mean of programmes over disjoint pixel subsets, beside the paper's sweeps.

    OMP_NUM_THREADS=1 python benchmarks/probes_pocs_noise.py [--maps studio] [--conditions 0:0,0.01:0,0.01:1]
        [--orientations 0,1,2] [--subsets 4] [--plain] [--pixels 1000]

The ball and measure of ``benchmarks/probes_pocs_least_power.py`` (a Lambertian ball of albedo 0.7, 80 px, seen
from the relit capture's camera; the bundled map at 64 rows; Gaussian noise of ``noise`` times the image's mean from
``numpy.random.default_rng(seed)`` for each map and seed; the set chosen on ``--pixels`` pixels, ``max_pixels``, 1000
by default, 2000 the CLI's;
the ``ffls synth`` capture, 150 lights, relit under the recovered vs the true map, relative RMS). Orientations as
``benchmarks/probes_orientation.py``: the geodesic hierarchy fixed, the pixels' normals turned by ``R`` (the first
the identity, orientation ``i`` the ``i``-th of ``scipy.spatial.transform.Rotation.random(10, random_state=0)``) and
the sources turned back.
Rows per map, condition and orientation:

* ``sequential``: ``adaptive_singh_ahuja`` (CV, the paper's 50 sweeps), ``ffls probe pocs --scheme sequential`` (the
  default before least power);
* ``least-power x1``: ``averaged_least_power(..., subsets=1, refit=False)`` on that set (one programme, on the
  set's pixels: the least-power scheme before this round);
* ``least-power xK`` (with ``--plain``): ``averaged_least_power(..., subsets=K, refit=False)``, the mean of the
  programmes on ``K`` disjoint pixel subsets;
* ``least-power xK refit``: the same with ``refit=True`` (each programme's lit sources refitted by bounded least
  squares before the mean): what ``scheme='least-power'`` does, the default of ``ffls probe pocs``.

Time: CPU seconds of this process (one thread), the least-power rows' including the set's. Writes
``benchmarks/results/probes_pocs_noise.json``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from common import host_info, noisy_diffuse_probes, probe_benchmark_capture, relit_capture_error, write_json
from ffls.probes.singh_ahuja import adaptive_singh_ahuja, averaged_least_power
from ffls.probes.sources import sources_to_latlong

ROOT = Path(__file__).resolve().parent.parent
MAPS = ("courtyard", "studio", "sunrise", "night")
H = 64
PIXELS = 1000


def main(argv=None):
    from scipy.spatial.transform import Rotation

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", default=",".join(MAPS))
    ap.add_argument("--conditions", default="0:0,0.01:0,0.01:1", help="noise:seed pairs, comma-separated")
    ap.add_argument("--orientations", default="0,1,2", help="indices of the orientations (0: the identity)")
    ap.add_argument("--subsets", type=int, default=4)
    ap.add_argument("--plain", action="store_true", help="also the mean of the programmes without the refit")
    ap.add_argument("--pixels", type=int, default=PIXELS, help="max_pixels: of the set's choice and of each programme")
    ap.add_argument("--json", default=str(ROOT / "benchmarks/results/probes_pocs_noise.json"))
    a = ap.parse_args(argv)
    maps = [m for m in a.maps.split(",") if m]
    if not set(maps) <= set(MAPS):
        ap.error(f"--maps: choose from {','.join(MAPS)}")
    orients = [int(x) for x in a.orientations.split(",") if x]
    rots = Rotation.random(10, random_state=0).as_matrix()
    rots[0] = np.eye(3)
    cap, lights = probe_benchmark_capture("ffls_probes_pocs_noise_")
    rows = []
    for name, (_, _, truth), sph, noise, seed, rad in noisy_diffuse_probes(maps, H, cap, lights, a.conditions):
        for o in orients:
            R = rots[o]
            n = sph.normals @ R.T
            t = time.process_time()
            sel = adaptive_singh_ahuja(n, rad, 0.7, criterion="cv", max_pixels=a.pixels)
            t_set = time.process_time() - t
            fits = [("sequential", sel.fit, t_set)]
            runs = ((1, False),) + (((a.subsets, False),) if a.plain else ()) + ((a.subsets, True),)
            for k, refit in runs:   # x1: the scheme before this round
                t = time.process_time()
                fit = averaged_least_power(n, rad, 0.7, sel.fit.directions, max_pixels=a.pixels, subsets=k,
                                           refit=refit)
                fits.append((f"least-power x{k}" + (" refit" if refit else ""), fit,
                             t_set + time.process_time() - t))
            for method, fit, cpu in fits:
                err = relit_capture_error(cap, lights, sources_to_latlong(fit.directions @ R, fit.intensities, H),
                                          truth)
                rows.append({"map": name, "noise": noise, "seed": seed, "orientation": o, "method": method,
                             "chosen": int(sel.chosen), "pixels": int(fit.pixels_used), "relit_capture": err,
                             "cpu_s": cpu})
                print(f"{name:9s} noise {noise:g} seed {seed} orientation {o}  {method:22s} {sel.chosen:4d}  "
                      f"relit {100 * err:5.1f}%  {cpu:6.2f} s", flush=True)
    write_json(a.json, {"host": host_info(), "map_height": H, "pixels": a.pixels, "subsets": a.subsets,
                        "orientations": orients, "rows": rows,
                        "command": " ".join(["OMP_NUM_THREADS=1 python", "benchmarks/probes_pocs_noise.py",
                                             *sys.argv[1:]])})


if __name__ == "__main__":
    main()
