"""Differential rendering on independent, path-traced renders (Mitsuba 3; docs/composite.md).

Nothing here comes from ``ffls.synth``: Mitsuba 3's path tracer (``max_depth`` 6: the object's
shadow *and* its bounce light on the ground, the ground's light on the object, interreflections)
renders

* the object capture: a rotated blue cube with a red ball on it and a green cylinder beside it,
  on a grey diffuse ground (albedo 0.3) with four white diffuse spheres (albedo 0.8, r = 5 cm),
  one ``directional`` light of irradiance 1 per image, N stratified directions (seed 0);
* the surface capture: the ground and spheres alone, N other directions (seed 1);
* the virtual scene under a real HDR map (``envmap`` with :data:`ENVMAP_TO_WORLD`): another
  ground albedo (0.5) and a real wall (a 2.5 m x 0.8 m rectangle 0.8 m to the -X side, albedo
  0.6, 0.35, 0.25): the background (no object, no spheres), the truth (with the object), and the
  scene's light map at the object's place (``scripts/mitsuba_latlong.py``'s lat-long sensor 8 cm
  above the ground, without the object);
* the masks, by casting the camera's rays.

Then ``ffls composite``'s library path (:func:`ffls.commands.composite.make_compositor`'s pieces:
:class:`ffls.relight.cpu.CpuRelighter` per capture, :func:`ffls.relight.composite.composite`) and
the errors of ``benchmarks/composite.py`` (change region: surface pixels off the object where the
truth differs from the background by more than 3%; pasting without the shadow; the ring around
the spheres) and the spheres' *shadow trace*: the composite's relative difference from the
background over the surface pixels off the change region and off the spheres' ring where the relit
surface-alone capture is more than 3% darker (over the background) than its median, i.e. in the
calibration spheres' shadows, which the virtual scene does not have. ``lit_trace`` is the same over
the other such pixels: the floor the shadow trace is read against. The change-region error is
also split at the same shadows (``change_in_shadows``, ``change_off_shadows``): inside them neither
capture holds the light the spheres block, so what the object blocks of it is in neither. For
``--sources lightflow``/``levelset`` each compact source's own sphere shadows are also found from
the geometry (:func:`sphere_shadows`: the spheres, the camera, the source's direction and angular
radius) and the change error split there (``source_shadows``).

    python benchmarks/composite_mitsuba.py [--maps courtyard,sunrise,studio] [--lights 100,200]
        [--res 128] [--spp 16] [--truth-spp 1024] [--map-spp 256] [--cache DIR] [--schemes voronoi,...]
        [--sources weights,lightflow,levelset] [--fill none,rest,all,model,rest+model,ground] [--spheres scene|found]

``--sources lightflow`` relights the map's compact sources by flow interpolation between the
(path-traced, noisy) basis photos, ``--sources levelset`` by moving the basis photos' cast shadows
(:class:`ffls.relight.lightflow.LightFlowRelighter`, ``interpolation='flow'`` or ``'levelset'``).
``--fill rest`` fills the calibration spheres' shadows in both captures
(:class:`ffls.relight.sphere_shadows.SphereShadowFill`, from the spheres' centres and radius, the
ground and the camera): a photo's weight at a pixel it sees through a sphere goes to the photos that
see the pixel; ``--fill all`` also fills the compact sources' photos where they are hidden (the visible
photos' blend). ``--fill model`` fills only the compact sources where a sphere hides them, with the
visible photos' unshadowed model times the object's visibility through its shadow hull
(:class:`ffls.relight.shadow_hull.ShadowHull`, carved from the object capture's own shadows; the
surface capture gets the model alone), and checks the hull's shadow of each source against a render
(:func:`hull_shadow_check`); ``--fill rest+model`` also fills the rest's weights; ``--fill ground``
relights the compact sources from the model times the hull on every ground pixel, not only in the
spheres' shadows. The fills take the scene's sphere centres, or with ``--spheres found`` each
capture's spheres found in its photos and the ground under them, as ``ffls composite --fill`` does
(:func:`ffls.commands.composite.sphere_geometry`); the errors are measured on the scene's geometry.

Needs ``pip install mitsuba`` (``ffls[validate]``). Writes ``benchmarks/results/composite_mitsuba.json``.
"""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import cv2
import numpy as np

