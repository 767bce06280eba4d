"""Light estimation with the per-photo work on Dask (Masselus, Dutre, Anrys 2002, section 5).

What grows with the photos' size is reading and linearising each one and picking its spheres'
pixels: :func:`photo_sphere_values` does that for one photo, and a runner
(:class:`ffls.cluster.DaskRunner`) maps it over the capture on the cluster. What remains is small
(the spheres' pixels of every photo) and runs here through the public two-pass driver
:func:`ffls.spheres.estimate.estimate_photos`, with the same samples, materials and views as
:func:`ffls.spheres.estimate.estimate_lights`: the lights are the same as the in-process run's.
"""
from __future__ import annotations

from functools import partial

import numpy as np

from ffls.conventions import UP, normalize
from ffls.errors import InputError

__all__ = ["photo_sphere_values", "estimate_lights_dask"]


def photo_sphere_values(capture, samples, saturation, i: int) -> list:
    """Photo ``i`` read, linearised, and its spheres' values (grey float32), as the in-process driver keeps them."""
    from ffls.radiance.photos import read_photo
    from ffls.spheres.samples import SphereValues, sphere_values

    photo = read_photo(capture, i)
    values = sphere_values(photo.linear, samples, saturation=saturation, raw=photo.raw, bit_depth=photo.bit_depth)
    return [SphereValues(v.grey.astype(np.float32), v.valid, v.n_saturated) for v in values]


def estimate_lights_dask(capture, runner, spheres=None, model: str = "auto", bounce: str = "calibrated",
                         refine_centres: bool = True, refine_options: dict | None = None, **kwargs):
    """:func:`ffls.spheres.estimate.estimate_lights` with the photos read on ``runner``'s workers.

    Parameters
    ----------
    capture : ffls.io.capture.Capture
    runner : ffls.cluster.DaskRunner or ffls.store.ingest.SerialRunner
    spheres, model, bounce, refine_centres, refine_options, **kwargs
        As :func:`ffls.spheres.estimate.estimate_lights` (pinhole or orthographic cameras alike).

    Returns
    -------
    ffls.io.capture.Lights
    """
    from ffls.io.capture import Lights, sphere_materials
    from ffls.spheres.estimate import capture_samples, check_estimable, estimate_photos, lens_centre, sphere_views

    model, refine_options = check_estimable(capture, model, refine_options)
    n = len(capture.image_names)
    if spheres is None:
        from ffls.spheres.detect import find_spheres_in_capture

        spheres = find_spheres_in_capture(capture)
    if model == "near" and len(spheres) < 2:
        raise InputError("model 'near' needs at least 2 spheres to triangulate the light", capture.json_path)
    if capture.image_size is not None:
        shape = (int(capture.image_size[1]), int(capture.image_size[0]))
    else:
        from ffls.radiance.photos import load_photo

        shape = load_photo(capture, 0).shape[:2]
    samples = capture_samples(capture, spheres, shape)
    values = runner.map(partial(photo_sphere_values, capture, samples, kwargs.get("saturation")), range(n),
                        desc="lights: photos")
    flat = lens_centre(capture, shape) if kwargs.pop("flat_field", True) else None  # as estimate_lights
    est = estimate_photos(values, samples, capture.scene_center, bounce=bounce, refine_centres=refine_centres,
                          refine_options=refine_options, flat_field=flat, materials=sphere_materials(capture, len(spheres)),
                          views=sphere_views(capture, spheres), model=model, **kwargs)
    dirs = np.array([normalize(r.direction) if np.all(np.isfinite(r.direction)) else UP for r in est.photos])
    pos = np.array([r.position if r.position is not None else np.full(3, np.nan) for r in est.photos])
    return Lights(image_names=capture.image_names, directions=dirs, positions=pos,
                  status=[r.status for r in est.photos], reasons=[r.reason for r in est.photos],
                  extra=est.records(), uncertainty=None if est.error_model is None else est.error_model.as_dict())
