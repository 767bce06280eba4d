"""Light maps from a diffuse sphere, cast shadows and POCS: errors and times over methods and parameters.

    OMP_NUM_THREADS=1 python benchmarks/probes.py [--quick] [--noise 0.01]

For each real HDR map (the bundled Poly Haven maps, area-averaged to 64 rows) it renders

* a Lambertian ball seen by an orthographic camera (``ffls.synth.probe_scenes.diffuse_sphere_scene``,
  80 px; the map integrated against the clamped cosine at every pixel) looking the way the relit
  capture's camera looks (30 degrees down), as a probe photographed from the object camera's place, and
* a 0.2 m cube's shadow on the plane ``z = 0`` seen from straight above (``cast_shadow_scene``, 128 px
  over 2.5 m x 2.5 m: a light 10 degrees high casts its whole shadow in view; the map reduced to 1024
  distant lights with the synthetic renderer's shadow rays),

then recovers the lighting with every method and parameter and reports, per row: the time (CPU
seconds of this process, the median of 3 runs; ``OMP_NUM_THREADS=1`` makes it single-threaded, and
CPU time is not inflated by other load on the machine), the papers' re-render error (relative RMS of the input re-rendered from the
recovered lighting), the relit error of a diffuse object (relative RMS of its irradiance under
the recovered vs the true map, ``ffls.probes.evaluate.relit_error``) over the probe's own
normals and over every normal of a sphere (the upper hemisphere for shadows, which see no light
from below), the relit error of an ``ffls synth`` capture (150 distant lights over the upper
hemisphere, 64 px; relative RMS over its lit pixels, the measure of ``benchmarks/probe_mirror.py``)
relit by the CPU relighter under the recovered (negative texels clipped) vs the true map, and
the map error. Rows ``floor`` hold the true map as each method's unknowns can hold it (the
power of every source cell, POCS grid texel or dome node exact): the error of the discretisation
alone; ``HA adaptive`` and ``Sato adaptive`` floors are the adaptive sets refined by the true
map's cell powers (``oracle_adaptive``), and ``... set N`` floors the sets the adaptive estimates
chose. Hougen-Ahuja and Sato-Sato-Ikeuchi are also run with their sizes chosen from the data:
``uniform`` over uniform sets, ``adaptive`` over the adaptive sets of
``ffls.probes.selection.refine_sources`` (POCS too: ``adaptive`` rows, ``adaptive_singh_ahuja``, with the floor of
the set each chose). Then the limit: per spherical-harmonic order, the relative error
of the recovered map's coefficients. Writes ``benchmarks/results/probes.json`` and
``docs/images/probes.png``.
"""
from __future__ import annotations

import argparse
import inspect
import sys
import time
from pathlib import Path

import numpy as np

from common import host_info, probe_benchmark_capture, probe_benchmark_map, write_json
from common import relit_capture_error as relit_error_of
from ffls.probes.sources import cell_energies, latlong_solid_angles, model_sources, sources_to_latlong
from ffls.probes.estimate import pixel_grid_subset, shadow_lightmap
from ffls.probes.evaluate import clamped_cosine_coefficients, clamped_cosine_energy, map_error, relit_error, sh_recovery
from ffls.probes.hougen_ahuja import hougen_ahuja
from ffls.probes.sato_sato_ikeuchi import box_visibility, dome_nodes, sato_sato_ikeuchi
from ffls.probes.selection import (adaptive_hougen_ahuja, adaptive_sato_sato_ikeuchi, refine_sources,
                                   select_hougen_ahuja, select_sato_sato_ikeuchi)
from ffls.probes.singh_ahuja import adaptive_singh_ahuja, singh_ahuja, singh_ahuja_sources
from ffls.synth.probe_scenes import cast_shadow_scene, diffuse_sphere_scene

