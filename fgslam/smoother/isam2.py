"""The online smoother: :class:`Isam2Smoother`, which composes the pieces of this package.

Steps are held and go to iSAM2 in one ``ISAM2.update`` once they carry 20 observations
and 10 steps (``update_observations``) or 50 steps wait (``update_every``); sooner after
an observation the online correction finds unlikely (``update_tail``), and at once for a
step that sees a landmark iSAM2 does not hold yet; with their new factors and new variables. A new pose is seeded from the
*current iSAM2 estimate* of the previous pose composed with the odometry increment and
corrected by the online correction (:mod:`fgslam.smoother.correction`, which is also the
online pose between updates; seeding from dead reckoning makes iSAM2 diverge on real
data: χ²/2 2.3e9 on Victoria Park, docs/estimators.md); a landmark seen for the first time is seeded from that seed pose and the
observation (in robust mode only once two observations agree, see
:meth:`.PendingObservations.confirm_first_sightings`, fgslam/smoother/pending.py). After the
update only the newest pose is read back (``calculateEstimatePose2``); the full estimate
is computed on demand.
:meth:`Isam2Smoother.finish` ends with full Gauss–Newton steps on the whole graph, so the
final estimate is the batch optimum whatever the settings (docs/performance.md) — to
first order with ``keyframes``, where the poses between keyframes are rebuilt
(:class:`~fgslam.smoother.policy.Keyframes`).

Everything accepted into iSAM2 is also kept in one ``NonlinearFactorGraph`` plus the
initial ``Values``, so :func:`~fgslam.smoother.batch.batch_solve` can run
Levenberg–Marquardt on the same problem, started from iSAM2's answer (batch LM started from odometry gets stuck in a
local minimum on real data; started from iSAM2 it converges — docs/datasets.md, Victoria Park).

The smoother itself holds the iSAM2 object, the graph and initial values accepted so far
(for :meth:`Isam2Smoother.graph` and the batch solve), the step loop and ``finish``. Its
other methods come from three mixins, by responsibility: giving held steps to iSAM2
(:mod:`~fgslam.smoother.updates`: when, the update itself, recovery, the window's slide),
answering questions (:mod:`~fgslam.smoother.queries`) and the smoother's side of pairing
observations without an id (:mod:`~fgslam.smoother.pairings`). What it composes
lives in its own module: its settings and why each default (:mod:`~fgslam.smoother.settings`),
factors and noise models (:mod:`~fgslam.smoother.factors`),
held steps and keyframes (:mod:`~fgslam.smoother.policy`), observations waiting outside
iSAM2 (:mod:`~fgslam.smoother.pending`), failure recovery (:mod:`~fgslam.smoother.recovery`),
the online pose and the marginals (:mod:`~fgslam.smoother.online`) and the landmarks iSAM2
holds (:mod:`~fgslam.smoother.variables`).
"""

from __future__ import annotations

from typing import Callable

import gtsam
import numpy as np
from gtsam.symbol_shorthand import H, L, X

from ekf.range_only import DelayedInitRule
from ekf.observation import has_height  # the same rule as the EKF's for a usable height
from fgslam.smoother.correction import PoseCorrector
from fgslam.smoother.association import SmootherAssociation
from fgslam.smoother.batch import gauss_newton_steps
from fgslam.smoother.map_marginals import JointBlocks
from fgslam.smoother.factors import (
    DEFAULT_ROBUST_K,
    X0,
    FactorBuilder,
    has_tag_yaw,
    odometry_noise_covariance,
    robust_estimator,
)
from fgslam.smoother.online import OnlinePose
from fgslam.smoother.pairings import IdlessPairings
from fgslam.smoother.pending import MAX_UNCONFIRMED, PENDING_GATE, PendingObservations, RangeOnlyLandmarks
from fgslam.smoother.policy import HeldSteps, Keyframes
from fgslam.smoother.relinearisation import CapChoice
from fgslam.smoother.queries import EstimateQueries
from fgslam.smoother.settings import Isam2Settings
from fgslam.smoother.updates import Isam2Updates
from fgslam.smoother.variables import LandmarkRegistry
from fgslam.smoother.window import SlidingWindow
from slamio.errors import FgslamError
from slamio.log import Header, Observation, Step


