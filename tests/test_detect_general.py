"""Sphere detection without hints on photo sequences made here (tests/detect_scenes.py).

Any number of spheres (1, 3, 6, 8) on black, grey, white and textured backgrounds; distractors
(a red matte sphere, a flat painted disc); spheres cut by the frame edge; a mirror (chrome) ball;
a long lens and an orthographic camera; hints (count, pixel circle without radius) and
conflicting hints; the no-sphere message. Tolerances come from ``benchmarks/detect_general.py``
(docs/spheres.md, "Detection without hints: measured"): centre errors there are at most 0.55 px
for matte spheres and 1 px for a mirror ball.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

import detect_scenes as ds
from ffls.errors import InputError
from ffls.spheres import detect

LIGHTS = ds.lights(12, seed=1)


def _errors(scene, fits):
    truth = np.array([scene.centre_px(b) for b in scene.balls])
    return [float(np.min(np.linalg.norm(truth - f.center_px, axis=1))) for f in fits]


@pytest.mark.parametrize("n,background", [(1, "black"), (1, "white"), (3, "grey"), (3, "texture"),
                                          (6, "white"), (6, "texture"), (8, "black"), (8, "grey")])
def test_any_count_any_background(n, background):
    """A diagonal of the count x background grid (the whole grid: benchmarks/detect_general.py)."""
    scene = ds.layout(n, seed=7 * n + len(background))
    seq = ds.render(scene, LIGHTS, background, seed=n)
    fits = detect.find_spheres(seq, scene.K, None, 0.04)
    assert len(fits) == n, (n, background, fits.rejected)
    err = _errors(scene, fits)
    assert max(err) < 0.6, err
    assert [f.center_px[0] for f in fits] == sorted(f.center_px[0] for f in fits)
    # one match per sphere: no sphere found twice
    truth = np.array([scene.centre_px(b) for b in scene.balls])
    assert len({int(np.argmin(np.linalg.norm(truth - f.center_px, axis=1))) for f in fits}) == n


@pytest.mark.parametrize("background", ["black", "grey"])
def test_distractors_are_not_spheres(background):
    scene = ds.layout(5, seed=11)
    scene.balls[3].albedo = (0.8, 0.1, 0.08)  # a red matte sphere: round, shaded, but coloured
    flat = scene.balls.pop(4)  # a flat white painted disc where the fifth sphere was
    u, v = scene.centre_px(flat)
    scene.discs.append((u, v, 18.0, (0.9, 0.9, 0.9)))
    seq = ds.render(scene, LIGHTS, background)
    fits = detect.find_spheres(seq, scene.K, None, 0.04)
    assert len(fits) == 3
    red = scene.centre_px(scene.balls[3])
    assert all(np.linalg.norm(f.center_px - red) > 10 for f in fits)
    assert all(np.linalg.norm(f.center_px - [u, v]) > 10 for f in fits)
    why = " | ".join(fits.rejected)
    assert "coloured" in why and "shading does not change" in why
    # a single max image has no per-photo information: the flat disc cannot be told apart then,
    # and the colour criterion still rejects the red sphere
    fits1 = detect.find_spheres(seq.max(axis=0), scene.K, None, 0.04)
    assert all(np.linalg.norm(f.center_px - red) > 10 for f in fits1)


def _ball_at(u, v, K, z=1.0, R=0.04):
    return ds.Ball(np.array([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z]), R)


def test_spheres_cut_by_the_frame_edge():
    K = np.array([[500.0, 0, 199.5], [0, 500, 149.5], [0, 0, 1]])
    # radius 20 px; the third is 63 % inside (used), the fourth 54 % (set aside)
    balls = [_ball_at(100, 150, K), _ball_at(250, 100, K), _ball_at(8, 200, K), _ball_at(300, 296, K)]
    scene = ds.Scene((300, 400), balls, "pinhole", K)
    seq = ds.render(scene, LIGHTS, "grey")
    fits = detect.find_spheres(seq, K, None, 0.04)
    assert len(fits) == 3
    assert max(_errors(scene, fits)) < 0.5
    cut = min(fits, key=lambda f: f.center_px[0])
    assert 0.6 < cut.visible_fraction < 0.7
    assert 0 < cut.center_sigma_px < 0.3  # well constrained, though less than a whole outline
    assert cut.center_sigma_px > max(f.center_sigma_px for f in fits if f is not cut)
    assert len(fits.rejected) == 1 and "cropped too much" in fits.rejected[0] and "54%" in fits.rejected[0]
    # its samples are the pixels inside the image only
    from ffls.spheres.samples import sphere_samples
    s = sphere_samples((300, 400), K, None, cut.center_cam, 0.04)
    assert s.cols.min() == 0 and np.all(s.cols < 400) and len(s) > 500
    # hinted, the same cropped sphere is an error naming it
    with pytest.raises(InputError, match=r"spheres\[0\].*cropped too much"):
        detect.find_spheres(seq, K, None, 0.04, hints=[{"center_px": [300, 294]}])


def test_mirror_ball():
    """A chrome ball: in the max image its reflected surroundings and the lights' highlights, no
    uniform disc, and a dim limb (it reflects what lies behind it)."""
    scene = ds.layout(2, seed=5)
    scene.balls[0].kind = "mirror"
    seq = ds.render(scene, LIGHTS, "grey")
    fits = detect.find_spheres(seq, scene.K, None, 0.04)
    assert len(fits) == 2
    assert max(_errors(scene, fits)) < 1.0
    scene = ds.layout(1, seed=9)
    scene.balls[0].kind = "mirror"
    fits = detect.find_spheres(ds.render(scene, LIGHTS, "black"), scene.K, None, 0.04)
    assert len(fits) == 1 and _errors(scene, fits)[0] < 0.5


def test_long_lens_needs_no_invented_focal_length():
    f = 30000.0  # 1.2 deg field of view: spheres at 40 m
    K = np.array([[f, 0, 199.5], [0, f, 149.5], [0, 0, 1]])
    balls = [_ball_at(u, v, K, z=40 + dz, R=0.03) for u, v, dz in [(80, 80, 0), (250, 200, 0.3), (330, 90, -0.2)]]
    scene = ds.Scene((300, 400), balls, "pinhole", K)
    fits = detect.find_spheres(ds.render(scene, LIGHTS, "grey"), K, None, 0.03)
    assert len(fits) == 3 and max(_errors(scene, fits)) < 0.3


def _ortho_scene():
    balls = [ds.Ball(np.array([u, v, 100.0]), 22.0) for u, v in [(80, 80), (250, 200), (330, 90)]]
    return ds.Scene((300, 400), balls, "orthographic", None)


def test_orthographic_camera():
    scene = _ortho_scene()
    seq = ds.render(scene, LIGHTS, "texture")
    fits = detect.find_spheres(seq, None, None, None, camera_model="orthographic")
    assert len(fits) == 3 and all(f.camera_model == "orthographic" and f.K is None for f in fits)
    assert max(_errors(scene, fits)) < 0.3
    for f in fits:
        assert abs(f.radius_px - 22.0) < 0.3
        ys, xs = np.nonzero(f.mask(seq.shape[1:3], margin_px=2))
        pix = np.stack([xs, ys], axis=1).astype(float)
        b = min(scene.balls, key=lambda b: np.linalg.norm(b.center[:2] - f.center_px))
        n_true = detect.orthographic_normals(pix, b.center[:2], b.radius)
        ang = np.degrees(np.arccos(np.clip(np.sum(n_true * f.normals(pix), axis=1), -1, 1)))
        assert np.nanmax(ang) < 3.0 and np.nanmean(ang) < 1.0
    # the sizes must agree under an orthographic camera: a half-size ball is set aside
    scene.balls.append(ds.Ball(np.array([150.0, 230.0, 100.0]), 11.0))
    fits = detect.find_spheres(ds.render(scene, LIGHTS, "black"), None, None, None, camera_model="orthographic")
    assert len(fits) == 3 and any("disagrees with the other spheres" in r for r in fits.rejected)


def test_orthographic_capture_end_to_end(tmp_path):
    """capture.json with an orthographic camera, no K and no sphere_radius: spheres found and
    the lights estimated (distant model), within a few degrees of the truth."""
    from ffls.conventions import angle_between
    from ffls.io.capture import load_capture
    from ffls.io.images import write_exr
    from ffls.spheres.estimate import estimate_lights

    scene = _ortho_scene()
    seq = ds.render(scene, LIGHTS, "grey", noise=0.001)
    names = []
    for i, im in enumerate(seq):
        names.append(f"p{i:02d}.exr")
        write_exr(tmp_path / names[-1], im)
    (tmp_path / "capture.json").write_text(json.dumps({
        "format": "ffls-capture", "version": 1, "images": names, "encoding": "linear",
        "camera": {"model": "orthographic"}, "hemisphere": "full"}))
    cap = load_capture(tmp_path)
    fits = detect.find_spheres_in_capture(cap)
    assert len(fits) == 3
    lights = estimate_lights(cap, progress=False, workers=1)
    truth = detect.to_world(LIGHTS, cap.world_from_camera, points=False)
    ok = np.array(lights.status) == "ok"
    assert ok.sum() >= 10
    err = np.degrees(angle_between(lights.directions[ok], truth[ok]))
    assert np.median(err) < 2.0 and err.max() < 5.0, err


# ----------------------------------------------------------------------------- hints
def test_count_hint_keeps_the_best():
    scene = ds.layout(3, seed=21)
    seq = ds.render(scene, LIGHTS, "grey")
    assert len(detect.find_spheres(seq, scene.K, None, 0.04, n_spheres=3)) == 3
    with pytest.raises(InputError, match=r"found 3 of 4 spheres.*sphere_count"):
        detect.find_spheres(seq, scene.K, None, 0.04, n_spheres=4)


def test_pixel_hint_without_radius():
    scene = ds.layout(3, seed=22)
    seq = ds.render(scene, LIGHTS, "white")
    hints = [{"center_px": list(scene.centre_px(b) + [3.0, -2.0])} for b in scene.balls[:2]]
    fits = detect.find_spheres(seq, scene.K, None, 0.04, hints=hints)
    assert len(fits) == 2 and all(f.source == "hint" for f in fits)
    assert max(_errors(scene, fits)) < 0.6


def test_conflicting_hints():
    scene = ds.layout(2, seed=23)
    seq = ds.render(scene, LIGHTS, "black")
    p = [list(scene.centre_px(b)) for b in scene.balls]
    with pytest.raises(InputError, match="sphere_count is 3 but 2 spheres are listed"):
        detect.find_spheres(seq, scene.K, None, 0.04, n_spheres=3, hints=[{"center_px": q} for q in p])
    with pytest.raises(InputError, match=r"spheres\[0\] and spheres\[1\] hint the same sphere"):
        detect.find_spheres(seq, scene.K, None, 0.04, hints=[{"center_px": p[0]}, {"center_px": [p[0][0] + 2, p[0][1]]}])
    world = detect.to_world(scene.balls[1].center)
    with pytest.raises(InputError, match=r"spheres\[0\].*disagrees with its world centre"):
        detect.find_spheres(seq, scene.K, None, 0.04, hints=[{"center_px": p[0], "center": list(world)}])
    fits = detect.find_spheres(seq, scene.K, None, 0.04, hints=[{"center_px": p[1], "center": list(world)}])
    assert _errors(scene, fits)[0] < 0.5


def test_no_sphere_message_says_where_and_how(tmp_path):
    scene = ds.Scene((200, 260), [], "pinhole", np.array([[400.0, 0, 130], [0, 400, 100], [0, 0, 1]]))
    seq = ds.render(scene, LIGHTS[:5], "texture")
    with pytest.raises(InputError) as e:
        detect.find_spheres(seq, scene.K, None, 0.04, source=tmp_path)
    msg = str(e.value)
    assert "\n" not in msg and str(tmp_path) in msg
    for part in ("no sphere found", "5 photos", "260x200 px", "radius 3 to 100 px", '"center_px"', '"sphere_count"'):
        assert part in msg, (part, msg)


def test_capture_json_count_and_hints(tmp_path):
    from ffls.io.capture import load_capture

    names = ["a.exr"]
    from ffls.io.images import write_exr
    write_exr(tmp_path / "a.exr", np.zeros((4, 4, 3), np.float32))
    doc = {"format": "ffls-capture", "version": 1, "images": names, "sphere_count": 2,
           "spheres": [{"center_px": [1, 2]}, {"center_px": [3, 2], "radius_px": 1.5}]}
    (tmp_path / "capture.json").write_text(json.dumps(doc))
    cap = load_capture(tmp_path)
    assert cap.sphere_count == 2 and "radius_px" not in cap.spheres[0]
    assert cap.to_json()["sphere_count"] == 2
    doc["sphere_count"] = 3
    (tmp_path / "capture.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="sphere_count.*lists 2 hints"):
        load_capture(tmp_path)
    doc["sphere_count"] = 0
    (tmp_path / "capture.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="sphere_count"):
        load_capture(tmp_path)


def test_only_sphere_cropped_too_much_is_named_in_the_error(tmp_path):
    K = np.array([[500.0, 0, 199.5], [0, 500, 149.5], [0, 0, 1]])
    scene = ds.Scene((300, 400), [_ball_at(300, 296, K)], "pinhole", K)  # 54 % of its outline inside
    with pytest.raises(InputError, match=r"no sphere found.*cropped too much, only 54%.*center_px") as e:
        detect.find_spheres(ds.render(scene, LIGHTS, "grey"), K, None, 0.04, source=tmp_path)
    assert "\n" not in str(e.value)


def test_pinhole_capture_without_sphere_radius_is_one_line(tmp_path):
    """A capture with no sphere_radius (e.g. the object shots of a calibration pair) names capture.json."""
    from ffls.io.capture import load_capture
    from ffls.spheres.detect import find_spheres_in_capture
    from ffls.synth.scene import make_scene, write_synthetic_capture

    write_synthetic_capture(tmp_path, n_lights=3, resolution=32, scene=make_scene(spheres=0), progress=False)
    cap = load_capture(tmp_path)
    assert cap.sphere_radius is None
    with pytest.raises(InputError, match="no sphere_radius") as e:
        find_spheres_in_capture(cap)
    assert "capture.json" in str(e.value)


def test_same_spheres_for_one_and_two_workers():
    """The candidate outlines fitted in 2 forked processes (``workers=2``) give the very same spheres
    as in this process, with and without hints: same circles to the bit, same set-aside list."""
    scene = ds.layout(3, seed=24)
    seq = ds.render(scene, LIGHTS, "texture", seed=3)
    one = detect.find_spheres(seq, scene.K, None, 0.04)
    two = detect.find_spheres(seq, scene.K, None, 0.04, workers=2)
    assert len(one) == 3 and list(one.rejected) == list(two.rejected)
    for a, b in zip(one, two, strict=True):
        assert np.array_equal(a.center_px, b.center_px) and a.radius_px == b.radius_px
        assert np.array_equal(a.center_cam, b.center_cam) and a.source == b.source
    hints = [{"center_px": list(map(float, f.center_px))} for f in one]
    h1 = detect.find_spheres(seq, scene.K, None, 0.04, hints=hints)
    h2 = detect.find_spheres(seq, scene.K, None, 0.04, hints=hints, workers=2)
    assert [tuple(f.center_px) for f in h1] == [tuple(f.center_px) for f in h2]


def test_cone_residuals_of_unit_rays_are_the_same_floats():
    """The outline fit's residual on rays normalised once (``unit_cone_residuals``) gives the
    very floats of the definition, ``f (angle_between(s, c) - alpha)`` with ``c`` the cone's axis."""
    from ffls.conventions import angle_between, normalize

    rng = np.random.default_rng(7)
    for _ in range(200):
        s = rng.normal(size=(int(rng.integers(1, 300)), 3)) * rng.uniform(0.1, 10)
        s[:, 2] = np.abs(s[:, 2]) + 5
        p = rng.normal(size=3) * [50, 50, 5] + [0, 0, 60]
        f = rng.uniform(200, 3000)
        x, y, a = p / f
        axis = np.array([x, y, 1.0]) / np.linalg.norm([x, y, 1.0])
        want = f * (angle_between(s, axis) - a)
        assert np.array_equal(detect.unit_cone_residuals(p, normalize(s), f), want)


