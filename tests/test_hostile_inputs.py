"""Hostile numbers and files through every verb that reads them (issue 40, item 6).

Every file fgslam reads — run logs, noise models, calibrations, trials CSV, camera and
landmark files, tolerance TOML, waypoints, datasets — is attacked with what no such file
holds: a FIFO (opening one waits for a writer forever), /dev/zero (never ends), a loop of
symbolic links, nesting thousands deep, 5 000-digit integers, 1e308 and infinity where a
finite value is needed, a huge CSV cell, landmark ids below 0 or at 2^31, stamps of ±1e308.
Each is refused before any work with exit status 2 and one line ``fgslam: error: FILE...``
(``FILE:LINE: ... field ...`` where the format has lines), no traceback, nothing written.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fgslam.cli import main
from slamio.errors import InputFileError, read_bytes
from slamio.safe_input import MAX_NESTING, parse_json, parse_toml, parse_yaml

ROOT = Path(__file__).resolve().parents[1]
ARENA = ROOT / "data" / "arena_octagon.jsonl"
PHOTOS = ROOT / "tests" / "data" / "apriltag-photos"
RGBD = ROOT / "tests" / "data" / "rgbd-real"
MRCLAM = ROOT / "tests" / "data" / "mrclam_excerpt"
TRIALS_HEADER = ("kind,command_distance_m,command_angle_rad,x_m,y_m,theta_rad,"
                 "true_range_m,true_bearing_rad,range_m,bearing_rad\n")


@pytest.fixture(autouse=True)
def never_hangs():
    """A FIFO opened for reading would wait forever: fail the test instead of the suite."""
    def hung(*_):
        raise AssertionError("hung: a file was opened that never ends or never opens")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def refused(capsys, argv: list[str], *words: str, never_written: tuple = ()) -> str:
    """``fgslam argv`` exits 2 with one ``fgslam: error:`` line holding ``words``; no
    traceback; none of ``never_written`` exists. Returns the line."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err, err
    lines = err.strip().splitlines()
    assert code == 2, (argv, out, err)
    assert lines and lines[0].startswith("fgslam: error: "), err
    for word in words:
        assert word in lines[0], (word, lines[0])
    for path in never_written:
        assert not Path(path).exists(), f"{path} was written"
    return lines[0]


# --------------------------------------------------------------------------- files that are not files


@pytest.fixture(params=["fifo", "dev-zero", "symlink-loop"])
def special(request, tmp_path):
    """``make(name)``: a path named ``name`` that fgslam must refuse without reading it, and
    the words that say what it is."""

    def make(name: str) -> tuple[Path, str]:
        path = tmp_path / name
        if request.param == "fifo":
            os.mkfifo(path)
            return path, "named pipe (FIFO)"
        if request.param == "dev-zero":
            path.symlink_to("/dev/zero")
            return path, "character device"
        other = path.with_name("other-" + path.name)
        path.symlink_to(other)
        other.symlink_to(path)
        return path, "loop of symbolic links"

    return make


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """The start of the arena log as if recorded (``run --noise`` refuses simulated logs)."""
    path = tmp_path_factory.mktemp("recorded") / "recorded.jsonl"
    lines = ARENA.read_text().splitlines(keepends=True)[:300]
    path.write_text("".join(lines).replace('"generator": "slamio.sim"', '"generator": "by hand"', 1))
    return path


@pytest.fixture(scope="module")
def camera(tmp_path_factory) -> Path:
    from slamio.camera.model import kinect_v1_default, save_camera

    path = tmp_path_factory.mktemp("camera") / "cam.yaml"
    save_camera(path, kinect_v1_default())
    return path


