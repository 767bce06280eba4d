"""``ffls probe``: light maps from photographs of a probe (:func:`ffls.probes.estimate_lightmap`), and bracket merging."""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "probe"
#: The attribute that names the chosen method (``ffls probe METHOD``): error lines name ``ffls probe METHOD``.
SUBCOMMAND_DEST = "method"
HELP = "estimate a light map from photos of a probe (mirror, diffuse, shadow, pocs), or merge an exposure bracket"
DESCRIPTION = (
    "probe METHOD FOLDER -o MAP.exr: FOLDER holds probe.json (docs/formats.md); the map is a lat-long "
    "EXR in the world frame whose alpha marks the directions the probe saw. "
    "probe merge IMAGES... -o HDR.exr: merge an exposure bracket (Debevec-Malik hat weights, zero at "
    "the clipping limits); exposure times from --exposures or the images' EXIF."
)

OUTPUT_SUFFIXES = (".exr",)
#: CPU seconds of ``ffls probe pocs`` per unit of work on the 2-core team machine, for fits over
#: the default 2000 pixels (``benchmarks/pocs_time.py``, docs/probes.md "Time of POCS"): per sweep
#: of the adaptive set's rounds and folds (least-power, the default, and sequential, which grow the
#: set by the same sweeps: 0.417 s); per sweep and unknown on the grid (sequential: 2.4e-5 s). The
#: others have no rate: their time is not the sweeps' (below).
POCS_RATES = {("adaptive", "least-power"): 0.417, ("adaptive", "sequential"): 0.417,
              ("grid", "sequential"): 2.4e-5}
#: Above this many grid unknowns, dykstra and least-power solve a linear programme over the pixels
#: and the unknowns (dykstra's residual bound, least-power's map) that takes more than half a minute:
#: 5 dykstra sweeps took 11.0 s at ``--grid 32`` and 36.9 s at ``--grid 48`` (4608 unknowns;
#: ``benchmarks/pocs_time.py``; 20 sweeps at 32 took 10.2 s in an earlier run): the time is the
#: programme's, not the sweeps'. No rate is measured for it: it is said to have none.
POCS_LP_UNKNOWNS_NOTE = 2 * 48 * 48
#: The pixel count the rates were measured at (each rate scales with the pixels a fit uses).
POCS_RATE_PIXELS = 2000
ENCODING_FORMS = "srgb, linear, gamma=G, response=FILE.npy|.csv, or calibrate (8-bit brackets)"


def _encoding_arg(text: str):
    """``--encoding``: 'srgb', 'linear', 'gamma=G', 'response=FILE' or 'calibrate'."""
    from ffls.io.capture import GAMMA_RANGE

    t = str(text).strip()
    if t in ("srgb", "linear", "calibrate"):
        return t
    if t.startswith("gamma="):
        try:
            g = float(t[6:])
        except ValueError:
            g = float("nan")
        if not GAMMA_RANGE[0] <= g <= GAMMA_RANGE[1]:
            raise argparse.ArgumentTypeError(f"gamma must be between {GAMMA_RANGE[0]} and {GAMMA_RANGE[1]}, "
                                             f"not {t[6:]!r}")
        return {"gamma": g}
    if t.startswith("response=") and len(t) > 9:
        return {"response": t[9:]}
    raise argparse.ArgumentTypeError(f"expected {ENCODING_FORMS}, not {text!r}")


def _add_mirror(sub, common):
    from ffls.commands.common import integer, number

    p = sub.add_parser("mirror", parents=[common], help="a mirror ball (Debevec 1998)",
                       description="Unwrap one or more views of a mirror ball with exact perspective "
                                   "(or orthographic) reflection; views are merged with a confidence per direction.")
    p.add_argument("--camera-cone", type=number(0.0, 90.0, unit="degrees"), default=None, metavar="DEG",
                   help="mask this cone around the direction toward the camera (camera and photographer); "
                        "0 keeps it (default: atan(0.5 / D) for a ball located in scene units at the "
                        "distance D from the camera, else 10)")
    p.add_argument("--rim", type=number(0.0, 100.0, unit="pixels"), default=1.0, metavar="PX",
                   help="leave out this rim of the ball, pixels (default 1)")
    p.add_argument("--supersample", type=integer(1, 16), default=None,
                   help="directions per texel side, 1 to 16 (default: about 4 samples per pixel of the ball)")
    p.add_argument("--weight-power", type=number(0.0, 16.0), default=2.0, metavar="P",
                   help="views are merged with weights confidence**P (default 2)")
    p.add_argument("--fill", choices=("nearest", "zero"), default="nearest",
                   help="unseen directions: from the nearest seen ones (default) or black")
    return p


