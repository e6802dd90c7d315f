"""ekf-vio, plain first-estimate Jacobians and ekf-vio-fej on simulated drives: NEES, NIS, ATE.

    python -m scripts.experiments.vio_fej [--seeds 1-10] [--jobs 2]

Prints one markdown row per seed and variant (the NEES's share of steps below, inside and
above the 95 % band) and the means (docs/seed003.md, *Consistency*). Variants:
``standard`` (``ekf-vio``), ``FEJ at m_fe`` (``first_estimates=True,
projected_jacobians=False``) and ``ekf-vio-fej`` (first estimates, projected Jacobians).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import sys
import time

from scripts.common import one_blas_thread, parse_seeds

one_blas_thread(force=False)

import numpy as np  # noqa: E402

from ekf.drive3d import position_errors_m, steps_of  # noqa: E402
from ekf.vio import VioEkf, pose_nees  # noqa: E402
from fgslam.compare import nees_band  # noqa: E402
from slamio.sim3d import simulate_drive  # noqa: E402

VARIANTS = {
    "standard": {},
    "FEJ at m_fe": {"first_estimates": True, "projected_jacobians": False},
    "ekf-vio-fej": {"first_estimates": True},
}


def measure(drive, **options) -> dict:
    ekf = VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu, **options)
    nees, seconds = [], 0.0
    for t, args in enumerate(steps_of(drive)):
        start = time.perf_counter()
        ekf.step(*args)
        seconds += time.perf_counter() - start
        nees.append(pose_nees(ekf.current_pose(), ekf.current_covariance(), drive.truth_world_T_imu[t]))
    nees = np.array(nees)
    low, high = nees_band(6)
    ate3, ate2 = position_errors_m(ekf.trajectory(), drive.truth_world_T_imu)
    return {"nees_mean": float(nees.mean()), "nees_first100": float(nees[:100].mean()),
            "below": float(np.mean(nees < low)), "in_band": float(np.mean((nees >= low) & (nees <= high))),
            "above": float(np.mean(nees > high)), "nis_mean": float(ekf.nis().mean()),
            "rejected": ekf.rejected, "ate3": ate3, "ate2": ate2, "ms": 1e3 * seconds / drive.n_steps}


def measure_seed(seed: int) -> dict:
    drive = simulate_drive(seed)
    return {name: measure(drive, **options) for name, options in VARIANTS.items()}


def row(label, name, m) -> str:
    return (f"| {label} | {name} | {m['nees_mean']:.1f} | {m['nees_first100']:.1f} | {100 * m['below']:.0f} % | "
            f"{100 * m['in_band']:.0f} % | {100 * m['above']:.0f} % | {m['nis_mean']:.2f} | {m['rejected']:.0f} | "
            f"{m['ate3']:.3f} | {m['ate2']:.3f} | {m['ms']:.1f} |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1-10")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    args = parser.parse_args(argv)
    seeds = parse_seeds(args.seeds)
    print("| seed | variant | NEES mean | NEES first 100 | below band | in band | above band | NIS | rejected | "
          "ATE 3-D m | ATE 2-D m | ms/step |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    with concurrent.futures.ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        results = list(pool.map(measure_seed, seeds))
    for seed, by_variant in zip(seeds, results):
        for name, m in by_variant.items():
            print(row(str(seed), name, m), flush=True)
    for name in VARIANTS:
        keys = results[0][name].keys()
        mean = {k: np.mean([r[name][k] for r in results]) for k in keys}
        print(row("mean", name, mean))
    return 0


if __name__ == "__main__":
    sys.exit(main())
