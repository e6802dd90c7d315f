#!/usr/bin/env python3
"""Seed 002's tables (Figures 5.1–5.3) redone on rendered frames: heights of its three shapes.

Seed 002 measured the heights of an upright circle (24.0 cm), triangle (24.3 cm) and
rectangle (40.5 cm) from single Kinect frames with ``gHeight`` and printed observed vs actual
heights (every observed height 1.0–10.4 % high). The paper gives neither the boards' widths
nor the distances, so this script renders each shape — red circle 0.24 m across, green
triangle with a 0.24 m base, blue rectangle 0.20 m wide; standing on the floor, facing the
camera — at 1.0 … 3.0 m straight ahead and 15° to the side, seen by the Kinect (fx = fy = 525,
lens 0.30 m above the floor, Kinect-quantised depth, pixel noise σ 2 grey levels, seed 0).
Each frame goes through the colour front-end twice, as ``fgslam detect`` does: with seed 002's
``gHeight`` (``--height-method gheight``) and with the exact pinhole height (the default), and
the table prints observed heights and the "percentage of deviation" the paper prints.

    .venv/bin/python -m scripts.seed002_shapes

docs/seeds.md quotes its output.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread(force=False)

import argparse  # noqa: E402
import math  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from slamio.camera.accuracy import ROBOT_POSE, kinect_camera, world_point  # noqa: E402
from slamio.camera.colour import DEFAULT_COLOURS, ColourOptions  # noqa: E402
from slamio.camera.detect import FrontEnd, FrontEndConfig  # noqa: E402
from slamio.camera.render import CYLINDER_BGR, BoardSpec, Scene, render  # noqa: E402
from slamio.camera.sources import Frame  # noqa: E402

#: (shape, colour, width m, actual height m) — seed 002's heights; widths chosen (not given).
SHAPES = (("circle", "red", 0.24, 0.240), ("triangle", "green", 0.24, 0.243), ("rectangle", "blue", 0.20, 0.405))
DISTANCES_M = (1.0, 1.5, 2.0, 2.5, 3.0)
BEARINGS_DEG = (0.0, 15.0)


def colour_options(height_method: str) -> ColourOptions:
    by_name = {c.name: c for c in DEFAULT_COLOURS}
    specs = tuple(replace(by_name[colour], shape=shape, width_m=width, height_m=height)
                  for shape, colour, width, height in SHAPES)
    return ColourOptions(colours=specs, height_method=height_method)


def measure(noise: float, seed: int) -> list[dict]:
    camera = kinect_camera()
    fronts = {m: FrontEnd(camera, FrontEndConfig(kind="colour", colour=colour_options(m))) for m in ("gheight", "pinhole")}
    rng = np.random.default_rng(seed)
    rows = []
    for shape, colour, width, height in SHAPES:
        for distance in DISTANCES_M:
            for bearing in BEARINGS_DEG:
                x, y = world_point(distance, bearing)
                facing = math.atan2(ROBOT_POSE[1] - y, ROBOT_POSE[0] - x)
                board = BoardSpec(shape, x, y, width, height, facing, CYLINDER_BGR[colour])
                image = render(camera, ROBOT_POSE, Scene(boards=(board,)), depth_model="kinect", noise_sigma=noise,
                               rng=rng, supersample=3)
                frame = Frame(0.0, len(rows), "rendered", image.bgr, image.depth_m)
                row = {"shape": shape, "distance_m": distance, "bearing_deg": bearing, "actual_m": height}
                for method, front in fronts.items():
                    heights = [o.height_m for o in front.process(frame).observations if o.height_m is not None]
                    row[method] = heights[0] if heights else float("nan")
                rows.append(row)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--noise", type=float, default=2.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rows = measure(args.noise, args.seed)

    def pct(v, actual):
        return f"{100 * (v / actual - 1):+.1f} %" if math.isfinite(v) else "—"

    def cm(v):
        return f"{100 * v:.2f}" if math.isfinite(v) else "—"

    print("| shape | distance | bearing | actual cm | gHeight cm | deviation | exact cm | deviation |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        a = r["actual_m"]
        print(f"| {r['shape']} | {r['distance_m']:.1f} m | {r['bearing_deg']:.0f}° | {100 * a:.1f} | {cm(r['gheight'])} "
              f"| {pct(r['gheight'], a)} | {cm(r['pinhole'])} | {pct(r['pinhole'], a)} |")
    print()
    for method in ("gheight", "pinhole"):
        dev = [100 * (r[method] / r["actual_m"] - 1) for r in rows if math.isfinite(r[method])]
        print(f"{method}: {len(dev)}/{len(rows)} measured, deviation {min(dev):+.1f} … {max(dev):+.1f} %, "
              f"mean {np.mean(dev):+.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
