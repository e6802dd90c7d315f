"""Frames → observations: named rejections that never stop a run, and `fgslam detect` end to end."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest
from builders import minimal_header

from fgslam.detect_cli import DetectError, add_detect_parser, merge_observations
from slamio.camera.detect import REASONS, DetectionStats, FrontEnd, FrontEndConfig, FrontEndError, annotate
from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default, save_camera
from slamio.camera.render import CYLINDER_BGR, CylinderSpec, Scene, TagSpec, render
from slamio.camera.sources import Frame
from slamio.geometry import between_pose, wrap_angle
from slamio.log import Observation, Odometry, TruthPose, read_log, write_log

TAG_CAM = kinect_v1_default(T_robot_camera_from_mount(x_m=0.1, z_m=0.2))
KINECT = kinect_v1_default(T_robot_camera_from_mount(x_m=0.1, z_m=0.3))
CYLINDERS = (
    CylinderSpec(3.0, 0.0, 0.05, 0.4, CYLINDER_BGR["red"], "red", 0),
    CylinderSpec(2.5, 1.2, 0.05, 0.6, CYLINDER_BGR["green"], "green", 1),
    CylinderSpec(2.8, -1.0, 0.05, 0.8, CYLINDER_BGR["blue"], "blue", 2),
)
TAGS = (TagSpec(3, 2.0, 0.4, 0.2, math.pi, 0.16), TagSpec(9, 2.5, -0.6, 0.2, math.pi - 0.4, 0.16))


def _frame(bgr, depth=None, name="f", stamp=0.0, **kw):
    return Frame(stamp, 0, name, bgr, depth, **kw)


@pytest.fixture(scope="module")
def tag_front():
    return FrontEnd(TAG_CAM, FrontEndConfig(kind="apriltag", tag_size_m=0.16))


@pytest.fixture(scope="module")
def colour_front():
    return FrontEnd(KINECT, FrontEndConfig(kind="colour"))


def test_tags_become_observations_in_the_robot_frame(tag_front):
    frame = render(TAG_CAM, (0.0, 0.0, 0.0), Scene(tags=TAGS), supersample=3)
    result = tag_front.process(_frame(frame.bgr))
    assert not result.rejections
    by_id = {o.landmark_id: o for o in result.observations}
    assert sorted(by_id) == [3, 9]
    for tag in TAGS:
        o = by_id[tag.tag_id]
        assert o.range_m == pytest.approx(math.hypot(tag.x_m, tag.y_m), rel=0.02)
        assert o.bearing_rad == pytest.approx(math.atan2(tag.y_m, tag.x_m), abs=math.radians(0.5))
        assert abs(wrap_angle(o.tag_yaw_rad - tag.yaw_rad)) < math.radians(5)
        assert o.sigma_range_m > 0 and o.sigma_tag_yaw_rad > 0 and o.height_m is None


def test_cylinders_become_observations_with_height(colour_front):
    frame = render(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=CYLINDERS), supersample=2, depth_model="kinect")
    result = colour_front.process(_frame(frame.bgr, frame.depth_m))
    assert not result.rejections
    by_id = {o.landmark_id: o for o in result.observations}
    for cyl in CYLINDERS:
        o = by_id[cyl.landmark_id]
        assert o.range_m == pytest.approx(math.hypot(cyl.x_m, cyl.y_m), rel=0.02)
        assert o.bearing_rad == pytest.approx(math.atan2(cyl.y_m, cyl.x_m), abs=math.radians(0.5))
        assert o.height_m == pytest.approx(cyl.height_m, rel=0.03) and o.sigma_height_m > 0


def test_each_problem_is_a_named_reason_never_an_exception(tag_front, colour_front, tmp_path):
    stats = DetectionStats()
    empty = render(KINECT, (0.0, 0.0, 0.0), Scene(), supersample=1)
    bright = render(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=CYLINDERS), gain=4.0, supersample=1)
    scene = render(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=CYLINDERS), supersample=2)
    no_depth = np.full_like(scene.depth_m, np.nan)  # 0 mm or raw 2047 everywhere
    cases = [
        (colour_front, _frame(None, name="bad.png", error="bad.png: not a decodable image"), "corrupt_image"),
        (colour_front, _frame(bright.bgr, bright.depth_m), "over_exposed"),
        (colour_front, _frame(np.zeros_like(empty.bgr), empty.depth_m), "under_exposed"),
        (colour_front, _frame(empty.bgr, empty.depth_m), "no_landmark"),
        (tag_front, _frame(empty.bgr), "no_landmark"),
        (colour_front, _frame(scene.bgr, no_depth), "missing_depth"),
        (colour_front, _frame(scene.bgr, None), "no_depth_image"),
        (colour_front, _frame(scene.bgr, None, depth_error="d.png: not a decodable depth image"), "corrupt_depth"),
        (tag_front, _frame(scene.bgr[:240]), "wrong_image_size"),
    ]
    for front, frame, reason in cases:
        result = front.process(frame)
        stats.add(result)
        assert reason in {r.reason for r in result.rejections}, reason
        assert reason in REASONS
        assert not result.observations
        annotate(frame.bgr, result, front.camera)  # drawing never fails either
    assert stats.reasons["missing_depth"] == 3  # one per colour blob
    summary = stats.summary()
    for name in ("corrupt_image", "over_exposed", "no_landmark", "missing_depth"):
        assert name in summary
    assert summary.startswith("9 frames, 0 with observations")


def test_tag_filters_are_named(tmp_path):
    frame = render(TAG_CAM, (0.0, 0.0, 0.0), Scene(tags=TAGS), supersample=2).bgr
    only_3 = FrontEnd(TAG_CAM, FrontEndConfig(tag_size_m=0.16, tag_ids=frozenset({3})))
    assert {r.reason for r in only_3.process(_frame(frame)).rejections} == {"tag_not_allowed"}
    near = FrontEnd(TAG_CAM, FrontEndConfig(tag_size_m=0.16, max_range_m=2.2))
    result = near.process(_frame(frame))
    assert [o.landmark_id for o in result.observations] == [3]
    assert [r.reason for r in result.rejections] == ["out_of_range"]
    # a tag whose white margin is cut by the image's right border
    cut = render(TAG_CAM, (0.0, 0.0, 0.0), Scene(tags=(TagSpec(4, 0.6, -0.215, 0.2, math.pi, 0.16),)), supersample=2)
    assert [r.reason for r in near.process(_frame(cut.bgr)).rejections] == ["tag_at_image_border"]


def test_bad_configuration_is_a_user_error():
    with pytest.raises(FrontEndError):
        FrontEnd(TAG_CAM, FrontEndConfig(kind="lidar"))
    with pytest.raises(FrontEndError):
        FrontEnd(TAG_CAM, FrontEndConfig(tag_size_m=0.0))
    with pytest.raises(FrontEndError):
        FrontEnd(TAG_CAM, FrontEndConfig(tag_family="tag99h99"))
    with pytest.raises(FrontEndError, match="upsample"):
        FrontEnd(TAG_CAM, FrontEndConfig(tag_upsample=0.5))
    with pytest.raises(FrontEndError, match="second pass"):
        FrontEnd(TAG_CAM, FrontEndConfig(tag_second_pass="sift"))


def _obs(stamp, landmark_id=0):
    return Observation(stamp, landmark_id, 1.0, 0.0, 0.01, 0.01)


def _odo(stamp):
    return Odometry(stamp, 0.1, 0.0, 0.0, ((1e-4, 0, 0), (0, 1e-4, 0), (0, 0, 1e-4)))


def test_merge_puts_observations_into_the_pose_of_their_time():
    header = minimal_header(stamp_s=10.0)
    records = [TruthPose(10.0, 0, 0, 0), _odo(11.0), TruthPose(11.0, 0.1, 0, 0), _odo(12.0), _obs(12.5, 7)]
    frames = [(9.0, [_obs(9.0)]), (10.02, [_obs(10.02, 1)]), (11.01, [_obs(11.01, 2), _obs(11.01, 3)]),
              (11.5, [_obs(11.5, 4)]), (12.01, [_obs(12.01, 5)]), (12.0, [])]
    merged, dropped = merge_observations(header, records, frames, max_pose_gap_s=0.05)
    assert dropped == {"no_pose_at_frame_time": 1, "before_log_start": 1}
    ids = [(type(r).__name__, getattr(r, "landmark_id", None)) for r in merged]
    assert ids == [("TruthPose", None), ("Observation", 1), ("Odometry", None), ("TruthPose", None),
                   ("Observation", 2), ("Observation", 3), ("Odometry", None), ("Observation", 5),
                   ("Observation", 7)]
    stamps = [r.stamp_s for r in merged]
    assert stamps == sorted(stamps)


# --------------------------------------------------------------------------- the CLI


def _run(argv):
    parser = argparse.ArgumentParser(prog="fgslam")
    verbs = parser.add_subparsers(dest="verb", required=True)
    add_detect_parser(verbs)
    args = parser.parse_args(argv)
    args.argv = argv
    return args.func(args)


def _recorded_run(tmp_path, camera_clock_s: float = 0.0):
    """A robot driving towards the cylinders: a run log with odometry at every camera frame,
    and a TUM RGB-D folder of what the Kinect saw (one frame corrupt, one with no pose).
    The camera's clock reads ``camera_clock_s`` more than the log's."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    import cv2

    poses = [(0.0, 0.0, 0.0), (0.3, 0.0, 0.05), (0.6, 0.05, 0.1), (0.9, 0.1, 0.1)]
    stamps = [0.0, 0.5, 1.0, 1.5]
    header = minimal_header(stamp_s=0.0)
    records = [TruthPose(0.0, *poses[0])]
    for k in range(1, len(poses)):
        dx, dy, dth = between_pose(poses[k - 1], poses[k])
        records += [Odometry(stamps[k], dx, dy, dth, ((1e-4, 0, 0), (0, 1e-4, 0), (0, 0, 1e-4))),
                    TruthPose(stamps[k], *poses[k])]
    log = tmp_path / "run.jsonl"
    write_log(log, header, records)
    frames = tmp_path / "frames"
    (frames / "rgb").mkdir(parents=True)
    (frames / "depth").mkdir()
    rgb_lines, depth_lines = [], []
    frame_stamps = stamps + [1.8]  # the last frame comes 0.3 s after the last odometry: no pose
    for k, stamp in enumerate(frame_stamps):
        pose = poses[min(k, len(poses) - 1)]
        image = render(KINECT, pose, Scene(cylinders=CYLINDERS), supersample=2, depth_model="kinect")
        camera_stamp = stamp + camera_clock_s
        name = f"{camera_stamp:.6f}.png"
        cv2.imwrite(str(frames / "rgb" / name), image.bgr)
        depth = np.nan_to_num(image.depth_m * 5000.0, nan=0.0).round().astype(np.uint16)
        cv2.imwrite(str(frames / "depth" / name), depth)
        rgb_lines.append(f"{camera_stamp:.6f} rgb/{name}")
        depth_lines.append(f"{camera_stamp + 0.004:.6f} depth/{name}")
    (frames / "rgb" / "corrupt.png").write_bytes(b"garbage, not a png")
    rgb_lines.append(f"{0.7 + camera_clock_s:.6f} rgb/corrupt.png")
    (frames / "rgb.txt").write_text("# timestamp filename\n" + "\n".join(rgb_lines) + "\n")
    (frames / "depth.txt").write_text("# timestamp filename\n" + "\n".join(depth_lines) + "\n")
    camera = tmp_path / "kinect.yaml"
    save_camera(camera, KINECT)
    return log, frames, camera, poses


