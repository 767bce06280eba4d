"""A fitted tilt's error against its stated 95% error, over many captures without a pose
(docs/spheres.md, "The tilt's own error").

Renders each row below (``ffls synth ROOT --lights L --resolution 256 --camera-elevation E
--spheres N --sphere-material grey --seed S`` plus the row's options; kept under ``--cache``: a
second run reuses them), deletes ``world_from_camera``, ``spheres`` and ``truth`` from capture.json,
runs ``FFLS lights ROOT --workers 1`` and prints the tilt found, its error against the true E, the
stated 95% error (``frame.tilt_uncertainty_deg``; 2.5 before the seventeenth stop) and whether it
holds the error; and the lights' share inside their cones in the scene's frame (the render's
world: the fitted tilt's error counts). Rows marked ``flip`` are another row's photos turned 180 deg
(a camera rolled 180: the tilt ``180 - E``, a camera looking down past the vertical, which
``ffls synth`` does not render; the truth turned 180 deg about +Z with them).

    cd benchmarks && OMP_NUM_THREADS=1 ../.venv/bin/python tilt_error.py --ffls ../.venv/bin/ffls \\
        --cache /tmp/tilt_error --out /tmp/tilt_error.json
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA
from ffls.io.images import read_exr, write_exr
from ffls.spheres.estimate import tilted_world_from_camera

from bench_no_pose import score  # benchmarks/bench_no_pose.py
from common import write_json  # benchmarks/common.py (atomic)

JPEG = ("--format", "jpeg", "--encoding", "srgb", "--unstated-encoding", "--jpeg-quality", "85")
NOISE = ("--format", "png8", "--encoding", "linear", "--unstated-encoding", "--shot-noise", "1e-4",
         "--read-noise", "0.002", "--exposure", "3")

#: name, elevation, seed, spheres, lights, options (or ``("flip", other row)``)
ROWS = [
    ("e30s0n3", 30, 0, 3, 24, ()), ("e30s1n2", 30, 1, 2, 24, ()), ("e30s2n4", 30, 2, 4, 24, ()),
    ("e30s3n3", 30, 3, 3, 24, ()), ("e35s8n2", 35, 8, 2, 24, ()), ("e45s0n4", 45, 0, 4, 24, ()),
    ("e45s2n2", 45, 2, 2, 24, ()), ("e45s3n3", 45, 3, 3, 24, ()), ("e50s10n2", 50, 10, 2, 24, ()),
    ("e55s8n3", 55, 8, 3, 24, ()), ("e60s1n2", 60, 1, 2, 24, ()), ("e60s2n3", 60, 2, 3, 24, ()),
    ("e60s3n2", 60, 3, 2, 24, ()), ("e65s9n2", 65, 9, 2, 24, ()), ("e75s0n2", 75, 0, 2, 24, ()),
    ("e75s1n4", 75, 1, 4, 24, ()), ("e75s2n3", 75, 2, 3, 24, ()), ("e80s9n4", 80, 9, 4, 24, ()),
    ("e85s1n2", 85, 1, 2, 24, ()), ("e85s3n4", 85, 3, 4, 24, ()), ("e88s0n2", 88, 0, 2, 24, ()),
    ("e88s1n3", 88, 1, 3, 24, ()), ("e88s2n4", 88, 2, 4, 24, ()), ("e88s3n2", 88, 3, 2, 24, ()),
    ("j30s4n2", 30, 4, 2, 24, JPEG), ("j45s7n4", 45, 7, 4, 24, JPEG), ("j88s6n2", 88, 6, 2, 24, JPEG),
    ("n30s4n3", 30, 4, 3, 24, NOISE), ("n60s5n2", 60, 5, 2, 24, NOISE), ("n75s6n2", 75, 6, 2, 24, NOISE),
    ("n88s7n3", 88, 7, 3, 24, NOISE), ("l30s4n2", 30, 4, 2, 24, ("--lens", "long")),
    ("l60s5n3", 60, 5, 3, 24, ("--lens", "long")), ("l85s6n2", 85, 6, 2, 24, ("--lens", "long")),
    ("v45s4n2", 45, 4, 2, 24, ("--vignetting", "cos4")), ("o40s5n1", 40, 5, 1, 24, ()),
    ("o70s6n1", 70, 6, 1, 24, NOISE), ("o89s7n1", 89, 7, 1, 24, ()),
    ("dome41", 88, 3, 2, 41, ()), ("dome41s5", 87, 5, 2, 41, ()),
    ("Fdome41", 92, 3, 2, 41, ("flip", "dome41")), ("Fdome41s5", 93, 5, 2, 41, ("flip", "dome41s5")),
    ("Fe88s3n2", 92, 3, 2, 24, ("flip", "e88s3n2")), ("Fo89s7n1", 91, 7, 1, 24, ("flip", "o89s7n1")),
]


def _render(root: Path, elev, seed, spheres, lights, options) -> None:
    subprocess.run([sys.executable, "-m", "ffls.cli", "synth", str(root), "--lights", str(lights), "--resolution",
                    "256", "--camera-elevation", str(elev), "--spheres", str(spheres), "--sphere-material", "grey",
                    "--seed", str(seed), "--quiet", *options], check=True, stdout=subprocess.DEVNULL)
    doc = json.loads((root / "capture.json").read_text())
    doc["camera"].pop("world_from_camera")
    for key in ("truth", "spheres"):
        doc.pop(key, None)
    (root / "capture.json").write_text(json.dumps(doc))


def _flip(src: Path, dst: Path) -> None:
    """``src``'s photos turned 180 deg (the principal point is the image's centre), truth with them."""
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("*.out.json"))
    for f in sorted(dst.iterdir()):
        if f.suffix == ".exr":
            write_exr(f, read_exr(f, working_space=False).pixels[::-1, ::-1].copy())
        elif f.suffix in (".png", ".jpg"):
            cv2.imwrite(str(f), cv2.imread(str(f), cv2.IMREAD_UNCHANGED)[::-1, ::-1].copy(),
                        [cv2.IMWRITE_JPEG_QUALITY, 100])
    truth = json.loads((dst / "truth.json").read_text())
    truth["directions"] = (np.asarray(truth["directions"]) * [-1.0, -1.0, 1.0]).tolist()
    (dst / "truth.json").write_text(json.dumps(truth))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ffls", default=str(Path(sys.executable).with_name("ffls")), help="the ffls to measure")
    ap.add_argument("--cache", default="/tmp/tilt_error", help="where the renders are kept")
    ap.add_argument("--only", nargs="*", help="row names")
    ap.add_argument("--out", help="JSON of the rows")
    a = ap.parse_args(argv)
    cache, rows = Path(a.cache), []
    cache.mkdir(parents=True, exist_ok=True)
    for name, elev, seed, spheres, lights, options in ROWS:
        if a.only and name not in a.only:
            continue
        root = cache / name
        if not (root / "truth.json").exists():
            if options[:1] == ("flip",):
                src = cache / options[1]
                if not (src / "truth.json").exists():
                    _render(src, 180 - elev, seed, spheres, lights, ())
                _flip(src, root)
            else:
                _render(root, elev, seed, spheres, lights, options)
        out = root / (Path(a.ffls).name + ".out.json")
        subprocess.run([a.ffls, "lights", str(root), "--workers", "1", "--no-progress", "-o", str(out)], check=True,
                       capture_output=True, env=dict(os.environ, OMP_NUM_THREADS="1"))
        doc = json.loads(out.read_text())
        r = score(root, out, tilted_world_from_camera(elev)[:3, :3], DEFAULT_WORLD_FROM_CAMERA[:3, :3])
        stated = (doc.get("frame") or {}).get("tilt_uncertainty_deg")
        err = None if r["tilt_deg"] is None else r["tilt_deg"] - elev
        held = None if err is None or stated is None else bool(abs(err) <= stated)
        rows.append({"name": name, "elevation": elev, **r, "tilt_error_deg": err, "stated_deg": stated,
                     "held": held, "cones": (doc.get("uncertainty") or {}).get("source")})
        print(f"{name:10s} E {elev:3d}: tilt {r['tilt_deg']}, error {err if err is None else round(err, 2)}, "
              f"stated {stated}, {'held' if held else 'NOT held' if held is not None else '-'}; scene frame "
              f"{r['world_median_deg']:.2f} / {r['world_max_deg']:.2f} deg, {r['world_inside']:.0%} in the cones "
              f"({rows[-1]['cones']}), {r['accepted']}", flush=True)
    judged = [r for r in rows if r["held"] is not None]
    multi = [r for r in rows if r["cones"] != "fallback"]
    print(f"tilts held: {sum(r['held'] for r in judged)} of {len(judged)}; lights in the cones (2+ spheres' cones, "
          f"{len(multi)} captures): {sum(r['world_inside'] >= 0.9 for r in multi)} at 90% or more, "
          f"{sum(0.9 <= r['world_inside'] <= 0.98 for r in multi)} in 90-98%")
    if a.out:
        write_json(a.out, {"args": vars(a), "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
