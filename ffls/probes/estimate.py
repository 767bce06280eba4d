"""Light maps from a probe folder: the pipelines behind :func:`ffls.probes.estimate_lightmap`.

Each pipeline reads a :class:`ffls.io.probe.Probe` (images, camera, sphere, geometry), runs one
paper's method on arrays and returns a :class:`ffls.probes.result.LightmapEstimate`.
"""
from __future__ import annotations

import numpy as np

from ffls.errors import InputError
from ffls.lightmaps.lightmap import LightMap
from ffls.probes.bracket import view_radiance
from ffls.probes.debevec import (CAMERA_CONE_DEG, RIM_PX, blind_spot, fill_unseen, latlong_solid_angles,
                                 merge_mirror_views, unwrap_mirror_ball_Debevec1998)
from ffls.probes.locate import locate_sphere
from ffls.probes.result import LightmapEstimate

__all__ = ["FILL_MODES", "CAMERA_SIZE", "camera_cone", "mirror_lightmap"]

#: How unseen directions are filled: from the nearest seen ones, or left black.
FILL_MODES = ("nearest", "zero")


def _integer_images(view) -> bool:
    return any(im.path.suffix.lower() not in (".exr", ".hdr", ".pic") for im in view.images)


#: Default radius (scene units, metres) of what stands at the camera: the photographer and the tripod.
CAMERA_SIZE = 0.5


def camera_cone(geo, camera_size: float = CAMERA_SIZE, fallback_deg: float = CAMERA_CONE_DEG) -> tuple[float, str]:
    """The half-angle (degrees) of the cone the camera and photographer fill, seen from the ball, and how it was set.

    ``atan(camera_size / D)`` with ``D`` the camera's distance from the ball, when the ball is
    located in scene units (a pinhole camera and a stated radius); otherwise ``fallback_deg``.
    """
    if geo.camera_model == "pinhole" and geo.radius_known:
        D = float(np.linalg.norm(geo.center_cam))
        return float(np.degrees(np.arctan(camera_size / D))), f"{camera_size:g} at {D:.3g} from the ball"
    return float(fallback_deg), "camera distance unknown: default"


def mirror_lightmap(probe, height: int = 128, camera_cone_deg: float | None = None, rim_px: float = RIM_PX,
                    supersample: int | None = None, weight_power: float = 2.0, fill: str = "nearest",
                    camera_size: float = CAMERA_SIZE) -> LightmapEstimate:
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

    Returns
    -------
    LightmapEstimate
        ``details``: ``views`` (per view: sphere, seen fraction), ``seen_fraction``,
        ``blind_spot_sr``, ``blind_spot_fraction``, ``camera_cone_sr``, ``clipped_fraction``.

    Raises
    ------
    InputError
        A view whose sphere is not a mirror, no sphere found, an unreadable or unusable image,
        a view that shows no usable direction.
    """
    if fill not in FILL_MODES:
        raise ValueError(f"fill must be one of {FILL_MODES}, not {fill!r}")
    src = probe.json_path
    views, notes, per_view = [], [], []
    sa = latlong_solid_angles(int(height))
    for k, view in enumerate(probe.views):
        tag = "" if len(probe.views) == 1 else f"view {k + 1}: "
        if view.sphere.material != "mirror":
            key = "sphere.material" if len(probe.views) == 1 else f"images[{k}].sphere.material"
            raise InputError(f"{key}: the mirror method needs a mirror ball, this one is {view.sphere.material!r} "
                             f"(use 'ffls probe diffuse')", src)
        vr = view_radiance(view, probe.encoding, probe.response, src)
        geo = locate_sphere(view, vr.radiance, src, saturates=_integer_images(view))
        cone, why = (float(camera_cone_deg), "given") if camera_cone_deg is not None else camera_cone(geo, camera_size)
        mv = unwrap_mirror_ball_Debevec1998(
            vr.radiance, geo.camera_model, geo.K, geo.dist, geo.world_from_camera, geo.center_cam, geo.radius,
            geo.center_px, geo.radius_px, height=height, valid=vr.valid, saturated=vr.saturated,
            camera_cone_deg=cone, rim_px=rim_px, supersample=supersample,
            reflectance=view.sphere.reflectance)
        frac = float(sa[mv.confidence > 0].sum() / (4 * np.pi))
        if frac == 0:
            raise InputError(f"{tag}the ball shows no usable direction (all its pixels invalid or masked)",
                             view.images[0].path)
        notes.append(f"{tag}{vr.note}; {geo.describe()}; saw {100 * frac:.1f}% of the sphere; camera cone "
                     + (f"{cone:.1f} deg masked ({why})" if cone > 0 else "kept"))
        per_view.append({"sphere_source": geo.source, "center_px": geo.center_px.tolist(),
                         "radius_px": geo.radius_px, "seen_fraction": frac, "camera_cone_deg": cone})
        views.append(mv)
    merged = merge_mirror_views(views, power=weight_power)
    seen = merged.confidence > 0
    data = fill_unseen(merged.radiance, seen) if fill == "nearest" else merged.radiance
    bs = blind_spot(seen)
    cone_sr = float(sa[merged.camera_cone].sum())
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
