"""A photo whose every sphere lies in a cast shadow is rejected against the capture
(:func:`ffls.spheres.estimate.reject_shadowed_photos`): within the photo no sphere is darker than
the others, so only the spheres' brightness in the capture's other photos shows it."""
from __future__ import annotations

import numpy as np
import pytest

from ffls.conventions import spherical_to_direction
from ffls.spheres.estimate import estimate_photos, reject_shadowed_photos
from ffls.spheres.photo import SHADOW_RATIO
from ffls.spheres.samples import SphereValues, ground_bounce
from sphere_rig import SCENE_CENTER, rig_samples

LIGHTS = [(th, ph) for th in (20, 40, 60) for ph in (-150, -30, 30, 90, 150)]


@pytest.fixture(scope="module")
def samples():
    return rig_samples(200, 190.0)


def values(samples, direction, lamp=1.0, direct=1.0, seed=0):
    """The lamp's Lambert shading and its bounce off the ground (times ``lamp``: a lamp farther
    away), of which ``direct`` reaches the spheres (a shadow on the spheres leaves the ground's
    bounce), plus the room's ambient and a little noise."""
    rng = np.random.default_rng(seed)
    out = []
    for s in samples:
        y = 0.8 * (lamp * (direct * np.maximum(s.normals @ direction, 0.0)
                           + 0.3 * max(direction[2], 0.0) * ground_bounce(s.normals)) + 0.02)
        y = y + 0.0005 * rng.standard_normal(y.shape)
        out.append(SphereValues(y.astype(np.float32), np.ones(y.shape, bool), 0))
    return out


def capture(samples, lamp):
    """Photo 0 has every sphere in a cast shadow (2% of the lamp reaches them); ``lamp`` gives
    each photo's lamp brightness (its distance)."""
    dirs = [spherical_to_direction(np.radians(th), np.radians(ph)) for th, ph in LIGHTS]
    direct = [0.02] + [1.0] * (len(dirs) - 1)
    vals = [values(samples, d, a, b, seed=i) for i, (d, a, b) in enumerate(zip(dirs, lamp, direct))]
    return estimate_photos(vals, samples, SCENE_CENTER, refine_centres=False, bounce="free"), dirs


def shadowed(est):
    return [i for i, r in enumerate(est.photos) if r.reason == "shadowed"]


def test_a_photo_with_every_sphere_shadowed_is_rejected(samples):
    """At one lamp distance the shadowed photo and a lone photo with the lamp three times farther
    (1/9 of the light, below :data:`SHADOW_RATIO` and outside the capture's spread) are rejected."""
    lamp = [1.0, 1.0 / 9.0] + [1.0] * (len(LIGHTS) - 2)
    est, _ = capture(samples, lamp)
    photo = est.photos[0]
    assert photo.status == "rejected" and not np.isfinite(photo.uncertainty_deg)
    assert all(s.status == "shadowed" for s in photo.spheres if s.fit.status == "ok"), [s.status for s in photo.spheres]
    assert 1.0 / 9.0 < SHADOW_RATIO
    # no other photo is taken for shadowed (some are rejected for their own reasons: low lights)
    assert shadowed(est) == [0, 1]


def test_a_lamp_moved_nearer_and_farther_is_no_shadow(samples):
    """With the lamp's brightness spread over 1/9-1 (distances over 1-3 times), the photo at 1/9 is
    within the capture's spread: kept; the shadowed photo is still rejected."""
    lamp = np.exp(np.linspace(0.0, np.log(1.0 / 9.0), len(LIGHTS)))
    lamp = np.r_[1.0, lamp[-1], lamp[1:-1]]  # photo 1 the farthest
    est, _ = capture(samples, lamp)
    assert est.photos[1].status == "ok", est.photos[1].reason
    assert shadowed(est) == [0]


def test_without_the_capture_the_shadowed_photo_passes(samples):
    """The test the capture adds is what rejects it: within the photo its spheres agree."""
    d = spherical_to_direction(np.radians(LIGHTS[0][0]), np.radians(LIGHTS[0][1]))
    again = estimate_photos([values(samples, d, direct=0.02, seed=0)], samples, SCENE_CENTER, refine_centres=False,
                            bounce="free")
    assert again.photos[0].status == "ok"  # one photo alone has no capture to compare with
    assert reject_shadowed_photos(again.photos) == again.photos


def _mirror_photo(direction, intensity):
    """A photo whose one used sphere is a mirror with a highlight of ``intensity``."""
    from ffls.spheres.highlight import HighlightFit
    from ffls.spheres.photo import PhotoEstimate, SphereResult

    fit = HighlightFit(status="ok", direction=np.asarray(direction, dtype=np.float64), uncertainty_deg=0.5,
                       intensity=float(intensity))
    return PhotoEstimate(status="ok", reason=None, direction=fit.direction, uncertainty_deg=1.0, model="distant",
                         used_spheres=[0], spheres=[SphereResult(fit, "ok")], weights=[4.0])


def test_a_mirror_highlight_far_fainter_than_the_capture_is_no_highlight():
    """With the lamp behind a chrome ball the brightest compact blob left is a reflection of the
    room (on a textured ground 1/3000 of the lamp's highlights: one photo 165 degrees off). Against
    the capture's highlights it is rejected as ``no_highlight``; highlights spread over 1/9-1 (a
    lamp moved by hand, a glossy ball's Fresnel rise) are kept."""
    rng = np.random.default_rng(3)
    spread = np.exp(rng.uniform(np.log(1.0 / 9.0), 0.0, 30))
    photos = [_mirror_photo([0.0, 0.0, 1.0], 200.0 * a) for a in spread] + [_mirror_photo([0.0, 1.0, 0.0], 0.06)]
    out = reject_shadowed_photos(photos)
    assert [r.status for r in out[:-1]] == ["ok"] * len(spread)
    assert out[-1].status == "rejected" and out[-1].reason == "no_highlight"
    assert out[-1].spheres[0].status == "no_highlight" and not np.isfinite(out[-1].uncertainty_deg)
