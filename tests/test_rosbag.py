"""ROS bag import/export (slamio.datasets.rosbag) with bags written by rosbags' own writers.

* Round trip: a run log exported to a ROS 2 bag and imported back is identical (header and
  records), on data/arena_octagon.jsonl and on small hypothesis-generated logs.
* The same bag read through its standard topics only (nav_msgs/Odometry, PoseStamped,
  AprilTagDetectionArray) gives poses within 1e-6 m of the integrated log.
* ROS 1 and ROS 2 bags of a known motion (a circle) and known tags: increments, detection
  poses, camera extrinsics, ground truth and covariance rules are checked in closed form.
* Missing topics, wrong types and foreign messages are refused naming the topic.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slamio.datasets.mrclam_motion import CommandOdometryNoise
from slamio.datasets.rosbag import (
    DETECTIONS_TOPIC,
    ODOMETRY_TOPIC,
    RUN_LOG_TOPIC,
    TRUTH_TOPIC,
    T_ROBOT_OPTICAL,
    BagFormatError,
    MessageFactory,
    apriltag_typestore,
    export_rosbag,
    import_rosbag,
    quaternion_from_rotation,
    rotation_from_quaternion,
)
from slamio.datasets.victoria_park import DatasetFormatError
from slamio.errors import FgslamError
from slamio.geometry import between_pose, compose_pose, wrap_angle
from slamio.log import (
    Header,
    LogFormatError,
    Observation,
    Odometry,
    RunLog,
    TruthLandmark,
    TruthPose,
    group_steps,
    read_log,
    write_log,
)

ROOT = Path(__file__).resolve().parents[1]
OCTAGON = ROOT / "data" / "arena_octagon.jsonl"


def integrate(header, records):
    """World pose of every step of a log (dead reckoning from the start pose)."""
    pose = tuple(header.start_pose)
    poses = [pose]
    for step in group_steps(header, records)[1:]:
        o = step.odometry
        pose = compose_pose(pose, (o.dx_m, o.dy_m, o.dtheta_rad))
        poses.append(pose)
    return poses


# ----------------------------------------------------------------------------- exact round trip


@pytest.fixture(scope="module")
def octagon_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "octagon_bag"
    summary = export_rosbag(OCTAGON, out)
    return out, summary


def test_octagon_round_trip_is_identical(octagon_bag):
    bag, summary = octagon_bag
    log = read_log(OCTAGON)
    assert summary[RUN_LOG_TOPIC] == 1 + len(log.records)
    assert summary["observations_not_on_detections"] == 0
    header, records = import_rosbag(bag)
    assert header == log.header
    assert tuple(records) == log.records
    # the topic names given for a foreign bag do not matter when the exact log is there
    header2, records2 = import_rosbag(bag / "metadata.yaml", odom_topic="/whatever")
    assert (header2, tuple(records2)) == (log.header, log.records)


def test_one_topic_named_for_two_roles_is_an_error(octagon_bag):
    """Truth on the odometry topic would read every message as odometry only: refused."""
    bag, _ = octagon_bag
    with pytest.raises(FgslamError, match="named as both the odometry topic and the truth topic"):
        import_rosbag(bag, odom_topic=ODOMETRY_TOPIC, truth_topic=ODOMETRY_TOPIC, standard_topics_only=True)


def test_octagon_standard_topics_give_the_integrated_poses(octagon_bag):
    bag, _ = octagon_bag
    log = read_log(OCTAGON)
    header, records = import_rosbag(
        bag, odom_topic=ODOMETRY_TOPIC, detections_topic=DETECTIONS_TOPIC, truth_topic=TRUTH_TOPIC,
        standard_topics_only=True,
    )
    original, imported = integrate(log.header, log.records), integrate(header, records)
    assert len(imported) == len(original)
    for a, b in zip(original, imported):
        assert math.hypot(a[0] - b[0], a[1] - b[1]) < 1e-6
        assert abs(wrap_angle(a[2] - b[2])) < 1e-9
    assert header.source["odometry_covariance"] == {"from_message": len(original) - 1, "default_model": 0}
    steps_a, steps_b = group_steps(log.header, log.records), group_steps(header, records)
    for sa, sb in zip(steps_a, steps_b):
        assert sb.stamp_s == pytest.approx(sa.stamp_s, abs=1e-9)
        if sa.odometry is not None:
            # the increment covariance is recovered from the growth of the pose covariance
            assert np.allclose(sb.odometry.covariance, sa.odometry.covariance, rtol=1e-5, atol=1e-12)
        assert (sb.truth.x_m, sb.truth.y_m) == (sa.truth.x_m, sa.truth.y_m)
        assert abs(wrap_angle(sb.truth.theta_rad - sa.truth.theta_rad)) < 1e-12
        assert [o.landmark_id for o in sb.observations] == [o.landmark_id for o in sa.observations]
        for oa, ob in zip(sa.observations, sb.observations):
            assert ob.range_m == pytest.approx(oa.range_m, abs=1e-12)
            assert abs(wrap_angle(ob.bearing_rad - oa.bearing_rad)) < 1e-12
            assert abs(wrap_angle(ob.tag_yaw_rad - oa.tag_yaw_rad)) < 1e-9


def _reads_range_only() -> bool:
    """Whether slamio.log already reads range-only observations (bearing_rad absent)."""
    from slamio.log import parse_record

    try:
        parse_record({"type": "observation", "stamp_s": 0.0, "landmark_id": 1, "range_m": 1.0, "sigma_range_m": 0.1})
    except Exception:
        return False
    return True


RANGE_ONLY = _reads_range_only()

# hypothesis: small logs with every optional field
finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)
positive = st.floats(min_value=1e-6, max_value=1e3, allow_nan=False)
angle_sigma = st.floats(min_value=1e-6, max_value=2 * math.pi, allow_nan=False)  # the reader's bound
text = st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=8)
scalar = st.one_of(st.none(), st.booleans(), st.integers(-(2**53), 2**53), finite, text)


@st.composite
def small_logs(draw):
    stamp = draw(st.floats(min_value=0.0, max_value=2e9, allow_nan=False))
    header = Header(
        stamp_s=stamp,
        start_pose=(draw(finite), draw(finite), draw(st.floats(-3.14, 3.14))),
        start_sigma=(draw(positive), draw(positive), draw(angle_sigma)),
        robot={"name": draw(text), **draw(st.dictionaries(text, scalar, max_size=2))},
        sensor={"kind": draw(text), "nested": draw(st.dictionaries(text, st.lists(scalar, max_size=3), max_size=2))},
        noise={"odometry": draw(st.dictionaries(text, scalar, max_size=2)), "observation": {}},
        source=draw(st.dictionaries(text, scalar, max_size=2)),
    )
    records = []
    truth_ids: set[int] = set()  # a landmark's truth is given once (the reader refuses a second)
    for _ in range(draw(st.integers(0, 10))):
        stamp += draw(st.sampled_from([0.0, 0.0, 1e-9, 0.05, draw(st.floats(0.0, 5.0))]))
        kind = draw(st.sampled_from(["odometry", "observation", "observation", "truth_pose", "truth_landmark"]))
        if kind == "odometry":
            d = [draw(st.floats(1e-8, 1.0)) for _ in range(3)]
            c = draw(st.floats(-0.9, 0.9)) * math.sqrt(d[0] * d[1])
            cov = ((d[0], c, 0.0), (c, d[1], 0.0), (0.0, 0.0, d[2]))
            raw = draw(st.booleans())
            records.append(Odometry(stamp, draw(finite), draw(finite), draw(st.floats(-3.0, 3.0)), cov,
                                    draw(finite) if raw else None, draw(finite) if raw else None))
        elif kind == "observation":
            range_only = RANGE_ONLY and draw(st.booleans())
            yaw = not range_only and draw(st.booleans())
            height = draw(st.booleans())
            records.append(Observation(
                stamp, draw(st.one_of(st.none(), st.integers(0, 2**31 - 1))), draw(positive),
                None if range_only else draw(st.floats(-3.14, 3.14)),
                draw(positive), None if range_only else draw(angle_sigma),
                height_m=draw(finite) if height else None, sigma_height_m=draw(positive) if height else None,
                tag_yaw_rad=draw(st.floats(-3.14, 3.14)) if yaw else None, sigma_tag_yaw_rad=draw(angle_sigma) if yaw else None,
                truth_landmark_id=draw(st.one_of(st.none(), st.integers(0, 10**9))),
            ))
        elif kind == "truth_pose":
            records.append(TruthPose(stamp, draw(finite), draw(finite), draw(finite)))
        else:
            lid = draw(st.integers(0, 10**9).filter(lambda i: i not in truth_ids))
            truth_ids.add(lid)
            records.append(TruthLandmark(lid, draw(finite), draw(finite),
                                         draw(st.one_of(st.none(), finite)), draw(st.one_of(st.none(), finite))))
    return header, records


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(log=small_logs(), storage=st.sampled_from(["sqlite3", "mcap"]))
def test_generated_logs_round_trip_exactly(log, storage):
    header, records = log
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "log.jsonl")
        write_log(path, header, records)
        expected = read_log(path)  # what the log reader gives; the bag must give the same
        export_rosbag(path, os.path.join(tmp, "bag"), storage=storage)
        got_header, got_records = import_rosbag(os.path.join(tmp, "bag"))
    assert got_header == expected.header
    assert tuple(got_records) == expected.records


def test_range_only_observations_stay_on_the_run_log_topic(tmp_path):
    """A range-only observation (bearing None, the Plaza format change) is not a tag pose."""
    header = Header(0.0, (0.0, 0.0, 0.0), (1e-3, 1e-3, 1e-3), {"name": "t"}, {"kind": "range-only"},
                    {"odometry": {}, "observation": {}})
    cov = ((1e-4, 0.0, 0.0), (0.0, 1e-4, 0.0), (0.0, 0.0, 1e-4))
    records = (
        Odometry(0.5, 0.1, 0.0, 0.0, cov),
        Observation(0.5, 3, 2.0, None, 0.1, None),  # type: ignore[arg-type]
        Observation(0.5, 4, 1.5, 0.3, 0.1, 0.02),
    )
    summary = export_rosbag(RunLog("mem", header, records), tmp_path / "bag")
    assert summary["observations_not_on_detections"] == 1
    assert summary[DETECTIONS_TOPIC] == 1
    h, r = import_rosbag(tmp_path / "bag", odom_topic=ODOMETRY_TOPIC, detections_topic=DETECTIONS_TOPIC,
                         standard_topics_only=True)
    assert [o.landmark_id for o in r if isinstance(o, Observation)] == [4]
    # exact path: equal once slamio.log reads range-only observations; until then the
    # importer reports the run-log message that the log reader refuses
    write_log(tmp_path / "probe.jsonl", header, records)
    try:
        expected = read_log(tmp_path / "probe.jsonl")
    except LogFormatError:
        with pytest.raises(BagFormatError, match=rf"topic {RUN_LOG_TOPIC} message 3: .*bearing_rad"):
            import_rosbag(tmp_path / "bag")
    else:
        assert import_rosbag(tmp_path / "bag") == (expected.header, list(expected.records))


# ----------------------------------------------------------------------------- bags of a known motion

V_MPS, W_RADPS = 0.2, 0.25
START = (1.0, 2.0, 0.5)
EPOCH_NS = 1_700_000_000 * 10**9
ODO_PERIOD_NS = 50_000_000
N_ODO = 61  # 3 s
#: tag id -> (x_m, y_m, height_m, facing yaw in the world)
TAGS = {3: (3.0, 3.0, 0.4, -2.5), 7: (1.5, 4.5, 0.3, -1.6), 12: (2.6, 0.9, 0.35, 2.4)}


def circle_pose(t_s):
    """Exact pose after t_s seconds of the constant command (v, w) from START."""
    x, y, th = START
    r = V_MPS / W_RADPS
    th1 = th + W_RADPS * t_s
    return x + r * (math.sin(th1) - math.sin(th)), y - r * (math.cos(th1) - math.cos(th)), th1


def camera_pose_of_tag(pose, tag, T_robot_camera):
    """Tag position and quaternion in the camera's optical frame (built independently)."""
    x, y, h, facing = tag
    c, s = math.cos(pose[2]), math.sin(pose[2])
    p_robot = np.array([c * (x - pose[0]) + s * (y - pose[1]), -s * (x - pose[0]) + c * (y - pose[1]), h])
    yaw = facing - pose[2]
    z = np.array([math.cos(yaw), math.sin(yaw), 0.0])  # out of the printed face
    up = np.array([0.0, 0.0, 1.0])
    R_robot_tag = np.column_stack([np.cross(up, z), up, z])
    R, t = T_robot_camera[:3, :3], T_robot_camera[:3, 3]
    return R.T @ (p_robot - t), quaternion_from_rotation(R.T @ R_robot_tag)


