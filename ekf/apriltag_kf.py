"""``ekf-s004``: seed 004's AprilTag Kalman-filter SLAM, reproduced as written.

Source: O. Jindal, *CSE 276A Intro to Robotics, Homework 3* (``shared/seeds/004_*.txt``),
section "Implementation of Kalman Filter" (the only technical section; it is short).

The paper's filter in one paragraph
    Two globals: the mean μ = [robot (x, y, θ), tag₁ (x, y, θ), …] and its covariance Σ,
    grown by a 3-vector and a 3×3 block per new tag. Each loop:

    * **Prediction** ``μ ← F μ + G u``, ``Σ ← F Σ Fᵀ + W`` with F = I, G = I·Δt and u the
      "3D velocity (x, y, yaw)" of the controller's ROS Twist — a *body-frame* velocity.
      W is "the co-variance matrix formed by random noise" (no value given).
    * **Update** on ``temp_mu``/``temp_sigma``, the rows and columns of the robot and the
      tags visible now: ``K = Σ Hᵀ (H Σ Hᵀ + V)⁻¹``, ``μ ← μ + K (z − H μ)``,
      ``Σ ← (I − K H) Σ``, written back into the globals "at the right places". z is each
      visible tag's pose "rotated (without translation)" into world axes "so that" H is a
      column of −I₃ blocks (robot) beside a big identity (tags), as in the paper's example.
      (Note the names: here W is the *process* noise and V the *measurement* noise, the
      reverse of seed 000.)

What is reproduced *as written* (the keyword that switches each one is in brackets; the
defaults are the paper):

* **Body velocity added to the world pose** (``rotate_input=False``): G = I·Δt adds
  (v_x, v_y, ω)·Δt straight onto (x, y, θ) with no rotation by θ — right only while the
  robot faces the world x axis. ``rotate_input=True`` rotates it by the current heading.
* **Heading treated as known in the observation**: z rotates the tag's position with the
  current heading estimate, and H = [−I₃ I₃] has no ∂/∂θ term for the rotated position.
* **Sub-state update** (``substate_update=True``): only the robot/visible-tag rows and
  columns of Σ are updated; the cross-covariances with tags not seen now are left as they
  were (a correct KF would update them and move the unseen tags through them).
  ``substate_update=False`` updates the full state with the same H padded with zeros.
* **Tag angle in z** (``tag_angle``): "rotating (without translation)" a relative tag
  pose leaves its relative yaw φ unchanged, which is what H's θ row (θ_tag − θ_robot)
  expects — ``"relative"`` (default). Rotating it as an SE(2) pose would give θ + φ, the
  tag's world yaw, which H does not predict — ``"world"`` shows that reading's cost.

Where the paper is silent (our choice, documented):

* **Velocity input**: derived from each odometry increment and its stamp difference,
  u = (dx, dy, dθ)/Δt, so G u = Δt·u is the increment itself (Δt cancels); a step with
  Δt ≤ 0 uses the increment directly (counted in ``zero_dt_steps``).
* **W** (``process_cov=None``): the log's odometry covariance, unrotated (the paper's
  model has no frame for the input); rotated by θ when ``rotate_input=True``. Only the
  robot block gets it (tags are static and G selects the robot).
* **V** (``observation_cov=None``): from the observation's sigmas — range/bearing
  propagated to the robot-frame position, rotated into world axes with the heading used
  for z, and σ_tag_yaw² for the angle.
* **New tags** (``new_tag_cov=None``): appended after the update with
  μ_tag = μ_robot + z and the observation's V block, no cross-covariance.
* **Angle wrapping** (``wrap_innovation=True``): the θ innovations are wrapped (the
  relative tag yaw is near ±π for a tag facing the robot, so without it the filter
  breaks at once); the state angles themselves are never wrapped (outputs are).

Frames: the paper is ROS, so the world frame, the robot frame (x forward, y left) and the
counter-clockwise yaw are the log's own; no conversion is needed at the edges. Tag
observations without ``tag_yaw_rad`` and observations without a landmark id are ignored.
"""

from __future__ import annotations

import math

import numpy as np

from ekf.filter_outputs import FilterOutputs
from slamio.geometry import wrap_angle
from slamio.log import Header, Observation, Step

__all__ = [
    "EkfS004",
    "body_velocity",
    "predict_robot",
    "rotation",
    "tag_pose_in_robot",
    "observation_vector",
    "observation_covariance_from_log",
    "measurement_matrix",
    "kalman_update",
]

