"""Differential rendering (ffls.relight.composite, ffls composite, ffls.synth.virtual; docs/composite.md)."""
from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest

from ffls.cli import main
from ffls.errors import InputError
from ffls.io.capture import Capture
from ffls.io.images import read_image, read_mask
from ffls.relight.composite import (LUMINANCE, Registration, check_same_camera, composite, composite_Debevec1998,
                                    composite_ratio, register_surface, registration_pixels)


# ----------------------------------------------------------------------------- arrays
def _scene(h=64, w=80, seed=0):
    """A surface with a brightness gradient, an object (a box) and its shadow (a disk beside it)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    tint = np.array([1.0, 0.9, 0.7])
    s = (0.1 + 0.3 * xx / w + 0.1 * yy / h)[..., None] * tint  # relit surface alone
    shadow = (yy - 40) ** 2 + (xx - 45) ** 2 < 10 ** 2
    o = s.copy()
    o[shadow] *= 0.3
    obj = np.zeros((h, w), dtype=bool)
    obj[10:25, 30:50] = True
    o[obj] = rng.random((obj.sum(), 3))
    surface = np.ones((h, w))
    surface[obj] = 0.0
    return s, o, obj.astype(np.float64), surface, shadow


def test_equal_fields_give_the_background():
    rng = np.random.default_rng(1)
    s = 0.2 + rng.random((32, 40, 3))
    bg = 1.3 * s * (1 + 0.05 * rng.standard_normal(s.shape))  # a background whose surface resembles it
    om = np.zeros((32, 40))
    om[5:10, 5:10] = 1.0
    sm = 1.0 - om
    for method in ("Debevec1998", "ratio"):
        for reg in ("auto", "scale", "none"):
            r = composite(bg, s, s, om, sm, method=method, registration=reg)
            out = om < 1
            assert np.array_equal(r.image[out], bg[out].astype(np.float32)), (method, reg)
            assert np.allclose(r.image[om == 1], s[om == 1])  # the relit object over its mask
            assert r.clamped_pixels == 0


@pytest.mark.parametrize("method", ["Debevec1998", "ratio"])
def test_shadow_transfers_under_an_exposure_and_albedo_mismatch(method):
    s, o, om, sm, shadow = _scene()
    scale, offset = np.array([1.6, 1.5, 1.7]), np.array([0.05, 0.04, 0.03])
    bg = s * scale + offset
    r = composite(bg, o, s, om, sm, method=method, registration="scale-offset")
    truth = (o * scale + offset)  # the virtual surface, shadowed as the captured one
    keep = om == 0
    assert np.allclose(r.image[keep], truth[keep], rtol=1e-4, atol=1e-5)
    assert np.allclose(r.image[shadow], 0.3 * s[shadow] * scale + offset, rtol=1e-4)
    assert np.allclose(r.image[om == 1], o[om == 1])  # the object is not rescaled by default
    r2 = composite(bg, o, s, om, sm, method=method, registration="scale-offset", object_scale=True)
    assert np.allclose(r2.image[om == 1], o[om == 1] * scale, rtol=1e-4)


@pytest.mark.parametrize("method", ["Debevec1998", "ratio"])
def test_captures_of_different_light_power_are_registered_separately(method):
    """The object capture's lights 20% brighter: the surface far from the object must stay the background."""
    s, o, om, sm, shadow = _scene()
    bg = 1.5 * s
    r = composite(bg, 1.2 * o, s, om, sm, method=method, registration="scale")
    assert np.allclose(r.registration.object_scale, 1.5 / 1.2) and np.allclose(r.registration.scale, 1.5)
    keep = (om == 0) & ~shadow
    assert np.allclose(r.image[keep], bg[keep], rtol=1e-5)
    assert np.allclose(r.image[shadow], 0.3 * bg[shadow], rtol=1e-5)
    plain = composite_Debevec1998(bg, 1.2 * o, s, om, sm, 1.5)[0]  # one scale for both: 20% too bright
    assert np.allclose(plain[keep], 1.2 * bg[keep], rtol=1e-5)


