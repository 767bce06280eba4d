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


def test_photo_edge_fits_in_two_workers_are_the_same(tmp_path, monkeypatch):
    """``workers=2``: the photo-edge circles are fitted in forked processes (the serial part of
    the detection on 2 cores): most outline fits run outside this process, and the spheres are
    the very same as in this process."""
    import os

    from ffls.spheres import detect

    _white_capture(tmp_path)
    cap = load_capture(tmp_path)
    one = find_spheres_in_capture(cap)
    pids = tmp_path / "pids.txt"
    fit = detect.fit_sphere_center

    def logged(*a, **k):  # (inherited by the forked workers: each appends its process id)
        with open(pids, "a") as f:
            f.write(f"{os.getpid()}\n")
        return fit(*a, **k)

    monkeypatch.setattr(detect, "fit_sphere_center", logged)
    two = find_spheres_in_capture(cap, workers=2)
    assert len(one) == 4 and list(one.rejected) == list(two.rejected)
    for a, b in zip(one, two, strict=True):
        assert np.array_equal(a.center_px, b.center_px) and a.radius_px == b.radius_px
        assert np.array_equal(a.center_cam, b.center_cam) and a.outline_edges == b.outline_edges
    calls = pids.read_text().split()
    here = calls.count(str(os.getpid()))
    assert here < len(calls) - here, (here, len(calls))  # before: the photo-edge fits, most of them, here


def test_photo_edges_read_once_per_search(tmp_path, monkeypatch):
    """The edges that hold in the photos (strength, angle, ridge points) are read once per
    ``find_spheres`` and shared by the photo-edge search and both refits on them (before: three
    times), and the changing edges once."""
    from ffls.spheres import detect

    _white_capture(tmp_path)
    cap = load_capture(tmp_path)
    calls = []
    strength = detect.consistent_edge_strength

    def counted(*a, **k):
        calls.append(bool(k.get("centered", a[2] if len(a) > 2 else False)))
        return strength(*a, **k)

    monkeypatch.setattr(detect, "consistent_edge_strength", counted)
    assert len(find_spheres_in_capture(cap)) == 4
    assert calls.count(False) == 1 and calls.count(True) <= 1, calls


def test_ridge_rows_bound_the_band_and_keep_the_fit():
    """``ConsistentEdges.near_rows`` holds every ridge point of a band of rows, in their order, for
    points listed row by row (short) and in any order; the photo-edge fit on it is the fit on all
    the points, to the bit."""
    from ffls.spheres import detect

    rng = np.random.default_rng(3)
    H, W = 200, 240
    c, R = np.array([120.0, 95.0]), 40.0
    t = np.radians(np.arange(0, 360, 0.8))
    ring = c + R * np.stack([np.cos(t), np.sin(t)], axis=1)
    clutter = rng.uniform(0, [W, H], (3000, 2))
    pix = np.rint(np.concatenate([ring, clutter]))  # each point's pixel, then sub-pixel within half of it
    order = np.lexsort((pix[:, 0], pix[:, 1]))  # row by row, as consistent_edge_points lists them
    pts = (pix + rng.uniform(-0.5, 0.5, pix.shape))[order]
    dirs = pts - c
    dirs /= np.maximum(np.hypot(dirs[:, 0], dirs[:, 1]), 1e-9)[:, None]
    for p, d in ((pts, dirs), (pts[rng.permutation(len(pts))], dirs)):
        ev = detect.ConsistentEdges(None, None, (p, d, np.ones(len(p))))
        for y0, y1 in ((50.0, 80.0), (-5.0, 3.0), (190.5, 260.0), (100.0, 99.0)):
            s = ev.near_rows(y0, y1)
            inside = np.flatnonzero((p[:, 1] >= y0) & (p[:, 1] <= y1))
            assert np.all((inside >= s.start) & (inside < s.stop)), (y0, y1)
    ev = detect.ConsistentEdges(None, None, (pts, dirs, np.ones(len(pts))))
    s = ev.near_rows(50.0, 80.0)
    assert s.stop - s.start < 0.25 * len(pts)  # row by row: about the band's rows only
    cam = detect.DetectionCamera("orthographic", None, None, np.eye(4), 1.0, (H, W))
    fit = detect.fit_on_consistent_edges(c + [2.0, -1.5], R + 1.0, ev, cam, "auto")
    everything = detect.ConsistentEdges(None, None, (pts, dirs, np.ones(len(pts))))
    everything.rows = (np.full(len(pts), np.inf), np.full(len(pts), -np.inf))  # no row is left out
    same = detect.fit_on_consistent_edges(c + [2.0, -1.5], R + 1.0, everything, cam, "auto")
    assert fit is not None and np.hypot(*(fit.center_px - c)) < 0.2
    assert np.array_equal(fit.center_px, same.center_px) and fit.radius_px == same.radius_px


