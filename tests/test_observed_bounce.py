"""The ground bounce from the photograph itself (:mod:`ffls.spheres.ground`, ``bounce='observed'``).

A matte ball resting on a ground that an object's cast shadow darkens beside it is rendered
here: every ground pixel has its radiance (the dark part, and the ball's own shadow), and every
ball pixel its direct light plus the bounce integrated from its own surface point over the
ground (cosine-weighted rays to the ground, each one's radiance there), independently of the
module's centre-based quadrature.
"""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from ffls.conventions import angle_between, spherical_to_direction
from ffls.spheres.ground import ground_radiance, ground_views, observed_bounce
from ffls.spheres.lambert import fit_lambert, shadowed_ground_bounce
from ffls.spheres.samples import sphere_samples, sphere_values

RES, FOCAL = 224, 700.0
R = 0.05
CENTER = np.array([0.0, 0.0, R])  # resting on z = 0
RHO_S, RHO_G = 0.8, 0.3
#: The object's cast shadow beside the ball: the ground within these x and |y| (world) is this dark.
SHADOW_X, SHADOW_Y, SHADOW_LEVEL = (1.5 * R, 4.0 * R), 3.0 * R, 0.15
#: A farther cast shadow beside the ball: 4.5 to 7.5 radii along x, |y| < 3 radii.
FAR_SHADOW_X, FAR_SHADOW_Y = (4.5 * R, 7.5 * R), 3.0 * R
LIGHTS = [spherical_to_direction(np.radians(th), np.radians(ph)) for th in (30, 50) for ph in range(-150, 180, 60)]


def _camera(res=RES, focal=FOCAL):
    """A camera 1 m away, 30 degrees above the ground, looking at the ball (world +Z up)."""
    el = np.radians(30.0)
    eye = CENTER + np.array([0.0, -np.cos(el), np.sin(el)])
    z = CENTER - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    M = np.eye(4)
    M[:3, :3] = np.stack([x, y, z], axis=1)
    M[:3, 3] = eye
    K = np.array([[focal, 0, (res - 1) / 2], [0, focal, (res - 1) / 2], [0, 0, 1.0]])
    return K, M


def _ground_radiance(X, light, dark_side=True, far_shadow=False):
    """The ground's radiance at points X (n, 3) under a distant light: rho_g / pi * l_z, darker
    in the object's shadow (SHADOW_X, SHADOW_Y; ``far_shadow``: FAR_SHADOW_X, FAR_SHADOW_Y), zero
    in the ball's own shadow."""
    L = np.full(len(X), RHO_G / np.pi * max(light[2], 0.0))
    if dark_side:
        L[(X[:, 0] > SHADOW_X[0]) & (X[:, 0] < SHADOW_X[1]) & (np.abs(X[:, 1]) < SHADOW_Y)] *= SHADOW_LEVEL
    if far_shadow:
        L[(X[:, 0] > FAR_SHADOW_X[0]) & (X[:, 0] < FAR_SHADOW_X[1]) & (np.abs(X[:, 1]) < FAR_SHADOW_Y)] *= SHADOW_LEVEL
    P = X - CENTER
    tc = -(P @ light)
    L[(tc > 0) & (np.einsum("ij,ij->i", P, P) - tc * tc < R * R)] = 0.0
    return L


#: An object standing beside the ball, as the camera sees it over the ground: the pixels whose ground
#: point lies within these x and |y| show its surface, normals turning about the vertical (a column).
OBJECT_X, OBJECT_Y, RHO_O = (1.8 * R, 3.2 * R), 1.2 * R, 0.5


