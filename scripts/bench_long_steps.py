"""Where the default isam2's long steps come from: each step timed, the longest taken apart.

    OPENBLAS_NUM_THREADS is forced to 1 before numpy loads, as in the other benchmarks.

Usage::

    .venv/bin/python -m scripts.bench_long_steps victoria-park
    .venv/bin/python -m scripts.bench_long_steps mrclam:1 mrclam:2 grid:2000
    .venv/bin/python -m scripts.bench_long_steps victoria-park --top 10 --consistency

Each log (``victoria-park``: the file shipped with gtsam; ``plaza1``, ``plaza2``: the files
shipped with gtsam; ``mrclam:K``: robot K of
``../shared/data/mrclam/MRCLAM_Dataset6`` imported as ``fgslam import`` does; ``grid:N`` or
``grid:N:LAPS``: the ``fgslam sim grid`` scenario with N landmarks, seed 1 (its own laps, or
LAPS as ``bench_scaling --laps``); or a run-log path) is run through the
default ``isam2`` (``fgslam run``'s factory, one process, BLAS on one thread) with
:func:`fgslam.runner.run_estimator`, so the step times are the ones ``fgslam run`` reports
(``--consistency`` also does its NIS/NEES work between the steps). Each step's CPU time
(``time.thread_time``) is kept too: on a shared machine the wall time of one step includes
whatever preempted it. For the ``--top`` longest steps (by CPU time; ``--by-wall``: by wall time) the script prints the step's time, the part inside ``ISAM2.update`` (wall and CPU; and how
many updates ran), the variables that update relinearised and re-eliminated
(``ISAM2Result``), the read of the newest pose after it (``calculateEstimatePose2``: GTSAM's
lazy back-substitution runs there; wall and CPU), the time the relinearisation cap's choice took in Python
(:meth:`fgslam.smoother.relinearisation.CapChoice.held_back`; wall / CPU), a rebuild after a failed update
(:mod:`fgslam.smoother.recovery`; the failed update counts in the update columns), and the time Python's garbage collector
ran in that step, by generation; then every collection of the run, by generation (the one
generation-2 collection of a run is usually :class:`fgslam.memory.PeakMemory`'s own
``gc.collect()`` before the first step).
Then the maximum step, the p99, the total and the final χ²/2 against the batch optimum.
"""

from __future__ import annotations

from scripts.common import SHARED_DATA, one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import gc  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402

import numpy as np  # noqa: E402

from fgslam.runner import ESTIMATORS, run_estimator  # noqa: E402
from fgslam.smoother.batch import batch_solve  # noqa: E402
from slamio.log import group_steps, read_log  # noqa: E402

MRCLAM = SHARED_DATA / "mrclam" / "MRCLAM_Dataset6"


def load(name: str):
    """(header, records) of a log named on the command line."""
    if name == "victoria-park":
        from slamio.datasets.victoria_park import import_victoria_park

        return import_victoria_park()
    if name in ("plaza1", "plaza2"):
        from slamio.datasets.plaza import import_plaza

        return import_plaza(name)
    if name.startswith("mrclam:"):
        from slamio.datasets.mrclam import import_mrclam

        return import_mrclam(MRCLAM, int(name.split(":")[1]))
    if name.startswith("grid:"):
        from slamio.sim import simulate

        _, n, *laps = name.split(":")
        return simulate("grid", 1, landmarks=int(n), laps=int(laps[0]) if laps else None)
    log = read_log(name)
    return log.header, log.records


