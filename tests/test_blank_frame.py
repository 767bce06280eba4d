"""A blank frame (the lens cap on: noise only) is ``too_dark``, not a sphere "ok" on its noise.

A sphere fitted on noise still gets a direction; two such spheres then disagreed and the photo
was rejected as ``spheres_disagree`` (i-user15's photometric-stereo set, docs/spheres.md,
"Rejection reasons"). The shading must be above the noise (:func:`shading_signal_p`).
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import normalize
from ffls.spheres.lambert import SIGNAL_SIGNIFICANCE, fit_lambert
from ffls.spheres.photo import estimate_photo
from ffls.spheres.samples import SphereSamples, SphereValues


def disc_normals(radius_px: int = 30) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera-facing unit normals of an orthographic sphere's pixels, and their rows and columns."""
    r = np.arange(-radius_px, radius_px + 1)
    cols, rows = np.meshgrid(r, r)
    inside = cols ** 2 + rows ** 2 < (radius_px - 0.5) ** 2
    x, y = cols[inside] / radius_px, rows[inside] / radius_px
    # camera frame: x right, y down, z toward the camera is -z; world: x, -y, the view +z up
    n = np.stack([x, -y, np.sqrt(np.maximum(1.0 - x * x - y * y, 0.0))], axis=1)
    return n, rows[inside], cols[inside]


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
@pytest.mark.parametrize("offset", [0.0, 0.01])
def test_noise_only_sphere_is_too_dark(seed, offset):
    n, rows, cols = disc_normals()
    rng = np.random.default_rng(seed)
    values = offset + 0.004 * rng.standard_normal(len(n))
    fit = fit_lambert(n, values, valid=values > 0 if offset else None, pixels=(rows, cols))
    assert fit.status == "too_dark", (fit.status, fit.rms, fit.uncertainty_deg)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dim_but_real_shading_stays_ok(seed):
    # a dim light: its peak is 2 noise deviations
    n, rows, cols = disc_normals()
    rng = np.random.default_rng(seed)
    light = normalize(np.array([0.4, -0.3, 0.8]))
    values = 0.008 * np.maximum(n @ light, 0.0) + 0.004 * rng.standard_normal(len(n))
    fit = fit_lambert(n, values, pixels=(rows, cols))
    assert fit.status == "ok"
    assert np.degrees(np.arccos(np.clip(fit.direction @ light, -1, 1))) < 3 * fit.uncertainty_deg


def test_blank_photo_rejected_as_too_dark():
    n, rows, cols = disc_normals()
    rng = np.random.default_rng(7)
    samples = []
    for k, cx in enumerate((-0.3, 0.3)):
        center = np.array([cx, 0.0, 0.05])
        samples.append(SphereSamples(rows=rows, cols=cols + 100 * k, normals=n,
                                     points=center + 0.05 * n, center=center, radius=0.05,
                                     radius_px=30.0))
    values = [SphereValues(0.004 * rng.standard_normal(len(n)), np.ones(len(n), dtype=bool), 0)
              for _ in samples]
    est = estimate_photo(None, samples, np.zeros(3), values=values, own_shadow=False)
    assert est.status == "rejected"
    assert est.reason == "too_dark"
    assert SIGNAL_SIGNIFICANCE == pytest.approx(1e-3)


def test_shading_signal_p_is_the_f_tests_survival_and_imports_no_scipy_stats():
    # scipy.stats' import (about 0.25 s of CPU, in the main process and in each worker that fits)
    # is made for nothing else in a run: the p-value is SciPy's fdtrc, which f.sf calls
    import subprocess
    import sys
    from pathlib import Path

    from scipy.stats import f

    from ffls.spheres.lambert import shading_signal_p

    rng = np.random.default_rng(3)
    for _ in range(200):
        k, p = int(rng.integers(10, 4000)), int(rng.integers(1, 6))
        y = rng.standard_normal(k)
        rss0 = float(np.sum((y - y.mean()) ** 2))
        fit = type("Fit", (), {"x": np.zeros(p), "rss": rss0 * rng.uniform(0.2, 1.0)})
        x = (rss0 - fit.rss) / max(p - 1, 1) / (fit.rss / (k - p))
        assert shading_signal_p(y, fit) == float(f.sf(x, max(p - 1, 1), k - p))
    code = ("import sys; import numpy as np; from ffls.spheres.lambert import fit_lambert; "
            "from tests.test_blank_frame import disc_normals; n, r, c = disc_normals(); "
            "v = np.maximum(n @ np.array([0.0, 0.6, 0.8]), 0.0); "
            "assert fit_lambert(n, v + 0.01 * np.random.default_rng(0).standard_normal(len(n)), "
            "pixels=(r, c)).status == 'ok'; print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.split() == ["False"]
