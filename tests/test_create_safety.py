"""slamio.create.safety and .signals: hazards from packets 7 and 35, the monitor, its watchdog, the
terminating signals."""

from __future__ import annotations

import os
import signal
import threading

import pytest

from slamio.create.protocol import OiMode
from slamio.create.safety import (
    SafetyMonitor,
    StopReason,
    hazard_from_bumps,
    hazard_from_mode,
    implausible_create1_reading,
    implausible_encoder_jump,
    implausible_frame,
)
from slamio.create.signals import TERMINATING_SIGNALS, Interrupted, TerminationSignals


@pytest.mark.parametrize(
    "packet7, kind, words",
    [
        (0b0001, "bump", "right bumper"),
        (0b0010, "bump", "left bumper"),
        (0b0011, "bump", "both bumpers"),
        (0b0100, "wheel-drop", "right"),
        (0b1000, "wheel-drop", "left"),
        (0b1011, "wheel-drop", "left"),  # a wheel drop outranks a bump
        (0b10000, "wheel-drop", "caster"),
    ],
)
def test_hazard_from_bumps(packet7, kind, words):
    reason = hazard_from_bumps(packet7)
    assert reason.kind == kind and words in reason.message and reason.is_fault


def test_no_hazard_when_nothing_is_pressed_or_in_the_right_mode():
    assert hazard_from_bumps(0) is None
    assert hazard_from_mode(2, OiMode.SAFE) is None
    reason = hazard_from_mode(1, OiMode.SAFE)
    assert reason.kind == "mode" and "passive" in reason.message


def test_stop_reason_kinds_are_checked():
    assert not StopReason("completed", "done").is_fault
    assert str(StopReason("bump", "x")) == "bump: x"
    with pytest.raises(ValueError):
        StopReason("oops", "x")


def test_implausible_values():
    assert implausible_frame({7: 0x20}, "create2") is not None
    assert implausible_frame({7: 0x10}, "create1") is None  # caster drop is real on a Create 1
    assert implausible_frame({35: 9}, "create2") is not None
    assert implausible_frame({7: 3, 35: 2}, "create2") is None
    assert implausible_encoder_jump(17, 0.015, 0.4446) is None  # 0.5 m/s for one frame
    assert implausible_encoder_jump(300, 0.015, 0.4446) is not None
    assert implausible_encoder_jump(300, 0.5, 0.4446) is None  # frames were lost meanwhile
    assert implausible_create1_reading(20, 4, 0.1) is None
    assert "distance" in implausible_create1_reading(5000, 4, 0.1)
    assert "angle" in implausible_create1_reading(20, 90, 0.1)


class _Stops:
    def __init__(self):
        self.calls = 0

    def __call__(self):
        self.calls += 1


def test_monitor_debounces_bumps_and_keeps_the_first_reason():
    stops = _Stops()
    monitor = SafetyMonitor(stops, debounce=2, expected_mode=OiMode.SAFE)
    assert monitor.readings({7: 1, 35: 2}) is None  # one reading could be a damaged frame
    assert monitor.readings({7: 0, 35: 2}) is None  # the streak is broken
    assert monitor.readings({7: 1, 35: 2}) is None
    reason = monitor.readings({7: 1, 35: 2})
    assert reason.kind == "bump" and monitor.tripped.is_set() and stops.calls == 1
    monitor.trip(StopReason("watchdog", "later"))
    assert monitor.reason.kind == "bump" and stops.calls == 1


def test_monitor_mode_check_waits_for_the_expected_mode():
    monitor = SafetyMonitor(_Stops(), debounce=1, expected_mode=None)
    assert monitor.readings({35: 1}) is None
    monitor.expected_mode = OiMode.SAFE
    assert monitor.readings({35: 1}).kind == "mode"


def test_stop_errors_are_kept_not_raised():
    def broken():
        raise OSError("port gone")

    monitor = SafetyMonitor(broken)
    assert monitor.trip(StopReason("serial-error", "unplugged"))
    assert monitor.reason.kind == "serial-error" and "port gone" in monitor.stop_errors[0]


def test_watchdog_thread_stops_the_motors_when_commands_stop():
    stopped = threading.Event()
    monitor = SafetyMonitor(stopped.set, command_timeout_s=0.05, data_timeout_s=60.0)
    with monitor:
        assert stopped.wait(10.0)
    assert monitor.reason.kind == "watchdog"


def test_data_timeout_stops_the_motors():
    t = [0.0]
    monitor = SafetyMonitor(_Stops(), command_timeout_s=10.0, data_timeout_s=0.5, wall_clock=lambda: t[0])
    monitor.readings({7: 0})
    t[0] = 0.4
    monitor.command_sent()
    assert monitor.check_timeouts() is None
    t[0] = 0.6
    assert monitor.check_timeouts().kind == "no-data"


@pytest.mark.parametrize("signum", TERMINATING_SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_each_terminating_signal_raises_interrupted_naming_it_once(signum):
    before = signal.getsignal(signum)
    with TerminationSignals() as signals:
        with pytest.raises(Interrupted) as raised:
            signal.raise_signal(signum)  # the handler runs in this (main) thread
        signal.raise_signal(signum)  # a second one is remembered, not raised
    assert raised.value.signum == signum and raised.value.exit_code == 128 + signum
    assert signal.Signals(signum).name in str(raised.value)
    assert signals.received == [signum, signum]
    assert signal.getsignal(signum) is before  # given back


def test_signals_inherited_as_ignored_are_caught_and_given_back_ignored():
    before = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        with TerminationSignals():
            with pytest.raises(Interrupted):
                signal.raise_signal(signal.SIGHUP)
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, before)


def test_held_signals_cannot_cut_a_block_short_and_the_first_is_raised_after_it():
    done = []
    with TerminationSignals() as signals:
        with pytest.raises(Interrupted) as raised:
            with signals.held():
                signal.raise_signal(signal.SIGTERM)
                signal.raise_signal(signal.SIGINT)  # a second signal during the stop sequence
                done.append("the whole block")
        assert raised.value.signum == signal.SIGTERM
        with signals.held(raise_after=False):  # the stop sequence: nothing raised, after it either
            signal.raise_signal(signal.SIGHUP)
            done.append("the stop")
    assert done == ["the whole block", "the stop"]
    assert signals.received == [signal.SIGTERM, signal.SIGINT, signal.SIGHUP]
