"""Benchmark: AprilTag detectors on the real photos — recall, false detections, corner error, time.

For each detector configuration, on the three NASA photos of ``tests/data/apriltag-photos``
(47 listed tag36h11 tags, corners listed by the AprilTag 3 reference detector), prints:

- recall (listed tags found, matched by id and corner set within 3 px) and false detections
  (detections matching no listed tag);
- corner error against the listed corners: max and mean over every matched corner (corner
  sets matched, orders differ); for the chosen configuration also after
  ``refine_tag_corners`` (the sub-pixel step the front-end adds);
- time per frame: median and 90th percentile over ``--repeats`` runs, on the 799×533 NASA
  photos and on 640×480 frames (the eleven pupil-labs photos and 640×480 crops of the NASA
  photos), detector only and the whole front-end (detection, refinement, pose, geometry).

Timing is wall-clock on whatever else this (shared) machine runs: read medians.
Usage: ``.venv/bin/python scripts/bench_apriltag.py [--photos DIR] [--repeats N]``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from slamio.camera.accuracy import MatchResult, match_detections, read_corner_list  # noqa: E402
from slamio.camera.apriltag import AprilTagDetector, refine_tag_corners  # noqa: E402
from slamio.camera.detect import FrontEnd, FrontEndConfig  # noqa: E402
from slamio.camera.model import kinect_v1_default  # noqa: E402
from slamio.camera.sources import Frame  # noqa: E402

DEFAULT_PHOTOS = Path(__file__).resolve().parents[1] / "tests" / "data" / "apriltag-photos"

CONFIGS = [
    ("apriltag3 decimate 1.0, refine_edges off (chosen)", dict(backend="apriltag3", quad_decimate=1.0)),
    ("apriltag3 decimate 1.0, refine_edges off, 2 threads", dict(backend="apriltag3", quad_decimate=1.0, nthreads=2)),
    ("apriltag3 decimate 1.0, refine_edges on", dict(backend="apriltag3", quad_decimate=1.0, refine_edges=True)),
    ("apriltag3 decimate 1.5, refine_edges on", dict(backend="apriltag3", quad_decimate=1.5, refine_edges=True)),
    ("apriltag3 decimate 2.0 (library default)", dict(backend="apriltag3", quad_decimate=2.0, refine_edges=True)),
    ("cv2.aruco APRILTAG_36h11, default parameters", dict(backend="aruco", aruco_refinement="none")),
    ("cv2.aruco APRILTAG_36h11, CORNER_REFINE_APRILTAG", dict(backend="aruco", aruco_refinement="apriltag")),
]


def timed(function, repeats):
    times = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = function()
        times.append(time.perf_counter() - t0)
    return out, times


def crops_640x480(image):
    """640×480 windows of a larger image: top-left, centre, bottom-right."""
    h, w = image.shape[:2]
    corners = [(0, 0), ((h - 480) // 2, (w - 640) // 2), (h - 480, w - 640)]
    return [np.ascontiguousarray(image[r:r + 480, c:c + 640]) for r, c in corners]


def ms(times):
    return f"{1e3 * np.median(times):6.1f} ms (p90 {1e3 * np.percentile(times, 90):5.1f})"


def match_refined(images, listed, paths) -> tuple[MatchResult, int]:
    """The chosen detector's tags with the front-end's refined corners (``refine_tag_corners``;
    the detector's own where refinement declines) matched to the listed corners, and how many
    tags kept the detector's corners."""
    detector = AprilTagDetector()
    refined, not_refined = MatchResult(), 0
    for image, tags, path in zip(images, listed, paths):
        pairs = []
        for d in detector.detect(image):
            c = refine_tag_corners(image, d.corners_px)
            not_refined += c is None
            pairs.append((d.tag_id, d.corners_px if c is None else c))
        refined.add(match_detections(pairs, tags, image=path.name))
    return refined, not_refined


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--photos", default=str(DEFAULT_PHOTOS), help="the apriltag-photos folder")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per image (default 5)")
    args = parser.parse_args(argv)
    photos = Path(args.photos)
    nasa = sorted(photos.glob("nasa_*.jpg"))
    if not nasa:
        print(f"no nasa_*.jpg in {photos}", file=sys.stderr)
        return 1
    nasa_grey = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in nasa]
    listed = [read_corner_list(p.with_suffix(".txt")) for p in nasa]
    small = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted(photos.glob("pupil_*.png"))]
    small += [c for g in nasa_grey for c in crops_640x480(g)]
    print(f"{len(nasa)} NASA photos ({nasa_grey[0].shape[1]}×{nasa_grey[0].shape[0]}), "
          f"{sum(len(x) for x in listed)} listed tags; {len(small)} frames of 640×480 for timing; "
          f"{os.cpu_count()} CPUs\n")
    header = f"{'detector':52} {'recall':>7} {'false':>5} {'corner err max/mean':>20}   ms/frame 799×533 | 640×480"
    print(header)
    print("-" * len(header))
    for name, settings in CONFIGS:
        detector = AprilTagDetector(**settings)
        total, big_times = MatchResult(), []
        for image, tags, path in zip(nasa_grey, listed, nasa):
            found, times = timed(lambda: detector.detect(image), args.repeats)
            big_times += times
            total.add(match_detections([(d.tag_id, d.corners_px) for d in found], tags, image=path.name))
        small_times = []
        for image in small:
            small_times += timed(lambda: detector.detect(image), args.repeats)[1]
        print(f"{name:52} {total.found:>3}/{total.listed:<3} {len(total.false_detections):>5} "
              f"{total.max_corner_error_px:9.3f}/{total.mean_corner_error_px:.3f} px   "
              f"{ms(big_times)} | {ms(small_times)}")
        for kind, items in (("missed", total.missed), ("false", total.false_detections)):
            for image_name, tag_id, centre in items[:3]:
                print(f"{'':8}{kind + ':':7} {image_name} id {tag_id} at ({centre[0]:.0f}, {centre[1]:.0f})")
            if len(items) > 3:
                print(f"{'':8}{kind + ':':7} ... and {len(items) - 3} more")

    print("\nchosen detector + refine_tag_corners (the front-end's corners) against the listed corners:")
    refined, not_refined = match_refined(nasa_grey, listed, nasa)
    print(f"  {refined.found}/{refined.listed} matched, corner difference max {refined.max_corner_error_px:.3f} px, "
          f"mean {refined.mean_corner_error_px:.3f} px; {not_refined} tags kept the detector's corners "
          "(the listed corners are the detector's own binarised corners, not ground truth)")

    print("\nwhole front-end per frame (detect, refine, IPPE pose, robot-frame geometry), 640×480:")
    front = FrontEnd(kinect_v1_default(), FrontEndConfig(kind="apriltag", tag_size_m=0.16))
    times, count = [], 0
    for image in small:
        bgr = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        result, t = timed(lambda: front.process(Frame(0.0, 0, "bench", bgr)), args.repeats)
        times += t
        count += len(result.tags)
    print(f"  {ms(times)} over {len(small)} frames with {count} tags in all")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
