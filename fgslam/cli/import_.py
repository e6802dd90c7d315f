"""``fgslam import``: convert a dataset from elsewhere into a run log."""

from __future__ import annotations

import dataclasses

import argparse
import sys

from fgslam.cli.common import (
    add_overwrite_option,
    add_verb,
    check_new_file,
    check_number,
    command_line,
    hold_outputs,
    write_run_log,
)
from fgslam.cli.import_rosbag import ROSBAG_OPTIONS, add_rosbag_options
from fgslam.cli.verbs import help_of
from slamio.errors import FgslamError

DATASETS = ["victoria-park", "plaza1", "plaza2", "mrclam", "rosbag", "seed003"]


def add_parser(verbs) -> argparse.ArgumentParser:
    imp = add_verb(
        verbs, "import",
        usage="%(prog)s DATASET [SOURCE] OUT [options]",
        help=help_of("import"),
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
            "                 tag corners (apriltag_msgs) with --camera and --tags/--tag-size;\n"
            "                 --image-topic: tags found in raw/compressed images by fgslam's own\n"
            "                 detector; repeat the topics for several cameras (--camera-pose NAME=);\n"
            "                 --camera-pose, --level, --truth-bag, --truth-frames map:rig (truth from\n"
            "                 /tf): docs/datasets-mrclam-rosbag.md; a bag with no odometry is refused;\n"
            "                 a bag from `fgslam export rosbag` needs no topics (topics named are\n"
            "                 read from it too, in place of the run log it stores).\n"
            "  seed003        one of seed 003's stereo + IMU drives (SOURCE: its .npz): a 3-D log\n"
            "                 with one velocity record per step and the stereo feature tracks;\n"
            "                 --pixel-sigma (or --pixel-covariance), --speed-sigma, --turn-rate-sigma\n"
            "                 set the noise.\n"
            "See docs/datasets.md for what is converted and how. An existing OUT is kept unless\n"
            "--overwrite. One dataset per command: SOURCE (or --source, not both) is optional for\n"
            "victoria-park, plaza1 and plaza2 (default: the gtsam wheel's copy). An option of one\n"
            "dataset (e.g. --robot: mrclam) is refused with another."
        ),
    )
    imp.add_argument("dataset", choices=DATASETS, metavar="DATASET",
                     help="victoria-park, plaza1, plaza2, mrclam, rosbag or seed003")
    # nargs="+" (not two positionals): fgslam.cli.main adds the paths typed after an option here;
    # cmd_import accepts one or two of them
    imp.add_argument("paths", nargs="+", metavar="[SOURCE] OUT",
                     help="the dataset file or folder (optional for victoria-park and plaza), then the run log "
                          "to write (.jsonl)")
    imp.add_argument(
        "--source",
        default=None,
        metavar="PATH",
        help="the dataset file (Victoria Park) or folder (Plaza); default: the installed gtsam wheel's copy",
    )
    add_overwrite_option(imp, "an existing OUT")
    imp.add_argument("--range-sigma", type=float, default=None, metavar="M",
                     help="Plaza: standard deviation given to every range (default 1.5 m)")
    imp.add_argument("--range-bias", type=float, default=None, metavar="M",
                     help="Plaza: subtract this from every range (default 0; GPS says the radios read 7 %% long, "
                          "not a constant: fit the model with fgslam calibrate and use --noise)")
    imp.add_argument("--robot", type=int, default=None, metavar="N", help="MRCLAM: which robot, 1-5 (default 1)")
    imp.add_argument("--noise", default=None, metavar="FILE",
                     help="MRCLAM: a noise model from `fgslam calibrate LOG... --out FILE` (odometry lag and "
                          "scale, range/bearing correction and sigmas); `round` for round, unfitted values (what "
                          "`fgslam calibrate` fits on); default: the model shipped with fgslam, fitted on MRCLAM "
                          "Dataset 6's five robots against Vicon. "
                          "Plaza: the range model (scale, bias, sigma) fitted on the other run")
    imp.add_argument("--hide-ids", action="store_true",
                     help="write observations without landmark ids (the estimators must associate them); "
                          "the dataset's id is kept in truth_landmark_id to score the association")
    imp.add_argument("--odom-topic", default=None, help="rosbag: nav_msgs/Odometry topic")
    imp.add_argument("--detections-topic", default=None, action="append", metavar="TOPIC",
                     help="rosbag: tag detections of one camera: apriltag_ros/AprilTagDetectionArray (poses) or "
                          "apriltag_msgs/ApriltagArrayStamped (corners); repeat it for each camera of a rig")
    imp.add_argument("--tag-pose-topic", default=None,
                     help="rosbag: prefix of one geometry_msgs/PoseStamped topic per tag, e.g. /tags/tag_")
    imp.add_argument("--truth-topic", default=None, help="rosbag: ground-truth pose topic (optional)")
    _add_seed003_options(imp)
    add_rosbag_options(imp)
    imp.set_defaults(func=cmd_import, takes_extra_paths=True)
    return imp


