"""fgslam tune-colours: ranges fitted to the landmarks in the user's frames, checked by the same tests as detect."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from fgslam.cli import main
from slamio.camera.colour import DEFAULT_COLOURS, detect_colour_landmarks
from slamio.camera.landmark_file import load_landmarks
from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default, save_camera
from slamio.camera.render import CYLINDER_BGR, CylinderSpec, Scene, render
from slamio.camera.sources import read_depth_png, read_image
from slamio.camera.tune import hue_runs, hue_set, loosened, tuned_ranges

KINECT = kinect_v1_default(T_robot_camera_from_mount(x_m=0.1, z_m=0.3))
ORANGE_BGR = (30, 100, 220)  # hue 11 on OpenCV's scale: outside the default red's 0-8


def test_loosening_and_tuning_wrap_around_red():
    red = DEFAULT_COLOURS[0]
    wide = loosened(red, hue_widen=12)
    assert hue_runs(hue_set(wide.hsv_ranges)) == [(0, 20), (158, 179)]
    assert all(lo[1] == 60 and lo[2] == 40 for lo, _ in wide.hsv_ranges)
    rng = np.random.default_rng(0)
    hues = (rng.normal(0.0, 2.0, 5000).round() % 180).astype(np.uint8)  # a red centred on H = 0
    pixels = np.column_stack([hues, rng.integers(150, 250, 5000), rng.integers(90, 250, 5000)]).astype(np.uint8)
    ranges = tuned_ranges(pixels)
    covered = hue_set(ranges)
    assert covered[0] and covered[5] and covered[175] and not covered[15] and not covered[165]
    assert all(85 <= lo[1] <= 95 and 50 <= lo[2] <= 60 for lo, _ in ranges)  # floors: 0.6 × 1st percentile


def _rgbd_folder(folder: Path, poses, cylinders):
    (folder / "rgb").mkdir(parents=True)
    (folder / "depth").mkdir()
    for k, pose in enumerate(poses):
        frame = render(KINECT, pose, Scene(cylinders=cylinders), supersample=2, depth_model="kinect")
        cv2.imwrite(str(folder / "rgb" / f"{k}.000000.png"), frame.bgr)
        cv2.imwrite(str(folder / "depth" / f"{k}.000000.png"),
                    np.nan_to_num(frame.depth_m * 5000.0, nan=0.0).round().astype(np.uint16))


def test_tune_colours_finds_an_orange_red_the_defaults_miss(tmp_path, capsys):
    cylinders = (CylinderSpec(2.2, 0.3, 0.05, 0.40, ORANGE_BGR, "red", 0),
                 CylinderSpec(2.8, -0.5, 0.05, 0.60, CYLINDER_BGR["green"], "green", 1))
    poses = [(0.0, 0.0, 0.0), (0.2, 0.0, 0.05), (0.4, 0.1, -0.05), (0.6, 0.0, 0.0)]
    frames = tmp_path / "frames"
    _rgbd_folder(frames, poses, cylinders)
    camera = tmp_path / "kinect.yaml"
    save_camera(camera, KINECT)
    bgr, _ = read_image(frames / "rgb" / "0.000000.png")
    depth, _ = read_depth_png(frames / "depth" / "0.000000.png")
    found, _, _ = detect_colour_landmarks(bgr, depth, KINECT)
    assert [m.colour for m in found] == ["green"]  # the default red range misses the orange cylinder

    out, show = tmp_path / "landmarks.yaml", tmp_path / "tuning"
    assert main(["tune-colours", str(frames), "--camera", str(camera), "--out", str(out), "--show", str(show)]) == 0
    printed = capsys.readouterr().out
    assert "red: found in 4 of 4 frames" in printed and "blue: not found" in printed
    tuned = load_landmarks(out)
    red = tuned.colours[0]
    assert hue_set(red.hsv_ranges)[11] and not hue_set(red.hsv_ranges)[30]
    # the tuned red survives a darker exposure of the same scene
    dim = render(KINECT, poses[0], Scene(cylinders=cylinders), supersample=2, depth_model="kinect", gain=0.6)
    assert [m.colour for m in detect_colour_landmarks(dim.bgr, dim.depth_m, KINECT, tuned)[0]].count("red") == 1
    assert tuned.colours[2].hsv_ranges == DEFAULT_COLOURS[2].hsv_ranges  # not seen: kept
    found, _, _ = detect_colour_landmarks(bgr, depth, KINECT, tuned)
    assert sorted(m.colour for m in found) == ["green", "red"]
    assert math.hypot(2.2 - 0.0, 0.3) == pytest.approx(next(m.range_m for m in found if m.colour == "red"), rel=0.02)
    assert len(list(show.glob("*_mask.png"))) == 4 and len(list(show.glob("*_detections.png"))) == 4
    # the tuned file still reports nothing on real clutter
    data = Path(__file__).parent / "data" / "rgbd-real"
    for name, scale in (("open3d_00000", 1000.0), ("tum", 5000.0)):
        real_bgr, _ = read_image(data / f"{name}_color.jpg")
        real_depth, _ = read_depth_png(data / f"{name}_depth.png", scale)
        assert detect_colour_landmarks(real_bgr, real_depth, KINECT, tuned)[0] == []
    # an existing file is kept
    assert main(["tune-colours", str(frames), "--camera", str(camera), "--out", str(out)]) == 1


def test_tune_colours_needs_depth(tmp_path):
    folder = tmp_path / "plain"
    folder.mkdir()
    cv2.imwrite(str(folder / "a.png"), np.full((480, 640, 3), 100, np.uint8))
    camera = tmp_path / "kinect.yaml"
    save_camera(camera, KINECT)
    assert main(["tune-colours", str(folder), "--camera", str(camera), "--out", str(tmp_path / "l.yaml")]) == 1
    assert not (tmp_path / "l.yaml").exists()
