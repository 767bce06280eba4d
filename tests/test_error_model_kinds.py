"""The error model's own terms per sphere kind (issue 9, items 2 and 5): matte shading and mirror
highlights err differently, and one scale and floor for both let either set the other's cone."""
import json

import numpy as np
import pytest

from ffls.spheres.uncertainty import ErrorModel, fit_error_model


def mixed_capture(rng, n_photos=200, tau=(0.05, 3.0), stat=((0.2, 0.6), (0.3, 0.8)), kinds=(0, 0, 1, 1)):
    """Per photo: spheres of kind 0 (matte: floor ``tau[0]``) and 1 (mirror: ``tau[1]``), per-axis
    sd ``sqrt(sigma^2 + tau^2)`` (degrees) about the photo's truth; offsets from the photo's
    inverse-variance mean (what the photo sees), the statistics, and the true error of that mean
    and of the kind-0 spheres' own mean."""
    kinds = np.asarray(kinds)
    res, sig, err, err_matte = [], [], [], []
    for _ in range(n_photos):
        s = np.array([rng.uniform(*stat[k]) for k in kinds])
        sd = np.radians(np.hypot(s, np.asarray(tau)[kinds]))
        e = rng.normal(size=(kinds.size, 2)) * sd[:, None]
        w = 1.0 / sd ** 2
        mean = (w[:, None] * e).sum(0) / w.sum()
        res.append(e - mean)
        sig.append(s)
        m0 = (w[kinds == 0, None] * e[kinds == 0]).sum(0) / w[kinds == 0].sum()
        err.append(np.degrees(np.linalg.norm(mean)))
        err_matte.append(np.degrees(np.linalg.norm(m0)))
    return res, sig, np.array(err), np.array(err_matte)


def test_each_kind_gets_its_own_floor(rng=np.random.default_rng(31)):
    """Two matte balls (floor 0.05 deg, honest statistics of 0.2-0.6) and two mirror balls (floor 3
    deg beside statistics of 0.3-0.8): the shared fit puts one floor
    between them; with the kinds, each kind's floor is its own, and the cone of a direction made
    from the matte balls alone covers its truth 90-98% of the time (the shared floor's is far too
    wide)."""
    res, sig, err, err_matte = mixed_capture(rng)
    spheres = [np.arange(4)] * len(res)
    shared = fit_error_model(res, sig, spheres=spheres, common_correlation=0.0)
    m = fit_error_model(res, sig, spheres=spheres, kinds=["matte", "matte", "mirror", "mirror"],
                        common_correlation=0.0)
    terms = {k: (s, t) for k, s, t, _ in m.kind_terms}
    assert set(terms) == {"matte", "mirror"}
    assert terms["matte"][1] < 0.2 and terms["matte"][0] == pytest.approx(1.0, rel=0.15), m
    assert terms["mirror"][1] == pytest.approx(3.0, rel=0.2), m
    assert not shared.kind_terms
    # the matte balls' own direction: its cone under each model (no common mode here but its floor)
    idx = np.array([0, 1])
    cones = np.array([m.cone_deg(m.photo_sigma_deg(s[:2], idx)) for s in sig])
    cones_shared = np.array([shared.cone_deg(shared.photo_sigma_deg(s[:2], idx)) for s in sig])
    assert 0.9 <= np.mean(err_matte <= cones) <= 0.99
    assert np.median(cones_shared) > 2.5 * np.median(cones)  # the mirrors' floor, given to the matte balls
    # and the photos' directions (all four) stay covered
    cov_all = np.mean([e <= m.cone_deg(m.photo_sigma_deg(s, np.arange(4))) for e, s in zip(err, sig)])
    assert 0.9 <= cov_all <= 0.99, cov_all
    # the per-sphere terms follow the kinds; a sphere of no kind has the shared ones
    s_, t_ = m.terms(np.array([0, 2, 7]), (3,))
    assert t_[0] == terms["matte"][1] and t_[1] == terms["mirror"][1] and t_[2] == m.floor_deg


def test_one_of_each_kind_per_photo_keeps_the_shared_fit(rng=np.random.default_rng(32)):
    """A calibration shot of one grey ball and one chrome ball: no photo holds two spheres of a kind,
    so their disagreement cannot tell the kinds apart and the shared fit is kept, unchanged."""
    res, sig, _, _ = mixed_capture(rng, n_photos=120, kinds=(0, 1))
    spheres = [np.arange(2)] * len(res)
    shared = fit_error_model(res, sig, spheres=spheres)
    m = fit_error_model(res, sig, spheres=spheres, kinds=["matte", "mirror"])
    assert m == shared and not m.kind_terms


def test_one_kind_keeps_the_shared_fit(rng=np.random.default_rng(33)):
    """Four matte balls: the shared fit is the matte kind's, and nothing changes."""
    res, sig, _, _ = mixed_capture(rng, n_photos=120, kinds=(0, 0, 0, 0))
    spheres = [np.arange(4)] * len(res)
    assert fit_error_model(res, sig, spheres=spheres, kinds=["matte"] * 4) == \
        fit_error_model(res, sig, spheres=spheres)


def test_kind_terms_round_trip_through_the_dict(rng=np.random.default_rng(34)):
    res, sig, _, _ = mixed_capture(rng, n_photos=80)
    m = fit_error_model(res, sig, spheres=[np.arange(4)] * len(res), kinds=["matte", "matte", "mirror", "mirror"])
    assert m.kind_terms
    back = ErrorModel.from_dict(json.loads(json.dumps(m.as_dict())))
    assert back == m
    stat = np.array([0.1, 0.1, 0.7, 0.7])
    assert back.budget(stat, np.arange(4)) == m.budget(stat, np.arange(4))
