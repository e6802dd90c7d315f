"""The numbers README.md and docs/*.md quote that a script can recompute.

Each quote names the doc, the exact text that holds the number, the source that measures it
(:mod:`doc_numbers.sources`) and how to read the number from the source's result. Times are
not registered: they depend on the machine and its load, and the docs say so where they
quote them.
"""

from __future__ import annotations

from doc_numbers.quotes import ROOT, Quote, parse_number, row
from doc_numbers.readers import association, association_rate, metric, metric_row, same_row

R = "README.md"
DEMO = "ate online final map landmarks - - - unused nees nis -"  # fgslam run's table with NEES/NIS
BATCH = "ate final map landmarks -"

README_DEMO = [
    *metric_row(R, "ekf                  0.0110        0.0110       0.0071      0.0144          8     447.8        "
                "0.194        8.723           0       96.1      95.5      1.0", "octagon", "ekf", DEMO),
    *metric_row(R, "isam2                0.0076        0.0108       0.0066      0.0125          8     374.0        "
                "0.099        8.961           0       96.4      95.0      7.3", "octagon", "isam2", DEMO),
    *metric_row(R, "dead_reckoning       0.0668        0.0668       0.0628      0.1171          8      14.1        "
                "0.012        0.036           0       88.5         -      0.1", "octagon", "dead_reckoning",
                "ate online final map landmarks - - - unused nees -"),
    *metric_row(R, "batch                0.0076             -       0.0066      0.0125          8      24.8",
                "octagon", "batch", BATCH),
    Quote(R, "660 poses over 65.9 s, 789 observations of 8 landmarks", "660", "octagon",
          lambda m: m["poses"], "bundled log: poses"),
    *row(R, "On the bundled log: NEES inside the band ekf 96 %, isam2 96 %; NIS mean 1.93 (ekf) and\n"
         "  1.90 (isam2), 95.5 % and 95.0 % inside.", "octagon", "NEES/NIS sentence",
         {0: metric("ekf", "nees_inside_95", 100), 1: metric("isam2", "nees_inside_95", 100),
          2: metric("ekf", "nis_mean"), 3: metric("isam2", "nis_mean"), 4: metric("ekf", "nis_inside_95", 100),
          5: metric("isam2", "nis_inside_95", 100)}),
]

README_GRID = [
    *metric_row(R, "ekf                  0.4076        0.4076       0.0305      0.3451        200    8628.5        "
                "0.828        6.378     3 gated       98.7      94.8      5.6", "grid200", "ekf", DEMO),
    *metric_row(R, "isam2                0.1936        0.3086       0.0264      0.1834        200   11313.8        "
                "0.184       27.636           0       98.8      95.0     76.9", "grid200", "isam2", DEMO),
    *metric_row(R, "dead_reckoning      11.4031       11.4031      15.1154      4.6379        200      87.1        "
                "0.012        0.022           0       88.2         -      0.8", "grid200", "dead_reckoning",
                "ate online final map landmarks - - - unused nees -"),
    *metric_row(R, "batch                0.1936             -       0.0264      0.1834        200     212.9",
                "grid200", "batch", BATCH),
    Quote(R, "wrote runs/grid200.jsonl: 6621 poses over 1324.0 s, 21839 observations", "6621", "grid200",
          lambda m: m["poses"], "grid 200: poses"),
    *row(R, "ends at\n  the same final estimate (0.1936 m); its online ATE is worse (0.384 m)", "grid200", "isam2-fast",
         {0: metric("isam2-fast", "ate_rmse_m"), 1: metric("isam2-fast", "ate_online_rmse_m")}),
]

