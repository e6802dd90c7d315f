"""Readings whose errors are correlated in time: a Gauss–Markov error per landmark.

Why
---
A camera that sees the same landmark from nearly the same place makes nearly the same
error (the barcode's apparent size and centre depend on lighting, distance and where it
falls in the image). On MRCLAM, two readings of one landmark taken within half a second
have errors correlated at about 0.6, still 0.2 at 10–20 s (``fgslam calibrate`` fits it:
``noise.observation.correlated_share`` ρ and ``correlation_time_s`` τ). A filter that
takes such readings as independent counts the same error many times: it moves the
landmark to where the error says, grows confident, and cannot take it back. On MRCLAM
Dataset 6 this is what most separates the EKF from the smoother (docs/datasets-mrclam-rosbag.md).

The model
---------
Each reading's error (range, bearing) is ``e + w``: ``w`` white with variance
``(1 − ρ)·σ²`` (σ the reading's own σ) and ``e = σ·u`` a Gauss–Markov error of the
landmark, ``u`` a unit process with ``corr(u(t), u(t + Δt)) = exp(−Δt/τ)``. Between two
readings Δt apart with σ₀ then σ₁ (per component),

    e₁ = φ·(σ₁/σ₀)·e₀ + n,   φ = exp(−Δt/τ),   n ~ N(0, ρ·σ₁²·(1 − φ²)),

so that ``e`` always has variance ρσ² and the right correlation whatever σ does.

How the EKF carries it
----------------------
The EKF appends the two errors (range, bearing) of each landmark to the state, after its
position. They enter only that landmark's readings, so their decay can wait until the
landmark is seen again (:func:`gauss_markov_step` over the whole gap): an update of
anything else does not involve them, and the linear decay commutes with such an update
(their cross-covariances are scaled later by the same factor). The lazy decay is exact, and a
step stays O(n) for the prediction. :mod:`tests.test_reading_error` checks it against a
filter that decays every error at every step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ReadingErrorModel", "gauss_markov_step", "reading_error_model", "reading_sigmas"]


@dataclass(frozen=True)
class ReadingErrorModel:
    """ρ (share of a reading's variance that is the landmark's Gauss–Markov error) and τ (s)."""

    share: float
    time_s: float

    def __post_init__(self) -> None:
        if not (0.0 < self.share < 1.0 and self.time_s > 0.0 and math.isfinite(self.time_s)):
            raise ValueError(f"need 0 < share < 1 and time_s > 0, got {self.share!r}, {self.time_s!r}")


def reading_error_model(noise: object) -> ReadingErrorModel | None:
    """The model a log header's ``noise.observation`` asks for, or None for white readings."""
    observation = noise.get("observation") if isinstance(noise, dict) else None
    if not isinstance(observation, dict):
        return None
    share, time_s = observation.get("correlated_share"), observation.get("correlation_time_s")
    if not isinstance(share, (int, float)) or not isinstance(time_s, (int, float)) or not share > 0.0:
        return None
    return ReadingErrorModel(float(share), float(time_s))


def gauss_markov_step(
    dt_s: float, time_s: float, sigma_before: np.ndarray, sigma_now: np.ndarray, share: float
) -> tuple[np.ndarray, np.ndarray]:
    """``(scale, added_variance)`` that carry a landmark's reading errors across ``dt_s``.

    ``e ← scale·e`` (per component) and ``var(e) ← scale²·var(e) + added_variance``, with
    ``scale = φ·σ_now/σ_before`` and ``added_variance = share·σ_now²·(1 − φ²)``,
    ``φ = exp(−dt_s/time_s)`` (module docstring). ``sigma_*`` are the readings' own σ.
    """
    phi = math.exp(-max(float(dt_s), 0.0) / time_s)
    sigma_before = np.asarray(sigma_before, dtype=float)
    sigma_now = np.asarray(sigma_now, dtype=float)
    scale = phi * sigma_now / sigma_before
    return scale, share * sigma_now**2 * (1.0 - phi * phi)


def reading_sigmas(observation) -> np.ndarray:
    """``(σ_range_m, σ_bearing_rad)`` a range-bearing observation states."""
    return np.array([observation.sigma_range_m, observation.sigma_bearing_rad], dtype=float)
