"""Images in and out: OpenEXR (half/float), Radiance .hdr, PNG/JPEG/TIFF; every write is atomic.

Readers return RGB in file order (OpenCV's BGR is swapped), float32, without any transfer
function applied: linearising 8-bit photographs is the capture's job (``ffls.io.capture``), never
guessed here. Bad input raises :class:`ffls.errors.InputError` naming the file.

Colour: an OpenEXR file whose ``chromaticities`` attribute is not Rec.709/D65 (ACEScg, a wide
gamut or a camera space) is converted to the working space (linear Rec.709, D65) by
:mod:`ffls.io.colourspace` as it is read, and :attr:`ImageData.colour_note` says so; one whose
attribute cannot be converted is an error. Alpha (an EXR ``A`` channel, a PNG/TIFF fourth
channel) is returned in :attr:`ImageData.alpha`; writers take an optional alpha.

OpenEXR goes through the OpenEXR 3.x Python bindings (``OpenEXR.File``), the rest through
OpenCV. OpenCV cannot read TGA; such files are rejected with a message saying so.

Quiet libraries: OpenCV's log is silenced, and what OpenEXR, libpng or OpenCV print on the C
level while a file is decoded is captured (:func:`quiet_native_output`) and becomes part of the
one error line when the file cannot be read, instead of extra lines on the terminal. NaN or Inf
pixels are an error naming the file and the count. Writers check what they wrote: ``cv2.imwrite``
does not report every failure (a full disk), so its return value and the file are checked
(:func:`ffls.errors.atomic_output`), and every write failure is one line naming the file.
"""
from __future__ import annotations

import contextlib
import errno
import io
import os
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffls.errors import (InputError, OutputError, atomic_output, not_a_regular_file, os_error_message,
                         register_input, run_uninterrupted)

__all__ = [
    "ImageData",
    "MAX_RINGING_SHARE",
    "mask_note",
    "READ_EXTENSIONS",
    "read_image",
    "read_exr",
    "write_exr",
    "write_hdr",
    "write_png",
    "read_mask",
    "exr_chromaticities",
    "colour_summary",
    "premultiply",
    "with_alpha",
    "quiet_native_output",
    "ImageHeader",
    "image_header",
    "ORIENTATION_NAMES",
    "check_one_orientation",
    "check_one_colour_kind",
    "check_one_bit_depth",
    "nonfinite_message",
    "check_opaque",
    "check_half_range",
    "HalfRangeError",
    "widen_half",
    "narrow_to_half",
]

_KINDS = {
    ".exr": "exr",
    ".hdr": "hdr",
    ".pic": "hdr",
    ".png": "png",
    ".jpg": "jpeg",
    ".jpeg": "jpeg",
    ".tif": "tiff",
    ".tiff": "tiff",
}
#: File extensions :func:`read_image` reads (lower case).
READ_EXTENSIONS = tuple(_KINDS)

_HALF_MAX = float(np.finfo(np.float16).max)
#: Half of an 8-bit step: a coverage within it of 0 or 1 is black or white (what a file can hold).
_HALF_EPS = 0.5 / 255
#: The float32 value ``k / 255`` of every 8-bit code ``k`` (what an 8-bit file is read as).
_CODE_VALUES_8 = np.arange(256, dtype=np.float32) / np.float32(255)


@dataclass
class ImageData:
    """An image as read from disk.

    Attributes
    ----------
    pixels : (H, W, 3) float32 ndarray
        RGB values as stored: float files as-is; 8/16-bit integer files divided by 255/65535.
        No transfer function is undone.
    bit_depth : {8, 16, 'half', 'float'}
        Storage precision of the file.
    kind : {'exr', 'hdr', 'png', 'jpeg', 'tiff'}
        File format.
    path : pathlib.Path
        Where it was read from.
    alpha : (H, W) float32 ndarray or None
        The alpha channel as stored (EXR ``A``; integer files scaled to [0, 1]), None when absent.
    chromaticities : (8,) tuple of float or None
        The EXR ``chromaticities`` attribute as stored (red, green, blue, white xy), None when
        absent (then the file is in the working space by the OpenEXR default, Rec.709/D65).
    colour_note : str or None
        Set when ``pixels`` were converted from the file's colour space to the working space:
        one line saying from what (:meth:`ffls.io.colourspace.ColourConversion.describe`).
    codes : (H, W, 3) uint8 or uint16 ndarray, or None
        An integer file's stored codes (RGB; ``pixels`` is ``codes / 255`` or ``codes / 65535``),
        None for float files: a transfer function is then undone by a table of the codes
        (:func:`ffls.radiance.photos.linearise`), not by evaluating it at every pixel.
    """

    pixels: np.ndarray
    bit_depth: int | str
    kind: str
    path: Path
    alpha: np.ndarray | None = None
    chromaticities: tuple | None = None
    colour_note: str | None = None
    codes: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W)."""
        return self.pixels.shape[:2]

    @property
    def is_hdr(self) -> bool:
        """True for floating-point storage (EXR, .hdr, float TIFF)."""
        return self.bit_depth in ("half", "float")


_QUIET_LOCK = threading.RLock()


class _Captured:
    """Text the native libraries printed during a :func:`quiet_native_output` block."""

    text = ""

    def first_line(self) -> str:
        """The most informative captured line (OpenEXR's ``EXR_ERR_...`` or OpenCV's ``error:``), or ''."""
        lines = [" ".join(ln.split()) for ln in self.text.splitlines() if ln.strip()]
        for key in ("EXR_ERR", "error:", "Error", "error"):
            for ln in lines:
                if key in ln:
                    return ln
        return lines[0] if lines else ""


def _silence_opencv_log() -> None:
    import cv2

    with contextlib.suppress(AttributeError, cv2.error):
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)


#: Bytes of stored values :func:`read_exr` interleaves at a time (16 MiB) where the caller keeps no
#: half copy: reading a 8192 x 4096 half map peaked at 2x its float32 size, now 1.5x.
EXR_BAND_BYTES = 1 << 24


def widen_half(rgb: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``rgb`` (H, W, 3) half or float32 as float32, into ``out`` (same shape, C-contiguous) when given.

    Half values are widened by OpenCV (``x * 1`` into float32: exact, as every half value is a
    float32 value; +-0, subnormals, infinities kept), 2.7x faster than NumPy's cast on this build
    (1.3 vs 3.4 ms per 768 px photo); NumPy where OpenCV cannot take the array."""
    if rgb.dtype == np.float16 and rgb.ndim == 3 and rgb.shape[2] <= 4 and rgb.flags.c_contiguous:
        import cv2

        try:
            if out is None:
                return cv2.multiply(rgb, 1.0, dtype=cv2.CV_32F)
            res = cv2.multiply(rgb, 1.0, out, dtype=cv2.CV_32F)
            if res is out or np.shares_memory(res, out):
                return out
            np.copyto(out, res)
            return out
        except cv2.error:
            pass
    if out is None:
        return rgb.astype(np.float32, copy=False)
    np.copyto(out, rgb)  # (exact: half and float32 values are float32 values)
    return out


