"""Benchmark: the default ``isam2`` against an iSAM2 that updates at every step, and the EKF.

For each log, in one process with BLAS on one thread: the EKF; the reference — an iSAM2
that updates and checks relinearisation at every step with no online correction
(``update_every=1, relinearize_skip=1, online_correction=False``, and a tight wildfire threshold, 0.001, so its back-substitution is near-exact; ``--reference-skip``
changes the skip, since on Victoria Park skip 1 takes minutes); and each candidate
(``--set key=value`` keywords, several ``--candidate`` groups separated by ``;``). Prints,
per log and estimator: total time and its ratio to the EKF's, p99 step, online ATE (against
the log's truth where it has it, else against the batch optimum) and its ratio to the
reference's, final χ²/2 and its ratio to the batch optimum's.

Usage::

    .venv/bin/python -m scripts.bench_online arena:1-20
    .venv/bin/python -m scripts.bench_online victoria-park --reference-skip 10
    .venv/bin/python -m scripts.bench_online mrclam:/path/MRCLAM_Dataset6:1,3 plaza1
    .venv/bin/python -m scripts.bench_online mrclam-fitted:/path/MRCLAM_Dataset6:4 --robust dcs   # bench_mrclam.py's noise
    .venv/bin/python -m scripts.bench_online arena:1-3 --candidate "update_every=5" --candidate "update_every=20"
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from ekf import EkfSlam  # noqa: E402
from fgslam.compare import ate_rmse_m  # noqa: E402
from fgslam.runner import run_estimator  # noqa: E402
from fgslam.smoother import Isam2Smoother, batch_solve  # noqa: E402
from slamio.log import group_steps  # noqa: E402
from scripts.common import parse_assignments  # noqa: E402

#: The every-step iSAM2 the online ATE is compared with: an update and a relinearisation
#: check at every step, the newest pose read straight from iSAM2.
REFERENCE = {"update_every": 1, "relinearize_skip": 1, "online_correction": False, "wildfire_threshold": 0.001}


def logs(spec: str):
    """Yield (name, header, records) for one command-line source."""
    if spec.startswith("arena:"):
        from slamio.sim import simulate

        first, _, last = spec.split(":", 1)[1].partition("-")
        for seed in range(int(first), int(last or first) + 1):
            header, records = simulate("arena-octagon", seed)
            yield f"arena-octagon seed {seed}", header, records
    elif spec.startswith("arena-laps:"):  # one long drive: arena-laps:SEED:LAPS
        from slamio.sim import simulate

        seed, _, laps = spec.split(":", 1)[1].partition(":")
        header, records = simulate("arena-octagon", int(seed), laps=int(laps or 40))
        yield f"arena-octagon seed {seed}, {int(laps or 40)} laps", header, records
    elif spec == "victoria-park":
        from slamio.datasets.victoria_park import import_victoria_park

        yield spec, *import_victoria_park()
    elif spec in ("plaza1", "plaza2"):
        from slamio.datasets.plaza import import_plaza

        yield spec, *import_plaza(spec)
    elif spec.startswith("mrclam-fitted:"):  # each robot with noise fitted on the others, as bench_mrclam.py
        from scripts.bench_mrclam import leave_one_out, raw_logs

        folder, _, robots = spec.split(":", 1)[1].rpartition(":")
        raw = raw_logs(folder)
        for robot in robots.split(","):
            header, records, _ = leave_one_out(folder, int(robot), raw)
            yield f"{Path(folder).name} robot {robot} (noise fitted on the others)", header, records
    elif spec.startswith("mrclam:"):
        from slamio.datasets.mrclam import import_mrclam

        folder, _, robots = spec.split(":", 1)[1].rpartition(":")
        for robot in robots.split(","):
            yield f"{Path(folder).name} robot {robot}", *import_mrclam(folder, int(robot))
    elif spec.endswith(".jsonl") and Path(spec).is_file():  # a run log (fgslam import …), as fgslam run reads it
        from slamio.log import read_log

        log = read_log(spec)
        yield Path(spec).name, log.header, log.records
    else:
        raise SystemExit(f"unknown log {spec!r}: arena:A-B, arena-laps:SEED:LAPS, victoria-park, plaza1, plaza2, mrclam:FOLDER:R1,R2, "
                         "mrclam-fitted:FOLDER:R1,R2 or a run log's path (.jsonl)")


def parse_sets(text: str) -> dict:
    """``"a=1,b=(0.1,0.01)"`` → keywords (commas inside brackets belong to the value)."""
    items, depth, current = [], 0, ""
    for ch in text + ",":
        depth += (ch in "([") - (ch in ")]")
        if ch == "," and depth == 0:
            items.append(current.strip())
            current = ""
        else:
            current += ch
    return parse_assignments([item for item in items if item])


def truth_of(steps) -> tuple[np.ndarray, np.ndarray] | None:
    mask = np.array([s.truth is not None for s in steps])
    if not mask.any():
        return None
    xy = np.array([[s.truth.x_m, s.truth.y_m, s.truth.theta_rad] if s.truth else [np.nan] * 3 for s in steps])
    return xy, mask


def online_ate_m(online: np.ndarray, truth, batch_trajectory: np.ndarray) -> float:
    """ATE of the online poses: against the log's truth (``truth_of``) over the poses that
    have it, else against the batch optimum's trajectory."""
    if truth is None:
        return ate_rmse_m(online, batch_trajectory)
    xy, mask = truth
    return float(np.sqrt(np.mean(np.sum((online[mask, :2] - xy[mask, :2]) ** 2, axis=1))))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--candidate", action="append", default=None, metavar="K=V,K=V",
                    help="Isam2Smoother keywords of one candidate (default: the defaults)")
    ap.add_argument("--reference-skip", type=int, default=1)
    ap.add_argument("--no-reference", action="store_true",
                    help="skip the every-step reference (ratios are then to the first candidate)")
    ap.add_argument("--robust", default=None, help="robust kernel for every iSAM2 (e.g. dcs)")
    args = ap.parse_args(argv)
    candidates = [parse_sets(c) for c in (args.candidate or [""])]
    common = {"robust": args.robust} if args.robust else {}
    print("| log | estimator | total s | × EKF | p99 ms | updates | online ATE m | × reference | χ²/2 × batch |")
    print("|---|---|---|---|---|---|---|---|---|")
    sums: dict[str, list] = {}
    for spec in args.logs:
        for name, header, records in logs(spec):
            steps = group_steps(header, records)
            ekf, _ = run_estimator(EkfSlam(header), steps, covariances=False)
            reference = {**REFERENCE, "relinearize_skip": args.reference_skip}
            rows = ([] if args.no_reference else [("reference", reference)]) + [(f"candidate {i}" if len(candidates) > 1 else "isam2", c)
                                                 for i, c in enumerate(candidates)]
            results = []
            batch = None
            for label, kwargs in rows:
                run, smoother = run_estimator(Isam2Smoother(header, **common, **kwargs), steps, covariances=False)
                if batch is None:
                    batch = batch_solve(smoother)
                results.append((label, run, smoother.updates, smoother.error()))
            truth = truth_of(steps)

            def online_ate(run):
                return online_ate_m(run.online, truth, batch.trajectory)

            ref_ate = online_ate(results[0][1])
            print(f"| {name} | ekf | {ekf.total_time_s:.2f} | 1 | {1e3 * np.percentile(ekf.step_times_s, 99):.2f} | "
                  f"- | {online_ate(ekf):.4f} | {online_ate(ekf) / ref_ate:.3f} | - |")
            for label, run, updates, chi2 in results:
                ate = online_ate(run)
                ratio_t = run.total_time_s / ekf.total_time_s
                sums.setdefault(label, []).append((ratio_t, ate / ref_ate, chi2 / batch.final_error,
                                                   1e3 * np.percentile(run.step_times_s, 99)))
                print(f"| {name} | {label} | {run.total_time_s:.2f} | {ratio_t:.2f} | "
                      f"{1e3 * np.percentile(run.step_times_s, 99):.2f} | {updates} | {ate:.4f} | "
                      f"{ate / ref_ate:.3f} | {chi2 / batch.final_error:.5f} |", flush=True)
    print()
    for label, values in sums.items():
        v = np.array(values)
        print(f"{label}: × EKF time mean {v[:, 0].mean():.2f} max {v[:, 0].max():.2f}; "
              f"online ATE × reference mean {v[:, 1].mean():.3f} max {v[:, 1].max():.3f}; "
              f"χ² × batch max {v[:, 2].max():.5f}; p99 max {v[:, 3].max():.1f} ms")
    if args.candidate:
        for i, c in enumerate(candidates):
            print(f"candidate {i}: {c}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