def _object_radiance(X, light):
    """The object's radiance where the camera sees it at ground points X (n, 3): its own normals'
    shading (Lambertian, ``RHO_O``), not the ground's."""
    a = np.pi * (X[:, 1] / OBJECT_Y) * 0.8
    n = np.stack([-np.cos(a), np.sin(a), np.full(len(X), 0.3)], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return RHO_O / np.pi * np.maximum(n @ light, 0.0)


def _in_object(X):
    return (X[:, 0] > OBJECT_X[0]) & (X[:, 0] < OBJECT_X[1]) & (np.abs(X[:, 1]) < OBJECT_Y)


def _render(light, samples, K, M, dark_side=True, n_rays=24, seen_object=False, far_shadow=False, res=RES):
    """The photo (RES, RES) float: ground pixels, and the ball's pixels (direct + bounce).
    ``seen_object``: the object of :func:`_object_radiance` stands in front of part of the ground
    (in the image only: the ball's bounce is the ground's)."""
    img = np.zeros((res, res))
    yy, xx = np.mgrid[0:res, 0:res]
    d = np.stack([(xx.ravel() - K[0, 2]) / K[0, 0], (yy.ravel() - K[1, 2]) / K[1, 1], np.ones(res * res)], axis=1)
    d = d @ M[:3, :3].T
    o = M[:3, 3]
    t = -o[2] / d[:, 2]
    X = o + d * t[:, None]
    ok = t > 0
    img.ravel()[ok] = _ground_radiance(X[ok], light, dark_side, far_shadow)
    if seen_object:
        on = np.flatnonzero(ok)[_in_object(X[ok])]
        img.ravel()[on] = _object_radiance(X[on], light)
    # the ball: direct light and, from each surface point, the bounce of the ground below
    n = samples.normals
    u = (np.arange(n_rays) + 0.5) / n_rays
    u1, u2 = (a.ravel() for a in np.meshgrid(u, u))
    r, ph = np.sqrt(u1), 2 * np.pi * u2
    local = np.stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(1 - u1)], axis=1)  # cosine-weighted
    bounce = np.zeros(len(n))
    for i, (ni, p) in enumerate(zip(n, samples.points)):
        a = np.array([1.0, 0, 0]) if abs(ni[0]) < 0.9 else np.array([0, 1.0, 0])
        t1 = np.cross(ni, a)
        t1 /= np.linalg.norm(t1)
        w = local @ np.stack([t1, np.cross(ni, t1), ni])
        w = w[w[:, 2] < -1e-9]
        G = p + w * (-p[2] / w[:, 2])[:, None]
        bounce[i] = _ground_radiance(G, light, dark_side, far_shadow).sum() / len(local)  # (1/pi) int L cos
    img[samples.rows, samples.cols] = RHO_S / np.pi * np.maximum(n @ light, 0.0) + RHO_S * bounce
    return img


@pytest.fixture(scope="module")
def rig():
    K, M = _camera()
    C_cam = (CENTER - M[:3, 3]) @ M[:3, :3]
    s = sphere_samples((RES, RES), K, None, C_cam, R, M)
    view = ground_views([s], (RES, RES), "pinhole", K, None, M)[0]
    from dataclasses import replace

    return replace(s, ground_view=view), K, M


_PHOTOS = {}


def _photo_values(rig, light_index, dark_side, seen_object=False):
    """The ball's values in the photo under ``LIGHTS[light_index]`` (rendered once per module)."""
    key = (light_index, dark_side, seen_object)
    if key not in _PHOTOS:
        s, K, M = rig
        _PHOTOS[key] = sphere_values(_render(LIGHTS[light_index], s, K, M, dark_side, seen_object=seen_object)[..., None],
                                     [s])
    return _PHOTOS[key]


def _errors(rig, dark_side, seen_object=False, values=None):
    s, K, M = rig
    out = {"uniform": [], "observed": []}
    for i, light in enumerate(LIGHTS):
        v = _photo_values(rig, i, dark_side, seen_object)[0] if values is None else values[i][0]
        assert v.ground is not None and v.ground.size == s.ground_view.n_seen
        kw = dict(bounce_ratio=RHO_G, g=s.ground)
        fu = fit_lambert(s.normals, v.grey, v.valid, **kw)
        fo = fit_lambert(s.normals, v.grey, v.valid, ground=(s.ground_view, v.ground), **kw)
        out["uniform"].append(np.degrees(angle_between(fu.direction, light)))
        out["observed"].append(np.degrees(angle_between(fo.direction, light)))
    return {k: np.asarray(e) for k, e in out.items()}


def test_observed_bounce_removes_the_bias_of_a_shadowed_ground(rig):
    e = _errors(rig, dark_side=True)
    # the uniform ground's bounce on a ball whose ground is dark on one side tilts the light
    assert np.median(e["uniform"]) > 0.3, e
    assert np.median(e["observed"]) < 0.4 * np.median(e["uniform"]), e
    assert e["observed"].max() < 0.6 * e["uniform"].max(), e


