"""Side input files (calibration, tolerances, trials, camera, landmarks, waypoints) that are
not what they should be, and `fgslam check`'s tolerances out of range: each is one line
`fgslam: error: ...` naming the file (or the option), never a traceback; exit status 2 for a
file (an input file that cannot be used), 1 for an option."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest

from fgslam.cli import main
from slamio.errors import FgslamError

HERE = Path(__file__).parent
PNG = HERE / "data" / "apriltag-photos" / "pupil_test_image.png"
GARBAGE = b"\xff\xfe\x00garbage\n\x80\x81 not text"  # fixed bytes: not UTF-8 from the first byte
BAD_CALIBRATION = {"format": "fgslam-calibration", "forward": "abc", "rotate": None,
                   "pooled_motion_covariance": "x", "observation": 5}


def one_error_line(capsys, *names: str) -> str:
    """The single `fgslam: error:` line on stderr; it names each of ``names``."""
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = err.strip("\n").splitlines()
    assert len(lines) == 1, err
    line = lines[0]
    assert line.startswith("fgslam: error:"), line
    for name in names:
        assert name in line, (name, line)
    return line


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    """A small simulated log (one lap of the octagon arena)."""
    path = tmp_path_factory.mktemp("log") / "a.jsonl"
    assert main(["sim", "arena-octagon", "--seed", "1", "--laps", "1", "--out", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def small_log(log, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("small") / "small.jsonl"
    path.write_text("".join(log.read_text().splitlines(keepends=True)[:400]))
    return path


@pytest.fixture(scope="module")
def good_calibration(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cal") / "cal.json"
    assert main(["calibrate", str(HERE.parent / "data" / "calibration_trials_s001.csv"), "--out", str(path)]) == 0
    return path


@pytest.fixture()
def garbage(tmp_path) -> Path:
    path = tmp_path / "garbage.jsonl"
    path.write_bytes(GARBAGE)
    return path


@pytest.fixture()
def camera(tmp_path) -> Path:
    from slamio.camera.model import kinect_v1_default, save_camera

    path = tmp_path / "cam.yaml"
    save_camera(path, kinect_v1_default())
    return path


@pytest.fixture()
def photos(tmp_path) -> Path:
    folder = tmp_path / "photos"
    folder.mkdir()
    shutil.copy(PNG, folder / PNG.name)
    return folder


# --------------------------------------------------------------------------- not UTF-8 text


def not_utf8(capsys, path: Path, kind: str) -> None:
    line = one_error_line(capsys, str(path), "not UTF-8 text", "byte 0xff at column 1", kind)
    assert line.startswith(f"fgslam: error: {path}:1: ")


def test_calibration_not_utf8_on_run(capsys, log, garbage, tmp_path):
    code = main(["run", str(log), "--out", str(tmp_path / "r"), "--estimators", "ekf,isam2",
                 "--calibration", str(garbage), "--no-report"])
    assert code == 2
    not_utf8(capsys, garbage, "calibration file")


def test_calibration_not_utf8_on_record(capsys, garbage, tmp_path):
    code = main(["record", "--port", "sim", "--model", "create2", "--out", str(tmp_path / "r.jsonl"),
                 "--calibration", str(garbage)])
    assert code == 2
    not_utf8(capsys, garbage, "calibration file")


def test_tolerances_not_utf8(capsys, log, garbage):
    assert main(["check", str(log), "--tolerances", str(garbage)]) == 2
    not_utf8(capsys, garbage, "tolerance file")


def test_trials_not_utf8(capsys, tmp_path):
    trials = tmp_path / "garbage.csv"
    trials.write_bytes(GARBAGE)
    assert main(["calibrate", str(trials)]) == 2
    not_utf8(capsys, trials, "trials file")


def test_not_utf8_names_the_line_and_column_of_the_first_bad_byte(capsys, tmp_path):
    trials = tmp_path / "latin1.csv"
    trials.write_bytes(b"kind,command_distance_m\nforward,0.5 # caf\xe9\n")
    assert main(["calibrate", str(trials)]) == 2
    one_error_line(capsys, f"{trials}:2: not UTF-8 text: byte 0xe9 at column 18")


def test_camera_not_utf8(capsys, garbage, photos, tmp_path):
    code = main(["detect", str(photos), "--camera", str(garbage), "--out", str(tmp_path / "zz.jsonl"), "--static"])
    assert code == 2
    not_utf8(capsys, garbage, "camera file")


def test_landmarks_not_utf8_on_detect(capsys, garbage, camera, photos, tmp_path):
    code = main(["detect", str(photos), "--camera", str(camera), "--kind", "colour", "--landmarks", str(garbage),
                 "--out", str(tmp_path / "zz.jsonl"), "--static"])
    assert code == 2
    not_utf8(capsys, garbage, "landmark file")


def test_landmarks_not_utf8_on_tune_colours(capsys, garbage, camera, photos, tmp_path):
    code = main(["tune-colours", str(photos), "--camera", str(camera), "--out", str(tmp_path / "t.yaml"),
                 "--landmarks", str(garbage)])
    assert code == 2
    not_utf8(capsys, garbage, "landmark file")


def test_landmarks_not_utf8_on_live(capsys, garbage, tmp_path):
    code = main(["live", "--port", "sim", "--kind", "colour", "--landmarks", str(garbage),
                 "--out", str(tmp_path / "lv.jsonl")])
    assert code == 2
    not_utf8(capsys, garbage, "landmark file")


def test_waypoints_not_utf8_on_live(capsys, garbage, tmp_path):
    assert main(["live", "--port", "sim", "--out", str(tmp_path / "lv.jsonl"), "--path", str(garbage)]) == 2
    not_utf8(capsys, garbage, "waypoint file")


def test_yaml_errors_are_one_line(capsys, camera, photos, tmp_path):
    """yaml's own messages span several lines; the camera and landmark errors keep one."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2\nb: {\n")
    control = tmp_path / "control.yaml"
    control.write_text("a: \x01\n")
    assert main(["detect", str(photos), "--camera", str(bad), "--out", str(tmp_path / "o.jsonl"), "--static"]) == 2
    one_error_line(capsys, f"{bad}:2: not valid YAML")
    assert main(["tune-colours", str(photos), "--camera", str(camera), "--out", str(tmp_path / "t.yaml"),
                 "--landmarks", str(control)]) == 2
    one_error_line(capsys, str(control), "not valid YAML/JSON")


