"""Light maps from a probe folder: the pipelines behind :func:`ffls.probes.estimate_lightmap`.

Each pipeline reads a :class:`ffls.io.probe.Probe` (images, camera, sphere, geometry), runs one
paper's method on arrays and returns a :class:`ffls.probes.result.LightmapEstimate`.
"""
from __future__ import annotations

import cv2
import numpy as np

from ffls.conventions import normalize
from ffls.errors import InputError
from ffls.lightmaps.lightmap import LightMap
from ffls.probes.bracket import view_radiance
from ffls.probes.debevec import (CAMERA_CONE_DEG, RIM_PX, blind_spot, fill_unseen, latlong_solid_angles,
                                 merge_mirror_views, unwrap_mirror_ball_Debevec1998)
from ffls.probes.locate import locate_sphere
from ffls.probes.result import LightmapEstimate
from ffls.probes.sato_sato_ikeuchi import ray_triangle

__all__ = ["FILL_MODES", "POCS_SOURCES", "CAMERA_SIZE", "SHADOW_CASES", "camera_cone", "mirror_lightmap", "diffuse_pixels",
           "diffuse_lightmap", "pocs_lightmap", "pixel_grid_subset", "shadow_pixels", "shadow_lightmap", "object_pixels"]

#: How unseen directions are filled: from the nearest seen ones, or left black.
FILL_MODES = ("nearest", "zero")


def _integer_images(view) -> bool:
    return any(im.path.suffix.lower() not in (".exr", ".hdr", ".pic") for im in view.images)


#: Default radius (scene units, metres) of what stands at the camera: the photographer and the tripod.
CAMERA_SIZE = 0.5
#: The coarsest map height at which the mirror method measures its blind spot: below it a texel
#: (45 degrees tall at height 4) holds the camera cone whole and counts as seen through its other
#: directions, so smaller maps are measured on a second unwrap at this height.
BLIND_SPOT_HEIGHT = 64


def camera_cone(geo, camera_size: float = CAMERA_SIZE, fallback_deg: float = CAMERA_CONE_DEG) -> tuple[float, str]:
    """The half-angle (degrees) of the cone the camera and photographer fill, seen from the ball, and how it was set.

    ``atan(camera_size / D)`` with ``D`` the camera's distance from the ball, when the ball is
    located in scene units (a pinhole camera and a stated radius); otherwise ``fallback_deg``.
    """
    if geo.camera_model == "pinhole" and geo.radius_known:
        D = float(np.linalg.norm(geo.center_cam))
        return float(np.degrees(np.arctan(camera_size / D))), f"{camera_size:g} at {D:.3g} from the ball"
    return float(fallback_deg), "camera distance unknown: default"


def _located_views(probe, material: str, needs: str, other: str):
    """Each view of ``probe``, checked to show a ``material`` sphere, with its radiance and the located sphere.

    Yields ``(tag, view, radiance, geometry)``: ``tag`` prefixes notes ("view k: " with several views).
    A view of another material is one line naming its key and ``ffls probe OTHER``.
    A view whose ``probe.json`` states no material is taken to show a ``material`` sphere (the
    command says what the sphere is), and its note says so.
    """
    from dataclasses import replace

    src = probe.json_path
    for k, view in enumerate(probe.views):
        tag = "" if len(probe.views) == 1 else f"view {k + 1}: "
        key = "sphere.material" if len(probe.views) == 1 else f"images[{k}].sphere.material"
        stated = view.sphere.material is not None
        if stated and view.sphere.material != material:
            raise InputError(f"{key}: {needs}, this one is {view.sphere.material!r} (use 'ffls probe {other}')", src)
        if not stated:
            view = replace(view, sphere=replace(view.sphere, material=material))
        vr = view_radiance(view, probe.encoding, probe.response, src)
        if not stated:
            vr.note += f"; {key} not stated in probe.json: taken as {material!r} (ffls probe {material})"
        yield tag, view, vr, locate_sphere(view, vr.radiance, src, saturates=_integer_images(view))


def mirror_lightmap(probe, height: int = 128, camera_cone_deg: float | None = None, rim_px: float = RIM_PX,
                    supersample: int | None = None, weight_power: float = 2.0, fill: str = "nearest",
                    camera_size: float = CAMERA_SIZE, resample: str = "splat") -> LightmapEstimate:
    """A light map from one or more photographs (or brackets) of a mirror ball (Debevec 1998).

    Parameters
    ----------
    probe : ffls.io.probe.Probe
    height : int
        Map height (width ``2 height``).
    camera_cone_deg : float or None
        Half-angle of the masked cone around the direction toward the camera (the camera and
        photographer); 0 keeps it. None (default): ``atan(camera_size / D)`` for a ball at a known
        distance ``D`` (:func:`camera_cone`), else 10 degrees.
    rim_px : float
        Width of the rim left out, pixels.
    supersample : int or None
        Directions per texel side; None: about 4 samples per pixel of the ball
        (:func:`ffls.probes.debevec.auto_supersample`).
    weight_power : float
        Views are merged with weights ``confidence ** weight_power``.
    fill : {'nearest', 'zero'}
        Unseen directions: from the nearest seen ones (default), or black.
    camera_size : float
        Radius (scene units) of the camera and photographer, for the default cone.
    resample : {'splat', 'bilinear'}
        How the photo's pixels become texels (:func:`ffls.probes.debevec.unwrap_mirror_ball_Debevec1998`):
        each pixel spread over the directions its footprint reflects (default), or the photo sampled
        bilinearly at each direction.

    Returns
    -------
    LightmapEstimate
        ``details``: ``views`` (per view: sphere, the 95% radius of its centre where stated
        (``center_uncertainty_px``, else None), a larger circle of steps enclosing its limb (``enclosed_by``:
        ``center_px``, ``radius_px``, ``coverage``, else None), seen fraction), ``seen_fraction``,
        ``blind_spot_sr``, ``blind_spot_fraction``, ``camera_cone_sr``, ``clipped_fraction``.

    Raises
    ------
    InputError
        A view whose sphere is not a mirror, no sphere found, an unreadable or unusable image,
        a view that shows no usable direction.
    """
    if fill not in FILL_MODES:
        raise ValueError(f"fill must be one of {FILL_MODES}, not {fill!r}")
    views, notes, per_view = [], [], []
    sa = latlong_solid_angles(int(height))
    located = []
    for tag, view, vr, geo in _located_views(probe, "mirror", "the mirror method needs a mirror ball", "diffuse"):
        cone, why = (float(camera_cone_deg), "given") if camera_cone_deg is not None else camera_cone(geo, camera_size)
        located.append((tag, view, vr, geo, cone, why))

    def unwrap(view, vr, geo, cone, h):
        return unwrap_mirror_ball_Debevec1998(
            vr.radiance, geo.camera_model, geo.K, geo.dist, geo.world_from_camera, geo.center_cam, geo.radius,
            geo.center_px, geo.radius_px, height=h, valid=vr.valid, saturated=vr.saturated,
            camera_cone_deg=cone, rim_px=rim_px, supersample=supersample,
            reflectance=view.sphere.reflectance, resample=resample)

    for tag, view, vr, geo, cone, why in located:
        mv = unwrap(view, vr, geo, cone, height)
        frac = float(sa[mv.confidence > 0].sum() / (4 * np.pi))
        if frac == 0:
            raise InputError(f"{tag}the ball shows no usable direction (all its pixels invalid or masked)",
                             view.images[0].path)
        notes.append(f"{tag}{vr.note}; {geo.describe()}; saw {100 * frac:.1f}% of the sphere; camera cone "
                     + (f"{cone:.1f} deg masked ({why})" if cone > 0 else "kept"))
        per_view.append({"sphere_source": geo.source, "center_px": geo.center_px.tolist(),
                         "radius_px": geo.radius_px, "seen_fraction": frac, "camera_cone_deg": cone,
                         "center_uncertainty_px": geo.center_uncertainty_px,
                         "enclosed_by": None if geo.enclosed_by is None else
                         {"center_px": [float(x) for x in geo.enclosed_by[0]], "radius_px": geo.enclosed_by[1],
                          "coverage": geo.enclosed_by[2]}})
        views.append(mv)
    merged = merge_mirror_views(views, power=weight_power)
    seen = merged.confidence > 0
    data = fill_unseen(merged.radiance, seen) if fill == "nearest" else merged.radiance
    if height >= BLIND_SPOT_HEIGHT:
        bs, cone_sr = blind_spot(seen), float(sa[merged.camera_cone].sum())
    else:  # a coarse texel holds the blind spot whole and counts as seen through its other directions
        fine = merge_mirror_views([unwrap(v, r, g, c, BLIND_SPOT_HEIGHT) for _, v, r, g, c, _ in located],
                                  power=weight_power)
        bs = blind_spot(fine.confidence > 0)
        cone_sr = float(latlong_solid_angles(BLIND_SPOT_HEIGHT)[fine.camera_cone].sum())
        # the alpha: a texel is seen where most of it was (its share of the fine texels seen)
        share = cv2.resize((fine.confidence > 0).astype(np.float32), (2 * int(height), int(height)),
                           interpolation=cv2.INTER_AREA)
        seen = share >= 0.5
    clipped = float(sa[merged.clipped].sum() / (4 * np.pi))
    notes.append(bs.describe() + (f" (the camera cone's {cone_sr:.3f} sr included)" if cone_sr > 0 else "") +
                 ("; filled from the nearest seen directions" if fill == "nearest" and bs.solid_angle > 0 else ""))
    if clipped > 0:
        notes.append(f"{100 * clipped:.2f}% of the sphere seen only through clipped pixels (lower bounds): "
                     f"use a bracket")
    lm = LightMap(data, "latlong", str(probe.folder))
    details = {"views": per_view, "seen_fraction": float(1 - bs.fraction), "blind_spot_sr": bs.solid_angle,
               "blind_spot_fraction": bs.fraction, "camera_cone_sr": cone_sr, "clipped_fraction": clipped}
    return LightmapEstimate(lm, seen, merged.confidence, "mirror", notes, details)


