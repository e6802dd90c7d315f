"""Camera model: intrinsics and distortion from a ROS ``camera_info`` YAML, and the mount.

Frames
======

- **Camera (optical) frame**: x right, y down, z forward along the optical axis (OpenCV's
  and ROS's ``*_optical_frame``). Pixels ``(u, v)``: u to the right, v down, with the
  centre of the top-left pixel at (0, 0) (OpenCV's convention; the AprilTag library puts
  that pixel's top-left *corner* at (0, 0), see :mod:`slamio.camera.apriltag`).
- **Robot frame**: x forward, y left, z up, origin on the floor under the robot's centre.
- ``T_robot_camera`` (4×4) maps camera-frame points into the robot frame:
  ``p_robot = R_robot_camera @ p_camera + t_robot_camera``. Its translation's z is the
  optical centre's height above the floor.

The file
========

The ROS ``camera_info`` YAML that ``camera_calibration`` and
``fgslam calibrate-camera`` write, plus one optional key for the mount::

    image_width: 640
    image_height: 480
    camera_name: kinect_rgb
    camera_matrix: {rows: 3, cols: 3, data: [525.0, 0, 319.5, 0, 525.0, 239.5, 0, 0, 1]}
    distortion_model: plumb_bob
    distortion_coefficients: {rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}
    robot_mount: {x_m: 0.10, y_m: 0.0, z_m: 0.30, roll_rad: 0.0, pitch_rad: 0.0, yaw_rad: 0.0}

``robot_mount`` places the camera's *body* (x forward, y left, z up) on the robot: position
in metres and roll/pitch/yaw about the robot's x, y, z axes (``pitch_rad > 0`` tilts the
camera down). Instead of it, ``T_robot_camera: {rows: 4, cols: 4, data: [...]}`` gives the
optical frame's pose directly. Without either, the camera sits at the robot's origin
(height 0), looking forward. ``rectification_matrix`` and ``projection_matrix`` are read
past (a monocular camera's are the identity and K).

Distortion models: ``plumb_bob`` (k1 k2 p1 p2 [k3]) and ``rational_polynomial`` (8
coefficients) go to OpenCV's standard model; ``equidistant`` (k1..k4) to ``cv2.fisheye``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from slamio.errors import InputFileError
from slamio.safe_input import Document

#: Rotation taking optical-frame vectors (x right, y down, z forward) into a body frame
#: (x forward, y left, z up): columns are the optical axes expressed in the body frame.
R_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

DISTORTION_MODELS = ("plumb_bob", "rational_polynomial", "equidistant")


class CameraConfigError(InputFileError):
    """A camera file that cannot be used: says which file (and line), which key, and how to
    fix it (``fgslam`` exits with status 2)."""


#: Bounds on a camera file's numbers, each far beyond any real camera, so that no product
#: the projection takes overflows: the image's side (px), focal lengths, principal point
#: and |distortion coefficients|, and the mount's offsets (m) and angles (rad).
MAX_IMAGE_SIDE_PX = 100_000
MAX_FOCAL_PX = 1e6
MAX_DISTORTION = 1e6
MAX_MOUNT_M = 1e3
MAX_MOUNT_RAD = 1e3


# --------------------------------------------------------------------------- pure maths


def rotation_x(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def T_robot_camera_from_mount(
    x_m: float = 0.0, y_m: float = 0.0, z_m: float = 0.0,
    roll_rad: float = 0.0, pitch_rad: float = 0.0, yaw_rad: float = 0.0,
) -> np.ndarray:
    """4×4 ``T_robot_camera`` (optical frame) of a camera body mounted at this pose.

    The body's attitude is ``Rz(yaw) · Ry(pitch) · Rx(roll)`` in the robot frame; positive
    pitch turns the body's x axis towards −z (the camera looks down).
    """
    T = np.eye(4)
    T[:3, :3] = rotation_z(yaw_rad) @ rotation_y(pitch_rad) @ rotation_x(roll_rad) @ R_BODY_OPTICAL
    T[:3, 3] = (x_m, y_m, z_m)
    return T


def transform_points(T_a_b: np.ndarray, p_b: np.ndarray) -> np.ndarray:
    """Apply a 4×4 transform to (N, 3) points (or one 3-vector)."""
    p = np.asarray(p_b, dtype=float)
    return p @ T_a_b[:3, :3].T + T_a_b[:3, 3]


def invert_transform(T_a_b: np.ndarray) -> np.ndarray:
    R, t = T_a_b[:3, :3], T_a_b[:3, 3]
    T = np.eye(4)
    T[:3, :3] = R.T
    T[:3, 3] = -R.T @ t
    return T


def floor_range_bearing(p_robot: np.ndarray) -> tuple[float, float]:
    """(range_m, bearing_rad) of a robot-frame point projected onto the floor plane."""
    x, y = float(p_robot[0]), float(p_robot[1])
    return math.hypot(x, y), math.atan2(y, x)


# --------------------------------------------------------------------------- the model


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A calibrated camera: pinhole intrinsics, lens distortion, and where it sits on the robot."""

    width_px: int
    height_px: int
    K: np.ndarray  # 3×3 camera matrix
    dist_coeffs: np.ndarray = field(default_factory=lambda: np.zeros(5))
    distortion_model: str = "plumb_bob"
    T_robot_camera: np.ndarray = field(default_factory=lambda: T_robot_camera_from_mount())
    name: str = "camera"

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist_coeffs != 0.0))

    @property
    def horizontal_fov_rad(self) -> float:
        """Full horizontal field of view of the pinhole (distortion ignored)."""
        return math.atan((self.width_px - 1 - self.cx + 0.5) / self.fx) + math.atan((self.cx + 0.5) / self.fx)

    def size_mismatch(self, width_px: int, height_px: int) -> str | None:
        """Why an image of ``width_px`` × ``height_px`` does not fit this camera (``None``: it
        does), naming a file that gives the size height first (TagSLAM's test_22 does)."""
        if (width_px, height_px) == (self.width_px, self.height_px):
            return None
        text = f"the image is {width_px}×{height_px} pixels but the camera file says {self.width_px}×{self.height_px}"
        if (width_px, height_px) == (self.height_px, self.width_px):
            text += (" (the file gives the size height first: Kalibr's resolution is [width, height], "
                     "a camera_info's image_width then image_height)")
        return text

    def with_mount(self, T_robot_camera: np.ndarray) -> "CameraModel":
        return CameraModel(self.width_px, self.height_px, self.K, self.dist_coeffs,
                           self.distortion_model, np.asarray(T_robot_camera, dtype=float), self.name)

    def normalized(self, uv_px: np.ndarray) -> np.ndarray:
        """Undistorted normalized image coordinates (x/z, y/z) of (N, 2) pixels."""
        import cv2

        uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 1, 2)
        if uv.shape[0] == 0:
            return np.zeros((0, 2))
        if self.distortion_model == "equidistant":
            out = cv2.fisheye.undistortPoints(uv, self.K, self.dist_coeffs[:4].reshape(4, 1))
        elif self.has_distortion:
            criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
            out = _undistort_iter(uv, self.K, self.dist_coeffs, criteria)
        else:
            xy = (uv.reshape(-1, 2) - (self.cx, self.cy)) / (self.fx, self.fy)
            return xy
        return out.reshape(-1, 2)

    def rays_camera(self, uv_px: np.ndarray) -> np.ndarray:
        """(N, 3) camera-frame rays with z = 1 through (N, 2) pixels."""
        xy = self.normalized(uv_px)
        return np.column_stack([xy, np.ones(len(xy))])

    def project(self, p_camera: np.ndarray) -> np.ndarray:
        """(N, 2) pixels of (N, 3) camera-frame points (in front of the camera)."""
        import cv2

        p = np.asarray(p_camera, dtype=np.float64).reshape(-1, 3)
        if self.distortion_model == "equidistant":
            out = cv2.fisheye.projectPoints(p.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.K,
                                            self.dist_coeffs[:4].reshape(4, 1))[0]
            return out.reshape(-1, 2)
        if not self.has_distortion:
            xy = p[:, :2] / p[:, 2:3]
            return xy * (self.fx, self.fy) + (self.cx, self.cy)
        out = cv2.projectPoints(p, np.zeros(3), np.zeros(3), self.K, self.dist_coeffs)[0]
        return out.reshape(-1, 2)

    def backproject(self, uv_px: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
        """(N, 3) camera-frame points of pixels with their depth (z along the optical axis)."""
        rays = self.rays_camera(uv_px)
        return rays * np.asarray(depth_m, dtype=float).reshape(-1, 1)


def _undistort_iter(uv: np.ndarray, K: np.ndarray, D: np.ndarray, criteria: tuple) -> np.ndarray:
    """cv2.undistortPoints with a termination criterion (the OpenCV 4 and 5 spellings differ)."""
    import cv2

    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x
        return cv2.undistortPointsIter(uv, K, D, None, None, criteria)
    return cv2.undistortPoints(uv, K, D, None, None, None, criteria)


def kinect_v1_default(T_robot_camera: np.ndarray | None = None) -> CameraModel:
    """The Kinect v1 RGB camera with the TUM RGB-D default intrinsics (fx = fy = 525)."""
    K = np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])
    return CameraModel(640, 480, K, np.zeros(5), "plumb_bob",
                       T_robot_camera_from_mount() if T_robot_camera is None else np.asarray(T_robot_camera, float),
                       "kinect_v1_rgb")


