"""The UTIAS MRCLAM importer (slamio.datasets.mrclam) on a small fixture in the published layout.

tests/fixtures/mrclam/ is written by make_fixture.py from a known trajectory (constant
commands: a straight line, an arc crossing ±π, a stop, a turn on the spot) with exact
"ground truth" and noise-free measurements, so the importer's integration, interpolation
and id mapping can be checked against closed forms.
"""

from __future__ import annotations

import importlib.util
import math
import os
import shutil

import numpy as np
import pytest

from slamio.datasets.mrclam import import_mrclam
from slamio.datasets.mrclam_motion import CommandOdometryNoise, integrate_commands, interpolate_pose, pose_times
from slamio.datasets.victoria_park import DatasetFormatError
from slamio.errors import FgslamError
from slamio.geometry import arc_increment, compose_pose, wrap_angle
from builders import assert_log_round_trips
from slamio.log import Observation, Odometry, TruthLandmark, TruthPose, group_steps

FIXTURE = os.path.join(os.path.dirname(__file__), "fixtures", "mrclam")


def _load_generator():
    spec = importlib.util.spec_from_file_location("mrclam_make_fixture", os.path.join(FIXTURE, "make_fixture.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


gen = _load_generator()


@pytest.fixture(scope="module")
def imported():
    return import_mrclam(FIXTURE)


@pytest.fixture
def folder(tmp_path):
    """A writable copy of the fixture folder."""
    out = tmp_path / "MRCLAM_Dataset1"
    shutil.copytree(FIXTURE, out, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    return out


def data_lines(path):
    """(line number, tokens) of the non-comment lines of a .dat file, read independently."""
    out = []
    with open(path) as f:
        for number, line in enumerate(f, start=1):
            if line.strip() and not line.startswith("#"):
                out.append((number, line.split()))
    return out


# ----------------------------------------------------------------------------- layout, ids


def test_the_fixture_has_the_published_layout():
    for name in ("Barcodes.dat", "Landmark_Groundtruth.dat", "Robot1_Odometry.dat",
                 "Robot1_Measurement.dat", "Robot1_Groundtruth.dat"):
        with open(os.path.join(FIXTURE, name)) as f:
            lines = f.read().splitlines()
        assert all(line.startswith("#") for line in lines[:4]), name
        assert not lines[4].startswith("#"), name


def test_counts_and_header(imported):
    header, records = imported
    counts = {kind: sum(isinstance(r, kind) for r in records) for kind in (Odometry, Observation, TruthPose, TruthLandmark)}
    assert counts[TruthLandmark] == 15
    src = header.source
    assert src["dataset"] == "utias-mrclam" and src["robot"] == 1
    assert src["dropped"] == {"robot_sightings": 2, "unknown_barcodes": 1, "outside_run": 2, "non_positive_range": 0,
                              "uncorrectable": 0, "stale_repeats": 0}
    assert src["unknown_barcodes"] == {"99": 1}
    assert src["measurement_lines"] == len(data_lines(os.path.join(FIXTURE, "Robot1_Measurement.dat")))
    assert counts[Observation] == src["observations"] == src["measurement_lines"] - 5
    assert src["time_origin_s"] == pytest.approx(gen.T0, abs=1e-6)
    assert src["duration_s"] == 6.0
    assert counts[Odometry] + 1 == src["poses"] == len(group_steps(header, records))
    assert counts[TruthPose] == src["poses_with_truth"] == src["poses"] - src["poses_without_truth"]
    assert header.start_sigma == (1e-3, 1e-3, 1e-3)
    assert header.noise["observation"]["sigma_range_m"] == 0.1
    assert header.noise["odometry"]["forward_m2_per_s"] > 0


def test_truth_landmarks_are_the_file_values(imported):
    _, records = imported
    truth = {r.landmark_id: (r.x_m, r.y_m) for r in records if isinstance(r, TruthLandmark)}
    assert set(truth) == set(range(6, 21))
    for lid, (x, y) in gen.LANDMARKS.items():
        assert truth[lid] == (x, y)
    std = imported[0].source["landmark_truth_std_m"]
    assert std["6"] == [0.0004, 0.0005]


def test_barcodes_map_to_subject_numbers(imported):
    _, records = imported
    ids = [r.landmark_id for r in records if isinstance(r, Observation)]
    assert set(ids) <= set(range(6, 21))
    # independently: the file's barcodes of the kept lines, through Barcodes.dat
    subject = {int(b): int(s) for _, (s, b) in data_lines(os.path.join(FIXTURE, "Barcodes.dat"))}
    expected = []
    for _, (t, barcode, _r, _b) in data_lines(os.path.join(FIXTURE, "Robot1_Measurement.dat")):
        s = subject.get(int(barcode))
        if s is not None and s > 5 and gen.T0 - 1e-6 <= float(t) <= gen.T0 + 6.0 + 1e-6:
            expected.append(s)
    assert ids == expected


def test_a_changed_barcode_table_changes_the_ids(folder):
    # swap the barcodes of subjects 6 and 7
    path = folder / "Barcodes.dat"
    text = path.read_text().replace("\n6\t72\n", "\n6\tSIX\n").replace("\n7\t27\n", "\n7\t72\n").replace("6\tSIX", "6\t27")
    path.write_text(text)
    _, swapped = import_mrclam(folder)
    _, original = import_mrclam(FIXTURE)
    a = [r.landmark_id for r in original if isinstance(r, Observation)]
    b = [r.landmark_id for r in swapped if isinstance(r, Observation)]
    assert b == [{6: 7, 7: 6}.get(i, i) for i in a]


def test_robot_sightings_and_unknown_barcodes_are_dropped_and_counted(folder):
    with open(folder / "Robot1_Measurement.dat", "a") as f:
        f.write(f"{gen.T0 + 5.9:.3f}\t41\t1.0\t0.0\n")  # robot 3
        f.write(f"{gen.T0 + 5.95:.3f}\t5\t1.0\t0.0\n")  # robot 1 (its own barcode)
        f.write(f"{gen.T0 + 5.96:.3f}\t12345\t1.0\t0.0\n")
    header, _ = import_mrclam(folder)
    assert header.source["dropped"]["robot_sightings"] == 4
    assert header.source["dropped"]["unknown_barcodes"] == 2
    assert header.source["unknown_barcodes"] == {"99": 1, "12345": 1}


def test_observations_sit_at_the_pose_of_their_own_time(imported):
    """Noise-free sightings from the truth pose of their step land on the landmark."""
    header, records = imported
    landmarks = {r.landmark_id: (r.x_m, r.y_m) for r in records if isinstance(r, TruthLandmark)}
    checked = 0
    for step in group_steps(header, records):
        for o in step.observations:
            assert o.stamp_s == step.stamp_s
            if step.truth is None:
                continue
            t = step.truth
            x = t.x_m + o.range_m * math.cos(t.theta_rad + o.bearing_rad)
            y = t.y_m + o.range_m * math.sin(t.theta_rad + o.bearing_rad)
            assert math.hypot(x - landmarks[o.landmark_id][0], y - landmarks[o.landmark_id][1]) < 2e-5
            checked += 1
    assert checked > 40


# ----------------------------------------------------------------------------- odometry


def test_constant_command_integrates_to_the_closed_form_arc():
    times = np.arange(0.0, 3.0001, 1.0 / 67.0)
    v, w = np.full(times.shape, 0.3), np.full(times.shape, -0.7)
    t_from, t_to = 0.123, 2.871  # not on command times
    (dx, dy, dth), P, distance, angle, _ = integrate_commands(times, v, w, t_from, t_to, CommandOdometryNoise())
    expected = arc_increment(0.3 * (t_to - t_from), -0.7 * (t_to - t_from))
    assert (dx, dy, dth) == pytest.approx(expected, abs=1e-12)
    assert distance == pytest.approx(0.3 * (t_to - t_from), abs=1e-12)
    assert angle == pytest.approx(-0.7 * (t_to - t_from), abs=1e-12)
    assert np.all(np.linalg.eigvalsh(P) > 0)


def test_odometry_records_on_the_arc_are_closed_form_arcs(imported):
    header, records = imported
    previous = 0.0
    on_arc = 0
    for r in records:
        if isinstance(r, Odometry):
            if 2.0 <= previous and r.stamp_s <= 4.0:
                dt = r.stamp_s - previous
                assert (r.dx_m, r.dy_m, r.dtheta_rad) == pytest.approx(arc_increment(0.1 * dt, 0.3 * dt), abs=1e-7)
                assert r.distance_m == pytest.approx(0.1 * dt, abs=1e-7)
                on_arc += 1
            previous = r.stamp_s
    assert on_arc >= 5


def test_dead_reckoning_follows_the_true_trajectory(imported):
    """The fixture's robot did exactly what it was told, so odometry reproduces the truth."""
    header, records = imported
    pose = header.start_pose
    for step in group_steps(header, records)[1:]:
        o = step.odometry
        pose = compose_pose(pose, (o.dx_m, o.dy_m, o.dtheta_rad))
        x, y, th = gen.true_pose(step.stamp_s)
        # file times near 1.2e9 s parse with ~1e-7 s rounding: that bounds the agreement
        assert math.hypot(pose[0] - x, pose[1] - y) < 1e-6
        assert abs(wrap_angle(pose[2] - th)) < 1e-7


def test_covariance_is_positive_definite_when_standing_still(imported):
    _, records = imported
    still = [r for r in records if isinstance(r, Odometry) and r.distance_m == 0.0 and r.angle_rad == 0.0]
    assert still, "the fixture stands still from 4 s to 5 s"
    noise = CommandOdometryNoise()
    for r in still:
        P = np.array(r.covariance)
        assert np.all(np.linalg.eigvalsh(P) > 0)
        assert (r.dx_m, r.dy_m, r.dtheta_rad) == (0.0, 0.0, 0.0)
    times = np.array([0.0, 1.0, 2.0])
    zero = np.zeros(3)
    _, P, *_ = integrate_commands(times, zero, zero, 0.25, 1.75, noise)
    assert np.allclose(P, np.diag([noise.forward_m2_per_s, noise.lateral_m2_per_s, noise.heading_rad2_per_s]) * 1.5)
    with pytest.raises(FgslamError, match="positive definite"):
        CommandOdometryNoise(heading_rad2_per_s=0.0)


def test_covariance_grows_with_distance_independently_of_the_command_rate():
    noise = CommandOdometryNoise()
    results = []
    for rate_hz in (10.0, 67.0, 200.0):
        times = np.linspace(0.0, 2.0, int(2.0 * rate_hz) + 1)
        _, P, *_ = integrate_commands(times, np.full(times.shape, 0.25), np.zeros(times.shape), 0.0, 2.0, noise)
        results.append(P[0, 0])
    assert results == pytest.approx([noise.forward_m2_per_m * 0.5 + noise.forward_m2_per_s * 2.0] * 3, rel=1e-9)


def test_poses_are_at_every_measurement_time_and_at_most_max_step_apart(imported):
    header, records = imported
    stamps = [0.0] + [r.stamp_s for r in records if isinstance(r, Odometry)]
    assert max(b - a for a, b in zip(stamps, stamps[1:])) <= 0.5 + 1e-6
    assert stamps[-1] == 6.0
    obs_stamps = {r.stamp_s for r in records if isinstance(r, Observation)}
    assert obs_stamps <= set(stamps)
    h2, r2 = import_mrclam(FIXTURE, max_step_s=None)
    stamps2 = [r.stamp_s for r in r2 if isinstance(r, Odometry)]
    assert stamps2 == sorted(obs_stamps - {0.0})
    assert pose_times(0.0, 1.0, [], 0.3) == pytest.approx([0.25, 0.5, 0.75, 1.0])


def test_max_duration_cuts_the_run(imported):
    header, records = import_mrclam(FIXTURE, max_duration_s=2.0)
    assert max(getattr(r, "stamp_s", 0.0) for r in records) == 2.0
    assert header.source["dropped"]["outside_run"] > imported[0].source["dropped"]["outside_run"]


# ----------------------------------------------------------------------------- ground truth


def test_truth_is_exact_on_the_straight_line_and_wraps_on_the_arc(imported):
    _, records = imported
    truths = [r for r in records if isinstance(r, TruthPose)]
    straight = [t for t in truths if t.stamp_s <= 2.0]
    arc = [t for t in truths if 2.0 < t.stamp_s <= 4.0]
    assert len(straight) >= 5 and len(arc) >= 5
    for t in straight:
        x, y, th = gen.true_pose(t.stamp_s)
        assert (t.x_m, t.y_m) == pytest.approx((x, y), abs=1e-7)
        assert t.theta_rad == pytest.approx(3.0, abs=1e-12)
    crossed = False
    for t in arc:
        x, y, th = gen.true_pose(t.stamp_s)
        assert abs(wrap_angle(t.theta_rad - th)) < 1e-7  # linear in time: exact up to time parsing
        assert math.hypot(t.x_m - x, t.y_m - y) < 1e-5  # chord of a 4 mm arc between samples
        assert -math.pi <= t.theta_rad < math.pi
        crossed |= t.theta_rad < 0.0
    assert crossed, "the arc crosses +-pi"


def test_no_truth_inside_a_vicon_dropout(imported):
    header, records = imported
    steps = group_steps(header, records)
    missing = [s.stamp_s for s in steps if s.truth is None]
    assert missing and all(4.2 - 0.04 < t < 4.9 + 0.04 for t in missing)
    assert header.source["poses_without_truth"] == len(missing)
    assert all(s.truth is not None and s.truth.stamp_s == s.stamp_s for s in steps if s.stamp_s not in missing)


def test_interpolate_pose_takes_the_short_way_round():
    times = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, 3.0], [1.0, 2.0, -3.0]])  # +0.283 rad across pi
    x, y, th = interpolate_pose(times.tolist(), poses, 0.5, 10.0)
    assert (x, y) == (0.5, 1.0)
    assert th == pytest.approx(wrap_angle(3.0 + 0.5 * (2 * math.pi - 6.0)))
    assert interpolate_pose(times.tolist(), poses, 0.5, 0.9) is None
    assert interpolate_pose(times.tolist(), poses, 1.5, 10.0) is None


