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

from ffls.commands.common import (CELLS_RES, FPS, FRAMES, RANK, add_capture_arguments, add_light_argument,
                                  add_mask_argument, add_quality_arguments, add_rotation_arguments,
                                  add_scale_arguments, add_weighting_argument, check_display_flags, check_gpu_pass1,
                                  check_mask_size, check_output_kind,
                                  exposure_arg, flush_notes, learnt_kernel, light_vector, load_relight_inputs,
                                  open_streamed_from_args, output_path, quality_from_args, resolve_quality,
                                  negative_pixels_note, print_notes, rotation_from_args, write_output,
                                  compressed_note)

NAME = "render"
HELP = "relight a capture on the GPU: an EXR/PNG still, or a light-map turntable (mp4 or PNG folder)"
DESCRIPTION = (
    "Relight a capture under an HDR light map with the GPU engine (pass 1: per-cell light-map "
    "integration; pass 2: weighted sum of the basis images; tone mapping). .exr output is linear "
    "float, .png tone-mapped sRGB. --turntable N rotates the map 360 degrees about +Z in N frames. "
    "--light AZ,EL relights with one directional light instead of a map (RTI style), interpolated "
    "with --weighting."
)



def add_arguments(p):
    add_capture_arguments(p, probe_required=False)
    add_light_argument(p)
    add_weighting_argument(p)
    add_rotation_arguments(p)
    p.add_argument("--exposure", type=exposure_arg, default=None, metavar="EV|auto",
                   help="exposure in stops of a PNG or video (default 0; refused with an .exr still, which is "
                        "linear); auto meters the object (the --mask when given)")
    add_mask_argument(p)
    p.add_argument("--tonemap", default=None, choices=("srgb", "reinhard", "aces"),
                   help="tone curve of a PNG or video (default srgb; refused with an .exr still)")
    p.add_argument("--rank", type=RANK, default=None, metavar="K",
                   help="use a compressed basis of K eigen-images, 1 <= K <= n-1 for n lights (computed once, "
                        "saved in the capture folder)")
    p.add_argument("--cells-res", type=CELLS_RES, default=None,
                   help="resolution of pass 1's texture, 16 to 4096: the cell texture of voronoi (default 256; too "
                        "coarse for the lights is refused) or a smooth scheme's weight texture (default 512)")
    p.add_argument("--turntable", type=FRAMES, default=None, metavar="N",
                   help="write N frames over 360 degrees about +Z: -o OUT.mp4 or a folder of PNGs")
    p.add_argument("--fps", type=FPS, default=None,
                   help="frames per second of the --turntable video, 0.1 to 1000 (default 30; refused for a still)")
    p.add_argument("--cpu", action="store_true", help="use the CPU reference path instead of the GPU")
    add_quality_arguments(p, precision_default="float16")
    add_scale_arguments(p)
    p.add_argument("-o", "--out", required=True, type=output_path((".exr", ".png", ".mp4"), folder_ok=True),
                   help="output: .exr/.png (still), .mp4 or DIR/ (turntable)")


def parse_rotation(args) -> np.ndarray:
    """The light-map rotation (3, 3) from ``--rotate-z`` or ``--rotate`` (:func:`ffls.commands.common.rotation_from_args`)."""
    return rotation_from_args(args)


