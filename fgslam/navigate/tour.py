"""A tour of the coverage goals: which one to go to first so that the whole set costs least.

Going to the nearest frontier each time (greedy) leaves pockets behind: a small frontier
beside the start is passed over for a nearer one, and the robot comes back for it minutes
later (a tag found there in the last minute cannot be revisited). A tour — a short path
from the robot through every goal — takes the goals in an order that sweeps the room once;
its first goal is the one to go to now (as in frontier-tour planners, e.g. Zhou et al.,
FUEL, 2021). ``end_m`` closes the tour at a point (the robot comes back past what it has
already seen); without it the tour ends anywhere.

Built by nearest neighbour and improved by 2-opt (reversing a stretch of the tour) and
or-opt moves (moving one goal elsewhere in it) while one shortens it, both ends fixed: for
the ~5–30 goals of a room, a few hundred µs.
"""

from __future__ import annotations

import numpy as np

__all__ = ["tour_order", "tour_length_m", "pairwise_m"]


def pairwise_m(xy: np.ndarray) -> np.ndarray:
    """Straight-line distances (n, n) between points ``xy`` (n, 2)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    return np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])


def _distances(first_leg_m, between_m, end_m) -> np.ndarray:
    """One matrix over the nodes: 0 the robot, 1..n the goals, n + 1 the end (``end_m`` from
    each goal; zeros: the tour may end anywhere)."""
    n = len(first_leg_m)
    d = np.zeros((n + 2, n + 2))
    d[0, 1:n + 1] = d[1:n + 1, 0] = first_leg_m
    d[1:n + 1, 1:n + 1] = between_m
    d[1:n + 1, n + 1] = d[n + 1, 1:n + 1] = np.zeros(n) if end_m is None else end_m
    d[0, n + 1] = d[n + 1, 0] = np.inf  # the tour visits every goal before it ends
    return d


def tour_length_m(order, first_leg_m, between_m, end_m=None) -> float:
    """Length of the tour from the robot through the goals in ``order`` (and to the end)."""
    d = _distances(np.asarray(first_leg_m, float), np.asarray(between_m, float), end_m)
    path = np.r_[0, np.asarray(order, int) + 1, len(first_leg_m) + 1]
    return float(d[path[:-1], path[1:]].sum())


_MOVES: dict[int, tuple] = {}


def _moves(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every move on a path of n goals between fixed ends (positions 0 and n + 1): 2-opt
    reverses path[i + 1 .. j]; or-opt moves the goal at path[p] between path[q] and
    path[q + 1]. Built once per n."""
    if n not in _MOVES:
        i, j = np.triu_indices(n + 1, k=2)
        p, q = np.nonzero((np.arange(1, n + 1)[:, None] != np.arange(n + 1)[None, :])
                          & (np.arange(1, n + 1)[:, None] != np.arange(n + 1)[None, :] + 1))
        _MOVES[n] = (i, j, p + 1, q)
    return _MOVES[n]


def tour_order(first_leg_m, between_m, end_m=None, max_moves: int = 60) -> np.ndarray:
    """Indices of the goals in the order of a short tour from the robot through all of them:
    ``first_leg_m`` (n,) the way from the robot to each, ``between_m`` (n, n) the distance
    between goals (symmetric), ``end_m`` (n,) from each goal to the tour's end (None: it
    ends at its last goal). Nearest neighbour, then the best of the 2-opt moves (reverse a
    stretch) and the or-opt moves (move one goal elsewhere) each time, until none shortens
    it (at most ``max_moves``)."""
    first_leg_m = np.asarray(first_leg_m, dtype=float)
    n = len(first_leg_m)
    if n <= 1:
        return np.arange(n)
    d = _distances(first_leg_m, np.asarray(between_m, dtype=float), end_m)
    path, masked = [0], d.copy()
    masked[:, [0, n + 1]] = np.inf
    for _ in range(n):  # nearest neighbour
        path.append(int(np.argmin(masked[path[-1]])))
        masked[:, path[-1]] = np.inf
    path = np.array(path + [n + 1])
    i, j, p, q = _moves(n)
    for _ in range(max_moves):  # the better move of the two kinds each time, until none shortens the tour
        a, b, c, e = path[i], path[i + 1], path[j], path[j + 1]
        reverse = d[a, b] + d[c, e] - d[a, c] - d[b, e]
        before, node, after, u, v = path[p - 1], path[p], path[p + 1], path[q], path[q + 1]
        move = d[before, node] + d[node, after] - d[before, after] + d[u, v] - d[u, node] - d[node, v]
        k, m = int(np.argmax(reverse)), int(np.argmax(move))
        if max(reverse[k], move[m]) <= 1e-9:
            break
        if reverse[k] >= move[m]:
            path[i[k] + 1:j[k] + 1] = path[i[k] + 1:j[k] + 1][::-1].copy()
        else:
            rest = np.delete(path, p[m])
            path = np.insert(rest, q[m] + (1 if q[m] < p[m] else 0), path[p[m]])
    return path[1:-1] - 1
