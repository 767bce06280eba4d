"""Camera effects applied to a linear render, so that synthetic captures look like photographs.

Each effect is one pure function on arrays, applied in the order a camera applies them:

1. :func:`expose`: scale the scene radiance to the sensor's full scale (1.0 = saturation);
2. :func:`vignette`: the lens' radial falloff, ``cos^4`` of the off-axis angle (a pinhole ``K``)
   or a radial polynomial ``1 + a r^2 + b r^4 + c r^6`` (``r`` = distance from the image centre
   over the half diagonal; the model of Goldman, "Vignette and exposure calibration and
   compensation", PAMI 2010);
3. :func:`sensor_noise`: Poisson-Gaussian sensor noise (Foi et al., "Practical Poissonian-Gaussian
   noise modeling and fitting for single-image raw-data", IEEE TIP 2008): shot noise of variance
   ``gain * x`` plus read noise of standard deviation ``read_noise``, in full-scale units;
4. :func:`encode`: clipping at full scale (the sensor saturates) and the transfer curve
   (``'linear'``, ``'srgb'`` IEC 61966-2-1, ``'gamma2.2'``, ``x ** (1 / 2.2)``, or ``'filmic'``, a
   camera-like S-shaped tone curve that is neither sRGB nor a gamma: :func:`filmic_encode`);
5. :func:`quantise`: to 8 or 16 bits;
6. :func:`write_photo`: EXR (linear half or float), PNG (8/16 bits), TIFF (16 bits) or JPEG at a
   given quality (``cv2.imencode``), always written atomically.

:class:`PhotoSettings` holds the settings of all of them and :func:`develop` chains them; both
are what :func:`ffls.synth.scene.write_synthetic_capture` uses and records in ``truth.json``.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ffls.errors import atomic_output
from ffls.io.images import write_exr, write_png
from ffls.radiance.encoding import srgb_decode, srgb_encode

__all__ = [
    "CURVES",
    "FORMATS",
    "PhotoSettings",
    "expose",
    "vignetting_factor",
    "vignette",
    "sensor_noise",
    "encode",
    "decode",
    "quantise",
    "develop",
    "write_photo",
    "gamma_response_table",
    "filmic_encode",
    "filmic_decode",
    "response_table",
]

#: Transfer curves of :func:`encode`.
CURVES = ("linear", "srgb", "gamma2.2", "filmic")
#: Hable's (2010) filmic curve: shoulder strength, linear strength, linear angle, toe strength, toe
#: numerator and denominator, and the linear white point (the scene value that reaches full scale).
_HABLE = (0.15, 0.50, 0.10, 0.20, 0.02, 0.30)
_HABLE_WHITE = 11.2
#: File formats: name -> (extension, bits per channel; None = float EXR).
FORMATS = {"exr": ("exr", None), "png8": ("png", 8), "png16": ("png", 16), "tiff16": ("tiff", 16),
           "jpeg": ("jpg", 8)}
_GAMMA = 2.2
_HALF_MAX = 65504.0


@dataclass(frozen=True)
class PhotoSettings:
    """How a linear render becomes a photograph (see the module docstring for the order).

    Parameters
    ----------
    file_format : {'exr', 'png8', 'png16', 'tiff16', 'jpeg'}
    curve : {'linear', 'srgb', 'gamma2.2', 'filmic'}
        Transfer curve of integer formats; EXR is always linear.
    exposure : float
        Scale from scene radiance to full scale (1.0 saturates).
    vignetting : {'none', 'cos4', 'radial'}
    vignetting_coeffs : tuple of up to 3 floats
        ``(a, b, c)`` of the radial polynomial (``'radial'`` only).
    shot_gain : float
        Full-scale units per photo-electron (shot-noise variance ``shot_gain * x``); 0 = none.
    read_noise : float
        Standard deviation of the read noise, full-scale units; 0 = none.
    noise : float
        Gaussian noise added to the *encoded* value before quantisation (or to the linear value
        for EXR), fraction of full scale: the historical ``ffls synth --noise``.
    jpeg_quality : int
        0..100, JPEG only.
    state_encoding : bool
        Whether ``capture.json`` states the encoding (False: the key is left out; ``truth.json``
        still records it).
    """

    file_format: str = "exr"
    curve: str = "linear"
    exposure: float = 1.0
    vignetting: str = "none"
    vignetting_coeffs: tuple = ()
    shot_gain: float = 0.0
    read_noise: float = 0.0
    noise: float = 0.0
    jpeg_quality: int = 90
    state_encoding: bool = True

    def __post_init__(self):
        object.__setattr__(self, "vignetting_coeffs", tuple(float(c) for c in self.vignetting_coeffs))
        if self.file_format not in FORMATS:
            raise ValueError(f"file_format must be one of {tuple(FORMATS)}, not {self.file_format!r}")
        if self.curve not in CURVES:
            raise ValueError(f"curve must be one of {CURVES}, not {self.curve!r}")
        if self.file_format == "exr" and self.curve != "linear":
            raise ValueError("an EXR file is linear: use curve='linear' with file_format='exr'")
        if not (math.isfinite(self.exposure) and self.exposure > 0):
            raise ValueError(f"exposure must be > 0, not {self.exposure}")
        if self.vignetting not in ("none", "cos4", "radial"):
            raise ValueError(f"vignetting must be 'none', 'cos4' or 'radial', not {self.vignetting!r}")
        if len(self.vignetting_coeffs) > 3 or (self.vignetting == "radial") != bool(self.vignetting_coeffs):
            raise ValueError("vignetting_coeffs: 1 to 3 numbers with 'radial', none otherwise")
        for name in ("shot_gain", "read_noise", "noise"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be >= 0, not {v}")
        if not 0 <= int(self.jpeg_quality) <= 100:
            raise ValueError(f"jpeg_quality must be in 0..100, not {self.jpeg_quality}")

    @property
    def bits(self) -> int | None:
        """Bits per channel of the file (None for float EXR)."""
        return FORMATS[self.file_format][1]

    @property
    def extension(self) -> str:
        return FORMATS[self.file_format][0]

    @property
    def gamma(self) -> float | None:
        """The exponent of a pure power curve (1.0 linear, 2.2), None for sRGB."""
        return {"linear": 1.0, "gamma2.2": _GAMMA}.get(self.curve)

    def to_json(self) -> dict:
        d = asdict(self)
        d["vignetting_coeffs"] = list(self.vignetting_coeffs)
        d.update(bits=self.bits, gamma=self.gamma)
        return d


# ============================================================================ effects
def expose(img, scale: float) -> np.ndarray:
    """Scene radiance times ``scale`` (full scale = 1). (H, W, 3) float -> float64."""
    return np.asarray(img, dtype=np.float64) * float(scale)


def vignetting_factor(shape, model: str, coeffs=(), K=None) -> np.ndarray:
    """(H, W) float64 relative illumination of each pixel (1 on the optical axis).

    Parameters
    ----------
    shape : (H, W)
    model : {'none', 'cos4', 'radial'}
        ``'cos4'``: ``cos(theta)^4`` of the angle between the pixel's ray and the optical axis
        (needs the pinhole ``K``); ``'radial'``: ``1 + a r^2 + b r^4 + c r^6`` with ``r`` the
        distance from the image centre ``((W - 1) / 2, (H - 1) / 2)`` over the half diagonal,
        clipped at 0.
    coeffs : tuple of up to 3 floats
        ``(a, b, c)`` for ``'radial'``.
    K : (3, 3) float, optional
    """
    H, W = int(shape[0]), int(shape[1])
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    if model == "none":
        return np.ones((H, W))
    if model == "cos4":
        if K is None:
            raise ValueError("cos4 vignetting needs a pinhole K (an orthographic lens has none: use 'radial')")
        K = np.asarray(K, dtype=np.float64)
        x = (u - K[0, 2]) / K[0, 0]
        y = (v - K[1, 2]) / K[1, 1]
        return 1.0 / (1.0 + x * x + y * y) ** 2
    if model == "radial":
        r2 = ((u - 0.5 * (W - 1)) ** 2 + (v - 0.5 * (H - 1)) ** 2) / (0.25 * ((W - 1) ** 2 + (H - 1) ** 2) or 1.0)
        return np.maximum(radial_falloff(r2, coeffs), 0.0)
    raise ValueError(f"unknown vignetting model {model!r}")


def radial_falloff(r2, coeffs) -> np.ndarray:
    """``1 + a r^2 + b r^4 + c r^6`` (not clipped) of the ``'radial'`` vignetting model.

    Parameters
    ----------
    r2 : float ndarray
        Squared distance from the image centre over the half diagonal (1 at the corners).
    coeffs : tuple of up to 3 floats
        ``(a, b, c)``.

    Returns
    -------
    float64 ndarray, the shape of ``r2``
    """
    f = np.ones_like(r2, dtype=np.float64)
    for k, c in enumerate(coeffs):
        f += c * r2 ** (k + 1)
    return f


def vignette(img, model: str, coeffs=(), K=None) -> np.ndarray:
    """``img`` (H, W, 3) times :func:`vignetting_factor`."""
    img = np.asarray(img, dtype=np.float64)
    return img * vignetting_factor(img.shape[:2], model, coeffs, K)[:, :, None]


def sensor_noise(img, rng: np.random.Generator, shot_gain: float, read_noise: float) -> np.ndarray:
    """Poisson-Gaussian noise on a linear image in full-scale units (before clipping).

    ``y = shot_gain * Poisson(x / shot_gain) + Normal(0, read_noise)``: mean ``x``, variance
    ``shot_gain * x + read_noise^2``. Negative ``x`` is taken as 0 for the shot noise.
    """
    x = np.asarray(img, dtype=np.float64)
    if shot_gain > 0:
        x = shot_gain * rng.poisson(np.maximum(x, 0.0) / shot_gain)
    if read_noise > 0:
        x = x + rng.normal(0.0, read_noise, x.shape)
    return x


def _hable(x: np.ndarray) -> np.ndarray:
    A, B, C, D, E, F = _HABLE
    return (x * (A * x + C * B) + D * E) / (x * (A * x + B) + D * F) - E / F


def filmic_encode(x) -> np.ndarray:
    """A camera-like tone curve: Hable's filmic operator (2010), then the sRGB encoding.

    ``encoded = srgb(h(W x) / h(W))`` with Hable's ``h(x) = (x (A x + C B) + D E) / (x (A x + B) +
    D F) - E / F`` and his published constants (``A`` 0.15, ``B`` 0.50, ``C`` 0.10, ``D`` 0.20,
    ``E`` 0.02, ``F`` 0.30, white point ``W`` 11.2). Its toe darkens the shadows and its shoulder
    rolls off the highlights: an S-shaped curve in the logarithm, as in-camera JPEG rendering
    applies, that no gamma and not the sRGB curve follows (from 5 to 8 code values apart on
    [0.03, 0.97]). Full scale stays 1.

    Parameters
    ----------
    x : (...) array_like
        Linear values in [0, 1] (clipped).

    Returns
    -------
    (...) float64 ndarray in [0, 1]
    """
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.clip(srgb_encode(_hable(_HABLE_WHITE * x) / _hable(np.float64(_HABLE_WHITE))), 0.0, 1.0)


def filmic_decode(values) -> np.ndarray:
    """Inverse of :func:`filmic_encode` on [0, 1] values (float64): monotone interpolation of a
    dense table of the curve (2^16 + 1 samples; it is strictly increasing)."""
    t = np.linspace(0.0, 1.0, 65537)
    return np.interp(np.asarray(values, dtype=np.float64), filmic_encode(t), t)


def encode(img, curve: str) -> np.ndarray:
    """Clip a linear image to [0, 1] (saturation) and apply the transfer curve; float64 in [0, 1]."""
    x = np.clip(np.asarray(img, dtype=np.float64), 0.0, 1.0)
    if curve == "linear":
        return x
    if curve == "srgb":
        return np.clip(srgb_encode(x), 0.0, 1.0)
    if curve == "gamma2.2":
        return x ** (1.0 / _GAMMA)
    if curve == "filmic":
        return filmic_encode(x)
    raise ValueError(f"curve must be one of {CURVES}, not {curve!r}")


def decode(values, curve: str) -> np.ndarray:
    """Inverse of :func:`encode` on [0, 1] values (float64)."""
    x = np.asarray(values, dtype=np.float64)
    if curve == "linear":
        return x
    if curve == "srgb":
        return srgb_decode(x).astype(np.float64)
    if curve == "gamma2.2":
        return np.clip(x, 0.0, None) ** _GAMMA
    if curve == "filmic":
        return filmic_decode(x)
    raise ValueError(f"curve must be one of {CURVES}, not {curve!r}")


def quantise(values, bits: int) -> np.ndarray:
    """Round [0, 1] values to ``bits`` (8 or 16) integer codes: uint8 or uint16."""
    if bits not in (8, 16):
        raise ValueError(f"bits must be 8 or 16, not {bits}")
    top = (1 << bits) - 1
    return np.rint(np.clip(values, 0.0, 1.0) * top).astype(np.uint8 if bits == 8 else np.uint16)


def develop(img, settings: PhotoSettings, rng: np.random.Generator, K=None) -> np.ndarray:
    """A linear render (H, W, 3) -> the stored array of ``settings.file_format``.

    Float32 linear for EXR (exposure, vignetting and noise applied, no clipping); uint8 or
    uint16 codes otherwise.
    """
    x = expose(img, settings.exposure)
    x = vignette(x, settings.vignetting, settings.vignetting_coeffs, K)
    x = sensor_noise(x, rng, settings.shot_gain, settings.read_noise)
    if settings.bits is None:
        if settings.noise > 0:
            x = x + rng.normal(0.0, settings.noise, x.shape)
        return x.astype(np.float32)
    enc = encode(x, settings.curve)
    if settings.noise > 0:
        enc = enc + rng.normal(0.0, settings.noise, enc.shape)
    return quantise(enc, settings.bits)


def write_photo(path, data, settings: PhotoSettings) -> Path:
    """Write what :func:`develop` returned, atomically, in ``settings.file_format``.

    EXR is half float when every value fits (|x| <= 65504), float otherwise (a very bright
    mirror highlight at a large exposure).
    """
    import cv2

    path = Path(path)
    fmt = settings.file_format
    if fmt == "exr":
        a = np.asarray(data, dtype=np.float32)
        return write_exr(path, a, half=bool(np.abs(a).max(initial=0.0) <= _HALF_MAX))
    if fmt in ("png8", "png16"):
        return write_png(path, data)
    bgr = np.ascontiguousarray(np.asarray(data)[:, :, ::-1])
    if fmt == "tiff16":
        ok, buf = cv2.imencode(".tiff", bgr)
    else:
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(settings.jpeg_quality)])
    if not ok:
        raise OSError(f"OpenCV could not encode {path}")
    with atomic_output(path) as tmp:
        tmp.write_bytes(buf.tobytes())
    return path


def gamma_response_table(gamma: float = _GAMMA) -> np.ndarray:
    """(256,) float64 inverse response of an 8-bit pure power curve: code ``v`` -> ``(v / 255) ** gamma``.

    The ``{"response": file}`` form of ``capture.json``'s ``encoding`` (docs/formats.md).
    """
    return (np.arange(256) / 255.0) ** float(gamma)


def response_table(curve: str) -> np.ndarray:
    """(256,) float64 inverse response of 8-bit codes under ``curve`` (:func:`decode` of ``v / 255``):
    what ``capture.json`` states, as ``{"response": file}``, for curves that are neither sRGB nor linear."""
    return decode(np.arange(256) / 255.0, curve)
