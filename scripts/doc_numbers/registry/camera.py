"""docs/results-camera.md's numbers (split from docs/camera.md, which keeps two): the rendered
accuracy table, the gHeight sentence, the corner precision of the real photos and the AprilTag detectors on the NASA photos and rendered tags
(``scripts/bench_apriltag.py`` without its times)."""

from __future__ import annotations

from scripts.doc_numbers.quotes import Quote, numbers_in, row
from scripts.doc_numbers.readers import item, same_row
from scripts.doc_numbers.registry.seeds import gheight_range

CAM = "docs/results-camera.md"  # the measured sections, split from docs/camera.md
CAM_USER = "docs/camera.md"  # the user's page keeps a few numbers

ACCURACY_ROWS = (  # python -m slamio.camera.accuracy, row by row
    "| 0.5 m | 9/9 | 0.02 % | 0.034° | 1.1° | 9/9 | 0.15 % | 0.003° | 0.06 % (3) | 1.58° | — |",
    "| 1.0 m | 9/9 | 0.16 % | 0.005° | 1.0° | 9/9 | 0.11 % | 0.005° | 0.32 % (6) | 2.77° | 12.3 % |",
    "| 1.5 m | 9/9 | 0.08 % | 0.007° | 1.7° | 9/9 | 0.22 % | 0.004° | 0.53 % (9) | 2.85° | 11.6 % |",
    "| 2.0 m | 9/9 | 0.26 % | 0.007° | 5.1° | 9/9 | 0.21 % | 0.001° | 0.25 % (9) | 2.89° | 11.4 % |",
    "| 2.5 m | 9/9 | 0.25 % | 0.007° | 5.6° | 9/9 | 0.14 % | 0.015° | 0.84 % (9) | 2.93° | 11.8 % |",
    "| 3.0 m | 9/9 | 0.20 % | 0.007° | 1.1° | 9/9 | 0.30 % | 0.031° | 1.24 % (9) | 2.94° | 12.7 % |",
    "| 3.5 m | 9/9 | 0.63 % | 0.010° | 0.9° | 9/9 | 0.40 % | 0.012° | 0.72 % (9) | 2.95° | 11.8 % |",
    "| 4.0 m | 9/9 | 0.62 % | 0.005° | 1.1° | 9/9 | 0.36 % | 0.013° | 1.04 % (9) | 2.93° | 12.9 % |",
)

# bench_apriltag.CONFIGS names of the detectors the docs name in prose
SINGLE = "apriltag3 decimate 1, refine_edges off (single pass)"
CHOSEN = "apriltag3 upsampled 1.75x, white-black 40, cluster 40 + cv2.aruco 3 px (front-end)"
ENLARGED_ARUCO = "apriltag3 upsampled 1.75x + cv2.aruco 3 px"  # the same with the library's quad thresholds
SINGLE_ARUCO = "apriltag3 first pass + cv2.aruco 3 px"
TWICE_ARUCO = "apriltag3 upsampled 2x + cv2.aruco 3 px"

#: The columns of the detector table after the detector, as the source names them.
COLUMNS = "union not_in_union reference rendered rendered_frames rendered_max rendered_mean"
NO_CORNERS = "union not_in_union reference rendered rendered_frames"  # rows that give no corner errors
SEEN_BY_EYE = "union not_in_union outside_counted reference rendered rendered_frames rendered_max rendered_mean"

