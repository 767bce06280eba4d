"""Capture folders (``capture.json`` + images), light lists (``lights.json``) and RTI ``.lp`` files.

The file formats are specified, with complete examples, in ``docs/formats.md``. Every loader
validates everything it reads and raises :class:`ffls.errors.InputError` naming the file and
the key, image or line at fault; every writer is atomic.

Encoding rule when ``capture.json`` has no ``"encoding"`` (``Capture.encoding == 'auto'``):
floating-point images (EXR, HDR) are linear by definition; integer images (8- or 16-bit PNG,
TIFF, JPEG) have an unknown encoding, which ffls never guesses. ``ffls lights`` calibrates it from
the spheres and writes it into ``lights.json`` (the top-level ``"encoding"`` record,
:attr:`Lights.encoding`); :func:`load_capture_and_lights` applies that record to a capture that
states none. Elsewhere :mod:`ffls.radiance.photos` refuses such images with one line. A stated
``"encoding"`` always wins.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from ffls import conventions
from ffls.errors import (InputError, atomic_output, broken_link, not_a_regular_file, os_error_message,
                         register_input)
from ffls.io.response import load_response, polynomial_response_table

__all__ = [
    "CAPTURE_FILE",
    "MAX_FOCAL_PX",
    "MAX_PIXEL_ASPECT",
    "LIGHTS_FILE",
    "Capture",
    "load_capture",
    "save_capture",
    "distortion_problem",
    "MAX_DISTORTION_SCALE",
    "capture_listing",
    "CAPTURE_SEARCH_DEPTH",
    "Lights",
    "load_lights",
    "save_lights",
    "read_lp",
    "write_lp",
    "lp_to_world",
    "world_to_lp",
    "lights_from_lp",
    "load_lights_any",
    "cap_cones",
    "parse_lights_map",
    "load_capture_and_lights",
    "UNIT_TOLERANCE",
    "ENCODING_CURVES",
    "ENCODING_NAMINGS",
    "GAMMA_RANGE",
    "encoding_from_record",
    "record_response",
    "CALIBRATED_RESPONSE",
    "apply_lights_encoding",
    "SPHERE_MATERIALS",
    "sphere_materials",
    "JsonReader",
    "parse_camera",
    "parse_encoding",
    "check_file_name",
    "MAX_JSON_BYTES",
    "FileTooLarge",
    "read_json_text",
]

CAPTURE_FILE = "capture.json"
LIGHTS_FILE = "lights.json"
#: Largest accepted | |d| - 1 | for a light direction read from a file.
UNIT_TOLERANCE = 1e-3
#: Largest accepted deviation of a stated rotation block from a rotation (``R R^T`` against the
#: identity, ``det R`` against 1): any rotation written to 3 decimals is within it (docs/formats.md,
#: "The camera's tilt", gives them so); such a block is taken as its nearest rotation.
ROTATION_TOLERANCE = 2e-3
#: A rotation block within this of orthonormal with determinant 1 is a rotation to float64 rounding
#: (a computed rotation's ``R R^T`` is within a few 1e-16 of the identity) and is used as given.
ROTATION_ROUNDING = 1e-14
_ENCODINGS = ("srgb", "linear")
_FLOAT_SUFFIXES = (".exr", ".hdr", ".pic")
_ENCODING_FORMS = "'srgb', 'linear', {\"gamma\": g} or {\"response\": \"file.npy|.csv\"}"
#: Gammas accepted in ``{"gamma": g}`` (also by :func:`ffls.radiance.encoding.gamma_decode`): wider is no camera's.
GAMMA_RANGE = (0.2, 5.0)
_DIST_LENGTHS = (4, 5, 8, 12, 14)
#: The largest entry of ``camera.K`` (pixels): a 100 m focal length on 1 um pixels; beyond it no
#: lens and sensor exist, and the projection's products overflow.
MAX_FOCAL_PX = 1e8
#: The largest ``fx / fy`` (or ``fy / fx``) of ``camera.K``: anamorphic lenses squeeze by 2 at most.
MAX_PIXEL_ASPECT = 3.0
_CAPTURE_KEYS = {"format", "version", "images", "image_size", "encoding", "camera", "sphere_radius",
                 "spheres", "sphere_count", "scene_center", "hemisphere", "units"}


# ----------------------------------------------------------------------------- validation helpers
class _Json:
    """Reads and checks values of one JSON file, raising InputError naming the file and key."""

    def __init__(self, path: Path):
        self.path = path

    def fail(self, key: str, problem: str):
        raise InputError(f"{key}: {problem}" if key else problem, self.path)

    @classmethod
    def folder_document(cls, folder, filename: str, fmt: str, kind: str) -> tuple:
        """``(folder, reader, doc)``: FOLDER (or FOLDER/filename itself), a reader of its document, the document.

        The document is read and its header checked (``format`` is ``fmt``, ``version`` 1); a
        missing folder is one line naming it as a ``kind`` folder.
        """
        folder = Path(folder)
        if folder.name == filename and folder.is_file():
            folder = folder.parent
        if not folder.is_dir():
            raise InputError(broken_link(folder) or (f"{kind} folder not found" if not folder.exists()
                                                     else "not a folder"), folder)
        j = cls(folder / filename)
        example = '"ball.exr"' if kind == "probe" else '"IMG_0001.JPG", ...'  # (a folder of photos: how to describe them)
        doc = j.load(filename, missing=f"{filename} not found: a {kind} folder needs one listing its photos, at least "
                                       f"{{\"format\": \"{fmt}\", \"version\": 1, \"images\": [{example}]}} "
                                       "(docs/formats.md)")
        j.header(doc, fmt)
        return folder, j, doc

    def load(self, what: str, missing: str | None = None) -> dict:
        if not self.path.exists():  # (``missing``: the line for a file that is not there, not a broken link)
            self.fail("", broken_link(self.path) or missing or f"{what} not found")
        if self.path.is_dir():
            self.fail("", f"is a folder, not {what}" + (" (a capture's lights are its lights.json)"
                                                         if what == LIGHTS_FILE else ""))
        special = not_a_regular_file(self.path)  # (a FIFO was waited on forever, /dev/zero read to no end)
        if special:
            self.fail("", f"{special} ({what} expected)")
        register_input(self.path)
        try:
            text = read_json_text(self.path, what)  # (a BOM, as Notepad writes, is no content)
        except FileTooLarge as e:
            self.fail("", str(e))
        except UnicodeDecodeError:
            self.fail("", f"is not a JSON text file ({what} expected): {NOT_TEXT}")
        except OSError as e:
            self.fail("", f"cannot read {what} ({os_error_message(e)})")
        try:
            doc = parse_json(text)
        except ValueError as e:
            self.fail("", str(e))
        if not isinstance(doc, dict):
            self.fail("", f"{what} must hold a JSON object, not {type(doc).__name__}")
        return doc

    def header(self, doc: dict, fmt: str) -> None:
        if doc.get("format") != fmt:
            self.fail("format", f"expected {fmt!r}, got {doc.get('format')!r}")
        if "version" not in doc:
            self.fail("version", "missing key")
        if isinstance(doc["version"], bool) or not isinstance(doc["version"], int) or doc["version"] != 1:
            self.fail("version", f"unsupported version {doc['version']!r} (this ffls reads version 1)")

    def require(self, doc: dict, key: str, prefix: str = ""):
        if key not in doc:
            self.fail(prefix + key, "missing key")
        return doc[key]

    def number(self, value, key: str, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.fail(key, f"expected a finite number, got {value!r}")
        if positive and value <= 0:
            self.fail(key, f"must be positive, got {value!r}")
        return float(value)

    def array(self, value, key: str, shape: tuple, max_abs: float | None = None) -> np.ndarray:
        if not _all_numbers(value):  # a boolean is not a number (np.array would take True as 1.0)
            self.fail(key, f"expected an array of shape {shape} of numbers, got {_short(value)}")
        try:
            a = np.array(value, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            a = None
        if a is None or a.shape != shape or isinstance(value, str):
            self.fail(key, f"expected an array of shape {shape} of numbers, got {_short(value)}")
        if not np.all(np.isfinite(a)):
            self.fail(key, "non-finite number")
        if max_abs is not None and np.any(np.abs(a) > max_abs):
            self.fail(key, f"values beyond +-{max_abs:g}: {_short(value)}")
        return a

    def direction(self, value, key: str) -> np.ndarray:
        """A (3,) unit vector (within :data:`UNIT_TOLERANCE`), renormalised; huge values fail without overflow."""
        d = self.array(value, key, (3,), max_abs=2.0)
        norm = float(np.linalg.norm(d))
        if abs(norm - 1.0) > UNIT_TOLERANCE:
            self.fail(key, f"not a unit vector (norm {norm:.6g}, tolerance {UNIT_TOLERANCE})")
        return d / norm

    def string(self, value, key: str) -> str:
        if not isinstance(value, str) or not value:
            self.fail(key, f"expected a non-empty string, got {_short(value)}")
        return value


class _DuplicateKey(Exception):
    pass


def _unique_keys(pairs) -> dict:
    """A JSON object as a dict, refusing a key given twice (``json`` keeps the last one silently)."""
    d = dict(pairs)
    if len(d) != len(pairs):
        seen = set()
        raise _DuplicateKey(next(k for k, _ in pairs if k in seen or seen.add(k)))
    return d


#: The largest JSON (or ``.lp``) file ffls reads, in bytes. Such a file is read whole and parsed into
#: Python objects: 1.6 times its size for a real ``lights.json`` (4 to 8 spheres, 5 to 8 kB a photo, so
#: 256 MiB holds some 30000 photos of 8 spheres), up to 24 times for ``[{}, {}, ...]`` (docs/formats.md).
MAX_JSON_BYTES = 256 << 20


NOT_TEXT = "its bytes are not UTF-8 (nor UTF-16 or UTF-32) text"
"""Why :func:`read_json_text` refused a file's bytes, the same words for every text file ffls reads."""


class FileTooLarge(ValueError):
    """A text file over :data:`MAX_JSON_BYTES`, refused before it is read (the message names no path)."""


