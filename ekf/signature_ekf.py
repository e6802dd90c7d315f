"""Seed 001 (Menon, "Raspberry Pi GoPiGo Robot EKF SLAM Implementation"), reproduced as written.

The paper describes EKF-SLAM for a GoPiGo robot with an ultrasonic rangefinder. This module
implements its filter, ``ekf-s001``, on this project's run logs, keeping every choice the
paper makes — including the ones that are wrong — so that a run can show what each costs.
Each flaw is listed below and in ``docs/estimators.md``; every one that can be switched off
has a keyword of :class:`EkfS001` that does so.

What the paper specifies (section numbers are the paper's)
==========================================================

State, eq. 19 (§III-E)
    ``y = (x, y, θ, m1x, m1y, s1, …, mNx, mNy, sN)`` — the robot pose, then per landmark its
    position *and its signature* ``s_i``. Here the signature is the landmark's **height**
    (``Observation.height_m``): it is the one property our sensors report that tells
    landmarks apart (the ``cylinders`` scenario's red/green/blue cylinders are 0.4/0.6/0.8 m
    tall). Observations without a height use range and bearing only; the landmark's ``s``
    then stays an inert "unknown" entry (mean 0, variance :data:`UNKNOWN_SIGNATURE_VARIANCE`,
    uncorrelated with everything) until a height is observed.

EKF, Algorithm 3 lines 2–6 (§III-D)::

    2: μ̄ = g(u, μ)                 3: Σ̄ = G Σ Gᵀ + R
    4: K = Σ̄ Hᵀ (H Σ̄ Hᵀ + Q)⁻¹     5: μ = μ̄ + K (z − h(μ̄))     6: Σ = (I − K H) Σ̄

Motion g and its Jacobian G, eqs. 23–26 (§VII-B, VII-C) — the robot only moves forward by
``d`` or rotates in place by ``θ'``::

    forward (23):  (x, y, θ) ← (x + d cos θ, y + d sin θ, θ)
                   G = I + [[0, 0, −d sin θ], [0, 0, d cos θ], [0, 0, 0]]      (25)
    rotate  (24):  (x, y, θ) ← (x, y, θ + θ')                  G = I           (26)

    Landmarks do not move: the full-state Jacobian is blockdiag(G, I) and R acts on the
    pose only (Thrun et al.'s F_xᵀ R F_x, the paper's reference [3]).

R (§IV): one constant 3×3 covariance over world (x, y, θ), computed with
``numpy.ma.cov`` from 30 tape-measured forward moves and 30 rotations; it does not depend
on how far the robot moved and is never rotated with the heading.

Q, eq. 20 (§III-E): ``Q = diag(σ_r, σ_φ, σ_s)``, with the text calling σ "the corresponding
covariances" — standard deviations where variances belong.

Data association (§IV): nearest neighbour, "closeness of the previously observed
landmarks to their new expected location based on the robot movement". No threshold is
given.

The correction step (lines 4–6) was never run (§IV: the association failed with the
ultrasonic sensor, "the correction step could not be implemented").

How this module reads each of those on our logs
===============================================

* **Arc odometry → the paper's two moves.** A log's odometry is an arc (the Create's
  ``distance_m``/``angle_rad``). Each reading is applied as the paper's robot executes
  commands: forward ``d = distance_m`` (eq. 23) *then* rotate ``θ' = angle_rad`` (eq. 24),
  as **one** prediction (lines 2–3) with ``G = G_rotate · G_forward = G_forward`` and R
  added once per reading (one reading = one calibrated "move"). For a pure forward or a
  pure rotation this is exactly eq. 23 or 24. A reading without ``distance_m`` is turned
  back into (d, θ') by inverting the arc model (:func:`paper_moves`).
* **R**: constant. Default: the covariance of the log's *first* odometry reading, taken as
  a world-frame (x, y, θ) matrix — it stands in for the calibration trials (the robot's
  first move, starting along the world axes of pose 0, is what a tape-measure trial
  measures). Override with ``motion_covariance=``.
* **Q**: ``diag(σ_r, σ_φ, σ_s)`` with each observation's own σ values (the log's σ are
  our sensor's calibration), or a constant ``q_sigmas=(σ_r, σ_φ, σ_s)`` like the paper's.
* **h and H** (the paper gives h only as "trigonometry"): Thrun's range, bearing,
  signature: ``h = (|m − p|, atan2(m_y − y, m_x − x) − θ, s)``; the bearing innovation and
  the heading are wrapped with the project's one ``wrap_angle``.
* **Nearest neighbour**: the observation is placed in the world from the current mean pose
  (``p + r (cos(θ+φ), sin(θ+φ))``); its Euclidean distance to every landmark's mean
  position — plus the signature difference ``s_obs − s_i`` as a third coordinate when both
  have one (a height, so also metres) — picks the nearest. Farther than ``gate_m`` (no
  threshold in the paper; default :data:`DEFAULT_GATE_M`) → a new landmark.
  Two observations of one step may go to the same landmark (the paper has no exclusion).
* **New landmarks** (the paper does not say how): the textbook augmentation — mean from
  the inverse observation model, covariance ``G_p Σ_rr G_pᵀ + G_z Q G_zᵀ`` and cross
  covariance ``G_p Σ_r·``, with the same as-written Q. This is the exact limit of [3]'s
  "initialise with infinite covariance, then update".
* **Correction**: the textbook lines 4–6 with the as-written Q, one observation at a time,
  ``Σ = (I − K H) Σ̄`` (not Joseph form), symmetrised against round-off.
  ``correction=False`` runs what the paper actually ran: prediction only.

Flaws reproduced (keyword that removes each, for measuring its cost)
====================================================================

1. Q holds σ where σ² belongs (``q_diagonal="variance"``). In SI units σ < 1, so σ > σ²:
   every measurement is trusted far less than it should be (σ_φ = 0.01 rad is used as if it
   were 0.1 rad). The size — even the direction — of this error depends on the units:
   in the paper's centimetres a 3 cm range σ becomes a 1.7 cm one (over-trusted).
2. R is constant: independent of the distance moved and not rotated with the heading
   (``motion_noise="log"`` uses each reading's own covariance, rotated into the world).
3. Forward-then-rotate instead of the arc: the position moves along the old heading, so
   each reading misplaces the robot sideways by ≈ d·θ'/2 (``motion_model="arc"``).
4. Nearest neighbour by Euclidean distance with a fixed gate ignores the uncertainty: two
   landmarks closer together than the pose error are confused (``gate_m`` sets the gate;
   there is no Mahalanobis option because the paper has none).
5. The paper never ran its correction step (``correction=False`` reproduces that run:
   dead reckoning with eqs. 23–26).

The module-level functions are the filter's arithmetic, each small and testable on its own;
:class:`EkfS001` only holds the filter state. Numpy only; never gtsam.
"""

