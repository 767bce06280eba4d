"""Speed against accuracy, measured: every quality knob on captures with ground truth.

Usage: python benchmarks/tradeoff.py [--lights 128] [--res 96] [--oracle-dirs 2048]
                                     [--time-res 512] [--reps 3] [--quick] [--out docs/tradeoff.md]

Ground truth: ``ffls.synth.scene.render_lightmap`` (the direct render of the synthetic scene under
the light map, ``--oracle-dirs`` clustered directions; docs/synth.md measures its own error at
4-600x below relighting's) for each light map and rotation. The capture is the same scene's
distant-light renders from ``--lights`` stratified directions (``ffls synth``'s).

Light maps (Poly Haven, CC0, ``/work/shared/hdri`` = ``assets/lightmaps``):

* ``sunrise.exr`` -- a sharp sun: open field, low sun (peak ~3.5e4);
* ``studio.exr`` -- an interior with windows: a small studio lit by soft boxes (peak ~617);
* ``courtyard.exr`` -- an overcast sky (peak ~55);

each at two yaw rotations (0 and 130 degrees).

For every configuration (:class:`ffls.relight.quality.Quality`):

* error: relative RMS error ``||I - T|| / ||T||`` of the relit image (CPU, float64 sums, the
  configuration's storage rounding, rank, subset and pass-1 map height), and PSNR (dB) of the
  tone-mapped 8-bit images (sRGB curve, exposure metered on the truth, same for both);
* time: ms per frame of the GPU engine (pass 1 + projection + pass 2 + display, the map rotated
  each frame, ``ctx.finish()``) on a ``--time-res`` square basis of as many lights (timing does
  not depend on the content); median of ``--reps`` interleaved rounds.

Also: the flicker metric of ``benchmarks/flicker.py`` when that file exists, the near-light
experiment (photos lit by point lights at different distances, relit with and without
``near_correction``) and the automatic choice's error estimate (leave-one-out) against the truth.

Writes the table and a Pareto plot (``docs/images/tradeoff_pareto.png``) into ``--out`` and JSON
to ``benchmarks/results/tradeoff.json``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from ffls.conventions import rotation_z
from ffls.display.tonemap import auto_exposure, to_uint8, tonemap
from ffls.lightmaps.lightmap import load_lightmap
from ffls.relight.auto import estimate_errors, relight_quality, truncate
from ffls.relight.compress import compress_basis
from ffls.relight.quality import Quality, apply_near_correction, farthest_point_subset
from ffls.synth import scene as synth
from ffls.weights.weighting import EXTRA_SCHEMES, SCHEMES

from common import device_info, device_line, host_info, write_json  # benchmarks/common.py

ROOT = Path(__file__).resolve().parents[1]
MAPS = (("sharp sun", "sunrise.exr"), ("interior, windows", "studio.exr"), ("overcast", "courtyard.exr"))
YAWS = (0.0, 130.0)


def rel_rmse(img, truth) -> float:
    return float(np.linalg.norm(img - truth) / np.linalg.norm(truth))


def psnr_tonemapped(img, truth) -> float:
    ev = auto_exposure(truth)
    a = to_uint8(tonemap(truth, ev, "srgb")).astype(np.float64)
    b = to_uint8(tonemap(img, ev, "srgb")).astype(np.float64)
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0 else float(10 * np.log10(255.0 ** 2 / mse))


def map_path(name) -> Path:
    for folder in (ROOT / "assets" / "lightmaps", Path("/work/shared/hdri")):
        if (folder / name).exists():
            return folder / name
    raise SystemExit(f"light map {name} not found in assets/lightmaps")


def configurations(n: int, quick: bool = False) -> list[Quality]:
    """The grid: scheme x rank x pass-1 map height (float16, all photos), then subsets, precision and textures."""
    ranks = [None, 7, 15, 23, 31, 63] if not quick else [None, 15]
    heights = [None, 64, 32] if not quick else [None, 64]
    out = []
    for k in ranks:
        if k is not None and k >= n - 1:
            continue
        for h in heights:
            out.append(Quality(rank=k, map_res=h))
    for w in SCHEMES[1:]:
        for k in ((None, 15, 31) if not quick else (None,)):
            for h in ((None, 64) if not quick else (64,)):
                out.append(Quality(weighting=w, rank=k, map_res=h))
    for m in (n // 2, n // 4):
        for h in ((None, 64) if not quick else (64,)):
            out.append(Quality(basis_subset=m, map_res=h))
            out.append(Quality(basis_subset=m, rank=15 if m > 16 else None, map_res=h))
    out += [Quality(precision="f32", map_res=64), Quality(precision="f32", rank=15, map_res=64)]
    out += [Quality(rank=15, map_res=64, cell_res=c) for c in (128, 512)]
    if not quick:
        out += [Quality(weighting="gaussian", rank=15, map_res=64, cell_res=c) for c in (128, 256)]
    seen, uniq = set(), []
    for q in out:
        if q not in seen:
            seen.add(q)
            uniq.append(q)
    return uniq


def time_configs(configs, n, res, reps, lightmap):
    """Median ms per frame of each configuration on the GPU engine; None where no context exists."""
    from ffls.errors import GLUnavailable
    from ffls.gpu.context import create_headless_context
    from ffls.gpu.engine import gpu_frame_ms

    try:
        ctx = create_headless_context()
    except GLUnavailable as e:
        print(f"no GL context ({e}); times left out")
        return None, {}
    rng = np.random.default_rng(0)
    basis = rng.random((n, res, res, 3), dtype=np.float32)
    dirs = synth.stratified_directions(n, "upper", seed=1)
    times = {i: [] for i in range(len(configs))}
    comp = {}  # one compression per subset, truncated per rank (timing does not depend on the content)
    for q in configs:
        if q.rank is not None:
            m = q.basis_subset or n
            comp[m] = max(comp.get(m, 0), q.rank)
    for m, k in comp.items():
        comp[m] = compress_basis(basis[farthest_point_subset(dirs, m)] if m < n else basis, k)
    for r in range(reps):
        for i, q in enumerate(configs):
            times[i].append(gpu_frame_ms(ctx, basis, dirs, lightmap, q, "upper", frames=3,
                                         compressed=comp.get(q.basis_subset or n)))
        print(f"  timing round {r + 1}/{reps} done")
    info = device_info(ctx)
    ctx.release()
    return [float(np.median(times[i])) for i in range(len(configs))], info


def near_experiment(scene, res, n, oracle_dirs, lm, quick=False):
    """Relit error of near-light captures (constant lamp intensity) with and without the correction."""
    d = synth.stratified_directions(n, "upper", seed=2)
    rng = np.random.default_rng(5)
    truth = synth.render_lightmap(scene, lm, res, n_dirs=oracle_dirs)
    obj = synth.pixel_labels(scene, res) == synth.LABEL_OBJECT
    rows = []
    cases = [("distant", None), ("near, all at 2 m", (2.0, 2.0)), ("near, 1.5-3 m", (1.5, 3.0)),
             ("near, 1-4 m", (1.0, 4.0)), ("near, 0.6-1.2 m", (0.6, 1.2))]
    if quick:
        cases = cases[:1] + cases[2:3]
    for label, span in cases:
        if span is None:
            basis = synth.render_lights(scene, res, d)
            pos = None
        else:
            r = rng.uniform(span[0], span[1], n)
            pos = d * r[:, None]
            I = float(np.median(r)) ** 2  # one lamp: constant intensity, unit irradiance at the median distance
            basis = np.stack([synth.render_light(scene, res, position=q, intensity=I) for q in pos])
        for corr in ((False, True) if pos is not None else (False,)):
            b, dd = basis, d
            if corr:
                b, dd, _ = apply_near_correction(basis, pos)
            img = relight_quality(b, dd, lm, None, Quality(precision="f32"))
            rows.append({"capture": label, "correction": corr, "rel_rmse": rel_rmse(img, truth),
                         "rel_rmse_object": rel_rmse(img[obj], truth[obj]), "psnr": psnr_tonemapped(img, truth)})
            print(f"  near: {label:<20} correction {corr!s:<5} rel RMSE {rows[-1]['rel_rmse']:.4f} "
                  f"(object {rows[-1]['rel_rmse_object']:.4f})")
    return rows


def library_rows(basis, dirs, maps, truths, schemes=("barycentric", "spline") + EXTRA_SCHEMES):
    """Relit error of the library-only schemes next to ``barycentric`` and ``spline``, errors only.

    The library-only schemes (:data:`ffls.weights.weighting.EXTRA_SCHEMES`: ``kriging``, its
    kernel learnt from ``basis`` by leave-one-out) have no ``Quality`` and are not timed; all rows
    here use the exact float64 weights (``integrate``) and the full float32 basis, so they
    compare with each other (the grid's rows store the basis in float16).
    """
    from ffls.relight.cpu import relight_fast
    from ffls.weights.kriging import fit_kernel
    from ffls.weights.weighting import Weighting, integrate

    fit = fit_kernel(dirs, basis)
    print(f"  kriging kernel by leave-one-out: nu {fit.nu:g}, length {fit.length:.3f} "
          f"({fit.length / fit.spacing:g} spacings), nugget {fit.nugget:g}, LOO error {fit.loo:.4f}")
    rows = []
    for s in schemes:
        opts = fit.options if s == "kriging" else {}
        wt = Weighting(dirs, s, "upper", **opts)
        row = {"weighting": s, "options": {k: v for k, v in opts.items()}}
        for name, lm in maps.items():
            errs = [rel_rmse(relight_fast(integrate(lm, dirs, rotation_z(yaw), "upper", s, weighting=wt, **opts).weights,
                                          basis).astype(np.float64), truths[(name, yaw)]) for yaw in YAWS]
            row[f"rel_rmse[{name}]"] = float(np.mean(errs))
        row["mean_rel_rmse"] = float(np.mean([row[f"rel_rmse[{m}]"] for m in maps]))
        rows.append(row)
        print(f"  library row {s:<12} mean rel RMSE {row['mean_rel_rmse']:.4f}")
    ref = next(r["mean_rel_rmse"] for r in rows if r["weighting"] == "barycentric")
    for r in rows:
        r["over_barycentric"] = r["mean_rel_rmse"] / ref
    return rows


def flicker_rows(basis, dirs, lm, frames: int = 40):
    """Flicker (benchmarks/flicker.py's metric: RMS of the second difference over the RMS image) of
    each scheme under a map with a sun turning in 1-degree steps; None where flicker.py is absent."""
    try:
        import flicker  # benchmarks/flicker.py (written with the weighting schemes)
    except ImportError:
        return None
    vals = flicker.scheme_flicker(basis, dirs, lm, SCHEMES, frames=frames, step_deg=1.0, start_deg=10.0)
    return [{"weighting": w, "flicker": float(v), "ratio_to_voronoi": float(v / vals["voronoi"])}
            for w, v in vals.items()]


def pareto(points):
    """Indices of the points (ms, error) not dominated by another (lower or equal in both, lower in one)."""
    idx = []
    for i, (t, e) in enumerate(points):
        if t is None:
            continue
        dom = any((t2 <= t and e2 <= e and (t2 < t or e2 < e)) for j, (t2, e2) in enumerate(points)
                  if j != i and t2 is not None)
        if not dom:
            idx.append(i)
    return idx


def plot(rows, map_names, path, device):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(map_names) + 1, figsize=(4.2 * (len(map_names) + 1), 4), sharey=False)
    for ax, name in zip(axes, list(map_names) + ["mean"]):
        key = "mean_rel_rmse" if name == "mean" else f"rel_rmse[{name}]"
        pts = [(r["ms"], r[key]) for r in rows]
        front = set(pareto(pts))
        for i, r in enumerate(rows):
            if r["ms"] is None:
                continue
            q = r["quality"]
            colour = "C0" if q["rank"] is None else "C1"
            marker = "s" if q["basis_subset"] else ("^" if q["precision"] == "f32" else "o")
            colour = {"voronoi": colour, "antialiased": "C2", "barycentric": "C3", "gaussian": "C4",
                      "spline": "C5", "kriging": "C6"}[q["weighting"]]
            ax.scatter(r["ms"], r[key], c=colour, marker=marker, s=36 if i in front else 14,
                       edgecolors="k" if i in front else "none", zorder=3)
        fr = sorted((pts[i] for i in front), key=lambda p: p[0])
        ax.plot([p[0] for p in fr], [p[1] for p in fr], "k--", lw=0.8, zorder=2)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ms per frame")
        ax.set_title(name)
        ax.grid(True, which="both", lw=0.3)
    axes[0].set_ylabel("relative RMS error")
    fig.suptitle(f"error against time per frame ({device}); voronoi blue (full) / orange (compressed), "
                 f"antialiased green, barycentric red, gaussian purple, spline brown, kriging pink; square: subset, "
                 f"triangle: float32; "
                 f"ringed: Pareto front", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lights", type=int, default=128)
    ap.add_argument("--res", type=int, default=96, help="image size for the errors")
    ap.add_argument("--oracle-dirs", type=int, default=2048)
    ap.add_argument("--time-res", type=int, default=512, help="image size for the times")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="a small grid (tests)")
    ap.add_argument("--no-near", action="store_true")
    ap.add_argument("--library-only", action="store_true",
                    help="only the library-only schemes' error rows (printed, and written to "
                         "benchmarks/results/tradeoff_library.json); no grid, no times, docs untouched")
    ap.add_argument("--map-height", type=int, default=128, help="the maps are resampled to this height first")
    ap.add_argument("--cache", default=None, help="folder keeping the capture and the truths between runs")
    ap.add_argument("--out", default=str(ROOT / "docs" / "tradeoff.md"))
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "tradeoff.json"))
    a = ap.parse_args()
    t_start = time.perf_counter()
    scene = synth.SynthScene()
    n = a.lights
    dirs = synth.stratified_directions(n, "upper", seed=1)
    print(f"capture: {n} distant lights, {a.res}^2")
    cache = Path(a.cache) / f"tradeoff_{n}_{a.res}_{a.oracle_dirs}.npz" if a.cache else None
    cached = dict(np.load(cache)) if cache is not None and cache.exists() else {}
    basis = cached["basis"] if "basis" in cached else synth.render_lights(scene, a.res, dirs)
    with warnings.catch_warnings():  # the maps' few tiny negative texels (lossy EXR) are clamped, as reported
        warnings.simplefilter("ignore")
        maps = {name: load_lightmap(map_path(f)).to_latlong(a.map_height) for name, f in MAPS}
    truths = {}
    for name, lm in maps.items():
        for yaw in YAWS:
            key = f"truth {name} {yaw:g}"
            if key in cached:
                truths[(name, yaw)] = cached[key]
                continue
            t0 = time.perf_counter()
            truths[(name, yaw)] = synth.render_lightmap(scene, lm, a.res, n_dirs=a.oracle_dirs, rotation=rotation_z(yaw))
            print(f"  truth {name} yaw {yaw:g}: {time.perf_counter() - t0:.0f} s")
    if cache is not None and not cached:
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.savez(cache, basis=basis, **{f"truth {k[0]} {k[1]:g}": v for k, v in truths.items()})
    if a.library_only:
        library = library_rows(basis, dirs, maps, truths)
        write_json(str(Path(a.json).with_name("tradeoff_library.json")),
                   {"host": host_info(), "lights": n, "res": a.res, "oracle_dirs": a.oracle_dirs, "maps": dict(MAPS),
                    "yaws": YAWS, "library": library, "seconds": time.perf_counter() - t_start})
        return
    configs = configurations(n, a.quick)
    max_rank = max((q.rank for q in configs if q.rank is not None), default=None)
    cb_full = compress_basis(basis, max_rank) if max_rank else None
    cb_sub = {}
    rows = []
    for q in configs:
        errs, psnrs = {}, {}
        for (name, yaw), truth in truths.items():
            cb = None
            if q.rank is not None:
                if q.basis_subset is None:
                    cb = truncate(cb_full, q.rank)
                else:
                    if q.basis_subset not in cb_sub:
                        idx = farthest_point_subset(dirs, q.basis_subset)
                        cb_sub[q.basis_subset] = compress_basis(basis[idx], min(max_rank, q.basis_subset - 1))
                    cb = truncate(cb_sub[q.basis_subset], q.rank)
            img = relight_quality(basis, dirs, maps[name], rotation_z(yaw), q, compressed=cb)
            errs.setdefault(name, []).append(rel_rmse(img, truth))
            psnrs.setdefault(name, []).append(psnr_tonemapped(img, truth))
        row = {"quality": q.as_dict(), "label": q.label()}
        for name in maps:
            row[f"rel_rmse[{name}]"] = float(np.mean(errs[name]))
            row[f"psnr[{name}]"] = float(np.mean(psnrs[name]))
        row["mean_rel_rmse"] = float(np.mean([row[f"rel_rmse[{m}]"] for m in maps]))
        row["mean_psnr"] = float(np.mean([row[f"psnr[{m}]"] for m in maps]))
        rows.append(row)
        print(f"  {q.label():<40} mean rel RMSE {row['mean_rel_rmse']:.4f}  PSNR {row['mean_psnr']:.1f} dB")
    library = library_rows(basis, dirs, maps, truths)
    ms, dev = time_configs(configs, n, a.time_res, a.reps, maps["overcast"])
    for r, t in zip(rows, ms or [None] * len(rows)):
        r["ms"] = t
    # the automatic choice's estimate (leave-one-out, no truth) against the truth, per map
    est_rows = []
    probe = [Quality(precision="f32"), Quality(rank=7), Quality(rank=min(31, n - 2)), Quality(basis_subset=n // 4),
             Quality(weighting="barycentric"), Quality(weighting="gaussian")]
    for name, lm in maps.items():
        est, info = estimate_errors(basis, dirs, lm, rotation_z(YAWS[0]), probe)
        for q, e in zip(probe, est):
            true = rel_rmse(relight_quality(basis, dirs, lm, rotation_z(YAWS[0]), q), truths[(name, YAWS[0])])
            est_rows.append({"map": name, "label": q.label(), "estimate": e, "true": true})
    near = [] if a.no_near else near_experiment(scene, a.res, min(n, 96), a.oracle_dirs, maps["overcast"], a.quick)
    fl = flicker_rows(basis, dirs, maps["sharp sun"], frames=12 if a.quick else 40)
    device = device_line(dev) if dev else "no GL"
    doc = {"host": host_info(), "device": dev, "lights": n, "res": a.res, "time_res": a.time_res,
           "oracle_dirs": a.oracle_dirs, "maps": dict(MAPS), "yaws": YAWS, "rows": rows, "estimate": est_rows,
           "near": near, "flicker": fl, "library": library, "seconds": time.perf_counter() - t_start}
    write_json(a.json, doc)
    img = ROOT / "docs" / "images" / "tradeoff_pareto.png"
    if ms is not None:
        plot(rows, list(maps), img, device)
    write_markdown(a, doc, list(maps), device, img if ms is not None else None)
    print(f"wrote {a.out}, {a.json} in {doc['seconds']:.0f} s")


def write_markdown(a, doc, names, device, img):
    rows = doc["rows"]
    front = set(pareto([(r["ms"], r["mean_rel_rmse"]) for r in rows]))
    cmd = "python benchmarks/tradeoff.py " + " ".join(sys.argv[1:])
    L = ["<!-- written by benchmarks/tradeoff.py; the prose around the generated part is in the script -->",
         "## Measured trade (generated)", "",
         f"`{cmd.strip()}` ({device}; {doc['host'].get('cpu_count', os.cpu_count())} CPUs; "
         f"{doc['lights']} lights, errors at {doc['res']}^2 against `render_lightmap` with {doc['oracle_dirs']} "
         f"directions, means over yaw {', '.join(f'{y:g}' for y in doc['yaws'])} degrees; times at "
         f"{doc['time_res']}^2, median of {a.reps} rounds; maps resampled to {a.map_height} texels high (`map-full`); "
         "JSON `benchmarks/results/tradeoff.json`). "
         "Error: relative RMSE (lower is better) and PSNR (dB) of the sRGB tone-mapped 8-bit images. "
         "**Bold**: on the Pareto front of mean error against time.", "",
         "| configuration | ms/frame | " + " | ".join(f"{m} rRMSE / PSNR" for m in names) + " | mean rRMSE |",
         "|---|---:|" + "---:|" * len(names) + "---:|"]
    for i, r in enumerate(sorted(range(len(rows)), key=lambda i: (rows[i]["ms"] or 0))):
        row = rows[r]
        lab = f"**{row['label']}**" if r in front else row["label"]
        t = "-" if row["ms"] is None else f"{row['ms']:.1f}"
        cells = " | ".join(f"{row[f'rel_rmse[{m}]']:.4f} / {row[f'psnr[{m}]']:.1f}" for m in names)
        L.append(f"| {lab} | {t} | {cells} | {row['mean_rel_rmse']:.4f} |")
    if img is not None:
        L += ["", f"![error against ms per frame](images/{img.name})"]
    if EXTRA_SCHEMES:  # library-only schemes (none while every scheme is offered by --weighting)
        L += ["", "### Library-only schemes (exact float64 weights, float32 basis; errors only, not timed)", "",
              "| weighting | " + " | ".join(f"{m} rRMSE" for m in names) + " | mean rRMSE | / barycentric |",
              "|---|" + "---:|" * len(names) + "---:|---:|"]
        for r in doc.get("library", []):
            cells = " | ".join(f"{r[f'rel_rmse[{m}]']:.4f}" for m in names)
            L.append(f"| {r['weighting']} | {cells} | {r['mean_rel_rmse']:.4f} | {r['over_barycentric']:.3f} |")
    L += ["", "### Leave-one-out estimate against the truth (what `--quality auto` sees without truth)", "",
          "| map | configuration | estimate | true |", "|---|---|---:|---:|"]
    for r in doc["estimate"]:
        L.append(f"| {r['map']} | {r['label']} | {r['estimate']:.4f} | {r['true']:.4f} |")
    if doc["near"]:
        L += ["", "### Near lights (point lamp of constant intensity, overcast map)", "",
              "| capture | correction | rel RMSE (image) | rel RMSE (object) | PSNR dB |", "|---|---|---:|---:|---:|"]
        for r in doc["near"]:
            L.append(f"| {r['capture']} | {'on' if r['correction'] else 'off'} | {r['rel_rmse']:.4f} | "
                     f"{r['rel_rmse_object']:.4f} | {r['psnr']:.1f} |")
    if doc["flicker"]:
        L += ["", "### Flicker (the sharp-sun map turning in 1-degree steps, `benchmarks/flicker.py`'s metric)", "",
              "| weighting | flicker | / voronoi |", "|---|---:|---:|"]
        for r in doc["flicker"]:
            L.append(f"| {r['weighting']} | {r['flicker']:.4g} | {r['ratio_to_voronoi']:.3f} |")
    L.append("")
    out = Path(a.out)
    head = out.read_text().split("<!-- written by benchmarks/tradeoff.py")[0] if out.exists() else ""
    out.write_text(head + "\n".join(L))


if __name__ == "__main__":
    main()
