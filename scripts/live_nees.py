#!/usr/bin/env python3
"""Are replayed live-simulation logs consistent? Each run's mean NEES against its own band.

    .venv/bin/python -m scripts.live_nees --record 10 [--draws 100]   # record seeds 1–10, then score
    .venv/bin/python -m scripts.live_nees runs/live*.jsonl             # score logs you have

``--record N`` drives N lockstep octagon laps of ``fgslam live``'s simulation (the simulated
Create on a pseudo-terminal, frames rendered from its true pose, the AprilTag front-end and
iSAM2 in the loop; seeds 1…N, as ``tests/test_live.py`` drives them) into a temporary folder.
Each log is then replayed with every estimator named (default ``ekf`` and ``isam2``) and
scored against its truth:

- the reading errors over the σ each observation states (RMS near 1: the log states the
  noise its camera has);
- the run's mean NEES (χ²(3): 3 for a consistent estimator);
- the band of that mean for *this* run, from ``--draws`` copies of it redrawn from its own
  stated noise (:func:`fgslam.consistency.run_nees_band`), and the band that independent
  poses would give (``nees_band(3, runs=poses)``), which one run's correlated poses do not
  obey;
- over all runs: the mean of the run means against the band of that many runs.

``--simulate N`` adds the reference case where the models are exact by construction:
``fgslam sim arena-octagon`` seeds 1…N (one lap each), the EKF's run means against the
independent-pose band, to show how often even a consistent estimator's run falls outside it.
"""

from __future__ import annotations

import os

from scripts.common import one_blas_thread

one_blas_thread(force=False)

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from fgslam.compare import nees_band  # noqa: E402
from fgslam.consistency import mean_nees, reading_z_scores, run_nees_band  # noqa: E402
from fgslam.live import (  # noqa: E402
    LiveSettings,
    Lockstep,
    polygon_waypoints,
    run_live,
    simulated_camera,
    start_pose_facing,
)
from fgslam.runner import ESTIMATORS  # noqa: E402
from slamio.create.link import CreateLink  # noqa: E402
from slamio.create.sim import SimulatedCreate  # noqa: E402
from slamio.log import RunLog, read_log  # noqa: E402
from slamio.sim import ARENA_PATH_WIDTH_M, ARENA_SIDE_M, simulate  # noqa: E402

TIME_SCALE = 3.0
CALM = LiveSettings(command_timeout_s=30.0, data_timeout_s=30.0)


def record_lap(out: str, seed: int) -> None:
    """One lockstep octagon lap of the simulated Create into ``out``."""
    waypoints = polygon_waypoints(8, ARENA_PATH_WIDTH_M, (0.5 * ARENA_SIDE_M, 0.5 * ARENA_SIDE_M))
    start = start_pose_facing(waypoints)
    with SimulatedCreate("create2", seed=seed, time_scale=TIME_SCALE, start_pose=start) as sim:
        grab_for, front_end, truth_landmarks = simulated_camera(sim, seed=seed)
        run_live(CreateLink(sim.port, "create2"), out, waypoints, start_pose=start, grab_for=grab_for,
                 front_end=front_end, truth=lambda: sim.true_pose, truth_landmarks=truth_landmarks,
                 clock=sim.clock, settings=CALM, lockstep=Lockstep(sim), odometry_noise=sim.odometry_noise)


def reading_z_rms(log) -> tuple[float, float]:
    """RMS of (range error / stated σ) and (bearing error / stated σ) against the log's truth."""
    z_range, z_bearing = reading_z_scores(log)
    return float(np.sqrt(np.mean(z_range**2))), float(np.sqrt(np.mean(z_bearing**2)))


def exact_models_reference(runs: int) -> dict:
    """The EKF's run means on ``runs`` simulated octagon laps: ``means``, how many are
    ``inside`` their independent-pose ``band``, and the ``runs_band`` of that many runs."""
    means, band = [], None
    for seed in range(1, runs + 1):
        header, records = simulate("arena-octagon", seed, laps=1)
        mean, poses = mean_nees(RunLog(f"arena-octagon seed {seed}", header, tuple(records)), ESTIMATORS["ekf"])
        means.append(mean)
        band = nees_band(3, runs=poses)
    m = np.array(means)
    return {"means": m, "band": band, "inside": int(np.sum((m >= band[0]) & (m <= band[1]))),
            "runs_band": nees_band(3, runs=runs)}


