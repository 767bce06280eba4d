"""Radiance basis on the GPU: float16 (or float32) texture arrays with a per-dataset scale.

A basis ``(n, H, W, 3)`` float32 is uploaded as one or more ``sampler2DArray`` textures, layer
``i`` holding light ``i``. Float16 storage multiplies every value by one power-of-two scale
``s`` (exact in binary floating point) chosen so that the largest magnitude lands at
:data:`F16_TARGET_MAX` = 2**12, far inside float16's range (65504) and far above its smallest
normal (2**-14): a 1e6 pixel becomes 1e6 * 2**-8 = 3906.25, never ``inf``. Pass 2 multiplies
its float32 accumulator by ``1 / s``.

The conversion is checked, never silent (:class:`Float16Report`): a non-finite input raises,
an overflow to ``inf`` raises, and a *significant* value (``|x| >= SIGNIFICANT_REL * max|x|``)
that becomes zero or subnormal raises.

Limits: if ``n`` exceeds :data:`ARRAY_LAYERS` (or ``max_layers``; at most the device's
``GL_MAX_ARRAY_TEXTURE_LAYERS``) the basis is split
into several arrays and pass 2 sums over all of them; if the whole basis exceeds the memory
budget it is refused with a one-line :class:`ffls.errors.InputError`. Nothing is ever truncated.
"""
from __future__ import annotations

import numpy as np

from ffls.errors import InputError
from ffls.gpu.context import release_gl
# the checked float16 conversion is shared with the chunked store on disk (one definition)
from ffls.store.float16 import (F16_TARGET_MAX, SIGNIFICANT_REL, Float16Report, choose_scale, finite_max_abs,
                                to_float16)

__all__ = ["F16_TARGET_MAX", "SIGNIFICANT_REL", "Float16Report", "choose_scale", "to_float16", "BasisTextures",
           "PackedBasis", "pack_pixel_major", "PACKED_LAYERS", "ARRAY_LAYERS", "SSBO_BAND_BYTES", "PACKED_STORAGES"]

#: Layers per texture array of :class:`BasisTextures` by default (fewer where the device allows
#: fewer): on an NVIDIA H100 the compute pass 2 over 1024 photos at 1024^2 read one 1024-layer
#: array at 725 GB/s and four 256-layer arrays at 1519 GB/s (docs/gpu.md, "On an NVIDIA H100").
ARRAY_LAYERS = 256
#: Default memory budget for basis textures, bytes (refused above it).
DEFAULT_BUDGET = 4 * 1024 ** 3
#: Layers summed by one pass-2 dispatch of :class:`PackedBasis` (its shader is unrolled over them).
PACKED_LAYERS = 256
#: Largest SSBO binding used for a band of :class:`PackedBasis` (Mesa's limit is 128 MiB).
SSBO_BAND_BYTES = 128 * 1024 ** 2
#: Where :class:`PackedBasis` keeps its words: ``'image'`` (an RGBA32UI texture array per chunk,
#: read with ``imageLoad``: one vector gather per load on llvmpipe, the default) or ``'buffer'``
#: (row bands of SSBOs: a per-lane scalar loop per load there; docs/gpu.md "Pass 2").
PACKED_STORAGES = ("image", "buffer")


def _check_basis(basis, dtype: str, path=None) -> np.ndarray:
    """``basis`` as an array of shape (n, H, W, 3), n >= 1, for storage as ``dtype`` ('f16'/'f32')."""
    if dtype not in ("f16", "f32"):
        raise ValueError(f"dtype must be 'f16' or 'f32', not {dtype!r}")
    basis = np.asarray(basis)
    if basis.ndim != 4 or basis.shape[-1] != 3 or basis.shape[0] < 1:
        raise InputError(f"basis must have shape (n, H, W, 3) with n >= 1, not {basis.shape}", path)
    return basis


def _finite_max_abs(basis: np.ndarray, path=None) -> float:
    """``max |basis|`` in one pass of cache-sized blocks (:func:`ffls.store.float16.finite_max_abs`);
    a basis with NaN or Inf values is refused, with their count."""
    max_abs = finite_max_abs(basis)
    if not np.isfinite(max_abs):
        raise InputError(f"basis has {int(np.count_nonzero(~np.isfinite(basis)))} NaN/Inf values", path)
    return max_abs


