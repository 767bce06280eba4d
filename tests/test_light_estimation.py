"""Light estimation from the spheres (issue 3): per-sphere Lambert fits, combination, rejection.

Analytic renders here (Lambertian spheres + ambient + a ground bounce of an infinite plane, less
the view factor of each sphere's own shadow on it, as the spheres rest on the ground; 2x2
supersampled) keep the tests fast and independent of ffls.synth.scene; one test uses ffls.synth.scene.
"""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA, angle_between, normalize, spherical_to_direction
from ffls.errors import InputError
from ffls.spheres.combine import combine_distant, fit_near_light, fit_ray_convergence
from ffls.spheres.estimate import BounceCalibration, calibrate_bounce, centres_to_refine, estimate_photos
from ffls.spheres.lambert import fit_lambert, own_shadow_factor
from ffls.spheres.photo import REASONS, estimate_photo, near_fit_mask
from ffls.spheres.samples import ground_bounce, pixel_validity, sphere_samples, sphere_values

RES = 200
R_SPH = 0.05
CENTERS = np.array([[-0.25, 0.55, 0.05], [0.25, 0.55, 0.05], [0.25, 1.05, 0.05], [-0.25, 1.05, 0.05]])  # world
WFC = np.eye(4)
WFC[:3, :3] = DEFAULT_WORLD_FROM_CAMERA[:3, :3]
WFC[:3, 3] = [0.0, -0.2, 0.45]  # camera raised, looking along +Y
# tilt the camera down by 25 deg
_c, _s = np.cos(np.radians(25)), np.sin(np.radians(25))
WFC[:3, :3] = np.array([[1, 0, 0], [0, _c, _s], [0, -_s, _c]]) @ WFC[:3, :3]
SCENE_CENTER = np.array([0.0, 0.8, 0.0])


def _K(f=250.0):
    return np.array([[f, 0, (RES - 1) / 2], [0, f, (RES - 1) / 2], [0, 0, 1.0]])


def _cam(c_world, wfc=WFC):
    M = np.linalg.inv(wfc)
    return M[:3, :3] @ c_world + M[:3, 3]


def render(direction=None, position=None, ambient=0.02, bounce=0.3, K=None, wfc=WFC, centers=CENTERS, ss=2,
           intensity=1.0, own_shadow=True):
    """Spheres only: E max(0, n.l) (1/r^2 for a point light) * 0.8 + ambient + bounce * E_z * g(n).

    ``g`` is the ground's form factor less, with ``own_shadow``, the view factor of the sphere's
    own shadow (the light's direction from the sphere's centre)."""
    K = _K() if K is None else K
    img = np.zeros((RES, RES, 3), np.float32)
    off = (np.arange(ss) + 0.5) / ss - 0.5
    for c in centers:
        C = _cam(c, wfc)
        acc = np.zeros((RES, RES))
        for dy in off:
            for dx in off:
                yy, xx = np.mgrid[0:RES, 0:RES].astype(float)
                xy = np.stack([(xx + dx - K[0, 2]) / K[0, 0], (yy + dy - K[1, 2]) / K[1, 1], np.ones_like(xx)], -1)
                d = xy / np.linalg.norm(xy, axis=-1, keepdims=True)
                b = d @ C
                disc = b * b - C @ C + R_SPH ** 2
                hit = disc > 0
                t = b - np.sqrt(np.where(hit, disc, 0))
                P = d * t[..., None]
                n = ((P - C) / R_SPH) @ wfc[:3, :3].T
                Pw = P @ wfc[:3, :3].T + wfc[:3, 3]
                if position is not None:
                    v = position - Pw
                    r = np.linalg.norm(v, axis=-1)
                    E = intensity * np.maximum(np.sum(n * v, -1) / r, 0) * (np.linalg.norm(position)) ** 2 / r ** 2
                    ez = max(normalize(position)[2], 0)
                else:
                    E = intensity * np.maximum(n @ direction, 0)
                    ez = max(direction[2], 0)
                g = ground_bounce(n.reshape(-1, 3))
                if own_shadow:
                    g = g - own_shadow_factor(n.reshape(-1, 3), direction if position is None else position - c)
                val = 0.8 * (E + ambient + bounce * ez * g.reshape(n.shape[:2]))
                acc += np.where(hit, val, 0)
        img += (acc / ss ** 2)[..., None]
    return img


def samples_for(K=None, wfc=WFC, centers=CENTERS):
    K = _K() if K is None else K
    return [sphere_samples((RES, RES), K, None, _cam(c, wfc), R_SPH, wfc) for c in centers]


def light(theta, phi):
    return spherical_to_direction(np.radians(theta), np.radians(phi))


@pytest.fixture(scope="module")
def samples():
    return samples_for()


# ----------------------------------------------------------------------------- geometry
def test_sphere_samples_normals_are_unit_and_face_camera(samples):
    for s, c in zip(samples, CENTERS):
        assert len(s) > 100
        np.testing.assert_allclose(np.linalg.norm(s.normals, axis=1), 1, atol=1e-9)
        np.testing.assert_allclose(s.center, c, atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(s.points - c, axis=1), R_SPH, atol=1e-9)
        cam = WFC[:3, 3]
        assert np.all(np.sum(s.normals * (cam - s.points), axis=1) > 0)


def test_ground_bounce_range():
    n = normalize(np.random.default_rng(0).normal(size=(100, 3)))
    g = ground_bounce(n)
    assert np.all((g >= 0) & (g <= 1))
    assert ground_bounce(np.array([[0, 0, -1.0]]))[0] == 1 and ground_bounce(np.array([[0, 0, 1.0]]))[0] == 0


# ----------------------------------------------------------------------------- per sphere
FRONTAL = pytest.mark.xfail(strict=True, reason=(
    "known limitation of a single photo with a FREE bounce: with the light on the camera side no "
    "shadow-side pixels are in view, the ground bounce is then collinear with ambient + a lower "
    "light, and the direction tilts by ~4 deg; the capture-wide calibration (bounce_ratio, "
    "test_fit_lambert_calibrated_bounce_frontal, test_distant_accuracy_frontal_lights) removes it"))


@pytest.mark.parametrize("theta,phi", [(0, 0), pytest.param(30, -90, marks=FRONTAL), (60, 40), (70, 180)])
def test_fit_lambert_with_bounce(samples, theta, phi):
    l = light(theta, phi)
    img = render(direction=l)
    s = samples[0]
    fit = fit_lambert(s.normals, s.values(img))
    assert fit.status == "ok"
    err = np.degrees(angle_between(fit.direction, l))
    assert err < 0.6, (err, fit.model)
    assert fit.uncertainty_deg < 1.0


