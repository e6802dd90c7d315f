"""The reader's checks between lines: a landmark's truth given twice, and a stamp earlier than
the one before it. Two lines that contradict each other are reported at the earlier one and
named both, so the good part ``fgslam`` offers (``head -n``) holds only lines known good.

Logs are built in ``tmp_path`` from the lines of ``data/arena_octagon.jsonl``: line 1 the
header, lines 2-9 the truth of landmarks 0-7, then the records from t = 0.0 s (line 281 an
observation at 8.6 s, line 282 the odometry at 8.7 s).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from fgslam.cli import main
from slamio.log import Header, LogFormatError, format_line, read_log
from slamio.log import TruthLandmark3, stereo_sensor

OCTAGON = Path(__file__).resolve().parent.parent / "data" / "arena_octagon.jsonl"
LINES = OCTAGON.read_text(encoding="utf-8").splitlines()


def write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def changed(number: int, **fields) -> str:
    """Line ``number`` (1-based) of the octagon log with ``fields`` replaced."""
    d = json.loads(LINES[number - 1])
    d.update(fields)
    return json.dumps(d)


def log_with(tmp_path: Path, name: str, replace: dict[int, str] | None = None, lines: list[str] | None = None) -> Path:
    out = list(LINES if lines is None else lines)
    for number, text in (replace or {}).items():
        out[number - 1] = text
    return write(tmp_path / name, out)


def read_error(path: Path) -> LogFormatError:
    with pytest.raises(LogFormatError) as err:
        read_log(path)
    message = str(err.value)
    assert message.startswith(f"{path}:{err.value.line}: ") and "\n" not in message, message
    return err.value


def validate(path: Path, capsys) -> tuple[int, str, str]:
    code = main(["validate", str(path)])
    out, err = capsys.readouterr()
    return code, out, err


def test_the_lines_these_tests_change_are_what_they_expect():
    assert [json.loads(x)["type"] for x in LINES[1:9]] == ["truth_landmark"] * 8
    assert [json.loads(x)["landmark_id"] for x in LINES[1:9]] == list(range(8))
    assert json.loads(LINES[280])["stamp_s"] == 8.6 and json.loads(LINES[281])["stamp_s"] == 8.7
    assert json.loads(LINES[281])["type"] == "odometry"
    assert json.loads(LINES[9])["stamp_s"] == 0.0 and json.loads(LINES[0])["start"]["stamp_s"] == 0.0


# ------------------------------------------------------------------ a landmark's truth twice


def test_two_truths_of_one_landmark_are_an_error_naming_both_lines(tmp_path, capsys):
    """The user's case: line 3's landmark_id 1 changed to 0 was read as valid, and `fgslam run`
    scored the map against 7 landmarks, id 0 at line 3's place."""
    path = log_with(tmp_path, "dup.jsonl", {3: changed(3, landmark_id=0)})
    err = read_error(path)
    message = str(err)
    assert err.line == 2  # the first definition: either line may be the wrong one
    assert message.startswith(f"{path}:2: landmark_id 0 has two truth_landmark records: ")
    assert "line 2 gives x_m 1.016, y_m 0.0, line 3 gives x_m 2.032, y_m 0.0" in message
    assert "one of them is wrong" in message and "fix its landmark_id" in message
    assert err.partial is not None and err.partial.records == ()  # nothing but the header precedes line 2

    code, out, stderr = validate(path, capsys)
    assert code == 2 and out == ""
    assert stderr.startswith(f"fgslam: error: {path}:2: landmark_id 0 has two truth_landmark records")
    assert "head -n" not in stderr  # only the header would be left


def test_a_later_conflicting_truth_keeps_only_the_lines_before_the_first(tmp_path, capsys):
    """Landmark 5 given again at the end of the log, elsewhere: reported at line 7 (its first
    truth); the good part is lines 1-6."""
    moved = json.dumps({**json.loads(LINES[6]), "x_m": 0.5, "yaw_rad": 0.25})
    path = log_with(tmp_path, "late.jsonl", lines=LINES + [moved])
    last = len(LINES) + 1
    err = read_error(path)
    assert err.line == 7
    assert f"line 7 gives x_m 1.016, y_m 3.048, yaw_rad -1.5707963267948966, line {last} gives x_m 0.5, " \
           "y_m 3.048, yaw_rad 0.25" in str(err)  # the position, and what else differs (not the height)
    assert "height_m" not in str(err)
    assert len(err.partial.records) == 5  # the truths of landmarks 0-4

    code, _, stderr = validate(path, capsys)
    assert code == 2
    assert f"{path}:7: landmark_id 5 has two truth_landmark records: line 7 gives" in stderr
    assert f"(the 6 lines before it are valid; fix or delete line 7, or keep only the good part: " \
           f"head -n 6 {path} > good.jsonl)" in stderr


