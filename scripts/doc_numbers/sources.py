"""The measurements behind the docs' numbers, each through the code the docs' command runs.

``fgslam run LOG --estimators E`` is :func:`fgslam.runner.compare_log` then
:func:`fgslam.compare.compute_metrics` (what the command prints and writes to metrics.json);
``fgslam sim ...`` is :func:`slamio.sim.simulate` (the same bytes, a test checks it); a
script's experiment is called through the function the script itself uses. Everything runs in
this process (no start-up cost per run) with BLAS pinned to one thread, as the docs' runs are.
"""

from __future__ import annotations

from pathlib import Path

from doc_numbers.quotes import Context, Source

DEFAULT = "ekf,isam2,dead_reckoning"  # fgslam run's default estimators
PAPERS = "ekf,ekf-s000,ekf-s001,ekf-s004,isam2,isam2-tags"
ROBUST = "ekf,isam2,isam2-huber,isam2-cauchy,isam2-tukey,isam2-dcs"
ASSOCIATING = "ekf,ekf-nn,ekf-s001,isam2"
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


def bundled(log: str, estimators: str = DEFAULT, consistency: bool = True):
    return lambda context: run_metrics(context.root / "data" / log, estimators, consistency)


def truth_metrics(log, estimator) -> dict:
    """One estimator on ``log`` (a RunLog with truth at every pose), scored against the truth."""
    from fgslam.compare import compute_metrics
    from fgslam.runner import run_estimator, truth_reference

    run, _ = run_estimator(estimator, log.steps())
    return compute_metrics([run], truth_reference(log), log_path=str(log.path))[run.name]


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
    from slamio.create.calibrate import calibrate, read_trials
    from slamio.log import read_log

    trials = context.root / "data" / "calibration_trials_s001.csv"
    cal = context.scratch / "cal_s001.json"
    cal.write_text(json.dumps(calibrate(*read_trials(trials), source=str(trials)).to_dict()), encoding="utf-8")
    out = {}
    for name in ("arena_octagon", "arena_square"):
        log = read_log(context.root / "data" / f"{name}.jsonl")
        out[name] = truth_metrics(log, EkfS001(log.header))
        calibrated = with_trial_calibration(log, cal)
        out[f"{name}+cal"] = truth_metrics(calibrated, EkfS001(calibrated.header))
    return out


def flaw_costs(context: Context) -> dict:
    """``scripts/flaw_costs.py`` on the bundled logs and on the simulated cylinders (seed 1):
    log name → setting → metrics."""
    import flaw_costs as script  # scripts/ is on sys.path (check_doc_numbers.py, the test)
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


def camera_accuracy(context: Context) -> dict[str, list[str]]:
    """``python -m slamio.camera.accuracy``'s table: first cell → the numbers of its row."""
    from doc_numbers.readers import markdown_rows
    from slamio.camera.accuracy import error_table, format_table

    return markdown_rows(format_table(error_table()))


def real_corner_sigma(context: Context) -> tuple[float, int]:
    """σ_px of the refined corners on the pupil-labs photos, and the number of tags."""
    from slamio.camera.accuracy import real_corner_sigma_px

    return real_corner_sigma_px(context.root / "tests" / "data" / "apriltag-photos")


def seed002_shapes(context: Context) -> dict:
    """``scripts/seed002_shapes.py``: the heights per shape, distance and bearing, and the
    summary over all frames (min, max, mean deviation in %, frames measured) per method."""
    import math

    import seed002_shapes as script

    rows = script.measure(2.0, 0)
    out: dict = {(r["shape"], r["distance_m"], r["bearing_deg"]): r for r in rows}
    for method in ("gheight", "pinhole"):
        dev = [100 * (r[method] / r["actual_m"] - 1) for r in rows if math.isfinite(r[method])]
        out[method] = {"min": min(dev), "max": max(dev), "mean": sum(dev) / len(dev), "measured": len(dev)}
    return out


SOURCES = [
    Source("octagon", f"fgslam run data/arena_octagon.jsonl --estimators {DEFAULT},{PAPERS}", "cheap",
           bundled("arena_octagon.jsonl", f"{DEFAULT},{PAPERS}")),
    Source("square-papers", f"fgslam run data/arena_square.jsonl --estimators {PAPERS}", "cheap",
           bundled("arena_square.jsonl", PAPERS, consistency=False)),
    Source("octagon-outliers", f"fgslam sim arena-octagon --seed 1 --outliers 0.1 --outlier-mode add; "
           f"fgslam run --estimators {ROBUST}", "cheap",
           sim_then_run("outliers", "arena-octagon", ROBUST, consistency=False, **OUTLIERS)),
    Source("octagon-hidden", f"fgslam sim arena-octagon --seed 1 --hide-ids; fgslam run --estimators {ASSOCIATING}",
           "cheap", sim_then_run("octagon_hidden", "arena-octagon", ASSOCIATING, consistency=False, hide_ids=True)),
    Source("check-octagon", "fgslam check data/arena_octagon.jsonl --estimator ekf --against smoothed", "cheap",
           check_smoothed),
    Source("trial-calibration", "fgslam calibrate data/calibration_trials_s001.csv; fgslam run LOG --calibration",
           "cheap", trial_calibration),
    Source("flaw-costs", "python scripts/flaw_costs.py (+ fgslam sim cylinders --seed 1)", "slow", flaw_costs),
    Source("camera-accuracy", "python -m slamio.camera.accuracy", "slow", camera_accuracy),
    Source("tag-corner-sigma", "slamio.camera.accuracy.real_corner_sigma_px(tests/data/apriltag-photos)", "cheap",
           real_corner_sigma),
    Source("seed002-shapes", "python scripts/seed002_shapes.py", "cheap", seed002_shapes),
    Source("grid200", "fgslam sim grid --landmarks 200 --seed 1; fgslam run", "slow",
           sim_then_run("grid200", "grid", landmarks=200)),
    Source("grid200-hidden", f"fgslam sim grid --landmarks 200 --seed 1 --hide-ids; fgslam run --estimators "
           f"{ASSOCIATING}", "slow", sim_then_run("grid200_hidden", "grid", ASSOCIATING, consistency=False,
                                                  landmarks=200, hide_ids=True)),
]


def ekf_without_gate(context: Context) -> float:
    """The EKF's ATE on the outlier log of ``octagon-outliers`` with its known-id gate off."""
    from ekf import EkfSlam
    from slamio.log import read_log

    log = read_log(simulated(context, "outliers_no_gate", "arena-octagon", 1, **OUTLIERS))
    return truth_metrics(log, EkfSlam(log.header, known_id_gate_probability=None))["ate_rmse_m"]


SOURCES.append(Source("octagon-outliers-ekf-no-gate", "fgslam sim arena-octagon --seed 1 --outliers 0.1 "
                      "--outlier-mode add; EkfSlam(known_id_gate_probability=None)", "cheap", ekf_without_gate))