def read_json_text(path, what: str = "JSON file") -> str:
    """The text of a JSON or ``.lp`` file, refused over :data:`MAX_JSON_BYTES`.

    UTF-8 (a BOM dropped), or UTF-16 / UTF-32 (as Windows Notepad's "Unicode" saves it), told apart
    as :func:`json.detect_encoding` does (which ``json.loads`` of bytes uses).

    The size is checked on the open file before anything is read, and at most one byte more than
    the limit is ever read (a file that grows meanwhile is refused too).

    Raises
    ------
    FileTooLarge
        The file is larger than :data:`MAX_JSON_BYTES`.
    UnicodeDecodeError
        Its bytes are not UTF-8 (nor UTF-16 / UTF-32): :data:`NOT_TEXT`.
    OSError
        It cannot be opened or read.
    """
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        data = b"" if size > MAX_JSON_BYTES else f.read(MAX_JSON_BYTES + 1)
    if size > MAX_JSON_BYTES or len(data) > MAX_JSON_BYTES:
        raise FileTooLarge(f"is {max(size, len(data))} bytes, more than the {MAX_JSON_BYTES >> 20} MiB "
                           f"({MAX_JSON_BYTES} bytes) a {what} may be (ffls reads it whole into memory; "
                           "docs/formats.md)")
    enc = json.detect_encoding(data)
    return data.decode("utf-8-sig" if enc == "utf-8" else enc)


def parse_json(text: str):
    """``json.loads(text)``, every failure one ``ValueError`` of one line.

    A key given twice in one object (``"encoding": "srgb", "encoding": "linear"``) is refused:
    Python's parser keeps the last silently, where the writer may have meant the first.

    Besides corrupt text (``corrupt JSON at line L column C: ...``), Python's parser fails on a
    document nested deeper than its recursion limit (``RecursionError``, a traceback before) and
    on an integer of more than 4300 digits (a ``ValueError`` of three sentences).
    """
    if not text.strip():  # (a 0-byte file said "corrupt JSON at line 1 column 1: Expecting value")
        raise ValueError("the file is empty (no JSON in it)")
    try:
        return json.loads(text, object_pairs_hook=_unique_keys)
    except _DuplicateKey as e:
        raise ValueError(f"corrupt JSON: the key {e.args[0]!r} is given twice in one object (which one is "
                         "meant?)") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"corrupt JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    except RecursionError:
        raise ValueError("corrupt JSON: nested deeper than Python's parser goes") from None
    except ValueError:  # (int: "Exceeds the limit (4300 digits) for integer string conversion ...")
        raise ValueError("corrupt JSON: a number of more than 4300 digits") from None


def _all_numbers(value) -> bool:
    """True when ``value`` is a number or nested lists of numbers, none of them a boolean."""
    if isinstance(value, bool):
        return False
    if isinstance(value, (int, float)):
        return True
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "iuf"
    if isinstance(value, (list, tuple)):
        return all(_all_numbers(v) for v in value)
    return False


def _short(value, n: int = 60) -> str:
    s = json.dumps(value) if not isinstance(value, np.ndarray) else repr(value.tolist())
    return s if len(s) <= n else s[: n - 3] + "..."


def _check_name(j: _Json, name, key: str) -> str:
    name = j.string(name, key)
    p = PurePosixPath(name.replace("\\", "/"))
    if p.is_absolute() or ".." in p.parts or ":" in name:
        j.fail(key, f"file name {name!r} must be a path relative to the folder of {j.path.name}, inside it")
    return name


def _write_json(path: Path, doc: dict) -> Path:
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


# ----------------------------------------------------------------------------- Capture
@dataclass
class Capture:
    """A capture folder: photographs of an object under free-form lights, plus metadata.

    Attributes
    ----------
    folder : pathlib.Path
    image_names : list of str
        As listed in ``capture.json`` (relative to ``folder``).
    image_paths : list of pathlib.Path
    encoding : str or dict
        ``'srgb'``, ``'linear'``, ``{'gamma': g}``, ``{'response': file}`` or ``'auto'`` (absent
        in the file: linear for floating-point images, unknown for integer ones; see the module
        docstring).
    K : (3, 3) float64 ndarray or None
        Camera intrinsics (None when the file has no ``camera``).
    dist : (k,) float64 ndarray
        OpenCV distortion coefficients (zeros when absent).
    world_from_camera : (4, 4) float64 ndarray
        Rigid transform; ``conventions.DEFAULT_WORLD_FROM_CAMERA`` when absent.
    world_from_camera_is_default : bool
        True when ``world_from_camera`` was not given.
    sphere_radius : float or None
        Radius of the calibration spheres in world units.
    scene_center : (3,) float64 ndarray
        World origin of the light directions (zeros when absent).
    hemisphere : ffls.conventions.Hemisphere
        ``'upper'`` (default), ``'full'`` or ``{"axis": [x, y, z]}`` in the file; compares equal
        to those forms.
    camera_model : {'pinhole', 'orthographic'}
        ``camera.model``; an orthographic camera has parallel rays along its +z and no ``K``
        (:func:`ffls.camera.projection.camera_rays`).
    spheres : list of dict
        Sphere hints: ``{'center': [x, y, z]}`` or ``{'center_px': [u, v]}`` with an optional
        ``'radius_px'`` (both forms in one hint must agree).
    sphere_count : int or None
        How many calibration spheres the images show (``sphere_count``); None: every sphere
        detection finds (:func:`ffls.spheres.detect.find_spheres`).
    image_size : (int, int) or None
        Expected (width, height) of every image, checked when images are read.
    units : str or None
    response : (256, 3) float64 ndarray or None
        Inverse camera response: linear value of each 8-bit code, per channel ((65536, 3) for a
        curve calibrated on 16-bit files, :func:`record_response`).
    extra : dict
        Unknown top-level keys, kept for round trips.
    """

    folder: Path
    image_names: list
    image_paths: list = field(default_factory=list)
    encoding: object = "auto"
    K: np.ndarray | None = None
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    world_from_camera: np.ndarray = field(default_factory=lambda: conventions.DEFAULT_WORLD_FROM_CAMERA.copy())
    world_from_camera_is_default: bool = True
    sphere_radius: float | None = None
    scene_center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    hemisphere: object = "upper"
    spheres: list = field(default_factory=list)
    image_size: tuple | None = None
    units: str | None = None
    response: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    camera_model: str = "pinhole"
    sphere_count: int | None = None

    def __post_init__(self):
        self.folder = Path(self.folder)
        self.hemisphere = conventions.as_hemisphere(self.hemisphere)
        if self.camera_model not in conventions.CAMERA_MODELS:
            raise ValueError(f"camera_model must be one of {conventions.CAMERA_MODELS}, not {self.camera_model!r}")
        self.image_names = list(self.image_names)
        if not self.image_paths:
            self.image_paths = [self.folder / n for n in self.image_names]

    @property
    def json_path(self) -> Path:
        """``folder / 'capture.json'``."""
        return self.folder / CAPTURE_FILE

    def __len__(self) -> int:
        return len(self.image_names)

    def to_json(self) -> dict:
        """The ``capture.json`` document of this capture."""
        doc: dict = {"format": "ffls-capture", "version": 1, "images": list(self.image_names)}
        if self.image_size is not None:
            doc["image_size"] = [int(self.image_size[0]), int(self.image_size[1])]
        if self.encoding != "auto":
            doc["encoding"] = self.encoding
        cam = {}
        if self.camera_model != "pinhole":
            cam["model"] = self.camera_model
        if self.K is not None:
            cam.update({"K": np.asarray(self.K).tolist(), "dist": np.asarray(self.dist).tolist()})
        if not self.world_from_camera_is_default:
            cam["world_from_camera"] = np.asarray(self.world_from_camera).tolist()
        if cam:
            doc["camera"] = cam
        if self.sphere_radius is not None:
            doc["sphere_radius"] = float(self.sphere_radius)
        if self.spheres:
            doc["spheres"] = [dict(s) for s in self.spheres]
        if self.sphere_count is not None:
            doc["sphere_count"] = int(self.sphere_count)
        if np.any(self.scene_center != 0):
            doc["scene_center"] = np.asarray(self.scene_center, dtype=float).tolist()
        doc["hemisphere"] = conventions.as_hemisphere(self.hemisphere).to_json()
        if self.units is not None:
            doc["units"] = self.units
        doc.update(self.extra)
        return doc


def _parse_gamma(j: _Json, value, key: str) -> float:
    g = j.number(value, key, positive=True)
    if not GAMMA_RANGE[0] <= g <= GAMMA_RANGE[1]:
        j.fail(key, f"gamma must be between {GAMMA_RANGE[0]} and {GAMMA_RANGE[1]}, got {g:g}")
    return g


def _parse_encoding(j: _Json, doc: dict, folder: Path) -> tuple:
    """``doc["encoding"]``: (encoding, response table or None); ``'auto'`` when absent."""
    encoding = doc.get("encoding", "auto")
    response = None
    if isinstance(encoding, dict) and set(encoding) == {"gamma"}:
        encoding = {"gamma": _parse_gamma(j, encoding["gamma"], "encoding.gamma")}
    elif isinstance(encoding, dict):
        if set(encoding) != {"response"}:
            j.fail("encoding", f"expected {_ENCODING_FORMS}")
        rname = _check_name(j, encoding["response"], "encoding.response")
        if not (folder / rname).is_file():
            j.fail("encoding.response", f"response file {rname!r} not found")
        response = load_response(folder / rname).astype(np.float64)
        encoding = {"response": rname}
    elif "encoding" in doc and encoding not in _ENCODINGS:
        j.fail("encoding", f"expected {_ENCODING_FORMS}, got {_short(encoding)}")
    return encoding, response


#: A lens may move an image corner at most this factor nearer to or farther from the principal
#: point (:func:`distortion_problem`). A lens that OpenCV's pinhole model describes stays well
#: inside it; a fisheye (over 180 degrees) is not such a lens at all.
MAX_DISTORTION_SCALE = 4.0


