"""Radiance from photographs: camera response recovery, HDR merging and valid-pixel masks.

Papers
------
Debevec, P. E. and Malik, J. (1997). Recovering high dynamic range radiance maps from
photographs. SIGGRAPH 97. Implemented by OpenCV's ``CalibrateDebevec`` / ``MergeDebevec``.

The *inverse response* (``curve``) is a (256, 3) float32 table: the linear exposure
``E * dt`` (relative units) that produces each 8-bit code, per channel, in the channel order of
the images given (RGB in ffls). It is the table that :mod:`ffls.io.capture` reads for
``"encoding": {"response": "response.npy"}`` (``.npy`` or ``.csv``, 256 rows of 3 numbers).
"""
from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from ffls.errors import InputError, not_a_regular_file
from ffls.io.capture import parse_json, read_json_text
from ffls.io.images import check_one_orientation, check_opaque, image_header, read_image
from ffls.io.probe import exposure_time_problem
from ffls.io.response import save_response

__all__ = [
    "recover_response_DebevecMalik1997",
    "exif_exposure_time",
    "recover_response",
    "merge_hdr",
    "linearize",
    "valid_pixel_mask",
    "read_bracket",
    "grid_samples_fit",
    "bracket_problem",
    "max_grid_samples",
    "calibrate_response_folder",
]

_IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff")


def _check_stack(images, exposure_times):
    imgs = [np.asarray(im) for im in images]
    t = np.asarray(exposure_times, dtype=np.float32).ravel()
    if len(imgs) < 2:
        raise ValueError("need at least two bracketed images")
    if len(imgs) != t.size:
        raise ValueError(f"{len(imgs)} images but {t.size} exposure times")
    if not np.all(np.isfinite(t)) or np.any(t <= 0):
        raise ValueError("exposure times must be positive")
    for im in imgs:
        if im.dtype != np.uint8 or im.ndim != 3 or im.shape[2] != 3:
            raise ValueError(f"images must be uint8 (H, W, 3), got {im.dtype} {im.shape}")
        if im.shape != imgs[0].shape:
            raise ValueError(f"image shapes differ: {im.shape} vs {imgs[0].shape}")
    return [np.ascontiguousarray(im) for im in imgs], t


def recover_response_DebevecMalik1997(images, exposure_times, samples: int = 70, smoothness: float = 10.0,
                                      random: bool = False) -> np.ndarray:
    """Inverse camera response from a bracketed stack (Debevec and Malik 1997).

    Parameters
    ----------
    images : list of (H, W, 3) uint8
        The same static scene at different exposure times (any channel order; the curve keeps it).
    exposure_times : (n,) float
        Seconds (or any unit: only ratios matter).
    samples : int
        Pixel locations sampled by OpenCV.
    smoothness : float
        The smoothness weight ``lambda``.
    random : bool
        Random pixel samples (else a regular grid).

    Returns
    -------
    (256, 3) float32
        Linear relative exposure per code, per channel; non-decreasing.
    """
    imgs, t = _check_stack(images, exposure_times)
    cal = cv2.createCalibrateDebevec(samples=int(samples), lambda_=float(smoothness), random=bool(random))
    curve = cal.process(imgs, t).reshape(256, 3).astype(np.float32)
    # The least-squares solution can wobble at the extreme codes where few samples land.
    return np.maximum.accumulate(curve, axis=0)


#: Public entry point; ``method`` chooses among algorithms (only Debevec-Malik for now).
def recover_response(images, exposure_times, method: str = "DebevecMalik1997", **kwargs) -> np.ndarray:
    """Inverse camera response; see :func:`recover_response_DebevecMalik1997`."""
    if method != "DebevecMalik1997":
        raise ValueError(f"unknown response method {method!r}")
    return recover_response_DebevecMalik1997(images, exposure_times, **kwargs)


def merge_hdr(images, exposure_times, curve) -> np.ndarray:
    """Merge a bracketed stack into linear radiance (Debevec and Malik 1997, OpenCV MergeDebevec).

    Parameters
    ----------
    images : list of (H, W, 3) uint8
    exposure_times : (n,) float
    curve : (256, 3) float
        Inverse response, as from :func:`recover_response_DebevecMalik1997`.

    Returns
    -------
    (H, W, 3) float32
        Radiance in the curve's units per second (relative).
    """
    imgs, t = _check_stack(images, exposure_times)
    c = np.asarray(curve, dtype=np.float32)
    if c.shape != (256, 3):
        raise ValueError(f"curve must be (256, 3), got {c.shape}")
    return cv2.createMergeDebevec().process(imgs, t, c.reshape(256, 1, 3).copy())


