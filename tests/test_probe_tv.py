"""Hougen-Ahuja with total variation on the source graph (issue 11): an edge-preserving prior.

The quadratic first-difference prior spreads a small bright lamp over its neighbours; total
variation (the L1 norm of the differences, by iteratively reweighted NNLS) charges a jump by its
height only, so the lamp keeps its peak while the broad sky around it stays even.
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.cli import main
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes import estimate_lightmap
from ffls.probes.hougen_ahuja import hougen_ahuja
from ffls.probes.linear import lambert_matrix, neighbour_edges, solve_sources
from ffls.probes.selection import select_regularization
from ffls.probes.sources import geodesic_sources
from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe


@pytest.fixture(scope="module")
def lamp_and_sky():
    """A ball's visible half (normals facing a camera 30 degrees above the horizon) lit by a broad sky
    over the upper hemisphere (intensity 1 per source of 162) and one small lamp (40 more in one source)."""
    d = geodesic_sources(4)
    rng = np.random.default_rng(0)
    n = rng.normal(size=(1500, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n = n[n @ np.array([0.0, -0.87, 0.5]) > 0]
    x = np.where(d[:, 2] > 0, 1.0, 0.0)
    want = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])
    lamp = int(np.argmin(np.linalg.norm(d - want, axis=1)))
    x[lamp] += 40.0
    return n, lambert_matrix(n, d) @ x * 0.7 / np.pi, d, x, lamp


def test_tv_keeps_a_small_lamp_that_the_quadratic_prior_spreads(lamp_and_sky):
    n, b, d, x, lamp = lamp_and_sky
    sky = d[:, 2] > 0.3
    kw = {"ambient": False, "nonnegative": True}
    quad = hougen_ahuja(n, b, 0.7, d, smoothness=0.01, **kw)
    tv = hougen_ahuja(n, b, 0.7, d, tv=0.01, **kw)
    # the quadratic prior at this weight loses over a third of the lamp's peak; TV keeps it within 5%
    assert quad.intensities[lamp, 0] < 0.7 * x[lamp]
    assert abs(tv.intensities[lamp, 0] - x[lamp]) < 0.05 * x[lamp]
    assert abs(np.median(tv.intensities[sky, 0]) - 1.0) < 0.05  # the sky stays even
    assert tv.relative_rms < quad.relative_rms
    assert np.all(tv.intensities >= 0)


def test_tv_solver_reweights_and_stops(lamp_and_sky):
    n, b, d, x, lamp = lamp_and_sky
    M = lambert_matrix(n, d)
    e = neighbour_edges(d)
    target = np.repeat(np.pi * b[:, None] / 0.7, 3, axis=1)
    once = solve_sources(M, target, nonnegative=True, tv=0.03, edges=e, tv_rounds=0)  # the quadratic fit
    quad = solve_sources(M, target, nonnegative=True, smoothness=0.03, edges=e)
    assert np.allclose(once.x, quad.x)
    more = solve_sources(M, target, nonnegative=True, tv=0.03, edges=e)
    assert more.x[lamp, 0] > once.x[lamp, 0] + 0.2 * x[lamp]
    # unconstrained (lstsq) too, and the weight 0 is the plain fit
    assert solve_sources(M, target, tv=0.03, edges=e).x.shape == (d.shape[0], 3)
    plain = solve_sources(M, target, nonnegative=True)
    assert np.allclose(solve_sources(M, target, nonnegative=True, tv=0.0, edges=e).x, plain.x)
    with pytest.raises(ValueError, match="need the edges"):
        solve_sources(M, target, nonnegative=True, tv=0.03)


def test_tv_weight_chosen_by_cv(lamp_and_sky):
    n, b, d, x, lamp = lamp_and_sky
    sel = select_regularization(n, b, 0.7, d, (0.0, 0.01), penalty="tv", nonnegative=True, ambient=False)
    assert sel.chosen in (0.0, 0.01) and "tv penalty" in sel.note
    assert abs(sel.fit.intensities[lamp, 0] - x[lamp]) < 0.1 * x[lamp]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    sc = diffuse_sphere_scene(builtin_lightmap("night").downsample(16), resolution=48, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("night"), sc)


def test_prior_tv_in_the_estimate_and_cli(folder, tmp_path, capsys):
    est = estimate_lightmap(folder, "diffuse", height=16, sources=42, smoothness="cv", prior="tv")
    assert est.details["prior"] == "tv" and "smoothness" in est.details
    assert any("tv penalty: cross-validation" in s for s in est.notes)
    fixed = estimate_lightmap(folder, "diffuse", height=16, sources=42, smoothness=0.01, prior="tv")
    quad = estimate_lightmap(folder, "diffuse", height=16, sources=42, smoothness=0.01)
    assert not np.allclose(fixed.lightmap.data, quad.lightmap.data)
    with pytest.raises(ValueError, match="prior must be one of"):
        estimate_lightmap(folder, "diffuse", height=16, sources=42, smoothness=0.01, prior="l1")
    out = tmp_path / "m.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--size", "16", "--sources", "42",
                 "--smoothness", "0.01", "--prior", "tv"]) == 0 and out.exists()
    capsys.readouterr()
    bad = tmp_path / "bad.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(bad), "--size", "16", "--prior", "tv",
                 "--smoothness", "0"]) == 2
    err = capsys.readouterr().err
    assert "--prior tv weighs --smoothness" in err and len(err.strip().splitlines()) == 1 and not bad.exists()
