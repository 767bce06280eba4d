"""Where a blurred outline's steps lie: per-octant distances of the step points from the true silhouette.

For each capture (a ``blur_lights.py`` condition folder) and the ``truth.json`` of its render, the
matte sphere nearest the truth's first sphere is found (``find_spheres_in_capture``); its outline
points are moved to the linear step (``step_edges``) of the max image and of the photos' mean, and
the median signed distance (pixels, + outside) of the moved points from the true silhouette (the
tangent cone) is printed per 45 deg octant around the ball (E, SE, down, SW, W, NW, up, NE in the
image), with the median fitted blur sigma. Nothing is written.

    cd benchmarks && OMP_NUM_THREADS=1 python blur_outline.py FOLDER TRUTH_FOLDER [SCALE]

``SCALE``: the folder's pixels per the render's (0.6667 for ``resized_768-512`` against ``render768``).
"""
from __future__ import annotations

import json
import sys

import numpy as np

from ffls.conventions import angle_between
from ffls.display.tonemap import luminance
from ffls.io.capture import load_capture
from ffls.radiance.photos import read_photo
from ffls.spheres.detect import find_spheres_in_capture, pixel_rays, sequence_stats, step_edges


def main(folder, truth_folder, scale=1.0):
    cap = load_capture(folder)
    s = json.load(open(f"{truth_folder}/truth.json"))["spheres"][0]
    cpx = (np.asarray(s["center_px"]) + 0.5) * scale - 0.5
    Ct = (np.linalg.inv(cap.world_from_camera) @ np.r_[s["center"], 1.0])[:3]
    f = float(np.sqrt(cap.K[0, 0] * cap.K[1, 1]))
    ray, at = Ct / np.linalg.norm(Ct), np.arcsin(s["radius"] / np.linalg.norm(Ct))
    fits = find_spheres_in_capture(cap)
    ft = min(fits, key=lambda g: np.hypot(*(np.asarray(g.center_px) - cpx)))
    st = sequence_stats((read_photo(cap, i).linear for i in range(len(cap.image_paths))), colour=False, edges=False)
    mx = st.max if st.max.ndim == 2 else luminance(st.max[..., :3])
    P = ft.edge_px
    u = (P - ft.center_px) / np.hypot(*(P - ft.center_px).T)[:, None]
    oct_ = ((np.degrees(np.arctan2(*(P - cpx).T[::-1])) % 360 + 22.5) // 45).astype(int) % 8
    print(f"{folder}: centre {np.round(ft.center_px, 2)} r {ft.radius_px:.2f} (truth {np.round(cpx, 2)} "
          f"r {s['radius_px'] * scale:.2f}); octants E SE down SW W NW up NE: distance px (blur px)")
    for name, img in (("max image", mx), ("mean", st.mean)):
        Q, ok, blur = step_edges(img, P, u, radius=ft.radius_px, with_blur=True)
        d = f * (angle_between(pixel_rays(Q, cap.K, cap.dist), ray) - at)
        cells = [f"{np.median(d[m]):+.2f} ({np.median(blur[m]):.2f})" if m.any() else "-"
                 for m in ((oct_ == k) & ok for k in range(8))]
        print(f"  {name:9s} " + "  ".join(cells))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]) if len(sys.argv) > 3 else 1.0)
