"""Light estimation with the per-photo work on Dask (Masselus, Dutre, Anrys 2002, section 5).

What grows with the photos' size is reading and linearising each one and picking its spheres'
pixels: :func:`photo_sphere_values` does that for one photo, and a runner
(:class:`ffls.cluster.DaskRunner`) maps it over the capture on the cluster. What remains is small
(the spheres' pixels of every photo) and runs here through the public two-pass driver
:func:`ffls.spheres.estimate.estimate_photos`, with the same samples, materials and views as
:func:`ffls.spheres.estimate.estimate_lights`: the lights are the same as the in-process run's.
A mirror or glossy ball's outline is refined on the sequence's mean luminance
(:func:`ffls.spheres.highlight.refine_view_limb`): each worker also returns its photo's luminance
in a window around each sphere (:func:`ffls.spheres.mirror_outline.limb_window`), and their mean
is the in-process run's mean image there.
"""
from __future__ import annotations

from functools import partial

import numpy as np

from ffls.errors import InputError

__all__ = ["photo_sphere_values", "photo_values_and_windows", "mean_window_image", "estimate_lights_dask"]


def photo_sphere_values(capture, samples, saturation, i: int) -> list:
    """Photo ``i`` read, linearised, and its spheres' values (grey float32), as the in-process driver keeps them."""
    from ffls.radiance.photos import read_photo
    from ffls.spheres.samples import SphereValues, sphere_values

    photo = read_photo(capture, i)
    values = sphere_values(photo.linear, samples, saturation=saturation, raw=photo.raw, bit_depth=photo.bit_depth)
    return [SphereValues(v.grey.astype(np.float32), v.valid, v.n_saturated) for v in values]


def photo_values_and_windows(capture, samples, saturation, windows, i: int) -> tuple[list, list]:
    """Photo ``i`` read once: its spheres' values (:func:`photo_sphere_values`) and its luminance
    (Rec. 709 of the linear photo, float32, as :class:`ffls.spheres.detect.SequenceAccumulator`
    sums it) in each window ``(x0, x1, y0, y1)`` (inclusive), float64."""
    from ffls.radiance.photos import read_photo
    from ffls.spheres.samples import SphereValues, sphere_values

    photo = read_photo(capture, i)
    values = sphere_values(photo.linear, samples, saturation=saturation, raw=photo.raw, bit_depth=photo.bit_depth)
    im = photo.linear
    crops = []
    for x0, x1, y0, y1 in windows:
        c = im[y0:y1 + 1, x0:x1 + 1]
        if c.ndim == 3 and c.shape[2] >= 3:
            lum = c[..., 0] * np.float32(0.2126) + c[..., 1] * np.float32(0.7152) + c[..., 2] * np.float32(0.0722)
        else:
            lum = (c[..., 0] if c.ndim == 3 else c).astype(np.float32)
        crops.append(lum.astype(np.float64))
    return [SphereValues(v.grey.astype(np.float32), v.valid, v.n_saturated) for v in values], crops


def mean_window_image(shape, windows, crops_per_photo) -> np.ndarray:
    """The mean over the photos of their window crops (:func:`photo_values_and_windows`), placed in
    an ``(H, W)`` float64 image that is NaN outside the windows."""
    out = np.full((int(shape[0]), int(shape[1])), np.nan)
    n = len(crops_per_photo)
    for k, (x0, x1, y0, y1) in enumerate(windows):
        total = np.zeros((y1 - y0 + 1, x1 - x0 + 1))
        for crops in crops_per_photo:
            total += crops[k]
        out[y0:y1 + 1, x0:x1 + 1] = total / max(n, 1)
    return out


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
    from ffls.io.capture import sphere_materials
    from ffls.spheres.estimate import (capture_samples, centres_to_refine, check_estimable, estimate_photos,
                                       lens_centre, lens_check, sphere_views, widen_for_lens)
    from ffls.spheres.mirror_outline import limb_window

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
    materials = sphere_materials(capture, len(spheres))
    views = sphere_views(capture, spheres)
    # a window per sphere that may be a mirror (declared or classified later): its limb's mean image
    windows = [limb_window(v.center_px, v.radius_px, shape) for v, m in zip(views, materials) if m != "matte"]
    out = runner.map(partial(photo_values_and_windows, capture, samples, kwargs.get("saturation"), windows), range(n),
                     desc="lights: photos")
    values = [o[0] for o in out]
    limb_image = mean_window_image(shape, windows, [o[1] for o in out]) if windows else None
    flat = lens_centre(capture, shape) if kwargs.pop("flat_field", True) else None  # as estimate_lights
    est = estimate_photos(values, samples, capture.scene_center, bounce=bounce,
                          refine_centres=centres_to_refine(spheres) if refine_centres else False,
                          refine_options=refine_options, flat_field=flat, materials=materials, views=views,
                          model=model, limb_image=limb_image, **kwargs)
    # a normal lens declared orthographic: the cones widened as estimate_lights widens them
    return widen_for_lens(est.lights(capture.image_names), lens_check(capture, spheres, shape))
