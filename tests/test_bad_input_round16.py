"""Bad input found by the round-16 tester (briefs s16/atk16, docs/reliability.md "Round 16").

Round 15's leftovers (a ``--lights`` file's unbounded ``uncertainty_deg`` and unchecked ``model``, a
float image's plateau called "clipped") and a fresh attack: ``ffls synth`` flags at their extremes,
``capture.json`` / ``probe.json`` / ``lights.json`` with wrong-typed nested keys, brackets that mix
bit depths. The promise checked is the one of ``tests/test_bad_input.py``: exit status 2, one stderr
line naming the flag or file, nothing left; and valid but unusual input read (no false refusal).
"""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from cli_lines import entries, one_line, tiny_capture


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r16"), seed=16)


def _edited(cap, tmp_path, name: str, edit) -> object:
    """A copy of the capture whose JSON file ``name`` went through ``edit(doc)``."""
    c = tmp_path / "c"
    shutil.copytree(cap, c)
    doc = json.loads((c / name).read_text())
    edit(doc)
    (c / name).write_text(json.dumps(doc))
    return c


def _relight(capfd, c, tmp_path):
    rc, line = one_line(capfd, ["relight", c, "--probe", "sky", "-o", tmp_path / "o.exr", "--workers", "1"])
    assert rc == 2 and not (tmp_path / "o.exr").exists()
    return line


# ----------------------------------------------------------------------------- lights.json (round 15's leftovers)
@pytest.mark.parametrize("cone", [181.0, 1e9])
def test_a_cone_wider_than_the_sphere_is_refused(cap, tmp_path, capfd, cone):
    """Round 15: ``uncertainty_deg`` had no upper bound (1e6 was read; ``composite --fill`` takes it
    as a margin in degrees)."""
    def edit(d):
        d["lights"][0]["uncertainty_deg"] = cone
    line = _relight(capfd, _edited(cap, tmp_path, "lights.json", edit), tmp_path)
    assert "lights.json" in line and "uncertainty_deg" in line and "between 0 and 180 deg" in line


def test_the_writer_caps_cones_at_180_deg(tmp_path):
    """``ffls lights`` writes sphere cones of up to 1617 deg (bench c00..ds04): what it writes is
    capped, so that its own file loads back under the reader's bound. The cap is applied when the
    ``Lights`` is built, so that what the command prints of its cones (the median) is the file's."""
    from ffls.io.capture import Lights, load_lights, save_lights

    extra = [{"uncertainty_deg": 400.0, "model": "distant",
              "spheres": [{"uncertainty_deg": 1616.7}, {"uncertainty_deg": 3.0}]}]
    lights = Lights(image_names=["a.exr"], directions=np.array([[0.0, 0.0, 1.0]]), positions=np.full((1, 3), np.nan),
                    status=["ok"], reasons=[None], extra=extra)
    assert lights.extra[0]["uncertainty_deg"] == 180.0 and lights.cones_deg([0]).tolist() == [180.0]
    save_lights(lights, tmp_path / "l.json")
    back = load_lights(tmp_path / "l.json")
    assert back.extra[0]["uncertainty_deg"] == 180.0
    assert [s["uncertainty_deg"] for s in back.extra[0]["spheres"]] == [180.0, 3.0]
    # the estimate's own records are left as they were
    assert extra[0]["uncertainty_deg"] == 400.0 and extra[0]["spheres"][0]["uncertainty_deg"] == 1616.7


