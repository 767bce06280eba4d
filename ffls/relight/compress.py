"""Compressed radiance basis: mean image + K eigen-images from a randomised SVD (PCA).

Each basis image is approximated as ``B_i ~= M + sum_k U[i, k] E_k`` (per channel), so the
relit image becomes

    relit = sum_i w_i B_i ~= (sum_i w_i) M + sum_k c_k E_k,   c_k = sum_i U[i, k] w_i,

and pass 2 sums ``K + 1`` layers ``[M, E_1..E_K]`` with coefficients ``c = P^T w`` instead of
``n`` layers (:meth:`CompressedBasis.projection_matrix`, ``P[:, 0] = 1``).

Two modes:

* ``'per_channel'`` (default): one SVD per colour channel, ``E_k`` of channel c spans only that
  channel; loadings ``U`` are ``(n, K, 3)``. At the same K and the same storage
  ``(K, H, W, 3)`` it is never worse than a shared basis (it is optimal per channel); on the
  synthetic capture both give the same error to 2 digits (docs/gpu.md, "Compressed basis"),
  at about three times the SVD cost.
* ``'shared'``: one SVD of the images as vectors of length ``H W 3``; the loadings are the same
  for the three channels (stored broadcast to ``(n, K, 3)``).

The SVD is the randomised range finder with power (subspace) iterations of N. Halko,
P.-G. Martinsson, J. A. Tropp, "Finding structure with randomness: probabilistic algorithms for
constructing approximate matrix decompositions", SIAM Review 53(2), 2011 (Algorithms 4.4 + 5.1):
``Y = X Omega``, ``q`` rounds of ``Q = qr(X (X^T Q))``, then the exact SVD of the small
``Q^T X``. The products run in float32 BLAS, the small factorisations in float64.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffls.errors import FflsError, InputError, atomic_output, os_error_message

__all__ = ["CompressedBasis", "compress_basis", "randomized_svd_Halko2011", "save_compressed",
           "load_compressed", "load_or_compress", "basis_checksum", "COMPRESSED_FILENAME", "MODES", "DEFAULT_RANK",
           "rank_range", "default_rank", "truncation_errors", "choose_rank", "AUTO_RANK_ERROR",
           "AUTO_RANK_MAX", "LAYER_BLOCK", "LAYER_PIXEL_BUDGET", "budget_rank"]

#: File name of a compressed basis inside a capture folder.
COMPRESSED_FILENAME = "basis_compressed.npz"
MODES = ("per_channel", "shared")
_FORMAT_VERSION = 1
#: Rank used where none is asked for (the viewer on a CPU rasteriser); capped by :func:`default_rank`.
#: K + 1 = 8 layers fill one block of the packed pass 2 (docs/viewer.md, "Frame budget").
DEFAULT_RANK = 7
#: Relative RMS error of the truncated basis that the viewer's data-driven rank aims at
#: (:func:`choose_rank`; docs/viewer.md, "Default rank").
AUTO_RANK_ERROR = 0.01
#: Layers of one block of the packed pass 2: K + 1 = 8, 16, 24... cost the same within a block.
LAYER_BLOCK = 8
#: Largest rank :func:`choose_rank` picks on a CPU rasteriser: K + 1 = 24 layers, three blocks
#: (the frame budget measured in docs/viewer.md, "Default rank").
AUTO_RANK_MAX = 23
#: Layers x pixels of pass 2 a CPU rasteriser's frame allows: three blocks at 384 x 384 (measured
#: in docs/viewer.md, "Default rank": 24 layers at 512 x 512 cut the frame rate 3-6x).
LAYER_PIXEL_BUDGET = 24 * 384 * 384


def budget_rank(height: int, width: int, budget: int = LAYER_PIXEL_BUDGET) -> int:
    """The largest rank whose K + 1 layers of ``height`` x ``width`` fit ``budget`` in whole blocks
    of :data:`LAYER_BLOCK` (at least one block: 7), at most :data:`AUTO_RANK_MAX`."""
    blocks = max(1, int(budget) // max(int(height) * int(width) * LAYER_BLOCK, 1))
    return int(min(blocks * LAYER_BLOCK - 1, AUTO_RANK_MAX))


def rank_range(n_lights: int) -> tuple[int, int]:
    """Valid ranks ``(1, n - 1)`` for a basis of ``n_lights`` images (``(1, 1)`` for a single light).

    The mean takes one degree of freedom, so K = n - 1 already reproduces the basis exactly.
    """
    return 1, max(int(n_lights) - 1, 1)


def default_rank(n_lights: int, preferred: int = DEFAULT_RANK) -> int:
    """``preferred`` capped to the valid range of :func:`rank_range`: always a valid rank.

    E.g. 7 for 100 lights, 7 for 12 lights, 1 for 2 lights (the range is 1..n-1).
    """
    lo, hi = rank_range(n_lights)
    return int(min(max(int(preferred), lo), hi))


def truncation_errors(basis, max_pixels: int = 1 << 14) -> np.ndarray:
    """Relative RMS error of the mean + K eigen-images approximation of ``basis``, for every K.

    ``err[K] = sqrt(sum_{k > K} s_k^2 / ||B||^2)`` (per-channel SVD of the centred basis, as
    :func:`compress_basis`'s default mode; ``||B||`` the uncentred basis, what a relit image is
    made of). The spectrum is the exact eigen-decomposition of the ``(n, n)`` Gram matrix of a
    regular pixel grid of at most ``max_pixels`` pixels (every s-th row and column).

    Parameters
    ----------
    basis : (n, H, W, 3) float array

    Returns
    -------
    (n,) float64
        ``err[0]`` the mean alone, ``err[n - 1] = 0`` (exact).
    """
    b = np.asarray(basis)
    if b.ndim != 4 or b.shape[-1] != 3:
        raise ValueError(f"basis must be (n, H, W, 3), not {b.shape}")
    n, H, W, _ = b.shape
    step = max(1, int(np.ceil(np.sqrt(H * W / max(int(max_pixels), 1)))))
    sub = b[:, ::step, ::step].astype(np.float64)
    total = float(np.square(sub).sum())
    discarded = np.zeros(n)
    for c in range(3):
        X = sub[..., c].reshape(n, -1)
        X = X - X.mean(axis=0, keepdims=True)
        ev = np.sort(np.maximum(np.linalg.eigvalsh(X @ X.T), 0.0))[::-1]
        tail = np.concatenate([np.cumsum(ev[::-1])[::-1], [0.0]])  # tail[K] = sum_{k >= K} ev_k
        discarded += tail[:n]
    discarded[-1] = 0.0  # K = n - 1 is exact (the centred basis has rank <= n - 1)
    return np.sqrt(discarded / total) if total > 0 else np.zeros(n)


def choose_rank(basis, max_error: float = AUTO_RANK_ERROR, max_rank: int = AUTO_RANK_MAX) -> tuple[int, float]:
    """The smallest rank whose truncation error (:func:`truncation_errors`) is ``<= max_error``,
    raised to fill its block of :data:`LAYER_BLOCK` layers (free in pass 2), capped by ``max_rank``
    and by :func:`rank_range`.

    Returns
    -------
    rank : int
    error : float
        The truncation error at ``rank`` (above ``max_error`` when the cap binds).
    """
    err = truncation_errors(basis)
    lo, hi = rank_range(len(err))
    ok = np.flatnonzero(err[lo:] <= max_error)
    k = lo + int(ok[0]) if len(ok) else hi
    k = -(-(k + 1) // LAYER_BLOCK) * LAYER_BLOCK - 1  # K + 1 a whole number of blocks
    k = int(min(max(k, lo), hi, max(int(max_rank), lo)))
    return k, float(err[min(k, len(err) - 1)])


@dataclass
class CompressedBasis:
    """Mean image + K eigen-images of a basis ``(n, H, W, 3)``.

    Attributes
    ----------
    mean : (H, W, 3) float32
        Mean basis image ``M``.
    components : (K, H, W, 3) float32
        Eigen-images ``E_k`` (singular value folded in).
    loadings : (n, K, 3) float32
        ``U[i, k, c]``; orthonormal columns per channel.
    singular_values : (K, 3) float64
    mode : {'per_channel', 'shared'}
    info : dict
        Parameters (seed, oversample, power_iters), timing, and the relative Frobenius error of
        the reconstruction when it was measured.
    note : str
        One line for the user, not saved: why a new compression could not be kept in the
        capture folder (:func:`load_or_compress`), or empty.
    """

    mean: np.ndarray
    components: np.ndarray
    loadings: np.ndarray
    singular_values: np.ndarray
    mode: str = "per_channel"
    info: dict = field(default_factory=dict)
    note: str = ""

    @property
    def rank(self) -> int:
        """K, the number of eigen-images."""
        return int(self.components.shape[0])

    @property
    def n_lights(self) -> int:
        return int(self.loadings.shape[0])

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the images."""
        return tuple(self.mean.shape[:2])

    def project_weights(self, weights) -> np.ndarray:
        """Coefficients ``c_k = sum_i U[i, k] w_i`` of the eigen-images.

        Parameters
        ----------
        weights : (n, 3) array_like

        Returns
        -------
        (K, 3) float64
            The mean term's coefficient is ``weights.sum(0)`` (see :meth:`layer_coefficients`).
        """
        w = _check_weights(weights, self.n_lights)
        return np.einsum("nkc,nc->kc", self.loadings.astype(np.float64), w)

    def layer_coefficients(self, weights) -> np.ndarray:
        """Coefficients ``(K + 1, 3)`` float64 of the layers ``[M, E_1..E_K]``: ``P^T w``."""
        w = _check_weights(weights, self.n_lights)
        return np.concatenate([w.sum(0, keepdims=True), self.project_weights(w)], axis=0)

    def layers(self) -> np.ndarray:
        """The ``K + 1`` images ``[M, E_1..E_K]`` as ``(K + 1, H, W, 3)`` float32 (pass-2 basis)."""
        return np.concatenate([self.mean[None], self.components], axis=0).astype(np.float32, copy=False)

    def projection_matrix(self) -> np.ndarray:
        """``P`` ``(n, K + 1, 3)`` float32 with ``P[:, 0] = 1`` and ``P[:, 1:] = U``."""
        P = np.ones((self.n_lights, self.rank + 1, 3), dtype=np.float32)
        P[:, 1:] = self.loadings
        return P

    def relight(self, weights) -> np.ndarray:
        """Relit image ``(H, W, 3)`` float64 from the compressed basis (exact algebra, float64)."""
        c = self.layer_coefficients(weights)
        out = c[0] * self.mean.astype(np.float64)
        for k in range(self.rank):
            out += c[k + 1] * self.components[k].astype(np.float64)
        return out

    def reconstruct(self, i: int) -> np.ndarray:
        """Approximation ``(H, W, 3)`` float64 of basis image ``i``."""
        return self.mean.astype(np.float64) + np.einsum("kc,khwc->hwc", self.loadings[i].astype(np.float64),
                                                        self.components.astype(np.float64))


