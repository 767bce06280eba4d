"""Hougen-Ahuja with a ground plane: sources above it, the light below it one uniform term (issue 11;
``docs/probes.md``, *A ground plane*). Small scenes: synthetic pixels or a 48 px ball, maps 16-64 rows."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.cli import main
from ffls.conventions import latlong_directions
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes.hougen_ahuja import average_fits, ground_column, hougen_ahuja
from ffls.probes.linear import irradiance_from_map
from ffls.probes.selection import adaptive_hougen_ahuja
from ffls.probes.sources import latlong_solid_angles
from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe

UP = np.array([0.0, 0.0, 1.0])


def _seen_normals(m=2500, elevation_deg=30.0, seed=0):
    """Normals of a ball seen from ``elevation_deg`` above the horizon (azimuth -90): the half facing the camera."""
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(m, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    e = np.radians(elevation_deg)
    v = np.array([0.0, -np.cos(e), np.sin(e)])
    return n[n @ v > 0]


def _lamp_and_ground(n, elevation_deg=3.0, lamp=3.0, ground=0.8):
    """Pixels (albedo 0.7) of a lamp of irradiance ``lamp`` a few degrees above the horizon (azimuth +60,
    behind the ball's seen side) and a uniform ground of power ``ground``."""
    e, a = np.radians(elevation_deg), np.radians(60.0)
    light = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    E = lamp * np.maximum(n @ light, 0.0) + ground * 0.25 * (1.0 - n[:, 2])
    return light, 0.7 / np.pi * E


def test_ground_column_is_the_irradiance_of_uniform_light_below_the_plane():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    h = 256
    d = latlong_directions(2 * h, h).reshape(-1, 3)
    sa = latlong_solid_angles(h).ravel()
    below = d[:, 2] < 0
    # a power of 1 over the lower hemisphere: radiance 1 / (its solid angle)
    rad = np.zeros((d.shape[0], 3))
    rad[below] = 1.0 / sa[below].sum()
    E = irradiance_from_map(n, (d, rad, sa))[:, 0]
    np.testing.assert_allclose(ground_column(n, UP), E, atol=2e-3)
    # facing straight down: pi x the radiance P / (2 pi) = P / 2; a vertical normal half that; facing up none
    np.testing.assert_allclose(ground_column(np.array([[0, 0, -1.0], [0, 0, 1.0], [1.0, 0, 0]]), UP),
                               [0.5, 0.0, 0.25])
    # the axis is any plane normal, normalised
    np.testing.assert_allclose(ground_column(n, (0, 0, 3.0)), ground_column(n, UP))
    for bad in ((0, 0, 0), (1, 2), (np.nan, 0, 1)):
        with pytest.raises(ValueError, match="ground"):
            ground_column(n, bad)


def test_ground_fit_keeps_the_sources_above_the_plane_and_its_map_the_energy():
    n = _seen_normals()
    light, rad = _lamp_and_ground(n)
    fit = hougen_ahuja(n, rad, 0.7, sources=92, nonnegative=True, ambient="auto", ground=UP)
    assert fit.ground is not None and fit.ground.shape == (3,)
    assert np.all(fit.directions @ UP >= -1e-12) and np.all(fit.ambient == 0)  # 'auto': no ambient
    L = fit.latlong(32)
    sa = latlong_solid_angles(32)
    d = latlong_directions(64, 32)
    np.testing.assert_allclose((L * sa[..., None]).sum(axis=(0, 1)), fit.intensities.sum(0) + fit.ground,
                               rtol=1e-9)
    below = d[..., 2] < 0
    np.testing.assert_allclose(L[below], np.broadcast_to(fit.ground / sa[below].sum(), L[below].shape), rtol=1e-9)
    np.testing.assert_allclose(fit.irradiance(n) * 0.7 / np.pi, fit.rendered, rtol=1e-9, atol=1e-12)
    assert fit.relative_rms < 0.08  # a dome of 91 nodes, the lamp between them
    with pytest.raises(ValueError, match="above"):
        hougen_ahuja(n, rad, 0.7, sources=-np.eye(3), nonnegative=True, ground=UP)
    plain = hougen_ahuja(n, rad, 0.7, sources=92, nonnegative=True, ambient="auto")
    assert plain.ground is None
    with pytest.raises(ValueError, match="ground"):
        average_fits([fit, plain], rad)


@pytest.mark.parametrize("seed", [0, 3])
def test_adaptive_ground_finds_a_lamp_just_above_the_horizon_in_every_orientation(seed):
    """A ball seen from 30 degrees above cannot tell a lamp 3 degrees above the horizon from one a few degrees
    below; with the ground plane every orientation (about its normal) puts the lamp's power above it, within
    10 degrees of the lamp, and the ground's power within 10%."""
    n = _seen_normals(seed=seed)
    light, rad = _lamp_and_ground(n)
    sel = adaptive_hougen_ahuja(n, rad, 0.7, nonnegative=True, ambient="auto", criterion="bic", max_sources=150,
                                ground=UP, orientations=3, orientation_seed=seed)
    assert len(sel.fit.members) == 3
    for f in sel.fit.members:
        assert np.all(f.directions @ UP >= -1e-9)  # turned about the normal: still above the plane
        p = f.intensities.sum(axis=1)
        near = f.directions @ light > np.cos(np.radians(10.0))
        assert p[near].sum() / 3 > 0.85 * 3.0, p[near].sum() / 3
        assert abs(f.ground.mean() / 0.8 - 1.0) < 0.10, f.ground
    np.testing.assert_allclose(sel.fit.ground, np.mean([f.ground for f in sel.fit.members], axis=0))


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    sc = diffuse_sphere_scene(builtin_lightmap("studio").downsample(16), resolution=48, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("studio"), sc)


def test_cli_ground(folder, tmp_path, capsys):
    out = tmp_path / "m.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--size", "16", "--criterion", "bic",
                 "--ground"]) == 0
    err = capsys.readouterr().err
    assert out.exists() and "ground plane" in err and "world +Z" in err
