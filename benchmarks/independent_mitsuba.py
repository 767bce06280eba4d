"""Light-direction accuracy on independent, physically based renders (Mitsuba 3).

``ffls.synth.scene`` renders with a one-bounce ground model that the estimator's bounce term was
designed around. This benchmark renders a different scene with Mitsuba 3's path tracer (multiple
bounces: ground <-> spheres <-> object, the spheres' contact shadows, the object's
interreflections) and runs the whole ffls pipeline on it: automatic sphere detection
(:func:`ffls.spheres.detect.find_spheres_in_capture`) and :func:`ffls.spheres.estimate.estimate_lights`
on :func:`ffls.io.capture.load_capture` of the written capture folder. The estimator is also run on
the true sphere centres, to separate detection from shading errors.

Scene (nothing taken from ``ffls.synth.scene``): a 6 m x 6 m grey diffuse ground (albedo 0.3), four white
diffuse spheres (albedo 0.8, radius 5 cm) resting on it at irregular positions, a rotated
rough-plastic cube and a capped diffuse cylinder between them, a perspective camera 1.15 m from
the scene centre at azimuth -115 deg and 35 deg elevation (fov chosen for ~45 px spheres at
768 px), path tracer ``max_depth`` 8, box pixel filter. One light per image on the paper's Table 1
grid (phi from the camera's azimuth, theta from the zenith): a ``directional`` emitter of
irradiance 1, or a spherical area light of radius 5 cm at 2 m from the scene centre.

Needs ``pip install mitsuba`` (``ffls[validate]``). Writes the capture (linear float EXR,
``capture.json`` without sphere hints or truth) and ``truth.json`` under ``--cache`` (renders are
reused), prints a table and writes ``benchmarks/results/independent_mitsuba.json``.

    python benchmarks/independent_mitsuba.py --configs distant_grey,near_grey \\
        [--res 768] [--spp 64] [--phi-step 20] [--theta-step 10] [--cache DIR]
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ffls.io.capture import load_capture
from ffls.conventions import angle_between
from ffls.io.images import write_exr

from common import host_info, print_error_table, write_json  # noqa: E402  (benchmarks/common.py)

SPHERE_RADIUS = 0.05
SPHERE_XY = ((0.29, -0.06), (-0.02, -0.27), (-0.30, 0.04), (0.36, 0.24))
SCENE_CENTER = (0.0, 0.0, 0.0)
CAMERA = dict(azimuth_deg=-115.0, elevation_deg=35.0, distance=1.15, target=(0.0, 0.0, 0.04))
LIGHT_DISTANCE, LIGHT_RADIUS = 2.0, 0.05
CONFIGS = {
    "distant_grey": dict(light="distant", ground_albedo=0.3),
    "near_grey": dict(light="near", ground_albedo=0.3),
    "distant_black": dict(light="distant", ground_albedo=0.0),
}
TARGETS = {"distant_grey": (1.0, 0.5), "near_grey": (2.5, 1.0)}


def camera_geometry(res: int, fov_deg: float):
    """Camera centre, Mitsuba ``look_at`` arguments, OpenCV ``K`` for a ``res`` x ``res`` image."""
    az, el = math.radians(CAMERA["azimuth_deg"]), math.radians(CAMERA["elevation_deg"])
    tgt = np.asarray(CAMERA["target"])
    origin = tgt + CAMERA["distance"] * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    # Mitsuba pixel i covers [i, i + 1): centre i + 0.5; OpenCV centres are integers
    f = 0.5 * res / math.tan(math.radians(fov_deg) / 2)
    K = np.array([[f, 0, 0.5 * res - 0.5], [0, f, 0.5 * res - 0.5], [0, 0, 1.0]])
    return origin, tgt, K


def light_grid(phi_step, theta_step):
    """(phis, thetas, directions (n, 3)): phi from the camera's azimuth, theta from the zenith."""
    phis = np.arange(0, 181, phi_step, dtype=float)
    thetas = np.arange(0, 71, theta_step, dtype=float)
    P, T = np.meshgrid(phis, thetas, indexing="ij")
    az = np.radians(CAMERA["azimuth_deg"] + P.ravel())
    t = np.radians(T.ravel())
    d = np.stack([np.sin(t) * np.cos(az), np.sin(t) * np.sin(az), np.cos(t)], axis=-1)
    return phis, thetas, d


