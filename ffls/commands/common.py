"""Arguments shared by the subcommands that relight a capture (relight, render, view).

One definition of each flag, used by every command that takes it:

* ``CAPTURE``, ``--lights`` (``lights.json`` or ``.lp``, possibly another capture's), ``--lights-map``,
  ``--probe``, ``--layout``: :func:`add_capture_arguments` (``view`` adds its own ``--probe``);
* ``--rotate YAW,PITCH,ROLL`` / ``--rotate-z DEG``: :func:`add_rotation_arguments`,
  :func:`rotation_from_args`;
* ``--exposure EV|auto``: :func:`exposure_arg`;
* ``--rank K``: checked against the number of lights, once it is known, by :func:`check_rank_arg`.
"""
from __future__ import annotations

import argparse
import math
import sys

__all__ = [
    "add_capture_arguments",
    "add_lights_arguments",
    "add_rotation_arguments",
    "parse_rotation",
    "rotation_angles",
    "rotation_from_args",
    "exposure_arg",
    "check_rank_arg",
    "print_notes",
    "add_mask_argument",
    "load_relight_inputs",
    "check_mask_size",
    "write_output",
]


def add_lights_arguments(p) -> None:
    """``--lights`` (lights.json or .lp, default CAPTURE/lights.json) and ``--lights-map``."""
    p.add_argument("--lights", default=None, metavar="FILE",
                   help="lights.json or RTI .lp file (default: CAPTURE/lights.json); another capture's lights "
                        "apply by name, by order when no name matches and the counts agree, or by --lights-map")
    p.add_argument("--lights-map", default=None, metavar="MAP",
                   help="which light applies to which image: a JSON object {\"light image\": \"capture image\"} "
                        "given inline or as a .json file (docs/formats.md)")


def add_capture_arguments(p, probe_required: bool = True, probe_default: str | None = None) -> None:
    """``CAPTURE``, ``--lights``, ``--lights-map`` and ``--probe`` (and ``--layout`` for the map file)."""
    p.add_argument("capture", help="capture folder (with capture.json)")
    add_lights_arguments(p)
    p.add_argument("--probe", required=probe_required, default=probe_default, metavar="MAP",
                   help="HDR light map (.exr/.hdr) or a built-in name (courtyard, studio, sunrise, night, sky, paper)"
                        + (f"; default {probe_default}" if probe_default else ""))
    p.add_argument("--layout", default=None, help="light-map layout (default: detected from the file)")


# ----------------------------------------------------------------------------- rotation
def parse_rotation(text: str) -> tuple[float, float, float]:
    """``'YAW,PITCH,ROLL'`` (degrees; missing trailing values are 0) -> three finite floats.

    Raises
    ------
    ValueError
        Not one to three comma-separated finite numbers.
    """
    try:
        v = [float(x) for x in str(text).split(",")]
    except ValueError:
        raise ValueError(f"rotation must be YAW,PITCH,ROLL in degrees, not {text!r}") from None
    if not 1 <= len(v) <= 3 or not all(math.isfinite(x) for x in v):
        raise ValueError(f"rotation must be YAW,PITCH,ROLL in degrees, not {text!r}")
    return tuple(v + [0.0] * (3 - len(v)))


