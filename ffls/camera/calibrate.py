"""Camera calibration from photos of a ChArUco board or a chessboard (OpenCV).

Zhang, Z. (2000). A flexible new technique for camera calibration. IEEE TPAMI 22(11), as
implemented by :func:`cv2.calibrateCamera`. Corners come from :class:`cv2.aruco.CharucoDetector`
(ChArUco: partial views are fine, corners are identified) or :func:`cv2.findChessboardCorners`
(the whole board must be visible) refined with :func:`cv2.cornerSubPix`.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import cv2
import numpy as np

from ffls.errors import InputError, atomic_output, not_a_regular_file
from ffls.io.capture import MAX_FOCAL_PX, MAX_PIXEL_ASPECT, parse_json, read_json_text
from ffls.io.images import read_image

__all__ = ["CameraCalibration", "aruco_dictionary", "charuco_problem", "camera_matrix_problem", "make_board",
           "legacy_differs", "detect_board", "calibrate_camera", "check_camera_capture", "write_camera_to_capture"]


@dataclasses.dataclass
class CameraCalibration:
    """Result of :func:`calibrate_camera`.

    Attributes
    ----------
    K : (3, 3) float64
    dist : (5,) float64
        OpenCV (k1, k2, p1, p2, k3).
    rms : float
        RMS reprojection error, pixels.
    image_size : (W, H)
    used : list of str
        The images whose board was found.
    skipped : list of str
        The images without a usable board.
    legacy_pattern : bool
        The ChArUco board was found with OpenCV's legacy layout (:func:`make_board`).
    """

    K: np.ndarray
    dist: np.ndarray
    rms: float
    image_size: tuple
    used: list
    skipped: list
    legacy_pattern: bool = False

    def to_dict(self) -> dict:
        return {"K": self.K.tolist(), "dist": self.dist.ravel().tolist(), "rms_px": float(self.rms),
                "image_size": list(self.image_size), "used": list(self.used), "skipped": list(self.skipped),
                **({"legacy_pattern": True} if self.legacy_pattern else {})}


def aruco_dictionary(dictionary):
    """The :class:`cv2.aruco.Dictionary` of an OpenCV name (``'DICT_5X5_100'``, or ``'5X5_100'``).

    Raises ValueError naming the known dictionaries when the name is not one of OpenCV's.
    """
    if isinstance(dictionary, str):
        name = dictionary if dictionary.startswith("DICT_") else f"DICT_{dictionary}"
        if not name.startswith("DICT_") or not isinstance(getattr(cv2.aruco, name, None), int):
            known = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and n == n.upper())
            raise ValueError(f"unknown ArUco dictionary {dictionary!r}; OpenCV's are {', '.join(known)}")
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    return dictionary


def charuco_problem(squares, square_size: float, marker_size: float, dictionary) -> str | None:
    """Why a ChArUco board cannot be built, or None.

    A marker sits inside a white square, so it must be smaller than the square (OpenCV raises a
    SystemError otherwise), and the board's ``columns * rows // 2`` markers need as many ids in
    the dictionary (OpenCV builds the board and then cannot detect the ids past the end).
    """
    if not marker_size < square_size:
        return f"the marker side {marker_size:g} must be smaller than the square side {square_size:g}"
    n = int(squares[0]) * int(squares[1]) // 2
    have = aruco_dictionary(dictionary).bytesList.shape[0]
    if n > have:
        return f"a {squares[0]}x{squares[1]} board has {n} markers but the dictionary has {have}"
    return None


#: Two views whose matched corners all lie within this many pixels are one view: corner detection
#: repeats to ~0.1 px, and a board moved or turned between photos shifts its corners by pixels.
SAME_VIEW_PX = 0.5


def _same_view(obj_a, img_a, obj_b, img_b) -> bool:
    """Whether two detections put the same board corners at the same pixels (within SAME_VIEW_PX)."""
    a = {tuple(np.round(p, 9)): q for p, q in zip(np.asarray(obj_a, np.float64), img_a)}
    pairs = [(a[k], q) for k, q in zip(map(tuple, np.round(np.asarray(obj_b, np.float64), 9)), img_b) if k in a]
    if len(pairs) < 4:
        return False
    d = np.array([np.hypot(*(np.asarray(p, np.float64) - q)) for p, q in pairs])
    return bool(np.max(d) <= SAME_VIEW_PX)


def camera_matrix_problem(K) -> str | None:
    """Why a calibrated ``K`` is no camera's, or None: the bounds that loading ``capture.json`` applies
    (:data:`ffls.io.capture.MAX_FOCAL_PX`, :data:`ffls.io.capture.MAX_PIXEL_ASPECT`), so that a
    calibration never writes a ``camera.K`` that the capture then refuses."""
    K = np.asarray(K, dtype=np.float64)
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        return f"fx = {K[0, 0]:.6g}, fy = {K[1, 1]:.6g} px: not positive finite focal lengths"
    if np.max(np.abs(K)) > MAX_FOCAL_PX:
        return (f"fx = {K[0, 0]:.6g}, fy = {K[1, 1]:.6g} px: beyond {MAX_FOCAL_PX:g} px (a 100 m lens on 1 um "
                "pixels)")
    if not 1.0 / MAX_PIXEL_ASPECT <= K[0, 0] / K[1, 1] <= MAX_PIXEL_ASPECT:
        return f"fx / fy = {K[0, 0] / K[1, 1]:.6g}: pixels that far from square are no camera's"
    return None


def make_board(squares=(7, 5), square_size: float = 0.03, marker_size: float = 0.022,
               dictionary="DICT_5X5_100", legacy: bool = False):
    """A :class:`cv2.aruco.CharucoBoard` of ``squares`` = (columns, rows) squares.

    ``legacy``: the layout of boards made before OpenCV 4.6 (and by generators that kept it), which
    differs from today's where the number of rows is even (:func:`legacy_differs`)."""
    why = charuco_problem(squares, square_size, marker_size, dictionary)
    if why:
        raise ValueError(why)
    b = cv2.aruco.CharucoBoard((int(squares[0]), int(squares[1])), float(square_size), float(marker_size),
                               aruco_dictionary(dictionary))
    if legacy:
        b.setLegacyPattern(True)
    return b


