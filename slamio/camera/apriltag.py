"""AprilTag detection and tag pose → range, bearing and tag yaw in the robot frame.

Detector
========

The default back-end is the AprilTag 3 library through ``pupil-apriltags`` with
``quad_decimate=1.0`` and ``refine_edges`` off, chosen by measurement on the real photos in
``tests/data/apriltag-photos`` (``scripts/bench_apriltag.py``, docs/camera.md).
``backend="aruco"`` runs OpenCV's detector with the family's AprilTag dictionary instead.

``upsample`` (1.0 by default) enlarges the image (bilinear) before the detector sees it and
maps the corners back (:func:`corners_from_upsampled`): enlarged, AprilTag 3 finds tags of
11–17 pixels and steeply foreshortened ones that it misses at the camera's resolution. The
front-end combines an enlarged AprilTag 3 pass with a cheap aruco pass
(:mod:`slamio.camera.tag_passes`).

Corners
=======

:class:`TagDetection.corners_px` are always in **OpenCV's order and pixel convention**: the
upright tag's top-left, top-right, bottom-right, bottom-left corner (the order
``SOLVEPNP_IPPE_SQUARE`` wants), with the centre of the top-left pixel at (0, 0). The AprilTag
library reports them counter-clockwise starting at the upright tag's top-right corner, with
the top-left pixel's *corner* at (0, 0): :func:`apriltag_to_opencv_corners` converts
(measured on rendered tags: an edge between pixels 119 and 120 is reported at 120.0).

Pose
====

``cv2.solvePnPGeneric(..., SOLVEPNP_IPPE_SQUARE)`` returns both IPPE solutions of the
planar pose; a small or far tag has two poses with nearly the same reprojection error
(the "flip"). :func:`estimate_tag_pose` keeps both; :func:`choose_tag_pose` takes the one
with the smaller error unless the two are ambiguous (error ratio below ``ambiguity_ratio``),
in which case, for tags mounted upright (every landmark tag of this project hangs on a
wall), it takes the solution whose face normal is closer to horizontal in the robot frame.

Tag frame (OpenCV's IPPE square): x to the right and y up on the upright tag, z out of the
printed face towards a viewer. **Tag yaw** is the direction of +z projected on the floor,
counter-clockwise from the robot's x axis: a tag seen head-on has tag yaw π.
"""

from __future__ import annotations

import math
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from slamio.camera.aruco_codes import ArucoCandidates, family_codes, identify_quads
from slamio.camera.model import CameraModel, floor_range_bearing, transform_points
from slamio.errors import FgslamError

#: AprilTag family name → OpenCV aruco dictionary name (for the aruco back-end and the renderer).
ARUCO_DICTIONARIES = {
    "tag36h11": "DICT_APRILTAG_36h11",
    "tag36h10": "DICT_APRILTAG_36h10",
    "tag25h9": "DICT_APRILTAG_25h9",
    "tag16h5": "DICT_APRILTAG_16h5",
}

BACKENDS = ("apriltag3", "aruco")


class TagDetectorError(FgslamError):
    """The AprilTag detector cannot be built (unknown family, missing library)."""


@dataclass(frozen=True, eq=False)
class TagDetection:
    """One decoded tag in an image (corners in OpenCV order and pixel convention)."""

    tag_id: int
    family: str
    corners_px: np.ndarray  # (4, 2): top-left, top-right, bottom-right, bottom-left
    hamming: int = 0
    decision_margin: float = float("nan")

    @cached_property
    def centre_px(self) -> np.ndarray:
        return self.corners_px.mean(axis=0)

    @cached_property
    def side_px(self) -> float:
        """Mean side length in pixels."""
        c = self.corners_px
        return float(np.mean(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)))


@dataclass(frozen=True, eq=False)
class TagPose:
    """A tag pose in the camera frame: ``p_camera = R_camera_tag @ p_tag + t_camera_tag_m``."""

    R_camera_tag: np.ndarray
    t_camera_tag_m: np.ndarray
    reprojection_error_px: float


@dataclass(frozen=True)
class TagGeometry:
    """A tag seen from the robot: what goes into an observation record."""

    range_m: float
    bearing_rad: float
    tag_yaw_rad: float
    height_m: float  # tag centre above the floor (the mount's z is the camera height)
    normal_tilt_rad: float  # angle between the face normal and the floor plane