# {name: (argv with FILE for the hostile path and OUT for an output, what the file is)}
VERBS = {
    "validate": (["validate", "FILE"], "run log"),
    "run": (["run", "FILE", "--out", "OUT", "--no-report"], "run log"),
    "check": (["check", "FILE"], "run log"),
    "export": (["export", "rosbag", "FILE", "OUT"], "run log"),
    "calibrate log": (["calibrate", "FILE.jsonl"], "run log"),
    "calibrate trials": (["calibrate", "FILE", "--out", "OUT"], "trials file"),
    "run --noise": (["run", "RECORDED", "--noise", "FILE", "--out", "OUT", "--no-report"], "noise-model file"),
    "run --calibration": (["run", "ARENA", "--calibration", "FILE", "--out", "OUT", "--estimators", "ekf-s001,isam2"],
                          "calibration"),
    "record --calibration": (["record", "--port", "sim", "--model", "create2", "--calibration", "FILE",
                              "--out", "OUT"], "calibration"),
    "check --tolerances": (["check", "ARENA", "--tolerances", "FILE"], "tolerance file"),
    "detect --camera": (["detect", "PHOTOS", "--camera", "FILE", "--out", "OUT", "--static"], "camera file"),
    "tune-colours --camera": (["tune-colours", "RGBD", "--camera", "FILE", "--out", "OUT"], "camera file"),
    "tune-colours --landmarks": (["tune-colours", "RGBD", "--camera", "CAMERA", "--landmarks", "FILE", "--out", "OUT"],
                                 "landmark file"),
    "live --landmarks": (["live", "--port", "sim", "--kind", "colour", "--landmarks", "FILE", "--out", "OUT"],
                         "landmark file"),
    "live --path": (["live", "--port", "sim", "--path", "FILE", "--out", "OUT"], "waypoint file"),
    "import victoria-park": (["import", "victoria-park", "FILE", "OUT"], "Victoria Park file"),
    "import seed003": (["import", "seed003", "FILE", "OUT"], "seed-003 drive"),
    "import rosbag": (["import", "rosbag", "FILE.bag", "OUT"], "bag file"),
    "import mrclam": (["import", "mrclam", "MRCLAM", "OUT", "--robot", "1"], "MRCLAM file"),
    "import mrclam --noise": (["import", "mrclam", "MRCLAM_COPY", "OUT", "--noise", "FILE"], "noise-model file"),
}


@pytest.mark.parametrize("verb", sorted(VERBS))
def test_a_fifo_dev_zero_or_link_loop_is_refused_by_every_verb(tmp_path, capsys, special, verb, recorded, camera):
    argv, what = VERBS[verb]
    out = tmp_path / "out"
    mrclam = tmp_path / "mrclam"
    if "MRCLAM" in argv:  # the dataset folder with its odometry file the hostile one
        shutil.copytree(MRCLAM, mrclam)
        (mrclam / "Robot1_Odometry.dat").unlink()
        path, kind = special("mrclam/Robot1_Odometry.dat")
    else:
        path, kind = special("hostile.bag" if "FILE.bag" in argv else "hostile.jsonl" if "FILE.jsonl" in argv
                             else "hostile")
    replace = {"FILE": path, "FILE.jsonl": path, "FILE.bag": path, "OUT": out, "RECORDED": recorded,
               "ARENA": ARENA, "PHOTOS": PHOTOS, "RGBD": RGBD, "CAMERA": camera, "MRCLAM": mrclam,
               "MRCLAM_COPY": MRCLAM}
    words = (kind, str(path)) if kind == "loop of symbolic links" and verb == "run" else (what, kind, str(path))
    refused(capsys, [replace.get(a, a) for a in argv], *words, never_written=(out,))  # run resolves the path first


def test_dev_zero_itself(capsys, tmp_path):
    refused(capsys, ["validate", "/dev/zero"], "/dev/zero: the run log is a character device")
    refused(capsys, ["calibrate", "/dev/zero", "--out", tmp_path / "c.json"], "/dev/zero: the trials file",
            never_written=(tmp_path / "c.json",))


def test_a_folder_given_as_a_file_says_so(tmp_path, capsys):
    refused(capsys, ["validate", tmp_path], "is a folder", "give the file inside it")


def test_a_regular_file_larger_than_the_cap_is_refused_without_reading_it(tmp_path):
    path = tmp_path / "big.json"
    with open(path, "wb") as f:
        f.truncate(2**20 + 1)  # sparse: no disk used
    with pytest.raises(InputFileError, match=r"1048577 bytes, more than the 1 MiB"):
        read_bytes(path, "noise-model file", limit=2**20)


