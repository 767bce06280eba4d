"""ABBA timing of ``ffls lights`` for two trees (or environments) A and B, on one capture.

Each round runs A B B A (then B A A B), each a new process ``ffls lights CAPTURE -o OUT
--no-progress [ARGS...]``: its wall time, its CPU (user + system of it and its worker processes)
and its main process's CPU; then the ratios B / A of the sums. A tree is named by environment
settings ``K=V,K=V`` (``PYTHONPATH=DIR`` of a ``git archive``; ``K=-`` unsets ``K``; ``PY=PATH``
another interpreter). The runs start in OUTDIR (a ``python -c`` puts its working directory first
on ``sys.path``: a checkout's ``ffls`` there would shadow ``PYTHONPATH``), where the lights.json of
every run is kept (compare them with ``cmp``).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/abba_lights.py ROUNDS CAPTURE OUTDIR \\
        PYTHONPATH=/tmp/a PYTHONPATH=/tmp/b -- --workers 2
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time

from common import MAIN_CPU  # benchmarks/common.py

def environment(spec: str) -> tuple[str, dict]:
    env, py = dict(os.environ, OMP_NUM_THREADS="1"), sys.executable
    for kv in filter(None, spec.split(",")):
        k, v = kv.split("=", 1)
        if k == "PY":
            py = v
        elif v == "-":
            env.pop(k, None)
        else:
            env[k] = v
    return py, env


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    cut = argv.index("--") if "--" in argv else len(argv)
    rounds, capture, outdir, a_spec, b_spec = argv[:cut]
    extra = argv[cut + 1:]
    capture, outdir = os.path.abspath(capture), os.path.abspath(outdir)
    os.makedirs(outdir, exist_ok=True)
    envs = {"A": environment(a_spec), "B": environment(b_spec)}
    order = [n for r in range(int(rounds)) for n in (("A", "B", "B", "A") if r % 2 == 0 else ("B", "A", "A", "B"))]
    runs = {"A": [], "B": []}
    for k, name in enumerate(order):
        py, env = envs[name]
        load = os.getloadavg()[0]
        before, t = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
        done = subprocess.run([py, "-c", MAIN_CPU, "lights", capture, "-o", os.path.join(outdir, f"{name}_{k}.json"),
                               "--no-progress", *extra], env=env, cwd=outdir, stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True)
        wall, after = time.perf_counter() - t, resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
        main_cpu = float(done.stdout.strip().splitlines()[-1].split()[-1]) if done.returncode == 0 else float("nan")
        runs[name].append({"wall_s": wall, "cpu_s": cpu, "main_cpu_s": main_cpu, "load": load})
        print(f"{name} wall {wall:6.2f} s, CPU {cpu:5.2f} s, main {main_cpu:5.2f} s, load {load:4.1f}, "
              f"status {done.returncode}", flush=True)
    sums = {n: {key: sum(r[key] for r in runs[n]) for key in ("wall_s", "cpu_s", "main_cpu_s")} for n in runs}
    for n in "AB":
        print(f"{n}: wall {sums[n]['wall_s']:.2f} s, CPU {sums[n]['cpu_s']:.2f} s, main {sums[n]['main_cpu_s']:.2f} s "
              f"(sums of {len(runs[n])} runs)")
    ratios = {key: sums["B"][key] / sums["A"][key] for key in sums["A"]}
    print("B / A, ratios of the sums: " + ", ".join(f"{k[:-2]} {v:.3f}" for k, v in ratios.items()))
    with open(os.path.join(outdir, "abba.json"), "w") as f:
        json.dump({"argv": argv, "runs": runs, "ratios": ratios}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
