"""``ffls probe diffuse | shadow | pocs`` on probe folders: the wiring of the inverse methods, and bad input."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ffls.cli import main
from ffls.errors import InputError
from ffls.io.images import read_image, write_exr
from ffls.lightmaps.lightmap import builtin_lightmap, load_lightmap
from ffls.probes import estimate_lightmap
from ffls.synth.probe_scenes import cast_shadow_scene, diffuse_sphere_scene, write_diffuse_probe


@pytest.fixture(scope="module")
def truth():
    return builtin_lightmap("courtyard").downsample(16)  # 32 x 64


@pytest.fixture(scope="module")
def diffuse_folder(tmp_path_factory, truth):
    sc = diffuse_sphere_scene(truth, resolution=64, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("diffuse"), sc)


def _top_view(res, extent, height=1000.0):
    """A pinhole camera far above, looking down, whose pixels match cast_shadow_scene's orthographic grid."""
    f = height * res / (2 * extent)
    K = [[f, 0, res / 2 - 0.5], [0, f, res / 2 - 0.5], [0, 0, 1]]
    T = np.eye(4)
    T[:3, :3] = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]]).T
    T[:3, 3] = [0, 0, height]
    return K, T


@pytest.fixture(scope="module")
def shadow_folder(tmp_path_factory, truth):
    d = tmp_path_factory.mktemp("shadow")
    ss = cast_shadow_scene(truth, resolution=48, extent=1.0, n_dirs=256)
    K, T = _top_view(48, 1.0)
    write_exr(d / "shadow.exr", ss.image)
    write_exr(d / "surface.exr", ss.surface_image)
    doc = {"format": "ffls-probe", "version": 1, "images": ["shadow.exr"],
           "camera": {"K": K, "world_from_camera": T.tolist()},
           "plane": {"point": [0, 0, 0], "normal": [0, 0, 1], "albedo": 0.6},
           "occluder": {"box": {"center": ss.box_center.tolist(), "size": ss.box_size.tolist()}},
           "surface_image": "surface.exr"}
    (d / "probe.json").write_text(json.dumps(doc))
    return d


@pytest.mark.parametrize("argv", [["diffuse", "--sources", "9"], ["diffuse", "--sources", "auto", "--criterion", "bic"], ["diffuse", "--sources", "17", "--unconstrained", "--ambient", "free"],
                                  ["diffuse", "--sources", "uniform"], ["diffuse", "--sources", "adaptive", "--criterion", "bic"],
                                  ["pocs", "--sources", "grid", "--grid", "8", "--iterations", "10", "--scheme", "sequential"],
                                  ["pocs", "--criterion", "bic", "--iterations", "10", "--scheme", "sequential"]])
def test_diffuse_methods_write_maps(diffuse_folder, tmp_path, capsys, argv):
    out = tmp_path / "m.exr"
    assert main(["probe", argv[0], str(diffuse_folder), "-o", str(out), "--size", "16", *argv[1:]]) == 0
    err = capsys.readouterr().err
    assert ("Hougen-Ahuja" in err) if argv[0] == "diffuse" else ("residual" in err and "iterations" in err)
    img = read_image(out)
    assert img.pixels.shape == (16, 32, 3) and img.alpha is not None and 0.5 < img.alpha.mean() < 1.0
    lm = load_lightmap(out)
    assert np.all(np.isfinite(lm.data)) and lm.data.min() >= 0


def test_pocs_reports_convergence(diffuse_folder):
    est = estimate_lightmap(diffuse_folder, "pocs", height=16, grid=8, iterations=8, sources="grid",
                            scheme="sequential")
    r = est.details["residuals"]
    assert len(r) == 9 and r[-1] < r[0]


@pytest.mark.parametrize("case", ["lambertian", "ratio"])
def test_shadow_method(shadow_folder, tmp_path, case):
    out = tmp_path / "s.exr"
    assert main(["probe", "shadow", str(shadow_folder), "-o", str(out), "--size", "16", "--nodes", "46",
                 "--case", case]) == 0
    est = estimate_lightmap(shadow_folder, "shadow", height=16, nodes=46, case=case)
    assert est.details["nodes"] == 46 and est.lightmap.data.min() >= 0
    # the lower hemisphere casts no shadow on the plane: never seen
    assert not est.seen[12:].any() and est.seen[:8].any()


def test_shadow_seen_by_an_orthographic_camera(shadow_folder, tmp_path):
    """The same photo described as orthographic (camera.pixel_size) gives the pinhole's map."""
    doc = json.loads((shadow_folder / "probe.json").read_text())
    T = np.array(doc["camera"]["world_from_camera"])
    T[:3, 3] = [0.0, 0.0, 5.0]
    doc["camera"] = {"model": "orthographic", "pixel_size": 2.0 / 48, "world_from_camera": T.tolist()}
    for name in ("shadow.exr", "surface.exr"):
        (tmp_path / name).write_bytes((shadow_folder / name).read_bytes())
    (tmp_path / "probe.json").write_text(json.dumps(doc))
    ortho = estimate_lightmap(tmp_path, "shadow", height=16, nodes=46)
    pin = estimate_lightmap(shadow_folder, "shadow", height=16, nodes=46)
    a, b = ortho.lightmap.data, pin.lightmap.data
    assert np.sqrt(np.mean((a - b) ** 2)) < 0.02 * np.sqrt(np.mean(b ** 2))