ROOT = Path(__file__).resolve().parent.parent
MAPS = ("courtyard", "studio", "sunrise", "night")
H = 64
#: The issue's cast-shadow set-up: a cube on a plane seen from straight above, with a margin: the view
#: reaches 1.25 m from the cube's centre, so the whole shadow of a light 10 degrees above the horizon
#: (0.1 + 0.2 / tan 10deg = 1.23 m) is seen along the axes; 128 px, 2 cm a pixel, 10 px across the cube.
CUBE = 0.2
SHADOW_GEOMETRY = {"extent": 1.25, "box_center": (0.0, 0.0, CUBE / 2), "box_size": (CUBE, CUBE, CUBE)}
SHADOW_RES = 128
#: ``ffls probe shadow``'s pixel budget (the CLI passes none: ``shadow_lightmap``'s default).
SHADOW_CLI_PIXELS = inspect.signature(shadow_lightmap).parameters["max_pixels"].default


def timed(fn, repeat=3):
    ts, out = [], None
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        ts.append(time.process_time() - t)
        if ts[-1] > 3.0:
            break
    return out, float(np.median(ts))


def oracle_adaptive(true, hemisphere, max_sources):
    """The adaptive set refined by the true map's cell powers (``refine_sources`` with every cell exact)."""

    class Exact:
        def __init__(self, d):
            self.directions = d
            self.intensities = cell_energies(d, true, hemisphere)

    sel = refine_sources(Exact, lambda d, f: -float(d.shape[0]), hemisphere=hemisphere, max_sources=max_sources,
                         criterion="bic")
    return sel.fit.directions


#: Cap on the extrapolated POCS iterations of the benchmark's rows (each two J x J products).
EXTRAPOLATED_SWEEPS = 3000
#: Sweep counts of the convergence curve.
CURVE_SWEEPS = (10, 50, 200, 1000, 3000)


def convergence_curve(normals, radiance, directions, relit_capture_error, cap_truth, height):
    """Error vs sweeps and CPU time on one source set: the paper's sweeps (relaxation 1 and 1.9), the
    extrapolated parallel projections, and scipy's NNLS on the same pixels as the reference."""
    from scipy.optimize import nnls

    from ffls.probes.linear import lambert_matrix
    from ffls.probes.singh_ahuja import pixel_subset

    out = {"sources": int(directions.shape[0]), "sweeps": list(CURVE_SWEEPS)}
    for label, kw in (("sequential", {}), ("sequential relaxation=1.9", {"relaxation": 1.9}),
                      ("extrapolated", {"scheme": "extrapolated"})):
        errs, times, res = [], [], []
        for it in CURVE_SWEEPS:
            if label != "extrapolated" and it > 1000:
                continue
            fit, t = timed(lambda: singh_ahuja_sources(normals, radiance, 0.7, directions, iterations=it,
                                                       max_pixels=1000, **kw), 1)
            errs.append(relit_capture_error(fit.latlong(height), cap_truth))
            times.append(t)
            res.append(float(fit.residuals[-1]))
            print(f"  curve {label:26s} {it:5d} sweeps  {t:6.2f} s  residual {100 * res[-1]:.3f}%  relit capture "
                  f"{100 * errs[-1]:.2f}%", flush=True)
        out[label] = {"relit_capture": errs, "cpu_s": times, "residual": res}
    use = pixel_subset(normals.shape[0], 1000, 0)
    A = lambert_matrix(normals[use], directions)
    g = np.pi * np.asarray(radiance)[use] / 0.7
    t = time.process_time()
    f = np.stack([nnls(A, g[:, c], maxiter=50 * A.shape[1])[0] for c in range(3)], axis=1)
    t = time.process_time() - t
    e = relit_capture_error(sources_to_latlong(directions, f, height), cap_truth)
    out["nnls"] = {"relit_capture": e, "cpu_s": t,
                   "residual": float(np.linalg.norm(g - A @ f) / np.linalg.norm(g))}
    print(f"  curve NNLS (scipy)                          {t:6.2f} s  residual {100 * out['nnls']['residual']:.3f}%  "
          f"relit capture {100 * e:.2f}%", flush=True)
    return out


