"""The numbers that README.md quoted before it became a manual, wherever they live now:
README.md keeps the demo (`make demo`'s table) and `fgslam check`; docs/output.md the worked
example on the 200-landmark grid; docs/results.md what the comparison shows, the seed papers'
filters, data association, outliers, `fgslam bench`, the camera summary, and (with --shared)
the MRCLAM Dataset 6 table."""

from __future__ import annotations

from scripts.doc_numbers.quotes import Quote, parse_number, row
from scripts.doc_numbers.readers import association, association_rate, flaw, item, median, metric, metric_row, scene
from scripts.doc_numbers.registry.camera import CHOSEN, SINGLE, SINGLE_ARUCO

R = "README.md"
OUT = "docs/output.md"  # the worked example on the grid, how to read the table
RES = "docs/results.md"  # the research results that moved out of the README
DEMO = "ate online final map landmarks - - - unused nees nis -"  # fgslam run's table with NEES/NIS
DEAD = "ate online final map landmarks - - - unused nees -"  # the same for dead reckoning (no NIS)
BATCH = "ate final map landmarks -"
#: The same since the table shows the aligned ATE (the results pages keep the tables as measured)
ALIGNED = {"ekf": "ate online aligned final map landmarks - - - unused nees nis -",
           "dead_reckoning": "ate online aligned final map landmarks - - - unused nees -",
           "batch": "ate aligned final map landmarks -"}
#: The table of a run with sampled NEES/NIS (``94.5±1.1``): those columns not compared
SAMPLED = {"ekf": "ate online aligned final map landmarks - - - unused - - -",
           "batch": "ate aligned final map landmarks -"}
ACCURACY = "ate online final map landmarks"  # a table row quoted up to its landmarks column
ACCURACY_ALIGNED = "ate online aligned final map landmarks"  # the same with the aligned ATE column


def run_table(source: str, lines: dict[str, str], doc: str = R, *, aligned: bool = False) -> list[Quote]:
    """The rows of a table ``fgslam run`` printed with its NEES/NIS columns: estimator → its line
    (``aligned``: the table with the ATE aligned column, as ``fgslam run`` prints it now)."""
    if aligned:
        return [q for e, line in lines.items() for q in metric_row(doc, line, source, e, ALIGNED.get(e, ALIGNED["ekf"]))]
    columns = {"dead_reckoning": DEAD, "batch": BATCH}
    return [q for e, line in lines.items() for q in metric_row(doc, line, source, e, columns.get(e, DEMO))]


README_DEMO = [
    # the demo's table as `fgslam run` prints it by default: NEES/NIS at a seeded sample of
    # steps (share±standard error, not compared here: the docs' every-step figures are below)
    *[q for e, line in {
        "ekf": 'ekf                  0.0110        0.0110         0.0092       0.0071      0.0144          8      59.5        0.076        0.182           0  100.0±2.6   98.3±1.7      1.2',
        "isam2": 'isam2                0.0076        0.0107         0.0052       0.0066      0.0125          8      76.1        0.022        1.070           0  100.0±2.6  100.0±2.6      9.3',
        "dead_reckoning": 'dead_reckoning       0.0668        0.0668         0.0367       0.0628      0.1171          8       9.0        0.012        0.031           0   90.0±4.6          -      0.0',
        "batch": 'batch                0.0076             -         0.0052       0.0066      0.0125          8       7.8            -            -           -          -          -        -'}.items()
      for q in metric_row(R, line, "octagon", e, SAMPLED.get(e, SAMPLED["ekf"]))],
    Quote(R, "660 poses over 65.9 s, 789 observations of 8 landmarks", "660", "octagon",
          lambda m: m["poses"], "bundled log: poses"),
    *row(OUT, "On the bundled log: NEES inside the band ekf 96 %, isam2 97 %; NIS mean 1.93 (ekf) and\n"
         "  1.78 (isam2), 95.5 % and 96.2 % inside.", "octagon", "NEES/NIS sentence",
         {0: metric("ekf", "nees_inside_95", 100), 1: metric("isam2", "nees_inside_95", 100),
          2: metric("ekf", "nis_mean"), 3: metric("isam2", "nis_mean"), 4: metric("ekf", "nis_inside_95", 100),
          5: metric("isam2", "nis_inside_95", 100)}),
]