def distortion_problem(K, dist, image_size=None, samples: int = 512) -> str | None:
    """Why OpenCV distortion coefficients ``dist`` cannot be a lens's over the image, or None.

    The photo's pixels are distorted positions; undistorting one inverts the model along its
    ray from the principal point. That inverse exists over the image only when the distorted
    radius grows monotonically with the undistorted one until it reaches the image's farthest
    corner, and a plausible lens gets there with a radial scale (distorted / undistorted radius)
    within [1 / MAX_DISTORTION_SCALE, MAX_DISTORTION_SCALE]. Checked along 16 rays of
    ``samples`` steps each with OpenCV's own model (``cv2.projectPoints``).

    Parameters
    ----------
    K : (3, 3) float
    dist : (k,) float, finite
    image_size : (width, height) or None
        None: the image is taken to be centred on the principal point (2 cx + 1 by 2 cy + 1).
    """
    import cv2

    K = np.asarray(K, np.float64)
    d = np.asarray(dist, np.float64).ravel()
    if not np.any(d):
        return None
    w, h = image_size if image_size is not None else (2 * K[0, 2] + 1, 2 * K[1, 2] + 1)
    corners = np.array([[-0.5, -0.5, 1], [w - 0.5, -0.5, 1], [-0.5, h - 0.5, 1], [w - 0.5, h - 0.5, 1]])
    rd_max = float(np.max(np.linalg.norm((np.linalg.solve(K, corners.T).T)[:, :2], axis=1)))
    if not rd_max > 0:
        return None
    r = np.linspace(0.0, MAX_DISTORTION_SCALE * rd_max, samples)[1:]
    a = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
    pts = np.stack([np.outer(np.cos(a), r), np.outer(np.sin(a), r), np.ones((a.size, r.size))], axis=-1)
    with np.errstate(all="ignore"):
        try:
            xy, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), np.eye(3), d)
        except cv2.error:
            return f"not OpenCV distortion coefficients ({len(d)} numbers)"
        rho = np.linalg.norm(xy.reshape(a.size, r.size, 2), axis=-1)
    for rho_ray in rho:
        if not np.all(np.isfinite(rho_ray)):
            return "the distorted positions overflow over the image"
        reach = np.nonzero(rho_ray >= rd_max)[0]
        end = reach[0] if reach.size else rho_ray.size - 1
        if np.any(np.diff(rho_ray[: end + 1]) <= 0):
            return (f"the distortion is not monotonic over the image (the distorted radius stops growing at "
                    f"{rho_ray[np.argmax(np.diff(rho_ray) <= 0)]:.3g} of the corners' {rd_max:.3g}, in normalised "
                    "units): no lens maps its image this way")
        scale = rd_max / r[end]
        if not reach.size or not 1 / MAX_DISTORTION_SCALE <= scale <= MAX_DISTORTION_SCALE:
            return (f"scales the image corners' distance from the principal point by "
                    f"{f'{scale:.3g}' if reach.size else f'less than {1 / MAX_DISTORTION_SCALE:g}'}, outside "
                    f"[{1 / MAX_DISTORTION_SCALE:g}, {MAX_DISTORTION_SCALE:g}]: no lens does")
    return None


def _parse_camera(j: _Json, cam, image_size=None) -> tuple:
    if not isinstance(cam, dict):
        j.fail("camera", f"expected an object, got {_short(cam)}")
    K = None
    dist = np.zeros(5)
    if "K" in cam:
        K = j.array(cam["K"], "camera.K", (3, 3), max_abs=MAX_FOCAL_PX)
        if not (K[0, 0] > 0 and K[1, 1] > 0 and np.allclose(K[2], [0, 0, 1])):
            j.fail("camera.K", "expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
        if not 1.0 / MAX_PIXEL_ASPECT <= K[0, 0] / K[1, 1] <= MAX_PIXEL_ASPECT:
            j.fail("camera.K", f"fx / fy = {K[0, 0] / K[1, 1]:.6g}: pixels that far from square are no camera's "
                               f"(an anamorphic lens squeezes 2x; at most {MAX_PIXEL_ASPECT:g} is taken)")
    elif "dist" in cam:
        j.fail("camera.K", "missing key (camera.dist is given)")
    if "dist" in cam:
        d = cam["dist"]
        n = len(d) if isinstance(d, list) else -1
        if n not in _DIST_LENGTHS:
            j.fail("camera.dist", f"expected a list of {', '.join(map(str, _DIST_LENGTHS))} numbers (OpenCV), got {_short(d)}")
        dist = j.array(d, "camera.dist", (n,))
        if K is not None:
            why = distortion_problem(K, dist, image_size)
            if why:
                j.fail("camera.dist", why)
    wfc = conventions.DEFAULT_WORLD_FROM_CAMERA.copy()
    default = True
    if "world_from_camera" in cam:
        wfc = _rigid(j, cam["world_from_camera"], "camera.world_from_camera")
        default = False
    unknown = set(cam) - {"K", "dist", "world_from_camera", "model"}
    if unknown:
        j.fail("camera", f"unknown key {sorted(unknown)[0]!r}")
    model = cam.get("model", "pinhole")
    if model not in conventions.CAMERA_MODELS:
        j.fail("camera.model", f"expected one of {conventions.CAMERA_MODELS}, got {_short(model)}")
    if model == "orthographic" and ("K" in cam or "dist" in cam):
        j.fail("camera", f"an orthographic camera has no {'K' if 'K' in cam else 'dist'} (parallel rays need no "
                         "focal length); remove it, or use \"model\": \"pinhole\"")
    return K, dist, wfc, default, model


def _rigid(j: _Json, value, key: str) -> np.ndarray:
    """``value`` as a 4x4 rigid transform; a rotation block within :data:`ROTATION_TOLERANCE` of a
    rotation (typed to 3 decimals) is replaced by its nearest rotation, ``U V^T`` of its SVD (the
    orthogonal Procrustes solution; its determinant is then 1, the block's being positive). A block
    within :data:`ROTATION_ROUNDING` (a rotation to float64 rounding, a renderer's pose) is used as
    given: the SVD's own rounding moved the probe benchmarks' exact pose by 1.1e-16, which changed
    ``benchmarks/probes_power_split.py``'s rows (``docs/probes.md``)."""
    T = j.array(value, key, (4, 4))
    if not np.allclose(T[3], [0, 0, 0, 1]):
        j.fail(key, f"not a rigid transform: its last row must be 0 0 0 1, got {_short(T[3].tolist())}")
    R = T[:3, :3]
    det = np.linalg.det(R)
    if not det > 0:
        j.fail(key, f"not a rigid transform: its rotation block has determinant {det:.3g} (a rotation's is 1; "
                    "a negative one mirrors the image: check the signs of its columns x right, y down, z forward)")
    dev = max(float(np.abs(R @ R.T - np.eye(3)).max()), abs(det - 1.0))
    if dev > ROTATION_TOLERANCE:
        j.fail(key, f"not a rigid transform: its rotation block is {dev:.2g} from orthonormal with determinant 1 "
                    f"(tolerance {ROTATION_TOLERANCE:g}, met by a rotation written to 3 decimals)")
    if dev <= ROTATION_ROUNDING:
        return T
    T = T.copy()
    U, _, Vt = np.linalg.svd(R)
    T[:3, :3] = U @ Vt
    return T


#: The keys of ``lights.json``'s ``frame`` record (others are kept and ignored, a near miss refused).
_FRAME_KEYS = {"world_from_camera", "source", "tilt_uncertainty_deg"}


def _frame_pose(j: _Json, value) -> np.ndarray:
    """``frame.world_from_camera`` (:func:`_rigid`), its translation within a distance a float holds.

    Only its rotation turns the lights, but a translation whose squared length overflows (1e308)
    places the camera beyond any distance: no frame a tool wrote (a fitted frame's camera is at
    the origin), so it is refused rather than carried into the next file."""
    T = _rigid(j, value, "frame.world_from_camera")
    with np.errstate(over="ignore"):
        far = not np.isfinite(np.dot(T[:3, 3], T[:3, 3]))
    if far:
        j.fail("frame.world_from_camera", f"its translation {_short(T[:3, 3].tolist())} puts the camera at a "
                                          "distance beyond any number (a frame's camera is at its origin)")
    return T


def _parse_spheres(j: _Json, spheres, count=None) -> tuple[list, int | None]:
    """``spheres`` (hints) and ``sphere_count``: (list of hint dicts, count or None).

    A hint is ``{"center": [x, y, z]}`` (world), ``{"center_px": [u, v]}`` with an optional
    ``"radius_px"``, or both (detection checks that they agree). A count that disagrees with the
    number of hints is an error.
    """
    n = None
    if count is not None:
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            j.fail("sphere_count", f"expected a positive integer, got {_short(count)}")
        n = int(count)
    if spheres is None:
        return [], n
    if not isinstance(spheres, list):
        j.fail("spheres", f"expected a list, got {_short(spheres)}")
    out = []
    for k, s in enumerate(spheres):
        key = f"spheres[{k}]"
        if not isinstance(s, dict):
            j.fail(key, f"expected an object, got {_short(s)}")
        _check_misspelt_keys(j, s, ("center", "center_px", "radius_px", "material"), key + ".")
        if "material" in s:
            _check_material(j, s["material"], key + ".material")
        item = {}
        if "center" in s:
            item["center"] = j.array(s["center"], key + ".center", (3,)).tolist()
        if "center_px" in s:
            item["center_px"] = j.array(s["center_px"], key + ".center_px", (2,)).tolist()
            if "radius_px" in s:
                item["radius_px"] = j.number(s["radius_px"], key + ".radius_px", positive=True)
        elif "radius_px" in s:
            j.fail(key, "'radius_px' without 'center_px'")
        if not item:
            j.fail(key, "expected 'center' [x, y, z] or 'center_px' [u, v] (with an optional 'radius_px')")
        for extra_key in set(s) - {"center", "center_px", "radius_px"}:
            item[extra_key] = s[extra_key]
        out.append(item)
    if n is not None and out and n != len(out):
        j.fail("sphere_count", f"is {n} but 'spheres' lists {len(out)} hints; hints conflict: give one hint per "
                               f"sphere, or remove sphere_count")
    return out, n


#: Sphere materials of ``capture.json`` (``"auto"``: classified from the photos).
SPHERE_MATERIALS = ("matte", "mirror", "auto")


def _material_problem(value) -> str | None:
    """What is wrong with a sphere material of ``capture.json``, or None."""
    if value not in SPHERE_MATERIALS:
        return f"expected one of {', '.join(repr(m) for m in SPHERE_MATERIALS)}, got {_short(value)}"
    return None


def _check_material(j: _Json, value, key: str) -> None:
    """A sphere material of ``capture.json`` checked where it is read (it was first looked at once the
    spheres were found, after the photos' longest step)."""
    why = _material_problem(value)
    if why:
        j.fail(key, why)


def sphere_materials(capture: Capture, n_spheres: int) -> list[str]:
    """Each sphere's declared material: ``spheres[k].material``, else ``sphere_material``, else ``'auto'``.

    ``"material"`` in a sphere hint applies to that sphere (hints keep their order); the
    capture-wide ``"sphere_material"`` to every sphere without one. ``"mirror"`` covers chrome
    and black glossy balls (the light is the highlight), ``"matte"`` diffuse ones (the light is
    the shading), ``"auto"`` is classified from the photos.

    Parameters
    ----------
    capture : Capture
    n_spheres : int
        Spheres found.

    Returns
    -------
    list of str
        One of :data:`SPHERE_MATERIALS` per sphere.

    Raises
    ------
    InputError
        An unknown material, or per-sphere materials for a different number of spheres than found.
    """
    path = capture.json_path

    def check(value, key):
        why = _material_problem(value)
        if why:
            raise InputError(f"{key}: {why}", path)
        return value

    default = check(capture.extra.get("sphere_material", "auto"), "sphere_material")
    per = [(k, h["material"]) for k, h in enumerate(capture.spheres or []) if isinstance(h, dict) and "material" in h]
    for k, m in per:
        check(m, f"spheres[{k}].material")
    if per and len(capture.spheres) != int(n_spheres):
        raise InputError(f"spheres[].material is given for {len(capture.spheres)} hinted spheres but "
                         f"{n_spheres} were found; give a hint (with its material) for every sphere, or use "
                         f"\"sphere_material\" for all", path)
    out = [default] * int(n_spheres)
    for k, m in per:
        out[k] = m
    return out


def _check_image_headers(names: list, paths: list, image_size) -> None:
    """Every photo's size and channel count from its header, before any photo is decoded.

    A photo of another size than ``image_size`` (or, without it, than the first photo) is
    refused here, where its header costs a fraction of a millisecond: decoding a 12000x12000 PNG
    to find its size took 7 s and 2.6 GB. A capture that mixes grey (one-channel) and colour
    photos is refused too: a grey photo would be replicated to RGB, a colourless light among
    coloured ones, and such a mix is almost always a wrong export. The minority is named. So is
    a capture mixing 8-bit and 16-bit photos, whatever its encoding (a camera's JPEGs and a raw
    converter's exports carry different tone curves).
    Headers that cannot be read here are left to the decoder (:func:`ffls.io.images.image_header`).

    Photos are read as image viewers show them, turned by their EXIF orientation; a capture whose
    photos state different orientations is refused, naming the minority. The photos of one fixed
    camera share their pixel grid, and a camera that looks down (at a turntable, a table top)
    tags its shots upright or turned as its tilt sensor wavers: turning some would misalign them.
    """
    from ffls.io.images import (ORIENTATION_NAMES, check_one_bit_depth, check_one_colour_kind, check_one_orientation,
                                image_header)

    heads = [image_header(p) for p in paths]
    ref = None if image_size is None else (tuple(image_size), f"{CAPTURE_FILE} says image_size")
    for n, p, h in zip(names, paths, heads):
        if h is None:
            continue
        if ref is None:
            ref = ((h.width, h.height), f"the first image {n!r} is")
        elif (h.width, h.height) != ref[0]:
            turned = (f" (as shown: its EXIF orientation {h.orientation}, {ORIENTATION_NAMES[h.orientation]}, turns "
                      f"the stored {h.height}x{h.width}; docs/formats.md)") if h.orientation >= 5 else ""
            raise InputError(f"image is {h.width}x{h.height} but {ref[1]} {ref[0][0]}x{ref[0][1]}{turned}", p)
    check_one_colour_kind(paths, names, heads, what="photos", whole="a capture")
    check_one_bit_depth(paths, names, heads, what="photos", whole="a capture")
    check_one_orientation(paths, names, heads)


def load_capture(folder: str | os.PathLike) -> Capture:
    """Load and validate a capture folder.

    Parameters
    ----------
    folder : path-like
        Folder holding ``capture.json`` and the images it lists (``capture.json`` itself may be
        passed too).

    Returns
    -------
    Capture

    Raises
    ------
    InputError
        Missing folder or ``capture.json``, corrupt JSON, a missing key, a value of the wrong
        type or shape, an unreadable response table, or a listed image that does not exist --
        naming ``capture.json`` and the key or image.
    """
    folder, j, doc = _Json.folder_document(folder, CAPTURE_FILE, "ffls-capture", "capture")
    names = j.require(doc, "images")
    if not isinstance(names, list) or not names:
        j.fail("images", f"expected a non-empty list of file names, got {_short(names)}")
    names = [_check_name(j, n, f"images[{k}]") for k, n in enumerate(names)]
    seen = set()
    for n in names:
        if n in seen:
            j.fail("images", f"image {n!r} is listed twice")
        seen.add(n)
    paths = [folder / n for n in names]
    for n, p in zip(names, paths):
        if not p.is_file():
            special = not_a_regular_file(p)
            j.fail("images", f"listed image {n!r} is a folder, not a file" if p.is_dir()
                   else f"listed image {n!r} {special}" if special else f"listed image {n!r} not found in {folder}")
        register_input(p)  # (an output onto a photo is refused from now on, not only once it was read)

    image_size = None
    if "image_size" in doc:
        s = doc["image_size"]
        if not (isinstance(s, list) and len(s) == 2 and all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in s)):
            j.fail("image_size", f"expected [width, height] positive integers, got {_short(s)}")
        image_size = (s[0], s[1])
    _check_image_headers(names, paths, image_size)

    encoding, response = _parse_encoding(j, doc, folder)
    K, dist, wfc, wfc_default, model = (None, np.zeros(5), conventions.DEFAULT_WORLD_FROM_CAMERA.copy(), True,
                                        "pinhole")
    if "camera" in doc:
        K, dist, wfc, wfc_default, model = _parse_camera(j, doc["camera"], image_size)

    radius = None
    if "sphere_radius" in doc:
        radius = j.number(doc["sphere_radius"], "sphere_radius", positive=True)
    spheres, sphere_count = _parse_spheres(j, doc.get("spheres"), doc.get("sphere_count"))
    center = j.array(doc["scene_center"], "scene_center", (3,)) if "scene_center" in doc else np.zeros(3)
    try:
        hemisphere = conventions.as_hemisphere(doc.get("hemisphere", "upper"))
    except ValueError:
        j.fail("hemisphere", f"expected 'upper', 'full' or {{\"axis\": [x, y, z]}} (three finite numbers, not all "
                             f"zero), got {_short(doc.get('hemisphere'))}")
    units = doc.get("units")
    if units is not None and not isinstance(units, str):
        j.fail("units", f"expected a string, got {_short(units)}")
    extra = {k: v for k, v in doc.items() if k not in _CAPTURE_KEYS}
    _check_misspelt_keys(j, extra)
    if "sphere_material" in extra:
        _check_material(j, extra["sphere_material"], "sphere_material")
    return Capture(
        folder=folder, image_names=names, image_paths=paths, encoding=encoding, K=K, dist=dist,
        world_from_camera=wfc, world_from_camera_is_default=wfc_default, sphere_radius=radius,
        scene_center=center, hemisphere=hemisphere, spheres=spheres, image_size=image_size,
        units=units, response=response, extra=extra, camera_model=model, sphere_count=sphere_count,
    )


