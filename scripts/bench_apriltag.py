"""Benchmark: AprilTag detectors on the real photos — recall, false detections, corner error, CPU time.

For each detector configuration, on the three NASA photos of ``tests/data/apriltag-photos``:

- **recall against the union listing** (``nasa_union.txt``: every tag that any of eight
  detector set-ups finds, 61, built by ``scripts/apriltag_union.py``), matched by id and
  centre; detections matching no tag of the union are listed ("not in union": false
  detections unless a look at the photo shows a tag — see ``SEEN_BY_EYE`` there);
- recall against the photos' own listing (47 tags listed by the AprilTag 3 reference
  detector: the chosen detector's own kind), matched by id and corner set within 3 px, and
  the corner error against those listed corners (max / mean);
- **CPU time per 640×480 frame** (``time.process_time``: this process's CPU, not the wall
  clock) on the eleven pupil-labs photos and nine 640×480 crops of the NASA photos, median
  and 90th percentile; each run of a configuration alternates with a run of the front-end's
  first pass (decimate 1, no upsampling) on the same frame, and the ratio of the two medians
  is printed: on a busy machine the ratio travels better than the milliseconds.

Then the chosen configuration's corners after ``refine_tag_corners`` against the listed ones,
and, by kind of frame (robot-camera photos, NASA crops), the CPU time per frame of each of the
front-end detector's passes, of the detector and of the whole front-end (detection,
refinement, pose, geometry): median, p90 and worst frame. Everything runs on one thread
(AprilTag 3's ``nthreads`` 1, and OpenCV's calls inside the detector and the front-end).
Usage: ``.venv/bin/python -m scripts.bench_apriltag [--photos DIR] [--repeats N] [--only SUBSTRING]``.
"""

from __future__ import annotations

import os

from scripts.common import one_blas_thread

one_blas_thread(force=False)

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from slamio.camera.accuracy import MatchResult, match_detections, read_corner_list  # noqa: E402
from slamio.camera.apriltag import AprilTagDetector, refine_tag_corners  # noqa: E402
from slamio.camera.detect import FrontEnd, FrontEndConfig  # noqa: E402
from slamio.camera.model import kinect_v1_default  # noqa: E402
from slamio.camera.sources import Frame  # noqa: E402
from slamio.camera.tag_passes import TagPasses  # noqa: E402
from slamio.camera.tag_union import found_by_a_setup as counts_for_recall  # noqa: E402
from slamio.camera.tag_union import read_union, score_against_union  # noqa: E402
from scripts.common import APRILTAG_PHOTOS  # noqa: E402

DEFAULT_PHOTOS = APRILTAG_PHOTOS
FIRST_PASS = dict(backend="apriltag3", quad_decimate=1.0)  # decimate 1, no upsampling: the reference for times
ARUCO_PASS = dict(backend="aruco", aruco_refinement="none", aruco_window_px=3, aruco_min_perimeter=0.1)
# AprilTag 3's quad thresholds: no threshold in 4x4 tiles of less contrast, quads of fewer edge pixels dropped
QUADS_20 = dict(min_white_black_diff=20, min_cluster_pixels=40)
QUADS_40 = dict(min_white_black_diff=40, min_cluster_pixels=40)  # the front-end's enlarged pass
QUADS_60 = dict(min_white_black_diff=60, min_cluster_pixels=60)

