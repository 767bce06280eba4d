"""Honest uncertainty of the light directions: 95% confidence cones calibrated on the data.

A reported ``uncertainty_deg`` is the radius of the 95% confidence cone around a direction
(GUIDE, section 1). It is built from three parts, each measured on the photographs themselves:

1. **Per sphere, the fit statistics inflated by the misfit.** The covariance ``s^2 (A^T A)^-1``
   of a shading fit (:mod:`ffls.spheres.lambert`) already scales with the residual variance
   ``s^2`` (the reduced chi-square of the fit), but it assumes independent residuals. Model
   misfit (interreflection, an approximate bounce, penumbra, a centre a fraction of a pixel off)
   leaves smooth, spatially correlated residuals, so the pixels carry far less independent
   information than their count. :func:`correlation_inflation` measures the residuals'
   correlation between neighbouring pixels along the rows and the columns and inflates the
   covariance by the variance inflation factor of a separable first-order autoregressive field,
   ``(1 + r_x) / (1 - r_x) * (1 + r_y) / (1 - r_y)`` (the ratio of the pixel count to the
   effective number of independent pixels; Bartlett 1946, Bayley & Hammersley 1946).
2. **Capture-wide, what the fit statistics miss, from the spheres' disagreement.** In a photo
   with two or more spheres, the spheres' directions must agree up to their errors. Their
   scatter about the photo's light measures the per-sphere error that the fit statistics do not
   see (:func:`fit_error_model`): a scale ``s`` of the statistical standard deviations and an
   added per-sphere floor ``tau`` (per axis), ``var_i = s^2 sigma_i^2 + g_i^2 + tau^2``, by
   restricted maximum likelihood (the photo's direction is estimated from the same spheres,
   Patterson & Thompson 1971) over all photos (from several starts: the likelihood can have a
   basin where the disagreement is a scale of the statistics and one where it is a floor beside
   them, and the global minimum is kept), trimmed: photos whose scatter is improbable under
   the fitted model at a family-wise level (``p < 1e-3 / n_photos``) are left out and the fit
   repeated. ``g_i`` is the sphere's centre uncertainty propagated to its direction
   (:func:`centre_floor_deg`: the outline and the shading place the centre ``shift`` apart), a
   known part of its variance. Where a capture holds both kinds of sphere and two or more of a
   kind disagree in enough photos, that kind gets its own ``s`` and ``tau`` (fitted again with
   the other spheres at the shared fit's; :attr:`ErrorModel.kind_terms`): a mirror's highlight
   and a matte ball's shading err differently, and one pair for both lets either set the other's
   cone. A photo of one sphere of each kind cannot tell them apart: such a capture keeps the
   shared fit. A sphere whose photos' other spheres are far less certain (a grey ball beside a
   chrome ball) has a floor the disagreement cannot measure: their sigma explains the scatter,
   and the fitted floor falls near 0 whatever its own is. Where the profile likelihood of an
   extra floor on that sphere alone cannot exclude doubling its variance, it gets that floor's
   95% upper bound, at most the fallback's (:func:`unchecked_floor_deg`,
   :attr:`ErrorModel.sphere_floor_deg`).
3. **The common mode, which no disagreement shows.** An error shared by all spheres of a photo
   (camera pose, the encoding or bounce model, a bias of all detected outlines) moves them
   together. For a photo's spheres it is the **common floor** alone: ``COMMON_FLOOR_DEG`` (per
   axis, stated) plus, in quadrature, the turns the spheres share that the capture measures (the
   mean of the spheres' centre shifts, shading against outline, and the turn of an undivided lens
   fall-off: :func:`ffls.spheres.estimate.calibrate_uncertainty`). Until stop 29 it also held a
   third of the spheres' systematic variance (an assumed correlation of at most 0.25 between two
   spheres' systematic errors), which made the common mode the largest term of the cone on most
   captures.
   Measured against renders' truth (``docs/spheres.md``, "The multi-sphere common mode
   measured"), the shared error does not follow the disagreement: on the bench's ffls synth rows
   (spheres around an object, 0.1-2.3 degrees of disagreement per axis) the spheres' errors
   correlate -0.21..+0.05 and partly cancel in the mean; on independent renders (balls before a
   plane) they correlate +0.08..+0.65 but disagree by 0.06-0.11 degrees. On 32 multi-sphere
   captures with distant lights (16 bench rows, 7 independent renders, 9 fresh ffls synth ones)
   the photos' error common to the whole capture (their mean, per axis) is at or under the floor
   (the largest excess 0.196 against 0.189 degrees, within its sampling error of 0.04). So the
   share is 0 for a photo's spheres
   (:data:`SPHERES_CORRELATION`, :meth:`ErrorModel.common_sigma_deg` with ``common_ratio`` 0), and
   the proportional bound (``COMMON_CORRELATION`` 0.25, ``rho / (1 - rho)`` of the shared
   systematic variance, :meth:`ErrorModel.shared_var_deg2`, averaged with the spheres' inverse
   variances) stays only for a lone sphere's two halves and the stated fallback, whose halves share
   one sphere's centre, surface and surroundings. The capture's fitted parameters cannot size the
   common mode: propagated by their standard errors (a GUM type-B evaluation,
   :func:`shading_shift`, :func:`shared_parameter_deg`, :func:`own_parameter_deg`), the encoding's
   exponent and the ground ratios move the directions by at most 0.06 degrees (``docs/spheres.md``,
   "The common mode from the capture's fitted parameters"). Left as an assumption: the spheres'
   errors beyond the common floor are independent. Around an object they partly cancel (the
   cones there are about 2 times the 95th percentile of the errors), which their offsets cannot
   tell from independent errors, and a layout where they do not cancel exists (a row).

   With one sphere there is no disagreement between spheres, but a matte sphere's two halves
   disagree (:func:`halves_error_model`): the same fit on the two halves' offsets gives its scale, floor,
   cone factor and common-mode bound, measured on its own photos. Where neither can be measured
   (a lone mirror ball, too few photos with both halves fitted), the fit statistics plus a stated
   per-sphere floor (``FALLBACK_FLOOR_DEG``, RMS) and its common-mode share are used
   (:data:`FALLBACK_MODEL`); a mirror sphere there has its highlight's and outline's own terms
   and the common floor only (:meth:`ErrorModel.with_mirrors_own_floor`).

The photo's per-axis standard deviation is that of the weighted mean its direction was made with
(``sum w_i^2 var_i``, :meth:`ErrorModel.photo_sigma_deg`) plus its common mode; a near light's
also holds its distance's error turned by the parallax of the spheres that place it
(:func:`distance_coupling_deg`, :func:`distance_spread`, :meth:`ErrorModel.distance_sigma_deg`). The cone is a
multiple of it, :attr:`ErrorModel.cone_factor`. A per-axis Gaussian on the tangent plane would
give ``sqrt(chi2.ppf(0.95, 2)) = 2.448`` (:data:`CONE_FACTOR`: the squared angle over the per-axis
variance is chi-square with 2 degrees of freedom), but systematic errors are not Gaussian: bounded
ones have lighter tails, a misfit that grows toward the terminator or the rim heavier ones. Where
the spheres disagree in enough photos, the factor is **the capture's own 95% quantile**
(:func:`tail_factor`): each used sphere's offset from the weighted mean of the photo's other
spheres, divided by its standard deviation under the fitted model (leave one out, so the offset
is independent of what it is compared with), is a draw of the standardised error's radius; the
95% quantile of these radii over the capture replaces the Gaussian's 2.448. With too few such
offsets (:data:`MIN_TAIL_SAMPLES`; one sphere) the Gaussian factor is used.

Internally (:mod:`ffls.spheres.lambert`, :mod:`ffls.spheres.combine`, the consistency and
outlier tests of :mod:`ffls.spheres.photo`) uncertainties stay 1-sigma RMS angles; only the
reported ``uncertainty_deg`` values are 95% cone radii.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from ffls.conventions import normalize, tangent_basis

__all__ = [
    "CONFIDENCE",
    "CONE_FACTOR",
    "COMMON_CORRELATION",
    "SPHERES_CORRELATION",
    "COMMON_FLOOR_DEG",
    "FALLBACK_FLOOR_DEG",
    "ErrorModel",
    "cone_deg",
    "correlation_inflation",
    "tangent_residuals",
    "fit_error_model",
    "centre_floor_deg",
    "common_mode_deg",
    "photo_residuals",
    "FALLBACK_MODEL",
    "MIN_TAIL_SAMPLES",
    "tail_factor",
    "halves_error_model",
    "unchecked_floor_deg",
    "shading_shift",
    "encoding_perturbation",
    "bounce_perturbation",
    "shared_parameter_deg",
    "own_parameter_deg",
    "distance_coupling_deg",
    "distance_spread",
]

#: Confidence level of a reported cone.
CONFIDENCE = 0.95
#: Radius of the 95% cone in per-axis standard deviations: ``sqrt(chi2.ppf(0.95, 2))``, in closed
#: form (the chi-square of 2 degrees of freedom is exponential: ``ppf(p) = -2 ln(1 - p)``; the same
#: float as ``scipy.special.chdtri(2, 0.05)``, without importing SciPy with this module).
CONE_FACTOR = float(np.sqrt(-2.0 * np.log(1.0 - CONFIDENCE)))
#: Assumed upper bound of the correlation between a lone sphere's two halves' systematic errors, and
#: the stated fallback's common-mode share (module docstring, part 3).
COMMON_CORRELATION = 0.25
#: The common mode's share of the systematic variance between two spheres of a photo (module
#: docstring, part 3): none beyond the common floor. Measured against renders' truth
#: (``docs/spheres.md``, "The multi-sphere common mode measured"): the spheres' errors correlate
#: -0.21..+0.05 where they disagree by 0.1-2.3 degrees and up to +0.65 only where they disagree by
#: 0.06-0.11, so the shared error does not follow the disagreement; the floor bounds it.
SPHERES_CORRELATION = 0.0
#: Per-axis standard deviation (degrees) of the common-mode error of even perfectly agreeing spheres.
COMMON_FLOOR_DEG = 0.1
#: Per-sphere RMS floor (degrees) where no disagreement can be measured (one sphere per photo).
FALLBACK_FLOOR_DEG = 1.0
#: Significance below which a photo's scatter is trimmed from the error-model fit.
TRIM_SIGNIFICANCE = 1e-3
#: Fewest leave-one-out sphere offsets for the capture's own cone quantile (:func:`tail_factor`):
#: the 95% quantile of 40 Rayleigh draws has a relative standard error of about 12%.
MIN_TAIL_SAMPLES = 40
#: Nodes per parameter of the coarse grid whose best node starts the error-model fit beside the
#: usual start (:func:`fit_error_model`; the restricted likelihood can have two local minima).
START_GRID = 9


def cone_deg(sigma_axis_deg):
    """95% cone radius (degrees) of a direction with per-axis standard deviation ``sigma_axis_deg``.

    Parameters
    ----------
    sigma_axis_deg : float or array
        Standard deviation of each of the two tangent-plane components (degrees).

    Returns
    -------
    float or array
        ``CONE_FACTOR * sigma_axis_deg``.
    """
    return CONE_FACTOR * np.asarray(sigma_axis_deg, dtype=np.float64) if np.ndim(sigma_axis_deg) \
        else CONE_FACTOR * float(sigma_axis_deg)


def correlation_inflation(residuals: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                          max_factor: float | None = None) -> tuple[float, float, float]:
    """Variance inflation of a fit's covariance from its residuals' spatial correlation.

    The residuals are placed on their pixel grid; the lag-one correlation ``r_x`` between
    horizontally adjacent pixels and ``r_y`` between vertically adjacent ones (both pixels
    present) give the factor ``(1 + r_x) / (1 - r_x) * (1 + r_y) / (1 - r_y)`` of a separable
    first-order autoregressive field: the pixel count divided by the effective number of
    independent pixels. Negative correlations count as zero (no deflation).

    Parameters
    ----------
    residuals : (m,) float
        Residuals of the pixels used in the fit.
    rows, cols : (m,) int
        Their pixel coordinates.
    max_factor : float, optional
        Upper bound of the factor (e.g. the pixel count over the parameter count).

    Returns
    -------
    factor : float
        >= 1.
    r_x, r_y : float
        The lag-one correlations, in [0, 1).
    """
    r = np.asarray(residuals, dtype=np.float64)
    rows = np.asarray(rows)
    cols = np.asarray(cols)
    if r.size < 4:
        return 1.0, 0.0, 0.0
    r = r - r.mean()
    r0, c0 = int(rows.min()), int(cols.min())
    grid = np.zeros((int(rows.max()) - r0 + 2, int(cols.max()) - c0 + 2))
    have = np.zeros(grid.shape, dtype=bool)
    grid[rows - r0, cols - c0] = r
    have[rows - r0, cols - c0] = True

    def lag_one(a, b, ha, hb):
        both = ha & hb
        if both.sum() < 3:
            return 0.0
        x, y = a[both], b[both]
        den = 0.5 * float(x @ x + y @ y)
        return float(np.clip((x @ y) / den, 0.0, 0.999)) if den > 0 else 0.0

    rx = lag_one(grid[:, :-1], grid[:, 1:], have[:, :-1], have[:, 1:])
    ry = lag_one(grid[:-1], grid[1:], have[:-1], have[1:])
    f = (1.0 + rx) / (1.0 - rx) * (1.0 + ry) / (1.0 - ry)
    if max_factor is not None:
        f = min(f, max(float(max_factor), 1.0))
    return float(max(f, 1.0)), rx, ry


def tangent_residuals(directions: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Tangent-plane offsets (radians) of directions from their predictions.

    Each offset is expressed in the tangent basis of the mean of the predictions (a photo's
    spheres are close to each other on the unit sphere), so the offsets of one photo share axes.

    Parameters
    ----------
    directions : (k, 3) float, unit
    predicted : (k, 3) float, unit

    Returns
    -------
    (k, 2) float
    """
    d = normalize(np.atleast_2d(np.asarray(directions, dtype=np.float64)))
    p = normalize(np.atleast_2d(np.asarray(predicted, dtype=np.float64)))
    e1, e2 = tangent_basis(normalize(p.sum(axis=0)))
    # log map of d at p, then expressed on the shared axes
    c = np.clip(np.einsum("ij,ij->i", d, p), -1.0, 1.0)
    t = d - c[:, None] * p
    nt = np.linalg.norm(t, axis=1)
    ang = np.arccos(c)
    scale = np.where(nt > 0, ang / np.maximum(nt, 1e-300), 0.0)
    t = t * scale[:, None]
    return np.stack([t @ e1, t @ e2], axis=1)


