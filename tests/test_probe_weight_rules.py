"""How a penalty weight is chosen from its held-out errors (issue 11): ``selection.choose_weight``.

All weights are scored on the same CV folds, so a fold that is hard for one is hard for all; the
``'paired_se'`` rule takes its standard error from the paired fold differences, ``'one_se'`` from
the spread of the best weight's own fold errors. Pure arrays, plus one small ball (32 px, 42 sources).
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes.selection import WEIGHT_RULES, choose_weight, select_regularization
from ffls.probes.sources import geodesic_sources
from ffls.synth.probe_scenes import diffuse_sphere_scene

#: Five folds of very different difficulty (how many and how bright their pixels are).
FOLDS = np.array([1.0, 3.0, 0.5, 2.0, 6.0])


def test_one_se_counts_fold_heterogeneity_the_paired_rule_cancels_it():
    # weight 1 is worse than weight 0 on every fold by 2%, far less than the folds differ
    S = np.stack([FOLDS, 1.02 * FOLDS, 1.5 * FOLDS])
    assert choose_weight(S, "min") == (0, 0)
    assert choose_weight(S, "one_se") == (1, 0)  # within sqrt(5) x std of the best's fold errors
    assert choose_weight(S, "paired_se") == (0, 0)  # worse on 5 of 5 folds: rejected
    # a weight better on some folds and worse on others, by more than it is worse in total, is kept
    noisy = FOLDS + np.array([0.1, -0.08, 0.06, -0.05, 0.0])
    assert choose_weight(np.stack([FOLDS, noisy, 1.5 * FOLDS]), "paired_se") == (1, 0)


def test_rules_never_choose_less_regularisation_than_the_lowest_error():
    rng = np.random.default_rng(0)
    for _ in range(50):
        S = FOLDS * rng.uniform(0.9, 1.1, size=(5, 5))
        for rule in WEIGHT_RULES:
            chosen, best = choose_weight(S, rule)
            assert best == int(np.argmin(S.sum(axis=1))) and chosen >= best
        # a weight worse on every fold in proportion to its error (folds as heterogeneous as FOLDS) is rejected
        assert choose_weight(np.vstack([S[:1], S[:1] * 1.001]), "paired_se")[0] == 0


def test_weights_that_could_not_be_fitted_are_not_chosen():
    S = np.stack([FOLDS, np.full(5, np.inf), 1.01 * FOLDS + np.array([0.05, -0.05, 0.05, -0.05, 0])])
    for rule in WEIGHT_RULES:
        assert choose_weight(S, rule)[1] == 0 and choose_weight(S, rule)[0] != 1
    with pytest.raises(InputError, match="no penalty weight"):
        choose_weight(np.full((3, 5), np.inf))
    with pytest.raises(ValueError, match="rule must be one of"):
        choose_weight(S, "one_sd")
    with pytest.raises(ValueError, match="2 folds at least"):
        choose_weight(FOLDS[:, None])


def test_select_regularization_reports_its_fold_errors():
    sph = diffuse_sphere_scene(builtin_lightmap("night").downsample(32), 32, albedo=0.7)
    args = (sph.normals, sph.radiance, 0.7, geodesic_sources(2), (0.0, 0.003, 0.03), "smoothness")
    kw = {"nonnegative": True, "ambient": False}
    sels = {rule: select_regularization(*args, rule=rule, **kw) for rule in WEIGHT_RULES}
    S = sels["min"].fold_errors
    assert S.shape == (3, 5) and np.all(S > 0)
    for rule, sel in sels.items():
        np.testing.assert_allclose(sel.fold_errors, S)
        assert sel.chosen == sel.candidates[choose_weight(S, rule)[0]] and f"rule {rule}" in sel.note
    # scores are the held-out relative RMS of the summed fold errors
    total = S.sum(axis=1)
    np.testing.assert_allclose(sels["min"].scores / sels["min"].scores[0], np.sqrt(total / total[0]))
