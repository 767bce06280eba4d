"""Light estimation under the conditions of real photographs: error, acceptance and 95% cone coverage.

For each condition (an exact ``ffls synth`` flag list) the paper's Table 1 grid of lights
(:func:`bench_lights.grid`: phi 0..180 in 20-degree steps, theta 0..70 in 10-degree steps, 80
lights) is rendered with :mod:`ffls.synth`, and the real command runs on it as a user would run
it: ``ffls lights CAPTURE --workers 1`` with no hints, no sphere count and (for the "unstated"
conditions) no encoding. The table gives, against ``truth.json``:

* accepted photos / all, and the rejection reasons;
* the median and maximum angular error of the accepted photos (degrees);
* the coverage: the share of accepted photos whose error is within their reported
  ``uncertainty_deg`` (the radius of the 95% cone; the goal is 90-98%), and the median cone;
* the mean signed elevation error of the accepted photos (estimated minus true elevation above
  the world's horizontal plane, degrees): an error shared by all spheres and photos, such as a
  ground bounce that the model under- or over-states, shows here;
* the encoding ``ffls lights`` reported (calibrated when the capture states none);
* the time per photo of ``ffls lights`` (one process; detection, calibration and both passes);
* the cone budget (:func:`cone_budget`): the median per-axis terms of the cones (fit, centre,
  floor, common-mode bound and floor, :meth:`ffls.spheres.uncertainty.ErrorModel.budget` with the
  combination's weights) and the cone factor, against the photos' per-axis RMS error and the
  factor 95% coverage would need, and the coverage with each part left out: which term makes a
  condition's cones too wide or too narrow.

A condition that makes ``ffls lights`` stop gets its one-line error in the table. Prints a
Markdown table (for docs/spheres.md) and writes JSON.

    python benchmarks/bench_conditions.py [--res 512] [--only NAME ...] [--cache DIR] [--out FILE]

With ``--shared-check`` (and a ``--cache`` of earlier runs) the capture's shared, fitted parameters
(the calibrated encoding's exponent, the spheres' ground ratios) are propagated to each photo's
direction by their standard errors (:func:`shared_check`, a GUM type-B propagation) and set
against the photos' actual errors: how much of the common error they could explain.

With ``--truth-check`` (and a ``--cache`` of earlier runs) each part of the stored runs' cones is set
against the renders' truth (:func:`truth_check`): the spheres' errors and their correlation within
photos, the photos' errors against the independent-sphere part and the common-mode bound, the cone
factor against the one 95% coverage needs, each sphere against its own cone, and beside them what
the capture measures itself (the disagreement, the shading fits' misfit, the common mode's share);
``--folders`` runs it on other captures than the cache's.

With ``--recalibrate`` (and a ``--cache`` of earlier runs) no ``ffls lights`` runs: the cones of
each stored run are made again by the current error model from the photo estimates it recorded
(:func:`recalibrate`): a cone-only change measured in seconds instead of a full run.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from ffls.cli import build_parser, main as ffls_main
from ffls.commands.synth import photo_settings, scene_of
from ffls.conventions import angle_between
from ffls.synth.scene import write_synthetic_capture

from bench_lights import grid  # benchmarks/bench_lights.py
from common import cached_capture, host_info, write_json  # benchmarks/common.py

#: name -> ``ffls synth OUT`` flags (the lights are the Table 1 grid).
CONDITIONS = {
    "4 white, grey ground, EXR": [],
    "4 white, near 10 cm light at 2 m": ["--near", "2", "--light-radius", "0.05"],
    "sRGB 8-bit, unstated": ["--format", "png8", "--encoding", "srgb", "--unstated-encoding", "--exposure", "3"],
    "linear 8-bit, unstated": ["--format", "png8", "--encoding", "linear", "--unstated-encoding", "--exposure", "3"],
    "gamma 2.2 8-bit, unstated": ["--format", "png8", "--encoding", "gamma2.2", "--unstated-encoding",
                                  "--exposure", "3"],
    "sRGB 16-bit TIFF, unstated": ["--format", "tiff16", "--encoding", "srgb", "--unstated-encoding",
                                   "--exposure", "3"],
    "JPEG q85, sRGB stated": ["--format", "jpeg", "--jpeg-quality", "85", "--encoding", "srgb", "--exposure", "3"],
    "noise + vignetting, 8-bit sRGB": ["--format", "png8", "--encoding", "srgb", "--exposure", "3",
                                       "--shot-noise", "1e-4", "--read-noise", "0.002", "--vignetting", "cos4"],
    "one grey sphere, 8-bit linear unstated": ["--spheres", "1", "--sphere-material", "grey", "--format", "png8",
                                               "--encoding", "linear", "--unstated-encoding", "--exposure", "3"],
    "one mirror ball, 8-bit sRGB": ["--spheres", "1", "--sphere-material", "mirror", "--format", "png8",
                                    "--encoding", "srgb", "--exposure", "3"],
    "one glossy black ball, 8-bit sRGB": ["--spheres", "1", "--sphere-material", "glossy_black", "--format", "png8",
                                          "--encoding", "srgb", "--exposure", "3"],
    "8 mixed spheres": ["--spheres", "8", "--sphere-material", "mixed"],
    "black background": ["--background", "black"],
    "white background": ["--background", "white"],
    "textured background": ["--background", "textured"],
    "long lens (10 m, 4.8 deg)": ["--lens", "long"],
    "orthographic": ["--lens", "orthographic"],
    "calibration shot: grey + mirror, no object": ["--no-object", "--spheres", "2", "--sphere-material", "grey,mirror"],
    # appended (the cache folders are numbered by position; each records its condition: check_cached_condition)
    "one mirror ball, textured ground": ["--spheres", "1", "--sphere-material", "mirror", "--background", "textured"],
    # the spheres on one side of the object: their errors (each away from the object) add in the
    # photo's mean instead of cancelling as on the ring (docs/spheres.md, "The cones too wide")
    "4 white in a row in front of the object": ["--sphere-xy=-0.3,-0.25;-0.1,-0.25;0.1,-0.25;0.3,-0.25"],
    # each pixel integrated as a camera's is (3 x 3 rays), not one ray through its centre: the
    # outlines' anti-aliased steps of real photographs (docs/spheres.md, the blurred photos' step and
    # the chrome outline on an anti-aliased limb)
    "4 white, anti-aliased (3x3 rays a pixel), 8-bit sRGB": ["--supersample", "3", "--format", "png8", "--encoding",
                                                            "srgb", "--exposure", "3"],
    "one mirror ball, anti-aliased (3x3 rays a pixel), 8-bit sRGB": ["--supersample", "3", "--spheres", "1",
                                                                    "--sphere-material", "mirror", "--format",
                                                                    "png8", "--encoding", "srgb", "--exposure", "3"],
}


#: name -> (balls, background, stored curve, file type) of a capture made WITHOUT ffls synth:
#: ``tests/detect_scenes.py`` (NumPy ray casting; grey matte balls of albedo 0.45 in front of a
#: lit background plane, 40 lights, 400 x 300 px, noise 0.004, 8-bit, encoding unstated).
SCENES = {
    "ds: 1 ball, textured background, linear PNG": (1, "texture", "linear", "png"),
    "ds: 2 balls, white background, linear PNG": (2, "white", "linear", "png"),
    "ds: 3 balls, black background, gamma-2.2 JPEG": (3, "black", "gamma", "jpg"),
    "ds: 3 balls, grey background, linear JPEG": (3, "grey", "linear", "jpg"),
    "ds: 3 balls, grey background, gamma-2.2 PNG": (3, "grey", "gamma", "png"),
}


def scene_directions() -> np.ndarray:
    """The 40 world light directions of the :data:`SCENES` captures."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import detect_scenes as ds
    from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA

    return (DEFAULT_WORLD_FROM_CAMERA[:3, :3] @ ds.lights(40, seed=1).T).T