def test_a_cone_widened_for_the_tilt_stays_capped(tmp_path):
    """A built ``Lights``'s cone widened in place by a fitted tilt's error (``widen_for_tilt``) is
    capped again: 179 deg widened by 30 deg is 181.5 deg, which the reader refuses."""
    from ffls.io.capture import Lights, load_lights, save_lights
    from ffls.spheres.estimate import widen_for_tilt

    lights = Lights(image_names=["a.exr"], directions=np.array([[0.0, 0.0, 1.0]]), positions=np.full((1, 3), np.nan),
                    status=["ok"], reasons=[None], extra=[{"uncertainty_deg": 179.0, "model": "distant"}],
                    frame={"world_from_camera": np.eye(4), "source": "fitted", "tilt_uncertainty_deg": 30.0})
    widen_for_tilt(lights)
    assert lights.extra[0]["uncertainty_deg"] == 180.0 and lights.extra[0]["tilt_widened_deg"] == 30.0
    save_lights(lights, tmp_path / "l.json")
    assert load_lights(tmp_path / "l.json").extra[0]["uncertainty_deg"] == 180.0


@pytest.mark.parametrize("model, position, expect", [
    ("far", None, "model: expected one of ('distant', 'near')"),
    (3, None, "model: expected one of"),
    ("near", None, "a near light needs a position"),
    ("distant", [0.0, 0.0, 2.0], "a distant light has no position"),
])
def test_a_lights_model_is_checked(cap, tmp_path, capfd, model, position, expect):
    """Round 15: a light's ``model`` was read whatever it said, and a "distant" light with a position
    was used by ``composite`` as a near one."""
    def edit(d):
        d["lights"][0]["model"] = model
        if position is not None:
            d["lights"][0]["position"] = position
    line = _relight(capfd, _edited(cap, tmp_path, "lights.json", edit), tmp_path)
    assert "lights.json" in line and "img_0000" in line and expect in line


def test_lights_written_by_ffls_lights_still_load(tmp_path):
    """The guard: every ``lights_estimated.json`` shape ffls writes (distant without a position,
    near with one, a rejected light of model null) is read."""
    from ffls.io.capture import Lights, load_lights, save_lights

    lights = Lights(image_names=["a.exr", "b.exr", "c.exr"], directions=np.eye(3)[[2, 2, 2]],
                    positions=np.array([[np.nan] * 3, [0.0, 0.0, 2.0], [np.nan] * 3]),
                    status=["ok", "ok", "rejected"], reasons=[None, None, "no sphere lit"],
                    extra=[{"uncertainty_deg": 2.0, "model": "distant"}, {"uncertainty_deg": 180.0, "model": "near"},
                           {"uncertainty_deg": None, "model": None}])
    save_lights(lights, tmp_path / "l.json")
    assert load_lights(tmp_path / "l.json").status == ["ok", "ok", "rejected"]


# ----------------------------------------------------------------------------- ffls synth at its extremes
@pytest.mark.parametrize("vig, expect", [
    ("radial:-10", "reaches -0.00489 at r = 0.317"),  # black from a third of the way out: was clipped at 0
    ("radial:-1", "reaches 0 at r = 1"),
    ("radial:2,-5,2", "reaches 0 at r = 1"),
    ("radial:1e300", "brightens to 1e+300"),  # was "warning: overflow encountered in cast", status 0
    ("radial:0.1", "brightens to 1.1"),
])
def test_synth_vignetting_that_is_no_falloff_is_refused(tmp_path, capfd, vig, expect):
    rc, line = one_line(capfd, ["synth", tmp_path / "s", "--lights", "2", "--resolution", "16", "--quiet",
                                "--vignetting", vig])
    assert rc == 2 and "--vignetting" in line and expect in line and not (tmp_path / "s").exists()


@pytest.mark.parametrize("vig", ["radial:-0.99", "radial:-0.4,0.1", "radial:-0.3"])
def test_synth_strong_vignetting_is_read(tmp_path, capfd, vig):
    from ffls.cli import main

    assert main(["synth", str(tmp_path / "s"), "--lights", "2", "--resolution", "16", "--quiet",
                 "--vignetting", vig]) == 0