def test_fit_lambert_calibrated_bounce_frontal(samples):
    """With the sphere's ground ratio imposed (0.3 in :func:`render`) the frontal light is exact."""
    l = light(30, -90)
    s = samples[0]
    y = s.values(render(direction=l))
    fit = fit_lambert(s.normals, y, bounce_ratio=0.3)
    assert fit.status == "ok" and fit.model in ("fixed", "fixed_ambient")
    assert np.degrees(angle_between(fit.direction, l)) < 0.2
    np.testing.assert_allclose(fit.bounce, 0.3 * fit.intensity * l[2], rtol=1e-3)
    # a wrong ratio (black ground assumed) tilts it: the ratio matters
    wrong = fit_lambert(s.normals, y, bounce_ratio=0.0)
    assert np.degrees(angle_between(wrong.direction, l)) > 1.0
    with pytest.raises(ValueError):
        fit_lambert(s.normals, y, bounce_ratio=-0.1)


def test_free_fit_reports_ground_ratio(samples):
    """A light from behind shows the shadow side: c / (a l_z) is the ground ratio, well determined."""
    l = light(40, 80)
    s = samples[0]
    fit = fit_lambert(s.normals, s.values(render(direction=l, bounce=0.25)))
    assert abs(fit.ground_ratio - 0.25) < 0.01 and fit.ground_ratio_sigma < 0.05


def test_bounce_term_removes_bias(samples):
    """Fitting only ambient (no bounce) tilts the light downward; the bounce model does not."""
    l = light(40, 30)
    img = render(direction=l, bounce=0.5)
    s = samples[0]
    full = fit_lambert(s.normals, s.values(img))
    plain = fit_lambert(s.normals, s.values(img), models=("ambient",))
    e_full = np.degrees(angle_between(full.direction, l))
    e_amb = np.degrees(angle_between(plain.direction, l))
    assert full.model == "bounce"
    assert e_full < 0.5 < e_amb


def test_black_ground_picks_simple_model(samples):
    l = light(20, 0)
    img = render(direction=l, ambient=0.0, bounce=0.0)
    s = samples[1]
    fit = fit_lambert(s.normals, s.values(img), valid=s.values(img) > 1e-4)
    assert fit.model in ("plain", "ambient")
    assert np.degrees(angle_between(fit.direction, l)) < 0.3


def test_pixel_validity_saturation_plateau():
    px = np.linspace(0, 2, 100)[:, None].repeat(3, 1)
    px[-10:] = 1.5
    px[-5:] = np.nan
    valid, nsat = pixel_validity(np.minimum(px, 1.5))
    assert nsat >= 5 and not valid[-10:].any()
    assert valid[1:20].all()  # dark but not clipped: data


def _validity_by_definition(p, min_plateau=4, saturation=None):
    """pixel_validity's rules written out on the (m, c) array: finite; not on a plateau of at least
    ``min_plateau`` pixels at a channel's maximum (or at or above 0.999 of ``saturation``); not on
    such a plateau at a channel's minimum where that is at most 0."""
    finite = np.all(np.isfinite(p), axis=1)
    sat = np.zeros(len(p), bool)
    floor = np.zeros(len(p), bool)
    for ch in range(p.shape[1]):
        c = p[:, ch]
        top = np.max(c[finite]) if finite.any() else -np.inf
        at_top = finite & (c >= top * (1 - 1e-6))
        if top > 0 and at_top.sum() >= min_plateau:
            sat |= at_top
        if saturation is not None:
            sat |= finite & (c >= 0.999 * saturation)
        low = np.min(c[finite]) if finite.any() else np.inf
        at_low = finite & (c <= low)
        if low <= 0 and at_low.sum() >= min_plateau:
            floor |= at_low
    return finite & ~sat & ~floor, int((sat & finite).sum())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pixel_validity_and_sphere_values_follow_the_definition(samples, seed):
    """Validity, saturated count and grey values are those of the rules applied pixel by pixel,
    with NaN, Inf, clipped tops and floors; sphere_values reads the same pixels of a contiguous
    photo and of a strided view of it."""
    rng = np.random.default_rng(seed)
    px = rng.normal(0.3, 0.2, (400, 3))
    px[rng.integers(0, 400, 12), rng.integers(0, 3, 12)] = np.nan
    px[rng.integers(0, 400, 3), 1] = np.inf
    px[:, 0] = np.minimum(px[:, 0], 0.6)  # a clipped top in one channel
    px[:, 2] = np.maximum(px[:, 2], 0.0)  # a clipped floor in another
    for kw in ({}, {"saturation": 0.7}, {"min_plateau": 50}):
        valid, nsat = pixel_validity(px, **kw)
        want, want_sat = _validity_by_definition(px, **kw)
        np.testing.assert_array_equal(valid, want)
        assert nsat == want_sat
    img = render(direction=light(20, 30)).astype(np.float32)
    img[5, 5] = np.nan
    wide = np.zeros((img.shape[0], img.shape[1], 6), np.float32)
    wide[..., ::2] = img
    for got in (sphere_values(img, samples), sphere_values(wide[..., ::2], samples)):
        for s, (grey, valid, nsat) in zip(samples, got):
            p = img[s.rows, s.cols].astype(np.float64)
            np.testing.assert_array_equal(grey, p.mean(axis=1))
            want, want_sat = _validity_by_definition(p)
            np.testing.assert_array_equal(valid, want)
            assert nsat == want_sat


def test_pixel_validity_keeps_noisy_dark_pixels_and_drops_the_clipped_floor():
    rng = np.random.default_rng(0)
    dark = rng.normal(0.002, 0.01, 500)  # a dark region under sensor noise: negative values too
    valid, _ = pixel_validity(np.concatenate([dark, np.linspace(0.1, 1.0, 500)]))
    assert valid.all()  # no censoring by value: it would keep the bright half of the noise
    clipped = np.concatenate([np.maximum(dark, 0.0), np.linspace(0.1, 1.0, 500)])  # clipped at 0
    valid, _ = pixel_validity(clipped)
    assert not valid[clipped == 0].any() and valid[clipped > 0].all()


