"""A mirror ball found without any hint in one HDR probe photo (ffls.probes.locate).

A chrome ball (reflectance 0.7) ray-traced by ``ffls.synth.probe`` under a built-in light map, with
the map itself as the background; ``probe.json`` locates nothing. ``benchmarks/probe_detect.py``
measures the rate over 12 renders.
"""
from __future__ import annotations

import numpy as np
import pytest

from ffls.camera.projection import project_points
from ffls.io.probe import load_probe
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes.bracket import view_radiance
from ffls.probes.locate import locate_sphere, mirror_limb
from ffls.synth.probe import look_at, write_mirror_probe


def _probe(folder, name="night", f=400.0, d=1.2, offset=(-70.0, 10.0)):
    center = np.array([0.0, 0.0, 0.1])
    eye = center + d * np.array([0.94, 0.0, 0.34])
    T0 = look_at(eye, center)
    T = look_at(eye, center - offset[0] / f * d * T0[:3, 0] - offset[1] / f * d * T0[:3, 1])
    K = np.array([[f, 0, 159.5], [0, f, 119.5], [0, 0, 1.0]])
    write_mirror_probe(folder, builtin_lightmap(name), (320, 240), "pinhole", K, None, T, center, 0.1,
                       sphere="auto", reflectance=0.7)
    Ti = np.linalg.inv(T)
    return project_points((Ti[:3, :3] @ center + Ti[:3, 3])[None], K, None)[0]


def _located(folder, name):
    c_true = _probe(folder, name)
    probe = load_probe(folder)
    view = probe.views[0]
    vr = view_radiance(view, probe.encoding, probe.response, probe.json_path)
    return locate_sphere(view, vr.radiance, probe.json_path), c_true


def test_mirror_ball_found_without_hint(tmp_path):
    """Within 2 px: the finder's outer outline is 0.06-0.43 px from the true centre, and
    ``mirror_limb`` then takes a circle of limb steps 0.9 px off (NumPy's AVX2 kernels) or 1.7 px off
    (its AVX-512 kernels, e.g. on an AMD EPYC): the steps of the limb and of a reflected edge just
    inside it score alike, so the last bits of the arithmetic choose (docs/probes.md). A reflected
    circle taken for the ball (sunrise below: 5.7 px) or another round outline (studio: 30 px)
    fails it."""
    geo, c_true = _located(tmp_path, "night")
    assert geo.source == "auto"
    assert np.hypot(*(geo.center_px - c_true)) < 2.0


@pytest.mark.xfail(strict=True, reason="known limitation (docs/probes.md): under the sunrise map the finder takes a "
                                       "reflected circle inside the limb (5.7 px off) and the limb's steps do not "
                                       "reach the silhouette")
def test_mirror_ball_found_without_hint_under_sunrise(tmp_path):
    geo, c_true = _located(tmp_path, "sunrise")
    assert np.hypot(*(geo.center_px - c_true)) < 1.0


def test_mirror_limb_moves_an_inner_circle_to_the_limb(tmp_path):
    """Started from a circle 2 px off and 8% small (a reflected edge inside the limb), the limb's
    reflectance steps give the silhouette; a start far from any ball gives None."""
    c_true = _probe(tmp_path, "sunrise")
    probe = load_probe(tmp_path)
    vr = view_radiance(probe.views[0], probe.encoding, probe.response, probe.json_path)
    r_true = 400.0 * 0.1 / np.sqrt(1.2 ** 2 - 0.1 ** 2)
    limb = mirror_limb(vr.radiance, c_true + [1.5, -1.4], 0.92 * r_true, vr.radiance.shape[:2])
    assert limb is not None
    assert np.hypot(*(limb[0] - c_true)) < 1.0 and abs(limb[1] - r_true) < 1.0
    assert mirror_limb(vr.radiance, (300.0, 30.0), 12.0, vr.radiance.shape[:2]) is None