POSE_DIM = 3  # x_m, y_m, theta_rad for the robot and for every tag
TAG_ANGLES = ("relative", "world")


# --------------------------------------------------------------------------- models


def rotation(theta_rad: float) -> np.ndarray:
    """2×2 counter-clockwise rotation by ``theta_rad`` (robot axes → world axes)."""
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    return np.array([[c, -s], [s, c]])


def body_velocity(increment, dt_s: float) -> np.ndarray:
    """The Twist the paper's input u would be: body-frame (v_x, v_y, ω) = increment / Δt.

    ``increment`` is the log's (dx_m, dy_m, dtheta_rad) in the previous robot frame.
    Raises ``ValueError`` for Δt ≤ 0 (no velocity can be formed).
    """
    if not dt_s > 0.0:
        raise ValueError(f"the stamp difference must be > 0 to form a velocity, got {dt_s!r} s")
    return np.asarray(increment, dtype=float) / dt_s


def predict_robot(robot_pose, velocity, dt_s: float, *, rotate_input: bool = False) -> np.ndarray:
    """Prediction of the robot block: ``μ_r + G u`` with G = I·Δt.

    As written (``rotate_input=False``) the body-frame velocity is added to the world
    pose unrotated; ``rotate_input=True`` first rotates (v_x, v_y) by the current θ.
    """
    step = dt_s * np.asarray(velocity, dtype=float)
    if rotate_input:
        step[:2] = rotation(float(robot_pose[2])) @ step[:2]
    return np.asarray(robot_pose, dtype=float) + step


def tag_pose_in_robot(observation: Observation) -> np.ndarray:
    """The tag's pose in the robot frame, (x_m, y_m, yaw_rad), from range/bearing/tag_yaw."""
    r, b = observation.range_m, observation.bearing_rad
    return np.array([r * math.cos(b), r * math.sin(b), float(observation.tag_yaw_rad)])


def observation_vector(tag_in_robot, heading_rad: float, *, tag_angle: str = "relative") -> np.ndarray:
    """z: the tag pose "rotated (without translation)" into world axes with the heading θ.

    ``(R(θ)·(x, y), φ)`` — the relative yaw φ is unchanged by a rotation of axes — for
    ``tag_angle="relative"``; ``(R(θ)·(x, y), θ + φ)`` (the pose rotated as an SE(2)
    element, i.e. the tag's world yaw) for ``"world"``.
    """
    p = np.asarray(tag_in_robot, dtype=float)
    xy = rotation(heading_rad) @ p[:2]
    if tag_angle == "relative":
        return np.array([xy[0], xy[1], p[2]])
    if tag_angle == "world":
        return np.array([xy[0], xy[1], heading_rad + p[2]])
    raise ValueError(f"tag_angle must be one of {TAG_ANGLES}, got {tag_angle!r}")


def observation_covariance_from_log(observation: Observation, heading_rad: float) -> np.ndarray:
    """V block of one tag (3×3, world axes) from the observation's own sigmas.

    Position: ``A diag(σ_r², σ_b²) Aᵀ`` with A = R(θ)·∂(r cos b, r sin b)/∂(r, b);
    angle: σ_tag_yaw² (uncorrelated).
    """
    r, b = observation.range_m, observation.bearing_rad
    J = np.array([[math.cos(b), -r * math.sin(b)], [math.sin(b), r * math.cos(b)]])
    A = rotation(heading_rad) @ J
    V = np.zeros((3, 3))
    V[:2, :2] = A @ np.diag([observation.sigma_range_m**2, observation.sigma_bearing_rad**2]) @ A.T
    V[2, 2] = float(observation.sigma_tag_yaw_rad) ** 2
    return V


def measurement_matrix(n_tags: int) -> np.ndarray:
    """The paper's H for ``n_tags`` visible tags: 3n × 3(n+1), ``[−I₃ stacked | I₃ₙ]``.

    For two tags this is exactly the array printed in the paper.
    """
    H = np.zeros((POSE_DIM * n_tags, POSE_DIM * (n_tags + 1)))
    for k in range(n_tags):
        r = POSE_DIM * k
        H[r : r + 3, 0:3] = -np.eye(3)
        H[r : r + 3, r + 3 : r + 6] = np.eye(3)
    return H


