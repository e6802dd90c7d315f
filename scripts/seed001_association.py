#!/usr/bin/env python3
"""When does seed 001's nearest-neighbour association fail? Landmark spacing × noise.

Seed 001 (docs/estimators.md, ``ekf-s001``) associates each observation with the landmark
whose mean is nearest (Euclidean, a fixed gate — 0.5 m by default) to where the current
pose estimate puts it, and reports that this failed on its robot. This script simulates
the ``grid`` scenario with hidden landmark ids (``--landmarks`` landmarks on a square grid,
a lawnmower path, revisits) for each landmark spacing × noise scale (every random error
multiplied; the records keep the nominal σ), runs ``ekf-s001`` as written and the same filter
with its three non-association flaws removed (σ² in Q, the log's rotated motion
covariance, the arc motion model: only the nearest-neighbour rule left) and prints:

- the share of observations associated with the right landmark (median over seeds);
- the RMS error of the world point each observation gives from the *true* pose (the
  measurement's own scatter) and the filter's ATE (the pose's), both in metres.

Association fails where the spacing is no longer several times the sum of those two
errors, or where the gate cannot separate a landmark's own scatter from its neighbours.

    .venv/bin/python -m scripts.seed001_association --jobs 2

docs/seeds.md quotes its output.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread(force=False)

import argparse  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from ekf.signature_ekf import EkfS001  # noqa: E402
from fgslam.compare import ate_rmse_m  # noqa: E402
from fgslam.runner import run_estimator  # noqa: E402
from slamio.log import TruthLandmark, group_steps  # noqa: E402
from slamio.sim import simulate  # noqa: E402

VARIANTS = {
    "as written": {},
    "NN only": {"q_diagonal": "variance", "motion_noise": "log", "motion_model": "arc"},
}


def measurement_point_error_m(steps, truth_xy: dict[int, tuple[float, float]]) -> float:
    """RMS distance between each observation's world point from the true pose and its landmark."""
    squared = []
    for step in steps:
        x, y, th = step.truth.x_m, step.truth.y_m, step.truth.theta_rad
        for o in step.observations:
            a = th + o.bearing_rad
            lx, ly = truth_xy[o.truth_landmark_id]
            squared.append((x + o.range_m * math.cos(a) - lx) ** 2 + (y + o.range_m * math.sin(a) - ly) ** 2)
    return math.sqrt(sum(squared) / len(squared))


def one_run(spacing_m: float, noise_scale: float, seed: int, landmarks: int) -> dict:
    header, records = simulate("grid", seed, landmarks=landmarks, hide_ids=True, grid_spacing_m=spacing_m,
                               noise_scale=noise_scale)
    steps = group_steps(header, records)
    truth_xy = {r.landmark_id: (r.x_m, r.y_m) for r in records if isinstance(r, TruthLandmark)}
    truth_poses = np.array([(s.truth.x_m, s.truth.y_m, s.truth.theta_rad) for s in steps])
    row = {"spacing_m": spacing_m, "noise_scale": noise_scale, "seed": seed,
           "point_error_m": measurement_point_error_m(steps, truth_xy)}
    for name, choices in VARIANTS.items():
        run, _ = run_estimator(EkfS001(header, **choices), steps, covariances=False)
        a = run.association
        row[name] = (a.correct / a.observations, ate_rmse_m(run.final, truth_poses, align=False))
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spacings", default="0.25,0.5,1.0,1.5,2.0,3.0", help="landmark spacings, m")
    parser.add_argument("--noise-scales", default="0.5,1,2,4", help="noise scales")
    parser.add_argument("--seeds", type=int, default=3, help="seeds 1..N per cell (default 3)")
    parser.add_argument("--landmarks", type=int, default=36, help="grid landmarks (default 36, 6×6)")
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    spacings = [float(v) for v in args.spacings.split(",")]
    scales = [float(v) for v in args.noise_scales.split(",")]
    jobs = [(sp, ns, seed) for sp in spacings for ns in scales for seed in range(1, args.seeds + 1)]
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows = list(pool.map(one_run, *zip(*jobs), [args.landmarks] * len(jobs)))

    print(f"grid, {args.landmarks} landmarks, hidden ids, gate 0.5 m; medians over seeds 1..{args.seeds}")
    print("| spacing m | noise scale | point error m (measurement) | as written: correct / ATE m "
          "| NN only: correct / ATE m |")
    print("|---:|---:|---:|---:|---:|")
    for sp in spacings:
        for ns in scales:
            cell = [r for r in rows if r["spacing_m"] == sp and r["noise_scale"] == ns]
            med = {name: (statistics.median(r[name][0] for r in cell), statistics.median(r[name][1] for r in cell))
                   for name in VARIANTS}
            pe = statistics.median(r["point_error_m"] for r in cell)
            print(f"| {sp:.2f} | {ns:g} | {pe:.3f} | "
                  + " | ".join(f"{100 * med[n][0]:.1f} % / {med[n][1]:.3f}" for n in VARIANTS) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