def test_registration_recovers_a_known_scale_and_offset_with_outliers_and_noise():
    s, o, om, sm, shadow = _scene(96, 128, seed=2)
    rng = np.random.default_rng(3)
    scale, offset = np.array([2.0, 1.25, 0.8]), np.array([0.02, -0.01, 0.03])
    bg = s * scale + offset + rng.normal(0, 0.002, s.shape)
    junk = rng.random(s.shape[:2]) < 0.08  # a background that differs here and there (clutter, a highlight)
    bg[junk] += rng.random((junk.sum(), 3))
    used = registration_pixels(o, s, om, sm, background=bg)
    reg = register_surface(bg, s, used, "auto")
    assert reg.mode == "scale-offset"
    assert np.allclose(reg.scale, scale, rtol=0.01), reg
    assert np.allclose(reg.offset, offset, atol=0.003), reg
    assert reg.pixels == used.sum() > 1000 and reg.residual < 0.05
    assert "scale-offset" in reg.describe() and json.dumps(reg.to_json())


def test_registration_leaves_out_the_object_and_its_shadow():
    s, o, om, sm, shadow = _scene()
    used = registration_pixels(o, s, om, sm, margin_px=3)
    grown = cv2.dilate((shadow | (om > 0)).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert not (used & grown).any()
    assert used.sum() > 0.6 * (sm > 0).sum()


def test_uniform_surface_fits_the_scale_alone():
    s = np.full((40, 40, 3), 0.25)
    bg = 0.5 * s
    om = np.zeros((40, 40))
    om[:5, :5] = 1
    used = registration_pixels(s, s, om, 1 - om)
    reg = register_surface(bg, s, used, "auto")
    assert reg.mode == "scale" and np.allclose(reg.scale, 0.5) and np.all(reg.offset == 0)
    assert "offset not fitted" in reg.note
    with pytest.raises(InputError, match="surface pixels"):
        register_surface(bg, s, np.zeros((40, 40), bool), "scale")


def test_fixed_registration_and_none():
    s, o, om, sm, _ = _scene()
    bg = 2.0 * s
    fixed = Registration(np.full(3, 3.0), np.zeros(3), "given")
    r = composite(bg, o, s, om, sm, registration=fixed)
    assert r.registration is fixed and not r.used.any()
    img, clamped = composite_Debevec1998(bg, o, s, om, sm, 3.0)
    assert np.array_equal(r.image, img)
    r0 = composite(bg, o, s, om, sm, registration="none")
    assert np.allclose(r0.image[om == 0], (bg + (o - s))[om == 0], rtol=1e-6)


def test_negative_results_are_clamped_and_counted():
    s = np.full((20, 20, 3), 1.0)
    o = s.copy()
    o[10:, :] = 0.0
    bg = np.full((20, 20, 3), 0.5)  # darker than the relit surface: scale 1 makes the shadow negative
    om = np.zeros((20, 20))
    img, clamped = composite_Debevec1998(bg, o, s, om, np.ones((20, 20)), 1.0)
    assert clamped == 200 and img.min() == 0.0
    img, clamped = composite_ratio(bg, o, s, om, np.ones((20, 20)))
    assert clamped == 0 and np.allclose(img[10:], 0.0)


def test_bad_arrays_are_input_errors():
    s, o, om, sm, _ = _scene()
    with pytest.raises(InputError, match="object mask is"):
        composite(s, o, s, om[:-1], sm)
    with pytest.raises(InputError, match="background is"):
        composite(s[:, :-2], o, s, om, sm)
    with pytest.raises(InputError, match="no surface pixel"):
        composite(s, o, s, om, np.zeros_like(sm))
    with pytest.raises(InputError, match="different cameras|one camera"):
        composite(s, o, s[:-1], om, sm)
    bad = s.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        composite(bad, o, s, om, sm)


def test_check_same_camera(tmp_path):
    K = np.array([[100.0, 0, 31.5], [0, 100.0, 31.5], [0, 0, 1]])
    a = Capture(folder=tmp_path, image_names=["a.exr"], K=K, image_size=(64, 64))
    check_same_camera(a, dataclasses.replace(a))
    for change, what in ((dict(K=K * [[1.2], [1.2], [1]]), "intrinsics"), (dict(image_size=(64, 48)), "sizes"),
                         (dict(K=None), "states its camera"), (dict(dist=np.array([0.1, 0, 0, 0, 0])), "distortion")):
        with pytest.raises(InputError, match=what):
            check_same_camera(a, dataclasses.replace(a, **change))
    M = a.world_from_camera.copy()
    M[0, 3] += 0.1
    with pytest.raises(InputError, match="poses"):
        check_same_camera(a, dataclasses.replace(a, world_from_camera=M))


def test_fill_sphere_geometry_from_capture_json(tmp_path):
    """``--fill``'s spheres and ground (ffls.commands.composite.sphere_geometry): the centres stated in
    capture.json, the ground under them; one line for what the fill cannot do without."""
    from ffls.commands.composite import sphere_geometry
    from ffls.io.capture import Lights

    K = np.array([[100.0, 0, 31.5], [0, 100.0, 31.5], [0, 0, 1]])
    M = np.eye(4)
    M[:3, :3] = [[1, 0, 0], [0, -1, 0], [0, 0, -1]]
    M[:3, 3] = [0.0, 0.0, 1.2]
    centres = [[-0.2, 0.0, 0.07], [0.2, 0.0, 0.07], [0.0, 0.2, 0.072]]
    cap = Capture(folder=tmp_path, image_names=["a.exr", "b.exr"], K=K, image_size=(64, 64), world_from_camera=M,
                  world_from_camera_is_default=False, sphere_radius=0.05, spheres=[{"center": c} for c in centres])
    lights = Lights(image_names=["a.exr", "b.exr"], directions=np.array([[0, 0, 1.0], [0.6, 0, 0.8]]),
                    extra=[{"uncertainty_deg": 1.5}, {}])
    geo = sphere_geometry(cap, lights)
    assert geo["source"] == "capture.json" and geo["radius"] == 0.05
    assert geo["ground_z"] == pytest.approx(0.02) and np.allclose(geo["margin_deg"], [1.5, 0.0])
    for change, what in ((dict(world_from_camera_is_default=True), "world_from_camera"),
                         (dict(sphere_radius=None), "sphere_radius"), (dict(K=None), "pinhole"),
                         (dict(spheres=[{"center": c} for c in centres[:2] + [[0.0, 0.2, 0.2]]]),
                          "not on one ground plane")):
        with pytest.raises(InputError, match=what):
            sphere_geometry(dataclasses.replace(cap, **change), lights)
    near = Lights(image_names=["a.exr", "b.exr"], directions=lights.directions,
                  positions=np.array([[0.0, 0.0, 1.0], [np.nan] * 3]))
    with pytest.raises(InputError, match="distant lights"):
        sphere_geometry(cap, near)


def test_fill_finds_all_four_spheres_of_a_96_px_set(tmp_path):
    """``--fill`` finds the spheres in the photos (ffls.spheres' finder) when capture.json does not
    state them: at 96 px the two back spheres are 4.5 px wide in radius, below what the finder's
    Hough transforms resolve at the image's own pixels; it found 2 of the 4 before it also sought
    small circles on the upsampled images."""
    from ffls.commands.composite import sphere_geometry
    from ffls.io.capture import load_capture_and_lights

    root = tmp_path / "set"
    assert main(["synth", str(root), "--composite-set", "sunrise", "--lights", "40", "--surface-lights", "30",
                 "--resolution", "96", "--truth-dirs", "64", "--quiet"]) == 0
    for k in ("object", "surface"):
        truth = np.array(json.loads((root / k / "truth.json").read_text())["sphere_centers"])
        geo = sphere_geometry(*load_capture_and_lights(root / k))
        assert geo["source"] == "found" and len(geo["centres"]) == 4, geo
        # each true centre has a found one within 0.7 radius (the back ones are 4.5 px in radius)
        off = np.linalg.norm(truth[:, None] - geo["centres"][None], axis=-1).min(1)
        assert off.max() < 0.7 * geo["radius"], off
        assert abs(geo["ground_z"]) < 0.25 * geo["radius"]


def test_fill_finds_the_spheres_ffls_lights_found_on_an_unstated_encoding(tmp_path):
    """An 8-bit sRGB set whose capture.json states no encoding: ``--fill`` finds the spheres as ``ffls
    lights`` does, on the photos linearised with the curve it calibrated (lights.json's ``encoding``,
    applied by ``load_capture_and_lights``), not on the stored codes (``ffls lights`` before
    i-step15): the same world centres as lights.json's. Here (96 px) the four centres lie 2.46, 18.33,
    44.20 and 0.85 mm from the truth, on the stored codes 0.86, 30.46, 40.44 and 2.38 (the back
    spheres are 4.6 px in radius); at 256 px 0.05-1.33 mm against 0.15-3.66 (docs/composite.md)."""
    from ffls.commands.composite import sphere_geometry
    from ffls.io.capture import load_capture_and_lights

    root = tmp_path / "set"
    assert main(["synth", str(root), "--composite-set", "sunrise", "--lights", "16", "--surface-lights", "12",
                 "--resolution", "96", "--truth-dirs", "64", "--format", "png8", "--encoding", "srgb",
                 "--unstated-encoding", "--quiet"]) == 0
    cap = root / "object"
    assert main(["lights", str(cap), "--workers", "1", "--no-progress", "--model", "distant"]) == 0
    capture, lights = load_capture_and_lights(cap)
    assert capture.encoding != "auto"
    geo = sphere_geometry(capture, lights)
    found = [r["center"] for r in next(e["spheres"] for e in lights.extra if e.get("spheres"))]
    assert geo["source"] == "found" and np.allclose(geo["centres"], found, atol=1e-9), (geo["centres"], found)


# ----------------------------------------------------------------------------- end to end on ffls synth
@pytest.fixture(scope="module")
def cset(tmp_path_factory):
    """A composite set: 48 px, 60 + 50 lights, the courtyard map with a wall, truth reduced to 384 lights."""
    root = tmp_path_factory.mktemp("cset") / "set"
    rc = main(["synth", str(root), "--composite-set", "courtyard", "--lights", "60", "--surface-lights", "50",
               "--resolution", "48", "--truth-dirs", "384", "--quiet"])
    assert rc == 0
    return root


def _load(cset, name):
    return read_image(cset / name).pixels.astype(np.float64)


def test_synth_composite_set_files(cset):
    p = json.loads((cset / "composite.json").read_text())
    assert p["capture_albedo"] == 0.3 and p["scene_albedo"] == 0.5 and p["spheres"] == 4
    for name in ("object/capture.json", "surface/capture.json", "scene_map.exr", "background.exr", "truth.exr",
                 "object_mask.png", "surface_mask.png", "sphere_mask.png"):
        assert (cset / name).is_file(), name
    obj = json.loads((cset / "object" / "truth.json").read_text())
    sur = json.loads((cset / "surface" / "truth.json").read_text())
    assert obj["object"] and not sur["object"] and len(obj["spheres"]) == len(sur["spheres"]) == 4
    assert len(obj["images"]) == 60 and len(sur["images"]) == 50
    # the truth differs from the background by the object and its shadow on the ground
    om, sm = read_mask(cset / "object_mask.png") > 0.5, read_mask(cset / "surface_mask.png") > 0.5
    tr, bg = _load(cset, "truth.exr") @ LUMINANCE, _load(cset, "background.exr") @ LUMINANCE
    shadow = sm & ~om & (tr < 0.9 * bg)
    assert shadow.sum() > 20
    assert not (sm & (read_mask(cset / "sphere_mask.png") > 0.5)).any()


def test_composite_command_transfers_the_shadow_and_leaves_no_sphere_trace(cset, tmp_path, capfd):
    out = tmp_path / "c.exr"
    rc = main(["composite", "--object", str(cset / "object"), "--surface", str(cset / "surface"), "--lightmap",
               str(cset / "scene_map.exr"), "--background", str(cset / "background.exr"), "--mask",
               str(cset / "object_mask.png"), "--surface-mask", str(cset / "surface_mask.png"), "-o", str(out)])
    text = capfd.readouterr().out
    assert rc == 0 and "registration" in text
    assert out.is_file() and out.with_suffix(".png").is_file()
    rep = json.loads(out.with_suffix(".json").read_text())
    # the captured ground's albedo is 0.3, the scene's 0.5: the registration finds about their ratio
    # (up to the relighting's discretisation of the map over 50 lights, measured 10%)
    assert np.allclose(rep["registration"]["scale"], 0.5 / 0.3, rtol=0.15), rep
    c, tr, bg = read_image(out).pixels.astype(np.float64), _load(cset, "truth.exr"), _load(cset, "background.exr")
    om, sm = read_mask(cset / "object_mask.png") > 0.5, read_mask(cset / "surface_mask.png") > 0.5
    sph = read_mask(cset / "sphere_mask.png") > 0.5
    changed = sm & ~om & (np.abs(tr - bg) @ LUMINANCE > 0.03 * (bg @ LUMINANCE))
    err = np.abs(c - tr)[changed].sum() / tr[changed].sum()
    paste = np.abs(bg - tr)[changed].sum() / tr[changed].sum()
    assert paste > 0.05 and err < 0.5 * paste, (err, paste)
    assert np.array_equal(c[sph], bg[sph].astype(np.float32))  # the spheres leave no trace
    # nor do their shadows on the ground (in both captures, they cancel): the ring around the spheres
    ring = cv2.dilate(sph.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool) & sm & ~changed
    # (what is left is the two captures' different discretisations of the spheres' shadows: 5.6% here, with
    # 60 and 50 lights; less with more lights, docs/composite.md)
    assert (np.abs(c - bg)[ring] @ LUMINANCE).mean() < 0.08 * (bg[ring] @ LUMINANCE).mean()


def test_composite_does_not_replace_a_sibling_it_did_not_write(cset, tmp_path, capfd):
    """``-o DIR/truth.png`` writes truth.exr and truth.json too: an existing truth.exr that no
    earlier composite wrote (the synthetic set's truth) is not replaced."""
    (tmp_path / "truth.exr").write_bytes(b"not ours")
    rc = main(["composite", "--object", str(cset / "object"), "--surface", str(cset / "surface"), "--lightmap",
               str(cset / "scene_map.exr"), "--background", str(cset / "background.exr"), "--mask",
               str(cset / "object_mask.png"), "--surface-mask", str(cset / "surface_mask.png"),
               "-o", str(tmp_path / "truth.png")])
    err = capfd.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "truth.exr exists, not from an earlier composite" in err[0], err
    assert (tmp_path / "truth.exr").read_bytes() == b"not ours" and not (tmp_path / "truth.png").exists()


def _fill_args(cset, tmp_path, lightmap="sunrise"):
    """Copies of the set's captures whose capture.json states the spheres' centres, and the
    ``ffls composite`` arguments that merge them under ``lightmap``: (captures, argv)."""
    import shutil

    caps = {}
    for k in ("object", "surface"):
        caps[k] = tmp_path / k
        shutil.copytree(cset / k, caps[k])
        doc = json.loads((caps[k] / "capture.json").read_text())
        truth = json.loads((caps[k] / "truth.json").read_text())
        doc["spheres"] = [{"center": c} for c in truth["sphere_centers"]]
        (caps[k] / "capture.json").write_text(json.dumps(doc))
    return caps, ["composite", "--object", str(caps["object"]), "--surface", str(caps["surface"]), "--lightmap",
                  lightmap, "--background", str(cset / "background.exr"), "--mask", str(cset / "object_mask.png"),
                  "--surface-mask", str(cset / "surface_mask.png")]


def test_composite_fill_model_relights_the_sun_where_the_spheres_hide_it(cset, tmp_path, capfd):
    """``--fill model``: the spheres' world centres from capture.json, each capture's sphere shadows and
    the object's shadow hull; under a sun the composite changes where a sphere hides the sun from the
    ground and nowhere off the surface. Without the spheres' radius it is one line."""
    caps, common = _fill_args(cset, tmp_path)
    images = {}
    for fill in ("none", "model"):
        out = tmp_path / f"c_{fill}.exr"
        rc = main(common + ["--fill", fill, "-o", str(out)])
        text = capfd.readouterr().out
        assert rc == 0, text
        rep = json.loads(out.with_suffix(".json").read_text())
        assert rep["fill"] == fill and len(rep["compact_sources"]) >= 1
        images[fill] = read_image(out).pixels
    assert "object: 4 spheres (capture.json), ground at z = 0" in text and "shadow hull" in text, text
    sm = read_mask(cset / "surface_mask.png") > 0.5
    changed = np.any(images["model"] != images["none"], axis=-1)
    assert changed[sm].sum() >= 10 and not changed[~sm].any()
    # a capture that does not state its spheres' radius: their shadows cannot be placed
    doc = json.loads((caps["surface"] / "capture.json").read_text())
    del doc["sphere_radius"]
    (caps["surface"] / "capture.json").write_text(json.dumps(doc))
    rc = main(common + ["--fill", "model", "-o", str(tmp_path / "c_bad.exr")])
    err = [ln for ln in capfd.readouterr().err.splitlines() if ln.strip()]
    assert rc == 2 and len(err) == 1 and "--fill needs sphere_radius" in err[0], err
    assert not (tmp_path / "c_bad.exr").exists()


def test_composite_fill_auto_relights_the_ground_where_it_can_and_says_why_not(cset, tmp_path, capfd):
    """``--fill auto`` (the default): ``ground`` (the sources on every ground pixel from the model and
    the hull) where both captures state what it needs and the map has a compact source, as
    ``--fill ground`` does; otherwise ``none``, with the reason in one line, and no refusal."""
    caps, common = _fill_args(cset, tmp_path)
    images = {}
    for fill in ("auto", "ground", "none"):
        out = tmp_path / f"c_{fill}.exr"
        rc = main(common + ([] if fill == "auto" else ["--fill", fill]) + ["-o", str(out)])
        cap = capfd.readouterr()
        assert rc == 0, cap.err
        images[fill] = read_image(out).pixels
        assert json.loads(out.with_suffix(".json").read_text())["fill"] == ("ground" if fill == "auto" else fill)
        if fill == "auto":
            assert "fill auto: ground (1 compact source" in cap.err and "fill ground: object: 4 spheres" in cap.out
    assert np.array_equal(images["auto"], images["ground"])
    sm = read_mask(cset / "surface_mask.png") > 0.5
    changed = np.any(images["ground"] != images["none"], axis=-1)
    assert changed[sm].sum() >= 10 and not changed[~sm].any()
    # the map without a compact source (the set's courtyard), and a capture without sphere_radius
    for k, (argv, why) in enumerate((
            (common[:6] + [str(cset / "scene_map.exr")] + common[7:], "the light map has no compact source"),
            (common, "--fill needs sphere_radius in capture.json"))):
        if k == 1:
            doc = json.loads((caps["surface"] / "capture.json").read_text())
            del doc["sphere_radius"]
            (caps["surface"] / "capture.json").write_text(json.dumps(doc))
        out = tmp_path / f"c_none{k}.exr"
        rc = main(argv + ["-o", str(out)])
        err = [ln for ln in capfd.readouterr().err.splitlines() if "fill auto" in ln]
        assert rc == 0 and len(err) == 1 and err[0].startswith("ffls composite: fill auto: none (") and why in err[0]
        assert json.loads(out.with_suffix(".json").read_text())["fill"] == "none"


def test_composite_turntable(cset, tmp_path, capfd):
    frames = tmp_path / "frames"
    rc = main(["composite", "--object", str(cset / "object"), "--surface", str(cset / "surface"), "--lightmap",
               str(cset / "scene_map.exr"), "--background", str(cset / "background.exr"), "--mask",
               str(cset / "object_mask.png"), "--surface-mask", str(cset / "surface_mask.png"), "--turntable", "3",
               "--method", "ratio", "-o", str(frames)])
    assert rc == 0, capfd.readouterr().err
    imgs = sorted(frames.iterdir())
    assert [p.name for p in imgs] == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    a, b = (read_image(p, working_space=False).pixels for p in imgs[:2])
    assert not np.array_equal(a, b)  # the scene's map turned


def test_composite_turntable_frame_is_the_still_at_its_rotation(cset, tmp_path, capfd):
    """A turntable reuses the fill's spheres, hull and sphere shadows (fitted once per run, they do not
    depend on the map's rotation): its frame k is the still at rotation 360 k / n, pixel for pixel,
    under the default fill (``auto`` -> ``ground`` under the sunrise's sun)."""
    _, common = _fill_args(cset, tmp_path)
    common += ["--registration", "none", "--exposure", "0"]  # a still fits its own registration, exposure
    frames = tmp_path / "frames"
    rc = main(common + ["--turntable", "3", "-o", str(frames)])
    err = capfd.readouterr().err
    assert rc == 0 and "fill auto: ground" in err, err
    for k, deg in ((0, "0"), (1, "120")):
        out = tmp_path / f"still{k}.exr"
        assert main(common + ["--rotate-z", deg, "-o", str(out)]) == 0
        still = read_image(out.with_suffix(".png"), working_space=False).pixels
        frame = read_image(frames / f"frame_{k:04d}.png", working_space=False).pixels
        assert np.array_equal(frame, still), k


def test_viewer_composite_mode(cset, gl_session, tmp_path):
    """The viewer's composite mode: the background with the object and its shadow, live under rotation."""
    pytest.importorskip("imgui_bundle", reason="imgui-bundle is not installed")
    from ffls.errors import GLUnavailable
    from ffls.io.capture import load_capture_and_lights
    from viewer.app import ViewerApp
    from viewer.renderer import CompositeInputs
    from viewer.state import ViewerState

    cap, lights = load_capture_and_lights(cset / "object")
    scap, slights = load_capture_and_lights(cset / "surface")
    bg = read_image(cset / "background.exr").pixels
    om, sm = read_mask(cset / "object_mask.png"), read_mask(cset / "surface_mask.png")
    st = ViewerState(window_size=(480, 320), lightmap=str(cset / "scene_map.exr"), tonemap="srgb", composite=True)
    st.quality["method"] = "full f32"
    try:
        app = ViewerApp(cap, lights, st, headless=True, composite=CompositeInputs(scap, slights, bg, om, sm))
    except GLUnavailable as e:
        pytest.skip(f"no viewer window on glfw's null platform with EGL: {e}")
    try:
        app.step(dt=0.0)
        assert app.ctx.error == "GL_NO_ERROR"
        a = app.renderer.read_hdr().copy()
        assert app.renderer.info.composite_available and "registration" in app.renderer.info.registration
        sph = read_mask(cset / "sphere_mask.png") > 0.5
        assert np.array_equal(a[sph], bg[sph])  # the background, not the relit capture with its spheres
        ref = composite(bg, app.renderer.engine.read_hdr(), app.renderer.surface_engine.read_hdr(), om, sm)
        assert np.allclose(a, ref.image, rtol=1e-5, atol=1e-6)
        _, exr = app.save_screenshot(tmp_path / "shot.png")  # the screenshot's HDR is the composite too
        assert np.allclose(read_image(exr).pixels[..., :3], a, rtol=1e-3, atol=1e-6)
        st.yaw = 90.0
        app.step(dt=0.0)
        b = app.renderer.read_hdr()
        assert not np.allclose(a[om > 0.5], b[om > 0.5])  # the scene's map turned: the object relit
        st.composite = False
        app.step(dt=0.0)
        assert not np.array_equal(app.renderer.read_hdr()[sph], bg[sph])  # plain relighting again
        assert app.ctx.error == "GL_NO_ERROR"
    finally:
        app.close()


def test_mitsuba_latlong_sensor_and_envmap_follow_the_guide():
    """scripts/mitsuba_latlong.py: Mitsuba 3's envmap lit by an ffls map and seen by the latlong sensor gives the map back."""
    mi = pytest.importorskip("mitsuba", reason="Mitsuba 3 is not installed (pip install mitsuba)")
    import importlib.util
    from pathlib import Path

    from ffls.conventions import latlong_directions

    mi.set_variant("scalar_rgb")
    spec = importlib.util.spec_from_file_location("mitsuba_latlong",
                                                  Path(__file__).resolve().parents[1] / "scripts" / "mitsuba_latlong.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.register()
    H = 16
    data = (1.5 + latlong_directions(2 * H, H)).astype(np.float32)  # radiance 1.5 + direction: orientation shows
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "path"},
                          "emitter": {"type": "envmap", "bitmap": mi.Bitmap(data),
                                      "to_world": mi.ScalarTransform4f(mod.ENVMAP_TO_WORLD)},
                          "sensor": mod.latlong_sensor((0.0, 0.0, 0.0), H)})
    img = np.array(mi.render(scene, spp=16))
    assert img.shape == data.shape
    assert np.abs(img - data).mean() < 0.04 and np.abs(img - data).max() < 0.15  # pixel filter and bilinear lookup
    assert np.abs(img[:, ::-1] - data).mean() > 0.2 and np.abs(img[::-1] - data).mean() > 0.2  # not mirrored