def _add_seed003_options(imp: argparse.ArgumentParser) -> None:
    """seed003's noise options: the stereo pixels' σ or 4×4 covariance, the IMU's σ."""
    imp.add_argument("--pixel-sigma", type=float, default=None, metavar="PX",
                     help="seed003: σ of each stereo pixel coordinate (default 1 px)")
    imp.add_argument("--pixel-covariance", type=float, nargs="+", default=None, metavar="PX",
                     help="seed003: the stereo pixels' covariance instead of one sigma: SIGMA_U SIGMA_V RHO (px, px, "
                          "the correlation of v_L and v_R on one row) or the 16 entries of the 4x4 over "
                          "(u_L, v_L, u_R, v_R), px^2, row by row")
    imp.add_argument("--speed-sigma", type=float, default=None, metavar="M/S",
                     help="seed003: σ of each axis of the IMU's linear velocity (default 0.05 m/s)")
    imp.add_argument("--turn-rate-sigma", type=float, default=None, metavar="RAD/S",
                     help="seed003: σ of each axis of the IMU's angular velocity (default 0.005 rad/s)")


PLAZA = ("plaza1", "plaza2")

#: The options only some datasets read: (option, args attribute, those datasets, default when left out).
#: Their parser default is None, so an option typed for another dataset is seen and refused.
DATASET_OPTIONS = (
    ("--range-sigma", "range_sigma", PLAZA, 1.5),
    ("--range-bias", "range_bias", PLAZA, 0.0),
    ("--robot", "robot", ("mrclam",), 1),
    ("--noise", "noise", ("mrclam", *PLAZA), None),
    ("--odom-topic", "odom_topic", ("rosbag",), None),
    ("--detections-topic", "detections_topic", ("rosbag",), None),
    ("--tag-pose-topic", "tag_pose_topic", ("rosbag",), None),
    ("--truth-topic", "truth_topic", ("rosbag",), None),
    ("--pixel-sigma", "pixel_sigma", ("seed003",), 1.0),
    ("--pixel-covariance", "pixel_covariance", ("seed003",), None),
    ("--speed-sigma", "speed_sigma", ("seed003",), 0.05),
    ("--turn-rate-sigma", "turn_rate_sigma", ("seed003",), 0.005),
    *((option, name, ("rosbag",), None) for option, name in ROSBAG_OPTIONS),
)


def _source_and_out(args: argparse.Namespace) -> tuple[str | None, str]:
    """SOURCE (the positional one or --source, not both) and OUT."""
    paths = args.paths
    if len(paths) > 2:
        raise FgslamError(f"import converts one dataset: give [SOURCE] OUT (one or two paths), got {len(paths)}: "
                          f"{' '.join(paths)}; run fgslam import once per dataset")
    if len(paths) == 2 and args.source is not None:
        raise FgslamError(f"SOURCE given twice: {paths[0]} and --source {args.source}; give one of them")
    return (paths[0] if len(paths) == 2 else args.source), paths[-1]


def _check_dataset_options(args: argparse.Namespace) -> None:
    """Refuse an option of another dataset (it would be ignored), check the values, then fill in
    the defaults of those left out."""
    if getattr(args, "pixel_sigma", None) is not None and getattr(args, "pixel_covariance", None) is not None:
        raise FgslamError("--pixel-sigma and --pixel-covariance both state the pixel noise; give one of them")
    for option, name, datasets, default in DATASET_OPTIONS:
        value = getattr(args, name)
        if value is not None and args.dataset not in datasets:
            belongs = ", ".join(datasets[:-1]) + " and " + datasets[-1] if len(datasets) > 1 else datasets[0]
            raise FgslamError(f"{option} is for {belongs}, not {args.dataset}; leave it out")
        if value is None:
            setattr(args, name, default)
    check_number("--range-sigma", args.range_sigma, above=0, what="metres, the σ of every range")
    check_number("--range-bias", args.range_bias, what="metres subtracted from every range")
    if args.robot < 1:
        raise FgslamError(f"--robot must be 1 or more (MRCLAM robots are numbered from 1); got {args.robot}")


def cmd_import(args: argparse.Namespace) -> int:
    source, out = _source_and_out(args)
    with hold_outputs((out, "OUT")):  # one writer per output, from the checks to the last byte
        return _import(args, source, out)


