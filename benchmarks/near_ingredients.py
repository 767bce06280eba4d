"""One ingredient of a near light's error at a time, against an ``ffls synth`` capture's truth.

Runs :func:`ffls.spheres.estimate.estimate_lights` on one capture (which must hold the
``truth.json`` that ``ffls synth`` writes) with the spheres as detected, or with each detected
sphere's centre replaced by the true one (the photometric centre refinement then off), and with
the ground bounce calibrated over the capture or free per photo. For each run it prints: accepted
photos, median / max angle to the true direction, coverage of the 95% cone, median cone; the ratio
of the estimated to the true distance of the lamp from the mean true sphere centre and the median
elevation bias of that direction; each matte sphere's own (distant) fit against the true direction
from its true centre; and each detected centre's error in mm.

Usage (``OMP_NUM_THREADS=1`` advised; nothing is written)::

    python near_ingredients.py CAPTURE [--variants detected,detected_free,true,true_free,true_noown]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
from pathlib import Path

import numpy as np

from ffls.io.capture import load_capture, save_lights
from ffls.spheres.detect import find_spheres_in_capture
from ffls.spheres.estimate import estimate_lights

VARIANTS = ("detected", "detected_free", "true", "true_free", "true_noown")


def angle_deg(a, b):
    a = np.asarray(a, float) / np.linalg.norm(a, axis=-1, keepdims=True)
    b = np.asarray(b, float) / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0)))


def elevation_deg(v):
    v = np.asarray(v, float)
    return float(np.degrees(np.arcsin(v[2] / np.linalg.norm(v))))


def run(capture, truth, spheres, variant):
    centres = np.array(truth["sphere_centers"])
    which = [int(np.argmin(np.linalg.norm(centres - s.center_world, axis=1))) for s in spheres]
    use = list(spheres)
    if variant.startswith("true"):
        camera_from_world = np.linalg.inv(np.asarray(capture.world_from_camera))
        use = [dataclasses.replace(s, center_world=centres[k], center_cam=(camera_from_world @ np.r_[centres[k], 1.0])[:3])
               for s, k in zip(spheres, which)]
    opts = {"own_shadow": False} if variant.endswith("noown") else {}
    lights = estimate_lights(capture, spheres=use, progress=False, workers=1, refine_centres=not variant.startswith("true"),
                             bounce="free" if variant.endswith("free") else "calibrated", **opts)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "lights.json"
        save_lights(lights, path)
        records = json.loads(path.read_text())["lights"]
    positions = np.array(truth["positions"])
    middle = centres.mean(axis=0)
    err, cone, ratio, elev, sphere_err, sphere_elev = [], [], [], [], [], []
    for i, rec in enumerate(records):
        if rec["status"] != "ok":
            continue
        err.append(float(angle_deg(rec["direction"], positions[i])))
        cone.append(rec["uncertainty_deg"])
        if rec.get("position") is not None:
            ratio.append(np.linalg.norm(np.array(rec["position"]) - middle) / np.linalg.norm(positions[i] - middle))
            elev.append(elevation_deg(np.array(rec["position"]) - middle) - elevation_deg(positions[i] - middle))
        for j, s in enumerate(rec["spheres"]):
            if s["status"] == "ok" and s.get("kind") == "matte":
                true_dir = positions[i] - centres[which[j]]
                sphere_err.append(float(angle_deg(s["direction"], true_dir)))
                sphere_elev.append(elevation_deg(s["direction"]) - elevation_deg(true_dir))
    err, cone = np.array(err), np.array(cone)
    print(f"{variant:14s} ok {len(err)}/{len(records)}  median / max {np.median(err):.2f} / {err.max():.2f} deg  "
          f"coverage {np.mean(err <= cone):.0%}  cone {np.median(cone):.2f}  distance ratio {np.median(ratio):.3f} "
          f"(10-90% {np.percentile(ratio, 10):.3f}-{np.percentile(ratio, 90):.3f})  elevation {np.median(elev):+.2f}  "
          f"spheres {np.median(sphere_err):.2f} deg, elevation {np.median(sphere_elev):+.2f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("capture")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    a = ap.parse_args()
    variants = a.variants.split(",")
    unknown = set(variants) - set(VARIANTS)
    if unknown:
        ap.error(f"unknown variants {sorted(unknown)}; known: {', '.join(VARIANTS)}")
    capture = load_capture(a.capture)
    truth = json.loads((Path(a.capture) / "truth.json").read_text())
    spheres = find_spheres_in_capture(capture)
    centres = np.array(truth["sphere_centers"])
    for s in spheres:
        k = int(np.argmin(np.linalg.norm(centres - s.center_world, axis=1)))
        d = s.center_world - centres[k]
        ray = centres[k] - np.asarray(capture.world_from_camera)[:3, 3]
        along = float(d @ ray / np.linalg.norm(ray))
        print(f"sphere {k}: detected centre off by {np.round(d * 1000, 1).tolist()} mm ({along * 1000:+.1f} mm along the "
              f"camera ray), radius {s.radius_px:.2f} px")
    for v in variants:
        run(capture, truth, spheres, v)


if __name__ == "__main__":
    main()
