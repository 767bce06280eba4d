"""Pass 2 on the GPU: the weighted sum of basis images, the display pass and coefficient projection.

* :class:`WeightedSum` -- ``relit(p) = sum_i w_i * B_i(p)`` per channel over the texture
  arrays of a :class:`ffls.gpu.basis.BasisTextures`, float32 accumulation, into an RGBA32F
  texture. ``method='compute'`` (``shaders/weighted_sum.glsl``, one dispatch per array,
  accumulating through ``imageLoad``) or ``'fragment'`` (``shaders/weighted_sum_frag.glsl``, a
  full-screen triangle, arrays summed by additive float blending), or ``'packed'`` (the
  default of the Engine; ``shaders/weighted_sum_packed.glsl`` over a
  :class:`ffls.gpu.basis.PackedBasis`: pixel-major float16 pairs in SSBOs, weights through a
  uniform block, 3-8x faster than the other two on llvmpipe). The weights are read from an
  SSBO (std430 ``vec4 w[n]``, rgb used) bound at :data:`WEIGHTS_BINDING`: pass 1's
  ``weights_buffer`` as is, or a coefficient buffer of a compressed basis.
* :class:`ToneMapPass` -- exposure + sRGB/Reinhard/ACES + sRGB encoding into an RGBA8 texture
  (``shaders/tonemap.glsl``), matching :func:`ffls.display.tonemap.tonemap` + ``to_uint8`` within one
  code value.
* :class:`Projector` -- ``c = P^T w`` for a compressed basis (``shaders/project_coeffs.glsl``),
  ``P`` from :meth:`ffls.relight.compress.CompressedBasis.projection_matrix`.

NumPy references: :func:`ffls.relight.cpu.relight_reference` (float64) for the weighted sum,
:func:`ffls.display.tonemap.tonemap` for the display pass, :meth:`CompressedBasis.project_weights` for
the projection. Texture row 0 is image row 0 (the top row of the photograph); nothing is flipped.
"""
from __future__ import annotations

import numpy as np

from ffls.gpu.context import default_framebuffer, release_gl
from ffls.gpu.shaders import load_program

__all__ = ["WEIGHTS_BINDING", "WEIGHTS_UBO_BINDING", "BASIS_BINDING", "BASIS_IMAGE_UNIT", "METHODS", "DEFAULT_METHOD", "default_method", "WeightedSum", "ToneMapPass", "Projector", "weights_to_vec4"]

#: SSBO binding point from which pass 2 (and the projector) read the weights.
WEIGHTS_BINDING = 0
#: Uniform-buffer binding of the weights for ``method='packed'`` (the same buffer as the SSBO).
WEIGHTS_UBO_BINDING = 0
#: SSBO binding of a band of the packed basis (``method='packed'``, storage ``'buffer'``).
BASIS_BINDING = 1
#: Image unit of a chunk of the packed basis (``method='packed'``, storage ``'image'``; 0 and 1 are
#: the HDR output and the fused display).
BASIS_IMAGE_UNIT = 2
#: Pass-2 implementations: ``'compute'`` and ``'fragment'`` read a
#: :class:`ffls.gpu.basis.BasisTextures`, ``'packed'`` a :class:`ffls.gpu.basis.PackedBasis`.
METHODS = ("compute", "fragment", "packed")
#: The Engine's pass 2: ``'auto'`` picks :func:`default_method` for the context.
DEFAULT_METHOD = "auto"
_TONEMAP_CODES = {"srgb": 0, "reinhard": 1, "aces": 2}


