"""``ffls synth``: render a synthetic capture folder with the built-in scene (:mod:`ffls.synth.scene`).

Besides the default scene (an object and four white spheres, linear EXR), the flags give the
conditions of real photographs: any number of spheres of any material, calibration shots
without the object, black/grey/white/textured backgrounds, long and orthographic lenses, 8- and
16-bit files in sRGB, linear or gamma 2.2 (stated in ``capture.json`` or not), JPEG, exposure,
vignetting and Poisson-Gaussian sensor noise (``docs/synth.md``).
"""
from __future__ import annotations

import argparse
import sys
import time

from ffls.commands.common import ESTIMATE_NOTE_S

NAME = "synth"
HELP = "render a synthetic capture (object, calibration spheres, one light per image)"
DESCRIPTION = (
    "Render a synthetic Free-form Light Stage capture with the built-in NumPy ray tracer: a glossy "
    "and diffuse object on a table with calibration spheres (matte, grey, mirror or glossy black), one "
    "light per image, cast shadows and one bounce off the table, seen through a normal, long or "
    "orthographic lens and stored as a camera would (EXR, PNG, TIFF or JPEG; sRGB, linear or gamma 2.2; "
    "exposure, vignetting, sensor noise). Writes the images, capture.json, lights.json (true "
    "directions) and truth.json (everything needed to score)."
)

_MATERIALS = ("matte", "grey", "mirror", "glossy_black")
#: Defaults of the ``--composite-set`` flags (None in the parsed arguments when not given, so that a
#: flag given without ``--composite-set``, where it would do nothing, is refused).
SCENE_ALBEDO = 0.5
WALL_ALBEDO = (0.6, 0.35, 0.25)
TRUTH_DIRS = 2048
#: ``--camera-elevation``'s default (degrees): :class:`ffls.synth.scene.SynthScene`'s.
CAMERA_ELEVATION_DEG = 30.0
#: Cost of one image on the 2-core team machine (docs/synth.md "Speed"; ``ffls synth`` of 500 and
#: 2000 lights at 8 px, 500 at 64 px, 200 at 256 px): about 9 ms each plus 0.3 us a pixel, the
#: pixel part about 10 times more for a near light (9 sample points).
SECONDS_PER_IMAGE, SECONDS_PER_PIXEL, NEAR_FACTOR = 9e-3, 3e-7, 10.0
#: Bytes a pixel at most, per ``--format`` (RGB; EXR half floats; a JPEG is far smaller than 3).
BYTES_PER_PIXEL = {"exr": 6, "png8": 3, "png16": 6, "tiff16": 6, "jpeg": 3}


# ----------------------------------------------------------------------------- argument types
# Numbers use the shared argparse types of ffls.commands.common (finite, in range, one line);
# the parsers below read this command's own structured values.
def _finite(text: str) -> float:
    from ffls.commands.common import number

    return number()(text)


def _materials(text: str):
    """``matte``, ``grey``, ``mirror``, ``glossy_black``, ``mixed``, or a comma list (one per sphere)."""
    if text == "mixed":
        return text
    parts = [t.strip() for t in text.split(",")]
    bad = [t for t in parts if t not in _MATERIALS]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown material {bad[0]!r}: expected {', '.join(_MATERIALS)} or mixed "
                                         "(or a comma list, one per sphere)")
    return parts[0] if len(parts) == 1 else tuple(parts)


def _sphere_xy(text: str) -> tuple:
    """``X,Y;X,Y;...`` ground positions (m)."""
    out = []
    for item in text.split(";"):
        xy = item.split(",")
        if len(xy) != 2:
            raise argparse.ArgumentTypeError(f"expected X,Y;X,Y;... (metres), not {text!r}")
        out.append((_finite(xy[0]), _finite(xy[1])))
    return tuple(out)


