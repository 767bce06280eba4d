"""Tests of the synthetic scene renderer and capture writer (ffls.synth.scene, ffls.synth.geometry, ffls synth)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ffls.synth import scene as synth
from ffls.synth.geometry import Box, Capsule, Material, closest_hit, occluded
from ffls.synth.scene import SynthScene
from ffls.radiance.photos import load_photo

RES = 64


def _scene(**kw):
    return SynthScene(**kw)


def _ground_far(scene, res, margin=0.06):
    """Supersample-free pixel indices (flat) of ground points at least ``margin`` from every object."""
    gb = synth.gbuffer(scene, res)
    g = gb.labels.ravel()[gb.index] == synth.LABEL_GROUND
    p = gb.points
    far = g.copy()
    for c in scene.sphere_centers:
        far &= np.linalg.norm(p[:, :2] - c[:2], axis=1) > scene.sphere_radius + margin
    far &= np.linalg.norm(p[:, :2], axis=1) > 0.25 + margin  # the object fits in a 0.25 m disc
    return gb.index[far], p[far]


# ----------------------------------------------------------------------------- geometry
def test_capsule_and_box_hits_lie_on_their_surfaces():
    rng = np.random.default_rng(3)
    caps = Capsule((0.15, -0.08, 0.025), (0.10, 0.02, 0.19), 0.025, Material((1, 1, 1)), 1)
    box = Box((-0.09, -0.09, 0.0), (0.09, 0.09, 0.05), Material((1, 1, 1)), 1)
    o = rng.normal(size=(4000, 3)) * 0.5 + [0, 0, 0.6]
    for prim, sdf in (
        (caps, lambda x: np.linalg.norm(x - (np.array(caps.a) + np.clip(((x - caps.a) @ (np.subtract(caps.b, caps.a)))
                                                                       / np.sum(np.subtract(caps.b, caps.a) ** 2), 0, 1)[:, None]
                                            * np.subtract(caps.b, caps.a)), axis=1) - caps.radius),
        (box, lambda x: np.max(np.abs(x - [0, 0, 0.025]) - [0.09, 0.09, 0.025], axis=1)),
    ):
        target = rng.uniform(-0.1, 0.1, size=(4000, 3)) + (np.array(caps.a) + caps.b) / 2 * (prim is caps)
        d = target - o
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        t, idx = closest_hit([prim], o, d)
        hit = idx == 0
        assert hit.sum() > 500
        assert np.abs(sdf(o[hit] + t[hit, None] * d[hit])).max() < 1e-9
        # any-hit agrees with closest-hit for infinite rays from outside
        assert np.array_equal(occluded([prim], o, d), hit)
        # normals are unit and point against the incoming ray
        nrm = prim.normal(o[hit] + t[hit, None] * d[hit])
        assert np.allclose(np.linalg.norm(nrm, axis=1), 1)
        assert np.all(np.einsum("ij,ij->i", nrm, d[hit]) < 1e-9)


def test_sphere_layout_and_mask():
    s = _scene()
    uv, r = synth.sphere_pixel_radii(s, 768)
    assert 40 < r.mean() < 50  # "about 45 px at 768 x 768"
    assert np.all((uv - r[:, None] > 0) & (uv + r[:, None] < 767))
    m = synth.sphere_mask(s, 128)
    uv, r = synth.sphere_pixel_radii(s, 128)
    for k in range(4):
        v, u = np.nonzero(m == k)
        assert len(u) > 0.8 * np.pi * r[k] ** 2
        assert np.hypot(u.mean() - uv[k, 0], v.mean() - uv[k, 1]) < 0.15 * r[k]
    lab = synth.pixel_labels(s, 128)
    assert (lab == synth.LABEL_OBJECT).sum() > 500
    assert (lab != synth.LABEL_BACKGROUND).all()  # the camera sees only the table and what is on it


# ----------------------------------------------------------------------------- radiometry
def test_distant_light_from_zenith_gives_albedo_over_pi_on_open_ground():
    s = _scene(ground_albedo=0.3)
    img = synth.render_light(s, RES, direction=[0, 0, 1])
    idx, _ = _ground_far(s, RES)
    assert len(idx) > 100
    np.testing.assert_allclose(img.reshape(-1, 3)[idx], 0.3 / np.pi, rtol=1e-6)


def test_tilted_distant_and_near_light_on_ground():
    s = _scene(ground_albedo=0.5)
    l = np.array([0.3, -0.4, 0.8])
    img = synth.render_light(s, RES, direction=l * 7.0)  # normalised inside
    idx, p = _ground_far(s, RES, margin=0.25)
    np.testing.assert_allclose(img.reshape(-1, 3)[idx], 0.5 / np.pi * l[2] / np.linalg.norm(l), rtol=1e-6)
    q = np.array([0.4, -0.9, 1.1])
    img = synth.render_light(s, RES, position=q)
    w = q - p
    r = np.linalg.norm(w, axis=1)
    expect = 0.5 / np.pi * (q @ q) * (w[:, 2] / r) / r**2
    lit = img.reshape(-1, 3)[idx][:, 0] > 0
    assert lit.mean() > 0.95
    np.testing.assert_allclose(img.reshape(-1, 3)[idx][lit, 0], expect[lit], rtol=1e-6)


def test_white_sphere_follows_lambert_and_is_black_on_its_shadow_side_without_bounce():
    s = _scene(ground_albedo=0.0)
    l = np.array([-1.0, 0.2, 0.35])
    l /= np.linalg.norm(l)
    gb = synth.gbuffer(s, RES)
    img = synth.render_light(s, RES, direction=l).reshape(-1, 3)[gb.index]
    for k in (0, 3):  # the left spheres: nothing stands between them and this light
        on = gb.labels.ravel()[gb.index] == synth.LABEL_SPHERE0 + k
        cos = gb.normals[on] @ l
        np.testing.assert_allclose(img[on], 0.8 / np.pi * np.maximum(cos, 0)[:, None] * np.ones(3), atol=1e-7)
        assert (cos < 0).sum() > 5 and np.all(img[on][cos < 0] == 0)


def test_ground_bounce_brightens_sphere_undersides_linearly_in_albedo():
    l = np.array([0.0, 0.0, 1.0])
    imgs = {a: synth.render_light(_scene(ground_albedo=a), RES, direction=l) for a in (0.0, 0.2, 0.4)}
    s = _scene(ground_albedo=0.2)
    gb = synth.gbuffer(s, RES)
    sph = gb.labels.ravel()[gb.index] >= synth.LABEL_SPHERE0
    under = sph & (gb.normals[:, 2] < -0.2)
    side = sph & (np.abs(gb.normals[:, 2]) < 0.5)
    flat = {a: im.reshape(-1, 3)[gb.index] for a, im in imgs.items()}
    assert under.sum() > 10
    assert np.all(flat[0.0][under] == 0)
    assert np.all(flat[0.2][under] > 0.01)
    # one bounce is linear in the ground albedo
    b1, b2 = flat[0.2] - flat[0.0], flat[0.4] - flat[0.0]
    np.testing.assert_allclose(b2[sph], 2 * b1[sph], rtol=1e-4, atol=1e-7)
    # bounded: E_bounce <= pi * max ground radiance = albedo (the direct irradiance is <= 1)
    assert b1[sph].max() <= 0.8 / np.pi * 0.2 + 1e-7
    # a side-facing point sees about half the ground: E_bounce ~ albedo / 2 (unshadowed part)
    assert 0.25 < np.median(b1[side][:, 0]) / (0.8 / np.pi * 0.2) < 0.6


def test_object_casts_shadow_on_ground_opposite_the_light():
    s = _scene(ground_albedo=0.3)
    l = np.array([1.0, 0.0, 0.5])
    l /= np.linalg.norm(l)
    img = synth.render_light(s, RES, direction=l).reshape(-1, 3)
    gb = synth.gbuffer(s, RES)
    g = gb.labels.ravel()[gb.index] == synth.LABEL_GROUND
    p = gb.points
    behind = g & (p[:, 0] > -0.25) & (p[:, 0] < -0.14) & (np.abs(p[:, 1]) < 0.04)
    front = g & (p[:, 0] > 0.3) & (p[:, 0] < 0.45) & (np.abs(p[:, 1]) < 0.04)
    assert behind.sum() >= 3 and front.sum() >= 3
    lit = 0.3 / np.pi * l[2]
    assert np.all(img[gb.index[behind]] == 0)
    np.testing.assert_allclose(img[gb.index[front]], lit, rtol=1e-6)
    # sphere 0 (at -0.25, -0.25) shadows the ground on its -X side
    c = s.sphere_centers[0]
    sh = g & (np.abs(p[:, 1] - c[1]) < 0.02) & (p[:, 0] < c[0] - 0.06) & (p[:, 0] > c[0] - 0.09)
    assert sh.sum() >= 1 and np.all(img[gb.index[sh]] == 0)


def test_light_below_horizon_is_blocked_by_the_table():
    img = synth.render_light(_scene(), RES, direction=[0.3, 0.2, -0.5])
    assert np.all(img == 0)


def test_area_light_softens_shadows_and_keeps_unshadowed_irradiance():
    s = _scene()
    q = np.array([0.6, 0.0, 0.5])
    hard = synth.render_light(s, RES, position=q)
    soft = synth.render_light(s, RES, position=q, light_radius=0.05, light_samples=16)
    idx, _ = _ground_far(s, RES, margin=0.3)
    np.testing.assert_allclose(soft.reshape(-1, 3)[idx], hard.reshape(-1, 3)[idx], rtol=0.02)
    penumbra = (hard[..., 0] == 0) & (soft[..., 0] > 0)  # the hard shadow's edge is partly lit
    assert penumbra.sum() > 5


def test_render_lights_matches_render_light_and_is_deterministic():
    s = _scene()
    d = synth.stratified_directions(3, seed=5)
    b = synth.render_lights(s, RES, d)
    assert b.shape == (3, RES, RES, 3) and b.dtype == np.float32
    for i in range(3):
        np.testing.assert_array_equal(b[i], synth.render_light(s, RES, direction=d[i]))
    synth.gbuffer.cache_clear()  # the bounce sampling is seeded: a rebuilt cache gives the same
    np.testing.assert_array_equal(b[0], synth.render_light(s, RES, direction=d[0]))
    other = synth.gbuffer(SynthScene(seed=1), RES)
    assert (other.bounce != synth.gbuffer(s, RES).bounce).nnz > 0


def test_stratified_directions():
    d = synth.stratified_directions(200, "upper", seed=2)
    assert d.shape == (200, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1)
    assert d[:, 2].min() >= 0 and abs(d[:, 2].mean() - 0.5) < 0.01  # uniform in z: equal area
    np.testing.assert_array_equal(d, synth.stratified_directions(200, "upper", seed=2))
    assert not np.array_equal(d, synth.stratified_directions(200, "upper", seed=3))
    f = synth.stratified_directions(100, "full", seed=2)
    assert (f[:, 2] < 0).sum() == 50


# ----------------------------------------------------------------------------- oracle
def test_oracle_of_a_single_texel_is_the_distant_light_render():
    s = _scene()
    d = np.array([[0.4, 0.3, 0.8]]) / np.linalg.norm([0.4, 0.3, 0.8])
    rad = np.array([[2.0, 1.0, 0.5]])
    sa = np.array([0.01])
    img = synth.render_lightmap(s, (d, rad, sa), RES, n_dirs=64)
    expect = synth.render_light(s, RES, direction=d[0]).astype(np.float64) * rad[0] * 0.01
    np.testing.assert_allclose(img, expect, rtol=1e-5, atol=1e-9)


def test_oracle_constant_map_and_horizon_rule():
    from ffls.lightmaps.lightmap import constant_map

    s = _scene(ground_albedo=0.5)
    img = synth.render_lightmap(s, constant_map(64, 1.0), RES, n_dirs=256)
    idx, _ = _ground_far(s, RES, margin=0.15)
    g = img.reshape(-1, 3)[idx]
    # open ground under a uniform sky of radiance 1: E = pi, L = albedo; objects hide a little sky
    assert np.all(g <= 0.5 * 1.003) and np.median(g) > 0.5 * 0.95
    # light only from below the horizon: dropped ('upper') and blocked by the table ('full')
    d = np.array([[0.0, 0.6, -0.8], [0.6, 0.0, -0.8]])
    below = (d, np.ones((2, 3)), np.full(2, 0.1))
    assert synth.cluster_lightmap(below, 16, "upper")[2] == 2
    assert np.all(synth.render_lightmap(s, below, RES, n_dirs=16, hemisphere="upper") == 0)
    assert np.all(synth.render_lightmap(s, below, RES, n_dirs=16, hemisphere="full") == 0)


def test_cluster_lightmap_conserves_energy_and_rotates():
    from ffls.conventions import rotation_z
    from ffls.lightmaps.lightmap import sky_sun_map

    lm = sky_sun_map(32)
    d, rad, sa = lm.samples()
    up = d[:, 2] >= 0
    dirs, irr, dropped = synth.cluster_lightmap(lm, 300, "upper")
    total = (rad[up] * sa[up, None]).sum(0)
    assert np.all(irr.sum(0) <= total) and np.all(irr.sum(0) > 0.99 * total)
    # the first moment is kept exactly: sum_k E_k m_k . n = sum_i L_i w_i d_i . n for n in the cluster
    up_moment = (rad[up, 0] * sa[up]) @ d[up, 2]
    np.testing.assert_allclose(irr[:, 0] @ dirs[:, 2], up_moment, rtol=2e-3)
    assert dropped == int((~up).sum()) and np.all(dirs[:, 2] >= 0)
    dirs_r, irr_r, _ = synth.cluster_lightmap(lm, 300, "full", rotation=rotation_z(90))
    total = (rad * sa[:, None]).sum(0)
    assert np.all(irr_r.sum(0) <= total) and np.all(irr_r.sum(0) > 0.99 * total)
    # the sun (the brightest cluster) moved by +90 degrees in azimuth
    sun = dirs[np.argmax(irr[:, 0])]
    sun_r = dirs_r[np.argmax(irr_r[:, 0])]
    np.testing.assert_allclose(sun_r, rotation_z(90) @ sun, atol=1e-3)


# ----------------------------------------------------------------------------- capture folder
def test_capture_folder_loads_and_matches_renders(tmp_path):
    from ffls.io.capture import load_capture, load_lights

    res = synth.write_synthetic_capture(tmp_path / "cap", n_lights=4, resolution=RES, seed=7, progress=False)
    cap = load_capture(tmp_path / "cap")
    lights = load_lights(tmp_path / "cap" / "lights.json", cap)
    truth = json.loads((tmp_path / "cap" / "truth.json").read_text())
    assert len(cap) == 4 and cap.hemisphere == "upper" and cap.sphere_radius == 0.05
    assert cap.image_size == (RES, RES) and cap.encoding == "linear"
    np.testing.assert_allclose(cap.K, SynthScene().K(RES))
    np.testing.assert_allclose(cap.world_from_camera, SynthScene().world_from_camera())
    np.testing.assert_allclose(lights.directions, res["directions"])
    np.testing.assert_allclose(truth["directions"], res["directions"])
    np.testing.assert_allclose(truth["sphere_centers"], SynthScene().sphere_centers)
    assert all(s == "ok" for s in lights.status)
    for i in range(4):
        ref = synth.render_light(SynthScene(), RES, direction=res["directions"][i])
        np.testing.assert_allclose(load_photo(cap, i), ref, rtol=1e-3, atol=1e-4)  # half floats
    # K projects the true sphere centres onto the recorded pixel centres
    c = (np.asarray(truth["sphere_centers"]) - cap.world_from_camera[:3, 3]) @ cap.world_from_camera[:3, :3]
    uv = (c @ cap.K.T)[:, :2] / c[:, 2:]
    np.testing.assert_allclose(uv, truth["sphere_centers_px"])


def test_capture_is_deterministic_and_seeded(tmp_path):
    kw = dict(n_lights=3, resolution=32, progress=False, encoding="srgb8", noise=0.01)
    synth.write_synthetic_capture(tmp_path / "a", seed=1, **kw)
    synth.write_synthetic_capture(tmp_path / "b", seed=1, **kw)
    synth.write_synthetic_capture(tmp_path / "c", seed=2, **kw)
    for name in ("img_0000.png", "img_0002.png", "lights.json", "capture.json", "truth.json"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert (tmp_path / "a" / "lights.json").read_bytes() != (tmp_path / "c" / "lights.json").read_bytes()


def test_srgb8_capture_with_noise_and_near_lights(tmp_path):
    from ffls.io.capture import load_capture, load_lights

    d = np.array([[0.0, -0.5, 0.8], [0.5, 0.5, 0.5]])
    res = synth.write_synthetic_capture(tmp_path / "n", resolution=RES, light_model="near", light_distance=1.5,
                                        directions=d, encoding="srgb8", noise=2 / 255, progress=False)
    cap = load_capture(tmp_path / "n")
    lights = load_lights(tmp_path / "n" / "lights.json", cap)
    assert cap.encoding == "srgb" and cap.image_names[0].endswith(".png")
    np.testing.assert_allclose(lights.positions, 1.5 * d / np.linalg.norm(d, axis=1, keepdims=True))
    np.testing.assert_allclose(lights.directions, res["directions"])
    img = load_photo(cap, 0)
    ref = synth.render_light(SynthScene(), RES, position=res["positions"][0])
    err = img - np.clip(ref, 0, 1)
    assert 0.001 < np.std(err) < 0.02  # noise of 2 code values, seen through the sRGB curve
    assert abs(np.mean(err)) < 0.003


def test_bad_arguments():
    with pytest.raises(ValueError):
        synth.render_light(SynthScene(), 16)
    with pytest.raises(ValueError):
        synth.render_light(SynthScene(), 16, direction=[0, 0, 1], position=[0, 0, 1])
    with pytest.raises(ValueError):
        synth.write_synthetic_capture("/nonexistent-never", encoding="jpeg", progress=False)
    with pytest.raises(ValueError):
        SynthScene(sphere_radius=-1)


def test_cli(tmp_path, capsys):
    from ffls.cli import main

    out = tmp_path / "cli"
    assert main(["synth", str(out), "--lights", "2", "--resolution", "24", "--quiet", "--full-sphere",
                 "--ground-albedo", "0"]) == 0
    assert str(out) in capsys.readouterr().out
    doc = json.loads((out / "capture.json").read_text())
    assert doc["hemisphere"] == "full" and len(doc["images"]) == 2
    assert json.loads((out / "truth.json").read_text())["ground_albedo"] == 0.0
    assert main(["synth", str(tmp_path / "bad"), "--near", "-1", "--quiet"]) == 2
    assert "--near" in capsys.readouterr().err


def test_supersampling_averages_subpixels():
    s1, s2 = SynthScene(), SynthScene(supersample=2)
    a = synth.render_light(s1, 32, direction=[0, 0, 1])
    b = synth.render_light(s2, 32, direction=[0, 0, 1])
    assert b.shape == (32, 32, 3) and synth.pixel_labels(s2, 32).shape == (32, 32)
    idx, _ = _ground_far(s1, 32, margin=0.1)
    all_ground = (synth.gbuffer(s2, 32).labels.reshape(32, 2, 32, 2) == synth.LABEL_GROUND).all(axis=(1, 3))
    idx = idx[all_ground.ravel()[idx]]  # no sub-pixel sees an object in front of the ground
    assert len(idx) > 300
    # open ground is flat and uniformly lit: the box filter keeps its value
    np.testing.assert_allclose(b.reshape(-1, 3)[idx], a.reshape(-1, 3)[idx], rtol=1e-6)
    # silhouettes get intermediate values
    assert len(np.setdiff1d(np.unique(b[..., 0]), np.unique(a[..., 0]))) > 20


def test_docs_synth_python_example_names_resolve():
    """docs/synth.md's Python example: its imports run and every ``synth.NAME`` it calls exists (it
    imported ``from ffls import synth``, a package that exports none of them: a new user's first
    line failed with AttributeError)."""
    import re
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "synth.md").read_text(encoding="utf-8")
    block = doc.split("```python\n", 1)[1].split("```", 1)[0]
    ns: dict = {}
    exec("\n".join(line for line in block.splitlines() if line.startswith(("from ", "import "))), ns)
    names = set(re.findall(r"(?<![\w.])synth\.(\w+)", block))
    assert names and all(hasattr(ns["synth"], n) for n in names), sorted(n for n in names
                                                                          if not hasattr(ns["synth"], n))
    assert callable(ns["sky_sun_map"]) and "dirs = " in block


def test_docs_probes_comparison_command_runs(tmp_path):
    """docs/probes.md's command that compares a map with the true one runs as written (a map against
    itself: 0)."""
    import subprocess
    import sys
    from pathlib import Path

    from ffls.lightmaps.lightmap import sky_sun_map

    doc = (Path(__file__).resolve().parents[1] / "docs" / "probes.md").read_text(encoding="utf-8")
    cmd = doc.split("**Comparing a map with the true one.**", 1)[1].split("```sh\n", 1)[1].split("```", 1)[0]
    from ffls.io.images import write_exr

    write_exr(tmp_path / "TRUE.exr", sky_sun_map(16).data)
    write_exr(tmp_path / "MAP.exr", sky_sun_map(16).data)
    code = cmd.strip()[len('python -c "'):-1]
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["relit", "0.00%", "map", "0.000"], out.stdout