def default_method(ctx) -> str:
    """The pass-2 method for ``ctx``: ``'packed'`` on a CPU rasteriser, ``'compute'`` on a GPU.

    ``'packed'`` (pixel-major float16 in SSBOs) won every measured row on llvmpipe (docs/gpu.md
    "Pass 2"): there a texel fetch costs the same whatever its size. On a GPU the texture-array
    layout is the conventional one: neighbouring pixels read neighbouring texels (coalesced,
    through the texture cache), while the pixel-major layout strides them apart; compute was
    chosen over fragment because fragment arithmetic ran far slower on the H100/H200 machines
    this project has seen. This choice on a GPU is not yet measured here.
    """
    from ffls.gpu.context import is_software_renderer

    return "packed" if is_software_renderer(ctx.info.get("GL_RENDERER", "")) else "compute"


def weights_to_vec4(w) -> bytes:
    """Pack weights ``(n, 3)`` as std430 ``vec4[n]`` float32 bytes (alpha 0)."""
    w = np.asarray(w, dtype=np.float32)
    if w.ndim != 2 or w.shape[1] != 3:
        raise ValueError(f"weights must have shape (n, 3), not {w.shape}")
    out = np.zeros((w.shape[0], 4), dtype=np.float32)
    out[:, :3] = w
    return out.tobytes()


