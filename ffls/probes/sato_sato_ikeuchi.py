"""Illumination from cast shadows: Sato, Sato and Ikeuchi's geodesic-dome method.

Sato, Sato, Ikeuchi, "Illumination distribution from shadows", CVPR 1999 (summarised in
``shared/papers/illumination-estimation-survey.txt``, section 2). An occluder of known shape
stands on a receiving surface of known geometry; the illumination is discretised on the nodes of
a geodesic dome over the receiver's hemisphere (each node a patch of nearly equal solid angle,
for example 521 nodes). For a receiver point ``x``, whether node ``i`` reaches it is the
*occlusion coefficient* ``S(x, i)`` in {0, 1}, found by casting a ray from ``x`` toward the node
against the occluder (a box: slab test; a triangle mesh: Moeller-Trumbore, both vectorised over
points x nodes). The shadow image is then linear in the nodes' intensities ``E_i``
(irradiance at normal incidence, i.e. radiance x solid angle):

    I(x) = sum_i f(x, i) S(x, i) E_i.

The three cases of the paper:

``'lambertian'``
    known albedo: ``f = rho / pi cos(theta_i)``;
``'torrance_sparrow'``
    the simplified Torrance-Sparrow model, ``f = K_d cos(theta_i) + K_s / cos(theta_r)
    exp(-alpha^2 / (2 sigma^2))`` with ``K_d = rho / pi``, ``theta_r`` the viewing angle and
    ``alpha`` the angle between the normal and the half vector (``K_s``, ``sigma`` given);
``'ratio'``
    unknown albedo: the shadow image is divided by a *surface image* taken without the occluder.
    For a planar receiver under distant light the unshadowed irradiance ``E_0 = sum_i E_i
    cos(theta_i)`` is the same at every point, so ``I / I_surface = sum_i cos(theta_i) S(x, i)
    E_i / E_0``: linear in ``E / E_0`` whatever the (even spatially varying) albedo. The scale
    ``E_0`` then comes from the surface image and a reference albedo (the paper calibrates the
    camera with a white surface: ``reference_albedo = 1``).

The system is solved by non-negative least squares (``scipy.optimize.nnls``) by default, or
plain least squares. Nodes that the occluder never hides from any pixel are told apart only by
their cosine, so they are nearly collinear; the optional first-difference ``smoothness`` fills
them from their neighbours (:func:`ffls.probes.linear.solve_sources`).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from ffls.conventions import normalize
from ffls.errors import InputError
from ffls.probes.hougen_ahuja import SourceFit
from ffls.probes.linear import as_rgb_pixels, broadcast_albedo, neighbour_edges, solve_sources
from ffls.probes.sources import geodesic_frequency_for, geodesic_sources

__all__ = [
    "CASES",
    "shadow_in_view",
    "elevation_limit",
    "box_triangles",
    "box_visibility",
    "mesh_visibility",
    "ray_triangle",
    "occluder_visibility",
    "shadow_kernel",
    "dome_nodes",
    "sato_sato_ikeuchi",
    "shadow_confidence",
    "estimate_lighting_SatoSatoIkeuchi1999",
]

#: The receiver models.
CASES = ("lambertian", "torrance_sparrow", "ratio")


def dome_nodes(n: int = 521, normal=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Nodes of the geodesic dome over the hemisphere around ``normal`` nearest ``n`` in number.

    Parameters
    ----------
    n : int
        Wanted number (frequency 10 gives 526 with the horizon ring, the size of the paper's 521).
    normal : (3,) array_like
        The receiver's normal (pole of the dome).

    Returns
    -------
    (k, 3) float64
        Unit directions with ``d . normal >= 0``.
    """
    hemi = {"axis": [float(v) for v in normalize(np.asarray(normal, dtype=np.float64).reshape(3))]}
    return geodesic_sources(geodesic_frequency_for(n, hemi), hemi)


def box_triangles(center, size, rotation=None) -> np.ndarray:
    """The 12 triangles (12, 3, 3) of a box (world frame), for :func:`mesh_visibility`.

    Parameters
    ----------
    center, size : (3,) array_like
    rotation : (3, 3) array_like, optional
        World-from-box rotation (axis-aligned by default).
    """
    c = np.asarray(center, dtype=np.float64).reshape(3)
    h = 0.5 * np.asarray(size, dtype=np.float64).reshape(3)
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64) * h
    v = corners @ R.T + c
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = []
    for a, b, cc, d in quads:
        tris += [(a, b, cc), (a, cc, d)]
    return v[np.asarray(tris)]


