"""Synthetic photographs of a mirror ball under a known light map, and probe folders to test ``ffls probe``.

:func:`render_mirror_ball` ray-traces the ball forward, pixel by pixel (the opposite direction
to :func:`ffls.probes.debevec.unwrap_mirror_ball_Debevec1998`, which runs from the map's
directions to the pixels): each pixel's viewing ray (OpenCV pinhole with distortion, or
orthographic) is intersected with the ball, reflected about the normal and looked up in the map;
rays that miss the ball see the map directly (a distant environment). Pixels are supersampled on
a regular grid, so the rim mixes ball and background as in a photograph.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ffls.camera.projection import pixel_rays
from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA, direction_to_latlong_uv, normalize
from ffls.errors import atomic_output
from ffls.io.images import write_exr

__all__ = ["sample_latlong", "render_mirror_ball", "look_at", "write_mirror_probe"]


def sample_latlong(data, directions) -> np.ndarray:
    """Bilinear lookup of a lat-long map (H, 2H, 3) at world directions (..., 3), wrapping in longitude."""
    data = np.asarray(data, dtype=np.float32)
    h, w = data.shape[:2]
    d = np.asarray(directions, dtype=np.float64)
    u, v = direction_to_latlong_uv(d.reshape(-1, 3))
    x = u * w - 0.5
    y = np.clip(v * h - 0.5, 0.0, h - 1.0)
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0 = x0.astype(np.intp) % w
    x1 = (x0 + 1) % w  # wrap the seam
    y0 = y0.astype(np.intp)
    y1 = np.minimum(y0 + 1, h - 1)
    out = ((1 - fy) * ((1 - fx) * data[y0, x0] + fx * data[y0, x1])
           + fy * ((1 - fx) * data[y1, x0] + fx * data[y1, x1]))
    return out.reshape(d.shape[:-1] + (3,))


def look_at(eye, target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """``world_from_camera`` (4, 4) of an OpenCV camera at ``eye`` looking at ``target`` (image up toward ``up``)."""
    eye = np.asarray(eye, dtype=np.float64)
    z = normalize(np.asarray(target, dtype=np.float64) - eye)
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [0.0, 1.0, 0.0])
    x = normalize(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


def off_axis_view(center, distance: float, focal_px: float, offset_px, size=(320, 240),
                  direction=(0.94, 0.0, 0.34)):
    """A pinhole camera ``distance`` from ``center`` along ``direction`` (from the +x side, 20 deg up),
    turned so that ``center`` lies ``offset_px`` (right, up) off its principal point: a probe ball
    photographed off the lens axis, as a hand-held shot frames it.

    Returns ``(K, world_from_camera, center_px)``: the (3, 3) intrinsics of a ``size`` (W, H) image,
    the (4, 4) pose and ``center``'s projection (2,)."""
    from ffls.camera.projection import project_points

    center = np.asarray(center, dtype=np.float64)
    d, f = float(distance), float(focal_px)
    eye = center + d * np.asarray(direction, dtype=np.float64)
    T0 = look_at(eye, center)
    T = look_at(eye, center + offset_px[0] / f * d * T0[:3, 0] - offset_px[1] / f * d * T0[:3, 1])
    K = np.array([[f, 0, 0.5 * (size[0] - 1)], [0, f, 0.5 * (size[1] - 1)], [0, 0, 1.0]])
    Ti = np.linalg.inv(T)
    return K, T, project_points((Ti[:3, :3] @ center + Ti[:3, 3])[None], K, None)[0]