def test_fit_lambert_unbiased_under_noise_on_the_shadow_side():
    rng = np.random.default_rng(1)
    n = normalize(rng.normal(size=(20000, 3)))
    n = n[n[:, 1] < -0.1]  # the half facing a camera at -Y
    l = normalize(np.array([0.5, -0.3, 0.4]))
    clean = 0.5 * np.maximum(n @ l, 0.0) + 0.002
    errs = []
    for _ in range(4):
        y = clean + rng.normal(0, 0.01, clean.size)
        valid, nsat = pixel_validity(y)
        f = fit_lambert(n, y, valid, n_saturated=nsat, models=("ambient",))
        errs.append(np.degrees(angle_between(f.direction, l)))
    assert np.mean(errs) < 0.3


# ----------------------------------------------------------------------------- combination
def test_combine_distant_weights():
    d = normalize(np.array([[0, 0, 1.0], [0.01, 0, 1.0]]))
    m, u, chi, dof = combine_distant(d, np.array([0.1, 10.0]))
    assert np.degrees(angle_between(m, d[0])) < 0.01 and dof == 2 and u < 0.11


def test_ray_convergence_parallel_rays_stable():
    d = np.tile(light(30, 10), (4, 1))
    conv = fit_ray_convergence(CENTERS, d, np.full(4, 0.5), SCENE_CENTER)
    assert conv.rho < 1e-3 and np.all(np.isfinite(conv.direction))
    assert np.degrees(angle_between(conv.direction, d[0])) < 1e-3


def test_ray_convergence_finds_point():
    S = SCENE_CENTER + 1.5 * light(40, 60)
    d = normalize(S - CENTERS)
    conv = fit_ray_convergence(CENTERS, d, np.full(4, 0.5), SCENE_CENTER)
    np.testing.assert_allclose(conv.position, S, atol=1e-4)


def test_ray_convergence_counts_an_opposite_direction_as_180_degrees():
    """A sphere whose direction is opposite to the others' (a mirror ball's highlight taken on the
    wrong side) cannot be made consistent by placing the light on its side: its residual is its
    angle (the projection of p - d alone, sin(angle), vanishes at 180 degrees)."""
    d = np.tile(light(30, 10), (3, 1))
    d = np.vstack([d, -light(30, 10)])
    conv = fit_ray_convergence(CENTERS, d, np.array([0.5, 0.5, 0.5, 10.0]), SCENE_CENTER)
    assert conv.chi2 > 100  # (180 / (10 / sqrt 2))^2 / ... : far beyond any chi-square threshold


# ----------------------------------------------------------------------------- photos
GRID = [(0, 0), (40, 30), (30, 90), (10, 180), (60, 60), (45, 0), (50, 20), (20, -10)]
GRID_FRONTAL = [(20, -90), (60, -150), (70, -60)]


@pytest.fixture(scope="module")
def grid_values(samples):
    dirs = [light(th, ph) for th, ph in GRID + GRID_FRONTAL]
    return dirs, [sphere_values(render(direction=d), samples) for d in dirs]


def test_distant_accuracy_frontal_lights(samples, grid_values):
    """Two passes: the ground ratio from the photos that show the shadow side, imposed in all."""
    dirs, vals = grid_values
    est = estimate_photos(vals, samples, SCENE_CENTER)
    res, cal = est.photos, est.calibration
    for c in cal:
        assert c.n_photos >= 3 and abs(c.ratio - 0.3) < 0.01, cal
    errs = np.array([np.degrees(angle_between(r.direction, d)) if r.status == "ok" else 90.0
                     for r, d in zip(res, dirs)])
    # every camera-side light accepted; of the others at most one (thin lit crescents, see below)
    nf = len(GRID_FRONTAL)
    assert errs[-nf:].max() < 0.3 and np.sum(errs[:-nf] > 0.3) <= 1, errs
    assert all(sp.fit.bounce_ratio is not None for r in res for sp in r.spheres if sp.status == "ok")


def test_centre_refined_only_where_the_outline_is_not_at_the_linear_step(samples, grid_values):
    """A sphere whose outline was refitted at the step of the linear max image keeps its centre
    (the shading's centre is pulled by light the Lambert model leaves out); the others are refined
    as before. ``centres_to_refine`` reads it from the fits (``SphereFit.outline_at_step``)."""
    which = centres_to_refine([SimpleNamespace(outline_at_step=k == 0) for k in range(len(samples))])
    assert which == [False] + [True] * (len(samples) - 1)
    _, vals = grid_values
    est = estimate_photos(vals, samples, SCENE_CENTER, refine_centres=which)
    kept = est.refinements[0]
    assert not kept.accepted and kept.message == "outline at the linear step"
    assert np.array_equal(est.samples[0].center, samples[0].center)
    assert np.array_equal(est.samples[0].normals, samples[0].normals)
    assert all(r.message != "outline at the linear step" for r in est.refinements[1:])
    assert any(r.accepted for r in est.refinements[1:])


def test_calibration_falls_back_with_few_photos(samples, grid_values):
    """Two photos cannot calibrate (min_photos = 3): the bounce stays free."""
    dirs, vals = grid_values
    est = estimate_photos(vals[-2:], samples, SCENE_CENTER)
    res, cal = est.photos, est.calibration
    assert all(c.ratio is None for c in cal), cal
    assert all(sp.fit.bounce_ratio is None for r in res for sp in r.spheres)
    assert any(sp.status == "ok" for r in res for sp in r.spheres)
    assert calibrate_bounce([], 4) == [BounceCalibration(ratio=None, spread=None, n_photos=0)] * 4


def test_black_ground_calibrates_to_zero(samples):
    dirs = [light(th, ph) for th, ph in GRID]
    vals = [sphere_values(render(direction=d, bounce=0.0), samples) for d in dirs]
    est = estimate_photos(vals, samples, SCENE_CENTER)
    res, cal = est.photos, est.calibration
    assert all(c.ratio is not None and c.ratio < 0.01 for c in cal), cal
    errs = [np.degrees(angle_between(r.direction, d)) for r, d in zip(res, dirs) if r.status == "ok"]
    assert len(errs) >= 7 and max(errs) < 0.3, errs


def test_sphere_values_raw_validity(samples):
    """8-bit codes at the top (any channel) are saturated, all-channel codes near 0 are black."""
    img = render(direction=light(20, 30))
    raw = np.clip(np.rint(img / img.max() * 255 * 1.2), 0, 255).astype(np.uint8)
    lin = raw.astype(np.float32) / 255
    (g0, v0, n0), = sphere_values(lin, samples[:1])
    (g1, v1, n1), = sphere_values(lin, samples[:1], raw=raw, bit_depth=8)
    s = samples[0]
    top = np.any(raw[s.rows, s.cols] >= 0.98 * 255, axis=1)
    assert top.any() and not v1[top].any() and n1 >= top.sum()
    assert v1.sum() < v0.sum()