README_SHOWS = [
    *row(R, "| arena-octagon (660 poses, 8 tags) | 0.0110 m | 0.0076 m | 0.0076 m | 0.0668 m | 0.0110 m | 0.0108 m |",
         "octagon", "What the comparison shows, octagon",
         {0: lambda m: m["poses"], 2: metric("ekf", "ate_rmse_m"), 3: metric("isam2", "ate_rmse_m"),
          4: metric("batch", "ate_rmse_m"), 5: metric("dead_reckoning", "ate_rmse_m"),
          6: metric("ekf", "ate_online_rmse_m"), 7: metric("isam2", "ate_online_rmse_m")}),
    *row(R, "| grid, 200 landmarks (6 621 poses) | 0.4076 m | 0.1936 m | 0.1936 m | 11.40 m | 0.4076 m | 0.3086 m |",
         "grid200", "What the comparison shows, grid 200",
         {3: metric("ekf", "ate_rmse_m"), 4: metric("isam2", "ate_rmse_m"), 5: metric("batch", "ate_rmse_m"),
          6: metric("dead_reckoning", "ate_rmse_m"), 7: metric("ekf", "ate_online_rmse_m"),
          8: metric("isam2", "ate_online_rmse_m")}),
]

README_PAPERS = [
    *metric_row(R, "ekf              0.0110        0.0110       0.0071      0.0144          8",
                "octagon", "ekf", "ate online final map landmarks"),
    *metric_row(R, "ekf-s000         2.4732        2.4732       1.7789      2.4674          8",
                "octagon", "ekf-s000", "ate online final map landmarks"),
    *metric_row(R, "ekf-s001         0.0337        0.0337       0.0285      0.0475          8",
                "octagon", "ekf-s001", "ate online final map landmarks"),
    Quote(R, "100.00                0/8/0", "100.00", "octagon", association_rate("ekf-s001"),
          "ekf-s001 assoc %"),
    *metric_row(R, "ekf-s004         2.2687        2.2687       2.0489      1.7464          8",
                "octagon", "ekf-s004", "ate online final map landmarks"),
    *metric_row(R, "isam2            0.0076        0.0108       0.0066      0.0125          8",
                "octagon", "isam2", "ate online final map landmarks"),
    *metric_row(R, "isam2-tags       0.0069        0.0103       0.0070      0.0100          8",
                "octagon", "isam2-tags", "ate online final map landmarks"),
    *metric_row(R, "batch            0.0076             -       0.0066      0.0125          8",
                "octagon", "batch", BATCH),
    # the variants' summary: as written (octagon / square) from the runs, fixed from scripts/flaw_costs.py
    *row(R, "| `ekf-s000` | 2.47 m / 2.48 m |", "octagon", "ekf-s000 octagon", {0: metric("ekf-s000", "ate_rmse_m")}),
    *row(R, "| `ekf-s000` | 2.47 m / 2.48 m |", "square-papers", "ekf-s000 square", {1: metric("ekf-s000", "ate_rmse_m")}),
    *row(R, "| `ekf-s001` | 0.034 m / 0.016 m |", "octagon", "ekf-s001 octagon", {0: metric("ekf-s001", "ate_rmse_m")}),
    *row(R, "| `ekf-s001` | 0.034 m / 0.016 m |", "square-papers", "ekf-s001 square", {1: metric("ekf-s001", "ate_rmse_m")}),
    *row(R, "| `ekf-s004` | 2.27 m / 7.38 m |", "octagon", "ekf-s004 octagon", {0: metric("ekf-s004", "ate_rmse_m")}),
    *row(R, "| `ekf-s004` | 2.27 m / 7.38 m |", "square-papers", "ekf-s004 square", {1: metric("ekf-s004", "ate_rmse_m")}),
]


def scene(scenario: str, read):
    """``read`` applied to one scenario's metrics of a source that runs several."""
    return lambda result: read(result[scenario])


def association_cells(estimators=("ekf", "ekf-nn"), scenario: str | None = None) -> dict:
    """docs/estimators.md's association row: rate % (correct/observations[, N rejected]) per estimator."""
    cells, i = {}, 0
    for e in estimators:
        for read in (association_rate(e), association(e, "correct"), association(e, "observations")):
            cells[i] = read if scenario is None else scene(scenario, read)
            i += 1
    return cells


def flaw(log: str, setting: str, key: str = "ate_rmse_m"):
    return lambda result: result[log][setting][key]


