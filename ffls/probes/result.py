"""The result of a light-map estimate from a probe, and how it is written."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffls.io.images import write_exr
from ffls.lightmaps.lightmap import LightMap

__all__ = ["LightmapEstimate", "save_estimate"]


@dataclass
class LightmapEstimate:
    """A light map estimated from photographs of a probe.

    Attributes
    ----------
    lightmap : LightMap
        Lat-long, world frame (GUIDE section 1), float32; unseen directions filled (see ``seen``).
    seen : (H, 2H) bool
        The directions the probe actually saw.
    confidence : (H, 2H) float32
        In [0, 1] per direction (method-specific; 1 where a method has no such notion and saw it).
    method : str
        ``'mirror'``, ``'diffuse'``, ``'shadow'`` or ``'pocs'``.
    notes : list of str
        One line each: what was read, found, chosen and measured (the CLI prints them).
    details : dict
        Method-specific numbers (chosen model size, re-render RMS, blind spot, ...), JSON-friendly.
    """

    lightmap: LightMap
    seen: np.ndarray
    confidence: np.ndarray
    method: str
    notes: list = field(default_factory=list)
    details: dict = field(default_factory=dict)


def save_estimate(est: LightmapEstimate, path: str | os.PathLike, half: bool = False) -> Path:
    """Write the map as an RGBA OpenEXR: RGB the radiance, alpha 1 where the probe saw the direction, 0 elsewhere.

    ``load_lightmap`` (``relight``, ``render``, ``view``) reads the RGB and ignores the alpha. The header's
    string attributes say what made it: ``ffls:probe_method`` (``est.method``) and, where the method has one,
    ``ffls:pocs_scheme`` (POCS's ``details['scheme']``). The write is atomic (:func:`ffls.io.images.write_exr`).
    """
    path = Path(path)
    attrs = {"ffls:probe_method": str(est.method)}
    if est.method == "pocs" and "scheme" in est.details:
        attrs["ffls:pocs_scheme"] = str(est.details["scheme"])
    return write_exr(path, est.lightmap.data, half=half, alpha=est.seen.astype(np.float32), attributes=attrs)