def _check_points(points) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must be (m, 3), not {p.shape}")
    if not np.all(np.isfinite(p)):
        raise InputError("receiver points hold NaN or Inf")
    return p


def box_visibility(points, directions, center, size, rotation=None, chunk: int = 1 << 21) -> np.ndarray:
    """Whether each node reaches each point past a box: slab test on every ray (vectorised).

    Parameters
    ----------
    points : (m, 3) array_like
        Receiver points (outside the box).
    directions : (n, 3) array_like
        Unit node directions.
    center, size : (3,) array_like
        The box (world frame).
    rotation : (3, 3) array_like, optional
        World-from-box rotation.
    chunk : int
        Rays (points x nodes) per block.

    Returns
    -------
    (m, n) bool
        True where the ray ``x + t d`` (t > 0) misses the box.
    """
    p = _check_points(points)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    c = np.asarray(center, dtype=np.float64).reshape(3)
    h = 0.5 * np.abs(np.asarray(size, dtype=np.float64).reshape(3))
    o = (p - c) @ R  # box frame
    dl = d @ R
    with np.errstate(divide="ignore"):
        inv = 1.0 / np.where(dl == 0.0, 1e-300, dl)
    out = np.empty((p.shape[0], d.shape[0]), dtype=bool)
    rows = max(1, chunk // max(1, d.shape[0]))
    for s in range(0, p.shape[0], rows):
        oo = o[s:s + rows, None, :]
        with np.errstate(invalid="ignore", over="ignore"):
            a = (-h - oo) * inv
            b = (h - oo) * inv
        t0 = np.max(np.minimum(a, b), axis=2)
        t1 = np.min(np.maximum(a, b), axis=2)
        out[s:s + rows] = ~((t0 <= t1) & (t1 > 0))
    return out


def ray_triangle(origins, directions, v0, e1, e2, det_eps: float):
    """Moeller-Trumbore ray-triangle intersection, broadcast over any leading shapes.

    Parameters
    ----------
    origins, directions : (..., 3) array_like
        Rays ``x + t d``.
    v0, e1, e2 : (..., 3) array_like
        Each triangle's first vertex and its two edges from it.
    det_eps : float
        Rays closer to parallel (``|det| <= det_eps``) never hit.

    Returns
    -------
    inside : (...) bool
        The ray's line passes inside the triangle (and is not parallel to it).
    u, v, t : (...) float
        Barycentric coordinates of the crossing and its ray parameter (any sign).
    """
    h = np.cross(directions, e2)
    a = np.sum(e1 * h, axis=-1)
    ok = np.abs(a) > det_eps
    f = np.where(ok, 1.0 / np.where(ok, a, 1.0), 0.0)
    sv = origins - v0
    u = f * np.sum(sv * h, axis=-1)
    q = np.cross(sv, e1)
    v = f * np.sum(directions * q, axis=-1)
    t = f * np.sum(e2 * q, axis=-1)
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1), u, v, t


