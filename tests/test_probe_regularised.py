"""Hougen-Ahuja inside the Lambertian ambiguity (issue 11): the minimum-energy penalty and its CV weight.

A diffuse ball sees only the low orders of its lighting; NNLS returns a vertex of the maps that
fit it, which gathers light spread over many directions into a few sources. Scenes are small
(48 px balls, maps 32 rows).
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import latlong_directions
from ffls.errors import InputError
from ffls.lightmaps.lightmap import LightMap
from ffls.probes.evaluate import map_error
from ffls.probes.hougen_ahuja import cell_solid_angles, hougen_ahuja
from ffls.probes.linear import lambert_matrix, solve_sources
from ffls.probes.selection import select_regularization
from ffls.probes.sources import cell_energies, geodesic_level, geodesic_sources, split_sources
from ffls.synth.probe_scenes import diffuse_sphere_scene

KW = {"nonnegative": True, "ambient": "nonnegative"}


@pytest.fixture(scope="module")
def band_map():
    """Light spread evenly over a band 2-20 degrees high and 160 degrees of azimuth, over a dim sky."""
    h = 32
    w = latlong_directions(2 * h, h)
    el = np.degrees(np.arcsin(w[..., 2]))
    az = np.degrees(np.arctan2(w[..., 1], w[..., 0]))
    L = np.full((h, 2 * h, 3), 0.02)
    L[(el > 2) & (el < 20) & (az > -170) & (az < -10)] += 1.0
    return L


@pytest.fixture(scope="module")
def band_sphere(band_map):
    return diffuse_sphere_scene(LightMap(band_map.astype(np.float32), "latlong", "band"), 48, albedo=0.7)


def top_share(x, k=10):
    p = np.sort(np.abs(np.asarray(x)).sum(axis=1))[::-1]
    return float(p[:k].sum() / p.sum())


def test_cell_solid_angles_cover_the_domain():
    full = cell_solid_angles(geodesic_sources(3))
    assert full.shape == (92,) and np.all(full > 0)
    assert abs(full.sum() - 4 * np.pi) < 1e-9
    assert abs(cell_solid_angles(geodesic_sources(3, "upper"), "upper").sum() - 2 * np.pi) < 1e-9
    # an adaptive set: a split source's children have about a quarter of its cell
    d, lev = split_sources(geodesic_level(3, 0), np.zeros(92, int), [0], 3)
    om = cell_solid_angles(d)
    assert abs(om.sum() - 4 * np.pi) < 1e-9
    assert np.median(om[lev == 1]) < 0.4 * np.median(om[lev == 0])


def test_energy_penalty_spreads_what_nnls_concentrates(band_map, band_sphere):
    d = geodesic_sources(6)
    truth = top_share(cell_energies(d, band_map))
    plain = hougen_ahuja(band_sphere.normals, band_sphere.radiance, 0.7, d, **KW)
    reg = hougen_ahuja(band_sphere.normals, band_sphere.radiance, 0.7, d, energy=0.01, **KW)
    # the vertex solution gathers the band into fewer, stronger sources than the truth has
    assert top_share(plain.intensities) > truth + 0.1
    assert abs(top_share(reg.intensities) - truth) < 0.5 * abs(top_share(plain.intensities) - truth)
    # ... and the penalised map is much nearer the true one, for the same fit of the ball
    assert map_error(reg.latlong(32), band_map) < 0.5 * map_error(plain.latlong(32), band_map)
    assert reg.relative_rms < 2 * plain.relative_rms + 1e-3
    assert np.all(reg.intensities >= 0) and np.all(reg.ambient >= 0)


def test_energy_zero_is_the_papers_fit(band_sphere):
    d = geodesic_sources(3)
    a = hougen_ahuja(band_sphere.normals, band_sphere.radiance, 0.7, d, **KW)
    b = hougen_ahuja(band_sphere.normals, band_sphere.radiance, 0.7, d, energy=0.0, **KW)
    np.testing.assert_array_equal(a.intensities, b.intensities)


def test_energy_makes_a_rank_deficient_least_squares_solvable(band_sphere):
    d = geodesic_sources(6)  # 362 sources: rank deficient on a Lambertian ball
    with pytest.raises(InputError, match="singular system"):
        hougen_ahuja(band_sphere.normals, band_sphere.radiance, 0.7, d)
    fit = hougen_ahuja(band_sphere.normals, band_sphere.radiance, 0.7, d, energy=0.01)
    assert np.all(np.isfinite(fit.intensities)) and fit.relative_rms < 0.05


def test_solve_sources_energy_needs_positive_cells():
    M = lambert_matrix(geodesic_sources(2), geodesic_sources(1))
    b = M @ np.ones((M.shape[1], 1))
    with pytest.raises(ValueError, match="solid angles"):
        solve_sources(M, b, energy=0.1)
    with pytest.raises(ValueError, match="cell_solid_angles"):
        solve_sources(M, b, energy=0.1, cell_solid_angles=np.zeros(M.shape[1]))


def test_select_regularization_follows_its_rule(band_sphere):
    d = geodesic_sources(4)
    args = (band_sphere.normals, band_sphere.radiance, 0.7, d)
    low = select_regularization(*args, rule="min", **KW)
    se = select_regularization(*args, **KW)
    assert low.candidates == se.candidates == [0.0, 0.001, 0.003, 0.01, 0.03]
    np.testing.assert_allclose(low.scores, se.scores)
    assert low.chosen == low.candidates[int(np.argmin(low.scores))]
    # one standard error: never less regularised than the lowest held-out error, and the fit is the
    # plain fit with the chosen weight
    assert se.chosen >= low.chosen and se.criterion == "cv"
    ref = hougen_ahuja(*args, energy=se.chosen, **KW)
    np.testing.assert_allclose(se.fit.intensities, ref.intensities)
    assert "energy penalty" in se.note and f"{se.chosen:g}" in se.note
    sm = select_regularization(*args, (0.0, 0.01), penalty="smoothness", **KW)
    assert sm.chosen in (0.0, 0.01) and sm.scores.shape == (2,)


@pytest.mark.parametrize("kw, msg", [({"weights": (0.01, 0.001)}, "increasing"), ({"weights": ()}, "increasing"),
                                     ({"weights": (0.0, -1.0)}, "increasing"), ({"penalty": "ridge"}, "penalty"),
                                     ({"rule": "best"}, "rule")])
def test_select_regularization_rejects_bad_options(band_sphere, kw, msg):
    with pytest.raises(ValueError, match=msg):
        select_regularization(band_sphere.normals, band_sphere.radiance, 0.7, geodesic_sources(2), **kw)
