"""Speed of ``ffls synth`` under each condition of real photographs (docs/synth.md, "Conditions").

Usage: python benchmarks/synth_conditions.py [--resolution 768] [--photos 4] [--only NAME ...] [--out result.json]

Each condition is an exact ``ffls synth`` command line (the table prints it), parsed by the real
parser and run through the same library calls as the command (``ffls.commands.synth.scene_of``,
``photo_settings``, ``ffls.synth.scene.write_synthetic_capture``). For each it reports the
G-buffer build (once per scene and resolution: primary hits, bounce matrix, mirror rays) and the
median time per photograph (render, camera effects, file write) over ``--photos`` photographs.
The reference in the same run is NumPy's copy bandwidth on this machine.
"""
from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import numpy as np

from ffls.cli import build_parser
from ffls.commands.synth import photo_settings, scene_of
from ffls.synth import scene as synth

from common import numpy_copy_bandwidth, write_json  # benchmarks/common.py

#: name -> ``ffls synth OUT`` flags.
CONDITIONS = {
    "default (4 white, EXR)": [],
    "sRGB 8-bit, stated": ["--format", "png8", "--encoding", "srgb", "--exposure", "3"],
    "linear 8-bit, unstated": ["--format", "png8", "--encoding", "linear", "--unstated-encoding", "--exposure", "3"],
    "gamma 2.2 8-bit, unstated": ["--format", "png8", "--encoding", "gamma2.2", "--unstated-encoding", "--exposure", "3"],
    "sRGB 16-bit TIFF": ["--format", "tiff16", "--exposure", "3"],
    "JPEG q85": ["--format", "jpeg", "--jpeg-quality", "85", "--exposure", "3"],
    "noise + vignetting": ["--format", "png8", "--exposure", "3", "--shot-noise", "1e-4", "--read-noise", "0.002",
                           "--vignetting", "cos4"],
    "one grey sphere": ["--spheres", "1", "--sphere-material", "grey", "--format", "png8", "--exposure", "3"],
    "one mirror ball": ["--spheres", "1", "--sphere-material", "mirror", "--format", "png8", "--exposure", "3"],
    "one glossy black ball": ["--spheres", "1", "--sphere-material", "glossy_black", "--format", "png8",
                              "--exposure", "3"],
    "8 mixed spheres": ["--spheres", "8", "--sphere-material", "mixed"],
    "black background": ["--background", "black"],
    "white background": ["--background", "white"],
    "textured background": ["--background", "textured"],
    "long lens (10 m, 4.8 deg)": ["--lens", "long"],
    "orthographic": ["--lens", "orthographic"],
    "calibration shot (no object)": ["--no-object", "--spheres", "2", "--sphere-material", "grey,mirror"],
    "near area light, mirror balls": ["--near", "2", "--light-radius", "0.05", "--sphere-material", "mixed"],
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=768)
    ap.add_argument("--photos", type=int, default=4)
    ap.add_argument("--only", nargs="*", default=None, help="names (substrings) of the conditions to run")
    ap.add_argument("--out", help="write the table as JSON here")
    a = ap.parse_args()
    parser = build_parser()
    bw = numpy_copy_bandwidth(64 << 20, 5, np.float64)
    rows = []
    print(f"{'condition':<32} {'gbuffer':>8} {'per photo':>10}   command")
    for name, flags in CONDITIONS.items():
        if a.only and not any(o in name for o in a.only):
            continue
        with tempfile.TemporaryDirectory() as tmp:
            argv = ["synth", tmp, "--resolution", str(a.resolution), "--lights", str(a.photos), "--quiet", *flags]
            args = parser.parse_args(argv)
            scene, photo = scene_of(args), photo_settings(args)
            synth.gbuffer.cache_clear()
            t0 = time.perf_counter()
            synth.gbuffer(scene, a.resolution)
            t_gb = time.perf_counter() - t0
            per = []
            dirs = synth.stratified_directions(a.photos, "upper", 0)
            for i in range(a.photos):
                t0 = time.perf_counter()
                synth.write_synthetic_capture(
                    os.path.join(tmp, f"p{i}"), directions=dirs[i:i + 1], resolution=a.resolution, scene=scene,
                    photo=photo, progress=False, light_model="distant" if args.near is None else "near",
                    light_distance=2.0 if args.near is None else args.near, light_radius=args.light_radius or 0.0)
                per.append(time.perf_counter() - t0)
        cmd = "ffls synth OUT --resolution %d %s" % (a.resolution, " ".join(flags))
        rows.append({"condition": name, "command": cmd.strip(), "gbuffer_s": t_gb,
                     "per_photo_s": float(np.median(per)), "resolution": a.resolution})
        print(f"{name:<32} {t_gb:>7.2f}s {np.median(per):>9.2f}s   {cmd}", flush=True)
    info = {"cpu_count": os.cpu_count(), "machine": platform.machine(), "numpy": np.__version__,
            "load_average": os.getloadavg(), "copy_bandwidth_GBps": bw / 1e9, "rows": rows}
    print(f"cpus {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}, copy bandwidth {bw / 1e9:.1f} GB/s")
    if a.out:
        write_json(a.out, info)


if __name__ == "__main__":
    main()
