"""`fgslam detect`: user-facing faults found by a QA pass, each a one-line error (exit 1, nothing
written) or a clear summary line. Real photos: the pupil-labs robot-camera frames shipped in
tests/data/apriltag-photos (640×480, known intrinsics, 0.065 m tag36h11 tags)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from builders import minimal_header

from fgslam.cli import main
from fgslam.cli.detect_checks import TAG_FAMILY_IDS, parse_tag_ids
from slamio.camera.model import CameraConfigError, load_camera
from slamio.log import Observation, Odometry, read_log, write_log

PHOTOS = Path(__file__).resolve().parent / "data" / "apriltag-photos"
PUPIL_IDS = {1: [22, 24, 58, 85, 144, 198]}  # tags on pupil_test_image_multiple_01.png (checked by a run)
CAMERA_YAML = """\
image_width: 640
image_height: 480
camera_name: pupil
camera_matrix: {{rows: 3, cols: 3, data: [338.563277422543, 0, {cx}, 0, 338.939280638548, {cy}, 0, 0, 1]}}
distortion_model: plumb_bob
distortion_coefficients: {{rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}}
"""


def _camera(tmp_path, cx=336.45495347495824, cy=230.486982216255, name="pupil.yaml") -> Path:
    path = tmp_path / name
    path.write_text(CAMERA_YAML.format(cx=cx, cy=cy))
    return path


def _photo(k: int = 1) -> Path:
    return PHOTOS / f"pupil_test_image_multiple_{k:02d}.png"


def _frames(tmp_path, sizes=((640, 480),), name="frames") -> Path:
    """A folder of pupil photos named by their stamps (0.00, 0.01, ... s), each resized to its size."""
    import cv2

    folder = tmp_path / name
    folder.mkdir()
    for k, size in enumerate(sizes):
        image = cv2.imread(str(_photo(k + 1)))
        if size != (640, 480):
            image = cv2.resize(image, size)
        cv2.imwrite(str(folder / f"{0.01 * k:.6f}.png"), image)
    return folder


def _recorded_log(tmp_path, name="run.jsonl") -> Path:
    """A run log whose pose 0 (stamp 0) covers the frames at 0.00 and 0.01 s, then one odometry record."""
    log = tmp_path / name
    write_log(log, minimal_header(stamp_s=0.0),
              [Odometry(1.0, 0.1, 0.0, 0.0, ((1e-4, 0, 0), (0, 1e-4, 0), (0, 0, 1e-4)))])
    return log


def _detect(capsys, *argv) -> tuple[int, str, str]:
    status = main(["detect", *map(str, argv)])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def _rejection(stdout: str, reason: str) -> tuple[str, str]:
    """The summary's line of one rejection and the detail line under it."""
    lines = stdout.splitlines()
    at = next(i for i, line in enumerate(lines) if f"× {reason}" in line)
    return lines[at], lines[at + 1]