README_GRID = [
    *run_table("grid200", {
        "ekf": 'ekf                  0.4029        0.4029         0.0888       0.0303      0.3393        200    8202.6        0.851        6.107           0       98.7      94.8      6.7',
        "isam2": 'isam2                0.1935        0.3095         0.0192       0.0264      0.1833        200    6304.3        0.161       11.092           0       98.7      95.3     86.2',
        "dead_reckoning": 'dead_reckoning      11.4031       11.4031         6.5597      15.1154      4.6379        200     122.4        0.014        0.039           0       88.2         -      0.5',
        "batch": 'batch                0.1936             -         0.0192       0.0264      0.1834        200     154.2'}, doc=OUT, aligned=True),
    Quote(OUT, "wrote runs/grid200.jsonl: 6621 poses over 1324.0 s, 21839 observations", "6621", "grid200",
          lambda m: m["poses"], "grid 200: poses"),
    *row(RES, "the same final estimate (0.1936 m);", "grid200", "isam2-fast final",
         {0: metric("isam2-fast", "ate_rmse_m")}),
    *row(RES, "its\n  online ATE is 0.300 m.", "grid200", "isam2-fast online",
         {0: metric("isam2-fast", "ate_online_rmse_m")}),
]

README_SHOWS = [
    *row(RES, "| arena-octagon (660 poses, 8 tags) | 0.0110 m | 0.0076 m | 0.0076 m | 0.0668 m | 0.0110 m | 0.0107 m |",
         "octagon", "What the comparison shows, octagon",
         {0: lambda m: m["poses"], 2: metric("ekf", "ate_rmse_m"), 3: metric("isam2", "ate_rmse_m"),
          4: metric("batch", "ate_rmse_m"), 5: metric("dead_reckoning", "ate_rmse_m"),
          6: metric("ekf", "ate_online_rmse_m"), 7: metric("isam2", "ate_online_rmse_m")}),
    *row(RES, "| grid, 200 landmarks (6 621 poses) | 0.4029 m | 0.1935 m | 0.1936 m | 11.40 m | 0.4029 m | 0.3095 m |",
         "grid200", "What the comparison shows, grid 200",
         {1: lambda m: m["poses"], 2: metric("ekf", "ate_rmse_m"), 3: metric("isam2", "ate_rmse_m"),
          4: metric("batch", "ate_rmse_m"), 5: metric("dead_reckoning", "ate_rmse_m"),
          6: metric("ekf", "ate_online_rmse_m"), 7: metric("isam2", "ate_online_rmse_m")}),
]

README_PAPERS = [
    *metric_row(RES, "ekf              0.0110        0.0110       0.0071      0.0144          8",
                "octagon", "ekf", ACCURACY),
    *metric_row(RES, "ekf-s000         2.4732        2.4732       1.7789      2.4674          8",
                "octagon", "ekf-s000", ACCURACY),
    *metric_row(RES, "ekf-s001         0.0337        0.0337       0.0285      0.0475          8",
                "octagon", "ekf-s001", ACCURACY),
    Quote(RES, "100.00                0/8/0", "100.00", "octagon", association_rate("ekf-s001"),
          "ekf-s001 assoc %"),
    *metric_row(RES, "ekf-s004         2.2687        2.2687       2.0489      1.7464          8",
                "octagon", "ekf-s004", ACCURACY),
    *metric_row(RES, "isam2            0.0076        0.0107       0.0066      0.0125          8",
                "octagon", "isam2", ACCURACY),
    *metric_row(RES, "isam2-tags       0.0069        0.0105       0.0070      0.0100          8",
                "octagon", "isam2-tags", ACCURACY),
    *metric_row(RES, "batch            0.0076             -       0.0066      0.0125          8",
                "octagon", "batch", BATCH),
    # the variants' summary: as written (octagon / square) from the runs, fixed from scripts/flaw_costs.py
    *row(RES, "| `ekf-s000` | 2.47 m / 2.48 m |", "octagon", "ekf-s000 octagon", {0: metric("ekf-s000", "ate_rmse_m")}),
    *row(RES, "| `ekf-s000` | 2.47 m / 2.48 m |", "square-papers", "ekf-s000 square", {1: metric("ekf-s000", "ate_rmse_m")}),
    *row(RES, "| `ekf-s001` | 0.034 m / 0.016 m |", "octagon", "ekf-s001 octagon", {0: metric("ekf-s001", "ate_rmse_m")}),
    *row(RES, "| `ekf-s001` | 0.034 m / 0.016 m |", "square-papers", "ekf-s001 square", {1: metric("ekf-s001", "ate_rmse_m")}),
    *row(RES, "| `ekf-s004` | 2.27 m / 7.38 m |", "octagon", "ekf-s004 octagon", {0: metric("ekf-s004", "ate_rmse_m")}),
    *row(RES, "| `ekf-s004` | 2.27 m / 7.38 m |", "square-papers", "ekf-s004 square", {1: metric("ekf-s004", "ate_rmse_m")}),
]


