"""The reader's fast path: one record line decoded by msgspec straight into typed structs
whose types carry the bounds of docs/log-format.md, then turned into the record dataclass.

It only ever *accepts*: :func:`fast_record` returns None for any line it is not sure of
(malformed JSON, a bound crossed, a key given twice, a covariance near the limits, ...),
and the reader then runs the slow path (:func:`slamio.log.parse.parse_record` on
``json.loads``) on that line alone, which accepts it or says exactly what is wrong. So a
line the fast path accepts is one the slow path accepts with the same record
(tests/test_log_fast.py checks both on generated lines), and every message stays the slow
path's.

What msgspec does not check by itself is checked here:

* a key given twice (msgspec keeps the last): every ``:`` of an accepted line separates a
  key from its value (keys and the type name hold none), so the line's ``:`` count must be
  one more (``type``) than the fields present;
* pairs that go together (``height_m``/``sigma_height_m``, ...), the Create's reading, and
  a stereo observation's one noise (``sigma_px`` or ``covariance_px2``, not both);
* covariances: exactly symmetric and positive definite with a margin of 1e-12 of their
  largest entry above the smallest eigenvalue allowed (a pure-Python LDLᵀ), so that
  numpy's checks on the slow path agree whatever their rounding; anything closer goes to
  the slow path;
* a unit quaternion, with the slow path's own formula.
"""

from __future__ import annotations

import functools
import math
from typing import Annotated, Any, Callable, Literal, Optional, Union

import msgspec
from msgspec import UNSET, Meta, UnsetType

import slamio.log.fields as F
import slamio.log.records3d as R3
from slamio.log.records import EVENT_KINDS, EVENT_SIDES, Event, LiveStep, Observation, Odometry, TruthLandmark, TruthPose


def _within(lo: float, hi: float) -> Any:
    return Annotated[float, Meta(ge=lo, le=hi)]


def _beyond_not(limit: float) -> Any:
    return _within(-limit, limit)


_STAMP = _beyond_not(F.STAMP_S)
_ID = Annotated[int, Meta(ge=0, le=F.MAX_ID)]
_COORD = _beyond_not(F.COORDINATE_M)
_WORLD = _beyond_not(F.WORLD_ANGLE_RAD)
_INC_M, _INC_RAD = _beyond_not(F.INCREMENT_M), _beyond_not(F.INCREMENT_RAD)
_ANGLE = _beyond_not(math.pi)
_SIG_L, _SIG_A = _within(*F.SIGMA_LENGTH_M), _within(*F.SIGMA_ANGLE_RAD)
_VAR = _beyond_not(F.MAX_POSITION_VARIANCE_M2)
_ROW3 = tuple[_VAR, _VAR, _VAR]
_TWIST_VAR = _beyond_not(R3.MAX_TWIST_VARIANCE)
_ROW6 = tuple[(_TWIST_VAR,) * 6]  # type: ignore[misc]
_PIXEL = _beyond_not(R3.MAX_PIXEL_PX)
_PIXEL_VAR = _beyond_not(R3.MAX_PIXEL_VARIANCE_PX2)
_ROW4 = tuple[(_PIXEL_VAR,) * 4]  # type: ignore[misc]
#: Looser than any unit quaternion: the norm check decides.
_QUAT = _beyond_not(2.0)

