"""Tag corners in pixels (``apriltag_msgs/ApriltagArrayStamped``) → one tag observation.

The MIT / KumarRobotics detector that publishes ``apriltag_msgs`` (and TagSLAM, which reads
it) reports each tag's four corners "counter-clockwise around the target, always starting
from the same corner" (AprilTags C++ ``TagDetection::p``), and its pose code pairs them with
the tag-frame points ``(-s,-s), (s,-s), (s,s), (-s,s)``/2 (x right, y up on the printed
tag): bottom-left, bottom-right, top-right, top-left. OpenCV's IPPE square wants top-left,
top-right, bottom-right, bottom-left — the same corners backwards
(:func:`opencv_corners_from_mit`). The pose (:func:`slamio.camera.apriltag.estimate_tag_pose`,
corners undistorted through the camera model, pinhole or equidistant fisheye), refined by
Gauss–Newton on the corners in pixels (the maximum-likelihood pose under the pixel noise),
is checked by its RMS reprojection error: above ``max_reprojection_px`` the detection is refused (a wrong
corner order, a wrong tag size or camera, a misdetection). A mirrored corner order
reprojects just as well (a square seen from behind): it is caught because the tag's printed
face would then point away from the camera.

**Noise from the geometry.** Each corner is taken as known to ``pixel_sigma_px`` in u and v,
independently. The pose's covariance is the Gauss–Newton one of the 8 corner residuals,
``Σ_pose = σ_px² (JᵀJ)⁻¹`` (J: pixels w.r.t. rotation vector and translation, through the
lens model), and range, bearing, tag yaw and height follow by first-order propagation
(``Σ = G Σ_pose Gᵀ``, G numerical). So the range σ grows with the square of the distance and
shrinks with the tag's size and the focal length; the bearing σ is about σ_px/f. When the two
IPPE solutions fit about as well (a small or frontal tag: the "flip"), the yaw σ is at least
half the two solutions' yaw difference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slamio.camera.apriltag import TagPose, choose_tag_pose, estimate_tag_pose, rodrigues, tag_geometry, tag_object_points
from slamio.camera.model import CameraModel
from slamio.geometry import wrap_angle

__all__ = ["CornerObservation", "corner_observation", "opencv_corners_from_mit", "pose_covariance"]

#: Default bound on a pose's RMS reprojection error (pixels) before the detection is refused.
DEFAULT_MAX_REPROJECTION_PX = 3.0
#: A tag's face normal within this of vertical has no meaningful yaw (as rosbag_messages).
MIN_NORMAL_HORIZONTAL = 0.5


def opencv_corners_from_mit(corners_px) -> np.ndarray:
    """(4, 2) corners in the MIT detector's order (BL, BR, TR, TL) → OpenCV's (TL, TR, BR, BL)."""
    return np.asarray(corners_px, dtype=float).reshape(4, 2)[::-1].copy()


@dataclass(frozen=True)
class CornerObservation:
    """A tag seen from the level robot frame, with σ from the corner noise."""

    range_m: float
    bearing_rad: float
    tag_yaw_rad: float | None
    height_m: float
    sigma_range_m: float
    sigma_bearing_rad: float
    sigma_tag_yaw_rad: float | None
    sigma_height_m: float
    reprojection_px: float
    ambiguous: bool


def _project(camera: CameraModel, params: np.ndarray, object_points: np.ndarray) -> np.ndarray:
    R = rodrigues(params[:3])
    p = object_points @ R.T + params[3:]
    return camera.project(p).ravel()


def _jacobian(camera: CameraModel, params: np.ndarray, obj: np.ndarray) -> np.ndarray:
    J = np.zeros((8, 6))
    steps = np.array([1e-6] * 3 + [1e-6 * max(1.0, float(np.linalg.norm(params[3:])))] * 3)
    for k in range(6):
        d = np.zeros(6)
        d[k] = steps[k]
        J[:, k] = (_project(camera, params + d, obj) - _project(camera, params - d, obj)) / (2 * steps[k])
    return J


def pose_covariance(camera: CameraModel, pose: TagPose, tag_size_m: float, pixel_sigma_px: float,
                    corners_px: np.ndarray | None = None, iterations: int = 5
                    ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(params, Σ, RMS px): the pose as (rotation vector, translation), refined by Gauss–Newton
    on the ``corners_px`` (OpenCV order) in pixels when given — IPPE solves in undistorted
    coordinates, where a fisheye's pixel noise is not uniform — its 6×6 covariance from
    ``pixel_sigma_px`` per corner coordinate, and the RMS pixel residual; None when the
    geometry leaves the pose unobservable."""
    import cv2

    rvec = cv2.Rodrigues(np.asarray(pose.R_camera_tag, dtype=float))[0].ravel()
    params = np.concatenate([rvec, np.asarray(pose.t_camera_tag_m, dtype=float)])
    obj = tag_object_points(tag_size_m)
    target = None if corners_px is None else np.asarray(corners_px, dtype=float).ravel()
    for _ in range(iterations if target is not None else 0):
        J = _jacobian(camera, params, obj)
        r = target - _project(camera, params, obj)
        try:
            step = np.linalg.lstsq(J, r, rcond=None)[0]
        except np.linalg.LinAlgError:
            return None
        params = params + step
        if np.max(np.abs(step)) < 1e-10:
            break
    J = _jacobian(camera, params, obj)
    JtJ = J.T @ J
    if not np.all(np.isfinite(JtJ)) or np.linalg.cond(JtJ) > 1e14:
        return None
    rms = float("nan") if target is None else float(np.sqrt(np.mean(
        np.sum((target - _project(camera, params, obj)).reshape(4, 2) ** 2, axis=1))))
    return params, pixel_sigma_px ** 2 * np.linalg.inv(JtJ), rms