@dataclass(frozen=True)
class ErrorModel:
    """The error model of a capture's directions (module docstring).

    Attributes
    ----------
    scale : float
        ``s``: multiplies each sphere's statistical per-axis standard deviation.
    floor_deg : float
        ``tau``: per-axis standard deviation (degrees) added, in quadrature, to each sphere.
    common_deg : float
        Per-axis standard deviation (degrees) of the error shared by all spheres of a photo: the
        bound for the capture's median sphere (a summary), or, with ``common_ratio`` None, the
        value added to every photo.
    source : {'disagreement', 'halves', 'fallback'}
        Measured from the spheres' disagreement, from a lone sphere's halves'
        (:func:`halves_error_model`), or the stated single-sphere fallback.
    n_photos : int
        Photos with two or more spheres (or both halves of a lone sphere) used in the fit.
    n_trimmed : int
        Of those, left out as improbable under the fitted model.
    centre_deg : tuple of float
        Per sphere, the per-axis standard deviation (degrees) its centre's uncertainty gives its
        direction (:func:`centre_floor_deg`).
    cone_factor : float
        Radius of the 95% cone in per-axis standard deviations: the capture's own quantile
        (:func:`tail_factor`), or the Gaussian :data:`CONE_FACTOR`.
    n_tail : int
        Leave-one-out sphere offsets that measured ``cone_factor`` (0: the Gaussian factor).
    common_ratio : float or None
        ``rho / (1 - rho)``: the common mode's variance bound as a multiple of the systematic
        variance of the spheres a direction is made from (:meth:`common_sigma_deg`), so that a
        photo (or a sphere) gets its own bound. None: the fixed ``common_deg`` everywhere.
    common_floor_deg : float
        Per-axis common-mode floor (degrees) added in quadrature to the bound (with
        ``common_ratio``).
    distance_sigma : float
        Relative 1-sigma error of a near light's distance (:func:`distance_spread` of the
        capture's near lights; 0 for distant lights): with a photo's coupling of direction and
        distance (:func:`distance_coupling_deg`) a term of its cone
        (:meth:`distance_sigma_deg`).
    sphere_kinds : tuple of str
        Per sphere, its kind (``'matte'``, ``'mirror'``; empty: not given).
    kind_terms : tuple of (str, float, float, int)
        Per kind whose spheres disagree among themselves in enough photos, its own ``(kind, s,
        tau_deg, n_photos)`` (:func:`fit_error_model`); a sphere of another kind, or of none,
        has the shared ``scale`` and ``floor_deg``.
    sphere_floor_deg : tuple of float
        Per sphere, the least per-axis floor (degrees) of a sphere whose floor the disagreement
        cannot measure (0 where it does): the profile likelihood's upper bound of its own floor,
        at most the fallback's (:func:`unchecked_floor_deg`).
    """

    scale: float
    floor_deg: float
    common_deg: float
    source: str
    n_photos: int = 0
    n_trimmed: int = 0
    centre_deg: tuple = ()
    cone_factor: float = CONE_FACTOR
    n_tail: int = 0
    common_ratio: float | None = None
    common_floor_deg: float = COMMON_FLOOR_DEG
    distance_sigma: float = 0.0
    sphere_kinds: tuple = ()
    kind_terms: tuple = ()
    sphere_floor_deg: tuple = ()

    def terms(self, spheres, shape=()) -> tuple[np.ndarray, np.ndarray]:
        """Per sphere, its scale ``s`` and floor ``tau`` (degrees): its kind's own (``kind_terms``)
        or the shared ``scale`` and ``floor_deg``.

        Parameters
        ----------
        spheres : int or (k,) int or None
            Sphere indices (None: the shared terms).
        shape : tuple
            The shape of the result (that of the spheres' statistics).
        """
        s = np.full(shape, float(self.scale))
        t = np.full(shape, float(self.floor_deg))
        if spheres is None or not ((self.kind_terms and self.sphere_kinds) or self.sphere_floor_deg):
            return s, t
        idx = np.atleast_1d(np.asarray(spheres, dtype=np.intp)).ravel()
        s, t = np.broadcast_to(s, idx.shape).copy(), np.broadcast_to(t, idx.shape).copy()
        s_k, t_k = self._kind_sphere_terms
        have = (idx >= 0) & (idx < s_k.size)
        s[have], t[have] = s_k[idx[have]], t_k[idx[have]]
        lift = np.asarray(self.sphere_floor_deg, dtype=np.float64)  # (unchecked_floor_deg)
        at = (idx >= 0) & (idx < lift.size)
        t[at] = np.maximum(t[at], lift[idx[at]])
        return s.reshape(shape), t.reshape(shape)

    @cached_property
    def _kind_sphere_terms(self) -> tuple[np.ndarray, np.ndarray]:
        """Per sphere of ``sphere_kinds``, its ``s`` and ``tau`` (degrees) for :meth:`terms`: its kind's
        own (``kind_terms``) or the shared ones; derived once (the model is frozen)."""
        own = {k: (sk, tk) for k, sk, tk, _ in self.kind_terms}
        st = np.array([own.get(kd, (self.scale, self.floor_deg)) for kd in self.sphere_kinds],
                      dtype=np.float64).reshape(-1, 2)
        return st[:, 0], st[:, 1]

    def distance_sigma_deg(self, coupling_deg: float) -> float:
        """Per-axis standard deviation (degrees) of a near light's direction from its distance's
        error: ``coupling_deg * distance_sigma`` (a turn along one axis), half its variance on
        each tangent axis.

        Parameters
        ----------
        coupling_deg : float
            The photo's turn per unit relative distance error (:func:`distance_coupling_deg`).
        """
        return float(abs(float(coupling_deg)) * float(self.distance_sigma) / np.sqrt(2.0))

    def cone_deg(self, sigma_axis_deg):
        """95% cone radius (degrees) under this model: ``cone_factor * sigma_axis_deg``.

        Parameters
        ----------
        sigma_axis_deg : float or array
            Per-axis standard deviation (degrees) of a direction (:meth:`photo_sigma_deg`, or a
            sphere's :meth:`sphere_sigma_deg` with the common mode).

        Returns
        -------
        float or array
        """
        return cone_deg(sigma_axis_deg) * (float(self.cone_factor) / CONE_FACTOR)

    def centre_sigma_deg(self, spheres) -> np.ndarray:
        """Per-axis standard deviation (degrees) that each sphere's centre uncertainty gives its
        direction (:func:`centre_floor_deg`; 0 for a sphere without one).

        Parameters
        ----------
        spheres : (k,) int
            Sphere indices.
        """
        c = np.asarray(self.centre_deg, dtype=np.float64)
        idx = np.atleast_1d(np.asarray(spheres, dtype=np.intp))
        out = np.zeros(idx.shape)
        have = idx < c.size
        out[have] = c[idx[have]]
        return out

    def sphere_sigma_deg(self, stat_sigma_deg, spheres=None):
        """Per-axis standard deviation (degrees) of one sphere's direction:
        ``sqrt(s^2 sigma^2 + g^2 + tau^2)``, ``g`` its centre term (:meth:`centre_sigma_deg`).

        Parameters
        ----------
        stat_sigma_deg : float or (k,) float
            The sphere's statistical per-axis standard deviation (degrees).
        spheres : int or (k,) int, optional
            The spheres' indices (for their centre terms; none when omitted).
        """
        s = np.asarray(stat_sigma_deg, dtype=np.float64)
        g = 0.0 if spheres is None else self.centre_sigma_deg(spheres).reshape(np.shape(s))
        sc, tau = self.terms(spheres, np.shape(s))
        return np.sqrt((sc * s) ** 2 + g ** 2 + tau ** 2)

    def systematic_var_deg2(self, stat_sigma_deg, spheres=None) -> np.ndarray:
        """Per-axis variance (degrees squared) of each sphere's systematic error: what its variance
        holds beyond its fit statistics, ``tau^2 + g^2 + max(s^2 - 1, 0) sigma^2``.

        Parameters
        ----------
        stat_sigma_deg : float or (k,) float
        spheres : int or (k,) int, optional
        """
        s = np.asarray(stat_sigma_deg, dtype=np.float64)
        g = 0.0 if spheres is None else self.centre_sigma_deg(spheres).reshape(np.shape(s))
        return self.shared_var_deg2(s, spheres) + g ** 2

    def shared_var_deg2(self, stat_sigma_deg, spheres=None) -> np.ndarray:
        """Per-axis variance (degrees squared) of the part of each sphere's systematic error that
        other spheres may share, the base of the common-mode bound: ``tau^2 + max(s^2 - 1, 0)
        sigma^2`` (:meth:`systematic_var_deg2` without the centre term ``g``: a centre error is
        each sphere's own, from its own outline and shading, and no other sphere shares it).

        Parameters
        ----------
        stat_sigma_deg : float or (k,) float
        spheres : int or (k,) int, optional
            The spheres' indices (for their kinds' terms, :meth:`terms`).
        """
        s = np.asarray(stat_sigma_deg, dtype=np.float64)
        sc, tau = self.terms(spheres, np.shape(s))
        return tau ** 2 + np.maximum(sc ** 2 - 1.0, 0.0) * s ** 2

    def common_sigma_deg(self, stat_sigma_deg, spheres=None) -> float:
        """Per-axis standard deviation (degrees) of the common mode of a direction made from these
        spheres (module docstring, part 3).

        The bound ``rho / (1 - rho)`` times the systematic variance of the spheres
        (:meth:`systematic_var_deg2`) averaged with the spheres' inverse variances under this
        model (:meth:`sphere_sigma_deg`: the information each carries), plus
        ``common_floor_deg``. Equal spheres give the capture-wide bound; among unequal ones a
        sphere the model finds uninformative (a mirror ball whose highlight is uncertain by
        degrees beside a precise matte ball) cannot set the bound of the error they share. With
        ``common_ratio`` None, the fixed ``common_deg``.

        Parameters
        ----------
        stat_sigma_deg : float or (k,) float
            The spheres' statistical per-axis standard deviations (degrees).
        spheres : int or (k,) int, optional
        """
        if self.common_ratio is None:
            return float(self.common_deg)
        s = np.atleast_1d(np.asarray(stat_sigma_deg, dtype=np.float64))
        idx = None if spheres is None else np.atleast_1d(spheres)
        w = _weights(self.sphere_sigma_deg(s, idx) ** 2)
        if w is None:
            return float("inf")
        u = self.shared_var_deg2(s, idx)
        return float(np.sqrt(self.common_ratio * float(np.sum(w * u)) + self.common_floor_deg ** 2))

    def photo_sigma_deg(self, stat_sigma_deg, spheres=None, weights=None) -> float:
        """Per-axis standard deviation (degrees) of a photo's direction from its used spheres.

        The weighted mean of the spheres (variances :meth:`sphere_sigma_deg`) plus the common
        mode. With the ``weights`` the photo's direction was combined with, its variance is
        ``sum w_k^2 v_k``; without, the inverse-variance mean's ``1 / sum 1/v_k`` (the smallest
        possible: it understates a combination made with other weights).

        Parameters
        ----------
        stat_sigma_deg : (k,) float
            The used spheres' statistical per-axis standard deviations (degrees).
        spheres : (k,) int, optional
            Their indices (for their centre terms).
        weights : (k,) float, optional
            The combination's weights of these spheres (normalised here).
        """
        stat, idx, v, w = self._combination(stat_sigma_deg, spheres, weights)
        if w is None:
            return float("inf")
        return float(np.sqrt(np.sum(w * w * v) + self.common_sigma_deg(stat, idx) ** 2))

    def _combination(self, stat_sigma_deg, spheres, weights):
        """``(stat, idx, v, w)``: the spheres' statistics and indices as arrays, their variances
        under this model and the combination's normalised weights (None when not finite)."""
        stat = np.atleast_1d(np.asarray(stat_sigma_deg, dtype=np.float64))
        idx = None if spheres is None else np.atleast_1d(spheres)
        v = self.sphere_sigma_deg(stat, idx) ** 2
        return stat, idx, v, _weights(v, weights)

    def budget(self, stat_sigma_deg, spheres=None, weights=None) -> dict:
        """The terms of a photo's cone (:meth:`photo_sigma_deg`), each a per-axis standard deviation
        (degrees) of the photo's weighted mean, so that ``sigma_deg`` is their root sum of squares.

        Parameters
        ----------
        stat_sigma_deg : (k,) float
            The used spheres' statistical per-axis standard deviations (degrees).
        spheres : (k,) int, optional
            Their indices (for their centre terms).
        weights : (k,) float, optional
            The combination's weights (normalised here); the inverse variances under this model
            when omitted.

        Returns
        -------
        dict
            ``fit_deg`` (the fit statistics scaled by ``s``: ``sqrt(sum w^2 s^2 sigma^2)``),
            ``centre_deg`` (the centres' terms ``g``), ``floor_deg`` (the per-sphere floor
            ``tau``), ``common_deg`` (the common-mode bound, its floor included),
            ``common_floor_deg``, ``sigma_deg`` (:meth:`photo_sigma_deg`), ``cone_factor`` and
            ``cone_deg`` (:meth:`cone_deg` of ``sigma_deg``). Infinite terms where the spheres'
            variances are not finite.
        """
        stat, idx, v, w = self._combination(stat_sigma_deg, spheres, weights)
        common_floor = float(self.common_floor_deg) if self.common_ratio is not None else 0.0
        if w is None:
            inf = float("inf")
            return {"fit_deg": inf, "centre_deg": inf, "floor_deg": inf, "common_deg": inf,
                    "common_floor_deg": common_floor, "sigma_deg": inf, "cone_factor": float(self.cone_factor),
                    "cone_deg": inf}
        g = np.zeros(stat.shape) if idx is None else self.centre_sigma_deg(idx).reshape(stat.shape)
        sc, tau = self.terms(idx, stat.shape)
        w2 = w * w
        common = float(self.common_sigma_deg(stat, idx))
        sigma = np.sqrt(np.sum(w2 * v) + common ** 2)  # photo_sigma_deg's, without computing v and w again
        return {"fit_deg": float(np.sqrt(np.sum(w2 * (sc * stat) ** 2))),
                "centre_deg": float(np.sqrt(np.sum(w2 * g * g))),
                "floor_deg": float(np.sqrt(np.sum(w2 * tau * tau))),
                "common_deg": common, "common_floor_deg": common_floor,
                "sigma_deg": float(sigma), "cone_factor": float(self.cone_factor),
                "cone_deg": float(self.cone_deg(sigma))}

    @classmethod
    def from_dict(cls, doc: dict) -> "ErrorModel":
        """The model :meth:`as_dict` wrote (``lights.json``'s ``uncertainty``).

        Parameters
        ----------
        doc : dict

        Returns
        -------
        ErrorModel
        """
        ratio = doc.get("common_ratio")
        return cls(scale=float(doc["scale"]), floor_deg=float(doc["floor_deg"]), common_deg=float(doc["common_deg"]),
                   source=str(doc["source"]), n_photos=int(doc.get("n_photos", 0)),
                   n_trimmed=int(doc.get("n_trimmed", 0)),
                   centre_deg=tuple(float(x) for x in doc.get("centre_deg", ())),
                   cone_factor=float(doc.get("cone_factor", CONE_FACTOR)), n_tail=int(doc.get("n_tail", 0)),
                   common_ratio=None if ratio is None else float(ratio),
                   common_floor_deg=float(doc.get("common_floor_deg", COMMON_FLOOR_DEG)),
                   distance_sigma=float(doc.get("distance_sigma", 0.0)),
                   sphere_kinds=tuple(str(k) for k in doc.get("sphere_kinds", ())),
                   kind_terms=tuple((str(k), float(t["scale"]), float(t["floor_deg"]), int(t.get("n_photos", 0)))
                                    for k, t in (doc.get("kinds") or {}).items()),
                   sphere_floor_deg=tuple(float(x) for x in doc.get("sphere_floor_deg", ())))

    def with_mirrors_own_floor(self, sphere_kinds) -> "ErrorModel":
        """This (fallback) model with each mirror sphere's own terms: scale 1 and no added floor.

        :data:`FALLBACK_FLOOR_DEG` stands for a shading fit's unmeasured misfit (the bounce, the
        ambient, the encoding); a mirror's highlight carries its own floors and its outline's
        uncertainty (:func:`ffls.spheres.highlight.highlight_direction_Mudge2006`), so a lone mirror
        ball's cone is those alone, with the common floor (``docs/spheres.md``, "A lone mirror
        ball's own cone"). Other spheres keep the shared terms.

        Parameters
        ----------
        sphere_kinds : sequence of str
            Per sphere, its kind (``'matte'``, ``'mirror'``).
        """
        kinds = tuple(str(k) for k in sphere_kinds)
        if "mirror" not in kinds:
            return self
        own = tuple(t for t in self.kind_terms if t[0] != "mirror") + (("mirror", 1.0, 0.0, 0),)
        return replace(self, sphere_kinds=kinds, kind_terms=own)

    def with_shared_floor(self, shared_deg: float) -> "ErrorModel":
        """This model with a measured turn its spheres share, ``shared_deg`` per axis, added in
        quadrature to its common floor, and so to its ``common_deg`` summary (the floor is in
        every bound :meth:`common_sigma_deg` gives, as in the summary).

        Parameters
        ----------
        shared_deg : float
            Per-axis standard deviation (degrees), e.g. an unapplied lens gradient's turn.
        """
        shared = float(shared_deg)
        return replace(self, common_floor_deg=float(np.hypot(self.common_floor_deg, shared)),
                       common_deg=float(np.hypot(self.common_deg, shared)))

    def with_centres(self, centre_deg) -> "ErrorModel":
        """This model with per-sphere centre terms ``centre_deg`` (degrees per axis), e.g. for the fallback."""
        return replace(self, centre_deg=tuple(float(x) for x in np.atleast_1d(centre_deg)))

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {"scale": float(self.scale), "floor_deg": float(self.floor_deg), "common_deg": float(self.common_deg),
                "centre_deg": [float(x) for x in self.centre_deg],
                "source": self.source, "n_photos": int(self.n_photos), "n_trimmed": int(self.n_trimmed),
                "cone_factor": float(self.cone_factor), "n_tail": int(self.n_tail), "confidence": CONFIDENCE,
                "common_ratio": None if self.common_ratio is None else float(self.common_ratio),
                "common_floor_deg": float(self.common_floor_deg),
                "distance_sigma": float(self.distance_sigma),
                "sphere_kinds": list(self.sphere_kinds),
                "kinds": {k: {"scale": float(sk), "floor_deg": float(tk), "n_photos": int(n)}
                          for k, sk, tk, n in self.kind_terms},
                "sphere_floor_deg": [float(x) for x in self.sphere_floor_deg]}


