"""slamio.noise.trials (seed 001's trial calibration) and the `fgslam calibrate TRIALS.csv` /
`fgslam record` verbs (fgslam.record_cli)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from fgslam.record_cli import add_calibrate_parser, add_record_parser, main
from slamio.noise.errors import NoiseModelError, NoiseModelFileError
from slamio.noise.trials import (
    calibrate_from_trials, calibration_from_dict, load_calibration, motion_errors, read_trials, simulated_trials,
)
from slamio.log import Odometry, read_log

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "data" / "calibration_trials_s001.csv"
HEADER = "kind,command_distance_m,command_angle_rad,x_m,y_m,theta_rad,true_range_m,true_bearing_rad,range_m,bearing_rad\n"


def write(tmp_path, body, name="trials.csv"):
    path = tmp_path / name
    path.write_text(HEADER + body)
    return path


def test_errors_and_covariances_are_seed_001s_numpy_cov(tmp_path):
    path = write(tmp_path, (
        "# a comment\n"
        "forward,0.5,0,0.49,0.01,0.02,,,,\n"
        "forward,0.5,0,0.51,-0.01,0.00,,,,\n"
        "forward,0.5,0,0.50,0.00,-0.02,,,,\n"
        "rotate,0,1.5708,0.00,0.00,1.60,,,,\n"
        "rotate,0,1.5708,0.01,0.00,1.55,,,,\n"
        "sensor,,,,,,1.0,0.1,1.02,0.12\n"
        "sensor,,,,,,2.0,-0.2,1.97,-0.21\n"
    ))
    motion, sensor = read_trials(path)
    assert len(motion) == 5 and len(sensor) == 2
    forward = motion_errors([t for t in motion if t.kind == "forward"])
    assert np.allclose(forward, [[-0.01, 0.01, 0.02], [0.01, -0.01, 0.0], [0.0, 0.0, -0.02]])
    c = calibrate_from_trials(motion, sensor, source=str(path))
    assert np.allclose(c.forward["covariance"], np.ma.cov(forward, rowvar=False))
    assert np.allclose(c.forward["covariance_per_m"], np.array(c.forward["covariance"]) / 0.5)
    assert np.allclose(c.rotate["bias"], [0.005, 0.0, (1.60 + 1.55) / 2 - 1.5708])
    assert c.observation["bias"] == pytest.approx([(0.02 - 0.03) / 2, (0.02 - 0.01) / 2])
    assert c.observation["sigma_range_m"] == pytest.approx(np.std([0.02, -0.03], ddof=1))
    pooled = np.ma.cov(motion_errors(motion), rowvar=False)
    assert np.allclose(c.pooled_motion_covariance, pooled)  # seed 001's single R, as written


def test_odometry_noise_from_a_calibration_scales_per_metre_and_radian():
    c = calibrate_from_trials(*read_trials(BUNDLED), source=str(BUNDLED))
    noise = c.odometry_noise("create2")
    one_trial = np.array(noise.covariance(0.5, 0.0)) - np.array(noise.floor)
    assert np.allclose(one_trial, c.forward["covariance"])  # one 0.5 m trial's covariance back
    assert "fgslam calibrate" in noise.source


def test_bundled_trials_are_the_labelled_simulation():
    text = BUNDLED.read_text()
    assert text == simulated_trials(1) and text.startswith("# SIMULATED")
    motion, sensor = read_trials(BUNDLED)
    kinds = [t.kind for t in motion]
    assert kinds.count("forward") == 30 and kinds.count("rotate") == 30 and len(sensor) == 15


@pytest.mark.parametrize(
    "body, message",
    [
        ("walk,0.5,0,0.5,0,0,,,,\n", r"trials.csv:2: kind 'walk' is not one of"),
        ("forward,0.5,0,,0,0,,,,\n", r"trials.csv:2: a forward trial needs column x_m"),
        ("forward,0.5,0,abc,0,0,,,,\n", r"trials.csv:2: column x_m must be a number"),
        ("forward,0,0,0.5,0,0,,,,\nforward,0,0,0.5,0,0,,,,\n", "command_distance_m ≠ 0"),
        ("forward,0.5,0,0.5,0,0,,,,\n", "one forward trial cannot give a covariance"),
        ("sensor,,,,,,1,0,-1,0\n", "ranges must be > 0"),
    ],
)
def test_bad_trials_say_file_line_and_fix(tmp_path, body, message):
    path = write(tmp_path, body)
    with pytest.raises(NoiseModelError, match=message):
        calibrate_from_trials(*read_trials(path), source=str(path))


def test_bad_header_and_missing_file(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("kind,speed\n")
    with pytest.raises(NoiseModelFileError, match=r"x.csv:1: the header must name columns.*unknown: speed"):
        read_trials(path)
    with pytest.raises(NoiseModelFileError, match="cannot read the trials file"):
        read_trials(tmp_path / "nope.csv")


# --------------------------------------------------------------------------- the verbs


def test_verbs_plug_into_a_parent_parser(capsys):
    parser = argparse.ArgumentParser(prog="fgslam")
    verbs = parser.add_subparsers(dest="verb", required=True)
    add_record_parser(verbs)
    add_calibrate_parser(verbs)
    args = parser.parse_args(["record", "--port", "/dev/ttyUSB0", "--model", "create1", "--out", "x.jsonl"])
    assert args.path == "octagon" and args.func.__name__ == "cmd_record" and args.laps == 1
    args = parser.parse_args(["calibrate", "t.csv"])
    assert args.func.__name__ == "cmd_calibrate"
    for verb in ("record", "calibrate"):
        with pytest.raises(SystemExit):
            parser.parse_args([verb, "--help"])
        out = capsys.readouterr().out
        assert f"usage: fgslam {verb}" in out
    assert "Drive Direct 0 0" in out or "TRIALS.csv" in out
    with pytest.raises(SystemExit):
        parser.parse_args(["record", "--port", "x", "--model", "create3", "--out", "x"])


def test_calibrate_verb_prints_and_writes(tmp_path, capsys):
    out = tmp_path / "cal" / "calibration.json"
    assert main(["calibrate", str(BUNDLED), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "forward: 30 trials" in printed and "sensor: 15 readings" in printed
    c = load_calibration(out)
    assert c.forward["trials"] == 30 and json.loads(out.read_text())["format"] == "fgslam-calibration"


def test_calibrate_verb_missing_trials_file_exits_2(tmp_path, capsys):
    """An input file that cannot be used is exit status 2 (a mistake in the command is 1)."""
    assert main(["calibrate", str(tmp_path / "missing.csv")]) == 2
    assert "cannot read the trials file" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    with pytest.raises(NoiseModelFileError, match="not a calibration file"):
        load_calibration(bad)


def test_record_verb_on_the_simulator_with_a_calibration(tmp_path, capsys):
    cal = tmp_path / "cal.json"
    assert main(["calibrate", str(BUNDLED), "--out", str(cal)]) == 0
    out = tmp_path / "runs" / "square.jsonl"
    code = main(["record", "--port", "sim", "--model", "create2", "--path", "square", "--side", "0.5",
                 "--out", str(out), "--calibration", str(cal), "--sim-time-scale", "20", "--sim-seed", "3",
                 "--watchdog", "30"])  # a busy machine must not stop the robot
    printed = capsys.readouterr().out
    assert code == 0 and "wrote" in printed and "completed" in printed
    log = read_log(out)
    assert "fgslam calibrate" in log.header.noise["odometry"]["source"]
    assert log.header.noise["observation"]["sigma_range_m"] > 0
    assert log.header.source["command"].startswith("fgslam record --port sim")
    status = json.loads((tmp_path / "runs" / "square.jsonl.status.json").read_text())
    odometry = [r for r in log.records if isinstance(r, Odometry)]  # the simulator's truth_pose records too
    assert status["reason"]["kind"] == "completed" and status["records"] == len(odometry)
    # What the encoders counted, the recorder wrote: exact up to a count (0.44 mm) per record,
    # whatever the timing. (Σ|distance| against the true path would not do: how many records a
    # busy machine makes changes the sum of the noise's absolute values, a 1-3 % bias.)
    simulator = status["simulator"]
    signed = sum(r.distance_m for r in odometry)
    assert signed == pytest.approx(simulator["encoder_distance_m"], abs=1e-3)
    truth = simulator["true_path_length_m"]
    # 4 × 0.5 m; at 20× real time a busy machine's late stop at each corner lets the robot run
    # on (2.14-2.18 m seen under load): the path is driven, how far past a corner is timing
    assert 1.9 < truth < 2.4 and signed == pytest.approx(truth, rel=0.05)  # the calibrated noise


def test_record_verb_bad_port_exits_1_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "x.jsonl"
    assert main(["record", "--port", str(tmp_path / "ttyUSB0"), "--model", "create2", "--out", str(out)]) == 1
    assert "cannot open serial port" in capsys.readouterr().err
    assert not out.exists()


def test_record_verb_refuses_a_folder_and_too_much_speed(tmp_path, capsys):
    assert main(["record", "--port", "sim", "--model", "create2", "--out", str(tmp_path)]) == 1
    assert "is a folder" in capsys.readouterr().err
    assert main(["record", "--port", "sim", "--model", "create2", "--out", str(tmp_path / "a.jsonl"),
                 "--speed", "0.8"]) == 1
    assert "0.5 m/s" in capsys.readouterr().err


def test_calibrate_help_names_the_three_ways_and_not_the_camera(capsys):
    parser = argparse.ArgumentParser(prog="fgslam")
    add_calibrate_parser(parser.add_subparsers(dest="verb", required=True))
    with pytest.raises(SystemExit):
        parser.parse_args(["calibrate", "--help"])
    out = capsys.readouterr().out
    assert "from truth:" in out and "from trials:" in out and "without truth:" in out
    assert "--from {truth,self,trials}" in out and "--without-truth" in out
    assert "intrinsics" in out and "calibrate-camera" in out and "Seed 001's trial calibration" in out


@pytest.mark.parametrize(
    "paths, mode, expected",
    [
        (["a.jsonl", "b.jsonl"], None, "truth"),
        (["t.csv"], None, "trials"),
        (["t.csv"], "trials", "trials"),
        (["run.log"], "truth", "truth"),  # --from truth takes logs of any name
    ],
)
def test_calibration_mode_from_the_files_or_named(paths, mode, expected):
    from fgslam.cli.calibrate import calibration_mode

    assert calibration_mode(paths, mode) == expected


@pytest.mark.parametrize(
    "paths, mode, message",
    [
        (["a.jsonl", "t.csv"], None, "mix of logs and other files"),
        (["a.csv", "b.csv"], None, "from trials takes one TRIALS.csv"),
        (["a.jsonl"], "trials", "from trials takes one TRIALS.csv"),
    ],
)
def test_calibration_mode_refuses_files_of_the_other_kind(paths, mode, message):
    from fgslam.cli.calibrate import calibration_mode

    with pytest.raises(NoiseModelError, match=message):
        calibration_mode(paths, mode)


def test_calibrate_from_trials_named_with_from(tmp_path, capsys):
    assert main(["calibrate", str(BUNDLED), "--from", "trials"]) == 0
    assert "forward: 30 trials" in capsys.readouterr().out
    assert main(["calibrate", str(BUNDLED), "--from", "truth"]) == 2  # a CSV is no run log
    capsys.readouterr()


def test_scales_of_exact_trials_both_ways():
    """A robot that travels 0.95 m and turns 0.02 rad per commanded metre, and turns 1.03 rad
    per commanded radian, forward and backward, left and right: the scales come out exactly."""
    from slamio.geometry import arc_increment
    from slamio.noise.trials import MotionTrial

    motion = []
    for i, d in enumerate((0.5, -0.5, 1.0, 0.25)):
        dtheta = 0.02 * d
        x, y, _ = arc_increment(0.95 * d, dtheta)  # along a gentle arc of 0.95 d
        motion.append(MotionTrial("forward", d, 0.0, x, y, dtheta, i + 1))
    for i, a in enumerate((1.5708, -1.5708, 3.0, -0.5)):
        motion.append(MotionTrial("rotate", 0.0, a, 0.0, 0.0, 1.03 * a, i + 10))
    cal = calibrate_from_trials(motion, [])
    scales = cal.odometry_scales()
    assert scales["forward_scale"] == pytest.approx(0.95, abs=1e-4)  # the arc's chord, 1e-5 short
    assert scales["turn_per_m_rad"] == pytest.approx(0.02, abs=1e-12)
    assert scales["turn_scale"] == pytest.approx(1.03, abs=1e-12)
    assert cal.rotate["scale_std"] == pytest.approx(0.0, abs=1e-12)
    back = calibration_from_dict(cal.to_dict(), "round trip")
    assert back.odometry_scales() == scales


def test_a_calibration_without_scales_says_to_calibrate_again():

    d = calibrate_from_trials(*read_trials("data/calibration_trials_s001.csv")).to_dict()
    for part in ("forward", "rotate"):
        for key in ("scale", "scale_std", "turn_per_m_rad"):
            d[part].pop(key, None)
    with pytest.raises(NoiseModelError, match="before scales were kept.*calibrate TRIALS.csv"):
        calibration_from_dict(d, "old.json").odometry_scales()
    d["rotate"]["scale"] = -1.0
    with pytest.raises(NoiseModelError, match=r"rotate.scale must be > 0"):
        calibration_from_dict(d, "bad.json")
