"""Monte Carlo consistency on seed 003's simulated stereo + IMU drive (``fgslam bench stereo-loop``).

The 3-D task of :func:`fgslam.montecarlo.monte_carlo`: one seeded :func:`slamio.sim3d.simulate_drive`
per run, each named estimator of :data:`fgslam.runner3d.ESTIMATORS_3D` on it (as ``fgslam run``
runs them on the drive's log), and per step the pose NEES on SE(3) (right perturbation,
6 DoF) of the online pose against the truth. Averaged over N runs it is judged against
:func:`fgslam.compare.nees_band` ``(6, N)`` (for N = 10: [4.05, 8.33]). The ATE is the 3-D
position RMSE without alignment (every estimator starts at the IMU's first pose).
"""

from __future__ import annotations

from fgslam.runner3d import POSE_DOF as POSE_DOF_3D
from fgslam.runner3d import make_estimator_3d, pose_nees_series, position_rmse_m, run_estimator_3d
from slamio.datasets.seed003 import StereoImuNoise
from slamio.sim3d import DriveScenario, simulate_drive

__all__ = ["DEFAULT_BENCH_ESTIMATORS_3D", "POSE_DOF_3D", "run_one_3d"]

#: What ``fgslam bench stereo-loop`` runs when no estimator is named.
DEFAULT_BENCH_ESTIMATORS_3D = ("ekf-vio", "ekf-vio-fej", "isam2-3d")


def run_one_3d(seed: int, estimators: tuple[str, ...], scenario: DriveScenario | None = None):
    """One seeded simulated drive and every estimator on it: a :class:`fgslam.montecarlo.RunResult`
    (a picklable task)."""
    from fgslam.montecarlo import RunResult

    drive = simulate_drive(seed, scenario or DriveScenario())
    noise = StereoImuNoise()  # the simulator's noise, what `fgslam sim stereo-loop` writes in the log
    truth = drive.truth_world_T_imu
    nees, final, online, times = {}, {}, {}, {}
    for name in estimators:
        run = run_estimator_3d(make_estimator_3d(name, drive, noise), drive)
        nees[name] = pose_nees_series(run.online, run.covariances, truth)
        final[name] = position_rmse_m(run.final, truth)
        online[name] = position_rmse_m(run.online, truth)
        times[name] = run.total_time_s
    return RunResult(int(seed), nees, final, online, times, None)

