"""Frames → run-log observations, with every rejected frame or landmark counted by name.

:class:`FrontEnd` holds the camera model, the detector and the noise model; ``process(frame)``
returns a :class:`FrameResult` with the :class:`slamio.log.Observation` records of the frame
and, for everything that did not become an observation, a :class:`Rejection` with one of the
names in :data:`REASONS`. Nothing a frame contains (a corrupt file, a blown-out exposure, no
landmark, a blob without depth) raises: a run over thousands of frames finishes and
:class:`DetectionStats` says what happened how often.

Observation noise (:class:`NoiseModel`) is σ_r(r) = a + b·r + c·r² and a constant σ for
bearing, height and tag yaw — by default the simulator's numbers for the same sensors
(``fgslam sim``'s arena camera and Kinect), which are consistent with the errors measured on
rendered frames (docs/camera.md). A tag pose with an ambiguous flip gets its yaw σ
multiplied by ``ambiguous_yaw_factor``.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from slamio.camera.apriltag import (
    TagDetection,
    TagGeometry,
    choose_tag_pose,
    estimate_tag_pose,
    opencv_threads,
    refine_tag_corners,
    tag_geometry,
)
from slamio.camera.colour import BLOB_REJECTIONS, Blob, ColourOptions, detect_colour_landmarks
from slamio.camera.model import CameraModel
from slamio.camera.sources import Frame
from slamio.camera.tag_passes import front_end_detector
from slamio.errors import FgslamError
from slamio.log import Observation
from slamio.sim_models import observation_sigmas

KINDS = ("apriltag", "colour")

#: Every reason a frame or a landmark does not become an observation.
REASONS = {
    "corrupt_image": "the image file cannot be read or decoded",
    "corrupt_depth": "the frame's depth image cannot be read or decoded",
    "wrong_image_size": "the image size differs from the camera file's image_width × image_height",
    "over_exposed": "too many saturated pixels (a blown-out frame: nothing in it can be trusted)",
    "under_exposed": "the frame is nearly black",
    "no_landmark": "no tag or colour blob in the frame",
    "no_depth_image": "colour landmarks need a registered depth image and the frame has none",
    "tag_at_image_border": "a tag whose corners are too close to the image border to be trusted",
    **BLOB_REJECTIONS,
    "tag_not_allowed": "a tag id outside the allowed ids",
    "pose_failed": "no pose could be computed for a tag",
    "out_of_range": "a landmark measured outside [min_range_m, max_range_m]",
    "detector_error": "the detector failed on this frame (an OpenCV or library error)",
    # used when observations are merged into a run log (fgslam detect)
    "no_pose_at_frame_time": "the log has no pose within --max-pose-gap before the frame's stamp",
    "before_log_start": "the frame is older than the log's start stamp",
}

#: Things worth counting that do not drop anything.
NOTES = {
    "pose_ambiguous": "a tag pose whose two IPPE solutions fit almost equally well (yaw σ inflated)",
    "corners_not_refined": "a tag whose edges could not be located to sub-pixel accuracy (tiny, oblique or "
    "blurred): the detector's corners were used",
    "extra_blobs": "more than one blob of a colour passed every check; the one whose width fits best was kept",
    "height_cut_off": "a blob touching the image's top border: no height",
    "height_no_depth": "no depth at a blob's top edge: no height",
    "height_top_above_floor": "a blob cut at the image's bottom: height of its top above the floor",
    "height_ambiguous": "a landmark whose top or bottom is continued by something of its colour: no height",
}


class FrontEndError(FgslamError):
    """A front-end configured in a way that cannot work."""


@dataclass(frozen=True)
class Rejection:
    reason: str  # a key of REASONS
    what: str = ""  # the frame, tag or colour it concerns
    detail: str = ""


@dataclass(frozen=True)
class NoiseModel:
    sigma_range_m: float
    sigma_range_per_m: float
    sigma_range_per_m2: float
    sigma_bearing_rad: float
    sigma_height_m: float | None = None
    sigma_tag_yaw_rad: float | None = None
    ambiguous_yaw_factor: float = 3.0

    def sigma_range(self, range_m: float) -> float:
        return self.sigma_range_m + self.sigma_range_per_m * range_m + self.sigma_range_per_m2 * range_m**2

    def describe(self) -> dict:
        out = {
            "model": "sigma_range = a + b*r + c*r^2; constant sigmas for bearing, height, tag yaw",
            **observation_sigmas(self),
        }
        if self.sigma_tag_yaw_rad is not None:
            out["ambiguous_yaw_factor"] = self.ambiguous_yaw_factor
        return out


#: The simulator's arena camera (seed 004) and Kinect (seed 000) noise.
TAG_NOISE = NoiseModel(0.01, 0.0, 0.005, 0.01, None, 0.05)


COLOUR_NOISE = NoiseModel(0.01, 0.0, 1.425e-3, 0.01, 0.02, None)


@dataclass(frozen=True)
class FrontEndConfig:
    kind: str = "apriltag"
    # AprilTags
    tag_family: str = "tag36h11"
    tag_size_m: float = 0.16
    tag_sizes_m: dict[int, float] = field(default_factory=dict)  # per-id sizes override tag_size_m
    tag_ids: frozenset[int] | None = None  # None = every id of the family
    quad_decimate: float = 1.0
    refine_edges: bool = False
    tag_upsample: float = 1.75  # AprilTag 3 sees the image enlarged this many times (slamio/camera/tag_passes.py)
    tag_second_pass: str = "aruco"  # then cv2.aruco adds the tags it missed; "none": no second pass
    nthreads: int = 1
    ambiguity_ratio: float = 2.0
    tags_upright: bool = True
    # colour landmarks
    colour: ColourOptions = field(default_factory=ColourOptions)
    # both
    min_range_m: float = 0.1
    max_range_m: float = 8.0
    saturated_level: int = 250
    over_exposed_fraction: float = 0.5
    under_exposed_mean: float = 8.0
    noise: NoiseModel | None = None  # None: TAG_NOISE or COLOUR_NOISE by kind

    @property
    def noise_model(self) -> NoiseModel:
        if self.noise is not None:
            return self.noise
        return TAG_NOISE if self.kind == "apriltag" else COLOUR_NOISE


@dataclass(eq=False)
class TagResult:
    detection: TagDetection
    geometry: TagGeometry | None = None
    corners_px: np.ndarray | None = None  # the corners the pose was computed from


@dataclass(eq=False)
class FrameResult:
    frame_name: str
    stamp_s: float
    observations: list[Observation] = field(default_factory=list)
    rejections: list[Rejection] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    tags: list[TagResult] = field(default_factory=list)
    blobs: list[Blob] = field(default_factory=list)
    labels: list[tuple[tuple[float, float], str]] = field(default_factory=list)  # text at pixels, for --show


@dataclass
class DetectionStats:
    """Counts over a run: frames, observations, and every rejection and note by name."""

    frames: int = 0
    frames_with_observations: int = 0
    observations: int = 0
    reasons: Counter = field(default_factory=Counter)
    notes: Counter = field(default_factory=Counter)

    def add(self, result: FrameResult) -> None:
        self.frames += 1
        self.observations += len(result.observations)
        self.frames_with_observations += bool(result.observations)
        self.reasons.update(r.reason for r in result.rejections)
        self.notes.update(result.notes)

    def reject(self, reason: str, count: int = 1) -> None:
        self.reasons[reason] += count

    def summary(self) -> str:
        lines = [
            f"{self.frames} frames, {self.frames_with_observations} with observations, "
            f"{self.observations} observations"
        ]
        for reason, count in sorted(self.reasons.items(), key=lambda kv: (-kv[1], kv[0])):
            lines.append(f"  rejected {count:>6} × {reason}: {REASONS.get(reason, '')}")
        for note, count in sorted(self.notes.items(), key=lambda kv: (-kv[1], kv[0])):
            lines.append(f"  note     {count:>6} × {note}: {NOTES.get(note, '')}")
        return "\n".join(lines)


# --------------------------------------------------------------------------- pure checks


def exposure_problem(grey: np.ndarray, saturated_level: int = 250, over_fraction: float = 0.5,
                     under_mean: float = 8.0) -> str | None:
    """'over_exposed', 'under_exposed' or None for a grey frame."""
    if float(np.mean(grey >= saturated_level)) > over_fraction:
        return "over_exposed"
    if float(np.mean(grey)) < under_mean:
        return "under_exposed"
    return None


def corners_near_border(corners_px: np.ndarray, width_px: int, height_px: int, margin_px: float) -> bool:
    c = np.asarray(corners_px)
    return bool(np.any(c[:, 0] < margin_px - 0.5) or np.any(c[:, 0] > width_px - 0.5 - margin_px)
                or np.any(c[:, 1] < margin_px - 0.5) or np.any(c[:, 1] > height_px - 0.5 - margin_px))


def tag_corners_for_pose(grey: np.ndarray, det: TagDetection, camera: CameraModel) -> tuple[np.ndarray | None, str]:
    """The corners a detected tag's pose is solved from, and a reason or note: ``(None,
    "tag_at_image_border")`` for a tag within a cell and a pixel of the border; else its corners
    refined on ``grey`` when its cells are at least 1.5 px (``refine_tag_corners``), the
    detector's own with the note ``"corners_not_refined"`` when that fails, and ``""`` as note
    otherwise. ``fgslam detect`` and ``fgslam import rosbag --image-topic`` both use it."""
    cell_px = det.side_px / 8.0
    if corners_near_border(det.corners_px, camera.width_px, camera.height_px, cell_px + 1.0):
        return None, "tag_at_image_border"
    if cell_px < 1.5:  # smaller tags keep the detector's corners
        return det.corners_px, ""
    refined = refine_tag_corners(grey, det.corners_px, camera)
    return (det.corners_px, "corners_not_refined") if refined is None else (refined, "")


# --------------------------------------------------------------------------- the front-end


class FrontEnd:
    """Turns frames into observations for one camera and one kind of landmark."""

    def __init__(self, camera: CameraModel, config: FrontEndConfig = FrontEndConfig()):
        if config.kind not in KINDS:
            raise FrontEndError(f"unknown landmark kind {config.kind!r}; use one of {', '.join(KINDS)}")
        if config.tag_size_m <= 0 or any(s <= 0 for s in config.tag_sizes_m.values()):
            raise FrontEndError("tag sizes must be > 0 (metres, the black square's side)")
        self.camera = camera
        self.config = config
        self.noise = config.noise_model
        self.detector = None
        if config.kind == "apriltag":
            from slamio.camera.apriltag import TagDetectorError

            try:
                self.detector = front_end_detector(
                    config.tag_family, upsample=config.tag_upsample, second_pass=config.tag_second_pass,
                    quad_decimate=config.quad_decimate, refine_edges=config.refine_edges, nthreads=config.nthreads,
                )
            except TagDetectorError as exc:
                raise FrontEndError(str(exc)) from None

    def process(self, frame: Frame) -> FrameResult:
        """Observations of one frame; every problem becomes a named rejection, never an exception."""
        import cv2

        result = FrameResult(frame.name, frame.stamp_s)
        if frame.bgr is None:
            result.rejections.append(Rejection("corrupt_image", frame.name, frame.error or ""))
            return result
        h, w = frame.bgr.shape[:2]
        mismatch = self.camera.size_mismatch(w, h)
        if mismatch is not None:
            result.rejections.append(Rejection("wrong_image_size", frame.name, mismatch))
            return result
        grey = cv2.cvtColor(frame.bgr, cv2.COLOR_BGR2GRAY)
        problem = exposure_problem(grey, self.config.saturated_level, self.config.over_exposed_fraction,
                                   self.config.under_exposed_mean)
        if problem:
            result.rejections.append(Rejection(problem, frame.name))
            return result
        try:
            if self.config.kind == "apriltag":
                with opencv_threads(self.config.nthreads):  # refinement and pose too
                    self._tags(grey, result)
            else:
                self._colour(frame, result)
        except (cv2.error, ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeError) as exc:
            result.observations.clear()
            result.rejections.append(Rejection("detector_error", frame.name, f"{type(exc).__name__}: {exc}"))
        if not result.observations and not result.rejections and not result.tags and not result.blobs:
            result.rejections.append(Rejection("no_landmark", frame.name))
        return result

    # ---------------------------------------------------------------- AprilTags

    def _tags(self, grey: np.ndarray, result: FrameResult) -> None:
        cfg, cam = self.config, self.camera
        for det in self.detector.detect(grey):
            what = f"tag {det.tag_id}"
            tag = TagResult(det)
            result.tags.append(tag)
            if cfg.tag_ids is not None and det.tag_id not in cfg.tag_ids:
                result.rejections.append(Rejection("tag_not_allowed", what))
                continue
            corners, note = tag_corners_for_pose(grey, det, cam)
            if corners is None:
                result.rejections.append(Rejection(note, what))
                continue
            if note:
                result.notes.append(note)
            tag.corners_px = corners
            size = cfg.tag_sizes_m.get(det.tag_id, cfg.tag_size_m)
            poses = estimate_tag_pose(corners, size, cam)
            if not poses:
                result.rejections.append(Rejection("pose_failed", what))
                continue
            pose, ambiguous = choose_tag_pose(poses, cam.T_robot_camera, ambiguity_ratio=cfg.ambiguity_ratio,
                                              upright=cfg.tags_upright)
            geometry = tag_geometry(pose, cam.T_robot_camera)
            tag.geometry = geometry
            if not (cfg.min_range_m <= geometry.range_m <= cfg.max_range_m):
                result.rejections.append(Rejection("out_of_range", what, f"{geometry.range_m:.2f} m"))
                continue
            if ambiguous:
                result.notes.append("pose_ambiguous")
            n = self.noise
            sigma_yaw = n.sigma_tag_yaw_rad if n.sigma_tag_yaw_rad is not None else TAG_NOISE.sigma_tag_yaw_rad
            if ambiguous:
                sigma_yaw *= n.ambiguous_yaw_factor
            result.observations.append(Observation(
                stamp_s=result.stamp_s, landmark_id=det.tag_id, range_m=geometry.range_m,
                bearing_rad=geometry.bearing_rad, sigma_range_m=n.sigma_range(geometry.range_m),
                sigma_bearing_rad=n.sigma_bearing_rad, tag_yaw_rad=geometry.tag_yaw_rad,
                sigma_tag_yaw_rad=min(sigma_yaw, math.pi),
            ))
            result.labels.append(((float(det.centre_px[0]), float(det.centre_px[1])),
                                  f"id {det.tag_id} {geometry.range_m:.2f} m {math.degrees(geometry.bearing_rad):+.1f} deg"))

    # ---------------------------------------------------------------- colour landmarks

    def _colour(self, frame: Frame, result: FrameResult) -> None:
        cfg, cam = self.config, self.camera
        if frame.depth_m is None:
            reason = "corrupt_depth" if frame.depth_error else "no_depth_image"
            result.rejections.append(Rejection(reason, frame.name, frame.depth_error or ""))
            return
        mismatch = cam.size_mismatch(frame.depth_m.shape[1], frame.depth_m.shape[0])
        if mismatch is not None:
            result.rejections.append(Rejection("wrong_image_size", frame.name, f"depth: {mismatch}"))
            return
        measured, rejected, blobs = detect_colour_landmarks(frame.bgr, frame.depth_m, cam, cfg.colour)
        result.blobs.extend(blobs)
        for r in rejected:
            result.rejections.append(Rejection(r.reason, r.colour, r.detail))
            if r.blob is not None:
                result.labels.append(((r.blob.left, r.blob.bottom + 14), f"{r.colour}: {r.reason}"))
        n = self.noise
        for m in measured:
            if m.extra_blobs:
                result.notes.append("extra_blobs")
            if m.height_note in ("height_cut_off", "height_no_depth", "height_ambiguous"):
                result.notes.append(m.height_note)
            elif m.height_note == "top-above-floor":
                result.notes.append("height_top_above_floor")
            if not (cfg.min_range_m <= m.range_m <= cfg.max_range_m):
                result.rejections.append(Rejection("out_of_range", m.colour, f"{m.range_m:.2f} m"))
                continue
            has_height = m.height_m is not None and n.sigma_height_m is not None
            result.observations.append(Observation(
                stamp_s=result.stamp_s, landmark_id=m.landmark_id, range_m=m.range_m, bearing_rad=m.bearing_rad,
                sigma_range_m=n.sigma_range(m.range_m), sigma_bearing_rad=n.sigma_bearing_rad,
                height_m=m.height_m if has_height else None,
                sigma_height_m=n.sigma_height_m if has_height else None,
            ))
            height = f" h {m.height_m:.2f} m" if m.height_m is not None else ""
            result.labels.append(((m.blob.left, max(m.blob.top - 6, 10)),
                                  f"{m.colour} {m.range_m:.2f} m {math.degrees(m.bearing_rad):+.1f} deg{height}"))


# --------------------------------------------------------------------------- drawing


def _label(image: np.ndarray, text: str, org: tuple[int, int], colour: tuple[int, int, int]) -> None:
    """Text on a dark box (an outline drawn with a thicker stroke does not line up in OpenCV 5)."""
    import cv2

    font, scale = cv2.FONT_HERSHEY_SIMPLEX, 0.45
    (w, h), base = cv2.getTextSize(text, font, scale, 1)
    x, y = org
    cv2.rectangle(image, (x - 2, y - h - 3), (x + w + 2, y + base + 1), (0, 0, 0), -1)
    cv2.putText(image, text, (x, y), font, scale, colour, 1, cv2.LINE_AA)


def _rejection_lines(rejections: list[Rejection], max_lines: int = 8) -> list[str]:
    """One line per rejection (with its detail), or per reason and colour/tag with a count when
    there are many (a cluttered frame rejects dozens of blobs; their reasons are drawn at them)."""
    if len(rejections) <= max_lines:
        return [f"{r.reason} {r.what} {r.detail}".strip() for r in rejections]
    counts = Counter((r.reason, r.what) for r in rejections)
    return [f"{reason} {what} x{n}".strip() for (reason, what), n in counts.most_common()]


def annotate(bgr: np.ndarray | None, result: FrameResult, camera: CameraModel | None = None) -> np.ndarray:
    """A copy of the frame with detections, measurements and rejection reasons drawn."""
    import cv2

    if bgr is None:
        w, h = (camera.width_px, camera.height_px) if camera else (640, 480)
        image = np.full((h, w, 3), 60, dtype=np.uint8)
    else:
        image = bgr.copy()
    for tag in result.tags:
        corners = tag.corners_px if tag.corners_px is not None else tag.detection.corners_px
        colour = (0, 220, 0) if tag.geometry is not None else (0, 0, 230)
        cv2.polylines(image, [np.round(corners).astype(np.int32).reshape(-1, 1, 2)], True, colour, 1, cv2.LINE_AA)
        tl = corners[0]
        cv2.circle(image, (int(round(tl[0])), int(round(tl[1]))), 3, (255, 0, 255), -1)
        if tag.geometry is None:
            c = tag.detection.centre_px
            _label(image, f"id {tag.detection.tag_id}", (int(c[0]), int(c[1])), (80, 80, 255))
    for blob in result.blobs:
        cv2.rectangle(image, (blob.left, blob.top), (blob.right, blob.bottom), (255, 255, 255), 1)
    for (x, y), text in result.labels:
        _label(image, text, (int(x), int(y)), (255, 255, 255))
    y = 16
    header = f"{result.frame_name}  t={result.stamp_s:.3f} s  {len(result.observations)} obs"
    for text in [header] + _rejection_lines(result.rejections):
        _label(image, text[:90], (5, y), (0, 255, 255))
        y += 18
    return image
