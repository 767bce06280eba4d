"""The basis of a capture: the photos of the accepted lights, in the order of their directions.

One function, :func:`accepted_basis`, used by every relighter (:class:`ffls.relight.cpu.CpuRelighter`,
:class:`ffls.gpu.engine.Engine`, the demo). A basis image ``B_i`` is the linear photo lit from
light direction ``i`` (Masselus, Dutre, Anrys 2002, section 3).
"""
from __future__ import annotations

import numpy as np

from ffls.errors import InputError
from ffls.radiance.photos import load_photos

__all__ = ["accepted_basis", "accepted_positions", "capture_basis"]


def accepted_basis(capture, lights) -> tuple[np.ndarray, np.ndarray]:
    """Basis images and directions of the lights whose status is ``ok``, matched by image name.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
        Gives the photos (:func:`ffls.radiance.photos.load_photos`) and their ``image_names``.
    lights : ffls.io.capture.Lights
        ``directions`` (m, 3), ``ok_mask`` (m,) and ``image_names`` (m,); only lights with
        ``ok_mask`` set are used, and only their photos are loaded.

    Returns
    -------
    basis : (k, H, W, 3) float32
        Linear photos of the accepted lights, in the order of ``lights``.
    directions : (k, 3) float64
        Their light directions.

    Raises
    ------
    InputError
        No light has status ok, or a light names an image that is not in the capture (naming
        ``lights.path``, else the capture folder).
    """
    ok = np.asarray(lights.ok_mask, dtype=bool)
    path = getattr(lights, "path", None) or getattr(capture, "folder", None)
    if not np.any(ok):
        raise InputError("no light has status ok", path)
    names = [n for n, o in zip(lights.image_names, ok) if o]
    pos = {n: i for i, n in enumerate(capture.image_names)}
    missing = [n for n in names if n not in pos]
    if missing:
        raise InputError(f"lights name images not in the capture: {', '.join(missing[:3])}", path)
    basis = load_photos(capture, [pos[n] for n in names])
    return basis, np.asarray(lights.directions, dtype=np.float64)[ok]


def accepted_positions(lights) -> np.ndarray:
    """Positions ``(k, 3)`` float64 of the accepted lights (NaN rows where ``lights.json`` gives none)."""
    ok = np.asarray(lights.ok_mask, dtype=bool)
    pos = getattr(lights, "positions", None)
    if pos is None:
        return np.full((int(ok.sum()), 3), np.nan)
    return np.asarray(pos, dtype=np.float64)[ok]


def capture_basis(capture, lights, quality=None) -> tuple[np.ndarray, np.ndarray, dict]:
    """The basis and directions a relighter uses under ``quality`` (near correction, basis subset).

    Parameters
    ----------
    capture, lights
        As :func:`accepted_basis`.
    quality : ffls.relight.quality.Quality, optional
        Its ``near_correction`` and ``basis_subset`` are applied
        (:func:`ffls.relight.quality.prepare_basis`); None = the accepted basis as it is.

    Returns
    -------
    basis : (m, H, W, 3) float32
    directions : (m, 3) float64
    info : dict
        As :func:`ffls.relight.quality.prepare_basis`.
    """
    from ffls.relight.quality import prepare_basis

    basis, d = accepted_basis(capture, lights)
    if quality is None:
        return basis, d, {"indices": np.arange(len(d)), "near_scales": None}
    path = getattr(lights, "path", None) or getattr(capture, "folder", None)
    return prepare_basis(basis, d, accepted_positions(lights), near_correction=quality.near_correction,
                         basis_subset=quality.basis_subset, path=path)