def test_detect_adds_cylinders_to_a_recorded_run(tmp_path, capsys):
    log, frames, camera, poses = _recorded_run(tmp_path)
    show = tmp_path / "shown"
    argv = ["detect", str(frames), "--camera", str(camera), "--out", str(log), "--kind", "colour",
            "--show", str(show), "--max-pose-gap", "0.1"]
    assert _run(argv) == 0
    printed = capsys.readouterr().out
    assert "corrupt_image" in printed and "no_pose_at_frame_time" in printed
    run = read_log(log)  # still a valid log
    steps = run.steps()
    assert len(steps) == 4
    world = {c.landmark_id: (c.x_m, c.y_m, c.height_m) for c in CYLINDERS}
    for step, pose in zip(steps, poses):
        seen = set()
        for o in step.observations:
            x, y, h = world[o.landmark_id]
            dx, dy, _ = between_pose(pose, (x, y, 0.0))
            assert o.stamp_s == step.stamp_s
            assert o.range_m == pytest.approx(math.hypot(dx, dy), rel=0.02)
            assert o.bearing_rad == pytest.approx(math.atan2(dy, dx), abs=math.radians(0.5))
            assert o.height_m == pytest.approx(h, rel=0.03)
            seen.add(o.landmark_id)
        for landmark_id, (x, y, _) in world.items():  # every cylinder well inside the view was seen
            dx, dy, _ = between_pose(pose, (x, y, 0.0))
            if abs(math.atan2(dy, dx)) < math.radians(25):
                assert landmark_id in seen
    assert run.header.source["detect"][0]["rejected"]["corrupt_image"] == 1
    assert len(list(show.glob("*.png"))) == 6