def legacy_differs(board: str, squares) -> bool:
    """Whether OpenCV's legacy ChArUco layout differs from today's for this board: an even number of rows."""
    return board == "charuco" and int(squares[1]) % 2 == 0


def detect_board(gray, board: str = "charuco", squares=(7, 5), square_size: float = 0.03,
                 marker_size: float = 0.022, dictionary="DICT_5X5_100", min_corners: int = 6,
                 legacy: bool = False):
    """Board corners in one image.

    Parameters
    ----------
    gray : (H, W) uint8
    board : {'charuco', 'chessboard'}
    squares : (int, int)
        Squares along x and y (a chessboard has ``(x-1) * (y-1)`` inner corners).
    legacy : bool
        A ChArUco board of OpenCV's legacy layout (:func:`make_board`).

    Returns
    -------
    (object_points (n, 3) float32, image_points (n, 2) float32) or None when no board is found.
    """
    if board == "charuco":
        b = make_board(squares, square_size, marker_size, dictionary, legacy)
        det = cv2.aruco.CharucoDetector(b)
        corners, ids, _, _ = det.detectBoard(gray)
        if ids is None or len(ids) < min_corners:
            return None
        obj, img = b.matchImagePoints(corners, ids)
        return obj.reshape(-1, 3).astype(np.float32), img.reshape(-1, 2).astype(np.float32)
    if board == "chessboard":
        pattern = (int(squares[0]) - 1, int(squares[1]) - 1)
        ok, corners = cv2.findChessboardCorners(gray, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok:
            return None
        corners = cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4))
        gx, gy = np.meshgrid(np.arange(pattern[0]), np.arange(pattern[1]))
        obj = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1) * float(square_size)
        return obj.astype(np.float32), corners.reshape(-1, 2).astype(np.float32)
    raise ValueError(f"board must be 'charuco' or 'chessboard', not {board!r}")


#: How many photos without the board :func:`calibrate_camera` tries with the squares the other way round.
TRANSPOSED_TRIES = 3


