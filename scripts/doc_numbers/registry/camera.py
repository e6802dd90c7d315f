"""docs/camera.md's numbers: the rendered accuracy table, the gHeight sentence, the corner
precision of the real photos and the AprilTag detectors on the NASA photos."""

from __future__ import annotations

from doc_numbers.quotes import Quote, row
from doc_numbers.readers import item, same_row
from doc_numbers.registry.seeds import gheight_range

CAM = "docs/camera.md"

ACCURACY_ROWS = (  # python -m slamio.camera.accuracy, row by row
    "| 0.5 m | 9/9 | 0.02 % | 0.034° | 1.1° | 9/9 | 0.15 % | 0.003° | 0.06 % (3) | 1.58° | — |",
    "| 1.0 m | 9/9 | 0.16 % | 0.005° | 1.0° | 9/9 | 0.11 % | 0.005° | 0.32 % (6) | 2.77° | 12.3 % |",
    "| 1.5 m | 9/9 | 0.07 % | 0.007° | 1.7° | 9/9 | 0.22 % | 0.004° | 0.53 % (9) | 2.85° | 11.6 % |",
    "| 2.0 m | 9/9 | 0.26 % | 0.007° | 5.1° | 9/9 | 0.21 % | 0.001° | 0.25 % (9) | 2.89° | 11.4 % |",
    "| 2.5 m | 9/9 | 0.25 % | 0.007° | 5.5° | 9/9 | 0.14 % | 0.015° | 0.84 % (9) | 2.93° | 11.8 % |",
    "| 3.0 m | 9/9 | 0.22 % | 0.007° | 1.1° | 9/9 | 0.30 % | 0.031° | 1.24 % (9) | 2.94° | 12.7 % |",
    "| 3.5 m | 9/9 | 0.62 % | 0.010° | 0.8° | 9/9 | 0.40 % | 0.012° | 0.72 % (9) | 2.95° | 11.8 % |",
    "| 4.0 m | 9/9 | 0.62 % | 0.005° | 1.1° | 9/9 | 0.36 % | 0.013° | 1.04 % (9) | 2.93° | 12.9 % |",
)

CHOSEN = "apriltag3 decimate 1.0, refine_edges off (chosen)"
DETECTOR_ROWS = (  # camera.md's row (without its times), bench_apriltag.CONFIGS name, index of "found"
    ("| **AprilTag 3, decimate 1.0, refine_edges off (chosen)** | **46/47** | **0** | **0.14 / 0.004 px** |", CHOSEN, 2),
    ("| AprilTag 3, decimate 1.0, refine_edges on | 44/47 | 0 | 2.35 / 0.37 px |",
     "apriltag3 decimate 1.0, refine_edges on", 2),
    ("| AprilTag 3, decimate 1.5, refine_edges on | 37/47 | 1 | 1.97 / 0.40 px |",
     "apriltag3 decimate 1.5, refine_edges on", 2),
    ("| AprilTag 3, decimate 2.0 (the library's default) | 29/47 | 0 | 1.89 / 0.38 px |",
     "apriltag3 decimate 2.0 (library default)", 2),
    ("| cv2.aruco DICT_APRILTAG_36h11, default parameters | 34/47 | 8 | 2.90 / 1.02 px |",
     "cv2.aruco APRILTAG_36h11, default parameters", 0),
    ("| cv2.aruco DICT_APRILTAG_36h11, CORNER_REFINE_APRILTAG | 25/47 | 0 | 0.77 / 0.71 px |",
     "cv2.aruco APRILTAG_36h11, CORNER_REFINE_APRILTAG", 0),
)

QUOTES: list[Quote] = [
    *[q for text in ACCURACY_ROWS for q in same_row(CAM, text, "camera-accuracy", "accuracy table")],
    *row(CAM, "(largest error 11.4–12.9 % per\n   distance at 1–4 m;", "camera-accuracy", "gHeight error range",
         {0: gheight_range(min), 1: gheight_range(max)}),
    *row(CAM, "56 tags: **σ_px = 0.46 px**", "tag-corner-sigma", "real corner sigma",
         {0: lambda r: r[1], 1: lambda r: r[0]}),
    *[q for text, name, first in DETECTOR_ROWS
      for q in row(CAM, text, "apriltag-photos", name, {first + i: item(name, i) for i in range(5)})],
    *row(CAM, "Corners after `refine_tag_corners` differ from the listed ones by 0.30 px on average\n"
         "  (0.96 px at most)", "apriltag-photos", "refined corners", {0: item("refined", 3), 1: item("refined", 2)}),
    *row(CAM, "(oblique, blurred: 5 of the 46 NASA tags)", "apriltag-photos", "tags not refined",
         {0: item("refined", 4), 1: item("refined", 0)}),
]
