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
  ``centered``) and of the edges that hold in the photos (not centered);
* with ``--band``, the outer edge of the changing edges' band along 180 rays from the found
  centre, as the chrome radius step reads it (:func:`ffls.spheres.mirror_outline.changing_limb_edges`):
  the edge points' median ``t`` and per sector, their distances' median absolute deviation (the
  step, :func:`ffls.spheres.mirror_outline.changing_limb_radius`, once refused over 1 px; it keeps
  their median now: docs/spheres.md), and the outline fitted on them (:func:`ffls.spheres.detect.fit_outline`, centre and
  radius): its centre offset and radial offset, as for the found outline.

Usage: ``OMP_NUM_THREADS=1 python benchmarks/mirror_limb_profile.py CAPTURE ... [--band]``
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ffls.camera.projection import project_points
from ffls.io.capture import load_capture
from ffls.spheres.detect import (DetectionCamera, consistent_edge_strength, find_spheres_in_capture, fit_outline,
                                 silhouette_px)
from ffls.spheres.estimate import decode_photos
from ffls.spheres.mirror_outline import changing_limb_edges

KINDS = ("mirror", "glossy_black")


def signed_distance(points, outline, center) -> np.ndarray:
    """Signed distance (pixels, positive outside) of ``points`` (n, 2) from a closed, densely
    sampled convex ``outline`` (m, 2) around ``center``: to its nearest sample, signed by whether
    the point lies farther from ``center`` than that sample."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    d, i = cKDTree(outline).query(P)
    far = np.hypot(*(P - center).T) > np.hypot(*(outline[i] - center).T)
    return np.where(far, d, -d)


def by_sector(t, ang) -> str:
    """Median of ``t`` per 30-degree sector of ``ang`` (degrees; 0 = image right, 90 = down)."""
    return " ".join(f"{s}:{np.median(t[m]):+.2f}({m.sum()})" if (m := (ang >= s) & (ang < s + 30)).any()
                    else f"{s}:-" for s in range(0, 360, 30))


def outline_offsets(ft, outline, cpx) -> str:
    """A fit's centre offset (x, y) from the true centre ``cpx`` and its outline's mean signed
    distance from the true ``outline`` (pixels)."""
    found_outline = silhouette_px(np.asarray(ft.K, dtype=np.float64), ft.dist, ft.center_cam, ft.radius, n=1440)
    dr = float(np.mean(signed_distance(found_outline, outline, cpx)))
    return (f"centre offset {ft.center_px[0] - cpx[0]:+.2f}, {ft.center_px[1] - cpx[1]:+.2f} px "
            f"({np.hypot(*(np.asarray(ft.center_px) - cpx)):.2f}); outline {dr:+.2f} px from the silhouette")


def band_lines(strength, ft, outline, cpx, R, shape) -> list[str]:
    """The ``--band`` lines of one ball (the module's docstring)."""
    c = np.asarray(ft.center_px, dtype=np.float64)
    e = changing_limb_edges(strength, c, float(ft.radius_px))
    ok = np.isfinite(e)
    if ok.sum() < 8:
        return ["  band's outer edge: fewer than 8 rays"]
    th = np.arange(e.size) * 2 * np.pi / e.size
    P = c + e[ok, None] * np.stack([np.cos(th[ok]), np.sin(th[ok])], axis=1)
    t = signed_distance(P, outline, cpx)
    ang = np.degrees(np.arctan2(P[:, 1] - cpx[1], P[:, 0] - cpx[0])) % 360
    med = float(np.median(e[ok]))
    lines = [f"  band's outer edge ({int(ok.sum())} rays): median t {np.median(t):+.2f} px, spread (MAD) "
             f"{np.median(np.abs(e[ok] - med)):.2f} px; by sector " + by_sector(t, ang)]
    cam = DetectionCamera("pinhole", np.asarray(ft.K, dtype=np.float64), ft.dist,
                          np.asarray(ft.world_from_camera, dtype=np.float64), R, shape)
    try:
        fit = fit_outline(P, cam, c, float(ft.radius_px), ft.source)
        lines.append("  outline fitted on the band's edges: " + outline_offsets(fit, outline, cpx))
    except ValueError as err:
        lines.append(f"  outline fitted on the band's edges: failed ({err})")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("captures", type=Path, nargs="+")
    ap.add_argument("--band", action="store_true", help="the changing band's outer edge per ray, and a fit on it")
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
            print(f"{folder.name} {mats[j]} ({ft.source}): " + outline_offsets(ft, outline, cpx))
            P = np.asarray(ft.edge_px, dtype=np.float64).reshape(-1, 2)
            if len(P):
                t = signed_distance(P, outline, cpx)
                ang = np.degrees(np.arctan2(P[:, 1] - cpx[1], P[:, 0] - cpx[0])) % 360
                print(f"  outline points: median t {np.median(t):+.2f} px; by sector " + by_sector(t, ang))
            if a.band and "changing edges" in maps:
                for line in band_lines(maps["changing edges"], ft, outline, cpx, float(truth["sphere_radius"]),
                                       maps["mean image"].shape):
                    print(line)
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
