"""Mirror and glossy spheres (issue 9, item 2): the light from the specular highlight.

The images are rendered here with NumPy (ray-sphere intersection, reflection about the normal,
a small disc light at infinity or a sphere light nearby, 4x4 supersampling), in perspective and
orthographic projection, with sensor noise and clipping: independent of ``ffls synth``.
"""
from __future__ import annotations

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest

from ffls.camera.projection import pixel_rays
from ffls.conventions import angle_between, normalize
from ffls.errors import InputError
from ffls.io.capture import load_capture, sphere_materials
from ffls.spheres.estimate import estimate_photos
from ffls.spheres.highlight import (
    CONE95_PER_RMS,
    HighlightFit,
    MIRROR_COMPACTNESS,
    SphereView,
    classify_sphere,
    find_highlight,
    fit_highlight,
    fit_highlight_samples,
    highlight_compactness,
)
from ffls.spheres.photo import estimate_photo, sphere_uncertainty_deg
from ffls.spheres.samples import sphere_samples, sphere_values

F = 1000.0
R_SPH = 0.06  # at 1 m with f = 1000 px: 60 px radius


def _K(w, h, f=F):
    return np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])


def _rays(shape, K, dist, dx, dy):
    H, W = shape
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    px = np.stack([xx.ravel() + dx, yy.ravel() + dy], -1)
    return pixel_rays(px, K, dist).reshape(H, W, 3)


def render(shape, spheres, *, light=None, light_pos=None, light_radius_deg=2.0, light_size=0.03, power=1.0,
           env=0.05, K=None, dist=None, ortho=None, ss=4, clip=None, noise=0.0, seed=0):
    """Grey linear image of spheres (camera frame = world frame).

    spheres : list of (center (3,), radius, kind) with kind 'mirror', 'glossy' or 'matte'.
    light : (3,) distant light direction (a disc of ``light_radius_deg``), or light_pos (3,) a
    sphere light of radius ``light_size``. ortho : (scale m/px, cx, cy) for an orthographic camera.
    """
    H, W = shape
    off = (np.arange(ss) + 0.5) / ss - 0.5
    acc = np.zeros((H, W))
    for dy in off:
        for dx in off:
            depth = np.full((H, W), np.inf)
            rad = np.zeros((H, W))
            for C, R, kind in spheres:
                C = np.asarray(C, dtype=np.float64)
                if ortho is None:
                    d = _rays(shape, K, dist, dx, dy)
                    dc = d @ C
                    disc = dc * dc - C @ C + R * R
                    hit = disc > 0
                    t = dc - np.sqrt(np.where(hit, disc, 0.0))
                    P = d * t[..., None]
                else:
                    s, cx, cy = ortho
                    yy, xx = np.mgrid[0:H, 0:W].astype(float)
                    X, Y = (xx + dx - cx) * s - C[0], (yy + dy - cy) * s - C[1]
                    q = (X * X + Y * Y) / (R * R)
                    hit = q < 1
                    t = C[2] - R * np.sqrt(np.where(hit, 1 - q, 0.0))
                    P = np.stack([X + C[0], Y + C[1], t], -1)
                    d = np.zeros_like(P)
                    d[..., 2] = 1.0
                n = (P - C) / R
                r = d - 2.0 * np.sum(d * n, -1, keepdims=True) * n
                if light_pos is None:
                    ld = normalize(np.asarray(light, dtype=np.float64))
                    L = np.where(r @ ld >= np.cos(np.radians(light_radius_deg)), power, 0.0)
                    ndl = np.maximum(n @ ld, 0.0)
                else:
                    m = np.asarray(light_pos, dtype=np.float64) - P
                    tt = np.sum(m * r, -1)
                    L = np.where((tt > 0) & (np.sum(m * m, -1) - tt ** 2 < light_size ** 2), power, 0.0)
                    ndl = np.maximum(np.sum(n * normalize(m), -1), 0.0)
                refl = L + env * (0.6 + 0.4 * r[..., 1])
                val = {"mirror": refl, "glossy": 0.04 * refl + 0.02 * ndl, "matte": 0.8 * ndl + 0.01}[kind]
                front = hit & (t < depth)
                rad = np.where(front, val, rad)
                depth = np.where(front, t, depth)
            acc += rad
    img = acc / ss ** 2
    if noise:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    if clip is not None:
        img = np.minimum(img, clip)
    return img


