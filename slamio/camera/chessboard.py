"""Chessboard calibration: a camera's intrinsics and lens distortion from pictures of a printed board.

:func:`calibrate` finds the board's inner corners in each picture (sub-pixel), solves for the
intrinsics and the distortion of one of :data:`MODELS` (OpenCV's ``calibrateCamera``, or
``cv2.fisheye`` for ``equidistant``), drops the views whose RMS reprojection error is more
than 3× the median and solves again. ``fgslam calibrate-camera`` (:mod:`fgslam.cli.calibrate_camera`)
is its command line; the :class:`~slamio.camera.model.CameraModel` it returns is what
:func:`~slamio.camera.model.save_camera` writes and ``fgslam detect --camera`` reads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from slamio.camera.model import DISTORTION_MODELS, CameraModel, T_robot_camera_from_mount
from slamio.errors import FgslamError

#: The distortion models :func:`calibrate` fits (ROS ``distortion_model`` names).
MODELS = DISTORTION_MODELS


class CalibrationError(FgslamError):
    """The pictures cannot give a calibration (too few boards found, mixed image sizes, an unknown model)."""


@dataclass
class Calibration:
    """A calibration and how it was reached: the views used, those without a board, those dropped."""

    camera: CameraModel
    rms_px: float
    used: list[str]
    board_not_found: list[str]
    dropped: list[tuple[str, float]]  # (view, its RMS error) dropped as outliers
    per_view_rms_px: dict[str, float]


def board_points(board: tuple[int, int], square_m: float) -> np.ndarray:
    """(cols·rows, 3) chessboard inner corners in the board's frame (z = 0), row by row."""
    cols, rows = board
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2)
    return np.column_stack([grid * square_m, np.zeros(len(grid))]).astype(np.float32)


def find_corners(grey: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners of the board, or None when it is not (entirely) in view."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(grey, board, flags=flags)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    return cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1), criteria)


def _solve(object_points, image_points, size, model):
    n = len(object_points)
    if model == "equidistant":
        K, D = np.eye(3), np.zeros((4, 1))
        fisheye_flags = cv2.fisheye if hasattr(cv2.fisheye, "CALIB_FIX_SKEW") else cv2  # OpenCV 4 vs 5
        flags = fisheye_flags.CALIB_RECOMPUTE_EXTRINSIC | fisheye_flags.CALIB_FIX_SKEW
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-9)
        obj = [o.reshape(1, -1, 3).astype(np.float64) for o in object_points]
        img = [i.reshape(1, -1, 2).astype(np.float64) for i in image_points]
        _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(obj, img, size, K, D, flags=flags, criteria=criteria)
        errors = []
        for o, i, r, t in zip(obj, img, rvecs, tvecs):
            p = cv2.fisheye.projectPoints(o, r, t, K, D)[0].reshape(-1, 2)
            errors.append(float(np.sqrt(np.mean(np.sum((p - i.reshape(-1, 2)) ** 2, axis=-1)))))
        return K, D.ravel(), errors
    flags = cv2.CALIB_RATIONAL_MODEL if model == "rational_polynomial" else 0
    _, K, D, rvecs, tvecs = cv2.calibrateCamera(object_points, image_points, size, None, None, flags=flags)
    errors = []
    for k in range(n):
        p = cv2.projectPoints(object_points[k], rvecs[k], tvecs[k], K, D)[0].reshape(-1, 2)
        errors.append(float(np.sqrt(np.mean(np.sum((p - image_points[k].reshape(-1, 2)) ** 2, axis=-1)))))
    D = D.ravel()[: 8 if model == "rational_polynomial" else 5]
    return K, D, errors


def calibrate(paths: list[str], board: tuple[int, int], square_m: float, *, model: str = "plumb_bob",
              mount: np.ndarray | None = None, name: str = "camera", min_views: int = 5) -> Calibration:
    """Calibrate from chessboard images; raises CalibrationError when it cannot."""
    if model not in MODELS:
        raise CalibrationError(f"unknown model {model!r}; use one of {', '.join(MODELS)}")
    obj = board_points(board, square_m)
    object_points, image_points, used, not_found = [], [], [], []
    size = None
    for path in paths:
        grey = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if grey is None:
            not_found.append(path)
            continue
        if size is None:
            size = (grey.shape[1], grey.shape[0])
        elif size != (grey.shape[1], grey.shape[0]):
            raise CalibrationError(f"{path}: {grey.shape[1]}×{grey.shape[0]}, but earlier images are {size[0]}×{size[1]}")
        corners = find_corners(grey, board)
        if corners is None:
            not_found.append(path)
            continue
        object_points.append(obj)
        image_points.append(corners.reshape(-1, 1, 2).astype(np.float32))
        used.append(path)
    if len(used) < min_views:
        raise CalibrationError(
            f"the {board[0]}×{board[1]} board was found in {len(used)} of {len(paths)} images; need at least "
            f"{min_views} (is --board the count of inner corners, e.g. 9x6 for 10×7 squares?)"
        )
    K, D, errors = _solve(object_points, image_points, size, model)
    median = float(np.median(errors))
    keep = [k for k, e in enumerate(errors) if e <= 3.0 * median or e < 0.3]
    dropped = [(used[k], errors[k]) for k in range(len(used)) if k not in keep]
    if dropped and len(keep) >= min_views:
        object_points = [object_points[k] for k in keep]
        image_points = [image_points[k] for k in keep]
        used = [used[k] for k in keep]
        K, D, errors = _solve(object_points, image_points, size, model)
    else:
        dropped = []
    counts = [len(p) for p in image_points]
    rms = math.sqrt(sum(e * e * c for e, c in zip(errors, counts)) / sum(counts))
    camera = CameraModel(size[0], size[1], K, np.asarray(D, dtype=float), model,
                         T_robot_camera_from_mount() if mount is None else mount, name)
    return Calibration(camera, rms, used, not_found, dropped, dict(zip(used, errors)))
