"""A diffuse probe ball in front of a plain wall of its own brightness (``tests/test_probe_detect.py``,
``benchmarks/probe_wall.py``)."""
from __future__ import annotations

import numpy as np

from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.synth.probe_scenes import diffuse_sphere_scene

SIZE = (240, 320)  # height, width
X0 = 40  # the ball's square render is pasted from this column


def wall_photo(name: str, level: float, seed: int, ball: bool = True):
    """A grey ball (albedo 0.25, radius 72 px, orthographic) under the built-in map ``name`` (downsampled
    16x), pasted at (159.5, 119.5) into a 320 x 240 photo of a flat wall of ``level`` times the ball's
    90th percentile, the whole photo with 2% multiplicative Gaussian noise (``seed``); ``ball`` False:
    the wall alone. Returns the photo (H, W, 3) float32, the ball's centre (x, y) px and radius px."""
    sc = diffuse_sphere_scene(builtin_lightmap(name).downsample(16), resolution=SIZE[0], albedo=0.25,
                              radius_frac=0.3)
    img = np.full(SIZE + (3,), level * np.percentile(sc.image[sc.mask], 90), dtype=np.float64)
    if ball:
        sub = img[:, X0:X0 + SIZE[0]]
        sub[sc.mask] = sc.image[sc.mask]
    img *= 1.0 + 0.02 * np.random.default_rng(seed).standard_normal(img.shape)
    centre = np.asarray(sc.center_px, dtype=np.float64) + [X0, 0.0]
    return np.clip(img, 0, None).astype(np.float32), centre, 0.3 * SIZE[0]