def linearize(image_uint8, curve) -> np.ndarray:
    """Linear values of an 8-bit image through an inverse response table.

    Parameters
    ----------
    image_uint8 : (H, W, 3) uint8
    curve : (256, 3) float

    Returns
    -------
    (H, W, 3) float32
    """
    im = np.asarray(image_uint8)
    if im.dtype != np.uint8 or im.ndim != 3 or im.shape[2] != 3:
        raise ValueError(f"expected a uint8 (H, W, 3) image, got {im.dtype} {im.shape}")
    c = np.asarray(curve, dtype=np.float32)
    if c.shape != (256, 3):
        raise ValueError(f"curve must be (256, 3), got {c.shape}")
    return np.stack([c[im[..., k], k] for k in range(3)], axis=-1)


def valid_pixel_mask(raw, bit_depth, low: float = 0.02, high: float = 0.98) -> np.ndarray:
    """Pixels whose values are usable as photometric data: neither saturated nor near black.

    Parameters
    ----------
    raw : (H, W, 3) array
        The image as stored: integer codes, or floats normalised to [0, 1] for integer formats
        (``ImageData.pixels``), or linear floats for half/float images.
    bit_depth : {8, 16, 'half', 'float'}
        The stored bit depth (``ImageData.bit_depth``).
    low, high : float
        Fractions of full scale. A pixel is *saturated* if any channel is at or above ``high``
        (one clipped channel corrupts the others' ratios) and *near black* if every channel is at
        or below ``low``. For float images (no top code) only ``low`` applies, as an absolute
        value, and non-finite or negative pixels are invalid.

    Returns
    -------
    (H, W) bool
        True where the pixel may be used.
    """
    x = np.asarray(raw)
    if x.ndim != 3:
        raise ValueError(f"expected (H, W, c), got {x.shape}")
    if bit_depth in (8, 16):
        top = 255.0 if bit_depth == 8 else 65535.0
        v = x.astype(np.float64) / top if np.issubdtype(x.dtype, np.integer) else x.astype(np.float64)
        finite = np.all(np.isfinite(v), axis=-1)
        return finite & ~np.any(v >= high, axis=-1) & ~np.all(v <= low, axis=-1)
    if bit_depth in ("half", "float"):
        v = x.astype(np.float64)
        finite = np.all(np.isfinite(v), axis=-1) & np.all(v >= 0, axis=-1)
        return finite & ~np.all(np.where(np.isfinite(v), v, 0) <= low, axis=-1)
    raise ValueError(f"bit_depth must be 8, 16, 'half' or 'float', not {bit_depth!r}")


# ----------------------------------------------------------------------------- bracket folders
def exif_exposure_time(path: Path):
    """The EXIF ``ExposureTime`` (tag 33434, seconds) of an image read with Pillow: a float (NaN
    when the tag is there but not a number, e.g. ``1/0``), or None when absent."""
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover
        return None
    try:
        with Image.open(path) as im:
            exif = im.getexif()
            t = exif.get_ifd(0x8769).get(33434) or exif.get(33434)  # ExposureTime
    except (OSError, ValueError):
        return None
    try:
        return float(t) if t is not None else None
    except (TypeError, ValueError, ZeroDivisionError):
        return float("nan")


