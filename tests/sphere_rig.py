"""Four matte spheres on the ground around a scene centre, seen from above at 25 degrees: the
sphere geometry shared by the capture-wide sphere tests (a helper module, not a test file)."""
from __future__ import annotations

import numpy as np

from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA
from ffls.spheres.samples import sphere_samples

R_SPH = 0.05
CENTERS = np.array([[-0.25, 0.55, 0.05], [0.25, 0.55, 0.05], [0.25, 1.05, 0.05], [-0.25, 1.05, 0.05]])
SCENE_CENTER = np.array([0.0, 0.8, 0.0])
WFC = np.eye(4)
_c, _s = np.cos(np.radians(25)), np.sin(np.radians(25))
WFC[:3, :3] = np.array([[1, 0, 0], [0, _c, _s], [0, -_s, _c]]) @ DEFAULT_WORLD_FROM_CAMERA[:3, :3]
WFC[:3, 3] = [0.0, -0.2, 0.45]


def camera(res: int, focal: float) -> np.ndarray:
    """(3, 3) the pinhole ``K`` of a ``res`` x ``res`` image with its principal point at the centre."""
    return np.array([[focal, 0, (res - 1) / 2], [0, focal, (res - 1) / 2], [0, 0, 1.0]])


def rig_samples(res: int, focal: float) -> list:
    """The four spheres' :func:`ffls.spheres.samples.sphere_samples` in that camera."""
    M = np.linalg.inv(WFC)
    return [sphere_samples((res, res), camera(res, focal), None, M[:3, :3] @ c + M[:3, 3], R_SPH, WFC)
            for c in CENTERS]