class Isam2Smoother(IdlessPairings, Isam2Updates, EstimateQueries):
    """Online landmark SLAM with iSAM2 (implements :class:`slamio.estimator.Estimator`).

    Parameters
    ----------
    header:
        The run log's header (start pose and its prior sigmas).
    **settings:
        How the graph is solved — when steps go to iSAM2, the relinearisation threshold,
        schedule and cap, the online correction, the final Gauss–Newton steps, GTSAM's
        parameters, keyframes: the fields of
        :class:`~fgslam.smoother.settings.Isam2Settings`, each default with the measurement
        that chose it (fgslam/smoother/settings.py). Kept as :attr:`settings`.
    robust:
        ``None`` (default): every factor is Gaussian (least squares). ``"huber"``,
        ``"cauchy"``, ``"tukey"`` or ``"dcs"``: landmark factors get that robust kernel through
        ``gtsam.noiseModel.Robust`` around their diagonal noise, so observations far
        from the rest (misdetections with a valid id) lose their pull; odometry and the
        prior stay Gaussian. The graph kept for :func:`batch_solve` holds the same robust
        factors, so the batch solve is robust too, and :meth:`error` is the robust cost.
        ``name`` becomes ``"isam2-huber"``, ``"isam2-cauchy"``, ``"isam2-tukey"`` or ``"isam2-dcs"``.
    robust_k:
        The kernel width in whitened units (σ of the 2-D residual norm); None takes
        :data:`DEFAULT_ROBUST_K` (Huber 1.345, Cauchy 3.72, Tukey 7.43, DCS 3.72; why
        there). Only with ``robust``.

        A robust kernel cannot repair a landmark *seeded* from a misdetection, so in
        robust mode a landmark enters the map only once two of its observations agree
        (:meth:`.PendingObservations.confirm_first_sightings`, fgslam/smoother/pending.py).
        Measured on arena-octagon seeds 1–10 with 10 % outliers, ATE relative to iSAM2 on
        the log with exactly the outliers removed (an oracle; the simulator *replaces*
        observations, so the outlier-free log has 10 % more information and even the oracle
        is up to 1.4× its ATE): DCS max 1.06×, mean 1.01×; Cauchy max 1.10×, mean 0.99×;
        Tukey max 1.07×, mean 0.99×; Huber max 1.32×, mean 1.05× (Huber never stops
        pulling). Without the first-sighting check: Cauchy 1.08×, Huber 3.3×, Tukey 5.3× at
        worst. Use DCS: on the 200-landmark grid the others move the map even on a clean log
        (docs/performance.md has the tables).

    associate:
        ``True`` (default): observations without a ``landmark_id`` are associated with the
        landmarks the smoother holds, on its own marginals, with JCBB, new landmarks entering
        only once three sightings agree (:mod:`fgslam.smoother.association`; counts in
        :attr:`association_counts`, the ids used in :meth:`step_associations`). At
        :meth:`finish` the pairings are decided again against the settled map and the
        factors the data no longer support are moved or dropped (the attribute ``redecide``,
        default True; :meth:`_redecide`). ``False``: they are skipped and counted in
        ``skipped_unknown_observations``.
    tags:
        ``False`` (default): every landmark is a point, as in the EKF. ``True``: a landmark
        whose first observation carries a tag yaw is a ``Pose2`` tag observed through
        relative-pose factors (:mod:`fgslam.smoother`), so its facing direction is estimated
        too (:meth:`landmark_yaws`), and the yaw also constrains the robot's heading.
        ``name`` becomes ``"isam2-tags"``.
    isam_wrapper:
        None (default), or a callable applied to every ``gtsam.ISAM2`` the smoother builds
        (at the start, after a failed update, when a window slides) whose result it uses in
        its place: the benchmarks wrap it to time its calls (``scripts/profile_isam2.py``).

    Attributes
    ----------
    skipped_unknown_observations:
        Observations ignored because their ``landmark_id`` was None (only with
        ``associate=False``, or folded into a keyframe chain).
    update_failures:
        Steps whose iSAM2 update raised (each recovered from by a rebuild).
    dropped_observations:
        Observations withheld after a failed update and then abandoned (gated out, or
        failed ``1 + max_retries`` times).
    last_failure:
        The message of the most recent failed update, or None.
    pending_observations:
        Observations withheld after a failed update and not yet retried or dropped.
    rejected_first_sightings:
        Robust mode only: observations of a landmark not yet in the map that no later
        observation agreed with (see :meth:`.PendingObservations.confirm_first_sightings`);
        dropped.
    """

    name = "isam2"

    #: A pending observation whose ½‖whitened residual‖² at the current estimate exceeds
    #: this (≈ 7σ in one component) is dropped instead of retried.
    PENDING_GATE = PENDING_GATE

    #: Robust mode: first sightings of a landmark kept waiting for one that agrees.
    MAX_UNCONFIRMED = MAX_UNCONFIRMED
    #: End-of-run re-decisions of the id-less pairings (:meth:`_redecide`): at most this many
    #: passes, each against the map the previous one left; they stop when a pass changes nothing.
    #: Each pass retires at most one redundant landmark, so a map with several needs several;
    #: the passes alone pay too (MRCLAM robot 2 with the barcodes withheld, nothing retired:
    #: 2 548 readings right after 3 passes, 2 600 after 8, ATE 0.250 → 0.177 m).
    REDECIDE_PASSES = 8

    def __init__(
        self,
        header: Header,
        *,
        robust: str | None = None,
        robust_k: float | None = None,
        tags: bool = False,
        associate: bool = True,
        isam_wrapper: Callable[[gtsam.ISAM2], object] | None = None,
        **settings,
    ):
        self.settings = Isam2Settings(**settings)
        # applied to every ISAM2 this smoother builds (a benchmark's timer of its calls)
        self._isam_wrapper = isam_wrapper
        self.updates = 0  # iSAM2 updates run by step()/flushes (not counting finish or rebuilds)
        self.final_iterations_run = 0  # Gauss–Newton steps finish() took and kept
        if robust is None:
            if robust_k is not None:
                raise FgslamError("Isam2Smoother: robust_k needs a robust kernel (robust='huber' or 'cauchy')")
            self._robust = None
        else:
            self._robust = robust_estimator(robust, robust_k)
        self.tags = bool(tags)
        self.name = "-".join(["isam2"] + (["tags"] if self.tags else []) + ([robust] if robust else []))
        self.robust = robust
        self.robust_k = None if robust is None else (DEFAULT_ROBUST_K[robust] if robust_k is None else float(robust_k))
        self.header = header

        self.skipped_unknown_observations = 0
        self.update_failures = 0
        self.last_failure: str | None = None

        self._factors = FactorBuilder(self._robust)
        self._isam = self._new_isam()
        self._isam_updates = 0  # updates given to this ISAM2 (GTSAM counts them for relinearize_skip)
        # the relinearisation cap's choice, keeping iSAM2's keys between checks (relinearisation.py)
        self._cap = CapChoice(self.settings.relinearize_threshold, self.settings.relinearize_max_variables or 0,
                              self.settings.relinearize_choice)
        self._unlabelled = False  # observations without an id seen: the smoother associates them
        self._graph = gtsam.NonlinearFactorGraph()  # every factor accepted into iSAM2
        self._initial = gtsam.Values()  # the initial guess of every variable in iSAM2
        self._landmarks = LandmarkRegistry()
        self._pending = PendingObservations(self.settings.max_retries, self.PENDING_GATE, self.MAX_UNCONFIRMED)
        self.range_rule = DelayedInitRule()
        self._ranges = RangeOnlyLandmarks(self.range_rule)
        self._held = HeldSteps()  # steps not yet given to iSAM2 (update_every / update_on)
        self._keyframes = Keyframes(self.settings.keyframes, self.settings.max_keyframe_gap)
        self._online = OnlinePose()  # the newest pose, for current_pose/current_covariance
        self._corrector = (
            PoseCorrector(header.start_pose, np.diag(np.square(np.asarray(header.start_sigma, dtype=float))))
            if self.settings.online_correction else None
        )
        self._landmark_xy: dict[int, tuple[float, float]] = {}  # iSAM2's landmark estimates at its last update
        self._num_poses = 0
        self._estimate_cache: gtsam.Values | None = None
        self._finished = False  # finish() ran and nothing changed since: its estimate is the final one
        self._final_marginals: gtsam.GaussianBayesTree | None = None  # the whole graph's, at that estimate
        self._final_map: JointBlocks | bool | None = None  # the landmarks' joint there (map_marginals.py; False: not used)
        self._final_ordering: gtsam.Ordering | None = None  # the final Gauss–Newton steps' elimination ordering
        # id-less observations: associated (fgslam/smoother/association.py) or skipped
        self.associate = bool(associate)
        self.redecide = True  # re-decide the id-less pairings against the settled map at the end (_redecide)
        self._association = SmootherAssociation()
        # poses older than the newest window_poses leave iSAM2 (fgslam/smoother/window.py)
        self._window = None if self.settings.window_poses is None else SlidingWindow(self.settings.window_poses)

    def _new_isam(self, isam: gtsam.ISAM2 | None = None):
        """``isam`` (default: a new ``ISAM2`` from the settings) as the smoother will use it."""
        isam = gtsam.ISAM2(self.settings.isam2_params()) if isam is None else isam
        return isam if self._isam_wrapper is None else self._isam_wrapper(isam)

    # ------------------------------------------------------------------ Estimator protocol

    def step(self, step: Step) -> None:
        """Add pose ``step.index`` (and its observations); run an iSAM2 update when one is due.

        With ``update_every`` > 1 or ``update_on="observations"`` the step may be held: its
        factors wait for the next update, and :meth:`current_pose` is the last iSAM2
        estimate composed with the odometry since (what a live robot would act on).
        """
        k = step.index
        if k != self._num_poses:
            raise FgslamError(f"Isam2Smoother: expected step {self._num_poses}, got step {k}; feed steps in order")
        self._finished, self._final_marginals, self._final_map = False, None, None  # a step after finish(): iSAM2 answers again
        observations = step.observations
        self._association.begin_step(observations)  # for step_associations()
        if k == 0:
            if step.odometry is not None:
                raise FgslamError("Isam2Smoother: step 0 is the start pose and cannot have odometry")
            seed = gtsam.Pose2(*self.header.start_pose)
            self._held.core.append(self._factors.prior(self.header))
        else:
            odo = step.odometry
            if odo is None:
                raise FgslamError(f"Isam2Smoother: step {k} has no odometry; every step after 0 starts with one")
            assert self._online.pose is not None
            # latest iSAM2 estimate ⊕ the increments since, not dead reckoning from the start …
            if self._corrector is not None:  # … corrected by the observations of mapped landmarks
                seed, used = self._corrected(odo, observations)
            else:
                seed, used = self._online.pose.compose(gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad)), ()
            self._online.moved(odo, used)
            if self.settings.keyframes:
                increment = gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad)
                observed = any(o.landmark_id is not None or self.associate for o in observations)
                chain = self._keyframes.fold(k, increment, odometry_noise_covariance(odo), observed)
                if chain is not None:  # a keyframe: the chain since the last one becomes one compound factor
                    noise = gtsam.noiseModel.Gaussian.Covariance(chain.covariance())
                    self._held.core.append(gtsam.BetweenFactorPose2(X(chain.start), X(k), chain.compound, noise))
            else:
                self._held.core.append((k, odo))  # its factor is built when the held steps go to iSAM2
        if not self._keyframes.open.links:  # a variable of its own (always, without keyframes)
            self._held.values.append((X0 + k, seed))
            self._keyframes.indices.append(k)
            if observations or self._association.retry:  # (retries are due at any step; most steps see nothing)
                self._add_observations(k, seed, observations)
        else:  # folded into the open chain; it saw no landmark id
            self.skipped_unknown_observations += len(observations)
        self._held.steps += 1
        self._num_poses = k + 1
        self._online.pose = seed
        if self._due(k):
            self._flush()

    def _add_observations(self, k: int, seed: gtsam.Pose2, observations) -> None:
        """Hold the factors of pose ``k``'s observations (and their heights)."""
        if self.associate and (observations or self._association.retry):  # (retries are due at any step)
            observations = self._associate(k, seed, observations)
        for obs in observations:
            self._add_observation(k, seed, obs)

    def _add_observation(self, k: int, seed: gtsam.Pose2, obs: Observation) -> None:
        """Hold the factor of one observation made from pose ``k`` (and its height)."""
        if obs.landmark_id is None:
            self.skipped_unknown_observations += 1
            return
        if obs.range_only:
            self._landmarks.is_tag(obs.landmark_id, False)  # a range-only landmark is a point
            self._held.ranges += self._ranges.add(k, seed, obs, self._factors)
            self._held.observed = True
            return
        if obs.height_m is not None and has_height(obs):
            self._add_height(obs)
        is_tag = self._landmarks.is_tag(obs.landmark_id, self.tags and has_tag_yaw(obs))
        self._held.entries.append(self._factors.observation(k, seed, obs, is_tag))
        self._held.observed = True

    def _add_height(self, obs: Observation) -> None:
        """Hold a height observation's factor (:meth:`FactorBuilder.height`), and the height's
        seed when its landmark has none yet."""
        self._held.core.append(self._factors.height(obs))
        if obs.landmark_id not in self._landmarks.height_ids:
            self._held.values.append((H(obs.landmark_id), float(obs.height_m)))
            self._landmarks.height_ids.add(obs.landmark_id)

    def _corrected(self, odo, observations) -> tuple[gtsam.Pose2, tuple]:
        """The online correction (:mod:`fgslam.smoother.correction`): the corrector's pose
        moved by ``odo`` and corrected by the observations of landmarks iSAM2 holds, and
        those it used (``(landmark_id, landmark_xy, range_m, bearing_rad, R)``). A landmark iSAM2 does
        not hold yet, or a surprising observation, makes the step urgent."""
        corrector = self._corrector
        corrector.predict((odo.dx_m, odo.dy_m, odo.dtheta_rad), odo.covariance)
        if not observations:  # (most steps of a long log)
            return gtsam.Pose2(*corrector.mean), ()
        used = []
        known, tag_ids, landmark_xy = self._landmarks.known, self._landmarks.tag_ids, self._landmark_xy
        for obs in observations:
            lid = obs.landmark_id
            if lid is None:
                continue
            if lid not in known:
                # a range-only landmark waits for its trilateration (pending.py), not for an update
                self._held.urgent |= not obs.range_only
                continue
            if lid in tag_ids:
                continue
            xy = landmark_xy.get(lid)
            if xy is None:
                point = self._isam.calculateEstimatePoint2(L(lid))
                xy = landmark_xy[lid] = (float(point[0]), float(point[1]))
            if obs.range_only:
                R = obs.sigma_range_m**2
                bearing = None
            else:
                R = ((obs.sigma_range_m**2, 0.0), (0.0, obs.sigma_bearing_rad**2))
                bearing = obs.bearing_rad
            if corrector.correct(xy, obs.range_m, bearing, R):
                used.append((lid, xy, obs.range_m, bearing, R))
                if corrector.last_tail < self.settings.update_tail:
                    self._held.unlikely = True
            else:
                self._held.urgent = True
        return gtsam.Pose2(*corrector.mean), tuple(used)

    def finish(self) -> None:
        """Flush held steps, then refine: ``final_updates`` plain updates, then up to
        ``final_iterations`` Gauss–Newton steps on the whole graph until the error's
        relative decrease is below ``final_tolerance``
        (:func:`~fgslam.smoother.batch.gauss_newton_steps`).

        The final estimate is then those steps' result, not iSAM2's, and the covariances
        asked for after it (:meth:`landmark_covariances`, :meth:`current_covariance`) are the
        whole graph's marginals at that estimate (``gtsam.Marginals``' numbers, from
        :mod:`fgslam.smoother.map_marginals`)."""
        if self._num_poses == 0:
            return
        self._flush()
        self._settle_pairings()
        self._estimate_cache = None
        self._final_marginals, self._final_map, self._final_ordering = None, None, None
        self._landmark_xy.clear()
        self._online.forget_marginal()  # the final updates below change iSAM2
        for _ in range(self.settings.final_updates):
            try:
                self._isam_update()
            except RuntimeError as exc:  # relinearisation hit a singular system: rebuild
                self._recover(exc, gtsam.NonlinearFactorGraph(), gtsam.Values(), [])
        # The full back-substitution: calculateEstimate() skips delta changes below the
        # wildfire threshold, which on Victoria Park left χ²/2 25 % above the optimum.
        estimate = self._best_estimate()
        if self.settings.final_iterations:  # Gauss–Newton steps on the whole graph (batch.py: why not iSAM2's)
            polished = gauss_newton_steps(self._graph, estimate, self.settings.final_iterations,
                                          self.settings.final_tolerance)
            self.final_iterations_run += polished.iterations
            if polished.failure is not None:
                self.last_failure = polished.failure
            estimate = polished.values
            self._final_ordering = polished.ordering
        self._estimate_cache = estimate
        self._finished = True
        self._online.pose = self._keyframes.latest_pose(self._estimate_cache.atPose2(X(self._keyframes.last)))
