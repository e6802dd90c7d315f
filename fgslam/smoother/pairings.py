"""The smoother's side of pairing observations without an id: :class:`IdlessPairings`, the
part of :class:`~fgslam.smoother.isam2.Isam2Smoother` that hands the id-less observations of
a step to :class:`~fgslam.smoother.association.SmootherAssociation` (which decides), holds
the factors of the pairings it chose, re-decides them against the settled map at the end and
reports what became of them.

A mixin: it works on the state :class:`~fgslam.smoother.isam2.Isam2Smoother` sets up in its
``__init__``.
"""

from __future__ import annotations

from dataclasses import replace

import gtsam
from gtsam.symbol_shorthand import L, X

from fgslam.smoother.online import world_joint_marginal
from fgslam.smoother.chain import OdometryChain
from slamio.errors import FgslamError
from slamio.log import Observation


class IdlessPairings:
    """Pairing id-less observations with the landmarks iSAM2 holds, and re-deciding them."""

    def _point_landmarks(self) -> list[int]:
        """The point landmarks iSAM2 holds (tags excluded): what association pairs with."""
        return [i for i in self._landmarks.ids if i not in self._landmarks.tag_ids]

    def _marginal_at_pose(self, p: int, pose: gtsam.Pose2, ids):
        """iSAM2's joint marginal of pose ``p`` (at ``pose``) and landmarks ``ids``, in the world
        frame (:func:`~fgslam.smoother.online.world_joint_marginal`)."""
        return world_joint_marginal(self._isam, OdometryChain(p), pose, ids)

    def _associate(self, k: int, seed: gtsam.Pose2, observations) -> list[Observation]:
        """The step's observations with the id-less ones given the id association chose
        (:mod:`fgslam.smoother.association`); those it did not place are left out. First
        sightings confirmed now are held too, at their own poses."""
        if self._association.retry:  # listing the map's landmarks is O(map): only when something is due
            for s, lid in self._association.retry_rejected(k, self._isam, self._marginal_at_pose,
                                                           self._point_landmarks()):
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
            k, seed, unknown, self._isam, lambda ids: world_joint_marginal(self._isam, since, seed, ids),
            self._point_landmarks())
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
            self._isam = self._new_isam()
            self._isam_updates = 0
            self._isam_update(self._graph, before)
            return False
        self._graph = graph
        self._association.apply(changes)
        self._estimate_cache = None
        return True

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

    def _settle_pairings(self) -> None:
        """At :meth:`finish`: the deferred pairing decisions, against the whole map, then up to
        ``REDECIDE_PASSES`` re-decisions (:meth:`_redecide`), each against the map the one before left."""
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