def _vignetting(text: str):
    """``none``, ``cos4`` or ``radial:A[,B[,C]]`` -> (model, coeffs)."""
    if text in ("none", "cos4"):
        return text, ()
    if text.startswith("radial:"):
        coeffs = text[len("radial:"):].split(",")
        if 1 <= len(coeffs) <= 3:
            import numpy as np

            from ffls.synth.photo import radial_falloff

            coeffs = tuple(_finite(c) for c in coeffs)
            r = np.arange(1001) / 1000  # r = 1 at the corners
            with np.errstate(over="ignore"):  # (a sum beyond float range is inf: reported below)
                v = radial_falloff(r * r, coeffs)
            dark = np.flatnonzero(v <= 0)[:1]
            top = np.flatnonzero(v == v.max())[-1]  # (the last of equal maxima)
            if dark.size or v[top] > 1 + 1e-12:
                what = (f"reaches {v[dark[0]]:.3g} at r = {r[dark[0]]:.3g}" if dark.size else
                        f"brightens to {v[top]:.6g} at r = {r[top]:.3g}")
                raise argparse.ArgumentTypeError(
                    f"{text!r} {what} (r = 1 at the corners): vignetting darkens, by a factor in (0, 1] out to the "
                    "corners (0 or less would be clipped to black)")
            return "radial", coeffs
    raise argparse.ArgumentTypeError(f"expected none, cos4 or radial:A[,B[,C]], not {text!r}")


def _wall(text: str):
    """``none`` (returned as the word: no wall) or ``R,G,B`` albedo in [0, 1]."""
    if text == "none":
        return text
    from ffls.commands.common import float_list

    return float_list(0.0, 1.0, min_len=3, max_len=3)(text)


