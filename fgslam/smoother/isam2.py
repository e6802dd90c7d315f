"""The online smoother: :class:`Isam2Smoother`, which composes the pieces of this package.

Steps are held and go to iSAM2 in one ``ISAM2.update`` once they carry 20 observations
and 10 steps (``update_observations``) or 50 steps wait (``update_every``); sooner after
an observation the online correction finds unlikely (``update_tail``), and at once for a
step that sees a landmark iSAM2 does not hold yet; with their new factors and new variables. A new pose is seeded from the
*current iSAM2 estimate* of the previous pose composed with the odometry increment and
corrected by the online correction (:mod:`fgslam.smoother.correction`, which is also the
online pose between updates; seeding from dead reckoning makes iSAM2 diverge on real
data, see DESIGN.md); a landmark seen for the first time is seeded from that seed pose and the
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
local minimum on real data; started from iSAM2 it converges — DESIGN.md).

The smoother itself holds the iSAM2 object, the graph and initial values accepted so far
(for :meth:`Isam2Smoother.graph` and the batch solve) and the step loop; what it composes
lives in its own module: factors and noise models (:mod:`~fgslam.smoother.factors`),
held steps and keyframes (:mod:`~fgslam.smoother.policy`), observations waiting outside
iSAM2 (:mod:`~fgslam.smoother.pending`), failure recovery (:mod:`~fgslam.smoother.recovery`),
the online pose and the marginals (:mod:`~fgslam.smoother.online`) and the landmarks iSAM2
holds (:mod:`~fgslam.smoother.variables`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import gtsam
import numpy as np
from gtsam.symbol_shorthand import H, L, X

from ekf.range_only import DelayedInitRule
from ekf.observation import has_height  # the same rule as the EKF's for a usable height
from fgslam.smoother.correction import PoseCorrector
from fgslam.smoother.association import SmootherAssociation, world_joint_marginal
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
from fgslam.smoother.variables import LandmarkRegistry
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
    relinearize_threshold:
        iSAM2 relinearises a variable when its pending update exceeds this (radians or
        metres, per component). Default 0.01 (GTSAM's own default is 0.1). A pair
        ``(metres, radians)`` sets the translation and rotation thresholds apart (GTSAM's
        per-variable-type threshold map; a landmark's height counts as metres).
    relinearize_skip:
        Check for relinearisation every this many updates. Default 20 (GTSAM's is 10).

        Why these defaults, measured: with 0.01 a desk-sized robot's centimetre errors
        still trigger relinearisation (GTSAM's 0.1 lost the online ATE on the bundled
        octagon log: 0.01105 vs the EKF's 0.01099 m). Checking every update instead of
        every 10th changed nothing measurable — arena-octagon seeds 1–20 gave identical
        ATEs, grid 200 (seed 1) online ATE 0.3082 vs 0.3083 m — but cost 2.2× the time on
        grid 200 (35 vs 15.6 s) and 2.7× on grid 500: each check can relinearise a large
        part of the map after a loop closure. Now that an update carries 10–50 held steps,
        every 20th instead of every 10th: the checks were most of the update time (MRCLAM
        Dataset 6 robot 3: 1.4 of 2.3 s, each relinearising about 1 000 of 3 000 poses;
        Plaza1 10.4 of 14 s in ``ISAM2.update``); halving them cut the CPU time by 11–29 %
        and kept the online ATE within 3 % of an every-step iSAM2 on MRCLAM robots 1–5
        (the importer's noise and the fitted one), arena seeds 1–20, Victoria Park and
        Plaza1 (worst 1.023×); every 40th lost 3.5 % on MRCLAM robot 4
        (docs/performance.md). While the smoother associates observations without an id
        (``associate``), the check also runs on every
        :data:`ASSOCIATION_RELINEARIZE_SKIP`-th update, as before: its pairing decisions
        read the map, and every 20th moved MRCLAM Dataset 6 with barcodes withheld to a
        different association (robot 1's ATE 0.589 → 2.85 m, the median ratio to the run with
        barcodes 1.19 → 1.26; with the every-10th check 1.06: the pairings are that
        sensitive, docs/estimators.md). Very aggressive settings are where DESIGN.md
        saw IndeterminantLinearSystem failures on real data; those are recovered from
        (:mod:`fgslam.smoother.recovery`).
    relinearize_max_variables:
        On each check, relinearise at most this many variables: those whose pending step
        exceeds the threshold by the largest factor; the rest wait for a later check or for
        :meth:`finish` (:mod:`fgslam.smoother.relinearisation`; GTSAM's
        ``ISAM2UpdateParams.noRelinKeys``). Default 300; None relinearises every variable
        past the threshold, as GTSAM does. Not applied while observations without an id are
        associated (``associate``: the pairings are that sensitive, above).

        Why, measured (docs/performance.md, ``scripts/bench_relinearisation.py``, same
        process, one BLAS thread): an uncapped check relinearised up to 1 000 poses on MRCLAM
        and re-eliminated up to 12 000 variables on Plaza1, 40–330 ms in one update. With 300
        the slowest update fell 1.3–4.5× (Plaza1 326 → 73 ms, Victoria Park 121 → 28 ms,
        MRCLAM Dataset 6 robots 10–68 ms), the CPU time of the whole run by 6–32 %, and the
        online ATE stayed within 3 % of an every-step iSAM2 on MRCLAM robots 1–5 (the
        importer's noise and the fitted one), Victoria Park, Plaza1 and arena seeds 1–20
        (worst 1.024× and 1.021×, as without the cap); the final estimate is still the batch
        optimum. 200 moved MRCLAM robot 1 to 1.026×; 100 on every 10th update lost 6.4 % on
        robot 4, and 100 on every 20th 5.6 % on Victoria Park. The cap bounds
        the variables relinearised, not the variables re-eliminated: a landmark seen from
        every pose is in every pose's clique, so relinearising it re-eliminates most of the
        tree (Plaza1's four beacons: up to 2 200 variables in one check).
    final_updates:
        Extra plain ``isam.update()`` calls (no new factors) at the start of
        :meth:`finish`, letting a pending relinearisation check happen. Cheap; the full
        Gauss–Newton steps of ``final_iterations`` that follow do the real work.
    max_retries:
        How many further updates a withheld observation is retried with before it is
        dropped (see :mod:`fgslam.smoother.pending`).
    update_every, update_on, max_held_steps, update_observations, update_observations_min_steps, update_tail, update_tail_min_steps:
        When steps go to iSAM2: by information rather than by the clock. Steps are held
        until they carry ``update_observations`` observation factors (default 20; None
        turns this rule off) and ``update_observations_min_steps`` steps (default 10: where
        landmarks are seen at several a step, no more updates than one per 10 steps), or
        until ``update_every`` steps wait (default 50), then go to iSAM2 in one update. A step goes at once when it sees a landmark iSAM2 does not hold
        yet, or an observation the correction rejects (χ² tail below 0.001). An
        observation whose innovation against the online correction's prediction has a χ²
        tail probability below ``update_tail`` (default 0.02: the map iSAM2 last gave
        disagrees with what the robot sees; 0 turns this off) brings the update forward to
        the first step with at least ``update_tail_min_steps`` (default 5) held. With
        ``update_on="observations"`` only a step with observations triggers the
        ``update_every`` rule; ``max_held_steps`` bounds the wait; ``update_every=1``
        updates at every step. While steps are held, :meth:`current_pose` is the last
        iSAM2 estimate composed with the odometry since, corrected by ``online_correction``.
        A run of steps without observations gives iSAM2 nothing the odometry does not, so
        holding it costs the online pose nothing; the correction carries the pose
        through observations of mapped landmarks.
    online_correction:
        True (default): between updates, a pose-only EKF corrects the online pose with the
        observations of landmarks iSAM2 holds, their last iSAM2 estimates taken as known
        (:mod:`fgslam.smoother.correction`); new poses are seeded from it. False: dead
        reckoning from the last update.

        Why these triggers and the correction, measured (docs/performance.md,
        scripts/bench_online.py, against an iSAM2 that updates and checks relinearisation at
        every step): the final estimate is unchanged (the same Gauss–Newton ending); held
        without the correction the online ATE lost up to 2.7 % on the arena at 10 steps and
        5.9 % on Victoria Park at 50; with it, a fixed 50 steps still lost 4–7 % on MRCLAM
        robot 1 (least squares), which the observation count and the innovation trigger
        keep within 3 % on every log measured (worst 1.023× on MRCLAM robot 4) at 20–80 %
        fewer updates than the previous default (every 10 steps; Victoria Park 817 → 397,
        Plaza1 1 320 → 269). Range-only observations (Plaza) are corrected too.
    final_iterations, final_tolerance:
        In :meth:`finish`, after ``final_updates``: up to this many Gauss–Newton steps on
        the whole graph, until the error drops by less than ``final_tolerance``
        (relative). Each is an update with ``force_relinearize`` and ``forceFullSolve``:
        iSAM2 then solves the exact delta and relinearises *every* variable (measured:
        without ``forceFullSolve`` only variables whose wildfire delta exceeds the
        threshold move, and on Victoria Park it stalled 34 % above the optimum). The final estimate is then read with
        ``calculateBestEstimate`` (a full back-substitution; ``calculateEstimate`` skips
        changes below the wildfire threshold).
    partial_relinearization_check, cache_linearized_factors, factorization, wildfire_threshold:
        Passed to GTSAM's ``ISAM2Params`` (``factorization`` is "cholesky" or "qr").
        ``wildfire_threshold`` (default 1.0; GTSAM's 0.001) stops the back-substitution
        where a clique's solution changed by less than this, so reading the newest pose
        after an update (the top of the tree) no longer back-substitutes the whole tree;
        that read was a third of the default's time on Victoria Park and 40 % of Plaza's.
        The deltas deeper in the tree then lag, so the relinearisation check sees fewer
        variables move; the online ATE was unchanged on every log measured
        (docs/performance.md), and :meth:`finish` and the whole-estimate queries
        (:meth:`trajectory`, :meth:`landmarks`, …) back-substitute fully
        (``calculateBestEstimate``).
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
        relinearize_threshold: float | tuple[float, float] = 0.01,
        relinearize_skip: int = 20,
        relinearize_max_variables: int | None = 300,
        update_every: int = 50,
        update_on: str = "any",
        max_held_steps: int = 50,
        final_updates: int = 2,
        final_iterations: int = 10,
        final_tolerance: float = 1e-4,
        partial_relinearization_check: bool = False,
        cache_linearized_factors: bool = True,
        factorization: str = "cholesky",
        wildfire_threshold: float = 1.0,
        max_retries: int = 3,
        robust: str | None = None,
        robust_k: float | None = None,
        tags: bool = False,
        keyframes: bool = False,
        max_keyframe_gap: int = 50,
        online_correction: bool = True,
        associate: bool = True,
        update_observations: int | None = 20,
        update_tail: float = 0.02,
        update_tail_min_steps: int = 5,
        update_observations_min_steps: int = 10,
    ):
        threshold = _relinearize_threshold(relinearize_threshold)
        if relinearize_skip < 1 or final_updates < 0 or max_retries < 0:
            raise FgslamError(
                "Isam2Smoother: need relinearize_skip >= 1, final_updates >= 0 and max_retries >= 0"
            )
        if update_every < 1 or max_held_steps < 1 or final_iterations < 0 or not final_tolerance >= 0:
            raise FgslamError(
                "Isam2Smoother: need update_every >= 1, max_held_steps >= 1, final_iterations >= 0 "
                "and final_tolerance >= 0"
            )
        if update_on not in ("any", "observations"):
            raise FgslamError(f"Isam2Smoother: update_on must be 'any' or 'observations', got {update_on!r}")
        if factorization.lower() not in ("cholesky", "qr"):
            raise FgslamError(f"Isam2Smoother: factorization must be 'cholesky' or 'qr', got {factorization!r}")
        if not wildfire_threshold >= 0:
            raise FgslamError("Isam2Smoother: wildfire_threshold must be >= 0")
        self.update_every = int(update_every)
        self.update_observations = None if update_observations is None else int(update_observations)
        self.update_tail = float(update_tail)
        self.update_tail_min_steps = int(update_tail_min_steps)
        self.update_observations_min_steps = int(update_observations_min_steps)
        self.update_on = update_on
        self.max_held_steps = int(max_held_steps)
        self.final_iterations = int(final_iterations)
        self.final_tolerance = float(final_tolerance)
        self.partial_relinearization_check = bool(partial_relinearization_check)
        self.cache_linearized_factors = bool(cache_linearized_factors)
        self.factorization = factorization.lower()
        self.wildfire_threshold = float(wildfire_threshold)
        self.updates = 0  # iSAM2 updates run by step()/flushes (not counting finish or rebuilds)
        self.final_iterations_run = 0  # forced full relinearisations finish() ran
        if robust is None:
            if robust_k is not None:
                raise FgslamError("Isam2Smoother: robust_k needs a robust kernel (robust='huber' or 'cauchy')")
            self._robust = None
        else:
            self._robust = robust_estimator(robust, robust_k)
        self.tags = bool(tags)
        if max_keyframe_gap < 1:
            raise FgslamError("Isam2Smoother: need max_keyframe_gap >= 1")
        self.keyframes = bool(keyframes)
        self.max_keyframe_gap = int(max_keyframe_gap)
        self.name = "-".join(["isam2"] + (["tags"] if self.tags else []) + ([robust] if robust else []))
        self.robust = robust
        self.robust_k = None if robust is None else (DEFAULT_ROBUST_K[robust] if robust_k is None else float(robust_k))
        self.header = header
        self.relinearize_threshold = threshold
        self.relinearize_skip = int(relinearize_skip)
        if relinearize_max_variables is not None and relinearize_max_variables < 0:
            raise FgslamError("Isam2Smoother: relinearize_max_variables must be None or >= 0")
        self.relinearize_max_variables = None if relinearize_max_variables is None else int(relinearize_max_variables)
        self.final_updates = int(final_updates)
        self.max_retries = int(max_retries)

        self.skipped_unknown_observations = 0
        self.update_failures = 0
        self.last_failure: str | None = None

        self._factors = FactorBuilder(self._robust)
        self._isam = gtsam.ISAM2(self._params())
        self._isam_updates = 0  # updates given to this ISAM2 (GTSAM counts them for relinearize_skip)
        self._unlabelled = False  # observations without an id seen: the smoother associates them
        self._graph = gtsam.NonlinearFactorGraph()  # every factor accepted into iSAM2
        self._initial = gtsam.Values()  # the initial guess of every variable in iSAM2
        self._landmarks = LandmarkRegistry()
        self._pending = PendingObservations(self.max_retries, self.PENDING_GATE, self.MAX_UNCONFIRMED)
        self.range_rule = DelayedInitRule()
        self._ranges = RangeOnlyLandmarks(self.range_rule)
        self._held = HeldSteps()  # steps not yet given to iSAM2 (update_every / update_on)
        self._keyframes = Keyframes(self.keyframes, self.max_keyframe_gap)
        self._online = OnlinePose()  # the newest pose, for current_pose/current_covariance
        self.online_correction = bool(online_correction)
        self._corrector = (
            PoseCorrector(header.start_pose, np.diag(np.square(np.asarray(header.start_sigma, dtype=float))))
            if self.online_correction else None
        )
        self._landmark_xy: dict[int, tuple[float, float]] = {}  # iSAM2's landmark estimates at its last update
        self._num_poses = 0
        self._estimate_cache: gtsam.Values | None = None
        # id-less observations: associated (fgslam/smoother/association.py) or skipped
        self.associate = bool(associate)
        self.redecide = True  # re-decide the id-less pairings against the settled map at the end (_redecide)
        self._association = SmootherAssociation()

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
            if self.keyframes:
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
            self._isam = gtsam.ISAM2(self._params())
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
        if k == 0 or self._held.steps >= self.max_held_steps or self._held.urgent:
            return True
        if self._held.unlikely and self._held.steps >= self.update_tail_min_steps:
            return True
        if (self.update_observations and self._held.uncorrected
                and self._held.steps >= self.update_observations_min_steps):
            return True
        if (self.update_observations and self._held.observations >= self.update_observations
                and self._held.steps >= self.update_observations_min_steps):
            return True
        if self._held.steps < self.update_every:
            return False
        return self.update_on == "any" or self._held.observed

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
                if corrector.last_tail < self.update_tail:
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
        relative decrease is below ``final_tolerance``."""
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
        for _ in range(self.final_updates):
            try:
                self._isam_update()
            except RuntimeError as exc:  # relinearisation hit a singular system: rebuild
                self._recover(exc, gtsam.NonlinearFactorGraph(), gtsam.Values(), [])
        if self.final_iterations:
            previous = float(self._graph.error(self._isam.calculateBestEstimate()))
            for _ in range(self.final_iterations):
                # One Gauss–Newton step on the whole graph: with forceFullSolve the forced
                # relinearisation takes the exact delta and relinearises every variable.
                update_params = gtsam.ISAM2UpdateParams()
                update_params.force_relinearize = True
                update_params.forceFullSolve = True
                try:
                    self._isam_updates += 1
                    self._isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), update_params)
                except RuntimeError as exc:
                    self._recover(exc, gtsam.NonlinearFactorGraph(), gtsam.Values(), [])
                    break
                self.final_iterations_run += 1
                current = float(self._graph.error(self._isam.calculateBestEstimate()))
                if not previous - current > self.final_tolerance * current:
                    break
                previous = current
        # The full back-substitution: calculateEstimate() skips delta changes below the
        # wildfire threshold, which on Victoria Park left χ²/2 25 % above the optimum.
        self._estimate_cache = self._isam.calculateBestEstimate()
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
        return self._online.covariance(self._isam, frame)

    def landmark_covariances(self) -> dict[int, np.ndarray]:
        """Landmark id → 2×2 marginal covariance of its (x, y) in the world frame
        (``isam.marginalCovariance``; for a tag, the position block of its Pose2 marginal
        rotated from the tag's frame). Flushes held steps."""
        self._flush()
        return landmark_covariances(self._isam, self._landmarks.ids, self._landmarks.tag_ids)

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
        if not self.keyframes:
            return gtsam.NonlinearFactorGraph(self._graph)
        if not self.keyframes:
            return gtsam.NonlinearFactorGraph(self._graph)
        return self._keyframes.expanded(self._graph)

    def initial_values(self) -> gtsam.Values:
        """A copy of the initial guess of every variable of :meth:`graph` (held steps flushed
        first; with keyframes, poses between keyframes dead-reckoned from the keyframe's)."""
        self._flush()
        values = gtsam.Values(self._initial)
        if self.keyframes:
            self._keyframes.insert_between(values)
        return values

    def estimate(self) -> gtsam.Values:
        """A copy of iSAM2's current estimate of every variable of :meth:`graph` (one full
        back-substitution, ``calculateBestEstimate``; with keyframes, the poses between them as in :meth:`trajectory`)."""
        values = gtsam.Values(self._estimate())
        if self.keyframes:
            trajectory = self.trajectory_of(values)
            keyframes = set(self._keyframes.indices)
            for i in range(self._num_poses):
                if i not in keyframes:
                    values.insert(X(i), gtsam.Pose2(*trajectory[i]))
        return values

    def error(self) -> float:
        """:meth:`graph`'s error at :meth:`estimate` (χ²/2, like ``graph.error``)."""
        if self.keyframes:
            return float(self.graph().error(self.estimate()))
        return float(self._graph.error(self._estimate()))

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

    def _params(self) -> gtsam.ISAM2Params:
        params = gtsam.ISAM2Params()
        if isinstance(self.relinearize_threshold, tuple):
            metres, radians = self.relinearize_threshold
            per_type = gtsam.ISAM2ThresholdMap()
            per_type.insert(("x", np.array([metres, metres, radians])))  # Pose2 tangent: x, y, theta
            per_type.insert(("l", np.array([metres, metres])))
            per_type.insert(("t", np.array([metres, metres, radians])))
            per_type.insert(("h", np.array([metres])))
            params.setRelinearizeThreshold(per_type)
        else:
            params.setRelinearizeThreshold(self.relinearize_threshold)
        params.relinearizeSkip = self.relinearize_skip
        params.enablePartialRelinearizationCheck = self.partial_relinearization_check
        params.cacheLinearizedFactors = self.cache_linearized_factors
        params.setFactorization("QR" if self.factorization == "qr" else "CHOLESKY")
        gauss_newton = gtsam.ISAM2GaussNewtonParams()
        gauss_newton.setWildfireThreshold(self.wildfire_threshold)
        params.setOptimizationParams(gauss_newton)
        return params

    def _estimate(self) -> gtsam.Values:
        self._flush()
        if self._estimate_cache is None:
            # the full back-substitution: with the default wildfire threshold (1.0)
            # calculateEstimate() would leave the deltas deep in the tree stale
            self._estimate_cache = self._isam.calculateBestEstimate()
        return self._estimate_cache

    def _update_with_recovery(self, core, core_values, entries: list[PendingObservation]) -> None:
        self._estimate_cache = None
        factors, values = update_batch(core, core_values, entries, self._landmarks.known)
        try:
            self._isam_update(factors, values)
        except RuntimeError as exc:
            self._recover(exc, core, core_values, entries)
            return
        self._accept(factors, values)

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
        elif (self.relinearize_max_variables is not None and not self._unlabelled
              and self._isam_updates % self.relinearize_skip == 0):  # GTSAM's own check, capped
            update_params = gtsam.ISAM2UpdateParams()
            held = held_back(self._isam, self.relinearize_threshold, self.relinearize_max_variables)
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

    def _recover(self, exc: RuntimeError, core, core_values, entries: list[PendingObservation]) -> None:
        """Replace the broken iSAM2 by a fresh one holding everything but withheld observations
        (:func:`fgslam.smoother.recovery.rebuild`)."""
        self.update_failures += 1
        rebuilt = rebuild(exc, self._isam, self._params(), self._graph, self._initial, core, core_values, entries,
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


def _relinearize_threshold(value) -> float | tuple[float, float]:
    """Validate ``relinearize_threshold``: one number, or a (metres, radians) pair."""
    if isinstance(value, (tuple, list)):
        if len(value) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in value):
            raise FgslamError(
                f"Isam2Smoother: relinearize_threshold pair must be (metres >= 0, radians >= 0), got {value!r}"
            )
        return (float(value[0]), float(value[1]))
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise FgslamError(f"Isam2Smoother: relinearize_threshold must be a number >= 0 or a pair, got {value!r}")
    return float(value)
