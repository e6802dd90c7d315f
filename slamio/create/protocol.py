"""The iRobot Create Open Interface (OI) as pure functions: bytes in, values out.

Nothing here touches a serial port or a clock, so every function can be tested on byte
strings. Sources: the iRobot Create Open Interface spec (Create 1) and the iRobot Create 2
Open Interface spec (Roomba 600 series); the opcodes, packets and frame layout the
driver uses are summarised below.

Commands (host → robot)
=======================

Every command is one opcode byte followed by its data bytes. 16-bit values are sent
high byte first (big-endian), two's complement when signed.

====================  ======  =================================================
function              opcode  meaning
====================  ======  =================================================
:func:`start`          128    start the OI; puts it in **Passive** mode (also
                              the way back to Passive from Safe/Full)
:func:`baud`           129    change the baud rate (code 0–11)
:func:`safe`           131    Safe mode: motors allowed, robot stops itself on
                              cliff, wheel drop or charger
:func:`full`           132    Full mode: no safety checks at all
:func:`drive`          137    velocity mm/s and turn radius mm
:func:`drive_direct`   145    [right hi lo][left hi lo] wheel speeds, mm/s
:func:`sensors`        142    ask for one packet
:func:`query_list`     149    ask for several packets (concatenated, no ids)
:func:`stream`         148    have packets sent every 15 ms in checksummed frames
:func:`pause_stream`   150 0  stop the stream (``resume_stream``: 150 1)
:func:`stop_oi`        173    Create 2 only: stop the OI (Off mode)
====================  ======  =================================================

:func:`passive` is :func:`start`: the OI has no separate "passive" opcode.

Sensor packets (robot → host)
=============================

:data:`PACKETS` lists every single packet (ids 7–58) with its size, signedness and unit.
The ones the driver depends on:

* 7  bumps and wheel drops, bit field (bit 0 right bump, 1 left bump, 2 right wheel drop,
  3 left wheel drop; bit 4 caster drop on the Create 1 only) → :class:`BumpsAndDrops`;
* 19 distance, int16 mm since it was last read (mean of both wheels);
* 20 angle, int16 degrees counter-clockwise since it was last read (1° resolution: see
  :mod:`slamio.create.odometry` for the Create 1 truncation problem);
* 35 OI mode, 0 off, 1 passive, 2 safe, 3 full → :class:`OiMode`;
* 43/44 left/right encoder counts, uint16 that wrap around (Create 2 only).

Stream frames
=============

After ``stream([ids])`` the robot sends, every 15 ms::

    [19][N][id1][data1...][id2][data2...]...[checksum]

``N`` counts the bytes between itself and the checksum, and the checksum makes the low
8 bits of the sum of *every* byte of the frame, header included, zero. The spec's example
``19 5 29 2 25 13 0 163`` is packet 29 = 2·256 + 25 = 537 and packet 13 = 0, and
19 + 5 + 29 + 2 + 25 + 13 + 0 + 163 = 256 ≡ 0.
:class:`slamio.create.stream_parser.StreamParser` finds frames in a byte stream that may
hold garbage, flipped bits and dropped bytes (see its docstring).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Iterable, Mapping, Sequence

from slamio.errors import FgslamError

__all__ = [
    "ProtocolError",
    "Opcode",
    "OiMode",
    "PacketSpec",
    "PACKETS",
    "STREAM_HEADER",
    "MAX_WHEEL_SPEED_MM_S",
    "MAX_RADIUS_MM",
    "RADIUS_STRAIGHT",
    "RADIUS_TURN_CW",
    "RADIUS_TURN_CCW",
    "BAUD_CODES",
    "start",
    "passive",
    "safe",
    "full",
    "stop_oi",
    "baud",
    "drive",
    "drive_direct",
    "sensors",
    "query_list",
    "stream",
    "pause_stream",
    "resume_stream",
    "BumpsAndDrops",
    "decode_bumps_and_drops",
    "decode_packet",
    "encode_packet",
    "decode_query_response",
    "query_response_size",
    "decode_frame_payload",
    "encode_stream_frame",
    "stream_payload_size",
    "checksum_byte",
    "frame_checksum_ok",
    "valid_packet_id",
]


class ProtocolError(FgslamError):
    """Bytes that are not what the Open Interface says they should be."""


class Opcode(enum.IntEnum):
    START = 128
    BAUD = 129
    SAFE = 131
    FULL = 132
    DRIVE = 137
    SENSORS = 142
    STREAM = 148
    QUERY_LIST = 149
    PAUSE_RESUME_STREAM = 150
    DRIVE_DIRECT = 145
    STOP = 173  # Create 2 only


class OiMode(enum.IntEnum):
    """Packet 35: the Open Interface mode."""

    OFF = 0
    PASSIVE = 1
    SAFE = 2
    FULL = 3


STREAM_HEADER = 19
MAX_WHEEL_SPEED_MM_S = 500
MAX_RADIUS_MM = 2000
RADIUS_STRAIGHT = 32768  # 0x8000: drive straight (the spec also accepts 32767)
RADIUS_TURN_CW = -1  # turn in place clockwise
RADIUS_TURN_CCW = 1  # turn in place counter-clockwise

#: Baud rate → the code the Baud command (129) takes.
BAUD_CODES = {
    300: 0, 600: 1, 1200: 2, 2400: 3, 4800: 4, 9600: 5, 14400: 6,
    19200: 7, 28800: 8, 38400: 9, 57600: 10, 115200: 11,
}


@dataclass(frozen=True)
class PacketSpec:
    """One sensor packet: its id, size in bytes, signedness and unit."""

    packet_id: int
    name: str
    size: int
    signed: bool
    unit: str = ""


def _spec_table() -> dict[int, PacketSpec]:
    rows = [
        (7, "bumps_and_wheel_drops", 1, False, "bits"),
        (8, "wall", 1, False, "bool"),
        (9, "cliff_left", 1, False, "bool"),
        (10, "cliff_front_left", 1, False, "bool"),
        (11, "cliff_front_right", 1, False, "bool"),
        (12, "cliff_right", 1, False, "bool"),
        (13, "virtual_wall", 1, False, "bool"),
        (14, "overcurrents", 1, False, "bits"),
        (15, "dirt_detect", 1, False, ""),  # Create 2; unused byte on the Create 1
        (16, "unused_16", 1, False, ""),
        (17, "infrared_omni", 1, False, "char"),
        (18, "buttons", 1, False, "bits"),
        (19, "distance", 2, True, "mm"),
        (20, "angle", 2, True, "deg"),
        (21, "charging_state", 1, False, "enum"),
        (22, "voltage", 2, False, "mV"),
        (23, "current", 2, True, "mA"),
        (24, "temperature", 1, True, "degC"),
        (25, "battery_charge", 2, False, "mAh"),
        (26, "battery_capacity", 2, False, "mAh"),
        (27, "wall_signal", 2, False, ""),
        (28, "cliff_left_signal", 2, False, ""),
        (29, "cliff_front_left_signal", 2, False, ""),
        (30, "cliff_front_right_signal", 2, False, ""),
        (31, "cliff_right_signal", 2, False, ""),
        (32, "cargo_bay_digital_inputs", 1, False, "bits"),  # Create 1; unused on Create 2
        (33, "cargo_bay_analog_signal", 2, False, ""),  # Create 1; unused on Create 2
        (34, "charging_sources_available", 1, False, "bits"),
        (35, "oi_mode", 1, False, "enum"),
        (36, "song_number", 1, False, ""),
        (37, "song_playing", 1, False, "bool"),
        (38, "number_of_stream_packets", 1, False, ""),
        (39, "requested_velocity", 2, True, "mm/s"),
        (40, "requested_radius", 2, True, "mm"),
        (41, "requested_right_velocity", 2, True, "mm/s"),
        (42, "requested_left_velocity", 2, True, "mm/s"),
        (43, "left_encoder_counts", 2, False, "counts"),  # Create 2 only
        (44, "right_encoder_counts", 2, False, "counts"),  # Create 2 only
        (45, "light_bumper", 1, False, "bits"),
        (46, "light_bump_left_signal", 2, False, ""),
        (47, "light_bump_front_left_signal", 2, False, ""),
        (48, "light_bump_center_left_signal", 2, False, ""),
        (49, "light_bump_center_right_signal", 2, False, ""),
        (50, "light_bump_front_right_signal", 2, False, ""),
        (51, "light_bump_right_signal", 2, False, ""),
        (52, "infrared_left", 1, False, "char"),
        (53, "infrared_right", 1, False, "char"),
        (54, "left_motor_current", 2, True, "mA"),
        (55, "right_motor_current", 2, True, "mA"),
        (56, "main_brush_motor_current", 2, True, "mA"),
        (57, "side_brush_motor_current", 2, True, "mA"),
        (58, "stasis", 1, False, "bits"),
    ]
    return {row[0]: PacketSpec(*row) for row in rows}


#: Every single sensor packet this module can decode, by id. Group packets (0–6, 100–107)
#: are not supported: ask for the single packets instead.
PACKETS: dict[int, PacketSpec] = _spec_table()


# --------------------------------------------------------------------------- commands


def _int16_bytes(value: int) -> bytes:
    return int(value).to_bytes(2, "big", signed=True)


def _finite_number(value: float, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ProtocolError(f"{what} must be a finite number, got {value!r}")
    return float(value)


def _clamp_speed_mm_s(speed_mm_s: float, what: str) -> int:
    speed = _finite_number(speed_mm_s, what)
    return int(round(max(-MAX_WHEEL_SPEED_MM_S, min(MAX_WHEEL_SPEED_MM_S, speed))))


def valid_packet_id(packet_id: int) -> int:
    if isinstance(packet_id, bool) or not isinstance(packet_id, int) or packet_id not in PACKETS:
        raise ProtocolError(
            f"unknown sensor packet id {packet_id!r}; this driver knows ids "
            f"{min(PACKETS)}–{max(PACKETS)} (group packets 0–6 and 100–107 are not supported)"
        )
    return packet_id


def start() -> bytes:
    """Opcode 128 Start: starts the OI and puts it in Passive mode."""
    return bytes([Opcode.START])


def passive() -> bytes:
    """Back to Passive mode: the OI has no own opcode for it; Start (128) does it."""
    return start()


def safe() -> bytes:
    """Opcode 131 Safe: motors allowed; the robot stops itself on cliff/wheel drop/charger."""
    return bytes([Opcode.SAFE])


def full() -> bytes:
    """Opcode 132 Full: motors allowed and no safety checks at all."""
    return bytes([Opcode.FULL])


def stop_oi() -> bytes:
    """Opcode 173 Stop (Create 2 only): stop the OI; the robot goes to Off mode."""
    return bytes([Opcode.STOP])


def baud(baud_bps: int) -> bytes:
    """Opcode 129 Baud with the code for ``baud_bps`` (e.g. 57600 → code 10)."""
    if baud_bps not in BAUD_CODES:
        raise ProtocolError(f"baud rate {baud_bps!r} is not one the OI knows: {sorted(BAUD_CODES)}")
    return bytes([Opcode.BAUD, BAUD_CODES[baud_bps]])


def drive(velocity_mm_s: float, radius_mm: int) -> bytes:
    """Opcode 137 Drive: centre velocity (clamped to ±500 mm/s) on a turn radius.

    ``radius_mm`` is clamped to ±2000 mm, except the special values
    :data:`RADIUS_STRAIGHT` (32768, also 32767), :data:`RADIUS_TURN_CW` (−1) and
    :data:`RADIUS_TURN_CCW` (1). A positive radius turns left (counter-clockwise).
    """
    velocity = _clamp_speed_mm_s(velocity_mm_s, "drive velocity_mm_s")
    radius = _finite_number(radius_mm, "drive radius_mm")
    if radius in (32767, RADIUS_STRAIGHT):
        radius_bytes = int(radius).to_bytes(2, "big", signed=False)
    else:
        radius_bytes = _int16_bytes(int(round(max(-MAX_RADIUS_MM, min(MAX_RADIUS_MM, radius)))))
    return bytes([Opcode.DRIVE]) + _int16_bytes(velocity) + radius_bytes


def drive_direct(*, left_mm_s: float, right_mm_s: float) -> bytes:
    """Opcode 145 Drive Direct: ``[145][right hi][right lo][left hi][left lo]``.

    Keyword-only because the wire order (right first) is the opposite of the usual
    (left, right): the function puts them in the right place. Speeds are rounded to whole
    mm/s and clamped to ±500 mm/s; positive drives that wheel forward.
    """
    right = _clamp_speed_mm_s(right_mm_s, "drive_direct right_mm_s")
    left = _clamp_speed_mm_s(left_mm_s, "drive_direct left_mm_s")
    return bytes([Opcode.DRIVE_DIRECT]) + _int16_bytes(right) + _int16_bytes(left)


def sensors(packet_id: int) -> bytes:
    """Opcode 142 Sensors: ask for one packet; the answer is its data bytes only."""
    return bytes([Opcode.SENSORS, valid_packet_id(packet_id)])


def _id_list(opcode: int, packet_ids: Sequence[int]) -> bytes:
    ids = [valid_packet_id(i) for i in packet_ids]
    if not ids:
        raise ProtocolError("give at least one packet id")
    if len(ids) > 255:
        raise ProtocolError(f"at most 255 packet ids fit in one command, got {len(ids)}")
    return bytes([opcode, len(ids), *ids])


def query_list(packet_ids: Sequence[int]) -> bytes:
    """Opcode 149 Query List: ``[149][n][ids...]``; the answer is the data bytes, no ids."""
    return _id_list(Opcode.QUERY_LIST, packet_ids)


def stream(packet_ids: Sequence[int]) -> bytes:
    """Opcode 148 Stream: ``[148][n][ids...]``; frames follow every 15 ms."""
    return _id_list(Opcode.STREAM, packet_ids)


def pause_stream() -> bytes:
    """Opcode 150 with 0: stop sending stream frames (the packet list is kept)."""
    return bytes([Opcode.PAUSE_RESUME_STREAM, 0])


def resume_stream() -> bytes:
    """Opcode 150 with 1: send stream frames again."""
    return bytes([Opcode.PAUSE_RESUME_STREAM, 1])


# --------------------------------------------------------------------------- sensor packets


@dataclass(frozen=True)
class BumpsAndDrops:
    """Packet 7 as named booleans."""

    bump_right: bool
    bump_left: bool
    wheel_drop_right: bool
    wheel_drop_left: bool
    wheel_drop_caster: bool = False  # Create 1 only

    @property
    def any_bump(self) -> bool:
        return self.bump_left or self.bump_right

    @property
    def any_wheel_drop(self) -> bool:
        return self.wheel_drop_left or self.wheel_drop_right or self.wheel_drop_caster


def decode_bumps_and_drops(value: int) -> BumpsAndDrops:
    """Packet 7's byte → :class:`BumpsAndDrops` (bit 0 right bump … bit 4 caster drop)."""
    if not 0 <= value <= 255:
        raise ProtocolError(f"packet 7 is one byte, got {value!r}")
    return BumpsAndDrops(
        bump_right=bool(value & 0x01),
        bump_left=bool(value & 0x02),
        wheel_drop_right=bool(value & 0x04),
        wheel_drop_left=bool(value & 0x08),
        wheel_drop_caster=bool(value & 0x10),
    )


