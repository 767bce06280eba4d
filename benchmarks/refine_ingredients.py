"""The sphere outlines and the photometric centre refinement, one ingredient at a time, against truth.json.

Runs :func:`ffls.spheres.estimate.estimate_lights` on one ``ffls synth`` capture (its encoding
calibrated first where unstated, as ``ffls lights`` does) with:

* ``detected``: the spheres as detected, the refinement as ``estimate_lights`` runs it (not for an
  outline at the linear step, ``estimate.centres_to_refine``);
* ``refined``: the same outlines, every sphere refined (as before ``centres_to_refine``);
* ``norefine``: no sphere refined;
* ``true``: each detected sphere's centre replaced by the truth, not refined;
* ``true_refine``: the true centres, refined (where the shading puts them).

Per sphere it prints the detected outline's apparent radius error (the tangent cone's half-angle,
pixels), its centre's error along the camera ray (mm) and across it (pixels); per run: accepted
photos, median / max angle to the true direction, coverage of the 95% cone and its median, the
mean elevation error, each sphere's median own-fit error, and each sphere's refinement shift
(pixels; 0: none accepted). Nothing is written.

    OMP_NUM_THREADS=1 python benchmarks/refine_ingredients.py CAPTURE [--variants detected,norefine,...]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
from pathlib import Path

import numpy as np

from ffls.commands.lights import calibrate_if_unknown
from ffls.conventions import angle_between
from ffls.io.capture import load_capture, save_lights
from ffls.spheres.detect import find_spheres_in_capture
from ffls.spheres.estimate import decode_photos, estimate_lights

VARIANTS = ("detected", "refined", "norefine", "true", "true_refine")


def outline_errors(cap, spheres, truth) -> list[str]:
    """Per detected sphere: apparent radius error (px), centre error along (mm) and across (px) the ray."""
    cfw = np.linalg.inv(np.asarray(cap.world_from_camera))
    centres = np.asarray(truth["sphere_centers"])
    out = []
    for ft in spheres:
        k = int(np.argmin(np.linalg.norm(centres - ft.center_world, axis=1)))
        if ft.camera_model == "orthographic":
            s = truth["spheres"][k]
            out.append(f"sphere {k}: radius {ft.radius_px - s['radius_px']:+.3f} px, centre "
                       f"{np.hypot(*(np.asarray(ft.center_px) - s['center_px'])):.3f} px")
            continue
        Ct = (cfw @ np.r_[centres[k], 1.0])[:3]
        f = float(np.sqrt(cap.K[0, 0] * cap.K[1, 1]))
        err = f * (np.arcsin(ft.radius / ft.distance) - np.arcsin(ft.radius / np.linalg.norm(Ct)))
        ray = Ct / np.linalg.norm(Ct)
        dc = ft.center_cam - Ct
        across = f * np.linalg.norm(dc - (dc @ ray) * ray) / np.linalg.norm(Ct)
        out.append(f"sphere {k}: radius {err:+.3f} px, centre {1000 * dc @ ray:+.1f} mm along the ray, "
                   f"{across:.3f} px across (outline at the step: {ft.outline_at_step})")
    return out


def score(lights, truth) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "lights.json"
        save_lights(lights, path)
        recs = json.loads(path.read_text())["lights"]
    est = np.array([r["direction"] for r in recs], dtype=np.float64)
    ok = np.array([r.get("status", "ok") == "ok" for r in recs])
    unc = np.array([np.nan if r.get("uncertainty_deg") is None else r["uncertainty_deg"] for r in recs])
    true = np.asarray(truth["directions"], dtype=np.float64)
    err = np.degrees(angle_between(est, true))
    e, u = err[ok], unc[ok]
    elev = np.degrees(np.arcsin(np.clip(est[ok, 2], -1, 1)) - np.arcsin(np.clip(true[ok, 2], -1, 1)))
    own: dict = {}
    for r, t in zip(recs, true):
        for j, s in enumerate((r.get("spheres") or []) if r.get("status", "ok") == "ok" else []):
            if s.get("direction") is not None:
                own.setdefault(j, []).append(float(np.degrees(angle_between(np.asarray(s["direction"]), t))))
    shifts = [round(float(s.get("center_shift_px") or 0.0), 3) for s in (recs[0].get("spheres") or [])]
    return (f"{ok.sum()}/{len(ok)}  median / max {np.median(e):.3f} / {e.max():.3f} deg  coverage "
            f"{100 * np.mean(e <= u):.0f}%  cone {np.median(u):.2f}  elevation {elev.mean():+.3f}  own "
            + " ".join(f"{np.median(v):.2f}" for _, v in sorted(own.items())) + f"  shifts {shifts}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    a = ap.parse_args()
    truth = json.loads((Path(a.capture) / "truth.json").read_text())
    cap = load_capture(a.capture)
    decoded = decode_photos(cap, workers=1)
    cap, spheres, _ = calibrate_if_unknown(cap, progress=False, decoded=decoded, workers=1)
    if spheres is None:
        spheres = find_spheres_in_capture(cap, stats=decoded.stats, bit_depths=decoded.bit_depths, workers=1)
    spheres = list(spheres)
    for line in outline_errors(cap, spheres, truth):
        print(line)
    cfw = np.linalg.inv(np.asarray(cap.world_from_camera))
    centres = np.asarray(truth["sphere_centers"])
    for v in a.variants.split(","):
        use, kw = spheres, {}
        if v.startswith("true"):
            which = [int(np.argmin(np.linalg.norm(centres - s.center_world, axis=1))) for s in spheres]
            use = [dataclasses.replace(s, center_world=centres[k], center_cam=(cfw @ np.r_[centres[k], 1.0])[:3])
                   for s, k in zip(spheres, which)]
            kw["refine_centres"] = v == "true_refine"
        if v in ("refined", "true_refine"):  # every sphere refined: no outline taken as at the step
            use = [dataclasses.replace(s, outline_at_step=False) for s in use]
        if v == "norefine":
            kw["refine_centres"] = False
        lights = estimate_lights(cap, spheres=use, progress=False, workers=1, decoded=decoded, **kw)
        print(f"{v:12s} {score(lights, truth)}", flush=True)


if __name__ == "__main__":
    main()