def kalman_update(mu, Sigma, z, H, V, *, wrap_rows=()):
    """One linear KF update, the paper's three equations; returns new ``(μ, Σ)``.

    ``K = Σ Hᵀ (H Σ Hᵀ + V)⁻¹``, ``μ + K (z − H μ)``, ``(I − K H) Σ``. The innovation rows in
    ``wrap_rows`` (the angle rows) are wrapped into [−π, π).
    """
    innovation = np.asarray(z, dtype=float) - H @ mu
    rows = list(wrap_rows)
    if rows:
        innovation[rows] = wrap_angle(innovation[rows])
    S = H @ Sigma @ H.T + V
    K = np.linalg.solve(S.T, (Sigma @ H.T).T).T
    return mu + K @ innovation, (np.eye(len(mu)) - K @ H) @ Sigma


def _matrix3(value, name: str) -> np.ndarray | None:
    if value is None:
        return None
    m = np.asarray(value, dtype=float)
    if m.shape != (3, 3):
        raise ValueError(f"{name} must be a 3×3 matrix (or None for the log's own noise), got shape {m.shape}")
    return m


# --------------------------------------------------------------------------- the filter


class EkfS004(FilterOutputs):
    """Seed 004's AprilTag KF SLAM (implements ``slamio.estimator.AssociatingEstimator``).

    Built ``EkfS004(header)``: the robot starts at ``header.start_pose`` with covariance
    ``diag(header.start_sigma²)``. Keywords (defaults = the paper, see the module
    docstring): ``rotate_input`` (False), ``tag_angle`` ("relative"), ``substate_update``
    (True), ``wrap_innovation`` (True), and the noise choices ``process_cov``,
    ``observation_cov``, ``new_tag_cov`` (None = from the log; or a fixed 3×3 matrix).

    Counters: ``updates``, ``tags_added``, ``zero_dt_steps``.
    """

    name = "ekf-s004"

    def __init__(
        self,
        header: Header,
        *,
        rotate_input: bool = False,
        tag_angle: str = "relative",
        substate_update: bool = True,
        wrap_innovation: bool = True,
        process_cov=None,
        observation_cov=None,
        new_tag_cov=None,
    ):
        if tag_angle not in TAG_ANGLES:
            raise ValueError(f"tag_angle must be one of {TAG_ANGLES}, got {tag_angle!r}")
        self.rotate_input = bool(rotate_input)
        self.tag_angle = tag_angle
        self.substate_update = bool(substate_update)
        self.wrap_innovation = bool(wrap_innovation)
        self._process_cov = _matrix3(process_cov, "process_cov")
        self._observation_cov = _matrix3(observation_cov, "observation_cov")
        self._new_tag_cov = _matrix3(new_tag_cov, "new_tag_cov")

        self._mu = np.array(header.start_pose, dtype=float)
        self._Sigma = np.diag(np.square(np.asarray(header.start_sigma, dtype=float)))
        self._slot: dict[int, int] = {}  # tag id → slot (0, 1, …); its x is at 3 + 3·slot
        self._last_stamp_s = float(header.stamp_s)
        self._trajectory: list[tuple[float, float, float]] = []
        self._associations: list[int | None] = []
        self.updates = 0
        self.tags_added = 0
        self.zero_dt_steps = 0

    # ------------------------------------------------------------------ protocol

    def step(self, step: Step) -> None:
        """Predict with the odometry (if any), update with the visible known tags, then
        append the tags seen for the first time."""
        used: dict[int, Observation] = {}
        self._associations = []
        for observation in step.observations:
            lid = observation.landmark_id
            if lid is None or observation.tag_yaw_rad is None or lid in used:
                self._associations.append(None)
            else:
                used[lid] = observation
                self._associations.append(lid)
        if step.odometry is not None:
            self._predict(step)
        self._last_stamp_s = float(step.stamp_s)
        visible = {lid: obs for lid, obs in used.items() if lid in self._slot}
        if visible:
            self._update(visible)
        for lid, observation in used.items():
            if lid not in self._slot:
                self._add_tag(lid, observation)
        self._trajectory.append(self.current_pose())

    def step_associations(self) -> list[int | None]:
        """For each observation of the last step: its tag id, or None if ignored."""
        return list(self._associations)

    def current_pose(self) -> tuple[float, float, float]:
        """Current robot pose ``(x_m, y_m, theta_rad)``, heading wrapped into [−π, π)."""
        x, y, th = self._mu[:POSE_DIM]
        return float(x), float(y), float(wrap_angle(float(th)))

    def current_covariance(self) -> np.ndarray:
        """3×3 covariance of the current robot pose (world x, y, θ counter-clockwise)."""
        return self._Sigma[:POSE_DIM, :POSE_DIM].copy()

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Tag id → estimated ``(x_m, y_m)`` in the world frame."""
        return {lid: (x, y) for lid, (x, y, _) in self.tag_poses().items()}

    def tag_poses(self) -> dict[int, tuple[float, float, float]]:
        """Tag id → estimated ``(x_m, y_m, yaw_rad)`` (yaw wrapped)."""
        out = {}
        for lid, slot in self._slot.items():
            i = POSE_DIM * (slot + 1)
            x, y, th = self._mu[i : i + 3]
            out[lid] = (float(x), float(y), float(wrap_angle(float(th))))
        return out

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the full mean μ and covariance Σ (angles unwrapped, as the filter keeps them)."""
        return self._mu.copy(), self._Sigma.copy()

    # ------------------------------------------------------------------ the steps

    def _predict(self, step: Step) -> None:
        odometry = step.odometry
        increment = np.array([odometry.dx_m, odometry.dy_m, odometry.dtheta_rad])
        dt = float(step.stamp_s) - self._last_stamp_s
        if dt > 0.0:
            velocity = body_velocity(increment, dt)
        else:  # no velocity can be formed; G u is then taken to be the increment itself
            self.zero_dt_steps += 1
            velocity, dt = increment, 1.0
        robot = self._mu[:POSE_DIM]
        W = self._process_cov if self._process_cov is not None else np.asarray(odometry.covariance, dtype=float)
        if self.rotate_input:
            A = np.eye(3)
            A[:2, :2] = rotation(float(robot[2]))
            W = A @ W @ A.T
        self._mu[:POSE_DIM] = predict_robot(robot, velocity, dt, rotate_input=self.rotate_input)
        self._Sigma[:POSE_DIM, :POSE_DIM] += W  # F Σ Fᵀ + W, F = I, W on the robot only

    def _tag_cov(self, observation: Observation, heading: float) -> np.ndarray:
        if self._observation_cov is not None:
            return self._observation_cov
        return observation_covariance_from_log(observation, heading)

    def _update(self, visible: dict[int, Observation]) -> None:
        heading = float(self._mu[2])
        ids = list(visible)
        n_tags = len(ids)
        z = np.concatenate(
            [observation_vector(tag_pose_in_robot(visible[i]), heading, tag_angle=self.tag_angle) for i in ids]
        )
        V = np.zeros((3 * n_tags, 3 * n_tags))
        for k, lid in enumerate(ids):
            V[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = self._tag_cov(visible[lid], heading)
        wrap_rows = [3 * k + 2 for k in range(n_tags)] if self.wrap_innovation else []
        H_temp = measurement_matrix(n_tags)
        idx = np.concatenate([np.arange(3)] + [np.arange(3) + 3 * (self._slot[i] + 1) for i in ids])
        if self.substate_update:  # temp_mu / temp_sigma, written back at the right places
            mu, Sigma = kalman_update(
                self._mu[idx], self._Sigma[np.ix_(idx, idx)], z, H_temp, V, wrap_rows=wrap_rows
            )
            self._mu[idx] = mu
            self._Sigma[np.ix_(idx, idx)] = Sigma
        else:
            H = np.zeros((3 * n_tags, self._mu.shape[0]))
            H[:, idx] = H_temp
            self._mu, self._Sigma = kalman_update(self._mu, self._Sigma, z, H, V, wrap_rows=wrap_rows)
        self.updates += 1

    def _add_tag(self, lid: int, observation: Observation) -> None:
        robot = self._mu[:POSE_DIM]
        heading = float(robot[2])
        z = observation_vector(tag_pose_in_robot(observation), heading, tag_angle=self.tag_angle)
        tag = robot + z  # H μ = tag − robot = z
        cov = self._new_tag_cov if self._new_tag_cov is not None else self._tag_cov(observation, heading)
        n = self._mu.shape[0]
        self._mu = np.concatenate([self._mu, tag])
        Sigma = np.zeros((n + 3, n + 3))
        Sigma[:n, :n] = self._Sigma
        Sigma[n:, n:] = cov
        self._Sigma = Sigma
        self._slot[lid] = len(self._slot)
        self.tags_added += 1
