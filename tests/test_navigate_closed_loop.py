"""The robust navigators closed-loop in the clutter room (``clutter_world(seed)``: boxes,
pillars, colour cylinders, ~18 AprilTags seen from their front only) with the live loop's
±21° depth scan every 0.4 s: five robot-minutes each from the world's start — issue 44's
goals: no bump, never stuck more than 10 s, and ``explore`` sees ≥ 90 % of the landmarks and
revisits ≥ 80 % (met on some seeds only, see below). Two seeds each to keep CI cheap (a run costs ~3 s CPU); docs/navigate.md
has the ten-seed table (``scripts/navigate_report.py``). The step-time test prints, it does
not assert (wall-clock)."""

import numpy as np
import pytest

from fgslam.navigate import make_navigator
from fgslam.navigate.harness import drive
from slamio.clutter import clutter_world


def _run(name, seed, minutes=5.0):
    return drive(clutter_world(seed), make_navigator(name, seed=seed), duration_s=60.0 * minutes, seed=seed)


@pytest.mark.parametrize("seed", (1, 4))
def test_vfh_wanders_the_clutter_room_without_bumping_or_sticking(seed):
    result = _run("vfh", seed)
    print("vfh", seed, result.summary())
    assert result.bumps == 0
    assert result.longest_stuck_s <= 10.0
    assert result.area_seen_m2 >= 30.0  # of the room's 36 m²


@pytest.mark.parametrize("seed, seen, revisited", [(9, 0.9, 0.8), (7, 0.65, 0.55)])
def test_explore_sees_and_revisits_the_tags_without_bumping_or_sticking(seed, seen, revisited):
    """Issue 44's landmark goals hold on seed 9 (17/18 seen, 15/18 revisited); seed 7 was the
    worst of seeds 1-20 in this harness before the forward escape (13/19 seen, 11/19
    revisited; 17/19 and 13/19 with it: docs/navigate.md): a floor guards against regressions."""
    result = _run("explore", seed)
    print("explore", seed, result.summary())
    assert result.bumps == 0
    assert result.longest_stuck_s <= 10.0
    assert len(result.landmarks_seen) >= seen * result.landmark_count
    assert len(result.landmarks_revisited) >= revisited * result.landmark_count
    assert result.area_seen_m2 >= 33.0


@pytest.mark.parametrize("name", ["vfh-s000", "explore-s001"])
def test_the_seed_navigators_run_their_loops(name):
    """The seeds' flaws are reported, not asserted away: they run and move."""
    result = _run(name, 1, minutes=1.0)
    print(name, result.summary())
    assert np.ptp(result.path[:, :2], axis=0).max() > 0.3


def test_step_time_benchmark(capsys):
    for name in ("vfh-s000", "vfh", "explore-s001", "explore"):
        result = _run(name, 1, minutes=1.0)
        with capsys.disabled():
            for what, times in (("CPU", result.step_cpu_us), ("wall", result.step_time_us)):
                print(f"\n{name:13s} step {what:4s} µs: mean {times.mean():.0f}, median {np.median(times):.0f}, "
                      f"p99 {np.percentile(times, 99):.0f}, max {times.max():.0f}", end="")