from __future__ import annotations

import math

import numpy as np

from ekf.filter_outputs import FilterOutputs
from ekf.models import (
    landmark_from_range_bearing, landmark_init_jacobians, motion_jacobians, predict_pose, range_bearing,
    range_bearing_jacobians,
)
from slamio.geometry import wrap_angle
from slamio.log import Header, Observation, Odometry, Step

__all__ = [
    "EkfS001",
    "DEFAULT_GATE_M",
    "UNKNOWN_SIGNATURE_VARIANCE",
    "paper_moves",
    "move_forward",
    "move_forward_jacobian",
    "rotate_in_place",
    "rotate_in_place_jacobian",
    "predict_forward_rotate",
    "observation_noise",
    "expected_observation",
    "observation_jacobian",
    "observation_world_point",
    "nearest_landmark",
    "ekf_correct",
    "predict_covariance",
]

ROBOT_DIM = 3  # x_m, y_m, theta_rad
LANDMARK_DIM = 3  # m_x, m_y, s (eq. 19)

#: Default nearest-neighbour gate (m). The paper gives none; 0.5 m is half the smallest
#: spacing between two landmarks in the bundled scenarios (the arena's tags, 1.016 m apart).
DEFAULT_GATE_M = 0.5

#: Variance of a signature never observed (an "unknown" height: σ = 100 m).
UNKNOWN_SIGNATURE_VARIANCE = 1e4

