"""Images in and out: OpenEXR (half/float), Radiance .hdr, PNG/JPEG/TIFF; every write is atomic.

Readers return RGB in file order (OpenCV's BGR is swapped), float32, without any transfer
function applied: linearising 8-bit photographs is the capture's job (``ffls.io.capture``), never
guessed here. Bad input raises :class:`ffls.errors.InputError` naming the file.

OpenEXR goes through the OpenEXR 3.x Python bindings (``OpenEXR.File``), the rest through
OpenCV. OpenCV cannot read TGA; such files are rejected with a message saying so.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffls.errors import InputError, atomic_output

__all__ = [
    "ImageData",
    "READ_EXTENSIONS",
    "read_image",
    "read_exr",
    "write_exr",
    "write_hdr",
    "write_png",
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
    """

    pixels: np.ndarray
    bit_depth: int | str
    kind: str
    path: Path

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W)."""
        return self.pixels.shape[:2]

    @property
    def is_hdr(self) -> bool:
        """True for floating-point storage (EXR, .hdr, float TIFF)."""
        return self.bit_depth in ("half", "float")


def _kind_of(path: Path) -> str:
    ext = path.suffix.lower()
    if ext in _KINDS:
        return _KINDS[ext]
    if ext == ".tga":
        raise InputError("TGA images are not supported (OpenCV cannot read TGA); convert to PNG or TIFF", path)
    raise InputError(
        f"unsupported image format {ext or '(no extension)'!r}; supported: {', '.join(READ_EXTENSIONS)}", path
    )


def read_image(path: str | os.PathLike) -> ImageData:
    """Read an image file as RGB float32.

    Parameters
    ----------
    path : path-like
        An ``.exr``, ``.hdr``/``.pic``, ``.png``, ``.jpg``/``.jpeg`` or ``.tif``/``.tiff`` file.

    Returns
    -------
    ImageData
        ``pixels`` is (H, W, 3) float32. Grey images are replicated to three channels and alpha
        is dropped.

    Raises
    ------
    InputError
        If the file is missing, unreadable, corrupt or of an unsupported format.
    """
    path = Path(path)
    kind = _kind_of(path)
    if not path.is_file():
        raise InputError("image file not found" if not path.exists() else "not a file", path)
    if kind == "exr":
        return read_exr(path)
    return _read_cv2(path, kind)


def read_exr(path: str | os.PathLike) -> ImageData:
    """Read an OpenEXR file (half or float channels) as RGB float32.

    Takes the ``R``, ``G``, ``B`` channels, or replicates ``Y`` for luminance-only files; other
    channels (alpha, depth, ...) are ignored.

    Parameters
    ----------
    path : path-like
        The ``.exr`` file.

    Returns
    -------
    ImageData
        ``pixels`` (H, W, 3) float32, ``bit_depth`` ``'half'`` or ``'float'``.

    Raises
    ------
    InputError
        Missing, corrupt, or without R/G/B or Y channels, or with integer/subsampled channels.
    """
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise InputError("image file not found", path)
    try:
        f = OpenEXR.File(str(path), separate_channels=True)
        channels = f.channels()
    except Exception as e:  # the bindings raise RuntimeError/others with multi-line text
        raise InputError(f"cannot read OpenEXR file ({type(e).__name__}: {e})", path) from None
    names = set(channels)
    if {"R", "G", "B"} <= names:
        use = ["R", "G", "B"]
    elif "Y" in names:
        use = ["Y", "Y", "Y"]
    else:
        raise InputError(f"OpenEXR file has no R, G, B or Y channels (has {sorted(names)})", path)
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
        planes.append(px.astype(np.float32))
    if len({p.shape for p in planes}) != 1:
        raise InputError("OpenEXR channels differ in size", path)
    return ImageData(np.stack(planes, axis=-1), depth, "exr", path)


def _read_cv2(path: Path, kind: str) -> ImageData:
    import cv2

    try:
        buf = np.fromfile(str(path), dtype=np.uint8)
    except OSError as e:
        raise InputError(f"cannot read file ({e.strerror or e})", path) from None
    if buf.size == 0:
        raise InputError("image file is empty", path)
    flags = cv2.IMREAD_UNCHANGED if kind != "hdr" else cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR
    try:
        img = cv2.imdecode(buf, flags)
    except cv2.error:
        img = None
    if img is None:
        raise InputError(f"cannot decode {kind.upper()} image (corrupt or not a {kind.upper()} file)", path)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    elif img.shape[2] == 2:  # grey + alpha
        img = np.repeat(img[:, :, :1], 3, axis=2)
    elif img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    else:
        img = img[:, :, 2::-1]  # BGR(A) -> RGB, alpha dropped
    dt = img.dtype
    if dt == np.uint8:
        pixels, depth = img.astype(np.float32) / np.float32(255), 8
    elif dt == np.uint16:
        pixels, depth = img.astype(np.float32) / np.float32(65535), 16
    elif dt == np.float32:
        pixels, depth = img.astype(np.float32), "float"
    elif dt == np.float16:
        pixels, depth = img.astype(np.float32), "half"
    elif dt == np.float64:
        pixels, depth = img.astype(np.float32), "float"
    else:
        raise InputError(f"unsupported pixel type {dt} in {kind.upper()} image", path)
    return ImageData(np.ascontiguousarray(pixels), depth, kind, path)


# ----------------------------------------------------------------------------- writers
def _check_rgb(rgb, what: str) -> np.ndarray:
    a = np.asarray(rgb)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{what}: expected an (H, W, 3) RGB array, got shape {a.shape}")
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"{what}: expected a numeric array, got dtype {a.dtype}")
    return a


def _check_suffix(path: Path, allowed: tuple[str, ...], what: str) -> None:
    if path.suffix.lower() not in allowed:
        raise ValueError(f"{what}: {path} must end with {' or '.join(allowed)}")


def write_exr(path: str | os.PathLike, rgb, half: bool = False) -> Path:
    """Write an RGB OpenEXR file with ZIP compression, atomically.

    Parameters
    ----------
    path : path-like
        Output ``.exr`` path.
    rgb : (H, W, 3) array_like
        Linear values.
    half : bool
        Store 16-bit half floats instead of 32-bit floats.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        Wrong shape or extension, or (``half=True``) finite values beyond the half range
        (+-65504), which would silently become infinite.
    """
    import OpenEXR

    path = Path(path)
    _check_suffix(path, (".exr",), "write_exr")
    a = _check_rgb(rgb, "write_exr").astype(np.float32, copy=False)
    dtype = np.float16 if half else np.float32
    if half:
        finite = np.isfinite(a)
        big = finite & (np.abs(a) > _HALF_MAX)
        if big.any():
            raise ValueError(
                f"write_exr: {int(big.sum())} values exceed the half-float range (max |x| = "
                f"{float(np.abs(a[finite]).max()):.6g} > {_HALF_MAX}); scale them or write float"
            )
    # OpenEXR 3.x mis-writes non-contiguous channel views without error: copy each channel.
    channels = {c: np.ascontiguousarray(a[:, :, i], dtype=dtype) for i, c in enumerate("RGB")}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_output(path) as tmp:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))
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
    import cv2

    path = Path(path)
    _check_suffix(path, (".hdr", ".pic"), "write_hdr")
    a = _check_rgb(rgb, "write_hdr").astype(np.float32, copy=False)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"write_hdr: {int(np.count_nonzero(~np.isfinite(a)))} non-finite values")
    if (a < 0).any():
        raise ValueError(f"write_hdr: {int(np.count_nonzero(a < 0))} negative values (RGBE cannot store them)")
    bgr = np.ascontiguousarray(a[:, :, ::-1])
    with atomic_output(path) as tmp:
        if not cv2.imwrite(str(tmp), bgr):
            raise OSError(f"OpenCV could not write {path}")
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
    import cv2

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
    with atomic_output(path) as tmp:
        if not cv2.imwrite(str(tmp), out):
            raise OSError(f"OpenCV could not write {path}")
    return path
