"""``fgslam check``: one estimator against the smoothed solution or the truth (exit 0/1)."""

from __future__ import annotations

import argparse

from fgslam.cli.common import add_verb
from fgslam.cli.estimators import ESTIMATOR_HELP, ESTIMATOR_HELP_3D
from fgslam.cli.verbs import help_of


def _tolerance(key: str):
    """An argparse type for the tolerance ``key``: the ranges of the tolerance file
    (:data:`fgslam.check.TOLERANCE_RANGES`), checked when the command line is read."""

    def parse(text: str) -> float:
        from fgslam.check import TOLERANCE_RANGES, tolerance_is_valid  # with the option only: it loads gtsam

        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}; give {TOLERANCE_RANGES[key]}") from None
        if not tolerance_is_valid(key, value):
            raise argparse.ArgumentTypeError(f"must be {TOLERANCE_RANGES[key]}, got {text}")
        return value

    return parse


def add_parser(verbs) -> argparse.ArgumentParser:
    check = add_verb(
        verbs, "check",
        help=help_of("check"),
        description=(
            "Run one estimator on LOG and compare it with the smoothed solution (batch LM from\n"
            "iSAM2) or with the log's ground truth. Prints one line, PASS or FAIL, and exits 0 or 1.\n"
            "Against the truth only the poses with truth are scored; a log with truth for fewer than\n"
            "half of its poses (or fewer than 10) is refused: check it against the smoothed solution.\n"
            "Fails when the ATE exceeds --max-ate, or when the share of steps whose NEES is outside\n"
            "the 95 % chi-square band (above it, against the smoothed solution) exceeds\n"
            "--max-nees-outside. Tolerances not given here come from LOG.check.toml (or --tolerances),\n"
            "else the defaults 0.5 m and 0.1.\n\n"
            "A 3-D log (seed 003: stereo camera + IMU) is checked with its own estimators (default\n"
            "ekf-vio-fej): ATE in 3-D, pose NEES on SE(3) against the chi-square band with 6 degrees of\n"
            "freedom, the smoothed solution from the stereo factor graph (isam2-3d, then batch LM)."
        ),
        epilog=(
            "tolerance file (TOML):\n"
            "  [defaults]\n  max_ate_m = 0.5\n  max_nees_outside = 0.1\n\n"
            "  [ekf-nn]              # per estimator, overrides [defaults]\n  max_ate_m = 0.8"
        ),
    )
    check.add_argument("log", metavar="LOG", help="run log (.jsonl)")
    check.add_argument("--estimator", default=None, choices=[*ESTIMATOR_HELP, *ESTIMATOR_HELP_3D],
                       help="estimator to check (default ekf; ekf-vio-fej on a 3-D log)")
    check.add_argument("--against", default="smoothed", choices=["smoothed", "truth"],
                       help="reference: the smoothed solution (default) or the log's ground truth "
                            "(the poses that have it; at least half of them and at least 10)")
    check.add_argument("--max-ate", type=_tolerance("max_ate_m"), default=None, metavar="M",
                       help="largest ATE allowed, metres (>= 0)")
    check.add_argument("--max-nees-outside", type=_tolerance("max_nees_outside"),
                       default=None, metavar="F",
                       help="largest share of steps with the NEES outside the 95 %% band (0..1)")
    check.add_argument("--tolerances", default=None, metavar="FILE",
                       help="TOML file with tolerances (default: LOG.check.toml when it exists)")
    check.set_defaults(func=cmd_check)
    return check


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
    if result.noise_verdict:  # does the log's noise fit its measurements (the smoothed reference's verdict)
        from fgslam.verdict import verdict_lines

        print("\n".join(verdict_lines(result.noise_verdict, None)))
    return 0 if result.passed else 1
