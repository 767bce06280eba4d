"""probe.json: what it accepts, and one line naming the file and key for everything it refuses."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.io.images import write_exr, write_png
from ffls.io.probe import PROBE_FILE, load_probe, read_mesh

K = [[500.0, 0.0, 64.0], [0.0, 500.0, 64.0], [0.0, 0.0, 1.0]]
CUBE_OBJ = """# a unit cube
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1
f 1 2 3 4\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8
"""


def _folder(tmp_path, doc, images=("ball.exr",), pngs=()):
    for name in images:
        if name in pngs:
            continue
        write_exr(tmp_path / name, np.full((8, 8, 3), 0.5, np.float32))
    for name in pngs:
        write_png(tmp_path / name, np.full((8, 8, 3), 128, np.uint8))
    base = {"format": "ffls-probe", "version": 1, "images": list(images)}
    base.update(doc)
    (tmp_path / PROBE_FILE).write_text(json.dumps(base))
    return tmp_path


def test_minimal_probe_defaults(tmp_path):
    p = load_probe(_folder(tmp_path, {}))
    assert len(p.views) == 1 and not p.view.is_bracket
    assert p.view.camera.model == "pinhole" and p.view.camera.K is None
    assert p.view.sphere.location == "auto" and p.view.sphere.material is None  # the command says what it is
    assert p.encoding == "auto" and p.plane is None and p.occluder is None and p.surface_image is None


def test_full_probe(tmp_path):
    (tmp_path / "cube.obj").write_text(CUBE_OBJ)
    doc = {"camera": {"K": K, "dist": [0.01, 0, 0, 0, 0]}, "encoding": "srgb",
           "sphere": {"center": [0, 0, 0], "radius": 0.1, "material": "diffuse", "albedo": 0.8},
           "plane": {"point": [0, 0, 0], "normal": [0, 0, 2], "albedo": 0.5},
           "occluder": {"box": {"center": [0, 0, 0.1], "size": [0.2, 0.2, 0.2]}},
           "object": {"mesh": "cube.obj", "world_from_object": np.diag([2.0, 2, 2, 1]).tolist(), "albedo": 0.7},
           "surface_image": "surface.png", "x-note": "kept"}
    p = load_probe(_folder(tmp_path, doc, images=("ball.png",), pngs=("ball.png", "surface.png")))
    assert p.encoding == "srgb" and p.view.sphere.location == "world" and p.view.sphere.albedo == 0.8
    np.testing.assert_allclose(p.plane.normal, [0, 0, 1])
    assert p.occluder.kind == "box" and p.occluder.size.tolist() == [0.2, 0.2, 0.2]
    assert p.object.faces.shape == (12, 3) and p.object.vertices.max() == 2.0  # quads triangulated, scaled
    assert p.object_albedo == 0.7 and p.surface_image.name == "surface.png" and p.extra == {"x-note": "kept"}


def test_bracket_and_views(tmp_path):
    doc = {"images": [{"file": "a.exr", "exposure_s": 0.01}, {"file": "b.exr", "exposure_s": 0.04}]}
    p = load_probe(_folder(tmp_path, doc, images=("a.exr", "b.exr")))
    assert p.view.is_bracket and [im.exposure_s for im in p.view.images] == [0.01, 0.04]
    T2 = np.eye(4)
    T2[:3, :3] = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]
    doc = {"camera": {"K": K}, "sphere": {"center": [0, 0, 2], "radius": 0.1},
           "images": [{"images": ["a.exr"]}, {"images": ["b.exr"], "camera": {"K": K, "world_from_camera": T2.tolist()}}]}
    p = load_probe(_folder(tmp_path, doc, images=("a.exr", "b.exr")))
    assert len(p.views) == 2 and p.views[1].camera.world_from_camera[0, 2] == 1
    assert p.views[1].sphere.center.tolist() == [0, 0, 2]  # the top-level sphere is the default


def test_mesh_occluder_ply(tmp_path):
    import trimesh

    trimesh.creation.box().export(tmp_path / "box.ply")
    p = load_probe(_folder(tmp_path, {"occluder": {"mesh": "box.ply"}}))
    assert p.occluder.kind == "mesh" and p.occluder.mesh.faces.shape == (12, 3)
    v, f = read_mesh(tmp_path / "box.ply", np.diag([1.0, 1, 1, 1]))
    assert v.shape == (8, 3)


BAD = [
    ({"format": "ffls-capture"}, "format"),
    ({"version": 2}, "version"),
    ({"images": []}, "images"),
    ({"images": ["missing.exr"]}, "images[0]"),
    ({"images": ["ball.exr", "ball2.exr"]}, "exposure_s"),
    ({"images": [{"file": "ball.exr", "exposure_s": 0.1}]}, "at least two"),
    ({"images": [{"file": "ball.exr", "exposure_s": -1}, {"file": "ball2.exr", "exposure_s": 1}]}, "images[0].exposure_s"),
    ({"images": [{"file": "ball.exr", "exposure_s": 1e-300}, {"file": "ball2.exr", "exposure_s": 1}]},
     "images[0].exposure_s: 1e-300 s is not an exposure time"),
    ({"images": [{"file": "ball.exr"}, {"file": "ball2.exr", "exposure_s": 1}]}, "images[0].exposure_s"),
    ({"images": ["ball.exr", {"file": "ball2.exr", "exposure_s": 1}]}, "images[1]"),
    ({"images": ["../ball.exr"]}, "images[0]"),
    ({"images": ["/tmp/ball.exr"]}, "images[0]: file name '/tmp/ball.exr' must be a path relative to the folder of probe.json"),
    ({"images": [{"file": "ball.exr", "exposure_s": 0.1}, {"file": "ball2.exr", "exposure_s": 0.1}]}, "equal"),
    ({"camera": {"K": [[1, 2], [3, 4]]}}, "camera.K"),
    ({"camera": {"model": "orthographic", "K": K}}, "camera"),
    ({"camera": {"K": K, "pixel_size": 0.01}}, "camera.pixel_size"),
    ({"camera": {"model": "orthographic", "pixel_size": -1}}, "camera.pixel_size"),
    ({"images": [{"images": ["ball.exr"], "camera": {"K": "no"}}]}, "images[0].camera.K"),
    ({"images": [{"images": ["ball.exr"], "lens": 1}]}, "images[0]"),
    ({"encoding": "log"}, "encoding"),
    ({"sphere": {"material": "glass"}}, "sphere.material"),
    ({"sphere": {"material": "diffuse", "albedo": 1.5}}, "sphere.albedo"),
    ({"sphere": {"albedo": 0.5}}, "sphere.albedo"),
    ({"sphere": {"center": [0, 0, 0]}}, "sphere.radius"),
    ({"sphere": {"center": [0, 0]}, "x": 1}, "sphere.center"),
    ({"sphere": {"radius_px": 3}}, "sphere.radius_px"),
    ({"sphere": {"center_px": [10, 10], "radius_px": 1e308}}, "sphere.radius_px"),
    ({"sphere": {"center_px": [1e300, 10]}}, "sphere.center_px"),
    ({"sphere": {"reflectance": 0}}, "sphere.reflectance"),
    ({"sphere": {"size": 1}}, "sphere"),
    ({"camera": {"model": "orthographic"}, "sphere": {"center": [0, 0, 0], "radius": 1}}, "sphere.center"),
    ({"plane": {"point": [0, 0, 0], "normal": [0, 0, 0]}}, "plane.normal"),
    ({"plane": {"point": [0, 0, 0]}}, "plane.normal"),
    ({"occluder": {"box": {"center": [0, 0, 0], "size": [1, -1, 1]}}}, "occluder.box.size"),
    ({"occluder": {"box": {"center": [0, 0, 0], "size": [1, 1, 1]}, "mesh": "a.obj"}}, "occluder"),
    ({"occluder": {"mesh": "missing.obj"}}, "occluder.mesh"),
    ({"occluder": {"mesh": "ball.exr"}}, "occluder.mesh"),
    ({"object": {"mesh": "bad.obj"}}, "object.mesh"),
    ({"object": {"albedo": 0.5}}, "object.mesh"),
    ({"surface_image": "nope.png"}, "surface_image"),
    ({"unknown_key": 1}, "unknown_key"),
]


@pytest.mark.parametrize("doc,key", BAD, ids=[k for _, k in BAD])
def test_bad_values_name_the_file_and_key(tmp_path, doc, key):
    (tmp_path / "bad.obj").write_text("this is not a mesh\n")
    doc = {k: v for k, v in doc.items() if k != "x"}
    _folder(tmp_path, {}, images=("ball.exr", "ball2.exr"))
    base = json.loads((tmp_path / PROBE_FILE).read_text())
    base["images"] = ["ball.exr"]
    base.update(doc)
    (tmp_path / PROBE_FILE).write_text(json.dumps(base))
    with pytest.raises(InputError) as e:
        load_probe(tmp_path)
    msg = str(e.value)
    assert "\n" not in msg and key in msg and PROBE_FILE in msg, msg


def test_missing_folder_and_corrupt_json(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_probe(tmp_path / "none")
    (tmp_path / PROBE_FILE).write_text("{")
    with pytest.raises(InputError, match="corrupt JSON"):
        load_probe(tmp_path)
