"""POCS (Singh and Ahuja): the sweep's triangular solve, and POCS over adaptive geodesic source sets."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import latlong_directions
from ffls.errors import InputError
from ffls.lightmaps.lightmap import LightMap
from ffls.probes import singh_ahuja as sa_module
from ffls.probes.evaluate import relit_error
from ffls.probes.singh_ahuja import adaptive_singh_ahuja, pocs, singh_ahuja, singh_ahuja_sources
from ffls.probes.sources import latlong_solid_angles
from ffls.synth.probe_scenes import diffuse_sphere_scene


def _row_by_row(H, g, iterations, upper=None, order="random", seed=0):
    """The projections of Singh and Ahuja one row at a time (eq. 10 with delta 0, then eq. 8)."""
    norm2 = np.einsum("ij,ij->i", H, H)
    rows = np.flatnonzero(norm2 > 0)
    f = np.zeros((H.shape[1], g.shape[1]))
    rng = np.random.default_rng(seed)
    for _ in range(iterations):
        for i in (rng.permutation(rows) if order == "random" else rows):
            f += np.outer(H[i] / norm2[i], g[i] - H[i] @ f)
        hi = np.inf if upper is None else np.asarray(upper, dtype=float).reshape(-1, 1) if np.ndim(upper) else upper
        np.clip(f, 0.0, hi, out=f)
    return f


@pytest.fixture(scope="module")
def system():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    w = rng.normal(size=(80, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    H = np.maximum(n @ w.T, 0.0)
    H[7] = 0.0  # a pixel no source lights: no constraint
    g = H @ np.maximum(rng.normal(size=(80, 3)), 0.0) + 0.01 * rng.normal(size=(300, 3))
    return H, g


@pytest.mark.parametrize("order", ["random", "sequential"])
@pytest.mark.parametrize("upper", [None, 0.8, "per-source"])
def test_sweep_is_the_row_projections(system, monkeypatch, order, upper):
    """One triangular solve per sweep gives exactly the projections applied one row at a time, in blocks too."""
    H, g = system
    up = np.linspace(0.5, 1.5, H.shape[1]) if upper == "per-source" else upper
    ref = _row_by_row(H, g, 6, up, order, seed=4)
    f, res = pocs(H, g, 6, upper=up, order=order, seed=4)
    np.testing.assert_allclose(f, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    assert res.shape == (7,) and res[-1] < res[1] < res[0] == 1.0
    monkeypatch.setattr(sa_module, "BLOCK", 37)  # blocks of 37 rows: f updated between them
    fb, _ = pocs(H, g, 6, upper=up, order=order, seed=4)
    np.testing.assert_allclose(fb, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


def test_soft_threshold_projection_still_converges(system):
    H, g = system
    f, res = pocs(H, g, 20, delta=0.05)
    r = np.abs(g - H @ f)
    assert res[-1] < 0.1 and np.median(r) < 0.1


def _lamp_scene(res=56):
    """A dim sky and a 4-degree lamp 25 degrees high: what a fixed grid smears and an adaptive set can hold."""
    h = 64
    d = latlong_directions(2 * h, h)
    lamp = np.array([np.cos(np.radians(25)) * np.cos(0.6), np.cos(np.radians(25)) * np.sin(0.6) * -1,
                     np.sin(np.radians(25))])
    disc = d @ lamp >= np.cos(np.radians(4.0))
    L = np.full((h, 2 * h, 3), 0.05, dtype=np.float64)
    L[disc] += 30.0 / latlong_solid_angles(h)[disc].sum()
    sc = diffuse_sphere_scene(LightMap(L.astype(np.float32), "latlong"), res, albedo=0.7)
    return sc, L, lamp


@pytest.fixture(scope="module")
def lamp():
    return _lamp_scene()


@pytest.mark.parametrize("criterion", ["bic", "cv"])
def test_adaptive_pocs_refines_at_the_lamp(lamp, criterion):
    sc, L, lamp_dir = lamp
    sel = adaptive_singh_ahuja(sc.normals, sc.radiance, 0.7, iterations=30, max_pixels=800, criterion=criterion)
    fit = sel.fit
    # rounds grow the set; the choice is one of them and is reported
    assert sel.candidates[0] == 92 and all(b > a for a, b in zip(sel.candidates, sel.candidates[1:]))
    assert sel.chosen in sel.candidates and fit.directions.shape[0] == sel.chosen
    assert "POCS over adaptive sources" in sel.note and str(sel.chosen) in sel.note
    assert sel.chosen > 92  # a compact lamp is worth refining
    # the sources were split where the light is: the nearest source to the lamp is finer than the base spacing
    # (92 directions: about 23 degrees apart), and it carries the most power
    ang = np.degrees(np.arccos(np.clip(fit.directions @ lamp_dir, -1, 1)))
    near = np.sort(ang)[:6]
    assert near[-1] < 12.0
    assert ang[np.argmax(fit.intensities.sum(axis=1))] < 8.0
    # convergence measured: the chosen round's residual per sweep
    assert fit.residuals.shape == (31,) and fit.residuals[-1] < 0.05 * fit.residuals[0]
    assert fit.intensities.min() >= 0 and fit.rendered.shape == sc.radiance.shape
    # the power is right, and the probe relights its own normals within 5% (30 sweeps)
    Lr = fit.latlong(64)
    w = latlong_solid_angles(64)[..., None]
    assert (Lr * w).sum() == pytest.approx((L * w).sum(), rel=0.05)
    assert relit_error(Lr, L, sc.normals) < 0.05


def test_adaptive_beats_the_fixed_grid_on_a_compact_lamp(lamp):
    """The point of adaptive sets: a sphere of normals relit under the estimate, against the 16 x 32 grid."""
    sc, L, _ = lamp
    sel = adaptive_singh_ahuja(sc.normals, sc.radiance, 0.7, iterations=30, max_pixels=800, criterion="bic")
    grid = singh_ahuja(sc.normals, sc.radiance, 0.7, height=16, iterations=30, max_pixels=800)
    e_ad = relit_error(sel.fit.latlong(64), L, hemisphere="full")
    e_grid = relit_error(grid.latlong(64), L, hemisphere="full")
    assert e_ad < e_grid


def test_pocs_over_sources_bad_input(lamp):
    sc, _, _ = lamp
    with pytest.raises(InputError, match="no pixels"):
        singh_ahuja_sources(np.zeros((0, 3)), np.zeros((0, 3)), 0.7, [[0, 0, 1.0]])
    with pytest.raises(InputError, match="no pixel is lit"):  # every normal faces away from the only source
        singh_ahuja_sources(np.tile([0, 0, -1.0], (10, 1)), np.ones((10, 3)), 0.7, [[0, 0, 1.0]], iterations=2)
    with pytest.raises(ValueError, match="criterion"):
        adaptive_singh_ahuja(sc.normals, sc.radiance, 0.7, criterion="aic")
    with pytest.raises(InputError, match="NaN"):
        adaptive_singh_ahuja(np.full((5, 3), np.nan), np.ones((5, 3)), 0.7)
