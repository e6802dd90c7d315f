"""Benchmark: the final Gauss–Newton steps of ``finish()``, as batch steps and as iSAM2 updates.

``Isam2Smoother.finish()`` ends every run with full Gauss–Newton steps on the whole graph
until χ²/2 drops by less than ``final_tolerance`` (relative). They are batch steps
(:func:`fgslam.smoother.batch.gauss_newton_steps`); they used to be iSAM2 updates with
``force_relinearize`` and ``forceFullSolve`` (the same step) followed by the full
back-substitution ``calculateBestEstimate`` to test the error. For each log this runs the
default ``isam2`` (with ``final_iterations=0``), then, in the same process on the same
graph from the same estimate, both kinds of steps with the same stopping rule, and prints
their time per step, the steps taken and the χ²/2 each ends at against batch
Levenberg–Marquardt. One BLAS thread.

Usage::

    .venv/bin/python -m scripts.bench_finish mrclam-fitted:../shared/data/mrclam/MRCLAM_Dataset6:1,2,3,4,5 victoria-park plaza1
"""

from __future__ import annotations

from scripts.common import one_blas_thread, print_table_head, print_table_row

one_blas_thread()

import argparse  # noqa: E402
import time  # noqa: E402

import gtsam  # noqa: E402

from scripts.bench_online import logs  # noqa: E402
from fgslam.runner import expected_outlier_kernel, run_estimator  # noqa: E402
from fgslam.smoother import Isam2Smoother, batch_solve  # noqa: E402
from fgslam.smoother.batch import gauss_newton_steps  # noqa: E402
from slamio.log import group_steps  # noqa: E402


def isam2_steps(isam: gtsam.ISAM2, graph, max_iterations: int, tolerance: float) -> tuple[int, float]:
    """The previous ``finish()``: forced full iSAM2 updates, each followed by a full
    back-substitution to test the error. Returns (steps, χ²/2 at the end)."""
    previous = float(graph.error(isam.calculateBestEstimate()))
    steps = 0
    for _ in range(max_iterations):
        params = gtsam.ISAM2UpdateParams()
        params.force_relinearize = True
        params.forceFullSolve = True
        isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), params)
        steps += 1
        current = float(graph.error(isam.calculateBestEstimate()))
        if not previous - current > tolerance * current:
            return steps, current
        previous = current
    return steps, previous


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="sources as in scripts/bench_online.py")
    args = ap.parse_args(argv)
    print_table_head("log", "steps: batch / iSAM2", "ms a step: batch / iSAM2", "total s: batch / iSAM2",
                     "χ²/2 × batch LM: batch / iSAM2")
    for spec in args.logs:
        for name, header, records in logs(spec):
            built = []  # every ISAM2 the smoother builds; the last is the one it ends with
            smoother = Isam2Smoother(header, robust=expected_outlier_kernel(header), final_iterations=0,
                                     isam_wrapper=lambda isam: built.append(isam) or isam)
            run_estimator(smoother, group_steps(header, records), covariances=False)
            graph, start = smoother.graph(), smoother.estimate()
            iterations, tolerance = 10, 1e-4  # the defaults
            t0 = time.perf_counter()
            polished = gauss_newton_steps(graph, start, iterations, tolerance)
            batch_s = time.perf_counter() - t0
            t0 = time.perf_counter()
            steps, isam_error = isam2_steps(built[-1], graph, iterations, tolerance)
            isam_s = time.perf_counter() - t0
            optimum = batch_solve(smoother).final_error
            taken = max(polished.iterations, 1)
            print_table_row(name, f"{polished.iterations} / {steps}",
                            f"{1e3 * batch_s / taken:.0f} / {1e3 * isam_s / steps:.0f}", f"{batch_s:.3f} / {isam_s:.3f}",
                            f"{polished.error / optimum:.6f} / {isam_error / optimum:.6f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
