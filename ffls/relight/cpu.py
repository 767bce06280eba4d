"""CPU relighting: the weighted sum of basis images (Masselus, Dutre, Anrys 2002, section 6).

``relit = sum_i w_i * B_i`` per colour channel, where ``w`` are the angular Voronoi weights of a
light map (:func:`ffls.weights.voronoi.integrate_weights`) and ``B_i`` the basis image lit from light
direction ``i``.

* :func:`relight_reference` accumulates in float64 (the reference the GPU and the fast path are
  compared against).
* :func:`relight_fast` is one float32 BLAS product per block of pixels: ``(3, n) @ (n, 3 P)``
  over a reshaped view of the basis (no copy of the basis), keeping the channel-diagonal part.
"""
from __future__ import annotations

import numpy as np

from ffls.conventions import check_hemisphere
from ffls.weights.voronoi import Weights, bake_cells, integrate_weights
from ffls.radiance.photos import load_photos

__all__ = ["relight_reference", "relight_fast", "relight_capture"]


def _check(weights, basis) -> tuple[np.ndarray, np.ndarray]:
    w = np.asarray(weights)
    b = np.asarray(basis)
    if b.ndim != 4 or b.shape[-1] != 3:
        raise ValueError(f"basis must be (n, H, W, 3), not {b.shape}")
    if w.shape != (b.shape[0], 3):
        raise ValueError(f"weights must be (n, 3) = {(b.shape[0], 3)}, not {w.shape}")
    return w, b


def relight_reference(weights, basis) -> np.ndarray:
    """Relit image with float64 accumulation.

    Parameters
    ----------
    weights : (n, 3) array_like
        Per-light RGB weights.
    basis : (n, H, W, 3) array_like
        Basis images (any float dtype); converted one image at a time.

    Returns
    -------
    (H, W, 3) float64
        ``sum_i weights[i] * basis[i]``.
    """
    w, b = _check(weights, basis)
    w = w.astype(np.float64)
    out = np.zeros(b.shape[1:], dtype=np.float64)
    for i in range(b.shape[0]):
        if np.any(w[i] != 0):
            out += w[i] * b[i].astype(np.float64)
    return out


def relight_fast(weights, basis, block_pixels: int = 1 << 16) -> np.ndarray:
    """Relit image in float32 through BLAS.

    For each block of ``P`` pixels, ``(3, n) @ (n, 3 P)`` (one sgemm over a view of the basis)
    gives every channel weighting of every pixel channel; the diagonal ``out[c, 3 p + c]`` is the
    result. This reads the basis once without copying it (for float32 C-contiguous input); the
    temporaries are ``3 x 3 x block_pixels`` floats.

    Parameters
    ----------
    weights : (n, 3) array_like
    basis : (n, H, W, 3) float32 array_like
        Other dtypes are converted to float32 (a copy).
    block_pixels : int
        Pixels per BLAS call.

    Returns
    -------
    (H, W, 3) float32
        Agrees with :func:`relight_reference` within float32 accumulation error, about
        ``n * 6e-8 * sum_i |w_i B_i|`` in the worst case (typically ``sqrt(n)`` times less).
    """
    w, b = _check(weights, basis)
    n, H, W, _ = b.shape
    wt = np.ascontiguousarray(w.astype(np.float32).T)  # (3, n)
    flat = np.ascontiguousarray(b, dtype=np.float32).reshape(n, H * W * 3)
    out = np.empty((H * W, 3), dtype=np.float32)
    ch = np.arange(3)
    for s in range(0, H * W, block_pixels):
        e = min(s + block_pixels, H * W)
        prod = (wt @ flat[:, 3 * s:3 * e]).reshape(3, e - s, 3)  # [weight channel, pixel, basis channel]
        out[s:e] = prod[ch, :, ch].T
    return out.reshape(H, W, 3)


def relight_capture(capture, lights, lightmap, rotation=None, cells_res: int | None = 256, fast: bool = True,
                    k: int = 4, max_res: int | None = 1024) -> tuple[np.ndarray, Weights]:
    """Relight a capture under a light map.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
        Gives the basis images (``load_basis(indices)`` -> (n, H, W, 3)), ``image_names`` and
        ``hemisphere``.
    lights : ffls.io.capture.Lights
        Light directions (``directions`` (m, 3)), ``ok_mask`` (m,) and ``image_names`` (m,);
        only lights with ``ok_mask`` set take part.
    lightmap : ffls.lightmaps.lightmap.LightMap or (dirs, radiance, solid_angle)
    rotation : (3, 3) array_like, optional
        Light-map rotation; identity by default.
    cells_res : int or None
        Candidate cell-texture resolution (the GPU's lookup; doubled up to ``max_res`` while it
        overflows), or ``None`` for the exact k-d tree assignment.
    fast : bool
        :func:`relight_fast` (float32) rather than :func:`relight_reference` (float64).

    Returns
    -------
    image : (H, W, 3) float32 (fast) or float64
    weights : Weights
        For the used lights, in the order of ``lights`` restricted to ``ok_mask``.
    """
    hemisphere = check_hemisphere(getattr(capture, "hemisphere", "upper"))
    ok = np.asarray(lights.ok_mask, dtype=bool)
    if not np.any(ok):
        from ffls.errors import InputError

        raise InputError("no light has status ok", getattr(lights, "path", None))
    dirs = np.asarray(lights.directions, dtype=np.float64)[ok]
    names = [n for n, o in zip(lights.image_names, ok) if o]
    cap_names = list(capture.image_names)
    pos = {n: i for i, n in enumerate(cap_names)}
    missing = [n for n in names if n not in pos]
    if missing:
        from ffls.errors import InputError

        raise InputError(f"lights name images not in the capture: {', '.join(missing[:3])}", getattr(lights, "path", None))
    sel = [pos[n] for n in names]
    basis = load_photos(capture, sel)  # only the used images, in the order of ``dirs``
    cells = None if cells_res is None else bake_cells(dirs, hemisphere, res=cells_res, k=k, max_res=max_res)
    wts = integrate_weights(lightmap, dirs, rotation=rotation, hemisphere=hemisphere, cells=cells)
    image = relight_fast(wts.weights, basis) if fast else relight_reference(wts.weights, basis)
    return image, wts
