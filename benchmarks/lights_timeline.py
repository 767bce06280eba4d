"""Where the wall time of ``ffls lights`` goes: a timeline of its stages and of each process's CPU.

Runs ``ffls lights CAPTURE -o OUT --no-progress [ARGS...]`` in this process (``ffls.cli.main``)
with the pipeline's stages wrapped: each call records its ``time.perf_counter`` start and end and
this (the main) process's CPU over it. A sampler thread reads every process's CPU (the main one
and its worker processes, from /proc) every ``--every`` seconds, so each stage also shows the
workers' CPU over it and the main process's CPU *alone*: in the samples where no worker process
ran (grew its CPU by at least a tenth of the sample). That part is serial: on idle cores it is
wall time with one core unused, except where the main process runs threads of its own (the Hough
transforms). CPU is inflated by a loaded machine's contention much less than the wall is.

    OMP_NUM_THREADS=1 python benchmarks/lights_timeline.py CAPTURE --out T.json -- --workers 2

Prints one line per stage call (start, wall, main CPU, workers' CPU, main CPU alone; nested calls
indented; the Hough transforms run in two threads of the main process), then the run's totals:
wall, the main process's CPU (and its CPU before the first stage: the imports and the
arguments), the workers' CPU, the main CPU alone, and the wall spent with 0, 1, 2 or more
processes busy (busy: its CPU grew by at least half the sample's length; on a loaded machine few
are), and writes them with the samples to ``--out``.
"""
from __future__ import annotations

import argparse
import functools
import importlib
import json
import os
import sys
import threading
import time
from pathlib import Path

#: ``module: [function or Class.method, ...]`` wrapped as stages (a name missing on this tree is
#: skipped: the tool runs on older trees too).
STAGES = {
    "ffls.io.capture": ["load_capture", "save_lights"],
    "ffls.spheres.estimate": ["decode_photos", "estimate_lights", "capture_samples", "sphere_views",
                              "PhotoFitter.run", "PhotoFitter.map", "PhotoFitter.close",
                              "refine_sphere_centres", "calibrate_flat_field", "calibrate_bounce",
                              "calibrate_bounce_shape", "calibrate_uncertainty", "place_at_capture_range",
                              "reject_shadowed_photos", "sphere_kinds"],
    "ffls.spheres.detect": ["find_spheres_in_capture", "find_spheres", "SequenceAccumulator.result",
                            "_max_luminance", "edge_map", "ConsistentEdges.of", "shading_ratio",
                            "hough_circle_candidates", "fit_candidates", "_with_outer_outlines",
                            "_photo_edge_fits", "_hough_candidates_many", "_forked_map",
                            "_with_consistent_edges", "select_spheres", "_grown_on_changing_edges",
                            "_with_changing_edges", "mirror_outlines_replaced", "with_max_image_rings",
                            "_refine_on_profiles", "_pixel_noise"],
    "ffls.commands.lights": ["calibrate_if_unknown", "summary"],
    "ffls.weights.voronoi": ["coverage_warnings"],
}

_t0 = _cpu_start = 0.0
first_cpu = None  # the main process's CPU when the first stage began
_calls: list[dict] = []
_depth = threading.local()


def _wrap(fn, name):
    @functools.wraps(fn)
    def timed(*a, **k):
        global first_cpu
        if first_cpu is None:
            first_cpu = time.process_time() - _cpu_start
        d = getattr(_depth, "n", 0)
        _depth.n = d + 1
        row = {"stage": name, "depth": d, "start": time.perf_counter() - _t0, "cpu0": time.process_time()}
        _calls.append(row)
        try:
            return fn(*a, **k)
        finally:
            row["end"] = time.perf_counter() - _t0
            row["main_cpu"] = time.process_time() - row.pop("cpu0")
            _depth.n = d
    return timed


def install() -> list[str]:
    """Wrap :data:`STAGES`; returns the names wrapped."""
    done = []
    for mod, names in STAGES.items():
        try:
            m = importlib.import_module(mod)
        except ImportError:
            continue
        for name in names:
            owner, attr = (m, name) if "." not in name else (getattr(m, name.split(".")[0], None), name.split(".")[1])
            if owner is None or not hasattr(owner, attr):
                continue
            raw = owner.__dict__.get(attr) if isinstance(owner, type) else None
            if isinstance(raw, classmethod):  # (wrapped as the function it binds)
                setattr(owner, attr, classmethod(_wrap(raw.__func__, name)))
            else:
                setattr(owner, attr, _wrap(getattr(owner, attr), name))
            done.append(f"{mod}.{name}")
    return done