# ----------------------------------------------------------------------------- the log


def test_the_log_passes_validation_and_round_trips(imported, tmp_path):
    header, records = imported
    log = assert_log_round_trips(tmp_path / "mrclam.jsonl", header, records)
    assert log.has_full_truth() is False  # the dropout


def test_other_robot_and_options(folder):
    with pytest.raises(FgslamError, match="Robot2_Odometry.dat: no such file"):
        import_mrclam(folder, robot=2)
    with pytest.raises(FgslamError, match="robot must be one of"):
        import_mrclam(folder, robot=6)
    with pytest.raises(FgslamError, match="sigma_range_m"):
        import_mrclam(folder, sigma_range_m=0.0)
    header, records = import_mrclam(folder, sigma_range_m=0.3, sigma_bearing_rad=0.02)
    obs = [r for r in records if isinstance(r, Observation)]
    assert {(o.sigma_range_m, o.sigma_bearing_rad) for o in obs} == {(0.3, 0.02)}


def test_ground_truth_that_misses_the_run_is_refused(folder):
    path = folder / "Robot1_Groundtruth.dat"
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:4] + [f"{gen.T0 - 9.0 + 0.1 * i:.3f}\t1.0\t2.0\t0.0" for i in range(5)]) + "\n")
    with pytest.raises(FgslamError, match="do not overlap in time"):
        import_mrclam(folder)


