"""Colour-managed files (issue 9, item 10): an EXR ``chromaticities`` attribute is converted to the
working space (linear Rec.709, D65) and reported; one that cannot be converted is an error."""
from __future__ import annotations


import numpy as np
import pytest

from ffls.errors import InputError
from ffls.io.colourspace import working_space_conversion
from ffls.io.images import colour_summary, read_image

#: ACEScg (AP1 primaries, ACES white ~D60), as an EXR stores them.
ACESCG = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
REC709 = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)


def _write(path, rgb, chromaticities=None):
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if chromaticities is not None:
        header["chromaticities"] = tuple(float(v) for v in chromaticities)
    rgb = np.asarray(rgb, np.float32)
    channels = {c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    with OpenEXR.File(header, channels) as f:
        f.write(str(path))
    return path


def test_acescg_red_reads_as_its_rec709_value(tmp_path):
    import colour

    rng = np.random.default_rng(2)
    rgb = np.concatenate([np.array([[[1.0, 0.0, 0.0], [0.18, 0.18, 0.18]]]), rng.random((1, 2, 3))], axis=1)
    img = read_image(_write(tmp_path / "aces.exr", rgb, ACESCG))
    # hand-checked: ACEScg (1, 0, 0) is about (1.705, -0.130, -0.024) in linear Rec.709
    np.testing.assert_allclose(img.pixels[0, 0], [1.705, -0.130, -0.024], atol=1.5e-3)
    # colour-science's own conversion (from the stored float32 chromaticities)
    stored = np.asarray(img.chromaticities)
    src = colour.RGB_Colourspace("t", stored[:6].reshape(3, 2), stored[6:], use_derived_matrix_RGB_to_XYZ=True,
                                 use_derived_matrix_XYZ_to_RGB=True)
    ref = colour.RGB_to_RGB(rgb[0], src, colour.RGB_COLOURSPACES["ITU-R BT.709"],
                            chromatic_adaptation_transform="Bradford")
    np.testing.assert_allclose(img.pixels[0], ref, rtol=1e-5, atol=1e-6)
    # grey stays grey (whites map to whites under Bradford)
    np.testing.assert_allclose(img.pixels[0, 1], 0.18, rtol=1e-3)
    assert img.colour_note.startswith("colour space ACEScg (") and "Rec.709 (D65)" in img.colour_note
    assert "Bradford" in img.colour_note
    raw = read_image(tmp_path / "aces.exr", working_space=False)
    np.testing.assert_array_equal(raw.pixels, rgb.astype(np.float32))
    assert raw.colour_note is None


def test_rec709_chromaticities_and_none_are_not_converted(tmp_path):
    rgb = np.random.default_rng(0).random((3, 4, 3))
    for name, ch in (("rec709.exr", REC709), ("plain.exr", None)):
        img = read_image(_write(tmp_path / name, rgb, ch))
        np.testing.assert_array_equal(img.pixels, rgb.astype(np.float32))
        assert img.colour_note is None
    assert colour_summary([tmp_path / "rec709.exr", tmp_path / "plain.exr"]) is None


def test_aces2065_with_its_imaginary_blue_primary_is_converted():
    """ACES2065-1 (AP0), the ACES interchange EXR's space, has a blue primary below the spectral
    locus (y -0.077); it was refused as "not a colour space"."""
    import colour

    space = colour.RGB_COLOURSPACES["ACES2065-1"]
    c = np.r_[np.ravel(space.primaries), space.whitepoint]
    assert c[5] < 0
    conv = working_space_conversion(c)
    assert conv.name == "ACES2065-1"
    expected = colour.RGB_to_RGB([0.2, 0.5, 0.1], space, colour.RGB_COLOURSPACES["ITU-R BT.709"],
                                 chromatic_adaptation_transform="Bradford")
    np.testing.assert_allclose(conv.apply(np.array([[[0.2, 0.5, 0.1]]]))[0, 0], expected, rtol=1e-6)


def test_same_white_needs_no_adaptation():
    rec2020 = (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290)
    conv = working_space_conversion(rec2020)
    assert conv.name == "ITU-R BT.2020" and conv.adaptation is None
    # white (1, 1, 1) maps to (1, 1, 1) when the whites agree
    np.testing.assert_allclose(conv.matrix @ np.ones(3), np.ones(3), atol=1e-9)


@pytest.mark.parametrize("bad, match", [
    ((0.1, 0.1, 0.2, 0.2, 0.3, 0.3, 0.3127, 0.329), "degenerate primaries"),
    ((0.64, 0.33, 0.30, 0.60, 0.15, 0.0, 0.3127, 0.329), "a primary with a y of 0"),
    ((0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.9, 0.9), r"white point \(0.9, 0.9\) that no colour has"),
    ((0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.9, 0.05), "outside the triangle of its primaries"),
    ((0.64, 0.33, 0.30, 0.60, 0.15, 0.06, float("nan"), 0.329), "non-finite"),
])
def test_unconvertible_space_is_an_error_not_rec709(tmp_path, bad, match):
    from ffls.lightmaps.lightmap import load_lightmap

    path = _write(tmp_path / "bad.exr", np.ones((4, 8, 3)), bad)
    for read in (read_image, load_lightmap, lambda p: read_image(p, working_space=False), lambda p: colour_summary([p])):
        with pytest.raises(InputError, match=match) as e:
            read(path)
        assert str(path) in str(e.value) and "\n" not in str(e.value) and "Rec.709" in str(e.value)


def test_light_map_in_acescg_is_converted_and_reported(tmp_path):
    from ffls.lightmaps.lightmap import load_lightmap

    grey = np.full((16, 32, 3), 0.5)
    lm = load_lightmap(_write(tmp_path / "map.exr", grey, ACESCG))
    np.testing.assert_allclose(lm.data, 0.5, rtol=1e-3)  # a neutral map stays neutral
    assert lm.colour_note and "ACEScg" in lm.colour_note
    assert load_lightmap(_write(tmp_path / "map709.exr", grey)).colour_note is None


def test_lightmap_info_and_convert_say_the_colour_space_and_why_negatives_appear(tmp_path, capsys):
    """``ffls lightmap info`` and ``convert`` said nothing of an ACEScg map's conversion, and the
    negatives a saturated ACEScg colour gets in Rec.709 were warned about as if they were the file's."""
    import warnings

    from ffls.cli import main
    from ffls.lightmaps.lightmap import LightMapWarning, load_lightmap

    rgb = np.full((16, 32, 3), 0.2)
    rgb[2:5, 3:9] = (0.0, 5.0, 0.0)  # ACEScg green: (-3.1, 5.7, -0.6) in linear Rec.709
    rgb[10, 10:12] = (-0.5, 0.2, 0.2)  # negative in the file itself (as lossy compression leaves)
    path = _write(tmp_path / "green.exr", rgb, ACESCG)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_lightmap(path)
    text = " ".join(str(w.message) for w in caught if issubclass(w.category, LightMapWarning))
    assert "clamped 20 pixels" in text and "18 of them are colours outside Rec.709's gamut" in text, text
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_lightmap(_write(tmp_path / "neg709.exr", rgb))  # no conversion: nothing said of a gamut
    assert not any("gamut" in str(w.message) for w in caught)
    assert main(["lightmap", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "colour: colour space ACEScg (" in out and "converted to linear Rec.709 (D65)" in out, out
    assert main(["lightmap", "convert", str(path), str(tmp_path / "out.exr")]) == 0
    assert "colour: colour space ACEScg (" in capsys.readouterr().out
    assert main(["lightmap", "info", str(_write(tmp_path / "plain.exr", rgb))]) == 0
    assert "colour: linear Rec.709 (D65), the working space" in capsys.readouterr().out


def test_capture_photos_in_acescg_relight_in_rec709(tmp_path, capsys):
    """A capture whose EXR photos are tagged ACEScg: the photos are converted as they are loaded (the
    basis is the converted one), and relight says so in one line."""
    from ffls.cli import main
    from ffls.io.capture import load_capture_and_lights
    from ffls.lightmaps.lightmap import builtin_lightmap
    from ffls.radiance.photos import load_photos
    from ffls.relight.cpu import relight_capture, relight_reference
    from ffls.synth.scene import write_synthetic_capture

    folder = tmp_path / "cap"
    write_synthetic_capture(folder, n_lights=6, resolution=16, progress=False, seed=1)
    cap, lights = load_capture_and_lights(folder)
    basis0 = load_photos(cap, progress=False)
    for name in cap.image_names:
        _write(folder / name, read_image(folder / name).pixels, ACESCG)
    conv = working_space_conversion(read_image(folder / cap.image_names[0]).chromaticities)
    basis1 = load_photos(cap, progress=False)
    np.testing.assert_allclose(basis1, conv.apply(basis0), rtol=1e-6, atol=1e-7)
    out = tmp_path / "out.exr"
    assert main(["relight", str(folder), "--probe", "sky", "-o", str(out)]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "colour" in ln]
    assert len(lines) == 1 and lines[0].startswith("ffls relight: colour: 6 of 6 images: colour space ACEScg")
    _, w = relight_capture(cap, lights, builtin_lightmap("sky"))
    np.testing.assert_allclose(read_image(out).pixels, relight_reference(w.weights, conv.apply(basis0)),
                               rtol=1e-4, atol=1e-6)


def test_probe_merge_and_probe_photos_in_acescg_are_reported(tmp_path, capsys):
    """``ffls probe merge`` and ``ffls probe METHOD`` convert ACEScg EXRs and say so, as relight does."""
    from ffls.cli import main
    from ffls.lightmaps.lightmap import builtin_lightmap
    from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe

    rng = np.random.default_rng(3)
    scene = rng.uniform(0.1, 1.0, (8, 12, 3))
    paths = [_write(tmp_path / f"b{k}.exr", scene * t, ACESCG) for k, t in enumerate((1.0, 4.0))]
    assert main(["probe", "merge", *map(str, paths), "--exposures", "1,4", "-o", str(tmp_path / "m.exr")]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "colour" in ln]
    assert len(lines) == 1 and lines[0].startswith("ffls probe: colour: 2 of 2 images: colour space ACEScg"), lines
    folder = write_diffuse_probe(tmp_path / "probe", diffuse_sphere_scene(builtin_lightmap("courtyard").downsample(16),
                                                                          resolution=48))
    import json

    for name in json.loads((folder / "probe.json").read_text())["images"]:
        _write(folder / name, read_image(folder / name).pixels, ACESCG)
    assert main(["probe", "diffuse", str(folder), "-o", str(tmp_path / "d.exr"), "--size", "16", "--sources", "9"]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "colour" in ln]
    assert len(lines) == 1 and "colour space ACEScg" in lines[0], lines
