"""The built-in demo, end to end, small: both relighters, outputs, contact sheet."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.cli import main
from ffls.demo import run_demo
from ffls.display.tonemap import auto_exposure
from ffls.io.images import read_image

SMALL = dict(n_lights=24, resolution=48, maps=("sky", "paper"), rotations=(0.0, 180.0), progress=False)


def test_demo_cpu_writes_everything(tmp_path):
    res = run_demo(tmp_path / "demo", use_gpu=False, **SMALL)
    assert res.backend == "cpu"
    assert len(res.images) == len(res.exrs) == 4
    for key, png in res.images.items():
        assert png.is_file() and res.exrs[key].is_file()
        hdr = read_image(res.exrs[key]).pixels
        assert hdr.shape == (48, 48, 3) and np.isfinite(hdr).all() and hdr.max() > 0
    # a rotation of an asymmetric map changes the picture
    a = read_image(res.exrs[("paper", 0.0)]).pixels
    b = read_image(res.exrs[("paper", 180.0)]).pixels
    assert np.abs(a - b).mean() > 0.02 * a.mean()
    sheet = read_image(res.contact_sheet)
    assert sheet.pixels.shape[0] > 2 * 48 and sheet.pixels.shape[1] > 2 * 48
    # nothing half-written is left behind
    assert not list(tmp_path.rglob("*.tmp*"))


@pytest.mark.gl
def test_demo_gpu_matches_cpu(tmp_path, ctx):
    # ctx: the fixture asserts a context exists (else the test skips) and no GL error around it
    cpu = run_demo(tmp_path / "cpu", use_gpu=False, **SMALL)
    gpu = run_demo(tmp_path / "gpu", use_gpu=True, **SMALL)
    assert gpu.backend.startswith("gpu")
    for key in cpu.exrs:
        ref = read_image(cpu.exrs[key]).pixels.astype(np.float64)
        out = read_image(gpu.exrs[key]).pixels.astype(np.float64)
        # GPU: float16 basis with a per-dataset scale, float32 sums -> 1e-3 of the peak
        assert np.abs(out - ref).max() <= 1e-3 * ref.max(), key


def test_demo_command(tmp_path, capsys):
    rc = main(["demo", "-o", str(tmp_path / "d"), "--lights", "12", "--resolution", "32", "--maps", "sky",
               "--rotations", "0", "--cpu", "--no-view"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "contact sheet" in out and str(tmp_path / "d") in out
    assert (tmp_path / "d" / "contact_sheet.png").is_file()


def test_demo_command_finds_the_viewer_and_does_not_open_it_without_a_display(tmp_path, capsys, monkeypatch):
    """Without --no-view the demo asks the registered ``view`` command; with no display it only says how."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    rc = main(["demo", "-o", str(tmp_path / "d"), "--lights", "12", "--resolution", "32", "--maps", "sky",
               "--rotations", "0", "--cpu"])
    out = capsys.readouterr().out
    assert rc == 0
    assert f"viewer:        no display; run `ffls view {tmp_path / 'd' / 'capture'}` on a desktop" in out


def test_auto_exposure_maps_log_average_to_key():
    img = np.full((4, 4, 3), 0.36, np.float32)
    assert auto_exposure(img) == pytest.approx(-1.0, abs=1e-6)
    assert auto_exposure(np.zeros((4, 4, 3), np.float32)) == 0.0


def test_an_interrupted_demo_leaves_the_old_output_or_nothing(tmp_path, monkeypatch):
    """Ctrl-C while the demo renders: no folder where there was none; the old one, untouched,
    where there was one (the demo is written in a staging folder and swapped in when complete)."""
    import ffls.demo as demo

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    out = tmp_path / "demo"
    with monkeypatch.context() as m:
        m.setattr(demo, "contact_sheet", interrupted)
        with pytest.raises(KeyboardInterrupt):
            run_demo(out, use_gpu=False, **SMALL)
    assert not out.exists() and list(tmp_path.iterdir()) == []
    first = run_demo(out, use_gpu=False, **SMALL)
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*")}
    with monkeypatch.context() as m:
        m.setattr(demo, "contact_sheet", interrupted)
        with pytest.raises(KeyboardInterrupt):
            run_demo(out, use_gpu=False, seed=5, **SMALL)
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*")} == before and first.contact_sheet.is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["demo"]


def test_demo_refuses_a_folder_of_other_files(tmp_path):
    from ffls.errors import InputError

    (tmp_path / "notes.txt").write_text("keep me")
    with pytest.raises(InputError, match="refusing to replace it"):
        run_demo(tmp_path, use_gpu=False, **SMALL)
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]
