"""Build the union listing of the NASA AprilTag photos: every tag that any of eight detector set-ups finds.

The NASA photos' own listing (``nasa_*.txt``) was made by the AprilTag 3 reference detector
at decimate 1 without edge refinement — the front-end's AprilTag 3 pass at the camera's
resolution — so it cannot show what that detector misses. This script runs eight set-ups on the three photos, merges their
detections by id and centre (``slamio.camera.tag_union``), adds the reference listing's tags
and the tags listed in ``SEEN_BY_EYE``, and writes
``tests/data/apriltag-photos/nasa_union.txt``.

Recall is counted over the tags that at least one of the eight set-ups finds (61); the
reference listing has one more (a 12-pixel tag none of the eight decodes) and
``SEEN_BY_EYE`` holds six real tags (cube sides seen edge-on, 11-pixel tags far away) that
other detector settings tried while choosing the front-end decoded (each named) and that no
set-up finds. Finding those is not a false detection. Every tag of the listing was checked
by eye on an enlarged crop with the detected outline drawn.

Usage: ``.venv/bin/python -m scripts.apriltag_union [--photos DIR] [--out FILE]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2  # noqa: E402

from slamio.camera.accuracy import read_corner_list  # noqa: E402
from slamio.camera.apriltag import AprilTagDetector  # noqa: E402
from slamio.camera.tag_union import ListedTag, add_detections, write_union  # noqa: E402
from scripts.common import APRILTAG_PHOTOS  # noqa: E402

PHOTOS = APRILTAG_PHOTOS

#: The eight set-ups, by the name the listing's "found by" column uses.
SETUPS = {
    "apriltag3": dict(),  # decimate 1, refine_edges off: the single pass at the camera's resolution
    "apriltag3-edges": dict(refine_edges=True),
    "apriltag3-decimate2": dict(quad_decimate=2.0, refine_edges=True),  # the library's default
    "apriltag3-sigma0.8": dict(quad_sigma=0.8),
    "apriltag3-up2": dict(upsample=2.0),
    "aruco": dict(backend="aruco", aruco_refinement="none"),
    "aruco-apriltag": dict(backend="aruco", aruco_refinement="apriltag"),
    "aruco-up2": dict(backend="aruco", aruco_refinement="none", upsample=2.0),
}

#: Real tags none of the eight set-ups finds, decoded by other detector settings (named) and
#: checked by eye: (image, centre x, centre y, side px, the settings that decoded it).
SEEN_BY_EYE = [
    ("nasa_33369213973_9d9bb4cc96_c.jpg", 687.25, 441.50, 24.0, "aruco, one 5 px window"),
    ("nasa_34085369442_304b6bafd9_c.jpg", 445.96, 84.95, 10.9, "apriltag3, quad_sigma -0.8"),
    ("nasa_34085369442_304b6bafd9_c.jpg", 609.79, 105.00, 11.4, "apriltag3, quad_sigma -0.8"),
    ("nasa_34139872896_defdb2f8d9_c.jpg", 228.84, 395.44, 27.7, "apriltag3, quad_sigma -0.8"),
    ("nasa_34139872896_defdb2f8d9_c.jpg", 271.38, 418.01, 28.0, "apriltag3 upsampled 2.5x"),
    ("nasa_34139872896_defdb2f8d9_c.jpg", 361.97, 427.54, 28.0, "apriltag3, quad_sigma -0.8"),
]

HEADER = """\
Every tag36h11 tag found on the three NASA photos by any of eight detector set-ups, made by
scripts/apriltag_union.py (pupil-apriltags 1.0.4, OpenCV {cv2}):
  apriltag3           AprilTag 3 (pupil-apriltags), decimate 1, refine_edges off
  apriltag3-edges     the same with refine_edges on
  apriltag3-decimate2 decimate 2, refine_edges on (the library's default)
  apriltag3-sigma0.8  decimate 1, quad_sigma 0.8
  apriltag3-up2       decimate 1 on the image enlarged 2x (bilinear)
  aruco               cv2.aruco DICT_APRILTAG_36h11, no corner refinement
  aruco-apriltag      cv2.aruco with CORNER_REFINE_APRILTAG
  aruco-up2           cv2.aruco, no refinement, on the image enlarged 2x
plus "reference": the photos' own listing (nasa_*.txt, the AprilTag 3 reference detector),
and "seen-by-eye": real tags that none of these finds, decoded by other detector settings
(SEEN_BY_EYE in the script). Every tag here was checked by eye on an enlarged crop.
Recall is counted over the tags that one of the eight set-ups finds.
Same tag: same id, centres within max(3 px, 0.3 x side). Centres: OpenCV pixel convention.
Photos: NASA Swarmathon at KSC, CC BY-SA 2.0 (see nasa_README.md)."""


def build(photos: Path) -> list[ListedTag]:
    union: list[ListedTag] = []
    images = sorted(photos.glob("nasa_*.jpg"))
    for name, settings in SETUPS.items():
        detector = AprilTagDetector(**settings)
        for path in images:
            grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            add_detections(union, path.name, [(d.tag_id, d.centre_px, d.side_px) for d in detector.detect(grey)], name)
    for path in images:
        listed = read_corner_list(path.with_suffix(".txt"))
        add_detections(union, path.name, [(i, c.mean(axis=0), _side(c)) for i, c in listed], "reference")
    for image, x, y, side, _ in SEEN_BY_EYE:
        add_detections(union, image, [(0, (x, y), side)], "seen-by-eye")
    return union


def _side(corners):
    import numpy as np

    return float(np.mean(np.linalg.norm(corners - np.roll(corners, -1, axis=0), axis=1)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--photos", default=str(PHOTOS), help="the apriltag-photos folder")
    parser.add_argument("--out", default=str(PHOTOS / "nasa_union.txt"), help="the listing to write")
    args = parser.parse_args(argv)
    union = build(Path(args.photos))
    write_union(args.out, union, HEADER.format(cv2=cv2.__version__))
    counted = sum(1 for t in union if set(t.found_by) & set(SETUPS))
    print(f"{len(union)} tags written to {args.out}; {counted} found by at least one of the eight set-ups")
    for name in list(SETUPS) + ["reference", "seen-by-eye"]:
        print(f"  {name:20} {sum(1 for t in union if name in t.found_by):3}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
