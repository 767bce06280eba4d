"""How much a photo-edge outline fit depends on a small move of its start.

For each sphere of each capture (``truth.json`` of a ``bench_conditions.py`` render or an
``ffls synth`` capture), ``--starts`` start circles are drawn around the projected truth (centre
within 3 px, radius within 2 px; a fixed-seed generator) and each is fitted on the per-photo edge
evidence (:func:`ffls.spheres.detect.fit_on_consistent_edges`: the edges that hold in the photos and
the edges that change with the light, :class:`ffls.spheres.detect.ConsistentEdges`) from the start and
from the start moved by ``--move`` px along x. Reported per capture: fits made, how many of the
pairs end more than ``--tol`` px apart (centre distance plus radius difference), the largest gap,
and the pairs whose RMS falls on either side of ``PHOTO_EDGE_MAX_RESIDUAL_PX`` (a different
pass / fail decision).

Run from ``benchmarks/``: ``OMP_NUM_THREADS=1 ../.venv/bin/python detect_start_sensitivity.py DIR [DIR ...] [--out FILE]``
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from common import host_info, write_json
from ffls.io.capture import load_capture
from ffls.radiance.photos import read_photo
from ffls.spheres.detect import (PHOTO_EDGE_MAX_RESIDUAL_PX, ConsistentEdges, DetectionCamera,
                                 fit_on_consistent_edges, sequence_stats)


def capture_pairs(folder: Path, starts: int, move: float, seed: int = 0) -> list:
    """``[(gap px, rms a, rms b)]`` over the fitted pairs of one capture."""
    cap = load_capture(folder)
    n = len(cap.image_paths)
    st = sequence_stats((read_photo(cap, i).linear for i in range(n)), n_images=n)
    truth = json.loads((folder / "truth.json").read_text())
    H, W = st.max.shape[:2]
    model = getattr(cap, "camera_model", "pinhole")
    cam = DetectionCamera(model, cap.K, cap.dist, cap.world_from_camera, float(cap.sphere_radius or 1.0), (H, W))
    evidence = [ConsistentEdges.of(st.edge_tensor, st.edge_photos, centered=c) for c in (False, True)]
    rng = np.random.default_rng(seed)
    out = []
    for s in truth["spheres"]:
        c, r = np.asarray(s["center_px"], dtype=np.float64), float(s["radius_px"])
        for _ in range(starts):
            c0, r0 = c + rng.uniform(-3, 3, 2), r + rng.uniform(-2, 2)
            for ev in evidence:
                a = fit_on_consistent_edges(c0, r0, ev, cam, "auto")
                b = fit_on_consistent_edges(c0 + [move, 0.0], r0, ev, cam, "auto")
                if a is None or b is None:
                    continue
                gap = float(np.hypot(*(a.center_px - b.center_px)) + abs(a.radius_px - b.radius_px))
                out.append((gap, a.residual_px, b.residual_px))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("captures", nargs="+", type=Path)
    ap.add_argument("--starts", type=int, default=10, help="start circles per sphere")
    ap.add_argument("--move", type=float, default=0.05, help="the start's move, px")
    ap.add_argument("--tol", type=float, default=0.05, help="pairs further apart than this (px) differ")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "detect_start_sensitivity.json"))
    a = ap.parse_args(argv)
    totals = np.zeros(3, dtype=int)
    rows = []
    for folder in a.captures:
        pairs = capture_pairs(folder, a.starts, a.move)
        gaps = np.array([p[0] for p in pairs])
        flips = sum((ra <= PHOTO_EDGE_MAX_RESIDUAL_PX) != (rb <= PHOTO_EDGE_MAX_RESIDUAL_PX) for _, ra, rb in pairs)
        differ = int(np.count_nonzero(gaps > a.tol))
        totals += [len(pairs), differ, flips]
        rows.append({"capture": str(folder), "pairs": len(pairs), "apart": differ, "pass_fail_differs": int(flips),
                     "largest_gap_px": float(gaps.max()) if len(gaps) else 0.0})
        print(f"{folder.name:12s} pairs {len(pairs):4d}  apart > {a.tol} px: {differ:4d}  largest gap "
              f"{gaps.max() if len(gaps) else 0:.3f} px  pass/fail differs: {flips}", flush=True)
    print(f"all: pairs {totals[0]}, apart {totals[1]}, pass/fail differs {totals[2]}")
    write_json(a.out, {"host": host_info(), "settings": {"starts": a.starts, "move_px": a.move, "tol_px": a.tol},
                       "summary": {"pairs": int(totals[0]), "apart": int(totals[1]),
                                   "pass_fail_differs": int(totals[2])}, "rows": rows})


if __name__ == "__main__":
    main()
