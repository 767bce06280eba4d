"""``ffls view``: the interactive viewer (glfw + imgui-bundle over the GPU engine).

A thin layer over :mod:`viewer.app`. With ``--frames N`` it runs N frames and exits (scripted
mode, e.g. with ``--screenshot OUT.png``); with no display (or ``--headless``) the window lives
on glfw's null platform with EGL, so scripted runs work on machines without X.

The viewer registers this module as the ``view`` command under the entry-point group
``ffls.commands`` (``pyproject.toml``); ``ffls`` finds it there and never imports ``viewer``.
:func:`show_capture` is what ``ffls demo`` calls, through the same entry point, to open the
window on its capture afterwards.
"""
from __future__ import annotations

NAME = "view"
HELP = "interactive viewer: rotate light maps, change exposure and quality, save screenshots"
DESCRIPTION = (
    "Open a window over a capture: the relit image under a rotatable HDR light map, a light-map "
    "preview with the lights and their Voronoi cells, exposure, tone mapping, quality and speed "
    "panels. --frames N --screenshot OUT.png renders N frames, saves the window (and OUT.exr, the "
    "relit HDR) and exits; with no DISPLAY/WAYLAND_DISPLAY (or --headless) it runs on glfw's null "
    "platform with EGL. Keys: drag/arrows rotate, +/- exposure, space auto-rotate, S screenshot, "
    "F fullscreen, H help, Esc quit (docs/viewer.md)."
)


def add_arguments(p):
    from ffls.commands.common import (CELLS_RES, FRAMES, add_light_argument, add_lights_arguments,
                                      add_quality_arguments, add_rotation_arguments, add_weighting_argument,
                                      exposure_arg, input_path, number, output_path)

    p.add_argument("capture", type=input_path, help="capture folder (with capture.json)")
    add_lights_arguments(p)
    add_weighting_argument(p)
    add_light_argument(p)
    p.add_argument("--probe", default=None, metavar="MAP",
                   help="light map: a file (.exr/.hdr) or a built-in name (default courtyard; excludes --light)")
    add_rotation_arguments(p, default="0,0,0")
    p.add_argument("--auto-rotate", type=number(-1e6, 1e6, unit="degrees per second"), default=None,
                   metavar="DEG_PER_S",
                   help="start auto-rotating the yaw at this speed")
    p.add_argument("--exposure", type=exposure_arg, default="auto", metavar="EV|auto",
                   help="exposure in stops (default auto: the first frame metered on the object, the --mask when "
                        "given)")
    p.add_argument("--tonemap", default="aces", choices=("srgb", "reinhard", "aces"))
    p.add_argument("--size", type=_size_type, default="1280x800", metavar="WxH",
                   help="window size in screen coordinates (at most the OpenGL context's texture, renderbuffer "
                        "and viewport limits; ffls info lists them)")
    p.add_argument("--rank", type=int, default=None, metavar="K",
                   help="compressed basis of K eigen-images, 1 <= K <= n-1 for n lights; 0 = full float16 basis "
                        "(default: full on a GPU; on a CPU rasteriser such as llvmpipe the smallest rank whose "
                        "truncation error is <= 1%%, in whole blocks of 8 layers, within the frame "
                        "budget: 23 up to 384x384, 15 up to 470x470, else 7; printed)")
    p.add_argument("--mask", default=None, metavar="FILE", type=input_path,
                   help="object mask image (white = object): enables hiding the background")
    p.add_argument("--fullscreen", action="store_true",
                   help="start fullscreen on the primary monitor (needs a display: refused with --headless)")
    p.add_argument("--headless", action="store_true",
                   help="glfw's null platform with EGL (automatic when no display is set); needs --frames N")
    p.add_argument("--frames", type=FRAMES, default=None, metavar="N",
                   help="run N frames and exit (needed on the null platform, where nothing can close the window)")
    p.add_argument("--screenshot", type=output_path((".png",)), default=None, metavar="OUT.png",
                   help="after the last frame save the window (PNG) and the relit HDR (OUT.exr)")
    c = p.add_argument_group("composite mode (docs/composite.md)")
    c.add_argument("--composite-surface", default=None, metavar="CAPTURE",
                   help="capture of the surface alone (same camera): enables the composite mode, the object merged "
                        "into --background with its shadows as the light map turns; needs --mask and --surface-mask")
    c.add_argument("--surface-lights", default=None, metavar="FILE",
                   help="lights of the surface capture (default CAPTURE/lights.json)")
    c.add_argument("--background", default=None, metavar="BG.exr", help="linear background (.exr/.hdr)")
    c.add_argument("--surface-mask", default=None, metavar="SURF.png", help="surface region (white = surface)")
    c.add_argument("--composite", action="store_true", help="start in the composite mode")
    p.add_argument("--benchmark", action="store_true",
                   help="with --frames: rotate the light map every frame and print frame-time and CPU-time statistics")
    p.add_argument("--profile", action="store_true",
                   help="with --benchmark: also time each engine pass (waits for the GPU after each, so slower frames)")
    add_quality_arguments(p, precision_default=None, fps_flags=("--fps", "--target-fps"), cells_res=CELLS_RES)


