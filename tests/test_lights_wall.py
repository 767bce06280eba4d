"""The wall time of ``ffls lights --workers N``: what runs in the main process before and between the
worker processes (docs/spheres.md, Speed: "The wall time")."""


def test_an_error_in_the_workers_statistics_leaves_no_process(monkeypatch):
    """A failure in the photos' statistics made in a :class:`PhotoFitter`'s workers
    (``sphere_kinds(map_fn=fitter.map)``) is raised here, and the pool's processes are gone when the
    fitter is closed (as ``estimate_lights``' ``with`` closes it)."""
    import multiprocessing
    from types import SimpleNamespace

    import numpy as np
    import pytest

    import ffls.spheres.estimate as est

    def broken(rows, cols, grey):
        raise ValueError("broken statistic")

    monkeypatch.setattr(est, "highlight_compactness", broken)  # (inherited by the forked workers)
    rng = np.random.default_rng(0)
    samples = [SimpleNamespace(rows=np.arange(30), cols=np.arange(30)) for _ in range(2)]
    values = [[(rng.random(30),) for _ in samples] for _ in range(8)]
    with pytest.raises(ValueError, match="broken statistic"):
        with est.PhotoFitter(None, None, {"own_shadow": False}, workers=2) as fitter:
            est.sphere_kinds(["auto", "auto"], samples, values, map_fn=fitter.map)
    assert multiprocessing.active_children() == []
