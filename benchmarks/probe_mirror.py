"""Mirror-ball light maps (Debevec 1998): accuracy against the true map and as relit, and time.

For each built-in HDR map, a mirror ball (radius 0.1 m, reflectance 0.7) is ray-traced by
``ffls.synth.probe`` at 20 m (f = 14000 px) and at 1 m (f = 700 px) into a 256 x 256 photo, from
the direction of the relit capture's camera (30 degrees above the horizon, as a probe photographed
from the object camera's place), one view or two 90 degrees apart about the vertical, and unwrapped by ``ffls probe mirror``'s library call. Reported:

* ``map``: relative RMS (solid-angle weighted) of the recovered map against the true one, both
  area-averaged to 16 x 32 texels (what a 70-pixel ball resolves);
* ``relit``: relative RMS over the object of a synthetic capture (``ffls synth``, 150 distant lights,
  64 px) relit under the recovered map against the same capture relit under the true map;
* ``oracle``: the same with ``ffls.synth.scene.render_lightmap`` (the scene rendered directly under
  each map, 512 clustered directions), which has no light-cell discretisation;
* ``seen``: the fraction of the sphere seen; ``time``: the median of 3 estimates after a warm-up.

Run: ``OMP_NUM_THREADS=1 python benchmarks/probe_mirror.py [--height 64] [--out results/probe_mirror.json]``
"""
from __future__ import annotations

import argparse
import json
import tempfile
import warnings
from pathlib import Path

import numpy as np

from common import host_info, median_seconds, write_json
from ffls.io.capture import load_capture_and_lights
from ffls.lightmaps.lightmap import LightMapWarning, builtin_lightmap
from ffls.probes import estimate_lightmap
from ffls.probes.debevec import latlong_solid_angles
from ffls.relight.cpu import relight_capture
from ffls.synth.probe import look_at, write_mirror_probe
from ffls.synth.scene import make_scene, render_lightmap, write_synthetic_capture


def _rel(a, b):
    sa = latlong_solid_angles(a.shape[0])[..., None]
    return float(np.sqrt((sa * (a - b) ** 2).sum() / (sa * b ** 2).sum()))


def _rel_img(a, b):
    m = a.sum(-1) > 0
    return float(np.sqrt(((a - b) ** 2)[m].sum() / (a ** 2)[m].sum()))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--height", type=int, default=64)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "probe_mirror.json"))
    args = ap.parse_args()
    h = args.height
    tmp = Path(tempfile.mkdtemp())
    write_synthetic_capture(tmp / "cap", n_lights=150, resolution=64, progress=False, seed=1)
    cap, lights = load_capture_and_lights(tmp / "cap")
    scene = make_scene()
    rows = []
    print(f"{'map':10s} {'dist':>5s} {'views':>5s} {'map':>7s} {'relit':>7s} {'oracle':>7s} {'seen':>6s} {'time':>6s}")
    for name in ("courtyard", "sunrise", "studio", "night"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LightMapWarning)
            full = builtin_lightmap(name, 512)
        truth = full.downsample(512 // h)
        a = relight_capture(cap, lights, truth)[0]
        oa = render_lightmap(scene, truth, 48, n_dirs=512)
        for dist in (20.0, 1.0):
            f = 700.0 * dist
            K = np.array([[f, 0, 128], [0, f, 128], [0, 0, 1.0]])
            folder = tmp / f"{name}_{dist:g}"
            views = []
            # the ball is photographed from the relit capture's camera direction (30 degrees down), the
            # second view 90 degrees around the vertical from it
            back = -scene.world_from_camera()[:3, 2]
            for k, eye in enumerate((dist * back, dist * np.array([-back[1], back[0], back[2]]))):
                T = look_at(eye)
                write_mirror_probe(folder, full.downsample(2), (256, 256), K=K, world_from_camera=T, radius=0.1,
                                   reflectance=0.7, image_name=f"v{k}.exr")
                views.append({"images": [f"v{k}.exr"], "camera": {"K": K.tolist(), "world_from_camera": T.tolist()}})
            for n_views in (1, 2):
                doc = {"format": "ffls-probe", "version": 1, "images": views[:n_views],
                       "sphere": {"center": [0, 0, 0], "radius": 0.1, "reflectance": 0.7}}
                (folder / "probe.json").write_text(json.dumps(doc))
                est = estimate_lightmap(folder, "mirror", height=h)
                t = median_seconds(lambda: estimate_lightmap(folder, "mirror", height=h), repeat=3)
                b = relight_capture(cap, lights, est.lightmap)[0]
                ob = render_lightmap(scene, est.lightmap, 48, n_dirs=512)
                row = {"map": name, "distance_m": dist, "views": n_views, "height": h,
                       "map_error": _rel(est.lightmap.downsample(h // 16).data, truth.downsample(h // 16).data),
                       "relit_error": _rel_img(a, b), "oracle_error": _rel_img(oa, ob),
                       "seen_fraction": est.details["seen_fraction"], "seconds": t}
                rows.append(row)
                print(f"{name:10s} {dist:5g} {n_views:5d} {100 * row['map_error']:6.2f}% {100 * row['relit_error']:6.2f}%"
                      f" {100 * row['oracle_error']:6.2f}% {row['seen_fraction']:6.3f} {t:5.2f}s")
    write_json(args.out, {"host": host_info(), "rows": rows})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