def _weights(v: np.ndarray, weights=None) -> np.ndarray | None:
    """Normalised combination weights of spheres with variances ``v``: ``weights`` where usable,
    else the inverse variances; None where ``v`` is empty or not finite."""
    v = np.atleast_1d(np.asarray(v, dtype=np.float64))
    if v.size == 0 or not np.all(np.isfinite(v)):
        return None
    w = None if weights is None else np.atleast_1d(np.asarray(weights, dtype=np.float64))
    if w is None or w.size != v.size or not (np.all(np.isfinite(w)) and np.all(w >= 0) and w.sum() > 0):
        w = 1.0 / np.maximum(v, 1e-300)
    return w / w.sum()


def centre_floor_deg(shift_px, radius_px) -> float:
    """Per-axis standard deviation (degrees) of a sphere's direction from its centre's uncertainty.

    A sphere's centre has two independent estimates: its outline (the detection) and its shading
    (the photometric refinement, :mod:`ffls.spheres.refine`). Their difference ``shift_px`` has,
    per axis, the variance of both estimates' errors; taking them equal, each has a per-axis
    standard deviation of ``|shift| / 2`` pixels (the 2-D length of a difference of two isotropic
    errors of per-axis sd ``sigma`` has root mean square ``2 sigma``). A centre off by ``e``
    pixels turns every normal by ``e / r_px`` radians (to first order), and so the fitted light
    direction: the direction's per-axis standard deviation is ``|shift| / (2 r_px)``. This is
    systematic (the same in every photo), so it is not averaged over pixels or photos.

    Parameters
    ----------
    shift_px : (2,) float or float
        The refinement's centre shift (pixels), or its length.
    radius_px : float
        The sphere's radius in pixels.

    Returns
    -------
    float
        0 when either is not finite or the radius not positive.
    """
    d = float(np.linalg.norm(np.atleast_1d(np.asarray(shift_px, dtype=np.float64))))
    r = float(radius_px)
    if not (np.isfinite(d) and np.isfinite(r) and r > 0):
        return 0.0
    return float(np.degrees(0.5 * d / r))


