"""The parameters :func:`fgslam.self_calibration.fit_without_truth` profiles on the whole run
with the variance components θ held: the odometry's scales, the camera's range model (range
or depth, and its bias) and a radio's range scale. Each is the value that makes the run's
measurements most likely at the batch solution (a line search on the cost of the
:class:`fgslam.self_calibration.RunGraph` objects), between rounds of variance-component
estimation."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from slamio.noise.fit_self import parabola_minimum, scaled_increments

if TYPE_CHECKING:  # the graphs' class; self_calibration imports this module
    from fgslam.self_calibration import RunGraph

__all__ = ["PROFILE_ROUNDS", "profile_range_model", "profile_range_scale", "profile_scales", "settled"]

#: The odometry's scales searched on the whole run (:func:`profile_scales`): name, first step
#: and bounds.
SCALE_SEARCH = (("turn_scale", 0.04, (0.7, 1.3)), ("turn_per_m_rad", 0.03, (-0.3, 0.3)),
                ("forward_scale", 0.04, (0.7, 1.3)))


def profile_scales(graphs: list[RunGraph], theta: np.ndarray, start: dict[str, float] | None = None) -> dict[str, float]:
    """The odometry's turn scale, turn per metre and forward scale that make the whole run's
    measurements most likely (θ held), one at a time, twice (:func:`_line_search`).

    The cost is half the χ² of the graph with every odometry variance held at that of the
    increments as read (the regression of the smoothed motion on the odometry): the variances
    must not move with the scales, or the profile trades accuracy for σ. Tried: ``q`` of
    the scaled increments (smaller scales shrink every variance and win on the determinant:
    on a simulated run turn scale 0.916 and forward scale 0.874 for 0.93 and 0.95), and the
    noise taken as the reading's (covariance ``S Σ Sᵀ``: a larger scale inflates σ and
    whitens systematic misfit; on MRCLAM turn scales 1.28, at the search's bound).
    The graphs are left with the odometry re-read at the result, ``q`` of the scaled
    increments."""
    p = dict(start or {"forward_scale": 1.0, "turn_scale": 1.0, "turn_per_m_rad": 0.0})

    def re_read(values: dict[str, float], final: bool = False) -> None:
        fs, ts = values["forward_scale"], values["turn_scale"]
        for run in graphs:
            scaled = scaled_increments(run.read_increments, fs, ts, values["turn_per_m_rad"])
            run.set_increments(scaled, None if final else (1.0, 1.0, 1.0))

    def cost(values: dict[str, float]) -> float:
        re_read(values)
        return sum(run.chi2_half(theta) for run in graphs)

    for run in graphs:
        run.set_increments(run.read_increments)  # q of the increments as read
    for shrink in (1.0, 0.3):
        for name, step, bounds in SCALE_SEARCH:
            p[name] = line_search(lambda v: cost({**p, name: v}), p[name], step * shrink, bounds)
    re_read(p, final=True)
    return p


#: At most this many rounds of the profiles (scales, range model) and the variances in turn;
#: they stop when no profiled value moves by more than :data:`PROFILE_SETTLED`.
PROFILE_ROUNDS = 4
PROFILE_SETTLED = 0.003


def settled(last: tuple[dict, dict], now: tuple[dict, dict]) -> bool:
    for a, b in zip(last, now):
        if set(a) != set(b) or any(abs(float(a[k]) - float(b[k])) > PROFILE_SETTLED for k in a):
            return False
    return True


#: The camera's range bias searched without truth: first step and bounds (m).
RANGE_BIAS_STEP_M, RANGE_BIAS_BOUNDS_M = 0.02, (-0.3, 0.3)


def profile_range_model(graphs: list[RunGraph], theta: np.ndarray) -> tuple[bool, float, dict]:
    """The camera's range model most likely for the whole run (θ held): range or depth
    (``r·cos b``, what a camera that sizes the landmark's image measures), each with the
    bias that fits it best (:func:`_line_search`). Its scale stays 1: without truth the
    readings set the scale. ``(range_is_depth, range_bias_m, costs)``; the graphs are left
    with their ranges re-read under it."""
    found = {}
    for depth in (False, True):
        def cost(bias: float) -> float:
            for run in graphs:
                run.set_range_model(depth, bias)
            return sum(run.range_model_cost(theta) for run in graphs)

        bias = line_search(cost, 0.0, RANGE_BIAS_STEP_M, RANGE_BIAS_BOUNDS_M)
        bias = line_search(cost, bias, 0.3 * RANGE_BIAS_STEP_M, RANGE_BIAS_BOUNDS_M)
        found[depth] = (bias, cost(bias))
    depth = found[True][1] < found[False][1]
    for run in graphs:
        run.set_range_model(depth, found[depth][0])
    return depth, found[depth][0], {"range": found[False], "depth": found[True]}


#: A radio's range scale searched without truth: first step and bounds.
RANGE_SCALE_STEP, RANGE_SCALE_BOUNDS = 0.02, (0.8, 1.25)
#: The most solves :func:`profile_range_scale` makes: two line searches of at most
#: 1 + 2 × 8 costs each (:func:`line_search`), and the last at the result.
RANGE_SCALE_SOLVES = 35


def profile_range_scale(graphs: list[RunGraph], theta: np.ndarray, progress=None) -> tuple[float, float]:
    """The scale of range-only readings (``measured = scale · distance``: a radio's time of
    flight read long or short) most likely for the whole run (θ held), against the log's
    odometry: with nothing else to measure distance, only the ratio of the two scales shows,
    and the odometry as read is taken as the gauge. ``(scale, cost)``; the graphs are left
    with their ranges re-read under it. On Plaza1 and Plaza2 each run alone gives
    1.065–1.068, where GPS says 1.069–1.070 (docs/results-datasets.md).
    ``progress(done, total, label)`` after each solve (at most :data:`RANGE_SCALE_SOLVES`)."""
    solves = 0

    def cost(scale: float) -> float:
        nonlocal solves
        for run in graphs:
            run.set_range_scale(scale)
        total = sum(run.range_model_cost(theta) for run in graphs)
        solves += 1
        if progress is not None:
            progress(min(solves, RANGE_SCALE_SOLVES), RANGE_SCALE_SOLVES, "noise fit: range scale")
        return total

    scale = line_search(cost, 1.0, RANGE_SCALE_STEP, RANGE_SCALE_BOUNDS)
    scale = line_search(cost, scale, 0.3 * RANGE_SCALE_STEP, RANGE_SCALE_BOUNDS)
    found = cost(scale)  # also leaves the graphs at it
    if progress is not None:
        progress(RANGE_SCALE_SOLVES, RANGE_SCALE_SOLVES, "noise fit: range scale")
    return scale, found


def line_search(f, x: float, h: float, bounds: tuple[float, float], moves: int = 8) -> float:
    """A minimum of ``f`` near ``x``: step by ``h`` downhill until the middle of three points
    is the lowest, then the parabola's minimum through them (within ``bounds``)."""
    fx = f(x)
    for _ in range(moves):
        lo, hi = max(x - h, bounds[0]), min(x + h, bounds[1])
        f_lo, f_hi = f(lo), f(hi)
        if fx <= f_lo and fx <= f_hi:
            v = parabola_minimum(np.array([lo, x, hi]), np.array([f_lo, fx, f_hi]))
            return x if v is None else float(np.clip(v, lo, hi))
        x, fx = (lo, f_lo) if f_lo < f_hi else (hi, f_hi)
    return x


