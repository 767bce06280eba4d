"""Where the composite's error under compact sources comes from, with the fills (docs/composite.md).

On the Mitsuba renders of ``composite_mitsuba.py`` (same scenes, camera, cache and change region),
barycentric weighting, ``--sources lightflow``, ``Debevec1998``, each row the change-region error:

* ``none``, ``model``, ``ground``: ``ffls composite``'s library path with ``--fill none``, ``model``
  (the sources relit from the unshadowed model times the object's shadow hull where a sphere hides
  them) and ``ground`` (the same on every ground pixel); the scene's sphere centres;
* ``direct, spheres``: the rest of the map relit from the basis as usual, each compact source's
  samples rendered directly by Mitsuba as directional lights in the capture scenes (spheres
  included) at the basis's samples per pixel, and at ``--oracle-spp``: the sources exact but for the
  spheres' shadows, where neither capture holds what the object would block;
* ``direct, no spheres``: the same renders without the spheres: the sources exact everywhere, the
  bound of any way of relighting them.

    python benchmarks/composite_ground_split.py [--maps studio,sunrise] [--lights 100,200]
        [--spp 16] [--oracle-spp 256] [--cache DIR]

Needs ``pip install mitsuba``. Writes ``benchmarks/results/composite_ground_split.json``.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import composite_mitsuba as cm
from common import host_info, mitsuba_latlong_module, write_json
from composite_attribution import render_cached

from ffls.relight.basis import accepted_basis
from ffls.relight.composite import composite
from ffls.relight.cpu import CpuRelighter
from ffls.relight.lightflow import LightFlowRelighter
from ffls.relight.shadow_hull import ShadowHull
from ffls.relight.sphere_shadows import SphereShadowFill, ground_points, hidden_photos


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", default="studio,sunrise")
    ap.add_argument("--lights", default="100,200")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16, help="the basis photos' samples per pixel")
    ap.add_argument("--oracle-spp", type=int, default=256, help="the sources' direct renders, second row")
    ap.add_argument("--truth-spp", type=int, default=1024)
    ap.add_argument("--cache", default="/tmp/ffls_bench_composite_mitsuba")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "composite_ground_split.json"))
    a = ap.parse_args()
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    ll = mitsuba_latlong_module()
    ll.register()
    cache, R, t0 = Path(a.cache), a.res, time.perf_counter()
    om_b, sm_b, _ = cm.cast_masks(mi, R)
    om, sm = om_b.astype(np.float64), sm_b.astype(np.float64)
    K, M = cm.camera_matrices(R)
    ground = ground_points(K, M, (R, R))
    ground[~sm_b] = np.nan
    centres = [(x, y, 0.05) for x, y in cm.SPHERES]

    def capture_render(d, with_object, spheres, spp, seed):
        sc = {"type": "scene", "integrator": {"type": "path", "max_depth": 6}, "sensor": cm.camera_sensor(mi, R, spp),
              **cm.scene_shapes(mi, cm.CAPTURE_ALBEDO, with_object, spheres, False),
              "light": {"type": "directional", "direction": list(-np.asarray(d)),
                        "irradiance": {"type": "rgb", "value": 1.0}}}
        return np.array(mi.render(mi.load_dict(sc), seed=seed))

    rows = []
    for n in (int(v) for v in a.lights.split(",")):
        caps = (cm.render_capture(mi, cache / f"object_{R}_{n}_{a.spp}", n, 0, True, R, a.spp),
                cm.render_capture(mi, cache / f"surface_{R}_{n}_{a.spp}", n, 1, False, R, a.spp))
        fills = [SphereShadowFill.from_geometry(ground, centres, 0.05, li.directions) for _, li in caps]
        basis, dirs = accepted_basis(*caps[0])
        hull = ShadowHull.carve(basis, dirs, om_b, K, M, ground=sm_b, hidden=hidden_photos(ground, centres, 0.05, dirs))
        for name in a.maps.split(","):
            bg, tr, lm = cm.scene_renders(mi, ll, cache, name, R, a.truth_spp, 128, 256)
            change = cm.change_region(tr, bg, sm_b, om_b)

            def row(what, o, s):
                c = composite(bg, o, s, om, sm).image.astype(np.float64)
                err = float(np.abs(c - tr)[change].sum() / tr[change].sum())
                rows.append({"map": name, "lights": n, "what": what, "change": err})
                print(f"{name:8s} {n:4d} {100 * err:5.1f}%  {what}", flush=True)

            for fill in ("none", "model", "ground"):
                out = []
                for k, (cap, li) in enumerate(caps):
                    r = CpuRelighter.from_capture(cap, li, precision="f64", cell_max_res=4096, weighting="barycentric")
                    if fill == "none":
                        r = LightFlowRelighter(r, interpolation="flow")
                    else:
                        r = LightFlowRelighter(r, interpolation="flow", fill=fills[k], fill_sources=fill,
                                               fill_rest=False, hull=hull if k == 0 else None)
                    r.set_lightmap(lm)
                    r.render()
                    out.append(r.read_hdr().astype(np.float64))
                    split = r.last_split
                row(f"--fill {fill}", *out)
            rest = []
            for cap, li in caps:
                r = CpuRelighter.from_capture(cap, li, precision="f64", cell_max_res=4096, weighting="barycentric")
                r.set_lightmap(split.rest)
                r.render()
                rest.append(r.read_hdr().astype(np.float64))

            def sources(with_object, spheres, spp):
                img = np.zeros((R, R, 3))
                for si, src in enumerate(split.sources):
                    for k, (d, p) in enumerate(zip(src.sample_directions, src.sample_powers)):
                        if d[2] <= 0:
                            continue
                        f = cache / f"split_{name}_src{si}_{k}_{int(with_object)}{int(spheres)}_{R}_{spp}.exr"
                        img += render_cached(f, lambda: capture_render(
                            d, with_object, spheres, spp, 900 + 37 * si + k + (0 if with_object else 500))) * p
                return img

            for spp in (a.spp, a.oracle_spp):
                for spheres in (True, False):
                    row(f"sources rendered directly, {spp} spp, {'with' if spheres else 'without'} the spheres",
                        rest[0] + sources(True, spheres, spp), rest[1] + sources(False, spheres, spp))
    write_json(a.out, {"resolution": R, "spp": a.spp, "oracle_spp": a.oracle_spp, "truth_spp": a.truth_spp,
                       "host": host_info(), "seconds": time.perf_counter() - t0, "rows": rows})


if __name__ == "__main__":
    main()