#: Each record type: its dataclass and fields in the dataclass's order as
#: (name, type, required). A required field may still be nullable (``landmark_id``).
SPEC: dict[str, tuple[type, tuple[tuple[str, Any, bool], ...]]] = {
    "odometry": (Odometry, (
        ("stamp_s", _STAMP, True), ("dx_m", _INC_M, True), ("dy_m", _INC_M, True),
        ("dtheta_rad", _INC_RAD, True), ("covariance", tuple[_ROW3, _ROW3, _ROW3], True),
        ("distance_m", _INC_M, False), ("angle_rad", _INC_RAD, False))),
    "observation": (Observation, (
        ("stamp_s", _STAMP, True), ("landmark_id", Optional[_ID], True), ("range_m", _within(*F.RANGE_M), True),
        ("bearing_rad", _ANGLE, False), ("sigma_range_m", _SIG_L, True), ("sigma_bearing_rad", _SIG_A, False),
        ("height_m", _COORD, False), ("sigma_height_m", _SIG_L, False), ("tag_yaw_rad", _ANGLE, False),
        ("sigma_tag_yaw_rad", _SIG_A, False), ("truth_landmark_id", _ID, False))),
    "truth_pose": (TruthPose, (
        ("stamp_s", _STAMP, True), ("x_m", _COORD, True), ("y_m", _COORD, True), ("theta_rad", _WORLD, False))),
    "truth_landmark": (TruthLandmark, (
        ("landmark_id", _ID, True), ("x_m", _COORD, True), ("y_m", _COORD, True), ("height_m", _COORD, False),
        ("yaw_rad", _WORLD, False))),
    "live_step": (LiveStep, (
        ("stamp_s", _STAMP, True), ("pose_index", Annotated[int, Meta(ge=0, le=F.MAX_POSE_INDEX)], True),
        ("latency_s", _within(0.0, F.STAMP_S), True))),
    "event": (Event, (
        ("stamp_s", _STAMP, True), ("kind", Literal[EVENT_KINDS], True),  # type: ignore[valid-type]
        ("pose_index", Annotated[int, Meta(ge=0, le=F.MAX_POSE_INDEX)], True),
        ("side", Literal[EVENT_SIDES], False))),  # type: ignore[valid-type]
    "velocity_odometry": (R3.VelocityOdometry, (
        ("stamp_s", _STAMP, True), ("dt_s", Annotated[float, Meta(gt=0.0, le=R3.MAX_DT_S)], True),
        ("v_mps", tuple[(_beyond_not(R3.MAX_SPEED_MPS),) * 3], True),  # type: ignore[misc]
        ("w_radps", tuple[(_beyond_not(R3.MAX_TURN_RATE_RADPS),) * 3], True),  # type: ignore[misc]
        ("covariance", tuple[(_ROW6,) * 6], True))),  # type: ignore[misc]
    "stereo_observation": (R3.StereoObservation, (
        ("stamp_s", _STAMP, True), ("track_id", _ID, True), ("u_left_px", _PIXEL, True),
        ("v_left_px", _PIXEL, True), ("u_right_px", _PIXEL, True), ("v_right_px", _PIXEL, True),
        ("sigma_px", _within(*R3.SIGMA_PIXEL_PX), False),
        ("covariance_px2", tuple[(_ROW4,) * 4], False))),  # type: ignore[misc]
    "truth_pose3": (R3.TruthPose3, (
        ("stamp_s", _STAMP, True), ("x_m", _COORD, True), ("y_m", _COORD, True), ("z_m", _COORD, True),
        ("qx", _QUAT, True), ("qy", _QUAT, True), ("qz", _QUAT, True), ("qw", _QUAT, True))),
    "truth_landmark3": (R3.TruthLandmark3, (
        ("landmark_id", _ID, True), ("x_m", _COORD, True), ("y_m", _COORD, True), ("z_m", _COORD, True))),
}
PLANAR_KINDS = ("odometry", "observation", "truth_pose", "truth_landmark", "live_step", "event")
KINDS_3D = ("velocity_odometry", "stereo_observation", "truth_pose3", "truth_landmark3", "live_step")


def _struct(kind: str, unset: bool) -> type:
    """The msgspec struct of ``kind``; optional fields default to None, or with ``unset`` to
    UNSET (told apart from an explicit null, to count the keys of a line that holds one)."""
    _, fields = SPEC[kind]
    spec: list[tuple] = []
    for name, kind_of, required in fields:
        if required:
            spec.append((name, kind_of))
        elif unset:
            spec.append((name, Union[kind_of, None, UnsetType], UNSET))
        else:
            spec.append((name, Optional[kind_of], None))
    return msgspec.defstruct(
        f"_{kind}{'_unset' if unset else ''}", spec, tag=kind, tag_field="type", forbid_unknown_fields=True,
        kw_only=True, gc=False,
    )


def _decoders(kinds: tuple[str, ...], unset: bool) -> tuple[msgspec.json.Decoder, dict[type, type]]:
    structs = {_struct(kind, unset): SPEC[kind][0] for kind in kinds}
    return msgspec.json.Decoder(Union[tuple(structs)]), structs  # type: ignore[return-value]


class FastDecoder:
    """The fast path for the records of a planar or a 3-D log (the header says which).

    ``record(raw)``: the record of one line (bytes, line ending allowed), or None: let the slow
    path decide.
    """

    def __init__(self, is_3d: bool) -> None:
        kinds = KINDS_3D if is_3d else PLANAR_KINDS
        self._plain, self._plain_classes = _decoders(kinds, unset=False)
        self._unset, self._unset_classes = _decoders(kinds, unset=True)
        self.record: Callable[[bytes], Any] = self._record_function()

    def _record_function(self) -> Callable[[bytes], Any]:
        """``record``: each line through :func:`_decoded`'s steps inlined, with the structs that
        take an absent field as None; a line whose keys that count does not account for and that
        holds a null goes again through :func:`_decoded` with the structs that tell an explicit
        null from an absent field (UNSET).

        The plain structs accept exactly the lines the UNSET ones do (they differ only in what an
        absent field holds), and their count of keys (``:``) matches only on a line without an
        explicit null (a null field holds None, counted as absent) and without a key given
        twice, where both give the same record: so this is :func:`_decoded` with the structs the
        line's nulls call for, without searching every line for ``null`` first."""
        decode, unset, unset_classes = self._plain.decode, self._unset, self._unset_classes
        finishing = {struct: (cls, _CHECKS.get(cls)) for struct, cls in self._plain_classes.items()}
        asdict, new, failed = msgspec.structs.asdict, _new, (msgspec.DecodeError, RecursionError)

        def record(raw: bytes) -> Any:
            try:
                struct = decode(raw)
            except failed:
                return None
            values = asdict(struct)
            if raw.count(b":") != 1 + len(values) - list(values.values()).count(None):
                # a null (told from an absent field by the UNSET structs), or a key given twice
                return _decoded(unset, unset_classes, raw, UNSET) if b"null" in raw else None
            cls, check = finishing[type(struct)]
            if check is not None and not check(values):
                return None
            made = new(cls)
            made.__dict__.update(values)  # a frozen dataclass, built without its __init__'s per-field setattr
            return made

        return record


