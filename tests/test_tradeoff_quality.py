"""Quality knobs (issue 12): near-light correction, basis subset, storage precision, pass-1 map
height, the automatic choice, and their flags on relight / render / view."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import normalize
from ffls.lightmaps.lightmap import sky_sun_map
from ffls.relight.auto import Choice, choose, choose_quality, estimate_errors, leave_one_out_errors, loo_floor
from ffls.relight.cpu import CpuRelighter
from ffls.relight.quality import (Quality, apply_near_correction, farthest_point_subset, integration_map,
                                  near_light_scales)
from ffls.weights.kriging import KernelLearner
from ffls.weights.voronoi import integrate_weights
from ffls.weights.weighting import integrate

from test_stability import lambert_basis


def fibonacci(n):
    i = np.arange(n) + 0.5
    z = i / n  # upper hemisphere
    phi = np.pi * (1 + 5 ** 0.5) * i
    r = np.sqrt(1 - z ** 2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def max_gap_deg(subset, probes):
    return float(np.degrees(np.arccos(np.clip((probes @ subset.T).max(axis=1), -1, 1))).max())


# ----------------------------------------------------------------------------- knobs
def test_quality_validates_and_labels():
    q = Quality(precision="float32", rank=15, basis_subset=64, map_res=64, near_correction=True)
    assert q.precision == "f32" and q.label() == "voronoi f32 K15 sub64 map64 near"
    assert Quality(weighting="gaussian", cell_res=128).label() == "gaussian f16 full tex128 map-full"
    for bad in ({"precision": "f8"}, {"rank": 0}, {"basis_subset": 0}, {"map_res": 1}, {"cell_res": 8},
                {"weighting": "box"}):
        with pytest.raises(ValueError):
            Quality(**bad)


def test_farthest_point_subset_covers_better_than_random_and_ignores_order():
    d = fibonacci(400)
    probes = fibonacci(5000)
    sub = farthest_point_subset(d, 40)
    assert len(sub) == 40 and np.all(np.diff(sub) > 0)
    rng = np.random.default_rng(1)
    rand = [max_gap_deg(d[rng.choice(400, 40, replace=False)], probes) for _ in range(10)]
    assert max_gap_deg(d[sub], probes) < min(rand)
    perm = rng.permutation(400)
    sub2 = farthest_point_subset(d[perm], 40)
    assert {tuple(v) for v in d[perm][sub2].round(12)} == {tuple(v) for v in d[sub].round(12)}


def test_near_correction_undoes_the_inverse_square_of_a_constant_lamp():
    d = fibonacci(20)
    b = lambert_basis(d)
    r = np.linspace(0.8, 3.0, 20)
    intensity = 4.0
    near = b * (intensity / r ** 2)[:, None, None, None]  # what a lamp of constant intensity gives at the centre
    out, dirs, s = apply_near_correction(near, d * r[:, None])
    r_ref = np.median(r)
    np.testing.assert_allclose(s, (r / r_ref) ** 2)
    np.testing.assert_allclose(out, b * intensity / r_ref ** 2, rtol=1e-5)
    np.testing.assert_allclose(dirs, d, atol=1e-12)
    # the direction comes from the position as seen from the centre
    off = np.array([0.1, 0.0, 0.0])
    _, dirs2, _ = apply_near_correction(near[:1], (d[:1] * 2.0) + off)
    np.testing.assert_allclose(dirs2[0], normalize(d[0] * 2.0 + off))
    np.testing.assert_allclose(near_light_scales(d * 2.0, reference=1.0), 4.0)


def test_integration_map_keeps_the_integral():
    lm = sky_sun_map(256)
    for h in (128, 64, 32, 48):
        small = integration_map(lm, h)
        assert small.res == h
        np.testing.assert_allclose(small.total_power(), lm.total_power(), rtol=1e-5)
    assert integration_map(lm, None) is lm and integration_map(lm, 512) is lm


def test_storage_precision_on_the_cpu_path():
    d = fibonacci(12)
    b = lambert_basis(d) * 37.0
    lm = sky_sun_map(32)
    out = {}
    for storage in ("f32", "f16"):
        r = CpuRelighter(b, d, cell_res=None, precision="f64", storage=storage)
        r.set_lightmap(lm)
        r.render()
        out[storage] = r.hdr
    rel = np.abs(out["f16"] - out["f32"]).max() / np.abs(out["f32"]).max()
    assert 0 < rel <= 2 ** -10


# ----------------------------------------------------------------------------- leave-one-out and choice
def test_leave_one_out_floor_shrinks_as_the_lights_get_denser():
    lm = sky_sun_map(64)
    floors = []
    for n in (16, 64, 256):
        d = fibonacci(n)
        b = lambert_basis(d)
        w = integrate_weights(lm, d).weights
        e0, info = loo_floor(b, d, w)
        floors.append(e0)
        assert 0 < info["share"] <= 1
    assert floors[0] > floors[1] > floors[2] > 0
    eps = leave_one_out_errors(lambert_basis(fibonacci(16)), fibonacci(16), [0, 3])
    assert np.all(eps > 0)


def test_choose_picks_the_cheapest_meeting_the_target():
    qs = [Quality(rank=k) for k in (7, 15, 31)] + [Quality()]
    err = [0.30, 0.20, 0.12, 0.10]
    ms = [2.0, 4.0, 8.0, 20.0]
    c = choose(qs, err, ms, max_error=0.15)
    assert isinstance(c, Choice) and c.quality.rank == 31 and c.met
    assert "cheapest of 2 of 4" in c.reason and len(c.reason.splitlines()) <= 2
    c = choose(qs, err, ms, fps=200)  # 5 ms: the most accurate within the budget
    assert c.quality.rank == 15 and c.met
    c = choose(qs, err, ms, max_error=0.15, fps=200)  # both: nothing meets them
    assert not c.met and c.quality.rank == 7 and "no candidate" in c.reason
    c = choose(qs, err, ms, max_error=0.01)
    assert not c.met and c.quality.rank is None  # the most accurate
    with pytest.raises(ValueError):
        choose(qs, err, ms)


def test_choose_quality_measures_this_capture():
    d = fibonacci(40)
    b = lambert_basis(d, size=16)
    from ffls.relight.auto import candidate_qualities

    cands = candidate_qualities(len(d), weightings=("voronoi", "barycentric"), map_heights=(None,))
    c = choose_quality(b, d, sky_sun_map(32), max_error=0.5, max_photos=8, candidates=cands)
    assert c.met and c.ms > 0 and "leave-one-out" in c.reason
    errs = {r["label"]: r["error"] for r in c.table}
    assert errs["voronoi f16 K7 map-full"] >= errs["voronoi f32 full map-full"]
    # a smooth scheme interpolates a smooth light field better than the box filter (leave-one-out)
    assert errs["barycentric f32 full map-full"] < errs["voronoi f32 full map-full"]
    slow = max(r["ms"] for r in c.table)
    assert c.ms <= slow


def test_kriging_candidates_are_measured_with_the_kernel_learnt_from_the_photos():
    d = fibonacci(40)
    b = lambert_basis(d, size=16)
    lm = sky_sun_map(32)
    errs, info = estimate_errors(b, d, lm, None, [Quality(weighting="kriging", precision="f32")],
                                 weighting="kriging", max_photos=8)
    learnt = KernelLearner(d, b).options_for("kriging", {})
    floor, _ = loo_floor(b, d, integrate(lm, d, scheme="kriging", **learnt).weights, "kriging", max_photos=8,
                         **learnt)
    assert info["e0"] == pytest.approx(floor, rel=1e-9) and errs[0] == pytest.approx(floor, rel=1e-6)
    default, _ = loo_floor(b, d, integrate(lm, d, scheme="kriging").weights, "kriging", max_photos=8)
    assert abs(default - floor) > 0.01 * floor  # the default kernel would have given another floor


# ----------------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    from ffls.synth.scene import write_synthetic_capture

    folder = tmp_path_factory.mktemp("q") / "cap"
    write_synthetic_capture(folder, n_lights=16, resolution=24, progress=False, seed=4)
    return folder


@pytest.fixture(scope="module")
def near_capture(tmp_path_factory):
    from ffls.synth.scene import write_synthetic_capture

    folder = tmp_path_factory.mktemp("q") / "near"
    write_synthetic_capture(folder, n_lights=12, resolution=24, progress=False, seed=5, light_model="near",
                            light_distance=1.5)
    return folder


def test_relight_quality_flags(capture, near_capture, tmp_path, capsys):
    from ffls.cli import main
    from ffls.io.images import read_image

    out = tmp_path / "a.exr"
    assert main(["relight", str(capture), "--probe", "sky", "--basis-subset", "8", "--precision", "float16",
                 "--map-res", "32", "--rank", "5", "-o", str(out)]) == 0
    assert np.all(np.isfinite(read_image(out).pixels))
    assert main(["relight", str(near_capture), "--probe", "sky", "--near-correction", "-o", str(out)]) == 0
    capsys.readouterr()
    for argv, msg in ((["--basis-subset", "100"], "--basis-subset 100 exceeds the 16 accepted lights"),
                      (["--near-correction"], "--near-correction needs light positions"),
                      (["--max-error", "0.1"], "apply only with --quality auto"),
                      (["--quality", "auto"], "needs --max-error"),
                      (["--map-res", "1"], "--map-res")):
        assert main(["relight", str(capture), "--probe", "sky", *argv, "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert msg in err and len(err.splitlines()) == 1, err


def test_relight_quality_auto_says_what_it_chose(capture, tmp_path, capsys):
    from ffls.cli import main
    from ffls.lightmaps.lightmap import save_lightmap

    probe = save_lightmap(sky_sun_map(24), tmp_path / "sky24.exr")  # small: every candidate is timed on the CPU
    out = tmp_path / "auto.exr"
    assert main(["relight", str(capture), "--probe", str(probe), "--quality", "auto", "--max-error", "0.9",
                 "-o", str(out)]) == 0
    err = capsys.readouterr().err
    line = [s for s in err.splitlines() if "quality auto:" in s]
    assert len(line) == 1 and "meeting error <= 90%" in line[0] and out.exists()


@pytest.mark.gl
def test_render_quality_flags_on_the_gpu(capture, tmp_path, capsys, ctx):
    from ffls.cli import main
    from ffls.io.images import read_image

    a, b = tmp_path / "gpu.exr", tmp_path / "cpu.exr"
    flags = ["--basis-subset", "8", "--precision", "float32", "--map-res", "32"]
    assert main(["render", str(capture), "--probe", "sky", *flags, "-o", str(a)]) == 0
    assert main(["render", str(capture), "--probe", "sky", *flags, "--cpu", "-o", str(b)]) == 0
    assert "8 lights" in capsys.readouterr().out
    ga, gb = read_image(a).pixels, read_image(b).pixels
    np.testing.assert_allclose(ga, gb, rtol=1e-3, atol=1e-3 * gb.max())


@pytest.mark.gl
def test_gpu_frame_timer_applies_every_knob(ctx):
    from ffls.gpu.engine import gpu_frame_ms
    from ffls.relight.auto import candidate_qualities

    d = fibonacci(20)
    b = lambert_basis(d, size=16)
    cands = candidate_qualities(20, weightings=("voronoi", "gaussian"), map_heights=(None, 16))
    assert {q.weighting for q in cands} == {"voronoi", "gaussian"} and any(q.basis_subset for q in cands)
    for q in cands[:4] + [c for c in cands if c.basis_subset][:1]:
        assert gpu_frame_ms(ctx, b, d, sky_sun_map(32), q, frames=1) > 0


@pytest.mark.gl
def test_exposure_changes_rerun_only_the_display_pass(ctx):
    from ffls.gpu.engine import Engine

    d = fibonacci(10)
    eng = Engine(ctx, lambert_basis(d), d, rank=4, map_res=16)
    try:
        eng.set_lightmap(sky_sun_map(64))
        eng.render(0.0)
        assert {"pass1", "pass2"} <= set(eng.timings)  # the packed pass 2 also writes the display
        eng.render(1.5)
        assert set(eng.timings) == {"tonemap"}
        eng.profile = False
        eng.render(0.5)
        assert eng.timings == {}
    finally:
        eng.release()


def test_viewer_quality_panel_round_trip():
    from viewer.state import QUALITY_KNOBS, quality_from_state, state_quality, subset_size

    keys = {k.key for k in QUALITY_KNOBS}
    assert {"method", "rank", "cell_res", "map_res", "subset", "near"} <= keys
    q = Quality(weighting="gaussian", rank=7, basis_subset=30, cell_res=128, map_res=64, near_correction=True)
    assert quality_from_state(state_quality(q), 100, software=True) == q
    q = Quality(precision="f32", cell_res=256)
    assert quality_from_state(state_quality(q), 100, software=False) == q
    assert subset_size("1/4", 100) == 25 and subset_size("all", 100) is None and subset_size("300", 100) == 100
