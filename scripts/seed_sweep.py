#!/usr/bin/env python3
"""How robust is a result over random seeds? Simulate SCENARIO for several seeds, run every
estimator, and print per-seed ATEs plus how often each claim of the skeleton holds.

    python -m scripts.seed_sweep arena-octagon --seeds 0-9
    python -m scripts.seed_sweep grid --landmarks 200 --seeds 0-4 --jobs 2

One seed is one draw: errors are strongly correlated in time, so a single run is a handful
of independent samples at best. README.md quotes this script's output.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor

from fgslam.compare import compute_metrics
from fgslam.runner import compare_log
from slamio.log import read_log, write_log
from slamio.sim import SCENARIOS, simulate
from scripts.common import parse_seeds


def one_seed(scenario: str, seed: int, landmarks: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "run.jsonl")
        write_log(path, *simulate(scenario, seed, landmarks=landmarks))
        result = compare_log(read_log(path))
        m = compute_metrics(result.runs, result.reference, log_path=path)
    return {"seed": seed, **{k: m[k] for k in ("ekf", "isam2", "batch", "dead_reckoning")}}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scenario", choices=SCENARIOS)
    parser.add_argument("--seeds", default="0-9", help="range '0-9' or list '1,4,7' (default 0-9)")
    parser.add_argument("--landmarks", type=int, default=200, help="grid only (default 200)")
    parser.add_argument("--jobs", type=int, default=1, help="parallel processes (default 1)")
    args = parser.parse_args()
    seeds = parse_seeds(args.seeds)

    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows = list(pool.map(one_seed, [args.scenario] * len(seeds), seeds, [args.landmarks] * len(seeds)))

    print(f"{args.scenario}" + (f" --landmarks {args.landmarks}" if args.scenario == "grid" else ""))
    print("seed  ATE final m: ekf   isam2   batch   dead_rec | ATE online m: ekf   isam2 | time s: ekf  isam2")
    for r in rows:
        e, i, b, d = r["ekf"], r["isam2"], r["batch"], r["dead_reckoning"]
        print(
            f"{r['seed']:>4}  {e['ate_rmse_m']:14.4f} {i['ate_rmse_m']:7.4f} {b['ate_rmse_m']:7.4f} "
            f"{d['ate_rmse_m']:8.4f} | {e['ate_online_rmse_m']:16.4f} {i['ate_online_rmse_m']:7.4f} "
            f"| {e['time_total_s']:11.2f} {i['time_total_s']:6.2f}"
        )

    def share(claim) -> str:
        return f"{sum(claim(r) for r in rows)}/{len(rows)}"

    def mean(name: str, key: str) -> float:
        return statistics.fmean(r[name][key] for r in rows)

    print(f"mean ATE final  m: ekf {mean('ekf', 'ate_rmse_m'):.4f}  isam2 {mean('isam2', 'ate_rmse_m'):.4f}  "
          f"batch {mean('batch', 'ate_rmse_m'):.4f}  dead reckoning {mean('dead_reckoning', 'ate_rmse_m'):.4f}")
    print(f"mean ATE online m: ekf {mean('ekf', 'ate_online_rmse_m'):.4f}  isam2 {mean('isam2', 'ate_online_rmse_m'):.4f}")
    print("seeds where iSAM2 final ATE < EKF's:           " + share(lambda r: r["isam2"]["ate_rmse_m"] < r["ekf"]["ate_rmse_m"]))
    print("seeds where iSAM2 online ATE <= EKF's online:  "
          + share(lambda r: r["isam2"]["ate_online_rmse_m"] <= r["ekf"]["ate_online_rmse_m"]))
    print("seeds where iSAM2 final within 5 % of batch:   "
          + share(lambda r: abs(r["isam2"]["ate_rmse_m"] - r["batch"]["ate_rmse_m"]) <= 0.05 * r["batch"]["ate_rmse_m"]))
    print("seeds where all < dead reckoning / 3:          "
          + share(lambda r: max(r[k]["ate_rmse_m"] for k in ("ekf", "isam2", "batch")) < r["dead_reckoning"]["ate_rmse_m"] / 3))
    return 0


if __name__ == "__main__":
    sys.exit(main())
