"""A mirror ball found without any hint in one HDR probe photo: how often, and how close.

Each render is a chrome ball (radius 0.1 m, reflectance 0.7) ray-traced by
``ffls.synth.probe.write_mirror_probe`` under a real light map (``/work/shared/hdri``, Poly Haven,
CC0: courtyard, night, studio, sunrise); rays that miss the ball see the map itself, so the
background is the busy, high-dynamic-range scene around the ball, not a black or grey ground.
Three layouts per map (each map also turned about the vertical by the camera's azimuth): a wide
lens close by (f = 400 px, 1.2 m, ball left of centre), a normal lens (f = 800 px, 4 m, ball
upper right) and a long lens (f = 1600 px, 4 m, ball lower left), at 320 x 240 px; apparent radii
about 20 to 40 px. ``probe.json`` locates nothing (``"sphere": {"material": "mirror"}``), and
``ffls.probes.locate.locate_sphere`` (the ``ffls probe mirror`` path) finds the ball.

Reported per render: the centre error (pixels, against the projected true centre), the radius
error, and the outcome: ``ok`` (centre within 1 px), ``off`` (found, centre 1 px or more off),
``inner`` (a circle inside the ball: radius below 0.8 of the truth, an inner reflection),
``none`` (no sphere found). Then the rate within 1 px and the time per photo. Also per render the 95% radius
of the centre the located sphere states (``SphereGeometry.center_uncertainty_px``, None where not stated) and
whether its description flags it (``SphereGeometry.flagged``: over ``MIRROR_CENTRE_TOL_PX``, or a larger circle of
steps encloses its limb); summed: the renders whose error lies within
the stated radius, the flagged ones, and those off (1 px or more) without a flag. ``--sectors N`` sets
``ffls.probes.locate.LIMB_JACKKNIFE_SECTORS``.

``--azimuth DEG`` turns every layout's camera by that much more about the vertical: the same maps and
lenses seen from other sides, renders not looked at while building the finder.

Run: ``OMP_NUM_THREADS=1 python benchmarks/probe_detect.py [--maps courtyard,night,studio,sunrise] [--azimuth DEG]
[--sectors N] [--out FILE]``
"""
from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from common import host_info, write_json
from ffls.camera.projection import project_points
from ffls.errors import InputError
from ffls.io.probe import load_probe
from ffls.lightmaps.lightmap import LightMapWarning, load_lightmap
from ffls.probes.bracket import view_radiance
from ffls.probes import locate as locate_module
from ffls.probes.locate import locate_sphere
from ffls.synth.probe import look_at, write_mirror_probe

HDRI = Path("/work/shared/hdri")
SIZE = (320, 240)  # width, height
CENTER = np.array([0.0, 0.0, 0.1])
RADIUS = 0.1
#: (name, focal px, distance m, ball offset from the image centre (px), elevation deg)
MAPS = ("courtyard", "night", "studio", "sunrise")  # map m is turned by 90 m + 120 k degrees in layout k
LAYOUTS = [("wide", 400.0, 1.2, (-70.0, 10.0), 20.0),
           ("normal", 800.0, 4.0, (90.0, -55.0), 10.0),
           ("long", 1600.0, 4.0, (-60.0, 40.0), 30.0)]


def render(folder, lightmap, layout, azimuth_deg):
    """Write one probe folder; return the true centre (px) and apparent radius (px)."""
    _, f, d, (du, dv), el = layout
    a, e = np.radians(azimuth_deg), np.radians(el)
    eye = CENTER + d * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    T0 = look_at(eye, CENTER)
    x0, y0 = T0[:3, 0], T0[:3, 1]
    T = look_at(eye, CENTER - (du / f) * d * x0 - (dv / f) * d * y0)  # turn the camera: the ball moves by (du, dv)
    K = np.array([[f, 0, (SIZE[0] - 1) / 2], [0, f, (SIZE[1] - 1) / 2], [0, 0, 1.0]])
    write_mirror_probe(folder, lightmap, SIZE, "pinhole", K, None, T, CENTER, RADIUS, sphere="auto",
                       reflectance=0.7)
    Ti = np.linalg.inv(T)
    C = Ti[:3, :3] @ CENTER + Ti[:3, 3]
    c_px = project_points(C[None], K, None)[0]
    r_px = f * RADIUS / np.sqrt(C @ C - RADIUS ** 2)  # tangent-cone radius near the axis
    return c_px, float(r_px)


