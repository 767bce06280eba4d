"""Compact sources relit by optical-flow interpolation between basis photos (ffls.relight.lightflow)."""
from __future__ import annotations

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest

from ffls.cli import main
from ffls.conventions import rotation_z
from ffls.io.capture import load_capture_and_lights
from ffls.lightmaps.lightmap import LightMap, builtin_lightmap
from ffls.relight.basis import accepted_basis
from ffls.relight.cpu import CpuRelighter, relight_fast
from ffls.relight.lightflow import (FlowInterpolator, LightFlowRelighter, photo_flow, relight_lightflow,
                                    split_compact_sources)
from ffls.weights.weighting import integrate


def _uniform_with_disc(height=64, centre=(0.3, 0.2, 0.93), radius_deg=3.0, radiance=500.0):
    lm = LightMap(np.full((height, 2 * height, 3), 0.5, np.float32), "latlong")
    d, _, _ = lm.samples()
    c = np.asarray(centre) / np.linalg.norm(centre)
    disc = (d @ c) >= np.cos(np.radians(radius_deg))
    data = lm.data.reshape(-1, 3).copy()
    data[disc] = radiance
    return replace(lm, data=data.reshape(lm.data.shape)), c


@pytest.mark.parametrize("name", ["sunrise", "sky", "studio", "courtyard"])
def test_split_conserves_the_maps_power(name):
    lm = builtin_lightmap(name)
    sp = split_compact_sources(lm)
    assert np.allclose(sp.rest.total_power() + sp.source_power, lm.total_power(), rtol=1e-9, atol=0)
    for s in sp.sources:
        assert np.allclose(s.sample_powers.sum(0), s.power, rtol=1e-12)
        assert s.solid_angle <= 0.05 and s.direction[2] > 0
    assert sp.rest.data.shape == lm.data.shape and sp.rest.layout == lm.layout


def test_split_finds_a_disc_where_it_is_and_follows_the_rotation():
    lm, c = _uniform_with_disc()
    sp = split_compact_sources(lm)
    assert len(sp.sources) == 1
    s = sp.sources[0]
    assert np.degrees(np.arccos(np.clip(s.direction @ c, -1, 1))) < 0.5
    assert abs(s.radius_deg - 3.0) < 0.6 and len(s.sample_powers) == 2  # 1 + 3 // 2 samples
    assert sp.rest.data.max() == pytest.approx(0.5)  # every disc texel moved to the source
    R = rotation_z(90.0)
    sr = split_compact_sources(lm, R).sources[0]
    assert np.allclose(sr.direction, R @ s.direction, atol=1e-9)
    assert np.allclose(sr.power, s.power)
    # below the hemisphere after the rotation: left in the rest
    flip = np.diag([1.0, -1.0, -1.0])
    assert split_compact_sources(lm, flip).sources == ()


def test_no_compact_source_in_a_smooth_or_dark_map():
    lm = LightMap(np.full((32, 64, 3), 0.5, np.float32), "latlong")
    assert split_compact_sources(lm).sources == ()  # the whole sky is bright: too large
    dark = replace(lm, data=np.zeros_like(lm.data))
    assert split_compact_sources(dark).sources == ()
    with pytest.raises(ValueError):
        split_compact_sources(lm, threshold=0.0)


# ----------------------------------------------------------------------------- flow interpolation
H = W = 96


def shadow_photo(d, rng=None, noise=0.0, lambert: bool = False):
    """A textured ground with a sharp dark disc (a shadow) whose place follows the light direction.

    Its brightness is ``0.5 + 0.5 d_z`` (half ambient), or ``d_z`` (a Lambertian ground of normal +Z)
    with ``lambert``. Shared by ``tests/test_composite_levelset.py``.
    """
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    tex = 0.6 + 0.15 * np.sin(x / 5.0) * np.cos(y / 7.0)
    cx, cy = W / 2 - 60 * d[0], H / 2 - 60 * d[1]
    shade = np.where((x - cx) ** 2 + (y - cy) ** 2 < 12 ** 2, 0.15, 1.0)
    img = (tex * shade * (d[2] if lambert else 0.5 + 0.5 * d[2]))[..., None] * np.array([1.0, 0.9, 0.8])
    if noise:
        img = img * (1 + noise * rng.standard_normal(img.shape))
    return img.astype(np.float32)


def ring_lights():
    """The zenith and six lights 65 degrees high, 60 degrees apart."""
    az = np.radians(np.arange(0, 360, 60))
    el = np.radians(65.0)
    d = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.full(6, np.sin(el))]
    return np.r_[[[0.0, 0.0, 1.0]], d]


def test_interpolation_is_exact_at_a_light_and_moves_the_shadow():
    dirs = ring_lights()
    basis = np.stack([shadow_photo(d) for d in dirs])
    fi = FlowInterpolator(basis, dirs, "upper")
    assert np.array_equal(fi.image(dirs[3]), basis[3])
    t = dirs[0] + dirs[1] + dirs[2]
    t /= np.linalg.norm(t)
    idx, w = fi.weights(t)
    assert sorted(idx) == [0, 1, 2] and w.sum() == pytest.approx(1.0)
    truth = shadow_photo(t)
    blend = sum(wi * basis[i] for i, wi in zip(idx, w))
    flow = fi.image(t)
    e_flow = np.abs(flow - truth).sum() / truth.sum()
    e_blend = np.abs(blend - truth).sum() / truth.sum()
    assert e_flow < 0.6 * e_blend, (e_flow, e_blend)
    # bilinear warps and a convex blend: no value outside the neighbours' range (no ringing)
    lo, hi = basis[idx].min(0), basis[idx].max(0)
    assert (flow >= lo.min() - 1e-6).all() and (flow <= hi.max() + 1e-6).all()


