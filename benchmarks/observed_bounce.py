"""The ground bounce from the photograph itself, against an ``ffls synth`` capture's truth.

A measurement, not yet a method of ``ffls lights``. For one capture with the ``truth.json`` that
``ffls synth`` writes (distant lights; an 8-bit capture that states no encoding is read with the
truth's), each matte sphere is placed at its TRUE centre (so that only the bounce model differs),
and every photo is fitted (:func:`ffls.spheres.lambert.fit_lambert`) with two bounce form factors:

* ``uniform``: ffls's infinite uniform ground less the sphere's own shadow
  (:func:`ffls.spheres.lambert.shadowed_ground_bounce`);
* ``observed``: the ground as photographed around the sphere (:mod:`ffls.spheres.ground`), its
  departure from the uniform model added where the camera sees it, for the light of the uniform
  fit and then of its own fit (two rounds).

Each is fitted twice: with a free bounce coefficient, and with the sphere's ground ratio imposed
(the median over the photos of its free fits' ``ground_ratio``, clipped to [0, 1], the same rule
for both models). A third model, ``two terms``, splits the bounce: the SEEN ground's, measured in
the photo's own units (:func:`ffls.spheres.ground.seen_bounce`) times the sphere's albedo
``kappa``, one constant per sphere (the median over the photos of the free bounce coefficient
with the column ``seen + L_ref hidden``), subtracted from the pixels; and the hidden ground's
(:func:`ffls.spheres.ground.hidden_form_factor`), its ground ratio calibrated (the median of the
free fits of what is left) and imposed. Printed per capture: every sphere's fits pooled, median / max angle to the true
direction, and each sphere's median, over the fits that all four modes accept.

Usage (``OMP_NUM_THREADS=1`` advised)::

    python observed_bounce.py CAPTURE [CAPTURE ...] [--out results/observed_bounce.json]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ffls.io.capture import load_capture
from ffls.radiance.photos import read_photo
from ffls.spheres.ground import (ground_radiance, ground_views, hidden_form_factor, observed_bounce,
                                 mask_view, not_ground, own_shadow_mask, seen_bounce)
from ffls.spheres.lambert import fit_lambert, shadowed_ground_bounce
from ffls.spheres.samples import sphere_samples, sphere_samples_orthographic, sphere_values

MODES = ("uniform free", "observed free", "uniform calibrated", "observed calibrated", "two terms calibrated")


def true_samples(cap, truth):
    """The matte spheres' samples at their true centres, and their indices in the truth."""
    H = W = int(truth["resolution"])
    M = np.asarray(cap.world_from_camera)
    Rw, tw = M[:3, :3], M[:3, 3]
    out, idx = [], []
    for k, sp in enumerate(truth["spheres"]):
        if sp["material"] in ("mirror", "glossy_black"):
            continue
        C, R = np.asarray(sp["center"], dtype=np.float64), float(sp["radius"])
        if cap.camera_model == "orthographic":
            out.append(sphere_samples_orthographic((H, W), sp["center_px"], sp["radius_px"], (C - tw) @ Rw, R, M))
        else:
            out.append(sphere_samples((H, W), cap.K, cap.dist, (C - tw) @ Rw, R, M))
        idx.append(k)
    return out, idx, (H, W)