#: Top-level keys of ``capture.json`` that other readers take from ``Capture.extra`` (the viewer its ``mask``)
_EXTRA_KEYS = {"sphere_material", "truth", "mask"}


#: The keys of ``lights.json``: top level, and each light's (``ffls lights`` writes the last five)
_LIGHTS_KEYS = {"format", "version", "lights", "encoding", "uncertainty", "flat_field", "frame"}
_LIGHT_KEYS = {"image", "direction", "position", "status", "reason", "uncertainty_deg", "model", "used_spheres",
               "spheres", "chi2", "dof", "camera_tilt_deg", "camera_roll_deg", "tilt_widened_deg"}


def _check_misspelt_keys(j: _Json, keys, known=_CAPTURE_KEYS | _EXTRA_KEYS, where: str = "") -> None:
    """Refuse an unknown key that is a near miss of a ``known`` one (``"encodng"``, ``"sphere_radus"``,
    ``"Encoding"``, a light's ``"stauts"``): unknown keys are kept and ignored (docs/formats.md), so a
    misspelt one silently dropped what it stated (an unstated encoding was calibrated instead, a
    light meant ``"rejected"`` was used). ``where`` prefixes the key in the message."""
    import difflib

    known = sorted(known)
    for key in keys:
        if key in known or not isinstance(key, str) or key.startswith("x-"):
            continue
        close = difflib.get_close_matches(key, known, n=1, cutoff=0.8)
        if close:
            j.fail(where + key, f"unknown key; did you mean {close[0]!r}? (an unknown key is kept but ignored, so "
                                "what it states would be dropped; name a key of your own with an 'x-' prefix)")


#: How many folders up from a file :func:`capture_listing` looks for a ``capture.json`` that lists it.
CAPTURE_SEARCH_DEPTH = 3


def capture_listing(path: str | os.PathLike) -> Path | None:
    """The ``capture.json`` that lists the existing file ``path`` as one of its photos, or None.

    Looks in the file's folder and up to :data:`CAPTURE_SEARCH_DEPTH` folders above it (a
    capture may keep its photos in a subfolder). A ``capture.json`` that cannot be read is
    skipped: this only protects a capture's photos from being overwritten by an output (a
    command that has no capture among its inputs, ``ffls lightmap make``, would otherwise
    replace one), it does not check the capture.
    """
    p = Path(path)
    if not p.is_file():
        return None
    target = p.resolve()
    for folder in list(target.parents)[:CAPTURE_SEARCH_DEPTH + 1]:
        cj = folder / CAPTURE_FILE
        try:
            doc = parse_json(read_json_text(cj)) if cj.is_file() else None
        except (OSError, ValueError):
            continue
        names = doc.get("images") if isinstance(doc, dict) else None
        if isinstance(names, list) and any(isinstance(n, str) and n and (folder / n.replace("\\", "/")).resolve()
                                           == target for n in names):
            return cj
    return None


def save_capture(capture: Capture) -> Path:
    """Write ``capture.json`` into ``capture.folder`` atomically.

    Returns
    -------
    pathlib.Path
        The written ``capture.json``.
    """
    return _write_json(capture.json_path, capture.to_json())