def _ratio(correlation: float) -> float:
    """``rho / (1 - rho)`` of a correlation bound (clipped to [0, 0.99])."""
    rho = float(np.clip(correlation, 0.0, 0.99))
    return rho / (1.0 - rho)


def common_mode_deg(systematic_var_deg2: float, correlation: float = COMMON_CORRELATION,
                    floor_deg: float = COMMON_FLOOR_DEG) -> float:
    """Per-axis bound (degrees) of the common-mode error (module docstring, part 3).

    Parameters
    ----------
    systematic_var_deg2 : float
        Per-axis variance (degrees squared) of one sphere's systematic error that the spheres do
        not share.
    correlation : float
        Bound of the correlation between two spheres' systematic errors, in [0, 1).
    floor_deg : float
        Added in quadrature.

    Returns
    -------
    float
    """
    rho = float(np.clip(correlation, 0.0, 0.99))
    return float(np.sqrt(rho / (1.0 - rho) * max(float(systematic_var_deg2), 0.0) + floor_deg ** 2))


def _fallback() -> ErrorModel:
    # no disagreement to measure: the statistics as they are, plus the stated floor (RMS -> per
    # axis) and its common-mode share
    tau = FALLBACK_FLOOR_DEG / np.sqrt(2.0)
    return ErrorModel(scale=1.0, floor_deg=tau, common_deg=common_mode_deg(tau * tau), source="fallback",
                      common_ratio=_ratio(COMMON_CORRELATION))


