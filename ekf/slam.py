"""Textbook range-bearing EKF-SLAM (Thrun et al., *Probabilistic Robotics*, ch. 10) with
data association for landmarks without ids and optional landmark heights, written so that
every step costs O(n) or O(n²) in the state size n.

State layout
    ``mean = [x, y, θ, l1x, l1y, (l1h,) l2x, l2y, ...]`` — the robot pose first, then one
    block per landmark in the order the landmarks were first seen: (x, y), or (x, y, h) for
    a landmark first seen by an observation with a height (seed 002). ``P`` is the full
    joint covariance. Both live in buffers that grow by doubling their capacity, so adding
    thousands of landmarks copies the n×n matrix only O(log n) times. The covariance
    buffer is Fortran-ordered so that the one O(n²) pass of an update is a single in-place
    BLAS call (see :func:`ekf.covariance.add_low_rank_in_place`).

One step (:meth:`EkfSlam.step`)
    1. Predict with the odometry increment u (SE(2), previous robot frame) and its 3×3
       covariance Σ: ``pose ← pose ⊕ u``, ``Q = F_u Σ F_uᵀ``. Only the robot rows and
       columns of P change: ``P_rr ← F P_rr Fᵀ + Q`` and ``P_rm ← F P_rm`` — O(n).
    2. For every observation with a known ``landmark_id``, in log order:
       * first sighting → *augment* the state with the landmark placed by the inverse
         observation model, with its full cross-covariance to the robot and to every other
         landmark (``P_ll = G_p P_rr G_pᵀ + G_z R G_zᵀ``, ``P_lx = G_p P_rx``). The
         measurement is then fully used: it is not applied a second time as an update;
       * later sightings → one sequential EKF update with the bearing innovation wrapped,
         the Joseph-form covariance update in O(n²) (see :func:`ekf.covariance.joseph_factors`) and the
         heading wrapped.
    3. The observations with ``landmark_id is None`` form one association problem against
       the current map (χ² gate, then gated nearest neighbour or JCBB, see
       :mod:`ekf.association`): paired ones update as in 2, those outside every gate
       become new landmarks keyed −1, −2, …, and the rest are rejected and counted.
       With ``association=None`` they are skipped and counted instead.

Range-only observations (no bearing: ranging radios, Plaza)
    A landmark in the state gets a scalar update with ``H = [−e/r, 0 | e/r]``. A landmark
    not yet in it waits: its ranges are buffered with the robot position estimated at each,
    until :func:`ekf.range_only.try_initialise` (enough ranges, a small and unambiguous
    trilateration) places it; it then enters with the trilateration's covariance plus the
    robot's position covariance and no cross-covariance (an approximation, see
    :meth:`EkfSlam._buffer_range`).

Observation model with a height
    ``z = (range, bearing, height)``, ``height = h + n_h``: a direct measurement of the
    landmark's h, so ``H`` has one more row ``[0 0 0 | 0 0 1]`` and up to 6 non-zero
    columns (pose, x, y, h); R = diag(σ_r², σ_b², σ_h²). A new landmark's h is the measured
    height with variance σ_h² and no cross-covariance, and nothing ever correlates it with
    the rest of the state, so each height is an exact scalar Kalman filter: its estimate is
    the information-weighted mean of the heights measured and its variance
    ``1 / Σ 1/σ_h,k²``. An observation with a height of a landmark without one (or the
    reverse) uses range and bearing only.

The filter's arithmetic is in small pure functions, each testable on its own:
:mod:`ekf.covariance` (prediction, augmentation, gain, the O(n²) Joseph update),
:mod:`ekf.observation` (R, the model and its Jacobians with a height, the inverse model,
NIS), :mod:`ekf.map_association` (the association problem from the state) and
:mod:`ekf.association` (gates, nearest neighbour, JCBB). :class:`EkfSlam` holds the state
and the bookkeeping; three mixins hold the rest of its methods, by responsibility:
:class:`ekf.map_association.MapAssociation` (a step's id-less observations against the map),
:class:`ekf.range_updates.RangeOnlyUpdates` (range-only readings, delayed initialisation) and
:class:`ekf.reading_error_states.ReadingErrorStates` (correlated reading errors as states).
"""

