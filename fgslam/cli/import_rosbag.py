"""``fgslam import rosbag``'s options for a rig's own bag: tag corners with a camera file and
tag sizes, where the camera sits, levelling, and the truth from a second bag — and the
warnings the import prints (every assumption, with its numbers)."""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from slamio.errors import FgslamError

#: (option, args attribute) of the options only rosbag reads; their parser default is None.
ROSBAG_OPTIONS = (
    ("--camera", "camera"), ("--camera-name", "camera_name"), ("--camera-info-topic", "camera_info_topic"),
    ("--camera-pose", "camera_pose"), ("--camera-poses", "camera_poses"), ("--tags", "tags"),
    ("--tag-size", "tag_size"), ("--pixel-sigma-px", "pixel_sigma_px"), ("--max-reprojection-px", "max_reprojection_px"),
    ("--level", "level"), ("--truth-bag", "truth_bag"), ("--truth-pose-of", "truth_pose_of"),
    ("--truth-frames", "truth_frames"), ("--image-topic", "image_topic"), ("--tag-family", "tag_family"),
)


def add_rosbag_options(imp: argparse.ArgumentParser) -> None:
    imp.add_argument("--image-topic", default=None, action="append", metavar="TOPIC",
                     help="rosbag: detect tags in this camera's sensor_msgs/Image (mono8, bgr8, rgb8) or "
                          "CompressedImage (jpeg, png) with fgslam's own detector (depth images are refused); "
                          "repeat it for each camera. Default with --tag-size/--tags and no detections topic: "
                          "the bag's only image topic")
    imp.add_argument("--tag-family", default=None, metavar="FAMILY",
                     help="rosbag: the AprilTag family of --image-topic (default tag36h11)")
    imp.add_argument("--camera", default=None, action="append", metavar="FILE",
                     help="rosbag: the camera of tag corners or images: a Kalibr cameras.yaml or a ROS camera_info "
                          "YAML; for several cameras one file each (in the order of their topics) or one Kalibr "
                          "file holding cam0, cam1, ... Default: each topic's camera_info topic in the bag")
    imp.add_argument("--camera-name", default=None, metavar="NAME",
                     help="rosbag: which camera of a Kalibr file (and of --camera-poses), e.g. cam0")
    imp.add_argument("--camera-info-topic", default=None, action="append", metavar="TOPIC",
                     help="rosbag: read the camera from this sensor_msgs/CameraInfo topic instead of --camera "
                          "(repeat it: one per camera, in the order of their topics)")
    imp.add_argument("--camera-pose", default=None, action="append", metavar="[NAME=]X,Y,Z,QX,QY,QZ,QW",
                     help="rosbag: the camera's optical frame in the odometry's body frame (metres, unit quaternion); "
                          "with several cameras NAME=... for each (cam0, cam1, ... in the order of their topics, or "
                          "the topic). Default: /tf_static from the odometry's child frame to each camera's frame_id, "
                          "else the optical frame at the body's origin looking forward (with a warning)")
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


def _mount(args: argparse.Namespace, tags, topics: list[str]):
    """The camera pose of one camera (4×4 or None), or of each of several cameras (a list)."""
    if args.camera_pose is not None and args.camera_poses is not None:
        raise FgslamError("--camera-pose and --camera-poses both place the camera; give one of them")
    n = max(1, len(topics))
    if args.camera_pose is not None:
        return camera_poses_by_name(args.camera_pose, topics)
    if args.camera_poses is None:
        return None
    from slamio.datasets.tagslam_files import load_camera_poses

    T_rig_odom = tags.T_body_odom if tags is not None and tags.T_body_odom is not None else np.eye(4)
    if n == 1:
        return np.linalg.inv(T_rig_odom) @ load_camera_poses(args.camera_poses, args.camera_name)
    from slamio.datasets.rosbag_cameras import default_camera_names

    return [np.linalg.inv(T_rig_odom) @ load_camera_poses(args.camera_poses, name) for name in default_camera_names(n)]


