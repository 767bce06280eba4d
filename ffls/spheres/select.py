"""Which round outlines in the max image are calibration spheres (detection without hints).

Stage 5 of :func:`ffls.spheres.detect.find_spheres` when no hint is given: every fitted round
outline (a :class:`ffls.spheres.detect.SphereFit`) is judged by criteria that hold for real
calibration spheres in general (:data:`CRITERIA`, documented with their reasons in
``docs/spheres.md``, "Detection without hints"): round, closed and supported outline; visible
enough when the frame edge cuts it; a well-constrained centre; neutral colour; shading that
changes across the photos as a sphere's does, and unlike a flat patch of the ground's; a size
consistent with the other spheres (all share ``sphere_radius``).
"""
from __future__ import annotations

import numpy as np

from ffls.spheres.mirror_outline import OUTER_SOURCE, dark_cap, highlight_ratio

__all__ = ["CRITERIA", "COLOUR_STEP", "clip_levels", "disc_pixels", "light_directions_per_photo", "neutrality", "photo_neutrality",
           "light_spread", "moving_highlights", "shading_change", "select_spheres", "round_outline", "outline_closure"]


#: Criteria an unhinted round outline must meet to count as a calibration sphere
#: (:func:`select_spheres`; documented with their reasons in docs/spheres.md).
CRITERIA = {
    "max_residual_px": 1.5,      # RMS of the outline points about the fitted cone/circle
    "min_closed": 0.5,           # outline coverage (36 angular bins) over the visible outline
    "min_closed_photos": 0.8,    # the same, for an outline on the edges that hold in the photos
    "min_support": 0.5,          # inlier edge points per pixel of visible outline
    "min_neutral": 0.5,          # median min/max channel over the lit photos' pixels (white, grey, chrome)
    "min_shading_change": 0.1,   # share of the inside not brightest in the most common photo
    "size_ratio_pinhole": 2.0,   # implied depths of all spheres within this factor of each other
    "size_ratio_ortho": 1.25,    # apparent radii (orthographic) within this factor
    "max_light_disagreement_deg": 40.0,  # per-photo light directions vs the closest other sphere (3+ spheres)
    "max_center_sigma_px": 0.3,  # standard error of the fitted centre (a well-constrained fit)
    "min_highlight": 1.5,        # a mirror's brightest pixel over its surroundings' 95th percentile (max image)
    "min_light_spread": 0.2,     # spread (10th to 90th percentile) of ln(max / mean) inside 0.8 radii
    "light_spread_ratio": 0.5,   # and under this share of the round outlines' largest spread
    "min_moving_highlights": 3,  # or highlights of this many photos, each in its own place
    "max_outside_highlights": 3,  # a final outline with highlights of this many photos just outside it
}


def disc_pixels(ft, shape, frac: float = 0.7):
    """Row and column indices of the pixels within ``frac`` of the apparent radius, inside the image."""
    H, W = shape
    cx, cy = ft.center_px
    r = frac * ft.radius_px
    y0, y1 = max(int(np.floor(cy - r)), 0), min(int(np.ceil(cy + r)) + 1, H)
    x0, x1 = max(int(np.floor(cx - r)), 0), min(int(np.ceil(cx + r)) + 1, W)
    if y0 >= y1 or x0 >= x1:
        return np.zeros(0, int), np.zeros(0, int)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    m = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    return yy[m], xx[m]


def clip_levels(mx) -> np.ndarray:
    """Per channel, the level at or above which a pixel of the max image counts as clipped: 0.98 x its maximum.

    A file's clipped pixels all read the channel's largest code (after linearisation, the same
    value), so they sit at the channel's maximum over the image. In a floating-point image that
    never clipped this excludes only the few brightest pixels.
    """
    mx = np.asarray(mx, dtype=np.float64)
    peak = mx.reshape(-1, mx.shape[2])[:, :3].max(axis=0) if mx.ndim == 3 else np.array([mx.max()])
    return 0.98 * peak