def narrow_to_half(x: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``x`` (float32, C-contiguous) rounded to float16 into ``out`` (float16, same shape, C-contiguous).

    By OpenCV (``x * 1`` into half: F16C on x86), bit for bit NumPy's ``astype(np.float16)`` (round
    to nearest, ties to even; subnormals; +-0; inf at and beyond 65520) and 84x faster on this
    build: 0 differences over 44 M float32 bit patterns spread over all 2**32 (every 97th), 0.11
    against 9.4 s (a NaN stays a NaN; its payload may differ). NumPy where OpenCV cannot take the
    arrays. No overflow warning: an inf is what the caller checks for.
    """
    if x.dtype == np.float32 and out.dtype == np.float16 and x.shape == out.shape and x.size \
            and x.flags.c_contiguous and out.flags.c_contiguous:
        import cv2

        try:
            res = cv2.multiply(x.reshape(-1, 1), 1.0, out.reshape(-1, 1), dtype=cv2.CV_16F)
            if not np.shares_memory(res, out):
                np.copyto(out, res.reshape(out.shape))
            return out
        except cv2.error:
            pass
    with np.errstate(over="ignore"):
        np.copyto(out, x, casting="unsafe")
    return out


@contextlib.contextmanager
def quiet_native_output():
    """Capture what C libraries (OpenEXR, libpng, OpenCV) write to file descriptors 1 and 2 during the block.

    Yields an object whose ``text`` holds the captured output after the block, and whose
    ``first_line()`` gives the line worth quoting in an error. Python's ``sys.stdout`` and
    ``sys.stderr`` are flushed before and redirected too (bindings print through them).
    Thread-safe (one capture at a time).
    """
    cap = _Captured()
    with _QUIET_LOCK:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        try:
            sink = tempfile.TemporaryFile()
            saved = [(fd, os.dup(fd)) for fd in (1, 2)]
        except OSError:  # no descriptors to spare: run unquiet rather than fail
            yield cap
            return
        py = io.StringIO()  # what the bindings print through Python (pybind11 py::print)
        try:
            for fd, _ in saved:
                os.dup2(sink.fileno(), fd)
            with contextlib.redirect_stdout(py), contextlib.redirect_stderr(py):
                yield cap
        finally:
            def restore():  # resumable: an interrupt mid-way must not leave fd 2 on the sink
                if saved:
                    _flush_c_stdio()
                while saved:
                    fd, old = saved[-1]
                    os.dup2(old, fd)
                    saved.pop()
                    os.close(old)  # an interrupt just before this leaks one descriptor, no worse
                if not sink.closed:
                    sink.seek(0)
                    cap.text = sink.read().decode("utf-8", "replace") + py.getvalue()
                    sink.close()

            run_uninterrupted(restore)


def _flush_c_stdio() -> None:
    """fflush(NULL): C (and C++ iostream, synced with it) buffers reach the captured descriptors now."""
    import ctypes

    with contextlib.suppress(Exception):
        ctypes.CDLL(None).fflush(None)


def check_opaque(img: "ImageData", advice: str, path=None) -> None:
    """Refuse an integer image (PNG, TIFF) that has transparent pixels, naming ``path`` (default
    the image's) and adding ``advice``, what to do instead.

    Its colour is not premultiplied, so under alpha < 1 it is undefined: a capture's photo or a
    bracket's image with such pixels is refused (an EXR's RGB is premultiplied by convention: the
    radiance, whatever its alpha).
    """
    if img.alpha is None or img.bit_depth not in (8, 16):
        return
    clear = float(np.mean(img.alpha < 1.0))
    if clear == 0:
        return
    raise InputError(f"has transparent pixels (alpha below 1 in {100 * clear:.3g}% of them): the colour under an "
                     f"unpremultiplied alpha is undefined; {advice}", img.path if path is None else path)


class HalfRangeError(OutputError, ValueError):
    """Values beyond the half-float range for a half-float output (:func:`check_half_range`): an
    :class:`ffls.errors.OutputError` (one line naming the output, status 2 from the commands) and a
    ValueError (a wrong value given to :func:`write_exr`)."""


def check_half_range(a: np.ndarray, path) -> None:
    """Refuse, before writing ``path`` with half floats (:func:`write_exr`, ``--half``), values beyond
    the half-float range (+-65504), which would become infinite: one line naming the output (a bare
    ValueError reached the user as a traceback from ``probe merge --half`` and ``probe mirror --half``).

    Raises
    ------
    HalfRangeError
        Naming ``path``, the largest value and what to do.
    """
    a = np.asarray(a)
    finite = np.abs(a[np.isfinite(a)]) if a.size else a
    top = float(finite.max()) if finite.size else 0.0
    if top > _HALF_MAX:
        raise HalfRangeError(f"values up to {top:.6g} exceed the half-float range ({_HALF_MAX:g}): write "
                             "float (without --half / half=False)", path)


def nonfinite_message(a: np.ndarray) -> str | None:
    """``'N pixels with NaN or Inf values (a NaN, b Inf channel values; the first at column x, row y)'`` for
    (H, W, C) or (H, W) data, or None when all finite (the place: where to look in an image editor)."""
    bad = np.isfinite(a)
    np.logical_not(bad, out=bad)  # (in place: one mask of the data's size, not two)
    if not bad.any():
        return None
    px = bad.any(axis=-1) if a.ndim == 3 else bad
    npx = int(np.count_nonzero(px))
    where = ""
    if px.ndim == 2:
        row, col = np.unravel_index(int(np.argmax(px)), px.shape)
        where = f"; the first at column {col}, row {row}"
    return (f"{npx} pixels with NaN or Inf values ({int(np.isnan(a).sum())} NaN, "
            f"{int(np.isinf(a).sum())} Inf channel values{where})")


def _kind_of(path: Path) -> str:
    ext = path.suffix.lower()
    if ext in _KINDS:
        return _KINDS[ext]
    if ext == ".tga":
        raise InputError("TGA images are not supported (OpenCV cannot read TGA); convert to PNG or TIFF", path)
    raise InputError(
        f"unsupported image format {ext or '(no extension)'!r}; supported: {', '.join(READ_EXTENSIONS)}", path
    )


#: The first bytes of each format ffls reads (its signature), and how a message names it
_SIGNATURES = ((b"v/1\x01", "exr"), (b"\x89PNG\r\n\x1a\n", "png"), (b"\xff\xd8\xff", "jpeg"),
               (b"II*\x00", "tiff"), (b"MM\x00*", "tiff"), (b"II+\x00", "tiff"), (b"MM\x00+", "tiff"),
               (b"#?", "hdr"))
_KIND_NAMES = {"exr": ("an OpenEXR", ".exr"), "png": ("a PNG", ".png"), "jpeg": ("a JPEG", ".jpg"),
               "tiff": ("a TIFF", ".tif"), "hdr": ("a Radiance HDR", ".hdr")}
#: Formats ffls does not read whose signatures it knows, by (offset, bytes) (OpenCV decodes by content:
#: a WebP, BMP, GIF, JPEG 2000 or PNM file named .jpg/.png/.tif was decoded with no header check)
_OTHER_SIGNATURES = (((0, b"RIFF"), (8, b"WEBP"), "a WebP"), ((0, b"BM"), "a BMP"), ((0, b"GIF8"), "a GIF"),
                     ((0, b"\x00\x00\x00\x0cjP  \r\n\x87\n"), "a JPEG 2000"), ((0, b"\xffO\xffQ"), "a JPEG 2000"),
                     ((4, b"ftypheic"), "a HEIF (HEIC)"), ((4, b"ftypheix"), "a HEIF (HEIC)"),
                     ((4, b"ftypmif1"), "a HEIF"), ((4, b"ftypavif"), "an AVIF"),
                     ((0, b"\x00\x00\x00\x0cJXL \r\n\x87\n"), "a JPEG XL"), ((0, b"\xff\n"), "a JPEG XL"),
                     ((0, b"PF\n"), "a PFM"), ((0, b"Pf\n"), "a PFM"), ((0, b"P7\n"), "a PAM"),
                     *(((0, b"P%d" % k), "a PNM (PBM/PGM/PPM)") for k in range(1, 7)))


def _other_format(head: bytes) -> str | None:
    """The name of a format ffls does not read (:data:`_OTHER_SIGNATURES`) whose signature ``head`` has, or None."""
    for *parts, name in _OTHER_SIGNATURES:
        if all(head[at:at + len(sig)] == sig for at, sig in parts):
            if name.startswith("a PNM") and not head[2:3].isspace():
                continue  # (a netpbm magic number is followed by whitespace)
            return name
    return None


def _check_content_kind(path: Path, kind: str) -> None:
    """Refuse a file whose first bytes are another format's than its extension names (a 16-bit PNG
    named ``.jpg``): ffls reads a file as its extension says, and the checks it makes from the
    header before decoding (size, memory, grey or colour, bit depth, orientation) read that
    format's header, so such a file passed them all unread. So did a file of a format ffls does not
    read (a WebP, BMP, GIF, JPEG 2000 or PNM file, which OpenCV decodes by content; a HEIF or JPEG
    XL, which it refused as corrupt): refused naming it. A signature ffls does not know (a corrupt
    file) is left to the decoder, which names what is wrong."""
    try:
        with open(path, "rb") as f:
            head = f.read(16)
    except OSError:
        return  # (the decoder names it)
    found = next((k for sig, k in _SIGNATURES if head.startswith(sig)), None)
    if found is not None and found != kind:
        name, ext = _KIND_NAMES[found]
        raise InputError(f"is {name} file named {path.suffix!r}: ffls reads a file as its extension says (its "
                         f"checks before decoding read that format's header); rename it {path.stem}{ext}", path)
    other = None if found is not None else _other_format(head)
    if other is not None:
        raise InputError(f"is {other} file named {path.suffix!r}, a format ffls does not read; convert it to "
                         f"one of {', '.join(READ_EXTENSIONS)}", path)


def read_image(path: str | os.PathLike, working_space: bool = True, allow_nonfinite: bool = False,
               out: np.ndarray | None = None, stored: np.ndarray | None = None) -> ImageData:
    """Read an image file as RGB float32.

    Parameters
    ----------
    path : path-like
        An ``.exr``, ``.hdr``/``.pic``, ``.png``, ``.jpg``/``.jpeg`` or ``.tif``/``.tiff`` file.
    working_space : bool
        Convert an EXR whose ``chromaticities`` are another space to the working space (linear
        Rec.709, D65) and say so in ``colour_note`` (default). False returns the stored values.
    allow_nonfinite : bool
        Return NaN/Inf values as stored instead of raising (default: an error with the count).
    out : (H, W, 3) float32 ndarray, optional
        Where an EXR's pixels are widened to float32 when its size matches (``pixels`` is then
        ``out``, unless a colour conversion made a new array): a caller that keeps the photo, e.g.
        in shared memory, saves a copy. Ignored for other formats and other sizes.
    stored : (H, W, 3) float16 ndarray, optional
        Where a half EXR's R, G, B values are interleaved as stored (before any colour
        conversion) when its size matches; ``pixels`` is widened from them (into ``out``, if
        given). Ignored for other formats, float EXRs and other sizes.

    Returns
    -------
    ImageData
        ``pixels`` is (H, W, 3) float32. Grey images are replicated to three channels; alpha
        is in ``alpha``.

    Raises
    ------
    InputError
        If the file is missing, unreadable, corrupt (truncated) or of an unsupported format, its
        colour space cannot be converted, or (unless ``allow_nonfinite``) it holds NaN or Inf
        pixels (the message gives the count).
    """
    path = Path(path)
    if path.is_dir():  # (a folder without an extension was "unsupported image format '(no extension)'")
        raise InputError("is a folder, not an image file", path)
    kind = _kind_of(path)
    if not path.is_file():
        raise InputError(not_a_regular_file(path) or ("image file not found" if not path.exists() else "not a file"),
                         path)
    register_input(path)
    _check_content_kind(path, kind)
    head = _check_decodable_size(path)
    if kind == "exr":
        img = read_exr(path, working_space=working_space, out=out, stored=stored)
    else:
        img = _read_cv2(path, kind, 1 if head is None else head.orientation, working_space)
    if not allow_nonfinite:
        why = nonfinite_message(img.pixels)
        if why is None and img.alpha is not None and not np.all(np.isfinite(img.alpha)):
            why = "NaN or Inf values in the alpha channel"
        if why:
            raise InputError(f"image has {why}", path)
    return img


#: Bytes per pixel that decoding an image takes at its peak: float32 RGB (12) and the decoder's
#: own array (up to 12 more for a float file).
DECODE_BYTES_PER_PIXEL = 24


def _check_decodable_size(path: Path) -> ImageHeader | None:
    """Refuse, from its header, an image whose decoding needs more memory than is available
    (a huge light map or background, which was decoded until the system ran out of memory).
    Returns the header (:func:`image_header`)."""
    from ffls.errors import available_memory

    head = image_header(path)
    if head is None:
        return None
    if path.suffix.lower() != ".exr" and head.width * head.height >= 2 ** 30:
        return head  # (OpenCV refuses it without decoding, and _undecodable says so, the same on every machine)
    need = float(head.width) * float(head.height) * DECODE_BYTES_PER_PIXEL
    have = available_memory()
    if need > have:
        raise InputError(f"a {head.width}x{head.height} image needs about {need / 2**30:.3g} GiB to decode, more "
                         f"than the {have / 2**30:.3g} GiB of memory available", path)
    return head


def _in_working_space(pixels, primaries, path, working_space: bool):
    """``(pixels, note)``: pixels stored in ``primaries`` (a file's chromaticities; None: Rec.709)
    converted to the working space where ``working_space``, with the conversion's description (None
    where nothing was converted). Malformed primaries are an error either way."""
    if primaries is None:
        return pixels, None
    from ffls.io.colourspace import convert_to_working_space, working_space_conversion

    if not working_space:
        working_space_conversion(primaries, path)
        return pixels, None
    pixels, conv = convert_to_working_space(pixels, primaries, path)
    return pixels, None if conv is None else conv.describe()


def read_exr(path: str | os.PathLike, working_space: bool = True, out: np.ndarray | None = None,
             stored: np.ndarray | None = None) -> ImageData:
    """Read an OpenEXR file (half or float channels) as RGB float32.

    Takes the ``R``, ``G``, ``B`` channels, or replicates ``Y`` for luminance-only files, and
    ``A`` as alpha; other channels (depth, ...) are ignored. Luminance-chroma files (``Y``,
    ``RY``, ``BY``) are refused rather than read as grey.

    Parameters
    ----------
    path : path-like
        The ``.exr`` file.
    working_space : bool
        Convert RGB from the space of the ``chromaticities`` attribute (when present and not
        Rec.709/D65) to the working space, reporting it in ``colour_note``
        (:func:`ffls.io.colourspace.convert_to_working_space`).
    out : (H, W, 3) float32 ndarray, optional
        Where the pixels are widened when the file's size matches (:func:`read_image`).
    stored : (H, W, 3) float16 ndarray, optional
        Where a half file's R, G, B values are interleaved when its size matches (:func:`read_image`).

    Returns
    -------
    ImageData
        ``pixels`` (H, W, 3) float32, ``bit_depth`` ``'half'`` or ``'float'``.

    Raises
    ------
    InputError
        Missing, corrupt, or without R/G/B or Y channels, luminance-chroma, or with integer/subsampled channels,
        multi-part, with a data window other than its display window, or with a ``chromaticities``
        attribute that is not a convertible colour space.
    """
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise InputError(not_a_regular_file(path) or "image file not found", path)
    err = None
    with quiet_native_output() as cap:
        try:
            f = OpenEXR.File(str(path), separate_channels=True)
            channels = f.channels()
            header = f.header()
        except Exception as e:  # the bindings raise RuntimeError/others with multi-line text
            err = e
    if err is None and ("EXR_ERR" in cap.text or "Exception" in cap.text):  # read "successfully", data incomplete
        err = RuntimeError(cap.first_line())
    if err is not None:
        why = cap.first_line().replace(str(path) + ": ", "")
        raise InputError(f"cannot read OpenEXR file, corrupt or truncated ({why or f'{type(err).__name__}: {err}'})"
                         + _exr_levels_hint(path), path) from None
    n_parts = len(getattr(f, "parts", [None]))
    if n_parts > 1:  # only the first part would be read, as if it were the image
        raise InputError(f"OpenEXR file has {n_parts} parts; ffls reads single-part files: write the image as "
                         "one part", path)
    data_window, display_window = header.get("dataWindow"), header.get("displayWindow")
    if data_window is not None and display_window is not None and not all(
            np.array_equal(a, b) for a, b in zip(data_window, display_window)):
        (x0, y0), (x1, y1) = (tuple(int(v) for v in c) for c in data_window)
        (u0, v0), (u1, v1) = (tuple(int(v) for v in c) for c in display_window)
        raise InputError(f"OpenEXR data window ({x0},{y0})-({x1},{y1}) differs from its display window "
                         f"({u0},{v0})-({u1},{v1}); its pixels would be placed at the wrong position: crop or pad it "
                         "to the display window", path)
    names = set(channels)
    if {"R", "G", "B"} <= names:
        use = ["R", "G", "B"]
    elif names & {"RY", "BY"}:  # luminance + chroma (OpenEXR's YCA mode): reading Y alone would drop the colour
        raise InputError(f"OpenEXR file stores luminance and chroma channels ({', '.join(sorted(names))}); ffls "
                         "reads RGB or luminance-only (Y) files: convert it to RGB", path)
    elif "Y" in names:
        use = ["Y", "Y", "Y"]
    else:
        raise InputError(f"OpenEXR file needs the channels R, G and B, or Y (luminance); it has {sorted(names)}", path)
    planes = []
    depth = "half"
    for name in use:
        ch = channels[name]
        if getattr(ch, "xSampling", 1) != 1 or getattr(ch, "ySampling", 1) != 1:
            raise InputError(f"OpenEXR channel {name} is subsampled; not supported", path)
        px = np.asarray(ch.pixels)
        if px.dtype == np.float32:
            depth = "float"
        elif px.dtype != np.float16:
            raise InputError(f"OpenEXR channel {name} has integer type {px.dtype}; expected half or float", path)
        if px.ndim != 2:
            raise InputError(f"OpenEXR channel {name} is not a 2-D image (deep data?)", path)
        planes.append(px)
    alpha = None
    if "A" in names:
        a = np.asarray(channels["A"].pixels)
        if a.dtype not in (np.float16, np.float32) or a.ndim != 2:
            raise InputError(f"OpenEXR channel A has type {a.dtype} and {a.ndim} dimensions; expected a 2-D half "
                             "or float image", path)
        planes.append(a)
    if len({p.shape for p in planes}) != 1:
        raise InputError("OpenEXR channels differ in size", path)
    if "A" in names:
        alpha = planes.pop().astype(np.float32)
    # interleaved in the stored type, then widened (exact): half the bytes through the strided
    # interleave, which costs more than the decompression itself
    into = None
    if (stored is not None and depth == "half" and stored.shape == planes[0].shape + (len(planes),)
            and stored.dtype == np.float16 and stored.flags.c_contiguous and stored.flags.writeable):
        into = stored  # (the caller keeps the half values: no half copy of its own)
    shape = planes[0].shape + (len(planes),)
    if not (out is not None and out.shape == shape and out.dtype == np.float32
            and out.flags.c_contiguous and out.flags.writeable):
        out = None
    if into is not None:
        rgb = np.stack(planes, axis=-1, out=into)
        rgb = widen_half(rgb, out)
    elif depth == "float":  # float32 planes (any half among them widened exactly): straight into the result
        rgb = np.empty(shape, dtype=np.float32) if out is None else out
        np.stack(planes, axis=-1, out=rgb)
    else:  # half, in bands of rows: no interleaved copy of the whole image beside its planes and the result
        rgb = np.empty(shape, dtype=np.float32) if out is None else out
        step = max(1, EXR_BAND_BYTES // (shape[1] * shape[2] * planes[0].itemsize))
        for r in range(0, shape[0], step):
            widen_half(np.stack([p[r:r + step] for p in planes], axis=-1), rgb[r:r + step])
    chroma = header.get("chromaticities")
    rgb, note = _in_working_space(rgb, chroma, path, working_space)
    if chroma is not None:
        chroma = tuple(float(v) for v in np.asarray(chroma, dtype=np.float64).reshape(-1))
    return ImageData(rgb, depth, "exr", path, alpha=alpha, chromaticities=chroma, colour_note=note)


def _tiff_alpha_dropped(path: Path, shape: tuple) -> np.ndarray | None:
    """The alpha of a TIFF whose alpha OpenCV drops on decoding (grey + alpha, ``LA``), read by
    Pillow from the same file; None where the file has none (Pillow reads the header only)."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            if "A" not in im.getbands():
                return None
            a = np.asarray(im.getchannel("A"))
    except (OSError, ValueError):
        return None  # (a TIFF that Pillow cannot read: OpenCV's decoding stands)
    return a if a.shape == tuple(shape) else None


