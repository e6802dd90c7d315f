"""Pure maths of the colour-landmark checks: what a real landmark's blob must look like.

A blob of the right colour is a landmark only if it also has the landmark's **shape** (how
much of its bounding box it fills), a **consistent depth** (its body is one surface, not a
chair seat running away from the camera), a **physical width** that matches the landmark's
at the measured depth, and, when both ends are in view, the landmark's **height**. These
functions compute the numbers the checks compare; :mod:`slamio.camera.colour` applies them.

Shapes (seed 000's cylinders, seed 002's upright planar circle, triangle and rectangle):

- ``cylinder``: ``width_m`` is the diameter; the measured point is the axis.
- ``circle``, ``triangle``, ``rectangle``: a flat board standing upright and facing the
  camera; ``width_m`` is the circle's diameter, the triangle's base or the rectangle's width;
  the measured point is the board's face.
"""

from __future__ import annotations

import math

import numpy as np

SHAPES = ("cylinder", "circle", "triangle", "rectangle")

#: Area / bounding-box area of a shape's silhouette seen face-on (a circle π/4 = 0.785, a
#: triangle 0.5), with room for anti-aliased edges, shading and a slightly turned board.
FILL_RATIO_RANGE = {
    "cylinder": (0.70, 1.0),
    "rectangle": (0.80, 1.0),
    "circle": (0.66, 0.90),
    "triangle": (0.36, 0.64),
}

#: Kinect v1 depth step per m² of depth: d(depth)/d(raw) = −a·depth² with Burrus's a.
KINECT_DEPTH_STEP_PER_M2 = 0.0030711016


def fill_ratio(area_px: int, width_px: int, height_px: int) -> float:
    """Fraction of the bounding box covered by the blob."""
    return area_px / float(max(1, width_px * height_px))


def shape_fits(shape: str, fill: float) -> bool:
    lo, hi = FILL_RATIO_RANGE[shape]
    return lo <= fill <= hi


#: Shapes with vertical sides: every row of the silhouette about as wide as the median row.
STRAIGHT_SIDED = ("cylinder", "rectangle")


def uneven_row_fraction(mask: np.ndarray, min_px: float = 2.0, relative: float = 0.2) -> float:
    """Fraction of the mask's rows whose extent differs from the median row's by more than
    max(``min_px``, ``relative`` × median): a straight-sided landmark merged with another blob of
    its colour sticks out in some rows."""
    rows = np.nonzero(mask.any(axis=1))[0]
    if len(rows) == 0:
        return 1.0
    sub = mask[rows]
    left = np.argmax(sub, axis=1)
    right = sub.shape[1] - 1 - np.argmax(sub[:, ::-1], axis=1)
    widths = right - left + 1
    median = float(np.median(widths))
    return float(np.mean(np.abs(widths - median) > max(min_px, relative * median)))


def width_from_silhouette_m(shape: str, angle_rad: float, face_distance_m: float) -> float:
    """Physical width of a landmark whose silhouette spans ``angle_rad`` seen from the camera.

    ``face_distance_m`` is the horizontal distance from the lens to the face nearest the
    camera. A cylinder of radius R whose axis is D away spans 2·asin(R/D) and its face is
    D − R away, so R = f·s/(1 − s) with s = sin(angle/2). A board facing the camera spans
    2·atan(w/2 / f).
    """
    half = 0.5 * abs(angle_rad)
    if shape == "cylinder":
        s = math.sin(half)
        return 2.0 * face_distance_m * s / max(1e-9, 1.0 - s)
    return 2.0 * face_distance_m * math.tan(half)


def kinect_depth_step_m(depth_m: float) -> float:
    """The Kinect v1's depth quantisation step at this depth (3 mm at 1 m, 49 mm at 4 m)."""
    return KINECT_DEPTH_STEP_PER_M2 * depth_m * depth_m


def allowed_depth_deviation_m(width_m: float, distance_m: float, base_m: float) -> float:
    """How far from the face's median distance a pixel of a landmark's body may lie.

    A cylinder's front half spans its radius in depth; a board turned by up to 30° spans
    half its width. On top: ``base_m`` for noise and two Kinect depth steps.
    """
    return 0.5 * width_m + base_m + 2.0 * kinect_depth_step_m(distance_m)


def outlier_fraction(values: np.ndarray, centre: float, allowed: float) -> float:
    """Fraction of values farther than ``allowed`` from ``centre``."""
    return float(np.mean(np.abs(values - centre) > allowed)) if len(values) else 1.0


def relative_error(measured: float, expected: float) -> float:
    return (measured - expected) / expected


def z_at_horizontal_distance(origin: np.ndarray, ray: np.ndarray, distance_m: float) -> float:
    """Height of the point of the ray ``origin + t·ray`` that is ``distance_m`` away horizontally."""
    horizontal = math.hypot(float(ray[0]), float(ray[1]))
    return float(origin[2] + ray[2] * distance_m / max(horizontal, 1e-12))


# --------------------------------------------------------------------------- where a landmark ends


def row_extents(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Leftmost and rightmost column of each row of a mask (−1, −1 for an empty row)."""
    filled = mask.any(axis=1)
    left = np.where(filled, np.argmax(mask, axis=1), -1)
    right = np.where(filled, mask.shape[1] - 1 - np.argmax(mask[:, ::-1], axis=1), -1)
    return left, right


def rim_arc_rows(fy_px: float, dz_m: float, face_m: float, radius_m: float) -> float:
    """How many rows a cylinder's rim rises (or sinks) past its straight sides in the image.

    A level camera sees the rim ``dz_m`` above (below) the lens as an arc: its apex, on the face
    ``face_m`` away, is fy·dz/f from the horizon; the silhouette's sides touch the rim at depth
    D − R²/D (D = f + R), fy·dz·D/(D² − R²) from it. The difference is fy·|dz|·R/(D² − R²):
    12 rows for the top of a 0.8 m cylinder at 1 m with the lens at 0.3 m, under a row at 4 m.
    """
    distance = face_m + radius_m
    return fy_px * abs(dz_m) * radius_m / max(distance * distance - radius_m * radius_m, 1e-12)


def colour_rows_past(mask: np.ndarray, row: int, step: int, col0: int, col1: int, fraction: float = 1 / 3) -> int:
    """How many rows of ``mask`` past ``row`` (walking by ``step``, ±1), without a gap, fill at least
    ``fraction`` of columns ``col0``..``col1``: the landmark's colour continuing across that end
    as wide as a body could (a thinner thing touching it — a picture frame's corner — cannot
    be the landmark going on, and the colour alone tells where the landmark ends)."""
    need = fraction * (col1 - col0 + 1)
    count, v = 0, row + step
    while 0 <= v < mask.shape[0] and mask[v, col0 : col1 + 1].sum() >= need:
        count += 1
        v += step
    return count


def rows_outside_body(widths: np.ndarray, min_px: float = 2.0, relative: float = 0.2) -> tuple[int, int]:
    """Rows at the top and at the bottom of a silhouette (row widths, top to bottom) before its
    first and after its last row as wide as the median row (within max(``min_px``, ``relative`` ×
    median), as :func:`uneven_row_fraction`): a cylinder's are its rim arcs, a few rows at most."""
    median = float(np.median(widths))
    body = np.nonzero(np.abs(widths - median) <= max(min_px, relative * median))[0]
    if len(body) == 0:
        return len(widths), len(widths)
    return int(body[0]), int(len(widths) - 1 - body[-1])