def test_flow_with_sources_weights_is_refused_in_one_line(cset, tmp_path, capfd):
    """--flow has no effect with --sources weights: naming it there is refused, not ignored."""
    out = tmp_path / "c.exr"
    rc = main(["composite", "--object", str(cset / "object"), "--surface", str(cset / "surface"), "--lightmap",
               str(cset / "scene_map.exr"), "--background", str(cset / "background.exr"), "--mask",
               str(cset / "object_mask.png"), "--surface-mask", str(cset / "surface_mask.png"),
               "--sources", "weights", "--flow", "farneback", "-o", str(out)])
    err = capfd.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--flow farneback" in err[0] and "--sources weights" in err[0], err
    assert not out.exists()


def _composite_mitsuba(monkeypatch):
    """``(mitsuba, benchmarks/composite_mitsuba.py as a module)``, Mitsuba on its ``scalar_rgb`` variant;
    the test is skipped without Mitsuba."""
    mi = pytest.importorskip("mitsuba", reason="Mitsuba 3 is not installed (pip install mitsuba)")
    import importlib.util
    from pathlib import Path

    mi.set_variant("scalar_rgb")
    bench = Path(__file__).resolve().parents[1] / "benchmarks"
    monkeypatch.syspath_prepend(str(bench))  # its `common` module
    spec = importlib.util.spec_from_file_location("composite_mitsuba", bench / "composite_mitsuba.py")
    cm = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cm)
    return mi, cm