def test_cone_jacobian_is_the_residuals_derivative():
    """The outline fit's analytic Jacobian (``unit_cone_jacobian``, handed to ``least_squares``
    instead of its forward differences) agrees with central differences of the residuals, and a
    sphere's centre fitted with it is the one fitted with forward differences within 1e-6 px."""
    from ffls.conventions import normalize

    rng = np.random.default_rng(11)
    for _ in range(50):
        f = rng.uniform(200, 3000)
        p = np.concatenate([rng.normal(size=2) * 0.2 * f, [rng.uniform(0.01, 0.3) * f]])
        s = normalize(rng.normal(size=(int(rng.integers(3, 300)), 3)) * [0.3, 0.3, 0.05] + [0, 0, 1])
        J = detect.unit_cone_jacobian(p, s, f)
        h = 1e-3
        num = np.stack([(detect.unit_cone_residuals(p + h * e, s, f) - detect.unit_cone_residuals(p - h * e, s, f))
                        / (2 * h) for e in np.eye(3)], axis=1)
        np.testing.assert_allclose(J, num, rtol=1e-6, atol=1e-6)
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    C = np.array([0.05, -0.03, 0.7])
    P = detect.silhouette_px(K, None, C, 0.04, n=300) + rng.normal(0, 0.4, (300, 2))
    P = np.concatenate([P, rng.uniform([330, 170], [420, 260], (40, 2))])  # clutter for the trimming
    rays = detect.pixel_rays(P, K)
    c0 = normalize(C + [0.002, 0.001, 0.0])
    got = detect.fit_sphere_center(rays, 0.04, 800.0, c0, 0.06)
    fd = detect.trimmed_fit  # the same fit on forward differences (the Jacobian not handed over)

    def forward(residuals, p0, pts, f_scale, trim, jac=None):
        return fd(residuals, p0, pts, f_scale, trim)

    import unittest.mock as mock
    with mock.patch.object(detect, "trimmed_fit", forward):
        want = detect.fit_sphere_center(rays, 0.04, 800.0, c0, 0.06)
    px = [detect.project_points(w[0][None], K, None)[0] for w in (got, want)]
    assert np.hypot(*(px[0] - px[1])) < 1e-6 and np.array_equal(got[1], want[1])