def random_lights(n, seed, max_deg=65.0):
    """Distant lights on the camera side (camera frame: toward the camera is -z), up to ``max_deg`` off-axis."""
    rng = np.random.default_rng(seed)
    th = np.radians(rng.uniform(3.0, max_deg, n))
    ph = rng.uniform(0.0, 2 * np.pi, n)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), -np.cos(th)], -1)


def _disc_view(shape=(160, 160), C=(0.0, 0.0, 1.0), R=R_SPH, dist=None):
    K = _K(shape[1], shape[0])
    C = np.asarray(C, dtype=np.float64)
    s = sphere_samples(shape, K, dist, C, R)
    cpx = K @ (C / C[2])
    view = SphereView(center_px=cpx[:2], radius_px=float(s.radius_px), K=K, dist=dist, center_cam=C, radius=R,
                      center_sigma_px=0.05)
    return K, s, view


def _fit_image(img, s, view, clip=None):
    sat = np.zeros(img.shape, bool) if clip is None else img >= clip * (1 - 1e-9)
    grey = img[s.rows, s.cols]
    valid = ~sat[s.rows, s.cols]
    return fit_highlight_samples(view, s, grey, valid)


# ----------------------------------------------------------------------------- one sphere, one photo
@pytest.mark.parametrize("clip", [None, 0.3])
def test_distant_light_perspective_under_half_degree(clip):
    """60 px radius, a 1.5 deg disc light (3 deg where clipped to 30 %), noise 0.5 % of the light:
    errors well under 0.5 deg."""
    K, s, view = _disc_view()
    assert 59 < s.radius_px < 61
    errs = []
    for k, l in enumerate(random_lights(12, seed=3)):
        img = render((160, 160), [((0, 0, 1.0), R_SPH, "mirror")], light=l, K=K, noise=0.005, clip=clip, seed=k,
                     light_radius_deg=1.5 if clip is None else 3.0)
        fit = _fit_image(img, s, view, clip)
        assert fit.status == "ok", (k, fit.status)
        assert fit.clipped == (clip is not None)
        errs.append(float(np.degrees(angle_between(fit.direction, l))))
    assert max(errs) < 0.3, errs
    assert np.median(errs) < 0.15, errs


def test_distortion_and_off_axis_sphere():
    """A sphere off the optical axis under a distorting lens: the exact rays give the direction."""
    dist = np.array([-0.15, 0.05, 0.0, 0.0, 0.0])
    shape = (200, 300)
    C = (0.08, -0.02, 1.0)
    K, s, view = _disc_view(shape, C, dist=dist)
    for k, l in enumerate(random_lights(6, seed=5)):
        img = render(shape, [(C, R_SPH, "mirror")], light=l, K=K, dist=dist, noise=0.003, seed=k, ss=3)
        fit = _fit_image(img, s, view)
        assert fit.status == "ok"
        assert np.degrees(angle_between(fit.direction, l)) < 0.3


def test_orthographic_camera():
    """Parallel rays along +z: the view needs only the disc (no focal length)."""
    shape, scale = (160, 160), R_SPH / 60.0
    view = SphereView(center_px=np.array([80.0, 80.0]), radius_px=60.0, model="orthographic", center_sigma_px=0.05)
    yy, xx = np.mgrid[0:160, 0:160]
    disc = (xx - 80.0) ** 2 + (yy - 80.0) ** 2 < 58.5 ** 2
    for k, l in enumerate(random_lights(8, seed=11)):
        img = render(shape, [((0.0, 0.0, 1.0), R_SPH, "mirror")], light=l, ortho=(scale, 80.0, 80.0), noise=0.005,
                     seed=k)
        fit = fit_highlight(view, img, disc)
        assert fit.status == "ok"
        assert np.degrees(angle_between(fit.direction, l)) < 0.3