def mesh_visibility(points, directions, triangles, eps: float = 1e-9, chunk: int = 1 << 20) -> np.ndarray:
    """Whether each node reaches each point past a triangle mesh (Moeller-Trumbore, vectorised).

    Parameters
    ----------
    points : (m, 3) array_like
        Receiver points.
    directions : (n, 3) array_like
        Unit node directions.
    triangles : (F, 3, 3) array_like
        Triangle vertices (world frame); orientation does not matter.
    eps : float
        Hits at ``t <= eps`` (the point's own surface) are ignored.
    chunk : int
        Rays per block.

    Returns
    -------
    (m, n) bool
        True where the ray ``x + t d`` (t > eps) meets no triangle.
    """
    p = _check_points(points)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    if tri.shape[0] == 0:
        return np.ones((p.shape[0], d.shape[0]), dtype=bool)
    # cull: rays from a point can only hit triangles within the bounding sphere's cone
    bc = tri.reshape(-1, 3).mean(axis=0)
    br = float(np.max(np.linalg.norm(tri.reshape(-1, 3) - bc, axis=1))) * (1 + 1e-9)
    out = np.ones((p.shape[0], d.shape[0]), dtype=bool)
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    rows = max(1, chunk // max(1, d.shape[0]))
    for s in range(0, p.shape[0], rows):
        ps = p[s:s + rows]
        oc = bc - ps  # (r, 3)
        tc = oc @ d.T  # (r, n)
        dist2 = np.sum(oc * oc, axis=1)[:, None] - tc * tc
        near = (dist2 <= br * br) & ((tc > 0) | (np.sum(oc * oc, axis=1)[:, None] <= br * br))
        ri, ni = np.nonzero(near)
        if ri.size == 0:
            continue
        o = ps[ri]
        dd = d[ni]
        hit = np.zeros(ri.size, dtype=bool)
        for f in range(tri.shape[0]):
            inside, _, _, t = ray_triangle(o, dd, v0[f], e1[f], e2[f], 1e-15)
            hit |= inside & (t > eps)
        blk = out[s:s + rows]
        blk[ri[hit], ni[hit]] = False
    return out


def occluder_visibility(points, directions, occluder) -> np.ndarray:
    """Visibility (m, n) bool of every node from every receiver point past an occluder.

    Parameters
    ----------
    points : (m, 3) array_like
    directions : (n, 3) array_like
    occluder : dict or (F, 3, 3) array_like
        ``{'box': {'center': [...], 'size': [...], 'rotation': 3x3 (optional)}}`` (the
        ``probe.json`` form), ``{'triangles': (F, 3, 3)}``, or the triangles themselves.

    Returns
    -------
    (m, n) bool
    """
    if isinstance(occluder, dict):
        if "box" in occluder:
            b = occluder["box"]
            return box_visibility(points, directions, b["center"], b["size"], b.get("rotation"))
        if "triangles" in occluder:
            return mesh_visibility(points, directions, occluder["triangles"])
        raise ValueError("occluder must hold 'box' or 'triangles'")
    return mesh_visibility(points, directions, occluder)


def shadow_in_view(points, directions, occluder, plane_normal=(0.0, 0.0, 1.0), margin: float = 0.0) -> np.ndarray:
    """Whether each node casts its *whole* shadow inside the observed receiver.

    The shadow of a node low over the horizon runs past the view: the photograph then shows its
    sides but not its far end, so the node's elevation (and with it its intensity, seen on the
    plane only as ``E cos(theta)``) is not resolved by the data. A node's shadow is in view when
    every vertex of the occluder's convex hull, projected along the node's direction onto the
    plane, lands within two pixel spacings (the median distance between neighbouring receiver
    points, twice: a point inside the observed area is within one spacing of a pixel; twice
    allows for the gaps of subsampled pixels) of a receiver point.

    Parameters
    ----------
    points : (m, 3) array_like
        Receiver points (on the plane).
    directions : (n, 3) array_like
        Unit node directions.
    occluder : dict or (F, 3, 3) array_like
        As :func:`occluder_visibility`.
    plane_normal : (3,) array_like
    margin : float
        Pixel spacings of observed plane wanted around every projected vertex (0: the test
        above): with ``margin > 0`` the points ``margin`` spacings away from it along the plane
        (four of them, on two axes in the plane) must pass the same test, so the shadow's end is
        seen with plane beyond it.

    Returns
    -------
    (n,) bool
        False also for nodes at or below the horizon.
    """
    p = _check_points(points)
    d = normalize(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
    nrm = normalize(np.asarray(plane_normal, dtype=np.float64).reshape(3))
    if isinstance(occluder, dict):
        if "box" in occluder:
            b = occluder["box"]
            tri = box_triangles(b["center"], b["size"], b.get("rotation"))
        elif "triangles" in occluder:
            tri = np.asarray(occluder["triangles"], dtype=np.float64)
        else:
            raise ValueError("occluder must hold 'box' or 'triangles'")
    else:
        tri = np.asarray(occluder, dtype=np.float64)
    v = np.unique(tri.reshape(-1, 3), axis=0)
    if v.shape[0] >= 4:
        try:
            v = v[ConvexHull(v).vertices]
        except QhullError:  # a flat occluder (coplanar vertices): every vertex stands
            pass
    p0 = p.mean(axis=0)
    tree = cKDTree(p)
    spacing = float(np.median(tree.query(p, k=2)[0][:, 1])) if p.shape[0] > 1 else 0.0
    height = (v - p0) @ nrm  # (k,) above the plane
    cos = d @ nrm  # (n,)
    out = np.zeros(d.shape[0], dtype=bool)
    up = cos > 1e-9
    if not np.any(up):
        return out
    t = np.maximum(height, 0.0)[None, :] / cos[up, None]  # (n', k)
    proj = v[None, :, :] - t[..., None] * d[up, None, :]  # (n', k, 3)
    probes = proj[:, :, None, :]
    if margin > 0:
        a = normalize(np.cross(nrm, [1.0, 0.0, 0.0] if abs(nrm[0]) < 0.9 else [0.0, 1.0, 0.0]))
        b = np.cross(nrm, a)
        off = float(margin) * spacing * np.stack([a, -a, b, -b])
        probes = probes + np.concatenate([np.zeros((1, 3)), off])[None, None, :, :]
    dist, _ = tree.query(probes.reshape(-1, 3))
    out[up] = np.all(dist.reshape(probes.shape[:3]) <= 2.0 * spacing, axis=(1, 2))
    return out


def elevation_limit(points, directions, occluder, plane_normal=(0.0, 0.0, 1.0), step_deg: float = 0.5,
                    margin: float = 2.0) -> np.ndarray:
    """Per direction: the lowest elevation, at its azimuth, whose whole shadow is seen to end in view.

    Below it the shadow runs past the photograph: its sides (the azimuth) are seen, and the
    lit plane gives the light's ``E sin(elevation)``, but no pixel shows where it ends, so any
    lower elevation with the power scaled by ``sin`` explains the image as well. A light found
    there has an elevation the data do not fix, and its power (``1 / sin``) with it:
    ``benchmarks/probes_shadow_limit.py`` measures how far apart such maps relight an object.

    Parameters
    ----------
    points : (m, 3) array_like
        Receiver points (on the plane).
    directions : (n, 3) array_like
        Only their azimuth about ``plane_normal`` is used.
    occluder : dict or (F, 3, 3) array_like
        As :func:`occluder_visibility`.
    plane_normal : (3,) array_like
    step_deg : float
        Elevations tried, from ``step_deg`` up to 90 degrees (the shadow's far end moves by
        about ``h step / sin^2(elevation)`` a step, for an occluder ``h`` high).
    margin : float
        :func:`shadow_in_view`'s margin: 2 pixel spacings of plane beyond the shadow's far end
        (a fit can put a light whose shadow runs out of the view on a node whose shadow ends a
        pixel or two short of the edge, at a small cost in residual: such a node is no more
        resolved than one below it).

    Returns
    -------
    (n,) float64
        Radians; 0 along the normal (no azimuth); NaN where no elevation's shadow is wholly in
        view.
    """
    d = normalize(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
    nrm = normalize(np.asarray(plane_normal, dtype=np.float64).reshape(3))
    if not 0.0 < float(step_deg) < 90.0:
        raise ValueError(f"step_deg must be in (0, 90), not {step_deg!r}")
    flat = d - (d @ nrm)[:, None] * nrm
    norm = np.linalg.norm(flat, axis=1)
    out = np.zeros(d.shape[0])
    has = norm > 1e-9
    if not np.any(has):
        return out
    a = flat[has] / norm[has, None]
    el = np.radians(np.arange(float(step_deg), 90.0, float(step_deg)))
    cand = np.cos(el)[None, :, None] * a[:, None, :] + np.sin(el)[None, :, None] * nrm  # (n', e, 3)
    ok = shadow_in_view(points, cand.reshape(-1, 3), occluder, nrm, margin).reshape(cand.shape[:2])
    first = np.argmax(ok, axis=1)
    out[has] = np.where(ok.any(axis=1), el[first], np.nan)
    return out


def shadow_kernel(directions, visibility, plane_normal, case: str = "lambertian", albedo=1.0, view_dirs=None,
                  specular: dict | None = None) -> np.ndarray:
    """The linear model of a shadow image: ``I[x, c] = sum_i K[x, i, c] E[i, c]``.

    Parameters
    ----------
    directions : (n, 3) array_like
        Unit node directions.
    visibility : (m, n) array_like of bool
        Occlusion coefficients ``S(x, i)``.
    plane_normal : (3,) array_like
    case : {'lambertian', 'torrance_sparrow', 'ratio'}
        For ``'ratio'`` the kernel is ``cos(theta_i) S`` and predicts ``I / I_surface`` from
        ``E / E_0``.
    albedo : float, (3,), (m,) or (m, 3) array_like
        Unused by ``'ratio'``.
    view_dirs : (m, 3) array_like
        ``'torrance_sparrow'``: unit directions to the camera.
    specular : dict
        ``'torrance_sparrow'``: ``{'ks': , 'sigma': }``.

    Returns
    -------
    (m, n, 3) float64
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    V = np.asarray(visibility, dtype=np.float64)
    m = V.shape[0]
    nrm = normalize(np.asarray(plane_normal, dtype=np.float64).reshape(3))
    cos_i = np.maximum(d @ nrm, 0.0)
    if case == "ratio":
        return np.repeat((cos_i[None, :] * V)[:, :, None], 3, axis=2)
    rho = broadcast_albedo(albedo, m)
    K = (cos_i[None, :] * V)[:, :, None] * (rho[:, None, :] / np.pi)
    if case == "torrance_sparrow":
        if view_dirs is None or specular is None:
            raise InputError("the Torrance-Sparrow case needs view directions and the specular "
                             "parameters {'ks', 'sigma'}")
        v = normalize(np.asarray(view_dirs, dtype=np.float64).reshape(m, 3))
        cos_r = v @ nrm
        if np.any(cos_r <= 0):
            raise InputError("the camera sees the receiver from behind")
        h = normalize(d[None, :, :] + v[:, None, :])
        alpha = np.arccos(np.clip(h @ nrm, -1.0, 1.0))
        spec = float(specular["ks"]) / cos_r[:, None] * np.exp(-alpha ** 2 / (2.0 * float(specular["sigma"]) ** 2))
        K = K + (spec * (cos_i[None, :] > 0) * V)[:, :, None]
    elif case != "lambertian":
        raise ValueError(f"case must be one of {CASES}, not {case!r}")
    return K


def sato_sato_ikeuchi(points, radiance, occluder, plane_normal=(0.0, 0.0, 1.0), nodes=521, case: str = "lambertian",
                      albedo=1.0, surface_radiance=None, view_dirs=None, specular: dict | None = None,
                      nonnegative: bool = True, smoothness: float = 0.0, reference_albedo: float = 1.0,
                      visibility=None) -> SourceFit:
    """Recover a dome of node intensities from a cast shadow (Sato, Sato and Ikeuchi 1999).

    Parameters
    ----------
    points : (m, 3) array_like
        World points of the receiver pixels (on the plane, not hidden by the occluder).
    radiance : (m,) or (m, 3) array_like
        Their linear values in the shadow image.
    occluder : dict or (F, 3, 3) array_like
        See :func:`occluder_visibility`.
    plane_normal : (3,) array_like
        The receiver's normal (the dome's pole); the receiver is planar.
    nodes : int or (n, 3) array_like
        Dome size for :func:`dome_nodes`, or explicit node directions.
    case : {'lambertian', 'torrance_sparrow', 'ratio'}
        The receiver model (module docstring).
    albedo : float, (3,), (m,) or (m, 3) array_like
        ``rho`` for ``'lambertian'`` and ``'torrance_sparrow'`` (``K_d = rho / pi``); unused by
        ``'ratio'``.
    surface_radiance : (m,) or (m, 3) array_like
        ``'ratio'`` only: the same pixels without the occluder.
    view_dirs : (m, 3) array_like
        ``'torrance_sparrow'`` only: unit directions from the points to the camera.
    specular : dict
        ``'torrance_sparrow'`` only: ``{'ks': K_s, 'sigma': sigma (radians)}``.
    nonnegative : bool
        NNLS (default) or plain least squares.
    smoothness : float
        First-difference penalty between neighbouring nodes (0: the paper's plain fit).
    reference_albedo : float
        ``'ratio'`` only: the albedo that makes the surface image's scale absolute
        (``E_0 = pi mean(I_surface) / reference_albedo``); 1 for a white-calibrated camera.
    visibility : (m, n) array_like of bool, optional
        Precomputed occlusion coefficients (skips the ray tests).

    Returns
    -------
    SourceFit
        ``directions`` are the nodes, ``hemisphere`` the dome's; ``rendered`` re-renders the
        input (for ``'ratio'``: the ratio image times the surface image).

    Raises
    ------
    InputError
        The occluder casts no shadow on any given pixel; a singular system; bad values.
    """
    if case not in CASES:
        raise ValueError(f"case must be one of {CASES}, not {case!r}")
    p = _check_points(points)
    m = p.shape[0]
    if m == 0:
        raise InputError("no receiver pixels")
    b = as_rgb_pixels(radiance, m)
    nrm = normalize(np.asarray(plane_normal, dtype=np.float64).reshape(3))
    hemi = {"axis": [float(v) for v in nrm]}
    if isinstance(nodes, (int, np.integer)):
        dirs = dome_nodes(int(nodes), nrm)
    else:
        dirs = normalize(np.asarray(nodes, dtype=np.float64).reshape(-1, 3))
    V = occluder_visibility(p, dirs, occluder) if visibility is None else np.asarray(visibility, dtype=bool)
    if V.shape != (m, dirs.shape[0]):
        raise ValueError(f"visibility must be {(m, dirs.shape[0])}, not {V.shape}")
    cos_i = np.maximum(dirs @ nrm, 0.0)
    shadowed = ~V & (cos_i[None, :] > 0)
    if not shadowed.any():
        raise InputError("the occluder casts no shadow on the receiver pixels in view: "
                         "nothing to recover the lighting from")
    if case == "ratio":
        if surface_radiance is None:
            raise InputError("the unknown-albedo case needs the surface image (without the occluder)")
        s = as_rgb_pixels(surface_radiance, m, "surface image")
        if np.any(s <= 0):
            raise InputError("the surface image has pixels <= 0 where the receiver is seen")
        target = b / s
    else:
        target = b
    K = shadow_kernel(dirs, V, nrm, case, albedo, view_dirs, specular)
    edges = neighbour_edges(dirs) if smoothness > 0 else None
    what = f"{dirs.shape[0]} dome nodes"
    x = np.zeros((dirs.shape[0], 3))
    pred = np.empty((m, 3))
    conds, ranks = [], []
    observed = None
    same = bool(np.all(K == K[:, :, :1]))
    for chans in ([0, 1, 2],) if same else ([0], [1], [2]):
        sol = solve_sources(K[:, :, chans[0]], target[:, chans], None, nonnegative, None if nonnegative else 1e-8,
                            what, smoothness, edges)
        x[:, chans] = sol.x
        pred[:, chans] = sol.predicted
        conds.append(sol.condition)
        ranks.append(sol.rank)
        observed = sol.observed
    cond, rank = max(conds), min(ranks)
    if case == "ratio":
        e0 = np.pi * np.mean(s, axis=0) / float(reference_albedo)
        intensities = x * e0
        rendered = pred * s
    else:
        intensities = x
        rendered = pred
    rms = float(np.sqrt(np.mean((rendered - b) ** 2)))
    ref = float(np.sqrt(np.mean(b ** 2)))
    return SourceFit(directions=dirs, intensities=intensities, ambient=np.zeros(3), rendered=rendered, rms=rms,
                     relative_rms=rms / ref if ref > 0 else np.inf, condition=cond, method="SatoSatoIkeuchi1999",
                     hemisphere=hemi, rank=rank, observed=observed)


#: The colour-hdri style name of :func:`sato_sato_ikeuchi`.
estimate_lighting_SatoSatoIkeuchi1999 = sato_sato_ikeuchi


def shadow_confidence(directions, visibility, plane_normal=(0.0, 0.0, 1.0), height: int = 64) -> np.ndarray:
    """Per lat-long texel: the share of receiver pixels from which its node is hidden by the occluder.

    A node whose shadow falls on no pixel in view (0) is constrained only through the total
    irradiance of the plane, together with every other such node: its light is a guess. Nodes
    below the receiver's horizon are 0 too (the plane sees no light from there).

    Parameters
    ----------
    directions : (n, 3) array_like
        Dome nodes.
    visibility : (m, n) array_like of bool
        :func:`occluder_visibility` of the receiver pixels.
    plane_normal : (3,) array_like
    height : int

    Returns
    -------
    (height, 2 height) float64 in [0, 1]
    """
    from ffls.probes.sources import cells_to_latlong

    V = np.asarray(visibility, dtype=bool)
    nrm = normalize(np.asarray(plane_normal, dtype=np.float64).reshape(3))
    share = (~V).mean(axis=0)
    return cells_to_latlong(directions, share, height, {"axis": [float(v) for v in nrm]})
