"""Where a mirror or glossy ball's outline lies against its true silhouette, and what the images show there.

For ``ffls synth`` captures (their ``truth.json``), each mirror or glossy ball is found as ``ffls
lights`` finds it (:func:`ffls.spheres.detect.find_spheres_in_capture`), and set against the true
silhouette (the tangent cone's ellipse, :func:`ffls.spheres.detect.silhouette_px` of the true
sphere, 1440 points): ``t`` is the signed distance of a pixel from it (pixels, positive outside).

Printed per ball:

* the found outline's centre offset (x, y) and the mean radial offset of its own outline from
  the true one (pixels, negative: short);
* the outline's fitted points (``SphereFit.edge_px``): median ``t`` over all and per 30-degree
  sector (0 = image right, 90 = down; the count in brackets);
* medians over ``t`` bins (0.5 px) of the mean luminance (``SequenceStats.mean``), the strength of
  the edges that change with the light (:func:`ffls.spheres.detect.consistent_edge_strength`
  ``centered``) and of the edges that hold in the photos (not centered).

Usage: ``OMP_NUM_THREADS=1 python benchmarks/mirror_limb_profile.py CAPTURE ...``
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ffls.camera.projection import project_points
from ffls.io.capture import load_capture
from ffls.spheres.detect import consistent_edge_strength, find_spheres_in_capture, silhouette_px
from ffls.spheres.estimate import decode_photos

KINDS = ("mirror", "glossy_black")


def signed_distance(points, outline, center) -> np.ndarray:
    """Signed distance (pixels, positive outside) of ``points`` (n, 2) from a closed, densely
    sampled convex ``outline`` (m, 2) around ``center``: to its nearest sample, signed by whether
    the point lies farther from ``center`` than that sample."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    d, i = cKDTree(outline).query(P)
    far = np.hypot(*(P - center).T) > np.hypot(*(outline[i] - center).T)
    return np.where(far, d, -d)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("captures", type=Path, nargs="+")
    a = ap.parse_args(argv)
    bins = np.arange(-4.0, 4.01, 0.5)
    for folder in a.captures:
        truth = json.loads((folder / "truth.json").read_text())
        mats = [s.get("material") for s in truth.get("spheres") or []]
        if not any(m in KINDS for m in mats):
            continue
        cap = load_capture(folder)
        dec = decode_photos(cap, 1)
        found = find_spheres_in_capture(cap, stats=dec.stats, bit_depths=dec.bit_depths, workers=1)
        mean = np.asarray(dec.stats.mean, dtype=np.float64)
        maps = {"mean image": mean.mean(axis=2) if mean.ndim == 3 else mean}
        if dec.stats.edge_tensor is not None:
            for name, centered in (("changing edges", True), ("held edges", False)):
                maps[name] = consistent_edge_strength(dec.stats.edge_tensor, dec.stats.edge_photos, centered)[0]
        tc = np.asarray(truth["sphere_centers_px"], dtype=np.float64)
        for ft in found:
            j = int(np.argmin(np.hypot(*(tc - ft.center_px).T)))
            if mats[j] not in KINDS or ft.K is None:
                continue
            wfc = np.asarray(ft.world_from_camera, dtype=np.float64)
            C = (np.linalg.inv(wfc) @ np.append(truth["spheres"][j]["center"], 1.0))[:3]
            K = np.asarray(ft.K, dtype=np.float64)
            outline = silhouette_px(K, ft.dist, C, float(truth["sphere_radius"]), n=1440)
            cpx = project_points(C[None], K, ft.dist)[0]
            found_outline = silhouette_px(K, ft.dist, ft.center_cam, ft.radius, n=1440)
            dr = float(np.mean(signed_distance(found_outline, outline, cpx)))
            print(f"{folder.name} {mats[j]} ({ft.source}): centre offset {ft.center_px[0] - cpx[0]:+.2f}, "
                  f"{ft.center_px[1] - cpx[1]:+.2f} px; outline {dr:+.2f} px from the silhouette")
            P = np.asarray(ft.edge_px, dtype=np.float64).reshape(-1, 2)
            if len(P):
                t = signed_distance(P, outline, cpx)
                ang = np.degrees(np.arctan2(P[:, 1] - cpx[1], P[:, 0] - cpx[0])) % 360
                sec = [f"{s}:{np.median(t[m]):+.2f}({m.sum()})" if (m := (ang >= s) & (ang < s + 30)).any()
                       else f"{s}:-" for s in range(0, 360, 30)]
                print(f"  outline points: median t {np.median(t):+.2f} px; by sector " + " ".join(sec))
            H, W = maps["mean image"].shape
            r = float(np.max(np.hypot(*(outline - cpx).T))) + 6
            y0, y1 = max(int(cpx[1] - r), 0), min(int(cpx[1] + r) + 1, H)
            x0, x1 = max(int(cpx[0] - r), 0), min(int(cpx[0] + r) + 1, W)
            yy, xx = np.mgrid[y0:y1, x0:x1]
            t = signed_distance(np.stack([xx.ravel(), yy.ravel()], 1), outline, cpx).reshape(yy.shape)
            for name, img in maps.items():
                crop = img[y0:y1, x0:x1]
                prof = [np.median(crop[m]) if (m := np.abs(t - b) < 0.25).any() else np.nan for b in bins]
                print(f"  {name:14s} " + " ".join(f"{b:+.1f}:{p:.3f}" for b, p in zip(bins, prof)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
