"""A camera-only bag (tag detections, no odometry: 18 of TagSLAM's 21 test bags) is refused
with what is missing, what the bag has instead and what to do (slamio.datasets.rosbag_read.
no_odometry_error). The bags are written here with rosbags' own writer from the known circle
of tests/test_rosbag.py, its odometry left out."""

from __future__ import annotations

import pytest

from fgslam.cli import main
from slamio.datasets.rosbag import import_rosbag
from slamio.datasets.rosbag_read import BagFormatError
from tests.test_rosbag import circle_messages, write_bag


def test_a_camera_only_bag_is_refused_saying_what_is_missing_and_what_to_do(tmp_path, capsys):
    """18 of TagSLAM's 21 test bags have tag detections and no odometry."""
    bag = write_bag(tmp_path / "camera_only", 2, [m for m in circle_messages(2) if m[0] != "/odom"])
    for asked in (None, "/odom"):
        with pytest.raises(BagFormatError) as refused:
            import_rosbag(bag, odom_topic=asked, detections_topic="/tag_detections")
        text = str(refused.value)
        assert f"topic {asked or '(odometry)'}: " in text
        assert ("not in the bag, and " in text) == (asked is not None)
        assert "the bag has no odometry: no nav_msgs/msg/Odometry topic (it has camera topics /tag_detections: " \
               "a camera-only bag); its topics: /mocap, /tag_detections." in text
        assert "name it with --odom-topic; the pose topics here (/mocap) are not read as odometry" in text
        assert "'Camera-only bags'" in text
    out = tmp_path / "x.jsonl"
    code = main(["import", "rosbag", str(bag), str(out), "--odom-topic", "/odom", "--detections-topic", "/tag_detections"])
    assert code != 0 and "a camera-only bag" in capsys.readouterr().err and not out.exists()
    # a bag with odometry under another name still gets the short answer naming it
    odom_bag = write_bag(tmp_path / "with_odom", 2, [m for m in circle_messages(2) if m[0] == "/odom"])
    with pytest.raises(BagFormatError, match=r"topic /wheel_odom: not in the bag; expected the robot's odometry .*"
                                             r"topics of that type here: /odom"):
        import_rosbag(odom_bag, odom_topic="/wheel_odom")