def test_trimmed_fits_read_contiguous_columns_and_the_same_floats():
    """The outline fits (``trimmed_fit``) hand their points to the residuals column-major, so
    that each column the residuals read is contiguous; the residuals of either layout are the
    same floats, so the fits are too."""
    from ffls.conventions import normalize

    rng = np.random.default_rng(5)
    s = normalize(rng.normal(size=(500, 3)) * [0.05, 0.05, 0.01] + [0.1, -0.05, 1.0])
    p = np.array([100.0, -50.0, 40.0])
    assert np.array_equal(detect.unit_cone_residuals(p, s, 900.0),
                          detect.unit_cone_residuals(p, np.asfortranarray(s), 900.0))
    seen = []

    def residuals(q, pts):
        seen.append(pts.flags.f_contiguous and pts.ndim == 2)
        return detect.unit_cone_residuals(q, pts, 900.0)

    detect.trimmed_fit(residuals, p, s, 1.0, 3.0)
    assert seen and all(seen)


def test_hints_fitted_in_one_call(monkeypatch):
    """The hints' fits are one ``fit_candidates`` call (which undistorts the image's edge points
    once), not one per hint; the retries another; the same spheres as each hint fitted alone."""
    scene = ds.layout(3, seed=22)
    seq = ds.render(scene, LIGHTS, "white")
    hints = [{"center_px": list(scene.centre_px(b) + [3.0, -2.0])} for b in scene.balls]
    hints[1]["radius_px"] = float(np.mean(np.hypot(*(detect.silhouette_px(scene.K, None, scene.balls[1].center, 0.04)
                                                      - scene.centre_px(scene.balls[1])).T)))
    calls = []
    real = detect.fit_candidates

    def counted(cands, *a, **k):
        calls.append(len(cands))
        return real(cands, *a, **k)

    monkeypatch.setattr(detect, "fit_candidates", counted)
    fits = detect.find_spheres(seq, scene.K, None, 0.04, hints=hints, retry_hints=False)
    assert calls == [3], calls
    assert len(fits) == 3 and all(f.source == "hint" for f in fits)
    assert max(_errors(scene, fits)) < 0.6
    alone = [detect.find_spheres(seq, scene.K, None, 0.04, hints=[h], retry_hints=False)[0] for h in hints]
    assert [f.center_px.tolist() for f in fits] == [f.center_px.tolist() for f in alone]


