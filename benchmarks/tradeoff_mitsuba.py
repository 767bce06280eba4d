"""The weighting schemes' accuracy on independent, path-traced renders (Mitsuba 3; docs/tradeoff.md).

``benchmarks/tradeoff.py`` measures the speed/accuracy trade on captures rendered by
``ffls synth``, whose one-bounce shading is ffls's own model. This benchmark measures the accuracy
half of the trade on renders ffls did not make: Mitsuba 3's path tracer (``max_depth`` 8, so
interreflections, contact shadows, the rough-plastic cube's gloss) renders

* the capture: ``benchmarks/independent_mitsuba.py``'s scene (grey ground, four white spheres, a
  rotated rough-plastic cube, a capped cylinder) under one ``directional`` light of irradiance 1
  per photo, N stratified directions over the upper hemisphere
  (:func:`ffls.synth.scene.stratified_directions`, seed 0);
* the truth: the same scene under each real HDR map (``envmap`` with
  ``scripts/mitsuba_latlong.py``'s ``ENVMAP_TO_WORLD``), turned by each yaw. The map's lower half
  is set to zero for both the truth and the relighting, since a capture's lights cover the upper
  hemisphere only;
* the truth again with another seed. The truth is the mean of the two; half their relative
  difference is its own noise, which is also given subtracted in quadrature.

Each weighting scheme (:data:`ffls.weights.weighting.ALL_SCHEMES`; ``kriging`` with its kernel
learnt from the capture's photos, :func:`ffls.weights.kriging.fit_kernel`) relights the capture on the CPU in
float64 from the true light directions (:class:`ffls.relight.cpu.CpuRelighter`: the reference the
GPU passes are tested against), so the numbers are the schemes' accuracy alone, not the light
estimation's. The error is ``tradeoff.py``'s relative RMSE and PSNR of the tone-mapped images.

    python benchmarks/tradeoff_mitsuba.py [--lights 128] [--res 64] [--spp 64] [--truth-spp 1024]
        [--maps sunrise.exr,studio.exr,courtyard.exr] [--yaws 0,130] [--schemes voronoi,...]
        [--cache DIR]

Needs ``pip install mitsuba`` (``ffls[validate]``). Writes ``benchmarks/results/tradeoff_mitsuba.json``.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from common import host_info, mitsuba_latlong_module, write_json  # benchmarks/common.py
from independent_mitsuba import SPHERE_RADIUS, build_scene, render_capture
from tradeoff import map_path, psnr_tonemapped, rel_rmse

from ffls.io.capture import Lights, load_capture
from ffls.io.images import read_image, write_exr
from ffls.lightmaps.lightmap import load_lightmap
from ffls.relight.cpu import CpuRelighter
from ffls.synth.scene import stratified_directions
from ffls.radiance.photos import load_photos
from ffls.weights.kriging import fit_kernel
from ffls.weights.weighting import ALL_SCHEMES

FOV_DEG = 40.0


def upper_map(src: Path, yaw_deg: float, out: Path) -> Path:
    """``src`` turned by ``yaw_deg`` about +Z (a whole-column roll of the lat-long image) with the
    rows below the horizon and any negative texel set to zero, written to ``out`` (float32 EXR)."""
    px = read_image(src).pixels.astype(np.float32)[..., :3]
    h, w = px.shape[:2]
    shift = int(round(yaw_deg / 360.0 * w))
    px = np.roll(px, shift, axis=1)  # a turn about +Z: the same file lights the truth and the relighting
    px[h // 2:] = 0.0
    np.maximum(px, 0.0, out=px)  # studio.exr has texels of -7e-7: the truth and the relighting get the same map
    write_exr(out, np.ascontiguousarray(px), half=False)
    return out


def render_truth(mi, ll, envmap: Path, res: int, spp: int, seed: int, out: Path) -> np.ndarray:
    if not out.exists():
        sc = build_scene(mi, res, spp, FOV_DEG, 0.3)
        sc["env"] = {"type": "envmap", "filename": str(envmap), "to_world": mi.ScalarTransform4f(ll.ENVMAP_TO_WORLD)}
        write_exr(out, np.ascontiguousarray(np.array(mi.render(mi.load_dict(sc), spp=spp, seed=seed),
                                                     dtype=np.float32)[..., :3]), half=False)
    return read_image(out).pixels.astype(np.float64)[..., :3]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--lights", type=int, default=128)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=64, help="samples per pixel of each basis photo")
    ap.add_argument("--truth-spp", type=int, default=1024)
    ap.add_argument("--maps", default="sunrise.exr,studio.exr,courtyard.exr")
    ap.add_argument("--yaws", default="0,130")
    ap.add_argument("--schemes", default=",".join(ALL_SCHEMES))
    ap.add_argument("--threads", type=int, default=2, help="Mitsuba's threads (at least 2: with one, loading an "
                                                             "envmap scene hangs in Mitsuba 3.x)")
    ap.add_argument("--cache", default="/tmp/ffls_bench_tradeoff_mitsuba")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "tradeoff_mitsuba.json"))
    a = ap.parse_args()
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    ll = mitsuba_latlong_module()
    t0 = time.perf_counter()
    cache = Path(a.cache)
    folder = cache / f"capture_{a.res}_{a.lights}_{a.spp}"
    dirs = stratified_directions(a.lights, "upper", 0)
    render_capture(folder, {"light": "distant", "ground_albedo": 0.3}, a.res, a.spp, FOV_DEG, dirs, max(2, a.threads))
    capture = load_capture(folder)
    names = json.loads((folder / "capture.json").read_text())["images"]
    lights = Lights(image_names=names, directions=dirs)
    print(f"capture of {a.lights} lights ready ({time.perf_counter() - t0:.0f} s; sphere radius {SPHERE_RADIUS} m)",
          flush=True)
    scenes = []  # every Mitsuba render first: drjit's render hangs once the relighters' pools exist
    for mname in a.maps.split(","):
        for yaw in (float(y) for y in a.yaws.split(",")):
            tag = f"{Path(mname).stem}_{yaw:g}"
            env = upper_map(map_path(mname), yaw, cache / f"map_{tag}.exr")
            truth = render_truth(mi, ll, env, a.res, a.truth_spp, 7, cache / f"truth_{tag}_{a.res}_{a.truth_spp}.exr")
            again = render_truth(mi, ll, env, a.res, a.truth_spp, 8, cache / f"truth2_{tag}_{a.res}_{a.truth_spp}.exr")
            # the truth is the mean of the two renders; its own relative noise is half their difference's
            scenes.append((mname, yaw, env, 0.5 * (truth + again), 0.5 * rel_rmse(again, truth)))
    print(f"truths ready ({time.perf_counter() - t0:.0f} s)", flush=True)
    schemes = [s for s in a.schemes.split(",") if s]
    options = {}
    if "kriging" in schemes:  # its kernel learnt from the capture's own photos, by leave-one-out
        fit = fit_kernel(dirs, load_photos(capture, progress=False))
        options["kriging"] = fit.options
        print(f"kriging kernel learnt from the photos by leave-one-out: {fit.describe()}", flush=True)
    relighters = {s: CpuRelighter.from_capture(capture, lights, precision="f64", cell_max_res=4096, weighting=s,
                                               weighting_options=options.get(s))
                  for s in schemes}
    rows = []
    for mname, yaw, env, truth, floor in scenes:
        lm = load_lightmap(env)
        for s, r in relighters.items():
            r.set_lightmap(lm)
            r.render()
            img = r.read_hdr().astype(np.float64)[..., :3]
            e = rel_rmse(img, truth)
            rows.append({"map": mname, "yaw": yaw, "scheme": s, "rel_rmse": e,
                         "rel_rmse_less_noise": float(np.sqrt(max(e * e - floor * floor, 0.0))),
                         "psnr": psnr_tonemapped(img, truth), "truth_noise": floor})
            print(f"{mname:14s} yaw {yaw:5.0f}  {s:12s} rel RMSE {e:.4f} ({rows[-1]['rel_rmse_less_noise']:.4f} less "
                  f"the truth's noise {floor:.4f})  PSNR {rows[-1]['psnr']:5.1f} dB", flush=True)
    print("\nmean over maps and yaws: relative RMSE, and the same less the truth's noise, against barycentric:")
    summary = {}
    for key in ("rel_rmse", "rel_rmse_less_noise"):
        summary[key] = {s: float(np.mean([r[key] for r in rows if r["scheme"] == s])) for s in schemes}
    base = summary["rel_rmse"].get("barycentric"), summary["rel_rmse_less_noise"].get("barycentric")
    for s in schemes:
        m, c = summary["rel_rmse"][s], summary["rel_rmse_less_noise"][s]
        ratio = f"  ({m / base[0]:.3f}x / {c / base[1]:.3f}x barycentric)" if base[0] else ""
        print(f"  {s:12s} {m:.4f} / {c:.4f}{ratio}")
    write_json(a.out, {"lights": a.lights, "resolution": a.res, "spp": a.spp, "truth_spp": a.truth_spp,
                       "renderer": f"mitsuba {mi.__version__} scalar_rgb path max_depth 8", "host": host_info(),
                       "seconds": time.perf_counter() - t0, "kriging_kernel": options.get("kriging"),
                       "mean": summary, "rows": rows})


if __name__ == "__main__":
    main()
