"""The lens's fall-off across each sphere, fitted over a capture's photos and divided out
(:func:`ffls.spheres.estimate.calibrate_flat_field`, :func:`ffls.spheres.lambert.flat_field_terms`)."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import angle_between, spherical_to_direction
from ffls.io.capture import load_lights, save_lights
from ffls.spheres.estimate import (calibrate_flat_field, cos4_gradient, estimate_photos, flat_field_offsets,
                                   flat_field_values)
from ffls.spheres.samples import SphereValues, ground_bounce
from sphere_rig import SCENE_CENTER, camera, rig_samples

RES = 320
K = camera(RES, 300.0)
LENS = (K[0, 2], K[1, 2], K[0, 0])
LIGHTS = [(th, ph) for th in (15, 35, 55) for ph in (-150, -30, 30, 90, 150)]


@pytest.fixture(scope="module")
def samples():
    return rig_samples(RES, 300.0)


def cos4(s):
    """The natural vignetting of the pinhole ``K`` at the sphere's pixels."""
    x, y = (s.cols - K[0, 2]) / K[0, 0], (s.rows - K[1, 2]) / K[1, 1]
    return 1.0 / (1.0 + x * x + y * y) ** 2


def photo_values(samples, direction=None, position=None, vignetting=0, noise=0.003, seed=0):
    """Lambert + ambient + ground bounce at the spheres' pixels (a point light's inverse square
    where ``position`` is given), times the cos^4 fall-off to the power ``vignetting``, plus
    Gaussian noise."""
    rng = np.random.default_rng(seed)
    out = []
    for s in samples:
        if position is None:
            E, ez = np.maximum(s.normals @ direction, 0.0), max(direction[2], 0.0)
        else:
            v = position - s.points
            r = np.linalg.norm(v, axis=1)
            E = np.maximum(np.sum(s.normals * v, 1) / r, 0.0) * (np.linalg.norm(position - s.center) / r) ** 2
            ez = max((position - s.center)[2] / np.linalg.norm(position - s.center), 0.0)
        y = 0.8 * (E + 0.02 + 0.3 * ez * ground_bounce(s.normals))
        y = y * cos4(s) ** vignetting
        y = y + noise * rng.standard_normal(y.shape)
        out.append(SphereValues(y.astype(np.float32), np.ones(y.shape, bool), 0))
    return out


def true_gradient(s):
    V = cos4(s)
    A = np.column_stack([np.ones(len(s)), flat_field_offsets(s)])
    c = np.linalg.lstsq(A, V, rcond=None)[0]
    return c[1:] / c[0]


def errors(est, dirs):
    return np.array([np.degrees(angle_between(r.direction, d)) if r.status == "ok" else np.inf
                     for r, d in zip(est.photos, dirs)])


def test_a_lens_fall_off_is_found_and_divided_out(samples, tmp_path):
    dirs = [spherical_to_direction(np.radians(th), np.radians(ph)) for th, ph in LIGHTS]
    vals = [photo_values(samples, d, vignetting=1, seed=i) for i, d in enumerate(dirs)]
    before = estimate_photos(vals, samples, SCENE_CENTER, refine_centres=False, bounce="free", own_shadow=False)
    after = estimate_photos(vals, samples, SCENE_CENTER, refine_centres=False, bounce="free", own_shadow=False, flat_field=LENS)
    e0, e1 = errors(before, dirs), errors(after, dirs)
    # the gradients (6-10% per radius) tilt each sphere's light by degrees: the spheres disagree
    # (taken for a near light, or rejected), and the lights are off
    assert np.median(e0) > 2.0 * np.median(e1), (e0, e1)
    assert sum(r.model == "near" for r in after.photos) == 0
    assert np.all(np.isfinite(e1)) and np.median(e1) < 0.3 and e1.max() < 1.0, e1
    f = after.flat_field
    assert f.applied and f.p < 1e-3 and abs(f.strength - 1.0) < 0.1, f
    for s, g, m, sd in zip(samples, f.gradients, f.measured, f.measured_sigma):
        t = true_gradient(s)
        assert np.linalg.norm(g - t) < 0.1 * np.linalg.norm(t), (g, t)
        assert np.linalg.norm(cos4_gradient(s, LENS) - t) < 0.05 * np.linalg.norm(t)
        assert np.all(np.isfinite(m)) and np.all(sd > 0)
    rep = after.records()[0]["spheres"][0]["flat_field"]
    assert rep == [float(x) for x in f.gradients[0]]
    # the capture-wide record (top-level "flat_field" of lights.json) survives a round trip
    names = [f"p{i}.exr" for i in range(len(dirs))]
    path = tmp_path / "lights.json"
    save_lights(after.lights(names), path)
    rec = load_lights(path).flat_field
    assert rec["applied"] and rec["photos"] == [int(n) for n in f.n_photos]
    assert np.allclose(rec["measured"], f.measured) and np.allclose(rec["measured_sigma"], f.measured_sigma)
    assert np.allclose(rec["gradients"], f.gradients) and rec["strength"] == pytest.approx(f.strength)


