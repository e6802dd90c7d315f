"""Measurements that are fgslam runs: the bundled logs, simulated runs, `fgslam check`,
`fgslam bench`, the seed sweeps, the seed papers' flaw costs.

``fgslam run LOG --estimators E`` is :func:`fgslam.runner.compare_log` then
:func:`fgslam.compare.compute_metrics` (what the command prints and writes to metrics.json);
``fgslam sim ...`` is :func:`slamio.sim.simulate` (the same bytes, a test checks it). Everything
runs in this process (no start-up cost per run) with BLAS pinned to one thread, as the docs'
runs are.
"""

from __future__ import annotations

from pathlib import Path

from scripts.doc_numbers.quotes import Context

DEFAULT = "ekf,isam2,dead_reckoning"  # fgslam run's default estimators
PAPERS = "ekf,ekf-s000,ekf-s001,ekf-s004,isam2,isam2-tags"
ROBUST = "ekf,isam2,isam2-huber,isam2-cauchy,isam2-tukey,isam2-dcs"
ASSOCIATING = "ekf,ekf-nn,ekf-s001"
OUTLIERS = dict(outliers=0.1, outlier_mode="add")


def run_metrics(log_path: str | Path, estimators: str = DEFAULT, consistency: bool = True) -> dict:
    """``fgslam run LOG --estimators E``'s metrics.json, as a dictionary. Each estimator's figures
    do not depend on which others run with it (the batch solve is always plain isam2's);
    ``consistency=False`` is ``--no-consistency`` (no NEES/NIS: faster, the same accuracy)."""
    from fgslam.compare import compute_metrics
    from fgslam.runner import compare_log, parse_estimator_names
    from slamio.log import read_log

    result = compare_log(read_log(log_path), parse_estimator_names(estimators), consistency=consistency)
    return compute_metrics(result.runs, result.reference, log_path=str(log_path))


def simulated(context: Context, name: str, scenario: str, seed: int, **options) -> Path:
    """``fgslam sim SCENARIO --seed N [options] --out SCRATCH/NAME.jsonl``: the log's path."""
    from slamio.log import write_log
    from slamio.sim import simulate

    path = context.scratch / f"{name}.jsonl"
    write_log(path, *simulate(scenario, seed, **options))
    return path


def sim_then_run(name: str, scenario: str, estimators: str = DEFAULT, consistency: bool = True, **options):
    def measure(context: Context) -> dict:
        return run_metrics(simulated(context, name, scenario, 1, **options), estimators, consistency)
    return measure


def against_truth(name: str, scenario: str, estimators: str, **options):
    """``fgslam sim SCENARIO --seed 1 [options]`` and the named estimators scored against its truth
    (truth at every pose: the reference ``fgslam run`` uses too), without the iSAM2 + batch
    solve ``fgslam run`` adds, no NEES/NIS: their figures as ``fgslam run`` prints them."""
    def measure(context: Context) -> dict:
        from fgslam.compare import compute_metrics
        from fgslam.runner import ESTIMATORS, run_estimator, truth_reference
        from slamio.log import read_log

        log = read_log(simulated(context, name, scenario, 1, **options))
        steps = log.steps()
        runs = [run_estimator(ESTIMATORS[e](log.header), steps, covariances=False)[0]
                for e in estimators.split(",")]
        return compute_metrics(runs, truth_reference(log), log_path=str(log.path))
    return measure


def bundled(log: str, estimators: str = DEFAULT, consistency: bool = True):
    return lambda context: run_metrics(context.root / "data" / log, estimators, consistency)


def truth_metrics(log, estimator) -> dict:
    """One estimator on ``log`` (a RunLog with truth at every pose), scored against the truth."""
    from fgslam.compare import compute_metrics
    from fgslam.runner import run_estimator, truth_reference

    run, _ = run_estimator(estimator, log.steps())
    return compute_metrics([run], truth_reference(log), log_path=str(log.path))[run.name]


def hidden_ids(*scenarios: str):
    """Scenario → metrics of the associating estimators on its seed-1 run with hidden ids."""
    def measure(context: Context) -> dict:
        return {scenario: against_truth(f"{scenario}_hidden", scenario, ASSOCIATING, hide_ids=True)(context)
                for scenario in scenarios}
    return measure


def check_smoothed(context: Context) -> float:
    """The ATE of ``fgslam check data/arena_octagon.jsonl --estimator ekf --against smoothed``."""
    from fgslam.check import check_estimator

    return check_estimator(context.root / "data" / "arena_octagon.jsonl", estimator="ekf", against="smoothed",
                           max_ate_m=0.5, max_nees_outside=0.1).ate_m


def trial_calibration(context: Context) -> dict:
    """ekf-s001 on both bundled logs with and without seed 001's example trial calibration
    (``fgslam calibrate data/calibration_trials_s001.csv --out cal.json``, then
    ``fgslam run LOG --calibration cal.json``): log name (+cal) → ekf-s001's metrics."""
    import json

    from ekf import EkfS001
    from fgslam.cli.run import with_trial_calibration
    from slamio.noise.trials import calibrate_from_trials, read_trials
    from slamio.log import read_log

    trials = context.root / "data" / "calibration_trials_s001.csv"
    cal = context.scratch / "cal_s001.json"
    cal.write_text(json.dumps(calibrate_from_trials(*read_trials(trials), source=str(trials)).to_dict()), encoding="utf-8")
    out = {}
    for name in ("arena_octagon", "arena_square"):
        log = read_log(context.root / "data" / f"{name}.jsonl")
        out[name] = truth_metrics(log, EkfS001(log.header))
        calibrated = with_trial_calibration(log, cal)
        out[f"{name}+cal"] = truth_metrics(calibrated, EkfS001(calibrated.header))
    return out


