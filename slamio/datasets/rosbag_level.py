"""Odometry as it comes: the full 3-D pose, levelled when its frame is not, and what it loses
on the way to the plane said out loud.

A planar log needs the odometry frame's z axis to point up. A VIO or camera odometry frame
may not (the camera's optical frame at start-up, z forward). The robot's own z axis at the
first pose is taken as "up" (a ground robot starts on the floor): its angle to the frame's z
is the **first-pose tilt**. With ``level="auto"`` a tilt above ``level_threshold_deg``
(30°: more than a robot stands tilted) means the frame is not level, and every pose is turned
by the smallest rotation taking that axis to vertical (:func:`levelling_rotation`); a smaller
tilt is taken as the body's own tilt on a level frame and kept. ``"first-pose"`` always
levels, ``"none"`` never.

Each pose's heading is the yaw of its attitude (Z-Y-X); its roll and pitch are not thrown
away: a detection made at that time is turned by them (:func:`tilt_at`) into the level robot
frame before its range and bearing on the floor are taken, so a handheld or bumping camera
still gives the floor-plane geometry. What is left out — the height change and the tilt — is
reported (:func:`out_of_plane`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["LEVEL_MODES", "Attitudes", "levelling_rotation", "out_of_plane", "rotation_z"]

LEVEL_MODES = ("auto", "first-pose", "none")
DEFAULT_LEVEL_THRESHOLD_DEG = 30.0


def rotation_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _matrix(q) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(np.asarray(q, dtype=float)).as_matrix()


def tilt_deg(R: np.ndarray) -> float:
    """Angle between a body's z axis (column 2 of its attitude) and the frame's z, degrees."""
    return math.degrees(math.acos(max(-1.0, min(1.0, float(R[2, 2])))))


def levelling_rotation(first_quaternion, mode: str = "auto", threshold_deg: float = DEFAULT_LEVEL_THRESHOLD_DEG
                       ) -> tuple[np.ndarray, float, bool]:
    """(R_level, first-pose tilt in degrees, levelled?): R_level turns the odometry frame so the
    first pose's z axis points up (the smallest such rotation; the identity when not levelled)."""
    R0 = _matrix(first_quaternion)
    tilt = tilt_deg(R0)
    if mode == "none" or (mode == "auto" and tilt <= threshold_deg):
        return np.eye(3), tilt, False
    up = R0[:, 2]
    axis = np.cross(up, [0.0, 0.0, 1.0])
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return (np.eye(3) if up[2] > 0 else np.diag([1.0, -1.0, -1.0])), tilt, up[2] < 0
    from scipy.spatial.transform import Rotation

    angle = math.atan2(s, float(up[2]))
    return Rotation.from_rotvec(axis / s * angle).as_matrix(), tilt, True


class Attitudes:
    """The odometry's 3-D poses after levelling: planar poses, and the attitude at any time."""

    def __init__(self, odometry_3d: list, R_level: np.ndarray):
        from scipy.spatial.transform import Rotation, Slerp

        self.times = np.array([t for t, _, _ in odometry_3d], dtype=float)
        self.positions = np.array([R_level @ np.asarray(p, dtype=float) for _, p, _ in odometry_3d])
        Rs = np.array([R_level @ _matrix(q) for _, _, q in odometry_3d])
        self.rotations = Rs
        self.yaws = np.arctan2(Rs[:, 1, 0], Rs[:, 0, 0])
        self._slerp = Slerp(self.times, Rotation.from_matrix(Rs)) if len(Rs) > 1 else None

    def planar(self, i: int) -> tuple[float, float, float]:
        return float(self.positions[i, 0]), float(self.positions[i, 1]), float(self.yaws[i])

    def tilt_at(self, t_ns: int) -> np.ndarray:
        """The roll-and-pitch part of the attitude at ``t_ns`` (interpolated): body vectors →
        the level frame that turns with the body's heading."""
        if self._slerp is None:
            R = self.rotations[0]
        else:
            R = self._slerp(float(np.clip(t_ns, self.times[0], self.times[-1]))).as_matrix()
        return rotation_z(-math.atan2(R[1, 0], R[0, 0])) @ R


def out_of_plane(attitudes: Attitudes) -> dict[str, float]:
    """How far the motion left the plane: the largest height change from the first pose (m)
    and the largest tilt of the body's z axis from vertical (degrees)."""
    dz = attitudes.positions[:, 2] - attitudes.positions[0, 2]
    tilts = [tilt_deg(R) for R in attitudes.rotations]
    return {"max_abs_dz_m": float(np.max(np.abs(dz))), "max_tilt_deg": float(max(tilts)),
            "mean_tilt_deg": float(np.mean(tilts))}