def test_outline_refits_undistort_their_points_once(monkeypatch):
    """``fit_until_stable`` undistorts its points once for all its rounds (each round's fit and
    band read the same rays; they were undistorted twice a round), and makes a SphereFit (visible
    share, coverage, centre's standard error) of the round it returns only: the same fit as
    before, every field."""
    K = np.array([[500.0, 0, 160], [0, 500.0, 120], [0, 0, 1]])
    dist = np.array([-0.2, 0.05, 0.0, 0.0, 0.0])
    cam = detect.DetectionCamera("pinhole", K, dist, np.eye(4), 0.04, (240, 320))
    C = np.array([0.02, -0.01, 0.6])
    rng = np.random.default_rng(3)
    P = detect.silhouette_px(K, dist, C, 0.04, n=240) + rng.normal(0, 0.3, (240, 2))
    P = np.concatenate([P, rng.uniform([100, 60], [220, 180], (60, 2))])  # clutter inside and around
    c0 = detect.project_points(C[None], K, dist)[0] + [1.5, -1.0]
    on = np.abs(np.hypot(*(P - c0).T) - 34.0) <= detect.OUTLINE_BAND_PX
    many = []
    real = detect.pixel_rays

    def counted(px, *a, **k):
        if len(np.asarray(px).reshape(-1, 2)) > 1:
            many.append(len(np.asarray(px).reshape(-1, 2)))
        return real(px, *a, **k)

    def before(on, c0_px, r0_px):  # the rounds as written before: each undistorting the points
        ft = None
        for _ in range(4):
            ft = detect.fit_outline(P[on], cam, c0_px, r0_px, "auto")
            c0_px, r0_px = ft.center_px, ft.radius_px
            new = np.abs(detect.outline_residuals_px(ft, P, cam)) <= detect.OUTLINE_BAND_PX
            if np.array_equal(new, on):
                break
            on = new
        return ft

    want = before(on, c0, 34.0)
    made, solved = [], []
    real_make, real_solve = detect.make_fit, detect.outline_solved

    def make(*a, **k):
        made.append(1)
        return real_make(*a, **k)

    def solve(*a, **k):
        solved.append(1)
        return real_solve(*a, **k)

    monkeypatch.setattr(detect, "pixel_rays", counted)
    monkeypatch.setattr(detect, "make_fit", make)
    monkeypatch.setattr(detect, "outline_solved", solve)
    got = detect.fit_until_stable(P, on, cam, c0, 34.0, "auto")
    assert many == [len(P)], many
    assert len(solved) >= 2 and len(made) == 1, (solved, made)  # several rounds, one SphereFit
    assert np.hypot(*(got.center_px - detect.project_points(C[None], K, dist)[0])) < 0.3
    for name in ("center_px", "center_cam", "radius_px", "residual_px", "coverage", "visible_fraction",
                 "center_sigma_px", "n_inliers", "n_edge_points", "edge_px"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    # a fit its caller drops for its RMS (the photo-edge circles, over PHOTO_EDGE_MAX_RESIDUAL_PX) is
    # not made at all: None, as the caller's test would have it
    made.clear()
    assert detect.fit_until_stable(P, on, cam, c0, 34.0, "auto", max_rms_px=0.99 * want.residual_px) is None
    assert made == []
    kept = detect.fit_until_stable(P, on, cam, c0, 34.0, "auto", max_rms_px=want.residual_px)
    assert kept.residual_px == want.residual_px and np.array_equal(kept.center_px, want.center_px)


def test_seeds_that_do_not_come_back_are_searched_again_on_the_same_photos():
    """Seeds (the first detection's spheres) that the seeded fits do not return are searched in
    full (``find_spheres``' local search, not a second call with its arguments copied: the photos
    given once, as a generator, are read once) and give the full search's spheres."""
    scene = ds.layout(3, seed=24)
    seq = ds.render(scene, LIGHTS, "grey", seed=3)
    full = detect.find_spheres(seq, scene.K, None, 0.04)
    off = detect.make_fit(np.array([0.05, 0.02, 1.1]), 0.04, scene.K, None, np.eye(4), "auto")
    wrong = detect.Spheres([off], ["a line of the first detection"])
    found = detect.find_spheres((im for im in seq), scene.K, None, 0.04, seeds=wrong)
    assert len(found) == len(full) == 3
    for a, b in zip(found, full):
        assert np.array_equal(a.center_px, b.center_px) and a.radius_px == b.radius_px
    assert found.rejected == full.rejected