# Pillow modes of files OpenCV decodes (a header of another, e.g. 'F' or 'I;16S', is a sample
# format OpenCV does not read)
_CV2_MODES = {"1", "L", "LA", "P", "PA", "RGB", "RGBA", "CMYK", "YCbCr", "I;16", "I;16B", "I;16L"}


def _undecodable(path: Path, kind: str, whole: bool) -> str:
    """Why OpenCV decoded nothing: a valid file beyond its pixel limit or in a sample format it
    does not read (asked of Pillow, which reads the header only), else corrupt or truncated."""
    import warnings

    from PIL import Image

    what = f"cannot decode {kind.upper()} image"
    if whole:  # (a partly decoded image is a truncated one)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # (Pillow's own size warning: judged here)
                # the format's own reader: Image.open refuses sizes past its bomb limit, and the
                # 30000x30000 PNG whose data was cut was called "over 178956970 pixels"
                with (_pillow_reader(kind) or Image.open)(path) as im:
                    (w, h), mode = im.size, im.mode
        except (OSError, ValueError, SyntaxError, Image.DecompressionBombError):
            pass
        else:
            if w * h >= 2 ** 30:
                return f"{what}: {w}x{h} is beyond OpenCV's limit of 2^30 pixels"
            if mode in _CV2_MODES:  # a header OpenCV reads: the data after it is what failed
                return f"{what}: its {w}x{h} header is valid but the data is corrupt or truncated"
            return (f"{what}: a {w}x{h} {kind.upper()} of sample format {mode!r}, which OpenCV does not read; "
                    "convert it to 8- or 16-bit integer or 32-bit float (or EXR)")
    if kind == "tiff":  # (a TIFF's sample formats are many: 16-bit float, 1-bit, ...)
        return (f"{what} (corrupt, truncated, not a TIFF file, or in a sample format such as 16-bit float that "
                "OpenCV does not read: convert it to 8- or 16-bit integer or 32-bit float, or EXR)")
    return f"{what} (corrupt, truncated or not a {kind.upper()} file)"


