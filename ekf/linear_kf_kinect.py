"""``ekf-s000``: seed 000's linear Kalman-filter SLAM, reproduced as written.

Source: Norton & McCook, *Implementation of a Simultaneous Localization and Mapping
Algorithm in an Autonomous Robot*, Trinity College senior thesis, 2012
(``shared/seeds/000_*.txt``), §2.3 (the linear KF and its matrices) and §3.3
(initialisation, input vector, measurement vector, gain, update, landmark addition).

The paper's filter in one paragraph
    State ``x = [x_r, y_r, θ_r, x_1, y_1, …, x_n, y_n]`` in the paper's world frame, where
    the robot starts at (0, 0) facing *north* and θ is a **compass heading** (0 = north,
    clockwise positive). Prediction (eq. 19–20) ``x ← F x + G u``, ``P ← F P Fᵀ + V`` with
    F = I and G selecting the pose; the input ``u = (Δx_r, Δy_r, Δθ_r)`` is the Create's
    arc reading (ΔS, Δθ) turned into a world displacement (§3.3.2). The measurement of a
    landmark is its position relative to the robot rotated into world axes,
    ``y_i = x_i − x_r`` (§2.3.1), so ``H_i = [−I₂ 0 … I₂ …]`` has no heading column.
    Update (eq. 21–23) ``K = P Hᵀ (H P Hᵀ + W)⁻¹``, ``x ← x + K (y − H x)``,
    ``P ← P − K H P``. New landmarks are appended after the update (§3.3.7).

What is reproduced *as written* (each one can be switched for the comparison; the
defaults are the paper):

* **Heading used as if known.** Observations are rotated into world axes with the current
  heading estimate and H has no θ column, so landmarks never correct the heading: θ is
  dead reckoning (its cross-covariances stay zero with the paper's diagonal noise).
* **The §3.3.2 rotation.** The arc displacement (Δx′ sideways-right, Δy′ forward) is
  "rotated counterclockwise by θ" — but θ is a clockwise compass heading, so for every
  heading other than 0 and π forward motion comes out mirrored east–west (at θ = 90°,
  east, the robot is moved west). The same matrix
  is used wherever §3.3.4/§3.3.7 say "multiplied by a rotation matrix" (the text gives no
  other). ``rotation="as-written"`` (default) or ``"compass"`` (the rotation that is
  consistent with a clockwise heading).
* **The Δθ = 0 special case** ``u = (ΔS sin θ, ΔS cos θ, 0)``: taken when the reading is
  exactly zero (``straight_tolerance_rad=0.0``), as written. It is the compass-consistent
  formula, so under ``rotation="as-written"`` the two branches disagree in the sign of the
  sideways component. A positive tolerance also drops the (small) turn, since the special
  case has Δθ_r = 0.
* **Landmark initialisation** (§3.3.7): "the observed x and y coordinates … multiplied by
  a rotation matrix … and added to the state vector" — the rotated *relative* position,
  without adding the robot's position (``landmark_init="as-written"``; right only while
  the robot is at the origin). ``"offset-from-robot"`` adds the robot position.
  The new block of P is the fixed landmark covariance with **no cross-covariance**.
* **Non-re-observed landmarks in the measurement vector** (§3.3.4): every landmark in the
  state gets a row; one not seen this step gets its predicted value, i.e. zero innovation,
  but its W block still enters ``H P Hᵀ + W`` (a pseudo-measurement: it shrinks P as if it
  had been seen). ``pseudo_measurements=False`` stacks only re-observed landmarks.
* **Gain-row zeroing** (§3.3.5): rows of K belonging to non-re-observed landmarks are set
  to zero and eq. 22 is applied with that K, which leaves P non-symmetric (the pose rows
  change the landmark's columns, the landmark's rows stay). ``gain_zeroing=False`` keeps K.
* **"The variances were assumed to all be one"** (§3.3.1): P₀ = V_pose = I₃, landmark
  covariance I₂ (which also becomes the landmark's W block). The paper worked in the
  Create's and Kinect's units, so by default one means 1 mm² and 1 deg²
  (``variance_units="mm-deg"``); ``"m-rad"`` reads it as 1 m² and 1 rad². Both give the
  same mean (every position variance scales by the same factor and the heading is
  decoupled) and covariances 10⁶ apart. ``noise="log"`` replaces them with the log's own
  noise (start sigma, odometry covariance, observation sigmas).

Conventions at the edges
    Inside, everything is the paper's: world frame anchored at the start pose (origin at
    the start position, *north* = the start heading, *east* = its right), compass heading,
    and the paper's robot frame (x′ to the right, y′ forward, as in Figure 11). Units are
    SI (m, rad): a linear KF is unchanged by a change of units when its covariances are
    converted, so "1 mm²" is entered as 1e-6 m². The small functions below convert the
    log's x-forward/y-left/counter-clockwise records in, and the estimates back out.

The module-level functions are the filter's arithmetic; :class:`EkfS000` only holds the
state.
"""

