"""Per capture, the photos' frame levels over the capture's median, lowest first (the ``dark``
rejection's statistic, :func:`ffls.spheres.estimate.reject_dark_photos`).

    OMP_NUM_THREADS=1 ../.venv/bin/python frame_levels.py CAPTURE_DIR ...

Levels are :meth:`ffls.spheres.estimate.DecodedPhotos.photo_levels` (linear); where the encoding
is unstated (stored codes, no calibration here) the stored levels are printed, marked ``stored``.
"""
from __future__ import annotations

import sys

import numpy as np

from ffls.io.capture import load_capture
from ffls.spheres.estimate import DARK_RATIO, decode_photos


def main(dirs: list[str], lowest: int = 5) -> None:
    for d in dirs:
        cap = load_capture(d)
        decoded = decode_photos(cap)
        levels, kind = decoded.photo_levels(cap), "linear"
        if levels is None:
            levels, kind = np.array([v for _, v in decoded.stats.levels]), "stored"
        ratio = levels / np.median(levels)
        order = np.argsort(ratio)[:lowest]
        dark = int((ratio < DARK_RATIO).sum())
        print(d, kind, f"dark {dark}", "lowest:", ", ".join(f"{cap.image_names[i]} {ratio[i]:.3f}" for i in order))


if __name__ == "__main__":
    main(sys.argv[1:])
