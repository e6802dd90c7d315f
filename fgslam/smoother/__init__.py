"""Incremental smoothing with GTSAM's iSAM2, and the batch solve used as "smoothed ground truth".

Where things are
----------------
======================  ==================================================================
``isam2.py``            :class:`Isam2Smoother`: the step loop and ``finish()``; it composes
                        the modules below (start reading here)
``updates.py``          giving held steps to iSAM2: when an update is due, the update with
                        its relinearisation check, recovery, the window's slide (a mixin)
``queries.py``          the smoother's answers: poses, landmarks, covariances, NIS, the
                        whole graph and its estimate (a mixin)
``pairings.py``         the smoother's side of id-less observations: handing them to
                        ``association.py``, holding the pairings, re-deciding them (a mixin)
``settings.py``         :class:`Isam2Settings`: every knob of how the graph is solved,
                        validated, each default with the measurement that chose it
``factors.py``          log records → factors and noise models (pure maths: odometry, tag
                        and start-prior covariances, robust kernels and their widths)
``policy.py``           when steps go to iSAM2 (held steps) and which poses are variables
                        (keyframes); the ``isam2-fast`` preset :data:`FAST_SETTINGS`
``chain.py``            odometry links folded into one compound relative pose
``pending.py``          observations not yet in iSAM2: withheld after a failure, robust first
                        sightings waiting for a second, unplaced range-only landmarks
``recovery.py``         rebuilding iSAM2 after an update failed (indeterminate system)
``relinearisation.py``  which variables a relinearisation check may relinearise (the cap,
                        ``relinearize_max_variables``)
``window.py``           the sliding window (``window_poses``): marginalising the oldest
                        poses so iSAM2's steps stay bounded however long the run
``online.py``           the online pose, its covariance, predicted NIS, landmark marginals
``association.py``      pairing observations without an id with the landmarks iSAM2 holds
``correction.py``       the online pose between updates: a pose-only EKF against the
                        landmarks iSAM2 holds (scalar maths, microseconds a step)
``variables.py``        keys, the landmarks iSAM2 holds, reading ``gtsam.Values`` back
``batch.py``            :func:`batch_solve`: Levenberg–Marquardt on the whole graph
======================  ==================================================================

The factor graph
----------------
* ``X(i)``  — robot pose *i* (``gtsam.Pose2``); pose 0 is the log header's start pose.
* ``L(id)`` — landmark ``id`` (``gtsam.Point2``, world frame).
* A ``PriorFactorPose2`` pins ``X(0)`` at ``header.start_pose`` with standard deviations
  ``header.start_sigma`` (world frame; see :func:`start_prior_covariance`).
* Each odometry record adds ``BetweenFactorPose2(X(k-1), X(k))`` with the logged increment
  and covariance (see :func:`odometry_noise_covariance` for the frame).
* Each observation with a known id adds ``BearingRangeFactor2D(X(k), L(id))``. GTSAM
  orders that measurement **bearing first, then range**, so its noise sigmas are
  ``[sigma_bearing_rad, sigma_range_m]``.
* ``T(id)`` — with ``tags=True``, a landmark whose first observation carries a tag yaw
  (seed 004's AprilTags) is a tag: a ``gtsam.Pose2`` (centre and the world direction its
  face points to). Each observation with a yaw adds ``BetweenFactorPose2(X(k), T(id))``
  with the measured relative pose (r·cos b, r·sin b, yaw) and the covariance propagated
  from (σ_r, σ_b, σ_yaw) (:func:`tag_noise_covariance`); one without a yaw adds
  ``BearingRangeFactorPose2`` to the tag's centre. Without ``tags`` yaws are unused.
* ``H(id)`` — a landmark's height (seed 002), a scalar, when observations carry one: each
  adds ``PriorFactorDouble(H(id), height, σ_h)``. Nothing else touches a height, so it is
  the information-weighted mean of the heights measured, as in the EKF.
* With ``robust="huber"`` or ``"cauchy"`` (see :class:`~fgslam.smoother.isam2.Isam2Smoother`)
  every landmark factor's noise model is ``noiseModel.Robust`` wrapping its Gaussian model; the prior,
  the odometry and the height factors stay Gaussian.
"""

from fgslam.smoother.batch import BatchResult, batch_solve
from fgslam.smoother.factors import (
    DEFAULT_ROBUST_K,
    ROBUST_KERNELS,
    has_tag_yaw,
    odometry_noise_covariance,
    robust_estimator,
    start_prior_covariance,
    tag_noise_covariance,
    tag_relative_pose,
)
from fgslam.smoother.isam2 import Isam2Smoother
from fgslam.smoother.policy import FAST_SETTINGS
from fgslam.smoother.settings import Isam2Settings

__all__ = [
    "Isam2Smoother",
    "Isam2Settings",
    "BatchResult",
    "batch_solve",
    "odometry_noise_covariance",
    "start_prior_covariance",
    "ROBUST_KERNELS",
    "DEFAULT_ROBUST_K",
    "robust_estimator",
    "FAST_SETTINGS",
]