def _choice(*names):
    def parse(text: str) -> str:
        if text not in names:
            raise argparse.ArgumentTypeError(f"expected one of {', '.join(names)}, not {text!r}")
        return text
    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ffls.commands.common import N_LIGHTS, SEED, SYNTH_RES, integer, number, output_path

    p.add_argument("out_dir", metavar="OUT_DIR", type=output_path(folder_ok=True, file_ok=False),
                   help="output capture folder (created if missing)")
    p.add_argument("--lights", type=N_LIGHTS, default=100, metavar="N", help="number of images (default 100)")
    p.add_argument("--resolution", type=SYNTH_RES, default=256, metavar="R", help="image width and height (default 256)")
    p.add_argument("--supersample", type=integer(1, 8), default=1, metavar="S",
                   help="S x S rays per pixel, averaged: an anti-aliased outline, as a lens and sensor give "
                        "(default 1: one ray through each pixel's centre)")
    p.add_argument("--near", type=number(0.0, 1e6, lo_open=True), default=None, metavar="DIST",
                   help="point lights at DIST metres from the scene centre instead of distant lights")
    p.add_argument("--light-radius", type=number(0.0, 1e6), default=None, metavar="M",
                   help="radius of a spherical near light, with --near (soft shadows; default 0 = point)")
    p.add_argument("--light-angle", type=number(0.0, 90.0, lo_open=True, hi_open=True, unit="degrees"), default=0.5,
                   metavar="DEG",
                   help="angular radius of the light as mirror spheres see it (distant lights, and point near "
                        "lights from the scene centre; default 0.5)")
    g = p.add_argument_group("scene")
    g.add_argument("--spheres", type=integer(0, 64), default=4, metavar="N",
                   help="number of calibration spheres on a ring around the object (default 4)")
    g.add_argument("--sphere-xy", type=_sphere_xy, default=None, metavar="X,Y;X,Y;...",
                   help="ground positions of the spheres in metres (instead of --spheres); write --sphere-xy=... when "
                        "the first number is negative")
    g.add_argument("--sphere-radius", type=number(0.0, 10.0, lo_open=True), default=0.05, metavar="M", help="sphere radius (default 0.05)")
    g.add_argument("--sphere-material", type=_materials, default="matte", metavar="MAT",
                   help="matte (white), grey, mirror (chrome), glossy_black, mixed, or a comma list per sphere")
    g.add_argument("--no-object", action="store_true", help="spheres only (a calibration shot)")
    g.add_argument("--background", type=_choice("black", "grey", "white", "textured", "checker"), default="grey",
                   metavar="{black,grey,white,textured,checker}",
                   help="table: black, grey (default), white, textured (high-contrast blotches) or checker")
    g.add_argument("--ground-albedo", type=number(0.0, 1.0), default=None, metavar="A",
                   help="table albedo (mean albedo when textured); overrides --background's (grey 0.3)")
    g.add_argument("--lens", type=_choice("normal", "long", "orthographic"), default="normal",
                   metavar="{normal,long,orthographic}",
                   help="normal (46 deg at 1 m, default), long (4.8 deg at 10 m) or orthographic (parallel rays)")
    g.add_argument("--camera-elevation", type=number(1.0, 89.9, unit="degrees"), default=CAMERA_ELEVATION_DEG,
                   metavar="DEG",
                   help="how far the camera looks down at the scene's centre (default 30; 89.9: a copy stand)")
    g.add_argument("--camera-roll", type=number(-45.0, 45.0, unit="degrees"), default=0.0, metavar="DEG",
                   help="the camera turned about its optical axis (a tripod not level; positive dips the "
                        "image's right; default 0)")
    g.add_argument("--calibration-pair", action="store_true",
                   help="write OUT_DIR/calibration (spheres, no object, lights.json) and OUT_DIR/object "
                        "(object, no spheres, no lights.json) under the same lights")
    c = p.add_argument_group("composite test set (docs/composite.md)")
    c.add_argument("--composite-set", default=None, metavar="MAP",
                   help="write OUT_DIR/object (object and spheres), OUT_DIR/surface (ground and spheres alone, other "
                        "lights), and a virtual scene under MAP (a light-map file or built-in name) with a wall and "
                        "another ground albedo: scene_map.exr, background.exr, truth.exr and the masks")
    c.add_argument("--scene-albedo", type=number(0.0, 1.0), default=None, metavar="A",
                   help="ground albedo of the virtual scene (default 0.5; the captures' is --ground-albedo)")
    c.add_argument("--wall-albedo", type=_wall, default=None, metavar="R,G,B|none",
                   help="albedo of the virtual scene's wall (default 0.6,0.35,0.25), or none")
    c.add_argument("--surface-lights", type=N_LIGHTS, default=None, metavar="N",
                   help="lights of the surface capture (default --lights)")
    c.add_argument("--truth-dirs", type=integer(16, 100000), default=None, metavar="N",
                   help="distant lights the map is reduced to for the direct renders (default 2048)")
    f = p.add_argument_group("photograph")
    f.add_argument("--format", dest="file_format", type=_choice("exr", "png8", "png16", "tiff16", "jpeg"),
                   default=None, metavar="{exr,png8,png16,tiff16,jpeg}",
                   help="exr (linear half float, default), png8, png16, tiff16 or jpeg")
    f.add_argument("--encoding", type=_choice("srgb", "linear", "gamma2.2", "filmic"), default=None,
                   metavar="{srgb,linear,gamma2.2,filmic}",
                   help="transfer curve of integer files (default srgb; exr is linear); filmic is a camera-like "
                        "S-shaped tone curve, Hable's filmic operator then sRGB (neither sRGB nor a gamma)")
    f.add_argument("--unstated-encoding", action="store_true",
                   help="leave the encoding out of capture.json (truth.json still records it)")
    f.add_argument("--jpeg-quality", type=integer(0, 100), default=90, metavar="Q", help="JPEG quality 0..100 (default 90)")
    f.add_argument("--exposure", type=number(0.0, 1e6, lo_open=True), default=1.0, metavar="X",
                   help="scale from scene radiance to full scale (default 1: a white sphere peaks at 0.25)")
    f.add_argument("--vignetting", type=_vignetting, default=("none", ()), metavar="MODEL",
                   help="none (default), cos4 (pinhole lenses) or radial:A[,B[,C]] (1 + A r^2 + B r^4 + C r^6, "
                        "r = 1 at the corners)")
    f.add_argument("--shot-noise", type=number(0.0, 1.0), default=0.0, metavar="GAIN",
                   help="Poisson shot noise: full-scale units per electron (variance GAIN * x; e.g. 1e-4)")
    f.add_argument("--read-noise", type=number(0.0, 1.0), default=0.0, metavar="SIGMA",
                   help="Gaussian read noise, fraction of full scale (e.g. 0.002)")
    f.add_argument("--noise", type=number(0.0, 1.0), default=0.0, metavar="SIGMA",
                   help="Gaussian noise, fraction of full scale, added to the encoded value before quantisation "
                        "(default 0)")
    f.add_argument("--srgb8", action="store_true", help="shorthand for --format png8 --encoding srgb")
    p.add_argument("--seed", type=SEED, default=0, metavar="S", help="seed of the light directions and noise (default 0)")
    p.add_argument("--full-sphere", action="store_true", help="draw directions over the full sphere (hemisphere 'full')")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def photo_settings(args: argparse.Namespace):
    """The :class:`ffls.synth.photo.PhotoSettings` of the parsed flags (InputError on a conflict)."""
    from ffls.errors import InputError
    from ffls.synth.photo import PhotoSettings

    fmt, curve = args.file_format, args.encoding
    if args.srgb8:
        if fmt not in (None, "png8") or curve not in (None, "srgb"):
            raise InputError("--srgb8 means --format png8 --encoding srgb; give one or the other")
        fmt, curve = "png8", "srgb"
    fmt = fmt or "exr"
    if fmt == "exr" and curve not in (None, "linear"):
        raise InputError(f"--encoding {curve}: EXR files are linear; choose --format png8, png16, tiff16 or jpeg")
    curve = curve or ("linear" if fmt == "exr" else "srgb")
    if curve in ("gamma2.2", "filmic") and fmt in ("png16", "tiff16") and not args.unstated_encoding:
        raise InputError(f"--encoding {curve} with a 16-bit --format cannot be stated in capture.json (its response "
                         "table is 8-bit): add --unstated-encoding or use png8/jpeg")
    if args.jpeg_quality != 90 and fmt != "jpeg":
        raise InputError("--jpeg-quality needs --format jpeg")
    model, coeffs = args.vignetting
    if model == "cos4" and args.lens == "orthographic":
        raise InputError("--vignetting cos4 needs a pinhole lens (an orthographic lens has no off-axis angle); "
                         "use radial:A")
    return PhotoSettings(file_format=fmt, curve=curve, exposure=args.exposure, vignetting=model,
                         vignetting_coeffs=coeffs, shot_gain=args.shot_noise, read_noise=args.read_noise,
                         noise=args.noise, jpeg_quality=args.jpeg_quality, state_encoding=not args.unstated_encoding)