def decode_packet(packet_id: int, data: bytes) -> int:
    """The integer value of one packet's data bytes (big-endian, signed where the spec says).

    Values stay in the OI's units (mm, degrees, counts, ...); convert at the edge.
    """
    spec = PACKETS.get(packet_id)
    if spec is None:
        raise ProtocolError(f"unknown sensor packet id {packet_id}")
    if len(data) != spec.size:
        raise ProtocolError(f"packet {packet_id} ({spec.name}) has {spec.size} data byte(s), got {len(data)}")
    return int.from_bytes(bytes(data), "big", signed=spec.signed)


def encode_packet(packet_id: int, value: int) -> bytes:
    """A packet's data bytes for ``value`` (the inverse of :func:`decode_packet`).

    Unsigned 16-bit packets wrap around (encoder counts do), signed ones must fit.
    """
    spec = PACKETS[valid_packet_id(packet_id)]
    bits = 8 * spec.size
    if spec.signed:
        lo, hi = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
        if not lo <= value <= hi:
            raise ProtocolError(f"packet {packet_id} ({spec.name}) holds {lo}..{hi}, got {value}")
        return int(value).to_bytes(spec.size, "big", signed=True)
    return (int(value) % (1 << bits)).to_bytes(spec.size, "big", signed=False)


