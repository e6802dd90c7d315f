"""Trajectories as TUM files (``t x y z qx qy qz qw`` per line), written and read back.

The format of the TUM RGB-D benchmark, which evo and other tools read: ``fgslam run`` writes
each estimator's trajectory in it.
"""

from __future__ import annotations

import math
import os

import numpy as np

from fgslam.atomic import write_text_whole
from fgslam.compare.runs import ComparisonError, _as_poses
from slamio.errors import content_lines


def format_tum(stamps_s, poses) -> str:
    """Trajectory in TUM format: one line ``t x y 0 qx qy qz qw`` per pose, in order.

    A planar heading θ is the rotation about z: ``qx = qy = 0, qz = sin(θ/2),
    qw = cos(θ/2)``. Numbers are written with ``repr`` (shortest text that reads back as
    the same float), so nothing is lost. A NaN heading (a truth that measures position only,
    like GPS) is written as ``nan`` for qz and qw. The result ends with a newline (empty for
    no poses).
    """
    t = np.asarray(stamps_s, dtype=float).reshape(-1)
    p = _as_poses(poses, "poses")
    if len(t) != len(p):
        raise ComparisonError(f"format_tum: {len(t)} stamps but {len(p)} poses")
    lines = []
    for stamp, (x, y, theta) in zip(t, p):
        half = 0.5 * float(theta)
        values = (float(stamp), float(x), float(y), 0.0, 0.0, 0.0, math.sin(half), math.cos(half))
        lines.append(" ".join(repr(v) for v in values))
    return "".join(line + "\n" for line in lines)


def write_tum(path: str | os.PathLike[str], stamps_s, poses) -> None:
    """Write :func:`format_tum` output to ``path`` (replacing it), whole or not at all (:mod:`fgslam.atomic`)."""
    write_text_whole(path, format_tum(stamps_s, poses))


def read_tum(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory file into ``(stamps_s (n,), poses (n, 3))``.

    Blank lines and ``#`` comments are skipped. The heading is the yaw of the quaternion,
    ``atan2(2(qw qz + qx qy), 1 − 2(qy² + qz²))``, so files from other tools (with tiny
    non-zero qx, qy) read too; z is ignored. Raises :class:`ComparisonError` naming
    ``file:line`` for a malformed line.
    """
    stamps, poses = [], []
    for line_no, text in content_lines(path):
        fields = text.split()
        if len(fields) != 8:
            raise ComparisonError(
                f"{path}:{line_no}: expected 8 numbers 't x y z qx qy qz qw', got {len(fields)}"
            )
        try:
            t, x, y, _z, qx, qy, qz, qw = (float(v) for v in fields)
        except ValueError:
            raise ComparisonError(
                f"{path}:{line_no}: not a number in {text!r}; a TUM line is 8 numbers "
                "'t x y z qx qy qz qw'"
            ) from None
        yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        stamps.append(t)
        poses.append((x, y, yaw))
    return np.asarray(stamps, dtype=float), np.asarray(poses, dtype=float).reshape(-1, 3)