def _cpu_of(pid: int) -> float | None:
    """User + system CPU seconds of process ``pid`` (its threads included), None when gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / _TICKS


def _children(pid: int) -> list[int]:
    """``pid``'s child processes (any of its threads' children), from /proc."""
    out = []
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for t in tasks:
        try:
            with open(f"/proc/{pid}/task/{t}/children") as f:
                out += [int(x) for x in f.read().split()]
        except OSError:
            pass
    return out


_TICKS = os.sysconf("SC_CLK_TCK")


class Sampler(threading.Thread):
    """Every ``every`` seconds: each process's CPU (user + system), the main one and its children
    (read from /proc: a scan of every process, as psutil's children() makes, costs the main
    process more than the stages it measures)."""

    def __init__(self, every: float):
        super().__init__(daemon=True)
        self.every, self.me = every, os.getpid()
        self.samples: list[tuple] = []  # (t, main CPU, {pid: CPU})
        self.seen: dict = {}
        self.stop = threading.Event()

    def read(self):
        t = time.perf_counter() - _t0
        main = _cpu_of(self.me)
        todo = _children(self.me)
        while todo:
            pid = todo.pop()
            c = _cpu_of(pid)
            if c is not None:
                self.seen[pid] = c
                todo += _children(pid)
        self.samples.append((t, main, dict(self.seen)))

    def run(self):
        while not self.stop.wait(self.every):
            self.read()


def busy_profile(samples, every: float) -> dict:
    """Wall seconds with 0, 1, 2, ... processes busy, and each sample's busy count."""
    hist, marks = {}, []
    for (t0, m0, k0), (t1, m1, k1) in zip(samples, samples[1:]):
        dt = t1 - t0
        busy = int(m1 - m0 >= 0.5 * dt) + sum(int(v - k0.get(p, 0.0) >= 0.5 * dt) for p, v in k1.items())
        hist[busy] = hist.get(busy, 0.0) + dt
        marks.append((round(t1, 3), busy, int(m1 - m0 >= 0.5 * dt)))
    return {"seconds_with_n_busy": {str(k): round(v, 3) for k, v in sorted(hist.items())}, "marks": marks}


def main_alone(samples, a: float = -1.0, b: float = float("inf"), share: float = 0.1) -> float:
    """The main process's CPU in the samples between wall times ``a`` and ``b`` where no worker
    process grew its CPU by ``share`` of the sample's length."""
    out = 0.0
    for (t0, m0, k0), (t1, m1, k1) in zip(samples, samples[1:]):
        if a <= t0 < b and not any(v - k0.get(p, 0.0) >= share * (t1 - t0) for p, v in k1.items()):
            out += m1 - m0
    return out


def workers_cpu(samples, a: float, b: float) -> float:
    """The children's CPU grown between wall times ``a`` and ``b`` (nearest samples)."""
    def at(t):
        best = min(samples, key=lambda s: abs(s[0] - t))
        return sum(best[2].values())
    return at(b) - at(a)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture")
    ap.add_argument("--out", default=None, help="timeline JSON to write")
    ap.add_argument("--lights-out", default=None, help="lights.json to write (default: a temporary file)")
    ap.add_argument("--every", type=float, default=0.02, help="sampling period, s (default 0.02)")
    argv = sys.argv[1:] if argv is None else list(argv)
    cut = argv.index("--") if "--" in argv else len(argv)
    a = ap.parse_args(argv[:cut])
    a.rest = argv[cut + 1:]  # (more arguments of ffls lights, after --)
    global _t0, _cpu_start
    _t0, _cpu_start = time.perf_counter(), time.process_time()
    cpu_start = _cpu_start
    from ffls import cli  # (the imports are part of the run, as a user's command has them)

    wrapped = install()
    out = a.lights_out or os.path.join(os.environ.get("TMPDIR", "/tmp"), f"timeline_{os.getpid()}.json")
    sampler = Sampler(a.every)
    sampler.read()
    sampler.start()
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = cli.main(["lights", a.capture, "-o", out, "--no-progress", *a.rest])
    wall = time.perf_counter() - _t0
    sampler.stop.set()
    sampler.join()
    sampler.read()
    import resource

    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    main_cpu = time.process_time() - cpu_start
    s = sampler.samples
    print(f"{'stage':44s} {'start':>7s} {'wall':>7s} {'main':>7s} {'workers':>8s} {'alone':>6s}")
    print(f"{'(before: the imports, the arguments)':44s} {0:7.2f} {_calls[0]['start']:7.2f} {first_cpu:7.2f}")
    for r in _calls:
        if "end" not in r:
            continue
        w = workers_cpu(s, r["start"], r["end"])
        r["workers_cpu"], r["main_alone_cpu"] = w, main_alone(s, r["start"], r["end"])
        print(f"{'  ' * r['depth'] + r['stage']:44s} {r['start']:7.2f} {r['end'] - r['start']:7.2f} "
              f"{r['main_cpu']:7.2f} {w:8.2f} {r['main_alone_cpu']:6.2f}")
    prof = busy_profile(s, a.every)
    total = {"wall_s": wall, "main_cpu_s": main_cpu, "main_cpu_before_stages_s": first_cpu, "workers_cpu_s": kids.ru_utime + kids.ru_stime,
             "main_alone_cpu_s": main_alone(s),
             "processes": len(s[-1][2]) + 1, "rc": rc, **{k: v for k, v in prof.items() if k != "marks"}}
    print(f"wall {wall:.2f} s; CPU: main {main_cpu:.2f} s (before the stages {first_cpu:.2f}, alone "
          f"{total['main_alone_cpu_s']:.2f}), workers {total['workers_cpu_s']:.2f} s "
          f"({total['processes'] - 1} worker processes); wall with N processes busy: "
          + ", ".join(f"{k}: {v:.2f} s" for k, v in prof["seconds_with_n_busy"].items())
          + f"; load {os.getloadavg()[0]:.1f}")
    if a.out:
        Path(a.out).write_text(json.dumps({"argv": sys.argv[1:], "wrapped": wrapped, "totals": total,
                                           "stages": [r for r in _calls if "end" in r], "busy": prof["marks"],
                                           "samples": [(t, m, sum(k.values())) for t, m, k in s]}, indent=1))
    if not a.lights_out:
        Path(out).unlink(missing_ok=True)
    return rc


if __name__ == "__main__":
    sys.exit(main())