@pytest.mark.parametrize("case", ["none", "near", "brightening outward"])
def test_what_is_no_lens_fall_off_leaves_the_values_alone(samples, case):
    """Without vignetting no fall-off is significant, under a distant light or a near one (whose
    inverse-square fall-off across each sphere changes with the light); a brightening away from
    the lens's centre, the same in every photo, is no lens's."""
    dirs = [spherical_to_direction(np.radians(th), np.radians(ph)) for th, ph in LIGHTS]
    pos = [SCENE_CENTER + 0.8 * d for d in dirs] if case == "near" else [None] * len(dirs)
    vig = -1 if case == "brightening outward" else 0
    vals = [photo_values(samples, d, position=p, vignetting=vig, seed=i) for i, (d, p) in enumerate(zip(dirs, pos))]
    est = estimate_photos(vals, samples, SCENE_CENTER, refine_centres=False, bounce="free", own_shadow=False, flat_field=LENS)
    f = est.flat_field
    assert not f.applied and f.strength == 0.0 and np.all(f.gradients == 0), f
    if case == "brightening outward":
        assert np.all(np.sum(f.measured * np.array([cos4_gradient(s, LENS) for s in samples]), 1) < 0)
    assert all(rec["spheres"][k]["flat_field"] is None for rec in est.records() for k in range(len(samples)))
    assert flat_field_values(vals, samples, f) is vals


def test_too_few_photos_give_no_fall_off(samples):
    d = spherical_to_direction(np.radians(30.0), np.radians(60.0))
    vals = [photo_values(samples, d, vignetting=1, seed=i) for i in range(3)]
    est = estimate_photos(vals, samples, SCENE_CENTER, refine_centres=False, bounce="free", own_shadow=False)
    assert est.flat_field is None
    f = calibrate_flat_field(est.photos, samples, vals, LENS)
    assert np.all(f.n_photos <= 3) and not f.applied and np.all(np.isnan(f.measured))
    assert not calibrate_flat_field([], samples, [], LENS).applied


def test_lens_centre_of_a_pinhole_and_of_an_orthographic_camera():
    from types import SimpleNamespace

    from ffls.spheres.estimate import lens_centre

    pin = SimpleNamespace(K=np.array([[400.0, 0, 100.0], [0, 100.0, 50.0], [0, 0, 1]]), camera_model="pinhole")
    assert lens_centre(pin, (120, 200)) == (100.0, 50.0, 200.0)
    ortho = SimpleNamespace(K=None, camera_model="orthographic")
    assert lens_centre(ortho, (300, 400)) == (199.5, 149.5, 250.0)


def test_the_disagreement_change_counts_the_photos_accepted_both_times():
    from types import SimpleNamespace

    from ffls.spheres.estimate import disagreement_change

    def photo(status, chi2):
        return SimpleNamespace(status=status, chi2=chi2)

    before = [photo("ok", 10.0), photo("ok", 8.0), photo("rejected", 50.0)]
    after = [photo("ok", 4.0), photo("rejected", 0.0), photo("ok", 1.0)]
    assert disagreement_change(before, after) == -6.0
    assert disagreement_change(after, before) == 6.0
