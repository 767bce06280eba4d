"""Tests of ffls.lightmaps.sphere_maps and its GLSL twin shaders/include/sphere_maps.glsl."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ffls import conventions
from ffls.lightmaps.sphere_maps import MAPS, DEFAULT_PROBE_FRAME, AngularMap, MirrorBallMap, get_map

NAMES = sorted(MAPS)
FLAT = [n for n in NAMES if n != "cube"]
RESOLUTIONS = (1, 2, 3, 7, 10, 64, 255)


def _random_dirs(rng, n):
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _in_domain(m, d):
    return conventions.in_domain(d, m.domain)


def _angle(a, b):
    return conventions.angle_between(a, b)


def _spherical_triangle_area(a, b, c):
    """Van Oosterom & Strackee: solid angle of the spherical triangle abc, (...)."""
    num = np.abs(np.einsum("...i,...i", a, np.cross(b, c)))
    den = 1 + np.einsum("...i,...i", a, b) + np.einsum("...i,...i", b, c) + np.einsum("...i,...i", c, a)
    return 2 * np.arctan2(num, den)


def _texel_dir_fn(m, face=None):
    if m.name == "cube":
        return lambda uv: m.uv_to_direction(face, uv)
    return m.uv_to_direction


# ----------------------------------------------------------------------------- registry
def test_registry():
    assert set(MAPS) == {"latlong", "concentric", "octahedral", "angular", "mirrorball", "cube"}
    for name, m in MAPS.items():
        assert get_map(name) is m and m.name == name
        assert m.domain in conventions.HEMISPHERES
    assert get_map("concentric").domain == "upper"
    with pytest.raises(ValueError, match="known: latlong"):
        get_map("fisheye")
    with pytest.raises(ValueError):
        get_map("latlong").shape(0)
    with pytest.raises(ValueError):
        AngularMap(world_from_map=np.diag([1.0, 1.0, -1.0]))


@pytest.mark.parametrize("name", NAMES)
def test_shapes(name):
    m = get_map(name)
    expect = {"latlong": (7, 14), "cube": (6, 7, 7)}.get(name, (7, 7))
    assert m.shape(7) == expect
    assert m.solid_angles(7).shape == expect and m.solid_angles(7).dtype == np.float64
    assert m.valid_mask(7).shape == expect and m.valid_mask(7).dtype == bool
    assert m.directions(7).shape == expect + (3,)


# ----------------------------------------------------------------------------- solid angles
@pytest.mark.parametrize("res", RESOLUTIONS)
@pytest.mark.parametrize("name", NAMES)
def test_solid_angle_sum(name, res):
    """Sums hit 2 pi / 4 pi to rounding (the requirement is 1e-6 relative; we assert 1e-12)."""
    m = get_map(name)
    total = conventions.covered_solid_angle(m.domain)
    om = m.solid_angles(res)
    assert abs(om.sum() / total - 1.0) < 1e-12
    valid = m.valid_mask(res)
    assert np.all(om[valid] > 0) and np.all(om[~valid] == 0)
    d = m.directions(res)
    assert np.all(np.isfinite(d[valid])) and np.all(np.isnan(d[~valid]))
    np.testing.assert_allclose(np.linalg.norm(d[valid], axis=-1), 1.0, atol=1e-13)
    assert np.all(_in_domain(m, d[valid]))


@pytest.mark.parametrize("name", ["concentric", "octahedral"])
def test_equal_area_maps_are_uniform(name):
    m = get_map(name)
    om = m.solid_angles(9)
    np.testing.assert_allclose(om, conventions.covered_solid_angle(m.domain) / 81, rtol=1e-15)


@pytest.mark.parametrize("name", NAMES)
def test_texel_solid_angle_by_triangulation(name):
    """Independent estimate: split a texel into 64 x 64 sub-quads, map their corners through
    uv_to_direction and add up the spherical triangles. The estimate's error is O(1/64^2);
    tolerance 2e-4 relative. Texels chosen inside the valid region (not cut by the disc's rim)."""
    m = get_map(name)
    res = 7
    om = m.solid_angles(res)
    k = 64
    s = np.linspace(0.0, 1.0, k + 1)
    texels = [(0, 3, 3), (0, 0, 0), (2, 1, 5), (5, 6, 2)] if name == "cube" else \
        [(None, 3, 3), (None, 1, 2), (None, 2, 1), (None, 5, 4), (None, 1 if name in ("angular", "mirrorball") else 0, 6 if name == "latlong" else 3)]
    for face, j, i in texels:
        h, w = om.shape[-2:]
        uu, vv = np.meshgrid((i + s) / w, (j + s) / h)
        p = _texel_dir_fn(m, face)(np.stack([uu, vv], -1))
        assert np.all(np.isfinite(p)), (name, j, i)
        a, b, c, d = p[:-1, :-1], p[:-1, 1:], p[1:, 1:], p[1:, :-1]
        est = np.sum(_spherical_triangle_area(a, b, c) + _spherical_triangle_area(a, c, d))
        exact = om[j, i] if face is None else om[face, j, i]
        assert est == pytest.approx(exact, rel=2e-4), (name, face, j, i)


@pytest.mark.parametrize("name", NAMES)
def test_texel_solid_angle_monte_carlo(name, rng):
    """Every texel at res 5 (the disc maps' rim texels included) against the fraction of
    400 000 uniform directions that texel_index puts in it: |error| < 5 sigma + 1e-12."""
    m = get_map(name)
    res, n = 5, 400_000
    d = _random_dirs(rng, n)
    if m.domain == "upper":
        d[:, 2] = np.abs(d[:, 2])
    total = conventions.covered_solid_angle(m.domain)
    idx = m.texel_index(d, res)
    assert np.all(idx >= 0)
    counts = np.bincount(idx, minlength=m.solid_angles(res).size)
    om = m.solid_angles(res).ravel()
    p = om / total
    sigma = total * np.sqrt(p * (1 - p) / n)
    err = np.abs(counts * total / n - om)
    assert np.all(err < 5 * sigma + 1e-12), np.max(err / np.maximum(sigma, 1e-300))
    assert np.all(counts[om == 0] == 0)


def test_disc_texel_solid_angle_against_quadrature():
    """Rim texels of the angular and mirror-ball maps against scipy's adaptive quadrature of
    dOmega = pi sin(pi r)/r dA and 4 dA over texel ∩ disc (tolerance 1e-10 absolute)."""
    from scipy import integrate

    res = 7
    for m, f in ((get_map("angular"), lambda r: np.pi ** 2 * np.sinc(r)),
                 (get_map("mirrorball"), lambda r: 4.0)):
        om = m.solid_angles(res)
        for j, i in ((0, 3), (1, 0), (3, 6), (6, 5), (3, 3)):
            x0, y1 = -1 + 2 * i / res, 1 - 2 * j / res
            x1, y0 = x0 + 2 / res, y1 - 2 / res

            def inner(x):
                h = np.sqrt(max(1 - x * x, 0.0))
                lo, hi = max(y0, -h), min(y1, h)
                if hi <= lo:
                    return 0.0
                return integrate.quad(lambda y: f(np.hypot(x, y)), lo, hi, epsabs=1e-14)[0]

            ref = integrate.quad(inner, x0, x1, epsabs=1e-14, limit=200)[0]
            assert om[j, i] == pytest.approx(ref, abs=1e-10), (m.name, j, i)


# ----------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("name", NAMES)
def test_direction_round_trip(name, rng):
    m = get_map(name)
    d = _random_dirs(rng, 5000)
    d = d[_in_domain(m, d)]
    if name == "cube":
        face, uv = m.direction_to_uv(d)
        back = m.uv_to_direction(face, uv)
        assert np.all((uv >= 0) & (uv <= 1))
    else:
        uv = m.direction_to_uv(d)
        back = m.uv_to_direction(uv)
        assert np.all((uv >= 0) & (uv <= 1))
    assert np.max(_angle(back, d)) < 1e-12


@pytest.mark.parametrize("name", NAMES)
def test_uv_round_trip(name, rng):
    m = get_map(name)
    uv = rng.uniform(0.0, 1.0, size=(5000, 2))
    if name == "cube":
        face = rng.integers(0, 6, size=5000)
        f2, uv2 = m.direction_to_uv(m.uv_to_direction(face, uv))
        np.testing.assert_array_equal(f2, face)
    else:
        if name in ("angular", "mirrorball"):
            uv = uv[np.hypot(2 * uv[:, 0] - 1, 2 * uv[:, 1] - 1) < 0.999]
        uv2 = m.direction_to_uv(m.uv_to_direction(uv))
    np.testing.assert_allclose(uv2, uv, atol=1e-10)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("res", (1, 3, 7, 64))
def test_texel_index_consistency(name, res):
    m = get_map(name)
    valid = m.valid_mask(res)
    idx = m.texel_index(m.directions(res)[valid], res)
    np.testing.assert_array_equal(idx, np.flatnonzero(valid))


def test_texel_index_outside_domain():
    conc = get_map("concentric")
    d = np.array([[0.0, 0.0, -1.0], [0.3, 0.2, -0.1], [np.nan, 0.0, 1.0], [0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(conc.texel_index(d, 8), [-1, -1, -1, -1])
    assert np.all(np.isnan(conc.direction_to_uv(d)))
    for name in ("latlong", "octahedral", "angular", "mirrorball", "cube"):
        m = get_map(name)
        idx = m.texel_index(d, 8)
        assert idx[2] == -1 and np.all(idx[:2] >= 0), name
        assert np.all(m.valid_mask(8).ravel()[idx[:2]]), name


@pytest.mark.parametrize("name", ["angular", "mirrorball"])
def test_disc_maps_rim_goes_to_valid_texels(name, rng):
    """Directions near the rim (the direction behind the probe) land in valid texels only,
    even where the rim clips a texel to a sliver below the solid-angle floor."""
    m = get_map(name)
    back = -DEFAULT_PROBE_FRAME[:, 2]
    d = back + 1e-7 * rng.normal(size=(2000, 3))
    for res in (7, 10, 64, 255):
        idx = m.texel_index(d, res)
        assert np.all(idx >= 0) and np.all(m.valid_mask(res).ravel()[idx])
    outside = np.array([[0.99, 0.99], [0.0, 0.0], [0.1, 0.05]])
    assert np.all(np.isnan(m.uv_to_direction(outside)))


@settings(max_examples=150, deadline=None)
@given(st.tuples(*[st.floats(-1, 1, allow_nan=False) for _ in range(3)]).filter(
    lambda v: np.linalg.norm(v) > 1e-3), st.integers(1, 300))
def test_hypothesis_invariants(v, res):
    """For any direction: each map's texel_index is a valid texel of the domain, and the
    direction -> uv -> direction round trip closes to 1e-11 rad. Two maps get 1e-7 rad: the
    mirror ball, because next to its rim r = 1 - (pi - theta)^2 / 8 turns the rounding of uv
    (1e-16) into sqrt(8e-16) = 3e-8 rad; and lat-long, because conventions.direction_to_spherical
    takes theta = arccos(z), which is good to only ~sqrt(eps) = 1.5e-8 rad next to the poles."""
    d = np.asarray(v, dtype=np.float64)
    d /= np.linalg.norm(d)
    for name in NAMES:
        m = MAPS[name]
        if not _in_domain(m, d):
            assert m.texel_index(d, res) == -1
            continue
        idx = m.texel_index(d, res)
        assert 0 <= idx < np.prod(m.shape(res))
        if name in ("angular", "mirrorball", "latlong", "cube"):
            assert m.valid_mask(res).ravel()[idx]
        back = m.uv_to_direction(*m.direction_to_uv(d)) if name == "cube" else \
            m.uv_to_direction(m.direction_to_uv(d))
        assert _angle(back, d) < (1e-7 if name in ("mirrorball", "latlong") else 1e-11), name


@settings(max_examples=100, deadline=None)
@given(st.floats(0, 1), st.floats(0, 1))
def test_hypothesis_equal_area_uv_in_square(u, v):
    """Every uv in the closed square maps to a unit direction in the domain (no NaN)."""
    for name in ("concentric", "octahedral"):
        m = MAPS[name]
        d = m.uv_to_direction(np.array([u, v]))
        assert np.linalg.norm(d) == pytest.approx(1.0, abs=1e-14)
        assert _in_domain(m, d)


# ----------------------------------------------------------------------------- orientation
def test_latlong_orientation():
    m = get_map("latlong")
    res = 64
    d = m.directions(res)
    np.testing.assert_array_equal(d, conventions.latlong_directions(2 * res, res))
    assert np.all(d[0, :, 2] > np.cos(np.pi / res))  # top row: +Z
    np.testing.assert_allclose(m.uv_to_direction([[0.5, 0.5], [0.25, 0.5], [0.5, 0.0], [0.5, 1.0]]),
                               [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]], atol=1e-15)
    # centre column +X, quarter-from-left column +Y on the equator (even width: texel edges)
    W = 2 * res
    assert m.texel_index([1.0, 0.0, 0.0], res) % W == W // 2
    assert m.texel_index([0.0, 1.0, 0.0], res) % W == W // 4


def test_concentric_and_octahedral_orientation():
    uv = np.array([[0.5, 0.5], [1.0, 0.5], [0.5, 0.0], [0.0, 0.5], [0.5, 1.0]])
    expect = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    for name in ("concentric", "octahedral"):
        m = get_map(name)
        np.testing.assert_allclose(m.uv_to_direction(uv), expect, atol=1e-15)
        np.testing.assert_allclose(m.direction_to_uv(expect), uv, atol=1e-15)
    # +X is to the right of the image and +Y toward its top, for directions off the zenith too
    conc = get_map("concentric")
    uv = conc.direction_to_uv([[0.3, 0.0, 0.9], [0.0, 0.3, 0.9]])
    assert uv[0, 0] > 0.5 and uv[0, 1] == pytest.approx(0.5)
    assert uv[1, 1] < 0.5 and uv[1, 0] == pytest.approx(0.5)
    octa = get_map("octahedral")
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    np.testing.assert_allclose(octa.uv_to_direction(corners), [[0, 0, -1]] * 4, atol=1e-15)


@pytest.mark.parametrize("cls", [AngularMap, MirrorBallMap])
def test_probe_orientation(cls):
    m = cls()
    r_half = 0.5 if cls is AngularMap else np.sin(np.pi / 4)  # theta = 90 degrees
    uv = np.array([[0.5, 0.5], [0.5 + r_half / 2, 0.5], [0.5, 0.5 - r_half / 2], [1.0, 0.5]])
    np.testing.assert_allclose(m.uv_to_direction(uv), [[0, -1, 0], [1, 0, 0], [0, 0, 1], [0, 1, 0]],
                               atol=1e-15)
    # another frame: centre +Z (looking down from above), right +X, up +Y
    top = cls(world_from_map=np.eye(3))
    np.testing.assert_allclose(top.uv_to_direction([[0.5, 0.5]]), [[0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(top.direction_to_uv([[0.0, 1.0, 0.0]]), [[0.5, 0.5 - r_half / 2]], atol=1e-15)


def test_cube_opengl_faces():
    m = get_map("cube")
    axes = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    face, uv = m.direction_to_uv(axes)
    np.testing.assert_array_equal(face, np.arange(6))
    np.testing.assert_allclose(uv, 0.5)
    # OpenGL table 8.19 at s = 1 (sc = +1) and t = 1 (tc = +1) on every face
    s1 = [[1, 0, -1], [-1, 0, 1], [1, 1, 0], [1, -1, 0], [1, 0, 1], [-1, 0, -1]]
    t1 = [[1, -1, 0], [-1, -1, 0], [0, 1, 1], [0, -1, -1], [0, -1, 1], [0, -1, -1]]
    for f in range(6):
        np.testing.assert_allclose(m.uv_to_direction(f, [1.0, 0.5]), np.array(s1[f]) / np.sqrt(2), atol=1e-15)
        np.testing.assert_allclose(m.uv_to_direction(f, [0.5, 1.0]), np.array(t1[f]) / np.sqrt(2), atol=1e-15)
    face, px = m.to_pixel([[1.0, 0.0, 0.0]], 8)
    assert face[0] == 0 and np.allclose(px, 4.0)


# ----------------------------------------------------------------------------- GLSL twin
@pytest.mark.gl
def test_glsl_matches_python(ctx, rng):
    """concentric/octahedral/latlong in GLSL (float32) against Python (float64) for 10^4
    random directions and uv: |uv| within 1e-5 and directions within 1e-5 (componentwise).

    Seams are excluded where uv jumps: lat-long directions with u within 1e-4 of 0 or 1 (the
    phi = +-pi meridian) and octahedral lower-hemisphere directions with |x| or |y| < 1e-4 (the
    folds onto the square's border). Concentric uv is compared for z >= 1e-4 only (its domain)."""
    from ffls.gpu.shaders import load_program

    n = 10_000
    d = _random_dirs(rng, n)
    uv = rng.uniform(0.0, 1.0, size=(n, 2))
    prog = load_program(ctx, str(Path(__file__).resolve().parent / "shaders" / "sphere_maps_probe.glsl"))
    b_dir = ctx.buffer(np.concatenate([d, np.zeros((n, 1))], axis=1).astype("f4").tobytes())
    b_uv = ctx.buffer(uv.astype("f4").tobytes())
    b_out = ctx.buffer(reserve=n * 5 * 16)
    b_dir.bind_to_storage_buffer(0)
    b_uv.bind_to_storage_buffer(1)
    b_out.bind_to_storage_buffer(2)
    prog["n"] = n
    prog.run(group_x=(n + 63) // 64)
    out = np.frombuffer(b_out.read(), dtype="f4").reshape(n, 5, 4).astype(np.float64)
    for b in (b_dir, b_uv, b_out):
        b.release()

    d32 = d.astype("f4").astype(np.float64)  # the GPU's input
    conc, octa, ll = get_map("concentric"), get_map("octahedral"), get_map("latlong")
    up = d32[:, 2] >= 1e-4
    np.testing.assert_allclose(out[up, 0, :2], conc.direction_to_uv(d32[up]), atol=1e-5)
    keep = (d32[:, 2] >= 0) | ((np.abs(d32[:, 0]) >= 1e-4) & (np.abs(d32[:, 1]) >= 1e-4))
    np.testing.assert_allclose(out[keep, 0, 2:], octa.direction_to_uv(d32[keep]), atol=1e-5)
    ll_uv = ll.direction_to_uv(d32)
    keep = np.minimum(ll_uv[:, 0], 1 - ll_uv[:, 0]) >= 1e-4
    np.testing.assert_allclose(out[keep, 1, :2], ll_uv[keep], atol=1e-5)
    assert keep.sum() > 0.99 * n

    uv32 = uv.astype("f4").astype(np.float64)
    np.testing.assert_allclose(out[:, 2, :3], conc.uv_to_direction(uv32), atol=1e-5)
    np.testing.assert_allclose(out[:, 3, :3], octa.uv_to_direction(uv32), atol=1e-5)
    np.testing.assert_allclose(out[:, 4, :3], ll.uv_to_direction(uv32), atol=1e-5)