def neutrality(mx, L, rows, cols, clip=None) -> float | None:
    """Colour neutrality of the pixels: the 25th percentile over the lit, unclipped pixels of min/max channel.

    1 for grey; a white, grey or chrome sphere stays near 1 (sensor noise and white balance
    aside). The lower quartile rather than the median, because a coloured glossy ball's
    highlights from many photos whiten much of it in the max image. Pixels with any channel at
    or above its clip level (``clip``, default :func:`clip_levels` of ``mx``) carry no colour
    evidence (a saturated red ball clips to white in an 8-bit file) and are left out (with
    ``clip`` None nothing is left out: floating-point images do not clip). 1 for a single-channel
    image; None when fewer than 5 lit pixels are unclipped (no evidence: the colour criterion is
    then skipped, as for a chrome ball whose lit pixels are all clipped highlights).
    """
    if not (mx.ndim == 3 and mx.shape[2] >= 3) or rows.size == 0:
        return 1.0
    px = mx[rows, cols][:, :3].astype(np.float64)
    lum = L[rows, cols]
    lit = lum > 0.1 * float(np.percentile(lum, 95))
    if lit.sum() < 5:
        return 1.0
    use = lit if clip is None else lit & ~np.any(px >= np.asarray(clip, dtype=np.float64), axis=1)
    if use.sum() < 5:
        return None
    ratio = px[use].min(axis=1) / np.maximum(px[use].max(axis=1), 1e-12)
    return float(np.clip(np.percentile(ratio, 25), 0, 1))


#: The per-photo colour evidence (:func:`ffls.spheres.detect.photo_colour_counts`) is kept for every
#: ``COLOUR_STEP``-th pixel of every ``COLOUR_STEP``-th row (a sphere's body colour is smooth; a
#: 3-pixel sphere still has 4 samples per photo).
COLOUR_STEP = 2


def photo_neutrality(counts, rows, cols, min_samples: int = 20) -> float | None:
    """Colour neutrality judged in the photos: the median min/max channel over every lit, unclipped (pixel, photo).

    ``counts`` (:func:`ffls.spheres.detect.photo_colour_counts`) holds, per sampled pixel (every
    ``COLOUR_STEP``-th), how many photos put it in each bin of the min/max channel ratio. The bins of the given pixels are pooled and
    their median is returned (the middle of its bin, linearly interpolated within it). A coloured
    glossy ball reads its body colour: its highlights are white in only a few photos per pixel, so
    they move the median little, while the max image, which keeps every photo's highlight, reads
    it white. None when fewer than ``min_samples`` samples (no evidence: a chrome ball whose lit
    pixels are all clipped highlights).

    Parameters
    ----------
    counts : (B, ceil(H / COLOUR_STEP), ceil(W / COLOUR_STEP)) int
    rows, cols : (m,) int
        The pixels (full-resolution indices; each is read at its sampled pixel).
    min_samples : int
    """
    if rows.size == 0:
        return None
    r, c = np.asarray(rows) // COLOUR_STEP, np.asarray(cols) // COLOUR_STEP
    ok = (r < counts.shape[1]) & (c < counts.shape[2])
    flat = np.unique(r[ok] * counts.shape[2] + c[ok])  # each sampled pixel once
    h = np.asarray(counts.reshape(counts.shape[0], -1)[:, flat], dtype=np.int64).sum(axis=1)
    total = int(h.sum())
    if total < min_samples:
        return None
    cum = np.cumsum(h)
    k = int(np.searchsorted(cum, 0.5 * total))
    below = float(cum[k - 1]) if k else 0.0
    frac = (0.5 * total - below) / max(float(h[k]), 1.0)
    return float(np.clip((k + frac) / len(h), 0.0, 1.0))


def shading_change(brightest, L, rows, cols) -> float:
    """Share of the lit pixels whose brightest photo is not the most common one.

    A sphere's pixels face different ways, so different photos light them best: a matte sphere's
    pixels split among the lights (Voronoi cells of the normals), a mirror's highlights each come
    from their own photo. A flat painted disc or a print is brightest in the same photo
    everywhere: the share is about 0.
    """
    lum = L[rows, cols]
    lit = lum > 0.05 * float(np.percentile(lum, 95)) if lum.size else lum > 0
    if lit.sum() < 10:
        return 1.0
    counts = np.bincount(brightest[rows[lit], cols[lit]])
    return float(1.0 - counts.max() / lit.sum())


