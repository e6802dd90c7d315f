"""Why the bearing-pair search for the turn scale is biased: the same search on MRCLAM with
the odometry and with Vicon's own increments in its place (whose turn scale is 1 by
construction), with the readings as read and with the camera's fitted range model (depth,
+4.7 cm). Truth is the checker only. Prints one line per robot, source and range model.

    PYTHONPATH=. .venv/bin/python -m scripts.experiments.selffit_pairs_turn_scale RUNS_DIR

``RUNS_DIR`` holds ``robotN.jsonl`` imported with ``--noise round``.
"""
import argparse

import numpy as np

from slamio.log import read_log
from slamio.noise.dead_reckoning import DeadReckoning, odometry_arrays
from slamio.noise.fit_self import lag_from_readings, scaled_increments

GRID = np.round(np.arange(0.80, 1.101, 0.02), 2)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="?", default="runs", help="folder of robotN.jsonl (imported with --noise round)")
    runs = ap.parse_args(argv).runs
    for k in (1, 2, 3, 4, 5):
        log = read_log(f'{runs}/robot{k}.jsonl')
        steps = log.steps()
        stamps, inc = odometry_arrays(steps)
        truth = np.array([[s.truth.x_m, s.truth.y_m, s.truth.theta_rad] if s.truth else [np.nan]*3 for s in steps])
        tinc = np.zeros_like(inc)
        for i in range(len(inc)):
            a, b = truth[i], truth[i+1]
            c, s = np.cos(a[2]), np.sin(a[2]); dx, dy = b[0]-a[0], b[1]-a[1]
            tinc[i] = [c*dx+s*dy, -s*dx+c*dy, np.angle(np.exp(1j*(b[2]-a[2])))]
        ok = np.all(np.isfinite(tinc), axis=1)
        tinc[~ok] = inc[~ok]
        for label, depth_bias in (("raw", None), ("depth+4.7cm", (True, 0.047))):
            rd = []
            for s in steps:
                for o in s.observations:
                    if o.landmark_id is None or o.bearing_rad is None: continue
                    r = o.range_m
                    if depth_bias: r = (r - depth_bias[1]) / np.cos(o.bearing_rad)
                    rd.append((o.stamp_s, o.landmark_id, r, o.bearing_rad))
            for src, base, lags in (("odometry", inc, (0.26,)), ("vicon", tinc, (0.0,))):
                costs = [lag_from_readings(DeadReckoning(stamps, scaled_increments(base, 1.0, ts, 0.0)), rd, lags).cost[0] for ts in GRID]
                print(k, label, src, 'best ts', GRID[int(np.argmin(costs))], flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
