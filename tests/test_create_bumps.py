"""A bump that does not end the run (RecorderSettings.bump_ends_run False), event records, and
the normal ends of a run that its controller does not end (duration_s, the hooks' finished).

The rule and the debounce are checked on their own first; then the recorder drives the
simulated Create over its pseudo-terminal into the arena's wall, in simulated time (the
sim's clock, 20 × real time): every threshold below is robot time or robot geometry, worked
out by hand from the arena and the commands.
"""

from __future__ import annotations

import math
import struct

import builders
import pytest

from slamio.create.bumper import RELEASED, BumperState, BumperWatch, away_from_bumper
from slamio.create.controllers import PathController, path_moves
from slamio.create.link import CreateLink
from slamio.create.protocol import Opcode, OiMode
from slamio.create.record import record
from slamio.create.record_settings import RecorderSettings, status_of
from slamio.create.safety import SafetyMonitor
from slamio.create.sim import ARENA_M, ROBOT_RADIUS_M, SimulatedCreate
from slamio.errors import FgslamError
from slamio.log import Event, Odometry, iter_log, read_log

FAST = 20.0
CALM = RecorderSettings(command_timeout_s=10.0, data_timeout_s=10.0, startup_timeout_s=20.0)
START = (2.3, 1.5, 0.0)  # facing the +x wall, 0.578 m away (the disc's edge)
WALL_X_M = ARENA_M[0] - ROBOT_RADIUS_M  # where the centre stops against it


# --------------------------------------------------------------------------- the rule and the debounce


@pytest.mark.parametrize("wheels, obeyed", [
    ((200.0, 200.0), False),  # forward
    ((100.0, 0.0), False),  # a pivot on the right wheel: the centre goes forward
    ((150.0, -100.0), False),  # turning, the centre still forward
    ((-100.0, -100.0), True),  # reverse
    ((-100.0, 100.0), True),  # turn in place
    ((-150.0, 100.0), True),  # backing while turning
    ((0.0, 0.0), True),
])
def test_only_commands_that_do_not_drive_forward_are_obeyed_while_pressed(wheels, obeyed):
    for pressed in (BumperState(left=True), BumperState(right=True), BumperState(True, True)):
        assert away_from_bumper(wheels, pressed) == (wheels if obeyed else (0.0, 0.0))
    assert away_from_bumper(wheels, RELEASED) == wheels


def test_bumper_watch_debounces_presses_and_releases():
    watch = BumperWatch(debounce=2)
    assert watch.reading(0b10) is None  # one frame could be damaged
    assert watch.reading(0b00) is None and watch.reading(0b10) is None
    assert watch.reading(0b10) == BumperState(left=True) and watch.presses == 1
    assert watch.state.side == "left"
    assert watch.reading(0b11) is None and watch.reading(0b11) == BumperState(True, True)  # still one press
    assert watch.reading(0b00) is None and watch.reading(0b00) == RELEASED and watch.presses == 1
    assert watch.reading(0b01) is None and watch.reading(0b01).side == "right" and watch.presses == 2


class _Stops:
    def __init__(self):
        self.calls = 0

    def __call__(self):
        self.calls += 1


def test_monitor_that_goes_on_after_a_bump_stops_the_wheels_and_keeps_the_event():
    stops = _Stops()
    monitor = SafetyMonitor(stops, debounce=2, expected_mode=OiMode.SAFE, bump_ends_run=False)
    assert monitor.readings({7: 0b10, 35: 2}) is None and stops.calls == 0
    assert monitor.readings({7: 0b10, 35: 2}) is None  # pressed: no trip ...
    assert stops.calls == 1 and monitor.bump_stops == 1 and not monitor.tripped.is_set()  # ... but stopped
    assert monitor.bumper.state == BumperState(left=True)
    for _ in range(5):  # held down: one press, one stop
        monitor.readings({7: 0b10, 35: 2})
    assert stops.calls == 1 and monitor.take_events() == [("bump", "left")] and monitor.take_events() == []
    assert monitor.readings({7: 0b1100, 35: 2}) is None
    reason = monitor.readings({7: 0b1100, 35: 2})  # both wheels dropped: the end of the run
    assert reason.kind == "wheel-drop" and monitor.tripped.is_set() and stops.calls == 2
    assert monitor.take_events() == [("wheel-drop", "both")]


