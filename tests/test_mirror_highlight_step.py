"""A chrome ball's highlight next to a step in its reflection (ffls.spheres.highlight.find_highlight).

A point light on a mirror ball is one clipped pixel on the black reflected sky; a few pixels below
it the reflected table (a bright band) crosses the ring from which the local background is
fitted. The background there is the sky's (zero), not a plane tilted by the step: the blob's
signal-weighted centre is the clipped pixel itself. A smooth gradient across the ring is still
fitted as a plane (the shoulder's signal above it is zero).
"""
from __future__ import annotations

import numpy as np

from ffls.spheres.highlight import find_highlight


def _centre(spot):
    w = spot.weights
    return np.array([np.sum(w * spot.cols), np.sum(w * spot.rows)]) / np.sum(w)


def _disc(h=60, w=60, c=(30.0, 30.0), r=27.0):
    yy, xx = np.mgrid[0:h, 0:w]
    return np.hypot(xx - c[0], yy - c[1]) < r


def test_a_one_pixel_highlight_beside_a_reflected_step_is_centred_on_its_pixel():
    disc = _disc()
    img = np.zeros(disc.shape)
    img[35:, :] = 0.088  # the reflected table, 5 px below the highlight (sRGB 84 decoded)
    img[30, 25] = 1.0
    sat = np.zeros_like(disc)
    sat[30, 25] = True
    spot = find_highlight(img, disc, sat)
    assert spot.found and spot.status == "ok"
    np.testing.assert_allclose(_centre(spot), [25.0, 30.0], atol=0.05)


def test_a_highlight_on_a_smooth_gradient_keeps_the_plane_background():
    disc = _disc()
    yy, xx = np.mgrid[0:60, 0:60].astype(np.float64)
    img = 0.05 + 0.004 * (xx - 30.0) + 0.003 * (yy - 30.0)  # the reflected room, shading smoothly
    img += 0.8 * np.exp(-((xx - 27.3) ** 2 + (yy - 31.6) ** 2) / (2 * 0.8 ** 2))
    spot = find_highlight(img, disc)
    assert spot.found and spot.status == "ok"
    np.testing.assert_allclose(spot.background_at, 0.05 + 0.004 * (spot.cols - 30.0) + 0.003 * (spot.rows - 30.0),
                               atol=1e-9)
    np.testing.assert_allclose(_centre(spot), [27.3, 31.6], atol=0.02)


def test_a_glint_on_a_reflected_edge_is_no_highlight():
    # a light behind the ball: no highlight, only a pixel twice the level of the reflected table on
    # its edge (a renderer's or sensor's glint); it does not stand above the step around it
    disc = _disc()
    yy, xx = np.mgrid[0:60, 0:60]
    img = np.where(yy - 30 > 0.8 * (30 - xx), 0.029, 0.0)
    img[29, 31] = 0.064
    spot = find_highlight(img, disc)
    assert not spot.found and spot.status == "no_highlight"
