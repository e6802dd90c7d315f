"""The smoother's settings: when it updates iSAM2, how it relinearises, how it ends.

:class:`Isam2Settings` holds every knob of :class:`~fgslam.smoother.isam2.Isam2Smoother`
that changes *how* the same problem is solved (the model itself — robust kernels, tags,
association — is the smoother's own arguments). Each default is documented with the
measurement that chose it; docs/performance.md has the tables. The smoother takes these as
keyword arguments (``Isam2Smoother(header, update_every=1)``), and the ``isam2-fast``
preset is one dict of them (:data:`fgslam.smoother.policy.FAST_SETTINGS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np

from fgslam.smoother.relinearisation import CHOICES
from slamio.errors import FgslamError


@dataclass(frozen=True)
class Isam2Settings:
    """How :class:`~fgslam.smoother.isam2.Isam2Smoother` solves its graph (validated on creation).

    Fields
    ------
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
        :data:`~fgslam.smoother.updates.ASSOCIATION_RELINEARIZE_SKIP`-th update, as before: its pairing decisions
        read the map, and every 20th moved MRCLAM Dataset 6 with barcodes withheld to a
        different association (robot 1's ATE 0.589 → 2.85 m, the median ratio to the run with
        barcodes 1.19 → 1.26; with the every-10th check 1.06: the pairings are that
        sensitive, docs/estimators.md). Very aggressive settings are where GTSAM
        raised IndeterminantLinearSystem failures on real data; those are recovered from
        (:mod:`fgslam.smoother.recovery`).
    relinearize_max_variables:
        On each check, relinearise at most this many variables: those whose pending step
        exceeds the threshold by the largest factor; the rest wait for a later check or for
        :meth:`.Isam2Smoother.finish` (:mod:`fgslam.smoother.relinearisation`; GTSAM's
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
    relinearize_choice:
        Which variables past the threshold a capped check relinearises: ``"block"`` (default)
        those within the ``relinearize_max_variables`` consecutive variables, in the order
        they entered iSAM2, whose ratios (pending step over threshold) sum highest;
        ``"ratio"`` the ``relinearize_max_variables`` with the largest ratios, wherever they
        are (the first rule). GTSAM re-eliminates every clique from a relinearised variable
        up to the root; neighbours in entry order share that path, variables chosen by ratio
        alone do not.

        Why, measured (docs/performance.md, "The long steps, taken apart";
        ``scripts/bench_long_steps.py``, CPU time at a load of 6–13): the longest step of a
        run fell on Plaza1 from 109–136 to 39–52 ms (its checks re-eliminated 400–750
        variables where they re-eliminated up to 2 281), on Victoria Park from 42–44 to
        29–36 ms, on MRCLAM Dataset 6 robots 1–4 from 22–39 to 11–38 ms and on the
        2 000-landmark grid from 761 to 226 ms, with the online ATE within 2 % of the ratio
        rule's (better on Plaza1 and robots 1 and 3) and the final χ² at the batch optimum.
        A block of 150 was shorter still but lost 8.8 % online on robot 2.
    final_updates:
        Extra plain ``isam.update()`` calls (no new factors) at the start of
        :meth:`.Isam2Smoother.finish`, letting a pending relinearisation check happen. Cheap; the full
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
        updates at every step. While steps are held, :meth:`.Isam2Smoother.current_pose` is the last
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
        In :meth:`.Isam2Smoother.finish`, after ``final_updates``: up to this many Gauss–Newton steps on
        the whole graph, until the error drops by less than ``final_tolerance``
        (relative), started from iSAM2's estimate read with ``calculateBestEstimate`` (a
        full back-substitution; ``calculateEstimate`` skips changes below the wildfire
        threshold). Each is a batch step (:func:`~fgslam.smoother.batch.gauss_newton_steps`):
        every factor relinearised, the whole system solved. They were iSAM2 updates with
        ``force_relinearize`` and ``forceFullSolve`` (the same step: measured, without
        ``forceFullSolve`` only variables whose wildfire delta exceeds the threshold move,
        and on Victoria Park it stalled 34 % above the optimum); the batch step costs
        about half as much and ends at the same χ² (docs/performance.md).
    partial_relinearization_check, cache_linearized_factors, factorization, wildfire_threshold:
        Passed to GTSAM's ``ISAM2Params`` (``factorization`` is "cholesky" or "qr").
        ``wildfire_threshold`` (default 1.0; GTSAM's 0.001) stops the back-substitution
        where a clique's solution changed by less than this, so reading the newest pose
        after an update (the top of the tree) no longer back-substitutes the whole tree;
        that read was a third of the default's time on Victoria Park and 40 % of Plaza's.
        The deltas deeper in the tree then lag, so the relinearisation check sees fewer
        variables move; the online ATE was unchanged on every log measured
        (docs/performance.md), and :meth:`.Isam2Smoother.finish` and the whole-estimate queries
        (:meth:`.Isam2Smoother.trajectory`, :meth:`.Isam2Smoother.landmarks`, …) back-substitute fully
        (``calculateBestEstimate``).

    keyframes, max_keyframe_gap:
        ``keyframes=True``: only steps with observations (and every ``max_keyframe_gap``-th
        step, default 50) get a pose variable; the odometry in between is folded into one
        compound factor and those poses are rebuilt on demand
        (:class:`~fgslam.smoother.policy.Keyframes`). Off by default: it is the
        ``isam2-fast`` preset's, which loses online accuracy on real data
        (docs/performance.md).
    window_poses:
        None (default): iSAM2 holds every pose. A number N: a sliding window
        (:mod:`fgslam.smoother.window`): once iSAM2 holds more than 2N poses, all but the
        newest N are marginalised into a Gaussian on what they shared with the window, and a
        fresh iSAM2 goes on with the rest, so a step costs the same however long the run.
        :meth:`.Isam2Smoother.finish` still solves the whole graph (every factor is kept),
        so the final estimate does not depend on it. Refused with observations without an id
        (pairing them reads every pose). ``fgslam live`` uses 200
        (:data:`fgslam.live.run.LIVE_WINDOW_POSES`).

        Why not by default, measured (docs/performance.md, ``scripts/bench_window.py``):
        on a long drive it bounds the steps (the live arena, 40 laps: the p99 step 3.7 →
        27.9 ms from the first quarter to the last with every pose, 0.8–0.9 ms with 200;
        Plaza1's 1.3 → 8.8 ms, 1.0–1.3 ms with 500). But the marginal keeps the linearisation
        point of the landmarks it touches, and the online estimate then moves by more than
        the 3 % the default keeps to: MRCLAM Dataset 6 robots −25 … +21 % (either way), Plaza1
        +27 % with 500; and on Victoria Park, whose 151 landmarks the marginal couples into one
        dense block, the whole run got slower.
    """

    relinearize_threshold: float | tuple[float, float] = 0.01
    relinearize_skip: int = 20
    relinearize_max_variables: int | None = 300
    relinearize_choice: str = "block"
    update_every: int = 50
    update_on: str = "any"
    max_held_steps: int = 50
    update_observations: int | None = 20
    update_observations_min_steps: int = 10
    update_tail: float = 0.02
    update_tail_min_steps: int = 5
    online_correction: bool = True
    final_updates: int = 2
    final_iterations: int = 10
    final_tolerance: float = 1e-4
    partial_relinearization_check: bool = False
    cache_linearized_factors: bool = True
    factorization: str = "cholesky"
    wildfire_threshold: float = 1.0
    max_retries: int = 3
    keyframes: bool = False
    max_keyframe_gap: int = 50
    window_poses: int | None = None

    def __post_init__(self):
        if self.relinearize_skip < 1 or self.final_updates < 0 or self.max_retries < 0:
            raise FgslamError(
                "Isam2Smoother: need relinearize_skip >= 1, final_updates >= 0 and max_retries >= 0"
            )
        if (self.update_every < 1 or self.max_held_steps < 1 or self.final_iterations < 0
                or not self.final_tolerance >= 0):
            raise FgslamError(
                "Isam2Smoother: need update_every >= 1, max_held_steps >= 1, final_iterations >= 0 "
                "and final_tolerance >= 0"
            )
        if self.update_on not in ("any", "observations"):
            raise FgslamError(f"Isam2Smoother: update_on must be 'any' or 'observations', got {self.update_on!r}")
        if self.factorization.lower() not in ("cholesky", "qr"):
            raise FgslamError(
                f"Isam2Smoother: factorization must be 'cholesky' or 'qr', got {self.factorization!r}")
        if not self.wildfire_threshold >= 0:
            raise FgslamError("Isam2Smoother: wildfire_threshold must be >= 0")
        if self.max_keyframe_gap < 1:
            raise FgslamError("Isam2Smoother: need max_keyframe_gap >= 1")
        if self.relinearize_max_variables is not None and self.relinearize_max_variables < 0:
            raise FgslamError("Isam2Smoother: relinearize_max_variables must be None or >= 0")
        if self.relinearize_choice not in CHOICES:
            raise FgslamError(f"Isam2Smoother: relinearize_choice must be one of {CHOICES}, got {self.relinearize_choice!r}")
        if self.window_poses is not None and self.window_poses < 2:
            raise FgslamError(f"Isam2Smoother: window_poses must be None or >= 2, got {self.window_poses!r}")
        normalised = {
            "relinearize_threshold": _relinearize_threshold(self.relinearize_threshold),
            "factorization": self.factorization.lower(),
            "update_tail": float(self.update_tail),
            "final_tolerance": float(self.final_tolerance),
            "wildfire_threshold": float(self.wildfire_threshold),
            "update_observations": None if self.update_observations is None else int(self.update_observations),
            "relinearize_max_variables": (None if self.relinearize_max_variables is None
                                          else int(self.relinearize_max_variables)),
            "window_poses": None if self.window_poses is None else int(self.window_poses),
        }
        for name in ("relinearize_skip", "update_every", "max_held_steps", "update_observations_min_steps",
                     "update_tail_min_steps", "final_updates", "final_iterations", "max_retries",
                     "max_keyframe_gap"):
            normalised[name] = int(getattr(self, name))
        for name in ("online_correction", "partial_relinearization_check", "cache_linearized_factors",
                     "keyframes"):
            normalised[name] = bool(getattr(self, name))
        for name, value in normalised.items():
            object.__setattr__(self, name, value)  # frozen: set once, here

    def isam2_params(self) -> gtsam.ISAM2Params:
        """GTSAM's ``ISAM2Params`` for these settings (a fresh object each call)."""
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