def _sources_arg(text: str):
    """``--sources`` / ``--nodes``: a positive integer, 'auto', 'adaptive' or 'uniform'."""
    t = str(text).strip().lower()
    if t in ("auto", "adaptive", "uniform"):
        return t
    try:
        n = int(t)
    except ValueError:
        n = 0
    if n > 100000:
        raise argparse.ArgumentTypeError(f"at most 100000, not {text!r}")
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, 'auto', 'adaptive' or 'uniform', not {text!r}")
    return n


def _add_inverse(sub, common):
    from ffls.commands.common import integer, number

    shared = type(common)(add_help=False)  # (the command line's parser class: its store rules)
    shared.add_argument("--criterion", choices=("cv", "bic"), default="cv",
                        help="how the model size is chosen when 'auto': cross-validation (default) or BIC")
    # default None: diffuse's own (cv, 0 with --orientations > 1; ffls.probes.estimate.diffuse_lightmap), 0 elsewhere
    shared.add_argument("--smoothness", type=number(0.0, 1e6, special=("cv",)), default=None,
                        help="first-difference penalty between neighbouring sources (default 0: the paper's fit); "
                             "diffuse also takes cv: the weight chosen by blocked cross-validation (diffuse's "
                             "default, 0 with --orientations > 1)")
    shared.add_argument("--fill", choices=("nearest", "zero"), default="nearest",
                        help="directions not seen: the method's own values (default) or black")
    d = sub.add_parser("diffuse", parents=[common, shared], help="a diffuse sphere (Hougen-Ahuja 1993)",
                       description="Least squares over model sources (5, 9, 17 rings or geodesic sets) with a "
                                   "free ambient term, from a diffuse sphere.")
    d.add_argument("--sources", type=_sources_arg, default="auto", metavar="N|auto|adaptive|uniform",
                   help="model sources: 5, 9, 17 (rings), any other count (geodesic), uniform (a uniform set chosen "
                        "by --criterion), or adaptive = auto (default: a geodesic set refined where the light is)")
    d.add_argument("--unconstrained", action="store_true",
                   help="plain least squares (the paper) instead of non-negative intensities (scipy nnls)")
    d.add_argument("--ambient", choices=("auto", "nonnegative", "free", "none"), default="auto",
                   help="ambient term: auto (default: none when the sources cover the sphere, as geodesic and "
                        "adaptive sets do; non-negative with the 5, 9, 17 rings), non-negative, free (the paper's; "
                        "may be negative) or none")
    d.add_argument("--rcond", type=number(0.0, 1.0, lo_open=True), default=None,
                   help="with --unconstrained: truncate singular values below RCOND x the largest")
    d.add_argument("--orientations", type=integer(1, 64), default=1,
                   help="with adaptive sources: average the estimate over this many orientations of the geodesic "
                        "source set (default 1: one estimate; costs as many estimates)")
    d.add_argument("--azimuths", type=integer(1, 64), default=1,
                   help="with adaptive sources: make the estimate with the source set's vertex on the world's up "
                        "(probe.json's plane normal, else +Z) in this many azimuths about it, the same elevations "
                        "in each, and average them (default 1: one estimate; costs as many estimates)")
    d.add_argument("--prior", choices=("quadratic", "tv", "power"), default=None,
                   help="what --smoothness penalises: the squared differences between neighbouring sources "
                        "(quadratic), their absolute values (tv: total variation, keeps small lamps sharp) "
                        "or the light's total power (power: of the maps the ball cannot tell apart the least "
                        "powerful, whatever the source set's orientation). Default: power with --smoothness cv, "
                        "quadratic with a stated weight")
    d.add_argument("--rule", choices=("paired_se", "one_se"), default="paired_se",
                   help="how cross-validation chooses the adaptive set's refinement and the --smoothness cv weight: "
                        "within one standard error of the paired fold differences (paired_se, default) or the rules "
                        "before (one_se: the set within 5%% of the best, the weight within one fold spread)")
    d.add_argument("--ground", action="store_true",
                   help="sources only above the ground plane (probe.json's plane, else the world +Z), the light "
                        "below it one uniform term")
    s = sub.add_parser("shadow", parents=[common, shared], help="a cast shadow (Sato-Sato-Ikeuchi 1999)",
                       description="Dome node intensities from the shadow of a known occluder on a plane.")
    s.add_argument("--nodes", type=_sources_arg, default="auto", metavar="N|auto|adaptive|uniform",
                   help="dome nodes (e.g. 521), uniform (a uniform dome chosen by --criterion), or adaptive = auto "
                        "(default: a dome refined where the light is and its shadow in view)")
    s.add_argument("--case", choices=("lambertian", "torrance_sparrow", "ratio"), default="lambertian",
                   help="receiver model: Lambertian with known albedo (default), simplified Torrance-Sparrow, or "
                        "the ratio to surface_image (unknown albedo)")
    s.add_argument("--ks", type=number(0.0, 1e6), default=None, help="torrance_sparrow: specular coefficient K_s")
    s.add_argument("--sigma", type=number(0.0, 90.0, lo_open=True, unit="degrees"), default=None,
                   help="torrance_sparrow: lobe width, degrees")
    s.add_argument("--unconstrained", action="store_true", help="plain least squares instead of NNLS")
    q = sub.add_parser("pocs", parents=[common], help="a diffuse sphere by POCS (Singh-Ahuja)",
                       description="Projections onto convex sets from a diffuse sphere. By default (adaptive sources) the "
                                   "map of least total power within the residual the data allow (--scheme "
                                   "least-power); "
                                   "--scheme sequential is Singh and Ahuja's method (amplitude and residual "
                                   "projections in random order), whose residual per iteration is reported.")
    q.add_argument("--sources", choices=("auto", "adaptive", "grid"), default="auto",
                   help="unknowns: a geodesic source set refined where the light is, chosen by --criterion "
                        "(adaptive = auto, default), or the paper's lat-long grid of --grid rows (grid)")
    q.add_argument("--criterion", choices=("cv", "bic"), default="cv",
                   help="how the adaptive set's refinement is chosen: cross-validation (default) or BIC")
    q.add_argument("--grid", type=integer(2, 256), default=None,
                   help="with --sources grid: height of the grid of unknowns (default 16)")
    q.add_argument("--iterations", type=integer(1, 100000), default=None,
                   help="sweeps (default 50; 3000 with --scheme extrapolated or dykstra; with least-power, the "
                        "sweeps that grow the adaptive set); the cap with --tol")
    q.add_argument("--scheme", choices=("least-power", "sequential", "extrapolated", "dykstra"), default=None,
                   help="least-power (the default on adaptive sources): the map of least total power within the "
                        "L1 residual the data allow (a linear programme; on adaptive sources, grown by the paper's "
                        "sweeps, its lit sources refitted and averaged over pixel subsets); sequential: the paper's "
                        "method, Singh and Ahuja's sweeps of row projections (the default with --sources grid); "
                        "extrapolated parallel projections (Combettes), which converge to the least-squares point "
                        "when noise leaves no common point; or Dykstra's best approximation: the least-norm map "
                        "within the residual the data allow")
    q.add_argument("--relaxation", type=number(0.0, 2.0, lo_open=True, hi_open=True), default=1.0,
                   help="relaxation of the projections, in (0, 2); at most 1 with --scheme extrapolated")
    q.add_argument("--tol", type=number(0.0, 1.0, lo_open=True), default=None,
                   help="stop when a sweep changes the estimate by less than this fraction (default: fixed sweeps)")
    q.add_argument("--upper", type=number(0.0, None, lo_open=True), default=None,
                   help="upper amplitude bound on the radiance (default none)")
    q.add_argument("--order", choices=("random", "sequential"), default=None,
                   help="with --scheme sequential: projection order (default random)")
    q.add_argument("--seed", type=integer(0, 2**32 - 1), default=None,
                   help="with --scheme sequential and a random order: seed of the order (default 0)")
    q.add_argument("--fill", choices=("nearest", "zero"), default="nearest",
                   help="directions not seen: the method's own values (default) or black")


