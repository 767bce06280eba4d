"""Light maps from photographs of a probe (issue 11; the survey in ``shared/papers/illumination-estimation-survey.txt``).

One entry point, :func:`estimate_lightmap`, chooses among the methods with ``method=``:

* ``'mirror'``: a mirror ball, unwrapped with exact perspective reflection, views merged with a
  confidence per direction (Debevec 1998; :mod:`ffls.probes.debevec`), exposure brackets merged
  first (Debevec and Malik 1997; :mod:`ffls.probes.bracket`).

The modules hold pure functions on arrays, one paper per function; :mod:`ffls.probes.estimate`
runs them on a probe folder (:func:`ffls.io.probe.load_probe`).
"""
from __future__ import annotations

import os

from ffls.io.probe import Probe, load_probe
from ffls.probes.result import LightmapEstimate, save_estimate

__all__ = ["METHODS", "estimate_lightmap", "LightmapEstimate", "save_estimate"]

#: The methods of :func:`estimate_lightmap`.
METHODS = ("mirror",)


def estimate_lightmap(probe, method: str = "mirror", height: int = 128, **kwargs) -> LightmapEstimate:
    """Estimate a lat-long light map (world frame) from a probe.

    Parameters
    ----------
    probe : Probe or path-like
        A loaded probe, or its folder (``probe.json``).
    method : str
        One of :data:`METHODS`.
    height : int
        Map height (width ``2 height``).
    **kwargs
        The method's knobs (:func:`ffls.probes.estimate.mirror_lightmap`, ...).

    Returns
    -------
    LightmapEstimate

    Raises
    ------
    InputError
        Bad input (one line naming the file and what is wrong).
    ValueError
        An unknown method or knob.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r} (known: {', '.join(METHODS)})")
    if not isinstance(probe, Probe):
        probe = load_probe(os.fspath(probe))
    from ffls.probes import estimate

    return estimate.mirror_lightmap(probe, height=height, **kwargs)