@dataclass
class Events:
    """What happened inside the timed steps: (start, end) of each step, each update's time
    and ISAM2Result, each garbage collection's time and generation."""

    steps: list[tuple[float, float]] = field(default_factory=list)
    step_cpu_s: list[float] = field(default_factory=list)  # the thread's CPU time in each step
    updates: list[tuple[float, float, int, int, float]] = field(default_factory=list)  # start, s, relin, reelim, CPU s
    collections: list[tuple[float, float, int]] = field(default_factory=list)  # start, s, generation
    checks: list[tuple[float, float, float]] = field(default_factory=list)  # start, s, CPU s of each cap's choice
    reads: list[tuple[float, float, float]] = field(default_factory=list)  # start, s, CPU s of each newest-pose read
    rebuilds: list[tuple[float, float, float]] = field(default_factory=list)  # start, s, CPU s of each rebuild after a failure
    _gc_start: float = 0.0

    def on_gc(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._gc_start = time.perf_counter()
        else:
            self.collections.append((self._gc_start, time.perf_counter() - self._gc_start, info["generation"]))

    def within(self, at: float, step: tuple[float, float]) -> bool:
        return step[0] <= at <= step[1]


class _TimedIsam:
    """Passes every call through to the real ISAM2, noting each update's time and result."""

    def __init__(self, isam, events: Events):
        self._isam, self._events = isam, events

    def update(self, *args):
        start, cpu = time.perf_counter(), time.thread_time()
        try:
            result = self._isam.update(*args)
        except RuntimeError:  # a failed update (the smoother rebuilds): its time, nothing relinearised
            self._events.updates.append((start, time.perf_counter() - start, 0, 0, time.thread_time() - cpu))
            raise
        self._events.updates.append((start, time.perf_counter() - start, result.getVariablesRelinearized(),
                                     result.getVariablesReeliminated(), time.thread_time() - cpu))
        return result

    def calculateEstimatePose2(self, key):  # the read of the newest pose after each update
        start, cpu = time.perf_counter(), time.thread_time()
        pose = self._isam.calculateEstimatePose2(key)
        self._events.reads.append((start, time.perf_counter() - start, time.thread_time() - cpu))
        return pose

    def __getattr__(self, name):
        return getattr(self._isam, name)


def _plain() -> dict:
    from fgslam.smoother import relinearisation, updates

    return {"rebuild": updates.rebuild, "held_back": relinearisation.CapChoice.held_back}


#: The calls timed in each step, unwrapped (an experiment may put its own variant here:
#: scripts/experiments/long_steps_age_cap.py).
PLAIN = _plain()


def _timed_held_back(events: Events):
    """fgslam.smoother.relinearisation.CapChoice.held_back (the relinearisation cap's choice,
    in Python; wall and CPU time) and rebuild (a fresh iSAM2 from the whole graph after a
    failed update), timed."""
    from fgslam.smoother import relinearisation, updates

    def timed(plain, into: list):
        def call(*args):
            start, cpu = time.perf_counter(), time.thread_time()
            try:
                return plain(*args)
            finally:
                into.append((start, time.perf_counter() - start, time.thread_time() - cpu))
        return call

    # wrapped from the plain functions each time: wrapping the previous log's wrappers nested
    # them, and from the second log on each call was counted once per log before it
    updates.rebuild = timed(PLAIN["rebuild"], events.rebuilds)
    relinearisation.CapChoice.held_back = timed(PLAIN["held_back"], events.checks)


def _unwrap() -> None:
    """The plain calls back in place of :func:`_timed_held_back`'s (later runs in the process untimed)."""
    from fgslam.smoother import relinearisation, updates

    updates.rebuild = PLAIN["rebuild"]
    relinearisation.CapChoice.held_back = PLAIN["held_back"]


def instrumented(header, events: Events):
    """The default isam2 of ``fgslam run``, its ISAM2 calls and steps timed into ``events``."""
    _timed_held_back(events)
    smoother = ESTIMATORS["isam2"](header)
    smoother._isam_wrapper = lambda isam: _TimedIsam(isam, events)
    smoother._isam = smoother._new_isam(smoother._isam)
    plain_step = smoother.step

    def step(s):
        start, cpu = time.perf_counter(), time.thread_time()
        plain_step(s)
        events.steps.append((start, time.perf_counter()))
        events.step_cpu_s.append(time.thread_time() - cpu)

    smoother.step = step
    return smoother


def timed_run(header, steps, consistency: bool):
    """(run, events, smoother) of the default isam2 on ``steps``, every step timed (wall and
    CPU) into ``events`` with what ran inside it."""
    events = Events()
    smoother = instrumented(header, events)
    gc.callbacks.append(events.on_gc)
    try:
        run, _ = run_estimator(smoother, steps, covariances=consistency)
    finally:
        gc.callbacks.remove(events.on_gc)
        _unwrap()
    return run, events, smoother


def report(name: str, top: int, consistency: bool, by_cpu: bool = True) -> None:
    header, records = load(name)
    steps = group_steps(header, records)
    run, events, smoother = timed_run(header, steps, consistency)
    times = run.step_times_s * 1e3
    cpu = np.array(events.step_cpu_s) * 1e3
    print(f"## {name}: {len(steps)} steps, {smoother.updates} updates; max {times.max():.1f} ms "
          f"(CPU: max {cpu.max():.1f} ms, p99 {np.percentile(cpu, 99):.2f} ms, steps {cpu.sum() / 1e3:.2f} s), "
          f"p99 {np.percentile(times, 99):.2f} ms, total {run.total_time_s:.2f} s "
          f"(steps {times.sum() / 1e3:.2f} s); gen-2 collections {sum(c[2] == 2 for c in events.collections)}")
    print("| step | ms | CPU ms | in update ms (CPU) | updates | relinearised | re-eliminated | pose read ms (CPU) | cap's choice ms (CPU) | rebuild ms | gc ms (gen) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for k in np.argsort(-(cpu if by_cpu else times), kind="stable")[:top]:
        span = events.steps[k]
        ups = [u for u in events.updates if events.within(u[0], span)]
        gcs = [c for c in events.collections if events.within(c[0], span)]
        checks = [c for c in events.checks if events.within(c[0], span)]
        reads = [r for r in events.reads if events.within(r[0], span)]
        rebuilt = sum(r[1] for r in events.rebuilds if events.within(r[0], span))
        gc_text = ", ".join(f"{1e3 * c[1]:.1f} ({c[2]})" for c in gcs) or "-"
        print(f"| {k} | {times[k]:.1f} | {cpu[k]:.1f} | {1e3 * sum(u[1] for u in ups):.1f} ({1e3 * sum(u[4] for u in ups):.1f}) | {len(ups)} | "
              f"{sum(u[2] for u in ups)} | {sum(u[3] for u in ups)} | {1e3 * sum(r[1] for r in reads):.1f} ({1e3 * sum(r[2] for r in reads):.1f}) | {1e3 * sum(c[1] for c in checks):.1f} / {1e3 * sum(c[2] for c in checks):.1f} | {1e3 * rebuilt:.1f} | {gc_text} |")
    if events.checks:
        wall, cpu = np.array([c[1] for c in events.checks]) * 1e3, np.array([c[2] for c in events.checks]) * 1e3
        print(f"cap's choice: {len(wall)} checks, longest {wall.max():.1f} ms wall / {cpu.max():.1f} ms CPU, "
              f"total {wall.sum():.0f} ms wall / {cpu.sum():.0f} ms CPU")
    for generation in (0, 1, 2):
        spent = [c[1] * 1e3 for c in events.collections if c[2] == generation]
        if spent:
            print(f"gen-{generation} collections: {len(spent)}, longest {max(spent):.1f} ms, "
                  f"total {sum(spent):.0f} ms")
    with_truth = [i for i, s in enumerate(steps) if s.truth is not None]
    if with_truth:
        truth = np.array([[steps[i].truth.x_m, steps[i].truth.y_m] for i in with_truth])
        online = np.asarray(run.online)[with_truth, :2]
        print(f"online ATE {float(np.sqrt(np.mean(np.sum((online - truth) ** 2, axis=1)))):.4f} m "
              f"over the {len(with_truth)} poses with truth (anchored, no alignment)")
    error = smoother.error()
    optimum = batch_solve(smoother).final_error
    print(f"final chi2/2 {error:.6g}, batch optimum {optimum:.6g}, ratio {error / optimum:.6f}\n", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="victoria-park, plaza1, plaza2, mrclam:K, grid:N[:LAPS] or a run-log path")
    ap.add_argument("--top", type=int, default=8, help="how many of the longest steps to take apart")
    ap.add_argument("--consistency", action="store_true", help="do fgslam run's NIS/NEES work between steps")
    ap.add_argument("--by-wall", action="store_true", help="take apart the longest steps by wall time (default: by CPU time)")
    args = ap.parse_args(argv)
    for name in args.logs:
        report(name, args.top, args.consistency, by_cpu=not args.by_wall)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
