"""A near light's direction error from its distance's error (issue 9, items 2 and 5).

A near light triangulated by spheres that stand off the scene centre (the matte row of a mixed
capture) is reported from the centre: its distance's error turns its direction by the parallax.
"""
from dataclasses import replace

import numpy as np
import pytest

from ffls.conventions import normalize
from ffls.spheres.lambert import LambertFit
from ffls.spheres.photo import PhotoEstimate, SphereResult
from ffls.spheres.uncertainty import FALLBACK_MODEL, distance_coupling_deg, distance_spread


def _cov_along(u, sd_along, sd_across=1e-4):
    """A position covariance long along the unit vector ``u``."""
    u = normalize(np.asarray(u, dtype=np.float64))
    return sd_along ** 2 * np.outer(u, u) + sd_across ** 2 * (np.eye(3) - np.outer(u, u))


def test_coupling_is_the_parallax_of_the_triangulating_spheres():
    """Spheres 0.25 m off the centre triangulate a light 2 m away along their own ray: a distance
    error of a fraction f turns the direction from the centre by about f * 0.25 / 2 rad (the
    parallax); spheres around the centre place it along the centre's ray, and the distance
    does not turn the direction."""
    light = np.array([2.0, 0.0, 0.3])
    place = np.array([0.0, -0.25, 0.0])  # the triangulating spheres' midpoint
    ray = normalize(light - place)
    slope = distance_coupling_deg(light, _cov_along(ray, 0.1))
    # exact: move the light along its ray from the spheres by 1% of its distance from the centre
    t = 0.01 * np.linalg.norm(light) / (ray @ normalize(light))
    turned = np.degrees(np.arccos(normalize(light) @ normalize(light + t * ray)))
    assert slope == pytest.approx(turned / 0.01, rel=0.02)
    assert 5.0 < slope < 10.0  # about 0.25 m / 2 m of parallax, in degrees
    assert distance_coupling_deg(light, _cov_along(normalize(light), 0.1)) == pytest.approx(0.0, abs=1e-3)
    assert distance_coupling_deg(light, np.full((3, 3), np.nan)) == 0.0


def test_distance_spread_is_robust_and_relative():
    rng = np.random.default_rng(3)
    d = 2.0 * np.exp(0.03 * rng.normal(size=400))
    assert distance_spread(d) == pytest.approx(0.03, rel=0.15)
    assert distance_spread(10.0 * d) == pytest.approx(distance_spread(d), rel=1e-9)
    assert distance_spread(np.r_[d, 1e6, 1e-6]) == pytest.approx(distance_spread(d), rel=0.05)
    assert distance_spread([2.0, 2.1]) == 0.0


def test_a_near_photo_cone_holds_its_distance_error():
    """The cone of a near photo whose direction turns with its distance widens by that turn under
    the capture's distance error, and one whose does not stays as it was."""
    fit = LambertFit(status="ok", direction=np.array([0.0, 0.0, 1.0]), intensity=1.0, rms=0.01,
                     uncertainty_deg=0.2)
    photo = PhotoEstimate(status="ok", reason=None, direction=np.array([0.0, 0.0, 1.0]),
                          position=np.array([0.0, 0.0, 2.0]), model="near", used_spheres=[0, 1],
                          spheres=[SphereResult(fit, "ok"), SphereResult(fit, "ok")], weights=[1.0, 1.0])
    model = replace(FALLBACK_MODEL, distance_sigma=0.05)
    plain = photo.with_error_model(model).uncertainty_deg
    coupled = replace(photo, distance_coupling_deg=8.0).with_error_model(model).uncertainty_deg
    sigma = FALLBACK_MODEL.photo_sigma_deg(np.array([0.2, 0.2]) / np.sqrt(2.0), [0, 1], [1.0, 1.0])
    assert plain == pytest.approx(FALLBACK_MODEL.cone_deg(sigma), rel=1e-9)
    assert coupled == pytest.approx(model.cone_deg(np.hypot(sigma, 8.0 * 0.05 / np.sqrt(2.0))), rel=1e-9)
    assert coupled > plain
    # a distant capture (no distance error) is unchanged
    assert replace(photo, distance_coupling_deg=8.0).with_error_model(FALLBACK_MODEL).uncertainty_deg \
        == pytest.approx(plain, rel=1e-12)