def render_scene(folder: Path, spec: tuple) -> None:
    """A :data:`SCENES` capture, rendered by ``tests/detect_scenes.py`` (not ffls synth)."""
    import sys

    import cv2

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import detect_scenes as ds
    from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA

    n_balls, background, curve, ext = spec
    folder.mkdir(parents=True, exist_ok=True)
    sc = ds.layout(n_balls, shape=(300, 400), f=500.0, R=0.04, seed=3)
    for b in sc.balls:
        b.albedo = (0.45, 0.45, 0.45)
    imgs = ds.render(sc, ds.lights(40, seed=1), background=background, noise=0.004, seed=2)
    imgs = imgs / np.percentile(imgs, 99.5) * 0.9
    names = []
    for i, im in enumerate(imgs):
        v = np.clip(im, 0, 1) ** (1 / 2.2 if curve == "gamma" else 1.0)
        q = np.rint(v * 255).astype(np.uint8)[..., ::-1]
        name = f"p{i:03d}.{ext}"
        cv2.imwrite(str(folder / name), q, [cv2.IMWRITE_JPEG_QUALITY, 90] if ext == "jpg" else [])
        names.append(name)
    R, t = DEFAULT_WORLD_FROM_CAMERA[:3, :3], DEFAULT_WORLD_FROM_CAMERA[:3, 3]
    doc = {"format": "ffls-capture", "version": 1, "images": names, "camera": {"K": sc.K.tolist()},
           "sphere_radius": 0.04, "scene_center": (R @ np.mean([b.center for b in sc.balls], 0) + t).tolist(),
           "hemisphere": "full"}
    (folder / "capture.json").write_text(json.dumps(doc))
    (folder / "truth.json").write_text(json.dumps({"directions": scene_directions().tolist()}))


def render(folder: Path, flags: list, res: int, dirs: np.ndarray) -> None:
    """The capture of ``ffls synth OUT --resolution RES FLAGS`` under the lights ``dirs``."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    args = build_parser().parse_args(["synth", str(folder), "--resolution", str(res), "--quiet", *flags])
    write_synthetic_capture(folder, directions=dirs, resolution=res, scene=scene_of(args), photo=photo_settings(args),
                            progress=False, light_model="distant" if args.near is None else "near",
                            light_distance=2.0 if args.near is None else args.near, light_radius=args.light_radius or 0.0)


#: The combination's floor of a matte sphere (``ffls.spheres.photo.estimate_photo``'s ``sigma_floor_deg``).
MATTE_WEIGHT_FLOOR_DEG = 1.0


def recalibrate(doc: dict, common_correlation: float | None = None) -> dict:
    """``doc`` (a ``lights.json`` of ``ffls lights``) with its cones made again by the current
    :mod:`ffls.spheres.uncertainty` from the photo estimates it records, without running the fits.

    As :func:`ffls.spheres.estimate.calibrate_uncertainty` does: each accepted photo with 2+ used
    spheres gives their offsets from its light (:func:`~ffls.spheres.uncertainty.photo_residuals`;
    a near light's position seen from each sphere's recorded centre) and their fit statistics
    (``sigma_deg`` / sqrt 2); :func:`~ffls.spheres.uncertainty.fit_error_model` with the recorded
    centre terms gives the model, and each photo's cone is its
    :meth:`~ffls.spheres.uncertainty.ErrorModel.photo_sigma_deg` with the combination's weights
    (``photo.sphere_uncertainty_deg``: a matte sphere's ``sigma_deg`` with the 1 deg floor in
    quadrature, a highlight fit's own) times the cone factor. A near light's joint-fit statistics
    are not recorded, so its cone here can be below the one ``ffls lights`` would report.
    ``common_correlation``: the common-mode bound's correlation (default the module's
    ``SPHERES_CORRELATION``), to replay the cones under another bound.
    """
    from ffls.spheres.uncertainty import fit_error_model, photo_residuals

    lights = doc["lights"]
    old = doc.get("uncertainty") or {}
    centre = np.asarray(old.get("centre_deg", ()), dtype=np.float64)
    res, stats, used_all = [], [], []
    for l in lights:
        used = list(l.get("used_spheres") or [])
        if l.get("status", "ok") != "ok" or len(used) < 2:
            continue
        sph = [l["spheres"][i] for i in used]
        near = l.get("model") == "near" and l.get("position") is not None
        res.append(photo_residuals(np.array([s["direction"] for s in sph]), np.asarray(l["direction"]),
                                   np.asarray(l["position"]) if near else None,
                                   np.array([s["center"] for s in sph]) if near else None))
        stats.append(np.array([s["sigma_deg"] for s in sph]) / np.sqrt(2.0))
        used_all.append(np.asarray(used))
    from ffls.spheres.uncertainty import SPHERES_CORRELATION

    rho = SPHERES_CORRELATION if common_correlation is None else float(common_correlation)
    model = fit_error_model(res, stats, spheres=used_all, centre_deg=centre, common_correlation=rho)
    if model.source == "fallback" and common_correlation is not None:  # one sphere: its common share too
        from dataclasses import replace

        from ffls.spheres.uncertainty import common_mode_deg

        model = replace(model, common_ratio=rho / (1.0 - rho), common_deg=common_mode_deg(model.floor_deg ** 2, rho))
    out = []
    for l in lights:
        used = list(l.get("used_spheres") or [])
        if l.get("status", "ok") != "ok" or not used:
            out.append(l)
            continue
        sph = [l["spheres"][i] for i in used]
        sig = np.array([s.get("sigma_deg") or np.inf for s in sph])
        highlight = np.array([s.get("kind") not in (None, "matte") for s in sph])
        w = np.where(highlight, sig ** -2.0, 1.0 / (sig ** 2 + MATTE_WEIGHT_FLOOR_DEG ** 2))
        sigma = model.photo_sigma_deg(sig / np.sqrt(2.0), np.asarray(used), w)
        out.append({**l, "uncertainty_deg": float(model.cone_deg(sigma))})
    return {**doc, "lights": out, "uncertainty": model.as_dict()}


def shared_check(folder: Path) -> dict:
    """The capture's shared, fitted parameters propagated to its photos' directions, against the truth.

    The capture's spheres (their recorded world centres) and photos (linearised with the encoding
    ``ffls lights`` recorded, where the capture states none) are fitted again through the public
    API (:func:`ffls.spheres.estimate.estimate_photos`), which returns each sphere's calibrated
    ground ratio with its spread over the photos that determined it. Per accepted photo:

    * ``encoding_deg``: the encoding exponent's standard error (``lights.json`` ``encoding``
      ``uncertainty``) propagated to the photo's direction
      (:func:`~ffls.spheres.uncertainty.shading_shift` of
      :func:`~ffls.spheres.uncertainty.encoding_perturbation`, combined with the photo's weights:
      :func:`~ffls.spheres.uncertainty.shared_parameter_deg`; shared by all spheres);
    * ``ratio_deg``: each sphere's ground-ratio standard error (``1.2533 spread / sqrt(n)``, that
      of a median) propagated the same way (:func:`~ffls.spheres.uncertainty.own_parameter_deg`;
      one parameter per sphere);
    * ``ratio_spread_deg``: the same with the ratio's spread over the photos instead of its
      standard error (how far one photo's own bounce is from the capture's ratio: the model's
      misfit, a bound rather than a standard error).

    Returns the medians of these per-axis terms over the photos, and, from the truth, the photos'
    per-axis RMS error (``photo_rms_deg``) and their mean signed elevation error. Captures with
    mirror or glossy spheres (a highlight fit has none of these parameters) or an orthographic
    camera are skipped (``{"skipped": reason}``).
    """
    from dataclasses import replace
    from types import SimpleNamespace

    from ffls.conventions import UP
    from ffls.io.capture import encoding_from_record, load_capture, record_response
    from ffls.radiance.photos import load_photo
    from ffls.spheres.estimate import capture_samples, estimate_photos
    from ffls.spheres.samples import sphere_values
    from ffls.spheres.uncertainty import (bounce_perturbation, encoding_perturbation, own_parameter_deg,
                                          shading_shift, shared_parameter_deg, tangent_residuals)

    folder = Path(folder)
    doc = json.loads((folder / "lights_estimated.json").read_text())
    truth = np.asarray(json.loads((folder / "truth.json").read_text())["directions"], dtype=np.float64)
    cap = load_capture(folder)
    rec = doc.get("encoding")
    gamma_rel = 0.0
    if isinstance(rec, dict):
        cap = replace(cap, encoding=encoding_from_record(rec), response=record_response(rec))
        if rec.get("gamma") and rec.get("uncertainty") is not None:
            gamma_rel = float(rec["uncertainty"]) / float(rec["gamma"])
    first = next(l for l in doc["lights"] if l.get("spheres"))
    kinds = {s.get("kind") for l in doc["lights"] for s in l.get("spheres") or []} - {None}
    if kinds - {"matte"} or getattr(cap, "camera_model", "pinhole") != "pinhole":
        # a highlight fit has none of these parameters; an orthographic camera's samples need the
        # detected pixel circles, which lights.json does not keep
        return {"skipped": "mirror or glossy spheres" if kinds - {"matte"} else "orthographic camera"}
    M = np.linalg.inv(cap.world_from_camera)
    spheres = [SimpleNamespace(center_cam=M[:3, :3] @ np.asarray(s["center"]) + M[:3, 3], radius=cap.sphere_radius)
               for s in first["spheres"]]
    samples = capture_samples(cap, spheres, load_photo(cap, 0).shape[:2])
    vals = [sphere_values(load_photo(cap, i), samples) for i in range(len(cap.image_names))]
    est = estimate_photos(vals, samples, cap.scene_center)
    calib = est.calibration or [None] * len(samples)
    rows = []
    for p, t in zip(est.photos, truth):
        if not p.ok or not p.used_spheres or p.weights is None:
            continue
        used = list(p.used_spheres)
        enc, rat, se, spread = [], [], [], []
        for k in used:
            sp, c = p.spheres[k], calib[k]
            if sp.direction is None or sp.kind != "matte":
                enc.append(np.zeros(3)), rat.append(np.zeros(3)), se.append(0.0), spread.append(0.0)
                continue
            n, l = samples[k].normals, np.asarray(sp.direction, dtype=np.float64)
            g = samples[k].ground_factor(UP)
            ratio = c.ratio if c is not None and c.ratio is not None else 0.0
            dv_b = bounce_perturbation(g, l, UP)
            enc.append(shading_shift(n, l, encoding_perturbation(np.maximum(n @ l, 0.0) + ratio * dv_b)))
            rat.append(shading_shift(n, l, dv_b))
            ok = c is not None and c.ratio is not None and c.spread is not None and c.n_photos > 0
            spread.append(float(c.spread) if ok else 0.0)
            se.append(1.2533 * float(c.spread) / np.sqrt(c.n_photos) if ok else 0.0)
        w = np.asarray(p.weights, dtype=np.float64)
        e = np.degrees(tangent_residuals(np.asarray(p.direction)[None], t[None])[0])
        elev = np.degrees(np.arcsin(np.clip(p.direction[2], -1, 1)) - np.arcsin(np.clip(t[2], -1, 1)))
        rows.append((shared_parameter_deg(enc, w, gamma_rel), own_parameter_deg(rat, w, se),
                     own_parameter_deg(rat, w, spread), float(e @ e) / 2.0, elev))
    r = np.array(rows)
    return {"photos": int(len(r)), "gamma_relative_se": gamma_rel,
            "encoding_deg": float(np.median(r[:, 0])), "ratio_deg": float(np.median(r[:, 1])),
            "ratio_spread_deg": float(np.median(r[:, 2])), "photo_rms_deg": float(np.sqrt(np.mean(r[:, 3]))),
            "elevation_bias_deg": float(np.mean(r[:, 4])),
            "common_deg": float((doc.get("uncertainty") or {}).get("common_deg", np.nan))}


def _combination_weights(sph: list) -> np.ndarray:
    """The combination's weights of a photo's used spheres, as :func:`recalibrate` rebuilds them
    (``lights.json`` does not keep them): a matte sphere's ``sigma_deg`` with the 1 deg floor in
    quadrature, a highlight fit's own."""
    sig = np.array([s.get("sigma_deg") or np.inf for s in sph], dtype=np.float64)
    highlight = np.array([s.get("kind") not in (None, "matte") for s in sph])
    return np.where(highlight, sig ** -2.0, 1.0 / (sig ** 2 + MATTE_WEIGHT_FLOOR_DEG ** 2))


