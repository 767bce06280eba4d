"""Frame sequences: mp4 (atomic) and PNG folders."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.errors import InputError
from ffls.io.video import FrameWriter


def _frames(n, h=32, w=48):
    return [np.full((h, w, 3), 20 * k, np.uint8) for k in range(n)]


def test_mp4_written_whole_and_readable(tmp_path):
    import cv2

    out = tmp_path / "v.mp4"
    with FrameWriter(out, fps=10) as sink:
        for f in _frames(5):
            sink.write(f)
            assert not out.exists()  # nothing at the final name until the writer closes
    assert sink.describe() == f"{out} (5 frames, 10 fps)"
    cap = cv2.VideoCapture(str(out))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    assert n == 5
    assert [p.name for p in tmp_path.iterdir()] == ["v.mp4"]


def test_interrupted_mp4_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError):
        with FrameWriter(tmp_path / "v.mp4") as sink:
            sink.write(_frames(1)[0])
            raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []


def test_png_folder(tmp_path):
    with FrameWriter(tmp_path / "frames") as sink:
        for f in _frames(3):
            sink.write(f)
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == [f"frame_{k:04d}.png" for k in range(3)]
    assert sink.describe().endswith("frame_0000..0002.png")


def test_bad_frames_and_outputs(tmp_path):
    with pytest.raises(InputError, match="mp4 file or a folder"):
        FrameWriter(tmp_path / "v.avi")
    sink = FrameWriter(tmp_path / "v.mp4")
    with pytest.raises(ValueError, match="uint8"):
        sink.write(np.zeros((4, 4, 3), np.float32))
    sink.write(_frames(1)[0])
    with pytest.raises(ValueError, match="the first was"):
        sink.write(np.zeros((8, 8, 3), np.uint8))
    sink.abort()
    assert list(tmp_path.iterdir()) == []
    empty = FrameWriter(tmp_path / "e.mp4")
    with pytest.raises(InputError, match="no frames"):
        empty.close()
    assert list(tmp_path.iterdir()) == []
