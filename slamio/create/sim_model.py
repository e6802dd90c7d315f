"""The simulated Create's robot as plain functions (:mod:`slamio.create.sim` holds the
state and the pseudo-terminal): the wheel speeds of a Drive command, what the encoders
measure of a step (:func:`measured_wheel_travel_m`), the bumpers against the arena's
walls and obstacles (:func:`bump_bits`; :func:`move_disc` keeps the disc out of them), the bytes a bad cable delivers (:func:`damage_bytes`) and where
one Open Interface command ends (:func:`command_size`).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from slamio.create.odometry import OdometryNoise, default_noise
from slamio.create.protocol import Opcode
from slamio.geometry import arc_increment, compose_pose
from slamio.obstacles import Obstacles, disc_contacts, push_disc_out

__all__ = [
    "ARG_BYTES", "bump_bits", "command_size", "contact_bump_bits", "damage_bytes", "measured_wheel_travel_m",
    "move_disc", "ramp_wheels", "sign",
    "truncate", "wheel_odometry_noise", "wheel_speeds_from_drive", "without_sideways",
]

# Bytes that follow each opcode (148 and 149: a count, then that many ids).
ARG_BYTES = {
    Opcode.START: 0, Opcode.BAUD: 1, Opcode.SAFE: 0, Opcode.FULL: 0, Opcode.DRIVE: 4,
    Opcode.DRIVE_DIRECT: 4, Opcode.SENSORS: 1, Opcode.PAUSE_RESUME_STREAM: 1, Opcode.STOP: 0,
}


def sign(x: float) -> int:
    return (x > 0) - (x < 0)


def truncate(value: float) -> int:
    """Toward zero, clamped to int16 (what the robot reports for 19/20)."""
    return max(-32768, min(32767, int(value)))


def wheel_speeds_from_drive(velocity_mm_s: int, radius_mm: int, wheel_base_mm: float) -> tuple[float, float]:
    """(left, right) wheel speeds in mm/s for a Drive (137) command."""
    v = max(-500, min(500, velocity_mm_s))
    if radius_mm in (32767, 32768, -32768):
        return float(v), float(v)
    if radius_mm == 1:  # turn in place counter-clockwise
        return float(-v), float(v)
    if radius_mm == -1:
        return float(v), float(-v)
    r = max(-2000, min(2000, radius_mm))
    if r == 0:
        return float(v), float(v)
    half = wheel_base_mm / 2.0
    return v * (r - half) / r, v * (r + half) / r


def wheel_odometry_noise(model: str) -> OdometryNoise:
    """The nominal odometry noise (:func:`slamio.create.odometry.default_noise`) without its
    sideways terms, which wheels cannot produce: what the simulated Create's encoders do,
    and so what a recording from it states."""
    return without_sideways(default_noise(model))


def without_sideways(noise: OdometryNoise) -> OdometryNoise:
    """``noise`` with the rows and columns of y (sideways) zeroed in F and R (the floor,
    the quantisation, is kept)."""

    def drop_y(m) -> np.ndarray:
        a = np.array(m, float)
        a[1, :] = 0.0
        a[:, 1] = 0.0
        return a

    return OdometryNoise(drop_y(noise.forward_per_m), drop_y(noise.rotate_per_rad), noise.floor,
                         source=f"{noise.source}; no sideways slip (wheel encoders)")


def _matrix_sqrt_2x2(cov: np.ndarray) -> np.ndarray:
    """A square root S (S·Sᵀ = cov) of a 2×2 covariance that may be singular."""
    try:
        return np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        w, v = np.linalg.eigh(cov)
        return v * np.sqrt(np.clip(w, 0.0, None))


def measured_wheel_travel_m(travel_m: Sequence[float], wheel_base_m: float, noise: OdometryNoise,
                            rng: np.random.Generator) -> list[float]:
    """What the (left, right) encoders measure of the wheels' true (left, right) travel in
    one step: unsigned distances (the counting direction is the commanded one).

    The step's distance Δs and turn Δθ get an error drawn with covariance
    ``|Δs|·F + |Δθ|·R`` over (distance, heading) — the x and θ rows of ``noise``'s F and R —
    and the wheels' travel is made back from the erred (Δs, Δθ).
    """
    left, right = float(travel_m[0]), float(travel_m[1])
    ds, dtheta = 0.5 * (left + right), (right - left) / wheel_base_m
    index = np.ix_((0, 2), (0, 2))
    cov = abs(ds) * np.array(noise.forward_per_m)[index] + abs(dtheta) * np.array(noise.rotate_per_rad)[index]
    if cov.any():
        e_s, e_theta = _matrix_sqrt_2x2(cov) @ rng.standard_normal(2)
        ds, dtheta = ds + e_s, dtheta + e_theta
    half = 0.5 * wheel_base_m * dtheta
    measured = (ds - half, ds + half)
    # Each wheel counts its own travel's size; an error cannot flip a wheel's direction.
    return [abs(m) if (m >= 0) == (t >= 0) or t == 0 else 0.0 for m, t in zip(measured, (left, right))]


def ramp_wheels(wheel_m_s: Sequence[float], command_mm_s: Sequence[float], accel_m_s2: float,
                dt: float) -> tuple[list[float], list[float]]:
    """One step of the wheels toward the commanded (left, right) speeds (mm/s), changing at
    most ``accel_m_s2``·dt: their new speeds (m/s) and how far each rolled (m)."""
    speeds, travel = [], []
    for v0, command in zip(wheel_m_s, command_mm_s):
        target = command / 1000.0
        limit = accel_m_s2 * dt
        v1 = v0 + max(-limit, min(limit, target - v0))
        speeds.append(v1)
        travel.append(0.5 * (v0 + v1) * dt)
    return speeds, travel


def contact_bump_bits(theta_rad: float, contact_directions_rad) -> int:
    """Packet 7's bump bits of a robot heading ``theta_rad`` touched from these world
    directions: within 20° of straight ahead both bumpers, else the left or the right one
    on its side; a contact behind the wheel axis (more than 90° off) presses nothing."""
    bits = 0
    for direction in contact_directions_rad:
        bearing = (float(direction) - theta_rad + math.pi) % (2 * math.pi) - math.pi
        if abs(bearing) <= math.radians(20):
            bits |= 0x03
        elif 0 < bearing <= math.pi / 2:
            bits |= 0x02  # left bumper
        elif -math.pi / 2 <= bearing < 0:
            bits |= 0x01  # right bumper
    return bits


def bump_bits(pose: Sequence[float], arena_m: tuple[float, float] | None, robot_radius_m: float,
              obstacles: Obstacles | None = None) -> int:
    """Packet 7's bump bits of a disc of ``robot_radius_m`` at ``pose`` touching the arena's
    walls or ``obstacles`` (:func:`contact_bump_bits`)."""
    x, y, theta = pose
    r, eps = robot_radius_m, 1e-3
    directions: list[float] = []
    if arena_m is not None:  # (touching?, direction from the centre to that wall in the world frame)
        walls = ((x <= r + eps, math.pi), (x >= arena_m[0] - r - eps, 0.0),
                 (y <= r + eps, -math.pi / 2), (y >= arena_m[1] - r - eps, math.pi / 2))
        directions += [direction for touching, direction in walls if touching]
    if obstacles is not None:
        directions += disc_contacts(obstacles, (x, y), r).tolist()
    return contact_bump_bits(theta, directions)


def move_disc(pose: Sequence[float], distance_m: float, angle_rad: float, arena_m: tuple[float, float] | None,
              obstacles: Obstacles | None, robot_radius_m: float) -> tuple[float, float, float]:
    """The pose after the wheels roll an arc of ``distance_m`` and turn ``angle_rad``: a disc
    that would enter an obstacle is pushed out of it (it slides along), then kept inside the
    arena's walls."""
    x, y, theta = compose_pose(tuple(pose), arc_increment(distance_m, angle_rad))
    if obstacles is not None:
        x, y = push_disc_out(obstacles, (x, y), robot_radius_m)
    if arena_m is not None:
        r = robot_radius_m
        x = min(max(x, r), arena_m[0] - r)
        y = min(max(y, r), arena_m[1] - r)
    return x, y, theta


