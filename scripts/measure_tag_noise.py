"""Measure the AprilTag observation model of slamio/camera/tag_noise.py: real photos and rendered frames.

1. **Real photos** (tests/data/apriltag-photos, the eleven pupil-labs robot-camera frames with
   known intrinsics, tag side 0.065 m): the chosen detector's corners, refined as the
   front-end does, are fitted with a square (IPPE); the RMS reprojection residual over the
   four corners leaves 8 − 6 = 2 degrees of freedom of 8, so the corner σ is about
   residual·√(8/2). Those photos have no pose truth; they give the corner precision only.
2. **Rendered frames** at known poses (slamio/camera/render.py; the 0.16 m tag and the
   Kinect-intrinsics camera of slamio/camera/accuracy.py, fx = 525): distances × viewing
   angles, ``--repeats`` pixel-noise draws each. Per cell: RMS error of range, bearing and
   tag yaw against the truth, and the RMS corner error against the projected true corners.
   The gains of the model are the ratios of those RMS errors to the model's formula with
   gain 1 at the rendered corner precision (medians over cells; p_r a least-squares slope).

Usage: ``.venv/bin/python -m scripts.measure_tag_noise [--repeats N] [--noise GREY]``.
Prints the real-photo corner σ, the per-cell table, the fitted gains and, per cell, the
model's σ over the measured RMS (1 = the model fits).
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread(force=False)

import argparse  # noqa: E402
import math  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from slamio.camera.accuracy import ROBOT_POSE, real_corner_sigma_px, TAG_CENTRE_HEIGHT_M, TAG_SIZE_M, tag_camera, world_point  # noqa: E402
from slamio.camera.apriltag import AprilTagDetector, refine_tag_corners  # noqa: E402
from slamio.camera.detect import FrontEnd, FrontEndConfig  # noqa: E402
from slamio.camera.render import Scene, TagSpec, project_world_points, render, tag_corners_world  # noqa: E402
from slamio.camera.sources import Frame  # noqa: E402
from slamio.camera.tag_noise import TagNoise, TagNoiseGains  # noqa: E402
from slamio.geometry import wrap_angle  # noqa: E402
from scripts.common import APRILTAG_PHOTOS  # noqa: E402

DISTANCES_M = (0.75, 1.25, 2.0, 2.75, 3.5)
VIEWS_DEG = (0.0, 10.0, 20.0, 35.0, 50.0, 60.0, 70.0)


def rendered_cell(distance_m: float, view_deg: float, repeats: int, noise: float, rng, supersample: int = 2) -> dict:
    """RMS errors of one (distance, viewing angle) over ``repeats`` noisy renders; tag straight ahead."""
    camera = tag_camera()
    front = FrontEnd(camera, FrontEndConfig(kind="apriltag", tag_size_m=TAG_SIZE_M))
    detector = AprilTagDetector()
    x, y = world_point(distance_m, 0.0)
    face = ROBOT_POSE[2] + math.pi + math.radians(view_deg)
    tag = TagSpec(7, x, y, TAG_CENTRE_HEIGHT_M, face, TAG_SIZE_M)
    truth_px = project_world_points(camera, ROBOT_POSE, tag_corners_world(tag))
    true_yaw = wrap_angle(face - ROBOT_POSE[2])
    errs, corner_errs = [], []
    for k in range(repeats):
        image = render(camera, ROBOT_POSE, Scene(tags=(tag,)), noise_sigma=noise, rng=rng, supersample=supersample)
        grey = cv2.cvtColor(image.bgr, cv2.COLOR_BGR2GRAY)
        for d in detector.detect(grey):
            refined = refine_tag_corners(grey, d.corners_px, camera)
            refined = d.corners_px if refined is None else refined
            corner_errs.extend(np.linalg.norm(refined - truth_px, axis=1) / math.sqrt(2))  # per axis
        for o in front.process(Frame(0.0, k, "rendered", image.bgr)).observations:
            errs.append((o.range_m - distance_m, wrap_angle(o.bearing_rad), wrap_angle(o.tag_yaw_rad - true_yaw)))
    e = np.array(errs).reshape(-1, 3)
    rms = np.sqrt(np.mean(e**2, axis=0)) if len(e) else np.full(3, np.nan)
    yaw = np.abs(e[:, 2]) if len(e) else np.zeros(0)
    # a flipped IPPE solution is an outlier of about 2φ, not Gaussian noise: counted apart
    flips = int(np.sum(yaw > 0.5 * max(math.radians(view_deg), math.radians(10.0)) + 0.05)) if view_deg > 0 else 0
    yaw_core = yaw[yaw <= 0.5 * max(math.radians(view_deg), math.radians(10.0)) + 0.05] if view_deg > 0 else yaw
    return {
        "distance_m": distance_m, "view_deg": view_deg, "found": len(e), "frames": repeats,
        "range_rms_m": rms[0], "bearing_rms_rad": rms[1],
        "yaw_rms_rad": float(np.sqrt(np.mean(yaw_core**2))) if len(yaw_core) else float("nan"),
        "yaw_flips": flips,
        "corner_rms_px": float(np.sqrt(np.mean(np.square(corner_errs)))) if corner_errs else float("nan"),
    }


def fit_gains(cells: list[dict], corner_sigma_px: float, fx_px: float, tag_size_m: float) -> TagNoiseGains:
    """Gains making the model (at the rendered corner σ) match the measured RMS errors."""
    unit = TagNoise(fx_px, tag_size_m, corner_sigma_px, TagNoiseGains(1.0, 1.0, 0.0, 1.0))
    ok = [c for c in cells if c["found"] >= 3]
    g_b = float(np.nanmedian([c["bearing_rms_rad"] / unit.sigma_bearing_rad() for c in ok]))
    # range: log(ratio) = log g_r − p_r·log cos φ
    ratios = np.array([c["range_rms_m"] / unit.sigma_range_m(c["distance_m"], 0.0) for c in ok])
    minus_log_cos = np.array([-math.log(math.cos(math.radians(c["view_deg"]))) for c in ok])
    A = np.column_stack([np.ones(len(ok)), minus_log_cos])
    (log_g_r, p_r), *_ = np.linalg.lstsq(A, np.log(ratios), rcond=None)
    # yaw: g_y solves sigma(g_y) = measured per cell (monotone in g_y); median over cells
    g_ys = []
    for c in ok:
        target = c["yaw_rms_rad"]
        if not math.isfinite(target):
            continue
        lo, hi = 1e-3, 1e3
        for _ in range(60):
            mid = math.sqrt(lo * hi)
            model = TagNoise(fx_px, tag_size_m, corner_sigma_px, TagNoiseGains(1, 1, 0, mid))
            if model.sigma_tag_yaw_rad(c["distance_m"], math.radians(c["view_deg"])) < target:
                lo = mid
            else:
                hi = mid
        g_ys.append(math.sqrt(lo * hi))
    return TagNoiseGains(round(g_b, 2), round(float(math.exp(log_g_r)), 2), round(float(p_r), 2),
                         round(float(np.median(g_ys)), 2))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=12, help="noisy renders per cell (default 12)")
    parser.add_argument("--noise", type=float, default=6.0, help="pixel noise σ, grey levels (default 6)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--supersample", type=int, default=2,
                        help="rays per pixel side when rendering (default 2; fgslam live --port sim renders with 1)")
    args = parser.parse_args(argv)

    sigma_real, n_real = real_corner_sigma_px(APRILTAG_PHOTOS)
    print(f"real photos (pupil-labs, refined corners): {n_real} tags, corner sigma ≈ {sigma_real:.2f} px")

    rng = np.random.default_rng(args.seed)
    cells = [rendered_cell(d, v, args.repeats, args.noise, rng, args.supersample) for d in DISTANCES_M for v in VIEWS_DEG]
    sigma_px = float(np.nanmedian([c["corner_rms_px"] for c in cells]))
    fx = float(tag_camera().K[0, 0])
    gains = fit_gains(cells, sigma_px, fx, TAG_SIZE_M)
    model = TagNoise(fx, TAG_SIZE_M, sigma_px, gains)
    print(f"rendered frames: corner RMS (per axis) median {sigma_px:.3f} px; fitted gains {gains}")
    print("| distance | view | found | corner px | range RMS (model/meas.) | bearing RMS mrad (model/meas.) "
          "| yaw RMS deg (model/meas.) | yaw flips |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for c in cells:
        d, v = c["distance_m"], math.radians(c["view_deg"])
        print(f"| {d:.2f} m | {c['view_deg']:.0f}° | {c['found']}/{c['frames']} | {c['corner_rms_px']:.3f} "
              f"| {c['range_rms_m'] * 1000:.1f} mm ({model.sigma_range_m(d, v) / c['range_rms_m']:.2f}) "
              f"| {c['bearing_rms_rad'] * 1000:.2f} ({model.sigma_bearing_rad() / c['bearing_rms_rad']:.2f}) "
              f"| {math.degrees(c['yaw_rms_rad']):.2f} ({model.sigma_tag_yaw_rad(d, v) / c['yaw_rms_rad']:.2f}) "
              f"| {c['yaw_flips']} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
