"""Relit error of each weighting scheme against ground truth (ffls synth's direct renders).

Usage::

    python benchmarks/weighting_error.py [--lights 120] [--res 64] [--maps sky,studio,courtyard]
        [--rotations 0,40] [--dirs 2048] [--texture-res 512] [--json benchmarks/results/weighting_error.json]
        [--rows spline,kriging] [--cache /tmp/NAME]

``--maps`` takes built-in map names and light-map files (``.exr``/``.hdr``, e.g.
``../shared/hdri/sunrise.exr``: real HDR maps, area-downsampled to ``--map-height`` rows).

The default synthetic scene is rendered under ``--lights`` stratified upper-hemisphere directions
(the basis) and, as the truth, lit directly by every light map (``ffls.synth.scene.render_lightmap``,
the map reduced to ``--dirs`` clustered directions) for each rotation about +Z. Every scheme
relights the basis (``ffls.weights.weighting.integrate``: exact weights, and, with
``--texture-res``, the GPU's baked-texture lookup). Reported: relative RMS error
``||relit - truth|| / ||truth||`` per map (mean over rotations), and the mean over maps; a
gaussian width sweep is included (``gaussian:k=..,w=...``); the library-only ``kriging`` scheme
(:mod:`ffls.weights.kriging`) with its Matérn kernel and nugget learnt from the basis photos by
leave-one-out (:func:`ffls.weights.kriging.fit_kernel`, no ground truth), with its default 24
slots per direction, exact and through the baked texture; and a floor, the least-squares fit of the photos to the truth
(:func:`oracle_weights`). The ``spline`` scheme (:mod:`ffls.weights.spline`) is measured
at its default, at other Lebesgue bounds, and at the bound chosen by leave-one-out on the capture
itself (:func:`spline_loo_choice`: predict held-out photos from the others, no ground truth).
Prints a table (with the ratio to ``barycentric`` and the worst per-map ratio to ``voronoi``)
and writes JSON.
"""
from __future__ import annotations

import argparse
import time

from pathlib import Path

import numpy as np

from ffls.conventions import rotation_z
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.relight.cpu import relight_fast
from ffls.weights.kriging import fit_kernel
from ffls.weights.spline import DEFAULT_MAX_LEBESGUE
from ffls.weights.weighting import ALL_SCHEMES, Weighting, bake_weights, integrate

#: Lebesgue bounds of the spline scheme measured, and offered to the leave-one-out choice.
SPLINE_BOUNDS = (1.0, 1.5, 2.0, 3.0, DEFAULT_MAX_LEBESGUE, 100.0)


def spline_loo_choice(directions, basis, bounds=SPLINE_BOUNDS, n_held: int = 25, seed: int = 0):
    """The spline's ``max_lebesgue`` with the least leave-one-out error on the capture itself.

    Each of ``n_held`` random photos ``B_j`` is predicted from the others with the spline
    weights at ``d_j`` over the remaining lights; the error is ``sum ||B_j - pred||^2 /
    sum ||B_j||^2`` (square-rooted). ``1.0`` is barycentric. Returns ``(best, {bound: error})``.
    """
    rng = np.random.default_rng(seed)
    n = directions.shape[0]
    held = rng.choice(n, min(n_held, n), replace=False)
    flat = basis.reshape(n, -1).astype(np.float64)
    errs = {}
    for bound in bounds:
        num = den = 0.0
        for j in held:
            others = np.delete(np.arange(n), j)
            wt = Weighting(directions[others], "spline", "upper", max_lebesgue=bound)
            w = wt(directions[j:j + 1]).dense(n - 1)[0]
            num += float(np.sum((w @ flat[others] - flat[j]) ** 2))
            den += float(np.sum(flat[j] ** 2))
        errs[bound] = float(np.sqrt(num / den))
    return min(errs, key=errs.get), errs


#: The row of :func:`oracle_weights`.
ORACLE = "oracle (lstsq on the truth)"


