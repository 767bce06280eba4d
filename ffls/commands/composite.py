"""``ffls composite``: put the relit object into a virtual scene or a photograph (paper section 7).

Differential rendering (:mod:`ffls.relight.composite`): the object-on-surface and surface-alone
captures are relit under the scene's light map, each over its own lights, and merged into the
background: ``background + scale * (object - surface)`` over the surface mask, the relit object
over its mask. The registration (scale and offset of the relit surface to the background's
surface) is fitted once and printed. A still writes OUT.exr (linear) and OUT.png (tone-mapped)
and OUT.json (the registration); ``--turntable N`` rotates the scene's map about +Z and writes
frames like ``ffls render``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ffls.commands.common import (CELLS_RES, FPS, FRAMES, RANK, add_rotation_arguments, add_weighting_argument,
                                  check_fps_flag, check_output_kind,
                                  exposure_arg, input_path, learnt_kernel, output_path, print_notes, flush_notes,
                                  rotation_from_args, compressed_note)
from ffls.io.images import MAX_RINGING_SHARE

NAME = "composite"
HELP = "merge a relit object and its shadows into a virtual scene or photograph (differential rendering)"
DESCRIPTION = (
    "Relight two captures made with one camera, the object on a surface and the surface alone, under "
    "the scene's light map (made at the object's place), and merge them into the background with "
    "differential rendering: background + scale * (object - surface) over the surface mask, the relit object "
    "over its mask, so that its shadows and bounce light transfer. A uniform scale and offset registering "
    "the relit surface to the background's surface is fitted and reported. Writes OUT.exr, OUT.png and "
    "OUT.json; --turntable N rotates the scene's map 360 degrees about +Z (mp4 or folder of PNGs)."
)

#: ``--sources``: how the map's compact bright sources are relit.
SOURCES = ("lightflow", "levelset", "weights")
#: ``--fill``: how the compact sources reach the ground (docs/composite.md, "The object's shadow
#: inside the spheres' shadows" and "The compact sources on the whole ground"): ``ground`` where
#: the captures have what it needs, else ``none`` (``auto``, the default); as interpolated (none);
#: from the ground's unshadowed model and the object's shadow hull where a sphere hides them
#: (model), and also the rest's weights (rest+model); from the model and the hull on every ground
#: pixel (ground).
FILLS = ("auto", "none", "model", "rest+model", "ground")
#: What ``--fill`` gives ``LightFlowRelighter``'s ``fill_sources``.
FILL_SOURCES = {"model": "model", "rest+model": "model", "ground": "ground"}
#: The spheres' bottoms (centre height less the radius) may spread this many radii around their
#: median and still be read as one ground plane (``--fill``).
GROUND_SPREAD_RADII = 0.5
BACKGROUND_SUFFIXES = (".exr", ".hdr", ".pic")
#: Share of a background's pixels that may hold a negative value: a renderer's reconstruction
#: filter (Lanczos, Mitchell) rings below zero beside bright edges, on a few pixels; more than this
#: is not radiance (an offset image, a difference image).
MAX_NEGATIVE_BACKGROUND = MAX_RINGING_SHARE


def add_arguments(p):
    from ffls.lightmaps.lightmap import LAYOUTS
    from ffls.relight.composite import METHODS, REGISTRATION_MODES

    g = p.add_argument_group("inputs")
    g.add_argument("--object", required=True, metavar="CAPTURE", type=input_path,
                   help="capture folder of the object on the surface")
    g.add_argument("--object-lights", default=None, metavar="FILE", type=input_path,
                   help="lights.json or .lp of the object capture (default CAPTURE/lights.json)")
    g.add_argument("--surface", required=True, metavar="CAPTURE", type=input_path,
                   help="capture folder of the surface alone (same camera; its own lights)")
    g.add_argument("--surface-lights", default=None, metavar="FILE", type=input_path,
                   help="lights.json or .lp of the surface capture (default CAPTURE/lights.json)")
    g.add_argument("--lightmap", required=True, metavar="MAP", type=input_path,
                   help="the scene's light map at the object's place (.exr/.hdr, or a built-in name)")
    g.add_argument("--layout", default=None, choices=LAYOUTS,
                   help="layout of the light-map file (default: detected from the file)")
    g.add_argument("--background", required=True, metavar="BG.exr", type=input_path,
                   help="linear render or photograph of the scene without the object, from the captures' camera "
                        "(.exr or .hdr, same size as the photos)")
    g.add_argument("--mask", required=True, metavar="OBJ_MASK.png", type=input_path,
                   help="object mask (white = object)")
    g.add_argument("--surface-mask", required=True, metavar="SURF.png", type=input_path,
                   help="surface region (white = the captured surface stands for the scene's; leave the "
                        "calibration spheres out)")
    add_rotation_arguments(p)
    c = p.add_argument_group("composite")
    c.add_argument("--method", default="Debevec1998", choices=METHODS,
                   help="Debevec1998: add the difference (default); ratio: multiply by object/surface")
    c.add_argument("--registration", default="auto", choices=REGISTRATION_MODES,
                   help="fit background ~ scale * surface + offset on the surface (auto: the offset only where the "
                        "surface's brightness varies enough); none: scale 1")
    add_weighting_argument(c)
    c.add_argument("--sources", default="lightflow", choices=SOURCES,
                   help="compact bright sources of the map (a sun, a window, a lamp): lightflow (default) relights "
                        "each from the basis photos of its nearest lights warped toward it by optical flow (Chen and "
                        "Lensch 2005; CPU, flows cached per pair of lights), the rest with --weighting; levelset: the "
                        "blend of the nearest lights' photos with their cast shadows moved by interpolating the "
                        "shadows' signed distances (CPU); weights: every texel through --weighting")
    c.add_argument("--flow", default=None, choices=("dis", "farneback"),
                   help="optical flow of --sources lightflow (between the photos) and levelset (between the "
                        "shadows' signed distances): OpenCV DIS (default) or Farneback; refused with --sources "
                        "weights, which uses no flow")
    c.add_argument("--fill", default="auto", choices=FILLS,
                   help="how the map's compact sources light the ground: ground relights them on every ground "
                        "pixel from the ground's unshadowed model times the object's shadow hull, carved from the "
                        "object capture's own shadows (the object's shadow placed by its geometry, not "
                        "interpolated between the nearest lights' photos); model does so only where a calibration "
                        "sphere hides a source from the ground (no photo holds the object's shadow there); "
                        "rest+model also moves the rest's weights off the photos a sphere hides; none: as "
                        "interpolated. These need --sources lightflow or levelset, distant lights, and "
                        "capture.json's camera (K, world_from_camera, +Z up) and sphere_radius; the spheres' "
                        "world centres come from capture.json's spheres[].center, or are found in the photos. "
                        "auto (default): ground where the captures and the map allow it, else none, saying why")
    c.add_argument("--scale-object", action="store_true",
                   help="scale the relit object by the registration too (the mismatch is the exposure, e.g. a "
                        "photographed background; default: it is the surface's albedo)")
    o = p.add_argument_group("output")
    o.add_argument("--exposure", type=exposure_arg, default=0.0, metavar="EV|auto",
                   help="exposure in stops of the PNG/video (auto: metered on the whole composite)")
    o.add_argument("--tonemap", default="srgb", choices=("srgb", "reinhard", "aces"), help="tone curve (PNG/video)")
    o.add_argument("--rank", type=RANK, default=None, metavar="K",
                   help="relight with compressed bases of K eigen-images (1 <= K <= n-1 for each capture)")
    o.add_argument("--cells-res", type=CELLS_RES, default=256,
                   help="cell-texture resolution, 16 to 4096 (default 256)")
    o.add_argument("--turntable", type=FRAMES, default=None, metavar="N",
                   help="write N frames rotating the scene's map 360 degrees about +Z: -o OUT.mp4 or a folder")
    o.add_argument("--fps", type=FPS, default=None,
                   help="frames per second of the --turntable video, 0.1 to 1000 (default 30; refused for a still)")
    o.add_argument("-o", "--out", required=True, type=output_path((".exr", ".png", ".mp4"), folder_ok=True),
                   help="OUT.exr or OUT.png (both are written, and OUT.json), or .mp4 / DIR/ with --turntable")


def _siblings(out: Path) -> dict:
    """The still's three files (``.exr``, ``.png``, ``.json`` beside ``out``), each a valid output.

    A sibling the user did not name is replaced only when it is an earlier composite's (its
    ``.json`` is an ``ffls-composite`` record): ``-o set/truth.png`` would have replaced the
    synthetic set's ``truth.exr`` and written ``truth.json`` beside it.
    """
    import json

    from ffls.errors import InputError, check_output_path
    from ffls.io.capture import read_json_text

    files = {s: out.with_suffix(s) for s in (".exr", ".png", ".json")}
    for p in files.values():
        check_output_path(p)
    others = [p for p in files.values() if p != out and p.exists()]
    if others:
        try:
            ours = json.loads(read_json_text(files[".json"])).get("format") == "ffls-composite"
        except (OSError, ValueError, AttributeError):
            ours = False
        if not ours:
            raise InputError(f"ffls composite writes {files['.exr'].name}, {files['.png'].name} and "
                             f"{files['.json'].name}, and {others[0].name} exists, not from an earlier composite: "
                             "choose another name", out)
    return files


def check_not_set_file(outputs, background) -> None:
    """Refuse an output that is one of the files of the synthetic set (``ffls synth --composite-set``)
    that ``background`` belongs to, when its ``composite.json`` lists it.

    The set's background and masks are this command's inputs, refused as such; its ``truth.exr``,
    ``scene_map.exr`` and ``sphere_mask.png`` are not read, and ``-o SET/truth.exr`` replaced
    the ground truth the composite is compared with.

    Raises
    ------
    ffls.errors.InputError
        Naming the output and the set's file it would replace.
    """
    import os

    from ffls.errors import InputError
    from ffls.io.capture import read_json_text
    from ffls.synth.virtual import COMPOSITE_FILE

    record = Path(background).parent / COMPOSITE_FILE
    if not record.is_file():  # (no set; nor a FIFO, which would wait for a writer)
        return
    try:
        doc = json.loads(read_json_text(record))
    except (OSError, ValueError, InputError):  # (no set, or not one ffls wrote: nothing to keep)
        return
    if not isinstance(doc, dict) or doc.get("format") != "ffls-composite-set":
        return
    listed = {key: record.parent / name for key, name in doc.items() if isinstance(name, str)
              and Path(name).suffix.lower() in (".exr", ".png", ".json") and Path(name).name == name}
    for out in outputs:
        for key, p in listed.items():
            if p.exists() and Path(out).exists() and os.path.samefile(p, out):
                raise InputError(f"is the {key.replace('_', ' ')} of the synthetic set {record.parent} (its "
                                 f"{COMPOSITE_FILE} lists it), which the composite would replace: choose another "
                                 "name", out)


def _image_size(capture) -> tuple[int, int]:
    """(W, H) of a capture's photos: ``image_size`` when stated, else the first photo's."""
    if capture.image_size is not None:
        return tuple(int(v) for v in capture.image_size)
    from ffls.io.images import read_image

    h, w = read_image(capture.image_paths[0], working_space=False).pixels.shape[:2]
    return w, h


def check_distinct_captures(object_capture, surface_capture) -> None:
    """Refuse ``--surface`` naming the object capture: the same folder, the same photo files, or a copy.

    Differential rendering subtracts the relit surface from the relit object; the same capture
    twice makes the difference zero and the composite is the background with the object pasted
    over it, no shadow: a mistake, never a request.

    Raises
    ------
    ffls.errors.InputError
    """
    import os

    from ffls.errors import InputError

    def identity(p):
        try:
            st = os.stat(p)
        except OSError:
            return None
        return st.st_dev, st.st_ino

    folder = Path(surface_capture.folder)
    if identity(folder) is not None and identity(folder) == identity(object_capture.folder):
        raise InputError("--surface is the --object capture: give the capture of the surface alone", folder)
    photos = {identity(p) for p in object_capture.image_paths} - {None}
    shared = [p for p in surface_capture.image_paths if identity(p) in photos]
    if shared:
        raise InputError(f"--surface shares {len(shared)} photo file(s) with --object ({Path(shared[0]).name}, ...): "
                         "give the capture of the surface alone", folder)
    # a copy of the object capture: its first photo is byte for byte the object's (two real
    # photographs, even of one scene, never are: sensor noise)
    import filecmp

    first = surface_capture.image_paths[:1] + object_capture.image_paths[:1]
    if len(first) == 2 and all(Path(p).is_file() for p in first) and filecmp.cmp(*first, shallow=False):
        raise InputError(f"--surface's photo {Path(first[0]).name} is byte for byte --object's {Path(first[1]).name}: "
                         "a copy of the object capture? give the capture of the surface alone", folder)


def _stated_spheres_problem(capture, centres, r: float) -> str | None:
    """Why the spheres stated in ``capture.json`` (``spheres[].center``, ``sphere_radius``) cannot be
    the calibration spheres of the photos, or None: two spheres whose centres are closer than a radius
    (a stated ``sphere_radius`` of 50 m for spheres 0.5 m apart, one centre given twice), or a sphere
    behind the camera or whose disc misses the photo (a centre of 1e300, a typo in a coordinate).
    Checked by K and ``world_from_camera`` without distortion: the disc only has to meet the photo."""
    from ffls.camera.projection import project_points

    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    i, k = np.unravel_index(np.argmin(d + np.diag(np.full(len(centres), np.inf))), d.shape)
    if len(centres) > 1 and not d[i, k] >= r:
        return (f"spheres[{i}].center and spheres[{k}].center are {d[i, k]:.4g} apart, less than sphere_radius "
                f"{r:.4g}: spheres of that radius would overlap")
    cam = np.linalg.inv(capture.world_from_camera)
    with np.errstate(over="ignore", invalid="ignore"):
        xc = centres @ cam[:3, :3].T + cam[:3, 3]
        uv = project_points(xc, capture.K)
        rad = float(max(capture.K[0, 0], capture.K[1, 1])) * r / xc[:, 2]
    w, h = capture.image_size if capture.image_size is not None else (2 * capture.K[0, 2] + 1,
                                                                      2 * capture.K[1, 2] + 1)
    for k in range(len(centres)):
        inside = (xc[k, 2] > r and np.all(np.isfinite(uv[k])) and -rad[k] <= uv[k, 0] <= w + rad[k]
                  and -rad[k] <= uv[k, 1] <= h + rad[k])
        if not inside:
            where = "is behind the camera" if not xc[k, 2] > r else \
                f"projects to pixel ({uv[k, 0]:.4g}, {uv[k, 1]:.4g}), off the {w}x{h} photos"
            centre = "[" + ", ".join(f"{v:.4g}" for v in centres[k]) + "]"  # (not numpy's printing: global options)
            return (f"spheres[{k}].center {centre} {where} "
                    "(camera.K and camera.world_from_camera)")
    return None


def sphere_geometry(capture, lights) -> dict:
    """The calibration spheres and the ground of a capture, in its world, for ``--fill``.

    The spheres' world centres are ``capture.json``'s ``spheres[].center`` where every hint gives
    one, else the spheres found in the photos (:func:`ffls.spheres.detect.find_spheres_in_capture`).
    The ground is the plane z = const under them: the median of their bottoms (centre height less
    the radius), the world's +Z up (``world_from_camera``).

    Parameters
    ----------
    capture : ffls.io.capture.Capture
    lights : ffls.io.capture.Lights

    Returns
    -------
    dict
        ``centres`` (k, 3) float64, ``radius`` float, ``ground_z`` float, ``source`` (str: where
        the centres come from), ``margin_deg`` (m,) float64: each accepted light's 95% cone
        (``uncertainty_deg`` of ``lights.json``, 0 where not stated).

    Raises
    ------
    ffls.errors.InputError
        One line: no pinhole camera, no ``world_from_camera``, no ``sphere_radius``, near lights,
        no sphere found, stated spheres that overlap or miss the photos, spheres not on one ground, a
        camera below the ground.
    """
    from ffls.errors import InputError

    where = capture.json_path
    if getattr(capture, "camera_model", "pinhole") != "pinhole" or capture.K is None:
        raise InputError("--fill needs a pinhole camera with K in capture.json (the ground's pixels are placed "
                         "along their rays)", where)
    if capture.world_from_camera_is_default:
        raise InputError("--fill needs camera.world_from_camera in capture.json (the camera, the ground and the "
                         "lights in one world, +Z up)", where)
    if capture.sphere_radius is None:
        raise InputError("--fill needs sphere_radius in capture.json (the spheres' shadows are cast from their "
                         "size)", where)
    idx, _ = lights.accepted()
    near = np.all(np.isfinite(lights.positions[idx]), axis=1)
    if near.any():
        raise InputError(f"--fill needs distant lights (the shadow hull is carved along light directions); "
                         f"{int(near.sum())} lights have near positions", getattr(lights, "path", None) or where)
    hints = list(capture.spheres or [])
    if hints and all("center" in h for h in hints):
        centres, source = np.array([h["center"] for h in hints], dtype=np.float64), "capture.json"
    else:
        from ffls.spheres.detect import find_spheres_in_capture

        try:
            found = find_spheres_in_capture(capture)
        except InputError as e:
            raise InputError(f"--fill needs the calibration spheres' world centres: {e.message}", e.path) from None
        centres, source = np.array([s.center_world for s in found], dtype=np.float64).reshape(-1, 3), "found"
    if not len(centres):
        raise InputError("--fill needs the calibration spheres' world centres: none found in the photos; give "
                         "them in capture.json, \"spheres\": [{\"center\": [x, y, z]}, ...]", where)
    r = float(capture.sphere_radius)
    why = _stated_spheres_problem(capture, centres, r) if source == "capture.json" else None
    if why:
        raise InputError(f"--fill: {why}", where)
    bottoms = centres[:, 2] - r
    ground = float(np.median(bottoms))
    if np.abs(bottoms - ground).max() > GROUND_SPREAD_RADII * r:
        raise InputError("--fill: the spheres' bottoms lie at z = " + ", ".join(f"{z:.4g}" for z in bottoms)
                         + f" ({source}): not on one ground plane; the fill needs the spheres on the ground and "
                           "world_from_camera's +Z up", where)
    if not capture.world_from_camera[2, 3] > ground:
        raise InputError(f"--fill: the camera (z = {capture.world_from_camera[2, 3]:.4g}) is not above the ground "
                         f"the spheres stand on (z = {ground:.4g})", where)
    margin = np.array([(lights.extra[i] or {}).get("uncertainty_deg") or 0.0 for i in idx], dtype=np.float64)
    return {"centres": centres, "radius": r, "ground_z": ground, "source": source, "margin_deg": margin}


def ground_world(capture, geometry: dict, ground_px) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A capture's camera and spheres in its world shifted to put the ground at z = 0.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
    geometry : dict
        :func:`sphere_geometry` of the capture.
    ground_px : (H, W) bool
        The pixels that see the ground (the surface mask off the object).

    Returns
    -------
    world_from_camera : (4, 4) float64
    centres : (k, 3) float64
        The spheres' centres.
    points : (H, W, 3) float64
        The ground points of ``ground_px`` (:func:`ffls.relight.sphere_shadows.ground_points`), NaN
        elsewhere.
    """
    from ffls.relight.sphere_shadows import ground_points

    M = np.array(capture.world_from_camera, dtype=np.float64)
    M[2, 3] -= geometry["ground_z"]
    centres = np.asarray(geometry["centres"], dtype=np.float64) - [0.0, 0.0, geometry["ground_z"]]
    H, W = np.shape(ground_px)
    pts = ground_points(capture.K, M, (W, H), dist=capture.dist)
    pts[~np.asarray(ground_px, dtype=bool)] = np.nan
    return M, centres, pts


