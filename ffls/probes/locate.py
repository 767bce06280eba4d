"""Where the probe sphere is in one view: from ``probe.json``, a pixel hint, or found (issue 7's finder).

:func:`locate_sphere` turns a view's :class:`ffls.io.probe.ProbeSphere` into the geometry the
methods use: the centre in the camera frame and the radius (pinhole), or the disc in pixels
(orthographic). A world centre is used as given (no detection); a pixel hint and the automatic
case run :func:`ffls.spheres.detect.find_spheres` on the view's radiance (one sphere).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from ffls.errors import InputError
from ffls.spheres.detect import (HINT_CENTRE_OFFSET, DetectionCamera, circle_candidates, disc_mask,
                                 find_spheres, fit_circle, fit_outline, orthographic_normals,
                                 outline_visible_fraction, sector_jackknife_centres, silhouette_px,
                                 sphere_mask, sphere_normals, stated_circle_problem)
from ffls.spheres.select import CRITERIA, round_outline

__all__ = ["SphereGeometry", "locate_sphere", "mirror_limb", "diffuse_ball", "LIMB_STEP_COVERAGE",
           "MIN_BALL_FRACTION", "MAX_INTERIOR_EDGES", "RIVAL_RATIO", "LIMB_CIRCLES",
           "MIRROR_SHARP_OUTLINE_PX", "OUTLINE_TOL_PX", "ENCLOSING_OFFSET", "LIMB_GROWTH", "unhinted_mirror_limb",
           "LIMB_CONE_MOVE_PX", "limb_cone",
           "LIMB_JACKKNIFE_SECTORS", "MIRROR_CENTRE_TOL_PX", "limb_centre_uncertainty",
           "ENCLOSED_LIMB_COVERAGE", "enclosing_steps"]


@dataclass
class SphereGeometry:
    """The probe sphere in one view.

    Attributes
    ----------
    camera_model : {'pinhole', 'orthographic'}
    K, dist : camera (pinhole; None for orthographic)
    world_from_camera : (4, 4) float64
    center_cam : (3,) float64 or None
        Centre, camera frame (pinhole), in the units of ``radius``.
    radius : float or None
        Radius (pinhole): the stated one, or 1 when the ball was located by pixels and no radius
        was given (a mirror's reflection depends only on ``|C| / R``).
    center_px : (2,) float64
        The centre's image.
    radius_px : float
        Apparent radius, pixels.
    source : str
        ``'probe.json'`` (world centre, or a stated pixel circle), ``'hint'`` or ``'auto'`` (found).
    radius_known : bool
        ``radius`` is the stated one (scene units), not the stand-in 1.
    center_uncertainty_px : float or None
        A mirror ball's limb (found or hinted): the radius (pixels) of the 95% region of its centre
        (:func:`limb_centre_uncertainty`); None where not measured (a stated sphere, a finder's fit).
    enclosed_by : ((2,) float, float, float) or None
        A mirror ball's limb (found or hinted) well inside a larger circle of brightness steps
        (:func:`enclosing_steps`): that circle's centre (px), radius (px) and the share of it its steps
        cover; the limb may be a reflection inside the ball. None where none was found or not looked for.
    """

    camera_model: str
    K: np.ndarray | None
    dist: np.ndarray | None
    world_from_camera: np.ndarray
    center_cam: np.ndarray | None
    radius: float | None
    center_px: np.ndarray
    radius_px: float
    source: str
    radius_known: bool = False
    center_uncertainty_px: float | None = None
    enclosed_by: tuple | None = None

    @property
    def flagged(self) -> bool:
        """The description says UNCERTAIN: the centre's 95% radius over :data:`MIRROR_CENTRE_TOL_PX`, or a circle
        of steps encloses the limb (``enclosed_by``)."""
        u = self.center_uncertainty_px
        return (u is not None and u > MIRROR_CENTRE_TOL_PX) or self.enclosed_by is not None

    def mask(self, shape, margin_px: float = 0.0) -> np.ndarray:
        """(H, W) bool: the pixels that see the sphere (``margin_px`` inside its outline)."""
        if self.camera_model == "orthographic":
            return disc_mask(shape, self.center_px, self.radius_px, margin_px)
        return sphere_mask(shape, self.K, self.dist, self.center_cam, self.radius, margin_px)

    def normals_world(self, pixels) -> np.ndarray:
        """(n, 3) world-frame unit normals at ``pixels`` (n, 2); NaN off the sphere."""
        n = orthographic_normals(pixels, self.center_px, self.radius_px) if self.camera_model == "orthographic" \
            else sphere_normals(pixels, self.K, self.dist, self.center_cam, self.radius)
        return n @ np.asarray(self.world_from_camera, dtype=np.float64)[:3, :3].T

    def describe(self) -> str:
        """One line."""
        where = "as given in probe.json" if self.source == "probe.json" else \
            ("found near the pixel hint" if self.source == "hint" else "found automatically")
        line = f"sphere {where}: centre ({self.center_px[0]:.1f}, {self.center_px[1]:.1f}) px, radius " \
               f"{self.radius_px:.1f} px"
        u = self.center_uncertainty_px
        if u is not None:
            # a centre off by u moves the normals near the ball's centre by u / radius_px radians, the
            # reflected directions by twice that (more toward the rim)
            line += f", centre within {u:.2f} px (95%; directions near the ball's centre within " \
                    f"{np.degrees(2 * u / self.radius_px):.1f} deg)"
        why = []
        if u is not None and u > MIRROR_CENTRE_TOL_PX:
            why.append(f"over {MIRROR_CENTRE_TOL_PX:g} px, the limb's steps disagree around the ball (a reflected "
                       "edge beside the limb?)")
        if self.enclosed_by is not None:
            (ex, ey), er, cov = self.enclosed_by
            why.append(f"a larger circle of brightness steps encloses it (({ex:.1f}, {ey:.1f}) px, radius {er:.1f} "
                       f"px, its steps cover {cov:.0%} of it): this one may be a reflection inside the ball")
        if why:
            line += f"; UNCERTAIN: {'; '.join(why)}: measure the ball's outline and give \"center_px\" with " \
                    "\"radius_px\" in probe.json"
        return line


def _given_circle(cam, T, sph, source) -> SphereGeometry:
    """A disc stated in pixels (``center_px`` and ``radius_px``): the ball's outline as measured in the photo.

    Orthographic: the disc itself. Pinhole: a sphere off the lens axis outlines an ellipse, and the circle
    that best fits it (what a measured outline is) is not centred on the image of the sphere's centre (0.5 px
    from it and 0.8 px larger than the cone's cross-section, for a 33 px ball 10 degrees off the axis at
    f = 400 px), so the cone through the circle (:func:`_circle_geometry`) put the ball's centre 0.5 px off.
    The sphere is instead the one whose exact outline best fits 360 points of the circle (the tangent cone of
    :func:`ffls.spheres.detect.fit_outline`, as :func:`limb_cone` fits a limb's steps): 0.004 px from the
    true centre there. (Far off the axis of a wide lens a circle only approximates the outline: for a 60 px
    circle in the corner of a 320 x 240 photo at f = 400 px the best outline is 1.5 px RMS from it, the
    least-squares sphere all the same.) Refused (InputError, one line) where the fit fails.
    """
    c, r = np.asarray(sph.center_px, dtype=np.float64), float(sph.radius_px)
    if cam.model == "orthographic":
        return _circle_geometry(cam, T, c, r, sph.radius, "probe.json")
    R = float(sph.radius) if sph.radius is not None else 1.0
    t = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    dc = DetectionCamera("pinhole", np.asarray(cam.K, dtype=np.float64), cam.dist, np.eye(4), R, (1, 1))
    try:
        ft = fit_outline(c + r * np.stack([np.cos(t), np.sin(t)], axis=1), dc, c, r, source)
    except ValueError:
        ft = None
    if ft is None or not np.all(np.isfinite(ft.center_cam)):
        raise InputError(f"sphere.center_px and radius_px: no sphere seen through camera.K has the circle "
                         f"({c[0]:.1f}, {c[1]:.1f}) px, radius {r:.1f} px as its outline: check the circle and "
                         "camera.K", source)
    return SphereGeometry(cam.model, cam.K, cam.dist, T, np.asarray(ft.center_cam, dtype=np.float64), R,
                          np.asarray(ft.center_px, dtype=np.float64), float(ft.radius_px), "probe.json",
                          sph.radius is not None)


def _circle_geometry(cam, T, cpx, rpx, radius, source) -> SphereGeometry:
    """The sphere whose outline is the pixel circle (``cpx``, ``rpx``).

    Pinhole: the cone of viewing rays through the circle (axis through ``cpx``, half-angle the
    mean angle to 72 points of the circle, with the distortion undone) gives the centre at
    ``C = R / sin(alpha) * axis`` (``R`` the stated ``radius``, or 1).
    """
    if cam.model == "orthographic":
        return SphereGeometry(cam.model, None, None, T, None, None, cpx, rpx, source)
    from ffls.camera.projection import pixel_rays

    axis = pixel_rays(cpx[None], cam.K, cam.dist)[0]
    t = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    ring = np.asarray(cpx, dtype=np.float64) + rpx * np.stack([np.cos(t), np.sin(t)], axis=1)
    alpha = float(np.mean(np.arccos(np.clip(pixel_rays(ring, cam.K, cam.dist) @ axis, -1.0, 1.0))))
    R = float(radius) if radius is not None else 1.0
    return SphereGeometry(cam.model, cam.K, cam.dist, T, R / np.sin(alpha) * axis, R, cpx, rpx, source,
                          radius is not None)


#: A found mirror ball is moved to the circle of its limb's reflectance steps
#: (:func:`ffls.spheres.mirror_outline.mirror_silhouette`) when the steps cover this share of it.
LIMB_STEP_COVERAGE = 0.85


#: Circles of limb steps compared by :func:`mirror_limb`: the best-supported ones, of which the largest
#: that covers :data:`LIMB_STEP_COVERAGE` is the limb.
LIMB_CIRCLES = 6
#: An unhinted mirror ball whose limb's steps do not confirm its outline (:func:`mirror_limb` None) is
#: used only when that outline is a single sharp contour: its fit's RMS at most this (pixels).
MIRROR_SHARP_OUTLINE_PX = 0.5


def mirror_limb(radiance, center_px, radius_px, shape):
    """The circle (centre (2,), radius) of a mirror ball's limb near a found outline, or None.

    A mirror ball in a probe photo shows the scene around it, so the strongest edges the finder
    follows are often reflected ones just inside the limb (in ``benchmarks/probe_detect.py``, 2
    to 3 px off on 5 of 12 renders). At the limb the ball shows what lies just behind it, dimmed by
    its reflectance: the radial brightness steps (:func:`ffls.spheres.mirror_outline.radial_steps`,
    radii 0.75 to 1.25 of the found one, log luminance) are searched for their best-supported
    circles (:data:`LIMB_CIRCLES`, :func:`ffls.spheres.mirror_outline.mirror_silhouette`); of those whose
    steps cover at least :data:`LIMB_STEP_COVERAGE` of them and that stay within 15% of the found
    circle (centre and radius) the largest is taken: a circle of steps inside a mirror ball is a
    reflection, and the limb encloses it (the best-supported circle alone was a reflected one in 3
    renders there, 1.7-2.3 px off).
    """
    return _limb_near(_log_luminance(radiance), center_px, radius_px, shape)


def _log_luminance(radiance):
    """The natural log of a photo's luminance (float64, floored at 1e-12), as the limb's steps are found on."""
    lum = np.asarray(radiance, dtype=np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    return np.log(np.maximum(lum, 1e-12))


def _limb_near(log_lum, center_px, radius_px, shape):
    """:func:`mirror_limb` on the photo's log luminance (:func:`_log_luminance`), computed once by a caller
    that tries many starts (:func:`unhinted_mirror_limb`)."""
    from ffls.spheres.mirror_outline import mirror_silhouette

    c0 = np.asarray(center_px, dtype=np.float64)
    found = mirror_silhouette(log_lum, c0, radius_px, shape=shape,
                              min_coverage=LIMB_STEP_COVERAGE, max_growth=1.25, tol=1.0, min_shrink=0.75,
                              n_best=LIMB_CIRCLES)
    good = [(float(r), np.asarray(c, dtype=np.float64)) for _, c, r in found
            if np.hypot(*(c - c0)) <= 0.15 * radius_px and abs(r / radius_px - 1) <= 0.15]
    if not good:
        return None
    r, c = max(good, key=lambda g: g[0])
    return c, r


#: :func:`unhinted_mirror_limb` grows a circle of limb steps to the largest one enclosing it with its centre
#: within this share of its radius and a radius up to this share larger (a 1 px search grid).
LIMB_GROWTH = 0.2


def _grown_limb(log_lum, center_px, radius_px, shape, max_steps: int = 8):
    """The largest circle of radial steps enclosing (``center_px``, ``radius_px``), grown until none does.

    :func:`mirror_limb`'s search spans half the radius on a 2-2.5 px grid, where a weak limb's votes
    lose to the reflected circles just inside it. Here the steps
    (:func:`ffls.spheres.mirror_outline.mirror_silhouette`, 0.9 to ``1 + 2 LIMB_GROWTH`` radii) are searched
    (a grid of 1 px) only for circles larger than the current one, centre within :data:`LIMB_GROWTH` of its
    radius, radius up to that share larger; of those that enclose it (to 1 px) and whose steps cover
    :data:`LIMB_STEP_COVERAGE` of them the largest is taken, and the search repeated from it.
    """
    from ffls.spheres.mirror_outline import mirror_silhouette

    c, r = np.asarray(center_px, dtype=np.float64), float(radius_px)
    for _ in range(max_steps):
        found = mirror_silhouette(log_lum, c, r, shape=shape, min_coverage=LIMB_STEP_COVERAGE,
                                  max_growth=1 + 2 * LIMB_GROWTH, tol=1.0, n_best=LIMB_CIRCLES,
                                  max_offset=LIMB_GROWTH * r, r_min=r + 0.5, r_max=(1 + LIMB_GROWTH) * r)
        good = [(float(rr), cc) for _, cc, rr in _enclosing(found, c, r)]
        if not good:
            break
        r, c = max(good, key=lambda g: g[0])
    return c, r


def unhinted_mirror_limb(radiance, image, outline, source, near=None, log_lum=None):
    """The limb of a mirror ball found without a hint: (centre (2,), radius), or None when no start confirms one.

    The calibration finder's outline of a mirror probe can be a reflected circle well inside the ball
    (``benchmarks/probe_detect.py``, night at f = 1600 px: 7.65 px off, radius 9.15 px short), from where
    :func:`mirror_limb`'s window (15 % of the outline) does not reach the limb. As :func:`diffuse_ball` does
    for diffuse balls, every candidate circle of the photo (:func:`ffls.spheres.detect.circle_candidates`,
    radius at least :data:`MIN_BALL_FRACTION` of the shorter side) is a start besides ``outline``; each start's
    :func:`mirror_limb` is grown to the largest enclosing circle of steps (:func:`_grown_limb`), and of the
    limbs found with at least 60% of their circle in the frame (as :func:`diffuse_ball` asks of an outline)
    the largest is taken: a circle of steps inside a mirror ball is a reflection. (From a start on the
    photo's top edge, a courtyard's round structure half outside the frame, radius 66 px, centre 134 px
    from a 33 px ball, was the largest: ``probe_detect.py --azimuth 45``.)

    ``near`` (2,), a centre-only pixel hint: ``outline`` may be None (the finder refused the hint), the starts
    and the limbs are only circles whose centre lies within :data:`ffls.spheres.detect.HINT_CENTRE_OFFSET` of
    their radius of it, of any size, and the largest is taken without the rival test (the hint says which).

    ``log_lum`` (H, W), optional: ``radiance``'s log luminance (:func:`_log_luminance`), when the caller has it.

    Raises
    ------
    InputError
        Two separate limbs (not overlapping), the smaller at least :data:`RIVAL_RATIO` of the larger.
    """
    log_lum = _log_luminance(radiance) if log_lum is None else log_lum
    shape = log_lum.shape
    cands, _ = circle_candidates(image, source)
    hint = None if near is None else np.asarray(near, dtype=np.float64)

    def by_hint(c, r):
        return hint is None or np.hypot(*(np.asarray(c) - hint)) <= HINT_CENTRE_OFFSET * r

    min_r = 0.0 if hint is not None else MIN_BALL_FRACTION * min(shape)
    starts = [] if outline is None else [(np.asarray(outline.center_px, dtype=np.float64), float(outline.radius_px))]
    for x, y, r in cands:
        if r >= min_r and by_hint((x, y), r) and not any(np.hypot(x - a[0], y - a[1]) < 0.5 and abs(r - b) < 0.5
                                                         for a, b in starts):
            starts.append((np.array([x, y], dtype=np.float64), float(r)))
    limbs = []
    t = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    for c0, r0 in starts:
        limb = _limb_near(log_lum, c0, r0, shape)
        if limb is None:
            continue
        c, r = _grown_limb(log_lum, limb[0], limb[1], shape)
        if outline_visible_fraction(c + r * np.stack([np.cos(t), np.sin(t)], axis=1), shape) >= 0.6 and by_hint(c, r):
            limbs.append((c, r))
    if not limbs:
        return None
    limbs.sort(key=lambda g: -g[1])
    c, r = limbs[0]
    for o, ro in ([] if hint is not None else limbs[1:]):
        if np.hypot(*(o - c)) >= r + ro and ro >= RIVAL_RATIO * r:
            raise InputError(f"two mirror ball limbs could be the probe: ({c[0]:.0f}, {c[1]:.0f}) px, radius "
                             f"{r:.0f} px and ({o[0]:.0f}, {o[1]:.0f}) px, radius {ro:.0f} px; give a hint in "
                             "probe.json, e.g. \"sphere\": {\"center_px\": [u, v], \"radius_px\": r}", source)
    return c, r


#: :func:`limb_cone` keeps the tangent cone fitted to a limb circle's steps only when the circle that best fits
#: the cone's outline lies within this many pixels of the limb circle (its centre's move plus its radius's
#: change): the same steps, seen through the exact perspective outline rather than a circle, move it by the
#: perspective's share alone (0.05-0.95 px in ``benchmarks/probe_detect.py``), where a larger move means
#: the robust cone fit followed other steps (2.9 px once there).
LIMB_CONE_MOVE_PX = 1.0


def limb_cone(radiance, center_px, radius_px, K, dist, radius, shape, source):
    """The pinhole sphere whose exact outline fits a mirror ball's limb circle's steps, or None.

    A sphere seen off the lens axis outlines an ellipse, not a circle, whose centre is not the image of
    the sphere's centre: a limb circle (:func:`mirror_limb`, :func:`unhinted_mirror_limb`) taken as the
    tangent cone's cross-section puts the ball's centre off by the perspective alone (0.5 px for a 33 px
    ball 10 degrees off the axis at f = 400 px). The radial steps
    (:func:`ffls.spheres.mirror_outline.radial_steps`, 0.9 to 1.1 radii, log luminance) within 1 px of the
    circle are fitted by the sphere's tangent cone (:func:`ffls.spheres.detect.fit_outline`, robust); the fit
    is kept when the circle that best fits its outline stays within :data:`LIMB_CONE_MOVE_PX` of the limb
    circle.

    Parameters
    ----------
    radiance : (H, W, 3) float
    center_px : (2,) float
    radius_px : float
        The limb circle, pixels.
    K, dist
        The pinhole camera.
    radius : float
        The sphere's radius in the units of the centre returned (1 when unknown).
    shape : (H, W)
    source : path-like
        Named by the fit.

    Returns
    -------
    ffls.spheres.detect.SphereFit or None
    """
    return _limb_cone(_log_luminance(radiance), center_px, radius_px, SimpleNamespace(K=K, dist=dist), radius,
                      source, shape, uncertainty=False)[0]


def _limb_cone(log_lum, center_px, radius_px, cam, radius, source, shape=None, uncertainty=True):
    """:func:`limb_cone` on the photo's log luminance (:func:`_log_luminance`), computed once by
    :func:`locate_sphere`; ``cam`` has the pinhole's ``K`` and ``dist``; ``shape`` defaults to
    ``log_lum``'s. Returns ``(fit or None, u)``: ``u`` the 95% radius of the centre
    (:func:`limb_centre_uncertainty`) of the fit kept, or of the limb circle where the fit is not kept (at
    least the two's disagreement, the circle's move); None without a fit, or without ``uncertainty`` (its
    refits skipped)."""
    from ffls.spheres.mirror_outline import radial_steps

    K, dist = cam.K, cam.dist
    shape = log_lum.shape if shape is None else shape
    c = np.asarray(center_px, dtype=np.float64)
    r = float(radius_px)
    pts = radial_steps(log_lum, c, r, r_range=(0.9, 1.1))
    on = np.abs(np.hypot(*(pts - c).T) - r) <= 1.0
    if np.count_nonzero(on) < 8:
        return None, None
    cam = DetectionCamera("pinhole", np.asarray(K, dtype=np.float64), dist, np.eye(4), float(radius), tuple(shape))
    try:
        ft = fit_outline(pts[on], cam, c, r, source, n_edge=len(pts))
        oc, orad, _, _ = fit_circle(silhouette_px(cam.K, dist, ft.center_cam, float(radius)), c, r)
    except ValueError:
        return None, None
    u = limb_centre_uncertainty(pts[on], cam, ft, source) if uncertainty else None
    move = float(np.hypot(*(oc - c)) + abs(orad - r))
    if move <= LIMB_CONE_MOVE_PX:
        return ft, u
    return None, (None if u is None else max(u, move))


#: :func:`limb_centre_uncertainty` refits a limb's tangent cone without each of this many equal angular
#: sectors of its steps in turn (a delete-one-group jackknife).
LIMB_JACKKNIFE_SECTORS = 6
#: A mirror ball's limb whose centre's 95% radius (:func:`limb_centre_uncertainty`) exceeds this many pixels
#: is flagged in its description (:meth:`SphereGeometry.describe`, printed with the map): the tolerance within
#: which ``benchmarks/probe_detect.py`` counts a ball as found.
MIRROR_CENTRE_TOL_PX = 1.0


def limb_centre_uncertainty(points, cam, fit, source) -> float | None:
    """The radius (pixels) of the 95% region of a limb fit's centre, from the spread of the fit over the circle.

    The fit's own standard error (``center_sigma_px``) takes the steps for independent noise about one
    outline; where an arc of them follows a reflected edge just inside the limb instead (studio at f = 400 px in
    ``benchmarks/probe_detect.py``: 2.5-3.3 px inside over 80 degrees, the centre 1.2 px off at a standard
    error of 0.12 px) the error is shared along that arc. The fit (:func:`ffls.spheres.detect.fit_outline`) is
    repeated without the steps of each of :data:`LIMB_JACKKNIFE_SECTORS` equal sectors (about the fit's centre)
    that hold any: the jackknife variance of the centre, ``(g - 1) / g * sum |c_i - mean|^2`` over the ``g``
    refits, is the sum of two axes' variances. Half of it per axis, with the fit's own standard error in
    quadrature, is the variance ``s^2`` of a round normal error estimated from ``g - 1`` degrees of freedom:
    the 95% radius is Hotelling's, ``s * sqrt(2 (g - 1) / (g - 2) * F(0.95; 2, g - 2))`` (4.17 ``s`` for six
    refits, where a known variance would give ``sqrt(-2 ln 0.05)`` = 2.45 ``s``: with that, 24 of 29 balls of
    ``probe_detect.py`` and ``probe_hint.py`` lay within it).

    Parameters
    ----------
    points : (m, 2) float
        The steps fitted, pixels.
    cam : ffls.spheres.detect.DetectionCamera
    fit : ffls.spheres.detect.SphereFit
        Their fit.
    source : path-like

    Returns
    -------
    float or None
        None when fewer than 3 sectors can be left out (a refit needs 8 steps).
    """
    from scipy.special import fdtri  # F's quantile (scipy.stats' f.ppf calls it; its import costs ~0.25 s)

    P = np.asarray(points, dtype=np.float64)
    c0, r0 = np.asarray(fit.center_px, dtype=np.float64), float(fit.radius_px)
    sector = np.floor((np.arctan2(P[:, 1] - c0[1], P[:, 0] - c0[0]) + np.pi) / (2 * np.pi)
                      * LIMB_JACKKNIFE_SECTORS).astype(int) % LIMB_JACKKNIFE_SECTORS
    cs = sector_jackknife_centres(P, sector, cam, c0, r0, source, 8)
    g = len(cs)
    if g < 3:
        return None
    var = (g - 1) / g * float(np.sum((cs - cs.mean(axis=0)) ** 2))
    scale = np.sqrt(2 * (g - 1) / (g - 2) * fdtri(2, g - 2, 0.95))
    return float(scale * np.sqrt(var / 2 + float(fit.center_sigma_px) ** 2))


#: :func:`enclosing_steps` reports a circle of a limb's radial steps that encloses the limb and whose steps cover
#: at least this share of it. In ``benchmarks/probe_detect.py`` (azimuths 0, 45, 130, 200: 46 limbs) the
#: best circle of steps enclosing a correct limb covered at most 0.68 of itself (the clutter around the 20 px
#: balls at f = 800 px); around the one reflected circle taken for the limb (azimuth 130, courtyard, f = 400
#: px: radius 20 px of 33, 8.6 px off) the ball's own limb did, 0.875 (radius 33.3 px), which the growth of
#: :func:`unhinted_mirror_limb` (a radius up to 1.2 of the current one at each step) did not reach.
ENCLOSED_LIMB_COVERAGE = 0.75


def enclosing_steps(log_lum, center_px, radius_px):
    """The best-covered circle of radial brightness steps that encloses a limb circle, or None.

    A reflected circle inside a mirror ball can be consistent all round (its steps one sharp edge, its
    jackknife radius small: :func:`limb_centre_uncertainty` 0.89 px for a circle 8.6 px off) and no larger
    circle of steps covers :data:`LIMB_STEP_COVERAGE` (the limb's own steps weak where the background beside
    it is as dark as the ball), so neither :func:`unhinted_mirror_limb`'s growth nor the jackknife catches
    it. The ball's outline still shows as a larger circle of steps enclosing it: the steps
    (:func:`ffls.spheres.mirror_outline.mirror_silhouette`, 0.9 to 2.8 radii on ``log_lum``, the photo's log
    luminance) are searched for circles of radius 1.15 to 2 of the limb's, centre within 0.8 of it, that
    enclose it (to 1 px); the best-covered one covering :data:`ENCLOSED_LIMB_COVERAGE` is returned as
    ``(centre (2,), radius, coverage)``.
    """
    from ffls.spheres.mirror_outline import circle_coverage, mirror_silhouette

    c, r, shape = np.asarray(center_px, dtype=np.float64), float(radius_px), log_lum.shape
    # the steps from 0.9 to 2.8 radii: every circle searched (radius up to 2, centre up to 0.8 away) lies in them
    found = mirror_silhouette(log_lum, c, r, shape=shape, min_coverage=ENCLOSED_LIMB_COVERAGE, max_growth=2.8,
                              tol=1.0, n_best=LIMB_CIRCLES, max_offset=0.8 * r, r_min=1.15 * r, r_max=2.0 * r)
    enc = [(circle_coverage(p, cc, rr, 1.0, shape), np.asarray(cc, dtype=np.float64), float(rr))
           for p, cc, rr in _enclosing(found, c, r)]
    if not enc:
        return None
    cov, cc, rr = max(enc, key=lambda e: e[0])
    return cc, rr, float(cov)


def _enclosing(found, c, r):
    """The circles ``(points, centre, radius)`` of ``found`` that enclose the circle (``c``, ``r``) to 1 px."""
    return [(p, cc, rr) for p, cc, rr in found if np.hypot(*(cc - c)) + r <= rr + 1.0]


#: An unhinted probe ball's apparent radius is at least this share of the photo's shorter side
#: (:func:`diffuse_ball`): a probe is photographed to be unwrapped, framed on the ball (Debevec's fill
#: the frame; the balls of ``benchmarks/probe_detect.py`` and ``probe_hint.py`` are 0.08-0.3 of it),
#: while a busy ground's blobs give small round outlines (8 px in a 200 px photo, 0.04). A smaller ball
#: is used when hinted (``center_px``).
MIN_BALL_FRACTION = 0.05
#: A diffuse ball's shading is smooth: the edge points strictly inside its outline (within 0.85 of its
#: radius) number at most this share of its circumference in pixels, where a circle fitted to a textured
#: ground's edges holds that ground's texture (1.1-2.5 in ``benchmarks/probe_hint.py``). The edges are
#: found on log luminance, where a sunlit ball's terminator, its shading falling to the sky's level, is a
#: step: about half a circumference (0.5 under ``sunrise`` there); a cast shadow's boundary across the
#: ball is at most a third of one.
MAX_INTERIOR_EDGES = 1.0
#: Two separate round outlines that both pass as the ball, the smaller at least this share of the larger's
#: radius: which one is the probe is not decided, and the finder asks for a hint.
RIVAL_RATIO = 0.8


def _interior_edges(points, center_px, radius_px) -> float:
    """Edge points within 0.85 of the radius of the centre, per pixel of circumference."""
    d = np.hypot(*(np.asarray(points) - np.asarray(center_px)).T) if len(points) else np.zeros(0)
    return float(np.count_nonzero(d < 0.85 * radius_px)) / (2 * np.pi * max(radius_px, 1e-9))


#: A diffuse ball's outline is judged on the photo's edge points within this distance (pixels) of its
#: circle whose gradient lies within 25 degrees of the radial direction, of either polarity
#: (:func:`_outline_both_ways`).
OUTLINE_TOL_PX = 1.0
#: An edge point lies on a circle's outline when its gradient is within this angle (degrees) of the radial
#: direction, of either polarity (:func:`_radial`).
RADIAL_GRADIENT_DEG = 25.0
_RADIAL_COS = np.cos(np.radians(RADIAL_GRADIENT_DEG))
#: :func:`diffuse_ball` looks for an outline enclosing the found one with its centre within this share of
#: the radius and a radius up to this share larger (:func:`_enclosing_outline`).
ENCLOSING_OFFSET = 0.15


def _radial(points, grads, center_px):
    """``(v, d, radial)`` of edge points about ``center_px``: their offsets (n, 2), distances (n,) and whether
    their gradient lies within :data:`RADIAL_GRADIENT_DEG` of the radial direction, of either polarity (n,)."""
    v = np.asarray(points, dtype=np.float64).reshape(-1, 2) - np.asarray(center_px, dtype=np.float64)
    d = np.hypot(v[:, 0], v[:, 1])
    cosr = np.abs(np.sum(v * np.asarray(grads, dtype=np.float64).reshape(-1, 2), axis=1)) / np.maximum(d, 1e-9)
    return v, d, cosr >= _RADIAL_COS


def _outline_both_ways(points, grads, center_px, radius_px, visible_fraction) -> tuple[float, float]:
    """``(closed, support)`` of a circle (as :func:`ffls.spheres.select.outline_closure` gives them)
    on the photo's edge points of either polarity.

    A diffuse ball in front of a wall of its own brightness is brighter than the wall on its lit side and
    darker toward its terminator; between, where the two match, its outline shows no edge at all. The
    hinted fit keeps the edge points of one side (closed 0.47, support 0.52 in ``benchmarks/probe_wall.py``
    at level 0.5, and in a 90 px ball of the same make in an 800 x 600 photo: under ``min_closed`` 0.5),
    while the outline's edge points of both polarities close it (0.86-0.89, support 0.96-0.97). Points:
    within :data:`OUTLINE_TOL_PX` of the circle, their gradient radial (:func:`_radial`); closed: the share
    of the 36 angular bins of the visible outline they fall in; support: their number per pixel of visible
    outline.
    """
    v, d, radial = _radial(points, grads, center_px)
    on = (np.abs(d - radius_px) <= OUTLINE_TOL_PX) & radial
    vis = max(float(visible_fraction), 1e-6)
    bins = np.floor((np.arctan2(v[on, 1], v[on, 0]) + np.pi) / (2 * np.pi) * 36).astype(int) % 36
    return min(np.unique(bins).size / 36 / vis, 1.0), float(on.sum()) / (2 * np.pi * radius_px * vis)


def diffuse_ball(image, K, dist, R, world_from_camera, camera_model, source, saturates: bool = False):
    """A diffuse probe ball found without a hint in one photo: a :class:`ffls.spheres.detect.SphereFit`.

    A calibration capture's finder (:func:`ffls.spheres.detect.find_spheres` without hints) fits each
    candidate circle on the edges around it, which on a ground as busy and as bright as the ball
    (``benchmarks/probe_hint.py``) gives no round outline for the ball at all. Here each distinct
    candidate circle (:func:`ffls.spheres.detect.circle_candidates`) is taken instead as a centre-only
    pixel hint, whose fit searches outward from it for the best-supported round outline (the hint's
    path, ``docs/probes.md``). A fit is the ball's when its outline is round, closed and supported
    (:func:`ffls.spheres.select.round_outline`, on the fit's own edge points or on the photo's of both
    polarities, :func:`_outline_both_ways`), its centre well constrained (``CRITERIA
    ['max_center_sigma_px']``), at least 60% of it in the frame, its interior smooth
    (:data:`MAX_INTERIOR_EDGES`: a circle fitted to the ground's texture holds that texture) and its
    radius at least :data:`MIN_BALL_FRACTION` of the photo's shorter side. Of outlines that overlap, the
    one fitting its edges best (lowest RMS) stays; of the separate ones left, the largest is the ball,
    unless another is nearly as large (:data:`RIVAL_RATIO`); an outline of edge points enclosing it, at
    least as closed and supported, replaces it (:func:`_enclosing_outline`).

    Parameters
    ----------
    image : (H, W, 3) float
        Linear radiance (the luminance repeated in the three channels, as
        :func:`locate_sphere` gives the finder).
    K, dist, R, world_from_camera, camera_model, source, saturates
        As :func:`ffls.spheres.detect.find_spheres` takes them.

    Raises
    ------
    InputError
        No fit passes (one line: what was judged, and how to give a hint), or two separate ones do.
    """
    H, W = np.shape(image)[:2]
    cands, pts, grads = circle_candidates(image, source, with_grads=True)
    min_r = MIN_BALL_FRACTION * min(H, W)
    seeds, fits, why = [], [], []
    for x, y, r in cands:
        if any(np.hypot(x - a, y - b) < HINT_CENTRE_OFFSET * max(r, s) for a, b, s in seeds):
            continue  # a hint this near an earlier one's centre finds the same outline
        seeds.append((x, y, r))
        try:
            ft = find_spheres(image, K, dist, R, n_spheres=1, hints=[{"center_px": [float(x), float(y)]}],
                              world_from_camera=world_from_camera, source=source, camera_model=camera_model,
                              saturates=saturates, lit_limb=None)[0]
        except InputError:
            continue
        if any(np.hypot(*(ft.center_px - o.center_px)) < 0.5 and abs(ft.radius_px - o.radius_px) < 0.5
               for o in fits):
            continue
        fits.append(ft)
    ok = []
    for ft in sorted(fits, key=lambda f: -f.radius_px):
        if ft.center_sigma_px > CRITERIA["max_center_sigma_px"] or ft.residual_px > CRITERIA["max_residual_px"]:
            continue  # no round outline: not worth a word
        if not round_outline(ft, CRITERIA["max_residual_px"]):
            closed, support = _outline_both_ways(pts, grads, ft.center_px, ft.radius_px, ft.visible_fraction)
            if closed < CRITERIA["min_closed"] or support < CRITERIA["min_support"]:
                continue
        where = f"({ft.center_px[0]:.0f}, {ft.center_px[1]:.0f}) px, radius {ft.radius_px:.0f} px"
        inner = _interior_edges(pts, ft.center_px, ft.radius_px)
        if ft.visible_fraction < 0.6:
            why.append(f"{where}: cut by the frame ({ft.visible_fraction:.0%} of its outline inside)")
        elif inner > MAX_INTERIOR_EDGES:
            why.append(f"{where}: not smooth inside as a diffuse ball is ({inner:.1f} edge points per pixel of "
                       f"outline > {MAX_INTERIOR_EDGES})")
        elif ft.radius_px < min_r:
            why.append(f"{where}: too small for a probe (under {MIN_BALL_FRACTION:g} of the photo's shorter side, "
                       f"{min_r:.0f} px)")
        else:
            ok.append(ft)
    hint = "give a hint in probe.json, e.g. \"sphere\": {\"center_px\": [u, v]}"
    if not ok:
        judged = "; ".join(why[:3]) + (f"; and {len(why) - 3} more" if len(why) > 3 else "")
        if not seeds:
            raise InputError(f"no sphere found: no round outline in the photo ({W}x{H} px); {hint}", source)
        tried = f"{len(seeds)} place{'' if len(seeds) == 1 else 's'} tried"
        raise InputError(f"no sphere found: no round outline in the photo ({W}x{H} px, {tried}) is a diffuse "
                         f"ball's{': ' + judged if judged else ''}; {hint}", source)
    # overlapping outlines cannot both be the ball's silhouette: the one that fits its edges best stays (a
    # circle through a textured ground's edges, crossing or enclosing the ball, fits them at an RMS near the
    # fit's band, 1.0-1.5 px in benchmarks/probe_hint.py, where the silhouette, one contour, fits at 0.22-0.25)
    kept = []
    for ft in sorted(ok, key=lambda f: f.residual_px):
        if all(np.hypot(*(ft.center_px - k.center_px)) >= ft.radius_px + k.radius_px for k in kept):
            kept.append(ft)
    kept.sort(key=lambda f: -f.radius_px)
    ball = kept[0]
    for o in kept[1:]:
        if o.radius_px >= RIVAL_RATIO * ball.radius_px:
            raise InputError(f"two round outlines could be the probe ball: ({ball.center_px[0]:.0f}, "
                             f"{ball.center_px[1]:.0f}) px, radius {ball.radius_px:.0f} px and ({o.center_px[0]:.0f},"
                             f" {o.center_px[1]:.0f}) px, radius {o.radius_px:.0f} px; {hint}", source)
    return _enclosing_outline(image, ball, (pts, grads), K, dist, R, world_from_camera, camera_model, source)


def _enclosing_outline(image, ball, both, K, dist, R, world_from_camera, camera_model, source):
    """The ball's outline, or the circle of edge points (either polarity) enclosing it when that is at least as
    closed and as supported (:func:`_outline_both_ways`): the outline encloses whatever lies inside the ball.

    Under a low sun the terminator is a sharp arc just inside the limb on the ball's dark side; a fit of
    the lit side's outline with that arc (in ``benchmarks/probe_wall.py`` under ``sunrise``, 3.6-4.8 px off,
    3.1-4.4 px short) is round, closed and smooth inside, while the limb, whose edges run all round,
    encloses it. The enclosing circles are searched on the edge points of either polarity whose gradient
    is radial (:func:`ffls.spheres.mirror_outline.circle_search`, centre within :data:`ENCLOSING_OFFSET`
    of the radius, radius up to that share larger); the largest that is at least as closed and supported
    is fitted (:func:`ffls.spheres.detect.fit_outline`) on those points within twice
    :data:`OUTLINE_TOL_PX` of it, and kept when that fit stays within :data:`OUTLINE_TOL_PX` of it, fits
    its points no worse than the ball's fit and has a well-constrained centre. A circle encloses the
    found one when that lies inside it to :data:`OUTLINE_TOL_PX` plus the found fit's RMS (a fit through
    the lit limb and the terminator pokes out of the limb where they meet: by 1.1 px at RMS 1.37 px in
    ``probe_wall.py`` under ``sunrise``, level 0.3, seed 4).
    """
    from ffls.spheres.mirror_outline import circle_search

    pts, grads = both
    c0, r0 = np.asarray(ball.center_px, dtype=np.float64), float(ball.radius_px)
    _, d, radial = _radial(pts, grads, c0)
    sel = radial & (d >= r0 - 2 * OUTLINE_TOL_PX) & (d <= (1 + 2 * ENCLOSING_OFFSET) * r0 + OUTLINE_TOL_PX)
    found = circle_search(pts[sel], c0, ENCLOSING_OFFSET * r0, r0 + OUTLINE_TOL_PX, (1 + ENCLOSING_OFFSET) * r0,
                          tol=OUTLINE_TOL_PX, n_best=3)
    now = _outline_both_ways(pts, grads, c0, r0, ball.visible_fraction)
    cam = DetectionCamera(camera_model, K, dist, np.asarray(world_from_camera, dtype=np.float64), R,
                          np.shape(image)[:2])
    for c, r, _ in sorted(found, key=lambda f: -f[1]):
        if np.hypot(*(c - c0)) + r0 > r + OUTLINE_TOL_PX + ball.residual_px:
            continue  # does not enclose the fit (known to its RMS)
        closed, support = _outline_both_ways(pts, grads, c, r, ball.visible_fraction)
        if closed < now[0] or support < now[1]:
            continue
        on = sel & (np.abs(np.hypot(*(pts - c).T) - r) <= 2 * OUTLINE_TOL_PX)
        try:
            ft = fit_outline(pts[on], cam, c, r, source, n_edge=len(pts))
        except ValueError:
            continue
        if np.hypot(*(ft.center_px - c)) <= OUTLINE_TOL_PX and abs(ft.radius_px - r) <= OUTLINE_TOL_PX \
                and ft.residual_px <= ball.residual_px and ft.center_sigma_px <= CRITERIA["max_center_sigma_px"]:
            return ft
    return ball


def _check_probe_size(center_px, radius_px, shape, source) -> None:
    """Refuse an unhinted probe ball's outline under :data:`MIN_BALL_FRACTION` of the photo's shorter
    side (InputError, one line): the finder's best outline in a blurred, noisy night photo was a
    street lamp's 4 px blob at the frame's edge, 137 px from the mirror ball, used without a word.
    :func:`diffuse_ball` judges its candidates by the same bound."""
    min_r = MIN_BALL_FRACTION * min(shape)
    if radius_px < min_r:
        raise InputError(f"no sphere found: the round outline found, ({center_px[0]:.0f}, {center_px[1]:.0f}) px, "
                         f"radius {radius_px:.0f} px, is too small for a probe (under {MIN_BALL_FRACTION:g} of the "
                         f"photo's shorter side, {min_r:.0f} px); give a hint in probe.json, e.g. \"sphere\": "
                         "{\"center_px\": [u, v], \"radius_px\": r}", source)


def _limb_geometry(cam, T, stated_radius, log_lum, limb, how, source) -> SphereGeometry:
    """The sphere of a mirror ball's limb circle ``limb`` (centre, radius px): the tangent cone fitted to its steps
    (:func:`limb_cone`, pinhole; on the photo's log luminance ``log_lum``), else the cone through the circle
    (:func:`_circle_geometry`). The radius is ``stated_radius``, 1 when None (the scale unknown); a larger circle
    of steps enclosing the limb (:func:`enclosing_steps`) is kept as ``enclosed_by``."""
    R = 1.0 if stated_radius is None else stated_radius
    cone, u = (None, None) if cam.model == "orthographic" else _limb_cone(log_lum, limb[0], limb[1], cam, R, source)
    enclosed = enclosing_steps(log_lum, limb[0], limb[1])
    if cone is None:
        geo = _circle_geometry(cam, T, limb[0], limb[1], stated_radius, how)
        geo.center_uncertainty_px = u
        geo.enclosed_by = enclosed
        return geo
    return SphereGeometry(cam.model, cam.K, cam.dist, T, np.asarray(cone.center_cam, dtype=np.float64), float(R),
                          np.asarray(cone.center_px, dtype=np.float64), float(cone.radius_px), how,
                          stated_radius is not None, u, enclosed)


def locate_sphere(view, radiance, source, saturates: bool = False) -> SphereGeometry:
    """Locate the probe sphere of one view.

    Parameters
    ----------
    view : ffls.io.probe.ProbeView
    radiance : (H, W, 3) float
        The view's linear radiance (for detection).
    source : path-like
        ``probe.json``, named in errors.
    saturates : bool
        The images are integer files that clip (passed to the finder's neutrality test).

    Returns
    -------
    SphereGeometry

    Raises
    ------
    InputError
        No sphere found (one line saying where ffls looked and how to give a hint), a pinhole
        camera without ``K``, a world centre behind the camera, or a pixel circle that
        disagrees with the world centre.
    """
    cam, sph = view.camera, view.sphere
    T = np.asarray(cam.world_from_camera, dtype=np.float64)
    if cam.model == "pinhole" and cam.K is None:
        raise InputError("camera.K: missing (a pinhole camera needs its intrinsics to unwrap the probe; for a "
                         "long lens declare \"camera\": {\"model\": \"orthographic\"})", source)
    if sph.location == "world":
        Ti = np.linalg.inv(T)
        C = Ti[:3, :3] @ sph.center + Ti[:3, 3]
        R = float(sph.radius)
        with np.errstate(over="ignore", invalid="ignore"):  # a distance beyond any number: named here
            dist = float(np.linalg.norm(C))
        if not np.isfinite(dist):
            raise InputError(f"sphere.center {np.round(sph.center, 4).tolist()} and camera.world_from_camera put "
                             "the ball at a distance beyond any number from the camera: one of them is wrong",
                             source)
        if not (C[2] > R and dist > R):
            raise InputError(f"sphere.center: {np.round(sph.center, 4).tolist()} is not in front of the camera "
                             f"(camera frame {np.round(C, 4).tolist()}); check camera.world_from_camera", source)
        from ffls.camera.projection import project_points
        from ffls.spheres.detect import silhouette_px

        cpx = project_points(C[None], cam.K, cam.dist)[0]
        rpx = float(np.mean(np.hypot(*(silhouette_px(cam.K, cam.dist, C, R) - cpx).T)))
        if sph.center_px is not None:  # both given: they must agree (the capture hints' rule), not one ignored
            hpx = np.asarray(sph.center_px, dtype=np.float64)
            hr = None if sph.radius_px is None else float(sph.radius_px)
            if np.hypot(*(hpx - cpx)) > 0.5 * rpx + 2 or (hr is not None and not 1 / 1.5 <= hr / rpx <= 1.5):
                raise InputError(f"sphere.center_px ({hpx[0]:.0f}, {hpx[1]:.0f}) px"
                                 f"{f', radius_px {hr:.0f}' if hr is not None else ''} disagrees with sphere.center, "
                                 f"which projects to ({cpx[0]:.0f}, {cpx[1]:.0f}) px, radius {rpx:.0f} px: give "
                                 "one of them, or correct it", source)
        why = stated_circle_problem(cpx, rpx, np.shape(radiance))
        if why:
            raise InputError(f"sphere.center projects to a circle {why}", source)
        return SphereGeometry(cam.model, cam.K, cam.dist, T, C, R, cpx, rpx, "probe.json", True)
    if sph.location == "pixel" and sph.radius_px is not None:
        why = stated_circle_problem(sph.center_px, sph.radius_px, np.shape(radiance))
        if why:
            raise InputError(f"sphere.center_px and radius_px: the circle {why}", source)
        return _given_circle(cam, T, sph, source)
    hints = None
    if sph.location == "pixel":
        h = {"center_px": [float(x) for x in sph.center_px]}
        if sph.radius_px is not None:
            h["radius_px"] = float(sph.radius_px)
        hints = [h]
    R = sph.radius if sph.radius is not None else 1.0
    # without a stated radius the scale is unknown: put the camera at the world origin so that the
    # finder's scale check (camera distance against scene centre) has nothing to compare
    Tf = T.copy()
    if sph.radius is None:
        Tf[:3, 3] = 0.0
    # the finder looks for the outline on luminance: a mirror ball's colours are the scene's, not
    # evidence of what it is (its neutrality criterion is for calibration spheres)
    rad = np.asarray(radiance, dtype=np.float32)
    lum = rad @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    lum3 = np.repeat(lum[..., None], 3, axis=2)
    try:
        if hints is None and sph.material == "diffuse":
            found = [diffuse_ball(lum3, cam.K, cam.dist, R, Tf, cam.model, source,
                                  saturates)]
        else:
            found = find_spheres(lum3, cam.K, cam.dist, R, n_spheres=1, hints=hints,
                                 world_from_camera=Tf, source=source, camera_model=cam.model, saturates=saturates,
                                 lit_limb=None, retry_hints=sph.material != "mirror")
    except InputError as e:
        limb = None
        if hints is not None and sph.material == "mirror":
            # the finder's outline near the hint failed its own tests (in benchmarks/probe_hint.py a reflected
            # edge's fit, centre poorly constrained): the limb of the candidate circles around the hint instead
            log_lum = _log_luminance(rad)
            limb = unhinted_mirror_limb(rad, lum3, None, source, near=sph.center_px, log_lum=log_lum)
        if limb is not None:
            return _limb_geometry(cam, T, sph.radius, log_lum, limb, "hint", source)
        # the finder speaks capture.json's keys (spheres[0], sphere_count); probe.json has one "sphere"
        msg = e.message.replace("capture.json", "probe.json").replace("\"spheres\": [{\"center_px\": [u, v]}] or "
                                                                      "\"sphere_count\": n",
                                                                      "\"sphere\": {\"center_px\": [u, v]}")
        msg = re.sub(r"\bspheres\[0\]", "sphere", msg).replace("no sphere found (sphere_count 1)", "no sphere found")
        if sph.location == "pixel" and "radius_px" not in msg:  # the hint's way out: a circle used as given
            msg += ("; measure the ball's outline in the photo and give \"radius_px\" with \"center_px\" "
                    "(a circle stated in pixels is used as given)")
        raise InputError(msg, source) from None
    ft = found[0]
    if hints is None:
        _check_probe_size(ft.center_px, ft.radius_px, rad.shape[:2], source)
    if view.sphere.material == "mirror":  # the limb's reflectance step rather than a reflected edge
        log_lum = _log_luminance(rad)  # (once: the limb's search and its cone's fit)
        limb = _limb_near(log_lum, ft.center_px, ft.radius_px, rad.shape[:2]) if hints else \
            unhinted_mirror_limb(rad, lum3, ft, source, log_lum=log_lum)
        if limb is not None:
            if hints is None:
                _check_probe_size(limb[0], limb[1], rad.shape[:2], source)
            return _limb_geometry(cam, T, sph.radius, log_lum, limb, "hint" if hints else "auto", source)
        if hints is None and ft.residual_px > MIRROR_SHARP_OUTLINE_PX:
            raise InputError(f"no sphere found: the round outline found, ({ft.center_px[0]:.0f}, "
                             f"{ft.center_px[1]:.0f}) px, radius {ft.radius_px:.0f} px, is neither confirmed by a "
                             f"mirror ball's limb (its reflectance steps cover under {LIMB_STEP_COVERAGE:.0%} of any "
                             f"circle near it) nor a sharp outline (RMS {ft.residual_px:.2f} px > "
                             f"{MIRROR_SHARP_OUTLINE_PX}); give a hint in probe.json, e.g. \"sphere\": "
                             "{\"center_px\": [u, v], \"radius_px\": r}", source)
    if cam.model == "orthographic":
        return SphereGeometry(cam.model, None, None, T, None, None, np.asarray(ft.center_px, dtype=np.float64),
                              float(ft.radius_px), "hint" if hints else "auto")
    return SphereGeometry(cam.model, cam.K, cam.dist, T, np.asarray(ft.center_cam, dtype=np.float64), float(R),
                          np.asarray(ft.center_px, dtype=np.float64), float(ft.radius_px),
                          "hint" if hints else "auto", sph.radius is not None)
