"""Hougen-Ahuja with the source hierarchy's vertex on the world's up, averaged over azimuths (issue 11;
``docs/probes.md``, *The horizon fixed, the azimuth averaged*). Small scenes: synthetic pixels or a 32 px
ball, maps 16 rows."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.cli import main
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes import estimate_lightmap
from ffls.probes.hougen_ahuja import hougen_ahuja
from ffls.probes.selection import HIERARCHY_PERIOD_DEG, horizon_rotations, oriented_fits
from ffls.probes.sources import geodesic_level
from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe


@pytest.mark.parametrize("up", [(0.0, 0.0, 1.0), (0.3, -0.2, 0.9)])
def test_horizon_rotations_keep_the_elevations_and_turn_the_azimuth(up):
    up = np.asarray(up) / np.linalg.norm(up)
    d = geodesic_level(3, 1)  # the hierarchy in its own frame (a vertex on +Z)
    rots = horizon_rotations(up, 4)
    assert rots.shape == (4, 3, 3)
    if up[2] == 1.0:
        np.testing.assert_array_equal(rots[0], np.eye(3))  # the hierarchy's own orientation, to the bit
    worlds = [d @ R for R in rots]  # the world's sources of each member (R^T d')
    for w, R in zip(worlds, rots):
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(np.array([0.0, 0.0, 1.0]) @ R, up, atol=1e-12)  # the vertex on up
        np.testing.assert_allclose(np.sort(w @ up), np.sort(d[:, 2]), atol=1e-12)  # the same elevations
    # member k is member 0 turned about up by k steps of a quarter of the period
    for k in range(1, 4):
        turn = rots[0].T @ rots[k]  # world(k) = world(0) @ turn
        c = np.cos(np.radians(HIERARCHY_PERIOD_DEG * k / 4))
        assert abs((np.trace(turn) - 1.0) / 2.0 - c) < 1e-12 and np.allclose(up @ turn, up, atol=1e-12)
        assert not np.allclose(worlds[k], worlds[0])
    # a full period maps the hierarchy onto itself
    full = d @ (horizon_rotations(up, 1)[0].T @ horizon_rotations(up, 1)[0])
    assert np.allclose(full, d)
    with pytest.raises(ValueError, match="azimuths"):
        horizon_rotations(up, 0)


def test_oriented_fits_find_a_light_in_the_world_frame():
    light = np.array([0.5, -0.6, 0.4])
    light /= np.linalg.norm(light)
    rng = np.random.default_rng(0)
    n = rng.normal(size=(900, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[:, 1] = -np.abs(n[:, 1])
    rad = 0.7 / np.pi * 2.0 * np.maximum(n @ light, 0.0)
    seen = []

    def one(turned):
        seen.append(turned)
        fit = hougen_ahuja(turned, rad, 0.7, geodesic_level(4, 1), ambient=False, nonnegative=True)
        return fit, fit.directions.shape[0]

    fits, sizes = oriented_fits(n, horizon_rotations((0.0, 0.0, 1.0), 3), one)
    assert seen[0] is n and len(fits) == 3 and sizes == [fits[0].directions.shape[0]] * 3
    for f in fits:
        p = f.intensities.sum(axis=1)
        mean = (p[:, None] * f.directions).sum(axis=0)
        assert np.degrees(np.arccos(np.clip(mean @ light / np.linalg.norm(mean), -1, 1))) < 3.0
    assert not np.allclose(fits[1].directions, fits[0].directions)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    sc = diffuse_sphere_scene(builtin_lightmap("studio").downsample(16), resolution=32, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("studio"), sc)


def test_azimuths_average_the_members_and_the_default_is_one(folder):
    est = estimate_lightmap(folder, "diffuse", height=16, max_pixels=600, azimuths=4)
    assert est.details["azimuths"] == 4
    assert len(est.details["sources"]) == 4 and len(est.details["smoothness"]) == 4
    assert any("4 azimuths 18 degrees apart" in s for s in est.notes)
    assert any("within one paired standard error" in s for s in est.notes)
    one = estimate_lightmap(folder, "diffuse", height=16, max_pixels=600)  # the default: one estimate
    assert "azimuths" not in one.details and isinstance(one.details["sources"], int)
    assert isinstance(one.details["smoothness"], float)
    assert not np.allclose(est.lightmap.data, one.lightmap.data)  # the mean of 4 is not its first member
    for bad in ({"azimuths": 2, "ground": True}, {"azimuths": 2, "sources": "uniform"},
                {"azimuths": 2, "orientations": 2}, {"azimuths": 0}):
        with pytest.raises(ValueError, match="azimuths"):
            estimate_lightmap(folder, "diffuse", height=16, max_pixels=600, **bad)


def test_cli_azimuths(folder, tmp_path, capsys):
    out = tmp_path / "m.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--size", "16", "--azimuths", "2"]) == 0
    assert out.exists() and "2 azimuths 36 degrees apart" in capsys.readouterr().err
    for bad in (["--azimuths", "0"], ["--azimuths", "2", "--ground"], ["--azimuths", "2", "--sources", "uniform"],
                ["--azimuths", "3", "--orientations", "2", "--smoothness", "0"]):
        assert main(["probe", "diffuse", str(folder), "-o", str(tmp_path / "x.exr"), *bad]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "azimuths" in err and "Traceback" not in err
        assert not (tmp_path / "x.exr").exists()