def make_fills(args, inputs, relighters) -> tuple[list, object, str]:
    """``--fill``'s :class:`ffls.relight.sphere_shadows.SphereShadowFill` per capture and the object's
    :class:`ffls.relight.shadow_hull.ShadowHull`, and a line describing them.

    Each capture's spheres (:func:`sphere_geometry`, in ``inputs['fill_geometry']``) hide its photos'
    lights from the ground pixels of the surface mask (off the object); the world is shifted so that
    the ground is z = 0. The hull is carved from the object relighter's basis.
    """
    from ffls.relight.shadow_hull import ShadowHull
    from ffls.relight.sphere_shadows import SphereShadowFill, hidden_photos

    ground_px = (inputs["surface_mask"] > 0.5) & (inputs["object_mask"] < 0.5)
    fills, hull, lines = [], None, []
    for key, rel in zip(("object", "surface"), relighters):
        cap = inputs[key][0]
        geo = inputs["fill_geometry"][key]
        M, centres, pts = ground_world(cap, geo, ground_px)
        hidden = hidden_photos(pts, centres, geo["radius"], rel.directions, margin_deg=geo["margin_deg"])
        fills.append(SphereShadowFill(hidden, rel.directions, cap.hemisphere,
                                      geometry={"points": pts, "centres": centres, "radius": geo["radius"],
                                                "dilate_px": 1}))
        lines.append(f"{key}: {len(centres)} spheres ({geo['source']}), ground at z = {geo['ground_z']:.4g}")
        if key == "object":
            hull = ShadowHull.carve(rel.basis, rel.directions, inputs["object_mask"], cap.K, M, ground=ground_px,
                                    hidden=hidden, dist=cap.dist)
            units = f" {cap.units}" if getattr(cap, "units", None) else ""
            note = (f"the object's shadow hull: {int(hull.occupancy.sum())} voxels of {hull.voxel:.3g}{units}, "
                    f"umbra {hull.umbra:.2f}")
        del hidden
    return fills, hull, "fill " + args.fill + ": " + "; ".join(lines + [note])