def test_distant_accuracy_reduced_grid(samples):
    """At most one of 8 photos rejected (small back spheres with a thin lit crescent can be); the
    accepted ones within 0.6 deg, median 0.3 deg."""
    errs = []
    for th, ph in GRID:
        l = light(th, ph)
        r = estimate_photo(render(direction=l), samples, SCENE_CENTER)
        if r.status == "ok":
            assert r.model == "distant"
            errs.append(np.degrees(angle_between(r.direction, l)))
    assert len(errs) >= 7
    assert max(errs) < 0.6 and np.median(errs) < 0.3, errs


@pytest.mark.parametrize("th,ph", [(20, -60), (50, 120), (30, 20)])
def test_near_light_joint_fit(samples, th, ph):
    S = SCENE_CENTER + 2.0 * light(th, ph)
    r = estimate_photo(render(position=S), samples, SCENE_CENTER)
    assert r.status == "ok" and r.model == "near"
    err = np.degrees(angle_between(r.direction, S - SCENE_CENTER))
    assert err < 1.0
    # the per-sphere distant fits alone are worse than the joint near fit
    assert np.linalg.norm(r.position - S) < 0.1


def test_forced_distant_model(samples):
    S = SCENE_CENTER + 30.0 * light(30, 0)
    r = estimate_photo(render(position=S), samples, SCENE_CENTER, model="distant")
    assert r.status == "ok" and r.model == "distant"
    assert np.degrees(angle_between(r.direction, S - SCENE_CENTER)) < 0.6


def test_single_sphere(samples):
    l = light(35, 70)
    r = estimate_photo(render(direction=l), samples[:1], SCENE_CENTER)
    assert r.status == "ok" and r.used_spheres == [0]
    assert np.degrees(angle_between(r.direction, l)) < 0.6


def test_near_orthographic_camera():
    f = 20000.0
    wfc = WFC.copy()
    wfc[:3, 3] = SCENE_CENTER - 100.0 * wfc[:3, 2]  # 100 m away along the optical axis
    K = _K(f)
    l = light(45, -30)
    smp = samples_for(K=K, wfc=wfc)
    r = estimate_photo(render(direction=l, K=K, wfc=wfc), smp, SCENE_CENTER)
    assert r.status == "ok"
    assert np.degrees(angle_between(r.direction, l)) < 0.6


# ----------------------------------------------------------------------------- rejection
def test_all_black_photo_too_dark(samples):
    r = estimate_photo(np.zeros((RES, RES, 3), np.float32), samples, SCENE_CENTER)
    assert r.status == "rejected" and r.reason == "too_dark"
    assert np.all(np.isfinite(r.direction))


def test_saturated_photo(samples):
    img = np.minimum(render(direction=light(20, 0), intensity=8.0), 1.0)
    r = estimate_photo(img, samples, SCENE_CENTER)
    assert r.status == "rejected" and r.reason == "saturated"


def test_one_shadowed_sphere_is_dropped(samples):
    l = light(30, 45)
    img = render(direction=l)
    s = samples[2]
    img[s.rows, s.cols] *= 0.05  # the person's shadow: only a little light left
    r = estimate_photo(img, samples, SCENE_CENTER)
    assert r.status == "ok" and 2 not in r.used_spheres
    assert r.spheres[2].status in ("shadowed", "outlier", "too_dark")
    assert np.degrees(angle_between(r.direction, l)) < 0.6


def test_partial_cast_shadow_rejected_as_outliers(samples):
    l = light(30, 45)
    img = render(direction=l)
    s = samples[0]
    cut = s.normals[:, 0] > 0.3  # a shadow edge across the sphere
    img[s.rows[cut], s.cols[cut]] *= 0.1
    r = estimate_photo(img, samples, SCENE_CENTER)
    assert r.status == "ok"
    assert np.degrees(angle_between(r.direction, l)) < 0.8


def test_all_spheres_shadowed(samples):
    img = render(direction=light(30, 45))
    for s in samples[1:]:
        img[s.rows, s.cols] = 0.0
    r = estimate_photo(img, samples, SCENE_CENTER)
    assert r.status == "rejected" and r.reason == "too_few_spheres"


def test_spheres_disagree(samples):
    a = render(direction=light(30, 0))
    b = render(direction=light(30, 180))
    img = a.copy()
    for s in samples[2:]:
        img[s.rows, s.cols] = b[s.rows, s.cols]
    r = estimate_photo(img, samples, SCENE_CENTER, model="distant")
    assert r.status == "rejected" and r.reason == "spheres_disagree"


def test_reasons_documented():
    assert set(REASONS) == {"spheres_disagree", "saturated", "too_dark", "shadowed", "too_few_spheres", "fit_failed",
                            "no_highlight", "highlight_at_rim", "dark"}


# ----------------------------------------------------------------------------- capture level
def test_estimate_lights_on_synth_capture(tmp_path):
    from ffls.synth import scene as synth
    from ffls.io.capture import load_capture, load_lights, save_lights
    from ffls.spheres.estimate import estimate_lights

    dirs = np.array([light(10, -90), light(40, 0), light(60, 150)])
    synth.write_synthetic_capture(tmp_path, resolution=256, directions=dirs, ground_albedo=0.0, progress=False)
    cap = load_capture(tmp_path)
    truth = json.loads((tmp_path / "truth.json").read_text())
    M = np.linalg.inv(cap.world_from_camera)
    sph = [SimpleNamespace(center_cam=M[:3, :3] @ np.asarray(c) + M[:3, 3], radius=truth["sphere_radius"])
           for c in truth["sphere_centers"]]
    L = estimate_lights(cap, spheres=sph, progress=False, workers=1)
    err = np.degrees(angle_between(L.directions, dirs))
    assert all(s == "ok" for s in L.status) and err.max() < 1.0, err
    save_lights(L, tmp_path / "lights.json")
    back = load_lights(tmp_path / "lights.json", cap)
    np.testing.assert_allclose(back.directions, L.directions, atol=1e-9)
    with pytest.raises(InputError):
        estimate_lights(cap, spheres=sph[:1], progress=False, workers=1, model="near")


