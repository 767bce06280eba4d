"""Numerical stability of relighting at the extremes (issue 12): few lights, duplicate and
clustered directions, lights on the horizon, ranks out of range, a 1e6 texel, float16 range, and
rotations by tiny angles. CPU paths always; the GPU engine where a context exists."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import normalize, rotation_z
from ffls.errors import InputError
from ffls.lightmaps.lightmap import LightMap, constant_map, sky_sun_map
from ffls.relight.auto import leave_one_out_errors
from ffls.relight.compress import compress_basis
from ffls.relight.cpu import CpuRelighter, relight_reference
from ffls.relight.quality import Quality, farthest_point_subset, near_light_scales, prepare_basis
from ffls.relight.storage import store_basis, to_float16
from ffls.weights.voronoi import integrate_weights

TWO_PI = 2 * np.pi


def lambert_basis(directions, size: int = 12) -> np.ndarray:
    """Images of a diffuse hemisphere of normals lit from each direction: smooth in the direction."""
    d = normalize(np.asarray(directions, dtype=np.float64))
    yy, xx = np.mgrid[0:size, 0:size]
    u, v = (xx + 0.5) / size * 2 - 1, (yy + 0.5) / size * 2 - 1
    nz = np.sqrt(np.clip(1 - u ** 2 - v ** 2, 0, 1))
    normals = np.stack([u, -v, nz], axis=-1) * (u ** 2 + v ** 2 <= 1)[..., None]
    shade = np.clip(np.einsum("hwk,nk->nhw", normals, d), 0, None)
    albedo = np.array([0.8, 0.5, 0.3])
    return (shade[..., None] * albedo).astype(np.float32)


def elevation_ring(n, elevation_deg, phase=0.0):
    az = np.radians(phase + 360.0 * np.arange(n) / n)
    el = np.radians(elevation_deg)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.full(n, np.sin(el))], axis=1)


def spot_map(height=32, background=1e-3, peak=1e6, row=5, col=11) -> LightMap:
    img = np.full((height, 2 * height, 3), background, dtype=np.float32)
    img[row, col] = peak
    return LightMap(img, "latlong", "spot")


# ----------------------------------------------------------------------------- few lights
@pytest.mark.parametrize("n", [1, 2, 3])
def test_one_to_three_lights_conserve_energy_and_relight(n):
    d = elevation_ring(n, 40.0)
    w = integrate_weights(constant_map(16, 2.0), d, hemisphere="upper")
    np.testing.assert_allclose(w.weights.sum(0) + w.dropped_power, w.total_power, rtol=1e-12)
    np.testing.assert_allclose(w.weights.sum(0), 2.0 * TWO_PI, rtol=1e-3)  # the upper half of a sphere
    b = lambert_basis(d)
    r = CpuRelighter(b, d, cell_res=None, precision="f64")
    r.set_lightmap(constant_map(16, 2.0))
    r.render()
    np.testing.assert_allclose(r.hdr, relight_reference(w.weights, b), rtol=1e-12)
    assert np.all(np.isfinite(r.hdr))


@pytest.mark.parametrize("n", [1, 2, 3])
def test_few_lights_leave_one_out_and_subset_are_defined(n):
    d = elevation_ring(n, 30.0)
    b = lambert_basis(d)
    eps = leave_one_out_errors(b, d, np.arange(n))
    if n == 1:
        assert np.isnan(eps[0])  # nothing to predict from
    else:
        assert np.all(np.isfinite(eps)) and np.all(eps >= 0)
    assert list(farthest_point_subset(d, 5)) == list(range(n))
    assert len(farthest_point_subset(d, 1)) == 1


# ----------------------------------------------------------------------------- duplicates, cap, horizon
def test_duplicate_directions_conserve_energy_and_tie_to_the_lowest_index():
    base = elevation_ring(5, 45.0)
    d = np.concatenate([base, base[:2]])  # lights 5 and 6 repeat lights 0 and 1
    w = integrate_weights(sky_sun_map(32), d)
    np.testing.assert_allclose(w.weights.sum(0) + w.dropped_power, w.total_power, rtol=1e-12)
    assert np.all(w.weights[5:] == 0)  # later exact duplicates get nothing
    b = lambert_basis(d)
    eps = leave_one_out_errors(b, d, [0, 5])
    np.testing.assert_allclose(eps, 0.0, atol=1e-7)  # a duplicate is predicted exactly by its twin
    sub = farthest_point_subset(d, 5)
    assert len(set(map(tuple, d[sub].round(12)))) == 5  # duplicates are chosen last


def test_all_lights_in_a_10_degree_cap():
    rng = np.random.default_rng(3)
    ang = np.radians(10.0) * np.sqrt(rng.random(40))
    az = rng.random(40) * 2 * np.pi
    d = np.stack([np.sin(ang) * np.cos(az), np.sin(ang) * np.sin(az), np.cos(ang)], axis=1)
    lm = sky_sun_map(32)
    w = integrate_weights(lm, d)
    np.testing.assert_allclose(w.weights.sum(0) + w.dropped_power, w.total_power, rtol=1e-12)
    assert w.dropped_texels == int(np.count_nonzero(lm.samples()[0][:, 2] < 0))  # only the lower half
    r = CpuRelighter(lambert_basis(d), d, cell_res=256)  # the candidate texture handles the crowding
    r.set_lightmap(lm)
    r.render()
    np.testing.assert_allclose(r.read_weights(), w.weights, rtol=1e-9, atol=1e-12)
    from ffls.weights.voronoi import coverage_warnings

    assert coverage_warnings(d, "upper")  # the user is told the rim is far from every light


def test_lights_on_the_horizon():
    d = np.concatenate([elevation_ring(8, 0.0), elevation_ring(4, 60.0, 45.0)])
    assert np.all(d[:8, 2] == 0)
    lm = sky_sun_map(32)
    for R in (np.eye(3), rotation_z(10.0)):
        w = integrate_weights(lm, d, R)
        np.testing.assert_allclose(w.weights.sum(0) + w.dropped_power, w.total_power, rtol=1e-12)
        assert np.all(w.weights >= 0)
    # near lights on the horizon: the correction is defined (distance only)
    s = near_light_scales(d * np.linspace(1, 2, len(d))[:, None])
    assert np.all(np.isfinite(s)) and np.all(s > 0)


def test_near_correction_needs_positions_and_refuses_the_centre():
    d = elevation_ring(4, 30.0)
    b = lambert_basis(d)
    with pytest.raises(InputError, match="positions"):
        prepare_basis(b, d, np.full((4, 3), np.nan), near_correction=True)
    with pytest.raises(InputError, match="centre"):
        prepare_basis(b, d, np.zeros((4, 3)), near_correction=True)
    pos = d * np.array([1.0, 2.0, 3.0, 4.0])[:, None]
    out, dirs, info = prepare_basis(b, d, pos, near_correction=True)
    np.testing.assert_allclose(info["near_scales"], (np.arange(1, 5) / 2.5) ** 2)
    np.testing.assert_allclose(out[3], b[3] * (4 / 2.5) ** 2, rtol=1e-6)
    np.testing.assert_allclose(dirs, d, atol=1e-12)


# ----------------------------------------------------------------------------- rank
def test_rank_above_n_and_zero_are_refused_in_one_line():
    d = elevation_ring(6, 40.0)
    b = lambert_basis(d)
    for k in (0, 6, 7, 100):
        with pytest.raises(ValueError, match=r"rank must be in \[1, 5\]"):
            compress_basis(b, k)
    from ffls.commands.common import check_rank_arg

    for k in (0, 6):
        with pytest.raises(InputError, match=r"--rank .* must be in \[1, 5\] for 6 lights"):
            check_rank_arg(k, 6)
    with pytest.raises(ValueError, match="rank"):
        Quality(rank=0)
    # K = n - 1 is exact
    cb = compress_basis(b, 5)
    w = np.random.default_rng(0).random((6, 3))
    np.testing.assert_allclose(cb.relight(w), relight_reference(w, b), rtol=1e-4, atol=1e-6)


def test_view_rank_zero_means_the_full_basis():
    import argparse

    from viewer.command import add_arguments, build_state

    p = argparse.ArgumentParser()
    add_arguments(p)
    st = build_state(p.parse_args(["cap", "--rank", "0"]))
    assert st.quality["method"] == "full f16"
    st = build_state(p.parse_args(["cap", "--rank", "0", "--precision", "float32"]))
    assert st.quality["method"] == "full f32"


# ----------------------------------------------------------------------------- 1e6 texel, float16
def test_a_map_with_one_1e6_texel():
    d = np.concatenate([elevation_ring(12, 20.0), elevation_ring(6, 60.0, 30.0), [[0, 0, 1.0]]])
    lm = spot_map()
    w = integrate_weights(lm, d)
    np.testing.assert_allclose(w.weights.sum(0) + w.dropped_power, w.total_power, rtol=1e-12)
    top = np.argmax(w.weights[:, 0])
    sa = lm.solid_angles()[5, 11]
    assert w.weights[top, 0] >= 1e6 * sa  # the spot's cell holds it
    b = lambert_basis(d)
    for storage in ("f32", "f16"):
        r = CpuRelighter(b, d, cell_res=None, storage=storage)
        r.set_lightmap(lm)
        r.render()
        ref = relight_reference(w.weights, b)
        assert np.all(np.isfinite(r.hdr))
        np.testing.assert_allclose(r.hdr, ref, rtol=2e-3, atol=1e-6 * ref.max())


def test_float16_storage_scales_instead_of_overflowing():
    b = np.full((2, 4, 4, 3), 1e-3, dtype=np.float32)
    b[0, 0, 0] = 1e6  # 15 times float16's largest value
    stored, scale, rep = store_basis(b, "float16")
    assert stored.dtype == np.float16 and np.all(np.isfinite(stored))
    assert rep.n_overflow == 0 and scale == 2.0 ** -8
    back = stored.astype(np.float64) / scale
    assert abs(back[0, 0, 0, 0] - 1e6) <= 1e6 * 2 ** -11  # the significant value keeps float16's precision
    # 1e-3 is 1e-9 of the largest value: below SIGNIFICANT_REL, stored as a subnormal and counted
    assert rep.n_flushed == b.size - 3 and np.all(back[b < 1] > 0)
    with pytest.raises(InputError, match="overflow"):
        to_float16(b, scale=1.0)  # the scale is what keeps it finite: checked, never inf
    with pytest.raises(InputError, match="NaN/Inf"):
        store_basis(np.array([[[[np.inf, 0, 0]]]], dtype=np.float32), "float32")
    huge = np.full((1, 2, 2, 3), 3e38, dtype=np.float32)
    h, s, _ = store_basis(huge, "f16")
    assert np.all(np.isfinite(h)) and s < 2.0 ** -100


# ----------------------------------------------------------------------------- tiny rotations
def test_tiny_rotations_change_the_image_smoothly():
    """Voronoi (a box filter): a rotation by a tiny angle moves only the texels that cross a cell
    border, so the change shrinks with the angle and is bounded by those texels' power."""
    d = np.concatenate([elevation_ring(10, 20.0), elevation_ring(5, 55.0, 18.0), [[0, 0, 1.0]]])
    b = lambert_basis(d)
    lm = sky_sun_map(64)
    r = CpuRelighter(b, d, cell_res=None, precision="f64")
    r.set_lightmap(lm)
    r.set_rotation(rotation_z(7.0))
    r.render()
    base = r.hdr.copy()
    norm = np.linalg.norm(base)
    changes = []
    for delta in (1e-7, 1e-5, 1e-3, 1e-1):
        r.set_rotation(rotation_z(7.0 + delta))
        r.render()
        changes.append(np.linalg.norm(r.hdr - base) / norm)
    assert changes[0] <= 1e-6
    assert all(a <= b + 1e-12 for a, b in zip(changes, changes[1:]))  # non-decreasing with the angle
    assert changes[-1] < 0.05


