"""``ffls lights CAPTURE``: estimate each photograph's light direction from the spheres."""
from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

import numpy as np

NAME = "lights"
HELP = "estimate each photo's light direction from the white spheres"
DESCRIPTION = ("Fit every photo's spheres (Lambert + ambient + ground bounce), combine them into one "
               "distant or near light, reject inconsistent photos, and write lights.json. Integer images "
               "whose encoding capture.json does not state are first calibrated from the matte spheres "
               "(a gamma, or the sRGB curve); the result is printed and recorded in lights.json.")


def add_arguments(p):
    from ffls.commands.common import WORKERS, input_path, integer, output_path, scheduler_type

    p.add_argument("capture", type=input_path, help="capture folder (with capture.json)")
    p.add_argument("-o", "--output", default=None, type=output_path((".json",)),
                   help="lights.json to write (default: CAPTURE/lights.json)")
    p.add_argument("--model", choices=("auto", "distant", "near"), default="auto",
                   help="light model: chosen per photo (auto), distant or near (default auto)")
    p.add_argument("--bounce", choices=("calibrated", "free", "observed"), default="calibrated",
                   help="ground bounce: each sphere's ground ratio calibrated over the capture and imposed "
                        "(two passes), free per photo, or observed: calibrated, with each sphere's bounce from "
                        "the ground photographed around it (needs camera.world_from_camera and --model distant; "
                        "docs/spheres.md) "
                        "(default calibrated)")
    p.add_argument("--bounce-shape", choices=("auto", "on", "off"), default="auto",
                   help="with --bounce calibrated, give each matte sphere's bounce the horizontal gradient its "
                        "shadow sides show over the capture (a textured ground, an object hiding part of it): "
                        "on, off, or auto, on only with one matte sphere (default auto; docs/spheres.md)")
    p.add_argument("--workers", type=WORKERS, default=None,
                   help="processes, 1 to 4 per core (default: every core)")
    p.add_argument("--first-pass", type=integer(1, 1_000_000, special={"all": 0}), default=None, metavar="N|all",
                   help="with --bounce calibrated, fit only N photos spread over the sequence in the first pass (it "
                        "feeds the centre refinement, the flat field and the bounce calibration; the second pass "
                        "fits every photo), or all of them (default: ffls.spheres.estimate.FIRST_PASS_PHOTOS; "
                        "docs/spheres.md, Speed)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT|local", type=scheduler_type(allow_local=True),
                   help="read and linearise the photos on Dask: a dask.distributed cluster, or 'local' for a local "
                        "cluster of --workers processes (docs/scale.md)")
    p.add_argument("--fit-roll", action="store_true",
                   help="where capture.json gives no camera.world_from_camera, fit the camera's roll about its "
                        "axis with its tilt (a tripod not level); off by default: an object beside a sphere can "
                        "pass for a roll (docs/spheres.md, 'The search's cost, and the camera's roll')")
    p.add_argument("--plot", default=None, type=output_path((".png",)), metavar="PLOT.png",
                   help="draw the accepted directions and their Voronoi cells on the hemisphere")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (bars are drawn only on a terminal, and not when CI is set)")
    p.add_argument("--lp", default=None, type=output_path((".lp",)), metavar="OUT.lp",
                   help="also write the accepted lights as an RTI .lp file (camera frame; docs/formats.md)")


#: How many rejected photos of each reason the summary names
REJECTED_NAMED = 4