@pytest.mark.parametrize("bump_ends_run", [True, False])
def test_a_cliff_ends_the_run_and_is_an_event(bump_ends_run):
    """The OI leaves Safe for Passive by itself at a cliff; no wheel drop in packet 7."""
    monitor = SafetyMonitor(_Stops(), debounce=1, expected_mode=OiMode.SAFE, bump_ends_run=bump_ends_run)
    assert monitor.readings({7: 0, 35: OiMode.PASSIVE}).kind == "mode"
    assert monitor.take_events() == [("cliff", None)]


def test_the_default_monitor_ends_the_run_on_a_bump_as_before():
    stops = _Stops()
    monitor = SafetyMonitor(stops, debounce=1, expected_mode=OiMode.SAFE)
    assert monitor.readings({7: 0b01, 35: 2}).kind == "bump" and monitor.tripped.is_set()
    assert monitor.take_events() == [("bump", "right")] and monitor.bump_stops == 0 and stops.calls == 1


@pytest.mark.parametrize("field, value", [("duration_s", 0.0), ("duration_s", math.inf), ("max_duration_s", -1.0),
                                          ("bump_ends_run", 0)])
def test_settings_refuse_nonsense_ends(field, value):
    with pytest.raises(FgslamError, match=field):
        RecorderSettings(**{field: value})


# --------------------------------------------------------------------------- on the simulated robot


class BackOff:
    """A navigator's reaction to a bump, in robot time from the press it is told of: keep
    asking forward for 0.3 s (must not be obeyed), reverse at 0.1 m/s for 1 s, stand 0.5 s,
    turn left in place (wheels ∓0.1 m/s) for 1 s, then stand. Before the bump: forward at 0.2 m/s."""

    def __init__(self, sim: SimulatedCreate):
        self.sim = sim
        self.changes: list[tuple[float, BumperState]] = []
        self.stopped_before_told = None
        self.forward_while_pressed = 0

    def advance(self, distance_m, angle_rad):
        pass

    def bumper_changed(self, state, now_s):
        if state.pressed and self.stopped_before_told is None:
            # the monitor's stop went out before we were told: the robot obeys it while we wait
            self.stopped_before_told = builders.wait_for(lambda: self.sim.commanded_mm_s == (0.0, 0.0), 30.0)
        self.changes.append((now_s, state))

    def command(self, now_s, unread=(0.0, 0.0)):
        if not self.changes:
            return (200.0, 200.0)
        since = now_s - self.changes[0][0]
        if since < 0.3:
            self.forward_while_pressed += self.changes[-1][1].pressed
            return (200.0, 200.0)
        if since < 1.3:
            return (-100.0, -100.0)
        if 1.8 <= since < 2.8:
            return (-100.0, 100.0)
        return (0.0, 0.0)


def drive_directs(sim: SimulatedCreate) -> list[tuple[float, float, float]]:
    """(sim time, left, right) of every Drive Direct the robot received, in order."""
    out = []
    for t, c in sim.commands:
        if c[0] == Opcode.DRIVE_DIRECT:
            right, left = struct.unpack(">hh", c[1:5])
            out.append((t, float(left), float(right)))
    return out


class SimClock:
    """The sim's clock, remembering its first reading: the recorder's t0, so a stamp in the
    log is ``t0 + stamp`` on the sim's clock (the one ``sim.commands`` are timed by)."""

    def __init__(self, sim: SimulatedCreate):
        self.sim, self.t0 = sim, None

    def __call__(self) -> float:
        t = self.sim.clock()
        if self.t0 is None:
            self.t0 = t
        return t


def run_into_the_wall(tmp_path, model, settings, controller_of=BackOff, **kwargs):
    out = tmp_path / f"{model}.jsonl"
    with SimulatedCreate(model, seed=3, time_scale=FAST, start_pose=START) as sim:
        controller = controller_of(sim)
        clock = SimClock(sim)
        link = CreateLink(sim.port, model, reconnect_delay_s=0.05, reconnect_attempts=3)
        sim.unread.host_bytes_read = lambda: link.bytes_read  # paced as fgslam record paces it
        result = record(link, out, controller, settings=settings, clock=clock, **kwargs)
        assert builders.wait_for(lambda: sim.commanded_mm_s == (0.0, 0.0) and sim.mode == OiMode.PASSIVE)
        controller.t0, controller.truth = clock.t0, sim.true_pose
        commands = drive_directs(sim)
    return out, result, controller, controller.truth, commands


