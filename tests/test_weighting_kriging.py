"""Kriging weights with a kernel learnt from the capture (ffls.weights.kriging) and their GPU pass 1.

Contracts tested: the Matérn kernels are positive definite on the sphere; the closed-form
leave-one-out error equals refitting without each photo; :func:`fit_kernel` picks the candidate
with the least leave-one-out error and recovers the smoothness of a field drawn from a known
kernel; the weights sum to 1 per direction (truncated to ``slots`` or not), so a light map's power
is conserved exactly; duplicates take nothing; captures of 1 to 3 lights, all in a 10-degree cap,
or on the horizon stay finite and sum to 1; tiny rotations change the weights by amounts
proportional to the angle; a smooth function is interpolated better than by barycentric; the
GPU's pass 1 matches ``integrate(..., texture=)`` within ``1e-5 * total`` per light and channel.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from ffls.conventions import rotation_ypr, rotation_z
from ffls.lightmaps.lightmap import paper_map, sky_sun_map
from ffls.weights.kriging import NUS, Kriging, fit_kernel, light_spacing, loo_errors, matern
from ffls.weights.weighting import (EXTRA_SCHEMES, SCHEMES, SIGNED_SCHEMES, Weighting, bake_weights, cell_weights,
                                    integrate, light_weights, texture_slots)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from directions import random_directions  # noqa: E402  (tests/directions.py, beside this file)


def test_kriging_is_offered_and_checks_its_options():
    assert "kriging" in SCHEMES and "kriging" not in EXTRA_SCHEMES and "kriging" in SIGNED_SCHEMES
    assert texture_slots("kriging") == 24 and texture_slots("kriging", slots=8) == 8
    d = random_directions(20, 1)
    for bad in ({"nu": 1.0}, {"nugget": 0.0}, {"nugget": float("nan")}, {"length": -1.0}, {"slots": 0}):
        with pytest.raises(ValueError):
            Weighting(d, "kriging", **bad)
    with pytest.raises(ValueError, match="takes no option"):
        Weighting(d, "kriging", k=4)


@pytest.mark.parametrize("nu", NUS)
def test_matern_is_positive_definite_on_the_sphere(nu):
    d = random_directions(300, 2, "full")
    for length in (0.05, 0.5, 3.0):
        k = matern(d @ d.T, nu, length)
        assert np.allclose(np.diag(k), 1.0)
        assert np.linalg.eigvalsh(k).min() > -1e-9, (nu, length)


def test_closed_form_leave_one_out_equals_refitting():
    d = random_directions(25, 3)
    y = np.stack([np.cos(3 * d[:, 0]) + d[:, 2] ** 2, np.exp(d[:, 1])], axis=1)  # two "pixels"
    nu, length, tau = 1.5, 0.6, 0.02
    num = 0.0
    for j in range(25):
        others = np.delete(np.arange(25), j)
        kr = Kriging(d, others, nu, length, tau, slots=25)
        pred = kr.dense(d[j:j + 1])[0] @ y
        num += float(np.sum((y[j] - pred) ** 2))
    brute = np.sqrt(num / np.sum(y * y))
    assert np.isclose(loo_errors(d, y, nu, length, tau), brute, rtol=1e-8)


def test_fit_kernel_picks_the_least_loo_and_recovers_the_smoothness():
    rng = np.random.default_rng(4)
    d = random_directions(120, 5)
    h = light_spacing(d)
    for nu_true in (0.5, 2.5):
        k = matern(d @ d.T, nu_true, 3.0 * h) + 1e-3 * np.eye(120)
        y = np.linalg.cholesky(k) @ rng.standard_normal((120, 300))  # 300 pixels drawn from that field
        fit = fit_kernel(d, y.T.reshape(-1, 120).T)
        assert fit.loo == min(fit.table.values())
        assert np.isclose(fit.loo, loo_errors(d, y, fit.nu, fit.length, fit.nugget))
        assert fit.nu == nu_true, (nu_true, fit)
        assert fit.options == {"nu": fit.nu, "length": fit.length, "nugget": fit.nugget}
    with pytest.raises(ValueError, match="at least 5"):
        fit_kernel(d[:4], np.ones((4, 3)))
    with pytest.raises(ValueError, match="NaN"):
        fit_kernel(d[:6], np.full((6, 3), np.nan))


@pytest.mark.parametrize("n", [1, 2, 3, 40])
def test_weights_sum_to_one(n):
    d = random_directions(n, 6)
    q = random_directions(3000, 7)
    sw = cell_weights(d, q, "kriging")
    np.testing.assert_allclose(sw.weight.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    assert np.all((sw.index >= 0) | (sw.weight == 0)) and sw.index.max() < n
    kr = Kriging(d, np.arange(n), slots=n)
    np.testing.assert_allclose(kr.dense(q).sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(sw.dense(n), kr.dense(q), atol=1e-12) if n <= 24 else None
    if n == 1:
        assert np.all(sw.dense(1) == 1.0)


@pytest.mark.parametrize("hemisphere", ["upper", "full"])
def test_power_is_conserved_exactly(hemisphere):
    d = random_directions(30, 8, hemisphere)
    lm = paper_map(48)
    R = rotation_ypr(20, 35, -10)
    for slots in (6, 24):
        w = integrate(lm, d, R, hemisphere, "kriging", slots=slots)
        np.testing.assert_allclose(w.weights.sum(0) + w.dropped_power, w.total_power, rtol=1e-10)
        tex = bake_weights(d, "kriging", hemisphere, res=48, slots=slots)
        wt = integrate(lm, d, R, hemisphere, "kriging", texture=tex, slots=slots)
        np.testing.assert_allclose(wt.weights.sum(0) + wt.dropped_power, wt.total_power, rtol=1e-10)


def test_truncation_keeps_the_largest_weights():
    d = random_directions(80, 9)
    q = random_directions(2000, 10)
    dense = Kriging(d, np.arange(80), slots=80).dense(q)
    sw = cell_weights(d, q, "kriging", slots=24).dense(80)
    # 24 of 80 lights carry all but a small part of |w|
    dropped = np.abs(dense).sum(1) - np.sort(np.abs(dense), axis=1)[:, -24:].sum(1)
    assert np.median(dropped) < 0.05
    assert np.all(np.count_nonzero(sw, axis=1) <= 24)
    np.testing.assert_allclose(sw.sum(1), 1.0, atol=1e-12)
    # integrated against a map, the truncated weights stay close to the untruncated ones
    lm = paper_map(48)
    w24 = integrate(lm, d, None, "upper", "kriging", slots=24).weights
    w80 = integrate(lm, d, None, "upper", "kriging", slots=80).weights
    assert np.linalg.norm(w24 - w80) < 0.05 * np.linalg.norm(w80), np.linalg.norm(w24 - w80) / np.linalg.norm(w80)


def test_degenerate_captures():
    q = random_directions(2000, 11)
    d = random_directions(12, 12)
    sw = cell_weights(np.concatenate([d, d[:2]]), q, "kriging")
    assert not np.isin(sw.index[sw.weight != 0], [12, 13]).any()  # duplicates take nothing
    # lights on the horizon
    h = random_directions(25, 13)
    h[0] = [1.0, 0.0, 0.0]
    h[1] = [0.0, 1.0, 0.0]
    rim = np.stack([np.cos(np.linspace(0, 2 * np.pi, 500)), np.sin(np.linspace(0, 2 * np.pi, 500)), np.zeros(500)], 1)
    sw = cell_weights(h, rim, "kriging")
    assert np.all(np.isfinite(sw.weight))
    np.testing.assert_allclose(sw.weight.sum(1), 1.0, atol=1e-12)
    # all lights in a 10-degree cap (the linear trend is nearly degenerate there)
    cap = random_directions(6, 14)
    cap[:, :2] *= 0.05
    cap /= np.linalg.norm(cap, axis=1, keepdims=True)
    sw = cell_weights(cap, random_directions(2000, 15, "full"), "kriging", hemisphere="full")
    assert np.all(np.isfinite(sw.weight))
    np.testing.assert_allclose(sw.weight.sum(1), 1.0, atol=1e-12)
    w = light_weights(cap, cap[2], "kriging", "full")
    assert np.isclose(w.sum(), 1.0) and np.argmax(w) == 2


def test_changes_smoothly_with_tiny_rotations():
    d = random_directions(60, 16)
    q = random_directions(4000, 17)
    wt = Weighting(d, "kriging")  # 24 slots of 60 lights: the truncation is continuous too
    base = wt(q).dense(60)
    for eps_deg in (1e-3, 1e-5):
        moved = wt((rotation_z(eps_deg) @ q.T).T).dense(60)
        assert np.abs(moved - base).max() < 50 * eps_deg, (eps_deg, np.abs(moved - base).max())


def test_interpolates_a_smooth_function_better_than_barycentric():
    d = random_directions(150, 18)
    q = random_directions(5000, 19)
    q = q[q[:, 2] > 0.2]

    def f(x):
        return np.exp(x @ np.array([0.6, -0.3, 0.9])) + 0.5 * x[:, 0] * x[:, 1]

    fit = fit_kernel(d, f(d)[:, None])
    assert fit.nu == 2.5 and fit.nugget == 1e-4  # smooth, noiseless
    err = {}
    # all 150 lights kept: a long, smooth kernel's weights are not local, and 24 slots would
    # truncate them (the GPU's texture; the real captures' fitted kernels are short, with a nugget)
    for scheme, opts in (("barycentric", {}), ("kriging", {**fit.options, "slots": 150})):
        est = cell_weights(d, q, scheme, **opts).dense(150) @ f(d)
        err[scheme] = np.sqrt(np.mean((est - f(q)) ** 2))
    assert err["kriging"] < 0.05 * err["barycentric"], err


def test_flicker_at_least_5x_below_voronoi():
    from flicker import scheme_flicker, synthetic_basis

    basis, d = synthetic_basis(40, 16)
    el = np.radians(40.0)
    lm = sky_sun_map(96, sun_direction=(np.cos(el), 0.0, np.sin(el)))
    fit = fit_kernel(d, basis)
    res = scheme_flicker(basis, d, lm, schemes=("voronoi", "kriging"), frames=40, step_deg=1.0,
                         options={"kriging": fit.options})
    assert res["voronoi"] >= 5.0 * res["kriging"], res


@pytest.mark.gl
@pytest.mark.parametrize("hemisphere", ["upper", "full"])
@pytest.mark.parametrize("method", ["sort", "blend"])
def test_gpu_pass1_matches_the_texture_reference(ctx, hemisphere, method):
    from ffls.gpu.integrate import CellIntegrator

    d = random_directions(40, 20, hemisphere)
    # no sun: a direction on a texel edge may take the neighbouring texel in float32, and with one
    # texel holding most of the power that flip alone can exceed the tolerance
    lm = paper_map(48)
    tex = bake_weights(d, "kriging", hemisphere, res=64)
    assert np.any(tex.weight < 0)  # signed weights go through the sparse pass
    gi = CellIntegrator(ctx, d, hemisphere, tex, method=method)
    try:
        gi.set_lightmap(lm)
        for R in (np.eye(3), rotation_ypr(33, 21, 7)):
            gi.run(R)
            ref = integrate(lm, d, R, hemisphere, "kriging", texture=tex)
            g = gi.read_weights().astype(np.float64)
            assert np.all(np.abs(g - ref.weights) <= 1e-5 * ref.total_power[None, :]), np.abs(g - ref.weights).max()
            np.testing.assert_allclose(g.sum(0) + gi.dropped_power, ref.total_power, rtol=1e-5)
    finally:
        gi.release()


@pytest.mark.gl
def test_engine_renders_kriging_like_the_reference(ctx):
    from ffls.gpu.engine import Engine
    from ffls.relight.cpu import relight_reference

    rng = np.random.default_rng(21)
    d = random_directions(30, 21)
    basis = rng.uniform(0, 1, size=(30, 8, 8, 3)).astype(np.float32)
    opts = fit_kernel(d, basis).options
    lm = sky_sun_map(32)
    eng = Engine(ctx, basis, d, "upper", dtype="f32", weighting="kriging", weights_res=64, weighting_options=opts)
    try:
        eng.set_lightmap(lm)
        for R in (np.eye(3), rotation_z(17)):
            eng.set_rotation(R)
            eng.render()
            ref = integrate(lm, d, R, "upper", "kriging", texture=bake_weights(d, "kriging", "upper", res=64, **opts),
                            **opts)
            np.testing.assert_allclose(eng.read_weights(), ref.weights, atol=1e-5 * ref.total_power.max())
            img = relight_reference(ref.weights, basis)
            np.testing.assert_allclose(eng.read_hdr(), img, atol=1e-4 * np.abs(img).max())
    finally:
        eng.release()


def test_weights_are_bounded_where_the_lights_cover_poorly():
    """All 20 lights within 0.2 degrees of the zenith: unbounded, the linear trend extrapolated to
    weights of 1e5 over the hemisphere; the sum of |w| is now at most MAX_LEBESGUE, rows sum to 1."""
    from ffls.weights.kriging import MAX_LEBESGUE

    rng = np.random.default_rng(3)
    off = rng.normal(scale=np.radians(0.1), size=(20, 2))
    d = np.c_[off, np.ones(20)]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    q = random_directions(500, 8)
    for nugget in (0.3, 0.03):
        wt = Weighting(d, "kriging", nugget=nugget, length=1e-3)
        sw = wt(q)
        dense = sw.dense(20)
        np.testing.assert_allclose(dense.sum(1), 1.0, atol=1e-9)
        assert np.abs(dense).sum(1).max() <= MAX_LEBESGUE + 1e-9
    # a well-spread capture is untouched by the bound
    d = random_directions(60, 2)
    k = Weighting(d, "kriging")
    assert np.abs(k(q).dense(60)).sum(1).max() < MAX_LEBESGUE