def visible(pose):
    return [i for i, (x, y, _, _) in TAGS.items()
            if abs(wrap_angle(math.atan2(y - pose[1], x - pose[0]) - pose[2])) < 1.2]


def write_bag(path, ros_version, messages):
    """messages: (topic, msgtype, bag time ns, message); written with rosbags' own writers."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2

    store = apriltag_typestore(ros_version)
    make = MessageFactory(store, ros_version)
    writer = Writer2(path, version=8) if ros_version == 2 else Writer1(path)
    with writer:
        conns = {}
        for topic, msgtype, t, msg in sorted(messages, key=lambda m: m[2]):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], t, make.serialize(msg))
    return path


def circle_messages(ros_version, *, T_robot_camera=T_ROBOT_OPTICAL, odom_covariance=None, per_tag_topics=False):
    make = MessageFactory(apriltag_typestore(ros_version), ros_version)
    out = []
    for k in range(N_ODO):
        t = EPOCH_NS + k * ODO_PERIOD_NS
        cov = None if odom_covariance is None else odom_covariance(k)
        out.append(("/odom", "nav_msgs/msg/Odometry", t, make.odometry(t, circle_pose(k * 0.05), cov, "odom", "base_link")))
        if k % 4 == 0:
            truth = circle_pose(k * 0.05)
            out.append(("/mocap", "geometry_msgs/msg/PoseStamped", t + 1_000_000,
                        make.pose_stamped(t, (truth[0] + 10.0, truth[1], truth[2]), "mocap")))
    # detections between odometry messages, one on an odometry time, one before, one after
    times = [EPOCH_NS + 25_000_000 + j * 100_000_000 for j in range(29)] + [EPOCH_NS + 20 * ODO_PERIOD_NS]
    times += [EPOCH_NS - 10_000_000, EPOCH_NS + 3_100_000_000]
    for t in times:
        pose = circle_pose((t - EPOCH_NS) / 1e9)
        ids = visible(pose)
        tags = [([i], [0.16], *camera_pose_of_tag(pose, TAGS[i], T_robot_camera)) for i in ids]
        if per_tag_topics:
            for (ids_, _, p, q) in tags:
                out.append((f"/tags/tag_{ids_[0]}", "geometry_msgs/msg/PoseStamped", t, make.pose_stamped_3d(t, p, q)))
        else:
            tags.append(([1, 2], [0.1, 0.1], np.array([0.0, 0.0, 2.0]), (0.0, 0.0, 0.0, 1.0)))  # a bundle
            out.append(("/tag_detections", "apriltag_ros/msg/AprilTagDetectionArray", t, make.detection_array(t, tags)))
    return out


def assert_observations_hit_the_tags(header, records, exact_stamps_s=()):
    poses = integrate(header, records)
    n = 0
    for step, pose in zip(group_steps(header, records), poses):
        for o in step.observations:
            x, y, _, facing = TAGS[o.landmark_id]
            px = pose[0] + o.range_m * math.cos(pose[2] + o.bearing_rad)
            py = pose[1] + o.range_m * math.sin(pose[2] + o.bearing_rad)
            # poses between odometry messages are interpolated linearly: a 16 µm chord at most
            tol = 1e-9 if any(abs(step.stamp_s - s) < 1e-12 for s in exact_stamps_s) else 5e-5
            assert math.hypot(px - x, py - y) < tol
            assert abs(wrap_angle(pose[2] + o.tag_yaw_rad - facing)) < 1e-9
            n += 1
    return n


@pytest.mark.parametrize("ros_version", [1, 2])
def test_bag_of_a_known_circle(tmp_path, ros_version):
    path = tmp_path / ("circle.bag" if ros_version == 1 else "circle")
    write_bag(path, ros_version, circle_messages(ros_version))
    header, records = import_rosbag(path, odom_topic="/odom", detections_topic="/tag_detections", truth_topic="/mocap")
    src = header.source
    assert src["ros_version"] == ros_version and src["time_origin_ns"] == EPOCH_NS
    assert header.start_pose == pytest.approx(START, abs=1e-12)
    # every detection message has one bundle; the sightings before/after the odometry are single tags
    early, late = len(visible(circle_pose(-0.01))), len(visible(circle_pose(3.1)))
    assert early and late
    assert src["dropped"] == {"tag_bundles": 32, "zero_range": 0, "before_first_odometry": early, "after_last_odometry": late}
    odometry = [r for r in records if isinstance(r, Odometry)]
    # 60 odometry intervals + one pose per detection time strictly between two messages (29)
    assert len(odometry) == 60 + 29 == src["poses"] - 1
    # every increment between odometry messages is the exact circle's
    poses = integrate(header, records)
    stamps = [0.0] + [o.stamp_s for o in odometry]
    for s, pose in zip(stamps, poses):
        if abs(s / 0.05 - round(s / 0.05)) < 1e-9:
            expected = circle_pose(s)
            assert math.hypot(pose[0] - expected[0], pose[1] - expected[1]) < 1e-9
            assert abs(wrap_angle(pose[2] - expected[2])) < 1e-9
    n = assert_observations_hit_the_tags(header, records, exact_stamps_s=(1.0,))
    assert n == src["observations"] > 30
    # zero covariance in the messages: the default model, positive definite
    assert src["odometry_covariance"] == {"from_message": 0, "default_model": 60}
    for o in odometry:
        assert np.all(np.linalg.eigvalsh(np.array(o.covariance)) > 0)
    # ground truth: interpolated at every pose (10 m off in x: mocap's own frame)
    steps = group_steps(header, records)
    with_truth = [s for s in steps if s.truth is not None]
    assert len(with_truth) == len(steps)  # mocap at 5 Hz covers 0..3 s
    for s in with_truth:
        exact = circle_pose(s.stamp_s)
        assert math.hypot(s.truth.x_m - exact[0] - 10.0, s.truth.y_m - exact[1]) < 3e-4  # chord of a 4 cm arc: 0.25 mm
        assert abs(wrap_angle(s.truth.theta_rad - exact[2])) < 1e-9


def test_camera_extrinsic_option(tmp_path):
    # a camera 12 cm ahead, 30 cm up, tilted 0.2 rad down
    c, s = math.cos(0.2), math.sin(0.2)
    pitch = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    T = np.eye(4)
    T[:3, :3] = pitch @ T_ROBOT_OPTICAL[:3, :3]
    T[:3, 3] = (0.12, 0.0, 0.30)
    write_bag(tmp_path / "b", 2, circle_messages(2, T_robot_camera=T))
    header, records = import_rosbag(tmp_path / "b", odom_topic="/odom", detections_topic="/tag_detections",
                                    T_robot_camera=T, with_height=True)
    assert assert_observations_hit_the_tags(header, records, exact_stamps_s=(1.0,)) > 30
    heights = {o.landmark_id: o.height_m for o in records if isinstance(o, Observation)}
    assert heights == pytest.approx({i: TAGS[i][2] for i in heights}, abs=1e-9)
    # read with the wrong (default) extrinsic, the geometry is off
    _, wrong = import_rosbag(tmp_path / "b", odom_topic="/odom", detections_topic="/tag_detections")
    with pytest.raises(AssertionError):
        assert_observations_hit_the_tags(header, wrong)


def test_one_pose_stamped_topic_per_tag(tmp_path):
    write_bag(tmp_path / "b", 2, circle_messages(2, per_tag_topics=True))
    header, records = import_rosbag(tmp_path / "b", odom_topic="/odom", tag_pose_topic="/tags/tag_")
    assert header.sensor["tag_pose_topics"] == ["/tags/tag_12", "/tags/tag_3", "/tags/tag_7"]
    assert assert_observations_hit_the_tags(header, records, exact_stamps_s=(1.0,)) > 30
    flipped = import_rosbag(tmp_path / "b", odom_topic="/odom", tag_pose_topic="/tags/tag_", tag_normal_axis="-z")[1]
    for a, b in zip((r for r in records if isinstance(r, Observation)), (r for r in flipped if isinstance(r, Observation))):
        assert abs(wrap_angle(a.tag_yaw_rad - b.tag_yaw_rad + math.pi)) < 1e-9


def test_detections_attach_to_the_earlier_pose_without_interpolation(tmp_path):
    write_bag(tmp_path / "b.bag", 1, circle_messages(1))
    header, records = import_rosbag(tmp_path / "b.bag", odom_topic="/odom", detections_topic="/tag_detections",
                                    interpolate_detections=False)
    odometry = [r for r in records if isinstance(r, Odometry)]
    assert len(odometry) == 60
    for step in group_steps(header, records):
        for o in step.observations:
            assert step.stamp_s <= o.stamp_s < step.stamp_s + 0.05


def test_covariance_from_propagating_messages_and_thinning(tmp_path):
    # a driver that propagates its covariance with a constant increment covariance Q
    Q = np.diag([4e-4, 1e-4, 9e-4])
    pose_cov = [np.diag([1e-6, 1e-6, 1e-6])]
    step = between_pose(circle_pose(0.0), circle_pose(0.05))
    for k in range(1, N_ODO):
        pose = circle_pose((k - 1) * 0.05)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        J1 = np.array([[1, 0, -s * step[0] - c * step[1]], [0, 1, c * step[0] - s * step[1]], [0, 0, 1]])
        J2 = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        pose_cov.append(J1 @ pose_cov[-1] @ J1.T + J2 @ Q @ J2.T)
    write_bag(tmp_path / "b", 2, circle_messages(2, odom_covariance=lambda k: pose_cov[k]))
    header, records = import_rosbag(tmp_path / "b", odom_topic="/odom", interpolate_detections=False)
    assert header.source["odometry_covariance"] == {"from_message": 60, "default_model": 0}
    for o in (r for r in records if isinstance(r, Odometry)):
        assert np.allclose(o.covariance, Q, rtol=1e-6, atol=1e-12)
    # the same bag, covariances ignored
    header, records = import_rosbag(tmp_path / "b", odom_topic="/odom", covariance_from_message=False,
                                    odometry_noise=CommandOdometryNoise(forward_m2_per_m=0.5))
    assert header.source["odometry_covariance"] == {"from_message": 0, "default_model": 60}
    first = next(r for r in records if isinstance(r, Odometry))
    assert first.covariance[0][0] == pytest.approx(0.5 * 0.2 * 0.05 + 1e-6 * 0.05, rel=1e-3)
    # thinning a 20 Hz topic to 5 Hz keeps every fourth message (and the last)
    header, records = import_rosbag(tmp_path / "b", odom_topic="/odom", odom_min_period_s=0.2)
    stamps = [r.stamp_s for r in records if isinstance(r, Odometry)]
    assert stamps == pytest.approx([0.2 * i for i in range(1, 16)])


def test_start_from_truth_puts_the_estimate_in_the_truth_frame(tmp_path):
    write_bag(tmp_path / "b", 2, circle_messages(2))
    header, _ = import_rosbag(tmp_path / "b", odom_topic="/odom", truth_topic="/mocap", start_from="truth")
    assert header.start_pose == pytest.approx((START[0] + 10.0, START[1], START[2]), abs=1e-9)
    header, _ = import_rosbag(tmp_path / "b", odom_topic="/odom", start_from="zero")
    assert header.start_pose == (0.0, 0.0, 0.0)


def test_quaternion_helpers_are_inverse():
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        R = rotation_from_quaternion(*q)
        assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
        assert np.allclose(rotation_from_quaternion(*quaternion_from_rotation(R)), R, atol=1e-12)
    assert rotation_from_quaternion(0.0, 0.0, 0.0, 0.0) is None


# ----------------------------------------------------------------------------- malformed input


@pytest.fixture(scope="module")
def circle_bag(tmp_path_factory):
    return write_bag(tmp_path_factory.mktemp("bags") / "circle", 2, circle_messages(2))


@pytest.mark.parametrize(
    "kwargs, topic, expected",
    [
        ({"odom_topic": "/odometry"}, "/odometry", r"not in the bag; expected the robot's odometry \(nav_msgs/msg/Odometry\); topics of that type here: /odom"),
        ({"odom_topic": "/mocap"}, "/mocap", r"has type geometry_msgs/msg/PoseStamped, expected the robot's odometry \(nav_msgs/msg/Odometry\)"),
        ({}, "(odometry)", r"no /fgslam/run_log topic .* name the odometry topic .*candidates: /odom"),
        ({"odom_topic": "/odom", "detections_topic": "/odom"}, "/odom", r"has type nav_msgs/msg/Odometry, expected tag detections \(apriltag_ros/msg/AprilTagDetectionArray or apriltag_msgs/msg/ApriltagArrayStamped\)"),
        ({"odom_topic": "/odom", "truth_topic": "/tag_detections"}, "/tag_detections", r"expected ground-truth poses"),
        ({"odom_topic": "/odom", "tag_pose_topic": "/tags/tag_"}, r"/tags/tag_<id>", r"expected one geometry_msgs/PoseStamped topic per tag"),
    ],
)
def test_missing_topic_or_wrong_type_names_the_topic(circle_bag, kwargs, topic, expected):
    with pytest.raises(BagFormatError, match=expected) as err:
        import_rosbag(circle_bag, **kwargs)
    assert str(err.value).startswith(f"{circle_bag}: topic {topic}: ")
    assert isinstance(err.value, DatasetFormatError) and err.value.topic == topic


def test_detections_without_a_pose_are_refused(tmp_path):
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import get_types_from_msg

    store = apriltag_typestore(2)
    store.register(get_types_from_msg("int32 id\nstring family\n", "apriltag_msgs/msg/AprilTagDetection"))
    store.register(get_types_from_msg("std_msgs/Header header\nAprilTagDetection[] detections\n",
                                      "apriltag_msgs/msg/AprilTagDetectionArray"))
    make = MessageFactory(store, 2)
    T = store.types
    with Writer(tmp_path / "b", version=8) as w:
        odom = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        det = w.add_connection("/detections", "apriltag_msgs/msg/AprilTagDetectionArray", typestore=store)
        w.write(odom, 1, make.serialize(make.odometry(1, (0.0, 0.0, 0.0))))
        msg = T["apriltag_msgs/msg/AprilTagDetectionArray"](
            header=make.header(2, "cam"), detections=[T["apriltag_msgs/msg/AprilTagDetection"](id=3, family="36h11")])
        w.write(det, 2, make.serialize(msg))
    with pytest.raises(BagFormatError, match=r"topic /detections message 1: .*has no detections\[\]\.pose.*tag_pose_topic"):
        import_rosbag(tmp_path / "b", odom_topic="/odom", detections_topic="/detections")


def test_a_run_log_topic_with_a_bad_line_names_the_message(tmp_path):
    store = apriltag_typestore(2)
    make = MessageFactory(store, 2)
    from rosbags.rosbag2 import Writer

    lines = OCTAGON.read_text().splitlines()[:4]
    assert lines[2].startswith('{"type": "truth_landmark"')
    lines[2] = lines[2].replace('"x_m"', '"xx_m"')
    with Writer(tmp_path / "b", version=8) as w:
        c = w.add_connection(RUN_LOG_TOPIC, "std_msgs/msg/String", typestore=store)
        for i, line in enumerate(lines):
            w.write(c, i, make.serialize(make.string(line)))
    with pytest.raises(BagFormatError, match=rf"topic {RUN_LOG_TOPIC} message 3: unknown field\(s\) xx_m"):
        import_rosbag(tmp_path / "b")


def test_paths_and_options(tmp_path, circle_bag, octagon_bag):
    with pytest.raises(FgslamError, match="no such file or folder"):
        import_rosbag(tmp_path / "missing.bag", odom_topic="/odom")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(FgslamError, match="not a ROS bag"):
        import_rosbag(tmp_path / "notes.txt", odom_topic="/odom")
    (tmp_path / "broken.bag").write_bytes(b"#ROSBAG V2.0\ngarbage")
    with pytest.raises(FgslamError, match="cannot read as a ROS 1 bag"):
        import_rosbag(tmp_path / "broken.bag", odom_topic="/odom")
    with pytest.raises(FgslamError, match="T_robot_camera must be a 4x4 rigid transform"):
        import_rosbag(circle_bag, odom_topic="/odom", T_robot_camera=np.ones((4, 4)))
    with pytest.raises(FgslamError, match="start_from='truth' needs a truth_topic"):
        import_rosbag(circle_bag, odom_topic="/odom", start_from="truth")
    with pytest.raises(FgslamError, match="already exists"):
        export_rosbag(OCTAGON, octagon_bag[0])