_MOTION_MODELS = ("forward-rotate", "arc")
_MOTION_NOISES = ("constant", "log")
_Q_DIAGONALS = ("sigma", "variance")


# --------------------------------------------------------------------------- motion (eqs. 23–26)


def _sin_over_x(x: float) -> float:
    return 1.0 - x * x / 6.0 if abs(x) < 1e-4 else math.sin(x) / x


def paper_moves(odometry: Odometry) -> tuple[float, float]:
    """The paper's two commands ``(d, θ')`` for one odometry reading: forward d, then rotate θ'.

    ``d = distance_m`` and ``θ' = angle_rad`` when the log keeps the Create's reading.
    Otherwise they are recovered from the SE(2) increment by inverting the arc model
    (``slamio.geometry.arc_increment``): θ' = dθ and, since the arc's chord is
    ``|d| · |sin(θ'/2)/(θ'/2)|``, ``d = ±chord / sinc(θ'/2)`` with the sign of dx.
    """
    if odometry.distance_m is not None and odometry.angle_rad is not None:
        return float(odometry.distance_m), float(odometry.angle_rad)
    angle = float(odometry.dtheta_rad)
    chord = math.hypot(odometry.dx_m, odometry.dy_m)
    d = chord / abs(_sin_over_x(0.5 * angle))
    return (d if odometry.dx_m >= 0.0 else -d), angle


def move_forward(pose, d: float) -> np.ndarray:
    """Eq. 23: the pose after moving forward ``d`` metres along its heading."""
    x, y, th = (float(v) for v in pose)
    return np.array([x + d * math.cos(th), y + d * math.sin(th), th])


def move_forward_jacobian(pose, d: float) -> np.ndarray:
    """Eq. 25: ``G = ∂(eq. 23)/∂(x, y, θ) = I + [[0,0,−d sin θ],[0,0,d cos θ],[0,0,0]]``."""
    th = float(pose[2])
    G = np.eye(3)
    G[0, 2] = -d * math.sin(th)
    G[1, 2] = d * math.cos(th)
    return G


def rotate_in_place(pose, theta_prime: float) -> np.ndarray:
    """Eq. 24: the pose after rotating in place by ``θ'`` (heading wrapped)."""
    x, y, th = (float(v) for v in pose)
    return np.array([x, y, wrap_angle(th + theta_prime)])


def rotate_in_place_jacobian() -> np.ndarray:
    """Eq. 26: rotating in place has Jacobian ``G = I``."""
    return np.eye(3)


def predict_forward_rotate(pose, d: float, theta_prime: float) -> tuple[np.ndarray, np.ndarray]:
    """One odometry reading as the paper's forward ``d`` then rotate ``θ'``: ``(μ̄, G)``.

    ``μ̄ = eq24(eq23(pose, d), θ')`` and, by the chain rule,
    ``G = G_rotate(26) · G_forward(25) = G_forward`` evaluated at the starting heading.
    """
    moved = move_forward(pose, d)
    G = rotate_in_place_jacobian() @ move_forward_jacobian(pose, d)
    return rotate_in_place(moved, theta_prime), G


# --------------------------------------------------------------------------- observation


def observation_noise(sigmas, *, diagonal: str = "sigma") -> np.ndarray:
    """Eq. 20: ``Q = diag(σ_r, σ_φ[, σ_s])`` as written, or ``diag(σ²)`` with ``diagonal="variance"``.

    ``sigmas`` are standard deviations (m, rad[, m]). The paper puts them on the diagonal
    unsquared (``diagonal="sigma"``, the default); ``"variance"`` is the correct form.
    """
    s = np.asarray(sigmas, dtype=float)
    if diagonal == "sigma":
        return np.diag(s)
    if diagonal == "variance":
        return np.diag(s * s)
    raise ValueError(f"diagonal must be one of {_Q_DIAGONALS}, got {diagonal!r}")


