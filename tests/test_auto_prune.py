"""--quality auto times only the candidates it could choose (ffls.relight.auto.timed_candidates)."""
import numpy as np
import pytest

from ffls.relight.auto import candidate_qualities, choose, no_costlier, timed_candidates
from ffls.relight.quality import Quality


def _model_ms(q, n, rng_jitter=0.0):
    """A frame time that grows with the pass-2 layers, the storage width and the pass-1 map (as measured)."""
    photos = n if q.basis_subset is None else q.basis_subset
    layers = photos if q.rank is None else q.rank + 1
    scheme = {"voronoi": 1.0, "antialiased": 1.1, "barycentric": 2.0, "gaussian": 2.5}[q.weighting]
    return (layers * (2.0 if q.precision == "f32" else 1.0) * 0.3 + scheme * (4.0 if q.map_res is None else 1.0)
            + rng_jitter)


def test_no_costlier_is_structural():
    n = 64
    r7, r15 = Quality(rank=7), Quality(rank=15)
    full16, full32 = Quality(precision="f16"), Quality(precision="f32")
    assert no_costlier(r7, r15, n) and not no_costlier(r15, r7, n)
    assert no_costlier(r15, full16, n) and no_costlier(full16, full32, n) and not no_costlier(full32, full16, n)
    assert no_costlier(r7.replace(map_res=64), r7, n) and not no_costlier(r7, r7.replace(map_res=64), n)
    assert not no_costlier(r7, r7.replace(weighting="gaussian"), n)  # another scheme: only a measurement says
    assert not no_costlier(Quality(basis_subset=16), full16, n)  # other photos: not comparable either


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("targets", [(0.05, None), (0.2, None), (0.001, None), (None, 30.0), (None, 1000.0),
                                     (0.2, 60.0), (0.001, 60.0), (None, 0.5)])
def test_pruned_timing_makes_the_same_choice(seed, targets):
    """With times that grow with the work (the structural order), timing only what could be chosen
    gives the same choice as timing all ~50 candidates, and times fewer of them."""
    rng = np.random.default_rng(seed)
    n = 64
    cands = candidate_qualities(n)
    errors = rng.uniform(0.01, 0.4, size=len(cands))
    every = np.array([_model_ms(q, n, rng.uniform(0, 0.05)) for q in cands])
    calls = []

    def time_one(q):
        calls.append(q)
        return float(every[cands.index(q)])

    max_error, fps = targets
    pruned = timed_candidates(cands, errors, time_one, n, max_error, fps)
    a, b = choose(cands, errors, every, max_error, fps), choose(cands, errors, pruned, max_error, fps)
    assert a.quality == b.quality and a.met == b.met
    assert len(calls) == len(set(calls)) == np.count_nonzero(np.isfinite(pruned))
    assert np.all(pruned[np.isfinite(pruned)] == every[np.isfinite(pruned)])
    if fps is None or fps > 10:
        assert len(calls) < len(cands) // 2, len(calls)