README_FIXED = [
    *row(RES, "0.10 m / 0.12 m with both fixed", "flaw-costs", "ekf-s000 both fixes",
         {0: flaw("arena_octagon", "ekf-s000 with both geometry fixes"),
          1: flaw("arena_square", "ekf-s000 with both geometry fixes")}),
    *row(RES, "0.011 m / 0.011 m with its three flaws off", "flaw-costs", "ekf-s001 three off",
         {0: flaw("arena_octagon", "ekf-s001 all three off"), 1: flaw("arena_square", "ekf-s001 all three off")}),
    *row(RES, "0.028 m / 0.014 m with both off", "flaw-costs", "ekf-s004 both off",
         {0: flaw("arena_octagon", "ekf-s004 both off (heading still treated as known)"),
          1: flaw("arena_square", "ekf-s004 both off (heading still treated as known)")}),
]

README_ASSOCIATION = [
    *row(RES, "| arena-octagon | 100.00 % | 100.00 % | 100.00 % |", "octagon-hidden", "association, octagon",
         {i: scene("arena-octagon", association_rate(e)) for i, e in enumerate(("ekf", "ekf-nn", "ekf-s001"))}),
    *row(RES, "| grid, 200 landmarks | 99.96 % (8 rejected, 200 landmarks) | 99.87 % (29 rejected) | "
         "83.39 % (241 landmarks for 200) |", "grid200-hidden", "association, grid 200",
         {1: association_rate("ekf"), 2: association("ekf", "rejected"), 3: association("ekf", "landmarks_created"),
          4: association_rate("ekf-nn"), 5: association("ekf-nn", "rejected"), 6: association_rate("ekf-s001"),
          7: association("ekf-s001", "landmarks_created")}),
]

README_OUTLIERS = [
    *metric_row(RES, "ekf                0.0110        0.0110         0.0092       0.0071      0.0144          8",
                "octagon-outliers", "ekf", ACCURACY_ALIGNED),
    *metric_row(RES, "isam2              0.0076        0.0107         0.0052       0.0067      0.0126          8",
                "octagon-outliers", "isam2", ACCURACY_ALIGNED),
    *metric_row(RES, "isam2-huber        0.0077        0.0098         0.0057       0.0086      0.0137          8",
                "octagon-outliers", "isam2-huber", ACCURACY_ALIGNED),
    *metric_row(RES, "isam2-cauchy       0.0078        0.0107         0.0053       0.0077      0.0133          8",
                "octagon-outliers", "isam2-cauchy", ACCURACY_ALIGNED),
    *metric_row(RES, "isam2-tukey        0.0074        0.0110         0.0052       0.0070      0.0123          8",
                "octagon-outliers", "isam2-tukey", ACCURACY_ALIGNED),
    *metric_row(RES, "isam2-dcs          0.0076        0.0107         0.0052       0.0067      0.0126          8",
                "octagon-outliers", "isam2-dcs", ACCURACY_ALIGNED),
    *metric_row(RES, "batch              0.0076             -         0.0052       0.0067      0.0126          8",
                "octagon-outliers", "batch", "ate aligned final map landmarks"),
    Quote(RES, "94 gated", "94", "octagon-outliers", lambda m: m["ekf"]["unused_observations"]["gated"], "ekf gated"),
    Quote(RES, "here it leaves out 94 readings", "94", "octagon-outliers",
          lambda m: m["ekf"]["unused_observations"]["gated"], "ekf gated (prose)"),
    Quote(RES, "wreck it (0.2055 m)", "0.2055", "octagon-outliers-ekf-no-gate", lambda ate: ate, "ekf without its gate"),
]