def scene_of(args: argparse.Namespace):
    """The :class:`ffls.synth.scene.SynthScene` of the parsed flags (InputError on a conflict)."""
    from ffls.errors import InputError
    from ffls.synth.scene import make_scene

    n = len(args.sphere_xy) if args.sphere_xy is not None else args.spheres
    mats = args.sphere_material
    if isinstance(mats, tuple) and len(mats) != n:
        raise InputError(f"--sphere-material lists {len(mats)} materials for {n} spheres")
    if args.no_object and n == 0:
        raise InputError("--no-object with no spheres: the images would show only the table")
    if args.calibration_pair and n == 0:
        raise InputError("--calibration-pair needs spheres (--spheres N >= 1)")
    if getattr(args, "composite_set", None) is not None and (args.calibration_pair or args.no_object):
        raise InputError("--composite-set writes the object and surface captures itself; drop "
                         + ("--calibration-pair" if args.calibration_pair else "--no-object"))
    if args.calibration_pair and args.no_object:
        raise InputError("--calibration-pair writes the object capture itself; drop --no-object")
    background = "textured" if args.background == "checker" else args.background
    kw = {"ground_texture": "checker"} if args.background == "checker" else {}
    if args.ground_albedo is not None:
        kw["ground_albedo"] = args.ground_albedo
    kw["supersample"] = getattr(args, "supersample", 1)
    kw["camera_roll_deg"] = getattr(args, "camera_roll", 0.0)
    kw["camera_elevation_deg"] = getattr(args, "camera_elevation", CAMERA_ELEVATION_DEG)
    return make_scene(spheres=n, sphere_material=mats, background=background, lens=args.lens,
                      with_object=not args.no_object, sphere_xy=args.sphere_xy, sphere_radius=args.sphere_radius, **kw)