def _transposed_hint(missed, board, squares, square_size, marker_size, dictionary) -> str:
    """``"; it is a RxC board in k of the first m photos without it: ..."`` when a ChArUco board given as
    ``C x R`` squares is found as ``R x C`` (its columns and rows swapped: the tools that print boards
    name them in either order), else ``""``."""
    other = (int(squares[1]), int(squares[0]))
    if board != "charuco" or other[0] == other[1] or not missed:
        return ""
    hits = sum(detect_board(im, board, other, square_size, marker_size, dictionary) is not None for im in missed)
    if not hits:
        return ""
    return (f"; the board is found as {other[0]}x{other[1]} squares in {hits} of the first {len(missed)} photos "
            f"without it: give --squares {other[0]}x{other[1]} (squares along x, then y)")


def calibrate_camera(image_paths, board: str = "charuco", squares=(7, 5), square_size: float = 0.03,
                     marker_size: float = 0.022, dictionary="DICT_5X5_100", fix_k3: bool = True,
                     images=None, legacy: bool = False) -> CameraCalibration:
    """Intrinsics K and distortion from photos of a calibration board.

    Parameters
    ----------
    image_paths : list of path
        Photos of the board (named in errors). Ignored for reading when ``images`` is given.
    board : {'charuco', 'chessboard'}
    squares : (int, int)
        Squares along the board's x and y.
    square_size, marker_size : float
        Side of a square and of an ArUco marker (scene units, e.g. metres).
    dictionary : str or cv2.aruco.Dictionary
        ArUco dictionary, e.g. ``'DICT_5X5_100'`` (OpenCV's name).
    fix_k3 : bool
        Keep k3 = 0 (recommended unless the lens is very wide).
    images : list of (H, W) or (H, W, 3) uint8, optional
        Images already in memory (then ``image_paths`` only names them).
    legacy : bool
        Look for a ChArUco board of OpenCV's legacy layout. Without it, a board with an even number
        of rows found in fewer than 3 photos is looked for in that layout too, and used when the
        first photos without it show it so (a board printed before OpenCV 4.6 was "found in 0 of
        N photos"): ``legacy_pattern`` of the result says so.

    Returns
    -------
    CameraCalibration

    Raises
    ------
    InputError
        An unreadable image, images of different sizes, the same image twice or two photos of one
        view (every corner within SAME_VIEW_PX: a copy adds no view), fewer than 3 views with a
        board, or a K that is no camera's (:func:`camera_matrix_problem`).
    """
    paths = [Path(p) for p in image_paths]
    obj_pts, img_pts, used, skipped = [], [], [], []
    missed = []  # the first photos without the board, to try it with its squares the other way round
    size = None
    seen = {}
    n = len(images) if images is not None else len(paths)
    retry = not legacy and legacy_differs(board, squares)
    decoded = [] if retry and images is None else None  # (the legacy retry reuses them, not the files)
    for i in range(n):
        name = paths[i] if i < len(paths) else Path(f"image {i}")
        if images is not None:
            im = np.asarray(images[i])
        else:
            # (read_image's one line: not found, a folder, truncated, ...; any depth, as 8-bit grey)
            grey = cv2.cvtColor(read_image(name, working_space=False).pixels, cv2.COLOR_RGB2GRAY)
            im = np.clip(np.rint(grey * 255), 0, 255).astype(np.uint8)
        if im.ndim == 3:
            im = cv2.cvtColor(im, cv2.COLOR_RGB2GRAY)
        if im.dtype != np.uint8:
            raise InputError(f"calibration photos must be 8-bit, got {im.dtype}", name)
        if decoded is not None:
            decoded.append(im)
        if size is None:
            size = (im.shape[1], im.shape[0])
        elif size != (im.shape[1], im.shape[0]):
            raise InputError(f"image size {im.shape[1]}x{im.shape[0]} differs from {size[0]}x{size[1]}", name)
        found = detect_board(im, board, squares, square_size, marker_size, dictionary, legacy=legacy)
        if found is None:
            skipped.append(str(name))
            if len(missed) < TRANSPOSED_TRIES:
                missed.append(im)
            continue
        digest = hashlib.sha1(np.ascontiguousarray(im).tobytes()).hexdigest()
        if digest in seen:
            raise InputError(f"the same image as {seen[digest]}: a photo given twice is not a second view of the"
                             " board", name)
        seen[digest] = name
        for o, q, u in zip(obj_pts, img_pts, used):
            if _same_view(o, q, found[0], found[1]):
                raise InputError(f"shows the board where {u} does (every corner within {SAME_VIEW_PX:g} px): not a"
                                 " second view; move the board or the camera between photos", name)
        obj_pts.append(found[0])
        img_pts.append(found[1])
        used.append(str(name))
        if len(obj_pts) >= 3:
            decoded = None  # (three views: the legacy retry cannot fire, the decoded photos are not kept)
    if (len(obj_pts) < 3 and retry
            and any(detect_board(im, board, squares, square_size, marker_size, dictionary, legacy=True) is not None
                    for im in missed)):
        return calibrate_camera(image_paths, board, squares, square_size, marker_size, dictionary, fix_k3,
                                images if decoded is None else decoded, legacy=True)
    if len(obj_pts) < 3:
        where = paths[0].parent if paths else None
        raise InputError(f"a {board} board ({squares[0]}x{squares[1]} squares) was found in {len(obj_pts)} of"
                         f" {n} photos; need at least 3"
                         + _transposed_hint(missed, board, squares, square_size, marker_size, dictionary), where)
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    rms, K, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, size, None, None, flags=flags)
    why = camera_matrix_problem(K)
    if why:
        raise InputError(f"the calibration from {', '.join(Path(u).name for u in used)} is no camera's ({why}):"
                         " the views are too alike; photograph the board from several angles", paths[0].parent
                         if paths else None)
    return CameraCalibration(K=np.asarray(K, dtype=np.float64), dist=np.asarray(dist, dtype=np.float64).ravel()[:5],
                             rms=float(rms), image_size=size, used=used, skipped=skipped, legacy_pattern=legacy)