def test_clipped_highlights_unbiased():
    """A large (4 deg) light clipped to a flat core: same direction as unclipped, no systematic shift.

    The signed error along the highlight's radial direction on the ball (where a pixel centroid
    would be pulled toward the centre by the ball's magnification) averages to ~0.
    """
    K, s, view = _disc_view()
    radial, diff = [], []
    for k, l in enumerate(random_lights(10, seed=7, max_deg=60)):
        img = render((160, 160), [((0, 0, 1.0), R_SPH, "mirror")], light=l, light_radius_deg=4.0, K=K, ss=5,
                     noise=0.002, seed=k)
        full = _fit_image(img, s, view)
        clipped = _fit_image(np.minimum(img, 0.2), s, view, clip=0.2)
        assert clipped.status == "ok" and clipped.n_saturated > 10 and clipped.method == "censored"
        e = clipped.direction - l
        axis = normalize(l - (l @ np.array([0, 0, -1.0])) * np.array([0, 0, -1.0]))
        radial.append(float(np.degrees(e @ axis)))
        diff.append(float(np.degrees(angle_between(clipped.direction, full.direction))))
        assert np.degrees(angle_between(clipped.direction, l)) < 0.3
    assert abs(np.mean(radial)) < 0.05, radial
    assert max(diff) < 0.3, diff


def test_small_clipped_highlights_within_their_cone():
    """A 1.5 deg light clipped to 30 %: 2-4 clipped pixels, a centroid of a few pixels. Less
    accurate, and its uncertainty says so: every error within the 95 % cone, none above 1 deg."""
    K, s, view = _disc_view()
    errs, cones = [], []
    for k, l in enumerate(random_lights(12, seed=3)):
        img = render((160, 160), [((0, 0, 1.0), R_SPH, "mirror")], light=l, light_radius_deg=1.5, K=K, noise=0.005,
                     seed=k, clip=0.3)
        fit = _fit_image(img, s, view, 0.3)
        assert fit.status == "ok" and fit.clipped and fit.method == "centroid"
        errs.append(float(np.degrees(angle_between(fit.direction, l))))
        cones.append(fit.cone95_deg)
    assert max(errs) < 1.0, errs
    assert np.all(np.array(errs) <= np.array(cones)), (errs, cones)


def test_black_glossy_ball():
    """A dark diffuse body (2 %) with a dim 4 % reflection: the same method, unsaturated."""
    K, s, view = _disc_view()
    for k, l in enumerate(random_lights(6, seed=13)):
        img = render((160, 160), [((0, 0, 1.0), R_SPH, "glossy")], light=l, power=10.0, K=K, noise=0.002, seed=k)
        fit = _fit_image(img, s, view)
        assert fit.status == "ok" and not fit.clipped
        assert np.degrees(angle_between(fit.direction, l)) < 0.3


def test_statuses_no_highlight_rim_saturated():
    K, s, view = _disc_view()
    sph = [((0, 0, 1.0), R_SPH, "mirror")]
    behind = render((160, 160), sph, light=[0.0, 0.0, 1.0], K=K, noise=0.002)  # light right behind the ball
    assert _fit_image(behind, s, view).status == "no_highlight"
    grazing = normalize(np.array([0.45, 0.0, 0.89]))  # 153 deg from the view: reflected next to the silhouette
    rim = render((160, 160), sph, light=grazing, light_radius_deg=6.0, K=K)
    assert _fit_image(rim, s, view).status == "highlight_at_rim"
    huge = render((160, 160), sph, light=[0.2, 0.1, -1.0], light_radius_deg=30.0, K=K)
    assert _fit_image(np.minimum(huge, 0.01), s, view, clip=0.01).status == "saturated"