def test_estimate_photos_with_the_observed_bounce(rig):
    """The library's two passes (``bounce='observed'``): the ground ratio calibrated over the
    photos with the observed form factor, then imposed; the photos' lights lose the bias."""
    from ffls.spheres.estimate import estimate_photos

    from dataclasses import replace

    s = rig[0]
    values = [_photo_values(rig, i, True) for i in range(len(LIGHTS))]
    kw = dict(refine_centres=False, first_pass=None, bounce_shape=False)
    med = {}
    # (the samples' ground view is what makes the fits read the ground: without it, the uniform)
    for bounce, sm in (("calibrated", replace(s, ground_view=None)), ("observed", s)):
        est = estimate_photos(values, [sm], CENTER, bounce=bounce, **kw)
        med[bounce] = np.median([np.degrees(angle_between(r.direction, d)) for r, d in zip(est.photos, LIGHTS)
                                 if r.status == "ok"])
    assert med["observed"] < 0.4 * med["calibrated"], med
    with pytest.raises(ValueError, match="ground_view"):
        estimate_photos(values, [replace(s, ground_view=None)], CENTER, bounce="observed", **kw)


def test_a_uniform_ground_gives_the_uniform_form_factor(rig):
    s, K, M = rig
    light = LIGHTS[3]
    img = _render(light, s, K, M, dark_side=False, n_rays=2)
    v = sphere_values(img[..., None], [s])[0]
    uniform = shadowed_ground_bounce(s.normals, light, g=s.ground)
    B = observed_bounce(s.ground_view, v.ground, light, uniform, s.normals)
    # the seen ground's own shadow is the centre's view of it, the uniform one the points' (their
    # difference is where the photo adds to the model): small next to the form factor's range
    assert np.max(np.abs(B - uniform)) < 0.03
    e = _errors(rig, dark_side=False)
    assert np.median(e["observed"]) < 0.1 and np.median(e["uniform"]) < 0.1, e


def test_the_ground_view_reads_only_ground(rig):
    s, K, M = rig
    view = s.ground_view
    # no read pixel falls on the ball (or its outline's margin)
    ball = np.zeros((RES, RES), bool)
    ball[s.rows, s.cols] = True
    assert not ball[view.rows, view.cols].any()
    assert 0.3 * 1024 < view.n_seen < 1024  # behind the ball and beyond reach are not read
    # the hidden points filled from their seen neighbours are in the frame (behind the ball): the
    # ground out of the frame is the uniform model's (filled from the frame's edge, a cast shadow
    # by the edge would spread out to the reach)
    X = CENTER + R * view.offsets[view.n_seen:]
    Xc = (X - M[:3, 3]) @ M[:3, :3]
    px = Xc[:, :2] / Xc[:, 2:] * FOCAL + K[0, 2]
    assert len(X) > 0 and np.all((px >= 0) & (px <= RES - 1)), px