DETECTOR_ROWS = (  # camera.md's row up to its times, bench_apriltag.CONFIGS name, its numbers after the detector
    ("| AprilTag 3, decimate 1, refine_edges off (the single pass) | 46 | 0 | 46 | 59/63, 0.65 / 0.37 px |",
     SINGLE, COLUMNS),
    ("| AprilTag 3, refine_edges on | 44 | 0 | 44 | 61/63, 0.39 / 0.23 px |",
     "apriltag3 decimate 1, refine_edges on", COLUMNS),
    ("| AprilTag 3, decimate 2 (the library's default) | 29 | 0 | 29 | 46/63, 0.69 / 0.27 px |",
     "apriltag3 decimate 2 (library default)", COLUMNS),
    ("| AprilTag 3, quad_sigma −0.8 (sharpening) | 46 | 0 (+4 seen by eye) | 44 | 59/63, 0.65 / 0.38 px |",
     "apriltag3 decimate 1, quad_sigma -0.8 (sharpen)", SEEN_BY_EYE),
    ("| AprilTag 3 on the image enlarged 1.5× | 47 | 0 (+1) | 44 | 61/63, 0.42 / 0.24 px |",
     "apriltag3 on the image upsampled 1.5x", SEEN_BY_EYE),
    ("| AprilTag 3 enlarged 1.75× | 51 | 0 | 45 | 61/63, 0.46 / 0.26 px |",
     "apriltag3 on the image upsampled 1.75x", COLUMNS),
    ("| AprilTag 3 enlarged 2× | 53 | 0 | 45 | 60/63, 0.42 / 0.19 px |",
     "apriltag3 on the image upsampled 2x", COLUMNS),
    ("| single pass, then enlarged 2× | 54 | 0 | 46 | 60/63 |", "apriltag3 first pass + upsampled 2x", NO_CORNERS),
    ("| cv2.aruco, no corner refinement (three threshold windows) | 42 | 0 | 34 | 53/63, 1.36 / 0.74 px |",
     "cv2.aruco, no corner refinement", COLUMNS),
    ("| cv2.aruco, CORNER_REFINE_APRILTAG | 25 | 0 | 25 | 32/63, 1.05 / 0.81 px |",
     "cv2.aruco, CORNER_REFINE_APRILTAG", COLUMNS),
    ("| cv2.aruco, one 3 px window, perimeter ≥ 0.1 × image side | 24 | 0 | 18 | 37/63, 1.06 / 0.75 px |",
     "cv2.aruco, one 3 px window, perimeter >= 0.1", COLUMNS),
    ("| single pass, then that aruco | 52 | 0 | 46 | 59/63 |", SINGLE_ARUCO, NO_CORNERS),
    ("| AprilTag 3 enlarged 1.75×, then that aruco | 57 | 0 | 45 | 61/63, 0.46 / 0.26 px |", ENLARGED_ARUCO, COLUMNS),
    ("| AprilTag 3 enlarged 1.75×, quad thresholds 20 / 40 | 51 | 0 | 45 | 61/63, 0.46 / 0.26 px |",
     "apriltag3 upsampled 1.75x, white-black 20, cluster 40", COLUMNS),
    ("| AprilTag 3 enlarged 1.75×, quad thresholds 40 / 40 | 51 | 0 | 45 | 61/63, 0.46 / 0.26 px |",
     "apriltag3 upsampled 1.75x, white-black 40, cluster 40", COLUMNS),
    ("| AprilTag 3 enlarged 1.75×, quad thresholds 60 / 60 | 51 | 0 | 45 | 61/63, 0.46 / 0.26 px |",
     "apriltag3 upsampled 1.75x, white-black 60, cluster 60", COLUMNS),
    ("| **AprilTag 3 enlarged 1.75×, quad thresholds 40 / 40, then that aruco (chosen)** | **57** | **0** | **45** | "
     "**61/63, 0.46 / 0.26 px** |", CHOSEN, COLUMNS),
    ("| AprilTag 3 enlarged 2×, quad thresholds 40 / 40, then that aruco | 59 | 0 | 45 | 60/63, 0.42 / 0.19 px |",
     "apriltag3 upsampled 2x, white-black 40, cluster 40 + cv2.aruco 3 px", COLUMNS),
    ("| AprilTag 3 enlarged 2×, then that aruco | 59 | 0 | 45 | 60/63, 0.42 / 0.19 px |", TWICE_ARUCO, COLUMNS),
    ("| AprilTag 3 enlarged 2×, then aruco with three windows | 60 | 0 | 46 | 61/63 |",
     "apriltag3 upsampled 2x + cv2.aruco", NO_CORNERS),
)


def detector_row(text: str, name: str, columns: str) -> list[Quote]:
    """The quotes of one row of the detector table: the numbers after its first cell, in order,
    are the source's ``columns`` (space-separated keys) of CONFIGS entry ``name``."""
    first = len(numbers_in(text.split("|")[1]))  # numbers in the detector's own name
    return row(CAM, text, "apriltag-photos", name,
               {first + i: item(name, key) for i, key in enumerate(columns.split())})


def missed_by(name: str):
    """How many tags of the counted union ``name`` misses."""
    return lambda result: result[name]["counted"] - result[name]["union"]