def test_uncertainty_is_an_honest_rms():
    """Noise-dominated highlights (a dim light): the RMS uncertainty tracks the observed errors.

    ``floor_deg = 0`` isolates the propagated part: the RMS error over many photos lies within a
    factor 1.6 of the RMS predicted, and the 95 % cone covers 80-100 % of them."""
    K, s, view = _disc_view()
    errs, unc = [], []
    for k, l in enumerate(random_lights(30, seed=17)):
        img = render((160, 160), [((0, 0, 1.0), R_SPH, "mirror")], light=l, K=K, light_radius_deg=2.0, noise=0.03,
                     seed=k, ss=3)
        sat = np.zeros(img.shape, bool)
        disc = np.zeros(img.shape, bool)
        disc[s.rows, s.cols] = True
        fit = fit_highlight(view, img, disc, sat, floor_deg=0.0)
        assert fit.status == "ok"
        errs.append(float(np.degrees(angle_between(fit.direction, l))))
        unc.append(fit.uncertainty_deg)
    errs, unc = np.array(errs), np.array(unc)
    ratio = np.sqrt(np.mean(errs ** 2)) / np.sqrt(np.mean(unc ** 2))
    assert 1 / 1.6 < ratio < 1.6, ratio
    cover = np.mean(errs <= CONE95_PER_RMS * unc)
    assert 0.8 <= cover <= 1.0, cover


def test_find_highlight_ignores_a_hot_pixel():
    img = np.full((60, 60), 0.05)
    disc = np.ones((60, 60), bool)
    img[10, 10] = 5.0  # a single hot pixel
    yy, xx = np.mgrid[0:60, 0:60]
    img += 1.0 * np.exp(-((xx - 40.3) ** 2 + (yy - 30.6) ** 2) / (2 * 1.5 ** 2))
    spot = find_highlight(img, disc)
    assert spot.found
    w = spot.weights
    cx, cy = np.sum(w * spot.cols) / w.sum(), np.sum(w * spot.rows) / w.sum()
    assert abs(cx - 40.3) < 0.1 and abs(cy - 30.6) < 0.1


# ----------------------------------------------------------------------------- kinds
def test_classification_mirror_glossy_matte():
    K, s, view = _disc_view()
    stats = {}
    for kind in ("mirror", "glossy", "matte"):
        vals = []
        for k, l in enumerate(random_lights(5, seed=19)):
            img = render((160, 160), [((0, 0, 1.0), R_SPH, kind)], light=l, K=K, noise=0.002, seed=k, ss=2,
                         power=10.0 if kind == "glossy" else 1.0)
            vals.append(highlight_compactness(s.rows, s.cols, img[s.rows, s.cols]))
        stats[kind] = classify_sphere(vals)
    assert stats["mirror"].kind == "mirror" and stats["mirror"].statistic < MIRROR_COMPACTNESS / 5
    assert stats["glossy"].kind == "mirror"
    assert stats["matte"].kind == "matte" and stats["matte"].statistic > 5 * MIRROR_COMPACTNESS
    assert "classified" in str(stats["matte"])
    assert classify_sphere([np.nan, np.nan]).kind == "matte"


def test_a_small_balls_two_pixel_highlight_is_compact_and_a_hot_pixel_is_not():
    """A small chrome ball (18 px) with its highlight on 2 clipped pixels, and the lit table it
    reflects over its lower half at a quarter of the clip: compact (a mirror). A matte ball's lit
    cap with a lone hot pixel at the clip: not compact."""
    yy, xx = np.mgrid[0:40, 0:40]
    disc = np.hypot(xx - 19.5, yy - 19.5) <= 18
    rows, cols = np.nonzero(disc)
    chrome = np.where(yy > 24, 0.25, 0.02).astype(np.float64)
    chrome[12, 20:22] = 1.0
    assert highlight_compactness(rows, cols, chrome[rows, cols]) < MIRROR_COMPACTNESS / 5
    matte = np.clip(np.cos(np.radians(2.5 * np.hypot(xx - 14, yy - 15))), 0, None) * 0.4
    matte[30, 20] = 1.0  # hot pixel
    assert highlight_compactness(rows, cols, matte[rows, cols]) > 5 * MIRROR_COMPACTNESS


