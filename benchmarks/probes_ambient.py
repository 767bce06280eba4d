"""Hougen-Ahuja: the free ambient term against a non-negative one, the rank of large source sets, cell sizes.

    OMP_NUM_THREADS=1 python benchmarks/probes_ambient.py

For each bundled HDR map (64 rows) and a 64 px Lambertian ball: NNLS with 162 geodesic sources
and the ambient free (the paper) or non-negative; the fitted ambient, the number of negative
texels of the map, and the relit error of the ball as seen under the *saved* (clipped) map.
Then the numerical rank of the design for 42, 162, 492 sources, and the max/min ratio of the
Voronoi cell solid angles of the geodesic spheres. Writes ``benchmarks/results/probes_ambient.json``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from common import host_info, write_json
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes.evaluate import relit_error
from ffls.probes.hougen_ahuja import hougen_ahuja
from ffls.probes.sources import cell_solid_angles, geodesic_sources
from ffls.synth.probe_scenes import diffuse_sphere_scene

ROOT = Path(__file__).resolve().parent.parent


def main():
    rows = []
    for name in ("courtyard", "studio", "sunrise", "night"):
        lm = builtin_lightmap(name)
        lm = lm.downsample(lm.res // 64)
        sc = diffuse_sphere_scene(lm, 64)
        for amb in (True, "nonnegative"):
            fit = hougen_ahuja(sc.normals, sc.radiance, sc.albedo, 162, nonnegative=True, ambient=amb)
            L = fit.latlong(64)
            row = {"map": name, "ambient": "free" if amb is True else amb, "ambient_value": fit.ambient.tolist(),
                   "negative_texels": int(np.count_nonzero((L < 0).any(-1))),
                   "relit_own_clipped": relit_error(L, lm, sc.normals, clip=True)}
            rows.append(row)
            print(f"{name:9s} ambient {row['ambient']:11s} A = {np.round(fit.ambient, 3)}  negative texels "
                  f"{row['negative_texels']:5d}  ball relit under the clipped map {100 * row['relit_own_clipped']:.1f}%")
    lm = builtin_lightmap("courtyard")
    sc = diffuse_sphere_scene(lm.downsample(lm.res // 64), 64)
    ranks = {}
    for n in (42, 162, 492):
        fit = hougen_ahuja(sc.normals, sc.radiance, sc.albedo, n, rcond=1e-3)
        ranks[n] = fit.rank
        print(f"{n} sources + ambient, {sc.normals.shape[0]} pixels: numerical rank {fit.rank}")
    ratios = {}
    for f in (2, 4, 7):
        w = cell_solid_angles(geodesic_sources(f), "full")
        ratios[int(10 * f * f + 2)] = float(w.max() / w.min())
        print(f"geodesic sphere of {10 * f * f + 2} nodes: cell solid angles max/min {w.max() / w.min():.3f}")
    write_json(ROOT / "benchmarks/results/probes_ambient.json",
               {"host": host_info(), "rows": rows, "ranks": ranks, "cell_ratio": ratios})


if __name__ == "__main__":
    main()
