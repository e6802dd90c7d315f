"""A cap on how many variables one relinearisation check relinearises (``relinearize_max_variables``).

On a checking update (every ``relinearize_skip``-th) GTSAM relinearises every variable whose
pending step — its entry of iSAM2's delta — exceeds the threshold, and re-eliminates every
clique that holds one of them (as a frontal or a separator variable) and all their
ancestors. After iSAM2 has smoothed a stretch of poses seeded from the online correction
that was up to a thousand poses on MRCLAM and twelve thousand variables re-eliminated on
Plaza1, in one update of 50–570 ms (docs/performance.md). :class:`CapChoice` lets a check
relinearise at most ``max_variables`` of the variables past the threshold (which ones:
below) and names the rest, which go to GTSAM as ``ISAM2UpdateParams.noRelinKeys``.
Those stay linearised where they are until a later check chooses them (or
:meth:`~fgslam.smoother.isam2.Isam2Smoother.finish`'s full Gauss–Newton steps); their delta
still moves the estimate.

The cap bounds the variables relinearised, not the variables re-eliminated: GTSAM
re-eliminates every clique holding a relinearised variable and every clique above it, up to
the root, so what a check costs is the union of those paths. Variables chosen by ratio
alone lie all over the tree (on Plaza1 and Victoria Park nearly every variable is past the
threshold at a check, the furthest past it hundreds to thousands of entries old) and their
paths share little: 300 of them re-eliminated 1 500–2 300 variables. So by default
(``choice="block"``) a check relinearises the variables past the threshold within one block
of ``max_variables`` consecutive variables in the order they entered iSAM2, the block with
the largest sum of ratios; neighbours in that order are neighbours in the tree, their paths
to the root are mostly one path, and the same checks re-eliminated 400–1 100
(docs/performance.md, "Relinearising a block of neighbours"; after a rebuild or a window's
slide the keys are read back in key order, landmarks first, and the block follows that
order). ``choice="ratio"`` is the first rule:
the ``max_variables`` furthest past the threshold, wherever they are. Choosing by GTSAM's own
prediction of the re-elimination (``ISAM2.predictUpdateInfo``) was measured and cost more
than it saved (docs/performance.md).
"""

from __future__ import annotations

import gtsam
import numpy as np

#: The tangent dimension of each kind of variable, by the key's character
#: (fgslam/smoother/variables.py): a pose or a tag (x, y, θ: the third component in
#: radians), a point landmark (x, y), a height.
_DIMENSIONS = {ord("x"): 3, ord("t"): 3, ord("l"): 2, ord("h"): 1}

#: A key is its symbol's character in the top 8 bits and its index in the 56 below (gtsam.Symbol).
_INDEX_BITS = 56
_INDEX_MASK = (1 << _INDEX_BITS) - 1
#: Indices below this are exact as float64 (what createKeyList takes them as).
_EXACT_IN_FLOAT = 1 << 53
#: How a capped check chooses what to relinearise (:class:`CapChoice`).
CHOICES = ("block", "ratio")
#: A block's weight per variable is its ratio, clipped here (a zero threshold makes it
#: infinite): a power of two, so sums of tied weights are exact.
_RATIO_CEILING = 2.0**40