def test_observed_needs_a_world_frame(tmp_path, capsys):
    """``ffls lights --bounce observed`` without camera.world_from_camera, or without ``--model
    distant``: one line, exit 2."""
    from ffls.cli import main

    cap = tmp_path / "cap"
    cap.mkdir()
    import cv2

    for i in range(3):
        cv2.imwrite(str(cap / f"img_{i}.png"), np.zeros((32, 32, 3), np.uint8))
    (cap / "capture.json").write_text(json.dumps({"format": "ffls-capture", "version": 1, "encoding": "srgb",
                                                  "images": [f"img_{i}.png" for i in range(3)]}))
    rc = main(["lights", str(cap), "--bounce", "observed", "--model", "distant"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--bounce observed needs camera.world_from_camera" in err[0], err
    doc = json.loads((cap / "capture.json").read_text())
    doc["camera"] = {"world_from_camera": np.eye(4).tolist()}
    (cap / "capture.json").write_text(json.dumps(doc))
    rc = main(["lights", str(cap), "--bounce", "observed"])  # (--model auto: a near light's fit)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--bounce observed needs --model distant" in err[0], err


def test_two_terms_seen_bounce_and_hidden_form_factor(rig):
    """The bounce split in two (docs/spheres.md, "Two terms"): the seen ground's, in the photo's
    units, times the ball's albedo, plus the hidden ground's form factor at the ground ratio. On a
    uniform ground the two add up to the uniform model; on the shadowed ground, with the ball's
    albedo and the ground's ratio, the fits lose the uniform model's bias."""
    from ffls.spheres.ground import ground_radiance, hidden_form_factor, seen_bounce

    s, K, M = rig
    light = LIGHTS[3]
    img = _render(light, s, K, M, dark_side=False, n_rays=2)
    L = ground_radiance(s.ground_view, img[..., None])
    uniform = shadowed_ground_bounce(s.normals, light, g=s.ground)
    ref = RHO_G / np.pi * light[2]  # the lit ground's radiance
    total = seen_bounce(s.ground_view, L, s.normals) / ref + hidden_form_factor(s.ground_view, light, uniform,
                                                                              s.normals)
    assert np.percentile(np.abs(total - uniform), 99) < 0.03
    errors = []
    for i, light in enumerate(LIGHTS):
        v = _photo_values(rig, i, True)[0]
        bs = seen_bounce(s.ground_view, v.ground, s.normals)
        hid = hidden_form_factor(s.ground_view, light, shadowed_ground_bounce(s.normals, light, g=s.ground),
                                 s.normals)
        f = fit_lambert(s.normals, v.grey - RHO_S * bs, v.valid, g=hid, bounce_ratio=RHO_G, own_shadow=False)
        errors.append(np.degrees(angle_between(f.direction, light)))
    assert np.median(errors) < 0.15 and max(errors) < 0.25, errors  # (uniform model: 0.53 / 0.99)


def test_a_far_cast_shadow_is_read_within_reach():
    """A cast shadow 4.5 to 7.5 radii beside the ball (another object's; a wider lens, 9 radii
    each side of the ball, sees it): with
    the ground read out to GROUND_REACH (8 radii) the seen term measures it; read out to 4 radii
    (the earlier reach) it is the hidden ground's uniform model, and the two terms' fits at the
    true albedo and ground ratio keep its bias (docs/spheres.md, "The hidden ratio's bias")."""
    from dataclasses import replace

    from ffls.spheres.ground import GROUND_REACH, ground_radiance, hidden_form_factor, seen_bounce

    res = 320
    K, M = _camera(res, 350.0)
    s = sphere_samples((res, res), K, None, (CENTER - M[:3, 3]) @ M[:3, :3], R, M)
    assert GROUND_REACH >= FAR_SHADOW_X[1] / R
    views = {"reach 4": ground_views([s], (res, res), "pinhole", K, None, M, reach=4.0)[0],
             "reach": ground_views([s], (res, res), "pinhole", K, None, M)[0]}
    s = replace(s, ground_view=views["reach"])
    errors = {k: [] for k in views}
    for light in LIGHTS:
        img = _render(light, s, K, M, dark_side=False, far_shadow=True, res=res)
        v = sphere_values(img[..., None], [s])[0]
        for k, view in views.items():
            L = ground_radiance(view, img[..., None])
            hid = hidden_form_factor(view, light, shadowed_ground_bounce(s.normals, light, g=s.ground), s.normals)
            f = fit_lambert(s.normals, v.grey - RHO_S * seen_bounce(view, L, s.normals), v.valid, g=hid,
                            bounce_ratio=RHO_G, own_shadow=False)
            errors[k].append(np.degrees(angle_between(f.direction, light)))
    med = {k: float(np.median(e)) for k, e in errors.items()}
    assert med["reach"] < 0.5 * med["reach 4"], med


def test_not_ground_flags_what_is_not_shaded_as_the_plane():
    """A textured, vignetted ground under 20 distant lights, each point in a cast shadow in up to
    40% of the photos and in the sphere's own shadow in some, with 2% noise: no ground point is
    flagged; the points of a surface turning about the vertical (an object) are."""
    from ffls.spheres.ground import not_ground

    rng = np.random.default_rng(3)
    n, p, q = 20, 300, 40
    lights = np.stack([spherical_to_direction(np.radians(th), np.radians(ph))
                       for th, ph in zip(rng.uniform(10, 60, n), rng.uniform(-180, 180, n))])
    albedo = rng.uniform(0.05, 0.9, p) * rng.uniform(0.6, 1.0, p)  # texture times vignetting
    R = albedo[None, :] * lights[:, 2:3] * rng.uniform(0.2, 1.0, n)[:, None]  # the lamps' powers
    R[rng.uniform(size=(n, p)) < rng.uniform(0.0, 0.4, p)] *= 0.1  # cast shadows
    a = rng.uniform(-np.pi, np.pi, q)
    normals = np.stack([np.cos(a), np.sin(a), rng.uniform(0.0, 0.6, q)], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    R[:, -q:] = rng.uniform(0.2, 0.9, q) * np.maximum(lights @ normals.T, 0.0) * rng.uniform(0.2, 1.0, n)[:, None]
    R *= rng.normal(1.0, 0.02, R.shape)
    lit = rng.uniform(size=(n, p)) > 0.2
    flagged = not_ground(R, lit)
    assert not flagged[:-q].any()
    assert flagged[-q:].mean() > 0.9, flagged[-q:].mean()
    assert not not_ground(R[:2], lit[:2]).any()  # too few photos: nothing is flagged


def test_the_object_seen_over_the_ground_is_masked(rig):
    """An object seen in front of the ball's ground (its own shading) is read as ground without the
    mask, which tilts the observed bounce's fits; ``mask_object_from_ground`` takes it out (its
    points then taken as their seen neighbours') and the fits are back to the plain ground's."""
    from ffls.spheres.estimate import mask_object_from_ground

    s, K, M = rig
    values = [_photo_values(rig, i, False, seen_object=True) for i in range(len(LIGHTS))]
    (masked_s,), masked_values, counts = mask_object_from_ground([s], values, list(enumerate(LIGHTS)))
    gv = s.ground_view
    X = gv.offsets[:gv.n_seen] * R + CENTER
    obj = _in_object(X)
    assert counts[0] >= 0.75 * obj.sum() and counts[0] <= obj.sum() + 0.05 * gv.n_seen, (counts, obj.sum())
    # the masked view reads, in a photo, what the values were cut to
    img = _render(LIGHTS[0], s, K, M, False, n_rays=2, seen_object=True)
    np.testing.assert_allclose(ground_radiance(masked_s.ground_view, img), masked_values[0][0].ground, rtol=1e-5)
    plain = _errors(rig, False)["observed"]
    seen = _errors(rig, False, seen_object=True)["observed"]
    fixed = _errors((masked_s, K, M), False, values=masked_values)["observed"]
    assert np.median(seen) > 2.0 * np.median(plain) + 0.05, (seen, plain)
    assert np.median(fixed) < 0.7 * np.median(seen) and fixed.max() < 0.8 * seen.max(), (fixed, seen, plain)
    # nothing to mask on the plain ground
    assert mask_object_from_ground([s], [_photo_values(rig, i, False) for i in range(len(LIGHTS))],
                                   list(enumerate(LIGHTS)))[2] == [0]


def test_grounded_values_survive_pickling_to_the_workers():
    """``GroundedValues`` go to the ``--workers`` processes by pickle: the triple and its ground come
    back (``ffls lights --bounce observed --workers 2`` failed with BrokenProcessPool: ``__new__``
    missing ``ground``)."""
    import pickle

    from ffls.spheres.samples import GroundedValues

    v = GroundedValues(np.arange(3.0), np.ones(3, bool), 2, {"radiance": np.arange(4.0)})
    w = pickle.loads(pickle.dumps(v))
    assert type(w) is GroundedValues and w.n_saturated == 2 and tuple(map(len, w[:2])) == (3, 3)
    assert np.array_equal(w.ground["radiance"], np.arange(4.0)) and np.array_equal(w.grey, v.grey)


def test_mask_object_from_ground_builds_one_neighbour_fill_per_sphere(rig, monkeypatch):
    """The masked view and every photo's cut ground values share one neighbour fill per sphere
    (one k-d tree of the kept points, not one more per photo), with the same values as a fill
    made afresh for each."""
    from dataclasses import replace

    import ffls.spheres.ground as gr
    from ffls.spheres.estimate import mask_object_from_ground

    s, K, M = rig
    s = replace(s, ground_view=replace(s.ground_view, _fills={}))  # (no fill kept from another test)
    values = [_photo_values(rig, i, False, seen_object=True) for i in range(len(LIGHTS))]
    trees = []

    class CountingTree(gr.cKDTree):
        def __init__(self, *args, **kwargs):
            trees.append(1)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(gr, "cKDTree", CountingTree)
    (masked_s,), masked_values, counts = mask_object_from_ground([s], values, list(enumerate(LIGHTS)))
    assert counts[0] > 0 and len(trees) == 1, (counts, len(trees))
    gv = s.ground_view
    keep = ~gr.not_ground(np.stack([v[0].ground for v in values]),
                          np.stack([~gr.own_shadow_mask(gv, light)[:gv.n_seen] for light in LIGHTS]))
    assert int((~keep).sum()) == counts[0]
    monkeypatch.undo()
    for v, mv in zip(values, masked_values):
        fresh = replace(gv, _fills={})
        assert np.array_equal(gr.mask_radiance(fresh, keep, v[0].ground), mv[0].ground)


def test_ground_kernel_widened_once_and_the_same_floats(rig):
    """``GroundView.kernel64`` is the float32 kernel widened, made once per normals array: the
    observed bounce and the seen ground's bounce read it instead of widening the kernel at every
    fit, with the same floats as the float32 kernel promoted in the product."""
    from dataclasses import replace

    from ffls.spheres.ground import hidden_form_factor, own_shadow_mask, seen_bounce

    s, K, M = rig
    view = replace(s.ground_view, _kernels={})
    n = s.normals
    K64 = view.kernel64(n)
    assert K64.dtype == np.float64 and view.kernel64(n) is K64
    assert np.array_equal(K64, view.kernel(n).astype(np.float64))
    light = LIGHTS[3]
    img = _render(light, s, K, M, True, n_rays=2)
    L = ground_radiance(view, img)
    g_l = shadowed_ground_bounce(n, light)
    lit = ~own_shadow_mask(view, light)
    ref = float(np.median(L[lit[:view.n_seen]]))
    q = L / ref
    w = view.fill_weights * lit[:view.n_seen][view.fill_index]
    near = (w * q[view.fill_index]).sum(axis=1) / np.where(w.sum(axis=1) > 0, w.sum(axis=1), 1.0)
    dev = np.concatenate([q - lit[:view.n_seen], lit[view.n_seen:] * (near - 1.0)])
    want = np.maximum(g_l + view.kernel(n) @ dev, 0.0)  # (float32 kernel promoted in the product)
    assert observed_bounce(view, L, light, g_l, n).tobytes() == want.tobytes()
    want = view.kernel(n)[:, :view.n_seen].astype(np.float64) @ L
    assert seen_bounce(view, L, n).tobytes() == want.tobytes()
    want = np.maximum(g_l - view.kernel(n)[:, :view.n_seen] @ lit[:view.n_seen], 0.0)  # (float32 product)
    assert hidden_form_factor(view, light, g_l, n).tobytes() == want.tobytes()


def test_workers_build_the_ground_kernel_once_per_pass(rig, tmp_path, monkeypatch):
    """``--workers 2``: a sphere's ground kernel is built once per worker process, not once per fit
    (a worker's unpickled normals came to each fit as a new view, missing the kernel kept per
    array) nor once per chunk of photos (each chunk re-sent the samples): ``ffls lights --bounce
    observed --workers 2`` took 6.6x the CPU of ``--workers 1``. The estimates are those of
    ``--workers 1``, to the bit."""
    from dataclasses import replace

    import ffls.spheres.ground as gr
    from ffls.spheres.estimate import PhotoFitter, PhotoTask

    s = replace(rig[0], ground_view=replace(rig[0].ground_view, _kernels={}))
    values = [_photo_values(rig, i, True) for i in range(len(LIGHTS))]
    log = tmp_path / "builds.txt"
    kernel = gr.GroundView.kernel

    def counted(self, normals):  # (a build: the view keeps one more kernel; the workers inherit it)
        before = len(self._kernels)
        out = kernel(self, normals)
        if len(self._kernels) > before:
            with open(log, "a") as f:
                f.write(f"{os.getpid()}\n")
        return out

    monkeypatch.setattr(gr.GroundView, "kernel", counted)
    tasks = [PhotoTask(i, values=values[i], bounce_ratio=[RHO_G]) for i in range(len(LIGHTS))]
    out = {}
    for workers in (1, 2):
        log.write_text("")
        with PhotoFitter(None, CENTER, {}, workers=workers) as fitter:
            out[workers] = [r for r, _ in fitter.run(tasks, [s])]
            assert len(tasks) // (8 * workers) <= 1  # (one photo a chunk: a build per chunk before)
        assert 1 <= len(log.read_text().splitlines()) <= workers, (workers, log.read_text())
        s = replace(s, ground_view=replace(s.ground_view, _kernels={}))
    assert [r.direction.tobytes() for r in out[1]] == [r.direction.tobytes() for r in out[2]]