def test_detect_static_tags_into_a_new_log(tmp_path, capsys):
    import cv2

    folder = tmp_path / "tags"
    folder.mkdir()
    for k in range(3):
        image = render(TAG_CAM, (0.0, 0.0, 0.0), Scene(tags=TAGS), supersample=2)
        cv2.imwrite(str(folder / f"frame_{k}.png"), image.bgr)
    camera = tmp_path / "cam.yaml"
    save_camera(camera, TAG_CAM)
    out = tmp_path / "still.jsonl"
    with pytest.raises(DetectError, match="--static"):
        _run(["detect", str(folder), "--camera", str(camera), "--out", str(out)])
    assert _run(["detect", str(folder), "--camera", str(camera), "--out", str(out), "--static",
                 "--fps", "10", "--tag-size", "0.16"]) == 0
    run = read_log(out)
    (step,) = run.steps()
    assert sorted(o.landmark_id for o in step.observations) == [3, 3, 3, 9, 9, 9]
    assert run.header.robot["name"].startswith("static camera")
    assert "6 observations added" in capsys.readouterr().out


def test_detect_user_errors(tmp_path):
    camera = tmp_path / "cam.yaml"
    save_camera(camera, TAG_CAM)
    from slamio.camera.sources import FrameSourceError

    with pytest.raises(FrameSourceError):
        _run(["detect", str(tmp_path / "none"), "--camera", str(camera), "--out", str(tmp_path / "o.jsonl"),
              "--static"])
    with pytest.raises(DetectError, match="--tag-size"):
        _run(["detect", str(tmp_path), "--camera", str(camera), "--out", str(tmp_path / "o.jsonl"),
              "--static", "--tag-size", "-1"])
    with pytest.raises(DetectError, match="is a number"):
        _run(["detect", "kinect:front", "--camera", str(camera), "--out", str(tmp_path / "o.jsonl"), "--static"])


