"""Temporal flicker of each weighting scheme under a slowly rotating map with a sun (issue 12).

Usage::

    python benchmarks/flicker.py [--lights 120] [--res 48] [--frames 120] [--step 1] [--map-height 256]
                                 [--texture-res 0] [--json benchmarks/results/flicker.json]

A synthetic capture (``ffls.synth``: the default scene, ``--lights`` stratified upper-hemisphere
directions, ``--res`` pixels) is relit under ``sky_sun_map`` (a 1-degree sun, 40 degrees up)
rotated about +Z in ``--step``-degree steps over ``--frames`` frames, with every scheme
(``ALL_SCHEMES``, ``spline`` included; the library-only ``kriging`` with its kernel learnt from the
basis photos by leave-one-out, ``ffls.weights.kriging.fit_kernel``)
(``ffls.weights.weighting.integrate``: the exact float64 weights, or with ``--texture-res R`` the
baked weight texture the GPU reads). The measure (:func:`flicker`) is the RMS over frames and
pixels of the second difference ``I[t+1] - 2 I[t] + I[t-1]`` over the RMS of the images: a box
filter pops whenever the sun crosses a cell border, a smooth scheme bends. Prints a table
(flicker, and its ratio to voronoi's) and writes JSON.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from ffls.conventions import rotation_z
from ffls.lightmaps.lightmap import sky_sun_map
from ffls.relight.cpu import relight_fast
from ffls.weights.weighting import ALL_SCHEMES, Weighting, bake_weights, integrate

__all__ = ["flicker", "rotation_frames", "scheme_flicker", "synthetic_basis"]


def flicker(frames) -> float:
    """Temporal flicker of a frame sequence.

    Parameters
    ----------
    frames : (T, H, W, 3) array_like, T >= 3

    Returns
    -------
    float
        ``rms(I[t+1] - 2 I[t] + I[t-1]) / rms(I)`` over all frames, pixels and channels
        (0 for a sequence that changes linearly in time; 0 for an all-zero sequence).
    """
    f = np.asarray(frames, dtype=np.float64)
    if f.ndim < 2 or f.shape[0] < 3:
        raise ValueError("flicker needs at least 3 frames")
    d2 = f[2:] - 2.0 * f[1:-1] + f[:-2]
    rms = np.sqrt(np.mean(f * f))
    return float(np.sqrt(np.mean(d2 * d2)) / rms) if rms > 0 else 0.0


def rotation_frames(basis, directions, lightmap, scheme: str, angles_deg, hemisphere="upper",
                    texture_res: int | None = None, **options) -> np.ndarray:
    """Relit frames ``(T, H, W, 3)`` float32 of ``lightmap`` rotated about +Z by each angle (degrees)."""
    if texture_res:
        tex = bake_weights(directions, scheme, hemisphere, res=texture_res, **options)
        kw = {"texture": tex}
    elif scheme != "voronoi":
        kw = {"weighting": Weighting(directions, scheme, hemisphere, **options)}
    else:
        kw = {}
    samples = lightmap.samples() if hasattr(lightmap, "samples") else lightmap
    out = []
    for a in angles_deg:
        w = integrate(samples, directions, rotation_z(float(a)), hemisphere, scheme, **kw, **options).weights
        out.append(relight_fast(w, basis))
    return np.stack(out)


def scheme_flicker(basis, directions, lightmap, schemes=ALL_SCHEMES, frames: int = 120, step_deg: float = 1.0,
                   start_deg: float = 0.0, hemisphere="upper", texture_res: int | None = None,
                   options: dict | None = None) -> dict:
    """:func:`flicker` of every scheme for a rotation in ``step_deg`` steps; ``{scheme: value}``.

    ``options``: ``{scheme: {option: value}}`` for the schemes that take some (e.g. ``kriging``'s
    fitted kernel).
    """
    angles = start_deg + step_deg * np.arange(int(frames))
    options = options or {}
    return {s: flicker(rotation_frames(basis, directions, lightmap, s, angles, hemisphere, texture_res,
                                       **options.get(s, {})))
            for s in schemes}


def synthetic_basis(n_lights: int, res: int, seed: int = 0):
    """Basis ``(n, res, res, 3)`` float32 and directions ``(n, 3)`` of the default synthetic scene."""
    from ffls.synth.scene import make_scene, render_lights, stratified_directions

    d = stratified_directions(int(n_lights), "upper", seed=seed)
    return render_lights(make_scene(), int(res), d), d


def main(argv=None) -> int:
    from common import host_info, write_json  # benchmarks/common.py

    ap = argparse.ArgumentParser()
    ap.add_argument("--lights", type=int, default=120)
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--step", type=float, default=1.0)
    ap.add_argument("--map-height", type=int, default=256)
    ap.add_argument("--sun-elevation", type=float, default=40.0)
    ap.add_argument("--texture-res", type=int, default=0, help="0: exact weights; R: the GPU's baked texture")
    ap.add_argument("--json", default="benchmarks/results/flicker.json")
    args = ap.parse_args(argv)
    basis, d = synthetic_basis(args.lights, args.res)
    el = np.radians(args.sun_elevation)
    lm = sky_sun_map(args.map_height, sun_direction=(np.cos(el), 0.0, np.sin(el)))
    from ffls.weights.kriging import fit_kernel

    fit = fit_kernel(d, basis)
    t0 = time.perf_counter()
    res = scheme_flicker(basis, d, lm, frames=args.frames, step_deg=args.step, texture_res=args.texture_res or None,
                         options={"kriging": fit.options})
    dt = time.perf_counter() - t0
    print(f"{args.lights} lights, {args.res}^2, sky_sun_map({args.map_height}) sun at {args.sun_elevation:g} deg, "
          f"{args.frames} frames of {args.step:g} deg, weights {'texture ' + str(args.texture_res) if args.texture_res else 'exact'} "
          f"({dt:.0f} s)")
    print(f"{'scheme':>12} {'flicker':>10} {'voronoi / scheme':>17}")
    for s, v in res.items():
        print(f"{s:>12} {v:>10.3e} {res['voronoi'] / v if v > 0 else float('inf'):>17.1f}")
    write_json(args.json, {"args": vars(args), "host": host_info(), "flicker": res, "kriging": fit.options,
                           "ratio_to_voronoi": {s: res["voronoi"] / v if v > 0 else None for s, v in res.items()}})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
