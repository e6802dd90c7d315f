"""Camera files people already have: a Kalibr ``cameras.yaml``, a ROS camera_info YAML, or a
``sensor_msgs/CameraInfo`` message in a bag — each read into a :class:`CameraModel`.

Kalibr (``kalibr_calibrate_cameras`` output; TagSLAM's ``cameras.yaml`` is the same)::

    cam0:
      camera_model: pinhole                 # the only projection model read here
      intrinsics: [fu, fv, pu, pv]          # pixels
      distortion_model: equidistant         # or radtan (= ROS plumb_bob: k1 k2 p1 p2), or none
      distortion_coeffs: [k1, k2, k3, k4]
      resolution: [width, height]           # pixels

One file may hold several cameras (``cam0``, ``cam1``, ...): ``name`` picks one, and a file
with one camera needs no name. A ROS camera_info YAML (``image_width``, ``camera_matrix``,
...) goes to :func:`slamio.camera.model.camera_from_dict`, which reads ``robot_mount`` too.
A Kalibr file says nothing of where the camera sits on the robot: the caller places it.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from slamio.camera.model import CameraConfigError, CameraModel, camera_from_dict
from slamio.errors import read_text
from slamio.safe_input import Document, parse_yaml

__all__ = ["KALIBR_DISTORTION", "camera_from_camera_info_message", "camera_from_kalibr", "load_camera_file"]

#: Kalibr's distortion model → the ROS name :class:`CameraModel` uses.
KALIBR_DISTORTION = {"equidistant": "equidistant", "radtan": "plumb_bob", "none": "plumb_bob"}


def load_camera_file(path: str | os.PathLike[str], name: str | None = None) -> CameraModel:
    """A Kalibr ``cameras.yaml`` (camera ``name``, or its only camera) or a ROS camera_info
    YAML, whichever the file is; :class:`CameraConfigError` naming the file, line and key."""
    path = os.fspath(path)
    text = read_text(path, "camera file", "a camera file is a UTF-8 YAML file: a ROS camera_info file (fgslam "
                     "calibrate-camera writes one; docs/camera.md) or a Kalibr cameras.yaml "
                     "(docs/datasets-mrclam-rosbag.md)", CameraConfigError)
    doc = parse_yaml(path, text, error=CameraConfigError, fix="write a ROS camera_info or Kalibr cameras.yaml file")
    data = doc.data
    if isinstance(data, dict) and "image_width" in data:
        if name is not None and str(data.get("camera_name", name)) != name:
            raise CameraConfigError(f"{path}: a ROS camera_info file of camera {data.get('camera_name')!r}, "
                                    f"not {name!r}; leave out --camera-name or give that camera's file")
        return camera_from_dict(data, path, doc)
    return camera_from_kalibr(data, path, name, doc)


def _kalibr_camera(d: Any, path: str, name: str | None) -> tuple[str, dict]:
    """The chosen camera's mapping of a Kalibr file."""
    cameras = {k: v for k, v in d.items() if isinstance(v, dict) and "intrinsics" in v} if isinstance(d, dict) else {}
    if not cameras:
        raise CameraConfigError(f"{path}: neither a ROS camera_info file (image_width, camera_matrix, ...) nor a "
                                "Kalibr cameras.yaml (cam0: {camera_model, intrinsics, distortion_model, "
                                "distortion_coeffs, resolution})")
    if name is None:
        if len(cameras) > 1:
            raise CameraConfigError(f"{path}: holds cameras {', '.join(sorted(cameras))}; pick one with --camera-name")
        name = next(iter(cameras))
    if name not in cameras:
        raise CameraConfigError(f"{path}: no camera {name!r}; the file's cameras: {', '.join(sorted(cameras))}")
    return name, cameras[name]


def _numbers(where: str, cam: dict, key: str, count: tuple[int, ...]) -> list[float]:
    value = cam.get(key)
    if (not isinstance(value, list) or len(value) not in count
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise CameraConfigError(f"{where}: '{key}' must be a list of {' or '.join(map(str, count))} numbers, "
                                f"got {str(value)[:60]!r}")
    return [float(v) for v in value]


def camera_from_kalibr(d: Any, path: str = "<camera>", name: str | None = None, doc: Document | None = None
                       ) -> CameraModel:
    """The camera ``name`` of a parsed Kalibr mapping (module docstring) as a :class:`CameraModel`
    (checked like a camera_info file: focal lengths, principal point, coefficient counts)."""
    name, cam = _kalibr_camera(d, path, name)

    def at(key: str) -> str:
        return doc.where(name, key) if doc is not None else f"{path}: {name}.{key}"

    projection = cam.get("camera_model", "pinhole")
    if projection != "pinhole":
        raise CameraConfigError(f"{at('camera_model')}: camera_model {str(projection)[:30]!r} is not supported; "
                                "fgslam reads Kalibr's pinhole model (with equidistant or radtan distortion)")
    model = cam.get("distortion_model", "none")
    if model not in KALIBR_DISTORTION:
        raise CameraConfigError(f"{at('distortion_model')}: distortion_model {str(model)[:30]!r} is not supported; "
                                f"use one of {', '.join(KALIBR_DISTORTION)}")
    fu, fv, pu, pv = _numbers(at("intrinsics"), cam, "intrinsics", (4,))
    width, height = _numbers(at("resolution"), cam, "resolution", (2,))
    expected = (0,) if model == "none" else (4,)
    coeffs = _numbers(at("distortion_coeffs"), cam, "distortion_coeffs", expected) if model != "none" else []
    info = {
        "image_width": int(width), "image_height": int(height), "camera_name": name,
        "camera_matrix": {"rows": 3, "cols": 3, "data": [fu, 0.0, pu, 0.0, fv, pv, 0.0, 0.0, 1.0]},
        "distortion_model": KALIBR_DISTORTION[model],
        "distortion_coefficients": {"rows": 1, "cols": len(coeffs) or 5, "data": coeffs or [0.0] * 5},
    }
    if int(width) != width or int(height) != height:
        raise CameraConfigError(f"{at('resolution')}: 'resolution' must be whole pixels [width, height], "
                                f"got {[width, height]}")
    return camera_from_dict(info, f"{path}: camera {name}")


def camera_from_camera_info_message(msg: Any, where: str) -> CameraModel:
    """A ``sensor_msgs/CameraInfo`` message (ROS 1 ``K``/``D`` or ROS 2 ``k``/``d``) as a
    :class:`CameraModel`; ``where`` names the bag and topic in an error."""
    K = getattr(msg, "K", getattr(msg, "k", None))
    D = getattr(msg, "D", getattr(msg, "d", None))
    if K is None or D is None:
        raise CameraConfigError(f"{where}: not a sensor_msgs/CameraInfo message (no K and D fields)")
    model = str(msg.distortion_model) or "plumb_bob"
    if model == "fisheye":  # what some drivers call the equidistant model
        model = "equidistant"
    D = [float(v) for v in np.asarray(D, dtype=float).ravel()]
    if model == "plumb_bob" and not D:
        D = [0.0] * 5
    info = {
        "image_width": int(msg.width), "image_height": int(msg.height), "camera_name": str(msg.header.frame_id),
        "camera_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in np.asarray(K, dtype=float).ravel()]},
        "distortion_model": model,
        "distortion_coefficients": {"rows": 1, "cols": len(D), "data": D},
    }
    return camera_from_dict(info, where)