def light_spread(max_over_mean, ft) -> float | None:
    """How much the light's change across the photos differs over a circle's inside: a sphere's, or a
    pattern's of the ground.

    ``ln(max / mean)`` of a pixel over the photos cancels its albedo (a Lambertian pixel's photos
    share it) and keeps how the lights fall on it, which depends on its normal. A flat patch of a
    textured ground faces one way: the ratio is the same all over it (as on the ground around it), and
    its spread stays within the noise's, however dark or bright the patch; a sphere faces every way
    and a mirror's highlights each sit in their own photo's place, so the ratio varies across it.
    Returns the 10th to 90th percentile spread of ``ln(max_over_mean)`` over the pixels within 0.8
    radii (inside the image; the limb's mixed pixels left out), or None with fewer than 20 of them.

    Parameters
    ----------
    max_over_mean : (H, W) float
        The max over the mean luminance of the photos (``exp`` of
        :func:`ffls.spheres.detect.shading_ratio`).
    ft : ffls.spheres.detect.SphereFit
    """
    rows, cols = disc_pixels(ft, max_over_mean.shape, 0.8)
    if rows.size < 20:
        return None
    v = np.log(np.maximum(np.asarray(max_over_mean, dtype=np.float64)[rows, cols], 1e-30))
    q10, q90 = np.percentile(v, [10, 90])
    return float(q90 - q10)


def moving_highlights(max_over_mean, brightest, L, ft) -> int:
    """How many photos hold a highlight on a circle: a mirror's highlights move with the light.

    A chrome ball mirrors the ground and the room, whose light changes as the ground's does, so away
    from its highlights its ``ln(max / mean)`` is as flat as the ground's (under 16 lights at 256 px
    the highlights fill less than a tenth of it). Its highlights are lit in one photo each: their
    ``ln(max / mean)`` stands above the rest of it, they are as bright in the max image as the
    brightest of the ground around it, and each is brightest in its own photo. A patch of the ground
    holds none. Returns the count of distinct brightest photos among the pixels within 0.95 radii
    whose ``ln(max / mean)`` exceeds the median inside 0.8 radii by ``ln 2`` and whose max
    luminance reaches the 95th percentile of the ring from 1.15 to 1.4 radii (0 where either holds
    fewer than 5 pixels in the frame).

    Parameters
    ----------
    max_over_mean : (H, W) float
    brightest : (H, W) int
        Per pixel, the brightest photo.
    L : (H, W) float
        Luminance of the max image.
    ft : ffls.spheres.detect.SphereFit
    """
    shape = L.shape
    rows, cols = disc_pixels(ft, shape, 1.4)
    d = np.hypot(cols - ft.center_px[0], rows - ft.center_px[1]) / ft.radius_px
    ring, disc, core = d >= 1.15, d <= 0.95, d <= 0.8
    if ring.sum() < 5 or core.sum() < 5:
        return 0
    v = np.log(np.maximum(np.asarray(max_over_mean, dtype=np.float64)[rows, cols], 1e-30))
    lum = np.asarray(L, dtype=np.float64)[rows, cols]
    hl = disc & (v > np.median(v[core]) + np.log(2.0)) & (lum >= np.percentile(lum[ring], 95))
    return int(np.unique(brightest[rows[hl], cols[hl]]).size)


def highlight_pixels(L, ratio, n_photos: int) -> np.ndarray:
    """(H, W) bool: the max image's highlights, pixels as bright as half its maximum and lit in
    about one photo (``ratio``, ``ln(max / mean)`` over the photos, above ``ln(n_photos / 2)``)."""
    L = np.asarray(L, dtype=np.float64)
    return (np.asarray(ratio) > np.log(n_photos / 2.0)) & (L >= 0.5 * float(L.max()))


def photos_highlighted_around(hl, brightest, ft) -> int:
    """How many photos hold a highlight (:func:`highlight_pixels`) just outside a circle, between
    1.1 and 1.6 radii: a mirror ball's highlights all lie on it, so a circle with highlights just
    around it is the outline of some of them, inside the ball (a chrome ball on a black ground,
    whose silhouette does not show: the cluster of its highlights outlined as a dark cap's
    enclosing circle, ``docs/spheres.md``, "A chrome ball on a black ground"). ``hl``: the max
    image's highlights (:func:`highlight_pixels`); ``brightest``: per pixel, the brightest photo."""
    rows, cols = disc_pixels(ft, hl.shape, 1.6)
    d = np.hypot(cols - ft.center_px[0], rows - ft.center_px[1]) / ft.radius_px
    out = (d >= 1.1) & hl[rows, cols]
    return int(np.unique(brightest[rows[out], cols[out]]).size)


