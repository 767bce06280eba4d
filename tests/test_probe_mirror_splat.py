"""Mirror-ball unwrap by forward splatting (``debevec.splat_mirror_ball``) against bilinear backward sampling."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from ffls.conventions import latlong_directions
from ffls.lightmaps.lightmap import LightMap, LightMapWarning, builtin_lightmap
from ffls.probes import estimate_lightmap
from ffls.probes.debevec import (latlong_solid_angles, splat_mirror_ball, splat_supersample,
                                 unwrap_mirror_ball_Debevec1998)
from ffls.synth.probe import look_at, render_mirror_ball, write_mirror_probe


def _rel(a, b, mask):
    sa = latlong_solid_angles(a.shape[0])[..., None]
    return float(np.sqrt((sa * (a - b) ** 2)[mask].sum() / (sa * b ** 2)[mask].sum()))


def _smooth_map(h=64):
    d = latlong_directions(2 * h, h)
    return np.stack([1 + 0.5 * d[..., 0], 1 + 0.5 * d[..., 1], 1 + 0.5 * d[..., 2] + 0.3 * d[..., 0] * d[..., 1]],
                    -1).astype(np.float32)


def _lamp_map(direction, radius_deg=1.0, h=256, power=50.0, sky=0.05):
    """A dim uniform sky and one small disc lamp of the given power (W m^-2 at normal incidence)."""
    d = latlong_directions(2 * h, h)
    sa = latlong_solid_angles(h)
    disc = d @ (np.asarray(direction, float) / np.linalg.norm(direction)) >= np.cos(np.radians(radius_deg))
    L = np.full((h, 2 * h, 3), sky)
    L[disc] += power / sa[disc].sum()
    return L.astype(np.float32), disc


def _pinhole(distance, f_per_m=700.0, size=256):
    f = f_per_m * distance
    return np.array([[f, 0, size / 2], [0, f, size / 2], [0, 0, 1.0]])


@pytest.mark.parametrize("camera", ["pinhole", "orthographic"])
def test_splat_recovers_a_smooth_map(camera):
    """Every pixel lands on the directions it reflects: a smooth map comes back to 0.3% over the seen texels."""
    lm = _smooth_map()
    T = look_at([0.2, -20.0, 6.0])
    if camera == "pinhole":
        K = _pinhole(20.0)
        img, _ = render_mirror_ball(lm, (256, 256), K=K, world_from_camera=T, radius=0.1, supersample=3)
        geo = dict(K=K, center_cam=np.linalg.inv(T)[:3, 3], radius=0.1)
    else:
        img, _ = render_mirror_ball(lm, (200, 200), "orthographic", world_from_camera=T, center_px=(101.3, 98.7),
                                    radius_px=90, supersample=3)
        geo = dict(center_px=(101.3, 98.7), radius_px=90)
    rad, w = splat_mirror_ball(img, camera, world_from_camera=T, height=64, **geo)
    mv = unwrap_mirror_ball_Debevec1998(img, camera, world_from_camera=T, height=64, camera_cone_deg=0, **geo)
    seen = mv.confidence > 0
    covered = w > 0
    # the splat covers what the backward map sees, but for texels at the rim and the blind spot's edge
    assert latlong_solid_angles(64)[seen & ~covered].sum() < 0.02 * latlong_solid_angles(64)[seen].sum()
    assert _rel(rad, lm, seen & covered) < 0.003
    assert _rel(mv.radiance, lm, seen) < 0.003


def test_splat_keeps_a_small_lamp_in_place():
    """A 1-degree lamp: its power is kept, and more of it stays within 3 degrees of it than with bilinear sampling."""
    lamp = np.array([0.3, -0.8, 0.5])
    L, _ = _lamp_map(lamp)
    T = look_at([0.0, -20.0, 10.0])
    K = _pinhole(20.0)
    img, _ = render_mirror_ball(L, (256, 256), K=K, world_from_camera=T, radius=0.1, supersample=4)
    C = np.linalg.inv(T)[:3, 3]
    d = latlong_directions(128, 64)
    sa = latlong_solid_angles(64)
    near = d @ (lamp / np.linalg.norm(lamp)) >= np.cos(np.radians(3.0))
    out = {}
    for mode in ("splat", "bilinear"):
        mv = unwrap_mirror_ball_Debevec1998(img, "pinhole", K, None, T, C, 0.1, height=64, camera_cone_deg=0,
                                            resample=mode)
        p = (mv.radiance.astype(np.float64) * sa[..., None]).sum(axis=2)
        out[mode] = (p[near].sum() - 3 * 0.05 * sa[near].sum(), p[mv.confidence > 0].sum())
    total = 3 * (50.0 + 0.05 * 4 * np.pi)
    assert out["splat"][1] == pytest.approx(total, rel=0.03)  # every pixel's power kept (blind spot aside)
    assert out["splat"][0] > out["bilinear"][0]
    assert out["splat"][0] > 0.9 * 3 * 50.0


def test_splat_supersample_and_bad_mode():
    assert splat_supersample(70.0, 64) == 8 and splat_supersample(10.0, 512) == 16
    with pytest.raises(ValueError, match="resample"):
        unwrap_mirror_ball_Debevec1998(np.zeros((8, 8, 3)), "orthographic", world_from_camera=np.eye(4),
                                       center_px=(4, 4), radius_px=3, height=8, resample="nearest")


def test_splat_leaves_out_invalid_pixels_and_the_camera_cone():
    lm = _smooth_map()
    T = look_at([0.0, -1.0, 0.0])
    img, _ = render_mirror_ball(lm, (200, 200), "orthographic", world_from_camera=T, center_px=(100, 100),
                                radius_px=90, supersample=2)
    valid = np.ones((200, 200), bool)
    valid[:, :100] = False  # the left half of the ball
    geo = dict(center_px=(100, 100), radius_px=90, world_from_camera=T, height=32)
    _, w_all = splat_mirror_ball(img, "orthographic", **geo)
    _, w_half = splat_mirror_ball(img, "orthographic", valid=valid, **geo)
    assert 0.4 < w_half.sum() / w_all.sum() < 0.6
    _, w_cone = splat_mirror_ball(img, "orthographic", toward=[0, -1, 0], camera_cone_deg=20, **geo)
    d = latlong_directions(64, 32)
    assert not np.any(w_cone[(d @ [0, -1, 0]) > np.cos(np.radians(14))] > 0)  # texels 5.6 deg: wholly inside


def test_night_from_20_m_one_view_within_2_percent(tmp_path):
    """Issue 11's mirror goal on the map it missed: one view from 20 m, from the capture camera's direction."""
    from ffls.io.capture import load_capture_and_lights
    from ffls.relight.cpu import relight_capture
    from ffls.synth.scene import make_scene, write_synthetic_capture

    write_synthetic_capture(tmp_path / "cap", n_lights=100, resolution=48, progress=False, seed=1)
    cap, lights = load_capture_and_lights(tmp_path / "cap")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LightMapWarning)
        full = builtin_lightmap("night", 512)
    truth = full.downsample(8)
    back = -make_scene().world_from_camera()[:3, 2]
    write_mirror_probe(tmp_path / "p", full.downsample(2), (256, 256), K=_pinhole(20.0),
                       world_from_camera=look_at(20.0 * back), radius=0.1, reflectance=0.7)
    a = relight_capture(cap, lights, truth)[0]
    m = a.sum(-1) > 0
    err = {}
    for mode in ("splat", "bilinear"):
        est = estimate_lightmap(tmp_path / "p", "mirror", height=64, resample=mode)
        b = relight_capture(cap, lights, est.lightmap)[0]
        err[mode] = float(np.sqrt(((a - b) ** 2)[m].sum() / (a ** 2)[m].sum()))
    assert err["splat"] < 0.02 and err["splat"] < 0.85 * err["bilinear"], err
    assert isinstance(est.lightmap, LightMap)
