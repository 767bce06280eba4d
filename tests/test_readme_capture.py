"""README.md's smallest capture.json is one ``ffls lights`` runs on: the minimal file it quoted
(``images`` only: a pinhole camera without ``K`` or ``sphere_radius``) stopped with ``has no
sphere_radius``."""
import json
import re
from pathlib import Path


def test_readme_smallest_capture_runs_ffls_lights(tmp_path, capfd):
    from ffls.cli import main

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    text = " ".join(re.search(r"The smallest[^`]*`(\{.*?\})`", readme, re.S).group(1).split())
    cap = tmp_path / "cap"
    assert main(["synth", str(cap), "--lights", "8", "--resolution", "192", "--lens", "orthographic",
                 "--spheres", "1", "--sphere-material", "grey", "--format", "png8", "--encoding", "srgb",
                 "--exposure", "3", "--seed", "1", "--quiet"]) == 0
    images = json.loads((cap / "capture.json").read_text())["images"]
    doc = json.loads(text.replace('"IMG_0001.JPG", ...', ", ".join(json.dumps(n) for n in images)))
    assert set(doc) >= {"format", "version", "images"}
    (cap / "capture.json").write_text(json.dumps(doc))
    capfd.readouterr()
    assert main(["lights", str(cap), "-o", str(tmp_path / "l.json"), "--workers", "1", "--no-progress"]) == 0, \
        capfd.readouterr().err
