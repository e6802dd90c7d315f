#!/usr/bin/env python3
"""Measure the noise of ``fgslam live --port sim``'s camera: the σ its observations must state.

    .venv/bin/python -m scripts.measure_live_camera [--frames 400] [--seed 0]

The simulated live camera (:func:`fgslam.live.simulated_camera`) renders seed 004's eight
arena tags from the simulated Create's true pose (640×480, the Kinect's intrinsics, pixel
noise σ 2 grey levels, no supersampling) and runs the AprilTag front-end on the frame. Its
errors are not white pixel noise: without supersampling a tag's edges are aliased, so the
error depends on where the tag falls on the pixel grid, and it looks like noise only over
many poses. This script therefore draws robot poses the way a lap does (a point on the
octagon or square path with a small offset, heading along the path or, at a corner, turning
between the two legs), renders each, and compares every observation with the truth.

It prints the RMS bearing error, the range error's c in σ_range = c·r² (c² = mean(e²/r⁴),
the maximum-likelihood c for that law), the tag yaw's RMS, and the share of readings beyond
5σ of the fitted model. These are second moments with every reading counted: NIS and NEES
are second moments too. :data:`fgslam.live.LIVE_SIM_SIGMA_BEARING_RAD`,
:data:`~fgslam.live.LIVE_SIM_RANGE_SIGMA_PER_M2` and
:data:`~fgslam.live.LIVE_SIM_SIGMA_TAG_YAW_RAD` are what it printed (docs/camera.md); the
lockstep laps of ``tests/test_live.py`` are then checked against them, not fitted.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread(force=False)

import argparse  # noqa: E402
import math  # noqa: E402

import numpy as np  # noqa: E402

from fgslam.live import arena_tag_scene, live_sim_camera, polygon_waypoints  # noqa: E402
from slamio.camera.detect import FrontEnd, FrontEndConfig  # noqa: E402
from slamio.camera.render import render  # noqa: E402
from slamio.camera.sources import Frame  # noqa: E402
from slamio.geometry import wrap_angle  # noqa: E402
from slamio.sim import ARENA_PATH_WIDTH_M, ARENA_SIDE_M  # noqa: E402

CENTRE = (0.5 * ARENA_SIDE_M, 0.5 * ARENA_SIDE_M)
CORNER_SHARE = 0.3  # laps spend about this share of their frames turning at a corner
OFFSET_SIGMA_M = 0.03  # how far a lap's robot strays from its path
HEADING_SIGMA_RAD = 0.05


def lap_pose(rng) -> tuple[float, float, float]:
    """A pose a lap of the octagon or square passes through."""
    path = polygon_waypoints(int(rng.choice((8, 4))), ARENA_PATH_WIDTH_M, CENTRE)
    k = int(rng.integers(len(path)))
    a, b, c = path[k - 1], path[k], path[(k + 1) % len(path)]
    leg_in, leg_out = math.atan2(*(b - a)[::-1]), math.atan2(*(c - b)[::-1])
    if rng.random() < CORNER_SHARE:  # turning in place at corner b
        xy = b
        heading = leg_in + rng.random() * wrap_angle(leg_out - leg_in)
    else:  # driving from a to b
        xy = a + rng.random() * (b - a)
        heading = leg_in + rng.normal(0.0, HEADING_SIGMA_RAD)
    xy = xy + rng.normal(0.0, OFFSET_SIGMA_M, 2)
    return float(xy[0]), float(xy[1]), float(wrap_angle(heading))


def reading_errors(frames: int, seed: int) -> np.ndarray:
    """Rows (range_m, range error, bearing error, tag yaw error) over ``frames`` rendered lap poses."""
    rng = np.random.default_rng(seed)
    scene, camera = arena_tag_scene(), live_sim_camera()
    front_end = FrontEnd(camera, FrontEndConfig(tag_size_m=scene.tags[0].size_m))
    tags = {t.tag_id: t for t in scene.tags}
    rows = []
    for index in range(frames):
        x, y, theta = lap_pose(rng)
        image = render(camera, (x, y, theta), scene, supersample=1, noise_sigma=2.0, rng=rng)
        for o in front_end.process(Frame(0.0, index, "rendered", image.bgr, image.depth_m)).observations:
            tag = tags[o.landmark_id]
            dx, dy = tag.x_m - x, tag.y_m - y
            range_m = math.hypot(dx, dy)
            rows.append((range_m, o.range_m - range_m, wrap_angle(o.bearing_rad - math.atan2(dy, dx) + theta),
                         wrap_angle(o.tag_yaw_rad - (tag.yaw_rad - theta))))
    return np.array(rows).reshape(-1, 4)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=400, help="rendered lap poses (default 400)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    e = reading_errors(args.frames, args.seed)
    r, e_range, e_bearing, e_yaw = e.T
    sigma_bearing = float(np.sqrt(np.mean(e_bearing**2)))
    c = float(np.sqrt(np.mean(e_range**2 / r**4)))
    sigma_yaw = float(np.sqrt(np.mean(e_yaw**2)))
    beyond_5 = np.mean((np.abs(e_range) > 5 * c * r**2) | (np.abs(e_bearing) > 5 * sigma_bearing))
    print(f"{len(e)} readings in {args.frames} frames, ranges {r.min():.2f}–{r.max():.2f} m")
    print(f"sigma_bearing_rad = {sigma_bearing:.3g}   (median |error| / 0.6745: {np.median(np.abs(e_bearing)) / 0.6745:.3g})")
    print(f"range_sigma_per_m2 = {c:.3g}   (sigma_range = c·r²; median-based: "
          f"{np.median(np.abs(e_range) / r**2) / 0.6745:.3g}; mean error {np.mean(e_range) * 1000:+.1f} mm)")
    print(f"sigma_tag_yaw_rad = {sigma_yaw:.3g}")
    print(f"readings beyond 5 sigma (range or bearing): {100 * beyond_5:.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
