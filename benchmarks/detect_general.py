"""Detection rate and centre accuracy of sphere detection without hints, on constructed scenes.

Scenes from ``tests/detect_scenes.py`` (NumPy ray casting, independent of ``ffls synth``): 12
lights on the camera's side; 1, 3, 6 and 8 white matte spheres (radius about 16-20 px) at random
places in a 400x300 pinhole view, on black, grey, white and textured-noise backgrounds, several
seeds each; plus a chrome ball, distractors (a red matte sphere and a flat white disc), spheres
cut by the frame edge, a long lens (f = 30000 px) and an orthographic camera. For each condition:
spheres found / present, false detections, centre error (px, median and max) and detection time.

    python benchmarks/detect_general.py [--seeds 3]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import detect_scenes as ds  # noqa: E402

from ffls.errors import InputError  # noqa: E402
from ffls.spheres import detect  # noqa: E402


def _run(scene, seq, R, **kw):
    truth = np.array([scene.centre_px(b) for b in scene.balls]).reshape(-1, 2)
    t0 = time.perf_counter()
    try:
        fits = detect.find_spheres(seq, scene.K, None, R, **kw)
    except InputError:
        fits = []
    dt = time.perf_counter() - t0
    found, false, err = set(), 0, []
    for f in fits:
        d = np.linalg.norm(truth - f.center_px, axis=1) if len(truth) else np.array([np.inf])
        k = int(np.argmin(d))
        if d[k] < 0.5 * f.radius_px and k not in found:
            found.add(k)
            err.append(float(d[k]))
        else:
            false += 1
    return len(found), false, err, dt


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args(argv)
    L = ds.lights(12, seed=1)
    rows = []

    def add(name, results, expected):
        n_found = sum(r[0] for r in results)
        n_false = sum(r[1] for r in results)
        err = [e for r in results for e in r[2]]
        t = np.mean([r[3] for r in results])
        rows.append((name, f"{n_found}/{expected}", n_false, np.median(err) if err else np.nan,
                     max(err) if err else np.nan, t))

    for n in (1, 3, 6, 8):
        for bg in ds.BACKGROUNDS:
            res = []
            for s in range(args.seeds):
                scene = ds.layout(n, seed=100 * s + 7 * n + len(bg))
                res.append(_run(scene, ds.render(scene, L, bg, seed=s), 0.04))
            add(f"{n} matte, {bg}", res, n * args.seeds)
    for bg in ("black", "grey", "texture"):
        res = []
        for s in range(args.seeds):
            scene = ds.layout(1, seed=200 + s)
            scene.balls[0].kind = "mirror"
            res.append(_run(scene, ds.render(scene, L, bg, seed=s), 0.04))
        add(f"1 chrome, {bg}", res, args.seeds)
    res = []
    for s in range(args.seeds):
        scene = ds.layout(5, seed=300 + s)
        scene.balls[3].albedo = (0.8, 0.1, 0.08)
        flat = scene.balls.pop(4)
        u, v = scene.centre_px(flat)
        scene.discs.append((u, v, 18.0, (0.9, 0.9, 0.9)))
        red = scene.balls.pop(3)  # not a calibration sphere: a detection of it counts as false
        seq = ds.render(ds.Scene(scene.shape, scene.balls + [red], "pinhole", scene.K, scene.discs), L, "grey", seed=s)
        res.append(_run(scene, seq, 0.04))
    add("3 matte + red sphere + flat disc, grey", res, 3 * args.seeds)
    K = np.array([[500.0, 0, 199.5], [0, 500, 149.5], [0, 0, 1]])

    def at(u, v, K, z=1.0, R=0.04):
        return ds.Ball(np.array([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z]), R)

    scene = ds.Scene((300, 400), [at(100, 150, K), at(8, 200, K), at(390, 60, K)], "pinhole", K)
    seq = ds.render(scene, L, "grey")
    add("cut by the frame (63 % and 62 % visible), grey", [_run(scene, seq, 0.04)], 3)
    truth = np.array([scene.centre_px(b) for b in scene.balls])
    cut_lines = [f"  visible {f.visible_fraction:.0%}: centre standard error {f.center_sigma_px:.3f} px, actual error "
                 f"{np.min(np.linalg.norm(truth - f.center_px, axis=1)):.3f} px"
                 for f in detect.find_spheres(seq, K, None, 0.04)]
    f = 30000.0
    KL = np.array([[f, 0, 199.5], [0, f, 149.5], [0, 0, 1]])
    scene = ds.Scene((300, 400), [at(u, v, KL, 40 + dz, 0.03) for u, v, dz in [(80, 80, 0), (250, 200, 0.3), (330, 90, -0.2)]],
                     "pinhole", KL)
    add("long lens f=30000 px, grey", [_run(scene, ds.render(scene, L, "grey"), 0.03)], 3)
    res = []
    for bg in ds.BACKGROUNDS:
        scene = ds.Scene((300, 400), [ds.Ball(np.array([u, v, 100.0]), 20.0) for u, v in [(80, 80), (250, 200), (330, 90)]],
                         "orthographic", None)
        res.append(_run(scene, ds.render(scene, L, bg), None, camera_model="orthographic"))
    add("orthographic, 3 spheres x 4 backgrounds", res, 12)
    print(f"{'condition':44s} {'found':>7s} {'false':>5s} {'med px':>7s} {'max px':>7s} {'time s':>7s}")
    for name, found, false, med, mx, t in rows:
        print(f"{name:44s} {found:>7s} {false:5d} {med:7.3f} {mx:7.3f} {t:7.2f}")
    print("spheres cut by the frame:")
    print("\n".join(cut_lines))


if __name__ == "__main__":
    main()