from __future__ import annotations

import numpy as np

from ekf.association import DEFAULT_AMBIGUITY_MARGIN, DEFAULT_GATE_PROBABILITY, DEFAULT_MAX_NODES, chi2_gate
from ekf.covariance import add_low_rank_in_place, augment_covariance, joseph_factors, kalman_gain, predict_covariance
from ekf.filter_outputs import FilterOutputs
from ekf.map_association import MapAssociation
from ekf.models import (
    LANDMARK_DIM,
    ROBOT_DIM,
    motion_jacobians,
    predict_pose,
    range_bearing,
    range_bearing_jacobians,
)
from ekf.observation import (
    has_height,
    landmark_from_observation,
    landmark_from_observation_jacobians,
    measurement_covariance,
    observation_jacobians,
    observation_model,
    observation_nis,
)
from ekf.range_only import DelayedInitRule
from ekf.range_updates import RangeOnlyUpdates
from ekf.reading_error import reading_error_model
from ekf.reading_error_states import ReadingErrorStates
from slamio.geometry import wrap_angle
from slamio.log import Header, Observation, Step
from slamio.noise.model import log_expects_outliers

__all__ = [
    "EkfSlam",
    "ASSOCIATION_METHODS",
    "DEFAULT_NEW_LANDMARK_PROBABILITY",
]


# --------------------------------------------------------------------------- the filter

ASSOCIATION_METHODS = ("jcbb", "nn", None)
_NAMES = {"jcbb": "ekf", "nn": "ekf-nn", None: "ekf-ids"}

#: An unpaired observation creates a new landmark only when it lies outside this larger
#: gate of *every* landmark (χ²_dof at this probability; 27.6 for dof 2); between the
#: association gate and this one it is rejected. See the class docstring.
DEFAULT_NEW_LANDMARK_PROBABILITY = 0.999999
#: Validation gate on observations *with* an id (χ²_dof at this probability; 18.4 for
#: dof 2). A consistent filter rejects one good observation in 10⁴; a misread id or a
#: reflection far outside its predicted place is rejected instead of pulling the whole
#: state (MRCLAM's misread barcodes: docs/datasets-mrclam-rosbag.md). None: no gate.
DEFAULT_KNOWN_ID_GATE_PROBABILITY = 0.9999