def build_scene(mi, res, spp, fov_deg, ground_albedo):
    T = mi.ScalarTransform4f
    origin, tgt, _ = camera_geometry(res, fov_deg)

    def diffuse(c):
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(c)}}

    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8, "rr_depth": 5},
        "sensor": {"type": "perspective", "fov": fov_deg, "fov_axis": "x",
                   "to_world": T().look_at(origin=origin.tolist(), target=tgt.tolist(), up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"},
                            "pixel_format": "rgb", "component_format": "float32"},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "ground": {"type": "rectangle", "to_world": T().scale([3.0, 3.0, 1.0]), "bsdf": diffuse((ground_albedo,) * 3)},
        "cube": {"type": "cube",
                 "to_world": T().translate([0.02, 0.02, 0.07]).rotate([0, 0, 1], 27.0).scale([0.07, 0.07, 0.07]),
                 "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.25,
                          "diffuse_reflectance": {"type": "rgb", "value": [0.55, 0.12, 0.08]}}},
        "cyl": {"type": "cylinder", "p0": [-0.12, 0.12, 0.0], "p1": [-0.12, 0.12, 0.22], "radius": 0.045,
                "bsdf": diffuse((0.15, 0.45, 0.2))},
        "cyl_cap": {"type": "disk", "to_world": T().translate([-0.12, 0.12, 0.22]).scale([0.045, 0.045, 1.0]),
                    "bsdf": diffuse((0.15, 0.45, 0.2))},
    }
    for k, (x, y) in enumerate(SPHERE_XY):
        scene[f"sphere{k}"] = {"type": "sphere", "center": [x, y, SPHERE_RADIUS + 1e-4], "radius": SPHERE_RADIUS,
                               "bsdf": diffuse((0.8, 0.8, 0.8))}
    return scene


def world_from_camera_of(mi, scene):
    """OpenCV ``world_from_camera`` from the loaded Mitsuba sensor's own ``to_world``.

    Mitsuba's camera frame looks along +Z with +Y up and +X to the image's left (``look_at``
    puts ``cross(up, dir)`` on +X); OpenCV has x right, y down: flip x and y.
    """
    M = np.array(scene.sensors()[0].world_transform().matrix, dtype=np.float64).reshape(4, 4)
    return M @ np.diag([-1.0, -1.0, 1.0, 1.0])


