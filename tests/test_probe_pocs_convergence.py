"""POCS (Singh and Ahuja): extrapolated parallel projections converge; the projections still project."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import nnls

from ffls.probes.singh_ahuja import PROJECTION_SCHEMES, pocs, singh_ahuja_sources


def _kernel(rng, pixels=400, sources=60):
    n = rng.normal(size=(pixels, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    w = rng.normal(size=(sources, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    H = np.maximum(n @ w.T, 0.0)
    return H[H.sum(axis=1) > 0], n, w


@pytest.fixture(scope="module")
def noisy_system():
    """A clamped-cosine kernel, six sources lit, 1% noise: the residual hyperplanes have no common point."""
    rng = np.random.default_rng(5)
    H, _, _ = _kernel(rng)
    f = np.zeros((H.shape[1], 1))
    f[rng.choice(H.shape[1], 6, replace=False), 0] = rng.uniform(1.0, 3.0, 6)
    g = H @ f
    return H, g + 0.01 * g.std() * rng.normal(size=g.shape)


def _proximity(H, g, f):
    """The mean squared distance to the residual hyperplanes (times m): |gn - Hn f|^2 with unit rows."""
    s = np.linalg.norm(H, axis=1, keepdims=True)
    return float(np.sum((g / s - (H / s) @ f) ** 2))


def test_extrapolated_reaches_the_least_squares_limit_the_sweeps_cycle_around(noisy_system):
    """With noise the sets do not meet: the extrapolated parallel projections converge to the
    row-normalised NNLS (Combettes 1994), the paper's sequential sweeps stay on their cycle."""
    H, g = noisy_system
    s = np.linalg.norm(H, axis=1, keepdims=True)
    best = float(nnls(H / s, (g / s)[:, 0])[1] ** 2)
    f_new, res_new = pocs(H, g, 2000, scheme="extrapolated")
    f_old, res_old = pocs(H, g, 2000)  # the paper's scheme (the old solver)
    assert _proximity(H, g, f_new) / best - 1.0 < 1e-2
    assert _proximity(H, g, f_old) / best - 1.0 > 1.0
    assert res_new[-1] < res_old[-1]
    assert np.all(f_new >= 0.0)


def test_extrapolated_is_faster_than_the_sweeps_at_equal_work(noisy_system):
    """600 extrapolated iterations (two 60 x 60 products each) fit better than 200 sweeps of ~400 row projections."""
    H, g = noisy_system
    _, res_new = pocs(H, g, 600, scheme="extrapolated")
    _, res_old = pocs(H, g, 200)
    assert res_new[-1] < res_old[-1]


