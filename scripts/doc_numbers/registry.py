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
         {0: association_rate("ekf"), 1: association_rate("ekf-nn"), 2: association_rate("ekf-s001")}),
    *row(R, "| grid, 200 landmarks | 99.96 % (8 rejected, 200 landmarks) | 99.87 % (29 rejected) | "
         "83.30 % (241 landmarks for 200) |", "grid200-hidden", "association, grid 200",
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

SEEDS = [
    *flaw_row(S, "| `ekf` (textbook EKF-SLAM) | 0.011 | 0.011 | 0.026 |", "ekf (textbook EKF-SLAM)"),
    *flaw_row(S, "| dead reckoning | 0.067 | 0.080 | 0.054 |", "dead reckoning"),
    *flaw_row(S, "| `ekf-s000` as written | 2.473 | 2.478 | 2.444 |", "ekf-s000 as written"),
    *flaw_row(S, "| `ekf-s000`, both geometry fixes | 0.101 | 0.117 | 0.171 |", "ekf-s000 with both geometry fixes"),
    *flaw_row(S, "| `ekf-s000`, geometry fixed + the log's noise | 0.049 | 0.058 | 0.058 |",
              "ekf-s000 geometry fixed, log noise instead of unit variances"),
    *[q for doc, text, cells in CALIBRATION_SENTENCE
      for q in row(doc, text, "trial-calibration", "ekf-s001 trial calibration", cells, tolerance=None)],
    *row(S, "it associates 83.30 %", "grid200-hidden", "ekf-s001 association, grid 200",
         {0: association_rate("ekf-s001")}),
    *row(S, "seed\n000's linear column-to-angle map adds up to 2.95° of bearing error", "camera-accuracy",
         "seed 000 linear bearing, max", {1: lambda r: max(parse_number(v[-2]) for v in r.values())}),
    *row(S, "the front-end's gHeight option reads\n11.4–12.9 % low at 1–4 m", "camera-accuracy", "gHeight error range",
         {0: lambda r: min(parse_number(v[-1]) for k, v in r.items() if k != "0.5 m"),
          1: lambda r: max(parse_number(v[-1]) for k, v in r.items() if k != "0.5 m")}),
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
    *row(CAM, "56 tags: **σ_px = 0.46 px**", "tag-corner-sigma", "real corner sigma",
         {0: lambda r: r[1], 1: lambda r: r[0]}),
]

QUOTES: list[Quote] = [
    *README_DEMO, *README_GRID, *README_SHOWS, *README_PAPERS, *README_FIXED, *README_ASSOCIATION,
    *README_OUTLIERS, *README_CHECK, *SEEDS, *SEED002, *CAMERA,
]