README_FIXED = [
    *row(R, "0.10 m / 0.12 m with both fixed", "flaw-costs", "ekf-s000 both fixes",
         {0: flaw("arena_octagon", "ekf-s000 with both geometry fixes"),
          1: flaw("arena_square", "ekf-s000 with both geometry fixes")}),
    *row(R, "0.011 m / 0.011 m with its three flaws off", "flaw-costs", "ekf-s001 three off",
         {0: flaw("arena_octagon", "ekf-s001 all three off"), 1: flaw("arena_square", "ekf-s001 all three off")}),
    *row(R, "0.028 m / 0.014 m with both off", "flaw-costs", "ekf-s004 both off",
         {0: flaw("arena_octagon", "ekf-s004 both off (heading still treated as known)"),
          1: flaw("arena_square", "ekf-s004 both off (heading still treated as known)")}),
]

README_ASSOCIATION = [
    *row(R, "| arena-octagon | 100.00 % | 100.00 % | 100.00 % |", "octagon-hidden", "association, octagon",
         {i: scene("arena-octagon", association_rate(e)) for i, e in enumerate(("ekf", "ekf-nn", "ekf-s001"))}),
    *row(R, "| grid, 200 landmarks | 99.96 % (8 rejected, 200 landmarks) | 99.87 % (29 rejected) | "
         "83.39 % (241 landmarks for 200) |", "grid200-hidden", "association, grid 200",
         {1: association_rate("ekf"), 2: association("ekf", "rejected"), 3: association("ekf", "landmarks_created"),
          4: association_rate("ekf-nn"), 5: association("ekf-nn", "rejected"), 6: association_rate("ekf-s001"),
          7: association("ekf-s001", "landmarks_created")}),
]

README_OUTLIERS = [
    *metric_row(R, "ekf                0.0110        0.0110       0.0071      0.0144          8",
                "octagon-outliers", "ekf", "ate online final map landmarks"),
    *metric_row(R, "isam2              0.1462        0.2039       0.0910      0.1277          8",
                "octagon-outliers", "isam2", "ate online final map landmarks"),
    *metric_row(R, "isam2-huber        0.0076        0.0096       0.0086      0.0137          8",
                "octagon-outliers", "isam2-huber", "ate online final map landmarks"),
    *metric_row(R, "isam2-cauchy       0.0078        0.0106       0.0078      0.0133          8",
                "octagon-outliers", "isam2-cauchy", "ate online final map landmarks"),
    *metric_row(R, "isam2-tukey        0.0074        0.0109       0.0070      0.0123          8",
                "octagon-outliers", "isam2-tukey", "ate online final map landmarks"),
    *metric_row(R, "isam2-dcs          0.0076        0.0107       0.0067      0.0126          8",
                "octagon-outliers", "isam2-dcs", "ate online final map landmarks"),
    *metric_row(R, "batch              0.1462             -       0.0909      0.1276          8",
                "octagon-outliers", "batch", "ate final map landmarks"),
    Quote(R, "94 gated", "94", "octagon-outliers", lambda m: m["ekf"]["unused_observations"]["gated"], "ekf gated"),
    Quote(R, "here it leaves out 94 readings", "94", "octagon-outliers", lambda m: m["ekf"]["unused_observations"]["gated"], "ekf gated (prose)"),
    Quote(R, "wreck it (0.2055 m)", "0.2055", "octagon-outliers-ekf-no-gate", lambda ate: ate, "ekf without its gate"),
]

README_CHECK = [
    Quote(R, "PASS ekf vs smoothed on arena_octagon.jsonl: ATE 0.0097 m <= 0.5 m", "0.0097", "check-octagon",
          lambda ate: ate, "fgslam check ATE"),
]

S = "docs/seeds.md"
CAM = "docs/camera.md"
EST = "docs/estimators.md"
LOGS = ("arena_octagon", "arena_square", "cylinders")


