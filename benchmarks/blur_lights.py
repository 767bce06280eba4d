"""Light directions from photos whose outlines are blurred, as a real lens, focus and resampling blur them.

A calibration shot of a grey and a chrome ball (``ffls synth --no-object --spheres 2
--sphere-material grey,mirror --lens long``, half-float EXR, the true ``K`` and pose kept), then:

- ``sharp``: as rendered at ``--res``;
- ``blur S``: each photo through ``cv2.GaussianBlur`` of sigma S px (a lens's and the focus's blur);
- ``resized``: rendered at 1.5 ``--res`` and shrunk to ``--res`` with ``cv2.INTER_AREA`` (what a user
  does to a camera's photos), ``K`` scaled with it.

Each is run through ``ffls lights CAPTURE --workers 1`` and scored against ``truth.json``: per sphere
found (its own direction, named by the kind ffls gave it) and per photo (the combined one), median /
max error, and the share of accepted photos whose truth lies inside their 95% cone.

    cd benchmarks && OMP_NUM_THREADS=1 python blur_lights.py --cache /tmp/blur --out /tmp/blur.json
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from common import host_info, write_json
from ffls.io.images import read_image, write_exr


def _synth(folder: Path, res: int, lights: int, seed: int) -> None:
    if not (folder / "truth.json").exists():
        subprocess.run([sys.executable, "-m", "ffls", "synth", str(folder), "--no-object", "--spheres", "2",
                        "--sphere-material", "grey,mirror", "--lens", "long", "--lights", str(lights),
                        "--resolution", str(res), "--seed", str(seed), "--quiet"], check=True)


def _condition(src: Path, dst: Path, image, scale: float = 1.0) -> None:
    """``dst``: ``src``'s photos through ``image`` (pixels -> pixels), its capture.json (K scaled by ``scale``,
    the pixel centres kept) without the true lights."""
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir(parents=True)
    doc = json.loads((src / "capture.json").read_text())
    for name in doc["images"]:
        write_exr(dst / name, image(read_image(src / name).pixels))
    K = np.asarray(doc["camera"]["K"], dtype=float)
    K[:2, :2] *= scale
    K[:2, 2] = (K[:2, 2] + 0.5) * scale - 0.5
    doc["camera"]["K"] = K.tolist()
    h, w = image(read_image(src / doc["images"][0]).pixels).shape[:2]
    doc["image_size"] = [w, h]
    doc.pop("truth", None)
    (dst / "capture.json").write_text(json.dumps(doc))


def _score(folder: Path, truth: dict) -> dict:
    subprocess.run([sys.executable, "-m", "ffls", "lights", str(folder), "--workers", "1", "--no-progress"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    lights = json.loads((folder / "lights.json").read_text())["lights"]
    true = np.asarray(truth["directions"], dtype=float)

    def angle(d, i):
        return float(np.degrees(np.arccos(np.clip(np.dot(d, true[i]), -1.0, 1.0))))

    def row(pairs):
        if not pairs:
            return {"accepted": 0}
        e, c = np.array(pairs).T
        return {"accepted": len(e), "median_deg": float(np.median(e)), "max_deg": float(e.max()),
                "coverage": float(np.mean(e <= c)), "median_cone_deg": float(np.median(c))}

    out = {"photos": row([(angle(li["direction"], i), li["uncertainty_deg"]) for i, li in enumerate(lights)
                          if li["status"] == "ok"]), "spheres": []}
    found = max((len(li.get("spheres", ())) for li in lights), default=0)
    for k in range(found):  # each sphere found, by the kind ffls gave it
        fits = [(i, li["spheres"][k]) for i, li in enumerate(lights) if k < len(li.get("spheres", ()))]
        out["spheres"].append({"material": fits[0][1]["kind"], **row(
            [(angle(f["direction"], i), f["uncertainty_deg"]) for i, f in fits if f["status"] == "ok"])})
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", required=True, help="folder for the renders and the conditions")
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--lights", type=int, default=24)
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--sigmas", default="0.7,1.2")
    ap.add_argument("--out", default="blur_lights.json")
    args = ap.parse_args(argv)
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    big = round(1.5 * args.res)
    _synth(cache / "sharp", args.res, args.lights, args.seed)
    _synth(cache / f"render{big}", big, args.lights, args.seed)
    truth = json.loads((cache / "sharp" / "truth.json").read_text())
    conditions = [("sharp", cache / "sharp", None, 1.0)]
    conditions += [(f"blur {s}", cache / "sharp", (lambda x, s=float(s): cv2.GaussianBlur(x, (0, 0), s)), 1.0)
                   for s in args.sigmas.split(",")]

    def shrink(x):
        return cv2.resize(x, (args.res, args.res), interpolation=cv2.INTER_AREA)
    conditions += [(f"resized {big}->{args.res}", cache / f"render{big}", shrink, args.res / big)]
    rows = []
    print(f"{'condition':18s} {'photos: n, median / max deg, coverage (cone)':46s} per sphere")
    for name, src, image, scale in conditions:
        folder = src if image is None else cache / name.replace(" ", "_").replace(">", "")
        if image is not None:
            _condition(src, folder, image, scale)
        (folder / "lights.json").unlink(missing_ok=True)
        r = {"condition": name, **_score(folder, truth)}
        rows.append(r)

        def text(d):
            if not d["accepted"]:
                return "none accepted"
            return (f"{d['accepted']}, {d['median_deg']:.2f} / {d['max_deg']:.2f}, "
                    f"{100 * d['coverage']:.0f}% ({d['median_cone_deg']:.2f})")
        spheres = "; ".join(f"{s['material']}: {text(s)}" for s in r["spheres"])
        print(f"{name:18s} {text(r['photos']):46s} {spheres}")
    write_json(args.out, {"host": host_info(), "res": args.res, "lights": args.lights, "seed": args.seed,
                          "rows": rows})


if __name__ == "__main__":
    main()