def _check_weights(weights, n) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n, 3):
        raise ValueError(f"weights must have shape ({n}, 3), not {w.shape}")
    return w


def randomized_svd_Halko2011(X: np.ndarray, rank: int, oversample: int = 10, power_iters: int = 2,
                             seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truncated SVD ``X ~= U diag(s) Vt`` by randomised subspace iteration (Halko et al. 2011).

    Parameters
    ----------
    X : (m, D) float32 array
        ``m`` small (lights), ``D`` large (pixels).
    rank : int
        K, 1 <= K <= m.
    oversample : int
        Extra sketch columns ``p`` (``l = K + p``, clipped to m).
    power_iters : int
        Subspace iterations ``q``; each re-orthonormalises (Algorithm 4.4).
    seed : int

    Returns
    -------
    U : (m, K) float64, orthonormal columns
    s : (K,) float64, non-increasing
    Vt : (K, D) float32, orthonormal rows
    """
    m, D = X.shape
    if not 1 <= rank <= m:
        raise ValueError(f"rank must be in [1, {m}], not {rank}")
    l = min(m, rank + oversample)
    rng = np.random.default_rng(seed)
    if l == m:  # the sketch spans everything: the exact range is the identity
        Q = np.eye(m)
    else:
        omega = rng.standard_normal((D, l), dtype=np.float32)
        Q, _ = np.linalg.qr((X @ omega).astype(np.float64))
        for _ in range(power_iters):
            Z, _ = np.linalg.qr((X.T @ Q.astype(np.float32)).astype(np.float64))
            Q, _ = np.linalg.qr((X @ Z.astype(np.float32)).astype(np.float64))
    Bm = Q.T.astype(np.float32) @ X  # (l, D)
    # SVD of the small (l, D) matrix through its (l, l) Gram matrix, in float64
    G = Bm.astype(np.float64) @ Bm.T.astype(np.float64)
    evals, evecs = np.linalg.eigh(G)
    order = np.argsort(evals)[::-1][:rank]
    s = np.sqrt(np.maximum(evals[order], 0.0))
    Ub = evecs[:, order]
    inv = np.divide(1.0, s, out=np.zeros_like(s), where=s > s.max(initial=0.0) * 1e-12)
    Vt = ((Ub * inv).T.astype(np.float32)) @ Bm
    return Q @ Ub, s, Vt


def compress_basis(basis, rank: int, seed: int = 0, mode: str = "per_channel", oversample: int = 10,
                   power_iters: int = 2) -> CompressedBasis:
    """Compress a basis to its mean and ``rank`` eigen-images (randomised PCA).

    Parameters
    ----------
    basis : (n, H, W, 3) float array
        Finite linear radiance.
    rank : int
        K, 1 <= K <= n - 1 (the mean takes one degree of freedom; K = n - 1 is exact).
    seed : int
        Seed of the random sketch (results are deterministic for a seed).
    mode : {'per_channel', 'shared'}
    oversample, power_iters : int
        See :func:`randomized_svd_Halko2011`.

    Returns
    -------
    CompressedBasis
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, not {mode!r}")
    b = np.asarray(basis)
    if b.ndim != 4 or b.shape[-1] != 3:
        raise ValueError(f"basis must be (n, H, W, 3), not {b.shape}")
    n, H, W, _ = b.shape
    lo, hi = rank_range(n)
    if not lo <= rank <= hi:
        raise ValueError(f"rank must be in [{lo}, {hi}] for {n} lights, not {rank}")
    if not np.all(np.isfinite(b)):
        raise ValueError("basis has NaN/Inf values")
    t0 = time.perf_counter()
    mean = b.mean(axis=0, dtype=np.float64).astype(np.float32)
    comps = np.empty((rank, H, W, 3), dtype=np.float32)
    loadings = np.empty((n, rank, 3), dtype=np.float32)
    svals = np.empty((rank, 3))
    if mode == "shared":
        X = b.reshape(n, -1).astype(np.float32) - mean.reshape(1, -1)
        U, s, Vt = randomized_svd_Halko2011(X, rank, oversample, power_iters, seed)
        comps[:] = (s[:, None].astype(np.float32) * Vt).reshape(rank, H, W, 3)
        loadings[:] = U[:, :, None]
        svals[:] = s[:, None]
    else:
        for c in range(3):
            X = b[..., c].reshape(n, -1).astype(np.float32) - mean[..., c].reshape(1, -1)
            U, s, Vt = randomized_svd_Halko2011(X, rank, oversample, power_iters, seed + c)
            comps[..., c] = (s[:, None].astype(np.float32) * Vt).reshape(rank, H, W)
            loadings[..., c] = U
            svals[:, c] = s
            del X
    info = {"seed": seed, "oversample": oversample, "power_iters": power_iters,
            "seconds": time.perf_counter() - t0, "n": n, "H": H, "W": W, "basis_sum": basis_checksum(b)}
    return CompressedBasis(mean, comps, loadings, svals, mode, info)


def basis_checksum(basis) -> float:
    """A cheap fingerprint of a basis (float64 sum of |x| weighted by the light index + 1).

    Stored in ``info['basis_sum']`` so that a saved compression of other images is not reused.
    """
    b = np.asarray(basis)
    return float(sum((i + 1) * np.abs(b[i], dtype=np.float64).sum() for i in range(b.shape[0])))


def save_compressed(cb: CompressedBasis, folder, filename: str = COMPRESSED_FILENAME) -> Path:
    """Write ``cb`` to ``folder/filename`` (.npz, atomically).

    Returns
    -------
    Path of the written file.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("capture folder does not exist", folder)
    path = folder / filename
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, version=np.int64(_FORMAT_VERSION), mean=cb.mean, components=cb.components,
                     loadings=cb.loadings, singular_values=cb.singular_values, mode=np.str_(cb.mode),
                     info_keys=np.array(list(cb.info.keys()), dtype=str),
                     info_values=np.array([float(v) for v in cb.info.values()]))
    return path


def load_compressed(folder_or_file, n_lights: int | None = None, shape: tuple[int, int] | None = None,
                    rank: int | None = None, basis=None) -> CompressedBasis:
    """Read a compressed basis written by :func:`save_compressed`.

    Parameters
    ----------
    folder_or_file : path-like
        A capture folder (reads :data:`COMPRESSED_FILENAME`) or the .npz itself.
    n_lights, shape : optional
        Checked against the file (a stale file of another capture is refused).
    rank : int, optional
        Keep only the first ``rank`` eigen-images (must be <= the stored rank).
    basis : (n, H, W, 3) array, optional
        The basis it should have been made from (checked with :func:`basis_checksum`).

    Raises
    ------
    InputError
        Missing, corrupt or inconsistent file.
    """
    p = Path(folder_or_file)
    path = p / COMPRESSED_FILENAME if p.is_dir() else p
    if not path.is_file():
        raise InputError("no compressed basis (run with --rank K to create one)", path)
    try:
        with np.load(path, allow_pickle=False) as z:
            if int(z["version"]) != _FORMAT_VERSION:
                raise InputError(f"compressed basis format {int(z['version'])}, expected {_FORMAT_VERSION}", path)
            cb = CompressedBasis(z["mean"], z["components"], z["loadings"], z["singular_values"], str(z["mode"]),
                                 dict(zip([str(k) for k in z["info_keys"]], [float(v) for v in z["info_values"]])))
    except InputError:
        raise
    except (OSError, KeyError, ValueError) as e:
        raise InputError(f"corrupt compressed basis: {e}", path) from None
    K = cb.rank
    if cb.components.shape[1:] != cb.mean.shape or cb.loadings.shape[1:] != (K, 3) or cb.mean.shape[-1:] != (3,):
        raise InputError("inconsistent array shapes in compressed basis", path)
    if n_lights is not None and cb.n_lights != n_lights:
        raise InputError(f"compressed basis has {cb.n_lights} lights, the capture {n_lights}", path)
    if shape is not None and tuple(cb.shape) != tuple(shape):
        raise InputError(f"compressed basis images are {cb.shape}, the capture's {tuple(shape)}", path)
    if basis is not None:
        want = basis_checksum(basis)
        if abs(cb.info.get("basis_sum", np.nan) - want) > 1e-6 * max(abs(want), 1e-30):
            raise InputError("compressed basis was made from other images (stale file)", path)
    if rank is not None:
        if rank > K:
            raise InputError(f"compressed basis has rank {K} < requested {rank}", path)
        cb = CompressedBasis(cb.mean, cb.components[:rank], cb.loadings[:, :rank], cb.singular_values[:rank],
                             cb.mode, cb.info)
    return cb


def load_or_compress(folder, basis, rank: int, save: bool = True) -> CompressedBasis:
    """The rank-``rank`` compression of ``basis``: the one saved in ``folder`` if it fits, else a new one.

    Parameters
    ----------
    folder : path-like
        Capture folder; its :data:`COMPRESSED_FILENAME` is used when it has at least ``rank``
        eigen-images and was made from the same images (:func:`basis_checksum`).
    basis : (n, H, W, 3) array
    rank : int
    save : bool
        Save a newly computed compression in ``folder``. Where that fails (a read-only capture)
        the compression is used from memory and its ``note`` says so and why.

    Returns
    -------
    CompressedBasis
    """
    basis = np.asarray(basis)
    try:
        return load_compressed(folder, n_lights=basis.shape[0], shape=basis.shape[1:3], rank=int(rank), basis=basis)
    except InputError:
        cb = compress_basis(basis, int(rank))
    if save:
        try:
            save_compressed(cb, folder)
        except (OSError, InputError) as e:
            why = e.message if isinstance(e, FflsError) else os_error_message(e)
            cb.note = (f"the compressed basis (rank {cb.rank}) was computed in memory and not kept in {folder} "
                       f"({why}): it is computed again on every run")
    return cb
