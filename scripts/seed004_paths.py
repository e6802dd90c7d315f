#!/usr/bin/env python3
"""Seed 004's experiment: does the octagon path map the arena better than the square?

Seed 004 (docs/estimators.md, ``ekf-s004``) drove its robot around a 10 ft arena with 8
AprilTags on a square and on an octagon path and reports that the octagon's map is more
accurate "because the robot views the AprilTags from much more angles". This script
simulates both paths for every seed with the tag noise measured on real and rendered
images (``--tag-noise measured``: range, bearing and yaw σ depending on distance and
viewing angle, slamio/camera/tag_noise.py), runs ``ekf-s004`` as written, ``ekf`` and
``isam2`` on each log, and prints per seed the map error (RMSE of the tag positions after
the SE(2) alignment of the comparison) and ATE, then per estimator how many seeds the
octagon's map is the better one and the medians. It also counts, per path, the tag
sightings and the spread of viewing angles they come from (the mechanism the paper names).

    .venv/bin/python -m scripts.seed004_paths --seeds 1-20 --jobs 2

docs/seeds.md quotes its output.
"""

from __future__ import annotations

import os

from scripts.common import one_blas_thread

one_blas_thread(force=False)

import argparse  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from fgslam.compare import compute_metrics  # noqa: E402
from fgslam.runner import compare_log  # noqa: E402
from slamio.log import Observation, TruthLandmark, TruthPose, read_log, write_log  # noqa: E402
from slamio.sim import simulate  # noqa: E402
from scripts.common import parse_seeds  # noqa: E402

ESTIMATORS = ("ekf-s004", "ekf", "isam2")
PATHS = ("arena-square", "arena-octagon")


def viewing_angles_deg(records) -> dict[int, list[float]]:
    """Per tag, the true signed viewing angles (degrees) of its sightings: the mechanism's variable.

    The angle between the tag's face normal and the direction from the tag to the robot, from
    the true pose and the true tag (not the noisy measurements, whose noise would widen it).
    """
    tags = {r.landmark_id: r for r in records if isinstance(r, TruthLandmark)}
    out: dict[int, list[float]] = {}
    pose = None
    for r in records:
        if isinstance(r, TruthPose):
            pose = r
        elif isinstance(r, Observation):
            tag = tags[r.landmark_id]
            to_robot = math.atan2(pose.y_m - tag.y_m, pose.x_m - tag.x_m)
            d = tag.yaw_rad - to_robot
            out.setdefault(r.landmark_id, []).append(math.degrees(math.atan2(math.sin(d), math.cos(d))))
    return out


def one_run(scenario: str, seed: int, tag_noise: str) -> dict:
    header, records = simulate(scenario, seed, tag_noise=tag_noise)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "run.jsonl")
        write_log(path, header, records)
        result = compare_log(read_log(path), ESTIMATORS, consistency=False)
        metrics = compute_metrics(result.runs, result.reference, log_path=path)
    views = viewing_angles_deg(records)
    spread = float(np.median([np.std(v) for v in views.values()]))
    span = float(np.median([np.percentile(v, 95) - np.percentile(v, 5) for v in views.values()]))
    row = {"scenario": scenario, "seed": seed, "sightings": sum(len(v) for v in views.values()),
           "view_spread_deg": spread, "view_span_deg": span}
    for name in ESTIMATORS:
        row[name] = (metrics[name]["map_rmse_m"], metrics[name]["ate_rmse_m"])
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", default="1-20", help="range '1-20' or list '1,4,7' (default 1-20)")
    parser.add_argument("--tag-noise", choices=("measured", "nominal"), default="measured")
    parser.add_argument("--jobs", type=int, default=1, help="parallel processes (default 1)")
    args = parser.parse_args()
    seeds = parse_seeds(args.seeds)
    jobs = [(p, s) for s in seeds for p in PATHS]
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows = list(pool.map(one_run, [j[0] for j in jobs], [j[1] for j in jobs], [args.tag_noise] * len(jobs)))
    by = {(r["scenario"], r["seed"]): r for r in rows}

    print(f"tag noise: {args.tag_noise}; seeds {seeds[0]}..{seeds[-1]} ({len(seeds)})")
    print("seed | " + " | ".join(f"{e} map sq / oct m | {e} ATE sq / oct m" for e in ESTIMATORS))
    for s in seeds:
        sq, oc = by[("arena-square", s)], by[("arena-octagon", s)]
        cells = [f"{sq[e][0]:.4f} / {oc[e][0]:.4f} | {sq[e][1]:.4f} / {oc[e][1]:.4f}" for e in ESTIMATORS]
        print(f"{s:>4} | " + " | ".join(cells))
    print()
    for p in PATHS:
        rs = [by[(p, s)] for s in seeds]
        print(f"{p}: sightings per run median {statistics.median(r['sightings'] for r in rs):.0f}, "
              f"per tag, viewing angles' std median {statistics.median(r['view_spread_deg'] for r in rs):.1f}°, "
              f"5–95 % span median {statistics.median(r['view_span_deg'] for r in rs):.1f}°")
    print()
    print("| estimator | octagon map better | median map square / octagon m | octagon ATE better "
          "| median ATE square / octagon m |")
    print("|---|---:|---:|---:|---:|")
    for e in ESTIMATORS:
        sq = [by[("arena-square", s)][e] for s in seeds]
        oc = [by[("arena-octagon", s)][e] for s in seeds]
        map_wins = sum(o[0] < q[0] for o, q in zip(oc, sq))
        ate_wins = sum(o[1] < q[1] for o, q in zip(oc, sq))
        print(f"| {e} | {map_wins}/{len(seeds)} | {statistics.median(q[0] for q in sq):.4f} / "
              f"{statistics.median(o[0] for o in oc):.4f} | {ate_wins}/{len(seeds)} | "
              f"{statistics.median(q[1] for q in sq):.4f} / {statistics.median(o[1] for o in oc):.4f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