#: What the decoders print (and OpenCV decodes past, filling the rest grey) when the data after a
#: valid header is cut or damaged: libpng, libjpeg ("Corrupt JPEG data: 216 extraneous bytes before
#: marker 0xc4" of bytes zeroed in the middle), OpenCV's own "incomplete" warnings.
_CORRUPT_DATA_LINES = ("incomplete", "libpng error", "Corrupt JPEG data", "Premature end of JPEG file")


#: A Radiance resolution line: the scanline axis with its count, then the pixel axis with its
#: count; ``-Y H +X W`` (top to bottom, left to right) is the standard, and the format allows all 8
_RADIANCE_AXES = {(b"-Y", b"+X"), (b"-Y", b"-X"), (b"+Y", b"+X"), (b"+Y", b"-X"),
                  (b"+X", b"-Y"), (b"+X", b"+Y"), (b"-X", b"-Y"), (b"-X", b"+Y")}


def _radiance_resolution(buf: bytes):
    """The resolution line of a Radiance file's first bytes: ``(start, end, words)``, the line's
    byte span after the header's blank line and its four words; None where there is none."""
    end_head = buf.find(b"\n\n")
    if end_head < 0:
        return None
    start = end_head + 2
    end = buf.find(b"\n", start)
    words = buf[start:end].split() if end > 0 else []
    if (len(words) != 4 or (words[0], words[2]) not in _RADIANCE_AXES
            or not (words[1].isdigit() and words[3].isdigit())):
        return None
    return start, end, words


def _radiance_header(buf: bytes, path) -> tuple[np.ndarray, tuple | None]:
    """What a Radiance file's header says about its values (the lines before the blank line):
    ``(scale, primaries)``.

    ``scale`` (3,) float32 is what the stored values are divided by to give the radiance: the
    product of every ``EXPOSURE=`` line (cumulative, by the format's definition) times every
    ``COLORCORR=`` line (per channel); ``primaries`` the 8 numbers of a ``PRIMARIES=`` line (red,
    green, blue and white xy, as an EXR's ``chromaticities``), or None. OpenCV reads none of
    them: an hdrgen or Photosphere file with ``EXPOSURE=4`` was read 4 times too bright.

    Raises
    ------
    InputError
        An ``EXPOSURE`` or ``COLORCORR`` that is not a positive finite number (three for
        ``COLORCORR``), a ``PRIMARIES`` line that is not 8 numbers, or ``FORMAT=32-bit_rle_xyze``
        (CIE XYZ values, which OpenCV cannot decode: it was refused as a corrupt file).
    """
    end = buf.find(b"\n\n")
    scale, primaries = np.ones(3, dtype=np.float64), None
    for line in (buf[:end] if end >= 0 else b"").split(b"\n"):
        key, eq, value = line.partition(b"=")
        key = key.strip().upper()
        if key == b"FORMAT" and value.strip().lower() == b"32-bit_rle_xyze":
            raise InputError("is a Radiance XYZE file (FORMAT=32-bit_rle_xyze, CIE XYZ values): ffls reads "
                             "Radiance's RGBE files; convert it (Radiance's ra_xyze -r) or write an EXR", path)
        if not eq or key not in (b"EXPOSURE", b"COLORCORR", b"PRIMARIES"):
            continue
        words = value.split()
        try:
            v = np.array([float(w) for w in words], dtype=np.float64)
        except ValueError:
            v = np.array([])
        name = key.decode()
        if key == b"PRIMARIES":
            if v.size != 8:
                raise InputError(f"Radiance header line PRIMARIES= must give 8 numbers (red, green, blue and white "
                                 f"x y), not {value.strip().decode('latin-1')!r}", path)
            primaries = tuple(v.tolist())
            continue
        n = 1 if key == b"EXPOSURE" else 3
        if v.size != n or not np.all(np.isfinite(v) & (v > 0)):
            what = "a positive number" if n == 1 else "3 positive numbers"
            raise InputError(f"Radiance header line {name}= must give {what} (what the stored values were "
                             f"multiplied by), not {value.strip().decode('latin-1')!r}", path)
        scale *= v
    return scale.astype(np.float32), primaries


