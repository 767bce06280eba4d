"""Random light directions shared by the weighting tests (a helper module, not a test file)."""
from __future__ import annotations

import numpy as np


def random_directions(n: int, seed: int = 0, hemisphere: str = "upper") -> np.ndarray:
    """(n, 3) unit directions, uniform on the sphere, folded onto z >= 0 when ``hemisphere`` is 'upper'."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    if hemisphere == "upper":
        d[:, 2] = np.abs(d[:, 2])
    return d / np.linalg.norm(d, axis=1, keepdims=True)
