"""slamio.noise: the one home of odometry and reading noise.

Modules, from the model out (nothing is re-exported here: import from the module):

* :mod:`slamio.noise.errors`    — :class:`~slamio.noise.errors.NoiseModelError`, the one
  error of this package (:class:`~slamio.noise.errors.NoiseModelFileError` when a file is
  to blame: exit status 2);
* :mod:`slamio.noise.model`     — the noise model a log states
  (:class:`~slamio.noise.model.NoiseModel`: odometry lag, scales and variance rates, the
  camera's range-bearing model) and its JSON file (``load_noise_model``,
  ``save_noise_model``);
* :mod:`slamio.noise.dead_reckoning` — a log's odometry as a chain of poses readable at any
  time, read both by the fits and by applying a model;
* :mod:`slamio.noise.apply`     — applying a model: one reading (``correct_observation``,
  ``correct_range``, used by the importers' ``--noise``) or a written log
  (``apply_noise_model``, ``fgslam run --noise``). Depends on no fit;
* :mod:`slamio.noise.fitting`   — what the fits against ground truth share: a log read
  against its truth and robust statistics;
* :mod:`slamio.noise.fit_truth` — fitting a model from logs with ground truth
  (``fgslam calibrate LOG.jsonl... --out noise.json``);
* :mod:`slamio.noise.range`     — its range-only part (ranging radios, Plaza);
* :mod:`slamio.noise.trials`    — seed 001's trial calibration: covariances from
  tape-measured forward/rotate/sensor trials (``fgslam calibrate TRIALS.csv``), the
  calibration file ``fgslam record`` and ``fgslam run --calibration`` read.

* :mod:`slamio.noise.fit_self`  — fitting without ground truth, from the log alone: the
  variance-component estimation (Förstner's update, a Fisher-scoring step, Hutchinson traces
  of the hat matrix) on the whitened system of a smoothed solution. The factor graph that
  supplies that system needs GTSAM, so it lives in :mod:`fgslam.self_calibration`
  (``fgslam calibrate LOG... --without-truth``, ``fgslam run LOG --noise self``), which turns
  the components into the same :class:`~slamio.noise.model.NoiseModel`.

Camera intrinsics are not noise: ``fgslam calibrate-camera`` (``slamio.camera``).

Imports point one way: ``errors`` ← ``model`` ← ``dead_reckoning``/``apply`` ←
``fitting`` ← ``range`` ← ``fit_truth``; ``fit_self`` needs only ``errors``; ``trials`` stands apart (it uses
:class:`slamio.create.odometry.OdometryNoise`, the Create's per-metre/per-radian
covariances).
"""
