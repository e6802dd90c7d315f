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


def hidden_ids(*scenarios: str):
    """Scenario → metrics of the associating estimators on its seed-1 run with hidden ids."""
    def measure(context: Context) -> dict:
        return {scenario: sim_then_run(f"{scenario}_hidden", scenario, ASSOCIATING, consistency=False,
                                       hide_ids=True)(context) for scenario in scenarios}
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


def apriltag_photos(context: Context) -> dict:
    """``scripts/bench_apriltag.py``'s accuracy columns (no timing) on the NASA photos: detector
    name → (found, listed, false detections, corner error max, mean px); "refined" → the chosen
    detector's corners after ``refine_tag_corners`` (found, listed, max, mean, kept)."""
    import bench_apriltag as script
    import cv2

    from slamio.camera.accuracy import MatchResult, match_detections, read_corner_list
    from slamio.camera.apriltag import AprilTagDetector, refine_tag_corners

    nasa = sorted((context.root / "tests" / "data" / "apriltag-photos").glob("nasa_*.jpg"))
    images = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in nasa]
    listed = [read_corner_list(p.with_suffix(".txt")) for p in nasa]
    out = {}
    for name, settings in script.CONFIGS:
        detector, total = AprilTagDetector(**settings), MatchResult()
        for image, tags, path in zip(images, listed, nasa):
            found = [(d.tag_id, d.corners_px) for d in detector.detect(image)]
            total.add(match_detections(found, tags, image=path.name))
        out[name] = (total.found, total.listed, len(total.false_detections), total.max_corner_error_px,
                     total.mean_corner_error_px)
    detector, refined, kept = AprilTagDetector(), MatchResult(), 0
    for image, tags, path in zip(images, listed, nasa):
        pairs = []
        for d in detector.detect(image):
            corners = refine_tag_corners(image, d.corners_px)
            kept += corners is None
            pairs.append((d.tag_id, d.corners_px if corners is None else corners))
        refined.add(match_detections(pairs, tags, image=path.name))
    out["refined"] = (refined.found, refined.listed, refined.max_corner_error_px, refined.mean_corner_error_px, kept)
    return out


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
           "cheap", hidden_ids("arena-octagon")),
    Source("square-cylinders-hidden", "fgslam sim arena-square|cylinders --seed 1 --hide-ids; fgslam run "
           f"--estimators {ASSOCIATING}", "slow", hidden_ids("arena-square", "cylinders")),
    Source("check-octagon", "fgslam check data/arena_octagon.jsonl --estimator ekf --against smoothed", "cheap",
           check_smoothed),
    Source("trial-calibration", "fgslam calibrate data/calibration_trials_s001.csv; fgslam run LOG --calibration",
           "cheap", trial_calibration),
    Source("flaw-costs", "python scripts/flaw_costs.py (+ fgslam sim cylinders --seed 1)", "slow", flaw_costs),
    Source("camera-accuracy", "python -m slamio.camera.accuracy", "slow", camera_accuracy),
    Source("tag-corner-sigma", "slamio.camera.accuracy.real_corner_sigma_px(tests/data/apriltag-photos)", "cheap",
           real_corner_sigma),
    Source("apriltag-photos", "python scripts/bench_apriltag.py (accuracy columns)", "slow", apriltag_photos),
    Source("seed002-shapes", "python scripts/seed002_shapes.py", "slow", seed002_shapes),
    Source("grid200", f"fgslam sim grid --landmarks 200 --seed 1; fgslam run --estimators {DEFAULT},isam2-fast",
           "slow", sim_then_run("grid200", "grid", f"{DEFAULT},isam2-fast", landmarks=200)),
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


def monte_carlo_octagon(context: Context) -> dict:
    """``fgslam bench arena-octagon --runs 50 --jobs 2``: band, steps and per estimator the
    share inside/above the band (%), mean NEES and the final ATE's median and max."""
    import numpy as np

    from fgslam.montecarlo import monte_carlo

    result = monte_carlo("arena-octagon", 50, estimators=("ekf", "isam2"), jobs=2)
    out = {"band": result.band, "steps": len(next(iter(result.average_nees.values())))}
    for name in ("ekf", "isam2"):
        finals = np.array([r.ate_final_m[name] for r in result.runs])
        out[name] = (100 * result.share_inside(name), 100 * result.share_above(name), result.mean_nees(name),
                     float(np.median(finals)), float(np.max(finals)))
    return out


