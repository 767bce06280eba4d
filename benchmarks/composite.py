"""Differential rendering against a direct render of the virtual scene (issue 14, docs/composite.md).

For each light map (the virtual scene's sky, with a wall: :func:`ffls.synth.virtual.wall_lightmap`)
the virtual scene is rendered directly, with and without the object (ground albedo 0.5;
:func:`ffls.synth.virtual.render_virtual_scene`). For each number of lights N, two captures are
rendered once (:func:`ffls.synth.scene.write_synthetic_capture`): the object and four spheres on a
ground of albedo 0.3 under N lights, and the ground and spheres alone under N other lights. For
each weighting scheme (``--schemes``, each a ``method=`` of
:func:`ffls.weights.weighting.integrate`, every scheme of :data:`ffls.weights.weighting.SCHEMES`),
both captures are relit under the map and composited (:func:`ffls.relight.composite.composite`,
both methods), and compared with the direct render:

* ``change``: relative L1 error (sum |composite - truth| / sum truth, RGB) over the pixels where
  the object changes the surface: surface pixels off the object whose luminance in the truth
  differs from the background's by more than 3% (its shadows; ``ffls synth`` renders no bounce
  from the object onto the ground);
* ``paste``: the same error for the object pasted without its shadow (the background with the
  relit object over its mask);
* ``overall``: over every pixel; ``object``: over the object's mask;
* ``sphere_trace``: mean |composite - background| over a ring around the calibration spheres
  (surface pixels within 2% of the image size of a sphere, off the change region), relative to
  the background's mean there; the spheres themselves are outside the surface mask.

    python benchmarks/composite.py [--maps courtyard,sunrise,studio,sky] [--lights 50,100,200,400]
        [--schemes voronoi,...] [--res 256] [--truth-dirs 2048] [--cache DIR] [--oracle]
        [--lightflow [--flow dis|farneback]] [--exact-sources]

``--oracle`` adds rows (scheme ``direct``, lights 0) where the two fields are not relit captures but
the capture scenes rendered directly under the map: the error of differential rendering itself
(the captured ground's albedo in the object's bounce light, the registration), without the
relighting's discretisation of the map over the lights.

``--lightflow`` adds rows (scheme ``SCHEME+lightflow``) where the map's compact bright sources are
split off and relit by optical-flow interpolation between the basis photos of their nearest lights
(:func:`ffls.relight.lightflow.relight_lightflow`), the rest with the scheme. ``--exact-sources``
adds rows (``SCHEME+exact``) with the same split but the sources rendered directly by ``ffls
synth`` (what a perfect interpolation would give).

Prints a table and writes ``benchmarks/results/composite.json``.
"""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import cv2
import numpy as np

from common import host_info, write_json

from ffls.io.capture import load_capture_and_lights
from ffls.io.images import read_image, write_exr
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.relight.basis import accepted_basis
from ffls.relight.composite import LUMINANCE, METHODS, composite
from ffls.relight.cpu import relight_fast
from ffls.relight.lightflow import FlowInterpolator, LevelSetInterpolator, relight_lightflow, split_compact_sources
from ffls.synth.scene import (make_scene, render_light, render_lightmap, stratified_directions,
                              write_synthetic_capture)
from ffls.synth.virtual import composite_masks, render_virtual_scene, wall_lightmap
from ffls.weights.weighting import SCHEMES, integrate

#: Weighting schemes tried by default (:mod:`ffls.weights.weighting`); --schemes names a subset.
DEFAULT_SCHEMES = tuple(SCHEMES)
CAPTURE_ALBEDO, SCENE_ALBEDO = 0.3, 0.5


def _capture(folder: Path, scene, n: int, seed: int, res: int):
    if not (folder / "capture.json").exists():
        write_synthetic_capture(folder, scene=scene, directions=stratified_directions(n, "upper", seed), seed=seed,
                                resolution=res, progress=False)
    cap, lights = load_capture_and_lights(folder)
    return accepted_basis(cap, lights), cap.hemisphere


