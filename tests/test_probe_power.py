"""Hougen-Ahuja's least-total-power prior (issue 11; ``docs/probes.md``, *Least total power*): the
penalty on the sum of the sources' powers (``solve_sources(..., power=)``, ``hougen_ahuja(..., power=)``,
``select_regularization(..., 'power')``, ``diffuse_lightmap(prior='power')``, ``ffls probe diffuse --prior
power``)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ffls.cli import main
from ffls.conventions import latlong_directions, normalize
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes import estimate_lightmap
from ffls.probes.estimate import POWER_WEIGHTS
from ffls.probes.hougen_ahuja import hougen_ahuja
from ffls.probes.linear import lambert_matrix, solve_sources
from ffls.probes.selection import REGULARIZERS, adaptive_hougen_ahuja
from ffls.probes.sources import latlong_solid_angles
from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe

#: The probe benchmarks' camera (``benchmarks/common.py``'s capture): 30 degrees down, looking along +Y.
WORLD_FROM_CAMERA = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, -0.5, 0.866025403784, -0.866025403784],
                              [0.0, -0.866025403784, -0.5, 0.55], [0.0, 0.0, 0.0, 1.0]])


def test_least_power_takes_the_one_source_that_two_others_imitate():
    # pixels within 60 degrees of v see a lamp at v and two at v turned by +-20 degrees (each lighting them all):
    # on them the pair with powers P / (2 cos 20) is the lamp exactly, at 6% more power
    rng = np.random.default_rng(0)
    v = normalize(np.array([0.0, -0.8, 0.6]))
    n = normalize(rng.normal(size=(4000, 3)))
    n = n[n @ v > np.cos(np.radians(60.0))]
    axis = normalize(np.cross(v, [1.0, 0.0, 0.0]))
    turn = [Rotation.from_rotvec(axis * np.radians(a)).apply(v) for a in (20.0, -20.0)]
    d = np.stack([turn[0], v, turn[1]])
    M = lambert_matrix(n, d)
    b = 2.0 * (n @ v)[:, None]
    pair = M @ np.array([1.0, 0.0, 1.0]) / np.cos(np.radians(20.0))
    np.testing.assert_allclose(pair, b[:, 0], rtol=1e-12)  # the ball cannot tell them apart
    sol = solve_sources(M, b, nonnegative=True, power=0.001)
    assert sol.x[1, 0] == pytest.approx(2.0, rel=1e-3) and sol.x[[0, 2], 0].max() < 1e-3
    # a uniform weight on every power: the answer does not depend on which source comes first
    sol2 = solve_sources(M[:, ::-1], b, nonnegative=True, power=0.001)
    np.testing.assert_allclose(sol2.x[::-1], sol.x, atol=1e-9)
    assert "power" in REGULARIZERS
    fit = hougen_ahuja(n, b[:, 0] * 0.7 / np.pi, 0.7, d, nonnegative=True, ambient=False, power=0.001)
    np.testing.assert_allclose(fit.intensities, np.repeat(sol.x, 3, axis=1), atol=1e-9)


def _bands(directions, power):
    """Power (all channels) below -10 degrees, between -10 and 0, between 0 and 10, and above 10."""
    z, p = directions[:, 2], power.sum(axis=1)
    s = np.sin(np.radians(10.0))
    return np.array([p[(z >= lo) & (z < hi)].sum() for lo, hi in ((-2, -s), (-s, 0), (0, s), (s, 2))])


def test_least_power_keeps_studios_lamps_above_the_horizon_in_a_turned_source_set():
    # the benchmark's studio ball (64-row map, 80 px, seen 30 degrees from above) with the geodesic hierarchy in
    # ``probes_tv.py``'s orientation 2: plain NNLS moves the lamps 0-10 degrees high to just below the horizon
    # (9.1 of 20.6 between -10 and 0; truth 2.0), the least-power fit keeps them where they are (3.1), with the
    # same re-rendered error; ``docs/probes.md`` measures the relit capture 16.4% -> 2.8%
    lm = builtin_lightmap("studio")
    lm = lm.downsample(lm.res // 64)
    true = np.asarray(lm.data, dtype=np.float64)
    h = true.shape[0]
    texel_power = true.reshape(-1, 3) * latlong_solid_angles(h).reshape(-1, 1)
    truth = _bands(latlong_directions(2 * h, h).reshape(-1, 3), texel_power)
    sph = diffuse_sphere_scene(lm, 80, albedo=0.7, world_from_camera=WORLD_FROM_CAMERA)
    R = Rotation.random(4, random_state=0).as_matrix()[2]
    n = sph.normals @ R.T
    d = adaptive_hougen_ahuja(n, sph.radiance, 0.7, nonnegative=True, ambient="auto", rule="paired_se").fit.directions
    plain, least = (hougen_ahuja(n, sph.radiance, 0.7, d, nonnegative=True, ambient="auto", power=w)
                    for w in (0.0, 1e-4))
    bp, bl = (_bands(normalize(f.directions @ R), f.intensities) for f in (plain, least))
    assert bp[1] > 3.0 * truth[1] and bp[2] < 0.7 * truth[2]  # the lottery, without the prior
    assert bl[1] < 1.7 * truth[1] and bl[2] > 0.9 * truth[2]
    assert least.relative_rms < 1.1 * plain.relative_rms


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    sc = diffuse_sphere_scene(builtin_lightmap("studio").downsample(16), resolution=32, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("studio"), sc)


def test_prior_power_weight_by_cross_validation(folder, tmp_path, capsys):
    est = estimate_lightmap(folder, "diffuse", height=16, max_pixels=600, prior="power")
    assert est.details["prior"] == "power" and est.details["smoothness"] in POWER_WEIGHTS
    assert any(s.startswith("power penalty: cross-validation") for s in est.notes)
    # the default since the fifteenth stop: the power's weight by CV; a stated weight keeps weighing differences
    stated = estimate_lightmap(folder, "diffuse", height=16, max_pixels=600, smoothness=0.003)
    assert "prior" not in stated.details  # the quadratic prior at 0.003
    assert not np.array_equal(stated.lightmap.data, est.lightmap.data)
    out = tmp_path / "m.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--size", "16"]) == 0
    assert out.exists() and "power penalty: cross-validation" in capsys.readouterr().err
    bad = tmp_path / "bad.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(bad), "--size", "16", "--prior", "power",
                 "--smoothness", "0"]) == 2
    assert "--prior power weighs --smoothness" in capsys.readouterr().err and not bad.exists()
