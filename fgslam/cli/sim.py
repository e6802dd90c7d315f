"""``fgslam sim``: simulate a run and write its log (with ground truth)."""

from __future__ import annotations

import argparse

from fgslam.cli.common import add_overwrite_option, add_verb, check_new_file, command_line, holds_outputs, write_run_log
from fgslam.cli.verbs import help_of
from slamio.errors import FgslamError


#: slamio.sim's SCENARIOS, then slamio.sim3d's STEREO_LOOP (the 3-D scenario: a stereo + IMU car,
#: written as a 3-D log). Names only, kept equal by a test: the parser of every verb is built
#: at each start, and importing the simulators for their names costs ~40 ms of it.
SCENARIOS = ("arena-square", "arena-octagon", "cylinders", "grid", "clutter")
STEREO_LOOP = "stereo-loop"


def add_parser(verbs) -> argparse.ArgumentParser:
    sim = add_verb(
        verbs, "sim",
        help=help_of("sim"),
        description=(
            "Simulate a differential-drive robot with noisy wheel odometry and a range-bearing "
            "landmark sensor, and write the run log with ground truth. The same seed gives the "
            "same log, byte for byte. An existing LOG is kept unless --overwrite.\n\nscenarios:\n"
            "  arena-square   seed 004's 10 ft x 10 ft arena, 8 AprilTags, square path\n"
            "  arena-octagon  the same arena, octagon path\n"
            "  cylinders      seed 000's three coloured cylinders seen by a Kinect\n"
            "  grid           N landmarks on a grid (--landmarks N), a long loop with revisits\n"
            "  clutter        a 6 m room with boxes and cylinders (slamio.clutter, world seed 0):\n"
            "                 AprilTags on walls and boxes, hidden when an obstacle is in the way\n"
            "  stereo-loop    seed 003's car: a 435 m city loop seen by a stereo camera, with IMU\n"
            "                 velocities; writes a 3-D log (--outliers moves that share of the\n"
            "                 stereo measurements by up to 30 px)"
        ),
    )
    scenarios = (*SCENARIOS, STEREO_LOOP)
    sim.add_argument("scenario", choices=scenarios, metavar="SCENARIO", help="one of: " + ", ".join(scenarios))
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


def _check_options(args: argparse.Namespace) -> None:
    """Every number option, in the words of the command line (the simulator's own checks name
    its Python arguments), before anything is simulated or written."""
    from slamio.sim import MAX_GRID_LANDMARKS

    if args.seed < 0:
        raise FgslamError(f"--seed must be a whole number >= 0; got {args.seed}")
    if args.laps is not None and args.laps < 1:
        raise FgslamError(f"--laps must be a whole number >= 1; got {args.laps} "
                          "(leave --laps out for the scenario's own number of laps)")
    if not 1 <= args.landmarks <= MAX_GRID_LANDMARKS:
        raise FgslamError(f"--landmarks must be from 1 to {MAX_GRID_LANDMARKS} (landmarks of the grid scenario); "
                          f"got {args.landmarks}")
    # planar scenarios keep some true observations (< 1); the stereo loop takes 0..1 (slamio.sim3d)
    rule = "from 0 to 1" if args.scenario == STEREO_LOOP else ">= 0 and < 1"
    if not (0.0 <= args.outliers < 1.0 or (args.scenario == STEREO_LOOP and args.outliers == 1.0)):
        raise FgslamError(f"--outliers must be a fraction {rule} (the share of observations that are "
                          f"misdetections, e.g. 0.05); got {args.outliers}")


@holds_outputs(out="--out")
def cmd_sim(args: argparse.Namespace) -> int:
    from slamio.sim import simulate

    _check_options(args)
    check_new_file(args.out, overwrite=args.overwrite)  # before the work: nothing computed for nothing
    if args.scenario == STEREO_LOOP:
        return _sim_stereo_loop(args)
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


def _sim_stereo_loop(args: argparse.Namespace) -> int:
    """Seed 003's simulated drive (slamio.sim3d) as a 3-D run log, with truth."""
    from slamio.datasets.seed003_log import drive_to_log
    from slamio.sim3d import DriveScenario, simulate_drive

    planar_only = [flag for flag, used in (("--hide-ids", args.hide_ids), ("--laps", args.laps is not None),
                                           ("--outlier-mode add", args.outlier_mode != "replace")) if used]
    if planar_only:
        raise FgslamError(f"{', '.join(planar_only)}: not available for {STEREO_LOOP} (stereo tracks carry their ids)")
    if not 0.0 <= args.outliers <= 1.0:
        raise FgslamError(f"--outliers {args.outliers!r} must be a fraction between 0 and 1")
    drive = simulate_drive(args.seed, DriveScenario(outlier_rate=args.outliers))
    source = {"generator": "slamio.sim3d", "scenario": STEREO_LOOP, "seed": args.seed,
              "outlier_rate": args.outliers, "command": command_line(args)}
    header, records = drive_to_log(drive, source=source)
    return write_run_log(args.out, header, records, overwrite=args.overwrite)