def _import(args: argparse.Namespace, source: str | None, out: str) -> int:
    _check_dataset_options(args)
    needs_source = ("mrclam", "rosbag", "seed003")
    if args.dataset in needs_source and source is None:
        raise FgslamError(f"import {args.dataset} needs SOURCE: fgslam import {args.dataset} SOURCE OUT")
    check_new_file(out, overwrite=args.overwrite, option="OUT")  # before the conversion
    if args.dataset == "victoria-park":
        from slamio.datasets import import_victoria_park

        header, records = import_victoria_park(source)
    elif args.dataset == "mrclam":
        from slamio.datasets.mrclam import import_mrclam

        from slamio.datasets.mrclam import SHIPPED_NOISE_MODEL, SHIPPED_NOISE_NOTE
        from slamio.noise.model import load_noise_model

        if args.noise == "round":
            model = None
        else:
            model = load_noise_model(SHIPPED_NOISE_MODEL if args.noise is None else args.noise)
        header, records = import_mrclam(source, args.robot, model=model)
        if args.noise is None:  # say which model, in the header and here
            header = dataclasses.replace(header, source={**header.source, "noise_model": SHIPPED_NOISE_NOTE})
            print(f"noise: {SHIPPED_NOISE_NOTE} (--noise round for the round, unfitted values)")
    elif args.dataset == "seed003":
        header, records = _import_seed003(source, args)
    elif args.dataset == "rosbag":
        from fgslam.cli.import_rosbag import import_rosbag_cli

        topics = (args.odom_topic, args.detections_topic, args.tag_pose_topic, args.truth_topic, args.image_topic)
        # topics named: read them, also from a bag fgslam export wrote
        header, records = import_rosbag_cli(args, source, standard_topics_only=any(t is not None for t in topics))
    else:  # plaza1, plaza2
        from slamio.datasets.plaza import import_plaza

        model = None
        if args.noise is not None:
            from slamio.noise.model import load_noise_model

            model = load_noise_model(args.noise)
        header, records = import_plaza(
            args.dataset, source, range_sigma_m=args.range_sigma, range_bias_m=args.range_bias, range_model=model
        )
        dropped = header.source.get("ranges_not_positive_after_bias_dropped", 0)
        if args.range_bias and dropped:
            print(f"fgslam: warning: --range-bias {args.range_bias:g} m left {dropped} ranges at or below 0; "
                  "they were dropped", file=sys.stderr)
    if args.hide_ids:
        header, records = hide_landmark_ids(header, records)
    return write_run_log(out, header, records, overwrite=args.overwrite, option="OUT")


def _import_seed003(source: str, args: argparse.Namespace):
    """A seed-003 npz as a 3-D log (slamio.datasets.seed003_log)."""
    from slamio.datasets.seed003 import StereoImuNoise, load_drive
    from slamio.datasets.seed003_log import drive_to_log

    for flag, value in (("--pixel-sigma", args.pixel_sigma), ("--speed-sigma", args.speed_sigma),
                        ("--turn-rate-sigma", args.turn_rate_sigma)):
        if not (value > 0.0 and value < 1e3):
            raise FgslamError(f"{flag} {value!r} must be a standard deviation > 0 (and below 1000)")
    noise = StereoImuNoise(sigma_px=args.pixel_sigma, sigma_v_mps=args.speed_sigma, sigma_w_radps=args.turn_rate_sigma,
                           pixel_covariance=_pixel_covariance_option(args.pixel_covariance))
    drive = load_drive(source)
    return drive_to_log(drive, noise, source={"dataset": "seed003", "file": str(source), "command": command_line(args)})


def _pixel_covariance_option(values: list[float] | None):
    """``--pixel-covariance``: σ_u σ_v ρ (rectified stereo) or the 16 entries of the 4×4, checked
    as the log's ``covariance_px2`` is; None when not given."""
    if values is None:
        return None
    from slamio.log.records3d import checked_pixel_covariance
    from slamio.stereo import rectified_pixel_covariance

    if len(values) == 3:
        try:
            matrix = rectified_pixel_covariance(*values)
        except ValueError:
            raise FgslamError(f"--pixel-covariance {' '.join(f'{v:g}' for v in values)}: SIGMA_U and SIGMA_V must be "
                              "> 0 px and RHO (the correlation of v_L and v_R) within (-1, 1)") from None
        values = [float(v) for v in matrix.ravel()]
    if len(values) != 16:
        raise FgslamError(f"--pixel-covariance takes 3 numbers (SIGMA_U SIGMA_V RHO) or 16 (the 4x4 over u_L, v_L, "
                          f"u_R, v_R, row by row), got {len(values)}")
    try:
        return checked_pixel_covariance([values[i:i + 4] for i in range(0, 16, 4)])
    except ValueError as bad:
        raise FgslamError(f"--pixel-covariance: {bad}") from None


def hide_landmark_ids(header, records):
    """The log with every observation's ``landmark_id`` moved to ``truth_landmark_id``
    (range-only observations keep theirs: a range alone cannot be associated)."""
    from dataclasses import replace

    from slamio.log import Observation

    hidden = [
        replace(r, landmark_id=None, truth_landmark_id=r.landmark_id)
        if isinstance(r, Observation) and r.landmark_id is not None and not r.range_only else r
        for r in records
    ]
    return replace(header, source={**header.source, "hide_ids": True}), hidden
