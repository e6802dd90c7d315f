"""``fgslam import rosbag``'s options for a rig's own bag: tag corners with a camera file and
tag sizes, where the camera sits, levelling, and the truth from a second bag — and the
warnings the import prints (every assumption, with its numbers)."""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from slamio.errors import FgslamError

#: (option, args attribute) of the options only rosbag reads; their parser default is None.
ROSBAG_OPTIONS = (
    ("--camera", "camera"), ("--camera-name", "camera_name"), ("--camera-info-topic", "camera_info_topic"),
    ("--camera-pose", "camera_pose"), ("--camera-poses", "camera_poses"), ("--tags", "tags"),
    ("--tag-size", "tag_size"), ("--pixel-sigma-px", "pixel_sigma_px"), ("--max-reprojection-px", "max_reprojection_px"),
    ("--level", "level"), ("--truth-bag", "truth_bag"), ("--truth-pose-of", "truth_pose_of"),
    ("--truth-frames", "truth_frames"),
)


def add_rosbag_options(imp: argparse.ArgumentParser) -> None:
    imp.add_argument("--camera", default=None, metavar="FILE",
                     help="rosbag: the camera of tag-corner detections: a Kalibr cameras.yaml or a ROS camera_info YAML")
    imp.add_argument("--camera-name", default=None, metavar="NAME",
                     help="rosbag: which camera of a Kalibr file (and of --camera-poses), e.g. cam0")
    imp.add_argument("--camera-info-topic", default=None, metavar="TOPIC",
                     help="rosbag: read the camera from this sensor_msgs/CameraInfo topic instead of --camera")
    imp.add_argument("--camera-pose", default=None, metavar="X,Y,Z,QX,QY,QZ,QW",
                     help="rosbag: the camera's optical frame in the odometry's body frame (metres, unit quaternion); "
                          "default: /tf_static from the odometry's child frame to the detections' frame, else the "
                          "optical frame at the body's origin looking forward (with a warning)")
    imp.add_argument("--camera-poses", default=None, metavar="FILE",
                     help="rosbag: TagSLAM's camera_poses.yaml (the camera on the rig; with --tags, the rig's "
                          "T_body_odom places it in the odometry's body frame)")
    imp.add_argument("--tags", default=None, metavar="FILE",
                     help="rosbag: tag sizes by id: TagSLAM's tagslam.yaml, or default_tag_size and tags: [{id, size}]")
    imp.add_argument("--tag-size", type=float, default=None, metavar="M",
                     help="rosbag: the side of every tag --tags does not list (metres, the black square)")
    imp.add_argument("--pixel-sigma-px", type=float, default=None, metavar="PX",
                     help="rosbag: σ of each tag corner coordinate (default: the tags file's pixel_noise, else 1)")
    imp.add_argument("--max-reprojection-px", type=float, default=None, metavar="PX",
                     help="rosbag: drop a tag whose pose reprojects its corners worse than this (default 3 px)")
    imp.add_argument("--level", default=None, choices=("auto", "first-pose", "none"),
                     help="rosbag: level the odometry frame with the first pose's z axis: auto (when it is tilted "
                          "more than 30 deg; default), first-pose (always) or none")
    imp.add_argument("--truth-bag", default=None, metavar="BAG",
                     help="rosbag: read --truth-topic from this bag (e.g. TagSLAM's reference.bag); its /tf tag "
                          "frames tag_<id> become the truth map")
    imp.add_argument("--truth-frames", default=None, metavar="PARENT:CHILD",
                     help="rosbag: the truth is the chain of /tf transforms from PARENT to CHILD (e.g. map:rig), in "
                          "--truth-bag or else in this bag, instead of a --truth-topic")
    imp.add_argument("--truth-pose-of", default=None, choices=("body", "camera"),
                     help="rosbag: the truth poses are the odometry body's (default) or the camera's (TagSLAM's "
                          "body_rig of a rig whose body is the camera)")