# ----------------------------------------------------------------------------- diffuse objects (Hougen-Ahuja, POCS)
def _with_source(e: InputError, src) -> InputError:
    """An InputError of an array function (no path) re-raised naming ``probe.json``."""
    return InputError(e.message, src) if e.path is None else e


def diffuse_pixels(probe, method: str, rim_px: float = 0.5, max_pixels: int | None = 20000, seed: int = 0):
    """The usable pixels of a diffuse sphere over every view: world normals, radiance, albedo, notes.

    Pixels within ``rim_px`` of the outline, invalid or clipped are left out; at most
    ``max_pixels`` (a fixed-seed random subset) are returned. With a mesh ``object`` in
    ``probe.json`` the pixels and normals are the object's (:func:`object_pixels`).

    Returns
    -------
    normals : (m, 3) float64
    radiance : (m, 3) float64
    albedo : float
        ``sphere.albedo``, or 1 when not stated (then the map carries the unknown albedo as a scale).
    notes : list of str
    """
    src = probe.json_path
    if probe.object is not None:
        return object_pixels(probe, max_pixels, seed)
    normals, values, notes = [], [], []
    needs = f"the {method} method needs a diffuse sphere (\"material\": \"diffuse\")"
    for tag, view, vr, geo in _located_views(probe, "diffuse", needs, "mirror"):
        mask = geo.mask(vr.radiance.shape, margin_px=rim_px) & vr.valid & ~vr.saturated
        yy, xx = np.nonzero(mask)
        n = geo.normals_world(np.stack([xx, yy], axis=1).astype(np.float64)) if len(yy) else np.zeros((0, 3))
        ok = np.all(np.isfinite(n), axis=1)
        normals.append(n[ok])
        values.append(vr.radiance[yy[ok], xx[ok]].astype(np.float64))
        notes.append(f"{tag}{vr.note}; {geo.describe()}; {int(ok.sum())} usable pixels")
    N, V = np.concatenate(normals), np.concatenate(values)
    if len(N) == 0:
        raise InputError("the sphere shows no usable pixel (all clipped, invalid or at the rim)", src)
    if max_pixels is not None and len(N) > max_pixels:
        keep = np.sort(np.random.default_rng(seed).choice(len(N), int(max_pixels), replace=False))
        N, V = N[keep], V[keep]
        notes.append(f"used {max_pixels} of the pixels (a fixed-seed random subset)")
    albedo = probe.view.sphere.albedo
    if albedo is None:
        notes.append("sphere.albedo not stated: the map is scaled by the unknown albedo (taken as 1)")
        albedo = 1.0
    return N, V, float(albedo), notes


