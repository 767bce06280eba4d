"""GPU pass 1 (ffls.gpu.integrate.CellIntegrator) against the float64 reference.

Tolerance (all tests): per cell,
``|w_gpu - w_ref| <= RTOL * max(|w_ref|, FLOOR * total)`` with ``RTOL = 1e-5``, ``FLOOR = 1e-6``
and ``total`` the map's power per channel: plain 1e-5 relative on every cell holding at least
1e-6 of the power, and 1e-11 of the total on the smaller ones. The reference is
``ffls.weights.voronoi.integrate_weights(..., cells=<the same CellTexture>)`` in float64; the GPU
rounds each texel's power to float32 once and accumulates in float32. Dropped-texel counts are
compared exactly, and energy is conserved: ``sum(w) + dropped_power == total`` within 1e-5.
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import rotation_ypr
from ffls.lightmaps.lightmap import LightMap, constant_map, sky_sun_map
from ffls.weights.voronoi import bake_cells, integrate_weights

pytestmark = pytest.mark.gl

RTOL = 1e-5
FLOOR = 1e-6
METHODS = ("blend", "atomic", "sort")


def _lights(n, hemisphere, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    if hemisphere == "upper":
        d[:, 2] = np.abs(d[:, 2])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


_CELLS: dict = {}


def _cells(key, directions, hemisphere, res=64, k=8):
    if key not in _CELLS:
        _CELLS[key] = bake_cells(directions, hemisphere, res, k=k)
    return _CELLS[key]


def _check(gpu, ref, total):
    w = gpu.read_weights().astype(np.float64)
    scale = np.maximum(np.abs(ref.weights), FLOOR * np.abs(total)[None, :])
    err = np.abs(w - ref.weights)
    bad = err > RTOL * scale
    assert not bad.any(), (
        f"{bad.sum()} cell channels over tolerance; worst relative "
        f"{np.max(err / np.where(scale > 0, scale, 1)):.3g}")
    assert gpu.dropped_texels == ref.dropped_texels
    np.testing.assert_allclose(w.sum(0) + gpu.dropped_power, ref.total_power, rtol=RTOL, atol=1e-30)


def _rotations():
    rng = np.random.default_rng(7)
    out = [np.eye(3), rotation_ypr(0, 90, 0), rotation_ypr(10, 89.999, 0), rotation_ypr(0, -90, 0),
           rotation_ypr(360, 0, 0)]
    out += [rotation_ypr(*rng.uniform(-180, 180, 3)) for _ in range(2)]
    return out


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("n, hemisphere", [(1, "upper"), (2, "full"), (64, "upper"), (64, "full")])
def test_matches_reference(ctx, method, n, hemisphere):
    from ffls.gpu.integrate import CellIntegrator

    if n == 2:
        d = np.array([[0.3, -0.4, 0.866], [-0.3, 0.4, -0.866]])  # antipodal
    else:
        d = _lights(n, hemisphere, seed=n)
    cells = _cells((n, hemisphere), d, hemisphere)
    lm = sky_sun_map(48)
    gpu = CellIntegrator(ctx, d, hemisphere, cells, method=method)
    try:
        gpu.set_lightmap(lm)
        for R in _rotations():
            gpu.run(R)
            ref = integrate_weights(lm, d, R, hemisphere, cells=cells)
            _check(gpu, ref, ref.total_power)
    finally:
        gpu.release()


@pytest.mark.parametrize("hemisphere", ["upper", "full"])
def test_2048_lights(ctx, hemisphere):
    from ffls.gpu.integrate import CellIntegrator

    d = _lights(2048, hemisphere, seed=3)
    cells = _cells((2048, hemisphere), d, hemisphere)
    lm = sky_sun_map(96)
    R = rotation_ypr(33, 89.999, -12)
    ref = integrate_weights(lm, d, R, hemisphere, cells=cells)
    for method in METHODS:
        gpu = CellIntegrator(ctx, d, hemisphere, cells, method=method)
        try:
            gpu.set_lightmap(lm)
            gpu.run(R)
            _check(gpu, ref, ref.total_power)
        finally:
            gpu.release()


def test_sun_next_to_dim_sky(ctx):
    from ffls.gpu.integrate import CellIntegrator

    data = np.full((64, 128, 3), 1e-3, dtype=np.float32)
    data[20, 37] = 1e6  # one texel
    lm = LightMap(data, "latlong", "sun")
    d = _lights(64, "upper", seed=64)
    cells = _cells((64, "upper"), d, "upper")
    R = rotation_ypr(20, 5, 0)
    ref = integrate_weights(lm, d, R, "upper", cells=cells)
    assert ref.weights.max() > 1e3 * np.sort(ref.weights[:, 0])[-2]  # the sun dominates one cell
    for method in METHODS:
        gpu = CellIntegrator(ctx, d, "upper", cells, method=method)
        try:
            gpu.set_lightmap(lm)
            gpu.run(R)
            # the dim cells hold less than FLOOR of the power: check them at 1e-5 on their own
            w = gpu.read_weights().astype(np.float64)
            dim = np.argsort(ref.weights[:, 0])[:-1]
            np.testing.assert_allclose(w[dim], ref.weights[dim], rtol=RTOL, atol=0)
            _check(gpu, ref, ref.total_power)
        finally:
            gpu.release()


def test_all_zero_map(ctx):
    from ffls.gpu.integrate import CellIntegrator

    lm = constant_map(32, 0.0)
    d = _lights(64, "upper", seed=64)
    cells = _cells((64, "upper"), d, "upper")
    for method in METHODS:
        gpu = CellIntegrator(ctx, d, "upper", cells, method=method)
        try:
            gpu.set_lightmap(lm)
            gpu.run(rotation_ypr(0, 45, 0))
            assert np.all(gpu.read_weights() == 0)
            assert np.all(gpu.dropped_power == 0)
            ref = integrate_weights(lm, d, rotation_ypr(0, 45, 0), "upper", cells=cells)
            assert gpu.dropped_texels == ref.dropped_texels > 0
        finally:
            gpu.release()


def test_constant_map_sums_to_covered_solid_angle(ctx):
    """Invariant: a constant map c gives weights summing to c x 2 pi (upper), for any rotation."""
    from ffls.gpu.integrate import CellIntegrator

    lm = constant_map(64, 2.0)
    d = _lights(64, "upper", seed=64)
    cells = _cells((64, "upper"), d, "upper")
    gpu = CellIntegrator(ctx, d, "upper", cells)
    try:
        gpu.set_lightmap(lm)
        for R in _rotations()[:3]:
            gpu.run(R)
            # dropped texels are whole texels, so the kept part is 2 pi up to one texel band
            kept = gpu.read_weights().astype(np.float64).sum(0)
            np.testing.assert_allclose(kept + gpu.dropped_power, 2.0 * 4 * np.pi, rtol=1e-5)
            np.testing.assert_allclose(kept, 2.0 * 2 * np.pi, rtol=0.05)
    finally:
        gpu.release()


@pytest.mark.parametrize("method", METHODS)
def test_deterministic(ctx, method):
    """Two runs (and a run after another rotation) give identical bits."""
    from ffls.gpu.integrate import CellIntegrator

    d = _lights(2048, "upper", seed=3)
    cells = _cells((2048, "upper"), d, "upper")
    lm = sky_sun_map(96)
    R = rotation_ypr(-70, 30, 5)
    gpu = CellIntegrator(ctx, d, "upper", cells, method=method)
    try:
        gpu.set_lightmap(lm)
        a = gpu.run(R).read()
        gpu.run(rotation_ypr(5, 5, 5))
        b = gpu.run(R).read()
        assert a == b
    finally:
        gpu.release()


def test_rejects_mismatched_cells(ctx):
    from ffls.gpu.integrate import CellIntegrator

    d = _lights(64, "upper", seed=64)
    cells = _cells((64, "upper"), d, "upper")
    with pytest.raises(ValueError, match="hemisphere"):
        CellIntegrator(ctx, d, "full", cells)
    with pytest.raises(ValueError, match="other directions"):
        CellIntegrator(ctx, d[::-1], "upper", cells)
    with pytest.raises(ValueError, match="method"):
        CellIntegrator(ctx, d, "upper", cells, method="nope")


def test_describe_context_and_info(ctx, capsys):
    from ffls.commands.info import format_info
    from ffls.gpu.context import describe_context

    info = describe_context(ctx)
    assert info["gl_version_code"] >= 430
    assert info["max_ssbo_bytes"] >= 1 << 24
    text = format_info(info)
    assert info["renderer"] in text and "float atomics" in text


@pytest.mark.parametrize("method", METHODS)
def test_cells_of_more_than_65535_texels(ctx, method):
    """A 1024 x 512 map shared by 3 lights: each cell (and the dropped half) holds more than 65535
    texels. llvmpipe cuts an invocation's loops at 65535 iterations, so the sort's segment sum
    summed such a cell short (by up to half here) until it was split into chunks."""
    from ffls.gpu.integrate import CellIntegrator

    d = _lights(3, "upper", seed=5)
    cells = _cells((3, "upper"), d, "upper")
    lm = sky_sun_map(512)
    gpu = CellIntegrator(ctx, d, "upper", cells, method=method)
    try:
        gpu.set_lightmap(lm)
        gpu.run(np.eye(3))
        ref = integrate_weights(lm, d, np.eye(3), "upper", cells=cells)
        assert ref.dropped_texels > 65535
        _check(gpu, ref, ref.total_power)
    finally:
        gpu.release()
