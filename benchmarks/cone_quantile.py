"""How well a capture's cones fit its errors: accepted photos, median / max error (deg), coverage of
the 95 % cones, their median, and q95, the 95th percentile of error / cone (a calibrated cone has it
near 1; under 1 the cones are too wide by about its inverse).

Usage: ``python benchmarks/cone_quantile.py CAPTURE LIGHTS.json [LIGHTS.json ...]`` (``CAPTURE``
holds ``truth.json``; each ``LIGHTS.json`` is ``ffls lights CAPTURE -o LIGHTS.json``'s output).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def scores(truth: dict, lights: dict) -> dict:
    """The accepted photos' errors (deg) against ``truth["directions"]`` (matched by image name
    where the truth lists them) and their cones' fit."""
    names = truth.get("images")
    by_name = {Path(n).name: np.asarray(d, float) for n, d in zip(names, truth["directions"])} if names else None
    errs, cones = [], []
    for j, e in enumerate(lights["lights"]):
        if e.get("status", "ok") != "ok" or e.get("direction") is None:
            continue
        t = by_name[Path(e["image"]).name] if by_name else np.asarray(truth["directions"][j], float)
        d = np.asarray(e["direction"], float)
        errs.append(np.degrees(np.arccos(np.clip(t @ d / np.linalg.norm(t) / np.linalg.norm(d), -1.0, 1.0))))
        cones.append(float(e.get("uncertainty_deg", np.inf)))
    errs, cones = np.asarray(errs), np.asarray(cones)
    return dict(accepted=int(errs.size), photos=len(lights["lights"]), median=float(np.median(errs)),
                max=float(errs.max()), coverage=float(np.mean(errs <= cones)), cone=float(np.median(cones)),
                q95=float(np.quantile(errs / cones, 0.95)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("lights", type=Path, nargs="+")
    a = ap.parse_args(argv)
    truth = json.loads((a.capture / "truth.json").read_text())
    for p in a.lights:
        s = scores(truth, json.loads(p.read_text()))
        print(f"{a.capture.name} {p.name}: {s['accepted']}/{s['photos']}, {s['median']:.2f} / {s['max']:.2f}, "
              f"{s['coverage']:.1%} ({s['cone']:.2f}), q95 {s['q95']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
