"""Cast shadows: what the view resolves (elevation limit), and the shadow probe's pixel budget."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ffls.io.images import write_exr
from ffls.probes import estimate_lightmap
from ffls.probes.estimate import pixel_grid_subset
from ffls.probes.sato_sato_ikeuchi import elevation_limit, occluder_visibility, shadow_in_view
from ffls.probes.sources import to_lightmap
from ffls.synth.probe_scenes import cast_shadow_scene

EXTENT, RES = 1.0, 100  # the view: [-1, 1]^2, 2 cm a pixel
BOX = {"box": {"center": [0.0, 0.0, 0.1], "size": [0.2, 0.2, 0.2]}}


def _plane_points(res=RES, extent=EXTENT):
    px = (np.arange(res) + 0.5) / res * 2 * extent - extent
    X, Y = np.meshgrid(px, px)
    keep = ~((np.abs(X) <= 0.1) & (np.abs(Y) <= 0.1))
    return np.stack([X[keep], Y[keep], np.zeros(int(keep.sum()))], axis=1)


def _dir(el_deg, az_deg):
    e, a = np.radians(el_deg), np.radians(az_deg)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def test_elevation_limit_is_where_the_shadow_reaches_the_edge_of_the_view():
    p = _plane_points()
    lim = np.degrees(elevation_limit(p, np.stack([_dir(30, 0), _dir(30, 45), _dir(5, 180)]), BOX))
    # along an axis the far end of a 0.2 m cube's shadow is 0.1 + 0.2 / tan(el) from the centre; it must
    # end two pixel spacings (4 cm) inside the view
    axis = np.degrees(np.arctan(0.2 / (EXTENT - 0.1 - 0.04)))
    assert abs(lim[0] - axis) < 1.0 and abs(lim[2] - axis) < 1.0
    # along the diagonal the view reaches further: a lower limit
    assert lim[1] < lim[0] - 2.0
    assert elevation_limit(p, [[0.0, 0.0, 1.0]], BOX)[0] == 0.0  # the zenith has no azimuth
    with pytest.raises(ValueError):
        elevation_limit(p, [[1.0, 0.0, 0.1]], BOX, step_deg=0.0)


def test_below_the_limit_the_in_view_shadow_does_not_change_with_elevation():
    p = _plane_points()
    lim = np.degrees(elevation_limit(p, [_dir(10, 0)], BOX)[0])
    V = occluder_visibility(p, np.stack([_dir(0.5 * lim, 0), _dir(0.9 * lim, 0), _dir(2.0 * lim, 0)]), BOX)
    assert not shadow_in_view(p, [_dir(0.9 * lim, 0)], BOX)[0] and shadow_in_view(p, [_dir(2.0 * lim, 0)], BOX)[0]
    assert np.count_nonzero(V[:, 0] != V[:, 1]) == 0  # the same pixels hidden: elevation not seen
    assert np.count_nonzero(V[:, 1] != V[:, 2]) > 50  # above the limit the shadow ends in view


def test_pixel_grid_subset_is_a_regular_grid_near_the_budget():
    yy, xx = np.mgrid[0:128, 0:128]
    xy = np.stack([xx.ravel(), yy.ravel()], axis=1)
    keep, s = pixel_grid_subset(xy, 4000)
    assert s == 2 and keep.size == 64 * 64
    assert np.all(xy[keep] % 2 == 0) and np.all(np.diff(keep) > 0)
    for budget in (500, 1000, 3000, 9000):
        keep, s = pixel_grid_subset(xy, budget)
        assert 0.55 * budget <= keep.size <= 2.25 * budget
    keep, s = pixel_grid_subset(xy, None)
    assert s == 1 and keep.size == xy.shape[0]
    assert pixel_grid_subset(xy[:10], 4000)[1] == 1
    with pytest.raises(ValueError):
        pixel_grid_subset(xy, 0)


def _one_light_folder(path, row):
    """A shadow probe under one light in lat-long row ``row`` of a 32-row map (azimuth 0)."""
    L = np.zeros((32, 64, 3))
    L[row, 32] = 2000.0
    ss = cast_shadow_scene(to_lightmap(L)[0], resolution=64, extent=EXTENT, box_center=(0, 0, 0.1),
                           box_size=(0.2, 0.2, 0.2), albedo=0.6, n_dirs=64)
    # a little noise, as a photograph has: a flat top would read as clipped float data
    noise = 1.0 + 0.002 * np.random.default_rng(row).standard_normal(ss.image.shape)
    write_exr(path / "shadow.exr", (ss.image * noise).astype(np.float32))
    doc = {"format": "ffls-probe", "version": 1, "images": ["shadow.exr"],
           "camera": {"model": "orthographic", "pixel_size": 2 * EXTENT / 64,
                      "world_from_camera": [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 10], [0, 0, 0, 1]]},
           "plane": {"point": [0, 0, 0], "normal": [0, 0, 1], "albedo": 0.6},
           "occluder": BOX}
    (path / "probe.json").write_text(json.dumps(doc))
    return path


def test_shadow_probe_reports_light_whose_elevation_the_view_does_not_fix(tmp_path):
    (tmp_path / "low").mkdir()
    (tmp_path / "high").mkdir()
    low = _one_light_folder(tmp_path / "low", 15)
    high = _one_light_folder(tmp_path / "high", 6)
    el = 90 - (np.array([15, 6]) + 0.5) * 180 / 32  # 2.8 and 56 degrees: the limit here is about 12.5
    assert el[0] < 10 < 20 < el[1]
    est = estimate_lightmap(low, "shadow", height=16, max_pixels=1000)
    assert est.details["unresolved_elevation_share"] > 0.5
    assert any("run past the photograph" in n for n in est.notes)
    assert any("one pixel in 2 along each row and column" in n for n in est.notes)
    est = estimate_lightmap(high, "shadow", height=16, max_pixels=1000)
    assert est.details["unresolved_elevation_share"] < 0.1