VICTORIA_PARK = [
    *metric_row(RES, "ekf                 15.1124       15.1124       3.0099     19.4226        151", "victoria-park",
                "ekf", ACCURACY),
    *metric_row(RES, "isam2-fast           0.0080        7.3211       0.0002      0.0129        151", "victoria-park",
                "isam2-fast", ACCURACY),
    *metric_row(RES, "dead_reckoning     155.3987      155.3987     202.2922    150.4639        151", "victoria-park",
                "dead_reckoning", ACCURACY),
    *metric_row(RES, "batch                0.0000             -       0.0000      0.0000        151", "victoria-park",
                "batch", BATCH),
    *row(RES, "(15.11 m from the smoothed solution, against 155.4 m for odometry\nalone)", "victoria-park",
         "ekf and dead reckoning (prose)", {0: metric("ekf", "ate_rmse_m"), 1: metric("dead_reckoning", "ate_rmse_m")}),
    *row(RES, "it rejects 2 577 of the 3 489 re-observations of\nmapped trees once the heading has drifted, and the EKF "
         "ends 191.8 m off", "victoria-park", "ekf with the gate forced on (prose)",
         {0: lambda m: m["ekf-gated"]["unused_observations"]["gated"], 1: lambda m: m["ekf"]["nis_count"],
          2: metric("ekf-gated", "ate_rmse_m")}),
    *row(RES, "(online\nATE 7.32 m;", "victoria-park", "isam2-fast online (prose)", {0: metric("isam2-fast", "ate_online_rmse_m")}),
    *row("docs/performance.md", "the EKF's online ATE against it is 15.11 m. (The", "victoria-park",
         "performance.md ekf", {0: metric("ekf", "ate_online_rmse_m")}),
    *row("docs/performance.md", "rejects 2 577 re-observations and ends 191.8 m off", "victoria-park",
         "performance.md ekf with the gate forced on",
         {0: lambda m: m["ekf-gated"]["unused_observations"]["gated"], 1: metric("ekf-gated", "ate_rmse_m")}),
]

