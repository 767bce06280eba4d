"""``ffls relight``: relight a capture under a light map (CPU, Masselus et al. 2002 section 6)."""
from __future__ import annotations

from pathlib import Path

from ffls.commands.common import (CELLS_RES_OR_EXACT, add_capture_arguments, add_mask_argument,
                                  add_quality_arguments, add_rotation_arguments, add_scale_arguments,
                                  add_weighting_argument, check_display_flags, check_mask_size, exposure_arg,
                                  compressed_note, learnt_kernel, load_relight_inputs,
                                  open_streamed_from_args, output_path, resolve_quality, rotation_from_args,
                                  negative_pixels_note, print_notes, write_output)

NAME = "relight"
HELP = "relight a capture under an HDR light map and write an EXR (linear) or PNG (tone-mapped)"
DESCRIPTION = (
    "Integrate the light map over the angular Voronoi cells of the capture's light directions "
    "and write the weighted sum of the basis images: .exr is linear float, .png is tone-mapped sRGB."
)

OUTPUT_SUFFIXES = (".exr", ".png")


def add_arguments(p):
    add_capture_arguments(p)
    add_rotation_arguments(p)
    p.add_argument("--exposure", type=exposure_arg, default=None, metavar="EV|auto",
                   help="exposure in stops of PNG output (default 0; refused with .exr output, which is linear); "
                        "auto meters the object (the --mask when given)")
    add_mask_argument(p)
    p.add_argument("--tonemap", default=None, choices=("srgb", "reinhard", "aces"),
                   help="tone curve of PNG output (default srgb; refused with .exr output, which is linear)")
    p.add_argument("--cells-res", type=CELLS_RES_OR_EXACT, default=256,
                   help="cell-texture resolution, 16 to 4096, or 0 for the exact k-d tree (default 256)")
    add_weighting_argument(p)
    add_quality_arguments(p, precision_default=None, rank=True)
    add_scale_arguments(p)
    p.add_argument("-o", "--out", required=True, type=output_path(OUTPUT_SUFFIXES), help="output image, .exr or .png")


def run(args) -> int:
    from ffls.errors import InputError
    from ffls.relight.cpu import CpuRelighter
    from ffls.display.tonemap import auto_exposure, to_uint8, tonemap

    out = Path(args.out)
    if out.suffix.lower() not in OUTPUT_SUFFIXES:
        raise InputError(f"output must end with {' or '.join(OUTPUT_SUFFIXES)}", out)
    check_display_flags(args, out)
    args.exposure = 0.0 if args.exposure is None else args.exposure
    args.tonemap = args.tonemap or "srgb"
    capture, lights, lightmap, mask = load_relight_inputs(args, NAME)
    R = rotation_from_args(args)
    copies = 2 if out.suffix.lower() == ".exr" and mask is None else 4  # the result, the writer's copy, the tone map's
    r = open_streamed_from_args(args, capture, lights, NAME, copies)
    weighting = args.weighting  # the scheme used (--quality auto may choose another)
    if r is not None:  # tile by tile from the store
        r.set_lightmap(lightmap)
        r.set_rotation(R)
        r.render()
        image, w = r.hdr, r.last_weights
        r.release()
    else:
        q = resolve_quality(args, capture, lights, lightmap, R, command=NAME)
        weighting = q.weighting
        storage = None if args.precision is None and args.quality != "auto" else q.precision
        r = CpuRelighter.from_capture(capture, lights, quality=q, storage=storage, cell_res=args.cells_res or None,
                                      save_compressed=True,  # --rank K: kept in the capture, as render and view do
                                      cell_k=4, cell_max_res=1024)
        print_notes(NAME, compressed_note(r))
        r.set_lightmap(lightmap)
        r.set_rotation(R)
        r.render()
        image, w = r.hdr, r.last_weights
    check_mask_size(mask, image.shape)
    display = None
    if out.suffix.lower() != ".exr":
        exposure = auto_exposure(image, mask=mask) if args.exposure == "auto" else args.exposure
        display = to_uint8(tonemap(image, exposure=exposure, method=args.tonemap))
    write_output(out, image, display, mask)
    print_notes(NAME, negative_pixels_note(image, out))
    kept = w.total_power.sum() - w.dropped_power.sum()
    frac = kept / w.total_power.sum() if w.total_power.sum() > 0 else 1.0
    if learnt_kernel(r):
        print(f"ffls relight: {learnt_kernel(r)}")
    print(f"ffls relight: {out} ({image.shape[1]}x{image.shape[0]}, {w.weights.shape[0]} lights, "
          f"{w.dropped_texels} light-map texels dropped (outside the capture's hemisphere, {capture.hemisphere}), "
          f"{100 * frac:.1f}% of the power used, {weighting} weighting)")
    return 0
