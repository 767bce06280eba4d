"""The encoding calibration's CPU, and its every field at full precision, on captures that state no encoding.

For each capture: :func:`ffls.spheres.estimate.decode_photos` and the first sphere detection (on the
stored values, as ``ffls lights`` does), then :func:`ffls.spheres.encoding.calibrate_capture_encoding`
alone in this process (``workers=1``), timed by ``time.process_time``. Writes every field of the
:class:`ffls.spheres.encoding.EncodingCalibration` as its ``repr`` (full precision) and the CPU to
``OUT``; with ``--against OTHER.json`` (another tree's run) prints the fields that differ.

    OMP_NUM_THREADS=1 python benchmarks/calibration_cpu.py OUT.json CAPTURE [CAPTURE ...] [--against A.json]
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict, replace


def main(argv=None) -> int:
    from ffls.io.capture import load_capture
    from ffls.spheres.detect import find_spheres_in_capture
    from ffls.spheres.encoding import calibrate_capture_encoding
    from ffls.spheres.estimate import decode_photos

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("captures", nargs="+")
    ap.add_argument("--against", help="another run's OUT: print the fields that differ")
    args = ap.parse_args(argv)
    out = {}
    for path in args.captures:
        cap = load_capture(path)
        dec = decode_photos(cap, workers=1)
        spheres = find_spheres_in_capture(replace(cap, encoding="linear"), stats=dec.stats,
                                          bit_depths=dec.bit_depths, workers=1)
        c0 = time.process_time()
        cal, _ = calibrate_capture_encoding(cap, spheres=spheres, decoded=dec, workers=1)
        cpu = time.process_time() - c0
        out[path] = {"cpu_s": cpu, **{k: repr(v) for k, v in asdict(cal).items()}}
        print(f"{path}: {cpu:.2f} s CPU; {cal.summary()}", flush=True)
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    if args.against:
        with open(args.against) as f:
            other = json.load(f)
        for path, rec in out.items():
            for k, v in rec.items():
                if k != "cpu_s" and path in other and other[path].get(k) != v:
                    print(f"{path}: {k} {other[path].get(k)} -> {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
