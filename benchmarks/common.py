"""What every benchmark shares: timing, the device, the copy-bandwidth reference, JSON and tables.

The scripts run as ``python benchmarks/NAME.py`` (their folder is then on ``sys.path``) and
import these helpers with ``from common import ...``. Timings are the median of several runs
after a warm-up (docs/architecture.md, "Benchmarks"); GPU timings call ``ctx.finish()`` after
every run so that they include the work, not only its submission.
"""
from __future__ import annotations

import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from ffls.errors import atomic_output

__all__ = ["median_seconds", "median_ms", "numpy_copy_bandwidth", "gl_copy_bandwidth", "host_info", "device_info",
           "device_line", "write_json", "print_error_table"]


def median_seconds(fn, repeat: int = 5, warmup: int = 1, ctx=None) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeat`` runs after ``warmup`` runs.

    Parameters
    ----------
    fn : callable
    repeat, warmup : int
    ctx : moderngl.Context, optional
        ``ctx.finish()`` after every run (GPU work is timed to its end).
    """
    for _ in range(warmup):
        fn()
        if ctx is not None:
            ctx.finish()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        if ctx is not None:
            ctx.finish()
        ts.append(time.perf_counter() - t0)
    return float(statistics.median(ts))


def median_ms(fn, repeat: int = 5, warmup: int = 1, ctx=None) -> float:
    """:func:`median_seconds` in milliseconds."""
    return 1e3 * median_seconds(fn, repeat, warmup, ctx)


def numpy_copy_bandwidth(nbytes: int, repeat: int = 5, dtype=np.float32) -> float:
    """NumPy ``copyto`` bandwidth of ``nbytes`` buffers, bytes read + written per second."""
    x = np.ones(nbytes // np.dtype(dtype).itemsize, dtype)
    y = np.empty_like(x)
    return 2 * x.nbytes / median_seconds(lambda: np.copyto(y, x), repeat)


def gl_copy_bandwidth(ctx, nbytes: int, repeat: int = 5) -> float:
    """GPU ``copy_buffer`` bandwidth of ``nbytes`` buffers, bytes read + written per second."""
    a = ctx.buffer(reserve=nbytes)
    b = ctx.buffer(reserve=nbytes)
    try:
        return 2 * nbytes / median_seconds(lambda: ctx.copy_buffer(b, a), repeat, ctx=ctx)
    finally:
        a.release()
        b.release()


def host_info() -> dict:
    """``cpu_count`` and ``machine`` (the processor, else the architecture) of this computer."""
    return {"cpu_count": os.cpu_count(), "machine": platform.processor() or platform.machine()}


def device_info(ctx) -> dict:
    """:func:`ffls.gpu.context.describe_context` of ``ctx`` (renderer, GL version, limits) plus :func:`host_info`."""
    from ffls.gpu.context import describe_context

    return {**describe_context(ctx), **host_info()}


def device_line(info: dict) -> str:
    """``device: <renderer> | GL <version> | <n> CPUs``, the first line every GPU benchmark prints."""
    return f"device: {info['renderer']} | GL {info['version']} | {info['cpu_count']} CPUs"


def write_json(path, doc, indent: int = 1, quiet: bool = False) -> Path:
    """Write a benchmark's results atomically (creating the folder) and say where (unless ``quiet``)."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(out) as t:
        Path(t).write_text(json.dumps(doc, indent=indent))
    if not quiet:
        print(f"wrote {out}")
    return out


#: ``python -c`` program: ``ffls ARGS`` (``sys.argv[1:]``), then the CPU seconds (user + system) of
#: this, the command's main process, printed as the last line (its last word the number).
MAIN_CPU = ("import resource, sys; from ffls.cli import main; rc = main(sys.argv[1:]); "
            "u = resource.getrusage(resource.RUSAGE_SELF); print('main process CPU s', u.ru_utime + u.ru_stime); "
            "sys.exit(rc)")


def set_probe_sphere(folder, sphere) -> None:
    """Replace the ``sphere`` of ``folder/probe.json`` (a benchmark's hint or material)."""
    doc = json.loads((Path(folder) / "probe.json").read_text())
    doc["sphere"] = sphere
    (Path(folder) / "probe.json").write_text(json.dumps(doc))


def cached_capture(folder, directions, render) -> dict:
    """The ``truth.json`` of a synthetic capture in ``folder`` under ``directions`` (n, 3).

    Calls ``render(folder)`` when the folder holds no capture yet (no ``--cache``, or a new one);
    a cached capture of other directions stops the benchmark (remove it or use another cache).
    """
    folder = Path(folder)
    truth_file = folder / "truth.json"
    if truth_file.exists():
        old = np.asarray(json.loads(truth_file.read_text())["directions"])
        if old.shape != np.shape(directions) or not np.allclose(old, directions, atol=1e-9):
            raise SystemExit(f"{folder} holds another grid; remove it or use another --cache")
    else:
        render(folder)
    return json.loads(truth_file.read_text())