def test_a_symlink_loop_in_the_log_path_of_run_is_one_line(tmp_path, capsys):
    """run resolves the log's path for its manifest: Python < 3.13 says a loop there as a
    RuntimeError, which the CLI turns into the same one line."""
    (tmp_path / "a.jsonl").symlink_to(tmp_path / "b.jsonl")
    (tmp_path / "b.jsonl").symlink_to(tmp_path / "a.jsonl")
    refused(capsys, ["run", tmp_path / "a.jsonl", "--out", tmp_path / "r"], "loop of symbolic links",
            never_written=(tmp_path / "r",))


# --------------------------------------------------------------------------- run logs: stamps and ids


def arena_lines(count: int = 120) -> list[dict]:
    return [json.loads(line) for line in ARENA.read_text().splitlines()[:count]]


def log_with(tmp_path: Path, change) -> tuple[Path, int]:
    """The start of the arena log with one record changed; (path, the changed line)."""
    records = arena_lines()
    line = change(records)
    path = tmp_path / "hostile.jsonl"
    path.write_text("".join(json.dumps(d) + "\n" for d in records))
    return path, line


def set_first(kind: str, **fields):
    def change(records: list[dict]) -> int:
        index = next(i for i, d in enumerate(records) if i > 0 and d["type"] == kind)
        records[index].update(fields)
        return index + 1
    return change


def set_start_stamp(value):
    def change(records: list[dict]) -> int:
        records[0]["start"]["stamp_s"] = value
        return 1
    return change


LOG_CASES = {
    "stamp 1e308": (set_first("odometry", stamp_s=1e308), "stamp_s", "beyond ±1e+10 s"),
    "stamp -1e308 in the header": (set_start_stamp(-1e308), "stamp_s", "beyond ±1e+10 s"),
    "stamp in nanoseconds": (set_first("truth_pose", stamp_s=1.7e18), "stamp_s", "nanoseconds"),
    "landmark id -1": (set_first("observation", landmark_id=-1), "landmark_id", "0 ≤ id < 2^31"),
    "landmark id 2^31": (set_first("observation", landmark_id=2**31), "landmark_id", "0 ≤ id < 2^31"),
    "truth id 2^63": (set_first("truth_landmark", landmark_id=2**63), "landmark_id", "0 ≤ id < 2^31"),
    "range 1e308": (set_first("observation", range_m=1e308), "range_m", "outside"),
    "truth x 1e308": (set_first("truth_pose", x_m=1e308), "x_m", "beyond"),
}


@pytest.mark.parametrize("case", sorted(LOG_CASES))
@pytest.mark.parametrize("verb", ["validate", "run", "check", "export"])
def test_hostile_numbers_in_a_log_name_the_file_line_and_field(tmp_path, capsys, case, verb):
    change, field, words = LOG_CASES[case]
    path, line = log_with(tmp_path, change)
    out = tmp_path / "out"
    argv = {"validate": ["validate", path], "run": ["run", path, "--out", out], "check": ["check", path],
            "export": ["export", "rosbag", path, out]}[verb]
    refused(capsys, argv, f"{path}:{line}: ", f"'{field}'", words, never_written=(out,))


def test_a_5000_digit_integer_and_deep_nesting_in_a_log(tmp_path, capsys):
    header = ARENA.read_text().splitlines()[0]
    path = tmp_path / "digits.jsonl"
    path.write_text(header + "\n" + '{"type": "truth_pose", "stamp_s": ' + "9" * 5000 + ', "x_m": 0, "y_m": 0}\n')
    refused(capsys, ["validate", path], f"{path}:2: ", "digits")
    path.write_text(header + "\n" + "[" * 100_000 + "]" * 100_000 + "\n")
    refused(capsys, ["run", path, "--out", tmp_path / "r"], f"{path}:2: ", "nested too deeply",
            never_written=(tmp_path / "r",))