#: The single-sphere model (no disagreement to measure): statistics plus ``FALLBACK_FLOOR_DEG``.
FALLBACK_MODEL = _fallback()


def halves_error_model(residuals: list[np.ndarray], stat_sigma_deg: list[np.ndarray], centre_deg=None, *,
                       common_correlation: float = COMMON_CORRELATION, min_photos: int = 3) -> ErrorModel:
    """A lone sphere's error model from the disagreement of its two halves (module docstring, "one sphere").

    With one sphere per photo no other sphere checks it, but the two halves of its pixels (either
    side of a plane through its light, :func:`ffls.spheres.estimate.halves_offsets`) are two fits of
    the same light with their own pixels' noise and their own share of the model's misfit (light the
    model leaves out, a blurred or darkened limb, an unmodelled shading pattern). Their offsets
    from the sphere's direction are fitted as two spheres' (:func:`fit_error_model`: the halves'
    scale ``s``, floor ``tau``, cone factor and common-mode bound), and the sphere's direction is,
    to first order, the mean of its halves': its per-axis floor is ``tau / sqrt(2)`` (its
    statistics, about those of a half over ``sqrt(2)``, keep the scale), and the common-mode bound,
    stated on a half's systematic variance, is twice the mean's (``common_ratio`` doubled). The
    centre term ``g`` is the sphere's (a centre error turns both halves alike, so it is not in
    their disagreement). The cone factor is the halves' own quantile where their tails are heavier
    than the Gaussian's, never less than :data:`CONE_FACTOR`: the cone also holds what the halves
    share and cannot show (the centre, the common mode), whose tails nothing measures (a lone
    orthographic grey ball turned 0.21 degrees alike in both halves: the halves' factor 2.10 covered
    86.8% of its photos, the Gaussian's 97.4%, ``docs/spheres.md``). Too few photos with both
    halves fitted: :data:`FALLBACK_MODEL`.

    Parameters
    ----------
    residuals : list of (2, 2) float
        Per photo, its halves' tangent offsets (radians) from the sphere's direction.
    stat_sigma_deg : list of (2,) float
        The halves' statistical per-axis standard deviations (degrees).
    centre_deg : (n_spheres,) float, optional
        Per sphere, its centre term (:func:`centre_floor_deg`).
    common_correlation : float
    min_photos : int

    Returns
    -------
    ErrorModel
        ``source`` ``'halves'`` (or the fallback's).
    """
    centre = np.zeros(0) if centre_deg is None else np.asarray(centre_deg, dtype=np.float64)
    halves = fit_error_model(residuals, stat_sigma_deg, common_correlation=common_correlation,
                             min_photos=min_photos)
    if halves.source != "disagreement":
        return FALLBACK_MODEL.with_centres(centre)
    return replace(halves, floor_deg=float(halves.floor_deg / np.sqrt(2.0)), common_ratio=2.0 * halves.common_ratio,
                   source="halves", centre_deg=tuple(float(x) for x in centre),
                   cone_factor=max(float(halves.cone_factor), CONE_FACTOR))


def tail_factor(residuals: list[np.ndarray], variances: list[np.ndarray], confidence: float = CONFIDENCE,
                min_samples: int = MIN_TAIL_SAMPLES) -> tuple[float, int]:
    """Radius of the capture's own ``confidence`` cone, in per-axis standard deviations.

    In each photo with ``k >= 2`` spheres, sphere ``i``'s tangent offset ``r_i`` is compared with
    the inverse-variance mean of the photo's *other* spheres (leave one out, so the two are
    independent): ``d_i = r_i - sum_{j != i} w_j r_j`` has per-axis variance
    ``u_i = v_i + sum_{j != i} w_j^2 v_j`` under the model, and ``|d_i| / sqrt(u_i)`` is a draw of
    the radius of a standardised 2-D error. Under a Gaussian model its ``confidence`` quantile is
    ``sqrt(chi2.ppf(confidence, 2))`` (:data:`CONE_FACTOR` at 95%); the empirical quantile of the
    draws measures the tails of the capture's actual errors instead (lighter for bounded
    systematic errors, heavier for a misfit that grows toward the rim). The offsets of one photo
    are correlated (for ``k = 2`` they are one offset twice), so ``min_samples`` counts draws,
    not independent ones.

    Parameters
    ----------
    residuals : list of (k_j, 2) float
        Per photo, its spheres' tangent offsets from the photo's light (:func:`tangent_residuals`).
    variances : list of (k_j,) float
        Their per-axis variances under the model (same unit squared).
    confidence : float
    min_samples : int
        Fewer draws give the Gaussian factor.

    Returns
    -------
    factor : float
        The quantile, or ``sqrt(chi2.ppf(confidence, 2))`` with too few draws.
    n : int
        The draws used (0 with too few).
    """
    from scipy.special import chdtri
    gauss = float(np.sqrt(chdtri(2, 1.0 - confidence)))
    z = []
    for r, v in zip(residuals, variances):
        r = np.asarray(r, dtype=np.float64).reshape(-1, 2)
        v = np.asarray(v, dtype=np.float64).ravel()
        k = r.shape[0]
        if k < 2 or v.size != k or not (np.all(np.isfinite(r)) and np.all(np.isfinite(v)) and np.all(v > 0)):
            continue
        w = 1.0 / v
        others = ~np.eye(k, dtype=bool)  # row i: the spheres other than i
        wo = np.where(others, w[None, :], 0.0)
        wo = wo / wo.sum(axis=1, keepdims=True)
        d = r - wo @ r
        u = v + (wo * wo) @ v
        z.append(np.sqrt(np.sum(d * d, axis=1) / u))
    z = np.concatenate(z) if z else np.zeros(0)
    if z.size < max(int(min_samples), 1):
        return gauss, 0
    return float(np.quantile(z, confidence)), int(z.size)