# ----------------------------------------------------------------------------- malformed files


def corrupt(path, number, text):
    lines = path.read_text().split("\n")
    lines[number - 1] = text
    path.write_text("\n".join(lines))


@pytest.mark.parametrize(
    "name, number, text, expected",
    [
        ("Robot1_Odometry.dat", 7, "1248272272.941\t0.2", "2 columns, expected 3"),
        ("Robot1_Odometry.dat", 9, "1248272272.841\t0.2\t0.0", "earlier than the line before"),
        ("Robot1_Measurement.dat", 6, "1248272272.841\tseventy-two\t2.0\t0.1", "column 2 (Subject #) is not a number"),
        ("Robot1_Measurement.dat", 6, "1248272272.841\t72.5\t2.0\t0.1", "must be an integer"),
        ("Robot1_Groundtruth.dat", 10, "1248272273.0\t1.0\tnan\t0.0", "column 3 (y [m]) must be finite"),
        ("Barcodes.dat", 7, "2\t99", "subject 2 is listed twice"),
        ("Barcodes.dat", 8, "4\t14", "barcode 14 is already subject 2's"),
        ("Landmark_Groundtruth.dat", 5, "3\t1.0\t2.0\t0.001\t0.001", "subject 3 is a robot"),
    ],
)
def test_malformed_line_names_file_line_and_layout(folder, name, number, text, expected):
    path = folder / name
    corrupt(path, number, text)
    with pytest.raises(DatasetFormatError) as err:
        import_mrclam(folder)
    message = str(err.value)
    assert message.startswith(f"{path}:{number}: ")
    assert expected in message
    assert err.value.line == number