def test_detect_records_its_runs_in_the_header(tmp_path):
    log, frames, camera, _ = _recorded_run(tmp_path)
    argv = ["detect", str(frames), "--camera", str(camera), "--out", str(log), "--kind", "colour"]
    assert _run(argv) == 0
    runs = read_log(log).header.source["detect"]
    assert len(runs) == 1 and runs[0]["kind"] == "colour" and runs[0]["frames"] == 6
    rejected = runs[0]["rejected"]
    assert rejected["corrupt_image"] == 1 and rejected["no_pose_at_frame_time"] == 1
    assert set(rejected) <= {"corrupt_image", "no_pose_at_frame_time", "blob_at_image_border"}
    assert runs[0]["noise"]["sigma_height_m"] == 0.02


def test_detect_reads_the_landmark_file(tmp_path):
    from slamio.camera.colour import DEFAULT_COLOURS, ColourOptions
    from slamio.camera.landmark_file import save_landmarks

    log, frames, camera, _ = _recorded_run(tmp_path)
    only_red = tmp_path / "red.yaml"
    save_landmarks(only_red, ColourOptions(colours=DEFAULT_COLOURS[:1]))
    with pytest.raises(DetectError, match="--kind colour"):
        _run(["detect", str(frames), "--camera", str(camera), "--out", str(log), "--landmarks", str(only_red)])
    assert _run(["detect", str(frames), "--camera", str(camera), "--out", str(log), "--kind", "colour",
                 "--landmarks", str(only_red)]) == 0
    run = read_log(log)
    assert {o.landmark_id for step in run.steps() for o in step.observations} == {0}
    assert [c["name"] for c in run.header.source["detect"][0]["landmarks"]["landmarks"]] == ["red"]


