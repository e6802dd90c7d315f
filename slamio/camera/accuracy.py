"""Accuracy of the front-end: errors vs distance on rendered frames, and scoring against listed corners.

``python -m slamio.camera.accuracy`` prints the table of docs/camera.md. Each row renders,
for one distance, every combination of bearing and landmark orientation below, runs the
frame through :class:`~slamio.camera.detect.FrontEnd` exactly as ``fgslam detect`` does, and
reports the largest error over them:

- **Tags**: a 0.16 m tag36h11 tag (id 7) at centre height 0.20 m, seen by a 640×480 camera
  with the Kinect's intrinsics (fx = fy = 525) mounted 0.10 m ahead of the robot's centre at
  0.20 m height; bearings −20°, 0°, +20° (±10° at 0.5 m, where a wider bearing puts the
  tag partly out of view) and tag faces turned −40°, 0°, +40° from facing the robot.
- **Cylinders**: seed 000's red, green and blue cylinders (radius 0.05 m, 0.40 / 0.60 /
  0.80 m tall) seen by the Kinect mounted at 0.30 m height, 0.10 m ahead; the same bearings;
  depth quantised like the Kinect's 11-bit disparity. Heights are scored where the top is in
  view; the "seed" columns run the same frames through seed 000's linear column-to-angle
  map and seed 002's gHeight.

The robot stands at (1.0 m, 2.0 m, 0.3 rad) in the world, so every frame conversion is
exercised. Frames get Gaussian pixel noise (σ = 2 grey levels) from a seeded generator.

:func:`real_corner_sigma_px` measures the corner precision on the real pupil-labs photos
(slamio/camera/tag_noise.py uses it). :func:`read_corner_list` and :func:`match_detections` score a detector against listed tag
corners (the real photos in ``tests/data/apriltag-photos``); ``scripts/bench_apriltag.py``
and ``tests/test_camera_apriltag.py`` use them.
"""

from __future__ import annotations

import argparse
import math
import os
import re
from dataclasses import dataclass, field, replace

import numpy as np

from slamio.camera.colour import ColourOptions
from slamio.camera.detect import FrontEnd, FrontEndConfig
from slamio.camera.model import CameraModel, T_robot_camera_from_mount, kinect_v1_default
from slamio.camera.render import CYLINDER_BGR, CylinderSpec, Scene, TagSpec, render
from slamio.camera.sources import Frame
from slamio.camera.tag_union import listing_lines
from slamio.geometry import wrap_angle

ROBOT_POSE = (1.0, 2.0, 0.3)
DISTANCES_M = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0)
TAG_SIZE_M = 0.16
TAG_CENTRE_HEIGHT_M = 0.20
CYLINDERS = (("red", 0, 0.40), ("green", 1, 0.60), ("blue", 2, 0.80))
CYLINDER_RADIUS_M = 0.05


def tag_camera() -> CameraModel:
    return kinect_v1_default(T_robot_camera_from_mount(x_m=0.10, z_m=0.20))


def kinect_camera() -> CameraModel:
    return kinect_v1_default(T_robot_camera_from_mount(x_m=0.10, z_m=0.30))


def bearings_deg(distance_m: float) -> tuple[float, ...]:
    return (-10.0, 0.0, 10.0) if distance_m < 0.75 else (-20.0, 0.0, 20.0)


def world_point(distance_m: float, bearing_deg: float, pose=ROBOT_POSE) -> tuple[float, float]:
    a = pose[2] + math.radians(bearing_deg)
    return pose[0] + distance_m * math.cos(a), pose[1] + distance_m * math.sin(a)


@dataclass(frozen=True)
class Errors:
    """Largest absolute errors over the frames of one distance (NaN when nothing was measured)."""

    distance_m: float
    frames: int
    measured: int
    range_pct: float
    bearing_deg: float
    third: float  # tag yaw (degrees) or height (%)
    third_count: int  # how many had a tag yaw / height
    seed_bearing_deg: float = float("nan")  # seed 000's linear map (cylinders)
    seed_height_pct: float = float("nan")  # seed 002's gHeight (cylinders)


def _max(values) -> float:
    values = [v for v in values if v is not None and math.isfinite(v)]
    return max(values) if values else float("nan")


def tag_errors(distance_m: float, *, noise_sigma: float = 2.0, rng: np.random.Generator | None = None,
               yaw_offsets_deg=(-40.0, 0.0, 40.0), supersample: int = 4) -> Errors:
    rng = rng if rng is not None else np.random.default_rng(0)
    camera = tag_camera()
    front = FrontEnd(camera, FrontEndConfig(kind="apriltag", tag_size_m=TAG_SIZE_M))
    rows, frames = [], 0
    for bearing in bearings_deg(distance_m):
        for yaw_offset in yaw_offsets_deg:
            x, y = world_point(distance_m, bearing)
            face = ROBOT_POSE[2] + math.radians(bearing) + math.pi + math.radians(yaw_offset)
            tag = TagSpec(7, x, y, TAG_CENTRE_HEIGHT_M, face, TAG_SIZE_M)
            image = render(camera, ROBOT_POSE, Scene(tags=(tag,)), noise_sigma=noise_sigma, rng=rng,
                           supersample=supersample)
            frames += 1
            result = front.process(Frame(0.0, frames, "rendered", image.bgr))
            for o in result.observations:
                true_yaw = wrap_angle(face - ROBOT_POSE[2])
                rows.append((abs(o.range_m - distance_m) / distance_m * 100.0,
                             abs(math.degrees(wrap_angle(o.bearing_rad - math.radians(bearing)))),
                             abs(math.degrees(wrap_angle(o.tag_yaw_rad - true_yaw)))))
    return Errors(distance_m, frames, len(rows), _max(r[0] for r in rows), _max(r[1] for r in rows),
                  _max(r[2] for r in rows), len(rows))


