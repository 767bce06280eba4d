"""Synthetic probe scenes with known lighting, for the inverse methods of :mod:`ffls.probes`.

* :func:`diffuse_sphere_scene` -- a Lambertian sphere seen by an orthographic camera (a ball
  seen from far away), lit by a lat-long map: every pixel's irradiance is the map integrated
  against the clamped cosine, ``sum L max(0, n . w) dw`` over all texels (no discretisation
  beyond the map's own texels).
* :func:`cast_shadow_scene` -- an axis-aligned box standing on the plane ``z = 0``, seen from
  straight above by an orthographic camera; the plane's pixels are lit by the map reduced to
  ``n_dirs`` distant lights (:func:`ffls.synth.scene.cluster_lightmap`, the oracle's
  discretisation) with shadow rays against the box (:func:`ffls.synth.geometry.occluded`, the
  synthetic renderer's ray code, independent of the probes' visibility tests). The plane is
  Lambertian (``rho / pi``) or follows the simplified Torrance-Sparrow model of Sato, Sato and
  Ikeuchi; a shadow-free "surface image" (no box) is made too, for the unknown-albedo case.

The camera convention is GUIDE section 1: pixel ``(x, y)`` with ``x`` right and ``y`` down.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA, normalize
from ffls.errors import atomic_output
from ffls.io.images import write_exr
from ffls.lightmaps.lightmap import as_samples
from ffls.synth.geometry import Box, Material, occluded
from ffls.synth.scene import cluster_lightmap

__all__ = ["SphereProbeScene", "diffuse_sphere_scene", "write_diffuse_probe", "ShadowScene", "cast_shadow_scene", "checker_albedo"]


@dataclass(frozen=True)
class SphereProbeScene:
    """A rendered diffuse sphere and its ground truth.

    Attributes
    ----------
    image : (res, res, 3) float32
        Linear radiance; 0 off the sphere.
    mask : (res, res) bool
        Sphere pixels.
    normals : (m, 3) float64
        World-frame normals of the mask pixels (row-major order).
    radiance : (m, 3) float64
        Their values.
    albedo : float
    center_px : (2,) float
    radius_px : float
    world_from_camera : (4, 4) float64
    """

    image: np.ndarray
    mask: np.ndarray
    normals: np.ndarray
    radiance: np.ndarray
    albedo: float
    center_px: np.ndarray
    radius_px: float
    world_from_camera: np.ndarray


def _map_irradiance(normals: np.ndarray, lightmap, chunk: int = 2048) -> np.ndarray:
    dirs, rad, sa = as_samples(lightmap)
    p = rad * sa[:, None]
    nz = np.any(p != 0, axis=1)
    dirs, p = dirs[nz], p[nz]
    out = np.empty((normals.shape[0], 3))
    for s in range(0, normals.shape[0], chunk):
        out[s:s + chunk] = np.maximum(normals[s:s + chunk] @ dirs.T, 0.0) @ p
    return out


def diffuse_sphere_scene(lightmap, resolution: int = 128, albedo: float = 0.7, world_from_camera=None,
                         radius_frac: float = 0.45) -> SphereProbeScene:
    """Render a Lambertian sphere under a light map with an orthographic camera.

    Parameters
    ----------
    lightmap : LightMap or (dirs, radiance, solid_angle)
    resolution : int
        Image side (pixels).
    albedo : float
        Radiance = ``albedo / pi`` x irradiance.
    world_from_camera : (4, 4) array_like, optional
        Camera pose (only its rotation matters); GUIDE's default (looking along +Y, image up +Z).
    radius_frac : float
        Sphere radius as a fraction of the image side.

    Returns
    -------
    SphereProbeScene
    """
    res = int(resolution)
    T = DEFAULT_WORLD_FROM_CAMERA if world_from_camera is None else np.asarray(world_from_camera, dtype=np.float64)
    R = T[:3, :3]
    c = np.array([(res - 1) / 2.0, (res - 1) / 2.0])
    r = radius_frac * res
    y, x = np.mgrid[0:res, 0:res]
    a = (x - c[0]) / r
    b = (y - c[1]) / r
    q = 1.0 - a * a - b * b
    mask = q > 0
    ncam = np.stack([a[mask], b[mask], -np.sqrt(q[mask])], axis=1)
    normals = normalize(ncam @ R.T)
    E = _map_irradiance(normals, lightmap)
    rad = albedo / np.pi * E
    img = np.zeros((res, res, 3), dtype=np.float32)
    img[mask] = rad
    return SphereProbeScene(image=img, mask=mask, normals=normals, radiance=rad, albedo=float(albedo),
                            center_px=c, radius_px=float(r), world_from_camera=T)


def write_diffuse_probe(folder, scene: SphereProbeScene, image_name: str = "ball.exr") -> Path:
    """Write ``scene`` as a probe folder for ``ffls probe diffuse | pocs``: its image (EXR) and a
    ``probe.json`` with its orthographic camera and the sphere's pixel circle and albedo.

    Returns
    -------
    Path
        ``folder`` (made if missing).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_exr(folder / image_name, scene.image)
    doc = {"format": "ffls-probe", "version": 1, "images": [image_name],
           "camera": {"model": "orthographic", "world_from_camera": np.asarray(scene.world_from_camera).tolist()},
           "sphere": {"center_px": np.asarray(scene.center_px).tolist(), "radius_px": float(scene.radius_px),
                      "material": "diffuse", "albedo": float(scene.albedo)}}
    with atomic_output(folder / "probe.json") as tmp:
        tmp.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return folder


