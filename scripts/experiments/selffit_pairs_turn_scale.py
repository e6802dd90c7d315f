"""Why the bearing-pair search for the turn scale is biased: the same search on MRCLAM with
the odometry and with Vicon's own increments in its place (whose turn scale is 1 by
construction), with the readings as read and with the camera's fitted range model (depth,
+4.7 cm). Truth is the checker only. Prints one line per robot, source and range model.

    PYTHONPATH=. .venv/bin/python -m scripts.experiments.selffit_pairs_turn_scale RUNS_DIR

``RUNS_DIR`` holds ``robotN.jsonl`` imported with ``--noise round``.
"""
import argparse

import numpy as np

from slamio.geometry import between_pose
from slamio.log import read_log
from slamio.noise.dead_reckoning import DeadReckoning, odometry_arrays
from slamio.noise.fit_self import lag_from_readings, scaled_increments

GRID = np.round(np.arange(0.80, 1.101, 0.02), 2)


def truth_increments(steps, odometry: np.ndarray) -> np.ndarray:
    """Vicon's increment between consecutive poses (the odometry's where a pose has no truth)."""
    out = odometry.copy()
    for i, (a, b) in enumerate(zip(steps, steps[1:])):
        if a.truth is not None and b.truth is not None:
            out[i] = between_pose((a.truth.x_m, a.truth.y_m, a.truth.theta_rad),
                                  (b.truth.x_m, b.truth.y_m, b.truth.theta_rad))
    return out


def readings_of(steps, depth_bias_m: float | None) -> list[tuple[float, int, float, float]]:
    """(stamp, landmark, range, bearing) of every identified reading; with ``depth_bias_m`` the
    range re-read as a depth with that bias."""
    out = []
    for step in steps:
        for o in step.observations:
            if o.landmark_id is None or o.bearing_rad is None:
                continue
            r = o.range_m if depth_bias_m is None else (o.range_m - depth_bias_m) / np.cos(o.bearing_rad)
            out.append((o.stamp_s, o.landmark_id, r, o.bearing_rad))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="?", default="runs", help="folder of robotN.jsonl (imported with --noise round)")
    runs = ap.parse_args(argv).runs
    for k in (1, 2, 3, 4, 5):
        steps = read_log(f"{runs}/robot{k}.jsonl").steps()
        stamps, odometry = odometry_arrays(steps)
        vicon = truth_increments(steps, odometry)
        for label, depth_bias_m in (("raw", None), ("depth+4.7cm", 0.047)):
            readings = readings_of(steps, depth_bias_m)
            for source, increments, lags in (("odometry", odometry, (0.26,)), ("vicon", vicon, (0.0,))):
                costs = [lag_from_readings(DeadReckoning(stamps, scaled_increments(increments, 1.0, ts, 0.0)),
                                           readings, lags).cost[0] for ts in GRID]
                print(k, label, source, "best ts", GRID[int(np.argmin(costs))], flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