def truth_check(folder: Path) -> dict:
    """Each part of the cones of a stored run against the render's truth (``truth.json``).

    Per accepted photo with two or more used spheres, from ``lights_estimated.json`` and its error
    model (:meth:`ErrorModel.budget` with the combination's weights, :func:`_combination_weights`):

    * each sphere's error against the truth (a tangent 2-vector, degrees; a near light's truth at a
      sphere is its position seen from the true centre nearest the recorded one), set against the
      sphere's per-axis sd under the model (``sphere_ratio``: the median of ``|e| / (1.1774 sd)``,
      1 for a Gaussian of that sd; 1.1774 = the median of a Rayleigh radius);
    * ``pair_correlation``: per pair of spheres, the correlation of their errors over the photos
      that use both (uncentred: ``sum e_i . e_j / sqrt(sum |e_i|^2 sum |e_j|^2)``), averaged over
      the pairs. The model takes the spheres' errors as independent beside a common mode that is
      its floor alone (``SPHERES_CORRELATION`` 0);
    * ``photo_over_independent``: the median over the photos of the photo's squared per-axis error
      ``|E|^2 / 2`` over the variance the independent-sphere part predicts for it (``sum w^2 v``,
      the budget's sigma without the common mode): 1 if the spheres' errors are independent,
      below 1 if they cancel in the mean, above if they add;
    * ``needed_factor``: the 95% quantile of ``|E| / sigma`` (the factor 95% coverage needs on
      these sigmas), against the capture's ``cone_factor``; ``needed_factor_independent`` the same
      on the independent-sphere part alone; ``shape_factor``: that quantile over the RMS of
      ``|E| / sigma`` per axis (2.448 for a Gaussian: the photo errors' own tail, whatever their
      scale);
    * ``sphere_coverage``: the share of the used spheres whose error lies within the sphere's own
      95% cone (:meth:`ffls.spheres.photo.PhotoEstimate.with_error_model`: ``f sqrt(v_i +
      common_i^2)``), ``sphere_coverage_independent`` the same without the common mode (what the
      disagreement measures, calibrated by ``f``), and ``photo_coverage`` that of the photos'
      cones (``f`` times the budget's sigma). Near 95% per sphere while the photos are at 100%:
      the spheres' errors cancel in the photo's mean more than independent ones would; per sphere
      well under 95% without the common mode: they share an error the disagreement cannot see;
    * what the capture measures itself, no truth used (``i-cones17``: does any of these tell the
      captures whose spheres' errors cancel from those whose errors add?): ``disagreement_deg``,
      the used spheres' offsets from the photo's direction as a per-axis sd (their median radius
      over 1.1774: a sphere the combination all but ignores, its statistics tens of degrees, does
      not set it; distant lights); ``inflation``, the median
      of the used spheres' residual correlation factor (``correlation_inflation``: smooth misfit
      against pixel noise); ``relative_rms``, the median of their shading fits' RMS residual over
      their intensity; ``common_share``, the median over the photos of the common mode's share of
      the photo's variance (``common_deg^2 / sigma^2``), and ``photo_coverage_without_common``, the
      photos' coverage with the common mode left out of their cones (what the floor buys);
    * ``away_mean_deg`` / ``away_share``: the spheres' errors resolved along the horizontal
      direction from the centre of the spheres' layout to each sphere (on the light's tangent
      plane; photos where that direction's tangent part is under 0.2 are left out): its mean, and
      its share of the errors' mean square. Errors that point away from the layout's centre (an
      object between the spheres hiding part of each sphere's ground) cancel in the mean of
      spheres placed around it.

    Returns medians and these measures; ``{"skipped": reason}`` without a fitted model or photos
    with 2+ spheres.
    """
    from ffls.conventions import normalize
    from ffls.spheres.uncertainty import ErrorModel, tangent_residuals

    folder = Path(folder)
    doc = json.loads((folder / "lights_estimated.json").read_text())
    truth = json.loads((folder / "truth.json").read_text())
    if not doc.get("uncertainty"):
        return {"skipped": "no error model"}
    model = ErrorModel.from_dict(doc["uncertainty"])
    T = np.asarray(truth["directions"], dtype=np.float64)
    pos = np.asarray(truth["positions"], dtype=np.float64) if truth.get("light_model") == "near" else None
    true_centres = np.asarray(truth.get("sphere_centers") or np.zeros((0, 3)), dtype=np.float64)
    n_spheres = max(len(l.get("spheres") or []) for l in doc["lights"])
    first = next(l for l in doc["lights"] if l.get("spheres"))
    layout = np.mean([s["center"] for s in first["spheres"]], axis=0)
    per = np.full((len(doc["lights"]), n_spheres, 2), np.nan)
    rows, away, own, offsets, misfit = [], [], [], [], []
    for j, l in enumerate(doc["lights"]):
        used = list(l.get("used_spheres") or [])
        if l.get("status", "ok") != "ok" or len(used) < 2:
            continue
        sph = [l["spheres"][i] for i in used]
        dirs = np.array([s["direction"] for s in sph], dtype=np.float64)
        centres = np.array([s["center"] for s in sph], dtype=np.float64)
        at = _sphere_truth(l, j, T, pos, true_centres, centres)
        e = np.degrees(tangent_residuals(dirs, at))
        per[j, used] = e
        E = np.degrees(tangent_residuals(np.asarray(l["direction"], dtype=np.float64)[None], T[j][None]))[0]
        if l.get("model") != "near":  # a near light's spheres see it from their own centres
            offsets.append(np.degrees(tangent_residuals(dirs, np.asarray(l["direction"], dtype=np.float64))))
        misfit += [(s.get("inflation") or np.nan, (s.get("rms") or np.nan) / (s.get("intensity") or np.nan))
                   for s in sph]
        stat = np.array([s.get("sigma_deg") or np.inf for s in sph]) / np.sqrt(2.0)
        b = model.budget(stat, np.asarray(used, dtype=np.intp), _combination_weights(sph))
        if not np.isfinite(b["sigma_deg"]):
            continue
        sd = model.sphere_sigma_deg(stat, np.asarray(used, dtype=np.intp))
        indep = b["sigma_deg"] ** 2 - b["common_deg"] ** 2
        rows.append((E, b, indep, np.linalg.norm(e, axis=1) / (1.1774 * sd)))
        # each sphere against its own cone (PhotoEstimate.with_error_model), with and without its common mode
        common = np.array([model.common_sigma_deg(st, i) for st, i in zip(stat, used)])
        rad_i = np.linalg.norm(e, axis=1)
        own.append(np.stack([rad_i <= model.cone_deg(np.hypot(sd, common)), rad_i <= model.cone_deg(sd)], axis=1))
        for k, c in enumerate(centres):
            h = c - layout
            h[2] = 0.0
            if np.linalg.norm(h) == 0:
                continue
            h = normalize(h)
            ht = h - (h @ at[k]) * at[k]
            if np.linalg.norm(ht) < 0.2:
                continue
            d = normalize(dirs[k])
            err = d - (d @ at[k]) * at[k]  # tangent error (radians, to first order)
            away.append((np.degrees(err @ normalize(ht)), np.degrees(np.linalg.norm(err))))
    if not rows:
        return {"skipped": "no photo with 2+ spheres"}
    E = np.array([r[0] for r in rows])
    sig = np.array([r[1]["sigma_deg"] for r in rows])
    indep = np.array([r[2] for r in rows])
    rad = np.linalg.norm(E, axis=1)
    z = rad / sig
    corr = []
    for a in range(n_spheres):
        for c in range(a + 1, n_spheres):
            both = np.all(np.isfinite(per[:, a]), axis=1) & np.all(np.isfinite(per[:, c]), axis=1)
            if both.sum() >= 5:
                x, y = per[both, a], per[both, c]
                corr.append(float(np.sum(x * y) / np.sqrt(np.sum(x * x) * np.sum(y * y))))
    aw = np.array(away) if away else np.zeros((0, 2))
    mf = np.array(misfit, dtype=np.float64)
    common2 = np.array([r[1]["common_deg"] ** 2 for r in rows])
    med = {k: float(np.median([r[1][k] for r in rows])) for k in (*BUDGET_TERMS, "sigma_deg")}
    centre_ratio = _centre_check(folder, truth, first, model)
    return {"photos": int(len(rows)), "scale": float(model.scale), "floor": float(model.floor_deg),
            "cone_factor": float(model.cone_factor), "source": model.source, **med,
            "sphere_ratio": float(np.median(np.concatenate([r[3] for r in rows]))),
            "pair_correlation": float(np.mean(corr)) if corr else None,
            "photo_over_independent": float(np.median(np.sum(E * E, axis=1) / 2.0 / indep)),
            "photo_rms_deg": float(np.sqrt(np.mean(E * E))),
            "independent_deg": float(np.sqrt(np.median(indep))),
            "needed_factor": float(np.quantile(z, 0.95)),
            "needed_factor_independent": float(np.quantile(rad / np.sqrt(indep), 0.95)),
            "shape_factor": float(np.quantile(z, 0.95) / np.sqrt(np.mean(z * z) / 2.0)),
            "sphere_coverage": float(np.mean(np.concatenate(own)[:, 0])),
            "sphere_coverage_independent": float(np.mean(np.concatenate(own)[:, 1])),
            "photo_coverage": float(np.mean(rad <= np.array([r[1]["cone_deg"] for r in rows]))),
            "disagreement_deg": (float(np.median(np.linalg.norm(np.concatenate(offsets), axis=1)) / 1.1774)
                                 if offsets else None),
            "inflation": float(np.nanmedian(mf[:, 0])) if np.isfinite(mf[:, 0]).any() else None,
            "relative_rms": float(np.nanmedian(mf[:, 1])) if np.isfinite(mf[:, 1]).any() else None,
            "common_share": float(np.median(common2 / sig ** 2)),
            "photo_coverage_without_common": float(np.mean(
                rad <= model.cone_deg(np.sqrt(np.maximum(sig ** 2 - common2, 0.0))))),
            "away_mean_deg": float(aw[:, 0].mean()) if len(aw) else None,
            "away_share": float(np.sum(aw[:, 0] ** 2) / np.sum(aw[:, 1] ** 2)) if len(aw) else None,
            "centre_ratio": centre_ratio}