from common import host_info, mitsuba_latlong_module, write_json

from ffls.assets import builtin_lightmaps
from ffls.commands.composite import ground_world, sphere_geometry
from ffls.io.capture import Capture, Lights, load_capture_and_lights, save_capture, save_lights
from ffls.io.images import read_image, write_exr
from ffls.lightmaps.lightmap import load_lightmap
from ffls.relight.composite import LUMINANCE, METHODS, composite
from ffls.relight.cpu import CpuRelighter
from ffls.relight.lightflow import LightFlowRelighter
from ffls.relight.basis import accepted_basis
from ffls.relight.shadow_hull import ShadowHull
from ffls.relight.sphere_shadows import SphereShadowFill, ground_points, hidden_photos
from ffls.synth.scene import stratified_directions

CAPTURE_ALBEDO, SCENE_ALBEDO = 0.3, 0.5
WALL_ALBEDO = (0.6, 0.35, 0.25)
CAM_ORIGIN, CAM_TARGET, FOV = (0.0, -0.866, 0.55), (0.0, 0.0, 0.05), 46.0
SPHERES = ((-0.25, -0.25), (0.25, -0.25), (0.25, 0.25), (-0.25, 0.25))
#: ``--fill`` values that fill the rest's weights.
FILL_REST = ("rest", "all", "rest+model")
#: ``--fill`` values that relight the compact sources from the unshadowed model and the shadow hull.
MODEL_FILLS = ("model", "rest+model", "ground")


def _diffuse(rgb):
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb) if np.ndim(rgb) else rgb}}