def test_bad_input(diffuse_folder, shadow_folder, tmp_path):
    doc = json.loads((shadow_folder / "probe.json").read_text())
    far = tmp_path / "far"
    far.mkdir()
    for name in ("shadow.exr", "surface.exr"):
        (far / name).write_bytes((shadow_folder / name).read_bytes())
    # an occluder whose shadow falls on no pixel in view
    doc_far = dict(doc, occluder={"box": {"center": [0, 0, -50.0], "size": [0.1, 0.1, 0.1]}})
    (far / "probe.json").write_text(json.dumps(doc_far))
    with pytest.raises(InputError) as e:
        estimate_lightmap(far, "shadow", height=16, nodes=46)
    assert "shadow" in str(e.value) and "probe.json" in str(e.value) and "\n" not in str(e.value)
    # an occluder so large that it stands between the camera and every pixel of the plane
    huge = dict(doc, occluder={"box": {"center": [0, 0, 0.25], "size": [1e308, 1e308, 1e308]}})
    (far / "probe.json").write_text(json.dumps(huge))
    with pytest.raises(InputError, match="occluder.box hides every pixel of the plane") as e:
        estimate_lightmap(far, "shadow", height=16, nodes=46)
    assert "\n" not in str(e.value)
    for drop, key in (("plane", "plane"), ("occluder", "occluder")):
        (far / "probe.json").write_text(json.dumps({k: v for k, v in doc.items() if k != drop}))
        with pytest.raises(InputError, match=key):
            estimate_lightmap(far, "shadow", height=16)
    (far / "probe.json").write_text(json.dumps(dict(doc, camera={"model": "orthographic"})))
    with pytest.raises(InputError, match="pixel_size"):
        estimate_lightmap(far, "shadow", height=16)
    # a singular system: too few pixels for the sources
    tiny = tmp_path / "tiny"
    tiny.mkdir()
    sc = diffuse_sphere_scene(builtin_lightmap("courtyard").downsample(16), resolution=16, albedo=0.7,
                              radius_frac=0.2)
    write_exr(tiny / "ball.exr", sc.image)
    d = json.loads((diffuse_folder / "probe.json").read_text())
    d["sphere"].update(center_px=sc.center_px.tolist(), radius_px=sc.radius_px)
    (tiny / "probe.json").write_text(json.dumps(d))
    with pytest.raises(InputError) as e:
        estimate_lightmap(tiny, "diffuse", height=16, sources=162)
    assert "probe.json" in str(e.value) and "\n" not in str(e.value)
    # a measured circle larger than the photo is named as such (not as too few cross-validation blocks)
    big = dict(d, sphere=dict(d["sphere"], radius_px=500.0))
    (tiny / "probe.json").write_text(json.dumps(big))
    with pytest.raises(InputError, match=r"sphere.center_px and radius_px: the circle \([0-9]+, [0-9]+\) px, "
                                         r"radius 500 px, is larger than the photo \(16x16 px\)"):
        estimate_lightmap(tiny, "diffuse", height=16, sources=9)
    (tiny / "probe.json").write_text(json.dumps(d))
    # the wrong material for the method
    d["sphere"]["material"] = "mirror"
    d["sphere"].pop("albedo")
    (tiny / "probe.json").write_text(json.dumps(d))
    with pytest.raises(InputError, match="diffuse sphere"):
        estimate_lightmap(tiny, "pocs", height=16)
    with pytest.raises(InputError, match="multiple of the POCS grid"):
        estimate_lightmap(diffuse_folder, "pocs", height=20, grid=16, sources="grid")


