"""Identify cv2.aruco's tag candidates against a whole AprilTag family in one array operation.

Why this is written here: OpenCV's aruco detector compares each candidate quad with every
code of the dictionary, one code and one C++ call at a time. For tag36h11 (587 codes, four
rotations each) that costs about 0.6 ms per candidate on this project's machine: on the
tag-dense NASA frames 20–30 candidates made the front-end's aruco pass 12–31 ms, against
about 2 ms to find the candidates themselves (measured with a dictionary of ten codes).

So :class:`ArucoCandidates` asks OpenCV only for the candidates — its detector with a
one-code dictionary that no real candidate matches, which hands every quad back as
"rejected" — and :func:`identify_quads` decides them all at once with OpenCV's own rules:

- the quad is warped to an 8 × 8-cell square (tag36h11: 6 × 6 data cells and a one-cell black
  border), ``pixels_per_cell`` pixels a side, nearest-neighbour, black outside the image;
- if the grey levels inside half a cell of the square's edge vary by less than
  ``min_otsu_std`` (5 grey levels), every cell is black or white by the mean; otherwise the
  square is binarised at its Otsu threshold and each cell's value is its share of white pixels;
- a cell reads 0 when its share is at most ``valid_bit_threshold`` (0.49) and 1 when at least
  1 − 0.49: a cell of half and half is wrong whatever the code says;
- more than ``max_border_rate`` × 36 (12) white border cells reject the quad;
- the tag is the first code of the dictionary, in id order, whose best rotation has at most
  ``error_correction_rate`` × the family's correctable bits (0.6 × 5 → 3) wrong cells, and
  the quad's corners are turned by that rotation so that the first is the upright tag's
  top-left.

This holds for one adaptive-threshold window: with several, OpenCV groups the candidates
the windows find of one tag and tries them in turn, and hands back only some of a group
it could not identify, so the detector uses this module only with one window (and without
corner refinement, which OpenCV applies to the tags it identified).

On the project's real photos (three NASA photos, their nine 640 × 480 crops, eleven
robot-camera photos) this returns exactly the tags and corners of OpenCV's own
identification (``tests/test_aruco_codes.py``), and the aruco pass costs 3–10 ms instead of
5–27 ms.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: OpenCV's DetectorParameters defaults that the identification uses.
PIXELS_PER_CELL = 4
MIN_OTSU_STD = 5.0
VALID_BIT_THRESHOLD = 0.49
MAX_BORDER_RATE = 0.35
ERROR_CORRECTION_RATE = 0.6


@dataclass(frozen=True)
class FamilyCodes:
    """A dictionary's codes as integers: ``codes[id, rotation]``, the data cells read row by
    row (first cell in the highest bit), and what identification needs besides."""

    codes: np.ndarray  # (n_ids, 4) uint64
    marker_cells: int  # data cells a side (6 for tag36h11)
    correctable_bits: int  # the dictionary's maxCorrectionBits


def cell_weights(n_cells: int) -> np.ndarray:
    """The bit value of each of ``n_cells`` cells read row by row, the first in the highest bit."""
    return np.left_shift(np.uint64(1), np.arange(n_cells - 1, -1, -1, dtype=np.uint64))


@lru_cache(maxsize=None)
def family_codes(dictionary_name: str) -> FamilyCodes:
    """The codes of OpenCV's predefined dictionary ``dictionary_name`` (e.g. "DICT_APRILTAG_36h11").

    OpenCV keeps each code's four rotations one after the other in its row of ``bytesList``;
    each is unpacked with OpenCV's own ``getBitsFromByteList`` (which reads the first)."""
    import cv2

    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary_name))
    size = int(dictionary.markerSize)
    rows = np.ascontiguousarray(dictionary.bytesList).reshape(len(dictionary.bytesList), -1)
    per_rotation = rows.shape[1] // 4
    weights = cell_weights(size * size)
    codes = np.zeros((len(rows), 4), dtype=np.uint64)
    for index, row in enumerate(rows):
        for rotation in range(4):
            first = np.roll(row, -per_rotation * rotation).reshape(1, per_rotation, 4)
            bits = cv2.aruco.Dictionary.getBitsFromByteList(first, size).ravel().astype(np.uint64)
            codes[index, rotation] = np.sum(bits * weights, dtype=np.uint64)
    return FamilyCodes(codes, size, int(dictionary.maxCorrectionBits))


def otsu_thresholds(patches: np.ndarray) -> np.ndarray:
    """Otsu's threshold of each uint8 patch (n, h, w): a pixel above it is white, as
    ``cv2.threshold(..., THRESH_OTSU)`` (the first grey level of largest between-class variance)."""
    n = len(patches)
    flat = patches.reshape(n, -1).astype(np.int64)
    hist = np.bincount((flat + 256 * np.arange(n)[:, None]).ravel(), minlength=256 * n).reshape(n, 256)
    p = hist / flat.shape[1]
    below = np.cumsum(p, axis=1)  # share at or below each level
    mean_below = np.cumsum(p * np.arange(256), axis=1)
    total_mean = mean_below[:, -1:]
    above = 1.0 - below
    eps = np.finfo(np.float32).eps
    usable = (np.minimum(below, above) >= eps) & (np.maximum(below, above) <= 1.0 - eps)
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (total_mean * below - mean_below) ** 2 / (below * above)
    between = np.where(usable, between, -1.0)
    return np.argmax(between, axis=1)


