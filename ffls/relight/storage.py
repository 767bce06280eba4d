"""Storage precision of a radiance basis: float32, or float16 with a checked per-dataset scale.

Float16 storage multiplies every value by one power-of-two scale ``s`` (exact in binary floating
point) chosen so that the largest magnitude lands at :data:`F16_TARGET_MAX` = 2**12, far inside
float16's range (65504) and far above its smallest normal (2**-14): a 1e6 pixel becomes
1e6 * 2**-8 = 3906.25, never ``inf``. Readers multiply by ``1 / s``.

The conversion is checked, never silent (:class:`Float16Report`): a non-finite input raises, an
overflow to ``inf`` raises, and a *significant* value (``|x| >= SIGNIFICANT_REL * max|x|``) that
becomes zero or subnormal raises. The conversion itself is :mod:`ffls.store.float16`, shared by the GPU uploads
(:mod:`ffls.gpu.basis`), the chunked store and the CPU relighter's ``storage='f16'``
(:func:`store_basis`), so every path rounds the same way.
"""
from __future__ import annotations


import numpy as np

from ffls.errors import InputError
# the checked float16 conversion: one definition, shared with the chunked store on disk
from ffls.store.float16 import F16_TARGET_MAX, SIGNIFICANT_REL, Float16Report, choose_scale, to_float16

__all__ = ["F16_TARGET_MAX", "SIGNIFICANT_REL", "Float16Report", "choose_scale", "to_float16", "STORAGES",
           "store_basis", "parse_storage"]

#: Storage precisions of a basis: float16 (checked scale) or float32.
STORAGES = ("f16", "f32")


def parse_storage(value: str) -> str:
    """``'float16'``/``'f16'`` -> ``'f16'``, ``'float32'``/``'f32'`` -> ``'f32'``; ``ValueError`` otherwise."""
    v = str(value).lower()
    alias = {"float16": "f16", "half": "f16", "float32": "f32", "float": "f32"}
    v = alias.get(v, v)
    if v not in STORAGES:
        raise ValueError(f"precision must be float16 or float32, not {value!r}")
    return v


def store_basis(basis, storage: str = "f32", path=None) -> tuple[np.ndarray, float, Float16Report | None]:
    """A basis as it is stored: float32, or checked float16 values with their scale.

    Parameters
    ----------
    basis : (n, H, W, 3) float array
        Finite linear radiance.
    storage : {'f16', 'f32'} (or 'float16', 'float32')
    path : path-like, optional
        Named in errors.

    Returns
    -------
    stored : (n, H, W, 3) float16 or float32 ndarray
        ``basis * scale`` rounded to the storage type.
    scale : float
        1 for float32; the power of two of :func:`choose_scale` for float16.
    report : Float16Report or None
        For float16.
    """
    storage = parse_storage(storage)
    if storage == "f32":
        b = np.asarray(basis, dtype=np.float32)
        if b.size and not np.all(np.isfinite(b)):
            raise InputError(f"basis has {int(np.count_nonzero(~np.isfinite(b)))} NaN/Inf values", path)
        return b, 1.0, None
    h, rep = to_float16(basis, path=path)
    return h, rep.scale, rep
