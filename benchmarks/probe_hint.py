"""A probe ball located from a pixel hint without a radius, in one photo: how often, and how close.

Diffuse: a grey ball (albedo 0.25, radius 60 px, centre (99.5, 99.5), 200 x 200 px, orthographic)
rendered by ``ffls.synth.probe_scenes.diffuse_sphere_scene`` under the built-in ``courtyard`` and
``sunrise`` maps (downsampled 16x), on a ground of blurred uniform noise (sigma 3 px, 6 seeds)
scaled to the ball's 90th percentile: the ball is brighter than the ground on its lit side and
darker on its shadowed side (``--seeds``: other grounds). Three ``probe.json`` spheres per render:
no hint, ``center_px`` on the centre (100, 100), and ``center_px`` 10 px off (108, 94). Outcome: ``ok`` (centre within
0.1 px), ``off`` (found farther), ``refused`` (one-line InputError).

Mirror: the chrome ball of ``tests/test_probe_detect.py`` (f = 400 px at 1.2 m, 320 x 240 px,
radius 33 px) under the 4 built-in maps, ``center_px`` on the projected centre and 7.8 px off;
outcome ``ok`` within 1 px, else ``off`` (``off, flagged`` where the sphere's description flags its centre
as uncertain); with the 95% centre radius it states.

Run: ``OMP_NUM_THREADS=1 python benchmarks/probe_hint.py [--seeds 1,2,...] [--no-mirror] [--out FILE]``
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import cv2
import numpy as np

from common import host_info, set_probe_sphere, write_json
from ffls.errors import InputError
from ffls.io.images import write_exr
from ffls.io.probe import load_probe
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes.bracket import view_radiance
from ffls.probes.locate import locate_sphere
from ffls.synth.probe import off_axis_view, write_mirror_probe
from ffls.synth.probe_scenes import diffuse_sphere_scene


def _locate(folder):
    """(centre px, radius px, stated 95% centre radius or None, flagged) of the located sphere, or None (refused);
    flagged: its description says UNCERTAIN (``SphereGeometry.flagged``)."""
    probe = load_probe(folder)
    vr = view_radiance(probe.views[0], probe.encoding, probe.response, probe.json_path)
    try:
        geo = locate_sphere(probe.views[0], vr.radiance, probe.json_path)
        return np.asarray(geo.center_px), float(geo.radius_px), geo.center_uncertainty_px, geo.flagged
    except InputError:
        return None


def diffuse_rows(tmp: Path, seeds=range(1, 7)) -> list:
    rows = []
    for name in ("courtyard", "sunrise"):
        sc = diffuse_sphere_scene(builtin_lightmap(name).downsample(16), resolution=200, albedo=0.25,
                                  radius_frac=0.3)
        for seed in seeds:
            bg = cv2.GaussianBlur(np.random.default_rng(seed).uniform(0, 1, (200, 200, 3)), (0, 0), 3)
            bg = (bg - bg.min()) / np.ptp(bg) * np.percentile(sc.image[sc.mask], 90)
            folder = tmp / f"{name}_{seed}"
            folder.mkdir()
            write_exr(folder / "ball.exr", np.where(sc.mask[..., None], sc.image, bg).astype(np.float32))
            (folder / "probe.json").write_text(json.dumps({"format": "ffls-probe", "version": 1,
                                                           "images": ["ball.exr"],
                                                           "camera": {"model": "orthographic"}}))
            for hint in (None, [100.0, 100.0], [108.0, 94.0]):
                set_probe_sphere(folder, {"material": "diffuse", **({"center_px": hint} if hint else {})})
                got = _locate(folder)
                err = None if got is None else float(np.hypot(*(got[0] - sc.center_px)))
                rows.append({"kind": "diffuse", "map": name, "seed": seed, "hint": hint, "centre_error_px": err,
                             "outcome": "refused" if got is None else ("ok" if err < 0.1 else "off")})
    return rows


def mirror_rows(tmp: Path) -> list:
    rows = []
    center = np.array([0.0, 0.0, 0.1])
    K, T, c_true = off_axis_view(center, 1.2, 400.0, (70.0, 10.0))
    for name in ("courtyard", "night", "studio", "sunrise"):
        folder = tmp / f"mirror_{name}"
        write_mirror_probe(folder, builtin_lightmap(name), (320, 240), "pinhole", K, None, T, center, 0.1,
                           sphere="auto", reflectance=0.7)
        for off in ((0.0, 0.0), (6.0, -5.0)):
            hint = [float(c_true[0] + off[0]), float(c_true[1] + off[1])]
            set_probe_sphere(folder, {"material": "mirror", "reflectance": 0.7, "center_px": hint})
            got = _locate(folder)
            err = None if got is None else float(np.hypot(*(got[0] - c_true)))
            u = None if got is None else got[2]
            flagged = got is not None and got[3]
            rows.append({"kind": "mirror", "map": name, "hint_offset_px": list(off), "centre_error_px": err,
                         "center_uncertainty_px": u, "flagged": flagged,
                         "outcome": "refused" if got is None else ("ok" if err < 1.0 else
                                                                   ("off, flagged" if flagged else "off"))})
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "probe_hint.json"))
    ap.add_argument("--seeds", default="1,2,3,4,5,6", help="the busy grounds' seeds (default 1-6)")
    ap.add_argument("--no-mirror", action="store_true", help="the diffuse rows only")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        rows = diffuse_rows(Path(tmp), seeds) + ([] if args.no_mirror else mirror_rows(Path(tmp)))
    for r in rows:
        e = "-" if r["centre_error_px"] is None else f"{r['centre_error_px']:.3f}"
        where = f"seed {r['seed']} hint {r['hint']}" if r["kind"] == "diffuse" else f"offset {r['hint_offset_px']}"
        u = r.get("center_uncertainty_px")
        print(f"{r['kind']:8s} {r['map']:10s} {where:28s} centre error {e:>7s} px  {r['outcome']}"
              + ("" if u is None else f"  (stated {u:.2f} px, 95%)") + (" FLAGGED" if r.get("flagged") else ""))
    summary = {}
    for r in rows:
        key = f"{r['kind']} {'no hint' if r.get('hint', 1) is None else 'centre hint'}"
        summary.setdefault(key, {}).setdefault(r["outcome"], 0)
        summary[key][r["outcome"]] += 1
    for k, v in summary.items():
        print(k, v)
    write_json(args.out, {"host": host_info(), "summary": summary, "rows": rows})


if __name__ == "__main__":
    main()
