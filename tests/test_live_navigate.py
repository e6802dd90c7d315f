"""``fgslam live --navigate``: a navigator drives the simulated Create in the clutter room
(lockstep: every frame and smoother step takes fixed robot time, so what happens in robot
time does not depend on this machine's speed), bumps become event records and the run
ends normally on --duration or --until-landmarks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgslam.cli import main
from fgslam.live.navigation import NavigatingController, ScanSlot, Sightings
from fgslam.navigate import Command
from slamio.create.bumper import BumperState
from slamio.log import Event, Observation, TruthLandmark, TruthPose, read_log
from slamio.scan import Scan


def test_the_navigator_drives_the_clutter_room_and_the_run_ends_on_its_duration(tmp_path, capsys):
    out = tmp_path / "vfh.jsonl"
    code = main(["live", "--port", "sim", "--world", "clutter", "--navigate", "vfh", "--duration", "12",
                 "--sim-seed", "4", "--sim-time-scale", "20", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    said = captured.out + captured.err
    assert "completed: ran for the 12 s asked for" in said and "robot stopped (confirmed)" in said
    assert "navigator:" in captured.out
    log = read_log(out)
    assert log.has_full_truth()
    assert log.header.source["navigator"] == "vfh"
    tags = [r for r in log.records if isinstance(r, TruthLandmark)]
    assert len(tags) >= 12  # the room's tags
    steps = log.steps()
    truth = [r for r in log.records if isinstance(r, TruthPose)]
    assert len(steps) > 20 and any(isinstance(r, Observation) for r in log.records)
    assert math.hypot(truth[-1].x_m - truth[0].x_m, truth[-1].y_m - truth[0].y_m) > 0.1  # it drove
    events = [r for r in log.records if isinstance(r, Event)]
    assert all(e.kind == "bump" for e in events)  # a bump is logged and the run went on


@pytest.mark.parametrize("options, message", [
    (["--navigate", "vfh", "--path", "square"], "leave out --path"),
    (["--navigate", "vfh", "--world", "arena"], "needs --world clutter"),
    (["--world", "clutter"], "give --navigate NAME"),
    (["--navigate", "vfh", "--duration", "0"], "--duration"),
    (["--navigate", "vfh", "--until-landmarks", "0"], "--until-landmarks"),
])
def test_navigation_options_are_refused_before_the_robot_moves(tmp_path, capsys, options, message):
    out = tmp_path / "never.jsonl"
    code = main(["live", "--port", "sim", "--out", str(out), *options])
    assert code == 1 and message in capsys.readouterr().err
    assert not out.exists()


def test_a_real_robot_needs_depth_to_navigate(tmp_path, capsys):
    code = main(["live", "--port", "/dev/null-robot", "--navigate", "vfh", "--out", str(tmp_path / "x.jsonl")])
    assert code == 1 and "--frames kinect:N" in capsys.readouterr().err


class _Recorder:
    name = "recorder"

    def __init__(self):
        self.seen = []

    def step(self, situation):
        self.seen.append(situation)
        return Command(0.2, 0.5, "drive")


def test_the_controller_hands_the_navigator_its_situation_and_a_bump():
    scans, sightings = ScanSlot(), Sightings()
    navigator = _Recorder()
    controller = NavigatingController(navigator, lambda: (1.0, 2.0, 0.5), scans, sightings, accel_m_s2=1e9)
    scan = Scan(np.array([-0.1, 0.1]), np.array([1.0, np.inf]), 4.0)
    scans.offer(scan, (0.9, 2.0, 0.5))
    sightings.seen([Observation(0.0, 7, 1.0, 0.1, 0.01, 0.01)])
    sightings.mapped({7: (2.0, 3.0)})
    controller.command(0.0)  # the ramp's first call: from standing
    left, right = controller.command(1.0)
    # 0.2 m/s ahead turning at 0.5 rad/s: v ∓ ω·b/2 with the Create's 0.235 m wheel base
    assert (left, right) == pytest.approx((1000 * (0.2 - 0.5 * 0.1175), 1000 * (0.2 + 0.5 * 0.1175)))
    first = navigator.seen[0]
    assert first.scan is scan and first.scan_pose == (0.9, 2.0, 0.5) and first.pose == (1.0, 2.0, 0.5)
    assert first.sightings == {7: 1} and first.landmarks == {7: (2.0, 3.0)} and not first.bumped
    controller.bumper_changed(BumperState(True, True), 1.1)
    controller.bumper_changed(BumperState(False, False), 1.12)  # released before the next step
    controller.command(1.15)
    controller.command(1.2)
    told, after = navigator.seen[2], navigator.seen[3]
    assert told.bumped and told.bump_side == "front"  # a press between two steps is not lost
    assert not after.bumped and controller.state == "drive"


def test_the_run_ends_normally_once_enough_landmarks_are_seen(tmp_path, capsys):
    out = tmp_path / "until.jsonl"
    code = main(["live", "--port", "sim", "--navigate", "explore", "--until-landmarks", "2", "--duration", "120",
                 "--sim-seed", "2", "--sim-time-scale", "20", "--out", str(out)])
    captured = capsys.readouterr()
    said = captured.out + captured.err
    assert code == 0, said
    assert "saw 2 landmarks (--until-landmarks 2)" in said and "robot stopped (confirmed)" in said
    seen = {r.landmark_id for r in read_log(out).records if isinstance(r, Observation)}
    assert len(seen) >= 2
    assert read_log(out).steps()[-1].stamp_s < 120.0  # long before the duration
