"""Bias of the per-sphere fit from the dark pixels under sensor noise (docs/spheres.md, "Pixel validity").

One sphere's visible half (10,000 normals), a distant light, Lambert + ambient 0.003 + ground
bounce 0.01 g, Poisson-Gaussian noise (shot gain 2e-4, read noise 0.004 of full scale), stored as
linear floats (negative values kept) or as linear 8-bit codes (clipped at code 0). Each photo is
fitted (:func:`ffls.spheres.lambert.fit_lambert`, free bounce) with the current validity
(:func:`ffls.spheres.samples.pixel_validity`: no censoring by value) and with the former rule
(``black_fraction=0.02``: grey values below 2 % of the 99th percentile dropped); prints the mean
and max angular error.

    OMP_NUM_THREADS=1 python benchmarks/noise_floor_check.py [--photos 30] [--seed 3]
"""
from __future__ import annotations

import argparse

import numpy as np

from ffls.conventions import angle_between, normalize
from ffls.spheres.lambert import fit_lambert
from ffls.spheres.samples import pixel_validity


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photos", type=int, default=30)
    ap.add_argument("--seed", type=int, default=3)
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    n = normalize(rng.normal(size=(40000, 3)))
    n = n[n[:, 1] < -0.1][:10000]  # the half seen by a camera at -Y
    g = 0.5 * (1 - n[:, 2])
    errs = {}
    for _ in range(a.photos):
        l = normalize(np.array([rng.uniform(-1, 1), rng.uniform(-1, -0.2), rng.uniform(0.1, 1)]))
        clean = 0.5 * np.maximum(n @ l, 0) + 0.003 + 0.01 * g
        x = 2e-4 * rng.poisson(clean / 2e-4) + rng.normal(0, 0.004, clean.size)
        for enc in ("float", "linear 8-bit"):
            y = x if enc == "float" else np.clip(np.round(x * 255), 0, 255) / 255
            for rule, bf in (("now", None), ("by value (former)", 0.02)):
                valid, nsat = pixel_validity(y, black_fraction=bf)
                f = fit_lambert(n, y, valid, n_saturated=nsat, g=g)
                errs.setdefault((enc, rule), []).append(float(np.degrees(angle_between(f.direction, l))))
    for (enc, rule), e in errs.items():
        print(f"{enc:13s} {rule:18s} mean {np.mean(e):.3f} max {np.max(e):.3f} deg ({len(e)} photos)")


if __name__ == "__main__":
    main()
