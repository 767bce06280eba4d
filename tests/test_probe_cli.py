"""``ffls probe``: the map it writes loads in ``relight``, ``render`` and ``view``; bad input is one line."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ffls.cli import main
from ffls.io.images import read_image
from ffls.lightmaps.lightmap import lightmap_from_spec, load_lightmap
from ffls.synth.probe import look_at, write_mirror_probe


def _smooth_map(h=32):
    from ffls.conventions import latlong_directions

    d = latlong_directions(2 * h, h)
    return np.stack([1 + 0.5 * d[..., 0], 1 + 0.5 * d[..., 1], 1 + 0.5 * d[..., 2]], -1).astype(np.float32)


@pytest.fixture(scope="module")
def probe_map(tmp_path_factory):
    folder = tmp_path_factory.mktemp("probe")
    K = np.array([[700.0, 0, 80], [0, 700.0, 80], [0, 0, 1]])
    write_mirror_probe(folder, _smooth_map(), (160, 160), K=K, world_from_camera=look_at([0, -1.0, 0.2]), radius=0.1)
    out = folder / "map.exr"
    assert main(["probe", "mirror", str(folder), "-o", str(out), "--size", "16"]) == 0
    return out


def test_probe_writes_a_latlong_map_with_the_seen_mask_as_alpha(probe_map, capsys):
    img = read_image(probe_map)
    assert img.pixels.shape == (16, 32, 3) and img.alpha is not None
    assert set(np.unique(img.alpha)) <= {0.0, 1.0} and 0.85 < img.alpha.mean() < 1.0
    lm = load_lightmap(probe_map)
    assert lm.layout == "latlong" and np.all(np.isfinite(lm.data)) and lm.data.min() > 0  # unseen texels filled
    assert lightmap_from_spec(str(probe_map)).data.shape == (16, 32, 3)  # what view's renderer calls


def test_the_map_relights_and_renders(probe_map, tmp_path):
    from ffls.synth.scene import write_synthetic_capture

    cap = tmp_path / "cap"
    write_synthetic_capture(cap, n_lights=12, resolution=24, progress=False, seed=2)
    assert main(["relight", str(cap), "--probe", str(probe_map), "-o", str(tmp_path / "r.exr")]) == 0
    assert main(["render", str(cap), "--probe", str(probe_map), "--cpu", "-o", str(tmp_path / "r.png")]) == 0
    assert read_image(tmp_path / "r.exr").pixels.max() > 0


def test_view_accepts_the_map(probe_map):
    from ffls.cli import subcommands

    p = subcommands()["view"]
    args = p.parse_args(["capture", "--probe", str(probe_map)])
    assert args.probe == str(probe_map)


@pytest.mark.parametrize("case", ["no folder", "bad json", "bad size", "bad cone", "bad suffix", "sphere"])
def test_bad_input_one_line(tmp_path, capsys, case):
    folder = tmp_path / "p"
    folder.mkdir()
    write_mirror_probe(folder, _smooth_map(8), (48, 48), "orthographic", center_px=(24, 24), radius_px=20,
                       sphere="pixel")
    argv = ["probe", "mirror", str(folder), "-o", str(tmp_path / "m.exr"), "--size", "8"]
    if case == "no folder":
        argv[2] = str(tmp_path / "none")
    elif case == "bad json":
        (folder / "probe.json").write_text("[1]")
    elif case == "bad size":
        argv[-1] = "2"
    elif case == "bad cone":
        argv += ["--camera-cone", "-3"]
    elif case == "bad suffix":
        argv[4] = str(tmp_path / "m.png")
    else:
        doc = json.loads((folder / "probe.json").read_text())
        doc["sphere"]["radius_px"] = "big"
        (folder / "probe.json").write_text(json.dumps(doc))
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "error" in err[0] and "Traceback" not in err[0], err
    assert not (tmp_path / "m.exr").exists()


def test_a_coarse_map_still_reports_the_blind_spot(probe_map):
    # at --size 4 a texel is 45 degrees tall: it holds the camera cone whole and was seen through its
    # other directions, so the blind spot is measured on a finer unwrap, the same as a fine map's
    from ffls.probes import estimate_lightmap

    folder = probe_map.parent
    fine = estimate_lightmap(folder, method="mirror", height=64)
    coarse = estimate_lightmap(folder, method="mirror", height=4)
    assert fine.details["blind_spot_sr"] > 0.05
    assert coarse.details["blind_spot_sr"] == pytest.approx(fine.details["blind_spot_sr"], rel=1e-6)
    assert coarse.details["camera_cone_sr"] == pytest.approx(fine.details["camera_cone_sr"], rel=1e-6)
    assert not any("blind spot: none" in n for n in coarse.notes), coarse.notes
    assert coarse.seen.shape == (4, 8)


def test_the_camera_cone_defaults_to_the_camera_distance(probe_map, capsys):
    """Without ``--camera-cone`` the CLI masks ``atan(0.5 / D)`` as ``docs/probes.md`` says (the library's
    default); it passed 10 degrees as if given, whatever the ball's distance."""
    folder = probe_map.parent
    assert main(["probe", "mirror", str(folder), "-o", str(folder / "d.exr"), "--size", "16"]) == 0
    err = capsys.readouterr().err
    expect = np.degrees(np.arctan(0.5 / np.hypot(1.0, 0.2)))  # the ball at the origin, the camera at (0, -1, 0.2)
    assert f"camera cone {expect:.1f} deg masked (0.5 at " in err, err
    assert main(["probe", "mirror", str(folder), "-o", str(folder / "g.exr"), "--size", "16",
                 "--camera-cone", "10"]) == 0
    assert "camera cone 10.0 deg masked (given)" in capsys.readouterr().err