def add_arguments(p):
    from ffls.commands.common import MAP_HEIGHT, float_list, input_path, output_path

    sub = p.add_subparsers(dest="method", metavar="METHOD", required=True)
    common = type(p)(add_help=False)  # (the command line's parser class: its store rules)
    common.add_argument("folder", metavar="FOLDER", type=input_path, help="probe folder (probe.json)")
    common.add_argument("-o", "--out", required=True, type=output_path(OUTPUT_SUFFIXES),
                        help="output lat-long map, .exr (alpha: the directions seen)")
    common.add_argument("--size", type=MAP_HEIGHT, default=128, metavar="H",
                        help="map height, 4 to 16384 (width twice it; default 128)")
    common.add_argument("--half", action="store_true", help="write half floats")
    _add_mirror(sub, common)
    _add_inverse(sub, common)
    m = sub.add_parser("merge", help="merge an exposure bracket into one HDR image",
                       description="Merge bracketed exposures (8-, 16-bit or float) with hat weights that fall to "
                                   "zero at the clipping limits; pixels clipped in every exposure get alpha 0.")
    m.add_argument("images", nargs="+", metavar="IMAGE", type=input_path,
                   help="the bracketed images (two or more, one size)")
    m.add_argument("-o", "--out", required=True, type=output_path(OUTPUT_SUFFIXES), help="output .exr")
    m.add_argument("--exposures", type=float_list(0.0, None, min_len=2), default=None, metavar="T1,T2,...",
                   help="exposure times in seconds, one per image (default: each image's EXIF ExposureTime)")
    m.add_argument("--encoding", type=_encoding_arg, default=None, metavar="ENC",
                   help=f"how the stored values encode light: {ENCODING_FORMS}; required for 8/16-bit images "
                        "(ffls does not guess), float images are linear")
    m.add_argument("--half", action="store_true", help="write half floats")


