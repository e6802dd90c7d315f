"""Our TUM exports and our ATE, checked against evo (dev/test dependency only, GPL-3.0).

`evo_ape tum reference.tum <estimator>.tum` must read the files `fgslam run` writes, and its
APE translation RMSE (no alignment: every estimator here starts at the reference's first
pose, as the comparison assumes) must equal the ATE in metrics.json to 1e-6 m.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from evo.core import metrics as evo_metrics  # a dev extra (GPL-3.0): tests only, never shipped
from evo.core import sync
from evo.tools import file_interface

from fgslam.cli import main

DATA = Path(__file__).resolve().parent.parent / "data"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("evo")
    assert main(["run", str(DATA / "arena_octagon.jsonl"), "--out", str(out), "--no-report"]) == 0
    return out


def evo_ape_rmse(reference: Path, estimate: Path) -> float:
    ref = file_interface.read_tum_trajectory_file(str(reference))
    est = file_interface.read_tum_trajectory_file(str(estimate))
    ref, est = sync.associate_trajectories(ref, est)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    return float(ape.get_statistic(evo_metrics.StatisticsType.rmse))


@pytest.mark.parametrize("name", ["ekf", "isam2", "dead_reckoning", "batch"])
def test_our_ate_equals_evo_ape_translation_rmse(run_dir, name):
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert evo_ape_rmse(run_dir / "reference.tum", run_dir / f"{name}.tum") == pytest.approx(
        metrics[name]["ate_rmse_m"], abs=1e-6)
    if name != "batch":  # the batch solve has no online trajectory
        assert evo_ape_rmse(run_dir / "reference.tum", run_dir / f"{name}_online.tum") == pytest.approx(
            metrics[name]["ate_online_rmse_m"], abs=1e-6)


def test_evo_ape_command_line_reads_our_files(run_dir):
    evo_ape = Path(sys.executable).with_name("evo_ape")
    if not evo_ape.exists():
        pytest.skip("evo_ape is not installed next to this Python")
    done = subprocess.run([str(evo_ape), "tum", str(run_dir / "reference.tum"), str(run_dir / "isam2.tum")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    rmse = float(re.search(r"rmse\s+([0-9.eE+-]+)", done.stdout).group(1))
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert rmse == pytest.approx(metrics["isam2"]["ate_rmse_m"], abs=1e-6)


@pytest.mark.parametrize("name", ["ekf", "isam2"])
def test_our_rpe_equals_evo_rpe(run_dir, name):
    metrics = json.loads((run_dir / "metrics.json").read_text())
    delta = metrics["rpe_delta_frames"]
    ref = file_interface.read_tum_trajectory_file(str(run_dir / "reference.tum"))
    est = file_interface.read_tum_trajectory_file(str(run_dir / f"{name}.tum"))
    ref, est = sync.associate_trajectories(ref, est)
    for relation, key in ((evo_metrics.PoseRelation.translation_part, "rpe_trans_rmse_m"),
                          (evo_metrics.PoseRelation.rotation_angle_rad, "rpe_heading_rmse_rad")):
        rpe = evo_metrics.RPE(relation, delta=delta, delta_unit=evo_metrics.Unit.frames, all_pairs=True)
        rpe.process_data((ref, est))
        assert rpe.get_statistic(evo_metrics.StatisticsType.rmse) == pytest.approx(metrics[name][key], abs=1e-6)