def _closest_hits(origins, dirs, tri):
    """Closest hit of rays with triangles (Moeller-Trumbore).

    Returns face index (m,) int (-1 for a miss), distance (m,) and barycentric (u, v) (m, 2).
    """
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    m = len(dirs)
    face = np.full(m, -1, dtype=np.int64)
    best = np.full(m, np.inf)
    bary = np.zeros((m, 2))
    rows = max(1, 2_000_000 // max(1, len(tri)))
    for s in range(0, m, rows):
        inside, u, v, t = ray_triangle(origins[s:s + rows, None, :], dirs[s:s + rows, None, :], v0[None], e1[None],
                                       e2[None], 1e-14)
        t = np.where(inside & (t > 1e-12), t, np.inf)
        k = np.argmin(t, axis=1)
        tk = t[np.arange(len(k)), k]
        hit = np.isfinite(tk)
        face[s:s + rows] = np.where(hit, k, -1)
        best[s:s + rows] = tk
        r = np.arange(len(k))
        bary[s:s + rows] = np.stack([u[r, k], v[r, k]], axis=1)
    return face, best, bary


def object_pixels(probe, max_pixels: int | None = 20000, seed: int = 0):
    """The usable pixels of a diffuse mesh ``object`` (known geometry and pose) seen by a pinhole camera.

    Each pixel's ray is met with the mesh (closest hit, Moeller-Trumbore on every triangle; the
    pixels are subsampled first, to ``max_pixels`` of those inside the mesh's projected bounds);
    the normal is interpolated from the vertex normals (area-weighted, ``trimesh``) where the
    face is smooth (its vertex normals within 30 degrees of its face normal), else the face
    normal (a crease), and turned toward the camera. Cast self-shadows are not modelled (a
    convex object has none). Returns what :func:`diffuse_pixels` returns.
    """
    from ffls.camera.projection import pixel_rays, project_points

    src = probe.json_path
    mesh = probe.object
    normals, values, notes = [], [], []
    tri = mesh.vertices[mesh.faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    import trimesh

    vn = np.asarray(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).vertex_normals, dtype=np.float64)
    fvn = vn[mesh.faces]  # (F, 3, 3)
    smooth = np.all(np.abs(np.sum(fvn * fn[:, None, :], axis=2)) >= np.cos(np.radians(30.0)), axis=1)
    fvn = fvn * np.sign(np.sum(fvn * fn[:, None, :], axis=2))[..., None]  # on the face normal's side
    rng = np.random.default_rng(seed)
    for k, view in enumerate(probe.views):
        cam = view.camera
        if cam.model != "pinhole" or cam.K is None:
            raise InputError("camera: a mesh object needs a calibrated pinhole camera (camera.K and "
                             "camera.world_from_camera) to find which pixels see which face", src)
        vr = view_radiance(view, probe.encoding, probe.response, src)
        H, W = vr.radiance.shape[:2]
        T = cam.world_from_camera
        Ti = np.linalg.inv(T)
        vc = mesh.vertices @ Ti[:3, :3].T + Ti[:3, 3]
        front = vc[:, 2] > 0
        if not front.any():
            raise InputError("object: the mesh is behind the camera (check world_from_object and the camera pose)",
                             src)
        uv = project_points(vc[front], cam.K, cam.dist)
        x0, y0 = np.clip(np.floor(uv.min(axis=0)).astype(int), 0, [W - 1, H - 1])
        x1, y1 = np.clip(np.ceil(uv.max(axis=0)).astype(int) + 1, 1, [W, H])
        yy, xx = np.mgrid[y0:y1, x0:x1]
        yy, xx = yy.ravel(), xx.ravel()
        ok = vr.valid[yy, xx] & ~vr.saturated[yy, xx]
        yy, xx = yy[ok], xx[ok]
        cap = None if max_pixels is None else int(max_pixels) // len(probe.views)
        if cap is not None and len(yy) > cap:
            keep = np.sort(rng.choice(len(yy), cap, replace=False))
            yy, xx = yy[keep], xx[keep]
        d = pixel_rays(np.stack([xx, yy], axis=1).astype(np.float64), cam.K, cam.dist) @ T[:3, :3].T
        face, _, bary = _closest_hits(np.broadcast_to(T[:3, 3], d.shape), d, tri)
        hit = face >= 0
        fh, (bu, bv) = face[hit], bary[hit].T
        interp = normalize((1 - bu - bv)[:, None] * fvn[fh, 0] + bu[:, None] * fvn[fh, 1] + bv[:, None] * fvn[fh, 2])
        n = np.where(smooth[fh][:, None], interp, fn[fh])
        n = np.where((np.sum(n * d[hit], axis=1) > 0)[:, None], -n, n)
        normals.append(n)
        values.append(vr.radiance[yy[hit], xx[hit]].astype(np.float64))
        tag = "" if len(probe.views) == 1 else f"view {k + 1}: "
        notes.append(f"{tag}{vr.note}; {int(hit.sum())} pixels on the mesh {mesh.path.name} ({len(tri)} triangles)")
    N, V = np.concatenate(normals), np.concatenate(values)
    if len(N) == 0:
        raise InputError("object: no pixel sees the mesh (check world_from_object and the camera pose)", src)
    albedo = probe.object_albedo
    if albedo is None:
        notes.append("object.albedo not stated: the map is scaled by the unknown albedo (taken as 1)")
        albedo = 1.0
    return N, V, float(albedo), notes


def _finish(radiance, confidence, threshold: float, method: str, probe, notes: list, details: dict, fill: str
            ) -> LightmapEstimate:
    """Clip negatives (counted), mask, fill and wrap a recovered lat-long map."""
    from ffls.probes.sources import to_lightmap

    conf = np.clip(np.asarray(confidence, dtype=np.float64), 0.0, 1.0)
    seen = conf > threshold
    lm, clipped = to_lightmap(np.asarray(radiance, dtype=np.float64), str(probe.folder))
    data = lm.data
    if fill == "zero":
        data = np.where(seen[..., None], data, 0.0).astype(np.float32)
    if clipped:
        notes.append(f"{clipped} texels with negative radiance (unconstrained least squares) set to 0")
    bs = blind_spot(seen)
    notes.append(bs.describe().replace("blind spot", "poorly seen") + ("" if bs.direction is None else (
        f" (confidence <= {threshold:g}; the map there is the method's extrapolation)")))
    details.update(seen_fraction=float(1 - bs.fraction), blind_spot_sr=bs.solid_angle,
                   blind_spot_fraction=bs.fraction, negative_texels=int(clipped))
    return LightmapEstimate(LightMap(data, "latlong", str(probe.folder)), seen, conf.astype(np.float32), method,
                            notes, details)


#: ``diffuse_lightmap(smoothness='cv')``'s candidate weights: ``select_regularization``'s default, 0 (the
#: plain fit) and steps of about 3 up to 0.03, the range ``docs/probes.md`` measures.
SMOOTHNESS_WEIGHTS = (0.0, 0.001, 0.003, 0.01, 0.03)
#: ``diffuse_lightmap(smoothness='cv', prior='power')``'s candidate weights: the least-total-power penalty
#: charges every source's power, not only differences, so its useful weights are about ten times smaller
#: (``docs/probes.md``, *Least total power*: 0.01 already raises the held-out error tenfold).
POWER_WEIGHTS = (0.0, 0.0001, 0.0003, 0.001, 0.003)
#: ``diffuse_lightmap``'s ``prior``: what its ``smoothness`` weight penalises.
PRIORS = ("quadratic", "tv", "power")
#: ``diffuse_lightmap``'s ``rule``: how cross-validation chooses the adaptive set's round and the weight.
DIFFUSE_RULES = ("paired_se", "one_se")


def diffuse_lightmap(probe, height: int = 128, sources="auto", nonnegative: bool = True, ambient="auto",
                     criterion: str = "cv", smoothness: float | str | None = None, rcond: float | None = None,
                     orientations: int = 1, ground: bool = False, prior: str | None = None, rule: str = "paired_se",
                     azimuths: int = 1,
                     rim_px: float = 0.5,
                     max_pixels: int | None = 5000, confidence_threshold: float = 0.2,
                     fill: str = "nearest") -> LightmapEstimate:
    """A light map from a diffuse sphere (Hougen and Ahuja 1993, :mod:`ffls.probes.hougen_ahuja`).

    Parameters
    ----------
    probe : ffls.io.probe.Probe
    height : int
    sources : int, 'auto', 'adaptive' or 'uniform'
        Model sources (5, 9, 17 rings, or geodesic sets of about that size). ``'auto'``
        (default) or ``'adaptive'``: an adaptive geodesic set, refined where the recovered light is and stopped by
        ``criterion`` (:func:`ffls.probes.selection.adaptive_hougen_ahuja`; ``docs/probes.md``
        measures why it is the default). ``'uniform'``: chosen by ``criterion`` among the uniform
        sets 5, 9, 17, 42, 92, 162, 252 (:func:`ffls.probes.selection.select_hougen_ahuja`).
    nonnegative : bool
        Non-negative source intensities (scipy ``nnls``; default). False is the paper's plain
        least squares, whose negative lobes a saved map clips (counted in the notes).
    ambient : {'auto', 'nonnegative', True, False}
        The ambient term. ``'auto'`` (default): none with sources over the whole sphere (geodesic
        and adaptive sets, which hold any uniform light themselves), non-negative with the ring
        sets 5, 9, 17 (:func:`ffls.probes.hougen_ahuja.resolve_ambient`); ``'nonnegative'``
        (with ``nonnegative``), free (``True``, the paper's; it may come out negative), or none.
        ``docs/probes.md`` (*The ambient term*) measures why.
    criterion : {'cv', 'bic'}
    smoothness : float, 'cv' or None
        First-difference penalty between neighbouring sources (0: the paper). ``'cv'``: the
        source set is chosen without it, then its weight among ``SMOOTHNESS_WEIGHTS`` by blocked
        cross-validation on that set (:func:`ffls.probes.selection.select_regularization`, by
        ``rule``); ``docs/probes.md`` (*The ambient term*, *Choosing with paired folds*) measures it.
        None (default): ``'cv'``, or 0 with ``orientations > 1`` (whose members have no one set).
    rule : {'paired_se', 'one_se'}
        How cross-validation chooses. ``'paired_se'`` (default): the adaptive set's round (with
        ``criterion='cv'``) and the ``'cv'`` weight are the smallest round and the largest weight whose
        held-out excess over the best is within one standard error of that excess, from the paired
        differences of the folds (:func:`ffls.probes.selection.refine_sources`,
        :func:`ffls.probes.selection.choose_weight`); ``'one_se'``: the round within 5% of the best held-out
        error and the largest weight within one standard error of the best fold spread (the rules before;
        ``docs/probes.md``, *Choosing with paired folds*, measures why they were replaced).
    prior : {'quadratic', 'tv', 'power'} or None
        What ``smoothness`` weighs. None (default): ``'power'`` with ``smoothness='cv'`` (since the fifteenth
        stop: it halves the misses of 7% over orientations, ``docs/probes.md``, *Least total power*), else
        ``'quadratic'`` (a stated weight keeps its meaning). ``'quadratic'``: the squared first differences between
        neighbouring sources; ``'tv'``, total variation, their absolute values (edge-preserving: a small
        bright lamp keeps its peak; :func:`ffls.probes.linear.solve_sources`' ``tv``;
        ``docs/probes.md``, *An edge-preserving prior*); ``'power'``, the light's total power (the sum of
        the sources' powers, the same whatever the set's orientation; of the maps the ball cannot tell apart
        the least powerful, the most concentrated; the ``'cv'`` weight among ``POWER_WEIGHTS``;
        :func:`ffls.probes.linear.solve_sources`' ``power``; ``docs/probes.md``, *Least total power*).
    rcond : float, optional
        Unconstrained only: truncate singular values below ``rcond`` times the largest (large
        source sets are rank deficient on a Lambertian sphere).
    orientations : int
        Adaptive sources only: average the estimate over this many orientations of the geodesic
        hierarchy (:func:`ffls.probes.selection.adaptive_hougen_ahuja`; 1, the default, is one
        estimate; ``docs/probes.md``, *The orientation of the source set*, measures the trade).
    azimuths : int
        Adaptive sources: the estimate (its set, and its ``'cv'`` weight) made with the geodesic hierarchy's
        vertex on the world's up (``probe.plane``'s normal; without a plane, +Z), in this many azimuths about
        it, evenly over the hierarchy's period (:func:`ffls.probes.selection.horizon_rotations`), and the fits
        averaged. Every member has the same sources' elevations about the horizon; only their azimuths
        change. 1 (default): one estimate, in the hierarchy's own orientation. It costs as many estimates,
        and it is not the default: the azimuth is as much a lottery as the orientation, and the mean of 4
        still misses 7% on studio in turned orientations (``docs/probes.md``, *The horizon fixed, the
        azimuth averaged*).
    ground : bool
        Sources only above a ground plane (``probe.plane``'s normal; without a plane, the world's
        +Z, GUIDE section 1), the light from below it one uniform term
        (:func:`ffls.probes.hougen_ahuja.hougen_ahuja`'s ``ground``; ``docs/probes.md``, *A ground
        plane*, measures it). False (default): sources over the whole sphere.
    rim_px, max_pixels
        See :func:`diffuse_pixels`.
    confidence_threshold : float
        Directions with :func:`ffls.probes.hougen_ahuja.normal_confidence` at or below it are
        reported as not seen (alpha 0).
    fill : {'nearest', 'zero'}
        ``'nearest'`` keeps the method's own values everywhere (the sources extend over the
        whole domain); ``'zero'`` blacks out the directions not seen.
    """
    from ffls.probes.hougen_ahuja import average_fits, hougen_ahuja, normal_confidence, resolve_ambient
    from ffls.probes.selection import (HIERARCHY_PERIOD_DEG, adaptive_hougen_ahuja, horizon_rotations, oriented_fits,
                                       select_hougen_ahuja, select_regularization)

    src = probe.json_path
    N, V, albedo, notes = diffuse_pixels(probe, "diffuse", rim_px, max_pixels)
    if int(orientations) != orientations or orientations < 1:
        raise ValueError(f"orientations must be an integer >= 1, not {orientations!r}")
    if smoothness is None:
        smoothness = "cv" if orientations == 1 else 0.0
    by_cv = isinstance(smoothness, str)
    if by_cv and smoothness != "cv":
        raise ValueError(f"smoothness must be a number >= 0 or 'cv', not {smoothness!r}")
    if rule not in DIFFUSE_RULES:
        raise ValueError(f"rule must be one of {DIFFUSE_RULES}, not {rule!r}")
    if orientations > 1 and (sources not in ("auto", "adaptive") or by_cv):
        raise ValueError("orientations > 1 applies to adaptive sources without smoothness='cv'")
    if prior is None:
        prior = "power" if by_cv else "quadratic"
    if prior not in PRIORS:
        raise ValueError(f"prior must be one of {PRIORS}, not {prior!r}")
    if prior != "quadratic" and not by_cv and smoothness == 0:
        raise ValueError(f"prior {prior!r} weighs smoothness: give it a weight or 'cv' (it is 0)")
    penalty = {"quadratic": "smoothness"}.get(prior, prior)
    weights_cv = POWER_WEIGHTS if prior == "power" else SMOOTHNESS_WEIGHTS
    kw = {"nonnegative": nonnegative, "ambient": ambient, penalty: 0.0 if by_cv else smoothness, "rcond": rcond}
    rounds_by_rule = sources in ("auto", "adaptive") and criterion == "cv"  # the adaptive set's round by ``rule``
    up = None
    plane_up = np.asarray(probe.plane.normal if probe.plane is not None else (0.0, 0.0, 1.0), dtype=np.float64)
    if ground:
        up = plane_up
        kw["ground"] = up
        notes.append(f"ground plane: sources above the plane of normal ({up[0]:+.2f}, {up[1]:+.2f}, {up[2]:+.2f})"
                     f"{'' if probe.plane is not None else ' (no plane in probe.json: the world +Z)'}, the light "
                     f"below it uniform")
    if int(azimuths) != azimuths or azimuths < 1:
        raise ValueError(f"azimuths must be an integer >= 1, not {azimuths!r}")
    if azimuths > 1 and (sources not in ("auto", "adaptive") or orientations > 1 or ground):
        raise ValueError("azimuths > 1 applies to adaptive sources, without orientations > 1 or a ground plane")

    def one(normals):  # the estimate in one orientation of the source hierarchy: (fit, (selection, weight's))
        sel = reg = None
        if sources in ("auto", "adaptive", "uniform"):
            select = select_hougen_ahuja if sources == "uniform" else adaptive_hougen_ahuja
            extra = {"orientations": int(orientations)} if orientations > 1 else {}
            if rounds_by_rule:
                extra["rule"] = "paired_se" if rule == "paired_se" else "tolerance"
            sel = select(normals, V, albedo, criterion=criterion, **kw, **extra)
            fit = sel.fit
        else:
            fit = hougen_ahuja(normals, V, albedo, sources=int(sources), **kw)
        if by_cv:
            # the set's own domain and ambient (the rings keep theirs: explicit directions default to the sphere)
            amb_set = False if up is not None and ambient == "auto" else resolve_ambient(ambient, nonnegative,
                                                                                          fit.hemisphere)
            reg = select_regularization(normals, V, albedo, fit.directions, weights_cv, penalty, rule=rule,
                                        nonnegative=nonnegative, rcond=rcond, hemisphere=fit.hemisphere,
                                        ambient=amb_set, **({} if up is None else {"ground": up}))
            fit = reg.fit
        return fit, (sel, reg)

    try:
        if azimuths > 1:
            fits, parts = oriented_fits(N, horizon_rotations(plane_up, azimuths), one)
            fit = average_fits(fits, V)
            chosen = tuple(int(sel.chosen) for sel, _ in parts)
            weights = [float(reg.chosen) for _, reg in parts] if by_cv else []
            u = plane_up
            notes.append(f"the source hierarchy with a vertex on the world's up ({u[0]:+.2f}, {u[1]:+.2f}, {u[2]:+.2f}"
                         f"{'' if probe.plane is not None else ': no plane in probe.json, +Z'}) "
                         f"in {azimuths} azimuths {HIERARCHY_PERIOD_DEG / azimuths:g} degrees apart, the same "
                         f"elevations in each, the fits averaged"
                         + (f" (smoothness weights by cross-validation {'/'.join(f'{w:g}' for w in weights)})"
                            if by_cv else ""))
            notes.extend(f"the first azimuth's {x.note}" for x in parts[0] if x is not None)
        else:
            fit, (sel, reg) = one(N)
            if sel is not None:
                chosen = sel.chosen
                notes.append(sel.note)
            else:
                chosen = int(fit.directions.shape[0])  # a geodesic set has the size nearest the one asked
                if chosen != int(sources):
                    notes.append(f"--sources {int(sources)}: no model set has that size; the nearest geodesic "
                                 f"set has {chosen}")
            if by_cv:
                notes.append(reg.note)
    except InputError as e:
        raise _with_source(e, src) from None
    amb = {False: "no ambient", "nonnegative": "non-negative ambient", True: "free ambient", "free": "free ambient"}[
        False if up is not None and ambient == "auto" else resolve_ambient(ambient, nonnegative, fit.hemisphere)]
    count = (f"{chosen} sources" if orientations == 1 and azimuths == 1 else
             f"the mean of {len(chosen)} fits ({', '.join(map(str, chosen))} sources)")
    notes.append(f"Hougen-Ahuja: {count}{' (non-negative)' if nonnegative else ''}, {amb}, re-rendered "
                 f"relative RMS {100 * fit.relative_rms:.2f}%, condition {fit.condition:.3g}")
    details = {"sources": chosen if orientations == 1 and azimuths == 1 else list(chosen),
               "relative_rms": float(fit.relative_rms), "condition": float(fit.condition)}
    if orientations > 1:
        details["orientations"] = int(orientations)
    if azimuths > 1:
        details["azimuths"] = int(azimuths)
    if up is not None:
        details["ground"] = [float(g) for g in fit.ground]
    if by_cv:
        details["smoothness"] = weights if azimuths > 1 else float(reg.chosen)
    if by_cv or rounds_by_rule:
        details["rule"] = rule
    if prior != "quadratic":
        details["prior"] = prior
    return _finish(fit.latlong(height), normal_confidence(N, height), confidence_threshold, "diffuse", probe, notes,
                   details, fill)


#: How ``pocs_lightmap`` builds its unknowns: an adaptive geodesic source set (``'auto'`` = ``'adaptive'``)
#: or the paper's fixed lat-long grid (``'grid'``).
POCS_SOURCES = ("auto", "adaptive", "grid")


#: ``pocs_lightmap``'s default scheme per kind of unknowns (``sources``): on adaptive sources the least total power
#: within the L1 residual the data allow, refitted and averaged over pixel subsets (it meets the 9% goal on every map,
#: noise level and orientation of ``benchmarks/probes_pocs_noise.py``, where the paper's sweeps relight studio 17-19%
#: wrong: ``docs/probes.md``, "Noise: refitted least-power maps averaged over pixel subsets"); on the paper's grid
#: Singh and Ahuja's own sweeps (``'sequential'``; least power there relit a studio ball worse, ``docs/probes.md``).
POCS_DEFAULT_SCHEME = {"auto": "least-power", "adaptive": "least-power", "grid": "sequential"}

#: ``pocs_lightmap``'s sweep count when none is given, per scheme: the paper's 50 sweeps; the extrapolated
#: scheme's iterations cost two J x J products each (not m row projections), and its relit error on
#: ``benchmarks/probes.py`` still falls between 1000 and 3000 (``docs/probes.md``, "POCS"); Dykstra's cycles
#: (two exact projections each) are capped as the extrapolated scheme's. The least-power scheme solves one linear
#: programme; its adaptive set is grown and chosen by the paper's 50 sweeps.
POCS_ITERATIONS = {"sequential": 50, "extrapolated": 3000, "dykstra": 3000, "least-power": 50}


def pocs_lightmap(probe, height: int = 128, grid: int = 16, iterations: int | None = None,
                  upper: float | None = None, delta: float = 0.0, order: str = "random", seed: int = 0,
                  rim_px: float = 0.5, max_pixels: int | None = 2000, confidence_threshold: float = 0.2,
                  fill: str = "nearest", sources: str = "auto", criterion: str = "cv",
                  scheme: str | None = None, relaxation: float = 1.0,
                  tol: float | None = None, before_solve=None) -> LightmapEstimate:
    """A light map from a diffuse sphere by POCS (Singh and Ahuja, :mod:`ffls.probes.singh_ahuja`).

    Parameters
    ----------
    probe : ffls.io.probe.Probe
    height : int
        Map height.
    grid : int
        ``sources='grid'``: the height of the lat-long grid of unknowns; ``height`` must be a
        multiple of it (texels are repeated, the energy kept).
    iterations, upper, delta, order, seed, max_pixels, scheme, relaxation, tol
        :func:`ffls.probes.singh_ahuja.singh_ahuja`'s (``delta`` applies to the grid only; ``iterations``
        ``None``: :data:`POCS_ITERATIONS` of the scheme; with ``tol`` it is the cap).
    rim_px : float
        See :func:`diffuse_pixels`.
    confidence_threshold : float
        Directions with :func:`ffls.probes.hougen_ahuja.normal_confidence` at or below it are
        reported as not seen (alpha 0).
    fill : {'nearest', 'zero'}
    sources : {'auto', 'adaptive', 'grid'}
        ``'adaptive'`` (``'auto'``, the default): POCS over a geodesic source set refined where the
        recovered light is, the round chosen by ``criterion``
        (:func:`ffls.probes.singh_ahuja.adaptive_singh_ahuja`); ``'grid'``: the paper's
        ``grid x 2 grid`` lat-long grid. ``docs/probes.md`` measures why adaptive is the default.
    criterion : {'cv', 'bic'}
        How the adaptive round is chosen.
    scheme : {None, 'least-power', 'sequential', 'extrapolated', 'dykstra'}
        ``'least-power'``: the map of least total power within the L1 residual the data allow
        (:func:`ffls.probes.singh_ahuja.least_power_pocs`; on adaptive sources the set is grown by the paper's
        sweeps and its powers are :func:`ffls.probes.singh_ahuja.averaged_least_power`'s); ``'sequential'``:
        Singh and Ahuja's own method, sweeps of row projections in random order; the others as
        :func:`ffls.probes.singh_ahuja.pocs`. ``None``: :data:`POCS_DEFAULT_SCHEME` of ``sources`` (least-power
        on adaptive sources, the paper's sweeps on its grid). ``details['scheme']`` and the saved map's header
        say which ran.
    before_solve : callable, optional
        Called once the probe's pixels are read and the knobs checked, before the solve (a caller's
        time estimate: ``ffls probe pocs``), with the keywords ``scheme``, ``sources`` (``'grid'`` or
        ``'adaptive'``), ``grid``, ``iterations`` (the sweeps that will run, or cap) and ``pixels``
        (those each fit uses).
    """
    from ffls.probes.hougen_ahuja import normal_confidence
    from ffls.probes.singh_ahuja import adaptive_singh_ahuja, singh_ahuja

    src = probe.json_path
    if sources not in POCS_SOURCES:
        raise ValueError(f"sources must be one of {POCS_SOURCES}, not {sources!r}")
    if sources == "grid" and int(height) % int(grid):
        raise InputError(f"--size {height} must be a multiple of the POCS grid height --grid {grid}")
    if scheme is None:
        scheme = POCS_DEFAULT_SCHEME[sources]
    if scheme not in POCS_ITERATIONS:
        raise ValueError(f"scheme must be one of {tuple(POCS_ITERATIONS)}, not {scheme!r}")
    if scheme == "least-power":
        # one linear programme: a flag of the iterations would be ignored, so it is refused
        for flag, value, unset in (("--relaxation", relaxation, 1.0), ("--tol", tol, None),
                                   ("--iterations", None if sources != "grid" else iterations, None)):
            if value != unset:
                raise InputError(f"{flag} does not apply with --scheme least-power" + (
                    " --sources grid" if flag == "--iterations" else "") + " (one linear programme, solved exactly; "
                    "--scheme sequential runs the paper's sweeps)")
    if iterations is None:
        iterations = POCS_ITERATIONS[scheme]
    if scheme == "extrapolated" and not 0.0 < float(relaxation) <= 1.0:
        raise InputError(f"--relaxation {relaxation:g} must be in (0, 1] with --scheme extrapolated")
    if scheme == "extrapolated" and float(delta) != 0.0:
        raise InputError("--scheme extrapolated projects onto the residual hyperplanes: delta must be 0")
    if scheme == "dykstra" and float(relaxation) != 1.0:
        raise InputError(f"--relaxation {relaxation:g} does not apply with --scheme dykstra (exact projections)")
    solver = dict(scheme=scheme, relaxation=relaxation, tol=tol)
    N, V, albedo, notes = diffuse_pixels(probe, "pocs", rim_px, None)
    if before_solve is not None:
        before_solve(scheme=scheme, sources="grid" if sources == "grid" else "adaptive", grid=int(grid),
                     iterations=int(iterations), pixels=len(N) if max_pixels is None else min(len(N), int(max_pixels)))
    try:
        if sources == "grid":
            res = singh_ahuja(N, V, albedo, height=grid, iterations=iterations, upper=upper, delta=delta,
                              order=order, seed=seed, max_pixels=max_pixels, **solver)
            model, data = f"{grid}x{2 * grid} grid", res.latlong(height)
        else:
            sel = adaptive_singh_ahuja(N, V, albedo, iterations=iterations, upper=upper, order=order, seed=seed,
                                       max_pixels=max_pixels, criterion=criterion, **solver)
            res = sel.fit
            notes.append(sel.note)
            model, data = f"{sel.chosen} adaptive sources", res.latlong(height)
    except InputError as e:
        raise _with_source(e, src) from None
    r = res.residuals
    if not r[-1] < r[0] * (1.0 - 1e-6) or not np.any(np.asarray(data) > 0):  # a black map: no output to write
        raise InputError(f"POCS made no progress: residual {100 * r[0]:.2f}% -> {100 * r[-1]:.2f}% after "
                         f"{res.iterations} iterations" + (f"; --relaxation {relaxation:g} is too small to move the "
                                                           "estimate" if relaxation < 1.0 else ""), src)
    how = {"sequential": f"{order} order", "extrapolated": "parallel, extrapolated",
           "dykstra": "Dykstra, the least-norm feasible map",
           "least-power": "the least total power within the L1 residual the data allow" + (
               "" if sources == "grid" else f", its lit sources refitted; the set grown by {iterations} {order}-order "
                                            "sweeps")}[scheme] + (
        f", relaxation {relaxation:g}" if relaxation != 1.0 else "") + (
        f", stopped at a change below {tol:g}" if tol is not None and res.iterations < iterations else "")
    runs = "one linear programme per channel" if scheme == "least-power" else f"{res.iterations} iterations"
    if scheme == "least-power" and sources != "grid" and max_pixels is not None and res.pixels_used > max_pixels:
        runs += f" and disjoint subset of about {max_pixels} pixels, averaged"   # averaged_least_power
    named = "the paper's projections" if scheme == "sequential" else "not the paper's"
    notes.append(f"POCS (Singh-Ahuja), --scheme {scheme} ({named}): {model}, {runs} ({how}) over "
                 f"{res.pixels_used} pixels; residual {100 * r[0]:.2f}% -> {100 * r[-1]:.2f}% (relative), "
                 f"re-rendered relative RMS {100 * res.relative_rms:.2f}%")
    details = {"iterations": int(res.iterations), "scheme": scheme, "residuals": [float(x) for x in r],
               "relative_rms": float(res.relative_rms)}
    if sources == "grid":
        details["grid"] = int(grid)
    else:
        details.update({"sources": int(sel.chosen), "criterion": criterion,
                        "rounds": [int(c) for c in sel.candidates],
                        "round_scores": [float(x) for x in sel.scores]})
    return _finish(data, normal_confidence(N, height), confidence_threshold, "pocs", probe, notes, details, fill)


# ----------------------------------------------------------------------------- cast shadows (Sato, Sato and Ikeuchi)
def _segments_blocked(points, ends, occ) -> np.ndarray:
    """(m,) bool: the segment from each point to its end (the camera) meets the occluder (box or mesh)."""
    p = np.asarray(points, dtype=np.float64)
    d = np.asarray(ends, dtype=np.float64) - p
    if occ.kind == "box":
        lo, hi = occ.center - occ.size / 2, occ.center + occ.size / 2
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # slabs at +-inf compare right
            inv = 1.0 / d
            t0, t1 = (lo - p) * inv, (hi - p) * inv
        tmin = np.nanmax(np.minimum(t0, t1), axis=1)
        tmax = np.nanmin(np.maximum(t0, t1), axis=1)
        return (tmax >= np.maximum(tmin, 1e-9)) & (tmin <= 1.0)
    tri = occ.mesh.vertices[occ.mesh.faces]
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    out = np.zeros(len(p), dtype=bool)
    rows = max(1, 2_000_000 // max(1, len(tri)))
    for s in range(0, len(p), rows):  # Moeller-Trumbore, every segment against every triangle
        inside, _, _, t = ray_triangle(p[s:s + rows, None, :], d[s:s + rows, None, :], v0[None], e1[None], e2[None],
                                       1e-12)
        hit = inside & (t > 1e-9) & (t < 1.0)
        out[s:s + rows] = hit.any(axis=1)
    return out


def pixel_grid_subset(pixel_xy, max_pixels: int | None) -> tuple[np.ndarray, int]:
    """A regular grid of pixels, every ``s``-th column and row, about ``max_pixels`` of them.

    A cast shadow is told apart from its neighbouring nodes' shadows by its edges: a regular
    grid samples every edge at the same spacing, while a random subset leaves gaps of random
    size along them (``docs/probes.md`` measures the difference), and the spacing that
    :func:`ffls.probes.sato_sato_ikeuchi.shadow_in_view` infers stays that of the grid.

    Parameters
    ----------
    pixel_xy : (m, 2) array_like of int
        Column and row of every candidate pixel.
    max_pixels : int or None
        The budget; the stride is the integer nearest ``sqrt(m / max_pixels)`` (at least 1), so
        the subset holds between about 0.56 and 2.25 times ``max_pixels``. None keeps all.

    Returns
    -------
    keep : (m',) int64
        Indices into ``pixel_xy``, in their order.
    stride : int
    """
    xy = np.asarray(pixel_xy, dtype=np.int64).reshape(-1, 2)
    if max_pixels is not None and int(max_pixels) < 1:
        raise ValueError(f"max_pixels must be >= 1 or None, not {max_pixels!r}")
    if max_pixels is None or xy.shape[0] <= int(max_pixels):
        return np.arange(xy.shape[0]), 1
    s = max(1, int(round(float(np.sqrt(xy.shape[0] / int(max_pixels))))))
    return np.flatnonzero((xy[:, 0] % s == 0) & (xy[:, 1] % s == 0)), s


def shadow_pixels(probe, max_pixels: int | None = 4000, need_surface: bool = False):
    """The receiver pixels of a cast-shadow probe: world points on the plane, radiance, view directions.

    Needs a calibrated camera to map the pixels onto the plane: a pinhole camera (``K`` and
    ``world_from_camera``) or an orthographic one with ``pixel_size``; and ``plane`` and
    ``occluder``. Pixels whose ray does not meet the plane in front of the
    camera, or that see the occluder, or that are clipped or invalid, are left out. More than
    ``max_pixels`` are thinned to a regular grid (:func:`pixel_grid_subset`).

    Returns
    -------
    points, radiance, view_dirs : (m, 3) float64
    surface : (m, 3) float64 or None
        The same pixels of ``surface_image`` (when ``need_surface``).
    notes : list of str
    """
    from ffls.camera.projection import pixel_rays
    from ffls.io.images import read_image
    from ffls.probes.bracket import check_encoding, decode_image

    src = probe.json_path
    if probe.plane is None:
        raise InputError("plane: missing (the shadow method needs the receiving plane: point, normal, albedo)", src)
    if probe.occluder is None:
        raise InputError("occluder: missing (the shadow method needs the occluder: a box or a mesh)", src)
    view = probe.view
    cam = view.camera
    if cam.model == "orthographic" and cam.pixel_size is None:
        raise InputError("camera.pixel_size: missing (an orthographic camera needs its scale, scene units per pixel, "
                         "to put the pixels on the plane)", src)
    if cam.model == "pinhole" and cam.K is None:
        raise InputError("camera.K: missing (the shadow method maps pixels onto the plane and needs a calibrated "
                         "camera: K and world_from_camera, or an orthographic camera with pixel_size)", src)
    vr = view_radiance(view, probe.encoding, probe.response, src)
    H, W = vr.radiance.shape[:2]
    yy, xx = np.mgrid[0:H, 0:W]
    px = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(np.float64)
    T = cam.world_from_camera
    if cam.model == "orthographic":  # parallel rays through the pixels' positions
        s_px = float(cam.pixel_size)
        pc = np.concatenate([(px - [(W - 1) / 2.0, (H - 1) / 2.0]) * s_px, np.zeros((len(px), 1))], axis=1)
        o = pc @ T[:3, :3].T + T[:3, 3]
        d = np.broadcast_to(T[:3, 2], o.shape)
    else:
        o = T[:3, 3]
        d = pixel_rays(px, cam.K, cam.dist) @ T[:3, :3].T
    n, p0 = probe.plane.normal, probe.plane.point
    den = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((p0 - o) @ n) / den
    ok = np.isfinite(t) & (t > 0) & vr.valid.ravel() & ~vr.saturated.ravel()
    pts = o + t[:, None] * d
    cam_pts = np.broadcast_to(o, pts.shape)  # each pixel's ray origin (the camera, or its orthographic pixel)
    if not ok.any():
        raise InputError("no pixel shows the plane (check camera.world_from_camera and plane)", src)
    ok[ok] &= ~_segments_blocked(pts[ok], cam_pts[ok], probe.occluder)
    idx = np.flatnonzero(ok)
    if len(idx) == 0:
        what = "occluder.box" if probe.occluder.kind == "box" else "occluder.mesh"
        raise InputError(f"{what} hides every pixel of the plane from the camera (the occluder stands between them "
                         "everywhere: check its size and position)", src)
    notes = [f"{vr.note}; {len(idx)} pixels on the plane"]
    keep, stride = pixel_grid_subset(px[idx], max_pixels)
    if stride > 1:
        idx = idx[keep]
        notes.append(f"used one pixel in {stride} along each row and column of them: {len(idx)} pixels, a regular "
                     f"grid (budget {max_pixels})")
    rad = vr.radiance.reshape(-1, 3)[idx].astype(np.float64)
    surface = None
    if need_surface:
        if probe.surface_image is None:
            raise InputError("surface_image: missing (the ratio case divides by a shadow-free image of the surface)",
                             src)
        img = read_image(probe.surface_image)
        check_encoding(img, probe.encoding, src)
        if img.shape != (H, W):
            raise InputError(f"surface_image: {img.shape[1]}x{img.shape[0]} differs from the photo's {W}x{H}", src)
        surface = decode_image(img, probe.encoding, probe.response)[0].reshape(-1, 3)[idx].astype(np.float64)
    views = -d[idx] if cam.model == "orthographic" else o - pts[idx]
    return pts[idx], rad, views / np.linalg.norm(views, axis=1, keepdims=True), surface, notes


def _occluder_dict(occ) -> dict:
    if occ.kind == "box":
        return {"box": {"center": occ.center.tolist(), "size": occ.size.tolist()}}
    return {"triangles": occ.mesh.vertices[occ.mesh.faces]}


SHADOW_CASES = ("lambertian", "torrance_sparrow", "ratio")


def shadow_lightmap(probe, height: int = 128, nodes="auto", case: str = "lambertian", nonnegative: bool = True,
                    smoothness: float = 0.0, criterion: str = "cv", ks: float | None = None,
                    sigma_deg: float | None = None, max_pixels: int | None = 4000,
                    confidence_threshold: float = 0.0, fill: str = "nearest") -> LightmapEstimate:
    """A light map from the shadow of a known occluder on a plane (Sato, Sato and Ikeuchi 1999).

    Parameters
    ----------
    probe : ffls.io.probe.Probe
        With ``plane``, ``occluder`` and a pinhole camera; ``plane.albedo`` for the
        ``'lambertian'`` and ``'torrance_sparrow'`` cases, ``surface_image`` for ``'ratio'``.
    height : int
    nodes : int, 'auto', 'uniform' or 'adaptive'
        Dome nodes (e.g. 521), or chosen by ``criterion``: ``'uniform'`` among uniform domes of
        46 to 526 nodes (:func:`ffls.probes.selection.select_sato_sato_ikeuchi`), ``'adaptive'``
        over an adaptive dome refined where the recovered light is
        (:func:`ffls.probes.selection.adaptive_sato_sato_ikeuchi`; only nodes whose whole shadow
        is in view are split). ``'auto'`` (default) is ``'adaptive'``: ``docs/probes.md``
        measures why.
    case : {'lambertian', 'torrance_sparrow', 'ratio'}
    nonnegative : bool
    smoothness : float
    criterion : {'cv', 'bic'}
    ks, sigma_deg : float
        ``'torrance_sparrow'``: the specular lobe's ``K_s`` and width (degrees).
    max_pixels : int or None
        Pixel budget: more receiver pixels are thinned to a regular grid (:func:`pixel_grid_subset`).
    confidence_threshold : float
        Directions whose node shadows at most this share of the pixels are reported as not seen.
    fill : {'nearest', 'zero'}
    """
    from ffls.probes.sato_sato_ikeuchi import occluder_visibility, sato_sato_ikeuchi, shadow_confidence
    from ffls.probes.selection import adaptive_sato_sato_ikeuchi, select_sato_sato_ikeuchi

    src = probe.json_path
    if case not in SHADOW_CASES:
        raise ValueError(f"case must be one of {SHADOW_CASES}, not {case!r}")
    pts, rad, views, surface, notes = shadow_pixels(probe, max_pixels, need_surface=case == "ratio")
    kw: dict = {"case": case, "nonnegative": nonnegative, "smoothness": smoothness}
    if case == "ratio":
        kw["surface_radiance"] = surface
        if probe.plane.albedo is not None:
            kw["reference_albedo"] = probe.plane.albedo  # makes the surface image's scale absolute
        else:
            notes.append("plane.albedo not stated: the ratio case takes the surface as white (albedo 1); the map "
                         "is scaled by the unknown albedo")
    else:
        if probe.plane.albedo is None:
            raise InputError(f"plane.albedo: missing (the {case} case needs the receiver's albedo; with a shadow-free "
                             f"surface_image use --case ratio)", src)
        kw["albedo"] = probe.plane.albedo
    if case == "torrance_sparrow":
        if ks is None or sigma_deg is None:
            raise InputError("the torrance_sparrow case needs the specular lobe: --ks and --sigma")
        kw.update(view_dirs=views, specular={"ks": float(ks), "sigma": float(np.radians(sigma_deg))})
    occ = _occluder_dict(probe.occluder)
    try:
        if nodes in ("auto", "uniform", "adaptive"):
            select = select_sato_sato_ikeuchi if nodes == "uniform" else adaptive_sato_sato_ikeuchi
            sel = select(pts, rad, occ, probe.plane.normal, criterion=criterion, **kw)
            fit, chosen = sel.fit, int(sel.fit.directions.shape[0])
            notes.append(sel.note)
        else:
            fit = sato_sato_ikeuchi(pts, rad, occ, probe.plane.normal, nodes=int(nodes), **kw)
            chosen = int(fit.directions.shape[0])  # the geodesic dome nearest the count asked
            if chosen != int(nodes):
                notes.append(f"--nodes {int(nodes)}: no geodesic dome has that size; the nearest has {chosen}")
    except InputError as e:
        raise _with_source(e, src) from None
    notes.append(f"Sato-Sato-Ikeuchi ({case}): {chosen} dome nodes, re-rendered relative RMS "
                 f"{100 * fit.relative_rms:.2f}%, condition {fit.condition:.3g}")
    vis = occluder_visibility(pts, fit.directions, occ)
    conf = shadow_confidence(fit.directions, vis, probe.plane.normal, height)
    share, note = _unresolved_elevation(pts, fit, occ, probe.plane.normal)
    if note:
        notes.append(note)
    details = {"nodes": chosen, "case": case, "relative_rms": float(fit.relative_rms),
               "condition": float(fit.condition), "unresolved_elevation_share": share}
    return _finish(fit.latlong(height), conf, confidence_threshold, "shadow", probe, notes, details, fill)


def _unresolved_elevation(points, fit, occluder, plane_normal) -> tuple[float, str]:
    """The share of the recovered light on the plane whose elevation the view does not fix, and a note.

    A node below :func:`ffls.probes.sato_sato_ikeuchi.elevation_limit` casts a shadow that runs
    past the photograph: its azimuth and ``E sin(elevation)`` are measured, its elevation (and so
    the light it sends sideways onto a relit object) is not.
    """
    from ffls.probes.sato_sato_ikeuchi import elevation_limit

    nrm = normalize(np.asarray(plane_normal, dtype=np.float64).reshape(3))
    d = np.asarray(fit.directions, dtype=np.float64)
    sin_el = d @ nrm
    power = np.maximum(np.asarray(fit.intensities, dtype=np.float64), 0.0).mean(axis=1) * np.maximum(sin_el, 0.0)
    up = sin_el > 1e-9
    lim = np.full(d.shape[0], np.nan)
    lim[up] = elevation_limit(points, d[up], occluder, nrm)
    el = np.arcsin(np.clip(sin_el, -1.0, 1.0))
    low = up & ~(el >= lim)  # below the limit, or no elevation at that azimuth is seen whole (NaN)
    total = float(power.sum())
    share = float(power[low].sum() / total) if total > 0 else 0.0
    if not np.any(low & (power > 0)):
        return share, ""
    seen = lim[low & np.isfinite(lim)]
    bound = (f"below their azimuth's elevation limit ({np.degrees(seen.min()):.1f}-{np.degrees(seen.max()):.1f} deg)"
             if seen.size else "at azimuths where no shadow is wholly in view")
    return share, (f"{int(np.count_nonzero(low & (power > 0)))} lit dome nodes, {100 * share:.1f}% of the light on the "
                   f"plane, are {bound}: their shadows run past the photograph (or end at its edge), which fixes "
                   f"their azimuth and E sin(elevation) but not their elevation, nor with it their power (E scales "
                   f"as 1 / sin): the light a relit object gets from the side there is uncertain")
