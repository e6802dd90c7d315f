"""Profile: where an iSAM2 run spends its time (cProfile, one BLAS thread).

    OPENBLAS_NUM_THREADS is forced to 1 before numpy loads, as in the other benchmarks.

Usage::

    .venv/bin/python -m scripts.profile_isam2 data/arena_octagon.jsonl
    .venv/bin/python -m scripts.profile_isam2 victoria-park           # the log shipped with gtsam
    .venv/bin/python -m scripts.profile_isam2 LOG --preset fast --set relinearize_skip=5

Runs ``Isam2Smoother`` over the log the way ``fgslam run`` does: before each step the NIS
of its observations (``predicted_nis``), then the step (the timed region), then the
online covariance for NEES (``current_covariance``); after the last step ``finish()``
(timed) and the landmark covariances. Two cProfile profiles are kept, one for the timed
region and one for the consistency work outside it, and each is summed into categories:

* GTSAM calls by name: ``ISAM2.update``; reading the estimate (``calculateEstimate*``,
  ``calculateBestEstimate``); marginals (``marginalCovariance``,
  ``jointMarginalCovariance``); ``graph.error`` (the convergence test of ``finish()``);
  the final Gauss–Newton steps of ``finish()`` (``linearize``, ``optimize``, ``retract``,
  ``orderingCOLAMD``: :func:`fgslam.smoother.batch.gauss_newton_steps`; until issue 43's
  step round they were missing here and their time counted as smoother bookkeeping);
* Python by module: factor building (``fgslam/smoother/factors.py``: records → factors and
  noise models), update assembly (``update_batch``: copying the held factors and ``Values``
  into one update), odometry chains (``chain.py``), NIS/NEES propagation (the marginal
  propagation of ``online.py``, ``ekf/models.py``), other smoother bookkeeping (the rest of
  ``fgslam/smoother/``).

Time of any other function (numpy, GTSAM constructors, which cProfile cannot see and
charges to their caller) goes to the category of its caller. Also printed: the same run's
time without the profiler, and how ``ISAM2.update``'s time splits over the update count
modulo ``relinearize_skip`` (GTSAM checks relinearisation on one update in that many).
The profiler's own overhead inflates the Python categories more than the GTSAM ones.
"""

from __future__ import annotations

import os

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import ast  # noqa: E402
import cProfile  # noqa: E402
import pstats  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402

from fgslam.smoother import FAST_SETTINGS, Isam2Smoother  # noqa: E402
from slamio.log import group_steps, read_log  # noqa: E402

GTSAM_CALLS = {
    "update": "ISAM2.update",
    "calculateEstimate": "reading the estimate",
    "calculateEstimatePose2": "reading the estimate",
    "calculateEstimatePoint2": "reading the estimate",
    "calculateBestEstimate": "reading the estimate",
    "marginalCovariance": "marginals",
    "jointMarginalCovariance": "marginals",
    "getDelta": "reading the estimate",  # the lazy back-substitution, when the relinearisation cap asks first
    "error": "graph.error (finish)",
    # finish()'s Gauss–Newton steps (fgslam/smoother/batch.py: gauss_newton_steps); before
    # they were named here their time went to "smoother bookkeeping (Python)", their caller's
    "linearize": "finish's Gauss–Newton steps",
    "optimize": "finish's Gauss–Newton steps",
    "orderingCOLAMD": "finish's Gauss–Newton steps",
    "retract": "finish's Gauss–Newton steps",
}


#: Functions of fgslam/smoother/online.py that serve NIS/NEES (the rest keep the online pose).
CONSISTENCY = {"covariance", "predicted_nis", "_caught_up_since_chain", "landmark_covariances", "body_to_world"}


def category(func) -> str | None:
    """The category of one pstats function key, or None to charge its time to its callers."""
    path, _, name = func
    if path == "~":
        method = name.removeprefix("<built-in method ").removesuffix(">").split(".")[-1]
        return GTSAM_CALLS.get(method) if "gtsam" in name else None
    path = path.replace(os.sep, "/")
    if path == __file__.replace(os.sep, "/") and name == "update":  # _TimedIsam.update
        return "ISAM2.update"
    if path.endswith("fgslam/smoother/factors.py"):
        return "update assembly (copies)" if name == "update_batch" else "factor building (Python)"
    if path.endswith("fgslam/smoother/chain.py"):
        return "odometry chains (Python)"
    if path.endswith("ekf/models.py") or (path.endswith("fgslam/smoother/online.py") and name in CONSISTENCY):
        return "NIS/NEES propagation (Python)"
    if "fgslam/smoother/" in path:
        return "smoother bookkeeping (Python)"
    return None