def _one_error(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fgslam: error: "), err
    return lines[0]


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# --------------------------------------------------------------------------- 1. the log's mode


@pytest.fixture
def umask():
    def set_to(mask: int) -> None:
        os.umask(mask)
    old = os.umask(0o022)
    os.umask(old)
    yield set_to
    os.umask(old)


@pytest.mark.parametrize("mode", [0o644, 0o640, 0o664])
def test_a_rewritten_log_keeps_its_permission_bits(tmp_path, capsys, umask, mode):
    frames = _frames(tmp_path)
    camera = _camera(tmp_path)
    log = _recorded_log(tmp_path)
    log.chmod(mode)
    umask(0o077)  # neither the umask nor a temporary file's 0600 may decide the mode of the user's log
    status, out, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065", "--out", log)
    assert status == 0, err
    assert "observations added" in out
    assert (log.stat().st_mode & 0o7777) == mode
    assert any(isinstance(r, Observation) for r in read_log(log).records)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_a_new_static_log_gets_the_umask_mode(tmp_path, capsys, umask):
    frames = _frames(tmp_path)
    camera = _camera(tmp_path)
    umask(0o022)
    plain = tmp_path / "plain"
    plain.write_text("")
    out = tmp_path / "still.jsonl"
    status, _, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065", "--out", out, "--static")
    assert status == 0, err
    assert (out.stat().st_mode & 0o7777) == (plain.stat().st_mode & 0o7777) == 0o644


# --------------------------------------------------------------------------- 2. image size


def test_every_frame_of_another_size_is_an_error_naming_both_sizes(tmp_path, capsys):
    frames = _frames(tmp_path, sizes=((320, 240), (320, 240)))
    camera = _camera(tmp_path)
    out, show = tmp_path / "still.jsonl", tmp_path / "shown" / "deep"
    before = _listing(tmp_path)
    status, stdout, err = _detect(capsys, frames, "--camera", camera, "--out", out, "--static", "--show", show)
    assert status == 1
    line = _one_error(err)
    assert "320×240" in line and "640×480" in line and str(camera) in line
    assert "camera file calibrated for these images" in line and "nothing was written" in line
    assert not out.exists() and not (tmp_path / "shown").exists()  # nor the --show frames and folders
    assert _listing(tmp_path) == before and "wrote" not in stdout


def test_every_frame_of_another_size_leaves_a_recorded_log_alone(tmp_path, capsys):
    frames = _frames(tmp_path, sizes=((800, 600),))
    camera = _camera(tmp_path)
    log = _recorded_log(tmp_path)
    content = log.read_bytes()
    status, _, err = _detect(capsys, frames, "--camera", camera, "--out", log)
    assert status == 1
    line = _one_error(err)
    assert "800×600" in line and "640×480" in line
    assert log.read_bytes() == content


def test_colour_depth_of_another_size_is_named_as_depth(tmp_path, capsys):
    import cv2

    frames = tmp_path / "tum"
    (frames / "rgb").mkdir(parents=True)
    (frames / "depth").mkdir()
    shutil.copy(_photo(1), frames / "rgb" / "0.000000.png")
    cv2.imwrite(str(frames / "depth" / "0.000000.png"), np.full((240, 320), 5000, dtype=np.uint16))
    camera = _camera(tmp_path)
    out = tmp_path / "still.jsonl"
    status, _, err = _detect(capsys, frames, "--camera", camera, "--out", out, "--static", "--kind", "colour")
    assert status == 1
    line = _one_error(err)
    assert "depth images 320×240" in line and "640×480" in line and not out.exists()


def test_some_frames_of_another_size_are_named_in_the_summary(tmp_path, capsys):
    frames = _frames(tmp_path, sizes=((640, 480), (320, 240)))
    camera = _camera(tmp_path)
    out = tmp_path / "still.jsonl"
    status, stdout, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065", "--out", out, "--static")
    assert status == 0, err
    _, detail = _rejection(stdout, "wrong_image_size")
    assert "320×240" in detail and "640×480" in detail and "0.010000.png" in detail and str(camera) in detail
    assert read_log(out).header.source["detect"][0]["rejected"]["wrong_image_size"] == 1


# --------------------------------------------------------------------------- 3. --tag-ids rejects every tag


def test_tag_ids_that_leave_out_every_tag_found_are_an_error_naming_the_ids_seen(tmp_path, capsys):
    frames = _frames(tmp_path)
    camera = _camera(tmp_path)
    log = _recorded_log(tmp_path)
    content = log.read_bytes()
    show = tmp_path / "shown"
    status, stdout, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065", "--out", log,
                                  "--tag-ids", "500,501", "--show", show)
    assert status == 1
    line = _one_error(err)
    assert "--tag-ids 500,501" in line and "none of the tags found" in line
    assert ", ".join(map(str, PUPIL_IDS[1])) in line and "tag36h11" in line
    assert "nothing was written" in line
    assert log.read_bytes() == content and not show.exists()


def test_tag_ids_that_leave_out_some_tags_name_them_in_the_summary(tmp_path, capsys):
    frames = _frames(tmp_path)
    camera = _camera(tmp_path)
    out = tmp_path / "still.jsonl"
    status, stdout, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065", "--out", out,
                                  "--static", "--tag-ids", "22,24")
    assert status == 0, err
    assert "ids seen that --tag-ids leaves out: 58, 85, 144, 198" in stdout
    assert {o.landmark_id for o in read_log(out).records if isinstance(o, Observation)} <= {22, 24}


# --------------------------------------------------------------------------- 4. --tag-ids values


@pytest.mark.parametrize("ids, expected", [
    ("-1", "a tag id is 0 or more; got -1"),
    ("3,-7", "got -7"),
    ("99999", "tag36h11 has 587 tags, ids 0..586; 99999"),
    ("587", "ids 0..586; 587"),
    ("1,,2", "'1,,2' has an empty item"),
    ("1,2,", "has an empty item"),
    ("", "has an empty item"),
    ("1,two", "'two' in '1,two' is not"),
])
def test_bad_tag_ids_are_refused_before_anything_is_read(tmp_path, capsys, ids, expected):
    frames = _frames(tmp_path)
    out = tmp_path / "still.jsonl"
    # the camera file does not even exist: the option is checked first
    status, _, err = _detect(capsys, frames, "--camera", tmp_path / "none.yaml", "--out", out, "--static",
                             f"--tag-ids={ids}")
    assert status == 1
    line = _one_error(err)
    assert "--tag-ids" in line and expected in line
    assert not out.exists()