def oracle_weights(basis, truth) -> np.ndarray:
    """Per-light weights (n, 3) that fit the truth best (least squares per channel): a bound, not a scheme.

    No weighting of the map can do better with these photos than the weights that minimise
    ``||sum_i w_i B_i - truth||`` knowing the truth; its error is the floor under every scheme
    (aliasing of hard shadows and highlights between the lights, which no interpolant undoes).
    """
    n = basis.shape[0]
    b = np.asarray(basis, dtype=np.float64).reshape(n, -1, 3)
    t = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    return np.stack([np.linalg.lstsq(b[:, :, c].T, t[:, c], rcond=None)[0] for c in range(3)], axis=1)


def variants(texture_res: int, kriging_options: dict) -> list:
    """(label, scheme, options, texture_res or None) of every configuration measured.

    ``kriging_options``: the kernel :func:`ffls.weights.kriging.fit_kernel` learnt (``KernelFit.options``).
    """
    def opts(s):
        return dict(kriging_options) if s == "kriging" else {}

    out = [(s, s, opts(s), None) for s in ALL_SCHEMES]
    out += [(f"spline:L={b:g}", "spline", {"max_lebesgue": b}, None) for b in SPLINE_BOUNDS
            if b != DEFAULT_MAX_LEBESGUE]
    out += [(f"gaussian:k={k},w={w}", "gaussian", {"k": k, "width": w}, None)
            for k, w in ((4, 0.2), (4, 0.5), (6, 0.3), (8, 0.25))]
    if texture_res:
        out += [(f"{s}@tex{texture_res}", s, opts(s), texture_res) for s in ALL_SCHEMES if s != "voronoi"]
    return out