def light_directions_per_photo(ft, brightest, n_photos: int, min_pixels: int = 3, L=None,
                               highlight_fraction: float = 0.8):
    """Per photo, the light direction a sphere's brightest pixels suggest, as matte and as mirror.

    The pixels (inside 0.95 of the outline) whose brightest photo is ``k`` face light ``k``: for a
    matte sphere their mean normal points near it (the light's cell among the others'). For a
    mirror only the highlight among them points at it: a mirror's pixels that reflect the lit
    table or room are brightest in whichever photo lights that most (under a near light on a
    table, most of a chrome ball's lower half is brightest in the same photo), so their mean points
    at the table. With the max image's luminance ``L``, a mirror's direction is the mean reflected
    view ray of the pixels within ``highlight_fraction`` of the brightest of them (clipped
    highlight pixels together); without it, of all of them. Camera frame.

    Parameters
    ----------
    ft : ffls.spheres.detect.SphereFit
    brightest : (H, W) int
        Per pixel, the brightest photo.
    n_photos : int
    min_pixels : int
        Photos with fewer of the sphere's pixels get NaN.
    L : (H, W) float, optional
        Luminance of the max image.
    highlight_fraction : float

    Returns
    -------
    matte, mirror : (n_photos, 3) float64
        Unit directions (NaN rows where the sphere has fewer than ``min_pixels`` pixels).
    """
    from ffls.camera.projection import pixel_rays

    rows, cols = disc_pixels(ft, brightest.shape, 0.95)
    matte = np.full((n_photos, 3), np.nan)
    mirror = np.full((n_photos, 3), np.nan)
    if rows.size == 0:
        return matte, mirror
    px = np.stack([cols, rows], axis=1).astype(np.float64)
    n = ft.normals(px)
    if ft.camera_model == "orthographic":
        v = np.tile([0.0, 0.0, -1.0], (len(px), 1))
    else:
        v = -pixel_rays(px, ft.K, ft.dist)
    ok = np.all(np.isfinite(n), axis=1)
    refl = 2.0 * np.sum(n * v, axis=1)[:, None] * n - v
    b = np.where(ok, brightest[rows, cols], -1)
    lum = None if L is None else np.asarray(L, dtype=np.float64)[rows, cols]
    for k in range(n_photos):
        sel = b == k
        if sel.sum() < min_pixels:
            continue
        m = n[sel].mean(axis=0)
        matte[k] = m / max(np.linalg.norm(m), 1e-12)
        if lum is not None:  # a mirror: the highlight, the brightest of these pixels (clipped ones together)
            lk = lum[sel]
            sel = np.flatnonzero(sel)[lk >= highlight_fraction * lk.max()]
        m = refl[sel].mean(axis=0)
        mirror[k] = m / max(np.linalg.norm(m), 1e-12)
    return matte, mirror


def _disagreement_deg(a, b) -> float:
    """Median angle (degrees) between two sets of per-photo directions over the photos both have (inf if < 3)."""
    both = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    if both.sum() < 3:
        return float("inf")
    return float(np.degrees(np.median(np.arccos(np.clip(np.sum(a[both] * b[both], axis=1), -1, 1)))))


def round_outline(ft, max_residual_px: float) -> bool:
    """Whether a fitted candidate is a round outline at all: the first test of :func:`select_spheres`.

    Its edge points fit within ``max_residual_px`` RMS, and they close (``min_closed``; for an
    outline found on the photos' edges ``min_closed_photos``: a silhouette holds in every photo all
    round, a contact shadow's boundary is an arc) and support (``min_support``) its part inside the
    image. A candidate that fails takes no part in any later test.
    """
    crit = CRITERIA
    closed, support = outline_closure(ft)
    min_closed = crit["min_closed_photos"] if ft.outline_edges == "photos" else crit["min_closed"]
    return bool(ft.residual_px <= max_residual_px and closed >= min_closed and support >= crit["min_support"])