def _centre_check(folder: Path, truth: dict, first: dict, model) -> list | None:
    """Per sphere, its recorded centre's actual error against the truth, as the per-axis angle it
    turns the normals by (``|dc_px| / sqrt 2 / r_px``, degrees), over the centre term ``g`` of the
    error model (:func:`ffls.spheres.uncertainty.centre_floor_deg`); None for a camera without
    ``K`` or a truth without the spheres' pixel circles. The centres are compared through the
    camera (the projection of the recorded world centre against that of the true one), so an error
    along the viewing ray, which does not turn the normals, does not count."""
    cap = json.loads((folder / "capture.json").read_text())
    cam = cap.get("camera") or {}
    if "K" not in cam or not truth.get("sphere_radii_px") or not truth.get("sphere_centers"):
        return None
    K = np.asarray(cam["K"], dtype=np.float64)
    M = np.linalg.inv(np.asarray(cam.get("world_from_camera", np.eye(4)), dtype=np.float64))

    def project(X):
        Y = M[:3, :3] @ X + M[:3, 3]
        return (K @ Y)[:2] / Y[2]

    true_centres = np.asarray(truth["sphere_centers"], dtype=np.float64)
    g = model.centre_sigma_deg(np.arange(len(first["spheres"])))
    out = []
    for k, s in enumerate(first["spheres"]):
        c = np.asarray(s["center"], dtype=np.float64)
        i = int(np.argmin(np.linalg.norm(true_centres - c, axis=1)))
        actual = np.degrees(np.linalg.norm(project(c) - project(true_centres[i])) / np.sqrt(2.0)
                            / float(truth["sphere_radii_px"][i]))
        out.append(float(actual / g[k]) if g[k] > 0 else None)
    return out