def auto_fill(args, fields: dict, lightmap) -> tuple[str, dict, str]:
    """``--fill auto``: ``ground`` where the captures and the map allow it, else ``none``.

    The fill relights the map's compact sources (``--sources lightflow`` or ``levelset``, a map
    with one) from each capture's geometry (:func:`sphere_geometry`: a pinhole ``K``,
    ``world_from_camera``, ``sphere_radius``, distant lights, the spheres stated or found).

    Returns
    -------
    fill : {'ground', 'none'}
    geometry : dict
        :func:`sphere_geometry` of ``'object'`` and ``'surface'`` (empty for ``none``).
    why : str
        One clause: what allowed it, or why not.
    """
    from ffls.errors import InputError
    from ffls.relight.lightflow import split_compact_sources

    if args.sources == "weights":
        return "none", {}, "--sources weights splits off no compact source to relight"
    cap = fields["object"][0]
    split = split_compact_sources(lightmap, rotation_from_args(args), cap.hemisphere)
    if not split.sources:
        return "none", {}, "the light map has no compact source"
    try:
        geometry = {k: sphere_geometry(*fields[k]) for k in ("object", "surface")}
    except InputError as e:
        return "none", {}, str(e)
    return "ground", geometry, (f"{split.describe()}; both captures state their camera and sphere_radius, "
                                "and have distant lights and spheres")


