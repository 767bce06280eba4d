"""Arguments shared by the subcommands that relight a capture (relight, render, view).

One definition of each flag, used by every command that takes it:

* ``CAPTURE``, ``--lights`` (``lights.json`` or ``.lp``, possibly another capture's), ``--lights-map``,
  ``--probe``, ``--layout``: :func:`add_capture_arguments` (``view`` adds its own ``--probe``);
* ``--rotate YAW,PITCH,ROLL`` / ``--rotate-z DEG``: :func:`add_rotation_arguments`,
  :func:`rotation_from_args`;
* ``--exposure EV|auto``: :func:`exposure_arg`;
* ``--rank K``: checked against the number of lights, once it is known, by :func:`check_rank_arg`.

And the one shared set of argparse types that every subcommand's numeric and path arguments use
(``docs/reliability.md``): :func:`number` (finite, in a range), :func:`integer` (in a range, with
an optional memory estimate checked against the memory the machine has), :func:`size_wxh`,
:func:`float_list` and :func:`output_path` (suffix, parent folder, not a folder). A bad value is
refused while parsing, in one line naming the flag and the allowed range.
"""
from __future__ import annotations

import argparse
import contextlib
import contextvars
import math
import os
import sys
from pathlib import Path

from ffls.errors import available_memory, physical_memory

__all__ = [
    "learnt_kernel",
    "negative_pixels_note",
    "CELLS_RES",
    "CELLS_RES_OR_EXACT",
    "RANK",
    "FRAMES",
    "FPS",
    "MAP_HEIGHT",
    "N_LIGHTS",
    "SYNTH_RES",
    "SEED",
    "number",
    "integer",
    "size_wxh",
    "float_list",
    "output_path",
    "builtin_map_names",
    "available_memory",
    "check_memory",
    "add_capture_arguments",
    "add_lights_arguments",
    "add_rotation_arguments",
    "parse_rotation",
    "rotation_angles",
    "rotation_from_args",
    "exposure_arg",
    "check_rank_arg",
    "check_cells_res",
    "print_notes",
    "flush_notes",
    "compressed_note",
    "check_output_kind",
    "deferred_notes",
    "add_mask_argument",
    "load_relight_inputs",
    "check_mask_size",
    "check_mask_not_empty",
    "check_display_flags",
    "check_fps_flag",
    "write_output",
    "MAP_RES",
    "BASIS_SUBSET",
    "MAX_ERROR",
    "TARGET_FPS",
    "add_quality_arguments",
    "quality_from_args",
    "check_quality_args",
    "resolve_quality",
    "check_gpu_pass1",
    "MEMORY",
    "add_scale_arguments",
    "runner_from_args",
    "memory_from_args",
    "open_streamed_from_args",
]