def test_outline_uncertainty_grows_toward_the_rim_with_the_radius():
    """A radius error moves a highlight near the rim, not one at the centre: the cone of a
    highlight near the rim grows with ``radius_sigma_px``; a centre error moves both."""
    K, s, view = _disc_view()
    c = np.asarray(view.center_px)
    r = view.radius_px
    J_mid, J_rim = view.outline_jacobian(c + [0.05 * r, 0.0]), view.outline_jacobian(c + [0.9 * r, 0.0])
    assert np.linalg.norm(J_mid[:, 2]) < 0.1 * np.linalg.norm(J_rim[:, 2])
    # a centre shift of 1 px tilts the normal at the centre by 1/r, its reflection by 2/r
    assert np.linalg.norm(J_mid[:, 0]) == pytest.approx(2.0 / r, rel=0.2)
    outside = c[None] + [[r + 0.5, 0.0]]
    assert np.all(np.isnan(view.reflect(outside)[0]))
    assert np.all(np.isfinite(view.with_outline((0.0, 0.0), 1.0).reflect(outside)[0]))  # the grown outline holds it
    assert np.all(np.isfinite(view.with_outline((0.7, 0.0), 0.0).reflect(outside)[0]))  # so does the shifted one


def test_sphere_materials_from_capture_json(tmp_path):
    def cap(doc):
        d = tmp_path / str(len(list(tmp_path.iterdir())))
        d.mkdir()
        cv2.imwrite(str(d / "a.png"), np.zeros((8, 8, 3), np.uint8))
        (d / "capture.json").write_text(json.dumps({"format": "ffls-capture", "version": 1, "images": ["a.png"],
                                                    **doc}))
        return load_capture(d)

    c = cap({"sphere_material": "mirror",
             "spheres": [{"center_px": [10, 10], "radius_px": 5}, {"center_px": [40, 10], "radius_px": 5,
                                                                   "material": "matte"}]})
    assert sphere_materials(c, 2) == ["mirror", "matte"]
    assert sphere_materials(cap({}), 3) == ["auto"] * 3
    with pytest.raises(InputError, match="sphere_material"):
        sphere_materials(cap({"sphere_material": "chrome"}), 1)
    with pytest.raises(InputError, match=r"spheres\[0\].material"):
        sphere_materials(cap({"spheres": [{"center_px": [10, 10], "radius_px": 5, "material": 3}]}), 1)
    with pytest.raises(InputError, match="found"):
        sphere_materials(c, 3)


# ----------------------------------------------------------------------------- photos and captures
SHAPE = (200, 400)
C_LEFT, C_RIGHT = np.array([-0.1, 0.0, 1.0]), np.array([0.1, 0.0, 1.0])


def _pipeline_spheres(kinds, centers=(C_LEFT, C_RIGHT)):
    K = _K(SHAPE[1], SHAPE[0])
    samples, views = [], []
    for C in centers:
        s = sphere_samples(SHAPE, K, None, C, R_SPH)
        samples.append(s)
        cpx = K @ (C / C[2])
        views.append(SphereView(center_px=cpx[:2], radius_px=float(s.radius_px), K=K, center_cam=C, radius=R_SPH,
                                center_sigma_px=0.05))
    return K, samples, views


def test_near_light_from_two_mirror_spheres():
    """A 3 cm sphere light 60 cm away: the rays from the two highlights' reflection points meet at it."""
    K, samples, views = _pipeline_spheres(["mirror", "mirror"])
    spheres = [(C_LEFT, R_SPH, "mirror"), (C_RIGHT, R_SPH, "mirror")]
    center = 0.5 * (C_LEFT + C_RIGHT)
    for S in (np.array([0.25, -0.3, 0.55]), np.array([-0.3, 0.2, 0.5])):
        img = render(SHAPE, spheres, light_pos=S, light_size=0.01, K=K, noise=0.003, ss=3)
        est = estimate_photo(img, samples, center, model="near", mirrors=views)
        assert est.ok and est.model == "near" and est.used_spheres == [0, 1]
        assert [sp.kind for sp in est.spheres] == ["mirror", "mirror"]
        assert np.linalg.norm(est.position - S) < 0.02, est.position
        assert np.degrees(angle_between(est.direction, normalize(S - center))) < 0.5
        # a distant model cannot explain it: auto picks the near light
        assert estimate_photo(img, samples, center, model="auto", mirrors=views).model == "near"