def expected_observation(pose, landmark_xy, signature: float | None = None) -> np.ndarray:
    """h(μ̄): ``(range, bearing[, signature])`` of a landmark seen from ``pose``.

    The paper gives h only as "trigonometry"; this is [3]'s: range ``|m − p|``, bearing
    ``atan2(m_y − y, m_x − x) − θ`` (wrapped, counter-clockwise from forward) and, when a
    signature is measured, the landmark's own signature ``s``.
    """
    r, b = range_bearing(pose, landmark_xy)
    return np.array([r, b]) if signature is None else np.array([r, b, float(signature)])


def observation_jacobian(pose, landmark_xy, with_signature: bool) -> np.ndarray:
    """H over ``(x, y, θ, m_x, m_y, s)``: 2×6, or 3×6 with the signature row ``[0 0 0 0 0 1]``."""
    H_pose, H_landmark = range_bearing_jacobians(pose, landmark_xy)
    H = np.zeros((3 if with_signature else 2, ROBOT_DIM + LANDMARK_DIM))
    H[:2, :3] = H_pose
    H[:2, 3:5] = H_landmark
    if with_signature:
        H[2, 5] = 1.0
    return H


def observation_world_point(pose, range_m: float, bearing_rad: float) -> np.ndarray:
    """Where an observation puts its landmark in the world, seen from ``pose``."""
    return np.asarray(landmark_from_range_bearing(pose, range_m, bearing_rad), dtype=float)


def nearest_landmark(
    point_xy,
    signature: float | None,
    landmarks_xy: np.ndarray,
    landmark_signatures: np.ndarray,
    has_signature: np.ndarray,
    gate_m: float,
) -> tuple[int | None, float]:
    """The paper's nearest-neighbour association: ``(index or None, distance)``.

    Distance from the observation's world point to each landmark's mean position,
    Euclidean; when the observation carries a signature and the landmark has one, the
    signature difference is a third coordinate (heights are metres too). Returns the index
    of the nearest landmark, or ``None`` when there is none within ``gate_m`` (the
    observation is then a new landmark); the distance is ``inf`` with no landmarks.
    """
    landmarks_xy = np.asarray(landmarks_xy, dtype=float).reshape(-1, 2)
    if landmarks_xy.shape[0] == 0:
        return None, math.inf
    d2 = np.sum(np.square(landmarks_xy - np.asarray(point_xy, dtype=float)), axis=1)
    if signature is not None:
        ds = np.where(np.asarray(has_signature, bool), np.asarray(landmark_signatures, float) - signature, 0.0)
        d2 = d2 + ds * ds
    i = int(np.argmin(d2))
    distance = math.sqrt(float(d2[i]))
    return (i if distance <= gate_m else None), distance


# --------------------------------------------------------------------------- EKF arithmetic