def locate(folder, stated: bool = False):
    """The located sphere (centre px, radius px) of the probe in ``folder``, or None, and the seconds taken;
    ``stated``: also its 95% centre radius (or None) and whether its description flags it
    (``SphereGeometry.flagged``) last in the tuple."""
    probe = load_probe(folder)
    view = probe.views[0]
    vr = view_radiance(view, probe.encoding, probe.response, probe.json_path)
    t = time.perf_counter()
    try:
        geo = locate_sphere(view, vr.radiance, probe.json_path)
        out = (np.asarray(geo.center_px), float(geo.radius_px)) + ((geo.center_uncertainty_px, geo.flagged)
                                                                   if stated else ())
    except InputError:
        out = None
    return out, time.perf_counter() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", default="courtyard,night,studio,sunrise")
    ap.add_argument("--azimuth", type=float, default=0.0, help="added to every camera's azimuth (degrees)")
    ap.add_argument("--sectors", type=int, default=locate_module.LIMB_JACKKNIFE_SECTORS,
                    help="the limb jackknife's sectors (ffls.probes.locate.LIMB_JACKKNIFE_SECTORS)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "probe_detect.json"))
    a = ap.parse_args(argv)
    locate_module.LIMB_JACKKNIFE_SECTORS = a.sectors
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in a.maps.split(","):
            m = MAPS.index(name) if name in MAPS else len(MAPS)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LightMapWarning)  # the maps' few negative texels, clamped
                lm = load_lightmap(HDRI / f"{name}.exr")
            for k, layout in enumerate(LAYOUTS):
                folder = Path(tmp) / f"{name}_{layout[0]}"
                c_true, r_true = render(folder, lm, layout, azimuth_deg=90.0 * m + 120.0 * k + a.azimuth)
                found, dt = locate(folder, stated=True)
                u, flag = (None, False) if found is None else found[2:4]
                if found is None:
                    err, dr, outcome = None, None, "none"
                else:
                    err = float(np.hypot(*(found[0] - c_true)))
                    dr = found[1] - r_true
                    outcome = ("inner" if found[1] < 0.8 * r_true else "ok" if err < 1.0 else "off")
                rows.append({"map": name, "layout": layout[0], "center_true_px": c_true.tolist(), "radius_true_px": r_true,
                             "center_error_px": err, "radius_error_px": dr, "outcome": outcome, "seconds": dt,
                             "center_uncertainty_px": u, "flagged": flag})
                print(f"{name:10s} {layout[0]:7s} r={r_true:5.1f} px  "
                      + ("not found" if err is None else f"centre error {err:6.2f} px, radius {dr:+6.2f} px")
                      + f"  {outcome:5s} {dt:5.2f} s" + ("" if u is None else f"  stated {u:5.2f} px (95%)")
                      + ("" if not flag else " FLAGGED"), flush=True)
    n_ok = sum(r["outcome"] == "ok" for r in rows)
    errs = [r["center_error_px"] for r in rows if r["center_error_px"] is not None]
    summary = {"renders": len(rows), "within_1px": n_ok,
               "outcomes": {o: sum(r["outcome"] == o for r in rows) for o in ("ok", "off", "inner", "none")},
               "median_center_error_px": float(np.median(errs)) if errs else None,
               "median_seconds": float(np.median([r["seconds"] for r in rows])),
               "stated": sum(r["center_uncertainty_px"] is not None for r in rows),
               "within_stated": sum(r["center_uncertainty_px"] is not None
                                    and r["center_error_px"] <= r["center_uncertainty_px"] for r in rows),
               "flagged": sum(r["flagged"] for r in rows),
               "off_without_flag": sum(r["center_error_px"] is not None and r["center_error_px"] >= 1.0
                                       and not r["flagged"] for r in rows)}
    print(f"found within 1 px: {n_ok}/{len(rows)}; outcomes {summary['outcomes']}; median centre error "
          f"{summary['median_center_error_px']:.2f} px; median {summary['median_seconds']:.2f} s per photo; within "
          f"the stated 95% radius {summary['within_stated']}/{summary['stated']}; flagged {summary['flagged']}; "
          f"1 px or more off without a flag {summary['off_without_flag']}")
    write_json(a.out, {"host": host_info(), "summary": summary, "rows": rows})


if __name__ == "__main__":
    main()
