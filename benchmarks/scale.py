"""Captures of any size: ingest throughput against Dask workers, peak memory against capture size, and the goal.

Usage: python benchmarks/scale.py [--work DIR] [--sections workers,memory,larger,goal] [--out result.json]

Captures are generated cheaply: ``ffls.synth`` renders ``n`` photos at a small base resolution
(the real renderer, real light directions), and each photo is then upsampled (bilinear, never
negative) to the benchmark's resolution and written as half-float EXR. The photos are therefore
smooth at the large size; what is measured (reading, linearising, storing, streaming and summing
the pixels) does not depend on their content.

Sections (each prints a table; all go to ``--out`` as JSON):

* ``workers``: ``ffls ingest`` throughput (photos/s) in this process and on a local Dask cluster of
  1 and 2 processes (the machine has ``os.cpu_count()`` cores), median of ``--repeats`` runs.
* ``memory``: peak RSS of ``ffls relight`` streamed (``--tiles --memory``) and in memory, for captures
  of 16, 48 and 160 photos at 1024^2 (10-fold growth); each run is a fresh subprocess that reads its
  own peak RSS as it ends (``VmHWM``; ``resource.getrusage`` keeps the parent's peak across exec).
* ``larger``: a capture whose photos in float32 are more than 10 times ``--memory`` (with 2%
  multiplicative noise, so that the store is about as large as a real one), relit streamed; compared with a reference summed photo by photo in float64 (never more than one photo
  in memory).
* ``goal``: 64 photos at 2048^2, streamed at ``--memory 1G`` against the in-memory ``ffls relight``:
  peak RSS of both, wall time, and the largest difference.
The reference measured in the same run is NumPy's copy bandwidth (``benchmarks/common.py``):
bytes of float16 photos streamed per second against it.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from common import host_info, numpy_copy_bandwidth, write_json  # benchmarks/common.py

# The child's own peak: VmHWM of /proc/self/status (its address space's high-water mark, new at
# exec). getrusage's ru_maxrss is kept across fork + exec on Linux, so a child of this (large)
# process would report the parent's peak when that is higher; both are recorded.
_CHILD = r"""
import json, resource, sys, time
from ffls.cli import main
t0 = time.perf_counter()
rc = main(sys.argv[1:])
dt = time.perf_counter() - t0
hwm = [int(l.split()[1]) * 1024 for l in open("/proc/self/status") if l.startswith("VmHWM:")][0]
print("RESULT " + json.dumps({"rc": rc, "seconds": dt, "peak_rss": hwm,
                              "ru_maxrss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
"""


def run_cli(args: list[str]) -> dict:
    """``ffls ARGS`` in a fresh Python: exit status, wall time and peak RSS (bytes)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "CI": "1"}
    p = subprocess.run([sys.executable, "-c", _CHILD, *args], capture_output=True, text=True, env=env)
    line = [x for x in p.stdout.splitlines() if x.startswith("RESULT ")]
    if not line:
        raise RuntimeError(f"ffls {' '.join(args)} failed:\n{p.stdout}\n{p.stderr}")
    out = json.loads(line[-1][7:])
    out["stderr"] = p.stderr.strip()
    return out


def make_capture(folder: Path, n: int, res: int, base: int = 128, seed: int = 0, noise: float = 0.0) -> Path:
    """``n`` synthetic photos rendered at ``base`` px and upsampled to ``res`` px (half EXR); cached by name.

    ``noise`` > 0 multiplies every pixel by ``1 + noise * N(0, 1)`` (clipped at 0): the smooth
    upsampled photos compress far better than real ones, noisy ones about as badly."""
    import cv2

    from ffls.io.images import read_image, write_exr
    from ffls.synth.scene import write_synthetic_capture

    done = folder / ".complete"
    if done.exists():
        return folder
    if folder.exists():
        shutil.rmtree(folder)
    write_synthetic_capture(folder, n_lights=n, resolution=base, seed=seed, progress=False)
    doc = json.loads((folder / "capture.json").read_text())
    rng = np.random.default_rng(seed)
    for name in doc["images"]:
        img = read_image(folder / name).pixels
        big = cv2.resize(img, (res, res), interpolation=cv2.INTER_LINEAR)
        if noise > 0:
            big *= 1.0 + noise * rng.standard_normal(big.shape, dtype=np.float32)
        write_exr(folder / name, np.maximum(big, 0.0), half=True)
    doc["image_size"] = [res, res]
    K = np.asarray(doc["camera"]["K"], dtype=float)
    K[:2] *= res / base
    doc["camera"]["K"] = K.tolist()
    (folder / "capture.json").write_text(json.dumps(doc, indent=1))
    done.write_text("ok")
    return folder


def disk_free(path: Path) -> int:
    return shutil.disk_usage(path).free


def photos_bytes(n: int, res: int, itemsize: int = 4) -> int:
    return n * res * res * 3 * itemsize


def section_workers(work: Path, repeats: int) -> list[dict]:
    from ffls.cluster import open_client
    from ffls.io.capture import load_capture
    from ffls.store.ingest import SerialRunner, ingest_capture

    cap = load_capture(make_capture(work / "w32", 32, 1024))
    rows = []
    configs = [("in process", None), ("dask 1 worker", 1), ("dask 2 workers", 2)]
    for label, workers in configs:
        times = []
        if workers is None:
            for _ in range(repeats):
                t0 = time.perf_counter()
                ingest_capture(cap, work / "w32.zarr", runner=SerialRunner(False), rebuild=True)
                times.append(time.perf_counter() - t0)
        else:
            with open_client(workers, progress=False) as runner:
                ingest_capture(cap, work / "w32.zarr", runner=runner, rebuild=True)  # warm-up: imports in workers
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    ingest_capture(cap, work / "w32.zarr", runner=runner, rebuild=True)
                    times.append(time.perf_counter() - t0)
        t = float(np.median(times))
        rows.append({"runner": label, "photos": 32, "res": 1024, "seconds": t, "photos_per_s": 32 / t})
        print(f"  {label:16s} 32 photos 1024^2: {t:6.2f} s  {32 / t:5.2f} photos/s")
    return rows


def section_memory(work: Path, memory: str) -> list[dict]:
    rows = []
    for n in (16, 48, 160):
        folder = make_capture(work / f"m{n}", n, 1024, seed=n)
        st = run_cli(["relight", str(folder), "--probe", "sky", "-o", str(work / f"m{n}_tiles.exr"), "--tiles",
                      "--memory", memory, "--workers", "1"])  # builds the store on first use
        st = run_cli(["relight", str(folder), "--probe", "sky", "-o", str(work / f"m{n}_tiles.exr"), "--tiles",
                      "--memory", memory, "--workers", "1"])
        im = run_cli(["relight", str(folder), "--probe", "sky", "-o", str(work / f"m{n}_mem.exr"), "--workers", "1",
                      "--memory", "64G"])
        d = max_rel_diff(work / f"m{n}_tiles.exr", work / f"m{n}_mem.exr")
        rows.append({"photos": n, "res": 1024, "float32_bytes": photos_bytes(n, 1024),
                     "streamed_peak_rss": st["peak_rss"], "streamed_s": st["seconds"],
                     "in_memory_peak_rss": im["peak_rss"], "in_memory_s": im["seconds"], "max_rel_diff": d})
        print(f"  {n:4d} photos 1024^2 ({photos_bytes(n, 1024) / 2**30:5.2f} GiB f32): streamed peak "
              f"{st['peak_rss'] / 2**20:6.0f} MiB in {st['seconds']:5.1f} s; in memory {im['peak_rss'] / 2**20:6.0f} MiB "
              f"in {im['seconds']:5.1f} s; max diff {d:.2e} of max")
    return rows


def max_rel_diff(a, b) -> float:
    from ffls.io.images import read_image

    x, y = read_image(a).pixels, read_image(b).pixels
    return float(np.max(np.abs(x - y)) / np.max(np.abs(y)))


def section_larger(work: Path, memory: str, n: int) -> dict:
    from ffls.io.capture import load_capture_and_lights
    from ffls.radiance.photos import load_photo
    from ffls.relight.stream import parse_memory

    folder = make_capture(work / f"l{n}", n, 1024, seed=7, noise=0.02)
    f32 = photos_bytes(n, 1024)
    budget = parse_memory(memory)
    out = work / f"l{n}.exr"
    run_cli(["ingest", str(folder), "--workers", "1", "--no-progress"])
    st = run_cli(["relight", str(folder), "--probe", "sky", "-o", str(out), "--tiles", "--memory", memory,
                  "--workers", "1"])
    # the reference: the same weights, summed photo by photo in float64
    from ffls.lightmaps.lightmap import lightmap_from_spec
    from ffls.relight.stream import open_streamed

    capture, lights = load_capture_and_lights(folder)
    r, _ = open_streamed(capture, lights, 2 ** 40, force=True, progress=False)
    r.set_lightmap(lightmap_from_spec("sky"))
    r.render()
    w = r.read_weights()
    r.release()
    idx, _ = lights.accepted()
    pos = {nm: i for i, nm in enumerate(capture.image_names)}
    ref = None
    for k, i in enumerate(idx):
        p = load_photo(capture, pos[lights.image_names[i]]).astype(np.float64)
        ref = w[k] * p if ref is None else ref + w[k] * p
    from ffls.io.images import read_image

    got = read_image(out).pixels
    d = float(np.max(np.abs(got - ref)) / np.max(np.abs(ref)))
    store = sum(f.stat().st_size for f in (folder / "field.zarr").rglob("*") if f.is_file())
    row = {"photos": n, "res": 1024, "float32_bytes": f32, "store_bytes": store, "memory": budget,
           "ratio_float32_to_memory": f32 / budget, "peak_rss": st["peak_rss"], "seconds": st["seconds"],
           "max_rel_diff_vs_float64": d}
    print(f"  {n} photos 1024^2: {f32 / 2**30:.2f} GiB in float32 = {f32 / budget:.1f} x --memory {memory} "
          f"(store {store / 2**30:.2f} GiB on disk); streamed peak {st['peak_rss'] / 2**20:.0f} MiB in "
          f"{st['seconds']:.1f} s; max diff to the float64 photo-by-photo sum {d:.2e} of max")
    return row


def section_goal(work: Path) -> dict:
    folder = make_capture(work / "g64", 64, 2048, base=256, seed=11)
    ing = run_cli(["ingest", str(folder), "--workers", "1", "--no-progress"])
    st = run_cli(["relight", str(folder), "--probe", "sky", "-o", str(work / "g64_tiles.exr"), "--tiles",
                  "--memory", "1G", "--workers", "1"])
    im = run_cli(["relight", str(folder), "--probe", "sky", "-o", str(work / "g64_mem.exr"), "--workers", "1",
                  "--memory", "64G"])
    d = max_rel_diff(work / "g64_tiles.exr", work / "g64_mem.exr")
    row = {"photos": 64, "res": 2048, "ingest_s": ing["seconds"], "ingest_peak_rss": ing["peak_rss"],
           "streamed_peak_rss": st["peak_rss"], "streamed_s": st["seconds"], "in_memory_peak_rss": im["peak_rss"],
           "in_memory_s": im["seconds"], "max_rel_diff": d}
    print(f"  64 photos 2048^2: ingest {ing['seconds']:.0f} s (peak {ing['peak_rss'] / 2**20:.0f} MiB); streamed "
          f"--memory 1G peak {st['peak_rss'] / 2**20:.0f} MiB in {st['seconds']:.1f} s; in memory peak "
          f"{im['peak_rss'] / 2**20:.0f} MiB in {im['seconds']:.1f} s; max diff {d:.2e} of max")
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/ffls-scale-bench", help="folder of the generated captures (kept)")
    ap.add_argument("--sections", default="workers,memory,larger,goal")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--memory", default="512M", help="--memory of the memory section")
    ap.add_argument("--larger-memory", default="256M", help="--memory of the larger-than-memory section")
    ap.add_argument("--larger-photos", type=int, default=220)
    ap.add_argument("--max-disk", type=float, default=6.0, help="GiB of generated data allowed")
    ap.add_argument("--out", help="write the tables as JSON here")
    a = ap.parse_args()
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    sections = a.sections.split(",")
    need = 0.0  # GiB on disk: photos (half EXR, about as float16) + the store (float16) + its staging
    plan = {"workers": photos_bytes(32, 1024, 2) * 3, "memory": photos_bytes(224, 1024, 2) * 3,
            "larger": photos_bytes(a.larger_photos, 1024, 2) * 3, "goal": photos_bytes(64, 2048, 2) * 3}
    need = sum(plan[s] for s in sections) / 2 ** 30
    free = disk_free(work) / 2 ** 30
    print(f"disk: {free:.0f} GiB free, this run needs at most {need:.1f} GiB (limit --max-disk {a.max_disk})")
    if need > a.max_disk or need > 0.5 * free:
        raise SystemExit("not enough disk (or over --max-disk); choose fewer sections")
    bw = numpy_copy_bandwidth(256 * 2 ** 20)
    result = {"host": host_info(), "copy_bandwidth": bw, "cpu_count": os.cpu_count()}
    print(f"{os.cpu_count()} CPUs; NumPy copy bandwidth {bw / 1e9:.1f} GB/s")
    if "workers" in sections:
        print("ingest throughput against workers:")
        result["workers"] = section_workers(work, a.repeats)
    if "memory" in sections:
        print(f"peak memory against capture size (--memory {a.memory}):")
        result["memory"] = section_memory(work, a.memory)
    if "larger" in sections:
        print("a capture more than 10 times the memory budget:")
        result["larger"] = section_larger(work, a.larger_memory, a.larger_photos)
    if "goal" in sections:
        print("the goal: 64 photos at 2048^2 within 1 GiB:")
        g = section_goal(work)
        g["stream_bytes_per_s_over_copy_bandwidth"] = photos_bytes(64, 2048, 2) / g["streamed_s"] / bw
        result["goal"] = g
    if a.out:
        write_json(a.out, result)


if __name__ == "__main__":
    main()