def _geometry(params: np.ndarray, T_level_camera: np.ndarray) -> np.ndarray:
    g = tag_geometry(TagPose(rodrigues(params[:3]), params[3:], 0.0), T_level_camera)
    return np.array([g.range_m, g.bearing_rad, g.tag_yaw_rad, g.height_m])


def corner_observation(corners_mit_px, tag_size_m: float, camera: CameraModel, T_level_camera: np.ndarray,
                       pixel_sigma_px: float, max_reprojection_px: float = DEFAULT_MAX_REPROJECTION_PX
                       ) -> CornerObservation | str:
    """The observation of one detection, or the reason it is refused (``"no_pose"``,
    ``"reprojection"``, ``"behind_camera"``, ``"facing_away"``, ``"unobservable"``). ``T_level_camera`` (4×4)
    places the camera's optical frame in the level robot frame at the detection's time."""
    corners = opencv_corners_from_mit(corners_mit_px)
    poses = estimate_tag_pose(corners, tag_size_m, camera)
    if not poses:
        return "no_pose"
    pose, ambiguous = choose_tag_pose(poses, T_level_camera)
    if not pose.reprojection_error_px <= max_reprojection_px:
        return "reprojection"
    if pose.t_camera_tag_m[2] <= 0.0:
        return "behind_camera"
    if float(np.dot(pose.R_camera_tag[:, 2], pose.t_camera_tag_m)) >= 0.0:
        return "facing_away"  # the printed face turned from the camera: corners in the mirrored order
    solved = pose_covariance(camera, pose, tag_size_m, pixel_sigma_px, corners)
    if solved is None or not math.isfinite(solved[2]):
        return "unobservable"
    params, cov, rms_px = solved
    if not rms_px <= max_reprojection_px:
        return "reprojection"
    g0 = _geometry(params, T_level_camera)
    G = np.zeros((4, 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = 1e-6
        diff = _geometry(params + d, T_level_camera) - _geometry(params - d, T_level_camera)
        diff[1:3] = [wrap_angle(v) for v in diff[1:3]]
        G[:, k] = diff / 2e-6
    sig = np.sqrt(np.maximum(np.diag(G @ cov @ G.T), 0.0))
    normal = T_level_camera[:3, :3] @ pose.R_camera_tag[:, 2]
    has_yaw = math.hypot(normal[0], normal[1]) >= MIN_NORMAL_HORIZONTAL
    sigma_yaw = float(sig[2])
    if has_yaw and ambiguous and len(poses) > 1:
        other = next(p for p in poses[:2] if p is not pose)
        other_yaw = tag_geometry(other, T_level_camera).tag_yaw_rad
        sigma_yaw = max(sigma_yaw, 0.5 * abs(float(wrap_angle(other_yaw - g0[2]))))
    return CornerObservation(
        float(g0[0]), float(g0[1]), float(g0[2]) if has_yaw else None, float(g0[3]),
        float(sig[0]), float(sig[1]), min(sigma_yaw, math.pi) if has_yaw else None, float(sig[3]),
        rms_px, bool(ambiguous),
    )