def cached_runs(a, flag: str, folders=None):
    """``(name, folder)`` of each cached run a check reads: ``--cache``'s rows, or ``folders``
    where the check takes them ([] when none are given), keeping ``--only``'s and those with a
    ``lights_estimated.json``."""
    if folders:
        jobs = [(Path(f).name, Path(f)) for f in folders]
    elif a.cache:
        jobs = [(name, Path(a.cache) / f"c{i:02d}_{a.res}") for i, name in enumerate(CONDITIONS)]
        jobs += [(name, Path(a.cache) / f"ds{i:02d}") for i, name in enumerate(SCENES)]
    else:
        raise SystemExit(f"{flag} needs --cache (a folder of earlier runs)"
                         + (" or --folders" if folders is not None else ""))
    return [(name, folder) for name, folder in jobs
            if not (a.only and not any(o in name for o in a.only)) and (folder / "lights_estimated.json").exists()]


def check_table(a, benchmark: str, header: str, rows, cells, footer: str | None = None) -> None:
    """A check's Markdown table, printed a row at a time as ``rows`` yields ``(lead, result)`` (the
    row's leading cells and the check's result; ``cells(result)`` the rest, or the reason it was
    skipped), then the results as JSON."""
    n = header.count("|") - 1
    print(header)
    print("|" + "---|" * n)
    out = []
    for lead, r in rows:
        out.append(r)
        if "skipped" in r:
            print("| " + " | ".join([*lead, f"skipped: {r['skipped']}"]) + " |" + " |" * (n - len(lead) - 1),
                  flush=True)
        else:
            print("| " + " | ".join([*lead, *cells(r)]) + " |", flush=True)
    if footer:
        print(footer)
    write_json(a.out, {"benchmark": benchmark, **host_info(), "resolution": a.res, "results": out})


def _num(x, fmt: str) -> str:
    """``x`` formatted, or "-" for None."""
    return "-" if x is None else format(x, fmt)


def main_truth_check(a) -> None:
    """``--truth-check``: :func:`truth_check` on each cached run; a Markdown table and JSON."""
    def cells(r):
        pc = "-" if r["pair_correlation"] is None else f"{r['pair_correlation']:+.2f}"
        cr = "-" if not r["centre_ratio"] else " / ".join("-" if x is None else f"{x:.1f}" for x in r["centre_ratio"])
        aw = "-" if r["away_mean_deg"] is None else f"{r['away_mean_deg']:+.2f}, {100 * r['away_share']:.0f}%"
        return [f"{r['scale']:.2f}", f"{r['floor']:.2f}", f"{r['sphere_ratio']:.2f}", pc,
                f"{r['photo_over_independent']:.2f}", f"{r['photo_rms_deg']:.3f}", f"{r['independent_deg']:.3f}",
                f"{r['common_deg']:.3f}", f"{r['cone_factor']:.2f}", f"{r['needed_factor']:.2f}",
                f"{r['needed_factor_independent']:.2f}", f"{r['shape_factor']:.2f}", aw, cr,
                f"{100 * r['sphere_coverage']:.1f}% ({100 * r['sphere_coverage_independent']:.1f}%)",
                f"{100 * r['photo_coverage']:.1f}%", _num(r["disagreement_deg"], ".3f"), _num(r["inflation"], ".2f"),
                _num(r["relative_rms"], ".4f"), f"{r['common_share']:.2f}",
                f"{100 * r['photo_coverage_without_common']:.1f}%"]

    check_table(a, "bench_conditions --truth-check",
                "| condition | s | tau | sphere error / model sd | pair correlation | photo / independent variance | "
                "photos' RMS error | independent part | common bound | cone factor | factor needed | "
                "needed, independent part only | shape factor | away from layout centre: mean, share | "
                "actual centre error / g, per sphere | sphere coverage (without common mode) | photo coverage | "
                "disagreement | inflation | shading RMS / intensity | common mode's share | "
                "photo coverage without common mode |",
                (([name], {"condition": name, **truth_check(folder)})
                 for name, folder in cached_runs(a, "--truth-check", a.folders or [])), cells,
                "\nper-axis degrees; medians over the accepted photos with 2+ spheres (truth_check)")


#: The directions a per-photo bias is resolved along (:func:`bias_check`): from each sphere toward
#: the scene centre on the light's tangent plane; ``visible`` weights it by the share of the
#: sphere's face toward the centre that the camera sees, ``(1 + g . v) / 2``.
BIAS_DIRECTIONS = ("toward_centre", "visible")