CONFIGS = [
    ("apriltag3 decimate 1, refine_edges off (single pass)", [FIRST_PASS]),
    ("apriltag3 decimate 1, refine_edges on", [dict(refine_edges=True)]),
    ("apriltag3 decimate 2 (library default)", [dict(quad_decimate=2.0, refine_edges=True)]),
    ("apriltag3 decimate 1, quad_sigma -0.8 (sharpen)", [dict(quad_sigma=-0.8)]),
    ("apriltag3 on the image upsampled 1.5x", [dict(upsample=1.5)]),
    ("apriltag3 on the image upsampled 1.75x", [dict(upsample=1.75)]),
    ("apriltag3 on the image upsampled 2x", [dict(upsample=2.0)]),
    ("apriltag3 first pass + upsampled 2x", [FIRST_PASS, dict(upsample=2.0)]),
    ("apriltag3 first pass + upsampled 1.5x", [FIRST_PASS, dict(upsample=1.5)]),
    ("cv2.aruco, no corner refinement", [dict(backend="aruco", aruco_refinement="none")]),
    ("cv2.aruco, CORNER_REFINE_APRILTAG", [dict(backend="aruco", aruco_refinement="apriltag")]),
    ("apriltag3 first pass + cv2.aruco", [FIRST_PASS, dict(backend="aruco", aruco_refinement="none")]),
    ("apriltag3 upsampled 2x + cv2.aruco", [dict(upsample=2.0), dict(backend="aruco", aruco_refinement="none")]),
    ("cv2.aruco, one 3 px window, perimeter >= 0.1", [ARUCO_PASS]),
    ("apriltag3 first pass + cv2.aruco 3 px", [FIRST_PASS, ARUCO_PASS]),
    ("apriltag3 upsampled 1.5x + cv2.aruco 3 px", [dict(upsample=1.5), ARUCO_PASS]),
    ("apriltag3 upsampled 1.75x + cv2.aruco 3 px", [dict(upsample=1.75), ARUCO_PASS]),
    ("apriltag3 upsampled 2x + cv2.aruco 3 px", [dict(upsample=2.0), ARUCO_PASS]),
    ("apriltag3 upsampled 1.75x, white-black 20, cluster 40", [dict(upsample=1.75, **QUADS_20)]),
    ("apriltag3 upsampled 1.75x, white-black 40, cluster 40", [dict(upsample=1.75, **QUADS_40)]),
    ("apriltag3 upsampled 1.75x, white-black 60, cluster 60", [dict(upsample=1.75, **QUADS_60)]),
    ("apriltag3 upsampled 1.75x, white-black 40, cluster 40 + cv2.aruco 3 px (front-end)",
     [dict(upsample=1.75, **QUADS_40), ARUCO_PASS]),
    ("apriltag3 upsampled 2x, white-black 40, cluster 40 + cv2.aruco 3 px", [dict(upsample=2.0, **QUADS_40), ARUCO_PASS]),
]


def rendered_tags(seed: int = 0):
    """Rendered frames of one 0.16 m tag with its true corners: 1-7 m, turned ±40° and 0°, three bearings.

    The Kinect's intrinsics (fx = 525), the camera 0.2 m above the floor, σ = 2 grey levels of noise.
    """
    import math

    from slamio.camera.model import T_robot_camera_from_mount
    from slamio.camera.render import Scene, TagSpec, project_world_points, render, tag_corners_world

    camera = kinect_v1_default(T_robot_camera_from_mount(z_m=0.2))
    rng = np.random.default_rng(seed)
    out = []
    for distance in (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0):
        for turn in (-0.7, 0.0, 0.7):
            for bearing in (-0.2, 0.0, 0.2):
                tag = TagSpec(11, distance * math.cos(bearing), distance * math.sin(bearing), 0.2, math.pi + turn, 0.16)
                bgr = render(camera, (0.0, 0.0, 0.0), Scene(tags=(tag,)), supersample=3).bgr
                noisy = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY) + rng.normal(0.0, 2.0, bgr.shape[:2])
                truth = project_world_points(camera, (0.0, 0.0, 0.0), tag_corners_world(tag))
                out.append((np.clip(noisy, 0, 255).astype(np.uint8), truth))
    return camera, out


def rendered_corner_errors(detect, frames, camera=None):
    """(found, largest corner error per found tag) over rendered frames; refined on the image when ``camera``."""
    errors = []
    for image, truth in frames:
        found = [d for d in detect(image) if d.tag_id == 11]
        if len(found) != 1:
            continue
        corners = found[0].corners_px
        if camera is not None and found[0].side_px / 8.0 >= 1.5:
            refined = refine_tag_corners(image, corners, camera)
            corners = corners if refined is None else refined
        errors.append(float(np.abs(corners - truth).max()))
    return len(errors), np.array(errors)


