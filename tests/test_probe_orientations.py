"""Hougen-Ahuja averaged over orientations of its source set (issue 11; ``docs/probes.md``, *The
orientation of the source set*). Small scenes: synthetic pixels or 48 px balls, maps 16-32 rows."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.cli import main
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes import estimate_lightmap
from ffls.probes.hougen_ahuja import SourceEnsemble, average_fits, hougen_ahuja
from ffls.probes.selection import adaptive_hougen_ahuja
from ffls.probes.sources import geodesic_sources, latlong_solid_angles
from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe


def _ball(light, n_px=900, seed=0):
    """Normals of the half of a ball facing -Y and its Lambertian pixels (albedo 0.7) under one source."""
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(n_px, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[:, 1] = -np.abs(n[:, 1])
    return n, 0.7 / np.pi * 2.0 * np.maximum(n @ light, 0.0)


def test_average_fits_is_the_mean_of_the_members():
    light = np.array([0.3, -0.5, 0.6])
    light /= np.linalg.norm(light)
    n, rad = _ball(light)
    a = hougen_ahuja(n, rad, 0.7, geodesic_sources(2), ambient=False, nonnegative=True)
    b = hougen_ahuja(n, rad, 0.7, geodesic_sources(3), ambient=False, nonnegative=True)
    ens = average_fits([a, b], rad)
    assert isinstance(ens, SourceEnsemble)
    np.testing.assert_allclose(ens.latlong(16), (a.latlong(16) + b.latlong(16)) / 2, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ens.rendered, (a.rendered + b.rendered) / 2)
    # the union of sources with half the intensities renders the same pixels as the map's mean
    E = np.maximum(n @ ens.directions.T, 0.0) @ ens.intensities * 0.7 / np.pi
    np.testing.assert_allclose(E, ens.rendered, rtol=1e-9, atol=1e-12)
    power = np.sum(ens.latlong(16) * latlong_solid_angles(16)[..., None], axis=(0, 1))
    np.testing.assert_allclose(power, ens.intensities.sum(axis=0), rtol=1e-9)
    with pytest.raises(ValueError, match="no fits"):
        average_fits([], rad)


def test_orientations_turn_the_sources_back_into_the_world_frame():
    """Each member finds a single source where it is (a wrong rotation, R instead of its transpose,
    would put the light elsewhere), and the first member is the plain estimate."""
    light = np.array([0.5, -0.6, 0.4])
    light /= np.linalg.norm(light)
    n, rad = _ball(light)
    kw = dict(nonnegative=True, ambient="auto", max_sources=150, criterion="bic")
    plain = adaptive_hougen_ahuja(n, rad, 0.7, **kw)
    sel = adaptive_hougen_ahuja(n, rad, 0.7, orientations=3, orientation_seed=2, **kw)
    assert isinstance(sel.fit, SourceEnsemble) and len(sel.chosen) == 3 and len(sel.fit.members) == 3
    np.testing.assert_array_equal(sel.fit.members[0].intensities, plain.fit.intensities)
    assert sel.chosen[0] == plain.chosen and "3 orientations" in sel.note
    for f in sel.fit.members:
        p = f.intensities.sum(axis=1)
        mean = (p[:, None] * f.directions).sum(axis=0)
        assert np.degrees(np.arccos(np.clip(mean @ light / np.linalg.norm(mean), -1, 1))) < 3.0
        assert abs(p.sum() / 6.0 - 1.0) < 0.05  # the source's power, 2 in each channel
    # the other members' sources are not the hierarchy's own directions
    assert not np.allclose(sel.fit.members[1].directions[:12], plain.fit.directions[:12])
    assert sel.fit.relative_rms < 0.02
    with pytest.raises(ValueError, match="orientations"):
        adaptive_hougen_ahuja(n, rad, 0.7, orientations=0, **kw)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    sc = diffuse_sphere_scene(builtin_lightmap("night").downsample(16), resolution=48, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("night"), sc)


def test_cli_orientations(folder, tmp_path, capsys):
    out = tmp_path / "m.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--size", "16", "--criterion", "bic",
                 "--orientations", "2"]) == 0
    assert out.exists() and "the mean of 2 fits" in capsys.readouterr().err
    for bad in (["--orientations", "0"], ["--orientations", "2", "--sources", "uniform"],
                ["--orientations", "2", "--smoothness", "cv"]):
        assert main(["probe", "diffuse", str(folder), "-o", str(tmp_path / "x.exr"), *bad]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "orientations" in err and "Traceback" not in err
        assert not (tmp_path / "x.exr").exists()
    with pytest.raises(ValueError, match="orientations"):
        estimate_lightmap(folder, "diffuse", height=16, sources="uniform", orientations=2)


def test_orientation_benchmark_takes_one_orientation():
    """``benchmarks/probes_orientation.py --orientations 1`` crashed: the plain estimate is a SourceFit
    (no members) and one size; its parts are the one member, its size and its chosen round's score."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from probes_orientation import ensemble_parts

    light = np.array([0.5, -0.6, 0.4])
    light /= np.linalg.norm(light)
    n, rad = _ball(light)
    kw = dict(nonnegative=True, ambient="auto", max_sources=150, criterion="bic")
    one = adaptive_hougen_ahuja(n, rad, 0.7, **kw)
    members, sizes, heldout = ensemble_parts(one)
    assert members == (one.fit,) and sizes == [one.chosen]
    assert heldout == [float(one.scores[list(one.candidates).index(one.chosen)])]
    two = adaptive_hougen_ahuja(n, rad, 0.7, orientations=2, **kw)
    members, sizes, heldout = ensemble_parts(two)
    assert members == two.fit.members and sizes == list(two.chosen) and len(heldout) == 2