def test_mitsuba_benchmark_sphere_shadows_match_a_render(monkeypatch):
    """benchmarks/composite_mitsuba.py's geometric sphere shadows are where Mitsuba renders them."""
    mi, cm = _composite_mitsuba(monkeypatch)
    res = 48
    _, ground, _ = cm.cast_masks(mi, res)
    for elevation in (15.0, 40.0):
        e, a = np.radians(elevation), np.radians(-35.0)
        d = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        scene = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                              "sensor": cm.camera_sensor(mi, res, 16), **cm.scene_shapes(mi, 0.3, False, True, False),
                              "light": {"type": "directional", "direction": list(-d),
                                        "irradiance": {"type": "rgb", "value": 1.0}}})
        lum = np.array(mi.render(scene), dtype=np.float64)[..., :3] @ LUMINANCE
        dark = ground & (lum < 0.5 * np.median(lum[ground]))
        geo = cm.sphere_shadows(res, d, 0.0) & ground
        assert geo.sum() > 20
        assert (dark & geo).sum() / (dark | geo).sum() > 0.8  # 0.91-0.93 measured: pixel-edge coverage only
        mirrored = cm.sphere_shadows(res, d * [-1, -1, 1], 0.0)  # the light from the other side
        assert (mirrored & dark).sum() < 0.1 * dark.sum()