from __future__ import annotations

import math

import numpy as np

from ekf.filter_outputs import FilterOutputs
from slamio.geometry import wrap_angle
from slamio.log import Header, Observation, Odometry, Step

__all__ = [
    "EkfS000",
    "NORTH_RAD",
    "compass_from_ccw",
    "ccw_from_compass",
    "compass_turn_from_ccw",
    "paper_xy_from_world",
    "world_xy_from_paper",
    "paper_pose_from_world",
    "world_pose_from_paper",
    "paper_to_world_jacobian",
    "paper_robot_xy_from_log_robot",
    "paper_robot_xy_from_range_bearing",
    "arc_reading",
    "rotation_matrix",
    "input_vector",
    "measurement_matrix",
    "landmark_rows",
    "h_times",
    "kalman_gain",
    "zero_gain_rows",
    "kalman_update",
    "unit_variances",
    "process_covariance_from_log",
    "observation_covariance_from_log",
]

ROBOT_DIM = 3
LANDMARK_DIM = 2
NORTH_RAD = math.pi / 2  # the log world's +y axis, when no start pose re-anchors "north"

ROTATIONS = ("as-written", "compass")
LANDMARK_INITS = ("as-written", "offset-from-robot")
VARIANCE_UNITS = ("mm-deg", "m-rad")
NOISES = ("paper", "log")

# The log's robot frame (x forward, y left) → the paper's (x′ right, y′ forward).
LOG_TO_PAPER_ROBOT = np.array([[0.0, -1.0], [1.0, 0.0]])


# --------------------------------------------------------------------------- conventions


def compass_from_ccw(theta_rad, north_rad=NORTH_RAD):
    """Compass heading (0 = north, clockwise positive) of a counter-clockwise angle.

    ``theta_rad`` is measured counter-clockwise from the world x axis; ``north_rad`` is the
    counter-clockwise angle of "north" (default: the +y axis, so east = +x is π/2).
    Not wrapped: the paper accumulates θ without wrapping.
    """
    return north_rad - theta_rad


def ccw_from_compass(heading_rad, north_rad=NORTH_RAD):
    """Counter-clockwise angle from the world x axis of a compass heading (inverse of
    :func:`compass_from_ccw`). Not wrapped."""
    return north_rad - heading_rad


def compass_turn_from_ccw(angle_rad):
    """A heading *change* in the paper's convention (clockwise positive) from a
    counter-clockwise one (the Create's angle packet, the log's ``dtheta_rad``)."""
    return -angle_rad


def _east_north_axes(north_rad: float) -> np.ndarray:
    """2×2 matrix whose columns are the world-frame unit vectors of the paper's x (east =
    north turned clockwise by 90°) and y (north) axes."""
    c, s = math.cos(north_rad), math.sin(north_rad)
    return np.array([[s, c], [-c, s]])


