"""The verdict of a run: does the noise the log states fit what its measurements show?

Without ground truth a run can still tell whether its noise is right. At the batch optimum,
each noise group's whitened χ² (odometry, range, bearing) over its redundancy — its rows
minus what the solution absorbed, ``Σ (1 − h_jj)`` over the hat matrix's diagonal
(:mod:`slamio.noise.fit_self`) — is 1 when the stated σ fit the data and ``k²`` when they are
``k``× too small. The groups are read from the smoother's own graph by factor type:
``BetweenFactorPose2`` between two poses is odometry, ``BearingRangeFactor2D`` a bearing and
a range row, ``RangeFactor2D`` a range row; in a 3-D log ``BetweenFactorPose3`` between two
poses is the IMU ("imu") and ``GenericStereoFactor3D`` a stereo observation ("stereo").

A noise model is σ *and* an outlier rate (``outlier_rate``: the share of readings beyond the
5σ gate, :mod:`slamio.noise.fit_truth`), and the verdict checks them apart: a measurement
whose whitened error exceeds :data:`GATE_SIGMA` on any row (unweighted by a robust kernel)
is counted as an outlier of its group and left out of the group's χ² and redundancy; the
rest is the χ² the solution weighed (a robust kernel's weights in the whitened rows, as the
estimator saw them). For Gaussian noise one 3-row factor in ~600 000
is beyond the gate, so a log whose noise fits reads the same either way; a stereo drive with
mismatched tracks no longer reads "σ too small" because of them, and says how many there are.

:data:`FITS` is the band called "fits": σ off by less than √2 either way. The 95 % band of
χ²/r is also given, but with thousands of rows it is a few per cent wide and no real robot's
noise model is that exact; outside :data:`FITS`, the run says what to do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np

from fgslam.linearized import whitened_system
from slamio.chi2 import chi2_ppf
from slamio.noise.fit_self import hat_traces

__all__ = ["FITS", "GroupVerdict", "graph_verdict", "verdict_lines", "verdict_or_none"]

#: χ²/redundancy inside this band: the stated σ are within a factor √2 of what the data show.
FITS = (0.5, 2.0)
#: A measurement with a whitened error beyond this many σ on any row is an outlier.
GATE_SIGMA = 5.0
GROUPS = ("odometry", "range", "bearing", "imu", "stereo")


@dataclass(frozen=True)
class GroupVerdict:
    group: str
    chi2: float
    redundancy: float
    rows: int
    outliers: int = 0  # measurements beyond the gate, left out of chi2 and redundancy
    measurements: int = 0

    @property
    def ratio(self) -> float:
        return self.chi2 / self.redundancy if self.redundancy > 0 else math.nan

    @property
    def band95(self) -> tuple[float, float]:
        r = max(self.redundancy, 1e-9)
        return float(chi2_ppf(0.025, r) / r), float(chi2_ppf(0.975, r) / r)

    @property
    def sigma_factor(self) -> float:
        """How many times larger the σ should be (√ratio): > 1 when the stated σ are too small."""
        return math.sqrt(self.ratio) if self.ratio >= 0 else math.nan

    @property
    def fits(self) -> bool:
        return FITS[0] <= self.ratio <= FITS[1]

    def sentence(self) -> str:
        head = (f"{self.group}: chi2/dof {self.ratio:.2f} over {self.redundancy:.0f} dof "
                f"(95 % band {self.band95[0]:.2f}-{self.band95[1]:.2f})")
        if not math.isfinite(self.ratio):
            return f"{self.group}: no redundancy (nothing checks it)"
        if self.outliers:
            head += (f"; {self.outliers} of {self.measurements} ({100.0 * self.outliers / self.measurements:.1f} %) "
                     f"beyond {GATE_SIGMA:g} sigma, counted apart")
        if self.fits:
            return head + ": the stated noise fits"
        k = self.sigma_factor
        if k > 1.0:
            return head + f": the stated {self.group} sigma is ~{k:.1f}x too small"
        return head + f": the stated {self.group} sigma is ~{1.0 / k:.1f}x too large"

    def as_dict(self) -> dict:
        return {"chi2": self.chi2, "dof": self.redundancy, "rows": self.rows, "chi2_per_dof": self.ratio,
                "band95": list(self.band95), "fits": self.fits, "sigma_factor": self.sigma_factor,
                "outliers": self.outliers, "measurements": self.measurements}


def _group_of(factor) -> str:
    """The noise group of one factor ("" for none)."""
    between_poses = isinstance(factor, (gtsam.BetweenFactorPose2, gtsam.BetweenFactorPose3)) and all(
        gtsam.Symbol(k).chr() == ord("x") for k in factor.keys())
    if between_poses:
        return "odometry" if isinstance(factor, gtsam.BetweenFactorPose2) else "imu"  # a 3-D log's IMU increments
    if isinstance(factor, gtsam.BearingRangeFactor2D):
        return "bearing+range"
    if isinstance(factor, gtsam.RangeFactor2D):
        return "range"
    if isinstance(factor, gtsam.GenericStereoFactor3D):
        return "stereo"  # (u_L, u_R, v) of a stereo observation
    return ""


def _unweighted_whitened(factor, values: gtsam.Values) -> np.ndarray:
    """The factor's whitened error without a robust kernel's weight."""
    model = factor.noiseModel()
    if isinstance(model, gtsam.noiseModel.Robust):
        return np.asarray(model.unweightedWhiten(factor.unwhitenedError(values)), dtype=float)
    return np.asarray(factor.whitenedError(values), dtype=float)


def _rows(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values):
    """Per row of ``graph``'s whitened Jacobian: its group ("" for rows of none), whether its
    measurement is an outlier (by its unweighted whitened error), and the measurement's index."""
    groups, outlier, index = [], [], []
    for i in range(graph.size()):
        factor = graph.at(i)
        if factor is None:
            continue
        dim = int(factor.dim())
        group = _group_of(factor)
        rows = ["bearing", "range"] if group == "bearing+range" else [group] * dim
        beyond = bool(group) and bool(np.any(np.abs(_unweighted_whitened(factor, values)) > GATE_SIGMA))
        groups += rows
        outlier += [beyond] * dim
        index += [i] * dim
    return np.array(groups), np.array(outlier, dtype=bool), np.array(index)


