"""Outline radius and centre of each detected sphere against an ``ffls synth`` capture's truth.json.

Per true sphere: the detected apparent radius error (pinhole: ``f (asin(R/|C_det|) - asin(R/|C_true|))``,
the tangent cone's half-angle in pixels; orthographic: the circle's radius minus the true one), the
centre error (mm, and its part along the camera ray; pixels of the projected centre), and the median
distance of the outline's points from the true silhouette (pixels). An unstated encoding is read as
linear. Nothing is written.

    OMP_NUM_THREADS=1 python benchmarks/outline_radius.py CAPTURE [CAPTURE ...]
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import replace

import numpy as np

from ffls.conventions import angle_between
from ffls.io.capture import load_capture
from ffls.spheres.detect import find_spheres_in_capture, pixel_rays

def main(folder):
    cap = load_capture(folder)
    if cap.encoding == "auto":
        cap = replace(cap, encoding="linear")
    truth = json.load(open(f"{folder}/truth.json"))
    t = time.perf_counter()
    fits = find_spheres_in_capture(cap)
    dt = time.perf_counter() - t
    cfw = np.linalg.inv(cap.world_from_camera)
    for s in truth["spheres"]:
        d = [np.hypot(*(np.asarray(ft.center_px) - s["center_px"])) for ft in fits]
        k = int(np.argmin(d)) if d else -1
        if k < 0 or d[k] > s["radius_px_from_area"]:
            print(f"{s['material']:7s} NOT FOUND"); continue
        ft = fits[k]
        if ft.camera_model == "orthographic":
            rerr = ft.radius_px - s["radius_px"]
            cerr = d[k]
            eb = np.hypot(*(ft.edge_px - s["center_px"]).T) - s["radius_px"]
            print(f"{s['material']:7s} r {ft.radius_px:7.3f} true {s['radius_px']:7.3f} err {rerr:+.3f} px  "
                  f"centre {cerr:.3f} px  edges med {np.median(eb):+.3f} n {len(eb)} {ft.outline_edges} {ft.source}")
            continue
        Ct = (cfw @ np.r_[s["center"], 1.0])[:3]
        f = float(np.sqrt(cap.K[0, 0] * cap.K[1, 1]))
        R = ft.radius
        at, ad = np.arcsin(R / np.linalg.norm(Ct)), np.arcsin(R / np.linalg.norm(ft.center_cam))
        ray = Ct / np.linalg.norm(Ct)
        dc = ft.center_cam - Ct
        rays = pixel_rays(ft.edge_px, cap.K, cap.dist)
        eb = f * (angle_between(rays, ray) - at)
        print(f"{s['material']:7s} r {ft.radius_px:7.3f} err {f*(ad-at):+.3f} px  centre {1000*np.linalg.norm(dc):6.1f} mm "
              f"(depth {1000*dc@ray:+6.1f})  px {d[k]:.3f}  edges med {np.median(eb):+.3f} n {len(eb)} "
              f"{ft.outline_edges} {ft.source}")
    print(f"detect {dt:.1f} s")

if __name__ == "__main__":
    for folder in sys.argv[1:]:
        print("==", folder)
        main(folder)
