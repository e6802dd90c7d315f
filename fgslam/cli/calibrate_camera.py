"""``fgslam calibrate-camera``: a camera's intrinsics and distortion from chessboard pictures,
written as the camera_info YAML that ``fgslam detect --camera`` reads.

The maths is :mod:`slamio.camera.chessboard`; this module reads the command line, checks the
output before any work, and writes the file (never replacing one unless ``--overwrite``).
"""

from __future__ import annotations

import argparse
import glob

from fgslam.cli.common import (
    add_overwrite_option, add_verb, check_new_file, check_number, holds_outputs, write_new_file,
)
from fgslam.cli.verbs import help_of

DESCRIPTION = """\
Calibrate a camera from pictures of a printed chessboard: intrinsics (fx, fy, cx, cy) and
lens distortion, written as a ROS camera_info YAML for fgslam detect --camera.

Print a chessboard, tape it flat, and take 15-30 pictures of it with the camera to calibrate,
filling different parts of the image, tilted up to ~45 degrees in different directions, at
the distances you will use.

--board counts *inner* corners (a board of 10x7 squares has 9x6). --square is the side of
one square in metres (measure the print). --model picks the distortion model: plumb_bob
(k1 k2 p1 p2 k3, the ROS default), rational_polynomial (8 coefficients, wide lenses) or
equidistant (fisheye). --mount x,y,z,roll,pitch,yaw (metres, radians) records where the
camera sits on the robot (docs/camera.md).

Pictures where the board is not found are listed and skipped; after a first solve, views
whose RMS reprojection error is more than 3x the median are dropped and the solve repeated.
The RMS reprojection error is printed (below ~0.5 px is a good calibration).
"""


def _board(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError("--board is COLSxROWS of inner corners, e.g. 9x6") from None
    if cols < 2 or rows < 2:
        raise argparse.ArgumentTypeError("--board needs at least 2x2 inner corners")
    return cols, rows


def _mount(text: str):
    from slamio.camera.model import T_robot_camera_from_mount

    try:
        values = [float(x) for x in text.split(",")]
        if len(values) != 6:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError("--mount is x,y,z,roll,pitch,yaw in metres and radians") from None
    return T_robot_camera_from_mount(*values)


def add_parser(verbs) -> argparse.ArgumentParser:
    from slamio.camera.model import DISTORTION_MODELS as MODELS  # not chessboard's: it loads OpenCV

    p = add_verb(
        verbs, "calibrate-camera",
        help=help_of("calibrate-camera"),
        description=DESCRIPTION,
        epilog="example:\n  fgslam calibrate-camera 'calib/*.png' --board 9x6 --square 0.025 "
               "--mount 0.10,0,0.30,0,0,0 --out kinect.yaml",
    )
    p.add_argument("images", nargs="+", metavar="IMAGE", help="image files or quoted glob patterns ('calib/*.png')")
    p.add_argument("--board", type=_board, required=True, metavar="COLSxROWS", help="inner corners, e.g. 9x6")
    p.add_argument("--square", type=float, required=True, metavar="M", help="side of one square in metres")
    p.add_argument("--model", choices=MODELS, default="plumb_bob", help="distortion model (default plumb_bob)")
    p.add_argument("--mount", type=_mount, default=None, metavar="X,Y,Z,ROLL,PITCH,YAW",
                   help="where the camera sits on the robot, metres and radians (default: docs/camera.md's mount)")
    p.add_argument("--name", default="camera", help="camera_name in the file (default camera)")
    p.add_argument("--out", required=True, metavar="CAM.yaml", help="the camera_info YAML to write")
    add_overwrite_option(p, "an existing --out file")
    p.set_defaults(func=cmd_calibrate_camera)
    return p


def _image_paths(patterns: list[str]) -> list[str]:
    """The files the arguments name (a quoted glob pattern expanded), each a regular file,
    else one :class:`InputFileError` line naming what matched nothing (before OpenCV is asked)."""
    from slamio.errors import InputFileError, check_regular

    paths = set()
    for pattern in patterns:
        matched = glob.glob(pattern) if glob.has_magic(pattern) else [pattern]
        if not matched:
            raise InputFileError(f"{pattern}: no file matches this pattern; give the chessboard pictures' paths "
                                 "(e.g. 'calib/*.png', quoted)")
        for path in matched:
            check_regular(path, "chessboard picture")
            paths.add(path)
    return sorted(paths)


@holds_outputs(out="--out")
def cmd_calibrate_camera(args: argparse.Namespace) -> int:
    import numpy as np

    from slamio.camera.chessboard import calibrate
    from slamio.camera.model import save_camera

    check_number("--square", args.square, above=0, what="the side of one square in metres")
    out = check_new_file(args.out, overwrite=args.overwrite, example="camera.yaml")
    paths = _image_paths(args.images)
    result = calibrate(paths, args.board, args.square, model=args.model, mount=args.mount, name=args.name)
    cam = result.camera
    for path in result.board_not_found:
        print(f"  board not found: {path}")
    for path, error in result.dropped:
        print(f"  dropped (RMS {error:.2f} px, > 3x the median): {path}")
    print(f"{len(result.used)} views, RMS reprojection error {result.rms_px:.3f} px")
    print(f"  fx {cam.fx:.2f}  fy {cam.fy:.2f}  cx {cam.cx:.2f}  cy {cam.cy:.2f}  "
          f"{cam.distortion_model} {np.array2string(cam.dist_coeffs, precision=4)}")
    comment = (f"written by fgslam calibrate-camera: {len(result.used)} views of a {args.board[0]}x{args.board[1]} "
               f"board, {args.square} m squares, RMS {result.rms_px:.3f} px")
    write_new_file(out, lambda tmp: save_camera(tmp, cam, comment=comment), overwrite=args.overwrite)
    print(f"wrote {out}")
    return 0
