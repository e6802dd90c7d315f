"""A planar log held as columns (slamio.log.columns): the same steps as the records give,
the same errors, memory that grows with the numbers, and a run that holds no records."""

from __future__ import annotations

import dataclasses
import gc
import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fgslam.compare import compute_metrics
from fgslam.runner import compare_log, truth_trajectory
from slamio.log import LogFormatError, LogStream, Observation, event_counts, read_log, write_log
from slamio.log.columns import ColumnLog, StepColumns, columns_of, read_columns, step_stamps
from slamio.sim import simulate
from builders import retained_bytes
from test_log import headers, records_in_time_order

DATA = Path(__file__).resolve().parent.parent / "data"


def assert_same_log(path) -> ColumnLog:
    """``read_columns(path)`` answers as ``read_log(path)`` does, step for step and type for type."""
    log, columns = read_log(path), read_columns(path)
    steps, table = log.steps(), columns.steps()
    assert isinstance(table, StepColumns)
    assert_same_steps_and_notes(log, columns)
    for ours, theirs in zip(truth_trajectory(table), truth_trajectory(steps)):  # from the columns / the steps
        np.testing.assert_array_equal(ours, theirs)
    assert columns.truth_landmarks() == log.truth_landmarks()
    assert event_counts(columns.events) == event_counts(log.records)
    return columns