# ----------------------------------------------------------------------------- Lights
@dataclass
class Lights:
    """Light directions estimated for (or given with) the images of a capture.

    Attributes
    ----------
    image_names : list of str
    directions : (n, 3) float64 ndarray
        Unit vectors in the world frame, from the scene centre toward the light.
    positions : (n, 3) float64 ndarray
        Light positions in world units, NaN where absent.
    status : list of {'ok', 'rejected'}
    reasons : list of str or None
        Why a light was rejected (None for accepted ones).
    extra : list of dict
        Other per-light keys (e.g. ``uncertainty_deg``), kept for round trips.
    note : str or None
        How the lights were matched to a capture's images when that is worth saying (by order,
        or by a name map; see :func:`load_lights_any`); not written to ``lights.json``.
    encoding : dict or None
        The encoding that ``ffls lights`` calibrated from the spheres (the top-level
        ``"encoding"`` record of ``lights.json``, ``docs/formats.md``): ``curve`` (``'linear'``,
        ``'srgb'`` or ``'gamma'``), ``gamma``, ``uncertainty`` (95% half-width of the gamma),
        ``method``, ``spheres``, ``photos``, and any other keys kept. None when the encoding was
        stated in ``capture.json`` or the images are floating point.
        :func:`encoding_from_record` gives the ``Capture.encoding`` it stands for.
    path : pathlib.Path or None
        The file the lights were read from (:func:`load_capture_and_lights`), named in errors
        about them (e.g. no light has status ok); not written.
    uncertainty : dict or None
        How ``ffls lights`` sized the cones (the top-level ``"uncertainty"`` record of
        ``lights.json``: :meth:`ffls.spheres.uncertainty.ErrorModel.as_dict`, e.g. ``cone_factor``,
        ``n_tail``, ``scale``, ``floor_deg``, ``source``); kept as read, None when absent.
    flat_field : dict or None
        The lens's fall-off that ``ffls lights`` fitted over the spheres (the top-level
        ``"flat_field"`` record: :meth:`ffls.spheres.estimate.FlatField.as_dict`, e.g. ``strength``,
        ``p``, ``applied``, and per sphere its ``gradients`` and freely ``measured`` gradients);
        kept as read, None when absent.
    frame : dict or None
        The world frame of the directions where it is not the capture's (the top-level ``"frame"``
        record): ``world_from_camera`` ((4, 4) float64, the camera's pose in that frame) and
        ``source`` (str, e.g. ``'camera tilt fitted to the spheres' shading'``). ``ffls lights``
        writes it for a capture without ``camera.world_from_camera`` whose camera's tilt it fitted:
        the lights are then in the scene's frame (+Z the ground's normal), not the image's. None:
        the capture's frame.
    """

    image_names: list
    directions: np.ndarray
    positions: np.ndarray | None = None
    status: list | None = None
    reasons: list | None = None
    extra: list | None = None
    note: str | None = field(default=None, compare=False)
    encoding: dict | None = None
    path: Path | None = field(default=None, compare=False)
    uncertainty: dict | None = None
    flat_field: dict | None = None
    frame: dict | None = None

    def __post_init__(self):
        if self.encoding is not None:
            encoding_from_record(self.encoding)  # ValueError for a malformed record
            self.encoding = dict(self.encoding)
        n = len(self.image_names)
        self.image_names = list(self.image_names)
        self.directions = np.asarray(self.directions, dtype=np.float64).reshape(n, 3)
        self.positions = (np.full((n, 3), np.nan) if self.positions is None
                          else np.asarray(self.positions, dtype=np.float64).reshape(n, 3))
        self.status = ["ok"] * n if self.status is None else list(self.status)
        self.reasons = [None] * n if self.reasons is None else list(self.reasons)
        self.extra = [{} for _ in range(n)] if self.extra is None else [dict(e) for e in self.extra]
        for e in self.extra:
            cap_cones(e)
        if not (len(self.status) == len(self.reasons) == len(self.extra) == n):
            raise ValueError("Lights: image_names, status, reasons and extra must have the same length")
        bad = [s for s in self.status if s not in ("ok", "rejected")]
        if bad:
            raise ValueError(f"Lights: status must be 'ok' or 'rejected', not {bad[0]!r}")

    def __len__(self) -> int:
        return len(self.image_names)

    @property
    def ok_mask(self) -> np.ndarray:
        """(n,) bool: True for accepted lights."""
        return np.array([s == "ok" for s in self.status], dtype=bool)

    def accepted(self) -> tuple[np.ndarray, np.ndarray]:
        """Indices (k,) int and directions (k, 3) float64 of the accepted lights."""
        idx = np.flatnonzero(self.ok_mask)
        return idx, self.directions[idx]

    def cones_deg(self, idx) -> np.ndarray:
        """The 95% cone radii (deg) of the lights ``idx``, (k,) float64: NaN where a light has none."""
        c = [self.extra[i].get("uncertainty_deg") for i in np.asarray(idx, dtype=np.int64).ravel()]
        return np.array([np.nan if v is None else float(v) for v in c], dtype=np.float64)

    def to_json(self) -> dict:
        """The ``lights.json`` document."""
        lights = []
        for i, name in enumerate(self.image_names):
            item = {"image": name, "direction": [float(v) for v in self.directions[i]]}
            if np.all(np.isfinite(self.positions[i])):
                item["position"] = [float(v) for v in self.positions[i]]
            item["status"] = self.status[i]
            if self.reasons[i] is not None:
                item["reason"] = self.reasons[i]
            item.update(self.extra[i])
            lights.append(item)
        doc = {"format": "ffls-lights", "version": 1}
        if self.encoding is not None:
            doc["encoding"] = dict(self.encoding)
        if self.uncertainty is not None:
            doc["uncertainty"] = dict(self.uncertainty)
        if self.flat_field is not None:
            doc["flat_field"] = dict(self.flat_field)
        if self.frame is not None:
            doc["frame"] = {**self.frame, "world_from_camera": np.asarray(self.frame["world_from_camera"]).tolist()}
        doc["lights"] = lights
        return doc


def cap_cones(item: dict) -> None:
    """A light's cones, its own and its spheres', at most ``MAX_CONE_DEG`` (in place; the spheres'
    list is copied): a fit that knows little of a direction has a cone wider than the sphere (a
    sphere's reached 1617 deg on the bench), which means the same and which ``load_lights`` refuses.
    ``Lights`` caps its ``extra`` when built; a stage that widens a built one's cones caps again."""
    def capped(d):
        wide = isinstance(d, dict) and isinstance(d.get("uncertainty_deg"), float) \
            and d["uncertainty_deg"] > conventions.MAX_CONE_DEG
        return {**d, "uncertainty_deg": conventions.MAX_CONE_DEG} if wide else d

    item.update(capped(item))
    if isinstance(item.get("spheres"), list):
        item["spheres"] = [capped(s) for s in item["spheres"]]


ENCODING_CURVES = ("linear", "srgb", "gamma", "polynomial")
#: ``Capture.encoding`` of a capture linearised with a calibrated ``"polynomial"`` curve: its table
#: (:func:`ffls.io.response.polynomial_response_table`) is ``Capture.response``.
CALIBRATED_RESPONSE = {"response": "lights.json:polynomial"}


def encoding_from_record(record: dict):
    """The ``Capture.encoding`` that a ``lights.json`` ``"encoding"`` record stands for.

    Parameters
    ----------
    record : dict
        ``{"curve": "linear" | "srgb" | "gamma", "gamma": g, ...}`` (:attr:`Lights.encoding`).

    Returns
    -------
    str or dict
        ``'linear'``, ``'srgb'``, ``{'gamma': g}`` or, for a ``"polynomial"`` curve (its
        ``"coefficients"``: :func:`ffls.io.response.polynomial_response`),
        :data:`CALIBRATED_RESPONSE`, whose table :func:`record_response` gives.

    Raises
    ------
    ValueError
        Not a dict, an unknown ``curve``, a ``gamma`` curve without a finite gamma in
        :data:`GAMMA_RANGE`, or a ``polynomial`` curve whose coefficients are not 2 to 6 finite
        numbers making an increasing curve.
    """
    if not isinstance(record, dict):
        raise ValueError(f"expected an object, got {_short(record)}")
    _check_naming_keys(record)
    curve = record.get("curve")
    if curve not in ENCODING_CURVES:
        raise ValueError(f"curve must be one of {ENCODING_CURVES}, got {_short(curve)}")
    if curve == "polynomial":
        record_response(record)  # ValueError when malformed
        return dict(CALIBRATED_RESPONSE)
    if curve != "gamma":
        return curve
    g = record.get("gamma")
    if not _finite_number(g) or not GAMMA_RANGE[0] <= g <= GAMMA_RANGE[1]:
        raise ValueError(f"gamma must be a number between {GAMMA_RANGE[0]} and {GAMMA_RANGE[1]}, got {_short(g)}")
    return {"gamma": float(g)}


#: What named a calibrated curve (the encoding record's ``"naming"``, ``docs/formats.md``).
ENCODING_NAMINGS = ("bic", "half_code", "shown_codes", "dark_sides")


def _finite_number(v) -> bool:
    """A JSON number that is finite (not a bool, a string, NaN or infinity)."""
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


def _check_naming_keys(record: dict) -> None:
    """The naming keys of an encoding record, where present: ``naming``, ``shown_codes``,
    ``dark_srgb_excess``, ``dark_bic_penalty`` (ValueError naming the key)."""
    if "naming" in record and record["naming"] not in ENCODING_NAMINGS:
        raise ValueError(f"naming must be one of {ENCODING_NAMINGS}, got {_short(record['naming'])}")
    if "shown_codes" in record:
        c = record["shown_codes"]
        if not (isinstance(c, list) and len(c) == 2 and all(_finite_number(v) for v in c)
                and 0.0 <= c[0] <= c[1] <= 1.0):
            raise ValueError(f"shown_codes must be [lo, hi] with 0 <= lo <= hi <= 1, got {_short(c)}")
    if "dark_srgb_excess" in record and not _finite_number(record["dark_srgb_excess"]):
        raise ValueError(f"dark_srgb_excess must be a finite number, got {_short(record['dark_srgb_excess'])}")
    if "dark_bic_penalty" in record and not (_finite_number(record["dark_bic_penalty"])
                                             and record["dark_bic_penalty"] >= 0):
        raise ValueError(f"dark_bic_penalty must be a number >= 0, got {_short(record['dark_bic_penalty'])}")


def record_response(record: dict) -> np.ndarray | None:
    """The inverse response table of a ``"polynomial"`` encoding record, (256, 3), or (65536, 3) when its
    ``"bits"`` is 16; None for other curves.

    Raises
    ------
    ValueError
        ``"coefficients"`` not a list of 2 to 6 finite numbers, or a curve not increasing over
        the 8-bit codes.
    """
    if not isinstance(record, dict) or record.get("curve") != "polynomial":
        return None
    c = record.get("coefficients")
    if not isinstance(c, list) or not 2 <= len(c) <= 6 or not all(_finite_number(v) for v in c):
        raise ValueError(f"coefficients must be a list of 2 to 6 numbers (g, a_1, ...), got {_short(c)}")
    bits = record.get("bits", 8)  # the files' bit depth the curve was calibrated on: the table's rows
    if bits not in (8, 16) or isinstance(bits, bool):
        raise ValueError(f"bits must be 8 or 16, got {_short(bits)}")
    if "dark_sides" in record and not isinstance(record["dark_sides"], bool):
        raise ValueError(f"dark_sides must be true or false, got {_short(record['dark_sides'])}")
    return polynomial_response_table(c, bits)


def _order_to_capture(j: _Json, names: list, capture: Capture) -> np.ndarray:
    known = set(capture.image_names)
    for n in names:
        if n not in known:
            j.fail("lights", f"image {n!r} is not in the capture's {CAPTURE_FILE}")
    have = set(names)
    for n in capture.image_names:
        if n not in have:
            j.fail("lights", f"capture image {n!r} has no light")
    pos = {n: k for k, n in enumerate(names)}
    return np.array([pos[n] for n in capture.image_names], dtype=np.intp)


#: How far (deg) a light's ``position``, seen from the scene centre, may lie from its ``direction``:
#: ffls writes them within 1e-6 deg; a hand-typed file rounded to 3 decimals is within 0.1 deg
POSITION_DIRECTION_TOLERANCE_DEG = 0.5