def load_inputs(args):
    """The two captures and lights, light map, background and masks of ``args``, checked before any relighting.

    Returns
    -------
    dict
        ``object``, ``surface`` ((capture, lights) each), ``lightmap``, ``background`` (H, W, 3),
        ``object_mask``, ``surface_mask`` ((H, W) float32), ``notes`` (informational lines).
    """
    from ffls.commands.common import check_cells_res, check_mask_not_empty, check_rank_arg, coverage_notes
    from ffls.errors import InputError
    from ffls.io.capture import load_capture_and_lights
    from ffls.io.images import colour_summary, mask_note, read_image, read_mask
    from ffls.lightmaps.lightmap import lightmap_from_spec
    from ffls.relight.composite import check_same_camera

    fields = {}
    notes = []
    for key, folder, lights in (("object", args.object, args.object_lights),
                                ("surface", args.surface, args.surface_lights)):
        cap, li = load_capture_and_lights(folder, lights)
        idx, dirs = li.accepted()
        check_rank_arg(args.rank, len(idx), f"--rank (the {key} capture)")
        check_cells_res(args.cells_res, dirs, cap.hemisphere)
        fields[key] = (cap, li)
        notes += [li.note, colour_summary([cap.image_paths[i] for i in idx])]
        notes += [f"{key}: {w}" for w in coverage_notes(cap, li, idx, dirs)]
    (ocap, _), (scap, _) = fields["object"], fields["surface"]
    check_distinct_captures(ocap, scap)
    check_same_camera(ocap, scap, Path(scap.folder) / "capture.json")
    size = _image_size(ocap)
    ssize = _image_size(scap)
    if ssize != size:
        raise InputError(f"the surface capture's photos are {ssize[0]}x{ssize[1]}, the object capture's "
                         f"{size[0]}x{size[1]}: two fields from different cameras", scap.folder)
    bg_path = Path(args.background)
    if bg_path.suffix.lower() not in BACKGROUND_SUFFIXES:
        raise InputError("the background must be a linear HDR image (.exr or .hdr), not "
                         f"{bg_path.suffix or 'a file without an extension'}; "
                         "convert a photograph to linear radiance first (ffls never guesses an integer image's "
                         "encoding), or save a float TIFF as .exr", bg_path)
    bg = read_image(bg_path)
    if (bg.pixels.shape[1], bg.pixels.shape[0]) != size:
        raise InputError(f"the background is {bg.pixels.shape[1]}x{bg.pixels.shape[0]}, the captures' photos "
                         f"{size[0]}x{size[1]} (render the scene from the capture's camera at its size)", bg_path)
    neg = np.any(bg.pixels < 0, axis=-1)
    if neg.mean() > MAX_NEGATIVE_BACKGROUND:  # a filter's ringing touches a few pixels; more is not radiance
        raise InputError(f"the background has negative values in {100 * neg.mean():.1f}% of its pixels (lowest "
                         f"{float(bg.pixels.min()):.4g}): a linear radiance image has none (at most "
                         f"{100 * MAX_NEGATIVE_BACKGROUND:g}% from a reconstruction filter's ringing)", bg_path)
    if getattr(bg, "colour_note", None):
        notes.append(f"colour: background: {bg.colour_note}")
    om = read_mask(args.mask, size=size)
    check_mask_not_empty(om, args.mask)
    notes.append(mask_note(om, args.mask))
    sm = read_mask(args.surface_mask, size=size)
    if not ((sm > 0.5) & (om < 0.5)).any():
        raise InputError("the surface mask has no surface pixel outside the object's mask (white = surface)",
                         args.surface_mask)
    lm = lightmap_from_spec(args.lightmap, args.layout)
    if lm.colour_note:
        notes.append(f"colour: light map: {lm.colour_note}")
    geometry = {}  # last: finding the spheres reads every photo
    if getattr(args, "fill", "none") == "auto":
        args.fill, geometry, why = auto_fill(args, fields, lm)
        notes.append(f"fill auto: {args.fill} ({why})")
    elif getattr(args, "fill", "none") != "none":
        geometry = {k: sphere_geometry(*fields[k]) for k in ("object", "surface")}
    return {**fields, "lightmap": lm, "background": bg.pixels, "object_mask": om, "surface_mask": sm,
            "fill_geometry": geometry, "notes": notes}