def _wall_albedo(args: argparse.Namespace):
    """The wall albedo of ``--wall-albedo``: its default when not given, None for ``none``."""
    if args.wall_albedo is None:
        return WALL_ALBEDO
    return None if args.wall_albedo == "none" else args.wall_albedo


def check_flags_in_effect(args: argparse.Namespace) -> None:
    """Refuse a flag that would change nothing (InputError naming it), as ``--jpeg-quality`` without jpeg.

    ``--surface-lights``, ``--scene-albedo``, ``--wall-albedo`` and ``--truth-dirs`` shape only the
    ``--composite-set`` scene; ``--light-radius`` is the radius of a near light (``--near``).
    """
    from ffls.errors import InputError

    if args.composite_set is None:
        for flag, dest in (("--surface-lights", "surface_lights"), ("--scene-albedo", "scene_albedo"),
                           ("--wall-albedo", "wall_albedo"), ("--truth-dirs", "truth_dirs")):
            if getattr(args, dest) is not None:
                raise InputError(f"{flag} needs --composite-set (it shapes only the composite test set)")
    if args.light_radius is not None and args.near is None:
        raise InputError("--light-radius needs --near (distant lights have no radius; see --light-angle)")


def _object_clearance(scene, c) -> float:
    """Distance (m) from the point ``c`` (3,) to the nearest solid of the scene's object (inf
    without one): its pedestal (a box), body (a sphere) and capsule."""
    from ffls.synth.scene import LABEL_OBJECT

    return min((p.distance(c) for p in scene.primitives()
                if getattr(p, "label", None) == LABEL_OBJECT and hasattr(p, "distance")), default=float("inf"))