def check_camera_capture(capture_dir) -> tuple[Path, dict]:
    """``(path, doc)`` of ``CAPTURE_DIR/capture.json`` that :func:`write_camera_to_capture` can update:
    a readable JSON object whose ``camera`` is an object, in a folder where it can be replaced.

    Called before the board photos are calibrated too (a missing capture, a broken link or a
    read-only folder was reported only after the calibration).
    """
    from ffls.errors import broken_link, check_output_path

    folder = Path(capture_dir)
    if folder.name == "capture.json" and folder.is_file():  # (the file named instead of its folder)
        folder = folder.parent
    why = broken_link(folder)
    if why or not folder.is_dir():
        raise InputError(why or ("capture folder not found" if not folder.exists() else "not a folder"), folder)
    path = folder / "capture.json"
    if not path.is_file():
        raise InputError(not_a_regular_file(path) or "capture.json not found", path)
    try:
        doc = parse_json(read_json_text(path, "capture.json"))
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read JSON ({e})", path) from None
    if not isinstance(doc, dict):
        raise InputError("expected a JSON object", path)
    if not isinstance(doc.get("camera") or {}, dict):
        raise InputError("'camera' must be an object", path)
    check_output_path(path)
    return path, doc


def write_camera_to_capture(capture_dir, K, dist, image_size=None) -> Path:
    """Set ``camera.K`` and ``camera.dist`` in ``CAPTURE_DIR/capture.json``, keeping every other key.

    The file is read, modified and written back atomically. With ``image_size`` (W, H), the size
    of the board photos, a capture whose ``image_size`` differs is refused: K is in the pixels of
    the photos it was calibrated on.
    """
    path, doc = check_camera_capture(capture_dir)
    have = doc.get("image_size")
    if image_size is not None and isinstance(have, list) and len(have) == 2 and list(have) != [int(v) for v in image_size]:
        raise InputError(f"image_size {have[0]}x{have[1]} differs from the {image_size[0]}x{image_size[1]} board "
                         "photos: K calibrated on them is not this capture's camera", path)
    cam = doc.get("camera") or {}
    cam["K"] = np.asarray(K, dtype=np.float64).reshape(3, 3).tolist()
    cam["dist"] = np.asarray(dist, dtype=np.float64).ravel().tolist()
    doc["camera"] = cam
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path
