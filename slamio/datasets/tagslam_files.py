"""Tag sizes and the camera's place on the robot, from the files TagSLAM users have.

**Tags file** (:func:`load_tags_file`): TagSLAM's ``tagslam.yaml`` — ``bodies:`` a list of
``{name: {default_tag_size, tags: [{id, size, pose}], odom_topic, T_body_odom}}`` and
``tagslam_parameters.pixel_noise`` — or a plain file with only ``default_tag_size`` and
``tags: [{id, size}]``. Read from it: every tag's side (the black square's edge, metres),
the default side for tags not listed, the corner detector's pixel noise when given, the
surveyed tag poses of static bodies (``pose: {position, rotation}``), and ``T_body_odom``
of the body that carries the odometry (where the odometry's frame sits on that body).

**Camera poses file** (:func:`load_camera_poses`): TagSLAM's ``camera_poses.yaml`` —
``cam0: {pose: {position: {x, y, z}, rotation: {x, y, z}}}``, the camera's pose on the rig
body. TagSLAM writes rotations as a rotation vector (axis × angle, radians).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from slamio.errors import InputFileError, read_text
from slamio.safe_input import parse_yaml

__all__ = ["TagsFile", "load_camera_poses", "load_tags_file", "pose_matrix", "rotation_from_rotvec"]

#: A landmark tag is between 1 cm and 10 m wide.
MIN_TAG_SIZE_M, MAX_TAG_SIZE_M = 0.01, 10.0


def rotation_from_rotvec(rotvec) -> np.ndarray:
    """3×3 rotation of an axis-angle vector (Rodrigues)."""
    v = np.asarray(rotvec, dtype=float)
    angle = float(np.linalg.norm(v))
    if angle < 1e-15:
        return np.eye(3)
    k = v / angle
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * Kx + (1 - math.cos(angle)) * Kx @ Kx


def pose_matrix(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


@dataclass
class TagsFile:
    """What a tags file says: sizes by id, the default size, pixel noise, surveyed poses."""

    path: str
    sizes_m: dict[int, float] = field(default_factory=dict)
    default_size_m: float | None = None
    pixel_noise_px: float | None = None
    surveyed: dict[int, np.ndarray] = field(default_factory=dict)  # id -> 4×4 pose in the map
    T_body_odom: np.ndarray | None = None

    def size_m(self, tag_id: int) -> float | None:
        return self.sizes_m.get(tag_id, self.default_size_m)


def _number(path: str, where: str, value: Any, low: float, high: float, what: str) -> float:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not (low <= float(value) <= high):
        raise InputFileError(f"{path}: {where} must be {what} between {low:g} and {high:g}, got {str(value)[:40]!r}")
    return float(value)


def _xyz(path: str, where: str, d: Any) -> np.ndarray:
    if not isinstance(d, dict) or not all(k in d for k in "xyz"):
        raise InputFileError(f"{path}: {where} must be a mapping {{x, y, z}}, got {str(d)[:60]!r}")
    return np.array([_number(path, f"{where}.{k}", d[k], -1e4, 1e4, "a number") for k in "xyz"])


def _pose(path: str, where: str, d: Any) -> np.ndarray:
    if not isinstance(d, dict) or "position" not in d or "rotation" not in d:
        raise InputFileError(f"{path}: {where} must hold position {{x, y, z}} and rotation {{x, y, z}} "
                             "(a rotation vector, radians)")
    return pose_matrix(rotation_from_rotvec(_xyz(path, f"{where}.rotation", d["rotation"])),
                       _xyz(path, f"{where}.position", d["position"]))


def _read_body(path: str, name: str, body: dict, out: TagsFile) -> None:
    where = f"bodies.{name}"
    if "default_tag_size" in body:
        out.default_size_m = _number(path, f"{where}.default_tag_size", body["default_tag_size"],
                                     MIN_TAG_SIZE_M, MAX_TAG_SIZE_M, "a tag side in metres")
    for i, tag in enumerate(body.get("tags") or []):
        if not isinstance(tag, dict) or not isinstance(tag.get("id"), int) or isinstance(tag.get("id"), bool):
            raise InputFileError(f"{path}: {where}.tags[{i}] must be a mapping with an integer id")
        tag_id = int(tag["id"])
        if "size" in tag:
            out.sizes_m[tag_id] = _number(path, f"{where}.tags[{i}].size", tag["size"], MIN_TAG_SIZE_M,
                                          MAX_TAG_SIZE_M, "a tag side in metres")
        if "pose" in tag and body.get("is_static", False):
            out.surveyed[tag_id] = _pose(path, f"{where}.tags[{i}].pose", tag["pose"])
    if "T_body_odom" in body:
        out.T_body_odom = _pose(path, f"{where}.T_body_odom", body["T_body_odom"])


def load_tags_file(path: str | os.PathLike[str]) -> TagsFile:
    """A TagSLAM ``tagslam.yaml`` or a plain tags file (module docstring)."""
    path = os.fspath(path)
    text = read_text(path, "tags file", "a tags file is TagSLAM's tagslam.yaml or a YAML file with "
                     "default_tag_size and tags: [{id, size}]")
    data = parse_yaml(path, text, fix="write a tags file: default_tag_size and tags: [{id, size}]").data
    if not isinstance(data, dict):
        raise InputFileError(f"{path}: a tags file is a YAML mapping (bodies: [...] or default_tag_size/tags)")
    out = TagsFile(path)
    params = data.get("tagslam_parameters")
    if isinstance(params, dict) and "pixel_noise" in params:
        out.pixel_noise_px = _number(path, "tagslam_parameters.pixel_noise", params["pixel_noise"], 1e-3, 100.0,
                                     "a pixel noise")
    bodies = data.get("bodies")
    if bodies is None:
        _read_body(path, "(top level)", data, out)
    elif not isinstance(bodies, list):
        raise InputFileError(f"{path}: bodies must be a list of {{name: {{...}}}} mappings")
    else:
        for i, item in enumerate(bodies):
            if not isinstance(item, dict) or len(item) != 1 or not isinstance(next(iter(item.values())), dict):
                raise InputFileError(f"{path}: bodies[{i}] must be one mapping {{name: {{...}}}}")
            name, body = next(iter(item.items()))
            _read_body(path, str(name), body, out)
    if not out.sizes_m and out.default_size_m is None:
        raise InputFileError(f"{path}: no tag size found (default_tag_size, or tags: [{{id, size}}])")
    return out


def load_camera_poses(path: str | os.PathLike[str], name: str | None = None) -> np.ndarray:
    """The 4×4 pose of camera ``name`` (or the only one) on its rig, from a TagSLAM camera_poses.yaml."""
    path = os.fspath(path)
    text = read_text(path, "camera poses file", "TagSLAM's camera_poses.yaml: cam0: {pose: {position, rotation}}")
    data = parse_yaml(path, text, fix="write cam0: {pose: {position: {x, y, z}, rotation: {x, y, z}}}").data
    cams = {k: v for k, v in data.items() if isinstance(v, dict) and "pose" in v} if isinstance(data, dict) else {}
    if not cams:
        raise InputFileError(f"{path}: no camera with a pose (cam0: {{pose: {{position, rotation}}}})")
    if name is None and len(cams) > 1:
        raise InputFileError(f"{path}: holds cameras {', '.join(sorted(cams))}; pick one with --camera-name")
    name = name if name is not None else next(iter(cams))
    if name not in cams:
        raise InputFileError(f"{path}: no camera {name!r}; the file's cameras: {', '.join(sorted(cams))}")
    return _pose(path, f"{name}.pose", cams[name]["pose"])
