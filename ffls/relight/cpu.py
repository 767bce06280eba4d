"""CPU relighting: the weighted sum of basis images (Masselus, Dutre, Anrys 2002, section 6).

``relit = sum_i w_i * B_i`` per colour channel, where ``w`` are the angular Voronoi weights of a
light map (:func:`ffls.weights.voronoi.integrate_weights`) and ``B_i`` the basis image lit from light
direction ``i``.

* :func:`relight_reference` accumulates in float64 (the reference the GPU and the fast path are
  compared against).
* :func:`relight_fast` is one float32 BLAS product per block of pixels: ``(3, n) @ (n, 3 P)``
  over a reshaped view of the basis (no copy of the basis), keeping the channel-diagonal part.
* :class:`CpuRelighter` relights one capture with the interface of the GPU engine
  (:class:`ffls.gpu.engine.Engine`): ``set_lightmap``, ``set_rotation``, ``render``,
  ``read_hdr``, ``read_display``, ``release``. ``ffls relight``, ``ffls render --cpu`` and the
  demo's CPU path all use it; :func:`relight_capture` is its one-call form.
"""
from __future__ import annotations

import numpy as np

from ffls.conventions import check_hemisphere
from ffls.errors import InputError
from ffls.relight.basis import capture_basis
from ffls.relight.compress import CompressedBasis, compress_basis, load_or_compress
from ffls.relight.quality import integration_map
from ffls.relight.storage import store_basis
from ffls.weights.kriging import KernelLearner
from ffls.weights.voronoi import Weights, bake_cells, integrate_weights
from ffls.weights.weighting import Weighting, integrate as integrate_scheme
from ffls.relight.inputs import WeightsInputs

__all__ = ["relight_reference", "relight_fast", "CpuRelighter", "relight_capture", "PRECISIONS"]

#: Accumulation of the weighted sum: ``'f32'`` :func:`relight_fast`, ``'f64'`` :func:`relight_reference`.
PRECISIONS = ("f32", "f64")


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


