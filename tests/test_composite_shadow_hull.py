"""The object's shadow hull (ffls.relight.shadow_hull): carved from its cast shadows, it gives the
object's shadow where a calibration sphere hides the ground from a light (SphereShadowFill.source_model)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.lightmaps.lightmap import LightMap
from ffls.relight.cpu import CpuRelighter
from ffls.relight.lightflow import LightFlowRelighter, unshadowed_fit
from ffls.relight.shadow_hull import MIN_SHADOWS, ShadowHull, lit_photos
from ffls.relight.sphere_shadows import SphereShadowFill, ground_points, hidden_photos
from ffls.synth.scene import stratified_directions

RES = 96
BOX = (np.array([-0.06, -0.04, 0.0]), np.array([0.06, 0.04, 0.16]))  # the object: a box on the ground
SPHERE = ((0.25, 0.0, 0.05), 0.05)                                      # a calibration sphere beside it


def _camera():
    """A camera 1 m up, 0.4 m to the -y side, looking at the origin (OpenCV axes), 60 degrees wide."""
    f = 0.5 * RES / math.tan(math.radians(30))
    K = np.array([[f, 0, 0.5 * (RES - 1)], [0, f, 0.5 * (RES - 1)], [0, 0, 1.0]])
    o = np.array([0.0, -0.4, 1.0])
    z = -o / np.linalg.norm(o)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = x, np.cross(z, x), z, o
    return K, M


def _hits_box(p, d):
    """(m,) bool: rays from points p (m, 3) along d (3,) or (m, 3) meet the box."""
    lo, hi = BOX
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - p) / d, (hi - p) / d
    tn = np.where(np.isnan(t0), -np.inf, np.minimum(t0, t1)).max(-1)
    tf = np.where(np.isnan(t1), np.inf, np.maximum(t0, t1)).min(-1)
    return (tf > np.maximum(tn, 1e-9))


def _scene(directions, spheres=(SPHERE,)):
    """Photos of a white Lambertian ground (n . d) with the box's and the spheres' hard shadows."""
    K, M = _camera()
    g = ground_points(K, M, (RES, RES))
    jj, ii = np.mgrid[0:RES, 0:RES].astype(np.float64)
    rays = np.stack([(ii - K[0, 2]) / K[0, 0], (jj - K[1, 2]) / K[1, 1], np.ones_like(ii)], -1) @ M[:3, :3].T
    cam = np.broadcast_to(M[:3, 3], rays.shape)
    obj = _hits_box(cam.reshape(-1, 3), rays.reshape(-1, 3)).reshape(RES, RES)
    sph = np.zeros_like(obj)
    for c, r in spheres:
        v = np.asarray(c) - cam
        along = np.einsum("hwi,hwi->hw", v, rays) / np.einsum("hwi,hwi->hw", rays, rays)
        sph |= np.linalg.norm(cam + along[..., None] * rays - c, axis=-1) < r
    ground = ~obj & ~sph
    pts = np.where(ground[..., None], g, np.nan)
    hid = hidden_photos(pts, [c for c, _ in spheres], spheres[0][1], directions=directions, dilate_px=0)
    basis = np.zeros((len(directions), RES, RES, 3))
    for i, d in enumerate(directions):
        lit = ~_hits_box(g.reshape(-1, 3), d).reshape(RES, RES) & ~hid[i]
        basis[i] = (max(d[2], 0.0) * lit * ground)[..., None]
    return K, M, obj, ground, pts, basis


def _one_texel_sun(sun):
    """A dim uniform lat-long map (1e-4) with one texel of 2e4 toward ``sun``."""
    lm = LightMap(np.full((64, 128, 3), 1e-4, np.float32), "latlong")
    dirs, _, _ = lm.samples()
    data = lm.data.reshape(-1, 3).copy()
    data[np.argmax(dirs @ sun)] = 2e4
    return replace(lm, data=data.reshape(lm.data.shape))


def test_unshadowed_fit_prior_leaves_out_photos_known_to_be_dark():
    """A photo with prior 0 does not pull the model, however many are dark (a sphere's cone)."""
    d = stratified_directions(60, "upper", 0)
    photos = np.broadcast_to(d[:, 2][:, None, None, None], (60, 1, 2, 3)).copy()
    dark = np.degrees(np.arccos(d[:, 2])) < 40
    photos[dark, :, 0] = 0.0
    prior = np.ones((60, 1, 2))
    prior[dark, :, 0] = 0.0
    b = unshadowed_fit(photos, d, prior=prior)
    np.testing.assert_allclose(b[0, 0, :, 2], 1.0, atol=1e-6)
    np.testing.assert_allclose(b[0, 1, :, 2], 1.0, atol=1e-6)
    with pytest.raises(ValueError):
        unshadowed_fit(photos, d, prior=-prior)


def test_carved_hull_casts_the_objects_shadow_for_a_new_light():
    d = stratified_directions(150, "upper", 3)
    d = d[d[:, 2] > math.sin(math.radians(12))]
    K, M, obj, ground, pts, basis = _scene(d)
    vis, known, umbra = lit_photos(basis, d, ground)
    assert known.any() and (vis[known] >= 0.5).mean() > 0.5 and umbra == 0.0 and np.all(vis[~known] == 0)
    hull = ShadowHull.carve(basis, d, obj, K, M, ground=ground)
    # a light the capture does not have, low (20 degrees), between capture lights
    e, a = math.radians(20), math.radians(37)
    new = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    g = pts.reshape(-1, 3)
    ok = ground.ravel()
    truth = _hits_box(np.nan_to_num(g), new) & ok
    got = (hull.shadow(g, new) > 0.5) & ok
    iou = (truth & got).sum() / (truth | got).sum()
    assert truth.sum() > 40 and iou > 0.8, (truth.sum(), got.sum(), iou)
    assert np.median(hull.visibility(g[truth & got], new)) < 0.05
    # nothing in the hull far from the box
    far = hull.shadow(np.array([[0.4, 0.4, 0.0]]), np.array([0.0, 0.0, 1.0]))
    assert far[0] == 0.0
    with pytest.raises(InputError):
        ShadowHull.carve(basis, d, np.zeros_like(obj), K, M)


def test_hull_keeps_no_unseen_space_beside_a_sphere_behind_the_object():
    """A sphere standing behind the box, in the camera's silhouette of it: the space beside the
    sphere casts its shadows onto ground the camera does not see or that the sphere shades, so no
    photo carves it. The strict hull (min_shadows=0) keeps it, and its shadow under a low light runs
    along the sphere's own shadow, where the fill relights the ground from the hull; the hull keeps
    only voxels whose shadow some photos show (MIN_SHADOWS), and loses none of the box's shadow."""
    d = stratified_directions(150, "upper", 3)
    d = d[d[:, 2] > math.sin(math.radians(12))]
    spheres = (SPHERE, ((0.0, 0.15, 0.05), 0.05))
    K, M, obj, ground, pts, basis = _scene(d, spheres)
    centres = [c for c, _ in spheres]
    hid = hidden_photos(pts, centres, 0.05, directions=d, dilate_px=0)
    fill = SphereShadowFill.from_geometry(pts, centres, 0.05, d, dilate_px=0)
    g = pts.reshape(-1, 3)
    counts = {}
    for ms in (0, MIN_SHADOWS):
        hull = ShadowHull.carve(basis, d, obj, K, M, ground=ground, hidden=hid, min_shadows=ms)
        extra = missed = 0
        for az in range(-180, 180, 30):  # low lights all around, 10 degrees up
            e, a = math.radians(10), math.radians(az)
            src = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
            box = _hits_box(np.nan_to_num(g), src).reshape(RES, RES) & ground
            got = (hull.shadow(g, src) > 0.5).reshape(RES, RES) & ground
            extra += int((got & ~box & fill.hidden_for(src)).sum())
            missed += int((box & ~got).sum())
        counts[ms] = extra, missed
    (strict_extra, strict_missed), (extra, missed) = counts[0], counts[MIN_SHADOWS]
    # measured: 326 extra pixels in the spheres' shadows and 365 missed with the strict hull, 126 and
    # 384 with MIN_SHADOWS = 2
    assert strict_extra > 200 and extra < 0.5 * strict_extra, counts
    assert missed <= 1.1 * strict_missed, counts


def test_source_model_puts_the_objects_shadow_inside_a_spheres_shadow():
    """A light the sphere hides from part of the box's shadow: both captures' photos are dark there;
    the model fill with the hull gives the object's shadow there and the lit ground around it."""
    d = stratified_directions(150, "upper", 3)
    d = d[d[:, 2] > math.sin(math.radians(12))]
    K, M, obj, ground, pts, basis = _scene(d)
    c, r = SPHERE
    hid = hidden_photos(pts, [c], r, directions=d, dilate_px=0)
    hull = ShadowHull.carve(basis, d, obj, K, M, ground=ground, hidden=hid)
    # the light from -x at 15 degrees: the box's shadow runs toward +x, through the sphere's
    e = math.radians(15)
    src = np.array([-math.cos(e), 0.0, math.sin(e)])
    here = hidden_photos(pts, [c], r, directions=src[None], dilate_px=0)[0]
    g = pts.reshape(-1, 3)
    box_shadow = _hits_box(np.nan_to_num(g), src).reshape(RES, RES) & ground
    both = here & box_shadow
    assert both.sum() >= 5 and (here & ~box_shadow).sum() >= 5
    fill = SphereShadowFill.from_geometry(pts, [c], r, d, dilate_px=0)
    dark = np.zeros((RES, RES, 3))
    truth = (src[2] * ~box_shadow)[..., None] * np.ones(3)
    with_hull = fill.source_model(dark, src, basis, hull=hull)
    without = fill.source_model(dark, src, basis)
    err = np.abs(with_hull - truth)[..., 0]
    assert err[both].mean() < 0.2 * src[2], err[both].mean()
    assert err[here & ~box_shadow].mean() < 0.05 * src[2]
    # without the hull the object's shadow there is lost (the surface-alone capture's fill)
    assert np.abs(without - truth)[..., 0][both].mean() > 0.9 * src[2]
    # pixels the sphere does not hide are the image as given
    assert np.array_equal(with_hull[~here], dark[~here])


def test_relighter_fills_a_hidden_sun_with_the_model_and_the_hull():
    """LightFlowRelighter(fill_sources='model'): where the sphere hides the sun, the object capture
    relit under a sun map shows the box's shadow (hull) and the lit ground; without the fill, the
    sphere's shadow."""
    d = stratified_directions(150, "upper", 3)
    d = d[d[:, 2] > math.sin(math.radians(12))]
    K, M, obj, ground, pts, basis = _scene(d)
    c, r = SPHERE
    hull = ShadowHull.carve(basis, d, obj, K, M, ground=ground, hidden=hidden_photos(pts, [c], r, directions=d))
    e = math.radians(15)
    sun = np.array([-math.cos(e), 0.0, math.sin(e)])
    lm = _one_texel_sun(sun)
    fill = SphereShadowFill.from_geometry(pts, [c], r, d)
    images = {}
    for mode, h in (("model", hull), (False, None)):
        rel = LightFlowRelighter(CpuRelighter(basis, d, weighting="barycentric"), fill=fill, fill_sources=mode,
                                 fill_rest=False, hull=h)
        rel.set_lightmap(lm)
        rel.render()
        images[mode] = rel.read_hdr()[..., 0]
        assert len(rel.last_split.sources) == 1
    sun = rel.last_split.sources[0].sample_directions[0]  # the texel's centre
    here = fill.hidden_for(sun)
    box_shadow = _hits_box(np.nan_to_num(pts.reshape(-1, 3)), sun).reshape(RES, RES) & ground
    lit_here, shade_here = here & ~box_shadow, here & box_shadow
    lit_far = ground & ~here & ~box_shadow
    assert lit_here.sum() >= 5 and shade_here.sum() >= 5
    level = np.median(images["model"][lit_far])
    assert np.median(images["model"][lit_here]) > 0.85 * level
    assert np.median(images["model"][shade_here]) < 0.2 * level
    assert np.median(images[False][lit_here]) < 0.2 * level
    with pytest.raises(ValueError):
        LightFlowRelighter(CpuRelighter(basis, d), fill=fill, fill_sources="hull")


def test_ground_fill_places_the_objects_shadow_by_its_hull_on_the_whole_ground():
    """``fill_sources='ground'`` (``source_model(everywhere=True)``): a sun between sparse capture
    lights is relit on every ground pixel from the model times the hull, so the box's shadow falls
    where its geometry puts it, closer to the truth than the photos' interpolation; ``'model'``
    leaves the pixels no sphere hides as interpolated."""
    d = stratified_directions(60, "upper", 3)                # 48 lights above 12 degrees
    d = d[d[:, 2] > math.sin(math.radians(12))]
    K, M, obj, ground, pts, basis = _scene(d)
    c, r = SPHERE
    hull = ShadowHull.carve(basis, d, obj, K, M, ground=ground, hidden=hidden_photos(pts, [c], r, directions=d))
    # the sun as far from the capture's lights as the upper sky 20-40 degrees up allows
    az, el = np.meshgrid(np.radians(np.arange(0, 360, 5)), np.radians(np.arange(20, 41, 5)))
    cand = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1).reshape(-1, 3)
    sun = cand[np.argmax(np.arccos(np.clip(cand @ d.T, -1, 1)).min(1))]
    lm = _one_texel_sun(sun)
    fill = SphereShadowFill.from_geometry(pts, [c], r, d)
    images = {}
    for mode in ("ground", "model", False):
        rel = LightFlowRelighter(CpuRelighter(basis, d, weighting="barycentric"), fill=fill, fill_sources=mode,
                                 fill_rest=False, hull=hull)
        rel.set_lightmap(lm)
        rel.render()
        images[mode] = rel.read_hdr()[..., 0].astype(np.float64)
    sun = rel.last_split.sources[0].sample_directions[0]
    power = float(rel.last_split.sources[0].sample_powers[0][0])
    box_shadow = _hits_box(np.nan_to_num(pts.reshape(-1, 3)), sun).reshape(RES, RES) & ground
    here = fill.hidden_for(sun)
    off = ground & ~here                                     # the ground no sphere hides from the sun
    truth = power * sun[2] * ~box_shadow
    err = {m: np.abs(images[m] - truth)[off & box_shadow].mean() / (power * sun[2]) for m in images}
    assert box_shadow[off].sum() >= 20
    assert err["ground"] < 0.5 * err[False] and err["ground"] < 0.15, err
    # 'model' changes only the pixels a sphere hides from the sun
    assert np.array_equal(images["model"][~here], images[False][~here])
    with pytest.raises(ValueError):
        SphereShadowFill(np.zeros((len(d), RES, RES), bool), d).ground_pixels()