def flaw_row(doc: str, text: str, setting: str) -> list[Quote]:
    """A row "setting | octagon | square | cylinders" of ATEs from scripts/flaw_costs.py."""
    return row(doc, text, "flaw-costs", setting, {i: flaw(log, setting) for i, log in enumerate(LOGS)})


def calibrated(log: str, key: str = "ate_rmse_m", scale: float = 1.0):
    return lambda result: result[log][key] * scale


def calibrated_nees(extreme):
    return lambda result: extreme(100 * result[f"{log}+cal"]["nees_inside_95"] for log in LOGS[:2])


CALIBRATION_SENTENCE = [
    (doc, text, {0: calibrated("arena_octagon"), 1: calibrated("arena_octagon+cal"), 2: calibrated("arena_square"),
                 3: calibrated("arena_square+cal"), 4: calibrated_nees(min), 5: calibrated_nees(max)})
    for doc, text in (
        (S, "the bundled logs' ATE goes from 0.0337 to 0.0295 m (octagon) and from 0.0162 to\n"
            "   0.0107 m (square), while the NEES inside its band falls to 3–11 %"),
        (EST, "the bundled logs' ATE\ngoes from 0.0337 to 0.0295 m (octagon) and from 0.0162 to 0.0107 m (square), while the\n"
              "NEES inside its band falls to 3–11 %"),
    )
]

#: Where seed 000's linear bearing and seed 002's gHeight sit among the numbers of a row of the
#: accuracy table: distance, tags found/frames, range, bearing, yaw, cylinders found/frames,
#: range, bearing, height (n), seed 000, seed 002 (none when "—").
SEED000, GHEIGHT = 12, 13


def largest(column: int):
    """The largest number at ``column`` over the rows of the accuracy table."""
    return lambda result: max(parse_number(v[column]) for v in result.values())

SEEDS = [
    *flaw_row(S, "| `ekf` (textbook EKF-SLAM) | 0.011 | 0.011 | 0.026 |", "ekf (textbook EKF-SLAM)"),
    *flaw_row(S, "| dead reckoning | 0.067 | 0.080 | 0.054 |", "dead reckoning"),
    *flaw_row(S, "| `ekf-s000` as written | 2.473 | 2.478 | 2.444 |", "ekf-s000 as written"),
    *flaw_row(S, "| `ekf-s000`, both geometry fixes | 0.101 | 0.117 | 0.171 |", "ekf-s000 with both geometry fixes"),
    *flaw_row(S, "| `ekf-s000`, geometry fixed + the log's noise | 0.049 | 0.058 | 0.058 |",
              "ekf-s000 geometry fixed, log noise instead of unit variances"),
    *[q for doc, text, cells in CALIBRATION_SENTENCE
      for q in row(doc, text, "trial-calibration", "ekf-s001 trial calibration", cells, tolerance=None)],
    *row(S, "it associates 83.39 %", "grid200-hidden", "ekf-s001 association, grid 200",
         {0: association_rate("ekf-s001")}),
    *row(S, "seed\n000's linear column-to-angle map adds up to 2.95° of bearing error", "camera-accuracy",
         "seed 000 linear bearing, max", {1: lambda r: max(parse_number(v[SEED000]) for v in r.values())}),
    *row(S, "the front-end's gHeight option reads\n11.4–12.9 % low at 1–4 m", "camera-accuracy", "gHeight error range",
         {0: lambda r: min(parse_number(v[GHEIGHT]) for v in r.values() if len(v) > GHEIGHT),
          1: lambda r: max(parse_number(v[GHEIGHT]) for v in r.values() if len(v) > GHEIGHT)}),
]


def shape_heights(shape: str, method: str):
    """Numbers 1-5 of a row of seeds.md's shape table: the heights in cm at 1.0 → 3.0 m, 0°."""
    return {i + 1: (lambda r, d=d: 100 * r[(shape, d, 0.0)][method]) for i, d in enumerate((1.0, 1.5, 2.0, 2.5, 3.0))}


def summary(method: str, key: str):
    return lambda r: r[method][key]


