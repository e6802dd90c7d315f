"""Kinect colour landmarks (seed 000): coloured cylinders found by colour, measured with depth.

Pipeline for one colour (:class:`ColourSpec`)
=============================================

1. **Segmentation** in HSV (OpenCV scale: H 0–179, S and V 0–255): the union of the
   colour's ranges (red needs two, it wraps around H = 0). Saturation and value floors make
   it independent of brightness within limits: a shaded side of a cylinder keeps its hue.
2. **Clean-up**: morphological opening (drops speckle) then closing (fills holes from
   highlights), then connected components; components smaller than ``min_area_px`` are
   noise. **One blob per colour**: the largest component; how many others were dropped is
   reported (``extra_blobs``). A blob touching the image's left or right side is rejected
   (``blob_at_image_border``): its silhouette, hence its bearing, is cut.
3. **Depth**: registered depth in metres (NaN = missing; see :func:`depth_from_mm`,
   :func:`depth_from_kinect_raw` for the Kinect's encodings, where 0 and 2047 mean
   missing). Only pixels of the blob's middle third of columns are used — the part of a
   cylinder's face nearest the camera — and at least ``min_valid_depth_fraction`` of them
   must have depth, else the blob is rejected (``missing_depth``).
4. **Bearing** (exact): the blob's left and right silhouette edges (pixel boundaries
   u_left − ½ and u_right + ½, at the blob's middle row) are back-projected through the
   intrinsics and distortion; each ray lies in a vertical plane tangent to the cylinder, so
   the axis is at the mean of the two azimuths seen from the camera — exact for any camera
   tilt and any bearing. ``bearing_method="linear"`` is seed 000's map instead: the angle is
   a linear function of the blob's centre column, (cx − u)·HFOV/width, with the Kinect's
   nominal 57° HFOV; :func:`linear_bearing_error_rad` gives its error against the pinhole
   with fx = 525: up to 3.2° about 250 px from the centre (2.9° at the image edge).
5. **Range**: every valid depth pixel of the middle third is back-projected into the robot
   frame; the median of their horizontal distances from the camera plus the cylinder radius
   is the distance of the axis from the camera; the axis point gives range and bearing from
   the robot's origin (the camera need not sit at the origin).
6. **Height** (exact pinhole): the top edge (row v_top − ½, depth = median of the top rows'
   valid depth) and the bottom edge (v_bottom + ½) are back-projected into the robot frame;
   height = z_top − z_bottom, independent of the camera's height. When the blob touches the
   image's bottom border (the cylinder's foot is out of view) the height is z_top above the
   floor, which needs the mount's height to be right (``height_from="top"``); when it touches
   the top border there is no height (``height_cut_off``). ``height_method="gheight"`` is
   seed 002's ``gHeight(d1, d2, pd)`` instead (:func:`gheight_seed002`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from slamio.camera.model import CameraModel, transform_points

# Kinect v1 raw 11-bit disparity → metres (N. Burrus's fit); 2047 = no reading.
KINECT_RAW_MISSING = 2047
_KINECT_A = -0.0030711016
_KINECT_B = 3.3309495161

#: Seed 000/002's nominal Kinect fields of view.
KINECT_HFOV_RAD = math.radians(57.0)
GHEIGHT_VFOV_DEG = 47.0  # seed 002's gHeight uses 47° over 480 rows


@dataclass(frozen=True)
class ColourSpec:
    """One landmark colour: HSV ranges (OpenCV scale), its landmark id and cylinder radius."""

    name: str
    landmark_id: int | None
    hsv_ranges: tuple[tuple[tuple[int, int, int], tuple[int, int, int]], ...]
    radius_m: float = 0.05
    min_area_px: int = 40


#: Seed 000's red, green and blue cylinders, ids as in ``fgslam sim cylinders``.
DEFAULT_COLOURS = (
    ColourSpec("red", 0, (((0, 110, 60), (8, 255, 255)), ((170, 110, 60), (179, 255, 255)))),
    ColourSpec("green", 1, (((40, 110, 50), (85, 255, 255)),)),
    ColourSpec("blue", 2, (((100, 110, 50), (130, 255, 255)),)),
)


@dataclass(frozen=True, eq=False)
class Blob:
    """One connected component of a colour mask."""

    colour: ColourSpec
    mask: np.ndarray  # (H, W) bool, the component only
    left: int
    top: int
    right: int  # inclusive
    bottom: int  # inclusive
    area_px: int
    extra_blobs: int = 0  # other components of this colour above min_area, dropped

    @property
    def width_px(self) -> int:
        return self.right - self.left + 1


@dataclass(frozen=True)
class ColourMeasurement:
    """A measured colour landmark in the robot frame (height None when not measurable)."""

    colour: str
    landmark_id: int | None
    range_m: float
    bearing_rad: float
    height_m: float | None
    height_note: str | None = None  # why there is no height, or how it was measured
    extra_blobs: int = 0


@dataclass(frozen=True)
class ColourRejection:
    colour: str
    reason: str
    detail: str = ""


@dataclass(frozen=True)
class ColourOptions:
    """How blobs become measurements (see the module doc)."""

    bearing_method: str = "exact"  # or "linear" (seed 000)
    height_method: str = "pinhole"  # or "gheight" (seed 002)
    hfov_rad: float = KINECT_HFOV_RAD  # for bearing_method="linear"
    min_valid_depth_fraction: float = 0.3
    min_valid_depth_px: int = 5
    edge_rows: int = 3  # rows whose depth is used at the top and bottom edge
    open_px: int = 3
    close_px: int = 5
    colours: tuple[ColourSpec, ...] = field(default=DEFAULT_COLOURS)


# --------------------------------------------------------------------------- depth encodings


def depth_from_mm(depth_mm: np.ndarray) -> np.ndarray:
    """Registered depth in millimetres (OpenNI2, libfreenect DEPTH_REGISTERED; 0 = missing) → metres."""
    d = np.asarray(depth_mm).astype(np.float32) / 1000.0
    d[np.asarray(depth_mm) == 0] = np.nan
    return d


def depth_from_scaled(depth_png: np.ndarray, scale_per_m: float = 5000.0) -> np.ndarray:
    """16-bit depth PNG with ``scale_per_m`` units per metre (TUM RGB-D: 5000; 0 = missing) → metres."""
    d = np.asarray(depth_png).astype(np.float32) / float(scale_per_m)
    d[np.asarray(depth_png) == 0] = np.nan
    return d


def depth_from_kinect_raw(raw: np.ndarray) -> np.ndarray:
    """Kinect v1 raw 11-bit disparity (2047 = missing) → metres (Burrus's fit)."""
    r = np.asarray(raw).astype(np.float64)
    with np.errstate(divide="ignore"):
        d = 1.0 / (_KINECT_A * r + _KINECT_B)
    d[(np.asarray(raw) >= KINECT_RAW_MISSING) | ~(d > 0)] = np.nan
    return d.astype(np.float32)


# --------------------------------------------------------------------------- pure maths


def linear_bearing_rad(u_px: float, width_px: int, hfov_rad: float = KINECT_HFOV_RAD) -> float:
    """Seed 000's bearing: linear in the column, 0 at the image centre, +hfov/2 at the left edge."""
    cx = 0.5 * (width_px - 1)
    return (cx - u_px) * hfov_rad / width_px


def exact_bearing_rad(u_px: float, camera: CameraModel) -> float:
    """Bearing of a column through the pinhole (camera looking along robot x, no distortion)."""
    return math.atan2(camera.cx - u_px, camera.fx)


def linear_bearing_error_rad(u_px: float, camera: CameraModel, hfov_rad: float = KINECT_HFOV_RAD) -> float:
    """Seed 000's linear map minus the pinhole bearing of the same column."""
    return linear_bearing_rad(u_px, camera.width_px, hfov_rad) - exact_bearing_rad(u_px, camera)


def gheight_seed002(d1: float, d2: float, pd_px: float, vfov_deg: float = GHEIGHT_VFOV_DEG,
                    rows: int = 480) -> float:
    """Seed 002's ``gHeight(d1, d2, pd)``, as written (any length unit in, same unit out).

    ``theta = pd·47/480`` degrees; ``db1 = ds·cos θ``; ``db2 = db − db1``;
    ``dp = sqrt(ds² − db1²)``; ``h = sqrt(db2² + dp²)`` with ds, db the smaller and larger
    depth. Algebraically this is the law of cosines, h² = ds² + db² − 2·ds·db·cos θ: the
    distance between the two points — exact if d1 and d2 were distances *along the rays*
    and θ the true angle between them. The Kinect gives depth along the optical axis and
    the angle is not linear in the row, which is where its error comes from.
    """
    ds, db = min(d1, d2), max(d1, d2)
    theta = math.radians(pd_px * vfov_deg / rows)
    db1 = ds * math.cos(theta)
    db2 = db - db1
    dp = math.sqrt(max(ds * ds - db1 * db1, 0.0))
    return math.sqrt(db2 * db2 + dp * dp)


# --------------------------------------------------------------------------- segmentation


def colour_mask(hsv: np.ndarray, colour: ColourSpec) -> np.ndarray:
    """uint8 mask (255 = in any of the colour's HSV ranges)."""
    import cv2

    mask = np.zeros(hsv.shape[:2], dtype=np.uint8)
    for lo, hi in colour.hsv_ranges:
        mask |= cv2.inRange(hsv, np.array(lo, dtype=np.uint8), np.array(hi, dtype=np.uint8))
    return mask


def clean_mask(mask: np.ndarray, open_px: int = 3, close_px: int = 5) -> np.ndarray:
    """Opening then closing with elliptical kernels (sizes in pixels; 0 skips)."""
    import cv2

    out = mask
    if open_px > 1:
        out = cv2.morphologyEx(out, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (open_px, open_px)))
    if close_px > 1:
        out = cv2.morphologyEx(out, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (close_px, close_px)))
    return out


