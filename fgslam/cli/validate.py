"""``fgslam validate``: check a run log line by line and summarise it."""

from __future__ import annotations

import argparse
import sys

from fgslam.cli.verbs import help_of


def add_parser(verbs) -> argparse.ArgumentParser:
    validate = verbs.add_parser(
        "validate",
        help=help_of("validate"),
        description="Read a run log, validate every line, and print a one-line summary. "
        "Exits 1 with file:line and how to fix it at the first bad line.",
    )
    validate.add_argument("log", metavar="LOG", help="run log (.jsonl)")
    validate.set_defaults(func=cmd_validate)
    return validate


#: How many rejected observations are shown one per line.
SHOWN = 5


def cmd_validate(args: argparse.Namespace) -> int:
    """Stream the log (memory does not grow with it), counting what the summary says."""
    from fgslam.cli.common import PROG, LogTally
    from slamio.log import Rejected, iter_log
    from slamio.log.records import rejection_line

    stream = iter_log(args.log)
    tally = LogTally(stream.header)
    add = tally.add
    by_reason: dict[str, tuple[int, int, int]] = {}
    shown: list[Rejected] = []
    for item in stream:
        if type(item) is Rejected:
            count, first, _ = by_reason.get(item.reason, (0, item.line, item.line))
            by_reason[item.reason] = (count + 1, first, item.line)
            if len(shown) < SHOWN:
                shown.append(item)
        else:
            add(item)
    rejected = rejection_line(stream.path, by_reason)
    if stream.truncated:
        print(f"{PROG}: warning: {stream.truncated}", file=sys.stderr)
    if rejected:
        print(f"{PROG}: warning: {rejected}", file=sys.stderr)
    header = stream.header
    kind = "3-D stereo + IMU " if header.is_3d else ""
    what = "velocity odometry" if header.is_3d else "odometry"
    print(f"{args.log}: valid fgslam {kind}run log v{header.version}: {tally.text()}; {tally.odometry} {what} records")
    if rejected:  # usable, but say what the estimators will not see, and where
        print(f"note: {rejected}")
        for r in shown:
            print(f"  {r.message}")
        n = sum(count for count, _, _ in by_reason.values())
        if n > SHOWN:
            print(f"  ... and {n - SHOWN} more")
    return 0
