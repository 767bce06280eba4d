"""POCS's least-power scheme: the feasible map of least total power, one linear programme (HiGHS)."""
import numpy as np
import pytest
from scipy.optimize import nnls

from ffls.errors import InputError
from ffls.probes.linear import lambert_matrix
from ffls.probes.singh_ahuja import (adaptive_singh_ahuja, dykstra_pocs, least_power_pocs, pocs, residual_l1_bound,
                                     singh_ahuja_sources)
from ffls.probes.sources import model_sources


def _ball(m=400, seed=0):
    """Unit normals of the half of a ball a camera on -Y sees (the other half is dark to it)."""
    n = np.random.default_rng(seed).normal(size=(m, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[:, 1] = -np.abs(n[:, 1])
    return n


def _two_lights(m, seed):
    """A ball's normals (:func:`_ball`) and its radiance (albedo 0.7) under two sources of a
    42-source set."""
    n = _ball(m, seed=seed)
    d = model_sources(42)
    L = np.zeros((d.shape[0], 3))
    L[[3, 17]] = [[2.0, 1.5, 1.0], [0.5, 0.5, 0.8]]
    return n, lambert_matrix(n, d) @ L * 0.7 / np.pi


def test_least_power_is_the_sparsest_fit_where_least_norm_spreads():
    # x + 2 y = 2 (three identical pixels): every point of the segment fits exactly. Least power: (0, 1);
    # Dykstra's least norm: (0.4, 0.8)
    H = np.array([[1.0, 2.0]] * 3)
    f, res = least_power_pocs(H, np.full(3, 2.0))
    np.testing.assert_allclose(f[:, 0], [0.0, 1.0], atol=1e-7)
    assert res[0] == pytest.approx(1.0) and res[-1] < 1e-7
    fd, _ = dykstra_pocs(H, np.full(3, 2.0), iterations=2000)
    np.testing.assert_allclose(fd[:, 0], [0.4, 0.8], atol=1e-4)
    # the amplitude set holds: with y <= 0.5 the least power is x = 1, y = 0.5
    f, _ = least_power_pocs(H, np.full(3, 2.0), upper=[10.0, 0.5])
    np.testing.assert_allclose(f[:, 0], [1.0, 0.5], atol=1e-7)
    # pocs() dispatches to it
    f2, _ = pocs(H, np.full(3, 2.0), scheme="least-power")
    np.testing.assert_allclose(f2[:, 0], [0.0, 1.0], atol=1e-7)


def test_residual_l1_bound_is_zero_on_exact_data_and_above_the_fit_with_noise():
    rng = np.random.default_rng(1)
    H = np.abs(rng.normal(size=(80, 10)))
    g = H @ np.abs(rng.normal(size=(10, 2)))
    np.testing.assert_allclose(residual_l1_bound(H, g), 0.0, atol=1e-7 * np.abs(g).sum())
    g = g + 0.05 * rng.normal(size=g.shape)
    eps = residual_l1_bound(H, g)
    # the least absolute residual of a non-negative map (a reference by NNLS: its L1 residual is no smaller)
    r_nnls = np.array([np.abs(g[:, c] - H @ nnls(H, g[:, c])[0]).sum() for c in range(2)])
    m, J = H.shape
    assert np.all(eps > 0) and np.all(eps <= r_nnls * m / (m - J) * (1 + 1e-9))
    f, _ = least_power_pocs(H, g, eps=eps)
    assert np.all(np.abs(g - H @ f).sum(axis=0) <= eps * (1 + 1e-6))   # the answer is in the residual set
    assert np.all(f >= 0)


def test_least_power_recovers_two_lamps_on_a_noisy_ball():
    # two lamps of a 92-source set seen by half a ball, 1% noise: the least-power map relights a sphere of normals
    # within 5% (NNLS on the same pixels: about 3 times that), its power within 3% of the truth
    from ffls.probes.evaluate import relit_error
    from ffls.probes.sources import sources_to_latlong

    n = _ball(600)
    d = model_sources(92)
    L = np.zeros((d.shape[0], 3))
    L[[5, 40]] = [[3.0, 2.5, 2.0], [0.6, 0.7, 1.0]]
    rad = lambert_matrix(n, d) @ L * 0.7 / np.pi
    rad = rad + np.random.default_rng(2).normal(0.0, 0.01 * rad.mean(), size=rad.shape)
    fit = singh_ahuja_sources(n, rad, 0.7, d, scheme="least-power", max_pixels=None)
    true = sources_to_latlong(d, L, 32)
    err = relit_error(sources_to_latlong(d, fit.intensities, 32), true)
    g = np.pi * rad / 0.7
    f_nnls = np.stack([nnls(lambert_matrix(n, d), g[:, c])[0] for c in range(3)], axis=1)
    err_nnls = relit_error(sources_to_latlong(d, f_nnls, 32), true)
    assert err < 0.05 and err < err_nnls
    np.testing.assert_allclose(fit.intensities.sum(axis=0), L.sum(axis=0), rtol=0.03)
    assert fit.iterations == 1 and fit.residuals.shape == (2,)


def test_adaptive_least_power_keeps_the_sweeps_set():
    # the set is grown and chosen by the paper's sweeps; only the chosen set's powers change
    n, rad = _two_lights(300, seed=3)
    a = adaptive_singh_ahuja(n, rad, 0.7, criterion="bic", max_pixels=None, max_level=1)
    b = adaptive_singh_ahuja(n, rad, 0.7, criterion="bic", max_pixels=None, max_level=1, scheme="least-power")
    np.testing.assert_allclose(b.fit.directions, a.fit.directions, atol=1e-12)   # (renormalised)
    assert a.candidates == b.candidates and b.fit.iterations == 1
    assert b.fit.relative_rms < 1e-3


def test_least_power_refuses_options_it_does_not_take():
    H = np.ones((3, 2))
    for kw, word in ((dict(relaxation=0.5), "relaxation"), (dict(tol=1e-6), "tol"), (dict(delta=0.1), "delta"),
                     (dict(x0=np.ones((2, 1))), "x0")):
        with pytest.raises(ValueError, match=word):
            pocs(H, np.ones(3), scheme="least-power", **kw)
    with pytest.raises(InputError, match="no solution"):   # a residual bound below what any map leaves
        least_power_pocs(np.array([[1.0], [1.0]]), np.array([0.0, 2.0]), eps=[0.5])


def test_cli_least_power_scheme(courtyard_ball_folder, tmp_path, capsys):
    from ffls.cli import main
    from ffls.lightmaps.lightmap import load_lightmap

    out = tmp_path / "m.exr"
    assert main(["probe", "pocs", str(courtyard_ball_folder), "-o", str(out), "--size", "16", "--sources", "grid",
                 "--grid", "8", "--scheme", "least-power"]) == 0
    assert "the least total power within the L1 residual" in capsys.readouterr().err
    assert load_lightmap(out).data.min() >= 0


@pytest.mark.parametrize("flags, words", [(["--tol", "1e-5"], "--tol"), (["--relaxation", "0.5"], "--relaxation"),
                                          (["--sources", "grid", "--iterations", "10"], "--iterations"),
                                          (["--order", "random"], "--order")])
def test_cli_least_power_refuses_flags_it_does_not_take(courtyard_ball_folder, tmp_path, capsys, flags, words):
    from ffls.cli import main

    out = tmp_path / "m.exr"
    assert main(["probe", "pocs", str(courtyard_ball_folder), "-o", str(out), "--size", "16",
                 "--scheme", "least-power", *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and not out.exists()


@pytest.mark.parametrize("scale", [1e-7, 1e5])
def test_least_power_does_not_depend_on_the_exposure(scale):
    # the programme is homogeneous in the data; solved at the data's own scale, HiGHS's absolute tolerances
    # would swamp a dark photograph's values
    n = _ball(300, seed=4)
    d = model_sources(42)
    L = np.zeros((d.shape[0], 3))
    L[[3, 17, 30]] = [[2.0, 1.5, 1.0], [0.5, 0.5, 0.8], [0.2, 0.3, 0.1]]
    H = lambert_matrix(n, d)
    g = H @ L + np.random.default_rng(5).normal(0.0, 0.01, size=(n.shape[0], 3))
    f, _ = least_power_pocs(H, g)
    fs, _ = least_power_pocs(H, g * scale)
    np.testing.assert_allclose(fs / scale, f, atol=1e-6 * np.abs(f).max())
    np.testing.assert_allclose(residual_l1_bound(H, g * scale) / scale, residual_l1_bound(H, g), rtol=1e-6)


def test_grid_least_power_minimises_power_not_radiance(monkeypatch):
    # x + y = 2 seen by three pixels: the least power is the unknown whose unit costs least
    H = np.ones((3, 2))
    for w, want in (([1.0, 3.0], [2.0, 0.0]), ([3.0, 1.0], [0.0, 2.0])):
        f, _ = least_power_pocs(H, np.full(3, 2.0), weights=w)
        np.testing.assert_allclose(f[:, 0], want, atol=1e-7)
    # on the lat-long grid the unknowns are radiances: a texel's power is its radiance times its solid angle
    import ffls.probes.singh_ahuja as sa_mod
    from ffls.probes.sources import latlong_solid_angles

    seen = {}

    def spy(*args, **kw):
        seen.update(kw)
        return least_power_pocs(*args, **kw)

    monkeypatch.setattr(sa_mod, "least_power_pocs", spy)
    n = _ball(200, seed=6)
    sa_mod.singh_ahuja(n, np.full((n.shape[0], 3), 0.1), 0.7, height=4, scheme="least-power", max_pixels=None)
    np.testing.assert_allclose(seen["weights"], latlong_solid_angles(4).ravel())


def test_pixel_subsets_are_disjoint_and_start_with_the_selection_subset():
    from ffls.probes.singh_ahuja import pixel_subset, pixel_subsets

    parts = pixel_subsets(4060, 1000, 4, seed=0)
    np.testing.assert_array_equal(parts[0], pixel_subset(4060, 1000, 0))
    assert [p.size for p in parts] == [1000, 1020, 1020, 1020]   # the 3060 others in three parts
    allp = np.concatenate(parts)
    assert np.unique(allp).size == allp.size == 4060 and all(np.all(np.diff(p) > 0) for p in parts)
    capped = pixel_subsets(100000, 1000, 4, seed=0)   # more pixels than 4 parts: parts of exactly max_pixels
    assert [p.size for p in capped] == [1000] * 4 and np.unique(np.concatenate(capped)).size == 4000
    assert len(pixel_subsets(1400, 1000, 4)) == 1        # 400 left: less than half a part
    assert [p.size for p in pixel_subsets(2600, 1000, 4)] == [1000, 800, 800]
    assert len(pixel_subsets(500, None, 4)) == 1 and pixel_subsets(500, None, 4)[0].size == 500
    with pytest.raises(ValueError, match="count"):
        pixel_subsets(500, 100, 0)


def test_averaged_least_power_is_the_mean_of_the_refitted_subset_programmes_and_nearer_the_truth():
    # three lamps on the nodes of a 162-source set, 3% noise, one programme per 400-pixel subset. In every noise
    # draw: refitting a programme's lit sources gives back the power its residual budget took (total power within
    # 0.5% of the truth; the programme alone 0.5-2% short), and each of the mean over four subsets and the refit
    # brings the powers nearer the truth than the first subset's programme alone
    from ffls.probes.singh_ahuja import averaged_least_power, pixel_subsets, refit_support

    n = _ball(1600, seed=0)
    d = model_sources(162)
    L = np.zeros((d.shape[0], 3))
    L[[7, 60, 100]] = [[3.0, 2.5, 2.0], [0.6, 0.7, 1.0], [0.3, 0.3, 0.2]]
    clean = lambert_matrix(n, d) @ L * 0.7 / np.pi
    for s in range(4):
        rad = clean + np.random.default_rng(10 + s).normal(0.0, 0.03 * clean.mean(), size=clean.shape)
        fit = {(k, rf): averaged_least_power(n, rad, 0.7, d, max_pixels=400, subsets=k, refit=rf)
               for k in (1, 4) for rf in (False, True)}
        if s == 0:
            parts = pixel_subsets(n.shape[0], 400, 4)
            each = [singh_ahuja_sources(n[p], rad[p], 0.7, d, max_pixels=None, scheme="least-power").intensities
                    for p in parts]
            refit = [refit_support(lambert_matrix(n[p], d), np.pi * rad[p] / 0.7, f) for p, f in zip(parts, each)]
            np.testing.assert_allclose(fit[1, False].intensities, each[0], atol=1e-12)
            np.testing.assert_allclose(fit[4, False].intensities, np.mean(each, axis=0), atol=1e-12)
            np.testing.assert_allclose(fit[4, True].intensities, np.mean(refit, axis=0), atol=1e-12)
            assert all(np.all((r > 0) <= (f > 0)) for r, f in zip(refit, each))   # no source lit that was dark
            assert fit[4, True].pixels_used == 1600 and fit[1, True].pixels_used == 400
            assert fit[4, True].rendered.shape == (1600, 3)
        err = {k: np.linalg.norm(f.intensities - L) for k, f in fit.items()}
        assert err[4, False] < err[1, False] and err[1, True] < err[1, False] and err[4, True] < err[1, True]
        np.testing.assert_allclose(fit[4, True].intensities.sum(axis=0), L.sum(axis=0), rtol=0.005)


def test_adaptive_least_power_averages_over_subsets():
    # scheme='least-power' solves the chosen set on up to `subsets` pixel subsets and averages them
    from ffls.probes.singh_ahuja import averaged_least_power

    n, rad = _two_lights(900, seed=7)
    rad = rad + np.random.default_rng(8).normal(0.0, 0.01 * rad.mean(), size=rad.shape)
    sel = adaptive_singh_ahuja(n, rad, 0.7, criterion="bic", max_pixels=300, max_level=1, scheme="least-power")
    want = averaged_least_power(n, rad, 0.7, sel.fit.directions, max_pixels=300, subsets=4)
    np.testing.assert_allclose(sel.fit.intensities, want.intensities, atol=1e-12)
    assert sel.fit.pixels_used == 900
    with pytest.raises(ValueError, match="subsets"):
        adaptive_singh_ahuja(n, rad, 0.7, scheme="least-power", subsets=0)


def test_pocs_lightmap_least_power_reports_the_averaged_subsets(courtyard_ball_folder):
    from ffls.io.probe import load_probe
    from ffls.probes.estimate import pocs_lightmap

    est = pocs_lightmap(load_probe(courtyard_ball_folder), height=16, max_pixels=600, criterion="bic",
                        scheme="least-power")
    line = next(x for x in est.notes if x.startswith("POCS (Singh-Ahuja)"))
    assert "disjoint subset of about 600 pixels, averaged" in line and "over 600 pixels" not in line
    assert "its lit sources refitted" in line


def test_refit_support_gives_back_shrunk_power_on_the_lit_unknowns_only():
    from ffls.probes.singh_ahuja import refit_support

    # x + 2 y = 2: a shrunk answer (0, 0.9) is refitted to (0, 1); x stays 0; the amplitude bound holds
    H = np.array([[1.0, 2.0]] * 3)
    np.testing.assert_allclose(refit_support(H, np.full(3, 2.0), [[0.0], [0.9]])[:, 0], [0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(refit_support(H, np.full(3, 2.0), [[0.0], [0.9]], upper=[10.0, 0.5])[:, 0],
                               [0.0, 0.5], atol=1e-9)
    np.testing.assert_array_equal(refit_support(H, np.full(3, 2.0), np.zeros((2, 1))), np.zeros((2, 1)))


def test_default_scheme_is_least_power_and_meets_its_error(courtyard_ball_folder, tmp_path):
    """POCS with no scheme named: least power on adaptive sources, said in the notes, the details and the saved map's
    header; a sphere relit under it within 9% of the true courtyard (7.7% measured), where the paper's sweeps on the
    same set give more than 11% (12.7%)."""
    import OpenEXR

    from ffls.lightmaps.lightmap import builtin_lightmap
    from ffls.probes import estimate_lightmap, save_estimate
    from ffls.probes.evaluate import relit_error

    truth = builtin_lightmap("courtyard").downsample(16)
    kw = dict(height=16, max_pixels=600, criterion="bic")
    est = estimate_lightmap(courtyard_ball_folder, "pocs", **kw)
    assert est.details["scheme"] == "least-power"
    assert any(x.startswith("POCS (Singh-Ahuja), --scheme least-power (not the paper's)") for x in est.notes)
    assert relit_error(est.lightmap, truth) < 0.09
    paper = estimate_lightmap(courtyard_ball_folder, "pocs", scheme="sequential", **kw)
    assert any(x.startswith("POCS (Singh-Ahuja), --scheme sequential (the paper's projections)") for x in paper.notes)
    assert relit_error(paper.lightmap, truth) > 0.11
    for e, scheme in ((est, "least-power"), (paper, "sequential")):
        header = OpenEXR.File(str(save_estimate(e, tmp_path / f"{scheme}.exr"))).header()
        assert header["ffls:probe_method"] == "pocs" and header["ffls:pocs_scheme"] == scheme


@pytest.mark.parametrize("flags, scheme", [([], "least-power"), (["--sources", "adaptive"], "least-power"),
                                           (["--sources", "grid"], "sequential"),
                                           (["--scheme", "sequential"], "sequential"),
                                           (["--sources", "grid", "--scheme", "least-power"], "least-power")])
def test_cli_default_scheme_follows_the_sources(flags, scheme):
    from ffls.cli import build_parser
    from ffls.commands.probe import method_knobs
    from ffls.probes.estimate import POCS_DEFAULT_SCHEME

    args = build_parser().parse_args(["probe", "pocs", "folder", "-o", "m.exr", *flags])
    assert method_knobs(args)["scheme"] == scheme
    if "--scheme" not in flags:   # the CLI's default is the library's
        assert POCS_DEFAULT_SCHEME[args.sources] == scheme


def test_pocs_lightmap_default_scheme_follows_the_sources(courtyard_ball_folder):
    from ffls.io.probe import load_probe
    from ffls.probes.estimate import POCS_DEFAULT_SCHEME, pocs_lightmap

    assert POCS_DEFAULT_SCHEME == {"auto": "least-power", "adaptive": "least-power", "grid": "sequential"}
    probe = load_probe(courtyard_ball_folder)
    assert pocs_lightmap(probe, height=16, grid=8, sources="grid", iterations=3).details["scheme"] == "sequential"


@pytest.mark.parametrize("upper", [None, 0.6, "some"])
def test_l1_bound_is_the_primal_least_absolute_deviation(upper):
    """``residual_l1_bound`` (solved through the dual programme) against the primal LAD programme, bounds included."""
    from scipy.optimize import linprog

    rng = np.random.default_rng(3)
    m, J = 80, 30
    H = np.maximum(rng.normal(size=(m, J)), 0.0)
    g = H @ np.maximum(rng.normal(size=(J, 2)), 0.0) + rng.normal(0.0, 0.3, (m, 2))
    hi = None if upper is None else np.where(np.arange(J) % 2 == 0, 0.6, np.inf) if upper == "some" else upper
    eps = residual_l1_bound(H, g, 0.0, hi)
    ub = np.broadcast_to(np.inf if hi is None else hi, (J,))
    for c in range(2):
        sol = linprog(np.r_[np.zeros(J), np.ones(2 * m)], A_eq=np.c_[H, np.eye(m), -np.eye(m)], b_eq=g[:, c],
                      bounds=[(0.0, u) for u in ub] + [(0.0, None)] * (2 * m), method="highs")
        x = sol.x[:J]
        k = int(np.count_nonzero((x > 1e-9 * x.max()) & (x < ub - 1e-9 * x.max())))
        assert eps[c] == pytest.approx(sol.fun * m / (m - k), rel=1e-7)