SEED002 = [
    *row(S, "| circle (24.0 cm) | 21.34, 21.51, 21.39, 21.33, 20.75 cm", "seed002-shapes", "circle gHeight",
         shape_heights("circle", "gheight")),
    *row(S, "| triangle (24.3 cm) | 21.19, 21.03, 20.74, 20.92, — cm", "seed002-shapes", "triangle gHeight",
         {k: v for k, v in shape_heights("triangle", "gheight").items() if k < 5}),
    *row(S, "| rectangle (40.5 cm) | 35.92, 36.02, 35.94, 36.08, 35.56 cm", "seed002-shapes", "rectangle gHeight",
         shape_heights("rectangle", "gheight")),
    *row(S, "(−10.4 … −13.5 %) | 24.02, 24.27, 24.22, 24.24, 23.68 cm", "seed002-shapes", "circle pinhole",
         {k + 1: v for k, v in shape_heights("circle", "pinhole").items()}),
    *row(S, "(−12.8 … −14.6 %) | 23.85, 23.73, 23.49, 23.78, 23.13 cm", "seed002-shapes", "triangle pinhole",
         {k + 1: v for k, v in shape_heights("triangle", "pinhole").items()}),
    *row(S, "(−10.9 … −12.2 %) | 40.49, 40.53, 40.48, 40.71, 40.21 cm", "seed002-shapes", "rectangle pinhole",
         {k + 1: v for k, v in shape_heights("rectangle", "pinhole").items()}),
    *row(S, "Over all 30 frames (both bearings): gHeight −14.6 … −8.6 %, mean −11.5 % (29 of 30 measured",
         "seed002-shapes", "gHeight summary",
         {1: summary("gheight", "min"), 2: summary("gheight", "max"), 3: summary("gheight", "mean"),
          4: summary("gheight", "measured")}),
    *row(S, "the pinhole height\n−4.8 … +3.1 %, mean −0.1 %", "seed002-shapes", "pinhole summary",
         {0: summary("pinhole", "min"), 1: summary("pinhole", "max"), 2: summary("pinhole", "mean")}),
]

CAMERA = [
    *[q for line in (ROOT / CAM).read_text(encoding="utf-8").splitlines() if line.startswith("| ") and
      line.split("|")[1].strip() in ("0.5 m", "1.0 m", "1.5 m", "2.0 m", "2.5 m", "3.0 m", "3.5 m", "4.0 m")
      for q in same_row(CAM, line, "camera-accuracy", "accuracy table")],
    *row(CAM, "(largest error 11.4–12.9 % per\n   distance at 1–4 m;", "camera-accuracy", "gHeight error range",
         {0: lambda r: min(parse_number(v[GHEIGHT]) for v in r.values() if len(v) > GHEIGHT),
          1: lambda r: max(parse_number(v[GHEIGHT]) for v in r.values() if len(v) > GHEIGHT)}),
    *row(R, "  - tag range error ≤ 0.62 % and bearing error ≤ 0.034°;\n"
         "  - cylinder range error ≤ 0.40 %, bearing ≤ 0.031°, height ≤ 1.24 %;", "camera-accuracy",
         "README rendered-frame errors", {i: largest(column) for i, column in enumerate((3, 4, 8, 9, 10))}),
    *row(CAM, "56 tags: **σ_px = 0.46 px**", "tag-corner-sigma", "real corner sigma",
         {0: lambda r: r[1], 1: lambda r: r[0]}),
]

def detector(name: str, item: int):
    return lambda result: result[name][item]


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

APRILTAG = [
    *[q for text, name, first in DETECTOR_ROWS
      for q in row(CAM, text, "apriltag-photos", name, {first + i: detector(name, i) for i in range(5)})],
    *row(R, "finds 46/47 with no false detection, corners within 0.14 px", "apriltag-photos", "README chosen detector",
         {0: detector(CHOSEN, 0), 1: detector(CHOSEN, 1), 2: detector(CHOSEN, 3)}),
    *row(R, "OpenCV's `cv2.aruco` finds 25/47", "apriltag-photos", "README aruco",
         {0: detector("cv2.aruco APRILTAG_36h11, CORNER_REFINE_APRILTAG", 0)}),
    *row(CAM, "Corners after `refine_tag_corners` differ from the listed ones by 0.30 px on average\n"
         "  (0.96 px at most)", "apriltag-photos", "refined corners", {0: detector("refined", 3), 1: detector("refined", 2)}),
    *row(CAM, "(oblique, blurred: 5 of the 46 NASA tags)", "apriltag-photos", "tags not refined",
         {0: detector("refined", 4), 1: detector("refined", 0)}),
]