@pytest.mark.gl
def test_gpu_engine_at_the_extremes(ctx):
    from ffls.gpu.engine import Engine

    cases = [elevation_ring(1, 40.0), elevation_ring(3, 0.0),
             np.concatenate([elevation_ring(5, 45.0), elevation_ring(5, 45.0)[:1]])]
    for d in cases:
        b = lambert_basis(d)
        lm = spot_map()
        w = integrate_weights(lm, d)
        eng = Engine(ctx, b, d, cell_res=64)
        try:
            eng.set_lightmap(lm)
            eng.render()
            np.testing.assert_allclose(eng.read_weights(), w.weights, rtol=1e-5, atol=1e-6 * w.total_power.max())
            ref = relight_reference(w.weights, b)
            np.testing.assert_allclose(eng.read_hdr(), ref, rtol=2e-3, atol=1e-3 * ref.max())
        finally:
            eng.release()


@pytest.mark.parametrize("scheme", ["antialiased", "barycentric", "gaussian"])
def test_tiny_rotations_are_lipschitz_for_the_smooth_schemes(scheme):
    """A smooth scheme's weights move continuously with the direction: the image changes in
    proportion to the angle (barycentric, gaussian). ``antialiased`` is soft only across a band
    about a map texel wide at each cell border, so below some angle nothing crosses into the band
    and the change is 0; above it, it must not jump (no more than linear growth)."""
    d = np.concatenate([elevation_ring(10, 20.0), elevation_ring(5, 55.0, 18.0), [[0, 0, 1.0]]])
    b = lambert_basis(d)
    r = CpuRelighter(b, d, cell_res=None, precision="f64", weighting=scheme)
    r.set_lightmap(sky_sun_map(48))
    r.set_rotation(rotation_z(7.0))
    r.render()
    base = r.hdr.copy()
    norm = np.linalg.norm(base)
    rates = []
    for delta in (1e-4, 1e-3, 1e-2, 1e-1):
        r.set_rotation(rotation_z(7.0 + delta))
        r.render()
        rates.append(np.linalg.norm(r.hdr - base) / norm / delta)
    assert all(np.isfinite(rates)) and max(rates) > 0
    if scheme == "antialiased":
        changes = [rt * dl for rt, dl in zip(rates, (1e-4, 1e-3, 1e-2, 1e-1))]
        assert all(a <= b + 1e-15 for a, b in zip(changes, changes[1:]))  # grows with the angle
        assert max(rates) < 0.01  # under 0.1 % of the image per 0.1 degree: no pop
    else:
        assert max(rates) <= 5 * min(rates)  # change / angle roughly constant: no jumps at tiny angles