def test_cli_lights(tmp_path, capsys):
    """``ffls lights``: summary printed, lights.json and the --plot PNG written."""
    from ffls.synth import scene as synth
    from ffls.io.capture import load_lights
    from ffls.cli import main

    dirs = np.array([light(10, -90), light(40, 0), light(60, 150), light(30, 60)])
    synth.write_synthetic_capture(tmp_path, resolution=256, directions=dirs, ground_albedo=0.3, progress=False)
    truth = json.loads((tmp_path / "truth.json").read_text())
    out, png = tmp_path / "L.json", tmp_path / "lights.png"
    rc = main(["lights", str(tmp_path), "-o", str(out), "--workers", "1", "--no-progress", "--plot", str(png)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "of 4 lights accepted" in text and f"wrote {out}" in text and f"wrote {png}" in text
    back = load_lights(out)
    assert len(back) == 4
    ok = back.ok_mask
    assert ok.sum() >= 3
    err = np.degrees(angle_between(back.directions[ok], np.asarray(truth["directions"])[ok]))
    assert err.max() < 3.0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 1000


def test_near_joint_fit_when_calibration_falls_back(samples):
    """With too few photos to calibrate the bounce, the first pass is final: its near photos (whose
    joint fit the first pass defers, ``joint=False``) still get the joint fit."""
    Ss = [SCENE_CENTER + 2.0 * light(th, ph) for th, ph in [(20, -60), (50, 120)]]
    vals = [sphere_values(render(position=S), samples) for S in Ss]
    est = estimate_photos(vals, samples, SCENE_CENTER, refine_centres=False)
    assert all(c.ratio is None for c in est.calibration)
    for r, v, S in zip(est.photos, vals, Ss):
        assert r.status == "ok" and r.model == "near" and not r.joint_pending
        full = estimate_photo(None, samples, SCENE_CENTER, values=v)
        assert np.allclose(r.position, full.position, atol=1e-6)
        assert np.linalg.norm(r.position - S) < 0.1
    deferred = estimate_photo(None, samples, SCENE_CENTER, values=vals[0], joint=False)
    assert deferred.joint_pending and deferred.model == "near"


def test_near_fit_pixel_lattice_matches_all_pixels(samples):
    """The joint fit on every 4th pixel (default ``stride``) agrees with the fit on all pixels far
    within the statistical uncertainty of the direction."""
    S = SCENE_CENTER + 2.0 * light(40, 30)
    v = sphere_values(render(position=S, own_shadow=False), samples)
    r = estimate_photo(None, samples, SCENE_CENTER, values=v)
    fits = [fit_lambert(s.normals, g, ok, g=s.ground) for s, (g, ok, _) in zip(samples, v)]
    kw = {"terms": None, "terminator": 0.15}
    a = fit_near_light(samples, [x[0] for x in v], [f.inliers for f in fits], r.position, stride=1, **kw)
    b = fit_near_light(samples, [x[0] for x in v], [f.inliers for f in fits], r.position, **kw)
    assert a.success and b.success and b.n_pixels < 0.3 * a.n_pixels
    assert np.degrees(angle_between(a.position - SCENE_CENTER, b.position - SCENE_CENTER)) < 0.05
    assert np.linalg.norm(a.position - S) < 0.1 and np.linalg.norm(b.position - S) < 0.1


def test_near_fit_mask_keeps_the_terminator_band(samples):
    """The joint near fit gets every valid, non-outlier pixel (it re-selects the terminator band
    with the light's position), not only the per-sphere fit's pixels outside its own band; dark
    specks (outliers) and invalid pixels stay out."""
    l = light(50, 30)
    s = samples[0]
    y = s.values(render(direction=l))
    valid = np.ones(len(s), bool)
    valid[::7] = False  # "saturated" pixels
    specks = np.zeros(len(s), bool)
    specks[np.flatnonzero(s.normals @ l > 0.5)[::11]] = True
    y[specks] *= 0.3
    fit = fit_lambert(s.normals, y, valid, terminator=0.15)
    assert fit.status == "ok" and np.degrees(angle_between(fit.direction, l)) < 0.5
    mask = near_fit_mask(fit)
    band = valid & (np.abs(s.normals @ fit.direction) < 0.15)
    assert band.sum() > 20 and mask[band & fit.non_outliers].all() and mask[band].mean() > 0.9
    assert (mask & ~fit.inliers).any()  # more than the per-sphere fit's own pixels
    assert not mask[~valid].any()
    assert (specks & valid).sum() > 5 and not mask[specks].any()


def test_fit_lambert_clipped_black_floor_is_censored_by_the_model():
    """8-bit linear codes under Poisson-Gaussian noise: the shadow side is partly clipped at code
    0. The clipped pixels are invalid for pixel_validity; the fit leaves out the pixels its model
    predicts near the floor and keeps the others, so the shadow side still separates the bounce."""
    rng = np.random.default_rng(3)
    n = normalize(rng.normal(size=(40000, 3)))
    n = n[n[:, 1] < -0.1][:10000]
    g = 0.5 * (1 - n[:, 2])
    errs, errs_by_value, clipped = [], [], 0
    for _ in range(6):
        l = normalize(np.array([rng.uniform(-1, 1), rng.uniform(-1, -0.2), rng.uniform(0.1, 1)]))
        clean = 0.5 * np.maximum(n @ l, 0) + 0.003 + 0.01 * g
        x = 2e-4 * rng.poisson(clean / 2e-4) + rng.normal(0, 0.004, clean.size)
        y = np.clip(np.round(x * 255), 0, 255) / 255
        valid, nsat = pixel_validity(y)
        clipped += int((~valid & (y == 0)).sum())
        f = fit_lambert(n, y, valid, n_saturated=nsat, g=g, own_shadow=False)
        errs.append(np.degrees(angle_between(f.direction, l)))
        valid, nsat = pixel_validity(y, black_fraction=0.02)  # the former rule: censored by value
        f = fit_lambert(n, y, valid, n_saturated=nsat, g=g, own_shadow=False)
        errs_by_value.append(np.degrees(angle_between(f.direction, l)))
    assert clipped > 0
    assert np.mean(errs) < 0.15, errs
    assert np.mean(errs) < 0.6 * np.mean(errs_by_value), (errs, errs_by_value)


def test_near_fit_mixed_matte_pixels_and_mirror_rays(samples):
    """Two matte spheres' pixels and two mirror rays (exact, from points on the other two spheres)
    in one least-squares problem: the position is found from a start 20 cm off, its covariance is
    finite, and rays alone (no matte sphere) triangulate it with a covariance that scales with
    their stated deviation."""
    from ffls.spheres.combine import fit_near_light_mixed

    S = SCENE_CENTER + 2.0 * light(40, 30)
    v = sphere_values(render(position=S, own_shadow=False), samples[:2])
    fits = [fit_lambert(s.normals, g, ok, g=s.ground) for s, (g, ok, _) in zip(samples[:2], v)]
    points = [CENTERS[k] + R_SPH * normalize(S - CENTERS[k]) for k in (2, 3)]
    sig = np.radians(0.3) / np.sqrt(2.0)
    rays = [(p, normalize(S - p), sig) for p in points]
    start = S + np.array([0.2, -0.1, 0.1])
    fit = fit_near_light_mixed(samples[:2], [x[0] for x in v], [near_fit_mask(f) for f in fits], start, rays,
                               inflation=[f.inflation for f in fits])
    assert fit.success and np.all(np.isfinite(fit.cov))
    assert np.linalg.norm(fit.position - S) < 0.1
    assert np.degrees(angle_between(fit.position - SCENE_CENTER, S - SCENE_CENTER)) < 0.3
    # rays only: exact rays meet at S; twice the stated deviation, twice the position's sd
    rays3 = rays + [(CENTERS[0] + R_SPH * normalize(S - CENTERS[0]), normalize(S - CENTERS[0] - R_SPH
                                                                            * normalize(S - CENTERS[0])), sig)]
    a = fit_near_light_mixed([], [], [], start, rays3)
    b = fit_near_light_mixed([], [], [], start, [(p, d, 2 * s) for p, d, s in rays3])
    assert a.success and np.linalg.norm(a.position - S) < 1e-3
    assert np.sqrt(np.trace(b.cov)) == pytest.approx(2 * np.sqrt(np.trace(a.cov)), rel=0.05)


def _png_capture(folder, n=5, shape=(24, 32), encoding="linear", seed=0):
    import json

    import cv2

    rng = np.random.default_rng(seed)
    names = []
    for i in range(n):
        q = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)
        q[0, 0] = 255  # a saturated pixel
        names.append(f"p{i}.png")
        cv2.imwrite(str(folder / names[-1]), q)
    K = [[40.0, 0, (shape[1] - 1) / 2], [0, 40.0, (shape[0] - 1) / 2], [0, 0, 1]]
    (folder / "capture.json").write_text(json.dumps({"format": "ffls-capture", "version": 1, "images": names,
                                                     "camera": {"K": K}, "sphere_radius": 0.04,
                                                     "encoding": encoding}))
    return names


@pytest.mark.parametrize("workers", [1, 2])
def test_decode_photos_once_matches_reading_them(tmp_path, workers):
    """decode_photos gives the detection's reductions (as sequence_stats over the photos: max,
    brightest, mean, per-photo colour counts and edge evidence) and keeps the decoded photos
    (linear values and stored codes) that the first pass would read."""
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import read_photo
    from ffls.spheres.detect import sequence_stats
    from ffls.spheres.estimate import decode_photos

    _png_capture(tmp_path)
    cap = load_capture(tmp_path)
    d = decode_photos(cap, workers=workers)
    st = sequence_stats([read_photo(cap, i).linear for i in range(5)])
    assert d.n == st.n == 5 and d.bit_depths == {8}  # five chunks merged
    assert np.array_equal(d.stats.max, st.max) and np.array_equal(d.stats.brightest, st.brightest)
    assert np.allclose(d.stats.mean, st.mean, rtol=1e-6, atol=1e-7)
    assert d.stats.colour_counts.sum() > 0 and np.array_equal(d.stats.colour_counts, st.colour_counts)
    assert d.stats.edge_photos == st.edge_photos == 5
    assert np.allclose(d.stats.edge_tensor, st.edge_tensor, rtol=1e-5, atol=1e-6)
    for i in range(5):
        ph = read_photo(cap, i)
        lin, raw, depth = d.photo(i)
        assert depth == 8 and np.array_equal(lin, ph.linear)
        assert np.array_equal(raw, np.rint(ph.raw * 255).astype(np.uint8))


@pytest.mark.parametrize("workers", [1, 2])
def test_decode_photos_keeps_half_photos_as_stored(tmp_path, workers):
    """Half EXR photos are kept as their half values (half the memory of float32) and widened where
    read: the same float32 values as reading the photo, whole or at given pixels (0 elsewhere). A
    photo colour-converted on reading (an EXR ``chromaticities`` attribute) is not held: it is read
    again."""
    import json

    from ffls.io.capture import load_capture
    from ffls.io.images import write_exr
    from ffls.radiance.photos import read_photo
    from ffls.spheres.estimate import decode_photos

    import OpenEXR

    rng = np.random.default_rng(4)
    names = [f"p{i}.exr" for i in range(5)]
    for i, name in enumerate(names):
        rgb = rng.uniform(0.0, 3.0, (24, 32, 3))
        if i != 3:
            write_exr(tmp_path / name, rgb, half=True)
            continue
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
                  "chromaticities": (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)}  # ACEScg
        planes = {c: np.ascontiguousarray(rgb[..., k], np.float16) for k, c in enumerate("RGB")}
        with OpenEXR.File(header, planes) as f:
            f.write(str(tmp_path / name))
    (tmp_path / "capture.json").write_text(json.dumps({"format": "ffls-capture", "version": 1, "images": names,
                                                       "sphere_radius": 0.04}))
    cap = load_capture(tmp_path)
    d = decode_photos(cap, workers=workers)
    assert d.linear.dtype == np.float16 and d.held.tolist() == [True, True, True, False, True]
    rows, cols = np.array([0, 5, 23]), np.array([1, 7, 31])
    for i in range(5):
        want = read_photo(cap, i).linear
        if i == 3:
            assert d.photo(i) is None and d.photo(i, pixels=(rows, cols)) is None
            continue
        lin, raw, depth = d.photo(i)
        assert depth == "half" and raw is None and lin.dtype == np.float32
        np.testing.assert_array_equal(lin.view(np.uint32), want.view(np.uint32))
        lin, _, _ = d.photo(i, pixels=(rows, cols))
        np.testing.assert_array_equal(lin[rows, cols].view(np.uint32), want[rows, cols].view(np.uint32))
        assert np.count_nonzero(lin) == np.count_nonzero(want[rows, cols])