# --------------------------------------------------------------------------- calibration contents


def write_json(path: Path, data) -> Path:
    path.write_text(json.dumps(data))
    return path


def test_bad_calibration_on_run_is_one_line(capsys, small_log, tmp_path):
    cal = write_json(tmp_path / "badcal.json", BAD_CALIBRATION)
    code = main(["run", str(small_log), "--out", str(tmp_path / "rc1"), "--calibration", str(cal),
                 "--estimators", "ekf-s001,isam2", "--no-report"])
    assert code == 2
    run_line = one_error_line(capsys, str(cal), "forward", "fgslam calibrate")
    code = main(["record", "--port", "sim", "--model", "create2", "--out", str(tmp_path / "r.jsonl"),
                 "--calibration", str(cal)])
    assert code == 2
    assert one_error_line(capsys, str(cal)) == run_line  # the same check on both paths
    assert not (tmp_path / "rc1" / "metrics.json").exists()


def _good(good_calibration) -> dict:
    return json.loads(good_calibration.read_text())


@pytest.mark.parametrize("change, says", [
    (lambda d: d.update(pooled_motion_covariance="x"), "pooled_motion_covariance must be a 3×3 matrix"),
    (lambda d: d.update(pooled_motion_covariance=[[1, 0, 0], [0, 1, 0]]), "pooled_motion_covariance must be a 3×3"),
    (lambda d: d["pooled_motion_covariance"][0].__setitem__(1, 5.0), "not symmetric"),
    (lambda d: d.update(pooled_motion_covariance=[[-1, 0, 0], [0, 1, 0], [0, 0, 1]]), "negative eigenvalue"),
    (lambda d: d["forward"]["covariance_per_m"][2].__setitem__(2, "abc"), "forward.covariance_per_m[2][2]"),
    (lambda d: d["rotate"].pop("covariance_per_rad"), "rotate lacks covariance_per_rad"),
    (lambda d: d["rotate"].update(trials=1), "rotate.trials must be a whole number >= 2"),
    (lambda d: d["forward"].update(bias=[0, 0]), "forward.bias must be a list of 3 numbers"),
    (lambda d: d["observation"].update(sigma_range_m=float("nan")), "field 'observation.sigma_range_m' is not a number"),
    (lambda d: d["observation"].update(sigma_range_m=1e308), "observation.sigma_range_m must be a finite number within"),
    (lambda d: d["observation"].update(sigma_bearing_rad=-0.1), "observation.sigma_bearing_rad must be >= 0"),
    (lambda d: d.update(observation=5), "observation must be null or an object"),
    (lambda d: d.update(forward=None, rotate=None, pooled_motion_covariance=None, observation=None),
     "holds no calibration"),
])
def test_bad_calibration_contents(capsys, good_calibration, tmp_path, change, says):
    from slamio.noise.trials import load_calibration

    data = _good(good_calibration)
    change(data)
    cal = write_json(tmp_path / "cal.json", data)
    with pytest.raises(FgslamError, match=None) as caught:
        load_calibration(cal)
    message = str(caught.value)
    assert message.startswith(f"{cal}:") and says in message and "\n" not in message, message
    # record goes through load_calibration before the port is opened
    assert main(["record", "--port", "sim", "--model", "create2", "--out", str(tmp_path / "r.jsonl"),
                 "--calibration", str(cal)]) == 2
    one_error_line(capsys, str(cal), says)