class CpuRelighter(WeightsInputs):
    """CPU relighting of one capture, with the interface of :class:`ffls.gpu.engine.Engine`.

    Pass 1 is :func:`ffls.weights.voronoi.integrate_weights` (through a candidate-cell texture,
    the GPU's lookup, or the exact k-d tree), pass 2 :func:`relight_fast` (float32),
    :func:`relight_reference` (float64) or, with a compressed basis, its exact float64 algebra
    (:meth:`ffls.relight.compress.CompressedBasis.relight`); the display image is
    :func:`ffls.display.tonemap.tonemap` of the relit image, made when first read. Only what
    changed is recomputed.

    Parameters
    ----------
    basis : (n, H, W, 3) float array
        Linear basis images; row 0 is the top row.
    directions : (n, 3) float array
        Unit light directions (world frame) of the basis images.
    hemisphere : {'upper', 'full'}
    precision : {'f32', 'f64'}
        Accumulation of the weighted sum (:data:`PRECISIONS`); ignored with a compressed basis.
    rank : int, optional
        Use a compressed basis of ``rank`` eigen-images (computed here unless ``compressed``).
    compressed : ffls.relight.compress.CompressedBasis, optional
        A precomputed compression of ``basis``.
    cell_res : int or None
        Resolution of the candidate-cell texture (:func:`ffls.weights.voronoi.bake_cells`), or
        ``None`` for the exact k-d tree assignment.
    cell_k, cell_max_res : int
        Candidate slots per texel, and the resolution up to which an overflowing bake is redone
        at twice the resolution (``None``: no retry); as :func:`ffls.weights.voronoi.bake_cells`.
    storage : {'f32', 'f16'}, optional
        Round the basis (or the compressed layers) as the GPU stores it
        (:func:`ffls.relight.storage.store_basis`: float16 with the checked per-dataset scale),
        so that the CPU path shows the storage's error; None (default) keeps the input as is.
    map_res : int, optional
        Height of the lat-long light map pass 1 integrates
        (:func:`ffls.relight.quality.integration_map`); None = the map as given.
    weighting : {'voronoi', 'antialiased', 'barycentric', 'gaussian', 'spline'}
        Weighting scheme of pass 1 (:mod:`ffls.weights.weighting`). The smooth schemes are
        evaluated exactly at every rotated light-map direction (the float64 reference; the GPU
        looks them up in a baked texture).
    weighting_options : dict, optional
        The scheme's options (:data:`ffls.weights.weighting.OPTIONS`).
    path : path-like, optional
        Named in errors (the capture folder).
    """

    def __init__(self, basis, directions, hemisphere: str = "upper", *, precision: str = "f32",
                 rank: int | None = None, compressed=None, cell_res: int | None = 256, cell_k: int = 8,
                 cell_max_res: int | None = None, storage: str | None = None, map_res: int | None = None,
                 path=None, weighting: str = "voronoi", weighting_options: dict | None = None):
        self.hemisphere = check_hemisphere(hemisphere)
        basis = np.asarray(basis)
        d = np.asarray(directions, dtype=np.float64)
        if basis.ndim != 4 or basis.shape[-1] != 3:
            raise InputError(f"basis must have shape (n, H, W, 3), not {basis.shape}", path)
        if d.shape != (basis.shape[0], 3):
            raise InputError(f"{d.shape[0] if d.ndim == 2 else '?'} light directions for {basis.shape[0]} basis images", path)
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, not {precision!r}")
        if compressed is None and rank is not None:
            compressed = compress_basis(basis, int(rank))
        if compressed is not None and (compressed.n_lights != basis.shape[0] or tuple(compressed.shape) != basis.shape[1:3]):
            raise InputError("compressed basis does not match the capture's basis", path)
        if storage is not None:
            if compressed is not None:
                compressed = _stored_compressed(compressed, storage, path)
            else:
                basis = _stored(basis, storage, path)
        self.storage = storage
        self.map_res = None if map_res is None else int(map_res)
        self.basis = basis
        self.directions = d
        self.precision = precision
        self.compressed = compressed
        self._cell_args = (cell_res, cell_k, cell_max_res)
        self.cells = None
        self.weighting = None
        self._weighting = None
        #: Kriging's kernel, learnt from this basis when first chosen (:class:`ffls.weights.kriging.KernelLearner`).
        self.kernel = KernelLearner(d, basis)
        self.set_weighting(weighting, **(weighting_options or {}))
        #: :class:`ffls.weights.voronoi.Weights` of the last render (None before the first, or after set_weights).
        self.last_weights: Weights | None = None
        self._init_inputs()

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_capture(cls, capture, lights, *, save_compressed: bool = False, quality=None, **kw) -> "CpuRelighter":
        """A relighter for a capture folder and its light directions.

        Parameters
        ----------
        capture : ffls.io.capture.Capture
            The basis comes from :func:`ffls.relight.basis.accepted_basis`, the domain from
            ``capture.hemisphere``.
        lights : ffls.io.capture.Lights
            Lights with ``ok_mask`` False are left out (their photos are not loaded).
        save_compressed : bool
            With ``rank=K``: a compressed basis saved in the capture folder is used when it fits
            (:func:`ffls.relight.compress.load_or_compress`); a new one is saved there only if
            this is set.
        quality : ffls.relight.quality.Quality, optional
            Every knob at once: near-light correction and basis subset
            (:func:`ffls.relight.basis.capture_basis`), then ``storage``, ``rank``, ``cell_res``,
            ``map_res`` and ``weighting`` from it (keywords given in ``kw`` win).
        **kw
            As :class:`CpuRelighter`.
        """
        basis, d, _ = capture_basis(capture, lights, quality)
        if quality is not None:
            for k, v in (("storage", quality.precision), ("rank", quality.rank), ("map_res", quality.map_res),
                         ("weighting", quality.weighting)):
                kw.setdefault(k, v)
            if quality.cell_res is not None:
                kw.setdefault("cell_res", quality.cell_res)
        rank = kw.get("rank")
        if rank is not None and kw.get("compressed") is None:
            kw["compressed"] = load_or_compress(capture.folder, basis, int(rank), save=save_compressed)
        kw.setdefault("path", getattr(capture, "folder", None))
        return cls(basis, d, getattr(capture, "hemisphere", "upper"), **kw)

    # ------------------------------------------------------------------ inputs
    def set_lightmap(self, lm) -> None:
        """Use light map ``lm`` (:class:`ffls.lightmaps.lightmap.LightMap` or ``(dirs, radiance, solid_angle)``)."""
        self._lightmap = integration_map(lm, self.map_res)
        self._weights = None

    def set_weighting(self, scheme: str = "voronoi", **options) -> None:
        """Use weighting ``scheme`` (:mod:`ffls.weights.weighting`) from the next render on.

        ``'kriging'`` without options uses the kernel learnt from this basis
        (:class:`ffls.weights.kriging.KernelLearner`).
        """
        options = self.kernel.options_for(scheme, options)
        if scheme == "voronoi":
            if options:
                raise ValueError("weighting 'voronoi' takes no options")
            res, k, max_res = self._cell_args
            if self.cells is None and res is not None:
                self.cells = bake_cells(self.directions, self.hemisphere, res=res, k=k, max_res=max_res)
            self._weighting = None
        else:
            self._weighting = Weighting(self.directions, scheme, self.hemisphere, **options)
        if scheme != self.weighting and getattr(self, "_lightmap", None) is not None:
            self._weights = None
        self.weighting = scheme

    # ------------------------------------------------------------------ passes
    def _pass1(self) -> np.ndarray:
        if self._weighting is None:
            self.last_weights = integrate_weights(self._lightmap, self.directions, self._rotation, self.hemisphere,
                                                  cells=self.cells)
        else:
            self.last_weights = integrate_scheme(self._lightmap, self.directions, self._rotation, self.hemisphere,
                                                 self.weighting, weighting=self._weighting,
                                                 **self._weighting.options)
        return self.last_weights.weights

    def _pass2(self, weights) -> np.ndarray:
        if self.compressed is not None:
            return self.compressed.relight(weights)
        if self.precision == "f64":
            return relight_reference(weights, self.basis)
        return relight_fast(weights, self.basis)

    # ------------------------------------------------------------------ outputs
    @property
    def size(self) -> tuple[int, int]:
        """(W, H) of the images."""
        return int(self.basis.shape[2]), int(self.basis.shape[1])

    @property
    def n_lights(self) -> int:
        return int(self.basis.shape[0])

    def read_hdr(self) -> np.ndarray:
        """The relit image ``(H, W, 3)`` float32, row 0 = top row (``hdr`` keeps the accumulation dtype:
        float32 for 'f32', else float64)."""
        return self.hdr.astype(np.float32)

    def release(self) -> None:
        """Drop the basis and the images (the GPU engine's counterpart frees GL objects)."""
        self.basis = self.cells = self.compressed = None
        self._hdr = self._display = self._weights = self._display_key = None