def test_an_exact_repeat_is_an_error_at_the_repeat(tmp_path, capsys):
    """No writer repeats a truth (each writes one per landmark); an identical copy is refused at
    the copy, since everything before it is good."""
    path = log_with(tmp_path, "repeat.jsonl", lines=LINES[:12] + [LINES[3]] + LINES[12:])
    err = read_error(path)
    assert err.line == 13
    assert str(err) == (
        f"{path}:13: line 13 repeats line 4's truth_landmark of landmark_id 2 exactly; each landmark's truth is "
        "given once: delete line 13"
    )
    assert len(err.partial.records) == 11  # lines 2-12

    code, _, stderr = validate(path, capsys)
    assert code == 2 and f"head -n 12 {path} > good.jsonl" in stderr


def test_two_truths_of_one_landmark_in_a_3d_log(tmp_path):
    header = Header(
        stamp_s=0.0, start_pose=(0.0, 0.0, 0.0), start_sigma=(1e-6,) * 3, robot={"name": "car"},
        sensor=stereo_sensor([[700.0, 0.0, 600.0], [0.0, 700.0, 180.0], [0.0, 0.0, 1.0]], 0.5,
                             [[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]),
        noise={"odometry": {}, "observation": {}}, version=2,
        start_pose3=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0), start_sigma3=(1e-6,) * 6,
    )
    lines = [format_line(header), format_line(TruthLandmark3(4, 20.0, 5.0, 1.5)),
             format_line(TruthLandmark3(9, 1.0, 2.0, 3.0)), format_line(TruthLandmark3(4, 20.0, 5.0, -1.5))]
    err = read_error(write(tmp_path / "3d.jsonl", lines))
    assert err.line == 2
    assert "landmark_id 4 has two truth_landmark3 records: line 2 gives x_m 20.0, y_m 5.0, z_m 1.5, " \
           "line 4 gives x_m 20.0, y_m 5.0, z_m -1.5" in str(err)


def test_the_same_id_in_observations_and_distinct_truths_is_fine(tmp_path):
    log = read_log(OCTAGON)
    assert sorted(log.truth_landmarks()) == list(range(8))


# ------------------------------------------------------------------ a stamp earlier than the one before


def test_a_forward_jump_names_both_lines_and_keeps_only_lines_known_good(tmp_path, capsys):
    """The user's case: line 281's stamp 8.6 made 86.0. Line 282 (8.7) is fine, but the reader
    cannot know which of the two is wrong: the good part ends at line 280."""
    path = log_with(tmp_path, "jump.jsonl", {281: changed(281, stamp_s=86.0)})
    err = read_error(path)
    assert err.line == 281
    assert str(err) == (
        f"{path}:281: line 282's stamp_s 8.7 is earlier than line 281's 86.0: one of them is wrong; records must "
        "be written in time order (fix the wrong stamp or delete its line)"
    )
    assert len(err.partial.records) == 279  # lines 2-280: line 281 is not known good
    assert err.partial.records[-1] == read_log(OCTAGON).records[278]

    code, out, stderr = validate(path, capsys)
    assert code == 2 and out == ""
    assert stderr == (
        f"fgslam: error: {err}\n"
        f"  (the 280 lines before it are valid; fix or delete line 281, or keep only the good part: "
        f"head -n 280 {path} > good.jsonl)\n"
    )
    good = write(tmp_path / "good.jsonl", LINES[:280])  # what that head keeps reads cleanly
    assert len(read_log(good).records) == 279


