"""``fgslam sim``: simulate a run and write its log (with ground truth)."""

from __future__ import annotations

import argparse

from fgslam.cli.common import add_overwrite_option, check_new_file, command_line, write_run_log


def add_parser(verbs) -> argparse.ArgumentParser:
    from slamio.sim import SCENARIOS

    sim = verbs.add_parser(
        "sim",
        help="simulate a run and write its log (with ground truth)",
        description=(
            "Simulate a differential-drive robot with noisy wheel odometry and a range-bearing "
            "landmark sensor, and write the run log with ground truth. The same seed gives the "
            "same log, byte for byte. An existing LOG is kept unless --overwrite.\n\nscenarios:\n"
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
    add_overwrite_option(sim, "an existing LOG")
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
    sim.add_argument(
        "--tag-noise",
        choices=("nominal", "measured"),
        default="nominal",
        help="arena scenarios: nominal = fixed sigmas (slamio/sim.py docstring; default); measured = "
        "range, bearing and yaw noise growing with distance and viewing angle as measured on real "
        "and rendered AprilTag images (docs/camera.md), each observation with its own sigmas",
    )
    sim.set_defaults(func=cmd_sim)
    return sim


def cmd_sim(args: argparse.Namespace) -> int:
    from slamio.sim import simulate

    check_new_file(args.out, overwrite=args.overwrite)  # before the work: nothing computed for nothing
    header, records = simulate(
        args.scenario,
        args.seed,
        landmarks=args.landmarks,
        laps=args.laps,
        hide_ids=args.hide_ids,
        outliers=args.outliers,
        outlier_mode=args.outlier_mode,
        tag_noise=args.tag_noise,
        command=command_line(args),
    )
    return write_run_log(args.out, header, records, overwrite=args.overwrite)
