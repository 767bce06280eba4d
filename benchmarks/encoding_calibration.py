"""Encoding calibration from the spheres: recovered curve and light-direction error per true encoding.

Renders one linear capture of the built-in scene (``write_synthetic_capture``, noise free), then
stores it as integer PNGs encoded linear, sRGB, gamma 2.2 and (``--filmic``) a camera-like S-shaped
tone curve, :func:`ffls.synth.photo.filmic_encode`, that must be named ``polynomial`` (plus sensor-like noise of
``--noise`` code values added to the stored value), with no ``encoding`` in ``capture.json``. For
each it runs what ``ffls lights`` runs (:func:`ffls.commands.lights.calibrate_if_unknown`, then
:func:`ffls.spheres.estimate.estimate_lights`) and, as the reference, the same estimation with the
true encoding stated. Prints a table and writes JSON.

    OMP_NUM_THREADS=1 python benchmarks/encoding_calibration.py --res 512 --lights 40 --json out.json
    OMP_NUM_THREADS=1 python benchmarks/encoding_calibration.py --res 256 --lights 20 --repeat 10
    OMP_NUM_THREADS=1 python benchmarks/encoding_calibration.py --detect-scenes --lights 40
    OMP_NUM_THREADS=1 python benchmarks/encoding_calibration.py --res 384 --lights 40 --near 2

``--detect-scenes``: the captures are made without ``ffls synth`` (``tests/detect_scenes.py``: 3
grey balls on a grey background, 400 x 300 px, NumPy ray casting), stored as 8-bit PNGs in each
encoding; only the calibration (the curve named and the test line) is printed. ``--near D``: the
lights are 10 cm spheres D metres from the scene centre (as ``bench_lights.py``'s ``near_grey``),
whose direction and ``1/r^2`` vary over each sphere; the calibration's shading model (distant or
near, chosen by the BIC) is in the ``shading`` column.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ffls.commands.lights import calibrate_if_unknown
from ffls.errors import InputError
from ffls.io.capture import load_capture
from ffls.io.images import read_image, write_png
from ffls.radiance.encoding import gamma_encode, srgb_encode
from ffls.spheres.estimate import estimate_lights
from ffls.synth.photo import filmic_decode, filmic_encode, response_table
from ffls.synth.scene import write_synthetic_capture

TRUE = {"linear": "linear", "srgb": "srgb", "gamma2.2": 2.2}
STATED = {"linear": "linear", "srgb": "srgb", "gamma2.2": {"gamma": 2.2}, "filmic": {"response": "response.npy"}}
#: The curve each true encoding must be named.
EXPECTED = {"linear": "linear", "srgb": "srgb", "gamma2.2": "gamma", "filmic": "polynomial"}


def encode_values(lin: np.ndarray, true) -> np.ndarray:
    """Linear values in [0, 1] stored with the curve ``true``."""
    if true == "linear":
        return lin
    if true == "srgb":
        return srgb_encode(lin)
    if true == "filmic":
        return filmic_encode(lin)
    return gamma_encode(lin, true)


def stated(cap, name, bits: int = 8):
    """``cap`` with its true encoding stated (the filmic curve as its response table: 8-bit, or every
    16-bit code's :func:`ffls.synth.photo.filmic_decode`)."""
    if name == "filmic":
        table = response_table("filmic") if bits == 8 else filmic_decode(np.arange(65536) / 65535.0)
        return replace(cap, encoding=STATED[name], response=np.repeat(np.asarray(table)[:, None], 3, axis=1))
    return replace(cap, encoding=STATED[name])


def encode_capture(src: Path, dst: Path, true, bits: int, noise: float, seed: int) -> Path:
    """``src`` (linear EXR) stored as ``bits``-bit PNGs with the curve ``true``; no ``encoding`` key."""
    dst.mkdir()
    doc = json.loads((src / "capture.json").read_text())
    doc.pop("encoding")
    imgs = [read_image(src / nm).pixels.astype(np.float64) for nm in doc["images"]]
    exposure = 0.9 / max(float(np.percentile(im, 99.9)) for im in imgs)
    rng = np.random.default_rng(seed)
    top = 255 if bits == 8 else 65535
    names = []
    for nm, im in zip(doc["images"], imgs):
        lin = np.clip(im * exposure, 0.0, None)
        enc = encode_values(np.clip(lin, 0.0, 1.0), true)
        enc = enc + rng.normal(0.0, noise, enc.shape)
        png = nm.replace(".exr", ".png")
        write_png(dst / png, np.rint(np.clip(enc, 0, 1) * top).astype(np.uint8 if bits == 8 else np.uint16))
        names.append(png)
    doc["images"] = names
    (dst / "capture.json").write_text(json.dumps(doc))
    return dst


def errors_deg(lights, truth) -> np.ndarray:
    ok = lights.ok_mask
    cos = np.clip(np.sum(lights.directions * truth, axis=1), -1, 1)
    return np.degrees(np.arccos(cos))[ok]


def run_seed(args, seed: int) -> list:
    """The three true encodings of one rendered capture (light directions drawn with ``seed``)."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        light = {} if args.near is None else dict(light_model="near", light_distance=args.near, light_radius=0.05)
        info = write_synthetic_capture(tmp / "source", n_lights=args.lights, resolution=args.res, progress=False,
                                       seed=seed, **light)
        truth = info["directions"]
        for k, (name, true) in enumerate(curves(args).items()):
            folder = encode_capture(tmp / "source", tmp / name, true, args.bits, args.noise / 255, seed + k)
            cap = load_capture(folder)
            t0 = time.perf_counter()
            try:
                cal_cap, spheres, cal = calibrate_if_unknown(cap)
            except InputError as err:  # the calibration refused (one line asking for the encoding): a row saying so
                print(f"{name}: refused: {err}", flush=True)
                rows.append({"seed": seed, "true": name, "named": "refused", "summary": str(err)})
                continue
            t_cal = time.perf_counter() - t0
            got = estimate_lights(cal_cap, spheres=spheres, progress=False, workers=1)
            ref = estimate_lights(stated(cap, name, args.bits), spheres=spheres, progress=False, workers=1)
            e, r = errors_deg(got, truth), errors_deg(ref, truth)
            rows.append({"seed": seed, "true": name, "named": cal.curve, "gamma": cal.gamma,
                         "uncertainty": cal.uncertainty, "sd_spheres": cal.sd_spheres, "srgb_excess": cal.srgb_excess,
                         "linear_excess": cal.linear_excess, "bic_penalty": cal.bic_penalty,
                         "spheres": cal.n_spheres, "photos": cal.n_photos, "shading": cal.shading,
                         "order": cal.order, "polynomial_excess": cal.polynomial_excess,
                         "calibration_s": t_cal, "median_deg": float(np.median(e)), "max_deg": float(e.max()),
                         "accepted": int(got.ok_mask.sum()), "stated_median_deg": float(np.median(r)),
                         "stated_max_deg": float(r.max()), "summary": cal.summary()})
    return rows


def detect_scenes_naming(args) -> list:
    """The encoding named on captures made without ``ffls synth`` (``tests/detect_scenes.py``), per true curve."""
    from ffls.spheres.encoding import calibrate_capture_encoding

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    import detect_scenes as ds

    rows = []
    for seed in range(args.seed, args.seed + args.repeat):
        sc = ds.layout(3, shape=(300, 400), f=500.0, R=0.04, seed=seed)
        for b in sc.balls:
            b.albedo = (0.45, 0.45, 0.45)
        imgs = ds.render(sc, ds.lights(args.lights, seed=seed + 1), background="grey", noise=0.004, seed=seed + 2)
        imgs = np.clip(imgs / np.percentile(imgs, 99.5) * 0.9, 0, 1)
        for name, true in TRUE.items():  # not the filmic curve: the detection finds no sphere in it (docs/spheres.md)
            with tempfile.TemporaryDirectory() as tmp:
                tmp = Path(tmp)
                names = []
                for i, im in enumerate(imgs):
                    enc = encode_values(im, true)
                    names.append(f"p{i:02d}.png")
                    write_png(tmp / names[-1], np.rint(np.clip(enc, 0, 1) * 255).astype(np.uint8))
                (tmp / "capture.json").write_text(json.dumps({
                    "format": "ffls-capture", "version": 1, "images": names, "camera": {"K": sc.K.tolist()},
                    "sphere_radius": 0.04}))
                cal, _ = calibrate_capture_encoding(load_capture(tmp))
            rows.append({"seed": seed, "true": name, "named": cal.curve, "summary": cal.summary()})
            print(f"seed {seed} {name:9} -> {cal.summary()}", flush=True)
    return rows


def curves(args) -> dict:
    """The true encodings to store: linear, sRGB and gamma 2.2, and the filmic curve with ``--filmic``."""
    return {**TRUE, "filmic": "filmic"} if args.filmic else dict(TRUE)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--lights", type=int, default=40)
    ap.add_argument("--noise", type=float, default=1.0, help="noise sd in code values of 8 bits (default 1)")
    ap.add_argument("--bits", type=int, choices=(8, 16), default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=1, help="captures with seeds SEED, SEED+1, ... (coverage)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--near", type=float, default=None, metavar="D",
                    help="near lights (radius 5 cm) D metres from the scene centre instead of distant ones")
    ap.add_argument("--detect-scenes", action="store_true", help="captures made without ffls synth (naming only)")
    ap.add_argument("--filmic", action="store_true",
                    help="also store a camera-like S-shaped tone curve (ffls.synth.photo.filmic_encode), to be named "
                         "polynomial")
    args = ap.parse_args(argv)
    if args.detect_scenes:
        rows = detect_scenes_naming(args)
        right = sum(r["named"] == EXPECTED[r["true"]] for r in rows)
        print(f"named right {right}/{len(rows)}")
        if args.json:
            Path(args.json).write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1))
        return 0
    rows = []
    for seed in range(args.seed, args.seed + args.repeat):
        rows += run_seed(args, seed)
    print(f"{args.lights} lights, {args.res} px, {args.bits}-bit PNG, noise {args.noise} code values")
    print(f"{'true':9} {'named':10} {'gamma':>13} {'lin exc':>9} {'sRGB exc':>9} {'ln n_eff':>8} {'median':>7} {'max':>6} {'acc':>5} "
          f"{'stated med':>10} {'stated max':>10} {'cal s':>6} {'shading':>8}")
    for r in rows:
        if r["named"] == "refused":
            print(f"{r['true']:9} refused")
            continue
        named = r["named"] + (f" {r['order']}" if r["named"] == "polynomial" else "")
        print(f"{r['true']:9} {named:10} {r['gamma']:6.3f}+-{r['uncertainty']:.3f} {r['linear_excess']:9.1f} "
              f"{r['srgb_excess']:9.1f} {r['bic_penalty']:8.1f} "
              f"{r['median_deg']:7.2f} {r['max_deg']:6.2f} {r['accepted']:5d} {r['stated_median_deg']:10.2f} "
              f"{r['stated_max_deg']:10.2f} {r['calibration_s']:6.1f} {r['shading']:>8}")
    if args.repeat > 1:
        for name, g in (("linear", 1.0), ("srgb", None), ("gamma2.2", 2.2), ("filmic", None)):
            rs = [r for r in rows if r["true"] == name]
            if not rs:
                continue
            named = sum(r["named"] == EXPECTED[name] for r in rs)
            rs_cal = [r for r in rs if r["named"] != "refused"]
            inside = sum(abs(r["gamma"] - g) <= r["uncertainty"] for r in rs_cal) if g is not None else 0
            cover = "" if g is None else f", true gamma inside the 95% interval {inside}/{len(rs)}"
            print(f"{name}: named right {named}/{len(rs)}{cover}, median of medians "
                  f"{np.median([r['median_deg'] for r in rs_cal]) if rs_cal else float('nan'):.2f} deg")
    if args.json:
        Path(args.json).write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