def warp_quads(grey: np.ndarray, quads: np.ndarray, side_px: int) -> np.ndarray:
    """Each quad (n, 4, 2; clockwise from the corner that becomes the top-left) warped to a
    ``side_px`` square, nearest-neighbour, black outside the image: what
    ``cv2.warpPerspective(..., INTER_NEAREST)`` with ``cv2.getPerspectiveTransform`` gives."""
    import cv2

    last = float(side_px - 1)
    square = np.float32([[0, 0], [last, 0], [last, last], [0, last]])
    to_image = np.stack([cv2.getPerspectiveTransform(square, q.astype(np.float32)) for q in quads])
    ys, xs = np.mgrid[0:side_px, 0:side_px]
    grid = np.stack([xs.ravel(), ys.ravel(), np.ones(side_px * side_px)])  # (3, side²)
    mapped = to_image @ grid  # (n, 3, side²)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.rint(mapped[:, 0] / mapped[:, 2])
        v = np.rint(mapped[:, 1] / mapped[:, 2])
    h, w = grey.shape
    inside = np.isfinite(u) & np.isfinite(v) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    values = np.zeros(u.shape, dtype=np.uint8)
    values[inside] = grey[v[inside].astype(np.intp), u[inside].astype(np.intp)]
    return values.reshape(len(quads), side_px, side_px)


def cell_white_shares(patches: np.ndarray, pixels_per_cell: int, min_otsu_std: float = MIN_OTSU_STD) -> np.ndarray:
    """Share of white pixels per cell of each warped square (n, cells, cells)."""
    n, side, _ = patches.shape
    cells = side // pixels_per_cell
    half = pixels_per_cell // 2
    inner = patches[:, half:side - half, half:side - half].reshape(n, -1).astype(float)
    flat = inner.std(axis=1) < min_otsu_std
    white = patches > otsu_thresholds(patches)[:, None, None]
    shares = white.reshape(n, cells, pixels_per_cell, cells, pixels_per_cell).mean(axis=(2, 4))
    shares[flat] = (inner[flat].mean(axis=1) > 127)[:, None, None].astype(float)
    return shares


def popcount(values: np.ndarray) -> np.ndarray:
    """Set bits of each uint64."""
    if hasattr(np, "bitwise_count"):  # numpy >= 2.0
        return np.bitwise_count(values)
    table = np.array([bin(i).count("1") for i in range(256)], dtype=np.uint8)
    return table[values.view(np.uint8)].reshape(values.shape + (8,)).sum(axis=-1)


def identify_quads(grey: np.ndarray, quads: np.ndarray, family: FamilyCodes, *,
                   pixels_per_cell: int = PIXELS_PER_CELL, min_otsu_std: float = MIN_OTSU_STD,
                   valid_bit_threshold: float = VALID_BIT_THRESHOLD, max_border_rate: float = MAX_BORDER_RATE,
                   error_correction_rate: float = ERROR_CORRECTION_RATE) -> list[tuple[int, np.ndarray]]:
    """(tag id, corners 4 × 2 with the upright tag's top-left first) for each quad that is a tag
    of ``family``, by OpenCV's identification rules (module docstring)."""
    quads = np.asarray(quads, dtype=float).reshape(-1, 4, 2)
    if len(quads) == 0:
        return []
    size = family.marker_cells
    shares = cell_white_shares(warp_quads(grey, quads, (size + 2) * pixels_per_cell), pixels_per_cell, min_otsu_std)
    border = np.concatenate([shares[:, 0, :], shares[:, -1, :], shares[:, 1:-1, 0], shares[:, 1:-1, -1]], axis=1)
    border_ok = np.sum(border > valid_bit_threshold, axis=1) <= int(size * size * max_border_rate)
    data = shares[:, 1:-1, 1:-1].reshape(len(quads), -1)
    weights = cell_weights(size * size)
    not_black = np.sum((data > valid_bit_threshold) * weights, axis=1, dtype=np.uint64)
    not_white = np.sum((data < 1.0 - valid_bit_threshold) * weights, axis=1, dtype=np.uint64)
    # a cell is wrong where the code says 0 and it is not black, or 1 and it is not white
    wrong = not_black[:, None, None] ^ ((not_black ^ not_white)[:, None, None] & family.codes[None])
    errors = popcount(wrong)  # (n, ids, 4)
    allowed = int(family.correctable_bits * error_correction_rate)
    fits = errors.min(axis=2) <= allowed
    out = []
    for k in np.flatnonzero(border_ok & fits.any(axis=1)):
        tag_id = int(np.argmax(fits[k]))
        rotation = int(np.argmin(errors[k, tag_id]))
        out.append((tag_id, np.roll(quads[k], rotation, axis=0)))
    return out


class ArucoCandidates:
    """cv2.aruco's quad candidates of an image, with ``parameters`` (a ``cv2.aruco.DetectorParameters``):
    its detector with a one-code dictionary (every data cell black, no correction), so that the
    candidates come back unidentified; a black square that matches that code comes back too."""

    def __init__(self, parameters, marker_cells: int):
        import cv2

        blank = cv2.aruco.Dictionary(np.zeros((1, (marker_cells * marker_cells + 7) // 8, 4), np.uint8), marker_cells, 0)
        self._detector = cv2.aruco.ArucoDetector(blank, parameters)

    def quads(self, grey: np.ndarray) -> np.ndarray:
        """Candidate corners (n, 4, 2) in pixels."""
        matched, _, rejected = self._detector.detectMarkers(grey)
        found = [np.asarray(c, dtype=float).reshape(4, 2) for c in (*matched, *rejected)]
        return np.array(found).reshape(-1, 4, 2)
