"""What each part of the MRCLAM noise model buys: ATE against Vicon, median over the robots.

Every variant uses, for robot k, a model fitted on the other robots (leave-one-out), with
one part switched back to the round default. Prints a markdown table (the one in
docs/datasets-mrclam-rosbag.md). Two worker processes; about five minutes on Dataset 6.

    .venv/bin/python -m scripts.experiments.ablation_mrclam ../shared/data/mrclam/MRCLAM_Dataset6
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import sys  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from ekf import EkfSlam  # noqa: E402
from fgslam.runner import ESTIMATORS, run_estimator  # noqa: E402
from slamio.datasets import mrclam  # noqa: E402
from slamio.log import RunLog  # noqa: E402
from slamio.noise.fit_truth import fit_noise_model  # noqa: E402
from slamio.noise.model import ObservationModel  # noqa: E402

from scripts.bench_mrclam import ate_pair_m  # noqa: E402

VARIANTS = {
    "round default noise (no model)": None,
    "+ fitted odometry (lag, scales, turn per metre, variance rates)": "odometry",
    "+ fitted camera model (depth, scale, bias, sigmas), no outlier handling": "no_outliers",
    "+ outlier handling (EKF gate, iSAM2 DCS), white readings": "white",
    "+ readings' error in time (the EKF's Gauss–Markov states): the full model": "full",
    "full model, EKF without its gate": "full_no_gate",
    "full model, zero-command blips integrated": "full_blips",
}


def _log(folder, k, model) -> RunLog:
    header, records = mrclam.import_mrclam(folder, k, model=model)
    return RunLog(f"robot{k}", header, tuple(records))


def one_robot(args) -> dict:
    folder, k, variant = args
    if variant == "full_blips":
        mrclam.MAX_ZERO_BLIP_S = 0.0
    raw = {j: _log(folder, j, None) for j in mrclam.ROBOT_SUBJECTS}
    model = None if variant is None else fit_noise_model([raw[j] for j in mrclam.ROBOT_SUBJECTS if j != k])
    if variant == "odometry":
        model = dataclasses.replace(model, observation=ObservationModel())
    elif variant in ("no_outliers", "white"):
        white = dataclasses.replace(model.observation, correlated_share=0.0, correlation_time_s=0.0)
        if variant == "no_outliers":
            white = dataclasses.replace(white, outlier_rate=0.0)
        model = dataclasses.replace(model, observation=white)
    log = raw[k] if model is None else _log(folder, k, model)
    steps = log.steps()
    mask = np.array([s.truth is not None for s in steps])
    truth = np.array([[s.truth.x_m, s.truth.y_m] if s.truth else [np.nan] * 2 for s in steps])
    ekf = EkfSlam(log.header, known_id_gate_probability=None) if variant in (None, "odometry", "no_outliers", "full_no_gate") \
        else EkfSlam(log.header)
    out = {}
    for name, est in (("ekf", ekf), ("isam2", ESTIMATORS["isam2"](log.header))):
        run, _ = run_estimator(est, steps, covariances=False)
        out[name] = ate_pair_m(run.final, truth, mask) + ate_pair_m(run.online, truth, mask)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("folder")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    print("| variant | EKF ATE m | iSAM2 final ATE m | iSAM2 online ATE m | EKF aligned | iSAM2 final aligned | iSAM2 online aligned |")
    print("|---|---|---|---|---|---|---|")
    with ProcessPoolExecutor(args.jobs) as pool:
        for label, variant in VARIANTS.items():
            rows = list(pool.map(one_robot, [(args.folder, k, variant) for k in mrclam.ROBOT_SUBJECTS]))
            med = lambda name, i: float(np.median([r[name][i] for r in rows]))  # noqa: E731
            print(f"| {label} | {med('ekf', 0):.3f} | {med('isam2', 0):.3f} | {med('isam2', 2):.3f} | "
                  f"{med('ekf', 1):.3f} | {med('isam2', 1):.3f} | {med('isam2', 3):.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