README_CHECK = [
    Quote(R, "PASS ekf vs smoothed on arena_octagon.jsonl: ATE 0.0097 m <= 0.5 m", "0.0097", "check-octagon",
          lambda ate: ate, "fgslam check ATE"),
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
    ("| iSAM2 online ATE ≤ EKF's online | 12/20 (means 0.0179 vs 0.0179 m) | 2/6 (means 0.272 vs 0.281 m) |",
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
            quotes += row(RES, text, source, f"seed sweep {source}", cells)
    return quotes


BENCH = [
    *row(RES, "50 runs (seeds 0-49), 654 steps; 95 % band of the average NEES over 50 runs: [2.360, 3.716]",
         "bench-octagon", "bench band", {3: lambda r: r["steps"], 6: lambda r: r["band"][0], 7: lambda r: r["band"][1]}),
    *row(RES, "ekf                  98.5%        0.8%       3.16        0.0154, 0.0351", "bench-octagon", "bench ekf",
         {i: item("ekf", i) for i in range(5)}),
    *row(RES, "isam2                95.7%        3.5%       3.25        0.0136, 0.0315", "bench-octagon", "bench isam2",
         {i: item("isam2", i) for i in range(5)}),
    *row(RES, "The default `isam2` is inside the band at 95.7 % of the steps, with\nshort excursions above it "
         "(the longest around steps 177–181 and 333–337; 3.5 % of the steps)", "bench-octagon", "bench isam2 prose",
         {0: item("isam2", 0), 5: item("isam2", 1)}),
]


def largest(column: int):
    """The largest number at ``column`` over the rows of the rendered accuracy table (the
    ``camera-accuracy`` source: first cell → the numbers of its row)."""
    return lambda result: max(parse_number(v[column]) for v in result.values())


CAMERA = [
    *row(RES, "  - tag range error ≤ 0.63 % and bearing error ≤ 0.034°;\n"
         "  - cylinder range error ≤ 0.40 %, bearing ≤ 0.031°, height ≤ 1.24 %;", "camera-accuracy",
         "rendered-frame errors", {i: largest(column) for i, column in enumerate((3, 4, 8, 9, 10))}),
    *row(RES, "of the 61 tags that any of", "apriltag-photos", "union", {0: item(CHOSEN, "counted")}),
    *row(RES, "finds 57\n  with no false detection", "apriltag-photos", "front-end", {0: item(CHOSEN, "union")}),
    *row(RES, "AprilTag 3 alone, which finds 46.", "apriltag-photos", "single pass", {1: item(SINGLE, "union")}),
    *row(RES, "`--tag-upsample 1` finds 52", "apriltag-photos", "single pass + aruco", {1: item(SINGLE_ARUCO, "union")}),
]

#: The columns of the MRCLAM Dataset 6 table after the robot: (estimator, score, scale).
MRCLAM_COLUMNS = (("ekf", "ate_final_m", 1), ("isam2", "ate_final_m", 1), ("isam2", "ate_online_m", 1),
                  ("batch", "ate_final_m", 1), ("dead_reckoning", "ate_final_m", 1), ("ekf", "ate_final_aligned_m", 1),
                  ("isam2", "ate_final_aligned_m", 1), ("isam2", "ate_online_aligned_m", 1), ("ekf", "map_rmse_m", 1),
                  ("isam2", "map_rmse_m", 1), ("ekf", "nis_inside", 100), ("isam2", "nis_inside", 100))


def mrclam(robot: int | None, estimator: str, score: str, scale: float):
    """One robot's score, or (robot None) the median over the five."""
    if robot is None:
        return lambda r: scale * median(r[k][estimator][score] for k in r)
    return lambda r: scale * r[robot][estimator][score]


def mrclam_row(text: str, robot: int | None) -> list[Quote]:
    first = 0 if robot is None else 1  # a robot's row starts with its number
    return row(RES, text, "mrclam6", f"MRCLAM Dataset 6 robot {robot or 'median'}",
               {first + i: mrclam(robot, *column) for i, column in enumerate(MRCLAM_COLUMNS)})


MRCLAM = [  # the "Real robot data" section: registered here, edited elsewhere
    *mrclam_row("| 1 | 0.149 | 0.136 | 0.173 | 0.136 | 1.732 | 0.128 | 0.056 | 0.134 | 0.05 / 0.15 | 92.4 / 93.1 % |", 1),
    *mrclam_row("| 2 | 0.642 | 0.131 | 0.265 | 0.131 | 1.219 | 0.194 | 0.095 | 0.205 | 1.07 / 0.17 | 90.2 / 93.7 % |", 2),
    *mrclam_row("| 3 | 0.117 | 0.074 | 0.114 | 0.074 | 2.896 | 0.088 | 0.047 | 0.089 | 0.10 / 0.11 | 89.6 / 91.3 % |", 3),
    *mrclam_row("| 4 | 0.221 | 0.241 | 0.289 | 0.241 | 1.384 | 0.185 | 0.068 | 0.209 | 0.22 / 0.35 | 88.1 / 91.6 % |", 4),
    *mrclam_row("| 5 | 1.349 | 0.513 | 0.497 | 0.513 | 2.295 | 0.255 | 0.064 | 0.121 | 2.03 / 0.73 | 88.7 / 90.6 % |", 5),
    *mrclam_row("| **median** | **0.221** | **0.136** | **0.265** | **0.136** | **1.732** | **0.185** | **0.064** | "
                "**0.134** | 0.22 / 0.17 | 89.6 / 91.6 % |", None),
]

QUOTES: list[Quote] = [
    *README_DEMO, *README_GRID, *README_SHOWS, *README_PAPERS, *README_FIXED, *README_ASSOCIATION,
    *README_OUTLIERS, *VICTORIA_PARK, *README_CHECK, *sweep_quotes(), *BENCH, *CAMERA, *MRCLAM,
]
