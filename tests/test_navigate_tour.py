"""``explore``'s tour of the coverage goals (issue 44): against hand-worked orders and a
brute-force search over every order."""

import itertools

import numpy as np
import pytest

from fgslam.navigate.tour import pairwise_m, tour_length_m, tour_order


def _brute_force_m(first, between, end=None) -> float:
    return min(tour_length_m(p, first, between, end) for p in itertools.permutations(range(len(first))))


def test_pairwise_distances_are_the_straight_lines():
    xy = np.array([[0.0, 0.0], [3.0, 4.0], [-1.0, 0.0]])
    assert pairwise_m(xy) == pytest.approx(np.array([[0, 5, 1], [5, 0, np.hypot(4, 4)], [1, np.hypot(4, 4), 0]]))


def test_tour_length_adds_the_legs_and_the_way_to_the_end():
    first, between = np.array([1.0, 2.0]), np.array([[0.0, 3.0], [3.0, 0.0]])
    assert tour_length_m([0, 1], first, between) == pytest.approx(1.0 + 3.0)
    assert tour_length_m([1, 0], first, between, end_m=np.array([0.5, 7.0])) == pytest.approx(2.0 + 3.0 + 0.5)


def test_a_goal_left_behind_by_the_nearest_is_taken_first():
    # goals on a line at x = -1, 0.5, 1, 2, the robot at 0: nearest first goes 0.5, 1, 2 and
    # back to -1 (5 m); the tour takes -1 first and sweeps once (1 + 1.5 + 0.5 + 1 = 4 m)
    x = np.array([-1.0, 0.5, 1.0, 2.0])
    xy = np.column_stack([x, np.zeros(4)])
    order = tour_order(np.abs(x), pairwise_m(xy))
    assert list(order) == [0, 1, 2, 3]
    assert tour_length_m(order, np.abs(x), pairwise_m(xy)) == pytest.approx(4.0)


def test_a_tour_closed_at_the_start_comes_back_round_the_other_side():
    # six goals on a circle round the start, the robot beside the start: round the circle
    # one way and back to the start, not out and back across it
    angle = np.radians([0, 60, 120, 180, 240, 300])
    xy = 2.0 * np.column_stack([np.cos(angle), np.sin(angle)])
    robot = np.array([0.1, 0.0])
    first = np.hypot(*(xy - robot).T)
    order = tour_order(first, pairwise_m(xy), end_m=np.hypot(*xy.T))
    steps = np.round(np.diff(np.degrees(angle[order])) % 360)
    assert np.all(steps == steps[0]) and steps[0] in (60, 300)


@pytest.mark.parametrize("closed", [False, True])
def test_tours_are_near_the_best_order_found_by_brute_force(closed):
    rng = np.random.default_rng(7)
    ratios = []
    for _ in range(25):
        xy, robot = rng.uniform(0.0, 6.0, (6, 2)), rng.uniform(0.0, 6.0, 2)
        first = np.hypot(*(xy - robot).T) * rng.uniform(1.0, 1.3, 6)  # the floor's way is no shorter
        between = pairwise_m(xy)
        end = np.hypot(*(xy - robot).T) if closed else None
        order = tour_order(first, between, end)
        assert sorted(order) == list(range(6))
        ratios.append(tour_length_m(order, first, between, end) / _brute_force_m(first, between, end))
    assert min(ratios) >= 1.0 - 1e-12
    assert np.mean(ratios) < 1.03 and max(ratios) < 1.15


def test_no_goal_or_one_goal():
    assert list(tour_order(np.zeros(0), np.zeros((0, 0)))) == []
    assert list(tour_order(np.array([2.0]), np.zeros((1, 1)))) == [0]
