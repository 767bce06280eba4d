"""Photo sequences of calibration spheres made here with NumPy, for the sphere-detection tests.

Independent of :mod:`ffls.synth`: ray-sphere intersection per (supersampled) pixel, matte
(Lambert) or mirror (reflected environment plus a Phong highlight per light) spheres, a flat
background facing the camera (black, grey, white or a textured noise albedo, lit by the same
lights), optional distractors (a red matte sphere, a flat white painted disc). Pinhole cameras
use :func:`ffls.camera.projection.pixel_rays`; the orthographic camera has rays +z from each
pixel, with spheres given in pixel units.

Used by ``tests/test_detect_general.py`` and ``benchmarks/detect_general.py``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ffls.camera.projection import pixel_rays, project_points

BACKGROUNDS = ("black", "grey", "white", "texture")


@dataclass
class Ball:
    """One sphere: camera-frame centre and radius (pixel units for the orthographic camera)."""

    center: np.ndarray
    radius: float
    albedo: tuple = (0.8, 0.8, 0.8)
    kind: str = "matte"  # 'matte' or 'mirror'


@dataclass
class Scene:
    shape: tuple
    balls: list
    model: str = "pinhole"
    K: np.ndarray | None = None
    discs: list = field(default_factory=list)  # flat painted discs (u, v, r_px, albedo)

    def centre_px(self, ball: Ball) -> np.ndarray:
        if self.model == "orthographic":
            return np.asarray(ball.center[:2], dtype=np.float64)
        return project_points(np.asarray(ball.center)[None], self.K, None)[0]


def lights(n: int, seed: int = 0, min_elev: float = 15.0, max_elev: float = 75.0) -> np.ndarray:
    """``n`` unit directions toward the lights (camera frame), on the camera's side (z < 0),
    spread in azimuth around the view axis; ``elev`` is the angle from the -z axis, degrees."""
    rng = np.random.default_rng(seed)
    az = (np.arange(n) + rng.uniform(0, 1, n)) * 2 * np.pi / n
    el = np.radians(rng.uniform(min_elev, max_elev, n))
    d = np.stack([np.sin(el) * np.cos(az), np.sin(el) * np.sin(az), -np.cos(el)], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _environment(r: np.ndarray) -> np.ndarray:
    """A mirror's surroundings along reflected directions r (m, 3): a sky-to-floor gradient with
    a slight warm tint and a soft window, (m, 3) RGB."""
    up = -r[:, 1]  # image up is -y
    base = 0.45 + 0.35 * up + 0.08 * np.sin(3 * r[:, 0])
    window = 0.4 * np.exp(-((r[:, 0] - 0.5) ** 2 + (up - 0.4) ** 2) / 0.02)
    v = np.clip(base + window, 0.02, None)
    return np.stack([v * 1.05, v, v * 0.92], axis=1)


def render(scene: Scene, light_dirs: np.ndarray, background: str = "black", ss: int = 2, noise: float = 0.003,
           seed: int = 0, texture_scale: float = 6.0) -> np.ndarray:
    """The photo sequence (n, H, W, 3) float32 of ``scene`` under ``light_dirs`` (n, 3), linear."""
    H, W = scene.shape
    rng = np.random.default_rng(seed)
    if background == "black":
        bg_alb = np.full((H, W), 0.01)
    elif background == "grey":
        bg_alb = np.full((H, W), 0.35)
    elif background == "white":
        bg_alb = np.full((H, W), 1.0)
    elif background == "texture":
        import cv2
        t = rng.uniform(0, 1, (H, W)).astype(np.float32)
        t = cv2.GaussianBlur(t, (0, 0), texture_scale)
        t = (t - t.min()) / (t.max() - t.min() + 1e-9)
        bg_alb = (0.1 + 0.6 * t).astype(np.float64)
    else:
        raise ValueError(background)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    off = (np.arange(ss) + 0.5) / ss - 0.5
    n_l = len(light_dirs)
    out = np.zeros((n_l, H, W, 3))
    for oy in off:
        for ox in off:
            px = np.stack([xx.ravel() + ox, yy.ravel() + oy], axis=1)
            if scene.model == "orthographic":
                o = np.concatenate([px, np.zeros((len(px), 1))], axis=1)
                d = np.tile([0.0, 0.0, 1.0], (len(px), 1))
            else:
                o = np.zeros((len(px), 3))
                d = pixel_rays(px, scene.K, None)
            tbest = np.full(len(px), np.inf)
            who = np.full(len(px), -1)
            nrm = np.zeros((len(px), 3))
            for k, b in enumerate(scene.balls):
                oc = o - b.center
                bb = np.sum(oc * d, axis=1)
                disc = bb * bb - (np.sum(oc * oc, axis=1) - b.radius ** 2)
                hit = disc >= 0
                t = np.where(hit, -bb - np.sqrt(np.where(hit, disc, 0)), np.inf)
                closer = (t < tbest) & (t > 0)
                tbest[closer] = t[closer]
                who[closer] = k
                nrm[closer] = (o[closer] + t[closer, None] * d[closer] - b.center) / b.radius
            # background: a flat plane facing the camera, normal (0, 0, -1), painted discs on it
            alb = np.repeat(bg_alb.ravel()[:, None], 3, axis=1)
            for (u, v, r, a) in scene.discs:
                inside = (px[:, 0] - u) ** 2 + (px[:, 1] - v) ** 2 <= r * r
                alb[inside] = a
            shade_bg = np.clip(-light_dirs[:, 2], 0, None)  # (n_l,)
            val = alb[None] * (shade_bg[:, None, None] + 0.02)
            for k, b in enumerate(scene.balls):
                m = who == k
                if not m.any():
                    continue
                n = nrm[m]
                if b.kind == "mirror":
                    r = d[m] - 2 * np.sum(d[m] * n, axis=1, keepdims=True) * n
                    env = _environment(r)
                    spec = np.exp((np.clip(r @ light_dirs.T, -1, 1) - 1) / 0.0015)  # (m, n_l) highlight
                    val[:, m] = 0.6 * env[None] + 20.0 * spec.T[..., None]  # chrome: reflectance 0.6
                else:
                    shade = np.clip(n @ light_dirs.T, 0, None).T  # (n_l, m)
                    val[:, m] = shade[..., None] * np.asarray(b.albedo)[None, None] + 0.01
            out += val.reshape(n_l, H, W, 3)
    out /= ss * ss
    out += rng.normal(0, noise, out.shape)
    return np.clip(out, 0, None).astype(np.float32)


def layout(n: int, shape=(300, 400), f: float = 500.0, R: float = 0.04, depth=(1.0, 1.25), seed: int = 0,
           margin: float = 6.0) -> Scene:
    """``n`` white matte spheres at random non-overlapping places in a pinhole view (f px)."""
    H, W = shape
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]])
    rng = np.random.default_rng(seed)
    balls = []
    placed = []
    for _ in range(5000):
        if len(balls) == n:
            break
        z = rng.uniform(*depth)
        r_px = f * R / z
        u = rng.uniform(r_px + margin, W - 1 - r_px - margin)
        v = rng.uniform(r_px + margin, H - 1 - r_px - margin)
        if all(np.hypot(u - pu, v - pv) > r_px + pr + 2 * margin for pu, pv, pr in placed):
            placed.append((u, v, r_px))
            C = np.array([(u - K[0, 2]) / f * z, (v - K[1, 2]) / f * z, z])
            balls.append(Ball(C, R))
    if len(balls) < n:
        raise ValueError(f"could not place {n} spheres in {shape}")
    return Scene(shape, balls, "pinhole", K)
