"""A corrupted odometry record (the robot "jumps" metres in one reading with a millimetre σ):
iSAM2 recovers from the updates GTSAM cannot factor and the run ends; `fgslam run` says
that iSAM2's final estimate is not the batch optimum, and says nothing of the kind on a
clean log."""

from __future__ import annotations

import json

import pytest

from fgslam.cli import main

ARENA = "data/arena_octagon.jsonl"


def arena_with_jump(path, jump_m: float | None):
    """The first 400 lines of the octagon log, the 21st odometry record moved ``jump_m`` forward."""
    lines = [json.loads(line) for line in open(ARENA, encoding="utf-8").read().splitlines()[:400]]
    if jump_m is not None:
        odometry = [i for i, d in enumerate(lines) if d["type"] == "odometry"]
        lines[odometry[20]]["dx_m"] += jump_m
    path.write_text("".join(json.dumps(d) + "\n" for d in lines), encoding="utf-8")
    return path


@pytest.mark.parametrize("jump_m", [10.0, 100.0])
def test_a_jump_in_the_odometry_is_recovered_from_and_reported(tmp_path, capsys, jump_m):
    log = arena_with_jump(tmp_path / "jump.jsonl", jump_m)
    code = main(["run", str(log), "--out", str(tmp_path / "out"), "--estimators", "ekf,isam2", "--no-report"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "Traceback" not in out + err
    assert "note: isam2's final estimate is not the batch optimum" in out
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert "lowered χ²/2" in metrics["smoother_short_of_optimum"]


def test_a_clean_log_gets_no_such_note(tmp_path, capsys):
    log = arena_with_jump(tmp_path / "clean.jsonl", None)
    assert main(["run", str(log), "--out", str(tmp_path / "out"), "--estimators", "ekf,isam2", "--no-report"]) == 0
    assert "batch optimum" not in capsys.readouterr().out
    assert "smoother_short_of_optimum" not in json.loads((tmp_path / "out" / "metrics.json").read_text())


def test_rounding_on_a_log_with_nothing_to_disagree_about_gets_no_note():
    """Odometry alone: iSAM2 and the batch solve both end at χ²/2 ≈ 1e-22, apart by rounding."""
    from types import SimpleNamespace

    import numpy as np

    from fgslam.runner import OPTIMUM_FLOOR, Comparison

    smoother = SimpleNamespace(name="isam2", update_failures=0)

    def note(isam2, batch):
        return Comparison([], None, np.zeros(0), smoother, (isam2, batch)).smoother_short_of_optimum()

    assert note(9.0e-23, 8.4e-23) is None
    assert note(100.0 + 0.5 * OPTIMUM_FLOOR, 100.0) is None
    assert "lowered χ²/2 from 100.2 to 100" in note(100.2, 100.0)  # 0.2 % above: said