def test_layout_error_shows_the_expected_columns(folder):
    path = folder / "Robot1_Measurement.dat"
    corrupt(path, 5, "1248272272.341 72 2.0")
    with pytest.raises(DatasetFormatError, match=r"expected the layout 'Time \[s\]  Subject #  Range \[m\]  Bearing \[rad\]'"):
        import_mrclam(folder)


def test_binary_garbage_is_a_format_error(folder):
    (folder / "Barcodes.dat").write_bytes(b"# header\n\xff\xfe\x00\n")
    with pytest.raises(DatasetFormatError, match=r"Barcodes.dat:2: not plain ASCII"):
        import_mrclam(folder)


# ----------------------------------------------------------------------------- command blips, stale repeats


def test_short_zero_command_blips_are_filled_and_real_stops_kept():
    from slamio.datasets.mrclam_motion import fill_zero_blips

    t = np.array([0.0, 0.01, 0.02, 0.05, 0.06, 0.5, 1.0, 1.1])
    v = np.array([0.1, 0.0, 0.0, 0.1, 0.0, 0.1, 0.0, 0.0])
    w = np.array([0.3, 0.0, 0.0, 0.3, 0.0, 0.3, 0.0, 0.0])
    # rows 1-2: a 40 ms blip (filled); row 4: a 0.44 s stop (kept); rows 6-7: the run's end (kept)
    fv, fw, filled = fill_zero_blips(t, v, w, 0.06)
    assert filled == 1
    np.testing.assert_array_equal(fv, [0.1, 0.1, 0.1, 0.1, 0.0, 0.1, 0.0, 0.0])
    np.testing.assert_array_equal(fw, [0.3, 0.3, 0.3, 0.3, 0.0, 0.3, 0.0, 0.0])
    assert v[1] == 0.0  # the input is not changed


def test_a_reading_repeated_to_the_digit_while_moving_is_dropped(folder):
    path = folder / "Robot1_Measurement.dat"
    rows = data_lines(path)
    moving = [tokens for _, tokens in rows if float(tokens[0]) - float(rows[0][1][0]) < 3.0]  # the straight line
    t, barcode, r, b = moving[4]  # inside the run, on the move
    with open(path, "a") as f:  # the same barcode, range and bearing 0.24 s later: a stale re-report
        f.write(f"{float(t) + 0.24:.3f}\t{barcode}\t{r}\t{b}\n")
    header, _ = import_mrclam(folder)
    assert header.source["dropped"]["stale_repeats"] == 1