def test_decode_photos_same_for_any_workers(tmp_path):
    """The chunks do not depend on the number of workers: the reductions are identical to the bit."""
    from ffls.io.capture import load_capture
    from ffls.spheres.estimate import decode_photos

    _png_capture(tmp_path)
    cap = load_capture(tmp_path)
    a, b = decode_photos(cap, workers=1), decode_photos(cap, workers=2)
    for f in ("max", "brightest", "mean", "colour_counts", "edge_tensor"):
        assert np.array_equal(getattr(a.stats, f), getattr(b.stats, f)), f


def test_cli_lights_same_for_one_and_two_workers(tmp_path, capsys):
    """``ffls lights`` decodes the photos once (in a pool with 2 workers), detection included: its
    per-photo colour evidence sets the object's red glossy ball aside as coloured either way, and
    lights.json is the same, byte for byte, with 1 and 2 workers."""
    from ffls.synth import scene as synth
    from ffls.cli import main

    dirs = np.array([light(t, p) for t, p in [(10, -90), (40, 0), (60, 150), (30, 60), (50, -120), (20, 100),
                                              (65, -30), (35, 170), (45, -60)]])
    synth.write_synthetic_capture(tmp_path, resolution=224, directions=dirs, progress=False)
    docs = []
    for w in (1, 2):
        out = tmp_path / f"L{w}.json"
        assert main(["lights", str(tmp_path), "-o", str(out), "--workers", str(w), "--no-progress"]) == 0
        text, err = capsys.readouterr()
        assert "4 spheres found" in text
        assert any("coloured" in ln and "in the photos" in ln for ln in err.splitlines()), err
        docs.append(out.read_bytes())
    assert docs[0] == docs[1]