ESTIMATORS_ASSOCIATION = [
    *row(EST, "on the grid it is 0.403 m against\n0.408 m with ids, where the validation gate for observations with an id "
         "leaves out 3 readings", "grid200-hidden", "ekf hidden ids, grid", {0: metric("ekf", "ate_rmse_m")}),
    *row(EST, "on the grid it is 0.403 m against\n0.408 m with ids, where the validation gate for observations with an id "
         "leaves out 3 readings", "grid200", "ekf with ids, grid",
         {1: metric("ekf", "ate_rmse_m"), 2: lambda m: m["ekf"]["unused_observations"]["gated"]}),
    *row(EST, "| arena-octagon | 100.00 % (789/789) | 100.00 % (789/789) |", "octagon-hidden", "octagon",
         association_cells(scenario="arena-octagon")),
    *row(EST, "| arena-square | 99.91 % (1158/1159, 1 rejected) | 99.91 % (1158/1159, 1 rejected) |", "square-cylinders-hidden",
         "square", {**{k if k < 3 else k + 1: v for k, v in association_cells(scenario="arena-square").items()},
          3: scene("arena-square", association("ekf", "rejected")), 7: scene("arena-square", association("ekf-nn", "rejected"))}),
    *row(EST, "| cylinders | 99.91 % (1063/1064, 1 rejected) | 99.91 % (1063/1064, 1 rejected) |", "square-cylinders-hidden",
         "cylinders", {**{k if k < 3 else k + 1: v for k, v in association_cells(scenario="cylinders").items()},
          3: scene("cylinders", association("ekf", "rejected")), 7: scene("cylinders", association("ekf-nn", "rejected"))}),
    *row(EST, "| grid, 200 landmarks | 99.96 % (21831/21839, 8 rejected) | 99.87 % (21810/21839, 29 rejected) |",
         "grid200-hidden", "grid 200", {1: association_rate("ekf"), 2: association("ekf", "correct"),
                                        3: association("ekf", "observations"), 4: association("ekf", "rejected"),
                                        5: association_rate("ekf-nn"), 6: association("ekf-nn", "correct"),
                                        7: association("ekf-nn", "observations"), 8: association("ekf-nn", "rejected")}),
    *row(EST, "83.39 % (241 landmarks for 200, ATE 1.495 m against 0.403 m for `ekf`)", "grid200-hidden",
         "ekf-s001 on the hidden-id grid", {0: association_rate("ekf-s001"), 1: association("ekf-s001", "landmarks_created"),
                                            3: metric("ekf-s001", "ate_rmse_m"), 4: metric("ekf", "ate_rmse_m")}),
]

def sweep_count(claim):
    return lambda rows: sum(bool(claim(r)) for r in rows)


def sweep_mean(name: str, key: str):
    return lambda rows: sum(r[name][key] for r in rows) / len(rows)


def _final(r, name):
    return r[name]["ate_rmse_m"]