def test_tag_ids_range_follows_the_family():
    with pytest.raises(Exception, match=r"tag16h5 has 30 tags, ids 0\.\.29; 30"):
        parse_tag_ids("30", "tag16h5")
    assert parse_tag_ids("0, 29", "tag16h5") == frozenset({0, 29})
    assert parse_tag_ids("586", "tag36h11") == frozenset({586})
    assert parse_tag_ids(None, "tag36h11") is None


def test_family_sizes_agree_with_opencv():
    import cv2

    from slamio.camera.apriltag import ARUCO_DICTIONARIES

    for family, dictionary in ARUCO_DICTIONARIES.items():
        assert len(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)).bytesList) == \
            TAG_FAMILY_IDS[family]


# --------------------------------------------------------------------------- 5. the principal point


@pytest.mark.parametrize("cx, cy, named", [(3364.5, 230.49, "cx = 3364.5"), (336.45, -12.0, "cy = -12"),
                                           (640.0, 230.49, "cx = 640")])
def test_a_principal_point_outside_the_image_is_refused(tmp_path, capsys, cx, cy, named):
    camera = _camera(tmp_path, cx=cx, cy=cy, name="cam_cx.yaml")
    with pytest.raises(CameraConfigError) as error:
        load_camera(camera)
    message = str(error.value)
    assert str(camera) in message and named in message and "640×480" in message
    frames = _frames(tmp_path)
    out = tmp_path / "still.jsonl"
    status, _, err = _detect(capsys, frames, "--camera", camera, "--out", out, "--static")
    assert status == 2  # an input file that cannot be used
    line = _one_error(err)
    assert str(camera) in line and named in line and "principal point" in line
    assert not out.exists()


def test_a_principal_point_inside_the_image_is_accepted(tmp_path):
    assert load_camera(_camera(tmp_path)).K[0, 2] == pytest.approx(336.45495347495824)
    assert load_camera(_camera(tmp_path, cx=0.0, cy=479.0, name="edge.yaml")).K[1, 2] == 479.0


# --------------------------------------------------------------------------- 6. --static with a log


def test_static_with_an_existing_log_is_refused(tmp_path, capsys):
    frames = _frames(tmp_path)
    camera = _camera(tmp_path)
    log = _recorded_log(tmp_path)
    content = log.read_bytes()
    status, _, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065", "--out", log, "--static")
    assert status == 1
    line = _one_error(err)
    assert "--static" in line and str(log) in line and "already exists" in line and "leave out --static" in line
    assert log.read_bytes() == content


# --------------------------------------------------------------------------- 7. --show in FRAMES


@pytest.mark.parametrize("inside", ["", "shown", "shown/deeper"])
def test_show_in_the_frame_folder_is_refused(tmp_path, capsys, inside):
    frames = _frames(tmp_path)
    camera = _camera(tmp_path)
    out = tmp_path / "still.jsonl"
    before = _listing(tmp_path)
    show = frames / inside if inside else frames
    status, _, err = _detect(capsys, frames, "--camera", camera, "--out", out, "--static", "--show", show)
    assert status == 1
    line = _one_error(err)
    assert f"--show {show}" in line and "frame folder" in line and "outside" in line
    assert _listing(tmp_path) == before


def test_show_outside_the_frame_folder_is_written(tmp_path, capsys):
    frames = _frames(tmp_path)
    camera = _camera(tmp_path)
    show = tmp_path / "shown"
    status, _, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065",
                             "--out", tmp_path / "still.jsonl", "--static", "--show", show)
    assert status == 0, err
    assert len(list(show.glob("*.png"))) == 1 and len(list(frames.iterdir())) == 1


# --------------------------------------------------------------------------- 8. unreadable files named


def test_corrupt_and_missing_images_are_named_in_the_summary(tmp_path, capsys):
    frames = _frames(tmp_path)
    for k, content in enumerate([b"garbage, not a png", b"", b"\x89PNG\r\n\x1a\n cut", b"more garbage"]):
        (frames / f"{1 + k:.6f}.png").write_bytes(content)
    camera = _camera(tmp_path)
    out = tmp_path / "still.jsonl"
    status, stdout, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065", "--out", out, "--static")
    assert status == 0, err
    line, detail = _rejection(stdout, "corrupt_image")
    assert "4 × corrupt_image" in line
    assert detail.strip().startswith("first: 1.000000.png (not a decodable image")
    assert "2.000000.png (empty file)" in detail and "3.000000.png" in detail
    assert "4.000000.png" not in detail  # the first few only
    assert str(tmp_path) not in detail  # the frame's name, not its whole path again