def summary(lights) -> str:
    """One-paragraph summary: accepted, rejected by reason (the first photos named), median uncertainty."""
    from ffls.spheres.photo import REASONS

    n = len(lights)
    ok = lights.ok_mask
    reasons = Counter(r for r, s in zip(lights.reasons, lights.status) if s == "rejected")
    unc = [e.get("uncertainty_deg") for e, s in zip(lights.extra, lights.status) if s == "ok"]
    unc = [u for u in unc if u is not None]
    models = Counter(e.get("model") for e, s in zip(lights.extra, lights.status) if s == "ok")
    lines = [f"{int(ok.sum())} of {n} lights accepted"
             + (f" ({', '.join(f'{v} {k}' for k, v in sorted(models.items()))})" if models else "")]
    for k, (reason, count) in enumerate(reasons.most_common()):
        # each reason's photos named (the first few) with what it means: a misfired flash's photos
        # were only counted ("rejected: no_highlight 4"), the names only in lights.json
        names = [m for m, r, s in zip(lights.image_names, lights.reasons, lights.status)
                 if s == "rejected" and r == reason]
        shown = _first_named(names, ", ")
        meaning = REASONS.get(reason)
        lines.append(("rejected: " if k == 0 else "          ") + f"{reason} {count} ({shown})"
                     + (f": {meaning}" if meaning else ""))
    if unc:
        lines.append(f"median uncertainty {float(np.median(unc)):.2f} deg (radius of the 95% cone)")
    shapes = next((e["spheres"] for e in lights.extra if e and e.get("spheres")), [])
    shaped = [(k, r["bounce_gradient"]) for k, r in enumerate(shapes) if r.get("bounce_gradient") is not None]
    if shaped:
        lines.append("ground bounce shaped (--bounce-shape): " + "; ".join(
            f"sphere {k} gradient ({g[0]:+.3f}, {g[1]:+.3f})" for k, g in shaped))
    return "\n".join(lines)


def _first_named(items: list[str], sep: str) -> str:
    """The first :data:`REJECTED_NAMED` of ``items`` joined by ``sep``, then how many more."""
    more = f"{sep}... ({len(items) - REJECTED_NAMED} more)" if len(items) > REJECTED_NAMED else ""
    return sep.join(items[:REJECTED_NAMED]) + more


def spheres_summary(spheres) -> str:
    """One line: how many spheres were found and, per sphere, its kind (when known) and pixel circle."""
    parts = []
    for ft in spheres:
        kind = getattr(ft, "kind", None)
        parts.append(f"{kind + ' ' if kind else ''}at ({ft.center_px[0]:.1f}, {ft.center_px[1]:.1f}) px, "
                     f"radius {ft.radius_px:.1f} px")
    n = len(parts)
    return f"{n} sphere{'s' if n != 1 else ''} found: " + "; ".join(parts)


