"""The ground bounce less the sphere's own shadow (ffls.spheres.lambert.own_shadow_factor) and its use in the fit.

The view factor is checked against an independent computation: an area integral over the
shadow on the ground (the sphere's projection along the light), not the table's hemisphere
quadrature. The fits use spheres rendered with that independent shadow.
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import angle_between, normalize
from ffls.spheres.lambert import fit_lambert, own_shadow_factor, shadowed_ground_bounce
from ffls.spheres.samples import ground_bounce


def shadow_view_factor_by_area(n: np.ndarray, light: np.ndarray, grid: int = 500) -> float:
    """View factor from the point of normal ``n`` on a unit sphere resting on ``z = -1`` to its shadow.

    ``F = integral over the shadow of cos_p cos_g / (pi d^2) dA``, on a ``grid x grid`` lattice of
    the ground around the shadow (a ground point is in shadow when the ray toward the light meets
    the sphere).
    """
    p = np.asarray(n, dtype=np.float64)
    lz = light[2]
    # the shadow lies between the contact point and the projection of the sphere along the light
    reach = 1.0 + 2.0 / max(lz, 1e-3)
    x = np.linspace(-reach, reach, grid)
    h = x[1] - x[0]
    X, Y = np.meshgrid(x, x)
    G = np.stack([X.ravel(), Y.ravel(), np.full(X.size, -1.0)], axis=1)
    w = -G
    tc = w @ light
    shadow = (tc > 0) & (np.einsum("ij,ij->i", w, w) - tc * tc < 1.0)
    d = G[shadow] - p
    dist = np.linalg.norm(d, axis=1)
    cos_p = np.maximum(d @ p, 0.0) / dist  # the normal of a unit sphere point is the point
    cos_g = (p[2] + 1.0) / dist
    return float(np.sum(cos_p * cos_g / (np.pi * dist ** 2)) * h * h)


@pytest.mark.parametrize("nz, az, elev", [(-0.3, 180.0, 45.0), (0.0, 150.0, 30.0), (-0.5, 90.0, 60.0),
                                          (0.3, 180.0, 20.0), (-0.2, 0.0, 50.0), (-0.6, 120.0, 80.0)])
def test_own_shadow_factor_matches_an_area_integral_over_the_shadow(nz, az, elev):
    n = np.array([np.sqrt(1 - nz * nz), 0.0, nz])
    e, a = np.radians(elev), np.radians(az)
    light = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    ref = shadow_view_factor_by_area(n, light)
    got = float(own_shadow_factor(n[None], light)[0])
    assert abs(got - ref) < 0.01 + 0.05 * ref, (got, ref)
    # the same geometry turned about the vertical, in another size: the same factor (scale-free)
    t = np.radians(37.0)
    Rz = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1.0]])
    assert abs(float(own_shadow_factor((Rz @ n)[None], Rz @ light)[0]) - got) < 1e-9


def test_own_shadow_factor_limits():
    rng = np.random.default_rng(0)
    n = normalize(rng.normal(size=(4000, 3)))
    for light in (normalize(np.array([0.3, -0.2, 0.9])), normalize(np.array([-0.8, 0.1, 0.25]))):
        S = own_shadow_factor(n, light)
        g = ground_bounce(n)
        assert S.min() >= 0.0 and np.all(S <= g + 0.02)  # a part of the ground's view factor
        assert np.all(S[n[:, 2] > 0.999] < 1e-3)  # the top sees no ground
        assert np.all(shadowed_ground_bounce(n, light) >= 0.0)
        # lower points turned toward the light's azimuth see the lit ground; turned away, the shadow
        lh = normalize(light * [1, 1, 0])
        facing = (n * [1, 1, 0]) @ lh / np.linalg.norm(n[:, :2], axis=1)
        low = (n[:, 2] < -0.2) & (n[:, 2] > -0.8)
        assert S[(facing > 0.7) & low].mean() < 0.2 * S[(facing < -0.7) & low].mean()
    # light overhead: the shadow is the disc under the sphere, the same in every azimuth
    ring = np.stack([np.cos(np.linspace(0, 6, 12)) * 0.8, np.sin(np.linspace(0, 6, 12)) * 0.8, np.full(12, -0.6)], 1)
    S = own_shadow_factor(ring, np.array([0.0, 0.0, 1.0]))
    assert np.ptp(S) < 1e-9 and S[0] > 0.1
    # no light above the ground: no shadow (and no ground irradiance)
    assert not own_shadow_factor(n, np.array([0.3, 0.0, -0.5])).any()


def _sphere_normals(camera_elevation_deg: float = 25.0, k: int = 60) -> np.ndarray:
    """The visible normals of a sphere seen from a camera at -Y, raised by ``camera_elevation_deg``."""
    u = (np.arange(k) + 0.5) / k * 2 - 1
    X, Y = np.meshgrid(u, u)
    inside = X * X + Y * Y < 0.97
    x, y = X[inside], Y[inside]
    view = np.stack([x, -np.sqrt(1 - x * x - y * y), -y], axis=1)  # camera frame mapped to world, level
    e = np.radians(camera_elevation_deg)
    R = np.array([[1, 0, 0], [0, np.cos(e), -np.sin(e)], [0, np.sin(e), np.cos(e)]])
    return view @ R.T


def _render_with_area_shadow(n: np.ndarray, light: np.ndarray, ground_ratio: float, ambient: float = 0.0):
    """Lambert + ambient + bounce of a uniformly lit ground less the sphere's own shadow (area integral)."""
    S = np.array([shadow_view_factor_by_area(p, light, grid=160) for p in n])
    return 0.6 * np.maximum(n @ light, 0.0) + ambient + 0.6 * ground_ratio * light[2] * (ground_bounce(n) - S)