def parse_camera_pose(text: str) -> np.ndarray:
    """``x,y,z,qx,qy,qz,qw`` → 4×4; one error line naming the option and the rule."""
    from slamio.se3 import rotation_from_quaternion

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 7 or not all(math.isfinite(v) for v in values):
        raise FgslamError(f"--camera-pose {text!r}: give seven numbers x,y,z,qx,qy,qz,qw (metres and a quaternion)")
    q = np.array(values[3:])
    if abs(np.linalg.norm(q) - 1.0) > 1e-3:
        raise FgslamError(f"--camera-pose {text!r}: the quaternion (qx,qy,qz,qw) has norm {np.linalg.norm(q):.4f}, "
                          "not 1")
    T = np.eye(4)
    T[:3, :3] = rotation_from_quaternion(*(q / np.linalg.norm(q)))
    T[:3, 3] = values[:3]
    return T


def parse_truth_frames(text: str) -> tuple[str, str]:
    """``map:rig`` → ("map", "rig"); one error line naming the option."""
    parent, sep, child = text.partition(":")
    if not sep or not parent.strip("/") or not child.strip("/") or ":" in child or parent == child:
        raise FgslamError(f"--truth-frames {text!r}: give two different /tf frame names as PARENT:CHILD, e.g. map:rig "
                          "(the truth is CHILD's pose in PARENT)")
    return parent, child


def _mount(args: argparse.Namespace, tags) -> np.ndarray | None:
    if args.camera_pose is not None and args.camera_poses is not None:
        raise FgslamError("--camera-pose and --camera-poses both place the camera; give one of them")
    if args.camera_pose is not None:
        return parse_camera_pose(args.camera_pose)
    if args.camera_poses is None:
        return None
    from slamio.datasets.tagslam_files import load_camera_poses

    T_rig_cam = load_camera_poses(args.camera_poses, args.camera_name)
    T_rig_odom = tags.T_body_odom if tags is not None and tags.T_body_odom is not None else np.eye(4)
    return np.linalg.inv(T_rig_odom) @ T_rig_cam


def import_rosbag_cli(args: argparse.Namespace, source: str, standard_topics_only: bool):
    """Run :func:`slamio.datasets.rosbag.import_rosbag` with the command line's options and
    print its warnings to stderr."""
    from fgslam.cli.common import check_number
    from slamio.datasets.rosbag import import_rosbag

    for option, value, what in (("--tag-size", args.tag_size, "metres, a tag's side"),
                                ("--pixel-sigma-px", args.pixel_sigma_px, "pixels, the corner noise"),
                                ("--max-reprojection-px", args.max_reprojection_px, "pixels")):
        if value is not None:
            check_number(option, value, above=0, what=what)
    camera = None
    if args.camera is not None:
        if args.camera_info_topic is not None:
            raise FgslamError("--camera and --camera-info-topic both give the camera; give one of them")
        from slamio.camera.camera_files import load_camera_file

        camera = load_camera_file(args.camera, args.camera_name)
    truth_frames = parse_truth_frames(args.truth_frames) if args.truth_frames is not None else None
    tags = None
    if args.tags is not None:
        from slamio.datasets.tagslam_files import load_tags_file

        tags = load_tags_file(args.tags)
    header, records = import_rosbag(
        source, odom_topic=args.odom_topic, detections_topic=args.detections_topic,
        tag_pose_topic=args.tag_pose_topic, truth_topic=args.truth_topic,
        standard_topics_only=standard_topics_only, camera=camera, camera_info_topic=args.camera_info_topic,
        tag_sizes=tags, tag_size_m=args.tag_size, pixel_sigma_px=args.pixel_sigma_px,
        T_robot_camera=_mount(args, tags), level=args.level or "auto",
        truth_bag=args.truth_bag, truth_pose_of=args.truth_pose_of or "body", truth_frames=truth_frames,
        start_from="truth" if args.truth_bag is not None or truth_frames is not None else "odom",
        **({"max_reprojection_px": args.max_reprojection_px} if args.max_reprojection_px is not None else {}),
    )
    for warning in header.source.get("warnings", []):
        print(f"fgslam: warning: {warning}", file=sys.stderr)
    return header, records
