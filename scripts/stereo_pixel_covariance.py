"""Experiment: the 3-D estimators told the true 4×4 stereo pixel covariance against one σ
(issue 42 part 7, "correlated stereo noise").

Simulated stereo-loop drives (``slamio.sim3d``) whose pixel noise is rectified stereo's:
σ_u on u_L and u_R, σ_v on v_L and v_R, v_L and v_R correlated ρ (read on one row). Each
drive is written three times as a 3-D run log (the same pixels, only the stated noise
differs) and run through ``fgslam run``'s pipeline (:func:`fgslam.runner3d.run_log3d`):

* ``true`` — ``covariance_px2`` = the covariance the simulator drew from;
* ``diagonal`` — ``covariance_px2`` = its diagonal (σ_u, σ_v per coordinate, no correlation);
* ``isotropic`` — ``sigma_px`` = √(trace/4), one σ (what a log without a covariance states).

Prints, per told noise and estimator, the median over the drives of the 3-D ATE and of the
pose NEES share inside its 95 % band (and the mean NEES and NIS), as a Markdown table.

Usage::

    .venv/bin/python -m scripts.stereo_pixel_covariance --seeds 1 2 3 4 5
    .venv/bin/python -m scripts.stereo_pixel_covariance --sigma-u 0.3 --sigma-v 1.0 --rho 0.95
"""

from __future__ import annotations

from scripts.common import one_blas_thread, print_table_head, print_table_row

one_blas_thread()

import argparse  # noqa: E402

import numpy as np  # noqa: E402

#: The estimators compared (``fgslam run``'s names).
ESTIMATORS = ("ekf-vio", "ekf-vio-fej", "isam2-3d")
TOLD = ("true", "diagonal", "isotropic")


def told_noise(true_cov: np.ndarray, told: str):
    """The :class:`StereoImuNoise` an estimator is given: the true covariance, its diagonal, or one σ."""
    from slamio.datasets.seed003 import StereoImuNoise
    from slamio.stereo import rms_sigma_px

    if told == "true":
        return StereoImuNoise(pixel_covariance=tuple(tuple(float(v) for v in row) for row in true_cov))
    if told == "diagonal":
        diagonal = np.diag(np.diag(true_cov))
        return StereoImuNoise(pixel_covariance=tuple(tuple(float(v) for v in row) for row in diagonal))
    return StereoImuNoise(sigma_px=rms_sigma_px(true_cov))


def measure(seed: int, true_cov: np.ndarray, scenario=None) -> dict[str, dict[str, dict]]:
    """told → estimator → metrics (``fgslam run``'s metrics.json entries) on the drive of ``seed``."""
    from fgslam.runner3d import compute_metrics_3d, run_log3d
    from slamio.datasets.seed003_log import drive_to_log
    from slamio.log import RunLog
    from slamio.sim3d import DriveScenario, simulate_drive

    drive = simulate_drive(seed, scenario or DriveScenario(), told_noise(true_cov, "true"))
    out: dict[str, dict[str, dict]] = {}
    for told in TOLD:
        header, records = drive_to_log(drive, told_noise(true_cov, told))
        metrics = compute_metrics_3d(run_log3d(RunLog(f"sim-{seed}-{told}", header, records), list(ESTIMATORS)),
                                     log_path=f"sim-{seed}-{told}")
        out[told] = {name: metrics[name] for name in ESTIMATORS}
    return out


#: The figures of the table (metrics.json keys).
KEYS = ("ate_rmse_m", "nees_inside_95", "nees_mean", "nis_mean")


def medians(seeds, true_cov: np.ndarray) -> dict[str, dict[str, dict[str, float]]]:
    """told → estimator → key of :data:`KEYS` → its median over the drives of ``seeds`` (NaN
    where an estimator has none, e.g. isam2-3d's NIS)."""
    results = [measure(seed, true_cov) for seed in seeds]
    out: dict = {}
    for told in TOLD:
        for name in ESTIMATORS:
            values = {key: [v for r in results if (v := r[told][name].get(key)) is not None] for key in KEYS}
            out.setdefault(told, {})[name] = {k: float(np.median(v)) if v else float("nan") for k, v in values.items()}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5], help="drives' seeds (1 2 3 4 5)")
    parser.add_argument("--sigma-u", type=float, default=0.3, help="σ of u_L and u_R, px (0.3)")
    parser.add_argument("--sigma-v", type=float, default=1.0, help="σ of v_L and v_R, px (1.0)")
    parser.add_argument("--rho", type=float, default=0.95, help="correlation of v_L and v_R (0.95)")
    args = parser.parse_args(argv)
    from slamio.stereo import rectified_pixel_covariance

    true_cov = rectified_pixel_covariance(args.sigma_u, args.sigma_v, args.rho)
    print(f"pixel noise: σ_u {args.sigma_u} px, σ_v {args.sigma_v} px, ρ(v_L, v_R) {args.rho}; "
          f"seeds {' '.join(str(s) for s in args.seeds)}; medians over the drives")
    table = medians(args.seeds, true_cov)
    print_table_head("told", "estimator", "ATE 3-D m", "NEES in band %", "NEES mean", "NIS mean")
    for told in TOLD:
        for name in ESTIMATORS:
            m = table[told][name]
            print_table_row(told, name, f"{m['ate_rmse_m']:.3f}", f"{100 * m['nees_inside_95']:.0f}",
                            f"{m['nees_mean']:.1f}", "-" if np.isnan(m["nis_mean"]) else f"{m['nis_mean']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
