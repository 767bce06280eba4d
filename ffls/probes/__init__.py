"""Light maps from photographs of a probe (issue 11; the survey in ``shared/papers/illumination-estimation-survey.txt``).

One entry point, :func:`estimate_lightmap`, chooses among the methods with ``method=``:

* ``'mirror'``: a mirror ball, unwrapped with exact perspective reflection, views merged with a
  confidence per direction (Debevec 1998; :mod:`ffls.probes.debevec`), exposure brackets merged
  first (Debevec and Malik 1997; :mod:`ffls.probes.bracket`);
* ``'diffuse'``: least squares over model sources from a diffuse sphere (Hougen and Ahuja 1993;
  :mod:`ffls.probes.hougen_ahuja`), the number of sources chosen from the data
  (:mod:`ffls.probes.selection`);
* ``'shadow'``: the cast shadow of a known occluder on a plane (Sato, Sato and Ikeuchi 1999;
  :mod:`ffls.probes.sato_sato_ikeuchi`);
* ``'pocs'``: projections onto convex sets from a diffuse sphere (Singh and Ahuja;
  :mod:`ffls.probes.singh_ahuja`).

The modules hold pure functions on arrays, one paper per function; model source sets and their
light maps are in :mod:`ffls.probes.sources`, the shared linear solver in
:mod:`ffls.probes.linear`, evaluation in :mod:`ffls.probes.evaluate`.
:mod:`ffls.probes.estimate` runs them on a probe folder (:func:`ffls.io.probe.load_probe`).
"""
from __future__ import annotations

import os

from ffls.io.probe import Probe, load_probe
from ffls.probes.result import LightmapEstimate, save_estimate

__all__ = ["METHODS", "estimate_lightmap", "LightmapEstimate", "save_estimate"]

#: The methods of :func:`estimate_lightmap`.
METHODS = ("mirror", "diffuse", "shadow", "pocs")


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
        The method's knobs: :func:`ffls.probes.estimate.mirror_lightmap`, ``diffuse_lightmap``,
        ``shadow_lightmap``, ``pocs_lightmap``.

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

    run = {"mirror": estimate.mirror_lightmap, "diffuse": estimate.diffuse_lightmap,
           "shadow": estimate.shadow_lightmap, "pocs": estimate.pocs_lightmap}[method]
    return run(probe, height=height, **kwargs)