def main(argv=None) -> int:
    from common import host_info, write_json  # benchmarks/common.py
    from ffls.lightmaps.lightmap import load_lightmap
    from ffls.synth.scene import make_scene, render_lightmap, render_lights, stratified_directions

    ap = argparse.ArgumentParser()
    ap.add_argument("--lights", type=int, default=120)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--maps", default="sky,studio,courtyard")
    ap.add_argument("--rotations", default="0,40")
    ap.add_argument("--dirs", type=int, default=2048)
    ap.add_argument("--map-height", type=int, default=256)
    ap.add_argument("--texture-res", type=int, default=512)
    ap.add_argument("--json", default="benchmarks/results/weighting_error.json")
    ap.add_argument("--rows", default=None,
                    help="comma list of row labels to measure (e.g. spline,kriging,kriging@tex512; voronoi and "
                         "barycentric always; default all rows and the spline leave-one-out choice)")
    ap.add_argument("--cache", default=None, help="folder keeping the basis and the truths between runs")
    args = ap.parse_args(argv)
    scene = make_scene()
    d = stratified_directions(args.lights, "upper", seed=0)
    cache = (Path(args.cache) / f"weighting_error_{args.lights}_{args.res}_{args.dirs}_{args.map_height}.npz"
             if args.cache else None)
    cached = dict(np.load(cache)) if cache is not None and cache.exists() else {}
    basis = cached["basis"] if "basis" in cached else render_lights(scene, args.res, d)
    rots = [float(a) for a in args.rotations.split(",")]
    t0 = time.perf_counter()
    fit = fit_kernel(d, basis)
    print(f"kriging kernel by leave-one-out on the capture: Matern nu={fit.nu:g}, length {fit.length:.3f} "
          f"({fit.length / fit.spacing:g} light spacings), nugget {fit.nugget:g}; relative LOO error {fit.loo:.4f} "
          f"({time.perf_counter() - t0:.1f} s)")
    cfgs = variants(args.texture_res, fit.options)
    if args.rows:
        keep = set(args.rows.split(",")) | {"voronoi", "barycentric"}
        cfgs = [c for c in cfgs if c[0] in keep]
    prepared = {}
    for label, s, opts, tr in cfgs:
        prepared[label] = ({"texture": bake_weights(d, s, "upper", res=tr, **opts)} if tr else
                           {"weighting": Weighting(d, s, "upper", **opts)} if s != "voronoi" else {})
    loo_bound, loo_errs, loo_label = None, {}, None
    if not args.rows:
        loo_bound, loo_errs = spline_loo_choice(d, basis)
        print("spline leave-one-out on the capture: " + ", ".join(f"L={b:g} {e:.4f}" for b, e in loo_errs.items())
              + f" -> chosen L={loo_bound:g}")
        loo_label = f"spline:L={loo_bound:g}" if loo_bound != DEFAULT_MAX_LEBESGUE else "spline"
    table = {label: {} for label, *_ in cfgs}
    table[ORACLE] = {}
    t0 = time.perf_counter()
    names = []
    for spec in args.maps.split(","):
        if spec.lower().endswith((".exr", ".hdr")):
            lm = load_lightmap(spec)
            name = spec.replace("\\", "/").rsplit("/", 1)[-1].rsplit(".", 1)[0]
        else:
            lm = builtin_lightmap(spec, args.map_height)
            name = spec
        names.append(name)
        h = lm.data.shape[0]
        if lm.layout == "latlong" and h > args.map_height and h % args.map_height == 0:
            lm = lm.downsample(h // args.map_height)
        samples = lm.samples()
        errs = {label: [] for label, *_ in cfgs}
        errs[ORACLE] = []
        for a in rots:
            R = rotation_z(a)
            key = f"truth {name} {a:g}"
            if key not in cached:
                cached[key] = render_lightmap(scene, samples, args.res, n_dirs=args.dirs, rotation=R)
            truth = cached[key].astype(np.float64)
            for label, s, opts, tr in cfgs:
                w = integrate(samples, d, R, "upper", s, **prepared[label], **opts).weights
                relit = relight_fast(w, basis).astype(np.float64)
                errs[label].append(float(np.linalg.norm(relit - truth) / np.linalg.norm(truth)))
            relit = relight_fast(oracle_weights(basis, truth), basis).astype(np.float64)
            errs[ORACLE].append(float(np.linalg.norm(relit - truth) / np.linalg.norm(truth)))
        for label in errs:
            table[label][name] = float(np.mean(errs[label]))
    maps = names
    if cache is not None and not cache.exists():
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.savez(cache, basis=basis, **{k: v for k, v in cached.items() if k != "basis"})
    print(f"{args.lights} lights, {args.res}^2, truth from {args.dirs} directions, rotations {args.rotations} "
          f"({time.perf_counter() - t0:.0f} s); relative RMS error")
    print(f"{'scheme':>28} " + " ".join(f"{m:>10}" for m in maps)
          + f" {'mean':>8} {'/ voronoi':>9} {'/ bary':>7} {'worst map / voronoi':>20}")
    ref = np.mean([table["voronoi"][m] for m in maps])
    ref_b = np.mean([table["barycentric"][m] for m in maps])
    for label in table:
        mean = float(np.mean([table[label][m] for m in maps]))
        worst = max(table[label][m] / table["voronoi"][m] for m in maps)
        table[label]["mean"] = mean
        table[label]["worst_map_over_voronoi"] = float(worst)
        print(f"{label:>28} " + " ".join(f"{table[label][m]:>10.4f}" for m in maps)
              + f" {mean:>8.4f} {mean / ref:>9.3f} {mean / ref_b:>7.3f} {worst:>20.3f}")
    if loo_label is not None:
        print(f"spline, bound chosen by leave-one-out (L={loo_bound:g}): "
              f"{table[loo_label]['mean'] / ref_b:.3f} of barycentric")
    write_json(args.json, {"args": vars(args), "host": host_info(), "rel_rmse": table,
                           "kriging": {**fit.options, "loo": fit.loo, "spacing": fit.spacing},
                           "spline_loo": {"chosen": loo_bound, "errors": {str(b): e for b, e in loo_errs.items()}}})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