def largest_blob(mask: np.ndarray, colour: ColourSpec) -> Blob | None:
    """The largest connected component of at least ``colour.min_area_px`` pixels."""
    import cv2

    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    big = np.nonzero(areas >= colour.min_area_px)[0]
    if len(big) == 0:
        return None
    best = big[np.argmax(areas[big])] + 1
    x, y, w, h, area = stats[best]
    return Blob(colour, labels == best, int(x), int(y), int(x + w - 1), int(y + h - 1), int(area), len(big) - 1)


def find_blobs(bgr: np.ndarray, options: ColourOptions = ColourOptions()) -> tuple[list[Blob], list[str]]:
    """One blob per configured colour (colours not found are listed in the second item)."""
    import cv2

    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    blobs, missing = [], []
    for colour in options.colours:
        blob = largest_blob(clean_mask(colour_mask(hsv, colour), options.open_px, options.close_px), colour)
        if blob is None:
            missing.append(colour.name)
        else:
            blobs.append(blob)
    return blobs, missing


# --------------------------------------------------------------------------- measurement


def _middle_columns(blob: Blob) -> tuple[int, int]:
    third = blob.width_px / 3.0
    c0 = blob.left + int(math.floor(third))
    c1 = blob.right - int(math.floor(third))
    return c0, max(c0, c1)