def measure(folder: str, mask: bool = False, kappa_imposed: float | None = None,
            hidden_ratio: float | None = None) -> dict:
    cap = load_capture(folder)
    truth = json.loads((Path(folder) / "truth.json").read_text())
    if truth.get("positions"):
        raise SystemExit(f"{folder}: a near light (the observed bounce is measured for distant lights only)")
    if cap.encoding in (None, "auto"):
        cap.encoding = truth["encoding"]
    samples, idx, shape = true_samples(cap, truth)
    views = ground_views(samples, shape, cap.camera_model, cap.K, cap.dist, cap.world_from_camera)
    dirs = np.asarray(truth["directions"], dtype=np.float64)
    masked = [0] * len(views)
    if mask:  # the seen points that the photos show are not the ground (under the true lights)
        photos = [[ground_radiance(gv, img) for gv in views]
                  for img in (read_photo(cap, i).linear for i in range(len(cap.image_names)))]
        for k, gv in enumerate(views):
            R = np.stack([row[k] for row in photos])
            lit = np.stack([~own_shadow_mask(gv, d)[:gv.n_seen] for d in dirs])
            keep = ~not_ground(R, lit)
            views[k] = mask_view(gv, keep)
            masked[k] = 0 if views[k] is gv else int((~keep).sum())
    fits = []  # per photo, per sphere: (values, uniform free fit, observed form factor, observed free fit)
    for i in range(len(cap.image_names)):
        img = read_photo(cap, i).linear
        row = []
        for s, v, gv in zip(samples, sphere_values(img, samples), views):
            kw = dict(pixels=(s.rows, s.cols))
            fu = fit_lambert(s.normals, v.grey, v.valid, g=s.ground, **kw)
            L = ground_radiance(gv, img)
            light = fu.direction if fu.status == "ok" else np.array([0.0, 0.0, 1.0])
            for _ in range(2):
                B = observed_bounce(gv, L, light, shadowed_ground_bounce(s.normals, light, g=s.ground), s.normals)
                fo = fit_lambert(s.normals, v.grey, v.valid, g=B, own_shadow=False, **kw)
                light = fo.direction if fo.status == "ok" else light
            # two terms, for the light of the observed fit: the seen ground's bounce (photo units),
            # the hidden ground's form factor, and the lit seen ground's median (L_ref)
            lit = ~own_shadow_mask(gv, light)[:gv.n_seen]
            hid = hidden_form_factor(gv, light, shadowed_ground_bounce(s.normals, light, g=s.ground), s.normals)
            two = (seen_bounce(gv, L, s.normals), hid, float(np.median(L[lit])) if lit.any() else 0.0)
            row.append((v, fu, B, fo, two))
        fits.append(row)
    errors = {m: {} for m in MODES}  # (sphere, photo) -> angle to the truth

    def add(mode, k, i, f):
        if f.status == "ok":
            errors[mode][k, i] = float(np.degrees(np.arccos(np.clip(f.direction @ dirs[i], -1.0, 1.0))))

    ratios, kappas = [], []
    for k, s in enumerate(samples):
        kw = dict(pixels=(s.rows, s.cols))
        rho = []
        for j in (1, 3):
            r = [row[k][j].ground_ratio for row in fits if row[k][j].status == "ok"
                 and np.isfinite(row[k][j].ground_ratio)]
            rho.append(float(np.clip(np.median(r), 0.0, 1.0)) if r else 0.0)
        # two terms: the sphere's albedo kappa from free fits of the column seen + L_ref hidden,
        # then the hidden ground's ratio from free fits of the pixels less kappa seen
        c = []
        for row in fits:
            v, _, _, _, (bs, hid, lref) = row[k]
            f = fit_lambert(s.normals, v.grey, v.valid, g=bs + lref * hid, own_shadow=False, **kw)
            if f.status == "ok" and f.model == "bounce" and f.bounce > 0:
                c.append(f.bounce)
        kappa = float(np.median(c)) if c else 0.0
        kappa = kappa if kappa_imposed is None else kappa_imposed
        r = []
        for row in fits:
            v, _, _, _, (bs, hid, lref) = row[k]
            f = fit_lambert(s.normals, v.grey - kappa * bs, v.valid, g=hid, own_shadow=False, **kw)
            if f.status == "ok" and np.isfinite(f.ground_ratio):
                r.append(f.ground_ratio)
        rho.append(float(np.clip(np.median(r), 0.0, 1.0)) if r else 0.0)
        rho[2] = rho[2] if hidden_ratio is None else hidden_ratio
        ratios.append(rho)
        kappas.append(kappa)
        for i, row in enumerate(fits):
            v, fu, B, fo, (bs, hid, _) = row[k]
            add("uniform free", k, i, fu)
            add("observed free", k, i, fo)
            add("uniform calibrated", k, i,
                fit_lambert(s.normals, v.grey, v.valid, g=s.ground, bounce_ratio=rho[0], **kw))
            add("observed calibrated", k, i,
                fit_lambert(s.normals, v.grey, v.valid, g=B, bounce_ratio=rho[1], own_shadow=False, **kw))
            add("two terms calibrated", k, i, fit_lambert(s.normals, v.grey - kappa * bs, v.valid, g=hid,
                                                          bounce_ratio=rho[2], own_shadow=False, **kw))
    out = {"capture": str(folder), "spheres": idx, "seen_directions": [v.n_seen for v in views], "masked": masked,
           "ground_ratios": ratios, "kappas": kappas}
    # only the fits that every mode accepts (a mode's extra acceptances, e.g. a sphere in the
    # object's shadow, would not be compared)
    common = sorted(set.intersection(*(set(e) for e in errors.values())))
    out["compared"] = len(common)
    for m, e in errors.items():
        pooled = np.array([e[key] for key in common])
        per = [[e[key] for key in common if key[0] == k] for k in range(len(samples))]
        out[m] = {"median": float(np.median(pooled)), "max": float(pooled.max()),
                  "sphere_medians": [float(np.median(p)) if p else None for p in per]}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("captures", nargs="+")
    ap.add_argument("--out")
    ap.add_argument("--albedo", type=float, help="impose this sphere albedo (kappa) in the two terms (e.g. the "
                    "truth's, to tell its calibration's error from the model's)")
    ap.add_argument("--hidden-ratio", type=float, help="impose this hidden ground ratio in the two terms (e.g. "
                    "the truth's ground albedo)")
    ap.add_argument("--mask", action="store_true", help="take out of each sphere's ground the seen points that "
                    "are not shaded as the ground plane (ffls.spheres.ground.not_ground, under the true lights)")
    args = ap.parse_args(argv)
    rows = []
    for c in args.captures:
        r = measure(c, args.mask, args.albedo, args.hidden_ratio)
        rows.append(r)
        print(f"{c}: spheres {r['spheres']}, seen directions {r['seen_directions']}, masked {r['masked']}, ground ratios "
              f"(uniform, observed, two terms' hidden) {[[round(x, 3) for x in p] for p in r['ground_ratios']]}, "
              f"albedos (two terms) {[round(x, 3) for x in r['kappas']]}, "
              f"{r['compared']} fits compared")
        for m in MODES:
            e = r[m]
            print(f"  {m:20s} median {e['median']:.3f} max {e['max']:.2f} | per sphere "
                  + " ".join(f"{x:.3f}" for x in e["sphere_medians"] if x is not None))
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