def cpu_times(detect, reference, frames, repeats, inputs=None):
    """CPU seconds of ``detect`` and of ``reference`` per frame, run alternately on each frame
    (``detect`` on ``inputs`` — the same frames in another form, such as BGR — when given)."""
    mine, ref = [], []
    for image, own in zip(frames, frames if inputs is None else inputs):
        for _ in range(repeats):
            for function, argument, times in ((detect, own, mine), (reference, image, ref)):
                t0 = time.process_time()
                function(argument)
                times.append(time.process_time() - t0)
    return np.array(mine), np.array(ref)


def crops_640x480(image):
    """640×480 windows of a larger image: top-left, centre, bottom-right."""
    h, w = image.shape[:2]
    corners = [(0, 0), ((h - 480) // 2, (w - 640) // 2), (h - 480, w - 640)]
    return [np.ascontiguousarray(image[r:r + 480, c:c + 640]) for r, c in corners]


def timing_frames(photos: Path, nasa_grey) -> list:
    """The 640×480 frames times are measured on: the pupil-labs photos, then crops of the NASA photos."""
    frames = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted(photos.glob("pupil_*.png"))]
    return frames + [c for g in nasa_grey for c in crops_640x480(g)]


def front_end_tags(front: FrontEnd, frames) -> int:
    """How many tags the whole front-end reports over grey ``frames``."""
    return sum(len(front.process(Frame(0.0, 0, "bench", cv2.cvtColor(g, cv2.COLOR_GRAY2BGR))).tags) for g in frames)


def ms(times, repeats=1):
    """Median (90th percentile, worst frame) in ms; ``times`` run frame by frame, ``repeats`` each
    (a frame's time is the median of its runs)."""
    per_frame = np.median(np.asarray(times).reshape(-1, repeats), axis=1)
    return (f"{1e3 * np.median(per_frame):5.1f} (p90 {1e3 * np.percentile(per_frame, 90):5.1f}, "
            f"worst {1e3 * per_frame.max():5.1f})")


def accuracy_columns(detector, images, listed, paths, union, rendered):
    """The columns of a detector's row that are not times: its score against the union listing
    (:class:`UnionScore`), against the reference listing (:class:`MatchResult`), and on the
    rendered frames (found, largest corner error per found tag)."""
    reference, found_by_image = MatchResult(), {}
    for image, tags, path in zip(images, listed, paths):
        found = detector.detect(image)
        found_by_image[path.name] = [(d.tag_id, d.centre_px) for d in found]
        reference.add(match_detections([(d.tag_id, d.corners_px) for d in found], tags, image=path.name))
    score = score_against_union(found_by_image, union, counts_for_recall)
    n_rendered, errors = rendered_corner_errors(detector.detect, rendered)
    return score, reference, n_rendered, errors


def match_refined(images, listed, paths, detector=None) -> tuple[MatchResult, int]:
    """The front-end detector's tags with ``refine_tag_corners``'s corners (the detector's own
    where refinement declines) matched to the listed corners, and how many kept the detector's."""
    detector = detector or FrontEnd(kinect_v1_default(), FrontEndConfig()).detector
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
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per frame (default 3)")
    parser.add_argument("--only", default="", help="run only configurations whose name contains this (or one of "
                        "these, comma-separated)")
    args = parser.parse_args(argv)
    photos = Path(args.photos)
    nasa = sorted(photos.glob("nasa_*.jpg"))
    if not nasa:
        print(f"no nasa_*.jpg in {photos}", file=sys.stderr)
        return 1
    nasa_grey = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in nasa]
    listed = [read_corner_list(p.with_suffix(".txt")) for p in nasa]
    union = read_union(photos / "nasa_union.txt")
    small = timing_frames(photos, nasa_grey)
    counted = sum(1 for t in union if counts_for_recall(t))
    print(f"{len(nasa)} NASA photos ({nasa_grey[0].shape[1]}×{nasa_grey[0].shape[0]}): {counted} tags in the union "
          f"listing, {sum(len(x) for x in listed)} in the reference listing; {len(small)} frames of 640×480 for "
          f"timing; {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}\n")
    camera, rendered = rendered_tags()
    print(f"rendered: {len(rendered)} frames of a 0.16 m tag at 1-7 m (fx 525), corner error against the truth "
          "(largest coordinate error per tag; max and mean over the tags found)\n")
    header = (f"{'detector':52} {'union':>6} {'not in':>6} {'reference':>9} {'corner err':>11} "
              f"{'rendered: found, corner err':>27}   CPU ms per 640×480 | first pass | ratio")
    print(header)
    print("-" * len(header))
    first_pass = AprilTagDetector(**FIRST_PASS)
    for name, settings in CONFIGS:
        if not any(part in name for part in args.only.split(",")):
            continue
        detector = TagPasses([AprilTagDetector(**s) for s in settings])
        score, reference, n_rendered, errors = accuracy_columns(detector, nasa_grey, listed, nasa, union, rendered)
        mine, ref = cpu_times(detector.detect, first_pass.detect, small, args.repeats)
        unlisted = score.not_listed + score.duplicates
        print(f"{name:52} {score.found:>2}/{score.counted:<3} {len(unlisted):>6} {reference.found:>4}/{reference.listed:<4} "
              f"{reference.max_corner_error_px:5.2f}/{reference.mean_corner_error_px:.2f}  "
              f"{n_rendered:>10}/{len(rendered)} {errors.max():5.2f}/{errors.mean():.2f} px   "
              f"{ms(mine, args.repeats)} | {ms(ref, args.repeats)} | {np.median(mine) / np.median(ref):.2f}", flush=True)
        for image_name, tag_id, centre in unlisted:
            print(f"{'':8}not in the union: {image_name} id {tag_id} at ({centre[0]:.1f}, {centre[1]:.1f})")
        if score.found_other:
            print(f"{'':8}also found {score.found_other} real tag(s) outside the counted union")

    print("\nfront-end detector + refine_tag_corners against the reference listing's corners:")
    detector = FrontEnd(kinect_v1_default(), FrontEndConfig()).detector
    refined, not_refined = match_refined(nasa_grey, listed, nasa, detector)
    print(f"  {refined.found}/{refined.listed} matched, corner difference max {refined.max_corner_error_px:.3f} px, "
          f"mean {refined.mean_corner_error_px:.3f} px; {not_refined} tags kept the detector's corners "
          "(the listed corners are the reference detector's binarised corners, not ground truth)")
    for label, detect in (("first pass", first_pass.detect), ("front-end detector", detector.detect)):
        n_rendered, errors = rendered_corner_errors(detect, rendered, camera)
        print(f"  rendered, {label} + refine_tag_corners: {n_rendered}/{len(rendered)} found, corner error against the "
              f"truth max {errors.max():.2f} px, mean {errors.mean():.2f} px, 95 % {np.percentile(errors, 95):.2f} px")

    print("\nby kind of 640×480 frame, CPU ms per frame (median / p90 / worst of the frames, each frame the median of "
          f"its {args.repeats} runs), each run alternating with the single pass on the same frame:")
    front = FrontEnd(kinect_v1_default(), FrontEndConfig(kind="apriltag", tag_size_m=0.16))
    n_robot = len(sorted(photos.glob("pupil_*.png")))
    groups = (("robot-camera photos", small[:n_robot]), ("NASA crops", small[n_robot:]))
    for group, frames in groups:
        bgr = [cv2.cvtColor(g, cv2.COLOR_GRAY2BGR) for g in frames]
        print(f"  {group} ({len(frames)} frames, {front_end_tags(front, frames)} tags found by the front-end):")
        steps = [*((f"pass {k + 1}", frames, d.detect) for k, d in enumerate(detector.detectors)),
                 ("detector (both passes)", frames, detector.detect),
                 ("whole front-end", bgr, lambda image: front.process(Frame(0.0, 0, "bench", image)))]
        for label, images, function in steps:
            mine, ref = cpu_times(function, first_pass.detect, frames, args.repeats, inputs=images)
            print(f"    {label:24} {ms(mine, args.repeats)}   single pass {ms(ref, args.repeats)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
