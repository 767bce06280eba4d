"""A lone matte sphere's cones from its own data (issue 9, item 5; docs/spheres.md, "A lone sphere's
cones from its two halves"): its halves' disagreement, its centre measured by its shading, and a
lens fall-off it measured but the capture did not divide out."""
from dataclasses import replace

import numpy as np
import pytest

from ffls.spheres.estimate import (FlatField, calibrate_uncertainty, flat_field_offsets, flat_field_shift_deg)
from ffls.spheres.photo import estimate_photo
from ffls.spheres.samples import sphere_samples_orthographic, sphere_values_of
from ffls.spheres.uncertainty import COMMON_FLOOR_DEG

from lone_sphere_rig import WORLD_FROM_CAMERA, front_lights

def _sphere(center_px=(60.0, 60.0), radius_px=30.0, margin_px=1.5):
    return sphere_samples_orthographic((120, 120), center_px, radius_px, world_from_camera=WORLD_FROM_CAMERA,
                                       margin_px=margin_px)


def _values(rendered, lights, gradient=(0.0, 0.0), noise=0.002, seed=4):
    """Lambertian values of the sphere ``rendered`` (its normals) at the lights, times a lens gradient."""
    rng = np.random.default_rng(seed)
    fall = 1.0 + flat_field_offsets(rendered) @ np.asarray(gradient, dtype=np.float64)
    out = []
    for l in lights:
        v = 0.5 * np.maximum(rendered.normals @ l, 0.0) * fall + 0.01 + noise * rng.normal(size=fall.size)
        out.append([sphere_values_of(v, np.ones(v.size, bool), 0)])
    return out


def _photos(samples, values):
    return [estimate_photo(None, [samples], np.zeros(3), values=v, min_spheres=1, own_shadow=False)
            for v in values]


def _flat(measured, sigma):
    return FlatField(strength=0.0, sigma=0.0, p=1.0, applied=False, gradients=np.zeros((1, 2)),
                     measured=np.array([measured], dtype=float), measured_sigma=np.array([sigma], dtype=float),
                     n_photos=np.array([24]))


def test_an_unapplied_lens_gradient_is_the_turn_it_gives():
    """A lens gradient of 0.05 across the disk turns a lone sphere's direction by about 1 degree in
    every photo; measured (significant) and not divided out, it is that turn, and nothing where the
    measurement is within its noise."""
    s, lights = _sphere(), front_lights()
    photos = _photos(s, _values(s, lights, gradient=(0.04, -0.03)))
    ok = [p.ok for p in photos]
    err = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", np.array([p.direction for p in photos])[ok],
                                                 lights[ok]), -1, 1)))
    values = _values(s, lights, gradient=(0.04, -0.03))
    turn = flat_field_shift_deg(photos, [s], values, _flat((0.04, -0.03), (0.002, 0.002)), own_shadow=False)
    assert turn == pytest.approx(np.sqrt(np.mean(err ** 2) / 2.0), rel=0.05), (turn, err)
    assert np.median(err) > 0.5
    assert flat_field_shift_deg(photos, [s], values, _flat((0.004, -0.003), (0.002, 0.002)),
                                own_shadow=False) == 0.0
    assert flat_field_shift_deg(photos, [s], values, None) == 0.0


def test_a_lone_sphere_model_is_its_halves_with_its_measured_centre_and_lens():
    """One sphere whose outline is 1 px off its shading's centre and whose lens darkens one side: both
    turn its two halves alike, so the halves' model alone covers a third of the photos (cones of
    0.55 deg); with its centre measured by its shading (1.08 deg per axis) and the lens's turn
    (1.03), every photo."""
    rendered, lights = _sphere(margin_px=0.0), front_lights()
    outline = _sphere(center_px=(61.0, 60.0), margin_px=2.5)  # found 1 px to the right; inside the disk
    idx = {(r, c): i for i, (r, c) in enumerate(zip(rendered.rows, rendered.cols))}
    take = np.array([idx[(r, c)] for r, c in zip(outline.rows, outline.cols)])
    values = [[sphere_values_of(v[0][0][take], v[0][1][take], 0)]
              for v in _values(rendered, lights, gradient=(0.05, 0.0))]
    photos = _photos(outline, values)
    flat = _flat((0.05, 0.0), (0.002, 0.002))
    options = {"own_shadow": False}
    fallback = calibrate_uncertainty(photos, [outline])[0]
    model, new = calibrate_uncertainty(photos, [outline], values=values, fit_options=options, flat=flat)
    assert fallback.source == "fallback" and model.source == "halves", model
    assert model.centre_deg[0] > 0.3, model  # 1 px on a 30 px sphere: about 1 deg, shared by its halves
    assert model.common_floor_deg > 0.5, model  # the lens's turn
    ok = np.array([p.ok for p in new])
    err = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", np.array([p.direction for p in new])[ok],
                                                 lights[ok]), -1, 1)))
    cone_new = np.array([p.uncertainty_deg for p in new])[ok]
    halves_only = replace(model, centre_deg=(0.0,), common_floor_deg=COMMON_FLOOR_DEG)
    cone_halves = np.array([p.with_error_model(halves_only).uncertainty_deg for p in new])[ok]
    assert np.mean(err <= cone_new) >= 0.9, (err, cone_new)
    assert np.mean(err <= cone_halves) < 0.5, (err, cone_halves)  # the halves alone do not see either


def test_the_lens_turns_refits_run_through_map_fn():
    """The refits with the gradient divided out run through ``map_fn`` (the pool of worker
    processes in ``ffls lights``: they had run serially in the main process), one task per sphere
    with all its photos, and give the turn they give in this process."""
    s, lights = _sphere(), front_lights()
    values = _values(s, lights, gradient=(0.04, -0.03))
    photos = _photos(s, _values(s, lights, gradient=(0.04, -0.03)))
    flat = _flat((0.04, -0.03), (0.002, 0.002))
    calls = []

    def spy(fn, items):
        items = list(items)
        calls.append(len(items))
        return [fn(x) for x in items]

    turn = flat_field_shift_deg(photos, [s], values, flat, own_shadow=False, map_fn=spy)
    assert calls == [1]
    assert turn > 0.5
    assert turn == flat_field_shift_deg(photos, [s], values, flat, own_shadow=False)
