"""Depth images among colour frames are not frames (slamio/camera/sources.py): a 16-bit
single-channel image, or a file name with the word "depth", is left out of a plain image
folder, and a folder called depth/ is refused. The references: the real frames of
tests/data/rgbd-real (Open3D's and TUM's colour JPEGs beside their 16-bit depth PNGs), and
folders written here with known bit depths and names."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from fgslam.cli import main
from slamio.camera.model import kinect_v1_default, save_camera
from slamio.camera.sources import FrameSourceError, depth_image_reason, folder_frames, open_frames, split_depth_images

RGBD = Path(__file__).parent / "data" / "rgbd-real"


def _write(path, array):
    import cv2

    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), array)


def test_the_real_rgbd_folder_gives_its_three_colour_frames_only():
    colour, depth = split_depth_images(RGBD)
    assert [p.name for p in colour] == ["open3d_00000_color.jpg", "open3d_00004_color.jpg", "tum_color.jpg"]
    assert sorted(p.name for p in depth) == ["open3d_00000_depth.png", "open3d_00004_depth.png", "tum_depth.png"]
    frames = list(open_frames(RGBD, fps=10.0))
    assert [f.name for f in frames] == [p.name for p in colour]
    assert [f.stamp_s for f in frames] == [0.0, 0.1, 0.2]  # frame k at k/fps, counting colour frames only
    assert all(f.bgr is not None and f.bgr.shape == (480, 640, 3) for f in frames)


def test_bit_depth_or_name_decides(tmp_path):
    colour = np.full((12, 16, 3), 90, np.uint8)
    _write(tmp_path / "a.png", colour)
    _write(tmp_path / "b.png", np.full((12, 16), 1500, np.uint16))  # 16-bit grey, a neutral name
    _write(tmp_path / "c.png", np.full((12, 16), 90, np.uint8))  # an 8-bit mono camera: a frame
    _write(tmp_path / "d.png", np.full((12, 16, 3), 900, np.uint16))  # 16-bit colour: a frame
    _write(tmp_path / "frame-000000.depth.png", colour)  # 7-Scenes' naming, whatever it holds
    _write(tmp_path / "e_Depth.jpg", colour)
    _write(tmp_path / "indepth.png", colour)  # not the word "depth"
    assert depth_image_reason(tmp_path / "b.png") == "a 16-bit single-channel image (Pillow mode I;16)"
    assert depth_image_reason(tmp_path / "frame-000000.depth.png") == "its name says depth"
    assert depth_image_reason(tmp_path / "e_Depth.jpg") == "its name says depth"
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n not really a png")
    assert depth_image_reason(tmp_path / "broken.png") is None  # left to the reader: a corrupt frame
    frames = list(folder_frames(tmp_path))
    assert [f.name for f in frames] == ["a.png", "broken.png", "c.png", "d.png", "indepth.png"]


def test_a_depth_folder_or_a_folder_of_only_depth_is_refused_with_the_colour_folder_named(tmp_path):
    for k in range(2):  # Open3D's layout, as /work/shared/data/rgbd-real/sequence: color/*.jpg, depth/*.png
        _write(tmp_path / "seq" / "color" / f"{k:05d}.jpg", np.full((12, 16, 3), 90, np.uint8))
        _write(tmp_path / "seq" / "depth" / f"{k:05d}.png", np.full((12, 16), 1500, np.uint16))
    with pytest.raises(FrameSourceError, match=r"a folder of depth images, not colour frames: give .*seq/color"):
        list(open_frames(tmp_path / "seq" / "depth"))
    with pytest.raises(FrameSourceError, match=r"holds the folders color/, depth/: give .*\(.*seq/color for the colour"):
        list(open_frames(tmp_path / "seq"))
    assert len(list(open_frames(tmp_path / "seq" / "color"))) == 2
    shutil.copytree(tmp_path / "seq" / "depth", tmp_path / "scans")
    with pytest.raises(FrameSourceError, match=r"no colour images, only 2 depth images \(00000.png: a 16-bit"):
        list(open_frames(tmp_path / "scans"))


def test_detect_says_how_many_depth_images_it_left_out(tmp_path, capsys):
    camera = tmp_path / "kinect.yaml"
    save_camera(camera, kinect_v1_default())
    log = tmp_path / "run.jsonl"
    assert main(["sim", "arena-square", "--seed", "1", "--out", str(log)]) == 0
    capsys.readouterr()
    assert main(["detect", str(RGBD), "--camera", str(camera), "--out", str(log), "--tag-size", "0.16",
                 "--replace"]) == 0
    printed = capsys.readouterr().out
    assert "3 depth images in" in printed and "are not colour frames and are left out" in printed
    assert "3 colour frames" in printed
