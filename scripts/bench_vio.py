"""Benchmark: ``ekf-vio`` and ``ekf-vio-fej`` keeping every feature (the old filter) against
the bounded state (features marginalised once out of view; issue 43 part 5).

For each log, in one process with BLAS on one thread: each filter keeping every landmark
(``marginalise_after=None, max_landmarks=None``) and with the defaults (:data:`ekf.vio.
MARGINALISE_AFTER`, :data:`ekf.vio.MAX_LANDMARKS`) or the ``--after``/``--cap`` given. Prints
per log and run: total time, the peak resident memory the run added (MB,
:class:`fgslam.memory.PeakMemory`), the largest state, the 3-D ATE (final = online for a
filter) against the reference — the log's truth where it has some, else the batch solution of
``isam2-3d``'s graph, as ``fgslam run`` scores it — and how many landmarks were marginalised.
With ``--full-run`` it also times the whole default ``fgslam run`` pipeline in the same
process (every default estimator, the batch solve and the metrics; no report), with its peak
memory.

Usage::

    .venv/bin/python -m scripts.bench_vio seed003:0020 seed003:0027 seed003:0042 long-sim
    .venv/bin/python -m scripts.bench_vio long-sim --full-run
    .venv/bin/python -m scripts.bench_vio path/to/log.jsonl --after 5 20 --cap 300

Sources: ``seed003:NAME`` (``../shared/data/seed003/NAME.npz``, imported as ``fgslam import
seed003`` does), ``long-sim[:SEED]`` (:func:`long_drive`: the stereo loop at 4 m/s with a
facade point every step on each side and up to 40 features a step — 1 089 steps, ~2 000
landmarks, the quadratic case), or a 3-D run log path.
"""

from __future__ import annotations

from scripts.common import one_blas_thread, print_table_head, print_table_row

one_blas_thread()

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from ekf.vio import MARGINALISE_AFTER, MAX_LANDMARKS, VioEkf  # noqa: E402
from fgslam.memory import PeakMemory  # noqa: E402
from fgslam.runner3d import (  # noqa: E402
    Reference3d, in_world, position_rmse_m, prepare_log3d, run_estimator_3d, truth_reference_3d,
)
from scripts.common import SHARED_DATA  # noqa: E402
from slamio.log import RunLog  # noqa: E402

#: The long simulated drive: the stereo loop slowed to 4 m/s (1 089 steps) with a facade
#: point every 0.4 m on each side and up to 40 features a step.
LONG_SCENARIO = dict(speed_mps=4.0, landmark_spacing_m=0.4, max_features=40)


def long_drive(seed: int = 7):
    from slamio.sim3d import DriveScenario, simulate_drive

    return simulate_drive(seed, DriveScenario(**LONG_SCENARIO))


def load(spec: str) -> tuple[str, RunLog]:
    """(name, log) of a source (module docstring)."""
    from slamio.datasets.seed003_log import drive_to_log
    from slamio.log import read_log

    if spec.startswith("seed003:"):
        from slamio.datasets.seed003 import load_drive

        name = spec.split(":", 1)[1]
        header, records = drive_to_log(load_drive(SHARED_DATA / "seed003" / f"{name}.npz"))
        return name, RunLog(path=spec, header=header, records=tuple(records))
    if spec.startswith("long-sim"):
        seed = int(spec.split(":", 1)[1]) if ":" in spec else 7
        header, records = drive_to_log(long_drive(seed))
        return spec, RunLog(path=spec, header=header, records=tuple(records))
    return spec, read_log(spec)


def reference_of(log: RunLog, ready) -> Reference3d:
    """The log's truth, else the batch solution of isam2-3d's graph (as ``fgslam run``)."""
    truth = truth_reference_3d(log, ready.steps)
    if truth is not None:
        return truth
    from fgslam.smoother3d import batch_solve

    smoother = ready.estimator("isam2-3d")
    run_estimator_3d(smoother, ready.inputs, covariances=False)
    batch = batch_solve(smoother)
    moved = in_world(_final_only(batch.trajectory()), ready.world_T_start)
    return Reference3d("batch", moved.final, {})