def _make_renderer(args, capture, lights, lightmap=None, R0=None):
    """The relighter (GPU engine, or with ``--cpu`` the float64 reference) and its context, under the
    configuration of the quality flags (``--quality auto`` measures it here, on the same path); a
    capture that does not fit ``--memory`` or the GPU is relit tile by tile from its store."""
    from ffls.gpu.basis import DEFAULT_BUDGET

    copies = 2 if args.turntable is None and Path(args.out).suffix.lower() == ".exr" else 4
    streamed = open_streamed_from_args(args, capture, lights, NAME, copies,
                                       gpu_budget=None if args.cpu else DEFAULT_BUDGET)
    if streamed is not None:
        if args.cpu:
            return streamed, None
        return _tiled_gpu(args, streamed, lightmap)
    if args.cpu:
        from ffls.relight.cpu import CpuRelighter

        q = resolve_quality(args, capture, lights, lightmap, R0, command=NAME)
        return CpuRelighter.from_capture(capture, lights, quality=q, precision="f64"), None
    from ffls.errors import GLUnavailable, InputError
    from ffls.gpu.context import create_headless_context
    from ffls.gpu.engine import Engine, gpu_frame_ms

    try:
        ctx = create_headless_context()
    except GLUnavailable as e:
        raise GLUnavailable(f"no GPU path ({e.message}); rerun with --cpu for the CPU reference path") from None
    try:
        def timer(q, basis, directions):
            try:
                check_gpu_pass1(ctx, lightmap, q)
            except InputError:  # a candidate whose pass 1 cannot run here: never chosen
                return float("inf")
            return gpu_frame_ms(ctx, basis, directions, lightmap, q, capture.hemisphere)

        q = resolve_quality(args, capture, lights, lightmap, R0, timer=timer, command=NAME)
        check_gpu_pass1(ctx, lightmap, q)
        eng = Engine.from_capture(ctx, capture, lights, quality=q)
    except BaseException:
        ctx.release()
        raise
    return eng, ctx


def _tiled_gpu(args, streamed, lightmap=None):
    """The GPU engine tile by tile over the store (:class:`ffls.gpu.tiled.TiledEngine`)."""
    from ffls.errors import GLUnavailable
    from ffls.gpu.context import create_headless_context
    from ffls.gpu.tiled import TiledEngine

    try:
        ctx = create_headless_context()
    except GLUnavailable as e:
        raise GLUnavailable(f"no GPU path ({e.message}); rerun with --cpu for the CPU reference path") from None
    try:
        from ffls.relight.storage import parse_storage

        check_gpu_pass1(ctx, lightmap, quality_from_args(args))
        return TiledEngine(ctx, streamed, dtype=parse_storage(args.precision or "float16"),
                           cell_res=args.cells_res or 256), ctx
    except BaseException:
        ctx.release()
        raise


def _auto_exposure(r, args, mask) -> float:
    """``--exposure``: the number, or (``auto``) the metering of the current render's object."""
    if args.exposure != "auto":
        return args.exposure
    from ffls.display.tonemap import auto_exposure

    r.render(0.0, args.tonemap)
    hdr = r.read_hdr()
    check_mask_size(mask, hdr.shape)
    return auto_exposure(hdr, mask=mask)


def single_light_weights(r, args, R) -> np.ndarray:
    """Per-light RGB weights ``(n, 3)`` of ``--light AZ,EL`` rotated by ``R``, under ``--weighting``
    (``kriging`` with the kernel the relighter learnt).

    A light outside the capture's hemisphere gives no light (all zero).
    """
    from ffls.conventions import in_domain
    from ffls.weights.weighting import light_weights

    d = R @ light_vector(args.light)
    if not in_domain(d[None, :], r.hemisphere)[0]:
        return np.zeros((r.n_lights, 3))
    kernel = getattr(r, "kernel", None)  # kriging: the kernel the relighter learnt from its photos
    options = {} if kernel is None else kernel.options_for(args.weighting, {})
    w = light_weights(r.directions, d, args.weighting, r.hemisphere, **options)
    return np.repeat(w[:, None], 3, axis=1)


def light_summary(light, R) -> str:
    """``light az A el E`` of ``--light AZ,EL`` as relit: rotated by ``R`` (``--rotate``/``--rotate-z``
    turn the light as they turn a map; docs/weighting.md), with the given value when they moved it."""
    import math

    d = R @ light_vector(light)
    az = math.degrees(math.atan2(d[1], d[0])) if math.hypot(d[0], d[1]) > 1e-12 else 0.0
    el = math.degrees(math.asin(max(-1.0, min(1.0, float(d[2])))))
    text = f"light az {az:.4g} el {el:.4g}"
    if not np.allclose(R, np.eye(3)):
        text += f" (--light {light[0]:g},{light[1]:g} turned by --rotate/--rotate-z)"
    return text