def check_spheres_in_frame(args: argparse.Namespace, scene) -> None:
    """Refuse spheres that cannot be photographed (InputError naming the flags that placed them).

    A sphere around the camera (``--sphere-radius 1`` put the camera, 1 m away, inside every
    sphere: a NaN traceback), two spheres that intersect (``--sphere-xy 0.2,0.2;0.2,0.2``, or
    ``--sphere-radius 0.3`` on the default 0.5 m square: written as if they were apart), a sphere
    that intersects the object (``--sphere-xy 0,0``), and
    ``--sphere-xy`` positions whose sphere has no pixel in the image. The frame test is
    :func:`ffls.synth.scene.sphere_silhouettes` (each sphere alone, rays through the pixel
    centres): a sphere out of frame would be written into truth.json with 0 pixels.
    """
    import numpy as np

    from ffls.errors import InputError
    from ffls.synth.scene import sphere_silhouettes

    if scene.n_spheres == 0:
        return
    r = scene.sphere_radius
    flags = (f"--sphere-xy with --sphere-radius {r:g}" if args.sphere_xy is not None else
             f"--sphere-radius {r:g} with --spheres {scene.n_spheres}")
    far = np.linalg.norm(scene.sphere_centers - scene.camera_center(), axis=1)
    if np.any(far <= r):
        k = int(np.argmin(far))
        raise InputError(f"{flags} puts the camera inside sphere {k} (its centre is {far[k]:.3g} m from the camera)")
    xy = np.asarray(scene.sphere_xy, dtype=np.float64)
    gap = np.linalg.norm(xy[:, None] - xy[None], axis=-1) + np.diag(np.full(len(xy), np.inf))
    i, k = np.unravel_index(np.argmin(gap), gap.shape)
    if gap[i, k] < 2 * r * (1 - 1e-9):  # (spheres that touch are apart: 0.3 - 0.2 is 0.0999...)
        raise InputError(f"{flags} makes spheres {min(i, k)} and {max(i, k)} intersect: their centres are "
                         f"{gap[i, k]:.3g} m apart, less than two radii ({2 * r:g} m)")
    for k, c in enumerate(scene.sphere_centers):
        near = _object_clearance(scene, np.asarray(c, dtype=np.float64))
        if near < r * (1 - 1e-9):
            where = ("its centre is inside the object" if near <= 0 else
                     f"its centre is {near:.3g} m from the object, less than its radius {r:g} m")
            raise InputError(f"{flags} makes sphere {k} intersect the object ({where}); --no-object leaves the "
                             "object out")
    if args.sphere_xy is None:
        return
    _, in_frame = sphere_silhouettes(scene, args.resolution)
    out = np.flatnonzero(in_frame == 0)
    if out.size:
        x, y = args.sphere_xy[out[0]]
        raise InputError(f"--sphere-xy {x:g},{y:g} puts sphere {out[0]} out of the frame (no pixel of it in the "
                         f"{args.resolution}x{args.resolution} image)")


def _synth(args: argparse.Namespace, folder) -> dict:
    from ffls.synth.scene import write_calibration_pair, write_synthetic_capture

    kw = dict(
        resolution=args.resolution,
        light_model="distant" if args.near is None else "near",
        light_distance=2.0 if args.near is None else args.near,
        light_radius=args.light_radius or 0.0,
        light_angular_radius_deg=args.light_angle,
        seed=args.seed,
        hemisphere="full" if args.full_sphere else "upper",
        photo=photo_settings(args),
        progress=not args.quiet and sys.stderr.isatty(),  # a bar is for a terminal, not a log
        scene=scene_of(args),
    )
    if args.calibration_pair:
        return write_calibration_pair(folder, n_lights=args.lights, **kw)
    if args.composite_set is not None:
        from ffls.lightmaps.lightmap import lightmap_from_spec
        from ffls.synth.virtual import write_composite_set

        return write_composite_set(folder, lightmap_from_spec(args.composite_set), n_object_lights=args.lights,
                                   n_surface_lights=args.surface_lights, resolution=args.resolution,
                                   scene_albedo=SCENE_ALBEDO if args.scene_albedo is None else args.scene_albedo,
                                   wall_albedo=_wall_albedo(args), seed=args.seed,
                                   truth_dirs=TRUTH_DIRS if args.truth_dirs is None else args.truth_dirs, photo=kw["photo"], progress=kw["progress"],
                                   scene=kw["scene"])
    return write_synthetic_capture(folder, n_lights=args.lights, **kw)


def _mib(nbytes: float) -> str:
    return f"{nbytes / 2**20:.3g} MiB" if nbytes < 2**30 else f"{nbytes / 2**30:.3g} GiB"


