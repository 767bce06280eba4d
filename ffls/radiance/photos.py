"""The photos of a capture as linear radiance.

A capture's ``encoding`` (see :mod:`ffls.io.capture`) says how stored pixel values map to
radiance: ``'srgb'`` (IEC 61966-2-1), ``'linear'``, ``{'gamma': g}`` (a power law), an inverse
response table for 8-bit codes, or ``'auto'`` when ``capture.json`` states none.

ffls never guesses an encoding. With ``'auto'``, floating-point images (EXR, HDR) are linear by
definition; integer images (8- or 16-bit PNG, TIFF, JPEG) have an *unknown* encoding and
:func:`linearise` refuses them with one line: state ``"encoding"`` in ``capture.json``, or run
``ffls lights``, which calibrates it from the spheres (:mod:`ffls.spheres.encoding`) and records
it in ``lights.json``, where the other commands find it
(:func:`ffls.io.capture.load_capture_and_lights`).
"""
from __future__ import annotations

import functools
import os
import sys
from dataclasses import dataclass

import numpy as np

from ffls.errors import InputError
from ffls.io.capture import CAPTURE_FILE
from ffls.io.images import ImageData, check_opaque, read_image
from ffls.radiance.encoding import gamma_decode, srgb_decode

__all__ = ["Photo", "linearise", "encoding_unknown", "unknown_encoding_message", "read_photo", "load_photo",
           "load_photos", "full_scale_share"]


@dataclass(frozen=True)
class Photo:
    """One photo of a capture, read and linearised.

    Attributes
    ----------
    linear : (H, W, 3) float32 ndarray
        Linear radiance.
    raw : (H, W, 3) float32 ndarray
        The stored values scaled to [0, 1] (for saturation and validity masks).
    bit_depth : {8, 16, 'half', 'float'}
    codes : (H, W, 3) uint8 or uint16 ndarray or None
        An integer file's stored codes (``raw`` is ``codes / 255`` or ``codes / 65535``); None
        for floating-point files.
    """

    linear: np.ndarray
    raw: np.ndarray
    bit_depth: int | str
    codes: np.ndarray | None = None


def full_scale_share(photo: Photo) -> float | None:
    """The share of ``photo``'s pixels stored at full scale (the top code in any channel): how much
    of an integer file the camera clipped; None for a floating-point file, which does not clip."""
    if photo.bit_depth not in (8, 16):
        return None
    a = photo.codes if photo.codes is not None else photo.raw
    at_top = a >= (np.iinfo(a.dtype).max if photo.codes is not None else 1.0)  # (whole-array: fast)
    pixels = at_top.shape[0] * at_top.shape[1]
    if at_top.ndim == 2 or not at_top.any():
        return float(np.count_nonzero(at_top)) / pixels
    e = at_top.reshape(pixels, -1)  # any channel (column ors: 20x a reduction over the last axis)
    return float(np.count_nonzero(np.logical_or.reduce([e[:, k] for k in range(e.shape[1])]))) / pixels


def unknown_encoding_message(bit_depth) -> str:
    """The one line that refuses an integer image of unknown encoding (``bit_depth`` 8 or 16)."""
    return (f"{CAPTURE_FILE} states no \"encoding\" and this {bit_depth}-bit image could be sRGB, linear or "
            f"gamma-encoded; ffls does not guess: state \"encoding\" (\"srgb\", \"linear\" or {{\"gamma\": g}}) "
            f"in {CAPTURE_FILE}, or calibrate it from spheres: 'ffls lights' on this capture if its photos "
            f"show spheres, else give as this command's lights the lights.json of a calibration capture of the "
            f"same camera (its \"encoding\" record applies)")


def encoding_unknown(encoding, bit_depth) -> bool:
    """True when ``encoding`` (a capture's) leaves images of ``bit_depth`` undetermined.

    That is ``'auto'`` (no ``"encoding"`` in ``capture.json``) with integer data (8 or 16 bits);
    floating-point data are linear by definition.
    """
    return encoding == "auto" and bit_depth in (8, 16)