def _size_type(text: str) -> tuple[int, int]:
    """argparse type of ``--size``: ``WxH``, both positive (the OpenGL limits are checked once the
    window's context exists: :class:`viewer.app.ViewerApp`)."""
    import argparse

    from viewer.state import parse_size

    try:
        return parse_size(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def build_state(args):
    """The initial :class:`viewer.state.ViewerState` from the parsed arguments."""
    from ffls.commands.common import rotation_angles
    from ffls.errors import InputError
    from viewer.state import ViewerState, parse_size

    try:
        size = tuple(args.size) if isinstance(args.size, tuple) else parse_size(args.size)
    except ValueError as e:
        raise InputError(f"--size: {e}") from None
    yaw, pitch, roll = rotation_angles(args)
    st = ViewerState(yaw=yaw, pitch=pitch, roll=roll, tonemap=args.tonemap, lightmap=args.probe or "courtyard",
                     window_size=size, fullscreen=bool(args.fullscreen))
    if args.exposure != "auto":
        st.exposure = float(args.exposure)
    if args.auto_rotate is not None:
        st.auto_rotate, st.auto_rotate_speed = True, float(args.auto_rotate)
    st.quality["weighting"] = getattr(args, "weighting", "voronoi")
    if getattr(args, "light", None) is not None:  # start in light mode (RTI style)
        st.light_mode = True
        st.light_az, st.light_el = (float(a) for a in args.light)
    if args.rank is not None and args.rank < 0:
        raise InputError(f"--rank must be >= 0, not {args.rank}")
    prec = getattr(args, "precision", None)
    if args.rank == 0:
        st.quality["method"] = "full f32" if prec in ("float32", "f32") else "full f16"
    elif args.rank is not None:
        if prec in ("float32", "f32"):
            raise InputError("--precision float32 applies to the full basis in the viewer (--rank 0); "
                             "compressed layers are float16")
        st.quality["method"] = "compressed"
        st.quality["rank"] = int(args.rank)
    elif prec is not None:
        st.quality["method"] = "full f32" if prec in ("float32", "f32") else "full f16"
    if getattr(args, "basis_subset", None) is not None:
        st.quality["subset"] = str(int(args.basis_subset))
    if getattr(args, "map_res", None) is not None:
        st.quality["map_res"] = str(int(args.map_res))
    if getattr(args, "cells_res", None) not in (None, 256):
        st.quality["cell_res"] = str(int(args.cells_res))
    if getattr(args, "near_correction", False):
        st.quality["near"] = True
    return st


def choose_auto_quality(app, args, capture, lights) -> None:
    """``--quality auto``: measure this capture and map in the window's context, and set the panel."""
    from ffls.commands.common import check_gpu_pass1, resolve_quality
    from ffls.conventions import rotation_ypr
    from ffls.errors import InputError
    from ffls.gpu.engine import gpu_frame_ms
    from ffls.lightmaps.lightmap import lightmap_from_spec
    from viewer.renderer import pass1_lightmap
    from viewer.state import state_quality

    st = app.state
    lm = lightmap_from_spec(st.lightmap)

    def timer(q, basis, directions):
        app.make_current()
        try:
            check_gpu_pass1(app.ctx, lm, q)
        except InputError:  # a candidate whose pass 1 cannot run here (spline over a large map): never chosen
            return float("inf")
        return gpu_frame_ms(app.ctx, basis, directions, pass1_lightmap(lm, q.map_res), q.replace(map_res=None),
                            capture.hemisphere)

    args.cells_res = args.cells_res or 256
    q = resolve_quality(args, capture, lights, lm, rotation_ypr(st.yaw, st.pitch, st.roll), timer=timer,
                        command=NAME)
    st.quality.update(state_quality(q))


def choose_default_rank(app, capture, lights, args=None) -> str | None:
    """No ``--rank``, ``--precision`` or ``--quality`` in ``args`` (None: ``ffls demo``'s window) on
    a CPU rasteriser (the compressed basis):
    the rank from the data (:func:`ffls.relight.compress.choose_rank`: the smallest whose
    truncation error is under :data:`~ffls.relight.compress.AUTO_RANK_ERROR`, capped by the frame
    budget), set in the panel. Returns the line saying so, or None where nothing was chosen (a
    GPU, a flag given, or photos too large for host memory: the fixed default then)."""
    import numpy as np

    from ffls.commands.common import available_memory
    from ffls.gpu.context import is_software_renderer
    from ffls.relight.basis import capture_basis
    from ffls.relight.compress import AUTO_RANK_ERROR, LAYER_BLOCK, budget_rank, choose_rank
    from ffls.relight.stream import default_memory
    from viewer.state import quality_from_state

    st = app.state
    if (getattr(args, "rank", None) is not None or getattr(args, "precision", None) is not None
            or getattr(args, "quality", None) == "auto" or st.quality.get("method") != "auto"
            or not is_software_renderer(app.renderer.info.renderer)):
        return None
    n = int(np.count_nonzero(lights.ok_mask))
    w, h = capture.image_size or (0, 0)
    if n < 2 or n * w * h * 12 > default_memory(available_memory()):
        return None
    q = quality_from_state(st.quality, n, True)
    cap = budget_rank(h, w)
    if cap < LAYER_BLOCK:  # one block of layers: the data cannot change the rank, the photos are not read again
        k = st.quality["rank"] = min(cap, n - 1)
        why = "exact" if k == n - 1 else f"the frame budget at {w}x{h} allows one block of {LAYER_BLOCK} layers"
        return f"rank {k} of {n} photos ({why}; --rank K to override; docs/viewer.md, \"Default rank\")"
    basis, d, _ = capture_basis(capture, lights, q)
    if len(basis) < 2:
        return None
    app.renderer.hand_basis(basis, d, q)  # (the first engine takes it: the photos are read once)
    k, err = choose_rank(basis, max_rank=cap)
    st.quality["rank"] = k
    why = "exact" if k >= len(basis) - 1 else (f"under {AUTO_RANK_ERROR:.0%}" if err <= AUTO_RANK_ERROR
                                                else f"capped by the frame budget at {w}x{h}")
    return (f"rank {k} of {len(basis)} photos chosen from the data ({why}): expected basis error "
            f"{err:.1%} RMS (--rank K to override; docs/viewer.md, \"Default rank\")")


def _check_and_report(args, capture, lights) -> None:
    """``--rank`` against the accepted lights (0 = full basis), and the informational lines
    (lights matched by order or map, colour conversions, coverage warnings)."""
    from ffls.commands.common import check_quality_args, check_rank_arg, coverage_notes, print_notes
    from ffls.io.images import colour_summary
    from ffls.relight.basis import accepted_positions

    idx, dirs = lights.accepted()
    if args.rank:
        check_rank_arg(args.rank, len(idx))
    check_quality_args(args, len(idx), accepted_positions(lights))
    notes = [lights.note, colour_summary([capture.image_paths[i] for i in idx])]
    notes += coverage_notes(capture, lights, idx, dirs)
    print_notes(NAME, *notes)


def composite_inputs(args, capture):
    """:class:`viewer.renderer.CompositeInputs` of ``--composite-surface`` (None without it), checked.

    Raises
    ------
    ffls.errors.InputError
        A missing companion flag, cameras that differ, or images and masks of the wrong size.
    """
    from pathlib import Path

    from ffls.errors import InputError

    given = [f for f, v in (("--background", args.background), ("--surface-mask", args.surface_mask),
                            ("--surface-lights", args.surface_lights)) if v is not None]
    if args.composite_surface is None:
        if given or args.composite:
            raise InputError(f"{(given or ['--composite'])[0]} needs --composite-surface CAPTURE")
        return None
    missing = [f for f, v in (("--background", args.background), ("--surface-mask", args.surface_mask),
                              ("--mask", args.mask)) if v is None]
    if missing:
        raise InputError(f"--composite-surface needs {' and '.join(missing)}")
    from ffls.commands.common import check_mask_not_empty
    from ffls.io.images import read_image, read_mask
    from ffls.relight.composite import check_same_camera
    from viewer.app import open_capture
    from viewer.renderer import CompositeInputs

    scap, slights = open_capture(args.composite_surface, args.surface_lights)
    check_same_camera(capture, scap, Path(scap.folder) / "capture.json")
    bg = read_image(args.background)
    size = capture.image_size or (bg.pixels.shape[1], bg.pixels.shape[0])
    if (bg.pixels.shape[1], bg.pixels.shape[0]) != tuple(size):
        raise InputError(f"the background is {bg.pixels.shape[1]}x{bg.pixels.shape[0]}, the captures' photos "
                         f"{size[0]}x{size[1]}", args.background)
    om = read_mask(args.mask, size=size)
    check_mask_not_empty(om, args.mask)
    sm = read_mask(args.surface_mask, size=size)
    if not ((sm > 0.5) & (om < 0.5)).any():
        raise InputError("the surface mask has no surface pixel outside the object's mask", args.surface_mask)
    return CompositeInputs(scap, slights, bg.pixels, om, sm)


def check_window_args(args) -> None:
    """Refuse flags that the chosen window platform or each other make meaningless, and check the
    outputs of ``--screenshot`` (the PNG and its sibling ``.exr``) before anything is written.

    * the null platform (``--headless``, or no display) without ``--frames N``: nobody can close
      its window, so the command would never end;
    * ``--fullscreen`` on the null platform: there is no monitor;
    * ``--light`` with ``--probe``: light mode relights with one light, not the map (as ``render``).

    Raises
    ------
    ffls.errors.InputError, ffls.errors.OutputError
    """
    from ffls.errors import InputError
    from viewer.headless import choose_platform

    null = choose_platform(True if args.headless else None) == "null"
    why = "--headless" if args.headless else "no DISPLAY or WAYLAND_DISPLAY: the null platform"
    if null and args.frames is None:
        raise InputError(f"{why} needs --frames N: nothing can close its window")
    if null and args.fullscreen:
        raise InputError(f"--fullscreen needs a display ({why} has no monitor)")
    if getattr(args, "light", None) is not None and args.probe is not None:
        raise InputError("--probe and --light exclude each other: give one")
    check_screenshot_paths(args)


def check_screenshot_paths(args) -> None:
    """Both outputs of ``--screenshot`` (the PNG and its sibling ``.exr``) can be written and
    replace no input (:func:`ffls.errors.check_output_path`). Checked again once the capture is
    open, its photos then being registered inputs: ``--screenshot CAP/img_0000.png`` was refused
    only when the screenshot was written, after the window's informational lines."""
    from pathlib import Path

    from ffls.errors import check_output_path

    if args.screenshot is not None:
        check_output_path(args.screenshot)
        check_output_path(Path(args.screenshot).with_suffix(".exr"))


def run(args) -> int:
    from ffls.errors import InputError
    from viewer.app import ViewerApp, open_capture

    if args.frames is not None and args.frames < 1:
        raise InputError(f"--frames must be >= 1, not {args.frames}")
    if args.benchmark and args.frames is None:
        raise InputError("--benchmark needs --frames N")
    check_window_args(args)
    if args.probe is not None:  # a bad --probe is one line here: the window shows a failed map only in its panel,
        from ffls.lightmaps.lightmap import lightmap_from_spec  # and a missing one rendered black with status 0

        lightmap_from_spec(args.probe)
    st = build_state(args)
    capture, lights = open_capture(args.capture, args.lights, getattr(args, "lights_map", None))
    check_screenshot_paths(args)
    _check_and_report(args, capture, lights)
    if args.profile and not args.benchmark:
        raise InputError("--profile needs --benchmark")
    comp = composite_inputs(args, capture)
    st.composite = comp is not None and bool(args.composite)
    app = ViewerApp(capture, lights, st, headless=True if args.headless else None, timing=args.benchmark,
                    mask_path=args.mask, composite=comp, profile=args.profile)
    try:
        if args.quality == "auto":
            choose_auto_quality(app, args, capture, lights)
        line = choose_default_rank(app, capture, lights, args)
        if line:
            print(f"ffls {NAME}: {line}")
        if args.exposure == "auto":  # expose the first frame for the object's log-average luminance
            app.auto_expose()
        from ffls.commands.common import flush_notes

        flush_notes()  # the window runs until closed: the informational lines and warnings now
        if args.benchmark:
            st.auto_rotate = True
            st.auto_rotate_speed = st.auto_rotate_speed if args.auto_rotate is not None else 30.0
            app.run(frames=args.frames, screenshot=args.screenshot, dt=1.0 / 30.0)
        else:
            app.run(frames=args.frames, screenshot=args.screenshot)
        if args.frames is not None:
            s = app.summary(skip=min(2, max(0, args.frames - 1)))
            passes = ", ".join(f"{k} {v:.1f}" for k, v in s["passes"].items())
            b = app.renderer.info
            print(f"ffls view: {app.frames_rendered} frames on {app.platform} platform ({b.renderer}); "
                  f"{b.image_size[0]}x{b.image_size[1]}, {b.n_lights} lights, "
                  f"{'full basis' if b.basis_info.get('rank') is None else 'rank ' + str(b.basis_info['rank'])}")
            print(f"  frame time: mean {s['mean_ms']:.1f} ms, median {s['median_ms']:.1f} ms "
                  f"({s['fps']:.1f} fps), CPU {s['cpu_ms']:.1f} ms per frame, over {s['frames']} frames; "
                  f"passes (ms, mean where run): {passes or 'none'}")
            if s["panel_redraws"] is not None:
                print(f"  control panel drawn into its texture {s['panel_redraws']} times in "
                      f"{app.frames_rendered} frames (docs/viewer.md, frame budget)")
            if args.screenshot:
                print(f"  screenshot: {args.screenshot} (window) and {args.screenshot[:-4]}.exr (relit HDR)")
    finally:
        app.close()
    return 0


def show_capture(capture_dir) -> str | None:
    """Open the interactive window on ``capture_dir`` when a display exists (``ffls demo`` calls this).

    Returns
    -------
    str or None
        None after the window was opened and closed; otherwise one line saying why it was not
        opened (no display, no OpenGL 4.3 window), for the caller to print.
    """
    from ffls.errors import GLUnavailable
    from viewer.headless import has_display

    if not has_display():
        return f"no display; run `ffls view {capture_dir}` on a desktop"
    try:
        from viewer.app import ViewerApp, open_capture
    except ImportError as e:  # imgui-bundle or glfw missing
        return f"not opened ({e})"
    try:
        capture, lights = open_capture(capture_dir)
        app = ViewerApp(capture, lights, headless=False)
    except GLUnavailable as e:
        return f"not opened ({e})"
    try:
        line = choose_default_rank(app, capture, lights)
        if line:
            print(f"ffls {NAME}: {line}")
        app.auto_expose()
        app.run()
    finally:
        app.close()
    return None