def score_log(path: str, estimators, draws: int) -> dict:
    """One log: ``poses``, ``z_range``/``z_bearing`` RMS, the ``independent_band`` of its scored
    poses and, per estimator, its mean NEES (``means``) and, unless ``draws`` is 0, its
    :class:`~fgslam.consistency.RunNeesBand` (``bands``)."""
    log = read_log(path)
    z_range, z_bearing = reading_z_rms(log)
    out = {"poses": len(log.steps()), "z_range": z_range, "z_bearing": z_bearing, "bands": {}, "means": {}}
    for name in estimators:
        out["means"][name], scored = mean_nees(log, ESTIMATORS[name])
        out["independent_band"] = nees_band(3, runs=scored)
        if draws:
            out["bands"][name] = run_nees_band(log, ESTIMATORS[name], draws=draws)
    return out


def recorded_laps(runs: int, folder: str | None = None) -> list[str]:
    """Record lockstep laps of seeds 1…``runs`` into ``folder`` (a new temporary one if None);
    their paths. Lockstep laps are reproducible: the same seed gives the same log."""
    folder = folder or tempfile.mkdtemp(prefix="fgslam-live-nees-")
    logs = []
    for seed in range(1, runs + 1):
        out = os.path.join(folder, f"seed{seed}.jsonl")
        print(f"recording lap {seed}/{runs} -> {out}", file=sys.stderr, flush=True)
        record_lap(out, seed)
        logs.append(out)
    return logs


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="*", help="live-simulation logs with truth at every pose")
    parser.add_argument("--record", type=int, default=0, metavar="N", help="record N lockstep laps first (seeds 1…N)")
    parser.add_argument("--estimators", nargs="+", default=["ekf", "isam2"], choices=sorted(ESTIMATORS))
    parser.add_argument("--draws", type=int, default=100, help="redrawn copies per run and estimator (default 100)")
    parser.add_argument("--simulate", type=int, default=0, metavar="N",
                        help="also score N simulated octagon laps, whose models are exact (EKF, independent-pose band)")
    args = parser.parse_args(argv)
    if args.simulate:
        ref = exact_models_reference(args.simulate)
        m, band, runs_band = ref["means"], ref["band"], ref["runs_band"]
        print(f"simulated octagon, exact models, ekf: run means {m.min():.2f}–{m.max():.2f}, {ref['inside']} of "
              f"{len(m)} inside the independent-pose band [{band[0]:.2f}, {band[1]:.2f}]; mean of the run means "
              f"{m.mean():.2f} (band of {len(m)} runs [{runs_band[0]:.2f}, {runs_band[1]:.2f}])", flush=True)

    logs = list(args.logs) + (recorded_laps(args.record) if args.record else [])
    if not logs:
        if args.simulate:
            return 0
        parser.error("give logs, --record N or --simulate N")

    print("| log | poses | range z RMS | bearing z RMS | " + " | ".join(
        f"{name} mean NEES, band of the run (redrawn)" for name in args.estimators) + " | independent-pose band |")
    print("|---|---:|---:|---:|" + "---|" * len(args.estimators) + "---|")
    scores = []
    for path in logs:
        score = score_log(path, args.estimators, args.draws)
        scores.append(score)
        cells = []
        for name in args.estimators:
            b = score["bands"].get(name)
            cells.append(f"{score['means'][name]:.2f}" if b is None else
                         f"{b.mean_nees:.2f} [{b.low:.2f}, {b.high:.2f}]{'' if b.inside else ' OUT'}")
        low, high = score["independent_band"]
        print(f"| {Path(path).name} | {score['poses']} | {score['z_range']:.2f} | {score['z_bearing']:.2f} | "
              + " | ".join(cells) + f" | [{low:.2f}, {high:.2f}] |", flush=True)
    low, high = nees_band(3, runs=len(logs))
    for name in args.estimators:
        m = np.array([s["means"][name] for s in scores])
        inside = sum(s["bands"][name].inside for s in scores) if args.draws else None
        print(f"{name}: " + (f"{inside} of {len(logs)} runs inside their own band; " if args.draws else "")
              + f"mean of the run means {m.mean():.2f} (band of {len(logs)} runs [{low:.2f}, {high:.2f}]); "
              f"run means {m.min():.2f}–{m.max():.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