def _observations(log):
    return [(o.stamp_s, o.landmark_id, round(o.range_m, 9)) for o in read_log(log).records
            if isinstance(o, Observation)]


def test_detect_refuses_to_add_observations_twice_and_replaces_them_on_request(tmp_path, capsys):
    log, frames, camera, _ = _recorded_run(tmp_path)
    argv = ["detect", str(frames), "--camera", str(camera), "--out", str(log), "--kind", "colour",
            "--max-pose-gap", "0.1"]
    assert _run(argv) == 0
    first = _observations(log)
    others = [r for r in read_log(log).records if not isinstance(r, Observation)]
    assert len(first) >= 6
    with pytest.raises(DetectError, match=r"already has \d+ observations .*--replace") as error:
        _run(argv)
    assert "\n" not in str(error.value)
    assert _observations(log) == first  # untouched
    capsys.readouterr()
    assert _run(argv + ["--replace"]) == 0
    assert f"({len(first)} earlier ones removed)" in capsys.readouterr().out
    run = read_log(log)
    assert _observations(log) == first  # the same observations, once
    assert [r for r in run.records if not isinstance(r, Observation)] == others  # odometry and truth kept
    runs = run.header.source["detect"]
    assert len(runs) == 2 and runs[0]["observations_removed"] and runs[1]["replaced_observations"] == len(first)


def test_detect_puts_frames_on_the_log_clock_with_a_time_offset(tmp_path, capsys):
    reference = tmp_path / "reference"
    log, frames, camera, _ = _recorded_run(reference)
    common = ["--camera", str(camera), "--kind", "colour", "--max-pose-gap", "0.1"]
    assert _run(["detect", str(frames), "--out", str(log)] + common) == 0
    expected = _observations(log)
    epoch = 1_700_000_000.25  # a camera whose files are named by the wall clock
    shifted = tmp_path / "shifted"
    log, frames, camera, _ = _recorded_run(shifted, camera_clock_s=epoch)
    capsys.readouterr()
    assert _run(["detect", str(frames), "--out", str(log)] + common) == 0
    printed = capsys.readouterr().out
    assert "0 observations added" in printed and "different clocks" in printed and f"{-epoch:+.3f}" in printed
    for offset in (str(-epoch), "start"):
        log, frames, camera, _ = _recorded_run(tmp_path / f"run{offset}", camera_clock_s=epoch)
        assert _run(["detect", str(frames), "--out", str(log), "--time-offset", offset] + common) == 0
        got = _observations(log)
        assert [(i, r) for _, i, r in got] == [(i, r) for _, i, r in expected]
        assert np.allclose([t for t, _, _ in got], [t for t, _, _ in expected], atol=1e-6)
        assert read_log(log).header.source["detect"][0]["time_offset_s"] == pytest.approx(-epoch)
    with pytest.raises(DetectError, match="--time-offset must be seconds"):
        _run(["detect", str(frames), "--out", str(log), "--replace", "--time-offset", "soon"] + common)


def test_merge_treats_stamps_a_microsecond_apart_as_the_same_instant():
    header = minimal_header(stamp_s=10.0)
    records = [_odo(11.0 + 1e-7)]  # the log keeps every digit; a frame file name keeps six
    merged, dropped = merge_observations(header, records, [(11.0, [_obs(11.0, 4)])], max_pose_gap_s=0.05)
    assert dropped == {"no_pose_at_frame_time": 0, "before_log_start": 0}
    assert isinstance(merged[0], Odometry) and merged[1].stamp_s == 11.0 + 1e-7
