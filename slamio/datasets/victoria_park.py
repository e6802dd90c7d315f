"""Victoria Park (as shipped with GTSAM) → run-log records.

The file
--------
``gtsam.findExampleDataFile("victoria_park.txt")`` is a plain-text file of two line kinds,
whitespace-separated, no times::

    ODOMETRY  i j  dx dy dtheta  v0 v1 v2 v3 v4 v5
    LANDMARK  i l  x y  vxx vxy vyy

* ``ODOMETRY i j`` is the SE(2) increment from pose ``i`` to pose ``j`` in pose ``i``'s
  frame (x forward, y left), with six noise numbers. GTSAM's ``load2D`` (default
  ``NoiseFormatAUTO``) reads them by their zero pattern: ``v0 0 0 v3 0 v5`` is the
  *covariance* upper triangle row by row (``[[v0 v1 v2] [v1 v3 v4] [v2 v4 v5]]``,
  ``NoiseFormatCOV``); ``v0 0 v2 v3 0 0`` is the TORO-ordered covariance
  ``[[v0 v1 v4] [v1 v2 v5] [v4 v5 v3]]`` (``NoiseFormatGRAPH``); any other pattern is
  refused. Both patterns are diagonal, so this importer accepts exactly the files
  ``load2D`` accepts. The shipped file is ``1e-4 0 0 4e-6 0 4e-6`` on every line: σ = 0.01 m
  forward, 0.002 m sideways, 0.002 rad.
* ``LANDMARK i l`` is landmark ``l`` seen from pose ``i`` at Cartesian ``(x, y)`` in the
  robot frame, with a 2×2 covariance upper triangle. ``load2D`` turns it into a bearing
  ``atan2(y, x)`` and range ``sqrt(x² + y²)`` and, when ``|vxx − vyy| < 1e-4``, into the
  sigmas ``σ_bearing = sqrt(vxx / 10)`` rad and ``σ_range = sqrt(vxx)`` m ("assume the
  x-y covariance describes the uncertainty at a range of 10 m"); otherwise into σ = 1 and 1.
  ``vxy`` is never used. The shipped file is ``0.4 0 0.4`` everywhere: σ_bearing 0.2 rad,
  σ_range 0.632 m.

Poses and landmarks were numbered from one counter, so the pose ids in the ODOMETRY chain
skip every landmark id (6 969 poses with ids 0…7119; the 151 gaps are the 151 landmark ids).

The conversion
--------------
The result is built so that the factor graph ``fgslam``'s smoother makes from the log is
the graph ``gtsam.load2D`` makes from the file (same measurements, same noise), plus the
smoother's prior on pose 0:

* Step ``k`` is the ``k``-th pose of the ODOMETRY chain; its file id is not kept (count the
  chain to recover it). Pose 0 — the first ODOMETRY line's ``i`` — is ``(0, 0, 0)``, which
  is also ``load2D``'s initial value for it. The header pins it with σ = 1e-3.
* The file has no times. Step ``k`` is stamped ``k · nominal_period_s`` (0.2 s by default:
  a round number, not a measurement); observations carry their pose's stamp.
* ODOMETRY ``(dx, dy, dθ)`` is written as is. Its covariance ``M`` is GTSAM's
  between-factor covariance, which lives in the frame at the *end* of the increment; the
  log's covariance is over the increment's own numbers, which the smoother rotates by
  ``R(dθ)ᵀ`` (``fgslam.smoother.odometry_noise_covariance``). So the log gets
  ``Q = Aᵀ M A`` with ``A = blockdiag(R(dθ)ᵀ, 1)``, which the smoother turns back into ``M``
  exactly (to rounding) and the EKF uses as the same noise to first order. Because the
  file's σx ≠ σy, ``Q`` has small x–y cross terms (|dθ| ≤ 0.13 rad in the shipped file).
* LANDMARK ``(x, y)`` becomes ``range_m``/``bearing_rad`` and sigmas by ``load2D``'s rule
  above, computed with the same formulas, so the numbers are bit-identical.

What is lost: the Cartesian covariance itself (only ``vxx`` survives, through ``load2D``'s
10 m rule; ``vxy`` and, when it differs from ``vxx``, ``vyy`` are dropped exactly as
``load2D`` drops them — the log holds one range σ and one bearing σ, uncorrelated), the
file's pose ids, and any notion of time.

Every line is validated: a bad one raises :class:`DatasetFormatError` naming
``file:line``, what is wrong and how to fix it.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
from typing import Any

import numpy as np

from slamio.errors import FgslamError, InputFileError, read_bytes
from slamio.log import Header, Matrix3, Observation, Odometry, Record
from slamio.log.read import MAX_LOG_BYTES, check_records
from slamio.safe_input import shown

__all__ = [
    "DatasetFormatError",
    "NOMINAL_PERIOD_S",
    "START_SIGMA",
    "default_victoria_park_path",
    "import_victoria_park",
    "landmark_sigmas",
    "odometry_file_covariance",
]

#: Stamp spacing between consecutive poses; the file has no times.
NOMINAL_PERIOD_S = 0.2
#: Prior sigmas (m, m, rad) on pose 0. ``load2D`` adds no prior; this pins the gauge.
START_SIGMA = (1e-3, 1e-3, 1e-3)

_INT = re.compile(r"\+?\d+\Z")
_FLOAT = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
_ODOMETRY_FIELDS = "ODOMETRY i j dx dy dtheta v0 v1 v2 v3 v4 v5"
_LANDMARK_FIELDS = "LANDMARK i l x y vxx vxy vyy"


class DatasetFormatError(InputFileError):
    """A dataset file that cannot be converted: ``path:line: what is wrong; how to fix it``
    (``fgslam`` exits with status 2)."""

    def __init__(self, path: str, line: int, message: str):
        super().__init__(f"{path}:{line}: {message}")
        self.path = path
        self.line = line


class _BadLine(Exception):
    """Internal: what is wrong with one line (of this file or of an MRCLAM file)."""


def ascii_text(raw: bytes, hint: str) -> str:
    """One line of a dataset's text file, decoded; a line that is not plain ASCII is a
    :class:`_BadLine` (``hint`` asks whether the file is the one expected)."""
    try:
        return raw.decode("ascii")
    except UnicodeDecodeError:
        raise _BadLine(f"not plain ASCII text; {hint}") from None


def default_victoria_park_path() -> str:
    """The ``victoria_park.txt`` shipped inside the installed gtsam wheel."""
    try:
        import gtsam  # lazy: slamio does not need gtsam for anything else
    except ImportError as exc:  # pragma: no cover - gtsam is a dependency
        raise FgslamError(
            f"cannot find victoria_park.txt: gtsam is not importable ({exc}); "
            "install gtsam or give the file's path"
        ) from None
    try:
        return str(gtsam.findExampleDataFile("victoria_park.txt"))
    except (RuntimeError, ValueError) as exc:
        raise FgslamError(
            f"gtsam does not ship victoria_park.txt here ({exc}); give the file's path"
        ) from None


def odometry_file_covariance(v: tuple[float, ...]) -> np.ndarray:
    """The 3×3 covariance ``gtsam.load2D`` (``NoiseFormatAUTO``) reads from six noise numbers.

    Raises ``ValueError`` with the reason when ``load2D`` would refuse them too.
    """
    v0, v1, v2, v3, v4, v5 = v
    if v0 != 0.0 and v1 == 0.0 and v2 != 0.0 and v3 != 0.0 and v4 == 0.0 and v5 == 0.0:
        # NoiseFormatGRAPH (TORO order, but a covariance): [[v0 v1 v4] [v1 v2 v5] [v4 v5 v3]]
        M = np.array([[v0, v1, v4], [v1, v2, v5], [v4, v5, v3]])
    elif v0 != 0.0 and v1 == 0.0 and v2 == 0.0 and v3 != 0.0 and v4 == 0.0 and v5 != 0.0:
        # NoiseFormatCOV: the upper triangle row by row, [[v0 v1 v2] [v1 v3 v4] [v2 v4 v5]]
        M = np.array([[v0, v1, v2], [v1, v3, v4], [v2, v4, v5]])
    else:
        raise ValueError(
            f"the noise numbers {' '.join(_fmt(x) for x in v)} match neither layout gtsam.load2D "
            "recognises: 'vxx 0 0 vyy 0 vtt' (covariance upper triangle) or 'vxx 0 vyy vtt 0 0' "
            "(TORO order); write a diagonal covariance in the first layout"
        )
    if not np.all(np.diag(M) > 0.0):
        raise ValueError(
            f"the covariance diagonal {', '.join(_fmt(x) for x in np.diag(M))} must be > 0 "
            "(every motion has some uncertainty)"
        )
    return M


def landmark_sigmas(vxx: float, vyy: float) -> tuple[float, float]:
    """(σ_bearing_rad, σ_range_m) as ``gtsam.load2D`` derives them from a LANDMARK covariance.

    ``load2D`` assumes the Cartesian covariance describes the uncertainty at 10 m:
    ``σ_bearing = sqrt(vxx / 10)``, ``σ_range = sqrt(vxx)`` when ``|vxx − vyy| < 1e-4``;
    otherwise it ignores the covariance and uses 1 and 1. ``vxy`` is never used.
    """
    if abs(vxx - vyy) < 1e-4:
        return math.sqrt(vxx / 10.0), math.sqrt(vxx)
    return 1.0, 1.0


def _end_frame_to_increment(M: np.ndarray, dtheta_rad: float) -> Matrix3:
    """The log covariance ``Aᵀ M A`` whose rotation by the smoother gives back ``M``."""
    c, s = math.cos(dtheta_rad), math.sin(dtheta_rad)
    A = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # blockdiag(R(dθ)ᵀ, 1)
    Q = A.T @ M @ A
    Q = 0.5 * (Q + Q.T)
    return tuple(tuple(float(x) for x in row) for row in Q)  # type: ignore[return-value]


def _fmt(x: float) -> str:
    return repr(float(x))


def _ints(tokens: list[str], names: tuple[str, ...]) -> list[int]:
    out = []
    for token, name in zip(tokens, names):
        if not _INT.match(token):
            raise _BadLine(f"{name} must be a non-negative integer id, got {shown(token)}")
        out.append(int(token))
    return out


def _floats(tokens: list[str], names: tuple[str, ...]) -> list[float]:
    out = []
    for token, name in zip(tokens, names):
        if not _FLOAT.match(token):
            raise _BadLine(f"{name} must be a finite decimal number, got {shown(token)}")
        value = float(token)
        if not math.isfinite(value):
            raise _BadLine(f"{name} overflows to infinity ({shown(token)}); write a finite number")
        out.append(value)
    return out


def _count(tokens: list[str], expected: str) -> None:
    n = len(expected.split())
    if len(tokens) != n:
        raise _BadLine(
            f"{tokens[0]} line has {len(tokens)} fields, expected {n}: '{expected}'"
        )


def import_victoria_park(
    source_path: str | os.PathLike[str] | None = None, *, nominal_period_s: float = NOMINAL_PERIOD_S
) -> tuple[Header, list[Record]]:
    """Convert GTSAM's ``victoria_park.txt`` into a run-log header and records.

    ``source_path`` None means the file shipped in the gtsam wheel
    (:func:`default_victoria_park_path`). The records are in file order: one
    :class:`~slamio.log.Odometry` per ODOMETRY line (each starts a new pose) and one
    :class:`~slamio.log.Observation` per LANDMARK line; see the module docstring for how
    each is converted and what is lost. Write them with ``slamio.log.write_log``.

    Raises :class:`DatasetFormatError` (``file:line: ...``) at the first bad line, and
    :class:`~slamio.errors.FgslamError` when the file cannot be opened.
    """
    if not (math.isfinite(nominal_period_s) and nominal_period_s > 0.0):
        raise FgslamError(f"nominal_period_s must be a positive number of seconds, got {nominal_period_s!r}")
    path = os.fspath(source_path) if source_path is not None else default_victoria_park_path()
    # a regular file of at most a run log's size: never a FIFO, /dev/zero or a link loop
    raw_lines = read_bytes(path, "Victoria Park file", limit=MAX_LOG_BYTES).split(b"\n")
    if raw_lines and raw_lines[-1] == b"":
        raw_lines.pop()  # the text after the final newline

    chain = _Chain(nominal_period_s)
    for number, raw in enumerate(raw_lines, start=1):
        try:
            tokens = ascii_text(raw, "is this the Victoria Park .txt file?").split()
            if not tokens:
                continue  # gtsam's parser skips blank lines too
            tag = tokens[0]
            if tag == "ODOMETRY":
                chain.odometry(tokens)
            elif tag == "LANDMARK":
                chain.landmark(tokens)
            else:
                raise _BadLine(
                    f"unknown line type {shown(tag)}; a Victoria Park file holds only ODOMETRY and "
                    "LANDMARK lines"
                )
        except _BadLine as bad:
            raise DatasetFormatError(path, number, str(bad)) from None

    if chain.current is None or chain.first_pose_id is None:
        raise DatasetFormatError(path, max(1, len(raw_lines)), "no ODOMETRY or LANDMARK lines; is this the Victoria Park file?")

    header = _header(
        path,
        raw_lines,
        nominal_period_s,
        n_poses=len(chain.pose_ids),
        n_odometry=chain.n_odometry,
        n_landmark=chain.n_landmark,
        n_landmarks=len(chain.landmark_ids),
        n_nonuniform=chain.n_nonuniform,
        odometry_covariances=chain.odometry_covariances,
        landmark_covariances=chain.landmark_covariances,
        first_pose_id=chain.first_pose_id,
    )
    return header, list(check_records(path, header, chain.records))  # never a log the reader refuses


class _Chain:
    """The records converted so far: one odometry chain of poses, the landmarks seen from
    its latest pose, and what the header counts."""

    def __init__(self, nominal_period_s: float):
        self.nominal_period_s = nominal_period_s
        self.records: list[Record] = []
        self.pose_ids: set[int] = set()  # file ids of the poses so far
        self.current: int | None = None  # file id of the latest pose (the one observations belong to)
        self.first_pose_id: int | None = None
        self.n_odometry = self.n_landmark = self.n_nonuniform = 0
        self.odometry_covariances: set[tuple[float, ...]] = set()
        self.landmark_covariances: set[tuple[float, float, float]] = set()
        self.landmark_ids: set[int] = set()
        self.stamp = 0.0

    def _start(self, i: int) -> None:
        """The file's first line starts the chain at its pose ``i``."""
        if self.current is None:
            self.current = self.first_pose_id = i
            self.pose_ids.add(i)

    def odometry(self, tokens: list[str]) -> None:
        _count(tokens, _ODOMETRY_FIELDS)
        i, j = _ints(tokens[1:3], ("pose id i", "pose id j"))
        dx, dy, dth = _floats(tokens[3:6], ("dx", "dy", "dtheta"))
        v = tuple(_floats(tokens[6:12], ("v0", "v1", "v2", "v3", "v4", "v5")))
        self._start(i)
        if i != self.current:
            raise _BadLine(
                f"ODOMETRY {i} {j} does not start at the latest pose {self.current}: a run log "
                "holds one odometry chain, each line continuing from the previous one "
                "(loop-closure edges cannot be converted)"
            )
        if j in self.pose_ids:
            raise _BadLine(
                f"ODOMETRY {i} {j} returns to pose {j}, which already exists: a run log "
                "holds one odometry chain without loop-closure edges"
            )
        try:
            M = odometry_file_covariance(v)  # type: ignore[arg-type]
        except ValueError as exc:
            raise _BadLine(str(exc)) from None
        self.stamp = len(self.pose_ids) * self.nominal_period_s
        self.records.append(Odometry(self.stamp, dx, dy, dth, _end_frame_to_increment(M, dth)))
        self.pose_ids.add(j)
        self.current = j
        self.n_odometry += 1
        self.odometry_covariances.add(tuple(float(x) for x in np.diag(M)))

    def landmark(self, tokens: list[str]) -> None:
        _count(tokens, _LANDMARK_FIELDS)
        i, lid = _ints(tokens[1:3], ("pose id i", "landmark id l"))
        x, y, vxx, vxy, vyy = _floats(tokens[3:8], ("x", "y", "vxx", "vxy", "vyy"))
        self._start(i)
        if i != self.current:
            raise _BadLine(
                f"LANDMARK seen from pose {i}, but the latest pose is {self.current}: a "
                "landmark line must follow the ODOMETRY line that created its pose"
            )
        range_m = math.sqrt(x * x + y * y)  # load2D's formulas, for identical numbers
        bearing_rad = math.atan2(y, x)
        if not range_m > 0.0:
            raise _BadLine(
                f"landmark {lid} at (x, y) = ({_fmt(x)}, {_fmt(y)}) is at zero range: its "
                "bearing is undefined; remove the line"
            )
        if not (vxx > 0.0 and vyy > 0.0):
            raise _BadLine(
                f"the covariance diagonal vxx = {_fmt(vxx)}, vyy = {_fmt(vyy)} must be > 0 "
                "(load2D takes the square root of vxx for the sigmas)"
            )
        sigma_bearing, sigma_range = landmark_sigmas(vxx, vyy)
        if abs(vxx - vyy) >= 1e-4:
            self.n_nonuniform += 1
        self.records.append(Observation(self.stamp, lid, range_m, bearing_rad, sigma_range, sigma_bearing))
        self.n_landmark += 1
        self.landmark_covariances.add((vxx, vxy, vyy))
        self.landmark_ids.add(lid)


