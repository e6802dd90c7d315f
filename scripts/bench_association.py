"""Smoother data association on logs without ids: association score and ATE vs the same log with ids.

Usage: python scripts/bench_association.py OUTDIR SCENARIO[,SCENARIO...] SEEDS [OUTLIERS [ESTIMATOR]]
(e.g. ``/tmp/a arena-octagon,cylinders 1-5 0.1``). Makes the logs with ``fgslam sim``.
Or: python scripts/bench_association.py --pair IDS.jsonl HIDDEN.jsonl ESTIMATOR[,ESTIMATOR...]
for two existing logs (e.g. ``fgslam import mrclam ... [--hide-ids]``).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from fgslam.compare import ate_rmse_m
from fgslam.runner import ESTIMATORS, run_estimator, truth_trajectory
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


def main() -> None:
    if sys.argv[1] == "--pair":
        pair(*sys.argv[2:5])
        return
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    scenarios = sys.argv[2].split(",")
    a, _, b = sys.argv[3].partition("-")
    seeds = range(int(a), int(b or a) + 1)
    outliers = float(sys.argv[4]) if len(sys.argv) > 4 else 0.0
    estimator = sys.argv[5] if len(sys.argv) > 5 else "isam2"
    print("scenario seed outliers | ATE ids m | ATE hidden m | ratio | obs correct wrong rejected created dup")
    for scenario in scenarios:
        for seed in seeds:
            ids_ate, _, _ = ate(sim(out, scenario, seed, outliers, False), estimator)
            hid_ate, score, est = ate(sim(out, scenario, seed, outliers, True), estimator)
            wrong = score.observations - score.correct - score.rejected
            print(f"{scenario} {seed} {outliers} | {ids_ate:.4f} | {hid_ate:.4f} | {hid_ate / ids_ate:.3f} | "
                  f"{score.observations} {score.correct} {wrong} {score.rejected} {score.landmarks_created} "
                  f"{len(score.duplicate_keys)} {getattr(est, 'association_counts', '')}", flush=True)


if __name__ == "__main__":
    main()
