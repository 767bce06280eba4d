"""Photometric refinement of a sphere's centre (ffls.spheres.refine) on an analytic render.

The render here is a few lines of NumPy (a Lambertian sphere through a pinhole camera, 3x3
supersampled, a small ambient), independent of ffls.synth.scene and of the code under test.
"""
from __future__ import annotations

import numpy as np

from ffls.conventions import angle_between, normalize
from ffls.spheres.lambert import fit_lambert
from ffls.spheres.samples import pixel_validity, sphere_samples
from ffls.spheres.refine import recentre_samples, refine_sphere_centre

RES, F, R = 120, 400.0, 0.05
K = np.array([[F, 0, (RES - 1) / 2], [0, F, (RES - 1) / 2], [0, 0, 1.0]])
C_TRUE = np.array([0.01, -0.005, 0.5])  # camera frame = world frame here


def render(light, ss=3):
    """0.8 max(0, n . l) + 0.02 on the sphere, 0 elsewhere; box-filtered over ss x ss subpixels."""
    off = (np.arange(ss) + 0.5) / ss - 0.5
    yy, xx = np.mgrid[0:RES, 0:RES].astype(float)
    acc = np.zeros((RES, RES))
    for dy in off:
        for dx in off:
            d = np.stack([(xx + dx - K[0, 2]) / F, (yy + dy - K[1, 2]) / F, np.ones_like(xx)], -1)
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            b = d @ C_TRUE
            disc = b * b - C_TRUE @ C_TRUE + R * R
            hit = disc > 0
            n = (d * (b - np.sqrt(np.where(hit, disc, 0)))[..., None] - C_TRUE) / R
            acc += np.where(hit, 0.8 * np.maximum(n @ light, 0) + 0.02, 0.0)
    return acc / ss ** 2


def test_refinement_recovers_perturbed_centre():
    rng = np.random.default_rng(3)
    # 24 lights on the camera's side of the sphere (the camera looks along +Z)
    th = np.radians(rng.uniform(10, 75, 24))
    ph = rng.uniform(0, 2 * np.pi, 24)
    lights = normalize(np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), -np.cos(th)], -1))
    # the detected centre: its direction off by 0.5 px (0.4 right, 0.3 down), same distance
    D = np.linalg.norm(C_TRUE)
    u = normalize(C_TRUE / D + np.array([0.4, 0.3, 0.0]) / F)
    C0 = D * u
    s = sphere_samples((RES, RES), K, None, C0, R)
    vals, dirs = [], []
    for l in lights:
        img = render(l) + rng.normal(0, 0.002, (RES, RES))
        grey = s.values(img)
        valid, nsat = pixel_validity(grey)
        vals.append((grey, valid, nsat))
        fit = fit_lambert(s.normals, grey, valid, models=("ambient",))
        dirs.append(fit.direction if fit.status == "ok" else None)

    def err_px(C):
        return F * float(angle_between(C[None], C_TRUE[None])[0])

    assert 0.45 < err_px(C0) < 0.55
    ref = refine_sphere_centre(s, vals, dirs)
    assert ref.accepted, ref.message
    assert ref.n_photos == 20  # the default max_photos (farthest-point sampling of the 24)
    # measured: 0.01 px; the perturbation was 0.5 px
    assert err_px(ref.center) < 0.08
    assert abs(np.linalg.norm(ref.center) - D) < 1e-9  # the distance (half-angle) is kept
    s2, idx = recentre_samples(s, ref.center)
    assert len(s2) == idx.size and 0.9 * len(s) < len(s2) <= len(s)
    assert np.allclose(np.linalg.norm(s2.normals, axis=1), 1.0)
    # the normals at the kept pixels are now those of the true sphere
    n_true = normalize(s2.points - C_TRUE)
    assert np.degrees(np.max(angle_between(s2.normals, n_true))) < 2.0


def test_refinement_needs_photos():
    s = sphere_samples((RES, RES), K, None, C_TRUE, R)
    img = render(normalize(np.array([0.3, -0.2, -1.0])))
    grey = s.values(img)
    ref = refine_sphere_centre(s, [(grey, np.ones(len(s), bool), 0)] * 2, [np.array([0.3, -0.2, -1.0])] * 2)
    assert not ref.accepted and np.array_equal(ref.center, ref.center_initial)


def test_degenerate_shading_system_keeps_the_detected_centre(monkeypatch):
    """A singular shading system (white background, pixels set aside) is a refinement not accepted, not a crash."""
    import ffls.spheres.refine as refine
    from ffls.spheres.samples import sphere_samples

    K = np.array([[500.0, 0, 64], [0, 500.0, 64], [0, 0, 1]])
    s = sphere_samples((128, 128), K, None, np.array([0.0, 0.0, 1.0]), 0.05)

    def singular(*args, **kwargs):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(refine, "refine_sphere_centre_shading", singular)
    ref = refine.refine_sphere_centre(s, [], [])
    assert not ref.accepted and "degenerate" in ref.message
    np.testing.assert_allclose(ref.center, ref.center_initial)
