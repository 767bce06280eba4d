"""Every photograph's light in a capture: the capture-wide two-pass driver.

Masselus, Dutre, Anrys, "The Free-form Light Stage", EGWR 2002, section 5, for a whole
sequence. The stages, each in its own module:

* :mod:`ffls.spheres.detect` finds the spheres (centres from the silhouettes);
* :mod:`ffls.spheres.samples` gives their pixels and normals (:func:`capture_samples`) and, per
  photo, their values;
* :mod:`ffls.spheres.lambert` fits one sphere in one photo;
* :mod:`ffls.spheres.photo` (with :mod:`ffls.spheres.combine`) gives one photo's light;
* this module runs them over the capture in two passes (:func:`estimate_lights`, in a process
  pool, and :func:`estimate_photos`, in this process, share one driver):

  1. every photo is fitted with a free ground bounce (with a calibrated bounce, optionally only
     some photos spread over the sequence, :func:`first_pass_photos`: this pass only feeds steps
     2 and 3; the other photos' values are read); the lens's fall-off (vignetting) across
     the spheres is fitted over those fits and, where significant and where the spheres then
     agree better, divided out and the photos fitted again (:func:`calibrate_flat_field`);
  2. optionally each sphere's centre is refined from the first pass's shading
     (:func:`refine_sphere_centres`, :mod:`ffls.spheres.refine`) and the recentred spheres'
     fits are redone (:func:`refit_spheres`);
  3. each sphere's ground ratio is calibrated on the photos that determine it
     (:func:`calibrate_bounce`);
  4. every photo is fitted again with that ratio imposed (spheres without enough such photos
     keep the free bounce);
  5. the error model of the directions is calibrated on the spheres' disagreement over all
     photos (:func:`calibrate_uncertainty`, :mod:`ffls.spheres.uncertainty`) and every photo's
     ``uncertainty_deg`` becomes the radius of its 95% cone under it.

The spheres' pixels are kept in memory between the passes (never the images).

Each sphere is matte or a mirror (chrome, black glossy): declared in ``capture.json``
(:func:`ffls.io.capture.sphere_materials`) or, for ``'auto'``, classified after the first pass
from its photos (:func:`ffls.spheres.highlight.classify_sphere`); a sphere found to be a mirror
has its first-pass fits redone from its highlight. A mirror sphere takes no part in the centre
refinement or the bounce calibration (both model shading).
"""
from __future__ import annotations

import importlib
import os
import pickle
import warnings
from contextlib import nullcontext
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from ffls.conventions import TILT_REACH_DEG, UP, normalize
from ffls.errors import InputError
from ffls.io.capture import Lights, cap_cones, sphere_materials
from ffls.radiance.photos import load_photo, read_photo
from ffls.spheres.detect import SequenceAccumulator, SequenceStats
from ffls.spheres.highlight import (HighlightFit, SphereKind, SphereView, classify_sphere, highlight_compactness,
                                   outline_holding_highlights, refine_view_limb, sample_patch)
from ffls.spheres.ground import (ground_pixels, ground_views, mask_radiance, mask_view, not_ground, own_shadow_mask,
                                 reference_radiance)
from ffls.spheres.mirror_outline import MIRROR_OUTLINE_FLOOR_PX
from ffls.spheres.lambert import (LambertFit, fit_lambert, flat_field_terms, own_shadow_of, own_shadow_table,
                                  shadowed_ground_bounce)
from ffls.spheres.photo import (LIGHT_MODELS, SHADOW_RATIO, SIGNIFICANCE, PhotoEstimate, SphereResult,
                               estimate_photo, fit_spheres, ray_origins)
from ffls.spheres.refine import CentreRefinement, recentre_samples, refine_sphere_centre
from ffls.spheres.samples import (SphereSamples, SphereValues, sphere_samples, sphere_samples_orthographic,
                                  sphere_values, sphere_values_of)
from ffls.spheres.uncertainty import (FALLBACK_FLOOR_DEG, ErrorModel, centre_floor_deg, distance_spread,
                                     fit_error_model,
                                     halves_error_model, photo_residuals, tangent_residuals)

__all__ = [
    "BOUNCE_MODES",
    "BounceCalibration",
    "check_estimable",
    "CaptureEstimate",
    "capture_samples",
    "observed_ground_samples",
    "calibrate_ground_albedo",
    "mask_object_from_ground",
    "mask_foreign_pixels",
    "sphere_views",
    "sphere_kinds",
    "calibrate_bounce",
    "calibrate_bounce_shape",
    "shaped_samples",
    "FlatField",
    "flat_field_offsets",
    "calibrate_flat_field",
    "centres_to_refine",
    "cos4_gradient",
    "lens_centre",
    "flat_field_values",
    "disagreement_change",
    "refine_sphere_centres",
    "refit_spheres",
    "calibrate_uncertainty",
    "reject_shadowed_photos",
    "reject_dark_photos",
    "DARK_RATIO",
    "lens_check",
    "widen_for_lens",
    "place_at_capture_range",
    "DecodedPhotos",
    "decode_photos",
    "estimate_photos",
    "estimate_lights",
    "estimate_lights_MasselusDutreAnrys2002",
    "first_pass_photos",
    "FIRST_PASS_PHOTOS",
]

#: Ground-bounce handling of the driver: calibrated over the capture (two passes) or free per photo.
BOUNCE_MODES = ("calibrated", "free", "observed")
#: Default number of photos the first pass fits with a calibrated bounce (:func:`first_pass_photos`;
#: None: every photo). That pass only feeds the capture-wide steps, each a statistic over photos:
#: the centre refinement reads at most 20 of them (:func:`refine_sphere_centres`), the bounce
#: calibration a weighted median of the photos that determine the ratio, the flat field a sum over
#: photos; the second pass fits every photo. Every photo by default: with 40 of 80 the 768 px near
#: capture's errors grew from 0.50 / 1.10 to 0.53 / 1.21 deg (median / max; docs/spheres.md, Speed),
#: a near light's direction being sensitive to the capture-wide parameters.
FIRST_PASS_PHOTOS = None


def first_pass_photos(n_photos: int, limit: int | None) -> list[int]:
    """The photos the first pass fits: ``limit`` of the ``n_photos``, spread evenly over the sequence.

    A capture's photos are taken in the order the light moves (a sweep, rings of a dome), so
    photos evenly spaced in the sequence are spread over the lights; the capture-wide steps the
    first pass feeds (the centre refinement, the bounce calibration, the flat field) are
    statistics over photos that do not need every photo.

    Parameters
    ----------
    n_photos : int
    limit : int or None
        Photos to fit (None, or at least ``n_photos``: every photo).

    Returns
    -------
    list of int
        Increasing photo indices, ``min(limit, n_photos)`` of them.
    """
    if limit is None or int(limit) >= n_photos:
        return list(range(n_photos))
    if int(limit) < 1:
        raise ValueError(f"limit must be at least 1, got {limit!r}")
    return [int(i) for i in np.unique(np.round(np.linspace(0.0, n_photos - 1.0, int(limit))).astype(np.intp))]


@dataclass(frozen=True)
class BounceCalibration:
    """One sphere's capture-wide ground ratio (:func:`calibrate_bounce`).

    Attributes
    ----------
    ratio : float or None
        ``rho_g`` in [0, 1]; None where too few photos determine it (the bounce stays free).
    spread : float or None
        Robust standard deviation of the photos' estimates.
    n_photos : int
        Photos that determined it.
    gradient : (float, float) or None
        The bounce's horizontal gradient ``beta`` along world x, y (:func:`calibrate_bounce_shape`),
        imposed in the second pass; None where not determined.
    """

    ratio: float | None
    spread: float | None
    n_photos: int
    gradient: tuple | None = None


@dataclass
class CaptureEstimate:
    """Result of the two-pass driver (:func:`estimate_photos`).

    Attributes
    ----------
    photos : list of PhotoEstimate
        Per photo, the final pass.
    calibration : list of BounceCalibration or None
        Per sphere (None with ``bounce='free'``).
    refinements : list of CentreRefinement or None
        Per sphere (None without ``refine_centres``).
    samples : list of SphereSamples
        The spheres' pixels, recentred where a refinement was accepted.
    error_model : ErrorModel or None
        The capture's error model of the directions (:func:`calibrate_uncertainty`); the photos'
        ``uncertainty_deg`` are 95% cones under it.
    kinds : list of SphereKind or None
        Per sphere, its material as used and how it was decided.
    flat_field : FlatField or None
        The lens's fall-off across the spheres found over the photos, and divided out where
        significant (:func:`calibrate_flat_field`; None where not fitted).
    """

    photos: list[PhotoEstimate]
    calibration: list[BounceCalibration] | None
    refinements: list[CentreRefinement] | None
    samples: list[SphereSamples]
    error_model: ErrorModel | None = None
    kinds: list[SphereKind] | None = None
    flat_field: FlatField | None = None

    def records(self) -> list[dict]:
        """Per photo, its ``lights.json`` ``extra`` (:meth:`PhotoEstimate.record`); each sphere's
        report also says how its kind was decided (``kind_source``, ``compactness``), the lens's
        fall-off divided out (``flat_field``) and its bounce's gradient (``bounce_gradient``,
        :func:`calibrate_bounce_shape`; None where not imposed)."""
        out = [p.record(self.refinements) for p in self.photos]
        for rec in out:
            for rep, kind in zip(rec["spheres"], self.kinds or []):
                rep["kind_source"] = kind.source
                rep["compactness"] = kind.statistic
            if self.flat_field is not None:
                for rep, g in zip(rec["spheres"], self.flat_field.gradients):
                    rep["flat_field"] = [float(x) for x in g] if np.any(g != 0) else None
            if self.calibration is not None:
                for rep, cal in zip(rec["spheres"], self.calibration):
                    rep["bounce_gradient"] = None if cal.gradient is None else [float(x) for x in cal.gradient]
        return out

    def lights(self, image_names: list) -> Lights:
        """The ``lights.json`` contents of these estimates for a capture's images (in photo order):
        directions (rejected or failed photos: world up, status ``rejected``), near positions, the
        per-photo records, the error model and the flat field."""
        dirs = np.array([normalize(r.direction) if np.all(np.isfinite(r.direction)) else UP for r in self.photos])
        pos = np.array([r.position if r.position is not None else np.full(3, np.nan) for r in self.photos])
        return Lights(image_names=list(image_names), directions=dirs, positions=pos,
                      status=[r.status for r in self.photos], reasons=[r.reason for r in self.photos],
                      extra=self.records(), uncertainty=None if self.error_model is None else self.error_model.as_dict(),
                      flat_field=None if self.flat_field is None else self.flat_field.as_dict())


# ----------------------------------------------------------------------------- capture stages
def capture_samples(capture, spheres, shape: tuple[int, int]) -> list[SphereSamples]:
    """:func:`ffls.spheres.samples.sphere_samples` for each found sphere (objects with ``center_cam`` and ``radius``)."""
    out = []
    ortho = getattr(capture, "camera_model", "pinhole") == "orthographic"
    for k, s in enumerate(spheres):
        R = float(getattr(s, "radius", None) or capture.sphere_radius or 1.0)
        try:
            if ortho:  # parallel rays: normals from the pixel offset over the pixel radius
                out.append(sphere_samples_orthographic(shape, s.center_px, s.radius_px, s.center_cam, R,
                                                       capture.world_from_camera))
            else:
                out.append(sphere_samples(shape, capture.K, capture.dist, np.asarray(s.center_cam), R,
                                          capture.world_from_camera))
        except ValueError as e:
            raise InputError(f"sphere {k}: {e}", capture.folder) from None
        if len(out[-1]) < 20:
            raise InputError(f"sphere {k} covers only {len(out[-1])} pixels; too small to estimate a light",
                             capture.folder)
    return out


def observed_ground_samples(capture, samples: list[SphereSamples], shape: tuple[int, int]) -> list[SphereSamples]:
    """The spheres' samples with their ground views (:func:`ffls.spheres.ground.ground_views`): the
    photos' values then carry each sphere's photographed ground, and the fits take the bounce from
    it (``bounce='observed'``). The ground is the plane under each sphere, normal to the world's
    up: the capture must give ``world_from_camera`` (InputError otherwise)."""
    if getattr(capture, "world_from_camera_is_default", False):
        raise InputError("bounce 'observed' needs camera.world_from_camera (the ground under the spheres is "
                         "the plane normal to the world's +Z)", capture.json_path)
    views = ground_views(samples, shape, getattr(capture, "camera_model", "pinhole"), capture.K, capture.dist,
                         capture.world_from_camera)
    return [replace(s, ground_view=v) for s, v in zip(samples, views)]


def mask_object_from_ground(samples: list[SphereSamples], values: list,
                            lights: list) -> tuple[list[SphereSamples], list, list[int]]:
    """Each sphere's ground view without the seen points that the photos show are not the ground
    plane (:func:`ffls.spheres.ground.not_ground`: the object, or another one, within reach), and
    every photo's ground values cut to match (``bounce='observed'``).

    Parameters
    ----------
    samples : list of SphereSamples
    values : list (photos) of lists (spheres) of SphereValues
        Every photo's values, as read (:class:`~ffls.spheres.samples.GroundedValues` where the
        sphere has a ground view).
    lights : list of (photo index, (3,) float)
        Photos with a light found (the first pass's), for the sphere's own shadow on its ground.

    Returns
    -------
    samples, values, masked
        ``masked`` per sphere: how many seen points were taken out (0: the view is unchanged).
    """
    out_samples, keeps, masked = list(samples), [None] * len(samples), [0] * len(samples)
    for k, s in enumerate(samples):
        gv = s.ground_view
        if gv is None or gv.n_seen == 0:
            continue
        rows, lit = [], []
        for i, light in lights:
            g = getattr(values[i][k], "ground", None)
            if g is not None and len(g) == gv.n_seen:
                rows.append(g)
                lit.append(~own_shadow_mask(gv, light)[:gv.n_seen])
        if len(rows) < 3:
            continue
        keep = ~not_ground(np.stack(rows), np.stack(lit))
        view = mask_view(gv, keep)
        if view is not gv:
            out_samples[k], keeps[k], masked[k] = replace(s, ground_view=view), keep, int((~keep).sum())
    if not any(masked):
        return list(samples), values, masked

    def cut(v, s, keep):
        if keep is None or getattr(v, "ground", None) is None:
            return v
        return sphere_values_of(v.grey, v.valid, v.n_saturated, mask_radiance(s.ground_view, keep, v.ground))

    return out_samples, [[cut(v, s, keep) for v, s, keep in zip(photo, samples, keeps)] for photo in values], masked


#: Least share of the photos whose fits reject a pixel of a matte sphere's disk that makes it
#: foreign (:func:`mask_foreign_pixels`): an object in front of the ball, not its surface. A cast
#: shadow, a highlight or the terminator's band moves with the light and is rejected in a few
#: photos; an occluder's pixels follow no light and are rejected in most.
FOREIGN_REJECTED_SHARE = 0.5
#: Fewest photos with a fit that must see a pixel valid before :func:`mask_foreign_pixels` judges it.
FOREIGN_MIN_PHOTOS = 5
#: Most of a sphere's pixels that :func:`mask_foreign_pixels` takes out (more: the fits, not the
#: pixels, are wrong, and the sphere keeps every pixel).
FOREIGN_MAX_SHARE = 0.4
#: Most rounds of :func:`mask_foreign_pixels` in :func:`two_pass`: fits turned by an occluder reject
#: only part of it, and the fits without that part reject more of it.
FOREIGN_ROUNDS = 3


def _grown(s: SphereSamples, mask: np.ndarray) -> np.ndarray:
    """``mask`` over sphere ``s``'s pixels grown by one pixel (its 8 neighbours) within them."""
    import cv2

    (c0, r0), _, (grid,) = sample_patch(s.rows, s.cols, np.asarray(mask, dtype=np.uint8))
    return cv2.dilate(grid, np.ones((3, 3), np.uint8))[s.rows - r0, s.cols - c0].astype(bool)


def mask_foreign_pixels(results: list[PhotoEstimate], photos: list[int], samples: list[SphereSamples],
                        values: list) -> tuple[list, list[int]]:
    """Every photo's matte-sphere values without the disk's pixels that are not the sphere.

    An object in front of the ball (or a stand, a finger) covers part of its disk in every photo;
    its pixels follow no light on the sphere, and a fit either rejects them as outliers or, where
    they are many, is turned by them (a lone grey ball behind the object under a long lens: 17% of
    its disk hidden, every photo 3-9 deg off). A pixel that at least :data:`FOREIGN_REJECTED_SHARE`
    of the first pass's matte fits reject (valid, not :attr:`LambertFit.non_outliers`), among at
    least :data:`FOREIGN_MIN_PHOTOS` that see it valid, is made invalid in every photo.

    Parameters
    ----------
    results : list of PhotoEstimate
        The first pass's estimates of ``photos``.
    photos : list of int
        Their indices into ``values``.
    samples : list of SphereSamples
        The spheres' pixels (the foreign pixels grow by one pixel among them: the occluder's edge).
    values : list (photos) of lists (spheres) of SphereValues

    Returns
    -------
    values, masked
        ``masked`` per sphere: how many pixels were taken out (0: its values are unchanged).
    """
    n_spheres = len(values[0]) if values else 0
    seen, rejected = [None] * n_spheres, [None] * n_spheres
    for i, r in zip(photos, results):
        for k, sr in enumerate(r.spheres):
            f = sr.fit
            if not isinstance(f, LambertFit) or f.non_outliers is None or sr.status not in ("ok", "shadowed"):
                continue
            valid = np.asarray(values[i][k].valid, bool)
            if seen[k] is None:
                seen[k], rejected[k] = np.zeros(valid.size, int), np.zeros(valid.size, int)
            seen[k] += valid
            rejected[k] += valid & ~np.asarray(f.non_outliers, bool)
    keeps, masked = [None] * n_spheres, [0] * n_spheres
    for k in range(n_spheres):
        if seen[k] is None:
            continue
        foreign = (seen[k] >= FOREIGN_MIN_PHOTOS) & (rejected[k] >= FOREIGN_REJECTED_SHARE * seen[k])
        if foreign.any():  # the occluder's edge: pixels that mix it with the sphere
            foreign = _grown(samples[k], foreign)
        if 0 < foreign.sum() <= FOREIGN_MAX_SHARE * foreign.size:
            keeps[k], masked[k] = ~foreign, int(foreign.sum())
    if not any(masked):
        return values, masked

    def cut(v, keep):
        if keep is None:
            return v
        return sphere_values_of(v.grey, v.valid & keep, v.n_saturated, getattr(v, "ground", None))

    return [[cut(v, keep) for v, keep in zip(photo, keeps)] for photo in values], masked


