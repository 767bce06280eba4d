"""What a mirror probe's circle off by 1-2 px costs the light map, and what the finder's circle costs.

The 12 renders of ``probe_detect.py`` (a chrome ball, reflectance 0.7, radius 20-40 px, 320 x 240 px,
under the 4 maps of ``/work/shared/hdri``) are unwrapped by ``ffls probe mirror``'s library call with
the ball stated as a pixel circle (``center_px`` + ``radius_px``, used as given): the true circle, the
true circle moved 1 and 2 px (along the image's x), the true circle 1 and 2 px smaller, and the ball
the finder gives without a hint (``ffls.probes.locate.locate_sphere``, the ``probe.json`` sphere left
unlocated as ``ffls probe mirror`` reads it; the row is left out where it refuses). The true circle is
the circle that best fits the ball's exact outline (``ffls.spheres.detect.fit_circle`` on
``silhouette_px``), what a measured outline is: off the lens axis the outline is an ellipse, whose best
circle is 0.5 px from the image of the ball's centre and 0.8 px larger than the tangent cone's radius near
the axis in the f = 400 px layout. (Before the eighteenth stop a stated circle was taken as the cone's
cross-section, and the true circle here was that centre with that radius: ``--circle cone``.) Reported per circle: ``map``, the relative RMS (solid-angle weighted) over the directions the
true circle's estimate saw, of the map against the true one, both area-averaged to 16 x 32 texels; and
``relit``, the relative RMS over the object of a synthetic capture (``ffls synth``, 150 distant lights,
64 px) relit under the estimate against the same capture relit under the true map.

Run: ``OMP_NUM_THREADS=1 python benchmarks/probe_limb_cost.py [--maps ...] [--out FILE]``
"""
from __future__ import annotations

import argparse
import tempfile
import warnings
from pathlib import Path

import numpy as np

from common import host_info, set_probe_sphere, write_json
from ffls.io.capture import load_capture_and_lights
from ffls.lightmaps.lightmap import LightMapWarning, load_lightmap
from ffls.probes import estimate_lightmap
from ffls.probes.debevec import latlong_solid_angles
from ffls.relight.cpu import relight_capture
from ffls.synth.scene import write_synthetic_capture
from ffls.io.probe import load_probe
from ffls.spheres.detect import fit_circle, silhouette_px
from probe_detect import CENTER, HDRI, LAYOUTS, MAPS, RADIUS, locate, render

HEIGHT = 64
CIRCLES = ("true", "x+1", "x+2", "r-1", "r-2", "found")


def _map_error(est, truth, seen):
    sa = latlong_solid_angles(est.shape[0])[..., None] * seen[..., None]
    return float(np.sqrt((sa * (est - truth) ** 2).sum() / (sa * truth ** 2).sum()))


def _relit_error(a, b):
    m = a.sum(-1) > 0
    return float(np.sqrt(((a - b) ** 2)[m].sum() / (a ** 2)[m].sum()))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", default="courtyard,night,studio,sunrise")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "probe_limb_cost.json"))
    ap.add_argument("--circle", choices=("outline", "cone"), default="outline",
                    help="the true circle: the exact outline's best circle, or the centre's image with the "
                         "cone's radius near the axis (the stored tables before the eighteenth stop)")
    a = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_synthetic_capture(tmp / "cap", n_lights=150, resolution=64, progress=False, seed=1)
        cap, lights = load_capture_and_lights(tmp / "cap")
        print(f"{'map':10s} {'layout':7s} " + " ".join(f"{c:>13s}" for c in CIRCLES) + "   (map % / relit %)")
        for name in a.maps.split(","):
            m = MAPS.index(name) if name in MAPS else len(MAPS)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LightMapWarning)  # the maps' few negative texels, clamped
                lm = load_lightmap(HDRI / f"{name}.exr")
            truth = lm.downsample(lm.data.shape[0] // HEIGHT)
            coarse_truth = truth.downsample(HEIGHT // 16).data
            relit_truth = relight_capture(cap, lights, truth)[0]
            for k, layout in enumerate(LAYOUTS):
                folder = tmp / f"{name}_{layout[0]}"
                c_true, r_true = render(folder, lm, layout, azimuth_deg=90.0 * m + 120.0 * k)
                if a.circle == "outline":
                    cam = load_probe(folder).views[0].camera
                    Ti = np.linalg.inv(np.asarray(cam.world_from_camera, dtype=np.float64))
                    c_true, r_true, _, _ = fit_circle(silhouette_px(cam.K, cam.dist, Ti[:3, :3] @ CENTER + Ti[:3, 3],
                                                                    RADIUS), c_true, r_true)
                circles = {"true": (c_true, r_true), "x+1": (c_true + [1.0, 0.0], r_true),
                           "x+2": (c_true + [2.0, 0.0], r_true), "r-1": (c_true, r_true - 1.0),
                           "r-2": (c_true, r_true - 2.0), "found": locate(folder)[0]}
                row = {"map": name, "layout": layout[0], "radius_true_px": r_true}
                seen = None
                for c in CIRCLES:
                    if circles[c] is None:
                        row[c] = None
                        continue
                    cpx, rpx = circles[c]
                    # the finder's ball is unwrapped as ``ffls probe mirror`` does it, located again (its sphere
                    # may be a tangent cone fitted to the limb, not the cone through a stated circle)
                    set_probe_sphere(folder, {"material": "mirror", "reflectance": 0.7} if c == "found" else
                                     {"material": "mirror", "reflectance": 0.7,
                                      "center_px": [float(v) for v in cpx], "radius_px": float(rpx)})
                    est = estimate_lightmap(folder, "mirror", height=HEIGHT)
                    if seen is None:  # the true circle's seen directions, area-averaged like the maps
                        seen = est.seen.reshape(16, HEIGHT // 16, 32, HEIGHT // 16).mean(axis=(1, 3)) > 0.5
                    row[c] = {"center_px": [float(v) for v in cpx], "radius_px": float(rpx),
                              "map_error": _map_error(est.lightmap.downsample(HEIGHT // 16).data, coarse_truth, seen),
                              "relit_error": _relit_error(relit_truth, relight_capture(cap, lights, est.lightmap)[0])}
                rows.append(row)
                print(f"{name:10s} {layout[0]:7s} " + " ".join(
                    f"{'refused':>13s}" if row[c] is None else
                    f"{100 * row[c]['map_error']:6.1f}/{100 * row[c]['relit_error']:5.1f}" for c in CIRCLES), flush=True)
    summary = {c: {"median_map_error": float(np.median([r[c]["map_error"] for r in rows if r[c]])),
                   "median_relit_error": float(np.median([r[c]["relit_error"] for r in rows if r[c]]))}
               for c in CIRCLES if any(r[c] for r in rows)}
    print("median " + " ".join(f"{c}: {100 * s['median_map_error']:.1f}/{100 * s['median_relit_error']:.1f}%"
                               for c, s in summary.items()))
    write_json(a.out, {"host": host_info(), "summary": summary, "rows": rows})


if __name__ == "__main__":
    main()