def test_good_calibration_still_loads(good_calibration):
    from slamio.noise.trials import load_calibration

    c = load_calibration(good_calibration)
    assert c.forward["trials"] == 30 and c.observation["trials"] == 15


def test_bad_calibration_in_a_log_header_is_one_line(capsys, small_log, tmp_path):
    """A log whose header carries a broken noise.calibration (edited by hand): seed 001's EKF
    says so in one line instead of a ValueError."""
    from ekf.signature_ekf import trial_calibration
    from slamio.log import read_log

    lines = small_log.read_text().splitlines(keepends=True)
    header = json.loads(lines[0])
    header["noise"]["calibration"] = {**BAD_CALIBRATION, "forward": None, "observation": None}
    bad_log = tmp_path / "header.jsonl"
    bad_log.write_text(json.dumps(header) + "\n" + "".join(lines[1:]))
    h = read_log(bad_log).header
    with pytest.raises(FgslamError, match=r"noise\.calibration.*pooled_motion_covariance"):
        trial_calibration(h)
    assert trial_calibration(dataclasses.replace(h, noise={})) == (None, None)
    code = main(["run", str(bad_log), "--out", str(tmp_path / "r"), "--estimators", "ekf-s001,isam2", "--no-report"])
    assert code == 1
    one_error_line(capsys, "noise.calibration", "pooled_motion_covariance")


# --------------------------------------------------------------------------- check's tolerances


@pytest.mark.parametrize("option, value, allowed", [
    ("--max-nees-outside", "2", "[0, 1]"),
    ("--max-nees-outside", "-0.1", "[0, 1]"),
    ("--max-nees-outside", "nan", "[0, 1]"),
    ("--max-nees-outside", "inf", "[0, 1]"),
    ("--max-ate", "-1", ">= 0"),
    ("--max-ate", "nan", ">= 0"),
    ("--max-ate", "inf", ">= 0"),
    ("--max-ate", "x", ">= 0"),
])
def test_check_rejects_tolerance_options_out_of_range(capsys, tmp_path, option, value, allowed):
    missing_log = tmp_path / "never-read.jsonl"  # refused before the log is even read
    with pytest.raises(SystemExit) as stopped:  # argparse's error path: one line, exit 1
        main(["check", str(missing_log), option, value])
    assert stopped.value.code == 1
    one_error_line(capsys, option, allowed)


def test_check_accepts_tolerance_options_at_the_ends_of_their_range():
    from fgslam.cli import build_parser

    args = build_parser().parse_args(["check", "x.jsonl", "--max-ate", "0", "--max-nees-outside", "1"])
    assert (args.max_ate, args.max_nees_outside) == (0.0, 1.0)
    args = build_parser().parse_args(["check", "x.jsonl", "--max-ate", "2.5", "--max-nees-outside", "0"])
    assert (args.max_ate, args.max_nees_outside) == (2.5, 0.0)


@pytest.mark.parametrize("text, says", [
    ("[defaults]\nmax_nees_outside = 5\n", "max_nees_outside must be a finite number in [0, 1]"),
    ("[defaults]\nmax_nees_outside = nan\n", "max_nees_outside must be a finite number in [0, 1]"),
    ("[ekf]\nmax_nees_outside = -0.5\n", "[ekf] max_nees_outside must be a finite number in [0, 1]"),
    ("[defaults]\nmax_ate_m = -3\n", "max_ate_m must be a finite number >= 0"),
    ("[defaults]\nmax_ate_m = nan\n", "max_ate_m must be a finite number >= 0"),
    ("[defaults]\nmax_ate_m = inf\n", "max_ate_m must be a finite number >= 0"),
    ("[defaults]\nmax_ate_m = true\n", "max_ate_m must be a finite number >= 0"),
])
def test_check_rejects_tolerance_file_out_of_range(capsys, log, tmp_path, text, says):
    tolerances = tmp_path / "tol.toml"
    tolerances.write_text(text)
    assert main(["check", str(log), "--tolerances", str(tolerances)]) == 2
    one_error_line(capsys, f"{tolerances}:2: ", says)


def test_check_estimator_checks_its_tolerances_before_reading_the_log(tmp_path):
    from fgslam.check import check_estimator, load_tolerances

    for kwargs in ({"max_ate_m": -1.0}, {"max_ate_m": float("nan")}, {"max_nees_outside": 2.0},
                   {"max_nees_outside": float("inf")}):
        with pytest.raises(FgslamError, match="must be a finite number"):
            check_estimator(tmp_path / "never-read.jsonl", **kwargs)
    good = tmp_path / "good.toml"
    good.write_text("[defaults]\nmax_ate_m = 0\nmax_nees_outside = 1\n[ekf]\nmax_ate_m = 0.8\n")
    assert load_tolerances(good, "ekf") == {"max_ate_m": 0.8, "max_nees_outside": 1.0}
