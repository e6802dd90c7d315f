"""The EKF's reading-error states: :class:`ReadingErrorStates`, the part of
:class:`ekf.slam.EkfSlam` that carries each landmark's Gauss–Markov reading error (range,
bearing) as two states after the landmark when the header's noise has a
``correlated_share`` (the model and why: :mod:`ekf.reading_error`).

A mixin: it works on the state :class:`ekf.slam.EkfSlam` sets up in its ``__init__``.
"""

from __future__ import annotations

import numpy as np

from ekf.models import ROBOT_DIM, normalised_innovation_squared, range_bearing, range_bearing_jacobians
from ekf.observation import measurement_covariance
from ekf.reading_error import gauss_markov_step, reading_sigmas
from slamio.geometry import wrap_angle
from slamio.log import Observation


class ReadingErrorStates:
    """Adding, decaying and reading each landmark's correlated reading error."""

    def _nis_with_reading_error(self, pose, P_rr, F, observation: Observation) -> float:
        """NIS of a reading of a landmark that carries reading-error states (nothing changes):
        the errors decayed to the reading's time, then ``ν = z − h − e`` and
        ``S = H Σ Hᵀ + (1 − ρ)R`` over (pose, landmark, errors)."""
        key = observation.landmark_id
        i, j = self._slot[key], self._error_index[key]
        scale, added = self._error_transition(key, observation)
        rows = [i, i + 1, j, j + 1]
        joint = np.empty((7, 7))
        joint[:3, :3] = P_rr
        joint[:3, 3:] = F @ self._cov[:ROBOT_DIM, rows]
        joint[3:, :3] = joint[:3, 3:].T
        joint[3:, 3:] = self._cov[rows][:, rows]
        decay = np.ones(7)
        decay[5:] = scale  # the decay of the two errors: A joint A with A = diag(decay), then their added variance
        joint = joint * decay[:, None] * decay
        joint[5, 5] += added[0]
        joint[6, 6] += added[1]
        landmark = self._mean[i : i + 2]
        predicted_range, predicted_bearing = range_bearing(pose, landmark)
        error = scale * self._mean[j : j + 2]
        nu = (observation.range_m - predicted_range - error[0],
              wrap_angle(observation.bearing_rad - predicted_bearing - error[1]))
        H = np.empty((2, 7))
        H[:, :3], H[:, 3:5] = range_bearing_jacobians(pose, landmark)
        H[:, 5:] = ((1.0, 0.0), (0.0, 1.0))
        S = H @ joint @ H.T + (1.0 - self.reading_error.share) * measurement_covariance(observation)
        return normalised_innovation_squared(nu, S)

    def _errors_to_now(self) -> tuple[np.ndarray, np.ndarray]:
        """Per state entry: the scale and added variance that carry each landmark's reading
        errors from its last reading to the last step (ones and zeros elsewhere)."""
        scale, added = np.ones(self._dim), np.zeros(self._dim)
        for key, j in self._error_index.items():
            sigma = self._error_sigma[key]
            scale[j : j + 2], added[j : j + 2] = gauss_markov_step(
                self._time - self._error_time[key], self.reading_error.time_s, sigma, sigma, self.reading_error.share
            )
        return scale, added

    def _add_reading_error(self, key: int, observation: Observation, G_measurement: np.ndarray) -> None:
        """Append the landmark's reading errors (range, bearing) just after it.

        The landmark was placed from ``z = h + e + w``, so it carries ``−G_z·e``: its
        covariance (already ``G_z R G_zᵀ``, R the whole reading variance) stays, and it is
        correlated with the errors by ``−G_z·ρR``; the errors start at 0 with variance ρR
        and are independent of everything else."""
        j = self._dim
        sigma = reading_sigmas(observation)
        P_ee = np.diag(self.reading_error.share * sigma**2)
        i, k = self._slot[key], self._landmark_dim(key)
        self._mean[j : j + 2] = 0.0
        self._cov[j : j + 2, :j] = 0.0
        self._cov[:j, j : j + 2] = 0.0
        P_le = -G_measurement[:, :2] @ P_ee
        self._cov[i : i + k, j : j + 2] = P_le
        self._cov[j : j + 2, i : i + k] = P_le.T
        self._cov[j : j + 2, j : j + 2] = P_ee
        self._error_index[key] = j
        self._error_time[key] = observation.stamp_s
        self._error_sigma[key] = sigma
        self._dim = j + 2

    def _error_transition(self, key: int, observation: Observation) -> tuple[np.ndarray, np.ndarray]:
        """(scale, added variance) from the landmark's last reading to ``observation``."""
        return gauss_markov_step(
            observation.stamp_s - self._error_time[key], self.reading_error.time_s,
            self._error_sigma[key], reading_sigmas(observation), self.reading_error.share,
        )

    def _decay_reading_error(self, key: int, observation: Observation) -> None:
        """Carry the landmark's reading errors to ``observation``'s time, in place, O(n)."""
        j = self._error_index[key]
        n = self._dim
        scale, added = self._error_transition(key, observation)
        self._mean[j : j + 2] *= scale
        self._cov[j : j + 2, :n] *= scale[:, None]
        self._cov[:n, j : j + 2] *= scale[None, :]
        self._cov[j, j] += added[0]
        self._cov[j + 1, j + 1] += added[1]
        self._error_time[key] = observation.stamp_s
        self._error_sigma[key] = reading_sigmas(observation)
