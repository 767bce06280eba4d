"""Where the inverse methods' relit error comes from: per map, per direction band, seen or not.

    OMP_NUM_THREADS=1 python benchmarks/probes_attribution.py

The scenes and the measure are those of ``benchmarks/probes.py`` (its geometry constants are
imported): a Lambertian ball seen from the relit capture's camera direction, a 0.2 m cube's shadow
seen from above, the four bundled maps at 64 rows, and the ``ffls synth`` capture (150 lights)
relit under the recovered vs the true map. For the main setting of each method (Hougen-Ahuja, 492
sources, NNLS, and its adaptive set chosen by BIC; POCS 16 x 32, 50 sweeps; Sato-Sato-Ikeuchi, 526
nodes, and its adaptive dome chosen by BIC) it reports the relit error

* ``all``: of the recovered map;
* ``band a-b``: of the true map with only the directions between elevations ``a`` and ``b``
  (degrees) taken from the recovered one: which light the error comes from;
* ``seen only``: of the recovered map with the directions the probe sees poorly replaced by the
  truth (``normal_confidence <= 0.2`` for the ball; for the shadow, nodes hidden from fewer than
  1% of the receiver pixels): what is left is the ambiguity among the directions it does see;
* ``floor``: of the true map as the method's unknowns hold it (``cell_energies``; the POCS grid
  area-averaged; for the adaptive rows, the set the estimate chose).

Writes ``benchmarks/results/probes_attribution.json``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from common import host_info, probe_benchmark_capture, probe_benchmark_map, relit_capture_error, write_json
from probes import H, MAPS, SHADOW_GEOMETRY, SHADOW_RES
from ffls.conventions import latlong_directions
from ffls.probes.hougen_ahuja import hougen_ahuja, normal_confidence
from ffls.probes.sato_sato_ikeuchi import (box_visibility, dome_nodes, occluder_visibility, sato_sato_ikeuchi,
                                           shadow_confidence)
from ffls.probes.selection import adaptive_hougen_ahuja, adaptive_sato_sato_ikeuchi
from ffls.probes.singh_ahuja import singh_ahuja
from ffls.probes.sources import cell_energies, latlong_solid_angles, model_sources, sources_to_latlong
from ffls.synth.probe_scenes import cast_shadow_scene, diffuse_sphere_scene

ROOT = Path(__file__).resolve().parent.parent
BANDS = ((0, 10), (10, 30), (30, 90))


def main():
    cap, lights = probe_benchmark_capture("ffls_probes_attr_")
    elev = np.degrees(np.arcsin(latlong_directions(2 * H, H)[..., 2]))
    sa = latlong_solid_angles(H).reshape(16, H // 16, 32, H // 16, 1)
    out = []
    print(f"{'map':9s} {'method':14s} {'all':>6s} " + " ".join(f"{f'band {a}-{b}':>10s}" for a, b in BANDS)
          + f" {'seen only':>9s} {'floor':>6s}")
    for name in MAPS:
        lm, true, truth = probe_benchmark_map(name, H, cap, lights)

        def err(L):
            return relit_capture_error(cap, lights, L, truth)

        def report(method, L, poorly_seen, floor_map):
            row = {"map": name, "method": method, "all": err(L)}
            for a, b in BANDS:
                band = (elev >= a) & (elev < b)
                row[f"band {a}-{b}"] = err(np.where(band[..., None], L, true))
            row["seen only"] = err(np.where(poorly_seen[..., None], true, L))
            row["floor"] = err(floor_map)
            out.append(row)
            print(f"{name:9s} {method:14s} {100 * row['all']:5.1f}% " + " ".join(
                f"{100 * row[f'band {a}-{b}']:9.1f}%" for a, b in BANDS)
                + f" {100 * row['seen only']:8.1f}% {100 * row['floor']:5.1f}%", flush=True)

        sph = diffuse_sphere_scene(lm, 80, albedo=0.7, world_from_camera=cap.world_from_camera)
        poor = normal_confidence(sph.normals, H) <= 0.2
        fit = hougen_ahuja(sph.normals, sph.radiance, 0.7, 492, nonnegative=True, ambient="nonnegative")
        d = model_sources(492)
        report("HA 492 nnls", fit.latlong(H), poor, sources_to_latlong(d, cell_energies(d, true), H))
        sel = adaptive_hougen_ahuja(sph.normals, sph.radiance, 0.7, criterion="bic", nonnegative=True,
                                    ambient="nonnegative")
        d = sel.fit.directions
        report(f"HA adapt {d.shape[0]}", sel.fit.latlong(H), poor, sources_to_latlong(d, cell_energies(d, true), H))
        r = singh_ahuja(sph.normals, sph.radiance, 0.7, 16, 50, max_pixels=1000)
        grid = (true.reshape(16, H // 16, 32, H // 16, 3) * sa).sum(axis=(1, 3)) / sa.sum(axis=(1, 3))
        report("POCS 16x32", r.latlong(H), poor, np.repeat(np.repeat(grid, H // 16, axis=0), H // 16, axis=1))
        sc = cast_shadow_scene(lm, SHADOW_RES, albedo="checker", **SHADOW_GEOMETRY)
        occ = {"box": {"center": sc.box_center.tolist(), "size": sc.box_size.tolist()}}
        d = dome_nodes(526)
        V = box_visibility(sc.points, d, sc.box_center, sc.box_size)
        fit = sato_sato_ikeuchi(sc.points, sc.radiance, occ, nodes=d, albedo=sc.albedo, visibility=V)
        poor = shadow_confidence(d, V, height=H) < 0.01
        report("Sato 526", fit.latlong(H), poor, sources_to_latlong(d, cell_energies(d, true, "upper"), H, "upper"))
        sel = adaptive_sato_sato_ikeuchi(sc.points, sc.radiance, occ, criterion="bic", albedo=sc.albedo)
        d = sel.fit.directions
        poor = shadow_confidence(d, occluder_visibility(sc.points, d, occ), height=H) < 0.01
        report(f"Sato adapt {d.shape[0]}", sel.fit.latlong(H), poor,
               sources_to_latlong(d, cell_energies(d, true, "upper"), H, "upper"))
    write_json(ROOT / "benchmarks/results/probes_attribution.json",
               {"host": host_info(), "map_height": H, "bands_deg": BANDS, "rows": out,
                "command": "OMP_NUM_THREADS=1 python benchmarks/probes_attribution.py"})


if __name__ == "__main__":
    main()