SWEEP_CLAIMS = (  # README's row, the claim counted per seed, the means quoted beside it (or none)
    ("| iSAM2 final ATE < EKF's | 15/20 (means 0.0158 vs 0.0179 m) | 5/6 (means 0.184 vs 0.281 m) |",
     lambda r: _final(r, "isam2") < _final(r, "ekf"), ("isam2", "ate_rmse_m"), ("ekf", "ate_rmse_m")),
    ("| iSAM2 online ATE ≤ EKF's online | 13/20 (means 0.0178 vs 0.0179 m) | 2/6 (means 0.271 vs 0.281 m) |",
     lambda r: r["isam2"]["ate_online_rmse_m"] <= r["ekf"]["ate_online_rmse_m"], ("isam2", "ate_online_rmse_m"),
     ("ekf", "ate_online_rmse_m")),
    ("| iSAM2 final ATE within 5 % of batch | 20/20 | 6/6 |",
     lambda r: abs(_final(r, "isam2") - _final(r, "batch")) <= 0.05 * _final(r, "batch"), None, None),
    ("| every estimator < ⅓ of dead reckoning | 18/20 | 6/6 |",
     lambda r: max(_final(r, k) for k in ("ekf", "isam2", "batch")) < _final(r, "dead_reckoning") / 3, None, None),
)


def sweep_quotes() -> list[Quote]:
    quotes = []
    for text, claim, first, second in SWEEP_CLAIMS:
        offset = 1 if "within 5 %" in text else 0  # its "5 %" comes first
        for source, start, n in (("sweep-octagon", offset, 20), ("sweep-grid200", offset + (4 if first else 2), 6)):
            cells = {start: sweep_count(claim), start + 1: (lambda rows: len(rows))}
            if first:
                cells.update({start + 2: sweep_mean(*first), start + 3: sweep_mean(*second)})
            quotes += row(R, text, source, f"seed sweep {source}", cells)
    return quotes


def paths(tag_noise: str, estimator: str, scale: float):
    """A row of seeds.md's seed-004 table: wins and medians of map error and ATE over seeds 1–20."""
    import statistics

    def pair(r, i):
        return r[("arena-square", i[0])][estimator][i[1]], r[("arena-octagon", i[0])][estimator][i[1]]

    def wins(item):
        return lambda r: sum(pair(r, (s, item))[1] < pair(r, (s, item))[0] for s in range(1, 21))

    def median(path, item):
        return lambda r: scale * statistics.median(r[(path, s)][estimator][item] for s in range(1, 21))

    return {0: wins(0), 1: lambda r: 20, 2: median("arena-square", 0), 3: median("arena-octagon", 0),
            4: wins(1), 5: lambda r: 20, 6: median("arena-square", 1), 7: median("arena-octagon", 1)}


def views(path: str, key: str):
    import statistics

    return lambda r: statistics.median(r[(path, s)][key] for s in range(1, 21))


SEED004 = [
    *[q for text, noise, estimator, scale in (
        ("| measured | `ekf-s004` as written | 12/20 | 2.398 / 2.829 m | 11/20 | 1.971 / 2.565 m |", "measured",
         "ekf-s004", 1),
        ("| measured | `ekf` | 6/20 | 3.6 / 5.7 mm | 2/20 | 5.1 / 7.5 mm |", "measured", "ekf", 1000),
        ("| measured | `isam2` | 5/20 | 3.7 / 5.6 mm | 6/20 | 4.1 / 5.4 mm |", "measured", "isam2", 1000),
        ("| nominal (default) | `ekf-s004` as written | 14/20 | 1.965 / 1.746 m | 15/20 | 3.279 / 2.292 m |",
         "nominal", "ekf-s004", 1),
        ("| nominal (default) | `ekf` | 4/20 | 11.3 / 15.8 mm | 5/20 | 11.2 / 15.1 mm |", "nominal", "ekf", 1000),
        ("| nominal (default) | `isam2` | 4/20 | 10.9 / 15.6 mm | 7/20 | 10.1 / 13.3 mm |", "nominal", "isam2", 1000),
    ) for q in row(S, text, f"seed004-{noise}", f"seed 004 {noise} {estimator}", paths(noise, estimator, scale))],
    *row(S, "| square | 1 160 | 11.4° | 28.8° |", "seed004-measured", "square viewing angles",
         {2: views("arena-square", "view_spread_deg"), 3: views("arena-square", "view_span_deg")}),
    *row(S, "| octagon | 784 | 1.9° | 5.7° |", "seed004-measured", "octagon viewing angles",
         {0: views("arena-octagon", "sightings"), 1: views("arena-octagon", "view_spread_deg"),
          2: views("arena-octagon", "view_span_deg")}),
]