# --------------------------------------------------------------------------- pure maths


def apriltag_to_opencv_corners(corners_px: np.ndarray) -> np.ndarray:
    """AprilTag library corners (CCW from the upright tag's top-right, pixel-corner origin)
    → OpenCV order (TL, TR, BR, BL) and convention (pixel-centre origin)."""
    c = np.asarray(corners_px, dtype=float).reshape(4, 2)
    return c[[1, 0, 3, 2]] - 0.5


def corners_from_upsampled(corners_px: np.ndarray, factor: float) -> np.ndarray:
    """Corners found in an image enlarged ``factor`` times by ``cv2.resize`` → the original image's pixels.

    ``cv2.resize`` puts the centre of enlarged pixel x at original x' = (x + ½)/factor − ½ (both
    in OpenCV's pixel-centre convention).
    """
    return (np.asarray(corners_px, dtype=float) + 0.5) / factor - 0.5


def fit_lines(point_sets: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Total-least-squares lines through sets of (N, 2) points: (K, 2) points on them (the
    centroids) and (K, 2) unit directions (the scatter's major axis, in closed form)."""
    centres = np.array([pts.mean(axis=0) for pts in point_sets])
    scatter = np.array([(d := pts - c).T @ d for pts, c in zip(point_sets, centres)])  # (K, 2, 2)
    angle = 0.5 * np.arctan2(2.0 * scatter[:, 0, 1], scatter[:, 0, 0] - scatter[:, 1, 1])
    return centres, np.column_stack([np.cos(angle), np.sin(angle)])


def cross_2d(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """z of the cross product of 2-D vectors (row by row)."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def neighbour_intersections(centres: np.ndarray, directions: np.ndarray) -> np.ndarray | None:
    """Where line k−1 meets line k, for each k of a closed chain of lines (point, direction);
    None when two neighbours are parallel."""
    before = np.arange(len(centres)) - 1  # line k−1 (the last line before the first)
    previous, previous_dir = centres[before], directions[before]
    det = cross_2d(previous_dir, directions)
    if np.any(np.abs(det) < 1e-9):
        return None
    s = cross_2d(centres - previous, directions) / det
    return previous + s[:, None] * previous_dir


def edge_crossings(grey: np.ndarray, starts: np.ndarray, ends: np.ndarray, outwards: np.ndarray,
                   halves_px: np.ndarray, *, min_contrast: float = 15.0) -> list[np.ndarray]:
    """Sub-pixel points of dark-inside/bright-outside edges between rough corners, one (N, 2) array per edge.

    Edge k runs from ``starts[k]`` to ``ends[k]`` with unit normal ``outwards[k]``. Samples
    intensity profiles (bicubic, 0.25 px steps, ± ``halves_px[k]``) across the edge at points
    spread over its middle 70 %, and returns where each crosses the mid level between its dark
    (inner) and bright (outer) halves — the upward crossing nearest the rough edge, so a
    white data cell inside the border or clutter beyond the margin does not capture it.
    Profiles with too little contrast are skipped. All edges' profiles are sampled by one
    ``cv2.remap`` and evaluated together (rows of different lengths padded): a tag-dense frame
    refines hundreds of edges.
    """
    import cv2

    starts, ends, outwards = (np.asarray(a, dtype=float).reshape(-1, 2) for a in (starts, ends, outwards))
    lengths = np.linalg.norm(ends - starts, axis=1)
    counts = np.array([min(max(round(0.7 * float(length)), 4), 60) for length in lengths])
    offsets = [np.arange(-h, h + 1e-9, 0.25) for h in np.asarray(halves_px, dtype=float)]
    width = max(len(o) for o in offsets)
    edge = np.repeat(np.arange(len(starts)), counts)  # the edge of each profile
    first = np.cumsum(counts) - counts  # each edge's first profile
    fraction = (np.arange(len(edge)) - first[edge]) * ((0.85 - 0.15) / (counts - 1))[edge] + 0.15  # np.linspace's arithmetic
    fraction[first + counts - 1] = 0.85
    along = starts[edge] + fraction[:, None] * (ends - starts)[edge]
    offset = np.zeros((len(offsets), width))  # padded: never a crossing there (see ``up``)
    for k, o in enumerate(offsets):
        offset[k, : len(o)] = o
    offset = offset[edge]  # (profiles, width)
    map_x, map_y = (along[:, axis, None] + offset * outwards[edge, axis, None] for axis in (0, 1))
    values = cv2.remap(grey, map_x.astype(np.float32), map_y.astype(np.float32), cv2.INTER_CUBIC,
                       borderMode=cv2.BORDER_REPLICATE).astype(float)
    column = np.arange(width)[None, :]
    middle = np.array([len(o) // 2 for o in offsets])[edge][:, None]  # offset 0: the rough edge
    size = np.array([len(o) for o in offsets])[edge][:, None]
    dark = np.where(column <= middle, values, np.inf).min(axis=1)
    bright = np.where((column >= middle) & (column < size), values, -np.inf).max(axis=1)
    level = 0.5 * (dark + bright)[:, None]
    v0, v1 = values[:, :-1], values[:, 1:]
    up = (v0 < level) & (v1 >= level) & (column[:, 1:] < size)  # dark → bright going outward
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing = offset[:, :-1] + (level - v0) / (v1 - v0) * (offset[:, 1:] - offset[:, :-1])
    crossing = np.where(up, crossing, np.inf)
    nearest = np.argmin(np.abs(crossing), axis=1)  # the crossing nearest the rough edge
    found = crossing[np.arange(len(crossing)), nearest]
    keep = np.isfinite(found) & (bright - dark >= min_contrast)
    out = along + np.where(keep, found, 0.0)[:, None] * outwards[edge]
    return [out[a:b][keep[a:b]] for a, b in zip(first, first + counts)]


def refine_tag_corners(grey: np.ndarray, corners_px: np.ndarray, camera: CameraModel | None = None,
                       *, max_shift_px: float = 1.5) -> np.ndarray | None:
    """Sub-pixel tag corners from the four black-border edges, or None when they cannot be refined.

    The detector's corners (``refine_edges`` off: the setting that finds the most tags on
    real photos) sit on the binarised boundary, up to half a pixel off each edge — up to
    5 % of the range of a 20-pixel tag. This fits a line to sub-pixel crossings of each
    edge (:func:`edge_crossings`, profiles reaching one cell — the smallest nearby, for
    perspective — into the black border and the white margin) and intersects neighbouring
    lines. Returns None for tags under 12 px, too few edge points, or corners that would move
    more than ``max_shift_px`` (the detector's corners are then the better guess). With a distorted ``camera`` the lines
    are fitted in undistorted coordinates (straight edges stay straight there).
    """
    c = np.asarray(corners_px, dtype=float).reshape(4, 2)
    grey = np.ascontiguousarray(grey, dtype=np.uint8)
    ends = c[[1, 2, 3, 0]]  # side i: corner i → i+1
    sides = np.linalg.norm(ends - c, axis=1)
    if np.min(sides) / 8.0 < 1.5:
        return None
    tangents = (ends - c) / sides[:, None]
    normals = np.column_stack([tangents[:, 1], -tangents[:, 0]])
    inward = np.sum((0.5 * (c + ends) - c.mean(axis=0)) * normals, axis=1) < 0
    normals[inward] *= -1.0
    cells = np.minimum(np.minimum(sides[[3, 0, 1, 2]], sides), sides[[1, 2, 3, 0]]) / 8.0  # perspective: the smallest nearby
    point_sets = edge_crossings(grey, c, ends, normals, np.maximum(1.5, cells))
    if min(len(pts) for pts in point_sets) < 3:
        return None
    distorted = camera is not None and (camera.has_distortion or camera.distortion_model == "equidistant")
    if distorted:
        point_sets = np.split(camera.normalized(np.concatenate(point_sets)), np.cumsum([len(p) for p in point_sets])[:-1])
    refined = neighbour_intersections(*fit_lines(point_sets))
    if refined is None:
        return None
    if distorted:
        refined = camera.project(np.column_stack([refined, np.ones(4)]))
    if not np.all(np.isfinite(refined)) or np.max(np.linalg.norm(refined - c, axis=1)) > max_shift_px:
        return None
    return refined


def tag_object_points(tag_size_m: float) -> np.ndarray:
    """The IPPE-square object points: TL, TR, BR, BL in the tag frame (x right, y up)."""
    h = 0.5 * tag_size_m
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def rodrigues(rvec: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(np.asarray(rvec, dtype=float).reshape(3, 1))[0]


def _reprojection_rms(object_points: np.ndarray, xy: np.ndarray, R: np.ndarray, t: np.ndarray) -> float:
    """RMS distance between normalized image points and the projected object points."""
    p = object_points @ R.T + t
    if np.any(p[:, 2] <= 0):
        return float("inf")
    return float(np.sqrt(np.mean(np.sum((p[:, :2] / p[:, 2:3] - xy) ** 2, axis=1))))


def estimate_tag_pose(corners_px: np.ndarray, tag_size_m: float, camera: CameraModel,
                      *, fallback_error_px: float = 1.0) -> list[TagPose]:
    """Both IPPE solutions of a square tag's pose, best (smallest reprojection error) first.

    The corners are undistorted to normalized coordinates first, so any supported lens model
    works; errors are recomputed here and reported in pixels (normalized RMS error × mean
    focal length). When even the best IPPE solution reprojects worse than
    ``fallback_error_px`` — OpenCV 5.0's IPPE returns a wrong rotation for an exactly
    fronto-parallel square — an SQPnP solution refined by Levenberg–Marquardt joins the
    candidates. Returns an empty list when nothing is found.
    """
    import cv2

    xy = camera.normalized(np.asarray(corners_px, dtype=float).reshape(4, 2))
    object_points = tag_object_points(tag_size_m)
    image_points = xy.reshape(4, 1, 2)
    focal = 0.5 * (camera.fx + camera.fy)
    candidates: list[tuple[np.ndarray, np.ndarray]] = []
    try:
        count, rvecs, tvecs, _ = cv2.solvePnPGeneric(
            object_points, image_points, np.eye(3), None, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        candidates += [(np.asarray(rvecs[i], float).ravel(), np.asarray(tvecs[i], float).ravel()) for i in range(int(count))]
    except cv2.error:
        pass

    def pose(rvec, tvec) -> TagPose:
        R = rodrigues(rvec)
        return TagPose(R, tvec, _reprojection_rms(object_points, xy, R, tvec) * focal)

    poses = [pose(r, t) for r, t in candidates]
    if not poses or min(p.reprojection_error_px for p in poses) > fallback_error_px:
        try:
            ok, rvec, tvec = cv2.solvePnP(object_points, image_points, np.eye(3), None, flags=cv2.SOLVEPNP_SQPNP)
            if ok:
                rvec, tvec = cv2.solvePnPRefineLM(object_points, image_points, np.eye(3), None, rvec, tvec)
                poses.append(pose(rvec.ravel(), tvec.ravel()))
        except cv2.error:
            pass
    poses = [p for p in poses if math.isfinite(p.reprojection_error_px)]
    poses.sort(key=lambda p: p.reprojection_error_px)
    return poses


def tag_geometry(pose: TagPose, T_robot_camera: np.ndarray) -> TagGeometry:
    """Range, bearing, tag yaw, centre height and normal tilt of a tag pose, robot frame."""
    p_robot = transform_points(T_robot_camera, pose.t_camera_tag_m)
    normal_robot = T_robot_camera[:3, :3] @ pose.R_camera_tag[:, 2]
    range_m, bearing_rad = floor_range_bearing(p_robot)
    yaw = math.atan2(normal_robot[1], normal_robot[0])
    tilt = math.asin(max(-1.0, min(1.0, float(normal_robot[2]))))
    return TagGeometry(range_m, bearing_rad, yaw, float(p_robot[2]), tilt)


def choose_tag_pose(
    poses: list[TagPose], T_robot_camera: np.ndarray, *, ambiguity_ratio: float = 2.0, upright: bool = True
) -> tuple[TagPose, bool]:
    """Pick one IPPE solution; returns (pose, ambiguous).

    ``ambiguous`` is true when the second solution's reprojection error is within
    ``ambiguity_ratio`` of the best one's. Then, if ``upright``, the solution whose face
    normal is closer to the floor plane wins (a flip tilts the normal up or down).
    """
    if not poses:
        raise ValueError("no pose to choose from")
    best = poses[0]
    if len(poses) < 2:
        return best, False
    second = poses[1]
    ambiguous = second.reprojection_error_px <= ambiguity_ratio * max(best.reprojection_error_px, 1e-9)
    if ambiguous and upright:
        tilts = [abs(tag_geometry(p, T_robot_camera).normal_tilt_rad) for p in (best, second)]
        if tilts[1] < tilts[0]:
            best = second
    return best, ambiguous


# --------------------------------------------------------------------------- detector


@contextmanager
def opencv_threads(count: int):
    """OpenCV's calls inside run on ``count`` threads (its process-wide setting, restored after).

    OpenCV otherwise spreads resizing, thresholding and contour work over every core, and on a
    shared machine its idle workers' spinning shows up as CPU time of this process (the aruco
    pass took about 1.5× less CPU on the NASA crops with one thread; docs/camera.md).
    """
    import cv2

    before = cv2.getNumThreads()
    cv2.setNumThreads(int(count))
    try:
        yield
    finally:
        cv2.setNumThreads(before)


def _quad_threshold_struct():
    """ctypes mirror of the head of AprilTag 3's C ``apriltag_detector`` up to its quad-threshold
    parameters (``struct apriltag_quad_thresh_params qtp``), which pupil-apriltags does not expose."""
    import ctypes

    class QuadThresholds(ctypes.Structure):
        _fields_ = [("min_cluster_pixels", ctypes.c_int), ("max_nmaxima", ctypes.c_int),
                    ("critical_rad", ctypes.c_float), ("cos_critical_rad", ctypes.c_float),
                    ("max_line_fit_mse", ctypes.c_float), ("min_white_black_diff", ctypes.c_int),
                    ("deglitch", ctypes.c_int)]

    class DetectorHead(ctypes.Structure):
        _fields_ = [("nthreads", ctypes.c_int), ("quad_decimate", ctypes.c_float), ("quad_sigma", ctypes.c_float),
                    ("refine_edges", ctypes.c_int), ("decode_sharpening", ctypes.c_double), ("debug", ctypes.c_int),
                    ("qtp", QuadThresholds)]

    return DetectorHead


#: AprilTag 3's own defaults (apriltag.c), read back before anything is written.
QUAD_THRESHOLD_DEFAULTS = {"min_cluster_pixels": 5, "max_nmaxima": 10, "max_line_fit_mse": 10.0,
                           "min_white_black_diff": 5}


def set_quad_thresholds(pupil_detector, min_white_black_diff: int, min_cluster_pixels: int) -> None:
    """Set AprilTag 3's ``min_white_black_diff`` (grey levels between the darkest and brightest
    pixel of a 4×4 tile for it to be thresholded at all) and ``min_cluster_pixels`` (edge pixels
    of a quad candidate). The library's defaults are checked first, so a binding whose struct
    layout differs raises :class:`TagDetectorError` instead of writing into the wrong field."""
    import ctypes

    head = ctypes.cast(pupil_detector.tag_detector_ptr, ctypes.POINTER(_quad_threshold_struct())).contents
    found = {key: getattr(head.qtp, key) for key in QUAD_THRESHOLD_DEFAULTS}
    if found != QUAD_THRESHOLD_DEFAULTS:
        raise TagDetectorError(f"unexpected AprilTag detector layout ({found}); cannot set its quad thresholds")
    head.qtp.min_white_black_diff = int(min_white_black_diff)
    head.qtp.min_cluster_pixels = int(min_cluster_pixels)


def _pupil_detector_class():
    """pupil_apriltags.Detector whose destructor frees the detector before its tag families.

    pupil-apriltags 1.0.4 frees the families first, and the library's detector destructor
    then touches them (use after free): the heap is corrupted and a later allocation aborts
    ("malloc(): mismatching next->prev_size") as soon as a second detector is dropped
    (pupil-labs/apriltags#46, fix proposed in #65). This order is the library's own example's.
    """
    import pupil_apriltags

    class _Detector(pupil_apriltags.Detector):
        def __del__(self):
            ptr = getattr(self, "tag_detector_ptr", None)
            if ptr is None:
                return
            self.libc.apriltag_detector_destroy.restype = None
            self.libc.apriltag_detector_destroy(ptr)
            self.tag_detector_ptr = None
            for family, tf in self.tag_families.items():
                destroy = getattr(self.libc, f"{family}_destroy", None)
                if destroy is not None:
                    destroy.restype = None
                    destroy(tf)
            self.tag_families = {}

    return _Detector


class AprilTagDetector:
    """Finds tags of one family in grey images.

    ``backend="apriltag3"`` (default) uses pupil-apriltags with ``quad_decimate``,
    ``refine_edges``, ``decode_sharpening``, ``quad_sigma`` and ``nthreads`` passed through;
    ``max_hamming`` drops decodes with more corrected bits. ``backend="aruco"`` uses
    ``cv2.aruco`` with the AprilTag dictionary of the family and its AprilTag corner
    refinement (``aruco_refinement``), OpenCV's three adaptive-threshold windows or the one
    given by ``aruco_window_px``, and candidates whose perimeter is at least
    ``aruco_min_perimeter`` × the image's larger side. ``upsample`` > 1 enlarges the image
    that many times (bilinear) before detection; corners are always in the given image's pixels.
    ``min_white_black_diff`` and ``min_cluster_pixels`` are AprilTag 3's quad-threshold
    parameters (:func:`set_quad_thresholds`; the library's defaults 5 and 5).
    """

    def __init__(
        self,
        family: str = "tag36h11",
        *,
        backend: str = "apriltag3",
        quad_decimate: float = 1.0,
        refine_edges: bool = False,
        decode_sharpening: float = 0.25,
        quad_sigma: float = 0.0,
        nthreads: int = 1,
        max_hamming: int = 2,
        aruco_refinement: str = "apriltag",
        aruco_window_px: int | None = None,
        aruco_min_perimeter: float = 0.03,
        upsample: float = 1.0,
        min_white_black_diff: int = 5,
        min_cluster_pixels: int = 5,
    ):
        if backend not in BACKENDS:
            raise TagDetectorError(f"unknown AprilTag backend {backend!r}; use one of {', '.join(BACKENDS)}")
        if not (1.0 <= upsample <= 4.0):
            raise TagDetectorError(f"AprilTag upsample must be between 1 and 4, not {upsample}")
        # the C detector divides by both: 0 threads or a decimation below 1 kill the process (SIGFPE)
        if isinstance(nthreads, bool) or not isinstance(nthreads, int) or nthreads < 1:
            raise TagDetectorError(f"AprilTag nthreads must be a whole number >= 1, not {nthreads!r}")
        if not (isinstance(quad_decimate, (int, float)) and quad_decimate >= 1.0 and math.isfinite(quad_decimate)):
            raise TagDetectorError(f"AprilTag quad_decimate must be a finite number >= 1, not {quad_decimate!r}")
        self.upsample = float(upsample)
        self.family = family
        self.backend = backend
        self.max_hamming = max_hamming
        self.settings = dict(quad_decimate=quad_decimate, refine_edges=refine_edges,
                             decode_sharpening=decode_sharpening, quad_sigma=quad_sigma, nthreads=nthreads)
        if backend == "apriltag3":
            self._build_apriltag3(family, nthreads, quad_decimate, quad_sigma, refine_edges, decode_sharpening,
                                  min_white_black_diff, min_cluster_pixels)
        else:
            self._build_aruco(family, aruco_refinement, aruco_window_px, aruco_min_perimeter)

    def _build_apriltag3(self, family, nthreads, quad_decimate, quad_sigma, refine_edges, decode_sharpening,
                         min_white_black_diff, min_cluster_pixels) -> None:
        """The pupil-apriltags detector, with the quad thresholds asked for where the binding allows."""
        try:
            detector_class = _pupil_detector_class()
        except ImportError:
            raise TagDetectorError(
                "AprilTag detection needs the 'pupil-apriltags' package: pip install pupil-apriltags"
            ) from None
        try:
            self._detector = detector_class(
                families=family, nthreads=nthreads, quad_decimate=quad_decimate, quad_sigma=quad_sigma,
                refine_edges=int(bool(refine_edges)), decode_sharpening=decode_sharpening,
            )
        except Exception as exc:  # the binding raises a bare RuntimeError for an unknown family
            raise TagDetectorError(f"cannot build an AprilTag detector for family {family!r}: {exc}") from None
        #: whether the quad thresholds asked for are in force (they only save time: with a
        #: binding laid out otherwise the library's defaults stay, with a warning)
        self.quad_thresholds_set = (min_white_black_diff, min_cluster_pixels) == (5, 5)
        if not self.quad_thresholds_set:
            try:
                set_quad_thresholds(self._detector, min_white_black_diff, min_cluster_pixels)
                self.quad_thresholds_set = True
            except TagDetectorError as exc:
                warnings.warn(f"{exc}: AprilTag keeps its default quad thresholds (same tags, slower on "
                              "textured scenes)", RuntimeWarning, stacklevel=3)

    def _build_aruco(self, family, aruco_refinement, aruco_window_px, aruco_min_perimeter) -> None:
        """OpenCV's ArUco detector for ``family``, and the one-array candidate reader where it applies."""
        import cv2

        if family not in ARUCO_DICTIONARIES:
            raise TagDetectorError(
                f"the aruco backend knows families {', '.join(ARUCO_DICTIONARIES)}, not {family!r}"
            )
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARIES[family]))
        params = cv2.aruco.DetectorParameters()
        methods = {"none": cv2.aruco.CORNER_REFINE_NONE, "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
                   "contour": cv2.aruco.CORNER_REFINE_CONTOUR, "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG}
        if aruco_refinement not in methods:
            raise TagDetectorError(f"aruco_refinement must be one of {', '.join(methods)}")
        params.cornerRefinementMethod = methods[aruco_refinement]
        if aruco_window_px is not None:  # one adaptive-threshold window instead of OpenCV's 3, 13, 23 px
            params.adaptiveThreshWinSizeMin = params.adaptiveThreshWinSizeMax = int(aruco_window_px)
        params.minMarkerPerimeterRate = float(aruco_min_perimeter)
        self._detector = cv2.aruco.ArucoDetector(dictionary, params)
        self._candidates = None
        if aruco_refinement == "none" and aruco_window_px is not None:
            # one window and unrefined corners: identify OpenCV's candidates in one array operation
            # (aruco_codes; with several windows OpenCV tries each tag's candidates in turn)
            self._codes = family_codes(ARUCO_DICTIONARIES[family])
            self._candidates = ArucoCandidates(params, self._codes.marker_cells)

    def detect(self, grey: np.ndarray) -> list[TagDetection]:
        """Tags in a 2-D uint8 image, sorted by id (OpenCV's calls on ``nthreads`` threads too)."""
        import cv2

        grey = np.ascontiguousarray(grey, dtype=np.uint8)
        out: list[TagDetection] = []
        with opencv_threads(self.settings["nthreads"]):
            if self.upsample != 1.0:
                grey = cv2.resize(grey, None, fx=self.upsample, fy=self.upsample, interpolation=cv2.INTER_LINEAR)
            if self.backend == "apriltag3":
                for d in self._detector.detect(grey):
                    if d.hamming > self.max_hamming:
                        continue
                    corners = corners_from_upsampled(apriltag_to_opencv_corners(d.corners), self.upsample)
                    out.append(TagDetection(int(d.tag_id), self.family, corners, int(d.hamming),
                                            float(d.decision_margin)))
            elif self._candidates is not None:
                for tag_id, corners in identify_quads(grey, self._candidates.quads(grey), self._codes):
                    out.append(TagDetection(tag_id, self.family, corners_from_upsampled(corners, self.upsample)))
            else:
                corners, ids, _ = self._detector.detectMarkers(grey)
                if ids is not None:
                    for c, i in zip(corners, ids.ravel()):
                        c = corners_from_upsampled(np.asarray(c, dtype=float).reshape(4, 2), self.upsample)
                        out.append(TagDetection(int(i), self.family, c))
        out.sort(key=lambda t: (t.tag_id, float(t.centre_px[0])))
        return out