DETECTOR_PROSE = [
    *row(CAM, "| detector | union (61) | not in union | reference (47) |", "apriltag-photos", "table header",
         {0: item(SINGLE, "counted"), 1: item(SINGLE, "listed")}),
    *row(CAM, "the NASA photos, 9.8 tags per frame", "apriltag-photos", "tags per timing frame",
         {0: item("timing frames", "tags_per_frame")}),
    *row(CAM, "on those frames with 9.8 tags each", "apriltag-photos", "tags per timing frame (front-end time)",
         {0: item("timing frames", "tags_per_frame")}),
    *row(CAM_USER, "(oblique, blurred: 10 of the 57 NASA tags found)", "apriltag-photos", "front-end tags not refined",
         {0: item("refined", "kept"), 1: item("refined", "detections")}),
    *row(CAM, "| 11 robot-camera photos (56 tags) |", "apriltag-photos", "robot-camera timing frames",
         {0: item("timing frames", "robot_frames"), 1: item("timing frames", "robot_tags")}),
    *row(CAM, "| 9 NASA crops (139 tags) |", "apriltag-photos", "NASA timing crops",
         {0: item("timing frames", "nasa_frames"), 1: item("timing frames", "nasa_tags")}),
    *row(CAM, "**The chosen front-end finds 57 of the 61 tags (the single pass: 46)", "apriltag-photos",
         "chosen vs single pass", {0: item(CHOSEN, "union"), 1: item(CHOSEN, "counted"), 2: item(SINGLE, "union")}),
    *row(CAM, "**Enlarged 2× instead of 1.75×** finds 59", "apriltag-photos", "enlarged 2x + aruco",
         {2: item(TWICE_ARUCO, "union")}),
    *row(CAM, "`--tag-upsample 1` with the aruco\n  pass finds 52 at", "apriltag-photos", "single pass + aruco (prose)",
         {1: item(SINGLE_ARUCO, "union")}),
    *row(CAM, "of the 15 tags of the union that the single pass misses", "apriltag-photos", "missed by the single pass",
         {0: missed_by(SINGLE)}),
    *row(CAM, "are better enlarged (worst 0.46 px against 0.65 px)", "apriltag-photos", "rendered worst corner",
         {0: item(CHOSEN, "rendered_max"), 1: item(SINGLE, "rendered_max")}),
    *row(CAM, "are within 0.46 px, mean 0.14 px, 95 % 0.33 px, against 0.54 / 0.16 / 0.46 px for the",
         "apriltag-photos", "rendered refined corners",
         {0: item("rendered refined", "max"), 1: item("rendered refined", "mean"), 3: item("rendered refined", "p95"),
          4: item("rendered refined single pass", "max"), 5: item("rendered refined single pass", "mean"),
          6: item("rendered refined single pass", "p95")}),
    *row(CAM, "refined corners differ by 0.34 px on average, 1.14 px at most, over the 44 tags matched\n"
         "  within 3 px (the single pass's: 0.30 / 0.96 px)", "apriltag-photos", "refined vs listed corners",
         {0: item("refined", "mean"), 1: item("refined", "max"), 2: item("refined", "matched"),
          4: item("refined single pass", "mean"), 5: item("refined single pass", "max")}),
    *row(CAM, "detector ≥ 55 of 61 (prints 57)", "apriltag-photos", "test: front-end",
         {1: item(CHOSEN, "counted"), 2: item(CHOSEN, "union")}),
    *row(CAM, "single pass 46 of 61, and 46 of the 47 reference tags with corners within 0.14 px", "apriltag-photos",
         "test: single pass", {0: item(SINGLE, "union"), 1: item(SINGLE, "counted"), 2: item(SINGLE, "reference"),
                               3: item(SINGLE, "listed"), 4: item(SINGLE, "reference_max")}),
]

COLOUR_REAL_ROWS = (  # python -m scripts.bench_colour_real ../shared/data/rgbd-real, row by row
    "| sequence/00000 | 1 | 0 | shape_mismatch 1 |",
    "| sequence/00001 | 2 | 0 | shape_mismatch 2 |",
    "| sequence/00002 | 1 | 0 | shape_mismatch 1 |",
    "| sequence/00003 | 2 | 0 | blob_at_image_border 1, shape_mismatch 1 |",
    "| sequence/00004 | 3 | 0 | shape_mismatch 2, blob_at_image_border 1 |",
    "| TUM | 24 | 0 | shape_mismatch 22, blob_at_image_border 2 |",
    "| SUN | 1 | 0 | shape_mismatch 1 |",
    "| +0, +0 | 730/735 (99.3 %) | 0 | 0.40 % | 0.053° | 1.04 % | 0 | 2.34 % (689) |",
    "| +2, +0 | 729/735 (99.2 %) | 0 | 0.53 % | 0.184° | 1.04 % | 0 | 2.21 % (690) |",
    "| -2, +0 | 727/735 (98.9 %) | 0 | 0.53 % | 0.203° | 1.04 % | 0 | 2.46 % (688) |",
    "| +0, +2 | 727/735 (98.9 %) | 0 | 0.40 % | 0.053° | 1.38 % | 0 | 2.37 % (686) |",
    "| +0, -2 | 730/735 (99.3 %) | 0 | 0.40 % | 0.053° | 1.04 % | 0 | 2.34 % (683) |",
    "| +2, +2 | 727/735 (98.9 %) | 0 | 0.53 % | 0.184° | 1.24 % | 0 | 2.34 % (686) |",
)

QUOTES: list[Quote] = [
    *[q for text in ACCURACY_ROWS for q in same_row(CAM, text, "camera-accuracy", "accuracy table")],
    *row(CAM_USER, "(largest error 11.4–12.9 % per\n   distance at 1–4 m;", "camera-accuracy", "gHeight error range",
         {0: gheight_range(min), 1: gheight_range(max)}),
    *row(CAM, "56 tags: **σ_px = 0.46 px**", "tag-corner-sigma", "real corner sigma",
         {0: lambda r: r[1], 1: lambda r: r[0]}),
    *[q for text, name, columns in DETECTOR_ROWS for q in detector_row(text, name, columns)],
    *DETECTOR_PROSE,
    *[q for text in COLOUR_REAL_ROWS for q in same_row(CAM, text, "colour-real", "real RGB-D frames")],
]
