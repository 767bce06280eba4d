"""Camera models: the pinhole camera with OpenCV's distortion model, and the orthographic camera.

Conventions (GUIDE section 1): x right, y down, z forward; ``K`` is 3x3 and ``dist`` is OpenCV's
distortion vector. Pixel centres are at integer coordinates.

The orthographic camera (``"camera": {"model": "orthographic"}`` in ``capture.json``: a long
lens, or a ball seen from far away) has parallel viewing rays along its +z axis; directions need
no focal length and no pixel scale.
"""
from __future__ import annotations

import cv2
import numpy as np

from ffls.conventions import CAMERA_MODELS

__all__ = ["CAMERA_MODELS", "camera_arrays", "pixel_rays", "orthographic_rays", "camera_rays", "project_points"]


def camera_arrays(K, dist=None) -> tuple[np.ndarray, np.ndarray]:
    """``K`` as (3, 3) float64 and ``dist`` as a flat float64 vector (zeros when None)."""
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=np.float64).ravel()
    return K, dist


def pixel_rays(pixels, K, dist=None) -> np.ndarray:
    """Unit viewing rays (camera frame) through image points.

    Parameters
    ----------
    pixels : (n, 2) float
        Pixel coordinates (x right, y down; pixel centres at integers), in the distorted image.
    K : (3, 3) float
    dist : (k,) float or None
        OpenCV distortion coefficients.

    Returns
    -------
    (n, 3) float64, unit, z > 0.
    """
    K, dist = camera_arrays(K, dist)
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    if p.shape[0] == 0:
        return np.zeros((0, 3))
    if np.any(dist != 0):
        xy = cv2.undistortPoints(p, K, dist, None, None, None,
                                 (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)).reshape(-1, 2)
    else:
        xy = (p.reshape(-1, 2) - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T
    r = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
    return r / np.linalg.norm(r, axis=1, keepdims=True)


def orthographic_rays(pixels) -> np.ndarray:
    """Unit viewing rays (camera frame) of an orthographic camera: every ray is +z.

    Parameters
    ----------
    pixels : (n, 2) float
        Pixel coordinates (only their count matters: the rays are parallel).

    Returns
    -------
    (n, 3) float64, every row ``(0, 0, 1)``.
    """
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    r = np.zeros((p.shape[0], 3))
    r[:, 2] = 1.0
    return r


def camera_rays(pixels, model: str = "pinhole", K=None, dist=None) -> np.ndarray:
    """Unit viewing rays (camera frame) through image points under a capture's camera model.

    Parameters
    ----------
    pixels : (n, 2) float
    model : {'pinhole', 'orthographic'}
        ``capture.camera_model``.
    K, dist
        Pinhole intrinsics (required for ``'pinhole'``, ignored for ``'orthographic'``).

    Returns
    -------
    (n, 3) float64, unit, z > 0.
    """
    if model == "orthographic":
        return orthographic_rays(pixels)
    if model != "pinhole":
        raise ValueError(f"camera model must be one of {CAMERA_MODELS}, not {model!r}")
    if K is None:
        raise ValueError("a pinhole camera needs K")
    return pixel_rays(pixels, K, dist)


def project_points(points_cam, K, dist=None) -> np.ndarray:
    """Project camera-frame points (n, 3) to pixels (n, 2) with OpenCV's model.

    Without distortion (``dist`` None or all zero) the pinhole projection is computed here, as
    ``cv2.projectPoints`` does it (``fx``, ``fy``, ``cx``, ``cy``; a point at z = 0 divided by 1):
    OpenCV's Python binding also computes the (2n, 15) Jacobian, 30 times the work."""
    K, dist = camera_arrays(K, dist)
    P = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    if P.shape[0] == 0:
        return np.zeros((0, 2))
    if not np.any(dist):
        z = P[:, 2:]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(z != 0, 1.0 / np.where(z != 0, z, 1.0), 1.0)
        return P[:, :2] * inv * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
    px, _ = cv2.projectPoints(P.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, dist)
    return px.reshape(-1, 2)
