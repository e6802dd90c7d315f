#!/usr/bin/env python3
"""Plaza1 and Plaza2 with the ranging radios' fitted model, against the default import.

For each run the range model (``fgslam calibrate``: scale, bias, σ, outliers, correlation in
time; slamio/noise/range.py) is fitted on the *other* run and applied at import
(``fgslam import plazaN OUT --noise OTHER.json``). Then the EKF, ``isam2`` and ``isam2-fast`` run and
the batch optimum is solved, as ``fgslam run`` does. Printed per run and import:

* ATE against GPS without alignment (what ``fgslam run`` reports: pose 0 is pinned at the
  first GPS pose and heading), and after a rigid SE(2) alignment, with its rotation. With
  ranges to beacons whose positions are unknown, a rotation of the whole solution about
  pose 0 changes no range: only the start heading fixes it, and Plaza1's GPS "heading" is
  its dead-reckoned heading. The unaligned ATE is dominated by that rotation;
* NIS (1 degree of freedom per range) of the EKF and of iSAM2's online prediction: mean
  and share inside the 95 % χ²(1) band;
* NEES of the online positions against GPS (2 degrees of freedom: the truth has no
  heading): share inside the 95 % χ²(2) band.

    python -m scripts.plaza_range_model            # ~1 min
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np


from fgslam.compare import align_se2, apply_se2, compute_metrics  # noqa: E402
from fgslam.runner import compare_log  # noqa: E402
from slamio.datasets.plaza import import_plaza  # noqa: E402
from slamio.log import RunLog  # noqa: E402
from slamio.noise.fit_truth import fit_noise_model  # noqa: E402

RUNS = ("plaza1", "plaza2")
ESTIMATORS = ("ekf", "isam2", "isam2-fast", "dead_reckoning")


def as_log(run: str, header, records) -> RunLog:
    return RunLog(run, header, tuple(records), False)


def fitted_models() -> dict:
    """Run → the noise model fitted on it (its observation part is the range model)."""
    return {run: fit_noise_model([as_log(run, *import_plaza(run))]) for run in RUNS}


def score(log: RunLog) -> dict:
    """``fgslam run``'s metrics per estimator (and ``batch``), plus ``ate_aligned_m`` and the
    alignment's ``rotation_deg``."""
    comparison = compare_log(log, ESTIMATORS)
    metrics = compute_metrics(comparison.runs, comparison.reference, log_path=log.path)
    truth = comparison.reference.trajectory[:, :2]
    for run in comparison.runs:
        final = np.asarray(run.final)[:, :2]
        rotation, translation = align_se2(final, truth)
        aligned = apply_se2(final, rotation, translation)
        metrics[run.name]["ate_aligned_m"] = float(np.sqrt(np.mean(np.sum((aligned - truth) ** 2, axis=1))))
        metrics[run.name]["rotation_deg"] = math.degrees(rotation)
    return metrics


def measure() -> dict:
    """``results[(run, "default" | "fitted")]`` (:func:`score`), the fitted ``models``'
    observation parts, their fit ``reports`` and each run's GT heading ``turn_deg``."""
    models = fitted_models()
    results = {}
    for run in RUNS:
        other = RUNS[1 - RUNS.index(run)]
        results[(run, "default")] = score(as_log(run, *import_plaza(run)))
        results[(run, "fitted")] = score(as_log(run, *import_plaza(run, range_model=models[other])))
    return {"results": results, "models": {r: m.observation for r, m in models.items()},
            "reports": {r: m.fit_report["observation"] for r, m in models.items()},
            "turn_deg": {r: _gt_turn_deg(r) for r in RUNS}}


def _gt_turn_deg(run: str) -> float:
    """The angle every ``GT`` heading is turned by (the start heading from the GPS track
    minus the first ``GT`` heading, after Plaza2's π)."""
    from scipy.io import loadmat

    from slamio.datasets.plaza import gps_start_heading_rad, gt_heading_offset_rad, plaza_files
    from slamio.geometry import wrap_angle

    dr_path, _, mat_path = plaza_files(run)
    gt = np.asarray(loadmat(str(mat_path))["GT"], dtype=float)
    if abs(gt_heading_offset_rad(gt)) > math.pi / 2:
        gt[:, 3] = wrap_angle(gt[:, 3] + math.pi)
    return math.degrees(wrap_angle(gps_start_heading_rad(gt, np.loadtxt(dr_path)) - gt[0, 3]))


def _f(value, digits=2, scale=1.0) -> str:
    return "–" if value is None else f"{value * scale:.{digits}f}"


def main(argv=None) -> int:
    argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                            epilog="No options: it imports both runs from the gtsam wheel (about a minute).").parse_args(argv)
    measured = measure()
    for run, model in measured["models"].items():
        report = measured["reports"][run]
        print(f"{run}: measured = {model.range_scale:.4f} x distance + {model.range_bias_m:+.3f} m, "
              f"sigma {model.range_sigma_m:.3f} m (+{model.range_sigma_per_m:.4f} x distance), "
              f"outliers {model.outlier_rate:.2%}, correlated share {model.correlated_share:.2f}; "
              f"constant-offset fit: median {report['constant_offset_fit']['median_offset_m']} m, "
              f"spread {report['constant_offset_fit']['robust_spread_m']} m")
    print()
    print("| run | import | estimator | ATE m | ATE aligned m | rotation deg | map RMSE m | NIS mean | NIS in % | NEES in % |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for (run, kind), metrics in measured["results"].items():
        for name in (*ESTIMATORS, "batch"):
            m = metrics[name]
            print(f"| {run} | {kind} | {name} | {_f(m['ate_rmse_m'])} | {_f(m['ate_aligned_m'])} | "
                  f"{_f(m['rotation_deg'], 1)} | {_f(m.get('map_rmse_m'))} | {_f(m.get('nis_mean'))} | "
                  f"{_f(m.get('nis_inside_95'), 1, 100.0)} | {_f(m.get('nees_inside_95'), 1, 100.0)} |")
    print()
    for run, turn in measured["turn_deg"].items():
        print(f"{run}: the start heading from the GPS track is the first GT heading (turned round in Plaza2) "
              f"{turn:+.2f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