def paper_xy_from_world(xy, origin_xy, north_rad) -> np.ndarray:
    """A world point in the paper's frame: origin at ``origin_xy``, y along north."""
    return _east_north_axes(north_rad).T @ (np.asarray(xy, float) - np.asarray(origin_xy, float))


def world_xy_from_paper(xy_paper, origin_xy, north_rad) -> np.ndarray:
    """Inverse of :func:`paper_xy_from_world`."""
    return np.asarray(origin_xy, float) + _east_north_axes(north_rad) @ np.asarray(xy_paper, float)


def paper_pose_from_world(pose, origin_xy, north_rad) -> np.ndarray:
    """World pose ``(x_m, y_m, theta_rad)`` → paper pose ``(x, y, compass heading)``."""
    xy = paper_xy_from_world(pose[:2], origin_xy, north_rad)
    return np.array([xy[0], xy[1], compass_from_ccw(float(pose[2]), north_rad)])


def world_pose_from_paper(pose_paper, origin_xy, north_rad) -> np.ndarray:
    """Paper pose → world pose ``(x_m, y_m, theta_rad)``, heading wrapped into [−π, π)."""
    xy = world_xy_from_paper(pose_paper[:2], origin_xy, north_rad)
    return np.array([xy[0], xy[1], wrap_angle(ccw_from_compass(float(pose_paper[2]), north_rad))])


def paper_to_world_jacobian(north_rad) -> np.ndarray:
    """3×3 Jacobian of :func:`world_pose_from_paper` (constant: a rotation and a sign flip).

    A paper-frame pose covariance P becomes ``J P Jᵀ`` in the world frame; the inverse
    map has Jacobian ``Jᵀ`` (J is orthogonal).
    """
    J = np.zeros((3, 3))
    J[:2, :2] = _east_north_axes(north_rad)
    J[2, 2] = -1.0
    return J


def paper_robot_xy_from_log_robot(x_forward_m, y_left_m) -> np.ndarray:
    """A point in the log's robot frame (x forward, y left) in the paper's robot frame
    (x′ to the right, y′ forward; Figure 11)."""
    return LOG_TO_PAPER_ROBOT @ np.array([float(x_forward_m), float(y_left_m)])


def paper_robot_xy_from_range_bearing(range_m: float, bearing_rad: float) -> np.ndarray:
    """The landmark position the Kinect gave (§3.2.2, §3.3.4) in the paper's robot frame.

    The log's bearing is counter-clockwise from the robot's forward axis; the paper's
    landmark angle is counter-clockwise from x′ (to the right), i.e. bearing + 90°.
    """
    return paper_robot_xy_from_log_robot(range_m * math.cos(bearing_rad), range_m * math.sin(bearing_rad))


def arc_reading(odometry: Odometry) -> tuple[float, float]:
    """The Create's reading (ΔS metres, Δθ radians counter-clockwise) behind an odometry record.

    §3.3.2 starts from the Create's own packets (distance, angle). When the log kept them
    (``distance_m``/``angle_rad``) they are used; otherwise they are recovered from the
    increment: Δθ = dθ and ΔS the arc length of the chord (dx, dy) for that turn, signed by
    dx (exact for increments made with ``slamio.geometry.arc_increment``).
    """
    if odometry.distance_m is not None and odometry.angle_rad is not None:
        return float(odometry.distance_m), float(odometry.angle_rad)
    turn = float(odometry.dtheta_rad)
    chord = math.hypot(odometry.dx_m, odometry.dy_m)
    half = 0.5 * turn
    chord_per_arc = 1.0 if half == 0.0 else abs(math.sin(half) / half)
    return math.copysign(chord / chord_per_arc, odometry.dx_m), turn


# --------------------------------------------------------------------------- the paper's matrices


