"""Benchmark: colour landmarks on real RGB-D frames — nothing found in clutter, composited cylinders found.

Reads real colour + depth frames without landmarks and prints the two tables of
docs/camera.md:

1. per frame: candidate blobs (red, green or blue components), landmarks reported (must be
   0), and every rejection by reason;
2. seed 000's red, green and blue cylinders (0.40 / 0.60 / 0.80 m tall, 0.10 m across)
   rendered at 1.0–4.0 m and −20°…+20° and composited into every frame (colour and depth,
   slamio.camera.composite), for each depth-to-colour misregistration: found / placed,
   observations of a landmark not in the frame, and the largest range, bearing and height
   errors (height where the top is in view; its 95th percentile too).

FOLDER is either a folder laid out as ``shared/data/rgbd-real`` (``sequence/color/*.jpg`` +
``sequence/depth/*.png`` in mm, ``other/TUM_*`` at 5000 per metre, ``other/SUN_*`` in mm with
SUN RGB-D's 3-bit rotation) or ``tests/data/rgbd-real``. The Kinect sits 0.10 m ahead of the
robot's centre at 0.30 m, level, with fx = fy = 525.
Usage: ``.venv/bin/python -m scripts.bench_colour_real [FOLDER] [--supersample N]``.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread(force=False)

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from slamio.camera.colour import DEFAULT_COLOURS  # noqa: E402
from slamio.camera.composite import composite_trial  # noqa: E402
from slamio.camera.detect import FrontEnd, FrontEndConfig  # noqa: E402
from slamio.camera.kinect import depth_from_mm  # noqa: E402
from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default  # noqa: E402
from slamio.camera.render import CYLINDER_BGR, CylinderSpec  # noqa: E402
from slamio.camera.sources import Frame, read_depth_png, read_image  # noqa: E402
from scripts.common import SHARED_DATA  # noqa: E402

SHIFTS_PX = ((0, 0), (2, 0), (-2, 0), (0, 2), (0, -2), (2, 2))
DISTANCES_M = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0)
BEARINGS_DEG = (-20.0, -10.0, 0.0, 10.0, 20.0)


def _sun_depth(path: Path) -> np.ndarray:
    import cv2

    raw = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH).astype(np.uint32)
    return depth_from_mm((((raw >> 3) | (raw << 13)) & 0xFFFF).astype(np.uint16))


def load_frames(folder: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    pairs = []  # (name, colour path, depth path or loader, scale)
    for colour in sorted((folder / "sequence" / "color").glob("*.jpg")):
        pairs.append((f"sequence/{colour.stem}", colour, folder / "sequence" / "depth" / f"{colour.stem}.png", 1000.0))
    if (folder / "other").is_dir():
        pairs.append(("TUM", folder / "other" / "TUM_color.png", folder / "other" / "TUM_depth.png", 5000.0))
        pairs.append(("SUN", folder / "other" / "SUN_color.jpg", folder / "other" / "SUN_depth.png", None))
    for colour in sorted(folder.glob("*_color.jpg")):  # tests/data/rgbd-real
        stem = colour.name[: -len("_color.jpg")]
        pairs.append((stem, colour, folder / f"{stem}_depth.png", 5000.0 if stem.startswith("tum") else 1000.0))
    frames = []
    for name, colour, depth_path, scale in pairs:
        bgr, error = read_image(colour)
        depth = _sun_depth(depth_path) if scale is None else read_depth_png(depth_path, scale)[0]
        if error or depth is None:
            raise SystemExit(f"{colour}: cannot read the frame ({error or 'depth'})")
        frames.append((name, bgr, depth))
    if not frames:
        raise SystemExit(f"{folder}: no frames found (see the script's doc for the layout)")
    return frames


def cylinders() -> list[CylinderSpec]:
    out = []
    for c in DEFAULT_COLOURS:
        for d in DISTANCES_M:
            for b in BEARINGS_DEG:
                r = math.radians(b)
                out.append(CylinderSpec(d * math.cos(r), d * math.sin(r), 0.5 * c.width_m, c.height_m,
                                        CYLINDER_BGR[c.name], c.name, c.landmark_id))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folder", nargs="?", default=str(SHARED_DATA / "rgbd-real"))
    parser.add_argument("--supersample", type=int, default=3)
    args = parser.parse_args(argv)
    frames = load_frames(Path(args.folder))
    camera = kinect_v1_default(T_robot_camera_from_mount(x_m=0.10, z_m=0.30))
    front = FrontEnd(camera, FrontEndConfig(kind="colour"))

    print("| frame | candidate blobs | landmarks reported | rejections |")
    print("|---|---:|---:|---|")
    total = Counter()
    for index, (name, bgr, depth) in enumerate(frames):
        result = front.process(Frame(0.0, index, name, bgr, depth))
        reasons = Counter(r.reason for r in result.rejections)
        total.update(reasons)
        text = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1]))
        print(f"| {name} | {len(result.blobs)} | {len(result.observations)} | {text} |")
    print()
    placements = cylinders()
    start = time.perf_counter()
    scores = composite_trial(front, frames, placements, SHIFTS_PX, supersample=args.supersample, noise_sigma=2.0)
    print(f"{len(placements)} cylinder placements × {len(frames)} frames × {len(SHIFTS_PX)} depth shifts "
          f"({time.perf_counter() - start:.0f} s)\n")
    print("| depth shift (px) | found | wrong landmark | range max | bearing max | height p95 | height > 3 % "
          "| height max (n) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for shift, s in scores.items():
        p95 = float(np.percentile(s.height_pct, 95)) if s.height_pct else float("nan")
        print(f"| {shift[0]:+d}, {shift[1]:+d} | {s.found}/{s.placed} ({100 * s.found_fraction:.1f} %) "
              f"| {s.wrong_landmarks} | {s.worst(s.range_pct):.2f} % | {s.worst(s.bearing_deg):.3f}° "
              f"| {p95:.2f} % | {sum(h > 3.0 for h in s.height_pct)} | {s.worst(s.height_pct):.2f} % "
              f"({len(s.height_pct)}) |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
