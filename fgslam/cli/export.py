"""``fgslam export``: write a run log in another format (a ROS 2 bag)."""

from __future__ import annotations

import argparse
import os
import shutil
import sqlite3
from pathlib import Path

from fgslam.atomic import temp_path
from fgslam.cli.common import explain, hold_outputs, probe_writable, read
from fgslam.cli.verbs import help_of
from slamio.errors import FgslamError


def add_parser(verbs) -> argparse.ArgumentParser:
    export = verbs.add_parser(
        "export",
        help=help_of("export"),
        description="Write a run log as a ROS 2 bag (sqlite3): odometry as nav_msgs/Odometry, ground truth as "
                    "geometry_msgs/PoseStamped (truth with a heading; GPS positions are on /fgslam/run_log only), detections as apriltag_ros arrays, plus the exact log on "
                    "/fgslam/run_log so `fgslam import rosbag BAG OUT` gives it back unchanged. See "
                    "docs/datasets-mrclam-rosbag.md.",
    )
    export.add_argument("format", choices=["rosbag"], metavar="FORMAT", help="rosbag")
    export.add_argument("log", metavar="LOG", help="run log to export")
    export.add_argument("out", metavar="OUT", help="bag folder to create (must not exist; it appears only when "
                                                   "complete: a failed export, e.g. on a full disk, leaves nothing)")
    export.set_defaults(func=cmd_export)
    return export


def cmd_export(args: argparse.Namespace) -> int:
    out = Path(args.out)
    with hold_outputs((out, "OUT")):  # one writer per output, from the checks to the last byte
        return _export(args, out)


def _export(args: argparse.Namespace, out: Path) -> int:
    if out.exists() or out.is_symlink():  # before reading the log; a bag is never overwritten
        raise FgslamError(f"OUT {out} exists; a bag is never overwritten: give another name or remove it")
    probe_writable(out.parent, option="OUT", target=out)
    log = read(args.log)
    counts = write_bag_whole(log, out)
    topics = ", ".join(f"{topic} {n}" for topic, n in counts.items() if topic.startswith("/"))
    print(f"wrote {args.out}: ROS 2 bag ({topics})")
    only_in_log = {"observations_not_on_detections": "observations without bearing or id",
                   "truth_poses_without_heading": "truth poses without heading (GPS)"}
    kept = [f"{counts[key]} {what}" for key, what in only_in_log.items() if counts.get(key)]
    if kept:
        print(f"only on /fgslam/run_log (no ROS message holds them): {', '.join(kept)}")
    return 0


def write_bag_whole(log, out: Path) -> dict[str, int]:
    """Export ``log`` as a bag into a hidden folder beside ``out`` and rename it to ``out``
    when it is complete: an export that fails (a full disk, a quota, a file-size limit)
    leaves nothing behind, so the same command can simply be run again."""
    from slamio.datasets.rosbag import export_rosbag

    work = temp_path(out)  # a fresh folder of our own: removed whole at the end
    bag = work / out.name  # the bag inside it has its final name (its files are named after it)
    try:
        work.mkdir()
        counts = export_rosbag(log, bag)
        if out.exists() or out.is_symlink():
            raise FgslamError(f"OUT {out} appeared while the bag was being written; nothing was replaced, "
                              "give another name")
        os.rename(bag, out)
        return counts
    except FgslamError as error:
        raise FgslamError(str(error).replace(str(bag), str(out))) from None
    except (OSError, sqlite3.Error) as error:
        raise FgslamError(f"OUT {out}: writing the bag failed ({_why(error, bag, out)}); nothing was left at {out}: "
                          "free some space (a full disk, a quota or a file-size limit?) and run the same command "
                          "again") from None
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _why(error: BaseException, bag: Path, out: Path) -> str:
    if isinstance(error, sqlite3.Error):
        name = getattr(error, "sqlite_errorname", None)
        return f"sqlite: {error}" + (f", {name}" if name else "")
    return explain(error).replace(str(bag), str(out))
