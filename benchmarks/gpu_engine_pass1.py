"""Pass 1 inside an Engine frame: its time against the light set, the number of lights and the image size.

Written to settle a question of the first H100 run (docs/gpu.md "On an NVIDIA H100"): an Engine
frame's pass 1 had taken 9.9-13.2 ms where the standalone ``CellIntegrator`` took 3.6 ms for the
same map. Each row builds an :class:`ffls.gpu.engine.Engine` (default technique, ``profile=True``)
on a random float32 basis, sets ``sky_sun_map(512)`` and renders ``--reps`` frames after one
warm-up, the map turned 5 degrees about +Z every frame; it prints the frame's GPU time (a
time-elapsed query), the median of the Engine's own per-pass timings, the wall clock at the row's
end and, for the light-set rows, the largest Voronoi cell of the lights in texels of the
1024 x 512 pass-1 map's upper hemisphere (the ``sort`` technique sums each cell serially). Where
``pynvml`` is importable, the SM clock is sampled every 5 ms during each row.

    python benchmarks/gpu_engine_pass1.py [--sets fib rand0 rand1] [--lights 256 1024]
                                          [--sizes 256 1024 2048] [--reps 41] [--out FILE.json]

Light sets: ``fib`` a Fibonacci hemisphere, ``randK`` the upper directions of
``gpu_passes.upper_directions`` with seed K. Light-set rows use 256^2 images; the size rows use
``rand0`` with the first ``--lights``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import threading
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
import gpu_passes as gp  # noqa: E402  (the same timer, directions and bases as gpu_passes.py)
from common import device_info, device_line, write_json  # noqa: E402

from ffls.conventions import rotation_z  # noqa: E402
from ffls.gpu.context import create_headless_context, is_software_renderer  # noqa: E402
from ffls.gpu.engine import Engine  # noqa: E402
from ffls.lightmaps.lightmap import sky_sun_map  # noqa: E402


def fibonacci_hemisphere(n: int) -> np.ndarray:
    """``n`` near-uniform directions on the upper hemisphere (a Fibonacci spiral in z)."""
    i = np.arange(n) + 0.5
    z = 1.0 - i / n
    r = np.sqrt(1.0 - z * z)
    a = np.pi * (3.0 - 5.0 ** 0.5) * i
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=1)


def light_set(name: str, n: int) -> np.ndarray:
    if name == "fib":
        return fibonacci_hemisphere(n)
    if name.startswith("rand") and name[4:].isdigit():
        return gp.upper_directions(np.random.default_rng(int(name[4:])), n)
    raise SystemExit(f"gpu_engine_pass1.py: error: --sets: unknown light set {name!r} (fib or randK)")


def largest_cell(d: np.ndarray, height: int = 512) -> int:
    """Texels of the upper hemisphere of a ``2 height x height`` lat-long map in the largest cell."""
    th = (np.arange(height) + 0.5) / height * np.pi
    ph = (np.arange(2 * height) + 0.5) / (2 * height) * 2.0 * np.pi
    t, p = np.meshgrid(th, ph, indexing="ij")
    tex = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    tex = tex[tex[:, 2] >= 0]
    return int(np.bincount(cKDTree(d).query(tex)[1], minlength=len(d)).max())


class ClockSampler:
    """The SM clock (MHz) every 5 ms while in a ``with`` block, through NVML; empty without it."""

    def __init__(self):
        try:
            import pynvml
            pynvml.nvmlInit()
            self._nvml, self._handle = pynvml, pynvml.nvmlDeviceGetHandleByIndex(0)
        except Exception:  # no NVIDIA driver or no pynvml: no clock column
            self._nvml = None
        self.samples: list[int] = []

    def __enter__(self):
        self.samples, self._stop = [], threading.Event()
        if self._nvml is not None:
            self._thread = threading.Thread(target=self._run, daemon=True)
            self._thread.start()
        return self

    def _run(self):
        while not self._stop.is_set():
            self.samples.append(self._nvml.nvmlDeviceGetClockInfo(self._handle, self._nvml.NVML_CLOCK_SM))
            time.sleep(0.005)

    def __exit__(self, *exc):
        self._stop.set()
        if self._nvml is not None:
            self._thread.join()


def frame_row(ctx, d: np.ndarray, size: int, reps: int, lm, clock: ClockSampler) -> dict:
    basis = gp.random_basis(np.random.default_rng(0), len(d), size, np.float32)
    eng = Engine(ctx, basis, d, "upper", budget_bytes=1 << 62)
    eng.set_lightmap(lm)
    per: dict[str, list[float]] = {}

    def setup(k):
        eng.set_rotation(rotation_z(5.0 * (k + 1)))
        if k > 1:  # frame k - 1's passes; frame 0 is the warm-up
            for name, v in eng.timings.items():
                per.setdefault(name, []).append(v)

    with clock:
        t = gp.timed(ctx, lambda: eng.render(0.0, "aces"), reps, setup=setup)
    eng.release()
    ctx.gc()
    row = {"n": len(d), "size": size, **t, "pass_ms": {k: float(statistics.median(v)) for k, v in per.items()},
           "time": time.strftime("%H:%M:%S")}
    if clock.samples:
        row["sm_clock_mhz"] = {"median": float(statistics.median(clock.samples)), "min": min(clock.samples),
                               "max": max(clock.samples)}
    return row


def row_line(label: str, row: dict) -> str:
    passes = "  ".join(f"{k} {v:.3f}" for k, v in row["pass_ms"].items())
    clk = row.get("sm_clock_mhz")
    clk = f"  SM clock {clk['median']:.0f} MHz ({clk['min']}-{clk['max']})" if clk else ""
    return f"{row['time']} {label} frame {row['ms']:8.3f} ms  {passes}{clk}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", nargs="+", default=["fib", "rand0", "rand1"])
    ap.add_argument("--lights", nargs="+", type=int, default=[256, 1024])
    ap.add_argument("--sizes", nargs="+", type=int, default=[256, 1024, 2048])
    ap.add_argument("--reps", type=int, default=41)
    ap.add_argument("--out", help="write the rows as JSON here")
    args = ap.parse_args(argv)
    if args.reps < 3 or min(args.lights) < 4 or min(args.sizes) < 8:
        ap.error("--reps must be >= 3, --lights >= 4 and --sizes >= 8")
    ctx = create_headless_context()
    info = device_info(ctx)
    gp.SOFTWARE = is_software_renderer(info["renderer"])
    print(device_line(info), flush=True)
    lm = sky_sun_map(512)
    clock = ClockSampler()
    rows = []
    for name in args.sets:
        for n in args.lights:
            d = light_set(name, n)
            row = {"set": name, "largest_cell_texels": largest_cell(d), **frame_row(ctx, d, 256, args.reps, lm, clock)}
            rows.append(row)
            print(row_line(f"{name:6s} N={n:5d} largest cell {row['largest_cell_texels']:6d} texels", row), flush=True)
    d = light_set("rand0", args.lights[0])
    for s in args.sizes:
        row = {"set": "rand0", **frame_row(ctx, d, s, args.reps, lm, clock)}
        rows.append(row)
        print(row_line(f"rand0  N={len(d):5d} {s:5d}^2", row), flush=True)
    if args.out:
        write_json(args.out, {"device": info, "command": " ".join(sys.argv), "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