# ----------------------------------------------------------------------------- brackets
def _bracket(tmp_path, depths):
    import cv2

    rng = np.random.default_rng(7)
    scene = rng.uniform(0.05, 0.9, (16, 16, 3))
    paths = []
    for k, bits in enumerate(depths):
        top = 255 if bits == 8 else 65535
        img = np.round(np.clip(scene * 2.0 ** k / 2, 0, 1) * top).astype(np.uint8 if bits == 8 else np.uint16)
        paths.append(tmp_path / f"b{k}.png")
        cv2.imwrite(str(paths[-1]), img)
    return paths


def test_a_bracket_mixing_8_and_16_bit_files_is_refused(tmp_path, capfd):
    """A capture mixing 8- and 16-bit photos is refused (round 14); a bracket was merged."""
    paths = _bracket(tmp_path, (16, 8, 16))
    rc, line = one_line(capfd, ["probe", "merge", *paths, "--exposures", "1,2,4", "--encoding", "srgb",
                                "-o", tmp_path / "m.exr"])
    assert rc == 2 and "b1.png" in line and "8-bit" in line and "2 of the 3 bracketed images are 16-bit" in line
    assert not (tmp_path / "m.exr").exists()


def test_a_bracket_of_one_depth_is_merged(tmp_path, capfd):
    from ffls.cli import main

    paths = _bracket(tmp_path, (16, 16, 16))
    assert main(["probe", "merge", *map(str, paths), "--exposures", "1,2,4", "--encoding", "srgb",
                 "-o", str(tmp_path / "m.exr")]) == 0


# ----------------------------------------------------------------------------- a float image's plateau
def test_a_float_plateau_is_not_called_clipped_alone(tmp_path):
    """Round 15: a render's flat brightest region (a sun of constant radiance) was reported as
    "N pixels clipped". Nothing in the values tells it from a raw converter's clip (both are a
    plateau at the maximum, bordered by values near it), so it is still taken as clipped, and
    the note says what was seen and that a render's flat region reads the same."""
    from ffls.io.probe import load_probe
    from ffls.probes.bracket import view_radiance
    from ffls.synth.probe import write_mirror_probe

    m = np.full((32, 64, 3), 0.2, np.float32)
    m[6:10, 20:26] = 50.0  # a sun of constant radiance on a coarse map
    write_mirror_probe(tmp_path / "p", m, size=(160, 160), camera_model="orthographic", center_px=(80, 80),
                       radius_px=70, sphere="pixel")
    probe = load_probe(tmp_path / "p")
    vr = view_radiance(probe.views[0], probe.encoding, probe.response, probe.folder / "probe.json")
    assert vr.saturated.sum() > 0
    assert "plateau at its maximum (50)" in vr.note and "render's flat brightest region" in vr.note
    assert "pixels clipped" not in vr.note


# ----------------------------------------------------------------------------- capture.json's sphere materials
@pytest.mark.parametrize("edit, expect", [
    (lambda d: d.update(sphere_material="chrome"), 'sphere_material: expected one of \'matte\', \'mirror\', \'auto\', '
                                                   'got "chrome"'),
    (lambda d: d.update(sphere_material=["mirror"]), "sphere_material: expected one of"),
    (lambda d: d.update(spheres=[{"center_px": [12, 12], "radius_px": 4, "material": 7}]),
     "spheres[0].material: expected one of"),
    (lambda d: d.update(spheres=[{"center_px": [12, 12], "radius_px": 4, "materal": "mirror"}]),
     "spheres[0].materal: unknown key; did you mean 'material'?"),
    (lambda d: d.update(spheres=[{"center_px": [12, 12], "radius_pix": 4}]),
     "spheres[0].radius_pix: unknown key; did you mean 'radius_px'?"),
])
def test_sphere_materials_and_hint_keys_are_checked_where_read(cap, tmp_path, capfd, edit, expect):
    """A material was checked only once the spheres were found (``lights`` on bench c08: refused
    after 6.8 s, now 1.7 s), and never by ``relight``; a misspelt hint key dropped what it said."""
    c = _edited(cap, tmp_path, "capture.json", edit)
    for argv in (["lights", c, "-o", tmp_path / "l.json", "--workers", "1", "--no-progress"],
                 ["relight", c, "--probe", "sky", "-o", tmp_path / "o.exr", "--workers", "1"]):
        rc, line = one_line(capfd, argv)
        assert rc == 2 and "capture.json" in line and expect in line
    assert entries(tmp_path) == {"c"}


