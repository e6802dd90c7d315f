"""``fgslam validate``: check a run log line by line and summarise it."""

from __future__ import annotations

import argparse

from fgslam.cli.common import read, summary


def add_parser(verbs) -> argparse.ArgumentParser:
    validate = verbs.add_parser(
        "validate",
        help="check a run log line by line and summarise it",
        description="Read a run log, validate every line, and print a one-line summary. "
        "Exits 1 with file:line and how to fix it at the first bad line.",
    )
    validate.add_argument("log", metavar="LOG", help="run log (.jsonl)")
    validate.set_defaults(func=cmd_validate)
    return validate


def cmd_validate(args: argparse.Namespace) -> int:
    from slamio.log import Odometry
    from slamio.log import VelocityOdometry

    log = read(args.log)
    odometry = sum(isinstance(r, (Odometry, VelocityOdometry)) for r in log.records)
    kind = "3-D stereo + IMU " if log.header.is_3d else ""
    what = "velocity odometry" if log.header.is_3d else "odometry"
    print(f"{args.log}: valid fgslam {kind}run log v{log.header.version}: {summary(log)}; {odometry} {what} records")
    rejected = log.rejection_summary()
    if rejected:  # usable, but say what the estimators will not see, and where
        print(f"note: {rejected}")
        shown = 5
        for r in log.rejected[:shown]:
            print(f"  {r.message}")
        if len(log.rejected) > shown:
            print(f"  ... and {len(log.rejected) - shown} more")
    return 0