def _with_zero_alpha(rgb: np.ndarray) -> np.ndarray:
    """``(m, H, W, 3)`` float16 layers as ``(m, H, W, 4)`` with alpha 0: OpenCV's channel copy
    (``mixChannels``, a layer at a time: 5x NumPy's strided ``rgba[..., :3] = rgb``, the same
    bytes); NumPy where OpenCV cannot take the arrays."""
    import cv2

    m, H, W, _ = rgb.shape
    rgba = np.empty((m, H, W, 4), dtype=np.float16)
    src, dst = rgb.view(np.uint16), rgba.view(np.uint16)
    if rgb.flags.c_contiguous:
        try:
            for k in range(m):  # (channel -1: filled with zero)
                cv2.mixChannels([src[k].reshape(H * W, 1, 3)], [dst[k].reshape(H * W, 1, 4)],
                                [0, 0, 1, 1, 2, 2, -1, 3])
            return rgba
        except cv2.error:
            pass
    rgba[..., :3] = rgb
    rgba[..., 3] = 0
    return rgba


class BasisTextures:
    """A basis ``(n, H, W, 3)`` resident on the GPU as one or more texture arrays.

    Parameters
    ----------
    ctx : moderngl.Context
    basis : (n, H, W, 3) float32 array
        Linear radiance, finite. Row 0 of the image is the top row of the photograph; the
        texture stores it at ``texelFetch`` row 0 (no flip).
    dtype : {'f16', 'f32'}
        Storage: RGBA16F with a power-of-two per-dataset scale, or RGBA32F with scale 1.
    max_layers : int, optional
        Layers per array; default :data:`ARRAY_LAYERS` (at most ``GL_MAX_ARRAY_TEXTURE_LAYERS``).
        Larger ``n`` is split.
    budget_bytes : int
        Refuse (``InputError``) a basis whose GPU storage exceeds this.
    path : path-like, optional
        Named in errors (the capture folder).

    Attributes
    ----------
    textures : list of moderngl.TextureArray
        ``textures[j]`` holds layers ``offsets[j] : offsets[j] + counts[j]``.
    offsets, counts : list of int
    scale : float
        Stored value = radiance * scale; pass 2 multiplies by ``1 / scale``.
    report : Float16Report or None
        For ``dtype='f16'``.
    """

    def __init__(self, ctx, basis, dtype: str = "f16", *, max_layers: int | None = None,
                 budget_bytes: int = DEFAULT_BUDGET, path=None):
        basis = _check_basis(basis, dtype, path)
        n, H, W, _ = basis.shape
        self.ctx = ctx
        self.dtype = dtype
        self.n = int(n)
        self.size = (int(W), int(H))
        max_tex = int(ctx.info.get("GL_MAX_TEXTURE_SIZE") or 16384)
        if W > max_tex or H > max_tex:
            raise InputError(f"basis images {W}x{H} exceed GL_MAX_TEXTURE_SIZE {max_tex}", path)
        hw_layers = int(ctx.info.get("GL_MAX_ARRAY_TEXTURE_LAYERS") or 256)
        self.max_layers = min(ARRAY_LAYERS if max_layers is None else int(max_layers), hw_layers)
        if self.max_layers < 1:
            raise ValueError("max_layers must be >= 1")
        itemsize = 2 if dtype == "f16" else 4
        self.nbytes = n * H * W * 4 * itemsize
        if self.nbytes > budget_bytes:
            raise InputError(
                f"basis of {n} images {W}x{H} needs {self.nbytes / 2**20:.0f} MiB of GPU memory as {dtype}, "
                f"over the budget of {budget_bytes / 2**20:.0f} MiB; use --rank K (compression), dtype 'f16', "
                f"or a smaller capture", path)
        max_abs = _finite_max_abs(basis, path)
        self.scale = choose_scale(max_abs) if dtype == "f16" else 1.0
        self.report = None
        self.textures, self.offsets, self.counts = [], [], []
        rel, n_flush = 0.0, 0
        try:
            for a in range(0, n, self.max_layers):
                b = min(n, a + self.max_layers)
                if dtype == "f16":
                    h, rep = to_float16(basis[a:b], scale=self.scale, path=path, max_abs=max_abs)
                    rgba = _with_zero_alpha(h)
                    rel, n_flush = max(rel, rep.max_rel_error), n_flush + rep.n_flushed
                else:
                    rgba = np.zeros((b - a, H, W, 4), dtype=np.float32)
                    rgba[..., :3] = basis[a:b]
                tex = ctx.texture_array((W, H, b - a), 4, data=rgba, dtype="f2" if dtype == "f16" else "f4")
                tex.filter = (0x2600, 0x2600)  # GL_NEAREST; pass 2 uses texelFetch anyway
                self.textures.append(tex)
                self.offsets.append(a)
                self.counts.append(b - a)
        except BaseException:
            self.release()
            raise
        if dtype == "f16":
            self.report = Float16Report(self.scale, max_abs, 0, 0, n_flush, rel)

    @property
    def n_arrays(self) -> int:
        """Number of texture arrays the basis was split into."""
        return len(self.textures)

    def release(self) -> None:
        """Release the textures."""
        for t in self.textures:
            release_gl(t)
        self.textures = []