def _restricted_terms(v, R, starts, photo_of):
    """Per photo, -2 log restricted likelihood and chi-square of its spheres' scatter.

    ``R`` (n, 2) the stacked tangent offsets, ``v`` (n,) their per-axis variances, ``starts`` each
    photo's first row and ``photo_of`` each row's photo (:func:`fit_error_model`)."""
    w = 1.0 / v
    sw = np.add.reduceat(w, starts)
    mu = np.add.reduceat(w[:, None] * R, starts) / sw[:, None]
    chi = np.add.reduceat(w * np.sum((R - mu[photo_of]) ** 2, axis=1), starts)
    return 2.0 * np.add.reduceat(np.log(v), starts) + 2.0 * np.log(sw) + chi, chi


def unchecked_floor_deg(residuals: list[np.ndarray], variances: list[np.ndarray], spheres: list[np.ndarray],
                        n_spheres: int, confidence: float = CONFIDENCE,
                        cap_deg: float | None = None) -> np.ndarray:
    """Per sphere, a floor (per axis, degrees) where the disagreement cannot measure its own.

    A floor added to one sphere shows in its photos' scatter only as far as the photos' other
    spheres are as certain: beside a matte ball, a chrome ball's highlight uncertain by a degree
    explains all their disagreement, and the fit puts the matte ball's floor near 0 whatever it
    is (the calibration shot of ``docs/spheres.md``). For each sphere, an extra per-axis variance
    ``a^2`` added to it alone (the others at the fitted model) is profiled in the restricted
    likelihood of the photos, and its one-sided ``confidence`` upper bound ``a_up`` taken (where
    ``-2 log L`` has risen ``chi2.ppf(2 confidence - 1, 1)`` above its least value). Where ``a_up``
    is above the sphere's own standard deviation under the model (the median over its photos), the
    disagreement cannot tell its variance from twice its variance: the floor is not measured, and
    the sphere gets ``min(a_up, cap_deg)``. Elsewhere 0 (the fitted floor stands).

    Parameters
    ----------
    residuals : list of (k_j, 2) float
        Per photo, its spheres' tangent offsets (radians).
    variances : list of (k_j,) float
        Their per-axis variances under the fitted model (radians squared).
    spheres : list of (k_j,) int
        Their sphere indices.
    n_spheres : int
    confidence : float
    cap_deg : float, optional
        The most a floor is raised to (the fallback's per-axis floor, :data:`FALLBACK_MODEL`, when
        omitted: a sphere no other checks gets at most what a lone sphere gets).

    Returns
    -------
    (n_spheres,) float
    """
    from scipy.optimize import brentq
    from scipy.special import chdtri
    cap = np.radians(FALLBACK_MODEL.floor_deg if cap_deg is None else float(cap_deg))
    out = np.zeros(int(n_spheres))
    if not residuals:
        return out
    k = np.array([np.asarray(r).reshape(-1, 2).shape[0] for r in residuals])
    R = np.concatenate([np.asarray(r, dtype=np.float64).reshape(-1, 2) for r in residuals])
    V = np.concatenate([np.asarray(v, dtype=np.float64).ravel() for v in variances])
    I = np.concatenate([np.asarray(i, dtype=np.intp).ravel() for i in spheres])
    photo_of = np.repeat(np.arange(len(k)), k)
    rise = float(chdtri(1, 2.0 * (1.0 - confidence)))
    a_grid = np.concatenate([[0.0], np.geomspace(1e-3 * np.sqrt(np.min(V)), np.radians(30.0), 160)])
    for i in range(int(n_spheres)):
        mine = I == i
        if not mine.any():
            continue
        rows = np.unique(photo_of[mine])
        sub = np.isin(photo_of, rows)
        Rs, Vs, ms = R[sub], V[sub], mine[sub]
        ks = np.bincount(photo_of[sub])[rows]
        st = np.concatenate([[0], np.cumsum(ks)[:-1]])
        po = np.repeat(np.arange(rows.size), ks)

        def f(a):
            return float(np.sum(_restricted_terms(Vs + a * a * ms, Rs, st, po)[0]))

        prof = np.array([f(a) for a in a_grid])
        j0 = int(np.argmin(prof))
        above = np.flatnonzero(prof[j0:] >= prof[j0] + rise)
        if above.size:
            j = j0 + int(above[0])
            a_up = brentq(lambda a: f(a) - prof[j0] - rise, a_grid[j - 1], a_grid[j], xtol=1e-9)
        else:
            a_up = np.inf
        if a_up * a_up > np.median(Vs[ms]):
            out[i] = np.degrees(min(a_up, cap))
    return out


