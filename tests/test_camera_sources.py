"""Frame sources: TUM RGB-D folders, plain image folders, video, and the optional live Kinect."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest

from slamio.camera.sources import (
    FrameSourceError,
    associate,
    folder_frames,
    kinect_frames,
    open_frames,
    read_image,
    tum_frames,
    video_frames,
)


def _write_png(path, array):
    import cv2

    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), array)


def _tum_folder(root, with_lists=True):
    rng = np.random.default_rng(0)
    rgb_stamps = [100.000, 100.033, 100.067, 100.100]
    depth_stamps = [100.005, 100.030, 100.071, 100.300]  # the last colour frame has no depth within 20 ms
    for k, s in enumerate(rgb_stamps):
        _write_png(root / "rgb" / f"{s:.6f}.png", rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
    for k, s in enumerate(depth_stamps):
        depth = np.full((48, 64), 5000 * (k + 1), dtype=np.uint16)
        depth[0, 0] = 0  # missing
        _write_png(root / "depth" / f"{s:.6f}.png", depth)
    if with_lists:
        (root / "rgb.txt").write_text("# color images\n# file: 'x.bag'\n# timestamp filename\n"
                                      + "".join(f"{s:.6f} rgb/{s:.6f}.png\n" for s in rgb_stamps))
        (root / "depth.txt").write_text("# depth maps\n# timestamp filename\n"
                                        + "".join(f"{s:.6f} depth/{s:.6f}.png\n" for s in depth_stamps))
    return rgb_stamps


@pytest.mark.parametrize("with_lists", [True, False])
def test_tum_folder_pairs_colour_with_nearest_depth(tmp_path, with_lists):
    stamps = _tum_folder(tmp_path, with_lists)
    frames = list(open_frames(tmp_path))
    assert [f.stamp_s for f in frames] == stamps
    assert all(f.bgr is not None and f.bgr.shape == (48, 64, 3) for f in frames)
    depths = [None if f.depth_m is None else float(np.nanmax(f.depth_m)) for f in frames]
    assert depths == [1.0, 2.0, 3.0, None]  # 16-bit / 5000 per metre; the last has no partner
    assert np.isnan(frames[0].depth_m[0, 0])  # 0 = missing


def test_association_is_one_to_one_nearest_first():
    assert associate([0.0, 0.01, 1.0], [0.012, 0.5]) == {1: 0}
    assert associate([0.0], []) == {}


def test_malformed_stamp_list_says_file_and_line(tmp_path):
    _tum_folder(tmp_path)
    (tmp_path / "rgb.txt").write_text("# ok\n100.0 rgb/100.000000.png\nnot-a-stamp rgb/x.png\n")
    with pytest.raises(FrameSourceError, match=r"rgb.txt:3: expected 'STAMP_S PATH'"):
        list(tum_frames(tmp_path))


def test_plain_folder_stamps_from_names_or_fps(tmp_path):
    img = np.zeros((10, 12, 3), np.uint8)
    for name in ("2.5.png", "1.25.jpg"):
        _write_png(tmp_path / "a" / name, img)
    assert [f.stamp_s for f in folder_frames(tmp_path / "a")] == [1.25, 2.5]
    for name in ("frame_b.png", "frame_a.png", "frame_c.bmp"):
        _write_png(tmp_path / "b" / name, img)
    frames = list(folder_frames(tmp_path / "b", fps=10.0, start_s=5.0))
    assert [f.name for f in frames] == ["frame_a.png", "frame_b.png", "frame_c.bmp"]
    assert [f.stamp_s for f in frames] == [5.0, 5.1, 5.2]


def test_corrupt_and_empty_images_do_not_raise(tmp_path):
    _write_png(tmp_path / "0.png", np.zeros((10, 12, 3), np.uint8))
    (tmp_path / "1.png").write_bytes(b"\x89PNG\r\n\x1a\n not really a png")
    (tmp_path / "2.jpg").write_bytes(b"")
    frames = list(folder_frames(tmp_path))
    assert frames[0].bgr is not None and frames[0].error is None
    assert frames[1].bgr is None and "not a decodable image" in frames[1].error
    assert frames[2].bgr is None and "empty file" in frames[2].error
    grey_path = tmp_path / "g.png"
    _write_png(grey_path, np.zeros((5, 6), np.uint8))
    assert read_image(grey_path)[0].shape == (5, 6, 3)


def test_missing_sources_are_user_errors(tmp_path):
    with pytest.raises(FrameSourceError, match="no such folder"):
        open_frames(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FrameSourceError, match="no images"):
        list(folder_frames(tmp_path / "empty"))
    (tmp_path / "empty" / "color").mkdir()  # an RGB-D recording laid out another way
    with pytest.raises(FrameSourceError, match=r"holds the folders color/: give the folder of the images.*rgb\.txt"):
        list(folder_frames(tmp_path / "empty"))
    with pytest.raises(FrameSourceError, match="cannot open video source"):
        list(video_frames(str(tmp_path / "missing.avi")))


def test_video_file_through_videocapture(tmp_path):
    import cv2

    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    assert writer.isOpened()
    for k in range(5):
        writer.write(np.full((48, 64, 3), 40 * k, np.uint8))
    writer.release()
    frames = list(open_frames(path))
    assert len(frames) == 5 and frames[0].bgr.shape == (48, 64, 3)
    assert [round(f.stamp_s, 3) for f in frames] == [0.0, 0.1, 0.2, 0.3, 0.4]
    assert len(list(video_frames(str(path), max_frames=2))) == 2


def test_kinect_without_freenect_says_how_to_get_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "freenect", None)  # makes `import freenect` fail
    with pytest.raises(FrameSourceError, match="optional 'freenect' package"):
        next(kinect_frames())


def test_kinect_frames_with_a_stand_in_freenect(monkeypatch):
    calls = []
    fake = types.ModuleType("freenect")
    fake.VIDEO_RGB, fake.DEPTH_REGISTERED = 0, 4
    rgb = np.zeros((480, 640, 3), np.uint8)
    rgb[..., 0] = 255  # pure red in RGB order
    depth = np.full((480, 640), 1500, np.uint16)
    depth[0, 0] = 0

    def sync_get_video(index, fmt):
        calls.append(("video", index, fmt))
        return rgb, 1

    def sync_get_depth(index, fmt):
        calls.append(("depth", index, fmt))
        return depth, 1

    fake.sync_get_video, fake.sync_get_depth = sync_get_video, sync_get_depth
    fake.sync_stop = lambda: calls.append(("stop",))
    monkeypatch.setitem(sys.modules, "freenect", fake)
    frames = list(kinect_frames(0, max_frames=2, clock=lambda: 12.5))
    assert len(frames) == 2 and frames[0].stamp_s == 12.5
    assert tuple(frames[0].bgr[5, 5]) == (0, 0, 255)  # converted to BGR
    assert frames[0].depth_m[5, 5] == pytest.approx(1.5) and np.isnan(frames[0].depth_m[0, 0])
    assert ("depth", 0, 4) in calls and calls[-1] == ("stop",)