def test_mixed_matte_and_mirror_combined_by_uncertainty():
    K, samples, views = _pipeline_spheres(["matte", "mirror"])
    spheres = [(C_LEFT, R_SPH, "matte"), (C_RIGHT, R_SPH, "mirror")]
    for k, l in enumerate(random_lights(4, seed=23, max_deg=50)):
        img = render(SHAPE, spheres, light=l, K=K, noise=0.003, seed=k, ss=2)
        est = estimate_photo(img, samples, np.zeros(3), model="distant", mirrors=[None, views[1]])
        assert est.ok and est.used_spheres == [0, 1]
        matte, mirror = est.spheres
        assert (matte.kind, mirror.kind) == ("matte", "mirror")
        rep = est.record()["spheres"]
        assert rep[1]["kind"] == "mirror" and rep[1]["highlight_px"] is not None and rep[0]["kind"] == "matte"
        # the mirror is far more certain than the matte sphere (its 1 deg floor): the mean sits near it
        assert sphere_uncertainty_deg(mirror.fit, 1.0) < 0.5 < sphere_uncertainty_deg(matte.fit, 1.0)
        assert np.degrees(angle_between(est.direction, l)) < 0.4
        assert angle_between(est.direction, mirror.direction) < angle_between(est.direction, matte.direction)


def test_capture_auto_classifies_and_rejects_all_saturated(tmp_path):
    K, samples, views = _pipeline_spheres(["matte", "mirror"])
    spheres = [(C_LEFT, R_SPH, "matte"), (C_RIGHT, R_SPH, "mirror")]
    lights = random_lights(5, seed=29, max_deg=50)
    values = [sphere_values(render(SHAPE, spheres, light=l, K=K, noise=0.002, seed=k, ss=2), samples)
              for k, l in enumerate(lights)]
    est = estimate_photos(values, samples, np.zeros(3), materials=["auto", "auto"], views=views, model="distant",
                          refine_centres=False)
    assert [k.kind for k in est.kinds] == ["matte", "mirror"]
    assert all(k.source == "classified" for k in est.kinds)
    for p, l in zip(est.photos, lights):
        assert p.ok and [s.kind for s in p.spheres] == ["matte", "mirror"]
        assert np.degrees(angle_between(p.direction, l)) < 0.5
    rec = est.records()[0]["spheres"][1]
    assert rec["kind_source"] == "classified" and rec["compactness"] < MIRROR_COMPACTNESS
    # an exposure so high that every highlight is a large clipped disc: one error naming the capture
    big = [sphere_values(np.minimum(render(SHAPE, spheres, light=l, K=K, light_radius_deg=30.0, ss=1), 0.01),
                         samples) for l in lights]
    with pytest.raises(InputError, match="saturated in every photo"):
        estimate_photos(big, samples, np.zeros(3), materials=["matte", "mirror"], views=views,
                        refine_centres=False, model="distant")