def render_capture(folder: Path, cfg, res, spp, fov_deg, dirs, threads):
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    try:
        dr.set_thread_count(threads)
    except Exception:
        pass
    folder.mkdir(parents=True, exist_ok=True)
    base = build_scene(mi, res, spp, fov_deg, cfg["ground_albedo"])
    _, _, K = camera_geometry(res, fov_deg)
    names, times = [], []
    M = None
    c0 = np.asarray(SCENE_CENTER)
    for i, d in enumerate(dirs):
        name = f"img_{i:03d}.exr"
        names.append(name)
        if (folder / name).exists():
            continue
        sc = dict(base)
        if cfg["light"] == "distant":
            sc["light"] = {"type": "directional", "direction": (-d).tolist(),
                           "irradiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
        else:  # radiance for an irradiance of ~1 at the scene centre: E = L pi r^2 / D^2
            L = LIGHT_DISTANCE ** 2 / (math.pi * LIGHT_RADIUS ** 2)
            sc["light"] = {"type": "sphere", "center": (c0 + LIGHT_DISTANCE * d).tolist(), "radius": LIGHT_RADIUS,
                           "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [L, L, L]}}}
        scene = mi.load_dict(sc)
        if M is None:
            M = world_from_camera_of(mi, scene)
        t = time.perf_counter()
        img = np.array(mi.render(scene, spp=spp, seed=i), dtype=np.float32)[..., :3]
        times.append(time.perf_counter() - t)
        write_exr(folder / name, img)
        print(f"  rendered {name} ({times[-1]:.1f} s)", flush=True)
    if M is None:
        M = world_from_camera_of(mi, mi.load_dict(dict(base)))
    cap = {"format": "ffls-capture", "version": 1, "images": names, "image_size": [res, res], "encoding": "linear",
           "camera": {"K": K.tolist(), "dist": [0.0] * 5, "world_from_camera": M.tolist()},
           "sphere_radius": SPHERE_RADIUS, "scene_center": list(SCENE_CENTER), "hemisphere": "upper", "units": "m"}
    (folder / "capture.json").write_text(json.dumps(cap, indent=1))
    centers = [[x, y, SPHERE_RADIUS + 1e-4] for x, y in SPHERE_XY]
    positions = (c0 + LIGHT_DISTANCE * dirs).tolist() if cfg["light"] == "near" else None
    truthp = folder / "truth.json"
    old = json.loads(truthp.read_text()) if truthp.exists() else {}
    truth = {"directions": dirs.tolist(), "positions": positions, "sphere_centers": centers,
             "sphere_radius": SPHERE_RADIUS, "renderer": f"mitsuba {mi.__version__} scalar_rgb path max_depth 8",
             "spp": spp, "resolution": res, "fov_deg": fov_deg, **cfg,
             "render_s_per_image": float(np.median(times)) if times else old.get("render_s_per_image")}
    truthp.write_text(json.dumps(truth, indent=1))
    return truth


def project(K, M, X):
    Mi = np.linalg.inv(M)
    Xc = np.asarray(X) @ Mi[:3, :3].T + Mi[:3, 3]
    p = Xc @ K.T
    return p[:, :2] / p[:, 2:], Xc


def evaluate(folder: Path, truth, workers, spheres_from="detect"):
    from ffls.spheres.detect import find_spheres_in_capture
    from ffls.spheres.estimate import estimate_lights

    cap = load_capture(folder)
    K, M = cap.K, cap.world_from_camera
    true_c = np.asarray(truth["sphere_centers"])
    true_px, true_cam = project(K, M, true_c)
    det = {}
    t = time.perf_counter()
    if spheres_from == "detect":
        found = find_spheres_in_capture(cap)
        det["seconds"] = time.perf_counter() - t
        fpx = np.array([s.center_px for s in found])
        fw = np.array([s.center_world for s in found])
        match = [int(np.argmin(np.linalg.norm(true_px - p, axis=1))) for p in fpx]
        det.update(found=len(found), matched=match,
                   center_err_px=[float(np.linalg.norm(true_px[m] - p)) for m, p in zip(match, fpx)],
                   center_err_mm=[float(1e3 * np.linalg.norm(true_c[m] - w)) for m, w in zip(match, fw)],
                   radius_px=[float(s.radius_px) for s in found], residual_px=[float(s.residual_px) for s in found])
        spheres = found
    else:
        spheres = [SimpleNamespace(center_cam=c, radius=truth["sphere_radius"]) for c in true_cam]
        match = list(range(len(spheres)))
    t = time.perf_counter()
    lights = estimate_lights(cap, spheres=spheres, progress=False, workers=workers)
    dt = (time.perf_counter() - t) / len(cap.image_names)
    err = np.degrees(angle_between(lights.directions, np.asarray(truth["directions"])))
    ok = np.array([s == "ok" for s in lights.status])
    e = err[ok]
    reasons = {}
    for s, r in zip(lights.status, lights.reasons):
        if s != "ok":
            reasons[r] = reasons.get(r, 0) + 1
    ratios = []
    for k in range(len(spheres)):
        vals = [x["spheres"][k].get("bounce_ratio") for x in lights.extra if x.get("spheres")]
        vals = [v for v in vals if v is not None]
        ratios.append(float(vals[0]) if vals else None)
    sphere_status = [[x["spheres"][k]["status"] if x.get("spheres") else None for k in range(len(spheres))]
                     for x in lights.extra]
    return {
        "spheres": spheres_from, "detection": det, "sphere_truth_index": match, "n": int(len(err)),
        "accepted": int(ok.sum()), "rejected": reasons,
        "median_deg": float(np.median(e)) if e.size else None, "p90_deg": float(np.percentile(e, 90)) if e.size else None,
        "max_deg": float(e.max()) if e.size else None, "bounce_ratio": ratios, "ms_per_image": 1e3 * dt,
        "models": {m: sum(1 for x in lights.extra if x.get("model") == m) for m in ("distant", "near")},
        "errors_deg": [float(x) if o else None for x, o in zip(err, ok)],
        "errors_all_deg": [float(x) for x in err], "sphere_status": sphere_status,
        "uncertainty_deg": [x.get("uncertainty_deg") for x in lights.extra],
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configs", default="distant_grey,near_grey")
    ap.add_argument("--res", type=int, default=768)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--fov", type=float, default=40.0, help="horizontal field of view, degrees")
    ap.add_argument("--phi-step", type=int, default=20)
    ap.add_argument("--theta-step", type=int, default=10)
    ap.add_argument("--threads", type=int, default=2, help="Mitsuba render threads")
    ap.add_argument("--workers", type=int, default=1, help="ffls estimate_lights processes")
    ap.add_argument("--cache", default="/tmp/ffls_mitsuba")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "independent_mitsuba.json"))
    ap.add_argument("--evaluate", nargs="*", default=None, metavar="DIR",
                    help="only evaluate existing capture folders with a truth.json (e.g. bench_lights --cache"
                         " renders of ffls.synth.scene), detected and true spheres; no Mitsuba needed")
    a = ap.parse_args(argv)
    if a.evaluate:
        for folder in a.evaluate:
            truth = json.loads((Path(folder) / "truth.json").read_text())
            for sph in ("detect", "truth"):
                r = evaluate(Path(folder), truth, a.workers, sph)
                d = r["detection"]
                print(f"{folder}: spheres={sph:6s} ok={r['accepted']}/{r['n']} median={r['median_deg']:.2f} "
                      f"p90={r['p90_deg']:.2f} max={r['max_deg']:.2f} deg"
                      + (f" centre px {[round(x, 2) for x in d['center_err_px']]}" if d else ""), flush=True)
        return
    phis, thetas, dirs = light_grid(a.phi_step, a.theta_step)
    rows = []
    for name in a.configs.split(","):
        cfg = CONFIGS[name]
        folder = Path(a.cache) / f"{name}_{a.res}_spp{a.spp}_p{a.phi_step}_t{a.theta_step}"
        truth = render_capture(folder, cfg, a.res, a.spp, a.fov, dirs, a.threads)
        for sph in ("detect", "truth"):
            r = evaluate(folder, truth, a.workers, sph)
            r.update(config=name, folder=str(folder), res=a.res, spp=a.spp,
                     render_s_per_image=truth.get("render_s_per_image"), **cfg)
            rows.append(r)
            tgt = TARGETS.get(name)
            d = r["detection"]
            dets = (f" found={d['found']} centre px max {max(d['center_err_px']):.2f} mm max {max(d['center_err_mm']):.1f}"
                    if d else "")
            med = "-" if r["median_deg"] is None else f"{r['median_deg']:.2f}"
            mx = "-" if r["max_deg"] is None else f"{r['max_deg']:.2f}"
            print(f"{name:14s} spheres={sph:6s}{dets} ok={r['accepted']}/{r['n']} rej={r['rejected']} "
                  f"median={med} max={mx} deg rho_g={[None if x is None else round(x, 3) for x in r['bounce_ratio']]}"
                  + (f" (target max {tgt[0]} median {tgt[1]})" if tgt else ""), flush=True)
    for r in rows:
        print(f"\n{r['config']} spheres={r['spheres']}: median {r['median_deg']}, max {r['max_deg']}")
        print_error_table(r["errors_deg"], phis, thetas)
    doc = {"benchmark": "independent_mitsuba", **host_info(), "phis_deg": phis.tolist(),
           "thetas_deg": thetas.tolist(), "camera": CAMERA, "sphere_xy": SPHERE_XY, "fov_deg": a.fov, "results": rows}
    write_json(a.out, doc)


if __name__ == "__main__":
    main()