def checker_albedo(points: np.ndarray, period: float = 0.1, low: float = 0.35, high: float = 0.8) -> np.ndarray:
    """A grey checkerboard albedo (m,) over plane points (m, 3), squares of side ``period / 2``."""
    k = np.floor(points[:, 0] / (0.5 * period)) + np.floor(points[:, 1] / (0.5 * period))
    return np.where(np.mod(k, 2) == 0, low, high)


@dataclass(frozen=True)
class ShadowScene:
    """A box's shadow on the plane ``z = 0`` seen from above, and its ground truth.

    Attributes
    ----------
    image : (res, res, 3) float32
        The shadow image (linear radiance); the box's own pixels are 0.
    surface_image : (res, res, 3) float32
        The same view without the box (no shadow).
    mask : (res, res) bool
        Pixels that show the plane (not the box's top).
    points : (m, 3) float64
        World points of the mask pixels on the plane (row-major).
    radiance, surface_radiance : (m, 3) float64
        Their values in the two images.
    albedo : (m,) float64
        The plane's albedo at those points.
    box_center, box_size : (3,) float64
    view_dirs : (m, 3) float64
        Unit directions from the points to the camera (+Z).
    extent : float
        Half-width of the plane region seen (world units).
    specular : dict or None
        ``{'ks': , 'sigma': }`` of the Torrance-Sparrow lobe, or None (Lambertian).
    """

    image: np.ndarray
    surface_image: np.ndarray
    mask: np.ndarray
    points: np.ndarray
    radiance: np.ndarray
    surface_radiance: np.ndarray
    albedo: np.ndarray
    box_center: np.ndarray
    box_size: np.ndarray
    view_dirs: np.ndarray
    extent: float
    specular: dict | None


def cast_shadow_scene(lightmap, resolution: int = 64, extent: float = 1.0, box_center=(0.0, 0.0, 0.25),
                      box_size=(0.4, 0.4, 0.5), albedo=0.6, n_dirs: int = 1024, specular: dict | None = None,
                      ) -> ShadowScene:
    """Render a box's cast shadow on a plane under a light map, seen from straight above.

    Parameters
    ----------
    lightmap : LightMap or (dirs, radiance, solid_angle)
        Light from below the plane (z < 0) is dropped.
    resolution : int
        Image side (pixels); the image covers ``[-extent, extent]^2`` of the plane.
    extent : float
    box_center, box_size : (3,) array_like
        The axis-aligned box (it should stand on the plane: ``center_z = size_z / 2``).
    albedo : float or 'checker'
        The plane's albedo: a constant, or :func:`checker_albedo`.
    n_dirs : int
        Distant lights the map is reduced to (:func:`ffls.synth.scene.cluster_lightmap`).
    specular : dict, optional
        ``{'ks': float, 'sigma': float (radians)}``: add the simplified Torrance-Sparrow lobe
        ``ks / cos(theta_r) exp(-alpha^2 / (2 sigma^2))`` (``alpha`` the angle between the normal
        and the half vector), per unit irradiance at normal incidence.

    Returns
    -------
    ShadowScene
    """
    res = int(resolution)
    c = np.asarray(box_center, dtype=np.float64)
    s = np.asarray(box_size, dtype=np.float64)
    lo, hi = c - s / 2, c + s / 2
    px = (np.arange(res) + 0.5) / res * 2 * extent - extent
    X, Yimg = np.meshgrid(px, px)
    # image up is +Y in the world (camera above, looking down -Z, image right +X)
    Y = -Yimg
    on_box = (X >= lo[0]) & (X <= hi[0]) & (Y >= lo[1]) & (Y <= hi[1])
    mask = ~on_box
    pts = np.stack([X[mask], Y[mask], np.zeros(int(mask.sum()))], axis=1)
    if isinstance(albedo, str):
        if albedo != "checker":
            raise ValueError(f"albedo must be a number or 'checker', not {albedo!r}")
        rho = checker_albedo(pts)
    else:
        rho = np.full(pts.shape[0], float(albedo))
    d, irr, _ = cluster_lightmap(lightmap, n_dirs, "upper")
    up = d[:, 2] > 0
    d, irr = d[up], irr[up]
    view = np.broadcast_to(np.array([0.0, 0.0, 1.0]), pts.shape).copy()
    cos_i = d[:, 2]
    # per-light response of a unit irradiance at normal incidence: rho/pi cos_i (+ specular)
    resp = (rho[:, None] / np.pi) * cos_i[None, :]
    if specular is not None:
        h = normalize(d[None, :, :] + view[:, None, :])
        alpha = np.arccos(np.clip(h[..., 2], -1.0, 1.0))
        cos_r = view[:, 2:3]
        resp = resp + float(specular["ks"]) / cos_r * np.exp(-alpha ** 2 / (2.0 * float(specular["sigma"]) ** 2))
    box = Box(tuple(lo), tuple(hi), Material((0.5, 0.5, 0.5)), 1)
    origin = pts + np.array([0.0, 0.0, 1e-9])
    vis = np.empty((pts.shape[0], d.shape[0]), dtype=bool)
    for k in range(d.shape[0]):
        vis[:, k] = ~occluded([box], origin, d[k])
    rad = (resp * vis) @ irr
    surf = resp @ irr
    img = np.zeros((res, res, 3), dtype=np.float32)
    simg = np.zeros((res, res, 3), dtype=np.float32)
    img[mask] = rad
    simg[mask] = surf
    return ShadowScene(image=img, surface_image=simg, mask=mask, points=pts, radiance=rad, surface_radiance=surf,
                       albedo=rho, box_center=c, box_size=s, view_dirs=view, extent=float(extent),
                       specular=None if specular is None else dict(specular))