def test_decode_photos_names_a_photo_of_another_size(tmp_path):
    import cv2

    from ffls.io.capture import load_capture
    from ffls.spheres.estimate import decode_photos

    names = _png_capture(tmp_path)
    cv2.imwrite(str(tmp_path / names[3]), np.zeros((20, 32, 3), np.uint8))
    with pytest.raises(InputError) as e:  # the capture's load reads each photo's header and says so
        decode_photos(load_capture(tmp_path), workers=1)
    assert names[3] in str(e.value.path) and "32x20" in str(e.value) and names[0] in str(e.value)


# ----------------------------------------------------------------------------- the fit's fixed point
def _least_squares_of_own_pixels(n, y, g, fit):
    """The linear least-squares solution of ``fit``'s model on ``fit``'s own pixels (``inliers``),
    classified lit / shadow by its direction, solved from the design (not normal equations)."""
    use = fit.inliers
    lit = use & (n @ fit.direction > 0)
    cols = [n * lit[:, None], np.ones((n.shape[0], 1))]
    if fit.model == "bounce":
        cols.append(g[:, None])
    A = np.concatenate(cols, axis=1)[use]
    if fit.model == "plain":
        A = A[:, :3]
    x = np.linalg.lstsq(A, y[use], rcond=None)[0]
    return x


@pytest.mark.parametrize("noise", [0.02, 0.001])  # above and below the 1% relative noise floor
@pytest.mark.parametrize("start_offset_deg", [None, 2.0, 50.0])
def test_fit_lambert_is_the_least_squares_fit_of_its_own_pixels(noise, start_offset_deg):
    """The classification iterations end at a fixed point whose normal equations (updated pixel by
    pixel between iterations) are those of its final pixels; the robust scale, above or below the
    noise floor, rejects the speckle and keeps the noise; any start reaches the same fixed point."""
    rng = np.random.default_rng(3)
    n = normalize(rng.normal(size=(12000, 3)))
    n = n[n[:, 1] < -0.05]
    l = normalize(np.array([0.4, -0.5, 0.6]))
    g = ground_bounce(n)
    y = 0.5 * np.maximum(n @ l, 0.0) + 0.01 + 0.05 * g + rng.normal(0, noise * 0.5, n.shape[0])
    speck = rng.random(n.shape[0]) < 0.03
    y[speck] += 0.3  # highlights / specks: outliers
    start = None
    if start_offset_deg is not None:
        axis = normalize(np.cross(l, [0.0, 0.0, 1.0]))
        t = np.radians(start_offset_deg)
        start = l * np.cos(t) + np.cross(axis, l) * np.sin(t)
    fit = fit_lambert(n, y, g=g, start=start, own_shadow=False)
    assert fit.status == "ok" and fit.model == "bounce"
    x = _least_squares_of_own_pixels(n, y, g, fit)
    np.testing.assert_allclose(x[:3] / np.linalg.norm(x[:3]), fit.direction, atol=1e-9)
    np.testing.assert_allclose([np.linalg.norm(x[:3]), x[3], x[4]], [fit.intensity, fit.ambient, fit.bounce],
                               rtol=1e-7, atol=1e-10)
    assert not (fit.non_outliers & speck).any()  # every speck (0.3 above) rejected
    kept = fit.non_outliers[~speck & np.isfinite(y)].mean()
    assert kept > 0.8  # the noise is kept (the rest: the darkest shadow, censored by the model)
    assert np.degrees(angle_between(fit.direction, l)) < (0.3 if noise > 0.01 else 0.05)
    if start_offset_deg is not None:  # the same fixed point as from the least-squares start
        ref = fit_lambert(n, y, g=g, own_shadow=False)
        np.testing.assert_allclose(fit.direction, ref.direction, atol=1e-9)
        assert np.array_equal(fit.non_outliers, ref.non_outliers)


def test_sphere_kinds_subtract_the_per_pixel_median_with_or_without_nan(samples):
    """'auto' spheres: each pixel's median over the photos is subtracted before the compactness
    (the median of the finite values where a pixel is non-finite in some photo); matte balls stay matte."""
    from ffls.spheres.estimate import sphere_kinds
    from ffls.spheres.highlight import classify_sphere, highlight_compactness

    values = [sphere_values(render(direction=light(t, p)), samples) for t, p in ((10, 0), (40, 60), (60, 200))]

    def reference(vals):
        out = []
        for k, s in enumerate(samples):
            grey = np.stack([np.asarray(v[k][0], dtype=np.float64) for v in vals])
            grey = grey - np.nanmedian(grey, axis=0)
            out.append(classify_sphere([highlight_compactness(s.rows, s.cols, g) for g in grey]))
        return out

    kinds = sphere_kinds(["auto"] * len(samples), samples, values)
    assert kinds == reference(values) and all(k.kind == "matte" for k in kinds)
    values[1][2].grey[:25] = np.nan  # a few non-finite pixels in one photo
    kinds = sphere_kinds(["auto"] * len(samples), samples, values)
    assert kinds == reference(values) and all(k.kind == "matte" and np.isfinite(k.statistic) for k in kinds)