def _edge_depth(depth: np.ndarray, band: np.ndarray, rows: np.ndarray, from_top: bool, k: int) -> float:
    """Median valid depth of the first k mask rows of the band from the top (or bottom)."""
    chosen = rows[:k] if from_top else rows[-k:]
    values = depth[chosen][band[chosen]]
    values = values[np.isfinite(values) & (values > 0)]
    return float(np.median(values)) if len(values) else float("nan")


def measure_blob(blob: Blob, depth_m: np.ndarray, camera: CameraModel,
                 options: ColourOptions = ColourOptions()) -> ColourMeasurement | ColourRejection:
    """Range, bearing and height of a blob in the robot frame, or why it cannot be measured."""
    name = blob.colour.name
    if blob.left <= 0 or blob.right >= camera.width_px - 1:
        return ColourRejection(name, "blob_at_image_border", "the silhouette is cut by the image's side")
    c0, c1 = _middle_columns(blob)
    band = np.zeros_like(blob.mask)
    band[:, c0 : c1 + 1] = blob.mask[:, c0 : c1 + 1]
    rows_v, cols_u = np.nonzero(band)
    if len(rows_v) == 0:
        return ColourRejection(name, "missing_depth", "empty middle band")
    z = depth_m[rows_v, cols_u]
    valid = np.isfinite(z) & (z > 0)
    n_valid = int(valid.sum())
    if n_valid < max(options.min_valid_depth_px, options.min_valid_depth_fraction * len(z)):
        return ColourRejection(
            name, "missing_depth", f"{n_valid} of {len(z)} pixels of the blob's middle have depth"
        )
    T = camera.T_robot_camera
    camera_xy = T[:2, 3]
    # bearing: the two silhouette edges at the blob's middle row
    mid_row = int(round(0.5 * (blob.top + blob.bottom)))
    row_cols = np.nonzero(blob.mask[mid_row])[0]
    if len(row_cols) == 0:
        row_cols = np.array([blob.left, blob.right])
    u_left, u_right = row_cols.min() - 0.5, row_cols.max() + 0.5
    if options.bearing_method == "linear":
        u_mid = 0.5 * (u_left + u_right)
        azimuth = linear_bearing_rad(u_mid, camera.width_px, options.hfov_rad) + math.atan2(T[1, 2], T[0, 2])
    else:
        rays = camera.rays_camera(np.array([[u_left, mid_row], [u_right, mid_row]], dtype=float))
        rays_robot = rays @ T[:3, :3].T
        a = np.arctan2(rays_robot[:, 1], rays_robot[:, 0])
        azimuth = float(a[0] + 0.5 * math.remainder(a[1] - a[0], 2 * math.pi))
    # range: median horizontal distance of the face, plus the radius, along the axis azimuth
    uv = np.column_stack([cols_u[valid], rows_v[valid]]).astype(float)
    p_robot = transform_points(T, camera.backproject(uv, z[valid]))
    rho = np.hypot(p_robot[:, 0] - camera_xy[0], p_robot[:, 1] - camera_xy[1])
    distance = float(np.median(rho)) + blob.colour.radius_m
    axis_xy = camera_xy + distance * np.array([math.cos(azimuth), math.sin(azimuth)])
    range_m = float(math.hypot(*axis_xy))
    bearing_rad = float(math.atan2(axis_xy[1], axis_xy[0]))
    height, note = _height(blob, band, depth_m, camera, options, c0, c1)
    return ColourMeasurement(name, blob.colour.landmark_id, range_m, bearing_rad, height, note, blob.extra_blobs)