def outline_closure(ft) -> tuple[float, float]:
    """``(closed, support)`` of a fitted outline over its part inside the image: the share of its
    angular bins its edge points cover (at most 1), and its inlier edge points per pixel of outline."""
    vis = max(ft.visible_fraction, 1e-6)
    return min(ft.coverage / vis, 1.0), ft.n_inliers / (2 * np.pi * ft.radius_px * vis)


def select_spheres(fits, mx, brightest, L, ortho: bool, n_photos, max_residual_px, min_visible,
                   saturates: bool = False, colour_counts=None, max_over_mean=None):
    """Stage 5 without hints: which fitted round outlines are calibration spheres.

    A candidate is a *round outline* when its fit residual is at most ``max_residual_px``, its
    inlier points cover at least :data:`CRITERIA` ``min_closed`` of the visible outline and give at
    least ``min_support`` points per pixel of it (an outline fitted on the edges that hold in the
    photos must cover ``min_closed_photos``: a silhouette holds there all round, while a contact
    shadow's boundary, which holds in many photos too, is an open arc). Overlapping round outlines keep the best-scored
    one (support x closure x (0.25 + 0.75 neutrality) / (1 + (rms / 0.5 px)^2)). A round outline
    is then set aside, with a one-line reason, when it is cut by the frame edge (less than
    ``min_visible`` of it inside), its centre is poorly constrained (standard error above
    ``max_center_sigma_px``), it is coloured (``min_neutral``), the light changes alike all over it
    as on a flat patch of the ground (with at least 3 photos and ``max_over_mean``: the spread of
    ``ln(max / mean)`` inside it, :func:`light_spread`, below ``min_light_spread`` and below
    ``light_spread_ratio`` of the largest spread among the neutral round outlines, and, with
    ``brightest``, the highlights of fewer than ``min_moving_highlights`` photos on it,
    :func:`moving_highlights`; a textured ground's blob, dark or bright, whatever its outline;
    judged after the other tests), its shading does not change
    across the photos as a sphere's does (``min_shading_change``, with at least 3 photos; not asked
    of a mirror ball's outer outline or dark cap, whose reflected table is brightest in the same
    photo: with at least 3 photos, lit by lights, such an outline must instead hold a highlight, its
    brightest pixel at least ``min_highlight`` times its surroundings' 95th percentile,
    :func:`ffls.spheres.mirror_outline.highlight_ratio`; a single probe photo under a smooth sky
    may show none; where the max image's surroundings clip and so give no evidence, the same ratio
    is taken on ``max_over_mean``, where each highlight, lit in one photo only, stands out of a
    clipped diffuse ground as much as of a dark one), or its
    size disagrees with the other spheres' (all spheres share ``sphere_radius``: implied depths
    within ``size_ratio_pinhole``, or apparent radii within ``size_ratio_ortho`` for an
    orthographic camera; the consistent group with the largest total score wins).

    Parameters
    ----------
    fits : list of ffls.spheres.detect.SphereFit
        The fitted candidates; each kept one gets its ``score`` set.
    mx : (H, W, 3) or (H, W) float
        Max image.
    brightest : (H, W) int or None
        Per pixel, the photo that is brightest there (None: the shading criterion is skipped).
    L : (H, W) float
        Luminance of ``mx``.
    ortho : bool
        Orthographic camera (sizes compared as pixel radii, not depths).
    n_photos : int
    max_residual_px, min_visible : float
    saturates : bool
        The photos are integer files that clip: colour is judged on the unclipped pixels only
        (:func:`clip_levels`, :func:`neutrality`; without ``colour_counts``).
    colour_counts : (B, H, W) int, optional
        Per-photo colour evidence (:func:`ffls.spheres.detect.photo_colour_counts`).
    max_over_mean : (H, W) float, optional
        The max over the mean luminance of the photos (``exp`` of
        :func:`ffls.spheres.detect.shading_ratio`): the mirror test's evidence where the max
        image's is clipped.

    Returns
    -------
    chosen : list of SphereFit
    rejected : list of str
    """
    shape = L.shape
    round_ = []
    clip = clip_levels(mx) if saturates and mx.ndim == 3 and mx.shape[2] >= 3 else None
    for ft in fits:
        if not round_outline(ft, max_residual_px):
            continue
        closed, support = outline_closure(ft)
        rows, cols = disc_pixels(ft, shape)
        if rows.size < 5:
            continue
        neutral = (photo_neutrality(colour_counts, rows, cols) if colour_counts is not None
                   else neutrality(mx, L, rows, cols, clip))
        ft.score = (min(support, 1.2) * closed * (0.25 + 0.75 * (0.5 if neutral is None else neutral))
                    / (1 + (ft.residual_px / 0.5) ** 2))
        round_.append((ft, neutral, rows, cols))
    round_.sort(key=lambda t: -t[0].score)
    # Overlapping round outlines keep the best-scored one. A candidate that fails a test of its own
    # suppresses the outlines it overlaps (a cropped sphere's highlight is no sphere); one set aside
    # only by the group tests (size, lights) does not: the overlap is judged again without it (a
    # chrome ball's highlight, a small sharp circle that outscores the ball's faint silhouette, is
    # set aside by its size, and the silhouette it hid is then judged).
    rejected, set_aside = [], set()
    while True:
        ok, alone = _judged_alone([t for t in round_ if id(t[0]) not in set_aside], brightest, L, n_photos,
                                  min_visible, colour_counts, max_over_mean)
        group_rej, ok = _judged_together(ok, brightest, L, ortho, n_photos)
        if not group_rej:
            break
        set_aside.update(id(ft) for ft, _ in group_rej)
        rejected.extend(why for _, why in group_rej)
    return ok, alone + rejected


