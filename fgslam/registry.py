"""The one registry of estimators: every name ``--estimators`` accepts, for 2-D and 3-D logs.

Each :class:`EstimatorEntry` says its user-visible name, the dimension of log it takes (2:
planar landmark logs; 3: seed 003's stereo + IMU logs), one line of help, whether its graph
can start the batch solve, and how to build it. ``fgslam run``, ``check``, ``bench``, the
help texts (:mod:`fgslam.cli.estimators`), :mod:`fgslam.runner` and :mod:`fgslam.runner3d`
all read it. No estimator code is imported here: a factory imports its estimator when it is
called, so ``fgslam --help`` stays fast.

A planar factory takes the log's :class:`slamio.log.Header`; a 3-D factory takes the stereo
rig of the log's header (:class:`slamio.log.StereoCalibration`: ``K``, ``baseline_m``,
``cam_T_imu``) and the noise its records state (``slamio.datasets.seed003.StereoImuNoise``),
as :func:`fgslam.runner3d.prepare_log3d` reads them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

from slamio.errors import FgslamError

__all__ = [
    "EstimatorEntry", "REGISTRY", "DEFAULTS", "BENCH_DEFAULTS", "CHECK_DEFAULTS", "names_for", "help_for",
    "isam2_names", "entry", "build", "parse_names", "expected_outlier_kernel",
]


@dataclass(frozen=True)
class EstimatorEntry:
    """One estimator: its name, the dimension of log it takes, its help and its factory."""

    name: str
    dimension: int  # 2 (planar logs) or 3 (stereo + IMU logs)
    help: str
    factory: Callable[..., object]  # 2-D: factory(header); 3-D: factory(rig, noise)
    isam2: bool = False  # a factor-graph smoother the batch solve can start from


def expected_outlier_kernel(header) -> str | None:
    """``"dcs"`` when the log expects outliers (:func:`slamio.noise.model.log_expects_outliers`:
    a fitted noise model's outlier rate, or a simulator's), else None (least squares).

    A noise model fitted by ``fgslam calibrate`` carries the share of readings beyond its
    5σ gate (``noise.observation.outlier_rate``; MRCLAM: 0.3–1.6 %, misread barcodes).
    Where it is above zero, plain least squares is the wrong model: on MRCLAM Dataset 6
    robots 3 and 5 a handful of misread barcodes take plain iSAM2 to 2.6 / 2.4 m ATE, DCS
    to 0.07 / 0.5 m (docs/datasets-mrclam-rosbag.md). DCS leaves every residual within
    3.7σ at full weight, so it costs nothing on clean readings.
    """
    from slamio.noise.model import log_expects_outliers

    return "dcs" if log_expects_outliers(header) else None


def _named(estimator, name: str):
    estimator.name = name
    return estimator


# --------------------------------------------------------------------------- planar factories


def _ekf(association: str | None = None, fej: bool = False, invariant: bool = False):
    def factory(header):
        from ekf import EkfSlam, FejEkfSlam, InvariantEkfSlam

        if fej:
            return FejEkfSlam(header)
        if invariant:
            return InvariantEkfSlam(header)
        return EkfSlam(header) if association is None else EkfSlam(header, association=association)
    return factory


def _seed(class_name: str):
    def factory(header):
        import ekf

        return getattr(ekf, class_name)(header)
    return factory


def _isam2(name: str | None = None, **settings):
    def factory(header):
        from fgslam.smoother import FAST_SETTINGS, Isam2Smoother

        if name == "isam2":
            return _named(Isam2Smoother(header, robust=expected_outlier_kernel(header)), name)
        if name == "isam2-fast":
            return _named(Isam2Smoother(header, **FAST_SETTINGS), name)
        return Isam2Smoother(header, **settings)
    return factory


def _dead_reckoning(header):
    from ekf import DeadReckoning

    return DeadReckoning(header)


# --------------------------------------------------------------------------- 3-D factories


def _ekf_s003(figures: bool = False):
    def factory(rig, noise):
        from ekf.stereo_imu_ekf import AS_THE_FIGURES_SHOW, EkfS003

        return EkfS003(rig.K, rig.baseline_m, rig.cam_T_imu, noise, **(AS_THE_FIGURES_SHOW if figures else {}))
    return factory


def _vio(first_estimates: bool = False):
    def factory(rig, noise):
        from ekf.vio import VioEkf

        if first_estimates:
            return VioEkf(rig.K, rig.baseline_m, rig.cam_T_imu, noise, first_estimates=True)
        return VioEkf(rig.K, rig.baseline_m, rig.cam_T_imu, noise)
    return factory


def _isam2_3d(rig, noise):
    from fgslam.smoother3d import StereoIsam2  # imports gtsam

    return StereoIsam2(rig.K, rig.baseline_m, rig.cam_T_imu, noise)


_ENTRIES = (
    EstimatorEntry("ekf", 2, "textbook EKF-SLAM; JCBB data association for observations without an id", _ekf()),
    EstimatorEntry("ekf-nn", 2, "the same EKF with Mahalanobis-gated nearest-neighbour association", _ekf("nn")),
    EstimatorEntry("ekf-fej", 2, "the same EKF with first-estimates Jacobians (the global heading stays "
                   "unobservable)", _ekf(fej=True)),
    EstimatorEntry("ekf-inv", 2, "the same EKF with the right-invariant error (Barrau and Bonnabel): the global heading "
                   "stays unobservable with every Jacobian at the latest estimate", _ekf(invariant=True)),
    EstimatorEntry("ekf-s000", 2, "seed 000's linear KF (Trinity College, Create + Kinect), as written",
                   _seed("EkfS000")),
    EstimatorEntry("ekf-s001", 2, "seed 001's EKF (GoPiGo, forward/rotate moves, nearest neighbour), as written",
                   _seed("EkfS001")),
    EstimatorEntry("ekf-s004", 2, "seed 004's KF over robot and AprilTag poses, as written", _seed("EkfS004")),
    EstimatorEntry("isam2", 2, "GTSAM iSAM2 factor-graph smoother (the batch solve starts from its result; DCS "
                   "on the landmark factors when the log expects outliers)",
                   _isam2("isam2"), isam2=True),
    EstimatorEntry("isam2-fast", 2, "iSAM2 for long runs/large maps: keyframes, one update per 50 steps",
                   _isam2("isam2-fast"), isam2=True),
    EstimatorEntry("isam2-tags", 2, "iSAM2 with AprilTags as Pose2 landmarks (relative-pose factors use the tag "
                   "yaw)", _isam2(tags=True), isam2=True),
    EstimatorEntry("isam2-huber", 2, "iSAM2 with a Huber kernel on landmark factors (robust to outliers)",
                   _isam2(robust="huber"), isam2=True),
    EstimatorEntry("isam2-cauchy", 2, "iSAM2 with a Cauchy kernel on landmark factors (robust to outliers)",
                   _isam2(robust="cauchy"), isam2=True),
    EstimatorEntry("isam2-tukey", 2, "iSAM2 with a Tukey kernel on landmark factors (misdetections get zero "
                   "weight)", _isam2(robust="tukey"), isam2=True),
    EstimatorEntry("isam2-dcs", 2, "iSAM2 with dynamic covariance scaling: least squares within 3.7 sigma, "
                   "outliers fade", _isam2(robust="dcs"), isam2=True),
    EstimatorEntry("dead_reckoning", 2, "odometry alone: the baseline", _dead_reckoning),
    EstimatorEntry("ekf-s003", 3, "seed 003's EKF (stereo + IMU, pose from the IMU alone, per-landmark updates), "
                   "as written", _ekf_s003()),
    EstimatorEntry("ekf-s003-figures", 3, "the same with eq. 16's and eq. 1's typos read as its figures require",
                   _ekf_s003(figures=True)),
    EstimatorEntry("ekf-vio", 3, "textbook visual-inertial EKF-SLAM on SE(3): pose and landmarks updated jointly; "
                   "landmarks out of view for 10 steps are marginalised (at most 300 kept)", _vio()),
    EstimatorEntry("ekf-vio-fej", 3, "the same keeping the unobservable directions of its first estimates (FEJ, "
                   "projected Jacobians): NEES in band on most drives", _vio(first_estimates=True)),
    EstimatorEntry("isam2-3d", 3, "GTSAM iSAM2 on Pose3 + stereo factors + IMU between factors (the batch solve "
                   "starts from it)", _isam2_3d, isam2=True),
)

#: name → entry, for 2-D and 3-D logs (names are unique across both).
REGISTRY: dict[str, EstimatorEntry] = {e.name: e for e in _ENTRIES}
#: What ``fgslam run`` runs when no estimator is named, by dimension of log.
DEFAULTS: dict[int, tuple[str, ...]] = {2: ("ekf", "isam2", "dead_reckoning"),
                                        3: ("ekf-s003", "ekf-vio", "ekf-vio-fej", "isam2-3d")}
#: What ``fgslam bench`` (Monte Carlo) runs when no estimator is named, by dimension of its scenario.
BENCH_DEFAULTS: dict[int, tuple[str, ...]] = {2: ("ekf", "isam2"), 3: ("ekf-vio", "ekf-vio-fej", "isam2-3d")}
#: What ``fgslam check`` checks when no estimator is named, by dimension.
CHECK_DEFAULTS: dict[int, str] = {2: "ekf", 3: "ekf-vio-fej"}


def names_for(dimension: int) -> list[str]:
    """The estimator names a log of ``dimension`` (2 or 3) takes, in registry order."""
    return [e.name for e in _ENTRIES if e.dimension == dimension]


def help_for(dimension: int) -> dict[str, str]:
    """name → one line of help, for the estimators of a ``dimension``-D log."""
    return {e.name: e.help for e in _ENTRIES if e.dimension == dimension}


def isam2_names(dimension: int) -> tuple[str, ...]:
    """The smoothers of a ``dimension``-D log the batch solve can start from."""
    return tuple(e.name for e in _ENTRIES if e.dimension == dimension and e.isam2)


def _what(dimension: int) -> str:
    return "a 3-D log" if dimension == 3 else "a planar log"


def entry(name: str, dimension: int) -> EstimatorEntry:
    """The entry of ``name`` for a ``dimension``-D log; an unknown or wrong-dimension name is a
    one-line :class:`FgslamError` listing the valid names for that log."""
    found = REGISTRY.get(name)
    if found is None or found.dimension != dimension:
        raise FgslamError(_unknown_message([name], dimension))
    return found


def build(name: str, dimension: int, *args):
    """A fresh estimator ``name`` (2-D: ``build(name, 2, header)``; 3-D: ``build(name, 3, rig, noise)``).
    A 3-D estimator is always named ``name``."""
    estimator = entry(name, dimension).factory(*args)
    return _named(estimator, name) if dimension == 3 else estimator


def _unknown_message(unknown: Sequence[str], dimension: int) -> str:
    other = [n for n in unknown if n in REGISTRY]
    prefix = "unknown estimator(s) for a 3-D log: " if dimension == 3 else "unknown estimator(s) "
    message = f"{prefix}{', '.join(unknown) or '(none given)'}; choose from {', '.join(names_for(dimension))} " \
              "(comma-separated)"
    if other:
        message += (f"; {', '.join(other)} {'takes' if len(other) == 1 else 'take'} "
                    f"{_what(REGISTRY[other[0]].dimension)}, this is {_what(dimension)}")
    return message


def parse_names(text: str | None, dimension: int, *, need_isam2: bool = True) -> list[str]:
    """``"ekf,isam2"`` → ``["ekf", "isam2"]`` for a ``dimension``-D log (None: its defaults),
    rejecting unknown, wrong-dimension or missing names and (with ``need_isam2``, for the batch
    solve) a list without a smoother the batch solve can start from. Duplicates go."""
    names = list(DEFAULTS[dimension]) if text is None else [n.strip() for n in text.split(",") if n.strip()]
    valid = names_for(dimension)
    unknown = [n for n in names if n not in valid]
    if unknown or not names:
        raise FgslamError(_unknown_message(unknown, dimension))
    smoothers = isam2_names(dimension)
    if need_isam2 and not any(n in smoothers for n in names):
        if dimension == 3:
            raise FgslamError("the batch solve (the reference without truth) starts from iSAM2's result: keep "
                              "isam2-3d")
        raise FgslamError(
            "the batch solve (the smoothed reference) starts from iSAM2's result: keep isam2 (or one of "
            f"{', '.join(n for n in smoothers if n != 'isam2')}) in --estimators"
        )
    return list(dict.fromkeys(names))