def test_3d_estimators_map_ids_to_dense_columns(tmp_path):
    """Track ids up to 2^31 - 1: the estimators key landmarks by id, never one slot per possible id."""
    from ekf.vio import VioEkf
    from fgslam.runner3d import prepare_log3d
    from slamio.log import read_log

    log_path = tmp_path / "stereo.jsonl"
    assert main(["sim", "stereo-loop", "--seed", "1", "--out", str(log_path)]) == 0
    renumbered = []
    for line in log_path.read_text().splitlines():
        d = json.loads(line)
        if d.get("type") == "stereo_observation":
            d["track_id"] = 2**31 - 1 - d["track_id"]
        if d.get("type") == "truth_landmark3":
            d["landmark_id"] = 2**31 - 1 - d["landmark_id"]
        renumbered.append(json.dumps(d))
    big = tmp_path / "big_ids.jsonl"
    big.write_text("\n".join(renumbered) + "\n")
    small, large = prepare_log3d(read_log(log_path)), prepare_log3d(read_log(big))
    ids, pixels = large.inputs[0].ids, large.inputs[0].pixels
    assert len(ids) and min(ids) > 2**30 and pixels.shape == (len(ids), 4)
    estimates = []
    for ready in (small, large):
        vio = ready.estimator("ekf-vio")
        assert isinstance(vio, VioEkf)
        for args in ready.inputs[:20]:
            vio.step(*args)
        estimates.append(vio)
    assert min(estimates[1].landmarks()) > 2**30
    assert np.allclose(estimates[0].current_pose(), estimates[1].current_pose())


# --------------------------------------------------------------------------- side files: numbers and nesting


def noise_model(**observation) -> dict:
    return {"format": "fgslam-noise-model", "version": 1, "observation": observation}


def calibration(matrix) -> dict:
    return {"format": "fgslam-calibration", "version": 1, "pooled_motion_covariance": matrix}


SIDE_CASES = {
    # name: (file name, text, verb (FILE, OUT), words)
    "noise 1e308": ("n.json", json.dumps(noise_model(range_scale=1e308), indent=1), "run --noise",
                    ("n.json:5: ", "observation.range_scale", "within")),
    "noise Infinity": ("n.json", '{\n "format": "fgslam-noise-model",\n "version": 1,\n "odometry": {"lag_s": Infinity}}',
                       "run --noise", ("n.json:4: ", "'odometry.lag_s'", "not a number")),
    "noise 5000 digits": ("n.json", '{"format": "fgslam-noise-model",\n"version": ' + "9" * 5000 + "}", "run --noise",
                          ("n.json:2: ", "'version'", "5000 digits")),
    "noise deep": ("n.json", "[" * 5000 + "]" * 5000, "run --noise", ("n.json:1: ", "nested more than 64")),
    "calibration 1e308": ("c.json", json.dumps(calibration([[1e308, 0, 0], [0, 1, 0], [0, 0, 1]]), indent=1),
                          "run --calibration", ("c.json:6: ", "pooled_motion_covariance[0][0]", "within")),
    "calibration 1e400": ("c.json", '{"format": "fgslam-calibration",\n"x": 1e400}', "record --calibration",
                          ("c.json:2: ", "'x'", "beyond the largest number")),
    "trials 1e308": ("t.csv", TRIALS_HEADER + "forward,0.5,0,1e308,0,0,,,,\n", "calibrate trials",
                     ("t.csv:2: ", "column x_m", "beyond ±1000")),
    "trials inf": ("t.csv", TRIALS_HEADER + "rotate,0,1.57,0,0,inf,,,,\n", "calibrate trials",
                   ("t.csv:2: ", "column theta_rad", "finite")),
    "trials huge cell": ("t.csv", TRIALS_HEADER + "forward,0.5,0," + "1" * 300_000 + ",0,0,,,,\n", "calibrate trials",
                         ("t.csv:2: ", "field larger than field limit")),
    "camera .inf": ("cam.yaml", "image_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3, cols: 3, "
                    "data: [.inf, 0, 319.5, 0, 525.0, 239.5, 0, 0, 1]}\n", "detect --camera",
                    ("cam.yaml:3: ", "'camera_matrix.data[0]'", "not a finite number")),
    "camera 1e308": ("cam.yaml", "image_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3, cols: 3, "
                     "data: [1.0e+308, 0, 319.5, 0, 525.0, 239.5, 0, 0, 1]}\n", "tune-colours --camera",
                     ("cam.yaml:3: ", "'camera_matrix'", "beyond")),
    "camera 5000 digits": ("cam.yaml", "image_width: " + "9" * 5000 + "\n", "detect --camera",
                           ("cam.yaml:1: ", "'image_width'", "5000 digits")),
    "camera deep": ("cam.yaml", "a: " + "[" * 3000 + "]" * 3000 + "\n", "detect --camera",
                    ("cam.yaml:1: ", "nested more than 64")),
    "camera alias": ("cam.yaml", "a: &x [1, 2]\nb: *x\n", "detect --camera", ("cam.yaml:2: ", "alias")),
    "landmark id 2^31": ("lm.yaml", "landmarks:\n  - {name: red, id: 2147483648, hsv: [[[0, 110, 60], [8, 255, 255]]]}\n",
                         "tune-colours --landmarks", ("lm.yaml:2: ", ".id", "at most 2147483647")),
    "landmark id -1": ("lm.yaml", "landmarks:\n  - {name: red, id: -1, hsv: [[[0, 110, 60], [8, 255, 255]]]}\n",
                       "live --landmarks", ("lm.yaml:2: ", ".id", ">= 0")),
    "landmark width 1e308": ("lm.json", '{"landmarks": [\n {"name": "red", "width_m": 1e308, '
                             '"hsv": [[[0, 110, 60], [8, 255, 255]]]}]}', "tune-colours --landmarks",
                             ("lm.json:2: ", "width_m", "at most 100")),
    "tolerance inf": ("t.toml", "[defaults]\nmax_ate_m = inf\n", "check --tolerances",
                      ("t.toml:2: ", "max_ate_m", "finite")),
    "tolerance 5000 digits": ("t.toml", "[defaults]\nmax_ate_m = " + "9" * 5000 + "\n", "check --tolerances",
                              ("t.toml:2: ", "digits")),
    "tolerance deep": ("t.toml", "[defaults]\nmax_ate_m = " + "[" * 3000 + "]" * 3000 + "\n", "check --tolerances",
                       ("t.toml:2: ", "nested")),
}