@pytest.fixture(scope="module")
def backlit():
    """A light behind the sphere (its shadow falls toward the camera): the case the term is for."""
    n = _sphere_normals()
    light = normalize(np.array([0.5, 0.5, 0.7]))
    return n, light, _render_with_area_shadow(n, light, 0.3)


def test_free_fit_with_the_own_shadow_finds_the_ground_ratio(backlit):
    n, light, y = backlit
    fit = fit_lambert(n, y)
    assert fit.model == "bounce" and fit.status == "ok"
    assert abs(fit.ground_ratio - 0.3) < 0.01, fit.ground_ratio
    assert np.degrees(angle_between(fit.direction, light)) < 0.1
    assert fit.own_shadow and fit.as_dict()["own_shadow"] is True
    # the infinite-ground form factor: the shadow side looks too dark for it, the ratio is lost
    # and the difference goes into the ambient and the direction
    plain = fit_lambert(n, y, own_shadow=False)
    assert not abs(plain.ground_ratio - 0.3) < 0.05
    assert np.degrees(angle_between(plain.direction, light)) > 1.0


def test_calibrated_ratio_with_the_own_shadow_gives_the_direction(backlit):
    n, light, y = backlit
    start = normalize(light + np.array([0.03, -0.02, 0.0]))
    fit = fit_lambert(n, y, bounce_ratio=0.3, start=start)
    assert np.degrees(angle_between(fit.direction, light)) < 0.1
    assert abs(fit.bounce - 0.3 * fit.intensity * fit.direction[2]) < 1e-9
    plain = fit_lambert(n, y, bounce_ratio=0.3, start=start, own_shadow=False)
    assert np.degrees(angle_between(plain.direction, light)) > 1.0


def test_black_ground_directions_do_not_change():
    """No bounce in the data: the own-shadow term (a refinement of the bounce) changes nothing."""
    n = _sphere_normals()
    light = normalize(np.array([-0.4, 0.5, 0.6]))
    y = 0.6 * np.maximum(n @ light, 0.0)
    a = fit_lambert(n, y)
    b = fit_lambert(n, y, own_shadow=False)
    assert np.degrees(angle_between(a.direction, b.direction)) < 1e-3
    assert np.degrees(angle_between(a.direction, light)) < 1e-3
    assert not a.own_shadow and a.as_dict()["own_shadow"] is False  # no bounce fitted: nothing taken out
    c = fit_lambert(n, y, bounce_ratio=0.0)
    assert np.degrees(angle_between(c.direction, light)) < 1e-3


def test_own_shadow_geometry_made_once_per_normals_array(backlit, monkeypatch):
    """The own shadow's per-pixel geometry (``OwnShadow``) depends on the normals and ``up`` only:
    the fits of one normals array (a sphere's, over a capture's photos and passes) make it once,
    with the same fits as a fresh one each time; another array, or another ``up``, gets its own."""
    import ffls.spheres.lambert as lam

    n, light, y = backlit
    n = n.copy()  # (an array no other test has fitted)
    monkeypatch.setattr(lam, "OWN_SHADOWS_KEPT", 10 ** 6)  # (the kept ones not cleared by earlier tests' arrays)
    made = []
    init = lam.OwnShadow.__init__

    def counting(self, *args, **kwargs):
        made.append(1)
        init(self, *args, **kwargs)

    fresh = [fit_lambert(n.copy(), y), fit_lambert(n.copy(), y, bounce_ratio=0.3)]
    monkeypatch.setattr(lam.OwnShadow, "__init__", counting)
    kept = [fit_lambert(n, y), fit_lambert(n, y, bounce_ratio=0.3), fit_lambert(n, 1.1 * y)]
    assert len(made) == 1
    for a, b in zip(fresh, kept):
        assert a.status == b.status == "ok" and a.model == b.model
        assert np.array_equal(a.direction, b.direction) and a.bounce == b.bounce
    assert lam.own_shadow_of(n) is lam.own_shadow_of(n) and lam.own_shadow_of(n.copy()) is not lam.own_shadow_of(n)
    up = normalize(np.array([0.0, 0.1, 1.0]))
    assert lam.own_shadow_of(n, up) is not lam.own_shadow_of(n) and len(made) == 3