def _groups(size, local=8):
    return (-(-size[0] // local), -(-size[1] // local), 1)


class WeightedSum:
    """Pass 2: ``sum_i w_i B_i`` over a basis on the GPU into an RGBA32F texture.

    Parameters
    ----------
    ctx : moderngl.Context
    basis : ffls.gpu.basis.BasisTextures or ffls.gpu.basis.PackedBasis
        A :class:`~ffls.gpu.basis.PackedBasis` for ``method='packed'``, texture arrays otherwise.
    method : {'compute', 'fragment', 'packed'}

    Attributes
    ----------
    output : moderngl.Texture
        RGBA32F, ``basis.size`` (W, H); alpha is 1.
    """

    def __init__(self, ctx, basis, method: str = "compute"):
        from ffls.gpu.basis import PackedBasis

        if method not in METHODS:
            raise ValueError(f"pass-2 method must be one of {METHODS}, not {method!r}")
        if (method == "packed") != isinstance(basis, PackedBasis):
            need = "a PackedBasis" if method == "packed" else "BasisTextures"
            raise TypeError(f"pass-2 method {method!r} needs {need}, not {type(basis).__name__}")
        self.ctx, self.basis, self.method = ctx, basis, method
        self.size = basis.size
        self.output = ctx.texture(self.size, 4, dtype="f4")
        self.output.filter = (0x2600, 0x2600)
        self._fbo = self._vao = self._wscratch = None
        if method == "packed":
            self._init_packed()
            return
        if method == "compute":
            self.prog = load_program(ctx, "weighted_sum.glsl", {"WEIGHTS_BINDING": WEIGHTS_BINDING})
            self._fbo = self._vao = None
        else:
            self.prog = load_program(ctx, "weighted_sum_frag.glsl", {"WEIGHTS_BINDING": WEIGHTS_BINDING})
            self._fbo = ctx.framebuffer(color_attachments=[self.output])
            self._vao = ctx.vertex_array(self.prog, [])

    def _init_packed(self):
        b = self.basis
        per = 8 if b.dtype == "f16" else 4
        self._progs, self._defines = [], []
        for cnt in b.counts:
            defines = {"N_LAYERS": cnt, "N_BLOCKS": -(-cnt // per), "WEIGHTS_UBO_BINDING": WEIGHTS_UBO_BINDING,
                       "BASIS_BINDING": BASIS_BINDING}
            if b.dtype == "f16":
                defines["PACKED_F16"] = True
            if b.storage == "image":
                defines["IMAGE_BASIS"] = True
                defines["BASIS_IMAGE_UNIT"] = BASIS_IMAGE_UNIT
            self._defines.append(defines)
            self._progs.append(load_program(self.ctx, "weighted_sum_packed.glsl", defines))
        # uniform-block ranges must start at a multiple of the device's alignment: chunks whose
        # first weight is not aligned read a copy of their weights (a GPU-side copy, no read-back)
        align = int(self.ctx.info.get("GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT") or 256)
        self._wslots, total = [], 0
        for off, cnt in zip(b.offsets, b.counts):
            if (16 * off) % align == 0:
                self._wslots.append(None)
            else:
                self._wslots.append(total)
                total += -(-16 * cnt // align) * align
        if total:
            self._wscratch = self.ctx.buffer(reserve=total)

    def _run_packed(self, weights_buffer, display=None, hdr=True):
        ctx, b = self.ctx, self.basis
        self.output.bind_to_image(0, read=True, write=True)
        progs = list(self._progs)
        if display is not None:  # the last chunk also tone-maps into the display texture
            tex, exposure, method = display
            extra = {"FUSED_TONEMAP": True} if hdr else {"FUSED_TONEMAP": True, "DISPLAY_ONLY": True}
            last = load_program(ctx, "weighted_sum_packed.glsl", {**self._defines[-1], **extra})
            last["u_exposure_scale"].value = float(2.0 ** float(exposure))
            last["u_method"].value = _TONEMAP_CODES[method]
            tex.bind_to_image(1, read=False, write=True)
            progs[-1] = last
        images = b.images if b.storage == "image" else [None] * len(progs)
        bands = b.bands if b.storage == "buffer" else [[(0, self.size[1], None)]] * len(progs)
        for j, (prog, off, cnt, slot, chunk, img) in enumerate(zip(progs, b.offsets, b.counts, self._wslots, bands,
                                                                   images)):
            if slot is None:
                weights_buffer.bind_to_uniform_block(WEIGHTS_UBO_BINDING, offset=16 * off, size=16 * cnt)
            else:
                ctx.copy_buffer(self._wscratch, weights_buffer, size=16 * cnt, read_offset=16 * off, write_offset=slot)
                self._wscratch.bind_to_uniform_block(WEIGHTS_UBO_BINDING, offset=slot, size=16 * cnt)
            if j:
                ctx.memory_barrier()
            prog["u_width"].value = self.size[0]  # programs are cached per context: this instance's size, each run
            prog["u_inv_scale"].value = 1.0 / b.scale
            prog["u_accumulate"].value = 1 if j else 0
            if img is not None:
                img.bind_to_image(BASIS_IMAGE_UNIT, read=True, write=False)
            for row0, rows, buf in chunk:
                if buf is not None:
                    buf.bind_to_storage_buffer(BASIS_BINDING)
                prog["u_row0"].value = row0
                prog.run(-(-self.size[0] // 64), rows, 1)
        ctx.memory_barrier()

    @property
    def fuses_display(self) -> bool:
        """Whether :meth:`run` can also write the display image (``display=``): the packed method."""
        return self.method == "packed"

    @property
    def display_only(self) -> bool:
        """Whether :meth:`run` can write the display image alone (``hdr=False``): packed, one chunk."""
        return self.method == "packed" and self.basis.n_arrays == 1

    def run(self, weights_buffer, n_weights: int | None = None, display=None, hdr: bool = True) -> None:
        """Compute the relit image into :attr:`output`.

        Parameters
        ----------
        weights_buffer : moderngl.Buffer
            std430 ``vec4 w[n]`` with at least ``basis.n`` entries (rgb used).
        n_weights : int, optional
            Entries in the buffer, checked against ``basis.n`` when given.
        display : (moderngl.Texture, float, str), optional
            ``(rgba8 texture of the same size, exposure, tone curve)``: the last dispatch also
            writes what :class:`ToneMapPass` would (same curves, ``shaders/include/tonemap_curves.glsl``),
            saving the display pass's read of the HDR. Only where :attr:`fuses_display`.
        hdr : bool
            False (with ``display``, where :attr:`display_only`): write the display image only;
            :attr:`output` is then left as it was (its store is ~15 % of the pass on llvmpipe).
        """
        if n_weights is not None and n_weights < self.basis.n:
            raise ValueError(f"{n_weights} weights for a basis of {self.basis.n} layers")
        if weights_buffer.size < 16 * self.basis.n:
            raise ValueError(f"weights buffer holds {weights_buffer.size // 16} vec4, basis has {self.basis.n} layers")
        if not hdr and (display is None or not self.display_only):
            raise ValueError("hdr=False needs display= and a packed basis of one chunk")
        if display is not None:
            if not self.fuses_display:
                raise ValueError(f"pass-2 method {self.method!r} does not write the display image")
            if display[2] not in _TONEMAP_CODES:
                raise ValueError(f"tone-map method must be one of {tuple(_TONEMAP_CODES)}, not {display[2]!r}")
            if tuple(display[0].size) != tuple(self.size):
                raise ValueError(f"display texture {display[0].size} is not the image size {self.size}")
        if self.method == "packed":
            self._run_packed(weights_buffer, display, hdr)
            return
        weights_buffer.bind_to_storage_buffer(WEIGHTS_BINDING)
        prog = self.prog
        # the programs are cached per context and shared by every instance: this one's uniforms, each run
        if "u_basis" in prog:
            prog["u_basis"].value = 0
        if "u_size" in prog:
            prog["u_size"].value = self.size
        prog["u_inv_scale"].value = 1.0 / self.basis.scale
        if self.method == "compute":
            self.output.bind_to_image(0, read=True, write=True)
            for j, (tex, off, cnt) in enumerate(zip(self.basis.textures, self.basis.offsets, self.basis.counts)):
                if j:
                    self.ctx.memory_barrier()
                tex.use(0)
                prog["u_offset"].value = off
                prog["u_count"].value = cnt
                prog["u_accumulate"].value = 1 if j else 0
                prog.run(*_groups(self.size))
            self.ctx.memory_barrier()
        else:
            ctx = self.ctx
            previous = ctx.fbo
            self._fbo.use()
            ctx.disable(ctx.DEPTH_TEST)
            self._fbo.clear(0.0, 0.0, 0.0, 0.0)
            ctx.enable(ctx.BLEND)
            ctx.blend_func = (ctx.ONE, ctx.ONE, ctx.ONE, ctx.ZERO)  # rgb summed, alpha stays 1
            ctx.blend_equation = ctx.FUNC_ADD
            try:
                for tex, off, cnt in zip(self.basis.textures, self.basis.offsets, self.basis.counts):
                    tex.use(0)
                    prog["u_offset"].value = off
                    prog["u_count"].value = cnt
                    self._vao.render(mode=ctx.TRIANGLES, vertices=3)
            finally:
                ctx.disable(ctx.BLEND)
                ctx.blend_func = ctx.DEFAULT_BLENDING
                # never leave our framebuffer bound: moderngl re-binds the bound one when it
                # creates framebuffers, an error once ours is released
                (previous if previous is not None else default_framebuffer(ctx)).use()

    def read(self) -> np.ndarray:
        """The relit image ``(H, W, 3)`` float32 (row 0 = image row 0)."""
        W, H = self.size
        return np.frombuffer(self.output.read(), dtype=np.float32).reshape(H, W, 4)[..., :3].copy()

    def release(self) -> None:
        """Release the output texture, framebuffer and scratch buffer (programs are cached by the loader)."""
        for o in (self._vao, self._fbo, self._wscratch, self.output):
            release_gl(o)
        self._vao = self._fbo = self._wscratch = self.output = None


class ToneMapPass:
    """Exposure + tone curve + sRGB encoding of an RGBA32F texture into an RGBA8 texture.

    Parameters
    ----------
    ctx : moderngl.Context
    size : (W, H)

    Attributes
    ----------
    output : moderngl.Texture
        RGBA8 display texture (alpha 255); ``output.glo`` is usable by imgui.
    """

    def __init__(self, ctx, size):
        self.ctx, self.size = ctx, tuple(size)
        self.prog = load_program(ctx, "tonemap.glsl")
        self.output = ctx.texture(self.size, 4, dtype="f1")
        self.output.filter = (0x2601, 0x2601)  # GL_LINEAR for display

    def run(self, hdr_texture, exposure: float = 0.0, method: str = "srgb") -> None:
        """Tone-map ``hdr_texture`` (RGBA32F, same size) into :attr:`output`.

        Parameters
        ----------
        hdr_texture : moderngl.Texture
        exposure : float
            Stops; the radiance is multiplied by ``2 ** exposure``.
        method : {'srgb', 'reinhard', 'aces'}
        """
        if method not in _TONEMAP_CODES:
            raise ValueError(f"tone-map method must be one of {tuple(_TONEMAP_CODES)}, not {method!r}")
        hdr_texture.bind_to_image(0, read=True, write=False)
        self.output.bind_to_image(1, read=False, write=True)
        self.prog["u_size"].value = self.size  # the program is shared by every pass of this context
        self.prog["u_exposure_scale"].value = float(2.0 ** float(exposure))
        self.prog["u_method"].value = _TONEMAP_CODES[method]
        self.prog.run(*_groups(self.size))
        self.ctx.memory_barrier()

    def read(self) -> np.ndarray:
        """The display image ``(H, W, 3)`` uint8."""
        W, H = self.size
        return np.frombuffer(self.output.read(), dtype=np.uint8).reshape(H, W, 4)[..., :3].copy()

    def release(self) -> None:
        release_gl(self.output)
        self.output = None


class Projector:
    """``c = P^T w`` on the GPU for a compressed basis.

    Parameters
    ----------
    ctx : moderngl.Context
    P : (n, L, 3) float array
        Projection matrix (:meth:`ffls.relight.compress.CompressedBasis.projection_matrix`), ``L = K + 1``.

    Attributes
    ----------
    coeffs_buffer : moderngl.Buffer
        std430 ``vec4 c[L]`` (rgb used): the weights for pass 2 over ``[mean, E_1..E_K]``.
    """

    def __init__(self, ctx, P):
        P = np.asarray(P, dtype=np.float32)
        if P.ndim != 3 or P.shape[2] != 3:
            raise ValueError(f"P must have shape (n, L, 3), not {P.shape}")
        self.ctx = ctx
        self.n, self.L = P.shape[:2]
        p4 = np.zeros((self.n, self.L, 4), dtype=np.float32)
        p4[..., :3] = P
        self.p_buffer = ctx.buffer(p4.tobytes())
        self.coeffs_buffer = ctx.buffer(reserve=16 * self.L)
        self.prog = load_program(ctx, "project_coeffs.glsl", {"WEIGHTS_BINDING": WEIGHTS_BINDING})

    def run(self, weights_buffer) -> None:
        """Project the weights in ``weights_buffer`` (``vec4 w[n]``) into :attr:`coeffs_buffer`."""
        if weights_buffer.size < 16 * self.n:
            raise ValueError(f"weights buffer holds {weights_buffer.size // 16} vec4, projection needs {self.n}")
        weights_buffer.bind_to_storage_buffer(WEIGHTS_BINDING)
        self.p_buffer.bind_to_storage_buffer(1)
        self.coeffs_buffer.bind_to_storage_buffer(2)
        self.prog["u_n"].value = self.n
        self.prog["u_L"].value = self.L
        self.prog.run(-(-self.L // 64), 1, 1)
        self.ctx.memory_barrier()

    def read(self) -> np.ndarray:
        """Coefficients ``(L, 3)`` float32."""
        return np.frombuffer(self.coeffs_buffer.read(), dtype=np.float32).reshape(self.L, 4)[:, :3].copy()

    def release(self) -> None:
        for b in (self.p_buffer, self.coeffs_buffer):
            release_gl(b)
