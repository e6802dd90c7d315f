"""Benchmark: Python's share of the default ``isam2``'s time, by CPU time, without a profiler.

For each log (the sources of ``scripts/bench_online.py``: ``victoria-park``, ``plaza1``,
``mrclam:FOLDER:1,2``, ``mrclam-fitted:…``, ``arena:1-3``, or a run log's path), in one
process with BLAS on one thread, ``--repeats`` runs of ``Isam2Smoother`` (the defaults, or
``--set key=value``) fed the way ``fgslam run --no-consistency`` feeds it: each step, then
``current_pose()``; at the end ``finish()`` and ``trajectory()``. That is the timed region,
timed as one interval (a ``time.thread_time`` call is a system call of about 1 µs, too
much to take twice a step); its CPU time is set against the CPU time inside GTSAM's calls:
every method of the smoother's ``ISAM2`` (wrapped: updates, the reads of the newest pose and
of the landmarks, the relinearisation cap's reads) and the final Gauss–Newton steps of
``finish()`` (:func:`fgslam.smoother.batch.gauss_newton_steps`, whose calls are all GTSAM's).
"Python" is the rest: building factors, noise models and ``Values`` through GTSAM's
bindings, the online correction, bookkeeping, and the timing wrapper's own cost (about
1 µs a GTSAM call: some thousands a run). CPU time, not wall time, because on a shared
machine the wall time of a run moves with the load; CPU time still moves some (caches, the
other hyperthread), so the table gives every repeat's share and the load average.

With ``--floor`` it also prints the floor of that Python: the same graph's factors and
seeds built and nothing else (per step the odometry's ``BetweenFactorPose2`` with its noise
model and the pose's ``Pose2`` seed in a ``Values``; each observation's factor, a new
landmark's seed), in a loop of its own and alternating with ``ISAM2.update`` at the steps
where the default updated (as the smoother's construction must; the replay's GTSAM time is
not the default's, its seeds being the start pose).

Usage::

    .venv/bin/python -m scripts.bench_python_share victoria-park plaza1 --repeats 3
    .venv/bin/python -m scripts.bench_python_share mrclam:../shared/data/mrclam/MRCLAM_Dataset6:1,2,3,4,5
    .venv/bin/python -m scripts.bench_python_share victoria-park --floor
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import os  # noqa: E402
import time  # noqa: E402

import gtsam  # noqa: E402
from gtsam.symbol_shorthand import X  # noqa: E402

import fgslam.smoother.isam2 as isam2_module  # noqa: E402
from fgslam.smoother import Isam2Smoother  # noqa: E402
from fgslam.smoother.factors import FactorBuilder  # noqa: E402
from scripts.bench_online import logs, parse_sets  # noqa: E402
from slamio.log import group_steps, read_log  # noqa: E402

clock = time.thread_time


class CpuTimedIsam2:
    """Forwards to an ``ISAM2``, adding the CPU time of every method call to ``seconds``."""

    def __init__(self, isam, seconds: dict[str, float]):
        self._isam = isam
        self._seconds = seconds

    def __getattr__(self, name):
        attribute = getattr(self._isam, name)
        if not callable(attribute):
            return attribute
        seconds = self._seconds

        def timed(*args):
            start = clock()
            try:
                return attribute(*args)
            finally:
                seconds[name] = seconds.get(name, 0.0) + clock() - start

        return timed


def timed_run(header, steps, settings: dict) -> tuple[float, dict[str, float]]:
    """(CPU s of the timed region, CPU s inside GTSAM by call) of one run."""
    gtsam_s: dict[str, float] = {}
    gauss_newton = isam2_module.gauss_newton_steps

    def timed_gauss_newton(*args):
        start = clock()
        try:
            return gauss_newton(*args)
        finally:
            gtsam_s["final Gauss-Newton"] = gtsam_s.get("final Gauss-Newton", 0.0) + clock() - start

    isam2_module.gauss_newton_steps = timed_gauss_newton
    try:
        smoother = Isam2Smoother(header, isam_wrapper=lambda isam: CpuTimedIsam2(isam, gtsam_s), **settings)
        start = clock()  # one interval for the whole loop: a thread_time call costs about 1 µs
        for step in steps:
            smoother.step(step)
            smoother.current_pose()
        smoother.finish()
        smoother.trajectory()
        total = clock() - start
    finally:
        isam2_module.gauss_newton_steps = gauss_newton
    return total, gtsam_s


def construction_floor(header, steps, update_at: set[int] | None) -> float:
    """CPU s of building the graph's factors and seeds alone (module docstring); with
    ``update_at``, each batch goes to an ``ISAM2.update`` after those steps (not counted)."""
    factors = FactorBuilder()
    isam = gtsam.ISAM2(Isam2Smoother(header).settings.isam2_params()) if update_at is not None else None
    seed, known, python_s = gtsam.Pose2(*header.start_pose), set(), 0.0
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    start = clock()
    for step in steps:
        k = step.index
        graph.add(factors.prior(header) if k == 0 else factors.odometry(k, step.odometry))
        values.insert(X(k), pose2=seed)  # by keyword, as the smoother's HeldSteps.take
        for observation in step.observations:
            if observation.landmark_id is None or observation.range_only:
                continue
            entry = factors.observation(k, seed, observation, False)
            graph.add(entry.factor)
            if observation.landmark_id not in known:
                known.add(observation.landmark_id)
                values.insert(entry.key, entry.landmark_guess)
        if update_at is not None and k in update_at:
            python_s += clock() - start
            isam.update(graph, values)
            graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            start = clock()
    return python_s + clock() - start


def update_steps(header, steps) -> set[int]:
    """The steps after which the default ``isam2`` ran an update."""
    smoother, out = Isam2Smoother(header), set()
    for step in steps:
        updates = smoother.updates
        smoother.step(step)
        if smoother.updates != updates:
            out.add(step.index)
    return out


def sources(spec: str):
    """(name, header, records) of a ``scripts/bench_online.py`` source or a run log's path."""
    if os.path.exists(spec):
        log = read_log(spec)
        yield os.path.basename(spec), log.header, log.records
    else:
        yield from logs(spec)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="victoria-park, plaza1, mrclam:FOLDER:R1,R2, arena:A-B or a run log")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--set", default="", metavar="K=V,K=V", help="Isam2Smoother settings (default: the defaults)")
    ap.add_argument("--floor", action="store_true", help="also the CPU s of building the factors and seeds alone")
    args = ap.parse_args(argv)
    settings = parse_sets(args.set)
    print(f"load average at the start: {os.getloadavg()[0]:.1f}")
    print("| log | steps | CPU s (min) | GTSAM s | Python s | Python share (each repeat) |")
    print("|---|---:|---:|---:|---:|---|")
    for spec in args.logs:
        for name, header, records in sources(spec):
            steps = group_steps(header, records)
            runs = [timed_run(header, steps, settings) for _ in range(args.repeats)]
            shares = [100.0 * (total - sum(g.values())) / total for total, g in runs]
            total, gtsam_s = min(runs, key=lambda r: r[0])
            in_gtsam = sum(gtsam_s.values())
            print(f"| {name} | {len(steps)} | {total:.3f} | {in_gtsam:.3f} | {total - in_gtsam:.3f} | "
                  f"{100.0 * (total - in_gtsam) / total:.1f} % ({', '.join(f'{s:.1f}' for s in shares)}) |",
                  flush=True)
            if args.floor:
                alone = min(construction_floor(header, steps, None) for _ in range(args.repeats))
                at = update_steps(header, steps)
                interleaved = min(construction_floor(header, steps, at) for _ in range(args.repeats))
                print(f"|   floor: factors and seeds alone | | | | {alone:.3f} ({1e6 * alone / len(steps):.1f} µs a step); "
                      f"alternating with the updates {interleaved:.3f} ({1e6 * interleaved / len(steps):.1f} µs a step) | |",
                      flush=True)
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