def make_compositor(args, inputs):
    """A :class:`ffls.relight.composite.Compositor` over two CPU relighters (float32 sums, or ``--rank K``).

    With ``--sources lightflow`` or ``levelset`` each is a :class:`ffls.relight.lightflow.LightFlowRelighter`:
    the compact sources by flow or shadow level-set interpolation, the rest through the CPU relighter.
    """
    from ffls.relight.composite import Compositor
    from ffls.relight.cpu import CpuRelighter
    from ffls.relight.lightflow import LightFlowRelighter

    rel = [CpuRelighter.from_capture(*inputs[k], precision="f32", rank=args.rank, cell_res=args.cells_res,
                                     cell_max_res=4096, weighting=args.weighting)
           for k in ("object", "surface")]
    for k, r in zip(("object", "surface"), rel):  # --weighting kriging: each field learns its own kernel
        print_notes(NAME, compressed_note(r) and f"{k}: {compressed_note(r)}")
        if learnt_kernel(r):
            print(f"ffls composite: {k}: {learnt_kernel(r)}")
    if args.sources in ("lightflow", "levelset"):
        kind = "flow" if args.sources == "lightflow" else "levelset"
        fill = getattr(args, "fill", "none")
        if fill in ("none", "auto"):  # auto is resolved by load_inputs
            rel = [LightFlowRelighter(r, flow=args.flow, interpolation=kind) for r in rel]
        else:
            fills, hull, line = make_fills(args, inputs, rel)
            print(f"ffls composite: {line}")
            rel = [LightFlowRelighter(r, flow=args.flow, interpolation=kind, fill=f, fill_sources=FILL_SOURCES[fill],
                                      fill_rest=fill == "rest+model", hull=hull if k == 0 else None)
                   for k, (r, f) in enumerate(zip(rel, fills))]
    return Compositor(*rel, inputs["background"], inputs["object_mask"], inputs["surface_mask"],
                      method=args.method, registration=args.registration, object_scale=args.scale_object,
                      paths={"background": args.background, "object_mask": args.mask,
                             "surface_mask": args.surface_mask, "surface_relit": args.surface,
                             "object_relit": args.object})