def test_a_stated_material_and_own_hint_keys_are_read(cap, tmp_path):
    from ffls.io.capture import load_capture

    c = _edited(cap, tmp_path, "capture.json", lambda d: d.update(
        sphere_material="mirror", spheres=[{"center_px": [12, 12], "radius_px": 4, "material": "matte",
                                            "x-note": "the left ball"}]))
    got = load_capture(c)
    assert got.extra["sphere_material"] == "mirror" and got.spheres[0]["material"] == "matte"


# ----------------------------------------------------------------------------- a flag given twice
@pytest.mark.parametrize("argv, flag", [
    (["synth", "{t}/s", "--lights", "2", "--lights", "3", "--resolution", "16"], "--lights"),
    (["relight", "{cap}", "--probe", "sky", "--exposure", "1", "--exposure", "2", "-o", "{t}/o.exr"], "--exposure"),
    (["lightmap", "make", "sky", "{t}/a.exr", "--height", "16", "--height", "32"], "--height"),
    (["probe", "mirror", "{t}/p", "-o", "{t}/a.exr", "-o", "{t}/b.exr"], "-o/--out"),  # (a parents= flag)
])
def test_a_flag_given_twice_with_two_values_is_refused(cap, tmp_path, capfd, argv, flag):
    """argparse kept the last value silently (``-o a.exr ... -o b.exr`` wrote b.exr), as a JSON key
    given twice was read before round 11: which one is meant?"""
    argv = [a.format(t=tmp_path, cap=cap) for a in argv]
    rc, line = one_line(capfd, argv)
    assert rc == 2 and f"argument {flag}: given twice" in line and "which one is meant" in line
    assert entries(tmp_path) == set()


def test_a_flag_given_twice_with_one_value_is_read(tmp_path, capfd):
    from ffls.cli import main

    assert main(["lightmap", "make", "sky", str(tmp_path / "a.exr"), "--height", "16", "--height", "16"]) == 0
    assert main(["lightmap", "make", "sky", str(tmp_path / "b.exr"), "--half", "--half"]) == 0


# ----------------------------------------------------------------------------- a stated circle of less than a pixel
@pytest.mark.parametrize("circle, expect", [
    ({"center_px": [80, 80], "radius_px": 1e-9}, "radius 1e-09 px, holds at most one pixel"),
    ({"center_px": [80.5, 80.5], "radius_px": 0.6}, "holds at most one pixel"),
])
def test_a_probe_circle_of_no_pixels_names_probe_json(tmp_path, capfd, circle, expect):
    """Round 15 named probe.json for a circle off the photo; one of 1e-9 px on it blamed the photo:
    "ball.exr: the ball shows no usable direction"."""
    from ffls.synth.probe import write_mirror_probe

    m = np.random.default_rng(1).uniform(0.1, 1.0, (32, 64, 3)).astype(np.float32)
    write_mirror_probe(tmp_path / "p", m, size=(160, 160), camera_model="orthographic", center_px=(80, 80),
                       radius_px=70, sphere="pixel")
    doc = json.loads((tmp_path / "p" / "probe.json").read_text())
    doc["sphere"].update(circle)
    (tmp_path / "p" / "probe.json").write_text(json.dumps(doc))
    rc, line = one_line(capfd, ["probe", "mirror", tmp_path / "p", "-o", tmp_path / "m.exr"])
    assert rc == 2 and "probe.json" in line and expect in line and not (tmp_path / "m.exr").exists()
