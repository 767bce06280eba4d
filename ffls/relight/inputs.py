"""What every relighter that keeps its per-light weights on the CPU shares: its inputs, its render and its reads.

:class:`ffls.relight.cpu.CpuRelighter`, :class:`ffls.relight.stream.StreamedRelighter` and
:class:`ffls.gpu.tiled.TiledEngine` have the :class:`ffls.gpu.engine.Engine`'s interface; this mix-in
holds the part of it they do the same way. A class using it keeps ``_lightmap``, ``_rotation``,
``_weights`` (None: pass 1 reruns at the next render), ``_hdr``, ``_display``, ``_display_key`` and
``last_weights``, has an ``n_lights`` property, and gives its two passes:
``_pass1() -> (n, 3) weights`` and ``_pass2(weights) -> (H, W, 3) image``.
"""
from __future__ import annotations

import numpy as np

from ffls.conventions import checked_rotation, checked_weights
from ffls.display.tonemap import to_uint8, tonemap as tonemap_np

__all__ = ["WeightsInputs"]


class WeightsInputs:
    """``set_rotation``, ``set_weights``, ``render``, ``hdr``, ``read_hdr``, ``read_display`` and ``read_weights``
    of a relighter whose pass 1 gives its weights on the CPU."""

    def _init_inputs(self) -> None:
        """No light map, no rotation, nothing rendered: the state a relighter starts in."""
        self._lightmap = None
        self._rotation = np.eye(3)
        self._weights = None
        self._hdr = None
        self._display = None
        self._display_key = None

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

    def render(self, exposure: float = 0.0, tonemap: str = "srgb") -> None:
        """Compute what changed: the weights (pass 1), the relit image (pass 2); the display image on first read.

        Parameters
        ----------
        exposure : float
            Stops applied before the tone curve (display image only; the HDR is unscaled).
        tonemap : {'srgb', 'reinhard', 'aces'}
        """
        if self._lightmap is None and self._weights is None:
            raise RuntimeError(f"{type(self).__name__}.render: call set_lightmap(lm) or set_weights(w) first")
        if self._weights is None:
            self._weights = self._pass1()
            self._hdr = None
        if self._hdr is None:
            self._hdr = self._pass2(self._weights)
            self._display = None
        key = (float(exposure), tonemap)
        if key != self._display_key:
            self._display = None
            self._display_key = key

    @property
    def hdr(self) -> np.ndarray:
        """The last relit image ``(H, W, 3)`` (pass 2's output)."""
        if self._hdr is None:
            raise RuntimeError(f"{type(self).__name__}: nothing rendered yet")
        return self._hdr

    def read_hdr(self) -> np.ndarray:
        """The relit image ``(H, W, 3)``, row 0 = top row."""
        return self.hdr

    def read_display(self) -> np.ndarray:
        """The display image ``(H, W, 3)`` uint8, tone-mapped on first read (an EXR-only caller never pays for it)."""
        if self._display is None:
            exposure, method = self._display_key if self._display_key is not None else (0.0, "srgb")
            self._display = to_uint8(tonemap_np(self.hdr, exposure, method))
        return self._display

    def read_weights(self) -> np.ndarray:
        """The weights of the last render ``(n, 3)`` float64 (pass-1 output or :meth:`set_weights`)."""
        if self._weights is None:
            raise RuntimeError(f"{type(self).__name__}: nothing rendered yet")
        return np.array(self._weights, dtype=np.float64)
