"""``fgslam calibrate-camera`` (:mod:`slamio.camera.chessboard`) on chessboard views rendered
through a known lens."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fgslam.cli import main
from slamio.camera.chessboard import calibrate
from slamio.camera.model import CameraModel, load_camera

TRUE_K = np.array([[540.0, 0.0, 322.0], [0.0, 538.0, 236.0], [0.0, 0.0, 1.0]])
TRUE_D = np.array([-0.12, 0.08, 0.0005, -0.0008, 0.0])
BOARD = (9, 6)  # inner corners: a board of 10 × 7 squares
SQUARE_M = 0.03
PX = 24  # texture pixels per square


def _texture():
    cols, rows = BOARD[0] + 1, BOARD[1] + 1
    tex = np.full(((rows + 2) * PX, (cols + 2) * PX), 255, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                tex[(r + 1) * PX:(r + 2) * PX, (c + 1) * PX:(c + 2) * PX] = 0
    return tex


def _views(folder: Path, count: int, seed: int = 7):
    import cv2

    rng = np.random.default_rng(seed)
    camera = CameraModel(640, 480, TRUE_K, TRUE_D)
    tex = _texture()
    s = SQUARE_M / PX  # metres per texture pixel; board origin at the first inner corner
    A = np.array([[s, 0, -2 * PX * s], [0, s, -2 * PX * s], [0, 0, 1.0]])
    u, v = np.meshgrid(np.arange(640, dtype=float), np.arange(480, dtype=float))
    undist = camera.normalized(np.column_stack([u.ravel(), v.ravel()]))
    mapx = (undist[:, 0] * TRUE_K[0, 0] + TRUE_K[0, 2]).reshape(480, 640).astype(np.float32)
    mapy = (undist[:, 1] * TRUE_K[1, 1] + TRUE_K[1, 2]).reshape(480, 640).astype(np.float32)
    centre = np.array([(BOARD[0] - 1) * SQUARE_M / 2, (BOARD[1] - 1) * SQUARE_M / 2, 0.0])
    paths = []
    while len(paths) < count:
        angles = rng.uniform(-0.6, 0.6, 3) * (1.0, 1.0, 0.5)
        R = cv2.Rodrigues(angles)[0]
        t = np.array([rng.uniform(-0.12, 0.12), rng.uniform(-0.08, 0.08), rng.uniform(0.45, 0.8)]) - R @ centre
        corners = np.array([[x, y, 0.0] for x in (-2 * SQUARE_M, (BOARD[0] + 1) * SQUARE_M)
                            for y in (-2 * SQUARE_M, (BOARD[1] + 1) * SQUARE_M)])
        uv = camera.project(corners @ R.T + t)
        if uv.min() < 10 or uv[:, 0].max() > 630 or uv[:, 1].max() > 470:
            continue
        H = TRUE_K @ np.column_stack([R[:, 0], R[:, 1], t]) @ A
        ideal = cv2.warpPerspective(tex, H, (640, 480), flags=cv2.INTER_LINEAR, borderValue=128)
        image = cv2.remap(ideal, mapx, mapy, cv2.INTER_LINEAR)
        path = folder / f"view_{len(paths):02d}.png"
        cv2.imwrite(str(path), image)
        paths.append(str(path))
    return paths


def test_calibration_recovers_the_lens(tmp_path):
    paths = _views(tmp_path, 12)
    (tmp_path / "not_a_board.png").write_bytes(b"junk")
    result = calibrate(paths + [str(tmp_path / "not_a_board.png")], BOARD, SQUARE_M)
    cam = result.camera
    assert result.board_not_found == [str(tmp_path / "not_a_board.png")]
    assert result.rms_px < 0.3
    assert cam.fx == pytest.approx(540.0, rel=0.01) and cam.fy == pytest.approx(538.0, rel=0.01)
    assert cam.cx == pytest.approx(322.0, abs=3) and cam.cy == pytest.approx(236.0, abs=3)
    assert cam.dist_coeffs[0] == pytest.approx(-0.12, abs=0.03)


def test_command_line_writes_a_loadable_camera_file(tmp_path, capsys):
    paths = _views(tmp_path, 8, seed=11)
    out = tmp_path / "cam.yaml"
    assert main(["calibrate-camera", str(tmp_path / "view_*.png"), "--board", "9x6", "--square", str(SQUARE_M),
                 "--mount", "0.1,0,0.3,0,0.05,0", "--out", str(out)]) == 0
    cam = load_camera(out)
    assert cam.width_px == 640 and cam.fx == pytest.approx(540.0, rel=0.02)
    assert cam.T_robot_camera[2, 3] == pytest.approx(0.3)
    assert "RMS reprojection error" in capsys.readouterr().out
    assert len(paths) == 8


def test_too_few_views_is_explained(tmp_path, capsys):
    _views(tmp_path, 2)
    assert main(["calibrate-camera", str(tmp_path / "*.png"), "--board", "9x6", "--square", "0.03",
                 "--out", str(tmp_path / "c.yaml")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("fgslam: error:") and "need at least 5" in err
    assert not (tmp_path / "c.yaml").exists()


def test_an_existing_camera_file_is_kept_unless_overwrite(tmp_path, capsys):
    _views(tmp_path, 6, seed=3)
    out = tmp_path / "cam.yaml"
    out.write_text("mine\n")
    argv = ["calibrate-camera", str(tmp_path / "view_*.png"), "--board", "9x6", "--square", str(SQUARE_M),
            "--out", str(out)]
    assert main(argv) == 1
    assert "exists" in capsys.readouterr().err and out.read_text() == "mine\n"
    assert main(argv + ["--overwrite"]) == 0
    assert load_camera(out).width_px == 640


@pytest.mark.parametrize("option, value, message", [("--board", "9", "COLSxROWS"), ("--square", "0", "--square"),
                                                    ("--mount", "1,2,3", "--mount")])
def test_bad_options_are_one_line_before_any_work(tmp_path, capsys, option, value, message):
    options = {"--board": "9x6", "--square": "0.03", option: value}
    argv = ["calibrate-camera", str(tmp_path / "*.png"), "--out", str(tmp_path / "c.yaml")]
    argv += [text for pair in options.items() for text in pair]
    try:
        status = main(argv)
    except SystemExit as stop:  # argparse refuses a malformed value itself
        status = stop.code
    assert status == 1
    err = capsys.readouterr().err
    assert err.startswith("fgslam: error:") and message in err and err.count("\n") == 1
    assert not (tmp_path / "c.yaml").exists()
