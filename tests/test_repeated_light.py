"""The coverage line's repeated lights: one photo twice, or one light position given twice.

On the paper's Table 1 grid (bench c00) the zenith light is on every ring: its photos are renders of
one light, pixel for pixel the same, and the line guessed "(the same photo twice?)" for them, as it
did for any repeat. The guess is now made from the photos: identical pixels, or a light file that
gives different photos one position."""
import json
import shutil
from types import SimpleNamespace

import numpy as np
import pytest


def test_same_pixels_tells_a_copy_from_a_second_shot(tmp_path):
    """A copy (and a copy in another format) is the same photo; a second shot of the same light, with
    the sensor's noise (1%), is not; images of two sizes differ."""
    from ffls.io.images import same_pixels, write_exr, write_png

    rng = np.random.default_rng(0)
    a = rng.uniform(0.2, 0.8, (24, 32, 3)).astype(np.float32)
    b = (a * (1 + 0.01 * rng.standard_normal(a.shape))).astype(np.float32)
    for name, img in (("a.exr", a), ("copy.exr", a), ("b.exr", b), ("small.exr", a[:20])):
        write_exr(tmp_path / name, img)
    write_png(tmp_path / "a.png", (a * 255).round().astype(np.uint8))
    shutil.copy(tmp_path / "a.png", tmp_path / "copy.png")
    assert same_pixels(tmp_path / "a.exr", tmp_path / "copy.exr")
    assert same_pixels(tmp_path / "a.png", tmp_path / "copy.png")
    assert not same_pixels(tmp_path / "a.exr", tmp_path / "b.exr")
    assert not same_pixels(tmp_path / "a.exr", tmp_path / "small.exr")


def test_the_guess_follows_the_photos():
    """``same_photo`` says which: identical photos (the same photo twice?), different ones (one light
    position given twice), both; without it no guess is made."""
    from ffls.synth.scene import stratified_directions
    from ffls.weights.voronoi import coverage_warnings

    d = stratified_directions(40)
    d = np.concatenate([d[:10], d[9:10], d[10:20], d[3:4], d[20:]])  # 10 repeats 9, 21 repeats 3
    names = [f"img_{i:04d}.tiff" for i in range(len(d))]

    def line(same_photo):
        return next(x for x in coverage_warnings(d, names=names, same_photo=same_photo) if "repeat" in x)

    assert "'img_0010.tiff' repeats 'img_0009.tiff', 'img_0021.tiff' repeats 'img_0003.tiff'" in line(None)
    assert "twice" not in line(None) and "(" not in line(None).split("repeats", 2)[-1]
    assert "(identical photos: the same photo twice" in line(lambda i, j: True)
    assert "(the photos differ: the same light position given" in line(lambda i, j: False)
    assert "the same photo twice?" not in line(lambda i, j: False)
    assert "1 of the 2 named pairs identical photos" in line(lambda i, j: (i, j) == (10, 9))


@pytest.fixture(scope="module")
def three_photos(tmp_path_factory):
    from ffls.cli import main

    root = tmp_path_factory.mktemp("rep")
    assert main(["synth", str(root / "c"), "--lights", "3", "--resolution", "32", "--spheres", "1", "--quiet",
                 "--seed", "5"]) == 0
    return root / "c"


@pytest.mark.parametrize("copied", [False, True])
def test_relight_guesses_from_the_photos(three_photos, tmp_path, capfd, copied):
    """A lights file that gives photo 2 photo 0's direction: its photos differ (the line says the light
    position repeats), or photo 2 is a copy of photo 0 (the line asks whether it is the same photo)."""
    from ffls.commands.common import load_relight_inputs

    cap = tmp_path / "c"
    shutil.copytree(three_photos, cap)
    doc = json.loads((cap / "lights.json").read_text())
    doc["lights"][2]["direction"] = doc["lights"][0]["direction"]
    (cap / "lights.json").write_text(json.dumps(doc))
    images = json.loads((cap / "capture.json").read_text())["images"]
    if copied:
        shutil.copy(cap / images[0], cap / images[2])
    capfd.readouterr()
    load_relight_inputs(SimpleNamespace(capture=cap, lights=None, probe=None, layout=None), "relight",
                        lightmap=False)
    line = next(x for x in capfd.readouterr().err.splitlines() if "repeat" in x)
    assert f"{images[2]!r} repeats {images[0]!r}" in line, line
    if copied:
        assert "(identical photos: the same photo twice" in line, line
    else:
        assert "(the photos differ: the same light position given for different photos)" in line, line


def test_relight_says_a_light_at_the_horizon(three_photos, tmp_path, capfd):
    """relight passes the lights' cones to the coverage lines: a light 0.4 deg under the horizon with a
    2 deg cone is at the horizon (no advice to declare full); with a 0.1 deg cone it is outside."""
    from ffls.commands.common import load_relight_inputs

    cap = tmp_path / "c"
    shutil.copytree(three_photos, cap)
    doc = json.loads((cap / "lights.json").read_text())
    e = np.radians(-0.4)
    for cone, want in ((2.0, "1 light at the horizon"), (0.1, "1 light outside the capture's upper hemisphere")):
        doc["lights"][2].update(direction=[float(np.cos(e)), 0.0, float(np.sin(e))], uncertainty_deg=cone)
        (cap / "lights.json").write_text(json.dumps(doc))
        capfd.readouterr()
        load_relight_inputs(SimpleNamespace(capture=cap, lights=None, probe=None, layout=None), "relight",
                            lightmap=False)
        line = next(x for x in capfd.readouterr().err.splitlines() if "light at the horizon" in x or "outside" in x)
        assert want in line, line
        assert ("declare" in line) == (cone < 0.4), line


def test_same_photo_of_reads_each_photo_once(tmp_path, monkeypatch):
    """The pairs named share photos (a grid's zenith on every ring): each is read once, not once a
    pair."""
    from ffls.commands.common import same_photo_of
    from ffls.io import images

    rng = np.random.default_rng(1)
    a = rng.uniform(0.2, 0.8, (16, 16, 3)).astype(np.float32)
    paths = []
    for i, img in enumerate((a, a, a * 1.5, a)):
        paths.append(tmp_path / f"p{i}.exr")
        images.write_exr(paths[-1], img)
    reads = []
    read = images.read_image
    monkeypatch.setattr(images, "read_image", lambda p, **kw: reads.append(p) or read(p, **kw))
    same = same_photo_of(SimpleNamespace(image_paths=paths), [0, 1, 2, 3])
    assert [same(j, 0) for j in (1, 2, 3)] == [True, False, True]
    assert sorted(reads) == paths