def _stored(basis, storage, path=None) -> np.ndarray:
    """``basis`` as the storage ``storage`` gives it back: float32 values after the rounding."""
    stored, scale, _ = store_basis(basis, storage, path)
    if stored.dtype == np.float32:
        return stored
    out = stored.astype(np.float32)
    out *= np.float32(1.0 / scale)  # a power of two: exact
    return out


def _stored_compressed(cb, storage, path=None):
    """A compressed basis whose mean and eigen-images went through ``storage`` together (one scale, as on the GPU)."""
    layers = _stored(cb.layers(), storage, path)
    return CompressedBasis(layers[0], layers[1:], cb.loadings, cb.singular_values, cb.mode, dict(cb.info))


def relight_capture(capture, lights, lightmap, rotation=None, cells_res: int | None = 256, fast: bool = True,
                    k: int = 4, max_res: int | None = 1024, weighting: str = "voronoi",
                    weighting_options: dict | None = None) -> tuple[np.ndarray, Weights]:
    """Relight a capture under a light map (one :class:`CpuRelighter` render).

    Parameters
    ----------
    capture : ffls.io.capture.Capture
        Gives the basis images, ``image_names`` and ``hemisphere``.
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
    k : int
        Candidate slots per texel of the cell texture.
    weighting : str
        Weighting scheme (:mod:`ffls.weights.weighting`); ``weighting_options`` its options.

    Returns
    -------
    image : (H, W, 3) float32 (fast) or float64
    weights : Weights
        For the used lights, in the order of ``lights`` restricted to ``ok_mask``.
    """
    r = CpuRelighter.from_capture(capture, lights, precision="f32" if fast else "f64", cell_res=cells_res,
                                  cell_k=k, cell_max_res=max_res, weighting=weighting,
                                  weighting_options=weighting_options)
    r.set_lightmap(lightmap)
    if rotation is not None:
        r.set_rotation(rotation)
    r.render()
    return r.hdr, r.last_weights
