"""A misfired flash (a photo far darker than the rest of the capture) is rejected as ``dark``
(:func:`ffls.spheres.estimate.reject_dark_photos`), on the frame's level, not the spheres': a light
behind or grazing the spheres darkens them, not the frame, and keeps its own reason."""
from __future__ import annotations

import json

import numpy as np

from ffls.spheres.detect import SequenceAccumulator
from ffls.spheres.estimate import DARK_RATIO, reject_dark_photos
from ffls.spheres.photo import REASONS, PhotoEstimate


def test_the_sequence_keeps_each_photos_frame_level():
    """:attr:`SequenceStats.levels`: per photo, washed-out ones included, merged in index order."""
    rng = np.random.default_rng(0)
    ims = [rng.uniform(0.0, s, (64, 64, 3)).astype(np.float32) for s in (1.0, 0.02, 0.5)]
    a, b = SequenceAccumulator(), SequenceAccumulator()
    a.add(ims[0], 0)
    b.add(ims[1], 1)
    b.add(ims[2], 2, full_scale=0.9)  # washed out: kept apart, its level kept too
    stats = a.merge(b).result()
    idx, levels = zip(*stats.levels)
    assert idx == (0, 1, 2)
    assert abs(levels[0] / levels[1] - 50.0) < 1.0 and abs(levels[0] / levels[2] - 2.0) < 0.05, levels


def test_only_a_photo_far_below_the_capture_is_dark():
    photos = [PhotoEstimate(status="ok", reason=None, direction=np.array([0.0, 0.0, 1.0])) for _ in range(6)]
    levels = [1.0, 0.9, 1.2, 0.02, 0.3, 1.1]  # a lamp 1.8 times farther (0.3) is no misfire
    out = reject_dark_photos(photos, levels)
    assert [r.reason for r in out] == [photos[0].reason] * 3 + ["dark"] + [photos[0].reason] * 2
    assert out[3].status == "rejected" and not np.isfinite(out[3].uncertainty_deg)
    assert 0.02 < DARK_RATIO < 0.3 and "dark" in REASONS
    assert reject_dark_photos(photos, None) == photos


def test_misfired_flashes_are_rejected_as_dark(tmp_path):
    """``ffls synth`` (16 lights, 192 px, EXR) with photos 3 and 9 at 2 % of their light: both
    ``dark``; main rejected them for whatever their spheres' fits said (or accepted them)."""
    from ffls.io.capture import load_capture
    from ffls.io.images import read_exr, write_exr
    from ffls.spheres.estimate import estimate_lights
    from ffls.synth.scene import write_synthetic_capture

    write_synthetic_capture(tmp_path, n_lights=16, resolution=192, seed=7, progress=False)
    names = json.loads((tmp_path / "capture.json").read_text())["images"]
    for i in (3, 9):
        write_exr(tmp_path / names[i], read_exr(tmp_path / names[i]).pixels * 0.02)
    out = estimate_lights(load_capture(tmp_path), progress=False, workers=1)
    dark = [i for i, r in enumerate(out.reasons) if r == "dark"]
    assert dark == [3, 9], list(zip(out.status, out.reasons))