def cylinder_errors(distance_m: float, *, noise_sigma: float = 2.0, rng: np.random.Generator | None = None,
                    depth_model: str = "kinect", colours=CYLINDERS, supersample: int = 4) -> Errors:
    rng = rng if rng is not None else np.random.default_rng(0)
    camera = kinect_camera()
    exact = FrontEnd(camera, FrontEndConfig(kind="colour"))
    seeds = FrontEnd(camera, FrontEndConfig(
        kind="colour", colour=replace(ColourOptions(), bearing_method="linear", height_method="gheight")))
    rows, seed_rows, frames = [], [], 0
    for bearing in bearings_deg(distance_m):
        for name, landmark_id, height in colours:
            x, y = world_point(distance_m, bearing)
            cyl = CylinderSpec(x, y, CYLINDER_RADIUS_M, height, CYLINDER_BGR[name], name, landmark_id)
            image = render(camera, ROBOT_POSE, Scene(cylinders=(cyl,)), depth_model=depth_model,
                           noise_sigma=noise_sigma, rng=rng, supersample=supersample)
            frames += 1
            frame = Frame(0.0, frames, "rendered", image.bgr, image.depth_m)
            for front, out in ((exact, rows), (seeds, seed_rows)):
                for o in front.process(frame).observations:
                    out.append((abs(o.range_m - distance_m) / distance_m * 100.0,
                                abs(math.degrees(wrap_angle(o.bearing_rad - math.radians(bearing)))),
                                None if o.height_m is None else abs(o.height_m - height) / height * 100.0))
    return Errors(distance_m, frames, len(rows), _max(r[0] for r in rows), _max(r[1] for r in rows),
                  _max(r[2] for r in rows), sum(r[2] is not None for r in rows),
                  _max(r[1] for r in seed_rows), _max(r[2] for r in seed_rows))


def error_table(distances_m=DISTANCES_M, *, noise_sigma: float = 2.0, seed: int = 0,
                supersample: int = 4) -> list[tuple[Errors, Errors]]:
    """(tag errors, cylinder errors) per distance; all pixel noise from one seeded generator."""
    rng = np.random.default_rng(seed)
    return [(tag_errors(d, noise_sigma=noise_sigma, rng=rng, supersample=supersample),
             cylinder_errors(d, noise_sigma=noise_sigma, rng=rng, supersample=supersample)) for d in distances_m]


def format_table(rows: list[tuple[Errors, Errors]]) -> str:
    def f(v, digits=2):
        return "—" if not math.isfinite(v) else f"{v:.{digits}f}"

    lines = [
        "| distance | tags found | tag range | tag bearing | tag yaw | cylinders found | cyl. range | cyl. bearing "
        "| cyl. height (n) | seed 000 linear bearing | seed 002 gHeight |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for tag, cyl in rows:
        lines.append(
            f"| {tag.distance_m:.1f} m | {tag.measured}/{tag.frames} | {f(tag.range_pct)} % | {f(tag.bearing_deg, 3)}° "
            f"| {f(tag.third, 1)}° | {cyl.measured}/{cyl.frames} | {f(cyl.range_pct)} % | {f(cyl.bearing_deg, 3)}° "
            f"| {f(cyl.third)} % ({cyl.third_count}) | {f(cyl.seed_bearing_deg)}° | {f(cyl.seed_height_pct, 1)} % |"
        )
    return "\n".join(lines)


# --------------------------------------------------------------------------- real photos


#: fx, cx, fy, cy of the pupil-labs photos (tests/data/apriltag-photos/README.md); tags 0.065 m.
PUPIL_K = {
    "pupil_test_image.png": (336.7755634193813, 333.3575643300718, 336.02729840829176, 212.77376312080065),
    **{f"pupil_test_image_multiple_{k:02d}.png": (338.563277422543, 336.45495347495824, 338.939280638548,
                                                    230.486982216255) for k in range(1, 11)},
}


def real_corner_sigma_px(photos: str | os.PathLike[str]) -> tuple[float, int]:
    """Corner precision (px) of the front-end on the pupil-labs photos in ``photos``, and the tag count.

    Those photos have intrinsics but no pose truth. Each tag's corners, refined as the
    front-end does, are fitted with a square (IPPE); the RMS residual over 8 coordinates
    with 6 pose parameters fitted leaves 2 degrees of freedom, so the per-axis corner σ is
    about residual·√(8/2). Returns the median over tags of that.
    """
    import cv2

    from slamio.camera.apriltag import AprilTagDetector, estimate_tag_pose, refine_tag_corners

    detector = AprilTagDetector()
    residuals = []
    for name, (fx, cx, fy, cy) in PUPIL_K.items():
        cam = CameraModel(640, 480, np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]))
        grey = cv2.imread(os.path.join(photos, name), cv2.IMREAD_GRAYSCALE)
        for d in detector.detect(grey):
            corners = refine_tag_corners(grey, d.corners_px, cam)
            if corners is None:  # as the front-end: the detector's corners
                corners = d.corners_px
            poses = estimate_tag_pose(corners, 0.065, cam)
            if poses:
                residuals.append(poses[0].reprojection_error_px)
    return float(np.median(residuals)) * math.sqrt(8 / 2), len(residuals)


