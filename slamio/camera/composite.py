"""Rendered landmarks composited into real RGB-D frames at known poses: the colour front-end on real images.

Real frames without landmarks (clutter: red, green and blue furniture, bottles, walls) are
the test of what the colour checks reject; the same frames with a rendered cylinder pasted
in, colour and depth, at a known pose are the test of what they keep and how well it is
measured. :func:`landmark_layer` renders a scene's landmarks alone — their colour already
multiplied by their per-pixel coverage α (anti-aliased edges), α itself, and their depth
(from two renders over a black and a white world: α = 1 − (white − black)/255). The
landmark is pasted in front of the real scene (:func:`composite`): colour
``layer + (1 − α)·real``, depth replaced where the landmark covers the pixel centre, then
optionally the whole depth image shifted by a few pixels against the colour image
(:func:`shift_depth`), as a Kinect's imperfect depth-to-colour registration does.

:func:`composite_trial` scores the front-end over frames × landmark placements × depth
shifts: how many landmarks were found, the largest range, bearing and height errors, and how
many observations named a landmark that was not there. ``scripts/bench_colour_real.py``
prints the table of docs/camera.md from the real frames; ``tests/test_camera_colour_real.py``
asserts the goals on the frames shipped in ``tests/data/rgbd-real``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from slamio.camera.model import CameraModel
from slamio.camera.render import Scene, kinect_quantise_depth, render


@dataclass(frozen=True, eq=False)
class LandmarkLayer:
    colour: np.ndarray  # (H, W, 3) float, already multiplied by alpha
    alpha: np.ndarray  # (H, W) float in [0, 1]: coverage of each pixel by a landmark
    depth_m: np.ndarray  # (H, W) float32, NaN where no landmark covers the pixel centre


def landmark_layer(camera: CameraModel, robot_pose: tuple[float, float, float], scene: Scene, *,
                   supersample: int = 4, depth_model: str = "kinect") -> LandmarkLayer:
    """The scene's landmarks alone, seen by ``camera`` on a robot at ``robot_pose``."""
    black = Scene(scene.tags, scene.cylinders, floor_bgr=(0, 0, 0), background_bgr=(0, 0, 0), light_dir=scene.light_dir)
    white = Scene(scene.tags, scene.cylinders, floor_bgr=(255, 255, 255), background_bgr=(255, 255, 255),
                  light_dir=scene.light_dir)
    on_black = render(camera, robot_pose, black, supersample=supersample)
    on_white = render(camera, robot_pose, white, supersample=supersample)
    empty = render(camera, robot_pose, Scene(), supersample=1)
    alpha = 1.0 - (on_white.bgr.astype(np.float64) - on_black.bgr.astype(np.float64)).mean(axis=2) / 255.0
    alpha = np.clip(alpha, 0.0, 1.0)
    nearer = np.isfinite(on_black.depth_m) & ~(on_black.depth_m >= np.nan_to_num(empty.depth_m, nan=np.inf) - 1e-6)
    depth = np.where(nearer, on_black.depth_m, np.nan).astype(np.float32)
    if depth_model == "kinect":
        depth = kinect_quantise_depth(depth)
    return LandmarkLayer(on_black.bgr.astype(np.float64), alpha, depth)


def shift_depth(depth_m: np.ndarray, dx_px: int, dy_px: int) -> np.ndarray:
    """Depth moved by (dx, dy) pixels against the colour image; pixels shifted in are missing (NaN)."""
    out = np.full_like(depth_m, np.nan)
    h, w = depth_m.shape
    src = depth_m[max(0, -dy_px) : h - max(0, dy_px), max(0, -dx_px) : w - max(0, dx_px)]
    out[max(0, dy_px) : max(0, dy_px) + src.shape[0], max(0, dx_px) : max(0, dx_px) + src.shape[1]] = src
    return out