def assert_same_steps_and_notes(log, columns) -> None:
    """What a planar and a 3-D log in columns both answer as the records do: the steps as a
    sequence (values and types: repr tells -0.0 from 0.0 and 1.0 from 1), their stamps and
    observation count, motion, and the notes on what was cut off or rejected."""
    steps, table = log.steps(), columns.steps()
    assert len(table) == len(steps)
    assert repr(list(table)) == repr(steps)
    assert list(table) == steps
    assert repr(table[len(steps) // 2]) == repr(steps[len(steps) // 2]) and repr(table[-1]) == repr(steps[-1])
    assert repr(table[1:4]) == repr(steps[1:4])
    with pytest.raises(IndexError):
        table[len(steps)]
    assert table.observation_count == sum(len(s.observations) for s in steps)
    np.testing.assert_array_equal(step_stamps(table), step_stamps(steps))
    assert columns.has_motion() == log.has_motion()
    assert (columns.truncated, columns.rejected) == (log.truncated, log.rejected)
    assert columns.rejection_summary() == log.rejection_summary()


@pytest.mark.parametrize("name", ["arena_square.jsonl", "arena_octagon.jsonl"])
def test_the_bundled_logs_read_into_the_same_steps(name):
    assert_same_log(DATA / name)


def _range_only(record):
    """``record`` as a radio's reading when it is an observation (no bearing, no tag yaw)."""
    if not isinstance(record, Observation):
        return record
    return dataclasses.replace(record, bearing_rad=None, sigma_bearing_rad=None, tag_yaw_rad=None,
                               sigma_tag_yaw_rad=None)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_valid_log_reads_into_the_same_steps(tmp_path, data):
    """Every record kind, every optional field present or absent, a sensor mounted off the
    robot's centre (its readings moved as group_steps moves them) and range-only readings."""
    header = data.draw(headers())
    if data.draw(st.booleans()):
        header = dataclasses.replace(header, sensor={**header.sensor, "pose_on_robot": [0.2, -0.05, 0.3]})
    records = data.draw(records_in_time_order(header.stamp_s))
    radios = data.draw(st.lists(st.booleans(), min_size=len(records), max_size=len(records)))
    records = [_range_only(r) if radio else r for r, radio in zip(records, radios)]
    path = tmp_path / "run.jsonl"
    write_log(path, header, records)
    assert_same_log(path)


def test_rejected_readings_and_a_cut_off_last_line_as_read_log(tmp_path):
    lines = (DATA / "arena_square.jsonl").read_text().splitlines()
    header = json.loads(lines[0])
    header["sensor"]["max_range_m"] = 1.5  # some of the arena's readings are beyond it: rejected
    path = tmp_path / "run.jsonl"
    path.write_text("\n".join([json.dumps(header), *lines[1:]]) + "\n" + lines[5][: len(lines[5]) // 2])
    columns = assert_same_log(path)
    assert columns.rejected and columns.truncated


def both_errors(source, tmp_path, kind: str, edit, read):
    """(path, line number, read_log's error, ``read``'s error) of the log ``source`` with its
    first ``kind`` record past line 30 changed by ``edit(record)``."""
    lines = source.read_text().splitlines()
    number = next(i for i, line in enumerate(lines) if f'"{kind}"' in line and i > 30) + 1
    record = json.loads(lines[number - 1])
    edit(record)
    lines[number - 1] = json.dumps(record)
    path = tmp_path / "bad.jsonl"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogFormatError) as expected:
        read_log(path)
    with pytest.raises(LogFormatError) as got:
        read(path)
    return path, number, expected.value, got.value


def test_a_bad_line_is_the_same_error_as_read_log(tmp_path):
    path, number, expected, got = both_errors(DATA / "arena_square.jsonl", tmp_path, "observation",
                                              lambda record: record.update(range_m="far"), read_columns)
    assert str(got) == str(expected) and got.line == expected.line == number
    assert str(got).startswith(f"{path}:{number}: field 'range_m'")


def test_a_3d_log_is_refused():
    class Stream:  # what columns_of reads first: a stream whose header says 3-D
        path = "drive.jsonl"

        class header:
            is_3d = True

    with pytest.raises(ValueError, match="drive.jsonl is a 3-D log"):
        columns_of(Stream())  # type: ignore[arg-type]


def test_columns_hold_less_than_half_the_file_where_records_hold_more_than_twice_it(tmp_path):
    """A generated log (~2 MB): ~0.43 of its size in columns (~90 B an observation, ~170 B a
    pose) against ~2.8 as records; the bounds are loose, the ratio does not grow with the log."""
    header, records = simulate("grid", 3, landmarks=100, laps=1)
    path = tmp_path / "grid.jsonl"
    write_log(path, header, records)
    del records
    size = os.path.getsize(path)
    assert retained_bytes(read_columns, path) < 0.6 * size
    assert retained_bytes(read_log, path) > 2.0 * size  # the measurement tells the two apart


def _alive_observations() -> int:
    gc.collect()
    return sum(type(o) is Observation for o in gc.get_objects())


def test_a_run_on_columns_holds_no_records_and_gives_the_same_results():
    """Half-way through each estimator at most a couple of steps' observations are alive when
    the log is read into columns (all of them when it is read whole), and every figure is the
    same either way. Counted above what was alive before the log was read (other tests' data)."""
    path, names = DATA / "arena_octagon.jsonl", ["dead_reckoning", "ekf"]
    steps = read_log(path).steps()
    total, most = sum(len(s.observations) for s in steps), max(len(s.observations) for s in steps)
    del steps
    alive: dict[tuple[str, str], int] = {}
    results = {}
    for reader in (read_columns, read_log):
        before = _alive_observations()
        log = reader(path)

        def progress(done, total, name, reader=reader.__name__, before=before):
            if done > total // 2 and (reader, name) not in alive:
                alive[reader, name] = _alive_observations() - before

        results[reader.__name__] = compare_log(log, names, progress=progress)
        del log
    for name in names:
        assert alive["read_columns", name] <= 2 * most < total <= alive["read_log", name]
    timing = ("time_", "peak_memory_mb")

    def figures(result) -> dict:
        metrics = compute_metrics(result.runs, result.reference, log_path=str(path))
        return {name: {k: v for k, v in m.items() if not k.startswith(timing)} if isinstance(m, dict) else m
                for name, m in metrics.items()}

    assert figures(results["read_columns"]) == figures(results["read_log"])
    for ours, theirs in zip(results["read_columns"].runs, results["read_log"].runs):
        np.testing.assert_array_equal(ours.online, theirs.online)
        np.testing.assert_array_equal(ours.final, theirs.final)
        np.testing.assert_array_equal(ours.online_covariances, theirs.online_covariances)
        np.testing.assert_array_equal(ours.nis, theirs.nis)
        assert ours.landmarks == theirs.landmarks


def test_a_stream_read_into_columns_is_read_once(tmp_path):
    """``columns_of`` consumes the stream it is given, to its end, once: every record is visited
    once, in file order."""
    path = DATA / "arena_octagon.jsonl"
    seen: list = []
    columns = columns_of(LogStream(path), visit=seen.append)
    assert seen == list(read_log(path).records)
    assert len(columns.steps()) == len(read_log(path).steps())