@pytest.fixture(scope="module", params=["create2", "create1"])
def backed_off(request, tmp_path_factory):
    settings = RecorderSettings(command_timeout_s=10.0, data_timeout_s=10.0, startup_timeout_s=20.0,
                                bump_ends_run=False, duration_s=8.0)
    return run_into_the_wall(tmp_path_factory.mktemp(request.param), request.param, settings)


def test_a_bump_stops_the_wheels_and_the_run_goes_on_to_its_duration(backed_off):
    out, result, controller, _, commands = backed_off
    assert result.reason.kind == "completed" and result.reason.message == "ran for the 8 s asked for"
    assert result.completed and result.shutdown.confirmed and result.bumps == 1
    assert status_of(result)["bumps"] == 1
    assert controller.stopped_before_told  # the robot obeyed the stop before the controller knew
    (t_press, pressed), (t_release, released) = controller.changes  # one press, then released
    assert pressed == BumperState(True, True) and released == RELEASED  # head on: both bumpers
    log = read_log(out)
    odometry = [r for r in log.records if isinstance(r, Odometry)]
    start = odometry[0].stamp_s  # written on the drive's first pass
    # the wall is 0.578 m ahead: 0.2 s at the sim's 1 m/s² to reach 0.2 m/s (0.02 m), then
    # 2.79 s from when the robot got the command; two 15 ms frames to debounce (a Create 1
    # reads every 0.1 s)
    forward_from = next(t for t, left, right in commands if left > 0)
    assert controller.t0 + t_press - forward_from > 2.99  # not before the robot can have got there
    assert t_press + 0.3 < t_release < t_press + 1.3
    assert_drove_for(odometry, result.started_s, 8.0)
    assert len(odometry) == result.records and start >= result.started_s
    assert sum(r.stamp_s > t_press + 3.0 for r in odometry) >= 10  # long after the bump, still recording


def assert_drove_for(odometry, started_s, duration_s):
    """Every record of the loop but its last came before the duration was up (each pass
    writes at most one), and the one written at the stop after it."""
    stamps = [r.stamp_s for r in odometry]
    assert all(t < started_s + duration_s for t in stamps[:-2]) and stamps[-1] >= started_s + duration_s


def test_the_bump_is_an_event_record_of_the_pose_it_happened_at(backed_off):
    out, result, controller, _, _ = backed_off
    log = read_log(out)
    (event,) = [r for r in log.records if isinstance(r, Event)]
    assert (event.kind, event.side, event.stamp_s) == ("bump", "both", controller.changes[0][0])
    at = log.records.index(event)
    assert event.pose_index == sum(isinstance(r, Odometry) for r in log.records[:at])
    assert isinstance(log.records[at + 1], Odometry) and log.records[at + 1].stamp_s >= event.stamp_s
    assert [r for r in iter_log(out)] == list(log.records)  # the streaming reader agrees


def test_forward_while_pressed_is_not_obeyed_and_the_reverse_is(backed_off):
    _, _, controller, truth, commands = backed_off
    assert controller.forward_while_pressed >= 1  # asked while pressed
    forward = [i for i, (_, left, right) in enumerate(commands) if left + right > 0]
    stop = forward[-1] + 1  # the monitor's stop, right after the last forward command
    first_turn = next(i for i, c in enumerate(commands) if c[1] < 0 < c[2])
    assert commands[stop][1:] == (0.0, 0.0) and all(i < stop or i >= first_turn for i in forward)
    after = [c[1:] for c in commands[stop:first_turn] if c[1:] != (0.0, 0.0)]
    assert after and all(c == (-100.0, -100.0) for c in after)  # only the reverse went out
    # hand-worked truth from the commands as the robot got them: back from the wall at 0.1 m/s
    # (the ramp up's loss is made up by the ramp down), then turning in place at 0.2 m/s /
    # 0.235 m = 0.851 rad/s; the controller asked 1 s of each (the robot got them as the host
    # sent them)
    reverse_from = next(t for t, left, right in commands[stop:] if (left, right) == (-100.0, -100.0))
    reverse_s = next(t for t, left, right in commands[stop:] if t > reverse_from and left == right == 0.0) - reverse_from
    turn_from = commands[first_turn][0]
    turn_s = next(t for t, left, right in commands[first_turn:] if left == right == 0.0) - turn_from
    assert reverse_s > 0.5 and turn_s > 0.5  # each asked for 1 s
    x, y, theta = truth
    # the robot takes a command on its next 15 ms step, and on a busy machine the host's stamp
    # of a command can lead or trail that step by one or two: ±3 steps of motion at each speed
    # (0.1 m/s: 4.5 mm; 0.851 rad/s: 0.038 rad) is what the commands' times can account for
    assert x == pytest.approx(WALL_X_M - 0.1 * reverse_s, abs=0.0045)
    assert y == pytest.approx(START[1], abs=1e-6)
    assert theta == pytest.approx(0.2 / 0.235 * turn_s, abs=0.038)


