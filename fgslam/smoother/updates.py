"""Giving held steps to iSAM2: :class:`Isam2Updates`, the part of
:class:`~fgslam.smoother.isam2.Isam2Smoother` that decides when an update is due, runs it
(with its relinearisation check, :mod:`~fgslam.smoother.relinearisation`), recovers from a
failed one (:mod:`~fgslam.smoother.recovery`) and slides the window
(:mod:`~fgslam.smoother.window`).

A mixin: it works on the state :class:`~fgslam.smoother.isam2.Isam2Smoother` sets up in its
``__init__`` (the iSAM2 object, the graph and initial values kept, the held steps).
"""

from __future__ import annotations

import gtsam

from fgslam.smoother.factors import X0, PendingObservation, update_batch
from fgslam.smoother.recovery import rebuild
from slamio.errors import FgslamError


#: While observations without an id are associated, check relinearisation on every this
#: many updates (``relinearize_skip``'s own schedule continues alongside).
ASSOCIATION_RELINEARIZE_SKIP = 10


class Isam2Updates:
    """When held steps go to iSAM2 and how: one update, recovery, the window's slide."""

    def _due(self, k: int) -> bool:
        """Whether the held steps go to iSAM2 now (see ``update_every`` / ``update_on``)."""
        held, settings = self._held, self.settings  # (asked at every step)
        steps = held.steps
        if k == 0 or steps >= settings.max_held_steps or held.urgent:
            return True
        if held.unlikely and steps >= settings.update_tail_min_steps:
            return True
        if (settings.update_observations and held.uncorrected
                and steps >= settings.update_observations_min_steps):
            return True
        if (settings.update_observations and held.observations >= settings.update_observations
                and steps >= settings.update_observations_min_steps):
            return True
        if steps < settings.update_every:
            return False
        return settings.update_on == "any" or held.observed

    def _flush(self) -> None:
        """Give every held step to iSAM2 in one update; read back the newest pose."""
        if self._held.steps == 0:
            return
        core, core_values, fresh, ranges = self._held.take(self._factors)
        if self._robust is not None:
            fresh = self._pending.confirm_first_sightings(fresh, self._landmarks.known)
        entries = self._pending.screen(fresh, self._isam, self._landmarks) + fresh + ranges
        self._update_with_recovery(core, core_values, entries)
        self.updates += 1
        if self.associate:
            self._association.entered(self._landmarks.known)
        # the newest pose in iSAM2 is the last keyframe; only the open chain's steps follow it
        last = self._keyframes.last
        anchor = self._isam.calculateEstimatePose2(X0 + last)
        pose = self._keyframes.latest_pose(anchor)
        self._online.updated(pose, last, len(self._keyframes.open.links), anchor)
        self._landmark_xy.clear()
        if self._corrector is not None:
            self._corrector.reset((pose.x(), pose.y(), pose.theta()))

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
        fresh = self._new_isam()
        try:
            fresh.update(kept.factors, kept.values)
        except RuntimeError as exc:  # an indeterminate system: go on with every pose, as without a window
            self.update_failures += 1
            self.last_failure = str(exc)
            self._window.stopped = True
            return
        self._window.commit(kept, estimate)
        self._isam, self._isam_updates = fresh, 1  # its first update, counted as GTSAM counts it
        self._online.forget_marginal()
        self._landmark_xy.clear()

    def _isam_update(self, factors: gtsam.NonlinearFactorGraph | None = None,
                     values: gtsam.Values | None = None) -> None:
        """One ``ISAM2.update`` (none: no new factors); with observations being associated, a
        relinearisation check on every :data:`ASSOCIATION_RELINEARIZE_SKIP`-th (GTSAM checks
        on the n-th update of an ``ISAM2`` when n is a multiple of ``relinearize_skip``);
        otherwise GTSAM's own check relinearises at most ``relinearize_max_variables``."""
        self._isam_updates += 1
        capped = self.settings.relinearize_max_variables is not None and not self._unlabelled
        if self._unlabelled and self._isam_updates % ASSOCIATION_RELINEARIZE_SKIP == 0:
            update_params = gtsam.ISAM2UpdateParams()
            update_params.force_relinearize = True  # forces the check, not the relinearisation
            self._isam.update(factors or gtsam.NonlinearFactorGraph(), values or gtsam.Values(), update_params)
        elif capped and self._isam_updates % self.settings.relinearize_skip == 0:  # GTSAM's own check, capped
            update_params = gtsam.ISAM2UpdateParams()
            held = self._cap.held_back(self._isam)
            if held.size():
                update_params.noRelinKeys = held
            self._isam.update(factors or gtsam.NonlinearFactorGraph(), values or gtsam.Values(), update_params)
        elif factors is None:
            self._isam.update()
        else:
            self._isam.update(factors, values)
        if capped and values is not None:
            self._cap.entered(self._isam, values)

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
        self._isam = self._new_isam(rebuilt.isam)
        # the rebuild's own update counts: GTSAM checks on its n-th update when n is a multiple
        # of relinearize_skip, and the cap must be computed for those (counted from 0 here,
        # every check after a rebuild ran uncapped: MRCLAM Dataset 6 robot 5, two rebuilds,
        # then checks of up to 2 604 variables; docs/performance.md)
        self._isam_updates = 1
        self._accept(rebuilt.factors, rebuilt.values)
        self._pending.withhold(rebuilt.withheld)