def read_bracket(folder: str | os.PathLike):
    """Read a folder of bracketed 8-bit photos and their exposure times.

    Exposure times come from ``exposures.json`` in the folder when present (an object mapping
    file name to seconds, e.g. ``{"a.jpg": 0.01, "b.jpg": 0.04}``, naming every photo of the
    folder: one left out is refused, not skipped), otherwise from each image's EXIF ``ExposureTime`` (tag 33434, read with Pillow).

    Returns
    -------
    images : list of (H, W, 3) uint8, RGB
    times : (n,) float32
    paths : list of Path
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("not a folder", folder)
    jpath = folder / "exposures.json"
    photos = sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)  # (the folder, listed once)
    for p in [jpath] + photos:
        special = not_a_regular_file(p)  # (a FIFO's EXIF or JSON was waited for forever)
        if special:
            raise InputError(special, p)
    if jpath.is_file():
        try:
            doc = parse_json(read_json_text(jpath, "exposures.json"))
        except (OSError, ValueError) as e:  # (a UnicodeDecodeError is a ValueError)
            raise InputError(f"cannot read exposures ({e})", jpath) from None
        if not isinstance(doc, dict) or not doc:
            raise InputError('expected an object {"file name": seconds, ...}', jpath)
        paths, times = [], []
        for name, t in sorted(doc.items()):
            p = folder / name
            if not p.is_file():
                raise InputError(f"image {name!r} listed in exposures.json not found", p)
            why = exposure_time_problem(t)
            if why:
                raise InputError(f"exposure of {name!r}: {why}", jpath)
            t = float(t)
            paths.append(p)
            times.append(t)
        unlisted = [p.name for p in photos if p.name not in doc]
        if unlisted:
            raise InputError(f"photo {unlisted[0]!r} has no exposure time in exposures.json (list every photo of the"
                             " bracket, or move the others out)", folder / unlisted[0])
    else:
        paths = photos
        times = []
        for p in paths:
            t = exif_exposure_time(p)
            if t is None:
                raise InputError("no EXIF ExposureTime (add exposures.json to the folder)", p)
            why = exposure_time_problem(t)
            if why:
                raise InputError(f"EXIF ExposureTime: {why} (add exposures.json to the folder)", p)
            times.append(t)
    if len(paths) < 2:
        raise InputError(f"need at least two bracketed images, found {len(paths)}", folder)
    heads = [image_header(p) for p in paths]
    check_one_orientation(paths, heads=heads, what="bracketed photos")
    images = []
    for p, header in zip(paths, heads):
        data = read_image(p, working_space=False)  # (its one line: not found, a folder, truncated, ...)
        check_opaque(data, "export the bracket without alpha", p)
        if data.bit_depth != 8 or (header is not None and header.grey):
            depth = {"half": "half-float", "float": "32-bit float"}.get(data.bit_depth, f"{data.bit_depth}-bit")
            raise InputError(f"bracketed images must be 8-bit RGB, got a {depth} "
                             f"{'grey' if header is not None and header.grey else 'RGB'} image", p)
        im = data.codes
        if images and im.shape != images[0].shape:
            raise InputError(f"image size {im.shape[1]}x{im.shape[0]} differs from"
                             f" {images[0].shape[1]}x{images[0].shape[0]} of {paths[0].name}", p)
        images.append(im)
    return images, np.asarray(times, dtype=np.float32), paths


def bracket_problem(images) -> str | None:
    """Why a bracket of 8-bit photos cannot calibrate a response, or None.

    The Debevec-Malik solve links codes through the change of a pixel's code with the exposure:

    * with every code at 0 or 255 (black or saturated everywhere) no sample lies on the curve and
      the solve returns a flat table (every code -> 1.0);
    * photos that are identical although their exposure times differ (the same file copied, or a
      camera that ignored the exposure setting) contradict the model; the solve returns NaN or
      negative values.

    Parameters
    ----------
    images : list of (H, W, 3) uint8
    """
    imgs = [np.asarray(im) for im in images]
    if not any(np.any((im > 0) & (im < 255)) for im in imgs):
        return ("every pixel of every photo is black (0) or saturated (255): nothing between them to calibrate a "
                "response from")
    if all(np.array_equal(im, imgs[0]) for im in imgs[1:]):
        return (f"the {len(imgs)} photos are identical although their exposure times differ: photos that do not "
                "change with the exposure cannot calibrate a response")
    return None


def grid_samples_fit(samples: int, width: int, height: int) -> bool:
    """Whether OpenCV's ``CalibrateDebevec`` (``random=False``) can place ``samples`` on a
    ``width`` x ``height`` image.

    Its grid has ``x = floor(sqrt(samples * width / height))`` columns and ``samples // x`` rows,
    and asserts ``0 < x <= width`` and ``0 < rows <= height`` (``cv2.error ... x_points <= cols``).
    """
    w, h, n = int(width), int(height), int(samples)
    x = int(np.sqrt(n * w / h))
    return 0 < x <= w and 0 < n // x <= h


def max_grid_samples(width: int, height: int) -> int:
    """The largest ``n`` such that every sample count up to ``n`` fits (:func:`grid_samples_fit`)."""
    n = 0
    while grid_samples_fit(n + 1, width, height):
        n += 1
    return n


def calibrate_response_folder(folder, output, samples: int = 70, smoothness: float = 10.0) -> np.ndarray:
    """Recover the inverse response from a bracket folder and save it; returns the (256, 3) curve."""
    images, times, _ = read_bracket(folder)
    h, w = images[0].shape[:2]
    if not grid_samples_fit(samples, w, h):
        raise InputError(f"--samples {samples} is more than the {w}x{h} photos can give"
                         f" (at most {max_grid_samples(w, h)})", folder)
    if len(set(np.round(times, 9).tolist())) < 2:
        raise InputError("all exposure times are equal: not a bracket", folder)
    why = bracket_problem(images)
    if why:
        raise InputError(why, folder)
    curve = recover_response_DebevecMalik1997(images, times, samples=samples, smoothness=smoothness)
    save_response(output, curve)
    return curve
