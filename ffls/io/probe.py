"""Probe folders: ``probe.json`` and the photographs of a light probe (issue 11).

A probe folder holds the photographs from which a light map is estimated
(:func:`ffls.probes.estimate_lightmap`): a mirror ball (Debevec 1998), a diffuse sphere or
object (Hougen and Ahuja 1993), a cast shadow (Sato, Sato and Ikeuchi 1999) or the same for
POCS (Singh and Ahuja). The format is specified, with complete examples, in
``docs/formats.md`` ("probe.json"). It shares ``capture.json``'s ``camera`` and ``encoding``
keys and their validation (:func:`ffls.io.capture.parse_camera`,
:func:`ffls.io.capture.parse_encoding`), the orthographic model included.

Every value is checked here; a bad one raises :class:`ffls.errors.InputError` naming
``probe.json`` and the key. Keys that a method does not need are still validated when present
(a typo should not pass silently) but otherwise ignored.

Meshes (``occluder.mesh``, ``object.mesh``) are read with ``trimesh`` (OBJ, PLY, STL, OFF, GLB,
...): its readers handle the binary and ASCII variants, quads and polygons (triangulated), and
a file holding a scene of several meshes (concatenated), which a hand-written reader of two
formats would not.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffls import conventions
from ffls.errors import InputError, not_a_regular_file, register_input
from ffls.io.capture import JsonReader, check_file_name, parse_camera, parse_encoding

__all__ = ["PROBE_FILE", "PROBE_FORMAT", "SPHERE_MATERIALS", "ProbeCamera", "ProbeSphere", "ProbeImage", "ProbeView",
           "ProbePlane", "ProbeMesh", "ProbeOccluder", "Probe", "load_probe", "read_mesh", "MAX_PIXELS",
           "EXPOSURE_RANGE_S", "exposure_time_problem"]

PROBE_FILE = "probe.json"
PROBE_FORMAT = "ffls-probe"
#: Materials of the probe sphere.
SPHERE_MATERIALS = ("mirror", "diffuse")
_TOP_KEYS = {"format", "version", "images", "camera", "encoding", "sphere", "plane", "occluder", "object",
             "surface_image"}
#: The largest pixel coordinate or radius a pixel hint may give (no sensor is wider).
MAX_PIXELS = 1e6
#: Exposure times a camera can give, seconds: from a microsecond (the fastest electronic shutters,
#: 1/32000 s and flash durations, lie above it) to about a day (long astronomical exposures).
#: A time outside is a typo or a broken EXIF tag, and would overflow or zero the merged radiance.
EXPOSURE_RANGE_S = (1e-6, 1e5)
_SPHERE_KEYS = {"center", "radius", "center_px", "radius_px", "material", "albedo", "reflectance"}
_MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


@dataclass(frozen=True)
class ProbeCamera:
    """The camera of one view, as ``capture.json`` states it (:func:`ffls.io.capture.parse_camera`).

    Attributes
    ----------
    model : {'pinhole', 'orthographic'}
    K : (3, 3) float64 or None
        None for an orthographic camera (and for a pinhole camera the file gives no ``K`` for;
        the methods that need one say so).
    dist : (k,) float64
        OpenCV distortion (zeros when absent).
    world_from_camera : (4, 4) float64
        Rigid transform; :data:`ffls.conventions.DEFAULT_WORLD_FROM_CAMERA` when absent.
    world_from_camera_is_default : bool
    pixel_size : float or None
        Orthographic only (``camera.pixel_size``, a ``probe.json`` addition to the keys of
        ``capture.json``): scene units per pixel, which puts the pixels in the world (pixel
        ``(u, v)`` is at camera-frame ``((u - cx) s, (v - cy) s, 0)``, ``(cx, cy)`` the image
        centre); needed to map a cast-shadow photo onto its plane.
    """

    model: str
    K: np.ndarray | None
    dist: np.ndarray
    world_from_camera: np.ndarray
    world_from_camera_is_default: bool = True
    pixel_size: float | None = None


@dataclass(frozen=True)
class ProbeSphere:
    """Where the probe sphere is and what it is made of.

    It is located by its world centre and radius (``center`` + ``radius``), by a pixel hint
    (``center_px`` with an optional ``radius_px``: the sphere finder searches near it), or,
    with neither, found automatically (:func:`ffls.spheres.detect.find_spheres`).

    Attributes
    ----------
    center : (3,) float64 or None
        World centre, scene units.
    radius : float or None
        Radius, scene units (needed with ``center``; optional otherwise: a mirror ball's
        reflection does not depend on the scale).
    center_px : (2,) float64 or None
        Pixel hint (x right, y down).
    radius_px : float or None
        Apparent radius hint, pixels.
    material : {'mirror', 'diffuse'} or None
        None when ``probe.json`` does not state it: the command (``ffls probe mirror`` or
        ``diffuse``) says what the sphere is, and its notes say it was taken so.
    albedo : float or None
        Diffuse albedo in (0, 1] (``material`` ``'diffuse'``); None when not stated.
    reflectance : float
        A mirror ball's reflectance in (0, 1] (chrome reflects about 0.5 to 0.8 of the light);
        the map is the image divided by it. 1 when not stated.
    """

    center: np.ndarray | None = None
    radius: float | None = None
    center_px: np.ndarray | None = None
    radius_px: float | None = None
    material: str | None = None
    albedo: float | None = None
    reflectance: float = 1.0

    @property
    def location(self) -> str:
        """``'world'`` (centre and radius given), ``'pixel'`` (a pixel hint) or ``'auto'`` (to be found)."""
        if self.center is not None:
            return "world"
        return "pixel" if self.center_px is not None else "auto"


@dataclass(frozen=True)
class ProbeImage:
    """One image file and, in a bracket, its exposure time (seconds)."""

    path: Path
    exposure_s: float | None = None


@dataclass(frozen=True)
class ProbeView:
    """One view of the probe: a single image or an exposure bracket, with its camera and sphere.

    Attributes
    ----------
    images : tuple of ProbeImage
        One image, or a bracket (two or more, each with ``exposure_s``).
    camera : ProbeCamera
    sphere : ProbeSphere
    """

    images: tuple
    camera: ProbeCamera
    sphere: ProbeSphere

    @property
    def is_bracket(self) -> bool:
        """True when the view is an exposure bracket (its images carry exposure times)."""
        return self.images[0].exposure_s is not None


@dataclass(frozen=True)
class ProbePlane:
    """The receiving plane of cast shadows: a point on it, its unit normal (world) and albedo (None: unknown)."""

    point: np.ndarray
    normal: np.ndarray
    albedo: float | None = None


@dataclass(frozen=True)
class ProbeMesh:
    """A triangle mesh in world coordinates.

    Attributes
    ----------
    vertices : (n, 3) float64
        World coordinates (``world_from_object`` applied).
    faces : (m, 3) int64
    path : pathlib.Path
    world_from_object : (4, 4) float64
    """

    vertices: np.ndarray
    faces: np.ndarray
    path: Path
    world_from_object: np.ndarray


@dataclass(frozen=True)
class ProbeOccluder:
    """The object casting the shadows: an axis-aligned box (``center``, ``size``) or a mesh."""

    kind: str
    center: np.ndarray | None = None
    size: np.ndarray | None = None
    mesh: ProbeMesh | None = None


@dataclass
class Probe:
    """A probe folder: views of the probe and the scene geometry the methods need.

    Attributes
    ----------
    folder : pathlib.Path
    views : list of ProbeView
        One view, or several (a mirror ball seen from directions 90 degrees apart).
    encoding : str or dict
        As in ``capture.json``: ``'srgb'``, ``'linear'``, ``{'gamma': g}``, ``{'response': file}``,
        or ``'auto'`` (not stated: floating-point images are linear, integer images are refused,
        ffls never guesses).
    response : (256, 3) float64 or None
        The inverse response table of ``{'response': file}``.
    plane : ProbePlane or None
    occluder : ProbeOccluder or None
    object : ProbeMesh or None
        A diffuse object of known geometry (Hougen-Ahuja on something other than a sphere).
    object_albedo : float or None
    surface_image : pathlib.Path or None
        A shadow-free image of the receiving surface (Sato-Sato-Ikeuchi with unknown albedo).
    """

    folder: Path
    views: list
    encoding: object = "auto"
    response: np.ndarray | None = None
    plane: ProbePlane | None = None
    occluder: ProbeOccluder | None = None
    object: ProbeMesh | None = None
    object_albedo: float | None = None
    surface_image: Path | None = None
    extra: dict = field(default_factory=dict)

    @property
    def json_path(self) -> Path:
        """``folder / 'probe.json'``."""
        return self.folder / PROBE_FILE

    @property
    def view(self) -> ProbeView:
        """The first view (the methods that take one view use it)."""
        return self.views[0]


# ----------------------------------------------------------------------------- parsing helpers
def _short(value, n: int = 60) -> str:
    s = repr(value)
    return s if len(s) <= n else s[: n - 3] + "..."


def exposure_time_problem(t) -> str | None:
    """Why ``t`` is not an exposure time in seconds (not a finite number inside
    :data:`EXPOSURE_RANGE_S`), or None when it is one. A JSON string (``"0.01"``) or boolean is
    not a number (``float()`` would read them: ``true`` as 1 s)."""
    if isinstance(t, (str, bool)):
        return f"{json.dumps(t)} is not a number of seconds"
    try:
        t = float(t)
    except (TypeError, ValueError, ZeroDivisionError):
        return f"{t!r} is not a number of seconds"
    lo, hi = EXPOSURE_RANGE_S
    if not np.isfinite(t) or not lo <= t <= hi:
        return f"{t:g} s is not an exposure time (expected {lo:g} to {hi:g} s)"
    return None


def _object(j: JsonReader, value, key: str, allowed: set) -> dict:
    if not isinstance(value, dict):
        j.fail(key, f"expected an object, got {_short(value)}")
    unknown = sorted(set(value) - allowed)
    if unknown:
        j.fail(key, f"unknown key {unknown[0]!r} (known: {', '.join(sorted(allowed))})")
    return value


def _fraction(j: JsonReader, value, key: str) -> float:
    v = j.number(value, key, positive=True)
    if v > 1.0:
        j.fail(key, f"must be in (0, 1], got {v:g}")
    return v


def _file(j: JsonReader, folder: Path, name, key: str, suffixes: tuple | None = None) -> Path:
    name = check_file_name(j, name, key)
    p = folder / name
    if suffixes is not None and p.suffix.lower() not in suffixes:
        j.fail(key, f"{name!r}: expected one of {', '.join(suffixes)}")
    if not p.is_file():
        special = not_a_regular_file(p)
        j.fail(key, f"file {name!r} {special}" if special else f"file {name!r} not found in {folder}")
    register_input(p)
    return p


def _image_list(j: JsonReader, folder: Path, items, key: str) -> tuple:
    """``images`` of one view: a list of file names (one image) or of bracket entries."""
    from ffls.io.images import READ_EXTENSIONS

    if not isinstance(items, list) or not items:
        j.fail(key, f"expected a non-empty list, got {_short(items)}")
    out = []
    bracket = isinstance(items[0], dict)
    for k, it in enumerate(items):
        ik = f"{key}[{k}]"
        if isinstance(it, dict) != bracket:
            j.fail(ik, "mixes bracket entries {\"file\": ..., \"exposure_s\": ...} with plain file names")
        if bracket:
            _object(j, it, ik, {"file", "exposure_s"})
            path = _file(j, folder, j.require(it, "file", ik + "."), ik + ".file", READ_EXTENSIONS)
            t = j.number(j.require(it, "exposure_s", ik + "."), ik + ".exposure_s", positive=True)
            why = exposure_time_problem(t)
            if why:
                j.fail(ik + ".exposure_s", why)
            out.append(ProbeImage(path, t))
        else:
            out.append(ProbeImage(_file(j, folder, it, ik, READ_EXTENSIONS)))
    if not bracket and len(out) > 1:
        j.fail(key, f"{len(out)} plain images in one view: give each its \"exposure_s\" for an exposure bracket "
                    "([{\"file\": ..., \"exposure_s\": ...}, ...]), or list separate views, each "
                    "{\"images\": [...], \"camera\": {...}}")
    if bracket:
        if len(out) < 2:
            j.fail(key, "a bracket needs at least two exposures")
        names = [p.path.name for p in out]
        if len(set(names)) != len(names):
            j.fail(key, "an image is listed twice in the bracket")
        t = [p.exposure_s for p in out]
        if max(t) - min(t) <= 1e-9 * max(t):
            j.fail(key, f"all {len(t)} exposure times are equal ({t[0]:g} s): not a bracket")
    return tuple(out)


def _camera(j: JsonReader, value, key: str = "camera") -> ProbeCamera:
    if value is None:
        return ProbeCamera("pinhole", None, np.zeros(5), conventions.DEFAULT_WORLD_FROM_CAMERA.copy(), True)
    pixel_size = None
    if isinstance(value, dict) and "pixel_size" in value:
        pixel_size = j.number(value["pixel_size"], key + ".pixel_size", positive=True)
        if value.get("model") != "orthographic":
            j.fail(key + ".pixel_size", "applies to an orthographic camera (\"model\": \"orthographic\"); a pinhole "
                                        "camera's scale is its K")
        value = {k: v for k, v in value.items() if k != "pixel_size"}
    if key != "camera":  # a view's camera: name the view's key in the message
        sub = JsonReader(j.path)

        def fail(k, problem, _key=key):
            j.fail(_key + k[len("camera"):], problem)

        sub.fail = fail
        K, dist, wfc, default, model = parse_camera(sub, value)
    else:
        K, dist, wfc, default, model = parse_camera(j, value)
    return ProbeCamera(model, K, dist, wfc, default, pixel_size)


def _sphere(j: JsonReader, value, key: str = "sphere", base: ProbeSphere | None = None) -> ProbeSphere:
    if value is None:
        return base if base is not None else ProbeSphere()
    s = _object(j, value, key, _SPHERE_KEYS)
    kw = {}
    if base is not None:
        kw = {"material": base.material, "albedo": base.albedo, "reflectance": base.reflectance,
              "radius": base.radius}
    if "center" in s:
        kw["center"] = j.array(s["center"], key + ".center", (3,))
    if "radius" in s:
        kw["radius"] = j.number(s["radius"], key + ".radius", positive=True)
    if "center_px" in s:
        kw["center_px"] = j.array(s["center_px"], key + ".center_px", (2,), max_abs=MAX_PIXELS)
    if "radius_px" in s:
        if "center_px" not in s:
            j.fail(key + ".radius_px", "given without center_px")
        kw["radius_px"] = j.number(s["radius_px"], key + ".radius_px", positive=True)
        if kw["radius_px"] > MAX_PIXELS:
            j.fail(key + ".radius_px", f"must be at most {MAX_PIXELS:g} px (a pixel circle), got {s['radius_px']!r}")
    if "center" in kw and kw.get("radius") is None:
        j.fail(key + ".radius", "missing key (a world centre needs the sphere's radius)")
    if "material" in s:
        if s["material"] not in SPHERE_MATERIALS:
            j.fail(key + ".material", f"expected one of {', '.join(map(repr, SPHERE_MATERIALS))}, "
                                      f"got {_short(s['material'])}")
        kw["material"] = s["material"]
    if "albedo" in s:
        kw["albedo"] = _fraction(j, s["albedo"], key + ".albedo")
    if "reflectance" in s:
        kw["reflectance"] = _fraction(j, s["reflectance"], key + ".reflectance")
    if "albedo" in kw and kw.get("material") != "diffuse" and "albedo" in s:
        j.fail(key + ".albedo", "applies to a diffuse sphere (\"material\": \"diffuse\")")
    return ProbeSphere(**kw)


def _pose(j: JsonReader, value, key: str) -> np.ndarray:
    if value is None:
        return np.eye(4)
    T = j.array(value, key, (4, 4))
    if not (conventions.is_rotation(T[:3, :3], atol=1e-4) and np.allclose(T[3], [0, 0, 0, 1])):
        # a uniform scale is allowed (a mesh in other units): check the rotation of the normalised block
        s = np.cbrt(np.linalg.det(T[:3, :3])) if np.linalg.det(T[:3, :3]) > 0 else 0.0
        if not (s > 0 and conventions.is_rotation(T[:3, :3] / s, atol=1e-4) and np.allclose(T[3], [0, 0, 0, 1])):
            j.fail(key, "not a similarity transform (rotation times a positive scale, last row 0 0 0 1)")
    return T


def read_mesh(path: str | os.PathLike, world_from_object=None) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh (OBJ, PLY, STL, OFF, glTF) with ``trimesh``, in world coordinates.

    Parameters
    ----------
    path : path-like
    world_from_object : (4, 4) float, optional
        Pose (a similarity transform) applied to the vertices.

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64

    Raises
    ------
    InputError
        Unreadable or corrupt file, no triangles, or non-finite vertices.
    """
    import logging

    import trimesh

    path = Path(path)
    logging.getLogger("trimesh").setLevel(logging.ERROR)  # the library logs warnings; errors are ours
    try:
        m = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # trimesh raises many kinds (ValueError, KeyError, IndexError, ...)
        raise InputError(f"cannot read mesh ({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})",
                         path) from None
    v = np.asarray(getattr(m, "vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
    f = np.asarray(getattr(m, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    if len(f) == 0 or len(v) < 3:
        raise InputError("mesh has no triangles", path)
    if not np.all(np.isfinite(v)):
        raise InputError("mesh has non-finite vertex coordinates", path)
    if f.min() < 0 or f.max() >= len(v):
        raise InputError("mesh faces index missing vertices", path)
    if world_from_object is not None:
        T = np.asarray(world_from_object, dtype=np.float64)
        v = v @ T[:3, :3].T + T[:3, 3]
    return v, f


def _mesh(j: JsonReader, folder: Path, value: dict, key: str) -> ProbeMesh:
    path = _file(j, folder, value["mesh"], key + ".mesh", _MESH_SUFFIXES)
    T = _pose(j, value.get("world_from_object"), key + ".world_from_object")
    try:
        v, f = read_mesh(path, T)
    except InputError as e:
        j.fail(key + ".mesh", f"{path.name}: {e.message}")
    return ProbeMesh(v, f, path, T)


def _occluder(j: JsonReader, folder: Path, value) -> ProbeOccluder:
    o = _object(j, value, "occluder", {"box", "mesh", "world_from_object"})
    if ("box" in o) == ("mesh" in o):
        j.fail("occluder", "expected exactly one of \"box\" {\"center\": [x, y, z], \"size\": [sx, sy, sz]} or "
                           "\"mesh\": \"file.obj|.ply\"")
    if "box" in o:
        if "world_from_object" in o:
            j.fail("occluder.world_from_object", "applies to a mesh occluder")
        b = _object(j, o["box"], "occluder.box", {"center", "size"})
        c = j.array(j.require(b, "center", "occluder.box."), "occluder.box.center", (3,))
        s = j.array(j.require(b, "size", "occluder.box."), "occluder.box.size", (3,))
        if np.any(s <= 0):
            j.fail("occluder.box.size", f"every side must be positive, got {s.tolist()}")
        return ProbeOccluder("box", center=c, size=s)
    return ProbeOccluder("mesh", mesh=_mesh(j, folder, o, "occluder"))


def _plane(j: JsonReader, value) -> ProbePlane:
    p = _object(j, value, "plane", {"point", "normal", "albedo"})
    point = j.array(j.require(p, "point", "plane."), "plane.point", (3,))
    n = j.array(j.require(p, "normal", "plane."), "plane.normal", (3,))
    big = float(np.abs(n).max())  # (scaled first: the norm of [1e308, 1e308, 1e308] overflowed to a zero normal)
    if not big > 0:
        j.fail("plane.normal", "must not be zero")
    n = n / big
    albedo = _fraction(j, p["albedo"], "plane.albedo") if "albedo" in p else None
    return ProbePlane(point, n / np.linalg.norm(n), albedo)


def _views(j: JsonReader, folder: Path, items, camera: ProbeCamera, sphere: ProbeSphere) -> list:
    if not isinstance(items, list) or not items:
        j.fail("images", f"expected a non-empty list of file names, bracket entries or views, got {_short(items)}")
    is_view = [isinstance(it, dict) and "images" in it for it in items]
    if not any(is_view):
        return [ProbeView(_image_list(j, folder, items, "images"), camera, sphere)]
    if not all(is_view):
        j.fail("images", "mixes views {\"images\": [...], \"camera\": {...}} with file names or bracket entries")
    views = []
    for k, it in enumerate(items):
        key = f"images[{k}]"
        _object(j, it, key, {"images", "camera", "sphere"})
        cam = _camera(j, it["camera"], key + ".camera") if "camera" in it else camera
        sph = _sphere(j, it.get("sphere"), key + ".sphere", base=sphere)
        views.append(ProbeView(_image_list(j, folder, it["images"], key + ".images"), cam, sph))
    return views


def load_probe(folder: str | os.PathLike) -> Probe:
    """Load and validate a probe folder.

    Parameters
    ----------
    folder : path-like
        Folder holding ``probe.json`` (``probe.json`` itself may be passed too).

    Returns
    -------
    Probe

    Raises
    ------
    InputError
        A missing folder, file or key, corrupt JSON, an unknown key, or a value of the wrong
        type, shape or range; one line naming ``probe.json`` (or the image or mesh) and the key.
    """
    folder, j, doc = JsonReader.folder_document(folder, PROBE_FILE, PROBE_FORMAT, "probe")
    unknown = sorted(k for k in doc if k not in _TOP_KEYS and not k.startswith("x-"))
    if unknown:
        j.fail(unknown[0], f"unknown key (known: {', '.join(sorted(_TOP_KEYS))}; private keys start with 'x-')")
    encoding, response = parse_encoding(j, doc, folder)
    camera = _camera(j, doc.get("camera"))
    sphere = _sphere(j, doc.get("sphere"))
    views = _views(j, folder, j.require(doc, "images"), camera, sphere)
    for k, v in enumerate(views):
        where = "camera" if len(views) == 1 else f"images[{k}].camera"
        if v.sphere.location == "world" and v.camera.model == "orthographic":
            j.fail("sphere.center", f"an orthographic camera ({where}) measures no depth: locate the sphere by "
                                    "\"center_px\" (and \"radius_px\"), or let ffls find it")
    plane = _plane(j, doc["plane"]) if "plane" in doc else None
    occluder = _occluder(j, folder, doc["occluder"]) if "occluder" in doc else None
    obj = albedo = None
    if "object" in doc:
        o = _object(j, doc["object"], "object", {"mesh", "world_from_object", "albedo"})
        j.require(o, "mesh", "object.")
        obj = _mesh(j, folder, o, "object")
        albedo = _fraction(j, o["albedo"], "object.albedo") if "albedo" in o else None
    from ffls.io.images import READ_EXTENSIONS

    surface = _file(j, folder, doc["surface_image"], "surface_image", READ_EXTENSIONS) \
        if "surface_image" in doc else None
    extra = {k: v for k, v in doc.items() if k.startswith("x-")}
    return Probe(folder=folder, views=views, encoding=encoding, response=response, plane=plane, occluder=occluder,
                 object=obj, object_albedo=albedo, surface_image=surface, extra=extra)