def composite(bgr: np.ndarray, depth_m: np.ndarray, layer: LandmarkLayer, *, depth_shift_px: tuple[int, int] = (0, 0),
              noise_sigma: float = 0.0, rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(BGR, depth) of a real frame with the layer's landmarks pasted in front of it."""
    colour = layer.colour + (1.0 - layer.alpha)[..., None] * bgr.astype(np.float64)
    if noise_sigma > 0:
        if rng is None:
            raise ValueError("noise needs an explicit numpy.random.Generator (seeded)")
        covered = layer.alpha > 0
        colour[covered] += rng.normal(0.0, noise_sigma, colour[covered].shape)
    out_bgr = np.clip(np.round(colour), 0, 255).astype(np.uint8)
    out_depth = np.where(np.isfinite(layer.depth_m), layer.depth_m, depth_m).astype(np.float32)
    dx, dy = depth_shift_px
    if dx or dy:
        out_depth = shift_depth(out_depth, dx, dy)
    return out_bgr, out_depth


# --------------------------------------------------------------------------- scoring


@dataclass
class CompositeScore:
    """Results of the colour front-end on composited frames (errors are the largest absolute ones)."""

    placed: int = 0
    found: int = 0
    wrong_landmarks: int = 0  # observations of a landmark that was not in the frame
    range_pct: list[float] = field(default_factory=list)
    bearing_deg: list[float] = field(default_factory=list)
    height_pct: list[float] = field(default_factory=list)

    @property
    def found_fraction(self) -> float:
        return self.found / self.placed if self.placed else float("nan")

    @staticmethod
    def worst(values: list[float]) -> float:
        return max(values) if values else float("nan")


def score_frame(observations, truth: dict[int, tuple[float, float, float]], score: CompositeScore) -> None:
    """Add one frame's observations; ``truth`` maps landmark id → (range_m, bearing_rad, height_m)."""
    from slamio.geometry import wrap_angle

    seen = set()
    for o in observations:
        if o.landmark_id not in truth or o.landmark_id in seen:
            score.wrong_landmarks += 1
            continue
        seen.add(o.landmark_id)
        range_m, bearing_rad, height_m = truth[o.landmark_id]
        score.range_pct.append(abs(o.range_m - range_m) / range_m * 100.0)
        score.bearing_deg.append(abs(math.degrees(wrap_angle(o.bearing_rad - bearing_rad))))
        if o.height_m is not None:
            score.height_pct.append(abs(o.height_m - height_m) / height_m * 100.0)
    score.placed += len(truth)
    score.found += len(seen)


def composite_trial(front, frames, cylinders, shifts_px=((0, 0),), *, supersample: int = 4,
                    noise_sigma: float = 2.0, seed: int = 0) -> dict[tuple[int, int], CompositeScore]:
    """Score ``front`` (a colour :class:`~slamio.camera.detect.FrontEnd`) on every real frame with
    each cylinder pasted in alone, for each depth shift.

    ``frames`` is [(name, bgr, depth_m)]; ``cylinders`` are :class:`~slamio.camera.render.CylinderSpec`
    in the robot frame (the robot stands at the origin). Pixel noise from one seeded generator.
    """
    from slamio.camera.sources import Frame

    rng = np.random.default_rng(seed)
    scores = {shift: CompositeScore() for shift in shifts_px}
    for cyl in cylinders:
        layer = landmark_layer(front.camera, (0.0, 0.0, 0.0), Scene(cylinders=(cyl,)), supersample=supersample)
        truth = {cyl.landmark_id: (math.hypot(cyl.x_m, cyl.y_m), math.atan2(cyl.y_m, cyl.x_m), cyl.height_m)}
        for index, (name, bgr, depth) in enumerate(frames):
            for shift in shifts_px:
                image, shifted = composite(bgr, depth, layer, depth_shift_px=shift, noise_sigma=noise_sigma, rng=rng)
                result = front.process(Frame(0.0, index, name, image, shifted))
                score_frame(result.observations, truth, scores[shift])
    return scores