def graph_verdict(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> dict[str, GroupVerdict]:
    """Per noise group present in ``graph``, its :class:`GroupVerdict` at ``values`` (the batch
    optimum)."""
    A, b = whitened_system(graph, values)
    groups, outlier, index = _rows(graph, values)
    if len(groups) != A.shape[0]:  # a factor type of unexpected rows: no verdict rather than a wrong one
        return {}
    present = [g for g in GROUPS if np.any(groups == g)]
    if not present:
        return {}
    onehot = np.stack([((groups == g) & ~outlier).astype(float) for g in present], axis=1)
    hat = hat_traces(A, onehot, columns_ordered=True)
    out = {}
    for g, h in zip(present, hat):
        rows = groups == g
        kept = rows & ~outlier
        out[g] = GroupVerdict(g, float(np.sum(b[kept] ** 2)), float(np.count_nonzero(kept) - h),
                              int(np.count_nonzero(kept)), outliers=len(np.unique(index[rows & outlier])),
                              measurements=len(np.unique(index[rows])))
    return out


def verdict_or_none(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> dict[str, GroupVerdict]:
    """:func:`graph_verdict`, or an empty verdict when the graph cannot be judged (its system is
    singular): what a run reports after its batch solve, 2-D and 3-D alike."""
    from slamio.noise.errors import NoiseModelError

    try:
        return graph_verdict(graph, values)
    except NoiseModelError:
        return {}


def verdict_lines(verdict: dict, noise_source: str | None) -> list[str]:
    """The lines ``fgslam run`` prints after its table (``verdict``: group → GroupVerdict or its
    dict)."""
    lines = ["noise verdict (batch solution; 1 = the stated noise fits):"]
    if noise_source:
        lines.append(f"  the log's noise: {noise_source}")
    bad = False
    for v in verdict.values():
        lines.append("  " + v.sentence())
        bad |= not v.fits
    learned = bool(noise_source) and noise_source.startswith("learned from this log")
    if bad and learned:
        lines.append("  the noise was learned from this log: what still does not fit is readings the fit left out "
                     "as outliers, or motion and readings the model does not describe")
    elif bad:
        lines.append("  to fix it: fgslam run LOG --noise self (learn the noise from this log), or fgslam calibrate "
                     "LOG... --without-truth --out noise.json and --noise noise.json")
    planar = [v for g, v in verdict.items() if g in ("odometry", "range", "bearing")]
    if sum(1 for v in planar if v.ratio > FITS[1]) >= 2:
        lines.append("  every group too small at once: is the sensor off the robot's centre? State where it sits "
                     "in the log header (sensor.pose_on_robot: [x_m, y_m, yaw_rad], docs/log-format.md)")
    return lines