def upper_only(a):
    a = a.copy()
    a[a.shape[0] // 2:] = 0.0
    return a


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two maps, fewer parameters")
    ap.add_argument("--noise", type=float, default=0.0, help="Gaussian noise, as a fraction of each image's mean")
    ap.add_argument("--maps", default=None, help="comma-separated subset of " + ",".join(MAPS))
    ap.add_argument("--pocs-only", action="store_true",
                    help="only the POCS rows and their convergence study (write to another --json / --plot)")
    ap.add_argument("--json", default=str(ROOT / "benchmarks/results/probes.json"))
    ap.add_argument("--plot", default=str(ROOT / "docs/images/probes.png"))
    a = ap.parse_args(argv)
    maps = MAPS[:2] if a.quick else MAPS
    if a.maps:
        maps = tuple(m for m in a.maps.split(",") if m)
        if not set(maps) <= set(MAPS):
            ap.error(f"--maps: choose from {','.join(MAPS)}")
    rng = np.random.default_rng(0)
    rows, limit, conv, curve = [], {}, {}, {}
    cap, lights = probe_benchmark_capture("ffls_probes_")

    def relit_capture_error(L, truth_img):
        return relit_error_of(cap, lights, L, truth_img)

    def noisy(x):
        if a.noise <= 0:
            return x
        return x + rng.normal(0.0, a.noise * float(np.mean(x)), size=x.shape)

    for name in maps:
        lm, true, cap_truth = probe_benchmark_map(name, H, cap, lights)
        # the probe is photographed from the relit object's camera position (it looks the same way)
        sph = diffuse_sphere_scene(lm, 80, albedo=0.7, world_from_camera=cap.world_from_camera)
        rad = noisy(sph.radiance)

        def add(method, params, fit_fn, fit, t, normals_own, full_true, hemi):
            L = fit_fn(fit)
            row = {"map": name, "method": method, "params": params, "time_s": t,
                   "rerender": float(fit.relative_rms),
                   "relit_own": relit_error(L, full_true, normals_own),
                   "relit_sphere": relit_error(L, full_true, hemisphere=hemi),
                   "map_error": map_error(L, full_true, hemisphere=hemi),
                   "relit_capture": relit_capture_error(L, cap_truth)}
            rows.append(row)
            print(f"{name:9s} {method:12s} {params:30s} {t:6.2f}s  rerender {row['rerender']:.4f}  relit own "
                  f"{row['relit_own']:.4f}  sphere {row['relit_sphere']:.4f}  capture {row['relit_capture']:.4f}  "
                  f"map {row['map_error']:.3f}", flush=True)
            return L

        # ------------------------------------------------------------ discretisation floors
        # the true map as each method's unknowns hold it (every unknown exact): the error no estimate
        # on that discretisation can go below
        def floor(label, L, hemi):
            row = {"map": name, "method": "floor", "params": label, "time_s": 0.0, "rerender": 0.0,
                   "relit_own": 0.0, "relit_sphere": relit_error(L, true, hemisphere=hemi),
                   "map_error": map_error(L, true, hemisphere=hemi), "relit_capture": relit_capture_error(L, cap_truth)}
            rows.append(row)
            print(f"{name:9s} floor        {label:30s}          capture {row['relit_capture']:.4f}  "
                  f"map {row['map_error']:.3f}", flush=True)

        for n in (162, 492):
            d = model_sources(n)
            floor(f"HA cells n={d.shape[0]}", sources_to_latlong(d, cell_energies(d, true), H), "full")
        g = true.reshape(16, H // 16, 32, H // 16, 3)
        sa = latlong_solid_angles(H).reshape(16, H // 16, 32, H // 16, 1)
        grid = (g * sa).sum(axis=(1, 3)) / sa.sum(axis=(1, 3))
        floor("POCS grid 16x32", np.repeat(np.repeat(grid, H // 16, axis=0), H // 16, axis=1), "full")
        d = oracle_adaptive(true, "full", 500)
        floor(f"HA adaptive n={d.shape[0]}", sources_to_latlong(d, cell_energies(d, true), H), "full")
        d = dome_nodes(526)
        floor(f"Sato dome {d.shape[0]}", sources_to_latlong(d, cell_energies(d, true, "upper"), H, "upper"), "upper")
        d = oracle_adaptive(true, "upper", 526)
        floor(f"Sato adaptive {d.shape[0]}", sources_to_latlong(d, cell_energies(d, true, "upper"), H, "upper"),
              "upper")
        if not a.pocs_only:
            # ------------------------------------------------------------ Hougen-Ahuja
            ha = [(5, False, {}), (9, False, {}), (17, False, {}), (5, True, {}), (9, True, {}), (17, True, {}),
                  (162, False, {"rcond": 1e-3}), (42, True, {"ambient": "nonnegative"}),
                  (162, True, {"ambient": "nonnegative"}), (492, True, {"ambient": "nonnegative"}),
                  (492, True, {"ambient": "nonnegative", "smoothness": 0.003})]
            if a.quick:
                ha = [h for h in ha if h[0] != 492]
            for n, nn, kw in ha:
                fit, t = timed(lambda: hougen_ahuja(sph.normals, rad, 0.7, n, nonnegative=nn, **kw))
                L = add("hougen_ahuja", f"n={n} {'nnls' if nn else 'lstsq'} {' '.join(f'{k}={v}' for k, v in kw.items())}",
                        lambda f: f.latlong(H), fit, t, sph.normals, true, "full")
                if n == 162 and nn:
                    limit[f"{name} HA-162 nnls"] = sh_recovery(L, true, 8).relative_error.tolist()
                if n == 17 and not nn:
                    limit[f"{name} HA-17 lstsq"] = sh_recovery(L, true, 8).relative_error.tolist()
            sel, t = timed(lambda: select_hougen_ahuja(sph.normals, rad, 0.7, nonnegative=True, ambient="nonnegative"), 1)
            add("hougen_ahuja", f"uniform (cv) -> {sel.chosen}", lambda f: f.latlong(H), sel.fit, t, sph.normals, true,
                "full")
            # ambient 'nonnegative' (the default before) and 'auto' (none with these full-sphere sets, the default now)
            for crit, amb in (("bic", "nonnegative"), ("cv", "nonnegative"), ("bic", "auto"), ("cv", "auto")):
                sel, t = timed(lambda: adaptive_hougen_ahuja(sph.normals, rad, 0.7, criterion=crit, nonnegative=True,
                                                             ambient=amb), 1)
                tag = crit if amb == "nonnegative" else f"{crit}, ambient auto"
                add("hougen_ahuja", f"adaptive ({tag}) -> {sel.chosen}", lambda f: f.latlong(H), sel.fit, t, sph.normals,
                    true, "full")
                d = sel.fit.directions
                floor(f"HA adaptive ({tag}) set {d.shape[0]}", sources_to_latlong(d, cell_energies(d, true), H), "full")
        # ------------------------------------------------------------ POCS
        pocs_rows = [(8, 10, "random"), (8, 50, "random"), (16, 10, "random"), (16, 50, "random"),
                     (16, 50, "sequential")]
        if a.quick:
            pocs_rows = pocs_rows[:3]
        for h, it, order in pocs_rows:
            r, t = timed(lambda: singh_ahuja(sph.normals, rad, 0.7, h, it, order=order, max_pixels=1000), 1)
            L = add("singh_ahuja", f"grid {h}x{2 * h} it={it} {order}", lambda f: f.latlong(H), r, t, sph.normals,
                    true, "full")
            if (h, it) == (16, 50):
                conv[f"{name} {order}"] = r.residuals.tolist()
                if order == "random":
                    limit[f"{name} POCS-16"] = sh_recovery(L, true, 8).relative_error.tolist()
        for crit in ("bic", "cv"):
            sel, t = timed(lambda: adaptive_singh_ahuja(sph.normals, rad, 0.7, criterion=crit, max_pixels=1000), 1)
            L = add("singh_ahuja", f"adaptive ({crit}) -> {sel.chosen} it=50 random", lambda f: f.latlong(H), sel.fit,
                    t, sph.normals, true, "full")
            conv[f"{name} adaptive {crit}"] = sel.fit.residuals.tolist()
            if crit == "cv":
                limit[f"{name} POCS adaptive"] = sh_recovery(L, true, 8).relative_error.tolist()
            d = sel.fit.directions
            floor(f"POCS adaptive ({crit}) set {d.shape[0]}", sources_to_latlong(d, cell_energies(d, true), H), "full")
        # extrapolated parallel projections (Combettes), a fixed count and the stopping rule
        for crit, it, tol in (("bic", EXTRAPOLATED_SWEEPS, None), ("cv", EXTRAPOLATED_SWEEPS, None),
                              ("bic", 20000, 1e-6)):
            sel, t = timed(lambda: adaptive_singh_ahuja(sph.normals, rad, 0.7, criterion=crit, max_pixels=1000,
                                                        scheme="extrapolated", iterations=it, tol=tol), 1)
            add("singh_ahuja", f"adaptive ({crit}) -> {sel.chosen} extrapolated it={sel.fit.iterations}"
                f"{f' tol={tol:g}' if tol else ''}", lambda f: f.latlong(H), sel.fit, t, sph.normals, true, "full")
            conv[f"{name} adaptive {crit} extrapolated{' tol' if tol else ''}"] = sel.fit.residuals.tolist()
        # Dykstra's best approximation: the least-norm powers within the residual the data allow
        sel, t = timed(lambda: adaptive_singh_ahuja(sph.normals, rad, 0.7, criterion="bic", max_pixels=1000,
                                                    scheme="dykstra", iterations=3000, tol=1e-6), 1)
        add("singh_ahuja", f"adaptive (bic) -> {sel.chosen} dykstra it={sel.fit.iterations}", lambda f: f.latlong(H),
            sel.fit, t, sph.normals, true, "full")
        conv[f"{name} adaptive bic dykstra"] = sel.fit.residuals.tolist()
        # the convergence curve on one fixed set (the paper's scheme's BIC set): error vs sweeps and CPU time
        sel = adaptive_singh_ahuja(sph.normals, rad, 0.7, criterion="bic", max_pixels=1000)
        curve[name] = convergence_curve(sph.normals, rad, sel.fit.directions, relit_capture_error, cap_truth, H)
        if not a.pocs_only:
            # ------------------------------------------------------------ Sato, Sato and Ikeuchi
            sc = cast_shadow_scene(lm, SHADOW_RES, albedo="checker", **SHADOW_GEOMETRY)
            occ = {"box": {"center": sc.box_center.tolist(), "size": sc.box_size.tolist()}}
            tu = upper_only(true)
            up = np.array([[0.0, 0.0, 1.0]])
            srad = noisy(sc.radiance)
            nodes = (46, 126, 246, 526) if not a.quick else (46, 126)
            for n in nodes:
                d = dome_nodes(n)
                V, tv = timed(lambda: box_visibility(sc.points, d, sc.box_center, sc.box_size), 1)
                fit, t = timed(lambda: sato_sato_ikeuchi(sc.points, srad, occ, nodes=d, albedo=sc.albedo, visibility=V), 1)
                add("sato", f"nodes={d.shape[0]} lambertian", lambda f: f.latlong(H), fit, t + tv, up, tu, "upper")
            d = dome_nodes(246 if not a.quick else 126)
            V = box_visibility(sc.points, d, sc.box_center, sc.box_size)
            fit, t = timed(lambda: sato_sato_ikeuchi(sc.points, srad, occ, nodes=d, case="ratio", visibility=V,
                                                     surface_radiance=noisy(sc.surface_radiance),
                                                     reference_albedo=float(np.mean(sc.albedo)))
                           , 1)
            add("sato", f"nodes={d.shape[0]} ratio", lambda f: f.latlong(H), fit, t, up, tu, "upper")
            spec = {"ks": 0.05, "sigma": 0.2}
            scs = cast_shadow_scene(lm, SHADOW_RES, albedo=0.6, specular=spec, **SHADOW_GEOMETRY)
            fit, t = timed(lambda: sato_sato_ikeuchi(scs.points, noisy(scs.radiance), occ, nodes=d, case="torrance_sparrow",
                                                     albedo=0.6, view_dirs=scs.view_dirs, specular=spec, visibility=V), 1)
            add("sato", f"nodes={d.shape[0]} torrance_sparrow", lambda f: f.latlong(H), fit, t, up, tu, "upper")
            for crit in ("cv", "bic"):
                sel, t = timed(lambda: select_sato_sato_ikeuchi(sc.points, srad, occ, candidates=nodes, criterion=crit,
                                                                albedo=sc.albedo), 1)
                add("sato", f"uniform ({crit}) -> {sel.fit.directions.shape[0]}", lambda f: f.latlong(H), sel.fit, t, up,
                    tu, "upper")
            sel, t = timed(lambda: adaptive_sato_sato_ikeuchi(sc.points, srad, occ, criterion="bic", albedo=sc.albedo), 1)
            add("sato", f"adaptive (bic) -> {sel.chosen}", lambda f: f.latlong(H), sel.fit, t, up, tu, "upper")
            d = sel.fit.directions
            floor(f"Sato adaptive (bic) set {d.shape[0]}", sources_to_latlong(d, cell_energies(d, true, "upper"), H,
                                                                              "upper"), "upper")
            # what `ffls probe shadow` runs by default: adaptive, CV, the pixels thinned to the CLI's budget
            # by the same regular grid (ffls.probes.estimate.pixel_grid_subset); BIC on them beside it
            rows_px, cols_px = np.nonzero(sc.mask)  # row-major, as sc.points
            keep, stride = pixel_grid_subset(np.stack([cols_px, rows_px], axis=1), SHADOW_CLI_PIXELS)
            for crit in ("cv", "bic") if not a.quick else ("cv",):
                sel, t = timed(lambda: adaptive_sato_sato_ikeuchi(sc.points[keep], srad[keep], occ, criterion=crit,
                                                                  albedo=sc.albedo[keep]), 1)
                add("sato", f"adaptive ({crit}, {keep.size} px{', default' if crit == 'cv' else ''}) -> {sel.chosen}",
                    lambda f: f.latlong(H), sel.fit, t, up, tu, "upper")
            if not a.quick:
                sel, t = timed(lambda: adaptive_sato_sato_ikeuchi(sc.points, srad, occ, criterion="cv", albedo=sc.albedo),
                               1)
                add("sato", f"adaptive (cv) -> {sel.chosen}", lambda f: f.latlong(H), sel.fit, t, up, tu, "upper")

    kernel = {"energy_up_to_order": {str(l): clamped_cosine_energy(l) for l in range(7)},
              "coefficients_2pi_c_l": (2 * np.pi * clamped_cosine_coefficients(8)).tolist()}
    print("\nclamped-cosine energy up to order L:", {k: round(v, 5) for k, v in kernel["energy_up_to_order"].items()})
    print("per-order relative error of the recovered map's SH coefficients (orders 0..8):")
    for k, v in limit.items():
        print(f"  {k:24s} " + " ".join(f"{x:5.2f}" for x in v))
    doc = {"host": host_info(), "noise": a.noise, "map_height": H, "rows": rows, "sh_limit": limit,
           "kernel": kernel, "pocs_convergence": conv,
           "pocs_convergence_curve": curve, "command": " ".join(["python", "benchmarks/probes.py", *sys.argv[1:]])}
    write_json(a.json, doc)
    plot(rows, conv, a.plot)
    print(f"wrote {a.plot}")


def plot(rows, conv, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ffls.errors import atomic_output

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6))
    colours = {"hougen_ahuja": "tab:blue", "singh_ahuja": "tab:green", "sato": "tab:red"}
    for m, c in colours.items():
        r = [x for x in rows if x["method"] == m]
        ax[0].scatter([x["time_s"] for x in r], [100 * x["relit_own"] for x in r], c=c, s=14, label=m)
        ax[1].scatter([x["time_s"] for x in r], [100 * x["relit_capture"] for x in r], c=c, s=14, label=m)
    for a_, t in zip(ax[:2], ("relit error on the probe's own normals (%)",
                              "relit error, ffls synth capture (%)")):
        a_.set_xscale("log")
        a_.set_yscale("log")
        a_.set_xlabel("time (s)")
        a_.set_title(t, fontsize=9)
        a_.grid(True, which="both", alpha=0.3)
        a_.legend(fontsize=8)
    for k, v in conv.items():
        ax[2].semilogy(v, label=k, ls=":" if "adaptive" in k else "-" if "random" in k else "--")
    ax[2].set_xlabel("POCS iteration (16 x 32 grid; dotted: the adaptive set chosen)")
    ax[2].set_title("relative residual |g - Hf| / |g|", fontsize=9)
    if conv:
        ax[2].legend(fontsize=7)
    ax[2].grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    with atomic_output(Path(path)) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)


if __name__ == "__main__":
    main()