def pack_pixel_major(layers: np.ndarray, dtype: str = "f16") -> np.ndarray:
    """Reorder basis layers into the pixel-major words of ``shaders/weighted_sum_packed.glsl``.

    Parameters
    ----------
    layers : (m, h, w, 3) float16 (``dtype='f16'``) or float32 (``dtype='f32'``) array
        Already scaled/converted values of ``m`` consecutive layers over ``h`` rows.
    dtype : {'f16', 'f32'}

    Returns
    -------
    (h, w, n_blocks, 3, 4) uint32 ndarray
        For each pixel, ``n_blocks = ceil(m / L)`` blocks of ``L`` layers (``L = 8`` for f16,
        4 for f32), each block one uvec4 per channel; a float16 word holds layers ``2k`` (low
        half) and ``2k + 1`` (high half). Padding layers are 0.
    """
    per = 8 if dtype == "f16" else 4
    m, h, w, _ = layers.shape
    nb = -(-m // per)
    x = np.zeros((nb * per, h, w, 3), dtype=np.float16 if dtype == "f16" else np.float32)
    x[:m] = layers
    x = np.ascontiguousarray(x.reshape(nb, per, h, w, 3).transpose(2, 3, 0, 4, 1))  # h, w, nb, 3, per
    return x.view(np.uint32).reshape(h, w, nb, 3, 4)


class PackedBasis:
    """A basis ``(n, H, W, 3)`` resident on the GPU as packed words (pass 2 ``'packed'``).

    The layers are cut into chunks of at most ``max_layers`` (one dispatch each). A chunk of
    ``m`` layers is, per pixel, ``ceil(m / 8)`` blocks of 3 ``uvec4`` (one per channel) of
    float16 pairs, or ``ceil(m / 4)`` blocks of float32 (:func:`pack_pixel_major`). With
    ``storage='image'`` (default) a chunk is one RGBA32UI texture array of ``3 ceil(m / 8)``
    layers (layer ``3 b + c`` = block ``b``, channel ``c``), read with ``imageLoad``; with
    ``storage='buffer'`` its rows are cut into bands whose pixel-major buffer fits one SSBO
    binding (``band_bytes``). Float16 uses the same checked power-of-two per-dataset scale as
    :class:`BasisTextures`.

    Parameters
    ----------
    ctx : moderngl.Context
    basis : (n, H, W, 3) float32 array
        Linear radiance, finite; row 0 is the top row (stored first; no flip).
    dtype : {'f16', 'f32'}
    max_layers : int, optional
        Layers per chunk (default :data:`PACKED_LAYERS`; at most 4096, the 64 KiB uniform
        block of the weights).
    budget_bytes : int
        Refuse (``InputError``) a basis whose GPU storage exceeds this.
    band_bytes : int, optional
        Largest band buffer (default the device's SSBO block size, at most :data:`SSBO_BAND_BYTES`);
        ``storage='buffer'`` only.
    storage : {'image', 'buffer'}
        :data:`PACKED_STORAGES`: on llvmpipe ``imageLoad`` of a ``uvec4`` is a vector gather, an
        SSBO load with per-invocation addresses a per-lane scalar loop (3x the CPU time of pass
        2 at 8 layers, docs/gpu.md "Pass 2").
    path : path-like, optional
        Named in errors.

    Attributes
    ----------
    images : list of moderngl.TextureArray
        ``storage='image'``: ``images[j]`` holds chunk ``j`` (layers ``offsets[j] : offsets[j] + counts[j]``).
    bands : list of list of (row0, rows, moderngl.Buffer)
        ``storage='buffer'``: ``bands[j]`` holds chunk ``j``.
    offsets, counts : list of int
    scale : float
        Stored value = radiance * scale; pass 2 multiplies by ``1 / scale``.
    report : Float16Report or None
        For ``dtype='f16'``.
    nbytes : int
        Bytes of all images or band buffers.
    """

    def __init__(self, ctx, basis, dtype: str = "f16", *, max_layers: int | None = None,
                 budget_bytes: int = DEFAULT_BUDGET, band_bytes: int | None = None, storage: str = "image",
                 path=None):
        basis = _check_basis(basis, dtype, path)
        if storage not in PACKED_STORAGES:
            raise ValueError(f"storage must be one of {PACKED_STORAGES}, not {storage!r}")
        n, H, W, _ = basis.shape
        self.ctx = ctx
        self.dtype = dtype
        self.storage = storage
        self.n = int(n)
        self.size = (int(W), int(H))
        self.max_layers = PACKED_LAYERS if max_layers is None else int(max_layers)
        if not 1 <= self.max_layers <= 4096:
            raise ValueError("max_layers must be in [1, 4096] for the packed basis")
        per = 8 if dtype == "f16" else 4
        self.offsets = list(range(0, n, self.max_layers))
        self.counts = [min(n, a + self.max_layers) - a for a in self.offsets]
        pixel_bytes = [48 * -(-c // per) for c in self.counts]
        self.nbytes = int(H * W * sum(pixel_bytes))
        if self.nbytes > budget_bytes:
            raise InputError(
                f"basis of {n} images {W}x{H} needs {self.nbytes / 2**20:.0f} MiB of GPU memory as {dtype}, "
                f"over the budget of {budget_bytes / 2**20:.0f} MiB; use --rank K (compression), dtype 'f16', "
                f"or a smaller capture", path)
        max_abs = _finite_max_abs(basis, path)
        limit = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or SSBO_BAND_BYTES)
        limit = min(limit, SSBO_BAND_BYTES) if band_bytes is None else int(band_bytes)
        if storage == "image":
            max_tex = int(ctx.info.get("GL_MAX_TEXTURE_SIZE") or 16384)
            max_arr = int(ctx.info.get("GL_MAX_ARRAY_TEXTURE_LAYERS") or 2048)
            if W > max_tex or H > max_tex:
                raise InputError(f"basis images {W}x{H} exceed GL_MAX_TEXTURE_SIZE {max_tex}", path)
            if 3 * -(-max(self.counts) // per) > max_arr:
                raise ValueError(f"{max(self.counts)} layers per chunk need more than GL_MAX_ARRAY_TEXTURE_LAYERS "
                                 f"({max_arr}) image layers; use a smaller max_layers")
        self.scale = choose_scale(max_abs) if dtype == "f16" else 1.0
        self.report = None
        self.bands = []
        self.images = []
        rel, n_flush = 0.0, 0
        try:
            for a, cnt, pb in zip(self.offsets, self.counts, pixel_bytes):
                if storage == "image":  # one RGBA32UI array per chunk: layer 3 b + c = block b, channel c
                    nb = -(-cnt // per)
                    tex = ctx.texture_array((W, H, 3 * nb), 4, dtype="u4")
                    tex.filter = (0x2600, 0x2600)  # GL_NEAREST (read with imageLoad)
                    self.images.append(tex)
                    for blk in range(nb):  # a block at a time: no second copy of the whole basis in memory
                        part = basis[a + per * blk:a + min(cnt, per * (blk + 1))]
                        if dtype == "f16":
                            part, rep = to_float16(part, scale=self.scale, path=path, max_abs=max_abs)
                            rel, n_flush = max(rel, rep.max_rel_error), n_flush + rep.n_flushed
                        else:
                            part = np.asarray(part, dtype=np.float32)
                        words = pack_pixel_major(part, dtype)[:, :, 0]  # h, w, 3, 4
                        planes = np.ascontiguousarray(words.transpose(2, 0, 1, 3))  # 3, h, w, 4
                        tex.write(planes, viewport=(0, 0, 3 * blk, W, H, 3))
                    continue
                if W * pb > limit:
                    raise InputError(f"one image row of {cnt} packed layers ({W * pb} bytes) exceeds the SSBO "
                                     f"limit of {limit} bytes; use a smaller max_layers", path)
                rows = max(1, min(H, limit // (W * pb)))
                chunk = []
                self.bands.append(chunk)
                for r in range(0, H, rows):
                    part = basis[a:a + cnt, r:r + rows]
                    if dtype == "f16":
                        part, rep = to_float16(part, scale=self.scale, path=path, max_abs=max_abs)
                        rel, n_flush = max(rel, rep.max_rel_error), n_flush + rep.n_flushed
                    else:
                        part = np.asarray(part, dtype=np.float32)
                    words = pack_pixel_major(part, dtype)
                    chunk.append((r, part.shape[1], ctx.buffer(words)))
        except BaseException:
            self.release()
            raise
        if dtype == "f16":
            self.report = Float16Report(self.scale, max_abs, 0, 0, n_flush, rel)

    @property
    def n_arrays(self) -> int:
        """Number of layer chunks (one dispatch each per band), as :attr:`BasisTextures.n_arrays`."""
        return len(self.images) if self.storage == "image" else len(self.bands)

    @property
    def n_bands(self) -> int:
        """Largest number of row bands of a chunk (1 with ``storage='image'``)."""
        if self.storage == "image":
            return 1 if self.images else 0
        return max((len(c) for c in self.bands), default=0)

    def release(self) -> None:
        """Release the buffers or images."""
        for chunk in self.bands:
            for _, _, buf in chunk:
                release_gl(buf)
        for tex in self.images:
            release_gl(tex)
        self.bands = []
        self.images = []