def _check_position_on_direction(j: _Json, key: str, position, direction, scene_center) -> None:
    """Refuse a light whose ``position`` does not lie along its ``direction`` from the scene centre."""
    v = np.asarray(position, dtype=np.float64) - np.asarray(scene_center, dtype=np.float64)
    dist = float(np.linalg.norm(v))
    if dist == 0.0:
        j.fail(key + ": position", "the position is the scene centre, which has no direction")
    angle = float(np.degrees(conventions.angle_between(v, np.asarray(direction, dtype=np.float64))))
    if angle > POSITION_DIRECTION_TOLERANCE_DEG:
        seen = (v / dist).round(4).tolist()
        j.fail(key + ": position", f"seen from the scene centre it lies {angle:.2f} deg off the light's "
                                   f"direction (along {seen}; at most {POSITION_DIRECTION_TOLERANCE_DEG:g} "
                                   "deg): direction and position disagree (another frame, or a typo?)")


def load_lights(path: str | os.PathLike, capture: Capture | None = None, *,
                scene_center=None) -> Lights:
    """Load and validate a ``lights.json`` file.

    Parameters
    ----------
    path : path-like
        The ``lights.json`` file.
    capture : Capture, optional
        When given, the light images must be exactly the capture's images, and the result is
        reordered to the capture's image order (light ``i`` belongs to image ``i``).
    scene_center : (3,) float, optional
        The world point the directions are measured from (default: the capture's, else the
        origin): a light's ``position`` must lie along its ``direction`` from it.

    Returns
    -------
    Lights
        Directions renormalised to exact unit length.

    Raises
    ------
    InputError
        Corrupt JSON, missing keys, non-finite numbers, a direction that is not unit (within
        ``UNIT_TOLERANCE``; the message gives the image and the norm), duplicate images, or
        images that do not match the capture (naming the first one), a ``position`` off its
        ``direction`` by more than ``POSITION_DIRECTION_TOLERANCE_DEG``.
    """
    path = Path(path)
    if scene_center is None:
        scene_center = capture.scene_center if capture is not None else np.zeros(3)
    j = _Json(path)
    doc = j.load("lights.json")
    j.header(doc, "ffls-lights")
    _check_misspelt_keys(j, doc, _LIGHTS_KEYS)
    items = j.require(doc, "lights")
    if not isinstance(items, list) or not items:
        j.fail("lights", f"expected a non-empty list, got {_short(items)}")
    names, dirs, pos, status, reasons, extra = [], [], [], [], [], []
    for k, it in enumerate(items):
        key = f"lights[{k}]"
        if not isinstance(it, dict):
            j.fail(key, f"expected an object, got {_short(it)}")
        _check_misspelt_keys(j, it, _LIGHT_KEYS, key + ".")
        name = j.string(j.require(it, "image", key + "."), key + ".image")
        if name in names:
            j.fail(key + ".image", f"image {name!r} has two lights")
        key = f"light for {name!r}"
        d = j.direction(j.require(it, "direction", key + ": "), key + ": direction")
        norm = 1.0
        p = j.array(it["position"], key + ": position", (3,)) if "position" in it else np.full(3, np.nan)
        st = it.get("status", "ok")
        if st not in ("ok", "rejected"):
            j.fail(key, f"status must be 'ok' or 'rejected', got {_short(st)}")
        reason = it.get("reason")
        if st == "rejected" and not isinstance(reason, str):
            j.fail(key, "a rejected light needs a 'reason' string")
        if reason is not None and not isinstance(reason, str):
            j.fail(key, f"reason must be a string, got {_short(reason)}")
        ex = {kk: v for kk, v in it.items() if kk not in ("image", "direction", "position", "status", "reason")}
        if ex.get("uncertainty_deg") is not None:  # null: a rejected light has none
            ex["uncertainty_deg"] = j.number(ex["uncertainty_deg"], key + ": uncertainty_deg")
            if not 0 <= ex["uncertainty_deg"] <= conventions.MAX_CONE_DEG:
                j.fail(key + ": uncertainty_deg", f"a 95% cone's radius is between 0 and "
                                                  f"{conventions.MAX_CONE_DEG:g} deg, got {ex['uncertainty_deg']:g}")
        model = ex.get("model")
        if model is not None and model not in conventions.LIGHT_MODELS:
            j.fail(key + ": model", f"expected one of {conventions.LIGHT_MODELS} (or null), got {_short(model)}")
        if model is not None and (model == "near") != ("position" in it):
            j.fail(key + ": model", "a near light needs a position" if model == "near" else
                   "a distant light has no position (a light with one is taken as near): drop the position "
                   "or say \"model\": \"near\"")
        if "position" in it:
            _check_position_on_direction(j, key, p, d, scene_center)
        # (a tilt past 90 looks down and back: conventions.TILT_REACH_DEG)
        for angle, what, (low, high) in (("camera_tilt_deg", "tilt", conventions.TILT_REACH_DEG),
                                         ("camera_roll_deg", "roll", (-180, 180))):
            if ex.get(angle) is not None:
                ex[angle] = j.number(ex[angle], f"{key}: {angle}")
                if not low <= ex[angle] <= high:
                    j.fail(f"{key}: {angle}", f"a camera's {what} is between {low:g} and {high:g} deg, got "
                                              f"{ex[angle]:g}")
        names.append(name)
        dirs.append(d / norm)
        pos.append(p)
        status.append(st)
        reasons.append(reason)
        extra.append(ex)
    record = doc.get("encoding")
    if record is not None:
        try:
            encoding_from_record(record)
        except ValueError as e:
            j.fail("encoding", str(e))
    uncertainty = doc.get("uncertainty")
    if "uncertainty" in doc and not isinstance(uncertainty, dict):
        j.fail("uncertainty", f"expected an object, got {_short(uncertainty)}")
    flat = doc.get("flat_field")
    if "flat_field" in doc and not isinstance(flat, dict):
        j.fail("flat_field", f"expected an object, got {_short(flat)}")
    frame = doc.get("frame")
    if "frame" in doc:
        if not isinstance(frame, dict):
            j.fail("frame", f"expected an object, got {_short(frame)}")
        frame = {**frame, "world_from_camera": _frame_pose(j, j.require(frame, "world_from_camera", "frame: "))}
        _check_misspelt_keys(j, frame, _FRAME_KEYS, "frame.")
        if "source" in frame:
            j.string(frame["source"], "frame.source")
        if frame.get("tilt_uncertainty_deg") is not None:  # (null: not measured; float() by the cones' widening)
            e = j.number(frame["tilt_uncertainty_deg"], "frame.tilt_uncertainty_deg")
            if not 0 <= e <= 180:
                j.fail("frame.tilt_uncertainty_deg", f"expected an angle in degrees from 0 to 180, got {e!r}")
    order = np.arange(len(names)) if capture is None else _order_to_capture(j, names, capture)
    return Lights(
        encoding=record,
        uncertainty=uncertainty,
        flat_field=flat,
        frame=frame,
        image_names=[names[i] for i in order],
        directions=np.array(dirs)[order],
        positions=np.array(pos)[order],
        status=[status[i] for i in order],
        reasons=[reasons[i] for i in order],
        extra=[extra[i] for i in order],
    )


def save_lights(lights: Lights, path: str | os.PathLike) -> Path:
    """Write ``lights.json`` atomically.

    Raises
    ------
    ValueError
        Non-finite or non-unit directions, or rejected lights without a reason (the file would
        not load back).
    """
    d = np.asarray(lights.directions, dtype=np.float64)
    if not np.all(np.isfinite(d)):
        raise ValueError("save_lights: non-finite directions")
    norms = np.linalg.norm(d, axis=1)
    if np.any(np.abs(norms - 1) > UNIT_TOLERANCE):
        i = int(np.argmax(np.abs(norms - 1)))
        raise ValueError(f"save_lights: direction of {lights.image_names[i]!r} has norm {norms[i]:.6g}")
    for name, st, r in zip(lights.image_names, lights.status, lights.reasons):
        if st == "rejected" and not isinstance(r, str):
            raise ValueError(f"save_lights: rejected light {name!r} needs a reason")
    return _write_json(Path(path), lights.to_json())


# ----------------------------------------------------------------------------- RTI .lp files
#: Camera (OpenCV: x right, y down, z forward) from the RTI .lp frame (x right, y up, z toward the camera).
_CAM_FROM_LP = np.diag([1.0, -1.0, -1.0])


def lp_to_world(directions, world_from_camera=None) -> np.ndarray:
    """Convert RTI ``.lp`` directions to the ffls world frame.

    The ``.lp`` frame is the image's: x right, y up, z toward the camera. In OpenCV camera
    coordinates (x right, y down, z forward) that is ``(x, -y, -z)``; the rotation block of
    ``world_from_camera`` then takes it to the world.

    Parameters
    ----------
    directions : (n, 3) array_like
        Directions in the ``.lp`` frame.
    world_from_camera : (4, 4) array_like, optional
        Defaults to ``conventions.DEFAULT_WORLD_FROM_CAMERA`` (then .lp z -> world -Y, y -> +Z).

    Returns
    -------
    (n, 3) float64 ndarray
    """
    wfc = conventions.DEFAULT_WORLD_FROM_CAMERA if world_from_camera is None else np.asarray(world_from_camera, dtype=np.float64)
    R = wfc[:3, :3] @ _CAM_FROM_LP
    return np.asarray(directions, dtype=np.float64) @ R.T