# --------------------------------------------------------------------------- listed corners


_POINT = re.compile(r"\(\s*([-+0-9.eE]+)\s+([-+0-9.eE]+)\s*\)")


def read_corner_list(path: str | os.PathLike[str]) -> list[tuple[int, np.ndarray]]:
    """Listed detections ``id, (x0 y0), (x1 y1), (x2 y2), (x3 y3)`` per line → [(id, (4, 2) corners)].

    The corners are converted from the AprilTag library's pixel convention (top-left pixel's
    corner at 0, 0) to OpenCV's (its centre at 0, 0), the convention of
    :class:`~slamio.camera.apriltag.TagDetection`. Their order is kept (sets are matched).
    """
    out = []
    for number, text in listing_lines(path):
        head, _, rest = text.partition(",")
        points = _POINT.findall(rest)
        try:
            tag_id = int(head)
            if len(points) != 4:
                raise ValueError
        except ValueError:
            raise ValueError(f"{path}:{number}: expected 'id, (x y), (x y), (x y), (x y)', got {text!r}") from None
        out.append((tag_id, np.array([[float(x), float(y)] for x, y in points]) - 0.5))
    return out


def corner_set_errors(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-corner distances between two quadrilaterals under the best corner correspondence.

    Corner orders differ between detectors (start corner and direction), so every cyclic
    shift of both directions is tried and the one with the smallest largest distance wins.
    """
    a = np.asarray(a, dtype=float).reshape(4, 2)
    b = np.asarray(b, dtype=float).reshape(4, 2)
    best = None
    for order in (b, b[::-1]):
        for shift in range(4):
            d = np.linalg.norm(a - np.roll(order, shift, axis=0), axis=1)
            if best is None or d.max() < best.max():
                best = d
    return best


@dataclass
class MatchResult:
    """A detector scored against listed tags: matched corner errors, false detections, misses."""

    listed: int = 0
    found: int = 0
    false_detections: list = field(default_factory=list)  # (image, id, centre)
    missed: list = field(default_factory=list)  # (image, id, centre)
    corner_errors_px: list = field(default_factory=list)  # every matched corner's distance

    def add(self, other: "MatchResult") -> None:
        self.listed += other.listed
        self.found += other.found
        self.false_detections += other.false_detections
        self.missed += other.missed
        self.corner_errors_px += other.corner_errors_px

    @property
    def max_corner_error_px(self) -> float:
        return max(self.corner_errors_px) if self.corner_errors_px else float("nan")

    @property
    def mean_corner_error_px(self) -> float:
        return float(np.mean(self.corner_errors_px)) if self.corner_errors_px else float("nan")


def match_detections(detections: list[tuple[int, np.ndarray]], listed: list[tuple[int, np.ndarray]],
                     *, tolerance_px: float = 3.0, image: str = "") -> MatchResult:
    """Match (id, corners) detections to listed ones: same id, every corner within ``tolerance_px``.

    Each listed tag matches at most one detection (the closest); a detection matching no
    listed tag is a false detection.
    """
    result = MatchResult(listed=len(listed))
    used = set()
    for tag_id, corners in detections:
        best, best_k = None, None
        for k, (lid, lcorners) in enumerate(listed):
            if k in used or lid != tag_id:
                continue
            e = corner_set_errors(corners, lcorners)
            if e.max() <= tolerance_px and (best is None or e.max() < best.max()):
                best, best_k = e, k
        if best is None:
            result.false_detections.append((image, tag_id, np.asarray(corners).mean(axis=0)))
        else:
            used.add(best_k)
            result.found += 1
            result.corner_errors_px.extend(float(x) for x in best)
    for k, (lid, lcorners) in enumerate(listed):
        if k not in used:
            result.missed.append((image, lid, lcorners.mean(axis=0)))
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m slamio.camera.accuracy", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--noise", type=float, default=2.0, help="pixel noise sigma, grey levels (default 2)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the pixel noise (default 0)")
    parser.add_argument("--distances", default=",".join(str(d) for d in DISTANCES_M), help="comma-separated, metres")
    args = parser.parse_args(argv)
    distances = tuple(float(d) for d in args.distances.split(","))
    print(format_table(error_table(distances, noise_sigma=args.noise, seed=args.seed)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
