"""Where a mirror or glossy ball's light directions go wrong: the sphere's outline or the highlight.

For an ``ffls synth`` capture (its ``truth.json``) already estimated (``lights.json`` or
``lights_estimated.json`` from ``ffls lights``), per mirror sphere and photo, the highlight pixel
that the estimate used is mapped to a direction three ways: through the detected sphere, through
the sphere with its outline at the limb's step (:func:`ffls.spheres.highlight.refine_view_limb`)
and through the true sphere. The true sphere's error is the highlight centre's alone; the rest is
the outline's. Printed: the median error of each, the mean *tilt* error (the angle of the
direction from the sphere's view ray, estimated less true: an apparent radius too small tilts
every direction away from the camera) and the highlight pixel's distance to where the true light
reflects (pixels). Two more spheres split the outline's part: the true centre's direction at the
detected depth ("true centre only": the detected apparent radius) and the detected centre's
direction at the true depth ("true radius only"); for each sphere also the mean *elevation* error
(degrees above the world's horizontal plane, estimated less true), and the highlight pixel's mean
offset (x, y) from where the true light reflects.

Usage: ``OMP_NUM_THREADS=1 python benchmarks/attribute_mirror.py CAPTURE [ESTIMATE.json]``
"""
from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from ffls.conventions import angle_between
from ffls.io.capture import load_capture
from ffls.spheres.detect import find_spheres_in_capture
from ffls.spheres.estimate import decode_photos, sphere_views
from ffls.spheres.highlight import highlight_direction, refine_view_limb


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("estimate", type=Path, nargs="?", help="default CAPTURE/lights_estimated.json")
    a = ap.parse_args(argv)
    est_path = a.estimate or a.capture / "lights_estimated.json"
    cap = load_capture(a.capture)
    truth = json.loads((a.capture / "truth.json").read_text())
    est = json.loads(est_path.read_text())
    M = np.asarray(truth["lens"]["world_from_camera"], dtype=np.float64)
    R, t = M[:3, :3], M[:3, 3]
    tdirs = np.asarray(truth["directions"], dtype=np.float64)
    dec = decode_photos(cap, 1)
    spheres = find_spheres_in_capture(cap, stats=dec.stats, bit_depths=dec.bit_depths)
    views = sphere_views(cap, spheres)
    for k, (s, view) in enumerate(zip(spheres, views)):
        records = [(i, L["spheres"][k]) for i, L in enumerate(est["lights"])
                   if len(L.get("spheres", [])) == len(spheres) and L["spheres"][k].get("kind") == "mirror"
                   and L["spheres"][k].get("highlight_px") is not None]
        if not records:
            continue
        cw = R @ np.asarray(s.center_cam) + t
        j = int(np.argmin([np.linalg.norm(cw - np.asarray(q["center"])) for q in truth["spheres"]]))
        q = truth["spheres"][j]
        c_true = R.T @ (np.asarray(q["center"]) - t)
        true_view = replace(view, center_cam=c_true, center_px=np.asarray(q["center_px"], dtype=np.float64),
                            radius_px=float(q["radius_px"]))
        limb_view, limb = refine_view_limb(view, dec.stats.mean)
        c_det = np.asarray(view.center_cam, dtype=np.float64)
        # one part of the outline at a time: the true centre's direction at the detected depth
        # (the detected apparent radius), and the detected centre's direction at the true depth
        centre_only = replace(view, center_cam=c_true / np.linalg.norm(c_true) * np.linalg.norm(c_det),
                              center_px=true_view.center_px, radius_px=float(view.radius_px))
        radius_only = replace(view, center_cam=c_det / np.linalg.norm(c_det) * np.linalg.norm(c_true),
                              center_px=np.asarray(view.center_px, dtype=np.float64), radius_px=true_view.radius_px)
        views3 = (view, limb_view, true_view, centre_only, radius_only)
        v_world = R @ (-c_true / np.linalg.norm(c_true))  # from the sphere to the camera

        def tilt(d):
            return np.degrees(np.arccos(np.clip(d @ v_world, -1.0, 1.0)))

        def elevation(d):  # degrees above the world's horizontal plane (+Z up)
            return np.degrees(np.arcsin(np.clip(d[2], -1.0, 1.0)))

        rows = []
        for i, r in records:
            px = np.asarray(r["highlight_px"], dtype=np.float64)
            ds = [highlight_direction(v, px)[0] for v in views3]
            if not all(np.all(np.isfinite(d)) for d in ds):
                continue

            def miss(p, i=i):
                return highlight_direction(true_view, p)[0] - tdirs[i]

            try:
                ideal = least_squares(miss, px, diff_step=1e-4).x
            except ValueError:  # the search stepped off the sphere
                ideal = np.full(2, np.nan)
            rows.append([np.degrees(angle_between(d, tdirs[i])) for d in ds]
                        + [tilt(d) - tilt(tdirs[i]) for d in ds] + [float(np.hypot(*(px - ideal)))]
                        + [elevation(d) - elevation(tdirs[i]) for d in ds] + list(px - ideal))
        a_ = np.asarray(rows)
        print(f"sphere {k} ({q['material']}, truth {j}): {len(a_)} photos; limb step "
              f"{'used' if not np.array_equal(limb_view.center_px, view.center_px) else 'not used'}")
        n = len(views3)
        names = "detected %s  limb %s  true sphere %s  true centre only %s  true radius only %s"
        print("  median error deg: " + names % tuple(f"{v:.2f}" for v in np.median(a_[:, :n], axis=0)))
        print("  mean tilt error deg: " + names % tuple(f"{v:+.2f}" for v in np.mean(a_[:, n:2 * n], axis=0)))
        print("  mean elevation error deg: " + names % tuple(f"{v:+.2f}" for v in np.mean(a_[:, 2 * n + 1:3 * n + 1], axis=0)))
        print("  highlight pixel off the true reflection: median %.2f px, mean offset (x, y) %+.2f, %+.2f px"
              % (np.nanmedian(a_[:, 2 * n]), *np.nanmean(a_[:, 3 * n + 1:], axis=0)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