def test_interpolation_on_noisy_jpeg_photos_stays_honest():
    rng = np.random.default_rng(3)
    dirs = ring_lights()
    clean = np.stack([shadow_photo(d) for d in dirs])
    noisy = []
    for d in dirs:
        img = shadow_photo(d, rng, 0.05)
        ok, buf = cv2.imencode(".jpg", np.clip(img * 255, 0, 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 80])
        noisy.append(cv2.imdecode(buf, cv2.IMREAD_COLOR).astype(np.float32) / 255)
    noisy = np.stack(noisy)
    t = dirs[0] + dirs[1] + dirs[2]
    t /= np.linalg.norm(t)
    fi = FlowInterpolator(noisy, dirs, "upper")
    idx, w = fi.weights(t)
    truth = shadow_photo(t)
    blend = sum(wi * clean[i] for i, wi in zip(idx, w))
    e_flow = np.abs(fi.image(t) - truth).sum() / truth.sum()
    e_blend = np.abs(blend - truth).sum() / truth.sum()
    assert e_flow < e_blend, (e_flow, e_blend)
    # a flow between two photos of the same light (noise only) is about zero: nothing moves
    f = photo_flow(noisy[0], np.clip(noisy[0] * (1 + 0.05 * rng.standard_normal(noisy[0].shape)), 0, None))
    assert np.abs(f).mean() < 0.3


def test_photo_flow_rejects_an_unknown_method():
    with pytest.raises(ValueError):
        photo_flow(np.zeros((8, 8, 3)), np.zeros((8, 8, 3)), "lucas-kanade")


# ----------------------------------------------------------------------------- on a synthetic capture
@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("lf") / "cap"
    assert main(["synth", str(root), "--lights", "40", "--resolution", "40", "--quiet"]) == 0
    cap, lights = load_capture_and_lights(root)
    return cap, lights


def test_relighter_is_the_rest_plus_the_sources(capture):
    cap, lights = capture
    basis, dirs = accepted_basis(cap, lights)
    lm = builtin_lightmap("sky", 64)
    R = rotation_z(30.0)
    img, split = relight_lightflow(basis, dirs, lm, R, cap.hemisphere, scheme="barycentric")
    assert len(split.sources) == 1
    rest = relight_fast(integrate(split.rest, dirs, R, cap.hemisphere, "barycentric").weights, basis)
    fi = FlowInterpolator(basis, dirs, cap.hemisphere)
    s = split.sources[0]
    direct = rest + sum(fi.image(d) * p.astype(np.float32) for d, p in zip(s.sample_directions, s.sample_powers))
    assert np.allclose(img, direct, rtol=1e-5, atol=1e-6)
    rel = LightFlowRelighter(CpuRelighter(basis, dirs, cap.hemisphere, weighting="barycentric"))
    rel.set_lightmap(lm)
    rel.set_rotation(R)
    rel.render()
    assert np.allclose(rel.read_hdr(), img, rtol=1e-4, atol=1e-5)
    assert rel.read_display().dtype == np.uint8 and rel.last_split.describe().startswith("1 compact source")
    # the image's energy: the sources carry most of the sky map's power, relit at the same total
    # brightness as the plain weighting within the interpolation's few percent
    plain = relight_fast(integrate(lm, dirs, R, cap.hemisphere, "barycentric").weights, basis)
    assert abs(img.sum() / plain.sum() - 1) < 0.05
    rel.release()


def test_composite_command_reports_the_sources(tmp_path, capfd):
    root = tmp_path / "set"
    assert main(["synth", str(root), "--composite-set", "sky", "--lights", "40", "--surface-lights", "40",
                 "--resolution", "40", "--truth-dirs", "256", "--quiet"]) == 0
    outs = {}
    for src in ("lightflow", "weights"):
        out = tmp_path / f"{src}.exr"
        rc = main(["composite", "--object", str(root / "object"), "--surface", str(root / "surface"), "--lightmap",
                   str(root / "scene_map.exr"), "--background", str(root / "background.exr"), "--mask",
                   str(root / "object_mask.png"), "--surface-mask", str(root / "surface_mask.png"),
                   "--sources", src, "--weighting", "barycentric", "-o", str(out)])
        text = capfd.readouterr().out
        assert rc == 0
        rep = json.loads(out.with_suffix(".json").read_text())
        assert rep["sources"] == src and rep["weighting"] == "barycentric"
        outs[src] = (text, rep)
    assert "1 compact source" in outs["lightflow"][0] and len(outs["lightflow"][1]["compact_sources"]) == 1
    assert "compact_sources" not in outs["weights"][1]
    rc = main(["composite", "--object", str(root / "object"), "--surface", str(root / "surface"), "--lightmap",
               str(root / "scene_map.exr"), "--background", str(root / "background.exr"), "--mask",
               str(root / "object_mask.png"), "--surface-mask", str(root / "surface_mask.png"),
               "--sources", "sun", "-o", str(tmp_path / "x.exr")])
    assert rc == 2