def _virtual(cache: Path, name: str, lm, res: int, dirs: int):
    out = {}
    for key, with_object in (("background", False), ("truth", True)):
        p = cache / f"{name}_{key}_{res}_{dirs}.exr"
        if not p.exists():
            write_exr(p, render_virtual_scene(lm, res, SCENE_ALBEDO, with_object, n_dirs=dirs))
        out[key] = read_image(p).pixels.astype(np.float64)
    return out["background"], out["truth"]


def _weights(lm, dirs, hemisphere, scheme):
    return integrate(lm, dirs, None, hemisphere, scheme).weights


def _rel(a, b, m):
    return float(np.abs(a - b)[m].sum() / max(np.abs(b)[m].sum(), 1e-30))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", default="courtyard,sunrise,studio,sky")
    ap.add_argument("--lights", default="50,100,200,400")
    ap.add_argument("--schemes", default=",".join(DEFAULT_SCHEMES))
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--truth-dirs", type=int, default=2048)
    ap.add_argument("--cache", default="/tmp/ffls_bench_composite")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "composite.json"))
    ap.add_argument("--oracle", action="store_true", help="also composite direct renders of the two capture scenes")
    ap.add_argument("--lightflow", action="store_true",
                    help="also relight with the compact sources interpolated by flow (scheme SCHEME+lightflow)")
    ap.add_argument("--flow", default="dis", help="flow method of --lightflow (dis, farneback)")
    ap.add_argument("--levelset", action="store_true",
                    help="also relight with the compact sources interpolated by shadow level sets "
                         "(ffls.relight.lightflow.LevelSetInterpolator; scheme SCHEME+levelset)")
    ap.add_argument("--exact-sources", action="store_true",
                    help="also rows SCHEME+exact: the compact sources rendered directly (ffls synth) and the rest "
                         "relit; the bound of --lightflow's split, without its interpolation error")
    a = ap.parse_args()
    cache = Path(a.cache)
    cache.mkdir(parents=True, exist_ok=True)
    R = a.res
    obj_scene = make_scene(spheres=4, ground_albedo=CAPTURE_ALBEDO)
    surf_scene = dataclasses.replace(obj_scene, with_object=False)
    masks = composite_masks(obj_scene, R)
    om, sm, sph = (masks[k].astype(np.float64) for k in ("object", "surface", "spheres"))
    grow = max(2, int(round(0.02 * R)))
    near_sph = cv2.dilate(masks["spheres"].astype(np.uint8), cv2.getStructuringElement(
        cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1))).astype(bool)
    rows = []
    t0 = time.perf_counter()
    captures = {}
    interpolators = {}
    for n in (int(v) for v in a.lights.split(",")):
        captures[n] = (_capture(cache / f"object_{R}_{n}", obj_scene, n, 0, R),
                       _capture(cache / f"surface_{R}_{n}", surf_scene, n, 1, R))
    print(f"captures ready ({time.perf_counter() - t0:.0f} s)")
    for name in a.maps.split(","):
        lm = wall_lightmap(builtin_lightmap(name), ground_albedo=SCENE_ALBEDO)
        bg, tr = _virtual(cache, name, lm, R, a.truth_dirs)
        lt, lb = tr @ LUMINANCE, bg @ LUMINANCE
        change = (sm > 0.5) & (om < 0.5) & (np.abs(lt - lb) > 0.03 * lb)
        ring = near_sph & (sm > 0.5) & ~change
        every = np.ones(om.shape, dtype=bool)
        obj = om > 0.5
        fields = []
        if a.oracle:
            direct = []
            for key, sc in (("object", obj_scene), ("surface", surf_scene)):
                p = cache / f"{name}_direct_{key}_{R}_{a.truth_dirs}.exr"
                if not p.exists():
                    write_exr(p, render_lightmap(sc, lm, R, n_dirs=a.truth_dirs))
                direct.append(read_image(p).pixels.astype(np.float64))
            fields.append((0, "direct", *direct))
        for n, (((ob, od), oh), ((sb, sd), sh)) in captures.items():
            for scheme in a.schemes.split(","):
                wo, ws = _weights(lm, od, oh, scheme), _weights(lm, sd, sh, scheme)
                fields.append((n, scheme, relight_fast(wo, ob).astype(np.float64),
                               relight_fast(ws, sb).astype(np.float64)))
                if a.lightflow:
                    for key, b, d, h in (("o", ob, od, oh), ("s", sb, sd, sh)):
                        if (n, key) not in interpolators:
                            interpolators[n, key] = FlowInterpolator(b, d, h, flow=a.flow)
                    t1 = time.perf_counter()
                    o, split = relight_lightflow(ob, od, lm, None, oh, scheme=scheme, interpolator=interpolators[n, "o"])
                    s, _ = relight_lightflow(sb, sd, lm, None, sh, scheme=scheme, interpolator=interpolators[n, "s"])
                    print(f"{name} {n} {scheme}+lightflow: {split.describe()} ({time.perf_counter() - t1:.1f} s)")
                    fields.append((n, f"{scheme}+lightflow", o.astype(np.float64), s.astype(np.float64)))
                if a.levelset:
                    for key, b, d, h in (("o", ob, od, oh), ("s", sb, sd, sh)):
                        if (n, key, "levelset") not in interpolators:
                            interpolators[n, key, "levelset"] = LevelSetInterpolator(b, d, h)
                    t1 = time.perf_counter()
                    o, split = relight_lightflow(ob, od, lm, None, oh, scheme=scheme,
                                                 interpolator=interpolators[n, "o", "levelset"])
                    s, _ = relight_lightflow(sb, sd, lm, None, sh, scheme=scheme,
                                             interpolator=interpolators[n, "s", "levelset"])
                    print(f"{name} {n} {scheme}+levelset: {split.describe()} ({time.perf_counter() - t1:.1f} s)")
                    fields.append((n, f"{scheme}+levelset", o.astype(np.float64), s.astype(np.float64)))
                if a.exact_sources:
                    split = split_compact_sources(lm, None, oh)
                    pair = []
                    for sc, b, d, h in ((obj_scene, ob, od, oh), (surf_scene, sb, sd, sh)):
                        img = relight_fast(integrate(split.rest, d, None, h, scheme).weights, b).astype(np.float64)
                        for src in split.sources:
                            for sdir, sp in zip(src.sample_directions, src.sample_powers):
                                img += render_light(sc, R, direction=sdir) * sp
                        pair.append(img)
                    fields.append((n, f"{scheme}+exact", *pair))
        for n, scheme, o, s in fields:
            paste = bg * (1 - om[..., None]) + o * om[..., None]
            for method in METHODS:
                r = composite(bg, o, s, om, sm, method=method)
                c = r.image.astype(np.float64)
                rows.append({
                    "map": name, "lights": n, "scheme": scheme, "method": method,
                    "change": _rel(c, tr, change), "paste": _rel(paste, tr, change),
                    "overall": _rel(c, tr, every), "object": _rel(c, tr, obj),
                    "sphere_trace": float((np.abs(c - bg)[ring] @ LUMINANCE).mean() / (bg[ring] @ LUMINANCE).mean()),
                    "change_pixels": int(change.sum()),
                    "registration": r.registration.to_json(),
                })
                x = rows[-1]
                print(f"{name:10s} {n:4d} {scheme:24s} {method:12s} change {100 * x['change']:5.1f}%  paste "
                      f"{100 * x['paste']:5.1f}%  overall {100 * x['overall']:4.1f}%  object "
                      f"{100 * x['object']:4.1f}%  sphere trace {100 * x['sphere_trace']:4.1f}%  "
                      f"({x['change_pixels']} px)", flush=True)
    write_json(a.out, {"resolution": R, "truth_dirs": a.truth_dirs, "capture_albedo": CAPTURE_ALBEDO,
                       "scene_albedo": SCENE_ALBEDO, "host": host_info(),
                       "seconds": time.perf_counter() - t0, "rows": rows})


if __name__ == "__main__":
    main()
