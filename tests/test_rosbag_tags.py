"""Real bags as they come (issue 45): tag corners → observations, camera and tags files,
levelling, and TagSLAM's public test_22 bags end to end against TagSLAM's own trajectory."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slamio.camera.camera_files import camera_from_kalibr, load_camera_file
from slamio.camera.model import CameraConfigError, CameraModel
from slamio.datasets.rosbag_corners import corner_observation
from slamio.datasets.rosbag_level import levelling_rotation
from slamio.datasets.rosbag_messages import T_ROBOT_OPTICAL
from slamio.datasets.tagslam_files import load_camera_poses, load_tags_file, rotation_from_rotvec
from slamio.errors import InputFileError

DATA = Path(__file__).parent / "data" / "rosbag-tagslam-test_22"
ROOT = Path(__file__).parent.parent


def fisheye() -> CameraModel:
    """test_22's T265 fisheye (cameras.yaml's numbers)."""
    K = np.array([[283.943, 0, 421.079], [0, 284.986, 400.527], [0, 0, 1.0]])
    return CameraModel(800, 848, K, np.array([0.00132, 0.03049, -0.02875, 0.0034]), "equidistant")


def mit_corners(camera: CameraModel, range_m: float, bearing_rad: float, size_m: float, turn_rad: float = 0.3):
    """The corners the MIT detector reports (tag frame (-s,-s), (s,-s), (s,s), (-s,s)/2: BL, BR,
    TR, TL) of an upright tag on the floor plane at (range, bearing) from the camera, its face
    turned ``turn_rad`` from facing the camera; and its tag yaw in the robot frame."""
    centre = np.array([range_m * math.cos(bearing_rad), range_m * math.sin(bearing_rad), 0.0])  # robot frame
    yaw = bearing_rad + math.pi + turn_rad  # the face normal, pointing back at the camera (turned)
    z = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    y = np.array([0.0, 0.0, 1.0])
    x = np.cross(y, z)
    h = size_m / 2
    pts = [centre + a * h * x + b * h * y for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    R, t = T_ROBOT_OPTICAL[:3, :3], T_ROBOT_OPTICAL[:3, 3]
    cam = np.array([R.T @ (p - t) for p in pts])
    return camera.project(cam), yaw


@pytest.mark.parametrize("bearing", [-0.8, 0.0, 0.5])
def test_mit_corner_order_gives_the_tag_back(bearing):
    camera = fisheye()
    corners, yaw = mit_corners(camera, 3.0, bearing, 0.42)
    seen = corner_observation(corners, 0.42, camera, T_ROBOT_OPTICAL, 1.0)
    assert seen.range_m == pytest.approx(3.0, abs=1e-5)
    assert seen.bearing_rad == pytest.approx(bearing, abs=1e-6)
    assert math.remainder(seen.tag_yaw_rad - yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-4)
    assert seen.height_m == pytest.approx(0.0, abs=1e-5)
    assert seen.reprojection_px < 1e-3


def test_mirrored_or_damaged_corners_are_refused():
    camera = fisheye()
    corners, _ = mit_corners(camera, 3.0, 0.2, 0.42)
    assert corner_observation(corners[[1, 0, 3, 2]], 0.42, camera, T_ROBOT_OPTICAL, 1.0) == "facing_away"
    damaged = corners.copy()
    damaged[0] += (25.0, -10.0)
    assert corner_observation(damaged, 0.42, camera, T_ROBOT_OPTICAL, 1.0) == "reprojection"


def test_range_sigma_grows_with_the_square_of_the_distance_and_matches_monte_carlo():
    camera = fisheye()
    sig = {}
    for r in (2.0, 4.0):
        corners, _ = mit_corners(camera, r, 0.1, 0.42, turn_rad=0.5)
        sig[r] = corner_observation(corners, 0.42, camera, T_ROBOT_OPTICAL, 1.0)
    assert sig[4.0].sigma_range_m / sig[2.0].sigma_range_m == pytest.approx(4.0, rel=0.15)
    assert sig[4.0].sigma_bearing_rad == pytest.approx(sig[2.0].sigma_bearing_rad, rel=0.15)  # about σ_px / f
    # the propagated σ against the spread of poses solved from seeded noisy corners
    rng = np.random.default_rng(7)
    corners, _ = mit_corners(camera, 3.0, 0.1, 0.42, turn_rad=0.5)
    predicted = corner_observation(corners, 0.42, camera, T_ROBOT_OPTICAL, 0.5)
    ranges, bearings = [], []
    for _ in range(400):
        seen = corner_observation(corners + rng.normal(0, 0.5, corners.shape), 0.42, camera, T_ROBOT_OPTICAL, 0.5)
        if abs(math.remainder(seen.tag_yaw_rad - predicted.tag_yaw_rad, 2 * math.pi)) > 0.3:
            continue  # the other IPPE solution (the flip): a different pose, not spread around this one
        ranges.append(seen.range_m)
        bearings.append(seen.bearing_rad)
    assert len(ranges) > 200
    assert np.std(ranges) == pytest.approx(predicted.sigma_range_m, rel=0.2)
    assert np.std(bearings) == pytest.approx(predicted.sigma_bearing_rad, rel=0.2)


def test_kalibr_file_of_test_22():
    cam = load_camera_file(DATA / "cameras.yaml")
    assert (cam.width_px, cam.height_px, cam.distortion_model) == (800, 848, "equidistant")
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (283.943, 284.986, 421.079, 400.527)
    assert list(cam.dist_coeffs) == [0.00132, 0.03049, -0.02875, 0.0034]
    with pytest.raises(CameraConfigError, match="no camera 'cam1'.*cam0"):
        load_camera_file(DATA / "cameras.yaml", "cam1")


@settings(max_examples=40, deadline=None)
@given(f=st.floats(50, 2000), cx=st.floats(100, 500), cy=st.floats(100, 400),
       k=st.lists(st.floats(-0.5, 0.5), min_size=4, max_size=4), model=st.sampled_from(["equidistant", "radtan"]))
def test_kalibr_numbers_are_read_as_written(f, cx, cy, k, model):
    cam = camera_from_kalibr({"cam0": {"camera_model": "pinhole", "intrinsics": [f, f * 1.01, cx, cy],
                                       "distortion_model": model, "distortion_coeffs": k, "resolution": [1000, 800]}})
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (f, f * 1.01, cx, cy)
    assert list(cam.dist_coeffs) == k
    assert cam.distortion_model == {"equidistant": "equidistant", "radtan": "plumb_bob"}[model]


@pytest.mark.parametrize("cam, match", [
    ({"camera_model": "omni", "intrinsics": [1, 1, 1, 1]}, "camera_model 'omni' is not supported"),
    ({"intrinsics": [300, 300, 10, 10], "distortion_model": "equidistant", "distortion_coeffs": [0, 0],
      "resolution": [20, 20]}, "'distortion_coeffs' must be a list of 4 numbers"),
    ({"intrinsics": [300, 300, 10], "resolution": [20, 20]}, "'intrinsics' must be a list of 4 numbers"),
])
def test_bad_kalibr_files_name_the_key(cam, match):
    with pytest.raises(CameraConfigError, match=match):
        camera_from_kalibr({"cam0": cam}, "k.yaml")


def test_tagslam_files_of_test_22():
    tags = load_tags_file(DATA / "tagslam.yaml")
    assert tags.sizes_m == {3: 0.42} and tags.default_size_m == 0.42 and tags.pixel_noise_px == 1.0
    assert tags.surveyed[3][:3, 3] == pytest.approx([0.0, 0.0, 1.5])
    # T_body_odom's rotation: the T265 pose frame (x forward, z up) in the fisheye's optical frame,
    # i.e. the transpose of the optical axes written in a body frame (T_ROBOT_OPTICAL)
    assert tags.T_body_odom[:3, :3] == pytest.approx(T_ROBOT_OPTICAL[:3, :3].T, abs=0.01)
    assert load_camera_poses(DATA / "camera_poses.yaml") == pytest.approx(np.eye(4))


@settings(max_examples=30, deadline=None)
@given(sizes=st.dictionaries(st.integers(0, 500), st.floats(0.01, 10.0), min_size=1, max_size=8))
def test_plain_tags_file_reads_every_size(tmp_path_factory, sizes):
    import yaml

    path = tmp_path_factory.mktemp("tags") / "tags.yaml"
    path.write_text(yaml.safe_dump({"tags": [{"id": i, "size": s} for i, s in sizes.items()]}))
    assert load_tags_file(path).sizes_m == sizes


def test_bad_tags_file_names_the_field(tmp_path):
    path = tmp_path / "tags.yaml"
    path.write_text("bodies:\n - yard:\n     default_tag_size: -1\n")
    with pytest.raises(InputFileError, match="bodies.yard.default_tag_size must be a tag side"):
        load_tags_file(path)


def test_a_frame_that_is_not_level_is_levelled_with_the_first_pose():
    q = np.array([0.61, 0.1, 0.2, 0.76])
    q /= np.linalg.norm(q)
    from scipy.spatial.transform import Rotation

    R0 = Rotation.from_quat(q).as_matrix()
    R_level, tilt, levelled = levelling_rotation(q)
    assert levelled and tilt == pytest.approx(math.degrees(math.acos(R0[2, 2])))
    assert R_level @ R0[:, 2] == pytest.approx([0, 0, 1], abs=1e-12)
    _, small, levelled = levelling_rotation(Rotation.from_rotvec([0.2, 0, 0]).as_quat())
    assert not levelled and small == pytest.approx(math.degrees(0.2))
    assert rotation_from_rotvec([0, 0, math.pi / 2]) @ [1, 0, 0] == pytest.approx([0, 1, 0])


def test_test_22_from_bag_to_report_against_tagslam(tmp_path):
    """The README's recipe on TagSLAM's test_22: iSAM2 aligned ATE against TagSLAM's
    optimised trajectory ≤ 0.15 m, its tag map within 0.2 m, EKF NIS in band ≥ 85 %."""
    log = tmp_path / "t22.jsonl"
    fgslam = [sys.executable, "-m", "fgslam.cli"]
    imported = subprocess.run(fgslam + [
        "import", "rosbag", str(DATA / "tag_detections.bag"), str(log), "--odom-topic", "/camera/odom/sample",
        "--detections-topic", "/detector/tags/left", "--camera", str(DATA / "cameras.yaml"),
        "--tags", str(DATA / "tagslam.yaml"), "--camera-poses", str(DATA / "camera_poses.yaml"),
        "--truth-bag", str(DATA / "reference.bag"), "--truth-topic", "/tagslam/odom/body_rig",
        "--truth-pose-of", "camera"], capture_output=True, text=True, cwd=ROOT)
    assert imported.returncode == 0, imported.stderr
    assert "tilted 12.8 deg" in imported.stderr and "height changed by up to 0.24 m" in imported.stderr
    assert "odometry noise: 114 of 114 increments use the default model" in imported.stderr
    header = json.loads(log.read_text().splitlines()[0])
    assert header["sensor"]["T_robot_camera"][2][3] == pytest.approx(0.032, abs=1e-4)  # TagSLAM's T_body_odom
    run = subprocess.run(fgslam + ["run", str(log), "--out", str(tmp_path / "out")], capture_output=True,
                         text=True, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["landmark_reference"] == "ground_truth"  # the tag map on reference.bag's /tf
    assert metrics["isam2"]["ate_aligned_rmse_m"] <= 0.15
    assert metrics["isam2"]["map_rmse_m"] <= 0.2
    assert metrics["ekf"]["nis_inside_95"] >= 0.85


def test_without_a_truth_bag_the_tags_files_surveyed_tag_is_the_truth_map(tmp_path, capsys):
    """test_22's tagslam.yaml surveys tag 3 (the yard's anchor, 1.5 m up, facing -x): imported
    without reference.bag it is the log's truth landmark, at the place TagSLAM's optimised map
    (reference.bag's /tf, anchored on that survey) holds it; with the truth bag the map is /tf's."""
    from fgslam.cli import main
    from slamio.log import TruthLandmark, read_log

    common = ["import", "rosbag", str(DATA / "tag_detections.bag"), "--odom-topic", "/camera/odom/sample",
              "--detections-topic", "/detector/tags/left", "--camera", str(DATA / "cameras.yaml"),
              "--tags", str(DATA / "tagslam.yaml"), "--camera-poses", str(DATA / "camera_poses.yaml")]
    surveyed, optimised = tmp_path / "surveyed.jsonl", tmp_path / "optimised.jsonl"
    assert main([*common, str(surveyed)]) == 0
    assert main([*common, str(optimised), "--truth-bag", str(DATA / "reference.bag"),
                 "--truth-topic", "/tagslam/odom/body_rig", "--truth-pose-of", "camera"]) == 0
    capsys.readouterr()
    logs = {name: read_log(path) for name, path in (("surveyed", surveyed), ("optimised", optimised))}
    assert logs["surveyed"].header.source["truth_landmarks"] == "tags file (surveyed poses)"
    assert logs["optimised"].header.source["truth_landmarks"] == "tf"
    (tag,) = [r for r in logs["surveyed"].records if isinstance(r, TruthLandmark)]
    assert (tag.landmark_id, tag.x_m, tag.y_m) == (3, pytest.approx(0.0, abs=1e-9), pytest.approx(0.0, abs=1e-9))
    assert tag.height_m == pytest.approx(1.5) and abs(abs(tag.yaw_rad) - math.pi) < 1e-4  # rotvec (0, -π/2, 0)
    mapped = {r.landmark_id: r for r in logs["optimised"].records if isinstance(r, TruthLandmark)}
    assert math.hypot(mapped[3].x_m - tag.x_m, mapped[3].y_m - tag.y_m) < 0.02
