"""One matte sphere seen straight on by an orthographic camera, lit from the camera's side: the
geometry shared by the lone-sphere tests (a helper module, not a test file)."""
from __future__ import annotations

import numpy as np

from ffls.conventions import spherical_to_direction

# a camera looking along world +y (image x = world x, image down = world -z): the ground is the image's bottom
WORLD_FROM_CAMERA = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]])


def front_lights(n: int = 24, seed: int = 3) -> np.ndarray:
    """(n, 3) lights 15-70 deg up, in front of the sphere (the camera's side, -y)."""
    rng = np.random.default_rng(seed)
    theta = np.radians(rng.uniform(15, 70, n))
    phi = np.radians(rng.uniform(-160, -20, n))
    return spherical_to_direction(theta, phi)