def _radiance_standard(buf: np.ndarray):
    """A Radiance file stored in another of the format's 8 orientations, given to OpenCV (which
    reads only ``-Y H +X W``) as its scanlines, and the turn to the standard layout.

    Returns ``(buf, turn)``: the bytes with the resolution line ``-Y N1 +X N2`` (N1 scanlines of
    N2 pixels, the file's own counts) and a function from OpenCV's array to the image shown as
    viewers show it (top row up, +X right); ``turn`` is None for a standard or unreadable file.
    """
    found = _radiance_resolution(buf[:65536].tobytes())
    if found is None or (found[2][0], found[2][2]) == (b"-Y", b"+X"):
        return buf, None
    start, end, (a1, n1, a2, n2) = found
    line = np.frombuffer(b"-Y " + n1 + b" +X " + n2, dtype=np.uint8)
    buf = np.concatenate([buf[:start], line, buf[end:]])

    def turn(img: np.ndarray) -> np.ndarray:
        if a1 in (b"+Y", b"-X"):  # scanlines bottom to top, or right to left
            img = img[::-1]
        if a2 in (b"-X", b"+Y"):  # pixels right to left, or bottom to top
            img = img[:, ::-1]
        return np.ascontiguousarray(img.swapaxes(0, 1) if a1[1:] == b"X" else img)

    return buf, turn


def _exr_levels_hint(path: Path) -> str:
    """What to do with an unreadable EXR whose header names mip- or rip-mapped tiles, or ``''``.

    ffls reads a tiled file's level 0, which a complete mip-mapped file (every level's tiles in
    its chunk table) gives; the OpenEXR Python binding (3.x) writes such a header with level 0's
    tiles only, leaving the chunk table incomplete, which reads as corrupt."""
    import OpenEXR

    try:
        with quiet_native_output():
            tiles = OpenEXR.File(str(path), header_only=True).header().get("tiles")
    except Exception:  # the header itself is unreadable: nothing to add
        return ""
    mode = getattr(tiles, "mode", None)
    if mode is None or mode == OpenEXR.ONE_LEVEL:
        return ""
    kind = "mip-mapped" if mode == OpenEXR.MIPMAP_LEVELS else "rip-mapped"
    return (f"; its header says {kind} tiles, whose levels' tiles are not all there (a writer that stored level 0 "
            "only, as the OpenEXR Python binding does): ffls reads level 0 of a complete one; write this map "
            "with one level (tiles ONE_LEVEL, or scanlines)")


def _read_cv2(path: Path, kind: str, orientation: int = 1, working_space: bool = True) -> ImageData:
    """A PNG, JPEG, TIFF or Radiance file through OpenCV, shown as its EXIF ``orientation`` asks
    (OpenCV's ``IMREAD_UNCHANGED`` keeps a JPEG's or PNG's stored rows; it turns a TIFF itself).
    A Radiance file's values are divided by its header's ``EXPOSURE`` and ``COLORCORR``, and
    converted from its ``PRIMARIES`` as an EXR's ``chromaticities`` are (:func:`_radiance_header`)."""
    import cv2

    try:
        buf = np.fromfile(str(path), dtype=np.uint8)
    except OSError as e:
        raise InputError(f"cannot read file ({e.strerror or e})", path) from None
    if buf.size == 0:
        raise InputError("image file is empty", path)
    flags = cv2.IMREAD_UNCHANGED if kind != "hdr" else cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR
    scale, primaries = _radiance_header(buf[:65536].tobytes(), path) if kind == "hdr" else (None, None)
    buf, radiance_turn = _radiance_standard(buf) if kind == "hdr" else (buf, None)
    _silence_opencv_log()
    with quiet_native_output() as cap:
        try:
            img = cv2.imdecode(buf, flags)
        except cv2.error:
            img = None
    if img is None or any(m in cap.text for m in _CORRUPT_DATA_LINES):
        said = next((ln for ln in cap.text.splitlines() if "Corrupt JPEG" in ln or "Premature end" in ln), "")
        raise InputError(_undecodable(path, kind, img is None) + (f" (libjpeg: {said.strip()})" if said else ""),
                         path)
    if kind in ("jpeg", "png") and orientation in _ORIENTED:
        img = np.ascontiguousarray(_ORIENTED[orientation](img))
    if radiance_turn is not None:
        img = radiance_turn(img)
    alpha = None
    if kind == "tiff" and (img.ndim == 2 or img.shape[2] in (1, 3)):
        alpha = _tiff_alpha_dropped(path, img.shape[:2])
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    elif img.shape[2] == 2:  # grey + alpha
        alpha = img[:, :, 1]
        img = np.repeat(img[:, :, :1], 3, axis=2)
    elif img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    else:
        alpha = img[:, :, 3] if img.shape[2] == 4 else None
        if img.dtype in (np.uint8, np.uint16, np.float32):  # BGR(A) -> RGB, contiguous, in one pass
            img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB if img.shape[2] == 4 else cv2.COLOR_BGR2RGB)
        else:
            img = img[:, :, 2::-1]
    dt = img.dtype
    codes = None
    if dt == np.uint8:  # k / 255 by a table of the 256 codes: the same float32 values, 4x faster
        codes = np.ascontiguousarray(img)
        pixels, depth = cv2.LUT(codes, _CODE_VALUES_8), 8
    elif dt == np.uint16:
        codes = np.ascontiguousarray(img)
        pixels, depth = codes.astype(np.float32) / np.float32(65535), 16
    elif dt == np.float32:
        pixels, depth = img.astype(np.float32), "float"
    elif dt == np.float16:
        pixels, depth = img.astype(np.float32), "half"
    elif dt == np.float64:
        pixels, depth = img.astype(np.float32), "float"
    else:
        raise InputError(f"unsupported pixel type {dt} in {kind.upper()} image", path)
    if alpha is not None:
        top = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(alpha.dtype, 1.0)
        alpha = np.ascontiguousarray(alpha.astype(np.float32) / np.float32(top))
    if scale is not None and np.any(scale != 1):
        pixels = pixels / scale
    pixels, note = _in_working_space(pixels, primaries, path, working_space)
    return ImageData(np.ascontiguousarray(pixels), depth, kind, path, alpha=alpha, codes=codes,
                     chromaticities=primaries, colour_note=note)


#: Two images are the same photo (:func:`same_pixels`) when the RMS of their difference is at most
#: this share of their RMS value: a file copied twice differs by 0; two shots of one light differ
#: by the sensor's noise, about 1% at mid-grey even on a good camera (sqrt 2 times the shot noise),
#: and a rendered light twice by 0 (a deterministic renderer).
SAME_PIXELS_RTOL = 1e-3


def same_pixels(a: str | os.PathLike, b: str | os.PathLike, rtol: float = SAME_PIXELS_RTOL) -> bool:
    """Whether the images ``a`` and ``b`` hold (nearly) the same pixels, as stored: the RMS of the
    difference at most ``rtol`` times the RMS of ``a`` and ``b`` (:data:`SAME_PIXELS_RTOL`).
    Images of different sizes differ. Reads both (:func:`read_image`, as stored: no colour
    conversion)."""
    return pixels_match(read_image(a, working_space=False).pixels, read_image(b, working_space=False).pixels, rtol)