def test_mitsuba_benchmark_shadow_hull_casts_the_objects_shadow(monkeypatch, tmp_path):
    """The object's shadow hull carved from a small path-traced capture casts the object's shadow
    for a light the capture does not have (benchmarks/composite_mitsuba.py's hull_shadow_check)."""
    from ffls.relight.basis import accepted_basis
    from ffls.relight.shadow_hull import ShadowHull
    from ffls.relight.sphere_shadows import ground_points, hidden_photos

    mi, cm = _composite_mitsuba(monkeypatch)
    res = 64
    obj, ground, _ = cm.cast_masks(mi, res)
    cap, lights = cm.render_capture(mi, tmp_path / "object", 80, 0, True, res, 4)
    basis, dirs = accepted_basis(cap, lights)
    pts = ground_points(cap.K, cap.world_from_camera, (res, res))
    pts[~ground] = np.nan
    centres = [(x, y, 0.05) for x, y in cm.SPHERES]
    hull = ShadowHull.carve(basis, dirs, obj, cap.K, cap.world_from_camera, ground=ground,
                            hidden=hidden_photos(pts, centres, 0.05, dirs))
    for elevation, azimuth in ((12.0, 30.0), (35.0, 200.0)):
        e, a = np.radians(elevation), np.radians(azimuth)
        d = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        check = cm.hull_shadow_check(mi, res, hull, pts, ground, d)
        assert check["true_px"] > 30 and check["iou"] > 0.6, check
