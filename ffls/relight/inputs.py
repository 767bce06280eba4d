"""The inputs every relighter that keeps its per-light weights on the CPU shares: rotation and weights.

:class:`ffls.relight.cpu.CpuRelighter`, :class:`ffls.relight.stream.StreamedRelighter` and
:class:`ffls.gpu.tiled.TiledEngine` have the :class:`ffls.gpu.engine.Engine`'s interface; this mix-in
holds the part of it they do the same way. A class using it keeps ``_lightmap``, ``_rotation``,
``_weights`` (None: pass 1 reruns at the next render), ``_hdr`` and ``last_weights``, and has an
``n_lights`` property.
"""
from __future__ import annotations

import numpy as np

from ffls.conventions import checked_rotation, checked_weights

__all__ = ["WeightsInputs"]


class WeightsInputs:
    """``set_rotation`` and ``set_weights`` of a relighter whose pass 1 gives its weights on the CPU."""

    def set_rotation(self, R) -> None:
        """Rotate the light map by ``R`` (3, 3) (content at d moves to R d; conventions.rotation_z)."""
        R = checked_rotation(R)
        if not np.array_equal(R, self._rotation):
            self._rotation = R.copy()
            if self._lightmap is not None:
                self._weights = None

    def set_weights(self, weights) -> None:
        """Use these per-light weights ``(n, 3)`` directly (bypasses pass 1 until the next light map)."""
        self._weights = checked_weights(weights, self.n_lights)
        self._lightmap = None
        self.last_weights = None
        self._hdr = None