# --------------------------------------------------------------------------- the file


def _matrix(path: str, d: dict, key: str, rows: int | None, cols: int | None) -> np.ndarray:
    value = d.get(key)
    if not isinstance(value, dict) or "data" not in value:
        raise CameraConfigError(
            f"{path}: '{key}' must be a mapping {{rows: R, cols: C, data: [...]}} as in a ROS camera_info file"
        )
    data = value["data"]
    if not isinstance(data, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in data):
        raise CameraConfigError(f"{path}: '{key}.data' must be a list of numbers")
    r = value.get("rows", rows)
    c = value.get("cols", cols)
    if not isinstance(r, int) or not isinstance(c, int) or r * c != len(data):
        raise CameraConfigError(
            f"{path}: '{key}' says rows={r}, cols={c} but has {len(data)} numbers; make rows·cols match data"
        )
    if (rows is not None and r != rows) or (cols is not None and c != cols):
        raise CameraConfigError(f"{path}: '{key}' must be {rows}×{cols}, got {r}×{c}")
    m = np.array(data, dtype=float).reshape(r, c)
    if not np.all(np.isfinite(m)):
        raise CameraConfigError(f"{path}: '{key}' holds a non-finite number")
    return m


def _bounded(path: str, key: str, values, limit: float, unit: str) -> None:
    """Every value within ±``limit``, else one line naming the key."""
    worst = float(np.max(np.abs(values))) if np.size(values) else 0.0
    if worst > limit:
        raise CameraConfigError(f"{path}: '{key}' holds {worst:g}, beyond ±{limit:g} {unit}; no camera has such a "
                                "value: check the file (units are pixels, metres and radians)")


