"""A new user's workflows, round 5 (``i-user17``): what a first trial found broken, each fixed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.io.capture import POSITION_DIRECTION_TOLERANCE_DEG, load_lights


def _lights_file(tmp_path, direction, position):
    doc = {"format": "ffls-lights", "version": 1,
           "lights": [{"image": "a.png", "direction": list(direction), "position": list(position),
                       "model": "near"}]}
    path = tmp_path / "lights.json"
    path.write_text(json.dumps(doc))
    return path


def test_near_light_position_off_its_direction_refused(tmp_path):
    # a position in another frame (x and y swapped) beside the right direction
    d = np.array([0.6, 0.0, 0.8])
    path = _lights_file(tmp_path, d, [0.0, 1.2, 1.6])
    with pytest.raises(InputError, match=r"position: seen from the scene centre it lies 50\.21 deg off"):
        load_lights(path)


def test_near_light_position_on_its_direction_read(tmp_path):
    d = np.array([0.6, 0.0, 0.8])
    off = np.radians(POSITION_DIRECTION_TOLERANCE_DEG / 2)  # a hand-typed file's rounding
    p = 2.0 * np.array([np.sin(np.arcsin(0.6) + off), 0.0, np.cos(np.arcsin(0.6) + off)])
    lights = load_lights(_lights_file(tmp_path, d, p))
    np.testing.assert_allclose(lights.positions[0], p)


def test_near_light_position_seen_from_the_scene_centre(tmp_path):
    # the directions are measured from capture.json's scene_center, not the origin
    d = np.array([0.0, 0.0, 1.0])
    path = _lights_file(tmp_path, d, [1.0, 0.0, 2.0])
    load_lights(path, scene_center=np.array([1.0, 0.0, 0.0]))
    with pytest.raises(InputError, match="deg off the light's direction"):
        load_lights(path)


def test_constant_float_probe_read_as_a_uniform_light(tmp_path):
    # a float image with one value everywhere has no pixel under its plateau: nothing measures a
    # clip (it was refused as "saturated everywhere: use a shorter exposure"); an 8-bit one is read
    from ffls.io.images import write_exr
    from ffls.probes import estimate_lightmap

    write_exr(tmp_path / "ball.exr", np.full((96, 96, 3), 0.7, np.float32))
    doc = {"format": "ffls-probe", "version": 1, "images": ["ball.exr"],
           "camera": {"K": [[400, 0, 48], [0, 400, 48], [0, 0, 1]],
                      "world_from_camera": [[1, 0, 0, 0], [0, 0, 1, -2], [0, -1, 0, 0], [0, 0, 0, 1]]},
           "sphere": {"center": [0, 0, 0], "radius": 0.05, "material": "mirror"}}
    (tmp_path / "probe.json").write_text(json.dumps(doc))
    est = estimate_lightmap(tmp_path, "mirror", height=16)
    np.testing.assert_allclose(est.lightmap.data, 0.7, rtol=1e-6)
    assert any("one value everywhere (largest channel 0.7 in every pixel)" in n for n in est.notes)


def test_lights_summary_names_each_reasons_photos():
    # three misfired flashes and a light behind the ball were only counted ("no_highlight 4")
    from ffls.commands.lights import summary
    from ffls.io.capture import Lights

    names = [f"IMG_{k}.JPG" for k in range(1000, 1008)]
    status = ["ok", "rejected", "ok", "rejected", "rejected", "rejected", "rejected", "rejected"]
    reasons = [None, "no_highlight", None, "no_highlight", "no_highlight", "no_highlight", "no_highlight",
               "saturated"]
    lights = Lights(names, np.tile([0.0, 0.0, 1.0], (8, 1)), status=status, reasons=reasons,
                    extra=[{"uncertainty_deg": 1.0} if s == "ok" else {} for s in status])
    lines = summary(lights).splitlines()
    assert lines[1] == ("rejected: no_highlight 5 (IMG_1001.JPG, IMG_1003.JPG, IMG_1004.JPG, IMG_1005.JPG, "
                        "... (1 more)): no compact highlight on the mirror sphere (light behind it, or off)")
    assert lines[2] == "          saturated 1 (IMG_1007.JPG): the lit part of the spheres is clipped"


def test_voronoi_integration_in_bands_of_rows(monkeypatch):
    # relight --map-res full on an 8192 x 4096 map held its 33.5M samples at once: 6.3 GB peak,
    # 70.5 s (banded: 1.0 GB, 30.9 s, the relit EXR byte-identical)
    import tracemalloc

    from ffls.lightmaps import lightmap as lightmap_module
    from ffls.lightmaps.lightmap import LightMap
    from ffls.weights.voronoi import integrate_weights

    rng = np.random.default_rng(0)
    lm = LightMap(rng.uniform(0, 2, (512, 1024, 3)).astype(np.float32), "latlong")
    d = rng.normal(size=(40, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    whole = integrate_weights(lm.samples(), d)  # a tuple of samples: one band
    monkeypatch.setattr(lightmap_module, "DOWNSAMPLE_BAND_BYTES", 1 << 20)
    tracemalloc.start()
    banded = integrate_weights(lm, d)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    np.testing.assert_allclose(banded.weights, whole.weights, rtol=1e-12)
    np.testing.assert_allclose(banded.total_power, whole.total_power, rtol=1e-12)
    np.testing.assert_allclose(banded.dropped_power, whole.dropped_power, rtol=1e-12)
    assert banded.dropped_texels == whole.dropped_texels
    samples_bytes = lm.data.shape[0] * lm.data.shape[1] * 8 * 7  # directions, radiance, solid angles
    assert peak < samples_bytes / 2
