"""The calibration spheres' shadows (ffls.relight.sphere_shadows): found from geometry, filled from the photos that see a pixel."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.relight.sphere_shadows import SphereShadowFill, ground_points, hidden_photos
from ffls.synth.scene import stratified_directions


def _camera(res=48):
    """A camera 1 m above the origin looking straight down (OpenCV axes), 60 degree field of view."""
    f = 0.5 * res / math.tan(math.radians(30))
    K = np.array([[f, 0, 0.5 * (res - 1)], [0, f, 0.5 * (res - 1)], [0, 0, 1.0]])
    M = np.eye(4)
    M[:3, :3] = np.diag([1.0, -1.0, -1.0])
    M[:3, 3] = (0, 0, 1.0)
    return K, M


def test_ground_points_on_the_plane_and_under_the_camera():
    K, M = _camera()
    g = ground_points(K, M, (48, 48))
    assert np.allclose(g[..., 2], 0.0)
    assert np.allclose(g[23:25, 23:25, :2], 0.0, atol=0.02)
    # a camera looking up sees no ground
    M2 = M.copy()
    M2[:3, :3] = np.eye(3)
    assert np.all(np.isnan(ground_points(K, M2, (48, 48))))


def test_hidden_photos_shadow_of_a_sphere():
    K, M = _camera()
    g = ground_points(K, M, (48, 48))
    centre, r = (0.0, 0.0, 0.1), 0.1
    up = np.array([[0.0, 0.0, 1.0]])
    low = np.array([[math.cos(math.radians(30)), 0.0, math.sin(math.radians(30))]])
    h = hidden_photos(g, [centre], r, directions=np.vstack([up, low]), dilate_px=0)
    # the zenith light: the shadow is the disc of radius r under the sphere
    inside = np.hypot(g[..., 0], g[..., 1]) < r
    assert np.array_equal(h[0], inside)
    # the low light from +x: the shadow lies on the -x side, elongated
    assert h[1].any() and np.all(g[h[1]][:, 0] < 0.05)
    # a near light below the sphere's top hides nothing beyond it... and a dilation grows the masks
    near = hidden_photos(g, [centre], r, positions=[[0.0, 0.0, 0.15]], dilate_px=0)
    assert near[0].sum() > inside.sum()
    assert hidden_photos(g, [centre], r, directions=up, dilate_px=1)[0].sum() > inside.sum()
    with pytest.raises(InputError):
        hidden_photos(g, [centre], 0.0, directions=up)
    with pytest.raises(InputError):
        hidden_photos(g, [centre], r)


def test_fill_reproduces_an_unshadowed_lambertian_ground():
    """Photos of a white Lambertian ground (n . d) with some photos hidden per pixel: the filled
    weighted sum equals the unshadowed one (the fill's weights reproduce a photo linear in d)."""
    n, H, W = 120, 6, 8
    d = stratified_directions(n, "upper", 0)
    cos = d[:, 2]
    basis = np.broadcast_to(cos[:, None, None, None], (n, H, W, 3)).astype(np.float64).copy()
    hidden = np.zeros((n, H, W), dtype=bool)
    zen = np.degrees(np.arccos(np.clip(d[:, 2], -1, 1)))
    hidden[:, :3, :] = (zen < 25)[:, None, None]           # a sphere overhead: a cone around the zenith
    tilt = np.array([0.5, 0.3, 0.81])
    tilt /= np.linalg.norm(tilt)
    hidden[:, 3:, :4] = (np.degrees(np.arccos(np.clip(d @ tilt, -1, 1))) < 15)[:, None, None]
    basis[hidden] = 0.1 * basis[hidden]                   # the spheres' shadows in the photos
    w = np.random.default_rng(0).uniform(0.5, 1.5, (n, 3)) / n
    image = np.einsum("kc,khwc->hwc", w, basis)
    f = SphereShadowFill(hidden, d)
    assert f.hidden_pixels == 6 * 8 - 3 * 4 and len(f.groups) == 2
    filled = f.relight(image, w, basis)
    truth = np.broadcast_to((w * cos[:, None]).sum(0), (H, W, 3))
    assert np.abs(image - truth).max() > 0.05 * truth.max()
    np.testing.assert_allclose(filled, truth, rtol=1e-9)
    # no photo hidden: the image is unchanged
    f0 = SphereShadowFill(np.zeros_like(hidden), d)
    assert f0.groups == [] and np.array_equal(f0.relight(image, w, basis), image)
    # every weight change over a group moves weight off the hidden photos only
    for pix, photos, delta in f.weights_correction(w):
        h = hidden.reshape(n, -1)[:, pix[0]]
        assert np.all(delta[h[photos]] < 0) and np.all(delta[~h[photos]] > 0)
    with pytest.raises(InputError):
        SphereShadowFill(hidden[:-1], d)


def test_source_fill_only_where_the_source_is_hidden():
    K, M = _camera(32)
    g = ground_points(K, M, (32, 32))
    d = stratified_directions(80, "upper", 1)
    f = SphereShadowFill.from_geometry(g, [(0.0, 0.0, 0.1)], 0.1, d, dilate_px=0)
    basis = np.broadcast_to(d[:, 2][:, None, None, None], (80, 32, 32, 3)).astype(np.float64).copy()
    basis[hidden_photos(g, [(0.0, 0.0, 0.1)], 0.1, directions=d, dilate_px=0)] = 0.0
    sun = np.array([0.0, 0.0, 1.0])
    img = np.zeros((32, 32, 3))                  # as a photo interpolated at the sun: dark in its shadow
    here = f.hidden_for(sun)
    assert here.any() and not here.all()
    out = f.source_image(img, sun, [0, 1, 2], basis)
    assert np.all(out[~here] == 0)
    np.testing.assert_allclose(out[here], 1.0, rtol=1e-9)
    # the same through an interpolator (as FlowInterpolator.image_from): called with the visible
    # triangle and weights summing to 1, its image scaled as the plain blend's weights
    calls = []

    def blend(idx, w):
        calls.append((np.asarray(idx), np.asarray(w)))
        return np.einsum("k,khwc->hwc", w, basis[idx])

    out2 = f.source_image(img, sun, [0, 1, 2], basis, interpolate=blend)
    np.testing.assert_allclose(out2, out, rtol=1e-9)
    assert calls and all(abs(w.sum() - 1) < 1e-12 for _, w in calls)
    hid = hidden_photos(g, [(0.0, 0.0, 0.1)], 0.1, directions=d, dilate_px=0).reshape(80, -1)
    for idx, _ in calls:  # the photos it blends see the pixels it fills
        assert not np.any(hid[np.ix_(idx, np.flatnonzero(here.ravel()))].all(axis=1))


def test_triangulations_are_built_only_for_the_fills_that_use_them(monkeypatch):
    """The model fill (source_model) uses no group's triangulation: building one per group of hidden
    photos took a minute and 0.7 GB for 200 lights at 128 px (docs/composite.md); the rest's fill
    builds each group's once."""
    import ffls.relight.sphere_shadows as ss

    built = []

    class Counting(ss.Barycentric):
        def __init__(self, *a, **k):
            built.append(1)
            super().__init__(*a, **k)

    monkeypatch.setattr(ss, "Barycentric", Counting)
    R = 32
    K = np.array([[40.0, 0, 15.5], [0, 40.0, 15.5], [0, 0, 1]])
    M = np.eye(4)
    M[:3, :3] = [[1, 0, 0], [0, -1, 0], [0, 0, -1]]      # looking straight down from 1 m
    M[:3, 3] = [0, 0, 1.0]
    pts = ground_points(K, M, (R, R))
    d = stratified_directions(80, "upper", 1)
    f = SphereShadowFill.from_geometry(pts, [(0.1, 0.0, 0.05)], 0.05, d)
    assert len(f.groups) > 3 and built == []
    basis = np.broadcast_to(d[:, 2][:, None, None, None], (80, R, R, 3)).copy()
    sun = np.array([-0.9, 0.0, 0.3]) / np.linalg.norm([-0.9, 0.0, 0.3])
    f.source_model(np.zeros((R, R, 3)), sun, basis)
    assert built == []
    f.relight(np.zeros((R, R, 3)), np.full((80, 3), 1 / 80), basis)
    assert len(built) == sum(v.size >= 3 for _, _, v in f.groups)
    f.relight(np.zeros((R, R, 3)), np.full((80, 3), 1 / 80), basis)
    assert len(built) == sum(v.size >= 3 for _, _, v in f.groups)  # built once