def test_estimate_lights_on_a_mirror_capture(tmp_path):
    """``ffls lights`` end to end: 16-bit linear PNGs of two chrome balls, pixel hints, the kind
    classified (``"auto"``), sphere centres from detection, directions in the world frame."""
    from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA
    from ffls.spheres.estimate import estimate_lights

    K = _K(SHAPE[1], SHAPE[0])
    spheres = [(C_LEFT, R_SPH, "mirror"), (C_RIGHT, R_SPH, "mirror")]
    lights = random_lights(3, seed=31, max_deg=55)
    names = []
    for k, l in enumerate(lights):
        img = np.clip(render(SHAPE, spheres, light=l, K=K, noise=0.002, seed=k, ss=2, env=0.3), 0.0, 1.0)
        cv2.imwrite(str(tmp_path / f"img{k}.png"), np.repeat((img * 65535).astype(np.uint16)[..., None], 3, 2))
        names.append(f"img{k}.png")
    doc = {"format": "ffls-capture", "version": 1, "images": names, "encoding": "linear",
           "camera": {"K": K.tolist()}, "sphere_radius": R_SPH,
           "spheres": [{"center_px": (K @ (C / C[2]))[:2].tolist(), "radius_px": 60.0} for C in (C_LEFT, C_RIGHT)]}
    (tmp_path / "capture.json").write_text(json.dumps(doc))
    out = estimate_lights(load_capture(tmp_path), progress=False, workers=1)
    truth = lights @ DEFAULT_WORLD_FROM_CAMERA[:3, :3].T
    assert out.status == ["ok"] * 3
    for d, t, extra in zip(out.directions, truth, out.extra):
        assert np.degrees(angle_between(d, t)) < 0.5
        assert [(s["kind"], s["kind_source"]) for s in extra["spheres"]] == [("mirror", "classified")] * 2


