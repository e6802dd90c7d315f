"""The ``fgslam`` command line: simulate a run, compare estimators on a log, check a log.

Every verb explains itself with ``--help``. Errors a user can cause print one line,
``fgslam: error: <file:line: what is wrong, how to fix it>``, and exit with status 1.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import shlex
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from slamio.errors import FgslamError
from slamio.log import LogFormatError, Observation, Odometry, RunLog, read_log, write_log

DESCRIPTION = """\
fgslam compares factor-graph smoothing (GTSAM iSAM2) against EKF-SLAM on the same
2-D landmark run log: record or simulate a run, run every estimator on it, read the
comparison.

typical use:
  fgslam sim arena-octagon --seed 1 --out run.jsonl
  fgslam run run.jsonl --out results/
"""


#: What ``--estimators`` accepts (fgslam.runner.ESTIMATORS; a test keeps the two in step).
ESTIMATOR_HELP = {
    "ekf": "textbook EKF-SLAM; JCBB data association for observations without an id",
    "ekf-nn": "the same EKF with Mahalanobis-gated nearest-neighbour association",
    "ekf-s000": "seed 000's linear KF (Trinity College, Create + Kinect), as written",
    "ekf-s001": "seed 001's EKF (GoPiGo, forward/rotate moves, nearest neighbour), as written",
    "ekf-s004": "seed 004's KF over robot and AprilTag poses, as written",
    "isam2": "GTSAM iSAM2 factor-graph smoother (the batch solve starts from its result)",
    "isam2-fast": "iSAM2 for long runs/large maps: keyframes, one update per 50 steps",
    "isam2-tags": "iSAM2 with AprilTags as Pose2 landmarks (relative-pose factors use the tag yaw)",
    "isam2-huber": "iSAM2 with a Huber kernel on landmark factors (robust to outliers)",
    "isam2-cauchy": "iSAM2 with a Cauchy kernel on landmark factors (robust to outliers)",
    "isam2-tukey": "iSAM2 with a Tukey kernel on landmark factors (misdetections get zero weight)",
    "isam2-dcs": "iSAM2 with dynamic covariance scaling: least squares within 3.7 sigma, outliers fade",
    "dead_reckoning": "odometry alone: the baseline",
}


# --------------------------------------------------------------------------- progress


class ProgressBar:
    """A one-line progress bar on stderr, drawn only when stderr is a terminal."""

    def __init__(self, stream=sys.stderr):
        self.stream = stream
        self.enabled = stream.isatty()
        self._label = None

    def __call__(self, done: int, total: int, label: str) -> None:
        if not self.enabled:
            return
        width = 30
        filled = int(width * done / max(total, 1))
        self.stream.write(f"\r{label:>15} [{'#' * filled}{'.' * (width - filled)}] {done}/{total}")
        if done >= total:
            self.stream.write("\n")
        self.stream.flush()


# --------------------------------------------------------------------------- verbs


def _summary(log: RunLog) -> str:
    steps = log.steps()
    observations = [r for r in log.records if isinstance(r, Observation)]
    ids = {o.landmark_id for o in observations if o.landmark_id is not None}
    unknown = sum(o.landmark_id is None for o in observations)
    duration = steps[-1].stamp_s - steps[0].stamp_s
    with_truth = sum(s.truth is not None for s in steps)
    surveyed = len(log.truth_landmarks())
    if with_truth == len(steps):
        truth = "ground truth for every pose"
    elif with_truth:
        truth = f"ground truth for {with_truth} of {len(steps)} poses"
    elif surveyed:
        truth = f"no pose truth, {surveyed} surveyed landmarks"
    else:
        truth = "no ground truth"
    return (
        f"{len(steps)} poses over {duration:.1f} s, {len(observations)} observations of "
        f"{len(ids)} landmarks" + (f" (+{unknown} with unknown id)" if unknown else "") + f", {truth}"
    )


def _read(path: str) -> RunLog:
    log = read_log(path)
    if log.truncated:
        print(f"fgslam: warning: {log.truncated}", file=sys.stderr)
    return log


def _write(out_path: str, header, records) -> int:
    """Write a made or imported log and say what is in it (from memory, not re-read)."""
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_log(out, header, records)
    print(f"wrote {out}: {_summary(RunLog(str(out), header, tuple(records)))}")
    return 0


def cmd_sim(args: argparse.Namespace) -> int:
    from slamio.sim import simulate

    command = "fgslam " + " ".join(shlex.quote(a) for a in args.argv)
    header, records = simulate(
        args.scenario,
        args.seed,
        landmarks=args.landmarks,
        laps=args.laps,
        hide_ids=args.hide_ids,
        outliers=args.outliers,
        outlier_mode=args.outlier_mode,
        command=command,
    )
    return _write(args.out, header, records)


def cmd_import(args: argparse.Namespace) -> int:
    if len(args.paths) > 2:
        raise FgslamError(f"import takes [SOURCE] OUT, got {len(args.paths)} paths: {' '.join(args.paths)}")
    source = args.paths[0] if len(args.paths) == 2 else args.source
    out = args.paths[-1]
    needs_source = ("mrclam", "rosbag")
    if args.dataset in needs_source and source is None:
        raise FgslamError(f"import {args.dataset} needs SOURCE: fgslam import {args.dataset} SOURCE OUT")
    if args.dataset == "victoria-park":
        from slamio.datasets import import_victoria_park

        header, records = import_victoria_park(source)
    elif args.dataset == "mrclam":
        from slamio.datasets.mrclam import import_mrclam

        model = None
        if args.noise is not None:
            from slamio.noise_model import load_noise_model

            model = load_noise_model(args.noise)
        header, records = import_mrclam(source, args.robot, model=model)
    elif args.dataset == "rosbag":
        from slamio.datasets.rosbag import import_rosbag

        header, records = import_rosbag(
            source, odom_topic=args.odom_topic, detections_topic=args.detections_topic,
            tag_pose_topic=args.tag_pose_topic, truth_topic=args.truth_topic,
        )
    else:  # plaza1, plaza2
        from slamio.datasets.plaza import import_plaza

        header, records = import_plaza(
            args.dataset, source, range_sigma_m=args.range_sigma, range_bias_m=args.range_bias
        )
    return _write(out, header, records)


def cmd_export(args: argparse.Namespace) -> int:
    from slamio.datasets.rosbag import export_rosbag

    log = _read(args.log)
    counts = export_rosbag(log, args.out)
    topics = ", ".join(f"{topic} {n}" for topic, n in counts.items() if topic.startswith("/"))
    print(f"wrote {args.out}: ROS 2 bag ({topics})")
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    from fgslam.check import check_estimator

    result = check_estimator(
        args.log,
        estimator=args.estimator,
        against=args.against,
        max_ate_m=args.max_ate,
        max_nees_outside=args.max_nees_outside,
        tolerances_file=args.tolerances,
    )
    print(result.verdict)
    return 0 if result.passed else 1


def cmd_bench(args: argparse.Namespace) -> int:
    from fgslam.montecarlo import dask_executor, monte_carlo

    estimators = tuple(n.strip() for n in args.estimators.split(",") if n.strip())
    with dask_executor(args.dask) if args.dask else contextlib.nullcontext() as executor:
        result = monte_carlo(
            args.scenario, args.runs, estimators=estimators, first_seed=args.seed, jobs=args.jobs,
            landmarks=args.landmarks, laps=args.laps, executor=executor, progress=ProgressBar(),
        )
    low, high = result.band
    steps = len(next(iter(result.average_nees.values())))
    scored = steps if result.scored_steps is None else int(np.count_nonzero(result.scored_steps))
    judged = "" if scored == steps else f" ({scored} with truth in every run are judged)"
    print(f"Monte Carlo: {args.scenario}, {args.runs} runs (seeds {args.seed}-{args.seed + args.runs - 1}), "
          f"{steps} steps{judged}; 95 % band of the average NEES over {args.runs} runs: [{low:.3f}, {high:.3f}]")
    header = f"{'estimator':<14}{'inside band':>12}{'above band':>12}{'mean NEES':>11}" \
             f"{'ATE final m (median, max)':>28}{'time s (mean)':>15}"
    print(header)
    summary = {"scenario": args.scenario, "runs": args.runs, "first_seed": args.seed, "steps": steps,
               "band": [low, high], "estimators": {}}
    for name in estimators:
        finals = np.array([r.ate_final_m[name] for r in result.runs])
        times = np.array([r.time_s[name] for r in result.runs])
        print(f"{name:<14}{100 * result.share_inside(name):11.1f}%{100 * result.share_above(name):11.1f}%"
              f"{result.mean_nees(name):11.2f}"
              f"{np.median(finals):14.4f}, {np.max(finals):.4f}{'':>4}{np.mean(times):13.3f}")
        summary["estimators"][name] = {
            "share_inside_band": result.share_inside(name),
            "share_above_band": result.share_above(name),
            "average_nees": [float(v) if np.isfinite(v) else None for v in result.average_nees[name]],
            "ate_final_m": [float(v) for v in finals],
            "ate_online_m": [float(r.ate_online_m[name]) for r in result.runs],
            "time_s": [float(v) for v in times],
        }
    if args.out is not None:
        from fgslam.report import write_monte_carlo_figures

        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "montecarlo.json").write_text(json.dumps(summary, indent=1) + "\n")
        written = ["montecarlo.json"] + write_monte_carlo_figures(out, result)
        print(f"\nwrote {', '.join(written)} to {out}/")
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    log = _read(args.log)
    odometry = sum(isinstance(r, Odometry) for r in log.records)
    print(f"{args.log}: valid fgslam run log v{log.header.version}: {_summary(log)}; {odometry} odometry records")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    from fgslam.compare import compute_metrics, format_table, write_tum
    from fgslam.export import write_g2o
    from fgslam.runner import compare_log, parse_estimator_names

    names = parse_estimator_names(args.estimators)
    log = _read(args.log)
    print(f"{args.log}: {_summary(log)}")
    result = compare_log(log, names, progress=ProgressBar(), consistency=not args.no_consistency)
    metrics = compute_metrics(result.runs, result.reference, log_path=str(args.log))
    if log.truncated:
        metrics["log_truncated"] = log.truncated

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    has_pose = result.reference.has_pose  # TUM files are stamped: leave the poses without truth out
    write_tum(out / "reference.tum", result.stamps_s[has_pose], result.reference.trajectory[has_pose])
    for run in result.runs:
        write_tum(out / f"{run.name}.tum", result.stamps_s, run.final)
        if run.online is not None:
            write_tum(out / f"{run.name}_online.tum", result.stamps_s, run.online)
    smoother = result.smoother  # its graph, vertices at iSAM2's final estimate
    write_g2o(out / "graph.g2o", smoother.graph(), smoother.estimate(), smoother.num_poses)
    written = ["metrics.json", "*.tum", "graph.g2o"]
    if not args.no_report:
        from fgslam.report import write_report

        html = write_report(
            out, metrics, result.runs, result.reference, result.stamps_s, title=f"fgslam run {Path(args.log).name}"
        )
        written.insert(1, html.name)
    print()
    print(format_table(metrics))
    print(f"\nwrote {', '.join(written)} to {out}/")
    if log.truncated:
        print(f"note: {log.truncated}")
    return 0


# --------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    from slamio.sim import SCENARIOS

    parser = argparse.ArgumentParser(
        prog="fgslam", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"fgslam {_version()}")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)

    sim = verbs.add_parser(
        "sim",
        help="simulate a run and write its log (with ground truth)",
        description=(
            "Simulate a differential-drive robot with noisy wheel odometry and a range-bearing "
            "landmark sensor, and write the run log with ground truth. The same seed gives the "
            "same log, byte for byte.\n\nscenarios:\n"
            "  arena-square   seed 004's 10 ft x 10 ft arena, 8 AprilTags, square path\n"
            "  arena-octagon  the same arena, octagon path\n"
            "  cylinders      seed 000's three coloured cylinders seen by a Kinect\n"
            "  grid           N landmarks on a grid (--landmarks N), a long loop with revisits"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sim.add_argument("scenario", choices=SCENARIOS, metavar="SCENARIO", help="one of: " + ", ".join(SCENARIOS))
    sim.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    sim.add_argument("--out", required=True, metavar="LOG", help="run log to write (.jsonl)")
    sim.add_argument("--landmarks", type=int, default=200, metavar="N", help="grid only: number of landmarks (default 200)")
    sim.add_argument("--laps", type=int, default=None, metavar="N", help="laps of the path (default: the scenario's)")
    sim.add_argument(
        "--hide-ids",
        action="store_true",
        help="write observations without landmark ids (estimators must associate them); "
        "the true id is kept in truth_landmark_id to score the association",
    )
    sim.add_argument(
        "--outliers",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help="share of observations replaced by misdetections: the right id at a random range "
        "and bearing inside the sensor's limits (default 0)",
    )
    sim.add_argument(
        "--outlier-mode",
        choices=("replace", "add"),
        default="replace",
        help="replace: misdetections take the place of observations (default); add: every "
        "observation is kept and the misdetections come on top (still FRACTION of all)",
    )
    sim.set_defaults(func=cmd_sim)

    run = verbs.add_parser(
        "run",
        help="run the estimators on a log and write the comparison",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="estimators:\n" + "\n".join(f"  {name:<15} {text}" for name, text in ESTIMATOR_HELP.items()),
        description=(
            "Run every estimator on the same log and compare them. The reference is the log's\n"
            "ground truth wherever it has some: with gaps in the truth (e.g. Vicon drop-outs)\n"
            "only the poses with truth are scored, and the first line of the table says how\n"
            "many. Without any pose truth it is the batch Levenberg-Marquardt solution started\n"
            "from iSAM2's result (the 'smoothed ground truth'), and the map error is against the\n"
            "log's surveyed landmarks when it has them. Writes\n"
            "metrics.json, report.html (self-contained), PNG figures, and each estimator's\n"
            "trajectory in TUM format (<name>.tum final, <name>_online.tum online) to --out,\n"
            "and prints a table of the figures."
        ),
    )
    run.add_argument("log", metavar="LOG", help="run log (.jsonl)")
    run.add_argument("--out", required=True, metavar="DIR", help="folder for the results (created)")
    run.add_argument(
        "--estimators",
        default="ekf,isam2,dead_reckoning",
        metavar="LIST",
        help="comma-separated estimators to run (default ekf,isam2,dead_reckoning; all "
        "names below); the batch solve always runs from isam2's result",
    )
    run.add_argument("--no-report", action="store_true", help="skip report.html and the PNG figures")
    run.add_argument("--no-consistency", action="store_true",
                     help="skip NEES, NIS and covariance ellipses (their work runs between the timed steps "
                          "but can leave iSAM2 with cached marginals; use this for timings)")
    run.set_defaults(func=cmd_run)

    imp = verbs.add_parser(
        "import",
        help="convert a dataset from elsewhere into a run log",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Convert a public dataset into a run log, so every estimator can run on it.\n\n"
            "datasets:\n"
            "  victoria-park  the Victoria Park car run shipped inside the gtsam wheel (6 969 poses,\n"
            "                 151 trees; no ground truth, so `fgslam run` compares against the\n"
            "                 smoothed solution).\n"
            "  plaza1, plaza2 CMU's ranging-radio runs shipped inside the gtsam wheel: range-only\n"
            "                 beacons, GPS ground truth (`fgslam run` reports ATE against it).\n"
            "  mrclam         one robot of a UTIAS MRCLAM dataset folder (SOURCE; --robot N): Creates\n"
            "                 with cameras reading barcoded landmarks, Vicon ground truth.\n"
            "  rosbag         a ROS 1 .bag or ROS 2 bag folder (SOURCE) through the rosbags package:\n"
            "                 --odom-topic, --detections-topic or --tag-pose-topic, --truth-topic;\n"
            "                 a bag from `fgslam export rosbag` needs no topics.\n"
            "See docs/datasets.md for what is converted and how.\n\n"
            "usage: fgslam import DATASET [SOURCE] OUT   (SOURCE defaults to the gtsam wheel's copy)"
        ),
    )
    imp.add_argument("dataset", choices=["victoria-park", "plaza1", "plaza2", "mrclam", "rosbag"],
                     metavar="DATASET", help="victoria-park, plaza1, plaza2, mrclam or rosbag")
    imp.add_argument("paths", nargs="+", metavar="[SOURCE] OUT",
                     help="the dataset file or folder (optional), then the run log to write (.jsonl)")
    imp.add_argument(
        "--source",
        default=None,
        metavar="PATH",
        help="the dataset file (Victoria Park) or folder (Plaza); default: the installed gtsam wheel's copy",
    )
    imp.add_argument("--range-sigma", type=float, default=1.5, metavar="M",
                     help="Plaza: standard deviation given to every range (default 1.5 m)")
    imp.add_argument("--range-bias", type=float, default=0.0, metavar="M",
                     help="Plaza: subtract this from every range (default 0; GPS says the radios read ~2.8 m long)")
    imp.add_argument("--robot", type=int, default=1, metavar="N", help="MRCLAM: which robot, 1-5 (default 1)")
    imp.add_argument("--noise", default=None, metavar="FILE",
                     help="MRCLAM: a noise model from `fgslam calibrate LOG... --out FILE` (odometry lag and "
                          "scale, range/bearing correction and sigmas); default: round, unfitted values")
    imp.add_argument("--odom-topic", default=None, help="rosbag: nav_msgs/Odometry topic")
    imp.add_argument("--detections-topic", default=None,
                     help="rosbag: apriltag_ros/AprilTagDetectionArray topic")
    imp.add_argument("--tag-pose-topic", default=None,
                     help="rosbag: prefix of one geometry_msgs/PoseStamped topic per tag, e.g. /tags/tag_")
    imp.add_argument("--truth-topic", default=None, help="rosbag: ground-truth pose topic (optional)")
    imp.set_defaults(func=cmd_import)

    export = verbs.add_parser(
        "export",
        help="write a run log in another format (a ROS 2 bag)",
        description="Write a run log as a ROS 2 bag (sqlite3): odometry as nav_msgs/Odometry, ground truth as "
                    "geometry_msgs/PoseStamped, detections as apriltag_ros arrays, plus the exact log on "
                    "/fgslam/run_log so `fgslam import rosbag BAG OUT` gives it back unchanged. See "
                    "docs/datasets-mrclam-rosbag.md.",
    )
    export.add_argument("format", choices=["rosbag"], metavar="FORMAT", help="rosbag")
    export.add_argument("log", metavar="LOG", help="run log to export")
    export.add_argument("out", metavar="OUT", help="bag folder to create (must not exist)")
    export.set_defaults(func=cmd_export)

    validate = verbs.add_parser(
        "validate",
        help="check a run log line by line and summarise it",
        description="Read a run log, validate every line, and print a one-line summary. "
        "Exits 1 with file:line and how to fix it at the first bad line.",
    )
    validate.add_argument("log", metavar="LOG", help="run log (.jsonl)")
    validate.set_defaults(func=cmd_validate)

    check = verbs.add_parser(
        "check",
        help="regression check: one estimator against the smoothed solution or the truth (exit 0/1)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Run one estimator on LOG and compare it with the smoothed solution (batch LM from\n"
            "iSAM2) or with the log's ground truth. Prints one line, PASS or FAIL, and exits 0 or 1.\n"
            "Against the truth only the poses with truth are scored; a log with truth for fewer than\n"
            "half of its poses (or fewer than 10) is refused: check it against the smoothed solution.\n"
            "Fails when the ATE exceeds --max-ate, or when the share of steps whose NEES is outside\n"
            "the 95 % chi-square band (above it, against the smoothed solution) exceeds\n"
            "--max-nees-outside. Tolerances not given here come from LOG.check.toml (or --tolerances),\n"
            "else the defaults 0.5 m and 0.1."
        ),
        epilog=(
            "tolerance file (TOML):\n"
            "  [defaults]\n  max_ate_m = 0.5\n  max_nees_outside = 0.1\n\n"
            "  [ekf-nn]              # per estimator, overrides [defaults]\n  max_ate_m = 0.8"
        ),
    )
    check.add_argument("log", metavar="LOG", help="run log (.jsonl)")
    check.add_argument("--estimator", default="ekf", choices=list(ESTIMATOR_HELP), help="estimator to check (default ekf)")
    check.add_argument("--against", default="smoothed", choices=["smoothed", "truth"],
                       help="reference: the smoothed solution (default) or the log's ground truth "
                            "(the poses that have it; at least half of them and at least 10)")
    check.add_argument("--max-ate", type=float, default=None, metavar="M", help="largest ATE allowed, metres")
    check.add_argument("--max-nees-outside", type=float, default=None, metavar="F",
                       help="largest share of steps with the NEES outside the 95 %% band (0..1)")
    check.add_argument("--tolerances", default=None, metavar="FILE",
                       help="TOML file with tolerances (default: LOG.check.toml when it exists)")
    check.set_defaults(func=cmd_check)

    bench = verbs.add_parser(
        "bench",
        help="Monte Carlo: many seeded simulations, average NEES per step against its chi-square band",
        description=(
            "Simulate SCENARIO with seeds SEED..SEED+RUNS-1, run the estimators on each (in a process\n"
            "pool, or on a Dask cluster), and report for each estimator the share of steps at which\n"
            "the NEES averaged over the runs lies inside its 95 % chi-square band (N = 50: [2.36, 3.72]),\n"
            "the ATE over the runs and the time. Simulations have ground truth at every pose."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    bench.add_argument("scenario", choices=SCENARIOS, metavar="SCENARIO", help=", ".join(SCENARIOS))
    bench.add_argument("--runs", type=int, default=50, help="number of runs (default 50)")
    bench.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    bench.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    bench.add_argument("--estimators", default="ekf,isam2", help="comma-separated (default ekf,isam2)")
    bench.add_argument("--landmarks", type=int, default=200, help="landmarks of the grid scenario")
    bench.add_argument("--laps", type=int, default=None, help="laps (default: the scenario's)")
    bench.add_argument("--out", default=None, metavar="DIR", help="write montecarlo.json, nees.png, ate.png here")
    bench.add_argument("--dask", default=None, metavar="ADDRESS",
                       help="run on the Dask cluster at ADDRESS (needs the optional dask extra)")
    bench.set_defaults(func=cmd_bench)

    from fgslam.detect_cli import add_detect_parser
    from fgslam.record_cli import add_calibrate_parser, add_record_parser

    from fgslam.live_cli import add_live_parser

    add_detect_parser(verbs)
    add_record_parser(verbs)
    add_calibrate_parser(verbs)
    add_live_parser(verbs)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fgslam")
    except PackageNotFoundError:
        return "unknown"


def _explain(error: FgslamError) -> str:
    message = str(error)
    if isinstance(error, LogFormatError) and error.partial is not None and error.line > 2:
        message += (
            f"\n  (the {error.line - 1} lines before it are valid; fix or delete line {error.line}, "
            f"or keep only the good part: head -n {error.line - 1} {error.path} > good.jsonl)"
        )
    return message


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # `import DATASET SOURCE --robot 2 OUT`: positionals after an option
        if getattr(args, "func", None) is cmd_import and not any(e.startswith("-") for e in extra):
            args.paths.extend(extra)
        else:
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
    args.argv = argv
    try:
        return args.func(args)
    except FgslamError as error:
        print(f"fgslam: error: {_explain(error)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("fgslam: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