def pixels_match(pa: np.ndarray, pb: np.ndarray, rtol: float = SAME_PIXELS_RTOL) -> bool:
    """Whether the pixel arrays ``pa`` and ``pb`` (as :func:`read_image` gives them) are (nearly) the
    same: the test of :func:`same_pixels`, for callers that hold the arrays already."""
    if pa.shape != pb.shape:
        return False
    d = pa.astype(np.float64) - pb
    scale = np.sqrt(0.5 * (np.mean(np.square(pa, dtype=np.float64)) + np.mean(np.square(pb, dtype=np.float64))))
    return bool(np.sqrt(np.mean(d * d)) <= rtol * scale)


#: Share of an image's pixels that a reconstruction filter (Lanczos, Mitchell, bicubic) may ring
#: outside its range on, beside sharp edges; more than this is another kind of image (a mask's
#: coverage past 0..1: an HDR photo; a background's negative radiance: an offset image).
MAX_RINGING_SHARE = 0.01


def read_mask(path: str | os.PathLike, size: tuple | None = None) -> np.ndarray:
    """An object mask image as coverage (H, W) float32 in [0, 1] (white = object).

    The coverage of a pixel is its largest channel (integer files scaled to [0, 1]; floats
    clipped to [0, 1]: a resampled mask rings past them on a few pixels, at most
    :data:`MAX_RINGING_SHARE` of them); a file with alpha uses the alpha times that. Grey is
    partial coverage (a soft mask): :func:`mask_note` says when a mask is mostly grey.

    Parameters
    ----------
    path : path-like
        PNG, TIFF, EXR, ... (anything :func:`read_image` reads).
    size : (int, int), optional
        Expected (W, H): another size raises InputError naming both.

    Raises
    ------
    InputError
        Unreadable, non-finite values, values outside [0, 1] on more than
        :data:`MAX_RINGING_SHARE` of the pixels (a float photo, not a mask), or the wrong size.
    """
    img = read_image(path, working_space=False)
    m = img.pixels.max(axis=-1)
    if img.alpha is not None:
        m = m * img.alpha
    if not np.all(np.isfinite(m)):
        raise InputError("mask has NaN or Inf values", path)
    if size is not None and (m.shape[1], m.shape[0]) != tuple(size):
        raise InputError(f"mask is {m.shape[1]}x{m.shape[0]}, the images are {size[0]}x{size[1]}", path)
    outside = float(np.mean((m < 0) | (m > 1)))
    if outside > MAX_RINGING_SHARE:  # (a float EXR photo was clipped to a "mask" without a word)
        raise InputError(f"mask values run from {float(m.min()):.3g} to {float(m.max()):.3g}, outside 0..1 on "
                         f"{100 * outside:.1f}% of the pixels: a mask is coverage, 0 (black, background) to 1 "
                         f"(white, object); is it a photo? (at most {100 * MAX_RINGING_SHARE:g}% from a "
                         "filter's ringing is clipped)", path)
    return np.clip(m, 0.0, 1.0).astype(np.float32)


def mask_note(mask, path) -> str | None:
    """The line that says a mask (:func:`read_mask`'s coverage) is read as a soft one, or None.

    Grey is partial coverage (docs/formats.md): an anti-aliased or feathered edge is grey on
    fewer pixels than the object's white inside. A mask with no white pixel, or more grey pixels
    than white ones (a grey card, a photo), is still read as coverage, but said: its object is at
    most that opaque, or it is not the mask meant."""
    m = np.asarray(mask)
    white = int(np.count_nonzero(m >= 1.0 - _HALF_EPS))
    grey = int(np.count_nonzero((m > _HALF_EPS) & (m < 1.0 - _HALF_EPS)))
    name = Path(path).name
    if not white:
        return (f"mask: {name} has no white pixel (coverage at most {float(m.max()):.3g}): read as a soft mask, "
                f"the object at most {100 * float(m.max()):.0f}% opaque (white = object)")
    if grey > white:
        return (f"mask: {name} is grey (partial coverage) on {100 * grey / m.size:.0f}% of its pixels, more than "
                f"are white ({100 * white / m.size:.0f}%): read as a soft mask, each pixel's alpha its grey")
    return None


@dataclass(frozen=True)
class ImageHeader:
    """What an image file's header says, read without decoding its pixels (:func:`image_header`).

    Attributes
    ----------
    width, height : int
        The size in pixels.
    grey : bool
        One colour channel (grey, or grey + alpha; an EXR of ``Y`` only): :func:`read_image`
        replicates it to RGB.
    orientation : int
        The EXIF orientation (1 to 8; 1, upright as stored, where the file gives none or a value
        outside 1 to 8) of a JPEG, PNG or TIFF. ``width`` and ``height`` are the displayed size,
        after it (:func:`read_image` shows the photo as image viewers do).
    bits : {8, 16} or None
        The integer bit depth :func:`read_image` gives a PNG, JPEG or TIFF (its ``bit_depth``: 8
        for 1- to 8-bit samples, 16 for 16-bit ones); None for floating point files (EXR, HDR)
        and where the header does not say (a 12-bit JPEG).
    """

    width: int
    height: int
    grey: bool
    orientation: int = 1
    bits: int | None = None


#: The EXIF tag of the orientation (TIFF tag 274)
_ORIENTATION_TAG = 0x0112
#: What each EXIF orientation asks a viewer to do to the stored pixels (rows, columns, channels):
#: the transforms of Pillow's ``ImageOps.exif_transpose`` and OpenCV's ``IMREAD_COLOR``
_ORIENTED = {
    2: lambda a: a[:, ::-1],  # mirrored left-right
    3: lambda a: a[::-1, ::-1],  # rotated 180 degrees
    4: lambda a: a[::-1],  # mirrored top-bottom
    5: lambda a: a.swapaxes(0, 1),  # transposed
    6: lambda a: np.rot90(a, -1),  # turned 90 degrees clockwise
    7: lambda a: a.swapaxes(0, 1)[::-1, ::-1],  # transversed
    8: lambda a: np.rot90(a, 1),  # turned 90 degrees counter-clockwise
}
#: How each orientation is named in a message
ORIENTATION_NAMES = {1: "upright (as stored)", 2: "mirrored", 3: "rotated 180 degrees", 4: "mirrored upside down",
                     5: "transposed", 6: "turned 90 degrees clockwise", 7: "transversed",
                     8: "turned 90 degrees counter-clockwise"}


def _headers_of(paths, names, heads) -> tuple[list, list, list]:
    """The paths, the names the messages give them (default: the file names) and the headers
    (read here unless given) of a set of images, as the ``check_one_*`` functions take them."""
    paths = [Path(p) for p in paths]
    names = [p.name for p in paths] if names is None else list(names)
    heads = [image_header(p) for p in paths] if heads is None else list(heads)
    return paths, names, heads


def check_one_colour_kind(paths, names=None, heads=None, what: str = "photos", whole: str = "a capture") -> None:
    """Refuse images of one camera (a capture's photos, a bracket) that mix grey (one channel) and colour.

    A grey image would be replicated to RGB, a colourless light (or exposure) among coloured ones,
    and such a mix is almost always a wrong export. The minority is named. Arguments as
    :func:`check_one_orientation`; ``whole`` names the set in the message (``'a capture'``).

    Raises
    ------
    InputError
        Naming the first image of the minority.
    """
    paths, names, heads = _headers_of(paths, names, heads)
    grey = [k for k, h in enumerate(heads) if h is not None and h.grey]
    colour = [k for k, h in enumerate(heads) if h is not None and not h.grey]
    if not (grey and colour):
        return
    few, many = (grey, "colour") if len(grey) <= len(colour) else (colour, "grey")
    kind = "grey (one channel)" if many == "colour" else "colour"
    most = colour if many == "colour" else grey
    raise InputError(f"is {kind} but {len(most)} of the {len(grey) + len(colour)} {what} are {many} (e.g. "
                     f"{names[most[0]]!r}): {whole} mixing grey and colour images is almost always a wrong export; "
                     f"export every one {'in colour' if many == 'colour' else 'grey'}", paths[few[0]])


