"""Where the composite's error comes from, on the independent Mitsuba renders (docs/composite.md).

``benchmarks/composite_mitsuba.py`` measures differential rendering's change-region error on
path-traced captures (16 spp basis photos). This script splits that error by replacing one
ingredient at a time with an exact, independently rendered one (Mitsuba 3, same scenes and
cache as ``composite_mitsuba.py``), in this order:

A. the composite as ``ffls composite`` makes it: the basis photos (``--spp``), the map's compact
   sources (``split_compact_sources``) relit by ``--sources`` (levelset / lightflow / weights)
   and the rest of the map through the weighting scheme;
B. the sources' samples rendered *directly* as directional lights (same spp as the basis: as
   noisy), the rest as in A: A -> B is the **shadow interpolation between lights**;
C. those direct renders at ``--oracle-spp``: B -> C is the **sources' photo noise**;
D. the rest of the map relit from a less noisy basis (``--clean-spp``, another sampler seed), and
   C's sources: C -> D is the **rest's photo noise** (A on that basis is given too);
E. the rest rendered directly as an environment map (``--oracle-spp``): D -> E is the
   **discretisation of the smooth part into the lights**;
F. the whole map rendered directly: E -> F is the sources' **k-sample discretisation** (their
   extent); F is exact relighting, what remains is differential rendering itself:
G. F's captures rendered on the *scene's* ground albedo, with the registration fitted (``auto``)
   and with none: F -> G(auto) is the **albedo mismatch** (the registration's scale standing for
   the albedo ratio, the object's bounce), G(auto) -> G(none) the **registration fit**; G(none)
   is the **distant-map model** (the real wall's parallax, the spheres' trace) plus the truth's
   noise; the truth's own noise is measured by a second truth render (another seed).

Each row: relative L1 over the change region (surface pixels off the object where the truth
differs from the background by more than 3%), as ``composite_mitsuba.py``, and over its part off
the calibration spheres' shadows (where the surface-alone capture on the scene's albedo, rendered
exactly, is not 3% darker than the background): inside them both captures lack the light that the
object would block, so the object's shadow there is in neither (docs/composite.md).

    python benchmarks/composite_attribution.py [--maps sunrise,studio,courtyard] [--lights 200]
        [--scheme barycentric] [--sources levelset,lightflow] [--spp 16] [--clean-spp 64]
        [--oracle-spp 256] [--cache DIR]

Needs ``pip install mitsuba``. Writes ``benchmarks/results/composite_attribution.json``.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import composite_mitsuba as cm
from common import host_info, mitsuba_latlong_module, write_json

from ffls.errors import InputError
from ffls.io.images import read_image, write_exr
from ffls.lightmaps.lightmap import load_lightmap
from ffls.relight.composite import LUMINANCE, composite
from ffls.relight.cpu import CpuRelighter
from ffls.relight.lightflow import LightFlowRelighter, split_compact_sources


def upper_only(data: np.ndarray) -> np.ndarray:
    """A lat-long map with the rows below the horizon set to 0 (ffls relights the upper hemisphere)."""
    out = np.array(data, dtype=np.float32, copy=True)
    out[out.shape[0] // 2:] = 0
    return out


def render_cached(path: Path, make):
    """``make()``'s image, rendered once and cached as an EXR at ``path``."""
    if not path.exists():
        write_exr(path, make(), half=False)
    return read_image(path).pixels.astype(np.float64)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", default="sunrise,studio,courtyard")
    ap.add_argument("--lights", type=int, default=200)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16, help="the basis photos' samples per pixel")
    ap.add_argument("--clean-spp", type=int, default=64, help="a second, less noisy basis (0: none)")
    ap.add_argument("--oracle-spp", type=int, default=256, help="the direct renders")
    ap.add_argument("--truth-spp", type=int, default=1024)
    ap.add_argument("--map-height", type=int, default=128)
    ap.add_argument("--map-spp", type=int, default=256)
    ap.add_argument("--scheme", default="barycentric")
    ap.add_argument("--sources", default="levelset,lightflow")
    ap.add_argument("--cache", default="/tmp/ffls_bench_composite_mitsuba")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "composite_attribution.json"))
    a = ap.parse_args()
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    ll = mitsuba_latlong_module()
    ll.register()
    cache = Path(a.cache)
    cache.mkdir(parents=True, exist_ok=True)
    R, n, osp = a.res, a.lights, a.oracle_spp
    t0 = time.perf_counter()
    om_b, sm_b, _ = cm.cast_masks(mi, R)
    om, sm = om_b.astype(np.float64), sm_b.astype(np.float64)
    kinds = (("object", 0, True), ("surface", 1, False))
    caps = {spp: {k: cm.render_capture(mi, cache / f"{k}_{R}_{n}_{spp}", n, seed, obj, R, spp,
                                 seed_offset=0 if spp == a.spp else 50000)
                  for k, seed, obj in kinds}
            for spp in ([a.spp] + ([a.clean_spp] if a.clean_spp else []))}
    rows = []

    def envmap(path):
        return {"type": "envmap", "filename": str(path), "to_world": mi.ScalarTransform4f(ll.ENVMAP_TO_WORLD)}

    def capture_render(env_or_light, with_object, albedo, spp, seed):
        sc = {"type": "scene", "integrator": {"type": "path", "max_depth": 6}, "sensor": cm.camera_sensor(mi, R, spp),
              **cm.scene_shapes(mi, albedo, with_object, True, False), **env_or_light}
        return np.array(mi.render(mi.load_dict(sc), seed=seed))

    for name in a.maps.split(","):
        bg, tr, lm = cm.scene_renders(mi, ll, cache, name, R, a.truth_spp, a.map_height, a.map_spp)
        tr2 = render_cached(cache / f"{name}_truth2_{R}_{a.truth_spp}.exr", lambda: cm.scene_render(
            mi, ll, name, R, a.truth_spp, with_object=True, seed=8))
        change = cm.change_region(tr, bg, sm_b, om_b)

        def rel(x, ref=tr, where=change):
            return float(np.abs(x - ref)[where].sum() / max(ref[where].sum(), 1e-30))

        def comp(o, s, registration="auto"):
            return composite(bg, o, s, om, sm, registration=registration).image.astype(np.float64)

        split = split_compact_sources(lm, None, "upper")
        mtag = f"{name}{R}m{a.map_height}s{a.map_spp}"   # the direct renders depend on the map
        full_file, rest_file = cache / f"{mtag}_fullmap.exr", cache / f"{mtag}_restmap.exr"
        write_exr(full_file, upper_only(lm.data), half=False)
        write_exr(rest_file, upper_only(split.rest.data), half=False)

        def src_render(key, with_object, spp):
            out = np.zeros((R, R, 3))
            for si, s in enumerate(split.sources):
                for k, (d, p) in enumerate(zip(s.sample_directions, s.sample_powers)):
                    if d[2] <= 0:
                        continue
                    img = render_cached(cache / f"{mtag}_src{si}_{k}_{key}_{R}_{spp}.exr", lambda: capture_render(
                        {"light": {"type": "directional", "direction": list(-d),
                                   "irradiance": {"type": "rgb", "value": 1.0}}},
                        with_object, cm.CAPTURE_ALBEDO, spp, 900 + 37 * si + k + (0 if with_object else 500)))
                    out += img * p[None, None, :]
            return out

        def exact(file, tag, with_object, albedo):
            return render_cached(cache / f"{mtag}_{tag}_{'object' if with_object else 'surface'}_{albedo}_{R}_{osp}.exr",
                                 lambda: capture_render({"env": envmap(file)}, with_object, albedo, osp,
                                                        21 if with_object else 22))

        def relit_rest(spp):
            out = []
            for k, _, _ in kinds:
                r = CpuRelighter.from_capture(*caps[spp][k], precision="f64", cell_max_res=4096, weighting=a.scheme)
                r.set_lightmap(split.rest)
                r.render()
                out.append(r.read_hdr().astype(np.float64))
            return out

        def relit_sources(spp, kind):
            out = []
            for k, _, _ in kinds:
                r = CpuRelighter.from_capture(*caps[spp][k], precision="f64", cell_max_res=4096, weighting=a.scheme)
                if kind != "weights":
                    r = LightFlowRelighter(r, interpolation="flow" if kind == "lightflow" else kind)
                r.set_lightmap(lm)
                r.render()
                out.append(r.read_hdr().astype(np.float64))
            return out

        same = [exact(full_file, "full", obj, cm.SCENE_ALBEDO) for _, _, obj in kinds]
        # the spheres' shadows: where the surface-alone capture on the scene's albedo, relit exactly, is
        # 3% darker than the background (which has no spheres); there both captures lack the light the
        # object would block (docs/composite.md, "Differential rendering alone")
        clear = change & ~(same[1] @ LUMINANCE < 0.97 * (bg @ LUMINANCE))

        def row(step, what, o, s, registration="auto", ref=tr):
            try:
                c = comp(o, s, registration)
                err, out, note = rel(c, ref), rel(c, ref, clear), ""
            except InputError as e:   # a registration that fails is a result too
                err = out = None
                note = str(e)
            rows.append({"map": name, "lights": n, "scheme": a.scheme, "step": step, "what": what,
                         "change": err, "change_off_sphere_shadows": out, "change_pixels": int(change.sum()),
                         "off_sphere_shadow_pixels": int(clear.sum()), "note": note})
            print(f"{name:10s} {step:3s} " + (f"{100 * err:5.1f}% ({100 * out:5.1f}% off the spheres' shadows)"
                                               if err is not None else "  n/a ")
                  + f"  {what}" + (f" ({note})" if note else ""), flush=True)

        print(f"{name}: {split.describe()}; truth noise (truth vs second truth) "
              f"{100 * rel(tr2) / np.sqrt(2):.1f}% per render", flush=True)
        rows.append({"map": name, "step": "truth-noise", "change": rel(tr2) / np.sqrt(2),
                     "what": "the truth's own noise: |truth - truth2| / sqrt(2)", "split": split.describe()})
        rest16 = relit_rest(a.spp)
        for kind in a.sources.split(","):
            o, s = relit_sources(a.spp, kind)
            row("A", f"{kind}, {a.spp} spp basis", o, s)
            if a.clean_spp:
                o, s = relit_sources(a.clean_spp, kind)
                row("A'", f"{kind}, {a.clean_spp} spp basis", o, s)
        src_lo = [src_render(k, obj, a.spp) for k, _, obj in kinds]
        row("B", f"sources rendered directly at {a.spp} spp, rest weighted ({a.spp} spp basis)",
            rest16[0] + src_lo[0], rest16[1] + src_lo[1])
        src_hi = [src_render(k, obj, osp) for k, _, obj in kinds]
        row("C", f"sources rendered directly at {osp} spp, rest weighted ({a.spp} spp basis)",
            rest16[0] + src_hi[0], rest16[1] + src_hi[1])
        if a.clean_spp:
            rest_c = relit_rest(a.clean_spp)
            row("D", f"sources direct {osp} spp, rest weighted ({a.clean_spp} spp basis)",
                rest_c[0] + src_hi[0], rest_c[1] + src_hi[1])
        rest_x = [exact(rest_file, "rest", obj, cm.CAPTURE_ALBEDO) for _, _, obj in kinds]
        row("E", f"sources direct, rest rendered directly ({osp} spp)", rest_x[0] + src_hi[0], rest_x[1] + src_hi[1])
        full_x = [exact(full_file, "full", obj, cm.CAPTURE_ALBEDO) for _, _, obj in kinds]
        row("F", f"whole map rendered directly ({osp} spp): exact relighting", *full_x)
        row("F2", "F against the mean of two truths (half the truth's noise variance)", *full_x,
            ref=0.5 * (tr + tr2))
        row("G", f"exact relighting of captures on the scene's albedo {cm.SCENE_ALBEDO}, registration auto", *same)
        row("G0", "the same, registration none: the distant-map model and the truth's noise", *same,
            registration="none")
    write_json(a.out, {"resolution": R, "lights": n, "spp": a.spp, "clean_spp": a.clean_spp, "oracle_spp": osp,
                       "truth_spp": a.truth_spp, "host": host_info(), "seconds": time.perf_counter() - t0,
                       "rows": rows})


if __name__ == "__main__":
    main()
