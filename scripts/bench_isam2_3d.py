"""Benchmark: ``isam2-3d`` holding every variable against the bounded iSAM2 (old poses and the
landmarks only they saw marginalised once it holds more than ``max_held_factors``; issue 43
part 5, :mod:`fgslam.window3d`).

For each log, in one process with BLAS on one thread, ``isam2-3d`` with every variable kept
(``max_held_factors=None``) and with each bound given (default :data:`fgslam.smoother3d.
MAX_HELD_FACTORS`) and each load bound (``--loads``, default :data:`fgslam.smoother3d.MAX_HELD_LOAD`;
0 for none). Prints per run: the steps' total time, the per-step pose covariances' time
(what ``fgslam run`` takes for NEES, untimed there), both also as the process's CPU time
(``time.process_time``: what a loaded machine does not inflate), p99 and slowest step, the peak resident
memory the run added (MB, :class:`fgslam.memory.PeakMemory`), the most factors iSAM2 held, the
slides, the online and final 3-D ATE against the reference (the log's truth where it has
some, else the batch solution of the whole graph, as ``fgslam run`` scores it), the online pose NEES
against the truth (mean, share in the 95 % band), and the final
estimate's graph error over the batch optimum's. With ``--full-run`` it also times the whole
default ``fgslam run`` pipeline (no report) in the same process, with its peak memory.

Usage::

    .venv/bin/python -m scripts.bench_isam2_3d seed003:0020 seed003:0027 seed003:0042 long-sim
    .venv/bin/python -m scripts.bench_isam2_3d long-sim --bounds 1500 3000 6000 --full-run

Sources as in :mod:`scripts.bench_vio` (``seed003:NAME``, ``long-sim[:SEED]``, a log path).
"""

from __future__ import annotations

from scripts.common import one_blas_thread, print_table_head, print_table_row

one_blas_thread()

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from fgslam.memory import PeakMemory  # noqa: E402
from fgslam.compare import nees_band  # noqa: E402
from fgslam.runner3d import (  # noqa: E402
    Reference3d, in_world, pose_nees_series, position_rmse_m, prepare_log3d, truth_reference_3d,
)
from fgslam.smoother3d import MAX_HELD_FACTORS, MAX_HELD_LOAD, StereoIsam2, batch_solve  # noqa: E402
from scripts.bench_vio import fmt_or_dash, full_run, load, print_full_runs  # noqa: E402


class _Held:
    """Wraps the smoother to note the most factors its iSAM2 held, outside the step's time."""

    def __init__(self, smoother: StereoIsam2):
        self.s, self.most = smoother, 0

    def note(self) -> None:
        window = self.s.window
        held = self.s.graph.size() if window is None else window.held_factors
        self.most = max(self.most, held)


def one_run(ready, bound, load) -> tuple[StereoIsam2, dict]:
    rig = ready.rig
    s = StereoIsam2(rig.K, rig.baseline_m, rig.cam_T_imu, ready.noise, max_held_factors=bound, max_held_load=load)
    held, steps, cov_s, cpu_steps, cpu_cov, covs = _Held(s), [], 0.0, 0.0, 0.0, []
    with PeakMemory() as memory:
        for args in ready.inputs:
            start, cpu = time.perf_counter(), time.process_time()
            s.step(*args)
            steps.append(time.perf_counter() - start)
            cpu_steps += time.process_time() - cpu
            start, cpu = time.perf_counter(), time.process_time()
            covs.append(s.current_covariance())
            cov_s += time.perf_counter() - start
            cpu_cov += time.process_time() - cpu
            held.note()
        start = time.perf_counter()
        s.finish()
        finish_s = time.perf_counter() - start
    steps = np.array(steps)
    return s, {"steps_s": float(steps.sum()), "finish_s": finish_s, "cov_s": cov_s, "cpu": f"{cpu_steps:.1f} / {cpu_cov:.1f}",
               "p99_ms": 1e3 * float(np.percentile(steps, 99)), "max_ms": 1e3 * float(steps.max()),
               "peak_mb": None if memory.peak_bytes is None else memory.peak_bytes / 1e6, "held": held.most,
               "slides": 0 if s.window is None else s.window.slides, "covariances": np.array(covs)}


def _nees(online, covariances, reference) -> str:
    """Mean pose NEES (χ²₆) and its share in the 95 % band, against the truth ("–" without)."""
    if reference.kind != "ground_truth":
        return "–"
    nees = pose_nees_series(online, covariances, reference.trajectory)
    v = nees[np.isfinite(nees)]
    low, high = nees_band(6)
    return f"{np.mean(v):.2f} / {100 * np.mean((v >= low) & (v <= high)):.0f} %"


def reference_of(log, ready, batch) -> Reference3d:
    truth = truth_reference_3d(log, ready.steps)
    if truth is not None:
        return truth
    return Reference3d("batch", _moved(batch.trajectory(), ready), {})


def _moved(poses, ready):
    from fgslam.runner3d import Run3d

    return in_world(Run3d("x", poses, poses, {}, None, 0.0), ready.world_T_start).final


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="seed003:NAME, long-sim[:SEED] or a 3-D log path")
    ap.add_argument("--bounds", type=int, nargs="+", default=[MAX_HELD_FACTORS], metavar="N",
                    help=f"most factors iSAM2 holds (default {MAX_HELD_FACTORS})")
    ap.add_argument("--loads", type=float, nargs="+", default=[MAX_HELD_LOAD], metavar="LOAD",
                    help=f"most load (factors held × factors a step brings) iSAM2 holds; 0: no such bound "
                         f"(default {MAX_HELD_LOAD:g})")
    ap.add_argument("--no-unbounded", action="store_true", help="skip the run that keeps every variable")
    ap.add_argument("--full-run", action="store_true", help="also time the whole default fgslam run pipeline")
    args = ap.parse_args(argv)
    print_table_head("log", "max held", "max load", "steps s", "finish s", "covariances s", "CPU s steps / cov.", "p99 / max ms", "peak MB",
                     "most held", "slides", "ATE online m", "ATE final m", "NEES mean / in band", "final/batch error",
                     "reference")
    full = []
    for spec in args.logs:
        name, log = load(spec)
        ready = prepare_log3d(log)
        runs = ([] if args.no_unbounded else [(None, None)]) + [(b, most or None) for b in args.bounds for most in args.loads]
        for bound, most_load in runs:
            s, r = one_run(ready, bound, most_load)
            batch = batch_solve(s)
            reference = reference_of(log, ready, batch)
            ate_online = position_rmse_m(_moved(s.trajectory(), ready), reference.trajectory, 3, reference.mask)
            ate_final = position_rmse_m(_moved(s.smoothed_trajectory(), ready), reference.trajectory, 3,
                                        reference.mask)
            print_table_row(name, "every" if bound is None else bound, "–" if most_load is None else f"{most_load:g}",
                            f"{r['steps_s']:.1f}", f"{r['finish_s']:.1f}",
                            f"{r['cov_s']:.1f}", r["cpu"], f"{r['p99_ms']:.0f} / {r['max_ms']:.0f}", fmt_or_dash(r["peak_mb"], 0),
                            r["held"], r["slides"], f"{ate_online:.3f}", f"{ate_final:.3f}",
                            _nees(_moved(s.trajectory(), ready), r["covariances"], reference),
                            f"{s.error() / batch.error:.4f}", reference.kind)
            del s, batch
        if args.full_run:
            full.append((name, *full_run(log)))
    print_full_runs(full)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
