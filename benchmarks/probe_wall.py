"""An unhinted diffuse probe ball in front of a plain wall of its own brightness: found, or refused.

A grey ball (albedo 0.25, radius 72 px, orthographic) rendered by
``ffls.synth.probe_scenes.diffuse_sphere_scene`` under the built-in ``courtyard`` and ``sunrise`` maps
(downsampled 16x), pasted at (159.5, 119.5) into a 320 x 240 photo of a flat wall whose radiance is
``--levels`` times the ball's 90th percentile (0.5: the lit side brighter than the wall, the side
toward the terminator darker, and between them no outline at all), the whole photo with 2%
multiplicative Gaussian noise (``--seeds``; the scene: ``tests/probe_wall_scene.py``). Also the wall
alone (must be refused). ``probe.json`` locates nothing (``"sphere": {"material": "diffuse"}``);
outcome ``ok`` (centre within 0.3 px), ``off`` (found farther), ``refused`` (one-line InputError).

Run: ``OMP_NUM_THREADS=1 python benchmarks/probe_wall.py [--levels 0.3,0.5,0.7] [--seeds 1,2] [--out FILE]``
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from common import host_info, write_json
from ffls.errors import InputError
from ffls.io.images import write_exr
from ffls.io.probe import load_probe
from ffls.probes.bracket import view_radiance
from ffls.probes.locate import locate_sphere

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from probe_wall_scene import wall_photo  # noqa: E402


def locate(folder, img):
    write_exr(folder / "ball.exr", img)
    (folder / "probe.json").write_text(json.dumps({"format": "ffls-probe", "version": 1, "images": ["ball.exr"],
                                                   "camera": {"model": "orthographic"},
                                                   "sphere": {"material": "diffuse"}}))
    probe = load_probe(folder)
    vr = view_radiance(probe.views[0], probe.encoding, probe.response, probe.json_path)
    try:
        geo = locate_sphere(probe.views[0], vr.radiance, probe.json_path)
        return np.asarray(geo.center_px), float(geo.radius_px), None
    except InputError as e:
        return None, None, e.message


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="0.3,0.5,0.7", help="the wall's radiance over the ball's 90th percentile")
    ap.add_argument("--seeds", default="1,2", help="the noise's seeds")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "probe_wall.json"))
    a = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("courtyard", "sunrise"):
            for level in [float(v) for v in a.levels.split(",")]:
                for seed in [int(v) for v in a.seeds.split(",")]:
                    for ball in (True, False):
                        img, c_true, r_true = wall_photo(name, level, seed, ball)
                        folder = Path(tmp) / f"{name}_{level}_{seed}_{ball}"
                        folder.mkdir()
                        c, r, msg = locate(folder, img)
                        err = None if c is None else float(np.hypot(*(c - c_true)))
                        outcome = "refused" if c is None else ("ok" if ball and err < 0.3 else "off")
                        rows.append({"map": name, "level": level, "seed": seed, "ball": ball, "centre_error_px": err,
                                     "radius_error_px": None if r is None else r - r_true, "outcome": outcome,
                                     "message": msg})
                        what = "ball" if ball else "wall alone"
                        print(f"{name:10s} level {level:.2f} seed {seed} {what:10s} "
                              + (f"centre error {err:6.3f} px, radius {r - r_true:+.3f} px" if c is not None
                                 else f"refused: {msg[msg.find('no sphere'):][:110]}")
                              + f"  {outcome}", flush=True)
    summary = {"ball": {o: sum(r["outcome"] == o for r in rows if r["ball"]) for o in ("ok", "off", "refused")},
               "wall alone": {o: sum(r["outcome"] == o for r in rows if not r["ball"]) for o in ("off", "refused")}}
    print(f"ball: {summary['ball']}; wall alone: {summary['wall alone']}")
    write_json(a.out, {"host": host_info(), "summary": summary, "rows": rows})


if __name__ == "__main__":
    main()
