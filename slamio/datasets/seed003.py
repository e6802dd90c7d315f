"""Seed 003's stereo + IMU drives (npz) → typed arrays, and the writer the simulator uses.

The layout (seed 003 §II.A, §III.A; the course project's ``load_data``), numpy arrays:

* ``time_stamps`` (1, T) s;
* ``features`` (4, M, T): landmark j at step t seen at stereo pixels (u_L, v_L, u_R, v_R),
  or −1 in all four where it is not seen (ids are the column index j);
* ``linear_velocity`` (3, T) m/s and ``rotational_velocity`` (3, T) rad/s, in the IMU frame;
* ``K`` (3, 3) left-camera intrinsics; ``b`` the baseline in metres;
* ``cam_T_imu`` (4, 4): the IMU's pose in the left camera's *optical* frame (x right,
  y down, z forward): ``p_cam = cam_T_imu · p_imu``.

Simulated drives (``slamio.sim3d``) add the truth under two optional keys:
``truth_world_T_imu`` (T, 4, 4) and ``truth_landmarks`` (M, 3) metres in the world frame.

Inside the product, :class:`StereoImuDrive` holds them step-major: ``features_px[t, j]`` is
the 4-vector of landmark j at step t (NaN where unseen), velocities are (T, 3). The velocity
at step t acts from stamp t to stamp t + 1 (the seed's prediction uses τ = t_{t+1} − t_t).

The seed's own three drives derive from KITTI (CC BY-NC-SA 3.0): they never go into the
package or its tests; tests use simulated drives.
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slamio.errors import InputFileError, check_regular
from slamio.log.fields import COORDINATE_M, STAMP_S
from slamio.log.records3d import MAX_MOUNT_M, MAX_PIXEL_PX, MAX_SPEED_MPS, MAX_TURN_RATE_RADPS

__all__ = ["DriveFormatError", "StereoImuDrive", "StereoImuNoise", "load_drive", "save_drive"]

UNSEEN = -1.0
_REQUIRED = ("time_stamps", "features", "linear_velocity", "rotational_velocity", "K", "b", "cam_T_imu")


class DriveFormatError(InputFileError):
    """A seed-003 npz that cannot be read: ``path: key 'k': what is wrong; how to fix it``."""

    def __init__(self, path, key: str | None, message: str):
        where = f"{path}: key '{key}'" if key else f"{path}"
        super().__init__(f"{where}: {message}")
        self.path = str(path)
        self.key = key


@dataclass(frozen=True)
class StereoImuNoise:
    """White noise of the layout's two sensors, one σ per axis.

    The simulator draws with it; the estimators assume it (the seed's drives carry no noise
    figures, so the same defaults are used there: 1 px per pixel coordinate, 0.05 m/s and
    0.005 rad/s per velocity axis and step).
    """

    sigma_px: float = 1.0
    sigma_v_mps: float = 0.05
    sigma_w_radps: float = 0.005
    #: a full 6×6 covariance of the twist (per-axis or correlated, as a dataset states it);
    #: when given it replaces the two σ above
    velocity_covariance: tuple[tuple[float, ...], ...] | None = None
    #: a full 4×4 covariance of the stereo pixels (u_L, v_L, u_R, v_R) in px² (rectified
    #: stereo: v_L and v_R correlated, σ_u ≠ σ_v); when given it replaces ``sigma_px``
    pixel_covariance: tuple[tuple[float, ...], ...] | None = None

    def velocity_cov(self) -> np.ndarray:
        """6×6 covariance of the twist u = (v, ω)."""
        if self.velocity_covariance is not None:
            return np.array(self.velocity_covariance, dtype=float)
        return np.diag([self.sigma_v_mps**2] * 3 + [self.sigma_w_radps**2] * 3)

    def pixel_cov(self) -> np.ndarray:
        """4×4 covariance of the stereo pixels (u_L, v_L, u_R, v_R): σ_px² I without ``pixel_covariance``."""
        if self.pixel_covariance is not None:
            return np.array(self.pixel_covariance, dtype=float)
        return self.sigma_px**2 * np.eye(4)


@dataclass(frozen=True)
class StereoImuDrive:
    """One drive: T steps, M feature tracks (see the module docstring for frames and units)."""

    stamps_s: np.ndarray  # (T,)
    features_px: np.ndarray  # (T, M, 4) u_L, v_L, u_R, v_R; NaN where unseen
    linear_velocity_mps: np.ndarray  # (T, 3) IMU frame
    angular_velocity_radps: np.ndarray  # (T, 3) IMU frame
    K: np.ndarray  # (3, 3)
    baseline_m: float
    cam_T_imu: np.ndarray  # (4, 4)
    truth_world_T_imu: np.ndarray | None = None  # (T, 4, 4)
    truth_landmarks_m: np.ndarray | None = None  # (M, 3)
    source: str = ""
    #: (M,) the landmark id of each column (a log's ids may be sparse or large: the columns
    #: are dense, never one per possible id); None: the column index is the id.
    landmark_ids: np.ndarray | None = None

    @property
    def n_steps(self) -> int:
        return int(self.stamps_s.shape[0])

    @property
    def n_landmarks(self) -> int:
        return int(self.features_px.shape[1])

    def seen(self, step: int) -> np.ndarray:
        """Columns of the landmarks seen at ``step`` (ascending); :meth:`ids` gives their ids."""
        return np.flatnonzero(~np.isnan(self.features_px[step, :, 0]))

    def ids(self, columns: np.ndarray) -> np.ndarray:
        """The landmark ids of ``columns`` (the columns themselves without ``landmark_ids``)."""
        columns = np.asarray(columns, dtype=np.int64)
        return columns if self.landmark_ids is None else np.asarray(self.landmark_ids, dtype=np.int64)[columns]

    def twist(self, step: int) -> np.ndarray:
        """The IMU input ``u = (v, ω)`` at ``step`` (6-vector, translation first)."""
        return np.concatenate([self.linear_velocity_mps[step], self.angular_velocity_radps[step]])

    def dt_s(self, step: int) -> float:
        """τ from stamp ``step`` to ``step + 1``."""
        return float(self.stamps_s[step + 1] - self.stamps_s[step])


def _finite(path, key, a, limit: float | None = None, unit: str = ""):
    """Every entry finite (and within ±``limit`` when given: the run log's bounds, so the
    log ``fgslam import seed003`` writes is one the reader accepts)."""
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise DriveFormatError(path, key, f"non-finite value at index {tuple(int(i) for i in bad)}; every entry must be a number")
    if limit is not None and a.size and float(np.max(np.abs(a))) > limit:
        bad = np.argwhere(np.abs(a) > limit)[0]
        raise DriveFormatError(path, key, f"value {float(a[tuple(bad)]):g} at index {tuple(int(i) for i in bad)} is beyond "
                                          f"±{limit:g} {unit}; no drive holds one (is the file corrupted?)")


def _shape(path, key, a, shape, meaning):
    if a.shape != shape:
        raise DriveFormatError(path, key, f"shape {a.shape}, expected {shape} ({meaning})")


def _check_rigid(path, key, T):
    R = T[:3, :3]
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise DriveFormatError(path, key, f"last row {T[3].tolist()} is not [0, 0, 0, 1]; expected a 4×4 rigid transform")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-3) or np.linalg.det(R) < 0.0:
        raise DriveFormatError(path, key, "the 3×3 block is not a rotation (RᵀR ≠ I or det < 0)")


def _features_px(path, arrays: dict[str, np.ndarray], T: int) -> np.ndarray:
    """``features`` (4, M, T) with −1 for 'not seen', checked, as (T, M, 4) pixels with NaN."""
    features = arrays["features"].astype(float)
    if features.ndim != 3 or features.shape[0] != 4 or features.shape[2] != T:
        raise DriveFormatError(path, "features", f"shape {features.shape}, expected (4, M, {T}): (u_L, v_L, u_R, v_R) × landmarks × steps")
    _finite(path, "features", features, MAX_PIXEL_PX, "px")
    unseen = features == UNSEEN
    partial = unseen.any(axis=0) & ~unseen.all(axis=0)
    if partial.any():
        j, t = (int(i) for i in np.argwhere(partial)[0])
        raise DriveFormatError(path, "features", f"landmark {j} at step {t} has −1 in some of its four pixels but not all; use −1 in all four for 'not seen'")
    if np.any(features[~unseen] < 0.0):
        raise DriveFormatError(path, "features", "negative pixel coordinate other than the −1 'not seen' marker")
    features_px = np.where(unseen, np.nan, features).transpose(2, 1, 0).copy()
    return features_px


def _camera(path, arrays: dict[str, np.ndarray]) -> tuple[np.ndarray, float, np.ndarray]:
    """The intrinsics ``K``, the baseline ``b`` (m) and ``cam_T_imu``, checked."""
    K = arrays["K"].astype(float)
    _shape(path, "K", K, (3, 3), "camera intrinsics")
    _finite(path, "K", K, MAX_PIXEL_PX, "px")
    if not (K[0, 0] > 0.0 and K[1, 1] > 0.0) or not np.allclose(K[2], [0.0, 0.0, 1.0]):
        raise DriveFormatError(path, "K", "not an intrinsics matrix (needs fx, fy > 0 and last row [0, 0, 1])")
    b = arrays["b"].astype(float)
    if b.size != 1:
        raise DriveFormatError(path, "b", f"shape {b.shape}, expected a scalar baseline in metres")
    baseline = float(b.reshape(-1)[0])
    if not (np.isfinite(baseline) and 0.0 < baseline <= MAX_MOUNT_M):
        raise DriveFormatError(path, "b", f"baseline {baseline!r} must be a positive number of metres")
    cam_T_imu = arrays["cam_T_imu"].astype(float)
    _shape(path, "cam_T_imu", cam_T_imu, (4, 4), "IMU pose in the left optical frame")
    _finite(path, "cam_T_imu", cam_T_imu, MAX_MOUNT_M, "m")
    _check_rigid(path, "cam_T_imu", cam_T_imu)
    return K, baseline, cam_T_imu


def load_drive(path) -> StereoImuDrive:
    """Read a seed-003 npz (and its truth, if a simulated drive); errors are :class:`DriveFormatError`."""
    path = Path(path)
    if not os.path.lexists(path):
        raise DriveFormatError(path, None, "no such file; give the path of a seed-003 .npz drive")
    check_regular(path, "seed-003 drive")  # never a FIFO, a device or a link loop
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: np.asarray(data[k]) for k in data.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, MemoryError) as exc:
        raise DriveFormatError(path, None, f"not a readable numpy .npz archive ({type(exc).__name__}: "
                                           f"{str(exc)[:200]})") from None
    missing = [k for k in _REQUIRED if k not in arrays]
    if missing:
        raise DriveFormatError(path, missing[0], f"missing (the file has {sorted(arrays)}); a seed-003 drive needs {list(_REQUIRED)}")
    for key in arrays:
        if not np.issubdtype(arrays[key].dtype, np.number):
            raise DriveFormatError(path, key, f"dtype {arrays[key].dtype} is not numeric")

    raw_stamps = arrays["time_stamps"]
    if not (raw_stamps.ndim == 1 or (raw_stamps.ndim == 2 and raw_stamps.shape[0] == 1)):
        raise DriveFormatError(path, "time_stamps", f"shape {raw_stamps.shape}, expected (1, T)")
    stamps = raw_stamps.astype(float).reshape(-1)
    T = stamps.size
    if T < 2:
        raise DriveFormatError(path, "time_stamps", f"{T} stamp(s); a drive needs at least 2 steps")
    _finite(path, "time_stamps", stamps, STAMP_S, "s")
    steps = np.diff(stamps)
    if np.any(steps <= 0.0):
        k = int(np.argmax(steps <= 0.0))
        raise DriveFormatError(path, "time_stamps", f"not strictly increasing at step {k + 1} ({stamps[k]!r} → {stamps[k + 1]!r})")

    features_px = _features_px(path, arrays, T)

    velocities = {}
    for key in ("linear_velocity", "rotational_velocity"):
        v = arrays[key].astype(float)
        _shape(path, key, v, (3, T), "3 axes × steps")
        _finite(path, key, v, MAX_SPEED_MPS if key == "linear_velocity" else MAX_TURN_RATE_RADPS, "per s")
        velocities[key] = v.T.copy()

    K, baseline, cam_T_imu = _camera(path, arrays)

    truth_poses = truth_landmarks = None
    if "truth_world_T_imu" in arrays:
        truth_poses = arrays["truth_world_T_imu"].astype(float)
        _shape(path, "truth_world_T_imu", truth_poses, (T, 4, 4), "one IMU pose per step")
        _finite(path, "truth_world_T_imu", truth_poses, COORDINATE_M, "m")
    if "truth_landmarks" in arrays:
        truth_landmarks = arrays["truth_landmarks"].astype(float)
        _shape(path, "truth_landmarks", truth_landmarks, (features_px.shape[1], 3), "one world point per landmark")
        _finite(path, "truth_landmarks", truth_landmarks, COORDINATE_M, "m")

    return StereoImuDrive(
        stamps_s=stamps,
        features_px=features_px,
        linear_velocity_mps=velocities["linear_velocity"],
        angular_velocity_radps=velocities["rotational_velocity"],
        K=K,
        baseline_m=baseline,
        cam_T_imu=cam_T_imu,
        truth_world_T_imu=truth_poses,
        truth_landmarks_m=truth_landmarks,
        source=str(path),
    )


def save_drive(path, drive: StereoImuDrive, *, overwrite: bool = False) -> None:
    """Write ``drive`` in the seed's layout (plus the truth keys when it has truth).

    Refuses to replace an existing file unless ``overwrite`` is true.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise DriveFormatError(path, None, "exists; pass overwrite=True (--overwrite) to replace it")
    features = np.where(np.isnan(drive.features_px), UNSEEN, drive.features_px).transpose(2, 1, 0)
    arrays = {
        "time_stamps": drive.stamps_s.reshape(1, -1),
        "features": features,
        "linear_velocity": drive.linear_velocity_mps.T,
        "rotational_velocity": drive.angular_velocity_radps.T,
        "K": drive.K,
        "b": np.array(drive.baseline_m),
        "cam_T_imu": drive.cam_T_imu,
    }
    if drive.truth_world_T_imu is not None:
        arrays["truth_world_T_imu"] = drive.truth_world_T_imu
    if drive.truth_landmarks_m is not None:
        arrays["truth_landmarks"] = drive.truth_landmarks_m
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)
