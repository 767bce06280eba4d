"""Hemispheres around any axis (issue 9, item 7), coverage warnings, and the orthographic camera.

GL tolerance (as tests/test_gpu_integrate.py): per cell ``|w_gpu - w_ref| <= 1e-5 * max(|w_ref|,
1e-6 * total)``, 0 cells allowed over it; dropped-texel counts exact; energy within 1e-5.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from ffls import conventions as cv
from ffls.errors import InputError
from ffls.lightmaps.lightmap import constant_map, sky_sun_map
from ffls.weights.voronoi import (bake_cells, cell_solid_angles, coverage, coverage_warnings, integrate_weights)

AXES = [(0, 0, 1), (0, -1, 0), (1, 0, 0), (0.3, -0.5, 0.2), (0, 0, -1)]


def _lights_in(axis, n, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    side = d @ a
    d[side < 0] -= 2 * side[side < 0, None] * a  # mirror into the hemisphere
    return d / np.linalg.norm(d, axis=1, keepdims=True)


# ----------------------------------------------------------------------------- the value type
def test_hemisphere_forms_and_equality():
    assert cv.as_hemisphere("upper") == "upper" == cv.UPPER
    assert cv.as_hemisphere({"axis": [0, 0, 5]}) == "upper"  # normalised; +Z is the upper one
    assert cv.as_hemisphere("full").axis is None and cv.FULL.solid_angle == pytest.approx(4 * np.pi)
    h = cv.as_hemisphere({"axis": [0, -2, 0]})
    assert h.axis == (0.0, -1.0, 0.0) and h.name == "axis" and h != "upper" and h != "full"
    assert h.to_json() == {"axis": [0.0, -1.0, 0.0]} and cv.as_hemisphere(h.to_json()) == h
    assert cv.covered_solid_angle(h) == pytest.approx(2 * np.pi)
    np.testing.assert_array_equal(cv.in_domain(np.array([[0, -1, 0], [0, 1, 0], [1, 0, 0]]), h), [True, False, True])
    for bad in ("lower", {"axis": [0, 0, 0]}, {"axis": [1, 2]}, {"axis": "up"}, {"axis": [1, 0, float("nan")]}, 3):
        with pytest.raises(ValueError):
            cv.as_hemisphere(bad)


def test_capture_json_axis_hemisphere_and_orthographic_camera(tmp_path):
    from ffls.io.capture import load_capture, save_capture
    from ffls.io.images import write_png

    write_png(tmp_path / "a.png", np.zeros((4, 4, 3), np.uint8))
    doc = {"format": "ffls-capture", "version": 1, "images": ["a.png"], "hemisphere": {"axis": [0, -1, 0]},
           "camera": {"model": "orthographic"}}
    (tmp_path / "capture.json").write_text(json.dumps(doc))
    cap = load_capture(tmp_path)
    assert cap.hemisphere == {"axis": [0, -1, 0]} and cap.camera_model == "orthographic"
    assert cap.sphere_radius is None and cap.K is None  # neither is needed for directions
    save_capture(cap)
    again = json.loads((tmp_path / "capture.json").read_text())
    assert again["hemisphere"] == {"axis": [0.0, -1.0, 0.0]} and again["camera"] == {"model": "orthographic"}
    for bad, key in [({"hemisphere": {"axis": [0, 0, 0]}}, "hemisphere"), ({"hemisphere": "lower"}, "hemisphere"),
                     ({"camera": {"model": "fisheye"}}, "camera.model"),
                     ({"camera": {"model": "orthographic", "K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}}, "no K")]:
        (tmp_path / "capture.json").write_text(json.dumps({**doc, **bad}))
        with pytest.raises(InputError, match=key):
            load_capture(tmp_path)


def test_orthographic_rays_are_parallel():
    from ffls.camera.projection import camera_rays

    r = camera_rays(np.array([[0.0, 0.0], [100.0, 7.5], [-3.0, 2e4]]), "orthographic")
    np.testing.assert_array_equal(r, [[0, 0, 1]] * 3)
    K = np.array([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]])
    p = camera_rays(np.array([[50.0, 50.0], [150.0, 50.0]]), "pinhole", K)
    np.testing.assert_allclose(p, [[0, 0, 1], [np.sqrt(0.5), 0, np.sqrt(0.5)]], atol=1e-12)
    with pytest.raises(ValueError):
        camera_rays(np.zeros((1, 2)), "pinhole")


# ----------------------------------------------------------------------------- invariants
@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("cells_res", [None, 64])
def test_constant_map_weights_sum_to_c_times_2pi(axis, cells_res):
    """A constant map c gives weights summing to c x 2 pi for a hemisphere around any axis, any rotation."""
    h = {"axis": list(axis)}
    d = _lights_in(axis, 40, seed=5)
    cells = None if cells_res is None else bake_cells(d, h, cells_res)
    # constant_map is lat-long with exact solid angles, so the kept part is 2 pi up to the
    # texels that straddle the boundary plane (a band of one texel)
    lm = constant_map(256, 3.0)
    for R in (np.eye(3), cv.rotation_ypr(30, 40, -70)):
        w = integrate_weights(lm, d, R, h, cells=cells)
        np.testing.assert_allclose(w.weights.sum(0) + w.dropped_power, 3.0 * 4 * np.pi, rtol=1e-12)
        np.testing.assert_allclose(w.weights.sum(0), 3.0 * 2 * np.pi, rtol=0.01)
    if cells is not None:  # the candidate texture is exact: the same cells as the k-d tree
        ref = integrate_weights(lm, d, None, h)
        np.testing.assert_array_equal(integrate_weights(lm, d, None, h, cells=cells).weights, ref.weights)


@pytest.mark.parametrize("axis", AXES)
def test_cell_solid_angles_of_an_axis_hemisphere(axis):
    """Exact spherical-Voronoi areas (mirrored through the hemisphere's plane) sum to 2 pi and agree with
    sampling; rotating lights and axis together changes nothing."""
    h = {"axis": list(axis)}
    d = _lights_in(axis, 30, seed=11)
    sv = cell_solid_angles(d, h, method="spherical_voronoi")
    np.testing.assert_allclose(sv.sum(), 2 * np.pi, rtol=1e-9)
    sampled = cell_solid_angles(d, h, method="sample", res=512)
    np.testing.assert_allclose(sampled, sv, atol=4e-3)
    R = cv.rotation_ypr(20, -35, 50)
    a = R @ (np.asarray(axis, float) / np.linalg.norm(axis))
    np.testing.assert_allclose(cell_solid_angles(d @ R.T, {"axis": a.tolist()}, method="spherical_voronoi"), sv,
                               rtol=1e-9, atol=1e-12)


def test_axis_hemisphere_drops_the_other_half():
    """A sun behind the dome (d . axis < 0) is dropped and counted; in front of it, it is kept."""
    black = (0.0, 0.0, 0.0)
    lm = sky_sun_map(64, sun_direction=(0.0, 1.0, 0.2), sky_zenith=black, sky_horizon=black, ground=black)
    d = _lights_in((0, -1, 0), 12, seed=2)
    back = integrate_weights(lm, d, None, {"axis": [0, -1, 0]})
    front = integrate_weights(lm, d, None, {"axis": [0, 1, 0]})
    assert back.weights.sum() == 0 and back.dropped_power.sum() > 0
    assert front.dropped_power.sum() == 0 and front.weights.sum() > 0


# ----------------------------------------------------------------------------- GPU
@pytest.mark.gl
@pytest.mark.parametrize("method", ["blend", "atomic", "sort"])
def test_gl_pass_matches_numpy_for_an_axis_hemisphere(ctx, method):
    from ffls.gpu.integrate import CellIntegrator

    if method == "atomic" and "GL_NV_shader_atomic_float" not in ctx.extensions:
        pytest.skip("no GL_NV_shader_atomic_float")
    h = {"axis": [0.3, -0.8, 0.2]}
    d = _lights_in(h["axis"], 48, seed=9)
    cells = bake_cells(d, h, 64)
    lm = sky_sun_map(48)
    gpu = CellIntegrator(ctx, d, h, cells, method=method)
    try:
        gpu.set_lightmap(lm)
        for R in (np.eye(3), cv.rotation_ypr(0, 90, 0), cv.rotation_ypr(40, -20, 75)):
            gpu.run(R)
            ref = integrate_weights(lm, d, R, h, cells=cells)
            w = gpu.read_weights().astype(np.float64)
            scale = np.maximum(np.abs(ref.weights), 1e-6 * np.abs(ref.total_power)[None, :])
            assert np.count_nonzero(np.abs(w - ref.weights) > 1e-5 * scale) == 0
            assert gpu.dropped_texels == ref.dropped_texels > 0
            np.testing.assert_allclose(w.sum(0) + gpu.dropped_power, ref.total_power, rtol=1e-5)
    finally:
        gpu.release()


@pytest.mark.gl
def test_gl_constant_map_axis_hemisphere(ctx):
    from ffls.gpu.integrate import CellIntegrator

    h = {"axis": [0, -1, 0]}
    d = _lights_in(h["axis"], 20, seed=4)
    gpu = CellIntegrator(ctx, d, h, bake_cells(d, h, 64))
    try:
        gpu.set_lightmap(constant_map(128, 2.0))
        gpu.run(cv.rotation_ypr(10, 20, 30))
        np.testing.assert_allclose(gpu.read_weights().astype(np.float64).sum(0), 2.0 * 2 * np.pi, rtol=0.02)
    finally:
        gpu.release()


# ----------------------------------------------------------------------------- coverage
def test_coverage_numbers():
    # one light at the zenith: its cell is the whole upper hemisphere, 180 deg wide, and every
    # direction more than 30 deg from it is far: 1 - (1 - cos 30) = cos 30 of the domain
    c = coverage([[0, 0, 1]], "upper", res=512)
    assert c.cell_width_deg[0] == pytest.approx(180.0, abs=0.5)
    assert c.far_share == pytest.approx(np.cos(np.radians(30)), abs=2e-3)
    assert c.max_gap_deg == pytest.approx(90.0, abs=0.5)
    lines = coverage_warnings([[0, 0, 1]], "upper")  # sampled at texel centres: within a texel (0.7 deg)
    assert lines[0] in ("coverage: 1 cell wider than 60 deg (widest 179 deg at az 0 el 90)",
                        "coverage: 1 cell wider than 60 deg (widest 180 deg at az 0 el 90)")
    assert lines[1] in ("coverage: 86% of the domain is more than 30 deg from every light (farthest 90 deg)",
                        "coverage: 87% of the domain is more than 30 deg from every light (farthest 90 deg)")
    # a dense, even set covers the hemisphere: no warning
    from ffls.synth.scene import stratified_directions

    assert coverage_warnings(stratified_directions(200), "upper") == []
    # the same lights around the camera axis of a dome leave the other half far from every light
    dome = {"axis": [0, -1, 0]}
    dense = _lights_in(dome["axis"], 400, seed=1)
    assert coverage_warnings(dense, dome) == []
    half = dense[dense[:, 2] >= 0]  # only the top half of the dome lit
    lines = coverage_warnings(half, dome)
    assert len(lines) == 2 and "wider than 60 deg" in lines[0]
    share = float(lines[1].split("%")[0].split()[-1])
    # far = the dome's half of the cap z < -sin 30 (half of 2 pi (1 - cos 60) = pi / 2): 25% of 2 pi, plus
    # what the random lights near z = 0 leave uncovered
    assert 25 <= share <= 30
    # a light outside the domain (below the horizon of an upper capture) is said first, not kept silently
    below = np.vstack([stratified_directions(200), [[0.0, 0.866, -0.5], [0.0, 0.0, -1.0]]])
    lines = coverage_warnings(below, "upper")
    assert lines[0].startswith("coverage: 2 lights outside the capture's upper hemisphere (farthest at az 0 el -90, "
                               "90 deg beyond its edge)"), lines
    assert not any("outside" in ln for ln in coverage_warnings(below, "full"))
    # a light estimated just under the horizon, within its 95% cone, is at the horizon: no advice to declare
    # full (its cone reaches the hemisphere); one beyond its cone is still outside, with the advice
    e = np.radians(-0.4)
    near = np.vstack([stratified_directions(200), [[np.cos(e), 0.0, np.sin(e)], [0.0, 0.866, -0.5]]])
    cones = np.full(len(near), 2.0)
    lines = coverage_warnings(near, "upper", cones_deg=cones)
    assert lines[0].startswith("coverage: 1 light outside the capture's upper hemisphere (farthest at az 90 el "
                               "-30, 30 deg beyond its edge)") and "full" in lines[0], lines
    assert lines[1].startswith("coverage: 1 light at the horizon: estimated just outside the capture's upper "
                               "hemisphere, within its 95% cone (farthest at az 0 el -0.4, 0.4 deg beyond its "
                               "edge, cone 2.0 deg)") and "full" not in lines[1], lines
    assert not any("horizon" in ln for ln in coverage_warnings(near[:-1], "upper", cones_deg=np.full(201, 0.2)))
    assert not any("horizon" in ln for ln in coverage_warnings(near, "upper"))  # no cones: as before
    from ffls.io.capture import Lights

    li = Lights(["a.png", "b.png"], [[0, 0, 1], [1, 0, 0]], extra=[{"uncertainty_deg": 1.5}, {}])
    np.testing.assert_array_equal(li.cones_deg([1, 0]), [np.nan, 1.5])
    # lights repeating an earlier one's direction get no weight (only the first takes the cell): said first
    even = stratified_directions(200)
    lines = coverage_warnings(np.vstack([even, np.repeat(even[:1], 3, axis=0)]), "upper")
    assert lines == ["coverage: 3 lights repeat the direction of an earlier one and get no weight (200 distinct "
                     "directions of 203)"], lines