# ----------------------------------------------------------------------------- first pass on some photos
def test_first_pass_photos_are_spread_over_the_sequence():
    from ffls.spheres.estimate import first_pass_photos

    assert first_pass_photos(80, None) == list(range(80))
    assert first_pass_photos(12, 40) == list(range(12))
    sub = first_pass_photos(80, 40)
    assert len(sub) == 40 and sub[0] == 0 and sub[-1] == 79 and sub == sorted(set(sub))
    assert max(np.diff(sub)) <= 3  # evenly spaced: no stretch of the sequence left out
    assert first_pass_photos(5, 1) == [0]
    with pytest.raises(ValueError):
        first_pass_photos(5, 0)


def test_first_pass_on_some_photos_fits_every_photo_in_the_second(samples, grid_values):
    """The first pass on 6 of 11 photos: the calibration reads those, the second pass fits all 11,
    with the same statuses and directions within 0.05 deg of the first pass on every photo."""
    dirs, vals = grid_values
    full = estimate_photos(vals, samples, SCENE_CENTER)
    some = estimate_photos(vals, samples, SCENE_CENTER, first_pass=6)
    assert len(some.photos) == len(vals)
    assert all(c.n_photos <= 6 for c in some.calibration)
    assert [c.n_photos for c in full.calibration] != [c.n_photos for c in some.calibration]
    for c in some.calibration:
        assert abs(c.ratio - 0.3) < 0.01, some.calibration
    assert [r.status for r in some.photos] == [r.status for r in full.photos]
    for a, b in zip(full.photos, some.photos):
        if a.status == "ok":
            assert np.degrees(angle_between(a.direction, b.direction)) < 0.05
            assert all(sp.fit.bounce_ratio is not None for sp in b.spheres if sp.status == "ok")


def test_first_pass_on_some_photos_without_a_calibration_fits_the_others(samples, grid_values):
    """Two photos cannot calibrate (min_photos = 3) and the first pass fitted one: the other is
    fitted afterwards (free bounce), as with every photo in the first pass."""
    dirs, vals = grid_values
    full = estimate_photos(vals[-2:], samples, SCENE_CENTER, refine_centres=False)
    some = estimate_photos(vals[-2:], samples, SCENE_CENTER, refine_centres=False, first_pass=1)
    assert all(c.ratio is None for c in some.calibration)
    for a, b in zip(full.photos, some.photos):
        assert a.status == b.status and b.spheres
        assert np.degrees(angle_between(a.direction, b.direction)) < 1e-6


@pytest.mark.parametrize("value", ["0", "-3", "many"])
def test_first_pass_flag_out_of_range_is_one_line(value, tmp_path, capsys):
    from ffls.cli import main

    assert main(["lights", str(tmp_path), "--first-pass", value]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--first-pass" in err, err


def test_near_joint_fit_frees_a_calibrated_bounce(samples):
    """A ground ratio imposed on the spheres' own fits (the capture's calibration, read from
    distant-light fits: too low under a near light) does not bias the joint near fit, which fits
    each sphere's bounce itself: the light is where a free bounce puts it."""
    S = SCENE_CENTER + 2.0 * light(20, -60)
    v = sphere_values(render(position=S), samples)
    free = estimate_photo(None, samples, SCENE_CENTER, values=v)
    low = estimate_photo(None, samples, SCENE_CENTER, values=v, bounce_ratio=[0.15] * len(samples))
    assert free.model == "near" and low.model == "near"
    assert np.linalg.norm(low.position - free.position) < 0.1
    assert np.degrees(angle_between(low.direction, S - SCENE_CENTER)) < 0.3


@pytest.mark.parametrize("encoding", ["linear", None])
def test_decode_photos_reads_each_photo_once_and_the_first_once_more(tmp_path, monkeypatch, encoding):
    """decode_photos reads the first photo once before the chunks (its depth, shape and colour
    note; it was read twice) and every photo once in its chunk; the same reductions."""
    import os

    import ffls.io.images as images
    import ffls.radiance.photos as photos
    from ffls.io.capture import load_capture
    from ffls.spheres.estimate import decode_photos

    _png_capture(tmp_path)
    if encoding is None:  # none stated: the stored values are decoded
        doc = json.loads((tmp_path / "capture.json").read_text())
        del doc["encoding"]
        (tmp_path / "capture.json").write_text(json.dumps(doc))
    cap = load_capture(tmp_path)
    want = decode_photos(cap, workers=1)
    assert want.stored == (encoding is None)
    reads = []
    real = images.read_image

    def counted(path, *a, **k):
        reads.append(os.path.basename(path))
        return real(path, *a, **k)

    monkeypatch.setattr(images, "read_image", counted)
    monkeypatch.setattr(photos, "read_image", counted)
    got = decode_photos(cap, workers=1)
    assert sorted(reads) == sorted(["p0.png"] + [f"p{i}.png" for i in range(5)]), reads
    assert np.array_equal(got.stats.max, want.stats.max) and np.array_equal(got.raw, want.raw)
    assert got.bit_depths == want.bit_depths and got.stored == want.stored


def _worker_state(_):
    """(the validity masks' module imported, the own-shadow table built) in this process."""
    import sys

    from ffls.spheres import lambert

    return "ffls.radiance.response" in sys.modules, lambert.own_shadow_table.cache_info().currsize


def test_photo_fitter_workers_inherit_what_the_fits_need(monkeypatch):
    """A PhotoFitter's forked workers inherit the module of sphere_values' validity masks and the
    own-shadow table, imported and built once before the fork (each worker made them for itself:
    about 0.04 s of CPU per worker on a 768 px capture)."""
    import multiprocessing
    import sys

    import ffls.radiance
    from ffls.spheres import lambert
    from ffls.spheres.estimate import PhotoFitter

    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork on this platform")
    monkeypatch.delitem(sys.modules, "ffls.radiance.response", raising=False)
    monkeypatch.delattr(ffls.radiance, "response", raising=False)
    lambert.own_shadow_table.cache_clear()
    with PhotoFitter(None, None, {}, workers=2) as fitter:
        got = fitter.map(_worker_state, [0, 1])
    assert got == [(True, 1), (True, 1)]
    with PhotoFitter(None, None, {"own_shadow": False}, workers=2) as fitter:  # no table needed: none built
        lambert.own_shadow_table.cache_clear()
        assert [t for _, t in fitter.map(_worker_state, [0, 1])] == [0, 0]