def ekf_without_gate(context: Context) -> float:
    """The EKF's ATE on the outlier log of ``octagon-outliers`` with its known-id gate off."""
    from ekf import EkfSlam
    from slamio.log import read_log

    log = read_log(simulated(context, "outliers_no_gate", "arena-octagon", 1, **OUTLIERS))
    return truth_metrics(log, EkfSlam(log.header, known_id_gate_probability=None))["ate_rmse_m"]


def flaw_costs(context: Context) -> dict:
    """``scripts/flaw_costs.py`` on the bundled logs and on the simulated cylinders (seed 1):
    log name → setting → metrics."""
    from scripts import flaw_costs as script
    from ekf import DeadReckoning
    from slamio.log import read_log

    cylinders = simulated(context, "cylinders", "cylinders", 1)
    logs = [context.root / "data" / "arena_octagon.jsonl", context.root / "data" / "arena_square.jsonl", cylinders]
    out = {}
    for path in logs:
        out[path.stem] = script.measure(path)
        log = read_log(path)
        out[path.stem]["dead reckoning"] = truth_metrics(log, DeadReckoning(log.header))
    return out


def monte_carlo_octagon(context: Context) -> dict:
    """``fgslam bench arena-octagon --runs 50 --jobs 2 --estimators ekf,ekf-fej,isam2``: band, steps and per estimator the
    share inside/above the band (%), mean NEES and the final ATE's median and max."""
    import numpy as np

    from fgslam.montecarlo import monte_carlo

    result = monte_carlo("arena-octagon", 50, estimators=("ekf", "ekf-fej", "isam2"), jobs=2)
    out = {"band": result.band, "steps": len(next(iter(result.average_nees.values())))}
    for name in ("ekf", "ekf-fej", "isam2"):
        finals = np.array([r.ate_final_m[name] for r in result.runs])
        out[name] = (100 * result.share_inside(name), 100 * result.share_above(name), result.mean_nees(name),
                     float(np.median(finals)), float(np.max(finals)))
    return out


def seed_sweep(scenario: str, seeds: range, landmarks: int = 200):
    """``scripts/seed_sweep.py SCENARIO --seeds A-B``: the rows its claims are counted from."""
    def measure(context: Context) -> list[dict]:
        from concurrent.futures import ProcessPoolExecutor

        from scripts import seed_sweep as script

        with ProcessPoolExecutor(max_workers=2) as pool:
            return list(pool.map(script.one_seed, [scenario] * len(seeds), seeds, [landmarks] * len(seeds)))
    return measure


def victoria_park(context: Context) -> dict:
    """``fgslam import victoria-park vp.jsonl`` (the gtsam wheel's copy), then
    ``fgslam run vp.jsonl --estimators ekf,ekf-fej,isam2-fast,dead_reckoning``; and, as
    ``ekf-gated``, the EKF with its known-id validation gate forced on, against the same reference."""
    from ekf import EkfSlam
    from fgslam.compare import compute_metrics
    from fgslam.runner import compare_log, parse_estimator_names, run_estimator
    from slamio.datasets import import_victoria_park
    from slamio.log import read_log, write_log

    path = context.scratch / "vp.jsonl"
    write_log(path, *import_victoria_park())
    log = read_log(path)
    result = compare_log(log, parse_estimator_names("ekf,ekf-fej,isam2-fast,dead_reckoning"))
    gated, _ = run_estimator(EkfSlam(log.header, known_id_gate_probability=0.9999), log.steps(), covariances=False)
    metrics = compute_metrics(result.runs, result.reference, log_path=str(path))
    metrics["ekf-gated"] = compute_metrics([gated], result.reference, log_path=str(path))["ekf"]
    return metrics


def live_replay(context: Context) -> dict:
    """``tests/data/live-sim/octagon.jsonl`` (a lap of ``fgslam live --port sim``) replayed:
    estimator → ``nees_mean`` and ``nees_max`` of its online poses against the log's truth."""
    import numpy as np

    from fgslam.compare import nees_over_truth
    from fgslam.runner import ESTIMATORS, run_estimator, truth_trajectory
    from slamio.log import read_log

    log = read_log(context.root / "tests" / "data" / "live-sim" / "octagon.jsonl")
    steps = log.steps()
    truth, has = truth_trajectory(steps)
    out = {}
    for name in ("ekf", "isam2"):
        run, _ = run_estimator(ESTIMATORS[name](log.header), steps)
        nees, _ = nees_over_truth(run.online, run.online_covariances, truth, has)
        out[name] = {"nees_mean": float(np.mean(nees)), "nees_max": float(np.max(nees))}
    return out


def window_arena(context: Context) -> dict:
    """``python -m scripts.bench_window arena-laps:1:40 --window 200 500`` without its times:
    window → online ATE against the truth over that with every pose kept, and χ²/2 over the
    whole graph's (the batch optimum's)."""
    from scripts.bench_online import logs, online_ate_m, truth_of
    from fgslam.runner import run_estimator
    from fgslam.smoother import Isam2Smoother, batch_solve
    from slamio.log import group_steps

    (_, header, records), = logs("arena-laps:1:40")
    steps = group_steps(header, records)
    truth = truth_of(steps)
    out, reference, batch = {}, None, None
    for window in (None, 200, 500):
        smoother = Isam2Smoother(header, window_poses=window)
        run, _ = run_estimator(smoother, steps, covariances=False)
        batch = batch or batch_solve(smoother)
        ate = online_ate_m(run.online, truth, batch.trajectory)
        reference = reference or ate
        out[window] = {"online_ratio": ate / reference, "chi2_ratio": smoother.error() / batch.final_error,
                       "slides": smoother.window_slides}
    return out

