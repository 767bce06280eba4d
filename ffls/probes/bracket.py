"""Exposure brackets merged into one radiance image (Robertson et al. 2003), and a probe view's radiance.

Debevec, P. E. and Malik, J., "Recovering High Dynamic Range Radiance Maps from Photographs",
SIGGRAPH 1997, equation 6: the radiance of a pixel is the weighted mean over the exposures of
``g(Z_ij) - ln t_j`` with a hat weight ``w(z)`` that falls to zero at both ends of the range. Here
the mean is taken on linear values, ``E = sum_j w_j x_j / t_j / sum_j w_j``, where ``x_j`` is the
stored value decoded with the stated (or calibrated) encoding: sRGB, a gamma, linear, or an
inverse response table (:func:`ffls.radiance.response.recover_response_DebevecMalik1997`).
The default merge (:func:`merge_exposures_Robertson2003`, used by ``ffls probe merge`` and
bracketed probe views) also weighs each exposure by ``t_j^2``, the inverse variance of
``x_j / t_j`` under noise of a fixed size in the stored values (Robertson, Borman and Stevenson
2003): the hat weight alone lets a short exposure's noisy dark pixels set the dark parts.

Unlike OpenCV's ``MergeDebevec`` (8-bit input only, and a triangle weight that never reaches
zero inside the range), the input may be 8- or 16-bit integers or floats, and the weight is
exactly zero at and beyond the clipping limits:

* **top**: a pixel is clipped in an exposure when its largest channel reaches
  ``saturation`` (0.99) of the clipping level: the top code for integer files; for float files
  a plateau of pixels at the image's maximum (:func:`float_clip_level`), none when there is no
  plateau (a float image from a raw converter may clip, an HDR render does not);
* **bottom**: each channel's weight rises linearly from 0 at black to 1 at half the range
  (integer data), so quantisation and noise near black count for little; float data without a
  clipping level count fully above zero.

The top weight is shared by the channels (one clipped channel corrupts the colour of a
processed photo), the bottom one is per channel (a saturated colour has a legitimately dark
channel). A pixel clipped in every exposure is flagged (``saturated``) and takes the shortest
exposure's value, a lower bound; one dark in every exposure takes the longest exposure's.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffls.errors import InputError
from ffls.io.images import (ImageData, check_one_bit_depth, check_one_colour_kind, check_one_orientation, check_opaque,
                            image_header, read_image)
from ffls.radiance.photos import linearise

__all__ = ["SATURATION", "JSON_ENCODING_FORMS", "BracketMerge", "ViewRadiance", "hat_weights", "float_clip_level",
           "merge_exposures_DebevecMalik1997", "merge_exposures_Robertson2003", "MERGE_METHODS",
           "merge_exposures", "check_encoding", "decode_image",
           "merge_bracket_files", "view_radiance", "exposure_from_exif"]

#: Fraction of the clipping level at and above which a stored value counts as clipped.
SATURATION = 0.99


@dataclass
class BracketMerge:
    """A merged bracket.

    Attributes
    ----------
    radiance : (H, W, 3) float32
        Linear radiance in units of (decoded value) per second of exposure.
    saturated : (H, W) bool
        Clipped in every exposure (the value is a lower bound).
    dark : (H, W) bool
        Black (zero weight) in every exposure without being clipped.
    weight : (H, W) float32
        Sum of the weights (0 where the value is a fallback).
    exposures : (n,) float64
    """

    radiance: np.ndarray
    saturated: np.ndarray
    dark: np.ndarray
    weight: np.ndarray
    exposures: np.ndarray

    def describe(self) -> str:
        """One line: exposures, flagged pixels."""
        n = self.saturated.size
        t = ", ".join(f"{x:.4g}" for x in self.exposures)
        k = int(self.saturated.sum())
        # a sun clipped in every exposure can hold most of a scene's light: its value is only a bound
        bound = (" (their radiance is only a lower bound, and a light map misses the rest of their light: "
                 f"add an exposure shorter than {self.exposures.min():.4g} s, or an ND filter)") if k else ""
        return (f"{len(self.exposures)} exposures ({t} s); {k} pixel{'' if k == 1 else 's'} "
                f"({100 * k / n:.2f}%) saturated in every exposure{bound}, "
                f"{int(self.dark.sum())} ({100 * self.dark.sum() / n:.2f}%) black in every exposure")


def hat_weights(stored, clip=1.0, saturation: float = SATURATION) -> np.ndarray:
    """Per-channel hat weights of one exposure: zero at black and at the clipping level.

    Parameters
    ----------
    stored : (H, W, 3) float
        Stored values (integer files scaled to [0, 1], float files as they are).
    clip : float or None
        The clipping level (1 for integer files); None: the data do not clip (no top limit,
        and no bottom ramp: float data carry no quantisation floor).
    saturation : float
        The weight is zero where the pixel's largest channel reaches ``saturation * clip``.

    Returns
    -------
    (H, W, 3) float64
        In [0, 1].
    """
    z = np.asarray(stored, dtype=np.float64)
    finite = np.isfinite(z)
    z = np.where(finite, z, 0.0)
    if clip is None:
        return np.where(finite & (z > 0), 1.0, 0.0)
    z = z / float(clip)
    top = np.clip((saturation - z.max(axis=-1)) / (saturation - 0.5), 0.0, 1.0)[..., None]
    bottom = np.clip(z / 0.5, 0.0, 1.0)
    return np.where(finite, top * bottom, 0.0)


def float_clip_level(stored, min_fraction: float = 1e-4, min_count: int = 4) -> float | None:
    """The clipping level of a float image: its maximum, when a plateau of pixels sits there.

    A float image made from a raw file clips at the sensor's white level: a plateau of pixels
    whose largest channel equals the image maximum (to 1e-6 relative). A render or a merged HDR
    has no such plateau.

    Parameters
    ----------
    stored : (H, W, 3) float
    min_fraction, min_count : float, int
        A plateau needs at least ``max(min_count, min_fraction * H * W)`` pixels.

    Returns
    -------
    float or None
        The level, or None when the image does not clip.
    """
    m = np.max(np.asarray(stored, dtype=np.float64), axis=-1)
    top = float(m.max()) if m.size else 0.0
    if not top > 0:
        return None
    n = int(np.count_nonzero(m >= top * (1 - 1e-6)))
    return top if n >= max(min_count, min_fraction * m.size) else None


def merge_exposures_DebevecMalik1997(linear, stored, exposures, clip_levels, saturation: float = SATURATION
                                     ) -> BracketMerge:
    """Merge an exposure bracket: the hat-weighted mean of ``linear / t`` (Debevec and Malik 1997, eq. 6).

    Parameters
    ----------
    linear : (n, H, W, 3) float
        Each exposure decoded to linear values.
    stored : (n, H, W, 3) float
        The same exposures as stored (integer files scaled to [0, 1]), for the weights.
    exposures : (n,) float
        Exposure times, seconds (any consistent unit); positive, not all equal.
    clip_levels : sequence of (float or None)
        Per exposure: 1 for integer files, :func:`float_clip_level` for float files.
    saturation : float
        See :func:`hat_weights`.

    Returns
    -------
    BracketMerge

    Raises
    ------
    ValueError
        Shapes that differ, fewer than two exposures, a non-positive time, or all times equal.
    """
    return _weighted_merge(linear, stored, exposures, clip_levels, saturation, time_power=0)


def merge_exposures_Robertson2003(linear, stored, exposures, clip_levels, saturation: float = SATURATION
                                  ) -> BracketMerge:
    """Merge an exposure bracket: the mean of ``linear / t`` weighted by ``w(z) t^2`` (Robertson et al. 2003).

    Robertson, M. A., Borman, S. and Stevenson, R. L., "Estimation-theoretic approach to dynamic
    range enhancement using multiple exposures", Journal of Electronic Imaging 12(2), 2003:
    ``E = sum_j w_j t_j x_j / sum_j w_j t_j^2``. Noise of a fixed size in the stored
    values (read noise, quantisation, JPEG) becomes ``1 / t`` times larger in ``x / t``, so each
    exposure counts with its inverse variance ``t^2`` on top of the hat weight. The hat-weighted
    mean of Debevec and Malik (:func:`merge_exposures_DebevecMalik1997`) lets the shortest
    exposures' dark, noisy pixels (noise clipped at zero: biased upward) dominate the dark
    parts of the scene. Same parameters, clipping and flags as that function.
    """
    return _weighted_merge(linear, stored, exposures, clip_levels, saturation, time_power=2)


def _weighted_merge(linear, stored, exposures, clip_levels, saturation, time_power) -> BracketMerge:
    """The mean of ``linear / t`` weighted by ``hat_weights * t ** time_power``, with the flags."""
    t = np.asarray(exposures, dtype=np.float64).ravel()
    n = len(t)
    if n < 2:
        raise ValueError("a bracket needs at least two exposures")
    if not np.all(np.isfinite(t) & (t > 0)):
        raise ValueError(f"exposure times must be positive, got {t.tolist()}")
    if np.ptp(t) <= 1e-9 * t.max():
        raise ValueError(f"all {n} exposure times are equal ({t[0]:.6g} s): not a bracket")
    shape = np.shape(linear[0])
    if len(linear) != n or len(stored) != n or len(clip_levels) != n \
            or any(np.shape(a) != shape for a in list(linear) + list(stored)):
        raise ValueError("linear, stored, exposures and clip_levels must describe the same images of one size")
    num = np.zeros(shape, dtype=np.float64)
    den = np.zeros(shape, dtype=np.float64)
    clipped_all = np.ones(shape[:2], dtype=bool)
    for x, z, tj, c in zip(linear, stored, t, clip_levels):
        w = hat_weights(z, c, saturation) * (tj / t.max()) ** time_power
        num += w * np.asarray(x, dtype=np.float64) / tj
        den += w
        zz = np.where(np.isfinite(z), z, np.inf)
        clipped_all &= (np.max(zz, axis=-1) >= saturation * c) if c is not None else False
    order = np.argsort(t)
    shortest = np.asarray(linear[order[0]], dtype=np.float64) / t[order[0]]
    longest = np.asarray(linear[order[-1]], dtype=np.float64) / t[order[-1]]
    none = den <= 0
    out = np.where(none, np.where(clipped_all[..., None], shortest, longest), num / np.where(none, 1.0, den))
    dark = np.all(none, axis=-1) & ~clipped_all
    return BracketMerge(np.nan_to_num(out, nan=0.0, posinf=0.0).astype(np.float32), clipped_all, dark,
                        den.sum(axis=-1).astype(np.float32), t)


MERGE_METHODS = {"Robertson2003": merge_exposures_Robertson2003,
                 "DebevecMalik1997": merge_exposures_DebevecMalik1997}


def merge_exposures(linear, stored, exposures, clip_levels, method: str = "Robertson2003", **kwargs
                    ) -> BracketMerge:
    """Merge an exposure bracket; ``method`` is a key of :data:`MERGE_METHODS` (default ``'Robertson2003'``)."""
    if method not in MERGE_METHODS:
        raise ValueError(f"unknown merge method {method!r} (known: {', '.join(map(repr, MERGE_METHODS))})")
    return MERGE_METHODS[method](linear, stored, exposures, clip_levels, **kwargs)


# ----------------------------------------------------------------------------- files
#: How ``probe.json``'s ``encoding`` key states an encoding (the forms named when it is missing).
JSON_ENCODING_FORMS = '"srgb", "linear", {"gamma": g} or {"response": "file.npy"}'


def check_encoding(img: ImageData, encoding, source, key: str = "encoding", forms: str = JSON_ENCODING_FORMS
                   ) -> None:
    """Refuse an encoding that does not apply to ``img``, naming ``source`` (the file that states it) and ``key``.

    ``'auto'`` (not stated) with an integer image is refused: ffls never guesses whether an
    8- or 16-bit image is sRGB, gamma or linear. ``forms`` lists how ``key`` states one (the
    JSON values of ``probe.json``, or a command-line flag's values).
    """
    if encoding == "auto":
        if not img.is_hdr:
            article = "an" if img.bit_depth == 8 else "a"
            raise InputError(f"{key}: not stated, and {img.path.name} is {article} {img.bit_depth}-bit image that "
                             f"could be sRGB, gamma or linear; ffls does not guess: state it ({forms})", source)
        return
    if img.is_hdr and encoding != "linear":
        raise InputError(f"{key}: {encoding!r} applies to integer images, but {img.path.name} is floating point "
                         f"(linear by definition)", source)
    if isinstance(encoding, dict) and "response" in encoding and img.bit_depth != 8:
        raise InputError(f"{key}: an inverse response table applies to 8-bit images, {img.path.name} is "
                         f"{img.bit_depth}-bit", source)


def decode_image(img: ImageData, encoding, response=None) -> tuple[np.ndarray, float | None]:
    """Linear values of an image and its clipping level (1 for integer data, :func:`float_clip_level` for float).

    Call :func:`check_encoding` first.
    """
    lin = linearise(img, encoding if encoding != "auto" else "linear", response)
    clip = float_clip_level(img.pixels) if img.is_hdr else 1.0
    return np.asarray(lin, dtype=np.float32), clip


def _read_all(paths) -> list[ImageData]:
    heads = [image_header(p) for p in paths]
    check_one_orientation(paths, heads=heads, what="bracketed images")
    check_one_colour_kind(paths, heads=heads, what="bracketed images", whole="a bracket")
    check_one_bit_depth(paths, heads=heads, what="bracketed images", whole="a bracket")
    imgs = [read_image(p) for p in paths]
    for im in imgs:
        check_opaque(im, "export the bracket without alpha")
    for im in imgs[1:]:
        if im.shape != imgs[0].shape:
            raise InputError(f"image size {im.shape[1]}x{im.shape[0]} differs from {imgs[0].shape[1]}x"
                             f"{imgs[0].shape[0]} of {imgs[0].path.name} (a bracket needs one size)", im.path)
    return imgs


def merge_bracket_files(paths, exposures, encoding, response=None, source=None, key: str = "encoding",
                        forms: str = JSON_ENCODING_FORMS) -> BracketMerge:
    """Read a bracket of image files and merge it (:func:`merge_exposures_Robertson2003`).

    Parameters
    ----------
    paths : sequence of path-like
        Two or more images of one size (8-, 16-bit or float; they may differ).
    exposures : sequence of float
        Exposure times, seconds, one per image.
    encoding : str or dict
        ``'srgb'``, ``'linear'``, ``{'gamma': g}``, ``{'response': name}`` or ``'auto'`` (float files only).
    response : (256, 3) float, optional
        The table of ``{'response': ...}``.
    source : path-like, optional
        The file or flag named in errors about the encoding or the exposures (default: the first image).
    key, forms : str
        The key or flag that states the encoding, and how it states one, for messages.

    Returns
    -------
    BracketMerge

    Raises
    ------
    InputError
        An unreadable image, sizes that differ, an encoding that does not apply (or none stated
        for integer images), all exposure times equal, a bracket black or clipped everywhere.
    """
    paths = [Path(p) for p in paths]
    source = paths[0] if source is None else source
    imgs = _read_all(paths)
    lin, clips = [], []
    for im in imgs:
        check_encoding(im, encoding, source, key, forms)
        x, c = decode_image(im, encoding, response)
        lin.append(x)
        clips.append(c)
    t = np.asarray(exposures, dtype=np.float64)
    if len(t) != len(paths):
        raise InputError(f"{len(paths)} images but {len(t)} exposure times", source)
    try:
        m = merge_exposures_Robertson2003(lin, [im.pixels for im in imgs], t, clips)
    except ValueError as e:
        raise InputError(str(e), source) from None
    # a bracket black, or clipped, in every exposure holds no radiance (`probe merge` wrote it)
    _check_recorded(m.radiance, m.saturated, np.all(np.isfinite(m.radiance), axis=-1),
                    f"the bracket {paths[0].name}..{paths[-1].name}", paths[0])
    return m


@dataclass
class ViewRadiance:
    """The linear radiance of one probe view (a single image or a merged bracket).

    Attributes
    ----------
    radiance : (H, W, 3) float32
    saturated : (H, W) bool
        Clipped (in every exposure of a bracket): the value is a lower bound.
    valid : (H, W) bool
        Usable pixels: finite, and not transparent where the file has an alpha channel (a
        merged bracket written by ``ffls probe merge`` marks its saturated pixels with alpha 0).
    note : str
        One line on what was read (and merged).
    """

    radiance: np.ndarray
    saturated: np.ndarray
    valid: np.ndarray
    note: str


def view_radiance(view, encoding, response=None, source=None) -> ViewRadiance:
    """Read one view of a probe (:class:`ffls.io.probe.ProbeView`) as linear radiance.

    Parameters
    ----------
    view : ffls.io.probe.ProbeView
    encoding, response
        The probe's (:class:`ffls.io.probe.Probe`).
    source : path-like
        ``probe.json``, named in errors about the encoding.

    Returns
    -------
    ViewRadiance

    Raises
    ------
    InputError
        An unreadable image, an encoding that does not apply, an all-black image (or bracket),
        or one saturated everywhere.
    """
    paths = [im.path for im in view.images]
    if view.is_bracket:
        m = merge_bracket_files(paths, [im.exposure_s for im in view.images], encoding, response, source)
        rad, sat, note = m.radiance, m.saturated, "bracket: " + m.describe()
        alpha = None
    else:
        img = read_image(paths[0])
        check_encoding(img, encoding, source)
        rad, clip = decode_image(img, encoding, response)
        z = np.max(img.pixels, axis=-1)
        sat = (z >= SATURATION * clip) if clip is not None else np.zeros(z.shape, dtype=bool)
        alpha = img.alpha
        depth = {"half": "half float", "float": "32-bit float"}.get(img.bit_depth, f"{img.bit_depth}-bit")
        on = np.all(np.isfinite(img.pixels), axis=-1) & (alpha > 0 if alpha is not None else True)
        whole = img.is_hdr and clip is not None and bool(sat[on].all())
        if whole:  # no pixel under the plateau: nothing measures a clip level (a float has no white level)
            sat = np.zeros(z.shape, dtype=bool)
        note = f"{paths[0].name}: {depth}"
        if whole:
            note += (f", one value everywhere (largest channel {clip:.6g} in every pixel): read as it is, a "
                     f"uniform light (a float file states no clip level; an over-exposed one needs a shorter "
                     f"exposure)")
        elif sat.any() and not img.is_hdr:
            note += f", {int(sat.sum())} pixels clipped"
        elif sat.any():
            note += (f", {int(sat.sum())} pixels on a plateau at its maximum ({clip:.6g}), taken as clipped "
                     f"(lower bounds; a render's flat brightest region reads the same)")
    valid = np.all(np.isfinite(rad), axis=-1)
    if alpha is not None:
        valid &= alpha > 0
    if not view.is_bracket:  # (merge_bracket_files checked a bracket's merged radiance)
        _check_recorded(rad, sat, valid, paths[0].name, paths[0])
    return ViewRadiance(np.where(valid[..., None], rad, 0.0).astype(np.float32), sat, valid, note)


def _check_recorded(rad, sat, valid, what: str, path) -> None:
    """InputError naming ``path`` where the ``valid`` pixels of ``rad`` recorded no light, or where
    (nearly) all of them are clipped (``sat``): an image or merged bracket that holds no radiance."""
    if not np.any(rad[valid] > 0):
        raise InputError(f"{what} is black everywhere (no light recorded): check the exposure", path)
    if sat[valid].mean() > 0.999 if valid.any() else False:
        raise InputError(f"{what} is saturated everywhere (every pixel clipped): use a shorter exposure or a "
                         f"bracket", path)


def exposure_from_exif(path: str | os.PathLike) -> float:
    """The EXIF ``ExposureTime`` of an image (seconds); InputError naming the file when it has none,
    or one that is not an exposure time (:func:`ffls.io.probe.exposure_time_problem`)."""
    from ffls.io.probe import exposure_time_problem
    from ffls.radiance.response import exif_exposure_time

    t = exif_exposure_time(Path(path))
    if t is None:
        raise InputError("no EXIF ExposureTime: give the exposure times (--exposures t1,t2,...)", path)
    why = exposure_time_problem(t)
    if why:
        raise InputError(f"EXIF ExposureTime: {why}: give the exposure times (--exposures t1,t2,...)", path)
    return float(t)
