"""slamio.create.link: pyserial serial_for_url (loop:// and a real pty), the safe exit, reconnect."""

from __future__ import annotations

import builders

import pytest
import serial

from slamio.create import protocol as p
from slamio.create.link import CreateLink, LinkError
from slamio.create.sim import SimulatedCreate
from slamio.create.stopping import CONFIRM_IDS

STOP_BYTES = p.pause_stream() + p.drive(0, p.RADIUS_STRAIGHT) + p.drive_direct(left_mm_s=0, right_mm_s=0) + p.passive()
READ_BACK = p.query_list(CONFIRM_IDS)  # after the stop: is the robot stopped? (loop:// cannot say)


def stop_then_read_back(written: bytes) -> bool:
    """The stop sequence, then only the read-back's questions."""
    at = written.rfind(STOP_BYTES)
    rest = written[at + len(STOP_BYTES):]
    return at >= 0 and rest and rest == READ_BACK * (len(rest) // len(READ_BACK))


class Spy:
    """Wraps a pyserial port and keeps every byte written, even after it is closed."""

    def __init__(self, port):
        self.port = port
        self.written = bytearray()
        self.fail_writes = False
        self.fail_flush = False

    def flush(self):
        if self.fail_flush:  # what pyserial's tcdrain raises when the USB device vanishes
            import termios

            raise termios.error(5, "Input/output error")
        return self.port.flush()

    def write(self, data):
        if self.fail_writes:
            raise serial.SerialException("write failed: [Errno 5] Input/output error")
        self.written += data
        return self.port.write(data)

    def __getattr__(self, name):
        return getattr(self.port, name)


def spy_opener(spies):
    def opener(url, **kwargs):
        spy = Spy(serial.serial_for_url(url, **kwargs))
        spies.append(spy)
        return spy

    return opener


def wait_for(predicate, timeout_s=10.0):
    return builders.wait_for(predicate, timeout_s)


def test_loop_url_round_trip_and_default_baud():
    with CreateLink("loop://", "create2", timeout_s=0.2) as link:
        assert link.baud == 115200
        link.write(p.sensors(7))
        assert link.read_exactly(2, timeout_s=2.0) == bytes([142, 7])
    assert CreateLink("loop://", "create1").baud == 57600


def test_an_answer_already_buffered_is_taken_even_past_the_deadline():
    # a host not scheduled for longer than its timeout after asking (a busy machine) finds
    # the answer waiting: it is not lost (a Create 1's distance would be lost with it)
    with CreateLink("loop://", "create1", timeout_s=0.2) as link:
        link.write(bytes([142, 7]))
        assert link.read_exactly(2, timeout_s=0.0) == bytes([142, 7])


def test_the_guardian_takes_a_buffered_answer_past_the_deadline_too():
    import os

    from slamio.create.guardian import _read_exactly

    read_end, write_end = os.pipe()
    try:
        os.write(write_end, bytes([142, 7]))
        assert _read_exactly(read_end, 2, 0.0) == bytes([142, 7])
        assert _read_exactly(read_end, 2, 0.0) == b""  # nothing buffered: gives up at once
    finally:
        os.close(read_end), os.close(write_end)


def test_exit_always_stops_the_wheels_and_returns_to_passive():
    spies = []
    with CreateLink("loop://", "create2", opener=spy_opener(spies)) as link:
        link.drive_direct(200, 200)
    assert stop_then_read_back(bytes(spies[0].written))
    assert link.last_shutdown.stopped and not link.is_open
    assert not link.last_shutdown.confirmed and "NOT confirmed" in link.last_shutdown.summary  # loop:// is no robot


def test_exit_on_an_exception_stops_too_and_the_exception_goes_on():
    spies = []
    with pytest.raises(ZeroDivisionError):
        with CreateLink("loop://", "create2", opener=spy_opener(spies)) as link:
            link.drive_direct(-100, 100)
            1 / 0
    assert stop_then_read_back(bytes(spies[0].written))


def test_create2_can_also_stop_the_oi():
    spies = []
    with CreateLink("loop://", "create2", opener=spy_opener(spies), stop_oi_on_exit=True):
        pass
    written = bytes(spies[0].written)
    assert written.endswith(p.stop_oi()) and stop_then_read_back(written[:-1])  # Stop after the read-back


def test_failed_write_reconnects_and_still_stops():
    spies = []
    with CreateLink("loop://", "create2", opener=spy_opener(spies), reconnect_delay_s=0.0) as link:
        link.drive_direct(200, 200)
        spies[0].fail_writes = True
        with pytest.raises(LinkError, match="write failed"):
            link.drive_direct(100, 100)
    assert len(spies) == 2 and bytes(spies[1].written).startswith(STOP_BYTES)
    assert link.last_shutdown.stopped and link.last_shutdown.reconnected and link.reconnects == 1


def test_open_error_names_the_port_and_the_fixes(tmp_path):
    with pytest.raises(LinkError) as error:
        CreateLink(str(tmp_path / "ttyUSB9"), "create1").open()
    message = str(error.value)
    assert "ttyUSB9" in message and "57600" in message and "dialout" in message


def test_unknown_model_is_refused():
    with pytest.raises(LinkError, match="create1, create2"):
        CreateLink("loop://", "roomba")


def test_real_pty_to_the_simulated_create_and_unplug_replug():
    with SimulatedCreate("create2", seed=0, time_scale=5.0) as sim:
        link = CreateLink(sim.port, "create2", timeout_s=0.05, reconnect_delay_s=0.05, reconnect_attempts=100)
        with link:
            link.write(p.start() + p.safe() + p.drive_direct(left_mm_s=100, right_mm_s=100))
            assert wait_for(lambda: sim.commanded_mm_s == (100.0, 100.0))
            sim.unplug()
            with pytest.raises(LinkError, match="cable unplugged"):
                for _ in range(100):
                    link.read()
            assert sim.commanded_mm_s == (100.0, 100.0)  # the robot keeps driving
            sim.replug()
        assert link.last_shutdown.stopped and link.last_shutdown.reconnected
        assert link.last_shutdown.confirmed  # the robot itself says so
        assert sim.commanded_mm_s == (0.0, 0.0) and sim.mode == p.OiMode.PASSIVE


def test_a_vanishing_device_during_flush_is_a_link_error():
    """termios.error is not an OSError: a pulled cable seen by tcdrain must still be a
    LinkError (which the recorder turns into a serial-error stop), not a crash."""
    spies = []
    link = CreateLink("loop://", "create2", opener=spy_opener(spies)).open()
    spies[0].fail_flush = True
    with pytest.raises(LinkError, match="Input/output error"):
        link.write(p.drive_direct(left_mm_s=100, right_mm_s=100))
    link.close()


def test_a_stop_is_confirmed_only_when_the_robot_reads_back_stopped():
    with SimulatedCreate("create2", seed=0, time_scale=5.0) as sim:
        with CreateLink(sim.port, "create2") as link:
            link.write(p.start() + p.safe() + p.stream([7, 35, 43, 44]) + p.drive_direct(left_mm_s=100, right_mm_s=100))
            assert wait_for(lambda: sim.commanded_mm_s == (100.0, 100.0))
        assert link.last_shutdown.confirmed and "robot stopped (confirmed)" in link.last_shutdown.summary
        with CreateLink(sim.port, "create2") as link:
            link.write(p.start() + p.safe() + p.drive_direct(left_mm_s=100, right_mm_s=100))
            assert wait_for(lambda: sim.commanded_mm_s == (100.0, 100.0))
            sim.freeze()  # the firmware hangs: the stop goes out, nothing answers
        assert link.last_shutdown.stopped and not link.last_shutdown.confirmed
        assert "NOT confirmed" in link.last_shutdown.summary and sim.commanded_mm_s == (100.0, 100.0)


def test_check_stopped_reads_the_mode_and_every_requested_velocity():
    from slamio.create.stopping import check_stopped

    assert check_stopped({35: 1, 39: 0, 41: 0, 42: 0}).confirmed
    safe = check_stopped({35: 2, 39: 0, 41: 0, 42: 0})
    assert not safe.confirmed and "safe, not passive" in safe.detail
    moving = check_stopped({35: 1, 39: 0, 41: 120, 42: -3})
    assert not moving.confirmed and "right wheel velocity is 120" in moving.detail and "-3" in moving.detail