def _highlight_evidence(L, max_over_mean, ft) -> tuple[float | None, str]:
    """A mirror candidate's :func:`highlight_ratio`, and where it was judged: on the max image, or,
    where that image clips around the circle, on the max over the mean of the photos."""
    hl = highlight_ratio(L, ft.center_px, ft.radius_px)
    if hl is None and max_over_mean is not None:
        return highlight_ratio(max_over_mean, ft.center_px, ft.radius_px), " (max over mean of the photos)"
    return hl, ""


def _judged_alone(round_, brightest, L, n_photos, min_visible, colour_counts, max_over_mean=None):
    """The distinct round outlines (best score first) that pass the tests of a single candidate, and the reasons of the others."""
    crit = CRITERIA
    distinct = []
    for t in round_:
        ft = t[0]
        if all(np.hypot(*(ft.center_px - o[0].center_px)) > 0.8 * (ft.radius_px + o[0].radius_px) for o in distinct):
            distinct.append(t)
    rejected, ok = [], []
    # the spread a sphere shows depends on the lights and on the values' encoding (an unstated camera
    # curve's stored codes compress it: four white spheres under 16 lights, filmic codes, 0.18-0.24):
    # a flat candidate is one whose spread is also well under the capture's most varied outline's
    # (a white, grey or chrome one: the object's coloured ball under the same lights varied 0.40)
    spreads = {id(t[0]): light_spread(max_over_mean, t[0]) for t in distinct} if (
        max_over_mean is not None and n_photos >= 3) else {}
    top = max((spreads[id(t[0])] for t in distinct if spreads.get(id(t[0])) is not None
               and (t[1] is None or t[1] >= crit["min_neutral"])), default=None)
    for ft, neutral, rows, cols in distinct:
        where = f"round outline at pixel ({ft.center_px[0]:.0f}, {ft.center_px[1]:.0f}), radius {ft.radius_px:.0f} px"
        if ft.visible_fraction < min_visible:
            rejected.append(f"{where}: cropped too much, only {ft.visible_fraction:.0%} of its outline is inside the"
                            f" image (needs {min_visible:.0%})")
        elif ft.center_sigma_px > crit["max_center_sigma_px"]:
            rejected.append(f"{where}: its centre is poorly constrained by the visible outline (standard error "
                            f"{ft.center_sigma_px:.2f} px > {crit['max_center_sigma_px']})")
        elif neutral is not None and neutral < crit["min_neutral"]:
            judged = "median over its lit pixels in the photos" if colour_counts is not None else "in the max image"
            rejected.append(f"{where}: coloured (min/max channel {neutral:.2f} < {crit['min_neutral']}, {judged}),"
                            f" not a white, grey or chrome sphere")
        elif (mirror := ft.source == OUTER_SOURCE or dark_cap(L, ft.center_px, ft.radius_px)) and n_photos >= 3 and (
                (hl := _highlight_evidence(L, max_over_mean, ft))[0] is not None and hl[0] < crit["min_highlight"]):
            rejected.append(f"{where}: outlined as a mirror ball's, but it holds no highlight (its brightest pixel is"
                            f" {hl[0]:.2f} x its surroundings' 95th percentile < {crit['min_highlight']}{hl[1]})")
        elif (brightest is not None and n_photos >= 3 and not mirror  # a mirror shows its room
              and (chg := shading_change(brightest, L, rows, cols)) < crit["min_shading_change"]):
            rejected.append(f"{where}: its shading does not change across the {n_photos} photos as a sphere's does"
                            f" (the same photo is brightest on {1 - chg:.0%} of it)")
        elif ((spread := spreads.get(id(ft))) is not None and spread < crit["min_light_spread"]
              and top is not None and spread < crit["light_spread_ratio"] * top
              and (brightest is None or (hls := moving_highlights(max_over_mean, brightest, L, ft))
                   < crit["min_moving_highlights"])):
            moving = "" if brightest is None else f", and highlights of {hls} photos"
            rejected.append(f"{where}: the light changes alike all over it, as on a flat patch of the ground (the"
                            f" spread of ln(max / mean) over the {n_photos} photos is {spread:.2f} inside it"
                            f" < {crit['min_light_spread']}, and under {crit['light_spread_ratio']:g} x the"
                            f" {top:.2f} of the neutral round outline it varies most on{moving}), not a sphere")
        else:
            ok.append(ft)
    return ok, rejected