@pytest.mark.parametrize("case", sorted(SIDE_CASES))
def test_hostile_numbers_in_side_files_name_the_file_line_and_field(tmp_path, capsys, case, recorded, camera):
    name, text, verb, words = SIDE_CASES[case]
    path = tmp_path / name
    path.write_text(text)
    argv, _ = VERBS[verb]
    out = tmp_path / "out"
    replace = {"FILE": path, "OUT": out, "RECORDED": recorded, "ARENA": ARENA, "PHOTOS": PHOTOS, "RGBD": RGBD,
               "CAMERA": camera}
    line = refused(capsys, [replace.get(a, a) for a in argv], *words, never_written=(out,))
    assert line.startswith(f"fgslam: error: {path}:"), line


def test_a_mistake_in_the_command_is_still_status_1(tmp_path, capsys):
    assert main(["run", str(ARENA), "--out", str(tmp_path / "r"), "--estimators", "ukf"]) == 1
    assert "Traceback" not in capsys.readouterr().err


# --------------------------------------------------------------------------- the parsers, fuzzed

json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.text(max_size=5), st.integers(-(10**18), 10**18),
              st.floats(allow_nan=False, allow_infinity=False)),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=4), inner, max_size=3)),
    max_leaves=8,
)
HOSTILE_LITERALS = ["NaN", "Infinity", "-Infinity", "1e400", "-1e999", "9" * 5000, "1" * 20]