def fit_error_model(residuals: list[np.ndarray], stat_sigma_deg: list[np.ndarray], *,
                    common_correlation: float = SPHERES_CORRELATION, min_photos: int = 3,
                    fit_scale: bool = True, trim: float = TRIM_SIGNIFICANCE, max_rounds: int = 4,
                    spheres: list[np.ndarray] | None = None, centre_deg=None, kinds=None) -> ErrorModel:
    """The capture's error model from its spheres' disagreement (module docstring, parts 2 and 3).

    Parameters
    ----------
    residuals : list of (k_j, 2) float
        Per photo with ``k_j >= 2`` used spheres, their tangent-plane offsets (radians) from the
        directions the photo's light predicts at each sphere (:func:`tangent_residuals`).
    stat_sigma_deg : list of (k_j,) float
        The spheres' statistical per-axis standard deviations (degrees).
    common_correlation : float
        Bound of the correlation between two spheres' systematic errors (the common mode's share
        of their systematic variance, beside the floor): :data:`SPHERES_CORRELATION`, 0, for a
        photo's spheres; a lone sphere's halves pass :data:`COMMON_CORRELATION`.
    min_photos : int
        Fewer usable photos give :data:`FALLBACK_MODEL`.
    fit_scale : bool
        Fit the scale ``s`` with the floor ``tau`` (else ``s = 1``).
    trim : float
        Photos whose scatter has a chi-square probability below ``trim / n_photos`` under the
        fitted model (a family-wise level, Bonferroni) are left out, and the model refitted (up
        to ``max_rounds`` times). A per-photo level (no correction) trimmed 5-17% of the photos
        of ffls synth captures whose systematic errors are heavier-tailed than the Gaussian
        model, and so shrank the floor it estimates: cones 30-50% too narrow.
    max_rounds : int
    spheres : list of (k_j,) int, optional
        Per photo, the indices of its used spheres (for ``centre_deg``).
    centre_deg : (n_spheres,) float, optional
        Per sphere, the per-axis standard deviation (degrees) its centre's uncertainty gives its
        direction (:func:`centre_floor_deg`): a known variance component of each sphere, so
        that ``tau`` is what remains beyond it.
    kinds : (n_spheres,) str, optional
        Per sphere, its kind (``'matte'``, ``'mirror'``), with ``spheres``. A kind whose spheres
        disagree among themselves (two or more of them used) in at least ``min_photos`` kept photos
        gets its own scale and floor, fitted (restricted maximum likelihood again, on the same
        kept photos) with the other spheres at the shared fit's: a mirror's highlight and a
        matte ball's shading err differently, and one scale and floor for both let either set
        the other's cone (a chrome ball's larger sigma moved a grey ball's floor from 0.03 to 4.4
        degrees, ``docs/spheres.md``). A capture of one kind, or without enough of any, keeps
        the shared fit alone.

    Returns
    -------
    ErrorModel
        With ``centre_deg`` (also the fallback, where too few photos have 2+ spheres) and the
        capture's own cone factor (:func:`tail_factor` on the kept photos).
    """
    from scipy.optimize import minimize
    from scipy.special import chdtrc
    centre = np.zeros(0) if centre_deg is None else np.asarray(centre_deg, dtype=np.float64)
    centre_rad2 = np.radians(np.nan_to_num(centre)) ** 2
    data, index = [], []
    for j, (r, s) in enumerate(zip(residuals, stat_sigma_deg)):
        r = np.asarray(r, dtype=np.float64).reshape(-1, 2)
        s = np.radians(np.asarray(s, dtype=np.float64).ravel())
        g2 = np.zeros(s.size)
        idx = np.full(s.size, -1, dtype=np.intp)
        if spheres is not None and np.asarray(spheres[j]).size == s.size:
            idx = np.asarray(spheres[j], dtype=np.intp).ravel()
            if centre.size:
                g2 = np.where(idx < centre.size, centre_rad2[np.minimum(idx, centre.size - 1)], 0.0)
        if r.shape[0] >= 2 and r.shape[0] == s.size and np.all(np.isfinite(r)) and np.all(np.isfinite(s)) \
                and np.all(s > 0):
            data.append((r, s * s, g2))
            index.append(idx)
    if len(data) < min_photos:
        return FALLBACK_MODEL.with_centres(centre)
    keep = np.ones(len(data), dtype=bool)
    med_sigma = float(np.sqrt(np.median(np.concatenate([s2 for _, s2, _ in data]))))
    x0 = np.array([0.0, np.log(max(med_sigma, 1e-6))])  # log s, log tau (radians); every round starts here
    x = x0
    lo = np.array([np.log(0.2) if fit_scale else 0.0, np.log(1e-5)])
    hi = np.array([np.log(50.0) if fit_scale else 0.0, np.log(np.radians(30.0))])

    # all photos' spheres stacked, with segment sums per photo (one vector pass per evaluation)
    k_all = np.array([r.shape[0] for r, _, _ in data])
    starts = np.concatenate([[0], np.cumsum(k_all)[:-1]])
    R_all = np.concatenate([r for r, _, _ in data])
    S2_all = np.concatenate([s2 for _, s2, _ in data])
    G2_all = np.concatenate([g2 for _, _, g2 in data])
    photo_of = np.repeat(np.arange(len(data)), k_all)

    def var_of(ls, lt):
        """The spheres' variances under log scale ``ls`` and log floor ``lt`` (each one value, or one per sphere)."""
        return np.exp(2.0 * ls) * S2_all + G2_all + np.exp(2.0 * lt)

    def terms(x):
        """Per photo: -2 log restricted likelihood and chi-square of the scatter."""
        return terms_of(var_of(x[0], x[1]))

    def terms_of(v):
        """:func:`terms` of the spheres' variances ``v``."""
        return _restricted_terms(v, R_all, starts, photo_of)

    def objective(x, subset):
        return float(np.sum(terms(x)[0][subset]))

    # the likelihood has two basins (the disagreement as a scale of the statistics, or as a floor
    # beside them): start from the best node of a coarse grid over the box, not from one point
    grid = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], START_GRID if fit_scale else 1),
                                np.linspace(lo[1], hi[1], START_GRID), indexing="ij"), axis=-1).reshape(-1, 2)

    def start_nodes(f_grid):
        """The profile of the objective ``f_grid`` (one per node of ``grid``) over the scale nodes,
        each with its best floor node: that best node at each of its local minima, one in each basin
        the grid can separate."""
        f_grid = np.asarray(f_grid).reshape(-1, START_GRID)
        prof = f_grid.min(axis=1)
        padded = np.concatenate([[np.inf], prof, [np.inf]])
        rows = np.flatnonzero((prof <= padded[:-2]) & (prof <= padded[2:]))
        return [grid.reshape(-1, START_GRID, 2)[i, int(np.argmin(f_grid[i]))] for i in rows]

    for _ in range(max_rounds):
        if keep.sum() < min_photos:
            break
        starts_x = [np.clip(x0, lo, hi)] + start_nodes([objective(g, keep) for g in grid])
        fits = [minimize(objective, s0, args=(keep,), method="L-BFGS-B", bounds=list(zip(lo, hi)))
                for s0 in starts_x]
        x = min(fits, key=lambda f: f.fun).x
        p = chdtrc(2 * (k_all - 1), terms(x)[1])
        new_keep = p >= trim / len(data)  # family-wise (Bonferroni): a wild photo, not the model's tail
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    n_trimmed = int((~keep).sum())
    scale, tau = float(np.exp(x[0])), float(np.exp(x[1]))
    # per kind: its own scale and floor where its spheres disagree among themselves in enough photos
    I_all = np.concatenate(index)
    kind_names = tuple(str(k) for k in (kinds if kinds is not None else ()))
    kind_of = np.array([kind_names[i] if 0 <= i < len(kind_names) else "" for i in I_all], dtype=object)
    counts = {kd: np.add.reduceat((kind_of == kd).astype(np.intp), starts) for kd in set(kind_of) - {""}}
    own = sorted(kd for kd, n in counts.items() if int(np.sum((n >= 2) & keep)) >= min_photos)
    var_all = var_of(x[0], x[1])
    kind_terms = ()
    if own and set(kind_of) != {own[0]}:  # one kind alone: the shared fit is its own
        group = np.array([own.index(kd) + 1 if kd in own else 0 for kd in kind_of])
        n_own = len(own)

        def kind_var(y):
            ls = np.concatenate([[x[0]], y[0::2]])[group]
            lt = np.concatenate([[x[1]], y[1::2]])[group]
            return var_of(ls, lt)

        def kind_objective(y):
            return float(np.sum(terms_of(kind_var(y))[0][keep]))

        # each kind's starts: the local minima of its grid profile, the other kinds at the shared fit
        y_shared = np.tile(x, n_own)
        candidates = []
        for j in range(n_own):
            f = []
            for g in grid:
                y = y_shared.copy()
                y[2 * j:2 * j + 2] = g
                f.append(kind_objective(y))
            candidates.append([x] + start_nodes(f))
        from itertools import product
        bounds = list(zip(np.tile(lo, n_own), np.tile(hi, n_own)))
        fits = [minimize(kind_objective, np.concatenate(c), method="L-BFGS-B", bounds=bounds)
                for c in product(*candidates)]
        y = min(fits, key=lambda f: f.fun).x
        var_all = kind_var(y)
        kind_terms = tuple((kd, float(np.exp(y[2 * j])), float(np.degrees(np.exp(y[2 * j + 1]))),
                            int(np.sum((counts[kd] >= 2) & keep))) for j, kd in enumerate(own))
    # the systematic per-sphere variance: the floor, plus what the scale adds beyond the statistics
    s2_med = float(np.median(np.concatenate([s2 for (_, s2, _), k in zip(data, keep) if k] or [np.zeros(1)])))
    sys_var = tau * tau + max(scale * scale - 1.0, 0.0) * s2_med  # shared_var_deg2: no centre term
    common = common_mode_deg(float(np.degrees(np.sqrt(sys_var))) ** 2, common_correlation)
    # the cone's radius from the capture's own standardised leave-one-out offsets (kept photos)
    var_photo = np.split(var_all, np.cumsum(k_all)[:-1])
    factor, n_tail = tail_factor([r for (r, _, _), k in zip(data, keep) if k],
                                 [v for v, k in zip(var_photo, keep) if k])
    # a sphere whose floor the disagreement cannot measure (the others of its photos far less
    # certain) gets a floor bounded by the profile likelihood, not the fit's near-zero one
    kept = [j for j in np.flatnonzero(keep) if np.all(index[j] >= 0)]
    n_spheres = max((int(index[j].max()) + 1 for j in kept), default=0)
    lifted = unchecked_floor_deg([data[j][0] for j in kept], [var_photo[j] for j in kept],
                                 [index[j] for j in kept], n_spheres)
    return ErrorModel(scale=scale, floor_deg=float(np.degrees(tau)), common_deg=common,
                      sphere_floor_deg=tuple(float(f) for f in lifted) if np.any(lifted > 0) else (),
                      source="disagreement", n_photos=int(keep.sum()), n_trimmed=n_trimmed,
                      centre_deg=tuple(float(x) for x in centre), cone_factor=factor, n_tail=n_tail,
                      common_ratio=_ratio(common_correlation),
                      sphere_kinds=kind_names if kind_terms else (), kind_terms=kind_terms)


def photo_residuals(directions: np.ndarray, light_direction: np.ndarray, position: np.ndarray | None = None,
                    centers: np.ndarray | None = None) -> np.ndarray:
    """Tangent offsets (radians) of a photo's sphere directions from what its light predicts.

    A distant light predicts its direction at every sphere; a near light at ``position`` predicts
    ``normalize(position - center_i)``.

    Parameters
    ----------
    directions : (k, 3) float, unit
        The used spheres' fitted directions.
    light_direction : (3,) float, unit
    position : (3,) float, optional
        The near light's position (world).
    centers : (k, 3) float, optional
        The used spheres' centres (world), with ``position``.

    Returns
    -------
    (k, 2) float
    """
    d = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    if position is not None and centers is not None and np.all(np.isfinite(position)):
        pred = normalize(np.asarray(position, dtype=np.float64)[None, :] - np.atleast_2d(centers))
    else:
        pred = np.repeat(normalize(np.asarray(light_direction, dtype=np.float64))[None, :], len(d), axis=0)
    return tangent_residuals(d, pred)


