"""The time of ``ffls probe pocs`` per unit of work: the rates behind its time estimate.

    OMP_NUM_THREADS=1 python benchmarks/pocs_time.py

A Lambertian ball of albedo 0.7, 96 px (about 7000 pixels, so every fit uses the default 2000-pixel
subset, the most ``ffls probe pocs`` uses), under the bundled studio map at 16 rows. Each row is the
CPU seconds of ``pocs_lightmap`` (one thread; one warm-up call first) at two sizes of the knob that
grows the work, and the rate of the extra work between them:

* adaptive sources, least-power (the default): seconds per sweep (``iterations`` 10 and 40: the set
  is grown by ``iterations`` sweeps per round and fold);
* grid sources, sequential: seconds per sweep per unknown (``grid`` 16 and 32, 2 g^2 unknowns, 20
  sweeps);
* grid sources, dykstra: 5 sweeps at ``grid`` 32 and 48, whose time is its residual bound's linear
  programme, not the sweeps' (no rate: ``ffls probe pocs`` says it has no estimate).

``ffls.commands.probe.POCS_RATES`` takes these rates. Writes ``benchmarks/results/pocs_time.json``.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

from common import host_info, write_json
from ffls.io.probe import load_probe
from ffls.lightmaps.lightmap import builtin_lightmap
from ffls.probes.estimate import pocs_lightmap
from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe


def cpu(fn) -> float:
    t = time.process_time()
    fn()
    return time.process_time() - t


def main() -> None:
    sc = diffuse_sphere_scene(builtin_lightmap("studio").downsample(8), resolution=96, albedo=0.7)
    probe = load_probe(write_diffuse_probe(Path(tempfile.mkdtemp()) / "ball", sc))
    pocs_lightmap(probe, height=16, iterations=5)  # warm-up
    rows = {}
    t = [cpu(lambda it=it: pocs_lightmap(probe, height=16, iterations=it)) for it in (10, 40)]
    rows["adaptive least-power"] = {"seconds": t, "per_sweep": (t[1] - t[0]) / 30}
    print(rows, flush=True)
    t = [cpu(lambda g=g: pocs_lightmap(probe, height=32, sources="grid", grid=g, iterations=20,
                                       scheme="sequential")) for g in (16, 32)]
    rows["grid sequential"] = {"seconds": t, "per_sweep_unknown": (t[1] - t[0]) / (20 * 2 * (32**2 - 16**2))}
    print(rows, flush=True)
    t = [cpu(lambda g=g: pocs_lightmap(probe, height=96, sources="grid", grid=g, iterations=5,
                                       scheme="dykstra")) for g in (32, 48)]
    rows["grid dykstra, 5 sweeps"] = {"seconds": t}
    for name, r in rows.items():
        print(f"{name:24s} " + " ".join(f"{k} {v}" for k, v in r.items()))
    write_json(Path(__file__).parent / "results" / "pocs_time.json", {"host": host_info(), "rows": rows})


if __name__ == "__main__":
    main()