def check_one_bit_depth(paths, names=None, heads=None, what: str = "photos", whole: str = "a capture") -> None:
    """Refuse integer images of one camera (a capture's photos) that mix 8-bit and 16-bit files.

    Both decode to the same scale, but a camera's 8-bit JPEGs and a raw converter's 16-bit
    exports carry different tone curves, which one stated encoding cannot both undo: such a mix
    is almost always a wrong export. The minority is named (on a tie, the images not of the
    first image's depth). Arguments as :func:`check_one_colour_kind`; floating point images
    and headers that do not say (``ImageHeader.bits`` None) are not counted.

    Raises
    ------
    InputError
        Naming the first image of the minority depth.
    """
    paths, names, heads = _headers_of(paths, names, heads)
    bits = [h.bits if h is not None else None for h in heads]
    known = [b for b in bits if b is not None]
    if len(set(known)) <= 1:
        return
    common = max(known, key=known.count)  # (the first image's depth on a tie)
    odd = next(k for k, b in enumerate(bits) if b is not None and b != common)
    first = bits.index(common)
    raise InputError(f"is a {bits[odd]}-bit image but {known.count(common)} of the {len(known)} {what} are "
                     f"{common}-bit (e.g. {names[first]!r}): {whole} mixing 8-bit and 16-bit images is almost "
                     "always a wrong export (a camera's JPEGs and a raw converter's exports carry different "
                     f"tone curves, which one encoding cannot both undo); export every one at {common} bits",
                     paths[odd])


def check_one_orientation(paths, names=None, heads=None, what: str = "photos") -> None:
    """Refuse images of one fixed camera (a capture's photos, a bracket) whose EXIF orientations differ.

    They share their pixel grid, and a camera that looks down (at a turntable, a table top) tags
    its shots upright or turned as its tilt sensor wavers: read as viewers show them, some would
    be turned against the others. The minority is named.

    Parameters
    ----------
    paths : sequence of path-like
    names : sequence of str, optional
        How the message names the images (default: the file names).
    heads : sequence of ImageHeader or None, optional
        Their headers, when already read (:func:`image_header`; None where unreadable).

    Raises
    ------
    InputError
        Naming the first image of a minority orientation.
    """
    paths, names, heads = _headers_of(paths, names, heads)
    turns = [h.orientation for h in heads if h is not None]
    if len(set(turns)) <= 1:
        return
    common = max(sorted(set(turns)), key=turns.count)
    odd = next(k for k, h in enumerate(heads) if h is not None and h.orientation != common)
    first = next(k for k, h in enumerate(heads) if h is not None and h.orientation == common)
    turn = heads[odd].orientation
    raise InputError(f"its EXIF orientation is {turn} ({ORIENTATION_NAMES[turn]}) but {turns.count(common)} of the "
                     f"{len(turns)} {what} are {common} ({ORIENTATION_NAMES[common]}, e.g. {names[first]!r}): the "
                     f"{what} of one fixed camera share their pixels' layout, and a camera's tilt sensor tags shots "
                     "that look down either way; export them with one orientation (e.g. exiftool -Orientation=1 -n)",
                     paths[odd])


def _exif_orientation(im) -> int:
    """The EXIF orientation of an open Pillow image (1 where it gives none, or a value outside 1 to 8).

    A PNG's ``eXIf`` chunk counts where the PNG specification puts it, before the image data
    (Pillow has read it on opening; one after the data would need the whole image decoded).
    """
    if im.format != "TIFF" and "exif" not in im.info:
        return 1
    try:
        turn = im.getexif().get(_ORIENTATION_TAG, 1)
    except Exception:  # (a damaged EXIF block: the photo as stored, as viewers show it)
        return 1
    return turn if isinstance(turn, int) and 1 <= turn <= 8 else 1


# Pillow modes of one colour channel (with or without alpha)
_GREY_MODES = {"1", "L", "LA", "La", "I", "F", "I;16", "I;16B", "I;16L", "I;16N", "PA"}


def _pillow_reader(kind: str):
    """Pillow's reader of one format (PNG, JPEG, TIFF; None for others), not ``Image.open``: that
    refuses (or warns about) large sizes, which are the caller's to judge."""
    from PIL import JpegImagePlugin, PngImagePlugin, TiffImagePlugin

    return {"png": PngImagePlugin.PngImageFile, "jpeg": JpegImagePlugin.JpegImageFile,
            "tiff": TiffImagePlugin.TiffImageFile}.get(kind)


def _integer_bits(im, kind: str) -> int | None:
    """The bit depth (8 or 16) OpenCV decodes an open Pillow image of ``kind`` to; None where unsure."""
    if kind == "png":  # (Pillow unpacks 16-bit samples with a raw mode such as "RGB;16B" or "I;16B")
        return 16 if any(";16" in str(t.args) for t in im.tile) else 8
    if kind == "jpeg":
        return 8 if getattr(im, "bits", 8) == 8 else None
    samples = im.tag_v2.get(258, (1,))  # TIFF BitsPerSample; SampleFormat 3 is floating point
    samples = samples if isinstance(samples, tuple) else (samples,)
    formats = im.tag_v2.get(339, (1,))
    if 3 in (formats if isinstance(formats, tuple) else (formats,)):
        return None
    top = max(samples)
    return 16 if top == 16 else 8 if top <= 8 else None


def image_header(path: str | os.PathLike) -> ImageHeader | None:
    """Size and channel count of an image file from its header alone, without decoding it.

    OpenEXR through its bindings' header-only read, PNG/JPEG/TIFF through Pillow (which reads
    the header lazily), Radiance ``.hdr`` from its resolution line. A check of a photo's size
    thus costs a fraction of a millisecond, where decoding a 12000x12000 PNG to find it takes
    seconds and gigabytes.

    Returns
    -------
    ImageHeader or None
        None where the header cannot be read here (a sample format Pillow does not know, such as
        a float TIFF, a corrupt file): :func:`read_image`
        then decodes the file and reports what is wrong with it.
    """
    path = Path(path)
    kind = _KINDS.get(path.suffix.lower())
    try:
        if kind == "exr":
            import OpenEXR

            with quiet_native_output():
                header = OpenEXR.File(str(path), header_only=True).header()
            # the display window: a data window that differs is refused by read_exr, which says so
            (x0, y0), (x1, y1) = (tuple(int(v) for v in c) for c in header["displayWindow"])
            names = {ch.name for ch in header["channels"]}
            grey = not {"R", "G", "B"} <= names and "Y" in names and not names & {"RY", "BY"}
            return ImageHeader(x1 - x0 + 1, y1 - y0 + 1, grey)
        if kind == "hdr":  # text lines, a blank line, then e.g. "-Y 480 +X 640" (or "+X 640 -Y 480")
            with open(path, "rb") as f:
                found = _radiance_resolution(f.read(65536))
            if found is None:
                return None
            a1, n1, _, n2 = found[2]
            h, w = (n1, n2) if a1[1:] == b"Y" else (n2, n1)
            return ImageHeader(int(w), int(h), False)
        if kind in ("png", "jpeg", "tiff"):
            with _pillow_reader(kind)(path) as im:
                (w, h), mode = im.size, im.mode
                turn = _exif_orientation(im)
                bits = _integer_bits(im, kind)
            if turn >= 5 and kind != "tiff":  # (Pillow gives a TIFF's size as displayed already)
                w, h = h, w
            return ImageHeader(int(w), int(h), mode in _GREY_MODES, turn, bits)
    except Exception:  # (unreadable here: read_image decodes it and names what is wrong)
        return None
    return None


def exr_chromaticities(path: str | os.PathLike) -> tuple | None:
    """The ``chromaticities`` attribute of an OpenEXR file (8 floats), read from the header only; None when absent."""
    import OpenEXR

    path = Path(path)
    try:
        header = OpenEXR.File(str(path), header_only=True).header()
    except Exception as e:  # the bindings raise RuntimeError/others with multi-line text
        raise InputError(f"cannot read OpenEXR file ({type(e).__name__}: {e})", path) from None
    c = header.get("chromaticities")
    return None if c is None else tuple(np.asarray(c, dtype=np.float64).reshape(-1).tolist())


def _radiance_primaries(path: Path) -> tuple | None:
    """The ``PRIMARIES`` of a Radiance file's header (:func:`_radiance_header`), None when absent or unreadable."""
    try:
        with open(path, "rb") as f:
            return _radiance_header(f.read(65536), path)[1]
    except OSError:
        return None  # (read_image names it)