def test_photo_edge_circles_fitted_once_and_not_on_known_outlines():
    """``circles_to_fit``: of the photo-edge circles of one pass, those within ``SAME_START_PX`` of an
    earlier one are fitted once; a circle within 10 % of a round outline already fitted on the max
    image is not fitted (its fit would be dropped as that outline's near-duplicate); a circle of
    the other pass, and one just outside either tolerance, is; the order is kept."""
    from ffls.spheres.detect import SAME_START_PX, circles_to_fit

    d = 0.5 * SAME_START_PX
    circles = [(0, 100.0, 100.0, 40.0), (0, 100.0 + d, 100.0, 40.0 + 0.9 * d),  # the same start twice
               (1, 100.0 + d, 100.0, 40.0),  # the other pass
               (0, 100.0, 100.0 + 3 * d, 40.0),  # 0.15 px away: its own search
               (0, 300.0, 200.0, 30.0), (0, 302.9, 200.0, 30.0),  # within 10 % of the known outline
               (0, 303.1, 200.0, 30.0), (0, 300.0, 200.0, 33.4)]  # just outside it
    kept = circles_to_fit(circles, [(300.0, 200.0, 30.0)])
    assert kept == [circles[0], circles[2], circles[3], circles[6], circles[7]]
    assert circles_to_fit(circles[:1], []) == circles[:1] and circles_to_fit([], [(1.0, 2.0, 3.0)]) == []


def test_photo_edge_fit_does_not_depend_on_a_small_move_of_its_start():
    """``fit_on_consistent_edges`` fits the ridge points within 1.5 px of the *fitted* outline until they
    hold (``fit_until_stable``), not those of its start circle: starts 0.05 px apart end within 0.05
    px of each other (outline of 30 px with a contact shadow's arc 2 px outside it below, a reflected
    arc 1.6 px inside above and 1,500 clutter points; fitting the start circle's band, they ended up
    to 0.15 px apart), within 1 px of the true centre."""
    from ffls.spheres import detect

    H, W = 160, 200
    c, R = np.array([100.0, 80.0]), 30.0
    cam = detect.DetectionCamera("orthographic", None, None, np.eye(4), 1.0, (H, W))
    gaps, errors = [], []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        arcs = []
        for r, (a0, a1, step) in ((R, (0, 360, 1.0)), (R + 2.0, (30, 150, 1.5)), (R - 1.6, (200, 340, 1.5))):
            t = np.radians(np.arange(a0, a1, step))
            arcs.append(c + r * np.stack([np.cos(t), np.sin(t)], axis=1) + rng.normal(0, 0.25, (len(t), 2)))
        pts = np.concatenate(arcs + [rng.uniform(0, [W, H], (1500, 2))])
        pts = pts[np.lexsort((pts[:, 0], pts[:, 1]))]  # row by row, as consistent_edge_points lists them
        dirs = pts - c
        dirs /= np.maximum(np.hypot(dirs[:, 0], dirs[:, 1]), 1e-9)[:, None]
        ev = detect.ConsistentEdges(None, None, (pts, dirs, np.ones(len(pts))))
        starts = np.random.default_rng(100 + seed)
        for _ in range(8):
            s0, r0 = c + starts.uniform(-3, 3, 2), R + starts.uniform(-2, 2)
            a = detect.fit_on_consistent_edges(s0, r0, ev, cam, "auto")
            b = detect.fit_on_consistent_edges(s0 + [0.05, 0.0], r0, ev, cam, "auto")
            assert a is not None and b is not None
            gaps.append(np.hypot(*(a.center_px - b.center_px)) + abs(a.radius_px - b.radius_px))
            errors.append(np.hypot(*(a.center_px - c)))
    assert max(gaps) < 0.05, np.round(gaps, 3)
    assert max(errors) < 1.0


def test_each_photo_edge_circle_is_one_search(tmp_path, monkeypatch):
    """A photo-edge circle is one ``fit_on_consistent_edges`` (which refits on the points near its
    own outline until they hold); before, a fit that improved ``outline_quality`` was searched again
    from itself, up to twice more (10-40 % of the detection's CPU, no sphere of the bench rows
    changed), and the four white spheres are found as before."""
    from ffls.spheres import detect

    _white_capture(tmp_path)
    cap = load_capture(tmp_path)
    per_circle, calls = [], []
    fit, one = detect.fit_on_consistent_edges, detect.photo_edge_fit

    def counted(*a, **k):
        calls.append(1)
        return fit(*a, **k)

    def each(k):
        calls.clear()
        ft = one(k)
        per_circle.append(len(calls))
        return ft

    monkeypatch.setattr(detect, "fit_on_consistent_edges", counted)
    monkeypatch.setattr(detect, "photo_edge_fit", each)
    assert len(find_spheres_in_capture(cap)) == 4
    assert per_circle and set(per_circle) == {1}, per_circle
