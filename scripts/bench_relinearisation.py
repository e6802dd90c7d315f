"""Benchmark: where the default ``isam2``'s time goes inside GTSAM, per candidate setting.

For each log (the sources of ``scripts/bench_online.py``), in one process with BLAS on one
thread: the EKF, then each candidate (``--candidate "k=v,k=v"``, default: the defaults),
``--repeats`` times interleaved (the minimum time is kept: on a shared machine later runs
are not comparable across processes). Each candidate's ``ISAM2`` is wrapped so that every
GTSAM call is timed without a profiler: updates that relinearised something (the
relinearisation checks, ``relinearize_skip``) and those that did not, and the reads of the
newest pose and of the landmarks the online correction uses; ``finish()`` (with its final
Gauss–Newton steps, batch steps outside iSAM2) is timed whole, as ``fgslam run`` times it. Prints wall and CPU time,
their ratio to the EKF's, p99 and slowest step, variables relinearised during the run,
online ATE (against the log's truth, else the batch optimum) and final χ²/2 × batch.
The "GTSAM" column adds up the GTSAM work (updates, reads, ``finish()``) and gives it
against the EKF's whole run: what the candidate would cost with no Python at all;
"Python" is the rest of the wall time (building factors, the online correction, bookkeeping).

Usage::

    .venv/bin/python -m scripts.bench_relinearisation mrclam:../shared/data/mrclam/MRCLAM_Dataset6:3 --robust dcs \\
        --candidate "relinearize_skip=10" --candidate ""
    .venv/bin/python -m scripts.bench_relinearisation victoria-park plaza1 --candidate "relinearize_threshold=(0.3,0.1)"

If an update fails, the smoother rebuilds its ``ISAM2`` (fgslam/smoother/recovery.py) and
the calls after that are not counted: the row says so.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from scripts.bench_online import logs, parse_sets, truth_of  # noqa: E402
from ekf import EkfSlam  # noqa: E402
from fgslam.compare import ate_rmse_m  # noqa: E402
from fgslam.runner import run_estimator  # noqa: E402
from fgslam.smoother import Isam2Smoother, batch_solve  # noqa: E402
from slamio.log import group_steps  # noqa: E402


class TimedIsam2:
    """Forwards to an ``ISAM2``, timing its updates (with how many variables each
    relinearised) and the single-variable reads the smoother makes."""

    def __init__(self, isam):
        self._isam = isam
        self.updates: list[tuple[int, float]] = []  # (variables relinearised, seconds)
        self.read_s = 0.0
        self.first_read_s = 0.0  # the first read after each update: its back-substitution
        self._fresh = False

    def update(self, *args):
        start = time.perf_counter()
        result = self._isam.update(*args)
        self.updates.append((result.getVariablesRelinearized(), time.perf_counter() - start))
        self._fresh = True
        return result

    def _read(self, method, key):
        start = time.perf_counter()
        value = getattr(self._isam, method)(key)
        seconds = time.perf_counter() - start
        self.read_s += seconds
        if self._fresh:
            self.first_read_s += seconds
            self._fresh = False
        return value

    def calculateEstimatePose2(self, key):  # noqa: N802 (GTSAM's name)
        return self._read("calculateEstimatePose2", key)

    def calculateEstimatePoint2(self, key):  # noqa: N802
        return self._read("calculateEstimatePoint2", key)

    def __getattr__(self, name):
        return getattr(self._isam, name)

    def split(self, num_variables: int) -> dict[str, float]:
        """Seconds and counts: plain updates and relinearisation checks (an update that
        relinearised every variable is neither)."""
        checks = [(n, s) for n, s in self.updates if 0 < n < num_variables]
        return {"plain_s": sum(s for n, s in self.updates if n == 0), "checks": len(checks),
                "check_s": sum(s for _, s in checks), "relinearised": sum(n for n, _ in checks),
                "read_s": self.read_s, "first_read_s": self.first_read_s,
                "slowest_update_ms": 1e3 * max((s for n, s in self.updates if n < num_variables), default=0.0),
                "most_marked": max((n for n, _ in checks), default=0)}


def one_run(header, steps, kwargs, truth):
    timers: list[TimedIsam2] = []

    def timed_isam(isam):
        timers.append(TimedIsam2(isam))
        return timers[-1]

    smoother = Isam2Smoother(header, isam_wrapper=timed_isam, **kwargs)
    timed = timers[0]  # the ISAM2 built at the start (a rebuild or a slide would add one)
    cpu = time.process_time()
    run, smoother = run_estimator(smoother, steps, covariances=False)
    cpu = time.process_time() - cpu
    return run, smoother, timed, cpu


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--candidate", action="append", default=None, metavar="K=V,K=V")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--robust", default=None, help="robust kernel for every iSAM2 (e.g. dcs)")
    args = ap.parse_args(argv)
    candidates = [parse_sets(c) for c in (args.candidate or [""])]
    common = {"robust": args.robust} if args.robust else {}
    for spec in args.logs:
        for name, header, records in logs(spec):
            steps = group_steps(header, records)
            truth = truth_of(steps)
            ekf_wall, ekf_cpu, rows, batch = [], [], {i: [] for i in range(len(candidates))}, None
            for _ in range(args.repeats):
                cpu = time.process_time()
                ekf, _ = run_estimator(EkfSlam(header), steps, covariances=False)
                ekf_cpu.append(time.process_time() - cpu)
                ekf_wall.append(ekf.total_time_s)
                for i, kwargs in enumerate(candidates):
                    run, smoother, timed, cpu = one_run(header, steps, {**common, **kwargs}, truth)
                    if batch is None:
                        batch = batch_solve(smoother)
                    rows[i].append((run, smoother, timed, cpu))
            print(f"\n## {name}: EKF wall {min(ekf_wall):.2f} s, CPU {min(ekf_cpu):.2f} s (min of {args.repeats})")
            print("| candidate | wall s (× EKF) | CPU s (× EKF) | p99 / max ms | updates | checks: s, variables "
                  "| plain updates s | reads s (first after an update) | finish s | GTSAM s (× EKF) | Python s "
                  "| slowest update ms, most marked | online ATE m | χ²/2 × batch |")
            print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
            for i, kwargs in enumerate(candidates):
                run, smoother, timed, _ = min(rows[i], key=lambda r: r[0].total_time_s)
                wall = min(r[0].total_time_s for r in rows[i])
                cpu = min(r[3] for r in rows[i])
                if truth is None:
                    ate = ate_rmse_m(run.online, batch.trajectory)
                else:
                    xy, mask = truth
                    ate = float(np.sqrt(np.mean(np.sum((run.online[mask, :2] - xy[mask, :2]) ** 2, axis=1))))
                parts = timed.split(smoother.num_poses + len(smoother.landmarks()))
                rebuilt = " (rebuilt: counts partial)" if smoother.update_failures else ""
                finish_s = run.total_time_s - run.step_times_s.sum()
                gtsam_s = parts["check_s"] + parts["plain_s"] + parts["read_s"] + finish_s
                print(f"| {kwargs or 'defaults'}{rebuilt} | {wall:.2f} ({wall / min(ekf_wall):.2f}) | "
                      f"{cpu:.2f} ({cpu / min(ekf_cpu):.2f}) | {1e3 * np.percentile(run.step_times_s, 99):.1f} / "
                      f"{1e3 * run.step_times_s.max():.0f} | {smoother.updates} | {parts['check_s']:.2f}, "
                      f"{parts['relinearised']} in {parts['checks']} | {parts['plain_s']:.2f} | {parts['read_s']:.2f} ({parts['first_read_s']:.2f}) | "
                      f"{finish_s:.2f} | {gtsam_s:.2f} ({gtsam_s / min(ekf_wall):.2f}) | {wall - gtsam_s:.2f} | "
                      f"{parts['slowest_update_ms']:.0f}, {parts['most_marked']} | {ate:.4f} | {smoother.error() / batch.final_error:.5f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
