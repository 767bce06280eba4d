"""Compact sources relit by shadow level-set interpolation (ffls.relight.lightflow.LevelSetInterpolator)."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from ffls.cli import main
from ffls.conventions import rotation_z
from ffls.io.capture import load_capture_and_lights
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.relight.basis import accepted_basis
from ffls.relight.cpu import CpuRelighter
from ffls.relight.lightflow import (FlowInterpolator, LevelSetInterpolator, LightFlowRelighter, distance_flow,
                                    relight_lightflow, signed_distance, unshadowed_fit)
from test_composite_lightflow import ring_lights, shadow_photo

H = W = 96


def _photo(d, rng=None, noise=0.0):
    """A textured Lambertian ground (normal +Z) with a sharp cast shadow (a disc) that follows the light."""
    return shadow_photo(d, rng, noise, lambert=True)


def _centre(dirs):
    t = dirs[0] + dirs[1] + dirs[2]
    return t / np.linalg.norm(t)


def test_unshadowed_fit_recovers_a_lambertian_pixel_through_its_shadows():
    rng = np.random.default_rng(0)
    k = 12
    L = rng.normal(size=(k, 3))
    L[:, 2] = np.abs(L[:, 2]) + 2.0
    L /= np.linalg.norm(L, axis=1, keepdims=True)
    b_true = np.array([[0.1, 0.2, 0.9], [0.05, 0.1, 0.5], [0.0, 0.3, 0.7]])  # (channel, xyz)
    photos = (L @ b_true.T)[:, None, None, :].repeat(2, 1).repeat(3, 2)  # (k, 2, 3, 3)
    photos = photos.copy()
    photos[:4, 0, 0] *= 0.1  # pixel (0, 0): four lights shadowed
    photos[:, 1, 2] = 0.0  # pixel (1, 2): black under every light
    b = unshadowed_fit(photos.astype(np.float32), L)
    assert b.shape == (2, 3, 3, 3)
    assert np.allclose(b[0, 0], b_true, atol=1e-4)
    assert np.allclose(b[1, 1], b_true, atol=1e-4)
    assert (b[1, 2] == 0).all()
    # fewer than three photos: no model
    assert np.isnan(unshadowed_fit(photos[:2].astype(np.float32), L[:2])).all()


def test_signed_distance_is_negative_inside_and_half_way_at_the_edge():
    m = np.zeros((20, 30), dtype=bool)
    m[5:15, 10:20] = True
    d = signed_distance(m)
    assert (d[m] < 0).all() and (d[~m] > 0).all()
    assert d[10, 9] == pytest.approx(1.0) and d[10, 10] == pytest.approx(-1.0)
    assert d[10, 25] == pytest.approx(6.0) and d[10, 14] == pytest.approx(-5.0)
    assert (signed_distance(np.zeros((4, 5), bool)) == 10).all()
    assert (signed_distance(np.ones((4, 5), bool)) == -10).all()


def test_distance_flow_follows_a_thin_shadow_farther_than_its_width():
    a = np.zeros((96, 96), dtype=bool)
    b = np.zeros_like(a)
    a[30:70, 20:26] = True  # a 6-pixel-wide bar ...
    b[30:70, 34:40] = True  # ... moved 14 pixels right: the two do not overlap
    f = distance_flow(signed_distance(a), signed_distance(b))
    assert np.median(f[35:65, 20:26, 0]) == pytest.approx(14.0, abs=2.0)
    assert np.abs(f[35:65, 20:26, 1]).mean() < 2.0
    with pytest.raises(ValueError):
        distance_flow(signed_distance(a), signed_distance(b), "lucas-kanade")


@pytest.mark.parametrize("flow", [None, "dis"])
def test_interpolation_is_exact_at_a_light_and_moves_the_shadow(flow):
    dirs = ring_lights()
    basis = np.stack([_photo(d) for d in dirs])
    li = LevelSetInterpolator(basis, dirs, "upper", flow=flow)
    assert np.array_equal(li.image(dirs[3]), basis[3])
    t = _centre(dirs)
    idx, w = li.weights(t)
    assert sorted(idx) == [0, 1, 2] and w.sum() == pytest.approx(1.0)
    # each light's shadow is found where the disc is
    sh = li.shadow(1)
    y, x = np.mgrid[0:H, 0:W]
    disc = (x - (W / 2 - 60 * dirs[1, 0])) ** 2 + (y - (H / 2 - 60 * dirs[1, 1])) ** 2 < 12 ** 2
    assert (sh.shadow == disc).mean() > 0.99
    assert np.allclose(sh.visibility[disc], 0.15, atol=0.01) and np.allclose(sh.visibility[~disc], 1.0, atol=0.01)
    truth = _photo(t)
    blend = sum(wi * basis[i] for i, wi in zip(idx, w))
    img = li.image(t)
    e_level = np.abs(img - truth).sum() / truth.sum()
    e_blend = np.abs(blend - truth).sum() / truth.sum()
    # the discs of neighbouring lights are disjoint (25 px apart, 24 px wide): the plain average of
    # their distances keeps only part of the shadow; the distances' flow moves it whole
    assert e_level < (0.6 if flow else 0.9) * e_blend, (e_level, e_blend)
    # no shadow where none of the three lights has one: unchanged from the blend there
    none = ~np.any([li.shadow(i).shadow for i in idx], axis=0)
    assert np.allclose(img[none], blend[none], rtol=1e-5, atol=1e-6)


def test_interpolation_on_noisy_jpeg_photos_stays_honest():
    rng = np.random.default_rng(3)
    dirs = ring_lights()
    clean = np.stack([_photo(d) for d in dirs])
    noisy = []
    for d in dirs:
        img = _photo(d, rng, 0.05)
        ok, buf = cv2.imencode(".jpg", np.clip(img * 255, 0, 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 80])
        noisy.append(cv2.imdecode(buf, cv2.IMREAD_COLOR).astype(np.float32) / 255)
    noisy = np.stack(noisy)
    t = _centre(dirs)
    li = LevelSetInterpolator(noisy, dirs, "upper")
    idx, w = li.weights(t)
    truth = _photo(t)
    blend = sum(wi * clean[i] for i, wi in zip(idx, w))
    e_level = np.abs(li.image(t) - truth).sum() / truth.sum()
    e_blend = np.abs(blend - truth).sum() / truth.sum()
    assert e_level < e_blend, (e_level, e_blend)


def test_bad_options_are_refused():
    dirs = ring_lights()
    basis = np.zeros((len(dirs), 8, 8, 3), np.float32)
    for kw in ({"shadow_level": 0.0}, {"shadow_level": 1.0}, {"neighbours": 2}, {"flow": "sift"}):
        with pytest.raises(ValueError):
            LevelSetInterpolator(basis, dirs, **kw)


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("ls") / "cap"
    assert main(["synth", str(root), "--lights", "40", "--resolution", "40", "--quiet"]) == 0
    return load_capture_and_lights(root)


def test_relighter_with_level_sets_matches_the_function(capture):
    cap, lights = capture
    basis, dirs = accepted_basis(cap, lights)
    lm = builtin_lightmap("sky", 64)
    R = rotation_z(30.0)
    li = LevelSetInterpolator(basis, dirs, cap.hemisphere)
    img, split = relight_lightflow(basis, dirs, lm, R, cap.hemisphere, scheme="barycentric", interpolator=li)
    assert len(split.sources) == 1
    rel = LightFlowRelighter(CpuRelighter(basis, dirs, cap.hemisphere, weighting="barycentric"),
                             interpolation="levelset")
    assert isinstance(rel.interpolator, LevelSetInterpolator)
    rel.set_lightmap(lm)
    rel.set_rotation(R)
    rel.render()
    assert np.allclose(rel.read_hdr(), img, rtol=1e-4, atol=1e-5)
    rel.release()
    with pytest.raises(ValueError):
        LightFlowRelighter(CpuRelighter(basis, dirs, cap.hemisphere), interpolation="warp")


def test_composite_command_with_level_sets(tmp_path, capfd):
    root = tmp_path / "set"
    assert main(["synth", str(root), "--composite-set", "sky", "--lights", "40", "--surface-lights", "40",
                 "--resolution", "40", "--truth-dirs", "256", "--quiet"]) == 0
    out = tmp_path / "ls.exr"
    rc = main(["composite", "--object", str(root / "object"), "--surface", str(root / "surface"), "--lightmap",
               str(root / "scene_map.exr"), "--background", str(root / "background.exr"), "--mask",
               str(root / "object_mask.png"), "--surface-mask", str(root / "surface_mask.png"),
               "--sources", "levelset", "-o", str(out)])
    text = capfd.readouterr().out
    assert rc == 0
    rep = json.loads(out.with_suffix(".json").read_text())
    assert rep["sources"] == "levelset" and len(rep["compact_sources"]) == 1
    assert "relit by shadow level sets (dis flow)" in text
    assert out.with_suffix(".png").exists()


@pytest.mark.parametrize("size", [1, 4, 11])
def test_tiny_images_are_interpolated_too(size):
    # DIS needs 12 pixels on a side: the flows pad the images so that a thumbnail still works
    rng = np.random.default_rng(size)
    dirs = ring_lights()
    basis = rng.random((len(dirs), size, size + 1, 3)).astype(np.float32)
    t = _centre(dirs)
    for interp in (LevelSetInterpolator(basis, dirs), FlowInterpolator(basis, dirs)):
        img = interp.image(t)
        assert img.shape == basis.shape[1:] and np.isfinite(img).all() and (img >= 0).all()