# ----------------------------------------------------------------------------- measurement (docs/spheres.md)
def measure(n: int = 40) -> list[dict]:
    """Accuracy and 95 % cone coverage of the highlight fit on this module's renders (60 px radius).

    ``python tests/test_highlight.py`` prints the table of ``docs/spheres.md``."""
    K, s, view = _disc_view()
    disc = np.zeros((160, 160), bool)
    disc[s.rows, s.cols] = True
    ortho = SphereView(center_px=np.array([80.0, 80.0]), radius_px=60.0, model="orthographic", center_sigma_px=0.05)
    conditions = [
        ("perspective, 1.5 deg light, unclipped", dict(light_radius_deg=1.5), None, view, None),
        ("perspective, 3 deg light, clipped at 30 %", dict(light_radius_deg=3.0, clip=0.3), 0.3, view, None),
        ("perspective, 1.5 deg light, clipped at 30 %", dict(light_radius_deg=1.5, clip=0.3), 0.3, view, None),
        ("orthographic, 1.5 deg light", dict(light_radius_deg=1.5, ortho=(R_SPH / 60.0, 80.0, 80.0)), None, ortho,
         None),
        ("black glossy ball, 2 deg light", dict(light_radius_deg=2.0, power=10.0), None, view, "glossy"),
    ]
    rows = []
    for name, kw, clip, v, kind in conditions:
        errs, cones, stat, ok = [], [], [], 0
        v0 = SphereView(v.center_px, v.radius_px, v.model, v.K, v.dist, v.center_cam, v.radius, center_sigma_px=0.0)
        for k, l in enumerate(random_lights(n, seed=101)):
            kw2 = dict(kw)
            if "ortho" not in kw2:
                kw2["K"] = K
            img = render((160, 160), [((0, 0, 1.0), R_SPH, kind or "mirror")], light=l, noise=0.005, seed=k, ss=5,
                         **kw2)
            sat = None if clip is None else img >= clip * (1 - 1e-9)
            fit = fit_highlight(v, img, disc, sat)
            if fit.status != "ok":
                continue
            ok += 1
            errs.append(float(np.degrees(angle_between(fit.direction, l))))
            cones.append(fit.cone95_deg)
            stat.append(fit_highlight(v0, img, disc, sat, floor_deg=0.0).cone95_deg)  # without the floors
        e, c = np.array(errs), np.array(cones)
        rows.append(dict(condition=name, accepted=f"{ok}/{n}", median=float(np.median(e)), max=float(e.max()),
                         cone95_median=float(np.median(c)), coverage=float(np.mean(e <= c)),
                         coverage_stat=float(np.mean(e <= np.array(stat)))))
    # a near light (3 cm sphere light, 45-70 cm away) from two mirror spheres' rays
    _, samples, views = _pipeline_spheres(["mirror", "mirror"])
    K2 = _K(SHAPE[1], SHAPE[0])
    rng = np.random.default_rng(103)
    center = 0.5 * (C_LEFT + C_RIGHT)
    errs, cones, pos, ok = [], [], [], 0
    m = max(n // 4, 5)
    for k in range(m):
        d = random_lights(1, seed=200 + k, max_deg=60)[0]
        S = center + rng.uniform(0.45, 0.7) * d
        img = render(SHAPE, [(C_LEFT, R_SPH, "mirror"), (C_RIGHT, R_SPH, "mirror")], light_pos=S, light_size=0.015,
                     K=K2, noise=0.005, seed=k, ss=3)
        est = estimate_photo(img, samples, center, model="near", mirrors=views)
        if not est.ok:
            continue
        ok += 1
        errs.append(float(np.degrees(angle_between(est.direction, normalize(S - center)))))
        cones.append(CONE95_PER_RMS * est.uncertainty_deg)
        pos.append(float(np.linalg.norm(est.position - S) / np.linalg.norm(S - center)))
    e, c = np.array(errs), np.array(cones)
    rows.append(dict(condition=f"near light from 2 mirror spheres (position error median {100 * np.median(pos):.1f} % "
                               f"of the distance)", accepted=f"{ok}/{m}", median=float(np.median(e)),
                     max=float(e.max()), cone95_median=float(np.median(c)), coverage=float(np.mean(e <= c)),
                     coverage_stat=float("nan")))
    return rows


if __name__ == "__main__":
    print("| condition | accepted | median err (deg) | max err (deg) | median 95% cone (deg) | coverage | "
          "coverage without floors |")
    print("|---|---|---|---|---|---|---|")
    for r in measure():
        print(f"| {r['condition']} | {r['accepted']} | {r['median']:.3f} | {r['max']:.3f} | {r['cone95_median']:.3f} "
              f"| {100 * r['coverage']:.0f} % | "
              + ("–" if np.isnan(r["coverage_stat"]) else f"{100 * r['coverage_stat']:.0f} %") + " |")


def test_highlight_near_rim_kept_with_a_wider_cone():
    """A small chrome ball (23 px) lit from 110-125 deg off the view, its highlight blurred as by a
    lens or JPEG (sigma 0.8 px) so that its signal reaches the rim: the blob touches the edge
    (``rim_px`` <= 1.5, the old rejection), but its centre and core lie 2+ px inside, so the
    direction is determined. Kept (``near_rim``), every error within its (wider) 95 % cone."""
    K, s, view = _disc_view((72, 72), R=0.023)
    view = replace(view, center_sigma_px=0.5)
    for deg in (110.0, 115.0, 120.0, 125.0):
        for ph in (0.3, 2.0):
            th = np.radians(deg)
            l = np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), -np.cos(th)])
            img = render((72, 72), [((0, 0, 1.0), 0.023, "mirror")], light=l, light_radius_deg=1.5, K=K,
                         noise=0.002, seed=1)
            fit = _fit_image(cv2.GaussianBlur(img, (0, 0), 0.8), s, view)
            assert fit.rim_px <= 1.5 and fit.status == "ok" and fit.near_rim, (deg, ph, fit.status)
            assert np.degrees(angle_between(fit.direction, l)) <= fit.cone95_deg, (deg, ph)


def test_near_rim_highlight_only_where_no_other_sphere_is_usable():
    """A near-rim highlight (wide cone) is set aside beside a usable sphere (it would enter the
    capture's disagreement model), and used where it is the photo's only direction."""
    from ffls.spheres.photo import usable_spheres
    good = HighlightFit(status="ok", direction=np.array([0.0, 0.0, 1.0]), uncertainty_deg=0.1)
    rim = HighlightFit(status="ok", direction=np.array([0.0, 1.0, 0.0]), uncertainty_deg=12.0, near_rim=True)
    assert usable_spheres([good, rim]) == (["ok", "highlight_at_rim"], [0])
    assert usable_spheres([rim, HighlightFit(status="no_highlight")]) == (["ok", "no_highlight"], [0])