def colour_summary(paths) -> str | None:
    """One line saying which of the image files ``paths`` are converted to the working space on reading.

    Reads only the headers of the ``.exr`` and Radiance files (the others carry no colour space
    ffls reads).
    E.g. ``"colour: 12 of 12 images: colour space ACEScg (...) converted to linear Rec.709 (D65), ..."``.

    Returns
    -------
    str or None
        None when no file needs a conversion.

    Raises
    ------
    InputError
        A file whose colour space cannot be converted (as :func:`read_image` would).
    """
    from ffls.io.colourspace import working_space_conversion

    paths = [Path(p) for p in paths]
    notes = []
    for p in paths:
        if _KINDS.get(p.suffix.lower()) not in ("exr", "hdr"):
            continue
        c = exr_chromaticities(p) if p.suffix.lower() == ".exr" else _radiance_primaries(p)
        conv = None if c is None else working_space_conversion(c, p)
        if conv is not None:
            notes.append(conv.describe())
    if not notes:
        return None
    kinds = sorted(set(notes))
    head = f"colour: {len(notes)} of {len(paths)} images: " if len(paths) > 1 else "colour: "
    return head + kinds[0] + (f" (and {len(kinds) - 1} other spaces)" if len(kinds) > 1 else "")


# ----------------------------------------------------------------------------- writers
def _check_rgb(rgb, what: str) -> np.ndarray:
    a = np.asarray(rgb)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{what}: expected an (H, W, 3) RGB array, got shape {a.shape}")
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"{what}: expected a numeric array, got dtype {a.dtype}")
    return a


def _check_alpha(alpha, shape, what: str) -> np.ndarray:
    m = np.asarray(alpha, dtype=np.float32)
    if m.shape != tuple(shape):
        raise ValueError(f"{what}: alpha must have shape {tuple(shape)}, got {m.shape}")
    if not np.all(np.isfinite(m)) or m.min() < 0 or m.max() > 1:
        raise ValueError(f"{what}: alpha must be finite and in [0, 1]")
    return m


def premultiply(rgb, alpha) -> np.ndarray:
    """``rgb`` (H, W, 3) times ``alpha`` (H, W): OpenEXR's premultiplied RGBA convention."""
    m = _check_alpha(alpha, np.asarray(rgb).shape[:2], "premultiply")
    return np.asarray(rgb, dtype=np.float32) * m[..., None]


def with_alpha(rgb8, alpha) -> np.ndarray:
    """Display values (H, W, 3) uint8/uint16 with ``alpha`` (H, W) in [0, 1] as RGBA of the same dtype
    (PNG's straight, not premultiplied, alpha)."""
    a = np.asarray(rgb8)
    m = _check_alpha(alpha, a.shape[:2], "with_alpha")
    top = np.iinfo(a.dtype).max
    return np.concatenate([a, np.rint(m * top).astype(a.dtype)[..., None]], axis=-1)


def _check_suffix(path: Path, allowed: tuple[str, ...], what: str) -> None:
    if path.suffix.lower() not in allowed:
        raise ValueError(f"{what}: {path} must end with {' or '.join(allowed)}")


def _imwrite(path: Path, data: np.ndarray) -> None:
    """``cv2.imwrite`` through :func:`ffls.errors.atomic_output`, its return value and the file checked."""
    import cv2

    _silence_opencv_log()
    with atomic_output(path) as tmp:
        with quiet_native_output() as cap:
            try:
                ok = cv2.imwrite(str(tmp), data)
            except cv2.error:
                ok = False
        if not ok:
            raise OutputError(f"OpenCV could not write the image ({cap.first_line() or 'disk full or no permission'})",
                              path)


def write_exr(path: str | os.PathLike, rgb, half: bool = False, alpha=None, attributes=None) -> Path:
    """Write an RGB (or RGBA) OpenEXR file with ZIP compression, atomically.

    Parameters
    ----------
    path : path-like
        Output ``.exr`` path.
    rgb : (H, W, 3) array_like
        Linear values, written as given. OpenEXR's RGBA is premultiplied: pass ``rgb`` already
        multiplied by ``alpha`` (:func:`ffls.io.images.premultiply`) for compositing.
    half : bool
        Store 16-bit half floats instead of 32-bit floats.
    alpha : (H, W) array_like, optional
        Coverage in [0, 1], written as channel ``A``.
    attributes : dict of str to str, optional
        String attributes added to the header (what made the image, e.g. ``{"ffls:pocs_scheme":
        "least-power"}``); read back by ``OpenEXR.File(path).header()``.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        Wrong shape or extension; an attribute that is not a string, or that names a standard
        header attribute.
    HalfRangeError
        (a ValueError) ``half=True`` and finite values beyond the half range (+-65504), which
        would silently become infinite (:func:`check_half_range`: one line naming ``path``).
    """
    import OpenEXR

    path = Path(path)
    _check_suffix(path, (".exr",), "write_exr")
    a = _check_rgb(rgb, "write_exr")
    if half:
        check_half_range(a, path)
    a = a.astype(np.float32, copy=False)
    dtype = np.float16 if half else np.float32
    # OpenEXR 3.x mis-writes non-contiguous channel views without error: copy each channel.
    channels = {c: np.ascontiguousarray(a[:, :, i], dtype=dtype) for i, c in enumerate("RGB")}
    if alpha is not None:
        channels["A"] = np.ascontiguousarray(_check_alpha(alpha, a.shape[:2], "write_exr"), dtype=dtype)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (attributes or {}).items():
        if not (isinstance(key, str) and isinstance(value, str)) or key in header or key in (
                "channels", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
                "screenWindowCenter", "screenWindowWidth"):
            raise ValueError(f"write_exr: attribute {key!r}: {value!r} must be a string attribute of "
                             "a string name that is not a standard one")
        header[key] = value
    with atomic_output(path) as tmp:
        with quiet_native_output() as cap:
            try:
                with OpenEXR.File(header, channels) as f:
                    f.write(str(tmp))
                err = None
            except Exception as e:  # a full disk, ...: the bindings raise RuntimeError
                err = e
        if err is not None:
            why = cap.first_line() or str(err)
            if "No space left" in why:  # (OpenEXR's text names the temporary file)
                why = os_error_message(OSError(errno.ENOSPC, why))
            raise OutputError(f"cannot write OpenEXR file ({why})", path) from None
    return path


def write_hdr(path: str | os.PathLike, rgb) -> Path:
    """Write a Radiance RGBE ``.hdr`` file atomically.

    Parameters
    ----------
    path : path-like
        Output ``.hdr`` path.
    rgb : (H, W, 3) array_like
        Linear, finite, non-negative values (RGBE stores neither negatives nor NaN/Inf).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        Wrong shape or extension, negative or non-finite values.
    """
    path = Path(path)
    _check_suffix(path, (".hdr", ".pic"), "write_hdr")
    a = _check_rgb(rgb, "write_hdr").astype(np.float32, copy=False)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"write_hdr: {int(np.count_nonzero(~np.isfinite(a)))} non-finite values")
    if (a < 0).any():
        raise ValueError(f"write_hdr: {int(np.count_nonzero(a < 0))} negative values (RGBE cannot store them)")
    bgr = np.ascontiguousarray(a[:, :, ::-1])
    _imwrite(path, bgr)
    return path


def write_png(path: str | os.PathLike, img) -> Path:
    """Write an 8- or 16-bit PNG atomically.

    Parameters
    ----------
    path : path-like
        Output ``.png`` path.
    img : (H, W), (H, W, 3) or (H, W, 4) uint8 or uint16 ndarray
        Grey, RGB or RGBA, already encoded for display (see :func:`ffls.display.tonemap.to_uint8`).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        Float input (tone-map and quantise first), another dtype, shape or extension.
    """
    path = Path(path)
    _check_suffix(path, (".png",), "write_png")
    a = np.asarray(img)
    if a.dtype not in (np.uint8, np.uint16):
        if np.issubdtype(a.dtype, np.floating):
            raise ValueError(
                "write_png: float input is not accepted; tone-map it (ffls.display.tonemap.tonemap) and "
                "quantise it (ffls.display.tonemap.to_uint8) first"
            )
        raise ValueError(f"write_png: expected uint8 or uint16, got dtype {a.dtype}")
    if a.ndim == 2:
        out = a
    elif a.ndim == 3 and a.shape[2] == 3:
        out = a[:, :, ::-1]
    elif a.ndim == 3 and a.shape[2] == 4:
        out = a[:, :, [2, 1, 0, 3]]
    else:
        raise ValueError(f"write_png: expected (H, W), (H, W, 3) or (H, W, 4), got shape {a.shape}")
    out = np.ascontiguousarray(out)
    _imwrite(path, out)
    return path
