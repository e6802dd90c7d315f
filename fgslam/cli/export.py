"""``fgslam export``: write a run log in another format (a ROS 2 bag)."""

from __future__ import annotations

import argparse
from pathlib import Path

from fgslam.cli.common import probe_writable, read
from slamio.errors import FgslamError


def add_parser(verbs) -> argparse.ArgumentParser:
    export = verbs.add_parser(
        "export",
        help="write a run log in another format (a ROS 2 bag)",
        description="Write a run log as a ROS 2 bag (sqlite3): odometry as nav_msgs/Odometry, ground truth as "
                    "geometry_msgs/PoseStamped (truth with a heading; GPS positions are on /fgslam/run_log only), detections as apriltag_ros arrays, plus the exact log on "
                    "/fgslam/run_log so `fgslam import rosbag BAG OUT` gives it back unchanged. See "
                    "docs/datasets-mrclam-rosbag.md.",
    )
    export.add_argument("format", choices=["rosbag"], metavar="FORMAT", help="rosbag")
    export.add_argument("log", metavar="LOG", help="run log to export")
    export.add_argument("out", metavar="OUT", help="bag folder to create (must not exist)")
    export.set_defaults(func=cmd_export)
    return export


def cmd_export(args: argparse.Namespace) -> int:
    from slamio.datasets.rosbag import export_rosbag

    out = Path(args.out)
    if out.exists() or out.is_symlink():  # before reading the log; a bag is never overwritten
        raise FgslamError(f"OUT {out} exists; a bag is never overwritten: give another name or remove it")
    probe_writable(out.parent, option="OUT", target=out)
    log = read(args.log)
    counts = export_rosbag(log, args.out)
    topics = ", ".join(f"{topic} {n}" for topic, n in counts.items() if topic.startswith("/"))
    print(f"wrote {args.out}: ROS 2 bag ({topics})")
    only_in_log = {"observations_not_on_detections": "observations without bearing or id",
                   "truth_poses_without_heading": "truth poses without heading (GPS)"}
    kept = [f"{counts[key]} {what}" for key, what in only_in_log.items() if counts.get(key)]
    if kept:
        print(f"only on /fgslam/run_log (no ROS message holds them): {', '.join(kept)}")
    return 0