def test_the_log_with_a_bump_passes_validate(backed_off, capsys):
    from fgslam.cli import main

    out, _, _, _, _ = backed_off
    assert main(["validate", str(out)]) == 0
    assert "1 event (1 bump)" in capsys.readouterr().out


def test_by_default_a_bump_still_ends_the_run(tmp_path):
    out, result, controller, _, _ = run_into_the_wall(tmp_path, "create2", CALM)
    assert result.reason.kind == "bump" and result.reason.is_fault and result.bumps == 0
    assert controller.changes == []  # nobody to tell: the run is over
    events = [r for r in read_log(out).records if isinstance(r, Event)]
    assert [(e.kind, e.side) for e in events] == [("bump", "both")]


def test_a_wheel_drop_still_ends_a_run_that_goes_on_after_bumps(tmp_path):
    settings = RecorderSettings(command_timeout_s=10.0, data_timeout_s=10.0, startup_timeout_s=20.0,
                                bump_ends_run=False, duration_s=30.0)
    holder = {}

    def lift(n):  # 0.2 m on, far from the wall (0.578 m ahead)
        if holder["sim"].true_pose[0] > START[0] + 0.2:
            holder["sim"].lift()

    def controller_of(sim):
        holder["sim"] = sim
        return BackOff(sim)

    out, result, _, _, _ = run_into_the_wall(tmp_path, "create2", settings, controller_of, on_record=lift)
    assert result.reason.kind == "wheel-drop" and result.shutdown.confirmed and result.bumps == 0
    log = read_log(out)
    events = [r for r in log.records if isinstance(r, Event)]
    assert [(e.kind, e.side) for e in events] == [("wheel-drop", "both")]
    assert 2 <= events[0].pose_index == result.records - 1 and isinstance(log.records[-1], Odometry)


# --------------------------------------------------------------------------- normal ends


def test_duration_ends_a_path_normally(tmp_path):
    settings = RecorderSettings(command_timeout_s=10.0, data_timeout_s=10.0, startup_timeout_s=20.0,
                                duration_s=2.0)
    from fgslam.cli.robot_end import exit_status

    with SimulatedCreate("create2", seed=1, time_scale=FAST, arena_m=None) as sim:
        link = CreateLink(sim.port, "create2")
        result = record(link, tmp_path / "two.jsonl", PathController(path_moves("square"), settings),
                        settings=settings, clock=sim.clock)
    assert result.reason.kind == "completed" and exit_status(result) == 0
    assert result.reason.message == "ran for the 2 s asked for"
    assert_drove_for(read_log(tmp_path / "two.jsonl").records, result.started_s, 2.0)


class EnoughRecords:
    """Hooks that end the run once ``n`` odometry records are written (as ``until_landmarks`` will)."""

    def __init__(self, n):
        self.n, self.records, self.last = n, 0, -1.0

    def due(self, now_s):
        return now_s - self.last >= 0.1 - 1e-9

    def after_record(self, record, log):
        self.records += 1
        self.last = record.stamp_s

    def finished(self, now_s):
        return self.records >= self.n and f"{self.records} records written"


def test_hooks_can_end_the_run_normally(tmp_path):
    with SimulatedCreate("create2", seed=1, time_scale=FAST, arena_m=None) as sim:
        link = CreateLink(sim.port, "create2")
        result = record(link, tmp_path / "hooked.jsonl", PathController(path_moves("square"), CALM),
                        settings=CALM, clock=sim.clock, hooks=EnoughRecords(12))
    assert result.reason.kind == "completed" and result.reason.message == "12 records written"
    assert result.records == 13  # and the motion since the twelfth, written at the stop
