"""Angular Voronoi weighting (ffls.weights.voronoi): GUIDE section 4 invariants and extremes.

The light maps here are built directly as ``(dirs, radiance, solid_angle)`` tuples on a lat-long
grid with exact per-row solid angles, independent of ffls.lightmaps.lightmap and ffls.lightmaps.sphere_maps, so that
these tests check the weighting alone. Tests of the candidate texture need ffls.lightmaps.sphere_maps.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ffls import conventions as cv
from ffls.weights import voronoi as vo


# ----------------------------------------------------------------------------- fixtures
def latlong(height: int):
    """Texel-centre directions (M, 3) and exact solid angles (M,) of a 2h x h lat-long map."""
    width = 2 * height
    d = cv.latlong_directions(width, height).reshape(-1, 3)
    edges = np.cos(np.pi * np.arange(height + 1) / height)
    sa = np.repeat((edges[:-1] - edges[1:]) * (2 * np.pi / width), width)
    return d, sa


def random_dirs(rng, n, hemisphere="upper", duplicates=0):
    d = cv.normalize(rng.normal(size=(n, 3)))
    if hemisphere == "upper":
        d[:, 2] = np.abs(d[:, 2])
    if duplicates:
        src = rng.integers(0, n, size=duplicates)
        dst = rng.choice(n, size=duplicates, replace=False)
        d[dst] = d[src]
    return d


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


LL128 = latlong(128)


# ----------------------------------------------------------------------------- constant map
@pytest.mark.parametrize("hemisphere", ["upper", "full"])
@pytest.mark.parametrize("n,dups", [(1, 0), (2, 0), (3, 1), (17, 4), (50, 10), (400, 40)])
def test_constant_map_sums_to_covered_solid_angle(rng, hemisphere, n, dups):
    # Unrotated lat-long with an even height: rows split exactly at the equator, so the kept
    # texels are exactly the upper rows, whose exact solid angles sum to 2 pi.
    d, sa = LL128
    c = np.array([0.5, 1.0, 2.0])
    dirs = random_dirs(rng, n, hemisphere, duplicates=dups)
    w = vo.integrate_weights((d, np.broadcast_to(c, d.shape), sa), dirs, hemisphere=hemisphere)
    cov = cv.covered_solid_angle(hemisphere)
    np.testing.assert_allclose(w.weights.sum(axis=0), c * cov, rtol=1e-12)
    np.testing.assert_allclose(w.total_power, c * 4 * np.pi, rtol=1e-12)
    np.testing.assert_allclose(w.dropped_power, c * (4 * np.pi - cov), rtol=1e-12, atol=1e-12)
    assert w.dropped_texels == (d.shape[0] // 2 if hemisphere == "upper" else 0)
    assert w.weights.shape == (n, 3) and w.weights.dtype == np.float64
    assert np.all(w.weights >= 0)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60))
def test_constant_map_sum_hypothesis(seed, n):
    rng = np.random.default_rng(seed)
    d, sa = latlong(32)
    dirs = random_dirs(rng, n, "upper", duplicates=n // 5)
    R = random_rotation(rng)
    w = vo.integrate_weights((d, np.ones_like(d), sa), dirs, rotation=R, hemisphere="upper")
    # kept + dropped power is everything, to float64 rounding
    np.testing.assert_allclose(w.weights.sum(0) + w.dropped_power, 4 * np.pi, rtol=1e-12)
    # the rotated horizon is quantised by texel centres: the error is at most the solid angle
    # of the texels whose centre lies within one texel diagonal of the rotated horizon
    z = cv.rotate_directions(R, d)[:, 2]
    band = np.abs(z) < np.sin(np.pi / 32 * np.sqrt(2) * 1.01)
    assert abs(w.weights[:, 0].sum() - 2 * np.pi) <= sa[band].sum()


def test_rotated_constant_map_tolerance(rng):
    d, sa = latlong(256)
    dirs = random_dirs(rng, 100)
    for _ in range(3):
        R = random_rotation(rng)
        w = vo.integrate_weights((d, np.ones_like(d), sa), dirs, rotation=R)
        # measured: |error| ~ 1e-4 sr for H = 256; stated bound 2e-3 sr (0.03 %)
        assert abs(w.weights[:, 0].sum() - 2 * np.pi) < 2e-3


# ----------------------------------------------------------------------------- rotations
def _smooth_map(d):
    return np.stack([1 + d[:, 0] ** 2, 0.5 + 0.5 * d[:, 2], 1 + 0.3 * np.sin(3 * d[:, 1])], axis=1)


def test_rotation_by_360_changes_nothing(rng):
    d, sa = LL128
    L = _smooth_map(d) * rng.uniform(0.5, 1.5, size=d.shape)
    dirs = random_dirs(rng, 80)
    w0 = vo.integrate_weights((d, L, sa), dirs)
    for R in (cv.rotation_z(360.0), cv.rotation_ypr(360.0, 360.0, 360.0), cv.rotation_z(-720.0)):
        w = vo.integrate_weights((d, L, sa), dirs, rotation=R)
        np.testing.assert_allclose(w.weights, w0.weights, rtol=0, atol=1e-12)
        assert w.dropped_texels == w0.dropped_texels


def test_weights_move_continuously_under_small_rotations(rng):
    d, sa = latlong(512)
    L = _smooth_map(d)
    Lmax = L.max()
    dirs = random_dirs(rng, 20)
    axis = cv.normalize(rng.normal(size=3))
    w0 = vo.integrate_weights((d, L, sa), dirs).weights
    changes = []
    for deg in (1.0, 0.1, 0.01, 0.001):
        w = vo.integrate_weights((d, L, sa), dirs, rotation=cv.rotation_about_axis(axis, deg)).weights
        dw = np.abs(w - w0).max()
        # A rotation by delta moves every cell boundary by at most delta; a convex cell's
        # perimeter is at most 2 pi, so a cell gains or loses at most Lmax * 2 pi * delta, plus
        # the quantisation of the texel centres (a few texels).
        assert dw <= Lmax * (2 * np.pi * np.radians(deg) + 20 * sa.max())
        changes.append(dw)
    assert changes[0] > changes[2]  # the change shrinks with the angle
    assert changes[0] > 1e-3  # and 1 degree does change the weights (the test can fail)


# ----------------------------------------------------------------------------- gantry
@pytest.mark.parametrize("n_az", [4, 8, 16])
def test_gantry_ring_reproduces_light_stage_weights(rng, n_az):
    # Lights on a gantry: n_az columns at one elevation (upper), or mirrored at two elevations
    # (full). Their Voronoi cells are exactly the lat-long patches (lunes between the midway
    # meridians, split at the equator), so each light's weight is the map summed over its patch.
    H = 64
    W = 2 * H
    d, sa = latlong(H)
    L = rng.uniform(0, 2, size=(H * W, 3))
    phi = np.pi * (1 - 2 * (np.arange(n_az) + 0.5) / n_az)  # patch centres
    for hemisphere, thetas in (("upper", [np.radians(50)]), ("full", [np.radians(35), np.radians(145)])):
        dirs = np.concatenate([cv.spherical_to_direction(np.full(n_az, t), phi) for t in thetas])
        w = vo.integrate_weights((d, L, sa), dirs, hemisphere=hemisphere).weights
        P = (L * sa[:, None]).reshape(H, W, 3)
        cols = np.arange(W) // (W // n_az)
        expected = []
        for rows in ([slice(0, H // 2)] if hemisphere == "upper" else [slice(0, H // 2), slice(H // 2, H)]):
            expected += [P[rows][:, cols == k].sum(axis=(0, 1)) for k in range(n_az)]
        np.testing.assert_allclose(w, np.array(expected), rtol=1e-12)


# ----------------------------------------------------------------------------- linearity
def test_linear_in_the_map(rng):
    d, sa = LL128
    dirs = random_dirs(rng, 64, duplicates=3)
    L1 = rng.uniform(0, 1, size=d.shape)
    L2 = rng.exponential(5, size=d.shape)
    a, b = 0.3, 7.0
    R = random_rotation(rng)
    w1 = vo.integrate_weights((d, L1, sa), dirs, rotation=R).weights
    w2 = vo.integrate_weights((d, L2, sa), dirs, rotation=R).weights
    w12 = vo.integrate_weights((d, a * L1 + b * L2, sa), dirs, rotation=R).weights
    np.testing.assert_allclose(w12, a * w1 + b * w2, rtol=1e-12, atol=1e-15)


# ----------------------------------------------------------------------------- extremes
def test_single_light_gets_everything_kept(rng):
    d, sa = LL128
    L = rng.uniform(0, 1, size=d.shape)
    for hemisphere in ("upper", "full"):
        w = vo.integrate_weights((d, L, sa), [[0.3, -0.2, 0.9]], hemisphere=hemisphere)
        kept = (L * sa[:, None])[cv.in_domain(d, hemisphere)].sum(0)
        np.testing.assert_allclose(w.weights[0], kept, rtol=1e-12)


def test_two_antipodal_lights():
    d, sa = LL128
    one = np.ones_like(d)
    w = vo.integrate_weights((d, one, sa), [[0, 0, 1.0], [0, 0, -1.0]], hemisphere="full").weights[:, 0]
    np.testing.assert_allclose(w, [2 * np.pi, 2 * np.pi], rtol=1e-12)
    w = vo.integrate_weights((d, one, sa), [[0, 0, 1.0], [0, 0, -1.0]], hemisphere="upper").weights[:, 0]
    np.testing.assert_allclose(w, [2 * np.pi, 0.0], rtol=1e-12)
    # horizontal antipodes split the upper hemisphere in two equal halves (no texel centre on
    # the plane x = 0: the lat-long columns are symmetric about it)
    w = vo.integrate_weights((d, one, sa), [[1.0, 0, 0], [-1.0, 0, 0]], hemisphere="upper").weights[:, 0]
    np.testing.assert_allclose(w, [np.pi, np.pi], rtol=1e-12)


def test_horizon_and_pole_lights():
    d, sa = latlong(256)
    phi = np.radians([0, 90, 180, 270])
    dirs = np.concatenate([[[0, 0, 1.0]], cv.spherical_to_direction(np.full(4, np.pi / 2), phi)])
    w = vo.integrate_weights((d, np.ones_like(d), sa), dirs, hemisphere="upper").weights[:, 0]
    exact = vo.cell_solid_angles(dirs, "upper", method="spherical_voronoi")
    np.testing.assert_allclose(exact.sum(), 2 * np.pi, rtol=1e-12)
    # symmetric: the four horizon cells are equal
    np.testing.assert_allclose(exact[1:], exact[1], rtol=1e-9)
    # sampled vs exact: boundary quantisation at H = 256, stated 2e-3 sr
    np.testing.assert_allclose(w, exact, atol=2e-3)
    assert np.all(w > 0.5)


def test_sun_next_to_dim_sky_keeps_small_weights_accurate(rng):
    d, sa = LL128
    dirs = random_dirs(rng, 50)
    sky = np.full(d.shape, 1e-3)
    sun = np.zeros(d.shape)
    k = int(np.argmax(d @ cv.normalize(np.array([0.3, 0.2, 0.8]))))
    sun[k] = 1e6
    w_sky = vo.integrate_weights((d, sky, sa), dirs).weights
    w_all = vo.integrate_weights((d, sky + sun, sa), dirs).weights
    owner = vo.assign_cells(d[k:k + 1], dirs)[0]
    others = np.arange(50) != owner
    # the cells without the sun are summed independently: relative accuracy 1e-12, not 1e6 eps
    np.testing.assert_allclose(w_all[others], w_sky[others], rtol=1e-12)
    np.testing.assert_allclose(w_all[owner], w_sky[owner] + 1e6 * sa[k], rtol=1e-12)


def test_all_zero_map(rng):
    d, sa = LL128
    w = vo.integrate_weights((d, np.zeros_like(d), sa), random_dirs(rng, 10))
    assert np.all(w.weights == 0) and np.all(w.dropped_power == 0) and np.all(w.total_power == 0)


def test_duplicates_and_nearly_equal_directions(rng):
    d, sa = LL128
    L = rng.uniform(0, 1, size=d.shape)
    base = random_dirs(rng, 30)
    w0 = vo.integrate_weights((d, L, sa), base).weights
    # exact duplicate appended: the later copy has an empty cell, nothing else changes
    dup = np.concatenate([base, base[[4, 4, 17]]])
    w = vo.integrate_weights((d, L, sa), dup).weights
    np.testing.assert_array_equal(w[:30], w0)
    assert np.all(w[30:] == 0)
    # duplicate placed before its original: the lowest index wins
    w = vo.integrate_weights((d, L, sa), np.concatenate([base[[9]], base])).weights
    np.testing.assert_array_equal(w[0], w0[9])
    assert np.all(w[10] == 0)
    # nearly equal (1e-9 rad apart): the pair shares the cell of the single light
    near = np.concatenate([base, cv.normalize(base[[7]] + [[1e-9, 0, 0]])])
    w = vo.integrate_weights((d, L, sa), near).weights
    np.testing.assert_allclose(w[7] + w[30], w0[7], rtol=1e-12)
    np.testing.assert_array_equal(np.delete(w, [7, 30], axis=0), np.delete(w0, 7, axis=0))


def test_bad_input_raises():
    d, sa = latlong(8)
    with pytest.raises(ValueError):
        vo.integrate_weights((d, np.ones_like(d), sa), np.zeros((0, 3)))
    with pytest.raises(ValueError):
        vo.integrate_weights((d, np.ones_like(d), sa), [[0, 0, 0.0]])
    with pytest.raises(ValueError):
        vo.integrate_weights((d, np.ones_like(d), sa), [[0, 0, 1.0]], rotation=2 * np.eye(3))
    bad = np.ones_like(d)
    bad[3, 1] = np.nan
    with pytest.raises(ValueError):
        vo.integrate_weights((d, bad, sa), [[0, 0, 1.0]])
    with pytest.raises(ValueError):
        vo.integrate_weights((d, np.ones_like(d), sa), [[0, 0, 1.0]], hemisphere="lower")


# ----------------------------------------------------------------------------- cell areas
@pytest.mark.parametrize("hemisphere", ["upper", "full"])
@pytest.mark.parametrize("n", [1, 2, 3, 5, 50, 300])
def test_cell_solid_angles_sum(rng, hemisphere, n):
    dirs = random_dirs(rng, n, hemisphere, duplicates=n // 10)
    a = vo.cell_solid_angles(dirs, hemisphere, res=128)
    assert a.shape == (n,) and np.all(a >= 0)
    np.testing.assert_allclose(a.sum(), cv.covered_solid_angle(hemisphere), rtol=1e-9)


@pytest.mark.parametrize("hemisphere", ["upper", "full"])
def test_cell_solid_angles_methods_agree(rng, hemisphere):
    dirs = random_dirs(rng, 40, hemisphere, duplicates=2)
    a = vo.cell_solid_angles(dirs, hemisphere, method="spherical_voronoi")
    b = vo.cell_solid_angles(dirs, hemisphere, method="sample", res=256)
    # sampling error: boundary length x texel size at H = 256 (measured ~5e-4 sr)
    np.testing.assert_allclose(a, b, atol=3e-3)
    dup = np.flatnonzero(np.any(np.all(dirs[:, None] == dirs[None], axis=-1) & np.tri(40, k=-1, dtype=bool), axis=1))
    assert dup.size == 2 and np.all(a[dup] == 0) and np.all(b[dup] == 0)


# ----------------------------------------------------------------------------- cell texture
def _latlong_1024x512():
    from ffls.lightmaps.sphere_maps import get_map

    m = get_map("latlong")
    return m.directions(512).reshape(-1, 3), m.solid_angles(512).ravel()


@pytest.mark.parametrize("hemisphere", ["upper", "full"])
@pytest.mark.parametrize("n", [50, 400, 2048])
def test_candidate_lookup_equals_kdtree_for_every_texel(rng, hemisphere, n):
    # Every texel of a 1024 x 512 lat-long map, randomly rotated: the candidate-texture cell
    # must be the exact (k-d tree, max dot, lowest index) cell. Measured: 0 mismatches.
    d, _ = _latlong_1024x512()
    dirs = random_dirs(rng, n, hemisphere, duplicates=n // 50)
    cells = vo.bake_cells(dirs, hemisphere, res=256, max_res=1024)
    assert cells.overflow == 0
    p = cv.rotate_directions(random_rotation(rng), d)
    p = p[cv.in_domain(p, hemisphere)]
    exact = vo.assign_cells(p, dirs)
    looked_up = vo.assign_cells(p, dirs, cells)
    assert np.count_nonzero(exact != looked_up) == 0


def test_cell_texture_layout(rng):
    dirs = random_dirs(rng, 100, duplicates=5)
    cells = vo.bake_cells(dirs, "upper", res=64, k=8)
    assert cells.index.shape == (64, 64) and cells.index.dtype == np.int32
    assert cells.candidates.shape == (64, 64, 8) and cells.candidates.dtype == np.int32
    c = cells.candidates.reshape(-1, 8)
    valid = c >= 0
    # -1 padding only at the end, indices strictly increasing, the centre's nearest included
    assert np.all(valid[:, 0]) and np.all(valid[:, :-1] | ~valid[:, 1:])
    assert np.all(np.where(valid[:, 1:], np.diff(c, axis=1) > 0, True))
    assert np.all(np.any(c == cells.index.reshape(-1, 1), axis=1))
    # later duplicates never appear
    _, keep = vo.unique_directions(dirs)
    assert not np.isin(np.setdiff1d(np.arange(100), keep), c).any()
    # the index texture is the exact cell of each texel centre
    from ffls.lightmaps.sphere_maps import get_map

    centres = get_map("concentric").directions(64).reshape(-1, 3)
    np.testing.assert_array_equal(cells.index.ravel(), vo.assign_cells(centres, dirs))


def test_overflow_is_counted_and_res_raised(rng):
    dirs = random_dirs(rng, 200)
    small = vo.bake_cells(dirs, "upper", res=32, k=1)
    assert small.overflow > 0  # k = 1 cannot hold the texels on cell edges
    grown = vo.bake_cells(dirs, "upper", res=32, k=2, max_res=256)
    assert grown.res > 32 or grown.overflow == 0
    assert grown.res <= 256


@pytest.mark.parametrize("case", ["single", "antipodal", "horizon_pole", "duplicates", "nearly_equal"])
@pytest.mark.parametrize("hemisphere", ["upper", "full"])
def test_candidate_lookup_extremes(rng, case, hemisphere):
    d, sa = latlong(256)
    dirs = {
        "single": [[0.0, 0.0, 1.0]],
        "antipodal": [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]],
        "horizon_pole": np.concatenate([[[0, 0, 1.0]], cv.spherical_to_direction(
            np.full(6, np.pi / 2), np.radians(np.arange(6) * 60.0))]),
        "duplicates": np.repeat(random_dirs(rng, 5, hemisphere), 3, axis=0),
        "nearly_equal": np.concatenate([[[0.3, 0.2, 0.9]], cv.normalize([[0.3, 0.2 + 1e-9, 0.9]]),
                                        random_dirs(rng, 8, hemisphere)]),
    }[case]
    cells = vo.bake_cells(dirs, hemisphere, res=128, max_res=512)
    L = rng.uniform(0, 1, size=d.shape)
    R = random_rotation(rng)
    w_exact = vo.integrate_weights((d, L, sa), dirs, R, hemisphere)
    w_cells = vo.integrate_weights((d, L, sa), dirs, R, hemisphere, cells=cells)
    assert cells.overflow == 0
    np.testing.assert_array_equal(w_cells.weights, w_exact.weights)
    assert w_cells.dropped_texels == w_exact.dropped_texels


def test_cells_must_match_directions(rng):
    d, sa = latlong(16)
    cells = vo.bake_cells(random_dirs(rng, 10), "upper", res=16)
    with pytest.raises(ValueError):
        vo.integrate_weights((d, np.ones_like(d), sa), random_dirs(rng, 10), cells=cells)
    with pytest.raises(ValueError):
        vo.integrate_weights((d, np.ones_like(d), sa), cells.directions, hemisphere="full", cells=cells)


def test_rotate_directions_is_the_matrix_product(rng):
    d = cv.normalize(rng.normal(size=(1000, 3)))
    R = random_rotation(rng)
    np.testing.assert_allclose(cv.rotate_directions(R, d), d @ R.T, rtol=0, atol=1e-15)
    np.testing.assert_allclose(cv.rotate_directions(R, d.reshape(10, 100, 3)), (d @ R.T).reshape(10, 100, 3),
                               rtol=0, atol=1e-15)


def test_lightmap_object_accepted():
    from ffls.lightmaps.lightmap import constant_map

    lm = constant_map(64, radiance=(1.0, 2.0, 3.0))
    dirs = [[0, 0, 1.0], [1.0, 0, 0.2], [-0.5, 0.5, 0.3]]
    w = vo.integrate_weights(lm, dirs)
    np.testing.assert_allclose(w.weights.sum(0), np.array([1.0, 2.0, 3.0]) * 2 * np.pi, rtol=1e-9)
