"""The encoding of integer images, calibrated from the shading of matte spheres.

ffls never guesses whether 8- or 16-bit files are sRGB, linear or gamma-encoded. When
``capture.json`` states no ``"encoding"``, the matte spheres themselves calibrate it: a matte
sphere of known centre and radius under a distant light has a known shading law on its lit side,

    ``I(n) = v . n + b``,

Lambert's ``a max(0, n . l)`` (Masselus, Dutre, Anrys 2002, eq. 2) plus an ambient term
(Hougen & Ahuja 1993) and the ground bounce ``c (1 - n_z) / 2``, which is linear in ``n`` too and
so is absorbed into ``v`` and ``b`` (:mod:`ffls.spheres.lambert`). Only the right decoding curve
``f`` makes ``f(raw)`` an affine function of the normal over the whole lit side of every sphere
in every photo: the sphere is the known scene of the response calibration, in the spirit of
Debevec & Malik (1997) with known geometry in place of known exposures.

Method ``'gamma'`` (:func:`calibrate_encoding_gamma`): ``f(x) = x ** gamma`` on values normalised to
[0, 1], with ``gamma`` continuous in :data:`GAMMA_SEARCH`; the sRGB curve (IEC 61966-2-1) is a
second candidate, scored the same way, and a polynomial tone curve a third ("Tone curves" below).

* Every (photo, sphere) pair is a *unit*: its lit pixels (``n . l > terminator``, not clipped in
  any channel, not near black, no robust outlier) are chosen once per round with the current
  curve, then kept fixed while the curve varies, so the objective is smooth. A unit whose
  shading is not Lambertian (a mirror ball; ``min_r2``), or whose best RMS residual over all
  curves is more than 2.5 times the median unit's (a wrong lit side, a cast shadow), is left out.
* For a curve ``f`` each unit's ``(v, b)`` is the weighted least-squares solution, the residuals
  divided by the curve's slope ``f'(raw)``: the misfit is measured in stored values, where the
  noise (quantisation, sensor) lives, and so is comparable between curves. The sum over units is
  the profile objective ``RSS(gamma)``; :func:`scipy.optimize.minimize_scalar` finds its minimum,
  and a second round re-selects the pixels with that curve.
* The uncertainty is the largest of three: the curvature of the profile likelihood
  (``sd = sqrt(2 s^2 / RSS'')``), a bootstrap over photos (each photo's ``RSS`` curve is
  resampled, which keeps whatever misfit a photo shares across its pixels), and the spheres'
  disagreement. The model's misfit (interreflection, the bounce's shape, a near light seen from
  each sphere's place) is shared by every photo of a sphere, so the bootstrap over photos cannot
  see it, but it differs between spheres: each sphere's gamma (the minimum of its own ``RSS``
  curve) is one draw of it. A random effect per sphere (DerSimonian & Laird 1986) estimates the
  between-sphere variance ``tau^2`` from Cochran's ``Q`` (each sphere's variance: the bootstrap's,
  scaled by its share of the profile's curvature), and the pooled gamma's sd is that of the
  prediction for a new sphere (Higgins, Thompson & Spiegelhalter 2009),
  ``sqrt(tau^2 + 1 / sum 1 / (v_k + tau^2))``: the spheres share the ground and the lights, so
  their misfit need not average out. It is reported as a 95% half-width (1.96 sd), the GUIDE's
  convention for uncertainties.
* Naming is a model selection by the Bayesian information criterion (Schwarz 1978): a named curve
  (``linear``, gamma 1, or ``srgb``) has no free parameter, the best gamma has one. Each named
  curve's *excess* is its ``RSS`` above the best gamma's, in units of the noise variance inflated
  by the ratio of the larger of the bootstrap's and the spheres' variance to the curvature's (the
  residuals are correlated, and the misfit counts as noise; the same inflation gives the
  effective number of pixels ``n_eff = n / inflation``). The best gamma is worth its
  parameter only when it lowers the misfit by more than the BIC's ``ln(n_eff)``: the curve with
  the smallest of (linear excess, sRGB excess, ``ln(n_eff)``) is named. An interval test (does
  the 95% interval hold 1?) would call a linear file ``gamma 1.004`` as soon as the pixels are
  many and the model's small misfit biases the gamma by more than its tiny interval. The BIC is
  blind to a misfit the model shares between the curves (interreflection, a bounce shape), which
  can leave a linear file a few hundredths of a code value from gamma 1 yet "significantly" off:
  so when the free gamma wins but the linear or sRGB curve decodes every stored value within half
  a code value of it (``code_step``: 1/255 for 8-bit files), that curve is named, since the file
  cannot tell them apart. The shading model sees a curve only up to a scale and an offset, and
  only over the codes the lit sides show: when the named curve is, over each pair's codes, the
  best gamma's closest affine map to within the bend the pairs' shading shows beyond the model
  anyway (:func:`_shading_bend`, the median change a ``(n . l)^2`` column makes; the median pair's
  gap, :func:`_affine_gap`), it is named too (``naming`` ``'shown_codes'``): an sRGB file exposed so
  that its lit sides hold codes 0.44-0.91 only is gamma 2.275 there within 0.11 code, and a bend
  the spheres share decides the BIC. For sRGB the dark sides are then asked
  (:func:`calibrate_encoding_gamma`): they show the toe, where sRGB and a gamma differ, and the
  gamma is named when they reject sRGB (``'dark_sides'``); its value and interval are the lit sides'.

Tone curves. A camera's JPEG is rarely a pure gamma or the sRGB curve: its tone curve has a toe
(shadows darkened) and a shoulder (highlights rolled off), an S in the logarithm, and a gamma fitted
to it bends the spheres' shading and so their light directions. A third family is fitted on the
same units, after the shading model is chosen: the polynomial inverse response
``f(x) = x^g exp(sum_j a_j (x^j - 1))`` of order ``K`` (:func:`ffls.io.response.polynomial_response`;
Mitsunaga & Nayar 1999 fit a polynomial inverse response, here in the logarithm so that ``K = 0`` is
the gamma), jointly with every unit's lights (profiled out in closed form, as for the gamma),
increasing by construction (linear constraints on its log-log slope), by SLSQP
(:func:`_fit_polynomial`), for ``K`` = 1 to :data:`MAX_POLYNOMIAL_ORDER`. Its score is the BIC in
the same units as the named curves': ``RSS`` above the best gamma's over the gamma's inflated
noise, plus ``(K + 1) ln(n_eff)``; the lowest of linear (0 parameters), sRGB (0), gamma (1) and the
best order (``K + 1``) is named, provided every sphere alone would pay for the polynomial: its
``RSS`` under the curve named without it less that under the polynomial, over the noise, exceeds
the extra parameters times ``ln(n_eff)`` on each sphere (a tone curve is the camera's and bends every sphere alike; a misfit of the shading
model that the polynomial absorbs, a near light or an interreflection, is each sphere's own: on
a linear file lit from near, an order-4 polynomial won the total BIC by 47 without this test).
The noise is the gamma's (larger when the gamma misfits), which
makes the test conservative against the curve. As for the gamma, a polynomial that decodes every
stored value within half a code value of the best gamma, the linear or the sRGB curve is named as
that curve. A polynomial curve is used through its table of every code (256 rows for 8-bit files, 65536
for 16-bit ones) and written into ``lights.json`` with its order and coefficients (``docs/formats.md``). A
best gamma at an end of :data:`GAMMA_SEARCH` is refused only when no polynomial wins.

The shadow side and the offset. On the lit side alone the curve is fixed only up to an affine map
of the radiance, ``a f + c``: each unit's ambient term absorbs any offset ``c`` (and ``a`` is the
lights' scale). A gamma cannot bend into such a map, but a polynomial can, and the light estimator
(:mod:`ffls.spheres.lambert`) then reads the offset where the map fails: the dark side, which it
fits too, and its ambient term, bounded at 0 (an S-curve fitted to the lit sides of
``ffls synth --encoding filmic`` files matched ``1.12 f_true - 0.014``, and the directions were
2-4 deg off). Two things pin it, both true of a camera and of the physics, neither of the renders:

* **The attached-shadow side** (``n . l < -terminator``) joins each unit that shows ``min_pixels``
  of it (:class:`_ShadowSide`), with the estimator's own model, ``[n . l > 0] v . n + b + c g(n)``
  (``g`` the ground bounce less the sphere's own shadow, :func:`ffls.spheres.lambert.shadowed_ground_bounce`,
  where the world frame is known): the same ``b`` and ``c`` on both sides, so the curve must make
  the dark side's codes (the toe) affine in the bounce's form factor and continuous with the lit
  side across the terminator. The curve is then fitted over the codes the estimator reads, down
  to the darkest the spheres show.
* **Black is black, and no tone curve raises contrast beyond a linear file's**: a fitted tone
  curve's log-log slope ``d ln f / d ln x`` is at least :data:`TONE_MIN_SLOPE` (1) at every code,
  so ``f(x) / x`` does not decrease and ``f(0) = 0`` is approached no faster than linearly.
  Every camera encoding stores a value at or above a linear file's (sRGB: slope 1 at black, up to
  2.3; a gamma ``g >= 1``; Hable's filmic curve then sRGB: 1.0 to 10). An offset ``c > 0`` would
  need ``f / x`` to fall in the toe, an offset ``c < 0`` a dark side that is not affine: the
  remaining offset is below the toe's own values.

The lit sides still name the curve and choose its order (the dark side's model, rougher than
the lit side's, moved gamma-2.2 files' gamma by 0.015); only when they name a polynomial under a
distant light is the calibration run again with the dark sides and the bound
(:func:`calibrate_encoding_gamma`, ``shadow_side``), and its coefficients are used
(:attr:`EncodingCalibration.dark_sides`). With both, the filmic files' curve matched ``1.04 f_true + 0.0016`` and their directions came
within 0.06 deg of the stated curve's (docs/spheres.md); either alone left them 3.6 deg off (the
slope bound alone) or one photo 100 deg off (the shadow side alone: the curve jumped at black).

Near lights. A light at a few metres from spheres a few centimetres in radius has a direction and
an irradiance (``1/r^2``) that vary over each sphere: the shading bends along ``n . l``, and the
affine model reads the bend as a curve (8-bit sRGB renders lit from 2 m were named ``gamma
2.00``). When the spheres' world centres and radii are known (``geometry``; a pinhole camera:
:func:`calibrate_capture_encoding` passes them), a second shading model is fitted on the same
pixels: per photo a point light at ``center + m / rho`` (:func:`_fit_near_photo`: its distance
from the parallax between the spheres' directions, never from the bend, which the curve shares;
its direction refined on the pixels; a photo whose rays are parallel within the scatter of the
spheres' directions has no near light), and per (photo, sphere) pair
``I = a max(0, n . (S - P)) / |S - P|^3 + c (1 - n_z) / 2 + b`` at every surface point ``P``,
the point-light model of :func:`ffls.spheres.combine.fit_near_light` (free bounce). A photo with
one usable sphere keeps the distant model. The gamma is profiled again under the near model (the
lights refitted once at its best gamma), and the model is chosen by the BIC: the near model's
parameters are three per unit plus three per light, the distant model's four per unit; its
excess misfit over the near model, in the distant model's inflated noise units, less the
difference in parameters times ``ln(n_eff)``, is ``shading_excess``, and the near model is used
when it is positive. Under a distant light the near model gains nothing and the distant one is
kept (or, when the near model wins on a small misfit, the gamma is the same within its interval).

:func:`calibrate_encoding` is the entry point on arrays (``method=``);
:func:`calibrate_capture_encoding` runs it on a capture: spheres found on the stored values (edges
survive a monotone curve), their pixels read from every photo.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np

from ffls.conventions import UP, tangent_basis
from ffls.errors import InputError
from ffls.io.capture import CALIBRATED_RESPONSE, CAPTURE_FILE
from ffls.io.images import read_image
from ffls.io.response import (POLYNOMIAL_MIN_SLOPE, polynomial_response, polynomial_response_partials,
                              polynomial_response_table)
from ffls.radiance.encoding import gamma_decode, srgb_decode
from ffls.spheres.combine import fit_ray_convergence
from ffls.spheres.lambert import shadowed_ground_bounce
from ffls.spheres.samples import ground_bounce

__all__ = [
    "METHODS",
    "GAMMA_SEARCH",
    "MIN_PHOTOS",
    "EncodingCalibration",
    "EncodingCalibrationError",
    "calibrate_encoding",
    "calibrate_encoding_gamma",
    "calibrate_capture_encoding",
]

#: Calibration methods of :func:`calibrate_encoding`.
METHODS = ("gamma",)
#: Range of the gamma search: a best gamma at either end is no gamma curve (calibration fails).
GAMMA_SEARCH = (0.8, 3.2)
#: Photos with at least one usable matte sphere needed to calibrate (and to bootstrap over photos).
MIN_PHOTOS = 4
_COARSE_STEP = 0.1  # first round: the whole range
_GRID_STEP = 0.01  # second round: around the first round's minimum, for the bootstrap
_FINE_HALF_WIDTH = 0.2
_MAX_RMS_RATIO = 2.5  # a pair whose best RMS residual exceeds the median pair's by more is left out
_SLOPE_STEP = 1e-4
_TINY = 1e-6  # below the smallest 16-bit code (1.5e-5): log of a zero channel stays finite
#: Highest order of the polynomial response tried (:func:`ffls.io.response.polynomial_response`); the
#: BIC chooses among 1..this. Order 3 follows a filmic S-curve to a quarter of a code value
#: (docs/spheres.md); a fifth coefficient rarely pays its ln(n_eff) on spheres' shading.
MAX_POLYNOMIAL_ORDER = 4
#: Least local log-log slope ``d ln f / d ln x`` of a fitted tone curve (module docstring, "The offset").
TONE_MIN_SLOPE = 1.0


class EncodingCalibrationError(ValueError):
    """The spheres cannot calibrate the encoding (too few photos or matte spheres, no gamma fits)."""


@dataclass(frozen=True)
class EncodingCalibration:
    """The encoding found from the spheres (:func:`calibrate_encoding`).

    Attributes
    ----------
    curve : {'linear', 'srgb', 'gamma', 'polynomial'}
        The name given to the calibrated curve (module docstring, "Naming").
    gamma : float
        The best gamma.
    uncertainty : float
        95% half-width of ``gamma`` (1.96 times the largest of the three sd below).
    sd_curvature, sd_bootstrap : float
        Two standard deviations of ``gamma``: the profile's curvature, the bootstrap over photos.
    sd_spheres : float
        The third: the spheres' disagreement beyond the photos' noise (a random effect per sphere;
        module docstring, on the uncertainty); 0 with one sphere or when they agree.
    srgb_excess, linear_excess : float
        The sRGB and the linear curve's excess misfit over the best gamma, in units of the
        (inflated) noise variance (module docstring, "Naming").
    bic_penalty : float
        ``ln(n_eff)``: a named curve whose excess is below it is preferred to the free gamma.
    shading : {'distant', 'near'}
        The shading model the curve was calibrated with (module docstring, "Near lights").
    shading_excess : float or None
        The distant model's BIC over the near model's, in units of the distant model's inflated
        noise variance: positive chose the near light; None when no near model was tried (no sphere
        geometry, or no photo with two spheres).
    rms : float
        RMS residual at the best gamma, in stored values (full scale 1).
    order : int
        Order of the best polynomial response (module docstring, "Tone curves"); 0 when none was tried.
    coefficients : tuple of float
        Its coefficients ``(g, a_1, ..., a_order)`` (:func:`ffls.io.response.polynomial_response`).
    polynomial_excess : float or None
        Its BIC score less the best gamma's, in the same noise units as ``srgb_excess``
        (``(RSS_poly - RSS_gamma) / noise + order * ln(n_eff)``): negative chose it over the gamma.
        None when no polynomial was tried (16-bit files, ``max_order`` 0).
    polynomial_rms : float or None
        RMS residual under the best polynomial (of the lit sides), in stored values.
    bits : int
        The files' bit depth (8 or 16): the rows of :attr:`response`, ``2 ** bits``.
    dark_sides : bool
        Whether the polynomial's coefficients were fitted on the lit and the attached-shadow sides
        with the slope bound (module docstring, "The shadow side and the offset"); its order and the
        naming are the lit sides'.
    naming : {'bic', 'half_code', 'shown_codes', 'dark_sides'}
        What named the curve (module docstring, "Naming"): the BIC; a named curve within half a code
        value of the best gamma at every stored value; a named curve that the lit sides' codes
        cannot tell from the best gamma (up to a scale and an offset, within the shading's own bend
        along ``n . l``); or the dark sides, asked when the lit sides could not tell sRGB from the
        gamma and rejecting sRGB.
    shown_codes : (2,) float
        The lowest and highest stored value the lit sides' selected pixels show (any channel).
    dark_srgb_excess, dark_bic_penalty : float or None
        The sRGB curve's excess and the free gamma's penalty on the lit and dark sides together,
        when the dark sides were asked (``naming`` ``'shown_codes'`` with sRGB, or ``'dark_sides'``).
    n_dark_units : int
        (photo, sphere) pairs that showed their dark side to that run (0: not asked, or none showed it).
    method : str
    n_spheres, n_photos, n_units, n_pixels : int
        Spheres and photos that contributed, their (photo, sphere) pairs, and pixels used.
    """

    curve: str
    gamma: float
    uncertainty: float
    sd_curvature: float
    sd_bootstrap: float
    srgb_excess: float
    linear_excess: float
    bic_penalty: float
    rms: float
    method: str
    n_spheres: int
    n_photos: int
    n_units: int
    n_pixels: int
    sd_spheres: float = 0.0
    shading: str = "distant"
    shading_excess: float | None = None
    order: int = 0
    coefficients: tuple = ()
    polynomial_excess: float | None = None
    polynomial_rms: float | None = None
    bits: int = 8
    dark_sides: bool = False
    naming: str = "bic"
    shown_codes: tuple = (0.0, 1.0)
    dark_srgb_excess: float | None = None
    dark_bic_penalty: float | None = None
    n_dark_units: int = 0

    @property
    def encoding(self):
        """The ``Capture.encoding`` to use: ``'linear'``, ``'srgb'``, ``{'gamma': g}`` or, for a
        polynomial curve, :data:`ffls.io.capture.CALIBRATED_RESPONSE` (with :attr:`response`)."""
        if self.curve == "gamma":
            return {"gamma": round(float(self.gamma), 4)}
        if self.curve == "polynomial":
            return dict(CALIBRATED_RESPONSE)
        return self.curve

    @property
    def response(self):
        """The ``Capture.response`` to use: the (2 ** bits, 3) table of a polynomial curve, else None."""
        if self.curve != "polynomial":
            return None
        return polynomial_response_table(self._rounded_coefficients(), self.bits)

    def _rounded_coefficients(self) -> list:
        return [float(f"{c:.6g}") for c in self.coefficients]

    def apply(self, capture):
        """``capture`` with this encoding (and the polynomial's response table) set: a copy."""
        return replace(capture, encoding=self.encoding, response=self.response)

    def record(self) -> dict:
        """The top-level ``"encoding"`` record of ``lights.json`` (``docs/formats.md``)."""
        rec = {"curve": self.curve, "gamma": round(float(self.gamma), 4),
                "uncertainty": round(float(self.uncertainty), 4), "method": f"spheres:{self.method}",
                "spheres": int(self.n_spheres), "photos": int(self.n_photos), "pixels": int(self.n_pixels),
                "srgb_excess": round(float(self.srgb_excess), 3),
                "linear_excess": round(float(self.linear_excess), 3),
                "bic_penalty": round(float(self.bic_penalty), 3), "rms": float(f"{self.rms:.4g}"),
                "shading": self.shading, "naming": self.naming,
                "shown_codes": [round(float(v), 4) for v in self.shown_codes]}
        if self.dark_srgb_excess is not None:
            rec["dark_srgb_excess"] = round(float(self.dark_srgb_excess), 3)
            rec["dark_bic_penalty"] = round(float(self.dark_bic_penalty), 3)
        if self.polynomial_excess is not None:
            rec["polynomial_excess"] = round(float(self.polynomial_excess), 3)
            rec["order"] = int(self.order)
            rec["coefficients"] = self._rounded_coefficients()
            rec["polynomial_rms"] = float(f"{self.polynomial_rms:.4g}")
            rec["dark_sides"] = bool(self.dark_sides)
            if self.bits != 8:
                rec["bits"] = int(self.bits)  # the table's rows (ffls.io.capture.record_response)
        return rec

    def summary(self) -> str:
        """One line naming the curve and the test, e.g. ``encoding: linear (fits as well as the best gamma
        1.004 +- 0.003; BIC: excess misfit linear 2.1, sRGB 9e+03, free gamma's penalty 8.4; from 4
        spheres, 40 photos)``."""
        src = (f"from {self.n_spheres} sphere{'s' if self.n_spheres != 1 else ''}, "
               f"{self.n_photos} photos")
        nd = 3 if self.uncertainty < 0.01 else 2
        g = f"gamma {self.gamma:.{nd}f} +- {self.uncertainty:.{nd}f}"
        test = (f"BIC: excess misfit linear {self.linear_excess:.1f}, sRGB {self.srgb_excess:.1f}, "
                f"free gamma's penalty {self.bic_penalty:.1f}")
        if self.polynomial_excess is not None:
            test += f", polynomial order {self.order} {self.polynomial_excess:+.1f}"
        lo, hi = self.shown_codes
        if self.naming == "shown_codes":
            test += (f"; the lit sides' codes ({lo:.2f}-{hi:.2f}) cannot tell it from the best gamma: within the "
                     "shading's own bend, up to scale and offset")
            if self.dark_srgb_excess is not None:
                test += (f"; the dark sides agree (sRGB excess {self.dark_srgb_excess:.1f}, "
                         f"penalty {self.dark_bic_penalty:.1f})")
        elif self.naming == "dark_sides":
            test += (f"; the lit sides' codes ({lo:.2f}-{hi:.2f}) cannot tell sRGB from it, the dark sides can "
                     f"(sRGB excess {self.dark_srgb_excess:.1f}, penalty {self.dark_bic_penalty:.1f})")
        elif self.curve == "linear" and self.linear_excess > self.bic_penalty or \
                self.curve == "srgb" and self.srgb_excess > self.bic_penalty:
            test += "; within half a code value of the best gamma"
        if self.shading == "near":
            test += f"; shading of a near light (BIC {self.shading_excess:.0f} over a distant one)"
        if self.curve == "linear":
            return f"encoding: linear (fits as well as the best {g}; {test}; {src})"
        if self.curve == "srgb":
            return f"encoding: srgb (fits as well as the best {g}; {test}; {src})"
        if self.curve == "polynomial":
            return (f"encoding: curve (polynomial order {self.order}: a toe or shoulder no gamma has, best {g} "
                    f"fits worse; {test}; {src})")
        return f"encoding: {g} (linear and sRGB fit worse; {test}; {src})"


# ----------------------------------------------------------------------------- curves
def _shown_values(used: list) -> tuple[np.ndarray, np.ndarray]:
    """The distinct stored values (any channel) of the used units' selected pixels, sorted, and how
    many pixel channels hold each: (u,), (u,)."""
    vals, counts = [], []
    for u in used:
        c = u.selected_codes
        per_triple = np.bincount(c.index, minlength=c.triples.shape[1]).astype(np.float64)
        for ch in range(3):
            vals.append(c.values[c.triples[ch]])
            counts.append(per_triple)
    if not vals:
        return np.zeros(1), np.ones(1)
    values, inv = np.unique(np.concatenate(vals), return_inverse=True)
    counts = np.bincount(inv.reshape(-1), weights=np.concatenate(counts), minlength=len(values))
    held = counts > 0  # (a unit's codes list the values of all its pixels, selected or not)
    return values[held], counts[held]


def _shading_bend(used: list, curve) -> float:
    """How much the pairs' shading bends along ``n . l`` beyond their model, in stored values: the
    median over the used units of the largest change, over a unit's selected pixels, that a column
    ``(n . l)^2`` (weighted, as the unit's fit) adds to its fit under ``curve``.

    A curve's shape and such a bend trade on the lit side: two curves that differ by less than
    it, up to a scale and an offset, cannot be told apart by these pixels (the model's own misfit,
    interreflection or a bounce of another shape, bends them as much). ``n . l`` is the unit's
    fitted direction's (distant shading: the first three columns), or its point light's irradiance
    column over its largest value (near shading). 0 when no unit can be read.
    """
    amps = []
    for u in used:
        A = u.A[u.selected]
        y, w = u.selected_values(curve)
        x, _ = _solve(A, y, w)
        if A.shape[1] == 3:  # near shading: (s, g, 1)
            c = A[:, 0] / max(float(np.max(A[:, 0])), 1e-12)
        else:
            nv = float(np.linalg.norm(x[:3]))
            if not np.isfinite(nv) or nv <= 0:
                continue
            c = A[:, :3] @ (x[:3] / nv)
        Q = np.column_stack([A, c * c])
        xq, _ = _solve(Q, y, w)
        amps.append(float(np.max(np.abs(w * (Q @ xq - A @ x)))))
    return float(np.median(amps)) if amps else 0.0


def _affine_gap(values: np.ndarray, counts: np.ndarray, curve, other) -> float:
    """How far ``curve`` is from ``other`` as the shading model sees them: the largest difference,
    in stored values, between ``curve`` and the affine map ``s f_other + c`` closest to it over
    ``values`` (weighted least squares, weights ``counts``; each difference divided by ``curve``'s
    slope, as the residuals of :meth:`_Unit.rss_grid` are).

    Every (photo, sphere) pair's shading model has its own scale and offset, so one map for all is
    an upper bound on what the pairs' maps absorb. 0 for fewer than three values.
    """
    if len(values) < 3:
        return 0.0
    f, d2 = _curve_tables(values, curve)
    g, _ = _curve_tables(values, other)
    inv_slope = 1.0 / np.maximum(np.sqrt(d2), 1e-6)
    A = np.column_stack([g, np.ones_like(g)]) * inv_slope[:, None]
    sw = np.sqrt(np.asarray(counts, dtype=np.float64))
    coef, *_ = np.linalg.lstsq(A * sw[:, None], f * inv_slope * sw, rcond=None)
    return float(np.max(np.abs(f * inv_slope - A @ coef)))


def _decode(raw: np.ndarray, curve) -> np.ndarray:
    """Linear values of ``raw`` (float64, normalised) under ``curve`` (a gamma, ``'srgb'``, or a
    polynomial response's coefficients as a tuple)."""
    if isinstance(curve, tuple):
        return polynomial_response(raw, curve)
    return srgb_decode(raw) if isinstance(curve, str) and curve == "srgb" else gamma_decode(raw, curve)


def _curve_tables(values: np.ndarray, curve, log_values: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The decoded value ``f(x)`` and the squared slope ``f'(x)^2`` of each stored value ``x`` of ``values``.

    For a gamma the slope is exact (``g x^(g-1)``, from ``log_values`` when given), and for a
    polynomial response (``curve`` a tuple of its coefficients, :func:`ffls.io.response.polynomial_response`)
    too; for the sRGB curve a central difference.
    """
    if isinstance(curve, tuple):
        f, d = polynomial_response(values, curve, derivative=True)
        return f, d * d
    if isinstance(curve, str) and curve == "srgb":
        h = _SLOPE_STEP
        lo = np.maximum(values - h, 0.0)
        d = (_decode(values + h, curve) - _decode(lo, curve)) / (values + h - lo)
        return _decode(values, curve), d * d
    g = float(curve)
    lv = np.log(np.maximum(values, _TINY)) if log_values is None else log_values
    d = np.exp((g - 1.0) * lv)  # x^(g-1)
    f = values * d
    d *= g
    return f, d * d


def _grey_and_weight(codes: "_Codes", curve) -> tuple[np.ndarray, np.ndarray]:
    """Grey linear value (mean of the decoded channels) and the weight ``1 / slope`` of each pixel.

    The slope is the RMS over channels of ``f'(raw)``: the weighted residual is then in stored
    values. The curve is evaluated once per distinct stored value, the grey value and the weight
    once per distinct (r, g, b) triple (:class:`_Codes`: a few hundred for an 8-bit sphere), and
    gathered: the same numbers as evaluating them at every pixel.
    """
    f, d2 = _curve_tables(codes.values, curve, codes.log_values)
    y = f[codes.triples].mean(axis=0)
    w = 1.0 / np.maximum(np.sqrt(d2[codes.triples].mean(axis=0)), 1e-6)
    return y[codes.index], w[codes.index]


@dataclass
class _Codes:
    """Pixels' stored values (3, m), channel-first, as their distinct values, their distinct
    (r, g, b) triples, and each pixel's triple."""

    values: np.ndarray  # (u,) sorted distinct stored values
    log_values: np.ndarray  # (u,) their logarithms (floored at _TINY)
    triples: np.ndarray  # (3, t) indices into values
    index: np.ndarray  # (m,) each pixel's triple

    @classmethod
    def of(cls, raw: np.ndarray) -> "_Codes":
        values, inv = np.unique(raw, return_inverse=True)
        inv = inv.reshape(raw.shape).astype(np.int64)
        u = len(values)
        keys, index = np.unique((inv[0] * u + inv[1]) * u + inv[2], return_inverse=True)
        triples = np.stack([keys // (u * u), (keys // u) % u, keys % u])
        return cls(values, np.log(np.maximum(values, _TINY)), triples, index.reshape(-1))

    def subset(self, selected: np.ndarray) -> "_Codes":
        return _Codes(self.values, self.log_values, self.triples, self.index[selected])


class _SharedValues:
    """The distinct stored values of several units, and the curves' tables on them: a curve is
    evaluated once for all the units (an 8-bit capture has at most 256 values), not once per unit."""

    def __init__(self, units: list):
        self.values = np.unique(np.concatenate([u.selected_codes.values for u in units]))
        self.log_values = np.log(np.maximum(self.values, _TINY))
        self.index = {id(u): np.searchsorted(self.values, u.selected_codes.values) for u in units}
        self.tables: list = []

    def evaluate_partials(self, theta) -> "_SharedValues":
        """``partials``: the polynomial response ``f`` of coefficients ``theta`` on the shared values,
        its slope ``f'`` and their derivatives in ``theta`` ((P, U) each;
        :func:`ffls.io.response.polynomial_response_partials`)."""
        self.partials = polynomial_response_partials(self.values, theta)
        return self

    def evaluate(self, curves) -> "_SharedValues":
        """Tabulate ``curves`` (:func:`_curve_tables`) on the shared values; returns self."""
        self.tables = [_curve_tables(self.values, c, self.log_values) for c in curves]
        return self


def _solve(A: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least squares ``min ||w (y - A x)||`` (normal equations; ``A`` has a few columns);
    returns ``x`` and the weighted residuals."""
    Aw = A * w[:, None]
    try:
        x = np.linalg.solve(Aw.T @ Aw, Aw.T @ (y * w))
    except np.linalg.LinAlgError:  # a degenerate design (all normals alike): the minimum-norm solution
        x, *_ = np.linalg.lstsq(Aw, y * w, rcond=None)
    return x, w * (y - A @ x)


@dataclass
class _Unit:
    """One (photo, sphere) pair: its pixels' stored values (:class:`_Codes`) and normals (m, 3), and
    the selection."""

    photo: int
    sphere: int
    raw: _Codes
    A: np.ndarray  # (m, p): the shading model's columns (distant: normal and 1; with the shadow side, 5)
    usable: np.ndarray  # (m,) bool: not clipped, not near black
    selected: np.ndarray | None = None
    base: np.ndarray | None = None  # (m, 4): the lit side's columns (normal, 1); A when not given

    def __post_init__(self):
        if self.base is None:
            self.base = self.A

    @property
    def normals(self) -> np.ndarray:
        """(m, 3) the pixels' unit normals."""
        return self.base[:, :3]

    def select(self, selected: np.ndarray) -> None:
        """Fix the selection (and cache its values, design rows and per-triple sums for :meth:`rss`)."""
        self.selected = selected
        self._raw = self.raw.subset(selected)
        self._A = np.ascontiguousarray(self.A[selected])
        # the pixels' sums per (r, g, b) triple, whose grey value and weight they share: the count,
        # sum a (t, p) and sum a a^T (t, p^2) of the design rows a (distant: (n, 1))
        t = self._raw.triples.shape[1]
        idx = self._raw.index
        self._count = np.bincount(idx, minlength=t).astype(np.float64)
        A = self._A
        p = A.shape[1]
        self._sum_a = np.stack([np.bincount(idx, A[:, i], minlength=t) for i in range(p)], axis=1)
        self._sum_aa = np.stack([np.bincount(idx, A[:, i] * A[:, j], minlength=t)
                                 for i in range(p) for j in range(p)], axis=1)

    @property
    def sums(self) -> SimpleNamespace:
        """The selection's per-triple sums (:meth:`select`): ``width`` (the design's columns p),
        ``triples`` (3, t) indices into the stored values, ``count`` (t,), ``sum_a`` (t, p),
        ``sum_aa`` (t, p * p)."""
        return SimpleNamespace(width=self._A.shape[1], triples=self._raw.triples, count=self._count,
                               sum_a=self._sum_a, sum_aa=self._sum_aa)

    @property
    def selected_codes(self) -> _Codes:
        """The selected pixels' stored values (:meth:`select`)."""
        return self._raw

    def selected_values(self, curve) -> tuple[np.ndarray, np.ndarray]:
        """Grey linear value and weight of each selected pixel under ``curve`` (:func:`_grey_and_weight`)."""
        return _grey_and_weight(self._raw, curve)

    def rss(self, curve) -> float:
        """Weighted residual sum of squares (stored-value units) of the selected pixels under ``curve``."""
        return float(self.rss_grid([curve])[0])

    def rss_grid(self, curves, shared: "_SharedValues | None" = None) -> np.ndarray:
        """:meth:`rss` for every curve of ``curves`` (k,: gammas, or ``'srgb'``), at once: (k,) float.

        The pixels of one (r, g, b) triple share their grey value ``y`` and weight ``w``: with
        their sums (:meth:`select`), each curve's normal equations and residual cost one pass over
        the triples, not the pixels (``rss = sum w^2 y^2 - x . b`` at the solution ``G x = b``,
        which loses about 1e-12 of it). With ``shared`` (:class:`_SharedValues` of these units,
        its curves ``curves``), the curves' tables are read from it, not evaluated again."""
        codes = self._raw
        t = codes.triples.shape[1]
        y, w2 = np.empty((len(curves), t)), np.empty((len(curves), t))
        tr = codes.triples if shared is None else shared.index[id(self)][codes.triples]
        for j, curve in enumerate(curves):
            if shared is not None:
                f, d2 = shared.tables[j]
            else:
                if not isinstance(curve, (str, tuple)):
                    curve = float(curve)
                f, d2 = _curve_tables(codes.values, curve, codes.log_values)
            y[j] = f[tr].mean(axis=0)
            w = 1.0 / np.maximum(np.sqrt(d2[tr].mean(axis=0)), 1e-6)
            w2[j] = w * w
        p = self._A.shape[1]
        G = (w2 @ self._sum_aa).reshape(-1, p, p)
        w2y = w2 * y
        b = w2y @ self._sum_a
        try:
            x = np.linalg.solve(G, b[..., None])[..., 0]
        except np.linalg.LinAlgError:  # a degenerate design: the minimum-norm solutions, pixel by pixel
            return np.array([self._rss_pixels(c) for c in curves])
        return np.maximum((w2y * y) @ self._count - np.einsum("ki,ki->k", x, b), 0.0)

    def rss_and_gradient(self, shared: "_SharedValues") -> tuple[float, np.ndarray]:
        """:meth:`rss` under the polynomial curve whose partials ``shared`` holds
        (:meth:`_SharedValues.evaluate_partials`), and its gradient in the curve's coefficients.

        With the unit's coefficients ``x`` profiled out, the envelope theorem leaves the partial
        derivatives at fixed ``x``: per triple, ``rss_t = w_t^2 Q_t`` with ``Q_t = n_t y_t^2 - 2 y_t
        s_t . x + x^T S_t x`` (``n_t``, ``s_t``, ``S_t`` its pixels' count, design sums and products), so
        ``d rss = sum_t (d w_t^2) Q_t + 2 w_t^2 (n_t y_t - s_t . x) d y_t``."""
        codes = self._raw
        tr = shared.index[id(self)][codes.triples]
        f, d, df, dd = shared.partials
        y = f[tr].mean(axis=0)
        dt = d[tr]
        m = (dt * dt).mean(axis=0)
        floor = m < 1e-12  # the weight's floor (as rss_grid's): no derivative there
        w2 = 1.0 / np.maximum(m, 1e-12)
        dy = df[:, tr].mean(axis=1)  # (P, t)
        dm = 2.0 * (dt[None] * dd[:, tr]).mean(axis=1)
        dw2 = np.where(floor, 0.0, -dm * w2 * w2)
        p = self._A.shape[1]
        G = (w2 @ self._sum_aa).reshape(p, p)
        bvec = (w2 * y) @ self._sum_a
        try:
            x = np.linalg.solve(G, bvec)
        except np.linalg.LinAlgError:
            x, *_ = np.linalg.lstsq(G, bvec, rcond=None)
        sx = self._sum_a @ x
        q = self._count * y * y - 2.0 * y * sx + self._sum_aa @ np.outer(x, x).ravel()
        rss = max(float(w2 @ q), 0.0)
        grad = dw2 @ q + dy @ (2.0 * w2 * (self._count * y - sx))
        return rss, grad

    def _rss_pixels(self, curve) -> float:
        y, w = _grey_and_weight(self._raw, curve)
        Aw = self._A * w[:, None]
        x, *_ = np.linalg.lstsq(Aw, y * w, rcond=None)
        r = y * w - Aw @ x
        return float(r @ r)


class _StackedUnits:
    """Selected units (:meth:`_Unit.select`) stacked for the polynomial fit: their triples' sums
    side by side, grouped by the width of their design, so the summed :meth:`_Unit.rss_grid` and
    :meth:`_Unit.rss_and_gradient` of every unit are a few array operations over all the triples
    (segment sums per unit, one batched solve), not a Python call per unit (a capture has
    hundreds; the same arithmetic, summed in another order)."""

    def __init__(self, units: list, shared: _SharedValues):
        self.units, self.shared = units, shared
        sums = [u.sums for u in units]
        small = [(u, t) for u, t in zip(units, sums) if t.triples.shape[1] <= self.SMALL]
        self.alone = [u for u, t in zip(units, sums) if t.triples.shape[1] > self.SMALL]
        self.groups = []
        for p in sorted({t.width for _, t in small}):
            for block in self._blocks([(u, t) for u, t in small if t.width == p]):
                self._add_group(block, p)

    #: Units with more triples (16-bit files: ~1,400 a unit) are evaluated each on its own: their
    #: arithmetic outweighs a call (stacked, 278 units of 16-bit c05_384 cost 60-74 ms a gradient,
    #: one by one 51; 285 units of 8-bit distant_grey_768: 3.6 against 13.3 ms)
    SMALL = 512
    BLOCK = 8192  # triples per group at most (but one unit at least): the temporaries stay in the cache

    @classmethod
    def _blocks(cls, units: list) -> list:
        blocks, size = [], cls.BLOCK
        for u, t in units:
            n = t.triples.shape[1]
            if size + n > cls.BLOCK:
                blocks.append([])
                size = 0
            blocks[-1].append((u, t))
            size += n
        return blocks

    def _add_group(self, block: list, p: int) -> None:
        sizes = np.array([t.triples.shape[1] for _, t in block])
        self.groups.append(SimpleNamespace(
            p=p, triples=np.concatenate([self.shared.index[id(u)][t.triples] for u, t in block], axis=1),
            starts=np.concatenate([[0], np.cumsum(sizes)[:-1]]), sizes=sizes,
            count=np.concatenate([t.count for _, t in block]), sum_a=np.concatenate([t.sum_a for _, t in block]),
            sum_aa=np.concatenate([t.sum_aa for _, t in block])))

    @staticmethod
    def _solve(g, w2, y, degenerate: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Each unit's coefficients ``x`` (U, p) and right-hand side ``b`` from its normal
        equations, its triples weighted ``w2``; ``degenerate``: a singular design is solved by
        least squares (as :meth:`_Unit.rss_and_gradient`), else it raises ``LinAlgError``."""
        G = np.add.reduceat(w2[:, None] * g.sum_aa, g.starts, axis=0).reshape(-1, g.p, g.p)
        b = np.add.reduceat((w2 * y)[:, None] * g.sum_a, g.starts, axis=0)
        try:
            return np.linalg.solve(G, b[..., None])[..., 0], b
        except np.linalg.LinAlgError:
            if not degenerate:
                raise
            return np.array([np.linalg.lstsq(Gu, bu, rcond=None)[0] for Gu, bu in zip(G, b)]), b

    def rss(self, curves) -> np.ndarray:
        """The units' summed :meth:`_Unit.rss_grid` over ``curves`` (k,): the tables of ``shared``
        (evaluated on ``curves`` here)."""
        self.shared.evaluate(curves)
        try:
            out = np.zeros(len(curves))
            for j in range(len(curves)):
                f, d2 = self.shared.tables[j]
                for g in self.groups:
                    t0, t1, t2 = g.triples
                    y = (f[t0] + f[t1] + f[t2]) / 3.0
                    w = 1.0 / np.maximum(np.sqrt((d2[t0] + d2[t1] + d2[t2]) / 3.0), 1e-6)
                    w2 = w * w
                    x, b = self._solve(g, w2, y)
                    per_unit = np.add.reduceat(w2 * y * y * g.count, g.starts) - np.einsum("ui,ui->u", x, b)
                    out[j] += np.maximum(per_unit, 0.0).sum()
            for u in self.alone:
                out += u.rss_grid(curves, self.shared)
            return out
        except np.linalg.LinAlgError:  # a degenerate design: the units' own path, pixel by pixel
            return np.sum([u.rss_grid(curves, self.shared) for u in self.units], axis=0)

    def rss_and_gradient(self) -> tuple[float, np.ndarray]:
        """The units' summed :meth:`_Unit.rss_and_gradient` under the polynomial curve whose
        partials ``shared`` holds (:meth:`_SharedValues.evaluate_partials`)."""
        f, d, df, dd = self.shared.partials
        df, dd = np.ascontiguousarray(df.T), np.ascontiguousarray(dd.T)  # (values, P): a value's partials together
        rss, grad = 0.0, np.zeros(df.shape[1])
        for g in self.groups:
            t0, t1, t2 = g.triples
            y = (f[t0] + f[t1] + f[t2]) / 3.0  # the channels' mean, as the unit's
            d0, d1, d2 = d[t0], d[t1], d[t2]
            m = (d0 * d0 + d1 * d1 + d2 * d2) / 3.0
            w2 = 1.0 / np.maximum(m, 1e-12)
            dy = (df[t0] + df[t1] + df[t2]) / 3.0  # (T, P)
            dm = (2.0 / 3.0) * (d0[:, None] * dd[t0] + d1[:, None] * dd[t1] + d2[:, None] * dd[t2])
            dw2 = np.where((m < 1e-12)[:, None], 0.0, -dm * (w2 * w2)[:, None])
            x, _ = self._solve(g, w2, y, degenerate=True)
            sx = np.einsum("ti,ti->t", g.sum_a, np.repeat(x, g.sizes, axis=0))
            xx = np.repeat((x[:, :, None] * x[:, None, :]).reshape(len(x), -1), g.sizes, axis=0)
            q = g.count * y * y - 2.0 * y * sx + np.einsum("tk,tk->t", g.sum_aa, xx)
            rss += float(np.maximum(np.add.reduceat(w2 * q, g.starts), 0.0).sum())
            grad += q @ dw2 + (2.0 * w2 * (g.count * y - sx)) @ dy
        for u in self.alone:
            r, gu = u.rss_and_gradient(self.shared)
            rss, grad = rss + r, grad + gu
        return rss, grad


def _select(unit: _Unit, curve, terminator: float, min_pixels: int, min_r2: float, clip: float = 3.5,
            shadow: "_ShadowSide | None" = None) -> bool:
    """Choose ``unit``'s lit pixels with ``curve`` (iterating the fit); False when the unit is unusable.

    Start from the pixels within ``acos(terminator)`` of the mean normal of the brightest tenth,
    fit ``v . n + b``, keep the pixels with ``n . l > terminator`` that are no robust outlier
    (``clip`` MADs), refit; at most five rounds. The
    unit is unusable with fewer than ``min_pixels`` pixels, a normal range too narrow to show the
    curve (``n . l`` spanning less than 0.4), or a fit explaining less than ``min_r2`` of the
    variance (no Lambertian shading: a mirror ball, a shadowed or flat sphere).

    With ``shadow`` (:class:`_ShadowSide`), the attached-shadow side joins the unit when it has
    ``min_pixels`` pixels with ``n . l < -terminator``: the model becomes the light estimator's,
    ``[n . l > 0] v . n + b + c g(n)`` (:mod:`ffls.spheres.lambert`), and its columns replace the
    unit's (module docstring, "The shadow side").
    """
    ok = unit.usable
    if ok.sum() < min_pixels:
        return False
    y_all, w_all = _grey_and_weight(unit.raw, curve)
    normals = unit.normals
    base = unit.base
    top = ok & (y_all >= np.percentile(y_all[ok], 90))  # the brightest tenth: around the light's direction
    start = normals[top].sum(axis=0)
    if not np.linalg.norm(start) > 0:
        return False
    cos = normals @ (start / np.linalg.norm(start))
    sel = ok & (cos > terminator)
    for _ in range(5):
        if sel.sum() < min_pixels:
            return False
        x, _ = _solve(base[sel], y_all[sel], w_all[sel])
        nv = float(np.linalg.norm(x[:3]))
        if not np.isfinite(nv) or nv <= 0:
            return False
        cos = normals @ (x[:3] / nv)
        r = w_all * (y_all - base @ x)
        lit = ok & (cos > terminator)
        if lit.sum() < min_pixels:
            return False
        mad = 1.4826 * float(np.median(np.abs(r[lit] - np.median(r[lit]))))
        new = lit & (np.abs(r - np.median(r[lit])) <= clip * max(mad, 1e-12))
        if np.array_equal(new, sel):
            break
        sel = new
    if sel.sum() < min_pixels or float(np.ptp(cos[sel])) < 0.4:
        return False
    A = base
    if shadow is not None:
        dark = ok & (cos < -terminator)
        if dark.sum() >= min_pixels:
            A = shadow.columns(normals, x[:3] / nv, cos > 0)
            lit_sel, both = sel, sel | dark
            for _ in range(5):
                xs, _ = _solve(A[both], y_all[both], w_all[both])
                r = w_all * (y_all - A @ xs)
                med = float(np.median(r[both]))
                mad = 1.4826 * float(np.median(np.abs(r[both] - med)))
                new = (lit_sel | dark) & (np.abs(r - med) <= clip * max(mad, 1e-12))
                if np.array_equal(new, both):
                    break
                both = new
            if (both & dark).sum() >= min_pixels and (both & lit_sel).sum() >= min_pixels:
                sel = both
            else:
                A = base
    yw = y_all[sel] * w_all[sel]
    _, r = _solve(A[sel], y_all[sel], w_all[sel])
    tot = float(np.sum((yw - yw.mean()) ** 2))
    if tot <= 0 or 1.0 - float(r @ r) / tot < min_r2:
        return False
    unit.A = A
    unit.select(sel)
    return True


@dataclass(frozen=True)
class _ShadowSide:
    """The attached-shadow side's model (module docstring, "The shadow side"): the ground bounce
    ``g(n)`` less the sphere's own shadow on the ground (:func:`ffls.spheres.lambert.shadowed_ground_bounce`,
    as the light estimator) or, with ``own_shadow`` False, the plain bounce."""

    up: np.ndarray
    own_shadow: bool = True

    def columns(self, normals: np.ndarray, light: np.ndarray, lit: np.ndarray) -> np.ndarray:
        """Design columns ``([lit] n, 1, g)`` (m, 5) of a unit's pixels for the light ``light``."""
        g = (shadowed_ground_bounce(normals, light, self.up) if self.own_shadow
             else ground_bounce(normals, self.up))
        return np.column_stack([normals * lit[:, None], np.ones(len(normals)), g])


_DARK_COLUMNS = 5  # a unit with its dark side: ([lit] n, 1, g)
_pool_units: list | None = None  # the units of the worker processes of _UnitPool (inherited when forked)


def _set_pool_units(units) -> None:
    global _pool_units
    _pool_units = units


def _select_and_profile_range(task) -> list:
    """In a worker: per unit of ``_pool_units[start:stop]``, its selection and RSS curve (None, None: unusable)."""
    (start, stop), curve, grid, terminator, min_pixels, min_r2, shadow = task
    out = []
    for u in _pool_units[start:stop]:
        ok = _select(u, curve, terminator, min_pixels, min_r2, shadow=shadow)
        out.append((u.selected, u.A, u.rss_grid(grid)) if ok else (None, None, None))
    return out


class _UnitPool:
    """Selects and profiles the units in this process or, with several workers, in forked processes
    (each unit's work is independent; the parent then fixes the selections the workers chose)."""

    CHUNK = 16

    def __init__(self, units: list, workers: int = 1):
        self.units, self.workers = units, max(1, int(workers))

    def select_and_profile(self, curve, grid, terminator, min_pixels, min_r2, shadow=None) -> tuple[list, np.ndarray]:
        """The usable units (selected with ``curve``) and their RSS over ``grid``: (used, (len(used), k))."""
        if self.workers == 1 or len(self.units) < 2 * self.CHUNK:
            used = [u for u in self.units if _select(u, curve, terminator, min_pixels, min_r2, shadow=shadow)]
            curves = [u.rss_grid(grid) for u in used]
        else:
            from concurrent.futures import ProcessPoolExecutor

            bounds = [(a, min(a + self.CHUNK, len(self.units))) for a in range(0, len(self.units), self.CHUNK)]
            tasks = [(b, curve, grid, terminator, min_pixels, min_r2, shadow) for b in bounds]
            with ProcessPoolExecutor(max_workers=min(self.workers, len(tasks)), initializer=_set_pool_units,
                                     initargs=(self.units,)) as ex:
                parts = list(ex.map(_select_and_profile_range, tasks))
            used, curves = [], []
            for (a, _), part in zip(bounds, parts):
                for u, (sel, A, c) in zip(self.units[a:], part):
                    if sel is not None:
                        u.A = A
                        u.select(sel)
                        used.append(u)
                        curves.append(c)
        return used, np.array(curves).reshape(len(used), len(grid))


def _parabola_min(g: np.ndarray, f: np.ndarray) -> float:
    """Sub-grid minimum of ``f`` sampled on the regular grid ``g`` (parabola through the lowest point)."""
    k = int(np.argmin(f))
    if k == 0 or k == len(g) - 1:
        return float(g[k])
    a, b, c = f[k - 1], f[k], f[k + 1]
    den = a - 2 * b + c
    step = g[1] - g[0]
    return float(g[k] + (0.5 * (a - c) / den * step if den > 0 else 0.0))


def _sphere_heterogeneity_sd(grid: np.ndarray, per_sphere: np.ndarray, sd_pooled: float) -> float:
    """Standard deviation of the pooled gamma under a random effect per sphere (DerSimonian & Laird 1986).

    Each sphere's gamma ``g_k`` is the minimum of its ``RSS`` curve (``per_sphere``, (K, len(grid))),
    its variance ``v_k`` the pooled variance ``sd_pooled ** 2`` scaled by the share of the profile's
    curvature the sphere holds (its information). Cochran's ``Q = sum (g_k - g_bar)^2 / v_k`` beyond
    its ``K - 1`` degrees of freedom gives the between-sphere variance ``tau^2``: a misfit of the
    model that differs between spheres (interreflection from a neighbour, a near light seen from
    each sphere's place), which the bootstrap over photos cannot see when every photo shares it.
    The pooled gamma's variance is that of the prediction for a new sphere (Higgins, Thompson &
    Spiegelhalter 2009), ``tau^2 + 1 / sum 1 / (v_k + tau^2)``: the spheres share the ground and
    the lights, so their misfit need not average out. With one sphere, or a curvature that cannot
    be read, it returns 0 (no evidence of heterogeneity).
    """
    K = len(per_sphere)
    if K < 2 or not np.isfinite(sd_pooled) or sd_pooled <= 0:
        return 0.0
    step = float(grid[1] - grid[0])
    g, curv = np.empty(K), np.empty(K)
    for k, c in enumerate(per_sphere):
        g[k] = _parabola_min(grid, c)
        j = int(np.clip(np.argmin(c), 1, len(grid) - 2))
        curv[k] = (c[j - 1] - 2 * c[j] + c[j + 1]) / (step * step)
    if not np.all(curv > 0):
        return 0.0
    v = sd_pooled ** 2 * curv.sum() / curv
    w = 1.0 / v
    g_bar = float(w @ g / w.sum())
    q = float(w @ (g - g_bar) ** 2)
    tau2 = max(0.0, (q - (K - 1)) / (w.sum() - (w @ w) / w.sum()))
    return float(math.sqrt(tau2 + 1.0 / np.sum(1.0 / (v + tau2))))


@dataclass(frozen=True)
class _ProfileFit:
    """The statistics of a profiled gamma (:func:`_profile_statistics`)."""

    n_pixels: int
    s2: float  # residual variance (stored values squared)
    sd_curvature: float
    sd_bootstrap: float
    sd_spheres: float
    inflation: float  # the larger model variance over the curvature's (>= 1)
    noise: float  # s2 * inflation: the unit of the excess misfits
    penalty: float  # ln(n_eff), n_eff = n_pixels / inflation: the BIC's price of one parameter


def _profile_statistics(used: list, curves: np.ndarray, grid: np.ndarray, best: float, rss_best: float,
                        extra_params: int, n_bootstrap: int, seed: int) -> _ProfileFit:
    """Noise, the three standard deviations of the best gamma and the BIC's penalty (module docstring).

    ``curves`` (len(used), len(grid)) are the units' ``RSS`` over ``grid``; ``extra_params`` the
    model's parameters besides the units' linear coefficients and the gamma (the near lights').
    """
    photos = sorted({u.photo for u in used})
    n_pix = int(sum(int(u.selected.sum()) for u in used))
    dof = max(n_pix - sum(u.A.shape[1] for u in used) - extra_params - 1, 1)
    s2 = rss_best / dof
    h = 0.01
    d2 = (sum(u.rss(best + h) for u in used) - 2 * rss_best + sum(u.rss(best - h) for u in used)) / (h * h)
    sd_curv = math.sqrt(2 * s2 / d2) if d2 > 0 else float("inf")
    # bootstrap over photos: resample whole photos' RSS curves
    photo_index = {p: i for i, p in enumerate(photos)}
    per_photo = np.zeros((len(photos), len(grid)))
    for u, c in zip(used, curves):
        per_photo[photo_index[u.photo]] += c
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, len(photos), size=(int(n_bootstrap), len(photos)))
    boot = np.array([_parabola_min(grid, per_photo[d].sum(axis=0)) for d in draws])
    sd_boot = float(np.std(boot, ddof=1)) if len(boot) > 1 else float("inf")
    # the spheres' own gammas: a misfit the model lacks that differs between spheres (interreflection,
    # a near light across the scene) makes them disagree beyond the photos' noise (random effects)
    sphere_index = sorted({u.sphere for u in used})
    per_sphere = np.zeros((len(sphere_index), len(grid)))
    for u, c in zip(used, curves):
        per_sphere[sphere_index.index(u.sphere)] += c
    sd_spheres = _sphere_heterogeneity_sd(grid, per_sphere, sd_boot)
    sd_model = max(sd_boot, sd_spheres)
    inflation = max(1.0, (sd_model / sd_curv) ** 2) if np.isfinite(sd_curv) and sd_curv > 0 else 1.0
    n_eff = max(n_pix / inflation, math.e)
    return _ProfileFit(n_pixels=n_pix, s2=s2, sd_curvature=sd_curv, sd_bootstrap=sd_boot, sd_spheres=sd_spheres,
                       inflation=inflation, noise=s2 * inflation, penalty=math.log(n_eff))


# ----------------------------------------------------------------------------- near lights
#: Parameters of a near light per photo: its direction from the spheres' centre (2) and inverse distance (1).
_NEAR_PHOTO_PARAMS = 3


def _near_columns(normals: np.ndarray, points: np.ndarray, up: np.ndarray, m: np.ndarray, rho: float,
                  center: np.ndarray) -> np.ndarray:
    """Design columns ``(s, g, 1)`` (k, 3) of a sphere's pixels under a point light at ``center + m / rho``.

    ``s = max(0, n . q) / |q|^3`` with ``q = m + rho (center - P)``, which is ``rho^-2`` times a
    point light's irradiance ``max(0, n . (S - P)) / |S - P|^3`` at the surface point ``P`` (so
    ``rho = 0`` is a distant light along ``m``); ``g = (1 - n . up) / 2`` the ground bounce
    (:func:`ffls.spheres.samples.ground_bounce`), and 1 the ambient term.
    """
    q = m[None, :] + rho * (center[None, :] - points)
    qq = np.einsum("ij,ij->i", q, q)
    s_ = np.maximum(np.einsum("ij,ij->i", normals, q), 0.0) / (qq * np.sqrt(qq))
    return np.column_stack([s_, ground_bounce(normals, up), np.ones(len(s_))])


def _fit_near_photo(units: list, centers: np.ndarray, radii: np.ndarray, up: np.ndarray, curve: float):
    """A point light ``(m, rho, center)`` for one photo's units (two or more spheres) at ``curve``.

    * **Distance, from the parallax.** Each unit's distant fit (``v . n + b``) gives the light's
      direction from its sphere, ``v / |v|``; the rays from the spheres' centres along them meet
      at the light (:func:`ffls.spheres.combine.fit_ray_convergence`, the "best fitted
      intersection" of Masselus, Dutre & Anrys 2002): ``rho``, the inverse distance from the
      spheres' mean centre ``center`` (0: a distant light). The distance is never fitted to the
      shading's bend along ``n . l``: a wrong curve bends it too, so the two trade (fitted to the
      pixels, the inverse distance came out 0.7 times the true one on near-light renders and the
      gamma 0.09 too low), while a monotone curve hardly turns a sphere's direction.
    * **Direction, from the pixels.** The ground bounce pulls every ``v`` toward the ground, so
      the direction ``m`` is refined (two tangent offsets, :func:`scipy.optimize.least_squares`)
      to the units' weighted residuals under :func:`_near_columns` at that distance, each unit's
      coefficients in closed form. A curve bends the shading symmetrically about the light, so it
      does not trade with ``m``.

    None (the photo keeps the distant model) when a direction cannot be read, the spheres
    coincide, or the light's parallax (``rho`` times the spheres' largest distance from ``center``:
    the angle their spread subtends at the light) does not exceed the RMS angle between the
    spheres' directions and the rays' meeting point: the rays are then parallel within their
    scatter, and a distant light explains them. (Without this test the BIC chose a near light for
    distant-light captures whose spheres disagree, crediting the near model's fewer coefficients,
    and widened their gamma's interval until a gamma-2.2 file was named srgb.)
    """
    from scipy.optimize import least_squares
    dirs, data = [], []
    for u in units:
        n = u.normals[u.selected]
        y, w = u.selected_values(curve)
        x, _ = _solve(u.A[u.selected], y, w)
        nv = float(np.linalg.norm(x[:3]))
        if not np.isfinite(nv) or nv <= 0:
            return None
        dirs.append(x[:3] / nv)
        data.append((n, centers[u.sphere] + radii[u.sphere] * n, y, w))
    c = np.array([centers[u.sphere] for u in units])
    center = c.mean(axis=0)
    if not float(np.max(np.linalg.norm(c - center, axis=1))) > 0:  # no parallax to place a light
        return None
    start = fit_ray_convergence(c, np.array(dirs), np.ones(len(dirs)), center)
    m0, rho = start.direction, start.rho
    # a light is near only where its parallax (the angle the spheres' spread subtends at it) exceeds
    # the scatter of the spheres' directions about the rays' meeting point: otherwise the rays are
    # parallel within their noise, and the photo keeps the distant model
    pred = m0[None, :] - rho * (c - center)
    pred /= np.linalg.norm(pred, axis=1)[:, None]
    scatter = math.sqrt(float(np.mean(np.arccos(np.clip(np.sum(pred * np.array(dirs), axis=1), -1.0, 1.0)) ** 2)))
    parallax = rho * float(np.max(np.linalg.norm(c - center, axis=1)))
    if not parallax > scatter:
        return None
    e1, e2 = tangent_basis(m0)

    def direction(t):
        m = m0 + t[0] * e1 + t[1] * e2
        return m / np.sqrt(m @ m)

    def residuals(t):
        m = direction(t)
        return np.concatenate([_solve(_near_columns(n, P, up, m, rho, center), y, w)[1] for n, P, y, w in data])

    # x_scale: tangent offsets of a few degrees (0.05 rad) at most, the bounce's pull
    return direction(least_squares(residuals, np.zeros(2), x_scale=0.05).x), rho, center


def _near_model(used: list, geometry, up: np.ndarray, curve: float, lo: float, hi: float):
    """The used units under the near-light model: ``(units, curves, grid, best, rss_best, n_photos, stack)``
    or None (``stack`` the units' :class:`_StackedUnits`).

    In every photo with two or more spheres a point light is fitted (:func:`_fit_near_photo`) at the
    gamma ``curve`` and each unit gets the columns :func:`_near_columns` on the same pixels; a photo
    with one sphere keeps the distant model. The gamma is profiled over the whole range ``lo..hi``
    (the near light's shading may move it far from the distant model's), the lights refitted at the
    best gamma and the profile repeated on the fine grid around it (``curves`` over ``grid``, as the
    distant model's second round). ``n_photos`` counts the photos with a light. None when no photo
    has two spheres.
    """
    from scipy.optimize import minimize_scalar
    centers = np.array([np.asarray(c, dtype=np.float64).reshape(3) for c, _ in geometry])
    radii = np.array([float(r) for _, r in geometry])
    by_photo: dict[int, list[int]] = {}
    for i, u in enumerate(used):
        by_photo.setdefault(u.photo, []).append(i)
    if not any(len(ix) >= 2 for ix in by_photo.values()):
        return None
    best = curve
    grid = np.arange(lo, hi + 0.5 * _COARSE_STEP, _COARSE_STEP)
    for rnd in range(2):  # the lights at the current gamma, then the gamma under those lights
        units, n_near = list(used), 0
        for ix in by_photo.values():
            light = _fit_near_photo([used[i] for i in ix], centers, radii, up, best) if len(ix) >= 2 else None
            if light is None:
                continue
            n_near += 1
            m, rho, center = light
            for i in ix:
                u = used[i]
                n = u.normals
                A = _near_columns(n, centers[u.sphere] + radii[u.sphere] * n, up, m, rho, center)
                nu = _Unit(u.photo, u.sphere, u.raw, A, u.usable, base=u.base)
                nu.select(u.selected)
                units[i] = nu
        if n_near == 0:
            return None
        curves = np.array([u.rss_grid(grid) for u in units])
        k = int(np.argmin(curves.sum(axis=0)))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        stack = _StackedUnits(units, _SharedValues(units))
        res = minimize_scalar(lambda g: float(stack.rss([float(g)])[0]), bounds=(max(a, lo), min(b, hi)),
                              method="bounded", options={"xatol": 1e-4})
        best = float(res.x)
        if rnd == 0:
            grid = np.arange(max(lo, best - _FINE_HALF_WIDTH), min(hi, best + _FINE_HALF_WIDTH) + 0.5 * _GRID_STEP,
                             _GRID_STEP)
    return units, curves, grid, best, float(res.fun), n_near, stack


# ----------------------------------------------------------------------------- tone curves
def _fit_polynomial(stack: _StackedUnits, start: tuple, order: int,
                    min_slope: float = POLYNOMIAL_MIN_SLOPE) -> tuple[tuple, float]:
    """The polynomial response of ``order`` that minimises the summed ``RSS`` of the units of
    ``stack`` (:class:`_StackedUnits`, built once per set of units): (coefficients, RSS).

    ``start`` (a lower order's coefficients, or ``(gamma,)``) is padded with zeros. The units'
    selections and shading columns are fixed, each unit's coefficients profiled out in closed form
    (:meth:`_Unit.rss_grid`), so the objective is a smooth function of the ``order + 1``
    coefficients; :func:`scipy.optimize.minimize` (SLSQP) minimises it under the linear
    constraints that keep the curve increasing (the local log-log slope ``g + sum_j j a_j x^j`` at
    least ``min_slope`` on 65 codes across [0, 1]; ``g`` itself too), with the
    analytic gradient (:meth:`_Unit.rss_and_gradient`, for all the units at once: :class:`_StackedUnits`), the
    curve evaluated once over the units' shared values.
    """
    from scipy.optimize import minimize
    theta0 = np.zeros(order + 1)
    theta0[:len(start)] = start[:order + 1]
    x = np.linspace(0.0, 1.0, 65)
    C = np.column_stack([np.ones_like(x)] + [j * x ** j for j in range(1, order + 1)])

    shared = stack.shared

    def total(thetas) -> np.ndarray:
        return stack.rss([tuple(float(v) for v in t) for t in thetas])

    scale = float(total([theta0])[0]) or 1.0

    def fun(theta):
        shared.evaluate_partials(theta)
        rss, grad = stack.rss_and_gradient()
        return rss / scale, grad / scale

    theta0[0] = min(theta0[0], GAMMA_SEARCH[1])
    lo = min_slope
    bounds = [(lo, GAMMA_SEARCH[1])] + [(None, None)] * order
    res = minimize(fun, theta0, jac=True, method="SLSQP", bounds=bounds,
                   constraints=[{"type": "ineq", "fun": lambda t: C @ t - lo, "jac": lambda t: C}],
                   options={"maxiter": 200, "ftol": 1e-10})
    ok = np.all(C @ res.x >= lo - 1e-9) and res.x[0] <= GAMMA_SEARCH[1] + 1e-9
    theta = res.x if ok else theta0
    rss = float(total([theta])[0])
    if rss > scale:  # never worse than the start (a lower order's optimum)
        theta, rss = theta0, scale
    return tuple(float(v) for v in theta), rss


def _best_polynomial(stack: _StackedUnits, gamma: float, rss_gamma: float, noise: float, penalty: float,
                     max_order: int, min_slope: float = POLYNOMIAL_MIN_SLOPE) -> tuple[int, tuple, float, float]:
    """The polynomial response whose order the BIC chooses: (order, coefficients, RSS, score).

    Orders 1..``max_order`` are fitted in turn, each started from the last; the score is the BIC
    over the best gamma's, ``(RSS - RSS_gamma) / noise + order * penalty`` (the order's extra
    parameters over the gamma; ``noise`` the gamma's inflated noise variance, as for the named
    curves). The lowest score wins; ties keep the lower order.
    """
    best = (0, (gamma,), rss_gamma, float("inf"))
    theta = (gamma,)
    for order in range(1, max_order + 1):
        theta, rss = _fit_polynomial(stack, theta, order, min_slope=min_slope)
        score = (rss - rss_gamma) / noise + order * penalty
        if score < best[3]:
            best = (order, theta, rss, score)
    return best


# ----------------------------------------------------------------------------- methods
def calibrate_encoding_gamma(raw, normals, *, matte=None, terminator: float = 0.2, min_pixels: int = 40,
                             min_r2: float = 0.9, min_photos: int = MIN_PHOTOS, n_bootstrap: int = 400,
                             seed: int = 0, code_step: float | None = None, workers: int = 1, geometry=None,
                             up=UP, max_order: int = MAX_POLYNOMIAL_ORDER, shadow_side: bool = True,
                             own_shadow: bool = True) -> EncodingCalibration:
    """A gamma (and the sRGB curve) from the lit sides of matte spheres, profiled jointly with every light.

    Parameters
    ----------
    raw : sequence of sequence of (m_k, 3) float
        Per photo, per sphere, the stored values of the sphere's pixels normalised to [0, 1]
        (an 8-bit image divided by 255). Clipped values are recognised at 0.98 of full scale
        (any channel), near-black ones at 0.02 (every channel).
    normals : sequence of (m_k, 3) float
        Per sphere, the unit normals of those pixels (:attr:`ffls.spheres.samples.SphereSamples.normals`).
    matte : sequence of bool, optional
        Per sphere, whether it is matte; mirror and glossy spheres are left out. By default every
        sphere is tried, and a (photo, sphere) pair whose shading is not Lambertian (``min_r2``)
        is left out.
    terminator : float
        Pixels with ``n . l`` at or below this are left out (penumbra, the kink of Lambert's max).
    min_pixels : int
        Fewest selected pixels of a usable (photo, sphere) pair.
    min_r2 : float
        Least share of the shading variance the affine model must explain.
    min_photos : int
        Fewest photos with a usable sphere.
    n_bootstrap : int
        Bootstrap resamples of the photos.
    seed : int
        Seed of the bootstrap.
    code_step : float, optional
        One code value of the files, normalised (1/255 for 8 bits). When the BIC prefers the free
        gamma but the linear or sRGB curve decodes every stored value within half a code of it,
        that curve is named all the same: the files cannot tell them apart (module docstring,
        "Naming").
    workers : int
        Processes (forked) that select and profile the (photo, sphere) pairs; the result does not
        depend on it.
    geometry : sequence of (center (3,), radius), optional
        Per sphere, its centre and radius in the frame of ``normals`` (world units). Given, a near
        light is also tried (module docstring, "Near lights") in photos with two or more spheres.
    up : (3,) float
        The ground's normal in that frame (world ``+Z``), for the near model's bounce term.
    max_order : int
        Highest order of the polynomial response tried (module docstring, "Tone curves"); 0 tries
        none (the gamma family and sRGB only).
    shadow_side : bool
        Refit a polynomial that the lit sides name on the lit and attached-shadow sides, its
        log-log slope at least :data:`TONE_MIN_SLOPE` (module docstring, "The shadow side and the
        offset"); False keeps the lit sides' coefficients.
    own_shadow : bool
        The dark side's bounce less the sphere's own shadow on the ground (the world frame known).

    Returns
    -------
    EncodingCalibration

    Raises
    ------
    EncodingCalibrationError
        Too few usable photos, or a best gamma at an end of :data:`GAMMA_SEARCH`.
    """
    kwargs = dict(matte=matte, terminator=terminator, min_pixels=min_pixels, min_r2=min_r2, min_photos=min_photos,
                  n_bootstrap=n_bootstrap, seed=seed, code_step=code_step, workers=workers, geometry=geometry, up=up,
                  max_order=max_order, own_shadow=own_shadow)
    lit = _calibrate_encoding_gamma(raw, normals, shadow_side=False, **kwargs)
    if not shadow_side or lit.shading != "distant":
        return lit
    if lit.curve == "srgb" and lit.naming == "shown_codes":
        # the sRGB curve against the free gamma, where the lit sides show only codes on which the two
        # are alike up to a scale and an offset: the dark sides show the toe, where they differ, and
        # the gamma is named when they reject the sRGB curve (module docstring, "Naming"). The
        # gamma's value and interval stay the lit sides'
        try:
            dark = _calibrate_encoding_gamma(raw, normals, shadow_side=True,
                                             **{**kwargs, "geometry": None, "max_order": 0,
                                                "n_bootstrap": min(n_bootstrap, 100)})
        except EncodingCalibrationError:
            return lit
        if dark.n_dark_units == 0:
            return lit
        out = replace(lit, dark_srgb_excess=dark.srgb_excess, dark_bic_penalty=dark.bic_penalty,
                      n_dark_units=dark.n_dark_units)
        if dark.curve in ("srgb", "gamma") and dark.curve != lit.curve:
            out = replace(out, curve=dark.curve, naming="dark_sides")
        return out
    if lit.curve != "polynomial":
        return lit
    # the lit sides named a tone curve: its offset comes from the dark sides and the slope bound
    # (module docstring, "The shadow side and the offset"); the naming and its statistics stay the lit sides'
    try:
        # (the lit sides chose the distant shading; the dark run's bootstrap only sizes its BIC's noise)
        dark = _calibrate_encoding_gamma(raw, normals, shadow_side=True,
                                         **{**kwargs, "geometry": None, "n_bootstrap": min(n_bootstrap, 100)})
    except EncodingCalibrationError:
        return lit
    if dark.curve != "polynomial":
        return lit
    return replace(lit, order=dark.order, coefficients=dark.coefficients, dark_sides=True)


def _calibrate_encoding_gamma(raw, normals, *, matte, terminator, min_pixels, min_r2, min_photos, n_bootstrap, seed,
                              code_step, workers, geometry, up, max_order, shadow_side, own_shadow) -> EncodingCalibration:
    """:func:`calibrate_encoding_gamma`, on the lit sides alone or (``shadow_side``) with the dark sides."""
    from scipy.optimize import minimize_scalar
    normals = [np.asarray(n, dtype=np.float64).reshape(-1, 3) for n in normals]
    n_sph = len(normals)
    matte = [True] * n_sph if matte is None else [bool(m) for m in matte]
    if len(matte) != n_sph:
        raise ValueError(f"matte has {len(matte)} entries for {n_sph} spheres")
    if not any(matte):
        raise EncodingCalibrationError("no matte sphere: mirror and glossy spheres cannot calibrate the encoding")
    A = [np.column_stack([n, np.ones(len(n))]) for n in normals]
    units = []
    for p, per_photo in enumerate(raw):
        if len(per_photo) != n_sph:
            raise ValueError(f"photo {p} has {len(per_photo)} spheres, expected {n_sph}")
        for k, v in enumerate(per_photo):
            if not matte[k]:
                continue
            v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
            if len(v) != len(normals[k]):
                raise ValueError(f"photo {p}, sphere {k}: {len(v)} values for {len(normals[k])} normals")
            finite = np.all(np.isfinite(v), axis=1)
            v = np.where(finite[:, None], v, 0.0)
            usable = finite & ~np.any(v >= 0.98, axis=1) & ~np.all(v <= 0.02, axis=1)
            units.append(_Unit(p, k, _Codes.of(np.clip(v, 0.0, 1.0).T), A[k], usable))

    lo, hi = GAMMA_SEARCH
    coarse = np.arange(lo, hi + 0.5 * _COARSE_STEP, _COARSE_STEP)
    curve = 0.5 * (lo + hi)  # pilot selection: the middle of the range
    used, grid = units, coarse
    pool = _UnitPool(units, workers)
    shadow = _ShadowSide(np.asarray(up, dtype=np.float64).reshape(3), bool(own_shadow)) if shadow_side else None
    min_slope = TONE_MIN_SLOPE if shadow_side else POLYNOMIAL_MIN_SLOPE
    for rnd in range(2):  # select with the current curve, profile, repeat with the best gamma
        # the pilot curve may be far off: the shading test (min_r2) waits for the first round's gamma
        used, curves = pool.select_and_profile(curve, grid, terminator, min_pixels, min_r2 if rnd else -np.inf,
                                               shadow=shadow)
        if len(used):
            # a (photo, sphere) pair that no curve fits well (a wrong lit side, a cast shadow or an
            # interreflection the model lacks) is left out: its best RMS residual is an outlier
            best_ms = curves.min(axis=1) / np.array([u.selected.sum() for u in used])
            keep = best_ms <= _MAX_RMS_RATIO ** 2 * np.median(best_ms)
            used, curves = [u for u, k in zip(used, keep) if k], curves[keep]
        profiled = grid
        photos = sorted({u.photo for u in used})
        if len(photos) < min_photos:
            raise EncodingCalibrationError(
                f"only {len(photos)} photo{'s' if len(photos) != 1 else ''} show a matte sphere's shading clearly "
                f"enough (at least {min_photos} needed, of {len(raw)} photos)"
                + ("; if the sphere is a mirror or glossy ball (chrome, black glossy), it has no shading to "
                   "calibrate it from"
                   if not photos else ""))
        k = int(np.argmin(curves.sum(axis=0)))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        stack = _StackedUnits(used, _SharedValues(used))
        res = minimize_scalar(lambda g: float(stack.rss([float(g)])[0]), bounds=(a, b), method="bounded",
                              options={"xatol": 1e-4})
        best = curve = float(res.x)
        if rnd == 0 and max_order >= 1:
            # a tone curve no gamma follows: the second round selects the pixels (and tests each
            # unit's shading, min_r2) with the polynomial when it would be named (a rough BIC: the
            # residual variance uninflated); the naming below is made on the final pixels
            n_sel = sum(int(u.selected.sum()) for u in used)
            s2_pilot = float(res.fun) / max(n_sel - sum(u.A.shape[1] for u in used) - 1, 1)
            pen = math.log(max(n_sel, 3))
            order, coefs, _, score = _best_polynomial(stack, best, float(res.fun), s2_pilot, pen, max_order, min_slope)
            named = min((sum(u.rss(c) for u in used) - float(res.fun)) / s2_pilot for c in (1.0, "srgb"))
            if order and pen + score < min(named, pen):
                curve = coefs
        # the second round's grid (for the bootstrap): fine, around the first round's minimum
        grid = np.arange(max(lo, best - _FINE_HALF_WIDTH), min(hi, best + _FINE_HALF_WIDTH) + 0.5 * _GRID_STEP,
                         _GRID_STEP)
    rss_best = float(res.fun)
    fit = _profile_statistics(used, curves, profiled, best, rss_best, 0, n_bootstrap, seed)
    shading, shading_excess = "distant", None
    if geometry is not None:
        # the near-light model (module docstring, "Near lights"): chosen by the BIC over the distant one
        near_fit = _near_model(used, geometry, up, best, lo, hi)
        if near_fit is not None:
            near_used, near_curves, near_grid, near_best, near_rss, n_near, near_stack = near_fit
            k_distant = sum(u.A.shape[1] for u in used)
            k_near = sum(u.A.shape[1] for u in near_used) + _NEAR_PHOTO_PARAMS * n_near
            shading_excess = (rss_best - near_rss) / fit.noise - (k_near - k_distant) * fit.penalty
            if shading_excess > 0:
                shading = "near"
                used, curves, profiled, best, rss_best = near_used, near_curves, near_grid, near_best, near_rss
                stack = near_stack
                fit = _profile_statistics(used, curves, profiled, best, rss_best, _NEAR_PHOTO_PARAMS * n_near,
                                          n_bootstrap, seed)
    # (checked only now: a near light can bend a linear file's shading past the range's end under
    # the distant model; and a polynomial curve may still fit: checked after it)
    at_end = best <= lo + _GRID_STEP or best >= hi - _GRID_STEP
    photos = sorted({u.photo for u in used})
    n_pix, s2, inflation, sd_curv, sd_boot, sd_spheres = (fit.n_pixels, fit.s2, fit.inflation, fit.sd_curvature,
                                                          fit.sd_bootstrap, fit.sd_spheres)
    unc = 1.96 * max(sd_curv, sd_boot, sd_spheres)
    # model selection (BIC): a named curve has no free parameter, the best gamma one
    noise = s2 * inflation
    excess = (sum(u.rss("srgb") for u in used) - rss_best) / noise
    lin_excess = (sum(u.rss(1.0) for u in used) - rss_best) / noise
    penalty = fit.penalty
    scores = [("linear", lin_excess), ("srgb", excess), ("gamma", penalty)]
    order, coefs, poly_excess, poly_rms = 0, (), None, None
    if max_order >= 1:
        # a camera's tone curve (toe, shoulder) that no gamma follows: a polynomial response, its order
        # chosen by the BIC, scored against the named curves in the same units (module docstring)
        order, coefs, rss_poly, score = _best_polynomial(stack, best, rss_best, noise, penalty, max_order,
                                                          min_slope)
        if order:
            poly_excess, poly_rms = score, math.sqrt(rss_poly / n_pix)
            # a tone curve is the camera's: every sphere alone must pay for its parameters. A misfit
            # of the shading model (a near light, interreflection) that the polynomial absorbs is
            # each sphere's own, and does not lower every sphere's misfit that much (module docstring)
            # over the curve that would be named without it (linear, sRGB: no parameter; the gamma: one)
            base, _ = min(scores, key=lambda t: t[1])
            base_curve, base_params = {"linear": (1.0, 0), "srgb": ("srgb", 0), "gamma": (best, 1)}[base]
            gain: dict[int, float] = {}
            for u in used:
                gain[u.sphere] = gain.get(u.sphere, 0.0) + u.rss(base_curve) - u.rss(coefs)
            if min(gain.values()) / noise > (order + 1 - base_params) * penalty:
                scores.append(("polynomial", penalty + score))
    name, _ = min(scores, key=lambda t: t[1])
    if at_end and name != "polynomial":
        raise EncodingCalibrationError(
            f"the spheres' shading fits no gamma between {lo} and {hi} (best at {best:.2f})"
            + ("" if poly_excess is None else " and no polynomial curve fits better"))
    naming = "bic"
    if name == "polynomial" and code_step is not None:
        # as below: a simpler curve that decodes every stored value within half a code of the
        # polynomial is the same curve as far as the file can tell
        x = np.linspace(0.0, 1.0, 1025)
        fx = polynomial_response(x, coefs)
        gap, closest = min((float(np.max(np.abs(_decode(x, c) - fx))), n)
                           for c, n in ((best, "gamma"), (1.0, "linear"), ("srgb", "srgb")))
        if gap <= 0.5 * code_step:
            name, naming = closest, "half_code"
    if name == "gamma" and code_step is not None:
        # a named curve that decodes every stored value within half a code of the best gamma is the
        # same curve as far as the file can tell (the BIC is blind to a misfit the model shares)
        x = np.linspace(0.0, 1.0, 1025)
        near = [(float(np.max(np.abs(_decode(x, c) - _decode(x, best)))), n) for c, n in ((1.0, "linear"), ("srgb", "srgb"))]
        gap, closest = min(near)
        if gap <= 0.5 * code_step:
            name, naming = closest, "half_code"
        else:
            # the shading model sees a curve only up to a scale (the light's) and an offset (the
            # ambient term), and only over the codes the spheres show, where what is left of the
            # difference between two curves is a bend of the shading along n . l. A named curve
            # that is the best gamma's affine map, over those codes, within the bend the pairs'
            # shading shows beyond their model anyway cannot be told from it by these pixels (an
            # sRGB file whose lit sides hold codes 0.44-0.91 is gamma 2.275 there to 0.14 of a code,
            # and its pairs bend by 0.17), and the one with no free parameter is named (module
            # docstring, "Naming")
            gap, closest = min((float(np.median([_affine_gap(*_shown_values([u]), c, best) for u in used])), n)
                               for c, n in ((1.0, "linear"), ("srgb", "srgb")))
            if gap <= _shading_bend(used, best):
                name, naming = closest, "shown_codes"
    values, _ = _shown_values(used)
    return EncodingCalibration(
        curve=name, gamma=best, uncertainty=unc, sd_curvature=sd_curv, sd_bootstrap=sd_boot,
        srgb_excess=float(excess), linear_excess=float(lin_excess), bic_penalty=penalty,
        rms=math.sqrt(rss_best / n_pix), method="gamma",
        n_spheres=len({u.sphere for u in used}), n_photos=len(photos), n_units=len(used), n_pixels=n_pix,
        sd_spheres=sd_spheres, shading=shading,
        shading_excess=None if shading_excess is None else float(shading_excess),
        order=order, coefficients=coefs, polynomial_excess=None if poly_excess is None else float(poly_excess),
        polynomial_rms=poly_rms, naming=naming, shown_codes=(float(values[0]), float(values[-1])),
        n_dark_units=sum(1 for u in used if u.A.shape[1] == _DARK_COLUMNS))


def calibrate_encoding(raw, normals, method: str = "gamma", **kwargs) -> EncodingCalibration:
    """The encoding of integer images from the shading of matte spheres (module docstring).

    Parameters
    ----------
    raw : sequence of sequence of (m_k, 3) float
        Per photo, per sphere, the stored values of the sphere's pixels normalised to [0, 1].
    normals : sequence of (m_k, 3) float
        Per sphere, the unit normals of those pixels.
    method : {'gamma'}
        :func:`calibrate_encoding_gamma` (a continuous gamma, with the sRGB curve as a candidate).
    **kwargs
        Passed to the method.

    Returns
    -------
    EncodingCalibration

    Raises
    ------
    EncodingCalibrationError
        The spheres cannot calibrate it.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, not {method!r}")
    return calibrate_encoding_gamma(raw, normals, **kwargs)


def _ask(message: str) -> str:
    return (f"cannot calibrate the encoding: {message}; state \"encoding\" (\"srgb\", \"linear\" or "
            f"{{\"gamma\": g}}) in {CAPTURE_FILE}")


def calibrate_capture_encoding(capture, spheres=None, matte=None, method: str = "gamma", progress=None,
                               decoded=None, **kwargs) -> tuple[EncodingCalibration, list]:
    """Calibrate the encoding of a capture whose ``capture.json`` states none.

    The spheres are found on the stored values (a monotone curve keeps their outlines), unless
    given; their pixels are read from every photo and passed to :func:`calibrate_encoding`, with
    their world centres and radii (``geometry``: a near light is tried) unless the camera is
    orthographic (no depth, so no light position).

    Parameters
    ----------
    capture : ffls.io.capture.Capture
        Integer images (8 or 16 bits).
    spheres : list of SphereFit, optional
        As :func:`ffls.spheres.detect.find_spheres_in_capture` returns (found when None).
    matte : sequence of bool, optional
        Per sphere, whether it is matte (default: every sphere that ``capture.json`` does not
        declare a mirror, :func:`ffls.io.capture.sphere_materials`; see :func:`calibrate_encoding_gamma`).
    method : {'gamma'}
    progress : callable, optional
        A wrapper such as ``tqdm.tqdm``, called as ``progress(iterable, total=n, desc=...)``.
    decoded : ffls.spheres.estimate.DecodedPhotos, optional
        The photos decoded once, as stored (:func:`ffls.spheres.estimate.decode_photos` of this
        capture: ``stored``): the spheres are found on its reductions and the spheres' values
        read from its codes, no photo is read again (the same numbers as reading them).
    **kwargs
        Passed to the method; ``workers`` also to the sphere detection
        (:func:`ffls.spheres.detect.find_spheres_in_capture`).

    Returns
    -------
    calibration : EncodingCalibration
    spheres : list of SphereFit
        The spheres used (to estimate the lights with, once the photos are linearised).

    Raises
    ------
    InputError
        Naming ``capture.json``: floating-point images (linear by definition), mixed bit depths,
        or spheres that cannot calibrate the encoding (one line asking for ``"encoding"``).
    """
    from ffls.spheres.detect import find_spheres_in_capture
    from ffls.spheres.estimate import capture_samples

    workers = kwargs.get("workers", 1)  # (also the detection's: the same spheres for any number)
    first = read_image(capture.image_paths[0])
    if first.bit_depth not in (8, 16):
        raise InputError(f"the images are {first.bit_depth} floating point, linear by definition: nothing to "
                         "calibrate", capture.image_paths[0])
    if decoded is not None and not (decoded.stored and decoded.raw is not None and decoded.bit_depths == {first.bit_depth}):
        decoded = None  # not the stored codes of every photo (over the memory budget, mixed depths): read them
    if spheres is None and decoded is not None:
        try:
            spheres = find_spheres_in_capture(replace(capture, encoding="linear"), stats=decoded.stats,
                                              bit_depths=decoded.bit_depths, workers=workers)
        except InputError as first_error:  # as below: the sRGB-decoded values (read again, in this rare case)
            try:
                spheres = find_spheres_in_capture(replace(capture, encoding="srgb"), workers=workers)
            except InputError:
                raise first_error from None
    if spheres is None:
        # The outlines survive a monotone curve, but the detection's thresholds (edge noise, shading
        # ratio) are set for radiance: a curve that compresses contrast (gamma-encoded files on a
        # grey ground) can hide every candidate. Search the stored values, then the same values
        # decoded as sRGB, which undoes most of a camera's compression; this only finds the
        # spheres, the encoding is still calibrated from them below.
        try:
            spheres = find_spheres_in_capture(replace(capture, encoding="linear"), workers=workers)
        except InputError as first_error:
            try:
                spheres = find_spheres_in_capture(replace(capture, encoding="srgb"), workers=workers)
            except InputError:
                raise first_error from None
    if matte is None:  # a sphere capture.json declares a mirror (chrome, black glossy) has no shading to fit
        from ffls.io.capture import sphere_materials

        matte = [m != "mirror" for m in sphere_materials(capture, len(spheres))]
    h, w = first.shape
    samples = capture_samples(capture, spheres, (h, w))
    it = range(len(capture))
    if progress is not None and decoded is None:
        it = progress(it, total=len(capture), desc="encoding")
    raw = []
    if decoded is not None:  # the codes as ffls.io.images reads them (codes / top, float32), at the spheres' pixels
        top = np.float32(2 ** first.bit_depth - 1)
        it = ()
        raw = [[(decoded.raw[i][s.rows, s.cols].astype(np.float32) / top).astype(np.float64) for s in samples]
               for i in range(len(capture))]
    for i in it:
        img = first if i == 0 else read_image(capture.image_paths[i])
        if img.bit_depth != first.bit_depth:
            raise InputError(f"bit depth {img.bit_depth} differs from the first image's ({first.bit_depth}); with no "
                             f"'encoding' in {CAPTURE_FILE} a capture must not mix depths", img.path)
        if img.shape != (h, w):
            raise InputError(f"image is {img.shape[1]}x{img.shape[0]} but the first image is {w}x{h}", img.path)
        raw.append([np.asarray(img.pixels[s.rows, s.cols], dtype=np.float64) for s in samples])
    try:
        kwargs.setdefault("code_step", 1.0 / (2 ** first.bit_depth - 1))
        # the estimator's shadow-side bounce takes the sphere's own shadow where the world frame is known
        kwargs.setdefault("own_shadow", not getattr(capture, "world_from_camera_is_default", False))
        if getattr(capture, "camera_model", "pinhole") != "orthographic":
            # the spheres' world centres and radii place a near light (an orthographic camera sees no depth)
            kwargs.setdefault("geometry", [(s.center, s.radius) for s in samples])
        cal = calibrate_encoding(raw, [s.normals for s in samples], method=method, matte=matte, **kwargs)
    except EncodingCalibrationError as e:
        raise InputError(_ask(str(e)), capture.json_path) from None
    # a polynomial curve linearises the photos through a table of every code of their depth
    return replace(cal, bits=int(first.bit_depth)), spheres