def seed_sweep(scenario: str, seeds: range, landmarks: int = 200):
    """``scripts/seed_sweep.py SCENARIO --seeds A-B``: the rows its claims are counted from."""
    def measure(context: Context) -> list[dict]:
        from concurrent.futures import ProcessPoolExecutor

        import seed_sweep as script

        with ProcessPoolExecutor(max_workers=2) as pool:
            return list(pool.map(script.one_seed, [scenario] * len(seeds), seeds, [landmarks] * len(seeds)))
    return measure


def seed004_paths(tag_noise: str):
    """``scripts/seed004_paths.py --seeds 1-20 --jobs 2 --tag-noise T``: (path, seed) → its row."""
    def measure(context: Context) -> dict:
        from concurrent.futures import ProcessPoolExecutor

        import seed004_paths as script

        jobs = [(p, s) for s in range(1, 21) for p in script.PATHS]
        with ProcessPoolExecutor(max_workers=2) as pool:
            rows = pool.map(script.one_run, [j[0] for j in jobs], [j[1] for j in jobs], [tag_noise] * len(jobs))
            return {(r["scenario"], r["seed"]): r for r in rows}
    return measure


SOURCES += [
    Source("bench-octagon", "fgslam bench arena-octagon --runs 50 --jobs 2", "slow", monte_carlo_octagon),
    Source("sweep-octagon", "python scripts/seed_sweep.py arena-octagon --seeds 0-19 --jobs 2", "long",
           seed_sweep("arena-octagon", range(0, 20))),
    Source("sweep-grid200", "python scripts/seed_sweep.py grid --landmarks 200 --seeds 0-5 --jobs 2", "long",
           seed_sweep("grid", range(0, 6))),
    Source("seed004-measured", "python scripts/seed004_paths.py --seeds 1-20 --jobs 2", "long",
           seed004_paths("measured")),
    Source("seed004-nominal", "python scripts/seed004_paths.py --seeds 1-20 --jobs 2 --tag-noise nominal", "long",
           seed004_paths("nominal")),
]


def mrclam_dataset6(context: Context) -> dict:
    """``scripts/bench_mrclam.py SHARED/data/mrclam/MRCLAM_Dataset6``: robot → estimator → its
    scores (each robot with the noise model fitted on the other four)."""
    import contextlib
    import io
    import json

    import bench_mrclam as script

    out = context.scratch / "mrclam6.json"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        script.main([str(context.shared / MRCLAM6), "--json", str(out)])
    return {int(k): v for k, v in json.loads(out.read_text(encoding="utf-8"))["results"].items()}


MRCLAM6 = "data/mrclam/MRCLAM_Dataset6"
SOURCES.append(Source("mrclam6", "python scripts/bench_mrclam.py ../shared/data/mrclam/MRCLAM_Dataset6", "slow",
                      mrclam_dataset6, shared=MRCLAM6))


def seed003_drives(names_or_seeds, shared: bool):
    """``scripts/seed003_drives.py``'s first table: drive → estimator → ATE 3-D m (real drives
    against the batch smoother, simulated ones against the truth)."""
    def measure(context: Context) -> dict:
        import seed003_drives as script

        from ekf.drive3d import position_errors_m
        from slamio.datasets.seed003 import load_drive
        from slamio.sim3d import simulate_drive

        out = {}
        for item in names_or_seeds:
            drive = load_drive(context.shared / SEED003 / f"{item}.npz") if shared else simulate_drive(item)
            results, _, batch = script.run_all(drive)
            reference, _, _ = script.reference_of(drive, batch)
            out[item] = {name: position_errors_m(trajectory, reference)[0] for name, (trajectory, _, _) in results.items()}
        return out
    return measure


SEED003 = "data/seed003"
SOURCES += [
    Source("seed003-real", "python scripts/seed003_drives.py --data ../shared/data/seed003 (real drives)", "slow",
           seed003_drives(("0020", "0027", "0042"), shared=True), shared=SEED003),
    Source("seed003-sim", "python scripts/seed003_drives.py --seeds 1-10 (simulated drives)", "long",
           seed003_drives(range(1, 11), shared=False)),
]
