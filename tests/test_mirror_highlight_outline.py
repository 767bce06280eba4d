"""A chrome ball's outline must hold every photo's highlight
(ffls.spheres.highlight.outline_holding_highlights, highlights_outside), and a small highlight on a
bright reflection (highlight_centre_Debevec1998).

An area-sampled ball with a limb step at its true silhouette; a detected outline 1.2 px off and
short, so that highlights near the true limb fall off it. The limb step's outline holds them and is
taken; where every highlight is on the detected outline it is kept.
"""
from __future__ import annotations

import cv2
import numpy as np

from ffls.spheres.highlight import (HighlightSpot, SphereView, highlight_centre_Debevec1998, highlight_direction,
                                   highlights_outside, outline_holding_highlights)

SUB = 4


def _ball(c, r, h=110, w=110, jump=0.3, noise=0.002):
    off = (np.arange(SUB) + 0.5) / SUB - 0.5
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    sx = xx[..., None, None] + off[None, None, None, :]
    sy = yy[..., None, None] + off[None, None, :, None]
    inside = np.hypot(sx - c[0], sy - c[1]) < r
    img = np.where(inside, 0.45 - jump, 0.45).mean(axis=(2, 3))
    img = cv2.GaussianBlur(img, (0, 0), 0.6)
    return img + np.random.default_rng(3).normal(0.0, noise, img.shape)


def _rim_points(c, r, angles, inset):
    a = np.radians(angles)
    return np.stack([c[0] + (r - inset) * np.cos(a), c[1] + (r - inset) * np.sin(a)], axis=1)


def test_highlights_off_the_detected_outline_move_it_to_the_limb():
    c, r = np.array([54.4, 56.7]), 24.0
    img = _ball(c, r)
    detected = SphereView(center_px=c + [-1.2, 0.0], radius_px=r - 0.5, model="orthographic")
    # grazing lights on the side the detected outline misses, and a few elsewhere
    pixels = np.vstack([_rim_points(c, r, [-20, -5, 0, 10, 25], 0.4), _rim_points(c, r, [100, 200, 270], 3.0),
                        [[np.nan, np.nan]]])
    assert highlights_outside(detected, pixels) >= 3
    view, before, after = outline_holding_highlights(detected, img, pixels)
    assert before == highlights_outside(detected, pixels)
    assert after == 0 == highlights_outside(view, pixels)
    assert np.hypot(*(np.asarray(view.center_px) - c)) < 0.3
    assert abs(view.radius_px - r) < 0.3
    # the outline's uncertainties are the view's own (set by refine_view_limb), unchanged
    assert view.center_sigma_px == detected.center_sigma_px


def test_an_outline_holding_every_highlight_is_kept():
    c, r = np.array([54.4, 56.7]), 24.0
    img = _ball(c, r)
    detected = SphereView(center_px=c + [-1.2, 0.0], radius_px=r - 0.5, model="orthographic")
    pixels = _rim_points(c, r, [90, 180, 250], 3.0)
    view, before, after = outline_holding_highlights(detected, img, pixels)
    assert view is detected and before == after == 0


def test_a_limb_holding_no_more_highlights_is_not_taken():
    """Highlights that no outline holds (e.g. a reflection off the table beyond the ball) move nothing."""
    c, r = np.array([54.4, 56.7]), 24.0
    img = _ball(c, r)
    detected = SphereView(center_px=c + [-0.3, 0.2], radius_px=r - 0.2, model="orthographic")
    pixels = np.array([[c[0] + r + 6.0, c[1]], [c[0], c[1] - r - 6.0]])
    view, before, after = outline_holding_highlights(detected, img, pixels)
    assert view is detected and before == after == 2


def test_a_highlight_whose_signed_signal_sums_below_zero_is_the_centroid_of_its_positive_part():
    """A 2-pixel core over a shoulder the background plane overshoots (signed sum < 0): the
    source's radiance is never negative, so the centre is the positive core's, not a failure."""
    view = SphereView(center_px=np.array([30.0, 30.0]), radius_px=15.0, model="orthographic")
    rr, cc = np.mgrid[24:31, 34:41]
    rows, cols = rr.ravel(), cc.ravel()
    weights = np.full(rows.size, -0.02)
    core = ((rows == 27) & (cols == 37)) | ((rows == 27) & (cols == 38))
    weights[core] = [0.2, 0.1]
    spot = HighlightSpot(found=True, status="ok", peak=0.2, rows=rows, cols=cols, weights=weights)
    assert np.sum(weights) < 0
    d, pixel = highlight_centre_Debevec1998(view, spot)
    assert np.all(np.isfinite(d))
    # the core's weighted centre (x between 37 and 38, nearer 37), the magnification nearly flat there
    assert 37.0 < pixel[0] < 37.5 and abs(pixel[1] - 27.0) < 1e-9
    want, _ = highlight_direction(view, pixel)
    assert np.degrees(np.arccos(np.clip(np.dot(d, want), -1, 1))) < 1.0
