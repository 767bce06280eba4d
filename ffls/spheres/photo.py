"""One light per photograph from its spheres: per-sphere fits, combination, rejection.

Masselus, Dutre, Anrys, "The Free-form Light Stage", EGWR 2002, section 5. Per photo
(:func:`estimate_photo`):

1. every sphere is fitted on its own (:func:`ffls.spheres.lambert.fit_lambert`: Lambert +
   ambient + ground bounce); a sphere far darker than the others is in a cast shadow;
2. the usable spheres' directions ``l_i`` (RMS uncertainties ``s_i``, a statistical part from the
   fit and a floor ``sigma_floor_deg`` for what the model does not capture) are explained by a
   distant or a near light (:mod:`ffls.spheres.combine`); ``model='auto'`` takes the near model
   only when its chi-square drop is significant (likelihood-ratio test, 1 degree of freedom,
   ``p < 1e-3``);
3. if the chosen model is inconsistent (``p < 1e-3``) and one sphere's removal makes it
   consistent, that sphere is dropped (``'outlier'``); otherwise the photo is rejected;
4. a near light's position is refined by the joint fit to all used spheres' pixels, each
   sphere's over its own residual deviation (:func:`ffls.spheres.combine.fit_near_light_mixed`),
   initialised from the ray intersection.

A sphere is matte or a mirror (chrome, black glossy): a mirror sphere's step 1 is its
highlight (:func:`ffls.spheres.highlight.fit_highlight`, the RTI highlight method), whose
direction and RMS uncertainty enter steps 2 and 3 like a matte sphere's; its near-light ray starts
at the highlight's reflection point. In the joint near fit (step 4) a mirror's ray is a residual
beside the matte spheres' pixels (:func:`ffls.spheres.combine.fit_near_light_mixed`), and the
position's covariance carries into the cone.

Rejection reasons (:data:`REASONS`) are short fixed strings stored in ``lights.json``.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace

import numpy as np

from ffls import conventions
from ffls.conventions import UP, normalize
from ffls.spheres.combine import combine_distant, fit_near_light_mixed, fit_ray_convergence
from ffls.spheres.highlight import HIGHLIGHT_STATUSES, HighlightFit, SphereView, fit_highlight_samples
from ffls.spheres.lambert import (LambertFit, fit_lambert, near_ground_bounce, shadowed_ground_bounce,
                                  tangent_uncertainty_deg)
from ffls.spheres.samples import SphereSamples, SphereValues, sphere_values
from ffls.spheres.uncertainty import FALLBACK_MODEL, ErrorModel, distance_coupling_deg

__all__ = ["REASONS", "LIGHT_MODELS", "OUTLIER", "SIGNIFICANCE", "SHADOW_RATIO", "SphereResult", "LightHypothesis", "PhotoEstimate",
           "fit_spheres", "sphere_uncertainty_deg", "ray_origins", "fit_light_model", "near_fit_mask",
           "estimate_photo", "usable_spheres"]

#: Rejection reasons of a photo (and of single spheres), with their meaning.
REASONS = {
    "too_dark": "too few lit, unsaturated pixels on the spheres (light off, or pointing away)",
    "saturated": "the lit part of the spheres is clipped",
    "shadowed": "the spheres are in a cast shadow (object, person) or much darker than the others",
    "spheres_disagree": "the spheres' directions are inconsistent beyond their uncertainty and no single "
                        "sphere explains it",
    "too_few_spheres": "fewer usable spheres than needed (min_spheres)",
    "fit_failed": "the shading fit did not converge to a finite direction",
    "no_highlight": HIGHLIGHT_STATUSES["no_highlight"],
    "highlight_at_rim": HIGHLIGHT_STATUSES["highlight_at_rim"],
    "dark": "the whole photo is far darker than the capture's others (a misfired flash, or the lamp off)",
}
#: Light models of :func:`estimate_photo`.
LIGHT_MODELS = ("auto", *conventions.LIGHT_MODELS)
#: Sphere status for a sphere dropped from the combination because it disagreed with the others.
OUTLIER = "outlier"
#: Significance level of the consistency and likelihood-ratio tests.
SIGNIFICANCE = 1e-3


@dataclass
class SphereResult:
    """One sphere in one photo: its own fit, and its status in the photo's combination.

    Attributes
    ----------
    fit : LambertFit or HighlightFit
        A matte sphere's shading fit or a mirror sphere's highlight; both have ``status``,
        ``direction``, ``uncertainty_deg`` (RMS) and ``as_dict``.
    status : str
        ``fit.status``, or ``'shadowed'`` / :data:`OUTLIER` where the combination set the sphere
        aside.
    uncertainty_deg : float or None
        Radius (degrees) of the 95% cone of this sphere's direction under the error model
        (:meth:`PhotoEstimate.with_error_model`); None where it has no direction.
    """

    fit: LambertFit | HighlightFit
    status: str
    uncertainty_deg: float | None = None

    @property
    def kind(self) -> str:
        """``'mirror'`` for a highlight fit, ``'matte'`` for a shading fit."""
        return "mirror" if isinstance(self.fit, HighlightFit) else "matte"

    @property
    def direction(self) -> np.ndarray | None:
        """The fitted direction (3,), or None where it is not finite."""
        d = self.fit.direction
        return None if d is None or not np.all(np.isfinite(d)) else np.asarray(d, dtype=np.float64)

    def as_dict(self) -> dict:
        """JSON-ready report: ``status`` and :meth:`LambertFit.as_dict` (without the pixel mask)."""
        cone = self.uncertainty_deg
        return {"status": self.status, "kind": self.kind,
                **{k: v for k, v in self.fit.as_dict().items() if k not in ("status", "kind", "uncertainty_deg")},
                "sigma_deg": float(self.fit.uncertainty_deg) if np.isfinite(self.fit.uncertainty_deg) else None,
                "uncertainty_deg": float(cone) if cone is not None and np.isfinite(cone) else None}


@dataclass
class LightHypothesis:
    """A light model fitted to some spheres' directions (:func:`estimate_photo`, step 2).

    Attributes
    ----------
    spheres : list of int
        The spheres used.
    model : {'distant', 'near'}
    direction : (3,) float, unit
    uncertainty_deg : float
        RMS uncertainty of the distant mean (the near model keeps it until the joint fit).
    chi2 : float
    dof : int
    position : (3,) float or None
        The near light's position (ray intersection).
    p : float
        Chi-square probability of the fit (1 with no degree of freedom).
    """

    spheres: list[int]
    model: str
    direction: np.ndarray
    uncertainty_deg: float
    chi2: float
    dof: int
    position: np.ndarray | None
    p: float


@dataclass
class PhotoEstimate:
    """The light of one photograph (:func:`estimate_photo`).

    Attributes
    ----------
    status : {'ok', 'rejected'}
    reason : str or None
        A :data:`REASONS` key when rejected.
    direction : (3,) float
        Unit, from the scene centre (a best guess, or +Z, when rejected).
    position : (3,) float or None
        Near light's position (world).
    uncertainty_deg : float
        Radius (degrees) of the 95% confidence cone of ``direction`` (infinite when rejected):
        :meth:`with_error_model`, :mod:`ffls.spheres.uncertainty`.
    model : {'distant', 'near'} or None
    used_spheres : list of int
    spheres : list of SphereResult
        Every sphere, used or not.
    chi2 : float or None
        Of the chosen light model (None when rejected).
    dof : int or None
    joint_pending : bool
        A near light whose joint fit was deferred (``estimate_photo(joint=False)``): ``position``
        is the ray intersection.
    joint_sigma_deg : float
        1-sigma RMS angular error of the near light's joint fit statistics (0 otherwise).
    weights : list of float or None
        The used spheres' weights in the combination (inverse variances of
        :func:`sphere_uncertainty_deg`): the photo's variance under an error model is that of
        this weighted mean (:meth:`with_error_model`).
    distance_coupling_deg : float
        A near light's turn of direction (degrees) per unit relative error of its distance, along
        its joint fit's coupling (:func:`ffls.spheres.uncertainty.distance_coupling_deg`; 0
        otherwise): with the capture's distance error
        (:meth:`ErrorModel.distance_sigma_deg`) a term of its cone.
    range_deg : float
        A distant combination placed at the capture's light distance
        (:func:`ffls.spheres.estimate.place_at_capture_range`): the angle by which the spread of
        the capture's near lights' distances moves its direction, added to its cone (0 otherwise).
    """

    status: str
    reason: str | None
    direction: np.ndarray
    position: np.ndarray | None = None
    uncertainty_deg: float = float("inf")
    model: str | None = None
    used_spheres: list[int] = field(default_factory=list)
    spheres: list[SphereResult] = field(default_factory=list)
    chi2: float | None = None
    dof: int | None = None
    joint_pending: bool = False
    joint_sigma_deg: float = 0.0
    weights: list[float] | None = None
    distance_coupling_deg: float = 0.0
    range_deg: float = 0.0

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def with_error_model(self, model: ErrorModel) -> "PhotoEstimate":
        """This estimate with its 95% cones (photo and spheres) under ``model``.

        The photo's per-axis standard deviation is :meth:`ErrorModel.photo_sigma_deg` of its used
        spheres' 1-sigma fits, combined with the weights the photo's direction was made with (and
        at least the near light's joint fit statistics, scaled); each
        sphere with a direction gets the cone of its own direction
        (:meth:`ErrorModel.sphere_sigma_deg` plus the common mode).
        """
        stat = {i: s.fit.uncertainty_deg / np.sqrt(2.0) for i, s in enumerate(self.spheres)
                if s.direction is not None and np.isfinite(s.fit.uncertainty_deg)}
        spheres = [replace(s, uncertainty_deg=float(model.cone_deg(np.hypot(model.sphere_sigma_deg(stat[i], i),
                                                                       model.common_sigma_deg(stat[i], i))))
                           if i in stat else None) for i, s in enumerate(self.spheres)]
        unc = self.uncertainty_deg
        if self.ok:
            used = [stat.get(i, np.inf) for i in self.used_spheres]
            sigma = (model.photo_sigma_deg(np.asarray(used), self.used_spheres, self.weights) if used
                     else float("inf"))
            # the joint fit's statistics mix the kinds' pixels and rays: the shared scale
            sigma = max(sigma, model.scale * self.joint_sigma_deg / np.sqrt(2.0))
            sigma = float(np.hypot(sigma, model.distance_sigma_deg(self.distance_coupling_deg)))
            unc = float(np.hypot(model.cone_deg(sigma), self.range_deg))
        return replace(self, spheres=spheres, uncertainty_deg=unc)

    def sphere_directions(self) -> list[np.ndarray | None]:
        """Per sphere its fitted direction (None where it has none): the start of a later pass's fits."""
        return [s.direction for s in self.spheres]

    def sphere_reports(self, refinements: list | None = None) -> list[dict]:
        """JSON-ready per-sphere reports; with the spheres' :class:`~ffls.spheres.refine.CentreRefinement`
        also each sphere's world ``center``, ``center_shift_px`` and ``center_refined``."""
        reports = [s.as_dict() for s in self.spheres]
        for rep, ref in zip(reports, refinements or []):
            rep["center"] = [float(v) for v in ref.center]
            rep["center_shift_px"] = ref.shift_norm_px
            rep["center_refined"] = bool(ref.accepted)
        return reports

    def record(self, refinements: list | None = None) -> dict:
        """The ``extra`` entry of this photo in ``lights.json``: uncertainty, model, spheres, chi2."""
        extra = {"uncertainty_deg": float(self.uncertainty_deg) if np.isfinite(self.uncertainty_deg) else None,
                 "model": self.model, "used_spheres": self.used_spheres,
                 "spheres": self.sphere_reports(refinements)}
        if self.chi2 is not None:
            extra.update(chi2=self.chi2, dof=self.dof)
        if self.distance_coupling_deg:
            extra.update(distance_coupling_deg=self.distance_coupling_deg)
        if self.range_deg:
            extra.update(placed_at_capture_range=True, range_deg=self.range_deg)
        return extra


# ----------------------------------------------------------------------------- stages
def fit_spheres(samples: list[SphereSamples], values: list[SphereValues], *, terminator: float = 0.15,
                up: np.ndarray = UP, bounce_ratio: list | None = None, start: list | None = None,
                mirrors: list | None = None, mirror_floor_deg: float = 0.1,
                own_shadow: bool = True) -> list[LambertFit | HighlightFit]:
    """Step 1: every sphere's own fit (:func:`ffls.spheres.lambert.fit_lambert`, or for a mirror
    sphere :func:`ffls.spheres.highlight.fit_highlight_samples`).

    Parameters
    ----------
    samples : list of SphereSamples
    values : list of SphereValues
    terminator : float
    up : (3,) float
    bounce_ratio : list of (float or None), optional
        Per sphere, the calibrated ground ratio (None: free bounce).
    start : list of ((3,) float or None), optional
        Per sphere, a direction to start from.
    mirrors : list of (SphereView or None), optional
        Per sphere, the view of a mirror sphere (None: matte).
    mirror_floor_deg : float
        RMS floor of a mirror sphere's uncertainty (:func:`ffls.spheres.highlight.fit_highlight`).
    own_shadow : bool
        The bounce less the sphere's own shadow (:func:`ffls.spheres.lambert.fit_lambert`); off
        where the world's up is not known.

    Returns
    -------
    list of LambertFit or HighlightFit
    """
    n = len(samples)
    bounce_ratio = [None] * n if bounce_ratio is None else bounce_ratio
    start = [None] * n if start is None else start
    mirrors = [None] * n if mirrors is None else mirrors
    out = []
    for s, v, rho, l0, view in zip(samples, values, bounce_ratio, start, mirrors):
        if isinstance(view, SphereView):
            out.append(fit_highlight_samples(view, s, v[0], v[1], floor_deg=mirror_floor_deg))
        else:
            out.append(fit_lambert(s.normals, v[0], v[1], n_saturated=v[2], terminator=terminator,
                                   up=up, bounce_ratio=rho, g=s.ground_factor(up), start=l0, pixels=(s.rows, s.cols),
                                   own_shadow=own_shadow, ground=_ground(s, v)))
    return out


def _ground(s: SphereSamples, v: SphereValues) -> tuple | None:
    """The sphere's photographed ground for :func:`ffls.spheres.lambert.fit_lambert` (None: not read)."""
    g = getattr(v, "ground", None)
    return None if s.ground_view is None or g is None else (s.ground_view, g)


#: A matte sphere lit at less than this fraction of the photo's other usable matte spheres
#: (their median intensity) is in a cast shadow (``'shadowed'``).
SHADOW_RATIO = 0.25


def usable_spheres(fits: list) -> tuple[list[str], list[int]]:
    """Statuses and usable spheres: a matte sphere far darker than the other usable matte ones is
    in a shadow (a mirror's highlight brightness says nothing about a cast shadow's); a highlight
    near the rim is used only where no other sphere is usable."""
    status = [f.status for f in fits]
    ok = [i for i, f in enumerate(fits) if f.status == "ok"]
    matte = [i for i in ok if isinstance(fits[i], LambertFit)]
    if len(matte) >= 2:
        med = float(np.median([fits[i].intensity for i in matte]))
        for i in matte:
            if fits[i].intensity < SHADOW_RATIO * med:
                status[i] = "shadowed"
                ok.remove(i)
    # a highlight near the rim (HighlightFit.near_rim) is a photo's last resort: beside a sphere
    # that sees the light well it adds next to nothing, but its wide misfit would enter the
    # capture's error model (fit from the spheres' disagreement) as if it were any sphere's
    if any(not getattr(fits[i], "near_rim", False) for i in ok):
        for i in [i for i in ok if getattr(fits[i], "near_rim", False)]:
            status[i] = "highlight_at_rim"
            ok.remove(i)
    return status, ok


def _rejection_reason(status: list[str], ok: list[int]) -> str:
    """Why too few spheres are usable: the most common sphere status, or ``too_few_spheres``."""
    if ok:
        return "too_few_spheres"
    priority = ("saturated", "shadowed", "too_dark", "no_highlight", "highlight_at_rim", "fit_failed")
    counts = Counter(st for st in status)
    return max(priority, key=lambda r: (counts.get(r, 0), -priority.index(r)))


def sphere_uncertainty_deg(fit, sigma_floor_deg: float) -> float:
    """A sphere's RMS uncertainty in the combination: a matte fit's statistical part with the
    shading model's floor ``sigma_floor_deg`` in quadrature; a highlight fit's own (its floor is
    already inside)."""
    if isinstance(fit, HighlightFit):
        return float(fit.uncertainty_deg)
    return float(np.hypot(fit.uncertainty_deg, sigma_floor_deg))


def ray_origins(spheres: list[int], fits: list, centers: np.ndarray) -> np.ndarray:
    """Where each sphere's light ray starts (k, 3): a matte sphere's centre, a mirror's
    reflection point (where known)."""
    out = np.array([centers[i] for i in spheres], dtype=np.float64).reshape(-1, 3)
    for j, i in enumerate(spheres):
        if isinstance(fits[i], HighlightFit) and np.all(np.isfinite(fits[i].point)):
            out[j] = fits[i].point
    return out


def fit_light_model(spheres: list[int], fits: list, centers: np.ndarray, sigma_floor_deg: float,
                    scene_center: np.ndarray, model: str) -> LightHypothesis:
    """Step 2: the distant (and, where asked or significant, the near) light of some spheres' directions.

    Parameters
    ----------
    spheres : list of int
        The spheres to combine.
    fits : list of LambertFit
    centers : (k, 3) float
        All spheres' world centres.
    sigma_floor_deg : float
    scene_center : (3,) float
    model : {'auto', 'distant', 'near'}

    Returns
    -------
    LightHypothesis
    """
    from scipy.special import chdtrc, chdtri  # chi-square survival function and its inverse
    dirs = np.array([fits[i].direction for i in spheres])
    unc = np.array([sphere_uncertainty_deg(fits[i], sigma_floor_deg) for i in spheres])
    mean, u_mean, chi_d, dof_d = combine_distant(dirs, unc)
    out = LightHypothesis(spheres=list(spheres), model="distant", direction=mean, uncertainty_deg=u_mean,
                          chi2=chi_d, dof=dof_d, position=None, p=1.0)
    # a near fit can only lower chi2 to >= 0: when chi2 of the distant model is below the LR
    # threshold, the near model cannot be significant and is not fitted
    threshold = chdtri(1, SIGNIFICANCE)
    if len(spheres) >= 2 and (model == "near" or (model == "auto" and chi_d > threshold)):
        conv = fit_ray_convergence(ray_origins(spheres, fits, centers), dirs, unc, scene_center)
        if conv.position is not None and (model == "near" or chi_d - conv.chi2 > threshold):
            out.model, out.direction, out.chi2, out.dof, out.position = (
                "near", conv.direction, conv.chi2, conv.dof, conv.position)
    out.p = 1.0 if out.dof == 0 else float(chdtrc(out.dof, out.chi2))
    return out


def _consistent_light(ok: list[int], fits, centers, sigma_floor_deg, scene_center, model):
    """Step 3: the light of all usable spheres, or of all but one (the outlier) when only that is
    consistent; ``(hypothesis, outlier index or None)``, or ``(hypothesis of all, -1)`` when none is."""
    hyp = fit_light_model(ok, fits, centers, sigma_floor_deg, scene_center, model)
    if hyp.p >= SIGNIFICANCE:
        return hyp, None
    candidates = []
    if len(ok) >= 3:
        for j in ok:
            sub = fit_light_model([i for i in ok if i != j], fits, centers, sigma_floor_deg, scene_center, model)
            if sub.p >= SIGNIFICANCE:
                candidates.append((sub.chi2, j, sub))
    if not candidates:
        return hyp, -1
    _, j, sub = min(candidates, key=lambda c: c[0])
    return sub, j


def near_fit_mask(fit: LambertFit) -> np.ndarray:
    """The pixels of a sphere that the joint near-light fit may use, from the sphere's own fit.

    The pixels of the sphere's final fit and every other valid pixel that its model does not
    reject as an outlier, on either side of the sphere's terminator band: the joint fit
    re-selects the band itself with the light's position (a near light's direction changes over
    the sphere), so the per-sphere band must not be cut out here.

    Parameters
    ----------
    fit : LambertFit

    Returns
    -------
    (m,) bool
    """
    if fit.non_outliers is None:
        return fit.inliers
    return fit.inliers | fit.non_outliers


#: Pixel stride of the joint near-light fit's lattice (:func:`ffls.spheres.combine.fit_near_light_mixed` ``stride``).
JOINT_STRIDE = 4


def _near_ground(s: SphereSamples, position: np.ndarray, up: np.ndarray) -> np.ndarray:
    """A sphere's bounce form factor under a point light at ``position``: exact (:func:`near_ground_bounce`)
    on the joint fit's lattice (every :data:`JOINT_STRIDE`-th pixel), the distant one less the own shadow elsewhere."""
    g = shadowed_ground_bounce(s.normals, position - s.center, up, s.ground_factor(up))
    lattice = np.arange(0, len(s), JOINT_STRIDE)
    g[lattice] = near_ground_bounce(s.points[lattice], s.normals[lattice], s.center, s.radius, position, up)
    return g


def _near_terms(fits: list[LambertFit]) -> list[tuple]:
    """Per sphere, the joint fit's shading terms of its own fit's model: (ambient, bounce).

    A sphere whose fit imposed the capture's calibrated ground ratio gets a free (non-negative)
    bounce here: that ratio is read from the spheres' distant-light fits, which under a near
    light put it too low (0.24-0.25 for a ground of albedo 0.3), and imposed in the joint fit it
    pulls the light low and out of its cone (docs/spheres.md, "The bounce under a near light:
    free in the joint fit")."""
    terms = []
    for f in fits:
        if f.bounce_ratio is not None:
            terms.append((f.model == "fixed_ambient", True))
        else:
            terms.append((f.model != "plain", f.model == "bounce"))
    return terms


# ----------------------------------------------------------------------------- one photo
def estimate_photo(image: np.ndarray | None, samples: list[SphereSamples], scene_center: np.ndarray, *,
                   model: str = "auto", min_spheres: int | None = None, sigma_floor_deg: float = 1.0,
                   terminator: float = 0.15, saturation: float | None = None, up: np.ndarray = UP,
                   bounce_ratio: list | None = None, values: list | None = None, start: list | None = None,
                   joint: bool = True, mirrors: list | None = None, mirror_floor_deg: float = 0.1,
                   own_shadow: bool = True) -> PhotoEstimate:
    """Estimate the light of one photograph from its spheres.

    Parameters
    ----------
    image : (H, W, 3) float or None
        Linear radiance (None when ``values`` is given).
    samples : list of SphereSamples
        The spheres' pixels and normals (:func:`ffls.spheres.estimate.capture_samples`).
    scene_center : (3,) float
        World origin of the light direction.
    model : {'auto', 'distant', 'near'}
    min_spheres : int, optional
        Usable spheres needed; default 2, or 1 when only one sphere can show this light (a mirror
        sphere with ``no_highlight`` or ``highlight_at_rim`` cannot: the light is behind it).
    sigma_floor_deg : float
        RMS angular error added (in quadrature) to each sphere's 1-sigma uncertainty for what
        the shading model does not capture, in the combination and its consistency tests. The
        reported ``uncertainty_deg`` is a 95% cone of :data:`ffls.spheres.uncertainty.FALLBACK_MODEL`
        here; :func:`ffls.spheres.estimate.estimate_photos` recalibrates it over the capture.
    terminator : float
    saturation : float, optional
        Known clip level of the linear values.
    up : (3,) float
    bounce_ratio : list of (float or None), optional
        Per sphere, the calibrated ground ratio (:func:`ffls.spheres.estimate.calibrate_bounce`):
        the bounce is then imposed (``c = rho a max(l_z, 0)``) instead of fitted in the spheres'
        own fits (the joint near fit fits it: :func:`_near_terms`). None (or a None entry): free.
    values : list of SphereValues, optional
        :func:`ffls.spheres.samples.sphere_values` of the photo, instead of ``image``.
    start : list, optional
        Per sphere, a direction (or None) to start its fit from (:func:`fit_lambert` ``start``):
        an earlier pass's result for the same photo.
    joint : bool
        Run the joint near-light fit (:func:`ffls.spheres.combine.fit_near_light_mixed`) when the near
        model is chosen. False keeps the ray-intersection position (``joint_pending``): for a first
        pass whose per-sphere fits alone are used (the second pass refits with the calibrated
        bounce).
    mirrors : list of (SphereView or None), optional
        Per sphere, the :class:`~ffls.spheres.highlight.SphereView` of a mirror or glossy sphere
        (its light is its highlight); None (or a None entry): matte.
    mirror_floor_deg : float
        RMS floor of a mirror sphere's uncertainty (what the highlight model leaves out: the
        ball's roundness and radius).
    own_shadow : bool
        The matte spheres' ground bounce less each one's own shadow (:func:`fit_spheres`; the
        joint near fit too); :func:`ffls.spheres.estimate.estimate_lights` turns it off where
        the capture gives no world frame (its up is then the image's).

    Returns
    -------
    PhotoEstimate
    """
    if model not in LIGHT_MODELS:
        raise ValueError(f"model must be one of {LIGHT_MODELS}, not {model!r}")
    n_sph = len(samples)
    if values is None:
        if image is None:
            raise ValueError("estimate_photo needs an image or its sphere values")
        values = sphere_values(image, samples, saturation=saturation)
    fits = fit_spheres(samples, values, terminator=terminator, up=up, bounce_ratio=bounce_ratio, start=start,
                       mirrors=mirrors, mirror_floor_deg=mirror_floor_deg, own_shadow=own_shadow)
    status, ok = usable_spheres(fits)
    # a mirror that cannot show this light (behind it: no highlight, or one at the rim) is not missing
    blind = sum(isinstance(f, HighlightFit) and st in ("no_highlight", "highlight_at_rim") for f, st in zip(fits, status))
    need = max(min(2, n_sph - blind), 1) if min_spheres is None else int(min_spheres)
    centers = np.array([s.center for s in samples])

    def rejected(reason, direction=None):
        return PhotoEstimate(status="rejected", reason=reason,
                             direction=np.array(UP, dtype=np.float64) if direction is None else direction,
                             spheres=[SphereResult(f, st) for f, st in zip(fits, status)]
                             ).with_error_model(FALLBACK_MODEL)

    if len(ok) < need:
        return rejected(_rejection_reason(status, ok), fits[ok[0]].direction if ok else None)
    hyp, outlier = _consistent_light(ok, fits, centers, sigma_floor_deg, scene_center, model)
    if outlier == -1:
        return rejected("spheres_disagree", hyp.direction)
    if outlier is not None:
        status[outlier] = OUTLIER
    used = hyp.spheres
    direction, position, joint_sigma, coupling = hyp.direction, hyp.position, 0.0, 0.0
    # the joint fit: matte spheres' shading, each sphere's pixels over its own residual deviation
    # (fit_near_light_mixed: a sphere whose shading the model misses, e.g. in part of a cast
    # shadow, would otherwise outweigh the others: one photo 2.8-3.4 degrees off at 384 px); with
    # mirror spheres among the used, their reflected rays join the same least-squares problem
    pending = hyp.model == "near" and not joint
    if hyp.model == "near" and joint:
        matte = [i for i in used if isinstance(fits[i], LambertFit)]
        # the bounce's form factor under the point light at the start position (the fit moves it
        # by far less than the form factor changes): on the joint fit's pixel lattice, the ground's
        # irradiance from the point and the perspective own shadow (near_ground_bounce); elsewhere
        # the distant light's form factor less the own shadow
        if own_shadow:
            samples = [replace(s, ground=_near_ground(s, position, up)) if isinstance(f, LambertFit) else s
                       for s, f in zip(samples, fits)]
        rays = [(fits[i].point, fits[i].direction, np.radians(fits[i].uncertainty_deg) / np.sqrt(2.0))
                for i in used if i not in matte]
        jf = fit_near_light_mixed([samples[i] for i in matte], [values[i][0] for i in matte],
                                  [near_fit_mask(fits[i]) for i in matte], position, rays,
                                  terms=_near_terms([fits[i] for i in matte]),
                                  inflation=[fits[i].inflation for i in matte], terminator=terminator, up=up,
                                  stride=JOINT_STRIDE)
        if not (jf.success and np.all(np.isfinite(jf.position))):
            return rejected("fit_failed", direction)
        position = jf.position
        v = position - np.asarray(scene_center, dtype=np.float64)
        direction = normalize(v)
        joint_sigma = tangent_uncertainty_deg(v, jf.cov)
        coupling = distance_coupling_deg(v, jf.cov)
    # 95% cones of the stated single-photo model; estimate_photos recalibrates them capture-wide
    return PhotoEstimate(status="ok", reason=None, direction=np.asarray(direction, dtype=np.float64),
                         position=None if position is None else np.asarray(position, dtype=np.float64),
                         model=hyp.model, used_spheres=[int(i) for i in used],
                         spheres=[SphereResult(f, st) for f, st in zip(fits, status)], chi2=float(hyp.chi2),
                         dof=int(hyp.dof), joint_pending=pending, joint_sigma_deg=float(joint_sigma),
                         distance_coupling_deg=float(coupling),
                         weights=[float(sphere_uncertainty_deg(fits[i], sigma_floor_deg)) ** -2 for i in used]
                         ).with_error_model(FALLBACK_MODEL)
