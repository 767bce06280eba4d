"""Light directions from a capture that gives no camera pose (issue 9's first example).

Renders ``ffls synth --calibration-pair`` sets of one grey ball on the ground, seen from 30 deg above
(the photometric-stereo set of issue 9: 12 lights, 8-bit linear PNG, encoding unstated, shot and
read noise), cuts each ``capture.json`` to the images and a camera without ``world_from_camera``
(``--camera orthographic``: ``{"model": "orthographic"}``; ``pinhole``: the render's ``K``), runs
``ffls lights --workers 1`` with the given executable and scores the lights against ``truth.json``
in the camera's frame: accepted, median / max error, the share inside the 95% cones, the
camera tilt (and roll) found and the wall time of ``ffls lights``; and in the scene's frame (the
render's world, +Y the camera's forward, where the fitted tilt's error counts: the lights as
lights.json's ``frame`` gives them, or turned by the tilt found) with the accepted lights at
z >= 0 (docs/spheres.md, "Without the camera's pose"). ``--elevation DEG`` renders the camera
that far down (default 30; a copy stand 90), ``--roll DEG`` renders with the camera turned about
its optical axis (``ffls synth --camera-roll``: a tripod that is not level); ``--fit-roll`` runs
``ffls lights --fit-roll``.

    cd benchmarks && OMP_NUM_THREADS=1 ../.venv/bin/python bench_no_pose.py --seeds 0 1 2 3 4 \\
        --lens long --camera orthographic --ffls ../.venv/bin/ffls --out /tmp/no_pose.json
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA
from ffls.spheres.estimate import tilted_world_from_camera


def _render(folder: Path, seed: int, lens: str, resolution: int, roll: float, elevation: float) -> Path:
    subprocess.run([sys.executable, "-m", "ffls.cli", "synth", str(folder), "--calibration-pair", "--spheres", "1",
                    "--sphere-material", "grey", "--lights", "12", "--format", "png8", "--encoding", "linear",
                    "--unstated-encoding", "--lens", lens, "--exposure", "3", "--resolution", str(resolution),
                    "--shot-noise", "1e-4", "--read-noise", "0.002", "--seed", str(seed), "--camera-roll", str(roll),
                    "--camera-elevation", str(elevation),
                    "--quiet"], check=True,
                   stdout=subprocess.DEVNULL)
    return folder / "calibration"


def _without_pose(cal: Path, camera: str, pose: bool) -> np.ndarray:
    """Rewrites ``cal/capture.json``; returns the capture's world_from_camera rotation as ffls reads it."""
    doc = json.loads((cal / "capture.json").read_text())
    cam = doc["camera"]
    new = {"model": "orthographic"} if camera == "orthographic" else {"K": cam["K"], "dist": cam["dist"]}
    if pose:
        new["world_from_camera"] = cam["world_from_camera"]
    keep = {"format": doc["format"], "version": doc["version"], "images": doc["images"], "camera": new}
    if camera != "orthographic" or pose:
        keep["sphere_radius"] = doc["sphere_radius"]
    (cal / "capture.json").write_text(json.dumps(keep))
    return np.array(cam["world_from_camera"])[:3, :3] if pose else DEFAULT_WORLD_FROM_CAMERA[:3, :3]


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def score(cal: Path, lights: Path, Rw: np.ndarray, Rm: np.ndarray) -> dict:
    """Errors in the camera's frame (the fitted tilt's error cancels) and in the scene's (up +Z,
    azimuth from the camera: the render's world, whose +Y is the camera's forward; the lights as
    the tilt fitted turns them: the fitted tilt's error counts)."""
    truth = json.loads((cal / "truth.json").read_text())
    true_world = dict(zip(truth["images"], np.asarray(truth["directions"])))
    doc = json.loads(lights.read_text())
    got = doc["lights"]
    if (doc.get("frame") or {}).get("world_from_camera") is not None:  # the lights' own frame (the fitted one)
        Rm = np.asarray(doc["frame"]["world_from_camera"])[:3, :3]
    tilt = next((e["camera_tilt_deg"] for e in got if e.get("camera_tilt_deg") is not None), None)
    roll = next((e["camera_roll_deg"] for e in got if e.get("camera_roll_deg") is not None), None)
    # the scene's frame as the fit found it (the capture's own when stated or nothing was fitted)
    Rs = Rm if tilt is None or "frame" in doc else tilted_world_from_camera(tilt, roll or 0.0)[:3, :3]
    err, inside, werr, winside = [], [], [], []
    for e in got:
        if e.get("status", "ok") != "ok":
            continue
        d = Rm.T @ np.asarray(e["direction"])  # camera frame
        t = true_world[e["image"]]
        err.append(angle(Rw.T @ t, d))
        inside.append(err[-1] <= e["uncertainty_deg"])
        werr.append(angle(t, Rs @ d))
        winside.append(werr[-1] <= e["uncertainty_deg"])
    return {"accepted": f"{len(err)}/{len(got)}", "median_deg": float(np.median(err)), "max_deg": float(max(err)),
            "inside": float(np.mean(inside)), "tilt_deg": tilt, "roll_deg": roll,
            "world_median_deg": float(np.median(werr)), "world_max_deg": float(max(werr)),
            "world_inside": float(np.mean(winside)),
            "upper": f"{sum(float(np.asarray(e['direction'])[2]) >= 0 for e in got if e.get('status', 'ok') == 'ok')}"
                     f"/{len(err)}"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--lens", choices=("long", "normal"), default="long")
    ap.add_argument("--camera", choices=("orthographic", "pinhole"), default="orthographic")
    ap.add_argument("--pose", action="store_true", help="keep the true world_from_camera (the reference)")
    ap.add_argument("--resolution", type=int, default=384)
    ap.add_argument("--roll", type=float, default=0.0, help="the camera's roll about its optical axis (deg)")
    ap.add_argument("--fit-roll", action="store_true", help="run ffls lights --fit-roll")
    ap.add_argument("--elevation", type=float, default=30.0,
                    help="how far the camera looks down (deg; ffls synth --camera-elevation)")
    ap.add_argument("--ffls", default=str(Path(sys.executable).with_name("ffls")), help="the ffls to measure")
    ap.add_argument("--out", help="JSON of the rows")
    a = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in a.seeds:
            cal = _render(Path(tmp) / f"s{s}", s, a.lens, a.resolution, a.roll, a.elevation)
            Rw = np.array(json.loads((cal / "capture.json").read_text())["camera"]["world_from_camera"])[:3, :3]
            Rm = _without_pose(cal, a.camera, a.pose)
            out = Path(tmp) / f"lights{s}.json"
            t0 = time.perf_counter()
            subprocess.run([a.ffls, "lights", str(cal), "--workers", "1", "--no-progress", "-o", str(out),
                            *(["--fit-roll"] if a.fit_roll else [])], check=True,
                           capture_output=True, env=dict(os.environ, OMP_NUM_THREADS="1"))
            wall = time.perf_counter() - t0
            rows.append({"seed": s, **score(cal, out, Rw, Rm), "wall_s": wall})
            r = rows[-1]
            tilt = "-" if r["tilt_deg"] is None else f"{r['tilt_deg']:.1f}"
            roll = "-" if r["roll_deg"] is None else f"{r['roll_deg']:.1f}"
            print(f"seed {s}: {r['accepted']} {r['median_deg']:.2f} / {r['max_deg']:.2f} deg, "
                  f"{r['inside']:.0%} in the cones, tilt {tilt}, roll {roll}; in the scene's frame "
                  f"{r['world_median_deg']:.2f} / {r['world_max_deg']:.2f} deg, {r['world_inside']:.0%} in the "
                  f"cones, {r['upper']} at z >= 0; {wall:.1f} s", flush=True)
    if a.out:
        Path(a.out).write_text(json.dumps({"args": vars(a), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