def camera_poses_by_name(values: list[str], topics: list[str]):
    """``--camera-pose`` values (``[NAME=]x,y,z,qx,qy,qz,qw``) → one 4×4 (one camera) or one per
    camera (None where not given); NAME is cam<k> or camera k's topic."""
    n = max(1, len(topics))
    if n == 1 and len(values) == 1 and "=" not in values[0]:
        return parse_camera_pose(values[0])
    from slamio.datasets.rosbag_cameras import default_camera_names

    names = list(default_camera_names(n))
    out: list = [None] * n
    for value in values:
        name, sep, pose = value.rpartition("=")
        if not sep:
            raise FgslamError(f"--camera-pose {value!r}: with {n} cameras say which: NAME=x,y,z,qx,qy,qz,qw with NAME "
                              f"one of {', '.join(names)} or their topics ({', '.join(topics)})")
        k = names.index(name) if name in names else topics.index(name) if name in topics else None
        if k is None:
            raise FgslamError(f"--camera-pose {value!r}: no camera {name!r}; the cameras are {', '.join(names)} "
                              f"({', '.join(topics) or 'the tag pose topics'})")
        if out[k] is not None:
            raise FgslamError(f"--camera-pose: camera {name!r} placed twice")
        out[k] = parse_camera_pose(pose)
    return out if n > 1 else out[0]


def _cameras(args: argparse.Namespace, topics: list[str]):
    """The camera model of one camera, or one per camera (a list), from --camera files."""
    from slamio.camera.camera_files import load_camera_file

    files = args.camera or []
    if not files:
        return None
    if args.camera_info_topic is not None:
        raise FgslamError("--camera and --camera-info-topic both give the camera; give one of them")
    n = max(1, len(topics))
    if n == 1:
        if len(files) > 1:
            raise FgslamError(f"{len(files)} --camera files for one camera topic; give one")
        return load_camera_file(files[0], args.camera_name)
    if len(files) == 1:  # one Kalibr file holding cam0, cam1, ...
        from slamio.datasets.rosbag_cameras import default_camera_names

        return [load_camera_file(files[0], name) for name in default_camera_names(n)]
    if len(files) != n:
        raise FgslamError(f"{len(files)} --camera files for {n} camera topics ({', '.join(topics)}): give one per "
                          "topic in the same order, or one Kalibr file holding cam0, cam1, ...")
    return [load_camera_file(f) for f in files]


def import_rosbag_cli(args: argparse.Namespace, source: str, standard_topics_only: bool):
    """Run :func:`slamio.datasets.rosbag.import_rosbag` with the command line's options and
    print its warnings to stderr."""
    from fgslam.cli.common import check_number
    from fgslam.cli.progress import Progress
    from slamio.datasets.rosbag import import_rosbag

    for option, value, what in (("--tag-size", args.tag_size, "metres, a tag's side"),
                                ("--pixel-sigma-px", args.pixel_sigma_px, "pixels, the corner noise"),
                                ("--max-reprojection-px", args.max_reprojection_px, "pixels")):
        if value is not None:
            check_number(option, value, above=0, what=what)
    topics = [*(args.detections_topic or []), *(args.image_topic or [])]
    camera = _cameras(args, topics)
    info_topics = args.camera_info_topic
    if info_topics is not None and len(info_topics) == 1 and len(topics) <= 1:
        info_topics = info_topics[0]
    truth_frames = parse_truth_frames(args.truth_frames) if args.truth_frames is not None else None
    tags = None
    if args.tags is not None:
        from slamio.datasets.tagslam_files import load_tags_file

        tags = load_tags_file(args.tags)
    started = time.perf_counter()
    with Progress(unit="images") as progress:
        header, records = import_rosbag(
            source, odom_topic=args.odom_topic, detections_topic=args.detections_topic,
            tag_pose_topic=args.tag_pose_topic, truth_topic=args.truth_topic,
            standard_topics_only=standard_topics_only, camera=camera, camera_info_topic=info_topics,
            tag_sizes=tags, tag_size_m=args.tag_size, pixel_sigma_px=args.pixel_sigma_px,
            T_robot_camera=_mount(args, tags, topics), level=args.level or "auto",
            image_topic=args.image_topic, tag_family=args.tag_family or "tag36h11", progress=progress,
            **_rest(args, truth_frames))
    for warning in header.source.get("warnings", []):
        print(f"fgslam: warning: {warning}", file=sys.stderr)
    images = header.source.get("images")
    if images:
        frames = sum(c.get("frames", 0) for c in images.values())
        print(f"images: {frames} frames, {sum(c.get('tags', 0) for c in images.values())} tags found "
              f"({(time.perf_counter() - started) / max(frames, 1) * 1e3:.0f} ms per frame, whole import); "
              + "; ".join(f"{t}: {c}" for t, c in images.items()), file=sys.stderr)
    return header, records


def _rest(args: argparse.Namespace, truth_frames) -> dict:
    return dict(
        truth_bag=args.truth_bag, truth_pose_of=args.truth_pose_of or "body", truth_frames=truth_frames,
        start_from="truth" if args.truth_bag is not None or truth_frames is not None else "odom",
        **({"max_reprojection_px": args.max_reprojection_px} if args.max_reprojection_px is not None else {}),
    )
