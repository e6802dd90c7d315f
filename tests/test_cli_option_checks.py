"""Every option value is checked before any work: a bad one is one line ``fgslam: error: ...``
naming the option, exit status 1, no traceback, and nothing written (no --out file, no port
opened, no simulated robot started).

The verbs: detect, live (--port sim), import, bench, sim, tune-colours, run, check.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from fgslam.cli import main

DATA = Path(__file__).parent / "data"
PHOTOS = DATA / "apriltag-photos"


def _refused(capsys, argv: list[str], option: str, *, never_written: tuple[Path, ...] = ()) -> str:
    """Run ``fgslam argv``; assert the one-line user error naming ``option``; return the line."""
    code = main(argv)
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 1, (argv, captured.out, captured.err)
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("fgslam: error:"), lines[0]
    assert option in lines[0], lines[0]
    assert "Traceback" not in captured.err and "Traceback" not in captured.out
    for path in never_written:
        assert not path.exists(), f"{path} was written"
    return lines[0]


# --------------------------------------------------------------------------- detect


@pytest.fixture
def camera(tmp_path) -> Path:
    from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default, save_camera

    path = tmp_path / "cam.yaml"
    save_camera(path, kinect_v1_default(T_robot_camera_from_mount(x_m=0.1, z_m=0.2)))
    return path


# option: the bad values it is given
DETECT_BAD_NUMBERS = {
    "--threads": ["0", "-1"],  # 0 was: Floating point exception (exit 136) in the AprilTag detector
    "--tag-size": ["nan", "0"],  # nan was: a 2 KB line dumping the header
    "--quad-decimate": ["-1", "nan"],
    "--tag-upsample": ["nan"],
    "--max-pose-gap": ["-1", "nan"],
    "--depth-scale": ["0", "-5", "inf"],  # 0 was: a numpy divide-by-zero warning
    "--min-range": ["nan"],
    "--max-range": ["nan"],
    "--fps": ["0"],
    "--max-frames": ["0"],
}


@pytest.mark.parametrize("option, value", [(o, v) for o, values in DETECT_BAD_NUMBERS.items() for v in values])
def test_detect_refuses_bad_numbers_before_reading_a_frame(tmp_path, capsys, camera, option, value):
    out = tmp_path / "st.jsonl"
    argv = ["detect", str(PHOTOS), "--camera", str(camera), "--out", str(out), "--static", option, value]
    line = _refused(capsys, argv, option, never_written=(out,))
    assert len(line) < 200, line  # one short line, not a dump


def test_detect_refuses_bad_numbers_before_reading_the_camera_file(tmp_path, capsys):
    out = tmp_path / "st.jsonl"
    _refused(capsys, ["detect", str(PHOTOS), "--camera", str(tmp_path / "none.yaml"), "--out", str(out),
                      "--static", "--threads", "0"], "--threads", never_written=(out,))


# --------------------------------------------------------------------------- live --port sim


@pytest.fixture
def no_robot(monkeypatch) -> list[str]:
    """The simulated Create must not start, nor a link open: the checks come first. Returns
    the list of what was started anyway (each attempt also fails the command at once, so a
    late check can never leave a robot driving): a test asserts it stays empty."""
    import slamio.create.link
    import slamio.create.sim

    started: list[str] = []

    def starter(what: str):
        def start(*args, **kwargs):
            started.append(what)
            raise AssertionError(f"the {what} started before the options were checked")

        return start

    monkeypatch.setattr(slamio.create.sim, "SimulatedCreate", starter("simulated robot"))
    monkeypatch.setattr(slamio.create.link, "CreateLink", starter("serial link"))
    return started


LIVE_BAD = [
    ("--speed", "-1"), ("--speed", "nan"), ("--speed", "0"), ("--speed", "0.6"),
    ("--laps", "0"), ("--laps", "-2"),
    ("--side", "-1"), ("--side", "0"), ("--side", "nan"),
    ("--tag-size", "nan"), ("--tag-size", "-0.1"),
    ("--centre", "nan,nan"), ("--centre", "1,inf"),
    ("--start-pose", "1,nan,0"),
    ("--sim-time-scale", "0"), ("--sim-time-scale", "nan"),
    ("--sim-seed", "-1"),
    ("--sim-unplug-after", "nan"),
    ("--baud", "0"),
    ("--window", "1"), ("--window", "-3"),
]


@pytest.mark.parametrize("option, value", LIVE_BAD)
def test_live_checks_every_number_before_the_robot_starts(tmp_path, capsys, no_robot, option, value):
    out = tmp_path / "live.jsonl"
    _refused(capsys, ["live", "--port", "sim", "--sim-seed", "1", "--out", str(out), f"{option}={value}"], option,
             never_written=(out,))
    assert no_robot == []  # refused before the robot or its link started: nothing slow ran


def test_live_refuses_a_window_for_colour_landmarks_without_ids(tmp_path, capsys, no_robot):
    """Landmarks without an id are paired against every pose: no sliding window for them."""
    landmarks = tmp_path / "landmarks.yaml"
    landmarks.write_text("landmarks:\n  - {name: red, hsv: [[[0, 110, 60], [8, 255, 255]]]}\n")
    out = tmp_path / "live.jsonl"
    line = _refused(capsys, ["live", "--port", "sim", "--kind", "colour", "--landmarks", str(landmarks),
                             "--window", "100", "--out", str(out)], "--window", never_written=(out,))
    assert "red" in line and "--window 0" in line


def test_live_checks_the_map_png_before_the_robot_starts(tmp_path, capsys, no_robot):
    out = tmp_path / "live.jsonl"
    folder = tmp_path / "maps"
    folder.mkdir()
    old = tmp_path / "old.png"
    old.write_bytes(b"an earlier picture")
    a_file = tmp_path / "file"
    a_file.write_text("not a folder")
    bad = [folder, a_file / "map.png", old, out]
    if Path("/proc").is_dir():
        bad.append(Path("/proc/x.png"))  # a folder nothing can be written in (even as root)
    for png in bad:
        _refused(capsys, ["live", "--port", "sim", "--sim-seed", "1", "--out", str(out), "--map-png", str(png)],
                 "--map-png", never_written=(out,))
        assert no_robot == [], png  # refused before the robot or its link started: nothing slow ran
    assert old.read_bytes() == b"an earlier picture"
    assert list(folder.iterdir()) == []


@pytest.mark.parametrize("option, value", [("--camera", "cam.yaml"), ("--frames", "camera:7")])
def test_live_sim_refuses_a_real_camera_it_would_not_use(tmp_path, capsys, no_robot, option, value):
    out = tmp_path / "live.jsonl"
    _refused(capsys, ["live", "--port", "sim", "--out", str(out), option, value], option, never_written=(out,))


def test_record_refuses_frames_without_a_folder_to_save_them(tmp_path, capsys, no_robot):
    out = tmp_path / "run.jsonl"
    line = _refused(capsys, ["record", "--port", "sim", "--model", "create2", "--out", str(out),
                             "--frames", "camera:0"], "--frames", never_written=(out,))
    assert "--save-frames" in line


def test_live_sim_refuses_a_path_outside_the_arena(tmp_path, capsys, no_robot):
    path = tmp_path / "far.txt"
    path.write_text("1.0 1.0\n100 100\n")
    out = tmp_path / "live.jsonl"
    line = _refused(capsys, ["live", "--port", "sim", "--path", str(path), "--start-pose", "1,1,0", "--out", str(out)],
                    "waypoint 2", never_written=(out,))
    assert "(100.000, 100.000)" in line and "outside the simulated arena" in line
    _refused(capsys, ["live", "--port", "sim", "--side", "3", "--out", str(out)], "the start pose",
             never_written=(out,))


def test_live_makes_the_folders_of_its_outputs_before_the_robot_starts(tmp_path, no_robot):
    """As record does: a run never fails at its first pose for a missing folder."""
    out, png = tmp_path / "runs" / "live.jsonl", tmp_path / "maps" / "map.png"
    with pytest.raises(AssertionError, match="robot started"):
        main(["live", "--port", "sim", "--sim-seed", "1", "--out", str(out), "--map-png", str(png)])
    assert out.parent.is_dir() and png.parent.is_dir() and not out.exists()


# --------------------------------------------------------------------------- import


@pytest.mark.parametrize("argv, option", [
    (["plaza1", "{out}", "--range-bias", "nan"], "--range-bias"),  # was: a 2 KB line dumping the header
    (["plaza1", "{out}", "--range-bias", "1e9"], "--range-bias"),  # was: a log with 0 observations, exit 0
    (["plaza1", "{out}", "--range-bias=-1e9"], "--range-bias"),
    (["plaza2", "{out}", "--range-bias", "1000"], "--range-bias"),  # above Plaza2's longest range
    (["plaza1", "{out}", "--range-sigma", "nan"], "--range-sigma"),
    (["plaza1", "{out}", "--range-sigma", "-1"], "--range-sigma"),
    (["victoria-park", "{out}", "--robot", "3"], "--robot"),
    (["victoria-park", "{out}", "--noise", "noise.json"], "--noise"),
    (["plaza1", "{out}", "--pixel-sigma", "2"], "--pixel-sigma"),
    (["seed003", "drive.npz", "{out}", "--odom-topic", "/odom"], "--odom-topic"),
    (["rosbag", "bag", "{out}", "--range-bias", "1"], "--range-bias"),
    (["mrclam", "tests/fixtures/mrclam", "{out}", "--robot", "0"], "--robot"),
    (["victoria-park", "nope1", "{out}", "--source", "nope2"], "--source"),
    (["victoria-park", "a", "b", "c", "{out}"], "[SOURCE] OUT"),
])
def test_import_refuses_bad_options_before_the_conversion(tmp_path, capsys, argv, option):
    out = tmp_path / "out.jsonl"
    line = _refused(capsys, ["import"] + [str(out) if a == "{out}" else a for a in argv], option,
                    never_written=(out,))
    assert len(line) < 300, line


def test_import_names_the_dataset_an_option_belongs_to(tmp_path, capsys):
    line = _refused(capsys, ["import", "victoria-park", str(tmp_path / "vp.jsonl"), "--robot", "3"], "--robot")
    assert "mrclam" in line
    line = _refused(capsys, ["import", "victoria-park", str(tmp_path / "vp.jsonl"), "--turn-rate-sigma", "1"],
                    "--turn-rate-sigma")
    assert "seed003" in line


def test_import_usage_says_one_dataset_per_command(capsys):
    from fgslam.cli import build_parser

    parser = build_parser()
    verbs = next(a for a in parser._actions if a.dest == "verb")
    usage = verbs.choices["import"].format_usage()
    assert "DATASET [SOURCE] OUT" in usage
    assert "[[SOURCE] OUT ...]" not in usage and "..." not in usage


# --------------------------------------------------------------------------- bench and sim


@pytest.mark.parametrize("option, value", [("--jobs", "0"), ("--jobs", "-1"), ("--runs", "0"), ("--seed", "-1"),
                                           ("--laps", "0"), ("--landmarks", "0")])
def test_bench_refuses_bad_counts_before_a_run(tmp_path, capsys, option, value):
    out = tmp_path / "bench"
    _refused(capsys, ["bench", "arena-octagon", "--runs", "1", "--seed", "1", "--out", str(out), f"{option}={value}"],
             option, never_written=(out,))


@pytest.mark.parametrize("option, value", [("--laps", "0"), ("--seed", "-1"), ("--landmarks", "0"),
                                           ("--outliers", "nan"), ("--outliers", "1"), ("--outliers", "-0.1")])
def test_sim_refuses_bad_numbers_in_the_words_of_the_command_line(tmp_path, capsys, option, value):
    out = tmp_path / "a.jsonl"
    line = _refused(capsys, ["sim", "arena-octagon", "--seed", "1", "--out", str(out), f"{option}={value}"], option,
                    never_written=(out,))
    assert "None" not in line  # a Python detail, not the user's words


def test_sim_laps_error_says_how_to_get_the_default(tmp_path, capsys):
    line = _refused(capsys, ["sim", "arena-octagon", "--seed", "1", "--out", str(tmp_path / "a.jsonl"), "--laps", "0"],
                    "--laps")
    assert "leave --laps out" in line


# --------------------------------------------------------------------------- tune-colours


@pytest.mark.parametrize("value", ["0", "-5", "nan"])
def test_tune_colours_refuses_a_bad_depth_scale(tmp_path, capsys, camera, value):
    out = tmp_path / "landmarks.yaml"
    _refused(capsys, ["tune-colours", str(DATA / "rgbd-real"), "--camera", str(camera), "--out", str(out),
                      f"--depth-scale={value}"], "--depth-scale", never_written=(out,))


# --------------------------------------------------------------------------- run and check

BUNDLED = Path(__file__).resolve().parents[1] / "data" / "arena_octagon.jsonl"


def test_run_refuses_an_empty_estimator_list(tmp_path, capsys):
    _refused(capsys, ["run", str(BUNDLED), "--out", str(tmp_path / "r"), "--estimators", ""], "(none given)",
             never_written=(tmp_path / "r",))


def test_run_names_a_run_log_given_as_the_noise_model(tmp_path, capsys):
    recorded = tmp_path / "recorded.jsonl"  # the bundled log, as if it had not been simulated
    recorded.write_text(BUNDLED.read_text().replace('"generator": "slamio.sim"', '"generator": "by hand"', 1))
    line = _refused(capsys, ["run", str(recorded), "--out", str(tmp_path / "r"), "--noise", str(BUNDLED)],
                    "is a run log, not a noise model", never_written=(tmp_path / "r",))
    assert "fgslam calibrate" in line


def test_run_refuses_a_noise_model_for_a_simulated_log(tmp_path, capsys):
    _refused(capsys, ["run", str(BUNDLED), "--out", str(tmp_path / "r"), "--noise", str(tmp_path / "noise.json")],
             "was simulated", never_written=(tmp_path / "r",))


@pytest.mark.parametrize("verb", [["run", "--out", "OUT"], ["check"]])
def test_a_log_with_only_its_start_pose_is_refused(tmp_path, capsys, verb):
    header_only = tmp_path / "header.jsonl"
    header_only.write_text(BUNDLED.read_text().splitlines()[0] + "\n")
    argv = [verb[0], str(header_only), *[str(tmp_path / "r") if a == "OUT" else a for a in verb[1:]]]
    _refused(capsys, argv, "no odometry records", never_written=(tmp_path / "r",))


def test_without_truth_the_advice_names_every_isam2(tmp_path, capsys):
    no_truth = tmp_path / "no_truth.jsonl"
    no_truth.write_text("".join(line + "\n" for line in BUNDLED.read_text().splitlines()
                                if '"type": "truth' not in line))
    line = _refused(capsys, ["run", str(no_truth), "--out", str(tmp_path / "r"), "--estimators", "ekf",
                             "--no-report"], "keep isam2")
    assert "isam2-fast" in line and "isam2-dcs" in line
