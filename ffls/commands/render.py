"""``ffls render``: relight a capture on the GPU (ffls.gpu.Engine); stills, or a turntable video.

The GPU path is the default. Where no OpenGL 4.3 context can be created the command stops with
one line saying so and suggesting ``--cpu`` (it never falls back silently: the two paths differ
in speed by orders of magnitude and a CI job should notice). ``--cpu`` runs the reference path,
:class:`ffls.relight.cpu.CpuRelighter` with the same interface as the engine
(:func:`ffls.weights.voronoi.integrate_weights` + :func:`ffls.relight.cpu.relight_reference`, float64; with
``--rank K`` the compressed basis' exact float64 algebra).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ffls.commands.common import add_capture_arguments

NAME = "render"
HELP = "relight a capture on the GPU: an EXR/PNG still, or a light-map turntable (mp4 or PNG folder)"
DESCRIPTION = (
    "Relight a capture under an HDR light map with the GPU engine (pass 1: per-cell light-map "
    "integration; pass 2: weighted sum of the basis images; tone mapping). .exr output is linear "
    "float, .png tone-mapped sRGB. --turntable N rotates the map 360 degrees about +Z in N frames."
)

STILL_SUFFIXES = (".exr", ".png")


def add_arguments(p):
    add_capture_arguments(p)
    rot = p.add_mutually_exclusive_group()
    rot.add_argument("--rotate-z", type=float, default=None, metavar="DEG",
                     help="rotate the light map about +Z by DEG degrees (counter-clockwise from above)")
    rot.add_argument("--rotate", default=None, metavar="YAW,PITCH,ROLL",
                     help="rotate the light map by yaw (about +Z), pitch (+Y), roll (+X), degrees")
    p.add_argument("--exposure", type=float, default=0.0, metavar="EV", help="exposure in stops (PNG/video)")
    p.add_argument("--tonemap", default="srgb", choices=("srgb", "reinhard", "aces"), help="tone curve (PNG/video)")
    p.add_argument("--rank", type=int, default=None, metavar="K",
                   help="use a compressed basis of K eigen-images (computed once, saved in the capture folder)")
    p.add_argument("--dtype", default="f16", choices=("f16", "f32"), help="GPU storage of the basis")
    p.add_argument("--cells-res", type=int, default=256, help="cell-texture resolution")
    p.add_argument("--turntable", type=int, default=None, metavar="N",
                   help="write N frames over 360 degrees about +Z: -o OUT.mp4 or a folder of PNGs")
    p.add_argument("--fps", type=float, default=30.0, help="frames per second of the turntable video")
    p.add_argument("--cpu", action="store_true", help="use the CPU reference path instead of the GPU")
    p.add_argument("-o", "--out", required=True, help="output: .exr/.png (still), .mp4 or DIR/ (turntable)")


def parse_rotation(args) -> np.ndarray:
    """The light-map rotation (3, 3) from ``--rotate-z`` or ``--rotate``."""
    from ffls.conventions import rotation_ypr, rotation_z
    from ffls.errors import InputError

    if args.rotate is not None:
        try:
            yaw, pitch, roll = (float(v) for v in args.rotate.split(","))
        except ValueError:
            raise InputError(f"--rotate wants YAW,PITCH,ROLL in degrees, not {args.rotate!r}") from None
        return rotation_ypr(yaw, pitch, roll)
    return rotation_z(args.rotate_z or 0.0)


def _make_renderer(args, capture, lights):
    if args.cpu:
        from ffls.relight.cpu import CpuRelighter

        return CpuRelighter.from_capture(capture, lights, precision="f64", rank=args.rank,
                                         cell_res=args.cells_res), None
    from ffls.errors import GLUnavailable
    from ffls.gpu.context import create_headless_context
    from ffls.gpu.engine import Engine

    try:
        ctx = create_headless_context()
    except GLUnavailable as e:
        raise GLUnavailable(f"no GPU path ({e.message}); rerun with --cpu for the CPU reference path") from None
    eng = Engine.from_capture(ctx, capture, lights, dtype=args.dtype, rank=args.rank, cell_res=args.cells_res)
    return eng, ctx


def _write_still(out: Path, r, args):
    from ffls.io.images import write_exr, write_png

    if out.suffix.lower() == ".exr":
        write_exr(out, r.read_hdr())
    else:
        write_png(out, r.read_display())


def _write_turntable(out: Path, r, R0, args):
    from tqdm import tqdm

    from ffls.conventions import rotation_z
    from ffls.errors import InputError
    from ffls.io.video import FrameWriter

    n = args.turntable
    if n < 1:
        raise InputError(f"--turntable needs N >= 1, not {n}")
    frames = ((k, rotation_z(360.0 * k / n) @ R0) for k in range(n))
    with FrameWriter(out, fps=args.fps) as sink:
        for _, R in tqdm(frames, total=n, desc="ffls render", unit="frame"):
            r.set_rotation(R)
            r.render(args.exposure, args.tonemap)
            sink.write(r.read_display())
    return sink.describe()


def run(args) -> int:
    from ffls.io.capture import load_capture_and_lights
    from ffls.errors import InputError

    out = Path(args.out)
    if args.turntable is None and out.suffix.lower() not in STILL_SUFFIXES:
        raise InputError(f"output must end with {' or '.join(STILL_SUFFIXES)} (or use --turntable N)", out)
    R0 = parse_rotation(args)
    capture, lights = load_capture_and_lights(args.capture, args.lights)
    from ffls.lightmaps.lightmap import lightmap_from_spec

    lightmap = lightmap_from_spec(args.probe, args.layout)
    r, ctx = _make_renderer(args, capture, lights)
    try:
        r.set_lightmap(lightmap)
        if args.turntable is not None:
            what = _write_turntable(out, r, R0, args)
        else:
            r.set_rotation(R0)
            r.render(args.exposure, args.tonemap)
            _write_still(out, r, args)
            what = str(out)
        path = "cpu reference" if args.cpu else f"gpu {getattr(r, 'basis_info', {}).get('dtype', '')}"
        print(f"ffls render: {what} ({path}{'' if args.rank is None else f', rank {args.rank}'})")
    finally:
        r.release()
        if ctx is not None:
            ctx.release()
    return 0
