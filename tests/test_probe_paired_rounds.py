"""Hougen-Ahuja's default choices by paired folds (issue 11; ``docs/probes.md``, *Choosing with paired
folds*): the adaptive set's round (``refine_sources(..., rule='paired_se')``) and the smoothness weight
(``diffuse_lightmap``'s default ``smoothness='cv'``, ``rule='paired_se'``). Stub fits and one small ball."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from ffls.cli import main
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes import estimate_lightmap
from ffls.probes.selection import ROUND_RULES, refine_sources
from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe

#: Five folds of different difficulty; the noise every round shares.
FOLDS = np.array([1.0, 1.3, 0.8, 1.1, 1.2])


def _rounds(excess):
    """``fit_all`` and ``score`` of rounds whose held-out errors are the shared ``FOLDS`` plus ``excess[i]``
    (per fold) at round ``i``: a stub of noisy data, where the noise dominates every round's error."""
    seen = []

    def fit_all(d):
        seen.append(d.shape[0])
        return SimpleNamespace(directions=d, intensities=np.ones((d.shape[0], 3)))

    def score(d, fit):
        e = FOLDS + np.asarray(excess[min(len(seen), len(excess)) - 1])
        return float(np.sqrt(e.sum())), e

    return fit_all, score


def test_paired_rule_takes_the_round_the_folds_agree_on():
    # round 1 is 4% worse than round 2 on every fold: within a 5% tolerance, outside the paired error
    excess = [np.full(5, 2.0), np.full(5, 0.08), np.zeros(5), np.full(5, 0.01), np.full(5, 0.02)]
    fit_all, score = _rounds(excess)
    tol = refine_sources(fit_all, lambda d, f: score(d, f)[0], max_level=2)
    fit_all, score = _rounds(excess)
    pair = refine_sources(fit_all, score, max_level=2, rule="paired_se")
    assert tol.chosen == tol.candidates[1] and "tolerance 5%" in tol.note
    assert pair.chosen == pair.candidates[2] and "paired standard error" in pair.note
    assert pair.fold_errors.shape == (len(pair.candidates), 5) and tol.fold_errors is None
    # a round better on some folds and worse on others is the folds' noise: the smaller one stays
    excess = [np.full(5, 2.0), np.array([0.1, -0.1, 0.12, -0.08, 0.02]), np.zeros(5), np.zeros(5), np.zeros(5)]
    fit_all, score = _rounds(excess)
    assert refine_sources(fit_all, score, max_level=2, rule="paired_se").chosen == pair.candidates[1]
    with pytest.raises(ValueError, match="rule must be one of"):
        refine_sources(fit_all, score, rule="paired_se", criterion="bic")
    with pytest.raises(ValueError, match="rule must be one of"):
        refine_sources(fit_all, score, rule="min")
    assert ROUND_RULES == ("tolerance", "paired_se")


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    sc = diffuse_sphere_scene(builtin_lightmap("studio").downsample(16), resolution=32, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("studio"), sc)


def test_default_estimate_chooses_by_paired_folds(folder, tmp_path, capsys):
    est = estimate_lightmap(folder, "diffuse", height=16, max_pixels=600)
    assert est.details["rule"] == "paired_se" and "smoothness" in est.details
    assert any("within one paired standard error" in s for s in est.notes)
    assert any("rule paired_se" in s for s in est.notes)
    old = estimate_lightmap(folder, "diffuse", height=16, max_pixels=600, rule="one_se")
    assert any("tolerance 5%" in s for s in old.notes) and any("rule one_se" in s for s in old.notes)
    plain = estimate_lightmap(folder, "diffuse", height=16, max_pixels=600, orientations=2)
    assert "smoothness" not in plain.details  # the members have no one set: no weight to choose
    with pytest.raises(ValueError, match="rule must be one of"):
        estimate_lightmap(folder, "diffuse", height=16, max_pixels=600, rule="min")
    out = tmp_path / "m.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(out), "--size", "16", "--rule", "one_se"]) == 0
    assert out.exists()
    capsys.readouterr()
    bad = tmp_path / "bad.exr"
    assert main(["probe", "diffuse", str(folder), "-o", str(bad), "--size", "16", "--rule", "min"]) == 2
    err = capsys.readouterr().err
    assert "--rule" in err and len(err.strip().splitlines()) == 1 and not bad.exists()