def sphere_views(capture, spheres) -> list[SphereView]:
    """Each found sphere's :class:`~ffls.spheres.highlight.SphereView` (what maps its pixels to
    reflected directions) under the capture's camera.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
    spheres : list
        Objects with ``center_cam`` and ``radius`` (and, where known, ``center_px``, ``radius_px``,
        ``residual_px``, ``n_inliers``, ``outline_sigma_px``: :class:`ffls.spheres.detect.SphereFit`).

    Returns
    -------
    list of SphereView
    """
    from ffls.camera.projection import project_points

    model = getattr(capture, "camera_model", "pinhole")
    out = []
    for s in spheres:
        # a mirror outline's ambiguity (0 for a matte one): with 2+ spheres their directions are
        # combined by these statistics before the error model measures them, and a glossy ball at
        # the measured floor took a matte ball's weight (bench c11: 0.36 / 0.56 -> 0.39 / 0.62 deg),
        # so there the floor of an outline without a second estimate stays
        amb = float(getattr(s, "outline_sigma_px", 0.0) or 0.0)
        if amb > 0.0 and len(spheres) > 1:
            amb = max(amb, MIRROR_OUTLINE_FLOOR_PX)
        # a lone mirror's centre uncertainty as its second outline estimate measured it
        # (SphereFit.outline_centre_sigma_px: the misfit's sector jackknife bounded by the gap)
        own = float(getattr(s, "outline_centre_sigma_px", 0.0) or 0.0) if len(spheres) == 1 else 0.0
        C = np.asarray(s.center_cam, dtype=np.float64)
        R = float(getattr(s, "radius", None) or capture.sphere_radius)
        cpx = getattr(s, "center_px", None)
        rpx = getattr(s, "radius_px", None)
        if cpx is None and capture.K is not None:
            cpx = project_points(C[None], capture.K, capture.dist)[0]
        if rpx is None and capture.K is not None:
            f = 0.5 * (capture.K[0, 0] + capture.K[1, 1])
            rpx = f * np.tan(np.arcsin(min(R / float(np.linalg.norm(C)), 1.0)))
        proxy = type("Sphere", (), dict(center_px=cpx, radius_px=rpx, center_cam=C, radius=R,
                                        residual_px=getattr(s, "residual_px", 0.0),
                                        n_inliers=getattr(s, "n_inliers", 0),
                                        outline_sigma_px=amb, outline_centre_sigma_px=own))
        out.append(SphereView.from_sphere(proxy, model, capture.K, capture.dist, capture.world_from_camera))
    return out


def sphere_kinds(materials: list[str], samples: list[SphereSamples], values: list) -> list[SphereKind]:
    """Each sphere's kind: as declared, or for ``'auto'`` classified from the photos' values.

    With 3 photos or more, each pixel's median over the photos is subtracted first: a chrome ball
    reflects a lit table or room that is as bright as a matte sphere's lit cap, but it stays where it
    is, while the highlight moves with the light (a matte sphere's lit cap moves as a whole).

    Parameters
    ----------
    materials : list of {'matte', 'mirror', 'auto'}
    samples : list of SphereSamples
    values : list
        Per photo, its :func:`ffls.spheres.samples.sphere_values`.

    Returns
    -------
    list of SphereKind
    """
    out = []
    for k, (m, s) in enumerate(zip(materials, samples)):
        if m != "auto":
            out.append(SphereKind(m, "declared"))
            continue
        grey = np.stack([np.asarray(v[k][0], dtype=np.float64) for v in values])
        if len(grey) >= 3:  # the static part (a mirror's reflected room or table) removed: what moves is the light
            if not np.isnan(grey).any():  # (the same medians; nanmedian is ~3x slower, even without a NaN)
                grey = grey - np.median(grey, axis=0)
            else:
                with warnings.catch_warnings():  # a pixel non-finite in every photo stays NaN (then ignored)
                    warnings.simplefilter("ignore", RuntimeWarning)
                    grey = grey - np.nanmedian(grey, axis=0)
        stats = [highlight_compactness(s.rows, s.cols, g) for g in grey]
        out.append(classify_sphere(stats))
    return out


def calibrate_bounce(results: list[PhotoEstimate], n_spheres: int, max_sigma: float = 0.05, min_photos: int = 3,
                     min_lz: float = 0.2) -> list[BounceCalibration]:
    """Each sphere's ground ratio ``rho_g`` from the photos where it is well determined.

    The light reflected by the ground onto a sphere is ``c = rho_g a max(l_z, 0)``: the ground's
    irradiance is ``max(l_z, 0)`` times the sphere's (``a``), and ``rho_g`` (the ground albedo times
    the fraction of the ground the sphere sees lit) is a constant of the capture for each sphere.
    Where a photo shows the sphere's shadow side the free-bounce fit separates ``c`` from the
    ambient and the light (small ``ground_ratio_sigma``); where it does not (light on the camera
    side) ``c`` is confounded with them. The weighted median of the well-determined photos'
    ``c / (a l_z)`` is imposed in all photos (:func:`ffls.spheres.photo.estimate_photo`
    ``bounce_ratio``).

    Parameters
    ----------
    results : list of PhotoEstimate
        Fitted with a free bounce.
    n_spheres : int
    max_sigma : float
        Largest ``ground_ratio_sigma`` of a photo to use.
    min_photos : int
        Fewer usable photos than this leave the sphere uncalibrated (free bounce per photo).
    min_lz : float
        Smallest ``l_z`` of a photo to use (the ratio divides by ``l_z``).

    Returns
    -------
    list of BounceCalibration
        Per sphere.
    """
    out = []
    for k in range(n_spheres):
        est, w = [], []
        for r in results:
            if r.status != "ok" or not r.spheres:
                continue
            sp = r.spheres[k]
            if sp.kind != "matte":
                continue
            d, q, sd = sp.direction, sp.fit.ground_ratio, sp.fit.ground_ratio_sigma
            if (sp.status != "ok" or d is None or not np.isfinite(q) or not np.isfinite(sd) or d[2] < min_lz
                    or not sd <= max_sigma):
                continue
            est.append(float(q))
            w.append(1.0 / max(float(sd), 1e-6) ** 2)
        if len(est) < min_photos:
            out.append(BounceCalibration(ratio=None, spread=None, n_photos=len(est)))
            continue
        out.append(_weighted_median_ratio(est, w))
    return out


@dataclass(frozen=True)
class FlatField:
    """A capture's lens fall-off (vignetting) as its spheres see it (:func:`calibrate_flat_field`).

    The fall-off is the ``cos^4`` law of the lens, ``V(rho) = (1 + rho^2)^(-2 strength)`` with
    ``rho`` the distance from the lens's centre over its focal length in pixels (natural
    vignetting is ``strength`` 1; a lens's barrel adds to it). Across a sphere's disk it is the
    gradient ``1 + gradient . d`` (``d`` the offset from the disk's centre in apparent radii,
    columns then rows).

    Attributes
    ----------
    strength : float
        The law's exponent over the natural one, fitted to the spheres' measured gradients (0
        where not applied).
    sigma : float
        Its standard error.
    p : float
        One-sided significance of a fall-off (``strength > 0``; Student's t over the photos).
    applied : bool
        ``p <`` :data:`ffls.spheres.photo.SIGNIFICANCE`: every matte sphere's values are divided
        by its ``gradients`` before its directions are fitted; :func:`two_pass` then keeps the
        division only where the spheres agree better with it (:func:`disagreement_change`).
    gradients : (k, 2) float
        Per sphere, the law's gradient across its disk (zeros where not applied, and for
        mirror spheres).
    measured : (k, 2) float
        Per sphere, the gradient fitted freely over the photos (NaN with too few photos).
    measured_sigma : (k, 2) float
        Its standard errors, from the photos' scatter.
    n_photos : (k,) int
        Per sphere, the photos whose fit took part.
    """

    strength: float
    sigma: float
    p: float
    applied: bool
    gradients: np.ndarray
    measured: np.ndarray
    measured_sigma: np.ndarray
    n_photos: np.ndarray

    def as_dict(self) -> dict:
        """The top-level ``"flat_field"`` record of ``lights.json`` (``docs/formats.md``); a
        sphere's freely measured gradient is ``null`` where it had too few photos."""
        def pairs(a):
            return [[float(v) for v in row] if np.all(np.isfinite(row)) else None
                    for row in np.asarray(a, dtype=float).reshape(-1, 2)]

        return {"model": "cos4", "strength": float(self.strength),
                "sigma": float(self.sigma) if np.isfinite(self.sigma) else None, "p": float(self.p),
                "applied": bool(self.applied), "gradients": pairs(self.gradients), "measured": pairs(self.measured),
                "measured_sigma": pairs(self.measured_sigma),
                "photos": [int(n) for n in np.asarray(self.n_photos).ravel()]}


#: Rounds of the flat-field fit and first pass in :func:`two_pass` (the fit is one Gauss-Newton
#: step from the photos' fits, biased by the gradient: on a 7% per radius gradient the first
#: step found 87-92% of it; a second is kept only where the spheres then agree better).
FLAT_FIELD_ROUNDS = 2
#: Fewest photos for a sphere's measured gradient (two unknowns and a covariance from their scatter).
FLAT_FIELD_MIN_PHOTOS = 4


def _compose_flat(a: FlatField, b: FlatField) -> FlatField:
    """Two rounds' fields as one (the gradients are small: their sum)."""
    return FlatField(a.strength + b.strength, b.sigma, min(a.p, b.p), a.applied or b.applied,
                     a.gradients + b.gradients, a.measured, a.measured_sigma, a.n_photos)


def flat_field_offsets(s: SphereSamples) -> np.ndarray:
    """(m, 2) offsets of a sphere's pixels from its disk's centre (the pixels' mean), columns then
    rows, in apparent radii."""
    r = float(s.radius_px) if s.radius_px > 0 else 1.0
    return np.column_stack([(s.cols - s.cols.mean()) / r, (s.rows - s.rows.mean()) / r])


def _flat_field_divisor(s: SphereSamples, gradient) -> np.ndarray:
    """(m,) the divisor of a sphere's pixels under a relative ``gradient`` (2,) per radius
    (:func:`flat_field_offsets`); the guard keeps it positive: a gradient of a radius or more is no
    lens's."""
    return np.maximum(1.0 + flat_field_offsets(s) @ gradient, 1e-3)


def cos4_gradient(s: SphereSamples, lens: tuple) -> np.ndarray:
    """(2,) the relative gradient per radius of the natural ``cos^4`` fall-off across a sphere's disk.

    Parameters
    ----------
    s : SphereSamples
    lens : (cx, cy, f)
        The lens's centre (pixels) and focal length (pixels).
    """
    cx, cy, f = (float(x) for x in lens)
    x, y = (float(s.cols.mean()) - cx) / f, (float(s.rows.mean()) - cy) / f
    # d ln (1 + x^2 + y^2)^-2 = -4 (x, y) / (1 + x^2 + y^2), per pixel over f, times the radius
    return -4.0 * np.array([x, y]) / (1.0 + x * x + y * y) * float(s.radius_px) / f


def _measured_gradient(results, k, s, values, up, min_photos):
    """One sphere's gradient fitted freely over the photos: ``(gradient, covariance, n_photos)``."""
    offsets, A, b = None, [], []
    for r, vals in zip(results, values):
        if not r.spheres or k >= len(r.spheres):
            continue
        sr = r.spheres[k]
        f = sr.fit
        if not (isinstance(f, LambertFit) and f.status == "ok" and sr.status != "shadowed"
                and f.inliers is not None and f.intensity > 0):
            continue
        if offsets is None:
            offsets, g0, shadow = flat_field_offsets(s), s.ground_factor(up), own_shadow_of(s.normals, up)
        g = shadowed_ground_bounce(s.normals, f.direction, up, g0, shadow) if f.own_shadow else g0
        Ap, bp = flat_field_terms(s.normals, vals[k][0], f, offsets, g)
        A.append(Ap)
        b.append(bp)
    n = len(A)
    if n < max(int(min_photos), 3):
        return np.full(2, np.nan), np.full((2, 2), np.nan), n
    A, b = np.array(A), np.array(b)
    try:
        Ainv = np.linalg.inv(A.sum(axis=0))
    except np.linalg.LinAlgError:
        return np.full(2, np.nan), np.full((2, 2), np.nan), n
    grad = Ainv @ b.sum(axis=0)
    scores = b - A @ grad  # each photo's share: the photos as independent draws (the sandwich)
    return grad, Ainv @ (scores.T @ scores * (n / (n - 1.0))) @ Ainv, n


def lens_centre(capture, shape: tuple[int, int]) -> tuple[float, float, float]:
    """The lens's centre and focal length in pixels, ``(cx, cy, f)``, for :func:`calibrate_flat_field`:
    a pinhole's principal point and focal length (the geometric mean of ``fx`` and ``fy``); an
    orthographic camera's image centre and half diagonal (its fall-off is the barrel's)."""
    K = getattr(capture, "K", None)
    if getattr(capture, "camera_model", "pinhole") != "orthographic" and K is not None:
        K = np.asarray(K, dtype=np.float64)
        return float(K[0, 2]), float(K[1, 2]), float(np.sqrt(abs(K[0, 0] * K[1, 1])))
    H, W = int(shape[0]), int(shape[1])
    return 0.5 * (W - 1), 0.5 * (H - 1), 0.5 * float(np.hypot(W, H))


def calibrate_flat_field(results: list[PhotoEstimate], samples: list[SphereSamples], values: list, lens: tuple,
                         up: np.ndarray = UP, min_photos: int = FLAT_FIELD_MIN_PHOTOS) -> FlatField:
    """The capture's lens fall-off, fitted over all photos' shading fits of its matte spheres.

    A lens's fall-off (vignetting) is the same in every photo of a capture: across a sphere's
    disk it is a fixed multiplicative gradient, which one photo confounds with its light (a tilt
    of the direction of about the gradient per radius, in radians: 3.5 degrees at 7%), but many
    photos under different lights separate, as the encoding curve shared over photos is.

    1. Each sphere's gradient is fitted freely: the joint least squares of every photo's own
       parameters and the sphere's shared gradient, with the photos' parameters eliminated
       (:func:`ffls.spheres.lambert.flat_field_terms`: one Gauss-Newton step from the photos'
       fits). Its covariance is the photos' sandwich: a misfit inside a photo counts once.
    2. A lens's gradients are not free: they point to the lens's centre and grow away from it.
       The spheres' gradients are explained by the ``cos^4`` law with one exponent, fitted by
       generalised least squares (:func:`cos4_gradient`). A sphere's systematic misfit that is
       no lens's (an object's interreflection on one side, in every photo) gives gradients that
       the law does not share, and a law that brightens outward is no fall-off.
    3. The law is applied where its exponent is a significant fall-off (one-sided,
       p < :data:`ffls.spheres.photo.SIGNIFICANCE`): a capture without vignetting keeps its values.

    Parameters
    ----------
    results : list of PhotoEstimate
        The photos' fits (a pass of :func:`two_pass`).
    samples : list of SphereSamples
    values : list
        Per photo, its :func:`ffls.spheres.samples.sphere_values`.
    lens : (cx, cy, f)
        The lens's centre and focal length in pixels (an orthographic capture: the image's centre
        and half diagonal).
    up : (3,) float
        World up (the bounce's form factor).
    min_photos : int
        Fewer usable photos of a sphere leave it out of the law's fit.

    Returns
    -------
    FlatField
    """
    from scipy.special import stdtr

    k = len(samples)
    meas, sig, count = np.full((k, 2), np.nan), np.full((k, 2), np.inf), np.zeros(k, dtype=int)
    matte = np.zeros(k, dtype=bool)
    num = den = 0.0
    dof = None
    for i, s in enumerate(samples):
        matte[i] = any(r.spheres and i < len(r.spheres) and isinstance(r.spheres[i].fit, LambertFit) for r in results)
        grad, cov, count[i] = _measured_gradient(results, i, s, values, up, min_photos)
        if not np.all(np.isfinite(grad)):
            continue
        meas[i], sig[i] = grad, np.sqrt(np.maximum(np.diag(cov), 0.0))
        h = cos4_gradient(s, lens)
        try:
            w = np.linalg.solve(cov, h)
        except np.linalg.LinAlgError:
            continue
        num, den = num + float(w @ grad), den + float(w @ h)
        dof = count[i] - 1 if dof is None else min(dof, count[i] - 1)
    none = np.zeros((k, 2))
    if not den > 0 or dof is None:
        return FlatField(0.0, float("inf"), 1.0, False, none, meas, sig, count)
    strength, sigma = num / den, den ** -0.5
    p = float(stdtr(dof, -strength / sigma))  # one-sided: only a fall-off is a lens's
    applied = bool(p < SIGNIFICANCE)
    grads = np.array([strength * cos4_gradient(s, lens) if applied and m else np.zeros(2)
                      for s, m in zip(samples, matte)]).reshape(k, 2)
    return FlatField(strength if applied else 0.0, sigma, p, applied, grads, meas, sig, count)


def disagreement_change(before: list[PhotoEstimate], after: list[PhotoEstimate]) -> float:
    """The change of the spheres' disagreement (the sum of the photos' chi-square of their light
    model) over the photos accepted both before and after a change of the values.

    A lens's fall-off tilts each sphere's direction its own way (toward the lens's centre), so
    dividing it out makes the spheres agree; a gradient that is the scene's (an object's light on
    one side of a sphere in every photo) does not. Negative: they agree better."""
    both = [(b, a) for b, a in zip(before, after) if b.status == "ok" and a.status == "ok"]
    return float(sum(a.chi2 for _, a in both) - sum(b.chi2 for b, _ in both))


def flat_field_values(values: list, samples: list[SphereSamples], field: FlatField) -> list:
    """The photos' sphere values divided by the capture's applied flat field (:class:`FlatField`)."""
    if not field.applied:
        return values
    div = [_flat_field_divisor(s, g) if np.any(g != 0) else None
           for s, g in zip(samples, field.gradients)]
    return [[v if d is None else sphere_values_of((v[0] / d).astype(v[0].dtype, copy=False), v[1], v[2],
                                                  getattr(v, "ground", None))
             for v, d in zip(vals, div)] for vals in values]


#: Fewest photos whose shadow side shows a sphere's bounce for its shape (:func:`calibrate_bounce_shape`).
BOUNCE_SHAPE_MIN_PHOTOS = 5
#: Fewest shadow-side pixels of a photo for :func:`calibrate_bounce_shape`.
BOUNCE_SHAPE_MIN_PIXELS = 20