def _display(img, exposure, tonemap):
    from ffls.display.tonemap import to_uint8, tonemap as tonemap_np

    return to_uint8(tonemap_np(img, exposure=exposure, method=tonemap))


def run(args) -> int:
    from ffls.conventions import rotation_z
    from ffls.display.tonemap import auto_exposure
    from ffls.errors import InputError, atomic_output, atomic_outputs
    from ffls.io.images import write_exr, write_png

    out = Path(args.out)
    check_output_kind(args, out)
    if args.flow is not None and args.sources == "weights":
        raise InputError(f"--flow {args.flow} applies to --sources lightflow or levelset; --sources weights uses "
                         "no flow")
    if args.fill not in ("auto", "none") and args.sources == "weights":
        raise InputError(f"--fill {args.fill} relights the compact sources on the ground: it needs --sources "
                         "lightflow or levelset, not weights")
    check_fps_flag(args, out)
    args.flow, args.fps = args.flow or "dis", args.fps or 30.0
    R0 = rotation_from_args(args)
    inputs = load_inputs(args)
    files = _siblings(out) if args.turntable is None else None  # after the inputs are known: none is replaced
    check_not_set_file(files.values() if files else [out], args.background)
    print_notes(NAME, *inputs["notes"])
    comp = make_compositor(args, inputs)
    try:
        comp.set_lightmap(inputs["lightmap"])
        comp.set_rotation(R0)
        res = comp.render()
        exposure = auto_exposure(res.image) if args.exposure == "auto" else float(args.exposure)
        reg = res.registration
        if args.turntable is None:
            with atomic_outputs():  # OUT.exr, OUT.png and OUT.json appear together or not at all
                write_exr(files[".exr"], res.image)
                write_png(files[".png"], _display(res.image, exposure, args.tonemap))
                report = {"format": "ffls-composite", "version": 1, "method": res.method,
                          "registration": reg.to_json(), "clamped_pixels": res.clamped_pixels,
                          "object": str(args.object), "surface": str(args.surface), "lightmap": str(args.lightmap),
                          "background": str(args.background), "exposure": exposure, "weighting": args.weighting,
                          "sources": args.sources, "fill": args.fill}
                split = getattr(comp.object, "last_split", None)
                if split is not None:
                    report["compact_sources"] = [{"direction": s.direction.tolist(), "power": s.power.tolist(),
                                                  "solid_angle": s.solid_angle, "samples": len(s.sample_powers)}
                                                 for s in split.sources]
                with atomic_output(files[".json"]) as tmp:
                    tmp.write_text(json.dumps(report, indent=1) + "\n")
            what = f"{files['.exr']}, {files['.png'].name} and {files['.json'].name}"
        else:
            from tqdm import tqdm

            from ffls.io.video import FrameWriter

            flush_notes()
            n = args.turntable
            with FrameWriter(out, fps=args.fps) as sink:
                for k in tqdm(range(n), desc="ffls composite", unit="frame", disable=None):
                    if k:
                        comp.set_rotation(rotation_z(360.0 * k / n) @ R0)
                        res = comp.render()
                    sink.write(_display(res.image, exposure, args.tonemap))
            what = sink.describe()
        split = getattr(comp.object, "last_split", None)
        print(f"ffls composite: {what} ({res.method}, {args.weighting} weighting"
              + (f", {split.describe()} relit by " + (f"{args.flow} flow" if args.sources == "lightflow" else
                                                       f"shadow level sets ({args.flow} flow)")
                 if split is not None else "") + f"); {reg.describe()}"
              + (f"; {res.clamped_pixels} negative pixels set to 0" if res.clamped_pixels else ""))
    finally:
        comp.release()
    return 0
