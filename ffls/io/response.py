"""Inverse camera-response tables on disk: ``.npy`` or ``.csv``, 256 rows of 3 numbers.

The table is the linear exposure (relative units) that produces each 8-bit code, per channel
(RGB). :mod:`ffls.radiance.response` recovers it; ``capture.json`` names it with
``"encoding": {"response": "response.npy"}``.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ffls.errors import InputError, atomic_output

__all__ = ["save_response", "load_response"]


def save_response(path: str | os.PathLike, curve) -> Path:
    """Write an inverse response table atomically as ``.npy`` or ``.csv`` (256 rows, 3 columns)."""
    path = Path(path)
    c = np.asarray(curve, dtype=np.float64)
    if c.shape == (256,):
        c = np.repeat(c[:, None], 3, axis=1)
    if c.shape != (256, 3) or not np.all(np.isfinite(c)) or np.any(c < 0):
        raise ValueError(f"curve must be a finite non-negative (256, 3) table, got shape {c.shape}")
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".csv"):
        raise InputError("response files must end in .npy or .csv", path)
    with atomic_output(path) as tmp:
        if suffix == ".npy":
            with open(tmp, "wb") as f:
                np.save(f, c.astype(np.float32))
        else:
            np.savetxt(tmp, c, delimiter=",", fmt="%.9g")  # no header: ffls.io.capture reads it with loadtxt
    return path


def load_response(path: str | os.PathLike) -> np.ndarray:
    """Read an inverse response table written by :func:`save_response`.

    Returns
    -------
    (256, 3) float32
        A single-column table is repeated for the three channels.

    Raises
    ------
    InputError
        Missing file, wrong suffix or shape, non-finite, negative or decreasing values.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("response file not found", path)
    try:
        if path.suffix.lower() == ".npy":
            c = np.load(path, allow_pickle=False)
        elif path.suffix.lower() == ".csv":
            c = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=2)
        else:
            raise InputError("response files must end in .npy or .csv", path)
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read response table ({e})", path) from None
    c = np.asarray(c, dtype=np.float64)
    if c.shape in ((256,), (256, 1)):
        c = np.repeat(c.reshape(256, 1), 3, axis=1)
    if c.shape != (256, 3):
        raise InputError(f"response table must have shape (256, 3), got {c.shape}", path)
    if not np.all(np.isfinite(c)) or np.any(c < 0):
        raise InputError("response table must be finite and non-negative", path)
    if np.any(np.diff(c, axis=0) < 0):
        raise InputError("response table must be non-decreasing in every channel", path)
    return c.astype(np.float32)
