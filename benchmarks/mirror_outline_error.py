"""A mirror or glossy ball's outline: its error against the truth, and what its cone says of it.

For ``ffls synth`` captures (their ``truth.json``), each mirror or glossy ball is found as ``ffls
lights`` finds it (:func:`ffls.spheres.detect.find_spheres_in_capture` on the decoded photos, its
view through :func:`ffls.spheres.estimate.sphere_views` and
:func:`ffls.spheres.highlight.refine_view_limb`), and its outline is set against the projected
truth: the centre's error (pixels, in the image) and the apparent radius's
(:func:`ffls.spheres.highlight.apparent_radius_px` against ``sphere_radii_px``), beside the
per-axis sigmas its cone uses (``center_sigma_px``, ``radius_sigma_px``). ``c/sc`` is the centre's
error over its per-axis sigma (the 95 % region of a 2-D normal error is 2.45); ``r/sr`` the
radius's over its sigma (1.96 for 95 %).

Beside them, the outline fit's own statistical standard error of the centre (per axis, x and y):
``plain`` is ``rms^2 (J^T J)^-1`` of the tangent cone fit (independent points), ``hac`` the same
fit with the residuals' correlation along the outline (a Newey-West estimate, Bartlett weights
over 20 neighbours in angle), ``arcs`` a block bootstrap over 12 arcs of 30 degrees (400 draws,
one Gauss-Newton step each). All three take the points the outline was fitted on
(``SphereFit.edge_px``).

Usage: ``OMP_NUM_THREADS=1 python benchmarks/mirror_outline_error.py CAPTURE ... [--out OUT.json]``
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ffls.camera.projection import pixel_rays
from ffls.errors import InputError
from ffls.io.capture import load_capture
from ffls.spheres.detect import find_spheres_in_capture, unit_cone_residuals
from ffls.spheres.estimate import decode_photos, sphere_views
from ffls.spheres.highlight import apparent_radius_px, refine_view_limb

KINDS = ("mirror", "glossy_black")


def _jacobian(p, s, f):
    r0 = unit_cone_residuals(p, s, f)
    J = np.empty((r0.size, p.size))
    for i in range(p.size):
        dp = np.zeros_like(p)
        dp[i] = 1e-3
        J[:, i] = (unit_cone_residuals(p + dp, s, f) - r0) / 1e-3
    return r0, J


def fit_sigmas(ft, K, dist, bandwidth: int = 20, arcs: int = 12, draws: int = 400) -> dict:
    """The outline fit's standard errors of the centre (x, y pixels): plain, HAC, arc bootstrap."""
    f = 0.5 * (K[0, 0] + K[1, 1])
    C = np.asarray(ft.center_cam, dtype=np.float64)
    d = C / np.linalg.norm(C)
    p = f * np.array([d[0] / d[2], d[1] / d[2], np.arcsin(min(ft.radius / np.linalg.norm(C), 1.0))])
    s = pixel_rays(np.asarray(ft.edge_px, dtype=np.float64), K, dist)
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    r0, J = _jacobian(p, s, f)
    n = r0.size
    A = np.linalg.inv(J.T @ J)
    plain = A * float(r0 @ r0) / (n - 3)
    ang = np.arctan2(*(np.asarray(ft.edge_px) - ft.center_px).T[::-1])
    o = np.argsort(ang)
    u = J[o] * r0[o][:, None]
    S = u.T @ u
    for lag in range(1, bandwidth + 1):
        G = u[lag:].T @ u[:-lag]
        S += (1 - lag / (bandwidth + 1)) * (G + G.T)
    hac = A @ S @ A
    block = ((ang + np.pi) / (2 * np.pi) * arcs).astype(int) % arcs
    present = np.unique(block)
    rng = np.random.default_rng(0)
    steps = []
    for _ in range(draws):
        idx = np.concatenate([np.flatnonzero(block == b) for b in rng.choice(present, present.size)])
        try:
            steps.append(-np.linalg.solve(J[idx].T @ J[idx], J[idx].T @ r0[idx]))
        except np.linalg.LinAlgError:
            continue
    boot = np.cov(np.asarray(steps).T)

    def xy(c):
        return [float(np.sqrt(c[0, 0])), float(np.sqrt(c[1, 1]))]

    return {"plain": xy(plain), "hac": xy(hac), "arcs": xy(boot), "n_points": int(n), "n_arcs": int(present.size)}


def balls(folder: Path) -> list[dict]:
    """One row per mirror or glossy ball of the capture in ``folder``."""
    truth = json.loads((folder / "truth.json").read_text())
    mats = [s.get("material") for s in truth.get("spheres") or []]
    if not any(m in KINDS for m in mats):
        return []
    cap = load_capture(folder)
    dec = decode_photos(cap, 1)
    try:
        found = find_spheres_in_capture(cap, stats=dec.stats, bit_depths=dec.bit_depths, workers=1)
    except InputError as e:
        return [{"capture": folder.name, "error": str(e).splitlines()[0][:160]}]
    tc = np.asarray(truth["sphere_centers_px"], dtype=np.float64)
    rows = []
    for ft, view in zip(found, sphere_views(cap, found)):
        j = int(np.argmin(np.hypot(*(tc - ft.center_px).T)))
        if mats[j] not in KINDS:
            continue
        v, _ = refine_view_limb(view, dec.stats.mean, len(found) == 1)  # a lone ball: bracketed
        ce = np.asarray(v.center_px) - tc[j]
        re = apparent_radius_px(v) - float(truth["sphere_radii_px"][j])
        row = {"capture": folder.name, "material": mats[j], "source": ft.source,
               "centre_error_px": float(np.hypot(*ce)), "radius_error_px": float(re),
               "center_sigma_px": float(v.center_sigma_px), "radius_sigma_px": float(v.radius_sigma_px),
               "outline_sigma_px": float(ft.outline_sigma_px)}
        row["c_over_sigma"] = row["centre_error_px"] / row["center_sigma_px"]
        row["r_over_sigma"] = abs(re) / v.radius_sigma_px if v.radius_sigma_px > 0 else float("inf")
        if ft.edge_px is not None and len(ft.edge_px) > 6 and cap.K is not None:
            row["fit"] = fit_sigmas(ft, np.asarray(cap.K), cap.dist)
        rows.append(row)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("captures", type=Path, nargs="+")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    rows = []
    print(f"{'capture':10s} {'material':12s} {'c err':>6s} {'sc':>5s} {'c/sc':>5s} {'r err':>6s} {'sr':>5s} "
          f"{'r/sr':>5s} | fit sigma x/y: plain, hac, arcs")
    for folder in a.captures:
        for r in balls(folder):
            rows.append(r)
            if "error" in r:
                print(f"{r['capture']:10s} not found: {r['error']}")
                continue
            fs = r.get("fit")
            fit = " ".join(f"{fs[k][0]:.2f}/{fs[k][1]:.2f}" for k in ("plain", "hac", "arcs")) if fs else "-"
            print(f"{r['capture']:10s} {r['material']:12s} {r['centre_error_px']:6.2f} {r['center_sigma_px']:5.2f} "
                  f"{r['c_over_sigma']:5.2f} {r['radius_error_px']:6.2f} {r['radius_sigma_px']:5.2f} "
                  f"{r['r_over_sigma']:5.2f} | {fit}", flush=True)
    if a.out:
        a.out.write_text(json.dumps({"balls": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
