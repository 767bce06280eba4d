"""What a cast shadow cannot tell: the elevation of lights whose shadows run past the view.

    OMP_NUM_THREADS=1 python benchmarks/probes_shadow_limit.py

The scene and the measure are those of ``benchmarks/probes.py`` (its geometry constants are
imported): a 0.2 m cube's shadow on a 2.5 m x 2.5 m plane seen from above, the four bundled maps
at 64 rows (upper hemisphere), and the ``ffls synth`` capture (150 lights) relit under a map
against the true map. For every azimuth (lat-long column),
:func:`ffls.probes.sato_sato_ikeuchi.elevation_limit` gives the lowest elevation whose whole
shadow is in view. Two maps are made from the true one by moving the light below that limit, in
each column, to one row, with its power scaled so that the plane's irradiance ``E sin(elevation)``
is unchanged:

* ``lowest``: to the lowest row above the horizon (1.4 degrees);
* ``below``: to the highest row below the limit (the other end of what the view cannot tell apart).

Each is rendered as the probe (``cast_shadow_scene``) and compared with the true map's shadow
image (relative RMS over the receiver pixels) and by the relit error. A shadow image that differs
by less than the noise while the relit error is large is a lighting the photograph cannot tell
from the truth: any estimate's relit image is at least half that distance (relative to the true
relit image) from one of the two. Writes
``benchmarks/results/probes_shadow_limit.json``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from common import host_info, probe_benchmark_capture, relit_capture_error, write_json
from probes import H, MAPS, SHADOW_GEOMETRY, SHADOW_RES
from ffls.conventions import latlong_directions
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes.sato_sato_ikeuchi import elevation_limit
from ffls.probes.sources import latlong_solid_angles, to_lightmap
from ffls.relight.cpu import relight_capture
from ffls.synth.probe_scenes import cast_shadow_scene

ROOT = Path(__file__).resolve().parent.parent


def moved(true, below, target_row, sin_el, sa):
    """``true`` with each column's light below the limit moved to ``target_row[c]``, E sin(el) kept."""
    L = true.copy()
    w = (sin_el * sa)[..., None]
    for c in range(L.shape[1]):
        rows = np.flatnonzero(below[:, c])
        if rows.size == 0:
            continue
        power = (L[rows, c] * w[rows, c]).sum(axis=0)
        L[rows, c] = 0.0
        t = target_row[c]
        L[t, c] += power / w[t, c]
    return L


def main():
    cap, lights = probe_benchmark_capture("ffls_probes_limit_")
    dirs = latlong_directions(2 * H, H)
    sin_el = np.clip(dirs[..., 2], -1.0, 1.0)
    el = np.arcsin(sin_el)
    sa = latlong_solid_angles(H)
    upper = np.arange(H)[:, None] < H // 2
    out = []
    for name in MAPS:
        lm = builtin_lightmap(name)
        lm = lm.downsample(lm.res // H)
        true = np.asarray(lm.data, dtype=np.float64).copy()
        true[H // 2:] = 0.0
        truth = relight_capture(cap, lights, to_lightmap(true)[0])[0].astype(np.float64)

        def relit(L):
            return relit_capture_error(cap, lights, L, truth)

        sc = cast_shadow_scene(to_lightmap(true)[0], SHADOW_RES, albedo="checker", **SHADOW_GEOMETRY)
        occ = {"box": {"center": sc.box_center.tolist(), "size": sc.box_size.tolist()}}
        lim = elevation_limit(sc.points, dirs[H // 2 - 1], occ)  # one direction per column: its azimuth
        below = upper & (el < lim[None, :])
        limit_row = np.array([np.flatnonzero(upper[:, 0] & (el[:, c] >= lim[c])).max()
                              for c in range(2 * H)])
        w = (true * (np.maximum(sin_el, 0.0) * sa)[..., None]).sum(-1)
        row = {"map": name, "limit_deg": [float(np.degrees(lim.min())), float(np.degrees(lim.max()))],
               "plane_share_below": float(w[below].sum() / w.sum())}
        below_row = np.minimum(limit_row + 1, H // 2 - 1)
        for label, target in (("lowest", np.full(2 * H, H // 2 - 1)), ("below", below_row)):
            L = moved(true, below, target, sin_el, sa)
            s2 = cast_shadow_scene(to_lightmap(L)[0], SHADOW_RES, albedo="checker", **SHADOW_GEOMETRY)
            row[f"{label}_shadow_diff"] = float(np.sqrt(np.mean((s2.radiance - sc.radiance) ** 2))
                                                / np.sqrt(np.mean(sc.radiance ** 2)))
            row[f"{label}_relit"] = relit(L)
        out.append(row)
        print(f"{name:9s} limit {row['limit_deg'][0]:4.1f}-{row['limit_deg'][1]:4.1f} deg; plane irradiance below it "
              f"{100 * row['plane_share_below']:5.1f}%; moved to the lowest row: shadow image "
              f"{100 * row['lowest_shadow_diff']:5.2f}% apart, relit {100 * row['lowest_relit']:6.1f}%; to just below the "
              f"limit: {100 * row['below_shadow_diff']:5.2f}%, relit {100 * row['below_relit']:5.1f}%", flush=True)
    write_json(ROOT / "benchmarks/results/probes_shadow_limit.json",
               {"host": host_info(), "map_height": H, "rows": out,
                "command": "OMP_NUM_THREADS=1 python benchmarks/probes_shadow_limit.py"})


if __name__ == "__main__":
    main()