def _judged_together(ok, brightest, L, ortho, n_photos):
    """The candidates set aside by the group tests (size consistency, agreeing lights) as (fit, reason), and the rest."""
    crit = CRITERIA
    rejected = []
    if len(ok) > 1:  # size consistency: all spheres share sphere_radius
        size = np.array([ft.radius_px if ortho else ft.distance for ft in ok])
        tol = np.log(crit["size_ratio_ortho"] if ortho else crit["size_ratio_pinhole"])
        groups = [(size >= s) & (size <= s * np.exp(tol)) for s in size]  # windows [s, ratio * s]
        best = max(range(len(ok)), key=lambda i: (sum(ft.score for ft, g in zip(ok, groups[i]) if g), -i))
        keep = groups[best]
        ref = float(np.median(size[keep]))
        for ft, k, s in zip(ok, keep, size):
            if not k:
                what = f"radius {s:.1f} px" if ortho else f"depth {s:.3g}"
                ref_s = f"{ref:.1f} px" if ortho else f"{ref:.3g}"
                rejected.append((ft, f"round outline at pixel ({ft.center_px[0]:.0f}, {ft.center_px[1]:.0f}), radius "
                                f"{ft.radius_px:.0f} px: its size ({what}) disagrees with the other spheres' ({ref_s})"))
        ok = [ft for ft, k in zip(ok, keep) if k]
    if len(ok) >= 3 and brightest is not None and n_photos >= 3:  # all spheres see the same lights
        dirs = [light_directions_per_photo(ft, brightest, n_photos, L=L) for ft in ok]
        closest = []
        for i in range(len(ok)):
            closest.append(min(_disagreement_deg(a, b) for j in range(len(ok)) if j != i
                               for a in dirs[i] for b in dirs[j]))
        lim = crit["max_light_disagreement_deg"]
        agree = [c <= lim for c in closest]
        if sum(agree) >= 2:
            for ft, a, c in zip(ok, agree, closest):
                if not a:
                    rejected.append((ft, f"round outline at pixel ({ft.center_px[0]:.0f}, {ft.center_px[1]:.0f}), radius "
                                    f"{ft.radius_px:.0f} px: the lights its shading shows disagree with every other "
                                    f"sphere's (median {c:.0f} deg > {lim:.0f} to the closest, as matte or mirror)"))
            ok = [ft for ft, a in zip(ok, agree) if a]
    return rejected, ok
