"""The MRCLAM importer checks every value's physical range as it reads the .dat files.

A bearing of 25 rad or a forward velocity of 86 m/s (mm/s written as m/s) is a corrupted
line, not a reading: the import stops at it and names the .dat file, the line, the value,
the limit and how to fix it, instead of writing it into the log (where `fgslam run` named
only the log's line, or, for the odometry, nothing at all). The folder here is tiny and
written in tmp_path, in the published layout (four '#' lines, tab-separated columns).
"""

from __future__ import annotations

import math

import pytest

from fgslam.cli import main
from slamio.datasets.mrclam import import_mrclam
from slamio.datasets.victoria_park import DatasetFormatError

T0 = 1248444187.0
HEADER = [
    "# UTIAS Multi-Robot Cooperative Localization and Mapping Dataset",
    "# tiny synthetic copy for fgslam tests (tests/test_mrclam_import_ranges.py)",
]
# data lines start on line 5 of every file (after the four '#' lines)
FIRST = 5


def _write(path, kind, columns, lines):
    path.write_text("\n".join(HEADER + [f"# {kind} Data Format:", "# " + "    ".join(columns)] + lines) + "\n")


def _odometry_lines():
    # 0.1 m/s straight on, then a turn, 2 s at ~67 Hz
    return [f"{T0 + k * 0.015:.3f}\t0.100\t{0.0 if k < 60 else 0.3:.3f}" for k in range(134)]


def _groundtruth_lines():
    return [f"{T0 - 0.5 + k * 0.01:.3f}\t{1.0 + 0.001 * k:.8f}\t-2.00000000\t0.5000" for k in range(300)]


def _measurement_lines():
    # barcode 72 is landmark 6, 27 landmark 7
    return [f"{T0 + 0.3 + 0.25 * k:.3f}\t{72 if k % 2 else 27}\t{2.0 + 0.01 * k:.3f}\t{0.1 - 0.01 * k:.3f}"
            for k in range(6)]


@pytest.fixture
def folder(tmp_path):
    out = tmp_path / "MRCLAM_Dataset0"
    out.mkdir()
    _write(out / "Barcodes.dat", "Barcode", ["Subject #", "Barcode #"], ["1\t5", "2\t14", "6\t72", "7\t27"])
    _write(out / "Landmark_Groundtruth.dat", "Landmark Groundtruth",
           ["Subject #", "x [m]", "y [m]", "x std-dev [m]", "y std-dev [m]"],
           ["6\t3.00000000\t-2.00000000\t0.00005\t0.00020", "7\t3.10000000\t-1.50000000\t0.00005\t0.00020"])
    _write(out / "Robot1_Odometry.dat", "Odometry",
           ["Time [s]", "forward velocity [m/s]", "angular velocity[rad/s]"], _odometry_lines())
    _write(out / "Robot1_Measurement.dat", "Measurement",
           ["Time [s]", "Subject #", "range [m]", "bearing [rad]"], _measurement_lines())
    _write(out / "Robot1_Groundtruth.dat", "Robot Groundtruth",
           ["Time [s]", "x [m]", "y [m]", "orientation [rad]"], _groundtruth_lines())
    return out


def _replace(path, number, text):
    lines = path.read_text().split("\n")
    lines[number - 1] = text
    path.write_text("\n".join(lines))


def test_the_clean_folder_imports(folder):
    header, records = import_mrclam(folder)
    assert header.source["observations"] == 6
    assert sum(header.source["dropped"].values()) == 0


T = f"{T0 + 0.300:.3f}"


