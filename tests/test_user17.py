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


@pytest.mark.parametrize("scheme", ["voronoi", "gaussian"])
def test_integration_in_bands_of_rows(monkeypatch, scheme):
    # relight --map-res full on an 8192 x 4096 map held its 33.5M samples at once: 6.3 GB peak,
    # 70.5 s (banded: 1.0 GB, 30.9 s, the relit EXR byte-identical); gaussian 4.9 -> 1.0 GB
    import tracemalloc

    from ffls.lightmaps import lightmap as lightmap_module
    from ffls.lightmaps.lightmap import LightMap
    from ffls.weights.weighting import integrate

    def integrate_weights(lm, d):
        return integrate(lm, d, scheme=scheme)

    rng = np.random.default_rng(0)
    lm = LightMap(rng.uniform(0, 2, (512, 1024, 3)).astype(np.float32), "latlong")
    d = rng.normal(size=(40, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    monkeypatch.setattr(lightmap_module, "DOWNSAMPLE_BAND_BYTES", 1 << 20)
    peaks = []
    for given in (lm.samples, lambda: lm):  # a tuple of samples (one band), then the map
        tracemalloc.start()
        out = integrate_weights(given(), d)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    whole, banded = integrate_weights(lm.samples(), d), out
    np.testing.assert_allclose(banded.weights, whole.weights, rtol=1e-12)
    np.testing.assert_allclose(banded.total_power, whole.total_power, rtol=1e-12)
    np.testing.assert_allclose(banded.dropped_power, whole.dropped_power, rtol=1e-12)
    assert banded.dropped_texels == whole.dropped_texels
    assert peaks[1] < 0.5 * peaks[0]


def _tiled_exr(path, rgb, mode, tile=16):
    import OpenEXR

    t = OpenEXR.TileDescription()
    t.xSize = t.ySize = tile
    t.mode, t.roundingMode = mode, OpenEXR.ROUND_DOWN
    with OpenEXR.File({"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.tiledimage, "tiles": t},
                      {"RGB": rgb}) as f:
        f.write(str(path))


def _complete_mipmaps(path, rgb, tile=16):
    """Every level's tiles appended to the binding's level-0-only file, the chunk table filled (a
    mip-mapped map as a renderer's tools write it; uncompressed tiles: each row B, G, R float32)."""
    import struct

    b = bytearray(path.read_bytes())
    pos = 8
    while b[pos] != 0:  # the header's attributes: name, type, size, value
        end = b.index(0, b.index(0, pos) + 1)
        pos = end + 5 + struct.unpack_from("<i", b, end + 1)[0]
    pos += 1
    levels, img = [], rgb.astype(np.float64)
    while True:
        levels.append(img.astype(np.float32))
        h, w = img.shape[:2]
        if h == w == 1:
            break
        h2, w2 = max(1, h // 2), max(1, w // 2)
        img = img[:h2 * (h // h2), :w2 * (w // w2)].reshape(h2, h // h2, w2, w // w2, 3).mean(axis=(1, 3))
    n = sum(-(-lv.shape[0] // tile) * -(-lv.shape[1] // tile) for lv in levels)
    out, offsets = bytearray(b[:pos] + bytes(8 * n)), []
    for k, lv in enumerate(levels):
        for ty in range(-(-lv.shape[0] // tile)):
            for tx in range(-(-lv.shape[1] // tile)):
                t = lv[ty * tile:(ty + 1) * tile, tx * tile:(tx + 1) * tile]
                data = b"".join(t[r, :, c].astype("<f4").tobytes() for r in range(t.shape[0]) for c in (2, 1, 0))
                offsets.append(len(out))
                out += struct.pack("<iiiii", tx, ty, k, k, len(data)) + data
    struct.pack_into(f"<{n}Q", out, pos, *offsets)
    path.write_bytes(bytes(out))


def test_mip_mapped_exr_read_or_named(tmp_path):
    # a complete mip-mapped tiled map is read (level 0); the OpenEXR binding's own mip-mapped file
    # (level 0's tiles only) was "corrupt or truncated" with no word of the levels
    import OpenEXR

    from ffls.io.images import read_image

    rgb = np.random.default_rng(0).uniform(0, 5, (64, 128, 3)).astype(np.float32)
    path = tmp_path / "mip.exr"
    _tiled_exr(path, rgb, OpenEXR.MIPMAP_LEVELS)
    with pytest.raises(InputError, match="its header says mip-mapped tiles, whose levels' tiles are not all "
                                         r"there .* write this map with one level"):
        read_image(path)
    _complete_mipmaps(path, rgb)
    np.testing.assert_array_equal(read_image(path).pixels, rgb)
    _tiled_exr(path, rgb, OpenEXR.ONE_LEVEL)
    np.testing.assert_array_equal(read_image(path).pixels, rgb)


def test_occluded_sphere_named_per_photo():
    # a hand over one of four spheres in 5 photos of 80: the sphere kept "ok" at 42-130 times its
    # median RMS residual (cone 180 deg) and the photo accepted, without a word
    from ffls.commands.lights import occlusion_note
    from ffls.io.capture import Lights

    n = 12
    names = [f"img_{k:04d}.exr" for k in range(n)]

    def sphere(rms, status="ok"):
        return {"status": status, "kind": "matte", "rms": rms}

    extra = [{"uncertainty_deg": 0.5, "spheres": [sphere(0.005 + 1e-4 * k), sphere(0.004)]} for k in range(n)]
    assert occlusion_note(Lights(names, np.tile([0.0, 0.0, 1.0], (n, 1)), extra=extra)) is None
    extra[3]["spheres"][0] = sphere(0.3)
    extra[7]["spheres"][1] = sphere(0.02, "shadowed")
    note = occlusion_note(Lights(names, np.tile([0.0, 0.0, 1.0], (n, 1)), extra=extra))
    assert note.startswith("2 accepted photos have a sphere in a shadow or fitting its shading far worse")
    assert note.endswith("(numbered as found): 'img_0003.exr' sphere 0 (53x); 'img_0007.exr' sphere 1 (shadowed)")
