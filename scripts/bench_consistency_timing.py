"""Benchmark: how much the NIS/NEES work between the steps slows the timed steps themselves.

``fgslam run`` measures NIS before each step and the online covariance (for NEES) after it,
outside the timed region. That work still changes what the timed steps cost (it fills the
CPU caches with its own data, and iSAM2's marginals with their own). For each log (the
sources of ``scripts/bench_online.py``) this runs ``ekf`` and the default ``isam2`` (as
``fgslam run`` builds them) alone and with the NIS/NEES work, interleaved, ``--repeats``
times each in one process with BLAS on one thread, and prints the minimum total time of
each and the ratios. ``--consistency sampled`` takes the NIS/NEES at ``fgslam run``'s default
seeded sample (:mod:`fgslam.consistency_sample`) instead of at every step (``all``, the
default here), so "with" is a default ``fgslam run``'s timing; ``--cpu`` adds the isam2 × EKF
ratios by CPU time (``time.thread_time`` of the steps and ``finish()``, each the minimum of
the repeats), which a shared machine's load moves less than the wall time.

Usage::

    .venv/bin/python -m scripts.bench_consistency_timing mrclam-fitted:../shared/data/mrclam/MRCLAM_Dataset6:1,2,3,4,5 victoria-park
"""

from __future__ import annotations

from scripts.common import one_blas_thread, print_table_head, print_table_row

one_blas_thread()

import argparse  # noqa: E402

from scripts.bench_online import logs  # noqa: E402
from fgslam.consistency_sample import sample_of_steps  # noqa: E402
from fgslam.runner import ESTIMATORS, run_estimator  # noqa: E402
from slamio.log import group_steps  # noqa: E402

NAMES = ("ekf", "isam2")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="sources as in scripts/bench_online.py")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--consistency", choices=("all", "sampled"), default="all")
    ap.add_argument("--cpu", action="store_true", help="also the ratios by CPU time")
    args = ap.parse_args(argv)
    print_table_head("log", "ekf s: alone / with NIS, NEES", "isam2 s: alone / with", "isam2 × EKF: alone / with",
                     *(("ekf CPU s: alone / with", "isam2 CPU s: alone / with", "isam2 × EKF by CPU: alone / with")
                       if args.cpu else ()))
    for spec in args.logs:
        for name, header, records in logs(spec):
            steps = group_steps(header, records)
            sample = sample_of_steps(steps, args.consistency)
            best: dict[tuple[str, bool], float] = {}
            cpu: dict[tuple[str, bool], float] = {}
            for _ in range(args.repeats):
                for estimator in NAMES:
                    for consistency in (False, True):
                        run, _ = run_estimator(ESTIMATORS[estimator](header), steps, covariances=consistency,
                                               sample=sample)
                        key = (estimator, consistency)
                        best[key] = min(best.get(key, float("inf")), run.total_time_s)
                        cpu[key] = min(cpu.get(key, float("inf")), run.cpu_time_s)
            ekf, isam2 = (best[("ekf", False)], best[("ekf", True)]), (best[("isam2", False)], best[("isam2", True)])
            print_table_row(name, f"{ekf[0]:.3f} / {ekf[1]:.3f} (×{ekf[1] / ekf[0]:.2f})",
                            f"{isam2[0]:.3f} / {isam2[1]:.3f} (×{isam2[1] / isam2[0]:.2f})",
                            f"{isam2[0] / ekf[0]:.2f} / {isam2[1] / ekf[1]:.2f}",
                            *((f"{cpu[('ekf', False)]:.3f} / {cpu[('ekf', True)]:.3f}",
                               f"{cpu[('isam2', False)]:.3f} / {cpu[('isam2', True)]:.3f}",
                               f"{cpu[('isam2', False)] / cpu[('ekf', False)]:.2f} / "
                               f"{cpu[('isam2', True)] / cpu[('ekf', True)]:.2f}") if args.cpu else ()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