def _decoded(decoder: msgspec.json.Decoder, classes: dict[type, type], raw: bytes, absent: Any) -> Any:
    """The record ``decoder`` makes of ``raw``, or None; ``absent`` is what its structs hold for
    a field the line leaves out (None, or UNSET where the line holds a null)."""
    try:
        struct = decoder.decode(raw)
    except (msgspec.DecodeError, RecursionError):
        return None
    values = msgspec.structs.asdict(struct)
    if raw.count(b":") != 1 + len(values) - list(values.values()).count(absent):
        return None  # a key given twice
    if absent is UNSET:
        values = {k: None if v is UNSET else v for k, v in values.items()}
    return _finished(classes[type(struct)], values)


def _finished(cls: type, values: dict) -> Any:
    """The record ``cls`` of ``values`` once the checks across its fields pass, else None."""
    check = _CHECKS.get(cls)
    if check is not None and not check(values):
        return None
    record = _new(cls)
    record.__dict__.update(values)  # a frozen dataclass, built without its __init__'s per-field setattr
    return record


_new = object.__new__


def _observation_ok(v: dict) -> bool:
    bearing, yaw = v["bearing_rad"], v["tag_yaw_rad"]
    return (
        (bearing is None) == (v["sigma_bearing_rad"] is None)
        and (v["height_m"] is None) == (v["sigma_height_m"] is None)
        and (yaw is None) == (v["sigma_tag_yaw_rad"] is None)
        and not (bearing is None and yaw is not None)
    )


def _odometry_ok(v: dict) -> bool:
    return (v["distance_m"] is None) == (v["angle_rad"] is None) and covariance3_ok(v["covariance"])


def _velocity_ok(v: dict) -> bool:
    return covariance_ok(v["covariance"], R3.MIN_TWIST_EIGENVALUE)


def _stereo_ok(v: dict) -> bool:
    c = v["covariance_px2"]
    if c is None:
        return v["sigma_px"] is not None
    return v["sigma_px"] is None and covariance_ok(c, R3.MIN_PIXEL_EIGENVALUE_PX2)


def _quaternion_ok(v: dict) -> bool:
    norm = math.sqrt(sum(v[k] * v[k] for k in ("qx", "qy", "qz", "qw")))  # records3d.check_quaternion's sum
    return not abs(norm - 1.0) > R3.QUATERNION_NORM_TOLERANCE


_CHECKS: dict[type, Callable[[dict], bool]] = {
    Observation: _observation_ok, Odometry: _odometry_ok, R3.VelocityOdometry: _velocity_ok,
    R3.TruthPose3: _quaternion_ok, R3.StereoObservation: _stereo_ok,
}

#: The margin, relative to a covariance's largest entry, by which its smallest eigenvalue
#: must clear the bound on the fast path (rounding in numpy's checks is ~1e-15 of it).
MARGIN = 1e-12


def covariance3_ok(c: tuple) -> bool:
    """A planar odometry covariance the slow path surely accepts (entries already bounded)."""
    (a, b, d), (b2, e, f), (d2, f2, g) = c
    if b != b2 or d != d2 or f != f2:
        return False
    if a > F.MAX_POSITION_VARIANCE_M2 or e > F.MAX_POSITION_VARIANCE_M2 or g > F.MAX_HEADING_VARIANCE_RAD2:
        return False
    t = F.MIN_COVARIANCE_EIGENVALUE + MARGIN * max(abs(a), abs(b), abs(d), abs(e), abs(f), abs(g))
    p1 = a - t  # LDLᵀ of (C - t·I): positive pivots ⇔ every eigenvalue of C above t
    if not p1 > 0.0:
        return False
    l21, l31 = b / p1, d / p1
    p2 = (e - t) - b * l21
    if not p2 > 0.0:
        return False
    l32 = (f - d * l21) / p2
    return (g - t) - d * l31 - l32 * l32 * p2 > 0.0


@functools.lru_cache(maxsize=1024)  # a 3-D log often repeats one twist covariance
def covariance_ok(c: tuple, smallest: float) -> bool:
    """An n×n covariance exactly symmetric whose eigenvalues all exceed ``smallest`` by the margin."""
    n = len(c)
    if any(c[i][j] != c[j][i] for i in range(n) for j in range(i)):
        return False
    t = smallest + MARGIN * max(abs(x) for row in c for x in row)
    lower: list[list[float]] = []
    pivots: list[float] = []
    for i in range(n):  # LDLᵀ of (C - t·I)
        row = []
        for j in range(i):
            s = c[i][j] - sum(row[k] * lower[j][k] * pivots[k] for k in range(j))
            row.append(s / pivots[j])
        p = (c[i][i] - t) - sum(row[k] * row[k] * pivots[k] for k in range(i))
        if not p > 0.0:
            return False
        lower.append(row)
        pivots.append(p)
    return True
