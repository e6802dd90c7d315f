#!/usr/bin/env python3
"""Benchmark of ``fgslam live`` in the loop with the simulated Create (issue 8's figures).

    python -m scripts.bench_live [--laps 1] [--time-scale 1] [--seed 1] [--path octagon]

One hardware-in-the-loop run: the simulated Create on a real pseudo-terminal, frames
rendered from its true pose, the AprilTag front-end and iSAM2 in the loop, following seed
004's octagon (or square). Prints the final pose error against the simulator's truth, the
iSAM2 step latency (median, p99, max) against the Create's 15 ms stream period, the camera
time per frame, and the frames used, skipped (camera busy) and dropped (too late).

Time scale 1 is real time, as on a robot; the latency is wall-clock on whatever else this
machine runs (read it as an upper bound on a shared machine).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np


from fgslam.live import (  # noqa: E402
    polygon_waypoints,
    pose_error_m,
    run_live,
    simulated_camera,
    start_pose_facing,
)
from slamio.create.link import CreateLink  # noqa: E402
from slamio.create.sim import SimulatedCreate  # noqa: E402
from slamio.sim import ARENA_PATH_WIDTH_M, ARENA_SIDE_M  # noqa: E402

STREAM_PERIOD_MS = 15.0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--laps", type=int, default=1)
    parser.add_argument("--time-scale", type=float, default=1.0, help="robot seconds per wall second (1 = real time)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--path", choices=("octagon", "square"), default="octagon")
    parser.add_argument("--out", default=None, help="keep the run log here")
    args = parser.parse_args(argv)

    centre = (0.5 * ARENA_SIDE_M, 0.5 * ARENA_SIDE_M)
    waypoints = polygon_waypoints(8 if args.path == "octagon" else 4, ARENA_PATH_WIDTH_M, centre, args.laps)
    start = start_pose_facing(waypoints)
    out = args.out or os.path.join(tempfile.mkdtemp(prefix="fgslam-bench-live-"), "live.jsonl")
    wall = time.perf_counter()
    with SimulatedCreate("create2", seed=args.seed, time_scale=args.time_scale, start_pose=start) as sim:
        grab_for, front_end, truth_landmarks = simulated_camera(sim, seed=args.seed)
        result = run_live(CreateLink(sim.port, "create2"), out, waypoints, start_pose=start, grab_for=grab_for,
                          front_end=front_end, truth=lambda: sim.true_pose, truth_landmarks=truth_landmarks,
                          clock=sim.clock)
        true_pose = sim.true_pose
        robot_s = sim.clock()
    wall = time.perf_counter() - wall
    lat = 1e3 * result.latencies_s
    frames = 1e3 * result.frame_seconds
    p50, p99, worst = np.percentile(lat, [50, 99, 100])
    print(f"{args.path}, {args.laps} lap(s), seed {args.seed}, time scale {args.time_scale}: "
          f"{robot_s:.1f} s of robot time in {wall:.1f} s wall; stopped: {result.record.reason}")
    print(f"poses {result.poses}, observations {result.observations}, landmarks {len(result.landmarks)}")
    print(f"final iSAM2 pose error vs the simulator's truth: {pose_error_m(result.final_pose, true_pose):.4f} m "
          f"(goal 0.1 m)")
    print(f"iSAM2 step latency: median {p50:.3f} ms, p99 {p99:.3f} ms, max {worst:.3f} ms; "
          f"p99 / {STREAM_PERIOD_MS:.0f} ms stream period = {p99 / STREAM_PERIOD_MS:.3f} (goal <= 1)")
    print(f"camera (render + detect) per frame: median {np.median(frames):.1f} ms, p99 {np.percentile(frames, 99):.1f} ms")
    print(f"frames: {result.frames_requested} requested, {result.frames_used} used, "
          f"{result.frames_skipped} skipped (camera busy), {result.frames_dropped} dropped (too late)")
    print(f"log: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
