"""White spheres on a white ground, found without hints (issue 9, "Must work" 1).

In the max image every pixel reads its best light, so a white matte sphere on a white ground is
as bright as the ground all round its silhouette and the max image has no edge there: before,
Hough proposed no circle on any of the four spheres and ``ffls lights`` said "no sphere found".
The per-photo edge evidence outlines them (``ffls.spheres.detect`` proposes and fits circles on
it too)."""
from __future__ import annotations

import json

import numpy as np

from ffls.io.capture import load_capture
from ffls.spheres.detect import PHOTO_EDGES, consistent_edge_strength, extreme_images, find_spheres_in_capture
from ffls.synth.scene import make_scene, write_synthetic_capture


def _dirs(n=16, seed=3):
    rng = np.random.default_rng(seed)
    phi = rng.uniform(0, 2 * np.pi, n)
    z = rng.uniform(0.3, 0.95, n)
    s = np.sqrt(1 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def _white_capture(path):
    write_synthetic_capture(path, resolution=192, directions=_dirs(), progress=False,
                            scene=make_scene(background="white"))
    return json.loads((path / "truth.json").read_text())


def test_white_spheres_on_white_ground_found_without_hints(tmp_path):
    truth = _white_capture(tmp_path)
    sp = find_spheres_in_capture(load_capture(tmp_path))
    assert len(sp) == 4
    for s in truth["spheres"]:
        c = np.asarray(s["center_px"])
        d = [np.hypot(*(np.asarray(ft.center_px) - c)) for ft in sp]
        k = int(np.argmin(d))
        assert d[k] < 2.0, (s["center_px"], [ft.center_px for ft in sp])
        assert abs(sp[k].radius_px - s["radius_px_from_area"]) < 0.15 * s["radius_px_from_area"]
    assert all(ft.outline_edges == PHOTO_EDGES for ft in sp)


def test_white_ground_outline_is_in_the_photos_edges_not_the_max_image(tmp_path):
    """Why the max image cannot outline them: across each sphere's silhouette the max image's
    log-luminance barely steps, while the per-photo edge strength peaks on it."""
    truth = _white_capture(tmp_path)
    cap = load_capture(tmp_path)
    from ffls.radiance.photos import read_photo
    from ffls.spheres.detect import sequence_stats

    st = sequence_stats([read_photo(cap, i).linear for i in range(len(cap.image_paths))])
    mx, _, _, _ = extreme_images([read_photo(cap, i).linear for i in range(len(cap.image_paths))])
    L = mx[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    S, _ = consistent_edge_strength(st.edge_tensor, st.edge_photos)
    t = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    for s in truth["spheres"]:
        (cx, cy), r = s["center_px"], s["radius_px_from_area"]
        def ring(img, f):
            x = np.clip(np.rint(cx + f * r * np.cos(t)).astype(int), 0, img.shape[1] - 1)
            y = np.clip(np.rint(cy + f * r * np.sin(t)).astype(int), 0, img.shape[0] - 1)
            return img[y, x]
        top = np.sin(t) < -0.5  # the sphere's upper limb, away from its contact shadow
        step_max = np.abs(np.log(ring(L, 0.8)[top] / ring(L, 1.25)[top]))
        assert np.median(step_max) < 0.4  # under the radiance ratio of 1.5 the max image's edges need
        assert np.median(ring(S, 1.0)) > 2 * np.median(S)  # the photos' edges hold on the silhouette