def linearise(img: ImageData, encoding, response=None) -> np.ndarray:
    """Linear radiance of a decoded image.

    Parameters
    ----------
    img : ImageData
        As read by :func:`ffls.io.images.read_image`.
    encoding : {'auto', 'srgb', 'linear'} or dict
        ``'auto'`` (none stated) is linear for floating-point images and an error for integer
        ones (:func:`unknown_encoding_message`); ``{'gamma': g}`` is ``pixels ** g``;
        ``{'response': name}`` uses ``response``.
    response : (256, 3) or (65536, 3) ndarray, optional
        Inverse response table (linear value of each 8- or 16-bit code, per channel); its rows
        must match the image's bit depth.

    Returns
    -------
    (H, W, 3) ndarray

    Raises
    ------
    InputError
        An integer image with no stated encoding, or an encoding that does not apply to the
        image (sRGB or gamma for floating point, a response table for 16 bits).
    """
    enc = encoding
    if enc == "auto":
        if encoding_unknown(enc, img.bit_depth):
            raise InputError(unknown_encoding_message(img.bit_depth), img.path)
        enc = "linear"
    if enc == "linear":
        return img.pixels
    if enc == "srgb":
        if img.is_hdr:
            raise InputError(f"{CAPTURE_FILE} says encoding 'srgb' but the image is floating point", img.path)
        return _decode_codes(img, "srgb", 0.0) if _codes_of(img) is not None else srgb_decode(img.pixels)
    if isinstance(enc, dict) and "gamma" in enc:
        if img.is_hdr:
            raise InputError(f"{CAPTURE_FILE} says encoding {{\"gamma\": {enc['gamma']}}} but the image is floating "
                             "point (linear by definition)", img.path)
        if _codes_of(img) is not None:  # (the table is made by gamma_decode: the same range check)
            return _decode_codes(img, "gamma", float(enc["gamma"]))
        return gamma_decode(img.pixels, enc["gamma"])
    rows = len(response)  # 256 (a table from a file, or calibrated on 8-bit files) or 65536 (calibrated on 16-bit)
    if img.bit_depth not in (8, 16) or rows != 2 ** img.bit_depth:
        raise InputError(f"an inverse response table of {rows} codes applies to {int(rows).bit_length() - 1}-bit "
                         f"images, this one is {img.bit_depth}", img.path)
    codes = _codes_of(img)
    codes = np.rint(img.pixels * (rows - 1)).astype(np.intp) if codes is None else codes
    out = np.empty(img.pixels.shape, dtype=np.float32)
    for c in range(3):
        out[..., c] = response[codes[..., c], c]
    return out


def _codes_of(img: ImageData) -> np.ndarray | None:
    """The stored integer codes of ``img`` where the reader kept them (and they match its pixels' shape)."""
    codes = getattr(img, "codes", None)
    if codes is None or codes.shape != np.shape(img.pixels) or codes.dtype not in (np.uint8, np.uint16):
        return None
    return codes


@functools.lru_cache(maxsize=16)
def code_table(curve: str, gamma: float, dtype: str) -> np.ndarray:
    """The linear value of every code of ``dtype`` (uint8 or uint16) under ``curve``: the decode
    evaluated at the float32 values ``k / top`` that :func:`ffls.io.images.read_image` gives."""
    top = np.iinfo(np.dtype(dtype)).max
    values = np.arange(top + 1, dtype=np.float32) / np.float32(top)
    table = srgb_decode(values) if curve == "srgb" else gamma_decode(values, gamma)
    table = np.asarray(table, dtype=np.float32)
    table.setflags(write=False)
    return table


def _decode_codes(img: ImageData, curve: str, gamma: float) -> np.ndarray:
    """:func:`ffls.radiance.encoding.srgb_decode` or ``gamma_decode`` of an integer image's
    pixels, by a table of its codes (the same float32 values; one lookup per pixel instead of a
    power)."""
    import cv2

    codes = _codes_of(img)
    table = code_table(curve, gamma, codes.dtype.name)
    if codes.dtype == np.uint8 and codes.ndim == 3 and codes.shape[2] <= 4:
        return cv2.LUT(np.ascontiguousarray(codes), table)
    return table[codes]


