"""A lone grey ball partly hidden by an object in front of it, or half in an object's cast shadow
(issue 9; docs/spheres.md, "A lone grey ball behind the object, or half in its shadow"): the
occluder's pixels found by the photos' fits and taken out, and a photo whose fit a shadow's edge
broke rejected as shadowed."""
import numpy as np

from ffls.spheres.estimate import mask_foreign_pixels, reject_shadowed_photos
from ffls.spheres.photo import estimate_photo
from ffls.spheres.samples import sphere_samples_orthographic, sphere_values_of

from lone_sphere_rig import WORLD_FROM_CAMERA, front_lights

def _sphere():
    return sphere_samples_orthographic((120, 120), (60.0, 60.0), 30.0, world_from_camera=WORLD_FROM_CAMERA)


def _values(s, lights, occluder=None, shadow=(), noise=0.002, seed=4):
    """Lambertian values at ``lights``; ``occluder`` (pixel mask) shows a flat surface of its own,
    facing the camera, lit by the same lights; the photos in ``shadow`` have the disk's right half (x > 62)
    in a cast shadow."""
    rng = np.random.default_rng(seed)
    out = []
    for j, l in enumerate(lights):
        v = 0.5 * np.maximum(s.normals @ l, 0.0) + 0.01 + noise * rng.normal(size=len(s))
        if j in shadow:
            v = np.where(s.cols > 62, 0.01 + noise * rng.normal(size=len(s)), v)
        if occluder is not None:
            v = np.where(occluder, 0.4 * max(-l[1], 0.0) + 0.01 + noise * rng.normal(size=len(s)), v)
        out.append([sphere_values_of(v, np.ones(v.size, bool), 0)])
    return out


def _photos(s, values):
    return [estimate_photo(None, [s], np.zeros(3), values=v, min_spheres=1, own_shadow=False) for v in values]


def _errors(photos, lights):
    ok = np.array([p.ok for p in photos])
    d = np.array([p.direction for p in photos])[ok]
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", d, lights[ok]), -1, 1)))


def test_an_object_over_a_quarter_of_the_disk_is_masked_and_the_fits_recover():
    """A band over the disk's left quarter (an object in front of the ball, lit by the same lamp)
    turns one photo by 31 deg that the fits' outlier rejection does not save; the pixels most fits
    reject are that band (with a pixel of its edge), and every fit without them is right."""
    s, lights = _sphere(), front_lights()
    band = s.cols < 48
    values = _values(s, lights, occluder=band)
    photos = _photos(s, values)
    before = _errors(photos, lights)
    masked_values, masked = mask_foreign_pixels(photos, list(range(len(lights))), [s], values)
    keep = masked_values[0][0].valid
    assert masked[0] == int((~keep).sum())
    assert not keep[band].any()  # the whole band
    assert (~keep & ~band).sum() <= 0.25 * band.sum()  # and little else (its edge's ring)
    after = _errors(_photos(s, masked_values), lights)
    assert before.max() > 10.0, before
    assert after.max() < 0.1, after
    # a clean sphere: nothing is foreign
    clean = _values(s, lights)
    assert mask_foreign_pixels(_photos(s, clean), list(range(len(lights))), [s], clean)[1] == [0]


def test_a_photo_half_in_a_cast_shadow_is_rejected_as_shadowed():
    """Two photos with the disk's right half in a cast shadow: their fits, turned by degrees, keep
    their intensity and reject no pixel, but leave residuals many times the capture's; they are
    rejected as shadowed, and the others kept."""
    s, lights = _sphere(), front_lights()
    photos = _photos(s, _values(s, lights, shadow=(3, 7)))
    assert all(photos[j].ok for j in (3, 7))
    assert max(_errors([photos[j] for j in (3, 7)], lights[[3, 7]])) > 5.0
    out = reject_shadowed_photos(photos)
    assert [j for j, r in enumerate(out) if not r.ok] == [3, 7]
    assert all(out[j].reason == "shadowed" and out[j].spheres[0].status == "shadowed" for j in (3, 7))
    assert all(r.ok for r in reject_shadowed_photos(photos, misfit_ratio=np.inf)[:3])