def component_thresholds(keys: list[int], threshold: float | tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The relinearisation threshold of each tangent component of the variables ``keys``, in
    order (one number for all, or the (metres, radians) pair the smoother gives GTSAM as its
    per-type threshold map: θ in radians, the rest in metres), and where each variable's
    components start."""
    metres, radians = threshold if isinstance(threshold, tuple) else (threshold, threshold)
    characters = (np.asarray(keys, dtype=np.uint64) >> np.uint64(56)).astype(np.intp)
    lookup = np.zeros(256, dtype=np.intp)
    for character, dim in _DIMENSIONS.items():
        lookup[character] = dim
    dims = lookup[characters]
    if not dims.all():
        raise ValueError("component_thresholds: a key of an unknown kind of variable")
    starts = np.cumsum(dims) - dims
    thresholds = np.full(int(dims.sum()), float(metres))
    thresholds[starts[dims == 3] + 2] = radians
    return thresholds, starts


def ratios(delta: gtsam.VectorValues, keys: list[int], threshold: float | tuple[float, float]) -> np.ndarray:
    """Per variable of ``keys``: its largest |step component| / threshold (GTSAM relinearises
    a variable when a component reaches its threshold, i.e. this is at least 1; with a zero
    threshold, always: infinity)."""
    if not keys:
        return np.empty(0)
    thresholds, starts = component_thresholds(keys, threshold)
    return step_ratios(delta.vector(keys), thresholds, starts)


def step_ratios(step, thresholds: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Per variable: the largest |component of ``step``| / its component's threshold
    (infinity at a zero threshold); ``thresholds`` and ``starts`` as
    :func:`component_thresholds` gives them."""
    step = np.abs(np.asarray(step).ravel())
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(thresholds > 0, step / thresholds, np.inf)
    return np.maximum.reduceat(ratio, starts)


def block_start(weights: np.ndarray, width: int) -> int:
    """Where the ``width`` consecutive entries of ``weights`` with the largest sum start (the
    first such block on ties; 0 when there are no more than ``width``; past the end for an
    empty block)."""
    if width <= 0:
        return len(weights)
    if len(weights) <= width:
        return 0
    sums = np.concatenate([[0.0], np.cumsum(weights)])
    return int(np.argmax(sums[width:] - sums[:-width]))


class CapChoice:
    """The variables of one ``ISAM2`` past the threshold that its next check is not to
    relinearise (``ISAM2UpdateParams.noRelinKeys``): all but those within the block of
    ``max_variables`` consecutive kept keys with the largest sum of ratios
    (``choice="block"``), or all but the ``max_variables`` furthest past it (``"ratio"``).

    The keys of the ``ISAM2`` and their components' thresholds are kept from check to check
    and extended by the keys each update entered (:meth:`entered`), so a check reads only
    iSAM2's delta: reading the keys back from the linearisation point and converting them
    took about half of a check's choice on 49 000 variables. When the ``ISAM2`` is not the
    one the keys were kept for (a rebuild, a window's slide) or holds a different number of
    variables than they say, the keys are read back from it."""

    def __init__(self, threshold: float | tuple[float, float], max_variables: int, choice: str = "block"):
        if choice not in CHOICES:
            raise ValueError(f"CapChoice: choice must be one of {CHOICES}, got {choice!r}")
        self._threshold, self._max_variables, self._choice = threshold, max_variables, choice
        self._isam = None
        self._keys: list[int] = []  # as GTSAM's linearisation point listed them, then as entered
        self._entered: list[int] = []  # entered since the arrays below were last extended
        self._array = np.empty(0, dtype=np.uint64)
        self._thresholds = np.empty(0)
        self._starts = np.empty(0, dtype=np.intp)  # where each variable's components start

    def entered(self, isam, values: gtsam.Values) -> None:
        """``values`` went into ``isam`` in an update that succeeded."""
        if isam is self._isam:
            self._entered.extend(values.keys())
        elif self._isam is not None:  # a rebuilt or slid ISAM2: let the old one go now
            self._isam, self._keys, self._entered = None, [], []

    def held_back(self, isam) -> gtsam.KeyList:
        """What the check of ``isam``'s next update is not to relinearise (by ratio: the same
        keys as reading them all back and ranking by ratio, ties by key; by block: the same
        block as summing the ratios of every window in the order the keys entered: tested)."""
        ratio = self.ratios(isam)
        if ratio is None:
            return gtsam.KeyList()
        past = np.flatnonzero(ratio >= 1.0)
        if len(past) <= self._max_variables:
            return gtsam.KeyList()
        if self._choice == "block":
            weights = np.zeros(len(ratio))
            weights[past] = np.minimum(ratio[past], _RATIO_CEILING)
            start = block_start(weights, self._max_variables)
            held = past[(past < start) | (past >= start + self._max_variables)]
            return key_list(self._array[held])
        keys = self._array[past]
        chosen = keys[np.lexsort((keys, -ratio[past]))][self._max_variables:]  # by ratio, then by key
        return key_list(chosen)

    def ratios(self, isam) -> np.ndarray | None:
        """Each variable's largest pending step over its threshold (inf at a zero threshold),
        in the order of the kept keys; None when ``isam`` holds no variable."""
        self._sync(isam)
        if not self._keys:
            return None
        return step_ratios(isam.getDelta().vector(self._keys), self._thresholds, self._starts)

    def _sync(self, isam) -> None:
        size = isam.getLinearizationPoint().size()
        if isam is not self._isam or len(self._keys) + len(self._entered) != size:
            self._isam, self._keys, self._entered = isam, [], list(isam.getLinearizationPoint().keys())
            self._array, self._thresholds, self._starts = np.empty(0, dtype=np.uint64), np.empty(0), np.empty(0, dtype=np.intp)
        if self._entered:
            new = np.array(self._entered, dtype=np.uint64)
            thresholds, starts = component_thresholds(new, self._threshold)
            self._starts = np.concatenate([self._starts, starts + len(self._thresholds)])
            self._thresholds = np.concatenate([self._thresholds, thresholds])
            self._array = np.concatenate([self._array, new])
            self._keys.extend(self._entered)
            self._entered = []


def key_list(keys: np.ndarray) -> gtsam.KeyList:
    """``keys`` (uint64) as a ``gtsam.KeyList``, poses first (GTSAM reads ``noRelinKeys`` as a
    set). The poses, usually nearly all of them (a check may hold back thousands), are made in
    one call of ``gtsam.utilities.createKeyList`` from their indices, the rest one by one: a
    ``push_back`` per key took 1.1 ms a check on Victoria Park."""
    kinds = keys >> np.uint64(_INDEX_BITS)
    indices = keys & np.uint64(_INDEX_MASK)
    is_pose = (kinds == ord("x")) & (indices < np.uint64(_EXACT_IN_FLOAT))  # its index passes as a float64
    out = gtsam.utilities.createKeyList("x", indices[is_pose].astype(np.float64)) if is_pose.any() else gtsam.KeyList()
    for key in keys[~is_pose].tolist():
        out.push_back(key)
    return out