@pytest.mark.parametrize(
    "name, offset, text, value, limit",
    [
        # the user's cases: a bearing of 25 rad, a forward velocity of 86 m/s (mm/s?)
        ("Robot1_Measurement.dat", 0, f"{T}\t72\t2.000\t25.0", "25.0", "|bearing| <= pi"),
        ("Robot1_Odometry.dat", 3, f"{T0 + 0.045:.3f}\t86\t0.000", "86", "|v| <= 2 m/s"),
        ("Robot1_Odometry.dat", 70, f"{T0 + 70 * 0.015:.3f}\t-2.5\t0.000", "-2.5", "|v| <= 2 m/s"),
        ("Robot1_Odometry.dat", 70, f"{T0 + 70 * 0.015:.3f}\t0.1\t-17.2", "-17.2", "|w| <= 10 rad/s"),
        ("Robot1_Measurement.dat", 2, f"{T0 + 0.8:.3f}\t27\t2500\t0.1", "2500", "range <= 20 m"),
        ("Robot1_Measurement.dat", 3, f"{T0 + 1.05:.3f}\t72\t2.0\t-3.2", "-3.2", "|bearing| <= pi"),
        ("Robot1_Groundtruth.dat", 10, f"{T0 - 0.5 + 0.1:.3f}\t1010.0\t-2.0\t0.5", "1010.0", "|x| <= 20 m"),
        ("Robot1_Groundtruth.dat", 10, f"{T0 - 0.5 + 0.1:.3f}\t1.01\t-2000\t0.5", "-2000", "|y| <= 20 m"),
        ("Robot1_Groundtruth.dat", 10, f"{T0 - 0.5 + 0.1:.3f}\t1.01\t-2.0\t90", "90", "|orientation| <= pi"),
        ("Landmark_Groundtruth.dat", 1, "7\t3100.0\t-1.5\t0.00005\t0.0002", "3100.0", "|x| <= 20 m"),
    ],
)
def test_a_value_beyond_its_physical_limit_names_file_line_value_and_limit(folder, name, offset, text, value,
                                                                             limit):
    path = folder / name
    number = FIRST + offset
    _replace(path, number, text)
    with pytest.raises(DatasetFormatError) as err:
        import_mrclam(folder)
    message = str(err.value)
    assert message.startswith(f"{path}:{number}: ")
    assert err.value.path == str(path) and err.value.line == number
    assert f" is {value}, " in message
    assert limit in message
    assert "correct the value" in message and "delete this line" in message


def test_values_at_the_limits_and_the_datasets_rounded_pi_are_accepted(folder):
    # the real files write pi as 3.1416 (orientation, 4 decimals); a bearing of exactly
    # +-pi, 2 m/s, 10 rad/s and 20 m are still physical
    _replace(folder / "Robot1_Groundtruth.dat", FIRST + 10, f"{T0 - 0.5 + 0.1:.3f}\t1.01\t-2.0\t-3.1416")
    _replace(folder / "Robot1_Odometry.dat", FIRST + 70, f"{T0 + 70 * 0.015:.3f}\t-2.0\t10.0")
    _replace(folder / "Robot1_Measurement.dat", FIRST, f"{T}\t72\t20.0\t{math.pi!r}")
    _replace(folder / "Robot1_Measurement.dat", FIRST + 1, f"{T0 + 0.55:.3f}\t27\t2.0\t{-math.pi!r}")
    header, _ = import_mrclam(folder)
    assert header.source["observations"] == 6


def test_a_non_positive_range_is_still_dropped_and_counted(folder):
    _replace(folder / "Robot1_Measurement.dat", FIRST + 2, f"{T0 + 0.8:.3f}\t27\t-1.5\t0.1")
    header, _ = import_mrclam(folder)
    assert header.source["dropped"]["non_positive_range"] == 1
    assert header.source["observations"] == 5


def test_the_command_line_stops_with_the_dat_file_and_line_and_writes_no_log(folder, tmp_path, capsys):
    path = folder / "Robot1_Measurement.dat"
    _replace(path, FIRST, f"{T}\t72\t2.000\t25.0")
    out = tmp_path / "out.jsonl"
    assert main(["import", "mrclam", str(folder), str(out), "--robot", "1"]) == 2  # a bad input file: status 2
    err = capsys.readouterr().err
    assert f"{path}:{FIRST}:" in err and "25.0" in err and "|bearing| <= pi" in err
    assert not out.exists()