def probe_benchmark_capture(prefix: str):
    """The capture the probe benchmarks relight under recovered and true maps: ``ffls synth`` with
    150 distant lights at 64 px (seed 1), written to a new temporary folder named with ``prefix``.

    Returns ``(capture, lights)``. The capture's photos are read from the folder as the benchmark
    goes, and the folder is removed when the interpreter exits (it was left in /tmp).
    """
    import atexit
    import shutil
    import tempfile

    from ffls.io.capture import load_capture_and_lights
    from ffls.synth.scene import write_synthetic_capture

    tmp = Path(tempfile.mkdtemp(prefix=prefix))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    write_synthetic_capture(tmp / "cap", n_lights=150, resolution=64, progress=False, seed=1)
    return load_capture_and_lights(tmp / "cap")


def probe_benchmark_map(name: str, height: int, capture, lights):
    """A bundled light map at ``height`` rows, as the probe benchmarks use it as the truth.

    Returns ``(lightmap, radiance, truth)``: the downsampled ``LightMap``, its lat-long radiance
    as float64, and ``capture`` relit (CPU) under it, as float64.
    """
    from ffls.lightmaps.lightmap import builtin_lightmap
    from ffls.relight.cpu import relight_capture

    lm = builtin_lightmap(name)
    lm = lm.downsample(lm.res // height)
    return lm, np.asarray(lm.data, dtype=np.float64), relight_capture(capture, lights, lm)[0].astype(np.float64)


def noisy_diffuse_probes(maps, height: int, capture, lights, conditions: str):
    """The POCS benchmarks' scenes: per map of ``maps`` and per ``noise:seed`` pair of ``conditions``
    (comma-separated), the map's name, :func:`probe_benchmark_map`'s ``(lightmap, radiance, truth)``,
    the 80 px diffuse ball (albedo 0.7) under it, the noise, the seed, and the ball's radiance with
    Gaussian noise of ``noise`` times its mean added (seeded by ``seed``; none where ``noise`` is 0)."""
    from ffls.synth.probe_scenes import diffuse_sphere_scene

    pairs = [(float(x.split(":")[0]), int(x.split(":")[1])) for x in conditions.split(",") if x]
    for name in maps:
        truth = probe_benchmark_map(name, height, capture, lights)
        sph = diffuse_sphere_scene(truth[0], 80, albedo=0.7, world_from_camera=capture.world_from_camera)
        for noise, seed in pairs:
            yield name, truth, sph, noise, seed, with_noise(sph.radiance, noise, np.random.default_rng(seed))


def with_noise(radiance, noise: float, rng):
    """``radiance`` with Gaussian noise of ``noise`` times its mean added, drawn from ``rng`` (the
    probe benchmarks' noise); ``radiance`` itself, and no draw, where ``noise`` is 0."""
    if noise > 0:
        return radiance + rng.normal(0.0, noise * float(np.mean(radiance)), size=radiance.shape)
    return radiance


def diffuse_ball(lightmap, capture, noise: float, rng):
    """The probe benchmarks' 80 px diffuse ball (albedo 0.7) under ``lightmap``, seen as ``capture``'s
    camera sees it, and its radiance with :func:`with_noise`. Returns ``(scene, radiance)``."""
    from ffls.synth.probe_scenes import diffuse_sphere_scene

    sph = diffuse_sphere_scene(lightmap, 80, albedo=0.7, world_from_camera=capture.world_from_camera)
    return sph, with_noise(sph.radiance, noise, rng)


def probe_benchmark_args(doc: str, maps, argv=None):
    """The arguments shared by the probe benchmarks that loop over maps: ``--noise`` (Gaussian,
    as a fraction of the image's mean), ``--maps`` (comma-separated, default ``maps``) and ``--json``."""
    import argparse

    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--noise", type=float, default=0.0, help="Gaussian noise, as a fraction of the image's mean")
    ap.add_argument("--maps", default=",".join(maps))
    ap.add_argument("--json", default=None)
    return ap.parse_args(argv)


def relit_capture_error(capture, lights, latlong, truth) -> float:
    """Relative RMS error of ``capture`` relit (CPU) under the lat-long radiance ``latlong`` against
    ``truth`` (the float64 image relit under the true map), over the truth's lit pixels."""
    from ffls.probes.sources import to_lightmap
    from ffls.relight.cpu import relight_capture

    img = relight_capture(capture, lights, to_lightmap(latlong)[0])[0].astype(np.float64)
    lit = truth.sum(-1) > 0
    return float(np.sqrt(((img - truth) ** 2)[lit].sum() / (truth ** 2)[lit].sum()))


def print_error_table(errors_deg, phis, thetas) -> None:
    """Print per-light errors (degrees; None = rejected) as a Markdown table, phi rows x theta columns."""
    print("| phi \\ theta | " + " | ".join(f"{t:.0f}" for t in thetas) + " |")
    print("|---" * (len(thetas) + 1) + "|")
    e = np.array([np.nan if x is None else x for x in errors_deg]).reshape(len(phis), len(thetas))
    for p_, row in zip(phis, e):
        print(f"| {p_:.0f} | " + " | ".join("rej" if np.isnan(x) else f"{x:.2f}" for x in row) + " |")


def mitsuba_latlong_module():
    """``scripts/mitsuba_latlong.py`` (its ``latlong_sensor``, ``register``, ``ENVMAP_TO_WORLD``),
    loaded from its file: the Mitsuba benchmarks' lat-long sensor and envmap frame."""
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "scripts" / "mitsuba_latlong.py"
    spec = importlib.util.spec_from_file_location("mitsuba_latlong", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod

