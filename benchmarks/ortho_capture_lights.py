"""Light directions from an orthographic capture made here (tests/detect_scenes.py), end to end.

Two matte spheres (radius 22 px) under 12 lights, 400x300 px, grey background, written as 8-bit
PNG with ``"encoding": "linear"`` and ``"camera": {"model": "orthographic"}`` (no K, no
sphere_radius); then ``ffls lights`` runs on it and the directions are compared with the truth.

    python benchmarks/ortho_capture_lights.py OUT_FOLDER
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import detect_scenes as ds  # noqa: E402

from ffls.conventions import angle_between  # noqa: E402
from ffls.io.capture import load_capture, load_lights  # noqa: E402
from ffls.io.images import write_png  # noqa: E402
from ffls.spheres.detect import to_world  # noqa: E402


def main(out: str) -> None:
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    L = ds.lights(12, seed=1)
    scene = ds.Scene((300, 400), [ds.Ball(np.array([u, v, 100.0]), 22.0) for u, v in [(80, 80), (250, 200)]],
                     "orthographic", None)
    seq = ds.render(scene, L, "grey", noise=0.001)
    names = []
    for i, im in enumerate(seq):
        names.append(f"p{i:02d}.png")
        write_png(folder / names[-1], (np.clip(im, 0, 1) * 255 + 0.5).astype(np.uint8))
    (folder / "capture.json").write_text(json.dumps({
        "format": "ffls-capture", "version": 1, "images": names, "encoding": "linear",
        "camera": {"model": "orthographic"}, "hemisphere": "full"}))
    subprocess.run([sys.executable, "-m", "ffls", "lights", str(folder), "--no-progress", "--workers", "1"], check=True)
    cap = load_capture(folder)
    lights = load_lights(folder / "lights.json", cap)
    err = np.degrees(angle_between(lights.directions, to_world(L, cap.world_from_camera, points=False)))
    print(f"direction error: median {np.median(err):.2f} deg, max {err.max():.2f} deg")


if __name__ == "__main__":
    main(sys.argv[1])