def _final_only(poses):
    from fgslam.runner3d import Run3d

    return Run3d("batch", None, poses, {}, None, 0.0)


class _Largest:
    """Wraps a filter to record its largest state (landmarks) without timing it."""

    def __init__(self, f):
        self.f, self.name, self.largest = f, f.name, 0

    def step(self, *args):
        self.f.step(*args)
        self.largest = max(self.largest, len(self.f._slot))

    def __getattr__(self, item):
        return getattr(self.f, item)


def one_run(ready, reference: Reference3d, first_estimates: bool, after, cap) -> dict:
    f = VioEkf(ready.rig.K, ready.rig.baseline_m, ready.rig.cam_T_imu, ready.noise, first_estimates=first_estimates,
               marginalise_after=after, max_landmarks=cap)
    wrapped = _Largest(f)
    with PeakMemory() as memory:
        run = run_estimator_3d(wrapped, ready.inputs, covariances=False)
    run = in_world(run, ready.world_T_start)
    return {"time_s": run.total_time_s, "peak_mb": None if memory.peak_bytes is None else memory.peak_bytes / 1e6,
            "largest": wrapped.largest, "ate_m": position_rmse_m(run.final, reference.trajectory, 3, reference.mask),
            "marginalised": f.marginalised, "p99_ms": 1e3 * float(np.percentile(run.step_times_s, 99))}


def full_run(log: RunLog) -> tuple[float, float | None]:
    """Seconds and peak MB of the default ``fgslam run`` pipeline (no report) on ``log``."""
    from fgslam.registry import DEFAULTS
    from fgslam.runner3d import compute_metrics_3d, run_log3d

    start = time.perf_counter()
    with PeakMemory() as memory:
        compute_metrics_3d(run_log3d(log, list(DEFAULTS[3])), log_path=str(log.path))
    seconds = time.perf_counter() - start
    return seconds, None if memory.peak_bytes is None else memory.peak_bytes / 1e6


def fmt_or_dash(v, digits: int) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="seed003:NAME, long-sim[:SEED] or a 3-D log path")
    ap.add_argument("--after", type=int, nargs="+", default=[MARGINALISE_AFTER], metavar="N",
                    help=f"marginalise after N steps unseen (default {MARGINALISE_AFTER})")
    ap.add_argument("--cap", type=int, default=MAX_LANDMARKS, help=f"most landmarks kept (default {MAX_LANDMARKS})")
    ap.add_argument("--no-unbounded", action="store_true", help="skip the filters that keep every landmark")
    ap.add_argument("--full-run", action="store_true", help="also time the whole default fgslam run pipeline")
    args = ap.parse_args(argv)
    print_table_head("log", "estimator", "state", "total s", "p99 ms/step", "peak MB", "largest state", "ATE 3-D m",
                     "marginalised")
    full = []
    for spec in args.logs:
        name, log = load(spec)
        ready = prepare_log3d(log)
        reference = reference_of(log, ready)
        configs = ([] if args.no_unbounded else [("every landmark", None, None)]) + [
            (f"after {n}, cap {args.cap}", n, args.cap) for n in args.after]
        for first_estimates in (False, True):
            for label, after, cap in configs:
                r = one_run(ready, reference, first_estimates, after, cap)
                print_table_row(name, "ekf-vio-fej" if first_estimates else "ekf-vio", label, f"{r['time_s']:.2f}",
                                f"{r['p99_ms']:.1f}", fmt_or_dash(r["peak_mb"], 0), r["largest"], f"{r['ate_m']:.3f}",
                                r["marginalised"])
        if args.full_run:
            full.append((name, *full_run(log)))
    print_full_runs(full)
    return 0



def print_full_runs(full: list) -> None:
    """The table of default ``fgslam run`` figures, (log, seconds, peak MB) per row, if any."""
    if full:
        print()
        print_table_head("log", "default fgslam run s (no report)", "peak MB")
        for name, seconds, peak in full:
            print_table_row(name, f"{seconds:.1f}", fmt_or_dash(peak, 0))


if __name__ == "__main__":
    raise SystemExit(main())
