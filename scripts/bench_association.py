"""Smoother data association on logs without ids: association score and ATE vs the same log with ids.

Usage: python -m scripts.bench_association OUTDIR SCENARIO[,SCENARIO...] SEEDS [OUTLIERS [ESTIMATOR]]
(e.g. ``/tmp/a arena-octagon,cylinders 1-5 0.1``). Makes the logs with ``fgslam sim``.
Or: python -m scripts.bench_association --pair IDS.jsonl HIDDEN.jsonl ESTIMATOR[,ESTIMATOR...]
for two existing logs (e.g. ``fgslam import mrclam ... [--hide-ids]``).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from fgslam.compare import ate_rmse_m
from fgslam.runner import ESTIMATORS, run_estimator, truth_trajectory
from scripts.common import parse_seeds
from slamio.log import read_log


def sim(out: Path, scenario: str, seed: int, outliers: float, hide: bool) -> Path:
    name = f"{scenario}-{seed}-{outliers}-{'hid' if hide else 'ids'}.jsonl"
    path = out / name
    if not path.exists():
        cmd = [sys.executable, "-m", "fgslam.cli", "sim", scenario, "--seed", str(seed), "--out", str(path)]
        if hide:
            cmd.append("--hide-ids")
        if outliers:
            cmd += ["--outliers", str(outliers)]
        subprocess.run(cmd, check=True, capture_output=True)
    return path


def ate(path: Path, estimator: str):
    log = read_log(path)
    steps = log.steps()
    run, est = run_estimator(ESTIMATORS[estimator](log.header), steps, covariances=False)
    truth, has = truth_trajectory(steps)
    return ate_rmse_m(run.final, truth, has_pose=has), run.association, est


def pair(ids: str, hidden: str, estimators: str) -> None:
    for estimator in estimators.split(","):
        ids_ate, _, _ = ate(Path(ids), estimator)
        hid_ate, score, est = ate(Path(hidden), estimator)
        print(f"{Path(hidden).name} {estimator} | {ids_ate:.4f} | {hid_ate:.4f} | {hid_ate / ids_ate:.3f} | "
              f"{score.observations} {score.correct} {score.wrong} {score.rejected} {score.landmarks_created} "
              f"{len(score.duplicate_keys)} {getattr(est, 'association_counts', '')}", flush=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     epilog="--pair IDS.jsonl HIDDEN.jsonl ESTIMATOR[,...] scores two existing logs")
    parser.add_argument("--pair", nargs=3, metavar=("IDS", "HIDDEN", "ESTIMATORS"),
                        help="two existing logs of one run (with ids, ids hidden) and the estimators to run")
    parser.add_argument("outdir", nargs="?", type=Path, help="folder for the simulated logs (made if missing)")
    parser.add_argument("scenarios", nargs="?", help="SCENARIO[,SCENARIO...], e.g. arena-octagon,cylinders")
    parser.add_argument("seeds", nargs="?", type=parse_seeds, help="N-M or N,N,...")
    parser.add_argument("outliers", nargs="?", type=float, default=0.0, help="share of misdetections (default 0)")
    parser.add_argument("estimator", nargs="?", default="isam2", choices=sorted(ESTIMATORS))
    args = parser.parse_args(argv)
    if args.pair:
        pair(*args.pair)
        return
    if args.seeds is None:
        parser.error("give OUTDIR SCENARIO[,SCENARIO...] SEEDS, or --pair IDS HIDDEN ESTIMATORS")
    args.outdir.mkdir(parents=True, exist_ok=True)
    print("scenario seed outliers | ATE ids m | ATE hidden m | ratio | obs correct wrong rejected created dup")
    for scenario in args.scenarios.split(","):
        for seed in args.seeds:
            ids_ate, _, _ = ate(sim(args.outdir, scenario, seed, args.outliers, False), args.estimator)
            hid_ate, score, est = ate(sim(args.outdir, scenario, seed, args.outliers, True), args.estimator)
            wrong = score.observations - score.correct - score.rejected
            print(f"{scenario} {seed} {args.outliers} | {ids_ate:.4f} | {hid_ate:.4f} | {hid_ate / ids_ate:.3f} | "
                  f"{score.observations} {score.correct} {wrong} {score.rejected} {score.landmarks_created} "
                  f"{len(score.duplicate_keys)} {getattr(est, 'association_counts', '')}", flush=True)


if __name__ == "__main__":
    main()
