"""Accuracy of sphere detection (ffls.spheres.detect) on ffls.synth.scene captures: centre errors.

Usage: python benchmarks/sphere_detect_accuracy.py [--res 768] [--n 40] [--out result.json]
       python benchmarks/sphere_detect_accuracy.py --capture FOLDER [FOLDER ...]

With ``--capture``, each given ``ffls synth`` capture (any flags; an unstated encoding is read as
linear, as the encoding calibration's first search does) is searched without hints, and every
true sphere's centre error (pixels, projected centre) is printed with the fit's radius and the
edges its outline came from, followed by the round outlines set aside.

Prints one row per (encoding, ground albedo, light model, hints) case (hints: the true world
centres moved by 1 cm; otherwise automatic detection): the worst and mean centre errors
in pixels (projected centre) and in world units (metres, and as a fraction of the camera
distance), the RMS silhouette residual and the time to detect. Writes JSON with --out.
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

import numpy as np

from ffls.io.capture import load_capture
from ffls.spheres.detect import find_spheres_in_capture
from ffls.synth.scene import write_synthetic_capture

from common import write_json  # benchmarks/common.py


def run_case(folder, n, res, encoding, ground, light_model, hints):
    write_synthetic_capture(folder, n_lights=n, resolution=res, encoding=encoding, ground_albedo=ground,
                            light_model=light_model, noise=(1 / 255 if encoding == "srgb8" else 0.002),
                            progress=False)
    cap = load_capture(folder)
    with open(os.path.join(folder, "truth.json")) as f:
        truth = json.load(f)
    # hints: world centres off by 1 cm, as a user might measure them; else automatic detection
    cap.spheres = [{"center": (np.array(c) + [0.01, 0.0, 0.0]).tolist()} for c in truth["sphere_centers"]] if hints else []
    t = time.perf_counter()
    fits = find_spheres_in_capture(cap)
    dt = time.perf_counter() - t
    cw = np.array(truth["sphere_centers"])
    cpx = np.array(truth["sphere_centers_px"])
    cam = np.linalg.norm(cap.world_from_camera[:3, 3] - cw, axis=1)
    rows = []
    for ft in fits:
        k = int(np.argmin(np.linalg.norm(cw - ft.center_world, axis=1)))
        rows.append((np.linalg.norm(ft.center_px - cpx[k]), np.linalg.norm(ft.center_world - cw[k]),
                     np.linalg.norm(ft.center_world - cw[k]) / cam[k], ft.residual_px))
    r = np.array(rows)
    return {"encoding": encoding, "ground_albedo": ground, "light_model": light_model, "hints": hints,
            "n_images": n, "resolution": res, "found": len(fits),
            "px_max": float(r[:, 0].max()), "px_mean": float(r[:, 0].mean()),
            "world_max_m": float(r[:, 1].max()), "rel_depth_max": float(r[:, 2].max()),
            "residual_px_max": float(r[:, 3].max()), "detect_s": dt}


def report_capture(folder) -> dict:
    """Unhinted detection on one synthetic capture: per true sphere, the nearest fit's centre error (px)."""
    from dataclasses import replace

    cap = load_capture(folder)
    if cap.encoding == "auto":
        cap = replace(cap, encoding="linear")
    with open(os.path.join(folder, "truth.json")) as f:
        truth = json.load(f)
    t = time.perf_counter()
    fits = find_spheres_in_capture(cap)
    dt = time.perf_counter() - t
    rows = []
    for s in truth["spheres"]:
        d = [float(np.hypot(*(np.asarray(ft.center_px) - s["center_px"]))) for ft in fits]
        k = int(np.argmin(d)) if d else -1
        rows.append({"material": s["material"], "true_px": s["center_px"], "radius_px_from_area": s["radius_px_from_area"],
                     "error_px": d[k] if d and d[k] < s["radius_px_from_area"] else None,
                     "radius_px": fits[k].radius_px if k >= 0 else None,
                     "outline_edges": fits[k].outline_edges if k >= 0 else None, "source": fits[k].source if k >= 0 else None})
    print(f"{folder}: {len(fits)} found for {len(truth['spheres'])} true spheres, {dt:.1f} s")
    for r in rows:
        err = "not found" if r["error_px"] is None else (f"{r['error_px']:.2f} px off, radius {r['radius_px']:.2f} "
                                                         f"(area radius {r['radius_px_from_area']:.2f}), {r['source']}, "
                                                         f"edges of the {r['outline_edges']}")
        print(f"  {r['material']:12s} at ({r['true_px'][0]:.1f}, {r['true_px'][1]:.1f}): {err}")
    for r in fits.rejected:
        print(f"  set aside: {r}")
    return {"capture": str(folder), "found": len(fits), "spheres": rows, "rejected": fits.rejected, "detect_s": dt}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=768)
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--capture", nargs="+", default=None, help="report on these ffls synth captures instead")
    ap.add_argument("--out")
    a = ap.parse_args()
    if a.capture:
        out = [report_capture(c) for c in a.capture]
        if a.out:
            write_json(a.out, {"cpu_count": os.cpu_count(), "captures": out})
        return
    out = []
    print(f"{'encoding':8} {'ground':6} {'light':8} {'hints':5} {'found':5} {'px max':>7} {'px mean':>7} "
          f"{'world max (mm)':>14} {'rel max':>8} {'rms px':>7} {'time s':>6}")
    for enc, ground, lm, hints in [("linear", 0.3, "distant", False), ("srgb8", 0.3, "distant", False),
                                   ("srgb8", 0.0, "near", False), ("linear", 0.3, "near", True)]:
        with tempfile.TemporaryDirectory() as d:
            r = run_case(d, a.n, a.res, enc, ground, lm, hints)
        out.append(r)
        print(f"{enc:8} {ground:<6} {lm:8} {str(hints):5} {r['found']:5} {r['px_max']:7.3f} {r['px_mean']:7.3f} "
              f"{1000 * r['world_max_m']:14.2f} {r['rel_depth_max']:8.4f} {r['residual_px_max']:7.3f} {r['detect_s']:6.2f}")
    if a.out:
        write_json(a.out, {"cpu_count": os.cpu_count(), "cases": out})


if __name__ == "__main__":
    main()
