"""Accuracy and speed of light estimation on the paper's Table 1 grid (Masselus et al. 2002).

Lights at phi = 0..180 deg (20 deg steps, 0 = toward the camera) and theta = 0..70 deg (10 deg
steps from the zenith): 80 lights, rendered by :mod:`ffls.synth.scene` at 768 x 768 (spheres ~45 px).
Configurations: grey ground (albedo 0.3) distant and near (10 cm light at 2 m), black ground,
noise, 8-bit sRGB, one sphere. Besides the errors, the ``coverage`` of the reported 95% cones: the
fraction of accepted photos whose error is at most their ``uncertainty_deg`` (target 90-98%). ``--spheres detect`` (default) finds the spheres automatically
(:func:`ffls.spheres.detect.find_spheres_in_capture`, no hints: the real pipeline); ``--spheres
truth`` gives them from the renderer's truth (the estimator alone). ``--no-refine`` switches off
the photometric centre refinement. Both passes of :func:`ffls.spheres.estimate.estimate_photos` (free bounce, then the
capture-wide ground ratio imposed; ``--bounce free``: one pass) run in one process; the time per
image covers both passes and the sphere pixel extraction, not the image decoding (wall time, and
this process's CPU time, which other jobs' load inflates much less). Prints a table and writes
``benchmarks/results/bench_lights.json``.

    python benchmarks/bench_lights.py [--res 768] [--phi-step 20] [--theta-step 10] [--cache DIR]
        [--spheres detect|truth] [--no-refine] [--end-to-end WORKERS] [--first-pass N|all]

``--end-to-end WORKERS`` also times the whole command ``ffls lights CAPTURE --workers WORKERS``
in a new process (imports, decoding once, sphere detection, both passes, writing lights.json):
the throughput a user sees, in photos per second of wall time, and its CPU seconds (user + sys,
less sensitive to the machine's load; photos / (CPU s / 2), the throughput of 2 idle cores kept
busy), and the CPU of its main process alone (what the worker processes do not share). For a linear EXR configuration it is timed three times:
as rendered, and stored as 8-bit sRGB PNGs with the encoding stated in ``capture.json`` and
with none stated (then the encoding is calibrated from the spheres: :func:`eight_bit_copy`).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ffls.io.capture import load_capture
from ffls.conventions import angle_between, spherical_to_direction
from ffls.spheres.estimate import FIRST_PASS_PHOTOS, capture_samples, estimate_photos, sphere_views
from ffls.spheres.samples import sphere_values
from ffls.synth.scene import SynthScene, make_scene, write_synthetic_capture
from ffls.radiance.photos import load_photo

from common import MAIN_CPU, cached_capture, host_info, print_error_table, write_json  # benchmarks/common.py

CONFIGS = {
    "distant_grey": dict(light_model="distant", ground_albedo=0.3),
    "near_grey": dict(light_model="near", ground_albedo=0.3, light_distance=2.0, light_radius=0.05),
    "distant_black": dict(light_model="distant", ground_albedo=0.0),
    "near_black": dict(light_model="near", ground_albedo=0.0, light_distance=2.0, light_radius=0.05),
    "distant_grey_noise": dict(light_model="distant", ground_albedo=0.3, noise=0.01),
    "distant_grey_srgb8": dict(light_model="distant", ground_albedo=0.3, encoding="srgb8", noise=1 / 255),
    # one sphere (use --spheres truth: detection looks for four)
    "distant_grey_1sphere": dict(light_model="distant", scene=SynthScene(sphere_xy=((0.25, -0.25),), ground_albedo=0.3)),
    "near_grey_1sphere": dict(light_model="near", light_distance=2.0, light_radius=0.05,
                              scene=SynthScene(sphere_xy=((0.25, -0.25),), ground_albedo=0.3)),
    # white, grey, chrome and black glossy balls under a near light (as `ffls synth --near 2
    # --light-radius 0.05 --sphere-material mixed`): the joint near fit of matte pixels and mirror rays
    "near_mixed": dict(light_model="near", light_distance=2.0, light_radius=0.05,
                       scene=make_scene(sphere_material="mixed")),
}
TARGETS = {"distant_grey": (1.0, 0.5), "near_grey": (2.5, 1.0)}


def grid(phi_step, theta_step):
    phis = np.arange(0, 181, phi_step, dtype=float)
    thetas = np.arange(0, 71, theta_step, dtype=float)
    P, T = np.meshgrid(phis, thetas, indexing="ij")
    # phi = 0 toward the camera: the synthetic camera sits at -Y, so world azimuth = phi - 90 deg
    d = spherical_to_direction(np.radians(T.ravel()), np.radians(P.ravel() - 90.0))
    return phis, thetas, d


def run_config(name, cfg, res, dirs, folder, bounce="calibrated", spheres="detect", refine=True, first_pass=FIRST_PASS_PHOTOS):
    folder = Path(folder)
    truth = cached_capture(folder, dirs, lambda f: write_synthetic_capture(f, resolution=res, directions=dirs,
                                                                          progress=False, **cfg))
    cap = load_capture(folder)
    M = np.linalg.inv(cap.world_from_camera)
    if spheres == "detect":
        from ffls.spheres.detect import find_spheres_in_capture

        sph = find_spheres_in_capture(cap)
    else:
        sph = [SimpleNamespace(center_cam=M[:3, :3] @ np.asarray(c) + M[:3, 3], radius=truth["sphere_radius"])
               for c in truth["sphere_centers"]]
    shape = load_photo(cap, 0).shape[:2]
    samples = capture_samples(cap, sph, shape)
    imgs = [load_photo(cap, i) for i in range(len(dirs))]
    t, t_cpu = time.perf_counter(), time.process_time()
    vals = [sphere_values(im, samples) for im in imgs]
    if spheres == "detect":
        from ffls.io.capture import sphere_materials

        materials = sphere_materials(cap, len(sph))
    else:  # the renderer's materials: chrome and black glossy balls are mirrors
        materials = ["mirror" if t.get("material") in ("mirror", "glossy_black") else "matte"
                     for t in truth.get("spheres", [{}] * len(sph))]
    views = sphere_views(cap, sph) if any(m != "matte" for m in materials) else None
    result = estimate_photos(vals, samples, cap.scene_center, bounce=bounce, refine_centres=refine,
                             materials=materials, views=views, first_pass=first_pass)
    dt = (time.perf_counter() - t) / len(imgs)
    dt_cpu = (time.process_time() - t_cpu) / len(imgs)  # (this process's CPU: not inflated by other jobs' load)
    res_, refs = result.photos, result.refinements or []
    calib = None if result.calibration is None else [dataclasses.asdict(c) for c in result.calibration]
    est = np.array([r.direction for r in res_])
    err = np.degrees(angle_between(est, np.asarray(truth["directions"])))
    ok = np.array([r.status == "ok" for r in res_])
    e = err[ok]
    unc = np.array([r.uncertainty_deg for r in res_])[ok]  # 95% cone radius
    return {
        "config": name, **{k: v for k, v in cfg.items() if k != "scene"}, "n_spheres": len(samples), "resolution": res, "n": int(len(dirs)),
        "accepted": int(ok.sum()),
        "rejected": {r.reason: sum(1 for x in res_ if x.reason == r.reason) for r in res_ if r.reason},
        "median_deg": float(np.median(e)) if e.size else None, "p90_deg": float(np.percentile(e, 90)) if e.size else None,
        "max_deg": float(e.max()) if e.size else None,
        "median_uncertainty_deg": float(np.median(unc)) if e.size else None,
        "coverage": float(np.mean(e <= unc)) if e.size else None,
        "models": {m: sum(1 for r in res_ if r.model == m) for m in ("distant", "near")},
        "bounce": bounce, "spheres": spheres, "refine_centres": refine, "first_pass": first_pass,
        "centre_shift_px": [r.shift_norm_px for r in refs], "calibration": calib, "ms_per_image": 1e3 * dt, "images_per_second_per_core": 1.0 / dt,
        "cpu_ms_per_image": 1e3 * dt_cpu,
        "errors_deg": [float(x) if o else None for x, o in zip(err, ok)],
    }


def eight_bit_copy(src, dst, state_encoding: bool) -> Path:
    """``src`` (a rendered EXR capture) stored as 8-bit sRGB PNGs in ``dst``, as a camera writes them;
    ``capture.json`` states ``"encoding": "srgb"`` when ``state_encoding``, else none (then ``ffls
    lights`` calibrates it from the spheres). Kept when already there."""
    import json

    from ffls.io.images import read_image, write_png
    from ffls.radiance.encoding import srgb_encode

    src, dst = Path(src), Path(dst)
    if (dst / "capture.json").is_file():
        return dst
    dst.mkdir(parents=True, exist_ok=True)
    doc = json.loads((src / "capture.json").read_text())
    names = []
    for name in doc["images"]:
        rgb = read_image(src / name).pixels
        png = Path(name).with_suffix(".png").name
        write_png(dst / png, np.rint(np.clip(srgb_encode(rgb), 0.0, 1.0) * 255).astype(np.uint8))
        names.append(png)
    doc["images"] = names
    doc.pop("encoding", None)
    if state_encoding:
        doc["encoding"] = "srgb"
    (dst / "capture.json").write_text(json.dumps(doc, indent=1) + "\n")
    return dst


def end_to_end(folder, workers: int, n: int, label: str = "", truth_dirs=None, first_pass: str | None = None) -> dict:
    """Wall and CPU time (this process's children) of ``ffls lights FOLDER --workers WORKERS`` as a
    user runs it (a new Python process), and photos per second of wall time; keys prefixed with
    ``label``. With ``truth_dirs`` (n, 3) also the written lights' accuracy: accepted, median and
    max error, coverage of the 95% cone, and the encoding record (calibrated when unstated).
    ``first_pass`` (``N`` or ``'all'``) is passed as ``--first-pass`` (None: the command's default)."""
    import resource
    import subprocess
    import sys

    out = os.path.join(folder, "lights_end_to_end.json")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    # the command's main process reports its own CPU (with its threads) on its last line: the part
    # the worker processes do not share, which bounds the wall on idle cores from below
    done = subprocess.run([sys.executable, "-c", MAIN_CPU, "lights", str(folder), "-o", out, "--workers", str(workers),
                           "--no-progress"] + ([] if first_pass is None else ["--first-pass", str(first_pass)]),
                          check=True, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    user, sys_ = after.ru_utime - before.ru_utime, after.ru_stime - before.ru_stime
    main_cpu = float(done.stdout.strip().splitlines()[-1].split()[-1])
    p = f"end_to_end{label}"
    row = {f"{p}_s": wall, f"{p}_cpu_s": user + sys_, f"{p}_user_s": user, f"{p}_sys_s": sys_,
           f"{p}_main_cpu_s": main_cpu, f"{p}_photos_per_s": n / wall,
           f"{p}_photos_per_cpu_s_on_2_cores": n / ((user + sys_) / 2), f"{p}_workers": workers}
    if truth_dirs is not None:
        import json

        from ffls.io.capture import load_lights

        lights = load_lights(out)
        idx, est = lights.accepted()
        e = np.degrees(angle_between(est, np.asarray(truth_dirs)[idx]))
        unc = np.array([lights.extra[i].get("uncertainty_deg", np.nan) for i in idx], dtype=np.float64)
        row.update({f"{p}_accepted": int(len(idx)),
                    f"{p}_median_deg": float(np.median(e)) if e.size else None,
                    f"{p}_max_deg": float(e.max()) if e.size else None,
                    f"{p}_coverage": float(np.mean(e <= unc)) if e.size else None,
                    f"{p}_encoding": json.loads(Path(out).read_text()).get("encoding")})
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=768)
    ap.add_argument("--phi-step", type=int, default=20)
    ap.add_argument("--theta-step", type=int, default=10)
    ap.add_argument("--configs", default=",".join(CONFIGS))
    ap.add_argument("--bounce", choices=("calibrated", "free"), default="calibrated")
    ap.add_argument("--spheres", choices=("detect", "truth"), default="detect",
                    help="find the spheres automatically (the real pipeline) or take the true centres")
    ap.add_argument("--no-refine", action="store_true", help="no photometric refinement of the sphere centres")
    ap.add_argument("--cache", default=None, help="keep (and reuse) the renders in this folder")
    ap.add_argument("--end-to-end", type=int, default=0, metavar="WORKERS",
                    help="also time the whole command `ffls lights CAPTURE --workers WORKERS` (a new process: "
                         "imports, decoding, detection, both passes, writing) and report photos/s")
    ap.add_argument("--first-pass", default=None, metavar="N|all",
                    help="photos the first pass fits (estimate_photos first_pass, ffls lights --first-pass; "
                         "default: FIRST_PASS_PHOTOS)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_lights.json"))
    a = ap.parse_args(argv)
    first_pass = (FIRST_PASS_PHOTOS if a.first_pass is None else None if a.first_pass == "all"
                  else int(a.first_pass))
    phis, thetas, dirs = grid(a.phi_step, a.theta_step)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in a.configs.split(","):
            base = a.cache or tmp
            r = run_config(name, CONFIGS[name], a.res, dirs, os.path.join(base, f"{name}_{a.res}"), a.bounce,
                           a.spheres, not a.no_refine, first_pass)
            if a.end_to_end:
                folder = os.path.join(base, f"{name}_{a.res}")
                runs = [("", folder, "as rendered")]
                if CONFIGS[name].get("encoding", "linear") == "linear" and "photo" not in CONFIGS[name]:
                    runs += [("_srgb8_stated", eight_bit_copy(folder, folder + "_srgb8_stated", True),
                              "8-bit sRGB PNG, encoding stated"),
                             ("_srgb8_unstated", eight_bit_copy(folder, folder + "_srgb8_unstated", False),
                              "8-bit sRGB PNG, encoding unstated (calibrated)")]
                for label, f, what in runs:
                    r.update(end_to_end(f, a.end_to_end, r["n"], label, truth_dirs=dirs, first_pass=a.first_pass))
                    p = f"end_to_end{label}"
                    enc = r[p + "_encoding"]
                    enc = "as stated" if not enc else (f"gamma {enc['gamma']:.3f}" if enc.get("curve") == "gamma"
                                                       else enc.get("curve"))
                    print(f"{name} ({what}): ffls lights --workers {a.end_to_end}: {r[p + '_s']:.2f} s wall, "
                          f"{r[p + '_photos_per_s']:.1f} photos/s ({r[p + '_cpu_s']:.2f} s CPU: "
                          f"{r[p + '_user_s']:.2f} user + {r[p + '_sys_s']:.2f} sys, main process "
                          f"{r[p + '_main_cpu_s']:.2f}; {r[p + '_photos_per_cpu_s_on_2_cores']:.1f} photos / "
                          f"(CPU s / 2)); {r[p + '_accepted']} accepted, "
                          f"median {r[p + '_median_deg']:.2f} max {r[p + '_max_deg']:.2f} deg, coverage "
                          f"{100 * r[p + '_coverage']:.0f}%, encoding {enc}", flush=True)
            rows.append(r)
            tgt = TARGETS.get(name)
            print(f"{name:22s} spheres={a.spheres} refine={not a.no_refine} n={r['n']:3d} ok={r['accepted']:3d} median={r['median_deg']:.2f} "
                  f"p90={r['p90_deg']:.2f} max={r['max_deg']:.2f} deg  cone95~{r['median_uncertainty_deg']:.2f} "
                  f"coverage {100 * r['coverage']:.0f}%  "
                  f"{r['ms_per_image']:.0f} ms/img ({r['images_per_second_per_core']:.1f} img/s/core, "
                  f"{r['cpu_ms_per_image']:.0f} ms CPU/img)"
                  f" shift px {[round(x, 2) for x in r['centre_shift_px']]}"
                  + (f"  target max {tgt[0]} median {tgt[1]}" if tgt else ""), flush=True)
    doc = {"benchmark": "bench_lights", **host_info(),
           "phis_deg": phis.tolist(), "thetas_deg": thetas.tolist(), "results": rows}
    for r in rows:  # phi rows x theta columns, for docs/spheres.md
        print(f"\n{r['config']} ({r['bounce']} bounce): median {r['median_deg']:.2f}, max {r['max_deg']:.2f} deg, "
              f"{r['ms_per_image']:.0f} ms/img, accepted {r['accepted']}/{r['n']}")
        print_error_table(r["errors_deg"], phis, thetas)
    write_json(a.out, doc)


if __name__ == "__main__":
    main()
