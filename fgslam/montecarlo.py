"""Monte Carlo consistency: many seeded simulations, average NEES per step against its band.

One run is one draw. The classic consistency test (Bar-Shalom et al.; Bailey et al. 2006
for EKF-SLAM) averages the NEES of N independent runs at each step: for a consistent
estimator N·(average) is χ²(3N), so the average lies in :func:`fgslam.compare.nees_band`
``(3, N)`` (for N = 50: [2.36, 3.72]) at about 95 % of the steps. An EKF whose heading
uncertainty grows becomes optimistic (its average NEES climbs above the band).

The runs go through any :class:`concurrent.futures.Executor`: a process pool by default,
or a Dask cluster's executor (``dask.distributed.Client(address).get_executor()``), since
each run is an independent, picklable task (:func:`run_one`).

The scenario ``stereo-loop`` is seed 003's simulated car (stereo camera + IMU) with the 3-D
estimators; its NEES is on SE(3), 6 DoF (:func:`run_one_3d`). Which estimators a scenario
takes, and its defaults, come from :mod:`fgslam.registry`.

Simulated logs have truth at every pose. Should a run lack truth at some poses, its NEES is
NaN there, its ATE is over the poses with truth, and the per-step average (with its band for
N runs) is only judged at the steps where every run has truth (``scored_steps``).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import functools
from dataclasses import dataclass

import numpy as np

from fgslam.compare import ate_rmse_m, nees, nees_band
from fgslam.registry import BENCH_DEFAULTS, names_for
from fgslam.runner import ESTIMATORS, run_estimator, truth_trajectory
from slamio.errors import FgslamError
from slamio.log import group_steps
from slamio.sim import simulate

__all__ = ["RunResult", "MonteCarloResult", "run_one", "run_one_3d", "monte_carlo", "dask_executor",
           "DEFAULT_BENCH_ESTIMATORS_3D", "POSE_DOF_3D"]

#: What ``fgslam bench stereo-loop`` runs when no estimator is named.
DEFAULT_BENCH_ESTIMATORS_3D = BENCH_DEFAULTS[3]
#: Degrees of freedom of one pose's NEES on SE(3) (fgslam.runner3d.POSE_DOF).
POSE_DOF_3D = 6


@dataclass(frozen=True)
class RunResult:
    """One seeded run: per estimator, the NEES of each online pose (NaN where the pose has no
    truth), the ATEs over the poses with truth and the time; ``has_pose`` marks the poses
    with truth (None: all of them)."""

    seed: int
    nees: dict[str, np.ndarray]
    ate_final_m: dict[str, float]
    ate_online_m: dict[str, float]
    time_s: dict[str, float]
    has_pose: np.ndarray | None = None


@dataclass(frozen=True)
class MonteCarloResult:
    """All runs, and the per-step average NEES of each estimator with its band."""

    scenario: str
    runs: list[RunResult]
    average_nees: dict[str, np.ndarray]  # (steps,) over the runs (truncated to the shortest run)
    band: tuple[float, float]
    scored_steps: np.ndarray | None = None  # (steps,) True where every run has truth; None: all
    dof: int = 3  # of one pose's NEES: 3 on SE(2), 6 on SE(3) (stereo-loop)

    def _scored(self, estimator: str) -> np.ndarray:
        a = self.average_nees[estimator]
        return a if self.scored_steps is None else a[self.scored_steps]

    def share_inside(self, estimator: str) -> float:
        """Share of the scored steps whose average NEES lies inside the band."""
        a = self._scored(estimator)
        return float(np.mean((a >= self.band[0]) & (a <= self.band[1]))) if len(a) else float("nan")

    def share_above(self, estimator: str) -> float:
        """Share of the scored steps whose average NEES lies above the band (optimistic covariance)."""
        a = self._scored(estimator)
        return float(np.mean(a > self.band[1])) if len(a) else float("nan")

    def mean_nees(self, estimator: str) -> float:
        """Mean over the scored steps of the average NEES."""
        a = self._scored(estimator)
        return float(np.mean(a)) if len(a) else float("nan")


def run_one(scenario: str, seed: int, estimators: tuple[str, ...], landmarks: int = 200,
            laps: int | None = None) -> RunResult:
    """Simulate ``scenario`` with ``seed`` and run each estimator on it (a picklable task)."""
    header, records = simulate(scenario, seed, landmarks=landmarks, laps=laps)
    steps = group_steps(header, records)
    truth, has_pose = truth_trajectory(steps)
    if not has_pose.any():
        raise FgslamError(f"{scenario} seed {seed}: the simulation recorded no ground truth; nothing to score")
    out_nees, final, online, times = {}, {}, {}, {}
    for name in estimators:
        run, _ = run_estimator(ESTIMATORS[name](header), steps)
        if run.online_covariances is None:
            raise FgslamError(f"estimator {name!r} states no covariance: no NEES to average")
        values = np.full(len(steps), np.nan)
        values[has_pose] = nees(run.online[has_pose], run.online_covariances[has_pose], truth[has_pose])
        out_nees[name] = values
        final[name] = ate_rmse_m(run.final, truth, has_pose=has_pose)
        online[name] = ate_rmse_m(run.online, truth, has_pose=has_pose)
        times[name] = run.total_time_s
    return RunResult(int(seed), out_nees, final, online, times, None if has_pose.all() else has_pose)


def run_one_3d(seed: int, estimators: tuple[str, ...], scenario=None) -> RunResult:
    """One seeded simulated stereo + IMU drive (:func:`slamio.sim3d.simulate_drive`, the
    ``scenario`` a :class:`slamio.sim3d.DriveScenario`) and every estimator on it, as ``fgslam
    run`` runs them on the drive's log: per step the pose NEES on SE(3) (right perturbation,
    6 DoF) of the online pose against the truth; the ATE is the 3-D position RMSE without
    alignment (every estimator starts at the IMU's first pose). A picklable task."""
    from fgslam.runner3d import pose_nees_series, position_rmse_m, prepare_log3d, run_estimator_3d
    from slamio.datasets.seed003_log import drive_to_log
    from slamio.log import RunLog
    from slamio.sim3d import DriveScenario, simulate_drive

    drive = simulate_drive(seed, scenario or DriveScenario())
    # the drive's log, with the simulator's noise on every record: what `fgslam sim stereo-loop` writes
    header, records = drive_to_log(drive)
    ready = prepare_log3d(RunLog(f"stereo-loop seed {seed}", header, tuple(records)))
    truth = drive.truth_world_T_imu
    out_nees, final, online, times = {}, {}, {}, {}
    for name in estimators:
        run = run_estimator_3d(ready.estimator(name), ready.inputs, stamps_s=ready.stamps_s)
        out_nees[name] = pose_nees_series(run.online, run.covariances, truth)
        final[name] = position_rmse_m(run.final, truth)
        online[name] = position_rmse_m(run.online, truth)
        times[name] = run.total_time_s
    return RunResult(int(seed), out_nees, final, online, times, None)


@contextlib.contextmanager
def dask_executor(address: str, timeout_s: float = 20.0):
    """``with dask_executor(address) as executor:`` the ``concurrent.futures`` executor of
    the Dask distributed cluster at ``address`` (the optional ``dask`` extra); the client
    is closed on the way out."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise FgslamError(
            "--dask needs the optional dask extra: pip install 'fgslam[dask]' (or dask[distributed])"
        ) from None
    try:
        client = Client(address, timeout=timeout_s)
    except OSError as error:
        raise FgslamError(
            f"cannot reach the Dask scheduler at {address} ({error}); start one with "
            "`dask scheduler` and `dask worker ADDRESS`, or leave out --dask for a local process pool"
        ) from None
    try:
        yield client.get_executor()
    finally:
        client.close()


def monte_carlo(
    scenario: str,
    runs: int,
    *,
    estimators: tuple[str, ...] | None = None,
    first_seed: int = 0,
    jobs: int = 2,
    landmarks: int = 200,
    laps: int | None = None,
    executor: concurrent.futures.Executor | None = None,
    progress=None,
    drive_scenario=None,
) -> MonteCarloResult:
    """Run seeds ``first_seed .. first_seed + runs − 1`` through ``executor`` (default: a
    process pool with ``jobs`` workers) and average each estimator's NEES per step.

    ``estimators`` default to ekf and isam2, and on ``stereo-loop`` to
    :data:`DEFAULT_BENCH_ESTIMATORS_3D`; ``drive_scenario`` (a
    :class:`slamio.sim3d.DriveScenario`) changes the stereo-loop's geometry."""
    from slamio.sim3d import STEREO_LOOP

    if runs < 1:
        raise FgslamError(f"runs must be >= 1, got {runs}")
    dimension = 3 if scenario == STEREO_LOOP else 2
    estimators = tuple(estimators or BENCH_DEFAULTS[dimension])
    if dimension == 3:
        dof = POSE_DOF_3D
        task = functools.partial(run_one_3d, estimators=estimators, scenario=drive_scenario)  # task(seed)
    else:
        dof = 3
        task = functools.partial(run_one, scenario, estimators=estimators, landmarks=landmarks, laps=laps)
    known = names_for(dimension)
    unknown = [e for e in estimators if e not in known]
    if unknown:
        raise FgslamError(f"unknown estimator(s) {', '.join(unknown)}; choose from {', '.join(known)}")
    seeds = range(first_seed, first_seed + runs)
    own = executor is None
    pool = concurrent.futures.ProcessPoolExecutor(max_workers=max(1, jobs)) if own else executor
    try:
        futures = [pool.submit(task, s) for s in seeds]
        results = []
        for i, future in enumerate(concurrent.futures.as_completed(futures)):
            results.append(future.result())
            if progress is not None:
                progress(i + 1, runs, "monte carlo")
    finally:
        if own:
            pool.shutdown()
    results.sort(key=lambda r: r.seed)
    n = min(len(r.nees[estimators[0]]) for r in results)
    average = {e: np.mean([r.nees[e][:n] for r in results], axis=0) for e in estimators}
    scored = None
    if any(r.has_pose is not None for r in results):  # judge only steps where every run has truth
        scored = np.all([np.ones(n, bool) if r.has_pose is None else r.has_pose[:n] for r in results], axis=0)
    return MonteCarloResult(scenario, results, average, nees_band(dof, runs), scored, dof)