def categorise(profile: cProfile.Profile) -> dict[str, float]:
    """Seconds per category: each function's own time, charged up the call graph to the
    nearest caller with a category (split over callers in proportion to their calls' time)."""
    stats = pstats.Stats(profile).stats
    out: dict[str, float] = defaultdict(float)

    def charge(func, seconds: float, depth: int = 0) -> None:
        name = category(func)
        callers = stats[func][4] if func in stats else {}
        if name is not None or not callers or depth > 50:
            out[name or "other"] += seconds
            return
        total = sum(c[2] for c in callers.values()) or 1.0
        for caller, c in callers.items():
            charge(caller, seconds * (c[2] / total if total else 1.0 / len(callers)), depth + 1)

    for func, (_, _, tottime, _, _) in stats.items():
        charge(func, tottime)
    return dict(out)


class _TimedIsam:
    """Passes every call through to the real ISAM2, timing ``update`` calls."""

    def __init__(self, isam):
        self._isam = isam
        self.update_s: list[float] = []

    def update(self, *args):
        start = time.perf_counter()
        try:
            return self._isam.update(*args)
        finally:
            self.update_s.append(time.perf_counter() - start)

    def __getattr__(self, name):
        return getattr(self._isam, name)


def run(steps, header, kwargs, profiled: bool):
    """Drive the smoother over ``steps`` as ``fgslam run`` does; (smoother, timed profile,
    outside profile, seconds of each ISAM2.update, timed seconds, outside seconds)."""
    timers: list[_TimedIsam] = []

    def timed_isam(isam):
        timers.append(_TimedIsam(isam))
        return timers[-1]

    smoother = Isam2Smoother(header, isam_wrapper=timed_isam if profiled else None, **kwargs)
    timed, outside = cProfile.Profile(), cProfile.Profile()
    seconds = {"timed": 0.0, "outside": 0.0}

    def within(region: str, profile: cProfile.Profile, call) -> None:
        start = time.perf_counter()
        if profiled:
            profile.enable()
        call()
        if profiled:
            profile.disable()
        seconds[region] += time.perf_counter() - start

    for step in steps:
        within("outside", outside, lambda: smoother.predicted_nis(step))
        within("timed", timed, lambda: (smoother.step(step), smoother.current_pose()))
        within("outside", outside, smoother.current_covariance)
    within("timed", timed, smoother.finish)
    within("outside", outside, smoother.landmark_covariances)
    update_s = [t for timer in timers for t in timer.update_s]  # every ISAM2 built (rebuilds too)
    return smoother, timed, outside, update_s, seconds["timed"], seconds["outside"]


def table(title: str, seconds: dict[str, float], wall_s: float) -> None:
    total = sum(seconds.values())
    print(f"\n{title}: {total:.2f} s profiled ({wall_s:.2f} s wall with the profiler)")
    print("| where | s | share |\n|---|---|---|")
    for name, s in sorted(seconds.items(), key=lambda kv: -kv[1]):
        print(f"| {name} | {s:.2f} | {100 * s / total:.1f} % |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("log", help="a run log (.jsonl), or victoria-park")
    parser.add_argument("--preset", choices=("default", "fast"), default="default")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="Isam2Smoother keyword")
    args = parser.parse_args()
    if args.log == "victoria-park":
        from slamio.datasets.victoria_park import import_victoria_park

        header, records = import_victoria_park()
    else:
        log = read_log(args.log)
        header, records = log.header, log.records
    steps = group_steps(header, records)
    kwargs = dict(FAST_SETTINGS) if args.preset == "fast" else {}
    for item in args.set:
        key, _, text = item.partition("=")
        kwargs[key] = ast.literal_eval(text)
    print(f"{args.log}: {len(steps)} steps, Isam2Smoother({kwargs})")

    _, _, _, _, plain_timed_s, plain_outside_s = run(steps, header, kwargs, profiled=False)
    print(f"without the profiler: timed region (step + finish) {plain_timed_s:.2f} s, "
          f"NIS/NEES/landmark covariances outside it {plain_outside_s:.2f} s")
    smoother, timed, outside, update_s, timed_s, outside_s = run(steps, header, kwargs, profiled=True)
    table("timed region (step + current_pose + finish)", categorise(timed), timed_s)
    table("outside the timed region (predicted_nis, current_covariance, landmark_covariances)",
          categorise(outside), outside_s)

    print("\ntimed region, the functions with the most time of their own (GTSAM constructors included):")
    stats = pstats.Stats(timed)
    stats.sort_stats("tottime").print_stats(12)

    skip = smoother.settings.relinearize_skip
    by_phase = defaultdict(float)
    for i, s in enumerate(update_s):
        by_phase[i % skip] += s
    total = sum(by_phase.values())
    worst = max(by_phase, key=by_phase.get)
    print(f"\nISAM2.update: {len(update_s)} calls, {total:.2f} s; calls i with i % {skip} == {worst} "
          f"(1 in {skip}) took {100 * by_phase[worst] / total:.0f} % of it; "
          f"slowest call {1e3 * max(update_s):.1f} ms")


if __name__ == "__main__":
    main()