def query_response_size(packet_ids: Sequence[int]) -> int:
    """Bytes the robot answers to ``query_list(packet_ids)``."""
    return sum(PACKETS[valid_packet_id(i)].size for i in packet_ids)


def decode_query_response(packet_ids: Sequence[int], data: bytes) -> dict[int, int]:
    """Split the answer to a Query List (data bytes back to back, no ids) by packet.

    The answer carries no checksum: only its length can be checked here.
    """
    expected = query_response_size(packet_ids)
    if len(data) != expected:
        raise ProtocolError(
            f"a query for packets {list(packet_ids)} is answered with {expected} bytes, got {len(data)}"
        )
    values, at = {}, 0
    for packet_id in packet_ids:
        size = PACKETS[packet_id].size
        values[packet_id] = decode_packet(packet_id, data[at:at + size])
        at += size
    return values


def decode_frame_payload(payload: bytes, expected_ids: Sequence[int] | None = None) -> dict[int, int]:
    """The packets of one stream frame's payload ``[id][data]...`` (between N and checksum).

    Raises :class:`ProtocolError` when an id is unknown, a packet is cut short, an id
    repeats, or (with ``expected_ids``) the ids are not exactly the expected ones in order.
    """
    values: dict[int, int] = {}
    order: list[int] = []
    at = 0
    while at < len(payload):
        packet_id = payload[at]
        spec = PACKETS.get(packet_id)
        if spec is None:
            raise ProtocolError(f"unknown packet id {packet_id} at payload byte {at}")
        if packet_id in values:
            raise ProtocolError(f"packet id {packet_id} twice in one frame")
        data = payload[at + 1:at + 1 + spec.size]
        if len(data) != spec.size:
            raise ProtocolError(f"packet {packet_id} cut short at the end of the frame")
        values[packet_id] = decode_packet(packet_id, data)
        order.append(packet_id)
        at += 1 + spec.size
    if not order:
        raise ProtocolError("empty stream frame")
    if expected_ids is not None and order != list(expected_ids):
        raise ProtocolError(f"frame holds packets {order}, expected {list(expected_ids)}")
    return values


def checksum_byte(data: Iterable[int]) -> int:
    """The byte that makes ``sum(data) + checksum ≡ 0 (mod 256)``."""
    return (-sum(data)) & 0xFF


def frame_checksum_ok(frame: bytes) -> bool:
    """Whether every byte of a frame, header through checksum, sums to 0 mod 256."""
    return (sum(frame) & 0xFF) == 0


def encode_stream_frame(values: Mapping[int, int]) -> bytes:
    """A complete stream frame for ``{packet id: value}`` (in the mapping's order)."""
    payload = bytearray()
    for packet_id, value in values.items():
        payload.append(valid_packet_id(packet_id))
        payload += encode_packet(packet_id, value)
    if not payload:
        raise ProtocolError("a stream frame needs at least one packet")
    if len(payload) > 255:
        raise ProtocolError(f"a stream frame holds at most 255 payload bytes, got {len(payload)}")
    body = bytes([STREAM_HEADER, len(payload)]) + bytes(payload)
    return body + bytes([checksum_byte(body)])


def stream_payload_size(packet_ids: Sequence[int]) -> int:
    """N, the payload length of a frame for ``packet_ids`` (one id byte per packet + data)."""
    return sum(1 + PACKETS[valid_packet_id(i)].size for i in packet_ids)