def test_a_backward_jump_is_reported_the_same_way(tmp_path, capsys):
    """Line 282 (the odometry at 8.7 s) made 0.5: the pair is the same, so is the message."""
    path = log_with(tmp_path, "back.jsonl", {282: changed(282, stamp_s=0.5)})
    err = read_error(path)
    assert err.line == 281
    assert "line 282's stamp_s 0.5 is earlier than line 281's 8.6: one of them is wrong" in str(err)
    _, _, stderr = validate(path, capsys)
    assert f"head -n 280 {path} > good.jsonl" in stderr


def test_lines_without_a_stamp_between_the_two_are_skipped(tmp_path, capsys):
    """A truth_landmark (no stamp) between the pair: the earlier line is the last one with a stamp."""
    extra = json.dumps({**json.loads(LINES[1]), "landmark_id": 99})
    lines = LINES[:280] + [changed(281, stamp_s=86.0), extra] + LINES[281:]
    path = write(tmp_path / "between.jsonl", lines)
    err = read_error(path)
    assert err.line == 281
    assert "line 283's stamp_s 8.7 is earlier than line 281's 86.0" in str(err)
    _, _, stderr = validate(path, capsys)
    assert "(the 280 lines before it are valid; fix or delete line 281, " in stderr
    assert f"head -n 280 {path} > good.jsonl" in stderr


def test_a_rejected_observation_counts_as_the_earlier_line(tmp_path):
    """An observation the sensor cannot have made still has its stamp: as the earlier line of
    the pair it is left out of the good part like any other."""
    far = changed(281, stamp_s=86.0, range_m=40.0)  # above the header's max_range_m 3.5: rejected
    path = log_with(tmp_path, "rejected.jsonl", {281: far})
    err = read_error(path)
    assert err.line == 281 and "line 282's stamp_s 8.7 is earlier than line 281's 86.0" in str(err)
    assert err.partial.rejected == () and len(err.partial.records) == 279


def test_a_stamp_before_the_header_start_is_reported_at_the_header(tmp_path, capsys):
    """Line 10, the first record with a stamp, before the header's start.stamp_s: the header may
    be the wrong one, so nothing is known good (no partial, no head)."""
    path = log_with(tmp_path, "start.jsonl", {10: changed(10, stamp_s=-0.5)})
    err = read_error(path)
    assert err.line == 1 and err.partial is None
    assert str(err) == (
        f"{path}:1: line 10's stamp_s -0.5 is earlier than the header's start.stamp_s 0.0 (line 1): one of them "
        "is wrong; records must be written in time order (fix the wrong stamp or delete its line)"
    )
    code, _, stderr = validate(path, capsys)
    assert code == 2 and "head -n" not in stderr


def test_equal_stamps_are_in_order(tmp_path):
    log = read_log(log_with(tmp_path, "same.jsonl", {282: changed(282, stamp_s=8.6)}))
    assert len(log.records) == len(LINES) - 1


# ------------------------------------------------------------------ a log of only its header


@pytest.mark.parametrize("ending", ["\n", ""])
def test_a_header_only_log_is_read_and_validated_as_one_pose(tmp_path, capsys, ending):
    """Unchanged behaviour, recorded here: the reader accepts a log with no records (with or
    without a final newline) as one pose, the start; `fgslam validate` says it is valid."""
    path = tmp_path / "header.jsonl"
    path.write_text(LINES[0] + ending, encoding="utf-8")
    log = read_log(path)
    assert log.records == () and log.rejected == () and log.truncated is None
    assert [s.index for s in log.steps()] == [0] and math.isclose(log.steps()[0].stamp_s, 0.0)
    code, out, _ = validate(path, capsys)
    assert code == 0
    assert out.startswith(f"{path}: valid fgslam run log v1: 1 pose over 0.0 s, 0 observations of 0 landmarks")


# --------------------------------------------------------------------------- a key given twice


@pytest.mark.parametrize("number, key", [(1, "version"), (4, "x_m"), (282, "dx_m")])
def test_a_field_given_twice_in_one_line_is_refused(tmp_path, number, key):
    text = LINES[number - 1]
    twice = text.replace("{", "{" + json.dumps(key) + ": 0, ", 1)  # the same key again, first
    path = log_with(tmp_path, "twice.jsonl", {number: twice})
    with pytest.raises(LogFormatError) as err:
        read_log(path)
    assert err.value.line == number
    assert f"field '{key}' is given twice" in str(err.value)
    if number > 1:
        assert len(err.value.partial.records) == number - 2  # every line before it