def damage_bytes(data: bytes, rng: np.random.Generator, drop_fraction: float,
                 corrupt_fraction: float) -> tuple[bytes, int, int]:
    """``data`` as it arrives over a bad cable: each byte dropped with probability
    ``drop_fraction`` or else damaged (XOR with a random non-zero mask) with probability
    ``corrupt_fraction``. Returns (the bytes, how many dropped, how many damaged)."""
    u = rng.random((len(data), 2))
    masks = rng.integers(1, 256, len(data))
    out = bytearray()
    dropped = corrupted = 0
    for byte, (u_drop, u_corrupt), mask in zip(data, u, masks):
        if u_drop < drop_fraction:
            dropped += 1
            continue
        if u_corrupt < corrupt_fraction:
            byte ^= int(mask)
            corrupted += 1
        out.append(byte)
    return bytes(out), dropped, corrupted


def command_size(buf: bytes | bytearray) -> int | None:
    """The length of the command at the start of ``buf`` (opcode and arguments; 148 and 149
    give a count, then that many ids), None when it has not all arrived yet, 0 for an
    opcode the OI does not know."""
    opcode = buf[0]
    if opcode in (Opcode.STREAM, Opcode.QUERY_LIST):
        return 2 + buf[1] if len(buf) >= 2 and len(buf) >= 2 + buf[1] else None
    if opcode in ARG_BYTES:
        size = 1 + ARG_BYTES[opcode]
        return size if len(buf) >= size else None
    return 0
