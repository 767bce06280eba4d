"""Where differential rendering itself errs: the object's shadow inside a calibration sphere's shadow.

Reads the direct renders that ``python benchmarks/composite.py --oracle`` cached (both capture
scenes and the virtual scene rendered directly under each map: no relighting error) and splits the
change-region error of the composite between the pixels inside the spheres' shadows (where the
registered surface-alone field is more than 3% darker than the background) and the others. Inside,
both captures already miss the light the spheres block, so what the object blocks of it cannot be
seen in their difference.

    python benchmarks/composite_sphere_shadows.py --cache DIR --res 128 --truth-dirs 1024 [--maps courtyard,sunrise]
"""
from __future__ import annotations

import argparse

import numpy as np

from ffls.io.images import read_image
from ffls.relight.composite import LUMINANCE, composite
from ffls.synth.scene import make_scene
from ffls.synth.virtual import composite_masks


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cache", required=True)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--truth-dirs", type=int, default=1024)
    ap.add_argument("--maps", default="courtyard,sunrise,studio,sky")
    a = ap.parse_args()
    R = a.res
    m = composite_masks(make_scene(spheres=4, ground_albedo=0.3), R)
    om, sm = m["object"].astype(float), m["surface"].astype(float)
    for name in a.maps.split(","):
        def load(k):
            return read_image(f"{a.cache}/{name}_{k}_{R}_{a.truth_dirs}.exr").pixels.astype(float)

        bg, tr, o, s = load("background"), load("truth"), load("direct_object"), load("direct_surface")
        r = composite(bg, o, s, om, sm)
        c = r.image.astype(float)
        lt, lb = tr @ LUMINANCE, bg @ LUMINANCE
        change = (sm > 0.5) & (om < 0.5) & (np.abs(lt - lb) > 0.03 * lb)
        shadow = (sm > 0.5) & (((s * r.registration.scale + r.registration.offset) @ LUMINANCE) < 0.97 * lb)

        def err(msk):
            return np.abs(c - tr)[msk].sum() / max(tr[msk].sum(), 1e-30)

        print(f"{name:10s} change {100 * err(change):4.1f}%: outside the spheres' shadows "
              f"{100 * err(change & ~shadow):4.1f}% ({(change & ~shadow).sum()} px), inside "
              f"{100 * err(change & shadow):4.1f}% ({(change & shadow).sum()} px)")


if __name__ == "__main__":
    main()
