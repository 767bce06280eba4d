"""Putting a relit real object into a virtual scene or a photograph (Masselus et al. 2002, section 7).

The paper's application: capture two reflectance fields with the same camera, the object on a
surface and the surface alone; relight both with a light map made at the object's place in the
virtual scene; and merge them into a render (or photograph) of that scene with *differential
rendering* (Debevec, "Rendering Synthetic Objects into Real Scenes", SIGGRAPH 1998):

    composite = background + (relit object-on-surface - relit surface alone)   over the surface,
    composite = relit object                                                     over the object's mask.

The difference carries what the object does to the surface, its cast shadows and the light it
bounces onto it, and nothing else: wherever the two fields agree (the surface far from the
object, calibration spheres present in both) the background shows unchanged.

* :func:`registration_pixels` picks the surface pixels on which the two relit fields agree (the
  surface region minus the object's mask and the neighbourhood of what it changes).
* :func:`register_surface` fits, on those pixels, a uniform per-channel scale and offset
  ``background ~ scale * surface_relit + offset`` with a robust (soft-L1) loss. The scale
  corrects an exposure or albedo mismatch between the captured surface and the virtual one
  (the difference is multiplied by it); the offset absorbs additive mismatches (flare, a black
  level) so that they do not bias the scale. On a uniformly lit surface the two cannot be told
  apart, and ``mode='auto'`` then fits the scale alone (and says so). The object-on-surface
  field is registered on the same pixels with its own scale and offset: the two captures have
  different lights (another power, another sampling of the map), so their relit surfaces differ
  by a few percent even where the object changes nothing, and that must not be added to the
  whole surface.
* :func:`composite_Debevec1998` is the difference above; :func:`composite_ratio` its
  multiplicative variant, ``background * object_relit / surface_relit`` over the surface, which
  needs no scale and carries a textured background's texture into the shadow (but is noisy where
  the relit surface is dark).
* :func:`composite` chooses between them (``method=``) and returns a :class:`CompositeResult`.
* :class:`Compositor` drives two relighters (:class:`ffls.relight.cpu.CpuRelighter` or the GPU
  :class:`ffls.gpu.engine.Engine`, anything with ``set_lightmap``/``set_rotation``/``render``/
  ``read_hdr``) under one light map, for stills, turntables and the viewer.
* :func:`check_same_camera` refuses two fields captured from different cameras.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ffls.errors import InputError

__all__ = [
    "METHODS",
    "REGISTRATION_MODES",
    "LUMINANCE",
    "Registration",
    "CompositeResult",
    "registration_pixels",
    "register_surface",
    "composite_Debevec1998",
    "composite_ratio",
    "composite",
    "check_same_camera",
    "check_composite_inputs",
    "Compositor",
]

#: ``method=`` of :func:`composite`: Debevec's difference, or the multiplicative variant.
METHODS = ("Debevec1998", "ratio")
#: ``mode=`` of :func:`register_surface`.
REGISTRATION_MODES = ("auto", "scale-offset", "scale", "none")
#: Rec.709 luminance of linear RGB.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: Fewest surface pixels a registration is fitted on.
MIN_REGISTRATION_PIXELS = 50
#: ``mode='auto'`` fits an offset only when the relit surface's brightness spreads this much:
#: (90th - 10th percentile) / median of the registration pixels, every channel.
OFFSET_MIN_SPREAD = 0.25
#: Most pixels a registration fit uses (a fixed-seed subsample beyond).
MAX_FIT_PIXELS = 40000


@dataclass(frozen=True)
class Registration:
    """``background ~ scale * surface_relit + offset`` on the surface, per channel (and the same for the object field).

    Attributes
    ----------
    scale, offset : (3,) float64
        Per-channel scale and offset (radiance units of the background) of the surface-alone field.
    object_field_scale, object_field_offset : (3,) float64 or None
        The same for the object-on-surface field, fitted on the same pixels (None: as the surface's).
    mode : str
        What was fitted: ``'scale-offset'``, ``'scale'``, ``'none'`` or ``'given'``.
    pixels : int
        Surface pixels the fit used (0 for ``'none'``/``'given'``).
    residual : float
        Robust spread (1.4826 MAD) of the luminance residual, relative to the background's median
        luminance on those pixels: how well one scale and offset explain the surface.
    note : str
        Why the mode was chosen (e.g. the offset was left out on a uniformly lit surface).
    """

    scale: np.ndarray
    offset: np.ndarray
    mode: str
    pixels: int = 0
    residual: float = 0.0
    note: str = ""
    object_field_scale: np.ndarray | None = None
    object_field_offset: np.ndarray | None = None

    @property
    def object_scale(self) -> np.ndarray:
        """(3,) scale of the object-on-surface field."""
        return np.asarray(self.scale if self.object_field_scale is None else self.object_field_scale, dtype=np.float64)

    @property
    def object_offset(self) -> np.ndarray:
        """(3,) offset of the object-on-surface field."""
        return np.asarray(self.offset if self.object_field_offset is None else self.object_field_offset,
                          dtype=np.float64)

    def describe(self) -> str:
        """One line: scale and offset per channel, pixels and residual."""
        s = ", ".join(f"{v:.4g}" for v in self.scale)
        o = ", ".join(f"{v:.3g}" for v in self.offset)
        text = f"registration {self.mode}: scale ({s}), offset ({o})"
        if self.object_field_scale is not None:
            so = ", ".join(f"{v:.4g}" for v in self.object_scale)
            text += f" (object field: scale ({so}))"
        if self.pixels:
            text += f" on {self.pixels} surface pixels, residual {100 * self.residual:.2g}%"
        return text + (f"; {self.note}" if self.note else "")

    def to_json(self) -> dict:
        return {"scale": [float(v) for v in self.scale], "offset": [float(v) for v in self.offset],
                "object_field_scale": [float(v) for v in self.object_scale],
                "object_field_offset": [float(v) for v in self.object_offset],
                "mode": self.mode, "pixels": int(self.pixels), "residual": float(self.residual), "note": self.note}


@dataclass
class CompositeResult:
    """The output of :func:`composite`.

    Attributes
    ----------
    image : (H, W, 3) float32
        The composite, linear radiance in the background's units.
    registration : Registration
    method : str
    clamped_pixels : int
        Pixels where the composite went negative (the difference darker than the background
        allows: a registration or capture mismatch) and were set to 0.
    used : (H, W) bool
        The registration pixels (all False when none were fitted).
    alpha : (H, W) float32
        Coverage of the object (its mask), e.g. for an output alpha channel.
    """

    image: np.ndarray
    registration: Registration
    method: str
    clamped_pixels: int = 0
    used: np.ndarray = field(default=None, repr=False)
    alpha: np.ndarray = field(default=None, repr=False)


# ----------------------------------------------------------------------------- checks
def _as_image(a, name: str, path=None) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim != 3 or a.shape[2] != 3:
        raise InputError(f"{name} must be an RGB image (H, W, 3), not of shape {a.shape}", path)
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} has NaN or Inf pixels", path)
    return a.astype(np.float64, copy=False)


def _as_mask(m, shape, name: str, path=None) -> np.ndarray:
    m = np.asarray(m, dtype=np.float64)
    if m.ndim == 3 and m.shape[2] == 1:
        m = m[..., 0]
    if m.shape != tuple(shape[:2]):
        raise InputError(f"{name} is {m.shape[1] if m.ndim > 1 else '?'}x{m.shape[0]}, the images are "
                         f"{shape[1]}x{shape[0]}", path)
    if not np.all(np.isfinite(m)):
        raise InputError(f"{name} has NaN or Inf values", path)
    return np.clip(m, 0.0, 1.0)


def check_composite_inputs(background, object_relit, surface_relit, object_mask, surface_mask, paths=None):
    """Validated float64 images and float64 masks in [0, 1], all of one size.

    Parameters
    ----------
    background, object_relit, surface_relit : (H, W, 3) array_like
    object_mask, surface_mask : (H, W) array_like
        Coverage (1 = the object / the surface).
    paths : dict, optional
        File or flag to name in errors, by argument name.

    Raises
    ------
    InputError
        A shape that disagrees, NaN/Inf, or a surface mask with no surface pixel outside the object.
    """
    paths = paths or {}
    obj = _as_image(object_relit, "the relit object-on-surface field", paths.get("object_relit"))
    H, W = obj.shape[:2]
    sur = _as_image(surface_relit, "the relit surface-alone field", paths.get("surface_relit"))
    if sur.shape != obj.shape:
        raise InputError(f"the surface-alone field is {sur.shape[1]}x{sur.shape[0]}, the object field {W}x{H}: "
                         "the two captures must come from one camera", paths.get("surface_relit"))
    bg = _as_image(background, "the background", paths.get("background"))
    if bg.shape != obj.shape:
        raise InputError(f"the background is {bg.shape[1]}x{bg.shape[0]}, the captures {W}x{H} (render the "
                         "virtual scene from the capture's camera, at its size)", paths.get("background"))
    om = _as_mask(object_mask, obj.shape, "the object mask", paths.get("object_mask"))
    sm = _as_mask(surface_mask, obj.shape, "the surface mask", paths.get("surface_mask"))
    if not np.any((sm > 0.5) & (om < 0.5)):
        raise InputError("the surface mask has no surface pixel outside the object's mask (white = surface)",
                         paths.get("surface_mask"))
    return bg, obj, sur, om, sm


def check_same_camera(a, b, path=None, rtol: float = 1e-3) -> None:
    """Refuse two captures whose cameras differ (``camera`` K, distortion, pose, model, image size).

    Differential rendering subtracts the two fields pixel by pixel: they must be photographs from
    one camera that did not move.

    Parameters
    ----------
    a, b : ffls.io.capture.Capture
        The object-on-surface and surface-alone captures.
    path : path-like, optional
        Named in the error (default ``b``'s ``capture.json``).
    rtol : float
        Relative tolerance on K (and absolute, in scene units, on the pose).

    Raises
    ------
    InputError
        One line saying what differs.
    """
    where = path if path is not None else getattr(b, "folder", None)
    if getattr(a, "camera_model", "pinhole") != getattr(b, "camera_model", "pinhole"):
        raise InputError(f"the captures have different camera models ({a.camera_model} and {b.camera_model})", where)
    sa, sb = getattr(a, "image_size", None), getattr(b, "image_size", None)
    if sa is not None and sb is not None and tuple(sa) != tuple(sb):
        raise InputError(f"the captures have different image sizes ({sa[0]}x{sa[1]} and {sb[0]}x{sb[1]}): "
                         "two fields from different cameras", where)
    Ka, Kb = getattr(a, "K", None), getattr(b, "K", None)
    if (Ka is None) != (Kb is None):
        raise InputError("one capture states its camera (K) and the other does not: the fields cannot be checked "
                         "to come from one camera; state the same camera in both capture.json", where)
    if Ka is not None and not np.allclose(Ka, Kb, rtol=rtol, atol=rtol * max(1.0, float(np.abs(Ka).max()))):
        raise InputError("the captures have different camera intrinsics (K): two fields from different cameras",
                         where)
    da, db = np.asarray(getattr(a, "dist", np.zeros(5))), np.asarray(getattr(b, "dist", np.zeros(5)))
    n = max(len(da), len(db))
    da, db = np.pad(da, (0, n - len(da))), np.pad(db, (0, n - len(db)))
    if not np.allclose(da, db, rtol=rtol, atol=rtol):
        raise InputError("the captures have different lens distortion: two fields from different cameras", where)
    Ma, Mb = np.asarray(a.world_from_camera), np.asarray(b.world_from_camera)
    if not np.allclose(Ma[:3, :3], Mb[:3, :3], atol=rtol) or not np.allclose(Ma[:3, 3], Mb[:3, 3], atol=rtol):
        raise InputError("the captures have different camera poses (world_from_camera): the camera moved between "
                         "the two fields", where)


# ----------------------------------------------------------------------------- registration
def _disk(radius: int) -> np.ndarray:
    import cv2

    r = max(0, int(radius))
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    import cv2

    if radius <= 0 or not mask.any():
        return mask.copy()
    return cv2.dilate(mask.astype(np.uint8), _disk(radius)).astype(bool)


def registration_pixels(object_relit, surface_relit, object_mask, surface_mask, *, change_threshold: float = 0.03,
                        margin_px: int | None = None, background=None) -> np.ndarray:
    """Surface pixels on which to register the relit surface to the background.

    The surface region (coverage >= 0.99) minus the object's mask and minus the neighbourhood of
    what the object changes: pixels whose relative luminance difference between the two relit
    fields departs from its median by more than ``max(change_threshold, 4 sigma)`` (``sigma`` the
    robust spread of that difference over the surface: noise and the two captures' different
    lights), each grown by ``margin_px``.

    Parameters
    ----------
    object_relit, surface_relit : (H, W, 3) float
    object_mask, surface_mask : (H, W) float in [0, 1]
    change_threshold : float
        Smallest relative change that counts as the object's shadow or bounce.
    margin_px : int, optional
        Growth of the excluded regions; default 1% of the image diagonal (at least 2).
    background : (H, W, 3) float, optional
        Pixels where it is not positive are left out too.

    Returns
    -------
    (H, W) bool
    """
    o = np.asarray(object_relit, dtype=np.float64) @ LUMINANCE
    s = np.asarray(surface_relit, dtype=np.float64) @ LUMINANCE
    om = np.asarray(object_mask) > 0
    surf = np.asarray(surface_mask) >= 0.99
    H, W = s.shape
    if margin_px is None:
        margin_px = max(2, int(round(0.01 * np.hypot(H, W))))
    near_obj = _dilate(om, margin_px)
    pos = s > 0
    cand = surf & ~near_obj & pos
    if background is not None:
        cand &= (np.asarray(background, dtype=np.float64) @ LUMINANCE) > 0
    if not cand.any():
        return cand
    rel = np.zeros_like(s)
    rel[pos] = (o[pos] - s[pos]) / s[pos]
    med = float(np.median(rel[cand]))
    sigma = 1.4826 * float(np.median(np.abs(rel[cand] - med)))
    changed = surf & (np.abs(rel - med) > max(change_threshold, 4.0 * sigma)) & pos
    changed |= surf & ~pos
    return cand & ~_dilate(changed, margin_px)


def _robust_line(x: np.ndarray, y: np.ndarray, with_offset: bool) -> tuple[float, float]:
    """Soft-L1 fit of ``y ~ a x (+ b)`` (scipy.optimize.least_squares), started from the medians."""
    from scipy.optimize import least_squares

    mx, my = float(np.median(x)), float(np.median(y))
    a0 = my / mx if mx > 0 else 1.0
    r0 = y - a0 * x
    scale = 1.4826 * float(np.median(np.abs(r0 - np.median(r0))))
    f_scale = max(scale, 1e-3 * max(abs(my), 1e-12))
    if with_offset:
        b0 = float(np.median(r0))
        res = least_squares(lambda p: (p[0] * x + p[1] - y) / f_scale, [a0, b0], loss="soft_l1", method="trf",
                            x_scale=[max(abs(a0), 1e-6), max(abs(my), 1e-12)])
        return float(res.x[0]), float(res.x[1])
    res = least_squares(lambda p: (p[0] * x - y) / f_scale, [a0], loss="soft_l1", method="trf",
                        x_scale=[max(abs(a0), 1e-6)])
    return float(res.x[0]), 0.0


def register_surface(background, surface_relit, pixels, mode: str = "auto", seed: int = 0,
                     object_relit=None) -> Registration:
    """Per-channel scale and offset with ``background ~ scale * surface_relit + offset`` on ``pixels``.

    Parameters
    ----------
    background, surface_relit : (H, W, 3) float
    pixels : (H, W) bool
        Where to fit (:func:`registration_pixels`).
    mode : {'auto', 'scale-offset', 'scale', 'none'}
        ``'auto'`` fits the offset only when the relit surface's brightness spreads enough to
        separate it from the scale (:data:`OFFSET_MIN_SPREAD`); ``'none'`` is scale 1, offset 0.
    seed : int
        Seed of the subsample when more than :data:`MAX_FIT_PIXELS` pixels are given.
    object_relit : (H, W, 3) float, optional
        The object-on-surface field, registered on the same pixels with the same mode (its
        ``object_field_scale`` / ``object_field_offset``).

    Returns
    -------
    Registration

    Raises
    ------
    InputError
        Fewer than :data:`MIN_REGISTRATION_PIXELS` pixels, or a non-positive scale (the relit
        surface and the background do not resemble each other).
    """
    if mode not in REGISTRATION_MODES:
        raise ValueError(f"mode must be one of {REGISTRATION_MODES}, not {mode!r}")
    if mode == "none":
        return Registration(np.ones(3), np.zeros(3), "none")
    pixels = np.asarray(pixels, dtype=bool)
    n = int(np.count_nonzero(pixels))
    if n < MIN_REGISTRATION_PIXELS:
        raise InputError(f"only {n} surface pixels lie away from the object and its shadow (at least "
                         f"{MIN_REGISTRATION_PIXELS} are needed to register the surface to the background): give a "
                         "larger surface mask, or --registration none")
    x = np.asarray(surface_relit, dtype=np.float64)[pixels]
    y = np.asarray(background, dtype=np.float64)[pixels]
    xo = None if object_relit is None else np.asarray(object_relit, dtype=np.float64)[pixels]
    if n > MAX_FIT_PIXELS:
        pick = np.random.default_rng(seed).choice(n, MAX_FIT_PIXELS, replace=False)
        x, y = x[pick], y[pick]
        xo = None if xo is None else xo[pick]
    note = ""
    with_offset = mode == "scale-offset"
    if mode == "auto":
        p10, p50, p90 = np.percentile(x, [10, 50, 90], axis=0)
        spread = float(np.min((p90 - p10) / np.maximum(p50, 1e-30)))
        with_offset = spread >= OFFSET_MIN_SPREAD
        if not with_offset:
            note = (f"offset not fitted: the relit surface is nearly uniform (spread {100 * spread:.0f}% < "
                    f"{100 * OFFSET_MIN_SPREAD:.0f}%), so scale and offset cannot be told apart")
    scale, offset = np.ones(3), np.zeros(3)
    for c in range(3):
        scale[c], offset[c] = _robust_line(x[:, c], y[:, c], with_offset)
    oscale = ooffset = None
    if xo is not None:
        oscale, ooffset = np.ones(3), np.zeros(3)
        for c in range(3):
            oscale[c], ooffset[c] = _robust_line(xo[:, c], y[:, c], with_offset)
        scale = np.where(np.all(oscale > 0), scale, np.minimum(scale, oscale))  # either non-positive: refused below
    if not np.all(scale > 0):
        raise InputError(f"the registration scale is not positive ({', '.join(f'{v:.3g}' for v in scale)}): the "
                         "relit surface does not resemble the background's surface (check the surface mask, the "
                         "light map and the background)")
    r = (y - (x * scale + offset)) @ LUMINANCE
    yl = float(np.median(y @ LUMINANCE))
    resid = 1.4826 * float(np.median(np.abs(r - np.median(r)))) / max(yl, 1e-30)
    return Registration(scale, offset, "scale-offset" if with_offset else "scale", n, resid, note, oscale, ooffset)


# ----------------------------------------------------------------------------- composites
def _finish(out: np.ndarray, object_relit, object_mask, object_scale) -> tuple[np.ndarray, int]:
    a = object_mask[..., None]
    out = a * (object_relit * object_scale) + (1.0 - a) * out
    neg = out < 0
    clamped = int(np.count_nonzero(neg.any(axis=2)))
    return np.where(neg, 0.0, out).astype(np.float32), clamped


def _field(x, scale, offset):
    return np.asarray(x, dtype=np.float64) * np.asarray(scale, dtype=np.float64) + np.asarray(offset, dtype=np.float64)


def composite_Debevec1998(background, object_relit, surface_relit, object_mask, surface_mask, scale=1.0,
                          offset=0.0, object_field_scale=None, object_field_offset=None,
                          object_scale=1.0) -> tuple[np.ndarray, int]:
    """Differential rendering: ``background + (object_relit - surface_relit)`` over the surface, registered.

    Debevec, "Rendering Synthetic Objects into Real Scenes", SIGGRAPH 1998, section 5 (with the
    local scene's two renders replaced by the two relit reflectance fields, as in Masselus et al.
    2002, section 7). Each field is first brought to the background's units by its registration
    (``scale * field + offset``), so the difference is zero wherever the object changes nothing;
    the relit object replaces the result over its mask (blended by coverage).

    Parameters
    ----------
    background, object_relit, surface_relit : (H, W, 3) float
    object_mask, surface_mask : (H, W) float in [0, 1]
    scale, offset : float or (3,) float
        Registration of the surface-alone field (:func:`register_surface`).
    object_field_scale, object_field_offset : float or (3,) float, optional
        Registration of the object-on-surface field (default: the surface's).
    object_scale : float or (3,) float
        Applied to the relit object over its mask (1 when the mismatch is the surface's albedo;
        the field's registration scale when it is the exposure).

    Returns
    -------
    image : (H, W, 3) float32
    clamped : int
        Pixels set to 0 from negative.
    """
    osc = scale if object_field_scale is None else object_field_scale
    oof = offset if object_field_offset is None else object_field_offset
    d = _field(object_relit, osc, oof) - _field(surface_relit, scale, offset)
    out = np.asarray(background, dtype=np.float64) + d * np.asarray(surface_mask, dtype=np.float64)[..., None]
    return _finish(out, np.asarray(object_relit, dtype=np.float64), np.asarray(object_mask, dtype=np.float64),
                   np.asarray(object_scale, dtype=np.float64))


def composite_ratio(background, object_relit, surface_relit, object_mask, surface_mask, scale=1.0, offset=0.0,
                    object_field_scale=None, object_scale=1.0, floor: float = 0.02) -> tuple[np.ndarray, int]:
    """Multiplicative differential rendering: ``(background - offset) * ratio + offset`` over the surface.

    ``ratio = (object_field_scale * object_relit) / (scale * surface_relit)`` is the fraction of
    light the object leaves the surface (a shadow < 1, a bounce > 1), whatever the surface's
    albedo or the exposure of the background; the two scales only correct the captures'
    difference (their lights' power and sampling). A textured background keeps its texture
    inside the shadow. Where the relit surface is darker than ``floor`` times its median over the
    surface region the ratio is unreliable (noise over a dark denominator) and left at 1.

    Parameters
    ----------
    background, object_relit, surface_relit : (H, W, 3) float
    object_mask, surface_mask : (H, W) float in [0, 1]
    scale, offset : float or (3,) float
        Registration of the surface-alone field; the offset is the part of the background that
        the lighting does not scale.
    object_field_scale : float or (3,) float, optional
        Scale of the object-on-surface field (default: the surface's).
    object_scale : float or (3,) float
    floor : float

    Returns
    -------
    image : (H, W, 3) float32
    clamped : int
    """
    bg = np.asarray(background, dtype=np.float64)
    sc = np.asarray(scale, dtype=np.float64)
    o = np.asarray(object_relit, dtype=np.float64) * np.asarray(sc if object_field_scale is None
                                                                 else object_field_scale, dtype=np.float64)
    sr = np.asarray(surface_relit, dtype=np.float64) * sc
    sm = np.asarray(surface_mask, dtype=np.float64)
    region = sm > 0.5
    ref = np.median(sr[region], axis=0) if region.any() else np.ones(3)
    ok = sr > floor * np.maximum(ref, 1e-30)
    ratio = np.where(ok, o / np.where(ok, sr, 1.0), 1.0)
    off = np.asarray(offset, dtype=np.float64)
    out = bg + (bg - off) * (ratio - 1.0) * sm[..., None]
    return _finish(out, np.asarray(object_relit, dtype=np.float64), np.asarray(object_mask, dtype=np.float64),
                   np.asarray(object_scale, dtype=np.float64))


def composite(background, object_relit, surface_relit, object_mask, surface_mask, *, method: str = "Debevec1998",
              registration="auto", object_scale: bool = False, change_threshold: float = 0.03,
              margin_px: int | None = None, paths=None) -> CompositeResult:
    """Merge a relit object and its effect on the surface into a background (differential rendering).

    Parameters
    ----------
    background : (H, W, 3) float
        Linear render or photograph of the scene without the object, from the captures' camera.
    object_relit, surface_relit : (H, W, 3) float
        The object-on-surface and surface-alone fields relit under the scene's light map (each
        with its own lights' weights).
    object_mask : (H, W) float in [0, 1]
        The object's coverage.
    surface_mask : (H, W) float in [0, 1]
        Where the captured surface stands for the scene's surface (leave calibration spheres and
        anything not in the scene out of it).
    method : {'Debevec1998', 'ratio'}
        :func:`composite_Debevec1998` or :func:`composite_ratio`.
    registration : {'auto', 'scale-offset', 'scale', 'none'} or Registration
        A mode of :func:`register_surface` (fitted here), or a fixed registration.
    object_scale : bool
        Scale the relit object by its field's registration scale: right when the mismatch is the
        exposure (a photographed background), wrong when it is the surface's albedo (a virtual
        scene lit by a map rendered with it, where the relit object is already in its units).
    change_threshold, margin_px
        As :func:`registration_pixels`.
    paths : dict, optional
        Names for errors (:func:`check_composite_inputs`).

    Returns
    -------
    CompositeResult
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, not {method!r}")
    bg, obj, sur, om, sm = check_composite_inputs(background, object_relit, surface_relit, object_mask,
                                                  surface_mask, paths)
    used = np.zeros(om.shape, dtype=bool)
    if isinstance(registration, Registration):
        reg = registration
    else:
        if registration not in REGISTRATION_MODES:
            raise ValueError(f"registration must be a Registration or one of {REGISTRATION_MODES}")
        if registration != "none":
            used = registration_pixels(obj, sur, om, sm, change_threshold=change_threshold, margin_px=margin_px,
                                       background=bg)
        reg = register_surface(bg, sur, used, registration, object_relit=obj)
    osc = reg.object_scale if object_scale else 1.0
    if method == "Debevec1998":
        img, clamped = composite_Debevec1998(bg, obj, sur, om, sm, reg.scale, reg.offset, reg.object_scale,
                                             reg.object_offset, osc)
    else:
        img, clamped = composite_ratio(bg, obj, sur, om, sm, reg.scale, reg.offset, reg.object_scale, osc)
    return CompositeResult(img, reg, method, clamped, used, om.astype(np.float32))


# ----------------------------------------------------------------------------- driver
class Compositor:
    """Two relighters under one light map, merged into a background (stills, turntables, the viewer).

    Parameters
    ----------
    object_relighter, surface_relighter
        Relighters of the object-on-surface and surface-alone captures with the interface of
        :class:`ffls.relight.cpu.CpuRelighter` (``set_lightmap``, ``set_rotation``, ``render``,
        ``read_hdr``); each integrates the map over its own lights.
    background : (H, W, 3) float
    object_mask, surface_mask : (H, W) float in [0, 1]
    method, registration, object_scale
        As :func:`composite`. A registration mode is fitted on the first :meth:`render` and kept
        for the later ones (a turntable's frames share one exposure and albedo correction);
        :meth:`refit` fits again on the next render.
    paths : dict, optional
        Names for errors.
    """

    def __init__(self, object_relighter, surface_relighter, background, object_mask, surface_mask, *,
                 method: str = "Debevec1998", registration="auto", object_scale: bool = False, paths=None):
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, not {method!r}")
        self.object = object_relighter
        self.surface = surface_relighter
        self.paths = paths or {}
        self.background = _as_image(background, "the background", self.paths.get("background"))
        shape = self.background.shape
        self.object_mask = _as_mask(object_mask, shape, "the object mask", self.paths.get("object_mask"))
        self.surface_mask = _as_mask(surface_mask, shape, "the surface mask", self.paths.get("surface_mask"))
        self.method = method
        self.object_scale = bool(object_scale)
        self._mode = registration
        self.registration: Registration | None = registration if isinstance(registration, Registration) else None
        self.last: CompositeResult | None = None

    def set_lightmap(self, lm) -> None:
        """The scene's light map, for both relighters."""
        self.object.set_lightmap(lm)
        self.surface.set_lightmap(lm)

    def set_rotation(self, R) -> None:
        """Rotate the scene's light map (both fields)."""
        self.object.set_rotation(R)
        self.surface.set_rotation(R)

    def refit(self) -> None:
        """Fit the registration again on the next :meth:`render`."""
        if not isinstance(self._mode, Registration):
            self.registration = None

    def render(self) -> CompositeResult:
        """Relight both fields and composite them; returns (and keeps in ``last``) the result."""
        self.object.render()
        self.surface.render()
        reg = self.registration if self.registration is not None else self._mode
        self.last = composite(self.background, self.object.read_hdr(), self.surface.read_hdr(), self.object_mask,
                              self.surface_mask, method=self.method, registration=reg,
                              object_scale=self.object_scale, paths=self.paths)
        self.registration = self.last.registration
        return self.last

    def release(self) -> None:
        """Release both relighters."""
        for r in (self.object, self.surface):
            if r is not None:
                r.release()
        self.object = self.surface = None
