"""Kinect colour landmarks (seeds 000 and 002): coloured shapes found by colour, checked, measured with depth.

Pipeline for one landmark colour (:class:`ColourSpec`)
======================================================

1. **Segmentation** in HSV (OpenCV scale: H 0–179, S and V 0–255): the union of the
   colour's ranges (red needs two, it wraps around H = 0). Saturation and value floors make
   it independent of brightness within limits: a shaded side of a cylinder keeps its hue.
2. **Clean-up**: morphological opening (drops speckle) then closing (fills holes from
   highlights), then connected components; components smaller than ``min_area_px`` are
   noise. Every other component is a **candidate**.
3. **Checks** — a candidate becomes a landmark only if it passes all of them, in this order,
   and is otherwise rejected with the first failing reason (:data:`BLOB_REJECTIONS`):
   not touching the image's left or right side (its silhouette, hence its bearing, would be
   cut); the **shape** (the fraction of its bounding box it fills,
   :data:`slamio.camera.colour_checks.FILL_RATIO_RANGE`, and for straight-sided shapes rows
   of about equal width, :func:`slamio.camera.colour_checks.uneven_row_fraction`); enough valid **depth** in the
   middle third of its eroded body; a **consistent depth** across the eroded body (at most 5 %
   of it farther from the face's median distance than half the landmark's width plus noise: a
   landmark merged in the image with something of its colour behind it fails here); a physical
   **width** (silhouette angle × depth) within ``size_tolerance`` of the landmark's; and,
   when measurable, a **height** within ``height_tolerance`` of the landmark's. A candidate that
   fails on shape, depth, size or height is cut along depth discontinuities
   (:func:`split_by_depth`) and its parts are checked again: a landmark standing in front of
   something of its colour makes one colour blob with it, but not one surface. Only when no
   part passes is the candidate's rejection counted. When several candidates of one colour
   pass, the one whose width fits best is kept (``extra_blobs``).
4. **Depth of the body**: the blob's mask is eroded by ``erode_px`` before any depth is
   read, so a depth image misregistered against the colour image by up to that many pixels
   (the Kinect's depth-to-colour registration is a few pixels off at edges) reads the
   landmark, not the wall behind it. Depth is registered depth in metres (NaN = missing; see
   :func:`~slamio.camera.kinect.depth_from_mm`, :func:`~slamio.camera.kinect.depth_from_kinect_raw`
   for the Kinect's encodings).
5. **Bearing** (exact): the blob's left and right silhouette edges (pixel boundaries
   u_left − ½ and u_right + ½, at the blob's middle row) are back-projected through the
   intrinsics and distortion; for a cylinder each ray lies in a vertical plane tangent to it,
   so the axis is at the mean of the two azimuths seen from the camera — exact for any camera
   tilt and any bearing. ``bearing_method="linear"`` is seed 000's map instead: the angle is
   a linear function of the blob's centre column, (cx − u)·HFOV/width, with the Kinect's
   nominal 57° HFOV; :func:`~slamio.camera.kinect.linear_bearing_error_rad` gives its error
   against the pinhole with fx = 525: up to 3.2° about 250 px from the centre (2.9° at the
   image edge).
6. **Range**: the valid depth pixels of the eroded body's middle third of columns are
   back-projected into the robot frame; the median of their horizontal distances from the
   camera is the face distance f; plus the radius for a cylinder, it is the distance of the
   landmark point from the camera along the bearing azimuth; that point gives range and
   bearing from the robot's origin (the camera need not sit at the origin).
7. **Height** (exact pinhole, from the body's depth): the top edge (row v_top − ½) and the
   bottom edge (v_bottom + ½) are back-projected along their rays to the horizontal distance
   of the surface that makes them — the face f, or for a cylinder seen from above its top the
   far rim f + 2R — and height = z_top − z_bottom, independent of the camera's height. No
   depth is read at the edges themselves, where misregistration puts the background. When the
   blob touches the image's bottom border (the foot is out of view) the height is z_top above
   the floor, which needs the mount's height to be right; when it touches the top border
   there is no height (``height_cut_off``). Rows where the blob continues at another depth
   (something of its colour right above or below it) are not the landmark's
   (:func:`_surface_rows`). When something of its colour continues an end so that neither
   colour nor depth can place it well enough there is no height (``height_ambiguous``,
   :func:`_ambiguous_end`). ``height_method="gheight"`` is seed 002's
   ``gHeight(d1, d2, pd)`` instead (:func:`~slamio.camera.kinect.gheight_seed002`), with d1, d2 read at the top
   and bottom rows as the seed does.

The landmarks and the check tolerances are read from a file the user edits
(:mod:`slamio.camera.landmark_file`); :data:`DEFAULT_COLOURS` are seed 000's cylinders as
``fgslam sim cylinders`` places them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from slamio.camera.colour_checks import (
    SHAPES,
    STRAIGHT_SIDED,
    allowed_depth_deviation_m,
    colour_rows_past,
    fill_ratio,
    outlier_fraction,
    relative_error,
    rim_arc_rows,
    row_extents,
    rows_outside_body,
    shape_fits,
    uneven_row_fraction,
    width_from_silhouette_m,
    z_at_horizontal_distance,
)
from slamio.camera.kinect import (
    KINECT_HFOV_RAD,
    gheight_seed002,
    linear_bearing_rad,
)
from slamio.camera.model import CameraModel, transform_points

#: Why a candidate blob is not a landmark (the checks of step 3, in order).
BLOB_REJECTIONS = {
    "blob_at_image_border": "a colour blob cut by the image's left or right side (its bearing would be off)",
    "shape_mismatch": "a colour blob whose shape (fill of its bounding box) is not the landmark's",
    "missing_depth": "a colour blob whose middle has too few valid depth pixels (0 mm / raw 2047 / NaN)",
    "depth_inconsistent": "a colour blob whose depth varies more than one landmark's can (several objects, "
    "or a surface running away from the camera)",
    "size_mismatch": "a colour blob whose width at its depth is not the landmark's (too big or too small)",
    "height_mismatch": "a colour blob whose measured height is not the landmark's",
}

#: Rejections after which a blob is cut along depth discontinuities and its parts checked again.
SPLIT_WHEN = ("shape_mismatch", "depth_inconsistent", "size_mismatch", "height_mismatch")

HsvRange = tuple[tuple[int, int, int], tuple[int, int, int]]


@dataclass(frozen=True)
class ColourSpec:
    """One landmark: its colour (HSV ranges, OpenCV scale), landmark id, shape and size.

    ``width_m`` is a cylinder's or circle's diameter, a triangle's base or a rectangle's
    width; ``height_m`` None means any height (not checked).
    """

    name: str
    landmark_id: int | None
    hsv_ranges: tuple[HsvRange, ...]
    shape: str = "cylinder"
    width_m: float = 0.10
    height_m: float | None = None
    min_area_px: int = 40

    def __post_init__(self):
        if self.shape not in SHAPES:
            raise ValueError(f"landmark {self.name!r}: shape must be one of {', '.join(SHAPES)}, got {self.shape!r}")

    @property
    def radius_m(self) -> float:
        """Distance from the face the camera sees to the landmark point (a cylinder's axis)."""
        return 0.5 * self.width_m if self.shape == "cylinder" else 0.0


#: Seed 000's red, green and blue cylinders (ids, diameter and heights as ``fgslam sim cylinders``).
DEFAULT_COLOURS = (
    ColourSpec("red", 0, (((0, 110, 60), (8, 255, 255)), ((170, 110, 60), (179, 255, 255))), height_m=0.40),
    ColourSpec("green", 1, (((40, 110, 50), (85, 255, 255)),), height_m=0.60),
    ColourSpec("blue", 2, (((100, 110, 50), (130, 255, 255)),), height_m=0.80),
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
    extra_blobs: int = 0  # other candidates of this colour that passed every check too
    component: np.ndarray | None = None  # the colour component a depth cut took it from (None: itself)

    @property
    def width_px(self) -> int:
        return self.right - self.left + 1

    @property
    def height_px(self) -> int:
        return self.bottom - self.top + 1


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
    width_m: float | None = None  # the measured physical width
    blob: Blob | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class ColourRejection:
    colour: str
    reason: str  # a key of BLOB_REJECTIONS
    detail: str = ""
    blob: Blob | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class ColourOptions:
    """The landmarks, the checks' tolerances and the measuring methods (see the module doc)."""

    colours: tuple[ColourSpec, ...] = field(default=DEFAULT_COLOURS)
    size_tolerance: float = 0.35  # |measured width / landmark width − 1| at most
    height_tolerance: float = 0.15  # |measured height / landmark height − 1| at most
    height_precision: float = 0.03  # no height when an end set by depth alone may be off by more (× height)
    depth_tolerance_m: float = 0.03  # body depth off the face by more than this + width/2 + 2 Kinect steps ...
    depth_outliers: float = 0.05  # ... in more than this fraction of the body: not one landmark
    uneven_rows: float = 0.08  # cylinders, rectangles: at most this fraction of rows wider/narrower than most
    erode_px: int = 3  # read depth this far inside the blob (depth-to-colour misregistration)
    min_valid_depth_fraction: float = 0.3
    min_valid_depth_px: int = 5
    bearing_method: str = "exact"  # or "linear" (seed 000)
    height_method: str = "pinhole"  # or "gheight" (seed 002)
    hfov_rad: float = KINECT_HFOV_RAD  # for bearing_method="linear"
    edge_rows: int = 3  # rows whose depth seed 002's gHeight reads at the top and bottom edge
    open_px: int = 3
    close_px: int = 5


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


def candidate_blobs(mask: np.ndarray, colour: ColourSpec) -> list[Blob]:
    """Every connected component of at least ``colour.min_area_px`` pixels, largest first."""
    import cv2

    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    big = np.nonzero(areas >= colour.min_area_px)[0]
    blobs = []
    for index in big[np.argsort(-areas[big], kind="stable")] + 1:
        x, y, w, h, area = stats[index]
        blobs.append(Blob(colour, labels == index, int(x), int(y), int(x + w - 1), int(y + h - 1), int(area)))
    return blobs


def largest_blob(mask: np.ndarray, colour: ColourSpec) -> Blob | None:
    """The largest connected component of at least ``colour.min_area_px`` pixels."""
    blobs = candidate_blobs(mask, colour)
    return blobs[0] if blobs else None


def find_blobs(bgr: np.ndarray, options: ColourOptions = ColourOptions()) -> tuple[list[Blob], list[str]]:
    """Every candidate blob of every configured colour (colours with none are listed in the second item)."""
    import cv2

    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    blobs, missing = [], []
    for colour in options.colours:
        found = candidate_blobs(clean_mask(colour_mask(hsv, colour), options.open_px, options.close_px), colour)
        blobs.extend(found)
        if not found:
            missing.append(colour.name)
    return blobs, missing


def depth_jumps(depth_m: np.ndarray, min_jump_m: float = 0.1, relative: float = 0.05) -> np.ndarray:
    """Pixels on the far side of a depth discontinuity (a jump to a 4-neighbour larger than
    max(``min_jump_m``, ``relative`` × depth)); missing depth makes no jump."""
    d = np.where(np.isfinite(depth_m), depth_m, np.nan)
    far = np.zeros(d.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        for axis in (0, 1):
            a = d[:-1, :] if axis == 0 else d[:, :-1]
            b = d[1:, :] if axis == 0 else d[:, 1:]
            jump = np.abs(b - a) > np.maximum(min_jump_m, relative * np.fmin(a, b))
            a_far, b_far = jump & (a > b), jump & (b > a)
            if axis == 0:
                far[:-1, :] |= a_far
                far[1:, :] |= b_far
            else:
                far[:, :-1] |= a_far
                far[:, 1:] |= b_far
    return far


def split_by_depth(blob: Blob, depth_m: np.ndarray) -> list[Blob]:
    """The blob cut along depth discontinuities: a landmark standing in front of something of its
    colour makes one colour blob with it, but not one surface. Parts of at least the colour's
    ``min_area_px``, largest first (just the blob when nothing splits it)."""
    import cv2

    r0, r1, c0, c1 = blob.top, blob.bottom + 1, blob.left, blob.right + 1
    crop = blob.mask[r0:r1, c0:c1] & ~depth_jumps(depth_m[r0:r1, c0:c1])
    count, labels, stats, _ = cv2.connectedComponentsWithStats(crop.astype(np.uint8), connectivity=4)
    parts = []
    for index in range(1, count):
        x, y, w, h, area = stats[index]
        if area < blob.colour.min_area_px:
            continue
        mask = np.zeros_like(blob.mask)
        mask[r0:r1, c0:c1] = labels == index
        parts.append(Blob(blob.colour, mask, c0 + int(x), r0 + int(y), c0 + int(x + w - 1), r0 + int(y + h - 1),
                          int(area), component=blob.mask if blob.component is None else blob.component))
    return sorted(parts, key=lambda b: -b.area_px) if len(parts) > 1 else [blob]


# --------------------------------------------------------------------------- measurement


def eroded_body(blob: Blob, erode_px: int) -> np.ndarray:
    """The blob's mask eroded by up to ``erode_px`` (less for a blob too thin to keep a core)."""
    import cv2

    k = min(int(erode_px), max(0, (blob.width_px - 3) // 2), max(0, (blob.height_px - 3) // 2))
    if k <= 0:
        return blob.mask
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * k + 1, 2 * k + 1))
    return cv2.erode(blob.mask.astype(np.uint8), kernel).astype(bool)


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


def _horizontal_distances(camera: CameraModel, rows_v: np.ndarray, cols_u: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Horizontal distance from the lens of each (valid-depth) pixel, in the robot frame."""
    T = camera.T_robot_camera
    uv = np.column_stack([cols_u, rows_v]).astype(float)
    p_robot = transform_points(T, camera.backproject(uv, z))
    return np.hypot(p_robot[:, 0] - T[0, 3], p_robot[:, 1] - T[1, 3])


def _azimuths(camera: CameraModel, uv_px: np.ndarray) -> np.ndarray:
    """Robot-frame azimuths of the rays through these pixels."""
    rays_robot = camera.rays_camera(uv_px) @ camera.T_robot_camera[:3, :3].T
    return np.arctan2(rays_robot[:, 1], rays_robot[:, 0])


def measure_blob(blob: Blob, depth_m: np.ndarray, camera: CameraModel,
                 options: ColourOptions = ColourOptions()) -> ColourMeasurement | ColourRejection:
    """Range, bearing and height of a blob in the robot frame, or the first check it fails."""
    spec = blob.colour
    name = spec.name

    def reject(reason: str, detail: str) -> ColourRejection:
        return ColourRejection(name, reason, detail, blob)

    if blob.left <= 0 or blob.right >= camera.width_px - 1:
        return reject("blob_at_image_border", "the silhouette is cut by the image's side")
    fill = fill_ratio(blob.area_px, blob.width_px, blob.height_px)
    if not shape_fits(spec.shape, fill):
        return reject("shape_mismatch", f"fills {fill:.2f} of its box; not a {spec.shape}")
    if spec.shape in STRAIGHT_SIDED:
        crop = blob.mask[blob.top : blob.bottom + 1, blob.left : blob.right + 1]
        uneven = uneven_row_fraction(crop)
        if uneven > options.uneven_rows:
            return reject("shape_mismatch", f"{uneven:.0%} of its rows stick out; not a {spec.shape}")
    body = eroded_body(blob, options.erode_px)
    c0, c1 = _middle_columns(blob)
    band = np.zeros_like(body)
    band[:, c0 : c1 + 1] = body[:, c0 : c1 + 1]
    rows_v, cols_u = np.nonzero(band)
    z = depth_m[rows_v, cols_u]
    valid = np.isfinite(z) & (z > 0)
    n_valid = int(valid.sum())
    if len(z) == 0 or n_valid < max(options.min_valid_depth_px, options.min_valid_depth_fraction * len(z)):
        return reject("missing_depth", f"{n_valid} of {len(z)} pixels of the blob's middle have depth")
    face_m = float(np.median(_horizontal_distances(camera, rows_v[valid], cols_u[valid], z[valid])))
    body_v, body_u = np.nonzero(body)
    body_z = depth_m[body_v, body_u]
    body_ok = np.isfinite(body_z) & (body_z > 0)
    allowed = allowed_depth_deviation_m(spec.width_m, face_m, options.depth_tolerance_m)
    rho_body = _horizontal_distances(camera, body_v[body_ok], body_u[body_ok], body_z[body_ok])
    off = outlier_fraction(rho_body, face_m, allowed)
    if off > options.depth_outliers:
        return reject("depth_inconsistent", f"{off:.0%} of its body is more than {allowed:.2f} m off its {face_m:.2f} m")
    # bearing and width: the silhouette's edges at the blob's middle row, and its box's
    mid_row = int(round(0.5 * (blob.top + blob.bottom)))
    row_cols = np.nonzero(blob.mask[mid_row])[0]
    if len(row_cols) == 0:
        row_cols = np.array([blob.left, blob.right])
    u_left, u_right = row_cols.min() - 0.5, row_cols.max() + 0.5
    a_box = _azimuths(camera, np.array([[blob.left - 0.5, mid_row], [blob.right + 0.5, mid_row]], dtype=float))
    width_m = width_from_silhouette_m(spec.shape, math.remainder(a_box[0] - a_box[1], 2 * math.pi), face_m)
    size_error = relative_error(width_m, spec.width_m)
    if abs(size_error) > options.size_tolerance:
        return reject("size_mismatch", f"{width_m:.2f} m wide at {face_m:.2f} m, the landmark is {spec.width_m:.2f} m")
    T = camera.T_robot_camera
    camera_xy = T[:2, 3]
    if options.bearing_method == "linear":
        u_mid = 0.5 * (u_left + u_right)
        azimuth = linear_bearing_rad(u_mid, camera.width_px, options.hfov_rad) + math.atan2(T[1, 2], T[0, 2])
    else:
        a = _azimuths(camera, np.array([[u_left, mid_row], [u_right, mid_row]], dtype=float))
        azimuth = float(a[0] + 0.5 * math.remainder(a[1] - a[0], 2 * math.pi))
    distance = face_m + spec.radius_m
    axis_xy = camera_xy + distance * np.array([math.cos(azimuth), math.sin(azimuth)])
    range_m = float(math.hypot(*axis_xy))
    bearing_rad = float(math.atan2(axis_xy[1], axis_xy[0]))
    if options.height_method == "gheight":
        height, note = _gheight(blob, band, depth_m, camera, options)
    else:
        top, bottom = _surface_rows(blob, depth_m, camera, face_m, allowed, options.erode_px)
        height, note = _height(blob, camera, face_m, spec.radius_m, top, bottom)
        if height is not None and _ambiguous_end(blob, camera, face_m, top, bottom, spec.height_m or height, options):
            height, note = None, "height_ambiguous"
    if height is not None and spec.height_m is not None:
        if abs(relative_error(height, spec.height_m)) > options.height_tolerance:
            return reject("height_mismatch", f"{height:.2f} m tall, the landmark is {spec.height_m:.2f} m")
    return ColourMeasurement(name, spec.landmark_id, range_m, bearing_rad, height, note, blob.extra_blobs,
                             width_m, blob)


def _surface_rows(blob: Blob, depth_m: np.ndarray, camera: CameraModel, face_m: float, allowed_m: float,
                  margin_px: int) -> tuple[int, int]:
    """The blob's top and bottom rows, trimmed where something of the landmark's colour but at
    another depth continues it (a red poster on the wall right above a red cylinder).

    Walking up (down) from the body's middle, rows of the middle third whose median distance
    is off the face by more than ``allowed_m`` end the landmark. The colour edge is kept when
    the depth edge is within ``margin_px`` + 1 rows of it (misregistered depth), up to the
    first of those rows narrower than a third of the blob's median row (:func:`_wide_rows_end`)."""
    c0, c1 = _middle_columns(blob)
    rows = np.arange(blob.top, blob.bottom + 1)
    status = np.zeros(len(rows), dtype=int)  # +1 on the face, -1 off it, 0 no depth
    for k, v in enumerate(rows):
        cols = np.nonzero(blob.mask[v, c0 : c1 + 1])[0] + c0
        z = depth_m[v, cols]
        ok = np.isfinite(z) & (z > 0)
        if ok.any():
            rho = _horizontal_distances(camera, np.full(int(ok.sum()), v), cols[ok], z[ok])
            status[k] = 1 if abs(float(np.median(rho)) - face_m) <= allowed_m else -1
    middle = len(rows) // 2
    up = middle
    while up > 0 and status[up - 1] != -1:
        up -= 1
    down = middle
    while down < len(rows) - 1 and status[down + 1] != -1:
        down += 1
    top = int(rows[up]) if up - 0 > margin_px + 1 else _wide_rows_end(blob, rows[: up + 1][::-1])
    bottom = int(rows[down]) if (len(rows) - 1 - down) > margin_px + 1 else _wide_rows_end(blob, rows[down:])
    return top, bottom


def _wide_rows_end(blob: Blob, rows: np.ndarray, fraction: float = 1 / 3) -> int:
    """Walking ``rows`` outwards from the last row on the face, the last one before a row narrower
    than ``fraction`` of the blob's median row: rows off the face kept because misregistered
    depth may put the background on the landmark's edge are the landmark's only when they are
    at least a third as wide as its body (the corner of a poster's frame touching its top is not)."""
    median = float(np.median(blob.mask[blob.top : blob.bottom + 1].sum(axis=1)))
    end = int(rows[0])
    for v in rows:
        if blob.mask[v].sum() < fraction * median:
            break
        end = int(v)
    return end


def _height(blob: Blob, camera: CameraModel, face_m: float, radius_m: float, top: int, bottom: int
            ) -> tuple[float | None, str | None]:
    """Height from the body's depth: the edge rays meet the surface that makes each edge."""
    if top <= 0:
        return None, "height_cut_off"
    T = camera.T_robot_camera
    origin = T[:3, 3]
    u_mid = 0.5 * (blob.left + blob.right)
    rays = camera.rays_camera(np.array([[u_mid, top - 0.5], [u_mid, bottom + 0.5]])) @ T[:3, :3].T
    top_ray, bottom_ray = rays
    # looking down on the top: its silhouette is the far rim of a cylinder's cap
    top_distance = face_m if top_ray[2] > 0 else face_m + 2.0 * radius_m
    z_top = z_at_horizontal_distance(origin, top_ray, top_distance)
    if bottom >= camera.height_px - 1:
        return z_top, "top-above-floor"
    return z_top - z_at_horizontal_distance(origin, bottom_ray, face_m), "top-bottom"


def _ambiguous_end(blob: Blob, camera: CameraModel, face_m: float, top: int, bottom: int, height_m: float,
                   options: ColourOptions) -> str | None:
    """Why the landmark's top or bottom row cannot be trusted, or None when both can.

    - ``"outline"`` (cylinders): more rows between the straight-sided body and the end than its
      rim arc (:func:`rim_arc_rows`) and one anti-aliased row: something of its colour at its
      own depth continues it (a red toy standing on a red cylinder's top), so neither colour nor
      depth tells where the landmark ends.
    - ``"colour_continues"``: the landmark's colour goes on past the end, over at least a third of
      the body's columns (:func:`colour_rows_past`), for more rows than the rim arc and one: the
      end is where the depth changes, which a
      misregistered depth image may put ``erode_px`` rows off; that is given up when those
      rows are more than ``height_precision`` of the height at the landmark's distance.

    The bottom is not looked at when the blob touches the image's bottom (the foot is out of view).
    """
    spec = blob.colour
    left, right = row_extents(blob.mask[top : bottom + 1])
    rows = left >= 0
    widths = right[rows] - left[rows] + 1
    col0, col1 = int(np.median(left[rows])), int(np.median(right[rows]))
    T = camera.T_robot_camera
    u_mid = 0.5 * (blob.left + blob.right)
    rays = camera.rays_camera(np.array([[u_mid, top - 0.5], [u_mid, bottom + 0.5]])) @ T[:3, :3].T
    arcs = [rim_arc_rows(camera.fy, z_at_horizontal_distance(T[:3, 3], ray, face_m) - T[2, 3], face_m,
                         spec.radius_m) for ray in rays]
    ends = [(top, -1, arcs[0])]
    if bottom < camera.height_px - 1:
        ends.append((bottom, 1, arcs[1]))
    if spec.shape == "cylinder":
        outside = rows_outside_body(widths)
        if any(outside[k] > arc + 1 for k, (_, _, arc) in enumerate(ends)):
            return "outline"
    component = blob.mask if blob.component is None else blob.component
    depth_uncertainty_m = options.erode_px * face_m / camera.fy
    for row, step, arc in ends:
        if colour_rows_past(component, row, step, col0, col1) > arc + 1:
            if depth_uncertainty_m > options.height_precision * height_m:
                return "colour_continues"
    return None


def _gheight(blob: Blob, band: np.ndarray, depth_m: np.ndarray, camera: CameraModel,
             options: ColourOptions) -> tuple[float | None, str | None]:
    """Seed 002's gHeight on the depth of the top and bottom rows, as the seed reads them."""
    if blob.top <= 0 or blob.bottom >= camera.height_px - 1:
        return None, "height_cut_off"
    band_rows = np.nonzero(band.any(axis=1))[0]
    k = options.edge_rows
    d_top = _edge_depth(depth_m, band, band_rows, True, k)
    d_bottom = _edge_depth(depth_m, band, band_rows, False, k)
    if not (math.isfinite(d_top) and math.isfinite(d_bottom)):
        return None, "height_no_depth"
    return gheight_seed002(d_top, d_bottom, blob.bottom - blob.top, rows=camera.height_px), "gheight"


def detect_colour_landmarks(bgr: np.ndarray, depth_m: np.ndarray, camera: CameraModel,
                            options: ColourOptions = ColourOptions()
                            ) -> tuple[list[ColourMeasurement], list[ColourRejection], list[Blob]]:
    """Every configured landmark in one frame: measurements, rejected candidates (every one, with
    its reason), and all candidate blobs (for drawing). At most one measurement per colour: when
    several candidates pass, the one whose width fits the landmark best."""
    blobs, _ = find_blobs(bgr, options)
    measured, rejected = [], []
    for colour in options.colours:
        passed = []
        for blob in (b for b in blobs if b.colour is colour):
            result = measure_blob(blob, depth_m, camera, options)
            if isinstance(result, ColourRejection) and result.reason in SPLIT_WHEN:
                parts = [measure_blob(p, depth_m, camera, options) for p in split_by_depth(blob, depth_m)]
                kept = [p for p in parts if isinstance(p, ColourMeasurement)]
                if kept:  # the blob was a landmark and something of its colour behind it
                    passed.extend(kept)
                    continue
            (passed if isinstance(result, ColourMeasurement) else rejected).append(result)
        if passed:
            best = min(passed, key=lambda m: abs(relative_error(m.width_m, colour.width_m)))
            measured.append(ColourMeasurement(
                best.colour, best.landmark_id, best.range_m, best.bearing_rad, best.height_m, best.height_note,
                len(passed) - 1, best.width_m, best.blob))
    return measured, rejected, blobs
