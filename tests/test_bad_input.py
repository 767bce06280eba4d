"""Bad inputs, failed writes and interruptions across every command (issue 10, docs/reliability.md).

Each case runs ``ffls.cli.main`` in-process and asserts the promise: exit status 2, exactly one
line on stderr that names the flag or file, no traceback, nothing at the output path and no
temporary file left beside it. Interruptions are real signals to a child process.
"""
from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ffls.cli import main, subcommands
from ffls.io.images import read_image, write_exr, write_hdr, write_png

from cli_lines import entries

N_LIGHTS = 40


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    """A workspace: a good capture, broken copies and broken files, made once."""
    from ffls.synth.scene import write_synthetic_capture

    root = tmp_path_factory.mktemp("bad")
    cap = root / "cap"
    write_synthetic_capture(cap, n_lights=N_LIGHTS, resolution=24, progress=False, seed=3)
    w = {"root": root, "cap": cap}

    def copy(name):
        dst = root / name
        shutil.copytree(cap, dst)
        return dst

    # NaN / Inf pixels in one photo
    for name, bad in (("cap_nan", np.nan), ("cap_inf", np.inf)):
        c = copy(name)
        img = read_image(c / "img_0003.exr").pixels.copy()
        img[5, 7, 1] = bad
        write_exr(c / "img_0003.exr", img, half=True)
        w[name] = c
    # a capture of few lights (its coverage notes must not come before an error) with a NaN pixel,
    # and with a photo of the wrong size
    few = root / "few"
    write_synthetic_capture(few, n_lights=8, resolution=24, progress=False, seed=4)
    w["few"] = few
    for name, edit in (("few_nan", "nan"), ("few_size", "size")):
        c = root / name
        shutil.copytree(few, c)
        img = read_image(c / "img_0005.exr").pixels.copy()
        if edit == "nan":
            img[1, 1, 0] = np.nan
        else:
            img = img[:20, :22]
        write_exr(c / "img_0005.exr", img, half=True)
        w[name] = c
    # a truncated photo
    c = copy("cap_trunc")
    data = (c / "img_0002.exr").read_bytes()
    (c / "img_0002.exr").write_bytes(data[: len(data) // 2])
    w["cap_trunc"] = c
    # an 8-bit photo among float ones with no encoding stated; a folder named like a listed photo
    c = copy("cap_mixed")
    doc = json.loads((c / "capture.json").read_text())
    write_png(c / "img_0001.png", np.full((24, 24, 3), 90, np.uint8))
    doc["images"][1] = "img_0001.png"
    doc.pop("encoding", None)
    (c / "capture.json").write_text(json.dumps(doc))
    w["cap_mixed"] = c
    c = copy("cap_alpha")  # a 16-bit PNG photo with transparent rows (stated linear, as the others)
    doc = json.loads((c / "capture.json").read_text())
    rgba = np.full((24, 24, 4), 30000, np.uint16)
    rgba[:10, :, 3] = 0
    rgba[10:, :, 3] = 65535
    import cv2

    cv2.imwrite(str(c / "img_0004.png"), rgba)
    doc["images"][4] = "img_0004.png"
    (c / "capture.json").write_text(json.dumps(doc))
    (c / "lights.json").write_text((c / "lights.json").read_text().replace("img_0004.exr", "img_0004.png"))
    w["cap_alpha"] = c
    c = copy("cap_dirimg")
    (c / "img_0002.exr").unlink()
    (c / "img_0002.exr").mkdir()
    w["cap_dirimg"] = c
    # lights.json documents
    lights = json.loads((cap / "lights.json").read_text())

    def lights_doc(name, edit):
        doc = json.loads(json.dumps(lights))
        edit(doc)
        p = root / name
        p.write_text(json.dumps(doc))
        return p

    w["l_version_true"] = lights_doc("version_true.json", lambda d: d.update(version=True))
    w["l_version_float"] = lights_doc("version_float.json", lambda d: d.update(version=1.5))
    w["l_huge"] = lights_doc("huge.json", lambda d: d["lights"][0].update(direction=[1e308, 1e308, 1e308]))
    w["l_huge_neg"] = lights_doc("huge_neg.json", lambda d: d["lights"][1].update(direction=[-1e308, 0, 1e308]))
    w["l_bool_dir"] = lights_doc("bool_dir.json", lambda d: d["lights"][2].update(direction=[True, False, False]))
    w["l_none_ok"] = lights_doc("none_ok.json", lambda d: [it.update(status="rejected", reason="test")
                                                         for it in d["lights"]])
    w["l_unc_bool"] = lights_doc("unc_bool.json", lambda d: d["lights"][0].update(uncertainty_deg=True))
    # capture.json with "version": true
    c = copy("cap_version_true")
    doc = json.loads((c / "capture.json").read_text())
    doc["version"] = True
    (c / "capture.json").write_text(json.dumps(doc))
    w["cap_version_true"] = c
    # .lp files
    names = [it["image"] for it in lights["lights"]]
    lp = root / "huge.lp"
    lp.write_text(f"{len(names)}\n" + "".join(f"{n} {'1e308' if k == 0 else '0'} 0 {'0' if k == 0 else '1'}\n"
                                                for k, n in enumerate(names)))
    w["lp_huge"] = lp
    # light maps
    maps = root / "maps"
    maps.mkdir()
    write_exr(maps / "one.exr", np.ones((1, 1, 3), np.float32))
    write_exr(maps / "two.exr", np.ones((1, 2, 3), np.float32))
    write_hdr(maps / "two.hdr", np.ones((1, 2, 3), np.float32))
    write_exr(maps / "tiny_angular.exr", np.ones((2, 2, 3), np.float32))
    good = np.random.default_rng(0).random((32, 64, 3)).astype(np.float32)
    for ext, writer in ((".exr", write_exr), (".hdr", write_hdr)):
        writer(maps / f"good{ext}", good)
        data = (maps / f"good{ext}").read_bytes()
        (maps / f"trunc{ext}").write_bytes(data[: len(data) // 2])
    bright = good.copy()
    bright[3, 3] = 1e6
    write_exr(maps / "bright.exr", bright)
    nanmap = good.copy()
    nanmap[3, 4] = np.nan
    write_exr(maps / "nan.exr", nanmap)
    w["maps"] = maps
    # masks
    m = np.zeros((24, 24), np.uint8)
    m[6:18, 6:18] = 255
    write_png(root / "mask.png", m)
    data = (root / "mask.png").read_bytes()
    (root / "mask_trunc.png").write_bytes(data[: len(data) // 2])
    w["mask_trunc"] = root / "mask_trunc.png"
    # composite: backgrounds, surface masks, and a capture of another camera (K changed)
    write_exr(root / "bg.exr", np.full((24, 24, 3), 0.2, np.float32))
    write_exr(root / "bg_small.exr", np.full((20, 24, 3), 0.2, np.float32))
    write_exr(root / "bg_negative.exr", np.full((24, 24, 3), -9.8, np.float32))
    write_png(root / "bg.png", np.full((24, 24, 3), 50, np.uint8))
    sm = np.zeros((24, 24), np.uint8)
    sm[18:, :] = 255
    write_png(root / "surf.png", sm)
    write_png(root / "surf_empty.png", np.zeros((24, 24), np.uint8))
    write_png(root / "mask_small.png", np.full((20, 20), 255, np.uint8))
    write_png(root / "mask_empty.png", np.zeros((24, 24), np.uint8))
    w["cap_copy"] = copy("cap_copy")  # the object capture copied: composite's --surface must not be it
    (root / "shot.exr").mkdir()  # a screenshot's sibling HDR path taken by a folder
    c = root / "few_cam"
    shutil.copytree(few, c)
    doc = json.loads((c / "capture.json").read_text())
    doc["camera"]["K"][0][0] *= 1.5
    doc["camera"]["K"][1][1] *= 1.5
    (c / "capture.json").write_text(json.dumps(doc))
    w["few_cam"] = c
    # a folder where a file is wanted, a file where a folder is wanted
    (root / "isdir.exr").mkdir()
    (root / "isdir.png").mkdir()
    (root / "afile").write_text("x")
    # bracket folder for calibrate response
    br = root / "bracket"
    br.mkdir()
    for k, t in enumerate((0.01, 0.04, 0.16)):
        write_png(br / f"b{k}.png", (np.random.default_rng(k).random((16, 16, 3)) * 255).astype(np.uint8))
    (br / "exposures.json").write_text(json.dumps({f"b{k}.png": t for k, t in enumerate((0.01, 0.04, 0.16))}))
    w["bracket"] = br
    brm = root / "bracket_unlisted"  # exposures.json leaves a photo out
    shutil.copytree(br, brm)
    (brm / "exposures.json").write_text(json.dumps({"b0.png": 0.01, "b2.png": 0.16}))
    w["bracket_unlisted"] = brm
    # brackets that cannot calibrate a response: one photo copied three times, all black, all saturated
    for name, make in (("ident", lambda k: (np.random.default_rng(0).random((16, 16, 3)) * 255).astype(np.uint8)),
                       ("black", lambda k: np.zeros((16, 16, 3), np.uint8)),
                       ("sat", lambda k: np.full((16, 16, 3), 255, np.uint8))):
        b = root / f"bracket_{name}"
        b.mkdir()
        for k in range(3):
            write_png(b / f"b{k}.png", make(k))
        (b / "exposures.json").write_text((br / "exposures.json").read_text())
        w[f"bracket_{name}"] = b
    return w



def _run(capfd, argv, where: Path):
    """main(argv) -> (rc, stderr lines, entries of `where` before and after)."""
    before = entries(where)
    capfd.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    return rc, out, [ln for ln in err.splitlines() if ln.strip()], before, entries(where)


# ----------------------------------------------------------------------------- the table
# Each row: id, argv (with {cap}, {root}, {maps}, ... placeholders), what the line must name,
# and the output path that must not appear ("" when the case writes nothing by design).
R = ["render", "{cap}", "--probe", "sky", "--cpu"]
L = ["relight", "{cap}", "--probe", "sky"]
C = ["composite", "--object", "{cap}", "--surface", "{few}", "--lightmap", "sky", "--background", "{root}/bg.exr"]
CASES = [
    # --- numeric arguments: render / relight
    ("render-rank-0", R + ["--rank", "0", "-o", "{out}/a.png"], "--rank", "a.png"),
    ("render-rank-neg", R + ["--rank", "-1", "-o", "{out}/a.png"], "--rank", "a.png"),
    ("render-rank-huge", R + ["--rank", "1000000", "-o", "{out}/a.png"], "--rank", "a.png"),
    ("render-rank-abc", R + ["--rank", "abc", "-o", "{out}/a.png"], "--rank", "a.png"),
    ("render-rotz-nan", R + ["--rotate-z", "nan", "-o", "{out}/a.png"], "--rotate-z", "a.png"),
    ("render-rotz-inf", R + ["--rotate-z", "inf", "-o", "{out}/a.png"], "--rotate-z", "a.png"),
    ("render-rotz-abc", R + ["--rotate-z", "abc", "-o", "{out}/a.png"], "--rotate-z", "a.png"),
    ("render-rot-nan", R + ["--rotate", "nan,0,0", "-o", "{out}/a.png"], "--rotate", "a.png"),
    ("render-rot-4", R + ["--rotate", "1,2,3,4", "-o", "{out}/a.png"], "--rotate", "a.png"),
    ("render-rot-inf", R + ["--rotate", "0,inf", "-o", "{out}/a.png"], "--rotate", "a.png"),
    ("render-exp-nan", R + ["--exposure", "nan", "-o", "{out}/a.png"], "--exposure", "a.png"),
    ("render-exp-inf", R + ["--exposure", "inf", "-o", "{out}/a.png"], "--exposure", "a.png"),
    ("render-exp--inf", R + ["--exposure=-inf", "-o", "{out}/a.png"], "--exposure", "a.png"),
    ("render-exp-huge", R + ["--exposure", "1e9", "-o", "{out}/a.png"], "--exposure", "a.png"),
    ("render-cells-0", R + ["--cells-res", "0", "-o", "{out}/a.png"], "--cells-res", "a.png"),
    ("render-cells-neg", R + ["--cells-res", "-3", "-o", "{out}/a.png"], "--cells-res", "a.png"),
    ("render-cells-huge", R + ["--cells-res", "100000", "-o", "{out}/a.png"], "--cells-res", "a.png"),
    ("render-cells-1", R + ["--cells-res", "1", "-o", "{out}/a.png"], "--cells-res", "a.png"),
    ("render-cells-float", R + ["--cells-res", "2.5", "-o", "{out}/a.png"], "--cells-res", "a.png"),
    ("render-turntable-0", R + ["--turntable", "0", "-o", "{out}/t.mp4"], "--turntable", "t.mp4"),
    ("render-turntable-neg", R + ["--turntable", "-3", "-o", "{out}/t.mp4"], "--turntable", "t.mp4"),
    ("render-fps-nan", R + ["--turntable", "3", "--fps", "nan", "-o", "{out}/t.mp4"], "--fps", "t.mp4"),
    ("render-fps-0", R + ["--turntable", "3", "--fps", "0", "-o", "{out}/t.mp4"], "--fps", "t.mp4"),
    ("render-fps-inf", R + ["--turntable", "3", "--fps", "inf", "-o", "{out}/t.mp4"], "--fps", "t.mp4"),
    ("render-fps-neg", R + ["--turntable", "3", "--fps=-5", "-o", "{out}/frames"], "--fps", "frames"),
    # a video has no alpha: a --mask that would not even meter --exposure auto is refused, not ignored
    ("render-turntable-mask", R + ["--turntable", "3", "--mask", "{root}/mask.png", "-o", "{out}/t.mp4"], "--mask",
     "t.mp4"),
    ("render-out-suffix", R + ["-o", "{out}/a.txt"], "a.txt", "a.txt"),
    ("relight-rotz-nan", L + ["--rotate-z", "nan", "-o", "{out}/a.exr"], "--rotate-z", "a.exr"),
    ("relight-rot-nan", L + ["--rotate", "nan,0,0", "-o", "{out}/a.exr"], "--rotate", "a.exr"),
    ("relight-exp-nan", L + ["--exposure", "nan", "-o", "{out}/a.png"], "--exposure", "a.png"),
    ("relight-exp-inf", L + ["--exposure", "inf", "-o", "{out}/a.png"], "--exposure", "a.png"),
    ("relight-cells-neg", L + ["--cells-res", "-3", "-o", "{out}/a.exr"], "--cells-res", "a.exr"),
    ("relight-cells-huge", L + ["--cells-res", "100000", "-o", "{out}/a.exr"], "--cells-res", "a.exr"),
    ("relight-cells-1", L + ["--cells-res", "1", "-o", "{out}/a.exr"], "--cells-res", "a.exr"),
    ("relight-out-suffix", L + ["-o", "{out}/a.jpg"], "a.jpg", "a.jpg"),
    ("relight-layout-abc", L + ["--layout", "abc", "-o", "{out}/a.exr"], "--layout", "a.exr"),
    ("relight-layout-builtin", L + ["--layout", "latlong", "-o", "{out}/a.exr"], "--layout", "a.exr"),
    ("relight-lights-empty", L + ["--lights", "", "-o", "{out}/a.exr"], "--lights", "a.exr"),
    ("relight-mask-empty", L + ["--mask", "", "-o", "{out}/a.exr"], "--mask", "a.exr"),
    ("render-lights-map-empty", R + ["--lights-map", "", "-o", "{out}/a.png"], "--lights-map", "a.png"),
    # --- lightmap
    ("lm-height-0", ["lightmap", "make", "sky", "{out}/m.exr", "--height", "0"], "--height", "m.exr"),
    ("lm-height-neg", ["lightmap", "make", "sky", "{out}/m.exr", "--height", "-5"], "--height", "m.exr"),
    ("lm-height-huge", ["lightmap", "make", "sky", "{out}/m.exr", "--height", "1000000"], "--height", "m.exr"),
    ("lm-height-1", ["lightmap", "make", "paper", "{out}/m.exr", "--height", "1"], "--height", "m.exr"),
    ("lm-height-abc", ["lightmap", "make", "sky", "{out}/m.exr", "--height", "abc"], "--height", "m.exr"),
    ("lm-make-suffix", ["lightmap", "make", "sky", "{out}/m.png"], "m.png", "m.png"),
    ("lm-tolat-neg", ["lightmap", "convert", "{maps}/good.exr", "{out}/m.exr", "--to-latlong", "-4"],
     "--to-latlong", "m.exr"),
    ("lm-tolat-0", ["lightmap", "convert", "{maps}/good.exr", "{out}/m.exr", "--to-latlong", "0"],
     "--to-latlong", "m.exr"),
    ("lm-tolat-huge", ["lightmap", "convert", "{maps}/good.exr", "{out}/m.exr", "--to-latlong", "100000"],
     "--to-latlong", "m.exr"),
    ("lm-convert-1x1", ["lightmap", "convert", "{maps}/one.exr", "{out}/m.exr"], "one.exr", "m.exr"),
    ("lm-convert-2x1", ["lightmap", "convert", "{maps}/two.exr", "{out}/m.exr"], "two.exr", "m.exr"),
    ("lm-convert-2x1-hdr", ["lightmap", "convert", "{maps}/two.hdr", "{out}/m.hdr"], "two.hdr", "m.hdr"),
    ("lm-convert-2x2", ["lightmap", "convert", "{maps}/tiny_angular.exr", "{out}/m.exr"], "tiny_angular.exr",
     "m.exr"),
    ("lm-info-1x1", ["lightmap", "info", "{maps}/one.exr"], "one.exr", ""),
    ("lm-info-trunc-exr", ["lightmap", "info", "{maps}/trunc.exr"], "trunc.exr", ""),
    ("lm-info-trunc-hdr", ["lightmap", "info", "{maps}/trunc.hdr"], "trunc.hdr", ""),
    ("lm-info-nan", ["lightmap", "info", "{maps}/nan.exr"], "nan.exr", ""),
    ("lm-convert-onto-input", ["lightmap", "convert", "{maps}/good.exr", "{maps}/good.exr"], "good.exr", ""),
    ("lm-convert-missing", ["lightmap", "convert", "{maps}/nope.exr", "{out}/m.exr"], "nope.exr", "m.exr"),
    # --- calibrate
    ("cal-samples-0", ["calibrate", "response", "{bracket}", "--samples", "0", "-o", "{out}/r.npy"],
     "--samples", "r.npy"),
    ("cal-samples-neg", ["calibrate", "response", "{bracket}", "--samples", "-5", "-o", "{out}/r.npy"],
     "--samples", "r.npy"),
    ("cal-smooth-nan", ["calibrate", "response", "{bracket}", "--smoothness", "nan", "-o", "{out}/r.npy"],
     "--smoothness", "r.npy"),
    ("cal-smooth-neg", ["calibrate", "response", "{bracket}", "--smoothness=-1", "-o", "{out}/r.npy"],
     "--smoothness", "r.npy"),
    ("cal-samples-grid", ["calibrate", "response", "{bracket}", "--samples", "300", "-o", "{out}/r.npy"],
     "--samples 300", "r.npy"),
    ("cal-photo-unlisted", ["calibrate", "response", "{bracket_unlisted}", "-o", "{out}/r.npy"], "b1.png", "r.npy"),
    ("cal-bracket-identical", ["calibrate", "response", "{bracket_ident}", "-o", "{out}/r.npy"],
     "bracket_ident: the 3 photos are identical", "r.npy"),
    ("cal-bracket-black", ["calibrate", "response", "{bracket_black}", "-o", "{out}/r.npy"],
     "bracket_black: every pixel", "r.npy"),
    ("cal-bracket-saturated", ["calibrate", "response", "{bracket_sat}", "-o", "{out}/r.npy"],
     "bracket_sat: every pixel", "r.npy"),
    ("merge-calibrate-identical", ["probe", "merge", "{bracket_ident}/b0.png", "{bracket_ident}/b1.png",
                                   "{bracket_ident}/b2.png", "--exposures", "0.01,0.04,0.16", "--encoding",
                                   "calibrate", "-o", "{out}/m.exr"], "photos are identical", "m.exr"),
    ("cal-out-suffix", ["calibrate", "response", "{bracket}", "-o", "{out}/r.txt"], "r.txt", "r.txt"),
    ("cal-squares-0", ["calibrate", "camera", "{maps}/good.exr", "--squares", "0x5"], "--squares", ""),
    ("cal-squares-abc", ["calibrate", "camera", "{maps}/good.exr", "--squares", "abc"], "--squares", ""),
    ("cal-square-nan", ["calibrate", "camera", "{maps}/good.exr", "--square-size", "nan"], "--square-size", ""),
    ("cal-marker-neg", ["calibrate", "camera", "{maps}/good.exr", "--marker-size=-1"], "--marker-size", ""),
    ("cal-dictionary-unknown", ["calibrate", "camera", "{maps}/good.exr", "--dictionary", "DICT_FOO"], "--dictionary",
     ""),
    ("cal-marker-over-square", ["calibrate", "camera", "{maps}/good.exr", "--marker-size", "0.05", "--square-size",
                                "0.03"], "--marker-size", ""),
    ("cal-marker-chessboard", ["calibrate", "camera", "{maps}/good.exr", "--board", "chessboard", "--marker-size",
                               "0.5"], "--marker-size", ""),
    ("cal-dictionary-chessboard", ["calibrate", "camera", "{maps}/good.exr", "--board", "chessboard", "--dictionary",
                                   "DICT_4X4_50"], "--dictionary", ""),
    ("cal-dictionary-small", ["calibrate", "camera", "{maps}/good.exr", "--squares", "20x20", "--dictionary",
                              "DICT_4X4_50"], "--dictionary", ""),
    # --- demo
    ("demo-rot-abc", ["demo", "-o", "{out}/d", "--rotations", "abc", "--no-view"], "--rotations", "d"),
    ("demo-rot-nan", ["demo", "-o", "{out}/d", "--rotations", "0,nan", "--no-view"], "--rotations", "d"),
    ("demo-rot-empty", ["demo", "-o", "{out}/d", "--rotations", "", "--no-view"], "--rotations", "d"),
    ("demo-lights-0", ["demo", "-o", "{out}/d", "--lights", "0", "--no-view"], "--lights", "d"),
    ("demo-res-huge", ["demo", "-o", "{out}/d", "--resolution", "100000", "--no-view"], "--resolution", "d"),
    ("demo-seed-neg", ["demo", "-o", "{out}/d", "--seed", "-1", "--no-view"], "--seed", "d"),
    ("demo-maps-repeat", ["demo", "-o", "{out}/d", "--maps", "studio,studio", "--no-view"], "--maps", "d"),
    ("demo-rot-repeat", ["demo", "-o", "{out}/d", "--rotations", "0,360", "--no-view"], "--rotations", "d"),
    ("demo-out-missing", ["demo", "-o", "{out}/no/d", "--no-view"], "no", "no"),
    # --- synth
    ("synth-res-huge", ["synth", "{out}/s", "--resolution", "100000"], "--resolution", "s"),
    ("synth-res-0", ["synth", "{out}/s", "--resolution", "0"], "--resolution", "s"),
    ("synth-albedo-inf", ["synth", "{out}/s", "--ground-albedo", "inf"], "--ground-albedo", "s"),
    ("synth-albedo-nan", ["synth", "{out}/s", "--ground-albedo", "nan"], "--ground-albedo", "s"),
    ("synth-albedo-neg", ["synth", "{out}/s", "--ground-albedo=-1"], "--ground-albedo", "s"),
    ("synth-near-inf", ["synth", "{out}/s", "--near", "inf"], "--near", "s"),
    ("synth-near-0", ["synth", "{out}/s", "--near", "0"], "--near", "s"),
    ("synth-near-nan", ["synth", "{out}/s", "--near", "nan"], "--near", "s"),
    ("synth-radius-inf", ["synth", "{out}/s", "--near", "2", "--light-radius", "inf"], "--light-radius", "s"),
    ("synth-radius-neg", ["synth", "{out}/s", "--light-radius=-1"], "--light-radius", "s"),
    ("synth-radius-big", ["synth", "{out}/s", "--near", "2", "--light-radius", "3"], "--light-radius", "s"),
    ("synth-lights-0", ["synth", "{out}/s", "--lights", "0"], "--lights", "s"),
    ("synth-noise-nan", ["synth", "{out}/s", "--noise", "nan"], "--noise", "s"),
    ("synth-out-file", ["synth", "{root}/afile", "--lights", "2", "--resolution", "8"], "afile", ""),
    ("synth-out-missing", ["synth", "{out}/no/s"], "no", "no"),
    # --- lights
    ("lights-mixed-depths", ["lights", "{cap_mixed}", "-o", "{out}/l.json"],
     "img_0001.png: bit depth 8 differs from the first image's (half)", "l.json"),
    ("lights-transparent-photo", ["lights", "{cap_alpha}", "-o", "{out}/l.json"],
     "img_0004.png: has transparent pixels (alpha below 1 in 41.7% of them)", "l.json"),
    ("relight-transparent-photo", ["relight", "{cap_alpha}", "--probe", "sky", "-o", "{out}/r.exr"],
     "img_0004.png: has transparent pixels", "r.exr"),
    ("lights-folder-as-image", ["lights", "{cap_dirimg}", "-o", "{out}/l.json"],
     "listed image 'img_0002.exr' is a folder, not a file", "l.json"),
    ("lights-workers-0", ["lights", "{cap}", "--workers", "0", "-o", "{out}/l.json"], "--workers", "l.json"),
    ("lights-workers-1000", ["lights", "{cap}", "--workers", "1000", "-o", "{out}/l.json"], "--workers", "l.json"),
    ("lights-workers-neg", ["lights", "{cap}", "--workers", "-2", "-o", "{out}/l.json"], "--workers", "l.json"),
    ("lights-plot-missing", ["lights", "{cap}", "-o", "{out}/l.json", "--plot", "{out}/missing/p.png"],
     "missing", "l.json"),
    ("lights-plot-txt", ["lights", "{cap}", "-o", "{out}/l.json", "--plot", "{out}/p.txt"], "p.txt", "l.json"),
    ("lights-out-dir", ["lights", "{cap}", "-o", "{root}/isdir.exr"], "isdir.exr", ""),
    ("lights-lp-suffix", ["lights", "{cap}", "-o", "{out}/l.json", "--lp", "{out}/x.txt"], "x.txt", "l.json"),
    ("lights-scheduler-noport", ["lights", "{cap}", "-o", "{out}/l.json", "--scheduler", "foo"], "--scheduler",
     "l.json"),
    ("lights-scheduler-port", ["lights", "{cap}", "-o", "{out}/l.json", "--scheduler", "tcp://h:99999"],
     "--scheduler", "l.json"),
    ("lights-scheduler-scheme", ["lights", "{cap}", "-o", "{out}/l.json", "--scheduler", "xyz://h:3"],
     "--scheduler", "l.json"),
    ("lights-scheduler-nohost", ["lights", "{cap}", "-o", "{out}/l.json", "--scheduler", "tcp://:80"],
     "--scheduler", "l.json"),
    ("ingest-scheduler-noport", ["ingest", "{cap}", "--store", "{out}/s.zarr", "--scheduler", "foo"], "--scheduler",
     "s.zarr"),
    ("relight-scheduler-noport", L + ["--scheduler", "foo", "-o", "{out}/a.exr"], "--scheduler", "a.exr"),
    # --- output paths
    ("out-is-folder-exr", R + ["-o", "{root}/isdir.exr"], "isdir.exr", ""),
    ("out-is-folder-png", L + ["-o", "{root}/isdir.png"], "isdir.png", ""),
    ("out-no-parent", R + ["-o", "{out}/nope/a.png"], "nope", "nope"),
    ("out-parent-is-file", R + ["-o", "{root}/afile/a.png"], "afile", ""),
    ("out-proc", R + ["-o", "/proc/x.exr"], "/proc", ""),
    ("out-turntable-file", R + ["--turntable", "2", "-o", "{root}/afile"], "afile", ""),
    ("out-onto-input", L + ["-o", "{cap}/img_0000.exr"], "img_0000.exr", ""),
    # a still's coverage notes wait for its success: an output error is the only line
    ("few-render-onto-input", ["render", "{few}", "--probe", "sky", "--cpu", "-o", "{few}/img_0000.exr"],
     "img_0000.exr", ""),
    ("few-relight-onto-input", ["relight", "{few}", "--probe", "sky", "-o", "{few}/img_0000.exr"],
     "img_0000.exr", ""),
    ("view-screenshot-missing-folder", ["view", "{cap}", "--headless", "--frames", "1", "--screenshot",
                                        "{out}/missing/s.png"], "--screenshot", "missing"),
    ("view-screenshot-not-png", ["view", "{cap}", "--headless", "--frames", "1", "--screenshot", "{out}/s.txt"],
     "--screenshot", "s.txt"),
    ("view-frames-0", ["view", "{cap}", "--headless", "--frames", "0"], "--frames", ""),
    ("out-onto-mask", L + ["--mask", "{root}/mask.png", "-o", "{root}/mask.png"], "mask.png", ""),
    ("out-onto-probe", ["relight", "{cap}", "--probe", "{maps}/good.exr", "-o", "{maps}/good.exr"],
     "good.exr", ""),
    # --- data
    ("photo-nan", ["relight", "{cap_nan}", "--probe", "sky", "-o", "{out}/a.exr"], "img_0003.exr", "a.exr"),
    ("photo-inf", ["relight", "{cap_inf}", "--probe", "sky", "-o", "{out}/a.exr"], "img_0003.exr", "a.exr"),
    ("photo-nan-render", ["render", "{cap_nan}", "--probe", "sky", "--cpu", "-o", "{out}/a.png"], "img_0003.exr",
     "a.png"),
    ("photo-trunc", ["relight", "{cap_trunc}", "--probe", "sky", "-o", "{out}/a.exr"], "img_0002.exr", "a.exr"),
    ("probe-1x1", L[:3] + ["{maps}/one.exr", "-o", "{out}/a.exr"], "one.exr", "a.exr"),
    ("probe-2x1", L[:3] + ["{maps}/two.exr", "-o", "{out}/a.exr"], "two.exr", "a.exr"),
    ("probe-trunc-exr", L[:3] + ["{maps}/trunc.exr", "-o", "{out}/a.exr"], "trunc.exr", "a.exr"),
    ("probe-trunc-hdr", L[:3] + ["{maps}/trunc.hdr", "-o", "{out}/a.exr"], "trunc.hdr", "a.exr"),
    ("probe-nan", L[:3] + ["{maps}/nan.exr", "-o", "{out}/a.exr"], "nan.exr", "a.exr"),
    ("mask-trunc", L + ["--mask", "{mask_trunc}", "-o", "{out}/a.png"], "mask_trunc.png", "a.png"),
    ("lights-version-true", L + ["--lights", "{l_version_true}", "-o", "{out}/a.exr"], "version_true.json",
     "a.exr"),
    ("lights-version-float", L + ["--lights", "{l_version_float}", "-o", "{out}/a.exr"], "version_float.json",
     "a.exr"),
    ("lights-dir-1e308", L + ["--lights", "{l_huge}", "-o", "{out}/a.exr"], "huge.json", "a.exr"),
    ("lights-dir--1e308", L + ["--lights", "{l_huge_neg}", "-o", "{out}/a.exr"], "huge_neg.json", "a.exr"),
    ("lights-dir-bool", L + ["--lights", "{l_bool_dir}", "-o", "{out}/a.exr"], "bool_dir.json", "a.exr"),
    ("lights-unc-bool", L + ["--lights", "{l_unc_bool}", "-o", "{out}/a.exr"], "unc_bool.json", "a.exr"),
    ("lights-none-ok", L + ["--lights", "{l_none_ok}", "-o", "{out}/a.exr"], "none_ok.json", "a.exr"),
    ("lp-1e308", L + ["--lights", "{lp_huge}", "-o", "{out}/a.exr"], "huge.lp", "a.exr"),
    ("capture-version-true", ["relight", "{cap_version_true}", "--probe", "sky", "-o", "{out}/a.exr"],
     "capture.json", "a.exr"),
    ("few-nan", ["relight", "{few_nan}", "--probe", "sky", "-o", "{out}/a.exr"], "img_0005.exr", "a.exr"),
    ("few-nan-render", ["render", "{few_nan}", "--probe", "sky", "--cpu", "-o", "{out}/a.png"], "img_0005.exr",
     "a.png"),
    ("few-size", ["relight", "{few_size}", "--probe", "sky", "-o", "{out}/a.exr"], "img_0005.exr", "a.exr"),
    ("few-rank", ["render", "{few}", "--probe", "sky", "--cpu", "--rank", "8", "-o", "{out}/a.png"], "--rank",
     "a.png"),
    ("render-rot-huge", R + ["--rotate", "1e300,0,0", "-o", "{out}/a.png"], "--rotate", "a.png"),
    ("relight-rotz-huge", L + ["--rotate-z", "1e300", "-o", "{out}/a.png"], "--rotate-z", "a.png"),
    ("lm-half-overflow", ["lightmap", "convert", "{maps}/bright.exr", "{out}/m.exr", "--half"], "m.exr", "m.exr"),
    ("cal-camera-missing", ["calibrate", "camera", "{root}/nothere.png"], "nothere.png", ""),
    ("demo-maps-unknown", ["demo", "-o", "{out}/d", "--maps", "nosuch", "--no-view"], "--maps", "d"),
    ("render-probe-unknown", R[:3] + ["nosuchmap", "--cpu", "-o", "{out}/a.png"], "nosuchmap", "a.png"),
    ("relight-mask-missing", L + ["--mask", "{root}/nomask.png", "-o", "{out}/a.png"], "nomask.png", "a.png"),
    ("relight-lights-map-bad", L + ["--lights-map", "{{bad", "-o", "{out}/a.exr"], "--lights-map", "a.exr"),
    # --- composite
    ("comp-mask-size", C + ["--mask", "{root}/mask_small.png", "--surface-mask", "{root}/surf.png", "-o",
                            "{out}/c.exr"], "mask_small.png", "c.exr"),
    ("comp-surf-mask-size", C + ["--mask", "{root}/mask.png", "--surface-mask", "{root}/mask_small.png", "-o",
                                 "{out}/c.exr"], "mask_small.png", "c.exr"),
    ("comp-no-surface", C + ["--mask", "{root}/mask.png", "--surface-mask", "{root}/surf_empty.png", "-o",
                             "{out}/c.exr"], "surf_empty.png", "c.exr"),
    ("comp-surface-is-object", C + ["--mask", "{root}/mask.png", "--surface-mask", "{root}/mask.png", "-o",
                                    "{out}/c.exr"], "no surface pixel", "c.exr"),
    ("comp-other-camera", ["composite", "--object", "{cap}", "--surface", "{few_cam}", "--lightmap", "sky",
                           "--background", "{root}/bg.exr", "--mask", "{root}/mask.png", "--surface-mask",
                           "{root}/surf.png", "-o", "{out}/c.exr"], "different camera", "c.exr"),
    ("comp-bg-size", ["composite", "--object", "{cap}", "--surface", "{few}", "--lightmap", "sky", "--background",
                      "{root}/bg_small.exr", "--mask", "{root}/mask.png", "--surface-mask", "{root}/surf.png", "-o",
                      "{out}/c.exr"], "bg_small.exr", "c.exr"),
    ("comp-bg-negative", ["composite", "--object", "{cap}", "--surface", "{few}", "--lightmap", "sky", "--background",
                          "{root}/bg_negative.exr", "--mask", "{root}/mask.png", "--surface-mask", "{root}/surf.png",
                          "-o", "{out}/c.exr"], "bg_negative.exr: the background has negative values in 100.0%",
     "c.exr"),
    ("comp-bg-png", ["composite", "--object", "{cap}", "--surface", "{few}", "--lightmap", "sky", "--background",
                     "{root}/bg.png", "--mask", "{root}/mask.png", "--surface-mask", "{root}/surf.png", "-o",
                     "{out}/c.exr"], "bg.png", "c.exr"),
    ("comp-out-suffix", C + ["--mask", "{root}/mask.png", "--surface-mask", "{root}/surf.png", "-o",
                             "{out}/c.jpg"], "c.jpg", "c.jpg"),
    ("comp-turntable-still", C + ["--mask", "{root}/mask.png", "--surface-mask", "{root}/surf.png", "--turntable",
                                  "3", "-o", "{out}/c.exr"], "c.exr", "c.exr"),
    ("comp-rank", C + ["--mask", "{root}/mask.png", "--surface-mask", "{root}/surf.png", "--rank", "20", "-o",
                       "{out}/c.exr"], "--rank", "c.exr"),
    ("comp-lightmap-unknown", ["composite", "--object", "{cap}", "--surface", "{few}", "--lightmap", "nosuchmap",
                               "--background", "{root}/bg.exr", "--mask", "{root}/mask.png", "--surface-mask",
                               "{root}/surf.png", "-o", "{out}/c.exr"], "nosuchmap", "c.exr"),
    ("comp-onto-background", C + ["--mask", "{root}/mask.png", "--surface-mask", "{root}/surf.png", "-o",
                                  "{root}/bg.exr"], "bg.exr", ""),
    ("comp-png-sibling-onto-input", C + ["--mask", "{root}/mask.png", "--surface-mask", "{root}/surf.png", "-o",
                                         "{root}/mask.exr"], "mask.png", ""),
    ("view-composite-no-mask", ["view", "{cap}", "--headless", "--frames", "1", "--composite-surface", "{few}",
                                "--background", "{root}/bg.exr", "--surface-mask", "{root}/surf.png"], "--mask", ""),
    ("view-background-alone", ["view", "{cap}", "--headless", "--frames", "1", "--background", "{root}/bg.exr"],
     "--composite-surface", ""),
    ("view-composite-camera", ["view", "{cap}", "--headless", "--frames", "1", "--composite-surface", "{few_cam}",
                               "--background", "{root}/bg.exr", "--surface-mask", "{root}/surf.png", "--mask",
                               "{root}/mask.png"], "different camera", ""),
    ("synth-composite-near", ["synth", "{out}/s", "--composite-set", "sky", "--near", "2"], "--near", "s"),
    ("synth-composite-map", ["synth", "{out}/s", "--composite-set", "nosuchmap"], "nosuchmap", "s"),
    ("synth-composite-wall", ["synth", "{out}/s", "--composite-set", "sky", "--wall-albedo", "1,2"],
     "--wall-albedo", "s"),
    ("synth-surface-lights-alone", ["synth", "{out}/s", "--surface-lights", "5"], "--surface-lights", "s"),
    ("synth-scene-albedo-alone", ["synth", "{out}/s", "--scene-albedo", "0.4"], "--scene-albedo", "s"),
    ("synth-wall-alone", ["synth", "{out}/s", "--wall-albedo", "none"], "--wall-albedo", "s"),
    ("synth-truth-dirs-alone", ["synth", "{out}/s", "--truth-dirs", "100"], "--truth-dirs", "s"),
    ("synth-radius-distant", ["synth", "{out}/s", "--light-radius", "0.1"], "--light-radius", "s"),
    ("synth-sphere-out-of-frame", ["synth", "{out}/s", "--sphere-xy=-0.25,-0.25;100,100", "--lights", "2",
                                   "--resolution", "16"], "--sphere-xy 100,100", "s"),
    ("render-missing-capture", ["render", "{root}/nocap", "--probe", "sky", "--cpu", "-o", "{out}/a.png"],
     "nocap", "a.png"),
]


# Found by the round-7 tester (briefs s7/fixview): each exited 0, left a partial output, hung, or
# printed a traceback before.
_M = ["--mask", "{root}/mask.png", "--surface-mask", "{root}/surf.png"]
CASES += [
    ("view-size-0", ["view", "{cap}", "--headless", "--frames", "1", "--size", "0x0"], "--size", ""),
    ("view-auto-rotate-nan", ["view", "{cap}", "--headless", "--frames", "1", "--auto-rotate", "nan"],
     "--auto-rotate", ""),
    ("view-auto-rotate-inf", ["view", "{cap}", "--headless", "--frames", "1", "--auto-rotate", "inf"],
     "--auto-rotate", ""),
    ("view-auto-rotate-1e300", ["view", "{cap}", "--headless", "--frames", "1", "--auto-rotate", "1e300"],
     "--auto-rotate", ""),
    ("view-screenshot-sibling-folder", ["view", "{cap}", "--headless", "--frames", "1", "--screenshot",
                                        "{root}/shot.png"], "shot.exr", ""),
    ("view-headless-no-frames", ["view", "{cap}", "--headless", "--screenshot", "{out}/c.png"], "--frames", "c.png"),
    ("view-headless-fullscreen", ["view", "{cap}", "--headless", "--frames", "1", "--fullscreen"], "--fullscreen",
     ""),
    ("view-light-and-probe", ["view", "{cap}", "--headless", "--frames", "1", "--light", "10,45", "--probe",
                              "studio"], "--light", ""),
    ("relight-mask-all-black", L + ["--mask", "{root}/mask_empty.png", "--exposure", "auto", "-o", "{out}/b.png"],
     "mask_empty.png", "b.png"),
    ("render-mask-all-black", R + ["--mask", "{root}/mask_empty.png", "--exposure", "auto", "-o", "{out}/b.png"],
     "mask_empty.png", "b.png"),
    ("comp-mask-all-black", C + ["--mask", "{root}/mask_empty.png", "--surface-mask", "{root}/surf.png", "-o",
                             "{out}/c.png"], "mask_empty.png", "c.png"),
    ("comp-surface-same-folder", ["composite", "--object", "{cap}", "--surface", "{cap}", *C[5:], *_M, "-o",
                                  "{out}/c.png"], "--surface", "c.png"),
    ("comp-surface-copy", ["composite", "--object", "{cap}", "--surface", "{cap_copy}", *C[5:], *_M, "-o",
                           "{out}/c.png"], "--surface", "c.png"),
    ("relight-exr-exposure", L + ["--exposure", "3", "--tonemap", "aces", "-o", "{out}/e.exr"], "--exposure", "e.exr"),
    ("relight-exr-tonemap", L + ["--tonemap", "aces", "-o", "{out}/e.exr"], "--tonemap", "e.exr"),
    ("render-exr-exposure-auto", R + ["--exposure", "auto", "-o", "{out}/e.exr"], "--exposure", "e.exr"),
    ("render-still-fps", R + ["--fps", "24", "-o", "{out}/p.png"], "--fps", "p.png"),
    ("comp-still-fps", C + [*_M, "--fps", "5", "-o", "{out}/o.png"], "--fps", "o.png"),
    ("render-frames-fps", R + ["--turntable", "3", "--fps", "24", "-o", "{out}/frames"], "--fps", "frames"),
    ("comp-frames-fps", C + [*_M, "--turntable", "3", "--fps", "5", "-o", "{out}/frames"], "--fps", "frames"),
]

# --fill (round 11): the fill relights the compact sources where the spheres hide them, from the
# spheres' world centres (capture.json or found in the photos; none at 24 px)
CASES += [
    ("comp-fill-weights", C + [*_M, "--sources", "weights", "--fill", "model", "-o", "{out}/c.exr"],
     "--fill model", "c.exr"),
    ("comp-fill-no-spheres", C + [*_M, "--fill", "rest+model", "-o", "{out}/c.exr"],
     "--fill needs the calibration spheres' world centres", "c.exr"),
]


def _fill(argv, ws, out):
    keys = {k: str(v) for k, v in ws.items()}
    keys["out"] = str(out)
    return [a.format(**keys) for a in argv]


@pytest.mark.parametrize("argv,names,output", [pytest.param(a, n, o, id=i) for i, a, n, o in CASES])
def test_bad_input_is_one_line(ws, tmp_path, capfd, argv, names, output):
    out = tmp_path / "out"
    out.mkdir()
    args = _fill(argv, ws, out)
    watched = [out, ws["root"], ws["cap"], ws["maps"]]
    before = {w: entries(w) for w in watched}
    capfd.readouterr()
    rc = main(args)
    stdout, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, (rc, err)
    assert "Traceback" not in err and "Traceback" not in stdout
    assert len(lines) == 1, err
    assert "error" in lines[0] and names in lines[0], lines[0]
    assert "WARN" not in lines[0] and "libpng" not in lines[0]
    if output:
        assert not (out / output).exists()
    for w in watched:  # nothing written, no temporary left anywhere
        assert entries(w) == before[w], (w, entries(w) ^ before[w])


# ----------------------------------------------------------------------------- faults while writing
def _render_png(ws, out):
    return ["relight", str(ws["cap"]), "--probe", "sky", "-o", str(out)]


@pytest.mark.parametrize("kind", ["png", "exr", "hdr-map", "synth"])
def test_disk_full_mocked_is_one_line(ws, tmp_path, capfd, monkeypatch, kind):
    """ENOSPC from the file system (mocked at the final rename; test_real_full_disk_is_one_line has a real one)."""
    import ffls.errors

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(ffls.errors.os, "replace", full)
    argv = {
        "png": _render_png(ws, tmp_path / "a.png"),
        "exr": _render_png(ws, tmp_path / "a.exr"),
        "hdr-map": ["lightmap", "make", "sky", str(tmp_path / "m.hdr"), "--height", "8"],
        "json": ["synth", str(tmp_path / "s"), "--lights", "2", "--resolution", "8", "--quiet"],
    }[kind if kind != "synth" else "json"]
    capfd.readouterr()
    rc = main(argv)
    _, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip() and "error" in ln]
    assert rc == 2 and len(lines) == 1 and "disk full" in lines[0], err
    assert "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_composite_outputs_appear_together_or_not_at_all(ws, tmp_path, capfd, monkeypatch):
    """OUT.exr, OUT.png and OUT.json: a failure writing the PNG left a new OUT.exr alone (round 11,
    ``ffls.errors.atomic_outputs``)."""
    import ffls.io.images
    from ffls.errors import OutputError

    def full(path, *a, **k):
        raise OutputError("cannot write (no space left on the device (disk full))", path)

    monkeypatch.setattr(ffls.io.images, "write_png", full)
    argv = [a.format(**{k: str(v) for k, v in ws.items()}) for a in C] + [
        "--mask", str(ws["root"] / "mask.png"), "--surface-mask", str(ws["root"] / "surf.png"),
        "-o", str(tmp_path / "c.exr")]
    capfd.readouterr()
    rc = main(argv)
    err = [ln for ln in capfd.readouterr().err.splitlines() if "error" in ln]
    assert rc == 2 and len(err) == 1 and "disk full" in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_permission_denied_mocked_is_one_line(ws, tmp_path, capfd, monkeypatch):
    """A read-only folder (mocked: root ignores permission bits) gives one line naming the output."""
    import ffls.errors

    def denied(*a, **k):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(ffls.errors.tempfile, "mkstemp", denied)
    rc = main(["lightmap", "make", "sky", str(tmp_path / "m.exr"), "--height", "8"])
    err = capfd.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "m.exr" in err[0] and "permission denied" in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_read_only_file_system_is_one_line(ws, capfd):
    """/proc cannot take files: one line, nothing else."""
    rc = main(["lightmap", "make", "sky", "/proc/x.exr", "--height", "8"])
    err = capfd.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "/proc" in err[0], err


def test_imwrite_that_fails_silently_leaves_nothing(tmp_path, monkeypatch, capfd):
    """cv2.imwrite returning True without writing (as it may on a full disk) is caught by the size check."""
    import cv2

    def lying(path, img, *a):
        Path(path).write_bytes(b"")
        return True

    monkeypatch.setattr(cv2, "imwrite", lying)
    from ffls.errors import OutputError

    with pytest.raises(OutputError, match="empty file"):
        write_png(tmp_path / "a.png", np.zeros((4, 4, 3), np.uint8))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("cmd", ["lightmap-exr", "lightmap-hdr", "relight-png", "relight-exr"])
def test_real_full_disk_is_one_line(ws, tiny_tmpfs, capfd, cmd):
    """A really full disk: fill a 64 kB tmpfs, then write; one line, no 0-byte file."""
    fd = os.open(tiny_tmpfs / "filler", os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, b"\1" * 1024)
    except OSError as e:
        assert e.errno == errno.ENOSPC
    finally:
        os.close(fd)
    out = {"lightmap-exr": "m.exr", "lightmap-hdr": "m.hdr", "relight-png": "a.png", "relight-exr": "a.exr"}[cmd]
    if cmd.startswith("lightmap"):
        argv = ["lightmap", "make", "sky", str(tiny_tmpfs / out), "--height", "64"]
    else:
        argv = _render_png(ws, tiny_tmpfs / out)
    capfd.readouterr()
    rc = main(argv)
    _, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip() and "error" in ln]
    assert rc == 2 and len(lines) == 1 and out in lines[0], err
    assert "Traceback" not in err
    assert entries(tiny_tmpfs) == {"filler"}


def test_existing_output_survives_a_failed_write(ws, tmp_path, capfd, monkeypatch):
    import ffls.errors

    target = tmp_path / "m.exr"
    assert main(["lightmap", "make", "sky", str(target), "--height", "8"]) == 0
    old = target.read_bytes()

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(ffls.errors.os, "replace", full)
    assert main(["lightmap", "make", "sky", str(target), "--height", "16"]) == 2
    assert target.read_bytes() == old and entries(tmp_path) == {"m.exr"}


def test_cell_texture_too_coarse_for_the_lights_is_refused():
    """An overflowing cell texture gives wrong weights silently; the check names a resolution that works."""
    from ffls.commands.common import check_cells_res
    from ffls.errors import InputError

    d = np.random.default_rng(0).normal(size=(600, 3))
    d[:, 2] = np.abs(d[:, 2])
    with pytest.raises(InputError, match=r"--cells-res 16 is too coarse for 600 lights.*use --cells-res \d+"):
        check_cells_res(16, d, "upper")
    check_cells_res(512, d, "upper")  # fine enough


# ----------------------------------------------------------------------------- warnings, help
def test_clamped_negatives_warning_is_one_line(ws, tmp_path, capfd):
    data = np.ones((16, 32, 3), np.float32)
    data[2, 3] = -1.0
    write_exr(tmp_path / "neg.exr", data)
    capfd.readouterr()
    rc = main(["relight", str(ws["cap"]), "--probe", str(tmp_path / "neg.exr"), "-o", str(tmp_path / "a.exr")])
    _, err = capfd.readouterr()
    warn = [ln for ln in err.splitlines() if "warning" in ln]
    assert rc == 0 and len(warn) == 1, err
    assert warn[0].startswith("ffls relight: warning: ") and "neg.exr" in warn[0] and "clamped 1 pixels" in warn[0]
    assert "warnings.warn" not in err and "LightMapWarning" not in err


def test_warning_before_a_failure_leaves_only_the_error_line(ws, tmp_path, capfd):
    """A map's clamp warning, then a refused mask: the answer is the one error line, and no output."""
    import cv2

    data = np.ones((16, 32, 3), np.float32)
    data[2, 3] = -1.0
    write_exr(tmp_path / "neg.exr", data)
    assert cv2.imwrite(str(tmp_path / "m.png"), np.full((5, 7), 255, np.uint8))
    capfd.readouterr()
    rc = main(["relight", str(ws["cap"]), "--probe", str(tmp_path / "neg.exr"), "--mask", str(tmp_path / "m.png"),
               "-o", str(tmp_path / "a.exr")])
    err = capfd.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "m.png" in err[0] and "error:" in err[0], err
    assert not (tmp_path / "a.exr").exists()


def test_turntable_never_replaces_a_folder_of_other_files(ws, tmp_path, capfd):
    d = tmp_path / "mine"
    d.mkdir()
    (d / "notes.txt").write_text("keep me")
    assert main(["render", str(ws["cap"]), "--probe", "sky", "--cpu", "--turntable", "2", "-o", str(d)]) == 2
    assert entries(d) == {"notes.txt"} and entries(tmp_path) == {"mine"}
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mine" in err[0] and "refusing" in err[0], err


def test_turntable_replaces_its_own_frames_after_success(ws, tmp_path, capfd):
    d = tmp_path / "frames"
    assert main(["render", str(ws["cap"]), "--probe", "sky", "--cpu", "--turntable", "3", "-o", str(d)]) == 0
    assert entries(d) == {"frame_0000.png", "frame_0001.png", "frame_0002.png"}
    assert main(["render", str(ws["cap"]), "--probe", "sky", "--cpu", "--turntable", "2", "-o", str(d)]) == 0
    assert entries(d) == {"frame_0000.png", "frame_0001.png"} and entries(tmp_path) == {"frames"}


def test_every_command_has_help(capsys):
    for name, p in subcommands().items():
        with pytest.raises(SystemExit) as e:
            main([name, "--help"])
        assert e.value.code == 0, name
    for argv in (["calibrate", "response"], ["calibrate", "camera"], ["lightmap", "info"],
                 ["lightmap", "convert"], ["lightmap", "make"]):
        with pytest.raises(SystemExit) as e:
            main(argv + ["--help"])
        assert e.value.code == 0, argv


def test_usage_error_is_one_line(capfd):
    assert main(["render"]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ffls render: error:"), err


# ----------------------------------------------------------------------------- interruptions
def _default_sigint():
    # a child of a background job inherits SIGINT ignored (the shell's rule for asynchronous
    # commands), and Python then installs no KeyboardInterrupt handler: give it the default back,
    # as a terminal's foreground job has it
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _child(argv, cwd, **kw):
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "ffls", *map(str, argv)], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_default_sigint, **kw)


def _wait_for(pred, timeout=60.0):
    t = time.monotonic()
    while time.monotonic() - t < timeout:
        if pred():
            return True
        time.sleep(0.05)
    return False


def _staged(folder: Path) -> list:
    return [p.name for p in folder.iterdir() if ".tmp" in p.name or p.name.endswith(".old")]


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
@pytest.mark.parametrize("target", ["frames", "t.mp4"])
def test_signal_during_turntable_leaves_nothing(ws, tmp_path, sig, code, target):
    out = tmp_path / target
    p = _child(["render", ws["cap"], "--probe", "sky", "--cpu", "--turntable", "400", "-o", out], tmp_path)
    # wait until frames are being written (a staging folder or temporary mp4 exists)
    assert _wait_for(lambda: _staged(tmp_path) or p.poll() is not None), "the child never started writing"
    time.sleep(0.3)
    p.send_signal(sig)
    _, err = p.communicate(timeout=60)
    assert p.returncode == code, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()  # no progress bar when stderr is not a terminal
    assert len(lines) == 1 and lines[0].startswith("ffls render: ") and "nothing partial" in lines[0], err
    assert list(tmp_path.iterdir()) == [], list(tmp_path.iterdir())


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_during_synth_keeps_the_old_capture(ws, tmp_path, sig, code):
    cap = tmp_path / "cap"
    shutil.copytree(ws["cap"], cap)
    old = {p.name: p.read_bytes() for p in cap.iterdir()}
    p = _child(["synth", cap, "--lights", "300", "--resolution", "48", "--seed", "9"], tmp_path)
    assert _wait_for(lambda: any(_staged(tmp_path)) and any(
        any(s.iterdir()) for s in tmp_path.iterdir() if ".tmp" in s.name) or p.poll() is not None)
    time.sleep(0.3)
    p.send_signal(sig)
    _, err = p.communicate(timeout=60)
    assert p.returncode == code, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ffls synth: ") and "nothing partial" in lines[0], err
    assert {p.name: p.read_bytes() for p in cap.iterdir()} == old  # the old capture, untouched
    assert entries(tmp_path) == {"cap"}


def test_synth_over_a_capture_swaps_it_whole(ws, tmp_path, capfd):
    cap = tmp_path / "cap"
    shutil.copytree(ws["cap"], cap)
    (cap / "stale.txt").write_text("from the old capture")
    assert main(["synth", str(cap), "--lights", "5", "--resolution", "16", "--quiet"]) == 0
    assert not (cap / "stale.txt").exists() and len(json.loads((cap / "lights.json").read_text())["lights"]) == 5
    assert entries(tmp_path) == {"cap"}


def test_synth_refuses_a_folder_that_is_not_a_capture(tmp_path, capfd):
    d = tmp_path / "mine"
    d.mkdir()
    (d / "notes.txt").write_text("keep me")
    assert main(["synth", str(d), "--lights", "2", "--resolution", "8", "--quiet"]) == 2
    assert (d / "notes.txt").read_text() == "keep me"
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "capture.json" in err[0]


def test_lights_error_in_a_child_process_is_one_line_without_progress_bars(ws, tmp_path):
    # stderr is a pipe here, as in a log or CI: no bar may be drawn before the one-line answer
    p = _child(["lights", ws["few_nan"], "-o", tmp_path / "l.json"], tmp_path)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ffls lights: error: ") and "img_0005" in lines[0], err
    assert not (tmp_path / "l.json").exists()