def _merge(args) -> int:
    import numpy as np

    from ffls.commands.common import print_notes
    from ffls.errors import InputError
    from ffls.io.images import colour_summary, read_image, write_exr
    from ffls.io.response import load_response
    from ffls.io.probe import exposure_time_problem
    from ffls.probes.bracket import exposure_from_exif, merge_bracket_files

    paths = [Path(p) for p in args.images]
    if len(paths) < 2:
        raise InputError("a bracket needs at least two images", paths[0])
    seen = {}
    for p in paths:
        key = p.resolve()
        if key in seen:
            also = f" (also as {seen[key]})" if str(seen[key]) != str(p) else ""
            raise InputError(f"listed twice in the bracket{also}", p)
        seen[key] = p
    if args.exposures is not None:
        if len(args.exposures) != len(paths):
            raise InputError(f"--exposures: {len(args.exposures)} times for {len(paths)} images")
        for t in args.exposures:
            why = exposure_time_problem(t)
            if why:
                raise InputError(f"--exposures: {why}")
        times = [float(t) for t in args.exposures]
        how = "from --exposures"
    else:
        times = [exposure_from_exif(p) for p in paths]
        how = "from EXIF"
    enc, response = ("auto" if args.encoding is None else args.encoding), None  # auto: not stated
    if isinstance(enc, dict) and "response" in enc:
        response = load_response(enc["response"]).astype(np.float64)
    elif enc == "calibrate":
        from ffls.radiance.response import bracket_problem, recover_response_DebevecMalik1997

        imgs = [read_image(p) for p in paths]
        bad = [im for im in imgs if im.bit_depth != 8]
        if bad:
            raise InputError("--encoding calibrate recovers the response of 8-bit images; this one is "
                             f"{bad[0].bit_depth}", bad[0].path)
        if np.ptp(times) <= 1e-9 * max(times):
            raise InputError(f"all {len(times)} exposure times are equal ({times[0]:.6g} s): not a bracket", paths[0])
        codes = [np.rint(im.pixels * 255).astype(np.uint8) for im in imgs]
        why = bracket_problem(codes)
        if why:
            raise InputError(f"--encoding calibrate: {why}", paths[0])
        response = recover_response_DebevecMalik1997(codes, np.asarray(times, dtype=np.float32)).astype(np.float64)
        enc = {"response": "calibrated"}
        print_notes(NAME, "camera response recovered from the bracket (Debevec-Malik 1997)")
    m = merge_bracket_files(paths, times, enc, response, source=paths[0], key="--encoding", forms=ENCODING_FORMS)
    alpha = (~m.saturated).astype(np.float32)
    write_exr(args.out, m.radiance, half=args.half, alpha=alpha)
    print_notes(NAME, f"exposure times {how}; " + m.describe(), colour_summary(paths))
    print(f"wrote {args.out} ({m.radiance.shape[1]}x{m.radiance.shape[0]}, alpha 0 where saturated in every "
          f"exposure)")
    return 0


