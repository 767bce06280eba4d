"""Dykstra's best approximation for POCS: the residual-energy set, its bound and a definite answer."""
import numpy as np
import pytest
from scipy.optimize import nnls

from ffls.probes.linear import lambert_matrix
from ffls.probes.singh_ahuja import ResidualEnergySet, dykstra_pocs, pocs, residual_bound, singh_ahuja_sources
from ffls.probes.sources import model_sources


def _problem(m=60, J=12, noise=0.05, seed=1):
    rng = np.random.default_rng(seed)
    H = np.abs(rng.normal(size=(m, J)))
    f = np.abs(rng.normal(size=(J, 2)))
    return H, H @ f + noise * rng.normal(size=(m, 2))


def test_residual_set_projection_is_feasible_and_idempotent():
    H, g = _problem()
    eps = 1.2 * residual_bound(H, g)
    R = ResidualEnergySet(H, g, eps)
    z = np.random.default_rng(3).normal(size=(H.shape[1], 2)) * 5
    assert not R.contains(z)
    p = R.project(z)
    assert R.contains(p)
    np.testing.assert_allclose(np.linalg.norm(g - H @ p, axis=0), eps, rtol=1e-6)   # lands on the boundary
    np.testing.assert_allclose(R.project(p), p, atol=1e-9)                          # idempotent
    # the nearest point: moving along the boundary's tangent from p never gets closer to z than p is
    d0 = np.linalg.norm(z - p)
    for t in np.random.default_rng(4).normal(size=(20, H.shape[1], 2)) * 1e-3:
        q = R.project(p + t)
        assert np.linalg.norm(z - q) >= d0 - 1e-9


def test_residual_bound_is_zero_on_exact_data_and_above_the_fit_with_noise():
    H, g = _problem(noise=0.0)
    np.testing.assert_allclose(residual_bound(H, g), 0.0, atol=1e-8)
    H, g = _problem(noise=0.05)
    r = np.array([np.linalg.norm(g[:, c] - H @ nnls(H, g[:, c])[0]) for c in range(2)])
    eps = residual_bound(H, g)
    assert np.all(eps > r) and np.all(eps < r * np.sqrt(H.shape[0] / (H.shape[0] - H.shape[1])) * (1 + 1e-9))


def test_dykstra_reaches_the_least_norm_feasible_point():
    # x + y = 2 (three identical pixels): every point of the segment fits; the least-norm one is (1, 1)
    H = np.ones((3, 2))
    f, res = dykstra_pocs(H, np.full(3, 2.0), iterations=500)
    np.testing.assert_allclose(f[:, 0], [1.0, 1.0], atol=1e-6)
    assert res[-1] < 1e-6
    # the paper's sweeps stop wherever they start: from (2, 0) they never move
    f2, _ = pocs(H, np.full(3, 2.0), iterations=50, x0=[[2.0], [0.0]])
    np.testing.assert_allclose(f2[:, 0], [2.0, 0.0], atol=1e-12)
    # x - y = 1 with x, y >= 0: the unconstrained least-norm point (0.5, -0.5) is infeasible; the answer is (1, 0)
    f, _ = dykstra_pocs(np.array([[1.0, -1.0]] * 3), np.ones(3), iterations=2000, tol=None)
    np.testing.assert_allclose(f[:, 0], [1.0, 0.0], atol=1e-4)


def test_dykstra_matches_the_exact_best_approximation_with_noise():
    H, g = _problem()
    eps = residual_bound(H, g)
    f, _ = dykstra_pocs(H, g, iterations=20000, eps=eps, tol=1e-12)
    J = H.shape[1]
    for c in range(2):
        # reference: min |x|^2 with x >= 0 and |g - H x| = eps, by Tikhonov NNLS and bisection on its weight
        lo, hi = -30.0, 30.0
        for _ in range(80):
            t = 0.5 * (lo + hi)
            x = nnls(np.vstack([H, np.exp(-t / 2) * np.eye(J)]), np.r_[g[:, c], np.zeros(J)], maxiter=5000)[0]
            lo, hi = (t, hi) if np.linalg.norm(g[:, c] - H @ x) > eps[c] else (lo, t)
        np.testing.assert_allclose(f[:, c], x, atol=2e-3 * np.linalg.norm(x))
    assert np.all(f >= 0)


def test_dykstra_on_a_ball_is_independent_of_the_pixel_order():
    rng = np.random.default_rng(0)
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = model_sources(42)
    L = np.zeros((d.shape[0], 3))
    L[[3, 17]] = [[2.0, 1.5, 1.0], [0.5, 0.5, 0.8]]
    rad = lambert_matrix(n, d) @ L * 0.7 / np.pi
    a = singh_ahuja_sources(n, rad, 0.7, d, iterations=3000, scheme="dykstra", tol=1e-9)
    b = singh_ahuja_sources(n[::-1], rad[::-1], 0.7, d, iterations=3000, scheme="dykstra", tol=1e-9)
    np.testing.assert_allclose(a.intensities, b.intensities, atol=1e-5 * np.abs(a.intensities).max())
    assert a.relative_rms < 1e-3


def test_dykstra_refuses_options_it_does_not_take():
    H, g = _problem()
    with pytest.raises(ValueError, match="dykstra"):
        pocs(H, g, scheme="dykstra", relaxation=0.5)
    with pytest.raises(ValueError, match="empty"):
        ResidualEnergySet(H, g, 0.0)


def test_cli_dykstra_scheme(courtyard_ball_folder, tmp_path, capsys):
    from ffls.cli import main
    from ffls.lightmaps.lightmap import load_lightmap

    out = tmp_path / "m.exr"
    assert main(["probe", "pocs", str(courtyard_ball_folder), "-o", str(out), "--size", "16", "--sources", "grid",
                 "--grid", "8", "--scheme", "dykstra", "--iterations", "300", "--tol", "1e-5"]) == 0
    assert "Dykstra, the least-norm feasible map" in capsys.readouterr().err
    assert load_lightmap(out).data.min() >= 0


@pytest.mark.parametrize("flags, words", [(["--scheme", "dykstra", "--relaxation", "0.5"], "--relaxation"),
                                          (["--scheme", "dykstra", "--order", "random"], "--order")])
def test_cli_dykstra_refuses_flags_it_does_not_take(courtyard_ball_folder, tmp_path, capsys, flags, words):
    from ffls.cli import main

    out = tmp_path / "m.exr"
    assert main(["probe", "pocs", str(courtyard_ball_folder), "-o", str(out), "--size", "16", *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and not out.exists()
