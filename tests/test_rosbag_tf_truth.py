"""Truth from /tf (``--truth-frames map:rig``, slamio.datasets.rosbag_read.read_tf_poses):
the pose of one frame in another through the bag's chain of transforms. The bag is written
here with rosbags' own writer: the known circle of tests/test_rosbag.py as odom -> rig on
/tf, a fixed map -> odom on /tf_static, a surveyed tag_5 under map, and a transform off the
chain that must not add truth samples. The reference: the circle's exact poses composed
with the fixed map -> odom by hand."""

from __future__ import annotations

import math

import pytest

from fgslam.cli import main
from slamio.datasets.rosbag import MessageFactory, apriltag_typestore, import_rosbag
from slamio.datasets.rosbag_read import BagFormatError, read_tf_poses
from slamio.errors import FgslamError
from slamio.geometry import compose_pose
from slamio.log import TruthLandmark, TruthPose, read_log
from tests.test_rosbag import EPOCH_NS, N_ODO, ODO_PERIOD_NS, circle_messages, circle_pose, write_bag

MAP_ODOM = (10.0, -2.0, 0.3)  # the odometry frame's origin and heading in the map


def _tf(store, make, stamp_ns, transforms):
    T = store.types
    out = []
    for parent, child, (x, y, z), yaw in transforms:
        out.append(T["geometry_msgs/msg/TransformStamped"](
            header=make.header(stamp_ns, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z)),
                rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))))
    return T["tf2_msgs/msg/TFMessage"](transforms=out)


def _tf_bag(path, ros_version=2):
    store = apriltag_typestore(ros_version)
    make = MessageFactory(store, ros_version)
    messages = [m for m in circle_messages(ros_version) if m[0] == "/odom"]
    static = _tf(store, make, EPOCH_NS, [("map", "odom", (*MAP_ODOM[:2], 0.0), MAP_ODOM[2]),
                                         ("map", "tag_5", (4.0, 5.0, 0.4), 0.0)])
    messages.append(("/tf_static", "tf2_msgs/msg/TFMessage", EPOCH_NS - 1, static))
    for k in range(0, N_ODO, 4):
        t = EPOCH_NS + k * ODO_PERIOD_NS
        x, y, th = circle_pose(k * 0.05)
        messages.append(("/tf", "tf2_msgs/msg/TFMessage", t + 1000, _tf(store, make, t, [("odom", "rig", (x, y, 0.0), th)])))
        messages.append(("/tf", "tf2_msgs/msg/TFMessage", t + 2000,  # off the chain: no truth sample of its own
                         _tf(store, make, t + 7_000_000, [("rig", "wheel", (0.1, 0.0, 0.0), 0.01 * k)])))
    return write_bag(path, ros_version, messages)


def test_read_tf_poses_composes_the_chain_at_each_move(tmp_path):
    bag = _tf_bag(tmp_path / "b")
    poses, frame, last = read_tf_poses(str(bag), "map", "rig")
    assert frame == "map"
    assert [t for t, _, _ in poses] == [EPOCH_NS + k * ODO_PERIOD_NS for k in range(0, N_ODO, 4)]
    for (t, p, q), k in zip(poses, range(0, N_ODO, 4)):
        x, y, th = compose_pose(MAP_ODOM, circle_pose(k * 0.05))
        assert p == pytest.approx((x, y, 0.0), abs=1e-9)
        assert q[:2] == pytest.approx((0.0, 0.0), abs=1e-12)  # a turn about z only
        assert math.cos(2 * math.atan2(q[2], q[3]) - th) == pytest.approx(1.0, abs=1e-12)
    assert set(last) == {("map", "odom"), ("map", "tag_5"), ("odom", "rig"), ("rig", "wheel")}
    # the inverse direction is the same chain read backwards
    back, _, _ = read_tf_poses(str(bag), "rig", "map")
    x, y, th = compose_pose(MAP_ODOM, circle_pose(0.0))
    c, s = math.cos(th), math.sin(th)
    assert back[0][1][:2] == pytest.approx((-(c * x + s * y), s * x - c * y), abs=1e-9)


def test_a_chain_that_does_not_join_names_the_frames(tmp_path):
    bag = _tf_bag(tmp_path / "b")
    with pytest.raises(BagFormatError, match=r"no chain of transforms from 'map' to 'base_link'.*frames on /tf and "
                                             r"/tf_static: map, odom, rig, tag_5, wheel"):
        read_tf_poses(str(bag), "map", "base_link")
    write_bag(tmp_path / "no_tf", 2, [m for m in circle_messages(2) if m[0] == "/odom"])
    with pytest.raises(BagFormatError, match=r"topic /tf: not in this bag; --truth-frames map:rig reads"):
        read_tf_poses(str(tmp_path / "no_tf"), "map", "rig")


def test_import_takes_the_truth_from_tf_in_the_same_bag_or_a_truth_bag(tmp_path):
    bag = _tf_bag(tmp_path / "b")
    header, records = import_rosbag(bag, odom_topic="/odom", truth_frames=("map", "rig"), start_from="truth")
    assert header.start_pose == pytest.approx(compose_pose(MAP_ODOM, circle_pose(0.0)), abs=1e-9)
    assert header.source["truth_frames"] == "map:rig"
    truth = {round(r.stamp_s, 6): r for r in records if isinstance(r, TruthPose)}
    for k in range(0, N_ODO, 4):  # at the /tf samples the interpolated truth is the sample itself
        expected = compose_pose(MAP_ODOM, circle_pose(k * 0.05))
        got = truth[round(k * 0.05, 6)]
        assert (got.x_m, got.y_m) == pytest.approx(expected[:2], abs=1e-9)
        assert math.cos(got.theta_rad - expected[2]) == pytest.approx(1.0, abs=1e-12)
    # tag_5 under map is the truth map (its face points up here: no facing direction)
    assert [r for r in records if isinstance(r, TruthLandmark)] == [TruthLandmark(5, 4.0, 5.0, 0.4, None)]
    # the same from a second bag, through the command line
    main_bag = write_bag(tmp_path / "main", 2, [m for m in circle_messages(2) if m[0] == "/odom"])
    out = tmp_path / "run.jsonl"
    assert main(["import", "rosbag", str(main_bag), str(out), "--odom-topic", "/odom", "--truth-bag", str(bag),
                 "--truth-frames", "map:rig"]) == 0
    log = read_log(out)
    assert log.header.start_pose == pytest.approx(header.start_pose, abs=1e-9)
    assert sum(isinstance(r, TruthPose) for r in log.records) == len(truth)


def test_truth_frames_option_errors(tmp_path, capsys):
    bag = _tf_bag(tmp_path / "b")
    with pytest.raises(FgslamError, match="--truth-topic and --truth-frames both give the truth"):
        import_rosbag(bag, odom_topic="/odom", truth_topic="/x", truth_frames=("map", "rig"))
    for text in ("maprig", "map:", "map:map", "a:b:c"):
        assert main(["import", "rosbag", str(bag), str(tmp_path / "x.jsonl"), "--odom-topic", "/odom",
                     "--truth-frames", text]) == 1
        assert "--truth-frames" in capsys.readouterr().err
    with pytest.raises(FgslamError, match=r"truth topic \(--truth-topic\) or the /tf frames"):
        import_rosbag(bag, odom_topic="/odom", truth_bag=bag)