def test_diffuse_object_of_known_geometry(tmp_path, truth):
    """Hougen-Ahuja on a mesh object (an icosphere, scaled and moved by its pose) seen by a pinhole camera."""
    import trimesh

    from ffls.probes.linear import irradiance_from_map
    from ffls.spheres.detect import sphere_normals
    from ffls.synth.probe import look_at

    T = look_at([0.0, -1.0, 0.3], target=(0.1, 0.0, 0.05))
    K = np.array([[400.0, 0, 48], [0, 400.0, 48], [0, 0, 1]])
    C = np.array([0.1, 0.0, 0.05])
    Ti = np.linalg.inv(T)
    Cc = Ti[:3, :3] @ C + Ti[:3, 3]
    yy, xx = np.mgrid[0:96, 0:96]
    px = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(float)
    n = sphere_normals(px, K, None, Cc, 0.1)
    hit = np.all(np.isfinite(n), axis=1)
    img = np.zeros((96 * 96, 3), np.float32)
    img[hit] = 0.7 / np.pi * irradiance_from_map(n[hit] @ T[:3, :3].T, truth)
    write_exr(tmp_path / "obj.exr", img.reshape(96, 96, 3))
    trimesh.creation.icosphere(subdivisions=3).export(tmp_path / "ball.ply")
    pose = np.diag([0.1, 0.1, 0.1, 1.0])
    pose[:3, 3] = C
    doc = {"format": "ffls-probe", "version": 1, "images": ["obj.exr"],
           "camera": {"K": K.tolist(), "world_from_camera": T.tolist()},
           "object": {"mesh": "ball.ply", "world_from_object": pose.tolist(), "albedo": 0.7}}
    (tmp_path / "probe.json").write_text(json.dumps(doc))
    mesh = estimate_lightmap(tmp_path, "diffuse", height=16, sources=9)
    doc.pop("object")
    doc["sphere"] = {"center": C.tolist(), "radius": 0.1, "material": "diffuse", "albedo": 0.7}
    (tmp_path / "probe.json").write_text(json.dumps(doc))
    sphere = estimate_lightmap(tmp_path, "diffuse", height=16, sources=9)
    from ffls.probes.evaluate import relit_error

    assert any("pixels on the mesh ball.ply" in x for x in mesh.notes)
    e_mesh, e_sphere = relit_error(mesh.lightmap, truth), relit_error(sphere.lightmap, truth)
    assert e_mesh < e_sphere + 0.01
    # a pixel circle given beside the world centre must agree with it, not be ignored
    from ffls.camera.projection import project_points

    at = project_points(Cc[None], K, np.zeros(5))[0]
    for px, ok in (([at[0] + 1.0, at[1]], True), ([5.0, 5.0], False)):
        doc["sphere"]["center_px"] = [float(v) for v in px]
        (tmp_path / "probe.json").write_text(json.dumps(doc))
        if ok:
            estimate_lightmap(tmp_path, "diffuse", height=16, sources=9)
        else:
            with pytest.raises(InputError, match=r"sphere.center_px \(5, 5\) px disagrees with sphere.center"):
                estimate_lightmap(tmp_path, "diffuse", height=16, sources=9)


def test_shadow_adaptive_nodes(shadow_folder, tmp_path, capsys):
    out = tmp_path / "a.exr"
    assert main(["probe", "shadow", str(shadow_folder), "-o", str(out), "--size", "16", "--nodes", "adaptive",
                 "--criterion", "bic"]) == 0
    assert "adaptive sources, BIC" in capsys.readouterr().err
    est = estimate_lightmap(shadow_folder, "shadow", height=16, nodes="adaptive", criterion="bic")
    assert est.details["nodes"] >= 46 and est.lightmap.data.min() >= 0


@pytest.mark.parametrize("value", ["many", "0", "-3"])
def test_bad_sources_value_is_one_line(diffuse_folder, tmp_path, capsys, value):
    assert main(["probe", "diffuse", str(diffuse_folder), "-o", str(tmp_path / "x.exr"), "--sources", value]) == 2
    err = capsys.readouterr().err
    assert "--sources" in err and "'auto', 'adaptive' or 'uniform'" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "x.exr").exists()


def test_a_count_no_set_has_reports_the_size_used(diffuse_folder, shadow_folder, tmp_path, capsys):
    """--nodes 1 / --sources 2: the nearest geodesic set is used, and the output says which size."""
    assert main(["probe", "shadow", str(shadow_folder), "-o", str(tmp_path / "s.exr"), "--size", "16",
                 "--nodes", "1"]) == 0
    err = capsys.readouterr().err
    est = estimate_lightmap(shadow_folder, "shadow", height=16, nodes=1)
    n = est.details["nodes"]
    assert n > 1 and f"--nodes 1: no geodesic dome has that size; the nearest has {n}" in err
    assert f"{n} dome nodes" in err and " 1 dome nodes" not in err
    est = estimate_lightmap(diffuse_folder, "diffuse", height=16, sources=2)
    assert est.details["sources"] > 2 and any("--sources 2: no model set has that size" in x for x in est.notes)


def test_sources_over_the_limit_says_the_limit(diffuse_folder, tmp_path, capsys):
    assert main(["probe", "diffuse", str(diffuse_folder), "-o", str(tmp_path / "x.exr"), "--sources", "1000000"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "at most 100000" in err[0], err


@pytest.mark.parametrize("flags,named", [
    (["--grid", "4"], "--grid applies with --sources grid"),
    (["--sources", "adaptive", "--grid", "4"], "--grid applies with --sources grid"),
    (["--scheme", "extrapolated", "--order", "sequential"], "--order applies with --scheme sequential"),
    (["--scheme", "extrapolated", "--seed", "5"], "--seed applies with --scheme sequential"),
    (["--scheme", "sequential", "--order", "sequential", "--seed", "5"],
     "--seed applies with a random projection order"),
    (["--order", "random"], "--order applies with --scheme sequential"),   # the default is least-power
])
def test_pocs_flags_of_another_setting_are_refused_not_ignored(diffuse_folder, tmp_path, capsys, flags, named):
    assert main(["probe", "pocs", str(diffuse_folder), "-o", str(tmp_path / "x.exr"), "--size", "8", *flags]) == 2
    err = capsys.readouterr().err
    assert named in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert not (tmp_path / "x.exr").exists()