def render_mirror_ball(lightmap, size=(256, 256), camera_model: str = "pinhole", K=None, dist=None,
                       world_from_camera=None, center=(0.0, 0.0, 0.0), radius: float = 0.1, center_px=None,
                       radius_px=None, supersample: int = 4, reflectance: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Ray-trace a photograph of a mirror ball in a distant environment given by a lat-long map.

    Parameters
    ----------
    lightmap : LightMap or (H, 2H, 3) float
        Lat-long radiance (world frame).
    size : (int, int)
        Image (width, height).
    camera_model : {'pinhole', 'orthographic'}
    K, dist : camera (pinhole)
    world_from_camera : (4, 4) float
        Camera pose (pinhole: the ray origins and directions; orthographic: only the rotation).
    center, radius : (3,) float, float
        Ball centre (world) and radius (pinhole).
    center_px, radius_px : (2,) float, float
        The ball's disc (orthographic).
    supersample : int
        Samples per pixel side.
    reflectance : float
        Multiplies the reflected radiance.

    Returns
    -------
    image : (H, W, 3) float32
        Linear radiance.
    coverage : (H, W) float32
        Fraction of each pixel covered by the ball.
    """
    data = lightmap.data if hasattr(lightmap, "data") else np.asarray(lightmap, dtype=np.float32)
    W, H = int(size[0]), int(size[1])
    s = max(int(supersample), 1)
    T = DEFAULT_WORLD_FROM_CAMERA if world_from_camera is None else np.asarray(world_from_camera, dtype=np.float64)
    R = T[:3, :3]
    off = (np.arange(s) + 0.5) / s - 0.5
    ys, xs = np.mgrid[0:H * s, 0:W * s]
    px = np.stack([xs.ravel() // s + off[xs.ravel() % s], ys.ravel() // s + off[ys.ravel() % s]], axis=1)
    if camera_model == "orthographic":
        c = np.asarray(center_px, dtype=np.float64)
        ab = (px - c) / float(radius_px)
        q = 1.0 - np.sum(ab * ab, axis=1)
        hit = q > 0
        n = np.concatenate([ab, -np.sqrt(np.clip(q, 0, None))[:, None]], axis=1)
        v = np.tile([0.0, 0.0, 1.0], (len(px), 1))
    else:
        v = pixel_rays(px, K, dist)
        C = np.linalg.inv(T)[:3, :3] @ np.asarray(center, dtype=np.float64) + np.linalg.inv(T)[:3, 3]
        b = v @ C
        disc = b * b - (C @ C - radius * radius)
        hit = (disc >= 0) & (b > 0)
        t = b - np.sqrt(np.where(hit, disc, 0.0))
        n = (t[:, None] * v - C) / radius
    r = np.where(hit[:, None], v - 2 * np.sum(v * n, axis=1, keepdims=True) * n, v)
    rad = sample_latlong(data, r @ R.T)
    rad = np.where(hit[:, None], reflectance * rad, rad)
    img = rad.reshape(H, s, W, s, 3).mean(axis=(1, 3))
    cov = hit.reshape(H, s, W, s).mean(axis=(1, 3))
    return img.astype(np.float32), cov.astype(np.float32)


def write_mirror_probe(folder, lightmap, size=(256, 256), camera_model: str = "pinhole", K=None, dist=None,
                       world_from_camera=None, center=(0.0, 0.0, 0.0), radius: float = 0.1, center_px=None,
                       radius_px=None, sphere: str = "world", supersample: int = 4, image_name: str = "ball.exr",
                       reflectance: float = 1.0) -> Path:
    """Write a probe folder (``probe.json`` + one EXR) of a mirror ball rendered by :func:`render_mirror_ball`.

    Parameters
    ----------
    folder : path-like
        Created if missing.
    sphere : {'world', 'pixel', 'auto'}
        How ``probe.json`` locates the ball: its world centre and radius (pinhole), a pixel hint
        (the true disc), or not at all (found automatically).

    Other parameters are those of :func:`render_mirror_ball`.

    Returns
    -------
    pathlib.Path
        The folder.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    T = DEFAULT_WORLD_FROM_CAMERA if world_from_camera is None else np.asarray(world_from_camera, dtype=np.float64)
    img, _ = render_mirror_ball(lightmap, size, camera_model, K, dist, T, center, radius, center_px, radius_px,
                                supersample, reflectance)
    write_exr(folder / image_name, img)
    cam: dict = {"world_from_camera": T.tolist()}
    if camera_model == "orthographic":
        cam["model"] = "orthographic"
    else:
        cam["K"] = np.asarray(K, dtype=float).tolist()
        if dist is not None:
            cam["dist"] = np.asarray(dist, dtype=float).ravel().tolist()
    sph: dict = {"material": "mirror", "reflectance": float(reflectance)}
    if sphere == "world":
        sph.update(center=[float(x) for x in center], radius=float(radius))
    elif sphere == "pixel":
        if camera_model == "orthographic":
            sph.update(center_px=[float(x) for x in center_px], radius_px=float(radius_px))
        else:
            Ti = np.linalg.inv(T)
            Cc = Ti[:3, :3] @ np.asarray(center, dtype=np.float64) + Ti[:3, 3]
            from ffls.camera.projection import project_points

            sph["center_px"] = [float(x) for x in project_points(Cc[None], K, dist)[0]]
    doc = {"format": "ffls-probe", "version": 1, "images": [image_name], "camera": cam, "sphere": sph}
    with atomic_output(folder / "probe.json") as tmp:
        tmp.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return folder
