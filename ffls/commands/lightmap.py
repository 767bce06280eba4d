"""``ffls lightmap``: inspect, convert and make light maps (thin layer over :mod:`ffls.lightmaps.lightmap`)."""
from __future__ import annotations

import warnings
from pathlib import Path

NAME = "lightmap"
#: The attribute that names the chosen subcommand (``ffls lightmap ACTION``).
SUBCOMMAND_DEST = "action"
HELP = "inspect, convert or make light maps (info | convert | make)"
DESCRIPTION = (
    "info MAP: size, layout, statistics and integrated irradiance of a light map (a file or a "
    "built-in name). convert IN OUT: read .exr/.hdr, write .exr/.hdr (cube maps as a horizontal "
    "cross). make sky|paper OUT: write a procedural map."
)


def add_arguments(p):
    from ffls.commands.common import MAP_HEIGHT, input_path, output_path

    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    info = sub.add_parser("info", help="print size, layout, min/max/mean and irradiance")
    info.add_argument("map", type=input_path, help="light-map file (.exr/.hdr) or built-in name (courtyard, sky, ...)")
    info.add_argument("--layout", choices=("latlong", "angular", "mirrorball", "cube"), default=None,
                      help="layout of the input (default: from the aspect ratio; square = angular)")
    conv = sub.add_parser("convert", help="convert between .exr and .hdr (and optionally to lat-long)")
    conv.add_argument("input", type=input_path)
    conv.add_argument("output", type=output_path((".exr", ".hdr", ".pic")), help=".exr or .hdr")
    conv.add_argument("--layout", choices=("latlong", "angular", "mirrorball", "cube"), default=None,
                      help="layout of the input (default: from the aspect ratio; square = angular)")
    conv.add_argument("--to-latlong", type=MAP_HEIGHT, metavar="HEIGHT", default=None,
                      help="resample to a lat-long map of this height (nearest texel)")
    conv.add_argument("--half", action="store_true", help="write half-float EXR")
    make = sub.add_parser("make", help="write a procedural light map")
    make.add_argument("kind", choices=("sky", "paper"))
    make.add_argument("output", type=output_path((".exr", ".hdr", ".pic")), help=".exr or .hdr")
    make.add_argument("--height", type=MAP_HEIGHT, default=256, help="map height, 4 to 16384 (width is twice it)")
    make.add_argument("--half", action="store_true", help="write half-float EXR")


def _load(spec: str, layout):
    from ffls.lightmaps.lightmap import LightMapWarning, lightmap_from_spec, load_lightmap

    if not Path(spec).exists() and Path(spec).suffix == "":  # a built-in name (--layout refused, as relight does)
        return lightmap_from_spec(spec, layout=layout)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LightMapWarning)  # the count is kept in lm.clamped_negatives
        return load_lightmap(spec, layout=layout)


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def _colour(lm) -> str:
    """The map's colour space: its conversion to the working space, or that its values are taken as they are."""
    return lm.colour_note or "linear Rec.709 (D65), the working space (no other colour space stated)"


def run(args) -> int:
    from ffls.lightmaps.lightmap import paper_map, save_lightmap, sky_sun_map

    if args.action == "info":
        lm = _load(args.map, args.layout)
        st = lm.stats()
        if lm.layout == "cube":
            size = f"6 faces of {lm.res}x{lm.res}"
        else:
            size = f"{lm.data.shape[1]}x{lm.data.shape[0]} (width x height)"
        print(f"{lm.source}: {lm.layout}, {size}")
        print(f"  min  {_fmt(st['min'])}")
        print(f"  max  {_fmt(st['max'])}")
        print(f"  mean {_fmt(st['mean'])}  (solid-angle weighted)")
        print(f"  integral of L dw, upper hemisphere {_fmt(lm.total_power('upper'))}, full sphere {_fmt(lm.total_power('full'))}")
        print(f"  irradiance on an upward surface    {_fmt(lm.irradiance((0, 0, 1)))}")
        print(f"  negative pixels clamped to 0: {lm.clamped_negatives}")
        print(f"  colour: {_colour(lm)}")
        return 0
    if args.action == "convert":
        lm = _load(args.input, args.layout)
        colour = _colour(lm)  # (the map as read: resampling keeps no note)
        if args.to_latlong is not None:
            lm = lm.to_latlong(args.to_latlong)
        save_lightmap(lm, args.output, half=args.half)
        print(f"wrote {args.output} ({lm.layout}, {lm.clamped_negatives} negative pixels clamped; colour: "
              f"{colour})")
        return 0
    lm = sky_sun_map(args.height) if args.kind == "sky" else paper_map(args.height)
    save_lightmap(lm, args.output, half=args.half)
    print(f"wrote {args.output} ({args.kind}, {lm.data.shape[1]}x{lm.data.shape[0]} lat-long)")
    return 0