def plot_lights(lights, path, hemisphere: str = "upper", res: int = 400) -> Path:
    """PNG of the light directions with their angular Voronoi cells on the hemisphere disc.

    The hemisphere is drawn on the disc of Shirley and Chiu's concentric map with the
    equal-area lift (area on the disc is proportional to solid angle): +Z at the centre, the
    horizon on the rim, +X to the right, +Y up. Rings mark 30 and 60 degrees from the zenith.
    Accepted lights are black dots, rejected ones red crosses; a ``full`` capture gets a second
    disc for the lower hemisphere (seen from above).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ffls.errors import atomic_output
    from ffls.lightmaps.sphere_maps import disc_to_hemisphere, hemisphere_to_disc
    from ffls.weights.voronoi import assign_cells

    idx, d = lights.accepted()
    rejected = np.asarray(lights.directions)[~np.asarray(lights.ok_mask, dtype=bool)]
    halves = [False] if hemisphere == "upper" else [False, True]
    fig, axes = plt.subplots(1, len(halves), figsize=(6 * len(halves), 6.4), dpi=100, squeeze=False)
    t = (np.arange(res) + 0.5) / res * 2.0 - 1.0
    x, y = np.meshgrid(t, -t)  # image rows go down, +Y up
    inside = x * x + y * y <= 1.0
    rng = np.random.default_rng(0)
    perm = rng.permutation(max(len(d), 1))
    for ax, lower in zip(axes[0], halves):
        if len(d):
            lab = np.full(x.shape, -1, dtype=np.int64)
            pixel_dirs = disc_to_hemisphere(np.hypot(x[inside], y[inside]), np.arctan2(y[inside], x[inside]), lower)
            lab[inside] = assign_cells(pixel_dirs, d)
            border = np.zeros(lab.shape, dtype=bool)
            border[:, :-1] |= lab[:, :-1] != lab[:, 1:]
            border[:-1, :] |= lab[:-1, :] != lab[1:, :]
            img = np.where(lab >= 0, perm[np.maximum(lab, 0) % len(perm)], np.nan).astype(float)
            ax.imshow(np.ma.masked_invalid(img), cmap="tab20", extent=(-1, 1, -1, 1), interpolation="nearest",
                      alpha=0.55)
            ax.imshow(np.ma.masked_where(~(border & inside), border.astype(float)), cmap="gray_r",
                      extent=(-1, 1, -1, 1), interpolation="nearest", vmin=0, vmax=1)
        for pts, style in ((d, "k."), (rejected, "rx")):
            sel = pts[(pts[:, 2] < 0) == lower] if len(pts) else pts
            if len(sel):
                r, phi = hemisphere_to_disc(sel)
                ax.plot(r * np.cos(phi), r * np.sin(phi), style, ms=4)
        ang = np.linspace(0, 2 * np.pi, 200)
        for theta in (30, 60, 90):
            r = np.sqrt(1.0 - np.cos(np.radians(theta)))
            ax.plot(r * np.cos(ang), r * np.sin(ang), color="0.4", lw=0.6 if theta < 90 else 1.0)
        ax.text(1.02, 0, "+X", va="center")
        ax.text(0, 1.03, "+Y", ha="center")
        ax.set_xlim(-1.1, 1.1)
        ax.set_ylim(-1.1, 1.1)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(("lower" if lower else "upper") + " hemisphere (+Z at centre; rings 30, 60, 90 deg)"
                     if len(halves) > 1 else "hemisphere: +Z at centre; rings at 30, 60, 90 deg", fontsize=9)
    fig.suptitle(f"{len(d)} accepted light directions ({len(rejected)} rejected, red x) and their Voronoi cells")
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return Path(path)


def check_first_pass(first_pass, bounce: str, n_photos: int) -> None:
    """``--first-pass N`` against the capture: N above its photo count meant every photo silently,
    and with ``--bounce free`` there is no first pass (every photo is fitted once)."""
    from ffls.errors import InputError

    if not first_pass:  # (not given, or "all": every photo, as --bounce free fits them)
        return
    if bounce not in ("calibrated", "observed"):
        raise InputError(f"--first-pass applies only with --bounce calibrated or observed (--bounce {bounce} fits "
                         "every photo once)")
    if first_pass > n_photos:
        raise InputError(f"--first-pass {first_pass} is more than the capture's {n_photos} photos: give at most "
                         f"{n_photos}, or --first-pass all")


def check_bounce_shape(bounce_shape: str, bounce: str) -> None:
    """``--bounce-shape on|off`` only with ``--bounce calibrated``: the other bounces have no shape to
    turn on or off (``off`` with ``--bounce free`` was accepted and changed nothing)."""
    from ffls.errors import InputError

    if bounce_shape != "auto" and bounce != "calibrated":
        raise InputError(f"--bounce-shape {bounce_shape} applies only with --bounce calibrated (the shape is "
                         "calibrated over the capture with the ground ratio; --bounce free fits a uniform bounce "
                         "per photo and --bounce observed reads it from the photos, so neither has a shape to "
                         "turn on or off)")


def check_fit_roll(fit_roll: bool, cluster: bool, cap) -> None:
    """``--fit-roll`` only where the roll is fitted: without ``world_from_camera`` (a stated pose holds
    its roll) and not on a cluster (whose estimation fits no tilt)."""
    from ffls.errors import InputError

    if not fit_roll:
        return
    if cluster:
        raise InputError("--fit-roll is not available with --scheduler (the cluster's estimation fits no tilt)")
    if not cap.world_from_camera_is_default:
        raise InputError(f"--fit-roll: {cap.json_path} gives camera.world_from_camera, which holds the camera's "
                         "roll; the roll is fitted only without it")


def check_bounce_observed(bounce: str, model: str, cluster: bool, cap=None) -> None:
    """``--bounce observed`` against the other flags (before the capture is loaded) and, given
    ``cap``, against the capture. The lines name the flag: the capture is not wrong, the flag
    asks what it cannot give (they named capture.json)."""
    from ffls.errors import InputError

    if bounce != "observed":
        return
    if cluster:
        raise InputError("--bounce observed is not available with --scheduler (the cluster reads the spheres' "
                         "pixels only)")
    if cap is None:
        return
    if cap.world_from_camera_is_default:
        raise InputError(f"--bounce observed needs camera.world_from_camera in {cap.json_path} (the ground is the "
                         "plane under each sphere, normal to the world's +Z)")
    if model != "distant" and getattr(cap, "camera_model", "pinhole") != "orthographic":
        raise InputError(f"--bounce observed needs --model distant, not --model {model} (the near light's joint "
                         "fit keeps the uniform ground)")


def run(args) -> int:
    from ffls.errors import check_output_path
    from ffls.io.capture import load_capture, save_lights
    from ffls.spheres.estimate import estimate_lights

    from ffls.commands.common import coverage_notes, print_notes, show_progress

    check_bounce_shape(args.bounce_shape, args.bounce)
    cluster = bool(getattr(args, "scheduler", None))
    check_bounce_observed(args.bounce, args.model, cluster)
    cap = load_capture(args.capture)
    check_bounce_observed(args.bounce, args.model, cluster, cap)
    check_fit_roll(args.fit_roll, cluster, cap)
    check_first_pass(args.first_pass, args.bounce, len(cap))
    # onto capture.json or a photo, or into a read-only capture folder: refused before the fits
    for out in (args.output or cap.folder / "lights.json", args.plot, args.lp):
        if out:
            check_output_path(out)
    progress = show_progress(args)
    decoded = None
    # --first-pass given: N photos, or every photo ("all"); not given: the estimation's default
    first_pass = {} if args.first_pass is None else {"first_pass": args.first_pass or None}
    shape = {"auto": None, "on": True, "off": False}[args.bounce_shape]
    if not cluster:  # every photo decoded once: the encoding calibration, the detection's reductions, the first pass
        from ffls.spheres.estimate import decode_photos

        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=len(cap.image_paths), desc="decoding", unit="img")
        try:
            decoded = decode_photos(cap, workers=args.workers or os.cpu_count() or 1, progress_bar=bar)
        finally:
            if bar is not None:
                bar.close()
    if decoded is not None:
        print_notes(NAME, *washed_out_notes(decoded.stats, cap.image_names))
    cap, spheres, calibration = calibrate_if_unknown(cap, progress=progress, decoded=decoded,
                                                     workers=args.workers or os.cpu_count() or 1)
    if calibration is not None:
        print(calibration.summary())
    seeds = None
    if spheres is not None and calibration is not None:
        # found on the stored values: a curve keeps the outlines' pixels but not their steps, the
        # half-way crossings of the limbs' mixed pixels (0.2-0.3 px toward the dark side under an
        # sRGB curve, 0.8 deg on a 22 px ball); fitted again on the photos linearised with it,
        # from these circles (find_spheres' seeds: not searched again)
        seeds, spheres = spheres, None
    if spheres is None:  # on the cluster the photos are read there for the fits; here for detection only
        from ffls.spheres.detect import find_spheres_in_capture

        stats = None if decoded is None else decoded.stats
        if stats is not None and decoded.stored and calibration is not None:  # of the stored values
            stats = decoded.linear_stats(cap)  # None: the photos are read again
        spheres = (find_spheres_in_capture(cap) if decoded is None else  # (the cluster: as before)
                   find_spheres_in_capture(cap, workers=args.workers or os.cpu_count() or 1) if stats is None else
                   find_spheres_in_capture(cap, stats=stats, bit_depths=decoded.bit_depths,
                                           workers=args.workers or os.cpu_count() or 1, seeds=seeds))
    print(spheres_summary(spheres))
    print_notes(NAME, *(f"set aside: {r}" for r in getattr(spheres, "rejected", ())))
    print_notes(NAME, lens_note(cap, spheres, decoded))
    if cluster:
        from ffls.cluster import open_client
        from ffls.cluster.lights import estimate_lights_dask

        remote = None if args.scheduler == "local" else args.scheduler
        with open_client(args.workers, remote, progress=progress) as runner:
            lights = estimate_lights_dask(cap, runner, spheres=spheres, model=args.model, bounce=args.bounce,
                                          bounce_shape=shape, **first_pass)
    else:
        lights = estimate_lights(cap, spheres=spheres, progress=progress, workers=args.workers,
                                 model=args.model, bounce=args.bounce, decoded=decoded, bounce_shape=shape,
                                 fit_roll=args.fit_roll, **first_pass)
        if cap.world_from_camera_is_default:
            print_notes(NAME, tilt_note(lights, args.fit_roll))
    if calibration is not None:
        lights.encoding = calibration.record()
    out = Path(args.output) if args.output else cap.folder / "lights.json"
    from ffls.errors import atomic_outputs

    with atomic_outputs():  # lights.json, --plot and --lp appear together or not at all
        save_lights(lights, out)
        if args.plot:
            plot_lights(lights, args.plot, hemisphere=cap.hemisphere)
        lp_line = export_lp(lights, cap, args.lp) if args.lp else None
    print(summary(lights))
    print(f"wrote {out}")
    if args.plot:
        print(f"wrote {args.plot}")
    if lp_line:
        print(lp_line)
    print_notes(NAME, occlusion_note(lights))
    print_notes(NAME, *coverage_notes(cap, lights, *lights.accepted(), repeats=True))
    return 0


def occlusion_note(lights) -> str | None:
    """The line naming accepted photos in which a matte sphere fits its own shading far worse than in
    the capture's other photos (an arm, the object or its shadow over it), or None.

    Such a sphere is kept with a wide cone, so the photo leans on its other spheres, and nothing
    said so (``i-user17``: a hand over one of four spheres in 5 photos of 80: four kept ``ok`` at
    42-130 times the sphere's median RMS residual, cone 180 deg, one ``shadowed``). A sphere is
    named where its status is ``shadowed`` in an accepted photo or its relative RMS residual is over
    :data:`ffls.spheres.estimate.SHADOW_MISFIT_RATIO` times its median over the accepted photos.
    """
    from ffls.spheres.estimate import CAPTURE_SHADOW_MIN_PHOTOS, SHADOW_MISFIT_RATIO, matte_residuals

    ok = [k for k, s in enumerate(lights.status) if s == "ok"]
    rows = {k: (lights.extra[k] or {}).get("spheres") or [] for k in ok}
    n = max((len(r) for r in rows.values()), default=0)
    res = {(i, k): v for (i, k), v in matte_residuals(lights).items() if lights.status[i] == "ok" and v > 0}
    hits = []  # (photo, sphere, ratio or None)
    for j in range(n):
        rms = {i: v for (i, k), v in res.items() if k == j}
        if len(rms) < CAPTURE_SHADOW_MIN_PHOTOS:
            continue
        med = float(np.median(list(rms.values())))
        for k, r in rows.items():
            if len(r) <= j:
                continue
            if r[j].get("status") == "shadowed":
                hits.append((k, j, None))
            elif k in rms and rms[k] > SHADOW_MISFIT_RATIO * med:
                hits.append((k, j, rms[k] / med))
    if not hits:
        return None
    hits.sort()
    photos = sorted({k for k, _, _ in hits})
    shown = _first_named([f"{lights.image_names[k]!r} sphere {j} ({'shadowed' if q is None else f'{q:.0f}x'})"
                          for k, j, q in hits], "; ")
    return (f"{len(photos)} accepted photos have a sphere in a shadow or fitting its shading far worse than in the "
            f"other photos (RMS residual over {SHADOW_MISFIT_RATIO:g}x its median): an arm, the object or its "
            f"shadow over it? They lean on their other spheres (numbered as found): {shown}")


def lens_note(cap, spheres, decoded) -> str | None:
    """The line for a capture declared orthographic whose spheres' outlines show a normal lens
    (:func:`ffls.spheres.estimate.lens_check`; the estimation widens the cones by it), or None."""
    from ffls.spheres.estimate import lens_check, photo_shape

    if getattr(cap, "camera_model", "pinhole") != "orthographic":
        return None
    return lens_check(cap, spheres, photo_shape(cap, decoded)).note(cap.json_path)


def washed_out_notes(stats, names) -> list[str]:
    """The line for the photos the sphere detection left out as washed out (``stats.washed_out`` of
    :class:`ffls.spheres.detect.SequenceStats`), or none."""
    from ffls.spheres.detect import WASHED_OUT_SHARE

    out = list(stats.washed_out)
    if not out:
        return []
    shown = ", ".join(f"{names[i]!r} ({share:.0%})" for i, share in out[:3]) + (", ..." if len(out) > 3 else "")
    return [f"{len(out)} photo{'s' if len(out) > 1 else ''} with more than {WASHED_OUT_SHARE:.0%} of the pixels at "
            f"full scale (overexposed, or lit by more than the capture's light) left out of finding the spheres: "
            f"{shown}; each is still judged with the others, and rejected where its spheres clip"]


def tilt_note(lights, fit_roll: bool = False) -> str:
    """The line for a capture without ``world_from_camera``: the camera's tilt (and, with
    ``fit_roll``, roll) fitted to the matte spheres (``camera_tilt_deg``, ``camera_roll_deg`` of
    :func:`ffls.spheres.estimate.estimate_lights`), or that the image's up was taken as the world's."""
    fitted = next((e for e in lights.extra or () if e.get("camera_tilt_deg") is not None), None)
    if fitted is None:
        return ("capture.json gives no camera.world_from_camera: the world's up is taken as the image's, so the "
                "ground bounce is modelled around the image's up, without the spheres' own shadows; for a camera "
                "looking down, give its pose, or only its tilt (docs/formats.md, \"The camera's tilt\")")
    if fitted.get("camera_roll_deg") is not None:
        roll = f"rolled {fitted['camera_roll_deg']:.1f} deg about its axis"
    elif fit_roll:
        roll = "its roll not fitted (looking down too steeply, or no roll fits the photos better)"
    else:
        roll = "taken as level (--fit-roll fits its roll)"
    from ffls.conventions import TILT_REACH_DEG

    tilt = float(fitted["camera_tilt_deg"])
    error = (lights.frame or {}).get("tilt_uncertainty_deg")
    looking = f"{tilt:.1f}" + ("" if error is None else f" +- {error:.1f} (95%)") + " deg down"
    if tilt > 90:
        looking += " (past straight down: looking back under itself)"
    if min(abs(tilt - end) for end in TILT_REACH_DEG) < 0.5:
        looking += f" (at the search's end, {tilt:g} deg: the tilt may lie beyond it)"
    return (f"capture.json gives no camera.world_from_camera: the ground under the spheres was fitted to their "
            f"shading, the camera looking {looking}, {roll}; the lights are in "
            f"that ground's frame (+Z its normal, +X the image's right, +Y the camera's forward over the ground; "
            f"\"frame\" in lights.json; docs/spheres.md, 'Without the camera's pose'); to fix it, give the pose, "
            f"or only its tilt (docs/formats.md, \"The camera's tilt\")")


def calibrate_if_unknown(capture, progress: bool = False, decoded=None, workers: int = 1):
    """``capture`` with its encoding calibrated from the spheres when ``capture.json`` states none.

    Floating-point images are linear by definition, and a stated ``"encoding"`` always wins:
    then nothing is done. Otherwise (integer images, no ``"encoding"``) the spheres are found
    on the stored values and :func:`ffls.spheres.encoding.calibrate_capture_encoding` names the
    curve; the photos are then linearised with it for the light estimation.

    ``decoded`` (:func:`ffls.spheres.estimate.decode_photos` of ``capture``) gives the photos
    already decoded: no photo is read again. ``workers`` processes profile the spheres' pixels.

    Returns
    -------
    capture : Capture
        A copy with ``encoding`` set when calibrated, else the input.
    spheres : list of SphereFit or None
        The spheres found for the calibration (None when not calibrated: found later).
    calibration : EncodingCalibration or None
    """
    from ffls.io.images import read_image
    from ffls.radiance.photos import encoding_unknown

    if capture.encoding != "auto":
        return capture, None, None
    # (decoded: the first photo's bit depth was read there, not read again here)
    if not (decoded.stored if decoded is not None else
            encoding_unknown("auto", read_image(capture.image_paths[0]).bit_depth)):
        return capture, None, None
    from ffls.spheres.encoding import calibrate_capture_encoding

    wrap = None
    if progress:
        from tqdm import tqdm

        wrap = tqdm
    calibration, spheres = calibrate_capture_encoding(capture, progress=wrap, decoded=decoded, workers=workers)
    return calibration.apply(capture), spheres, calibration


def export_lp(lights, capture, path) -> str:
    """Write the accepted ``lights`` of ``capture`` as an RTI ``.lp`` file; returns the line to print.

    Directions go to the ``.lp`` frame with the camera's pose in the lights' frame: ``lights.frame``'s
    (a fitted tilt) or else the capture's ``world_from_camera`` (:func:`ffls.io.capture.world_to_lp`);
    rejected lights are left out (``.lp`` has no status).
    """
    from ffls.errors import InputError
    from ffls.io.capture import world_to_lp, write_lp

    idx, dirs = lights.accepted()
    if not len(idx):
        raise InputError("no accepted light to write", path)
    wfc = capture.world_from_camera if lights.frame is None else lights.frame["world_from_camera"]
    write_lp(path, [lights.image_names[i] for i in idx], world_to_lp(dirs, wfc))
    left = len(lights) - len(idx)
    return f"wrote {path} ({len(idx)} lights" + (f"; {left} rejected left out)" if left else ")")