def ekf_correct(
    mean: np.ndarray, P: np.ndarray, cols, H_cols: np.ndarray, innovation: np.ndarray, Q: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Algorithm 3 lines 4–6 for a measurement whose H is zero outside the columns ``cols``.

    ``H_cols`` (m×k) holds those columns of the full H, ``innovation = z − h(μ̄)``::

        K = Σ̄ Hᵀ (H Σ̄ Hᵀ + Q)⁻¹,   μ = μ̄ + K·innovation,   Σ = (I − K H) Σ̄

    computed in O(n·k) and O(n²) (``(I − KH)Σ̄ = Σ̄ − K (Σ̄ Hᵀ)ᵀ``), then symmetrised.
    Returns new ``(mean, P, K)``; the heading is *not* wrapped here.
    """
    cols = np.asarray(cols)
    PHt = P[:, cols] @ H_cols.T
    S = H_cols @ PHt[cols, :] + Q
    K = np.linalg.solve(S.T, PHt.T).T
    new_mean = mean + K @ innovation
    new_P = P - K @ PHt.T
    new_P += new_P.T  # numpy buffers the overlapping transpose
    new_P *= 0.5
    return new_mean, new_P, K


def predict_covariance(P: np.ndarray, G: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Line 3 for the full state, **in place**, O(n): ``blockdiag(G, I) Σ blockdiag(G, I)ᵀ + F_xᵀ R F_x``.

    Landmarks do not move, so only the robot rows and columns change:
    ``Σ_rr ← G Σ_rr Gᵀ + R``, ``Σ_rm ← G Σ_rm``. Returns ``P``.
    """
    r = slice(0, ROBOT_DIM)
    m = slice(ROBOT_DIM, P.shape[0])
    P[r, r] = G @ P[r, r] @ G.T + R
    P[r, m] = G @ P[r, m]
    P[m, r] = P[r, m].T
    return P


def trial_calibration(header: Header) -> tuple[np.ndarray | None, tuple | None]:
    """``(R, q_sigmas)`` from the trial calibration a log's header carries, as seed 001 made
    its R and Q (§IV): R the covariance of the pooled forward and rotate trials
    (``pooled_motion_covariance`` of ``fgslam calibrate TRIALS.csv``), Q's σ_r and σ_φ the
    sensor trials' (σ_s stays each observation's own: the trials have no signature). None
    where the header has no ``noise.calibration`` or it lacks that part. A calibration that is
    not what ``fgslam calibrate`` writes is one ``FgslamError`` line (the same check as
    :func:`slamio.noise.trials.load_calibration`), never a traceback."""
    from slamio.noise.trials import calibration_from_dict

    calibration = header.noise.get("calibration") if isinstance(header.noise, dict) else None
    if calibration is None:
        return None, None
    checked = calibration_from_dict(
        calibration, "the log's header (noise.calibration)",
        "replace it: fgslam run LOG --calibration FILE (a file from fgslam calibrate TRIALS.csv --out FILE)")
    pooled = checked.pooled_motion_covariance
    R = None if pooled is None else np.array(pooled, dtype=float).reshape(3, 3)
    sensor = checked.observation
    q = None if not sensor else (float(sensor["sigma_range_m"]), float(sensor["sigma_bearing_rad"]), None)
    return R, q


# --------------------------------------------------------------------------- the filter


class EkfS001(FilterOutputs):
    """Seed 001's EKF-SLAM as written: forward/rotate motion, σ-diagonal Q, nearest neighbour.

    Implements ``slamio.estimator.AssociatingEstimator``. It never reads
    ``Observation.landmark_id`` (the paper has no ids) nor ``truth_landmark_id``: every
    landmark it maps is its own, keyed −1, −2, … in order of creation.

    Keywords (defaults reproduce the paper; see the module docstring for each flaw):

    ``q_diagonal``        ``"sigma"`` (eq. 20 as written) or ``"variance"`` (correct).
    ``q_sigmas``          ``None``: each observation's own (σ_r, σ_φ, σ_height); or a constant
                          ``(σ_r, σ_φ, σ_s)`` like the paper's calibrated Q (a None entry:
                          the observation's own).
    ``motion_covariance`` and ``q_sigmas`` default to the log's trial calibration when its
    header carries one (``noise.calibration``, :func:`trial_calibration`): the paper's R and
    Q come from its 30 + 30 measured trials, and so do ours.
    ``motion_model``      ``"forward-rotate"`` (eqs. 23–26) or ``"arc"`` (the log's SE(2)
                          increment, exact).
    ``motion_noise``      ``"constant"`` (the paper's R) or ``"log"`` (each reading's own
                          covariance rotated into the world frame).
    ``motion_covariance`` the constant R (3×3, world x, y, θ); ``None`` = the first odometry
                          reading's covariance (see the module docstring).
    ``gate_m``            nearest-neighbour gate in metres (the paper gives none).
    ``use_signature``     use ``height_m`` as the signature s when observations carry it.
    ``correction``        ``False`` = prediction only, what the paper actually ran
                          (observations are then ignored).
    """

    name = "ekf-s001"

    def __init__(
        self,
        header: Header,
        *,
        q_diagonal: str = "sigma",
        q_sigmas=None,
        motion_model: str = "forward-rotate",
        motion_noise: str = "constant",
        motion_covariance=None,
        gate_m: float = DEFAULT_GATE_M,
        use_signature: bool = True,
        correction: bool = True,
    ):
        if q_diagonal not in _Q_DIAGONALS:
            raise ValueError(f"q_diagonal must be one of {_Q_DIAGONALS}, got {q_diagonal!r}")
        if motion_model not in _MOTION_MODELS:
            raise ValueError(f"motion_model must be one of {_MOTION_MODELS}, got {motion_model!r}")
        if motion_noise not in _MOTION_NOISES:
            raise ValueError(f"motion_noise must be one of {_MOTION_NOISES}, got {motion_noise!r}")
        if not gate_m > 0.0:
            raise ValueError(f"gate_m must be > 0, got {gate_m!r}")
        self.q_diagonal = q_diagonal
        calibrated_R, calibrated_q = trial_calibration(header)
        if motion_covariance is None:
            motion_covariance = calibrated_R
        if q_sigmas is None:
            q_sigmas = calibrated_q
        self.q_sigmas = None if q_sigmas is None else tuple(None if v is None else float(v) for v in q_sigmas)
        if self.q_sigmas is not None and len(self.q_sigmas) != 3:
            raise ValueError("q_sigmas must be (sigma_range_m, sigma_bearing_rad, sigma_signature)")
        self.motion_model = motion_model
        self.motion_noise = motion_noise
        self.R = None if motion_covariance is None else np.array(motion_covariance, dtype=float).reshape(3, 3)
        self.gate_m = float(gate_m)
        self.use_signature = bool(use_signature)
        self.correction = bool(correction)

        self._mean = np.array(header.start_pose, dtype=float)
        self._mean[2] = wrap_angle(float(self._mean[2]))
        self._P = np.diag(np.square(np.asarray(header.start_sigma, dtype=float)))
        self._has_signature: list[bool] = []
        self._trajectory: list[tuple[float, float, float]] = []
        self._associations: list[int | None] = []
        self.updates = 0
        self.landmarks_added = 0

    # ------------------------------------------------------------------ protocol

    def step(self, step: Step) -> None:
        """Predict with ``step.odometry`` (if any), then associate and apply each observation."""
        if step.odometry is not None:
            self._predict(step.odometry)
        self._associations = []
        for observation in step.observations:  # the paper has no range-only landmarks: skip them
            use = self.correction and not observation.range_only
            self._associations.append(self._observe(observation) if use else None)
        self._trajectory.append(self.current_pose())

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Key −1, −2, … (creation order) → estimated ``(x_m, y_m)``."""
        return {-(k + 1): (float(self._mean[i]), float(self._mean[i + 1])) for k, i in self._slots()}

    def landmark_heights(self) -> dict[int, float]:
        """Key → estimated signature s (a height, m), for landmarks whose height was observed."""
        return {-(k + 1): float(self._mean[i + 2]) for k, i in self._slots() if self._has_signature[k]}

    def step_associations(self) -> list[int | None]:
        """Per observation of the last step: the key it was used as (new key if it created one)."""
        return list(self._associations)

    def current_covariance(self) -> np.ndarray:
        """3×3 covariance of the current robot pose (a copy)."""
        return self._P[:ROBOT_DIM, :ROBOT_DIM].copy()

    # ------------------------------------------------------------------ more accessors

    def state_mean(self) -> np.ndarray:
        """The full state of eq. 19, ``[x, y, θ, m1x, m1y, s1, …]`` (a copy)."""
        return self._mean.copy()

    def state_covariance(self) -> np.ndarray:
        """The full joint covariance (a copy)."""
        return self._P.copy()

    # ------------------------------------------------------------------ the operations

    def _slots(self):
        return ((k, ROBOT_DIM + LANDMARK_DIM * k) for k in range(len(self._has_signature)))

    def _predict(self, odometry: Odometry) -> None:
        pose = self._mean[:ROBOT_DIM]
        if self.R is None:  # the "calibration": the first reading's covariance, then constant
            self.R = np.array(odometry.covariance, dtype=float)
        if self.motion_model == "forward-rotate":
            new_pose, G = predict_forward_rotate(pose, *paper_moves(odometry))
        else:
            increment = (odometry.dx_m, odometry.dy_m, odometry.dtheta_rad)
            G, _ = motion_jacobians(pose, increment)
            new_pose = predict_pose(pose, increment)
        if self.motion_noise == "constant":
            R = self.R
        else:
            _, F_u = motion_jacobians(pose, (odometry.dx_m, odometry.dy_m, odometry.dtheta_rad))
            R = F_u @ np.array(odometry.covariance, dtype=float) @ F_u.T
        predict_covariance(self._P, G, R)
        self._mean[:ROBOT_DIM] = new_pose

    def _sigmas(self, observation: Observation, with_signature: bool) -> list[float]:
        own = [observation.sigma_range_m, observation.sigma_bearing_rad, observation.sigma_height_m or 0.0]
        sigmas = own if self.q_sigmas is None else [o if q is None else q for q, o in zip(self.q_sigmas, own)]
        return sigmas if with_signature else sigmas[:2]

    def _observe(self, observation: Observation) -> int | None:
        with_signature = self.use_signature and observation.height_m is not None
        signature = float(observation.height_m) if with_signature else None
        Q = observation_noise(self._sigmas(observation, with_signature), diagonal=self.q_diagonal)
        pose = self._mean[:ROBOT_DIM]
        point = observation_world_point(pose, observation.range_m, observation.bearing_rad)
        blocks = self._mean[ROBOT_DIM:].reshape(-1, LANDMARK_DIM)
        has_signature = np.array(self._has_signature, dtype=bool)
        k, _ = nearest_landmark(point, signature, blocks[:, :2], blocks[:, 2], has_signature, self.gate_m)
        if k is None:
            return self._add_landmark(observation, signature, Q)
        self._update(k, observation, signature, Q)
        return -(k + 1)

    def _add_landmark(self, observation: Observation, signature: float | None, Q: np.ndarray) -> int:
        n = self._mean.shape[0]
        pose = self._mean[:ROBOT_DIM]
        G_pose2, G_z2 = landmark_init_jacobians(pose, observation.range_m, observation.bearing_rad)
        G_pose = np.vstack([G_pose2, np.zeros((1, ROBOT_DIM))])  # s does not depend on the pose
        P_lx = G_pose @ self._P[:ROBOT_DIM, :]  # 3×n cross-covariance
        P_ll = G_pose @ self._P[:ROBOT_DIM, :ROBOT_DIM] @ G_pose.T
        P_ll[:2, :2] += G_z2 @ Q[:2, :2] @ G_z2.T
        P_ll[2, 2] += Q[2, 2] if signature is not None else UNKNOWN_SIGNATURE_VARIANCE
        P = np.zeros((n + LANDMARK_DIM, n + LANDMARK_DIM))
        P[:n, :n] = self._P
        P[n:, :n] = P_lx
        P[:n, n:] = P_lx.T
        P[n:, n:] = P_ll
        xy = observation_world_point(pose, observation.range_m, observation.bearing_rad)
        self._mean = np.concatenate([self._mean, [xy[0], xy[1], signature if signature is not None else 0.0]])
        self._P = P
        self._has_signature.append(signature is not None)
        self.landmarks_added += 1
        return -len(self._has_signature)

    def _update(self, k: int, observation: Observation, signature: float | None, Q: np.ndarray) -> None:
        i = ROBOT_DIM + LANDMARK_DIM * k
        pose, landmark = self._mean[:ROBOT_DIM], self._mean[i : i + 2]
        with_signature = signature is not None
        H = observation_jacobian(pose, landmark, with_signature)
        z_hat = expected_observation(pose, landmark, self._mean[i + 2] if with_signature else None)
        z = [observation.range_m, observation.bearing_rad] + ([signature] if with_signature else [])
        innovation = np.asarray(z, dtype=float) - z_hat
        innovation[1] = wrap_angle(float(innovation[1]))
        cols = np.array([0, 1, 2, i, i + 1, i + 2])
        self._mean, self._P, _ = ekf_correct(self._mean, self._P, cols, H, innovation, Q)
        self._mean[2] = wrap_angle(float(self._mean[2]))
        if with_signature:
            self._has_signature[k] = True
        self.updates += 1