def _rotation_type(text: str) -> tuple[float, float, float]:
    try:
        return parse_rotation(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _degrees_type(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite angle in degrees, not {text!r}")
    return v


def add_rotation_arguments(p, default: str | None = None) -> None:
    """``--rotate YAW,PITCH,ROLL`` and ``--rotate-z DEG`` (mutually exclusive) of relight, render and view.

    Both rotate the light map (:func:`ffls.conventions.rotation_ypr`: yaw about +Z, pitch about
    +Y, roll about +X, degrees); ``--rotate-z DEG`` is ``--rotate DEG,0,0``.
    """
    rot = p.add_mutually_exclusive_group()
    rot.add_argument("--rotate", type=_rotation_type, default=None, metavar="YAW,PITCH,ROLL",
                     help="rotate the light map by yaw (about +Z), pitch (+Y), roll (+X), degrees"
                          + (f" (default {default})" if default else ""))
    rot.add_argument("--rotate-z", type=_degrees_type, default=None, metavar="DEG",
                     help="rotate the light map about +Z by DEG degrees (counter-clockwise from above); "
                          "same as --rotate DEG,0,0")
    if default is not None:
        p.set_defaults(rotate_default=parse_rotation(default))


def rotation_angles(args) -> tuple[float, float, float]:
    """(yaw, pitch, roll) in degrees from the parsed ``--rotate`` / ``--rotate-z``."""
    if getattr(args, "rotate", None) is not None:
        return tuple(args.rotate)
    if getattr(args, "rotate_z", None) is not None:
        return (float(args.rotate_z), 0.0, 0.0)
    return tuple(getattr(args, "rotate_default", (0.0, 0.0, 0.0)))


def rotation_from_args(args):
    """The light-map rotation (3, 3) float64 of the parsed ``--rotate`` / ``--rotate-z``."""
    from ffls.conventions import rotation_ypr

    return rotation_ypr(*rotation_angles(args))


# ----------------------------------------------------------------------------- exposure
def exposure_arg(text: str):
    """argparse type of ``--exposure``: a finite number of stops, or ``'auto'``.

    ``auto`` meters the object (the ``--mask`` when given), not the background:
    :func:`ffls.display.tonemap.auto_exposure`.
    """
    if str(text).strip().lower() == "auto":
        return "auto"
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected stops (a finite number) or 'auto', not {text!r}")
    return v


# ----------------------------------------------------------------------------- rank
def check_rank_arg(rank, n_lights: int, flag: str = "--rank") -> None:
    """Check ``--rank K`` against the capture's ``n_lights`` accepted lights (known only after loading).

    Raises
    ------
    ffls.errors.InputError
        One line naming the flag and the valid range ``[1, n-1]``
        (:func:`ffls.relight.compress.rank_range`).
    """
    if rank is None:
        return
    from ffls.errors import InputError
    from ffls.relight.compress import rank_range

    lo, hi = rank_range(n_lights)
    if not lo <= int(rank) <= hi:
        raise InputError(f"{flag} {rank} is out of range: it must be in [{lo}, {hi}] for {n_lights} lights")


def print_notes(command: str, *notes) -> None:
    """Print each non-empty informational line as ``ffls COMMAND: NOTE`` on stderr."""
    for note in notes:
        if note:
            print(f"ffls {command}: {note}", file=sys.stderr)


# ----------------------------------------------------------------------------- loading
def add_mask_argument(p) -> None:
    """``--mask MASK.png``: the object mask; the output gets alpha and ``--exposure auto`` meters it."""
    p.add_argument("--mask", default=None, metavar="MASK.png",
                   help="object mask (white = object, same size as the photos): EXR output gets an A channel "
                        "(premultiplied RGB), PNG output RGBA, and --exposure auto meters the object only")


def load_relight_inputs(args, command: str, lightmap: bool = True):
    """Capture, lights, light map and mask of relight / render, with their informational lines.

    Loads ``args.capture`` with ``--lights`` / ``--lights-map``, checks ``--rank`` against the
    accepted lights, loads ``--probe`` and ``--mask``, and prints (stderr, one line each): how the
    lights were matched when not by name, colour-space conversions of the photos and the light
    map, and coverage warnings of the lights (:func:`ffls.weights.voronoi.coverage_warnings`).

    Returns
    -------
    capture, lights, lightmap (or None), mask ((H, W) float32 coverage, or None)
    """
    from ffls.io.capture import load_capture_and_lights
    from ffls.io.images import colour_summary, read_mask
    from ffls.weights.voronoi import coverage_warnings

    capture, lights = load_capture_and_lights(args.capture, args.lights, getattr(args, "lights_map", None))
    idx, dirs = lights.accepted()
    check_rank_arg(getattr(args, "rank", None), len(idx))
    lm = None
    if lightmap:
        from ffls.lightmaps.lightmap import lightmap_from_spec

        lm = lightmap_from_spec(args.probe, args.layout)
    mask = None
    if getattr(args, "mask", None):
        mask = read_mask(args.mask, size=capture.image_size)
    notes = [lights.note, colour_summary([capture.image_paths[i] for i in idx])]
    notes.append(None if lm is None or not lm.colour_note else f"colour: light map: {lm.colour_note}")
    if len(idx):
        notes += coverage_warnings(dirs, capture.hemisphere)
    print_notes(command, *notes)
    return capture, lights, lm, mask


def check_mask_size(mask, shape, flag: str = "--mask") -> None:
    """InputError naming ``flag`` when ``mask`` (H, W) does not fit an image of ``shape`` (H, W, ...)."""
    if mask is not None and tuple(mask.shape) != tuple(shape[:2]):
        from ffls.errors import InputError

        raise InputError(f"{flag}: the mask is {mask.shape[1]}x{mask.shape[0]}, the relit image "
                         f"{shape[1]}x{shape[0]}")


def write_output(out, hdr, display8=None, mask=None) -> None:
    """Write a relit still: ``.exr`` linear (RGBA, premultiplied, with a mask) or ``.png`` (RGBA with a mask)."""
    from pathlib import Path

    from ffls.io.images import premultiply, with_alpha, write_exr, write_png

    check_mask_size(mask, hdr.shape)
    if Path(out).suffix.lower() == ".exr":
        write_exr(out, hdr if mask is None else premultiply(hdr, mask), alpha=mask)
    else:
        write_png(out, display8 if mask is None else with_alpha(display8, mask))