def test_source_model_in_chunks_is_the_same(monkeypatch):
    """``source_model(everywhere=True)`` fits the ground in chunks of pixels (a large photo's whole
    ground would not fit in memory at once): the same image for any chunk size."""
    import ffls.relight.sphere_shadows as ss

    d = stratified_directions(60, "upper", 3)
    d = d[d[:, 2] > math.sin(math.radians(12))]
    K, M, obj, ground, pts, basis = _scene(d)
    c, r = SPHERE
    fill = SphereShadowFill.from_geometry(pts, [c], r, d, dilate_px=0)
    src = np.array([0.5, 0.5, 0.7]) / np.linalg.norm([0.5, 0.5, 0.7])
    whole = fill.source_model(np.zeros((RES, RES, 3)), src, basis, everywhere=True)
    monkeypatch.setattr(ss, "MODEL_CHUNK_VALUES", 7 * len(d) + 3)   # 7 pixels a chunk
    chunked = fill.source_model(np.zeros((RES, RES, 3)), src, basis, everywhere=True)
    assert np.array_equal(whole, chunked) and (whole[ground][:, 0] > 0).mean() > 0.9


def test_hull_and_sphere_shadows_without_distortion_match_opencvs_projection():
    """Without lens distortion the carving maps voxels to the ground's pixels by one 3 x 3 matrix per
    light and ``project_points`` projects in NumPy (``cv2.projectPoints`` also computes a Jacobian,
    30 times the work), and ``hidden_photos`` tests only the points near each shadow's axis exactly:
    the same hull as through OpenCV's projection (a distortion of 1e-300 takes that path), and the
    same sphere shadows as the direct test of every point."""
    import cv2

    from ffls.camera.projection import project_points

    d = stratified_directions(150, "upper", 3)
    d = d[d[:, 2] > math.sin(math.radians(12))]
    K, M, obj, ground, pts, basis = _scene(d)
    cam = (pts[ground] - M[:3, 3]) @ M[:3, :3]
    ref, _ = cv2.projectPoints(cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, np.zeros(5))
    np.testing.assert_array_equal(project_points(cam, K), ref.reshape(-1, 2))
    fast = ShadowHull.carve(basis, d, obj, K, M, ground=ground)
    slow = ShadowHull.carve(basis, d, obj, K, M, ground=ground, dist=[0.0, 0.0, 0.0, 0.0, 1e-300])
    assert fast.occupancy.any()
    np.testing.assert_array_equal(fast.occupancy, slow.occupancy)
    np.testing.assert_array_equal(fast.votes, slow.votes)
    centres, r = np.array([SPHERE[0], (-0.2, 0.1, 0.05)]), SPHERE[1]
    margin = np.linspace(0.0, 3.0, len(d))
    got = hidden_photos(pts, centres, r, directions=d, margin_deg=margin, dilate_px=0)
    valid = np.all(np.isfinite(pts), axis=-1)
    for i in range(len(d)):
        want = np.zeros(valid.sum(), dtype=bool)
        for c in centres:
            v = c - pts[valid]
            along = v @ d[i]
            off = np.linalg.norm(v - along[:, None] * d[i], axis=-1)
            want |= (along > 0) & (off < r + along * math.tan(math.radians(margin[i])))
        np.testing.assert_array_equal(got[i][valid], want)
    assert got.any()


def test_sphere_fill_ground_pixels_made_once():
    """The ground's pixels (``ground_pixels``, read by every compact source's ``source_model`` on
    the whole ground) are made once, from the points held in float64 once: the same mask, and the
    same source image as before."""
    d = stratified_directions(60, "upper", 3)
    d = d[d[:, 2] > math.sin(math.radians(12))]
    K, M, obj, ground, pts, basis = _scene(d)
    c, r = SPHERE
    fill = SphereShadowFill.from_geometry(pts.astype(np.float32), [c], r, d, dilate_px=0)
    assert fill.geometry["points"].dtype == np.float64
    mask = fill.ground_pixels()
    assert fill.ground_pixels() is mask and not mask.flags.writeable
    assert np.array_equal(mask, np.all(np.isfinite(pts), axis=-1))
    src = np.array([0.5, 0.5, 0.7]) / np.linalg.norm([0.5, 0.5, 0.7])
    first = fill.source_model(np.zeros((RES, RES, 3)), src, basis, everywhere=True)
    again = fill.source_model(np.zeros((RES, RES, 3)), src, basis, everywhere=True)
    assert np.array_equal(first, again) and fill.ground_pixels() is mask
