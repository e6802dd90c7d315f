"""Chessboard calibration: camera intrinsics and distortion → a ROS camera_info YAML for fgslam.

Print a chessboard, tape it flat, and take 15–30 pictures of it with the camera to calibrate,
filling different parts of the image, tilted up to ~45° in different directions, at the
distances you will use. Then::

    .venv/bin/python scripts/calibrate_camera.py 'calib/*.png' --board 9x6 --square 0.025 \\
        --mount 0.10,0,0.30,0,0,0 --out kinect.yaml

``--board`` counts *inner* corners (a board of 10×7 squares has 9×6). ``--square`` is the side
of one square in metres (measure the print). ``--model`` picks the distortion model:
``plumb_bob`` (k1 k2 p1 p2 k3, the ROS default), ``rational_polynomial`` (8 coefficients, wide
lenses) or ``equidistant`` (fisheye, OpenCV's ``cv2.fisheye``). ``--mount x,y,z,roll,pitch,yaw``
(metres, radians) records where the camera sits on the robot (see docs/camera.md).

Views where the board is not found are listed and skipped; after a first solve, views whose
RMS reprojection error is more than 3× the median are dropped and the solve repeated. The
script prints the RMS error (below ~0.5 px is a good calibration) and writes the file that
``fgslam detect --camera`` and :func:`slamio.camera.model.load_camera` read.
"""

from __future__ import annotations

import argparse
import glob
import math
import sys
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from slamio.camera.model import CameraModel, T_robot_camera_from_mount, save_camera  # noqa: E402
from slamio.errors import FgslamError  # noqa: E402

MODELS = ("plumb_bob", "rational_polynomial", "equidistant")


class CalibrationError(FgslamError):
    pass


@dataclass
class Calibration:
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


def _board(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError("--board is COLSxROWS of inner corners, e.g. 9x6") from None
    if cols < 2 or rows < 2:
        raise argparse.ArgumentTypeError("--board needs at least 2x2 inner corners")
    return cols, rows


def _mount(text: str) -> np.ndarray:
    try:
        values = [float(x) for x in text.split(",")]
        if len(values) != 6:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError("--mount is x,y,z,roll,pitch,yaw in metres and radians") from None
    return T_robot_camera_from_mount(*values)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("images", nargs="+", help="image files or quoted glob patterns ('calib/*.png')")
    parser.add_argument("--board", type=_board, required=True, help="inner corners COLSxROWS, e.g. 9x6")
    parser.add_argument("--square", type=float, required=True, help="square side in metres")
    parser.add_argument("--model", choices=MODELS, default="plumb_bob", help="distortion model (default plumb_bob)")
    parser.add_argument("--mount", type=_mount, default=None, help="x,y,z,roll,pitch,yaw of the camera on the robot")
    parser.add_argument("--name", default="camera", help="camera_name in the file")
    parser.add_argument("--out", required=True, help="camera_info YAML to write")
    args = parser.parse_args(argv)
    if not args.square > 0:
        parser.error("--square must be > 0 (metres)")
    paths = sorted({p for pattern in args.images for p in (glob.glob(pattern) or [pattern])})
    try:
        result = calibrate(paths, args.board, args.square, model=args.model, mount=args.mount, name=args.name)
    except FgslamError as exc:
        print(f"calibrate_camera: error: {exc}", file=sys.stderr)
        return 1
    cam = result.camera
    for path in result.board_not_found:
        print(f"  board not found: {path}")
    for path, error in result.dropped:
        print(f"  dropped (RMS {error:.2f} px, > 3x the median): {path}")
    print(f"{len(result.used)} views, RMS reprojection error {result.rms_px:.3f} px")
    print(f"  fx {cam.fx:.2f}  fy {cam.fy:.2f}  cx {cam.cx:.2f}  cy {cam.cy:.2f}  "
          f"{cam.distortion_model} {np.array2string(cam.dist_coeffs, precision=4)}")
    comment = (f"written by scripts/calibrate_camera.py: {len(result.used)} views of a {args.board[0]}x{args.board[1]} "
               f"board, {args.square} m squares, RMS {result.rms_px:.3f} px")
    save_camera(args.out, cam, comment=comment)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
