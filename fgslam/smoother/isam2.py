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
(for :meth:`Isam2Smoother.graph` and the batch solve) and the step loop; what it composes
lives in its own module: its settings and why each default (:mod:`~fgslam.smoother.settings`),
factors and noise models (:mod:`~fgslam.smoother.factors`),
held steps and keyframes (:mod:`~fgslam.smoother.policy`), observations waiting outside
iSAM2 (:mod:`~fgslam.smoother.pending`), failure recovery (:mod:`~fgslam.smoother.recovery`),
the online pose and the marginals (:mod:`~fgslam.smoother.online`) and the landmarks iSAM2
holds (:mod:`~fgslam.smoother.variables`).
"""

from __future__ import annotations

from dataclasses import replace

import gtsam
import numpy as np
from gtsam.symbol_shorthand import H, L, X

from ekf.range_only import DelayedInitRule
from ekf.observation import has_height  # the same rule as the EKF's for a usable height
from fgslam.smoother.correction import PoseCorrector
from fgslam.smoother.association import SmootherAssociation, world_joint_marginal
from fgslam.smoother.batch import gauss_newton_steps
from fgslam.smoother.chain import OdometryChain
from fgslam.smoother.factors import (
    DEFAULT_ROBUST_K,
    FactorBuilder,
    PendingObservation,
    has_tag_yaw,
    odometry_noise_covariance,
    robust_estimator,
    update_batch,
)
from fgslam.smoother.online import OnlinePose, landmark_covariances
from fgslam.smoother.pending import MAX_UNCONFIRMED, PENDING_GATE, PendingObservations, RangeOnlyLandmarks
from fgslam.smoother.policy import HeldSteps, Keyframes
from fgslam.smoother.recovery import rebuild
from fgslam.smoother.relinearisation import held_back
from fgslam.smoother.settings import Isam2Settings
from fgslam.smoother.variables import LandmarkRegistry
from fgslam.smoother.window import SlidingWindow
from slamio.errors import FgslamError
from slamio.log import Header, Observation, Step


#: While observations without an id are associated, check relinearisation on every this
#: many updates (``relinearize_skip``'s own schedule continues alongside).
ASSOCIATION_RELINEARIZE_SKIP = 10


class Isam2Smoother:
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
        **settings,
    ):
        self.settings = Isam2Settings(**settings)
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
        self._isam = gtsam.ISAM2(self.settings.isam2_params())
        self._isam_updates = 0  # updates given to this ISAM2 (GTSAM counts them for relinearize_skip)
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
        self._final_marginals: gtsam.Marginals | None = None  # the whole graph's, at that estimate
        # id-less observations: associated (fgslam/smoother/association.py) or skipped
        self.associate = bool(associate)
        self.redecide = True  # re-decide the id-less pairings against the settled map at the end (_redecide)
        self._association = SmootherAssociation()
        # poses older than the newest window_poses leave iSAM2 (fgslam/smoother/window.py)
        self._window = None if self.settings.window_poses is None else SlidingWindow(self.settings.window_poses)

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
        self._finished, self._final_marginals = False, None  # a step after finish(): iSAM2 answers again
        self._association.begin_step(step.observations)  # for step_associations()
        if k == 0:
            if step.odometry is not None:
                raise FgslamError("Isam2Smoother: step 0 is the start pose and cannot have odometry")
            seed = gtsam.Pose2(*self.header.start_pose)
            self._held.core.add(self._factors.prior(self.header))
        else:
            odo = step.odometry
            if odo is None:
                raise FgslamError(f"Isam2Smoother: step {k} has no odometry; every step after 0 starts with one")
            increment = gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad)
            assert self._online.pose is not None
            # latest iSAM2 estimate ⊕ the increments since, not dead reckoning from the start
            seed = self._online.pose.compose(increment)
            used = ()
            if self._corrector is not None:  # … corrected by the observations of mapped landmarks
                seed, used = self._corrected(odo, step.observations)
            self._online.moved(increment, odo, used)
            if self.settings.keyframes:
                observed = any(o.landmark_id is not None or self.associate for o in step.observations)
                chain = self._keyframes.fold(k, increment, odometry_noise_covariance(odo), observed)
                if chain is not None:  # a keyframe: the chain since the last one becomes one compound factor
                    noise = gtsam.noiseModel.Gaussian.Covariance(chain.covariance())
                    self._held.core.add(gtsam.BetweenFactorPose2(X(chain.start), X(k), chain.compound, noise))
            else:
                self._held.core.add(self._factors.odometry(k, increment, odo))
        if not self._keyframes.open.links:  # a variable of its own (always, without keyframes)
            self._held.values.insert(X(k), seed)
            self._keyframes.indices.append(k)
            self._add_observations(k, seed, step.observations)
        else:  # folded into the open chain; it saw no landmark id
            self.skipped_unknown_observations += len(step.observations)
        self._held.steps += 1
        self._num_poses = k + 1
        self._online.pose = seed
        if self._due(k):
            self._flush()

    def _add_observations(self, k: int, seed: gtsam.Pose2, observations) -> None:
        """Hold the factors of pose ``k``'s observations (and their heights)."""
        if self.associate:
            observations = self._associate(k, seed, observations)
        for obs in observations:
            self._add_observation(k, seed, obs)

    def _point_landmarks(self) -> list[int]:
        """The point landmarks iSAM2 holds (tags excluded): what association pairs with."""
        return [i for i in self._landmarks.ids if i not in self._landmarks.tag_ids]

    def _marginal_at_pose(self, p: int, pose: gtsam.Pose2, ids):
        """iSAM2's joint marginal of pose ``p`` (at ``pose``) and landmarks ``ids``, in the world
        frame (:func:`~fgslam.smoother.association.world_joint_marginal`)."""
        return world_joint_marginal(self._isam, OdometryChain(p), pose, ids)

    def _associate(self, k: int, seed: gtsam.Pose2, observations) -> list[Observation]:
        """The step's observations with the id-less ones given the id association chose
        (:mod:`fgslam.smoother.association`); those it did not place are left out. First
        sightings confirmed now are held too, at their own poses."""
        points = self._point_landmarks()
        for s, lid in self._association.retry_rejected(k, self._isam, self._marginal_at_pose, points):
            self._add_observation(s.pose_index, s.seed, replace(s.observation, landmark_id=lid))
        unknown = [(i, o) for i, o in enumerate(observations) if o.landmark_id is None and not o.range_only]
        self._held.uncorrected |= bool(unknown)
        self._unlabelled |= bool(unknown)
        if not unknown:
            return list(observations)
        if self._window is not None:
            raise FgslamError(
                f"Isam2Smoother: step {k} has an observation without a landmark id, and window_poses is set; "
                "pairing such observations reads every pose of the run, so run them with window_poses=None")
        since = self._online._caught_up_since_chain()
        decision = self._association.associate(
            k, seed, unknown, self._isam, lambda ids: world_joint_marginal(self._isam, since, seed, ids), points)
        for lid, sightings in decision.confirmed.items():
            self._landmarks.is_tag(lid, False)
            for s in sightings:
                self._add_observation(s.pose_index, s.seed, replace(s.observation, landmark_id=lid))
        out = []
        for i, obs in enumerate(observations):
            if obs.landmark_id is None and i in decision.paired:
                self._landmarks.is_tag(decision.paired[i], False)
                out.append(replace(obs, landmark_id=decision.paired[i]))
            elif obs.landmark_id is not None or obs.range_only:
                out.append(obs)
        return out

    def _redecide(self) -> bool:
        """Re-decide the id-less pairings against the settled map
        (:meth:`~fgslam.smoother.association.SmootherAssociation.redecide`): each changed
        pairing's factor is removed from iSAM2 (and from the kept graph) and, when it was
        re-paired, the factor to its new landmark added, in one update. If GTSAM refuses
        the update, nothing changes (the iSAM2 it was given is rebuilt as it was)."""
        changes = self._association.redecide(self._isam, self._marginal_at_pose, self._point_landmarks())
        if not changes:
            return False
        gone = {(X(c.pose_index), L(c.old)) for c in changes if c.old is not None}
        held = self._isam.getFactorsUnsafe()
        remove = [i for i in range(held.size()) if held.exists(i) and tuple(held.at(i).keys()) in gone]
        added = gtsam.NonlinearFactorGraph()
        for c in changes:
            if c.new is not None:
                pose = self._isam.calculateEstimatePose2(X(c.pose_index))
                added.add(self._factors.observation(c.pose_index, pose, replace(c.observation, landmark_id=c.new),
                                                    False).factor)
        graph = gtsam.NonlinearFactorGraph()
        for i in range(self._graph.size()):
            f = self._graph.at(i)
            if f is not None and tuple(f.keys()) not in gone:
                graph.add(f)
        graph.push_back(added)
        before = self._isam.calculateBestEstimate()
        try:
            self._isam.update(added, gtsam.Values(), remove)
            self._isam.update()  # one more relinearisation: the next pass reads a settled map
        except RuntimeError as exc:  # leave the pairings as they were
            self.update_failures += 1
            self.last_failure = str(exc)
            self._isam = gtsam.ISAM2(self.settings.isam2_params())
            self._isam_updates = 0
            self._isam_update(self._graph, before)
            return False
        self._graph = graph
        self._association.apply(changes)
        self._estimate_cache = None
        return True

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
        if has_height(obs):
            self._add_height(obs)
        is_tag = self._landmarks.is_tag(obs.landmark_id, self.tags and has_tag_yaw(obs))
        self._held.entries.append(self._factors.observation(k, seed, obs, is_tag))
        self._held.observed = True

    def _add_height(self, obs: Observation) -> None:
        """Hold a height observation's factor (:meth:`FactorBuilder.height`), and the height's
        seed when its landmark has none yet."""
        self._held.core.add(self._factors.height(obs))
        if obs.landmark_id not in self._landmarks.height_ids:
            self._held.values.insert(H(obs.landmark_id), float(obs.height_m))
            self._landmarks.height_ids.add(obs.landmark_id)

    def _due(self, k: int) -> bool:
        """Whether the held steps go to iSAM2 now (see ``update_every`` / ``update_on``)."""
        if k == 0 or self._held.steps >= self.settings.max_held_steps or self._held.urgent:
            return True
        if self._held.unlikely and self._held.steps >= self.settings.update_tail_min_steps:
            return True
        if (self.settings.update_observations and self._held.uncorrected
                and self._held.steps >= self.settings.update_observations_min_steps):
            return True
        if (self.settings.update_observations and self._held.observations >= self.settings.update_observations
                and self._held.steps >= self.settings.update_observations_min_steps):
            return True
        if self._held.steps < self.settings.update_every:
            return False
        return self.settings.update_on == "any" or self._held.observed

    def _flush(self) -> None:
        """Give every held step to iSAM2 in one update; read back the newest pose."""
        if self._held.steps == 0:
            return
        core, core_values, fresh, ranges = self._held.take()
        if self._robust is not None:
            fresh = self._pending.confirm_first_sightings(fresh, self._landmarks.known)
        entries = self._pending.screen(fresh, self._isam, self._landmarks) + fresh + ranges
        self._update_with_recovery(core, core_values, entries)
        self.updates += 1
        if self.associate:
            self._association.entered(self._landmarks.known)
        # the newest pose in iSAM2 is the last keyframe; only the open chain's steps follow it
        last = self._keyframes.last
        anchor = self._isam.calculateEstimatePose2(X(last))
        pose = self._keyframes.latest_pose(anchor)
        self._online.updated(pose, last, len(self._keyframes.open.links), anchor)
        self._landmark_xy.clear()
        if self._corrector is not None:
            self._corrector.reset((pose.x(), pose.y(), pose.theta()))

    def _corrected(self, odo, observations) -> tuple[gtsam.Pose2, tuple]:
        """The online correction (:mod:`fgslam.smoother.correction`): the corrector's pose
        moved by ``odo`` and corrected by the observations of landmarks iSAM2 holds, and
        those it used (``(landmark_id, landmark_xy, range_m, bearing_rad, R)``). A landmark iSAM2 does
        not hold yet, or a surprising observation, makes the step urgent."""
        corrector = self._corrector
        used = []
        corrector.predict((odo.dx_m, odo.dy_m, odo.dtheta_rad), odo.covariance)
        for obs in observations:
            lid = obs.landmark_id
            if lid is None:
                continue
            if lid not in self._landmarks.known:
                # a range-only landmark waits for its trilateration (pending.py), not for an update
                self._held.urgent |= not obs.range_only
                continue
            if lid in self._landmarks.tag_ids:
                continue
            xy = self._landmark_xy.get(lid)
            if xy is None:
                point = self._isam.calculateEstimatePoint2(L(lid))
                xy = self._landmark_xy[lid] = (float(point[0]), float(point[1]))
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

    def current_pose(self) -> tuple[float, float, float]:
        """The online estimate of the latest pose (x_m, y_m, theta_rad).

        iSAM2's estimate when the latest step ran an update; otherwise the last iSAM2
        estimate composed with the odometry of the steps held since.
        """
        pose = self._online.pose
        if pose is None:
            raise FgslamError("Isam2Smoother: no step yet")
        return (pose.x(), pose.y(), pose.theta())

    def finish(self) -> None:
        """Flush held steps, then refine: ``final_updates`` plain updates, then up to
        ``final_iterations`` Gauss–Newton steps on the whole graph until the error's
        relative decrease is below ``final_tolerance``
        (:func:`~fgslam.smoother.batch.gauss_newton_steps`).

        The final estimate is then those steps' result, not iSAM2's, and the covariances
        asked for after it (:meth:`landmark_covariances`, :meth:`current_covariance`) are the
        whole graph's marginals at that estimate (``gtsam.Marginals``)."""
        if self._num_poses == 0:
            return
        self._flush()
        if self.associate and self._association.unsettled:  # the deferred decisions, against the whole map
            points = self._point_landmarks()
            for s, lid in self._association.settle(self._isam, self._marginal_at_pose, points):
                self._add_observation(s.pose_index, s.seed, replace(s.observation, landmark_id=lid))
                self._held.steps = max(self._held.steps, 1)
            self._flush()
        if self.associate and self.redecide:
            for _ in range(self.REDECIDE_PASSES):  # each pass settles the map the next one reads
                if not self._redecide():
                    break
        self._association.finish()
        self._estimate_cache = None
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
        self._estimate_cache = estimate
        self._finished = True
        self._online.pose = self._keyframes.latest_pose(self._estimate_cache.atPose2(X(self._keyframes.last)))

    def trajectory(self) -> np.ndarray:
        """(n, 3) array of every pose (x_m, y_m, theta_rad) as estimated now."""
        return self.trajectory_of(self._estimate())

    def trajectory_of(self, values: gtsam.Values) -> np.ndarray:
        """(n, 3) array of every pose for the keyframe (or all-pose) estimate ``values``
        (:meth:`fgslam.smoother.policy.Keyframes.trajectory`: with keyframes the poses between
        them are rebuilt from the odometry folded into their compound factor)."""
        return self._keyframes.trajectory(values, self._num_poses)

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Landmark id → estimated world (x_m, y_m), for landmarks accepted into iSAM2
        (a tag's position is its centre)."""
        return self._landmarks.positions(self._estimate())

    def landmark_yaws(self) -> dict[int, float]:
        """Tag id → estimated world direction its face points to (rad); tags only (``tags=True``)."""
        return self._landmarks.yaws(self._estimate())

    def landmark_heights(self) -> dict[int, float]:
        """Landmark id → estimated height (m), for landmarks observed with a height."""
        return self._landmarks.heights(self._estimate())

    # ------------------------------------------------------------------ extras

    @property
    def num_poses(self) -> int:
        return self._num_poses

    def current_covariance(self, frame: str = "world") -> np.ndarray:
        """3×3 covariance of :meth:`current_pose`, the online estimate.

        iSAM2's marginal of the newest pose it holds (``isam.marginalCovariance``, which
        uses the Bayes tree and does not recompute the whole graph's marginals), carried
        through the odometry of any steps held since (first order: Σ ← Ad(z⁻¹) Σ Ad(z⁻¹)ᵀ + Σ_z
        per increment z), so asking does not change when iSAM2 updates. GTSAM expresses a
        Pose2's uncertainty in the robot's own frame (a perturbation ``pose ⊕ δ``). With
        ``frame="world"`` (the default) it is rotated into world (x, y, theta) coordinates,
        the same coordinates as the EKF's covariance and as a world-frame pose error, which
        is what NEES needs; ``frame="body"`` returns GTSAM's own.
        """
        if self._num_poses == 0:
            raise FgslamError("Isam2Smoother: no step yet")
        if frame not in ("world", "body"):
            raise FgslamError(f"current_covariance: frame must be 'world' or 'body', got {frame!r}")
        return self._online.covariance(self._marginals(), frame)

    def landmark_covariances(self) -> dict[int, np.ndarray]:
        """Landmark id → 2×2 marginal covariance of its (x, y) in the world frame
        (``isam.marginalCovariance``; for a tag, the position block of its Pose2 marginal
        rotated from the tag's frame). Flushes held steps."""
        self._flush()
        return landmark_covariances(self._marginals(), self._estimate(), self._landmarks.ids, self._landmarks.tag_ids)

    def predicted_nis(self, step: Step) -> list[float | None]:
        """NIS of each observation of ``step`` against the smoother's prediction, before
        the step is added (nothing is changed; call it before :meth:`step`).

        The same question the EKF answers (:meth:`ekf.EkfSlam.predicted_nis`): the joint
        marginal of the newest iSAM2 pose and the observed landmarks
        (``isam.jointMarginalCovariance``), the pose carried through the odometry held since
        and this step's (Σ ← A Σ Aᵀ + Σ_z, cross-covariance ← A Σ_pl, A = Ad(z⁻¹)), rotated
        into world (x, y, θ), then :func:`ekf.models.range_bearing_nis`. None for an
        observation without an id, of a landmark iSAM2 does not hold yet, or of a tag, and
        for every observation of the step when iSAM2 cannot form the marginal (an
        indeterminate system, which real data with gross outliers can produce).
        """
        return self._online.predicted_nis(self._isam, step, self._landmarks.tag_ids)

    def graph(self) -> gtsam.NonlinearFactorGraph:
        """The whole problem: every factor accepted into iSAM2 (pending observations
        excluded), with a variable for every pose.

        Held steps are given to iSAM2 first, so the graph covers every step taken. With
        keyframes, each compound odometry factor iSAM2 holds is expanded back into its
        per-step factors, so this is the same graph as without keyframes."""
        self._flush()
        if not self.settings.keyframes:
            return gtsam.NonlinearFactorGraph(self._graph)
        return self._keyframes.expanded(self._graph)

    def initial_values(self) -> gtsam.Values:
        """A copy of the initial guess of every variable of :meth:`graph` (held steps flushed
        first; with keyframes, poses between keyframes dead-reckoned from the keyframe's)."""
        self._flush()
        values = gtsam.Values(self._initial)
        if self.settings.keyframes:
            self._keyframes.insert_between(values)
        return values

    def estimate(self) -> gtsam.Values:
        """A copy of iSAM2's current estimate of every variable of :meth:`graph` (one full
        back-substitution, ``calculateBestEstimate``; with keyframes, the poses between them as in :meth:`trajectory`)."""
        values = gtsam.Values(self._estimate())
        if self.settings.keyframes:
            trajectory = self.trajectory_of(values)
            keyframes = set(self._keyframes.indices)
            for i in range(self._num_poses):
                if i not in keyframes:
                    values.insert(X(i), gtsam.Pose2(*trajectory[i]))
        return values

    def error(self) -> float:
        """:meth:`graph`'s error at :meth:`estimate` (χ²/2, like ``graph.error``)."""
        if self.settings.keyframes:
            return float(self.graph().error(self.estimate()))
        return float(self._graph.error(self._estimate()))

    @property
    def window_slides(self) -> int:
        """How many times the sliding window (``window_poses``) marginalised the oldest poses."""
        return 0 if self._window is None else self._window.slides

    @property
    def pending_observations(self) -> int:
        """Observations withheld after a failed update, still to be retried."""
        return len(self._pending.withheld)

    @property
    def unconfirmed_observations(self) -> int:
        """Robust mode: first sightings of landmarks still waiting for a second that agrees."""
        return sum(len(q) for q in self._pending.unconfirmed.values())

    @property
    def dropped_observations(self) -> int:
        """Observations withheld after a failed update and then abandoned."""
        return self._pending.dropped

    @property
    def rejected_first_sightings(self) -> int:
        """Robust mode: first sightings no later observation agreed with (dropped)."""
        return self._pending.rejected_first_sightings

    def step_associations(self) -> list[int | None]:
        """Per observation of the last step: the landmark id it was used as (the log's id,
        or one the smoother chose, :mod:`fgslam.smoother.association`), or None (not used
        yet: rejected, or a first sighting waiting; see :meth:`associations`)."""
        return self._association.step_keys()

    def associations(self) -> list[int | None]:
        """Per observation of the whole run, in log order: the id it was finally used as
        (first sightings confirmed later included), or None (not used)."""
        return self._association.keys()

    @property
    def association_counts(self) -> dict[str, int]:
        """What became of the id-less observations: ``paired`` (to a landmark, new ones
        included), ``created`` landmarks, ``rejected`` (ambiguous: near a landmark but not
        jointly compatible, or nearly as likely another's), ``retried`` (paired when asked
        again), ``repaired`` and ``unpaired`` (pairings moved to another landmark or dropped
        at the end, :meth:`_redecide`), ``retired`` (landmarks found redundant at the end, whose
        readings moved to the others but one), ``unconfirmed`` (first sightings nothing agreed with), and
        ``skipped`` (observations ignored because they had no id, with ``associate=False``
        or inside a keyframe chain)."""
        a = self._association
        counts = {"skipped": self.skipped_unknown_observations}
        if self.associate:
            counts.update(paired=a.paired, created=a.created, rejected=a.rejected, retried=a.retried,
                          repaired=a.repaired, unpaired=a.unpaired, retired=len(a.retired),
                          unconfirmed=a.unconfirmed,
                          waiting=sum(len(g) for g in a.waiting))
        return counts

    # ------------------------------------------------------------------ internals

    def _marginals(self):
        """Where marginal covariances come from: iSAM2's Bayes tree during the run; after
        :meth:`finish`, the whole graph linearised at the final estimate (``gtsam.Marginals``,
        built on the first question), since the final Gauss–Newton steps moved the estimate
        past iSAM2's linearisation point."""
        if not self._finished:
            return self._isam
        if self._final_marginals is None:
            self._final_marginals = gtsam.Marginals(self._graph, self._estimate_cache)
        return self._final_marginals

    def _estimate(self) -> gtsam.Values:
        self._flush()
        if self._estimate_cache is None:
            # the full back-substitution: with the default wildfire threshold (1.0)
            # calculateEstimate() would leave the deltas deep in the tree stale
            self._estimate_cache = self._best_estimate()
        return self._estimate_cache

    def _best_estimate(self) -> gtsam.Values:
        """iSAM2's full back-substitution (``calculateBestEstimate``), with the poses that
        left the sliding window at their estimates then."""
        values = self._isam.calculateBestEstimate()
        if self._window is not None:
            values.insert(self._window.frozen)
        return values

    def _update_with_recovery(self, core, core_values, entries: list[PendingObservation]) -> None:
        self._estimate_cache = None
        if self._window is not None:
            entries = self._entries_in_window(entries)
        factors, values = update_batch(core, core_values, entries, self._landmarks.known)
        try:
            self._isam_update(factors, values)
        except RuntimeError as exc:
            self._recover(exc, core, core_values, entries)
            return
        self._accept(factors, values)
        if self._window is not None and self._window.due():
            self._slide()

    def _entries_in_window(self, entries: list[PendingObservation]) -> list[PendingObservation]:
        """Of an update's observation entries, those whose pose iSAM2 still holds. The others
        (first sightings confirmed late, ranges buffered before their landmark was placed)
        go into the whole graph only — :meth:`finish` solves it — once their landmark is in
        iSAM2; until then they wait with the withheld observations."""
        inside = [e for e in entries if self._window.holds(e.pose_index)]
        late = [e for e in entries if not self._window.holds(e.pose_index)]
        entering = self._landmarks.known | {e.landmark_id for e in inside}
        for e in late:
            if e.landmark_id in entering:
                self._graph.add(e.factor)
            else:
                self._pending.withheld.append(e)
        return inside

    def _slide(self) -> None:
        """Marginalise all but the newest ``window_poses`` poses and go on with a fresh
        iSAM2 holding the rest (:class:`~fgslam.smoother.window.SlidingWindow`)."""
        estimate = self._isam.calculateBestEstimate()
        kept = self._window.slide(estimate)
        fresh = gtsam.ISAM2(self.settings.isam2_params())
        try:
            fresh.update(kept.factors, kept.values)
        except RuntimeError as exc:  # an indeterminate system: go on with every pose, as without a window
            self.update_failures += 1
            self.last_failure = str(exc)
            self._window.stopped = True
            return
        self._window.commit(kept, estimate)
        self._isam, self._isam_updates = fresh, 0
        self._online.forget_marginal()
        self._landmark_xy.clear()

    def _isam_update(self, factors: gtsam.NonlinearFactorGraph | None = None,
                     values: gtsam.Values | None = None) -> None:
        """One ``ISAM2.update`` (none: no new factors); with observations being associated, a
        relinearisation check on every :data:`ASSOCIATION_RELINEARIZE_SKIP`-th (GTSAM checks
        on the n-th update of an ``ISAM2`` when n is a multiple of ``relinearize_skip``);
        otherwise GTSAM's own check relinearises at most ``relinearize_max_variables``."""
        self._isam_updates += 1
        if self._unlabelled and self._isam_updates % ASSOCIATION_RELINEARIZE_SKIP == 0:
            update_params = gtsam.ISAM2UpdateParams()
            update_params.force_relinearize = True  # forces the check, not the relinearisation
            self._isam.update(factors or gtsam.NonlinearFactorGraph(), values or gtsam.Values(), update_params)
        elif (self.settings.relinearize_max_variables is not None and not self._unlabelled
              and self._isam_updates % self.settings.relinearize_skip == 0):  # GTSAM's own check, capped
            update_params = gtsam.ISAM2UpdateParams()
            held = held_back(self._isam, self.settings.relinearize_threshold, self.settings.relinearize_max_variables)
            if held.size():
                update_params.noRelinKeys = held
            self._isam.update(factors or gtsam.NonlinearFactorGraph(), values or gtsam.Values(), update_params)
        elif factors is None:
            self._isam.update()
        else:
            self._isam.update(factors, values)

    def _accept(self, factors: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> None:
        self._graph.push_back(factors)
        self._initial.insert(values)
        self._landmarks.enter(values)
        if self._window is not None:
            self._window.entered(factors, values)

    def _recover(self, exc: RuntimeError, core, core_values, entries: list[PendingObservation]) -> None:
        """Replace the broken iSAM2 by a fresh one holding everything but withheld observations
        (:func:`fgslam.smoother.recovery.rebuild`)."""
        self.update_failures += 1
        held, seeds = (self._graph, self._initial) if self._window is None else (self._window.factors, self._window.values)
        rebuilt = rebuild(exc, self._isam, self.settings.isam2_params(), held, seeds, core, core_values, entries,
                          self._landmarks.known)
        self.last_failure = rebuilt.last_failure
        if rebuilt.isam is None:
            raise FgslamError(
                f"Isam2Smoother: the graph is singular even without this step's observations "
                f"(pose {self._num_poses}); check the odometry covariance and the start sigmas. "
                f"GTSAM said: {' '.join(self.last_failure.split('Thrown when')[0].split())}"
            )
        self._isam = rebuilt.isam
        self._isam_updates = 0  # counted from the rebuild on (its own updates are not)
        self._accept(rebuilt.factors, rebuilt.values)
        self._pending.withhold(rebuilt.withheld)

