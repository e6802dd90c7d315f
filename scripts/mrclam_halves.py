"""Does a noise model fitted on half a run hold on the other half? (issue 42's goal: NEES in
band ≥ 85 % and ATE no worse than the round guess.)

For each robot of a UTIAS MRCLAM dataset folder:

1. import it with the round-number noise (``fgslam import mrclam ... --noise round``);
2. split the log at its middle pose: the first half as recorded, the second half starting at
   that pose with Vicon's pose there as its start (as a user would restart a run where they
   know where the robot is);
3. fit a model on the first half, with truth (``fgslam calibrate``) and without
   (``fgslam calibrate --without-truth``);
4. run ``ekf`` and ``isam2`` on the second half with the round guess and with each model
   (``fgslam run HALF --noise FILE``), and read their ``metrics.json``.

Prints one markdown table per estimator: anchored ATE / aligned ATE / NEES in band / NIS in
band, round guess → fitted with truth → fitted without truth, and the medians.

Usage::

    .venv/bin/python -m scripts.mrclam_halves ../shared/data/mrclam/MRCLAM_Dataset6 --work /tmp/halves
    .venv/bin/python -m scripts.mrclam_halves FOLDER --work DIR --odometry-window 5 --estimators ekf,ekf-fej,isam2
    .venv/bin/python -m scripts.mrclam_halves FOLDER --work DIR --odometry-window 15 --self-window 15 --estimators ekf-inv,isam2
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import statistics
from pathlib import Path

from fgslam.cli import main as fgslam
from slamio.log import Odometry, TruthPose, read_log, write_log

MODELS = ("round", "truth", "self")
COLUMNS = (("ate_rmse_m", "ATE m"), ("ate_aligned_rmse_m", "aligned m"), ("nees_inside_95", "NEES in band"),
           ("nis_inside_95", "NIS in band"))


def split_at_middle(path: Path, first: Path, second: Path) -> None:
    """``path`` cut at its middle pose: ``first`` up to it, ``second`` from it (its start pose
    the truth there)."""
    log = read_log(path)
    odometry = [i for i, r in enumerate(log.records) if isinstance(r, Odometry)]
    k, following = odometry[len(odometry) // 2], odometry[len(odometry) // 2 + 1]
    truth = next(r for r in log.records[k:following] if isinstance(r, TruthPose))
    write_log(first, log.header, log.records[:k])
    header = dataclasses.replace(log.header, stamp_s=log.records[k].stamp_s,
                                 start_pose=(truth.x_m, truth.y_m, truth.theta_rad))
    write_log(second, header, log.records[k + 1:])


def _quiet(*argv: str) -> None:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        status = fgslam(list(argv))
    if status != 0:
        raise SystemExit(f"fgslam {' '.join(argv)} failed ({status})")


def measure_robot(folder: str, robot: int, work: Path, window_s: float = 1.0,
                  estimators: str = "ekf,isam2", self_window_s: float | None = None) -> dict[str, dict]:
    """``{model: metrics.json}`` of robot's second half (the model with truth fitted over
    ``window_s`` stretches of odometry: ``fgslam calibrate --odometry-window``; the model
    without truth over ``self_window_s`` stretches, step by step when None)."""
    whole, first, second = (work / f"r{robot}{part}.jsonl" for part in ("", "a", "b"))
    _quiet("import", "mrclam", folder, str(whole), "--robot", str(robot), "--noise", "round", "--overwrite")
    split_at_middle(whole, first, second)
    _quiet("calibrate", str(first), "--out", str(work / f"truth{robot}.json"), "--overwrite",
           "--odometry-window", str(window_s))
    self_window = [] if self_window_s is None else ["--odometry-window", str(self_window_s)]
    _quiet("calibrate", str(first), "--without-truth", "--out", str(work / f"self{robot}.json"), "--overwrite",
           *self_window)
    metrics = {}
    for model in MODELS:
        out = work / f"out_{model}_{robot}"
        noise = [] if model == "round" else ["--noise", str(work / f"{model}{robot}.json")]
        _quiet("run", str(second), "--estimators", estimators, "--out", str(out), "--overwrite", *noise)
        metrics[model] = json.loads((out / "metrics.json").read_text())
    return metrics


def print_tables(results: dict[int, dict[str, dict]], names: list[str]) -> None:
    def cell(values) -> str:
        return " → ".join("-" if v is None else f"{v:.3f}" for v in values)

    for name in names:
        print(f"\n{name}: round guess → fitted with truth → fitted without truth (second half of each run)\n")
        print("| robot | " + " | ".join(label for _, label in COLUMNS) + " |")
        print("|---" * (len(COLUMNS) + 1) + "|")
        for robot, by_model in results.items():
            print(f"| {robot} | " + " | ".join(cell(by_model[m][name].get(key) for m in MODELS)
                                              for key, _ in COLUMNS) + " |")
        medians = [cell(statistics.median(r[m][name][key] for r in results.values()) for m in MODELS)
                   for key, _ in COLUMNS]
        print("| **median** | " + " | ".join(medians) + " |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", help="an MRCLAM dataset folder (e.g. ../shared/data/mrclam/MRCLAM_Dataset6)")
    parser.add_argument("--work", type=Path, required=True, help="a folder for the logs, models and runs")
    parser.add_argument("--robots", default="1,2,3,4,5")
    parser.add_argument("--odometry-window", type=float, default=1.0, metavar="S",
                        help="the model with truth fits the odometry over S-second stretches (default 1)")
    parser.add_argument("--self-window", type=float, default=None, metavar="S",
                        help="the model without truth fits the odometry over S-second stretches "
                             "(default: step by step, as calibrate --without-truth does)")
    parser.add_argument("--estimators", default="ekf,isam2")
    args = parser.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    results = {}
    for robot in (int(r) for r in args.robots.split(",")):
        results[robot] = measure_robot(args.folder, robot, args.work, args.odometry_window, args.estimators,
                                       args.self_window)
        print(f"robot {robot}: done", flush=True)
    print_tables(results, args.estimators.split(","))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
