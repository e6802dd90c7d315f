"""Data association scored against truth: which estimator landmark stands for which true one.

For estimators that associate observations themselves: :func:`score_associations` scores a
run's choices against the log's true landmark ids, and :func:`relabel_landmarks` re-keys its
map by the true ids so that its map error can be computed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping


@dataclass(frozen=True)
class AssociationScore:
    """How an estimator associated observations with landmarks, scored against truth.

    Attributes:
        observations: observations scored (those whose true landmark is known).
        correct: observations used as the right landmark (see :func:`score_associations`).
        rejected: observations the estimator did not use (gated out or left unpaired).
        identity: estimator's landmark key → the true id it stands for.
        duplicate_keys: keys created for a true landmark that was already mapped.
    """

    observations: int
    correct: int
    rejected: int
    identity: dict[int, int]
    duplicate_keys: frozenset[int]

    @property
    def rate(self) -> float:
        return self.correct / self.observations if self.observations else math.nan

    @property
    def landmarks_created(self) -> int:
        return len(self.identity)

    @property
    def wrong(self) -> int:
        """Observations used as the wrong landmark (or as a duplicate of a mapped one)."""
        return self.observations - self.correct - self.rejected


def score_associations(true_ids, keys) -> AssociationScore:
    """Score one run's data association.

    ``true_ids[i]`` is the true landmark of observation ``i`` (None when unknown: not
    scored) and ``keys[i]`` the estimator's landmark key it was used as (None: rejected),
    in the order the observations were made. A key stands for the true landmark most of its
    scored observations saw (ties: the one seen first) — not merely the first one, so a
    landmark whose first sighting was a misdetection that happened to fall near it is still
    the landmark it maps. When several keys stand for the same true landmark, the one with
    the most observations of it (ties: the first created) is that landmark and the others
    are duplicates, every use of which is wrong. An observation is correct when its key
    stands for its true landmark and is not a duplicate; a rejected observation is not correct.
    """
    votes: dict[int, dict[int, int]] = {}  # key → true id → observations (insertion order = first seen)
    for true_id, key in zip(true_ids, keys, strict=True):
        if key is not None and true_id is not None:
            counts = votes.setdefault(key, {})
            counts[true_id] = counts.get(true_id, 0) + 1
    identity = {key: max(counts, key=counts.get) for key, counts in votes.items()}  # max keeps the first of ties
    primary: dict[int, int] = {}  # true id → its key
    for key, true_id in identity.items():  # keys in order of first use
        best = primary.get(true_id)
        if best is None or votes[key][true_id] > votes[best][true_id]:
            primary[true_id] = key
    duplicates = {key for key, true_id in identity.items() if primary[true_id] != key}
    observations = correct = rejected = 0
    for true_id, key in zip(true_ids, keys, strict=True):
        if true_id is None:
            continue
        observations += 1
        if key is None:
            rejected += 1
        elif key not in duplicates and identity.get(key) == true_id:
            correct += 1
    return AssociationScore(observations, correct, rejected, identity, frozenset(duplicates))


def relabel_landmarks(landmarks: Mapping[int, object], score: AssociationScore) -> dict:
    """Re-key an estimator's landmarks by the true id each stands for (duplicates dropped)."""
    return {
        score.identity[k]: v for k, v in landmarks.items() if k in score.identity and k not in score.duplicate_keys
    }
