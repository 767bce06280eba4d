"""Lights of a capture without a pose, two grey balls beside the object, scored in the camera's and
the scene's frames (docs/spheres.md, "The lights in the ground's frame").

Renders ``ffls synth ROOT --lights 24 --resolution 256 --camera-elevation E --spheres 2
--sphere-material grey --seed S`` (kept: a second run reuses it), deletes ``world_from_camera`` from
capture.json, runs ``FFLS lights ROOT --workers 1`` and prints: the tilt found, accepted, median
cone, median / max error and share in the cones in the camera's frame (the tilt's error cancels)
and in the scene's (the render's world, +Y the camera's forward: the tilt's error counts). Lights
without lights.json's ``frame`` (before the sixteenth stop) are turned by the tilt they record.

    cd benchmarks && OMP_NUM_THREADS=1 ../.venv/bin/python no_pose_spheres.py 60 1 ../.venv/bin/ffls
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA
from ffls.spheres.estimate import tilted_world_from_camera

from bench_no_pose import score  # benchmarks/bench_no_pose.py


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    elev, seed, ffls = float(argv[0]), int(argv[1]), argv[2]
    root = Path(f"/tmp/no_pose_spheres_{elev:g}_{seed}")
    if not (root / "truth.json").exists():
        subprocess.run([str(Path(sys.executable).with_name("ffls")), "synth", str(root), "--lights", "24",
                        "--resolution", "256", "--camera-elevation", str(elev), "--spheres", "2",
                        "--sphere-material", "grey", "--seed", str(seed), "--quiet"], check=True,
                       stdout=subprocess.DEVNULL)
        doc = json.loads((root / "capture.json").read_text())
        doc["camera"].pop("world_from_camera")
        doc.pop("truth", None)
        (root / "capture.json").write_text(json.dumps(doc))
    out = root / (Path(ffls).name + ".json")
    subprocess.run([ffls, "lights", str(root), "--workers", "1", "--no-progress", "-o", str(out)], check=True,
                   capture_output=True, env=dict(os.environ, OMP_NUM_THREADS="1"))
    doc = json.loads(out.read_text())
    ok = [e for e in doc["lights"] if e["status"] == "ok"]
    r = score(root, out, tilted_world_from_camera(elev)[:3, :3], DEFAULT_WORLD_FROM_CAMERA[:3, :3])
    tilt, u = r["tilt_deg"], np.asarray([e["uncertainty_deg"] for e in ok])
    print(f"elevation {elev:g}, seed {seed}, {Path(ffls).name}: tilt {tilt}, {r['accepted']}, "
          f"median cone {np.median(u):.2f}; camera frame {r['median_deg']:.2f} / {r['max_deg']:.2f}, "
          f"{r['inside']:.0%}; scene frame {r['world_median_deg']:.2f} / {r['world_max_deg']:.2f}, "
          f"{r['world_inside']:.0%} "
          f"(cones: {(doc.get('uncertainty') or {}).get('source')})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