def test_not_one_readable_image_is_an_error_naming_the_files(tmp_path, capsys):
    frames = tmp_path / "broken"
    frames.mkdir()
    for k in range(3):
        (frames / f"{k:.6f}.png").write_bytes(b"garbage, not a png")
    out = tmp_path / "still.jsonl"
    status, _, err = _detect(capsys, frames, "--camera", _camera(tmp_path), "--out", out, "--static")
    assert status == 1
    line = _one_error(err)
    assert "none of the 3 images could be read" in line and "0.000000.png (not a decodable image" in line
    assert not out.exists()


def test_a_missing_file_in_a_tum_list_is_named(tmp_path, capsys):
    frames = tmp_path / "tum"
    (frames / "rgb").mkdir(parents=True)
    shutil.copy(_photo(1), frames / "rgb" / "0.000000.png")
    (frames / "rgb.txt").write_text("0.000000 rgb/0.000000.png\n0.010000 rgb/gone.png\n")
    camera = _camera(tmp_path)
    status, stdout, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065",
                                  "--out", tmp_path / "still.jsonl", "--static")
    assert status == 0, err
    assert "first: rgb/gone.png (cannot read" in stdout


def test_the_log_states_the_camera_mount_its_detections_were_placed_from(tmp_path, capsys):
    frames, camera, log = _frames(tmp_path), _camera(tmp_path), _recorded_log(tmp_path)
    status, _, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065", "--out", log)
    assert status == 0, err
    sensor = read_log(log).header.sensor
    assert len(sensor["T_robot_camera"]) == 4 and "robot's centre" in sensor["readings_at"]
    assert "pose_on_robot" not in sensor


def test_a_log_whose_readings_are_a_sensors_own_is_refused_before_detecting(tmp_path, capsys):
    from dataclasses import replace

    frames, camera = _frames(tmp_path), _camera(tmp_path)
    log = tmp_path / "mounted.jsonl"
    header = minimal_header(stamp_s=0.0)
    write_log(log, replace(header, sensor={**header.sensor, "pose_on_robot": [0.2, 0.0, 0.0]}),
              [Odometry(1.0, 0.1, 0.0, 0.0, ((1e-4, 0, 0), (0, 1e-4, 0), (0, 0, 1e-4)))])
    content = log.read_bytes()
    status, _, err = _detect(capsys, frames, "--camera", camera, "--tag-size", "0.065", "--out", log)
    assert status == 1
    assert "sensor.pose_on_robot [0.2, 0.0, 0.0]" in _one_error(err) and log.read_bytes() == content


# --------------------------------------------------------------------------- 9. a Kalibr camera file

KALIBR_YAML = """\
cam0:
  camera_model: pinhole
  intrinsics: [500.0, 500.0, 320.0, 240.0]
  distortion_model: none
  distortion_coeffs: []
  resolution: [640, 480]
cam1:
  camera_model: pinhole
  intrinsics: [338.563277422543, 338.939280638548, 336.45495347495824, 230.486982216255]
  distortion_model: radtan
  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]
  resolution: [640, 480]
"""


def test_a_kalibr_camera_file_detects_as_its_camera_info_twin(tmp_path, capsys):
    """detect reads a Kalibr cameras.yaml (camera chosen with --camera-name) through the same
    reader as import rosbag: the same tags at the same ranges as the equal camera_info file."""
    frames = _frames(tmp_path)
    kalibr = tmp_path / "cameras.yaml"
    kalibr.write_text(KALIBR_YAML)
    results = []
    for name, camera in (("info", ["--camera", _camera(tmp_path)]),
                         ("kalibr", ["--camera", kalibr, "--camera-name", "cam1"])):
        out = tmp_path / f"{name}.jsonl"
        status, _, err = _detect(capsys, frames, *camera, "--tag-size", "0.065", "--out", out, "--static")
        assert status == 0, err
        results.append(sorted((o.landmark_id, o.range_m, o.bearing_rad)
                              for o in read_log(out).records if isinstance(o, Observation)))
    assert [r[0] for r in results[0]] == PUPIL_IDS[1]
    np.testing.assert_allclose(np.array(results[1]), np.array(results[0]), rtol=1e-9, atol=1e-12)
    status, _, err = _detect(capsys, frames, "--camera", kalibr, "--tag-size", "0.065",
                             "--out", tmp_path / "two.jsonl", "--static")
    assert status == 2 and "cam0, cam1" in err and "--camera-name" in err
