"""iSAM2 update and read policies measured for issue 16's time goal and not adopted.

Each variant is a small subclass of the product's ``Isam2Smoother``; everything else (the
factors, the online correction, ``finish()``'s Gauss–Newton steps) is the product's. For
each log (the sources of ``scripts/bench_online.py``), in one process with BLAS on one
thread: the EKF, the every-step reference iSAM2 of ``bench_online.py``, the default
``isam2`` and the variant, run in that order ``--repeats`` times (the fastest run of each is
kept). Prints total time × the EKF's, updates, online ATE (against the log's truth, else the
batch optimum) × the reference's, and the final χ²/2 × the batch optimum's.

Variants:

* ``news C``: instead of counting held readings (``update_observations``, 20), update when
  the held readings carry ``C`` landmarks' worth of new information: each landmark
  contributes the share of its readings that are held, ``held / (in iSAM2 + held)``. A
  landmark seen hundreds of times then asks for an update far less often than a new one.
* ``marginal-reads``: read the newest pose after an update, and the landmarks the online
  correction uses, from iSAM2's Bayes-tree marginal of that one variable
  (``ISAM2.marginalFactor``, whose mean is the exact solution of the current linear
  system) at the linearisation point, instead of ``calculateEstimate``, whose lazy
  wildfire back-substitution re-solves every clique re-eliminated since the last read.
  The linearisation point is the seed a variable entered with until iSAM2 relinearises
  something, then a copy of ``getLinearizationPoint()``.

Usage::

    .venv/bin/python scripts/isam2_policies_tried.py news 1 arena:1-20 mrclam-fitted:FOLDER:1,2,3,4,5
    .venv/bin/python scripts/isam2_policies_tried.py marginal-reads 0 plaza1 victoria-park arena:1-3
"""

from __future__ import annotations

import os

os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import gtsam  # noqa: E402
import numpy as np  # noqa: E402

from bench_online import REFERENCE, logs, online_ate_m, truth_of  # noqa: E402
from ekf import EkfSlam  # noqa: E402
from fgslam.runner import run_estimator  # noqa: E402
from fgslam.smoother import Isam2Smoother, batch_solve  # noqa: E402
from slamio.log import group_steps  # noqa: E402

class NewsSmoother(Isam2Smoother):
    """Updates when the held readings carry ``news`` landmarks' worth of new information
    (and ``update_observations_min_steps`` steps are held), in place of the reading count."""

    def __init__(self, header, news: float = 1.0, **kwargs):
        super().__init__(header, update_observations=None, **kwargs)
        self.news = news
        self._readings_in_isam: dict[int, int] = {}

    def _held_news(self) -> float:
        held: dict[int, int] = {}
        for entry in self._held.entries:
            held[entry.landmark_id] = held.get(entry.landmark_id, 0) + 1
        return sum(n / (self._readings_in_isam.get(lid, 0) + n) for lid, n in held.items())

    def _due(self, k: int) -> bool:
        return super()._due(k) or (self._held.steps >= self.settings.update_observations_min_steps
                                   and self._held_news() >= self.news)

    def _flush(self) -> None:
        for entry in self._held.entries:
            self._readings_in_isam[entry.landmark_id] = self._readings_in_isam.get(entry.landmark_id, 0) + 1
        super()._flush()


class _MarginalReads:
    """An ``ISAM2`` whose single-variable reads come from its marginal of that variable."""

    def __init__(self, isam: gtsam.ISAM2, seeds: gtsam.Values):
        self._isam, self._seeds = isam, seeds
        self._linearisation: gtsam.Values | None = None
        self._stale = False

    def update(self, *args):
        result = self._isam.update(*args)
        self._stale |= result.getVariablesRelinearized() > 0
        return result

    def _at(self, key: int) -> gtsam.Values:
        if self._stale:
            self._linearisation, self._stale = self._isam.getLinearizationPoint(), False
        if self._linearisation is not None and self._linearisation.exists(key):
            return self._linearisation
        return self._seeds  # entered since the copy and not relinearised since

    def _delta(self, key: int) -> np.ndarray:
        return self._isam.marginalFactor(key).solve(gtsam.VectorValues()).at(key)

    def calculateEstimatePose2(self, key):  # noqa: N802 (GTSAM's name)
        return self._at(key).atPose2(key).retract(self._delta(key))

    def calculateEstimatePoint2(self, key):  # noqa: N802
        return self._at(key).atPoint2(key) + self._delta(key)

    def __getattr__(self, name):
        return getattr(self._isam, name)


class MarginalReadSmoother(Isam2Smoother):
    """Reads the newest pose and the correction's landmarks from single-variable marginals."""

    def step(self, step) -> None:
        if not isinstance(self._isam, _MarginalReads):  # also after a rebuild or a window slide
            self._isam = _MarginalReads(self._isam, self._initial)
        super().step(step)

    def finish(self) -> None:
        if isinstance(self._isam, _MarginalReads):
            self._isam = self._isam._isam
        super().finish()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("variant", choices=("news", "marginal-reads"))
    ap.add_argument("value", type=float, help="news: the threshold C (landmarks' worth); marginal-reads: ignored")
    ap.add_argument("logs", nargs="+", help="sources as in scripts/bench_online.py")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--robust", default=None, help="robust kernel for every iSAM2 (e.g. dcs)")
    args = ap.parse_args(argv)
    common = {"robust": args.robust} if args.robust else {}
    if args.variant == "news":
        def variant(h):
            return NewsSmoother(h, news=args.value, **common)
    else:
        def variant(h):
            return MarginalReadSmoother(h, **common)
    print(f"| log | estimator | total s | × EKF | updates | online ATE m | × reference | χ²/2 × batch |  ({args.variant} {args.value:g})")
    print("|---|---|---|---|---|---|---|---|")
    for spec in args.logs:
        for name, header, records in logs(spec):
            steps = group_steps(header, records)
            truth = truth_of(steps)
            reference, reference_smoother = run_estimator(Isam2Smoother(header, **common, **REFERENCE), steps,
                                                          covariances=False)
            batch = batch_solve(reference_smoother)
            best: dict[str, tuple] = {}
            for _ in range(args.repeats):
                for label, build in (("ekf", EkfSlam), ("isam2", lambda h: Isam2Smoother(h, **common)),
                                     (args.variant, variant)):
                    run, estimator = run_estimator(build(header), steps, covariances=False)
                    if label not in best or run.total_time_s < best[label][0].total_time_s:
                        best[label] = (run, estimator)
            ekf_s = best["ekf"][0].total_time_s
            ref_ate = online_ate_m(reference.online, truth, batch.trajectory)
            for label in ("isam2", args.variant):
                run, smoother = best[label]
                ate = online_ate_m(run.online, truth, batch.trajectory)
                print(f"| {name} | {label} | {run.total_time_s:.3f} | {run.total_time_s / ekf_s:.2f} | {smoother.updates} "
                      f"| {ate:.4f} | {ate / ref_ate:.3f} | {smoother.error() / batch.final_error:.5f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
