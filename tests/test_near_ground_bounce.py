"""The ground bounce under a near (point) light (ffls.spheres.lambert.near_ground_bounce).

The form factor is checked against an independent computation: an area integral over the ground
(polar lattice around the contact point, point-light irradiance with cosine and inverse square,
shadow rays against the sphere), not the hemisphere quadrature of the function.
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import normalize
from ffls.spheres.lambert import near_ground_bounce, shadowed_ground_bounce

UP = np.array([0.0, 0.0, 1.0])


def near_bounce_by_area(p: np.ndarray, n: np.ndarray, center: np.ndarray, radius: float, light: np.ndarray,
                        n_r: int = 900, n_t: int = 720, r_max: float = 400.0) -> float:
    """``integral over the lit ground of cos_p cos_g / (pi d^2) E(x) / E(G) dA`` from the point ``p``.

    The ground is the plane through the contact point ``G``; a polar lattice around ``G``
    (log-spaced radii out to ``r_max`` sphere radii) covers it.
    """
    G = center - radius * UP
    r = radius * np.geomspace(1e-3, r_max, n_r)
    dr = np.gradient(r)
    t = (np.arange(n_t) + 0.5) * 2.0 * np.pi / n_t
    R, T = np.meshgrid(r, t, indexing="ij")
    X = np.stack([G[0] + R * np.cos(T), G[1] + R * np.sin(T), np.full(R.shape, G[2])], axis=-1).reshape(-1, 3)
    dA = (R * dr[:, None] * (2.0 * np.pi / n_t)).ravel()
    d = X - p
    dist = np.linalg.norm(d, axis=1)
    cos_p = np.maximum(d @ n, 0.0) / dist
    cos_g = np.maximum(-(d @ UP), 0.0) / dist
    V = light - X
    rv = np.linalg.norm(V, axis=1)
    E = np.maximum(V @ UP, 0.0) / rv ** 3
    U = V / rv[:, None]
    W = center - X
    tc = np.einsum("ij,ij->i", W, U)
    lit = ~((tc > 0) & (np.einsum("ij,ij->i", W, W) - tc * tc < radius * radius))
    e_ref = float((light - G) @ UP) / float(np.linalg.norm(light - G)) ** 3
    return float(np.sum(cos_p * cos_g / (np.pi * dist ** 2) * E * lit * dA) / e_ref)


@pytest.mark.parametrize("nz, az, light", [(-0.4, 180.0, (0.0, -1.5, 1.2)), (0.0, 90.0, (0.5, 1.8, 0.7)),
                                           (-0.7, 30.0, (0.3, 0.2, 1.9)), (0.2, 200.0, (-1.9, 0.4, 0.6))])
def test_near_form_factor_matches_an_area_integral_over_the_ground(nz, az, light):
    center, radius = np.array([0.2, -0.1, 0.05]), 0.05
    a = np.radians(az)
    n = np.array([np.sqrt(1 - nz * nz) * np.cos(a), np.sqrt(1 - nz * nz) * np.sin(a), nz])
    p = center + radius * n
    S = np.asarray(light, dtype=np.float64)
    ref = near_bounce_by_area(p, n, center, radius, S)
    got = float(near_ground_bounce(p[None], n[None], center, radius, S, side=48)[0])
    assert abs(got - ref) < 0.01 + 0.03 * ref, (got, ref)


@pytest.mark.parametrize("light", [(1.0, 0.5, 1.2), (0.0, -1.8, 0.7), (-1.9, 0.4, 0.6)])
def test_default_quadrature_and_interpolation_follow_the_fine_quadrature(light):
    """The default (a coarser quadrature at NEAR_BOUNCE_NODES points, interpolated between) over
    the normals a camera 30 degrees above the ground sees."""
    rng = np.random.default_rng(1)
    n = normalize(rng.normal(size=(8000, 3)))
    view = np.array([0.0, -np.cos(np.radians(30)), np.sin(np.radians(30))])
    n = n[n @ view > 0.15][:2000]
    center, radius = np.array([0.2, 0.1, 0.05]), 0.05
    p = center + radius * n
    S = np.asarray(light, dtype=np.float64)
    fine = near_ground_bounce(p, n, center, radius, S, side=40, nodes=None)
    got = near_ground_bounce(p, n, center, radius, S)
    assert np.mean(np.abs(got - fine)) < 0.03 and np.percentile(np.abs(got - fine), 95) < 0.1


def test_near_form_factor_tends_to_the_distant_one_and_differs_for_a_near_light():
    rng = np.random.default_rng(3)
    n = normalize(rng.normal(size=(400, 3)))
    center, radius = np.array([0.0, 0.0, 0.05]), 0.05
    p = center + radius * n
    l = normalize(np.array([0.4, -0.5, 0.75]))
    far = near_ground_bounce(p, n, center, radius, center + 1e5 * l, side=24, nodes=None)
    distant = shadowed_ground_bounce(n, l)
    assert np.mean(np.abs(far - distant)) < 0.01
    # at 2 m (40 radii) the ground toward the light is brighter: the normals facing it get more
    near = near_ground_bounce(p, n, center, radius, center + 2.0 * l, side=24, nodes=None)
    toward = (n @ normalize(l * [1, 1, 0]) > 0.5) & (n[:, 2] < 0)
    away = (n @ normalize(l * [1, 1, 0]) < -0.5) & (n[:, 2] < 0)
    assert np.mean(near[toward] - distant[toward]) > 0.02
    assert np.mean(near[toward] - distant[toward]) > np.mean(near[away] - distant[away]) + 0.02
    # a light below the contact point lights no ground
    assert np.all(near_ground_bounce(p, n, center, radius, center - 0.2 * UP) == 0.0)


def test_a_low_lamp_bright_spot_is_resolved_by_the_default_quadrature():
    """A lamp 2 m away at 5 degrees lights the ground under it ~100 times more than at the sphere,
    in a spot seen at a few degrees: 16 directions per side alias it (the form factor of the lower
    half ~9% RMS off; matte balls read low lamps low); the default takes more directions for a low
    lamp and follows the area integral."""
    center, radius = np.array([0.25, -0.25, 0.05]), 0.05
    e = np.radians(5.0)
    S = center + 2.0 * np.array([np.cos(e) * np.cos(0.7), np.cos(e) * np.sin(0.7), np.sin(e)])
    rng = np.random.default_rng(5)
    n = normalize(rng.normal(size=(200, 3)))
    n = n[n[:, 2] < -0.1][:24]
    p = center + radius * n
    ref = np.array([near_bounce_by_area(pi, ni, center, radius, S) for pi, ni in zip(p, n)])
    got = near_ground_bounce(p, n, center, radius, S, nodes=None)
    coarse = near_ground_bounce(p, n, center, radius, S, side=16, nodes=None)
    rel = lambda g: float(np.sqrt(np.mean((g - ref) ** 2) / np.mean(ref ** 2)))  # noqa: E731
    assert rel(got) < 0.03, (rel(got), rel(coarse))
    assert rel(coarse) > 0.06


def test_near_form_factor_geometry_made_once_per_sphere(monkeypatch):
    """The quadrature's geometry (directions, ground points, their offsets from the centre) does not
    depend on the light: a sphere's near fits, one per photo, make it once, and the form factor is
    the same floats as with the geometry made afresh; another sphere gets its own."""
    import ffls.spheres.lambert as lam

    rng = np.random.default_rng(11)
    n = normalize(rng.normal(size=(900, 3)) * [1.0, 0.3, 1.0] - [0.0, 1.0, 0.0])  # (a camera's side)
    center, radius = np.array([0.0, 0.0, 0.05]), 0.05
    p = center + radius * n
    lights = [center + d * normalize(np.array(v)) for d, v in ((2.0, (0.4, -0.5, 0.75)), (1.2, (-0.3, 0.2, 0.9)),
                                                               (0.6, (0.1, -0.8, 0.5)))]
    monkeypatch.setattr(lam, "NEAR_GEOMETRIES", {})
    fresh = []
    for S in lights:  # (the geometry dropped before each: made afresh)
        lam.NEAR_GEOMETRIES.clear()
        fresh.append(near_ground_bounce(p, n, center, radius, S))
    made = []
    cosine = lam.cosine_directions
    monkeypatch.setattr(lam, "cosine_directions", lambda side: made.append(side) or cosine(side))
    lam.NEAR_GEOMETRIES.clear()
    kept = [near_ground_bounce(p, n, center, radius, S) for S in lights]
    assert len(made) == 1
    assert all(a.tobytes() == b.tobytes() for a, b in zip(fresh, kept))
    near_ground_bounce(p, n, center + [0.3, 0.0, 0.0], radius, lights[0])  # another sphere
    assert len(made) == 2
