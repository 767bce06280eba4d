"""Hougen-Ahuja's ambient term with full-sphere source sets, and the smoothness weight chosen by CV (issue 11).

Sources over the whole sphere already hold any uniform light, so ``ambient='auto'`` (the default of
``ffls probe diffuse``) leaves the ambient column out there and keeps it for the paper's hemispherical
rings. ``smoothness='cv'`` chooses the first-difference weight on the chosen set by blocked CV.
Small scenes (48-64 px balls, maps 16-32 rows).
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.cli import main
from ffls.conventions import latlong_directions
from ffls.lightmaps.lightmap import LightMap, builtin_lightmap
from ffls.probes import estimate_lightmap
from ffls.probes.hougen_ahuja import hougen_ahuja, resolve_ambient
from ffls.probes.linear import lambert_matrix
from ffls.probes.selection import select_hougen_ahuja
from ffls.probes.sources import geodesic_sources
from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    truth = builtin_lightmap("night").downsample(16)  # 32 x 64
    sc = diffuse_sphere_scene(truth, resolution=48, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("night"), sc)


def test_resolve_ambient():
    assert resolve_ambient("auto", True, "full") is False
    assert resolve_ambient("auto", False, "full") is False
    assert resolve_ambient("auto", True, {"axis": [0, 0, 1]}) == "nonnegative"
    assert resolve_ambient("auto", True, "upper") == "nonnegative"
    assert resolve_ambient("auto", False, "upper") is True
    for given in (True, False, "free", "nonnegative"):
        assert resolve_ambient(given, True, "full") == given
    for bad in ("none", 2, 0.5):
        with pytest.raises(ValueError, match="ambient must be one of"):
            resolve_ambient(bad, True)


def test_full_sphere_sources_hold_a_uniform_ambient():
    """The reason for 'auto': a uniform map is a non-negative combination of the geodesic sources,
    so the ambient column is redundant with them (to the cells' discretisation)."""
    rng = np.random.default_rng(0)
    n = rng.normal(size=(400, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = geodesic_sources(6)
    fit = hougen_ahuja(n, np.full((400, 3), 0.7), 0.7, d, ambient=False, nonnegative=True)  # uniform irradiance pi
    assert fit.relative_rms < 0.01 and np.all(fit.intensities >= 0)
    # the hemispherical rings cannot: the ambient carries the other half
    ring = hougen_ahuja(n, np.full((400, 3), 0.7), 0.7, 17, ambient="auto", nonnegative=True)
    assert np.all(ring.ambient > 0)
    assert lambert_matrix(n, d).shape == (400, d.shape[0])


def test_auto_ambient_is_left_out_for_geodesic_sets_and_kept_for_rings():
    h = 16
    w = latlong_directions(2 * h, h)
    L = np.where(w[..., 2:3] > 0, 0.4, 0.1) * np.ones(3)  # a bright upper half: the rings need an ambient
    sph = diffuse_sphere_scene(LightMap(L.astype(np.float32), "latlong", "halves"), 48, albedo=0.7)
    geo = hougen_ahuja(sph.normals, sph.radiance, 0.7, 92, ambient="auto", nonnegative=True)
    assert np.all(geo.ambient == 0)
    rings = hougen_ahuja(sph.normals, sph.radiance, 0.7, 9, ambient="auto", nonnegative=True)
    assert np.all(rings.ambient > 0)
    # the uniform selection resolves it per candidate (rings keep it, geodesic sets do not)
    sel = select_hougen_ahuja(sph.normals, sph.radiance, 0.7, candidates=(9, 42), criterion="bic",
                              nonnegative=True, ambient="auto")
    assert (np.all(sel.fit.ambient > 0)) == (sel.chosen == 9)


def test_diffuse_default_has_no_ambient_with_geodesic_sources(folder, tmp_path, capsys):
    est = estimate_lightmap(folder, "diffuse", height=16, sources=92)
    assert any("no ambient" in s for s in est.notes)
    # the paper's rings keep it; a non-negative ambient is still there when asked for
    assert any("non-negative ambient" in s for s in estimate_lightmap(folder, "diffuse", height=16, sources=9).notes)
    est2 = estimate_lightmap(folder, "diffuse", height=16, sources=92, ambient="nonnegative")
    assert any("non-negative ambient" in s for s in est2.notes)
    out = tmp_path / "m.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--size", "16", "--sources", "92"]) == 0
    assert "no ambient" in capsys.readouterr().err


def test_smoothness_chosen_by_cv(folder, tmp_path, capsys):
    est = estimate_lightmap(folder, "diffuse", height=16, sources=42, smoothness="cv", prior="quadratic")
    w = est.details["smoothness"]
    assert w in (0.0, 0.001, 0.003, 0.01, 0.03)
    assert any("smoothness penalty: cross-validation" in s for s in est.notes)
    out = tmp_path / "m.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--size", "16", "--sources", "42",
                 "--smoothness", "cv", "--prior", "quadratic"]) == 0
    assert "smoothness penalty" in capsys.readouterr().err
    # the default prior with a cv weight (since the fifteenth stop): the total power's
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--size", "16", "--sources", "42",
                 "--smoothness", "cv"]) == 0
    assert "power penalty" in capsys.readouterr().err
    # with the rings the refit keeps their hemisphere and their ambient
    ring = estimate_lightmap(folder, "diffuse", height=16, sources=9, smoothness="cv")
    assert any("non-negative ambient" in s for s in ring.notes) and ring.details["sources"] == 9
    with pytest.raises(ValueError, match="smoothness must be"):
        estimate_lightmap(folder, "diffuse", height=16, sources=42, smoothness="gcv")


def test_smoothness_cv_refused_for_shadow_and_bad_words(folder, tmp_path, capsys):
    out = tmp_path / "m.exr"
    assert main(["probe", "shadow", str(folder), "-o", str(out), "--smoothness", "cv"]) == 2
    err = capsys.readouterr().err
    assert "--smoothness cv applies to diffuse" in err and len(err.strip().splitlines()) == 1
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--smoothness", "often"]) == 2
    err = capsys.readouterr().err
    assert "--smoothness" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