def check_estimate(args: argparse.Namespace, out) -> None:
    """Refuse a capture larger than the free space of OUT_DIR's file system; say, before it starts,
    the time and size of one estimated above :data:`ESTIMATE_NOTE_S` (``--lights 100000`` ran for
    many minutes without a word).

    Raises
    ------
    ffls.errors.InputError
        The images need more than the free space (the old capture is replaced only at the end, so
        both must fit).
    """
    import shutil

    from ffls.commands.common import flush_notes, print_notes
    from ffls.errors import InputError, disk_full

    n = args.lights * (2 if args.calibration_pair else 1)
    if args.composite_set is not None:
        n = args.lights + (args.lights if args.surface_lights is None else args.surface_lights)
    px = args.resolution ** 2
    seconds = n * (SECONDS_PER_IMAGE + SECONDS_PER_PIXEL * px * (NEAR_FACTOR if args.near is not None else 1.0))
    size = n * (BYTES_PER_PIXEL[photo_settings(args).file_format] * px + 1024)
    try:
        free = shutil.disk_usage(out.parent if str(out.parent) else ".").free
    except OSError:
        free = None
    what = f"--lights {args.lights} at --resolution {args.resolution}: {n} images"
    if free is not None and size > free:
        raise InputError(f"{what} need up to {_mib(size)}, more than the {_mib(free)} free on its file system"
                         + (" (disk full)" if disk_full(out.parent if str(out.parent) else ".") else ""), out)
    if seconds > ESTIMATE_NOTE_S:
        print_notes(NAME, f"estimate: {what}, about {seconds / 60:.0f} min and up to {_mib(size)} on a "
                          "2-core machine (docs/synth.md); Ctrl-C stops it and leaves the output as it was")
        flush_notes()


def run(args: argparse.Namespace) -> int:
    """Render into a staging folder beside OUT_DIR and swap it in when complete.

    An interrupted or failed ``ffls synth`` leaves OUT_DIR as it was (the old capture, or
    nothing), never new images beside an old ``lights.json`` (:func:`ffls.errors.atomic_folder`).
    An existing OUT_DIR that is not a capture folder (no ``capture.json``, nor the two captures of
    ``--calibration-pair``) is not replaced.
    """
    from pathlib import Path

    from ffls.errors import InputError, atomic_folder

    check_flags_in_effect(args)
    if args.near is not None and args.light_radius is not None and args.light_radius >= args.near:
        raise InputError(f"--light-radius {args.light_radius:g} must be smaller than --near {args.near:g} "
                         "(the light would enclose the scene)")
    photo_settings(args)  # conflicting flags: one line before anything is written
    check_spheres_in_frame(args, scene_of(args))
    if args.near is not None and args.near <= scene_of(args).reach():  # (1e-300: a ZeroDivisionError traceback)
        raise InputError(f"--near {args.near:g} puts the lights inside the scene: its object and spheres reach "
                         f"{scene_of(args).reach():.3g} m from the centre")
    if args.composite_set is not None:
        from ffls.lightmaps.lightmap import lightmap_from_spec

        if args.near is not None:
            raise InputError("--composite-set renders distant lights; drop --near")
        lightmap_from_spec(args.composite_set)  # a bad map: one line before anything is rendered
    out = Path(args.out_dir)
    captures = [out / "capture.json", out / "calibration" / "capture.json", out / "composite.json"]
    if out.is_dir() and any(out.iterdir()) and not any(c.is_file() for c in captures):
        raise InputError("exists, is not empty and holds no capture.json: refusing to replace it", out)
    check_estimate(args, out)
    t = time.perf_counter()
    with atomic_folder(out) as stage:
        res = _synth(args, stage)
    dt = time.perf_counter() - t
    if args.composite_set is not None:
        print(f"wrote {out / 'object'} ({res['params']['n_object_lights']} lights), {out / 'surface'} "
              f"({res['params']['n_surface_lights']} lights), scene_map.exr, background.exr, truth.exr, "
              f"object_mask.png, surface_mask.png, sphere_mask.png and composite.json to {out} in {dt:.1f} s")
    elif args.calibration_pair:
        cal, obj = out / "calibration", out / "object"
        print(f"wrote {len(res['calibration']['images'])} images, capture.json, lights.json and truth.json to {cal}, "
              f"and {len(res['object']['images'])} images, capture.json and truth.json (no lights.json: use --lights "
              f"{cal / 'lights.json'}) to {obj} in {dt:.1f} s")
    else:
        print(f"wrote {len(res['images'])} images, capture.json, lights.json and truth.json to {out} in {dt:.1f} s")
    return 0
