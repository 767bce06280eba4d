"""``ffls synth``: render a synthetic capture folder with the built-in scene (:mod:`ffls.synth.scene`)."""
from __future__ import annotations

import argparse
import sys
import time

NAME = "synth"
HELP = "render a synthetic capture (object, 4 white spheres, one light per image)"
DESCRIPTION = (
    "Render a synthetic Free-form Light Stage capture with the built-in NumPy ray tracer: a glossy "
    "and diffuse object on a grey table with four white diffuse spheres, one light per image, cast "
    "shadows and one bounce off the table. Writes the images, capture.json, lights.json (true "
    "directions) and truth.json."
)


def _positive_int(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, not {v}")
    return v


def _nonneg_float(text: str) -> float:
    v = float(text)
    if not v >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, not {text}")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ffls.commands.common import N_LIGHTS, SEED, SYNTH_RES, number, output_path

    p.add_argument("out_dir", metavar="OUT_DIR", type=output_path(folder_ok=True, file_ok=False), help="output capture folder (created if missing)")
    p.add_argument("--lights", type=N_LIGHTS, default=100, metavar="N", help="number of images (default 100)")
    p.add_argument("--resolution", type=SYNTH_RES, default=256, metavar="R", help="image width and height (default 256)")
    p.add_argument("--near", type=number(0.0, 1e6, lo_open=True), default=None, metavar="DIST",
                   help="point lights at DIST metres from the scene centre instead of distant lights")
    p.add_argument("--light-radius", type=number(0.0, 1e6), default=0.0, metavar="M",
                   help="radius of a spherical near light (soft shadows; default 0 = point)")
    p.add_argument("--ground-albedo", type=number(0.0, 1.0), default=0.3, metavar="A", help="table albedo (default 0.3; 0 = black velvet)")
    p.add_argument("--seed", type=SEED, default=0, metavar="S", help="seed of the light directions and noise (default 0)")
    p.add_argument("--srgb8", action="store_true", help="write 8-bit sRGB PNGs instead of half-float linear EXRs")
    p.add_argument("--noise", type=number(0.0, 1.0), default=0.0, metavar="SIGMA",
                   help="Gaussian noise, fraction of full scale, added before quantisation (default 0)")
    p.add_argument("--full-sphere", action="store_true", help="draw directions over the full sphere (hemisphere 'full')")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Render into a staging folder beside OUT_DIR and swap it in when complete.

    An interrupted or failed ``ffls synth`` leaves OUT_DIR as it was (the old capture, or
    nothing), never new images beside old ``lights.json`` (:func:`ffls.errors.atomic_folder`).
    An existing OUT_DIR that is not a capture folder (no ``capture.json``) is not replaced.
    """
    from pathlib import Path

    from ffls.errors import InputError, atomic_folder

    if args.near is not None and not args.near > 0:
        raise InputError(f"--near must be > 0, not {args.near}")
    if args.near is not None and args.light_radius >= args.near:
        raise InputError(f"--light-radius {args.light_radius:g} must be smaller than --near {args.near:g} "
                         "(the light would enclose the scene)")
    out = Path(args.out_dir)
    if out.is_dir() and any(out.iterdir()) and not (out / "capture.json").is_file():
        raise InputError("exists, is not empty and holds no capture.json: refusing to replace it", out)
    t = time.perf_counter()
    with atomic_folder(out) as stage:
        res = _synth(args, stage)
    print(f"wrote {len(res['images'])} images, capture.json, lights.json and truth.json to {out} "
          f"in {time.perf_counter() - t:.1f} s")
    return 0


def _synth(args: argparse.Namespace, folder) -> dict:
    from ffls.synth.scene import write_synthetic_capture

    return write_synthetic_capture(
        folder,
        n_lights=args.lights,
        resolution=args.resolution,
        light_model="distant" if args.near is None else "near",
        light_distance=2.0 if args.near is None else args.near,
        light_radius=args.light_radius,
        seed=args.seed,
        ground_albedo=args.ground_albedo,
        hemisphere="full" if args.full_sphere else "upper",
        encoding="srgb8" if args.srgb8 else "linear",
        noise=args.noise,
        progress=not args.quiet and sys.stderr.isatty(),  # a bar is for a terminal, not a log
    )