def _positive_int(path: str, d: dict, key: str) -> int:
    value = d.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 < value <= MAX_IMAGE_SIDE_PX:
        raise CameraConfigError(f"{path}: '{key}' must be a positive integer of pixels up to {MAX_IMAGE_SIDE_PX}, "
                                f"got {value!r}")
    return value


def _mount(path: str, d: dict) -> np.ndarray:
    if "T_robot_camera" in d and "robot_mount" in d:
        raise CameraConfigError(f"{path}: give either 'robot_mount' or 'T_robot_camera', not both")
    if "T_robot_camera" in d:
        T = _matrix(path, d, "T_robot_camera", 4, 4)
        _bounded(path, "T_robot_camera", T[:3, 3], MAX_MOUNT_M, "m")
        R = T[:3, :3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or not np.allclose(T[3], (0, 0, 0, 1)) \
                or np.linalg.det(R) < 0:
            raise CameraConfigError(
                f"{path}: 'T_robot_camera' must be a rigid transform (orthonormal rotation, det +1, "
                "last row 0 0 0 1)"
            )
        return T
    mount = d.get("robot_mount")
    if mount is None:
        return T_robot_camera_from_mount()
    if not isinstance(mount, dict):
        raise CameraConfigError(f"{path}: 'robot_mount' must be a mapping {{x_m: .., z_m: .., pitch_rad: ..}}")
    allowed = ("x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "yaw_rad")
    unknown = sorted(set(mount) - set(allowed))
    if unknown:
        raise CameraConfigError(
            f"{path}: unknown key(s) {', '.join(unknown)} in 'robot_mount'; allowed: {', '.join(allowed)} "
            "(metres and radians)"
        )
    values = {}
    for k in allowed:
        v = mount.get(k, 0.0)
        limit = MAX_MOUNT_M if k.endswith("_m") else MAX_MOUNT_RAD
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not abs(v) <= limit:
            raise CameraConfigError(f"{path}: 'robot_mount.{k}' must be a finite number within ±{limit:g} "
                                    f"({'metres' if k.endswith('_m') else 'radians'})")
        values[k] = float(v)
    return T_robot_camera_from_mount(**values)


def _check_principal_point(path: str, K: np.ndarray, width: int, height: int) -> None:
    """A calibration puts the principal point (cx, cy) inside the image, near its centre; one
    outside it (a mistyped digit, another camera's width) would give every bearing wrong."""
    cx, cy = float(K[0, 2]), float(K[1, 2])
    outside = [f"{name} = {value:g} px is not inside the image_{side} of {size} px (-0.5..{size - 0.5:g})"
               for name, value, size, side in (("cx", cx, width, "width"), ("cy", cy, height, "height"))
               if not (-0.5 <= value <= size - 0.5)]
    if outside:
        raise CameraConfigError(
            f"{path}: the principal point in 'camera_matrix' lies outside the {width}×{height} image: "
            f"{' and '.join(outside)}; a calibration puts it inside the image, near its centre "
            f"(about {(width - 1) / 2:g}, {(height - 1) / 2:g}): check cx and cy in "
            "[fx, 0, cx, 0, fy, cy, 0, 0, 1] (a mistyped digit?) and image_width / image_height, or calibrate again"
        )


def camera_from_dict(d: Any, path: str = "<camera>", doc: Document | None = None) -> CameraModel:
    """Build a :class:`CameraModel` from a parsed camera_info mapping (see the module doc);
    with ``doc`` (the file it was read from) each error names the line of its key."""

    def at(key: str) -> str:
        return doc.where(key) if doc is not None else path

    if not isinstance(d, dict):
        raise CameraConfigError(f"{path}: not a camera_info YAML mapping (image_width, camera_matrix, ...)")
    width = _positive_int(at("image_width"), d, "image_width")
    height = _positive_int(at("image_height"), d, "image_height")
    K = _matrix(at("camera_matrix"), d, "camera_matrix", 3, 3)
    if not (K[0, 0] > 0 and K[1, 1] > 0) or not np.allclose(K[2], (0, 0, 1)) or K[1, 0] != 0:
        raise CameraConfigError(
            f"{at('camera_matrix')}: 'camera_matrix' must be [fx, s, cx, 0, fy, cy, 0, 0, 1] with fx, fy > 0"
        )
    _bounded(at("camera_matrix"), "camera_matrix", K, MAX_FOCAL_PX, "px")
    _check_principal_point(at("camera_matrix"), K, width, height)
    model = d.get("distortion_model", "plumb_bob")
    if model not in DISTORTION_MODELS:
        raise CameraConfigError(
            f"{at('distortion_model')}: distortion_model {str(model)[:40]!r} is not supported; use one of "
            f"{', '.join(DISTORTION_MODELS)}"
        )
    if "distortion_coefficients" in d:
        D = _matrix(at("distortion_coefficients"), d, "distortion_coefficients", None, None).ravel()
        _bounded(at("distortion_coefficients"), "distortion_coefficients", D, MAX_DISTORTION, "")
    else:
        D = np.zeros(4 if model == "equidistant" else 5)
    expected = {"plumb_bob": (4, 5), "rational_polynomial": (8,), "equidistant": (4,)}[model]
    if len(D) not in expected:
        raise CameraConfigError(
            f"{at('distortion_coefficients')}: distortion_model {model} takes {' or '.join(map(str, expected))} "
            f"coefficients, got {len(D)}"
        )
    mount = at("T_robot_camera") if "T_robot_camera" in d else at("robot_mount")
    return CameraModel(width, height, K, D, model, _mount(mount, d), str(d.get("camera_name", "camera")))


def load_camera(path: str | os.PathLike[str], name: str | None = None) -> CameraModel:
    """Read a camera file into a :class:`CameraModel`: a ROS camera_info YAML (plus the
    optional mount) or a Kalibr ``cameras.yaml`` (camera ``name``, or its only camera). One
    reader for both: :func:`slamio.camera.camera_files.load_camera_file`."""
    from slamio.camera.camera_files import load_camera_file  # it builds on this module

    return load_camera_file(path, name)


def camera_to_dict(camera: CameraModel) -> dict[str, Any]:
    """The camera_info mapping of a model (the mount as ``T_robot_camera``)."""
    K = camera.K
    P = np.zeros((3, 4))
    P[:3, :3] = K
    return {
        "image_width": int(camera.width_px),
        "image_height": int(camera.height_px),
        "camera_name": camera.name,
        "camera_matrix": {"rows": 3, "cols": 3, "data": [float(x) for x in K.ravel()]},
        "distortion_model": camera.distortion_model,
        "distortion_coefficients": {"rows": 1, "cols": len(camera.dist_coeffs),
                                    "data": [float(x) for x in camera.dist_coeffs]},
        "rectification_matrix": {"rows": 3, "cols": 3, "data": [float(x) for x in np.eye(3).ravel()]},
        "projection_matrix": {"rows": 3, "cols": 4, "data": [float(x) for x in P.ravel()]},
        "T_robot_camera": {"rows": 4, "cols": 4, "data": [float(x) for x in camera.T_robot_camera.ravel()]},
    }


def save_camera(path: str | os.PathLike[str], camera: CameraModel, comment: str = "") -> None:
    """Write a camera_info YAML that :func:`load_camera` (and ROS) can read."""
    import yaml

    text = yaml.safe_dump(camera_to_dict(camera), sort_keys=False, default_flow_style=None)
    header = "".join(f"# {line}\n" for line in comment.splitlines())
    with open(path, "w", encoding="utf-8") as f:
        f.write(header + text)