# ----------------------------------------------------------------------------- type B: fitted parameters
def shading_shift(normals: np.ndarray, direction: np.ndarray, dvalues: np.ndarray, terminator: float = 0.15,
                  ambient: bool = True) -> np.ndarray:
    """Shift of a matte sphere's fitted direction when its pixel values change by ``dvalues``.

    The sensitivity ``d(direction) / d(parameter)`` of a shared, fitted parameter of the capture
    (the encoding's exponent, a ground ratio; a GUM "type B" propagation, JCGM 100:2008 section
    5.1) by linearisation: on the lit pixels (``n . l > terminator``) the shading is linear in
    ``m = a l`` and the ambient ``b`` (columns ``[n, 1]``), so a change ``dv`` of the values moves
    the least-squares solution by ``(A^T A)^-1 A^T dv`` (Gauss-Newton, exact to first order), and
    the direction by the part of ``dm / a`` across ``l``. ``dvalues`` is in units of the light's
    coefficient ``a`` (the shading of a sphere lit with ``a = 1``).

    Parameters
    ----------
    normals : (m, 3) float, unit
        The sphere's pixels' normals (world).
    direction : (3,) float, unit
        The sphere's fitted light direction.
    dvalues : (m,) float
        Change of each pixel's value per unit parameter, over ``a``.
    terminator : float
        Pixels with ``n . l`` at most this are left out (as the fit does).
    ambient : bool
        Fit an ambient column.

    Returns
    -------
    (3,) float
        The direction's shift (radians, a tangent vector at ``direction``) per unit parameter;
        zeros where fewer than 4 pixels are lit.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    l = normalize(np.asarray(direction, dtype=np.float64))
    dv = np.asarray(dvalues, dtype=np.float64).ravel()
    lit = (n @ l > terminator) & np.isfinite(dv)
    if lit.sum() < 4:
        return np.zeros(3)
    A = np.column_stack([n[lit], np.ones(int(lit.sum()))]) if ambient else n[lit]
    dm = np.linalg.lstsq(A, dv[lit], rcond=None)[0][:3]
    return dm - (dm @ l) * l


def encoding_perturbation(shading: np.ndarray) -> np.ndarray:
    """Change of linear values per unit relative change of a power-law encoding's exponent.

    Values decoded as ``v = code^gamma`` become ``v^(1 + e)`` with the exponent ``gamma (1 + e)``:
    ``dv / de = v ln v``. Scale-free: with ``v`` in other units the change differs by a multiple
    of ``v``, which the fit's intensity absorbs.

    Parameters
    ----------
    shading : (m,) float
        The modelled values (e.g. ``max(n . l, 0)`` plus the bounce, with ``a = 1``).

    Returns
    -------
    (m,) float
        0 where the value is not positive.
    """
    v = np.asarray(shading, dtype=np.float64)
    out = np.zeros(v.shape)
    pos = v > 0
    out[pos] = v[pos] * np.log(v[pos])
    return out


def bounce_perturbation(bounce_factor: np.ndarray, direction: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Change of values per unit change of a sphere's calibrated ground ratio ``rho_g``.

    The ground bounce of the calibrated model is ``rho_g a max(l . up, 0) g(n)``
    (:func:`ffls.spheres.estimate.calibrate_bounce`), so ``dv / d rho_g = max(l . up, 0) g(n)`` over ``a``.

    Parameters
    ----------
    bounce_factor : (m,) float
        ``g(n)``, the pixels' form factor to the ground.
    direction : (3,) float, unit
    up : (3,) float, unit

    Returns
    -------
    (m,) float
    """
    lz = max(float(np.asarray(direction, dtype=np.float64) @ np.asarray(up, dtype=np.float64)), 0.0)
    return lz * np.asarray(bounce_factor, dtype=np.float64)


def shared_parameter_deg(shifts: np.ndarray, weights, standard_error: float) -> float:
    """Per-axis standard deviation (degrees) of a photo's direction from one parameter all its spheres share.

    A shared parameter off by ``delta`` moves every sphere by ``delta`` times its shift, so the
    photo's weighted mean moves by ``delta sum_k w_k t_k``: a 2-D error along one axis, of
    variance ``|sum_k w_k t_k|^2 se^2``, written as a per-axis standard deviation (half that
    variance on each tangent axis). Such an error is the same on every sphere (a common mode), so
    the spheres' disagreement never shows it.

    Parameters
    ----------
    shifts : (k, 3) float
        Per used sphere, its direction's shift (radians) per unit parameter (:func:`shading_shift`).
    weights : (k,) float
        The combination's weights (normalised here).
    standard_error : float
        The parameter's standard error.

    Returns
    -------
    float
    """
    t = np.asarray(shifts, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(weights, dtype=np.float64).ravel()
    if t.shape[0] == 0 or w.size != t.shape[0] or not w.sum() > 0:
        return 0.0
    v = (w / w.sum()) @ t
    return float(np.degrees(np.linalg.norm(v) * abs(float(standard_error)) / np.sqrt(2.0)))


def own_parameter_deg(shifts: np.ndarray, weights, standard_errors) -> float:
    """Per-axis standard deviation (degrees) of a photo's direction from one parameter per sphere.

    Each sphere's own fitted parameter (its ground ratio) has an independent error: the photo's
    variance is ``sum_k w_k^2 |t_k|^2 se_k^2``, per axis half of it. Such an error differs from
    sphere to sphere, so the disagreement measures it already (part of the floor ``tau``).

    Parameters
    ----------
    shifts : (k, 3) float
    weights : (k,) float
    standard_errors : (k,) float

    Returns
    -------
    float
    """
    t = np.asarray(shifts, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(weights, dtype=np.float64).ravel()
    se = np.asarray(standard_errors, dtype=np.float64).ravel()
    if t.shape[0] == 0 or w.size != t.shape[0] or se.size != t.shape[0] or not w.sum() > 0:
        return 0.0
    w = w / w.sum()
    return float(np.degrees(np.sqrt(np.sum((w * np.linalg.norm(t, axis=1) * se) ** 2) / 2.0)))


# ----------------------------------------------------------------------------- a near light's distance
def distance_coupling_deg(v: np.ndarray, cov_v: np.ndarray) -> float:
    """How far a near light's direction moves with its distance's error, along the fit's coupling.

    A near light's position ``p`` is triangulated from the spheres; its direction is reported
    from the scene centre, ``v = p - c``. Where the spheres that place it stand off the centre
    (two matte balls of one row, the mirrors of the other row without a highlight), an error of
    the light's distance moves the position along the spheres' own ray, and so turns ``v``: the
    direction error is the distance error times the parallax. The fit's covariance ``cov_v``
    carries that coupling; its statistical size does not carry a systematic distance error
    (``docs/spheres.md``, "Near captures: the light's distance seen from the scene centre").
    The regression of the direction's tangent offset on the relative distance ``|v|``, under
    ``cov_v``, gives the expected turn per unit relative distance error:
    ``|E C u| / (u^T C u)`` with ``u = v / |v|`` and ``E`` the tangent basis at ``u``.

    Parameters
    ----------
    v : (3,) float
        The light's position from the scene centre.
    cov_v : (3, 3) float
        Its covariance (the joint fit's).

    Returns
    -------
    float
        Degrees per unit relative distance error (0 where the covariance is not finite or has
        no radial part).
    """
    v = np.asarray(v, dtype=np.float64)
    C = np.asarray(cov_v, dtype=np.float64)
    nv = float(np.linalg.norm(v))
    if not (np.isfinite(nv) and nv > 0 and C.shape == (3, 3) and np.all(np.isfinite(C))):
        return 0.0
    u = v / nv
    radial = float(u @ C @ u)
    if not radial > 0:
        return 0.0
    e1, e2 = tangent_basis(u)
    cu = C @ u
    return float(np.degrees(np.hypot(e1 @ cu, e2 @ cu) / radial))


def distance_spread(distances) -> float:
    """Relative 1-sigma spread of a capture's near lights' distances: ``1.4826 MAD`` of their logs.

    Of a rig whose lamps stand at one distance (a dome, the paper's gantry) it is the
    triangulation's own distance error; of hand-held lamps it is larger by their true spread, so
    the cones it widens (:meth:`ErrorModel.distance_sigma_deg`) are then wider than needed.

    Parameters
    ----------
    distances : (n,) float
        The near lights' distances from the scene centre.

    Returns
    -------
    float
        0 with fewer than 3 finite positive distances.
    """
    d = np.asarray(distances, dtype=np.float64).ravel()
    d = d[np.isfinite(d) & (d > 0)]
    if d.size < 3:
        return 0.0
    l = np.log(d)
    return float(1.4826 * np.median(np.abs(l - np.median(l))))
