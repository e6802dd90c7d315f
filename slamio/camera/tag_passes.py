"""The front-end's AprilTag detector: AprilTag 3 on the enlarged image, then cv2.aruco for what it missed.

Measured on the NASA photos against every tag that any of eight detector set-ups finds (61,
``tests/data/apriltag-photos/nasa_union.txt``; ``scripts/bench_apriltag.py``, docs/camera.md):

- AprilTag 3 at the camera's resolution (decimate 1, no edge refinement) finds 46. It misses
  tags of 11–17 pixels and tags seen so obliquely that their black border is a pixel thin:
  its quad search does not even find their outlines (its own quads cover 1 of the 16 it
  misses), so a second pass around its failed quads has nothing to work on.
- The same detector on the image **enlarged 1.75×** (bilinear) finds 51 (2×: 53), and
- **cv2.aruco** with one 3-pixel adaptive-threshold window and candidates of at least a
  tenth of the image's side in perimeter, its candidates identified by
  :mod:`slamio.camera.aruco_codes` — cheap: 0.15–0.3 of the single pass's time —
  decodes tags on cube tops and sides that AprilTag 3 rejects at any scale.
- Enlarged, AprilTag 3's quad thresholds are raised (40 grey levels of tile contrast, 40 edge
  pixels per candidate, :data:`ENLARGED_MIN_WHITE_BLACK_DIFF`): fine texture stops making
  thousands of candidates, the pass costs 1.2–1.5× the single pass instead of 2.1–2.4× and
  finds the same tags.

Together: 57 of 61 (2×: 59), none outside the union, at 1.3–1.5× the CPU time of the single
pass at the camera's resolution (2×: 1.5×), one thread: 16–24 ms per 640×480 frame on the
median frame of this project's shared 2-core machine, 21–31 ms on tag-dense frames of gravel
(worst 30–39 ms), where the enlarged pass takes most and the aruco pass 4–6 ms.

Tags found by the first pass keep its corners; the second pass only adds tags whose centre is
not within half a side of one already found. The front-end refines every tag's corners on the
original image afterwards (``refine_tag_corners``), whichever pass found it.
"""

from __future__ import annotations

import numpy as np

from slamio.camera.apriltag import ARUCO_DICTIONARIES, AprilTagDetector, TagDetection, TagDetectorError

#: Second passes the front-end knows.
SECOND_PASSES = ("aruco", "none")


class TagPasses:
    """Detectors run in turn; a later one adds only tags that no earlier one found."""

    def __init__(self, detectors: list[AprilTagDetector]):
        if not detectors:
            raise ValueError("need at least one detector")
        self.detectors = list(detectors)
        self.family = detectors[0].family

    def detect(self, grey: np.ndarray) -> list[TagDetection]:
        """Tags in a 2-D uint8 image, sorted by id (corners as :meth:`AprilTagDetector.detect`)."""
        found: list[TagDetection] = []
        for detector in self.detectors:
            for tag in detector.detect(grey):
                if not already_found(tag, found):
                    found.append(tag)
        found.sort(key=lambda t: (t.tag_id, float(t.centre_px[0])))
        return found


def already_found(tag: TagDetection, found: list[TagDetection]) -> bool:
    """True when ``tag``'s centre is within half a side of the centre of one of the ``found`` tags
    (the same tag). One array operation over ``found``: a tag-dense frame compares hundreds of pairs."""
    if not found:
        return False
    centres = np.array([other.centre_px for other in found])
    half_sides = 0.5 * np.array([other.side_px for other in found])
    return bool(np.any(np.hypot(*(centres - tag.centre_px).T) < half_sides))


#: AprilTag 3's quad-threshold parameters for the enlarged pass (the library's defaults: 5, 5): tiles
#: of less contrast than this are not thresholded, and quad candidates need this many edge pixels.
#: Gravel, grass and carpet stop making thousands of candidates; the tags the pass finds stay.
ENLARGED_MIN_WHITE_BLACK_DIFF = 40
ENLARGED_MIN_CLUSTER_PIXELS = 40


def front_end_detector(family: str = "tag36h11", *, upsample: float = 1.75, second_pass: str = "aruco",
                       quad_decimate: float = 1.0, refine_edges: bool = False, nthreads: int = 1) -> TagPasses:
    """The front-end's detector: AprilTag 3 on the image enlarged ``upsample`` times, then the second pass.

    Enlarged, AprilTag 3 ignores low-contrast tiles and small quad candidates
    (``ENLARGED_MIN_WHITE_BLACK_DIFF``, ``ENLARGED_MIN_CLUSTER_PIXELS``); at the camera's
    resolution (``upsample`` 1) it keeps the library's defaults.

    The aruco pass needs OpenCV's dictionary of the family (tag36h11, tag36h10, tag25h9,
    tag16h5); for other families AprilTag 3 runs alone."""
    if second_pass not in SECOND_PASSES:
        raise TagDetectorError(f"unknown second pass {second_pass!r}; use one of {', '.join(SECOND_PASSES)}")
    thresholds = {}
    if upsample > 1.0:
        thresholds = dict(min_white_black_diff=ENLARGED_MIN_WHITE_BLACK_DIFF,
                          min_cluster_pixels=ENLARGED_MIN_CLUSTER_PIXELS)
    passes = [AprilTagDetector(family, quad_decimate=quad_decimate, refine_edges=refine_edges, nthreads=nthreads,
                               upsample=upsample, **thresholds)]
    if second_pass == "aruco" and family in ARUCO_DICTIONARIES:
        passes.append(AprilTagDetector(family, backend="aruco", aruco_refinement="none", aruco_window_px=3,
                                       aruco_min_perimeter=0.1))
    return TagPasses(passes)
