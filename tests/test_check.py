"""`fgslam check` and `fgslam.check.assert_estimator_close` (the regression check)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from fgslam.check import assert_estimator_close, check_estimator, load_tolerances
from fgslam.cli import main
from slamio.errors import FgslamError
from slamio.log import Odometry, read_log, write_log

DATA = Path(__file__).resolve().parent.parent / "data"


@pytest.mark.parametrize("log", ["arena_octagon.jsonl", "arena_square.jsonl"])
@pytest.mark.parametrize("against", ["smoothed", "truth"])
def test_the_bundled_logs_pass_with_the_default_tolerances(log, against):
    result = assert_estimator_close(DATA / log, estimator="ekf", against=against)
    assert result.passed and result.verdict.startswith("PASS ekf vs " + against)
    assert result.ate_m < 0.05 and result.nees_outside < 0.1


@pytest.fixture(scope="module")
def overconfident_log(tmp_path_factory):
    """The bundled octagon log with every odometry covariance divided by 10 000 (σ by 100):
    an EKF that trusts its wheels far too much."""
    log = read_log(DATA / "arena_octagon.jsonl")
    records = [
        dataclasses.replace(r, covariance=tuple(tuple(v * 1e-4 for v in row) for row in r.covariance))
        if isinstance(r, Odometry) else r
        for r in log.records
    ]
    path = tmp_path_factory.mktemp("mistuned") / "overconfident.jsonl"
    write_log(path, log.header, records)
    return path


def test_a_mistuned_ekf_fails_from_the_command_line(overconfident_log, capsys):
    assert main(["check", str(overconfident_log), "--estimator", "ekf", "--against", "truth"]) == 1
    line = capsys.readouterr().out.strip()
    assert line.startswith("FAIL ekf vs truth on overconfident.jsonl") and "NEES outside" in line
    with pytest.raises(AssertionError, match="FAIL ekf"):
        assert_estimator_close(overconfident_log, estimator="ekf", against="truth")
    assert main(["check", str(DATA / "arena_octagon.jsonl")]) == 0
    assert capsys.readouterr().out.startswith("PASS ekf vs smoothed")


def test_tolerances_from_a_toml_next_to_the_log(tmp_path, capsys):
    log = tmp_path / "octagon.jsonl"
    log.write_bytes((DATA / "arena_octagon.jsonl").read_bytes())
    (tmp_path / "octagon.jsonl.check.toml").write_text(
        "[defaults]\nmax_ate_m = 0.001\n\n[isam2]\nmax_ate_m = 0.05\nmax_nees_outside = 0.2\n"
    )
    assert load_tolerances(tmp_path / "octagon.jsonl.check.toml", "isam2") == {"max_ate_m": 0.05, "max_nees_outside": 0.2}
    assert check_estimator(log, estimator="ekf").passed is False  # the file's 1 mm default
    assert check_estimator(log, estimator="ekf", max_ate_m=0.05).passed  # the call wins
    assert main(["check", str(log), "--estimator", "isam2", "--against", "truth"]) == 0
    assert "<= 0.05 m" in capsys.readouterr().out


@pytest.mark.parametrize(
    "toml, message",
    [("[defaults]\nmax_ate = 1\n", "unknown key 'max_ate'"), ("[defaults]\nmax_ate_m = -1\n", "number >= 0"),
     ("[defaults\n", "not valid TOML")],
)
def test_bad_tolerance_files_are_named(tmp_path, toml, message):
    path = tmp_path / "t.toml"
    path.write_text(toml)
    with pytest.raises(FgslamError, match=message):
        load_tolerances(path, "ekf")


def test_against_truth_needs_truth(tmp_path, capsys):
    log = read_log(DATA / "arena_square.jsonl")
    path = tmp_path / "no_truth.jsonl"
    write_log(path, log.header, [r for r in log.records if type(r).__name__ != "TruthPose"])
    assert main(["check", str(path), "--against", "truth"]) == 1
    assert "use --against smoothed" in capsys.readouterr().err