def calibrate_bounce_shape(results: list[PhotoEstimate], samples: list[SphereSamples], values: list,
                           terminator: float = 0.15, min_photos: int = BOUNCE_SHAPE_MIN_PHOTOS,
                           min_pixels: int = BOUNCE_SHAPE_MIN_PIXELS) -> list[np.ndarray | None]:
    """Each matte sphere's horizontal gradient of the ground's light, from its shadow sides over the photos.

    The bounce model is an infinite uniform ground (``g``, less the sphere's own shadow). A
    textured ground, or an object that hides part of a sphere's ground, is brighter on one side:
    the bounce is ``g (1 + beta . n_h)`` with ``n_h`` the normal's horizontal part (world x, y) and
    ``beta`` a constant of the capture for each sphere, like its ground ratio. Where no direct light
    falls (``n . l < -terminator``) the residual of a free-bounce fit is ``c g beta . n_h``: one
    linear least-squares problem over all photos (docs/spheres.md, "The ground bounce's shape").

    Parameters
    ----------
    results : list of PhotoEstimate
        Fitted with a free bounce (the first pass), one per entry of ``values``.
    samples : list of SphereSamples
    values : list
        Per photo of ``results``, its :func:`ffls.spheres.samples.sphere_values`.
    terminator : float
    min_photos, min_pixels : int
        A sphere needs ``min_photos`` photos with at least ``min_pixels`` shadow-side pixels.

    Returns
    -------
    list of (2,) float or None
        Per sphere ``beta`` (along world x, y), or None where too few photos show it.
    """
    out = []
    for k, s in enumerate(samples):
        n = s.normals
        g0, own = s.ground_factor(UP), own_shadow_of(n, UP)
        A, y = [], []
        for r, vals in zip(results, values):
            if not r.spheres:
                continue
            sp = r.spheres[k]
            f = sp.fit
            if sp.status != "ok" or sp.kind != "matte" or not isinstance(f, LambertFit) or not f.bounce > 0:
                continue
            v = vals[k]
            side = np.asarray(v.valid, bool) & np.isfinite(v.grey) & (n @ f.direction < -terminator)
            if side.sum() < min_pixels:
                continue
            g = (shadowed_ground_bounce(n, f.direction, UP, g0, own) if f.own_shadow else g0)[side]
            A.append(np.stack([g * n[side, 0], g * n[side, 1]], axis=1) * (f.bounce / f.intensity))
            y.append((v.grey[side] - f.ambient - f.bounce * g) / f.intensity)
        if len(A) < min_photos:
            out.append(None)
            continue
        beta = np.linalg.lstsq(np.concatenate(A), np.concatenate(y), rcond=None)[0]
        out.append(beta if np.all(np.isfinite(beta)) else None)
    return out


def shaped_samples(samples: list[SphereSamples], shapes: list) -> list[SphereSamples]:
    """The spheres' samples with each one's bounce factor ``g`` times ``1 + beta . n_h``
    (:func:`calibrate_bounce_shape`; None: unchanged)."""
    return [s if b is None else replace(s, ground=s.ground_factor(UP) * (1.0 + s.normals[:, :2] @ b))
            for s, b in zip(samples, shapes)]


#: Fewest photos whose free fit gives a sphere's albedo for its seen ground (:func:`calibrate_ground_albedo`).
GROUND_ALBEDO_MIN_PHOTOS = 3


def calibrate_ground_albedo(results: list[PhotoEstimate], samples: list[SphereSamples], values: list,
                            min_photos: int = GROUND_ALBEDO_MIN_PHOTOS) -> list[float | None]:
    """Each matte sphere's albedo ``kappa`` for the bounce of its seen ground (``bounce='observed'``).

    The first pass fits the bounce ``c B`` with the form factor of
    :func:`ffls.spheres.ground.observed_bounce`, the ground relative to ``L_ref`` (the lit seen
    ground's median): ``c / L_ref`` is the sphere's albedo in the photo's units, the same in every
    photo. Its median over the photos whose free fit has a bounce (docs/spheres.md, "Two terms").

    Returns
    -------
    list of float or None
        Per sphere (None: no ground view, or fewer than ``min_photos`` photos).
    """
    out = []
    for k, s in enumerate(samples):
        est = []
        for r, vals in zip(results, values):
            if s.ground_view is None or not r.spheres:
                continue
            sp, ground = r.spheres[k], getattr(vals[k], "ground", None)
            f = sp.fit
            if (ground is None or sp.status != "ok" or sp.kind != "matte" or not isinstance(f, LambertFit)
                    or f.model != "bounce" or not f.bounce > 0):
                continue
            ref = reference_radiance(s.ground_view, ground, f.direction)
            if ref > 0:
                est.append(f.bounce / ref)
        out.append(float(np.median(est)) if len(est) >= min_photos else None)
    return out


def _weighted_median_ratio(est: list, w: list) -> BounceCalibration:
    """The weighted median of per-photo ground ratios (weights: inverse variances), clipped to [0, 1]."""
    est, w = np.asarray(est, dtype=np.float64), np.asarray(w, dtype=np.float64)
    o = np.argsort(est)
    cw = np.cumsum(w[o])
    med = float(est[o][np.searchsorted(cw, 0.5 * cw[-1])])
    spread = float(1.4826 * np.median(np.abs(est - med)))
    return BounceCalibration(ratio=float(np.clip(med, 0.0, 1.0)), spread=spread, n_photos=int(len(est)))


def _used_matte_fits(results: list[PhotoEstimate], values: list):
    """``(k, fit, values)`` of each accepted photo's used matte spheres fitted ``'ok'``."""
    for r, vals in zip(results, values):
        if not r.ok:
            continue
        for k in r.used_spheres:
            f = r.spheres[k].fit
            if r.spheres[k].status == "ok" and isinstance(f, LambertFit):
                yield k, f, vals[k]


def _refit_each(args) -> list[LambertFit]:
    """Sphere ``s``'s fits made again, each on its own values from its own fit's ground ratio and
    direction (``starts``: ``(bounce_ratio, direction)`` per entry of ``values``): a picklable task."""
    s, starts, values, options = args
    n = len(values)
    return fit_spheres([s] * n, values, bounce_ratio=[b for b, _ in starts], start=[d for _, d in starts],
                       **options)