def _header(
    path: str,
    raw_lines: list[bytes],
    nominal_period_s: float,
    *,
    n_poses: int,
    n_odometry: int,
    n_landmark: int,
    n_landmarks: int,
    n_nonuniform: int,
    odometry_covariances: set[tuple[float, ...]],
    landmark_covariances: set[tuple[float, float, float]],
    first_pose_id: int,
) -> Header:
    digest = hashlib.sha256(b"\n".join(raw_lines) + b"\n").hexdigest()
    odo_noise: dict[str, Any] = {
        "model": (
            "from each ODOMETRY line's six noise numbers, read as gtsam.load2D reads them "
            "(NoiseFormatAUTO: 'v0 0 0 v3 0 v5' is the covariance upper triangle, diagonal here); "
            "that covariance M is GTSAM's between-factor covariance (end-of-increment frame), "
            "written to the log as A^T M A with A = blockdiag(R(dtheta)^T, 1) so that fgslam's "
            "smoother gets M back"
        ),
    }
    if len(odometry_covariances) == 1:
        (diag,) = odometry_covariances
        odo_noise["file_sigma"] = [math.sqrt(d) for d in diag]
        odo_noise["file_sigma_units"] = ["m", "m", "rad"]
    obs_noise: dict[str, Any] = {
        "model": (
            "from each LANDMARK line's Cartesian covariance (vxx vxy vyy) by gtsam.load2D's rule: "
            "sigma_bearing_rad = sqrt(vxx/10), sigma_range_m = sqrt(vxx) when |vxx - vyy| < 1e-4, "
            "else 1 and 1; vxy is not used"
        ),
        "lines_with_non_uniform_covariance": n_nonuniform,
    }
    if len(landmark_covariances) == 1:
        (cov,) = landmark_covariances
        sb, sr = landmark_sigmas(cov[0], cov[2])
        obs_noise["file_covariance_xx_xy_yy_m2"] = list(cov)
        obs_noise["sigma_bearing_rad"] = sb
        obs_noise["sigma_range_m"] = sr
    return Header(
        stamp_s=0.0,
        start_pose=(0.0, 0.0, 0.0),
        start_sigma=START_SIGMA,
        robot={
            "name": "Victoria Park utility vehicle (Guivant & Nebot, ACFR, Sydney)",
            "drive": "car-like",
            "note": "odometry already integrated into SE(2) increments in the file; no raw wheel data",
        },
        sensor={
            "kind": "range-bearing",
            "landmark_kind": "tree trunk",
            "measurement_in_file": "Cartesian (x forward, y left) in the robot frame, data association solved",
            "conversion": "range = sqrt(x^2 + y^2), bearing = atan2(y, x), as gtsam.load2D",
        },
        noise={"odometry": odo_noise, "observation": obs_noise},
        source={
            "dataset": "victoria_park",
            "file": path,
            "sha256": digest,
            "converted_by": "fgslam import victoria-park",
            "poses": n_poses,
            "landmarks": n_landmarks,
            "odometry_lines": n_odometry,
            "landmark_lines": n_landmark,
            "first_pose_id": first_pose_id,
            "pose_ids": "step k is the k-th pose of the ODOMETRY chain; the file's ids are not kept",
            "stamps": (
                f"the file has no times: step k is stamped k * {nominal_period_s!r} s (nominal), "
                "observations carry their pose's stamp"
            ),
            "nominal_period_s": nominal_period_s,
            "start": "pose 0 = (0, 0, 0), load2D's initial value for it; the prior sigma pins the gauge (load2D adds no prior)",
            "ground_truth": "none: fgslam run compares against the smoothed (batch) solution",
        },
    )