def fields_of(value, keys=()):
    """Every (keys, leaf) of a JSON value."""
    if isinstance(value, (dict, list)) and not value:
        yield keys, value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from fields_of(v, keys + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from fields_of(v, keys + (i,))
    else:
        yield keys, value


@settings(max_examples=200, deadline=None)
@given(value=json_values, literal=st.sampled_from(HOSTILE_LITERALS), data=st.data())
def test_a_hostile_number_anywhere_in_json_names_its_line_and_field(value, literal, data):
    """One leaf replaced by a number no fgslam file holds: the error names its line and field."""
    document = {"top": value}
    leaves = list(fields_of(document))
    keys, _ = data.draw(st.sampled_from(leaves))
    target = document
    for key in keys[:-1]:
        target = target[key]
    target[keys[-1]] = "@@HERE@@"
    text = json.dumps(document, indent=1).replace('"@@HERE@@"', literal)
    line = text[: text.index(literal)].count("\n") + 1
    with pytest.raises(InputFileError) as caught:
        parse_json("f.json", text)
    message = str(caught.value)
    assert message.startswith(f"f.json:{line}: field '") and "\n" not in message, message


def assert_parsed_or_one_line_error(parse, name: str, text: str) -> None:
    """``parse(name, text)`` returns, or raises an :class:`InputFileError` of one line naming ``name``."""
    try:
        parse(name, text)
    except InputFileError as err:
        assert str(err).startswith(name) and "\n" not in str(err)


@settings(max_examples=300, deadline=None)
@given(text=st.text(alphabet=st.sampled_from(list('[]{}:,"0123456789.eE-+ \nabtrufalsn\\')), max_size=200))
def test_random_json_text_is_parsed_or_one_input_file_error(text):
    assert_parsed_or_one_line_error(parse_json, "f.json", text)


@settings(max_examples=200, deadline=None)
@given(text=st.text(alphabet=st.sampled_from(list("[]{}:,-&*!|>'\"0123456789.eE+ \nabinfx_#")), max_size=200))
def test_random_yaml_text_is_parsed_or_one_input_file_error(text):
    assert_parsed_or_one_line_error(parse_yaml, "f.yaml", text)


@settings(max_examples=200, deadline=None)
@given(text=st.text(alphabet=st.sampled_from(list("[]{}=,.\"'0123456789eE+-_ \nabinfx#")), max_size=200))
def test_random_toml_text_is_parsed_or_one_input_file_error(text):
    assert_parsed_or_one_line_error(parse_toml, "f.toml", text)


@pytest.mark.parametrize("depth, refused_", [(MAX_NESTING, False), (MAX_NESTING + 1, True), (100_000, True)])
def test_nesting_is_refused_just_beyond_the_bound(depth, refused_):
    for parse, text in ((parse_json, "[" * depth + "]" * depth), (parse_yaml, "[" * depth + "]" * depth),
                        (parse_toml, "a = " + "[" * depth + "]" * depth)):
        if refused_:
            with pytest.raises(InputFileError, match="nested"):
                parse(f"f.{parse.__name__[6:]}", text)
        else:
            parse(f"f.{parse.__name__[6:]}", text)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=300))
def test_random_bytes_as_any_side_file_are_one_input_file_error(tmp_path, data):
    from fgslam.check import load_tolerances
    from slamio.camera.landmark_file import load_landmarks
    from slamio.camera.model import load_camera
    from slamio.noise.errors import NoiseModelError
    from slamio.noise.model import load_noise_model
    from slamio.noise.trials import load_calibration, read_trials

    path = tmp_path / "side"
    path.write_bytes(data)
    for load in (load_camera, load_landmarks, load_calibration, read_trials, load_noise_model,
                 lambda p: load_tolerances(p, "ekf")):
        try:
            load(path)
        except (InputFileError, NoiseModelError) as err:
            assert "\n" not in str(err)


@pytest.mark.parametrize("cell", ["x" * 300_000, "9" * 5000, "1e308"])
def test_a_huge_or_hostile_cell_in_a_dataset_file_is_one_short_line(tmp_path, capsys, cell):
    folder = tmp_path / "mrclam"
    shutil.copytree(MRCLAM, folder)
    odometry = folder / "Robot1_Odometry.dat"
    lines = odometry.read_text().splitlines(keepends=True)
    first = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    time_s, _, w = lines[first].split()
    lines[first] = f"{time_s}\t{cell}\t{w}\n"
    odometry.write_text("".join(lines))
    out = tmp_path / "out.jsonl"
    line = refused(capsys, ["import", "mrclam", folder, out, "--robot", "1"], f"{odometry}:{first + 1}: ",
                   "column 2", never_written=(out,))
    assert len(line) < 400, line