def method_knobs(args) -> dict:
    """The ``estimate_lightmap`` keyword arguments of the parsed method flags."""
    if args.method == "mirror":
        return {"camera_cone_deg": args.camera_cone, "rim_px": args.rim, "supersample": args.supersample,
                "weight_power": args.weight_power, "fill": args.fill}
    if args.method == "diffuse":
        ambient = {"auto": "auto", "nonnegative": "nonnegative", "free": True, "none": False}[args.ambient]
        if args.orientations > 1 and (args.sources not in ("auto", "adaptive") or args.smoothness == "cv"):
            from ffls.errors import InputError

            raise InputError(f"--orientations applies to --sources auto or adaptive without --smoothness cv, not "
                             f"--sources {args.sources}" + (" --smoothness cv" if args.smoothness == "cv" else ""))
        if args.azimuths > 1 and (args.sources not in ("auto", "adaptive") or args.orientations > 1
                                         or args.ground):
            from ffls.errors import InputError

            given = ((f"--sources {args.sources}", args.sources not in ("auto", "adaptive")),
                     (f"--orientations {args.orientations}", args.orientations > 1), ("--ground", args.ground))
            raise InputError(f"--azimuths {args.azimuths} applies to --sources auto or adaptive without --orientations "
                             f"or --ground, not " + " ".join(f for f, on in given if on))
        if args.prior not in (None, "quadratic") and (args.smoothness == 0
                                                        or args.smoothness is None and args.orientations > 1):
            from ffls.errors import InputError

            raise InputError(f"--prior {args.prior} weighs --smoothness: give it a weight or cv (it is 0)")
        return {"sources": args.sources, "nonnegative": not args.unconstrained, "ambient": ambient,
                "rcond": args.rcond, "criterion": args.criterion, "smoothness": args.smoothness, "fill": args.fill,
                "orientations": args.orientations, "ground": args.ground, "prior": args.prior, "rule": args.rule,
                "azimuths": args.azimuths}
    if args.method == "shadow":
        if args.smoothness == "cv":
            from ffls.errors import InputError

            raise InputError("--smoothness cv applies to diffuse (a weight chosen on the ball's pixels); give shadow "
                             "a number")
        return {"nodes": args.nodes, "case": args.case, "nonnegative": not args.unconstrained, "ks": args.ks,
                "sigma_deg": args.sigma, "criterion": args.criterion,
                "smoothness": 0.0 if args.smoothness is None else args.smoothness,
                "fill": args.fill}
    if args.method == "pocs":
        from ffls.errors import InputError

        # a flag of another setting would be ignored: refused, not dropped in silence
        if args.grid is not None and args.sources != "grid":
            raise InputError(f"--grid applies with --sources grid (the grid of unknowns), not --sources {args.sources}")
        # the default scheme of the sources (ffls.probes.estimate.POCS_DEFAULT_SCHEME, not imported here: 2 s)
        scheme = args.scheme or ("sequential" if args.sources == "grid" else "least-power")
        if scheme != "sequential":
            for flag, value in (("--order", args.order), ("--seed", args.seed)):
                if value is not None:
                    raise InputError(f"{flag} applies with --scheme sequential (the sweeps' projection order); "
                                     f"--scheme {scheme} has no order of projections" + (
                                         " (the default on adaptive sources)" if args.scheme is None else ""))
        elif args.seed is not None and args.order == "sequential":
            raise InputError("--seed applies with a random projection order, not --order sequential")
        return {"grid": 16 if args.grid is None else args.grid, "iterations": args.iterations, "upper": args.upper,
                "order": args.order or "random", "seed": args.seed or 0, "fill": args.fill, "sources": args.sources,
                "criterion": args.criterion, "scheme": scheme, "relaxation": args.relaxation, "tol": args.tol}
    return {}


