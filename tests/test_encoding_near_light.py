"""The encoding calibrated under a near light: the shading model places a point light per photo
(ffls.spheres.encoding, "Near lights"), chosen over the distant model by the BIC."""
import numpy as np
import pytest

from ffls.radiance.encoding import gamma_encode, srgb_encode
from ffls.spheres.encoding import calibrate_encoding

#: Four spheres of radius 5 cm resting on the ground at the corners of a 0.5 m square (world +Z up).
CENTRES = np.array([[-0.25, -0.25, 0.05], [0.25, -0.25, 0.05], [0.25, 0.25, 0.05], [-0.25, 0.25, 0.05]])
RADIUS = 0.05


def _visible_normals():
    """(m, 3) world normals of a sphere's disc seen by a camera at -Y, raised 30 degrees (unit, facing it)."""
    t = np.linspace(-0.97, 0.97, 44)
    a, b = np.meshgrid(t, t)
    inside = a * a + b * b < 0.97 ** 2
    view = np.array([0.0, -np.cos(np.radians(30)), np.sin(np.radians(30))])  # toward the camera
    right = np.array([1.0, 0.0, 0.0])
    up = np.cross(view, right)
    c = np.sqrt(1 - a[inside] ** 2 - b[inside] ** 2)
    return a[inside, None] * right + b[inside, None] * up + c[:, None] * view


def _capture(encode, distance, n_photos=24, seed=0, noise=0.0):
    """Stored values of the four spheres under point lights ``distance`` m from the scene centre
    (``np.inf``: distant), elevations 20-80 degrees on the camera's side: Lambert with the
    inverse square law at every surface point, an ambient term and the ground bounce
    ``c (1 - n_z) / 2`` with ``c`` the ground's irradiance at the sphere's contact point."""
    rng = np.random.default_rng(seed)
    normals = _visible_normals()
    raw = []
    for _ in range(n_photos):
        el, az = np.radians(rng.uniform(20, 80)), np.radians(rng.uniform(-170, -10))
        m = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        per = []
        for c in CENTRES:
            P = c + RADIUS * normals
            if np.isinf(distance):
                irr, ground = np.maximum(normals @ m, 0), max(m[2], 0)
            else:
                S = distance * m
                d = S - P
                r = np.linalg.norm(d, axis=1)
                irr = np.maximum(np.sum(normals * d, axis=1), 0) / r ** 3 * distance ** 2
                g = S - (c - [0, 0, RADIUS])
                ground = max(g[2], 0) / np.linalg.norm(g) ** 3 * distance ** 2
            lin = 0.5 * (0.8 * irr + 0.03 + 0.8 * 0.3 * ground * 0.5 * (1 - normals[:, 2]))
            enc = encode(np.clip(lin, 0, None))[:, None] + rng.normal(0, noise, (len(lin), 3))
            per.append(np.clip(np.rint(enc * 255), 0, 255) / 255)
        raw.append(per)
    return raw, [normals] * 4, [(c, RADIUS) for c in CENTRES]


def test_near_light_srgb_named_srgb_with_the_spheres_geometry():
    """A light 2 m from spheres 5 cm in radius bends each sphere's shading along
    ``n . l``: the distant model reads that bend as a lower gamma. With the spheres' world centres
    and radii, the near model is chosen and the sRGB file is named srgb."""
    raw, normals, geometry = _capture(srgb_encode, 2.0)
    distant = calibrate_encoding(raw, normals, code_step=1 / 255)
    near = calibrate_encoding(raw, normals, code_step=1 / 255, geometry=geometry)
    assert distant.shading == "distant" and distant.shading_excess is None
    assert distant.curve == "gamma" and distant.gamma < 2.2  # the bend taken for the curve
    assert near.shading == "near" and near.shading_excess > 0
    assert near.curve == "srgb" and abs(near.gamma - 2.28) < 0.03
    assert "near light" in near.summary() and near.record()["shading"] == "near"


@pytest.mark.parametrize("true, curve", [(1.0, "linear"), (2.2, "gamma")])
def test_near_light_other_curves(true, curve):
    """Linear and gamma-2.2 files under the same near light are named right, the gamma within its interval."""
    raw, normals, geometry = _capture(lambda v: gamma_encode(v, true), 2.0, noise=1 / 255, seed=1)
    cal = calibrate_encoding(raw, normals, code_step=1 / 255, geometry=geometry)
    assert cal.shading == "near" and cal.curve == curve
    assert abs(cal.gamma - true) <= cal.uncertainty


def test_distant_light_unchanged_by_the_geometry():
    """Under a distant light the near model gains nothing: the curve and the gamma are the distant model's."""
    raw, normals, geometry = _capture(srgb_encode, np.inf, noise=1 / 255, seed=2)
    distant = calibrate_encoding(raw, normals, code_step=1 / 255)
    cal = calibrate_encoding(raw, normals, code_step=1 / 255, geometry=geometry)
    assert distant.curve == "srgb" and cal.curve == "srgb"
    assert abs(cal.gamma - distant.gamma) < 0.01


def test_one_sphere_per_photo_keeps_the_distant_model():
    """A light cannot be placed from one sphere (no parallax): the near model is not tried."""
    raw, normals, geometry = _capture(srgb_encode, 2.0, n_photos=12)
    cal = calibrate_encoding([r[:1] for r in raw], normals[:1], code_step=1 / 255, geometry=geometry[:1])
    assert cal.shading == "distant" and cal.shading_excess is None
