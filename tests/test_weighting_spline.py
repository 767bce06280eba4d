"""The ``spline`` weighting (ffls.weights.spline): local thin-plate splines blended by
the barycentric coordinates.

Contracts tested: weights sum to 1 per direction (power conserved to 1e-10 relative, exact and
texture paths, upper and full); they interpolate (weight 1 at a light's own direction); their
Lebesgue function stays under ``max_lebesgue``; ``blend=0`` or ``max_lebesgue=1`` is barycentric;
the weights change smoothly with tiny rotations; degenerate captures (1 to 3 lights, duplicates,
a 10-degree cap, lights on the horizon) keep the contracts; on a smooth function the spline
interpolates better than barycentric; the GPU pass 1 matches the texture reference; its flicker
under a rotating sun is at least 5x below voronoi's.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from ffls.conventions import rotation_ypr, rotation_z
from ffls.lightmaps.lightmap import paper_map, sky_sun_map
from ffls.weights.weighting import (EXTRA_SCHEMES, SCHEMES, Weighting, bake_weights, cell_weights, integrate,
                                    light_weights, texture_slots)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from directions import random_directions  # noqa: E402  (tests/directions.py, beside this file)


def test_spline_is_offered_and_checks_its_options():
    assert "spline" in SCHEMES and "spline" not in EXTRA_SCHEMES
    assert texture_slots("spline") == 24
    with pytest.raises(ValueError, match="blend"):
        Weighting(random_directions(10), "spline", blend=1.5)
    with pytest.raises(ValueError, match="max_lebesgue"):
        Weighting(random_directions(10), "spline", max_lebesgue=0.5)
    with pytest.raises(ValueError, match="k must be"):
        Weighting(random_directions(10), "spline", k=3)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 40, 120])
def test_sums_to_one_interpolates_and_is_bounded(n):
    d = random_directions(n, 1)
    for bound in (8.0, 2.0):  # the default, and a tight one
        wt = Weighting(d, "spline", max_lebesgue=bound)
        sw = wt(random_directions(4000, 2))
        np.testing.assert_allclose(sw.weight.sum(axis=1), 1.0, rtol=0, atol=1e-12)
        assert np.all((sw.index >= 0) | (sw.weight == 0)) and sw.index.max() < n
        # the bound is enforced on samples of each star; between samples it may exceed it slightly
        lebesgue = np.abs(sw.dense(n)).sum(axis=1)
        assert lebesgue.max() <= bound * 1.1, (bound, lebesgue.max())
        if n > 5:
            assert sw.weight.min() < -1e-3  # a higher-order interpolant: it does use negative weights
        np.testing.assert_allclose(wt(d).dense(n), np.eye(n), atol=1e-9)


def test_blend_zero_and_unit_bound_are_barycentric():
    d = random_directions(30, 3)
    q = random_directions(3000, 4)
    bary = cell_weights(d, q, "barycentric").dense(30)
    for opts in ({"blend": 0.0}, {"max_lebesgue": 1.0}):
        np.testing.assert_allclose(cell_weights(d, q, "spline", **opts).dense(30), bary, atol=1e-12, err_msg=str(opts))
    assert np.abs(cell_weights(d, q, "spline").dense(30) - bary).max() > 0.05


@pytest.mark.parametrize("hemisphere", ["upper", "full"])
def test_power_is_conserved_exactly(hemisphere):
    d = random_directions(30, 5, hemisphere)
    lm = paper_map(48)
    R = rotation_ypr(20, 35, -10)
    w = integrate(lm, d, R, hemisphere, "spline")
    np.testing.assert_allclose(w.weights.sum(0) + w.dropped_power, w.total_power, rtol=1e-10)
    tex = bake_weights(d, "spline", hemisphere, res=48)
    wt = integrate(lm, d, R, hemisphere, "spline", texture=tex)
    np.testing.assert_allclose(wt.weights.sum(0) + wt.dropped_power, wt.total_power, rtol=1e-10)
    assert wt.dropped_texels == w.dropped_texels


def test_changes_smoothly_with_tiny_rotations():
    d = random_directions(60, 7)
    q = random_directions(4000, 8)
    wt = Weighting(d, "spline")
    base = wt(q).dense(60)
    for eps_deg in (1e-3, 1e-5):
        moved = wt((rotation_z(eps_deg) @ q.T).T).dense(60)
        assert np.abs(moved - base).max() < 50 * eps_deg, (eps_deg, np.abs(moved - base).max())


def test_degenerate_captures():
    q = random_directions(2000, 9)
    # duplicates get nothing; a nearly equal pair shares one light's weight
    d = random_directions(12, 3)
    sw = cell_weights(np.concatenate([d, d[:2]]), q, "spline")
    assert not np.isin(sw.index[sw.weight != 0], [12, 13]).any()
    near = np.concatenate([d, d[:1] + 1e-9])
    w = integrate(paper_map(32), near, None, "upper", "spline").weights
    one = integrate(paper_map(32), d, None, "upper", "spline").weights
    np.testing.assert_allclose(w[0] + w[12], one[0], rtol=1e-5)
    # lights on the horizon, and barely above it (a light next to its own mirror image)
    h = random_directions(25, 4)
    h[0] = [1.0, 0.0, 0.0]
    h[1] = [0.0, np.sqrt(1 - 1e-8), 1e-4]
    wt = Weighting(h, "spline")
    rim = np.stack([np.cos(np.linspace(0, 2 * np.pi, 500)), np.sin(np.linspace(0, 2 * np.pi, 500)), np.zeros(500)], 1)
    sw = wt(rim)
    np.testing.assert_allclose(sw.weight.sum(1), 1.0, atol=1e-12)
    assert np.abs(sw.dense(25)).sum(1).max() <= 8.8
    np.testing.assert_allclose(wt(h).dense(25), np.eye(25), atol=1e-9)
    # all lights in a 10-degree cap of a full-sphere capture
    cap = random_directions(6, 5)
    cap[:, :2] *= 0.05
    cap /= np.linalg.norm(cap, axis=1, keepdims=True)
    sw = cell_weights(cap, random_directions(2000, 6, "full"), "spline", hemisphere="full")
    np.testing.assert_allclose(sw.weight.sum(1), 1.0, atol=1e-12)
    assert np.abs(sw.dense(6)).sum(1).max() <= 8.8
    w = light_weights(cap, cap[2], "spline", "full")
    assert np.isclose(w[2], 1.0) and np.isclose(w.sum(), 1.0)


def test_interpolates_a_smooth_function_better_than_barycentric():
    d = random_directions(150, 10)
    q = random_directions(5000, 11)
    q = q[q[:, 2] > 0.2]  # away from the rim, where both extrapolate by mirroring

    def f(x):
        return np.exp(x @ np.array([0.6, -0.3, 0.9])) + 0.5 * x[:, 0] * x[:, 1]

    err = {}
    for scheme in ("barycentric", "spline"):
        est = cell_weights(d, q, scheme).dense(150) @ f(d)
        err[scheme] = np.sqrt(np.mean((est - f(q)) ** 2))
    assert err["spline"] < 0.6 * err["barycentric"], err


def test_flicker_at_least_5x_below_voronoi():
    from flicker import scheme_flicker, synthetic_basis

    basis, d = synthetic_basis(40, 16)
    el = np.radians(40.0)
    lm = sky_sun_map(96, sun_direction=(np.cos(el), 0.0, np.sin(el)))
    res = scheme_flicker(basis, d, lm, schemes=("voronoi", "spline"), frames=40, step_deg=1.0)
    assert res["voronoi"] >= 5.0 * res["spline"], res
