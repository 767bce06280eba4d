"""Conditions of real photographs in the synthetic scene (ffls.synth.scene, ffls.synth.photo, ffls synth).

Spheres of any number and material (mirror highlights checked against the analytic reflection
of the light, solved here independently of the renderer), calibration shots without the object,
textured backgrounds, long and orthographic lenses, and the camera effects: transfer curves,
16-bit and JPEG files, vignetting, Poisson-Gaussian noise, unstated encodings.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from ffls.synth import scene as synth
from ffls.synth.photo import PhotoSettings, decode, encode, quantise, sensor_noise, vignetting_factor
from ffls.synth.scene import SynthScene, make_scene


def _highlight_point(centre, radius, camera, light_dir=None, light_pos=None, iters=200):
    """The point of a sphere where the camera sees the light reflected (fixed-point on the half vector)."""
    centre = np.asarray(centre, dtype=float)
    n = np.asarray(camera, dtype=float) - centre
    n /= np.linalg.norm(n)
    for _ in range(iters):
        p = centre + radius * n
        v = camera - p
        v /= np.linalg.norm(v)
        l = light_dir if light_dir is not None else (light_pos - p) / np.linalg.norm(light_pos - p)
        h = v + l
        n = h / np.linalg.norm(h)
    return centre + radius * n


def _project(K, M, p):
    c = (np.asarray(p) - M[:3, 3]) @ M[:3, :3]
    uv = K @ c
    return uv[:2] / uv[2]


# ----------------------------------------------------------------------------- spheres
@pytest.mark.parametrize("light", ["distant", "near"])
def test_mirror_highlight_sits_at_the_analytic_reflection(light):
    res = 160
    s = make_scene(2, ("mirror", "glossy_black"), background="black")
    M, K = s.world_from_camera(), s.K(res)
    d = np.array([0.5, -0.45, 0.74])
    d /= np.linalg.norm(d)
    kw = {"direction": d} if light == "distant" else {"position": 1.5 * d}
    img = synth.render_light(s, res, **kw)
    mask = synth.sphere_mask(s, res)
    for k in range(2):
        p = _highlight_point(s.sphere_centers[k], s.sphere_radius, M[:3, 3],
                             light_dir=d if light == "distant" else None,
                             light_pos=1.5 * d if light == "near" else None)
        u, v = _project(K, M, p)
        lum = np.where(mask == k, img[..., 1], 0)
        row, col = np.unravel_index(np.argmax(lum), lum.shape)
        assert abs(col - u) <= 0.75 and abs(row - v) <= 0.75, (k, (col, row), (u, v))
        # the light is far brighter than anything diffuse in the frame
        assert lum.max() > 5 * img[mask != k].max() or k == 1
    # chrome (0.9) against a 4 % Schlick coat: the highlight ratio is about 0.9 / F
    assert img[mask == 0].max() > 8 * img[mask == 1].max()


def test_mirror_shows_the_reflected_scene_and_nothing_where_its_ray_escapes():
    res = 96
    s = make_scene(1, "mirror", background="grey", with_object=True)
    gb = synth.gbuffer(s, res)
    assert len(gb.mirror_idx) > 0.8 * np.count_nonzero(synth.sphere_mask(s, res) == 0)
    img = synth.render_light(s, res, direction=[0, 0, 1]).reshape(-1, 3)[gb.index]
    mi = gb.mirror_idx
    ground = gb.refl_hit.copy()
    ground[gb.refl_hit] = gb.refl_normals[:, 2] > 0.999  # reflections of the open table
    # a zenith light: the table is albedo / pi; the mirror shows 0.9 of it where unshadowed (the sphere's own
    # shadow darkens a few)
    vals = img[mi[ground], 0]
    assert np.median(vals) == pytest.approx(0.9 * 0.3 / np.pi, rel=1e-6)
    # reflected rays that leave the scene (upward, away from the zenith light's disc) see black
    esc = ~gb.refl_hit & (gb.refl_dir[:, 2] < 0.99)
    assert esc.sum() > 10 and np.all(img[mi[esc]] == 0)


@pytest.mark.parametrize("n", [1, 6])
def test_n_spheres_appear_with_their_labels_materials_and_truth(tmp_path, n):
    res = 96
    scene = make_scene(n, "mixed", with_object=False)
    synth.write_synthetic_capture(tmp_path, n_lights=2, resolution=res, scene=scene, progress=False)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert len(truth["spheres"]) == n and truth["object"] is False and truth["object_pixels"] == 0
    mats = [s["material"] for s in truth["spheres"]]
    assert mats == [synth.SPHERE_MATERIALS[k % 4] for k in range(n)]
    mask = synth.sphere_mask(scene, res)
    assert set(np.unique(mask)) == set(range(-1, n))
    for k, sph in enumerate(truth["spheres"]):
        v, u = np.nonzero(mask == k)
        assert sph["pixels"] == len(u) > 0.8 * np.pi * sph["radius_px"] ** 2
        assert np.hypot(u.mean() - sph["center_px"][0], v.mean() - sph["center_px"][1]) < 0.2 * sph["radius_px"]
        np.testing.assert_allclose(sph["center"], scene.sphere_centers[k])
    assert truth["sphere_centers_px"] == [s["center_px"] for s in truth["spheres"]]


def test_no_object_and_no_sphere_captures(tmp_path):
    from ffls.io.capture import load_capture, load_capture_and_lights

    pair = synth.write_calibration_pair(tmp_path, scene=make_scene(2, "grey"), n_lights=3, resolution=48,
                                        progress=False)
    cal, obj = tmp_path / "calibration", tmp_path / "object"
    assert (cal / "lights.json").is_file() and not (obj / "lights.json").exists()
    lab_cal = synth.pixel_labels(pair["calibration"]["scene"], 48)
    lab_obj = synth.pixel_labels(pair["object"]["scene"], 48)
    assert not (lab_cal == synth.LABEL_OBJECT).any() and (lab_cal >= synth.LABEL_SPHERE0).sum() > 20
    assert not (lab_obj >= synth.LABEL_SPHERE0).any() and (lab_obj == synth.LABEL_OBJECT).sum() > 100
    np.testing.assert_allclose(pair["calibration"]["directions"], pair["object"]["directions"])
    assert load_capture(obj).sphere_radius is None
    # the object capture takes the calibration capture's lights
    cap, lights = load_capture_and_lights(obj, lights=cal / "lights.json")
    np.testing.assert_allclose(lights.directions, pair["calibration"]["directions"])
    with pytest.raises(ValueError):
        synth.write_calibration_pair(tmp_path / "x", scene=make_scene(0), n_lights=2, resolution=16, progress=False)


def test_textured_ground_is_high_contrast_and_shaded_by_its_albedo():
    s = make_scene(4, background="textured")
    rng = np.random.default_rng(0)
    a = s.ground_albedo_at(rng.uniform(-1, 1, (20000, 2)))
    assert a.min() < 0.1 and a.max() > 0.5 and abs(a.mean() - 0.3) < 0.05
    assert np.mean(a < 0.15) > 0.2 and np.mean(a > 0.45) > 0.2  # blotches, not a flat mid-grey
    gb = synth.gbuffer(s, 64)
    img = synth.render_light(s, 64, direction=[0, 0, 1]).reshape(-1, 3)[gb.index]
    g = gb.labels.ravel()[gb.index] == synth.LABEL_GROUND
    far = g & (np.linalg.norm(gb.points[:, :2], axis=1) > 0.5)  # open ground: direct light only
    np.testing.assert_allclose(img[far, 0], s.ground_albedo_at(gb.points[far, :2]) / np.pi, rtol=1e-6)
    c = make_scene(4, background="textured", ground_texture="checker")
    assert set(np.round(c.ground_albedo_at(rng.uniform(-1, 1, (500, 2))), 6)) == {0.06, 0.54}


# ----------------------------------------------------------------------------- lenses
def test_long_lens_frames_like_the_normal_one():
    n, lg = make_scene(4), make_scene(4, lens="long")
    assert lg.camera_distance == 10 and lg.camera_fov_deg < 5
    _, rn = synth.sphere_pixel_radii(n, 256)
    _, rl = synth.sphere_pixel_radii(lg, 256)
    assert rl.max() / rl.min() < 1.06 < rn.max() / rn.min()  # near-orthographic: equal sizes


def test_orthographic_capture_has_no_K_and_loads(tmp_path):
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import load_photo

    res = 96
    scene = make_scene(3, "mixed", lens="orthographic", with_object=False)
    synth.write_synthetic_capture(tmp_path, n_lights=2, resolution=res, scene=scene, progress=False)
    doc = json.loads((tmp_path / "capture.json").read_text())
    assert doc["camera"]["model"] == "orthographic" and "K" not in doc["camera"]
    cap = load_capture(tmp_path)
    assert cap.camera_model == "orthographic" and cap.K is None
    assert load_photo(cap, 0).shape == (res, res, 3)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["lens"]["K"] is None and truth["lens"]["metres_per_pixel"] > 0
    mask = synth.sphere_mask(scene, res)
    vv, uu = np.mgrid[0:res, 0:res]
    for k, sph in enumerate(truth["spheres"]):
        # parallel rays: every outline is exactly the circle of radius R / pitch around the projected centre
        assert sph["radius_px"] == pytest.approx(0.05 / truth["lens"]["metres_per_pixel"])
        dist = np.hypot(uu - sph["center_px"][0], vv - sph["center_px"][1])
        assert np.array_equal(mask == k, dist < sph["radius_px"])


# ----------------------------------------------------------------------------- photographs
@pytest.mark.parametrize("curve", ["srgb", "linear", "gamma2.2"])
def test_8bit_curves_round_trip_through_capture_json(tmp_path, curve):
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import load_photo

    res = 48
    photo = PhotoSettings("png8", curve, exposure=2.0)
    r = synth.write_synthetic_capture(tmp_path, n_lights=1, resolution=res, photo=photo, progress=False)
    cap = load_capture(tmp_path)
    ref = np.clip(2.0 * synth.render_light(SynthScene(), res, direction=r["directions"][0]), 0, 1)
    got = load_photo(cap, 0)
    # at most half a code value, seen through the curve's slope
    e = encode(ref, curve)
    tol = np.maximum(decode(np.minimum(e + 0.5 / 255, 1), curve) - decode(e, curve),
                     decode(e, curve) - decode(np.maximum(e - 0.5 / 255, 0), curve)) + 1e-6
    err = np.abs(got - ref)
    assert np.all(err <= tol)
    assert np.mean(err > 0) > 0.5  # quantised: not the float render
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["curve"] == curve and truth["bits"] == 8 and truth["encoding_stated"] is True
    assert truth["gamma"] == {"linear": 1.0, "srgb": None, "gamma2.2": 2.2}[curve]


def test_encode_decode_quantise():
    x = np.linspace(0, 1, 1001)
    for curve in ("srgb", "linear", "gamma2.2"):
        np.testing.assert_allclose(decode(encode(x, curve), curve), x, atol=1e-12)
        q = quantise(encode(x, curve), 16)
        assert q.dtype == np.uint16
        np.testing.assert_allclose(decode(q / 65535.0, curve), x, atol=2e-4)
    np.testing.assert_allclose(encode(np.array([0.5]), "gamma2.2"), 0.5 ** (1 / 2.2))
    np.testing.assert_allclose(encode(np.array([3.0, -1.0]), "srgb"), [1.0, 0.0], atol=1e-12)  # saturation


def test_unstated_encoding_is_left_out_and_recorded_in_truth(tmp_path):
    from ffls.io.capture import load_capture

    photo = PhotoSettings("png16", "gamma2.2", state_encoding=False)
    synth.write_synthetic_capture(tmp_path, n_lights=1, resolution=24, photo=photo, progress=False)
    assert "encoding" not in json.loads((tmp_path / "capture.json").read_text())
    assert load_capture(tmp_path).encoding == "auto"
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["curve"] == "gamma2.2" and truth["bits"] == 16 and truth["encoding_stated"] is False
    with pytest.raises(ValueError):  # a 16-bit gamma 2.2 file cannot be stated
        synth.write_synthetic_capture(tmp_path / "s", n_lights=1, resolution=24, progress=False,
                                      photo=PhotoSettings("tiff16", "gamma2.2"))


def test_jpeg_is_written_atomically_readable_and_smaller_at_lower_quality(tmp_path):
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import load_photo

    res = 96
    sizes = {}
    for q in (95, 30):
        folder = tmp_path / f"q{q}"
        r = synth.write_synthetic_capture(folder, n_lights=1, resolution=res, progress=False,
                                          photo=PhotoSettings("jpeg", "srgb", exposure=3.0, jpeg_quality=q),
                                          scene=make_scene(4, background="textured"))
        path = folder / r["images"][0]
        assert path.suffix == ".jpg" and path.read_bytes()[:3] == b"\xff\xd8\xff"
        assert not list(folder.glob(".*tmp*"))
        sizes[q] = path.stat().st_size
        cap = load_capture(folder)
        ref = np.clip(3.0 * synth.render_light(r["scene"], res, direction=r["directions"][0]), 0, 1)
        err = np.abs(load_photo(cap, 0) - ref)
        assert np.median(err) < (0.01 if q == 95 else 0.03) and err.max() > 1 / 255  # lossy, but close
        assert json.loads((folder / "truth.json").read_text())["jpeg_quality"] == q
    assert sizes[30] < 0.6 * sizes[95]


def test_vignetting_falloff():
    s = SynthScene()
    K = s.K(64)
    f = vignetting_factor((64, 64), "cos4", K=K)
    assert f.max() <= 1 and f[31:33, 31:33].min() > 0.999
    corner = np.array([0.0, 0.0])
    theta = np.arctan(np.hypot(*(corner - K[:2, 2])) / K[0, 0])
    assert f[0, 0] == pytest.approx(np.cos(theta) ** 4)
    r = vignetting_factor((65, 33), "radial", (-0.4,))
    assert r[32, 16] == 1.0 and r[0, 0] == pytest.approx(0.6) and r[64, 32] == pytest.approx(0.6)
    assert r[32, 0] == pytest.approx(1 - 0.4 * 16 ** 2 / (32 ** 2 + 16 ** 2))
    with pytest.raises(ValueError):
        vignetting_factor((8, 8), "cos4")  # no K: an orthographic lens


def test_vignetting_in_a_capture(tmp_path):
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import load_photo

    res = 48
    photo = PhotoSettings("exr", vignetting="radial", vignetting_coeffs=(-0.5,))
    r = synth.write_synthetic_capture(tmp_path, n_lights=1, resolution=res, photo=photo, progress=False)
    got = load_photo(load_capture(tmp_path), 0)
    ref = synth.render_light(SynthScene(), res, direction=r["directions"][0])
    np.testing.assert_allclose(got, ref * vignetting_factor((res, res), "radial", (-0.5,))[..., None],
                               rtol=2e-3, atol=1e-4)


def test_poisson_gaussian_noise_statistics():
    rng = np.random.default_rng(5)
    x = np.full((400, 400, 3), 0.3)
    y = sensor_noise(x, rng, shot_gain=1e-3, read_noise=0.01)
    assert abs(y.mean() - 0.3) < 1e-3
    assert y.var() == pytest.approx(1e-3 * 0.3 + 1e-4, rel=0.03)
    y0 = sensor_noise(np.zeros((300, 300)), rng, shot_gain=1e-3, read_noise=0.0)
    assert np.all(y0 == 0)  # no light, no shot noise
    assert np.array_equal(sensor_noise(x, rng, 0.0, 0.0), x)


def test_mirror_highlight_saturates_8bit_and_is_recorded(tmp_path):
    res = 128
    scene = make_scene(1, "mirror", background="black", with_object=False)
    d = np.array([[0.3, -0.6, 0.74]])
    r = synth.write_synthetic_capture(tmp_path, resolution=res, directions=d, scene=scene, progress=False,
                                      photo=PhotoSettings("png8", "srgb"))
    import cv2

    img = cv2.imread(str(tmp_path / r["images"][0]), cv2.IMREAD_UNCHANGED)
    truth = json.loads((tmp_path / "truth.json").read_text())
    sph = truth["spheres"][0]
    assert sph["material"] == "mirror" and sph["mirror_reflectance"] == 0.9 and sph["albedo"] == 0
    assert truth["light_angular_radius_deg"] == 0.5
    v, u = np.nonzero(img.max(axis=2) == 255)
    assert 1 <= len(u) <= 12
    assert np.hypot(u.mean() - sph["center_px"][0], v.mean() - sph["center_px"][1]) < sph["radius_px"]


# ----------------------------------------------------------------------------- CLI
def _main(argv):
    from ffls.cli import main

    try:
        return main(argv)
    except SystemExit as e:  # argparse's own exit on a bad value
        return e.code


def test_cli_conditions(tmp_path, capsys):
    out = tmp_path / "c"
    assert _main(["synth", str(out), "--lights", "2", "--resolution", "40", "--quiet", "--spheres", "3",
                  "--sphere-material", "mirror,grey,glossy_black", "--no-object", "--background", "white",
                  "--lens", "long", "--format", "jpeg", "--jpeg-quality", "80", "--unstated-encoding",
                  "--exposure", "2", "--vignetting", "radial:-0.3", "--shot-noise", "1e-4", "--read-noise",
                  "0.002"]) == 0
    truth = json.loads((out / "truth.json").read_text())
    assert [s["material"] for s in truth["spheres"]] == ["mirror", "grey", "glossy_black"]
    assert truth["object"] is False and truth["ground_albedo"] == 0.8 and truth["lens"]["distance"] == 10
    assert truth["file_format"] == "jpeg" and truth["jpeg_quality"] == 80 and truth["curve"] == "srgb"
    assert truth["encoding_stated"] is False and truth["exposure"] == 2
    assert truth["vignetting"] == {"model": "radial", "coeffs": [-0.3]}
    assert truth["sensor_noise"] == {"shot_gain": 1e-4, "read_noise": 0.002}
    assert "encoding" not in json.loads((out / "capture.json").read_text())
    pair = tmp_path / "p"
    assert _main(["synth", str(pair), "--lights", "2", "--resolution", "24", "--quiet", "--calibration-pair",
                  "--lens", "orthographic", "--format", "png16", "--encoding", "linear"]) == 0
    assert "use --lights" in capsys.readouterr().out
    assert (pair / "calibration" / "lights.json").is_file() and not (pair / "object" / "lights.json").exists()


def test_cli_supersample_antialiases_the_outlines(tmp_path):
    """``--supersample S`` averages S x S rays per pixel: the same picture, with the outlines' pixels
    mixed (a mirror ball's limb as a lens gives it, not one ray through each pixel's centre)."""
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import load_photo

    ims = []
    for s in (1, 3):
        out = tmp_path / f"s{s}"
        assert _main(["synth", str(out), "--lights", "1", "--resolution", "48", "--quiet", "--spheres", "1",
                      "--sphere-material", "mirror", "--no-object", "--supersample", str(s)]) == 0
        ims.append(np.asarray(load_photo(load_capture(out), 0), dtype=np.float64))
    d = np.abs(ims[1] - ims[0]).max(axis=-1)
    assert np.count_nonzero(d > 1e-3) > 20  # the outlines' pixels changed
    assert abs(ims[1].mean() / ims[0].mean() - 1) < 0.05  # the picture did not
    assert np.median(d) < 1e-3


@pytest.mark.parametrize("argv, flag", [
    (["--supersample", "0"], "--supersample"),
    (["--sphere-material", "chrome"], "--sphere-material"),
    (["--spheres", "-1"], "--spheres"),
    (["--spheres", "2", "--sphere-material", "mirror,grey,grey"], "--sphere-material"),
    (["--format", "bmp"], "--format"),
    (["--format", "exr", "--encoding", "gamma2.2"], "--encoding"),
    (["--format", "tiff16", "--encoding", "gamma2.2"], "--unstated-encoding"),
    (["--jpeg-quality", "101", "--format", "jpeg"], "--jpeg-quality"),
    (["--jpeg-quality", "50"], "--jpeg-quality"),
    (["--vignetting", "radial:"], "--vignetting"),
    (["--vignetting", "cos4", "--lens", "orthographic"], "--vignetting"),
    (["--lens", "fisheye"], "--lens"),
    (["--background", "blue"], "--background"),
    (["--exposure", "0"], "--exposure"),
    (["--exposure", "nan"], "--exposure"),
    (["--shot-noise", "-1"], "--shot-noise"),
    (["--light-angle", "90"], "--light-angle"),
    (["--sphere-xy", "0.1;0.2"], "--sphere-xy"),
    (["--ground-albedo", "2"], "--ground-albedo"),
    (["--srgb8", "--format", "jpeg"], "--srgb8"),
    (["--no-object", "--spheres", "0"], "--no-object"),
    (["--camera-roll", "46"], "--camera-roll"),
    (["--camera-roll", "inf"], "--camera-roll"),
    (["--camera-elevation", "90.5"], "--camera-elevation"),
    (["--camera-elevation", "0"], "--camera-elevation"),
    (["--camera-elevation", "nan"], "--camera-elevation"),
])
def test_cli_bad_values_get_one_line(tmp_path, capsys, argv, flag):
    out = tmp_path / "bad"
    assert _main(["synth", str(out), "--lights", "1", "--resolution", "8", "--quiet", *argv]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if not line.startswith(("usage:", " "))]
    assert len(err) == 1 and flag in err[0], err
    assert not out.exists()


def test_mirror_highlight_flux_does_not_depend_on_the_light_size():
    # a distant light of angular radius theta has radiance 1 / (pi sin^2 theta): its irradiance, and so the
    # flux of its (unresolved) reflection in a chrome ball, stays the same
    s = make_scene(1, "mirror", background="black", with_object=False)
    d = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    flux = []
    for th in (0.5, 3.0):
        img = synth.render_light(s, 128, direction=d, light_angular_radius_deg=th)[..., 0]
        flux.append(img[img > 0.5].sum())
        assert img.max() <= 0.9 / (np.pi * np.sin(np.radians(th)) ** 2) * (1 + 1e-6)
    assert flux[0] == pytest.approx(flux[1], rel=0.05)
    with pytest.raises(ValueError):
        synth.render_light(s, 16, direction=d, light_angular_radius_deg=0)


def test_cropped_and_hidden_spheres_are_recorded(tmp_path):
    res = 64
    # one sphere in the open, one cut by the right frame edge, one behind the object
    scene = make_scene(sphere_xy=[(-0.25, -0.25), (0.33, -0.25), (0.0, 0.2)], sphere_material="grey")
    synth.write_synthetic_capture(tmp_path, n_lights=1, resolution=res, scene=scene, progress=False)
    sph = json.loads((tmp_path / "truth.json").read_text())["spheres"]
    assert sph[0]["in_frame_fraction"] == 1.0 and sph[0]["visible_fraction"] == 1.0
    assert sph[0]["silhouette_pixels"] == sph[0]["pixels"]
    assert 0.2 < sph[1]["in_frame_fraction"] < 0.9
    assert sph[1]["visible_fraction"] == pytest.approx(sph[1]["in_frame_fraction"])
    assert sph[2]["in_frame_fraction"] == 1.0 and sph[2]["visible_fraction"] < 0.9  # the object hides part
    # the edge sphere's centre is outside the frame or near it, and its pixels touch the border
    mask = synth.sphere_mask(scene, res)
    assert (mask[:, -1] == 1).any()


@pytest.mark.parametrize("fmt, curve", [("png16", "srgb"), ("tiff16", "linear"), ("png16", "linear")])
def test_16bit_files_round_trip(tmp_path, fmt, curve):
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import load_photo

    r = synth.write_synthetic_capture(tmp_path, n_lights=1, resolution=32, progress=False,
                                      photo=PhotoSettings(fmt, curve, exposure=2.0))
    assert r["images"][0].endswith(".tiff" if fmt == "tiff16" else ".png")
    ref = np.clip(2.0 * synth.render_light(SynthScene(), 32, direction=r["directions"][0]), 0, 1)
    got = load_photo(load_capture(tmp_path), 0)
    assert np.abs(got - ref).max() < 2e-5 and np.abs(got - ref).max() > 0  # 16-bit quantisation


def test_glossy_black_coat_follows_fresnel_and_chrome_does_not():
    s = make_scene(2, ("glossy_black", "mirror"), background="grey", with_object=False)
    gb = synth.gbuffer(s, 128)
    lab = gb.labels.ravel()[gb.index[gb.mirror_idx]] - synth.LABEL_SPHERE0
    cos = np.einsum("ij,ij->i", gb.normals[gb.mirror_idx], gb.view[gb.mirror_idx])
    black, chrome = lab == 0, lab == 1
    assert np.all(gb.mirror_F[chrome] == 0.9)
    assert gb.mirror_F[black & (cos > 0.95)].max() < 0.041 and gb.mirror_F[black & (cos < 0.15)].min() > 0.4
    # under a zenith light the black ball's grazing rim mirrors the bright table; its centre is dark
    img = synth.render_light(s, 128, direction=[0, 0, 1]).reshape(-1, 3)[gb.index[gb.mirror_idx]][:, 0]
    assert np.median(img[black & (cos < 0.15) & gb.refl_hit]) > 5 * np.median(img[black & (cos > 0.95)])


@pytest.mark.parametrize("camera", [{"camera_elevation_deg": 60.0}, {"camera_roll_deg": 3.0}])
def test_composite_set_virtual_scene_is_seen_as_the_captures_are(camera):
    """``--composite-set`` with ``--camera-elevation`` or ``--camera-roll``: the virtual scene (truth and
    background) keeps the captures' camera, so the object covers the same pixels in both (outside the
    spheres). Before, the roll was dropped from the virtual scene (53 of 729 object pixels moved at 96 px)
    and both flags were refused with --composite-set."""
    import dataclasses

    from ffls.synth.scene import LABEL_OBJECT, pixel_labels
    from ffls.synth.virtual import composite_masks, virtual_camera

    scene = dataclasses.replace(make_scene(**camera), with_object=True)
    virtual = pixel_labels(make_scene(spheres=0, with_object=True, **virtual_camera(scene)), 96) == LABEL_OBJECT
    masks = composite_masks(scene, 96)
    keep = ~masks["spheres"]
    assert masks["object"][keep].sum() > 500
    assert np.array_equal(virtual[keep], masks["object"][keep])


def test_composite_set_takes_camera_elevation_and_roll():
    """The flags once refused with ``--composite-set`` (the virtual scene is now seen alike) reach its scene."""
    from ffls.cli import build_parser
    from ffls.commands.synth import scene_of

    args = build_parser().parse_args(["synth", "out", "--camera-elevation", "60", "--camera-roll", "3",
                                      "--composite-set", "sky.exr"])
    s = scene_of(args)
    assert s.camera_elevation_deg == 60.0 and s.camera_roll_deg == 3.0