def rotation_matrix(heading_rad: float, rotation: str = "as-written") -> np.ndarray:
    """Robot-frame → world-frame rotation for a compass heading.

    ``"as-written"``: §3.3.2's matrix, "rotate counterclockwise by θ",
    ``[[cos θ, −sin θ], [sin θ, cos θ]]``. ``"compass"``: the rotation consistent with a
    clockwise heading, ``[[cos θ, sin θ], [−sin θ, cos θ]]`` (forward (0, 1) → (sin θ, cos θ),
    east at θ = 90°). They agree only for θ = 0 and π.
    """
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    if rotation == "as-written":
        return np.array([[c, -s], [s, c]])
    if rotation == "compass":
        return np.array([[c, s], [-s, c]])
    raise ValueError(f"rotation must be one of {ROTATIONS}, got {rotation!r}")


def input_vector(
    distance_m: float,
    turn_rad: float,
    heading_rad: float,
    *,
    rotation: str = "as-written",
    straight_tolerance_rad: float = 0.0,
) -> np.ndarray:
    """§3.3.2: the input ``u = (Δx_r, Δy_r, Δθ_r)`` from an arc reading.

    ``turn_rad`` is Δθ in the paper's convention (clockwise positive) and ``heading_rad``
    the current compass heading θ. With r = ΔS/Δθ the arc ends Δx′ = r(1 − cos Δθ) to the
    right and Δy′ = r sin Δθ ahead, and::

        u = [R(θ) · (Δx′, Δy′),  Δθ]                 (R from :func:`rotation_matrix`)
        u = (ΔS sin θ, ΔS cos θ, 0)    if Δθ = 0     (the paper's special case)

    "Δθ = 0" is ``|Δθ| <= straight_tolerance_rad``; the default 0.0 means exactly zero,
    as written (the Create 1 reports whole degrees, so zero is a common reading there).
    """
    if abs(turn_rad) <= straight_tolerance_rad:
        return np.array([distance_m * math.sin(heading_rad), distance_m * math.cos(heading_rad), 0.0])
    sideways = distance_m * (1.0 - math.cos(turn_rad)) / turn_rad
    ahead = distance_m * math.sin(turn_rad) / turn_rad
    dxy = rotation_matrix(heading_rad, rotation) @ np.array([sideways, ahead])
    return np.array([dxy[0], dxy[1], turn_rad])


def measurement_matrix(landmark_slots, state_dim: int) -> np.ndarray:
    """§2.3.1/§3.3.7: H with one ``H_i = [−I₂ 0 … I₂ …]`` block row per landmark.

    ``landmark_slots`` are the landmarks' positions in the state (0 = first landmark,
    whose x is state index 3). Shape ``(2·len(slots), state_dim)``; no heading column.
    """
    H = np.zeros((LANDMARK_DIM * len(landmark_slots), state_dim))
    for row, slot in enumerate(landmark_slots):
        r, c = LANDMARK_DIM * row, ROBOT_DIM + LANDMARK_DIM * slot
        H[r : r + 2, 0:2] = -np.eye(2)
        H[r : r + 2, c : c + 2] = np.eye(2)
    return H


def landmark_rows(landmark_slots) -> np.ndarray:
    """State indices (x, y, x, y, …) of the given landmark slots."""
    slots = np.asarray(list(landmark_slots), dtype=int)
    return (ROBOT_DIM + LANDMARK_DIM * slots[:, None] + np.arange(LANDMARK_DIM)).ravel()


def h_times(M: np.ndarray, landmark_slots) -> np.ndarray:
    """``H M`` for the H of :func:`measurement_matrix`, without forming H.

    Each block row of H is "landmark minus robot position", so ``H M`` is the landmark rows
    of M minus the robot's (x, y) rows. M may be a vector or a matrix (rows = state).
    """
    slots = list(landmark_slots)
    return M[landmark_rows(slots)] - M[np.tile([0, 1], len(slots))]