@pytest.mark.parametrize("scheme", PROJECTION_SCHEMES)
def test_one_residual_projection_projects(scheme):
    """One row: a sweep lands on the row's hyperplane (feasible) and a second sweep moves nothing (idempotent)."""
    rng = np.random.default_rng(1)
    h = rng.uniform(0.2, 1.0, size=(1, 7))
    g = np.array([[3.0]])
    f, _ = pocs(h, g, 1, scheme=scheme)
    np.testing.assert_allclose(h @ f, g, rtol=1e-12)
    np.testing.assert_allclose(f, h.T * 3.0 / np.sum(h * h), rtol=1e-12)  # the nearest point of the hyperplane to 0
    f2, _ = pocs(h, g, 1, scheme=scheme, x0=f)
    np.testing.assert_allclose(f2, f, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("scheme", PROJECTION_SCHEMES)
def test_amplitude_projection_keeps_the_bounds(noisy_system, scheme):
    H, g = noisy_system
    f, _ = pocs(H, g, 30, upper=0.5, scheme=scheme)
    assert f.min() >= 0.0 and f.max() <= 0.5
    f2, _ = pocs(np.zeros((1, H.shape[1])) + np.eye(1, H.shape[1]), np.array([[0.25]]), 1, upper=0.5, scheme=scheme,
                 x0=f)
    assert f2.min() >= 0.0 and f2.max() <= 0.5


def test_relaxed_sweep_is_the_relaxed_row_projections(noisy_system):
    """lambda in (0, 2): each row moves lambda times its projection's step, in the triangular solve too."""
    H, g = noisy_system
    H, g = H[:120], g[:120]
    lam = 1.6
    norm2 = np.einsum("ij,ij->i", H, H)
    ref = np.zeros((H.shape[1], 1))
    for i in range(H.shape[0]):
        ref += lam * np.outer(H[i] / norm2[i], g[i] - H[i] @ ref)
    np.clip(ref, 0.0, None, out=ref)
    f, _ = pocs(H, g, 1, order="sequential", relaxation=lam)
    np.testing.assert_allclose(f, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("scheme", PROJECTION_SCHEMES)
def test_stopping_rule_stops_when_the_estimate_settles(noisy_system, scheme):
    """tol: the run stops at the first sweep that moves f by less than tol |f| (fixed order: the sweeps settle too)."""
    H, g = noisy_system
    cap = 3000
    f, res = pocs(H, g, cap, scheme=scheme, order="sequential", tol=1e-3)
    k = res.size - 1
    assert 1 < k < cap
    before, _ = pocs(H, g, k - 1, scheme=scheme, order="sequential")
    assert np.linalg.norm(f - before) <= 1e-3 * np.linalg.norm(f)
    _, res_all = pocs(H, g, k, scheme=scheme, order="sequential")
    np.testing.assert_allclose(res, res_all, rtol=1e-12)


def test_sources_report_the_sweeps_run():
    rng = np.random.default_rng(2)
    _, n, w = _kernel(rng, 300, 40)
    b = np.maximum(n @ w[:3].T, 0.0) @ np.array([1.0, 2.0, 0.5])
    fit = singh_ahuja_sources(n, b, 1.0, w, iterations=50000, tol=1e-5, scheme="extrapolated")
    assert fit.iterations == fit.residuals.size - 1 < 50000
    assert fit.relative_rms < 0.01


@pytest.mark.parametrize("kw", [{"scheme": "parallel"}, {"relaxation": 2.0}, {"relaxation": 0.0},
                                {"scheme": "extrapolated", "relaxation": 1.5},
                                {"scheme": "extrapolated", "delta": 0.1}])
def test_bad_options_are_refused(noisy_system, kw):
    H, g = noisy_system
    with pytest.raises(ValueError):
        pocs(H, g, 2, **kw)


def test_cli_extrapolated_scheme_with_a_stopping_rule(courtyard_ball_folder, tmp_path, capsys):
    from ffls.cli import main
    from ffls.lightmaps.lightmap import load_lightmap

    out = tmp_path / "m.exr"
    assert main(["probe", "pocs", str(courtyard_ball_folder), "-o", str(out), "--size", "16", "--sources", "grid",
                 "--grid", "8", "--scheme", "extrapolated", "--iterations", "20000", "--tol", "1e-4"]) == 0
    err = capsys.readouterr().err
    assert "parallel, extrapolated" in err and "stopped at a change below 0.0001" in err
    assert load_lightmap(out).data.min() >= 0


@pytest.mark.parametrize("flags, words", [(["--scheme", "extrapolated", "--relaxation", "1.5"], "--relaxation"),
                                          (["--relaxation", "2"], "--relaxation"),
                                          (["--scheme", "parallel"], "--scheme"),
                                          (["--tol", "0"], "--tol"),
                                          (["--sources", "grid", "--grid", "8", "--relaxation", "1e-300",
                                            "--scheme", "sequential"], "POCS made no progress")])
def test_cli_bad_solver_flags_get_one_line(courtyard_ball_folder, tmp_path, capsys, flags, words):
    from ffls.cli import main

    out = tmp_path / "m.exr"
    assert main(["probe", "pocs", str(courtyard_ball_folder), "-o", str(out), "--size", "16", *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and not out.exists()