def _probe_colour_note(folder) -> str | None:
    """The ``colour:`` line of a probe folder's photos converted to the working space on reading
    (:func:`ffls.io.images.colour_summary`), as ``relight`` prints it for a capture."""
    from ffls.io.images import colour_summary
    from ffls.io.probe import load_probe

    probe = load_probe(folder)
    paths = [im.path for view in probe.views for im in view.images]
    return colour_summary(paths + ([probe.surface_image] if probe.surface_image is not None else []))


def pocs_seconds(scheme: str, sources: str, grid: int, iterations: int, pixels: int) -> float | None:
    """The estimated seconds of a POCS solve from :data:`POCS_RATES` (None where none is measured)."""
    rate = POCS_RATES.get((sources, scheme))
    if rate is None:
        return None
    return rate * pixels / POCS_RATE_PIXELS * iterations * (2 * grid * grid if sources == "grid" else 1)


def say_pocs_estimate(scheme: str, sources: str, grid: int, iterations: int, pixels: int) -> None:
    """``pocs_lightmap``'s ``before_solve``: say the estimate before a solve of more than
    :data:`ffls.commands.common.ESTIMATE_NOTE_S` (``--iterations 100000`` ran for minutes without a word)."""
    from ffls.commands.common import ESTIMATE_NOTE_S, flush_notes, print_notes

    seconds = pocs_seconds(scheme, sources, grid, iterations, pixels)
    unknowns = 2 * grid * grid
    if seconds is None and sources == "grid" and scheme in ("dykstra", "least-power") \
            and unknowns > POCS_LP_UNKNOWNS_NOTE:
        print_notes(NAME, f"--sources grid --grid {grid} ({unknowns} unknowns), --scheme {scheme}: a linear "
                          f"programme over {pixels} pixels and {unknowns} unknowns, with no time estimate; --grid "
                          "48 (4608) took 37 s on a 2-core machine, and the time grows faster than the "
                          "unknowns (docs/probes.md, \"Time of POCS\"); Ctrl-C stops it and writes nothing")
        flush_notes()
    if seconds is None or seconds <= ESTIMATE_NOTE_S:
        return
    what = (f"--sources grid --grid {grid} ({2 * grid * grid} unknowns)" if sources == "grid"
            else "adaptive sources") + f", --scheme {scheme}, {iterations} sweeps, {pixels} pixels"
    print_notes(NAME, f"estimate: {what}: about {seconds / 60:.0f} min on a 2-core machine (docs/probes.md, "
                      "\"Time of POCS\"); Ctrl-C stops it and writes nothing")
    flush_notes()


def run(args) -> int:
    from ffls.commands.common import print_notes
    from ffls.probes import estimate_lightmap, save_estimate

    if args.method == "merge":
        return _merge(args)
    knobs = method_knobs(args)
    if args.method == "pocs":
        knobs["before_solve"] = say_pocs_estimate
    est = estimate_lightmap(args.folder, method=args.method, height=args.size, **knobs)
    save_estimate(est, args.out, half=args.half)
    print_notes(NAME, *est.notes, _probe_colour_note(args.folder))
    h = est.lightmap.data.shape[0]
    print(f"wrote {args.out} ({2 * h}x{h} lat-long, {args.method}; alpha: the "
          f"{100 * est.details.get('seen_fraction', float(est.seen.mean())):.1f}% of directions seen)")
    return 0
