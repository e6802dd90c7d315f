"""Benchmark: the sliding window of poses (``window_poses``) against keeping every pose in iSAM2.

For each log, in one process with BLAS on one thread, the default ``isam2`` (with the
log's expected-outlier kernel, as ``fgslam run`` picks it) with every pose kept and with each
window size given. Prints, per log and run: the step time in each quarter of the run (p99
and slowest, ms: with every pose kept they grow with the run, with a window they should
not), the whole run's time, the online ATE (against the log's truth where it has it, else
against the batch optimum) and its ratio to the run that keeps every pose, the final χ²/2
against the batch optimum, and how many times the window slid.

Usage::

    .venv/bin/python -m scripts.bench_window arena-laps:1:40 --window 200 500
    .venv/bin/python -m scripts.bench_window plaza1 victoria-park --window 500 1000
    .venv/bin/python -m scripts.bench_window mrclam-fitted:../shared/data/mrclam/MRCLAM_Dataset6:1,2,3,4,5

Sources as in scripts/bench_online.py.
"""

from __future__ import annotations

from scripts.common import one_blas_thread, print_table_head, print_table_row

one_blas_thread()

import argparse  # noqa: E402

import numpy as np  # noqa: E402

from scripts.bench_online import logs, online_ate_m, truth_of  # noqa: E402
from fgslam.runner import expected_outlier_kernel, run_estimator  # noqa: E402
from fgslam.smoother import Isam2Smoother, batch_solve  # noqa: E402
from slamio.log import group_steps  # noqa: E402


def quarters_ms(step_times_s: np.ndarray) -> str:
    """p99 / slowest step of each quarter of the run, in ms."""
    parts = np.array_split(1e3 * step_times_s, 4)
    return " · ".join(f"{np.percentile(p, 99):.1f}/{p.max():.0f}" for p in parts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="sources as in scripts/bench_online.py")
    ap.add_argument("--window", type=int, nargs="+", default=[200], metavar="N", help="window sizes (default 200)")
    args = ap.parse_args(argv)
    print_table_head("log", "window", "p99/slowest step ms, by quarter", "total s", "online ATE m", "× every pose",
                     "χ²/2 × batch", "slides")
    for spec in args.logs:
        for name, header, records in logs(spec):
            steps = group_steps(header, records)
            truth = truth_of(steps)
            robust = expected_outlier_kernel(header)
            batch = reference_ate = None
            for window in [None] + args.window:
                smoother = Isam2Smoother(header, robust=robust, window_poses=window)
                run, _ = run_estimator(smoother, steps, covariances=False)
                if batch is None:
                    batch = batch_solve(smoother)
                ate = online_ate_m(run.online, truth, batch.trajectory)
                reference_ate = reference_ate or ate
                print_table_row(name, window or "every pose", quarters_ms(run.step_times_s), f"{run.total_time_s:.2f}",
                                f"{ate:.4f}", f"{ate / reference_ate:.3f}",
                                f"{smoother.error() / batch.final_error:.5f}", smoother.window_slides)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
