"""ekf-vio with and without first-estimate Jacobians on simulated drives: NEES, NIS, ATE.

    python scripts/vio_fej.py [--seeds 1-10]

Prints one markdown row per seed and variant and the means (docs/seed003.md, *Consistency*).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ekf.drive3d import position_errors_m, steps_of  # noqa: E402
from ekf.vio import VioEkf, pose_nees  # noqa: E402
from fgslam.compare import nees_band  # noqa: E402
from slamio.sim3d import simulate_drive  # noqa: E402


def measure(drive, first_estimates: bool) -> dict:
    ekf = VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu, first_estimates=first_estimates)
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
            "in_band": float(np.mean((nees >= low) & (nees <= high))), "nis_mean": float(ekf.nis().mean()),
            "ate3": ate3, "ate2": ate2, "ms": 1e3 * seconds / drive.n_steps}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1-10")
    args = parser.parse_args(argv)
    a, b = (int(v) for v in args.seeds.split("-"))
    rows = {False: [], True: []}
    print("| seed | variant | NEES mean | NEES first 100 | in band | NIS | ATE 3-D m | ATE 2-D m | ms/step |")
    print("|---|---|---|---|---|---|---|---|---|")
    for seed in range(a, b + 1):
        drive = simulate_drive(seed)
        for fej in (False, True):
            m = measure(drive, fej)
            rows[fej].append(m)
            print(f"| {seed} | {'FEJ' if fej else 'standard'} | {m['nees_mean']:.1f} | {m['nees_first100']:.1f} | "
                  f"{100 * m['in_band']:.0f} % | {m['nis_mean']:.2f} | {m['ate3']:.3f} | {m['ate2']:.3f} | {m['ms']:.1f} |",
                  flush=True)
    for fej in (False, True):
        keys = ("nees_mean", "nees_first100", "in_band", "nis_mean", "ate3", "ate2", "ms")
        mean = {k: np.mean([r[k] for r in rows[fej]]) for k in keys}
        print(f"| mean | {'FEJ' if fej else 'standard'} | {mean['nees_mean']:.1f} | {mean['nees_first100']:.1f} | "
              f"{100 * mean['in_band']:.0f} % | {mean['nis_mean']:.2f} | {mean['ate3']:.3f} | {mean['ate2']:.3f} | {mean['ms']:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
