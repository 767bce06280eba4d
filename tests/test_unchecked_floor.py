"""A floor the disagreement cannot measure (issue 9): beside a much less certain sphere, a sphere's
own floor does not show in its photos' scatter, and the fit must not let it fall to zero."""
import json

import numpy as np
import pytest

from ffls.spheres.uncertainty import FALLBACK_MODEL, ErrorModel, fit_error_model, unchecked_floor_deg


def capture(rng, n_photos, stat, tau, scale=None):
    """Per photo one sphere per entry of ``stat`` (per-axis statistics, degrees, each drawn within
    ``(lo, hi)``) whose true per-axis sd is ``hypot(scale * sigma, tau)`` (degrees); offsets from
    the photo's inverse-variance mean (what the photo sees), the statistics, and each sphere's
    true error (degrees)."""
    stat, tau = np.asarray(stat, dtype=float).reshape(-1, 2), np.asarray(tau, dtype=float)
    scale = np.ones(len(tau)) if scale is None else np.asarray(scale, dtype=float)
    res, sig, err = [], [], []
    for _ in range(n_photos):
        s = rng.uniform(stat[:, 0], stat[:, 1])
        sd = np.radians(np.hypot(scale * s, tau))
        e = rng.normal(size=(len(tau), 2)) * sd[:, None]
        w = 1.0 / sd ** 2
        res.append(e - (w[:, None] * e).sum(0) / w.sum())
        sig.append(s)
        err.append(np.degrees(np.linalg.norm(e, axis=1)))
    return res, sig, np.array(err)


@pytest.mark.parametrize("seed", [41, 42, 43])
def test_a_grey_ball_beside_a_chrome_ball_keeps_a_floor(seed):
    """A calibration shot: a grey ball (statistics 0.04-0.06 deg, its own floor 0.15 deg) and a chrome
    ball (statistics 1-4 deg, a quarter of them its true error) per photo. The chrome ball's scaled
    sigma explains most of the disagreement, and the fitted floor is whatever the chance scatter
    makes it (on bench row c17, 0.0006 deg). Its floor is not measured, so it gets the profile bound (at most the
    fallback's), and its cone covers it; the chrome ball's floor, which the grey ball measures,
    is not raised."""
    rng = np.random.default_rng(seed)
    res, sig, err = capture(rng, 80, ((0.04, 0.06), (1.0, 4.0)), (0.15, 0.0), (1.0, 0.25))
    spheres = [np.arange(2)] * len(res)
    m = fit_error_model(res, sig, spheres=spheres, kinds=["matte", "mirror"])
    assert len(m.sphere_floor_deg) == 2 and m.sphere_floor_deg[1] == 0.0, m
    assert 0.15 <= m.sphere_floor_deg[0] <= FALLBACK_MODEL.floor_deg + 1e-12, m
    cones = np.array([m.cone_deg(m.sphere_sigma_deg(s[0], 0)) for s in sig])
    assert np.mean(err[:, 0] <= cones) >= 0.95
    # the photo's own cone (inverse-variance mean of both) covers the grey ball too
    assert np.mean(err[:, 0] <= np.array([m.cone_deg(m.photo_sigma_deg(s, np.arange(2))) for s in sig])) >= 0.95


def test_equally_certain_spheres_keep_their_fitted_floor(rng=np.random.default_rng(44)):
    """Four grey balls of equal statistics check each other: every floor is measured, none is
    raised, and the model is the one the fit gives."""
    res, sig, _ = capture(rng, 80, [(0.15, 0.25)] * 4, (0.1, 0.1, 0.1, 0.1))
    spheres = [np.arange(4)] * len(res)
    m = fit_error_model(res, sig, spheres=spheres)
    assert m.sphere_floor_deg == ()
    var = [np.radians(m.sphere_sigma_deg(s, np.arange(4))) ** 2 for s in sig]
    assert not np.any(unchecked_floor_deg(res, var, spheres, 4))


def test_a_floor_the_profile_bounds_below_the_fallback(rng=np.random.default_rng(45)):
    """A second sphere three times less certain than the first (not twenty) still bounds the first's
    floor, above its own sigma: the floor is the profile bound, below the fallback's cap."""
    res, sig, _ = capture(rng, 200, ((0.1, 0.1), (0.3, 0.3)), (0.0, 0.0))
    var = [np.radians(s) ** 2 for s in sig]
    f = unchecked_floor_deg(res, var, [np.arange(2)] * len(res), 2)
    assert 0.1 < f[0] < FALLBACK_MODEL.floor_deg and f[1] == 0.0, f


def test_sphere_floors_round_trip_through_the_dict(rng=np.random.default_rng(46)):
    res, sig, _ = capture(rng, 80, ((0.04, 0.06), (1.0, 4.0)), (0.15, 0.0), (1.0, 0.25))
    m = fit_error_model(res, sig, spheres=[np.arange(2)] * len(res))
    assert m.sphere_floor_deg
    back = ErrorModel.from_dict(json.loads(json.dumps(m.as_dict())))
    assert back.sphere_floor_deg == pytest.approx(m.sphere_floor_deg)
    assert back.sphere_sigma_deg(0.05, 0) == pytest.approx(m.sphere_sigma_deg(0.05, 0))
