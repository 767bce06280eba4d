"""``ffls demo``: the built-in default job."""
from __future__ import annotations

import argparse
import sys

from ffls.commands import find_command

NAME = "demo"
HELP = "synthesise a capture and relight it under the built-in light maps (the default job)"
DESCRIPTION = (
    "Synthesise a capture of the built-in scene, relight it under the built-in light maps at "
    "several rotations, write EXR and PNG renders and a contact sheet, and print where they went."
)


def _distinct_maps(text) -> tuple:
    """argparse type: built-in light-map names, none repeated (a repeat would write one render twice)."""
    from ffls.commands.common import builtin_map_names

    names = builtin_map_names(text)
    repeated = sorted({m for m in names if names.count(m) > 1})
    if repeated:
        raise argparse.ArgumentTypeError(f"light map {repeated[0]!r} is given more than once in {text!r}")
    return names


def _distinct_rotations(text) -> tuple:
    """argparse type: rotations in degrees, none the same as another modulo 360 (one render each)."""
    from ffls.commands.common import float_list

    rots = float_list(-1e6, 1e6, 1, 360, "degrees")(text)
    seen = {}
    for r in rots:
        key = round(r % 360.0, 9) % 360.0
        if key in seen:
            raise argparse.ArgumentTypeError(f"rotations {seen[key]:g} and {r:g} are the same (modulo 360 degrees)"
                                             f" in {text!r}: each would write the same render")
        seen[key] = r
    return rots


def add_arguments(p):
    from ffls.commands.common import N_LIGHTS, SEED, SYNTH_RES, output_path

    p.add_argument("-o", "--out", default="ffls-demo", type=output_path(folder_ok=True, file_ok=False),

                   help="output folder (default: ./ffls-demo)")
    p.add_argument("--lights", type=N_LIGHTS, default=160, help="number of lights in the synthetic capture")
    p.add_argument("--resolution", type=SYNTH_RES, default=256, help="image size in pixels (square)")
    p.add_argument("--maps", default=None, type=_distinct_maps, help="comma-separated built-in light maps")
    p.add_argument("--rotations", default=(0.0, 90.0, 180.0, 270.0), type=_distinct_rotations,
                   help="comma-separated rotations about +Z, degrees")
    p.add_argument("--cpu", action="store_true", help="force the CPU reference relighter")
    p.add_argument("--seed", type=SEED, default=0)
    p.add_argument("--no-view", action="store_true",
                   help="do not open the viewer on the capture afterwards (it opens only when a display exists)")


def run(args) -> int:
    from ffls.demo import DEFAULT_MAPS, run_demo

    maps = args.maps or DEFAULT_MAPS
    rotations = tuple(args.rotations)
    res = run_demo(args.out, n_lights=args.lights, resolution=args.resolution, maps=maps,
                   rotations=rotations, use_gpu=False if args.cpu else "auto", seed=args.seed,
                   progress=sys.stderr.isatty())
    if res.note:
        print(f"ffls demo: {res.note}")
    print(f"ffls demo: relit with {res.backend}")
    print(f"  capture:       {res.capture_dir}  ({args.lights} images, {res.seconds['synth']:.1f} s)")
    print(f"  renders:       {res.out_dir / 'renders'}  ({len(res.images)} PNG + EXR, {res.seconds['relight']:.1f} s)")
    print(f"  contact sheet: {res.contact_sheet}")
    if not args.no_view:
        _open_viewer(res.capture_dir)
    return 0


def _open_viewer(capture_dir) -> None:
    """Open the viewer on the demo capture when one is installed and a display exists (else say how).

    The viewer is found through the ``view`` command it registers (:func:`ffls.commands.find_command`);
    its ``show_capture`` opens the window, or says why not.
    """
    view = find_command("view")
    if view is None or not hasattr(view, "show_capture"):  # the viewer is not installed
        return
    why = view.show_capture(capture_dir)
    if why:
        print(f"  viewer:        {why}")