def kalman_gain(P: np.ndarray, landmark_slots, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 23: ``K = P Hᵀ (H P Hᵀ + W)⁻¹``; returns ``(K, H P)``.

    H is the paper's over ``landmark_slots`` (see :func:`h_times`). P may be
    non-symmetric (see :func:`zero_gain_rows`), so ``P Hᵀ`` and ``H P`` are formed apart.
    """
    HP = h_times(P, landmark_slots)
    S = h_times(HP.T, landmark_slots).T + W
    PHt = h_times(P.T, landmark_slots).T
    return np.linalg.solve(S.T, PHt.T).T, HP


def zero_gain_rows(K: np.ndarray, landmark_slots) -> np.ndarray:
    """§3.3.5: a copy of K with the rows of the given landmarks set to zero."""
    K = K.copy()
    slots = list(landmark_slots)
    if slots:
        K[landmark_rows(slots), :] = 0.0
    return K


def kalman_update(x: np.ndarray, P: np.ndarray, K: np.ndarray, y: np.ndarray, landmark_slots, HP: np.ndarray):
    """Eq. 21–22 with whatever K is given: ``x + K (y − H x)``, ``P − K (H P)`` (new arrays)."""
    return x + K @ (y - h_times(x, landmark_slots)), P - K @ HP


# --------------------------------------------------------------------------- noise


def unit_variances(variance_units: str) -> tuple[float, float]:
    """"The variances were assumed to all be one" (§3.3.1), in SI: ``(length m², angle rad²)``.

    ``"mm-deg"``: one in the Create's and Kinect's units (1 mm², 1 deg²);
    ``"m-rad"``: one in SI units (1 m², 1 rad²).
    """
    if variance_units == "mm-deg":
        return 1e-6, math.radians(1.0) ** 2
    if variance_units == "m-rad":
        return 1.0, 1.0
    raise ValueError(f"variance_units must be one of {VARIANCE_UNITS}, got {variance_units!r}")


def process_covariance_from_log(odometry: Odometry, heading_rad: float, rotation: str = "as-written") -> np.ndarray:
    """The log's odometry covariance as the paper's V pose block (3×3, paper world frame).

    The increment (dx, dy, dθ) of the log's robot frame is mapped to the paper's robot
    frame (x′ = −dy, y′ = dx), rotated into world axes with the same rotation the filter
    uses for the mean, and the turn's sign flipped (clockwise heading).
    """
    A = np.zeros((3, 3))
    A[:2, :2] = rotation_matrix(heading_rad, rotation) @ LOG_TO_PAPER_ROBOT
    A[2, 2] = -1.0
    return A @ np.asarray(odometry.covariance, dtype=float) @ A.T


def observation_covariance_from_log(
    observation: Observation, heading_rad: float, rotation: str = "as-written"
) -> np.ndarray:
    """The observation's range/bearing sigmas as a 2×2 covariance of its world-axes
    relative position (first-order; paper world frame, same rotation as the mean)."""
    r, b = observation.range_m, observation.bearing_rad
    J = np.array([[math.cos(b), -r * math.sin(b)], [math.sin(b), r * math.cos(b)]])
    A = rotation_matrix(heading_rad, rotation) @ LOG_TO_PAPER_ROBOT @ J
    return A @ np.diag([observation.sigma_range_m**2, observation.sigma_bearing_rad**2]) @ A.T


def _choice(value: str, allowed: tuple[str, ...], name: str) -> str:
    if value not in allowed:
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
    return value


# --------------------------------------------------------------------------- the filter


class EkfS000(FilterOutputs):
    """Seed 000's linear KF SLAM (implements ``slamio.estimator.AssociatingEstimator``).

    Built ``EkfS000(header)``; the keywords select the documented alternatives to the
    paper's choices (the defaults are the paper, see the module docstring):

    * ``rotation``: ``"as-written"`` | ``"compass"``;
    * ``landmark_init``: ``"as-written"`` (rotated relative position) | ``"offset-from-robot"``;
    * ``straight_tolerance_rad``: |Δθ| at or below which the Δθ = 0 special case is taken (0.0);
    * ``variance_units``: ``"mm-deg"`` | ``"m-rad"``, the units of "variances all one";
    * ``noise``: ``"paper"`` (unit variances) | ``"log"`` (the log's start sigma, odometry
      covariance and observation sigmas);
    * ``pseudo_measurements``: stack non-re-observed landmarks with zero innovation (True);
    * ``gain_zeroing``: zero their gain rows (True).

    Uses the log's landmark ids; observations without an id, and repeated sightings of one
    id within a step after the first, are ignored (association None).

    The paper-frame state (for tests and docs) is available from :meth:`paper_state`.
    """

    name = "ekf-s000"

    def __init__(
        self,
        header: Header,
        *,
        rotation: str = "as-written",
        landmark_init: str = "as-written",
        straight_tolerance_rad: float = 0.0,
        variance_units: str = "mm-deg",
        noise: str = "paper",
        pseudo_measurements: bool = True,
        gain_zeroing: bool = True,
    ):
        self.rotation = _choice(rotation, ROTATIONS, "rotation")
        self.landmark_init = _choice(landmark_init, LANDMARK_INITS, "landmark_init")
        self.straight_tolerance_rad = float(straight_tolerance_rad)
        self.variance_units = _choice(variance_units, VARIANCE_UNITS, "variance_units")
        self.noise = _choice(noise, NOISES, "noise")
        self.pseudo_measurements = bool(pseudo_measurements)
        self.gain_zeroing = bool(gain_zeroing)
        self._length_var, self._angle_var = unit_variances(variance_units)

        # The paper's world frame: the robot starts at (0, 0) facing north (§3.3.1).
        self._origin = np.array(header.start_pose[:2], dtype=float)
        self._north = float(header.start_pose[2])
        self._x = np.zeros(ROBOT_DIM)
        if self.noise == "paper":
            self._P = np.diag([self._length_var, self._length_var, self._angle_var])
        else:
            J = paper_to_world_jacobian(self._north)
            self._P = J.T @ np.diag(np.square(header.start_sigma)) @ J
        self._W = np.zeros((0, 0))
        self._slot: dict[int, int] = {}  # landmark id → slot (0, 1, …) in the state
        self._trajectory: list[tuple[float, float, float]] = []
        self._associations: list[int | None] = []
        self.special_cases = 0  # predictions that took the Δθ = 0 branch

    # ------------------------------------------------------------------ protocol

    def step(self, step: Step) -> None:
        """§3.3.2–3.3.7 in order: input + predict, measurement vector + gain + update,
        then append the landmarks seen for the first time."""
        used: dict[int, Observation] = {}
        self._associations = []
        for observation in step.observations:
            lid = observation.landmark_id
            if lid is None or lid in used or observation.range_only:  # the paper has no range-only landmarks
                self._associations.append(None)
            else:
                used[lid] = observation
                self._associations.append(lid)
        if step.odometry is not None:
            self._predict(step.odometry)
        if self._slot:
            self._update({lid: obs for lid, obs in used.items() if lid in self._slot})
        for lid, observation in used.items():
            if lid not in self._slot:
                self._add_landmark(lid, observation)
        self._trajectory.append(self.current_pose())

    def step_associations(self) -> list[int | None]:
        """For each observation of the last step: its landmark id, or None if ignored."""
        return list(self._associations)

    def current_pose(self) -> tuple[float, float, float]:
        """Current robot pose ``(x_m, y_m, theta_rad)`` in the log's world frame."""
        x, y, th = world_pose_from_paper(self._x[:ROBOT_DIM], self._origin, self._north)
        return float(x), float(y), float(th)

    def current_covariance(self) -> np.ndarray:
        """3×3 covariance of the current pose over world (x, y, θ counter-clockwise).

        The paper's update leaves P non-symmetric (gain-row zeroing); the pose block is
        symmetrised here, at the output edge.
        """
        P = self._P[:ROBOT_DIM, :ROBOT_DIM]
        J = paper_to_world_jacobian(self._north)
        return J @ (0.5 * (P + P.T)) @ J.T

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Landmark id → estimated ``(x_m, y_m)`` in the log's world frame."""
        out = {}
        for lid, slot in self._slot.items():
            i = ROBOT_DIM + LANDMARK_DIM * slot
            xy = world_xy_from_paper(self._x[i : i + 2], self._origin, self._north)
            out[lid] = (float(xy[0]), float(xy[1]))
        return out

    def paper_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the state ``x`` and covariance ``P`` in the paper's frame (SI units)."""
        return self._x.copy(), self._P.copy()

    # ------------------------------------------------------------------ the steps

    def _predict(self, odometry: Odometry) -> None:
        distance, angle_ccw = arc_reading(odometry)
        heading = float(self._x[2])
        turn = compass_turn_from_ccw(angle_ccw)
        if abs(turn) <= self.straight_tolerance_rad:
            self.special_cases += 1
        u = input_vector(
            distance, turn, heading, rotation=self.rotation, straight_tolerance_rad=self.straight_tolerance_rad
        )
        if self.noise == "paper":
            V = np.diag([self._length_var, self._length_var, self._angle_var])
        else:
            V = process_covariance_from_log(odometry, heading, self.rotation)
        self._x[:ROBOT_DIM] += u  # F x + G u, F = I
        self._P[:ROBOT_DIM, :ROBOT_DIM] += V  # F P Fᵀ + V, V zero outside the pose

    def _relative_world(self, observation: Observation, heading: float) -> np.ndarray:
        p = paper_robot_xy_from_range_bearing(observation.range_m, observation.bearing_rad)
        return rotation_matrix(heading, self.rotation) @ p

    def _landmark_cov(self, observation: Observation, heading: float) -> np.ndarray:
        if self.noise == "paper":
            return self._length_var * np.eye(LANDMARK_DIM)
        return observation_covariance_from_log(observation, heading, self.rotation)

    def _update(self, seen: dict[int, Observation]) -> None:
        heading = float(self._x[2])
        slots_seen = {self._slot[lid]: obs for lid, obs in seen.items()}
        if self.noise == "log":  # the landmark's W block follows its latest sighting
            for slot, obs in slots_seen.items():
                i = LANDMARK_DIM * slot
                self._W[i : i + 2, i : i + 2] = self._landmark_cov(obs, heading)
        rows = sorted(self._slot.values()) if self.pseudo_measurements else sorted(slots_seen)
        if not rows:
            return
        y = h_times(self._x, rows)  # non-re-observed landmarks: their prediction (§3.3.4)
        for row, slot in enumerate(rows):
            if slot in slots_seen:
                y[2 * row : 2 * row + 2] = self._relative_world(slots_seen[slot], heading)
        w_idx = np.concatenate([[2 * s, 2 * s + 1] for s in rows])
        W = self._W[np.ix_(w_idx, w_idx)]
        K, HP = kalman_gain(self._P, rows, W)
        if self.gain_zeroing:
            K = zero_gain_rows(K, [s for s in self._slot.values() if s not in slots_seen])
        self._x, self._P = kalman_update(self._x, self._P, K, y, rows, HP)

    def _add_landmark(self, lid: int, observation: Observation) -> None:
        heading = float(self._x[2])
        xy = self._relative_world(observation, heading)
        if self.landmark_init == "offset-from-robot":
            xy = xy + self._x[:2]
        cov = self._landmark_cov(observation, heading)
        n = self._x.shape[0]
        self._x = np.concatenate([self._x, xy])
        P = np.zeros((n + 2, n + 2))
        P[:n, :n] = self._P
        P[n:, n:] = cov  # no cross-covariance (§3.3.7)
        self._P = P
        m = self._W.shape[0]
        W = np.zeros((m + 2, m + 2))
        W[:m, :m] = self._W
        W[m:, m:] = cov
        self._W = W
        self._slot[lid] = len(self._slot)
