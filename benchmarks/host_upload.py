"""Host-side cost of putting a capture's basis on the GPU (what `ffls render` / `relight` /
`view` pay before their first frame), against a reference tree in the same run.

Stages, each timed in a fresh process per run (CPU process time and wall time, median of the
runs; the trees alternate run by run, so that the machine's load falls on both alike):

- ``load_photos``: the accepted photos as one float32 basis (:func:`ffls.radiance.photos.load_photos`);
- ``to_float16``: the checked float16 conversion of the whole basis (:mod:`ffls.store.float16`);
- ``BasisTextures`` / ``PackedBasis``: the basis uploaded as f16 (:mod:`ffls.gpu.basis`; on
  llvmpipe the upload itself is a CPU copy).

Each run also hashes the float16 values, the report and the texture contents read back, so the
two trees are checked to give the same bytes.

Usage::

    git archive 33f3108 | tar -x -C /tmp/before
    ffls synth /tmp/cap --lights 128 --resolution 512
    python benchmarks/host_upload.py /tmp/cap --before /tmp/before --runs 4 --out results/host_upload.json
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from common import write_json  # benchmarks/common.py (atomic)

HERE = Path(__file__).resolve().parent
STAGES = ("load_photos", "to_float16", "BasisTextures", "PackedBasis")


def _worker(capture: str) -> dict:
    from ffls.gpu.basis import BasisTextures, PackedBasis
    from ffls.gpu.context import create_headless_context
    from ffls.io.capture import load_capture
    from ffls.radiance.photos import load_photos
    from ffls.store.float16 import to_float16

    res, digest = {}, hashlib.sha1()

    def timed(name, fn):
        c, w = time.process_time(), time.perf_counter()
        out = fn()
        res[name] = {"cpu_s": time.process_time() - c, "wall_s": time.perf_counter() - w}
        return out

    cap = load_capture(capture)
    basis = timed("load_photos", lambda: load_photos(cap, progress=False))
    digest.update(basis.tobytes())
    h, rep = timed("to_float16", lambda: to_float16(basis))
    digest.update(h.tobytes())
    digest.update(repr(rep).encode())
    del h
    ctx = create_headless_context()
    for name, cls in (("BasisTextures", BasisTextures), ("PackedBasis", PackedBasis)):
        bt = timed(name, lambda: cls(ctx, basis, "f16"))
        ctx.finish()
        for t in (bt.textures if name == "BasisTextures" else bt.images):
            digest.update(t.read())
        digest.update(repr(bt.report).encode())
        bt.release()
    res["sha1"] = digest.hexdigest()
    res["shape"] = list(basis.shape)
    res["renderer"] = ctx.info.get("GL_RENDERER")
    return res


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture")
    ap.add_argument("--before", help="reference tree (e.g. a git archive of main)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", help="JSON file")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        print(json.dumps(_worker(a.capture)))
        return
    trees = {"after": str(HERE.parent)}
    if a.before:
        trees = {"before": str(Path(a.before).resolve()), **trees}
    runs = {k: [] for k in trees}
    for r in range(a.runs):
        for name, tree in trees.items():
            env = dict(os.environ, PYTHONPATH=tree, OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS", "1"))
            out = subprocess.run([sys.executable, __file__, a.capture, "--worker"], env=env, check=True,
                                 capture_output=True, text=True).stdout
            runs[name].append(json.loads(out.strip().splitlines()[-1]))
            print(f"run {r} {name}: " + ", ".join(f"{s} {runs[name][-1][s]['cpu_s']:.2f}" for s in STAGES),
                  flush=True)
    table = {name: {s: {k: statistics.median(x[s][k] for x in rs) for k in ("cpu_s", "wall_s")} for s in STAGES}
             for name, rs in runs.items()}
    same = len({x["sha1"] for rs in runs.values() for x in rs}) == 1
    first = next(iter(runs.values()))[0]
    print(f"basis {first['shape']}, {first['renderer']}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; "
          f"median of {a.runs} runs; same bytes in every run: {same}")
    print(f"{'stage':14s}" + "".join(f"{n + ' cpu s':>14s}{n + ' wall s':>14s}" for n in table)
          + ("   cpu ratio" if "before" in table else ""))
    for s in STAGES:
        line = f"{s:14s}" + "".join(f"{t[s]['cpu_s']:14.2f}{t[s]['wall_s']:14.2f}" for t in table.values())
        if "before" in table:
            line += f"{table['after'][s]['cpu_s'] / table['before'][s]['cpu_s']:12.2f}"
        print(line)
    if a.out:
        write_json(a.out, {"capture": a.capture, "shape": first["shape"], "renderer": first["renderer"],
                           "cpus": os.cpu_count(), "runs": a.runs, "same_bytes": same, "median": table,
                           "all": runs})


if __name__ == "__main__":
    main()
