"""A synthetic test of differential rendering (Masselus et al. 2002, section 7; ``docs/composite.md``).

Writes what ``ffls composite`` takes and what it must reproduce:

* ``object/``: a capture of the object on its ground (albedo ``capture_albedo``) with the
  calibration spheres, one distant light per image;
* ``surface/``: a capture of the ground and the spheres alone, under *other* lights (another
  seed, possibly another count), as a second free-form pass would be;
* ``scene_map.exr``: the light map at the object's place in a *different* virtual scene: a base
  map (any light map) with a Lambertian wall of colour ``wall_albedo`` standing beside the object
  (out of the camera's frame), lit by the map's sky and the scene's ground;
* ``background.exr``: that virtual scene without the object: a ground of albedo
  ``scene_albedo`` (not the captured one) under the map, no spheres;
* ``truth.exr``: the virtual scene with the object, rendered directly under the map (cast
  shadows, and the ground's bounce onto the object, of the scene's albedo);
* ``object_mask.png`` (the object's pixels), ``surface_mask.png`` (the captured ground's pixels,
  spheres left out), ``sphere_mask.png`` (the spheres' pixels, to check they leave no trace);
* ``composite.json``: the parameters.

The wall is part of the light map, i.e. distant, which is the relighting's own assumption: the
truth is the scene a light map at the object's place describes exactly, so what the composite
misses is what differential rendering and the relighting miss (the discretisation of the map
over the capture's lights, and the captured ground's albedo in the object's own bounce light).
The synthetic renderer has no bounce from the object onto the ground (``ffls.synth.scene``); the
object changes the surface here through its shadows.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from ffls.conventions import latlong_directions
from ffls.errors import atomic_output
from ffls.lightmaps.lightmap import LightMap, save_lightmap
from ffls.synth.scene import (LABEL_GROUND, LABEL_OBJECT, LABEL_SPHERE0, make_scene, pixel_labels, render_lightmap,
                              stratified_directions, write_synthetic_capture)

__all__ = ["WALL", "wall_lightmap", "composite_masks", "render_virtual_scene", "virtual_camera",
           "write_composite_set", "COMPOSITE_FILE"]

#: Parameters of ``composite.json`` written by :func:`write_composite_set`.
COMPOSITE_FILE = "composite.json"
#: The default wall: the plane ``x = -0.8`` m from ``y = -1`` to ``1.5`` m, ``0.8`` m high, facing +X.
WALL = {"x": -0.8, "y": (-1.0, 1.5), "height": 0.8}


def wall_lightmap(lightmap, wall_albedo=(0.6, 0.35, 0.25), ground_albedo: float = 0.5, wall: dict | None = None,
                  height: int | None = None) -> LightMap:
    """The light map at the scene centre with a Lambertian wall standing in it (distant).

    The wall's texels (directions from the origin that hit the rectangle ``x = wall['x']``,
    ``wall['y'][0] <= y <= wall['y'][1]``, ``0 <= z <= wall['height']``) get the radiance
    ``albedo / pi * E``, where ``E`` is the irradiance on the wall's plane from the map's upper
    hemisphere on its side plus the scene's ground (albedo ``ground_albedo``, lit by the whole
    upper hemisphere and seen over half the wall's view: ``pi / 2`` of projected solid angle).

    Parameters
    ----------
    lightmap : LightMap
        The base map (any layout; resampled to lat-long).
    wall_albedo : (3,) float
    ground_albedo : float
    wall : dict, optional
        ``{"x": X, "y": (Y0, Y1), "height": Z}`` in metres (default :data:`WALL`); ``X`` < 0
        means the wall faces +X, ``X`` > 0 that it faces -X.
    height : int, optional
        Lat-long height of the result (default the base map's resolution).

    Returns
    -------
    LightMap
        Lat-long, float32.
    """
    wall = dict(WALL if wall is None else wall)
    h = int(height or lightmap.res)
    base = lightmap if (lightmap.layout == "latlong" and lightmap.res == h) else lightmap.to_latlong(h)
    data = base.data.astype(np.float64).copy()
    d = latlong_directions(2 * h, h)
    sa = base.solid_angles()
    x0 = float(wall["x"])
    y0, y1 = (float(v) for v in wall["y"])
    zt = float(wall["height"])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = x0 / d[..., 0]
        y, z = t * d[..., 1], t * d[..., 2]
    hit = (t > 0) & (y >= y0) & (y <= y1) & (z >= 0) & (z <= zt) & np.isfinite(t)
    n = np.array([-np.sign(x0), 0.0, 0.0])  # facing the origin
    up = d[..., 2] > 0
    cos_wall = np.clip(d @ n, 0.0, None)
    sky = up & ~hit
    E_sky = np.einsum("ij,ijc->c", sa * cos_wall * sky, data)
    E_ground = np.einsum("ij,ijc->c", sa * np.clip(d[..., 2], 0, None) * sky, data)
    E = E_sky + (np.pi / 2) * (float(ground_albedo) / np.pi) * E_ground
    data[hit] = np.asarray(wall_albedo, dtype=np.float64) / np.pi * E
    return LightMap(data.astype(np.float32), "latlong", source=f"{base.source} + wall")


def composite_masks(scene, resolution: int) -> dict:
    """The masks of a composite set: object, captured surface (ground, no spheres) and spheres, (R, R) bool.

    ``scene`` is the object capture's scene (object and spheres).
    """
    lab = pixel_labels(scene, int(resolution))
    surface = pixel_labels(dataclasses.replace(scene, with_object=False), int(resolution)) == LABEL_GROUND
    return {"object": lab == LABEL_OBJECT, "surface": surface, "spheres": lab >= LABEL_SPHERE0}


def virtual_camera(scene) -> dict:
    """The keywords of :func:`ffls.synth.scene.make_scene` that give the virtual scene ``scene``'s camera
    (distance, elevation, roll, field of view, target, model, supersampling): the truth and background
    are seen as the object and surface captures are."""
    return {k: getattr(scene, k) for k in ("camera_distance", "camera_elevation_deg", "camera_roll_deg",
                                           "camera_fov_deg", "camera_target", "camera_model", "supersample")}


def render_virtual_scene(lightmap, resolution: int, scene_albedo: float = 0.5, with_object: bool = True,
                         n_dirs: int = 2048, progress: bool = False, **scene_kwargs) -> np.ndarray:
    """The virtual scene rendered directly under ``lightmap`` (no spheres): (R, R, 3) float32.

    ``scene_kwargs`` go to :func:`ffls.synth.scene.make_scene` (camera, supersampling); the
    ground has albedo ``scene_albedo``.
    """
    scene = make_scene(spheres=0, with_object=with_object, ground_albedo=float(scene_albedo), **scene_kwargs)
    return render_lightmap(scene, lightmap, int(resolution), n_dirs=n_dirs, progress=progress)


def _write_mask(path: Path, m: np.ndarray) -> None:
    from ffls.io.images import write_png

    write_png(path, np.where(m, 255, 0).astype(np.uint8)[..., None].repeat(3, axis=2))


def write_composite_set(folder, lightmap, *, n_object_lights: int = 100, n_surface_lights: int | None = None,
                        resolution: int = 256, capture_albedo: float = 0.3, scene_albedo: float = 0.5,
                        wall_albedo=(0.6, 0.35, 0.25), wall: dict | None = None, spheres: int = 4,
                        sphere_material="matte", seed: int = 0, truth_dirs: int = 2048, photo=None,
                        progress: bool = False, scene=None) -> dict:
    """Write a composite test set into ``folder`` (see the module docstring for the files).

    Parameters
    ----------
    folder : path
    lightmap : LightMap
        The virtual scene's sky (the base of ``scene_map.exr``).
    n_object_lights, n_surface_lights : int
        Lights of the two captures (the surface's default: as many); their directions are drawn
        with seeds ``seed`` and ``seed + 1``.
    resolution : int
    capture_albedo, scene_albedo : float
        Ground albedo of the captures' table and of the virtual scene.
    wall_albedo, wall
        The wall (:func:`wall_lightmap`); ``wall_albedo=None`` leaves it out.
    spheres, sphere_material
        Calibration spheres of both captures (:func:`ffls.synth.scene.make_scene`).
    seed : int
    truth_dirs : int
        Distant lights the map is reduced to for the direct renders
        (:func:`ffls.synth.scene.render_lightmap`).
    photo : ffls.synth.photo.PhotoSettings, optional
        How the captures are stored (default linear EXR).
    progress : bool
    scene : ffls.synth.scene.SynthScene, optional
        The object capture's scene (its ground albedo, spheres, lens); replaces ``spheres``,
        ``sphere_material`` and ``capture_albedo``. The surface capture is it without the object;
        the virtual scene keeps its camera.

    Returns
    -------
    dict
        Paths (``object``, ``surface``, ``scene_map``, ``background``, ``truth``, ``object_mask``,
        ``surface_mask``, ``sphere_mask``) and the parameters written to ``composite.json``.
    """
    from ffls.io.images import write_exr

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    R = int(resolution)
    n_surface_lights = int(n_object_lights if n_surface_lights is None else n_surface_lights)
    if scene is None:
        scene = make_scene(spheres=spheres, sphere_material=sphere_material, ground_albedo=float(capture_albedo))
    obj_scene = dataclasses.replace(scene, with_object=True)
    camera = virtual_camera(obj_scene)
    surf_scene = dataclasses.replace(obj_scene, with_object=False)
    kw = {"resolution": R, "progress": progress, "photo": photo}
    write_synthetic_capture(folder / "object", scene=obj_scene,
                            directions=stratified_directions(int(n_object_lights), "upper", seed), seed=seed, **kw)
    write_synthetic_capture(folder / "surface", scene=surf_scene,
                            directions=stratified_directions(n_surface_lights, "upper", seed + 1), seed=seed + 1,
                            **kw)
    scene_map = lightmap if wall_albedo is None else wall_lightmap(lightmap, wall_albedo, scene_albedo, wall)
    paths = {k: folder / v for k, v in (("scene_map", "scene_map.exr"), ("background", "background.exr"),
                                         ("truth", "truth.exr"), ("object_mask", "object_mask.png"),
                                         ("surface_mask", "surface_mask.png"), ("sphere_mask", "sphere_mask.png"))}
    save_lightmap(scene_map, paths["scene_map"])
    for key, with_object in (("background", False), ("truth", True)):
        img = render_virtual_scene(scene_map, R, scene_albedo, with_object, n_dirs=truth_dirs, progress=progress,
                                   **camera)
        write_exr(paths[key], img)
    masks = composite_masks(obj_scene, R)
    for key in ("object", "surface"):
        _write_mask(paths[f"{key}_mask"], masks[key])
    _write_mask(paths["sphere_mask"], masks["spheres"])
    params = {
        "format": "ffls-composite-set", "version": 1, "resolution": R,
        "object": "object", "surface": "surface",
        "n_object_lights": int(n_object_lights), "n_surface_lights": n_surface_lights, "seed": int(seed),
        "capture_albedo": float(obj_scene.ground_albedo), "scene_albedo": float(scene_albedo),
        "wall_albedo": None if wall_albedo is None else [float(v) for v in wall_albedo],
        "wall": None if wall_albedo is None else {k: (list(v) if isinstance(v, tuple) else v)
                                                  for k, v in dict(WALL if wall is None else wall).items()},
        "base_map": str(lightmap.source), "truth_dirs": int(truth_dirs), "spheres": obj_scene.n_spheres,
        **{k: p.name for k, p in paths.items()},
    }
    with atomic_output(folder / COMPOSITE_FILE) as tmp:
        tmp.write_text(json.dumps(params, indent=1) + "\n")
    return {**{k: folder / v for k, v in (("object", "object"), ("surface", "surface"))}, **paths, "params": params}