def _height(blob: Blob, band: np.ndarray, depth_m: np.ndarray, camera: CameraModel, options: ColourOptions,
            c0: int, c1: int) -> tuple[float | None, str | None]:
    if blob.top <= 0:
        return None, "height_cut_off"
    band_rows = np.nonzero(band.any(axis=1))[0]
    top_row, bottom_row = int(band_rows[0]), int(band_rows[-1])
    bottom_visible = bottom_row < camera.height_px - 1
    k = options.edge_rows
    z_top_depth = _edge_depth(depth_m, band, band_rows, True, k)
    z_bottom_depth = _edge_depth(depth_m, band, band_rows, False, k) if bottom_visible else float("nan")
    if not math.isfinite(z_top_depth):
        return None, "height_no_depth"
    if options.height_method == "gheight":
        if not (bottom_visible and math.isfinite(z_bottom_depth)):
            return None, "height_cut_off"
        return gheight_seed002(z_top_depth, z_bottom_depth, bottom_row - top_row, rows=camera.height_px), "gheight"
    u_mid = 0.5 * (c0 + c1)
    T = camera.T_robot_camera
    top = transform_points(T, camera.backproject(np.array([[u_mid, top_row - 0.5]]), [z_top_depth]))[0]
    if bottom_visible and math.isfinite(z_bottom_depth):
        bottom = transform_points(T, camera.backproject(np.array([[u_mid, bottom_row + 0.5]]), [z_bottom_depth]))[0]
        return float(top[2] - bottom[2]), "top-bottom"
    return float(top[2]), "top-above-floor"


def detect_colour_landmarks(bgr: np.ndarray, depth_m: np.ndarray, camera: CameraModel,
                            options: ColourOptions = ColourOptions()
                            ) -> tuple[list[ColourMeasurement], list[ColourRejection], list[Blob]]:
    """Every configured colour in one frame: measurements, rejected blobs, and the blobs (for drawing)."""
    blobs, _ = find_blobs(bgr, options)
    measured, rejected = [], []
    for blob in blobs:
        result = measure_blob(blob, depth_m, camera, options)
        (measured if isinstance(result, ColourMeasurement) else rejected).append(result)
    return measured, rejected, blobs