def bench(estimator: str, item: int):
    return lambda result: result[estimator][item]


BENCH = [
    *row(R, "50 runs (seeds 0-49), 654 steps; 95 % band of the average NEES over 50 runs: [2.360, 3.716]",
         "bench-octagon", "bench band", {3: lambda r: r["steps"], 6: lambda r: r["band"][0], 7: lambda r: r["band"][1]}),
    *[q for name in ("ekf", "isam2") for line in (ROOT / R).read_text(encoding="utf-8").splitlines()
      if line.startswith(f"{name:<14}") and "%" in line and ", " in line
      for q in row(R, line[:line.rindex(",") + 8], "bench-octagon", f"bench {name}",
                   {i: bench(name, i) for i in range(5)})],
]

#: The columns of README's MRCLAM Dataset 6 table after the robot: (estimator, score, scale).
MRCLAM_COLUMNS = (("ekf", "ate_final_m", 1), ("isam2", "ate_final_m", 1), ("isam2", "ate_online_m", 1),
                  ("batch", "ate_final_m", 1), ("dead_reckoning", "ate_final_m", 1), ("ekf", "ate_final_aligned_m", 1),
                  ("isam2", "ate_final_aligned_m", 1), ("isam2", "ate_online_aligned_m", 1), ("ekf", "map_rmse_m", 1),
                  ("isam2", "map_rmse_m", 1), ("ekf", "nis_inside", 100), ("isam2", "nis_inside", 100))


def mrclam(robot, estimator: str, score: str, scale: float):
    """One robot's score, or (robot None) the median over the five."""
    import statistics

    if robot is None:
        return lambda r: scale * statistics.median(r[k][estimator][score] for k in r)
    return lambda r: scale * r[robot][estimator][score]


MRCLAM = [  # README's "Real robot data" section: registered only, edited elsewhere
    *[q for line in (ROOT / R).read_text(encoding="utf-8").splitlines()
      if line.startswith(("| 1 | 0.", "| 2 | 0.", "| 3 | 0.", "| 4 | 0.", "| 5 | 1.", "| **median** | **0."))
      for robot in [None if "median" in line else int(line[2])]
      for q in row(R, line, "mrclam6", f"MRCLAM Dataset 6 robot {robot or 'median'}",
                   {i + (0 if robot is None else 1): mrclam(robot, *column) for i, column in enumerate(MRCLAM_COLUMNS)})],
]

SEED003_COLUMNS = ("ekf-s003 as written", "ekf-s003 figures' reading (= IMU dead reckoning)", "ekf-vio",
                   "isam2-vio (online)")


def seed003_mean(estimator: str):
    return lambda result: sum(drive[estimator] for drive in result.values()) / len(result)


SEED003 = [
    *[q for drive in ("0020", "0027", "0042") for line in (ROOT / S).read_text(encoding="utf-8").splitlines()
      if line.startswith(f"| {drive} ATE 3-D m |")
      for q in row(S, line, "seed003-real", f"seed 003 drive {drive}",
                   {i + 2: (lambda r, d=drive, e=e: r[d][e]) for i, e in enumerate(SEED003_COLUMNS)})],
    *row(S, "| simulated, seeds 1–10, ATE 3-D m | 96.91 | 0.92 | 0.51 | 0.28 |", "seed003-sim", "seed 003 simulated",
         {i + 3: seed003_mean(e) for i, e in enumerate(SEED003_COLUMNS)}),
]

QUOTES: list[Quote] = [
    *README_DEMO, *README_GRID, *README_SHOWS, *README_PAPERS, *README_FIXED, *README_ASSOCIATION,
    *README_OUTLIERS, *README_CHECK, *SEEDS, *SEED002, *CAMERA, *ESTIMATORS_ASSOCIATION, *APRILTAG,
    *sweep_quotes(), *SEED004, *BENCH, *MRCLAM, *SEED003,
]