def halves_offsets(results: list[PhotoEstimate], samples: list[SphereSamples], values: list, *,
                   terminator: float = 0.15, up: np.ndarray = UP, own_shadow: bool = True,
                   map_fn=map) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Each accepted photo's matte spheres fitted again on the two halves of their pixels.

    The halves lie either side of a plane through the sphere's fitted light, across the plane of
    the light and the camera (the mean of the sphere's seen normals), placed where each holds
    half of the photo's lit pixels (the lit part the camera sees is symmetric about the plane of
    the light and the camera, so each half holds a like share of it): both fit the light about
    equally well, with their own pixels' noise and their own share of what the model leaves out
    (:func:`ffls.spheres.uncertainty.halves_error_model`).
    Each half is fitted as the sphere was (:func:`ffls.spheres.photo.fit_spheres`: its calibrated
    ground ratio, its own shadow, started from its direction).

    Parameters
    ----------
    results : list of PhotoEstimate
        One per entry of ``values``.
    samples : list of SphereSamples
    values : list
        Per photo, its :func:`ffls.spheres.samples.sphere_values`.
    terminator : float
    up : (3,) float
    own_shadow : bool
    map_fn : callable
        ``map``-like: runs the halves' fits (independent of each other), e.g. in a pool of processes.

    Returns
    -------
    residuals : list of (2, 2) float
        Per photo and used matte sphere whose halves both fit, the halves' tangent offsets
        (radians) from the sphere's direction.
    sigmas : list of (2,) float
        The halves' statistical per-axis standard deviations (degrees).
    """
    up = normalize(np.asarray(up, dtype=np.float64))
    tasks = []
    for k, f, v in _used_matte_fits(results, values):
        l = np.asarray(f.direction, dtype=np.float64)
        n = samples[k].normals
        axis = np.cross(l, n.mean(axis=0))  # across the plane of the light and the camera
        if np.linalg.norm(axis) < 1e-3 * np.linalg.norm(n.mean(axis=0)):
            axis = np.cross(l, up if abs(l @ up) < 0.99 else [1.0, 0.0, 0.0])
        key = n @ normalize(axis)
        lit = np.asarray(v[1], bool) & np.isfinite(v[0]) & (n @ l > terminator)
        if not lit.any():
            continue
        side = key >= np.median(key[lit])  # as many lit pixels on each side
        tasks.append((samples[k], f, [sphere_values_of(v[0], np.asarray(v[1], bool) & h, v[2],
                                                       getattr(v, "ground", None)) for h in (side, ~side)],
                      dict(terminator=terminator, up=up, own_shadow=own_shadow)))
    residuals, sigmas = [], []
    for (_, f, _, _), halves in zip(tasks, map_fn(_refit_halves, tasks)):
        if all(h.status == "ok" and np.isfinite(h.uncertainty_deg) for h in halves):
            residuals.append(tangent_residuals(np.array([h.direction for h in halves]),
                                               np.asarray(f.direction, dtype=np.float64)))
            sigmas.append(np.array([h.uncertainty_deg for h in halves]) / np.sqrt(2.0))
    return residuals, sigmas


def _refit_halves(args) -> list[LambertFit]:
    """Sphere ``s``'s fit ``fit`` made again on each of its two halves (its calibrated ground ratio,
    started from its direction; ``options``: ``terminator``, ``up``, ``own_shadow``): a picklable
    task of :func:`halves_offsets`."""
    s, fit, halves, options = args
    return _refit_each((s, [(fit.bounce_ratio, fit.direction)] * len(halves), halves, options))


def flat_field_shift_deg(results: list[PhotoEstimate], samples: list[SphereSamples], values: list,
                         flat: FlatField | None, *, terminator: float = 0.15, up: np.ndarray = UP,
                         own_shadow: bool = True, shared: bool = False, map_fn=map) -> float:
    """Per-axis standard deviation (degrees) of the matte spheres' directions from a lens fall-off
    that the spheres measured but the capture did not divide out.

    :func:`calibrate_flat_field` keeps a fall-off only where the spheres agree better with it
    (:func:`disagreement_change`), which one sphere cannot show; a gradient across its disk turns
    its direction alike in both halves, so their disagreement does not show it either. Where a
    sphere's freely fitted gradient (``FlatField.measured``, less what was divided out) is
    significant (its chi-square over its standard errors, 2 degrees of freedom, at
    :data:`ffls.spheres.photo.SIGNIFICANCE`), each accepted photo's sphere is fitted again with
    it divided out: the root mean square of the turn over the photos, half on each axis. With
    ``shared``, the turn is the part of each photo's used spheres' turns (a sphere without such a
    gradient, or not matte, turns 0) that they share, which their disagreement cannot show (it
    shows how their turns differ): the squared turn of their mean less what their spread about it
    gives that mean (:func:`_shared_square`), so that one sphere's own gradient (a shadow or a
    bounce across its disk, not the lens) is left to the disagreement that already holds it.

    Parameters
    ----------
    results : list of PhotoEstimate
    samples : list of SphereSamples
    values : list
        Per photo of ``results``, its sphere values (as fitted).
    flat : FlatField or None
    terminator, up, own_shadow
        As the spheres' own fits (:func:`ffls.spheres.photo.fit_spheres`).
    shared : bool
        The turn of each photo's spheres' mean, not of each sphere.
    map_fn : callable
        ``map``-like: runs the refits (one task per sphere, its photos' fits), e.g. in a pool of
        processes.

    Returns
    -------
    float
        0 without a significant unapplied gradient.
    """
    if flat is None:
        return 0.0
    rest = np.nan_to_num(np.asarray(flat.measured, dtype=np.float64)
                         - np.asarray(flat.gradients, dtype=np.float64))
    sd = np.asarray(flat.measured_sigma, dtype=np.float64)
    z2 = np.sum(np.where(sd > 0, rest / np.where(sd > 0, sd, 1.0), 0.0) ** 2, axis=1)
    significant = np.exp(-0.5 * z2) < SIGNIFICANCE  # (chi-square of 2 degrees of freedom)
    if not significant.any():
        return 0.0
    todo = {}  # per sphere with a significant gradient: its (photo, fit, values divided) to fit again
    for i, (r, vals) in enumerate(zip(results, values)):
        for k, f, v in _used_matte_fits([r], [vals]):
            if k < significant.size and significant[k]:
                div = _flat_field_divisor(samples[k], rest[k])
                todo.setdefault(k, []).append((i, f, sphere_values_of(v[0] / div, v[1], v[2],
                                                                      getattr(v, "ground", None))))
    options = dict(terminator=terminator, up=up, own_shadow=own_shadow)
    tasks = [(samples[k], [(f.bounce_ratio, f.direction) for _, f, _ in t], [v for _, _, v in t], options)
             for k, t in todo.items()]
    refits = {(i, k): g for k, fits in zip(todo, map_fn(_refit_each, tasks)) for (i, _, _), g in zip(todo[k], fits)}
    turns = []
    for i, (r, vals) in enumerate(zip(results, values)):
        moved = []  # the turns of the photo's used spheres with a significant gradient (vectors)
        for k, f, _ in _used_matte_fits([r], [vals]):
            g = refits.get((i, k))
            if g is not None and g.status == "ok":
                moved.append(g.direction - f.direction)
        if not shared:
            turns.extend(float(np.sum(np.square(m))) for m in moved)
        elif r.ok and r.used_spheres:  # the part of their turns they share (the others turn 0)
            t = np.zeros((len(r.used_spheres), 3))
            t[:len(moved)] = np.reshape(moved, (-1, 3))
            turns.append(_shared_square(t))
    return float(np.degrees(np.sqrt(max(float(np.mean(turns)), 0.0) / 2.0))) if turns else 0.0


def _shared_square(turns: np.ndarray) -> float:
    """The squared norm of the turn that ``k`` spheres share, from their turns ``(k, d)``.

    With ``t_i = c + e_i`` (``e_i`` each sphere's own, independent), ``|mean t|^2`` holds
    ``|c|^2`` plus ``sum |e_i|^2 / k^2``, whose expectation ``sum |t_i - mean t|^2 / (k (k - 1))``
    is subtracted (the between- and within-group decomposition of a one-way random-effects model):
    an unbiased estimate of ``|c|^2``, negative where the turns differ more than they agree (a mean
    over photos is clipped at 0 by the caller). One sphere turned alone gives 0; all turned alike,
    their turn's square.
    """
    t = np.asarray(turns, dtype=np.float64)
    k = t.shape[0]
    mean = t.mean(axis=0)
    if k < 2:
        return float(mean @ mean)
    return float(mean @ mean - np.sum((t - mean) ** 2) / (k * (k - 1)))


def _measured_centre_shifts(results: list[PhotoEstimate], samples: list[SphereSamples], values: list,
                            which: list[bool], terminator: float, map_fn=map) -> np.ndarray:
    """(k, 2) per sphere, its shading's centre against its outline (:func:`refine_sphere_centres`,
    not applied) in its radii, where ``which`` and accepted; 0 elsewhere
    (:func:`ffls.spheres.uncertainty.centre_floor_deg` of a radius 1 gives its turn)."""
    out = np.zeros((len(samples), 2))
    if any(which):
        for k, ref in enumerate(_centre_refinements(samples, results, values, terminator, map_fn, None, which)):
            if which[k] and ref.accepted and samples[k].radius_px > 0:
                out[k] = np.asarray(ref.shift_px, dtype=np.float64) / float(samples[k].radius_px)
    return out


def _fit_of(results: list[PhotoEstimate], k: int):
    """Sphere ``k``'s fit in the first accepted photo that used it (None: no such photo)."""
    return next((r.spheres[k].fit for r in results if r.ok and k in r.used_spheres), None)


def calibrate_uncertainty(results: list[PhotoEstimate], samples: list[SphereSamples],
                          refinements: list[CentreRefinement] | None = None,
                          scene_center: np.ndarray | None = None, kinds: list[SphereKind] | None = None,
                          values: list | None = None, fit_options: dict | None = None,
                          flat: FlatField | None = None, occluded: bool = False, map_fn=map,
                          **kwargs) -> tuple[ErrorModel, list[PhotoEstimate]]:
    """The capture's error model from its spheres' disagreement, and the photos' 95% cones under it.

    Every accepted photo with two or more used spheres gives their tangent offsets from the
    directions its light predicts at each sphere (the distant direction, or the near light's
    position seen from each sphere's centre) and their 1-sigma fit statistics;
    :func:`ffls.spheres.uncertainty.fit_error_model` fits the capture's per-sphere scale and floor
    (trimmed restricted maximum likelihood) and bounds the common mode. With fewer such photos
    (one sphere per photo) the stated fallback model is used. Every photo (accepted or not) then
    gets its cones (:meth:`ffls.spheres.photo.PhotoEstimate.with_error_model`). With the scene
    centre, the near photos' lights' distances from it give the model's distance error
    (:func:`ffls.spheres.uncertainty.distance_spread`), which turns each near photo's direction
    by its own coupling (``PhotoEstimate.distance_coupling_deg``).

    Parameters
    ----------
    results : list of PhotoEstimate
    samples : list of SphereSamples
        The spheres (their world centres, for near lights; their pixel radii).
    refinements : list of CentreRefinement, optional
        Per sphere, its photometric centre refinement: an accepted one measures the centre's
        uncertainty (outline against shading), propagated to the sphere's direction
        (:func:`ffls.spheres.uncertainty.centre_floor_deg`) as a known part of its variance.
    scene_center : (3,) float, optional
        Where the directions are reported from (no distance term without it).
    kinds : list of SphereKind, optional
        Each sphere's kind (:func:`sphere_kinds`), for its kind's own terms of the model (without
        them, one shared model).
    values : list, optional
        Per photo of ``results``, its :func:`ffls.spheres.samples.sphere_values`. Where no sphere
        checks another (fewer than 3 photos with 2+ spheres), the matte spheres' halves are then
        fitted (:func:`halves_offsets`) and the model is theirs
        (:func:`ffls.spheres.uncertainty.halves_error_model`), with each matte sphere's centre
        term measured (its shading's centre against its outline, :func:`refine_sphere_centres`,
        not applied) where no refinement gave one. Where the spheres check each other, the part
        of those measured shifts that the spheres share (what turns them alike, which their
        disagreement cannot show; :func:`_shared_square`, as the lens turn's) joins the model's
        common floor. None: the stated fallback, and no shared terms.
    fit_options : dict, optional
        ``terminator``, ``up`` and ``own_shadow`` of the spheres' fits (for the halves).
    flat : FlatField, optional
        The capture's lens fall-off: a significant gradient the spheres measured but the capture
        did not divide out adds its turn (:func:`flat_field_shift_deg`; with two or more spheres,
        that of their mean) to the model's common floor.
    occluded : bool
        Whether pixels of a matte sphere's disk were found foreign (:func:`mask_foreign_pixels`): with
        the halves, the occluder's own light on the ball (its bounce, the ground it hides from the
        ball), which turns both halves alike and nothing here measures, joins the model's common
        floor at the stated fallback's floor (:data:`ffls.spheres.uncertainty.FALLBACK_FLOOR_DEG`
        RMS, per axis over ``sqrt(2)``).
    map_fn : callable
        ``map``-like: runs the measured centres' refinements and the halves' fits, e.g. in a pool
        of processes (:meth:`PhotoFitter.map`).
    **kwargs
        Passed to :func:`ffls.spheres.uncertainty.fit_error_model`.

    Returns
    -------
    model : ErrorModel
    results : list of PhotoEstimate
    """
    centers = np.array([s.center for s in samples])
    centre = np.zeros(len(samples))
    for k, (s, ref) in enumerate(zip(samples, refinements or [])):
        if ref is not None and ref.accepted:
            centre[k] = centre_floor_deg(ref.shift_px, s.radius_px)
    residuals, sigmas, used_all = [], [], []
    for r in results:
        if not r.ok or len(r.used_spheres) < 2:
            continue
        used = r.used_spheres
        dirs = [r.spheres[i].direction for i in used]
        if any(d is None for d in dirs):
            continue
        near = r.model == "near" and r.position is not None
        residuals.append(photo_residuals(np.array(dirs), r.direction, r.position if near else None,
                                         centers[used] if near else None))
        sigmas.append(np.array([r.spheres[i].fit.uncertainty_deg for i in used]) / np.sqrt(2.0))
        used_all.append(np.asarray(used))
    model = fit_error_model(residuals, sigmas, spheres=used_all, centre_deg=centre,
                            kinds=[kd.kind for kd in kinds] if kinds is not None else None, **kwargs)
    if values is not None:
        options = fit_options or {}
        # a centre error turns a sphere's halves alike, and the spheres' outlines can be off alike
        # (one detector, the same ground below each): each unrefined matte sphere's centre measured
        # by its shading against its outline (not applied: only its uncertainty)
        unrefined = [c == 0.0 and isinstance(_fit_of(results, k), LambertFit) for k, c in enumerate(centre)]
        shifts = _measured_centre_shifts(results, samples, values, unrefined, options.get("terminator", 0.15),
                                         map_fn)
        lens = flat_field_shift_deg(results, samples, values, flat, shared=model.source != "fallback",
                                    map_fn=map_fn, **options)
        if model.source == "fallback":  # no sphere checks another: their halves do
            centre = np.where(unrefined, [centre_floor_deg(d, 1.0) for d in shifts], centre)
            model = halves_error_model(*halves_offsets(results, samples, values, map_fn=map_fn, **options), centre,
                                       **{k: v for k, v in kwargs.items() if k in ("common_correlation", "min_photos")})
            if model.source == "fallback" and kinds is not None:  # a mirror's highlight: its own floors
                model = model.with_mirrors_own_floor([kd.kind for kd in kinds])
            shared = lens  # (the centres are the halves' own terms)
            # the occluder's light on a matte ball: a turn the halves share, unmeasured (a mirror's
            # "foreign" pixels are its highlight and reflections, and it has no halves)
            if occluded and (kinds is None or any(kd.kind != "mirror" for kd in kinds)):
                shared = float(np.hypot(shared, FALLBACK_FLOOR_DEG / np.sqrt(2.0)))
        else:  # their disagreement shows how the spheres' centres differ, not the shift they share
            common = np.sqrt(max(_shared_square(shifts[unrefined]), 0.0)) if any(unrefined) else 0.0
            shared = float(np.hypot(lens, centre_floor_deg(common, 1.0)))
        if shared > 0.0:  # a turn the spheres (or halves) share, as the geometry's common floor is
            model = model.with_shared_floor(shared)
    if scene_center is not None:  # the near fits' own distances (not those placed at their median)
        c = np.asarray(scene_center, dtype=np.float64)
        model = replace(model, distance_sigma=distance_spread(
            [np.linalg.norm(r.position - c) for r in results
             if r.ok and r.model == "near" and r.position is not None and not r.range_deg]))
    return model, [r.with_error_model(model) for r in results]


def _refine_one(args) -> CentreRefinement:
    """:func:`ffls.spheres.refine.refine_sphere_centre` of one sphere (a picklable task)."""
    sample, vals, dirs, terminator, kwargs = args
    return refine_sphere_centre(sample, vals, dirs, terminator=terminator, **kwargs)


def centres_to_refine(spheres) -> list[bool]:
    """Per sphere, whether its centre is refined from the shading (:func:`refine_sphere_centres`).

    The refinement corrects an outline found inside its limb (the log image's edge where the limb
    is dimly lit). An outline refitted at the step of the linear max image
    (``SphereFit.outline_at_step``, :func:`ffls.spheres.detect.step_edges`) is not inside it,
    and the shading is the weaker estimate of its centre: the Lambert model leaves out light the
    scene sends (the ground bounce's cast shadows, interreflections), and on ``ffls synth``'s grey
    ground the refinement started from the true centres moves them 0.05-0.19 px
    (docs/spheres.md, "The outline at the linear step and the centre refinement"). A sphere given
    without ``outline_at_step`` (any object with a ``center_cam`` and a ``radius``) is refined.
    """
    return [not getattr(s, "outline_at_step", False) for s in spheres]


def _centre_refinements(samples: list[SphereSamples], results: list[PhotoEstimate], values: list,
                        terminator: float, map_fn, photos: list[int] | None, which: list[bool] | None,
                        **kwargs) -> list[CentreRefinement]:
    """:func:`refine_sphere_centres`' refinements alone (not applied: no sphere recentred)."""
    which = [True] * len(samples) if which is None else list(which)
    tasks = []
    for k, s in enumerate(samples):
        if not which[k]:
            continue
        dirs = []
        for r in results:
            sp = r.spheres[k] if r.spheres else None
            dirs.append(sp.direction if sp is not None and sp.status == "ok" and sp.kind == "matte" else None)
        fitted = values if photos is None else [values[i] for i in photos]
        tasks.append((s, [v[k] for v in fitted], dirs, terminator, kwargs))
    done = iter(map_fn(_refine_one, tasks))
    refinements = []
    for s, w in zip(samples, which):  # a sphere not refined: its detected centre, as not accepted
        centre = np.array(s.center, dtype=np.float64)
        refinements.append(next(done) if w else CentreRefinement(center=centre, center_initial=centre.copy(),
                                                                 shift_px=np.zeros(2),
                                                                 message="outline at the linear step"))
    return refinements


def refine_sphere_centres(samples: list[SphereSamples], results: list[PhotoEstimate], values: list,
                          terminator: float = 0.15, map_fn=map, photos: list[int] | None = None,
                          which: list[bool] | None = None,
                          **kwargs) -> tuple[list[SphereSamples], list, list]:
    """Refine every sphere's centre from the first-pass shading of all photos.

    :func:`ffls.spheres.refine.refine_sphere_centre` per sphere (photos where that sphere's fit
    was ``'ok'``), then :func:`ffls.spheres.refine.recentre_samples`; the photos' values are
    subset to the new pixels (no image is read again).

    Parameters
    ----------
    samples : list of SphereSamples
    results : list of PhotoEstimate
        First-pass results (their per-sphere fits).
    values : list
        Per photo, its :func:`ffls.spheres.samples.sphere_values` for ``samples``.
    terminator : float
    map_fn : callable
        ``map``-like: runs the spheres' refinements (independent of each other), e.g. in a pool
        of processes.
    photos : list of int, optional
        The photos (indices into ``values``) that ``results`` are of, when only some were fitted
        (:func:`first_pass_photos`); None: ``results`` are of every photo. Every photo's values
        are subset to the new pixels.
    which : list of bool, optional
        Per sphere, whether to refine it (:func:`centres_to_refine`); the others get a refinement
        not accepted. None: every sphere.
    **kwargs
        Passed to :func:`ffls.spheres.refine.refine_sphere_centre`.

    Returns
    -------
    samples : list of SphereSamples
        Recentred where a refinement was accepted (others unchanged).
    values : list
        Per photo, the values for the new samples.
    refinements : list of CentreRefinement
    """
    refinements = _centre_refinements(samples, results, values, terminator, map_fn, photos, which, **kwargs)
    new_samples, kept = [], []
    for s, ref in zip(samples, refinements):
        if ref.accepted:
            s2, idx = recentre_samples(s, ref.center)
            new_samples.append(s2)
            kept.append(idx)
        else:
            new_samples.append(s)
            kept.append(None)
    new_values = [[(vk if isinstance(vk, SphereValues) else SphereValues(*vk)).subset(i) if i is not None else vk
                   for vk, i in zip(v, kept)] for v in values]
    return new_samples, new_values, refinements


def refit_spheres(result: PhotoEstimate, samples: list[SphereSamples], values: list,
                  refinements: list[CentreRefinement], *, terminator: float = 0.15,
                  up: np.ndarray = UP, own_shadow: bool = True) -> PhotoEstimate:
    """A photo's first-pass ``result`` with the free-bounce fits of the recentred spheres redone.

    What the capture-wide bounce calibration needs after a centre refinement
    (:func:`calibrate_bounce` reads the per-sphere ground ratios of the photos that were
    ``'ok'``): the photo's status and the spheres' combination are kept from the first pass (the
    second pass redoes them with the calibrated ratios), only the per-sphere fits of the spheres
    whose centre moved are recomputed, each started from its first-pass direction. Spheres that
    the first pass marked (shadowed, outlier) keep that mark.

    Parameters
    ----------
    result : PhotoEstimate
    samples : list of SphereSamples
        Recentred (:func:`refine_sphere_centres`).
    values : list of SphereValues
        The photo's values for ``samples``.
    refinements : list of CentreRefinement
    terminator : float
    up : (3,) float
    own_shadow : bool
        The bounce less the sphere's own shadow (:func:`ffls.spheres.lambert.fit_lambert`).

    Returns
    -------
    PhotoEstimate
    """
    if not result.spheres:
        return replace(result)
    spheres = list(result.spheres)
    for k, (s, v, ref) in enumerate(zip(samples, values, refinements)):
        old = result.spheres[k]
        if not ref.accepted or old.kind != "matte":
            continue
        g = getattr(v, "ground", None)
        ground = None if s.ground_view is None or g is None else (s.ground_view, g)
        f = fit_lambert(s.normals, v[0], v[1], n_saturated=v[2], terminator=terminator, up=up,
                        g=s.ground_factor(up), start=old.direction,
                        own_shadow=own_shadow, ground=ground)  # (no uncertainty needed: no pixels)
        spheres[k] = SphereResult(f, f.status if old.status == "ok" else old.status)
    return replace(result, spheres=spheres)


# ----------------------------------------------------------------------------- decoding once
#: Largest share of the available memory that :func:`decode_photos` keeps decoded photos in.
DECODED_MEMORY_SHARE = 0.25
#: :func:`decode_photos` cuts the sequence into this many chunks of consecutive photos (fewer for
#: fewer photos), whatever the number of workers: the chunks' reductions are merged in order, so
#: the result, to the last bit, does not depend on the number of workers.
DECODE_CHUNKS = 8


@dataclass
class DecodedPhotos:
    """A capture's photos decoded once (:func:`decode_photos`): what the sphere detection needs of
    them, and (memory permitting) the decoded photos themselves for the first pass.

    Float photos are kept linear (float32), half EXR photos as their stored half values (half the
    memory, and half the pages to touch: the linear values are these widened, exactly, where no
    colour conversion applies; ``held`` says which photos); integer photos as their stored codes
    only (a quarter of the memory for 8 bits). Half and integer photos are widened or linearised
    where they are read (:meth:`photo`: the spheres' pixels), with the capture's encoding, or,
    when ``capture.json`` states none, with the encoding calibrated from these same codes
    (:func:`ffls.spheres.encoding.calibrate_capture_encoding`).

    Attributes
    ----------
    stats : ffls.spheres.detect.SequenceStats
        The detection's reductions of the sequence (max image, brightest photo, mean luminance,
        per-photo colour counts and edge evidence; :func:`ffls.spheres.detect.sequence_stats`):
        of the linear photos, or of the stored values when ``stored``.
    bit_depths : set
        The photos' stored bit depths.
    linear : (n, H, W, 3) float32 or float16, or None
        Float photos, in memory shared with the worker processes (None: integer photos, or over
        the budget); float16: half photos as stored.
    held : (n,) bool or None
        With float16 ``linear``: which photos it holds (False: one whose linear values are not
        its stored ones, a colour-converted or float photo, read again where needed).
    raw : (n, H, W, 3) uint8 or uint16, or None
        Integer photos' stored codes (None: float photos, or over the budget).
    encoding : str or dict
        The capture's encoding when decoded (``'auto'``: none stated).
    response : ndarray or None
        The capture's inverse response table, for ``{'response': ...}`` encodings.
    stored : bool
        The encoding was unknown when decoded (integer photos, none stated): ``stats`` are of the
        stored values (scaled to [0, 1]), and the photos can be read only with an encoding given
        (the calibrated one).
    """

    stats: SequenceStats
    bit_depths: set
    linear: np.ndarray | None = None
    raw: np.ndarray | None = None
    encoding: object = "auto"
    response: np.ndarray | None = None
    stored: bool = False
    held: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.stats.n

    @property
    def shape(self) -> tuple:
        """(H, W) of the photos."""
        return self.stats.max.shape[:2]

    def photo(self, i: int, capture=None, pixels: tuple | None = None):
        """Photo ``i`` as ``(linear, raw, bit_depth)`` from memory, or None where not kept.

        Parameters
        ----------
        i : int
        capture : ffls.io.capture.Capture, optional
            Its ``encoding`` and ``response`` linearise integer photos (default: the encoding
            they were decoded with); an encoding still unknown gives None.
        pixels : (rows, cols) of int arrays, optional
            Linearise an integer or half photo at these pixels only (the others are 0), e.g. the
            spheres'.

        Returns
        -------
        linear : (H, W, 3) float32
        raw : (H, W, 3) uint8 or uint16, or None
            The stored codes (None for float photos).
        bit_depth : {8, 16, 'half', 'float'}
        """
        if len(self.bit_depths) != 1:
            return None
        depth = next(iter(self.bit_depths))
        if self.linear is not None and self.linear.dtype == np.float32:
            return self.linear[i], None, depth
        if self.linear is not None:  # half values as stored: widened (exactly) where read
            if not self.held[i]:
                return None
            half = self.linear[i]
            if pixels is None:
                return half.astype(np.float32), None, depth
            rows, cols = pixels
            linear = np.zeros(half.shape, np.float32)  # (untouched pages of a zeroed array cost nothing)
            linear[rows, cols] = half[rows, cols]
            return linear, None, depth
        if self.raw is None:
            return None
        from ffls.io.images import ImageData
        from ffls.radiance.photos import encoding_unknown, linearise

        encoding = self.encoding if capture is None else capture.encoding
        response = self.response if capture is None else capture.response
        if encoding_unknown(encoding, depth):
            return None
        codes = self.raw[i]
        top = np.float32(255 if codes.dtype == np.uint8 else 65535)
        if pixels is None:  # the whole photo, as ffls.io.images reads it (codes / top, float32)
            # (with its codes: an sRGB or gamma curve is undone by a table of the codes, not a power)
            return np.asarray(linearise(ImageData(codes.astype(np.float32) / top, depth, "png", None, codes=codes),
                                        encoding, response), dtype=np.float32), codes, depth
        rows, cols = pixels
        stored = codes[rows, cols].astype(np.float32)[:, None] / top
        linear = np.zeros(codes.shape, np.float32)  # untouched pages of a large zeroed array cost nothing
        linear[rows, cols] = np.asarray(linearise(ImageData(stored, depth, "png", None), encoding, response),
                                        dtype=np.float32)[:, 0]
        return linear, codes, depth

    def photo_levels(self, capture) -> np.ndarray | None:
        """Per photo, its frame's level (:attr:`ffls.spheres.detect.SequenceStats.levels`, the
        99.5th percentile of its luminance) in linear units: stored levels (``stored``) linearised
        as a grey of that code with ``capture``'s encoding (the one calibrated from them); None
        where some photo has none or the encoding is still unknown."""
        levels = dict(self.stats.levels)
        if sorted(levels) != list(range(self.n)):
            return None
        out = np.array([levels[i] for i in range(self.n)], dtype=np.float64)
        if not self.stored:
            return out
        from ffls.io.images import ImageData
        from ffls.radiance.photos import encoding_unknown, linearise

        depth = max(self.bit_depths)
        if encoding_unknown(capture.encoding, depth):
            return None
        grey = np.repeat(np.clip(out, 0.0, 1.0).astype(np.float32)[:, None, None], 3, axis=2)
        linear = linearise(ImageData(grey, depth, "png", None), capture.encoding, capture.response)
        return np.asarray(linear, dtype=np.float64)[:, 0, 1]

    def linear_stats(self, capture):
        """The detection's reductions (:func:`ffls.spheres.detect.sequence_stats`) of the integer
        photos kept in memory, linearised with ``capture``'s encoding (e.g. the one calibrated from
        ``stats``, of the stored values): no photo is read again. None where they are not kept."""
        from types import SimpleNamespace

        from ffls.radiance.photos import full_scale_share

        if self.raw is None:
            return None
        acc = SequenceAccumulator(n_images=self.n)
        for i in range(self.n):
            ph = self.photo(i, capture)
            if ph is None:
                return None
            linear, codes, depth = ph
            acc.add(linear, i, full_scale=full_scale_share(SimpleNamespace(bit_depth=depth, codes=codes)))
        return acc.result()


def _available_memory() -> int:
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 0


def _shared_array(shape, dtype) -> np.ndarray:
    """A zeroed array in anonymous shared memory: written by forked worker processes, seen here."""
    import mmap

    nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    return np.frombuffer(mmap.mmap(-1, max(nbytes, 1)), dtype=dtype, count=int(np.prod(shape))).reshape(shape)


@dataclass
class _DecodeContext:
    capture: object
    n: int
    shape: tuple
    linear: np.ndarray | None
    raw: np.ndarray | None
    depth: int | str | None = None  # the bit depth every photo must have (no encoding stated), else None
    held: np.ndarray | None = None  # with float16 ``linear``: which photos it holds (DecodedPhotos.held)
    slots: dict | None = None  # per chunk start: shared buffers its reductions are stowed in (workers)


_decode_context: _DecodeContext | None = None


def _set_decode_context(context: _DecodeContext) -> None:
    global _decode_context
    _decode_context = context


def _decode_range(bounds: tuple[int, int]):
    """Decode photos ``start..stop-1`` (into the shared arrays where kept) and reduce them:
    ``(SequenceAccumulator of the range, bit depths)``."""
    from ffls.radiance.photos import full_scale_share, read_photo

    ctx = _decode_context
    start, stop = bounds
    # made in the shared buffers it is handed over in (workers)
    acc = SequenceAccumulator(n_images=ctx.n, buffers=None if ctx.slots is None else ctx.slots[start])
    depths = set()
    half = ctx.linear is not None and ctx.linear.dtype == np.float16
    scratch = np.empty(ctx.shape, np.float32) if half else None  # each half photo widened here
    for i in range(start, stop):
        slot = None if ctx.linear is None else ctx.linear[i]  # an EXR is widened in place (no copy)
        if half:  # its half values are interleaved into the slot as read, widened into the scratch
            ph = read_photo(ctx.capture, i, out=scratch, depth=ctx.depth, stored=slot)
            # held where the linear values are the stored ones widened: a half photo, no conversion
            ctx.held[i] = ph.bit_depth == "half" and ph.linear is scratch and ph.raw is scratch
        else:
            ph = read_photo(ctx.capture, i, out=slot, depth=ctx.depth)
        if ph.linear.shape != ctx.shape:
            raise InputError(f"image is {ph.linear.shape[1]}x{ph.linear.shape[0]}, the capture's first is "
                             f"{ctx.shape[1]}x{ctx.shape[0]}: every photo must have the same size",
                             ctx.capture.image_paths[i])
        depths.add(ph.bit_depth)
        if ctx.linear is not None and not half and ph.bit_depth not in (8, 16) and ph.linear is not slot:
            ctx.linear[i] = ph.linear
        if ctx.raw is not None and ph.bit_depth in (8, 16):
            if ph.codes is not None and ph.codes.dtype == ctx.raw.dtype:
                ctx.raw[i] = ph.codes
            else:
                top = 255.0 if ctx.raw.dtype == np.uint8 else 65535.0
                ctx.raw[i] = np.rint(np.clip(ph.raw, 0.0, 1.0) * top)
        acc.add(ph.linear, i, full_scale=full_scale_share(ph))
    if ctx.slots is not None:  # handed over in shared memory, not through the pipe
        acc.stow(ctx.slots[start])
    return acc, depths


def decode_photos(capture, workers: int = 1, keep: bool = True, progress_bar=None) -> DecodedPhotos:
    """Decode every photo of ``capture`` once: the reductions the sphere detection needs and,
    within :data:`DECODED_MEMORY_SHARE` of the available memory, the photos for the first pass.

    :data:`DECODE_CHUNKS` chunks of consecutive photos are decoded and reduced
    (:class:`ffls.spheres.detect.SequenceAccumulator`: max, brightest photo, mean luminance,
    per-photo colour counts and edge evidence) in ``workers`` processes (forked: they write the
    photos into shared memory), and the chunks' reductions merged in order: the result is that of
    :func:`ffls.spheres.detect.sequence_stats` over the sequence (the luminance and edge sums to
    within rounding), the same for any ``workers``.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
    workers : int
    keep : bool
        Keep the decoded photos (within the budget).
    progress_bar : tqdm, optional
        Advanced by one per photo.

    Returns
    -------
    DecodedPhotos

    Raises
    ------
    InputError
        An unreadable photo, or one whose size differs from the first one's.
    """
    from ffls.io.images import read_image
    from ffls.radiance.photos import encoding_unknown, photo_of_image

    n = len(capture.image_paths)
    if n == 0:
        raise InputError("capture lists no images", capture.json_path)
    decoding = capture
    head = read_image(capture.image_paths[0])
    stored = encoding_unknown(capture.encoding, head.bit_depth)
    if stored:  # no encoding stated: the stored values (what the encoding calibration finds the spheres on)
        decoding = replace(capture, encoding="linear")
    first = photo_of_image(decoding, 0, head)  # (read once here; its chunk reads it into place)
    shape = first.linear.shape
    integer = first.bit_depth in (8, 16)
    per_photo = first.linear.size * (1 if first.bit_depth == 8 else 2) if integer else first.linear.nbytes
    # half photos kept as stored where the first one's values are not colour-converted on reading
    half = first.bit_depth == "half" and head.colour_note is None
    if half:
        per_photo //= 2
    linear = raw = held = None
    if keep and n * per_photo <= DECODED_MEMORY_SHARE * _available_memory():
        if integer:
            raw = _shared_array((n,) + shape, np.uint8 if first.bit_depth == 8 else np.uint16)
        else:
            linear = _shared_array((n,) + shape, np.float16 if half else np.float32)
            held = _shared_array((n,), np.bool_) if half else None
    context = _DecodeContext(decoding, n, shape, linear, raw,
                             first.bit_depth if capture.encoding == "auto" else None, held=held)
    workers = max(1, min(int(workers), n))
    size = max(1, -(-n // DECODE_CHUNKS))  # the chunks do not depend on the workers: nor does the result
    chunks = [(a, min(a + size, n)) for a in range(0, n, size)]
    acc = depths = None

    def fold(part):  # in order: the earlier photo wins ties of the brightest
        nonlocal acc, depths
        if acc is None:
            acc, depths = part
        else:
            acc.merge(part[0])
            depths |= part[1]

    if workers == 1:
        _set_decode_context(context)
        try:
            for c in chunks:
                fold(_decode_range(c))
                if progress_bar is not None:
                    progress_bar.update(c[1] - c[0])
        finally:
            _set_decode_context(None)
    else:
        from concurrent.futures import ProcessPoolExecutor

        layout = SequenceAccumulator(n_images=n).layout(shape)
        context.slots = {c[0]: {k: _shared_array(*v) for k, v in layout.items()} for c in chunks}
        with ProcessPoolExecutor(max_workers=min(workers, len(chunks)), initializer=_set_decode_context,
                                 initargs=(context,)) as ex:
            parts = ex.map(_decode_range, chunks)  # (every chunk submitted: the workers are forked now)
            # the detection and the fits after the decoding need SciPy's optimisers, which this
            # package's modules import where they are used (about 1 s of import): imported here,
            # while the workers decode, instead of before they start
            import scipy.optimize  # noqa: F401
            for (part, d), c in zip(parts, chunks):
                fold((part.unstow(context.slots[c[0]], copy=acc is None), d))  # (the first is merged into)
                del context.slots[c[0]]  # (its shared memory is freed)
                if progress_bar is not None:
                    progress_bar.update(c[1] - c[0])
    if len(depths) != 1:  # mixed bit depths: the first pass reads each photo again
        linear = raw = held = None
    return DecodedPhotos(stats=acc.result(), bit_depths=depths, linear=linear, raw=raw, encoding=capture.encoding,
                         response=capture.response, stored=stored, held=held)


# ----------------------------------------------------------------------------- running the photo fits
class PhotoTask(NamedTuple):
    """One photo's fit: its values (None: read photo ``index`` of the capture), the imposed
    ground ratios, the spheres' start directions and whether to run the joint near fit."""

    index: int
    values: list | None = None
    bounce_ratio: list | None = None
    start: list | None = None
    joint: bool = True
    refit: tuple | None = None  # (first-pass estimate, refinements): refit_spheres instead of a fit
    fit: bool = True  # False: only read the photo's values (the estimate is None)


@dataclass
class _FitContext:
    """What every photo fit of a pass shares (sent once to each worker process)."""

    capture: object
    samples: list[SphereSamples]
    scene_center: np.ndarray
    options: dict  # estimate_photo keyword arguments (model, min_spheres, sigma_floor_deg, ...)
    decoded: DecodedPhotos | None = None  # photos decoded once (shared memory), else read here

    def __post_init__(self):
        # every sphere's pixels: where an integer photo kept as codes is linearised
        self.pixels = (np.concatenate([s.rows for s in self.samples]).astype(np.intp),
                       np.concatenate([s.cols for s in self.samples]).astype(np.intp)) if self.samples else None
        seen = [s.ground_view for s in self.samples if s.ground_view is not None]
        if seen and self.pixels is not None:  # and their grounds' pixels (bounce 'observed')
            rows, cols = ground_pixels(seen)
            self.pixels = (np.concatenate([self.pixels[0], rows]), np.concatenate([self.pixels[1], cols]))


#: The context of the photo fits running in this process (set by :func:`_set_context`).
_context: _FitContext | None = None


def _set_context(context: _FitContext) -> None:
    global _context
    _context = context


def _run_photo_task(task: PhotoTask) -> tuple[PhotoEstimate, list | None]:
    """Fit one photo in the current context; returns its estimate and, where the photo was read
    here, its sphere values (grey float32: kept in memory for the later passes)."""
    ctx = _context
    if task.refit is not None:
        return refit_spheres(task.refit[0], ctx.samples, task.values, task.refit[1],
                             terminator=ctx.options.get("terminator", 0.15), up=ctx.options.get("up", UP),
                             own_shadow=ctx.options.get("own_shadow", True)), None
    values, read = task.values, task.values is None
    if read:
        kept = None if ctx.decoded is None else ctx.decoded.photo(task.index, ctx.capture, ctx.pixels)
        if kept is None:
            photo = read_photo(ctx.capture, task.index)
            kept = (photo.linear, photo.raw, photo.bit_depth)
        values = sphere_values(kept[0], ctx.samples, saturation=ctx.options.get("saturation"), raw=kept[1],
                               bit_depth=kept[2])
        values = [sphere_values_of(v.grey.astype(np.float32), v.valid, v.n_saturated, v.ground) for v in values]
    if not task.fit:
        return None, (values if read else None)
    est = estimate_photo(None, ctx.samples, ctx.scene_center, values=values, bounce_ratio=task.bounce_ratio,
                         start=task.start, joint=task.joint, **ctx.options)
    return est, (values if read else None)


#: The decoded photos the worker processes of a :class:`PhotoFitter` inherited when forked.
_inherited_decoded: DecodedPhotos | None = None


def _set_inherited(decoded: DecodedPhotos | None) -> None:
    global _inherited_decoded
    _inherited_decoded = decoded


#: The pass whose context this worker process last unpickled: ``(pass number, context)``.
_worker_pass: tuple | None = None


def _run_photo_chunk(job: tuple) -> list:
    """A worker's share of a pass: ``(pass number, pickled context, tasks)``, the context without
    its decoded photos (inherited by the worker: :func:`_set_inherited`); :func:`_run_photo_task`
    of each task. The context is unpickled once per pass in each worker: its ground views' kernels
    (kept per normals array, :meth:`GroundView.kernel`) then serve every chunk of the pass, not
    only the chunk that built them."""
    global _worker_pass
    number, pickled, tasks = job
    if _worker_pass is None or _worker_pass[0] != number:
        context = pickle.loads(pickled)
        if context.decoded is None:
            context.decoded = _inherited_decoded
        _worker_pass = (number, context)
    _set_context(_worker_pass[1])
    return [_run_photo_task(t) for t in tasks]


class PhotoFitter:
    """Runs a pass's photo fits in this process (``workers == 1``) or in a pool of processes.

    One pool for every pass and the centre refinement: forked once, at the first parallel call,
    inheriting the decoded photos (shared memory); each pass sends its context (the spheres'
    samples and the fit options) with each chunk of photos. :meth:`close` ends it.
    """

    def __init__(self, capture, scene_center, options: dict, workers: int = 1, progress_bar=None,
                 decoded: DecodedPhotos | None = None):
        self.capture, self.scene_center, self.options, self.decoded = capture, scene_center, options, decoded
        self.workers, self.progress_bar = max(1, int(workers)), progress_bar
        self._pool = None
        self._passes = 0  # (numbers the passes sent to the workers: :func:`_run_photo_chunk`)

    def _executor(self):
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            # what each worker would otherwise make for itself after the fork, made here once and
            # inherited: the validity masks' module (imported by sphere_values where it is used) and
            # the own-shadow table (which the parent builds too)
            importlib.import_module("ffls.radiance.response")
            if self.options.get("own_shadow", True):
                own_shadow_table()  # (inherited by the workers, not built by each)
            methods = multiprocessing.get_all_start_methods()  # fork: the decoded photos are inherited
            self._pool = ProcessPoolExecutor(max_workers=self.workers, initializer=_set_inherited,
                                             initargs=(self.decoded,),
                                             mp_context=multiprocessing.get_context("fork" if "fork" in methods
                                                                                    else None))
        return self._pool

    def close(self) -> None:
        """End the pool of processes (if any)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def map(self, fn, items) -> list:
        """``[fn(x) for x in items]``, in the pool of processes when there are several workers and items."""
        items = list(items)
        if self.workers == 1 or len(items) < 2:
            return [fn(x) for x in items]
        return list(self._executor().map(fn, items))

    def advance(self, n: int) -> None:
        if self.progress_bar is not None:
            self.progress_bar.update(n)

    def run(self, tasks: list[PhotoTask], samples: list[SphereSamples],
            counted: bool = True) -> list[tuple[PhotoEstimate, list | None]]:
        """:func:`_run_photo_task` for every task, in order; ``counted`` advances the progress bar."""
        context = _FitContext(self.capture, samples, self.scene_center, self.options, self.decoded)
        out = []
        if self.workers == 1 or len(tasks) == 1:
            _set_context(context)
            for t in tasks:
                out.append(_run_photo_task(t))
                if counted:
                    self.advance(1)
            return out
        # (pickled once: the workers have the decoded photos, and unpickle it once per pass)
        sent = pickle.dumps(replace(context, decoded=None), protocol=pickle.HIGHEST_PROTOCOL)
        self._passes += 1
        size = max(1, len(tasks) // (8 * self.workers))
        chunks = [tasks[a:a + size] for a in range(0, len(tasks), size)]
        for part in self._executor().map(_run_photo_chunk, [(self._passes, sent, c) for c in chunks]):
            out.extend(part)
            if counted:
                self.advance(len(part))
        return out


def _check_highlights(results: list[PhotoEstimate], kinds: list[SphereKind], where) -> None:
    """InputError when a mirror sphere's highlight is saturated (no unclipped shoulder) in every photo."""
    for k, kind in enumerate(kinds):
        if kind.kind != "mirror" or not results:
            continue
        st = [r.spheres[k].fit.status for r in results if r.spheres]
        if st and all(x == "saturated" for x in st):
            raise InputError(f"sphere {k} (mirror): its highlight is saturated in every photo ({len(st)}), with no "
                             f"unclipped edge to locate it; lower the exposure, or give the images' encoding and "
                             f"saturation level", where)


def _outlines_holding_highlights(results: list[PhotoEstimate], mirrors: list, limb_image) -> list:
    """Per sphere its view, the mirror ones' outline chosen to hold the photos' highlights
    (:func:`ffls.spheres.highlight.outline_holding_highlights`); None where not a mirror."""
    out = []
    for k, v in enumerate(mirrors):
        if v is None:
            out.append(None)
            continue
        pixels = [getattr(r.spheres[k].fit, "pixel", (np.nan, np.nan)) for r in results
                  if r.spheres and r.spheres[k].fit is not None]
        out.append(outline_holding_highlights(v, limb_image, np.reshape(pixels, (-1, 2)))[0] if pixels else v)
    return out


def _sphere_fit_options(fitter: PhotoFitter) -> dict:
    """The fitter's options that a sphere's own fit takes (:func:`halves_offsets`)."""
    return {k: fitter.options[k] for k in ("terminator", "up", "own_shadow") if k in fitter.options}


def two_pass(fitter: PhotoFitter, samples: list[SphereSamples], values: list | None, n_photos: int, *,
              bounce: str, refine_centres: bool, refine_options: dict | None, materials: list | None = None,
              views: list | None = None, where=None, limb_image=None, flat_field: tuple | None = None,
              first_pass: int | None = FIRST_PASS_PHOTOS, bounce_shape: bool | None = None,
              halves: bool = True, levels=None) -> CaptureEstimate:
    """The two passes over the photos (module docstring); ``values`` None: the first pass reads the photos.

    ``materials`` (per sphere ``'matte'``, ``'mirror'`` or ``'auto'``; all matte when None) and
    ``views`` (per sphere its :class:`~ffls.spheres.highlight.SphereView`) decide each sphere's
    fit; ``where`` is the path named by a capture-wide error. ``limb_image`` (the sequence's mean
    luminance), when given, places each mirror sphere's outline at its limb's step
    (:func:`ffls.spheres.highlight.refine_view_limb`). ``flat_field`` (the lens's ``(cx, cy, f)``,
    or None: not fitted): after the first pass, the lens's fall-off is fitted over the photos
    (:func:`calibrate_flat_field`) and, where significant, divided out of the matte spheres'
    values and the first pass run again (at most :data:`FLAT_FIELD_ROUNDS` times: the fit is one
    Gauss-Newton step from the photos' fits). ``first_pass`` (None: every photo): with a calibrated
    bounce the first pass fits only that many photos (:func:`first_pass_photos`; the others' values
    are read) and the steps it feeds use those; the second pass fits every photo. A capture with a
    mirror sphere has every photo fitted in the first pass (its highlight checks read them all).
    ``halves`` False: a lone sphere's cones are the stated fallback's, not its halves'
    (:func:`calibrate_uncertainty` without the values). ``levels`` (per photo its frame's level,
    :meth:`DecodedPhotos.photo_levels`, or None): a misfired photo is rejected as ``dark``
    (:func:`reject_dark_photos`) before the cones are calibrated on the accepted ones."""
    materials = ["matte"] * len(samples) if materials is None else list(materials)
    if views is None and any(m != "matte" for m in materials):
        raise ValueError("mirror or 'auto' spheres need their views")
    views = [None] * len(samples) if views is None else list(views)

    def limb(v):
        return v if limb_image is None or v is None else refine_view_limb(v, limb_image, len(views) == 1)[0]

    views = [limb(v) if m == "mirror" else v for m, v in zip(materials, views)]
    fitter.options["mirrors"] = [v if m == "mirror" else None for m, v in zip(materials, views)]
    terminator = fitter.options.get("terminator", 0.15)
    # with a calibrated bounce the first pass only feeds the centre refinement and the calibration
    # (per-sphere fits): its near photos skip the joint position fit, redone in the second pass
    joint = bounce == "free"
    # the photos the first pass fits (with a calibrated bounce, first_pass of them; the others are
    # only read); ``results`` holds their estimates, in that order, until the second pass
    fitted = first_pass_photos(n_photos, first_pass if bounce == "calibrated" else None)
    chosen = set(fitted)

    def run_fitted(vals, counted=False):  # the fitted photos' first-pass fits from ``vals`` (every photo's)
        return [r for r, _ in fitter.run([PhotoTask(i, values=vals[i], joint=joint) for i in fitted], samples,
                                         counted=counted)]

    first = fitter.run([PhotoTask(i, values=None if values is None else values[i], joint=joint, fit=i in chosen)
                        for i in range(n_photos)], samples)
    if values is None:
        values = [v for _, v in first]
    results = [r for r, _ in first if r is not None]
    if any(s.ground_view is not None for s in samples):  # bounce 'observed': the object out of the ground
        lights = [(i, r.direction) for i, r in zip(fitted, results) if r.status == "ok"]
        samples, values, masked = mask_object_from_ground(samples, values, lights)
        if any(masked):
            results = run_fitted(values)
    # an occluder over a lone matte sphere: its pixels out, the fits again (with 2+ spheres the
    # photos' combination sets a turned sphere aside; masking there moved c11's and c14's errors)
    occluded = False
    for _ in range(FOREIGN_ROUNDS if len(samples) == 1 else 0):
        values, foreign = mask_foreign_pixels(results, fitted, samples, values)
        if not any(foreign):
            break
        occluded = True
        results = run_fitted(values)
    kinds = sphere_kinds(materials, samples, values)
    views = [limb(v) if kd.kind == "mirror" and m != "mirror" else v for kd, m, v in zip(kinds, materials, views)]
    mirrors = [v if kd.kind == "mirror" else None for kd, v in zip(kinds, views)]
    if len(fitted) < n_photos and any(kd.kind == "mirror" for kd in kinds):
        # a mirror sphere: every photo's first-pass fit (the highlight checks read them all)
        if mirrors == fitter.options["mirrors"]:  # the others' fits (else all are fitted again just below)
            rest = [i for i in range(n_photos) if i not in chosen]
            done = dict(zip(fitted, results))
            done.update(zip(rest, [r for r, _ in fitter.run([PhotoTask(i, values=values[i], joint=joint)
                                                              for i in rest], samples, counted=False)]))
            results = [done[i] for i in range(n_photos)]
        fitted = list(range(n_photos))
    if mirrors != fitter.options["mirrors"]:  # classified mirrors: their first-pass fits from the highlight
        fitter.options["mirrors"] = mirrors
        results = run_fitted(values)
    if limb_image is not None:  # a chrome ball's outline must hold every photo's highlight
        held = _outlines_holding_highlights(results, mirrors, limb_image)
        if held != mirrors:
            fitter.options["mirrors"] = mirrors = held
            views = [h if h is not None else v for h, v in zip(held, views)]
            results = run_fitted(values)
    _check_highlights(results, kinds, where)
    flat = None
    if flat_field is not None:  # the lens's fall-off across each sphere, shared by all photos, divided out
        up = fitter.options.get("up", UP)
        for _ in range(FLAT_FIELD_ROUNDS):
            step = calibrate_flat_field(results, samples, [values[i] for i in fitted], flat_field, up)
            if step.applied:
                corrected = flat_field_values(values, samples, step)
                refitted = run_fitted(corrected)
                if disagreement_change(results, refitted) < 0.0:
                    values, results = corrected, refitted
                else:  # the spheres agree no better: the gradients were the scene's, not the lens's
                    step = replace(step, strength=0.0, applied=False, gradients=np.zeros_like(step.gradients))
            flat = step if flat is None else _compose_flat(flat, step)
            if not step.applied:
                break
    by_photo = dict(zip(fitted, results))

    def refit(indices, ratios, counted):
        tasks = [PhotoTask(i, values=values[i], bounce_ratio=ratios,
                            start=_starts(by_photo[i]) if i in by_photo else None) for i in indices]
        return [r for r, _ in fitter.run(tasks, samples, counted)]

    def finished(results, samples, calibration):  # the final fits' near distances, cones and estimate
        results = reject_shadowed_photos(reject_dark_photos(results, levels))
        results = place_at_capture_range(results, samples, fitter.scene_center)
        error_model, results = calibrate_uncertainty(results, samples, refinements, fitter.scene_center, kinds,
                                                     values=values if halves else None,
                                                     fit_options=_sphere_fit_options(fitter), flat=flat,
                                                     occluded=occluded, map_fn=fitter.map)
        return CaptureEstimate(results, calibration, refinements, samples, error_model, kinds, flat)

    refinements = None
    which = None if isinstance(refine_centres, bool) else [bool(w) for w in refine_centres]
    if which is not None or refine_centres:
        samples, values, refinements = refine_sphere_centres(samples, results, values, terminator=terminator,
                                                             map_fn=fitter.map, photos=fitted, which=which,
                                                             **(refine_options or {}))
        if any(r.accepted for r in refinements):
            if bounce == "free":
                results = refit(range(n_photos), None, counted=False)
            else:  # only what the bounce calibration reads: the recentred spheres' fits
                results = [r for r, _ in fitter.run([PhotoTask(i, values=values[i], refit=(r, refinements))
                                                     for i, r in zip(fitted, results)],
                                                    samples, counted=False)]
            by_photo = dict(zip(fitted, results))
    if bounce == "free":
        return finished(results, samples, None)
    if any(s.ground_view is not None for s in samples):  # bounce 'observed': the seen ground measured
        kappas = calibrate_ground_albedo(results, samples, [values[i] for i in fitted])
        if any(k is not None for k in kappas):
            samples = [s if k is None else replace(s, ground_view=replace(s.ground_view, kappa=k))
                       for s, k in zip(samples, kappas)]
            results = run_fitted(values)  # the free fits of the hidden ground's bounce, for its ratio
            by_photo = dict(zip(fitted, results))
    calibration = calibrate_bounce(results, len(samples))
    ratios = [c.ratio for c in calibration]
    if bounce_shape is None:  # auto: with one matte sphere nothing cancels its bias (docs/spheres.md)
        bounce_shape = sum(kd.kind == "matte" for kd in kinds) == 1
    if bounce_shape and np.array_equal(fitter.options.get("up", UP), UP):  # (the world's ground, +Z up)
        shapes = calibrate_bounce_shape(results, samples, [values[i] for i in fitted], terminator=terminator)
        if any(b is not None for b in shapes):
            samples = shaped_samples(samples, shapes)
            calibration = [replace(c, gradient=None if b is None else tuple(float(x) for x in b))
                           for c, b in zip(calibration, shapes)]
    if any(r is not None for r in ratios):
        results = refit(range(n_photos), ratios, counted=True)
    elif refinements is not None and any(r.accepted for r in refinements):
        # no calibration, but recentred spheres: the first pass's combinations (directions, used
        # spheres) are of the old centres, so every photo is fitted again (free bounce)
        results = refit(range(n_photos), None, counted=True)
    else:  # no calibration: the first pass is final; its near photos get their joint fit now, and
        # the photos it did not fit their fit
        pending = [i for i in range(n_photos) if i not in by_photo or by_photo[i].joint_pending]
        if pending:
            for i, r in zip(pending, refit(pending, None, counted=False)):
                by_photo[i] = r
        results = [by_photo[i] for i in range(n_photos)]
        fitter.advance(n_photos)
    return finished(results, samples, calibration)


#: Fewest near photos, and least fraction of the accepted photos, that make a capture's lights near
#: for :func:`place_at_capture_range`.
NEAR_CAPTURE_MIN_PHOTOS = 3
NEAR_CAPTURE_FRACTION = 0.5
#: A near fit whose direction's 1-sigma error (``PhotoEstimate.joint_sigma_deg``) is over one radian
#: did not locate its light (the linearised covariance means nothing there): in
#: :func:`place_at_capture_range` it is placed like a distant combination.
UNLOCATED_SIGMA_DEG = float(np.degrees(1.0))


def _place_on_ray(r: PhotoEstimate, direction: np.ndarray, centers: np.ndarray, c: np.ndarray,
                  distance: float) -> np.ndarray | None:
    """The point at ``distance`` from ``c`` on the ray along ``direction`` from the weighted place
    of a photo's used spheres (None where the distance does not reach past them)."""
    w = np.asarray(r.weights if r.weights else np.ones(len(r.used_spheres)), dtype=np.float64)
    origin = (w[:, None] * ray_origins(r.used_spheres, [s.fit for s in r.spheres], centers)).sum(0) / w.sum() - c
    d = normalize(np.asarray(direction, dtype=np.float64))
    b = float(origin @ d)
    disc = b * b - float(origin @ origin) + distance ** 2
    return None if disc <= 0 else origin + (np.sqrt(disc) - b) * d + c


def place_at_capture_range(results: list[PhotoEstimate], samples: list[SphereSamples],
                           scene_center: np.ndarray, confidence: float = 0.95) -> list[PhotoEstimate]:
    """The distant combinations of a capture of near lights, placed at the capture's light distance.

    A photo keeps the distant model when its spheres' parallax is not significant: one sphere's
    direction far less certain than the others' (a grazing light, a highlight at the rim) leaves
    the rays' meeting point unmeasured. Its direction is then the used spheres' common direction,
    seen from their (weighted) place, not from the scene centre: under a lamp 2 m away, a sphere
    0.35 m off the centre sees it up to 10 degrees away from where the centre does, far outside
    the combination's cone (``ffls synth --near 2 --sphere-material mixed``: 9.4-11.2 degrees
    against cones of 0.75-0.94, docs/spheres.md). Where most accepted photos (at least
    :data:`NEAR_CAPTURE_FRACTION`, and :data:`NEAR_CAPTURE_MIN_PHOTOS`) have a near light, such
    a photo's light is put on its ray at the median distance of the near photos' lights.

    So is a near fit that did not locate its light (its direction's 1-sigma over one radian,
    :data:`UNLOCATED_SIGMA_DEG`): the rays of a grazing light's spheres nearly parallel, one of them
    in the object's cast shadow, its position ran off (a hand-held lamp 1.5 m away, 4 degrees up,
    put 9 km away, 12.9 degrees off, with a cone of 1e8 degrees; docs/spheres.md). Its direction,
    seen from its spheres, is placed the same way, and its joint fit's terms leave its cone.

    Its cone is widened (in quadrature, ``range_deg``) by what the same placement misses on the
    near photos themselves: each near photo's used spheres' inverse-variance mean direction,
    placed at the median distance, against its near fit's direction; the ``confidence`` quantile
    of those angles. It holds both the spread of the lights' distances and the spheres' own
    directions' bias under a near light (the shading's ``1/r^2`` over a matte sphere), which the
    joint near fit takes out and a distant combination keeps.

    Parameters
    ----------
    results : list of PhotoEstimate
    samples : list of SphereSamples
        The spheres (their world centres).
    scene_center : (3,) float
    confidence : float

    Returns
    -------
    list of PhotoEstimate
    """
    c = np.asarray(scene_center, dtype=np.float64)
    ok = [r for r in results if r.ok]
    is_near = [r.ok and r.model == "near" for r in results]
    unlocated = [n and not r.joint_sigma_deg <= UNLOCATED_SIGMA_DEG for r, n in zip(results, is_near)]
    near = [r for r, n, u in zip(results, is_near, unlocated) if n and r.position is not None and not u]
    if len(near) < max(NEAR_CAPTURE_MIN_PHOTOS, NEAR_CAPTURE_FRACTION * len(ok)):
        return results
    distance = float(np.median([np.linalg.norm(r.position - c) for r in near]))
    centers = np.array([s.center for s in samples], dtype=np.float64)
    misses = []
    for r in near:
        dirs = [r.spheres[i].direction for i in r.used_spheres]
        if any(d is None for d in dirs):
            continue
        w = np.asarray(r.weights if r.weights else np.ones(len(dirs)), dtype=np.float64)
        point = _place_on_ray(r, (w[:, None] * np.array(dirs)).sum(0), centers, c, distance)
        if point is not None:
            cos = float(normalize(point - c) @ normalize(np.asarray(r.direction, dtype=np.float64)))
            misses.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    if len(misses) < NEAR_CAPTURE_MIN_PHOTOS:
        return results
    miss = float(np.quantile(misses, confidence))
    out = []
    for r, u in zip(results, unlocated):
        point = (_place_on_ray(r, r.direction, centers, c, distance)
                 if r.ok and (r.model == "distant" or u) and r.used_spheres else None)
        out.append(r if point is None else replace(r, direction=normalize(point - c), position=point,
                                                   model="near", range_deg=miss, joint_sigma_deg=0.0,
                                                   distance_coupling_deg=0.0))
    return out


#: Fewest accepted photos of a sphere for its capture statistics in :func:`reject_shadowed_photos`.
CAPTURE_SHADOW_MIN_PHOTOS = 5


#: A matte fit's relative RMS residual above this multiple of its sphere's median over the capture
#: (and an outlier of their spread) is a cast shadow's edge across the ball
#: (:func:`reject_shadowed_photos`): noise, JPEG and the shading model's errors stay within a few
#: times the median, a shadow's edge leaves residuals of the order of the shading.
SHADOW_MISFIT_RATIO = 8.0


def reject_shadowed_photos(results: list[PhotoEstimate], ratio: float = SHADOW_RATIO,
                           level: float = SIGNIFICANCE,
                           min_photos: int = CAPTURE_SHADOW_MIN_PHOTOS,
                           misfit_ratio: float = SHADOW_MISFIT_RATIO) -> list[PhotoEstimate]:
    """The photos with every sphere in a cast shadow (or every mirror without the lamp's highlight), rejected.

    :func:`ffls.spheres.photo.estimate_photo` sets a sphere aside that is far darker than the
    photo's other spheres (below ``SHADOW_RATIO`` of them); when every sphere of a photo is in
    shadow, none is darker than the others, and their faint shading (the ground's bounce, the
    room's ambient) gives a direction, with a cone, that has nothing to do with the lamp. Against
    the capture it shows: a used matte sphere is dark when its fitted intensity is both below
    ``ratio`` times its median over the capture's accepted photos (the same test as within a
    photo) and an outlier of its own spread over them, ``log`` intensity below the median by
    more than the one-sided normal quantile of ``level`` in robust standard deviations (1.4826
    times the median absolute deviation): a lamp moved nearer and farther by hand spreads the
    intensities, and a photo within that spread is no shadow.

    A mirror sphere's highlight is held to the same test (its ``intensity``, the highlight's
    signal, against the capture's): where the light is behind the ball or off, the brightest
    compact blob left is a reflection of the room (a lit patch of the ground in a chrome ball,
    thousands of times fainter than the lamp's highlights: ``ffls synth --background textured``,
    one photo 165 degrees off), not the lamp. Such a sphere is marked ``no_highlight``; a photo
    whose used spheres are all dark is rejected, as ``no_highlight`` when they are all mirrors.

    A used matte sphere is shadowed too where its fit's relative RMS residual is above
    ``misfit_ratio`` times its median over the capture's accepted photos and an outlier of their
    spread (``log`` RMS, the same one-sided test): the edge of a cast shadow across its lit part
    (an object's shadow over half the ball) leaves residuals of the order of the shading itself,
    which the fit neither rejects (the robust clip scales with them) nor flags by its intensity,
    and turns it by 20-60 deg (lone grey balls ``g41``, ``g36r``, ``g38t``, ``g42l`` in
    docs/spheres.md: such fits at 13-107 times the median RMS, the others at most 5 times).

    Parameters
    ----------
    results : list of PhotoEstimate
    ratio : float
        The fraction of the sphere's median (:data:`ffls.spheres.photo.SHADOW_RATIO`).
    misfit_ratio : float
        The multiple of the sphere's median RMS residual (:data:`SHADOW_MISFIT_RATIO`).
    level : float
        One-sided significance of the outlier test (:data:`ffls.spheres.photo.SIGNIFICANCE`).
    min_photos : int
        A sphere with fewer accepted photos has no statistics, and its photos are kept.

    Returns
    -------
    list of PhotoEstimate
        ``results`` with the photos whose used spheres are all dark rejected, their spheres
        marked ``shadowed`` (matte) or ``no_highlight`` (mirror).
    """
    from scipy.special import ndtri

    k = max((len(r.spheres) for r in results), default=0)
    logs = [[] for _ in range(k)]
    for r in results:
        for i in r.used_spheres if r.ok else ():
            f = r.spheres[i].fit
            if isinstance(f, (LambertFit, HighlightFit)) and f.intensity > 0:
                logs[i].append(np.log(float(f.intensity)))
    z = -float(ndtri(level))

    def robust(v):
        return (np.median(v), 1.4826 * np.median(np.abs(np.asarray(v) - np.median(v)))) if len(v) >= min_photos \
            else None

    stats = [robust(v) for v in logs]
    misfits = [robust([np.log(float(r.spheres[i].fit.rms)) for r in results if r.ok and i in r.used_spheres
                       and isinstance(r.spheres[i].fit, LambertFit) and r.spheres[i].fit.rms > 0])
               for i in range(k)]

    def dark(f, st):
        if not isinstance(f, (LambertFit, HighlightFit)) or st is None:
            return False
        if not f.intensity > 0:
            return True
        d = np.log(float(f.intensity)) - st[0]
        return bool(d < np.log(ratio) and d < -z * st[1])

    def misfit(f, st):  # a cast shadow's edge across the lit part: residuals of the order of the shading
        if not isinstance(f, LambertFit) or st is None or not f.rms > 0:
            return False
        d = np.log(float(f.rms)) - st[0]
        return bool(d > np.log(misfit_ratio) and d > z * st[1])

    out = []
    for r in results:
        used = list(r.used_spheres) if r.ok else []
        shaded = [i for i in used if dark(r.spheres[i].fit, stats[i]) or misfit(r.spheres[i].fit, misfits[i])]
        if not used or len(shaded) < len(used):
            out.append(r)
            continue
        mirror = [isinstance(r.spheres[i].fit, HighlightFit) for i in shaded]
        spheres = [replace(s, status="no_highlight" if isinstance(s.fit, HighlightFit) else "shadowed")
                   if i in shaded else s for i, s in enumerate(r.spheres)]
        reason = "no_highlight" if all(mirror) else "shadowed"
        out.append(_rejected_after_fit(r, reason, spheres=spheres))
    return out


def _rejected_after_fit(r: PhotoEstimate, reason: str, **changes) -> PhotoEstimate:
    """``r`` rejected for ``reason`` by a capture-wide test after its fit (no model, no sphere used,
    no position or weights, an infinite cone); ``changes`` replace other fields too."""
    return replace(r, status="rejected", reason=reason, model=None, used_spheres=[], position=None,
                   uncertainty_deg=float("inf"), weights=None, **changes)


#: A photo whose frame's level is below this fraction of the capture's median is ``dark``
#: (:func:`reject_dark_photos`): a misfired flash.
DARK_RATIO = 0.06


def reject_dark_photos(results: list[PhotoEstimate], levels, ratio: float = DARK_RATIO) -> list[PhotoEstimate]:
    """Reject, as ``dark``, the photos whose whole frame is far darker than the capture's: a
    misfired flash (or a lamp that did not fire), whatever their spheres' fits said.

    ``levels`` are the photos' frame levels (:meth:`DecodedPhotos.photo_levels`: the 99.5th
    percentile of the linear luminance); a photo below ``ratio`` times their median is dark. A
    light behind the spheres or grazing them darkens the spheres, not the frame (the ground, the
    object and the background it lights), and keeps its own reason (``no_highlight``,
    ``shadowed``, ...). Without levels (None) the results are returned as they are."""
    if levels is None or len(levels) != len(results) or len(results) < 3:
        return results
    levels = np.asarray(levels, dtype=np.float64)
    median = float(np.median(levels))
    if not median > 0:
        return results
    out = []
    for r, level in zip(results, levels):
        if level < ratio * median:
            r = _rejected_after_fit(r, "dark")
        out.append(r)
    return out


def _starts(result: PhotoEstimate) -> list:
    """Per sphere, where its refit starts: its own earlier direction, or else the photo's.

    A sphere whose first fit failed starts from the light the photo's other spheres gave (also
    kept for a rejected photo, e.g. ``too_few_spheres``): the fit's own start, least squares on
    the bright pixels, points too low where the ground bounce is as bright as the lit side (a
    white ground, with the light behind the sphere), and so few pixels came out lit that well-lit
    spheres were rejected as ``too_dark`` (5 photos of 80, docs/spheres.md). The fit iterates to
    its own fixed point from either start."""
    own = result.sphere_directions()
    d = result.direction
    photo = np.asarray(d, dtype=np.float64) if d is not None and np.all(np.isfinite(d)) else None
    return [s if s is not None else photo for s in own]


def _check_modes(model: str, bounce: str) -> None:
    if model not in LIGHT_MODELS:
        raise ValueError(f"model must be one of {LIGHT_MODELS}, not {model!r}")
    if bounce not in BOUNCE_MODES:
        raise ValueError(f"bounce must be one of {BOUNCE_MODES}, not {bounce!r}")


# ----------------------------------------------------------------------------- entry points
def estimate_photos(values: list, samples: list[SphereSamples], scene_center: np.ndarray,
                    bounce: str = "calibrated", refine_centres: bool = True, refine_options: dict | None = None,
                    materials: list | None = None, views: list | None = None, limb_image=None,
                    flat_field: tuple | None = None, first_pass: int | None = FIRST_PASS_PHOTOS,
                    bounce_shape: bool | None = None,
                    **kwargs) -> CaptureEstimate:
    """The two passes of :func:`estimate_lights` on photos whose sphere values are given, in this process.

    Parameters
    ----------
    values : list
        Per photo, its :func:`ffls.spheres.samples.sphere_values`.
    samples : list of SphereSamples
    scene_center : (3,) float
    bounce : {'calibrated', 'free', 'observed'}
        ``'observed'``: calibrated, each sphere's bounce from its photographed ground (the
        samples carry their :attr:`~ffls.spheres.samples.SphereSamples.ground_view`, the values
        their ground's radiance: :func:`observed_ground_samples`); no gradient (``bounce_shape``).
    refine_centres : bool or list of bool
        Refine the spheres' centres (all, or per sphere: :func:`centres_to_refine`) from the first
        pass's shading and fit the photos again before the bounce calibration
        (:func:`refine_sphere_centres`).
    refine_options : dict, optional
        Passed to :func:`ffls.spheres.refine.refine_sphere_centre`.
    materials : list of {'matte', 'mirror', 'auto'}, optional
        Per sphere (all matte when None).
    views : list of SphereView, optional
        Per sphere (needed for ``'mirror'`` and ``'auto'``).
    limb_image : (H, W) float, optional
        The sequence's mean luminance (NaN where not read), as :func:`estimate_lights` uses it: a
        mirror sphere's outline at its limb's step (:func:`ffls.spheres.highlight.refine_view_limb`).
    flat_field : (cx, cy, f), optional
        The lens's centre and focal length (pixels): its fall-off (vignetting) is fitted over the
        photos and divided out where significant (:func:`calibrate_flat_field`). None: not fitted.
    first_pass : int, optional
        With a calibrated bounce, the first pass fits this many photos, spread over the sequence
        (:func:`first_pass_photos`); None: every photo.
    bounce_shape : bool, optional
        With a calibrated bounce, each matte sphere's bounce is also given the horizontal gradient
        its shadow sides show over the first pass (:func:`calibrate_bounce_shape`), imposed in the
        second; False: the uniform ground's shape; None (default): only where the capture has one
        matte sphere (with several, their biases partly cancel in the photo's mean around an
        object, and the gradient cost ``ffls synth``'s 4-sphere layout 0.02-0.07 deg of median).
    **kwargs
        Passed to :func:`ffls.spheres.photo.estimate_photo` (``model``, ``min_spheres``,
        ``sigma_floor_deg``, ``terminator``, ``up``, ``mirror_floor_deg``).

    Returns
    -------
    CaptureEstimate
    """
    _check_modes(kwargs.get("model", "auto"), bounce)
    if bounce == "observed":
        if not all(s.ground_view is not None for s in samples):
            raise ValueError("bounce 'observed' needs every sphere's ground_view (observed_ground_samples)")
        bounce, bounce_shape = "calibrated", False
    fitter = PhotoFitter(None, scene_center, kwargs)
    return two_pass(fitter, samples, list(values), len(values), bounce=bounce, refine_centres=refine_centres,
                     refine_options=refine_options, materials=materials, views=views, limb_image=limb_image,
                     flat_field=flat_field, first_pass=first_pass, bounce_shape=bounce_shape)


def check_estimable(capture, model: str, refine_options=None) -> tuple[str, dict | None]:
    """Check that light estimation can run on ``capture`` (camera, sphere radius, images), one line naming the file.

    An orthographic camera gives directions only: the model becomes ``'distant'`` and the centre
    refinement also fits the radius. Returns the ``(model, refine_options)`` to use.

    Raises
    ------
    InputError
        ``model='near'`` with an orthographic camera, a pinhole camera without ``K`` or a capture
        without ``sphere_radius``, or no images.
    """
    if getattr(capture, "camera_model", "pinhole") == "orthographic":
        # parallel rays: directions only (no depth for a near light; the photometric centre
        # refinement runs from a virtual far camera centre, sphere_samples_orthographic);
        # sphere_radius is optional
        if model == "near":
            raise InputError("model 'near' needs a pinhole camera (camera.K): an orthographic camera measures no "
                             "depth to place a near light", capture.json_path)
        model = "distant"
        refine_options = {"fit_radius": True, **(refine_options or {})}
    else:
        if capture.K is None:
            raise InputError("capture has no camera intrinsics (camera.K); light estimation needs them, or declare "
                             "\"camera\": {\"model\": \"orthographic\"} for a long lens", capture.json_path)
        if capture.sphere_radius is None:
            raise InputError("capture has no sphere_radius; light estimation needs it", capture.json_path)
    if not capture.image_names:
        raise InputError("capture lists no images", capture.json_path)
    return model, refine_options


#: Camera tilts searched when a capture gives no ``world_from_camera`` (:func:`fit_camera_tilt`):
#: degrees below the horizon that the optical axis looks, a level camera (0) to straight down (90:
#: a copy stand or an RTI dome's camera); the coarse grid's step, then a bounded refinement to this
#: tolerance. (Up to 80 only, a camera 88 deg down was found at 80.0, 0.75 / 1.39 deg, 88% covered;
#: to 90, 87.6: 0.49 / 0.80, 100%; docs/spheres.md.)
TILT_SEARCH_DEG = (0.0, 90.0, 10.0, 0.5)


#: The camera's roll about its optical axis searched after its tilt (:func:`fit_camera_tilt`): the
#: bound (degrees either way: a tripod that is not level), the largest tilt at which it is fitted,
#: and the refinement's tolerance. A roll ``r`` turns the ground's normal, seen from the camera, by
#: about ``r cos(tilt)`` sideways (a tilt ``t`` turns it by ``t``): looking down more steeply the
#: roll's effect vanishes (straight down it only turns the world about the normal), and past 60 deg
#: it is less than half the tilt's, which the shading gives to 1-2 deg (docs/spheres.md).
ROLL_SEARCH_DEG = (10.0, 60.0, 0.5)

#: Significance at which the photos must agree that the fitted roll fits their shading better than
#: none (:func:`_fits_better`), or the roll is not fitted.
ROLL_EVIDENCE = 0.05

#: Photos (spread over the sequence: :func:`first_pass_photos`) whose estimates the tilt search
#: compares (:func:`_estimate_with_fitted_tilt`); every photo is then fitted once, in the frame
#: found. A capture of at most this many photos is searched on all of them (the search's fit in
#: the frame found is the result). (A grid on 6 of 12 photos bracketed another tilt than all 12 on
#: a rolled capture: 33.4 against 30.0 deg.)
TILT_SEARCH_PHOTOS = 24


#: Resamples of the two-way bootstrap that measures a fitted tilt's 95% error (:func:`tilt_uncertainty`).
TILT_BOOTSTRAP = 200

#: ``Lights.frame['source']`` of lights in the frame of a fitted camera tilt (:func:`estimate_lights`).
FITTED_FRAME_SOURCE = "the camera's tilt fitted to the spheres' shading"


def tilted_world_from_camera(tilt_deg: float, roll_deg: float = 0.0) -> np.ndarray:
    """The ``world_from_camera`` of a camera at the origin looking ``tilt_deg`` degrees below the
    horizon, turned ``roll_deg`` about its optical axis (positive dips the image's right: the
    camera's x axis turns toward its y, down; ``ffls synth --camera-roll``); 0, 0 is
    :data:`ffls.conventions.DEFAULT_WORLD_FROM_CAMERA` (image right +X, image up +Z, forward +Y).

    Returns
    -------
    (4, 4) float64
    """
    t, r = np.radians(float(tilt_deg)), np.radians(float(roll_deg))
    M = np.eye(4)
    roll = np.array([[np.cos(r), -np.sin(r), 0.0], [np.sin(r), np.cos(r), 0.0], [0.0, 0.0, 1.0]])
    M[:3, :3] = np.array([[1.0, 0.0, 0.0], [0.0, -np.sin(t), np.cos(t)], [0.0, -np.cos(t), -np.sin(t)]]) @ roll
    return M


def matte_residuals(lights) -> dict:
    """``(photo, sphere) -> RMS`` shading residual (the ``rms`` of the sphere's record) of every matte
    sphere fitted in a photo with a light."""
    return {(i, k): float(r["rms"]) for i, e in enumerate(lights.extra or ()) if e.get("status", "ok") == "ok"
            for k, r in enumerate(e.get("spheres") or ())
            if r.get("kind") == "matte" and r.get("status") == "ok" and r.get("rms") is not None}


def _matte_misfit(lights) -> float:
    """Interquartile mean (:func:`scipy.stats.trim_mean`, a quarter cut from each end) over the photos
    with a light of their matte spheres' RMS shading residual (:func:`matte_residuals`): a few
    photos' misfits (a light behind the ball, a sphere near the frame's edge) would rule a mean, and
    a median of one ball's 12 photos wanders. NaN without any."""
    rms = list(matte_residuals(lights).values())
    return _interquartile_mean(rms) if rms else float("nan")


def _interquartile_mean(values) -> float:
    """Mean of ``values`` with a quarter cut from each end (the steps of :func:`scipy.stats.trim_mean`
    at 0.25, bit-identical to it, without its import and its per-call cost); NaN without any."""
    v = np.asarray(values, dtype=np.float64)
    n = v.size
    if n == 0:
        return float("nan")
    lo = int(0.25 * n)
    hi = n - lo
    return float(np.mean(np.partition(v, (lo, hi - 1))[lo:hi]))


def _fits_better(before, after, level: float) -> bool:
    """Whether the estimates ``after`` fit the matte spheres' shading better than ``before`` photo by
    photo: the one-sided Wilcoxon signed-rank test (:func:`scipy.stats.wilcoxon`) of the log ratios
    of each sphere's residual in each photo (:func:`matte_residuals`) rejects "no better" at
    ``level``. The misfit's curves are rough at the 1% level (a frame moves pixels across the
    terminator and the own shadow's edge), and a roll's gain is about as small: its least misfit
    alone would be a roll fitted to that roughness."""
    a, b = matte_residuals(before), matte_residuals(after)
    d = np.log([b[k] / a[k] for k in a if k in b and a[k] > 0 and b[k] > 0])
    d = d[d != 0]
    if len(d) < 6:
        return False
    from scipy.stats import wilcoxon

    return bool(wilcoxon(d, alternative="less").pvalue < level)


def fit_camera_tilt(fit, search=TILT_SEARCH_DEG, roll=ROLL_SEARCH_DEG,
                    evidence: float = ROLL_EVIDENCE) -> tuple[float, float, dict]:
    """The camera's tilt, and its roll, that the matte spheres' shading fits best, for a capture
    without ``world_from_camera``.

    The ground bounce lights a matte sphere's lower half around the ground's normal, and its own
    shadow darkens the ground under it: modelled around the wrong up (the image's, when the camera
    looks down, or leans), both leave a residual that leans the fitted light. ``fit(tilt_deg,
    roll_deg)`` estimates every light with the ground under a camera tilted and rolled that much
    (:func:`tilted_world_from_camera`) and returns the :class:`~ffls.io.capture.Lights`. The tilt
    minimising :func:`_matte_misfit` (the interquartile mean of the matte spheres' residuals) is
    found on a grid (reaching past ``search``'s ends, a step at a time, while the least misfit is at
    one: :data:`TILT_REACH_DEG`), then refined (:func:`scipy.optimize.minimize_scalar`, bounded); then, where
    the tilt found is at most ``roll``'s largest (:data:`ROLL_SEARCH_DEG`), the roll at that tilt,
    and where a roll fits better than none, the tilt at that roll within half a grid step (one
    bounded refinement each:
    the two turn the ground's normal, seen from the camera, at about right angles). The roll is
    kept only where the photos agree that it fits better than the tilt alone (:func:`_fits_better`
    at ``evidence``).

    Parameters
    ----------
    fit : callable
        ``fit(tilt_deg, roll_deg) -> Lights``.
    search : (lo, hi, step, tolerance) degrees
    roll : (bound, largest tilt, tolerance) degrees, optional
        None: no roll.
    evidence : float
        The roll's significance level (:data:`ROLL_EVIDENCE`).

    Returns
    -------
    tilt_deg : float
        NaN when no matte sphere fitted (the bounce then does not depend on the tilt).
    roll_deg : float
        NaN where not fitted (no tilt, a tilt past ``roll``'s largest, or a roll the photos do not
        agree fits better); 0 where no roll fits better at all.
    tried : dict
        ``(tilt, roll)`` (degrees) -> (misfit, Lights) of every ``fit`` made.
    """
    from scipy.optimize import minimize_scalar

    lo, hi, step, tol = search
    tried: dict = {}

    def misfit(t: float, r: float = 0.0) -> float:
        key = (float(t), float(r))
        if key not in tried:
            lights = fit(*key)
            tried[key] = (_matte_misfit(lights), lights)
        m = tried[key][0]
        return m if np.isfinite(m) else np.inf

    grid = list(np.arange(lo, hi + 0.5 * step, step))
    costs = [misfit(t) for t in grid]
    if not np.isfinite(min(costs)):
        return float("nan"), float("nan"), tried
    # a least misfit at the grid's end is searched past it (TILT_REACH_DEG), until one is inside
    while int(np.argmin(costs)) == len(grid) - 1 and grid[-1] + step <= TILT_REACH_DEG[1]:
        grid.append(grid[-1] + step)
        costs.append(misfit(grid[-1]))
    while int(np.argmin(costs)) == 0 and grid[0] - step >= TILT_REACH_DEG[0]:
        grid.insert(0, grid[0] - step)
        costs.insert(0, misfit(grid[0]))
    lo, hi = grid[0], grid[-1]
    k = int(np.argmin(costs))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    res = minimize_scalar(misfit, bounds=(a, b), method="bounded", options={"xatol": tol})
    best = min((t for t, r in tried if r == 0.0), key=misfit)
    tilt = float(res.x) if misfit(res.x) <= misfit(best) else best
    if roll is None or tilt > roll[1]:
        return tilt, float("nan"), tried
    # the roll at that tilt, then the tilt at that roll (within half a grid step): a roll also moves
    # the tilt that fits best (ffls synth --camera-roll 4, normal lens: 32.4 at no roll, 28.4 at the
    # roll found, true 30)
    minimize_scalar(lambda r: misfit(tilt, r), bounds=(-roll[0], roll[0]), method="bounded",
                    options={"xatol": roll[2]})
    r = min((r for t, r in tried if t == tilt), key=lambda r: misfit(tilt, r))  # (0 where none fits better)
    if r == 0.0:
        return tilt, r, tried
    minimize_scalar(lambda t: misfit(t, r), bounds=(max(tilt - 0.5 * step, lo), min(tilt + 0.5 * step, hi)),
                    method="bounded", options={"xatol": tol})
    rolled = min((t for t, q in tried if q == r), key=lambda t: misfit(t, r))
    # kept where the photos agree that it fits better than the tilt alone; else not measured
    if _fits_better(tried[(tilt, 0.0)][1], tried[(rolled, r)][1], evidence):
        return rolled, r, tried
    return tilt, float("nan"), tried


def _least_by_parabola(tilts: np.ndarray, misfits: np.ndarray) -> float:
    """Where the parabola through the least of ``misfits`` (at sorted ``tilts``) and its two
    neighbours is least, within them; the least tilt itself at an end or where it is not convex."""
    k = int(np.argmin(misfits))
    if k == 0 or k == len(tilts) - 1:
        return float(tilts[k])
    c = np.polyfit(tilts[k - 1:k + 2], misfits[k - 1:k + 2], 2)
    return float(np.clip(-c[1] / (2 * c[0]), tilts[k - 1], tilts[k + 1])) if c[0] > 0 else float(tilts[k])


def tilt_uncertainty(tried: dict, resamples: int = TILT_BOOTSTRAP, seed: int = 0) -> float:
    """The 95% error (degrees) of the tilt :func:`fit_camera_tilt` found, measured from its own fit.

    A two-way bootstrap over the photos and the matte spheres (each resampled with replacement, a
    sphere's residuals in a photo weighted by both counts): :func:`_matte_misfit` recomputed at every
    tilt tried without a roll (``tried``: :func:`fit_camera_tilt`'s), the tilt where each
    resample's misfit is least (:func:`_least_by_parabola`), and 1.96 times their standard
    deviation. The photos alone see the noise; a model's error (the bounce, an object's shadow)
    shows as the spheres' disagreement, which resampling them adds (docs/spheres.md, "The tilt's
    own error": 41 of 44 renders' tilts inside; over the photos alone 38). NaN without a matte
    sphere's residual.

    Parameters
    ----------
    tried : dict
        ``(tilt, roll) -> (misfit, Lights)`` (degrees).
    resamples : int
    seed : int
        The resampling's generator seed (the same fit gives the same error).
    """
    flat = sorted((t, lights) for (t, r), (_, lights) in tried.items() if r == 0.0)
    res = [matte_residuals(lights) for _, lights in flat]
    keys = sorted(set().union(*res))
    if len(flat) < 3 or not keys:
        return float("nan")
    tilts = np.array([t for t, _ in flat])
    table = np.array([[r.get(k, np.nan) for k in keys] for r in res])  # (tilts, photo-sphere pairs)
    photos, spheres = (np.unique([k[j] for k in keys], return_inverse=True)[1] for j in (0, 1))
    rng = np.random.default_rng(seed)
    found = []
    n_p, n_s = photos.max() + 1, spheres.max() + 1
    for _ in range(resamples):
        weight = (np.bincount(rng.integers(0, n_p, n_p), minlength=n_p)[photos]
                  * np.bincount(rng.integers(0, n_s, n_s), minlength=n_s)[spheres])
        drawn = table[:, np.repeat(np.arange(len(keys)), weight)]
        misfits = [_interquartile_mean(row[np.isfinite(row)]) if np.isfinite(row).any() else np.inf for row in drawn]
        found.append(_least_by_parabola(tilts, np.array(misfits)))
    return float(1.96 * np.std(found))


def estimate_lights(capture, spheres=None, progress: bool = True, workers: int | None = None,
                    model: str = "auto", bounce: str = "calibrated", refine_centres: bool = True,
                    refine_options: dict | None = None, decoded: DecodedPhotos | None = None,
                    flat_field: bool = True, first_pass: int | None = FIRST_PASS_PHOTOS, bounce_shape: bool | None = None,
                    fit_tilt: bool = True, fit_roll: bool = False, halves: bool = True, **kwargs):
    """Estimate every photograph's light from the capture's spheres.

    Two passes (module docstring): every photo is fitted with a free ground bounce; each sphere's
    ground ratio is calibrated on the photos that determine it (:func:`calibrate_bounce`); every
    photo is then fitted again with that ratio imposed (spheres without enough such photos keep
    the free bounce). The spheres' pixels are kept in memory between the passes (never the
    images).

    Parameters
    ----------
    capture : ffls.io.capture.Capture
    spheres : list of SphereFit, optional
        The spheres (``center_cam`` camera frame, ``radius``); found with
        :func:`ffls.spheres.detect.find_spheres_in_capture` when None.
    progress : bool
        tqdm progress bar.
    workers : int, optional
        Processes; default every core. 1 runs in this process.
    model : {'auto', 'distant', 'near'}
    bounce : {'calibrated', 'free', 'observed'}
        Two passes with the capture-wide ground ratio, or one pass with a free bounce per photo;
        ``'observed'``: calibrated, with each sphere's bounce from the ground photographed around
        it (:mod:`ffls.spheres.ground`, :func:`observed_ground_samples`; needs the camera's
        ``world_from_camera``: the ground is the plane under each sphere, and ``model``
        ``'distant'``; no ``bounce_shape``).
    refine_centres : bool
        After the first pass, refine the centre of each sphere whose outline is not at the linear
        step (:func:`centres_to_refine`) from the shading of up to 20 photos
        (:func:`refine_sphere_centres`) and repeat the first pass with the new centres.
    refine_options : dict, optional
        Passed to :func:`ffls.spheres.refine.refine_sphere_centre`.
    decoded : DecodedPhotos, optional
        The photos decoded once (:func:`decode_photos`, which the sphere detection also used):
        the first pass reads them from memory. Made here when ``spheres`` is None.
    flat_field : bool
        Fit the lens's fall-off (vignetting) over the photos and divide it out where significant
        (:func:`calibrate_flat_field`, :func:`lens_centre`).
    first_pass : int, optional
        With a calibrated bounce, the first pass fits this many photos, spread over the sequence
        (:func:`first_pass_photos`; the others are only read), and the centre refinement, the
        flat field and the bounce calibration use those; the second pass fits every photo.
        None: every photo.
    bounce_shape : bool, optional
        Give each matte sphere's calibrated bounce its horizontal gradient
        (:func:`calibrate_bounce_shape`); False: the uniform ground's shape; None (default): only
        with one matte sphere (as :func:`estimate_photos`).
    fit_tilt : bool
        Where the capture gives no ``world_from_camera`` and its lights cover the upper hemisphere
        (over a ground; ``model`` not ``'near'``), fit the camera's tilt (and with ``fit_roll`` its
        roll, where it shows), and so the ground's normal under the spheres, to the matte spheres' shading
        (:func:`fit_camera_tilt`; False: the image's up is the world's). The lights are then in
        the frame found (``Lights.frame``: +Z the ground's normal, +X the image's right turned by
        the roll, +Y the camera's forward over the ground), not the capture's default frame.
    fit_roll : bool
        With the tilt, fit the camera's roll about its axis (:data:`ROLL_SEARCH_DEG`); off by
        default: an object beside a sphere can pass for a roll (docs/spheres.md).
    halves : bool
        A lone matte sphere's cones from its halves' disagreement (:func:`calibrate_uncertainty`);
        False: the stated fallback's (as under a fitted tilt, whose error turns every photo alike).
    **kwargs
        Passed to :func:`ffls.spheres.photo.estimate_photo` (``min_spheres``,
        ``sigma_floor_deg``, ``terminator``, ``saturation``, ``own_shadow``: by default on, and
        off where ``capture.world_from_camera_is_default``, as the ground's normal is then unknown).

    Returns
    -------
    ffls.io.capture.Lights
        Directions (world, from the scene centre), positions for near lights, status, reasons
        (:data:`ffls.spheres.photo.REASONS`), and per light ``extra``: ``uncertainty_deg`` (the
        radius of the 95% cone, calibrated over the capture: :func:`calibrate_uncertainty`),
        ``model``, ``used_spheres``, ``spheres`` (per-sphere ``kind``, ``kind_source`` and
        ``compactness``, ``flat_field``: the gradient divided out or None, direction, residual
        or highlight, uncertainty,
        pixel counts, ground ratio estimate and the imposed ``bounce_ratio``; with
        ``refine_centres`` also the sphere's world ``center``, ``center_shift_px`` and
        ``center_refined``).
    """
    _check_modes(model, bounce)
    model, refine_options = check_estimable(capture, model, refine_options)
    if bounce == "observed" and model != "distant":
        raise InputError("bounce 'observed' needs model 'distant' (the near light's joint fit keeps the uniform "
                         "ground)", capture.json_path)
    workers = (os.cpu_count() or 1) if workers is None else max(1, int(workers))
    if spheres is None:
        from ffls.spheres.detect import find_spheres_in_capture

        if decoded is None:
            decoded = decode_photos(capture, workers)
            if decoded.stored:  # integer photos and no encoding stated: its one-line refusal, before any work
                read_photo(capture, 0)
        spheres = find_spheres_in_capture(capture, stats=decoded.stats, bit_depths=decoded.bit_depths,
                                          workers=workers)
    stages = dict(model=model, bounce=bounce, refine_centres=refine_centres, refine_options=refine_options,
                  decoded=decoded, flat_field=flat_field, first_pass=first_pass, bounce_shape=bounce_shape)
    # lights over the upper hemisphere stand above a ground, whose normal the tilt gives; lights all
    # round ("full") or around a stated axis have no ground under the spheres to orient
    # (a declared mirror is never matte: with only those the tilt's misfit would be NaN everywhere)
    if (fit_tilt and model != "near" and bounce != "observed"
            and getattr(capture, "world_from_camera_is_default", False)
            and getattr(capture.hemisphere, "name", "upper") == "upper"
            and any(m != "mirror" for m in sphere_materials(capture, len(spheres)))):
        lights = _estimate_with_fitted_tilt(capture, spheres, progress, workers, stages=stages,
                                            photo_options=kwargs, fit_roll=fit_roll)
    else:
        lights = _estimate_in_frame(capture, spheres, progress, workers, halves=halves, **stages, **kwargs)
    if getattr(capture, "camera_model", "pinhole") == "orthographic":  # (a pinhole's outlines are its lens's)
        lights = widen_for_lens(lights, lens_check(capture, spheres, photo_shape(capture, decoded)))
    return lights


def lens_check(capture, spheres, shape):
    """:func:`ffls.spheres.perspective.perspective_outlines` of a capture declared orthographic
    (None for a pinhole camera: its outlines are fitted as its lens projects them)."""
    if getattr(capture, "camera_model", "pinhole") != "orthographic":
        return None
    from ffls.spheres.perspective import perspective_outlines

    return perspective_outlines(spheres, shape)


def widen_for_lens(lights, evidence):
    """The lights with each accepted light's cone widened by its used spheres' largest angle off the
    lens axis (``evidence``: :func:`lens_check`, where it detected a normal lens behind an
    orthographic camera; the lights unchanged otherwise): the orthographic model turns a sphere's
    directions by about that angle (:mod:`ffls.spheres.perspective`). Each widened light's
    ``extra`` records it as ``orthographic_misfit_deg``."""
    if evidence is None or not evidence.detected or not lights.extra:
        return lights
    for st, e in zip(lights.status, lights.extra):
        used = [i for i in e.get("used_spheres") or () if 0 <= i < len(evidence.angles_deg)]
        if st != "ok" or not used or e.get("uncertainty_deg") is None:
            continue
        widen = max(evidence.angles_deg[i] for i in used)
        e["uncertainty_deg"] = float(np.hypot(e["uncertainty_deg"], widen))
        e["orthographic_misfit_deg"] = round(float(widen), 3)
        cap_cones(e)
    return lights


def photo_shape(capture, decoded: DecodedPhotos | None) -> tuple[int, int]:
    """The photos' ``(height, width)``: capture.json's, the decoded photos', or the first photo's."""
    if capture.image_size is not None:
        return int(capture.image_size[1]), int(capture.image_size[0])
    if decoded is not None:
        return decoded.shape
    return load_photo(capture, 0).shape[:2]


def _fit_options(capture, model: str, kwargs: dict) -> dict:
    """The photo fits' options (:func:`ffls.spheres.photo.estimate_photo`'s keywords) in the capture's frame."""
    # the own shadow needs the ground's normal: without a world frame, up is only the image's
    return {"model": model, "own_shadow": not getattr(capture, "world_from_camera_is_default", False), **kwargs}


def _estimate_in_frame(capture, spheres, progress, workers, *, model, bounce, refine_centres, refine_options,
                       decoded, flat_field, first_pass, bounce_shape, fitter: PhotoFitter | None = None,
                       values: list | None = None, photos: list | None = None, halves: bool = True, **kwargs):
    """:func:`estimate_lights` in the capture's world frame as given (no tilt search).

    ``fitter`` (a :class:`PhotoFitter` with :func:`_fit_options`, shared by the calls of a tilt
    search: one pool of processes), ``values`` (every photo's sphere values, read once for all the
    frames: the pixels are the same in each) and ``photos`` (fit only these photos, by index; the
    lights are theirs) serve the tilt search (:func:`_estimate_with_fitted_tilt`)."""
    if model == "near" and len(spheres) < 2:
        raise InputError("model 'near' needs at least 2 spheres to triangulate the light", capture.json_path)
    shape = photo_shape(capture, decoded)
    samples = capture_samples(capture, spheres, shape)
    if bounce == "observed":
        samples = observed_ground_samples(capture, samples, shape)
        bounce, bounce_shape = "calibrated", False
    materials = sphere_materials(capture, len(spheres))
    views = sphere_views(capture, spheres)
    names = list(capture.image_names)
    if photos is not None:
        names = [names[i] for i in photos]
        values = None if values is None else [values[i] for i in photos]
    levels = None if decoded is None else decoded.photo_levels(capture)
    if levels is not None and photos is not None:
        levels = levels[photos]
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(names) * (2 if bounce == "calibrated" else 1), desc="lights", unit="img")
    try:
        with (PhotoFitter(capture, capture.scene_center, _fit_options(capture, model, kwargs), workers, bar,
                          decoded) if fitter is None else nullcontext(fitter)) as fit:
            est = two_pass(fit, samples, values, len(names), bounce=bounce,
                            refine_centres=centres_to_refine(spheres) if refine_centres else False,
                            refine_options=refine_options, materials=materials, views=views,
                            where=capture.json_path, limb_image=None if decoded is None else decoded.stats.mean,
                            flat_field=lens_centre(capture, shape) if flat_field else None,
                            first_pass=first_pass, bounce_shape=bounce_shape, halves=halves, levels=levels)
    finally:
        if bar is not None:
            bar.close()
    return est.lights(names)


def widen_for_tilt(lights) -> None:
    """Widen, in place, the cones of ``lights`` in a fitted tilt's frame (``lights.frame``) by the
    tilt's error (``frame['tilt_uncertainty_deg']``): an error ``e`` turns every light about the
    frame's +X (the axis of the tilt), a direction ``d`` by ``e sqrt(1 - d_x^2)``, added in
    quadrature to its cone and recorded per light as ``tilt_widened_deg``. The cones measured from
    the spheres' disagreement do not see it (it turns every photo alike), nor the stated fallback's
    (a lone sphere), set for a typical capture, not this one's tilt: both take it (a lone ball 89
    deg down found at 93.6, 4.6 off, had 14% of its lights in the fallback's cones; docs/spheres.md,
    "The tilt's own error")."""
    if lights.frame is None or lights.frame.get("tilt_uncertainty_deg") is None:
        return
    e = float(lights.frame["tilt_uncertainty_deg"])
    if not np.isfinite(e):  # (NaN is truthy: every cone would turn NaN; estimate_lights never records one)
        raise ValueError(f"a fitted tilt's error must be a finite angle, got {e!r}")
    if not e:
        return
    for d, st, x in zip(lights.directions, lights.status, lights.extra or ()):
        if st != "ok" or x.get("uncertainty_deg") is None:
            continue
        w = e * float(np.sqrt(max(0.0, 1.0 - d[0] * d[0])))
        x["uncertainty_deg"] = float(np.hypot(x["uncertainty_deg"], w))
        x["tilt_widened_deg"] = round(w, 3)
        cap_cones(x)


def _estimate_with_fitted_tilt(capture, spheres, progress, workers, stages: dict, photo_options: dict,
                               fit_roll: bool = False):
    """:func:`estimate_lights` of a capture without ``world_from_camera``, the ground's normal (the
    camera's tilt, and with ``fit_roll`` its roll where it shows) fitted to the matte spheres' shading
    (:func:`fit_camera_tilt`); the lights are returned in the frame found
    (:func:`tilted_world_from_camera`, recorded as ``Lights.frame``; the cones widened by the tilt's
    error, :func:`widen_for_tilt`), each light's ``extra`` with ``camera_tilt_deg`` and
    ``camera_roll_deg`` (absent when not fitted: without a matte sphere's fit, or where the tilt's
    error cannot be measured (:func:`tilt_uncertainty`), the image's up is the world's, as before).

    The search reads every photo's sphere values once and runs every frame's estimate in one
    :class:`PhotoFitter` (one pool of processes), on a sample of the photos
    (:data:`TILT_SEARCH_PHOTOS`; ``stages``: the estimation's keywords, ``photo_options``:
    :func:`ffls.spheres.photo.estimate_photo`'s)."""

    def posed(tilt_deg: float, roll_deg: float = 0.0):
        return replace(capture, world_from_camera=tilted_world_from_camera(tilt_deg, roll_deg),
                       world_from_camera_is_default=False)

    n, decoded, level = len(capture.image_names), stages["decoded"], posed(0.0)
    with PhotoFitter(level, capture.scene_center, _fit_options(level, stages["model"], photo_options), workers,
                     None, decoded) as fitter:
        # every photo's sphere values, read once: a frame turns the spheres' normals, not their pixels
        samples = capture_samples(level, spheres, photo_shape(capture, decoded))
        values = [v for _, v in fitter.run([PhotoTask(i, fit=False) for i in range(n)], samples, counted=False)]

        def fit(tilt_deg: float, roll_deg: float = 0.0, photos=None):
            # (a lone sphere's halves are off: the tilt's error turns every photo alike, which they do
            # not measure; its fallback cones take the tilt's measured error, widen_for_tilt)
            return _estimate_in_frame(posed(tilt_deg, roll_deg), spheres, False, workers, fitter=fitter,
                                      values=values, photos=photos, halves=False, **stages, **photo_options)

        sample = first_pass_photos(n, TILT_SEARCH_PHOTOS)
        tilt, roll, tried = fit_camera_tilt(lambda t, r: fit(t, r, None if len(sample) == n else sample),
                                            roll=ROLL_SEARCH_DEG if fit_roll else None)
        rolled = float(roll) if np.isfinite(roll) else 0.0
        if np.isfinite(tilt):
            found = tried[(tilt, rolled)][1] if len(sample) == n else fit(tilt, rolled)
    # a tilt whose error cannot be measured (tilt_uncertainty: NaN) would give the lights cones that do
    # not hold it: it is not fitted, as without a matte sphere (the image's up is the world's, which
    # the lights command's note says). (fit_camera_tilt finds a tilt only where a matte sphere's
    # residual is finite, over its grid of 10 tilts: not reached by a capture; kept in case either
    # changes.)
    error = tilt_uncertainty(tried) if np.isfinite(tilt) else float("nan")
    if not np.isfinite(error):
        return _estimate_in_frame(capture, spheres, progress, workers, values=values, **stages, **photo_options)
    # the lights stay in the frame found (+Z the ground's normal: the scene's up, as a pose would give
    # it; GUIDE section 1), recorded as Lights.frame: in the image's frame a camera looking down put
    # the lights over the ground half below the upper hemisphere (docs/spheres.md)
    lights = replace(found, frame={"world_from_camera": tilted_world_from_camera(tilt, rolled),
                                   "source": FITTED_FRAME_SOURCE,
                                   "tilt_uncertainty_deg": round(error, 3)})
    widen_for_tilt(lights)
    for e in lights.extra or ():
        e["camera_tilt_deg"] = round(tilt, 2)
        if np.isfinite(roll):
            e["camera_roll_deg"] = round(rolled, 2)
    return lights


#: The paper's method under its name (GUIDE: one paper per function).
estimate_lights_MasselusDutreAnrys2002 = estimate_lights