def _sphere_truth(l: dict, j: int, T: np.ndarray, pos, true_centres: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Per used sphere of light ``l`` (index ``j``), the true direction there: the distant light's,
    or a near light's position seen from the true centre nearest each recorded one."""
    from ffls.conventions import normalize

    if pos is not None:
        near = [int(np.argmin(np.linalg.norm(true_centres - c, axis=1))) for c in centres]
        return normalize(pos[j][None, :] - true_centres[near])
    return np.repeat(T[j][None, :], len(centres), axis=0)


def bias_check(folder: Path, direction: str = "toward_centre") -> dict:
    """One bias magnitude per photo along a direction known from the geometry, against the truth.

    The spheres' main error around an object is light the object (and the ground it hides) sends
    onto each sphere's side that faces it. Model sphere ``i``'s error in a photo as ``b h_i +
    n_i``: one magnitude ``b`` per photo, ``h_i`` the direction from the sphere toward the scene
    centre (``capture.json``'s ``scene_center``, else the world origin) on the light's tangent
    plane (:data:`BIAS_DIRECTIONS`). Only ``b sum_i w_i h_i`` enters the photo's weighted mean.

    * ``explained``: the share of the spheres' squared errors against the truth that the term
      explains, ``b`` fitted per photo to the true errors (the best this term can do);
    * ``photo_over_independent`` / ``..._remainder``: ``sum |sum_i w_i e_i|^2 / sum sum_i w_i^2
      |e_i|^2`` over the photos, of the true errors and of what the term leaves (1: independent
      spheres; below 1: they still cancel in the mean);
    * ``p``: the capture's own test of the term (``b`` from each photo's sphere offsets, weighted
      by the sphere variances of the stored run's model; ``sum b^2 / var b`` against a chi-square
      with one degree of freedom per photo);
    * ``coverage`` / ``median_cone_deg`` (the stored run's model, replayed as :func:`recalibrate`)
      against ``coverage_term`` / ``median_cone_term_deg``: the model fitted to the offsets less
      the term, with the term's share of the mean, ``|sum w h| sqrt((b^2 + var b) / 2)`` per axis,
      added in quadrature.

    Returns ``{"skipped": reason}`` without photos with 2+ spheres.
    """
    from scipy.special import chdtrc

    from ffls.conventions import DEFAULT_WORLD_FROM_CAMERA, normalize, tangent_basis
    from ffls.spheres.uncertainty import ErrorModel, fit_error_model, photo_residuals, tangent_residuals

    if direction not in BIAS_DIRECTIONS:
        raise ValueError(f"direction must be one of {BIAS_DIRECTIONS}")
    folder = Path(folder)
    doc = json.loads((folder / "lights_estimated.json").read_text())
    truth = json.loads((folder / "truth.json").read_text())
    cap = json.loads((folder / "capture.json").read_text())
    centre_xyz = np.asarray(cap.get("scene_center", (0.0, 0.0, 0.0)), dtype=np.float64)
    camera = np.asarray((cap.get("camera") or {}).get("world_from_camera", DEFAULT_WORLD_FROM_CAMERA),
                        dtype=np.float64)[:3, 3]
    T = np.asarray(truth["directions"], dtype=np.float64)
    pos = np.asarray(truth["positions"], dtype=np.float64) if truth.get("light_model") == "near" else None
    true_centres = np.asarray(truth.get("sphere_centers") or np.zeros((0, 3)), dtype=np.float64)
    centre_deg = np.asarray((doc.get("uncertainty") or {}).get("centre_deg", ()), dtype=np.float64)
    photos = []
    for j, l in enumerate(doc["lights"]):
        used = list(l.get("used_spheres") or [])
        if l.get("status", "ok") != "ok" or not used:
            continue
        sph = [l["spheres"][i] for i in used]
        L = normalize(np.asarray(l["direction"], dtype=np.float64))
        centres = np.array([s["center"] for s in sph], dtype=np.float64)
        g = normalize(centre_xyz[None, :] - centres)
        e1, e2 = tangent_basis(L)
        h = np.stack([g @ e1, g @ e2], axis=1)
        if direction == "visible":
            h = h * ((1.0 + np.einsum("ij,ij->i", g, normalize(camera[None, :] - centres))) / 2.0)[:, None]
        w = _combination_weights(sph)
        p = {"used": np.asarray(used, dtype=np.intp), "w": w / w.sum(), "h": h,
             "stat": np.array([s.get("sigma_deg") or np.inf for s in sph]) / np.sqrt(2.0),
             "error": float(np.degrees(angle_between(L, T[j])))}
        if len(used) >= 2:
            near = l.get("model") == "near" and l.get("position") is not None
            p["r"] = photo_residuals(np.array([s["direction"] for s in sph]), L,
                                     np.asarray(l["position"]) if near else None, centres if near else None)
            p["e"] = np.degrees(tangent_residuals(np.array([s["direction"] for s in sph]),
                                                  _sphere_truth(l, j, T, pos, true_centres, centres)))
        photos.append(p)
    multi = [p for p in photos if "r" in p]
    if len(multi) < 3:
        return {"skipped": "fewer than 3 photos with 2+ spheres"}
    # the term fitted to the true errors: what it explains, and whether the rest still cancels
    tot = rest = ph0 = ind0 = ph1 = ind1 = 0.0
    for p in multi:
        e, h, w = p["e"], p["h"], p["w"]
        b = float(np.sum(h * e) / max(np.sum(h * h), 1e-300))
        n = e - b * h
        tot, rest = tot + np.sum(e * e), rest + np.sum(n * n)
        ph0, ind0 = ph0 + np.sum((w @ e) ** 2), ind0 + np.sum(w[:, None] ** 2 * e * e)
        ph1, ind1 = ph1 + np.sum((w @ n) ** 2), ind1 + np.sum(w[:, None] ** 2 * n * n)
    # the capture's own: b from each photo's offsets, r_i = b (h_i - sum w h) + noise
    model = fit_error_model([p["r"] for p in multi], [p["stat"] for p in multi],
                            spheres=[p["used"] for p in multi], centre_deg=centre_deg)
    chi, left = 0.0, []
    for p in multi:
        v = np.radians(model.sphere_sigma_deg(p["stat"], p["used"])) ** 2
        p["hbar"] = p["w"] @ p["h"]
        H = p["h"] - p["hbar"]
        info = float(np.sum(np.sum(H * H, axis=1) / v))
        p["b"] = float(np.sum(np.sum(H * p["r"], axis=1) / v) / info) if info > 0 else 0.0
        p["var_b"] = 1.0 / info if info > 0 else np.inf
        chi += p["b"] ** 2 * info if info > 0 else 0.0
        left.append(p["r"] - p["b"] * H)
    termed = fit_error_model(left, [p["stat"] for p in multi], spheres=[p["used"] for p in multi],
                             centre_deg=centre_deg)
    err = np.array([p["error"] for p in photos])

    def cones(m: ErrorModel, with_term: bool) -> np.ndarray:
        out = []
        for p in photos:
            s = m.photo_sigma_deg(p["stat"], p["used"], p["w"])
            if with_term and "b" in p:
                s = np.hypot(s, np.degrees(np.linalg.norm(p["hbar"]) * np.sqrt((p["b"] ** 2 + p["var_b"]) / 2.0)))
            out.append(m.cone_deg(s))
        return np.array(out)

    c0, c1 = cones(model, False), cones(termed, True)
    return {"photos": len(photos), "multi": len(multi), "direction": direction,
            "explained": float(1.0 - rest / tot), "photo_over_independent": float(ph0 / ind0),
            "photo_over_independent_remainder": float(ph1 / ind1),
            "p": float(chdtrc(len(multi), chi)), "median_hbar": float(np.median([np.linalg.norm(p["hbar"]) for p in multi])),
            "coverage": float(np.mean(err <= c0)), "median_cone_deg": float(np.median(c0)),
            "coverage_term": float(np.mean(err <= c1)), "median_cone_term_deg": float(np.median(c1)),
            "median_error_deg": float(np.median(err))}


def main_bias_check(a) -> None:
    """``--bias-check``: :func:`bias_check` (both :data:`BIAS_DIRECTIONS`) on each cached run, or on
    the ``--folders`` given; a Markdown table and JSON."""
    check_table(a, "bench_conditions --bias-check",
                "| condition | direction | photos (2+ spheres) | explained | photo / independent variance: errors, "
                "remainder | median abs(sum w h) | p | coverage (median cone) | with the term |",
                (([name, direction], {"condition": name, **bias_check(folder, direction)})
                 for name, folder in cached_runs(a, "--bias-check", a.folders or []) for direction in BIAS_DIRECTIONS),
                lambda r: [f"{r['photos']} ({r['multi']})", f"{100 * r['explained']:.0f}%",
                           f"{r['photo_over_independent']:.2f}, {r['photo_over_independent_remainder']:.2f}",
                           f"{r['median_hbar']:.2f}", f"{r['p']:.1e}",
                           f"{100 * r['coverage']:.1f}% ({r['median_cone_deg']:.2f})",
                           f"{100 * r['coverage_term']:.1f}% ({r['median_cone_term_deg']:.2f})"])


#: The file in each cached render's folder naming the condition it was rendered for
#: (:func:`check_cached_condition`).
CONDITION_FILE = "condition.txt"


def check_cached_condition(folder, command: str) -> None:
    """Stop when the cached render in ``folder`` was made for another condition than ``command``.

    The cache's folders are numbered by the conditions' positions (``c00_384``, ``ds00``): a
    condition inserted or removed anywhere but at the end would otherwise score one condition's
    renders as another's. Each folder records its condition's command (:data:`CONDITION_FILE`,
    written by :func:`run_condition`); a folder without one (a cache of an earlier version) is
    taken as it is.
    """
    f = Path(folder) / CONDITION_FILE
    if f.exists() and f.read_text().strip() != command:
        raise SystemExit(f"{folder} holds the renders of another condition ({f.read_text().strip()!r}, "
                         f"not {command!r}); remove it or use another --cache")


def run_condition(name: str, flags, res: int, dirs: np.ndarray, folder: Path, recalibrate_only: bool = False,
                  common_correlation: float | None = None) -> dict:
    """``flags``: ``ffls synth`` flags, or a :data:`SCENES` tuple (rendered by tests/detect_scenes.py).
    ``recalibrate_only``: no ``ffls lights`` run; the cones of the cached ``lights_estimated.json``
    made again (:func:`recalibrate`)."""
    folder = Path(folder)
    if isinstance(flags, tuple):
        spec = flags
        command = f"tests/detect_scenes.py: {spec[0]} balls, {spec[1]} background, {spec[2]} {spec[3]}"
        check_cached_condition(folder, command)
        truth = cached_capture(folder, scene_directions(), lambda f: render_scene(f, spec))
        flags = [command]
    else:
        command = f"ffls synth OUT --resolution {res} {' '.join(flags)}".strip()
        check_cached_condition(folder, command)
        truth = cached_capture(folder, dirs, lambda f: render(f, flags, res, dirs))
    (folder / CONDITION_FILE).write_text(command + "\n")
    out = folder / "lights_estimated.json"
    stdout, stderr = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    if recalibrate_only:
        rc = 0 if out.exists() else 1
        if rc:
            stderr.write(f"{out}: no stored run to recalibrate")
    else:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            rc = ffls_main(["lights", str(folder), "-o", str(out), "--workers", "1", "--no-progress"])
    dt = (time.perf_counter() - t0) / len(truth["directions"])
    row = {"condition": name, "flags": flags, "command": command,
           "resolution": res, "n": int(len(truth["directions"])), "rc": rc, "ms_per_photo": 1e3 * dt,
           "stdout": stdout.getvalue().strip().splitlines(), "stderr": stderr.getvalue().strip().splitlines()}
    if rc != 0:
        row["error"] = (row["stderr"] or ["(no message)"])[-1]
        return row
    doc = json.loads(out.read_text())
    if recalibrate_only:
        row["recalibrated"] = True
        doc = recalibrate(doc, common_correlation)
    lights = doc["lights"]
    est = np.array([l["direction"] for l in lights], dtype=np.float64)
    ok = np.array([l.get("status", "ok") == "ok" for l in lights])
    unc = np.array([l.get("uncertainty_deg") if l.get("uncertainty_deg") is not None else np.nan for l in lights],
                   dtype=np.float64)
    err = np.degrees(angle_between(est, np.asarray(truth["directions"], dtype=np.float64)))
    e, u = err[ok], unc[ok]
    true_dirs = np.asarray(truth["directions"], dtype=np.float64)
    elevation = np.degrees(np.arcsin(np.clip(est[ok, 2], -1.0, 1.0)) - np.arcsin(np.clip(true_dirs[ok, 2], -1.0, 1.0)))
    reasons: dict = {}
    for l in lights:
        if l.get("status", "ok") != "ok":
            reasons[l.get("reason")] = reasons.get(l.get("reason"), 0) + 1
    enc = doc.get("encoding")
    row["budget"] = cone_budget(doc, lights, ok, err)
    row.update({
        "accepted": int(ok.sum()), "rejected": reasons,
        "median_deg": float(np.median(e)) if e.size else None, "max_deg": float(e.max()) if e.size else None,
        "coverage": float(np.mean(e <= u)) if e.size else None,
        "median_cone_deg": float(np.median(u)) if e.size else None,
        "elevation_bias_deg": float(np.mean(elevation)) if e.size else None,
        "encoding": enc, "errors_deg": [float(x) if o else None for x, o in zip(err, ok)],
    })
    return row


#: The per-axis terms of a photo's cone (:meth:`ffls.spheres.uncertainty.ErrorModel.budget`).
BUDGET_TERMS = ("fit_deg", "centre_deg", "floor_deg", "common_deg")


#: Parts of a photo's cone that :func:`cone_budget` leaves out one at a time (its ``coverage_without``).
WITHOUT = ("common_bound", "common_floor", "common", "floor", "gaussian_factor")


def cone_budget(doc: dict, lights: list, ok: np.ndarray, err: np.ndarray) -> dict | None:
    """Which term makes the cones of a condition wide or narrow.

    Per accepted photo, :meth:`ErrorModel.budget` of the error model ``lights.json`` reports, from
    its used spheres' fit statistics (``sigma_deg``, RMS) and the combination's weights
    (:func:`_combination_weights`, as :func:`recalibrate` rebuilds them: the weights the photo's
    cone was made with; a near light's joint-fit statistics are not included). Returns the medians
    of the per-axis terms (``stat_deg`` the fit statistics before the scale ``s``, ``fit_deg``
    after it; the common mode also split into its bound, ``common_bound_deg``, and its floor), of
    the budget's sigma and cone, the cone factor, the error model's source, and against the truth:

    * ``photo_rms_deg``, the photos' per-axis RMS error (what ``sigma_deg`` should be if the
      model's variance is right), and ``needed_factor``, the 95% quantile of error /
      ``sigma_deg`` (the cone factor that would give 95% coverage with these sigmas);
    * ``coverage_budget``: the coverage of the budget's cones (``cone_factor * sigma_deg``), and
      ``coverage_without``: the same with one part left out of the root sum of squares
      (:data:`WITHOUT`: the common-mode bound, the common floor, both, the per-sphere floor
      ``tau``) or with the Gaussian factor 2.448 in place of the capture's (``gaussian_factor``);
    * ``share``: per term, the median over the photos of its share of the photo's variance.

    None without an error model or accepted photos.
    """
    from ffls.spheres.uncertainty import CONE_FACTOR, ErrorModel

    if not doc.get("uncertainty") or not ok.any():
        return None
    model = ErrorModel.from_dict(doc["uncertainty"])
    terms = []
    for l, good in zip(lights, ok):
        used = list(l.get("used_spheres") or []) if good else []
        if not used:
            terms.append(None)
            continue
        sph = [l["spheres"][i] for i in used]
        stat = np.array([s.get("sigma_deg") or np.inf for s in sph], dtype=np.float64) / np.sqrt(2.0)
        b = model.budget(stat, np.asarray(used, dtype=np.intp), _combination_weights(sph))
        b["common_bound_deg"] = float(np.sqrt(max(b["common_deg"] ** 2 - b["common_floor_deg"] ** 2, 0.0)))
        b["stat_deg"] = b["fit_deg"] / model.scale  # the fit statistics as they are, before the scale s
        terms.append(b)
    have = np.array([t is not None and np.isfinite(t["sigma_deg"]) for t in terms])
    if not have.any():
        return None
    kept = [t for t, h in zip(terms, have) if h]
    med = {k: float(np.median([t[k] for t in kept]))
           for k in (*BUDGET_TERMS, "stat_deg", "common_bound_deg", "common_floor_deg", "sigma_deg", "cone_deg")}
    sig = np.array([t["sigma_deg"] for t in kept])
    e = err[have]
    f = float(model.cone_factor)

    def part(k):
        return np.array([t[k] for t in kept]) ** 2

    var = sig * sig
    left = {"common_bound": var - part("common_bound_deg"), "common_floor": var - part("common_floor_deg"),
            "common": var - part("common_deg"), "floor": var - part("floor_deg"), "gaussian_factor": var}
    without = {}
    for k in WITHOUT:
        factor = CONE_FACTOR if k == "gaussian_factor" else f
        without[k] = float(np.mean(e <= factor * np.sqrt(np.maximum(left[k], 0.0))))
    share = {k: float(np.median(part(k) / var)) for k in ("fit_deg", "centre_deg", "floor_deg", "common_bound_deg",
                                                          "common_floor_deg")}
    return {**med, "cone_factor": f, "source": model.source, "weights": "combination",
            "photo_rms_deg": float(np.sqrt(np.mean(e * e) / 2.0)),
            "model_rms_deg": float(np.sqrt(np.mean(var))),
            "needed_factor": float(np.quantile(e / sig, 0.95)),
            "coverage_budget": float(np.mean(e <= f * sig)), "coverage_without": without, "share": share}


def budget_table(rows) -> list[str]:
    """Markdown lines: per condition, the median per-axis terms of the cones, the coverage with
    each part left out (:func:`cone_budget`) and the evidence."""
    out = ["| condition | source | statistics | fit | centre | floor | common bound | common floor | cone factor | "
           "median cone | photos' per-axis RMS error | model sigma (RMS) | factor for 95% | coverage | "
           "without common bound | without common floor | without common mode | without floor | Gaussian factor |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b = r.get("budget")
        if not b:
            continue
        terms = ("stat_deg", "fit_deg", "centre_deg", "floor_deg", "common_bound_deg", "common_floor_deg")
        w = b.get("coverage_without") or {}
        out.append(f"| {r['condition']} | {b['source']} | " + " | ".join(f"{b.get(k, np.nan):.3f}" for k in terms)
                   + f" | {b['cone_factor']:.2f} | {b.get('cone_deg', np.nan):.2f} | {b['photo_rms_deg']:.3f} | "
                   f"{b['model_rms_deg']:.3f} | "
                   f"{b['needed_factor']:.2f} | {100 * b.get('coverage_budget', np.nan):.0f}% | "
                   + " | ".join(f"{100 * w.get(k, np.nan):.0f}%" for k in WITHOUT) + " |")
    return out


def encoding_text(enc) -> str:
    if not enc:
        return "stated"
    if isinstance(enc, dict):
        name = enc.get("curve", "?")
        g, s = enc.get("gamma"), enc.get("uncertainty")
        return f"{name}" + (f" (gamma {g:.2f}" + (f" +- {s:.2f})" if s is not None else ")") if g is not None else "")
    return str(enc)


def coverage_summary(rows, low: float = 0.90, high: float = 0.98) -> str:
    """One line: how many conditions' coverage lies in ``[low, high]`` (the goal), and which lie outside."""
    done = [r for r in rows if r["rc"] == 0 and r.get("coverage") is not None]
    inside = [r for r in done if low <= r["coverage"] <= high]
    over = [f"{r['condition']} {100 * r['coverage']:.1f}%" for r in done if r["coverage"] > high]
    under = [f"{r['condition']} {100 * r['coverage']:.1f}%" for r in done if r["coverage"] < low]
    return (f"coverage in {100 * low:.0f}-{100 * high:.0f}%: {len(inside)} of {len(done)} conditions; "
            f"over ({len(over)}): {'; '.join(over) or '-'}; under ({len(under)}): {'; '.join(under) or '-'}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--phi-step", type=int, default=20)
    ap.add_argument("--theta-step", type=int, default=10)
    ap.add_argument("--only", nargs="*", default=None, help="names (substrings) of the conditions to run")
    ap.add_argument("--cache", default=None, help="keep (and reuse) the renders in this folder")
    ap.add_argument("--recalibrate", action="store_true",
                    help="no ffls lights run: make the cones of each cached run's lights_estimated.json again with "
                         "the current error model (directions unchanged; needs --cache with earlier runs)")
    ap.add_argument("--common-correlation", type=float, default=None,
                    help="with --recalibrate: the common-mode bound's correlation to replay the cones with")
    ap.add_argument("--shared-check", action="store_true",
                    help="no ffls lights run: the capture's shared, fitted parameters propagated to the photos' "
                         "directions against their actual errors (shared_check; needs --cache with earlier runs)")
    ap.add_argument("--truth-check", action="store_true",
                    help="no ffls lights run: each part of the stored runs' cones against the renders' truth "
                         "(truth_check; --cache with earlier runs, or --folders)")
    ap.add_argument("--bias-check", action="store_true",
                    help="no ffls lights run: one bias magnitude per photo along a direction known from the "
                         "geometry, against the stored runs' truth (bias_check; --cache with earlier runs, or --folders)")
    ap.add_argument("--folders", nargs="*", default=None,
                    help="with --bias-check or --truth-check: capture folders (truth.json, "
                         "lights_estimated.json) instead of the cache's")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_conditions.json"))
    a = ap.parse_args(argv)
    _, _, dirs = grid(a.phi_step, a.theta_step)
    if a.shared_check:
        return main_shared_check(a)
    if a.truth_check:
        return main_truth_check(a)
    if a.bias_check:
        return main_bias_check(a)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(a.cache or tmp)
        jobs = [(name, flags, f"c{i:02d}_{a.res}") for i, (name, flags) in enumerate(CONDITIONS.items())]
        jobs += [(name, spec, f"ds{i:02d}") for i, (name, spec) in enumerate(SCENES.items())]
        for name, flags, sub in jobs:
            if a.only and not any(o in name for o in a.only):
                continue
            r = run_condition(name, flags, a.res, dirs, base / sub, recalibrate_only=a.recalibrate,
                              common_correlation=a.common_correlation)
            rows.append(r)
            if r["rc"] != 0:
                print(f"{name:44s} ERROR {r['error']}", flush=True)
                continue
            if not r["accepted"]:
                print(f"{name:44s} ok   0/{r['n']} {r['rejected']}", flush=True)
                continue
            print(f"{name:44s} ok {r['accepted']:3d}/{r['n']} median {r['median_deg']:.2f} max {r['max_deg']:.2f} deg "
                  f"coverage {100 * r['coverage']:.1f}% cone {r['median_cone_deg']:.2f} "
                  f"elevation {r['elevation_bias_deg']:+.2f} enc {encoding_text(r['encoding'])} "
                  f"{r['ms_per_photo']:.0f} ms/photo {r['rejected'] or ''}", flush=True)
    print("\n| condition | accepted | median / max error (deg) | 95% cone coverage (median cone) | mean elevation error (deg) "
          "| encoding found | ms/photo | `ffls synth` flags |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        flags = "`" + " ".join(r["flags"]) + "`" if r["flags"] else "(defaults)"
        if r["rc"] != 0:
            print(f"| {r['condition']} | stopped: {r['error']} | | | | | | {flags} |")
            continue
        med = "-" if r["median_deg"] is None else f"{r['median_deg']:.2f} / {r['max_deg']:.2f}"
        cov = "-" if r["coverage"] is None else f"{100 * r['coverage']:.0f}% ({r['median_cone_deg']:.2f})"
        elev = "-" if r["elevation_bias_deg"] is None else f"{r['elevation_bias_deg']:+.2f}"
        print(f"| {r['condition']} | {r['accepted']}/{r['n']} | {med} | {cov} | {elev} | {encoding_text(r['encoding'])} | "
              f"{r['ms_per_photo']:.0f} | {flags} |")
    print("\nCone budget (median per-axis terms, degrees; ErrorModel.budget):\n")
    print("\n".join(budget_table(rows)))
    print("\n" + coverage_summary(rows))
    write_json(a.out, {"benchmark": "bench_conditions", **host_info(), "resolution": a.res, "results": rows})


def main_shared_check(a) -> None:
    """``--shared-check``: :func:`shared_check` on each cached run; a Markdown table and JSON."""
    check_table(a, "bench_conditions --shared-check",
                "| condition | photos | encoding exponent (deg) | ground ratios' SE (deg) | ground ratios' spread (deg) | "
                "common-mode bound now (deg) | photos' RMS error (deg) | mean elevation error (deg) |",
                (([name], {"condition": name, **shared_check(folder)})
                 for name, folder in cached_runs(a, "--shared-check")),
                lambda r: [str(r["photos"]), f"{r['encoding_deg']:.4f}", f"{r['ratio_deg']:.4f}",
                           f"{r['ratio_spread_deg']:.3f}", f"{r['common_deg']:.3f}", f"{r['photo_rms_deg']:.3f}",
                           f"{r['elevation_bias_deg']:+.2f}"],
                "\nper-axis standard deviations, medians over the accepted photos; RMS error per axis, from the truth")


if __name__ == "__main__":
    main()