def world_to_lp(directions, world_from_camera=None) -> np.ndarray:
    """Inverse of :func:`lp_to_world`: world directions (n, 3) to the ``.lp`` frame."""
    wfc = conventions.DEFAULT_WORLD_FROM_CAMERA if world_from_camera is None else np.asarray(world_from_camera, dtype=np.float64)
    R = wfc[:3, :3] @ _CAM_FROM_LP
    return np.asarray(directions, dtype=np.float64) @ R  # R orthonormal: inverse is R.T


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_lp(path: str | os.PathLike) -> tuple[list, np.ndarray]:
    """Read an RTI ``.lp`` light-position file.

    Format: the first line is the number of lights n; then n lines ``filename x y z``
    (whitespace separated; a file name may contain spaces). Blank lines are ignored.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    names : list of str
        File names as written.
    directions : (n, 3) float64 ndarray
        Unit directions in the ``.lp`` frame (see :func:`lp_to_world`), renormalised.

    Raises
    ------
    InputError
        Missing file, a bad count, a count that does not match the lines, numbers that do not
        parse, or non-unit vectors (naming the line).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("is a folder, not an .lp file" if path.is_dir() else not_a_regular_file(path)
                         or ".lp file not found", path)
    register_input(path)
    try:
        lines = read_json_text(path, ".lp file").splitlines()
    except FileTooLarge as e:
        raise InputError(str(e), path) from None
    except UnicodeDecodeError:  # (a Windows tool's latin-1 names were read with U+FFFD, then missed)
        raise InputError(f"is not a text .lp file: {NOT_TEXT} (save it as UTF-8)", path) from None
    except OSError as e:
        raise InputError(f"cannot read .lp file ({e})", path) from None
    rows = [(k + 1, ln.strip()) for k, ln in enumerate(lines) if ln.strip()]
    if not rows:
        raise InputError("empty .lp file", path)
    try:
        n = int(rows[0][1])
    except ValueError:
        raise InputError(f"line {rows[0][0]}: expected the number of lights, got {rows[0][1][:40]!r}", path) from None
    if n != len(rows) - 1:
        raise InputError(f"the count on line {rows[0][0]} says {n} lights but {len(rows) - 1} follow", path)
    if n <= 0:
        raise InputError(f"the count on line {rows[0][0]} says {n} lights: an .lp file lists at least one", path)
    names, dirs, seen = [], [], {}
    for lineno, text in rows[1:]:
        parts = text.rsplit(None, 3)
        try:
            if len(parts) != 4:
                raise ValueError
            d = np.array([float(v) for v in parts[1:]])
        except ValueError:
            raise InputError(f"line {lineno}: expected 'filename x y z', got {text[:60]!r}", path) from None
        if not np.all(np.isfinite(d)):
            raise InputError(f"line {lineno}: direction of {parts[0]!r} has a component that is not a finite "
                             f"number ({' '.join(parts[1:])})", path)
        head = parts[0].rsplit(None, 1)
        if len(head) == 2 and _is_number(head[1]):  # (a file name may hold spaces, not a trailing number)
            raise InputError(f"line {lineno}: more than three numbers after the file name ({text[:60]!r}): expected "
                             "'filename x y z'", path)
        with np.errstate(over="ignore"):
            norm = float(np.linalg.norm(d))
        if abs(norm - 1) > UNIT_TOLERANCE:
            raise InputError(f"line {lineno}: direction of {parts[0]!r} is not a unit vector (norm {norm:.6g})", path)
        if parts[0] in seen:
            raise InputError(f"line {lineno}: {parts[0]!r} is listed twice (first on line {seen[parts[0]]})", path)
        seen[parts[0]] = lineno
        names.append(parts[0])
        dirs.append(d / norm)
    return names, np.array(dirs)


def write_lp(path: str | os.PathLike, names, directions) -> Path:
    """Write an RTI ``.lp`` file atomically.

    Parameters
    ----------
    path : path-like
    names : sequence of str
        Image file names (no line breaks).
    directions : (n, 3) array_like
        Unit directions in the ``.lp`` frame (see :func:`world_to_lp`).

    Returns
    -------
    pathlib.Path
    """
    names = list(names)
    d = np.asarray(directions, dtype=np.float64)
    if d.shape != (len(names), 3):
        raise ValueError(f"write_lp: directions must be ({len(names)}, 3), got {d.shape}")
    if not np.all(np.isfinite(d)) or np.any(np.abs(np.linalg.norm(d, axis=1) - 1) > UNIT_TOLERANCE):
        raise ValueError("write_lp: directions must be finite unit vectors")
    for nm in names:
        if not nm or "\n" in nm or "\r" in nm or nm != nm.strip():
            raise ValueError(f"write_lp: invalid file name {nm!r}")
    text = f"{len(names)}\n" + "".join(f"{nm} {x:.9f} {y:.9f} {z:.9f}\n" for nm, (x, y, z) in zip(names, d))
    path = Path(path)
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def lights_from_lp(path: str | os.PathLike, capture: Capture) -> Lights:
    """Lights of a capture from an RTI ``.lp`` file, converted to the world frame.

    ``.lp`` file names are matched to the capture's images by base name (``.lp`` files often
    hold absolute or Windows paths). A capture image the file does not list gets a rejected light
    (an ``.lp`` holds no status: ``ffls lights --lp`` leaves rejected photos out, so its own
    capture, or the object shots of the same lights, would otherwise be refused); :attr:`Lights.note`
    says how many and which, and the commands print it.

    Parameters
    ----------
    path : path-like
    capture : Capture
        Supplies the image order and ``world_from_camera``.

    Returns
    -------
    Lights
        In the capture's image order: ``'ok'`` where the file has a line, else ``'rejected'``.
    """
    path = Path(path)
    names, d = read_lp(path)
    base = [PurePosixPath(n.replace("\\", "/")).name for n in names]
    by_base = {PurePosixPath(n.replace("\\", "/")).name: n for n in capture.image_names}
    mapped = []
    for b in base:
        if b not in by_base:
            raise InputError(f"image {b!r} is not in the capture's {CAPTURE_FILE}", path)
        mapped.append(by_base[b])
    if len(set(mapped)) != len(mapped):  # two paths with one base name (a/x.png, b/x.png)
        twice = next(m for k, m in enumerate(mapped) if m in mapped[:k])
        lines = ", ".join(repr(n) for n, m in zip(names, mapped) if m == twice)
        raise InputError(f"capture image {twice!r} is listed twice ({lines})", path)
    missing = [n for n in capture.image_names if n not in set(mapped)]
    if len(missing) == len(capture.image_names):
        raise InputError(f"capture image {missing[0]!r} has no light", path)
    pos = {n: k for k, n in enumerate(mapped)}
    world = lp_to_world(d, capture.world_from_camera)
    dirs = np.array([world[pos[n]] if n in pos else conventions.UP for n in capture.image_names], dtype=np.float64)
    why = f"no light in {path.name} (an .lp lists only accepted lights)"
    out = Lights(list(capture.image_names), dirs, status=["ok" if n in pos else "rejected" for n in capture.image_names],
                 reasons=[None if n in pos else why for n in capture.image_names])
    if missing:
        out.note = (f"lights: {path.name} has no light for {len(missing)} of the capture's {len(capture.image_names)} "
                    f"images ({missing[0]!r}{', ...' if len(missing) > 1 else ''}): they are left out")
    return out


def _base(name: str) -> str:
    return PurePosixPath(name.replace("\\", "/")).name


def parse_lights_map(spec) -> dict:
    """A name map ``{light image name: capture image name}`` from ``--lights-map``.

    Parameters
    ----------
    spec : str, path-like or dict
        A JSON object given inline (text starting with ``{``), a file holding one, or a dict.
        Keys are the image names of the lights file (for ``.lp`` files the name as written or
        its base name), values the images of the capture they apply to.

    Returns
    -------
    dict of str to str

    Raises
    ------
    InputError
        Not a JSON object of non-empty strings, or two keys mapped to one image (naming
        ``--lights-map`` or the file).
    """
    where = None
    if isinstance(spec, dict):
        doc = spec
    else:
        text = str(spec)
        if text.lstrip().startswith(("{", "[")):  # (inline JSON; '[]' was looked for as a file)
            try:
                doc = parse_json(text)
            except ValueError as e:
                raise InputError(f"--lights-map: not valid JSON ({e})") from None
        else:
            where = Path(text)
            doc = _Json(where).load("lights map")
    if not isinstance(doc, dict) or not doc:
        raise InputError("--lights-map: expected a non-empty JSON object {\"light image\": \"capture image\"}", where)
    for k, v in doc.items():
        if not isinstance(v, str) or not v or not k:
            raise InputError(f"--lights-map: {k!r} must map to a non-empty image name, not {_short(v)}", where)
    seen = {}
    for k, v in doc.items():
        if v in seen:
            raise InputError(f"--lights-map: {seen[v]!r} and {k!r} both map to {v!r}", where)
        seen[v] = k
    return dict(doc)


def _read_lights_file(path: Path, capture: Capture) -> Lights:
    """Lights in file order: ``lights.json`` as written, or ``.lp`` converted to the capture's world frame.

    The extension says which; a file whose text is the other kind (an ``.lp`` named ``.json``, a
    ``lights.json`` named ``.lp``) is named as such in its one error line.
    """
    is_lp = path.suffix.lower() == ".lp"
    try:
        if is_lp:
            names, d = read_lp(path)
            return Lights(names, lp_to_world(d, capture.world_from_camera))
        return load_lights(path, scene_center=capture.scene_center)
    except InputError as e:
        other = _looks_like(path)
        if other is None or other == ("lp" if is_lp else "json"):
            raise
        hint = ("its text is JSON (a lights.json?): name it .json" if other == "json"
                else "its text is an RTI .lp file (a count, then 'file x y z' lines): name it .lp")
        raise InputError(f"{e.message}; {hint}", path) from None


def _looks_like(path: Path) -> str | None:
    """``'json'`` or ``'lp'`` by the first characters of a lights file, None when neither."""
    if not path.is_file():  # (a FIFO: its first characters would be waited for)
        return None
    try:
        with open(path, "rb") as f:
            head = f.read(256).lstrip()
    except OSError:
        return None
    if head[:1] in (b"{", b"["):
        return "json"
    first = head.split(b"\n", 1)[0].strip()
    return "lp" if first.isdigit() else None


def _select(lights: Lights, order) -> Lights:
    return Lights(
        image_names=[lights.image_names[i] for i in order],
        directions=lights.directions[order],
        positions=lights.positions[order],
        status=[lights.status[i] for i in order],
        reasons=[lights.reasons[i] for i in order],
        extra=[lights.extra[i] for i in order],
        encoding=lights.encoding,
        frame=lights.frame,
    )


def load_lights_any(path: str | os.PathLike, capture: Capture, lights_map=None) -> Lights:
    """The lights of ``capture`` from a ``lights.json`` or RTI ``.lp`` file, possibly another capture's.

    Matching, in this order (``docs/formats.md``, "Lights of one capture applied to another"):

    1. ``lights_map`` given: light ``k`` (named by its image in the file; for ``.lp`` also by
       base name) applies to capture image ``lights_map[k]``; lights the map leaves out are
       unused; every capture image needs one, except from an ``.lp``, which lists only accepted
       lights: there a capture image without a light (unmapped, or mapped to a light the file
       lacks) gets a rejected light, and the note says how many.
    2. The file's image names are the capture's (``.lp``: by base name): matched by name.
    3. None of the names is an image of the capture and the counts agree: by order (light
       ``i`` to image ``i``), and :attr:`Lights.note` says so.

    Parameters
    ----------
    path : path-like
        ``lights.json`` (world frame) or ``.lp`` (converted with the capture's
        ``world_from_camera``, see :func:`lp_to_world`).
    capture : Capture
    lights_map : dict or str, optional
        As :func:`parse_lights_map` accepts.

    Returns
    -------
    Lights
        In the capture's image order, named by the capture's images; ``note`` set when matched
        by order or by the map, and for an ``.lp`` always: the frame its directions were read in
        (:func:`_lp_frame_note`).

    Raises
    ------
    InputError
        Naming the file: names that match only partly, counts that differ when nothing
        matches, a map naming unknown lights or images, or a capture image without a light.
    """
    path = Path(path)
    out = _match_lights_file(path, capture, lights_map)
    if path.suffix.lower() == ".lp":
        out.note = "; ".join(filter(None, [out.note, _lp_frame_note(path, out, capture)]))
    return out


def _lp_frame_note(path: str | os.PathLike, lights: Lights, capture: Capture) -> str:
    """What ffls assumed of an ``.lp`` file's directions, in one line.

    RTI tools differ (y up or down, z toward the camera or into the scene, another tool's world
    axes), and nothing in the file says which: the note names the frame ffls read (the image's:
    x right, y up, z toward the camera) and, where most accepted lights point away from the
    camera (z < 0: behind the object, which no RTI dome has), says so.

    Parameters
    ----------
    path : path-like
        The ``.lp`` file.
    lights : Lights
        Its lights in the capture's world frame.
    capture : Capture
        Whose ``world_from_camera`` turned them.
    """
    _, dirs = lights.accepted()
    z = world_to_lp(dirs, capture.world_from_camera)[:, 2]
    note = (f"lights: {Path(path).name}: .lp directions read in the image frame (x right, y up, z toward the "
            "camera; docs/formats.md) and turned to the world by capture.json's world_from_camera")
    away = int(np.sum(z < 0.0))
    if away > z.size / 2:
        note += (f"; {away} of its {z.size} lights point away from the camera (z < 0), behind the object: "
                 "a file whose z points into the scene needs its z negated")
    return note


def _match_lights_file(path: Path, capture: Capture, lights_map=None) -> Lights:
    """:func:`load_lights_any`'s matching of a lights file's lights to the capture's images."""
    lp = path.suffix.lower() == ".lp"
    raw = _read_lights_file(path, capture)
    cap_names = list(capture.image_names)
    if lights_map is not None:
        m = parse_lights_map(lights_map)
        index = {}
        for k, n in enumerate(raw.image_names):
            index.setdefault(n, k)
            if lp:
                index.setdefault(_base(n), k)
        known = set(cap_names)
        pos = {}
        for key, target in m.items():
            if target not in known:  # (the flag's value is wrong, not the lights file: it was named)
                span = (f"{cap_names[0]!r} to {cap_names[-1]!r}, {len(cap_names)} in all" if len(cap_names) > 1 else
                        repr(cap_names[0]))
                raise InputError(f"--lights-map maps {key!r} to {target!r}, which is not an image of the capture "
                                 f"{capture.json_path} (its images: {span})")
            if key in index:
                pos[target] = index[key]
            elif not lp:
                raise InputError(f"--lights-map names light {key!r}, which is not in the lights file", path)
        # an .lp lists only accepted lights (ffls lights --lp leaves the rejected out): a capture image
        # whose light it lacks is rejected, as when matching by name; a lights.json lists them all
        missing = [n for n in cap_names if n not in pos]
        if missing and (not lp or len(missing) == len(cap_names)):
            raise InputError(f"capture image {missing[0]!r} has no light in --lights-map", path)
        out = _select(raw, [pos.get(n, 0) for n in cap_names])
        out.image_names = cap_names
        why = f"no light in {path.name} (an .lp lists only accepted lights)"
        for i, n in enumerate(cap_names):
            if n not in pos:
                out.directions[i], out.positions[i] = conventions.UP, np.nan
                out.status[i], out.reasons[i], out.extra[i] = "rejected", why, {}
        out.note = (f"lights: {len(pos)} of the {len(raw)} lights in {path.name} applied to this capture's "
                    f"images by the name map" + (f"; {len(missing)} images without a light in it are left out "
                                                 f"({missing[0]!r}{', ...' if len(missing) > 1 else ''})"
                                                 if missing else ""))
        return out
    key = _base if lp else (lambda n: n)
    cap_key = {key(n): n for n in cap_names}
    hits = sum(key(n) in cap_key for n in raw.image_names)
    if hits == 0 and len(raw) == len(cap_names):
        out = _select(raw, list(range(len(raw))))
        out.image_names = cap_names
        out.note = (f"lights: {path.name} names none of this capture's images; its {len(raw)} lights are applied "
                    f"to the {len(cap_names)} images by order ({raw.image_names[0]!r} -> {cap_names[0]!r}, ...)")
        return out
    if hits == 0:
        # an .lp lists only the accepted lights: the lights.json written beside it keeps every photo, in order
        why = ("; an .lp lists only accepted lights (ffls lights --lp leaves the rejected out): the lights.json "
               "written with it keeps every photo in order" if lp and len(raw) < len(cap_names) else "")
        raise InputError(f"none of the {len(raw)} lights names an image of the capture ({len(cap_names)} images), so "
                         "they cannot apply by order either; give --lights-map '{\"light image\": \"capture image\"}'"
                         + why, path)
    first = {}
    for k, n in enumerate(raw.image_names):
        first.setdefault(key(n), k)
    named = [first[k] for k in cap_key if k in first]
    extra = len(raw) - len(named)
    if len(named) == len(cap_names) and extra > 0 and len(set(raw.image_names)) == len(raw):
        # the file names every image of the capture and more (a calibration set with extra shots):
        # by name, the others unused, and said
        out = _select(raw, named)
        out.image_names = cap_names
        out.note = (f"lights: {path.name} holds {len(raw)} lights; the {len(cap_names)} that name this capture's "
                    f"images are used by name, the other {extra} are not")
        return out
    try:
        return lights_from_lp(path, capture) if lp else load_lights(path, capture)
    except InputError as e:
        if hits < len(raw):  # names that match only partly: the map is the way
            raise InputError(f"{e.message}; {hits} of the {len(raw)} lights name images of the capture: to apply "
                             "them otherwise, give --lights-map '{\"light image\": \"capture image\"}'",
                             e.path) from None
        raise


def load_capture_and_lights(folder, lights=None, lights_map=None, *,
                            optional: bool = False) -> tuple[Capture, Lights | None]:
    """``(capture, lights)`` of a capture folder; ``lights`` defaults to ``FOLDER/lights.json``.

    ``lights`` may be a ``lights.json`` or an RTI ``.lp`` file, also one of another capture of
    the same lights (matched by :func:`load_lights_any`, with ``lights_map`` when given; the
    returned lights' ``note`` says how they were matched).

    Raises
    ------
    InputError
        As :func:`load_capture` and :func:`load_lights_any`; a missing default ``lights.json`` says how
        to make one (``ffls lights``), unless ``optional``: then ``(capture, None)``. A missing file
        named by ``lights`` is always an error.
    """
    capture = load_capture(folder)
    path = Path(lights) if lights else capture.folder / LIGHTS_FILE  # (FOLDER may name capture.json itself)
    if not path.exists():
        if lights:
            raise InputError(broken_link(path) or "lights file not found", path)
        if optional:
            return capture, None
        raise InputError(broken_link(path) or "no lights file: estimate the light directions first (ffls lights "
                         "CAPTURE)", path)
    found = load_lights_any(path, capture, lights_map)
    found.path = path
    applied = apply_lights_encoding(capture, found)
    if applied is not capture and path.resolve().parent != capture.folder.resolve():
        # another capture's calibration applied to these photos: an assumption (the same camera and settings), said
        curve = found.encoding.get("curve")
        what = f"gamma {found.encoding['gamma']:g}" if curve == "gamma" else curve
        found.note = "; ".join(filter(None, [found.note, (
            f"encoding: capture.json states none; the {what} curve that ffls lights calibrated for {path} is "
            "applied to these photos (the same camera and settings; state \"encoding\" in capture.json otherwise)")]))
    return applied, found


def apply_lights_encoding(capture: Capture, lights: Lights) -> Capture:
    """``capture`` with the encoding that ``ffls lights`` calibrated, where ``capture.json`` states none.

    A stated ``"encoding"`` always wins: the capture is returned unchanged when its encoding is
    not ``'auto'``, its images are floating point (``.exr``, ``.hdr``: linear by definition), or
    ``lights`` has no :attr:`Lights.encoding` record. The record may come
    from another capture's ``lights.json`` (calibration shots of the same camera).

    Returns
    -------
    Capture
        A copy with ``encoding`` set (the input is not modified), or ``capture`` itself.

    Raises
    ------
    InputError
        (naming ``lights.path``) a calibrated response table made for files of another bit depth
        than the capture's first image.
    """
    if capture.encoding != "auto" or lights.encoding is None:
        return capture
    if capture.image_paths and Path(capture.image_paths[0]).suffix.lower() in _FLOAT_SUFFIXES:
        return capture  # floating-point images are linear by definition
    from dataclasses import replace

    response = record_response(lights.encoding)
    if response is not None and capture.image_paths and Path(capture.image_paths[0]).is_file():
        from ffls.io.images import read_image

        depth = read_image(capture.image_paths[0]).bit_depth
        bits = int(len(response)).bit_length() - 1
        if depth != bits:
            raise InputError(f"its encoding was calibrated on {bits}-bit files (\"bits\": {bits}), but the capture's "
                             f"images are {depth}-bit: use the lights of a capture with {depth}-bit files, or state "
                             "the encoding in capture.json", lights.path)
    return replace(capture, encoding=encoding_from_record(lights.encoding), response=response)


# ----------------------------------------------------------------------------- shared with other documents
#: The validating reader of ffls' JSON documents (``JsonReader(path)``: ``load``, ``header``, ``require``,
#: ``number``, ``array``, ``direction``, ``string``, ``fail``), shared with ``probe.json`` (:mod:`ffls.io.probe`).
JsonReader = _Json


def parse_camera(reader: JsonReader, cam) -> tuple:
    """The ``camera`` object of ``capture.json`` (or of any document with the same keys).

    Returns
    -------
    K : (3, 3) float64 or None
    dist : (k,) float64
    world_from_camera : (4, 4) float64
    world_from_camera_is_default : bool
    model : {'pinhole', 'orthographic'}

    Raises
    ------
    InputError
        Naming ``reader.path`` and the key (``camera.K``, ``camera.dist``, ...).
    """
    return _parse_camera(reader, cam)


def parse_encoding(reader: JsonReader, doc: dict, folder) -> tuple:
    """``doc["encoding"]`` as ``capture.json`` states it: (encoding, (256, 3) response table or None).

    ``'auto'`` when the key is absent; a ``{"response": file}`` table is read from ``folder``.
    """
    return _parse_encoding(reader, doc, Path(folder))


def check_file_name(reader: JsonReader, name, key: str) -> str:
    """A file name relative to the document's folder, inside it (no absolute path, no ``..``)."""
    return _check_name(reader, name, key)
