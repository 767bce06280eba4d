"""How much of a near photo's error is its light's distance, against ``ffls synth`` captures' truth.

For each capture (a folder with the ``truth.json`` that ``ffls synth`` writes) and its
``lights.json`` (``ffls lights``), the accepted near photos (not those placed at the capture's
range) are grouped by how many mirror or glossy spheres they used. Per group it prints: photos,
median (and 90%) angle to the true direction, the same with the light moved along its ray from
the used matte spheres' midpoint to its true distance from the scene centre (what is left when the
distance is right), the median ratio of estimated to true distance, and the coverage of the 95%
cones. Then, over all near photos, the median elevation error (estimated minus true, degrees) by
the light's true elevation. Nothing is written.

Usage::

    python near_distance_error.py CAPTURE LIGHTS.json [CAPTURE LIGHTS.json ...]
"""
from __future__ import annotations

import json
import sys

import numpy as np


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _angle(a, b):
    return float(np.degrees(np.arccos(np.clip(_unit(a) @ _unit(b), -1.0, 1.0))))


def rows(capture: str, lights: str) -> list[tuple]:
    """Per accepted near photo: (error, error at the true distance, mirrors used, distance ratio,
    cone, elevation error, true elevation), degrees."""
    t = json.load(open(f"{capture}/truth.json"))
    doc = json.load(open(lights))
    truth_pos = dict(zip(t["images"], map(np.asarray, t["positions"])))
    out = []
    for e in doc["lights"]:
        if e.get("status") != "ok" or e.get("model") != "near" or e.get("placed_at_capture_range"):
            continue
        p_true, p = truth_pos[e["image"]], np.asarray(e["position"], dtype=np.float64)
        used = [e["spheres"][i] for i in e["used_spheres"]]
        matte = np.array([s["center"] for s in used if s["kind"] == "matte"]) if used else np.zeros((0, 3))
        if len(matte) == 0:
            continue
        m = matte.mean(axis=0)
        u = _unit(p - m)
        b = float(m @ u)  # the point m + s u at the true distance from the scene centre (the origin)
        s = -b + np.sqrt(b * b - m @ m + p_true @ p_true)
        elev = lambda v: float(np.degrees(np.arcsin(_unit(v)[2])))  # noqa: E731
        out.append((_angle(p, p_true), _angle(m + s * u, p_true), sum(x["kind"] != "matte" for x in used),
                    float(np.linalg.norm(p) / np.linalg.norm(p_true)), float(e["uncertainty_deg"]),
                    elev(p) - elev(p_true), elev(p_true)))
    return out


def main(argv: list[str]) -> None:
    if len(argv) < 2 or len(argv) % 2:
        raise SystemExit(__doc__)
    r = np.array([x for c, l in zip(argv[0::2], argv[1::2]) for x in rows(c, l)])
    print("mirrors used | photos | error med (p90) | at true distance med (p90) | distance ratio | coverage")
    for k in sorted(set(r[:, 2].astype(int))):
        v = r[r[:, 2] == k]
        print(f"{k} | {len(v)} | {np.median(v[:, 0]):.2f} ({np.quantile(v[:, 0], 0.9):.2f}) | "
              f"{np.median(v[:, 1]):.2f} ({np.quantile(v[:, 1], 0.9):.2f}) | {np.median(v[:, 3]):.3f} | "
              f"{np.mean(v[:, 0] <= v[:, 4]):.0%}")
    print("true elevation | photos | elevation error med | coverage")
    for lo, hi in ((0, 20), (20, 40), (40, 60), (60, 90)):
        v = r[(r[:, 6] >= lo) & (r[:, 6] < hi)]
        if len(v):
            print(f"{lo}-{hi} | {len(v)} | {np.median(v[:, 5]):+.2f} | {np.mean(v[:, 0] <= v[:, 4]):.0%}")


if __name__ == "__main__":
    main(sys.argv[1:])
