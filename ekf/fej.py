"""First-estimates Jacobian EKF-SLAM (``ekf-fej``): the textbook filter with its Jacobians
taken where they leave the unobservable directions unobservable.

In 2-D landmark SLAM nothing the robot senses fixes the world frame: a shift of every
position and a rotation about any point (three directions) leave every measurement the same.
The textbook EKF (:class:`ekf.slam.EkfSlam`) evaluates each Jacobian at the latest
estimate; because the estimate moves between a prediction and the updates that follow,
the linearised system then "observes" the global heading — one of the three directions
(Huang, Mourikis and Roumeliotis, *Analysis and improvement of the consistency of extended
Kalman filter based SLAM*, ICRA 2008). The filter gains heading information no sensor
gave it, its heading variance shrinks too far, and a heading error made while the map is
young is locked in: on MRCLAM Dataset 6 the textbook EKF ends turned by 15° and 24° on two
robots while it reports a heading σ of 1–2° (docs/estimators.md, "ekf-fej").

The first-estimates Jacobian filter (Huang, Mourikis and Roumeliotis, *A first-estimates
Jacobian EKF for improving SLAM consistency*, ISER 2008) evaluates

* the propagation Jacobian with the robot's *predicted* positions, before any update::

      Φ_k = [[I₂, J (p̂_{k+1|k} − p̂_{k|k−1})], [0, 1]],   J = [[0, −1], [1, 0]]

  (the textbook filter has ``p̂_{k|k}``, the updated position, in place of ``p̂_{k|k−1}``);
* every measurement Jacobian of landmark ``i`` at time ``k`` at the robot's predicted
  position ``p̂_{k|k−1}`` and at the landmark's *first* estimate ``p̂_{L_i}``, the one it
  was initialised with (for every observation of the step, also after the step's first
  update).

With these, the linearised system's observability matrix keeps all three unobservable
directions, as the nonlinear system has them (``tests/test_ekf_fej.py`` checks the null
space). The innovations, the state's mean and the landmark initialisation are the
textbook filter's: only where the Jacobians are taken changes. The first estimates can be
poor, so the price is some linearisation error; the cited papers and the measurements in
docs/estimators.md find it far smaller than the inconsistency it removes.

Everything else (data association, gates, landmark heights, range-only landmarks, the
readings' Gauss–Markov errors) is :class:`~ekf.slam.EkfSlam`'s. Association and the NIS
reported for the comparison table use the latest estimate, as for every estimator.
"""

from __future__ import annotations

import numpy as np

from ekf.slam import EkfSlam
from slamio.log import Header


def fej_motion_jacobian(prior_xy, predicted_xy) -> np.ndarray:
    """Φ = ∂(pose ⊕ u)/∂pose with the heading column ``J (p̂_{k+1|k} − p̂_{k|k−1})``:
    ``prior_xy`` is the robot's position predicted for the current step (before its
    updates), ``predicted_xy`` the one predicted for the next."""
    dx = float(predicted_xy[0]) - float(prior_xy[0])
    dy = float(predicted_xy[1]) - float(prior_xy[1])
    return np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])


class FejEkfSlam(EkfSlam):
    """:class:`~ekf.slam.EkfSlam` with first-estimates Jacobians (see the module docstring).

    Takes the same keyword arguments; ``name`` is "ekf-fej" ("ekf-fej-nn" with
    ``association="nn"``, "ekf-fej-ids" with None, as :class:`~ekf.slam.EkfSlam` names its own).
    """

    name = "ekf-fej"

    def __init__(self, header: Header, **kwargs):
        super().__init__(header, **kwargs)
        self.name = "ekf-fej" + self.name[len("ekf"):]  # ekf-fej, ekf-fej-nn, ekf-fej-ids
        self._prior_xy = self._mean[:2].copy()  # p̂_{k|k−1}: the start pose, before any update
        self._first_xy: dict[int, np.ndarray] = {}  # landmark key → its first estimate (x, y)

    def _propagation_jacobian(self, F_pose: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """Φ from the predicted positions; ``predicted`` becomes the prior of the next step."""
        F = fej_motion_jacobian(self._prior_xy, predicted)
        self._prior_xy = predicted[:2].copy()
        return F

    def _register_landmark(self, key: int, n: int, with_height: bool) -> None:
        super()._register_landmark(key, n, with_height)
        self._first_xy[key] = self._mean[n : n + 2].copy()

    def _linearisation_point(self, key: int, pose: np.ndarray, landmark: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        at_pose = np.array([self._prior_xy[0], self._prior_xy[1], pose[2]])
        at_landmark = np.array(landmark, dtype=float)
        at_landmark[:2] = self._first_xy[key]
        return at_pose, at_landmark
