"""Two suspects of a matte sphere's bias on a busy ground, against an ``ffls synth`` capture's truth.

A diagnosis, not a method of ffls. For one capture (with the ``truth.json`` that ``ffls synth``
writes; an 8-bit one must state its ``encoding``) it prints:

1. **The photometric centre refinement** (:func:`ffls.spheres.refine.refine_sphere_centre`): the
   photos' median / max angle to the true direction and the coverage of the 95% cone, with the
   refinement on (the default) and off (``estimate_photos(refine_centres=...)``; the lens's
   fall-off is not fitted in either, so only the refinement differs).
2. **The ground bounce's shape** (refinement off): ffls models the ground's light on a sphere as
   that of an infinite, uniform ground (``(1 - n_z) / 2`` less the sphere's own shadow), scaled
   per sphere by the capture's ground ratio. A textured ground, or an object that hides part of
   a sphere's ground, makes the bounce brighter on one side. Per sphere the script fits, over all
   photos at once, a horizontal gradient ``beta`` of that bounce from the shadow side's residuals
   (where no direct light falls: ``r = beta_x c g n_x + beta_y c g n_y``;
   :func:`ffls.spheres.estimate.calibrate_bounce_shape`), then refits each photo
   with the bounce ``g (1 + beta . n_h)`` (:func:`ffls.spheres.lambert.fit_lambert`, the capture's
   ratio imposed) and prints the sphere's own median / max error before and after.

Usage (``OMP_NUM_THREADS=1`` advised)::

    python bounce_shape.py CAPTURE [CAPTURE ...] [--out results/bounce_shape.json]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ffls.io.capture import load_capture
from ffls.radiance.photos import read_photo
from ffls.spheres.detect import find_spheres_in_capture
from ffls.spheres.estimate import calibrate_bounce_shape, capture_samples, estimate_photos, shaped_samples
from ffls.spheres.lambert import fit_lambert
from ffls.spheres.samples import sphere_values

#: Shadow-side pixels: ``n . l`` below minus this (the fits' terminator band).
TERMINATOR = 0.15


def _angle(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


def _photo_errors(est, truth) -> dict:
    ok = [(i, p) for i, p in enumerate(est.photos) if p.status == "ok"]
    e = np.array([_angle(p.direction, truth[i]) for i, p in ok])
    cov = np.mean([err <= p.uncertainty_deg for err, (_, p) in zip(e, ok)]) if ok else float("nan")
    return {"accepted": len(ok), "photos": len(est.photos), "median_deg": float(np.median(e)),
            "max_deg": float(e.max()), "coverage": float(cov)}


def diagnose(folder: Path) -> dict:
    cap = load_capture(folder)
    truth = np.asarray(json.loads((folder / "truth.json").read_text())["directions"], dtype=np.float64)
    spheres = find_spheres_in_capture(cap)
    photos = [read_photo(cap, i) for i in range(len(cap.image_paths))]
    samples = capture_samples(cap, spheres, photos[0].linear.shape[:2])
    values = [sphere_values(p.linear, samples, raw=p.raw if p.codes is not None else None, bit_depth=p.bit_depth)
              for p in photos]
    out = {"capture": str(folder), "spheres": len(spheres)}
    runs = {rc: estimate_photos(values, samples, cap.scene_center, flat_field=None, refine_centres=rc,
                                bounce_shape=False)  # (the uniform ground's bounce, diagnosed)
            for rc in (True, False)}
    out["refined"], out["unrefined"] = _photo_errors(runs[True], truth), _photo_errors(runs[False], truth)
    out["shifts_px"] = [float(r.shift_norm_px) for r in runs[True].refinements or []]
    est = runs[False]
    out["per_sphere"] = []
    betas = calibrate_bounce_shape(est.photos, est.samples, values, terminator=TERMINATOR)
    for k, (s, beta, shaped) in enumerate(zip(est.samples, betas, shaped_samples(est.samples, betas))):
        ratio = est.calibration[k].ratio if est.calibration else None
        if beta is None or ratio is None:
            out["per_sphere"].append({"sphere": k, "beta": None})
            continue
        g = shaped.ground
        pairs = []
        for i, ph in enumerate(est.photos):
            sr = ph.spheres[k]
            if sr.status != "ok" or sr.kind != "matte":
                continue
            v = values[i][k]
            fit = fit_lambert(s.normals, v.grey, v.valid, bounce_ratio=ratio, g=g, start=sr.fit.direction,
                              pixels=(s.rows, s.cols))
            if fit.status == "ok":
                pairs.append((_angle(sr.fit.direction, truth[i]), _angle(fit.direction, truth[i])))
        p = np.array(pairs)
        out["per_sphere"].append({"sphere": k, "beta": beta.tolist(), "refits": len(p),
                                  "before": [float(np.median(p[:, 0])), float(p[:, 0].max())],
                                  "after": [float(np.median(p[:, 1])), float(p[:, 1].max())]})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("captures", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, default=None, help="JSON file for the results")
    args = ap.parse_args()
    results = []
    for folder in args.captures:
        r = diagnose(folder)
        results.append(r)
        a, b = r["refined"], r["unrefined"]
        print(f"{folder.name}: {r['spheres']} spheres; refinement on {a['accepted']}/{a['photos']} "
              f"{a['median_deg']:.2f} / {a['max_deg']:.2f} deg, {a['coverage']:.0%} (shifts "
              f"{', '.join(f'{s:.2f}' for s in r['shifts_px'])} px); off {b['median_deg']:.2f} / "
              f"{b['max_deg']:.2f}, {b['coverage']:.0%}")
        for s in r["per_sphere"]:
            if s["beta"] is None:
                print(f"  sphere {s['sphere']}: no gradient (no calibrated ratio or no shadow side)")
                continue
            print(f"  sphere {s['sphere']}: beta ({s['beta'][0]:+.3f}, {s['beta'][1]:+.3f}); its own fits {s['before'][0]:.2f} / {s['before'][1]:.2f} -> "
                  f"{s['after'][0]:.2f} / {s['after'][1]:.2f} deg ({s['refits']} photos)")
    if args.out is not None:
        tmp = args.out.with_suffix(".tmp")
        tmp.write_text(json.dumps({"benchmark": "bounce_shape", "results": results}, indent=1))
        tmp.replace(args.out)


if __name__ == "__main__":
    main()