class EkfSlam(MapAssociation, RangeOnlyUpdates, ReadingErrorStates, FilterOutputs):
    """Range-bearing EKF-SLAM with known or associated landmark ids
    (implements ``slamio.estimator.AssociatingEstimator``).

    Built from the log header: the start mean is ``header.start_pose`` and the start
    covariance ``diag(header.start_sigma²)``. Feed it every :class:`~slamio.log.Step` in
    order with :meth:`step`; read the estimate with the accessors.

    ``association`` decides what happens to observations without a ``landmark_id``:
    ``"jcbb"`` (default, ``name`` "ekf") or ``"nn"`` (``name`` "ekf-nn") associate them, all
    those of one step together, against the current map (see :mod:`ekf.association`);
    ``None`` ignores them (``name`` "ekf-ids", the plain known-ids filter; they are counted
    in ``skipped_unknown_id``). Observations with an id are always used as that landmark,
    before the id-less ones of the same step.

    Gates, with ``d²`` the squared Mahalanobis distance of an observation to a landmark
    (``H P Hᵀ + R``, bearing wrapped) and ``dof`` the measurement size (2, or 3 with a
    height):

    * ``gate_probability`` p (default 0.999): NN pairs an observation only inside
      ``χ²_dof(p)``; JCBB accepts a hypothesis only if its joint D² is inside
      ``χ²_{Σdof}(p)``;
    * ``new_landmark_probability`` p_new (default 1 − 10⁻⁶, ``χ²_2`` = 27.6): an unpaired
      observation creates a new landmark only when ``d² > χ²_dof(p_new)`` for *every*
      landmark — the extra margin beyond the gate. Between the two gates it is rejected.
      Without the margin, the 1 − p of true re-observations that fall just outside the
      gate would each create a duplicate landmark, and later observations split between the
      two copies (measured with p = p_new = 0.99: 13 landmarks for the 8 arena tags, 90 %
      correct). JCBB takes its candidate pairs from this wider gate as well (the joint test
      decides).

    After JCBB (:func:`ekf.association.settle_pairing`): a landmark another observation of
    the step is paired with is no candidate for the others (one frame sees a landmark once),
    and a pair whose landmark is not at least ``exp(ambiguity_margin / 2)`` = 100 times as
    likely as some other landmark the step leaves free is dropped (None: kept), the
    observation rejected.

    For the associated observations of a step:

    * paired (by NN or by JCBB's best hypothesis) → an EKF update of that landmark;
    * unpaired and outside the new-landmark gate of every landmark → a new landmark, keyed
      −1, −2, … in order of creation;
    * otherwise → rejected, counted in ``rejected_observations``: it lost to another
      observation (NN's conflict rule, JCBB's hypothesis), lies between the gates, or its
      pair was ambiguous.

    Paired observations update in log order, then new landmarks are added (from the
    updated pose), in log order. :meth:`step_associations` says what each observation of
    the last step was used as.

    Landmark heights: a landmark first seen by an observation with a height is (x, y, h)
    and later observations with a height also measure h directly (``h_obs = h + n``,
    ``n ~ N(0, σ_h²)``), jointly with range and bearing, in the update and in the gates;
    others stay (x, y). :meth:`landmark_heights` returns the heights.

    Counters: ``updates`` (EKF updates applied), ``landmarks_added`` (state augmentations,
    known ids and new keys), ``landmarks_created`` (new keys from id-less observations),
    ``skipped_unknown_id`` (id-less observations ignored, ``association=None``),
    ``rejected_observations``, ``jcbb_nodes_max`` (largest JCBB search) and
    ``jcbb_truncated`` (steps where the JCBB node cap ``max_jcbb_nodes`` was hit).
    ``joint_test`` is passed to :func:`ekf.association.jcbb` ("final", or the paper's
    "prefix").

    Observations with an id pass a validation gate when the log expects outliers
    (:func:`log_expects_outliers`; ``known_id_gate_probability="auto"``, the default): an
    update whose innovation's ``d²`` exceeds ``χ²_dof(0.9999)`` is not applied and is counted
    in ``gated_known_id``. A number sets the gate's probability for any log; ``None`` turns
    it off, the plain textbook filter that trusts every id. Where the log does not expect
    outliers the gate would only cost: once a filter is off (Victoria Park's EKF), a gate
    refuses the very readings that could bring it back (there it refused 2 577 of 3 489
    re-observations and ended 192 m off instead of 15 m).

    Readings whose errors are correlated in time: when the header's noise model has a
    ``correlated_share`` ρ > 0 (``fgslam calibrate`` fits it), each range-bearing landmark
    carries its readings' Gauss–Markov error (range, bearing) as two more states after its
    position, and each reading's white part is ``(1 − ρ)·R`` (:mod:`ekf.reading_error`).
    Association (NN, JCBB) still scores pairs with the whole R and without those states, a
    slightly wider gate; the update of an associated reading uses them.

    ``landmark_capacity`` is only the initial room for landmarks; the storage doubles
    whenever it is full, so it never limits the map.
    """

    name = "ekf"

    def __init__(
        self,
        header: Header,
        *,
        association: str | None = "jcbb",
        gate_probability: float = DEFAULT_GATE_PROBABILITY,
        new_landmark_probability: float | None = None,
        max_jcbb_nodes: int = DEFAULT_MAX_NODES,
        joint_test: str = "final",
        ambiguity_margin: float | None = DEFAULT_AMBIGUITY_MARGIN,
        landmark_capacity: int = 16,
        known_id_gate_probability: float | str | None = "auto",
    ):
        if association not in ASSOCIATION_METHODS:
            raise ValueError(f"association must be one of {ASSOCIATION_METHODS}, got {association!r}")
        if joint_test not in ("final", "prefix"):
            raise ValueError(f"joint_test must be 'final' or 'prefix', got {joint_test!r}")
        if new_landmark_probability is None:
            new_landmark_probability = max(DEFAULT_NEW_LANDMARK_PROBABILITY, gate_probability)
        if not 0.0 < gate_probability <= new_landmark_probability < 1.0:
            raise ValueError(
                "need 0 < gate_probability ≤ new_landmark_probability < 1, got "
                f"{gate_probability!r} and {new_landmark_probability!r}"
            )
        if known_id_gate_probability == "auto":
            known_id_gate_probability = DEFAULT_KNOWN_ID_GATE_PROBABILITY if log_expects_outliers(header) else None
        if known_id_gate_probability is not None and not 0.0 < known_id_gate_probability < 1.0:
            raise ValueError(
                f"known_id_gate_probability must be in (0, 1), None or 'auto', got {known_id_gate_probability!r}"
            )
        self.known_id_gate_probability = known_id_gate_probability
        self.gated_known_id = 0
        self.association = association
        self.name = _NAMES[association]
        self.gate_probability = float(gate_probability)
        self.new_landmark_probability = float(new_landmark_probability)
        self.max_jcbb_nodes = int(max_jcbb_nodes)
        self.joint_test = joint_test
        self.ambiguity_margin = ambiguity_margin
        capacity = ROBOT_DIM + LANDMARK_DIM * max(1, int(landmark_capacity))
        self._mean = np.zeros(capacity)
        self._cov = np.zeros((capacity, capacity), order="F")  # see add_low_rank_in_place
        self._dim = ROBOT_DIM
        self._mean[:ROBOT_DIM] = header.start_pose
        self._mean[2] = wrap_angle(float(self._mean[2]))
        self._cov[:ROBOT_DIM, :ROBOT_DIM] = np.diag(np.square(header.start_sigma))
        self._slot: dict[int, int] = {}  # landmark key → index of its x in the state
        self._has_height: dict[int, bool] = {}  # landmark key → state is (x, y, h)
        self._keys: list[int] = []  # in order of creation, for the vectorised association
        self._x_index: list[int] = []
        self._h_index: list[int] = []  # −1 for a landmark without height
        self._next_key = -1
        self._trajectory: list[tuple[float, float, float]] = []
        self._associations: list[int | None] = []
        self.updates = 0
        self.landmarks_added = 0
        self.landmarks_created = 0
        self.skipped_unknown_id = 0
        self.rejected_observations = 0
        self.jcbb_nodes_max = 0
        self.jcbb_truncated = 0
        # range-only landmarks waiting for delayed initialisation (see ekf.range_only)
        self.range_rule = DelayedInitRule()
        self._range_buffer: dict[int, list[tuple[float, float, float, float]]] = {}  # id → (x, y, r, σ)
        self.range_updates = 0
        self.range_landmarks_initialised = 0
        # readings' Gauss–Markov errors (see ekf.reading_error): key → index, time, σ at that time
        self.reading_error = reading_error_model(header.noise)
        self._error_index: dict[int, int] = {}
        self._error_time: dict[int, float] = {}
        self._error_sigma: dict[int, np.ndarray] = {}
        self._time = float(header.stamp_s)

    # ------------------------------------------------------------------ protocol

    def step(self, step: Step) -> None:
        """Predict with ``step.odometry`` (if any), apply each observation with an id in
        turn, then associate and apply the observations without one (see the class docstring)."""
        if step.odometry is not None:
            self._predict(step.odometry)
        self._time = step.stamp_s
        associations: list[int | None] = [None] * len(step.observations)
        unknown: list[int] = []
        for k, observation in enumerate(step.observations):
            if observation.range_only:
                if observation.landmark_id is None:  # a range alone cannot be associated
                    self.skipped_unknown_id += 1
                elif observation.landmark_id in self._slot:
                    self._update_range(observation.landmark_id, observation)
                    associations[k] = observation.landmark_id
                elif self._buffer_range(observation.landmark_id, observation):
                    associations[k] = observation.landmark_id
            elif observation.landmark_id is None:
                if self.association is None:
                    self.skipped_unknown_id += 1
                else:
                    unknown.append(k)
            elif observation.landmark_id in self._slot:
                if self._update(observation.landmark_id, observation, gate=True):
                    associations[k] = observation.landmark_id
            else:
                self._add_landmark(observation.landmark_id, observation)
                associations[k] = observation.landmark_id
        if unknown:
            keys = self._associate_and_apply([step.observations[k] for k in unknown])
            for k, key in zip(unknown, keys):
                associations[k] = key
        self._associations = associations
        self._trajectory.append(self.current_pose())

    def step_associations(self) -> list[int | None]:
        """For each observation of the last step: the landmark key it was used as (its id,
        an associated key, or the key of the landmark it created), or None (rejected, or
        ignored with ``association=None``)."""
        return list(self._associations)

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Landmark key → estimated ``(x_m, y_m)``, in the order the landmarks were first seen."""
        return {lid: (float(self._mean[i]), float(self._mean[i + 1])) for lid, i in self._slot.items()}

    # ------------------------------------------------------------------ more accessors

    def landmark_heights(self) -> dict[int, float]:
        """Landmark key → estimated height ``h_m``, for the landmarks that have one."""
        return {k: float(self._mean[i + 2]) for k, i in self._slot.items() if self._has_height[k]}

    def current_covariance(self) -> np.ndarray:
        """3×3 covariance of the current robot pose (a copy)."""
        return self._cov[:ROBOT_DIM, :ROBOT_DIM].copy()

    def landmark_covariance(self, landmark_id: int) -> np.ndarray:
        """Covariance of one landmark (a copy): 2×2 over (x, y), or 3×3 over (x, y, h) for a
        landmark with a height. Raises ``KeyError`` for an unknown key."""
        i = self._slot[landmark_id]
        k = self._landmark_dim(landmark_id)
        return self._cov[i : i + k, i : i + k].copy()

    def landmark_covariances(self) -> dict[int, np.ndarray]:
        """Landmark key → 2×2 covariance of its (x, y) (copies; for the report's ellipses)."""
        return {k: self._cov[i : i + 2, i : i + 2].copy() for k, i in self._slot.items()}

    def predicted_nis(self, step: Step) -> list[float | None]:
        """NIS of each observation of ``step`` against the filter's prediction, before the
        step is applied (nothing is changed).

        The pose is predicted with ``step.odometry`` (its covariance blocks with it:
        ``P_rr ← F P_rr Fᵀ + Q``, ``P_rl ← F P_rl``); each observation of a landmark already
        in the map then gets :func:`ekf.models.range_bearing_nis` over (range, bearing)
        with the joint pose-landmark covariance (a range-only reading
        :func:`ekf.models.range_nis`, 1 degree of freedom). Every estimator answers this question the
        same way, so their NIS compare. None for an observation without an id or of a
        landmark not in the map yet.
        """
        pose = self._mean[:ROBOT_DIM].copy()
        P_rr = self._cov[:ROBOT_DIM, :ROBOT_DIM].copy()
        F = np.eye(ROBOT_DIM)
        if step.odometry is not None:
            odo = step.odometry
            increment = (odo.dx_m, odo.dy_m, odo.dtheta_rad)
            F, F_increment = motion_jacobians(pose, increment)
            P_rr = F @ P_rr @ F.T + F_increment @ np.asarray(odo.covariance, dtype=float) @ F_increment.T
            pose = predict_pose(pose, increment)
        out: list[float | None] = []
        for observation in step.observations:
            i = self._slot.get(observation.landmark_id) if observation.landmark_id is not None else None
            if i is None:
                out.append(None)
                continue
            if observation.landmark_id in self._error_index:
                out.append(self._nis_with_reading_error(pose, P_rr, F, observation))
                continue
            joint = np.empty((5, 5))
            joint[:3, :3] = P_rr
            joint[:3, 3:] = F @ self._cov[:ROBOT_DIM, i : i + 2]
            joint[3:, :3] = joint[:3, 3:].T
            joint[3:, 3:] = self._cov[i : i + 2, i : i + 2]
            out.append(observation_nis(pose, self._mean[i : i + 2], joint, observation))
        return out

    def state_mean(self) -> np.ndarray:
        """The full state vector ``[x, y, θ, l1x, l1y, (l1h,) (l1 range error, l1 bearing error,) ...]``
        (a copy; the reading errors only with a ``correlated_share`` in the header's noise,
        carried to the last step's time)."""
        if not self._error_index:
            return self._mean[: self._dim].copy()
        scale, _ = self._errors_to_now()
        return self._mean[: self._dim] * scale

    def state_covariance(self) -> np.ndarray:
        """The full n×n joint covariance (a copy; O(n²); reading errors as in :meth:`state_mean`)."""
        if not self._error_index:
            return self._cov[: self._dim, : self._dim].copy()
        scale, added = self._errors_to_now()
        return self._cov[: self._dim, : self._dim] * np.outer(scale, scale) + np.diag(added)

    def landmark_index(self, landmark_id: int) -> int:
        """Index of the landmark's x coordinate in :meth:`state_mean` (y, then h if any, follow it)."""
        return self._slot[landmark_id]

    @property
    def capacity(self) -> int:
        """Allocated state size; grows by doubling (always ≥ the state size)."""
        return self._mean.shape[0]

    # ------------------------------------------------------------------ the three operations

    def _predict(self, odometry) -> None:
        increment = (odometry.dx_m, odometry.dy_m, odometry.dtheta_rad)
        pose = self._mean[:ROBOT_DIM]
        F_pose, F_increment = motion_jacobians(pose, increment)
        Q = F_increment @ np.asarray(odometry.covariance, dtype=float) @ F_increment.T
        predicted = predict_pose(pose, increment)
        self._mean[:ROBOT_DIM] = predicted
        predict_covariance(self._cov[: self._dim, : self._dim], self._propagation_jacobian(F_pose, predicted), Q)

    def _landmark_dim(self, key: int) -> int:
        return 3 if self._has_height[key] else LANDMARK_DIM

    def _propagation_jacobian(self, F_pose: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """The pose Jacobian the covariance is propagated with: ``F_pose``, taken at the latest
        estimate (the textbook EKF). :class:`ekf.fej.FejEkfSlam` takes it at the predicted
        positions instead (``predicted`` is the pose just predicted)."""
        return F_pose

    def _linearisation_point(self, key: int, pose: np.ndarray, landmark: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where an update's measurement Jacobian is taken: at the current estimate (the
        textbook EKF). :class:`ekf.fej.FejEkfSlam` takes it at first estimates instead."""
        return pose, landmark

    def _add_landmark(self, key: int, observation: Observation) -> None:
        n = self._dim
        with_height = has_height(observation)
        k = 3 if with_height else LANDMARK_DIM
        self._reserve(n + k + (2 if self.reading_error is not None else 0))
        pose = self._mean[:ROBOT_DIM]
        R = measurement_covariance(observation, with_height)
        self._mean[n : n + k] = landmark_from_observation(
            pose, observation.range_m, observation.bearing_rad, observation.height_m if with_height else None
        )
        G_pose, G_measurement = landmark_from_observation_jacobians(
            pose, observation.range_m, observation.bearing_rad, with_height
        )
        augment_covariance(self._cov, n, G_pose, G_measurement, R)
        self._register_landmark(key, n, with_height)
        if self.reading_error is not None:
            self._add_reading_error(key, observation, G_measurement)

    def _register_landmark(self, key: int, n: int, with_height: bool) -> None:
        """Book a landmark just placed at state index ``n`` (its mean and covariance are set)."""
        self._slot[key] = n
        self._has_height[key] = with_height
        self._keys.append(key)
        self._x_index.append(n)
        self._h_index.append(n + 2 if with_height else -1)
        self._dim = n + (3 if with_height else LANDMARK_DIM)
        self.landmarks_added += 1

    def _update(self, key: int, observation: Observation, *, gate: bool = False) -> bool:
        """EKF update of landmark ``key``; with ``gate``, only inside the validation gate.

        Returns whether the update was applied."""
        n = self._dim
        i = self._slot[key]
        use_height = self._has_height[key] and has_height(observation)
        k = 3 if use_height else LANDMARK_DIM
        mean = self._mean[:n]
        P = self._cov[:n, :n]
        pose, landmark = mean[:ROBOT_DIM], mean[i : i + k]
        at_pose, at_landmark = self._linearisation_point(key, pose, landmark)
        R = measurement_covariance(observation, use_height)
        if use_height:
            predicted = observation_model(pose, landmark)
            H_pose, H_landmark = observation_jacobians(at_pose, at_landmark)
            cols = np.array([0, 1, 2, i, i + 1, i + 2])
            innovation = np.array([observation.range_m, observation.bearing_rad, observation.height_m]) - predicted
            innovation[1] = wrap_angle(float(innovation[1]))
        else:  # the plain range-bearing update (5 non-zero columns of H)
            predicted_range, predicted_bearing = range_bearing(pose, landmark)
            H_pose, H_landmark = range_bearing_jacobians(at_pose, at_landmark)
            cols = np.array([0, 1, 2, i, i + 1])
            innovation = np.array(
                [observation.range_m - predicted_range, wrap_angle(observation.bearing_rad - predicted_bearing)]
            )
        H_cols = np.hstack([H_pose, H_landmark])
        if key in self._error_index:  # the reading's error: its correlated part is in the state
            self._decay_reading_error(key, observation)
            j = self._error_index[key]
            innovation[:2] -= self._mean[j : j + 2]
            innovation[1] = wrap_angle(float(innovation[1]))
            cols = np.r_[cols, j, j + 1]
            E = np.zeros((len(innovation), 2))
            E[0, 0] = E[1, 1] = 1.0
            H_cols = np.hstack([H_cols, E])
            R = R.copy()
            R[:2, :2] *= 1.0 - self.reading_error.share
        K, S, _ = kalman_gain(P, cols, H_cols, R)
        if gate and self.known_id_gate_probability is not None:
            d2 = float(innovation @ np.linalg.solve(S, innovation))
            if not d2 <= chi2_gate(len(innovation), self.known_id_gate_probability):
                self.gated_known_id += 1
                return False
        self._correct(n, P, cols, H_cols, K, R, innovation)
        self.updates += 1
        return True

    def _correct(self, n: int, P: np.ndarray, cols: np.ndarray, H_cols: np.ndarray, K: np.ndarray, R: np.ndarray,
                 innovation: np.ndarray) -> None:
        """Apply one update: the mean moves by ``K ν`` (heading wrapped) and P takes the Joseph
        form, in place. :class:`ekf.invariant.InvariantEkfSlam` moves the mean on the group
        instead and carries P to the new estimate."""
        mean = self._mean[:n]
        mean += K @ innovation
        mean[2] = wrap_angle(float(mean[2]))
        add_low_rank_in_place(self._cov, n, *joseph_factors(P, cols, H_cols, K, R))

    def _reserve(self, needed: int) -> None:
        """Make room for a state of size ``needed``, doubling the capacity when it is full."""
        capacity = self._mean.shape[0]
        if needed <= capacity:
            return
        while capacity < needed:
            capacity *= 2
        n = self._dim
        mean = np.zeros(capacity)
        mean[:n] = self._mean[:n]
        cov = np.zeros((capacity, capacity), order="F")
        cov[:n, :n] = self._cov[:n, :n]
        self._mean, self._cov = mean, cov