# ----------------------------------------------------------------------------- shared argparse types
def _fmt_num(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _range_text(lo, hi, lo_open: bool = False, hi_open: bool = False) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{_fmt_num(lo)}, {_fmt_num(hi)}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {_fmt_num(lo)}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {_fmt_num(hi)}"
    return "finite"


def _in_range(v, lo, hi, lo_open, hi_open) -> bool:
    if lo is not None and (v <= lo if lo_open else v < lo):
        return False
    if hi is not None and (v >= hi if hi_open else v > hi):
        return False
    return True


def check_memory(nbytes: float, what: str) -> None:
    """Refuse, before allocating, a request estimated at ``nbytes`` above the memory available.

    Raises
    ------
    argparse.ArgumentTypeError
        ``what`` (e.g. ``"--cells-res 100000"``) needs more memory than is available; one line.
    """
    have = available_memory()
    if nbytes > have:
        raise argparse.ArgumentTypeError(
            f"{what} needs about {nbytes / 2**30:.3g} GiB of memory, more than the {have / 2**30:.3g} GiB available")


def number(lo: float | None = None, hi: float | None = None, lo_open: bool = False, hi_open: bool = False,
           unit: str = "", special: tuple = ()):
    """argparse type: a finite float in a range.

    Parameters
    ----------
    lo, hi : float, optional
        Bounds (inclusive unless ``lo_open`` / ``hi_open``).
    unit : str
        Said in the message (``"degrees"``, ``"stops"``).
    special : tuple of str
        Words accepted as themselves (lower case), e.g. ``("auto",)``.

    Returns
    -------
    callable
        ``text -> float`` (or the special word); raises ``argparse.ArgumentTypeError`` naming the
        range, which argparse prefixes with the flag.
    """
    def parse(text):
        t = str(text).strip()
        if t.lower() in special:
            return t.lower()
        try:
            v = float(t)
        except ValueError:
            v = math.nan
        if not math.isfinite(v) or not _in_range(v, lo, hi, lo_open, hi_open):
            extra = f" or {' or '.join(repr(w) for w in special)}" if special else ""
            rng = _range_text(lo, hi, lo_open, hi_open)
            raise argparse.ArgumentTypeError(
                f"expected a finite number{' of ' + unit if unit else ''} {rng}{extra}, not {text!r}"
                if rng != "finite" else f"expected a finite number{' of ' + unit if unit else ''}{extra}, not {text!r}")
        return v

    parse.__name__ = "number"  # argparse names the type in some messages
    return parse


def integer(lo: int | None = None, hi: int | None = None, memory=None, what: str = "", special: dict | None = None,
            why: str = ""):
    """argparse type: an integer in ``[lo, hi]``, optionally within the machine's memory.

    Parameters
    ----------
    lo, hi : int, optional
        Inclusive bounds. ``hi`` keeps a typo (``100000``) from becoming a huge allocation.
    memory : callable, optional
        ``value -> bytes`` the request will allocate; a value needing more than
        :func:`available_memory` is refused in the same line.
    what : str
        What the value is, for the memory message (``"cell texture"``).
    special : dict, optional
        Words or values accepted outside the range, mapped to what they mean (``{"0": 0}``).
    why : str
        Why the range is what it is, said after it in the message.
    """
    special = dict(special or {})

    def parse(text):
        t = str(text).strip()
        if t.lower() in special:
            return special[t.lower()]
        try:
            v = int(t)
        except ValueError:
            v = None
        if v is None or not _in_range(v, lo, hi, False, False):
            extra = "".join(f" or {k}" for k in special)
            rng = _range_text(lo, hi)
            raise argparse.ArgumentTypeError(f"expected an integer{'' if rng == 'finite' else ' ' + rng}{extra}"
                                             f"{f' ({why})' if why else ''}, not {text!r}")
        if memory is not None:
            check_memory(memory(v), f"{v}" + (f" ({what})" if what else ""))
        return v

    parse.__name__ = "integer"
    return parse


def size_wxh(lo: int = 1, hi: int = 16384, memory=None):
    """argparse type: ``WxH`` (e.g. ``7x5``, ``1920x1080``) with both in ``[lo, hi]`` -> ``(W, H)``."""
    def parse(text):
        try:
            a, b = str(text).lower().split("x")
            w, h = int(a), int(b)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected WxH (e.g. 7x5) with both in [{lo}, {hi}], not {text!r}") from None
        if not (lo <= w <= hi and lo <= h <= hi):
            raise argparse.ArgumentTypeError(f"expected WxH with both in [{lo}, {hi}], not {text!r}")
        if memory is not None:
            check_memory(memory(w, h), str(text))
        return w, h

    parse.__name__ = "size"
    return parse


def float_list(lo: float | None = None, hi: float | None = None, min_len: int = 1, max_len: int = 1000,
               unit: str = ""):
    """argparse type: comma-separated finite floats in ``[lo, hi]`` -> tuple (``0,90,180``)."""
    one = number(lo, hi, unit=unit)

    def parse(text):
        parts = [p for p in str(text).split(",")]
        if not min_len <= len(parts) <= max_len:
            raise argparse.ArgumentTypeError(
                f"expected {min_len} to {max_len} comma-separated numbers, not {text!r}")
        try:
            return tuple(one(p) for p in parts)
        except argparse.ArgumentTypeError as e:
            raise argparse.ArgumentTypeError(f"in {text!r}: {e}") from None

    parse.__name__ = "list"
    return parse


def builtin_map_names(text) -> tuple:
    """argparse type: comma-separated built-in light-map names (:func:`ffls.lightmaps.lightmap.builtin_lightmap`)."""
    from ffls.assets import builtin_lightmaps
    from ffls.lightmaps.lightmap import BUILTIN_PROCEDURAL

    known = [*builtin_lightmaps(), *BUILTIN_PROCEDURAL]
    names = tuple(m.strip() for m in str(text).split(","))
    for m in names:
        if m not in known:
            raise argparse.ArgumentTypeError(f"unknown light map {m!r}; built-in maps: {', '.join(known)}")
    return names


#: Extensions of the files ffls reads or writes: a folder output (``synth OUT_DIR``, ``demo -o``) with one
#: of them would be a folder named like a file.
FILE_SUFFIXES = (".exr", ".hdr", ".pic", ".png", ".jpg", ".jpeg", ".tif", ".tiff", ".tga", ".mp4", ".json",
                 ".lp", ".npy", ".npz", ".csv")


def output_path(suffixes: tuple = (), folder_ok: bool = False, file_ok: bool = True):
    """argparse type: an output path, checked before any work (:func:`ffls.errors.check_output_path`).

    Parameters
    ----------
    suffixes : tuple of str
        Allowed file extensions (lower case, with the dot); empty: any.
    folder_ok : bool
        A path without one of ``suffixes`` is a folder output (e.g. a turntable's PNG frames).
    file_ok : bool
        False: the path must be a folder output.

    The parent folder must exist; an existing path must be of the right kind (a file is not a
    folder and a folder is not a file), and a file must not be a photo that a ``capture.json``
    lists (:func:`ffls.io.capture.capture_listing`). Whether it is an input is checked when writing.
    """
    from pathlib import Path

    def parse(text):
        from ffls.errors import FflsError, check_output_path

        if not str(text).strip():  # (Path("") is the working folder: an unset shell variable wrote there)
            raise argparse.ArgumentTypeError("empty path")
        p = Path(text)
        is_file = file_ok and (not suffixes or p.suffix.lower() in suffixes)
        if not is_file and not folder_ok:
            raise argparse.ArgumentTypeError(f"{text}: must end with {' or '.join(suffixes)}")
        if not is_file and p.suffix and file_ok:
            raise argparse.ArgumentTypeError(
                f"{text}: must end with {' or '.join(suffixes)}, or name a folder (no extension)")
        if is_file and str(text).endswith(("/", os.sep)):  # (Path drops the slash: o/a.exr/ wrote the file o/a.exr)
            raise argparse.ArgumentTypeError(f"{text}: ends with '/', a folder, but names a {p.suffix} file")
        if not file_ok and p.suffix.lower() in FILE_SUFFIXES:  # (demo -o d.exr made a folder named d.exr)
            raise argparse.ArgumentTypeError(f"{text}: the output is a folder; a name ending with {p.suffix} is a "
                                             "file's: name the folder without it")
        try:
            check_output_path(p, folder=not is_file)
        except FflsError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
        if is_file:
            from ffls.io.capture import capture_listing

            owner = capture_listing(p)
            if owner is not None:  # (lightmap make has no capture among its inputs to refuse it)
                raise argparse.ArgumentTypeError(f"{text}: is a photo of the capture {owner}; refusing to "
                                                 "overwrite it")
        return str(p)

    parse.__name__ = "output path"
    return parse


# The numeric arguments several commands share, each declared once. Memory estimates per unit were
# measured with tracemalloc (docs/reliability.md): about 770 bytes per cell-texture texel
# (ffls.weights.voronoi.bake_cells), 1.3 kB per synthetic image pixel (ffls.synth.scene), 150 bytes
# per lat-long texel of a procedural or resampled light map.
#: ``--cells-res`` of render: the cell texture is res x res.
CELLS_RES = integer(16, 4096, memory=lambda r: 800.0 * r * r, what="cell texture")
#: ``--cells-res`` of relight: as :data:`CELLS_RES`, or 0 for the exact k-d tree.
CELLS_RES_OR_EXACT = integer(16, 4096, memory=lambda r: 800.0 * r * r, what="cell texture", special={"0": 0})
#: ``--rank K``: an integer here; its range [1, n-1] depends on the lights and is checked once they are
#: loaded, before anything is allocated, by :func:`check_rank_arg`.
RANK = integer()
#: ``--turntable N`` frames.
FRAMES = integer(1, 100000)
#: ``--fps``.
FPS = number(0.1, 1000.0)
#: Height of a lat-long light map made or resampled (width twice it).
MAP_HEIGHT = integer(4, 16384, memory=lambda h: 160.0 * 2 * h * h, what="light map")
#: A long job's time estimate above this many seconds is said before it starts (``synth``, ``probe pocs``).
ESTIMATE_NOTE_S = 60.0
#: Number of lights of a synthetic capture.
N_LIGHTS = integer(1, 100000)
#: Width and height of synthetic images.
SYNTH_RES = integer(8, 16384, memory=lambda r: 1400.0 * r * r, what="synthetic image")
#: ``--map-res H|full``: height of the lat-long map pass 1 integrates (None = full).
MAP_RES = integer(2, 16384, special={"full": None})
#: ``--basis-subset N``: photos kept; checked against the accepted lights once loaded.
BASIS_SUBSET = integer(1, 1000000)
#: ``--max-error E``: relative RMS error target of ``--quality auto`` (a fraction: 0.05 = 5 %).
MAX_ERROR = number(0.0, 10.0, lo_open=True)
#: ``--target-fps F`` (``view``: also ``--fps``): frame-rate target of ``--quality auto``.
TARGET_FPS = number(0.1, 1000.0)
def input_path(text: str) -> str:
    """argparse type of an optional input file: any non-empty text (the loader names a missing file).

    An empty value (``--mask ""``, often an unset shell variable) is refused rather than read as
    "not given", which would silently drop the input.
    """
    if not str(text).strip():
        raise argparse.ArgumentTypeError("empty path")
    return text


def store_path(text: str) -> str:
    """argparse type of ``--store DIR.zarr``: a non-empty path whose folder exists and that can be a
    store (:func:`ffls.store.ingest.store_path_problem`), checked even where the store goes unused
    (``relight``/``render`` on photos that fit in memory accepted ``--store nofolder/s.zarr``)."""
    from ffls.store.ingest import store_path_problem

    why = store_path_problem(input_path(text))
    if why:
        raise argparse.ArgumentTypeError(f"{text}: {why}")
    return text


#: A random seed (NumPy accepts non-negative integers).
SEED = integer(0, 2**63 - 1)


def add_lights_arguments(p) -> None:
    """``--lights`` (lights.json or .lp, default CAPTURE/lights.json) and ``--lights-map``."""
    p.add_argument("--lights", default=None, metavar="FILE", type=input_path,
                   help="lights.json or RTI .lp file (default: CAPTURE/lights.json); another capture's lights "
                        "apply by name, by order when no name matches and the counts agree, or by --lights-map")
    p.add_argument("--lights-map", default=None, metavar="MAP", type=input_path,
                   help="which light applies to which image: a JSON object {\"light image\": \"capture image\"} "
                        "given inline or as a .json file (docs/formats.md)")


#: Weighting schemes of pass 1 (``--weighting``; ffls.weights.weighting.SCHEMES, spelled here so
#: that parsing imports no SciPy; a test keeps the two equal).
WEIGHTINGS = ("voronoi", "antialiased", "barycentric", "gaussian", "spline", "kriging")


def add_weighting_argument(p) -> None:
    """``--weighting voronoi|antialiased|barycentric|gaussian|spline|kriging`` (relight, render, view, composite)."""
    p.add_argument("--weighting", default="voronoi", choices=WEIGHTINGS,
                   help="how a light-map direction is shared among the lights: voronoi (the paper's box filter, "
                        "default), antialiased (soft cell borders), barycentric (spherical triangles), gaussian "
                        "(von Mises-Fisher kernel over the nearest lights), spline (local thin-plate splines: the most "
                        "accurate of the local schemes, signed weights, pass 1 4-10x barycentric's cost), kriging (a "
                        "Gaussian process whose kernel is learnt from the photos by leave-one-out: the most accurate "
                        "measured, signed weights, spline's pass-1 cost plus seconds to learn); docs/weighting.md")


def learnt_kernel(relighter) -> str | None:
    """The line saying which kriging kernel ``relighter`` learnt from its photos, or None (another
    scheme, or a relighter without photos: :class:`ffls.weights.kriging.KernelLearner`)."""
    fit = getattr(getattr(relighter, "kernel", None), "fit", None)
    return None if fit is None else f"kriging kernel learnt from the photos by leave-one-out: {fit.describe()}"


def light_direction(text: str) -> tuple[float, float]:
    """``'AZ,EL'`` (degrees) -> (azimuth, elevation): azimuth from +X toward +Y, elevation above the xy plane.

    Raises
    ------
    ValueError
        Not two finite numbers, or the elevation outside [-90, 90].
    """
    parts = [t.strip() for t in str(text).split(",")]
    if len(parts) != 2:
        raise ValueError(f"expected AZ,EL in degrees, not {text!r}")
    try:
        az, el = (float(t) for t in parts)
    except ValueError:
        raise ValueError(f"expected AZ,EL in degrees, not {text!r}") from None
    if not (math.isfinite(az) and math.isfinite(el)) or abs(az) > 1e6:
        raise ValueError(f"AZ,EL must be finite numbers (|AZ| <= 1e6), not {text!r}")
    if not -90.0 <= el <= 90.0:
        raise ValueError(f"the elevation must be within [-90, 90] degrees, not {el:g}")
    return az, el


def _light_type(text: str):
    try:
        return light_direction(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_light_argument(p) -> None:
    """``--light AZ,EL``: one directional light instead of a light map (render)."""
    p.add_argument("--light", type=_light_type, default=None, metavar="AZ,EL",
                   help="relight with one directional light from azimuth AZ (degrees from +X toward +Y) and "
                        "elevation EL (degrees above the horizon), interpolated with --weighting (RTI style); "
                        "replaces --probe")


def light_vector(az_el) -> "np.ndarray":
    """Unit world direction (3,) of (azimuth, elevation) in degrees (:func:`light_direction`)."""
    import numpy as np

    az, el = (math.radians(float(a)) for a in az_el)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


def add_capture_arguments(p, probe_required: bool = True, probe_default: str | None = None) -> None:
    """``CAPTURE``, ``--lights``, ``--lights-map`` and ``--probe`` (and ``--layout`` for the map file)."""
    from ffls.lightmaps.lightmap import LAYOUTS

    p.add_argument("capture", type=input_path, help="capture folder (with capture.json)")
    add_lights_arguments(p)
    p.add_argument("--probe", required=probe_required, default=probe_default, metavar="MAP",
                   help="HDR light map (.exr/.hdr) or a built-in name (courtyard, studio, sunrise, night, sky, paper)"
                        + (f"; default {probe_default}" if probe_default else ""))
    p.add_argument("--layout", default=None, choices=LAYOUTS,
                   help="layout of the light-map file (default: detected from the file)")


# ----------------------------------------------------------------------------- rotation
def parse_rotation(text: str) -> tuple[float, float, float]:
    """``'YAW,PITCH,ROLL'`` (degrees; missing trailing values are 0) -> three finite floats, each within +-1e6.

    Raises
    ------
    ValueError
        Not one to three comma-separated finite numbers.
    """
    try:
        v = [float(x) for x in str(text).split(",")]
    except ValueError:
        raise ValueError(f"rotation must be YAW,PITCH,ROLL in degrees, not {text!r}") from None
    if not 1 <= len(v) <= 3 or not all(math.isfinite(x) and abs(x) <= 1e6 for x in v):
        raise ValueError(f"rotation must be YAW,PITCH,ROLL in degrees (finite, within +-1e6), not {text!r}")
    return tuple(v + [0.0] * (3 - len(v)))


def _rotation_type(text: str) -> tuple[float, float, float]:
    try:
        return parse_rotation(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


#: ``--rotate-z DEG``: any finite angle within a sane range.
_degrees_type = number(-1e6, 1e6, unit="degrees")


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
    return _exposure(text)


#: Stops of exposure: 2**±64 spans far beyond any radiance a float32 image holds.
_exposure = number(-64.0, 64.0, unit="stops", special=("auto",))


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


def check_cells_res(res, directions, hemisphere, flag: str = "--cells-res") -> None:
    """Refuse a cell texture too coarse for the lights: some texel would have more candidate cells than it holds.

    Such a texture gives wrong weights silently (the GPU engine bakes at exactly ``res``), so the
    smallest resolution that works (doubling ``res``) is named instead.

    Raises
    ------
    ffls.errors.InputError
        One line naming the flag, the overflowing texel count and a resolution that works.
    """
    if not res or not len(directions):
        return
    if int(res) >= 16 * math.sqrt(len(directions)):  # measured: no overflow this fine (docs/reliability.md)
        return
    from ffls.errors import InputError
    from ffls.weights.voronoi import bake_cells

    cells = bake_cells(directions, hemisphere, res=int(res), max_res=4096)
    if cells.overflow:
        raise InputError(f"{flag} {res} is too coarse for {len(directions)} lights ({cells.overflow} texels "
                         f"hold more candidate cells than fit even at {cells.res}); use fewer lights")
    if cells.res != int(res):
        raise InputError(f"{flag} {res} is too coarse for {len(directions)} lights: texels would hold more "
                         f"candidate cells than fit (the weights would be wrong); use {flag} {cells.res} or more")


_NOTES: contextvars.ContextVar = contextvars.ContextVar("ffls_notes", default=None)


def show_progress(args) -> bool:
    """Whether a command draws progress bars on stderr.

    Only for a person at a terminal: not with ``--no-progress``, not when stderr is a file or a
    pipe, and not under CI (``CI`` set), where a bar's lines would bury the one-line answer.
    """
    return not getattr(args, "no_progress", False) and sys.stderr.isatty() and not os.environ.get("CI")


def print_notes(command: str, *notes) -> None:
    """Print each non-empty informational line as ``ffls COMMAND: NOTE`` on stderr.

    Inside :func:`deferred_notes` (the CLI) the lines wait for :func:`flush_notes` (a command
    calls it once its inputs are loaded) or the command's successful end; a command that fails
    before then prints only its one error line.
    """
    pending = _NOTES.get()
    for note in notes:
        if note:
            line = f"ffls {command}: {note}"
            if pending is None:
                print(line, file=sys.stderr)
            else:
                pending.append(line)


def compressed_note(relighter) -> str:
    """The line of a relighter's compressed basis (``--rank K``) that could not be kept in a read-only
    capture (:func:`ffls.relight.compress.load_or_compress`), or ``""``."""
    return getattr(getattr(relighter, "compressed", None), "note", "")


def flush_notes() -> None:
    """Print the informational lines held by :func:`deferred_notes` now."""
    pending = _NOTES.get()
    while pending:
        print(pending.pop(0), file=sys.stderr)


@contextlib.contextmanager
def deferred_notes():
    """Hold :func:`print_notes` lines until :func:`flush_notes` or a successful end; drop them on an error."""
    token = _NOTES.set([])
    try:
        yield
        flush_notes()
    finally:
        _NOTES.reset(token)


# ----------------------------------------------------------------------------- loading
def add_mask_argument(p) -> None:
    """``--mask MASK.png``: the object mask; the output gets alpha and ``--exposure auto`` meters it."""
    p.add_argument("--mask", default=None, metavar="MASK.png", type=input_path,
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
    from ffls.io.images import colour_summary, mask_note, read_mask

    capture, lights = load_capture_and_lights(args.capture, args.lights, getattr(args, "lights_map", None))
    idx, dirs = lights.accepted()
    check_rank_arg(getattr(args, "rank", None), len(idx))
    if command == "render":  # relight re-bakes finer by itself (relight_capture's max_res)
        check_cells_res(getattr(args, "cells_res", None), dirs, capture.hemisphere)
    lm = None
    if lightmap:
        from ffls.lightmaps.lightmap import lightmap_from_spec

        lm = lightmap_from_spec(args.probe, args.layout)
    mask = None
    if getattr(args, "mask", None):
        mask = read_mask(args.mask, size=capture.image_size)
        check_mask_not_empty(mask, args.mask)
    notes = [lights.note, colour_summary([capture.image_paths[i] for i in idx])]
    notes.append(None if mask is None else mask_note(mask, args.mask))
    notes.append(None if lm is None or not lm.colour_note else f"colour: light map: {lm.colour_note}")
    notes += coverage_notes(capture, lights, idx, dirs, repeats=True)
    print_notes(command, *notes)
    return capture, lights, lm, mask


def coverage_notes(capture, lights, idx, dirs, repeats: bool = False) -> list:
    """The coverage warnings (:func:`ffls.weights.voronoi.coverage_warnings`, with their 95% cones)
    of the accepted lights ``idx`` (by capture index; directions ``dirs``) of ``capture``; [] when
    none is accepted. ``repeats=True`` names the photos of repeated lights and says whether they
    hold the same pixels (:func:`same_photo_of`)."""
    if not len(idx):
        return []
    from ffls.weights.voronoi import coverage_warnings

    named = {}
    if repeats:
        named = {"names": [capture.image_names[i] for i in idx], "same_photo": same_photo_of(capture, idx)}
    return coverage_warnings(dirs, capture.hemisphere, **named, cones_deg=lights.cones_deg(idx))


def same_photo_of(capture, idx):
    """``same_photo`` for :func:`ffls.weights.voronoi.coverage_warnings` of the lights ``idx`` (the
    accepted ones, by capture index) of ``capture``: whether two of their photos hold the same pixels
    (:func:`ffls.io.images.same_pixels`; read only for the repeated lights named, each once)."""
    from functools import lru_cache

    from ffls.io.images import pixels_match, read_image

    @lru_cache(maxsize=None)
    def pixels(i):
        return read_image(capture.image_paths[idx[i]], working_space=False).pixels

    return lambda a, b: pixels_match(pixels(a), pixels(b))


# ----------------------------------------------------------------------------- quality knobs
def add_quality_arguments(p, *, precision_default: str | None = "float16", fps_flags=("--target-fps",),
                          rank: bool = False, cells_res=None) -> None:
    """The speed/accuracy knobs shared by relight, render and view (``docs/tradeoff.md``).

    ``--precision float16|float32`` (``--dtype`` is the same flag), ``--basis-subset N``,
    ``--map-res H|full``, ``--near-correction``, and ``--quality manual|auto`` with its targets
    ``--max-error E`` and ``--target-fps F``. ``rank=True`` adds ``--rank K`` (commands that
    define their own leave it False); ``cells_res`` an argparse type adds ``--cells-res``.
    """
    g = p.add_argument_group("quality (speed against accuracy; docs/tradeoff.md)")
    g.add_argument("--precision", "--dtype", dest="precision", default=precision_default,
                   choices=("float16", "float32", "f16", "f32"),
                   help="storage of the basis: float16 (checked per-dataset scale) or float32"
                        + (f" (default {precision_default})" if precision_default else " (default: as loaded)"))
    g.add_argument("--basis-subset", type=BASIS_SUBSET, default=None, metavar="N",
                   help="use N of the photos, chosen by farthest-point sampling on the light directions")
    g.add_argument("--map-res", type=MAP_RES, default=None, metavar="H|full",
                   help="height of the lat-long light map that pass 1 integrates (box-filtered, integral kept; "
                        "default full)")
    g.add_argument("--near-correction", action="store_true",
                   help="near lights: scale each photo by its light's squared distance to the scene centre and "
                        "take its direction from the position (needs positions in the lights file)")
    if rank:
        g.add_argument("--rank", type=RANK, default=None, metavar="K",
                       help="compressed basis of K eigen-images, 1 <= K <= n-1 for n lights")
    if cells_res is not None:
        g.add_argument("--cells-res", type=cells_res, default=256,
                       help="cell-texture resolution, 16 to 4096 (default 256)")
    g.add_argument("--quality", default="manual", choices=("manual", "auto"),
                   help="auto: measure this capture and map and pick the cheapest configuration meeting "
                        "--max-error and/or " + "/".join(fps_flags) + " (rank, precision, subset, map height)")
    g.add_argument("--max-error", type=MAX_ERROR, default=None, metavar="E",
                   help="with --quality auto: relative RMS error target (0.05 = 5%%)")
    g.add_argument(*fps_flags, dest="target_fps", type=TARGET_FPS, default=None, metavar="F",
                   help="with --quality auto: frame-rate target (frames per second)")


def quality_from_args(args):
    """The :class:`ffls.relight.quality.Quality` that the manual knobs of ``args`` name."""
    from ffls.relight.quality import Quality

    prec = getattr(args, "precision", None) or "float32"
    cells = getattr(args, "cells_res", None)
    return Quality(weighting=getattr(args, "weighting", None) or "voronoi", precision=prec,
                   rank=getattr(args, "rank", None) or None, basis_subset=getattr(args, "basis_subset", None),
                   cell_res=int(cells) if cells else None, map_res=getattr(args, "map_res", None),
                   near_correction=bool(getattr(args, "near_correction", False)))


def check_quality_args(args, n_lights: int, positions=None) -> None:
    """Check the quality flags against the capture (one line naming the flag).

    Raises
    ------
    ffls.errors.InputError
        ``--basis-subset`` above the accepted lights; ``--near-correction`` without positions;
        ``--quality auto`` without a target, or a target without ``--quality auto``.
    """
    import numpy as np

    from ffls.errors import InputError

    sub = getattr(args, "basis_subset", None)
    if sub is not None and sub > n_lights:
        raise InputError(f"--basis-subset {sub} exceeds the {n_lights} accepted lights")
    if getattr(args, "near_correction", False):
        pos = np.full((n_lights, 3), np.nan) if positions is None else np.asarray(positions, dtype=float)
        missing = int(np.count_nonzero(~np.all(np.isfinite(pos), axis=1)))
        if missing:
            raise InputError(f"--near-correction needs light positions; {missing} of {n_lights} accepted lights "
                             f"have none in the lights file")
    auto = getattr(args, "quality", "manual") == "auto"
    targets = getattr(args, "max_error", None) is not None or getattr(args, "target_fps", None) is not None
    if auto and not targets:
        raise InputError("--quality auto needs --max-error E and/or a frame-rate target")
    if targets and not auto:
        raise InputError("--max-error and the frame-rate target apply only with --quality auto")


def open_streamed_from_args(args, capture, lights, command: str, output_copies: int, gpu_budget=None):
    """The relighter streamed from the capture's store when the photos do not fit ``--memory``
    (or with ``--tiles``), under the manual quality flags; None when the in-memory path fits.

    Raises
    ------
    ffls.errors.InputError
        ``--quality auto`` on a capture that streams (the choice measures the capture in memory).
    """
    from ffls.errors import InputError
    from ffls.relight.basis import accepted_positions
    from ffls.relight.stream import open_streamed

    idx, _ = lights.accepted()
    check_quality_args(args, len(idx), accepted_positions(lights))
    q = quality_from_args(args)
    with runner_from_args(args) as runner:
        r, notes = open_streamed(capture, lights, memory_from_args(args), store=args.store, runner=runner,
                                 cell_res=getattr(args, "cells_res", None) or None, cell_max_res=1024,
                                 force=args.tiles, output_copies=output_copies, gpu_budget=gpu_budget, quality=q)
    if r is not None and getattr(args, "quality", "manual") == "auto":
        r.release()
        raise InputError("--quality auto measures the capture in memory, and this capture streams from its store: "
                         "give the knobs instead (docs/tradeoff.md)")
    print_notes(command, *notes)
    return r


def resolve_quality(args, capture, lights, lightmap, rotation=None, timer=None, command: str = ""):
    """The configuration to relight with: the manual knobs, or (``--quality auto``) the measured choice.

    With ``--quality auto`` the candidates are measured on this capture and light map
    (:func:`ffls.relight.auto.choose_quality`; ``timer(quality, basis, directions) -> ms`` times a
    frame on the caller's path, default the CPU relighter) and the choice and its reason are printed (stderr,
    two lines).

    Returns
    -------
    ffls.relight.quality.Quality
    """
    from ffls.relight.basis import accepted_positions

    idx, _ = lights.accepted()
    check_quality_args(args, len(idx), accepted_positions(lights))
    q = quality_from_args(args)
    if getattr(args, "quality", "manual") != "auto":
        return q
    from ffls.relight.auto import choose_quality
    from ffls.relight.basis import capture_basis

    basis, d, _ = capture_basis(capture, lights, q.replace(basis_subset=None))
    choice = choose_quality(basis, d, lightmap, rotation, max_error=args.max_error, fps=args.target_fps,
                            timer=timer, hemisphere=capture.hemisphere, base=q.replace(rank=None, basis_subset=None))
    for line in choice.reason.splitlines():
        print(f"ffls {command}: {line.strip()}" if command else line, file=sys.stderr)
    return choice.quality


def check_gpu_pass1(ctx, lightmap, quality) -> None:
    """Refuse, in one line naming ``--weighting`` and ``--map-res``, a light map the GPU's pass 1 cannot take.

    Pass 1 keeps one 16-byte item per map texel and weight-texture slot in one storage buffer
    (:func:`ffls.relight.quality.pass1_buffer_bytes`); past the device's block size
    (``GL_MAX_SHADER_STORAGE_BLOCK_SIZE``, 128 MiB on llvmpipe) it cannot run. ``spline`` has 24
    slots: a 1024 x 512 map needs 192 MiB. The line says which ``--map-res`` fits.

    Raises
    ------
    ffls.errors.InputError
    """
    from ffls.errors import InputError
    from ffls.relight.quality import integration_map, pass1_buffer_bytes, pass1_fit_height
    from ffls.weights.weighting import texture_slots

    if lightmap is None:
        return
    limit = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 2 ** 27)
    lm = integration_map(lightmap, quality.map_res)
    dirs = lm.samples()[0] if hasattr(lm, "samples") else lm[0]
    m = int(len(dirs))
    need = pass1_buffer_bytes(m, quality.weighting)
    if need <= limit:
        return
    slots = 1 if quality.weighting == "voronoi" else texture_slots(quality.weighting)
    h = pass1_fit_height(limit, quality.weighting)
    fix = f"give --map-res {h} or lower" if h else "no map height fits"
    raise InputError(f"--weighting {quality.weighting}: the GPU's pass 1 cannot take this light map ({m} texels x "
                     f"{slots} slot{'s' if slots > 1 else ''} need {need / 2 ** 20:.0f} MiB in one storage buffer, "
                     f"over this GPU's {limit / 2 ** 20:.0f} MiB); {fix}, another --weighting, or --cpu")


def check_mask_size(mask, shape, flag: str = "--mask") -> None:
    """InputError naming ``flag`` when ``mask`` (H, W) does not fit an image of ``shape`` (H, W, ...)."""
    if mask is not None and tuple(mask.shape) != tuple(shape[:2]):
        from ffls.errors import InputError

        raise InputError(f"{flag}: the mask is {mask.shape[1]}x{mask.shape[0]}, the relit image "
                         f"{shape[1]}x{shape[0]}")


def check_mask_not_empty(mask, path, flag: str = "--mask", what: str = "object") -> None:
    """Refuse a mask with no ``what`` pixel (none above 0.5, the threshold every mask user applies:
    :func:`viewer.renderer.load_mask`, the composite's surface mask).

    An all-black mask would give an output with alpha 0 everywhere (and nothing to meter for
    ``--exposure auto``): a wrong file, not a request.

    Raises
    ------
    ffls.errors.InputError
        One line naming ``flag`` and the file.
    """
    import numpy as np

    if mask is not None and not np.any(np.asarray(mask) > 0.5):
        from ffls.errors import InputError

        raise InputError(f"{flag} is empty: no {what} pixel (white = {what})", path)


#: What a still (no ``--turntable``) is written as.
STILL_SUFFIXES = (".exr", ".png")


def check_output_kind(args, out) -> None:
    """``-o`` against ``--turntable``: a still is .exr/.png, a turntable an .mp4 or a folder.

    Checked before anything is loaded: a turntable into ``OUT.png`` was refused only when its
    frames were about to be written, after its coverage lines (two lines for one error).
    """
    from ffls.errors import InputError

    suffix = Path(out).suffix.lower()
    if args.turntable is None and suffix not in STILL_SUFFIXES:
        raise InputError(f"output must end with {' or '.join(STILL_SUFFIXES)} (or use --turntable N)", out)
    if args.turntable is not None and suffix and suffix != ".mp4":
        raise InputError(f"--turntable writes a video (.mp4) or a folder of PNGs (no extension), not {suffix}", out)
    if args.turntable is not None and not suffix:
        from ffls.io.video import frame_folder_problem

        why = frame_folder_problem(out)  # (render -o CAPTURE --turntable 2 was refused after its coverage lines)
        if why:
            raise InputError(why, out)
    store = getattr(args, "store", None)
    if store:  # (render --turntable 2 --store D -o D/ built the store, then refused D as the frames' folder)
        a, b = Path(os.path.abspath(store)), Path(os.path.abspath(out))
        if a == b or a in b.parents or b in a.parents:
            raise InputError(f"--store {store} and -o {out} {'are one path' if a == b else 'hold one another'}: "
                             "the store and the output each need their own place")


def check_fps_flag(args, out=None) -> None:
    """Refuse ``--fps`` without ``--turntable``, and with a turntable written as a folder of PNG
    frames when the output ``out`` is known (the flag defaults to None so that a given one is told
    from one left out; a still, or a folder of frames, has no frame rate).

    Raises
    ------
    ffls.errors.InputError
    """
    if getattr(args, "fps", None) is None:
        return
    from ffls.errors import InputError

    if getattr(args, "turntable", None) is None:
        raise InputError("--fps applies to a --turntable video; a still has no frame rate")
    if out is not None and os.path.splitext(str(out))[1].lower() != ".mp4":
        raise InputError("--fps applies to an .mp4 turntable; a folder of PNG frames has no frame rate", out)


def check_display_flags(args, out) -> None:
    """Refuse ``--exposure`` / ``--tonemap`` given with a linear ``.exr`` still (they shape only the
    tone-mapped PNG or video: the EXR is written linear), and ``--fps`` without ``--turntable``.

    The commands give these flags ``default=None`` so that a flag given is told from one left out.

    Raises
    ------
    ffls.errors.InputError
    """
    from pathlib import Path

    from ffls.errors import InputError

    check_fps_flag(args, out)
    if getattr(args, "turntable", None) is None and Path(out).suffix.lower() == ".exr":
        given = [f for f, k in (("--exposure", "exposure"), ("--tonemap", "tonemap"))
                 if getattr(args, k, None) is not None]
        if given:
            raise InputError(f"{' and '.join(given)} shape{'s' if len(given) == 1 else ''} the tone-mapped PNG; "
                             f"{Path(out).name} is written linear (write a .png, or leave "
                             f"{'it' if len(given) == 1 else 'them'} out)")


def negative_pixels_note(hdr, out) -> str:
    """The line saying how many pixels of a relit still went below zero, or ``""`` when none did.

    Weights that are not a partition of non-negative cells (barycentric outside the hull, spline,
    kriging) may be negative for some lights, and photos may hold negative values (a subtracted dark
    frame), so a pixel may sum below zero. The EXR keeps such
    values as they are (compositing tools carry negatives); the PNG's tone map shows them as black.
    """
    from pathlib import Path

    import numpy as np

    n = int(np.count_nonzero(np.any(np.asarray(hdr)[..., :3] < 0, axis=-1)))
    if not n:
        return ""
    total = int(np.prod(np.asarray(hdr).shape[:2]))
    kept = "kept as they are" if Path(out).suffix.lower() == ".exr" else "black in the PNG"
    return (f"{n} of {total} pixels ({100 * n / total:.2g}%) are negative (a smooth weighting's negative lobes, "
            f"or negative photo values); {kept}")


def write_output(out, hdr, display8=None, mask=None) -> None:
    """Write a relit still: ``.exr`` linear (RGBA, premultiplied, with a mask) or ``.png`` (RGBA with a mask)."""
    from pathlib import Path

    from ffls.io.images import premultiply, with_alpha, write_exr, write_png

    check_mask_size(mask, hdr.shape)
    if Path(out).suffix.lower() == ".exr":
        write_exr(out, hdr if mask is None else premultiply(hdr, mask), alpha=mask)
    else:
        write_png(out, display8 if mask is None else with_alpha(display8, mask))


#: Local worker processes per core at most (``--workers``): each process imports NumPy, OpenCV and
#: its share of the photos, so 1000 of them on 2 cores ran for minutes before any work.
WORKERS_PER_CORE = 4
#: ``--workers N``: local processes, 1 to :data:`WORKERS_PER_CORE` per core of this machine.
WORKERS = integer(1, WORKERS_PER_CORE * (os.cpu_count() or 1))
WORKERS.__name__ = "processes"


# ----------------------------------------------------------------------------- captures of any size (docs/scale.md)
def _memory_type(text):
    from ffls.relight.stream import parse_memory

    try:
        v = parse_memory(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    if v < 64 * 2 ** 20:
        raise argparse.ArgumentTypeError(f"expected at least 64M, not {text!r}")
    have = physical_memory()  # (1T on a 24 GiB machine was no limit: the photos were held, then swapped or killed)
    if have is not None and v > have:
        raise argparse.ArgumentTypeError(f"{text!r} is more than the {have / 2 ** 30:.3g} GiB of memory this "
                                         f"machine has (at most {have // 2 ** 20}M)")
    return v


#: ``--memory SIZE``: bytes (``1G``, ``512M``), at least 64 MiB.
MEMORY = _memory_type
MEMORY.__name__ = "size"


def add_scale_arguments(p, store: bool = True, memory: bool = True) -> None:
    """``--memory``, ``--store``, ``--tiles`` (streamed relighting) and ``--workers``, ``--scheduler`` (Dask)."""
    if memory:
        p.add_argument("--memory", type=MEMORY, default=None, metavar="SIZE",
                       help="memory budget, e.g. 1G or 512M (default: half of the memory available now); photos "
                            "that do not fit are streamed tile by tile from the capture's store")
    if store:
        p.add_argument("--store", default=None, metavar="DIR.zarr", type=store_path,
                       help="the chunked store of the photos (default CAPTURE/field.zarr; built on first use)")
        p.add_argument("--tiles", action="store_true",
                       help="stream from the store even when the photos would fit in memory")
    p.add_argument("--workers", type=WORKERS, default=None, metavar="N",
                   help="local Dask worker processes for the per-photo work (default every core; 1: in this process; "
                        "at most 4 per core)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT", type=scheduler_type(),
                   help="run the per-photo work on this dask.distributed cluster (docs/scale.md)")


def scheduler_type(allow_local: bool = False):
    """argparse type of ``--scheduler``: a checked ``SCHEME://HOST:PORT`` (or ``local`` when allowed).

    Checked when the arguments are parsed, so a malformed address is one line before any work
    (:func:`ffls.cluster.check_scheduler_address`).
    """

    def parse(text: str) -> str:
        if allow_local and text == "local":
            return text
        from ffls.cluster import check_scheduler_address

        try:
            return check_scheduler_address(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(f"{e}; give a running scheduler as tcp://HOST:PORT"
                                             + (" or 'local'" if allow_local else "")) from None

    parse.__name__ = "scheduler address"
    return parse


def memory_from_args(args) -> int:
    """``--memory``, or half of the memory available now (:func:`ffls.relight.stream.default_memory`)."""
    from ffls.relight.stream import default_memory

    m = getattr(args, "memory", None)
    return int(m) if m is not None else default_memory(available_memory())


class _LazyCluster:
    """A Dask runner started on its first task (a fresh store needs none, and a cluster takes seconds)."""

    def __init__(self, workers, scheduler, progress, stack):
        self.workers, self.scheduler, self.progress, self.stack = workers, scheduler, progress, stack
        self.runner = None

    def started(self):
        if self.runner is None:
            from ffls.cluster import open_client

            self.runner = self.stack.enter_context(open_client(self.workers, self.scheduler, self.progress))
        return self.runner

    @property
    def n_workers(self) -> int:
        return self.started().n_workers

    def map(self, fn, items, desc: str = ""):
        return self.started().map(fn, items, desc)


@contextlib.contextmanager
def runner_from_args(args, progress: bool = True):
    """The runner of the per-photo tasks: a Dask cluster (``--scheduler``, or local ``--workers``), or this process.

    ``--workers 1`` (and no ``--scheduler``) runs in this process, without Dask. The cluster is
    started on the first task only.
    """
    scheduler = getattr(args, "scheduler", None)
    workers = getattr(args, "workers", None)
    if not scheduler and workers == 1:
        from ffls.store.ingest import SerialRunner

        yield SerialRunner(progress)
        return
    with contextlib.ExitStack() as stack:
        yield _LazyCluster(workers, scheduler, progress, stack)
