"""A mirror-ball light map from a noisy 8-bit JPEG exposure bracket, end to end, by merge weighting.

A mirror ball (orthographic, reflectance 0.8, 150 px radius in a 400 px frame) under the bundled
``sunrise`` map is photographed as a camera would: 6 exposures, 1/64000 to 1 s (4 stops apart;
the shortest holds the sun), a gain of 2, vignetting ``1 - 0.25 r^2``, Poisson shot noise (2e4
electrons at full scale) and Gaussian read noise (0.002 of full scale), clipped, sRGB, 8-bit
JPEG q90 (OpenCV). The bracket is merged by each method of ``ffls.probes.bracket.MERGE_METHODS``,
written as EXR, unwrapped by ``ffls probe mirror`` (the ball located by a pixel hint) and used to
relight an ``ffls synth`` capture (100 lights, 128 px) with ``ffls relight``; the reference is
the same capture relit under the true map, and the noise-free radiance image is the floor.
Reported: the relit relative RMS error after the best scale (a bracket's radiance is in the
camera's units) and without it (the known gain 2).

Run: ``OMP_NUM_THREADS=1 python benchmarks/probe_bracket_mirror.py`` (about 20 s); writes
``benchmarks/results/probe_bracket_mirror.json``.
"""
from __future__ import annotations

import json
import tempfile
from pathlib import Path

import cv2
import numpy as np

from ffls.cli import main as ffls
from ffls.io.images import read_image, write_exr
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes.bracket import MERGE_METHODS, merge_exposures
from ffls.radiance.encoding import srgb_decode, srgb_encode
from ffls.synth.probe import render_mirror_ball
from ffls.synth.scene import write_synthetic_capture

TIMES = (1 / 64000, 1 / 4000, 1 / 500, 1 / 60, 1 / 8, 1.0)
SIZE, CENTRE, RADIUS, GAIN = 400, (205.3, 196.8), 150.0, 2.0


def relit_error(reference, test):
    a = read_image(reference).pixels[..., :3].astype(np.float64)
    b = read_image(test).pixels[..., :3].astype(np.float64)
    s = float((a * b).sum() / (b * b).sum())
    rms = lambda d: float(np.sqrt((d ** 2).mean() / (a ** 2).mean()))  # noqa: E731
    return rms(a - s * b), rms(a - b / GAIN)


def main():
    tmp = Path(tempfile.mkdtemp())
    img, _ = render_mirror_ball(builtin_lightmap("sunrise"), (SIZE, SIZE), "orthographic", center_px=CENTRE,
                                radius_px=RADIUS, supersample=4, reflectance=0.8)
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    radiance = img * GAIN * (1 - 0.25 * ((xx - SIZE / 2) ** 2 + (yy - SIZE / 2) ** 2) / (SIZE ** 2 / 2))[..., None]
    rng = np.random.default_rng(3)
    stored = []
    for t in TIMES:
        x = radiance * t
        x = x + rng.normal(0, 0.002, x.shape) + rng.poisson(np.clip(x, 0, 4) * 2e4) / 2e4 - np.clip(x, 0, 4)
        code = np.clip(np.round(srgb_encode(np.clip(x, 0, 1)) * 255), 0, 255).astype(np.uint8)
        ok, buf = cv2.imencode(".jpg", code[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
        stored.append(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1] / 255.0)
    write_synthetic_capture(tmp / "cap", n_lights=100, resolution=128, progress=False)
    ffls(["relight", str(tmp / "cap"), "--probe", "sunrise", "-o", str(tmp / "true.exr")])
    images = {"noise-free radiance": radiance.astype(np.float32)}
    for method in MERGE_METHODS:
        m = merge_exposures([srgb_decode(z) for z in stored], stored, TIMES, [1.0] * len(TIMES), method=method)
        images[f"merged, {method}"] = m.radiance
    rows = []
    print(f"{'probe image':34s} {'relit error (best scale)':>25s} {'(gain 2)':>9s}")
    for name, hdr in images.items():
        folder = tmp / name.replace(" ", "_").replace(",", "")
        folder.mkdir()
        write_exr(folder / "ball.exr", hdr)
        (folder / "probe.json").write_text(json.dumps(
            {"format": "ffls-probe", "version": 1, "images": ["ball.exr"], "camera": {"model": "orthographic"},
             "sphere": {"center_px": [205, 197], "radius_px": RADIUS, "material": "mirror", "reflectance": 0.8}}))
        ffls(["probe", "mirror", str(folder), "-o", str(folder / "map.exr")])
        ffls(["relight", str(tmp / "cap"), "--probe", str(folder / "map.exr"), "-o", str(folder / "relit.exr")])
        best, plain = relit_error(tmp / "true.exr", folder / "relit.exr")
        print(f"{name:34s} {100 * best:24.2f}% {100 * plain:8.2f}%")
        rows.append({"probe_image": name, "relit_error_best_scale": best, "relit_error_gain": plain})
    out = Path(__file__).parent / "results" / "probe_bracket_mirror.json"
    out.write_text(json.dumps({"benchmark": "probe_bracket_mirror", "times_s": TIMES, "results": rows}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