def scene_shapes(mi, ground_albedo, with_object, spheres, wall):
    T = mi.ScalarTransform4f
    s = {"ground": {"type": "rectangle", "to_world": T().scale([3.0, 3.0, 1.0]), "bsdf": _diffuse(ground_albedo)}}
    if with_object:
        s["cube"] = {"type": "cube", "to_world": T().translate([0, 0, 0.05]).rotate([0, 0, 1], 25).scale(0.08),
                     "bsdf": _diffuse((0.12, 0.22, 0.55))}
        s["ball"] = {"type": "sphere", "center": [0.0, 0.0, 0.18], "radius": 0.08,
                     "bsdf": {"type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.55, 0.1, 0.07]}}}
        s["post"] = {"type": "cylinder", "p0": [0.15, -0.08, 0.0], "p1": [0.15, -0.08, 0.2], "radius": 0.025,
                     "bsdf": _diffuse((0.2, 0.5, 0.12))}
    if spheres:
        for k, (x, y) in enumerate(SPHERES):
            s[f"sphere{k}"] = {"type": "sphere", "center": [x, y, 0.05], "radius": 0.05, "bsdf": _diffuse(0.8)}
    if wall:
        # a 2.5 m x 0.8 m wall in the plane x = -0.8 facing +X (y from -1 to 1.5, z from 0 to 0.8)
        s["wall"] = {"type": "rectangle", "bsdf": _diffuse(WALL_ALBEDO),
                     "to_world": T().translate([-0.8, 0.25, 0.4]).rotate([0, 1, 0], 90).scale([0.4, 1.25, 1.0])}
    return s


def camera_sensor(mi, res, spp):
    T = mi.ScalarTransform4f
    return {"type": "perspective", "fov": FOV, "fov_axis": "x",
            "to_world": T().look_at(origin=list(CAM_ORIGIN), target=list(CAM_TARGET), up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp}}


def camera_matrices(res):
    """K and world_from_camera (OpenCV axes) of the Mitsuba camera."""
    f = 0.5 * res / math.tan(math.radians(FOV) / 2)
    K = np.array([[f, 0, 0.5 * (res - 1)], [0, f, 0.5 * (res - 1)], [0, 0, 1.0]])
    o, t = np.array(CAM_ORIGIN), np.array(CAM_TARGET)
    z = (t - o) / np.linalg.norm(t - o)
    x = np.cross(z, [0, 0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = x, y, z, o
    return K, M


def render_capture(mi, folder: Path, n, seed, with_object, res, spp, seed_offset=0):
    """Render (once, cached in ``folder``) a capture of ``n`` directional lights; ``seed`` picks the
    directions, ``seed_offset`` shifts the renders' sampler seeds (an independent set of the same lights)."""
    folder.mkdir(parents=True, exist_ok=True)
    dirs = stratified_directions(n, "upper", seed)
    names = [f"img_{i:04d}.exr" for i in range(n)]
    if not (folder / "capture.json").exists():
        base = {"type": "scene", "integrator": {"type": "path", "max_depth": 6}, "sensor": camera_sensor(mi, res, spp),
                **scene_shapes(mi, CAPTURE_ALBEDO, with_object, True, False)}
        for i, d in enumerate(dirs):
            sc = mi.load_dict({**base, "light": {"type": "directional", "direction": list(-d),
                                                 "irradiance": {"type": "rgb", "value": 1.0}}})
            write_exr(folder / names[i], np.array(mi.render(sc, seed=seed * 100003 + seed_offset + i)), half=False)
        K, M = camera_matrices(res)
        save_lights(Lights(image_names=names, directions=dirs), folder / "lights.json")
        save_capture(Capture(folder=folder, image_names=names, encoding="linear", K=K, dist=np.zeros(5),
                             world_from_camera=M, world_from_camera_is_default=False, sphere_radius=0.05,
                             image_size=(res, res), hemisphere="upper", units="m"))
    return load_capture_and_lights(folder)


def sphere_shadows(res, direction, radius_deg):
    """Ground pixels in the calibration spheres' shadows from a distant source (geometry, no render).

    Parameters
    ----------
    res : int
        Image width and height, pixels.
    direction : (3,) array_like
        Direction towards the source (world frame, z up).
    radius_deg : float
        The source's angular radius: the shadow widens by ``t tan(radius)`` at distance ``t`` from
        the sphere (its penumbra).

    Returns
    -------
    (res, res) bool array
        Pixels whose ground point (z = 0 along the camera's pixel-centre ray) sees the source
        through one of :data:`SPHERES` (radius 5 cm, centres 5 cm above the ground).
    """
    K, M = camera_matrices(res)
    jj, ii = np.mgrid[0:res, 0:res].astype(np.float64)
    rays = np.stack([(ii - K[0, 2]) / K[0, 0], (jj - K[1, 2]) / K[1, 1], np.ones_like(ii)], -1) @ M[:3, :3].T
    origin = M[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -origin[2] / rays[..., 2]
    ground = origin + np.where(t > 0, t, np.nan)[..., None] * rays
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    hidden = np.zeros((res, res), dtype=bool)
    for x, y in SPHERES:
        v = np.array([x, y, 0.05]) - ground
        along = v @ d
        off = np.linalg.norm(v - along[..., None] * d, axis=-1)
        with np.errstate(invalid="ignore"):
            hidden |= (along > 0) & (off < 0.05 + along * math.tan(math.radians(radius_deg)))
    return hidden


def hull_shadow_check(mi, res, hull, ground, surface, direction, spp=8):
    """The shadow hull's shadow against the object's real one under a distant light from ``direction``.

    Renders the object on the ground (no spheres) with and without the object under one
    ``directional`` light; the real shadow is the surface pixels where the first is below half the
    second; the hull's, where :meth:`ffls.relight.shadow_hull.ShadowHull.shadow` > 1/2 at the
    pixels' ground points. Returns ``{"iou", "true_px", "hull_px", "missed", "extra"}``.
    """
    base = {"type": "scene", "integrator": {"type": "path", "max_depth": 2}, "sensor": camera_sensor(mi, res, spp)}
    lum = []
    for obj in (True, False):
        sc = mi.load_dict({**base, **scene_shapes(mi, CAPTURE_ALBEDO, obj, False, False),
                           "light": {"type": "directional", "direction": list(-np.asarray(direction, dtype=float)),
                                     "irradiance": {"type": "rgb", "value": 1.0}}})
        lum.append(np.array(mi.render(sc, seed=5)) @ LUMINANCE)
    true = surface & (lum[0] < 0.5 * lum[1])
    got = surface & (hull.shadow(ground.reshape(-1, 3), direction).reshape(surface.shape) > 0.5)
    union = int((true | got).sum())
    return {"iou": float((true & got).sum() / union) if union else float("nan"), "true_px": int(true.sum()),
            "hull_px": int(got.sum()), "missed": int((true & ~got).sum()), "extra": int((got & ~true).sum())}


def cast_masks(mi, res):
    """Object, surface (ground, no spheres) and sphere masks by casting the camera's pixel-centre rays."""
    scene = mi.load_dict({"type": "scene", "sensor": camera_sensor(mi, res, 1), **scene_shapes(mi, 0.3, True, True, False)})
    sensor = scene.sensors()[0]
    ids = {}
    for k, sh in enumerate(scene.shapes()):
        ids[k] = sh.id()
    label = np.empty((res, res), dtype=object)
    for j in range(res):
        for i in range(res):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((i + 0.5) / res, (j + 0.5) / res), mi.Point2f(0.5, 0.5))
            si = scene.ray_intersect(ray)
            label[j, i] = si.shape.id() if si.is_valid() else ""
    obj = np.isin(label, ["cube", "ball", "post"])
    sph = np.char.startswith(label.astype(str), "sphere")
    return obj, label == "ground", sph



def scene_render(mi, ll, name, res, spp, *, with_object=False, seed=7, latlong_height=None):
    """The virtual scene (ground ``SCENE_ALBEDO``, the wall, no spheres) under built-in map ``name``:
    from the camera (``res``), or with ``latlong_height`` the map at the object's place (8 cm up, no object)."""
    env = {"type": "envmap", "filename": str(builtin_lightmaps()[name]),
           "to_world": mi.ScalarTransform4f(ll.ENVMAP_TO_WORLD)}
    if latlong_height:
        sensor = {**ll.latlong_sensor((0.0, 0.0, 0.08), latlong_height),
                  "sampler": {"type": "independent", "sample_count": spp}}
    else:
        sensor = camera_sensor(mi, res, spp)
    sc = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 6}, "env": env, "sensor": sensor,
                       **scene_shapes(mi, SCENE_ALBEDO, with_object, False, True)})
    return np.array(mi.render(sc, seed=seed))


def scene_renders(mi, ll, cache: Path, name, res, truth_spp, map_height, map_spp=256):
    """Background, truth (``res`` x ``res``, ``truth_spp``) and the scene's light map (``map_spp``), rendered
    once into ``cache``."""
    files = {k: cache / f"{name}_{k}_{res}_{truth_spp}.exr" for k in ("background", "truth")}
    files["map"] = cache / f"{name}_map_{res}_{map_spp}.exr"
    for key, with_object in (("background", False), ("truth", True)):
        if not files[key].exists():
            write_exr(files[key], scene_render(mi, ll, name, res, truth_spp, with_object=with_object, seed=7), half=False)
    if not files["map"].exists():
        write_exr(files["map"], scene_render(mi, ll, name, res, map_spp, seed=11, latlong_height=map_height),
                  half=False)
    bg = read_image(files["background"]).pixels.astype(np.float64)
    tr = read_image(files["truth"]).pixels.astype(np.float64)
    return bg, tr, load_lightmap(files["map"])


def change_region(truth, background, surface, obj, threshold=0.03):
    """Surface pixels off the object where the truth's luminance differs from the background's by more than 3%."""
    lt, lb = truth @ LUMINANCE, background @ LUMINANCE
    return surface & ~obj & (np.abs(lt - lb) > threshold * lb)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", default="courtyard,sunrise,studio")
    ap.add_argument("--lights", default="100,200")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--truth-spp", type=int, default=1024)
    ap.add_argument("--map-height", type=int, default=128)
    ap.add_argument("--map-spp", type=int, default=256, help="samples per pixel of the scene's light map")
    ap.add_argument("--schemes", default="voronoi", help="weighting schemes (ffls.weights.weighting.SCHEMES)")
    ap.add_argument("--sources", default="weights,lightflow",
                    help="how compact sources are relit: weights (every texel weighted), lightflow (photos warped by "
                         "their flow), levelset (cast shadows moved by their signed distances; ffls.relight.lightflow)")
    ap.add_argument("--fill", default="none",
                    help="the calibration spheres' shadows filled (ffls.relight.sphere_shadows) in both captures, "
                         "with --sources lightflow/levelset: none, rest (the rest's weights), all (and the sources), "
                         "model (the sources alone, from the unshadowed model and the object's shadow hull), "
                         "rest+model, ground (the sources from the model and the hull on every ground pixel)")
    ap.add_argument("--spheres", default="scene", choices=("scene", "found"),
                    help="the calibration spheres' centres for --fill: the scene's (default), or found in each "
                         "capture's photos as ffls composite --fill does (ffls.commands.composite.sphere_geometry; "
                         "the ground under them)")
    ap.add_argument("--cache", default="/tmp/ffls_bench_composite_mitsuba")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "composite_mitsuba.json"))
    a = ap.parse_args()
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    ll = mitsuba_latlong_module()
    ll.register()
    cache = Path(a.cache)
    cache.mkdir(parents=True, exist_ok=True)
    R = a.res
    t0 = time.perf_counter()
    om_b, sm_b, sph = cast_masks(mi, R)
    om, sm = om_b.astype(np.float64), sm_b.astype(np.float64)
    grow = max(2, int(round(0.02 * R)))
    near_sph = cv2.dilate(sph.astype(np.uint8), cv2.getStructuringElement(
        cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1))).astype(bool)
    caps, fills, hulls, hull_points = {}, {}, {}, {}
    K, M = camera_matrices(R)
    ground = ground_points(K, M, (R, R))
    ground[~sm_b] = np.nan  # the ground the camera sees: neither the object nor a sphere
    centres = [(x, y, 0.05) for x, y in SPHERES]
    for n in (int(v) for v in a.lights.split(",")):
        caps[n] = (render_capture(mi, cache / f"object_{R}_{n}_{a.spp}", n, 0, True, R, a.spp),
                   render_capture(mi, cache / f"surface_{R}_{n}_{a.spp}", n, 1, False, R, a.spp))
        geometry = [(ground, centres, M)] * 2
        if a.spheres == "found":  # each capture's own spheres, the world shifted to put the ground at z = 0
            geometry = []
            for cap in caps[n]:
                geo = sphere_geometry(*cap)
                Mk, ck, pk = ground_world(cap[0], geo, sm_b)
                geometry.append((pk, ck, Mk))
                print(f"{len(geo['centres'])} spheres found in {cap[0].folder.name}, "
                      f"{1000 * max(np.linalg.norm(np.subtract(centres, c), axis=1).min() for c in geo['centres']):.1f}"
                      f" mm off at most; ground at z = {geo['ground_z']:.4f}", flush=True)
        fills[n] = tuple(SphereShadowFill.from_geometry(g, c, 0.05, lights.directions)
                         for (_, lights), (g, c, _) in zip(caps[n], geometry))
        if any(f in MODEL_FILLS for f in a.fill.split(",")):
            basis, dirs = accepted_basis(*caps[n][0])
            g, c, Mo = geometry[0]
            hulls[n] = ShadowHull.carve(basis, dirs, om_b, K, Mo, ground=sm_b, hidden=hidden_photos(g, c, 0.05, dirs))
            hull_points[n] = g  # the hull's world: the ground points it casts its shadow onto
            print(f"shadow hull of the {n}-light object capture: {int(hulls[n].occupancy.sum())} voxels of "
                  f"{1000 * hulls[n].voxel:.1f} mm, umbra {hulls[n].umbra:.2f} ({time.perf_counter() - t0:.0f} s)",
                  flush=True)
        print(f"captures of {n} lights ready ({time.perf_counter() - t0:.0f} s)", flush=True)
    rows = []
    for name in a.maps.split(","):
        bg, tr, lm = scene_renders(mi, ll, cache, name, R, a.truth_spp, a.map_height, a.map_spp)
        change = change_region(tr, bg, sm_b, om_b)
        ring = near_sph & sm_b & ~change
        rest = sm_b & ~change & ~near_sph
        for n, ((oc, ol), (sc_, sl)), scheme, sources, fill in (
                (n, c, sch, src, f) for n, c in caps.items() for sch in a.schemes.split(",")
                for src in a.sources.split(",") for f in a.fill.split(",")):
            if fill != "none" and sources == "weights":
                continue
            o = CpuRelighter.from_capture(oc, ol, precision="f64", cell_max_res=4096, weighting=scheme)
            s = CpuRelighter.from_capture(sc_, sl, precision="f64", cell_max_res=4096, weighting=scheme)
            if sources in ("lightflow", "levelset"):
                kind = "flow" if sources == "lightflow" else "levelset"
                fo, fs = fills[n] if fill != "none" else (None, None)
                mode = {"all": "blend", "model": "model", "rest+model": "model", "ground": "ground"}.get(fill, False)
                o = LightFlowRelighter(o, interpolation=kind, fill=fo, fill_sources=mode, fill_rest=fill in FILL_REST,
                                       hull=hulls[n] if fill in MODEL_FILLS else None)
                s = LightFlowRelighter(s, interpolation=kind, fill=fs, fill_sources=mode, fill_rest=fill in FILL_REST)
            for r in (o, s):
                r.set_lightmap(lm)
                r.render()
            oh, sh = o.read_hdr().astype(np.float64), s.read_hdr().astype(np.float64)
            note = o.last_split.describe() if sources != "weights" else ""
            paste = bg * (1 - om[..., None]) + oh * om[..., None]
            # The spheres' shadows in the relit surface-alone capture: its luminance over the background's
            # more than 3% (the change region's threshold) below its median over the surface, whatever
            # the albedos' ratio; the composite should equal the background there (no trace).
            q = (sh @ LUMINANCE) / np.maximum(bg @ LUMINANCE, 1e-12)
            in_shadow = sm_b & ~near_sph & (q < 0.97 * np.median(q[rest]))
            shadowed, lit = rest & in_shadow, rest & ~in_shadow
            # Each compact source's own (hard) sphere shadows, from the scene's geometry: there the
            # captures hold none of that source's light, so the object's shadow from it is in neither.
            hard = [(src, sphere_shadows(R, src.direction, src.radius_deg) & sm_b)
                    for src in (o.last_split.sources if sources != "weights" else ())]
            checked = {}

            def hull_checks(direction):
                key = tuple(np.round(direction, 9))
                if key not in checked:
                    checked[key] = hull_shadow_check(mi, R, hulls[n], hull_points[n], sm_b, direction)
                return checked[key]

            for method in METHODS:
                res = composite(bg, oh, sh, om, sm, method=method)
                c = res.image.astype(np.float64)

                def rel(x, m):
                    return float(np.abs(x - tr)[m].sum() / max(tr[m].sum(), 1e-30))

                def trace(x, m):
                    return float(np.abs(x - bg)[m].sum() / max(bg[m].sum(), 1e-30)) if m.any() else float("nan")

                rows.append({"map": name, "lights": n, "scheme": scheme, "sources": sources, "fill": fill,
                             "method": method,
                             "change": rel(c, change), "paste": rel(paste, change),
                             "overall": rel(c, np.ones_like(change)), "object": rel(c, om_b),
                             "sphere_trace": float((np.abs(c - bg)[ring] @ LUMINANCE).mean()
                                                   / (bg[ring] @ LUMINANCE).mean()),
                             "shadow_trace": trace(c, shadowed), "lit_trace": trace(c, lit),
                             "shadow_pixels": int(shadowed.sum()),
                             "change_in_shadows": rel(c, change & in_shadow),
                             "change_off_shadows": rel(c, change & ~in_shadow),
                             "change_pixels_in_shadows": int((change & in_shadow).sum()),
                             "change_pixels": int(change.sum()), "registration": res.registration.to_json(),
                             "compact_sources": note})
                total = max(float(np.abs(c - tr)[change].sum()), 1e-30)
                rows[-1]["source_shadows"] = [
                    {"direction": src.direction.tolist(), "radius_deg": src.radius_deg,
                     "power_share": float(src.power @ LUMINANCE) / max(float(
                         o.last_split.rest.total_power() @ LUMINANCE + o.last_split.source_power @ LUMINANCE), 1e-30),
                     "change_pixels_in": int((change & h).sum()), "change_in": rel(c, change & h),
                     "change_off": rel(c, change & ~h),
                     "error_share_in": float(np.abs(c - tr)[change & h].sum() / total),
                     "trace": trace(c, h & ~change & ~near_sph),
                     "hull_shadow": hull_checks(src.direction) if fill in MODEL_FILLS else None}
                    for src, h in hard]
                x = rows[-1]
                print(f"{name:10s} {n:4d} {scheme:12s} {sources:9s} fill {fill:4s} {method:12s} change {100 * x['change']:5.1f}%  "
                      f"paste {100 * x['paste']:5.1f}%  overall {100 * x['overall']:4.1f}%  object "
                      f"{100 * x['object']:4.1f}%  sphere trace {100 * x['sphere_trace']:4.1f}%  shadow trace "
                      f"{100 * x['shadow_trace']:4.1f}% ({x['shadow_pixels']} px, lit {100 * x['lit_trace']:4.1f}%)  "
                      f"change in / off the spheres' shadows {100 * x['change_in_shadows']:4.1f} / "
                      f"{100 * x['change_off_shadows']:4.1f}% ({x['change_pixels_in_shadows']} px in)  "
                      f"({x['change_pixels']} px) {note}", flush=True)
                for k, h in enumerate(x["source_shadows"]):
                    hs = h["hull_shadow"]
                    hull_note = "" if hs is None else (
                        f"; the hull's shadow of it: IoU {hs['iou']:.2f} with a render ({hs['true_px']} px, "
                        f"{hs['missed']} missed, {hs['extra']} extra)")
                    print(f"    source {k}: its spheres' shadows hold {h['change_pixels_in']} change px, error "
                          f"{100 * h['change_in']:4.1f}% there ({100 * h['error_share_in']:3.0f}% of the change "
                          f"error), {100 * h['change_off']:4.1f}% off them; trace there {100 * h['trace']:4.1f}%"
                          f"{hull_note}", flush=True)
    write_json(a.out, {"resolution": R, "spp": a.spp, "spheres": a.spheres, "truth_spp": a.truth_spp, "map_spp": a.map_spp,
                       "capture_albedo": CAPTURE_ALBEDO,
                       "scene_albedo": SCENE_ALBEDO, "host": host_info(), "seconds": time.perf_counter() - t0,
                       "rows": rows})


if __name__ == "__main__":
    main()