def _apply(r, args, R) -> None:
    """Set the frame's rotation (light map) or its single light's weights (``--light``)."""
    if args.light is None:
        r.set_rotation(R)
    else:
        r.set_weights(single_light_weights(r, args, R))


def _write_still(out: Path, r, args, mask=None):
    hdr = r.read_hdr()
    write_output(out, hdr, None if out.suffix.lower() == ".exr" else r.read_display(), mask)
    print_notes(NAME, negative_pixels_note(hdr, out))


def _write_turntable(out: Path, r, R0, args, exposure: float = 0.0):
    from tqdm import tqdm

    from ffls.conventions import rotation_z
    from ffls.errors import InputError
    from ffls.io.video import FrameWriter

    n = args.turntable
    if n < 1:
        raise InputError(f"--turntable needs N >= 1, not {n}")
    frames = ((k, rotation_z(360.0 * k / n) @ R0) for k in range(n))
    with FrameWriter(out, fps=args.fps) as sink:
        for _, R in tqdm(frames, total=n, desc="ffls render", unit="frame", disable=None):
            _apply(r, args, R)
            r.render(exposure, args.tonemap)
            sink.write(r.read_display())
    return sink.describe()


def run(args) -> int:
    from ffls.errors import InputError

    out = Path(args.out)
    check_output_kind(args, out)
    check_display_flags(args, out)
    args.exposure = 0.0 if args.exposure is None else args.exposure
    args.tonemap, args.fps = args.tonemap or "srgb", args.fps or 30.0
    R0 = rotation_from_args(args)
    if (args.light is None) == (args.probe is None):
        raise InputError("give either --probe MAP or --light AZ,EL" if args.light is None
                         else "--probe and --light exclude each other: give one")
    if args.turntable is not None and args.mask is not None:
        # a video has no alpha channel (nor, for now, the turntable's PNG frames): the mask can only meter
        if args.exposure != "auto":
            raise InputError("--mask: a --turntable's frames have no alpha channel, so the mask would only meter "
                             "--exposure auto; give --exposure auto, or leave --mask out (a still .png or .exr "
                             "gets the alpha)")
        print_notes(NAME, "--mask: the turntable's frames have no alpha channel; the mask meters --exposure auto")
    capture, lights, lightmap, mask = load_relight_inputs(args, NAME, lightmap=args.light is None)
    if args.light is not None:
        from ffls.conventions import in_domain

        if not in_domain((R0 @ light_vector(args.light))[None, :], capture.hemisphere)[0]:
            raise InputError(f"--light {args.light[0]:g},{args.light[1]:g} is outside the capture's hemisphere "
                             "(no photo was lit from there)")
    if args.light is not None and args.quality == "auto":
        raise InputError("--quality auto measures a light map: give --probe MAP, not --light")
    r, ctx = _make_renderer(args, capture, lights, lightmap, R0)
    print_notes(NAME, compressed_note(r))
    if args.turntable is not None:
        flush_notes()  # a long job: the informational lines now (a still's wait for its success)
    try:
        if lightmap is not None:
            r.set_lightmap(lightmap)
        _apply(r, args, R0)
        exposure = _auto_exposure(r, args, mask)  # a turntable keeps the first frame's
        if args.turntable is not None:
            what = _write_turntable(out, r, R0, args, exposure)
        else:
            r.render(exposure, args.tonemap)
            _write_still(out, r, args, mask)
            what = str(out)
        info = getattr(r, "basis_info", {})
        path = "cpu reference" if args.cpu else f"gpu {info.get('dtype', '')}"
        rank = info.get("rank") if not args.cpu else getattr(getattr(r, "compressed", None), "rank", None)
        what_light = "" if args.light is None else f"{light_summary(args.light, R0)}, "
        if learnt_kernel(r):
            print(f"ffls render: {learnt_kernel(r)}")
        print(f"ffls render: {what} ({path}, {r.n_lights} lights{'' if rank is None else f', rank {rank}'}, "
              f"{what_light}{getattr(r, 'weighting', args.weighting)} weighting)")
    finally:
        r.release()
        if ctx is not None:
            ctx.release()
    return 0