def _check_photo(capture, i: int, img: ImageData) -> None:
    """The photo's size against ``image_size``, and no transparency in an integer photo: a PNG's or
    TIFF's colour is not premultiplied, so under alpha < 1 it is undefined (an EXR's is
    premultiplied by convention: its RGB is the radiance, and its alpha is ignored)."""
    check_opaque(img, "export the photos without alpha (an object's mask goes to --mask)", capture.image_paths[i])
    if capture.image_size is not None:
        h, w = img.shape
        if (w, h) != tuple(capture.image_size):
            raise InputError(
                f"image is {w}x{h} but {CAPTURE_FILE} says image_size {capture.image_size[0]}x{capture.image_size[1]}",
                capture.image_paths[i],
            )


def read_photo(capture, i: int, out: np.ndarray | None = None, depth: int | str | None = None,
               stored: np.ndarray | None = None) -> Photo:
    """Photo ``i`` of ``capture``: linear radiance, raw values and bit depth.

    ``out`` (H, W, 3) float32, optional: where an EXR photo is widened (:func:`ffls.io.images.read_image`;
    its ``linear`` is then ``out`` when no colour conversion applies). ``stored`` (H, W, 3) float16,
    optional: where a half EXR photo's values are interleaved as stored (``read_image``).
    ``depth``, optional: the bit depth of the capture's first photo, which this one must share
    when ``capture.json`` states no encoding (checked before the encoding is applied, so that a
    mixed capture is named as such rather than as an unstated encoding).

    Raises
    ------
    InputError
        Unreadable image, a size that differs from the capture's ``image_size``, or a bit depth
        that differs from ``depth`` with no stated encoding.
    """
    return photo_of_image(capture, i, read_image(capture.image_paths[i], out=out, stored=stored), depth)


def photo_of_image(capture, i: int, img: ImageData, depth: int | str | None = None) -> Photo:
    """:func:`read_photo` of photo ``i`` of ``capture`` already read as ``img``
    (:func:`ffls.io.images.read_image` of its path): checked and linearised, not read again."""
    _check_photo(capture, i, img)
    if depth is not None and capture.encoding == "auto" and img.bit_depth != depth:
        raise InputError(_mixed_depth_message(img.bit_depth, depth), img.path)
    linear = np.asarray(linearise(img, capture.encoding, capture.response), dtype=np.float32)
    return Photo(linear, img.pixels, img.bit_depth, img.codes)


def load_photo(capture, i: int) -> np.ndarray:
    """Photo ``i`` of ``capture`` as (H, W, 3) float32 linear radiance."""
    return read_photo(capture, i).linear


def load_photos(capture, indices=None, progress: bool = True) -> np.ndarray:
    """Several photos of ``capture`` as one linear array.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
    indices : sequence of int, optional
        Which images (all by default), in that order.
    progress : bool
        Show a tqdm bar on stderr (never when stderr is not a terminal or ``CI`` is set).

    Returns
    -------
    (n, H, W, 3) float32 ndarray

    Raises
    ------
    InputError
        Naming the first image whose size differs from the first one's, or whose bit depth
        differs (with automatic encoding).
    """
    from tqdm import tqdm

    idx = list(range(len(capture))) if indices is None else [int(k) for k in indices]
    if not idx:
        raise ValueError("load_photos: no images selected")
    disable = not progress or not sys.stderr.isatty() or bool(os.environ.get("CI"))
    out = None
    depth0 = None
    for n, i in enumerate(tqdm(idx, desc="loading images", unit="img", disable=disable, leave=False)):
        # an EXR of the first one's size is widened straight into its place (no copy of its own)
        dst = None if out is None else out[n]
        img = read_image(capture.image_paths[i], out=dst)
        _check_photo(capture, i, img)
        if out is None:
            out = np.empty((len(idx), *img.pixels.shape), dtype=np.float32)
            depth0 = img.bit_depth
        elif img.pixels.shape != out.shape[1:]:
            h, w = img.shape
            raise InputError(
                f"image is {w}x{h} but the first image {capture.image_names[idx[0]]!r} is "
                f"{out.shape[2]}x{out.shape[1]}", img.path)
        elif capture.encoding == "auto" and img.bit_depth != depth0:
            raise InputError(_mixed_depth_message(img.bit_depth, depth0), img.path)
        lin = linearise(img, capture.encoding, capture.response)
        if lin is not dst:
            out[n] = lin
    return out


def _mixed_depth_message(depth, first) -> str:
    return (f"bit depth {depth} differs from the first image's ({first}); with no 'encoding' in {CAPTURE_FILE} "
            "a capture must not mix depths")
