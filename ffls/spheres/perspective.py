"""A normal lens declared orthographic: what the spheres' outlines say about the lens.

An orthographic camera sees every sphere as a circle. Through a pinhole, a sphere whose centre
is seen at an angle ``theta`` off the lens axis projects to an ellipse (the section of its tangent
cone) elongated along the line to the principal point, its axes in the ratio ``1 / cos theta``;
spheres of one size then also differ in pixel radius with their depth. Declared orthographic,
such a capture's normals are turned by about ``theta`` per sphere, and its lights with them, with
nothing in the shading to show it (i-user15: a 46 deg lens, 16.74 / 19.91 deg off, none inside its
cone; docs/formats.md).

:func:`perspective_outlines` fits an ellipse to each found sphere's outline points
(``cv2.fitEllipse``) and splits its elongation ``a / b - 1`` into the part along the line to the
image centre (a lens's) and the part across it (what outline noise, shading and blur make,
whatever the lens). The radial parts are tested against the spread of the cross parts and the
points' own noise; where significant (one-sided, :data:`SIGNIFICANCE`), each sphere's implied
angle off the axis, ``arccos(1 / (1 + e))`` at the upper end of its 95% interval, bounds the
orthographic model's error of its directions (:func:`ffls.spheres.estimate.estimate_lights`
widens the cones by it; ``ffls lights`` says so in one line).

A long lens (4.9 deg: the bench's c15, its outlines' radial elongation 0.1-1%) stays below
the noise; a 46 deg lens puts 2-6% into spheres 100-160 px off the centre of a 384 px photo.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["SIGNIFICANCE", "MIN_POINTS", "MIN_COVERAGE", "OutlineShape", "PerspectiveEvidence",
           "outline_shape", "perspective_outlines"]

#: One-sided level of the radial elongation's test (the photo fits' level,
#: :data:`ffls.spheres.photo.SIGNIFICANCE`).
SIGNIFICANCE = 1e-3
#: Fewest outline points for an ellipse.
MIN_POINTS = 20
#: Least share of the outline (:attr:`ffls.spheres.detect.SphereFit.coverage`) with points: an arc
#: leaves an ellipse's axes undetermined.
MIN_COVERAGE = 0.75


@dataclass
class OutlineShape:
    """One sphere's outline as an ellipse (:func:`outline_shape`).

    Attributes
    ----------
    center_px : (2,) float
        The ellipse's centre.
    offset_px : float
        Its distance from the image centre.
    radial, across : float
        The relative elongation ``a / b - 1`` times ``cos 2 d`` and ``sin 2 d``, ``d`` the angle
        between the major axis and the line to the image centre.
    sigma : float
        Standard deviation of either part from the outline points' noise (``2 s sqrt(2 / n) / r``:
        the second harmonic of ``n`` points with residual ``s`` around a circle of radius ``r``).
    """

    center_px: np.ndarray
    offset_px: float
    radial: float
    across: float
    sigma: float


@dataclass
class PerspectiveEvidence:
    """The outlines' verdict on an orthographic camera (:func:`perspective_outlines`).

    Attributes
    ----------
    shapes : list of (OutlineShape or None)
        Per sphere (None: not measured: a pinhole fit, too few points or too little of the outline).
    z : float
        The radial elongations' weighted mean over its standard error (0 with none measured).
    detected : bool
        ``z`` above the one-sided normal quantile of :data:`SIGNIFICANCE`.
    angles_deg : list of float
        Per sphere, the angle off the lens axis its outline implies, at the upper end of its 95%
        interval (0 where not detected or not measured): the orthographic model's error of its
        directions.
    focal_px : float
        The focal length the measured outlines imply (NaN where not detected).
    """

    shapes: list = field(default_factory=list)
    z: float = 0.0
    detected: bool = False
    angles_deg: list = field(default_factory=list)
    focal_px: float = float("nan")

    def note(self, where) -> str | None:
        """The one line for ``ffls lights`` (None where nothing was detected)."""
        if not self.detected:
            return None
        k = sum(s is not None and a > 0 for s, a in zip(self.shapes, self.angles_deg))
        outlines = f"{k} sphere outline{'s are' if k > 1 else ' is'}"
        return (f"{where}: the camera is declared orthographic, but {outlines} elongated "
                f"toward the image centre as a normal lens makes (significance {self.z:.1f} "
                f"sigma; a focal length of about {self.focal_px:.0f} px, spheres up to "
                f"{max(self.angles_deg):.1f} deg off its axis): the directions are turned by up "
                f"to that, and their cones were widened by it; give the lens's \"K\" (and "
                f"\"sphere_radius\") in \"camera\" (docs/formats.md, \"camera\")")


def outline_shape(fit, shape) -> OutlineShape | None:
    """:class:`OutlineShape` of one :class:`ffls.spheres.detect.SphereFit` in a photo of ``shape``
    (H, W); None where it cannot be measured (:data:`MIN_POINTS`, :data:`MIN_COVERAGE`)."""
    import cv2

    pts = np.asarray(fit.edge_px, dtype=np.float32).reshape(-1, 2)
    if len(pts) < MIN_POINTS or fit.coverage < MIN_COVERAGE or not fit.radius_px > 0:
        return None
    (cx, cy), (w, h), ang = cv2.fitEllipse(pts)
    a, b = 0.5 * max(w, h), 0.5 * min(w, h)
    if not (np.isfinite(a) and b > 0):
        return None
    major = np.radians(ang if w >= h else ang + 90.0)
    c0 = np.array([(shape[1] - 1) / 2.0, (shape[0] - 1) / 2.0])
    dx, dy = cx - c0[0], cy - c0[1]
    d = major - np.arctan2(dy, dx)
    e = a / b - 1.0
    sigma = 2.0 * max(float(fit.residual_px), 1e-3) * np.sqrt(2.0 / len(pts)) / float(fit.radius_px)
    return OutlineShape(center_px=np.array([cx, cy]), offset_px=float(np.hypot(dx, dy)),
                        radial=float(e * np.cos(2 * d)), across=float(e * np.sin(2 * d)),
                        sigma=float(sigma))


def perspective_outlines(spheres, shape) -> PerspectiveEvidence:
    """Whether the spheres' outlines show a normal lens behind a camera declared orthographic.

    Parameters
    ----------
    spheres : list of SphereFit
        The spheres found (only ``camera_model == 'orthographic'`` fits are measured).
    shape : (H, W)
        The photos' size.

    Returns
    -------
    PerspectiveEvidence
    """
    from scipy.stats import norm

    ortho = [getattr(s, "camera_model", "pinhole") == "orthographic" for s in spheres]
    shapes = [outline_shape(s, shape) if o else None for s, o in zip(spheres, ortho)]
    meas = [s for s in shapes if s is not None]
    out = PerspectiveEvidence(shapes=shapes, angles_deg=[0.0] * len(shapes))
    if not meas:
        return out
    # the elongation no lens makes (across the line to the centre) sets each radial part's noise
    across = float(np.mean([s.across ** 2 for s in meas]))
    sd = np.array([np.sqrt(max(s.sigma ** 2, across)) for s in meas])
    rad = np.array([s.radial for s in meas])
    w = sd ** -2
    out.z = float(np.sum(w * rad) / np.sqrt(np.sum(w)))
    out.detected = bool(out.z > norm.isf(SIGNIFICANCE))
    if not out.detected:
        return out
    q = norm.isf(0.025)
    focal = []
    for i, s in enumerate(shapes):
        if s is None:
            continue
        e = max(s.radial, 0.0) + q * np.sqrt(max(s.sigma ** 2, across))
        out.angles_deg[i] = float(np.degrees(np.arccos(1.0 / (1.0 + e))))
        if s.radial > 0 and s.offset_px > 0:
            focal.append(s.offset_px / np.tan(np.arccos(1.0 / (1.0 + s.radial))))
    out.focal_px = float(np.median(focal)) if focal else float("nan")
    c0 = np.array([(shape[1] - 1) / 2.0, (shape[0] - 1) / 2.0])
    # an unmeasured sphere: the lens's angle at its offset
    for i, (s, ft, o) in enumerate(zip(shapes, spheres, ortho)):
        if s is None and o and np.isfinite(out.focal_px):
            off = float(np.hypot(*(np.asarray(ft.center_px, dtype=np.float64) - c0)))
            out.angles_deg[i] = float(np.degrees(np.arctan2(off, out.focal_px)))
    return out
